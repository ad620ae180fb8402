/* ff.c: form-factor kernels on element geometry (see ff.h). */
#include "ff.h"
#include "vec.h"

#include <assert.h>
#include <stdint.h>
#include <string.h>

/* c ? a : b without a branch (the conditions below are data-dependent, and a mispredicted
 * branch costs more than the arithmetic of both sides). */
static inline double pick(int c, double a, double b) {
  uint64_t ua, ub;
  memcpy(&ua, &a, sizeof ua);
  memcpy(&ub, &b, sizeof ub);
  const uint64_t m = -(uint64_t)(c != 0), u = (ua & m) | (ub & ~m);
  double r;
  memcpy(&r, &u, sizeof r);
  return r;
}

/* angle()'s polynomial in z^2 and its range bound, tan(pi/8) (angle4 shares them). */
static const double ATAN_C[6] = {0.9999999993712282,   -0.33333306893050196,
                                 0.19998183041131562,  -0.14239532670272484,
                                 0.1056982881025639,   -0.060263052365912374};
static const double TAN_PI_8 = 0.41421356237309503;

/* The angle between two vectors from |u x v| = y >= 0 and u . v = x, in [0, pi]: atan2(y, x)
 * by range reduction to |z| <= tan(pi/8) and a polynomial in z^2 fitted at Chebyshev nodes
 * (absolute error below 3e-10 rad, measured on 20001 points; about 4x faster than atan2). */
static inline double angle(double y, double x) {
  const double *C = ATAN_C;
  const double ax = fabs(x);
  const int steep = y > ax;
  const double num = pick(steep, ax, y), den = pick(steep, y, ax);
  if (!(den > 0)) return 0;
  const double t0 = num / den, t1 = (t0 - 1) / (t0 + 1);
  const int big = t0 > TAN_PI_8;
  const double t = pick(big, t1, t0), base = pick(big, 0.25 * M_PI, 0);
  const double s = t * t;
  double a = base + t * (C[0] + s * (C[1] + s * (C[2] + s * (C[3] + s * (C[4] + s * C[5])))));
  a = pick(steep, 0.5 * M_PI - a, a);
  return pick(x < 0, M_PI - a, a);
}

double hr_ff_point(hr_vec3 x, hr_vec3 nx, const hr_ff_elem *s) {
  /* One-sided source: x must lie in front of its plane. */
  if (!(v3_dot(v3_sub(x, s->p[0]), s->n) > 0)) return 0;
  const int nv = s->nv;
  hr_vec3 a[4];
  double d[4];
  int nin = 0;
  for (int k = 0; k < nv; k++) {
    a[k] = v3_sub(s->p[k], x);
    d[k] = v3_dot(a[k], nx);
    nin += d[k] > 0;
  }
  if (nin == 0) return 0;
  hr_vec3 q[5];
  int m = 0;
  if (nin == nv) {
    for (int k = 0; k < nv; k++) q[k] = a[k];
    m = nv;
  } else {
    /* Clip to the front half-space of x's tangent plane (Sutherland-Hodgman): a convex polygon
     * cut by a plane keeps at most one more vertex. */
    for (int k = 0; k < nv; k++) {
      int k1 = k + 1 == nv ? 0 : k + 1;
      if (d[k] > 0) q[m++] = a[k];
      if ((d[k] > 0) != (d[k1] > 0)) {
        double t = d[k] / (d[k] - d[k1]);
        q[m++] = v3_lerp(a[k], a[k1], t);
      }
    }
  }
  /* Lambert: F = -1/(2 pi) sum over edges of angle(q_k, q_k+1) nx . unit(q_k x q_k+1); the
   * sign is negative because the polygon is counter-clockwise seen from its front, where x is. */
  double sum = 0;
  for (int k = 0; k < m; k++) {
    hr_vec3 u = q[k], v = q[k + 1 == m ? 0 : k + 1];
    hr_vec3 c = v3_cross(u, v);
    double cl = v3_len(c);
    if (!(cl > 0)) continue;
    sum += angle(cl, v3_dot(u, v)) * v3_dot(nx, c) / cl;
  }
  double f = -sum * (0.5 / M_PI);
  return f > 0 ? f : 0;
}

#if (defined(__x86_64__) || defined(__i386__)) && defined(__GNUC__)
#define HR_FF_AVX2 1
#include <immintrin.h>

#define AVX2_ATTR __attribute__((target("avx2")))

