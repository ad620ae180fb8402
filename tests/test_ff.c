/* Form factors against closed forms (Howell's catalogue, ../shared/REFERENCE-VALUES.md):
 * the eq. (2) kernel on the point-to-coaxial-disk case, the exact reference (ff_ref.c) on plates,
 * and the whole program on the one-bounce set-up (emitter E=1 rho=0, receiver rho=0.5 E=0, so the
 * receiver's mean radiosity is 0.5 F(receiver -> emitter)), at default settings and with a
 * decreasing BF_low to show the error shrinks. */
#include "ff.h"
#include "ff_ref.h"
#include "xorshift.h"
#include "solver_impl.h"
#include "testutil.h"
#include "vec.h"

#include <string.h>

static double howell_parallel(double a, double b, double c) {
  double X = a / c, Y = b / c;
  return 2 / (M_PI * X * Y) *
         (log(sqrt((1 + X * X) * (1 + Y * Y) / (1 + X * X + Y * Y))) +
          X * sqrt(1 + Y * Y) * atan(X / sqrt(1 + Y * Y)) +
          Y * sqrt(1 + X * X) * atan(Y / sqrt(1 + X * X)) - X * atan(X) - Y * atan(Y));
}

static double howell_perp(double l, double w, double h) {
  double W = w / l, H = h / l, W2 = W * W, H2 = H * H, S = sqrt(H2 + W2);
  double t = (1 + W2) * (1 + H2) / (1 + W2 + H2) *
             pow(W2 * (1 + W2 + H2) / ((1 + W2) * (W2 + H2)), W2) *
             pow(H2 * (1 + W2 + H2) / ((1 + H2) * (W2 + H2)), H2);
  return 1 / (M_PI * W) * (W * atan(1 / W) + H * atan(1 / H) - S * atan(1 / S) + 0.25 * log(t));
}

/* Receiver: a x b plate in the plane y=0 facing +y; emitter: plate at height c facing down. */
static hr_scene *parallel_scene(double a, double b, double c) {
  hr_scene *s;
  hr_scene_create("parallel", &s);
  int rec = t_mat(s, "receiver", 0.5, 0), em = t_mat(s, "emitter", 0, 1);
  t_quad(s, rec, tv(0, 0, 0), tv(0, 0, b), tv(a, 0, b), tv(a, 0, 0));
  t_quad(s, em, tv(0, c, 0), tv(a, c, 0), tv(a, c, b), tv(0, c, b));
  return s;
}

/* Receiver plate 1 (width w along +z, in y=0 facing +y), emitter plate 2 (height h along +y, in
 * z=0 facing +z), common edge of length l along x. */
static hr_scene *perp_scene(double l, double w, double h) {
  hr_scene *s;
  hr_scene_create("perp", &s);
  int rec = t_mat(s, "receiver", 0.5, 0), em = t_mat(s, "emitter", 0, 1);
  t_quad(s, rec, tv(0, 0, 0), tv(0, 0, w), tv(l, 0, w), tv(l, 0, 0));
  t_quad(s, em, tv(0, 0, 0), tv(l, 0, 0), tv(l, h, 0), tv(0, h, 0));
  return s;
}

static double solve_f(hr_scene *s, const hr_options *o) {
  hr_solver *sv = t_solve(s, o);
  double b[3];
  hr_solver_poly_radiosity(sv, 0, b);
  hr_stats st;
  hr_solver_stats(sv, &st);
  printf("    [%lld elements, %lld links, %d iterations, %lld rays, %.3f s]\n",
         (long long)st.elements, (long long)st.links, st.iterations, (long long)st.rays,
         st.time_s.total);
  hr_solver_destroy(&sv);
  return b[0] / 0.5;
}

/* A random convex quad around 'c' in the plane with unit normal 'n' (counter-clockwise seen
 * from the front), about 'size' across. */
