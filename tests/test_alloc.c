/* test_alloc.c: allocation failures, in the style of SQLite's malloc tests. The library's calls
 * to malloc, calloc, realloc, strdup and strndup go through wrappers (the link flags
 * -Wl,--wrap=... in tests/CMakeLists.txt) that make the Nth of them fail. For N = 0, 1, 2, ...
 * the whole pipeline of a small scene runs (parse OBJ + MTL text, solve, checkpoint, resume,
 * leaves, mesh, rendering, the output files) until a run completes without reaching N: every
 * failure must end in a clean error status, never a crash or a wrong success (and, under
 * make test-asan, without a leak). */
#include "hrad.h"
#include "output.h"
#include "report.h"
#include "testutil.h"

#include <string.h>
#include <unistd.h>

/* ---------------------------------------------------------------- the wrappers */

static long fail_at = -1; /* the index of the allocation to fail, -1: none */
static long calls;        /* allocations so far in this run */

void *__real_malloc(size_t n);
void *__real_calloc(size_t n, size_t m);
void *__real_realloc(void *p, size_t n);
char *__real_strdup(const char *s);
char *__real_strndup(const char *s, size_t n);

static int fail_now(void) { return calls++ == fail_at; }

void *__wrap_malloc(size_t n) { return fail_now() ? NULL : __real_malloc(n); }
void *__wrap_calloc(size_t n, size_t m) { return fail_now() ? NULL : __real_calloc(n, m); }
void *__wrap_realloc(void *p, size_t n) { return fail_now() ? NULL : __real_realloc(p, n); }
char *__wrap_strdup(const char *s) { return fail_now() ? NULL : __real_strdup(s); }
char *__wrap_strndup(const char *s, size_t n) { return fail_now() ? NULL : __real_strndup(s, n); }

/* ---------------------------------------------------------------- the pipeline */

static const char obj[] =
    "mtllib box.mtl\n"
    "v 0 0 0\nv 2 0 0\nv 2 2 0\nv 0 2 0\nv 0 0 2\nv 2 0 2\nv 2 2 2\nv 0 2 2\n"
    "v 0.7 1.99 0.7\nv 1.3 1.99 0.7\nv 1.3 1.99 1.3\nv 0.7 1.99 1.3\n"
    "v 0.5 0 0.5\nv 1 0 0.5\nv 1 0.6 0.5\nv 0.5 0.6 0.5\n"
    "usemtl white\n"
    "f 1 2 3 4\nf 5 8 7 6\nf 1 5 6 2\nf 4 3 7 8\nf 1 4 8 5\n"
    "usemtl red\nf 2 6 7 3\n"
    "usemtl light\nf 9 12 11 10\n"
    "usemtl grey\nf 13 14 15 16\n";
static const char mtl[] = "newmtl white\nKd 0.7 0.7 0.7\nnewmtl red\nKd 0.7 0.2 0.1\n"
                          "newmtl grey\nKd 0.4 0.4 0.4\nnewmtl light\nKd 0.5 0.5 0.5\n"
                          "Ke 10 10 10\n";
static char dir[256];

/* Runs everything once; HR_OK when every step succeeded, else the first error. */
static hr_status pipeline(void) {
  hr_err err = {{0}};
  hr_scene *s = NULL;
  hr_solver *sv = NULL, *sv2 = NULL;
  hr_leaf *lv = NULL;
  hr_mesh *m = NULL;
  float *img = NULL;
  int64_t n = 0;
  char path[512];
  hr_options o;
  hr_options_default(&o);
  o.bf_low = 5e-2;
  o.threads = 1;
  hr_status st = hr_scene_parse_obj_mtl(obj, strlen(obj), mtl, strlen(mtl), "box.obj", NULL, &s,
                                        &err);
  if (st == HR_OK) st = hr_solver_create(s, &o, &sv, &err);
  if (st == HR_OK) st = hr_solver_run(sv, NULL, NULL, &err);
  snprintf(path, sizeof path, "%s/state.ckpt", dir);
  if (st == HR_OK) st = hr_solver_checkpoint(sv, path, &err);
  if (st == HR_OK) st = hr_solver_create(s, &o, &sv2, &err);
  if (st == HR_OK) st = hr_solver_resume(sv2, path, &err);
  if (st == HR_OK) st = hr_solver_leaves(sv, &lv, &n);
  if (st == HR_OK) st = hr_mesh_build(s, lv, n, &m);
  if (st == HR_OK) st = (img = malloc(64 * 48 * 3 * sizeof *img)) ? HR_OK : HR_ERR_NOMEM;
  if (st == HR_OK) {
    hr_camera cam;
    hr_scene_auto_camera(s, &cam);
    st = hr_render_ex(s, m, lv, n, &cam, 64, 48, 0, 2, 1, img);
  }
  snprintf(path, sizeof path, "%s/a.png", dir);
  if (st == HR_OK) st = hr_png_write(path, 64, 48, img, 1, &err);
  snprintf(path, sizeof path, "%s/a.ply", dir);
  if (st == HR_OK) st = hr_ply_write(path, m, 1, &err);
  snprintf(path, sizeof path, "%s/a.glb", dir);
  if (st == HR_OK) st = hr_glb_write(path, m, 1, &err);
  snprintf(path, sizeof path, "%s/surfaces.csv", dir);
  if (st == HR_OK) st = hr_report_csv(path, sv, &err);
  snprintf(path, sizeof path, "%s/stats.json", dir);
  if (st == HR_OK) st = hr_report_json(path, sv, &o, &err);
  free(img);
  hr_mesh_destroy(&m);
  free(lv);
  hr_solver_destroy(&sv2);
  hr_solver_destroy(&sv);
  hr_scene_destroy(&s);
  return st;
}

int main(void) {
  snprintf(dir, sizeof dir, "/tmp/hrad_test_alloc_%ld", (long)getpid());
  char cmd[300];
  snprintf(cmd, sizeof cmd, "mkdir -p %s", dir);
  if (system(cmd) != 0) return 2;
  fail_at = -1;
  calls = 0;
  hr_status st = pipeline();
  const long total = calls;
  printf("the pipeline without failures: status %d, %ld allocations\n", (int)st, total);
  CHECK(st == HR_OK && total > 100, "the pipeline fails on its own (%d)", (int)st);
  int clean = 0, succeeded = 0;
  for (long k = 0; k < total; k++) {
    fail_at = k;
    calls = 0;
    st = pipeline();
    if (st == HR_OK)
      succeeded++; /* the failed allocation was one the code recovers from (none expected) */
    else
      clean++;
  }
  fail_at = -1;
  printf("failing allocation k = 0 .. %ld: %d clean errors, %d runs that recovered\n", total - 1,
         clean, succeeded);
  CHECK(clean + succeeded == total, "runs lost");
  snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
  if (system(cmd) != 0) return 2;
  return t_done("test_alloc");
}
