/* replay.c: a main() for the fuzz targets without libFuzzer, so that their corpora and the crash
 * inputs found so far run as ordinary regression tests under any compiler (ctest
 * fuzz_replay_obj, fuzz_replay_objmtl). Usage: replay_TARGET PATH...; each PATH is a file or a
 * directory whose regular files are run in name order. An invariant violation aborts (the test
 * fails); a missing PATH is an error (exit 2). Prints how many inputs ran. */
#include <dirent.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static int run_file(const char *path) {
  FILE *f = fopen(path, "rb");
  if (!f) {
    perror(path);
    return 0;
  }
  size_t cap = 4096, n = 0, got;
  uint8_t *b = malloc(cap);
  while (b && (got = fread(b + n, 1, cap - n, f)) > 0) {
    n += got;
    if (n == cap) {
      uint8_t *nb = realloc(b, cap *= 2);
      if (!nb) free(b);
      b = nb;
    }
  }
  int bad = !b || ferror(f);
  fclose(f);
  if (bad) {
    fprintf(stderr, "%s: cannot read\n", path);
    free(b);
    return 0;
  }
  /* an exact-size copy, so that ASan sees any read past the input's end */
  uint8_t *exact = malloc(n ? n : 1);
  if (!exact) {
    free(b);
    return 0;
  }
  memcpy(exact, b, n);
  free(b);
  LLVMFuzzerTestOneInput(exact, n);
  free(exact);
  return 1;
}

static int cmp_str(const void *a, const void *b) {
  return strcmp(*(char *const *)a, *(char *const *)b);
}

/* Runs 'path' (a file, or a directory's regular files in name order); returns the number of
 * inputs run, or -1 on an error. */
static long run_path(const char *path) {
  struct stat st;
  if (stat(path, &st) != 0) {
    perror(path);
    return -1;
  }
  if (!S_ISDIR(st.st_mode)) return run_file(path) ? 1 : -1;
  DIR *d = opendir(path);
  if (!d) {
    perror(path);
    return -1;
  }
  char **names = NULL;
  size_t nn = 0, cap = 0;
  struct dirent *e;
  while ((e = readdir(d))) {
    if (e->d_name[0] == '.') continue; /* ".", "..", and hidden files such as .gitkeep */
    if (nn == cap) {
      char **nb = realloc(names, (cap = cap ? 2 * cap : 64) * sizeof *names);
      if (!nb) break;
      names = nb;
    }
    size_t l = strlen(path) + strlen(e->d_name) + 2;
    names[nn] = malloc(l);
    if (!names[nn]) break;
    snprintf(names[nn++], l, "%s/%s", path, e->d_name);
  }
  closedir(d);
  if (nn) qsort(names, nn, sizeof *names, cmp_str);
  long ran = 0;
  for (size_t i = 0; i < nn; i++) {
    struct stat fs;
    if (stat(names[i], &fs) == 0 && S_ISREG(fs.st_mode)) {
      if (!run_file(names[i])) ran = -1;
      else if (ran >= 0) ran++;
    }
    free(names[i]);
  }
  free(names);
  return ran;
}

int main(int argc, char **argv) {
  if (argc < 2) {
    fprintf(stderr, "usage: %s FILE_OR_DIR...\n", argv[0]);
    return 2;
  }
  long total = 0;
  for (int i = 1; i < argc; i++) {
    long n = run_path(argv[i]);
    if (n < 0) return 2;
    printf("%s: %ld input(s)\n", argv[i], n);
    total += n;
  }
  printf("replay: %ld input(s), all checks passed\n", total);
  return 0;
}
