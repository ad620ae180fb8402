/* gltfext.h: what assimp 5.2 does not read from a glTF (internal API, gltfext.c). */
#ifndef HR_GLTFEXT_H
#define HR_GLTFEXT_H

#include <stddef.h>

/* Reads KHR_materials_emissive_strength of the first 'n' materials of the glTF or GLB file at
 * 'path' into k[0..n) (1 where a material has none, or when the file's JSON cannot be read: the
 * import reports real errors). Needed because assimp 5.2.5 drops the extension (5.3 reads it).
 * Can't fail. */
void hr_gltf_emissive_strength(const char *path, double *k, unsigned n);
/* The same from the JSON text 'json' ('len' bytes, not NUL-terminated), for tests and fuzzing:
 * k[i] is left alone where material i has no strength. Can't fail; never reads past 'len'. */
void hr_gltf_emissive_strength_json(const char *json, size_t len, double *k, unsigned n);

#endif
