/* test_pt.c: the reference path tracer (pt.c) against closed forms (../shared/REFERENCE-VALUES.md):
 * the one-bounce set-up (receiver B = rho F) for opposed and perpendicular unit squares, the
 * furnace (B = E / (1 - rho)), total power in a closed box with a small light, one-sidedness,
 * the image (furnace seen from inside, exact pixel coverage of a quad, alignment with
 * hr_render), thread invariance and bad arguments.
 *
 * Tolerances: a Monte Carlo mean must lie within 4 of its reported standard errors of the exact
 * value (a 6e-5 chance of failing for a correct tracer with Gaussian errors, but the seeds are
 * fixed, so a pass stays a pass) AND within 0.5% of it, so a tracer with a large reported error
 * cannot pass by noise alone. Path counts are chosen so that 4 se is below the 0.5% cap. */
#include "testutil.h"
#include "output.h"

#include <string.h>
#include <time.h>

#define KSE 4.0    /* standard errors allowed */
#define CAP 0.005  /* relative cap */

static double now_s(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}

static hr_scene *new_scene(const char *name) {
  hr_scene *s;
  if (hr_scene_create(name, &s) != HR_OK) abort();
  return s;
}

/* Parallelogram o, o+u, o+u+v, o+v: its front normal is u x v. */
static void rect(hr_scene *s, int mat, hr_vec3 o, hr_vec3 u, hr_vec3 v) {
  hr_vec3 ou = tv(o.x + u.x, o.y + u.y, o.z + u.z), ov = tv(o.x + v.x, o.y + v.y, o.z + v.z);
  t_quad(s, mat, o, ou, tv(ou.x + v.x, ou.y + v.y, ou.z + v.z), ov);
}

static hr_pt_options opts(int64_t paths) {
  hr_pt_options o;
  hr_pt_options_default(&o);
  o.paths = paths;
  o.threads = 2;
  return o;
}

/* Runs hr_pt_polys on 's'; mean and se get s->npolys rows (caller frees). */
static void trace(const hr_scene *s, int64_t paths, double (**mean)[3], double (**se)[3]) {
  *mean = malloc((size_t)s->npolys * sizeof **mean);
  *se = malloc((size_t)s->npolys * sizeof **se);
  hr_pt_options o = opts(paths);
  hr_err err = {{0}};
  hr_status st = hr_pt_polys(s, &o, *mean, *se, &err);
  if (st != HR_OK) {
    fprintf(stderr, "hr_pt_polys: %s\n", err.msg);
    abort();
  }
}

/* Checks est +- se against 'exact': within KSE se and within the relative cap CAP. */
static void check_mc(const char *what, double est, double se, double exact) {
  double d = fabs(est - exact);
  printf("  %-44s est %.6f exact %.6f se %.2e  |d| = %.2f se = %.3f%%\n", what, est, exact, se,
         se > 0 ? d / se : 0, 100 * d / fabs(exact));
  CHECK(d <= KSE * se, "%s: %.6f is %.1f se from %.6f", what, est, d / se, exact);
  CHECK(d <= CAP * fabs(exact), "%s: %.6f off %.6f by more than %.1f%%", what, est, exact,
        100 * CAP);
  CHECK(KSE * se <= CAP * fabs(exact), "%s: se %.2e too large for the %.1f%% cap", what, se,
        100 * CAP);
}

/* ---------------------------------------------------------------- closed forms */

/* Directly opposed a x b rectangles at distance c (Howell). */
static double f_opposed(double a, double b, double c) {
  double X = a / c, Y = b / c, x2 = 1 + X * X, y2 = 1 + Y * Y;
  return 2 / (M_PI * X * Y) *
         (log(sqrt(x2 * y2 / (x2 + Y * Y))) + X * sqrt(y2) * atan(X / sqrt(y2)) +
          Y * sqrt(x2) * atan(Y / sqrt(x2)) - X * atan(X) - Y * atan(Y));
}

