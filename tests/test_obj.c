/* test_obj.c: tests of the OBJ/MTL loader (src/obj.c): geometry and materials of small scenes
 * written to a temporary directory or parsed from memory, every index form, CRLF, names with
 * blanks, polygon splitting, warnings and the exact "PATH:LINE:" of errors, and the two
 * third-party scenes in ../shared/scenes checked against numbers derived independently. */
#include "hrad.h"

#include <png.h>

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

static int failures = 0;

#define CHECK(cond, ...)                                              \
  do {                                                                \
    if (!(cond)) {                                                    \
      failures++;                                                     \
      fprintf(stderr, "FAIL %s:%d: %s: ", __FILE__, __LINE__, #cond); \
      fprintf(stderr, __VA_ARGS__);                                   \
      fputc('\n', stderr);                                            \
    }                                                                 \
  } while (0)

#define NEAR(a, b, tol) (fabs((a) - (b)) <= (tol))

/* ---------------------------------------------------------------- helpers */

#define MAX_MSGS 64
typedef struct logcap {
  int n;      /* all warnings */
  int ndegen; /* warnings about degenerate polygons */
  char msg[MAX_MSGS][512];
} logcap;

static void cap_fn(void *ud, const char *msg) {
  logcap *c = ud;
  if (strstr(msg, "degenerate polygon skipped")) c->ndegen++;
  if (c->n < MAX_MSGS) snprintf(c->msg[c->n], sizeof c->msg[0], "%s", msg);
  c->n++;
  if (strchr(msg, '\n')) {
    failures++;
    fprintf(stderr, "FAIL: warning contains a newline: %s\n", msg);
  }
}

/* Number of captured warnings containing 'needle'. */
static int count_msgs(const logcap *c, const char *needle) {
  int k = 0;
  for (int i = 0; i < c->n && i < MAX_MSGS; i++)
    if (strstr(c->msg[i], needle)) k++;
  return k;
}

static char tmpdir[256];

/* Writes 'text' to tmpdir/name; returns the path in a static rotating buffer. */
static const char *write_file(const char *name, const char *text) {
  static char paths[8][512];
  static int slot = 0;
  char *p = paths[slot++ % 8];
  snprintf(p, 512, "%s/%s", tmpdir, name);
  FILE *f = fopen(p, "wb");
  if (!f) {
    fprintf(stderr, "cannot write %s\n", p);
    exit(2);
  }
  fputs(text, f);
  fclose(f);
  return p;
}

static void remove_tmpdir(void) {
  char cmd[600];
  snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmpdir);
  if (system(cmd) != 0) fprintf(stderr, "warning: could not remove %s\n", tmpdir);
}

/* Writes 'text' to tmpdir/name and loads it. */
static hr_status load_text(const char *name, const char *text, logcap *lc, hr_scene **s,
                           hr_err *err) {
  const char *path = write_file(name, text);
  hr_log log = {cap_fn, lc};
  memset(err, 0, sizeof *err);
  return hr_scene_load_obj(path, &log, s, err);
}

static int vec_eq(hr_vec3 a, hr_vec3 b) { return a.x == b.x && a.y == b.y && a.z == b.z; }

/* 1 if the two scenes have exactly the same surfaces, polygons and material names/values. */
static int same_geometry(const hr_scene *a, const hr_scene *b) {
  if (a->nsurfs != b->nsurfs || a->npolys != b->npolys || a->nmats != b->nmats) return 0;
  for (int i = 0; i < a->nsurfs; i++) {
    const hr_surface *p = &a->surfs[i], *q = &b->surfs[i];
    if (p->nverts != q->nverts || p->area != q->area || p->material != q->material ||
        p->poly != q->poly || !vec_eq(p->normal, q->normal))
      return 0;
    for (int k = 0; k < p->nverts; k++)
      if (!vec_eq(p->v[k], q->v[k])) return 0;
  }
  for (int i = 0; i < a->npolys; i++)
    if (a->poly_area[i] != b->poly_area[i]) return 0;
  for (int i = 0; i < a->nmats; i++) {
    if (strcmp(a->mats[i].name, b->mats[i].name) != 0) return 0;
    for (int k = 0; k < 3; k++)
      if (a->mats[i].rho[k] != b->mats[i].rho[k] || a->mats[i].emit[k] != b->mats[i].emit[k])
        return 0;
  }
  return 1;
}

/* Converts LF to CRLF into a fresh string. */
static char *to_crlf(const char *s) {
  size_t n = strlen(s), k = 0;
  char *r = malloc(2 * n + 1);
  for (size_t i = 0; i < n; i++) {
    if (s[i] == '\n') r[k++] = '\r';
    r[k++] = s[i];
  }
  r[k] = '\0';
  return r;
}

static char *read_all(const char *path, size_t *len) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  size_t cap = 1 << 20, n = 0, got;
  char *b = malloc(cap);
  while ((got = fread(b + n, 1, cap - n - 1, f)) > 0) {
    n += got;
    if (cap - n - 1 == 0) b = realloc(b, cap *= 2);
  }
  fclose(f);
  b[n] = '\0';
  if (len) *len = n;
  return b;
}

/* ---------------------------------------------------------------- small scenes */

static const char QUAD_MTL[] =
    "# lamp\n"
    "newmtl lamp\n"
    "Ka 0.1 0.1 0.1\n"
    "Kd 0.25 0.5 0.75\n"
    "Ke 1 2 3\n"
    "illum 2\n";

static void test_unit_quad(void) {
  write_file("quad.mtl", QUAD_MTL);
  logcap lc = {0};
  hr_err err;
  hr_scene *s = NULL;
  hr_status st = load_text("quad.obj",
                           "mtllib quad.mtl\n"
                           "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                           "usemtl lamp\n"
                           "f 1 2 3 4\n",
                           &lc, &s, &err);
  CHECK(st == HR_OK, "status %d: %s", st, err.msg);
  if (!s) return;
  CHECK(strcmp(s->name, "quad") == 0, "name '%s'", s->name);
  CHECK(lc.n == 0, "%d warnings, first: %s", lc.n, lc.msg[0]);
  CHECK(s->nsurfs == 1 && s->npolys == 1, "nsurfs %d npolys %d", s->nsurfs, s->npolys);
  CHECK(s->nmats == 1, "nmats %d", s->nmats);
  if (s->nsurfs == 1 && s->nmats == 1) {
    const hr_surface *f = &s->surfs[0];
    const hr_material *m = &s->mats[f->material];
    CHECK(f->nverts == 4, "nverts %d", f->nverts);
    CHECK(NEAR(f->area, 1.0, 1e-12), "area %g", f->area);
    CHECK(NEAR(s->poly_area[0], 1.0, 1e-12), "poly_area %g", s->poly_area[0]);
    CHECK(NEAR(f->normal.x, 0, 1e-12) && NEAR(f->normal.y, 0, 1e-12) && NEAR(f->normal.z, 1, 1e-12),
          "normal %g %g %g", f->normal.x, f->normal.y, f->normal.z);
    CHECK(strcmp(m->name, "lamp") == 0, "material '%s'", m->name);
    CHECK(m->rho[0] == 0.25 && m->rho[1] == 0.5 && m->rho[2] == 0.75, "rho %g %g %g", m->rho[0],
          m->rho[1], m->rho[2]);
    CHECK(m->emit[0] == 1 && m->emit[1] == 2 && m->emit[2] == 3, "emit %g %g %g", m->emit[0],
          m->emit[1], m->emit[2]);
    CHECK(hr_scene_max_emit(s) == 3, "max emit %g", hr_scene_max_emit(s));
  }
  hr_scene_destroy(&s);

  /* clockwise order seen from +z: the front faces -z */
  st = load_text("quad_cw.obj",
                 "mtllib quad.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nusemtl lamp\nf 4 3 2 1\n",
                 &lc, &s, &err);
  CHECK(st == HR_OK, "status %d: %s", st, err.msg);
  if (s) {
    CHECK(s->nsurfs == 1 && NEAR(s->surfs[0].normal.z, -1, 1e-12), "cw normal z %g",
          s->nsurfs ? s->surfs[0].normal.z : 0);
    CHECK(strcmp(s->name, "quad_cw") == 0, "name '%s'", s->name);
  }
  hr_scene_destroy(&s);
}