/* angle() on four lanes: the same operations, the picks as blends. */
AVX2_ATTR static inline __m256d angle4(__m256d y, __m256d x) {
  const __m256d zero = _mm256_setzero_pd(), one = _mm256_set1_pd(1);
  const __m256d ax = _mm256_andnot_pd(_mm256_set1_pd(-0.0), x);
  const __m256d steep = _mm256_cmp_pd(y, ax, _CMP_GT_OQ);
  const __m256d num = _mm256_blendv_pd(y, ax, steep), den = _mm256_blendv_pd(ax, y, steep);
  const __m256d ok = _mm256_cmp_pd(den, zero, _CMP_GT_OQ);
  const __m256d t0 = _mm256_div_pd(num, den);
  const __m256d t1 = _mm256_div_pd(_mm256_sub_pd(t0, one), _mm256_add_pd(t0, one));
  const __m256d big = _mm256_cmp_pd(t0, _mm256_set1_pd(TAN_PI_8), _CMP_GT_OQ);
  const __m256d t = _mm256_blendv_pd(t0, t1, big);
  const __m256d base = _mm256_blendv_pd(zero, _mm256_set1_pd(0.25 * M_PI), big);
  const __m256d s = _mm256_mul_pd(t, t);
  __m256d p = _mm256_set1_pd(ATAN_C[5]); /* C0 + s (C1 + s (... + s C5)), inside out */
  for (int i = 4; i >= 0; i--) p = _mm256_add_pd(_mm256_set1_pd(ATAN_C[i]), _mm256_mul_pd(s, p));
  __m256d a = _mm256_add_pd(base, _mm256_mul_pd(t, p));
  a = _mm256_blendv_pd(a, _mm256_sub_pd(_mm256_set1_pd(0.5 * M_PI), a), steep);
  a = _mm256_blendv_pd(a, _mm256_sub_pd(_mm256_set1_pd(M_PI), a),
                       _mm256_cmp_pd(x, zero, _CMP_LT_OQ));
  return _mm256_and_pd(a, ok);
}

/* (ax bx + ay by) + az bz, as v3_dot. */
AVX2_ATTR static inline __m256d dot4(__m256d ax, __m256d ay, __m256d az, __m256d bx, __m256d by,
                                     __m256d bz) {
  return _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(ax, bx), _mm256_mul_pd(ay, by)),
                       _mm256_mul_pd(az, bz));
}

/* One edge (u, v) of Lambert's sum on four lanes: angle(|u x v|, u . v) nx . (u x v) / |u x v|,
 * and +0 where |u x v| is 0 (hr_ff_point skips the edge: adding +0 to its sum, which is never
 * -0, changes nothing). */
AVX2_ATTR static inline __m256d edge4(__m256d ux, __m256d uy, __m256d uz, __m256d vx, __m256d vy,
                                      __m256d vz, __m256d nxx, __m256d nxy, __m256d nxz) {
  const __m256d cx = _mm256_sub_pd(_mm256_mul_pd(uy, vz), _mm256_mul_pd(uz, vy));
  const __m256d cy = _mm256_sub_pd(_mm256_mul_pd(uz, vx), _mm256_mul_pd(ux, vz));
  const __m256d cz = _mm256_sub_pd(_mm256_mul_pd(ux, vy), _mm256_mul_pd(uy, vx));
  const __m256d cl = _mm256_sqrt_pd(dot4(cx, cy, cz, cx, cy, cz));
  const __m256d ang = angle4(cl, dot4(ux, uy, uz, vx, vy, vz));
  const __m256d term = _mm256_div_pd(_mm256_mul_pd(ang, dot4(nxx, nxy, nxz, cx, cy, cz)), cl);
  return _mm256_and_pd(term, _mm256_cmp_pd(cl, _mm256_setzero_pd(), _CMP_GT_OQ));
}

/* Four lanes' sources: corners (nv of them; a triangle among quads repeats its first corner as
 * its fourth, which adds a zero-length edge, +0, to its sum) and front normals. */
typedef struct src4 {
  __m256d px[4], py[4], pz[4], nx, ny, nz;
} src4;

/* hr_ff_point on four lanes (points X, Y, Z, each with its lane's source in S). Where a source
 * straddles a point's tangent plane, the clipped polygon's edges in hr_ff_point's order: for
 * each corner k, (a_k, its successor) if a_k is in front, then (I_k, its successor) if edge k
 * crosses the plane at I_k; a corner's successor is I_k where edge k leaves, else a_k+1; an
 * exit's is the entry point. A lane whose polygon crosses the plane other than twice (rounding,
 * near-degenerate corners) is set in *mscalar, for hr_ff_point itself. */