/* Perpendicular rectangles sharing an edge of length l: from plate 1 (width w) to plate 2
 * (height h) (Howell). */
static double f_perp(double l, double w, double h) {
  double W = w / l, H = h / l, W2 = W * W, H2 = H * H, S = sqrt(H2 + W2);
  double t = (1 + W2) * (1 + H2) / (1 + W2 + H2);
  t *= pow(W2 * (1 + W2 + H2) / ((1 + W2) * (W2 + H2)), W2);
  t *= pow(H2 * (1 + W2 + H2) / ((1 + H2) * (W2 + H2)), H2);
  return 1 / (M_PI * W) * (W * atan(1 / W) + H * atan(1 / H) - S * atan(1 / S) + 0.25 * log(t));
}

static void test_closed_forms(void) {
  CHECK(fabs(f_opposed(1, 1, 1) - 0.19982) < 5e-6, "f_opposed(1,1,1) = %.6f", f_opposed(1, 1, 1));
  CHECK(fabs(f_opposed(1, 1, 0.5) - 0.41525) < 5e-6, "f_opposed(.5) = %.6f", f_opposed(1, 1, 0.5));
  CHECK(fabs(f_perp(1, 1, 1) - 0.20004) < 5e-6, "f_perp(1,1,1) = %.6f", f_perp(1, 1, 1));
  CHECK(fabs(f_perp(1, 2, 1) - 0.11643) < 5e-6, "f_perp(1,2,1) = %.6f", f_perp(1, 2, 1));
  CHECK(fabs(f_perp(1, 1, 2) - 0.23285) < 5e-6, "f_perp(1,1,2) = %.6f", f_perp(1, 1, 2));
}

/* ---------------------------------------------------------------- one bounce */

/* 1 when the centre of b lies in front of a. */
static int facing(const hr_surface *a, const hr_surface *b) {
  hr_vec3 ca = tv(0, 0, 0), cb = tv(0, 0, 0);
  for (int k = 0; k < 4; k++) {
    ca = tv(ca.x + a->v[k].x / 4, ca.y + a->v[k].y / 4, ca.z + a->v[k].z / 4);
    cb = tv(cb.x + b->v[k].x / 4, cb.y + b->v[k].y / 4, cb.z + b->v[k].z / 4);
  }
  return a->normal.x * (cb.x - ca.x) + a->normal.y * (cb.y - ca.y) +
             a->normal.z * (cb.z - ca.z) > 0;
}

/* Receiver (polygon 0, rho 0.5) and emitter (polygon 1, E 1, rho 0) facing each other; the
 * receiver's mean is 0.5 F(receiver -> emitter), the emitter's exactly 1. */
static void one_bounce(const char *what, int64_t paths, hr_vec3 ro, hr_vec3 ru, hr_vec3 rv,
                       hr_vec3 eo, hr_vec3 eu, hr_vec3 ev, double F) {
  hr_scene *s = new_scene("one-bounce");
  int rec = t_mat(s, "receiver", 0.5, 0), lamp = t_mat(s, "lamp", 0, 1);
  rect(s, rec, ro, ru, rv);
  rect(s, lamp, eo, eu, ev);
  CHECK(facing(&s->surfs[0], &s->surfs[1]) && facing(&s->surfs[1], &s->surfs[0]),
        "%s: the two squares do not face each other", what);
  double (*m)[3], (*se)[3];
  trace(s, paths, &m, &se);
  check_mc(what, m[0][0], se[0][0], 0.5 * F);
  CHECK(m[0][0] == m[0][1] && m[0][1] == m[0][2], "%s: grey receiver, channels differ", what);
  CHECK(m[1][0] == 1 && se[1][0] == 0, "%s: black emitter %.9g +- %g, want exactly 1", what,
        m[1][0], se[1][0]);
  free(m);
  free(se);
  hr_scene_destroy(&s);
}

