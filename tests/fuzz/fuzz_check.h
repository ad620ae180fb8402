/* fuzz_check.h: what every fuzz target checks after parsing (see TESTING.md). A failed check
 * prints what failed and calls abort(), which libFuzzer reports as a crash and the replay test
 * (replay.c) as a failed ctest.
 *
 * After HR_OK: every surface has 3 or 4 finite vertices (at most 1e12 in magnitude, the loader's
 * limit), a finite positive area, a unit normal (| |n| - 1 | <= 1e-6), a valid material and
 * polygon index, and surfaces come in polygon order; every kept polygon has a surface and a
 * finite positive poly_area equal to the sum of its surfaces' areas (relative 1e-12); every
 * material has a name, finite rho in [0,1] and finite emit >= 0 (0 or in [1e-30, 1e30]);
 * scene->inputs has one record per `f` statement (counted here independently): SOLVED records
 * name the kept polygons 0, 1, 2, ... in order, DUPLICATE records an earlier kept polygon,
 * DEGENERATE records -1.
 * After an error: no scene, and a one-line message starting with the file name ("PATH:" or the
 * MTL path). Warnings are one line. */
#ifndef HR_FUZZ_CHECK_H
#define HR_FUZZ_CHECK_H

#include "hrad.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define FUZZ_REQUIRE(cond, ...)                                                    \
  do {                                                                             \
    if (!(cond)) {                                                                 \
      fprintf(stderr, "fuzz check failed: %s: ", #cond);                          \
      fprintf(stderr, __VA_ARGS__);                                                \
      fputc('\n', stderr);                                                         \
      abort();                                                                     \
    }                                                                              \
  } while (0)

static inline int fuzz_finite3(hr_vec3 v) {
  return isfinite(v.x) && isfinite(v.y) && isfinite(v.z);
}

/* Number of `f` statements in OBJ text 'b' (n bytes), counted independently of obj.c with the
 * same logical lines: a leading UTF-8 BOM skipped, a line ending in '\\' (before an optional CR)
 * joined with the next, blanks ' ' \t \r \v \f. After HR_OK every one of them is one record
 * of scene->inputs. */
static inline int fuzz_blank(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}
static inline long fuzz_count_faces(const char *b, size_t n) {
  char *c = malloc(n + 1);
  FUZZ_REQUIRE(c != NULL, "out of memory");
  if (n) memcpy(c, b, n);
  c[n] = '\0';
  size_t p = n >= 3 && memcmp(c, "\xEF\xBB\xBF", 3) == 0 ? 3 : 0;
  long faces = 0;
  while (p < n) {
    size_t start = p, seg = p, le;
    for (;;) {
      const char *nl = memchr(c + seg, '\n', n - seg);
      le = nl ? (size_t)(nl - c) : n;
      size_t q = le;
      if (q > seg && c[q - 1] == '\r') q--;
      if (nl && q > seg && c[q - 1] == '\\') {
        for (size_t r = q - 1; r <= le; r++) c[r] = ' ';
        seg = le + 1;
        continue;
      }
      p = nl ? le + 1 : n;
      break;
    }
    size_t k = start;
    while (k < le && fuzz_blank(c[k])) k++;
    if (k < le && c[k] == 'f' && (k + 1 == le || fuzz_blank(c[k + 1]))) faces++;
  }
  free(c);
  return faces;
}

/* Checks a successfully parsed scene. */
static inline void fuzz_check_scene(const hr_scene *s) {
  FUZZ_REQUIRE(s != NULL, "HR_OK without a scene");
  FUZZ_REQUIRE(s->name != NULL, "no name");
  FUZZ_REQUIRE(s->nmats >= 1 && s->nmats <= s->cap_mats && s->mats, "nmats %d", s->nmats);
  for (int i = 0; i < s->nmats; i++) {
    const hr_material *m = &s->mats[i];
    FUZZ_REQUIRE(m->name != NULL, "material %d has no name", i);
    for (int k = 0; k < 3; k++) {
      FUZZ_REQUIRE(isfinite(m->rho[k]) && m->rho[k] >= 0 && m->rho[k] <= 1,
                   "material %d '%s': rho[%d] = %g", i, m->name, k, m->rho[k]);
      FUZZ_REQUIRE(isfinite(m->emit[k]) && m->emit[k] >= 0, "material %d '%s': emit[%d] = %g", i,
                   m->name, k, m->emit[k]);
      FUZZ_REQUIRE(m->emit[k] == 0 || (m->emit[k] >= 1e-30 && m->emit[k] <= 1e30),
                   "material %d '%s': emit[%d] = %g outside the loader's range", i, m->name, k,
                   m->emit[k]);
    }
  }
  FUZZ_REQUIRE(s->npolys >= 1 && s->poly_area, "npolys %d", s->npolys);
  FUZZ_REQUIRE(s->nsurfs >= s->npolys && s->nsurfs <= s->cap_surfs && s->surfs,
               "nsurfs %d npolys %d", s->nsurfs, s->npolys);
  double *sum = calloc((size_t)s->npolys, sizeof *sum);
  FUZZ_REQUIRE(sum != NULL, "out of memory");
  int prev_poly = 0;
  for (int i = 0; i < s->nsurfs; i++) {
    const hr_surface *f = &s->surfs[i];
    FUZZ_REQUIRE(f->nverts == 3 || f->nverts == 4, "surface %d: nverts %d", i, f->nverts);
    for (int k = 0; k < f->nverts; k++)
      FUZZ_REQUIRE(fuzz_finite3(f->v[k]) && fabs(f->v[k].x) <= 1e12 && fabs(f->v[k].y) <= 1e12 &&
                       fabs(f->v[k].z) <= 1e12,
                   "surface %d: vertex %d (%g %g %g)", i, k, f->v[k].x, f->v[k].y, f->v[k].z);
    FUZZ_REQUIRE(isfinite(f->area) && f->area > 0, "surface %d: area %g", i, f->area);
    double nl = sqrt(f->normal.x * f->normal.x + f->normal.y * f->normal.y +
                     f->normal.z * f->normal.z);
    FUZZ_REQUIRE(fuzz_finite3(f->normal) && fabs(nl - 1) <= 1e-6,
                 "surface %d: normal (%g %g %g), length %.17g", i, f->normal.x, f->normal.y,
                 f->normal.z, nl);
    FUZZ_REQUIRE(f->material >= 0 && f->material < s->nmats, "surface %d: material %d of %d", i,
                 f->material, s->nmats);
    FUZZ_REQUIRE(f->poly >= 0 && f->poly < s->npolys, "surface %d: poly %d of %d", i, f->poly,
                 s->npolys);
    FUZZ_REQUIRE(f->poly == prev_poly || f->poly == prev_poly + 1 || (i == 0 && f->poly == 0),
                 "surface %d: poly %d after %d", i, f->poly, prev_poly);
    FUZZ_REQUIRE(i > 0 || f->poly == 0, "first surface has poly %d", f->poly);
    prev_poly = f->poly;
    sum[f->poly] += f->area;
  }
  FUZZ_REQUIRE(prev_poly == s->npolys - 1, "last surface has poly %d of %d", prev_poly,
               s->npolys);
  for (int p = 0; p < s->npolys; p++) {
    FUZZ_REQUIRE(isfinite(s->poly_area[p]) && s->poly_area[p] > 0, "poly_area[%d] = %g", p,
                 s->poly_area[p]);
    FUZZ_REQUIRE(fabs(s->poly_area[p] - sum[p]) <= 1e-12 * sum[p],
                 "poly_area[%d] = %.17g, its surfaces sum to %.17g", p, s->poly_area[p], sum[p]);
  }
  free(sum);
  FUZZ_REQUIRE(s->ninputs >= s->npolys && s->ninputs <= s->cap_inputs && s->inputs,
               "ninputs %d npolys %d", s->ninputs, s->npolys);
  int next = 0; /* the next kept polygon a SOLVED record must name */
  for (int i = 0; i < s->ninputs; i++) {
    const hr_input *in = &s->inputs[i];
    switch (in->kind) {
    case HR_INPUT_SOLVED:
      FUZZ_REQUIRE(in->poly == next, "input %d: solved poly %d, want %d", i, in->poly, next);
      next++;
      break;
    case HR_INPUT_DUPLICATE:
      FUZZ_REQUIRE(in->poly >= 0 && in->poly < next, "input %d: duplicate of poly %d (%d kept)", i,
                   in->poly, next);
      break;
    case HR_INPUT_DEGENERATE:
      FUZZ_REQUIRE(in->poly == -1, "input %d: degenerate with poly %d", i, in->poly);
      break;
    default:
      FUZZ_REQUIRE(0, "input %d: kind %d", i, (int)in->kind);
    }
  }
  FUZZ_REQUIRE(next == s->npolys, "%d solved input records for %d polygons", next, s->npolys);
  for (int p = 0; p < s->npolys; p++)
    FUZZ_REQUIRE(hr_scene_poly_input(s, p) >= 0, "polygon %d has no input row", p);
  /* objects: every kept polygon in one, every object named, names distinct */
  FUZZ_REQUIRE(s->nobjects >= 1, "%d objects for %d polygons", s->nobjects, s->npolys);
  for (int p = 0; p < s->npolys; p++) {
    int o = hr_scene_poly_object(s, p);
    FUZZ_REQUIRE(o >= 0 && o < s->nobjects, "polygon %d in object %d of %d", p, o, s->nobjects);
  }
  for (int o = 0; o < s->nobjects; o++)
    for (int q = o + 1; q < s->nobjects && q < o + 64; q++)
      FUZZ_REQUIRE(strcmp(hr_scene_object_name(s, o), hr_scene_object_name(s, q)) != 0,
                   "objects %d and %d share a name", o, q);
  for (int m = 0; m < s->nmats; m++)
    FUZZ_REQUIRE(s->mats[m].base == m, "OBJ material %d is a variant of %d", m, s->mats[m].base);
}

/* Checks the outcome of one parse of OBJ text 'obj' (olen bytes): the scene after HR_OK (and one
 * input record per `f` statement), the message after an error: it starts with "PREFIX:" or
 * (unless NULL) with 'prefix2' (the directory of the MTL files). */
static inline void fuzz_check_result(hr_status st, const hr_scene *s, const hr_err *err,
                                     const char *obj, size_t olen, const char *prefix,
                                     const char *prefix2) {
  if (st == HR_OK) {
    fuzz_check_scene(s);
    long faces = fuzz_count_faces(obj, olen);
    FUZZ_REQUIRE(s->ninputs == faces, "%d input records for %ld f statements", s->ninputs, faces);
    return;
  }
  FUZZ_REQUIRE(st == HR_ERR_PARSE || st == HR_ERR_INVALID || st == HR_ERR_NOMEM,
               "unexpected status %d (%s)", (int)st, err->msg);
  FUZZ_REQUIRE(s == NULL, "error %d but a scene", (int)st);
  FUZZ_REQUIRE(err->msg[0] != '\0', "error %d without a message", (int)st);
  FUZZ_REQUIRE(strchr(err->msg, '\n') == NULL, "message with a newline: %s", err->msg);
  size_t n1 = strlen(prefix), n2 = prefix2 ? strlen(prefix2) : 0;
  FUZZ_REQUIRE((strncmp(err->msg, prefix, n1) == 0 && err->msg[n1] == ':') ||
                   (prefix2 && strncmp(err->msg, prefix2, n2) == 0),
               "message does not start with '%s:'%s%s: %s", prefix, prefix2 ? " or " : "",
               prefix2 ? prefix2 : "", err->msg);
}

/* Warning sink: every warning is one non-empty line. */
static inline void fuzz_log(void *ud, const char *msg) {
  (void)ud;
  FUZZ_REQUIRE(msg && msg[0] && strchr(msg, '\n') == NULL, "bad warning '%s'", msg ? msg : "");
}

#endif
