/* scene_impl.h: what scene.c shares with the loaders (obj.c, import.c) and the solver beyond
 * hrad.h. */
#ifndef HR_SCENE_IMPL_H
#define HR_SCENE_IMPL_H

#include "hrad.h"

/* A scene's name from its file's path: the base name without directory and last extension
 * ("scene" if that leaves nothing); malloc'd, NULL when out of memory. */
char *hr_scene_name_of(const char *path);

/* The first of kept polygon 'poly''s surfaces (they are consecutive: s->surfs[i].poly never
 * decreases), or s->nsurfs when it has none. O(log n). */
int hr_scene_poly_first(const hr_scene *s, int poly);

#endif
