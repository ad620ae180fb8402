/* link.c: the link graph. Initial linking of every pair of mutually facing surfaces with a
 * shaft-culled candidate blocker list (paper 2.2.1, step {1} of Figure 3) and refinement of links
 * (paper 2.2.2, steps {7..13}) by an error oracle relative to each receiver's light (link_err;
 * docs/design.md, "The refinement oracle"). A link's form factor comes from the kernels of ff.c
 * and visfrac.c, which see element geometry only.
 *
 * Refinement runs in rounds so that it is parallel and independent of scheduling: in a round
 * every active link decides (keep / split receiver / split source) from the current state only;
 * the elements to split are subdivided in link order; then each split link writes its four
 * children into slots fixed by a prefix sum. Children inherit their parent's candidate list and
 * shrink it to their own shaft; links whose elements face away get F = 0. The children become the
 * next round's active links, until no link splits. */
#include "mpi/dist.h"
#include "cluster.h"
#include "partition/partition.h"
#include "solver_impl.h"
#include "vec.h"

#include <assert.h>
#include <omp.h>
#include <stdlib.h>
#include <math.h>
#include <string.h>

/* ncand of a link whose candidate list has not been built yet (initial links). With clustering
 * no element link gets a list: their rays go through the scene's BVH (Embree) as the cluster
 * links' do. The lists' pool, each split link reserving four times its list for its children,
 * grew to 4.5 GB on the conference room with fine sources (8.0 GB peak; without lists 2.1 GB,
 * and 148 s instead of 204 s; without fine sources 3.2 -> 1.6 GB, 134 -> 119 s). */
#define NO_LIST (-1)

/* ---------------------------------------------------------------- growable arrays */

static int links_reserve(hr_solver *s, int64_t need) {
  if (need <= s->cap_links) return 1;
  int64_t nc = s->cap_links ? s->cap_links : 1024;
  while (nc < need) nc *= 2;
  hr_link *l = realloc(s->links, (size_t)nc * sizeof *l);
  if (!l) return 0;
  s->links = l;
  s->cap_links = nc;
  return 1;
}

/* The candidate pool is addressed by 32-bit offsets (hr_link.cand_off). */
#define POOL_MAX ((int64_t)UINT32_MAX)

static int pool_reserve(int32_t **pool, int64_t *cap, int64_t need) {
  if (need > POOL_MAX) return 0; /* the caller tells this from out of memory (pool_too_big) */
  if (need <= *cap) return 1;
  int64_t nc = *cap ? *cap : 1024;
  while (nc < need) nc *= 2;
  int32_t *p = realloc(*pool, (size_t)nc * sizeof *p);
  if (!p) return 0;
  *pool = p;
  *cap = nc;
  return 1;
}

/* ---------------------------------------------------------------- link evaluation */

/* Rays for the visible fraction of a pair (docs/design.md, "Rays per link"). */
static int pair_rays(const hr_solver *s) { return s->opt.rays; }

/* Rays of the decision set (see STREAM_DECIDE) in refinement: half the estimate's. (4 lost
 * Cornell's partly visible pairs; 8 decided as well as 16 at half the cost.) */
static int decide_rays(const hr_solver *s) { return s->opt.rays > 1 ? s->opt.rays / 2 : 1; }

static hr_vf_elem vf_elem(const hr_solver *s, int32_t idx, const hr_ff_elem *g) {
  return (hr_vf_elem){g, s->el[idx].gid, s->el[idx].surf};
}

/* 1 if some corner of 'b' lies in front of the plane of 'a' (by more than a relative
 * tolerance). */
static int elem_in_front(const hr_ff_elem *a, const hr_ff_elem *b) {
  double size = sqrt(a->area + b->area);
  for (int k = 0; k < b->nv; k++)
    if (v3_dot(v3_sub(b->p[k], a->p[0]), a->n) > 1e-9 * size) return 1;
  return 0;
}

/* Upper bound of the form factor from receiver r to source j with the cosines bounded by 1:
 * the refinement oracle's measure for links whose quadrature found nothing although parts of
 * the elements face each other. */
static hr_vec3 corner_mean(const hr_ff_elem *e) {
  hr_vec3 c = {0, 0, 0};
  for (int k = 0; k < e->nv; k++) c = v3_add(c, e->p[k]);
  return v3_scale(c, 1.0 / e->nv);
}

static double ff_bound(const hr_ff_elem *r, const hr_ff_elem *j) {
  const hr_vec3 d = v3_sub(corner_mean(j), corner_mean(r));
  return j->area / (M_PI * v3_dot(d, d) + j->area);
}

/* Upper bound of the form factor from r to j, cosines bounded by 1 and the distance by the gap
 * between the bounding spheres of the two elements (1 where they overlap). */
static double ff_bound_near(const hr_ff_elem *r, const hr_ff_elem *j) {
  const hr_vec3 cr = corner_mean(r), cj = corner_mean(j);
  double rr = 0, rj = 0;
  for (int k = 0; k < r->nv; k++) rr = fmax(rr, v3_len(v3_sub(r->p[k], cr)));
  for (int k = 0; k < j->nv; k++) rj = fmax(rj, v3_len(v3_sub(j->p[k], cj)));
  const double d = fmax(0, v3_len(v3_sub(cj, cr)) - rr - rj);
  return j->area / (M_PI * d * d + j->area);
}

/* The oracle's receiver measure of a link (fu: unoccluded form factor, spread: its variation
 * over the receiver, hd: visible fraction from the decision samples):
 *  - the spread of the point form factor over the receiver;
 *  - the whole fu where the decision samples found a shadow boundary (0 < hd < 1): visibility
 *    then varies over the receiver, which refinement resolves;
 *  - a bound where the quadrature saw nothing of a source that parts of the receiver face. */
static double link_df(const hr_ff_elem *r, const hr_ff_elem *j, double fu, double spread,
                      double hd) {
  double df = spread;
  if (hd > 0 && hd < 1 && fu > df) df = fu;
  if (fu == 0 && hd > 0) {
    double b = ff_bound(r, j);
    df = b > df ? b : df;
  }
  return df;
}

/* The oracle's source measure of a link: how much its light depends on where on the source it
 * comes from, fu times hr_ff_source_weight, or the whole fu across a shadow boundary (visibility
 * then weights parts of the source differently). A link takes its source's mean radiosity;
 * where that radiosity varies (the floor around a block standing on it is lit, the part in the
 * block's shadow dark), this measure times the variation bounds the error the link makes. */
static double link_ds(const hr_ff_elem *r, const hr_ff_elem *j, double fu, double hd) {
  double ds = fu * hr_ff_source_weight(r, j);
  if (hd > 0 && hd < 1 && fu > ds) ds = fu;
  return ds;
}

/* Two independent sets of visibility samples per link: refinement decides on one whether the
 * visibility is settled, and the form factor rests on the other. Deciding and estimating with
 * the same samples biases the light through partly visible gaps: a link whose samples all
 * happen to agree stops refining with H = 0 or 1, while its siblings go on (measured on the
 * Cornell box: parts of the floor's penumbra 5-18% too bright). */
enum { STREAM_ESTIMATE = 0, STREAM_DECIDE = 1 };

/* The form factor from the smaller of elements r and j to the larger, from fu (r to j). */
static double f_small(const hr_ff_elem *r, const hr_ff_elem *j, double fu) {
  return r->area <= j->area ? fu : fu * r->area / j->area;
}

/* The visible fraction of pair (a, b) from k samples of 'stream': with rays drawn by the kernel
 * where they land often enough (fs, the form factor from the smaller element to the larger, at
 * least HR_VF_LAND_MIN: near pairs), else weighted by it (visfrac.h). It goes with fine sources
 * (alone, the right share of a source's mean made small faces in front of it worse: office 2.9%
 * -> 3.6%, hall:2 clustered 12.2% -> 15.1%). */
static double pair_h(const hr_solver *s, hr_vf_elem a, hr_vf_elem b, const int32_t *cand,
                     int ncand, int k, int stream, double fs, hr_blockers *blk, int64_t *rays) {
  if (fs >= HR_VF_LAND_MIN)
    return hr_vf_pair_land(&s->vf, a, b, cand, ncand, k, stream, blk, rays);
  return hr_vf_pair(&s->vf, a, b, cand, ncand, k, stream, blk, rays);
}

/* The estimate set's visible fraction when the decision set gave 'hd' (k rays). */
static double estimate_h(const hr_solver *s, hr_vf_elem a, hr_vf_elem b, const int32_t *cand,
                         int ncand, int k, double hd, double fs, hr_blockers *blk, int64_t *rays) {
  if (ncand == 0) return hd;
  return pair_h(s, a, b, cand, ncand, k, STREAM_ESTIMATE, fs, blk, rays);
}

/* Source shares (hr_link.w): how the light of a link from source j into receiver r divides
 * among j's four children, from the exact kernel at r's centre. Only for links that all their
 * decision samples see ('visible'): where a shadow crosses, the shares would depend on
 * visibility, and the source term refines the link instead. A link with shares gathers the
 * children's radiosities once they exist, so a source need not be split for its links to see
 * how its radiosity varies at the next level (Cornell box, BF_low 1e-3: 0.43% -> 0.30% with a
 * quarter fewer links; 3e-4: 0.25% -> 0.16%). */
static void source_shares(const hr_ff_elem *r, const hr_ff_elem *j, int visible, float w[4]) {
  if (visible) {
    hr_ff_pair_shares(r, j, 1, w);
  } else {
    for (int q = 0; q < 4; q++) w[q] = -1;
  }
}

/* F of a link whose estimate is left for later (link_eval). */
#define F_LATER (-1.0f)

/* Fills F, Fu, dF and dS of link 'l', a refinement's child (receiver, source and candidate list
 * already set). A link whose estimate would cast rays gets none yet: F is F_LATER until
 * link_estimate, which refinement calls once a round keeps the link. The estimate's samples are
 * keyed by the pair's gids, so its value does not depend on when it is drawn. */
static void link_eval(const hr_solver *s, const int32_t *pool, hr_link *l, int64_t *rays) {
  const hr_ff_elem gr = hr_elem_geom(s, &s->el[l->r]), gj = hr_elem_geom(s, &s->el[l->s]);
  double spread, fu = hr_ff_pair(&gr, &gj, 0, &spread), hd = 0, he = 0;
  const int k = pair_rays(s), kd = decide_rays(s), nc = l->ncand;
  int defer = 0;
  if (fu > 0 || (elem_in_front(&gr, &gj) && elem_in_front(&gj, &gr))) {
    const hr_vf_elem a = vf_elem(s, l->r, &gr), b = vf_elem(s, l->s, &gj);
    const double fs = f_small(&gr, &gj, fu);
    hd = pair_h(s, a, b, pool + l->cand_off, nc, kd, STREAM_DECIDE, fs, NULL, rays);
    defer = nc != 0;
    if (!defer) he = estimate_h(s, a, b, pool + l->cand_off, nc, k, hd, fs, NULL, rays);
  }
  source_shares(&gr, &gj, nc == 0 || hd == 1, l->w);
  l->Fu = (float)fu;
  l->F = defer ? F_LATER : (float)(fu * he);
  l->dF = (float)link_df(&gr, &gj, fu, spread, hd);
  l->dS = (float)link_ds(&gr, &gj, fu, hd);
}

