/* cluster.c: hierarchical clustering (see cluster.h and docs/design.md, "Clustering").
 *
 * The hierarchy: a binary tree over the surfaces, split along the longest axis of the
 * centroids' box by the surface area heuristic over binned centroids (at the median centroid,
 * ties by surface id, where they all share a bin; deterministic either way), clusters numbered in
 * preorder so that a parent comes before its children. Each cluster knows its surfaces (a range
 * of 'perm'), its bounding box and sphere, its area, the largest reflectance of its surfaces and
 * N_lm = sum_i A_i Y_lm(n_i), the order-2 spherical harmonics of its area-weighted normals.
 *
 * Transfer (oriented on both sides in the mean, Sillion's "directional" cluster simplified):
 *  - A cluster link's form factor F is the receiver-area mean of the exact point form factor,
 *    estimated by k rays between points drawn by area on the two nodes' surfaces (cosines
 *    clamped at 0, so a surface turned away neither sends nor receives), keyed by the two ids so
 *    that it does not depend on threads. The source sends its surfaces' area-weighted mean
 *    radiosity.
 *  - A cluster receives the power F A_R B_S as an incident field from the direction d of the
 *    source, kept as order-2 spherical harmonics (9 numbers a channel, Ramamoorthi & Hanrahan
 *    2001: the clamped-cosine irradiance of any incident field to a few per cent). The field
 *    is scaled so that the cluster's surfaces together receive exactly that power (the
 *    normalisation sum_lm A_l Y_lm(d) N_lm), flows unchanged to the child clusters, and a
 *    surface with normal n gets the irradiance E(n) = sum_lm A_l L_lm Y_lm(n), at least 0.
 *  - Refinement: a link is kept when rho_R F_max (B_S k + dB_S) <= BF_e bref_R, with F_max =
 *    min(1, A_S / (pi d^2)) for the gap d between the bounding spheres, k = min(1, (r_R + r_S)
 *    / d) how much the kernel varies over the two, B_S the source's mean and dB_S the range of
 *    its surfaces' radiosities, bref_R the receiver's reference radiosity times its slack
 *    (--importance, hr_slack); else the larger cluster opens. Two surfaces make an element
 *    link (link.c) and refine from then on as elements do. */
#include "cluster.h"
#include "mpi/dist.h"
#include "partition/partition.h"
#include "solver_impl.h"
#include "vec.h"

#include <assert.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define NCH 5 /* field channels: RGB, max channel (for Gu), 1 (for Gf) */

typedef struct cnode {
  int32_t child[2]; /* node ids */
  int32_t lo, hi;   /* surfaces perm[lo, hi) */
  hr_vec3 bmin, bmax, c;
  double rad, area;
  hr_vec3 na;  /* normal cone: the surfaces' normals lie within angle nang of axis na */
  double nang;
} cnode;

/* A surface as node_point draws from it, in the hierarchy's order (one cache miss, not three). */
typedef struct csurf {
  hr_vec3 v[4], n; /* corners (v[3] unused for triangles), unit normal */
  int nv;
} csurf;

typedef struct clink {
  int32_t r, s; /* node ids: receiver, source */
  float F;      /* receiver-area mean form factor with visibility; < 0: not estimated yet */
  float kf;     /* for a cluster receiver: field per unit source radiosity, F A_R / D */
  float d[3];   /* unit direction from the receiver's centre to the source's */
  /* The oracle's geometry, computed once: the form-factor bound, how much the kernel varies
   * over the two nodes (both < 0 until first decided) and twice the unoccluded estimate (< 0
   * until needed); kv's sign says whether the source is far (far_source). */
  float fb, kv, fu2;
} clink;

struct hr_clusters {
  int32_t n, root; /* clusters; the root's node id */
  double size;     /* the root's bounding-sphere radius */
  cnode *node;
  int32_t *perm;
  double *cum;        /* cum[k]: area of perm[0, k) */
  csurf *sp;          /* sp[k]: surface perm[k] */
  hr_ff_elem *sg;     /* sg[k], sh[k]: surface perm[k]'s geometry and shape for form factors */
  hr_ff_shape *sh;
  double *srad;       /* per surface: bounding-sphere radius about its centroid */
  double (*nsh)[9];   /* per cluster: N_lm */
  double *rho;        /* per cluster: largest reflectance channel of its surfaces */
  double (*Bm)[3];    /* per cluster: area-weighted mean of its surfaces' sent radiosity */
  double *bhi, *blo;  /* per cluster: range of its surfaces' radiosities (largest channel) */
  double *bref;       /* per cluster: area-weighted mean reference radiosity of its surfaces,
                         without their slacks */
  double *slack;      /* per cluster: its slack by its area (hr_slack) */
  /* per cluster: incident field, A_l-weighted, from near sources [0] (taken by each surface
   * with Y_lm(n)) and far ones [1] (taken with its transfer vector) */
  double (*L)[2][NCH][9];
  /* Transfer (docs/design.md, "Clustering"): per surface root, Y_lm(n) less what nearby
   * geometry hides (tq); per cluster, N_lm from those (nsht) and how far its surfaces' rays
   * looked (lray); NULL until the ray caster exists */
  double (*tq)[9], (*nsht)[9], *lray;
  int initial;        /* before the first pull: reference radiosities are the floor */
  /* The links and, per link, its place: where it stands in the order in which refinement makes
   * links (the first round's kept links in their order, then each later round's, a round's
   * links being the children of the round before in their parents' order; docs/design.md,
   * "Clustering"); 'vnext' is the next unused place. A rank holds the links of the receivers
   * it owns, in link order: grouped by receiver (ascending node id), each receiver's by
   * place. The gather sums each receiver's links in place order, which is the same in one
   * process and on any number of ranks, and it streams through the links. */
  clink *links;
  int64_t *pos;
  int64_t nlinks, cap; /* links, and room for them */
  int64_t vnext;
  /* per cluster: rays refinement cast here for the links it receives (graph balancing's work,
   * balance.c; an element's go to s->erays) */
  float *crays;
  /* per cluster: the rank that holds the links it receives (drawn from its number, or set by
   * graph balancing: hr_cluster_set_owners) */
  int32_t *cown;
};

const double hr_sh_alpha[9] = {M_PI, 2 * M_PI / 3, 2 * M_PI / 3, 2 * M_PI / 3, M_PI / 4,
                               M_PI / 4, M_PI / 4, M_PI / 4, M_PI / 4};

void hr_sh9(const double d[3], double y[9]) {
  const double x = d[0], yy = d[1], z = d[2];
  y[0] = 0.282095;
  y[1] = 0.488603 * yy;
  y[2] = 0.488603 * z;
  y[3] = 0.488603 * x;
  y[4] = 1.092548 * x * yy;
  y[5] = 1.092548 * yy * z;
  y[6] = 0.315392 * (3 * z * z - 1);
  y[7] = 1.092548 * x * z;
  y[8] = 0.546274 * (x * x - yy * yy);
}

static inline double max3(const double *v) {
  double x = v[0] > v[1] ? v[0] : v[1];
  return x > v[2] ? x : v[2];
}

int hr_cluster_wanted(const hr_options *o, int nsurfs) {
  if (o->cluster == HR_CLUSTER_ON) return 1;
  if (o->cluster == HR_CLUSTER_OFF) return 0;
  const double pairs = 0.5 * (double)nsurfs * (double)(nsurfs - 1);
  return o->max_links > 0 && pairs > o->max_links;
}

/* ---------------------------------------------------------------- the hierarchy */

typedef struct builder {
  hr_clusters *cl;
  const hr_vec3 *cen; /* surface centroids */
  const hr_vec3 *blo, *bhi; /* surface boxes */
  int axis;
} builder;

static double key(const builder *b, int32_t i) {
  const hr_vec3 c = b->cen[i];
  return b->axis == 0 ? c.x : b->axis == 1 ? c.y : c.z;
}

static int before(const builder *b, int32_t i, int32_t j) {
  const double ki = key(b, i), kj = key(b, j);
  return ki < kj || (ki == kj && i < j);
}

/* Quickselect: perm[lo, hi) rearranged so that perm[m] is in place and nothing before it comes
 * after it (a total order: ties by surface id). */
static void select_nth(const builder *b, int32_t *p, int32_t lo, int32_t hi, int32_t m) {
  while (hi - lo > 1) {
    const int32_t mid = lo + (hi - lo) / 2;
    /* median of three as the pivot */
    int32_t a = p[lo], c = p[mid], e = p[hi - 1], piv;
    if (before(b, a, c)) piv = before(b, c, e) ? c : (before(b, a, e) ? e : a);
    else piv = before(b, a, e) ? a : (before(b, c, e) ? e : c);
    int32_t i = lo, j = hi - 1;
    while (i <= j) {
      while (before(b, p[i], piv)) i++;
      while (before(b, piv, p[j])) j--;
      if (i <= j) {
        int32_t t = p[i];
        p[i] = p[j], p[j] = t;
        i++, j--;
      }
    }
    if (m <= j) hi = j + 1;
    else if (m >= i) lo = i;
    else return;
  }
}

static void surf_box(const hr_surface *f, hr_vec3 *lo, hr_vec3 *hi) {
  *lo = *hi = f->v[0];
  for (int k = 1; k < f->nverts; k++) *lo = v3_min(*lo, f->v[k]), *hi = v3_max(*hi, f->v[k]);
}

/* The split of a cluster: the surface area heuristic (as in ray-tracing BVHs) over SAH_BINS
 * bins of the centroids along the longest axis of their box: the boundary between bins with
 * the least half-area of each side's box (of the surfaces' boxes) times its count. Against a
 * split at the median centroid, the conference room solves with 18% fewer links at 0.82x the
 * wall time and 0.87x the peak memory, its error unchanged (BENCHMARKS.md, "Clustering, sixth
 * pass"). */
#define SAH_BINS 16
static double box_half_area(hr_vec3 lo, hr_vec3 hi) {
  const hr_vec3 e = v3_sub(hi, lo);
  return e.x * e.y + e.y * e.z + e.z * e.x;
}

/* The SAH bin of surface i, its centroid's key o + t e with t in [0, 1]. */
static int sah_bin(const builder *b, int32_t i, double o, double e) {
  const int bin = (int)((key(b, i) - o) / e * SAH_BINS);
  return bin < 0 ? 0 : bin >= SAH_BINS ? SAH_BINS - 1 : bin;
}

/* The SAH split of perm[lo, hi) along b->axis (centroids from clo over ext): perm rearranged
 * with the lower bins first (in an order fixed by the input's), and the index of the first of
 * the upper side returned; -1 when all centroids fall in one bin (the caller splits at the
 * median then). */
static int32_t sah_split(builder *b, int32_t lo, int32_t hi, hr_vec3 clo, hr_vec3 ext) {
  hr_clusters *cl = b->cl;
  const double e = b->axis == 0 ? ext.x : b->axis == 1 ? ext.y : ext.z;
  const double o = b->axis == 0 ? clo.x : b->axis == 1 ? clo.y : clo.z;
  if (!(e > 0)) return -1;
  const hr_vec3 none_lo = {INFINITY, INFINITY, INFINITY}, none_hi = v3_scale(none_lo, -1);
  hr_vec3 bl[SAH_BINS], bh[SAH_BINS];
  int64_t cnt[SAH_BINS] = {0};
  for (int k = 0; k < SAH_BINS; k++) bl[k] = none_lo, bh[k] = none_hi;
  for (int32_t k = lo; k < hi; k++) {
    const int32_t i = cl->perm[k];
    const int bin = sah_bin(b, i, o, e);
    cnt[bin]++;
    bl[bin] = v3_min(bl[bin], b->blo[i]), bh[bin] = v3_max(bh[bin], b->bhi[i]);
  }
  /* the boxes and counts right of each boundary, then a sweep from the left */
  double right[SAH_BINS];
  int64_t nright[SAH_BINS];
  hr_vec3 sl = none_lo, sh = none_hi;
  int64_t ns = 0;
  for (int k = SAH_BINS - 1; k >= 1; k--) {
    sl = v3_min(sl, bl[k]), sh = v3_max(sh, bh[k]), ns += cnt[k];
    right[k] = ns ? box_half_area(sl, sh) : 0, nright[k] = ns;
  }
  sl = none_lo, sh = none_hi, ns = 0;
  double best = INFINITY;
  int split = -1;
  for (int k = 0; k < SAH_BINS - 1; k++) {
    sl = v3_min(sl, bl[k]), sh = v3_max(sh, bh[k]), ns += cnt[k];
    if (ns == 0 || nright[k + 1] == 0) continue;
    const double c = box_half_area(sl, sh) * (double)ns + right[k + 1] * (double)nright[k + 1];
    if (c < best) best = c, split = k + 1;
  }
  if (split < 0) return -1;
  /* the lower bins first: a two-pointer pass, deterministic for a given perm */
  int32_t i = lo, j = hi - 1;
  int32_t *p = cl->perm;
  while (i <= j) {
    if (sah_bin(b, p[i], o, e) < split) {
      i++;
      continue;
    }
    const int32_t t = p[i];
    p[i] = p[j], p[j] = t;
    j--;
  }
  return i > lo && i < hi ? i : -1;
}

/* Builds the subtree over perm[lo, hi) (hi - lo >= 2); returns its node id. */
static int32_t build(builder *b, int32_t lo, int32_t hi) {
  hr_clusters *cl = b->cl;
  const int32_t c = cl->n++;
  cnode *nd = &cl->node[c];
  nd->lo = lo, nd->hi = hi;
  hr_vec3 clo = b->cen[cl->perm[lo]], chi = clo;
  for (int32_t k = lo + 1; k < hi; k++)
    clo = v3_min(clo, b->cen[cl->perm[k]]), chi = v3_max(chi, b->cen[cl->perm[k]]);
  const hr_vec3 ext = v3_sub(chi, clo);
  b->axis = ext.x >= ext.y && ext.x >= ext.z ? 0 : ext.y >= ext.z ? 1 : 2;
  int32_t m = sah_split(b, lo, hi, clo, ext);
  if (m < 0) {
    m = lo + (hi - lo) / 2;
    select_nth(b, cl->perm, lo, hi, m);
  }
  int32_t ch[2];
  const int32_t r[2][2] = {{lo, m}, {m, hi}};
  for (int q = 0; q < 2; q++)
    ch[q] = r[q][1] - r[q][0] == 1 ? cl->perm[r[q][0]] : -1 - build(b, r[q][0], r[q][1]);
  nd = &cl->node[c]; /* (no reallocation: the array holds n - 1 nodes from the start) */
  nd->child[0] = ch[0], nd->child[1] = ch[1];
  return c;
}

#ifndef NDEBUG
/* The tree's invariants (asserted in debug builds): n - 1 clusters in preorder, each range
 * [lo, hi) cut by its two children into [lo, m) and [m, hi) (a surface child: a range of one,
 * at its place in perm), perm a permutation of the n surfaces. 1 when they hold. */
