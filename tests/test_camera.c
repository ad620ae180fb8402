/* test_camera.c: the automatic camera (hr_scene_auto_camera) for scenes without one: an open box
 * is seen through its opening, a closed room from inside (away from an object in a corner), a
 * closed object from outside, the up axis of y-up and z-up rooms, the Cornell box OBJ, and an
 * empty scene. */
#include "testutil.h"

#include <string.h>
#include <unistd.h>

static hr_vec3 sub(hr_vec3 a, hr_vec3 b) { return tv(a.x - b.x, a.y - b.y, a.z - b.z); }

static hr_vec3 unit(hr_vec3 a) {
  double l = sqrt(a.x * a.x + a.y * a.y + a.z * a.z);
  return tv(a.x / l, a.y / l, a.z / l);
}

static int inside(hr_vec3 p, hr_vec3 lo, hr_vec3 hi) {
  return p.x > lo.x && p.x < hi.x && p.y > lo.y && p.y < hi.y && p.z > lo.z && p.z < hi.z;
}

static int finite_cam(const hr_camera *c) {
  return isfinite(c->eye.x) && isfinite(c->eye.y) && isfinite(c->eye.z) && isfinite(c->at.x) &&
         isfinite(c->at.y) && isfinite(c->at.z) && isfinite(c->fov_deg) && c->fov_deg > 0 &&
         c->fov_deg < 180;
}

static void print_cam(const char *what, const hr_camera *c) {
  printf("%-28s eye (%.3f %.3f %.3f) at (%.3f %.3f %.3f) up (%g %g %g) fov %g\n", what, c->eye.x,
         c->eye.y, c->eye.z, c->at.x, c->at.y, c->at.z, c->up.x, c->up.y, c->up.z, c->fov_deg);
}

/* Inward box [lo,hi] without the faces whose bit is set in 'skip' (bit k: face k of t_box's
 * order -x, +x, -y, +y, -z, +z). */
static hr_scene *open_box(hr_vec3 lo, hr_vec3 hi, int skip) {
  hr_scene *s;
  if (hr_scene_create("box", &s) != HR_OK) abort();
  int grey = t_mat(s, "grey", 0.6, 0);
  int lamp = t_mat(s, "lamp", 0.5, 10);
  double X0 = lo.x, Y0 = lo.y, Z0 = lo.z, X1 = hi.x, Y1 = hi.y, Z1 = hi.z;
  hr_vec3 f[6][4] = {
      {{X0, Y0, Z0}, {X0, Y0, Z1}, {X0, Y1, Z1}, {X0, Y1, Z0}},
      {{X1, Y0, Z0}, {X1, Y1, Z0}, {X1, Y1, Z1}, {X1, Y0, Z1}},
      {{X0, Y0, Z0}, {X1, Y0, Z0}, {X1, Y0, Z1}, {X0, Y0, Z1}},
      {{X0, Y1, Z0}, {X0, Y1, Z1}, {X1, Y1, Z1}, {X1, Y1, Z0}},
      {{X0, Y0, Z0}, {X0, Y1, Z0}, {X1, Y1, Z0}, {X1, Y0, Z0}},
      {{X0, Y0, Z1}, {X1, Y0, Z1}, {X1, Y1, Z1}, {X0, Y1, Z1}},
  };
  for (int k = 0; k < 6; k++)
    if (!(skip & (1 << k))) t_quad(s, grey, f[k][3], f[k][2], f[k][1], f[k][0]); /* inward */
  (void)lamp;
  return s;
}

/* A small lamp under the ceiling (y-up) facing down, so that the scenes are solvable. */
static void add_lamp(hr_scene *s, hr_vec3 c, double y) {
  int lamp = hr_scene_find_material(s, "lamp");
  t_quad(s, lamp, tv(c.x - 0.2, y, c.z - 0.2), tv(c.x - 0.2, y, c.z + 0.2),
         tv(c.x + 0.2, y, c.z + 0.2), tv(c.x + 0.2, y, c.z - 0.2));
}

static void test_open_box(void) {
  hr_vec3 lo = tv(-1, 0, -1), hi = tv(1, 2, 1);
  /* open at +z: the camera must be on the +z side looking towards -z */
  hr_scene *s = open_box(lo, hi, 1 << 5);
  add_lamp(s, tv(0, 0, 0), 1.98);
  hr_camera c;
  hr_scene_auto_camera(s, &c);
  print_cam("open box (+z open)", &c);
  hr_vec3 d = unit(sub(c.at, c.eye));
  CHECK(finite_cam(&c), "non-finite camera");
  CHECK(c.eye.z > hi.z, "eye z %g not on the open +z side", c.eye.z);
  CHECK(d.z < -0.8, "view direction (%g %g %g) does not look towards -z", d.x, d.y, d.z);
  CHECK(c.up.x == 0 && c.up.y == 1 && c.up.z == 0, "up (%g %g %g)", c.up.x, c.up.y, c.up.z);
  CHECK(inside(c.at, lo, hi), "target outside the box");
  hr_scene_destroy(&s);

  /* open at -x: seen from -x */
  s = open_box(lo, hi, 1 << 0);
  hr_scene_auto_camera(s, &c);
  print_cam("open box (-x open)", &c);
  d = unit(sub(c.at, c.eye));
  CHECK(c.eye.x < lo.x && d.x > 0.8, "-x open box: eye x %g, direction x %g", c.eye.x, d.x);
  hr_scene_destroy(&s);
}

