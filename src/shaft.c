/* shaft.c: shaft culling for candidate blocker lists (paper 2.2.1).
 *
 * The shaft of polygons A and B (3 or 4 vertices each) is an intersection of half-spaces that
 * contains every segment from a point p of A to a point q of B that matters for light transport,
 * i.e. with q on or in front of A's plane and p on or in front of B's plane:
 *   - the axis-aligned box of both polygons,
 *   - the planes of the convex hull of the two vertex sets: every plane through an edge of one
 *     polygon and a vertex of the other, through an edge and the polygon's own normal (for
 *     coplanar pairs), or the polygons' own planes, kept when all vertices lie on one side of it,
 *   - the front half-spaces of A and of B (a blocker entirely behind A cannot cut a segment that
 *     leaves A's front towards a point in front of A; likewise for B).
 * Every half-space is widened by a tolerance proportional to the coordinates' magnitude, so that
 * segments whose ends were rounded to float still lie inside. A surface is rejected when its
 * vertices all lie outside one half-space; a BVH node when its box does.
 *
 * Node and surface tests: the box first (scalar), then all planes 4 at a time (AVX2 when
 * compiled with it). The BVH is built with binned SAH splits that leave at least 1/8 of the
 * surfaces on each side (depth <= log_{8/7} n; median split when no such split exists), stored in
 * depth-first order with skip indices so that traversal needs no stack. */
#include "vec.h"
#include "vis.h"

#include <math.h>
#ifdef __AVX2__
#include <immintrin.h>
#endif
#include <stdlib.h>
#include <string.h>

#define LEAF_SIZE 4
/* Relative tolerance of the half-spaces: ~8x float rounding of a coordinate. */
#define SHAFT_REL_TOL 1e-6
/* Room for every candidate plane of two quads: 4 own-plane orientations, 2 * 8 edge/normal
 * and 2 * 32 edge/vertex orientations (84, a multiple of 4; duplicates are merged, so far fewer
 * are kept: typically 8-12). */
#define MAX_PLANES 84

typedef struct {
  double lo[3], hi[3];
  int skip;  /* index of the next node after this subtree */
  int first; /* leaf: first index into perm */
  int count; /* leaf: number of surfaces (> 0); internal: 0 */
} bvh_node;

struct hr_shaft_index {
  const hr_scene *s;
  int nnodes;
  bvh_node *nodes;
  int *perm;    /* leaf slots -> surface ids */
  double *sbox; /* per leaf slot: lo[3], hi[3] of that surface */
};

/* The shaft: half-spaces n.x <= d in structure-of-arrays form (padded to a multiple of 4 so the
 * tests vectorise). 'dn' is d plus a little slack for box tests, so that rounding can never make
 * a node test reject a box while the vertex test would keep a surface inside it. */
typedef struct {
  double lo[3], hi[3]; /* box of both polygons, widened by the tolerance */
  int np;
  double nx[MAX_PLANES], ny[MAX_PLANES], nz[MAX_PLANES], d[MAX_PLANES];
  double ax[MAX_PLANES], ay[MAX_PLANES], az[MAX_PLANES], dn[MAX_PLANES];
  /* 'ds' = d - 2 tol: a surface with every vertex beyond it lies outside the exact hull or
   * merely touches its boundary (a wall adjacent to both polygons, a coplanar neighbour). Such a
   * surface meets only segments running along the hull's boundary, never one between interior
   * points of the two polygons, so it is not a candidate. Only for hulls with volume: for a
   * flat (coplanar) pair every segment runs in the boundary, and ds = d. */
  double ds[MAX_PLANES];
} shaft_t;

/* ------------------------------------------------------------------ shaft construction */

/* Adds the half-space n.x <= d (n unit); a plane with (nearly) the same normal as one already
 * kept is merged into it, keeping the tighter of the two offsets (both bound the shaft). */
static void push_plane(shaft_t *sh, hr_vec3 n, double d) {
  for (int k = 0; k < sh->np; k++) {
    if (sh->nx[k] * n.x + sh->ny[k] * n.y + sh->nz[k] * n.z > 1 - 1e-12) {
      if (d < sh->d[k]) sh->d[k] = d;
      return;
    }
  }
  if (sh->np >= MAX_PLANES) return; /* dropping a half-space only enlarges the shaft */
  int k = sh->np++;
  sh->nx[k] = n.x, sh->ny[k] = n.y, sh->nz[k] = n.z, sh->d[k] = d;
}