/* The estimate link_eval left for later: F, bit for bit what link_eval would have set (the
 * unoccluded form factor computed again: a link carries it only as a float). */
static void link_estimate(const hr_solver *s, const int32_t *pool, hr_link *l, int64_t *rays) {
  assert(l->F == F_LATER && l->ncand != 0);
  const hr_ff_elem gr = hr_elem_geom(s, &s->el[l->r]), gj = hr_elem_geom(s, &s->el[l->s]);
  const double fu = hr_ff_pair(&gr, &gj, 0, NULL);
  const hr_vf_elem a = vf_elem(s, l->r, &gr), b = vf_elem(s, l->s, &gj);
  const double he = pair_h(s, a, b, pool + l->cand_off, l->ncand, pair_rays(s), STREAM_ESTIMATE,
                           f_small(&gr, &gj, fu), NULL, rays);
  l->F = (float)(fu * he);
}

/* Fine sources. An input polygon that cannot be split (at most A_e) close to a larger leaf sees
 * the part of that leaf next to it, whose radiosity may differ from the leaf's mean: in `office`
 * a desk leg 4 cm from a wall sees the wall in the shadow of the leg and of the desk top, and a
 * book 4 cm from the bookshelf's side the strip of the side next to it; with the leaf's mean
 * they came out 40-85% too bright. The link then measures the leaf's own variation (a leaf's
 * bvar: the spread of the light its links bring, pushpull.c) with its source term and may split
 * it below A_e: 1 for element j (the link's source or one of its children) when the receiver is
 * an input polygon of at most A_e, the link is near (the form factor from the smaller element to
 * the larger at least HR_VF_LAND_MIN), and j is larger than A_e / 16 and than an eighth of the
 * part of it the receiver sees. The links into a split leaf then refine to its children as any
 * links do (hr_elem_splittable). */
static double longest_side(const hr_elem *e) {
  double m = 0; /* a triangle's p[3] is its p[2]: its fourth side is its third */
  for (int k = 0; k < 4; k++) m = fmax(m, v3_len(v3_sub(e->p[(k + 1) & 3], e->p[k])));
  return m;
}

static int fine_source(const hr_solver *s, const hr_link *l, int32_t j) {
  const hr_elem *r = &s->el[l->r], *e = &s->el[j];
  if (r->parent >= 0 || r->area > s->area_min || e->area <= s->area_min / 1024 ||
      e->depth >= HR_GID_DEPTH)
    return 0;
  /* the part of the source the receiver sees, about its size plus twice its distance squared:
   * the source splits while it is larger than an eighth of that. A sliver that touches the
   * source (closer to its plane than its width w, the area over its longest side) sees a strip
   * about as wide as itself, not as its square root: its size is scaled by q = 2 w / sqrt(A),
   * and the source may split to A_e / 16 times q^2, to A_e / 1024 at most (docs/design.md,
   * "Fine sources"). */
  const double d = fabs(v3_dot(v3_sub(r->c, e->p[0]), s->scene->surfs[e->surf].normal));
  const double w = r->area / longest_side(r), wr = sqrt(r->area);
  const double q = d < w ? fmin(1, 2 * w / wr) : 1;
  if (e->area <= s->area_min / 16 * fmax(q * q, 1.0 / 64)) return 0;
  const double fp = q * wr + 2 * d;
  if (e->area <= 0.125 * fp * fp) return 0;
  const double as = s->el[l->s].area;
  return l->Fu * r->area / (r->area < as ? r->area : as) >= HR_VF_LAND_MIN;
}

/* The variation of element j's radiosity that link l does not see: its leaves' spread, or, for a
 * leaf, its own variation where it is a fine source (stored negated, pushpull.c). */
static double var_of(const hr_solver *s, const hr_link *l, int32_t j) {
  const double v = s->bvar[j];
  return v >= 0 ? v : fine_source(s, l, j) ? -v : 0;
}

/* The variation of the source's radiosity that a link does not see: within its children where
 * it gathers them by shares, else within the source. */
static double source_var(const hr_solver *s, const hr_link *l) {
  const int32_t c = s->el[l->s].child;
  if (c < 0 || !(l->w[0] >= 0)) return var_of(s, l, l->s);
  double v = 0;
  for (int k = 0; k < 4; k++) {
    const double x = var_of(s, l, c + k);
    v = x > v ? x : v;
  }
  return v;
}

/* Refinement oracle (paper 2.2.2: a link whose "BF" is too strong is refined), measured
 * relative to the receiver, in its two parts:
 *  - receiver error: the largest variation over the receiver, in any channel, of the radiosity
 *    the link brings, rho_i B_j dF;
 *  - source error: rho_i dS times the variation of the source's radiosity over its leaves;
 * each over the receiver's reference radiosity bref (its reflected radiosity, at least a
 * fraction of the scene's mean radiosity). */
static void link_err(const hr_solver *s, const hr_link *l, double *er, double *es) {
  const double *rho = s->rho[l->r], *b = s->Bs[l->s];
  double m = 0;
  for (int c = 0; c < 3; c++) {
    double e = rho[c] * b[c];
    m = e > m ? e : m;
  }
  const double inv = 1.0 / s->bref[l->r];
  *er = m * l->dF * inv;
  *es = s->rho_max[l->r] * source_var(s, l) * l->dS * inv;
}

/* ---------------------------------------------------------------- initial linking */

typedef struct row {
  hr_link *links;
  int nlinks, cap;
  int64_t rays;
  int err;
} row;

/* Facing pairs (i, j[q]) of one row of initial linking waiting for their visible fraction. */
typedef struct pending {
  int n, segs;
  int j[HR_VF_BATCH_PAIRS], k[HR_VF_BATCH_PAIRS];
  double fs[HR_VF_BATCH_PAIRS]; /* f_small of near pairs (pair_h), else 0 */
  hr_ff_elem g[HR_VF_BATCH_PAIRS];
} pending;

/* Appends the two links of pair (i, j) to the row; 0 when out of memory. */
static int row_push(row *rw, hr_link lij, hr_link lji) {
  if (rw->nlinks + 2 > rw->cap) {
    int nc = rw->cap ? rw->cap * 2 : 16;
    hr_link *l = realloc(rw->links, (size_t)nc * sizeof *l);
    if (!l) {
      rw->err = 1;
      return 0;
    }
    rw->links = l;
    rw->cap = nc;
  }
  rw->links[rw->nlinks++] = lij;
  rw->links[rw->nlinks++] = lji;
  return 1;
}

/* A link r <- j before any refinement, from the pair's decision and estimated visible
 * fractions h and he: its form factors, the oracle's measures and source shares, no candidate
 * list yet. */
static hr_link link_of(int32_t r, int32_t j, const hr_ff_elem *gr, const hr_ff_elem *gj,
                       double f, double sp, double h, double he) {
  hr_link l = {.r = r, .s = j, .F = (float)(f * he), .Fu = (float)f,
               .dF = (float)link_df(gr, gj, f, sp, h), .dS = (float)link_ds(gr, gj, f, h),
               .cand_off = 0, .ncand = NO_LIST};
  source_shares(gr, gj, h == 1, l.w);
  return l;
}

static hr_link first_link(int32_t r, int32_t j, const hr_ff_elem *gr, const hr_ff_elem *gj,
                          double h, double he) {
  double sp;
  const double f = hr_ff_pair(gr, gj, 0, &sp);
  return link_of(r, j, gr, gj, f, sp, h, he);
}

/* Initial pairs all of whose k decision samples are blocked. That leaves a visible fraction
 * below about 3/k (95%), and a pair dropped here loses its light for good: in `office` a book's
 * side 6 cm from the bookshelf's side had no link to it (its 16 samples on the 1.9 m tall side
 * all fell above the shelf over the book or on the plinth), and 25-86% of what the faces inside
 * the shelf see had no link. Where the light that may be lost, the form factor times 3/n times
 * the source's emission over the radiosity unit (1 for surfaces that do not emit), could exceed
 * BF_low of what the receiver gets, more samples are drawn, doubling, each round with samples
 * of its own, until one sees through or the bound falls below BF_low (at most RECHECK_MAX). A
 * cheap bound of the form factor (cosines 1) settles most hidden pairs of a large scene without
 * quadrature. */
#define RECHECK_MAX 4096
enum { STREAM_RECHECK = 2 }; /* and up: one stream per round */

/* What the light from surface 'j' weighs against the radiosity unit: its emission (largest
 * channel) over the unit, at least 1. */
static double source_weight(const hr_solver *s, int j) {
  const double *e = s->scene->mats[s->scene->surfs[j].material].emit;
  double m = e[0] > e[1] ? e[0] : e[1];
  m = (m > e[2] ? m : e[2]) / s->unit;
  return m > 1 ? m : 1;
}

/* Samples still needed for the pair (i, j) with potential 'pot' (largest form factor times
 * source weight) after n blocked samples: 0 once 3 pot / n <= BF_low. */
static int recheck_more(const hr_solver *s, double pot, int n) {
  return n < RECHECK_MAX && 3 * pot > s->opt.bf_low * n;
}

/* The decision H of an initial pair whose k samples were all blocked: 0 when it stays hidden,
 * else the visible fraction of the round that saw through, with that round's sample count in
 * '*kout' (the estimate then takes as many). */
static double recheck(const hr_solver *s, hr_vf_elem ei, hr_vf_elem ej, int k, double fs,
                      hr_blockers *blk, int64_t *rays, int *kout) {
  const double wi = source_weight(s, ei.surf), wj = source_weight(s, ej.surf);
  double pot = ff_bound_near(ei.g, ej.g) * wj, pr = ff_bound_near(ej.g, ei.g) * wi;
  if (!recheck_more(s, pot > pr ? pot : pr, k)) return 0;
  pot = hr_ff_pair(ei.g, ej.g, 0, NULL) * wj;
  pr = hr_ff_pair(ej.g, ei.g, 0, NULL) * wi;
  pot = pot > pr ? pot : pr;
  for (int n = k, round = 0; recheck_more(s, pot, n); n *= 2, round++) {
    const double h = pair_h(s, ei, ej, NULL, -1, n, STREAM_RECHECK + round, fs, blk, rays);
    if (h > 0) {
      *kout = n;
      return h;
    }
  }
  return 0;
}

/* Computes H for the pending pairs of row i (batched where every sample counts, the rest one
 * by one), appends the links of the visible ones in pair order and empties 'pd'. Returns 0 when
 * out of memory.
 *
 * The k segments of a pair are cast against the whole scene: most pairs of a large scene are
 * hidden from each other, and most initial links are never refined, so a candidate list is
 * built only when a link first splits (see hr_link_refine). A pair all of whose k segments are
 * blocked is taken as mutually invisible unless it could carry light enough to recheck. */