static int tree_valid(const hr_clusters *cl, int32_t n) {
  if (n < 2) return 1;
  if (cl->n != n - 1) return 0;
  char *seen = calloc((size_t)n, 1);
  int ok = seen != NULL;
  for (int32_t k = 0; ok && k < n; k++) {
    ok = cl->perm[k] >= 0 && cl->perm[k] < n && !seen[cl->perm[k]];
    if (ok) seen[cl->perm[k]] = 1;
  }
  free(seen);
  for (int32_t c = 0; ok && c < cl->n; c++) {
    const cnode *nd = &cl->node[c];
    int32_t at = nd->lo;
    for (int q = 0; ok && q < 2; q++) {
      const int32_t id = nd->child[q];
      if (id >= 0) {
        ok = cl->perm[at] == id;
        at++;
      } else {
        const cnode *cc = &cl->node[-1 - id];
        ok = -1 - id > c && cc->lo == at && cc->hi > cc->lo + 1;
        at = cc->hi;
      }
    }
    ok = ok && at == nd->hi;
  }
  return ok;
}
#endif

/* Boxes, spheres, areas, reflectances and N_lm, children before parents. */
static double acos_clamped(double x) { return acos(x < -1 ? -1 : x > 1 ? 1 : x); }

/* The normal cone of n surfaces: the axis of their area-weighted mean normal (any, with angle
 * pi, where that is 0) and the largest angle of a normal from it. */
static void normal_cone(const hr_clusters *cl, int32_t lo, int32_t hi, hr_vec3 *axis,
                        double *ang) {
  hr_vec3 m = {0, 0, 0};
  for (int32_t k = lo; k < hi; k++)
    m = v3_add(m, v3_scale(cl->sp[k].n, cl->cum[k + 1] - cl->cum[k]));
  const double ml = v3_len(m);
  *axis = ml > 0 ? v3_scale(m, 1 / ml) : v3(0, 0, 1);
  *ang = ml > 0 ? 0 : M_PI;
  for (int32_t k = lo; k < hi && ml > 0; k++) {
    const double a = acos_clamped(v3_dot(cl->sp[k].n, *axis));
    *ang = a > *ang ? a : *ang;
  }
}

static void summarise(hr_solver *s, hr_clusters *cl) {
  const hr_scene *sc = s->scene;
  for (int32_t c = cl->n - 1; c >= 0; c--) {
    cnode *nd = &cl->node[c];
    nd->area = 0;
    cl->rho[c] = 0;
    memset(cl->nsh[c], 0, sizeof cl->nsh[c]);
    for (int q = 0; q < 2; q++) {
      const int32_t id = nd->child[q];
      hr_vec3 lo, hi;
      double a, rho, nsh[9];
      if (id >= 0) {
        const hr_surface *f = &sc->surfs[id];
        surf_box(f, &lo, &hi);
        a = s->el[id].area;
        rho = s->rho_max[id];
        const double n[3] = {f->normal.x, f->normal.y, f->normal.z};
        hr_sh9(n, nsh);
        for (int k = 0; k < 9; k++) nsh[k] *= a;
      } else {
        const cnode *cc = &cl->node[-1 - id];
        lo = cc->bmin, hi = cc->bmax, a = cc->area, rho = cl->rho[-1 - id];
        memcpy(nsh, cl->nsh[-1 - id], sizeof nsh);
      }
      nd->bmin = q ? v3_min(nd->bmin, lo) : lo;
      nd->bmax = q ? v3_max(nd->bmax, hi) : hi;
      nd->area += a;
      cl->rho[c] = rho > cl->rho[c] ? rho : cl->rho[c];
      for (int k = 0; k < 9; k++) cl->nsh[c][k] += nsh[k];
    }
    nd->c = v3_scale(v3_add(nd->bmin, nd->bmax), 0.5);
    nd->rad = 0.5 * v3_len(v3_sub(nd->bmax, nd->bmin));
    cl->slack[c] = hr_slack(s, nd->area);
    normal_cone(cl, nd->lo, nd->hi, &nd->na, &nd->nang);
  }
}

static hr_status build_tree(hr_solver *s, hr_clusters *cl) {
  const hr_scene *sc = s->scene;
  const int n = sc->nsurfs;
  hr_vec3 *cen = malloc((size_t)n * sizeof *cen);
  cl->perm = malloc((size_t)n * sizeof *cl->perm);
  cl->cum = malloc(((size_t)n + 1) * sizeof *cl->cum);
  cl->srad = malloc((size_t)n * sizeof *cl->srad);
  cl->sp = malloc((size_t)n * sizeof *cl->sp);
  cl->sg = malloc((size_t)n * sizeof *cl->sg);
  cl->sh = malloc((size_t)n * sizeof *cl->sh);
  const size_t m = n > 1 ? (size_t)n - 1 : 1;
  cl->node = calloc(m, sizeof *cl->node);
  cl->nsh = malloc(m * sizeof *cl->nsh);
  cl->rho = malloc(m * sizeof *cl->rho);
  cl->Bm = calloc(m, sizeof *cl->Bm);
  cl->bhi = calloc(m, sizeof *cl->bhi);
  cl->blo = calloc(m, sizeof *cl->blo);
  cl->bref = calloc(m, sizeof *cl->bref);
  cl->slack = malloc(m * sizeof *cl->slack);
  cl->L = calloc(m, sizeof *cl->L);
  if (!cen || !cl->perm || !cl->cum || !cl->srad || !cl->sp || !cl->sg || !cl->sh || !cl->node ||
      !cl->nsh || !cl->rho || !cl->Bm || !cl->bhi || !cl->blo || !cl->bref || !cl->slack ||
      !cl->L) {
    free(cen);
    return HR_ERR_NOMEM;
  }
  for (int i = 0; i < n; i++) {
    cen[i] = s->el[i].c;
    cl->perm[i] = i;
    double r = 0;
    for (int k = 0; k < sc->surfs[i].nverts; k++) {
      double d = v3_len(v3_sub(sc->surfs[i].v[k], cen[i]));
      r = d > r ? d : r;
    }
    cl->srad[i] = r;
  }
  hr_vec3 *sbl = malloc((size_t)n * sizeof *sbl), *sbh = malloc((size_t)n * sizeof *sbh);
  if (!sbl || !sbh) {
    free(cen), free(sbl), free(sbh);
    return HR_ERR_NOMEM;
  }
  for (int i = 0; i < n; i++) surf_box(&sc->surfs[i], &sbl[i], &sbh[i]);
  builder b = {cl, cen, sbl, sbh, 0};
  cl->n = 0;
  cl->root = n >= 2 ? -1 - build(&b, 0, n) : 0;
  assert(tree_valid(cl, n));
  free(cen), free(sbl), free(sbh);
  cl->cum[0] = 0;
  for (int k = 0; k < n; k++) cl->cum[k + 1] = cl->cum[k] + s->el[cl->perm[k]].area;
  for (int k = 0; k < n; k++) {
    const hr_surface *f = &sc->surfs[s->el[cl->perm[k]].surf];
    csurf *q = &cl->sp[k];
    memset(q, 0, sizeof *q);
    for (int j = 0; j < f->nverts; j++) q->v[j] = f->v[j];
    q->n = f->normal, q->nv = f->nverts;
    cl->sg[k] = hr_elem_geom(s, &s->el[cl->perm[k]]), cl->sh[k] = hr_ff_shape_of(&cl->sg[k]);
  }
  summarise(s, cl);
  cl->size = cl->n > 0 ? cl->node[0].rad : cl->srad[0];
  return HR_OK;
}

/* ---------------------------------------------------------------- nodes */

static uint64_t node_gid(const hr_solver *s, int32_t id) {
  return id >= 0 ? s->el[id].gid : HR_CLUSTER_GID | (uint64_t)(-1 - id);
}

static double elem_radius(const hr_solver *s, int32_t e) {
  const hr_elem *el = &s->el[e];
  const int nv = s->scene->surfs[el->surf].nverts;
  double r = 0;
  for (int k = 0; k < nv; k++) {
    const double d = v3_len(v3_sub(el->p[k], el->c));
    r = d > r ? d : r;
  }
  return r;
}

static void node_sphere(const hr_solver *s, int32_t id, hr_vec3 *c, double *r, double *a) {
  const hr_clusters *cl = s->cl;
  if (id >= 0) {
    *c = s->el[id].c, *a = s->el[id].area;
    *r = s->el[id].parent < 0 ? cl->srad[id] : elem_radius(s, id);
  } else {
    const cnode *nd = &cl->node[-1 - id];
    *c = nd->c, *r = nd->rad, *a = nd->area;
  }
}

/* The radiosity a node sends (RGB), its mean and range in the largest channel. */
static const double *node_b(const hr_solver *s, int32_t id, double *mean, double *range) {
  const hr_clusters *cl = s->cl;
  if (id >= 0) {
    /* a leaf's bvar (<= 0) is its own variation (pushpull.c); clusters read leaf means */
    *mean = max3(s->Bs[id]), *range = s->bvar[id] > 0 ? s->bvar[id] : 0;
    return s->Bs[id];
  }
  const int32_t c = -1 - id;
  *mean = max3(cl->Bm[c]), *range = cl->bhi[c] - cl->blo[c];
  return cl->Bm[c];
}

static void node_recv(const hr_solver *s, int32_t id, double *rho, double *bref) {
  const hr_clusters *cl = s->cl;
  const double floor = HR_BREF_FLOOR * s->unit;
  if (id >= 0) {
    *rho = s->rho_max[id];
    /* s->bref[id] holds its slack already */
    *bref = cl->initial ? floor * hr_slack(s, hr_elem_imp_area(s, id)) : s->bref[id];
  } else {
    *rho = cl->rho[-1 - id];
    *bref = (cl->initial ? floor : cl->bref[-1 - id]) * cl->slack[-1 - id];
  }
}

/* 1 when the whole box lies on or behind the plane of surface f (it cannot see f's front). */
static int box_behind(const hr_surface *f, hr_vec3 lo, hr_vec3 hi, double tol) {
  for (int k = 0; k < 8; k++) {
    const hr_vec3 p = {k & 1 ? hi.x : lo.x, k & 2 ? hi.y : lo.y, k & 4 ? hi.z : lo.z};
    if (v3_dot(v3_sub(p, f->v[0]), f->normal) > tol) return 0;
  }
  return 1;
}

/* Draws a link's point pairs in batches of this many (see draw). */
#define DRAW_BATCH 8

/* Which surface of cluster id (its place k in perm) takes the point at u0 in [0, 1) of its
 * area: the last k in [lo, hi) with cum[k] <= t (cum[lo] <= t always), without branches. -1 for
 * an element. */
static int32_t node_locate(const hr_solver *s, int32_t id, double u0) {
  if (id >= 0) return -1;
  const hr_clusters *cl = s->cl;
  const cnode *nd = &cl->node[-1 - id];
  const double t = cl->cum[nd->lo] + u0 * (cl->cum[nd->hi] - cl->cum[nd->lo]);
  int32_t lo = nd->lo, len = nd->hi - nd->lo;
  while (len > 1) {
    const int32_t h = len / 2;
    lo = cl->cum[lo + h] <= t ? lo + h : lo;
    len -= h;
  }
  return lo;
}

/* node_locate for the n draws u[b][c] (b < n) at once, into k: the searches of one node take the
 * same steps, and run side by side so that their loads overlap instead of each waiting for the
 * one before (a large cluster's search is a chain of cache misses). */
static void locate_batch(const hr_solver *s, int32_t id, const double (*u)[6], int c, int n,
                         int32_t *k) {
  if (id >= 0) {
    for (int b = 0; b < n; b++) k[b] = -1;
    return;
  }
  const hr_clusters *cl = s->cl;
  const cnode *nd = &cl->node[-1 - id];
  const double c0 = cl->cum[nd->lo], span = cl->cum[nd->hi] - c0;
  double t[DRAW_BATCH];
  for (int b = 0; b < n; b++) t[b] = c0 + u[b][c] * span, k[b] = nd->lo;
  for (int32_t len = nd->hi - nd->lo; len > 1;) {
    const int32_t h = len / 2;
    for (int b = 0; b < n; b++) k[b] = cl->cum[k[b] + h] <= t[b] ? k[b] + h : k[b];
    len -= h;
  }
}

/* The point of node id at u (u[0] chose place k of its surfaces: node_locate) and its normal. */
static hr_vec3 node_point_at(const hr_solver *s, int32_t id, int32_t k, const double u[3],
                             hr_vec3 *n) {
  const hr_vec3 *p;
  int nv;
  if (id < 0) {
    const csurf *q = &s->cl->sp[k];
    p = q->v, nv = q->nv, *n = q->n;
  } else {
    const hr_surface *f = &s->scene->surfs[s->el[id].surf];
    p = s->el[id].p, nv = f->nverts, *n = f->normal;
  }
  if (nv == 3) {
    const double a = sqrt(u[1]);
    return v3_add(v3_scale(p[0], 1 - a),
                  v3_add(v3_scale(p[1], a * (1 - u[2])), v3_scale(p[2], a * u[2])));
  }
  return v3_lerp(v3_lerp(p[0], p[1], u[1]), v3_lerp(p[3], p[2], u[1]), u[2]);
}

/* 1 when the sphere (c, rad) lies wholly behind the plane of node id's surface (place k for a
 * cluster, as node_point_at). */
static int behind_plane(const hr_solver *s, int32_t id, int32_t k, hr_vec3 c, double rad) {
  if (id < 0) return v3_dot(v3_sub(c, s->cl->sp[k].v[0]), s->cl->sp[k].n) < -rad;
  return v3_dot(v3_sub(c, s->el[id].p[0]), s->scene->surfs[s->el[id].surf].normal) < -rad;
}

/* A point of node id drawn by area from u in [0, 1)^3 (u[0] picks the surface of a cluster,
 * u[1], u[2] the point on it), and its normal. */
static hr_vec3 node_point(const hr_solver *s, int32_t id, const double u[3], hr_vec3 *n) {
  return node_point_at(s, id, node_locate(s, id, u[0]), u, n);
}

/* Asks for the surface record of place k (two cache lines) ahead of need. */
static void prefetch_surface(const hr_solver *s, int32_t k) {
  if (k < 0) return;
  __builtin_prefetch(&s->cl->sp[k]);
  __builtin_prefetch((const char *)&s->cl->sp[k] + 64);
}

/* A new link r <- sn: nothing estimated or decided yet. */
static clink fresh(int32_t r, int32_t sn) { return (clink){r, sn, -1, 0, {0, 0, 0}, -1, -1, -1}; }

/* ---------------------------------------------------------------- link estimate */

#define CL_RAYS_MAX 64

/* The six uniforms of draw q of the pair keyed 'key', 21 bits each (at the centres of 2^21
 * equal bins) from two mixes (six hashes of four mixes each: 4% of the conference room's
 * profile, and most of draw's own 6%). */
static inline void six_units(uint64_t key, uint64_t q, double u[6]) {
  const uint64_t h[2] = {u64_mix(key ^ (q * UINT64_C(0x9e3779b97f4a7c15))),
                         u64_mix(key + (q + 1) * UINT64_C(0xd1b54a32d192ed03))};
  for (int j = 0; j < 6; j++)
    u[j] = ((double)((h[j / 3] >> (21 * (j % 3))) & 0x1fffff) + 0.5) * 0x1.0p-21;
}

static int link_rays(const hr_solver *s) {
  const int k = s->opt.rays / 2;
  return k < 1 ? 1 : k > CL_RAYS_MAX ? CL_RAYS_MAX : k;
}

/* Draws the k point pairs of link (r <- sn), keyed by the two ids and the stream (the oracle
 * decides on one set and the estimate rests on another: deciding on the estimate's own samples
 * would keep the links whose samples happen to fall short, and bias the light low): the kernel
 * weights of the pairs that face each other into w (cos cos / (pi r^2 + reg)) and their lifted
 * ends into org and dst. Pairs are drawn until k face each other or 8k were drawn (as
 * hr_vf_pair: where the facing parts are small, k draws often found none, and such links
 * carried nothing although exact quadrature gave them light: museum 1.5% dark). Returns how
 * many face each other, and in *ndraw how many were drawn. */