static hr_ff_elem rnd_elem(hr_vec3 c, hr_vec3 n, double size) {
  hr_vec3 t = v3_norm(v3_cross(n, fabs(n.x) < 0.9 ? tv(1, 0, 0) : tv(0, 1, 0)));
  hr_vec3 b = v3_cross(n, t);
  double sx[4] = {-1, 1, 1, -1}, sy[4] = {-1, -1, 1, 1};
  hr_ff_elem e;
  e.nv = 4;
  for (int k = 0; k < 4; k++) {
    double jx = 0.5 * size * (0.8 + 0.4 * rnd()), jy = 0.5 * size * (0.8 + 0.4 * rnd());
    e.p[k] = v3_add(c, v3_add(v3_scale(t, sx[k] * jx), v3_scale(b, sy[k] * jy)));
  }
  hr_vec3 nn = v3_newell(e.p, 4);
  e.area = 0.5 * v3_len(nn);
  e.n = v3_norm(nn);
  return e;
}

/* 1 when every corner of s lies in front of r's plane (through the origin) and every corner of
 * r in front of s's: a pair of elements wholly facing each other. */
static int facing(const hr_ff_elem *r, const hr_ff_elem *s) {
  int ok = 1;
  for (int v = 0; v < 4; v++)
    ok &= v3_dot(s->p[v], r->n) > 0 && v3_dot(v3_sub(r->p[v], s->p[0]), s->n) > 0;
  return ok;
}

static hr_vec3 rnd_dir(void) {
  for (;;) {
    hr_vec3 v = tv(2 * rnd() - 1, 2 * rnd() - 1, 2 * rnd() - 1);
    double l = v3_len(v);
    if (l > 0.1 && l <= 1) return v3_scale(v, 1 / l);
  }
}

/* The kernels of ff.c against the reference of ff_ref.c: the point kernel exactly (also where
 * the source straddles the point's tangent plane, against a fine quadrature of the clipped
 * part), the pair quadrature within its stated accuracy. */
static void kernels(void) {
  printf("form-factor kernels (ff.c) against the reference (ff_ref.c)\n");
  double worst = 0;
  for (int k = 0; k < 2000; k++) {
    hr_vec3 x = tv(0, 0, 0), nx = rnd_dir();
    hr_vec3 d = rnd_dir();
    if (v3_dot(d, nx) < 0.2) continue; /* wholly in front: the reference's domain */
    hr_vec3 ns = rnd_dir();
    if (v3_dot(ns, d) > -0.2) continue;
    hr_ff_elem s = rnd_elem(v3_scale(d, 1 + 3 * rnd()), ns, 0.5);
    int infront = 1;
    for (int v = 0; v < 4; v++) infront &= v3_dot(s.p[v], nx) > 0;
    if (!infront) continue;
    double f = hr_ff_point(x, nx, &s), r = hr_ff_ref_point_poly(x, nx, s.p, 4);
    double e = fabs(f - r) / r;
    worst = e > worst ? e : worst;
  }
  /* 1e-7: the contour's angles come from a polynomial arctangent good to 3e-10 rad (ff.c) */
  printf("  point kernel, source in front: worst rel.err %.1e (tol 1e-7)\n", worst);
  CHECK(worst < 1e-7, "point kernel differs from the reference by %.3e", worst);
  /* Straddling: a unit square source in the plane z = 1 seen from a point tilted so that its
   * tangent plane cuts the square; reference: midpoint rule over the part in front. */
  {
    hr_ff_elem s = {4, {tv(-0.5, -0.5, 1), tv(-0.5, 0.5, 1), tv(0.5, 0.5, 1), tv(0.5, -0.5, 1)},
                    tv(0, 0, -1), 1};
    hr_vec3 nx = v3_norm(tv(0.8, 0, 0.6));
    const int m = 2000;
    double acc = 0;
    for (int i = 0; i < m; i++)
      for (int j = 0; j < m; j++) {
        hr_vec3 y = tv(-0.5 + (i + 0.5) / m, -0.5 + (j + 0.5) / m, 1);
        double r2 = v3_dot(y, y), cx = v3_dot(nx, y) / sqrt(r2), cy = 1 / sqrt(r2);
        if (cx > 0) acc += cx * cy / (M_PI * r2) / ((double)m * m);
      }
    CHECK_REL(hr_ff_point(tv(0, 0, 0), nx, &s), acc, 1e-5,
              "point kernel, source clipped by the tangent plane");
    CHECK(hr_ff_point(tv(0, 0, 2), tv(0, 0, 1), &s) == 0, "a point behind the source gets light");
  }
  /* Pairs at a clearance of at least their size: within 0.5% of a converged reference. */
  worst = 0;
  for (int k = 0; k < 200; k++) {
    hr_vec3 nr = rnd_dir();
    hr_ff_elem r = rnd_elem(tv(0, 0, 0), nr, 1);
    hr_vec3 d = rnd_dir();
    if (v3_dot(d, nr) < 0.3) continue;
    hr_vec3 ns = rnd_dir();
    if (v3_dot(ns, d) > -0.3) continue;
    hr_ff_elem s = rnd_elem(v3_scale(d, 2.5 + 3 * rnd()), ns, 0.5 + rnd());
    if (!facing(&r, &s)) continue;
    double f = hr_ff_pair(&r, &s, 0, NULL), ref = hr_ff_ref_poly_poly(r.p, 4, s.p, 4, 6, 6);
    double e = fabs(f - ref) / ref;
    worst = e > worst ? e : worst;
  }
  printf("  pair quadrature, clearance >= size: worst rel.err %.1e (tol 5e-3)\n", worst);
  CHECK(worst < 5e-3, "pair quadrature off by %.3e", worst);
}

