/* test_scene.c: polygons becoming surfaces (src/scene.c): convex and non-convex polygons keep
 * their area and orientation (ear clipping), keyhole polygons (holes joined by bridges) lose their
 * holes' area, self-crossing polygons are refused, large convex polygons split in linear time,
 * and every call records its input row. */
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
  /* Edges (5,1)-(0,0) and (4,1)-(2,0) cross; ear clipping alone found five left-turning ears
   * (overlapping, total 4) and accepted it. */
  hr_vec3 cross[5] = {tv(6, 4, 0), tv(5, 1, 0), tv(0, 0, 0), tv(4, 1, 0), tv(2, 0, 0)};
  s = one(cross, 5, &res);
  CHECK(res == HR_POLY_NOT_SIMPLE && s->nsurfs == 0 && s->ninputs == 0,
        "crossing edges: res %d, %d surfaces", res, s->nsurfs);
  hr_scene_destroy(&s);
  /* The dented pentagon with its first vertex repeated at the end (a zero-length edge): area 6 */
  hr_vec3 p6[6] = {p[0], p[1], p[2], p[3], p[4], p[0]};
  s = one(p6, 6, &res);
  CHECK(res == HR_POLY_ADDED, "closing vertex repeated: res %d", res);
  check_tris(s, 6, "pentagon with its first vertex repeated");
  hr_scene_destroy(&s);
}

/* Adds polygon q[0..n) rotated to start at vertex r; returns the scene and sets *res. */
static hr_scene *one_rotated(const hr_vec3 *q, int n, int r, hr_poly_result *res) {
  hr_vec3 w[32];
  for (int k = 0; k < n; k++) w[k] = q[(k + r) % n];
  return one(w, n, res);
}

/* Number of surfaces whose centroid lies in the open box (x0, x1) x (y0, y1) of the z = 0 plane:
 * inside a hole when it should be 0. */
static int centroids_in(const hr_scene *s, double x0, double y0, double x1, double y1) {
  int in = 0;
  for (int i = 0; i < s->nsurfs; i++) {
    const hr_surface *f = &s->surfs[i];
    double cx = 0, cy = 0;
    for (int k = 0; k < f->nverts; k++) {
      cx += f->v[k].x / f->nverts;
      cy += f->v[k].y / f->nverts;
    }
    in += cx > x0 && cx < x1 && cy > y0 && cy < y1;
  }
  return in;
}

/* 1 if the polygon was refused as not simple, with nothing added and no input row. */
static int refused(const hr_scene *s, hr_poly_result res) {
  return res == HR_POLY_NOT_SIMPLE && s->nsurfs == 0 && s->npolys == 0 && s->ninputs == 0;
}