/* The same two faces (a quad and a triangle) written with every index form. */
static const char *const FORMS[] = {
    "f 1 2 3 4\nf 2 5 3\n",
    "f 1/1 2/2 3/3 4/4\nf 2/2 5/1 3/3\n",
    "f 1//1 2//1 3//1 4//1\nf 2//1 5//1 3//1\n",
    "f 1/1/1 2/2/1 3/3/1 4/4/1\nf 2/2/1 5/1/1 3/3/1\n",
    "f -5 -4 -3 -2\nf -4 -1 -3\n",
    "f -5/-4/-1 -4/-3/-1 -3/-2/-1 -2/-1/-1\nf -4//-1 -1//-1 -3//-1\n",
    "f\t1   2\t3 4 # a comment\n  f 2 5 3  \n",
    "f 1 2 \\\n  3 4\nf 2 5 3\n", /* line continuation */
};

static void test_index_forms(void) {
  const char *head =
      "# header\n"
      "mtllib quad.mtl\n"
      "o thing\n"
      "g group one\n"
      "s 1\n"
      "v 0 0 0\nv 2 0 0\nv 2 1 0 1.0\nv 0 1 0\nv 3 0.5 0\n"
      "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
      "vn 0 0 1\n"
      "usemtl lamp\n"
      "l 1 2\np 3\n";
  write_file("quad.mtl", QUAD_MTL);
  hr_scene *ref = NULL;
  int nforms = (int)(sizeof FORMS / sizeof FORMS[0]);
  for (int i = 0; i < nforms; i++) {
    char text[2048];
    snprintf(text, sizeof text, "%s%s", head, FORMS[i]);
    logcap lc = {0};
    hr_err err;
    hr_scene *s = NULL;
    hr_status st = load_text("forms.obj", text, &lc, &s, &err);
    CHECK(st == HR_OK, "form %d: status %d: %s", i, st, err.msg);
    CHECK(lc.n == 0, "form %d: %d warnings, first: %s", i, lc.n, lc.msg[0]);
    if (!s) continue;
    if (i == 0) {
      CHECK(s->nsurfs == 2 && s->npolys == 2, "nsurfs %d npolys %d", s->nsurfs, s->npolys);
      CHECK(NEAR(hr_scene_total_area(s), 2.0 + 0.5, 1e-12), "area %g", hr_scene_total_area(s));
      ref = s;
      continue;
    }
    CHECK(same_geometry(ref, s), "form %d differs from plain indices", i);

    /* CRLF version parsed from memory equals the LF version parsed from memory */
    char *crlf = to_crlf(text);
    hr_scene *a = NULL, *b = NULL;
    char mpath[600];
    snprintf(mpath, sizeof mpath, "%s/forms.obj", tmpdir);
    hr_status sa = hr_scene_parse_obj(text, strlen(text), mpath, NULL, &a, &err);
    hr_status sb = hr_scene_parse_obj(crlf, strlen(crlf), mpath, NULL, &b, &err);
    CHECK(sa == HR_OK && sb == HR_OK, "form %d: memory parse %d %d: %s", i, sa, sb, err.msg);
    if (a && b) CHECK(same_geometry(a, b) && same_geometry(ref, b), "form %d: CRLF differs", i);
    hr_scene_destroy(&a);
    hr_scene_destroy(&b);
    free(crlf);
    hr_scene_destroy(&s);
  }
  hr_scene_destroy(&ref);
}

static void test_names_with_blanks(void) {
  write_file("my lib.mtl",
             "newmtl Material #0\n"
             "Kd 0.2\n"
             "newmtl plain\r\n"
             "Kd 0.1 0.2 0.3 # comment after numbers\r\n"
             "Ke 4\r\n");
  write_file("second.mtl", "newmtl second\nKd 0.9 0.8 0.7\n");
  logcap lc = {0};
  hr_err err;
  hr_scene *s = NULL;
  hr_status st = load_text("names.obj",
                           "mtllib my lib.mtl  \n"
                           "mtllib second.mtl missing.mtl\n"
                           "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n"
                           "usemtl   Material #0  \n"
                           "f 1 2 3\n"
                           "usemtl plain\n"
                           "f 2 4 3\n"
                           "usemtl second\n"
                           "f 1 2 4\n",
                           &lc, &s, &err);
  CHECK(st == HR_OK, "status %d: %s", st, err.msg);
  CHECK(lc.n == 1 && count_msgs(&lc, "names.obj:2: cannot open material library 'missing.mtl'"),
        "%d warnings, first: %s", lc.n, lc.msg[0]);
  if (!s) return;
  CHECK(s->nmats == 3, "nmats %d", s->nmats);
  int m0 = hr_scene_find_material(s, "Material #0");
  int m1 = hr_scene_find_material(s, "plain");
  int m2 = hr_scene_find_material(s, "second");
  CHECK(m0 >= 0 && m1 >= 0 && m2 >= 0, "materials %d %d %d", m0, m1, m2);
  if (m0 >= 0 && m1 >= 0 && m2 >= 0 && s->nsurfs == 3) {
    CHECK(s->surfs[0].material == m0 && s->surfs[1].material == m1 && s->surfs[2].material == m2,
          "surface materials %d %d %d", s->surfs[0].material, s->surfs[1].material,
          s->surfs[2].material);
    CHECK(s->mats[m0].rho[0] == 0.2 && s->mats[m0].rho[1] == 0.2 && s->mats[m0].rho[2] == 0.2,
          "grey Kd %g", s->mats[m0].rho[1]);
    CHECK(s->mats[m1].rho[2] == 0.3 && s->mats[m1].emit[0] == 4 && s->mats[m1].emit[2] == 4,
          "plain %g %g", s->mats[m1].rho[2], s->mats[m1].emit[2]);
    CHECK(s->mats[m2].rho[0] == 0.9 && s->mats[m2].emit[0] == 0, "second %g", s->mats[m2].rho[0]);
  }
  hr_scene_destroy(&s);

  /* a missing library whose name has blanks is reported once, by its whole name; a UTF-8 BOM
   * before the first statement is skipped */
  lc = (logcap){0};
  st = load_text("names2.obj",
                 "\xEF\xBB\xBFmtllib no such lib.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", &lc,
                 &s, &err);
  CHECK(st == HR_OK && s && s->npolys == 1, "status %d: %s", st, err.msg);
  CHECK(lc.n == 1 && count_msgs(&lc,
                                "names2.obj:1: cannot open material library 'no such "
                                "lib.mtl'; using grey default") == 1,
        "%d warnings, first: %s", lc.n, lc.msg[0]);
  hr_scene_destroy(&s);
}

static void test_pentagon_and_nonplanar_quad(void) {
  /* regular pentagon, circumradius 1, in the plane z = 2 */
  char text[1024];
  int k = 0;
  for (int i = 0; i < 5; i++) {
    double a = 2 * M_PI * i / 5;
    k += snprintf(text + k, sizeof text - (size_t)k, "v %.17g %.17g 2\n", cos(a), sin(a));
  }
  snprintf(text + k, sizeof text - (size_t)k, "f 1 2 3 4 5\n");
  logcap lc = {0};
  hr_err err;
  hr_scene *s = NULL;
  hr_status st = load_text("penta.obj", text, &lc, &s, &err);
  CHECK(st == HR_OK, "status %d: %s", st, err.msg);
  if (s) {
    double want = 2.5 * sin(2 * M_PI / 5); /* 5 * (1/2) R^2 sin(72 deg) */
    CHECK(s->nsurfs == 3 && s->npolys == 1, "nsurfs %d npolys %d", s->nsurfs, s->npolys);
    CHECK(NEAR(s->poly_area[0], want, 1e-12), "poly_area %.15g want %.15g", s->poly_area[0], want);
    CHECK(NEAR(hr_scene_total_area(s), want, 1e-12), "total %.15g", hr_scene_total_area(s));
    for (int i = 0; i < s->nsurfs; i++) {
      CHECK(s->surfs[i].nverts == 3 && s->surfs[i].poly == 0, "surf %d", i);
      CHECK(NEAR(s->surfs[i].normal.z, 1, 1e-12), "surf %d normal z %g", i, s->surfs[i].normal.z);
    }
    /* no usemtl: the grey "default" material */
    CHECK(s->nmats == 1 && strcmp(s->mats[0].name, "default") == 0 && s->mats[0].rho[1] == 0.5 &&
              s->mats[0].emit[0] == 0,
          "default material");
  }
  hr_scene_destroy(&s);

  /* non-planar quad: one corner lifted */
  st = load_text("bent.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0.3\nv 0 1 0\nf 1 2 3 4\n", &lc, &s, &err);
  CHECK(st == HR_OK, "status %d: %s", st, err.msg);
  if (s) {
    CHECK(s->nsurfs == 2 && s->npolys == 1, "nsurfs %d npolys %d", s->nsurfs, s->npolys);
    CHECK(s->nsurfs == 2 && s->surfs[0].nverts == 3 && s->surfs[1].nverts == 3 &&
              s->surfs[0].poly == 0 && s->surfs[1].poly == 0,
          "two triangles of poly 0");
    /* diagonal 0-2: two triangles with normals ~(0,-0.3,1), (-0.3,0,1): sqrt(1.09) in all;
     * diagonal 1-3: flat (0,0,0),(1,0,0),(0,1,0) = 1/2 plus (1,0,0),(1,1,.3),(0,1,0) whose
     * cross product is (-0.3,-0.3,1): 1/2 + sqrt(1.18)/2 */
    double d02 = sqrt(1.09), d13 = 0.5 + 0.5 * sqrt(1.18), sum = 0;
    for (int i = 0; i < s->nsurfs; i++) sum += s->surfs[i].area;
    CHECK(NEAR(s->poly_area[0], d02, 1e-12) || NEAR(s->poly_area[0], d13, 1e-12),
          "poly_area %.15g want %.15g or %.15g", s->poly_area[0], d02, d13);
    CHECK(NEAR(sum, s->poly_area[0], 1e-12), "surface sum %.15g", sum);
  }
  hr_scene_destroy(&s);
}

