/* fuzz_obj.c: libFuzzer target for the OBJ parser. The input bytes are the OBJ text of
 * "fuzz/fuzz.obj". It is parsed with hr_scene_parse_obj_mtl and no MTL text, so `mtllib`
 * statements give their "cannot open material library" warning without touching the disk: the
 * run is hermetic and deterministic. Every result is checked by fuzz_check.h (abort() on a
 * violated invariant). Built with libFuzzer by `make fuzz`, and with replay.c into the ctest
 * fuzz_replay_obj, which runs corpus_obj/ and crashes/obj/ (TESTING.md). */
#include "fuzz_check.h"

#include <stddef.h>
#include <stdint.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  hr_log log = {fuzz_log, NULL};
  hr_err err;
  err.msg[0] = '\0';
  hr_scene *s = NULL;
  hr_status st = hr_scene_parse_obj_mtl((const char *)data, size, NULL, 0, "fuzz/fuzz.obj", &log,
                                        &s, &err);
  fuzz_check_result(st, s, &err, (const char *)data, size, "fuzz/fuzz.obj", NULL);
  hr_scene_destroy(&s);
  return 0;
}