/* The (up to 8) vertices of both polygons in structure-of-arrays form, padded to 8 by repeating
 * the last one (repeats change no minimum or maximum). */
typedef struct {
  double x[8], y[8], z[8];
} pts8;

/* Smallest and largest of n.p - d over the points. */
static inline void pts8_range(const pts8 *p, hr_vec3 n, double d, double *mn, double *mx) {
#ifdef __AVX2__
  const __m256d vx = _mm256_set1_pd(n.x), vy = _mm256_set1_pd(n.y), vz = _mm256_set1_pd(n.z),
                vd = _mm256_set1_pd(d);
  __m256d s0 = _mm256_add_pd(_mm256_mul_pd(vx, _mm256_loadu_pd(p->x)),
                             _mm256_mul_pd(vy, _mm256_loadu_pd(p->y)));
  __m256d s1 = _mm256_add_pd(_mm256_mul_pd(vx, _mm256_loadu_pd(p->x + 4)),
                             _mm256_mul_pd(vy, _mm256_loadu_pd(p->y + 4)));
  s0 = _mm256_sub_pd(_mm256_add_pd(s0, _mm256_mul_pd(vz, _mm256_loadu_pd(p->z))), vd);
  s1 = _mm256_sub_pd(_mm256_add_pd(s1, _mm256_mul_pd(vz, _mm256_loadu_pd(p->z + 4))), vd);
  __m256d lo = _mm256_min_pd(s0, s1), hi = _mm256_max_pd(s0, s1);
  __m128d lo2 = _mm_min_pd(_mm256_castpd256_pd128(lo), _mm256_extractf128_pd(lo, 1));
  __m128d hi2 = _mm_max_pd(_mm256_castpd256_pd128(hi), _mm256_extractf128_pd(hi, 1));
  *mn = _mm_cvtsd_f64(_mm_min_sd(lo2, _mm_unpackhi_pd(lo2, lo2)));
  *mx = _mm_cvtsd_f64(_mm_max_sd(hi2, _mm_unpackhi_pd(hi2, hi2)));
#else
  double a = INFINITY, b = -INFINITY;
  for (int i = 0; i < 8; i++) {
    double s = n.x * p->x[i] + n.y * p->y[i] + n.z * p->z[i] - d;
    a = s < a ? s : a;
    b = s > b ? s : b;
  }
  *mn = a;
  *mx = b;
#endif
}

static void add_plane_if_bounding(shaft_t *sh, hr_vec3 n, hr_vec3 at, const pts8 *pts,
                                  double tol) {
  double len2 = v3_dot(n, n);
  if (!(len2 > 0) || !isfinite(len2)) return;
  /* Signed distances times |n| first (no square root for the many rejected planes). */
  double d = v3_dot(n, at), mn, mx;
  pts8_range(pts, n, d, &mn, &mx);
  double len = sqrt(len2), tl = tol * len;
  if (!(mx <= tl) && !(mn >= -tl)) return;
  double inv = 1.0 / len;
  n = v3_scale(n, inv);
  d *= inv, mn *= inv, mx *= inv;
  /* All points within 'tol' on the negative side: n.x <= d + tol bounds them (and the exact
   * hull, since it is the convex hull of these points). Likewise for the positive side. */
  if (mx <= tol) push_plane(sh, n, d + (mx > 0 ? mx : 0) + tol);
  if (mn >= -tol) push_plane(sh, v3_scale(n, -1), -d + (mn < 0 ? -mn : 0) + tol);
}

/* Adds the front half-space of polygon 'v' (always: by definition of the shaft) and its back
 * half-space when every point lies behind or on its plane (coplanar or back-to-back pairs). */
static int add_own_plane(shaft_t *sh, const hr_vec3 *v, int nv, const pts8 *pts, double tol) {
  hr_vec3 n = v3_newell(v, nv);
  double len = v3_len(n);
  if (!(len > 0) || !isfinite(len)) return 1;
  n = v3_scale(n, 1.0 / len);
  double d = 0;
  for (int i = 0; i < nv; i++) d += v3_dot(n, v[i]);
  d /= nv;
  double mx, pmn = INFINITY, pmx = -INFINITY;
  for (int i = 0; i < nv; i++) {
    double s = v3_dot(n, v[i]) - d;
    pmn = s < pmn ? s : pmn;
    pmx = s > pmx ? s : pmx;
  }
  double mn_unused;
  pts8_range(pts, n, d, &mn_unused, &mx);
  push_plane(sh, v3_scale(n, -1), -(d + pmn) + tol); /* front: n.x >= d + pmn - tol */
  if (mx <= (pmx > 0 ? pmx : 0) + tol) {
    push_plane(sh, n, d + (mx > 0 ? mx : 0) + tol); /* back */
    return 1;
  }
  return 0;
}

