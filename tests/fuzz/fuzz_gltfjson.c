/* fuzz_gltfjson.c: libFuzzer target for the glTF JSON scanner of src/gltfext.c (the emissive
 * strength that assimp 5.2 drops). The input bytes are the JSON text; the scanner must never
 * read past them, must terminate, and must give every material a finite strength >= 0 (1 where
 * it finds none). Replayed over corpus_gltfjson/ and crashes/gltfjson/ as the ctest
 * fuzz_replay_gltfjson. */
#include "fuzz_check.h"
#include "gltfext.h"

#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  enum { N = 8 };
  double k[N];
  /* an exact-size copy, so that ASan sees any read past the end */
  char *copy = malloc(size ? size : 1);
  if (!copy) return 0;
  if (size) memcpy(copy, data, size);
  for (int i = 0; i < N; i++) k[i] = 1;
  hr_gltf_emissive_strength_json(copy, size, k, N);
  for (int i = 0; i < N; i++)
    FUZZ_REQUIRE(isfinite(k[i]) && k[i] >= 0, "material %d: strength %g", i, k[i]);
  free(copy);
  return 0;
}