/* Receiver arguments first (origin, edges u and v), then the emitter's. */
static void test_one_bounce(void) {
  printf("one bounce (receiver rho 0.5, emitter E 1): mean = 0.5 F\n");
  /* receiver at z = c facing -z, emitter at z = 0 facing +z */
  one_bounce("opposed unit squares, c = 1", 400000, tv(0, 0, 1), tv(0, 1, 0), tv(1, 0, 0),
             tv(0, 0, 0), tv(1, 0, 0), tv(0, 1, 0), f_opposed(1, 1, 1));
  one_bounce("opposed unit squares, c = 0.5", 400000, tv(0, 0, 0.5), tv(0, 1, 0), tv(1, 0, 0),
             tv(0, 0, 0), tv(1, 0, 0), tv(0, 1, 0), f_opposed(1, 1, 0.5));
  /* common edge along z at x = y = 0: receiver in y = 0 (width w along x, facing +y), emitter
   * in x = 0 (height h along y, facing +x); the kernel is singular along the edge, so these
   * need more paths for the same error */
  one_bounce("perpendicular (l, w, h) = (1, 1, 1)", 2500000, tv(0, 0, 0), tv(0, 0, 1),
             tv(1, 0, 0), tv(0, 0, 0), tv(0, 1, 0), tv(0, 0, 1), f_perp(1, 1, 1));
  one_bounce("perpendicular (l, w, h) = (1, 2, 1)", 2500000, tv(0, 0, 0), tv(0, 0, 1),
             tv(2, 0, 0), tv(0, 0, 0), tv(0, 1, 0), tv(0, 0, 1), f_perp(1, 2, 1));
  one_bounce("perpendicular (l, w, h) = (1, 1, 2)", 2500000, tv(0, 0, 0), tv(0, 0, 1),
             tv(1, 0, 0), tv(0, 0, 0), tv(0, 2, 0), tv(0, 0, 1), f_perp(1, 1, 2));
}

/* ---------------------------------------------------------------- closed environments */

static hr_scene *furnace(double rho) {
  hr_scene *s = new_scene("furnace");
  int m = t_mat(s, "glow", rho, 1);
  int mats[6] = {m, m, m, m, m, m};
  t_box(s, mats, tv(0, 0, 0), tv(1, 1, 1), 1);
  return s;
}

/* Every face of the furnace: within KSE se of E / (1 - rho), and the mean over the six faces
 * (equal areas; independent samples) also within the cap. */
static void test_furnace(double rho, int64_t paths) {
  printf("furnace cube, E 1, rho %.1f: B = %g (%lld paths per face)\n", rho, 1 / (1 - rho),
         (long long)paths);
  hr_scene *s = furnace(rho);
  double (*m)[3], (*se)[3], exact = 1 / (1 - rho), all = 0, var = 0;
  trace(s, paths, &m, &se);
  for (int p = 0; p < s->npolys; p++) {
    double d = fabs(m[p][0] - exact);
    printf("  face %d: %.6f se %.2e, %.2f se = %.3f%% off\n", p, m[p][0], se[p][0], d / se[p][0],
           100 * d / exact);
    CHECK(d <= KSE * se[p][0], "face %d: %.6f is %.1f se from %g", p, m[p][0], d / se[p][0],
          exact);
    all += m[p][0] / s->npolys;
    var += se[p][0] * se[p][0] / (s->npolys * s->npolys);
  }
  check_mc("mean of the six faces", all, sqrt(var), exact);
  free(m);
  free(se);
  hr_scene_destroy(&s);
}

/* Unit box (inward) whose ceiling (y = 1) is a 0.2 x 0.2 light in the middle of four panels, and
 * a closed block floating above the floor (a block standing on the floor would leave a
 * zero-height gap whose lifted rays escape); everything rho 'rho'. Returns the light's polygon
 * index. Every front faces into the room's air. */
