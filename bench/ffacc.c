/* ffacc.c: accuracy and cost of the unoccluded form-factor rules of src/ff.h against a converged
 * reference (composite Gauss quadrature of the exact point kernel on the receiver), over
 * configurations that occur in radiosity meshes: parallel plates, perpendicular plates sharing an
 * edge or separated by a gap, random pairs at a given clearance, a receiver reaching through the
 * source's plane, and a long strip (a sliver) under a small plate. Prints, per configuration
 * family and clearance, the worst and RMS relative error of eq. (2) at the centres and of
 * hr_ff_pair at orders 1..3 and the automatic order, and the time per evaluation.
 *   build/bench/ffacc */
#include "ff.h"
#include "ff_ref.h"
#include "vec.h"
#include "xorshift.h"

#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static hr_ff_elem quad(hr_vec3 a, hr_vec3 b, hr_vec3 c, hr_vec3 d) {
  hr_ff_elem e;
  e.nv = 4;
  e.p[0] = a, e.p[1] = b, e.p[2] = c, e.p[3] = d;
  hr_vec3 nn = v3_newell(e.p, 4);
  e.area = 0.5 * v3_len(nn);
  e.n = v3_norm(nn);
  return e;
}

/* Converged reference: m x m cells of order-3 Gauss on the receiver's bilinear map, with cells
 * graded toward all four sides (u -> smoothstep-like map) so that edge singularities converge. */
static double reference(const hr_ff_elem *r, const hr_ff_elem *s, int m) {
  double acc = 0, wsum = 0;
  for (int i = 0; i < m; i++)
    for (int j = 0; j < m; j++) {
      hr_ff_elem cell;
      cell.nv = 4;
      cell.n = r->n;
      double u0 = (double)i / m, u1 = (double)(i + 1) / m, v0 = (double)j / m,
             v1 = (double)(j + 1) / m;
      /* grading: g(t) = t^2 (3 - 2 t) clusters cells at both ends */
#define G(t) ((t) * (t) * (3 - 2 * (t)))
      double a0 = G(u0), a1 = G(u1), b0 = G(v0), b1 = G(v1);
#undef G
      hr_vec3 c[4];
      double uu[4] = {a0, a1, a1, a0}, vv[4] = {b0, b0, b1, b1};
      for (int k = 0; k < 4; k++)
        c[k] = v3_lerp(v3_lerp(r->p[0], r->p[1], uu[k]), v3_lerp(r->p[3], r->p[2], uu[k]), vv[k]);
      for (int k = 0; k < 4; k++) cell.p[k] = c[k];
      cell.area = 0.5 * v3_len(v3_newell(c, 4));
      hr_vec3 x[9];
      double w[9];
      int n = hr_ff_points(&cell, 3, x, w);
      for (int k = 0; k < n; k++) {
        acc += cell.area * w[k] * hr_ff_point(x[k], r->n, s);
        wsum += cell.area * w[k];
      }
    }
  return acc / wsum;
}

typedef struct stat {
  double worst[6], sq[6];
  int n;
} stat;

/* One pair against the reference value 'ref'. */
static void add_ref(stat *st, const hr_ff_elem *r, const hr_ff_elem *s, double ref) {
  if (!(ref > 1e-9)) return;
  double v[6];
  v[0] = hr_ff_disk(r, s);
  for (int o = 1; o <= 3; o++) v[o] = hr_ff_pair(r, s, o, NULL);
  v[4] = hr_ff_pair(r, s, 0, NULL);
  v[5] = hr_ff_order(r, s);
  for (int k = 0; k < 5; k++) {
    double e = fabs(v[k] - ref) / ref;
    st->worst[k] = e > st->worst[k] ? e : st->worst[k];
    st->sq[k] += e * e;
  }
  st->sq[5] += v[5];
  st->n++;
}

static void add(stat *st, const hr_ff_elem *r, const hr_ff_elem *s) {
  add_ref(st, r, s, reference(r, s, 48));
}

static void print(const char *what, const stat *st) {
  if (st->n == 0) return;
  printf("%-34s %4d", what, st->n);
  for (int k = 0; k < 5; k++) printf("  %6.2f%% %6.2f%%", 100 * st->worst[k], 100 * sqrt(st->sq[k] / st->n));
  printf("  %.2f\n", st->sq[5] / st->n);
}