/* hr_ff_point_many (four points at a time with AVX2 where the CPU has it) against hr_ff_point
 * point by point, bit for bit: quads and triangles, receivers' quadrature points near the source
 * (all of it in front of a point's tangent plane, part of it, none; points behind it), and
 * points in the source's plane. */
static void point_many(void) {
  const int avx2 = hr_ff_use_avx2(1);
  printf("hr_ff_point_many against hr_ff_point (%s)\n", avx2 ? "AVX2 kernel" : "scalar loop");
  int n = 0, differ = 0, lit = 0, zero = 0;
  for (int k = 0; k < 6000; k++) {
    hr_ff_elem s = rnd_elem(v3_scale(rnd_dir(), 0.2 + 2 * rnd()), rnd_dir(), 0.5 + rnd());
    if (k % 2) { /* a triangle */
      s.nv = 3;
      hr_vec3 nn = v3_newell(s.p, 3);
      s.area = 0.5 * v3_len(nn), s.n = v3_norm(nn);
    }
    const hr_ff_elem r = rnd_elem(tv(0, 0, 0), rnd_dir(), 1);
    hr_vec3 x[12];
    double w[9], got[12];
    int m = hr_ff_points(&r, 1 + k % 3, x, w);
    /* a corner of the source, and a point in its plane: the tests' edge cases */
    x[m++] = s.p[k % s.nv];
    x[m++] = v3_add(s.p[0], v3_scale(v3_sub(s.p[1], s.p[0]), 2.5));
    const int use = 1 + k % m; /* every count, tails of 1-3 lanes included */
    hr_ff_point_many(x, use, r.n, &s, got);
    for (int q = 0; q < use; q++, n++) {
      const double want = hr_ff_point(x[q], r.n, &s);
      differ += memcmp(&want, &got[q], sizeof want) != 0;
      lit += want > 0, zero += want == 0;
    }
  }
  printf("  %d points, %d lit, %d dark, %d differ\n", n, lit, zero, differ);
  CHECK(differ == 0, "%d of %d points differ from hr_ff_point", differ, n);
  CHECK(lit > n / 5 && zero > n / 10, "%d lit and %d dark of %d points", lit, zero, n);
  CHECK(hr_ff_use_avx2(0) == 0, "the scalar loop could not be chosen");
  hr_ff_use_avx2(1);
}

/* hr_ff_point_pairs against hr_ff_point pair by pair, bit for bit: each lane its own point and
 * source, triangles and quads mixed in one batch (a triangle among quads takes a fourth corner
 * equal to its first), sources in front of, across and behind the points' tangent planes,
 * corners and points in a source's plane among the points. */