static void shaft_build(shaft_t *sh, const hr_vec3 *pa, int na, const hr_vec3 *pb, int nb) {
  hr_vec3 pts[8];
  int npts = 0;
  sh->np = 0;
  for (int i = 0; i < na && npts < 8; i++) pts[npts++] = pa[i];
  for (int i = 0; i < nb && npts < 8; i++) pts[npts++] = pb[i];
  if (npts == 0) { /* no half-spaces: everything is a candidate */
    for (int a = 0; a < 3; a++) sh->lo[a] = -INFINITY, sh->hi[a] = INFINITY;
    return;
  }
  hr_vec3 lo = v3(INFINITY, INFINITY, INFINITY), hi = v3(-INFINITY, -INFINITY, -INFINITY);
  for (int i = 0; i < npts; i++) {
    lo = v3_min(lo, pts[i]);
    hi = v3_max(hi, pts[i]);
  }
  double mag = fmax(fmax(fmax(fabs(lo.x), fabs(hi.x)), fmax(fabs(lo.y), fabs(hi.y))),
                    fmax(fabs(lo.z), fabs(hi.z)));
  mag = fmax(mag, v3_len(v3_sub(hi, lo)));
  double tol = SHAFT_REL_TOL * mag;
  /* The box of both polygons: tested first, scalar; the best discriminator for far nodes. */
  sh->lo[0] = lo.x - tol, sh->lo[1] = lo.y - tol, sh->lo[2] = lo.z - tol;
  sh->hi[0] = hi.x + tol, sh->hi[1] = hi.y + tol, sh->hi[2] = hi.z + tol;
  /* 'flat': all points on or behind a polygon's plane (coplanar or back-to-back pair). */
  pts8 p8;
  for (int i = 0; i < 8; i++) {
    hr_vec3 q = pts[i < npts ? i : npts - 1];
    p8.x[i] = q.x, p8.y[i] = q.y, p8.z[i] = q.z;
  }
  int flat = add_own_plane(sh, pa, na, &p8, tol);
  flat |= add_own_plane(sh, pb, nb, &p8, tol);
  /* Hull faces through an edge of one polygon and a vertex of the other. */
  for (int side = 0; side < 2; side++) {
    const hr_vec3 *p = side ? pb : pa, *q = side ? pa : pb;
    int np = side ? nb : na, nq = side ? na : nb;
    for (int i = 0; i < np; i++) {
      hr_vec3 a = p[i], e = v3_sub(p[(i + 1) % np], a);
      for (int j = 0; j < nq; j++)
        add_plane_if_bounding(sh, v3_cross(e, v3_sub(q[j], a)), a, &p8, tol);
    }
  }
  /* An edge and its polygon's normal: the hull's sides when both polygons are coplanar. Other
   * pairs need none: every face of the hull of two convex planar polygons that are not flat is
   * a polygon's own plane or holds an edge of one polygon and a vertex of the other. */
  for (int side = 0; side < 2 && flat; side++) {
    const hr_vec3 *p = side ? pb : pa;
    int np = side ? nb : na;
    hr_vec3 nrm = v3_newell(p, np);
    for (int i = 0; i < np; i++) {
      hr_vec3 a = p[i], e = v3_sub(p[(i + 1) % np], a);
      add_plane_if_bounding(sh, v3_cross(e, nrm), a, &p8, tol);
    }
  }
  const double slack = 1e-9 * mag;
  for (int k = 0; k < sh->np; k++) {
    sh->ax[k] = fabs(sh->nx[k]);
    sh->ay[k] = fabs(sh->ny[k]);
    sh->az[k] = fabs(sh->nz[k]);
    sh->dn[k] = sh->d[k] + slack;
    sh->ds[k] = flat ? sh->d[k] : sh->d[k] - 2 * tol;
  }
  /* Pad to a multiple of 4 with copies of the first plane (same answers, whole vectors). */
  while (sh->np % 4 && sh->np > 0) {
    int k = sh->np++;
    sh->nx[k] = sh->nx[0], sh->ny[k] = sh->ny[0], sh->nz[k] = sh->nz[0], sh->d[k] = sh->d[0];
    sh->ax[k] = sh->ax[0], sh->ay[k] = sh->ay[0], sh->az[k] = sh->az[0], sh->dn[k] = sh->dn[0];
    sh->ds[k] = sh->ds[0];
  }
}