static int init_flush(const hr_solver *s, int i, const hr_ff_elem *gi, pending *pd,
                      hr_blockers *blk, row *rw) {
  hr_vf_elem bs[HR_VF_BATCH_PAIRS] = {{NULL, 0, 0}};
  int kb[HR_VF_BATCH_PAIRS] = {0}, qb[HR_VF_BATCH_PAIRS], nb = 0;
  double hb[HR_VF_BATCH_PAIRS], h[HR_VF_BATCH_PAIRS];
  const hr_vf_elem ei = vf_elem(s, i, gi);
  for (int q = 0; q < pd->n; q++)
    if (pd->k[q] <= HR_VF_BATCH_SEGS && pd->fs[q] == 0) {
      bs[nb] = vf_elem(s, pd->j[q], &pd->g[q]);
      kb[nb] = pd->k[q];
      qb[nb++] = q;
    }
  hr_vf_batch(&s->vf, ei, bs, kb, nb, STREAM_DECIDE, blk, &rw->rays, hb);
  for (int q = 0; q < pd->n; q++) h[q] = -1;
  for (int r = 0; r < nb; r++) h[qb[r]] = hb[r];
  for (int q = 0; q < pd->n; q++) {
    int j = pd->j[q];
    const hr_ff_elem *gj = &pd->g[q];
    const hr_vf_elem ej = vf_elem(s, j, gj);
    const double fs = pd->fs[q];
    if (h[q] < 0) h[q] = pair_h(s, ei, ej, NULL, -1, pd->k[q], STREAM_DECIDE, fs, blk, &rw->rays);
    int ke = pair_rays(s);
    if (h[q] == 0) h[q] = recheck(s, ei, ej, pd->k[q], fs, blk, &rw->rays, &ke);
    if (h[q] == 0) continue;
    const double he = estimate_h(s, ei, ej, NULL, -1, ke, h[q], fs, blk, &rw->rays);
    /* The form factors only now: most facing pairs of a large scene are hidden (museum: 8.2 M
     * of 9.2 M), and their quadrature would be wasted. */
    if (!row_push(rw, first_link(i, j, gi, gj, h[q], he), first_link(j, i, gj, gi, h[q], he)))
      return 0;
  }
  pd->n = pd->segs = 0;
  return 1;
}

/* f_small of pair (i, j) where it may reach HR_VF_LAND_MIN (the quadrature only then), else 0;
 * the pair's form factor and spread in *f and *sp where computed (*f = -1 otherwise). */
static double near_fs(const hr_ff_elem *gi, const hr_ff_elem *gj, double *f, double *sp) {
  *f = -1; /* not computed: the pair is far */
  const int si = gi->area <= gj->area;
  if (ff_bound_near(si ? gi : gj, si ? gj : gi) < HR_VF_LAND_MIN) return 0;
  *f = hr_ff_pair(gi, gj, 0, sp);
  const double fs = f_small(gi, gj, *f);
  return fs >= HR_VF_LAND_MIN ? fs : 0;
}

/* Initial linking of row i: surface i against every later surface that faces it. */
static void init_row(const hr_solver *s, int i, row *rw) {
  const hr_scene *sc = s->scene;
  const hr_ff_elem gi = hr_elem_geom(s, &s->el[i]);
  hr_blockers blk;
  hr_blockers_clear(&blk);
  pending pd;
  pd.n = pd.segs = 0;
  const int P = hr_dist_size(s->dist);
  for (int j = i + 1; j < sc->nsurfs; j++) {
    /* distributed: pair (i, j) is evaluated by rank (i + j) mod P, an even spread of the
     * O(n^2) pairs (paper 2.2.1); its two links then go to their receivers' owners */
    if (P > 1 && (i + j) % P != s->rank) continue;
    const hr_ff_elem gj = hr_elem_geom(s, &s->el[j]);
    if (!elem_in_front(&gi, &gj) || !elem_in_front(&gj, &gi)) continue;
    /* Initial pairs whose decision samples are all blocked get no link at all: they decide with
     * the full k, since a partly visible pair dropped here loses its light for good. */
    int k = pair_rays(s);
    if (pd.n == HR_VF_BATCH_PAIRS || pd.segs + k > HR_VF_BATCH_SEGS) {
      if (!init_flush(s, i, &gi, &pd, &blk, rw)) return;
    }
    int q = pd.n++;
    pd.j[q] = j, pd.k[q] = k, pd.g[q] = gj;
    double f, sp;
    pd.fs[q] = near_fs(&gi, &gj, &f, &sp);
    pd.segs += k;
  }
  init_flush(s, i, &gi, &pd, &blk, rw);
}

/* The element link i <- j as initial linking makes it (clustering, cluster.c): 1 with *out
 * filled when the pair faces each other and some decision sample sees through, else 0. */
int hr_link_pair(const hr_solver *s, int32_t i, int32_t j, hr_link *out, int64_t *rays) {
  const hr_ff_elem gi = hr_elem_geom(s, &s->el[i]), gj = hr_elem_geom(s, &s->el[j]);
  if (!elem_in_front(&gi, &gj) || !elem_in_front(&gj, &gi)) return 0;
  const hr_vf_elem ei = vf_elem(s, i, &gi), ej = vf_elem(s, j, &gj);
  double f, sp = 0; /* the pair's form factor where near_fs computed it (f >= 0) */
  const double fs = near_fs(&gi, &gj, &f, &sp);
  const double h = pair_h(s, ei, ej, NULL, -1, pair_rays(s), STREAM_DECIDE, fs, NULL, rays);
  if (h == 0) return 0;
  if (f < 0) f = hr_ff_pair(&gi, &gj, 0, &sp);
  /* A pair that cannot refine (neither element splits, now or as a fine source) takes its
   * visible fraction from the decision samples: the second set guards decisions, and none
   * depends on these samples but whether the link is made, which keeps the mean unbiased
   * (E[h; h > 0] = E[h]; independent samples lose the light of the pairs dropped). Half the
   * rays of such pairs: the conference room 571 M -> 510 M rays, 4.76% -> 4.74% error. */
  *out = link_of(i, j, &gi, &gj, f, sp, h, h);
  if (hr_elem_splittable(s, &s->el[i]) || hr_elem_splittable(s, &s->el[j]) ||
      fine_source(s, out, j)) {
    const double he = estimate_h(s, ei, ej, NULL, -1, pair_rays(s), h, fs, NULL, rays);
    out->F = (float)(f * he);
  }
  return 1;
}

/* Distributed initial linking: every link goes to the rank that owns its receiver's surface
 * (receivers are roots here: element idx == surface). Links keep their order within each
 * sender; the order does not matter (hr_link_sort orders each receiver's links by source gid). */
static hr_status send_to_owners(hr_solver *s, hr_status st, hr_err *err) {
  if (st != HR_OK) return st;
  const int P = hr_dist_size(s->dist);
  int64_t *cnt = calloc((size_t)P, sizeof *cnt);
  hr_link *out = malloc((size_t)(s->nlinks > 0 ? s->nlinks : 1) * sizeof *out);
  int64_t *at = calloc((size_t)P + 1, sizeof *at);
  st = cnt && out && at ? HR_OK : hr_err_set(err, HR_ERR_NOMEM, "out of memory");
  if (hr_test_fail(s, HR_PHASE_INIT))
    st = hr_err_set(err, HR_ERR_NOMEM, "out of memory (injected by HRAD_TEST_FAIL)");
  if ((st = hr_dist_agree(s, st, err)) != HR_OK) {
    free(cnt), free(out), free(at);
    return st;
  }
  for (int64_t k = 0; k < s->nlinks; k++) cnt[s->eown[s->links[k].r]]++;
  for (int p = 0; p < P; p++) at[p + 1] = at[p] + cnt[p];
  for (int64_t k = 0; k < s->nlinks; k++) out[at[s->eown[s->links[k].r]]++] = s->links[k];
  for (int p = 0; p < P; p++) cnt[p] *= (int64_t)sizeof *out;
  void *recv = NULL;
  int64_t tot = 0;
  st = hr_dist_alltoall(s->dist, out, cnt, &recv, &tot);
  free(cnt), free(out), free(at);
  if (st != HR_OK) return hr_err_set(err, st, "out of memory in initial linking");
  free(s->links);
  s->links = recv;
  s->nlinks = s->cap_links = tot / (int64_t)sizeof(hr_link);
  return HR_OK;
}

/* Graph balancing's start in an unclustered run (as spread_by_hierarchy in cluster.c for a
 * clustered one): whole surfaces, by recursive bisection of their centroids weighted by area,
 * so that each rank's surfaces are a compact piece of the scene. The balancing's cut then joins
 * neighbouring surfaces into pieces (hr_partition_tree_cut_near): with surfaces by area,
 * largest first, scattered over the scene, museum's final graph at 64 ranks made 4,302 pieces
 * and the annealing took 93 ms a chain; from this start 814 and 23 ms, and a lower Z
 * (BENCHMARKS.md, "Graph balancing, sixth pass"). 0 when out of memory. */
static int spread_by_space(hr_solver *s) {
  const int n = s->scene->nsurfs;
  double *xyz = malloc((size_t)(3 * n + 1) * sizeof *xyz);
  double *w = malloc((size_t)(n + 1) * sizeof *w);
  const int ok = xyz && w;
  for (int i = 0; ok && i < n; i++) { /* element i is surface i's root */
    const hr_elem *r = &s->el[i];
    w[i] = r->area;
    xyz[3 * i] = r->c.x, xyz[3 * i + 1] = r->c.y, xyz[3 * i + 2] = r->c.z;
  }
  const int done = ok && hr_partition_orb(xyz, w, n, s->nranks, s->rootown);
  free(xyz), free(w);
  if (done) hr_owners_recompute(s);
  return done;
}

hr_status hr_link_init(hr_solver *s, hr_err *err) {
  const hr_scene *sc = s->scene;
  int n = sc->nsurfs;
  double pairs = 0.5 * (double)n * (double)(n - 1);
  if (hr_cluster_wanted(&s->opt, n)) {
    hr_status st = hr_cluster_init(s, err);
    s->initial_links = s->nlinks + hr_cluster_links(s);
    return st;
  }
  if (s->opt.max_links > 0 && pairs > s->opt.max_links)
    return hr_err_set(err, HR_ERR_TOO_BIG,
                      "%d surfaces make %.3g surface pairs for initial linking, above the limit "
                      "of %.3g (--max-pairs) with --cluster off",
                      n, pairs, s->opt.max_links);
  if (hr_start_compact(s) && hr_dist_any(s->dist, !spread_by_space(s)))
    return hr_err_set(err, HR_ERR_NOMEM, "out of memory");
  row *rows = calloc((size_t)n, sizeof *rows);
  if (!rows) return hr_err_set(err, HR_ERR_NOMEM, "out of memory in initial linking");
  /* Progress (HR_PHASE_LINK): row i holds the n-1-i pairs (i, j > i); the calling thread (the
   * team's thread 0) reports the share of pairs done, at most every 0.1 s. */
  int64_t pairs_done = 0;
  double t_report = hr_now();
#pragma omp parallel for schedule(dynamic, 4) if (n > 16) num_threads(s->threads)
  for (int i = 0; i < n; i++) {
    init_row(s, i, &rows[i]);
    int64_t d;
#pragma omp atomic capture
    d = pairs_done += n - 1 - i;
    if (omp_get_thread_num() == 0 && hr_now() - t_report >= 0.1) {
      t_report = hr_now();
      hr_solver_progress_report(s, HR_PHASE_LINK, pairs > 0 ? (double)d / pairs : 1);
    }
  }
  hr_solver_progress_report(s, HR_PHASE_LINK, 1);
  int64_t nl = 0;
  int failed = 0;
  for (int i = 0; i < n; i++) {
    failed |= rows[i].err;
    nl += rows[i].nlinks;
    s->rays += rows[i].rays;
  }
  hr_status st = HR_OK;
  if (failed || !links_reserve(s, nl)) {
    st = hr_err_set(err, HR_ERR_NOMEM, "out of memory in initial linking");
  } else {
    int64_t ol = 0;
    for (int i = 0; i < n; i++) {
      if (rows[i].nlinks > 0)
        memcpy(s->links + ol, rows[i].links, (size_t)rows[i].nlinks * sizeof(hr_link));
      ol += rows[i].nlinks;
    }
    s->nlinks = nl;
  }
  for (int i = 0; i < n; i++) free(rows[i].links);
  free(rows);
  if (s->dist) st = send_to_owners(s, hr_dist_agree(s, st, err), err);
  s->initial_links = s->nlinks;
  return st;
}