static void point_pairs(void) {
  const int avx2 = hr_ff_use_avx2(1);
  printf("hr_ff_point_pairs against hr_ff_point (%s)\n", avx2 ? "AVX2 kernel" : "scalar loop");
  enum { NS = 7, NX = 40 };
  int n = 0, differ = 0, lit = 0, zero = 0, mixed = 0;
  for (int k = 0; k < 1500; k++) {
    hr_ff_elem src[NS];
    for (int j = 0; j < NS; j++) {
      src[j] = rnd_elem(v3_scale(rnd_dir(), 0.2 + 2 * rnd()), rnd_dir(), 0.5 + rnd());
      if ((k + j) % 3 == 0) { /* a triangle */
        src[j].nv = 3;
        hr_vec3 nn = v3_newell(src[j].p, 3);
        src[j].area = 0.5 * v3_len(nn), src[j].n = v3_norm(nn);
      }
    }
    const hr_ff_elem r = rnd_elem(tv(0, 0, 0), rnd_dir(), 1);
    hr_vec3 pts[12];
    double w[9], got[NX];
    int m = hr_ff_points(&r, 1 + k % 3, pts, w);
    pts[m++] = src[k % NS].p[0];
    pts[m++] = v3_add(src[0].p[0], v3_scale(v3_sub(src[0].p[1], src[0].p[0]), 2.5));
    const hr_vec3 *x[NX];
    const hr_ff_elem *sp[NX];
    const int use = 1 + k % NX; /* every count, tails of 1-3 lanes included */
    for (int q = 0; q < use; q++) {
      x[q] = &pts[(q * 5 + k) % m], sp[q] = &src[(q * 3 + k / 7) % NS];
      mixed += q % 4 == 3 && sp[q]->nv != sp[q - 3]->nv;
    }
    hr_ff_point_pairs(x, sp, use, r.n, got);
    for (int q = 0; q < use; q++, n++) {
      const double want = hr_ff_point(*x[q], r.n, sp[q]);
      differ += memcmp(&want, &got[q], sizeof want) != 0;
      lit += want > 0, zero += want == 0;
    }
  }
  printf("  %d pairs, %d lit, %d dark, %d differ, %d batches of triangles and quads\n", n, lit,
         zero, differ, mixed);
  CHECK(differ == 0, "%d of %d pairs differ from hr_ff_point", differ, n);
  CHECK(lit > n / 5 && zero > n / 10 && mixed > 100, "%d lit, %d dark of %d; %d mixed", lit,
        zero, n, mixed);
  hr_ff_use_avx2(1);
}

/* hr_ff_pair_dark: where it says a pair sees nothing, every quadrature point gets exactly 0
 * (random pairs near each other, all orientations; in general position, so no corner lies in
 * the other's plane), and it is not a bound that also takes pairs that exchange light. */
static void dark_pairs(void) {
  printf("dark pairs (hr_ff_pair_dark), and hr_ff_pair_class\n");
  int dark = 0, lit = 0, n = 0, wrong = 0, cls = 0, orders[4] = {0, 0, 0, 0};
  for (int k = 0; k < 4000; k++, n++) {
    hr_ff_elem r = rnd_elem(tv(0, 0, 0), rnd_dir(), 1);
    hr_ff_elem s = rnd_elem(v3_scale(rnd_dir(), 0.3 + 2 * rnd()), rnd_dir(), 0.5 + rnd());
    if (k % 3 == 0) { /* a triangle, some of them far: every order */
      s.nv = 3;
      const hr_vec3 away = v3_scale(v3_norm(v3_add(s.p[0], s.p[1])), 3.0 * (k % 5));
      for (int v = 0; v < 3; v++) s.p[v] = v3_add(s.p[v], away);
      hr_vec3 nn = v3_newell(s.p, 3);
      s.area = 0.5 * v3_len(nn), s.n = v3_norm(nn);
    }
    const int d = hr_ff_pair_dark(&r, &s);
    const hr_ff_shape hr = hr_ff_shape_of(&r), hs = hr_ff_shape_of(&s);
    const int c = hr_ff_pair_class(&r, &s, &hr, &hs);
    cls += c != (d ? 0 : hr_ff_order(&r, &s));
    orders[c]++;
    double fmax = 0;
    for (int order = 1; order <= 3; order++) {
      double sp = 0;
      const double f = hr_ff_pair(&r, &s, order, &sp);
      fmax = fmax > f ? fmax : f;
      if (d && (f != 0 || sp != 0)) wrong++;
    }
    dark += d;
    lit += !d && fmax > 0;
  }
  printf("  %d of %d pairs dark, %d of the others lit, %d dark ones with light\n", dark, n, lit,
         wrong);
  printf("  hr_ff_pair_class: %d dark, orders 1-3: %d %d %d; %d differ\n", orders[0], orders[1],
         orders[2], orders[3], cls);
  CHECK(cls == 0, "hr_ff_pair_class differs from hr_ff_pair_dark and hr_ff_order %d times", cls);
  CHECK(orders[1] > 50 && orders[2] > 50 && orders[3] > 50, "orders %d %d %d", orders[1],
        orders[2], orders[3]);
  CHECK(wrong == 0, "%d pairs called dark get light", wrong);
  CHECK(dark > n / 5 && dark < 4 * n / 5, "%d of %d pairs dark", dark, n);
  CHECK(lit > (n - dark) / 2, "only %d of %d pairs not dark get light", lit, n - dark);
}