/* 1 when the box [lo,hi] may intersect the shaft: no plane has the whole box outside. */
static int box_in_shaft(const shaft_t *sh, const double lo[3], const double hi[3]) {
  if (lo[0] > sh->hi[0] || hi[0] < sh->lo[0] || lo[1] > sh->hi[1] || hi[1] < sh->lo[1] ||
      lo[2] > sh->hi[2] || hi[2] < sh->lo[2])
    return 0;
  const double cx = 0.5 * (lo[0] + hi[0]), cy = 0.5 * (lo[1] + hi[1]), cz = 0.5 * (lo[2] + hi[2]);
  const double hx = 0.5 * (hi[0] - lo[0]), hy = 0.5 * (hi[1] - lo[1]), hz = 0.5 * (hi[2] - lo[2]);
#ifdef __AVX2__
  const __m256d vcx = _mm256_set1_pd(cx), vcy = _mm256_set1_pd(cy), vcz = _mm256_set1_pd(cz);
  const __m256d vhx = _mm256_set1_pd(hx), vhy = _mm256_set1_pd(hy), vhz = _mm256_set1_pd(hz);
  __m256d acc = _mm256_setzero_pd();
  for (int k = 0; k < sh->np; k += 4) {
    __m256d m = _mm256_mul_pd(_mm256_loadu_pd(sh->nx + k), vcx);
    m = _mm256_add_pd(m, _mm256_mul_pd(_mm256_loadu_pd(sh->ny + k), vcy));
    m = _mm256_add_pd(m, _mm256_mul_pd(_mm256_loadu_pd(sh->nz + k), vcz));
    __m256d r = _mm256_mul_pd(_mm256_loadu_pd(sh->ax + k), vhx);
    r = _mm256_add_pd(r, _mm256_mul_pd(_mm256_loadu_pd(sh->ay + k), vhy));
    r = _mm256_add_pd(r, _mm256_mul_pd(_mm256_loadu_pd(sh->az + k), vhz));
    acc = _mm256_or_pd(acc,
                       _mm256_cmp_pd(_mm256_sub_pd(m, r), _mm256_loadu_pd(sh->dn + k), _CMP_GT_OQ));
  }
  return _mm256_movemask_pd(acc) == 0;
#else
  int out = 0;
  for (int k = 0; k < sh->np; k++)
    out |= sh->nx[k] * cx + sh->ny[k] * cy + sh->nz[k] * cz -
               (sh->ax[k] * hx + sh->ay[k] * hy + sh->az[k] * hz) >
           sh->dn[k];
  return !out;
#endif
}

/* 1 when surface 'f' may intersect the shaft: no plane has all its vertices outside it or on
 * it (within the tolerance; see shaft_t.ds). */
static int surf_in_shaft(const shaft_t *sh, const hr_surface *f) {
  const hr_vec3 *v = f->v;
  const int nv = f->nverts;
  double lo[3] = {v[0].x, v[0].y, v[0].z}, hi[3] = {v[0].x, v[0].y, v[0].z};
  for (int j = 1; j < nv; j++) {
    lo[0] = v[j].x < lo[0] ? v[j].x : lo[0], hi[0] = v[j].x > hi[0] ? v[j].x : hi[0];
    lo[1] = v[j].y < lo[1] ? v[j].y : lo[1], hi[1] = v[j].y > hi[1] ? v[j].y : hi[1];
    lo[2] = v[j].z < lo[2] ? v[j].z : lo[2], hi[2] = v[j].z > hi[2] ? v[j].z : hi[2];
  }
  if (lo[0] > sh->hi[0] || hi[0] < sh->lo[0] || lo[1] > sh->hi[1] || hi[1] < sh->lo[1] ||
      lo[2] > sh->hi[2] || hi[2] < sh->lo[2])
    return 0;
#ifdef __AVX2__
  __m256d acc = _mm256_setzero_pd();
  for (int k = 0; k < sh->np; k += 4) {
    const __m256d nx = _mm256_loadu_pd(sh->nx + k), ny = _mm256_loadu_pd(sh->ny + k),
                  nz = _mm256_loadu_pd(sh->nz + k), d = _mm256_loadu_pd(sh->ds + k);
    __m256d all = _mm256_castsi256_pd(_mm256_set1_epi64x(-1));
    for (int j = 0; j < nv; j++) {
      __m256d m = _mm256_mul_pd(nx, _mm256_set1_pd(v[j].x));
      m = _mm256_add_pd(m, _mm256_mul_pd(ny, _mm256_set1_pd(v[j].y)));
      m = _mm256_add_pd(m, _mm256_mul_pd(nz, _mm256_set1_pd(v[j].z)));
      all = _mm256_and_pd(all, _mm256_cmp_pd(m, d, _CMP_GT_OQ));
    }
    acc = _mm256_or_pd(acc, all);
  }
  return _mm256_movemask_pd(acc) == 0;
#else
  int out = 0;
  for (int k = 0; k < sh->np; k++) {
    int o = 1;
    for (int j = 0; j < nv; j++)
      o &= sh->nx[k] * v[j].x + sh->ny[k] * v[j].y + sh->nz[k] * v[j].z > sh->ds[k];
    out |= o;
  }
  return !out;
#endif
}

