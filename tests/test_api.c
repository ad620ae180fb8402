/* test_api.c: the public API a program that links libhrad uses beyond loading and solving
 * (hrad.h): the per-polygon material accessor, the progress callback's plumbing, the public
 * writers (PNG, PLY, GLB, CSV, JSON) on a solved Cornell box, and their errors. */
#include "testutil.h"

#include <stdint.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

/* ------------------------------------------------------------------ materials */

static void test_poly_material(const hr_scene *s) {
  int checked = 0;
  for (int p = 0; p < s->npolys; p++) {
    int m = hr_scene_poly_material(s, p);
    CHECK(m >= 0 && m < s->nmats && s->mats[m].base == m, "polygon %d: material %d", p, m);
    for (int i = 0; i < s->nsurfs; i++)
      if (s->surfs[i].poly == p) {
        CHECK(s->mats[s->surfs[i].material].base == m, "polygon %d: material %d, surface %d has %d",
              p, m, i, s->surfs[i].material);
        checked++;
      }
  }
  CHECK(checked == s->nsurfs, "%d of %d surfaces checked", checked, s->nsurfs);
  CHECK(hr_scene_poly_material(s, -1) == -1, "poly -1");
  CHECK(hr_scene_poly_material(s, s->npolys) == -1, "poly npolys");
  /* the Cornell box's light is the one emitting material */
  int nemit = 0;
  for (int p = 0; p < s->npolys; p++) nemit += s->mats[hr_scene_poly_material(s, p)].emit[0] > 0;
  CHECK(nemit == 1, "%d emitting polygons in the Cornell box", nemit);
  printf("poly_material: %d polygons, %d surfaces\n", s->npolys, checked);
}

/* ------------------------------------------------------------------ progress */

typedef struct {
  int calls;
  hr_phase phase;
  double fraction;
} progress_log;

static void on_progress(void *ud, hr_phase phase, double fraction) {
  progress_log *l = ud;
  l->calls++;
  l->phase = phase;
  l->fraction = fraction;
}

static void test_progress(hr_solver *a, hr_solver *b) {
  progress_log la = {0}, lb = {0};
  CHECK(hr_solver_set_progress(a, on_progress, &la) == HR_OK, "set a");
  CHECK(hr_solver_set_progress(b, on_progress, &lb) == HR_OK, "set b");
  hr_solver_progress_report(a, HR_PHASE_LINK, 0.25);
  CHECK(la.calls == 1 && la.phase == HR_PHASE_LINK && la.fraction == 0.25 && lb.calls == 0,
        "a: %d calls, phase %d, fraction %g; b: %d calls", la.calls, la.phase, la.fraction,
        lb.calls);
  hr_solver_progress_report(b, HR_PHASE_SOLVE, 1.5); /* clamped */
  CHECK(lb.calls == 1 && lb.phase == HR_PHASE_SOLVE && lb.fraction == 1, "b: %d %d %g", lb.calls,
        lb.phase, lb.fraction);
  hr_solver_progress_report(b, HR_PHASE_SOLVE, NAN);
  CHECK(lb.calls == 2 && lb.fraction == 0, "NaN fraction: %g", lb.fraction);
  CHECK(hr_solver_set_progress(a, NULL, NULL) == HR_OK, "clear a");
  hr_solver_progress_report(a, HR_PHASE_SOLVE, 0.5);
  CHECK(la.calls == 1, "a called after its callback was removed");
  CHECK(hr_solver_set_progress(b, NULL, NULL) == HR_OK, "clear b");
  CHECK(hr_solver_set_progress(NULL, on_progress, NULL) == HR_ERR_INVALID, "NULL solver");
}

/* The solve's reports on a run of one level of BF_e (the defaults): the share moves before the
 * end (it stayed at 0 until the last iteration before the convergence share), never falls, and
 * ends at 1. The callback sleeps past the solver's 0.1 s between reports, so every iteration
 * reports. */
typedef struct {
  int n;
  double f[256];
} progress_trace;

static void on_progress_trace(void *ud, hr_phase phase, double fraction) {
  progress_trace *l = ud;
  if (phase != HR_PHASE_SOLVE || l->n == 256) return;
  l->f[l->n++] = fraction;
  nanosleep(&(struct timespec){0, 110000000}, NULL);
}