static int draw(const hr_solver *s, int32_t r, int32_t sn, int k, int stream, double reg,
                double *w, float *org, float *dst, int *ndraw) {
  const uint64_t key = hr_hash4(s->opt.seed, node_gid(s, r), node_gid(s, sn), 11 + stream);
  const double lift = s->vf.lift;
  int m = 0, q = 0;
  /* in batches: the surfaces of a batch's draws are found first, and their records asked for,
   * so that the searches and the records' cache misses overlap (the same draws in the same
   * order; a batch's draws after the k-th facing pair are found and not used) */
  double u[DRAW_BATCH][6];
  int32_t kr[DRAW_BATCH], ks[DRAW_BATCH];
  hr_vec3 cr, cs;
  double rr, rs, a;
  node_sphere(s, r, &cr, &rr, &a);
  node_sphere(s, sn, &cs, &rs, &a);
  const double tol = 1e-9 * s->cl->size;
  for (int b = DRAW_BATCH; q < 8 * k && m < k; q++, b++) {
    if (b == DRAW_BATCH) {
      const int nb = 8 * k - q < DRAW_BATCH ? 8 * k - q : DRAW_BATCH;
      for (b = 0; b < nb; b++) six_units(key, (uint64_t)(q + b), u[b]);
      locate_batch(s, r, u, 0, nb, kr), locate_batch(s, sn, u, 3, nb, ks);
      for (b = 0; b < nb; b++) prefetch_surface(s, kr[b]), prefetch_surface(s, ks[b]);
      b = 0;
    }
    /* a surface with the other node's whole sphere behind its plane: no point of it faces
     * (the test below would say so; 64% of the conference room's draws face no way) */
    if (behind_plane(s, r, kr[b], cs, rs + tol) || behind_plane(s, sn, ks[b], cr, rr + tol))
      continue;
    hr_vec3 nx, ny;
    const hr_vec3 x = node_point_at(s, r, kr[b], u[b], &nx),
                  y = node_point_at(s, sn, ks[b], u[b] + 3, &ny);
    const hr_vec3 dv = v3_sub(y, x);
    const double r2 = v3_dot(dv, dv);
    if (!(r2 > 0)) continue;
    const double inv = 1 / sqrt(r2), cx = v3_dot(nx, dv) * inv, cy = -v3_dot(ny, dv) * inv;
    if (cx <= 0 || cy <= 0) continue;
    w[m] = cx * cy / (M_PI * r2 + reg);
    if (org) {
      const hr_vec3 o = v3_add(x, v3_scale(nx, lift)), e = v3_add(y, v3_scale(ny, lift));
      org[3 * m] = (float)o.x, org[3 * m + 1] = (float)o.y, org[3 * m + 2] = (float)o.z;
      dst[3 * m] = (float)e.x, dst[3 * m + 1] = (float)e.y, dst[3 * m + 2] = (float)e.z;
    }
    m++;
  }
  *ndraw = q;
  return m;
}

/* ---------------------------------------------------------------- transfer
 *
 * A cluster that receives as one gives each surface its share by orientation. Geometry close
 * to a surface hides part of its sky: the seat under a chair's arm, the inside of a cabinet.
 * Each surface root carries its transfer vector: Y_lm(n) less the SH projection of what
 * TRANSFER_RAYS cosine-distributed rays from it find hidden within lray, the width of the
 * largest cluster of at most A_e above it (the largest that receives as one by size; larger
 * ones do only from ten times their size, where visibility between the two is the link's). The
 * hidden part is subtracted, so an open surface keeps Y_lm(n) exactly. Light from sources
 * farther than lray from the receiving cluster reaches its surfaces through their transfer
 * vectors; nearer sources (a lamp inside its housing, which the rays toward it would find
 * hidden behind the far side of the housing) through Y_lm(n). */
#define TRANSFER_RAYS 64

/* 1 when link l's source lies farther from its receiving cluster than the cluster's surfaces'
 * transfer rays reach (link_geometry: the sign of kv). */
static int far_source(const clink *l) { return signbit(l->kv) != 0; }
/* How much the kernel varies over the two nodes of link l (link_geometry). */
static float kv_of(const clink *l) { return fabsf(l->kv); }

/* Surface id's transfer vector from rays of length len (0: Y_lm(n)). */
static void transfer_vector(const hr_solver *s, int32_t id, double len, double t[9]) {
  const hr_surface *f = &s->scene->surfs[id];
  const double n[3] = {f->normal.x, f->normal.y, f->normal.z};
  hr_sh9(n, t);
  if (!(len > 0)) return;
  const hr_vec3 e1 = v3_norm(v3_cross(f->normal, fabs(f->normal.x) < 0.9 ? v3(1, 0, 0)
                                                                          : v3(0, 1, 0)));
  const hr_vec3 e2 = v3_cross(f->normal, e1);
  const uint64_t key = hr_hash4(s->opt.seed, node_gid(s, id), 0, 29);
  float org[TRANSFER_RAYS * 3], dst[TRANSFER_RAYS * 3];
  hr_vec3 dir[TRANSFER_RAYS];
  uint8_t vis[TRANSFER_RAYS];
  for (int q = 0; q < TRANSFER_RAYS; q++) {
    double u[6];
    hr_vec3 nx;
    six_units(key, (uint64_t)q, u);
    const hr_vec3 x = node_point(s, id, u, &nx);
    /* cosine-distributed about n, stratified in the azimuth */
    const double r = sqrt(u[3]), ph = 2 * M_PI * (q + u[4]) / TRANSFER_RAYS;
    dir[q] = v3_add(v3_add(v3_scale(e1, r * cos(ph)), v3_scale(e2, r * sin(ph))),
                    v3_scale(f->normal, sqrt(1 - u[3])));
    const hr_vec3 o = v3_add(x, v3_scale(f->normal, s->vf.lift)),
                  e = v3_add(o, v3_scale(dir[q], len));
    org[3 * q] = (float)o.x, org[3 * q + 1] = (float)o.y, org[3 * q + 2] = (float)o.z;
    dst[3 * q] = (float)e.x, dst[3 * q + 1] = (float)e.y, dst[3 * q + 2] = (float)e.z;
  }
  hr_vis_segments(s->vis, TRANSFER_RAYS, org, dst, -1, -1, vis);
  for (int q = 0; q < TRANSFER_RAYS; q++) {
    if (vis[q]) continue;
    const double d[3] = {dir[q].x, dir[q].y, dir[q].z};
    double y[9];
    hr_sh9(d, y);
    /* E_cos[Y_lm] = A_l Y_lm(n) / pi over the cosine distribution */
    for (int k = 0; k < 9; k++) t[k] -= M_PI / hr_sh_alpha[k] * y[k] / TRANSFER_RAYS;
  }
}

static hr_status transfer_init(hr_solver *s) {
  hr_clusters *cl = s->cl;
  const int32_t ns = s->scene->nsurfs, nc = cl->n;
  const double ae = s->area_min;
  double *ls = calloc((size_t)(ns > 0 ? ns : 1), sizeof *ls);
  cl->tq = malloc((size_t)(ns > 0 ? ns : 1) * sizeof *cl->tq);
  cl->nsht = calloc((size_t)(nc > 0 ? nc : 1), sizeof *cl->nsht);
  cl->lray = calloc((size_t)(nc > 0 ? nc : 1), sizeof *cl->lray);
  if (!ls || !cl->tq || !cl->nsht || !cl->lray) {
    free(ls);
    return HR_ERR_NOMEM;
  }
  /* preorder: the width of the largest cluster of at most A_e above each node */
  for (int32_t c = 0; c < nc; c++) {
    const cnode *nd = &cl->node[c];
    if (cl->lray[c] == 0 && nd->area <= ae) cl->lray[c] = 2 * nd->rad;
    for (int q = 0; q < 2; q++) {
      const int32_t id = nd->child[q];
      if (id < 0) cl->lray[-1 - id] = cl->lray[c];
      else ls[id] = cl->lray[c];
    }
  }
  /* a cluster above A_e: its surfaces' rays reach at most its own width */
  for (int32_t c = 0; c < nc; c++)
    if (cl->lray[c] == 0) cl->lray[c] = 2 * cl->node[c].rad;
  /* (their rays are not in s->rays: a resumed run casts them again) */
#pragma omp parallel for schedule(dynamic, 64) num_threads(s->threads)
  for (int32_t i = 0; i < ns; i++) transfer_vector(s, i, ls[i], cl->tq[i]);
  free(ls);
  /* N_lm from the transfer vectors, from the leaves up */
  for (int32_t c = nc - 1; c >= 0; c--) {
    for (int q = 0; q < 2; q++) {
      const int32_t id = cl->node[c].child[q];
      const double *t = id < 0 ? cl->nsht[-1 - id] : cl->tq[id];
      const double a = id < 0 ? 1 : s->el[id].area;
      for (int k = 0; k < 9; k++) cl->nsht[c][k] += a * t[k];
    }
  }
  return HR_OK;
}

hr_status hr_cluster_prepare(hr_solver *s, hr_err *err) {
  if (!s->cl || s->cl->tq) return HR_OK;
  if (transfer_init(s) != HR_OK)
    return hr_err_set(err, HR_ERR_NOMEM, "out of memory building clusters");
  return HR_OK;
}

/* Links between nodes of at most this many surface pairs get their unoccluded form factor as
 * the sum over the pairs of the exact form factors (quadrature on the receiver)
 * where they are near (the point kernel then varies too much for a few samples: measured on a
 * tessellated furnace, 8 samples left single triangles up to 10% bright, and 128 still 1.5%).
 * hr_ff_pair's adaptive rule throughout: one point per receiver made the conference room's
 * refinement at each new BF_e 35-55% faster, but put the Cornell box's walls 1.7% RMS off and
 * museum's floors 1-9% dark (a floor tile's centre lies under the plinth standing on it, and
 * from there the plinth's sides send nothing: the links were kept with F = 0). 16 pairs instead
 * of 64 made more links split and was slower. */
#define EXACT_PAIRS 64

/* The surfaces of node id for form factors: a cluster's, in place order, from cl->sg and sh
 * (made once), an element's into *g and *h; their count, or -1 when more than max. */
static int node_geoms(const hr_solver *s, int32_t id, int max, const hr_ff_elem **pg,
                      const hr_ff_shape **ph, hr_ff_elem *g, hr_ff_shape *h) {
  if (id >= 0) {
    *g = hr_elem_geom(s, &s->el[id]), *h = hr_ff_shape_of(g);
    *pg = g, *ph = h;
    return 1;
  }
  const cnode *nd = &s->cl->node[-1 - id];
  if (nd->hi - nd->lo > max) return -1;
  *pg = &s->cl->sg[nd->lo], *ph = &s->cl->sh[nd->lo];
  return nd->hi - nd->lo;
}

/* How many of a cluster's surfaces its first child holds (its range starts the cluster's). */
static int first_child_count(const hr_solver *s, int32_t id) {
  const int32_t c = s->cl->node[-1 - id].child[0];
  return c >= 0 ? 1 : s->cl->node[-1 - c].hi - s->cl->node[-1 - c].lo;
}

/* The unoccluded form factor of link (r <- sn), receiver-area mean, by quadrature over the
 * surface pairs, or -1 when the two nodes make more than EXACT_PAIRS surface pairs. With 'kids'
 * (not NULL), also the values of the links its split would make, by the same sums in the same
 * order as those links would compute them: kids[0][c] for (child c of r <- sn), kids[1][c] for
 * (r <- child c of sn), -1 where that side is an element. */
static double exact_unoccluded(const hr_solver *s, int32_t r, int32_t sn, double kids[2][2]) {
  /* hr_ff_pair's sums, with each surface's geometry and each receiver's points of an order
   * made once */
  const hr_ff_elem *gr, *gs;
  const hr_ff_shape *hr, *hs;
  hr_ff_elem ge[2];
  hr_ff_shape he[2];
  const int nr = node_geoms(s, r, EXACT_PAIRS, &gr, &hr, &ge[0], &he[0]),
            ns = node_geoms(s, sn, EXACT_PAIRS, &gs, &hs, &ge[1], &he[1]);
  if (nr < 0 || ns < 0 || nr * ns > EXACT_PAIRS) return -1;
  /* the children's surfaces: receivers i < n0 and sources j < m0 are their first child's */
  const int n0 = r < 0 ? first_child_count(s, r) : nr, m0 = sn < 0 ? first_child_count(s, sn) : ns;
  double f = 0, ar = 0, fk[2][2] = {{0, 0}, {0, 0}}, ak[2] = {0, 0};
  /* one receiver's (point, source) pairs, evaluated four at a time whatever their sources
   * (a pair at one point filled one lane of four: 37% of the kernel's calls on the conference
   * room), then summed pair by pair in hr_ff_pair's order */
  const hr_vec3 *px[EXACT_PAIRS * HR_FF_CLIP_POINTS];
  const hr_ff_elem *ps[EXACT_PAIRS * HR_FF_CLIP_POINTS];
  double fx[EXACT_PAIRS * HR_FF_CLIP_POINTS];
  int8_t oj[EXACT_PAIRS], nj[EXACT_PAIRS];
  const double *wj[EXACT_PAIRS];
  double fr[EXACT_PAIRS]; /* the pair's value by reciprocity, or -1 */
  for (int i = 0; i < nr; i++) {
    const hr_ff_elem *gi = &gr[i];
    hr_vec3 x[3][9];
    double w[3][9], fi = 0, fs[2] = {0, 0};
    int np[3] = {-1, -1, -1}, nq = 0;
    /* the clipped points of the pairs that i reaches through the plane of (hr_ff_pair's rule:
     * the same sums) */
    hr_vec3 xc[EXACT_PAIRS][HR_FF_CLIP_POINTS];
    double wc[EXACT_PAIRS][HR_FF_CLIP_POINTS];
    for (int j = 0; j < ns; j++) {
      /* half of the pairs in clustered museum, and three quarters of the points (they take
       * the highest order, since one reaches behind the other) */
      const int o = oj[j] = (int8_t)(hr_ff_pair_class(gi, &gs[j], &hr[i], &hs[j]) - 1);
      if (o < 0) continue;
      fr[j] = o == 2 && hr_ff_recip_applies(gi, &gs[j], hr[i].diam, hs[j].diam)
                  ? hr_ff_recip(gi, &gs[j])
                  : -1;
      const int nc = o == 2 && fr[j] < 0 ? hr_ff_clip_points(gi, &gs[j], xc[j], wc[j]) : 0;
      const hr_vec3 *xj = xc[j];
      if (fr[j] >= 0) {
        nj[j] = 0;
      } else if (nc > 0) {
        nj[j] = (int8_t)nc, wj[j] = wc[j];
      } else {
        if (np[o] < 0) np[o] = hr_ff_points(gi, o + 1, x[o], w[o]);
        nj[j] = (int8_t)np[o], wj[j] = w[o], xj = x[o];
      }
      for (int k = 0; k < nj[j]; k++) px[nq] = &xj[k], ps[nq++] = &gs[j];
    }
    hr_ff_point_pairs(px, ps, nq, gi->n, fx);
    for (int j = 0, q = 0; j < ns; j++) {
      const int o = oj[j];
      if (o < 0) continue;
      double fij = fr[j] >= 0 ? fr[j] : 0;
      for (int k = 0; k < nj[j]; k++) fij += wj[j][k] * fx[q++];
      fi += fij;
      fs[j >= m0] += fij;
    }
    f += gi->area * fi;
    ar += gi->area;
    fk[0][i >= n0] += gi->area * fi, ak[i >= n0] += gi->area;
    fk[1][0] += gi->area * fs[0], fk[1][1] += gi->area * fs[1];
  }
  if (kids)
    for (int c = 0; c < 2; c++) {
      kids[0][c] = r >= 0 ? -1 : ak[c] > 0 ? fk[0][c] / ak[c] : 0;
      kids[1][c] = sn >= 0 ? -1 : ar > 0 ? fk[1][c] / ar : 0;
    }
  return ar > 0 ? f / ar : 0;
}