AVX2_ATTR static inline __m256d lanes_ff(__m256d X, __m256d Y, __m256d Z, const src4 *S, int nv,
                                         __m256d nxx, __m256d nxy, __m256d nxz, int *mscalar) {
  const __m256d zero = _mm256_setzero_pd(), one = _mm256_set1_pd(1);
  /* in front of the source's plane */
  const __m256d ox = _mm256_sub_pd(X, S->px[0]), oy = _mm256_sub_pd(Y, S->py[0]),
                oz = _mm256_sub_pd(Z, S->pz[0]);
  const __m256d front =
      _mm256_cmp_pd(dot4(ox, oy, oz, S->nx, S->ny, S->nz), zero, _CMP_GT_OQ);
  __m256d ax[4], ay[4], az[4], d[4], in[4], all = front, any = zero;
  for (int k = 0; k < nv; k++) {
    ax[k] = _mm256_sub_pd(S->px[k], X);
    ay[k] = _mm256_sub_pd(S->py[k], Y);
    az[k] = _mm256_sub_pd(S->pz[k], Z);
    d[k] = dot4(ax[k], ay[k], az[k], nxx, nxy, nxz);
    in[k] = _mm256_cmp_pd(d[k], zero, _CMP_GT_OQ);
    all = _mm256_and_pd(all, in[k]), any = _mm256_or_pd(any, in[k]);
  }
  const __m256d lit = _mm256_and_pd(front, any); /* lanes with something in front */
  const int mall = _mm256_movemask_pd(all), mlit = _mm256_movemask_pd(lit);
  __m256d sum = zero;
  *mscalar = 0;
  if (mlit & ~mall) { /* some lane's source is clipped */
    __m256d ix[4], iy[4], iz[4], cross[4], ncross = zero, ex = zero, ey = zero, ez = zero;
    for (int k = 0; k < nv; k++) {
      const int k1 = k + 1 == nv ? 0 : k + 1;
      cross[k] = _mm256_xor_pd(in[k], in[k1]);
      ncross = _mm256_add_pd(ncross, _mm256_and_pd(cross[k], one));
      const __m256d t = _mm256_div_pd(d[k], _mm256_sub_pd(d[k], d[k1]));
      ix[k] = _mm256_add_pd(ax[k], _mm256_mul_pd(_mm256_sub_pd(ax[k1], ax[k]), t));
      iy[k] = _mm256_add_pd(ay[k], _mm256_mul_pd(_mm256_sub_pd(ay[k1], ay[k]), t));
      iz[k] = _mm256_add_pd(az[k], _mm256_mul_pd(_mm256_sub_pd(az[k1], az[k]), t));
      const __m256d entry = _mm256_andnot_pd(in[k], cross[k]);
      ex = _mm256_blendv_pd(ex, ix[k], entry), ey = _mm256_blendv_pd(ey, iy[k], entry);
      ez = _mm256_blendv_pd(ez, iz[k], entry);
    }
    *mscalar = mlit & ~mall &
               ~_mm256_movemask_pd(_mm256_cmp_pd(ncross, _mm256_set1_pd(2), _CMP_EQ_OQ));
    for (int k = 0; k < nv; k++) {
      const int k1 = k + 1 == nv ? 0 : k + 1;
      /* (a_k, I_k where the edge crosses, else a_k1) where a_k is in front */
      __m256d vx = _mm256_blendv_pd(ax[k1], ix[k], cross[k]),
              vy = _mm256_blendv_pd(ay[k1], iy[k], cross[k]),
              vz = _mm256_blendv_pd(az[k1], iz[k], cross[k]);
      sum = _mm256_add_pd(sum, _mm256_and_pd(in[k], edge4(ax[k], ay[k], az[k], vx, vy, vz, nxx,
                                                          nxy, nxz)));
      /* (I_k, the entry where a_k is in front, else a_k1) where the edge crosses */
      vx = _mm256_blendv_pd(ax[k1], ex, in[k]), vy = _mm256_blendv_pd(ay[k1], ey, in[k]);
      vz = _mm256_blendv_pd(az[k1], ez, in[k]);
      sum = _mm256_add_pd(sum, _mm256_and_pd(cross[k], edge4(ix[k], iy[k], iz[k], vx, vy, vz,
                                                             nxx, nxy, nxz)));
    }
  } else if (mall) { /* the same edges with no plane crossed, at half the work */
    for (int k = 0; k < nv; k++) {
      const int k1 = k + 1 == nv ? 0 : k + 1;
      sum = _mm256_add_pd(sum,
                          edge4(ax[k], ay[k], az[k], ax[k1], ay[k1], az[k1], nxx, nxy, nxz));
    }
  }
  __m256d f = _mm256_mul_pd(_mm256_xor_pd(sum, _mm256_set1_pd(-0.0)), _mm256_set1_pd(0.5 / M_PI));
  return _mm256_and_pd(f, _mm256_and_pd(lit, _mm256_cmp_pd(f, zero, _CMP_GT_OQ)));
}