/* ---------------------------------------------------------------- refinement */

enum { KEEP = 0, SPLIT_R = 1, SPLIT_S = 2 };

/* Element polygon (world corners) for shaft filtering. */
static int elem_poly(const hr_solver *s, const hr_elem *e, hr_vec3 *p) {
  int n = s->scene->surfs[e->surf].nverts;
  for (int k = 0; k < n; k++) p[k] = e->p[k];
  return n;
}

/* Keep the link, or split its receiver or its source: the side whose error is larger (the
 * receiver's for a tie), or the other side when that one cannot be split. */
static uint8_t decide(const hr_solver *s, const hr_link *l, double bf_e) {
  if (l->Fu < 0) return KEEP; /* dead: refined away */
  double er, es;
  link_err(s, l, &er, &es);
  if (er <= bf_e && es <= bf_e) return KEEP;
  const hr_elem *j = &s->el[l->s];
  const int rs = hr_elem_splittable(s, &s->el[l->r]),
            ss = hr_elem_splittable(s, j) || (j->child < 0 && fine_source(s, l, l->s));
  if (er >= es) return rs ? SPLIT_R : ss && es > bf_e ? SPLIT_S : KEEP;
  return ss ? SPLIT_S : rs && er > bf_e ? SPLIT_R : KEEP;
}

/* Candidates a link carries: none until its list is built (NO_LIST). */
static int32_t ncands(const hr_link *l) { return l->ncand > 0 ? l->ncand : 0; }

/* Builds the candidate lists that splitting links (dec != KEEP) do not have yet (NO_LIST):
 * shaft queries through the BVH in parallel, then appended to the pool in link order. */
static hr_status build_lists(hr_solver *s, hr_link *cur, int64_t ncur, const uint8_t *dec) {
  int64_t nb = 0;
  for (int64_t i = 0; i < ncur; i++) nb += dec[i] != KEEP && cur[i].ncand == NO_LIST;
  if (nb == 0) return HR_OK;
  int64_t *which = malloc((size_t)nb * sizeof *which);
  int32_t **lists = calloc((size_t)nb, sizeof *lists);
  int *lens = calloc((size_t)nb, sizeof *lens);
  int failed = 0;
  if (!which || !lists || !lens) failed = 1;
  if (!failed) {
    int64_t k = 0;
    for (int64_t i = 0; i < ncur; i++)
      if (dec[i] != KEEP && cur[i].ncand == NO_LIST) which[k++] = i;
#pragma omp parallel for schedule(dynamic, 16) reduction(| : failed) \
    if (nb > 64) num_threads(s->threads)
    for (int64_t k2 = 0; k2 < nb; k2++) {
      const hr_link *l = &cur[which[k2]];
      const hr_elem *r = &s->el[l->r], *j = &s->el[l->s];
      hr_vec3 pa[4], pb[4];
      int na = elem_poly(s, r, pa), nbv = elem_poly(s, j, pb), cap = 0;
      failed |= hr_shaft_candidates(s->shaft, pa, na, r->surf, pb, nbv, j->surf, &lists[k2],
                                    &lens[k2], &cap) != HR_OK;
    }
  }
  if (!failed) {
    int64_t tot = 0;
    for (int64_t k = 0; k < nb; k++) tot += lens[k];
    if (!pool_reserve(&s->pool, &s->cap_pool, s->npool + tot))
      failed = 1 + (s->npool + tot > POOL_MAX);
  }
  if (!failed) {
    for (int64_t k = 0; k < nb; k++) {
      hr_link *l = &cur[which[k]];
      l->cand_off = (uint32_t)s->npool;
      l->ncand = lens[k];
      if (lens[k] > 0) memcpy(s->pool + s->npool, lists[k], (size_t)lens[k] * sizeof(int32_t));
      s->npool += lens[k];
    }
  }
  for (int64_t k = 0; lists && k < nb; k++) free(lists[k]);
  free(lists);
  free(lens);
  free(which);
  return failed == 2 ? HR_ERR_TOO_BIG : failed ? HR_ERR_NOMEM : HR_OK;
}

/* ---------------------------------------------------------------- distribution */

/* What a ghost of a source needs (see pushpull.c, msg_store): its Bs and bvar, and its
 * children's when it has some. */
typedef struct src_state {
  uint64_t nchild;
  double Bs[3], bvar;
  double cBs[4][3], cbvar[4];
} src_state;

static void src_state_get(const hr_solver *s, int32_t e, src_state *st) {
  memset(st, 0, sizeof *st);
  memcpy(st->Bs, s->Bs[e], sizeof st->Bs);
  st->bvar = s->bvar[e];
  const int32_t c = s->el[e].child;
  if (c < 0) return;
  st->nchild = 4;
  for (int k = 0; k < 4; k++) {
    memcpy(st->cBs[k], s->Bs[c + k], sizeof st->cBs[k]);
    st->cbvar[k] = s->bvar[c + k];
  }
}

/* Sets element 'e' from 'st', creating its children if it has some; own elements are left
 * alone unless 'force'. 0 when out of memory. */
static int src_state_set(hr_solver *s, int32_t e, const src_state *st, int force) {
  if (hr_owns(s, e) && !force) return 1;
  memcpy(s->Bs[e], st->Bs, sizeof st->Bs);
  s->bvar[e] = st->bvar;
  if (!st->nchild) return 1;
  if (s->el[e].child < 0 && hr_elem_subdivide(s, e) != HR_OK) return 0;
  const int32_t c = s->el[e].child;
  for (int k = 0; k < 4; k++) {
    if (hr_owns(s, c + k)) continue;
    memcpy(s->Bs[c + k], st->cBs[k], sizeof st->cBs[k]);
    s->bvar[c + k] = st->cbvar[k];
  }
  return 1;
}

/* A personalised exchange of fixed-size records: rec[i] (rsize bytes) goes to rank dest[i];
 * '*recv' gets what arrived, '*nrecv' records. A collective; every rank gets the same status
 * ('st' is this rank's so far). */
static hr_status exchange(hr_solver *s, const char *rec, const int32_t *dest, int64_t n,
                          size_t rsize, char **recv, int64_t *nrecv, hr_status st, hr_err *err) {
  const int P = s->nranks;
  *recv = NULL;
  *nrecv = 0;
  int64_t *sb = calloc((size_t)P, sizeof *sb), *at = calloc((size_t)P + 1, sizeof *at);
  char *out = malloc((size_t)n * rsize + 1);
  if (st == HR_OK && (!sb || !at || !out)) st = hr_err_set(err, HR_ERR_NOMEM, "out of memory");
  const int failed = st != HR_OK;
  if (!failed) {
    for (int64_t i = 0; i < n; i++) sb[dest[i]] += (int64_t)rsize;
    for (int p = 0; p < P; p++) at[p + 1] = at[p] + sb[p];
    for (int64_t i = 0; i < n; i++) {
      memcpy(out + at[dest[i]], rec + (size_t)i * rsize, rsize);
      at[dest[i]] += (int64_t)rsize;
    }
  }
  void *r = NULL;
  int64_t tot = 0;
  if (failed && sb) memset(sb, 0, (size_t)P * sizeof *sb);
  /* every rank must take part in the exchange: one without memory for its count table aborts */
  if (!sb) hr_dist_abort(s->dist, 1);
  const hr_status xs = hr_dist_alltoall_st(s->dist, out, sb, failed, &r, &tot);
  free(sb), free(at), free(out);
  if (failed) return st;
  if (xs == HR_ERR_REMOTE) return hr_err_set(err, xs, "stopped: another rank failed");
  if (xs != HR_OK) return hr_err_set(err, xs, "out of memory");
  *recv = r;
  *nrecv = tot / (int64_t)rsize;
  return HR_OK;
}

/* A subscription: rank 'rank' holds a ghost of element 'gid' and wants its stores; the answer
 * is the element's state now. */
typedef struct msg_sub {
  uint64_t gid;
  int64_t rank;
} msg_sub;

typedef struct msg_state {
  uint64_t gid;
  src_state st;
} msg_state;

static int subs_push(hr_solver *s, int32_t e, int32_t rank) {
  if (s->nsubs == s->cap_subs) {
    int64_t nc = s->cap_subs ? 2 * s->cap_subs : 1024;
    int32_t(*sb)[2] = realloc(s->subs, (size_t)nc * sizeof *sb);
    if (!sb) return 0;
    s->subs = sb, s->cap_subs = nc;
  }
  s->subs[s->nsubs][0] = e;
  s->subs[s->nsubs++][1] = rank;
  return 1;
}

/* Applies received element states to the ghosts they name. */
static hr_status apply_states(hr_solver *s, const char *in, int64_t nin, hr_status st,
                              hr_err *err) {
  for (int64_t i = 0; i < nin && st == HR_OK; i++) {
    msg_state m;
    memcpy(&m, in + i * (int64_t)sizeof m, sizeof m);
    const int32_t e = hr_elem_ensure(s, m.gid);
    if (e < 0 || !src_state_set(s, e, &m.st, 0))
      st = hr_err_set(err, HR_ERR_NOMEM, "out of memory (element states)");
  }
  return st;
}

/* Every ghost source of the live links[0, nl) and every ghost elems[0, ne) (sources of cluster
 * links) that this rank has not subscribed to yet subscribes at its owner and gets the owner's
 * state of it now (the paper's "search" and "fetch": a rank decides about a link only with its
 * source's current state, and every later push-pull stores it). A collective; 'st' is this
 * rank's status so far, and every rank returns the same status. */