static hr_vec3 rnd_unit(void) {
  for (;;) {
    hr_vec3 v = v3(2 * rnd() - 1, 2 * rnd() - 1, 2 * rnd() - 1);
    double l = v3_len(v);
    if (l > 0.1 && l <= 1) return v3_scale(v, 1 / l);
  }
}

/* A random planar convex quad of diameter about 'size' centred at c with normal n. */
static hr_ff_elem rnd_quad(hr_vec3 c, hr_vec3 n, double size) {
  hr_vec3 t = v3_norm(v3_cross(n, fabs(n.x) < 0.9 ? v3(1, 0, 0) : v3(0, 1, 0)));
  hr_vec3 b = v3_cross(n, t);
  double ang = 2 * M_PI * rnd(), asp = 0.4 + 0.6 * rnd();
  hr_vec3 e1 = v3_add(v3_scale(t, cos(ang)), v3_scale(b, sin(ang)));
  hr_vec3 e2 = v3_cross(n, e1);
  double hx = 0.35 * size, hy = 0.35 * size * asp;
  hr_vec3 p[4];
  double sx[4] = {-1, 1, 1, -1}, sy[4] = {-1, -1, 1, 1};
  for (int k = 0; k < 4; k++) {
    double jx = 1 + 0.2 * (rnd() - 0.5), jy = 1 + 0.2 * (rnd() - 0.5);
    p[k] = v3_add(c, v3_add(v3_scale(e1, sx[k] * hx * jx), v3_scale(e2, sy[k] * hy * jy)));
  }
  /* counter-clockwise seen from +n */
  return quad(p[0], p[1], p[2], p[3]);
}

