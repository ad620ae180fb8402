/* shaft.c: shaft culling for candidate blocker lists (paper 2.2.1).
 *
 * The shaft of polygons A and B is an intersection of half-spaces that contains every segment
 * from a point of A to a point of B that matters for light transport:
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
 * The BVH is built by median splits along the largest centroid extent (depth <= log2 n + 1),
 * stored in depth-first order with skip indices so that traversal needs no stack. */
#include "vec.h"
#include "vis.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define LEAF_SIZE 4
/* Relative tolerance of the half-spaces: ~8x float rounding of a coordinate. */
#define SHAFT_REL_TOL 1e-6
/* Room for every candidate plane of two quads: 4 own-plane orientations, 2 * 8 edge/normal and
 * 2 * 32 edge/vertex orientations (duplicates are merged, so far fewer are kept). */
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
  int *perm;
};

typedef struct {
  double n[3], d; /* inside: n.x <= d (d already includes the tolerance) */
} plane_t;

typedef struct {
  double lo[3], hi[3]; /* widened box of both polygons */
  int np;
  plane_t p[MAX_PLANES];
  int sa, sb;
} shaft_t;

/* ------------------------------------------------------------------ shaft construction */

/* Adds the half-space n.x <= d (n unit); a plane with (nearly) the same normal as one already
 * kept is merged into it, keeping the tighter of the two offsets (both bound the shaft). */
static void push_plane(shaft_t *sh, hr_vec3 n, double d) {
  for (int k = 0; k < sh->np; k++) {
    plane_t *p = &sh->p[k];
    if (p->n[0] * n.x + p->n[1] * n.y + p->n[2] * n.z > 1 - 1e-12) {
      if (d < p->d) p->d = d;
      return;
    }
  }
  if (sh->np >= MAX_PLANES) return; /* dropping a half-space only enlarges the shaft */
  plane_t *p = &sh->p[sh->np++];
  p->n[0] = n.x, p->n[1] = n.y, p->n[2] = n.z;
  p->d = d;
}

static void add_plane_if_bounding(shaft_t *sh, hr_vec3 n, hr_vec3 at, const hr_vec3 *pts,
                                  int npts, double tol) {
  double len = v3_len(n);
  if (!(len > 0) || !isfinite(len)) return;
  n = v3_scale(n, 1.0 / len);
  double d = v3_dot(n, at), mn = INFINITY, mx = -INFINITY;
  for (int i = 0; i < npts; i++) {
    double s = v3_dot(n, pts[i]) - d;
    mn = s < mn ? s : mn;
    mx = s > mx ? s : mx;
  }
  /* All points within 'tol' on the negative side: n.x <= d + tol bounds them (and the exact
   * hull, since it is the convex hull of these points). Likewise for the positive side. */
  if (mx <= tol) push_plane(sh, n, d + (mx > 0 ? mx : 0) + tol);
  if (mn >= -tol) push_plane(sh, v3_scale(n, -1), -d + (mn < 0 ? -mn : 0) + tol);
}

/* Newell normal of a polygon (unnormalised). */
static hr_vec3 poly_normal(const hr_vec3 *v, int n) {
  hr_vec3 r = {0, 0, 0};
  for (int i = 0; i < n; i++) {
    hr_vec3 a = v[i], b = v[(i + 1) % n];
    r.x += (a.y - b.y) * (a.z + b.z);
    r.y += (a.z - b.z) * (a.x + b.x);
    r.z += (a.x - b.x) * (a.y + b.y);
  }
  return r;
}

/* Adds the front half-space of polygon 'v' (always: by definition of the shaft) and its back
 * half-space when every point lies behind or on its plane (coplanar or back-to-back pairs). */
static void add_own_plane(shaft_t *sh, const hr_vec3 *v, int nv, const hr_vec3 *pts, int npts,
                          double tol) {
  hr_vec3 n = poly_normal(v, nv);
  double len = v3_len(n);
  if (!(len > 0) || !isfinite(len)) return;
  n = v3_scale(n, 1.0 / len);
  double d = 0;
  for (int i = 0; i < nv; i++) d += v3_dot(n, v[i]);
  d /= nv;
  double mx = -INFINITY, pmn = INFINITY, pmx = -INFINITY;
  for (int i = 0; i < nv; i++) {
    double s = v3_dot(n, v[i]) - d;
    pmn = s < pmn ? s : pmn;
    pmx = s > pmx ? s : pmx;
  }
  for (int i = 0; i < npts; i++) {
    double s = v3_dot(n, pts[i]) - d;
    mx = s > mx ? s : mx;
  }
  push_plane(sh, v3_scale(n, -1), -(d + pmn) + tol); /* front: n.x >= d + pmn - tol */
  if (mx <= (pmx > 0 ? pmx : 0) + tol) push_plane(sh, n, d + (mx > 0 ? mx : 0) + tol); /* back */
}