static hr_status subscribe(hr_solver *s, const hr_link *links, int64_t nl, const int32_t *elems,
                           int64_t ne, hr_status st, hr_err *err) {
  int64_t n = 0, cap = 0;
  msg_sub *rec = NULL;
  int32_t *dest = NULL;
  for (int64_t i = 0; i < nl + ne && st == HR_OK; i++) {
    const int32_t j = i < nl ? links[i].s : elems[i - nl];
    if ((i < nl && links[i].Fu < 0) || hr_owns(s, j) || s->esub[j]) continue;
    if (n == cap) {
      cap = cap ? 2 * cap : 1024;
      msg_sub *r2 = realloc(rec, (size_t)cap * sizeof *r2);
      int32_t *d2 = realloc(dest, (size_t)cap * sizeof *d2);
      if (r2) rec = r2;
      if (d2) dest = d2;
      if (!r2 || !d2) st = HR_ERR_NOMEM;
      if (st != HR_OK) break;
    }
    s->esub[j] = 1;
    rec[n] = (msg_sub){s->el[j].gid, s->rank};
    dest[n++] = s->eown[j];
  }
  char *in = NULL;
  int64_t nin = 0;
  st = exchange(s, (const char *)rec, dest, st == HR_OK ? n : 0, sizeof *rec, &in, &nin, st,
                err);
  free(rec), free(dest);
  if (st != HR_OK) return st;
  msg_state *ans = malloc((size_t)(nin > 0 ? nin : 1) * sizeof *ans);
  int32_t *adest = malloc((size_t)(nin > 0 ? nin : 1) * sizeof *adest);
  if (!ans || !adest) st = hr_err_set(err, HR_ERR_NOMEM, "out of memory (subscriptions)");
  for (int64_t i = 0; i < nin && st == HR_OK; i++) {
    msg_sub m;
    memcpy(&m, in + i * (int64_t)sizeof m, sizeof m);
    const int32_t e = hr_elem_find(s, m.gid);
    if (e < 0 || !hr_owns(s, e)) { /* cannot happen: owners hold what they own */
      st = hr_err_set(err, HR_ERR_INVALID, "internal error: subscription to %llx",
                      (unsigned long long)m.gid);
      break;
    }
    if (!subs_push(s, e, (int32_t)m.rank))
      st = hr_err_set(err, HR_ERR_NOMEM, "out of memory (subscriptions)");
    memset(&ans[i], 0, sizeof ans[i]);
    ans[i].gid = m.gid;
    src_state_get(s, e, &ans[i].st);
    adest[i] = (int32_t)m.rank;
  }
  free(in);
  st = exchange(s, (const char *)ans, adest, st == HR_OK ? nin : 0, sizeof *ans, &in, &nin, st,
                err);
  free(ans), free(adest);
  if (st != HR_OK) return st;
  st = apply_states(s, in, nin, st, err);
  free(in);
  return hr_dist_agree(s, st, err);
}

static hr_status subscribe_range(hr_solver *s, const hr_link *links, int64_t nl, hr_err *err) {
  return subscribe(s, links, nl, NULL, 0, HR_OK, err);
}

hr_status hr_link_subscribe(hr_solver *s, hr_err *err) {
  if (!s->dist) return HR_OK;
  int32_t *cs = NULL;
  int64_t ncs = 0;
  const hr_status st = hr_cluster_sources(s, &cs, &ncs);
  const hr_status r = subscribe(s, s->links, s->nlinks, cs, ncs,
                                st == HR_OK ? st : hr_err_set(err, st, "out of memory"), err);
  free(cs);
  return r;
}

hr_status hr_link_subscribe_new(hr_solver *s, int64_t lo, const int32_t *elems, int64_t ne,
                                hr_status st, hr_err *err) {
  if (!s->dist) return st;
  return subscribe(s, s->links + lo, s->nlinks - lo, elems, ne, st, err);
}

/* After a refinement round: the subscribers of every own element split in it (split[e] != 0)
 * learn of its children at once, since the next round's decisions and the next gather read
 * them (links with source shares gather the children). A collective. */
static hr_status notify_splits(hr_solver *s, const uint8_t *split, hr_err *err) {
  int64_t n = 0;
  for (int64_t i = 0; i < s->nsubs; i++) n += split[s->subs[i][0]];
  msg_state *rec = malloc((size_t)(n > 0 ? n : 1) * sizeof *rec);
  int32_t *dest = malloc((size_t)(n > 0 ? n : 1) * sizeof *dest);
  hr_status st = rec && dest ? HR_OK : hr_err_set(err, HR_ERR_NOMEM, "out of memory");
  n = 0;
  for (int64_t i = 0; i < s->nsubs && st == HR_OK; i++) {
    const int32_t e = s->subs[i][0];
    if (!split[e]) continue;
    memset(&rec[n], 0, sizeof rec[n]);
    rec[n].gid = s->el[e].gid;
    src_state_get(s, e, &rec[n].st);
    dest[n++] = s->subs[i][1];
  }
  char *in = NULL;
  int64_t nin = 0;
  st = exchange(s, (const char *)rec, dest, st == HR_OK ? n : 0, sizeof *rec, &in, &nin, st, err);
  free(rec), free(dest);
  if (st != HR_OK) return st;
  st = apply_states(s, in, nin, st, err);
  free(in);
  return hr_dist_agree(s, st, err);
}

/* A link on its way to its receiver's owner: ids instead of local indices, then ncand int32
 * candidates. Its source's state comes from the source's owner (subscribe_range). */
typedef struct msg_link {
  uint64_t r, s;
  float F, Fu, dF, dS, w[4];
  int32_t ncand, pad;
} msg_link;

/* Distributed refinement: the children of a link split on its receiver side may be received by
 * elements of other ranks; each goes to its receiver's owner with its candidate list. The links
 * that stay keep their place; the received ones are appended in rank order (order does not
 * matter: hr_link_sort orders each receiver's links by source gid). A collective: 'st' is this
 * rank's status so far, and every rank returns the same status. */
static hr_status route_links(hr_solver *s, hr_link **pcur, int64_t *pn, hr_status st,
                             hr_err *err) {
  const int P = s->nranks;
  hr_link *cur = *pcur;
  int64_t n = *pn, nstay = 0;
  int64_t *sb = calloc((size_t)P, sizeof *sb);
  int64_t *at = calloc((size_t)P + 1, sizeof *at);
  char *out = NULL;
  if (!sb) hr_dist_abort(s->dist, 1); /* every rank must take part in the exchange */
  if (st == HR_OK && at) {
    for (int64_t i = 0; i < n; i++) {
      const int d = s->eown[cur[i].r];
      if (d != s->rank) sb[d] += (int64_t)sizeof(msg_link) + 4 * (int64_t)ncands(&cur[i]);
    }
    for (int p = 0; p < P; p++) at[p + 1] = at[p] + sb[p];
    out = malloc((size_t)(at[P] > 0 ? at[P] : 1));
  }
  if (st == HR_OK && !out) st = hr_err_set(err, HR_ERR_NOMEM, "out of memory during refinement");
  const int failed = st != HR_OK;
  if (failed) memset(sb, 0, (size_t)P * sizeof *sb);
  for (int64_t i = 0; i < n && !failed; i++) {
    const hr_link *l = &cur[i];
    const int d = s->eown[l->r];
    if (d == s->rank) {
      cur[nstay++] = cur[i];
      continue;
    }
    msg_link m;
    memset(&m, 0, sizeof m);
    m.r = s->el[l->r].gid, m.s = s->el[l->s].gid;
    m.F = l->F, m.Fu = l->Fu, m.dF = l->dF, m.dS = l->dS, m.ncand = l->ncand;
    memcpy(m.w, l->w, sizeof m.w);
    memcpy(out + at[d], &m, sizeof m);
    at[d] += (int64_t)sizeof m;
    const size_t cb = 4 * (size_t)ncands(l);
    if (cb) memcpy(out + at[d], s->pool + l->cand_off, cb);
    at[d] += (int64_t)cb;
  }
  void *recv = NULL;
  int64_t tot = 0;
  const hr_status xs = hr_dist_alltoall_st(s->dist, out, sb, failed, &recv, &tot);
  free(sb), free(at), free(out);
  if (failed) return st;
  if (xs == HR_ERR_REMOTE) return hr_err_set(err, xs, "stopped: another rank failed");
  if (xs != HR_OK) return hr_err_set(err, xs, "out of memory during refinement");
  /* unpack: count, make room, copy */
  int64_t nr = 0, nc = 0;
  for (int64_t o = 0; o < tot; nr++) {
    msg_link m;
    memcpy(&m, (char *)recv + o, sizeof m);
    o += (int64_t)sizeof m + 4 * (int64_t)(m.ncand > 0 ? m.ncand : 0);
    nc += m.ncand > 0 ? m.ncand : 0;
  }
  hr_link *grown = realloc(cur, (size_t)(nstay + nr > 0 ? nstay + nr : 1) * sizeof *grown);
  if (!grown || s->npool + nc > POOL_MAX ||
      !pool_reserve(&s->pool, &s->cap_pool, s->npool + nc)) {
    if (grown) *pcur = grown;
    *pn = nstay; /* the links sent away are gone from here in any case */
    free(recv);
    return hr_err_set(err, s->npool + nc > POOL_MAX ? HR_ERR_TOO_BIG : HR_ERR_NOMEM,
                      "refinement exceeds a limit or is out of memory");
  }
  cur = grown;
  int bad = 0;
  int64_t k = nstay;
  for (int64_t o = 0; o < tot && !bad; k++) {
    msg_link m;
    memcpy(&m, (char *)recv + o, sizeof m);
    o += (int64_t)sizeof m;
    const int32_t r = hr_elem_find(s, m.r), j = hr_elem_ensure(s, m.s);
    if (r < 0 || !hr_owns(s, r) || j < 0) {
      bad = 1;
      break;
    }
    hr_link *l = &cur[k];
    *l = (hr_link){.r = r, .s = j, .F = m.F, .Fu = m.Fu, .dF = m.dF, .dS = m.dS,
                   .cand_off = (uint32_t)s->npool, .ncand = m.ncand};
    memcpy(l->w, m.w, sizeof l->w);
    const size_t cb = 4 * (size_t)(m.ncand > 0 ? m.ncand : 0);
    if (cb) memcpy(s->pool + s->npool, (char *)recv + o, cb);
    s->npool += m.ncand > 0 ? m.ncand : 0;
    o += (int64_t)cb;
  }
  free(recv);
  *pcur = cur;
  *pn = k;
  return bad ? hr_err_set(err, HR_ERR_NOMEM, "out of memory during refinement") : HR_OK;
}

/* An element moving to a new owner (hr_link_migrate) with what its owner keeps of it. */
typedef struct msg_move {
  uint64_t gid;
  double B[3], bref, open;
  double hist[2][3]; /* the extrapolation window's samples */
  src_state st; /* Bs, bvar, and its children's (for its subscribers) */
} msg_move;

/* Sends this rank's elements whose owner changed (old: the owners before) to the new owners,
 * which take them over (with their children, as ghosts where they own none). */
static hr_status move_elements(hr_solver *s, const int32_t *old, hr_err *err) {
  int64_t n = 0;
  for (int64_t e = 0; e < s->nel; e++) n += old[e] == s->rank && s->eown[e] != s->rank;
  msg_move *rec = malloc((size_t)(n > 0 ? n : 1) * sizeof *rec);
  int32_t *dest = malloc((size_t)(n > 0 ? n : 1) * sizeof *dest);
  hr_status st = rec && dest ? HR_OK : HR_ERR_NOMEM;
  n = 0;
  for (int64_t e = 0; e < s->nel && st == HR_OK; e++) {
    if (old[e] != s->rank || s->eown[e] == s->rank) continue;
    msg_move *m = &rec[n];
    memset(m, 0, sizeof *m);
    m->gid = s->el[e].gid;
    memcpy(m->B, s->B[e], sizeof m->B);
    m->bref = s->bref[e], m->open = s->open[e];
    memcpy(m->hist, s->hist[e], sizeof m->hist);
    src_state_get(s, (int32_t)e, &m->st);
    dest[n++] = s->eown[e];
  }
  char *in = NULL;
  int64_t nin = 0;
  st = exchange(s, (const char *)rec, dest, st == HR_OK ? n : 0, sizeof *rec, &in, &nin, st, err);
  free(rec), free(dest);
  for (int64_t i = 0; i < nin && st == HR_OK; i++) {
    msg_move m;
    memcpy(&m, in + i * (int64_t)sizeof m, sizeof m);
    const int32_t e = hr_elem_ensure(s, m.gid);
    if (e < 0 || !src_state_set(s, e, &m.st, 1)) {
      st = hr_err_set(err, HR_ERR_NOMEM, "out of memory moving elements");
      break;
    }
    memcpy(s->B[e], m.B, sizeof m.B);
    s->bref[e] = m.bref, s->open[e] = m.open;
    memcpy(s->hist[e], m.hist, sizeof m.hist);
  }
  free(in);
  return hr_dist_agree(s, st, err);
}