static hr_scene *lit_box(double rho, int *light) {
  hr_scene *s = new_scene("lit-box");
  int wall = t_mat(s, "wall", rho, 0), lamp = t_mat(s, "lamp", rho, 10);
  int mats[6] = {wall, wall, wall, wall, wall, wall};
  t_box(s, mats, tv(0.25, 0.05, 0.3), tv(0.6, 0.4, 0.55), 0); /* the block, outward */
  rect(s, wall, tv(0, 0, 0), tv(0, 0, 1), tv(1, 0, 0)); /* floor, +y */
  rect(s, wall, tv(0, 0, 0), tv(0, 1, 0), tv(0, 0, 1)); /* x = 0, +x */
  rect(s, wall, tv(1, 0, 0), tv(0, 0, 1), tv(0, 1, 0)); /* x = 1, -x */
  rect(s, wall, tv(0, 0, 0), tv(1, 0, 0), tv(0, 1, 0)); /* z = 0, +z */
  rect(s, wall, tv(0, 0, 1), tv(0, 1, 0), tv(1, 0, 0)); /* z = 1, -z */
  /* ceiling panels around the light, facing -y */
  rect(s, wall, tv(0, 1, 0), tv(1, 0, 0), tv(0, 0, 0.4));
  rect(s, wall, tv(0, 1, 0.6), tv(1, 0, 0), tv(0, 0, 0.4));
  rect(s, wall, tv(0, 1, 0.4), tv(0.4, 0, 0), tv(0, 0, 0.2));
  rect(s, wall, tv(0.6, 1, 0.4), tv(0.4, 0, 0), tv(0, 0, 0.2));
  *light = s->npolys;
  rect(s, lamp, tv(0.4, 1, 0.4), tv(0.2, 0, 0), tv(0, 0, 0.2));
  /* orientation: room surfaces face the centre, block faces face away from the block's centre */
  for (int i = 0; i < s->nsurfs; i++) {
    const hr_surface *f = &s->surfs[i];
    hr_vec3 c = i < 6 ? tv(0.425, 0.225, 0.425) : tv(0.5, 0.5, 0.5);
    double d = f->normal.x * (c.x - f->v[0].x) + f->normal.y * (c.y - f->v[0].y) +
               f->normal.z * (c.z - f->v[0].z);
    CHECK(i < 6 ? d < 0 : d > 0, "lit_box surface %d faces the wrong way", i);
  }
  return s;
}

static void test_total_power(void) {
  const double rho = 0.6;
  int light;
  hr_scene *s = lit_box(rho, &light);
  double (*m)[3], (*se)[3];
  trace(s, 20000, &m, &se);
  double P = 0, var = 0, exact = 0;
  for (int p = 0; p < s->npolys; p++) {
    P += s->poly_area[p] * m[p][0];
    var += s->poly_area[p] * s->poly_area[p] * se[p][0] * se[p][0];
  }
  exact = 10 * s->poly_area[light] / (1 - rho);
  printf("closed box, 0.2 x 0.2 light E 10 in the ceiling, floating block, rho %.1f:\n", rho);
  check_mc("total power sum(B A) = sum(E A) / (1 - rho)", P, sqrt(var), exact);
  free(m);
  free(se);
  hr_scene_destroy(&s);
}

/* ---------------------------------------------------------------- one-sidedness */