static void test_degenerate(void) {
  logcap lc = {0};
  hr_err err;
  hr_scene *s = NULL;
  hr_status st = load_text("degen.obj",
                           "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\n"
                           "f 1 2 4\n"
                           "# next face is collinear\n"
                           "f 1 2 3\n"
                           "f 2 3 4\n",
                           &lc, &s, &err);
  CHECK(st == HR_OK, "status %d: %s", st, err.msg);
  CHECK(lc.n == 1 && lc.ndegen == 1, "%d warnings, %d degenerate", lc.n, lc.ndegen);
  CHECK(count_msgs(&lc, "degen.obj:7: degenerate polygon skipped") == 1, "message '%s'", lc.msg[0]);
  if (s) {
    CHECK(s->npolys == 2 && s->nsurfs == 2, "npolys %d nsurfs %d", s->npolys, s->nsurfs);
    /* the skipped face keeps its row (surfaces.csv: area 0, status degenerate) */
    CHECK(s->ninputs == 3 && s->inputs[1].kind == HR_INPUT_DEGENERATE && s->inputs[1].poly == -1 &&
              s->inputs[2].poly == 1,
          "%d input rows; row 1 kind %d poly %d", s->ninputs, s->ninputs > 1 ? (int)s->inputs[1].kind : -1,
          s->ninputs > 1 ? s->inputs[1].poly : -9);
  }
  hr_scene_destroy(&s);

  /* only degenerate faces: no polygons */
  lc = (logcap){0};
  st = load_text("alldegen.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", &lc, &s, &err);
  char want[600];
  snprintf(want, sizeof want, "%s/alldegen.obj: no polygons", tmpdir);
  CHECK(st == HR_ERR_PARSE && s == NULL && strcmp(err.msg, want) == 0, "status %d: %s", st,
        err.msg);
  CHECK(lc.ndegen == 1, "%d degenerate warnings", lc.ndegen);
}

/* Found by fuzzing (tests/fuzz/crashes/obj): faces so small that the squares in the area and
 * normal computation underflow (extent near 1e-80 gave a normal of length 1.0000056) are
 * degenerate below an extent of 1e-30; coordinates up to 1e12 in magnitude are accepted. */
static void test_range(void) {
  logcap lc = {0};
  hr_log log = {cap_fn, &lc};
  hr_err err;
  hr_scene *s = NULL;
  const char *tiny =
      "v 1e-80 0 0\nv 0 1e-80 0\nv 0 0 0\nf 1 2 3\n"  /* 4: skipped */
      "v 1e-29 0 0\nv 0 1e-29 0\nf 3 4 5\n"            /* 7: kept, area 5e-59 */
      "v 1 0 0\nv 0 1 0\nf 3 6 7\n";                   /* 10: kept */
  hr_status st = hr_scene_parse_obj(tiny, strlen(tiny), "tiny.obj", &log, &s, &err);
  CHECK(st == HR_OK, "tiny: status %d: %s", st, err.msg);
  CHECK(lc.n == 1 && lc.ndegen == 1 &&
            count_msgs(&lc, "tiny.obj:4: degenerate polygon skipped (extent 1e-80 below 1e-30)") ==
                1,
        "tiny: %d warnings, first: %s", lc.n, lc.msg[0]);
  if (s) {
    CHECK(s->npolys == 2 && s->nsurfs == 2 && s->ninputs == 3, "tiny: npolys %d nsurfs %d",
          s->npolys, s->nsurfs);
    CHECK(s->ninputs == 3 && s->inputs[0].kind == HR_INPUT_DEGENERATE && s->inputs[0].poly == -1 &&
              s->inputs[1].kind == HR_INPUT_SOLVED && s->inputs[1].poly == 0,
          "tiny: input rows");
    for (int i = 0; i < s->nsurfs; i++) {
      const hr_surface *f = &s->surfs[i];
      double nl = sqrt(f->normal.x * f->normal.x + f->normal.y * f->normal.y +
                       f->normal.z * f->normal.z);
      CHECK(fabs(nl - 1) <= 1e-12 && f->area > 0, "tiny: surface %d normal length %.17g area %g",
            i, nl, f->area);
    }
    if (s->nsurfs == 2) CHECK(NEAR(s->surfs[0].area, 5e-59, 1e-70), "area %g", s->surfs[0].area);
  }
  hr_scene_destroy(&s);

  /* the largest coordinates accepted: finite area and a unit normal; the extreme Ke accepted */
  const char *huge =
      "v 1e12 -1e12 0\nv 1e12 1e12 0\nv -1e12 1e12 0\nv 0 0 1e12\nf 1 2 3\nf 1 2 4\n";
  lc = (logcap){0};
  st = hr_scene_parse_obj(huge, strlen(huge), "huge.obj", &log, &s, &err);
  CHECK(st == HR_OK && lc.n == 0, "huge: status %d: %s", st, err.msg);
  if (s) {
    CHECK(s->nsurfs == 2 && NEAR(s->surfs[0].area, 2e24, 1e10) &&
              NEAR(s->surfs[0].normal.z, 1, 1e-15),
          "huge: area %g normal z %g", s->nsurfs ? s->surfs[0].area : 0,
          s->nsurfs ? s->surfs[0].normal.z : 0);
    for (int i = 0; i < s->nsurfs; i++) CHECK(isfinite(s->poly_area[s->surfs[i].poly]), "huge");
  }
  hr_scene_destroy(&s);
  /* a non-convex polygon with more vertices than are triangulated: an error, not a lost face */
  int nv = HR_EAR_MAX + 2;
  size_t cap = (size_t)nv * 64 + 64, k = 0;
  char *big = malloc(cap);
  for (int i = 0; i < nv; i++) {
    double a = 2 * M_PI * i / nv, r = i == nv / 2 ? 0.5 : 1; /* one vertex pulled in */
    k += (size_t)snprintf(big + k, cap - k, "v %.17g %.17g 0\n", r * cos(a), r * sin(a));
  }
  k += (size_t)snprintf(big + k, cap - k, "f");
  for (int i = 1; i <= nv; i++) k += (size_t)snprintf(big + k, cap - k, " %d", i);
  k += (size_t)snprintf(big + k, cap - k, "\n");
  st = hr_scene_parse_obj(big, k, "ear.obj", NULL, &s, &err);
  char want[200];
  snprintf(want, sizeof want, "ear.obj:%d: non-convex polygon with %d vertices (at most %d", nv + 1,
           nv, HR_EAR_MAX);
  CHECK(st == HR_ERR_PARSE && s == NULL && strncmp(err.msg, want, strlen(want)) == 0,
        "ear limit: %d '%s'", st, err.msg);
  hr_scene_destroy(&s);
  free(big);

  const char *ke_obj = "mtllib k.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl k\nf 1 2 3\n";
  const char *ke_mtl = "newmtl k\nKe 1e30 1e-30 0\n";
  st = hr_scene_parse_obj_mtl(ke_obj, strlen(ke_obj), ke_mtl, strlen(ke_mtl), "ke.obj", NULL, &s,
                              &err);
  CHECK(st == HR_OK && s && s->mats[0].emit[0] == 1e30 && s->mats[0].emit[1] == 1e-30,
        "Ke limits: status %d: %s", st, err.msg);
  hr_scene_destroy(&s);
}