static void shaft_build(shaft_t *sh, const hr_vec3 *pa, int na, int sa, const hr_vec3 *pb,
                        int nb, int sb) {
  hr_vec3 pts[8];
  int npts = 0;
  sh->sa = sa;
  sh->sb = sb;
  sh->np = 0;
  for (int i = 0; i < na && npts < 8; i++) pts[npts++] = pa[i];
  for (int i = 0; i < nb && npts < 8; i++) pts[npts++] = pb[i];
  hr_vec3 lo = pts[0], hi = pts[0];
  double mag = 0;
  for (int i = 0; i < npts; i++) {
    lo = v3_min(lo, pts[i]);
    hi = v3_max(hi, pts[i]);
  }
  mag = fmax(fmax(fmax(fabs(lo.x), fabs(hi.x)), fmax(fabs(lo.y), fabs(hi.y))),
             fmax(fabs(lo.z), fabs(hi.z)));
  mag = fmax(mag, v3_len(v3_sub(hi, lo)));
  double tol = SHAFT_REL_TOL * mag;
  sh->lo[0] = lo.x - tol, sh->lo[1] = lo.y - tol, sh->lo[2] = lo.z - tol;
  sh->hi[0] = hi.x + tol, sh->hi[1] = hi.y + tol, sh->hi[2] = hi.z + tol;

  add_own_plane(sh, pa, na, pts, npts, tol);
  add_own_plane(sh, pb, nb, pts, npts, tol);
  /* Hull faces through an edge of one polygon and a vertex of the other. */
  for (int side = 0; side < 2; side++) {
    const hr_vec3 *p = side ? pb : pa, *q = side ? pa : pb;
    int np = side ? nb : na, nq = side ? na : nb;
    for (int i = 0; i < np; i++) {
      hr_vec3 a = p[i], e = v3_sub(p[(i + 1) % np], a);
      for (int j = 0; j < nq; j++)
        add_plane_if_bounding(sh, v3_cross(e, v3_sub(q[j], a)), a, pts, npts, tol);
    }
  }
  /* An edge and its polygon's normal: the hull's sides when both polygons are coplanar. */
  for (int side = 0; side < 2; side++) {
    const hr_vec3 *p = side ? pb : pa;
    int np = side ? nb : na;
    hr_vec3 nrm = poly_normal(p, np);
    for (int i = 0; i < np; i++) {
      hr_vec3 a = p[i], e = v3_sub(p[(i + 1) % np], a);
      add_plane_if_bounding(sh, v3_cross(e, nrm), a, pts, npts, tol);
    }
  }
}

/* 1 when the box [lo,hi] may intersect the shaft. */
static int box_in_shaft(const shaft_t *sh, const double lo[3], const double hi[3]) {
  if (lo[0] > sh->hi[0] || hi[0] < sh->lo[0] || lo[1] > sh->hi[1] || hi[1] < sh->lo[1] ||
      lo[2] > sh->hi[2] || hi[2] < sh->lo[2])
    return 0;
  for (int k = 0; k < sh->np; k++) {
    const plane_t *p = &sh->p[k];
    double m = (p->n[0] > 0 ? p->n[0] * lo[0] : p->n[0] * hi[0]) +
               (p->n[1] > 0 ? p->n[1] * lo[1] : p->n[1] * hi[1]) +
               (p->n[2] > 0 ? p->n[2] * lo[2] : p->n[2] * hi[2]);
    if (m > p->d) return 0;
  }
  return 1;
}

/* 1 when surface 'f' may intersect the shaft (its box first, then its vertices per plane). */
static int surf_in_shaft(const shaft_t *sh, const hr_surface *f) {
  double lo[3] = {f->v[0].x, f->v[0].y, f->v[0].z}, hi[3] = {lo[0], lo[1], lo[2]};
  for (int k = 1; k < f->nverts; k++) {
    const double c[3] = {f->v[k].x, f->v[k].y, f->v[k].z};
    for (int a = 0; a < 3; a++) {
      lo[a] = c[a] < lo[a] ? c[a] : lo[a];
      hi[a] = c[a] > hi[a] ? c[a] : hi[a];
    }
  }
  if (!box_in_shaft(sh, lo, hi)) return 0;
  for (int k = 0; k < sh->np; k++) {
    const plane_t *p = &sh->p[k];
    int out = 1;
    for (int j = 0; j < f->nverts && out; j++)
      out = p->n[0] * f->v[j].x + p->n[1] * f->v[j].y + p->n[2] * f->v[j].z > p->d;
    if (out) return 0;
  }
  return 1;
}

/* ------------------------------------------------------------------ BVH */

typedef struct {
  const hr_scene *s;
  bvh_node *nodes;
  int nnodes;
  int *perm;
  double *cen; /* [nsurfs][3] centroid (of the box) */
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
  int axis = 0;
  for (int a = 1; a < 3; a++)
    if (chi[a] - clo[a] > chi[axis] - clo[axis]) axis = a;
  int mid = b + (e - b) / 2;
  select_nth(B->perm, B->cen, axis, b, e, mid);
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
  free(B.cen);
  free(B.blo);
  free(B.bhi);
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
  free(*px);
  *px = NULL;
}

static int cmp_i32(const void *a, const void *b) {
  int32_t x = *(const int32_t *)a, y = *(const int32_t *)b;
  return (x > y) - (x < y);
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
  shaft_build(&sh, pa, na, sa, pb, nb, sb);
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
        if (surf_in_shaft(&sh, &s->surfs[id]) && !push_id(out, nout, cap, id))
          return HR_ERR_NOMEM;
      }
    }
    i++;
  }
  if (*nout - start > 1) qsort(*out + start, (size_t)(*nout - start), sizeof **out, cmp_i32);
  return HR_OK;
}

int hr_shaft_filter(const hr_scene *s, const hr_vec3 *pa, int na, int sa, const hr_vec3 *pb,
                    int nb, int sb, const int32_t *cand, int ncand, int32_t *out) {
  shaft_t sh;
  shaft_build(&sh, pa, na, sa, pb, nb, sb);
  int m = 0;
  for (int j = 0; j < ncand; j++) {
    int id = cand[j];
    if (id == sa || id == sb || id < 0 || id >= s->nsurfs) continue;
    if (surf_in_shaft(&sh, &s->surfs[id])) out[m++] = id;
  }
  return m;
}