static void test_one_sided(void) {
  printf("one-sidedness\n");
  /* (a) receiver (E 0.25, rho 0.5) at z = 1 facing away (+z) from an emitter at z = 0 facing +z
   * (rho 0.5 too: the receiver's black back sends nothing back). */
  hr_scene *s = new_scene("away");
  int rec = t_mat(s, "receiver", 0.5, 0.25), lamp = t_mat(s, "lamp", 0.5, 1);
  rect(s, rec, tv(0, 0, 1), tv(1, 0, 0), tv(0, 1, 0));
  rect(s, lamp, tv(0, 0, 0), tv(1, 0, 0), tv(0, 1, 0));
  double (*m)[3], (*se)[3];
  trace(s, 20000, &m, &se);
  printf("  receiver facing away: %.9g +- %g (exactly 0.25); emitter: %.9g +- %g (exactly 1)\n",
         m[0][0], se[0][0], m[1][0], se[1][0]);
  CHECK(m[0][0] == 0.25 && se[0][0] == 0, "receiver facing away got %.9g", m[0][0]);
  CHECK(m[1][0] == 1 && se[1][0] == 0, "emitter facing a back got %.9g", m[1][0]);
  free(m);
  free(se);
  hr_scene_destroy(&s);
  /* (b) receiver at z = 1 facing the emitter (-z), emitter at z = 0 facing away (-z). */
  s = new_scene("back");
  rec = t_mat(s, "receiver", 0.5, 0), lamp = t_mat(s, "lamp", 0.5, 1);
  rect(s, rec, tv(0, 0, 1), tv(0, 1, 0), tv(1, 0, 0));
  rect(s, lamp, tv(0, 0, 0), tv(0, 1, 0), tv(1, 0, 0));
  trace(s, 20000, &m, &se);
  printf("  receiver facing an emitter's back: %.9g +- %g (exactly 0)\n", m[0][0], se[0][0]);
  CHECK(m[0][0] == 0 && se[0][0] == 0, "receiver facing an emitter's back got %.9g", m[0][0]);
  free(m);
  free(se);
  hr_scene_destroy(&s);
}

/* ---------------------------------------------------------------- images */

static hr_status image(const hr_scene *s, const hr_camera *cam, int w, int h, int spp,
                       int threads, float *rgb, float *se) {
  hr_pt_options o = opts(1);
  o.threads = threads;
  hr_err err = {{0}};
  return hr_pt_image(s, cam, w, h, spp, &o, rgb, se, &err);
}

/* Furnace (rho 0.5) seen from its centre: every pixel is B = 2 within its noise. */
static void test_image_furnace(void) {
  const int w = 48, h = 36, spp = 16, n = w * h;
  hr_scene *s = furnace(0.5);
  hr_camera cam = {tv(0.5, 0.5, 0.5), tv(0.8, 0.4, 0), tv(0, 1, 0), 70};
  float *img = malloc(3 * sizeof(float) * n), *se = malloc(3 * sizeof(float) * n);
  CHECK(image(s, &cam, w, h, spp, 2, img, se) == HR_OK, "hr_pt_image failed");
  double sum = 0, var = 0, worst = 0;
  int bad = 0;
  for (int i = 0; i < n; i++) {
    double d = fabs(img[3 * i] - 2.0);
    sum += img[3 * i];
    var += (double)se[3 * i] * se[3 * i];
    if (d > worst) worst = d;
    bad += d > 5 * se[3 * i] + 1e-6;
  }
  printf("image of the furnace from inside (%dx%d, %d spp): worst pixel off by %.3f, %d pixels "
         "beyond 5 se\n", w, h, spp, worst, bad);
  check_mc("image mean", sum / n, sqrt(var) / n, 2.0);
  CHECK(worst < 0.5, "a furnace pixel is off by %.3f", worst); /* gross errors only */
  CHECK(bad <= 2, "%d furnace pixels beyond 5 se", bad);
  free(img);
  free(se);
  hr_scene_destroy(&s);
}

/* An emitting square [0, 0.5]^2 (z = 0, facing +z, E 1, rho 0) seen head-on from (0, 0, 2) with
 * a 90 degree vertical field of view at 64x48: its edges fall on pixel boundaries (x: NDC 0 and
 * 0.1875 -> columns 32..37; y: NDC 0.25 and 0 -> rows 18..23, row 0 at the top), so those 36
 * pixels are exactly 1 and all others exactly 0. The same square seen from behind is black. */