/* Moves elements and links to their owners after the owner function changed (hr_solver_migrate,
 * the test hook): own elements to their new owners, links to their receivers' owners (the dead
 * ones dropped), and every ghost subscribes afresh at its owner. A collective. */
hr_status hr_link_migrate(hr_solver *s, hr_err *err) {
  int32_t *old = malloc((size_t)(s->nel > 0 ? s->nel : 1) * sizeof *old);
  hr_status st = hr_dist_agree(s, old ? HR_OK : hr_err_set(err, HR_ERR_NOMEM, "out of memory"),
                               err);
  if (st != HR_OK) {
    free(old);
    return st;
  }
  memcpy(old, s->eown, (size_t)s->nel * sizeof *old);
  hr_owners_recompute(s);
  st = move_elements(s, old, err);
  free(old);
  if (st != HR_OK) return st;
  int64_t n = 0;
  for (int64_t i = 0; i < s->nlinks; i++)
    if (s->links[i].Fu >= 0) s->links[n++] = s->links[i];
  hr_link *cur = s->links;
  s->links = NULL;
  st = route_links(s, &cur, &n, HR_OK, err);
  s->links = cur;
  s->nlinks = s->cap_links = n;
  s->ndead = s->nsorted = 0;
  s->sorted = 0;
  if (st == HR_OK) st = hr_cluster_migrate(s, err); /* cluster links received by elements */
  if (st != HR_OK) return st;
  s->nsubs = 0;
  memset(s->esub, 0, (size_t)s->nel);
  hr_elem_prune(s); /* what this rank held for its old elements */
  return hr_link_subscribe(s, err);
}

/* A request to split element 'gid' (to its owner), and a new element for its owner with the
 * state it starts from (its parent's). */
typedef struct msg_split {
  uint64_t gid;
} msg_split;

typedef struct msg_create {
  uint64_t gid;
  double B[3], Bs[3], bref, open;
} msg_create;

/* Subdivides the elements marked in mark[0, n), here in increasing idx; asks the owners of
 * marked ghosts to split them too; the owners of split elements send each new child that
 * another rank owns to that rank. Then the new own elements' open fractions. A collective;
 * every rank returns the same status. */
hr_status hr_link_split_marked(hr_solver *s, const uint8_t *mark, int64_t n, hr_err *err) {
  const int64_t nel0 = s->nel;
  hr_status st = HR_OK;
  int64_t nreq = 0;
  for (int64_t e = 0; e < n && st == HR_OK; e++) {
    if (!mark[e]) continue;
    st = hr_elem_subdivide(s, (int32_t)e);
    nreq += !hr_owns(s, e);
  }
  if (s->dist) {
    msg_split *rq = malloc((size_t)(nreq > 0 ? nreq : 1) * sizeof *rq);
    int32_t *dest = malloc((size_t)(nreq > 0 ? nreq : 1) * sizeof *dest);
    if (!rq || !dest) st = HR_ERR_NOMEM;
    int64_t k = 0;
    for (int64_t e = 0; e < n && st == HR_OK; e++)
      if (mark[e] && !hr_owns(s, e)) rq[k].gid = s->el[e].gid, dest[k++] = s->eown[e];
    char *in = NULL;
    int64_t nin = 0;
    st = exchange(s, (const char *)rq, dest, st == HR_OK ? k : 0, sizeof *rq, &in, &nin, st, err);
    free(rq), free(dest);
    for (int64_t i = 0; i < nin && st == HR_OK; i++) {
      msg_split m;
      memcpy(&m, in + i * (int64_t)sizeof m, sizeof m);
      const int32_t e = hr_elem_find(s, m.gid);
      st = e >= 0 && hr_owns(s, e) ? hr_elem_subdivide(s, e) : HR_ERR_INVALID;
    }
    free(in);
    /* new children of own elements that other ranks own */
    int64_t nc = 0;
    for (int64_t e = nel0; e < s->nel; e++)
      nc += !hr_owns(s, e) && hr_owns(s, s->el[e].parent);
    msg_create *cr = malloc((size_t)(nc > 0 ? nc : 1) * sizeof *cr);
    int32_t *cd = malloc((size_t)(nc > 0 ? nc : 1) * sizeof *cd);
    if (!cr || !cd) st = st == HR_OK ? HR_ERR_NOMEM : st;
    k = 0;
    for (int64_t e = nel0; e < s->nel && st == HR_OK; e++) {
      const int32_t par = s->el[e].parent;
      if (hr_owns(s, e) || !hr_owns(s, par)) continue;
      msg_create *m = &cr[k];
      memset(m, 0, sizeof *m);
      m->gid = s->el[e].gid;
      memcpy(m->B, s->B[par], sizeof m->B);
      memcpy(m->Bs, s->Bs[par], sizeof m->Bs);
      m->bref = s->bref[par], m->open = s->open[par];
      cd[k++] = s->eown[e];
    }
    st = exchange(s, (const char *)cr, cd, st == HR_OK ? k : 0, sizeof *cr, &in, &nin, st, err);
    free(cr), free(cd);
    for (int64_t i = 0; i < nin && st == HR_OK; i++) {
      msg_create m;
      memcpy(&m, in + i * (int64_t)sizeof m, sizeof m);
      const int32_t e = hr_elem_ensure(s, m.gid);
      if (e < 0) {
        st = HR_ERR_NOMEM;
        break;
      }
      memcpy(s->B[e], m.B, sizeof m.B);
      memcpy(s->Bs[e], m.Bs, sizeof m.Bs);
      s->bref[e] = m.bref, s->bvar[e] = 0, s->open[e] = m.open;
      s->open[s->el[e].parent] = m.open;
    }
    free(in);
    /* the subscribers of what was split here learn of the children */
    uint8_t *split = calloc((size_t)s->nel + 1, 1);
    if (!split && st == HR_OK) st = HR_ERR_NOMEM;
    for (int64_t e = 0; split && e < nel0; e++)
      split[e] = hr_owns(s, e) && s->el[e].child >= nel0;
    if ((st = hr_dist_agree(s, st == HR_OK ? st : hr_err_set(err, st, "out of memory"), err)) ==
        HR_OK)
      st = notify_splits(s, split, err);
    free(split);
  }
  if (st == HR_OK) hr_elem_open(s, nel0, s->nel);
  if (st != HR_OK) st = hr_err_set(err, st, "refinement exceeds a limit or is out of memory");
  return hr_dist_agree(s, st, err);
}

/* The first decisions of a refinement pass (dec[i] for every link) from the current state;
 * returns how many links split. */
static int64_t decide_all(hr_solver *s, double bf_e, uint8_t *dec, float *bup) {
  int64_t nsplit0 = 0, lo = 0;
  if (s->sorted) {
    /* The sorted links, receiver by receiver, from the compact source and oracle arrays (8
     * bytes a link instead of the 32 of its record) and an upper bound of the oracle's errors;
     * only a link whose bound passes BF_e gets the exact test. */
    /* Largest channel of B per element, or the largest variation source_var can read for a
     * link from it if larger (its leaves' spread, or its children's: a leaf child's own
     * variation can exceed both the parent's spread and B), rounded up to float: a small array
     * that stays in cache while the pass reads the sources at random. Without the children's,
     * this bound kept links that the exact test splits, so a run's links depended on which of
     * them were sorted: on 2 ranks, where migration unsorts them all, the conference room split
     * 3 more links at iteration 5 than in one process. */
    for (int64_t e = 0; e < s->nel; e++) {
      const double *b = s->Bs[e];
      double x = b[0] > b[1] ? b[0] : b[1];
      x = x > b[2] ? x : b[2];
      x = x > fabs(s->bvar[e]) ? x : fabs(s->bvar[e]);
      for (int k = 0, c = s->el[e].child; c >= 0 && k < 4; k++)
        x = x > fabs(s->bvar[c + k]) ? x : fabs(s->bvar[c + k]);
      bup[e] = hr_float_up(x);
    }
    /* rho_max max(B_max, bvar) max(dF, dS)_up bounds both errors of link_err from above; the
     * margin covers the rounding of the products, so the bound never keeps a link that the
     * exact test would split. */
    const double margin = bf_e * (1 - 1e-9);
#pragma omp parallel for schedule(dynamic, 256) reduction(+ : nsplit0) \
    if (s->nsorted > PAR_MIN) num_threads(s->threads)
    for (int64_t e = 0; e < s->nrstart; e++) {
      const double rm = s->rho_max[e], lim = margin * s->bref[e];
      for (int64_t k = s->rstart[e]; k < s->rstart[e + 1]; k++) {
        dec[k] = rm * bup[s->ls[k]] * s->lfo[k] <= lim ? KEEP : decide(s, &s->links[k], bf_e);
        assert(dec[k] != KEEP || decide(s, &s->links[k], bf_e) == KEEP); /* a true bound */
        nsplit0 += dec[k] != KEEP;
      }
    }
    lo = s->nsorted;
  }
#pragma omp parallel for schedule(static) reduction(+ : nsplit0) \
    if (s->nlinks - lo > PAR_MIN) num_threads(s->threads)
  for (int64_t i = lo; i < s->nlinks; i++) {
    dec[i] = decide(s, &s->links[i], bf_e);
    nsplit0 += dec[i] != KEEP;
  }
  return nsplit0;
}

/* The kept links of a full pass's first round, packed to the front of its array *cur (in
 * order: slot[i] <= i), which becomes the kept links' array (capacity cap); *cur is NULL after.
 * Serial, since a link moves down over others. */
static hr_link *keep_in_place(hr_link **cur, int64_t n, const uint8_t *dec, const int64_t *slot,
                              int64_t cap, int64_t *nkeep, int64_t *capkeep) {
  hr_link *l = *cur;
  int64_t nk = 0;
  for (int64_t i = 0; i < n; i++)
    if (dec[i] == KEEP) {
      assert(slot[i] == nk && nk <= i);
      l[slot[i]] = l[i], nk++;
    }
  *cur = NULL;
  *nkeep = nk;
  *capkeep = cap > 0 ? cap : 1;
  return l;
}

/* Draws the estimates that link_eval left for later of the links of cur that this round keeps.
 * A link split in the round after the one that made it is never gathered: its estimate would
 * be wasted. */
static void estimate_kept(hr_solver *s, hr_link *cur, int64_t ncur, const uint8_t *dec,
                          int64_t *rays) {
  int64_t r = 0;
#pragma omp parallel for schedule(dynamic, 256) reduction(+ : r) if (ncur > 1024) \
    num_threads(s->threads)
  for (int64_t i = 0; i < ncur; i++) {
    if (dec[i] != KEEP || cur[i].F != F_LATER) continue;
    const int64_t r0 = r;
    link_estimate(s, s->pool, &cur[i], &r);
    const float cast = (float)(r - r0); /* the receiver's work (balance.c) */
#pragma omp atomic
    s->erays[cur[i].r] += cast;
  }
  *rays += r;
}