static void keyholes(void) {
  printf("keyhole polygons (holes joined by bridges)\n");
  hr_poly_result res;
  /* A 4x4 square with a 2x2 hole, written as one loop: round the outside from (0,0), along the
   * bridge to (1,1), round the hole clockwise, back along the bridge. Area 16 - 4, whichever
   * vertex the loop starts at; no triangle in the hole. */
  hr_vec3 sq[10] = {tv(0, 0, 0), tv(4, 0, 0), tv(4, 4, 0), tv(0, 4, 0), tv(0, 0, 0),
                    tv(1, 1, 0), tv(1, 3, 0), tv(3, 3, 0), tv(3, 1, 0), tv(1, 1, 0)};
  for (int r = 0; r < 10; r++) {
    hr_scene *s = one_rotated(sq, 10, r, &res);
    CHECK(res == HR_POLY_ADDED && s->nsurfs == 8, "square with hole, start %d: res %d, %d surfaces",
          r, res, s->nsurfs);
    if (res != HR_POLY_ADDED) {
      hr_scene_destroy(&s);
      continue;
    }
    check_tris(s, 12, "square with a bridged hole: area");
    CHECK(s->poly_area[0] == 12, "start %d: area %.17g, not exactly 12", r, s->poly_area[0]);
    CHECK(centroids_in(s, 1, 1, 3, 3) == 0, "start %d: %d triangles in the hole", r,
          centroids_in(s, 1, 1, 3, 3));
    CHECK(centroids_in(s, 0, 0, 4, 4) == s->nsurfs, "start %d: triangles outside the square", r);
    hr_scene_destroy(&s);
  }
  /* The hole's loop wound the same way as the outside: inside the hole the loop winds twice. */
  hr_vec3 ccw[10] = {tv(0, 0, 0), tv(4, 0, 0), tv(4, 4, 0), tv(0, 4, 0), tv(0, 0, 0),
                     tv(1, 1, 0), tv(3, 1, 0), tv(3, 3, 0), tv(1, 3, 0), tv(1, 1, 0)};
  for (int r = 0; r < 10; r += 3) {
    hr_scene *s = one_rotated(ccw, 10, r, &res);
    CHECK(refused(s, res), "hole wound wrongly, start %d: res %d, %d surfaces", r, res,
          s->nsurfs);
    hr_scene_destroy(&s);
  }
  /* A diamond hole reached by a bridge from the corner (0,4); its bottom vertex touches the
   * bottom edge of the square at (2,0): a contact other than the bridge, refused. Lifted by
   * 2^-10 off that edge it is an ordinary hole: area 16 - (2 - 2^-10). */
  const double lift[2] = {0, 1.0 / 1024};
  for (int t = 0; t < 2; t++) {
    hr_vec3 dia[10] = {tv(0, 0, 0), tv(4, 0, 0),        tv(4, 4, 0), tv(0, 4, 0), tv(2, 2, 0),
                       tv(3, 1, 0), tv(2, lift[t], 0), tv(1, 1, 0), tv(2, 2, 0), tv(0, 4, 0)};
    hr_scene *s = one(dia, 10, &res);
    if (t == 0) {
      CHECK(refused(s, res), "hole touching the edge: res %d, %d surfaces", res, s->nsurfs);
    } else {
      CHECK(res == HR_POLY_ADDED && s->nsurfs == 8, "hole near the edge: res %d, %d surfaces",
            res, s->nsurfs);
      check_tris(s, 14 + lift[t], "square with a diamond hole 2^-10 off its edge: area");
      int in = 0; /* centroids inside the diamond |x - 2| + |y - 1| < 1 */
      for (int i = 0; i < s->nsurfs; i++) {
        const hr_surface *f = &s->surfs[i];
        double cx = (f->v[0].x + f->v[1].x + f->v[2].x) / 3;
        double cy = (f->v[0].y + f->v[1].y + f->v[2].y) / 3;
        in += fabs(cx - 2) + fabs(cy - 1) < 1 - lift[t];
      }
      CHECK(in == 0, "%d triangles in the diamond hole", in);
    }
    hr_scene_destroy(&s);
  }
  /* Two holes bridged from the same corner (0,0) of a 6x6 square: area 36 - 1 - 1. Leaving the
   * corner, the loop must take the hole nearer its incoming edge first (the one towards (0,6));
   * in the other order its two passes through the corner cross there. */
  hr_vec3 two[16] = {tv(0, 0, 0), tv(6, 0, 0), tv(6, 6, 0), tv(0, 6, 0), tv(0, 0, 0), tv(1, 4, 0),
                     tv(1, 5, 0), tv(2, 5, 0), tv(2, 4, 0), tv(1, 4, 0), tv(0, 0, 0), tv(4, 1, 0),
                     tv(4, 2, 0), tv(5, 2, 0), tv(5, 1, 0), tv(4, 1, 0)};
  for (int r = 0; r < 16; r += 5) {
    hr_scene *s = one_rotated(two, 16, r, &res);
    CHECK(res == HR_POLY_ADDED, "two holes, start %d: res %d", r, res);
    check_tris(s, 34, "two holes bridged from one corner: area");
    CHECK(centroids_in(s, 1, 4, 2, 5) + centroids_in(s, 4, 1, 5, 2) == 0,
          "start %d: triangles in a hole", r);
    hr_scene_destroy(&s);
  }
  hr_vec3 swapped[16];
  for (int k = 0; k < 16; k++) /* outside, hole (4,1) first, the corner, hole (1,4) */
    swapped[k] = k < 5 ? two[k] : k < 10 ? two[k + 6] : k == 10 ? two[4] : two[k - 6];
  hr_scene *s = one(swapped, 16, &res);
  CHECK(refused(s, res), "two holes in the crossing order: res %d, %d surfaces", res, s->nsurfs);
  hr_scene_destroy(&s);
  /* A square written twice over (as the face of assimp's box_longline.obj, 234 times) winds
   * twice round its inside; a spike (an edge there and straight back) encloses nothing. */
  hr_vec3 twice[8] = {tv(0, 0, 0), tv(1, 0, 0), tv(1, 1, 0), tv(0, 1, 0),
                      tv(0, 0, 0), tv(1, 0, 0), tv(1, 1, 0), tv(0, 1, 0)};
  s = one(twice, 8, &res);
  CHECK(refused(s, res), "square written twice: res %d, %d surfaces", res, s->nsurfs);
  hr_scene_destroy(&s);
  hr_vec3 spike[6] = {tv(0, 0, 0), tv(2, 0, 0), tv(2, 2, 0), tv(1, 1, 0), tv(1, 0.5, 0),
                      tv(1, 1, 0)};
  s = one(spike, 6, &res);
  CHECK(refused(s, res), "spike: res %d, %d surfaces", res, s->nsurfs);
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
  keyholes();
  far_from_origin();
  large_convex();
  return t_done("test_scene");
}