/* hr_scene_parse_obj_mtl: every mtllib reads the MTL text from memory (even when a file of that
 * name exists), errors name the library as a file would be named; without MTL text no file is
 * read either. */
static void test_parse_obj_mtl(void) {
  write_file("lib.mtl", "newmtl lamp\nKd 0.1\nKe 9\n"); /* on the disk: must not be read */
  char path[600];
  snprintf(path, sizeof path, "%s/mem.obj", tmpdir);
  const char *obj = "mtllib lib.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl lamp\nf 1 2 3\n";
  const char *mtl = "newmtl lamp\r\nKd 0.25 0.5 0.75\r\nKe 1 2 3";
  logcap lc = {0};
  hr_log log = {cap_fn, &lc};
  hr_err err;
  hr_scene *s = NULL;
  hr_status st = hr_scene_parse_obj_mtl(obj, strlen(obj), mtl, strlen(mtl), path, &log, &s, &err);
  CHECK(st == HR_OK && lc.n == 0, "memory MTL: status %d: %s; %d warnings", st, err.msg, lc.n);
  if (s) {
    CHECK(s->nmats == 1 && strcmp(s->mats[0].name, "lamp") == 0 && s->mats[0].rho[2] == 0.75 &&
              s->mats[0].emit[1] == 2,
          "memory MTL: material %s rho %g emit %g", s->mats[0].name, s->mats[0].rho[2],
          s->mats[0].emit[1]);
    CHECK(strcmp(s->name, "mem") == 0, "name '%s'", s->name);
  }
  hr_scene_destroy(&s);

  /* an error in the MTL names it as the file DIR/lib.mtl */
  const char *bad = "newmtl lamp\nKd 2 2 2\n";
  st = hr_scene_parse_obj_mtl(obj, strlen(obj), bad, strlen(bad), path, &log, &s, &err);
  char want[700];
  snprintf(want, sizeof want, "%s/lib.mtl:2: rho must be in [0,1] (Kd 2)", tmpdir);
  CHECK(st == HR_ERR_PARSE && s == NULL && strcmp(err.msg, want) == 0, "bad MTL: %d '%s'", st,
        err.msg);

  /* no MTL text: a warning, grey materials, and lib.mtl on the disk is not read */
  lc = (logcap){0};
  st = hr_scene_parse_obj_mtl(obj, strlen(obj), NULL, 0, path, &log, &s, &err);
  CHECK(st == HR_OK, "no MTL: status %d: %s", st, err.msg);
  CHECK(lc.n == 2 && count_msgs(&lc, "mem.obj:1: cannot open material library 'lib.mtl'; using "
                                     "grey default") == 1 &&
            count_msgs(&lc, "mem.obj:5: unknown material 'lamp'") == 1,
        "no MTL: %d warnings, first: %s", lc.n, lc.msg[0]);
  if (s) CHECK(s->nmats == 1 && s->mats[0].rho[0] == 0.5 && s->mats[0].emit[0] == 0, "no MTL");
  hr_scene_destroy(&s);

  /* several names on one mtllib line: the one text, read once; two statements read it twice
   * (the second definition wins, as for files) */
  const char *two =
      "mtllib a.mtl b.mtl\nmtllib c.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl m\nf 1 2 3\n";
  const char *m = "newmtl m\nKd 0.3\n";
  lc = (logcap){0};
  st = hr_scene_parse_obj_mtl(two, strlen(two), m, strlen(m), "two.obj", &log, &s, &err);
  CHECK(st == HR_OK && lc.n == 0 && s && s->nmats == 1 && s->mats[0].rho[0] == 0.3,
        "two mtllib: status %d: %s; %d warnings", st, err.msg, lc.n);
  hr_scene_destroy(&s);

  /* same results as hr_scene_parse_obj for a file without mtllib; argument errors */
  const char *plain = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
  hr_scene *a = NULL;
  st = hr_scene_parse_obj_mtl(plain, strlen(plain), NULL, 0, "p.obj", NULL, &s, &err);
  hr_status sa = hr_scene_parse_obj(plain, strlen(plain), "p.obj", NULL, &a, &err);
  CHECK(st == HR_OK && sa == HR_OK && s && a && same_geometry(a, s), "plain: %d %d", st, sa);
  hr_scene_destroy(&s);
  hr_scene_destroy(&a);
  s = (hr_scene *)&lc;
  st = hr_scene_parse_obj_mtl(plain, strlen(plain), NULL, 5, "p.obj", NULL, &s, &err);
  CHECK(st == HR_ERR_INVALID && s == NULL, "NULL MTL with a length: %d", st);
  CHECK(hr_scene_parse_obj_mtl(plain, strlen(plain), NULL, 0, "p.obj", NULL, NULL, &err) ==
            HR_ERR_INVALID,
        "no output pointer");
  remove(write_file("lib.mtl", ""));
}

static void test_missing_mtl(void) {
  logcap lc = {0};
  hr_err err;
  hr_scene *s = NULL;
  hr_status st = load_text("nomtl.obj",
                           "mtllib nope.mtl\n"
                           "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n"
                           "f 1 2 3\n"
                           "usemtl red\n"
                           "f 2 4 3\n"
                           "usemtl red\n"
                           "f 3 2 1\n"
                           "usemtl blue\n"
                           "f 1 4 3\n",
                           &lc, &s, &err);
  CHECK(st == HR_OK, "status %d: %s", st, err.msg);
  CHECK(lc.n == 3, "%d warnings", lc.n);
  CHECK(count_msgs(&lc,
                   "nomtl.obj:1: cannot open material library 'nope.mtl'; using grey default") == 1,
        "mtllib warning: %s", lc.msg[0]);
  CHECK(count_msgs(&lc, "nomtl.obj:7: unknown material 'red'") == 1, "red warning");
  CHECK(count_msgs(&lc, "nomtl.obj:11: unknown material 'blue'") == 1, "blue warning");
  if (s) {
    CHECK(s->nmats == 3 && s->npolys == 4, "nmats %d npolys %d", s->nmats, s->npolys);
    const char *names[3] = {"default", "red", "blue"};
    for (int i = 0; i < s->nmats && i < 3; i++) {
      CHECK(strcmp(s->mats[i].name, names[i]) == 0, "mat %d '%s'", i, s->mats[i].name);
      for (int c = 0; c < 3; c++)
        CHECK(s->mats[i].rho[c] == 0.5 && s->mats[i].emit[c] == 0, "mat %d not grey", i);
    }
    if (s->nsurfs == 4)
      CHECK(s->surfs[0].material == 0 && s->surfs[1].material == 1 && s->surfs[2].material == 1 &&
                s->surfs[3].material == 2,
            "surface materials");
  }
  hr_scene_destroy(&s);
}

/* One bad input: 'file' is written (with 'mtl' as bad.mtl when given) and must fail with 'want'
 * and a message starting with PREFIX (the path of 'msgfile' then ":LINE:"), containing 'needle'. */
typedef struct bad_case {
  const char *obj, *mtl;
  hr_status want;
  const char *msgfile; /* file named in the message: "bad.obj" or "bad.mtl" */
  int line;
  const char *needle;
} bad_case;