/* ------------------------------------------------------------------ BVH */

typedef struct {
  const hr_scene *s;
  bvh_node *nodes;
  int nnodes;
  int *perm;
  double *cen;       /* [nsurfs][3] centroid (of the box) */
  double *blo, *bhi; /* [nsurfs][3] surface boxes */
} builder;

static void select_nth(int *perm, const double *cen, int axis, int b, int e, int nth) {
  /* Quickselect: afterwards perm[b..nth) <= perm[nth] <= perm[nth+1..e) by centroid[axis]. */
  while (e - b > 1) {
    int m = b + (e - b) / 2;
    double pivot = cen[3 * perm[m] + axis];
    int i = b, j = e - 1;
    while (i <= j) {
      while (cen[3 * perm[i] + axis] < pivot) i++;
      while (cen[3 * perm[j] + axis] > pivot) j--;
      if (i <= j) {
        int t = perm[i];
        perm[i] = perm[j];
        perm[j] = t;
        i++;
        j--;
      }
    }
    if (nth <= j)
      e = j + 1;
    else if (nth >= i)
      b = i;
    else
      return;
  }
}

static double half_area(const double lo[3], const double hi[3]) {
  double x = hi[0] - lo[0], y = hi[1] - lo[1], z = hi[2] - lo[2];
  return x * y + y * z + z * x;
}

/* Binned surface-area-heuristic split of perm[b..e): partitions the range and returns the split
 * point, or b when no split leaves at least 1/8 of the items on each side (which bounds the
 * depth by log_{8/7} n). */
static int sah_split(builder *B, int b, int e, const double clo[3], const double chi[3]) {
  enum { NB = 16 };
  const int n = e - b, minside = n / 8 > 1 ? n / 8 : 1;
  double best = INFINITY;
  int best_axis = -1, best_bin = 0;
  for (int a = 0; a < 3; a++) {
    double ext = chi[a] - clo[a];
    if (!(ext > 0)) continue;
    int cnt[NB] = {0};
    double blo[NB][3], bhi[NB][3];
    for (int k = 0; k < NB; k++)
      for (int c = 0; c < 3; c++) blo[k][c] = INFINITY, bhi[k][c] = -INFINITY;
    for (int i = b; i < e; i++) {
      int id = B->perm[i];
      int k = (int)((B->cen[3 * id + a] - clo[a]) / ext * NB);
      k = k < 0 ? 0 : k >= NB ? NB - 1 : k;
      cnt[k]++;
      for (int c = 0; c < 3; c++) {
        blo[k][c] = fmin(blo[k][c], B->blo[3 * id + c]);
        bhi[k][c] = fmax(bhi[k][c], B->bhi[3 * id + c]);
      }
    }
    /* sweep from the right, then from the left */
    double rarea[NB];
    int rcnt[NB];
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    int c_ = 0;
    for (int k = NB - 1; k > 0; k--) {
      for (int c = 0; c < 3; c++) lo[c] = fmin(lo[c], blo[k][c]), hi[c] = fmax(hi[c], bhi[k][c]);
      c_ += cnt[k];
      rcnt[k] = c_;
      rarea[k] = c_ ? half_area(lo, hi) : 0;
    }
    for (int c = 0; c < 3; c++) lo[c] = INFINITY, hi[c] = -INFINITY;
    c_ = 0;
    for (int k = 0; k < NB - 1; k++) { /* split between bin k and k+1 */
      for (int c = 0; c < 3; c++) lo[c] = fmin(lo[c], blo[k][c]), hi[c] = fmax(hi[c], bhi[k][c]);
      c_ += cnt[k];
      if (c_ < minside || rcnt[k + 1] < minside) continue;
      double cost = half_area(lo, hi) * c_ + rarea[k + 1] * rcnt[k + 1];
      if (cost < best) best = cost, best_axis = a, best_bin = k;
    }
  }
  if (best_axis < 0) return b;
  const int a = best_axis;
  const double ext = chi[a] - clo[a];
  int i = b, j = e - 1;
  while (i <= j) {
    int id = B->perm[i];
    int k = (int)((B->cen[3 * id + a] - clo[a]) / ext * NB);
    k = k < 0 ? 0 : k >= NB ? NB - 1 : k;
    if (k <= best_bin) {
      i++;
    } else {
      B->perm[i] = B->perm[j];
      B->perm[j--] = id;
    }
  }
  return i;
}