static hr_ff_elem elem_of(const hr_vec3 *p, int nv) {
  hr_ff_elem e = {nv, {p[0], p[1], p[2], p[nv - 1]}, tv(0, 0, 0), 0};
  hr_vec3 nn = v3_newell(e.p, nv);
  e.area = 0.5 * v3_len(nn), e.n = v3_norm(nn);
  return e;
}

/* Receivers that reach through the source's plane (hr_ff_clip_points): a unit square in y = 0
 * facing +y with z in [-a, 1 - a], and a triangle with its apex above z = 0, under a square
 * source in z = 0 facing +z (x in [0, 1], y in [y0, y0 + h]): the point kernel is 0 behind
 * z = 0 and jumps there. Reference: the part in front alone, converged, times its share of the
 * area. Before the clipped rule: 35% RMS, 80% at worst (bench/ffacc); now 1.1%, 5.3%. Slivers
 * keep the plain rule (checked: a 1 x 40 strip's value is the order-3 one). */
static void straddling(void) {
  printf("straddling receivers against the clipped reference\n");
  double worst = 0, sq = 0;
  int n = 0;
  const double as[] = {0.1, 0.25, 0.5, 0.75}, hs[] = {0.25, 1, 4};
  for (int ai = 0; ai < 4; ai++)
    for (int hi = 0; hi < 3; hi++)
      for (int yo = 0; yo < 2; yo++) {
        const double a = as[ai], h = hs[hi], y0 = yo * 0.5 * h;
        const hr_vec3 qs[4] = {tv(0, y0, 0), tv(1, y0, 0), tv(1, y0 + h, 0), tv(0, y0 + h, 0)};
        const hr_ff_elem s = elem_of(qs, 4);
        const hr_vec3 qr[4] = {tv(0, 0, -a), tv(0, 0, 1 - a), tv(1, 0, 1 - a), tv(1, 0, -a)};
        const hr_vec3 qf[4] = {tv(0, 0, 0), tv(0, 0, 1 - a), tv(1, 0, 1 - a), tv(1, 0, 0)};
        /* a triangle: apex at z = 1 - a, base at z = -a; its part in front, a triangle */
        const hr_vec3 tr[3] = {tv(0, 0, -a), tv(0.5, 0, 1 - a), tv(1, 0, -a)};
        const hr_vec3 tf[3] = {tv(0.5 * a, 0, 0), tv(0.5, 0, 1 - a), tv(1 - 0.5 * a, 0, 0)};
        const hr_ff_elem r[2] = {elem_of(qr, 4), elem_of(tr, 3)};
        const double ref[2] = {hr_ff_ref_poly_poly(qf, 4, qs, 4, 24, 6) * (1 - a),
                               hr_ff_ref_poly_poly(tf, 3, qs, 4, 24, 6) * (1 - a) * (1 - a)};
        for (int k = 0; k < 2; k++) {
          CHECK(r[k].n.y > 0.99, "receiver %d faces +y", k);
          const double e = fabs(hr_ff_pair(&r[k], &s, 0, NULL) - ref[k]) / ref[k];
          worst = e > worst ? e : worst;
          sq += e * e, n++;
        }
      }
  const double rms = sqrt(sq / n);
  /* the worst: a strip 1/8 above the line where the plane cuts the receiver (4-5%) */
  printf("  %d pairs: RMS rel.err %.2e, worst %.2e (tol 1.5e-2, 6e-2)\n", n, rms, worst);
  CHECK(rms < 1.5e-2 && worst < 6e-2, "straddling pairs: RMS %.3e, worst %.3e", rms, worst);
  /* a sliver (squared diameter over area 40) through the plane: the plain order-3 rule */
  const hr_vec3 sl[4] = {tv(0, 0, -0.5), tv(0, 0, 0.5), tv(40, 0, 0.5), tv(40, 0, -0.5)};
  const hr_vec3 ss[4] = {tv(19, 0, 0), tv(21, 0, 0), tv(21, 1, 0), tv(19, 1, 0)};
  const hr_ff_elem r = elem_of(sl, 4), s = elem_of(ss, 4);
  hr_vec3 x[HR_FF_CLIP_POINTS];
  double w[HR_FF_CLIP_POINTS];
  CHECK(hr_ff_clip_points(&r, &s, x, w) == 0, "a sliver is clipped");
  CHECK(hr_ff_pair(&r, &s, 0, NULL) == hr_ff_pair(&r, &s, 3, NULL), "sliver: not the plain rule");
}