static void test_bad_inputs(void) {
  static const bad_case cases[] = {
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", NULL, HR_ERR_PARSE, "bad.obj", 4, "index 0"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\n\n\nf 1 2 4\n", NULL, HR_ERR_PARSE, "bad.obj", 6,
       "out of range"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n", NULL, HR_ERR_PARSE, "bad.obj", 4, "out of range"},
      {"v 0 0 0\nv 1 nan 2\n", NULL, HR_ERR_PARSE, "bad.obj", 2, "non-finite"},
      {"v 0 0 0\r\nv 1 2 inf\r\n", NULL, HR_ERR_PARSE, "bad.obj", 2, "non-finite"},
      {"v 0 0 0\nv 1 2 1e999\n", NULL, HR_ERR_PARSE, "bad.obj", 2, "non-finite"},
      {"# one\n# two\nv 1 2\n", NULL, HR_ERR_PARSE, "bad.obj", 3, "3 coordinates"},
      {"v 1 2 3x\n", NULL, HR_ERR_PARSE, "bad.obj", 1, "bad number '3x'"},
      {"v 1,5 2 3\n", NULL, HR_ERR_PARSE, "bad.obj", 1, "bad number"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", NULL, HR_ERR_PARSE, "bad.obj", 4, "2 vertices"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf\n", NULL, HR_ERR_PARSE, "bad.obj", 4, "0 vertices"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/x 2 3\n", NULL, HR_ERR_PARSE, "bad.obj", 4,
       "malformed vertex reference '1/x'"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3/\n", NULL, HR_ERR_PARSE, "bad.obj", 4, "malformed"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3//\n", NULL, HR_ERR_PARSE, "bad.obj", 4, "malformed"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3/1/2/3\n", NULL, HR_ERR_PARSE, "bad.obj", 4, "malformed"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 a\n", NULL, HR_ERR_PARSE, "bad.obj", 4, "malformed"},
      {"mtllib bad.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
       "newmtl a\nKd 0.5\n\nnewmtl b\nKd 1.5 0 0\n", HR_ERR_PARSE, "bad.mtl", 5,
       "rho must be in [0,1]"},
      {"mtllib bad.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "newmtl a\nKd -0.1\n", HR_ERR_PARSE,
       "bad.mtl", 2, "rho must be in [0,1]"},
      {"mtllib bad.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "newmtl a\nKe 1 -2 3\n",
       HR_ERR_PARSE, "bad.mtl", 2, "Ke must not be negative"},
      {"mtllib bad.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "newmtl a\r\nKe 1 nan 3\r\n",
       HR_ERR_PARSE, "bad.mtl", 2, "non-finite"},
      {"mtllib bad.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "newmtl a\nKd 0.1 0.2\n",
       HR_ERR_PARSE, "bad.mtl", 2, "1 or 3 numbers"},
      {"mtllib bad.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "Kd 0.1 0.2 0.3\n", HR_ERR_PARSE,
       "bad.mtl", 1, "before any newmtl"},
      {"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0.5 1.5 0.5\nv 0 1 0\nf 1 2 3 4 5\n", NULL, HR_ERR_PARSE,
       "bad.obj", 6, "non-planar polygon with 5 vertices"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl\nf 1 2 3\n", NULL, HR_ERR_PARSE, "bad.obj", 4,
       "usemtl needs"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999999\n", NULL, HR_ERR_PARSE, "bad.obj",
       4, "out of range"},
      /* a face revisiting its vertices (HR_POLY_NOT_SIMPLE) vanished without a trace */
      {"v 0 0.5 0\nv 1 0.5 0\nv 1 0.5 1\nv 0 0.5 1\nv 0.5 0.5 2\nf 1 2 3 4 5 1 2\n", NULL,
       HR_ERR_PARSE, "bad.obj", 6, "polygon with 7 vertices is not simple"},
      /* found by fuzzing: coordinates whose squares overflow gave an infinite area */
      {"v 1e100 0 0\nv 0 1e100 0\nv 0 0 0\nf 1 2 3\n", NULL, HR_ERR_PARSE, "bad.obj", 1,
       "coordinate 1e+100 out of range (magnitude at most 1e+12)"},
      {"v 0 0 0\nv 1 0 0\nv 0 -1.5e12 0\nf 1 2 3\n", NULL, HR_ERR_PARSE, "bad.obj", 3,
       "coordinate -1.5e+12 out of range"},
      /* emission so large (or small) that E times an area overflows (underflows) */
      {"mtllib bad.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "newmtl a\nKe 0 1e31 0\n",
       HR_ERR_PARSE, "bad.mtl", 2, "Ke must be 0 or in [1e-30,1e+30] (Ke 1e+31)"},
      {"mtllib bad.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "newmtl a\nKe 1e-300\n",
       HR_ERR_PARSE, "bad.mtl", 2, "Ke must be 0 or in [1e-30,1e+30] (Ke 1e-300)"},
  };
  int ncases = (int)(sizeof cases / sizeof cases[0]);
  for (int i = 0; i < ncases; i++) {
    const bad_case *c = &cases[i];
    if (c->mtl) write_file("bad.mtl", c->mtl);
    logcap lc = {0};
    hr_err err;
    hr_scene *s = (hr_scene *)&lc; /* must come back NULL */
    hr_status st = load_text("bad.obj", c->obj, &lc, &s, &err);
    char prefix[600];
    snprintf(prefix, sizeof prefix, "%s/%s:%d: ", tmpdir, c->msgfile, c->line);
    CHECK(st == c->want, "case %d: status %d want %d (%s)", i, st, c->want, err.msg);
    CHECK(s == NULL, "case %d: scene not NULL", i);
    CHECK(strncmp(err.msg, prefix, strlen(prefix)) == 0, "case %d: message '%s' want prefix '%s'",
          i, err.msg, prefix);
    CHECK(strstr(err.msg, c->needle) != NULL, "case %d: message '%s' lacks '%s'", i, err.msg,
          c->needle);
    CHECK(strchr(err.msg, '\n') == NULL, "case %d: newline in message", i);
    if (s && s != (hr_scene *)&lc) hr_scene_destroy(&s);

    /* the same from memory gives the same message */
    if (!c->mtl) {
      char path[600];
      hr_err err2;
      snprintf(path, sizeof path, "%s/bad.obj", tmpdir);
      hr_scene *s2 = NULL;
      hr_status st2 = hr_scene_parse_obj(c->obj, strlen(c->obj), path, NULL, &s2, &err2);
      CHECK(st2 == st && s2 == NULL && strcmp(err.msg, err2.msg) == 0,
            "case %d: memory parse '%s' vs '%s'", i, err2.msg, err.msg);
      hr_scene_destroy(&s2);
    }
  }
  remove(write_file("bad.mtl", ""));

  /* missing file */
  char path[600];
  snprintf(path, sizeof path, "%s/does-not-exist.obj", tmpdir);
  hr_err err;
  hr_scene *s = NULL;
  hr_status st = hr_scene_load_obj(path, NULL, &s, &err);
  char want[700];
  snprintf(want, sizeof want, "%s: cannot open: No such file or directory", path);
  CHECK(st == HR_ERR_IO && s == NULL, "missing file: status %d", st);
  CHECK(strcmp(err.msg, want) == 0, "missing file: '%s'", err.msg);

  /* a directory is unreadable as a file */
  st = hr_scene_load_obj(tmpdir, NULL, &s, &err);
  CHECK(st == HR_ERR_IO && s == NULL && strncmp(err.msg, tmpdir, strlen(tmpdir)) == 0,
        "directory: status %d '%s'", st, err.msg);

  /* empty text */
  st = hr_scene_parse_obj("", 0, "empty.obj", NULL, &s, &err);
  CHECK(st == HR_ERR_PARSE && strcmp(err.msg, "empty.obj: no polygons") == 0, "empty: %d '%s'", st,
        err.msg);

  /* text not NUL-terminated: only 'len' bytes are read */
  const char *t = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 0 garbage";
  st = hr_scene_parse_obj(t, strlen(t) - 15, "cut.obj", NULL, &s, &err);
  CHECK(st == HR_OK && s && s->npolys == 1, "cut buffer: %d '%s'", st, err.msg);
  if (s) CHECK(strcmp(s->name, "cut") == 0, "name '%s'", s->name);
  hr_scene_destroy(&s);

  /* embedded NUL byte */
  const char nul[] = "v 0 0 0\nv 1 0 0\nv 0\0 1 0\nf 1 2 3\n";
  st = hr_scene_parse_obj(nul, sizeof nul - 1, "nul.obj", NULL, &s, &err);
  CHECK(st == HR_ERR_PARSE && s == NULL && strncmp(err.msg, "nul.obj:3:", 10) == 0,
        "NUL byte: %d '%s'", st, err.msg);

  /* line numbers after a continuation count physical lines */
  const char *cont = "v 0 0 \\\n 0\nv 1 0 0\nv 0 1 0\nf 1 2 3 \\\n 4\n";
  st = hr_scene_parse_obj(cont, strlen(cont), "cont.obj", NULL, &s, &err);
  CHECK(st == HR_ERR_PARSE && strncmp(err.msg, "cont.obj:5: vertex index 4", 26) == 0,
        "continuation: %d '%s'", st, err.msg);
}