static void test_progress_run(hr_solver *s) {
  progress_trace l = {0};
  hr_err err = {{0}};
  CHECK(hr_solver_set_progress(s, on_progress_trace, &l) == HR_OK, "set");
  CHECK(hr_solver_run(s, NULL, NULL, &err) == HR_OK, "run: %s", err.msg);
  CHECK(hr_solver_set_progress(s, NULL, NULL) == HR_OK, "clear");
  int up = 1, mid = 0;
  for (int i = 0; i < l.n; i++) {
    up &= i == 0 || l.f[i] >= l.f[i - 1];
    mid += l.f[i] >= 0.2 && l.f[i] < 1;
  }
  CHECK(l.n >= 3 && up && mid > 0 && l.f[l.n - 1] == 1,
        "solve progress: %d reports, increasing %d, %d between 0.2 and 1, last %g", l.n, up, mid,
        l.n ? l.f[l.n - 1] : -1);
  printf("solve progress: %d reports:", l.n);
  for (int i = 0; i < l.n; i++) printf(" %.2f", l.f[i]);
  printf("\n");
}

/* ------------------------------------------------------------------ writers */

static unsigned char *slurp(const char *path, size_t *n) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  fseek(f, 0, SEEK_END);
  long len = ftell(f);
  fseek(f, 0, SEEK_SET);
  unsigned char *b = malloc((size_t)len + 1);
  if (b && fread(b, 1, (size_t)len, f) != (size_t)len) len = 0;
  if (b) b[len] = 0;
  fclose(f);
  *n = (size_t)len;
  return b;
}

static uint32_t be32(const unsigned char *p) {
  return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
}

static void test_png(const hr_solver *s, const char *dir) {
  char path[512];
  hr_err err = {{0}};
  hr_image_options o;
  hr_image_options_default(&o);
  CHECK(o.width == 800 && o.height == 600 && !o.camera && o.exposure == 0 && !o.elements,
        "defaults");
  o.width = 64, o.height = 48;
  snprintf(path, sizeof path, "%s/x.png", dir);
  CHECK(hr_solver_write_png(s, path, &o, &err) == HR_OK, "png: %s", err.msg);
  size_t n;
  unsigned char *b = slurp(path, &n);
  CHECK(b && n > 33 && !memcmp(b, "\x89PNG\r\n\x1a\n", 8) && !memcmp(b + 12, "IHDR", 4) &&
            be32(b + 16) == 64 && be32(b + 20) == 48,
        "%s: not a 64x48 PNG (%zu bytes)", path, n);
  free(b);
  o.elements = 1;
  snprintf(path, sizeof path, "%s/x-elements.png", dir);
  CHECK(hr_solver_write_png(s, path, &o, &err) == HR_OK, "elements png: %s", err.msg);
  o.width = 8;
  snprintf(path, sizeof path, "%s/small.png", dir);
  CHECK(hr_solver_write_png(s, path, &o, &err) == HR_ERR_INVALID && strstr(err.msg, "8x48") &&
            access(path, F_OK) != 0,
        "8x48 image: %s", err.msg);
  snprintf(path, sizeof path, "%s/no/such/dir/x.png", dir);
  CHECK(hr_solver_write_png(s, path, NULL, &err) == HR_ERR_IO && strstr(err.msg, path),
        "unwritable png: %s", err.msg);
}

static void test_meshes(const hr_solver *s, const char *dir) {
  char path[512];
  hr_err err = {{0}};
  double ex = 0;
  CHECK(hr_solver_exposure(s, &ex, &err) == HR_OK && ex > 0 && isfinite(ex), "exposure %g", ex);
  snprintf(path, sizeof path, "%s/x.ply", dir);
  CHECK(hr_solver_write_ply(s, path, 0, &err) == HR_OK, "ply: %s", err.msg);
  size_t n;
  unsigned char *b = slurp(path, &n);
  char want[64];
  snprintf(want, sizeof want, "comment exposure %.17g", ex);
  long nv = 0;
  const char *v = b ? strstr((char *)b, "element vertex ") : NULL;
  if (v) nv = strtol(v + 15, NULL, 10);
  CHECK(b && !strncmp((char *)b, "ply\nformat binary_little_endian 1.0\n", 36) && nv > 100 &&
            strstr((char *)b, "property float radiosity_r") && strstr((char *)b, want),
        "%s: bad PLY header (%ld vertices)", path, nv);
  printf("ply: %ld vertices, automatic exposure %g\n", nv, ex);
  free(b);
  snprintf(path, sizeof path, "%s/x.glb", dir);
  CHECK(hr_solver_write_glb(s, path, 2.5, &err) == HR_OK, "glb: %s", err.msg);
  b = slurp(path, &n);
  CHECK(b && n > 20 && !memcmp(b, "glTF", 4) && b[4] == 2 &&
            (b[8] | b[9] << 8 | b[10] << 16 | (uint32_t)b[11] << 24) == n,
        "%s: bad GLB header (%zu bytes)", path, n);
  CHECK(b && n > 20 && memmem(b, n, "\"exposure\":2.5", 14), "%s: exposure 2.5 not recorded",
        path);
  free(b);
  snprintf(path, sizeof path, "%s/no/such/dir/x.glb", dir);
  CHECK(hr_solver_write_glb(s, path, 0, &err) == HR_ERR_IO && strstr(err.msg, path),
        "unwritable glb: %s", err.msg);
}