/* Points x[b, b + 4) (the first repeated past n) into X, Y, Z. */
AVX2_ATTR static inline void load_points(const hr_vec3 *const *x, __m256d *X, __m256d *Y,
                                         __m256d *Z) {
  *X = _mm256_set_pd(x[3]->x, x[2]->x, x[1]->x, x[0]->x);
  *Y = _mm256_set_pd(x[3]->y, x[2]->y, x[1]->y, x[0]->y);
  *Z = _mm256_set_pd(x[3]->z, x[2]->z, x[1]->z, x[0]->z);
}

/* lanes_ff at the points p[0, 4) (normal nx) into fv; returns the lanes for hr_ff_point. */
AVX2_ATTR static inline int lanes_at(const hr_vec3 *const *p, const src4 *S, int nv, hr_vec3 nx,
                                     double *fv) {
  __m256d X, Y, Z;
  load_points(p, &X, &Y, &Z);
  int mscalar;
  _mm256_storeu_pd(fv, lanes_ff(X, Y, Z, S, nv, _mm256_set1_pd(nx.x), _mm256_set1_pd(nx.y),
                                _mm256_set1_pd(nx.z), &mscalar));
  return mscalar;
}

/* hr_ff_point_many on four lanes: one source for all. */
AVX2_ATTR static void point_many_avx2(const hr_vec3 *x, int n, hr_vec3 nx, const hr_ff_elem *s,
                                      double *out) {
  const int nv = s->nv;
  src4 S;
  for (int k = 0; k < nv; k++)
    S.px[k] = _mm256_set1_pd(s->p[k].x), S.py[k] = _mm256_set1_pd(s->p[k].y),
    S.pz[k] = _mm256_set1_pd(s->p[k].z);
  S.nx = _mm256_set1_pd(s->n.x), S.ny = _mm256_set1_pd(s->n.y), S.nz = _mm256_set1_pd(s->n.z);
  for (int b = 0; b < n; b += 4) {
    const int m = n - b < 4 ? n - b : 4;
    const hr_vec3 *p[4];
    for (int l = 0; l < 4; l++) p[l] = &x[b + (l < m ? l : 0)];
    double fv[4];
    const int mscalar = lanes_at(p, &S, nv, nx, fv);
    for (int l = 0; l < m; l++)
      out[b + l] = (mscalar >> l & 1) ? hr_ff_point(x[b + l], nx, s) : fv[l];
  }
}

/* hr_ff_point_pairs on four lanes: each lane its own point and source. */
AVX2_ATTR static void point_pairs_avx2(const hr_vec3 *const *x, const hr_ff_elem *const *s,
                                       int n, hr_vec3 nx, double *out) {
  for (int b = 0; b < n; b += 4) {
    const int m = n - b < 4 ? n - b : 4;
    const hr_vec3 *p[4];
    const hr_ff_elem *q[4];
    int nv = 3;
    for (int l = 0; l < 4; l++) {
      p[l] = x[b + (l < m ? l : 0)], q[l] = s[b + (l < m ? l : 0)];
      nv = q[l]->nv > nv ? q[l]->nv : nv;
    }
    src4 S;
    for (int k = 0; k < nv; k++) {
      const hr_vec3 *c[4];
      for (int l = 0; l < 4; l++) c[l] = &q[l]->p[k < q[l]->nv ? k : 0];
      load_points(c, &S.px[k], &S.py[k], &S.pz[k]);
    }
    const hr_vec3 *nn[4] = {&q[0]->n, &q[1]->n, &q[2]->n, &q[3]->n};
    load_points(nn, &S.nx, &S.ny, &S.nz);
    double fv[4];
    const int mscalar = lanes_at(p, &S, nv, nx, fv);
    for (int l = 0; l < m; l++)
      out[b + l] = (mscalar >> l & 1) ? hr_ff_point(*x[b + l], nx, s[b + l]) : fv[l];
  }
}
#else
#define HR_FF_AVX2 0
#endif

static int g_ff_base; /* hr_ff_use_avx2(0) */

int hr_ff_use_avx2(int allow) {
  g_ff_base = !allow;
#if HR_FF_AVX2
  return allow && __builtin_cpu_supports("avx2");
#else
  return 0;
#endif
}