/* Duplicate polygons: the same set of positions (from any vertex indices, in any rotation,
 * -0 = +0, repeated positions counted once) facing the same way is skipped with a warning naming
 * the first one's line; the opposite facing (a back-to-back twin) and a different set are kept. */
static void test_duplicates(void) {
  static const char text[] =
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"     /* 1-4 */
      "v -0 0 0\nv 1 0 0\nv 1 1 -0\nv 0 1 0\n"   /* 5-8: same positions again */
      "f 1 2 3 4\n"                                 /* 9 */
      "f 6 7 8 5\n"                                 /* 10: duplicate of 9 (rotated) */
      "f 4 3 2 1\n"                                 /* 11: back to back with 9: kept */
      "usemtl other\n"                              /* 12 */
      "f 3 4 1 2\n"                                 /* 13: duplicate of 9, other material */
      "f 1 2 3\n"                                   /* 14: a subset: kept */
      "f 2 3 3 1\n"                                 /* 15: same set as 14: duplicate */
      "f 8 7 6 5\n"                                 /* 16: duplicate of 11 */
      "f 1 3 4\n";                                  /* 17: kept */
  logcap lc = {0};
  hr_err err;
  hr_scene *s = NULL;
  hr_status st = load_text("dup.obj", text, &lc, &s, &err);
  CHECK(st == HR_OK, "status %d: %s", st, err.msg);
  const char *want[4] = {"dup.obj:10: duplicate of the polygon on line 9; skipped",
                         "dup.obj:13: duplicate of the polygon on line 9; skipped",
                         "dup.obj:15: duplicate of the polygon on line 14; skipped",
                         "dup.obj:16: duplicate of the polygon on line 11; skipped"};
  CHECK(lc.n == 5, "%d warnings, first: %s", lc.n, lc.msg[0]); /* + unknown material 'other' */
  for (int i = 0; i < 4; i++)
    CHECK(count_msgs(&lc, want[i]) == 1, "missing warning '%s'", want[i]);
  if (s) {
    CHECK(s->npolys == 4, "npolys %d", s->npolys);
    CHECK(s->nsurfs == 4 && NEAR(s->surfs[0].normal.z, 1, 1e-12) &&
              NEAR(s->surfs[1].normal.z, -1, 1e-12),
          "nsurfs %d", s->nsurfs);
    CHECK(NEAR(hr_scene_total_area(s), 1 + 1 + 0.5 + 0.5, 1e-12), "area %g",
          hr_scene_total_area(s));
    /* One input row per face, in order: faces 9, 11, 14, 17 are kept polygons 0-3; the
     * duplicates point at their twins (surfaces.csv reports them with the twin's radiosity). */
    const hr_input want_in[8] = {{0, HR_INPUT_SOLVED},    {0, HR_INPUT_DUPLICATE},
                                 {1, HR_INPUT_SOLVED},    {0, HR_INPUT_DUPLICATE},
                                 {2, HR_INPUT_SOLVED},    {2, HR_INPUT_DUPLICATE},
                                 {1, HR_INPUT_DUPLICATE}, {3, HR_INPUT_SOLVED}};
    CHECK(s->ninputs == 8, "%d input rows, want 8", s->ninputs);
    for (int i = 0; i < 8 && i < s->ninputs; i++)
      CHECK(s->inputs[i].poly == want_in[i].poly && s->inputs[i].kind == want_in[i].kind,
            "input %d: poly %d kind %d, want %d %d", i, s->inputs[i].poly, (int)s->inputs[i].kind,
            want_in[i].poly, (int)want_in[i].kind);
    CHECK(hr_scene_poly_input(s, 2) == 4, "polygon 2 is input row %d, want 4",
          hr_scene_poly_input(s, 2));
  }
  hr_scene_destroy(&s);
  /* the same from memory */
  lc = (logcap){0};
  hr_log log = {cap_fn, &lc};
  st = hr_scene_parse_obj(text, strlen(text), "mem.obj", &log, &s, &err);
  CHECK(st == HR_OK && s && s->npolys == 4 && lc.n == 5 &&
            count_msgs(&lc, "mem.obj:16: duplicate of the polygon on line 11; skipped") == 1,
        "memory parse: %d, %d warnings", st, lc.n);
  hr_scene_destroy(&s);

  /* many faces, each one repeated at the end: all repeats found (hash table growth) */
  int nq = 3000;
  size_t cap = (size_t)nq * 200 + 64, k = 0;
  char *big = malloc(cap);
  for (int i = 0; i < nq; i++)
    k += (size_t)snprintf(big + k, cap - k, "v %d 0 0\nv %d 0 0\nv %d 1 %d\n", i, i + 1, i,
                          i % 7);
  for (int i = 0; i < nq; i++)
    k += (size_t)snprintf(big + k, cap - k, "f %d %d %d\n", 3 * i + 1, 3 * i + 2, 3 * i + 3);
  for (int i = 0; i < nq; i++) /* rotated */
    k += (size_t)snprintf(big + k, cap - k, "f %d %d %d\n", 3 * i + 2, 3 * i + 3, 3 * i + 1);
  lc = (logcap){0};
  st = hr_scene_parse_obj(big, k, "many.obj", &log, &s, &err);
  CHECK(st == HR_OK && s && s->npolys == nq && lc.n == nq, "many: %d, npolys %d, %d warnings", st,
        s ? s->npolys : -1, lc.n);
  hr_scene_destroy(&s);
  free(big);
}

static void test_unknown_statements(void) {
  logcap lc = {0};
  hr_err err;
  hr_scene *s = NULL;
  hr_status st = load_text("unk.obj",
                           "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
                           "frobnicate 1 2\nfrobnicate 3\nvp 0.5\ncstype bspline\n"
                           "f 1 2 3\n",
                           &lc, &s, &err);
  CHECK(st == HR_OK, "status %d: %s", st, err.msg);
  CHECK(lc.n == 1 && count_msgs(&lc, "unk.obj:4: unknown statement 'frobnicate'") == 1,
        "%d warnings: %s", lc.n, lc.msg[0]);
  hr_scene_destroy(&s);

  /* a long line and a face with many vertices (no fixed limits) */
  int nv = 5000;
  size_t cap = (size_t)nv * 64 + 64, k = 0;
  char *big = malloc(cap);
  for (int i = 0; i < nv; i++) {
    double a = 2 * M_PI * i / nv;
    k += (size_t)snprintf(big + k, cap - k, "v %.17g %.17g 0\n", cos(a), sin(a));
  }
  k += (size_t)snprintf(big + k, cap - k, "f");
  for (int i = 1; i <= nv; i++) k += (size_t)snprintf(big + k, cap - k, " %d", i);
  k += (size_t)snprintf(big + k, cap - k, "\n");
  st = hr_scene_parse_obj(big, k, "big.obj", NULL, &s, &err);
  CHECK(st == HR_OK, "big face: %d %s", st, err.msg);
  if (s) {
    double want = 0.5 * nv * sin(2 * M_PI / nv);
    CHECK(s->npolys == 1 && s->nsurfs == nv - 2, "npolys %d nsurfs %d", s->npolys, s->nsurfs);
    CHECK(NEAR(s->poly_area[0], want, 1e-9), "area %.15g want %.15g", s->poly_area[0], want);
  }
  hr_scene_destroy(&s);
  free(big);
}

/* ---------------------------------------------------------------- shared scenes */

/* Independent reading of an OBJ: counts `f` lines and sums each face's area as the length of
 * half its Newell vector (exact for planar polygons); supports plain and negative indices. The
 * faces on the 'nskip' lines 'skip' are counted in *nfaces but left out of *area. */