int main(void) {
  printf("%-34s %4s  %-15s  %-15s  %-15s  %-15s  %-15s  %s\n", "configuration", "n",
         "eq.(2) worst/rms", "order 1", "order 2", "order 3", "auto", "mean order");
  /* Parallel unit squares facing each other at distance c, lateral offset o. */
  double cs[] = {0.05, 0.1, 0.25, 0.5, 1, 2, 4};
  for (int ci = 0; ci < 7; ci++) {
    stat st = {{0}, {0}, 0};
    double c = cs[ci];
    for (int oi = 0; oi < 5; oi++) {
      double o = 0.5 * oi;
      hr_ff_elem r = quad(v3(0, 0, 0), v3(0, 0, 1), v3(1, 0, 1), v3(1, 0, 0));
      hr_ff_elem s = quad(v3(o, c, 0), v3(o + 1, c, 0), v3(o + 1, c, 1), v3(o, c, 1));
      add(&st, &r, &s);
    }
    char name[64];
    snprintf(name, sizeof name, "parallel c=%g", c);
    print(name, &st);
  }
  /* Perpendicular: receiver in y=0 (facing +y), x in [0,1], z in [g, g+w]; source in z=0
   * facing +z, x in [x0, x0+l], y in [y0, y0+h]. */
  double gs[] = {0, 0.05, 0.25, 0.5, 1, 2};
  for (int gi = 0; gi < 6; gi++) {
    stat st = {{0}, {0}, 0};
    double g = gs[gi];
    double ws[] = {1, 0.5, 0.25}, hs[] = {1, 0.5, 2};
    for (int a = 0; a < 3; a++)
      for (int b = 0; b < 3; b++)
        for (int yo = 0; yo < 2; yo++) {
          double w = ws[a], h = hs[b], y0 = yo * 0.5 * h;
          hr_ff_elem r = quad(v3(0, 0, g), v3(0, 0, g + w), v3(1, 0, g + w), v3(1, 0, g));
          hr_ff_elem s = quad(v3(0, y0, 0), v3(1, y0, 0), v3(1, y0 + h, 0), v3(0, y0 + h, 0));
          add(&st, &r, &s);
          /* and the other way round */
          add(&st, &s, &r);
        }
    char name[64];
    snprintf(name, sizeof name, "perpendicular gap=%g", g);
    print(name, &st);
  }
  /* Random pairs: receiver of size 1 at the origin, source of size 0.25-4 at clearance t. */

  double ts[] = {0.1, 0.25, 0.5, 1, 2, 4, 8};
  for (int ti = 0; ti < 7; ti++) {
    stat st = {{0}, {0}, 0};
    for (int k = 0; k < 200; k++) {
      hr_vec3 nr = rnd_unit();
      hr_ff_elem r = rnd_quad(v3(0, 0, 0), nr, 1.0);
      double ssz = pow(2, 4 * rnd() - 2);
      hr_vec3 dir = rnd_unit();
      if (v3_dot(dir, nr) < 0) dir = v3_scale(dir, -1);
      double dist = ts[ti] + 0.5 * (1 + ssz);
      hr_vec3 cs2 = v3_scale(dir, dist);
      hr_vec3 ns = rnd_unit();
      if (v3_dot(ns, dir) > 0) ns = v3_scale(ns, -1);
      hr_ff_elem s = rnd_quad(cs2, ns, ssz);
      add(&st, &r, &s);
    }
    char name[64];
    snprintf(name, sizeof name, "random clearance=%g", ts[ti]);
    print(name, &st);
  }
  /* Straddling: the receiver, a unit square in y = 0 facing +y with z in [-a, 1 - a], reaches
   * through the plane of the source, a square in z = 0 facing +z (x in [0, 1], y in [y0, y0 +
   * h]): hr_ff_point is 0 over the part behind that plane and jumps at z = 0, inside the
   * receiver. Reference: the part in front alone (a rectangle), times its share of the area. */
  {
    stat st = {{0}, {0}, 0};
    double as[] = {0.1, 0.25, 0.5, 0.75}, hs[] = {0.25, 1, 4};
    for (int ai = 0; ai < 4; ai++)
      for (int hi = 0; hi < 3; hi++)
        for (int yo = 0; yo < 2; yo++) {
          const double a = as[ai], h = hs[hi], y0 = yo * 0.5 * h;
          hr_ff_elem r = quad(v3(0, 0, -a), v3(0, 0, 1 - a), v3(1, 0, 1 - a), v3(1, 0, -a));
          hr_ff_elem f = quad(v3(0, 0, 0), v3(0, 0, 1 - a), v3(1, 0, 1 - a), v3(1, 0, 0));
          hr_ff_elem s = quad(v3(0, y0, 0), v3(1, y0, 0), v3(1, y0 + h, 0), v3(0, y0 + h, 0));
          add_ref(&st, &r, &s, reference(&f, &s, 48) * (1 - a));
        }
    print("straddling (receiver through plane)", &st);
  }
  /* Slivers: the receiver a strip L x 1 in z = 0 facing +z, the source a 1 x 4 plate standing
   * at height d over the strip's middle, facing down (-z), its long side across the strip:
   * hr_ff_point peaks over a stretch of the strip about d + 1 long. Reference by reciprocity,
   * the source's area over the receiver's times F from source to receiver, whose kernel is
   * smooth over the small source. */
  double Ls[] = {4, 16, 64, 256};
  for (int li = 0; li < 4; li++) {
    stat st = {{0}, {0}, 0};
    const double L = Ls[li];
    double ds[] = {0.1, 0.5, 2};
    for (int di = 0; di < 3; di++) {
      const double d = ds[di];
      hr_ff_elem r = quad(v3(0, 0, 0), v3(L, 0, 0), v3(L, 1, 0), v3(0, 1, 0));
      hr_ff_elem s = quad(v3(0.5 * L - 0.5, -1.5, d), v3(0.5 * L - 0.5, 2.5, d),
                          v3(0.5 * L + 0.5, 2.5, d), v3(0.5 * L + 0.5, -1.5, d));
      add_ref(&st, &r, &s, reference(&s, &r, 48) * s.area / r.area);
    }
    char name[64];
    snprintf(name, sizeof name, "sliver receiver L=%g", L);
    print(name, &st);
  }
  /* Cost per evaluation. */
  hr_ff_elem r = quad(v3(0, 0, 0), v3(0, 0, 1), v3(1, 0, 1), v3(1, 0, 0));
  hr_ff_elem s = quad(v3(0.3, 1.7, 0), v3(1.3, 1.7, 0), v3(1.3, 1.7, 1), v3(0.3, 1.7, 1));
  for (int o = 0; o <= 3; o++) {
    const int N = 2000000 / (o ? o * o : 1);
    double acc = 0;
    clock_t t0 = clock();
    for (int i = 0; i < N; i++) {
      s.p[0].x += 1e-9;
      acc += o == 0 ? hr_ff_disk(&r, &s) : hr_ff_pair(&r, &s, o, NULL);
    }
    double dt = (double)(clock() - t0) / CLOCKS_PER_SEC;
    printf("cost %s: %.1f ns per pair (%g)\n", o == 0 ? "eq.(2)" : o == 1 ? "order 1" : o == 2 ? "order 2" : "order 3",
           1e9 * dt / N, acc);
  }
  return 0;
}