/* Nodes are near when the gap between their spheres is below 1 / NEAR_KV times the sum of
 * their radii: the point kernel then varies so much over them that a few samples mislead
 * (measured on a tessellated furnace at a gap of 2 radii: single links 2x off). */
#define NEAR_KV 0.2f

static int near_pair(const clink *l) { return kv_of(l) >= NEAR_KV; }

/* The kernel's regularisation pi r^2 + reg: A_S / k for near nodes, where one sample pair can
 * come arbitrarily close, else 0 (a term of A_S / k biased far links from large sources low:
 * 8% on a tessellated furnace). */
static double link_reg(const clink *l, double as, int k) { return near_pair(l) ? as / k : 0; }

/* The unoccluded form factor of link (r <- sn) from the decision stream's point pairs, without
 * rays. */
static double sampled_unoccluded(const hr_solver *s, const clink *l, double as) {
  double w[CL_RAYS_MAX], f = 0;
  int nd;
  const int k = link_rays(s);
  const int m = draw(s, l->r, l->s, k, 1, link_reg(l, as, k), w, NULL, NULL, &nd);
  for (int q = 0; q < m; q++) f += w[q];
  return nd > 0 ? f * as / nd : 0;
}

/* Below this normalisation (per unit receiver area; 1/4 for an even spread) a cluster link's
 * power goes to its receiver's surfaces evenly instead of by their orientation. */
#define ISO_MIN 0.05

/* F, kf and d of link l by k rays between area-drawn points of its two nodes (half as many for
 * a weak link). */
static void estimate(const hr_solver *s, clink *l, int weak, int64_t *rays) {
  const hr_clusters *cl = s->cl;
  hr_vec3 cr, cs;
  double rr, rs, ar, as;
  node_sphere(s, l->r, &cr, &rr, &ar);
  node_sphere(s, l->s, &cs, &rs, &as);
  const int k = weak && link_rays(s) > 1 ? link_rays(s) / 2 : link_rays(s);
  float org[CL_RAYS_MAX * 3], dst[CL_RAYS_MAX * 3];
  double w[CL_RAYS_MAX];
  uint8_t vis[CL_RAYS_MAX];
  int nd;
  const int m = draw(s, l->r, l->s, k, 0, link_reg(l, as, k), w, org, dst, &nd);
  double f = 0, wsum = 0;
  if (m > 0) {
    hr_vis_segments(s->vis, m, org, dst, -1, -1, vis);
    *rays += m;
    for (int q = 0; q < m; q++) f += vis[q] ? w[q] : 0, wsum += w[q];
  }
  /* the decision's exact value where it has one (fu2 is twice it; 2: none) */
  const double fu = !near_pair(l) ? -1
                    : l->fu2 >= 0 && l->fu2 < 2 ? 0.5 * l->fu2
                                                : exact_unoccluded(s, l->r, l->s, NULL);
  /* exact times the visible fraction (0 when no sample counts: taking 1, as hr_vf_pair does,
   * made museum's walls 3% too bright) */
  if (fu >= 0) f = wsum > 0 ? fu * f / wsum : 0;
  else f *= nd > 0 ? as / nd : 0;
  f = f < 1 ? f : 1;
  /* The direction the light comes from: the kernel-weighted mean of the seen samples' (the
   * centres' direction misleads for a large near source: behind the receiver's plane, it lost
   * such links whole) */
  hr_vec3 d = {0, 0, 0};
  for (int q = 0; q < m; q++) {
    if (!vis[q]) continue;
    const hr_vec3 u = v3(dst[3 * q] - org[3 * q], dst[3 * q + 1] - org[3 * q + 1],
                         dst[3 * q + 2] - org[3 * q + 2]);
    const double ul = v3_len(u);
    if (ul > 0) d = v3_add(d, v3_scale(u, w[q] / ul));
  }
  if (!(v3_len(d) > 0)) d = v3_sub(cs, cr);
  const double dl = v3_len(d);
  d = dl > 0 ? v3_scale(d, 1 / dl) : v3(0, 0, 1);
  l->d[0] = (float)d.x, l->d[1] = (float)d.y, l->d[2] = (float)d.z;
  l->F = (float)f;
  l->kf = 0;
  if (l->r < 0 && f > 0) {
    const double dd[3] = {d.x, d.y, d.z};
    const double *N = far_source(l) ? cl->nsht[-1 - l->r] : cl->nsh[-1 - l->r];
    double y[9], D = 0;
    hr_sh9(dd, y);
    for (int q = 0; q < 9; q++) D += hr_sh_alpha[q] * y[q] * N[q];
    /* the receiver's surfaces hardly face d in the model: spread the power evenly over their
     * open area (kf < 0) */
    const double aop = N[0] / 0.282095;
    l->kf = D > ISO_MIN * ar ? (float)(f * ar / D) : aop > 0 ? (float)(-4 * f * ar / aop) : 0;
  }
}

/* ---------------------------------------------------------------- distribution
 *
 * Over several ranks (docs/design.md, "Clustering"): the hierarchy and the clusters' state
 * (Bm, bhi, blo, bref) are replicated, computed alike on every rank from the roots, which every
 * rank holds (push-pull shares what the pull reads of them). Each cluster link lives on the rank
 * that owns its receiver: an element's owner, or for a cluster a rank drawn from its number.
 * The gather sums each receiver's links in place order (see hr_clusters), the same on any number
 * of ranks: a kept link keeps its place, and each round's children take new places above all
 * earlier ones (vnext, the same on every rank), in their parents' place order, from prefix sums
 * of the children counts of the links that split, over all ranks in place order (scan; in one
 * process a local prefix sum). The clusters' fields are summed over the
 * ranks (each written by one, zeros elsewhere), so every rank pushes them down alike and adds
 * what reaches its own roots. */

/* The rank that holds the links node 'id' receives (0 in one process). */
static int node_owner(const hr_solver *s, int32_t id) {
  if (!s->dist) return 0;
  return id >= 0 ? s->eown[id] : s->cl->cown[-1 - id];
}

/* A cluster's first owner: a rank drawn from its number. */
static int32_t drawn_owner(const hr_solver *s, int32_t c) {
  const uint64_t h = hr_hash4(UINT64_C(0x636c7573746572), (uint64_t)c, 0, 0);
  return s->dist ? (int32_t)(h % (uint64_t)s->nranks) : 0;
}

/* Graph balancing's start in a clustered run (hr_cluster_init): the hierarchy in preorder,
 * surface roots weighing their area, cut into runs of equal area, one a rank (see
 * hr_partition_preorder): each rank's surfaces and clusters are a compact piece of the scene,
 * whose tree the balancing's clustering can cut into few pieces. Whole surfaces by area,
 * scattered over the scene, and clusters drawn at random left one piece a cluster (69,046 on
 * the conference room). Sets rootown and cown. 0 when out of memory. */
static int spread_by_hierarchy(hr_solver *s) {
  const hr_clusters *cl = s->cl;
  const int32_t n = cl->n + s->scene->nsurfs; /* clusters 0..n-1, then the surfaces */
  int32_t *par = malloc((size_t)n * sizeof *par), *part = malloc((size_t)n * sizeof *part);
  double *w = malloc((size_t)n * sizeof *w);
  int ok = par && part && w;
  for (int32_t v = 0; ok && v < n; v++) par[v] = -1, w[v] = v < cl->n ? 0 : s->el[v - cl->n].area;
  for (int32_t c = 0; ok && c < cl->n; c++)
    for (int k = 0; k < 2; k++) {
      const int32_t ch = cl->node[c].child[k];
      par[ch < 0 ? -1 - ch : cl->n + ch] = c;
    }
  ok = ok && hr_partition_preorder(par, w, n, s->nranks, part);
  for (int32_t v = 0; ok && v < n; v++) {
    if (v < cl->n) cl->cown[v] = part[v];
    else s->rootown[v - cl->n] = part[v];
  }
  free(par), free(part), free(w);
  return ok;
}

int hr_cluster_owner(const hr_solver *s, int32_t c) { return node_owner(s, -1 - c); }

int hr_cluster_set_owners(hr_solver *s, const uint64_t *gids, const int32_t *ranks, int64_t n) {
  const uint64_t top = HR_CLUSTER_GID;
  for (int64_t i = 0; i < n; i++)
    if ((gids[i] & top) && (!s->cl || (gids[i] & ~top) >= (uint64_t)s->cl->n)) return 0;
  for (int64_t i = 0; i < n; i++) {
    if (!(gids[i] & top)) continue;
    int32_t *o = &s->cl->cown[gids[i] & ~top];
    s->ncmoved += *o != ranks[i];
    *o = ranks[i];
  }
  return 1;
}

/* A cluster link between ranks: node ids (node_gid), its place, its eight floats. */
typedef struct msg_clink {
  uint64_t r, s;
  int64_t pos;
  float v[8];
} msg_clink;

static msg_clink pack(const hr_solver *s, const clink *l, int64_t pos) {
  msg_clink m = {node_gid(s, l->r), node_gid(s, l->s), pos,
                 {l->F, l->kf, l->d[0], l->d[1], l->d[2], l->fb, l->kv, l->fu2}};
  return m;
}

static clink link_of(int32_t r, int32_t sn, const float *v) {
  return (clink){r, sn, v[0], v[1], {v[2], v[3], v[4]}, v[5], v[6], v[7]};
}

/* The node of id g (node_gid's inverse), or INT32_MIN for an id that names no node; an element
 * this rank does not hold is made (a ghost) when 'make' (*st = HR_ERR_NOMEM when it cannot be),
 * else INT32_MIN. */
static int32_t node_here(hr_solver *s, uint64_t g, int make, hr_status *st) {
  if (g & HR_CLUSTER_GID) {
    const uint64_t c = g & ~HR_CLUSTER_GID;
    return c < (uint64_t)s->cl->n ? -1 - (int32_t)c : INT32_MIN;
  }
  const int32_t e = make ? hr_elem_ensure(s, g) : hr_elem_find(s, g);
  if (e == -2) *st = HR_ERR_NOMEM;
  return e >= 0 ? e : INT32_MIN;
}

/* The local link of message m: its receiver must be an own node here, its source is made a
 * ghost where this rank holds none. HR_OK, HR_ERR_NOMEM or HR_ERR_INVALID. */
static hr_status unpack(hr_solver *s, const msg_clink *m, clink *l) {
  hr_status st = HR_OK;
  const int32_t r = node_here(s, m->r, 0, &st);
  const int32_t sn = r == INT32_MIN ? INT32_MIN : node_here(s, m->s, 1, &st);
  if (st != HR_OK) return st;
  if (r == INT32_MIN || sn == INT32_MIN || node_owner(s, r) != s->rank) return HR_ERR_INVALID;
  *l = link_of(r, sn, m->v);
  return HR_OK;
}

/* The status every rank returns after a collective step: 'st' here, HR_ERR_REMOTE (with its
 * message) where another rank failed. */
static hr_status agreed(hr_status st, int any_failed, hr_err *err) {
  if (st != HR_OK) return st;
  return any_failed ? hr_err_set(err, HR_ERR_REMOTE, "stopped: another rank failed") : HR_OK;
}

static hr_status nomem(hr_err *err) {
  return hr_err_set(err, HR_ERR_NOMEM, "out of memory in cluster refinement");
}

/* A personalised exchange (hr_dist_alltoall_st) with this rank's status 'st'; its result's
 * status as every rank sees it. */
static hr_status xchg(const hr_solver *s, const void *out, int64_t *sb, hr_status st, void **in,
                      int64_t *nin, hr_err *err) {
  *in = NULL, *nin = 0;
  if (st != HR_OK) memset(sb, 0, (size_t)s->nranks * sizeof *sb);
  const hr_status xs = hr_dist_alltoall_st(s->dist, out, sb, st != HR_OK, in, nin);
  if (st != HR_OK) return st;
  if (xs == HR_ERR_REMOTE) return hr_err_set(err, xs, "stopped: another rank failed");
  return xs == HR_OK ? HR_OK : nomem(err);
}

typedef struct scan_rec {
  int64_t key, v, from;
} scan_rec;

static int cmp_scan_rec(const void *a, const void *b) {
  const scan_rec *x = a, *y = b;
  return x->key < y->key ? -1 : x->key > y->key;
}

/* Prefix sums in key order over all ranks: this rank's n items with keys key[0, n) (ascending;
 * distinct over all ranks) and values v[i]; ex[i] gets the sum of v over the items of every
 * rank with smaller keys, '*tot' the sum over all. The range of the keys is cut into P equal
 * parts, each summed on one rank: two personalised exchanges and two small reductions, nothing
 * beyond the first reduction when no rank has an item. '*any' gets the bits of 'flags' (two)
 * set on some rank. A collective; 'st' is this rank's status so far, and every rank returns the
 * same. */
static hr_status scan(hr_solver *s, const int64_t *key, const int64_t *v, int64_t n, int64_t *ex,
                      int64_t *tot, int flags, int *any, hr_status st, hr_err *err) {
  const int P = s->nranks, me = s->rank;
  *tot = 0;
  int64_t hdr[6] = {st != HR_OK, n > 0, flags & 1, flags & 2, n > 0 ? -key[0] : -INT64_MAX,
                    n > 0 ? key[n - 1] : -1};
  hr_dist_max_i64(s->dist, hdr, 6);
  *any = (int)(hdr[2] | hdr[3]);
  if ((st = agreed(st, hdr[0] > 0, err)) != HR_OK || hdr[1] == 0) return st;
  const int64_t kmin = -hdr[4], W = (hdr[5] - kmin) / P + 1; /* rank p: [kmin + p W, + W) */
  int64_t *sb = calloc((size_t)P, sizeof *sb), *all = calloc((size_t)P + 1, sizeof *all);
  if (!sb || !all) hr_dist_abort(s->dist, 1); /* every rank must take part in the exchanges */
  scan_rec *out = malloc((size_t)(n > 0 ? n : 1) * sizeof *out);
  if (!out) st = nomem(err);
  for (int64_t i = 0; i < n && st == HR_OK; i++) { /* ascending keys: grouped by rank */
    out[i] = (scan_rec){key[i], v[i], me};
    sb[(key[i] - kmin) / W] += (int64_t)sizeof *out;
  }
  void *in = NULL;
  int64_t nb = 0;
  st = xchg(s, out, sb, st, &in, &nb, err);
  free(out);
  if (st != HR_OK) {
    free(sb), free(all);
    return st;
  }
  /* this rank's part: its items in key order, each with its index in 'in' */
  const int64_t nin = nb / (int64_t)sizeof(scan_rec);
  const scan_rec *rin = in;
  scan_rec *srt = malloc((size_t)(nin > 0 ? nin : 1) * sizeof *srt);
  int64_t *ans = malloc((size_t)(nin > 0 ? nin : 1) * sizeof *ans), acc = 0;
  if (srt && ans) {
    for (int64_t i = 0; i < nin; i++) srt[i] = (scan_rec){rin[i].key, rin[i].v, i};
    qsort(srt, (size_t)nin, sizeof *srt, cmp_scan_rec);
    for (int64_t i = 0; i < nin; i++) ans[srt[i].from] = acc, acc += srt[i].v;
  }
  all[0] = !srt || !ans;
  all[1 + me] = acc;
  hr_dist_sum_i64(s->dist, all, (int64_t)P + 1);
  st = agreed(all[0] && (!srt || !ans) ? nomem(err) : HR_OK, all[0] > 0, err);
  int64_t off = 0;
  for (int p = 0; p < P; p++) off += p < me ? all[1 + p] : 0, *tot += all[1 + p];
  /* the answers go back in the order the questions came (by rank, each rank's in its order) */
  memset(sb, 0, (size_t)P * sizeof *sb);
  for (int64_t i = 0; i < nin && st == HR_OK; i++) {
    ans[i] += off;
    sb[rin[i].from] += (int64_t)sizeof *ans;
  }
  free(srt), free(in);
  if (all[0] == 0) { /* every rank got this far */
    st = xchg(s, ans, sb, st, &in, &nb, err);
    assert(st != HR_OK || nb == n * (int64_t)sizeof *ans);
    if (st == HR_OK && n > 0) memcpy(ex, in, (size_t)n * sizeof *ex);
    free(in);
  }
  free(ans), free(sb), free(all);
  return st;
}