static void test_tables(const hr_solver *s, const hr_options *o, const char *dir) {
  char path[512];
  hr_err err = {{0}};
  const hr_scene *sc = hr_solver_scene(s);
  snprintf(path, sizeof path, "%s/surfaces.csv", dir);
  CHECK(hr_solver_write_csv(s, path, &err) == HR_OK, "csv: %s", err.msg);
  FILE *f = fopen(path, "r");
  char line[512];
  int rows = 0, same = 0;
  if (f && fgets(line, sizeof line, f)) {
    CHECK(!strcmp(line, "id,area,r,g,b,status\n"), "csv header '%s'", line);
    int id;
    double area, r, g, bl;
    while (fgets(line, sizeof line, f) && sscanf(line, "%d,%lg,%lg,%lg,%lg", &id, &area, &r, &g,
                                                   &bl) == 5) {
      double want[3];
      hr_solver_poly_radiosity(s, sc->inputs[id].poly, want);
      same += id == rows && fabs(r - want[0]) <= 1e-6 * fabs(want[0]) &&
              fabs(bl - want[2]) <= 1e-6 * fabs(want[2]);
      rows++;
    }
  }
  if (f) fclose(f);
  CHECK(rows == sc->ninputs && same == rows, "csv: %d rows (%d agree with the solver), want %d",
        rows, same, sc->ninputs);
  snprintf(path, sizeof path, "%s/stats.json", dir);
  CHECK(hr_solver_write_json(s, o, path, &err) == HR_OK, "json: %s", err.msg);
  size_t n;
  unsigned char *b = slurp(path, &n);
  hr_stats st;
  hr_solver_stats(s, &st);
  char want[64];
  snprintf(want, sizeof want, "\"elements\": %lld", (long long)st.elements);
  CHECK(b && strstr((char *)b, want), "stats.json lacks %s", want);
  free(b);
  CHECK(hr_solver_write_json(s, NULL, path, &err) == HR_ERR_INVALID, "json without options");
}

int main(void) {
  char dir[] = "/tmp/hrad-test-api-XXXXXX";
  if (!mkdtemp(dir)) return 1;
  hr_err err = {{0}};
  hr_scene *sc = NULL;
  if (hr_scene_builtin("cornell", &sc, &err) != HR_OK) return fprintf(stderr, "%s\n", err.msg), 1;
  test_poly_material(sc);
  hr_options o;
  hr_options_default(&o);
  o.bf_low = 1e-2; /* coarse: the writers' plumbing is tested here, not the light */
  hr_solver *s = NULL, *s2 = NULL;
  CHECK(hr_solver_create(sc, &o, &s, &err) == HR_OK, "create: %s", err.msg);
  CHECK(hr_solver_create(sc, &o, &s2, &err) == HR_OK, "create: %s", err.msg);
  test_progress(s, s2);
  test_progress_run(s2);
  CHECK(hr_solver_run(s, NULL, NULL, &err) == HR_OK, "run: %s", err.msg);
  test_png(s, dir);
  test_meshes(s, dir);
  test_tables(s, &o, dir);
  hr_solver_destroy(&s2);
  hr_solver_destroy(&s);
  hr_scene_destroy(&sc);
  if (!t_failures) {
    char cmd[600];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    if (system(cmd) != 0) return 1;
  }
  return t_done("test_api");
}
