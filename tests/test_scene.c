/* test_scene.c: polygons becoming surfaces (src/scene.c): convex and non-convex polygons keep
 * their area and orientation (ear clipping), self-crossing polygons are refused, large convex
 * polygons split in linear time, and every call records its input row. */
#include "testutil.h"
#include "vec.h"

#include <string.h>
#include <time.h>

/* Adds polygon v[0..n) to a fresh scene; returns the scene (caller destroys) and the result. */
static hr_scene *one(const hr_vec3 *v, int n, hr_poly_result *res) {
  hr_scene *s;
  hr_scene_create("t", &s);
  int m = t_mat(s, "m", 0.5, 0);
  hr_status st = hr_scene_add_polygon(s, v, n, m, res);
  CHECK(st == HR_OK, "status %d", (int)st);
  return s;
}

/* Total area and the orientation check of every surface (normal along +z). */
static void check_tris(const hr_scene *s, double want_area, const char *what) {
  double a = 0;
  int flipped = 0;
  for (int i = 0; i < s->nsurfs; i++) {
    a += s->surfs[i].area;
    flipped += s->surfs[i].normal.z < 0.999;
  }
  CHECK_REL(a, want_area, 1e-12, what);
  CHECK(flipped == 0, "%s: %d surfaces face the wrong way", what, flipped);
  CHECK(s->npolys == 1 && s->ninputs == 1 && s->inputs[0].kind == HR_INPUT_SOLVED,
        "%s: npolys %d ninputs %d", what, s->npolys, s->ninputs);
  CHECK_REL(s->poly_area[0], want_area, 1e-12, what);
}

static void nonconvex(void) {
  printf("non-convex polygons\n");
  hr_poly_result res;
  /* The pentagon: a dent at (2,1); area 6, not the fan's 9. */
  hr_vec3 p[5] = {tv(0, 0, 0), tv(3, 0, 0), tv(3, 3, 0), tv(2, 1, 0), tv(0, 3, 0)};
  hr_scene *s = one(p, 5, &res);
  CHECK(res == HR_POLY_ADDED && s->nsurfs == 3, "pentagon: res %d, %d surfaces", res, s->nsurfs);
  check_tris(s, 6, "dented pentagon area");
  hr_scene_destroy(&s);
  /* Every rotation of the vertex list gives the same area. */
  for (int r = 1; r < 5; r++) {
    hr_vec3 q[5];
    for (int k = 0; k < 5; k++) q[k] = p[(k + r) % 5];
    s = one(q, 5, &res);
    check_tris(s, 6, "rotated pentagon area");
    hr_scene_destroy(&s);
  }
  /* An L shape with collinear vertices along its edges: area 3. */
  hr_vec3 l[8] = {tv(0, 0, 0), tv(1, 0, 0), tv(2, 0, 0), tv(2, 1, 0),
                  tv(1, 1, 0), tv(1, 2, 0), tv(0, 2, 0), tv(0, 1, 0)};
  s = one(l, 8, &res);
  check_tris(s, 3, "L shape area");
  hr_scene_destroy(&s);
  /* A star (10 vertices), tilted out of the xy plane: area by the shoelace formula. */
  hr_vec3 star[10];
  double area2 = 0;
  for (int k = 0; k < 10; k++) {
    double a = 2 * M_PI * k / 10, rad = k % 2 ? 0.4 : 1.0;
    star[k] = tv(rad * cos(a), rad * sin(a), 0);
  }
  for (int k = 0; k < 10; k++)
    area2 += star[k].x * star[(k + 1) % 10].y - star[(k + 1) % 10].x * star[k].y;
  s = one(star, 10, &res);
  check_tris(s, 0.5 * area2, "star area");
  hr_scene_destroy(&s);
  /* A bow tie crosses itself: refused, nothing added, no input row (the caller reports it). */
  hr_vec3 bow[6] = {tv(0, 0, 0), tv(2, 0, 0), tv(1, 1, 0), tv(2, 2, 0), tv(0, 2, 0),
                    tv(1.5, 1, 0)};
  s = one(bow, 6, &res);
  CHECK(res == HR_POLY_NOT_SIMPLE && s->nsurfs == 0 && s->npolys == 0 && s->ninputs == 0,
        "bow tie: res %d, %d surfaces, %d inputs", res, s->nsurfs, s->ninputs);
  hr_scene_destroy(&s);
  /* A quad bow tie with unequal lobes (edges 0-1 and 2-3 cross): neither diagonal splits it
   * into two triangles facing the same way. */
  hr_vec3 bow4[4] = {tv(0, 0, 0), tv(0, 1, 0), tv(1, 0, 0), tv(2, 2, 0)};
  s = one(bow4, 4, &res);
  CHECK(res == HR_POLY_NOT_SIMPLE && s->nsurfs == 0 && s->ninputs == 0,
        "quad bow tie: res %d, %d surfaces", res, s->nsurfs);
  hr_scene_destroy(&s);
  /* A pentagram turns left at every vertex but winds twice: not convex, and crossing itself. */
  hr_vec3 pent[5];
  for (int k = 0; k < 5; k++) pent[k] = tv(cos(4 * M_PI * k / 5), sin(4 * M_PI * k / 5), 0);
  s = one(pent, 5, &res);
  CHECK(res == HR_POLY_NOT_SIMPLE && s->nsurfs == 0 && s->ninputs == 0,
        "pentagram: res %d, %d surfaces", res, s->nsurfs);
  hr_scene_destroy(&s);
}