typedef struct placed {
  int64_t pos;
  clink l;
} placed;

/* Link order, the order of a rank's links (see hr_clusters): by receiver, then by place. */
static int link_before(int32_t ra, int64_t pa, int32_t rb, int64_t pb) {
  return ra < rb || (ra == rb && pa < pb);
}

static int placed_before(const placed *x, const placed *y) {
  return link_before(x->l.r, x->pos, y->l.r, y->pos);
}

/* Sorts a[0, n) into link order in place (quicksort: qsort's merge sort takes a copy as large,
 * 4.8 GB of the transient peak of hall:16's last level). Keys are distinct. */
static void sort_placed(placed *a, int64_t n) {
  while (n > 16) {
    const placed *x = &a[0], *y = &a[n / 2], *z = &a[n - 1]; /* the median of three */
    const placed p = placed_before(x, y)
                         ? (placed_before(y, z) ? *y : placed_before(x, z) ? *z : *x)
                         : (placed_before(x, z) ? *x : placed_before(y, z) ? *z : *y);
    int64_t i = -1, j = n;
    for (;;) {
      do i++;
      while (placed_before(&a[i], &p));
      do j--;
      while (placed_before(&p, &a[j]));
      if (i >= j) break;
      const placed t = a[i];
      a[i] = a[j], a[j] = t;
    }
    const int64_t m = j + 1; /* [0, m) <= p <= [m, n) */
    if (m < n - m) {
      sort_placed(a, m);
      a += m, n -= m;
    } else {
      sort_placed(a + m, n - m);
      n = m;
    }
  }
  for (int64_t i = 1; i < n; i++) {
    const placed t = a[i];
    int64_t j = i;
    for (; j > 0 && placed_before(&t, &a[j - 1]); j--) a[j] = a[j - 1];
    a[j] = t;
  }
}

/* Sorts run in parallel as up to this many chunks, then merged: the result is the same, keys
 * being distinct. Serial sorts were a tenth of the conference room's wall time on 2 threads. */
#define SORT_CHUNKS_MAX 8
#define SORT_CHUNK_MIN 1024

static int sort_chunks(int threads, int64_t n) {
  const int t = threads < SORT_CHUNKS_MAX ? threads : SORT_CHUNKS_MAX;
  return n < SORT_CHUNK_MIN || t < 1 ? 1 : t;
}
static int64_t chunk_lo(int64_t n, int c, int nc) { return (int64_t)((double)n * c / nc); }

/* Puts the links [n0, n) of cl (in any order) among the links [0, n0) (in link order) so that
 * all are in link order: they are sorted in chunks (in parallel), then merged from the back
 * with the others (the tail's old places are free). */
static hr_status regroup(hr_clusters *cl, int64_t n0, int64_t n, int threads) {
  const int64_t m = n - n0;
  if (m == 0) return HR_OK;
  placed *t = malloc((size_t)m * sizeof *t);
  if (!t) return HR_ERR_NOMEM;
  const int nc = sort_chunks(threads, m);
  int64_t top[SORT_CHUNKS_MAX], bot[SORT_CHUNKS_MAX]; /* each chunk's unmerged links */
#pragma omp parallel for schedule(static, 1) if (nc > 1) num_threads(nc)
  for (int c = 0; c < nc; c++) {
    const int64_t lo = chunk_lo(m, c, nc), hi = chunk_lo(m, c + 1, nc);
    for (int64_t j = lo; j < hi; j++) t[j] = (placed){cl->pos[n0 + j], cl->links[n0 + j]};
    sort_placed(t + lo, hi - lo);
    bot[c] = lo, top[c] = hi;
  }
  int64_t i = n0 - 1;
  for (int64_t k = n - 1; k > i; k--) {
    int b = -1; /* the chunk whose last link comes last */
    for (int c = 0; c < nc; c++)
      if (top[c] > bot[c] && (b < 0 || placed_before(&t[top[b] - 1], &t[top[c] - 1]))) b = c;
    if (b < 0) break; /* all placed: the rest is where it was */
    const placed *x = &t[top[b] - 1];
    if (i >= 0 && link_before(x->l.r, x->pos, cl->links[i].r, cl->pos[i])) {
      cl->links[k] = cl->links[i], cl->pos[k] = cl->pos[i--];
    } else {
      cl->links[k] = x->l, cl->pos[k] = x->pos, top[b]--;
    }
  }
  free(t);
  return HR_OK;
}

/* 1 when cl's links are in link order (asserts). */
static int in_link_order(const hr_clusters *cl) {
  for (int64_t i = 1; i < cl->nlinks; i++)
    if (!link_before(cl->links[i - 1].r, cl->pos[i - 1], cl->links[i].r, cl->pos[i])) return 0;
  return 1;
}

/* Room for n links in cl->links and cl->pos. */
static hr_status reserve(hr_clusters *cl, int64_t n) {
  if (n <= cl->cap) return HR_OK;
  int64_t c = cl->cap > 16 ? cl->cap : 16;
  while (c < n) c *= 2;
  clink *l = realloc(cl->links, (size_t)c * sizeof *l);
  if (l) cl->links = l;
  int64_t *p = l ? realloc(cl->pos, (size_t)c * sizeof *p) : NULL;
  if (p) cl->pos = p;
  if (!p) return HR_ERR_NOMEM;
  cl->cap = c;
  return HR_OK;
}

/* Puts all of cl's links in link order. */
static hr_status sort_links(hr_clusters *cl, int threads) {
  return regroup(cl, 0, cl->nlinks, threads);
}

/* The links cur[0, n) at places pos whose receivers other ranks own go there; those that arrive
 * join the others, and all are put in link order. A collective; 'st' is this rank's status so
 * far, and every rank returns the same status. */
static hr_status route(hr_solver *s, clink **pcur, int64_t **ppos, int64_t *pn, hr_status st,
                       hr_err *err) {
  const int P = s->nranks;
  clink *cur = *pcur;
  int64_t *pos = *ppos, n = *pn, nstay = 0;
  int64_t *sb = calloc((size_t)P, sizeof *sb), *at = calloc((size_t)P + 1, sizeof *at);
  if (!sb) hr_dist_abort(s->dist, 1); /* every rank must take part in the exchange */
  for (int64_t i = 0; i < n && st == HR_OK; i++) {
    const int d = node_owner(s, cur[i].r);
    if (d != s->rank) sb[d] += (int64_t)sizeof(msg_clink);
  }
  msg_clink *out = NULL;
  if (st == HR_OK && at) {
    for (int p = 0; p < P; p++) at[p + 1] = at[p] + sb[p] / (int64_t)sizeof *out;
    out = malloc((size_t)(at[P] > 0 ? at[P] : 1) * sizeof *out);
  }
  if (st == HR_OK && !out) st = nomem(err);
  for (int64_t i = 0; i < n && st == HR_OK; i++) {
    const int d = node_owner(s, cur[i].r);
    if (d != s->rank) {
      out[at[d]++] = pack(s, &cur[i], pos[i]);
    } else {
      cur[nstay] = cur[i], pos[nstay++] = pos[i];
    }
  }
  if (st == HR_OK) *pn = nstay; /* what was sent is gone from here in any case */
  void *in = NULL;
  int64_t nb = 0;
  st = xchg(s, out, sb, st, &in, &nb, err);
  free(out), free(sb), free(at);
  if (st != HR_OK) return st;
  const int64_t nr = nb / (int64_t)sizeof(msg_clink), nt = nstay + nr;
  /* Where the links that stayed are in link order (migration: a rank's whole list), only the
   * received ones are sorted, then merged in from the back: sorting all of them took most of
   * a migration (7 s of 8.6 on the conference room at 2 ranks). Refinement's children come in
   * place order: all are sorted. */
  int stayed_sorted = 1;
  for (int64_t i = 1; i < nstay && stayed_sorted; i++)
    stayed_sorted = link_before(cur[i - 1].r, pos[i - 1], cur[i].r, pos[i]);
  const int64_t ns = stayed_sorted ? nr : nt, s0 = stayed_sorted ? 0 : nstay;
  placed *all = malloc((size_t)(ns > 0 ? ns : 1) * sizeof *all);
  clink *c2 = all ? realloc(cur, (size_t)(nt > 0 ? nt : 1) * sizeof *c2) : NULL;
  if (c2) cur = *pcur = c2;
  int64_t *p2 = c2 ? realloc(pos, (size_t)(nt > 0 ? nt : 1) * sizeof *p2) : NULL;
  if (p2) pos = *ppos = p2;
  st = p2 ? HR_OK : HR_ERR_NOMEM;
  for (int64_t i = 0; i < s0 && st == HR_OK; i++) all[i] = (placed){pos[i], cur[i]};
  for (int64_t i = 0; i < nr && st == HR_OK; i++) {
    msg_clink m;
    memcpy(&m, (const char *)in + i * (int64_t)sizeof m, sizeof m);
    all[s0 + i].pos = m.pos;
    st = unpack(s, &m, &all[s0 + i].l);
  }
  free(in);
  if (st == HR_OK) {
    sort_placed(all, ns);
    if (stayed_sorted) { /* merged from the back: the stayed links' tail is free */
      int64_t i = nstay - 1, j = nr - 1;
      for (int64_t k = nt - 1; j >= 0; k--) {
        if (i >= 0 && link_before(all[j].l.r, all[j].pos, cur[i].r, pos[i]))
          cur[k] = cur[i], pos[k] = pos[i], i--;
        else cur[k] = all[j].l, pos[k] = all[j].pos, j--;
      }
    } else {
      for (int64_t i = 0; i < nt; i++) cur[i] = all[i].l, pos[i] = all[i].pos;
    }
    *pn = nt;
  }
  free(all);
  if (st == HR_ERR_INVALID) st = hr_err_set(err, st, "internal error: a cluster link astray");
  else if (st != HR_OK) st = nomem(err);
  return hr_dist_agree(s, st, err);
}

/* The ghost elements among the sources of links l[0, n) that this rank has not subscribed to
 * yet, into a new array '*out' (may repeat one). */
static hr_status ghost_sources(const hr_solver *s, const clink *l, int64_t n, int32_t **out,
                               int64_t *nout) {
  int64_t m = 0;
  for (int64_t i = 0; i < n; i++) m += l[i].s >= 0 && !hr_owns(s, l[i].s) && !s->esub[l[i].s];
  *nout = 0;
  *out = malloc((size_t)(m > 0 ? m : 1) * sizeof **out);
  if (!*out) return HR_ERR_NOMEM;
  for (int64_t i = 0; i < n; i++)
    if (l[i].s >= 0 && !hr_owns(s, l[i].s) && !s->esub[l[i].s]) (*out)[(*nout)++] = l[i].s;
  return HR_OK;
}

hr_status hr_cluster_sources(const hr_solver *s, int32_t **out, int64_t *n) {
  *out = NULL, *n = 0;
  if (!s->cl) return HR_OK;
  return ghost_sources(s, s->cl->links, s->cl->nlinks, out, n);
}

hr_status hr_cluster_migrate(hr_solver *s, hr_err *err) {
  hr_clusters *cl = s->cl;
  if (!cl || !s->dist) return HR_OK;
  const hr_status st = route(s, &cl->links, &cl->pos, &cl->nlinks, HR_OK, err);
  cl->cap = cl->nlinks > 0 ? cl->nlinks : 1; /* route's reallocation */
  return st;
}

void hr_cluster_keep(const hr_solver *s, uint8_t *keep) {
  const hr_clusters *cl = s->cl;
  for (int64_t i = 0; cl && i < cl->nlinks; i++) {
    if (cl->links[i].r >= 0) keep[cl->links[i].r] |= 1;
    if (cl->links[i].s >= 0) keep[cl->links[i].s] |= 1;
  }
}

void hr_cluster_renumber(hr_solver *s, const int32_t *nu) {
  hr_clusters *cl = s->cl;
  for (int64_t i = 0; cl && i < cl->nlinks; i++) {
    clink *l = &cl->links[i];
    assert((l->r < 0 || nu[l->r] >= 0) && (l->s < 0 || nu[l->s] >= 0)); /* kept: keep() */
    if (l->r >= 0) l->r = nu[l->r];
    if (l->s >= 0) l->s = nu[l->s];
  }
  assert(!cl || in_link_order(cl)); /* hr_elem_compact keeps the elements' order */
}

/* ---------------------------------------------------------------- refinement */

/* Decisions; C_WEAK keeps a link that brings at most a quarter of the error allowed (its
 * estimate takes half the rays: visibility noise on it matters a quarter as much). */
enum { C_DROP, C_KEEP, C_WEAK, C_SPLIT_R, C_SPLIT_S, C_ELEM };

static int node_splittable(const hr_solver *s, int32_t id) {
  return id < 0 || hr_elem_splittable(s, &s->el[id]);
}

/* A cluster receives as one (its surfaces' shares by orientation alone) only where that is no
 * coarser than the mesh: when it is at most A_e, the smallest element, or far from the source
 * (kv <= KV_RECV), where the light varies little over it. Elsewhere its surfaces' shares differ
 * by position and by what hides them within it: measured on a closed furnace of 384 triangles,
 * near-field cluster receivers left triangles 3-6% off although each link's own error was
 * within BF_e; they add up, all of one sign for a given triangle. */
#define KV_RECV 0.1f
static int recv_whole(const hr_solver *s, const clink *l) {
  return kv_of(l) <= KV_RECV || s->cl->node[-1 - l->r].area <= s->area_min;
}

/* The normal cone of node id (an element: its surface's normal). */
static void node_cone(const hr_solver *s, int32_t id, hr_vec3 *axis, double *ang) {
  if (id >= 0) {
    *axis = s->scene->surfs[s->el[id].surf].normal, *ang = 0;
  } else {
    *axis = s->cl->node[-1 - id].na, *ang = s->cl->node[-1 - id].nang;
  }
}