void hr_ff_point_many(const hr_vec3 *x, int n, hr_vec3 nx, const hr_ff_elem *s, double *out) {
#if HR_FF_AVX2
  if (!g_ff_base && __builtin_cpu_supports("avx2")) {
    point_many_avx2(x, n, nx, s, out);
    return;
  }
#endif
  for (int k = 0; k < n; k++) out[k] = hr_ff_point(x[k], nx, s);
}

void hr_ff_point_pairs(const hr_vec3 *const *x, const hr_ff_elem *const *s, int n, hr_vec3 nx,
                       double *out) {
#if HR_FF_AVX2
  if (!g_ff_base && __builtin_cpu_supports("avx2")) {
    point_pairs_avx2(x, s, n, nx, out);
    return;
  }
#endif
  for (int k = 0; k < n; k++) out[k] = hr_ff_point(*x[k], nx, s[k]);
}

/* Gauss-Legendre nodes on [0,1] and weights summing to 1, orders 1..3. */
static const double GX[3][3] = {{0.5}, {0.21132486540518713, 0.7886751345948129},
                                {0.1127016653792583, 0.5, 0.8872983346207417}};
static const double GW[3][3] = {{1}, {0.5, 0.5}, {5.0 / 18, 8.0 / 18, 5.0 / 18}};

/* Symmetric triangle rules (barycentric points, weights summing to 1): 1 point (degree 1),
 * 3 points (degree 2), 6 points (degree 4, Strang & Fix / Dunavant). */
static int tri_rule(int order, double (*b)[3], double *w) {
  if (order <= 1) {
    b[0][0] = b[0][1] = b[0][2] = 1.0 / 3;
    w[0] = 1;
    return 1;
  }
  if (order == 2) {
    for (int k = 0; k < 3; k++) {
      for (int j = 0; j < 3; j++) b[k][j] = j == k ? 2.0 / 3 : 1.0 / 6;
      w[k] = 1.0 / 3;
    }
    return 3;
  }
  static const double a1 = 0.445948490915965, w1 = 0.223381589678011;
  static const double a2 = 0.091576213509771, w2 = 0.109951743655322;
  for (int k = 0; k < 3; k++) {
    for (int j = 0; j < 3; j++) {
      b[k][j] = j == k ? 1 - 2 * a1 : a1;
      b[3 + k][j] = j == k ? 1 - 2 * a2 : a2;
    }
    w[k] = w1;
    w[3 + k] = w2;
  }
  return 6;
}

int hr_ff_points(const hr_ff_elem *e, int order, hr_vec3 *x, double *w) {
  if (order < 1) order = 1;
  if (order > 3) order = 3;
  if (e->nv == 3) {
    double b[6][3];
    int n = tri_rule(order, b, w);
    for (int k = 0; k < n; k++)
      x[k] = v3_add(v3_add(v3_scale(e->p[0], b[k][0]), v3_scale(e->p[1], b[k][1])),
                    v3_scale(e->p[2], b[k][2]));
    return n;
  }
  /* Bilinear map of the unit square, Gauss-Legendre in each parameter, weights times the
   * Jacobian (planar convex quads need not be parallelograms). */
  const hr_vec3 *p = e->p;
  int n = 0;
  double wsum = 0;
  for (int i = 0; i < order; i++)
    for (int j = 0; j < order; j++) {
      double u = GX[order - 1][i], v = GX[order - 1][j];
      hr_vec3 a = v3_lerp(p[0], p[1], u), b = v3_lerp(p[3], p[2], u);
      hr_vec3 du = v3_lerp(v3_sub(p[1], p[0]), v3_sub(p[2], p[3]), v);
      hr_vec3 dv = v3_sub(b, a);
      x[n] = v3_lerp(a, b, v);
      w[n] = GW[order - 1][i] * GW[order - 1][j] * v3_len(v3_cross(du, dv));
      wsum += w[n++];
    }
  for (int k = 0; k < n; k++) w[k] /= wsum;
  return n;
}

/* Largest distance between two corners of 'e' (its diameter). */
static double diameter(const hr_ff_elem *e) {
  double d = 0;
  for (int i = 0; i < e->nv; i++)
    for (int j = i + 1; j < e->nv; j++) {
      hr_vec3 t = v3_sub(e->p[i], e->p[j]);
      double l = v3_dot(t, t);
      d = l > d ? l : d;
    }
  return sqrt(d);
}

static hr_vec3 vcentroid(const hr_ff_elem *e) {
  hr_vec3 c = {0, 0, 0};
  for (int k = 0; k < e->nv; k++) c = v3_add(c, e->p[k]);
  return v3_scale(c, 1.0 / e->nv);
}