static void test_image_pixels(void) {
  const int w = 64, h = 48, n = w * h;
  hr_scene *s = new_scene("quad");
  rect(s, t_mat(s, "lamp", 0, 1), tv(0, 0, 0), tv(0.5, 0, 0), tv(0, 0.5, 0));
  hr_camera cam = {tv(0, 0, 2), tv(0, 0, 0), tv(0, 1, 0), 90};
  float *img = malloc(3 * sizeof(float) * n);
  CHECK(image(s, &cam, w, h, 4, 2, img, NULL) == HR_OK, "hr_pt_image failed");
  int wrong = 0, lit = 0;
  for (int y = 0; y < h; y++)
    for (int x = 0; x < w; x++) {
      int in = x >= 32 && x < 38 && y >= 18 && y < 24;
      lit += img[3 * (y * w + x)] > 0;
      wrong += img[3 * (y * w + x)] != (in ? 1.0f : 0.0f);
    }
  printf("emitting quad seen head-on: %d pixels lit (want 36), %d pixels wrong\n", lit, wrong);
  CHECK(wrong == 0 && lit == 36, "%d pixels differ from the expected footprint", wrong);
  cam.eye = tv(0, 0, -2);
  CHECK(image(s, &cam, w, h, 4, 2, img, NULL) == HR_OK, "hr_pt_image failed");
  lit = 0;
  for (int i = 0; i < 3 * n; i++) lit += img[i] != 0;
  printf("the same quad from behind: %d non-zero values (want 0)\n", lit);
  CHECK(lit == 0, "the back of an emitter shows %d non-zero values", lit);
  free(img);
  hr_scene_destroy(&s);
}

/* An emitting triangle at an odd position, rendered by hr_render_ex (4x4 samples, linear) and
 * traced (16x16 strata): pixel for pixel the two agree up to the coverage quantisation of the
 * edge pixels; a half-pixel shift would put whole edge pixels off by 0.5. */
static void test_image_alignment(void) {
  const int w = 80, h = 60, n = w * h;
  hr_scene *s = new_scene("tri");
  hr_vec3 v[3] = {tv(-0.83, -0.41, 0.1), tv(0.67, -0.23, -0.2), tv(0.12, 0.71, 0.05)};
  t_poly(s, t_mat(s, "lamp", 0, 1), 3, v);
  hr_camera cam = {tv(0.3, 0.2, 2.5), tv(0, 0, 0), tv(0, 1, 0), 45};
  hr_leaf leaf = {.surf = 0, .nverts = 3, .area = s->surfs[0].area, .B = {1, 1, 1}};
  leaf.lat[1][0] = HR_LATTICE, leaf.lat[2][1] = HR_LATTICE;
  for (int k = 0; k < 3; k++) leaf.p[k] = s->surfs[0].v[k];
  hr_mesh *m = NULL;
  float *ren = malloc(3 * sizeof(float) * n), *img = malloc(3 * sizeof(float) * n);
  CHECK(hr_mesh_build(s, &leaf, 1, &m) == HR_OK, "mesh");
  CHECK(hr_render_ex(s, m, &leaf, 1, &cam, w, h, 0, 4, -1, ren) == HR_OK, "render");
  CHECK(image(s, &cam, w, h, 256, 2, img, NULL) == HR_OK, "hr_pt_image failed");
  double worst = 0, sr = 0, si = 0;
  int inner_diff = 0;
  for (int i = 0; i < n; i++) {
    double d = fabs(ren[3 * i] - img[3 * i]);
    if (d > worst) worst = d;
    sr += ren[3 * i], si += img[3 * i];
    inner_diff += (ren[3 * i] == 1.0f) != (img[3 * i] == 1.0f) && d > 0.07;
  }
  printf("triangle: hr_render vs path tracer: coverage %.1f vs %.1f pixels, worst pixel %.3f\n",
         sr, si, worst);
  CHECK(worst < 0.15, "render and path tracer differ by %.3f in a pixel", worst);
  CHECK(fabs(sr - si) < 0.01 * si, "coverage %.2f vs %.2f", sr, si);
  CHECK(inner_diff == 0, "%d pixels full in one image only", inner_diff);
  hr_mesh_destroy(&m);
  free(ren);
  free(img);
  hr_scene_destroy(&s);
}

/* ---------------------------------------------------------------- determinism, arguments */