/* 0 when no surface of one node faces any point of the other's bounding sphere (centres cr,
 * cs at distance dl, radii sum rsum): the kernel is 0 throughout and the link carries nothing.
 * The directions between the two spheres lie within phi of the centres' direction u; a normal
 * within ang of axis faces one of them when the angle between axis and u is below
 * pi/2 + ang + phi. Exact culling: in the conference room 15% of cluster estimates found no
 * pair facing in 8k draws. */
static int cones_face(const hr_solver *s, const clink *l, hr_vec3 cr, hr_vec3 cs, double dl,
                      double rsum) {
  if (!(dl > rsum)) return 1;
  hr_vec3 ar, as;
  double tr, ts;
  const double phi = asin(rsum / dl) + 1e-6, lim = 0.5 * M_PI + phi;
  const hr_vec3 u = v3_scale(v3_sub(cs, cr), 1 / dl);
  node_cone(s, l->r, &ar, &tr);
  node_cone(s, l->s, &as, &ts);
  return acos_clamped(v3_dot(ar, u)) < lim + tr && acos_clamped(-v3_dot(as, u)) < lim + ts;
}

/* The oracle's geometry of link l (fb, kv, and whether its source is far: kv's sign), once;
 * 0 when the normal cones say the two nodes cannot face each other. */
static int link_geometry(const hr_solver *s, clink *l) {
  hr_vec3 cr, cs;
  double rr, rs, ar, as;
  node_sphere(s, l->r, &cr, &rr, &ar);
  node_sphere(s, l->s, &cs, &rs, &as);
  const double dl = v3_len(v3_sub(cr, cs)), gap = dl - rr - rs;
  l->fb = (float)(gap > 0 ? fmin(1, as / (M_PI * gap * gap)) : 1);
  l->kv = (float)(gap > 0 ? fmin(1, (rr + rs) / gap) : 1);
  if (l->r < 0 && gap > s->cl->lray[-1 - l->r]) l->kv = -l->kv;
  return cones_face(s, l, cr, cs, dl, rr + rs);
}

/* A link whose parent computed its exact unoccluded form factor carries it in F (fu2 says so)
 * until decided; a link that splits with its children's values (exact_unoccluded's 'kids')
 * holds them in F and kf for split() to hand down. Neither has been estimated: F is free. */
#define FU2_INHERITED (-2.0f)
#define FU2_KIDS (-3.0f)

/* Asks for what decide reads of source node id (its radiosity, mean and range) ahead of
 * need: the sources of a receiver's links lie anywhere, and a sweep over links that stay is
 * mostly waiting for them. */
static void prefetch_source(const hr_solver *s, int32_t id) {
  if (id >= 0) {
    __builtin_prefetch(s->Bs[id]);
    __builtin_prefetch(&s->bvar[id]);
  } else {
    __builtin_prefetch(s->cl->Bm[-1 - id]);
    __builtin_prefetch(&s->cl->bhi[-1 - id]);
    __builtin_prefetch(&s->cl->blo[-1 - id]);
  }
}

/* Keep, drop, split a side, or make it an element link. */
static int decide(const hr_solver *s, clink *l, double bf_e) {
  const hr_clusters *cl = s->cl;
  const hr_scene *sc = s->scene;
  float inherited = -1;
  if (l->fu2 == FU2_INHERITED) inherited = l->F, l->F = -1, l->fu2 = -1;
  if (l->r >= 0 && l->s >= 0) return l->r == l->s ? C_DROP : C_ELEM;
  if (l->r == l->s) return C_SPLIT_R;
  if (l->fb < 0) {
    const double tol = 1e-9 * cl->size;
    if (l->r >= 0) {
      const cnode *nd = &cl->node[-1 - l->s];
      if (box_behind(&sc->surfs[s->el[l->r].surf], nd->bmin, nd->bmax, tol)) return C_DROP;
    } else if (l->s >= 0) {
      const cnode *nd = &cl->node[-1 - l->r];
      if (box_behind(&sc->surfs[s->el[l->s].surf], nd->bmin, nd->bmax, tol)) return C_DROP;
    }
    if (!link_geometry(s, l)) return C_DROP;
  }
  double mean, range, rho, bref;
  node_b(s, l->s, &mean, &range);
  node_recv(s, l->r, &rho, &bref);
  double lim = bf_e * bref;
  const double b = mean * kv_of(l) + range;
  if (l->r < 0 && !recv_whole(s, l)) lim = 0;
  if (rho * l->fb * b <= lim) return rho * l->fb * b <= 0.25 * lim ? C_WEAK : C_KEEP;
  /* A link decided in an earlier sweep has its unoccluded value: the test on it needs none of
   * the geometry below (whose two node records were 5% of a late sweep's profile). */
  if (l->fu2 >= 0 && l->fu2 < l->fb && rho * l->fu2 * b <= lim)
    return rho * l->fu2 * b <= 0.25 * lim ? C_WEAK : C_KEEP;
  hr_vec3 cr, cs;
  double rr, rs, ar, as;
  node_sphere(s, l->r, &cr, &rr, &ar);
  node_sphere(s, l->s, &cs, &rs, &as);
  /* A near link that must open unless nothing of it faces (a cluster that may not receive as
   * one: lim = 0) opens once one of its sampled pairs faces, without the exact value, which is
   * positive too unless its quadrature points all miss the facing part (then the link was kept
   * with nothing). Clustered museum: 0.97x the wall time (0.95-1.06, three paired runs). */
  if (l->fu2 < 0 && lim == 0 && near_pair(l) && sampled_unoccluded(s, l, as) > 0) l->fu2 = 2;
  /* Near clusters: the bound says nothing (1 where the spheres meet), so the unoccluded form
   * factor from the link's own point pairs, doubled for its noise, stands in for it. */
  double kids[2][2] = {{-1, -1}, {-1, -1}};
  if (l->fu2 < 0) {
    /* a near link: exact (a few samples of a near pair were measured up to 13x low), from its
     * parent's sums where it has them (the same value) */
    const double fu = !near_pair(l)   ? sampled_unoccluded(s, l, as)
                      : inherited >= 0 ? 0.5 * inherited
                                       : exact_unoccluded(s, l->r, l->s, kids);
    l->fu2 = fu >= 0 ? (float)(2 * fu) : 2; /* 2: no estimate (never below fb <= 1) */
    /* the parent's sums are this link's own, bit for bit */
    assert(!(near_pair(l) && inherited >= 0) ||
           (float)(2 * exact_unoccluded(s, l->r, l->s, NULL)) == inherited);
  }
  if (l->fu2 >= 0 && l->fu2 < l->fb && rho * l->fu2 * b <= lim)
    return rho * l->fu2 * b <= 0.25 * lim ? C_WEAK : C_KEEP;
  /* the larger side opens (a cluster always can; an element above A_e) */
  const int okr = node_splittable(s, l->r), oks = node_splittable(s, l->s);
  assert(okr || oks); /* one side is a cluster */
  const int side = okr && (!oks || rr >= rs) ? 0 : 1;
  if (kids[side][0] >= 0) /* a cluster opens: its children's exact values go with them */
    l->F = (float)(2 * kids[side][0]), l->kf = (float)(2 * kids[side][1]), l->fu2 = FU2_KIDS;
  return side == 0 ? C_SPLIT_R : C_SPLIT_S;
}

/* The children of link l under decision dec into kids (at most 4); returns their count.
 * Elements to split are subdivided already. */
static int split(const hr_solver *s, const clink *l, int dec, clink *kids) {
  const hr_clusters *cl = s->cl;
  int32_t ch[4];
  const int32_t id = dec == C_SPLIT_R ? l->r : l->s;
  int nc;
  if (id < 0) {
    ch[0] = cl->node[-1 - id].child[0], ch[1] = cl->node[-1 - id].child[1], nc = 2;
  } else {
    for (int k = 0; k < 4; k++) ch[k] = s->el[id].child + k;
    nc = 4;
  }
  int n = 0;
  for (int a = 0; a < nc; a++) {
    if (l->r == l->s) { /* a cluster's self-link: every ordered pair of its children */
      for (int b = 0; b < nc; b++) kids[n++] = fresh(ch[a], ch[b]);
    } else {
      kids[n++] = dec == C_SPLIT_R ? fresh(ch[a], l->s) : fresh(l->r, ch[a]);
      if (l->fu2 == FU2_KIDS)
        kids[n - 1].F = a == 0 ? l->F : l->kf, kids[n - 1].fu2 = FU2_INHERITED;
    }
  }
  return n;
}

static hr_status append_links(hr_solver *s, const hr_link *add, const uint8_t *ok, int64_t n,
                              int64_t *nnew) {
  int64_t m = 0;
  for (int64_t i = 0; i < n; i++) m += ok[i];
  if (m == 0) return HR_OK;
  if (s->nlinks + m > s->cap_links) {
    int64_t nc = s->cap_links > 0 ? s->cap_links : 64;
    while (nc < s->nlinks + m) nc *= 2;
    hr_link *l = realloc(s->links, (size_t)nc * sizeof *l);
    if (!l) return HR_ERR_NOMEM;
    s->links = l, s->cap_links = nc;
  }
  for (int64_t i = 0; i < n; i++)
    if (ok[i]) s->links[s->nlinks++] = add[i];
  /* appended after the sorted links, as refinement's extras (hr_link_sort); a full sort only
   * once they are many (a full sort every iteration was most of hall:1's clustered solve) */
  if ((s->nlinks - s->nsorted + s->ndead) * 4 > s->nlinks) s->sorted = 0;
  *nnew += m;
  return HR_OK;
}

/* How many children split() makes of link l under decision dec. */
static int kid_count(const clink *l, int dec) {
  if (dec != C_SPLIT_R && dec != C_SPLIT_S) return 0;
  const int32_t id = dec == C_SPLIT_R ? l->r : l->s;
  const int nc = id < 0 ? 2 : 4;
  return l->r == l->s ? nc * nc : nc;
}

/* What decide's keep tests read of each source node, its mean and range (b = mean kv + range),
 * rounded up to float, elements first (nel of them), then clusters: a small array that stays in
 * cache while the decisions read sources at random. */
static float *source_bounds(const hr_solver *s) {
  const int64_t nel = s->nel, n = nel + s->cl->n;
  float *bup = malloc((size_t)(n > 0 ? n : 1) * 2 * sizeof *bup);
  if (!bup) return NULL;
  for (int64_t k = 0; k < n; k++) {
    double mean, range;
    node_b(s, k < nel ? (int32_t)k : (int32_t)(-1 - (k - nel)), &mean, &range);
    bup[2 * k] = hr_float_up(mean), bup[2 * k + 1] = hr_float_up(range);
  }
  return bup;
}

/* 1 when link l, decided and estimated in an earlier sweep, is surely kept again at bf_e: its
 * form-factor bound (the smaller of fb and its unoccluded value where decide computed one,
 * which decide tests in turn) times the source's bound passes, with a margin for the rounding
 * of the products. Most links of a late sweep pass, without decide reading the two nodes. */
static int kept_again(const hr_solver *s, const float *bup, const clink *l, double bf_e) {
  /* (fu2: -1 where the bound fb sufficed, and decide tests it first) */
  if (!(l->F >= 0 && l->fb >= 0 && (l->fu2 >= 0 || l->fu2 == -1))) return 0;
  double rho, bref;
  node_recv(s, l->r, &rho, &bref);
  if (l->r < 0 && !recv_whole(s, l)) return 0;
  const double fmin = l->fu2 >= 0 && l->fu2 < l->fb ? l->fu2 : l->fb;
  const float *u = &bup[2 * (l->s >= 0 ? l->s : s->nel + (-1 - l->s))];
  return rho * fmin * ((double)u[0] * kv_of(l) + u[1]) <= bf_e * bref * (1 - 1e-9);
}

/* Links are decided and made in chunks of this many, each chunk's outputs at offsets counted
 * beforehand, so that the work runs in parallel, its order does not depend on threads and no
 * per-link output array is needed. */
#define CHUNK 4096
/* How many links ahead decide's source data is asked for (prefetch_source). */
#define PREFETCH_AHEAD 8

/* After the decisions dec[0, n) of this rank's links cur (places pos): ex[j], for the j-th
 * link (in index order) that splits, the place of its first child among the next round's links
 * (offsets from cl->vnext: the children of all ranks' links, numbered in their parents' place
 * order); '*tot' their count. Distributed: '*what' whether some link of some rank becomes an
 * element link (ELEM_LINKS) and whether some rank opens an element that has no children yet
 * (ELEM_SPLITS), and a collective (see scan). '*ex' is allocated. The arrays are as long as
 * the splitting links, not all: in a sweep over the conference room's 22 M links that keep,
 * arrays for every link (56 bytes each, a first touch of every page) set the peak memory. */
enum { ELEM_LINKS = 1, ELEM_SPLITS = 2 };

/* places in one process when the splitting links' keys lie in a range no longer than twice the
 * links (a round's children hold consecutive places): the prefix sums in key order from a table
 * of the kid counts by key, without sorting. The table holds, in blocks of PBLOCK keys, each
 * key's offset within its block (at most 16 kids a link: within 16 bits). 0 when the range is
 * too wide or memory is short (the caller then sorts). */
#define PBLOCK 2048
static int places_dense(const scan_rec *q, int64_t m, int64_t n, int64_t kmin, int64_t kmax,
                        int64_t *ex, int64_t *tot, int threads) {
  if (m == 0 || kmax - kmin >= 2 * n + CHUNK) return 0;
  const int64_t range = kmax - kmin + 1, nb = (range + PBLOCK - 1) / PBLOCK;
  uint16_t *t = calloc((size_t)range, sizeof *t);
  int64_t *bs = malloc((size_t)(nb + 1) * sizeof *bs);
  if (!t || !bs) {
    free(t), free(bs);
    return 0;
  }
#pragma omp parallel num_threads(threads) if (m > PAR_MIN)
  {
#pragma omp for schedule(static)
    for (int64_t j = 0; j < m; j++) {
      assert(q[j].v > 0 && q[j].v <= 16);
      t[q[j].key - kmin] = (uint16_t)q[j].v;
    }
#pragma omp for schedule(static)
    for (int64_t b = 0; b < nb; b++) {
      const int64_t hi = (b + 1) * PBLOCK < range ? (b + 1) * PBLOCK : range;
      uint32_t acc = 0;
      for (int64_t o = b * PBLOCK; o < hi; o++) {
        const uint32_t x = t[o];
        t[o] = (uint16_t)acc;
        acc += x;
      }
      bs[b] = acc;
    }
#pragma omp single
    {
      int64_t acc = 0;
      for (int64_t b = 0; b < nb; b++) {
        const int64_t x = bs[b];
        bs[b] = acc;
        acc += x;
      }
      *tot = acc;
    }
#pragma omp for schedule(static)
    for (int64_t j = 0; j < m; j++) {
      const int64_t o = q[j].key - kmin;
      ex[q[j].from] = bs[o / PBLOCK] + t[o];
    }
  }
  free(t), free(bs);
  return 1;
}

