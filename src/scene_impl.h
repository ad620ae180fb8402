/* scene_impl.h: what the scene loaders (obj.c, import.c) share beyond hrad.h. */
#ifndef HR_SCENE_IMPL_H
#define HR_SCENE_IMPL_H

/* A scene's name from its file's path: the base name without directory and last extension
 * ("scene" if that leaves nothing); malloc'd, NULL when out of memory. */
char *hr_scene_name_of(const char *path);

#endif