static void test_closed_box(void) {
  hr_vec3 lo = tv(0, 0, 0), hi = tv(6, 3, 5);
  hr_scene *s = open_box(lo, hi, 0);
  add_lamp(s, tv(3, 0, 2.5), 2.98);
  hr_camera c;
  hr_scene_auto_camera(s, &c);
  print_cam("closed inward room", &c);
  CHECK(finite_cam(&c), "non-finite camera");
  CHECK(inside(c.eye, lo, hi), "eye (%g %g %g) not inside the closed room", c.eye.x, c.eye.y,
        c.eye.z);
  CHECK(inside(c.at, lo, hi), "target outside the room");
  CHECK(c.fov_deg >= 60, "fov %g is not wide", c.fov_deg);
  CHECK(c.up.y == 1, "up (%g %g %g)", c.up.x, c.up.y, c.up.z);
  CHECK(c.at.y < c.eye.y, "inside view does not look down");
  /* a block in the (low x, low z) corner: the camera takes another corner, not behind it */
  int grey = hr_scene_find_material(s, "grey");
  int mats[6] = {grey, grey, grey, grey, grey, grey};
  t_box(s, mats, tv(0.3, 0, 0.3), tv(1.8, 1.5, 1.8), 0);
  hr_scene_auto_camera(s, &c);
  print_cam("closed room + corner block", &c);
  CHECK(inside(c.eye, lo, hi), "eye not inside the room with a block");
  CHECK(!(c.eye.x < 3 && c.eye.z < 2.5), "eye (%g %g %g) in the block's corner", c.eye.x,
        c.eye.y, c.eye.z);
  hr_scene_destroy(&s);

  /* a closed outward box (an object): seen from outside */
  hr_scene_create("cube", &s);
  grey = t_mat(s, "grey", 0.6, 0);
  int m6[6] = {grey, grey, grey, grey, grey, grey};
  t_box(s, m6, tv(-1, -1, -1), tv(1, 1, 1), 0);
  hr_scene_auto_camera(s, &c);
  print_cam("closed outward cube", &c);
  CHECK(!inside(c.eye, tv(-1, -1, -1), tv(1, 1, 1)), "eye inside the cube");
  CHECK(c.fov_deg < 60, "outside view with fov %g", c.fov_deg);
  hr_scene_destroy(&s);
}

/* The same closed room, modelled y-up and z-up (6 x 5 floor, 3 high). */
static void test_up_axis(void) {
  for (int zup = 0; zup < 2; zup++) {
    hr_vec3 lo = tv(0, 0, 0), hi = zup ? tv(6, 5, 3) : tv(6, 3, 5);
    hr_scene *s = open_box(lo, hi, 0);
    hr_camera c;
    hr_scene_auto_camera(s, &c);
    print_cam(zup ? "z-up room" : "y-up room", &c);
    if (zup)
      CHECK(c.up.x == 0 && c.up.y == 0 && c.up.z == 1, "z-up room: up (%g %g %g)", c.up.x, c.up.y,
            c.up.z);
    else
      CHECK(c.up.x == 0 && c.up.y == 1 && c.up.z == 0, "y-up room: up (%g %g %g)", c.up.x, c.up.y,
            c.up.z);
    CHECK(inside(c.eye, lo, hi), "%s: eye not inside", zup ? "z-up" : "y-up");
    double h_eye = zup ? c.eye.z : c.eye.y, h_at = zup ? c.at.z : c.at.y;
    CHECK(h_at < h_eye, "%s: not looking down", zup ? "z-up" : "y-up");
    hr_scene_destroy(&s);
  }
  /* a cube-shaped box open at +z is not taken for z-up */
  hr_scene *s = open_box(tv(-1, -1, -1), tv(1, 1, 1), 1 << 5);
  hr_camera c;
  hr_scene_auto_camera(s, &c);
  CHECK(c.up.y == 1, "open cube: up (%g %g %g)", c.up.x, c.up.y, c.up.z);
  hr_scene_destroy(&s);
}

static void test_cornell_obj(void) {
  const char *path = HR_SOURCE_DIR "/tests/data/cornell/CornellBox-Original.obj"; /* vendored */
  if (access(path, R_OK) != 0) {
    printf("cornell obj: skipped (%s missing)\n", path);
    return;
  }
  hr_scene *s = NULL;
  hr_err err;
  CHECK(hr_scene_load_obj(path, NULL, &s, &err) == HR_OK, "load: %s", err.msg);
  if (!s) return;
  CHECK(!s->has_camera, "the OBJ has no camera");
  hr_vec3 lo, hi;
  hr_scene_bounds(s, &lo, &hi);
  hr_camera c;
  hr_scene_auto_camera(s, &c);
  print_cam("CornellBox-Original.obj", &c);
  hr_vec3 d = unit(sub(c.at, c.eye));
  CHECK(c.eye.z > hi.z && d.z < -0.8, "cornell: eye z %g, direction z %g (open side is +z)",
        c.eye.z, d.z);
  CHECK(c.eye.y > lo.y && c.eye.y < hi.y, "cornell: eye height %g outside the box's %g..%g",
        c.eye.y, lo.y, hi.y);
  CHECK(c.up.y == 1, "cornell: up (%g %g %g)", c.up.x, c.up.y, c.up.z);
  hr_scene_destroy(&s);
}

static void test_empty(void) {
  hr_scene *s;
  hr_scene_create("empty", &s);
  hr_camera c;
  memset(&c, 0, sizeof c);
  hr_scene_auto_camera(s, &c);
  CHECK(finite_cam(&c), "empty scene: non-finite camera");
  hr_scene_destroy(&s);
}

int main(void) {
  test_open_box();
  test_closed_box();
  test_up_axis();
  test_cornell_obj();
  test_empty();
  return t_done("test_camera");
}