/* A unit box (floor emitting) moved 'off' along every axis; returns hr_solver_create's status. */
static hr_status far_box(double off) {
  hr_scene *s;
  hr_scene_create("far", &s);
  int m = t_mat(s, "m", 0.5, 0), e = t_mat(s, "e", 0.5, 1);
  hr_poly_result res;
  hr_vec3 q[4] = {tv(off, off, off), tv(off + 1, off, off), tv(off + 1, off + 1, off),
                  tv(off, off + 1, off)};
  hr_scene_add_polygon(s, q, 4, e, &res);
  hr_vec3 c[4] = {q[3], q[2], q[1], q[0]};
  for (int k = 0; k < 4; k++) c[k].z += 1;
  hr_scene_add_polygon(s, c, 4, m, &res);
  hr_solver *sv = NULL;
  hr_err err = {0};
  hr_status st = hr_solver_create(s, NULL, &sv, &err);
  if (st != HR_OK) CHECK(strstr(err.msg, "near the origin") != NULL, "message: %s", err.msg);
  hr_solver_destroy(&sv);
  hr_scene_destroy(&s);
  return st;
}

static void far_from_origin(void) {
  printf("scenes far from the origin for their size\n");
  CHECK(far_box(100) == HR_OK, "a unit box at 100 is refused");
  CHECK(far_box(1e4) == HR_ERR_INVALID, "a unit box at 1e4 is solved in float");
}

static void large_convex(void) {
  printf("large convex polygon (linear time)\n");
  const int n = 40000;
  hr_vec3 *c = malloc((size_t)n * sizeof *c);
  for (int k = 0; k < n; k++) c[k] = tv(cos(2 * M_PI * k / n), sin(2 * M_PI * k / n), 0);
  clock_t t0 = clock();
  hr_poly_result res;
  hr_scene *s = one(c, n, &res);
  double secs = (double)(clock() - t0) / CLOCKS_PER_SEC;
  printf("  %d-gon: %d surfaces in %.3f s\n", n, s->nsurfs, secs);
  CHECK(res == HR_POLY_ADDED && s->nsurfs == n - 2, "circle: res %d, %d surfaces", res, s->nsurfs);
  CHECK(secs < 1.0, "a %d-gon took %.2f s (quadratic?)", n, secs);
  hr_scene_destroy(&s);
  free(c);
}

int main(void) {
  nonconvex();
  far_from_origin();
  large_convex();
  return t_done("test_scene");
}