static void build_rec(builder *B, int b, int e) {
  int me = B->nnodes++;
  bvh_node *nd = &B->nodes[me];
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  double clo[3] = {INFINITY, INFINITY, INFINITY}, chi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (int i = b; i < e; i++) {
    int id = B->perm[i];
    for (int a = 0; a < 3; a++) {
      lo[a] = fmin(lo[a], B->blo[3 * id + a]);
      hi[a] = fmax(hi[a], B->bhi[3 * id + a]);
      clo[a] = fmin(clo[a], B->cen[3 * id + a]);
      chi[a] = fmax(chi[a], B->cen[3 * id + a]);
    }
  }
  memcpy(nd->lo, lo, sizeof lo);
  memcpy(nd->hi, hi, sizeof hi);
  if (e - b <= LEAF_SIZE) {
    nd->first = b;
    nd->count = e - b;
    nd->skip = B->nnodes;
    return;
  }
  int mid = sah_split(B, b, e, clo, chi);
  if (mid <= b || mid >= e) { /* no useful SAH split: median along the widest centroid axis */
    int axis = 0;
    for (int a = 1; a < 3; a++)
      if (chi[a] - clo[a] > chi[axis] - clo[axis]) axis = a;
    mid = b + (e - b) / 2;
    select_nth(B->perm, B->cen, axis, b, e, mid);
  }
  nd->first = b;
  nd->count = 0;
  build_rec(B, b, mid);
  build_rec(B, mid, e);
  B->nodes[me].skip = B->nnodes;
}

hr_status hr_shaft_index_create(const hr_scene *s, hr_shaft_index **out) {
  *out = NULL;
  hr_shaft_index *x = calloc(1, sizeof *x);
  if (!x) return HR_ERR_NOMEM;
  x->s = s;
  int n = s->nsurfs;
  if (n == 0) {
    *out = x;
    return HR_OK;
  }
  builder B = {0};
  B.s = s;
  B.nodes = malloc((size_t)2 * (size_t)n * sizeof *B.nodes);
  B.perm = malloc((size_t)n * sizeof *B.perm);
  B.cen = malloc((size_t)n * 3 * sizeof *B.cen);
  B.blo = malloc((size_t)n * 3 * sizeof *B.blo);
  B.bhi = malloc((size_t)n * 3 * sizeof *B.bhi);
  if (!B.nodes || !B.perm || !B.cen || !B.blo || !B.bhi) {
    free(B.nodes);
    free(B.perm);
    free(B.cen);
    free(B.blo);
    free(B.bhi);
    free(x);
    return HR_ERR_NOMEM;
  }
  for (int i = 0; i < n; i++) {
    const hr_surface *f = &s->surfs[i];
    hr_vec3 lo = f->v[0], hi = f->v[0];
    for (int k = 1; k < f->nverts; k++) {
      lo = v3_min(lo, f->v[k]);
      hi = v3_max(hi, f->v[k]);
    }
    B.blo[3 * i] = lo.x, B.blo[3 * i + 1] = lo.y, B.blo[3 * i + 2] = lo.z;
    B.bhi[3 * i] = hi.x, B.bhi[3 * i + 1] = hi.y, B.bhi[3 * i + 2] = hi.z;
    for (int a = 0; a < 3; a++) B.cen[3 * i + a] = 0.5 * (B.blo[3 * i + a] + B.bhi[3 * i + a]);
    B.perm[i] = i;
  }
  build_rec(&B, 0, n);
  x->sbox = malloc((size_t)n * 6 * sizeof *x->sbox);
  if (x->sbox)
    for (int k = 0; k < n; k++)
      for (int a = 0; a < 3; a++) {
        x->sbox[6 * k + a] = B.blo[3 * B.perm[k] + a];
        x->sbox[6 * k + 3 + a] = B.bhi[3 * B.perm[k] + a];
      }
  free(B.cen);
  free(B.blo);
  free(B.bhi);
  if (!x->sbox) {
    free(B.nodes);
    free(B.perm);
    free(x);
    return HR_ERR_NOMEM;
  }
  bvh_node *shrunk = realloc(B.nodes, (size_t)B.nnodes * sizeof *B.nodes);
  x->nodes = shrunk ? shrunk : B.nodes;
  x->nnodes = B.nnodes;
  x->perm = B.perm;
  *out = x;
  return HR_OK;
}