/* How many corners of 'b' lie on or behind the plane of 'a'. */
static int corners_behind(const hr_ff_elem *a, const hr_ff_elem *b) {
  int n = 0;
  for (int k = 0; k < b->nv; k++) n += v3_dot(v3_sub(b->p[k], a->p[0]), a->n) <= 0;
  return n;
}

/* 1 if some corner of 'b' lies behind the plane of 'a' (b straddles or lies behind it). */
static int some_behind(const hr_ff_elem *a, const hr_ff_elem *b) {
  return corners_behind(a, b) > 0;
}

/* 1 when every corner of b is on or behind a's plane. */
static int all_behind(const hr_ff_elem *a, const hr_ff_elem *b) {
  return corners_behind(a, b) == b->nv;
}

int hr_ff_pair_dark(const hr_ff_elem *r, const hr_ff_elem *s) {
  /* a point x of r is a convex combination of r's corners: all on or behind s's plane, so is
   * x, and hr_ff_point's first test fails; all of s on or behind r's plane, so no corner of s
   * is in front of x's tangent plane (r's plane), and its clipping leaves nothing */
  return all_behind(r, s) || all_behind(s, r);
}

hr_ff_shape hr_ff_shape_of(const hr_ff_elem *e) {
  return (hr_ff_shape){diameter(e), vcentroid(e)};
}

/* hr_ff_order for a pair that is in front of each other's planes: by the clearance, a lower
 * bound of the distance between the two polygons, over the receiver's size. */
static int clearance_order(const hr_ff_shape *rs, const hr_ff_shape *ss) {
  const double t = (v3_len(v3_sub(rs->c, ss->c)) - 0.5 * (rs->diam + ss->diam)) / rs->diam;
  return t > 4.0 ? 1 : t > 1.0 ? 2 : 3;
}

int hr_ff_order(const hr_ff_elem *r, const hr_ff_elem *s) {
  /* Where one element reaches behind the other's plane, the point form factor has a kink or a
   * jump over the receiver: the highest order. */
  if (some_behind(r, s) || some_behind(s, r)) return 3;
  const hr_ff_shape rs = hr_ff_shape_of(r), ss = hr_ff_shape_of(s);
  return clearance_order(&rs, &ss);
}

int hr_ff_pair_class(const hr_ff_elem *r, const hr_ff_elem *s, const hr_ff_shape *rs,
                     const hr_ff_shape *ss) {
  const int brs = corners_behind(r, s), bsr = corners_behind(s, r);
  if (brs == s->nv || bsr == r->nv) return 0; /* hr_ff_pair_dark */
  return brs > 0 || bsr > 0 ? 3 : clearance_order(rs, ss); /* hr_ff_order */
}

/* Point-to-disk estimate of the point form factor at x (normal nx) from source 's' seen as a
 * disk of its area at its vertex centroid 'cs': cheap, for the spread of far pairs. */
static double disk_point(hr_vec3 x, hr_vec3 nx, const hr_ff_elem *s, hr_vec3 cs) {
  hr_vec3 d = v3_sub(cs, x);
  double r2 = v3_dot(d, d);
  if (!(r2 > 0)) return 0;
  double inv = 1.0 / sqrt(r2);
  double ci = v3_dot(nx, d) * inv, cj = -v3_dot(s->n, d) * inv;
  if (ci <= 0 || cj <= 0) return 0;
  return ci * cj * s->area / (M_PI * r2 + s->area);
}

/* Distance from the centre of a Gauss rule's outermost point to the element's side, as a factor
 * on the spread between the outermost points: orders 2 and 3 place them at 0.577 and 0.775 of
 * the half-width. */
static const double SPREAD_EXTRAPOLATE[4] = {0, 0, 1.7320508075688772, 1.2909944487358056};

/* Straddling receivers (hr_ff_clip_points). Where the receiver reaches through the source's
 * plane, hr_ff_point is 0 over the part behind it and jumps at the line where the plane cuts
 * the receiver; Gauss points over the whole receiver made such pairs' form factors 35% RMS off
 * (80% at worst; `build/bench/ffacc`, "straddling"), and `office`'s straddling links 12-19%
 * low: things standing on the floor or against a wall. Integrating over the part in front,
 * cut out exactly, is within 1%.
 *
 * Slivers keep the plain rule. On a long thin receiver near a small source the kernel peaks
 * over a stretch that neither rule resolves (ffacc "sliver": errors of 49% to 8126%), and
 * there the plain rule's errors happened to offset others: clipping slivers too put the
 * conference room's window rail and sill, strips 7.7 m long and 7-12 cm wide beside the blind's
 * slats, 30-70% dark (the room 4.03% -> 6.08% RMS; BENCHMARKS.md, sixteenth pass). Their fix
 * is adaptive quadrature and visibility for near pairs, not this. The bound: 8 and 16 did
 * alike, 64 made the conference room 4.15% (16: 4.07%). */
