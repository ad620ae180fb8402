/* test_checkpoint.c: saving the solver's state and resuming (src/checkpoint.c). A run stopped
 * after iteration k and resumed from its checkpoint, on another thread count, ends bit-identical
 * to an uninterrupted run, for several k; a checkpoint of another scene, other options or a
 * damaged file is refused with a message. */
#include "solver_impl.h"
#include "testutil.h"

#include <string.h>
#include <unistd.h>

static char path[256];

static hr_scene *scene(double light) {
  hr_scene *s;
  hr_scene_builtin("cornell", &s, NULL);
  double e[3] = {light, light * 0.7, light * 0.2};
  hr_scene_set_emit(s, "light", e, NULL);
  return s;
}

static int g_cluster = HR_CLUSTER_OFF; /* the runs of resume_identical */

static hr_options opts(int threads) {
  hr_options o;
  hr_options_default(&o);
  o.bf_low = 3e-3;
  o.threads = threads;
  o.cluster = g_cluster;
  return o;
}

typedef struct stopper {
  int at;
  hr_status st;
} stopper;

/* Writes the checkpoint after iteration 'at' and stops the run there. */
static int stop_at(void *ud, const hr_solver *s, const hr_iter_info *it) {
  stopper *sp = ud;
  if (it->iter != sp->at) return 0;
  hr_err err;
  sp->st = hr_solver_checkpoint(s, path, &err);
  if (sp->st != HR_OK) fprintf(stderr, "checkpoint: %s\n", err.msg);
  return 1;
}

/* The result to compare: every polygon's radiosity and the counts. */
typedef struct result {
  double b[64][3];
  hr_stats st;
} result;

static void take(const hr_solver *sv, const hr_scene *s, result *r) {
  memset(r, 0, sizeof *r);
  for (int p = 0; p < s->npolys && p < 64; p++) hr_solver_poly_radiosity(sv, p, r->b[p]);
  hr_solver_stats(sv, &r->st);
}

static int same(const result *a, const result *b) {
  return memcmp(a->b, b->b, sizeof a->b) == 0 && a->st.elements == b->st.elements &&
         a->st.links == b->st.links && a->st.iterations == b->st.iterations &&
         a->st.rays == b->st.rays && a->st.converged == b->st.converged;
}

static void resume_identical(void) {
  printf("stop after iteration k, resume on another thread count: bit-identical%s\n",
         g_cluster == HR_CLUSTER_ON ? " (clustering on)" : "");
  hr_scene *s = scene(17);
  hr_options o1 = opts(1), o2 = opts(2);
  result full;
  hr_solver *sv = t_solve(s, &o1);
  take(sv, s, &full);
  hr_solver_destroy(&sv);
  printf("  uninterrupted: %lld elements, %lld links, %d iterations\n",
         (long long)full.st.elements, (long long)full.st.links, full.st.iterations);
  /* the last three: inside the last extrapolation window, with its samples taken (solve.c) */
  const int n = full.st.iterations;
  int ks[] = {1, 2, 5, n / 2, n - 3, n - 2, n - 1};
  for (int i = 0; i < 7; i++) {
    hr_err err;
    stopper sp = {ks[i], HR_ERR_IO};
    CHECK(hr_solver_create(s, &o1, &sv, &err) == HR_OK, "%s", err.msg);
    CHECK(hr_solver_run(sv, stop_at, &sp, &err) == HR_OK, "%s", err.msg);
    CHECK(sp.st == HR_OK, "no checkpoint at iteration %d", ks[i]);
    hr_solver_destroy(&sv);
    CHECK(hr_solver_create(s, &o2, &sv, &err) == HR_OK, "%s", err.msg);
    hr_status st = hr_solver_resume(sv, path, &err);
    CHECK(st == HR_OK, "resume after %d: %s", ks[i], err.msg);
    if (st == HR_OK) CHECK(hr_solver_run(sv, NULL, NULL, &err) == HR_OK, "%s", err.msg);
    result r;
    take(sv, s, &r);
    int ok = same(&r, &full);
    printf("  stopped after %2d, resumed on 2 threads: %s\n", ks[i],
           ok ? "bit-identical" : "DIFFERENT");
    CHECK(ok, "resume after iteration %d differs (%lld elements, %lld links, %d iterations)",
          ks[i], (long long)r.st.elements, (long long)r.st.links, r.st.iterations);
    hr_solver_destroy(&sv);
  }
  hr_scene_destroy(&s);
}

static void refused(void) {
  printf("a checkpoint of another scene, other options or a damaged file is refused\n");
  hr_scene *s = scene(17);
  hr_options o = opts(2);
  hr_err err;
  hr_solver *sv;
  stopper sp = {3, HR_ERR_IO};
  hr_solver_create(s, &o, &sv, &err);
  hr_solver_run(sv, stop_at, &sp, &err);
  hr_solver_destroy(&sv);
  /* another scene: a different light */
  hr_scene *s2 = scene(20);
  hr_solver_create(s2, &o, &sv, &err);
  hr_status st = hr_solver_resume(sv, path, &err);
  printf("  other scene: %s\n", err.msg);
  CHECK(st == HR_ERR_INVALID && strstr(err.msg, "another scene"), "status %d: %s", st, err.msg);
  hr_solver_destroy(&sv);
  hr_scene_destroy(&s2);
  /* other options */
  hr_options o2 = o;
  o2.seed = 2;
  hr_solver_create(s, &o2, &sv, &err);
  st = hr_solver_resume(sv, path, &err);
  printf("  other options: %s\n", err.msg);
  CHECK(st == HR_ERR_INVALID && strstr(err.msg, "options"), "status %d: %s", st, err.msg);
  hr_solver_destroy(&sv);
  /* with clustering where the checkpoint had none */
  o2 = o;
  o2.cluster = HR_CLUSTER_ON;
  hr_solver_create(s, &o2, &sv, &err);
  st = hr_solver_resume(sv, path, &err);
  printf("  clustering on: %s\n", err.msg);
  CHECK(st == HR_ERR_INVALID && strstr(err.msg, "options"), "status %d: %s", st, err.msg);
  hr_solver_destroy(&sv);
  /* truncated, and one flipped byte */
  FILE *f = fopen(path, "rb");
  fseek(f, 0, SEEK_END);
  long len = ftell(f);
  fseek(f, 0, SEEK_SET);
  unsigned char *buf = malloc((size_t)len);
  CHECK(fread(buf, 1, (size_t)len, f) == (size_t)len, "read");
  fclose(f);
  for (int mode = 0; mode < 2; mode++) {
    f = fopen(path, "wb");
    if (mode == 1) buf[len / 2] ^= 0x10;
    fwrite(buf, 1, mode == 0 ? (size_t)len - 100 : (size_t)len, f);
    fclose(f);
    hr_solver_create(s, &o, &sv, &err);
    st = hr_solver_resume(sv, path, &err);
    printf("  %s: %s\n", mode == 0 ? "truncated" : "one byte flipped", err.msg);
    CHECK(st == HR_ERR_PARSE, "damaged file: status %d: %s", st, err.msg);
    hr_solver_destroy(&sv);
  }
  free(buf);
  hr_scene_destroy(&s);
}

int main(void) {
  snprintf(path, sizeof path, "/tmp/hrad_test_checkpoint_%ld.ckpt", (long)getpid());
  resume_identical();
  g_cluster = HR_CLUSTER_ON; /* the cluster links and their order go into the file too */
  resume_identical();
  g_cluster = HR_CLUSTER_OFF;
  refused();
  unlink(path);
  return t_done("test_checkpoint");
}