static int independent_obj(const char *path, double *area, int *nfaces, const long *skip,
                           int nskip) {
  size_t len;
  char *b = read_all(path, &len);
  if (!b) return 0;
  double(*v)[3] = malloc(sizeof *v * (len / 4 + 1));
  int nv = 0;
  *area = 0;
  *nfaces = 0;
  long lineno = 0;
  for (char *line = b, *next; line; line = next) {
    next = strchr(line, '\n');
    if (next) *next++ = '\0';
    lineno++;
    while (*line == ' ' || *line == '\t') line++;
    if (line[0] == 'v' && (line[1] == ' ' || line[1] == '\t')) {
      sscanf(line + 1, "%lf %lf %lf", &v[nv][0], &v[nv][1], &v[nv][2]);
      nv++;
    } else if (line[0] == 'f' && (line[1] == ' ' || line[1] == '\t')) {
      int idx[64], n = 0, off = 0, pos = 1;
      while (n < 64 && sscanf(line + pos, " %d%n", &idx[n], &off) == 1) {
        pos += off;
        while (line[pos] && line[pos] != ' ' && line[pos] != '\t') pos++;
        idx[n] = idx[n] < 0 ? nv + idx[n] : idx[n] - 1;
        n++;
      }
      double nx = 0, ny = 0, nz = 0;
      for (int i = 0; i < n; i++) {
        double *a = v[idx[i]], *c = v[idx[(i + 1) % n]];
        nx += (a[1] - c[1]) * (a[2] + c[2]);
        ny += (a[2] - c[2]) * (a[0] + c[0]);
        nz += (a[0] - c[0]) * (a[1] + c[1]);
      }
      int skipped = 0;
      for (int k = 0; k < nskip; k++) skipped |= skip[k] == lineno;
      if (!skipped) *area += 0.5 * sqrt(nx * nx + ny * ny + nz * nz);
      (*nfaces)++;
    }
  }
  free(v);
  free(b);
  return 1;
}

#if defined(__has_include)
#if __has_include(<valgrind/valgrind.h>)
#include <valgrind/valgrind.h>
#define HAVE_VALGRIND_H 1
#endif
#endif
static int under_valgrind(void) {
#ifdef HAVE_VALGRIND_H
  return RUNNING_ON_VALGRIND != 0;
#else
  return 0;
#endif
}

static int shared_missing(void) { return access(HR_SHARED_DIR "/scenes", F_OK) != 0; }

static void test_cornell(void) {
  /* vendored (tests/data/cornell, CC BY 3.0, McGuire's; the same file as ../shared's) */
  const char *path = HR_SOURCE_DIR "/tests/data/cornell/CornellBox-Original.obj";
  /* file defect: each box's "Bottom Face" reuses a side face's vertex indices (short box: line
   * 107 = its right face, line 93; tall box: line 155 = its front face, line 148), so the
   * "bottoms" are vertical duplicates, not floor-facing quads: skipped with a warning */
  const long dup_lines[2] = {107, 155};
  double want_area;
  int nfaces;
  if (!independent_obj(path, &want_area, &nfaces, dup_lines, 2)) {
    CHECK(0, "cannot read %s", path);
    return;
  }
  logcap lc = {0};
  hr_log log = {cap_fn, &lc};
  hr_err err;
  hr_scene *s = NULL;
  hr_status st = hr_scene_load_obj(path, &log, &s, &err);
  CHECK(st == HR_OK, "cornell: %d %s", st, err.msg);
  if (!s) return;
  CHECK(lc.n == 2, "cornell: %d warnings: %s", lc.n, lc.msg[0]);
  CHECK(count_msgs(&lc, "CornellBox-Original.obj:107: duplicate of the polygon on line 93; "
                        "skipped") == 1 &&
            count_msgs(&lc, "CornellBox-Original.obj:155: duplicate of the polygon on line 148; "
                            "skipped") == 1,
        "cornell warnings: '%s', '%s'", lc.msg[0], lc.msg[1]);
  CHECK(strcmp(s->name, "CornellBox-Original") == 0, "name '%s'", s->name);
  CHECK(nfaces == 18, "cornell has %d f lines", nfaces);
  CHECK(s->npolys == 16 && s->npolys == nfaces - 2, "npolys %d, f lines %d", s->npolys, nfaces);
  CHECK(s->nmats == 8, "nmats %d", s->nmats);
  int nquads = 0, ntris = 0;
  for (int i = 0; i < s->nsurfs; i++) (*(s->surfs[i].nverts == 4 ? &nquads : &ntris))++;
  printf("cornell: %d polygons -> %d surfaces (%d quads, %d triangles from split quads)\n",
         s->npolys, s->nsurfs, nquads, ntris);
  CHECK(nquads + ntris / 2 == s->npolys && ntris % 2 == 0, "quads %d tris %d", nquads, ntris);
  int light = hr_scene_find_material(s, "light");
  CHECK(light >= 0, "no light material");
  if (light >= 0) {
    const hr_material *m = &s->mats[light];
    CHECK(m->emit[0] == 17 && m->emit[1] == 12 && m->emit[2] == 4, "light Ke %g %g %g", m->emit[0],
          m->emit[1], m->emit[2]);
    CHECK(m->rho[0] == 0.78, "light Kd %g", m->rho[0]);
    /* the light quad (0.47 x 0.38 m) faces down */
    for (int i = 0; i < s->nsurfs; i++)
      if (s->surfs[i].material == light) {
        CHECK(NEAR(s->surfs[i].normal.y, -1, 1e-12), "light normal y %g", s->surfs[i].normal.y);
        CHECK(NEAR(s->poly_area[s->surfs[i].poly], 0.47 * 0.38, 1e-12), "light area %.15g",
              s->poly_area[s->surfs[i].poly]);
      }
  }
  int red = hr_scene_find_material(s, "leftWall");
  CHECK(red >= 0 && s->mats[red].rho[0] == 0.63 && s->mats[red].rho[1] == 0.065 &&
            s->mats[red].rho[2] == 0.05,
        "leftWall Kd");
  CHECK(hr_scene_max_emit(s) == 17, "max emit %g", hr_scene_max_emit(s));
  /* only the left wall is non-planar beyond tolerance (x = -1.01, -0.99, -1.02, -1.02): it is the
   * one quad split into two triangles */
  for (int i = 0; i < s->nsurfs; i++)
    if (s->surfs[i].nverts == 3)
      CHECK(red >= 0 && s->surfs[i].material == red, "split surface %d has material '%s'", i,
            s->mats[s->surfs[i].material].name);
  /* no polygon is left that repeats another's vertices (both boxes keep 5 faces each) */
  int same = 0;
  for (int i = 0; i < s->nsurfs; i++)
    for (int j = i + 1; j < s->nsurfs; j++) {
      const hr_surface *a = &s->surfs[i], *b = &s->surfs[j];
      int eq = a->nverts == b->nverts;
      for (int v = 0; eq && v < a->nverts; v++) eq = vec_eq(a->v[v], b->v[v]);
      same += eq;
    }
  CHECK(same == 0, "%d duplicated surfaces left", same);
  int box[2] = {hr_scene_find_material(s, "shortBox"), hr_scene_find_material(s, "tallBox")};
  for (int k = 0; k < 2; k++) {
    int np = 0;
    for (int i = 0; i < s->nsurfs; i++) np += box[k] >= 0 && s->surfs[i].material == box[k];
    CHECK(np == 5, "box %d has %d surfaces", k, np);
  }
  double area = hr_scene_total_area(s);
  /* the walls are only slightly non-planar: split triangles add at most a tiny fraction */
  printf("cornell: total area %.6f m^2 (Newell sum %.6f)\n", area, want_area);
  CHECK(area >= want_area - 1e-12 && NEAR(area, want_area, 1e-4 * want_area), "area %.9f want %.9f",
        area, want_area);
  /* rough box: 5 walls of ~2 x 2, boxes 0.6 x 0.53^2 and 1.2 x ..., light 0.18: about 26 m^2 */
  CHECK(area > 24 && area < 28, "area %g", area);
  hr_scene_destroy(&s);
}

