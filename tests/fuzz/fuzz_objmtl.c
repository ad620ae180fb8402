/* fuzz_objmtl.c: libFuzzer target for an OBJ file with its MTL library. The input is split at the
 * first line "%%mtl" (the bytes "\n%%mtl\n"): before it is the OBJ text of "fuzz/fuzz.obj", after
 * it the MTL text that every `mtllib` statement of the OBJ reads (hr_scene_parse_obj_mtl; no file
 * is opened). Without the separator the whole input is the OBJ and the MTL is empty. Every result
 * is checked by fuzz_check.h (abort() on a violated invariant); MTL errors are named
 * "fuzz/NAME:LINE:" (NAME from the mtllib line, or "/NAME" when absolute). Built with libFuzzer
 * by `make fuzz`, and with replay.c into the ctest fuzz_replay_objmtl, which runs
 * corpus_objmtl/ and crashes/objmtl/ (TESTING.md). */
#include "fuzz_check.h"

#include <stddef.h>
#include <stdint.h>
#include <string.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static const char SEP[] = "\n%%mtl\n";

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  const char *obj = (const char *)data, *mtl = "";
  size_t olen = size, mlen = 0, sl = sizeof SEP - 1;
  for (size_t i = 0; i + sl <= size; i++) {
    if (data[i] == '\n' && memcmp(data + i, SEP, sl) == 0) {
      olen = i + 1; /* the OBJ keeps its last line break */
      mtl = obj + i + sl;
      mlen = size - i - sl;
      break;
    }
  }
  hr_log log = {fuzz_log, NULL};
  hr_err err;
  err.msg[0] = '\0';
  hr_scene *s = NULL;
  hr_status st =
      hr_scene_parse_obj_mtl(obj, olen, mtl, mlen, "fuzz/fuzz.obj", &log, &s, &err);
  /* an MTL error names "fuzz/" + the mtllib name, or the name itself when it is absolute */
  const char *prefix2 = strncmp(err.msg, "/", 1) == 0 ? "/" : "fuzz/";
  fuzz_check_result(st, s, &err, obj, olen, "fuzz/fuzz.obj", prefix2);
  hr_scene_destroy(&s);
  return 0;
}