#define HR_FF_CLIP_ELONGATION 16.0

int hr_ff_clip_points(const hr_ff_elem *r, const hr_ff_elem *s, hr_vec3 *x, double *w) {
  double d[4];
  int nin = 0, nout = 0;
  for (int k = 0; k < r->nv; k++) {
    d[k] = v3_dot(v3_sub(r->p[k], s->p[0]), s->n);
    nin += d[k] > 0, nout += d[k] < 0;
  }
  if (!nin || !nout || !(r->area > 0)) return 0;
  const double dr = diameter(r);
  if (dr * dr > HR_FF_CLIP_ELONGATION * r->area) return 0;
  /* Sutherland-Hodgman against the plane, corners on it kept */
  hr_vec3 q[5];
  int m = 0;
  for (int k = 0; k < r->nv; k++) {
    const int k1 = k + 1 == r->nv ? 0 : k + 1;
    if (d[k] >= 0) q[m++] = r->p[k];
    if ((d[k] > 0 && d[k1] < 0) || (d[k] < 0 && d[k1] > 0))
      q[m++] = v3_lerp(r->p[k], r->p[k1], d[k] / (d[k] - d[k1]));
  }
  assert(m >= 3 && m <= 5);
  int n = 0;
  for (int t = 1; t + 1 < m; t++) {
    const hr_ff_elem tri = {3, {q[0], q[t], q[t + 1], q[t + 1]}, r->n, 0};
    const double at = 0.5 * v3_len(v3_cross(v3_sub(q[t], q[0]), v3_sub(q[t + 1], q[0])));
    const int nt = hr_ff_points(&tri, 3, x + n, w + n);
    for (int k = 0; k < nt; k++) w[n + k] *= at / r->area;
    n += nt;
  }
  return n;
}

/* Small near sources. Where a source much smaller than the receiver is near it, the point
 * form factor peaks over the part of the receiver next to the source, which the receiver's 9
 * points miss or hit; integrated over the small source instead (the point form factor from its
 * points to the receiver polygon, exact) and taken back by reciprocity, F(r <- s) = A_s / A_r
 * F(s <- r), it is smooth (ffacc, RMS: perpendicular plates meeting at an edge 2.09 -> 0.51%,
 * random pairs at clearance 0.1 1.66 -> 0.07%), and `office` went from 1.080% to 1.038%.
 * It goes before the clipped rule: a small source reaches through the receiver's plane as
 * well, and the source's points then stop at that plane (hr_ff_point clips the receiver
 * polygon to each point's tangent plane); clipping the receiver instead left office at 1.091%.
 * Neither may be a sliver (the rule of HR_FF_CLIP_ELONGATION, and for the same reason: the
 * conference room's window rail). */
int hr_ff_recip_applies(const hr_ff_elem *r, const hr_ff_elem *s, double dr, double ds) {
  return ds < 0.5 * dr && dr * dr <= HR_FF_CLIP_ELONGATION * r->area &&
         ds * ds <= HR_FF_CLIP_ELONGATION * s->area;
}

double hr_ff_recip(const hr_ff_elem *r, const hr_ff_elem *s) {
  hr_vec3 y[HR_FF_CLIP_POINTS];
  double wy[HR_FF_CLIP_POINTS], fy[HR_FF_CLIP_POINTS], g = 0;
  int m = hr_ff_clip_points(s, r, y, wy);
  if (m == 0) m = hr_ff_points(s, 3, y, wy);
  hr_ff_point_many(y, m, s->n, r, fy);
  for (int k = 0; k < m; k++) g += wy[k] * fy[k];
  return r->area > 0 ? g * s->area / r->area : 0;
}