static void test_conference(void) {
  const char *path = HR_SHARED_DIR "/scenes/conference/conference.obj";
  const char *mtl = HR_SHARED_DIR "/scenes/conference/conference.mtl";
  size_t len;
  char *b = read_all(path, &len);
  if (!b) {
    CHECK(0, "cannot read %s", path);
    return;
  }
  int nf = 0;
  for (char *p = b; p; p = strchr(p, '\n')) {
    if (*p == '\n') p++;
    if (p[0] == 'f' && (p[1] == ' ' || p[1] == '\t')) nf++;
  }
  free(b);
  char *m = read_all(mtl, NULL);
  int nnew = 0;
  for (char *p = m; p && (p = strstr(p, "newmtl ")); p += 7) nnew++;
  free(m);

  logcap lc = {0};
  hr_log log = {cap_fn, &lc};
  hr_err err;
  hr_scene *s = NULL;
  struct timespec t0, t1;
  clock_gettime(CLOCK_MONOTONIC, &t0);
  hr_status st = hr_scene_load_obj(path, &log, &s, &err);
  clock_gettime(CLOCK_MONOTONIC, &t1);
  double secs = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
  CHECK(st == HR_OK, "conference: %d %s", st, err.msg);
  if (!s) return;
  printf(
      "conference: %d f lines, %d degenerate skipped, %d polygons, %d surfaces, %d materials, "
      "parsed in %.3f s\n",
      nf, lc.ndegen, s->npolys, s->nsurfs, s->nmats, secs);
  CHECK(nf == 69047, "f lines %d", nf);
  CHECK(lc.n == lc.ndegen, "%d warnings, %d degenerate; first: %s", lc.n, lc.ndegen, lc.msg[0]);
  CHECK(s->npolys == nf - lc.ndegen, "npolys %d", s->npolys);
  CHECK(s->nsurfs == s->npolys, "triangles stay single surfaces: %d vs %d", s->nsurfs, s->npolys);
  CHECK(nnew == 35 && s->nmats == nnew, "nmats %d, newmtl lines %d", s->nmats, nnew);
  CHECK(hr_scene_find_material(s, "Material #0") >= 0, "no 'Material #0'");
  CHECK(hr_scene_find_material(s, "default") < 0, "unexpected default material");
  CHECK(hr_scene_max_emit(s) == 0, "max emit %g", hr_scene_max_emit(s));
  CHECK(strcmp(s->name, "conference") == 0, "name '%s'", s->name);
  /* ASan's and valgrind's realloc always move memory, so instrumented runs only get a sanity
   * bound; plain builds must be well under a second */
  double limit = under_valgrind() ? 600.0 : 1.0;
#if defined(__SANITIZE_ADDRESS__)
  limit = 120.0;
#endif
  CHECK(secs < limit, "parse took %.3f s (limit %g s)", secs, limit);
  hr_scene_destroy(&s);
}

/* Objects: faces before any name go to the default object (the scene's name); `g` names objects
 * until the first `o`, then only `o` does; a name used again continues its object. map_Kd warns
 * once. */
static void test_objects(void) {
  const char *obj = "mtllib m.mtl\n"
                    "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\n"
                    "f 1 2 3\n"          /* poly 0: default object */
                    "g wall\nf 1 3 4\n" /* poly 1: wall */
                    "o lamp\nf 1 2 5\n" /* poly 2: lamp */
                    "g ignored\nf 2 6 5\n" /* poly 3: still lamp */
                    "o wall\nf 1 5 4\n"; /* poly 4: wall again */
  const char *mtl = "newmtl a\nKd 0.5 0.5 0.5\nmap_Kd a.png\nnewmtl b\nmap_Kd b.png\n";
  logcap cap = {0};
  hr_log log = {cap_fn, &cap};
  hr_err err = {{0}};
  hr_scene *s = NULL;
  hr_status st = hr_scene_parse_obj_mtl(obj, strlen(obj), mtl, strlen(mtl), "dir/objs.obj", &log,
                                        &s, &err);
  CHECK(st == HR_OK, "status %d: %s", st, err.msg);
  if (st != HR_OK) return;
  CHECK(hr_scene_object_count(s) == 3, "objects %d", hr_scene_object_count(s));
  const char *want[3] = {"objs", "wall", "lamp"};
  for (int i = 0; i < 3 && i < hr_scene_object_count(s); i++)
    CHECK(strcmp(hr_scene_object_name(s, i), want[i]) == 0, "object %d is '%s'", i,
          hr_scene_object_name(s, i));
  const int poly_obj[5] = {0, 1, 2, 2, 1};
  CHECK(s->npolys == 5, "npolys %d", s->npolys);
  for (int p = 0; p < 5 && p < s->npolys; p++)
    CHECK(hr_scene_poly_object(s, p) == poly_obj[p], "poly %d in object %d, want %d", p,
          hr_scene_poly_object(s, p), poly_obj[p]);
  CHECK(hr_scene_poly_object(s, 5) == -1 && hr_scene_object_name(s, 3) == NULL, "out of range");
  CHECK(count_msgs(&cap, "map_Kd 'a.png' not read") == 1 && count_msgs(&cap, "map_Kd") == 1,
        "map_Kd warnings: %d", count_msgs(&cap, "map_Kd"));
  CHECK(hr_scene_material_count(s) == 3 && hr_scene_poly_material(s, 0) >= 0,
        "materials %d", hr_scene_material_count(s));
  hr_scene_destroy(&s);
}

/* map_Kd: a quad with texture coordinates over a 64x64 PNG, white (sRGB 255) for u < 0.5 and sRGB
 * 128 beyond, Kd 0.8: its reflectance is 0.8 times the texture's mean, 0.8 (1 + 0.2159) / 2; a
 * face without vt, or of a material whose texture is missing (one warning), keeps Kd. */
static void test_map_kd(void) {
  enum { W = 64 };
  static unsigned char px[W * W * 3];
  for (int y = 0; y < W; y++)
    for (int x = 0; x < W; x++)
      for (int k = 0; k < 3; k++) px[3 * (y * W + x) + k] = x < W / 2 ? 255 : 128;
  char png[600];
  snprintf(png, sizeof png, "%s/tex.png", tmpdir);
  png_image img;
  memset(&img, 0, sizeof img);
  img.version = PNG_IMAGE_VERSION;
  img.width = img.height = W;
  img.format = PNG_FORMAT_RGB;
  CHECK(png_image_write_to_file(&img, png, 0, px, 0, NULL), "writing %s", png);
  write_file("t.mtl", "newmtl tex\nKd 0.8 0.8 0.8\nmap_Kd -s 1 1 1 tex.png\n"
                      "newmtl lost\nKd 0.3 0.3 0.3\nmap_Kd nosuch.png\n");
  const char *path = write_file("t.obj", "mtllib t.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                                         "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl tex\n"
                                         "f 1/1 2/2 3/3 4/4\nf 1 3 2\n"
                                         "usemtl lost\nf 1/1 4/4 2/2\nf 2/2 4/4 3/3\n");
  logcap cap = {0};
  hr_log log = {cap_fn, &cap};
  hr_err err = {{0}};
  hr_scene *s = NULL;
  hr_status st = hr_scene_load_obj(path, &log, &s, &err);
  CHECK(st == HR_OK && s && s->npolys == 4, "status %d: %s", st, err.msg);
  if (!s || s->npolys != 4) return;
  double want = 0.8 * (1 + 0.2158605) / 2;
  const hr_material *m0 = &s->mats[s->surfs[0].material];
  CHECK(fabs(m0->rho[0] - want) < 0.01 * want && !strcmp(m0->name, "tex") &&
            m0->base == hr_scene_find_material(s, "tex"),
        "textured quad: rho %g, want %g", m0->rho[0], want);
  CHECK(s->mats[s->surfs[1].material].rho[0] == 0.8, "face without vt: rho %g",
        s->mats[s->surfs[1].material].rho[0]);
  CHECK(s->mats[s->surfs[2].material].rho[0] == 0.3 && count_msgs(&cap, "not used") == 1,
        "missing texture: rho %g, %d warnings", s->mats[s->surfs[2].material].rho[0],
        count_msgs(&cap, "not used"));
  CHECK(hr_scene_material_count(s) == 2, "%d input materials", hr_scene_material_count(s));
  hr_scene_destroy(&s);
}

int main(void) {
  snprintf(tmpdir, sizeof tmpdir, "%s/hrad_test_obj_XXXXXX",
           getenv("TMPDIR") ? getenv("TMPDIR") : "/tmp");
  if (!mkdtemp(tmpdir)) {
    perror("mkdtemp");
    return 2;
  }
  test_unit_quad();
  test_index_forms();
  test_names_with_blanks();
  test_pentagon_and_nonplanar_quad();
  test_degenerate();
  test_missing_mtl();
  test_bad_inputs();
  test_unknown_statements();
  test_duplicates();
  test_range();
  test_parse_obj_mtl();
  test_objects();
  test_map_kd();
  remove_tmpdir();
  test_cornell();
  if (shared_missing()) {
    printf("shared scenes: skipped (%s/scenes missing)\n", HR_SHARED_DIR);
  } else {
    test_conference();
  }
  if (failures) {
    fprintf(stderr, "test_obj: %d failure(s)\n", failures);
    return 1;
  }
  printf("test_obj: all passed\n");
  return 0;
}