static hr_status places(hr_solver *s, const clink *cur, const int64_t *pos, int64_t n,
                        const uint8_t *dec, const int64_t (*cnt)[4], int64_t **ex, int64_t *tot,
                        int *what, hr_status st, hr_err *err) {
  /* cnt[c][3]: the splitting links before chunk c (CHUNK links a chunk), cnt[nch][3] all */
  const int64_t nch = st == HR_OK ? (n + CHUNK - 1) / CHUNK : 0;
  int64_t m = nch > 0 ? cnt[nch][3] : 0;
  scan_rec *q = malloc((size_t)(m > 0 ? m : 1) * sizeof *q);
  int64_t *k = malloc((size_t)(m > 0 ? m : 1) * sizeof *k);
  int64_t *v = malloc((size_t)(m > 0 ? m : 1) * sizeof *v);
  int64_t *e = malloc((size_t)(m > 0 ? m : 1) * sizeof *e);
  *ex = malloc((size_t)(m > 0 ? m : 1) * sizeof **ex);
  if (st == HR_OK && (!q || !k || !v || !e || !*ex)) st = nomem(err);
  if (st != HR_OK) m = 0;
  int fl = 0, sorted = 1;
  int64_t kmin = INT64_MAX, kmax = INT64_MIN;
#pragma omp parallel for schedule(static) reduction(| : fl) reduction(& : sorted) \
    reduction(min : kmin) reduction(max : kmax) if (nch > 1) num_threads(s->threads)
  for (int64_t c = 0; c < nch; c++) {
    const int64_t hi = (c + 1) * CHUNK < n ? (c + 1) * CHUNK : n;
    for (int64_t i = c * CHUNK, j = cnt[c][3]; i < hi; i++) {
      const int32_t id = dec[i] == C_SPLIT_R ? cur[i].r : dec[i] == C_SPLIT_S ? cur[i].s : -1;
      fl |= (dec[i] == C_ELEM ? ELEM_LINKS : 0) |
            (id >= 0 && s->el[id].child < 0 ? ELEM_SPLITS : 0);
      const int nk = kid_count(&cur[i], dec[i]);
      if (nk == 0 || j >= m) continue;
      q[j] = (scan_rec){pos[i], nk, j};
      sorted &= j == 0 || j == cnt[c][3] || q[j - 1].key < q[j].key;
      kmin = pos[i] < kmin ? pos[i] : kmin, kmax = pos[i] > kmax ? pos[i] : kmax;
      j++;
    }
  }
  if (!s->dist && st == HR_OK && places_dense(q, m, n, kmin, kmax, *ex, tot, s->threads)) {
    *what = fl;
    free(q), free(k), free(v), free(e);
    return st;
  }
  /* across the chunks' seams */
  for (int64_t c = 1; c < nch && sorted; c++)
    if (cnt[c][3] > 0 && cnt[c][3] < m) sorted &= q[cnt[c][3] - 1].key < q[cnt[c][3]].key;
  /* in key order: k, v, and in 'fr' the index each came from (sorted in chunks, merged) */
  int64_t *fr = sorted ? NULL : malloc((size_t)(m > 0 ? m : 1) * sizeof *fr);
  if (st == HR_OK && !sorted && !fr) st = nomem(err), m = 0;
  if (st == HR_OK && !sorted) {
    const int nc = sort_chunks(s->threads, m);
    int64_t at[SORT_CHUNKS_MAX]; /* the first unmerged record of each chunk */
#pragma omp parallel for schedule(static, 1) if (nc > 1) num_threads(nc)
    for (int c = 0; c < nc; c++) {
      at[c] = chunk_lo(m, c, nc);
      qsort(q + at[c], (size_t)(chunk_lo(m, c + 1, nc) - at[c]), sizeof *q, cmp_scan_rec);
    }
    for (int64_t j = 0; j < m; j++) {
      int b = -1;
      for (int c = 0; c < nc; c++)
        if (at[c] < chunk_lo(m, c + 1, nc) && (b < 0 || q[at[c]].key < q[at[b]].key)) b = c;
      const scan_rec *x = &q[at[b]++];
      k[j] = x->key, v[j] = x->v, fr[j] = x->from;
    }
  }
  for (int64_t j = 0; j < m && st == HR_OK && sorted; j++) k[j] = q[j].key, v[j] = q[j].v;
  if (s->dist) {
    st = scan(s, k, v, st == HR_OK ? m : 0, e, tot, fl, what, st, err);
  } else {
    *tot = 0, *what = fl;
    for (int64_t j = 0; j < m && st == HR_OK; j++) e[j] = *tot, *tot += v[j];
  }
  for (int64_t j = 0; j < m && st == HR_OK; j++) (*ex)[fr ? fr[j] : q[j].from] = e[j];
  free(q), free(k), free(v), free(e), free(fr);
  return st;
}

/* Distributed refinement: the elements that open (own ones, and ghosts, which their owners
 * split too; hr_link_split_marked). A collective. */
static hr_status split_dist(hr_solver *s, const clink *cur, int64_t n, const uint8_t *dec,
                            hr_err *err) {
  uint8_t *mark = calloc((size_t)s->nel + 1, 1);
  hr_status st = hr_dist_agree(s, mark ? HR_OK : nomem(err), err);
  if (st == HR_OK) {
    for (int64_t i = 0; i < n; i++) {
      const int32_t id = dec[i] == C_SPLIT_R ? cur[i].r : dec[i] == C_SPLIT_S ? cur[i].s : -1;
      if (id >= 0 && s->el[id].child < 0) mark[id] = 1;
    }
    st = hr_link_split_marked(s, mark, s->nel, err);
  }
  free(mark);
  return st;
}

/* Rays cast for a link that node r receives, to its work (balance.c). A receiver's links can
 * fall in two threads' chunks: atomic. */
static void count_rays(hr_solver *s, int32_t r, float cast) {
  float *w = r >= 0 ? &s->erays[r] : &s->cl->crays[-1 - r];
#pragma omp atomic
  *w += cast;
}

hr_status hr_cluster_refine(hr_solver *s, double bf_e, int64_t *nnew, hr_err *err) {
  hr_clusters *cl = s->cl;
  if (!cl) return HR_OK;
  assert(in_link_order(cl));
  const int dist = s->dist != NULL;
  /* The first round works on cl's links in place; each later one on the children of the
   * round before ('cur', 'cpos'). The kept links gather in cl->links[0, nout). */
  clink *cur = cl->links;
  int64_t *cpos = cl->pos, ncur = cl->nlinks, nout = 0, nfirst = 0, cur_cap = 0;
  /* A finished round's links (capacity spare_cap), reused for the children of the round after
   * next: fresh memory costs a page fault a page (13.5 us each on these virtual machines). It
   * is kept only while it can take them and is at most twice their size: a larger one raised
   * hall:8's peak by 4%. */
  clink *spare = NULL;
  int64_t *spare_pos = NULL, spare_cap = 0;
  hr_status st = HR_OK;
  int64_t rays = 0, made = 0;
  /* the first round's links decided before: most pass a bound (kept_again); NULL: decide all */
  float *bup = source_bounds(s);
  /* the test hook HRAD_TEST_FAIL=RANK:cluster:ITER: this rank fails within the first round */
  int injected = hr_test_fail(s, HR_PHASE_CLUSTER);
  /* one process: until no link splits; distributed: until none does on any rank, every rank
   * taking part in every round's exchanges */
  for (int round = 0; dist || (st == HR_OK && ncur > 0); round++) {
    const int inplace = round == 0;
    const int64_t nch = (ncur + CHUNK - 1) / CHUNK;
    uint8_t *dec = malloc((size_t)(ncur > 0 ? ncur : 1));
    /* keep, element, kids, splitting links */
    int64_t(*cnt)[4] = calloc((size_t)nch + 1, sizeof *cnt);
    int64_t *ex = NULL, tot = 0;
    int what = 0;
    if (st == HR_OK && (!dec || !cnt)) st = HR_ERR_NOMEM;
    if (!dist && st != HR_OK) {
      free(dec), free(cnt);
      break;
    }
    if (st == HR_OK) {
#pragma omp parallel for schedule(dynamic, 1) if (nch > 1) num_threads(s->threads)
      for (int64_t c = 0; c < nch; c++) {
        const int64_t hi = (c + 1) * CHUNK < ncur ? (c + 1) * CHUNK : ncur;
        for (int64_t i = c * CHUNK; i < hi; i++) {
          if (i + PREFETCH_AHEAD < hi) prefetch_source(s, cur[i + PREFETCH_AHEAD].s);
          const int quick = inplace && bup && kept_again(s, bup, &cur[i], bf_e);
          const int d = quick ? C_KEEP : decide(s, &cur[i], bf_e);
          /* a true bound (keep and weak are alike for a link estimated before) */
          assert(!quick || decide(s, &cur[i], bf_e) == C_KEEP ||
                 decide(s, &cur[i], bf_e) == C_WEAK);
          dec[i] = (uint8_t)d;
          cnt[c + 1][0] += d == C_KEEP || d == C_WEAK;
          cnt[c + 1][1] += d == C_ELEM;
          cnt[c + 1][2] += kid_count(&cur[i], d);
          cnt[c + 1][3] += kid_count(&cur[i], d) > 0;
        }
      }
      for (int64_t c = 0; c < nch; c++)
        for (int k = 0; k < 4; k++) cnt[c + 1][k] += cnt[c][k];
    }
    /* the children go where the round before last's were when they fit and fill at least half
     * of it; otherwise that goes now, before this round's other arrays (see 'spare') */
    if (spare && (st != HR_OK || spare_cap < cnt[nch][2] || spare_cap > 2 * cnt[nch][2] + CHUNK)) {
      free(spare), free(spare_pos);
      spare = NULL, spare_pos = NULL, spare_cap = 0;
    }
    if ((st = places(s, cur, cpos, ncur, dec, (const int64_t(*)[4])cnt, &ex, &tot, &what, st,
                     err)) != HR_OK) {
      free(dec), free(cnt), free(ex);
      break;
    }
    /* elements that open: subdivided here, in increasing link order (the order does not depend
     * on threads), with their children's open fractions */
    const int64_t nel0 = s->nel;
    if (!dist) {
      for (int64_t i = 0; i < ncur && st == HR_OK; i++) {
        const int32_t id = dec[i] == C_SPLIT_R ? cur[i].r : dec[i] == C_SPLIT_S ? cur[i].s : -1;
        if (id >= 0 && s->el[id].child < 0) st = hr_elem_subdivide(s, id);
      }
      if (s->nel > nel0) hr_elem_open(s, nel0, s->nel);
    } else if ((what & ELEM_SPLITS) && (st = split_dist(s, cur, ncur, dec, err)) != HR_OK) {
      free(dec), free(cnt), free(ex);
      break;
    }
    const int64_t nkeep = cnt[nch][0], nelem = cnt[nch][1], nkids = cnt[nch][2];
    if (st == HR_OK && injected == 1) st = HR_ERR_NOMEM, injected = 2;
    if (st == HR_OK && !inplace && reserve(cl, nout + nkeep) != HR_OK) st = HR_ERR_NOMEM;
    clink *next = spare ? spare : malloc((size_t)(nkids > 0 ? nkids : 1) * sizeof *next);
    int64_t *npos = spare ? spare_pos : malloc((size_t)(nkids > 0 ? nkids : 1) * sizeof *npos);
    const int64_t next_cap = spare ? spare_cap : nkids > 0 ? nkids : 1;
    spare = NULL, spare_pos = NULL, spare_cap = 0;
    hr_link *el = malloc((size_t)(nelem > 0 ? nelem : 1) * sizeof *el);
    uint8_t *eok = calloc((size_t)(nelem > 0 ? nelem : 1), 1);
    if (st == HR_OK && (!next || !el || !eok || !npos)) st = HR_ERR_NOMEM;
    const int64_t nl0 = s->nlinks;
    if (st == HR_OK) {
      clink *out = cl->links;
      int64_t *opos = cl->pos;
      /* in place: each chunk first packs its kept links at its own start (never past the link
       * being read), then the chunks move down in order */
#pragma omp parallel for schedule(dynamic, 1) reduction(+ : rays, made) if (nch > 1) \
    num_threads(s->threads)
      for (int64_t c = 0; c < nch; c++) {
        const int64_t hi = (c + 1) * CHUNK < ncur ? (c + 1) * CHUNK : ncur;
        int64_t ko = inplace ? c * CHUNK : nout + cnt[c][0], eo = cnt[c][1], no = cnt[c][2],
                xo = cnt[c][3];
        for (int64_t i = c * CHUNK; i < hi; i++) {
          const int64_t r0 = rays;
          if (dec[i] == C_KEEP || dec[i] == C_WEAK) {
            if (cur[i].F < 0) estimate(s, &cur[i], dec[i] == C_WEAK, &rays), made++;
            if (!inplace || ko != i) out[ko] = cur[i], opos[ko] = cpos[i];
            ko++;
          } else if (dec[i] == C_ELEM) {
            eok[eo] = (uint8_t)hr_link_pair(s, cur[i].r, cur[i].s, &el[eo], &rays);
            eo++;
          } else if (dec[i] == C_SPLIT_R || dec[i] == C_SPLIT_S) {
            const int nk = split(s, &cur[i], dec[i], next + no);
            for (int k = 0; k < nk; k++) npos[no + k] = cl->vnext + ex[xo] + k;
            no += nk, xo++;
          }
          if (rays > r0) count_rays(s, cur[i].r, (float)(rays - r0));
        }
      }
      for (int64_t c = 0; inplace && c < nch; c++) {
        const int64_t from = c * CHUNK, to = cnt[c][0], m = cnt[c + 1][0] - cnt[c][0];
        if (from != to && m > 0) {
          memmove(out + to, out + from, (size_t)m * sizeof *out);
          memmove(opos + to, opos + from, (size_t)m * sizeof *opos);
        }
      }
      nout += nkeep;
      if (inplace) nfirst = nout;
      st = append_links(s, el, eok, nelem, nnew);
    }
    cl->vnext += tot;
    free(dec), free(cnt), free(el), free(eok), free(ex);
    if (!inplace) spare = cur, spare_pos = cpos, spare_cap = cur_cap;
    cur = next, cpos = npos, cur_cap = next_cap;
    ncur = st == HR_OK ? nkids : 0;
    if (!dist) continue;
    if (tot == 0 && !(what & ELEM_LINKS)) break; /* every rank: no children, no new links */
    /* the children to their receivers' owners; subscriptions of their ghost sources and of the
     * new element links' */
    st = route(s, &cur, &cpos, &ncur, st, err);
    cur_cap = ncur > 0 ? ncur : 1; /* (route's reallocation) */
    if (st != HR_OK) break;
    int32_t *src = NULL;
    int64_t nsrc = 0;
    if (ghost_sources(s, cur, ncur, &src, &nsrc) != HR_OK) st = nomem(err);
    st = hr_link_subscribe_new(s, nl0, src, nsrc, st, err);
    free(src);
    if (st != HR_OK || tot == 0) break;
  }
  if (cur != cl->links) free(cur), free(cpos);
  free(spare), free(spare_pos), free(bup);
  s->rays += rays;
  *nnew += made;
  /* the later rounds' links among the first's */
  if (st == HR_OK && regroup(cl, nfirst, nout, s->threads) != HR_OK) st = HR_ERR_NOMEM;
  if (st != HR_OK && st != HR_ERR_REMOTE)
    st = hr_err_set(err, st, "out of memory in cluster refinement%s",
                    injected == 2 ? " (injected by HRAD_TEST_FAIL)" : "");
  if (dist) st = hr_dist_agree(s, st, err); /* (a failure in the last round) */
  cl->nlinks = st == HR_OK ? nout : 0;
  assert(st != HR_OK || in_link_order(cl));
  return st;
}