void hr_shaft_index_destroy(hr_shaft_index **px) {
  if (!px || !*px) return;
  free((*px)->nodes);
  free((*px)->perm);
  free((*px)->sbox);
  free(*px);
  *px = NULL;
}

static int cmp_i32(const void *a, const void *b) {
  int32_t x = *(const int32_t *)a, y = *(const int32_t *)b;
  return (x > y) - (x < y);
}

/* Sorts ids increasingly: insertion sort for the usual short lists, qsort for long ones. */
static void sort_ids(int32_t *a, int n) {
  if (n > 48) {
    qsort(a, (size_t)n, sizeof *a, cmp_i32);
    return;
  }
  for (int i = 1; i < n; i++) {
    int32_t v = a[i];
    int j = i - 1;
    while (j >= 0 && a[j] > v) {
      a[j + 1] = a[j];
      j--;
    }
    a[j + 1] = v;
  }
}

static int push_id(int32_t **out, int *nout, int *cap, int32_t id) {
  if (*nout >= *cap) {
    int nc = *cap > 0 ? *cap : 16;
    while (nc <= *nout) {
      if (nc > (1 << 29)) return 0;
      nc *= 2;
    }
    int32_t *q = realloc(*out, (size_t)nc * sizeof *q);
    if (!q) return 0;
    *out = q;
    *cap = nc;
  }
  (*out)[(*nout)++] = id;
  return 1;
}

hr_status hr_shaft_candidates(const hr_shaft_index *x, const hr_vec3 *pa, int na, int sa,
                              const hr_vec3 *pb, int nb, int sb, int32_t **out, int *nout,
                              int *cap) {
  if (x->nnodes == 0) return HR_OK;
  shaft_t sh;
  shaft_build(&sh, pa, na, pb, nb);
  const hr_scene *s = x->s;
  int start = *nout;
  for (int i = 0; i < x->nnodes;) {
    const bvh_node *nd = &x->nodes[i];
    if (!box_in_shaft(&sh, nd->lo, nd->hi)) {
      i = nd->skip;
      continue;
    }
    if (nd->count > 0) {
      for (int k = nd->first; k < nd->first + nd->count; k++) {
        int id = x->perm[k];
        if (id == sa || id == sb) continue;
        if (!box_in_shaft(&sh, x->sbox + 6 * k, x->sbox + 6 * k + 3)) continue;
        if (surf_in_shaft(&sh, &s->surfs[id]) && !push_id(out, nout, cap, id)) return HR_ERR_NOMEM;
      }
    }
    i++;
  }
  if (*nout > start) sort_ids(*out + start, *nout - start);
  return HR_OK;
}

int hr_shaft_filter(const hr_scene *s, const hr_vec3 *pa, int na, int sa, const hr_vec3 *pb, int nb,
                    int sb, const int32_t *cand, int ncand, int32_t *out) {
  shaft_t sh;
  shaft_build(&sh, pa, na, pb, nb);
  int m = 0;
  for (int j = 0; j < ncand; j++) {
    int id = cand[j];
    if (id == sa || id == sb || id < 0 || id >= s->nsurfs) continue;
    if (surf_in_shaft(&sh, &s->surfs[id])) out[m++] = id;
  }
  return m;
}