hr_status hr_link_refine(hr_solver *s, double bf_e, int64_t *nnew, hr_err *err) {
  *nnew = 0;
  /* Most iterations split nothing: decide for every link first, without copying the graph. */
  uint8_t *dec = malloc((size_t)(s->nlinks > 0 ? s->nlinks : 1));
  float *bup = malloc((size_t)(s->nel > 0 ? s->nel : 1) * sizeof *bup);
  hr_status st = dec && bup ? HR_OK : HR_ERR_NOMEM;
  int64_t nsplit0 = st == HR_OK ? decide_all(s, bf_e, dec, bup) : 0;
  free(bup);
  if (hr_test_fail(s, HR_PHASE_REFINE)) {
    free(dec);
    dec = NULL;
    st = HR_ERR_NOMEM;
  }
  /* distributed: whether any rank splits (every rank then takes part in every round) */
  int64_t any[2] = {st != HR_OK, nsplit0};
  hr_dist_sum_i64(s->dist, any, 2);
  if (any[0]) {
    free(dec);
    return st != HR_OK ? hr_err_set(err, st, "out of memory during refinement%s",
                                     dec ? "" : " (or injected by HRAD_TEST_FAIL)")
                       : hr_err_set(err, HR_ERR_REMOTE, "stopped: another rank failed");
  }
  if (any[1] == 0) {
    free(dec);
    return HR_OK;
  }
  /* Few splits (the usual case late in a level): refine only those links, leave the others in
   * place and append the results; the graph is compacted and fully sorted once dead and extra
   * links make up a quarter of it. */
  int incremental = s->sorted && nsplit0 * 16 < s->nlinks;
  hr_link *cur = NULL, *keep = NULL, *next = NULL;
  int64_t ncur = 0, cap0 = 0;
  if (incremental) {
    cur = malloc((size_t)(nsplit0 > 0 ? nsplit0 : 1) * sizeof *cur);
    if (!cur) st = HR_ERR_NOMEM;
    for (int64_t i = 0; cur && i < s->nlinks; i++) {
      if (dec[i] == KEEP) continue;
      hr_link *l = &s->links[i];
      dec[ncur] = dec[i]; /* ncur <= i */
      cur[ncur++] = *l;
      l->Fu = -1; /* dead */
      l->F = 0;
      if (i < s->nsorted) s->lfo[i] = 0;
    }
    s->ndead += ncur;
  } else {
    s->sorted = 0;
    ncur = s->nlinks;
    cur = s->links;
    cap0 = s->cap_links;
    s->links = NULL;
    s->cap_links = 0;
  }
  int64_t nkeep = 0, capkeep = 0;
  int64_t *slot = NULL;
  uint8_t *mark = NULL;
  int64_t capmark = 0;
  int64_t rays = 0;
  /* dec[0, ncur) holds the decisions of the first round already. A local failure is carried to
   * the round's next collective, where every rank learns of it and all stop together. */
  for (int round = 0;; round++) {
    int64_t nsplit = 0, nchild_cand = 0, nk = 0;
    if (st == HR_OK && round > 0) {
      uint8_t *d2 = realloc(dec, (size_t)(ncur > 0 ? ncur : 1));
      if (d2) {
        dec = d2;
#pragma omp parallel for schedule(static) if (ncur > PAR_MIN) num_threads(s->threads)
        for (int64_t i = 0; i < ncur; i++) dec[i] = decide(s, &cur[i], bf_e);
      } else {
        st = HR_ERR_NOMEM;
      }
    }
    if (st == HR_OK && round > 0) estimate_kept(s, cur, ncur, dec, &rays);
    if (st == HR_OK) {
      int64_t *sl2 = realloc(slot, (size_t)(ncur > 0 ? ncur : 1) * sizeof *slot);
      if (sl2) slot = sl2;
      else st = HR_ERR_NOMEM;
    }
    if (st == HR_OK && !s->cl) st = build_lists(s, cur, ncur, dec);
    if (st == HR_OK && capmark < s->nel) {
      uint8_t *m = realloc(mark, (size_t)s->nel);
      if (m) mark = m, capmark = s->nel;
      else st = HR_ERR_NOMEM;
    }
    if (st == HR_OK) {
      memset(mark, 0, (size_t)s->nel);
      for (int64_t i = 0; i < ncur; i++) {
        if (dec[i] == KEEP) {
          slot[i] = nk++;
          continue;
        }
        mark[dec[i] == SPLIT_R ? cur[i].r : cur[i].s] = 1;
        slot[i] = nsplit++;
        nchild_cand += 4 * (int64_t)ncands(&cur[i]);
      }
    }
    if (st != HR_OK) st = hr_err_set(err, st, "refinement exceeds a limit or is out of memory");
    if ((st = hr_dist_agree(s, st, err)) != HR_OK) goto fail;
    if ((st = hr_link_split_marked(s, mark, s->nel, err)) != HR_OK) goto fail;
    /* Keep: append in order. The first round of a full pass keeps its links where they are,
     * packed once its children are made (keep_in_place): a copy of all links meant twice their
     * memory at once, and a first touch of every page (BENCHMARKS.md, "Memory"). */
    const int in_place = round == 0 && !incremental;
    if (!in_place && nkeep + nk > capkeep) {
      int64_t nc = capkeep ? capkeep : 1024;
      while (nc < nkeep + nk) nc *= 2;
      hr_link *k2 = realloc(keep, (size_t)nc * sizeof *k2);
      if (k2) keep = k2, capkeep = nc;
      else st = HR_ERR_NOMEM;
    }
    if (st == HR_OK && !in_place) {
#pragma omp parallel for schedule(static) if (ncur > PAR_MIN) num_threads(s->threads)
      for (int64_t i = 0; i < ncur; i++)
        if (dec[i] == KEEP) keep[nkeep + slot[i]] = cur[i];
      nkeep += nk;
    }
    int64_t more[2] = {st != HR_OK, nsplit};
    hr_dist_sum_i64(s->dist, more, 2);
    if (more[0]) {
      st = st != HR_OK ? hr_err_set(err, st, "out of memory during refinement")
                       : hr_err_set(err, HR_ERR_REMOTE, "stopped: another rank failed");
      goto fail;
    }
    if (more[1] == 0) {
      if (in_place) keep = keep_in_place(&cur, ncur, dec, slot, cap0, &nkeep, &capkeep);
      break;
    }
    /* Children: 4 per split link, candidate capacity = parent's count each. */
    next = malloc((size_t)(4 * nsplit > 0 ? 4 * nsplit : 1) * sizeof *next);
    int64_t pool0 = s->npool;
    int64_t *coff = malloc((size_t)(nsplit > 0 ? nsplit : 1) * sizeof *coff);
    if (pool0 + nchild_cand > POOL_MAX) st = HR_ERR_TOO_BIG;
    else if (!next || !coff || !pool_reserve(&s->pool, &s->cap_pool, pool0 + nchild_cand))
      st = HR_ERR_NOMEM;
    if (st == HR_OK) {
      /* Offsets of each split link's candidate area: prefix sum in link order. */
      int64_t acc = pool0;
      for (int64_t i = 0; i < ncur; i++)
        if (dec[i] != KEEP) {
          coff[slot[i]] = acc;
          acc += 4 * (int64_t)ncands(&cur[i]);
        }
#pragma omp parallel for schedule(dynamic, 64) reduction(+ : rays) \
    if (nsplit > 16) num_threads(s->threads)
      for (int64_t i = 0; i < ncur; i++) {
        if (dec[i] == KEEP) continue;
        const hr_link *pl = &cur[i];
        int32_t parent = dec[i] == SPLIT_R ? pl->r : pl->s;
        int32_t first = s->el[parent].child;
        for (int k = 0; k < 4; k++) {
          hr_link *cl = &next[4 * slot[i] + k];
          cl->r = dec[i] == SPLIT_R ? first + k : pl->r;
          cl->s = dec[i] == SPLIT_S ? first + k : pl->s;
          int64_t off = coff[slot[i]] + (int64_t)k * ncands(pl);
          cl->cand_off = (uint32_t)off;
          hr_vec3 pa[4], pb[4];
          int na = elem_poly(s, &s->el[cl->r], pa), nb = elem_poly(s, &s->el[cl->s], pb);
          /* Children shrink the parent's list to their own shaft. Always worth it (measured):
           * an emptied list means H = 1 with no rays. Without a list, none. */
          cl->ncand = pl->ncand <= 0
                          ? pl->ncand
                          : hr_shaft_filter(s->scene, pa, na, s->el[cl->r].surf, pb, nb,
                                            s->el[cl->s].surf, s->pool + pl->cand_off, pl->ncand,
                                            s->pool + off);
          const int64_t r0 = rays;
          link_eval(s, s->pool, cl, &rays);
          const float cast = (float)(rays - r0); /* the receiver's work (balance.c) */
#pragma omp atomic
          s->erays[cl->r] += cast;
        }
      }
      s->npool = pool0 + nchild_cand;
      *nnew += 4 * nsplit;
      if (in_place) keep = keep_in_place(&cur, ncur, dec, slot, cap0, &nkeep, &capkeep);
      free(cur);
      cur = next;
      next = NULL;
      ncur = 4 * nsplit;
    } else {
      /* the next round's first collective tells the others */
      st = hr_err_set(err, st, "refinement exceeds a limit or is out of memory");
      free(next);
      next = NULL;
      ncur = 0;
    }
    free(coff);
    if (s->dist) st = route_links(s, &cur, &ncur, st, err);
    if (s->dist && st == HR_OK) st = subscribe_range(s, cur, ncur, err);
  }
  free(cur);
  cur = NULL;
  s->rays += rays;
  if (incremental) {
    if (!links_reserve(s, s->nlinks + nkeep)) {
      st = HR_ERR_NOMEM;
      goto fail;
    }
    if (nkeep > 0) memcpy(s->links + s->nlinks, keep, (size_t)nkeep * sizeof *keep);
    s->nlinks += nkeep;
    free(keep);
    keep = NULL;
    /* The pool keeps its holes until the next full sort compacts it. */
    if ((s->nlinks - s->nsorted + s->ndead) * 4 > s->nlinks) s->sorted = 0;
  } else {
    s->links = keep;
    s->nlinks = nkeep;
    s->cap_links = capkeep;
    keep = NULL;
  }
  free(dec);
  free(slot);
  free(mark);
  return HR_OK;
fail:
  free(dec);
  free(slot);
  free(mark);
  free(next);
  free(cur);
  free(keep);
  if (st == HR_ERR_REMOTE) return st;
  if (st == HR_ERR_TOO_BIG)
    return hr_err_set(err, st,
                      "refinement exceeds a limit: more than 2^31 elements or 2^32 candidate "
                      "blockers in links (raise --bf-low or --area-min)");
  return hr_err_set(err, HR_ERR_NOMEM, "out of memory during refinement");
}

/* Sorts each receiver's group order[start[e] .. start[e+1]) by the gid of the link's source, so
 * that a receiver's links (and the sums over them in gather) come in an order fixed by global
 * ids alone, not by where links or elements sit in memory: a checkpoint restored in another
 * layout, or a distributed run, adds them up the same way. A receiver has one link per source,
 * so the order is total. */
typedef struct gid_key {
  uint64_t gid;
  int64_t idx;
} gid_key;

/* Sorts a[0, m) by gid (distinct within a receiver's group: a total order), with t room for
 * m / 2 keys: halves sorted in turn and merged, short runs by insertion; halves already in
 * order (most groups after a sweep that added few links) cost one comparison. The conference
 * room's sorts took 1.14 s of a run instead of 1.56 with qsort and a comparison function. */
