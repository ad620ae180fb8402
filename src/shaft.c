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
 * Node and surface tests: the box first (scalar), then all planes 4 at a time (AVX2 when the
 * CPU has it: shaft_kern.h is compiled for the baseline and for AVX2, chosen at run time). The
 * BVH is built with binned SAH splits that leave at least 1/8 of the surfaces on each side
 * (depth <= log_{8/7} n; median split when no such split exists), stored in depth-first order
 * with skip indices so that traversal needs no stack. */
#include "vec.h"
#include "vis.h"

#include <math.h>
#if (defined(__x86_64__) || defined(__i386__)) && defined(__GNUC__)
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

/* ------------------------------------------------------------------ kernels, dispatch */

/* The baseline instance of the kernels, and on x86 with GCC or clang the AVX2 one. */
#define KERN_AVX2 0
#define KERN_ATTR
#define KERN(name) name##_base
#include "shaft_kern.h"
#undef KERN_AVX2
#undef KERN_ATTR
#undef KERN
#if (defined(__x86_64__) || defined(__i386__)) && defined(__GNUC__)
#define HR_SHAFT_AVX2 1
#define KERN_AVX2 1
#define KERN_ATTR __attribute__((target("avx2")))
#define KERN(name) name##_avx2
#include "shaft_kern.h"
#else
#define HR_SHAFT_AVX2 0
#endif

static int g_force_base; /* hr_shaft_use_avx2(0) */

int hr_shaft_use_avx2(int allow) {
  g_force_base = !allow;
#if HR_SHAFT_AVX2
  return allow && __builtin_cpu_supports("avx2");
#else
  return 0;
#endif
}

/* Whether this call takes the AVX2 kernels: the CPU has them and no test turned them off. */
static inline int avx2(void) {
#if HR_SHAFT_AVX2
  return !g_force_base && __builtin_cpu_supports("avx2");
#else
  return 0;
#endif
}

hr_status hr_shaft_candidates(const hr_shaft_index *x, const hr_vec3 *pa, int na, int sa,
                              const hr_vec3 *pb, int nb, int sb, int32_t **out, int *nout,
                              int *cap) {
  if (x->nnodes == 0) return HR_OK;
  int start = *nout;
  hr_status st;
#if HR_SHAFT_AVX2
  if (avx2())
    st = candidates_avx2(x, pa, na, sa, pb, nb, sb, out, nout, cap);
  else
#endif
    st = candidates_base(x, pa, na, sa, pb, nb, sb, out, nout, cap);
  if (st == HR_OK && *nout > start) sort_ids(*out + start, *nout - start);
  return st;
}

int hr_shaft_filter(const hr_scene *s, const hr_vec3 *pa, int na, int sa, const hr_vec3 *pb, int nb,
                    int sb, const int32_t *cand, int ncand, int32_t *out) {
#if HR_SHAFT_AVX2
  if (avx2()) return filter_avx2(s, pa, na, sa, pb, nb, sb, cand, ncand, out);
#endif
  return filter_base(s, pa, na, sa, pb, nb, sb, cand, ncand, out);
}