/* ---------------------------------------------------------------- gather, push, pull */

/* What link l brings its receiver: to G, Gu and Gf of an element, or to a cluster's field L. */
static inline void gather_link(hr_solver *s, const clink *l) {
  hr_clusters *cl = s->cl;
  /* nothing to add (57% of the conference room's cluster links: hidden); the sums are the same
   * bit for bit without them (x + 0 B == x for finite B), and the source's B is not read */
  if (l->F == 0) return;
  double mean, range;
  const double *b = node_b(s, l->s, &mean, &range);
  if (l->r >= 0) {
    const double f = l->F;
    for (int c = 0; c < 3; c++) s->G[l->r][c] += f * b[c];
    s->Gu[l->r] += f * mean;
    s->Gf[l->r] += f;
    return;
  }
  if (l->kf == 0) return;
  const double d[3] = {l->d[0], l->d[1], l->d[2]}, v[NCH] = {b[0], b[1], b[2], mean, 1};
  double(*L)[9] = cl->L[-1 - l->r][far_source(l)];
  if (l->kf < 0) { /* even: E(n) = L_00 Y_00 = -kf v / 4 for every n */
    for (int c = 0; c < NCH; c++) L[c][0] += -l->kf * hr_sh_alpha[0] * 0.282095 * v[c];
    return;
  }
  double y[9];
  hr_sh9(d, y);
  for (int q = 0; q < 9; q++) {
    const double w = l->kf * hr_sh_alpha[q] * y[q];
    for (int c = 0; c < NCH; c++) L[c][q] += w * v[c];
  }
}

/* The first link at or after i whose receiver is not that of link i - 1 (in link order the
 * receivers ascend). */
static int64_t receiver_start(const hr_clusters *cl, int64_t i) {
  if (i <= 0 || i >= cl->nlinks) return i <= 0 ? 0 : cl->nlinks;
  const int32_t r = cl->links[i - 1].r;
  int64_t lo = i, hi = cl->nlinks; /* the first in [lo, hi) with a larger receiver */
  while (lo < hi) {
    const int64_t m = lo + (hi - lo) / 2;
    if (cl->links[m].r > r) hi = m;
    else lo = m + 1;
  }
  return lo;
}

void hr_cluster_gather(hr_solver *s) {
  hr_clusters *cl = s->cl;
  if (!cl) return;
  memset(cl->L, 0, (size_t)cl->n * sizeof *cl->L);
  assert(cl->tq); /* hr_cluster_prepare */
  /* chunks of whole receivers in parallel, each receiver's links in place order: the same sums
   * as one pass over the list, on any number of threads */
  const int64_t nch = (cl->nlinks + CHUNK - 1) / CHUNK;
#pragma omp parallel for schedule(dynamic, 4) if (nch > 1) num_threads(s->threads)
  for (int64_t c = 0; c < nch; c++) {
    const int64_t hi = receiver_start(cl, (c + 1) * CHUNK);
    for (int64_t i = receiver_start(cl, c * CHUNK); i < hi; i++) gather_link(s, &cl->links[i]);
  }
  /* distributed: each cluster's field is summed on the rank that holds its links, zeros
   * elsewhere (x + 0 == x); all of them on every rank */
  if (s->dist) hr_dist_sum_f64(s->dist, &cl->L[0][0][0][0], (int64_t)cl->n * 2 * NCH * 9);
  /* push: preorder, so a parent's field is complete before its children take it; every rank
   * pushes alike and adds what reaches its own roots */
  for (int32_t c = 0; c < cl->n; c++) {
    const cnode *nd = &cl->node[c];
    for (int q = 0; q < 2; q++) {
      const int32_t id = nd->child[q];
      if (id < 0) {
        double(*L)[NCH][9] = cl->L[-1 - id];
        for (int f = 0; f < 2; f++)
          for (int ch = 0; ch < NCH; ch++)
            for (int k = 0; k < 9; k++) L[f][ch][k] += cl->L[c][f][ch][k];
        continue;
      }
      if (!hr_owns(s, id)) continue;
      const hr_vec3 nv = s->scene->surfs[id].normal;
      const double n[3] = {nv.x, nv.y, nv.z};
      double y[9], e[NCH];
      hr_sh9(n, y);
      for (int ch = 0; ch < NCH; ch++) {
        double x = 0;
        for (int k = 0; k < 9; k++)
          x += cl->L[c][0][ch][k] * y[k] + cl->L[c][1][ch][k] * cl->tq[id][k];
        e[ch] = x > 0 ? x : 0;
      }
      for (int ch = 0; ch < 3; ch++) s->G[id][ch] += e[ch];
      s->Gu[id] += e[3];
      s->Gf[id] += e[4];
    }
  }
}

void hr_cluster_pull(hr_solver *s) {
  hr_clusters *cl = s->cl;
  if (!cl) return;
  for (int32_t c = cl->n - 1; c >= 0; c--) {
    const cnode *nd = &cl->node[c];
    double acc[3] = {0, 0, 0}, hi = 0, lo = INFINITY, br = 0;
    for (int q = 0; q < 2; q++) {
      const int32_t id = nd->child[q];
      double a, h, l, r;
      const double *b;
      if (id >= 0) {
        a = s->el[id].area, b = s->Bs[id];
        const double m = max3(b), v = s->bvar[id] > 0 ? s->bvar[id] : 0; /* leaf: 0 */
        h = m + v, l = m - v > 0 ? m - v : 0;
        r = s->bref[id] / hr_slack(s, hr_elem_imp_area(s, id));
      } else {
        const int32_t k = -1 - id;
        a = cl->node[k].area, b = cl->Bm[k], h = cl->bhi[k], l = cl->blo[k], r = cl->bref[k];
      }
      for (int ch = 0; ch < 3; ch++) acc[ch] += a * b[ch];
      hi = h > hi ? h : hi;
      lo = l < lo ? l : lo;
      br += a * r;
    }
    for (int ch = 0; ch < 3; ch++) cl->Bm[c][ch] = nd->area > 0 ? acc[ch] / nd->area : 0;
    cl->bhi[c] = hi, cl->blo[c] = lo, cl->bref[c] = nd->area > 0 ? br / nd->area : 0;
  }
  cl->initial = 0;
}

/* ---------------------------------------------------------------- set-up */

/* s->cl with its hierarchy and room for n links (none yet), with their places in distributed
 * runs. */
static hr_status create(hr_solver *s, int64_t n) {
  hr_clusters *cl = calloc(1, sizeof *cl);
  if (!cl) return HR_ERR_NOMEM;
  s->cl = cl;
  if (build_tree(s, cl) != HR_OK) return HR_ERR_NOMEM;
  cl->crays = calloc((size_t)cl->n + 1, sizeof *cl->crays);
  cl->cown = malloc(((size_t)cl->n + 1) * sizeof *cl->cown);
  if (!cl->crays || !cl->cown) return HR_ERR_NOMEM;
  for (int32_t c = 0; c < cl->n; c++) cl->cown[c] = drawn_owner(s, c);
  cl->cap = n > 0 ? n : 1;
  cl->links = malloc((size_t)cl->cap * sizeof *cl->links);
  cl->pos = malloc((size_t)cl->cap * sizeof *cl->pos);
  return cl->links && cl->pos ? HR_OK : HR_ERR_NOMEM;
}

hr_status hr_cluster_init(hr_solver *s, hr_err *err) {
  hr_status st = create(s, 1);
  if (st != HR_OK) st = hr_err_set(err, HR_ERR_NOMEM, "out of memory building clusters");
  else if (hr_test_fail(s, HR_PHASE_INIT))
    st = hr_err_set(err, HR_ERR_NOMEM, "out of memory building clusters (injected by "
                                       "HRAD_TEST_FAIL)");
  else st = hr_cluster_prepare(s, err);
  if (st == HR_OK && hr_start_compact(s)) {
    if (!spread_by_hierarchy(s)) st = hr_err_set(err, HR_ERR_NOMEM, "out of memory");
    else hr_owners_recompute(s);
  }
  if ((st = hr_dist_agree(s, st, err)) != HR_OK) return st;
  hr_clusters *cl = s->cl;
  hr_cluster_pull(s); /* radiosities: the emission */
  cl->initial = 1;
  /* the root's self-link, on the rank that holds the root's links, at place 0 */
  if (node_owner(s, cl->root) == s->rank) {
    cl->links[0] = fresh(cl->root, cl->root);
    cl->pos[0] = 0;
    cl->nlinks = 1;
  }
  cl->vnext = 1;
  int64_t nnew = 0;
  /* before the first gather only the emitters have light, and every receiver's reference is the
   * floor (node_recv): this sweep sets the direct light's resolution (docs/design.md) */
  return hr_cluster_refine(s, s->opt.bf_first, &nnew, err);
}

static int cmp_msg_pos(const void *a, const void *b) {
  const msg_clink *x = a, *y = b;
  return x->pos < y->pos ? -1 : x->pos > y->pos;
}

hr_status hr_cluster_export(const hr_solver *s, uint64_t **ids, float **vals, int64_t *n) {
  const hr_clusters *cl = s->cl;
  *ids = NULL, *vals = NULL, *n = cl ? cl->nlinks : 0;
  msg_clink *all = NULL;
  scan_rec *ord = NULL; /* one process: the links' indices in place order */
  if (!s->dist && cl && *n > 0) {
    ord = malloc((size_t)*n * sizeof *ord);
    if (!ord) return HR_ERR_NOMEM;
    for (int64_t i = 0; i < *n; i++) ord[i] = (scan_rec){cl->pos[i], 0, i};
    qsort(ord, (size_t)*n, sizeof *ord, cmp_scan_rec);
  }
  if (s->dist && cl) { /* everybody's to rank 0, in place order */
    hr_err e2;
    const int64_t m = *n;
    *n = 0;
    msg_clink *out = malloc((size_t)(m > 0 ? m : 1) * sizeof *out);
    int64_t *sb = calloc((size_t)s->nranks, sizeof *sb), nb = 0;
    if (!sb) hr_dist_abort(s->dist, 1); /* every rank must take part in the exchange */
    for (int64_t i = 0; out && i < m; i++) out[i] = pack(s, &cl->links[i], cl->pos[i]);
    sb[0] = m * (int64_t)sizeof *out;
    void *in = NULL;
    const hr_status st = xchg(s, out, sb, out ? HR_OK : HR_ERR_NOMEM, &in, &nb, &e2);
    free(out), free(sb);
    if (st != HR_OK) return st;
    all = in;
    *n = nb / (int64_t)sizeof *all;
    qsort(all, (size_t)*n, sizeof *all, cmp_msg_pos);
  }
  if (*n == 0) {
    free(all), free(ord);
    return HR_OK;
  }
  *ids = malloc((size_t)*n * 2 * sizeof **ids);
  *vals = malloc((size_t)*n * 8 * sizeof **vals);
  if (!*ids || !*vals) {
    free(*ids), free(*vals), free(all), free(ord);
    *ids = NULL, *vals = NULL;
    return HR_ERR_NOMEM;
  }
  for (int64_t i = 0; i < *n; i++) {
    const int64_t k = ord ? ord[i].from : i;
    const msg_clink m = ord ? pack(s, &cl->links[k], cl->pos[k]) : all[i];
    (*ids)[2 * i] = m.r, (*ids)[2 * i + 1] = m.s;
    memcpy(*vals + 8 * i, m.v, sizeof m.v);
  }
  free(all), free(ord);
  return HR_OK;
}

hr_status hr_cluster_import(hr_solver *s, const uint64_t *ids, const float *vals, int64_t n) {
  hr_status st = create(s, n);
  if (st != HR_OK) return st;
  hr_clusters *cl = s->cl;
  int64_t k = 0;
  for (int64_t i = 0; i < n; i++) {
    const int32_t r = node_here(s, ids[2 * i], 0, &st), sn = node_here(s, ids[2 * i + 1], 0, &st);
    if (r == INT32_MIN || sn == INT32_MIN || (r >= 0 && sn >= 0)) return HR_ERR_PARSE;
    if (node_owner(s, r) != s->rank) continue; /* distributed: another rank's */
    cl->pos[k] = i;
    cl->links[k++] = link_of(r, sn, vals + 8 * i);
  }
  cl->nlinks = k;
  cl->vnext = n;
  if (!in_link_order(cl) && sort_links(cl, s->threads) != HR_OK) return HR_ERR_NOMEM;
  hr_cluster_pull(s);
  return HR_OK;
}

int64_t hr_cluster_links(const hr_solver *s) { return s->cl ? s->cl->nlinks : 0; }
void hr_cluster_recv_counts(const hr_solver *s, int64_t *recv) {
  for (int64_t i = 0; s->cl && i < s->cl->nlinks; i++)
    if (s->cl->links[i].r >= 0) recv[s->cl->links[i].r]++;
}
int hr_cluster_graph(const hr_solver *s, hr_cluster_node *out, uint64_t *above) {
  const hr_clusters *cl = s->cl;
  if (!cl) return 0;
  int64_t *recv = calloc((size_t)cl->n + 1, sizeof *recv);
  if (!recv) return -1;
  for (int64_t i = 0; i < cl->nlinks; i++)
    if (cl->links[i].r < 0) recv[-1 - cl->links[i].r]++;
  for (int32_t c = 0; c < cl->n; c++) out[c].parent = 0;
  for (int32_t c = 0; c < cl->n; c++) {
    const cnode *nd = &cl->node[c];
    out[c].gid = node_gid(s, -1 - c);
    out[c].mine = node_owner(s, -1 - c) == s->rank;
    out[c].recv = recv[c];
    out[c].rays = cl->crays[c];
    out[c].xyz[0] = nd->c.x, out[c].xyz[1] = nd->c.y, out[c].xyz[2] = nd->c.z;
    for (int k = 0; k < 2; k++) {
      const int32_t ch = nd->child[k];
      if (ch < 0) out[-1 - ch].parent = out[c].gid;
      else above[ch] = out[c].gid;
    }
  }
  free(recv);
  return 1;
}

int64_t hr_cluster_elem_sources(const hr_solver *s, uint64_t (*e)[2]) {
  int64_t m = 0;
  for (int64_t i = 0; s->cl && i < s->cl->nlinks; i++) {
    const clink *l = &s->cl->links[i];
    if (l->r < 0 && l->s >= 0) e[m][0] = node_gid(s, l->r), e[m++][1] = node_gid(s, l->s);
  }
  return m;
}

size_t hr_cluster_link_bytes(const hr_solver *s) {
  (void)s;
  return sizeof(clink) + sizeof(int64_t);
}
int64_t hr_cluster_count(const hr_solver *s) { return s->cl ? s->cl->n : 0; }

void hr_cluster_free(hr_clusters **pc) {
  hr_clusters *cl = *pc;
  if (!cl) return;
  free(cl->node), free(cl->perm), free(cl->cum), free(cl->sp), free(cl->srad), free(cl->nsh);
  free(cl->sg), free(cl->sh);
  free(cl->rho), free(cl->slack);
  free(cl->Bm), free(cl->bhi), free(cl->blo), free(cl->bref), free(cl->L), free(cl->tq);
  free(cl->nsht), free(cl->lray), free(cl->links);
  free(cl->pos), free(cl->crays), free(cl->cown);
  free(cl);
  *pc = NULL;
}