double hr_ff_pair(const hr_ff_elem *r, const hr_ff_elem *s, int order, double *spread) {
  if (order <= 0) order = hr_ff_order(r, s);
  hr_vec3 x[HR_FF_CLIP_POINTS];
  double w[HR_FF_CLIP_POINTS];
  int n = hr_ff_clip_points(r, s, x, w);
  if (n > 0) order = 3; /* the spread's extrapolation of order 3 */
  else n = hr_ff_points(r, order, x, w);
  const int recip = order == 3 && hr_ff_recip_applies(r, s, diameter(r), diameter(s));
  if (recip && !spread) return hr_ff_recip(r, s); /* the receiver's points only for the spread */
  double f = 0, lo = INFINITY, hi = 0, fx[HR_FF_CLIP_POINTS];
  hr_ff_point_many(x, n, r->n, s, fx);
  for (int k = 0; k < n; k++) {
    const double fk = fx[k];
    f += w[k] * fk;
    lo = fk < lo ? fk : lo;
    hi = fk > hi ? fk : hi;
  }
  if (recip) f = hr_ff_recip(r, s); /* the spread stays the receiver points' */
  if (spread) {
    if (order >= 2) {
      *spread = (hi - lo) * SPREAD_EXTRAPOLATE[order];
    } else {
      /* One point: the spread of the point-to-disk estimate over the receiver's corners. */
      hr_vec3 cs = vcentroid(s);
      double klo = INFINITY, khi = 0;
      for (int k = 0; k < r->nv; k++) {
        double kk = disk_point(r->p[k], r->n, s, cs);
        klo = kk < klo ? kk : klo;
        khi = kk > khi ? kk : khi;
      }
      *spread = khi - klo;
    }
  }
  return f;
}

double hr_ff_source_weight(const hr_ff_elem *r, const hr_ff_elem *s) {
  if (some_behind(r, s)) return 1;
  double dr = diameter(r), ds = diameter(s);
  double gap = v3_len(v3_sub(vcentroid(r), vcentroid(s))) - 0.5 * (dr + ds);
  return gap > ds ? ds / gap : 1;
}

double hr_ff_disk(const hr_ff_elem *r, const hr_ff_elem *s) {
  hr_vec3 d = v3_sub(vcentroid(s), vcentroid(r));
  double r2 = v3_dot(d, d);
  if (!(r2 > 0)) return 0;
  double inv = 1.0 / sqrt(r2);
  double ci = v3_dot(r->n, d) * inv, cj = -v3_dot(s->n, d) * inv;
  if (ci <= 0 || cj <= 0) return 0;
  return ci * cj * s->area / (M_PI * r2 + s->area);
}

/* The four children of element 'e' (elem.c's subdivision: edge midpoints, and the centre of a
 * quad), as polygons with e's normal. */
static void children4(const hr_ff_elem *e, hr_ff_elem *c) {
  const hr_vec3 *p = e->p;
  for (int k = 0; k < 4; k++) {
    c[k].nv = e->nv;
    c[k].n = e->n;
  }
  if (e->nv == 4) {
    hr_vec3 m01 = v3_lerp(p[0], p[1], .5), m12 = v3_lerp(p[1], p[2], .5),
            m23 = v3_lerp(p[2], p[3], .5), m30 = v3_lerp(p[3], p[0], .5),
            mc = v3_lerp(m01, m23, .5);
    const hr_vec3 q[4][4] = {{p[0], m01, mc, m30}, {m01, p[1], m12, mc},
                             {mc, m12, p[2], m23}, {m30, mc, m23, p[3]}};
    for (int k = 0; k < 4; k++) {
      for (int j = 0; j < 4; j++) c[k].p[j] = q[k][j];
      c[k].area = 0.5 * v3_len(v3_newell(q[k], 4));
    }
  } else {
    hr_vec3 m01 = v3_lerp(p[0], p[1], .5), m12 = v3_lerp(p[1], p[2], .5),
            m20 = v3_lerp(p[2], p[0], .5);
    const hr_vec3 t[4][3] = {{p[0], m01, m20}, {m01, p[1], m12}, {m20, m12, p[2]},
                             {m12, m20, m01}};
    for (int k = 0; k < 4; k++) {
      for (int j = 0; j < 3; j++) c[k].p[j] = t[k][j];
      c[k].p[3] = t[k][2];
      c[k].area = 0.25 * e->area;
    }
  }
}

double hr_ff_pair_shares(const hr_ff_elem *r, const hr_ff_elem *s, int order, float share[4]) {
  if (order <= 0) order = hr_ff_order(r, s);
  hr_ff_elem c[4];
  children4(s, c);
  hr_vec3 x[9];
  double w[9], fc[4] = {0, 0, 0, 0};
  int n = hr_ff_points(r, order, x, w);
  for (int q = 0; q < 4; q++) { /* each child's sum in the points' order, as before */
    double fx[9];
    hr_ff_point_many(x, n, r->n, &c[q], fx);
    for (int k = 0; k < n; k++) fc[q] += w[k] * fx[k];
  }
  double f = fc[0] + fc[1] + fc[2] + fc[3];
  for (int q = 0; q < 4; q++) share[q] = f > 0 ? (float)(fc[q] / f) : -1.0f;
  return f;
}
