/* testutil.h: tiny assertion macros and scene builders shared by the C tests. */
#ifndef HR_TESTUTIL_H
#define HR_TESTUTIL_H

#include "hrad.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

static int t_failures = 0;

#define CHECK(cond, ...)                                                    \
  do {                                                                      \
    if (!(cond)) {                                                          \
      fprintf(stderr, "%s:%d: FAILED: %s: ", __FILE__, __LINE__, #cond);    \
      fprintf(stderr, __VA_ARGS__);                                         \
      fprintf(stderr, "\n");                                                \
      t_failures++;                                                         \
    }                                                                       \
  } while (0)

#define CHECK_REL(got, want, tol, what)                                               \
  do {                                                                                \
    double g_ = (got), w_ = (want);                                                   \
    double e_ = fabs(g_ - w_) / fabs(w_);                                             \
    printf("  %-48s got %.6f want %.6f rel.err %.2e (tol %.1e)\n", what, g_, w_, e_,  \
           (double)(tol));                                                            \
    CHECK(e_ <= (tol), "%s: got %.8g want %.8g", what, g_, w_);                       \
  } while (0)

static inline int t_done(const char *name) {
  if (t_failures) {
    fprintf(stderr, "%s: %d check(s) failed\n", name, t_failures);
    return 1;
  }
  printf("%s: all checks passed\n", name);
  return 0;
}

static inline hr_vec3 tv(double x, double y, double z) { return (hr_vec3){x, y, z}; }

/* Adds a material and returns its index; aborts on failure. */
static inline int t_mat(hr_scene *s, const char *name, double rho, double e) {
  double r[3] = {rho, rho, rho}, E[3] = {e, e, e};
  int idx;
  if (hr_scene_add_material(s, name, r, E, &idx) != HR_OK) abort();
  return idx;
}

static inline void t_poly(hr_scene *s, int mat, int n, const hr_vec3 *v) {
  hr_poly_result res;
  if (hr_scene_add_polygon(s, v, n, mat, &res) != HR_OK || res != HR_POLY_ADDED) {
    fprintf(stderr, "t_poly: polygon not added\n");
    abort();
  }
}

static inline void t_quad(hr_scene *s, int mat, hr_vec3 a, hr_vec3 b, hr_vec3 c, hr_vec3 d) {
  hr_vec3 v[4] = {a, b, c, d};
  t_poly(s, mat, 4, v);
}

/* Axis-aligned box [lo, hi]; faces point inward when 'inward', else outward. Uses materials
 * mats[0..5] for -x, +x, -y, +y, -z, +z faces. */
static inline void t_box(hr_scene *s, const int mats[6], hr_vec3 lo, hr_vec3 hi, int inward) {
  double X0 = lo.x, Y0 = lo.y, Z0 = lo.z, X1 = hi.x, Y1 = hi.y, Z1 = hi.z;
  hr_vec3 f[6][4] = {
      {{X0, Y0, Z0}, {X0, Y0, Z1}, {X0, Y1, Z1}, {X0, Y1, Z0}}, /* -x, normal -x (outward) */
      {{X1, Y0, Z0}, {X1, Y1, Z0}, {X1, Y1, Z1}, {X1, Y0, Z1}}, /* +x */
      {{X0, Y0, Z0}, {X1, Y0, Z0}, {X1, Y0, Z1}, {X0, Y0, Z1}}, /* -y */
      {{X0, Y1, Z0}, {X0, Y1, Z1}, {X1, Y1, Z1}, {X1, Y1, Z0}}, /* +y */
      {{X0, Y0, Z0}, {X0, Y1, Z0}, {X1, Y1, Z0}, {X1, Y0, Z0}}, /* -z */
      {{X0, Y0, Z1}, {X1, Y0, Z1}, {X1, Y1, Z1}, {X0, Y1, Z1}}, /* +z */
  };
  for (int k = 0; k < 6; k++) {
    if (inward)
      t_quad(s, mats[k], f[k][3], f[k][2], f[k][1], f[k][0]);
    else
      t_quad(s, mats[k], f[k][0], f[k][1], f[k][2], f[k][3]);
  }
}

/* Solves 's' with options 'o' (NULL = defaults); aborts on error. */
static inline hr_solver *t_solve(const hr_scene *s, const hr_options *o) {
  hr_solver *sv;
  hr_err err = {{0}};
  if (hr_solver_create(s, o, &sv, &err) != HR_OK || hr_solver_run(sv, NULL, NULL, &err) != HR_OK) {
    fprintf(stderr, "solve failed: %s\n", err.msg);
    abort();
  }
  return sv;
}

#endif