static void sort_gid_keys(gid_key *a, int64_t m, gid_key *t) {
  if (m <= 16) {
    for (int64_t i = 1; i < m; i++) {
      const gid_key x = a[i];
      int64_t j = i;
      for (; j > 0 && a[j - 1].gid > x.gid; j--) a[j] = a[j - 1];
      a[j] = x;
    }
    return;
  }
  const int64_t h = m / 2;
  sort_gid_keys(a, h, t);
  sort_gid_keys(a + h, m - h, t);
  if (a[h - 1].gid < a[h].gid) return;
  memcpy(t, a, (size_t)h * sizeof *t);
  int64_t i = 0, j = h, o = 0;
  while (i < h && j < m) a[o++] = t[i].gid < a[j].gid ? t[i++] : a[j++];
  while (i < h) a[o++] = t[i++];
}

static int sort_by_source(const hr_solver *s, int64_t nrecv, const int64_t *start,
                          int64_t *order) {
  const int64_t n = start[nrecv];
  int64_t mmax = 0;
  for (int64_t e = 0; e < nrecv; e++)
    mmax = start[e + 1] - start[e] > mmax ? start[e + 1] - start[e] : mmax;
  gid_key *k = malloc((size_t)(n > 0 ? n : 1) * sizeof *k);
  if (!k) return 0;
  int ok = 1;
#pragma omp parallel if (n > PAR_MIN) num_threads(s->threads) reduction(& : ok)
  {
    gid_key *t = malloc((size_t)(mmax / 2 + 1) * sizeof *t);
    ok = t != NULL;
#pragma omp for schedule(dynamic, 256)
    for (int64_t e = 0; e < nrecv; e++) {
      const int64_t a = start[e], m = start[e + 1] - a;
      if (m < 2 || !t) continue;
      for (int64_t i = a; i < a + m; i++) {
        /* the link and its source's record ahead of need: both lie anywhere */
        if (i + 16 < a + m) __builtin_prefetch(&s->links[order[i + 16]]);
        if (i + 8 < a + m) __builtin_prefetch(&s->el[s->links[order[i + 8]].s].gid);
        k[i] = (gid_key){s->el[s->links[order[i]].s].gid, order[i]};
      }
      sort_gid_keys(k + a, m, t);
      for (int64_t i = a; i < a + m; i++) order[i] = k[i].idx;
    }
    free(t);
  }
  free(k);
  return ok;
}

/* Counting sort of links[lo, hi) by receiver into 'order' (stable); 'start' gets nel+1 offsets. */
static void group_by_receiver(const hr_solver *s, int64_t lo, int64_t hi, int64_t *start,
                              int64_t *order) {
  memset(start, 0, (size_t)(s->nel + 1) * sizeof *start);
  for (int64_t i = lo; i < hi; i++) start[s->links[i].r + 1]++;
  for (int64_t e = 0; e < s->nel; e++) start[e + 1] += start[e];
  for (int64_t i = lo; i < hi; i++) order[start[s->links[i].r]++] = i;
  for (int64_t e = s->nel; e > 0; e--) start[e] = start[e - 1];
  start[0] = 0;
}

#ifndef NDEBUG
/* 1 when the links are grouped by receiver as rstart says and each group is in order of its
 * sources' gids (asserted in debug builds). */
static int sorted_links(const hr_solver *s) {
  for (int32_t e = 0; e < s->nel; e++)
    for (int64_t i = s->rstart[e]; i < s->rstart[e + 1]; i++)
      if (s->links[i].r != e ||
          (i > s->rstart[e] && s->el[s->links[i - 1].s].gid > s->el[s->links[i].s].gid))
        return 0;
  return s->rstart[s->nel] == s->nlinks;
}
#endif

/* Puts links[0, n) into 'order' (order[k]: the link that goes to place k) with one backward
 * pass, when the links [0, p) keep their relative order in it (a full sort's links that were
 * sorted, with the extras to merge in): those only move up, so each is read before its place
 * is written; the extras wait in a copy. It streams through memory where following the
 * permutation's cycles missed the cache at every link (85% of hr_link_sort's time on the
 * conference room, run by one thread). Returns 0, having moved nothing, when the order is of
 * another kind, the extras outnumber the rest (the copy would cost more than it saves) or
 * memory runs short. */
static int merge_in_place(hr_link *links, const int64_t *order, int64_t n, int64_t p,
                          int threads) {
  const int64_t nx = n - p;
  if (p == 0 || nx > p) return 0;
  for (int64_t k = 0, last = -1; k < n; k++) {
    if (order[k] >= p) continue;
    if (order[k] < last) return 0;
    last = order[k];
  }
  hr_link *x = malloc((size_t)(nx > 0 ? nx : 1) * sizeof *x);
  if (!x) return 0;
  /* (in parallel: the copy's first touch of each page is a fault) */
#pragma omp parallel for schedule(static) if (nx > PAR_MIN) num_threads(threads)
  for (int64_t j = 0; j < nx; j++) x[j] = links[p + j];
  for (int64_t k = n - 1; k >= 0; k--) {
    const int64_t i = order[k];
    assert(i >= p || i <= k);
    links[k] = i < p ? links[i] : x[i - p];
  }
  free(x);
  return 1;
}

hr_status hr_link_sort(hr_solver *s) {
  if (s->sorted) {
    /* Incremental state: index the extra links; extend rstart over new elements. */
    if (s->nrstart < s->nel) {
      int64_t *st = realloc(s->rstart, (size_t)(s->nel + 1) * sizeof *st);
      if (!st) return HR_ERR_NOMEM;
      for (int64_t e = s->nrstart + 1; e <= s->nel; e++) st[e] = st[s->nrstart];
      s->rstart = st;
      s->nrstart = s->nel;
    }
    /* the extras' index still holds when no link came or went since it was built */
    if (s->xfor[0] == s->nlinks && s->xfor[1] == s->nel) return HR_OK;
    int64_t nx = s->nlinks - s->nsorted;
    int64_t *xs = realloc(s->xstart, (size_t)(s->nel + 1) * sizeof *xs);
    int64_t *xi = realloc(s->xidx, (size_t)(nx > 0 ? nx : 1) * sizeof *xi);
    if (xs) s->xstart = xs;
    if (xi) s->xidx = xi;
    if (!xs || !xi) return HR_ERR_NOMEM;
    group_by_receiver(s, s->nsorted, s->nlinks, s->xstart, s->xidx);
    if (!sort_by_source(s, s->nel, s->xstart, s->xidx)) return HR_ERR_NOMEM;
    s->xfor[0] = s->nlinks, s->xfor[1] = s->nel;
    return HR_OK;
  }
  /* Full sort: drop dead links, group by receiver, compact the candidate pool. The links that
   * were sorted ([0, nsorted)) keep theirs in [0, p). */
  int64_t n = 0, p = 0;
  for (int64_t i = 0; i < s->nlinks; i++) {
    if (s->links[i].Fu >= 0) s->links[n++] = s->links[i];
    if (i < s->nsorted) p = n;
  }
  s->nlinks = n;
  s->ndead = 0;
  int64_t *st = realloc(s->rstart, (size_t)(s->nel + 1) * sizeof *st);
  if (!st) return HR_ERR_NOMEM;
  s->rstart = st;
  s->nrstart = s->nel;
  int64_t *order = malloc((size_t)(n > 0 ? n : 1) * sizeof *order);
  int64_t tot = 0;
  for (int64_t i = 0; i < n; i++) tot += s->links[i].ncand > 0 ? s->links[i].ncand : 0;
  int32_t *np = malloc((size_t)(tot > 0 ? tot : 1) * sizeof *np);
  if (!order || !np) {
    free(order);
    free(np);
    return HR_ERR_NOMEM;
  }
  group_by_receiver(s, 0, n, st, order);
  if (!sort_by_source(s, s->nel, st, order)) {
    free(order);
    free(np);
    return HR_ERR_NOMEM;
  }
  /* New pool offsets in receiver order (serial prefix sum), then the copies in parallel; and
   * room for the compact copies for the decision pass (see hr_link_refine), before the links
   * move. */
  int64_t *noff = malloc((size_t)(n > 0 ? n : 1) * sizeof *noff);
  int32_t *ls = noff ? realloc(s->ls, (size_t)(n > 0 ? n : 1) * sizeof *ls) : NULL;
  if (ls) s->ls = ls;
  float *lfo = ls ? realloc(s->lfo, (size_t)(n > 0 ? n : 1) * sizeof *lfo) : NULL;
  if (lfo) s->lfo = lfo;
  if (!noff || !ls || !lfo) {
    free(noff);
    free(order);
    free(np);
    return HR_ERR_NOMEM;
  }
  int64_t o = 0;
  for (int64_t k = 0; k < n; k++) {
    int32_t nc = s->links[order[k]].ncand;
    noff[k] = o;
    o += nc > 0 ? nc : 0;
  }
#pragma omp parallel for schedule(static) if (n > PAR_MIN) num_threads(s->threads)
  for (int64_t k = 0; k < n; k++) {
    const hr_link *l = &s->links[order[k]];
    if (l->ncand > 0) memcpy(np + noff[k], s->pool + l->cand_off, (size_t)l->ncand * sizeof *np);
  }
  /* The links into their order in place: merged with the extras where the sorted ones kept
   * their order, else cycle by cycle (order[j] = j once j holds its link). A second array of
   * every link meant a first touch of each of its pages at every full sort, 22% of a clustered
   * museum's page faults (13.5 us each on these virtual machines), and twice the links' memory
   * at once. */
  hr_link *out = s->links;
  if (!merge_in_place(out, order, n, p, s->threads))
    for (int64_t k = 0; k < n; k++) {
      if (order[k] == k) continue;
      const hr_link first = out[k];
      for (int64_t j = k;;) {
        const int64_t from = order[j];
        order[j] = j;
        if (from == k) {
          out[j] = first;
          break;
        }
        out[j] = out[from];
        j = from;
      }
    }
#pragma omp parallel for schedule(static) if (n > PAR_MIN) num_threads(s->threads)
  for (int64_t k = 0; k < n; k++)
    if (out[k].ncand >= 0) out[k].cand_off = (uint32_t)noff[k];
  free(noff);
  free(order);
  /* the compact copies */
#pragma omp parallel for schedule(static) if (n > PAR_MIN) num_threads(s->threads)
  for (int64_t k = 0; k < n; k++) {
    const double f = out[k].Fu >= 0 ? (out[k].dF > out[k].dS ? out[k].dF : out[k].dS) : 0;
    s->ls[k] = out[k].s;
    s->lfo[k] = hr_float_up(f);
  }
  /* what the dead links held goes back (a shrinking realloc moves nothing) */
  if (s->cap_links > n + n / 8 + 64) {
    hr_link *l = realloc(s->links, (size_t)(n > 0 ? n : 1) * sizeof *l);
    if (l) s->links = l, s->cap_links = n > 0 ? n : 1;
  }
  free(s->pool);
  s->pool = np;
  s->npool = tot;
  s->cap_pool = tot > 0 ? tot : 1;
  s->nsorted = n;
  s->sorted = 1;
  s->xfor[0] = s->xfor[1] = -1;
  assert(sorted_links(s));
  return HR_OK;
}