/* Small sources near a unit receiver (hr_ff_recip: by reciprocity from the source's points):
 * random pairs at a clearance of 0.1, the source 0.15-0.35 across, against the receiver's
 * converged quadrature. The receiver's own 9 points: 1.9% RMS, 4.6% worst. */
static void small_sources(void) {
  printf("small near sources against a converged reference\n");
  double worst = 0, sq = 0;
  int n = 0;
  for (int k = 0; n < 40 && k < 4000; k++) {
    hr_vec3 nr = rnd_dir();
    hr_ff_elem r = rnd_elem(tv(0, 0, 0), nr, 1);
    hr_vec3 d = rnd_dir(), ns = rnd_dir();
    if (v3_dot(d, nr) < 0.3 || v3_dot(ns, d) > -0.3) continue;
    const double size = 0.15 + 0.2 * rnd();
    hr_ff_elem s = rnd_elem(v3_scale(d, 0.5 * (1 + size) + 0.1), ns, size);
    if (!facing(&r, &s) || hr_ff_order(&r, &s) != 3) continue;
    const double f = hr_ff_pair(&r, &s, 0, NULL), ref = hr_ff_ref_poly_poly(r.p, 4, s.p, 4, 32, 6);
    const double e = fabs(f - ref) / ref;
    worst = e > worst ? e : worst;
    sq += e * e, n++;
  }
  const double rms = n ? sqrt(sq / n) : 1;
  printf("  %d pairs: RMS rel.err %.2e, worst %.2e (tol 3e-3, 1e-2)\n", n, rms, worst);
  CHECK(n == 40 && rms < 3e-3 && worst < 1e-2, "%d small sources: RMS %.3e, worst %.3e", n, rms,
        worst);
}