static void test_threads(void) {
  int light;
  hr_scene *s = lit_box(0.7, &light);
  const int np = s->npolys, w = 40, h = 30;
  double m1[64][3], s1[64][3], m2[64][3], s2[64][3];
  hr_pt_options o = opts(10000);
  hr_err err = {{0}};
  o.threads = 1;
  CHECK(hr_pt_polys(s, &o, m1, s1, &err) == HR_OK, "%s", err.msg);
  o.threads = 2;
  CHECK(hr_pt_polys(s, &o, m2, s2, &err) == HR_OK, "%s", err.msg);
  int same = !memcmp(m1, m2, (size_t)np * sizeof *m1) && !memcmp(s1, s2, (size_t)np * sizeof *s1);
  hr_camera cam = {tv(0.5, 0.5, 0.95), tv(0.5, 0.3, 0), tv(0, 1, 0), 60};
  float *a = malloc(3 * sizeof(float) * w * h), *b = malloc(3 * sizeof(float) * w * h);
  CHECK(image(s, &cam, w, h, 4, 1, a, NULL) == HR_OK, "image");
  CHECK(image(s, &cam, w, h, 4, 2, b, NULL) == HR_OK, "image");
  int same_img = !memcmp(a, b, 3 * sizeof(float) * w * h);
  printf("1 vs 2 threads: polygon means %s, image %s\n", same ? "bit-identical" : "DIFFER",
         same_img ? "bit-identical" : "DIFFERS");
  CHECK(same, "polygon results differ between 1 and 2 threads");
  CHECK(same_img, "images differ between 1 and 2 threads");
  o.seed = 2;
  CHECK(hr_pt_polys(s, &o, m2, s2, &err) == HR_OK, "%s", err.msg);
  CHECK(memcmp(m1, m2, (size_t)np * sizeof *m1) != 0, "seed 2 gave seed 1's numbers");
  free(a);
  free(b);
  hr_scene_destroy(&s);
}

static void test_bad_args(void) {
  hr_scene *s = furnace(0.5);
  double m[6][3];
  float px[3 * 16 * 16];
  hr_err err = {{0}};
  hr_pt_options o = opts(0);
  CHECK(hr_pt_polys(s, &o, m, NULL, &err) == HR_ERR_INVALID, "0 paths accepted");
  o.paths = 10;
  o.threads = -1;
  CHECK(hr_pt_polys(s, &o, m, NULL, &err) == HR_ERR_INVALID, "-1 threads accepted");
  hr_camera cam = {tv(0.5, 0.5, 0.5), tv(0.5, 0.5, 0), tv(0, 1, 0), 60};
  CHECK(image(s, &cam, 16, 16, 0, 1, px, NULL) == HR_ERR_INVALID, "0 spp accepted");
  cam.at = cam.eye;
  CHECK(image(s, &cam, 16, 16, 1, 1, px, NULL) == HR_ERR_INVALID, "degenerate camera accepted");
  hr_scene *e = new_scene("empty");
  CHECK(hr_pt_polys(e, NULL, m, NULL, &err) == HR_ERR_INVALID, "empty scene accepted");
  hr_scene_destroy(&e);
  hr_scene_destroy(&s);
}

int main(void) {
  double t0 = now_s(), t = t0;
#define LAP()                                                                                  \
  do {                                                                                             \
    printf("  (%.2f s)\n", now_s() - t);                                                           \
    t = now_s();                                                                                   \
  } while (0)
  test_closed_forms();
  test_one_bounce();
  LAP();
  test_furnace(0.5, 20000);
  LAP();
  test_furnace(0.9, 40000);
  LAP();
  test_total_power();
  LAP();
  test_one_sided();
  test_image_furnace();
  LAP();
  test_image_pixels();
  test_image_alignment();
  LAP();
  test_threads();
  test_bad_args();
  LAP();
#undef LAP
  printf("test_pt: %.1f s\n", now_s() - t0);
  return t_done("test_pt");
}