int main(void) {
  printf("closed forms vs. REFERENCE-VALUES.md\n");
  CHECK_REL(howell_parallel(1, 1, 1), 0.19982, 1e-4, "Howell parallel 1x1 at 1");
  CHECK_REL(howell_parallel(1, 1.5, 0.5), 0.47558, 1e-4, "Howell parallel 1x1.5 at 0.5");
  CHECK_REL(howell_perp(1, 1, 1), 0.20004, 1e-4, "Howell perpendicular 1,1,1");
  CHECK_REL(howell_perp(1, 1, 2), 0.23285, 1e-4, "Howell perpendicular 1,1,2");

  printf("eq. (2) kernel: point to coaxial disk (source area in the denominator)\n");
  {
    /* A tiny receiver at the origin facing +y; a source square of area pi R^2 at height h. */
    double R = 0.7, h = 1.3, side = sqrt(M_PI) * R, e = 1e-4;
    hr_scene *s;
    hr_scene_create("disk", &s);
    int m = t_mat(s, "m", 0.5, 1);
    t_quad(s, m, tv(-e, 0, -e), tv(-e, 0, e), tv(e, 0, e), tv(e, 0, -e));
    t_quad(s, m, tv(-side / 2, h, -side / 2), tv(side / 2, h, -side / 2),
           tv(side / 2, h, side / 2), tv(-side / 2, h, side / 2));
    hr_solver *sv;
    hr_err err;
    CHECK(hr_solver_create(s, NULL, &sv, &err) == HR_OK, "%s", err.msg);
    hr_ff_elem g0 = hr_elem_geom(sv, &sv->el[0]), g1 = hr_elem_geom(sv, &sv->el[1]);
    double f = hr_ff_disk(&g0, &g1);
    CHECK_REL(f, R * R / (R * R + h * h), 1e-12, "F point->disk = R^2/(R^2+h^2)");
    /* And the exact reference agrees on a real (polygonal) disk of 256 sides. */
    hr_vec3 disk[256];
    for (int k = 0; k < 256; k++) {
      double t = -2 * M_PI * k / 256;
      disk[k] = tv(R * cos(t), h, R * sin(t));
    }
    double fr = hr_ff_ref_point_poly(tv(0, 0, 0), tv(0, 1, 0), disk, 256);
    double area256 = 0.5 * 256 * R * R * sin(2 * M_PI / 256);
    double Req = sqrt(area256 / M_PI);
    CHECK_REL(fr, Req * Req / (Req * Req + h * h), 2e-3, "reference point->256-gon ~ disk");
    hr_solver_destroy(&sv);
    hr_scene_destroy(&s);
  }

  printf("reference quadrature vs. closed forms\n");
  {
    hr_vec3 a[4] = {tv(0, 0, 0), tv(0, 0, 1), tv(1, 0, 1), tv(1, 0, 0)};
    hr_vec3 b[4] = {tv(0, 1, 0), tv(1, 1, 0), tv(1, 1, 1), tv(0, 1, 1)};
    CHECK_REL(hr_ff_ref_poly_poly(a, 4, b, 4, 4, 6), howell_parallel(1, 1, 1), 1e-6,
              "ref parallel unit squares");
    hr_vec3 c[4] = {tv(0, 0, 0), tv(1, 0, 0), tv(1, 1, 0), tv(0, 1, 0)};
    CHECK_REL(hr_ff_ref_poly_poly(a, 4, c, 4, 32, 8), howell_perp(1, 1, 1), 2e-3,
              "ref perpendicular unit squares");
  }

  printf("whole solver, one-bounce set-up, default options\n");
  struct {
    const char *what;
    int perp;
    double p[3];
    double want;
  } cases[] = {
      {"parallel 1x1 at c=1", 0, {1, 1, 1}, 0},   {"parallel 1x1 at c=0.5", 0, {1, 1, 0.5}, 0},
      {"parallel 1x1.5 at c=0.5", 0, {1, 1.5, 0.5}, 0}, {"perpendicular 1,1,1", 1, {1, 1, 1}, 0},
      {"perpendicular 1,1,2", 1, {1, 1, 2}, 0},   {"perpendicular 1,2,1", 1, {1, 2, 1}, 0},
  };
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    double *p = cases[i].p;
    double want = cases[i].perp ? howell_perp(p[0], p[1], p[2]) : howell_parallel(p[0], p[1], p[2]);
    hr_scene *s = cases[i].perp ? perp_scene(p[0], p[1], p[2]) : parallel_scene(p[0], p[1], p[2]);
    CHECK_REL(solve_f(s, NULL), want, 0.005, cases[i].what);
    hr_scene_destroy(&s);
  }

  printf("accurate at any BF_low (the quadrature does not need refinement to be right)\n");
  for (int perp = 0; perp < 2; perp++) {
    double bfs[] = {1e-1, 1e-2, 1e-3};
    for (int k = 0; k < 3; k++) {
      hr_options o;
      hr_options_default(&o);
      o.bf_low = bfs[k];
      hr_scene *s = perp ? perp_scene(1, 1, 1) : parallel_scene(1, 1, 1);
      double want = perp ? howell_perp(1, 1, 1) : howell_parallel(1, 1, 1);
      char what[64];
      snprintf(what, sizeof what, "%s, BF_low %.0e", perp ? "perpendicular" : "parallel", bfs[k]);
      CHECK_REL(solve_f(s, &o), want, 0.005, what);
      hr_scene_destroy(&s);
    }
  }
  kernels();
  straddling();
  small_sources();
  point_many();
  point_pairs();
  dark_pairs();
  return t_done("test_ff");
}
