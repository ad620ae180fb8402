/* link.c: the link graph. Initial linking of every pair of mutually facing surfaces with a
 * shaft-culled candidate blocker list (paper 2.2.1, step {1} of Figure 3) and BF refinement of
 * links (paper 2.2.2, steps {7..13}).
 *
 * Refinement runs in rounds so that it is parallel and independent of scheduling: in a round
 * every active link decides (keep / split receiver / split source) from the current state only;
 * the elements to split are subdivided in link order; then each split link writes its four
 * children into slots fixed by a prefix sum. Children inherit their parent's candidate list and
 * shrink it to their own shaft; links whose elements face away get F = 0. The children become the
 * next round's active links, until no link splits. */
#include "solver_impl.h"
#include "vec.h"

#include <omp.h>
#include <stdlib.h>
#include <math.h>
#include <string.h>

/* ncand of a link whose candidate list has not been built yet (initial links). */
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

static int pool_reserve(int32_t **pool, int64_t *cap, int64_t need) {
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

/* Rays for the visible fraction between elements a and b, whose unoccluded form factors (eq. 2)
 * are fab (a receiving from b) and fba: the full k where the pair can carry a BF of BF_low or
 * more (w = max(rho_a F_ab, rho_b F_ba) >= BF_low, i.e. with a source as bright as the brightest
 * emitter), and proportionally fewer below, down to k_min. H stays unbiased for any count; only
 * its noise grows, on links that carry little energy (docs/design.md, "Rays per link"). The same
 * count for both directions keeps H_ab == H_ba. */
static int pair_rays(const hr_solver *s, int32_t a, int32_t b, double fab, double fba) {
  int k = s->opt.rays, kmin = s->opt.rays_min;
  if (kmin >= k || !(fab > 0)) return k;
  double w = fab * s->rho_max[a], w2 = fba * s->rho_max[b];
  w = w > w2 ? w : w2;
  double kk = ceil(k * w / s->opt.bf_low);
  return kk >= k ? k : kk > kmin ? (int)kk : kmin;
}

/* 1 if some corner of 'b' lies in front of the plane of element 'a'. */
static int elem_in_front(const hr_solver *s, const hr_elem *a, const hr_elem *b) {
  hr_vec3 n = s->scene->surfs[a->surf].normal;
  int nv = s->scene->surfs[b->surf].nverts;
  double size = sqrt(a->area + b->area);
  for (int k = 0; k < nv; k++)
    if (v3_dot(v3_sub(b->p[k], a->c), n) > 1e-9 * size) return 1;
  return 0;
}

/* Fills F and H of link 'l' (receiver, source and candidate list already set): eq. (2) times H
 * when the centres face each other; when only parts do, the ray-cast point-to-disk form factor
 * over the sampled segments (eq. (2) would give 0 and drop light that does arrive); when no part
 * faces the other, F = H = 0. */
static void link_eval(const hr_solver *s, const int32_t *pool, hr_link *l, int64_t *rays) {
  const hr_elem *r = &s->el[l->r], *j = &s->el[l->s];
  double f = hr_ff_unoccluded(s, r, j), h;
  l->Fu = (float)f;
  if (f > 0) {
    int k = l->ncand == 0 ? 0 : pair_rays(s, l->r, l->s, f, hr_ff_unoccluded(s, j, r));
    h = hr_ff_visibility(s, r, j, pool + l->cand_off, l->ncand, k, NULL, rays, NULL);
    f *= h;
  } else if (elem_in_front(s, r, j) && elem_in_front(s, j, r)) {
    double fmc[2];
    h = hr_ff_visibility(s, r, j, pool + l->cand_off, l->ncand, 0, NULL, rays, fmc);
    f = fmc[0];
  } else {
    h = 0;
  }
  l->H = (float)h;
  l->F = (float)f;
}

/* Refinement oracle: the largest energy, relative to the brightest emitter, that the link would
 * carry into its receiver (rho_i B_j F_ij per channel). When the elements' centres face away but
 * parts of them may still face each other, the cosines are bounded by 1 so that such a link
 * still refines instead of silently dropping its energy. */
/* The form factor the refinement oracle uses for link l (see link_bf). */
static double oracle_f(const hr_solver *s, const hr_link *l) {
  double f = l->F;
  if (l->H > 0 && l->H < 1) {
    /* Partly visible: H rests on k rays and varies across the elements (a shadow boundary
     * crosses them); refine as if unoccluded, so that visibility is resolved by refinement
     * instead of by the noise of one coarse estimate. */
    f = l->Fu > f ? l->Fu : f;
  }
  if (f == 0 && l->H > 0) {
    const hr_elem *r = &s->el[l->r], *j = &s->el[l->s];
    double r2 = v3_dot(v3_sub(j->c, r->c), v3_sub(j->c, r->c));
    f = j->area / (M_PI * r2 + j->area);
  }
  return f;
}

/* Refinement oracle: the largest energy, relative to the brightest emitter, that the link would
 * carry into its receiver (rho_i B_j F_ij per channel). When the elements' centres face away but
 * parts of them may still face each other, the cosines are bounded by 1 so that such a link
 * still refines instead of silently dropping its energy. */
static double link_bf(const hr_solver *s, const hr_link *l) {
  double f = oracle_f(s, l);
  const double *rho = s->rho[l->r], *b = s->B[l->s];
  double m = 0;
  for (int c = 0; c < 3; c++) {
    double e = rho[c] * b[c];
    m = e > m ? e : m;
  }
  return m * f / s->emax;
}

/* 1 if some vertex of 'b' lies in front of the plane of 'a' (by more than a relative tolerance). */
static int in_front(const hr_surface *a, const hr_surface *b) {
  double size = sqrt(a->area + b->area);
  for (int k = 0; k < b->nverts; k++)
    if (v3_dot(v3_sub(b->v[k], a->v[0]), a->normal) > 1e-9 * size) return 1;
  return 0;
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
  int j[HR_FF_BATCH_PAIRS], k[HR_FF_BATCH_PAIRS];
  double fij[HR_FF_BATCH_PAIRS], fji[HR_FF_BATCH_PAIRS];
} pending;

/* Computes H for the pending pairs of row i (batched where the centres face each other, the
 * rest one by one with the straddle estimate), appends the links of the visible ones in pair
 * order and empties 'pd'. Returns 0 when out of memory.
 *
 * The k segments of a pair are cast against the whole scene: most pairs of a large scene are
 * hidden from each other, and most initial links are never refined, so a candidate list is
 * built only when a link first splits (see hr_link_refine). A pair all of whose k segments are
 * blocked is taken as mutually invisible. */
static int init_flush(const hr_solver *s, int i, pending *pd, hr_blockers *blk, row *rw) {
  const hr_elem *bs[HR_FF_BATCH_PAIRS] = {NULL};
  int kb[HR_FF_BATCH_PAIRS] = {0}, qb[HR_FF_BATCH_PAIRS], nb = 0;
  double hb[HR_FF_BATCH_PAIRS], h[HR_FF_BATCH_PAIRS], fmc[HR_FF_BATCH_PAIRS][2];
  for (int q = 0; q < pd->n; q++)
    if (pd->fij[q] > 0 && pd->k[q] <= HR_FF_BATCH_SEGS) {
      bs[nb] = &s->el[pd->j[q]];
      kb[nb] = pd->k[q];
      qb[nb++] = q;
    }
  hr_ff_visibility_batch(s, &s->el[i], bs, kb, nb, blk, &rw->rays, hb);
  for (int q = 0; q < pd->n; q++) h[q] = -1;
  for (int r = 0; r < nb; r++) h[qb[r]] = hb[r];
  for (int q = 0; q < pd->n; q++) {
    int j = pd->j[q];
    if (h[q] < 0)
      h[q] = hr_ff_visibility(s, &s->el[i], &s->el[j], NULL, -1, pd->k[q], blk, &rw->rays,
                              pd->fij[q] > 0 ? NULL : fmc[q]);
    if (h[q] == 0) continue;
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
    double fij = pd->fij[q], fji = pd->fji[q];
    double Fij = fij > 0 ? fij * h[q] : fmc[q][0], Fji = fji > 0 ? fji * h[q] : fmc[q][1];
    hr_link lij = {i, j, (float)Fij, (float)h[q], (float)fij, 0, NO_LIST};
    hr_link lji = {j, i, (float)Fji, (float)h[q], (float)fji, 0, NO_LIST};
    rw->links[rw->nlinks++] = lij;
    rw->links[rw->nlinks++] = lji;
  }
  pd->n = pd->segs = 0;
  return 1;
}

hr_status hr_link_init(hr_solver *s, hr_err *err) {
  const hr_scene *sc = s->scene;
  int n = sc->nsurfs;
  double pairs = 0.5 * (double)n * (double)(n - 1);
  if (s->opt.max_links > 0 && pairs > s->opt.max_links)
    return hr_err_set(err, HR_ERR_TOO_BIG,
                      "%d surfaces make %.3g surface pairs for initial linking, above the limit "
                      "of %.3g (--max-pairs); hierarchical clustering is needed for scenes this "
                      "large",
                      n, pairs, s->opt.max_links);
  row *rows = calloc((size_t)n, sizeof *rows);
  if (!rows) return hr_err_set(err, HR_ERR_NOMEM, "out of memory in initial linking");
#pragma omp parallel for schedule(dynamic, 4) if (n > 16)
  for (int i = 0; i < n; i++) {
    row *rw = &rows[i];
    const hr_surface *a = &sc->surfs[i];
    hr_blockers blk;
    hr_blockers_clear(&blk);
    pending pd;
    pd.n = pd.segs = 0;
    for (int j = i + 1; j <= n; j++) {
      if (j < n) {
        const hr_surface *b = &sc->surfs[j];
        if (!in_front(a, b) || !in_front(b, a)) continue;
        /* Eq. (2) where the centres face each other, else the ray-cast estimate (link_eval).
         * Both directions share the two cosines: fji > 0 exactly when fij > 0. */
        double fij = hr_ff_unoccluded(s, &s->el[i], &s->el[j]);
        double fji = fij > 0 ? hr_ff_unoccluded(s, &s->el[j], &s->el[i]) : 0;
        int k = pair_rays(s, i, j, fij, fji);
        if (pd.n == HR_FF_BATCH_PAIRS || pd.segs + k > HR_FF_BATCH_SEGS) {
          if (!init_flush(s, i, &pd, &blk, rw)) break;
        }
        pd.j[pd.n] = j, pd.k[pd.n] = k, pd.fij[pd.n] = fij, pd.fji[pd.n] = fji;
        pd.n++;
        pd.segs += k;
      } else if (!init_flush(s, i, &pd, &blk, rw)) {
        break;
      }
    }
  }
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
    s->initial_links = nl;
  }
  for (int i = 0; i < n; i++) free(rows[i].links);
  free(rows);
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

static uint8_t decide(const hr_solver *s, const hr_link *l, double bf_e) {
  if (l->H <= 0) return KEEP; /* invisible, or dead (H < 0) */
  if (link_bf(s, l) <= bf_e) return KEEP;
  const hr_elem *r = &s->el[l->r], *j = &s->el[l->s];
  /* The paper subdivides the larger patch if its area is above A_e. */
  if (r->area >= j->area) {
    if (r->area > s->area_min && (r->child >= 0 || r->depth < HR_GID_DEPTH)) return SPLIT_R;
  } else {
    if (j->area > s->area_min && (j->child >= 0 || j->depth < HR_GID_DEPTH)) return SPLIT_S;
  }
  return KEEP;
}

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
#pragma omp parallel for schedule(dynamic, 16) reduction(| : failed) if (nb > 64)
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
    if (!pool_reserve(&s->pool, &s->cap_pool, s->npool + tot)) failed = 1;
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
  return failed ? HR_ERR_NOMEM : HR_OK;
}

hr_status hr_link_refine(hr_solver *s, double bf_e, int64_t *nnew, hr_err *err) {
  *nnew = 0;
  /* Most iterations split nothing: decide for every link first, without copying the graph. */
  uint8_t *dec = malloc((size_t)(s->nlinks > 0 ? s->nlinks : 1));
  if (!dec) return hr_err_set(err, HR_ERR_NOMEM, "out of memory during refinement");
  int64_t nsplit0 = 0, lo = 0;
  if (s->sorted) {
    /* The sorted links, receiver by receiver, from the compact source and oracle arrays (8
     * bytes a link instead of the 28 of its record) and an upper bound of BF; only a link whose
     * bound passes BF_e gets the exact test. */
    float *bup = malloc((size_t)s->nel * sizeof *bup);
    if (!bup) {
      free(dec);
      return hr_err_set(err, HR_ERR_NOMEM, "out of memory during refinement");
    }
    /* Largest channel of B per element, rounded up to float: a small array that stays in
     * cache while the pass reads the sources at random. */
    for (int64_t e = 0; e < s->nel; e++) {
      const double *b = s->B[e];
      double x = b[0] > b[1] ? b[0] : b[1];
      x = x > b[2] ? x : b[2];
      float xf = (float)x;
      bup[e] = (double)xf < x ? nextafterf(xf, INFINITY) : xf;
    }
    /* rho_max B_max F_up bounds rho_c B_c F from above; the margin covers the rounding of the
     * products, so the bound never keeps a link that the exact test would split. */
    const double lim = bf_e * s->emax * (1 - 1e-9);
#pragma omp parallel for schedule(dynamic, 256) reduction(+ : nsplit0) if (s->nsorted > PAR_MIN)
    for (int64_t e = 0; e < s->nrstart; e++) {
      const double rm = s->rho_max[e];
      for (int64_t k = s->rstart[e]; k < s->rstart[e + 1]; k++) {
        dec[k] = rm * bup[s->ls[k]] * s->lfo[k] <= lim ? KEEP : decide(s, &s->links[k], bf_e);
        nsplit0 += dec[k] != KEEP;
      }
    }
    free(bup);
    lo = s->nsorted;
  }
#pragma omp parallel for schedule(static) reduction(+ : nsplit0) if (s->nlinks - lo > PAR_MIN)
  for (int64_t i = lo; i < s->nlinks; i++) {
    dec[i] = decide(s, &s->links[i], bf_e);
    nsplit0 += dec[i] != KEEP;
  }
  if (nsplit0 == 0) {
    free(dec);
    return HR_OK;
  }
  /* Few splits (the usual case late in a level): refine only those links, leave the others in
   * place and append the results; the graph is compacted and fully sorted once dead and extra
   * links make up a quarter of it. */
  int incremental = s->sorted && nsplit0 * 16 < s->nlinks;
  hr_link *cur, *keep = NULL, *next = NULL;
  int64_t ncur;
  if (incremental) {
    cur = malloc((size_t)nsplit0 * sizeof *cur);
    if (!cur) {
      free(dec);
      return hr_err_set(err, HR_ERR_NOMEM, "out of memory during refinement");
    }
    ncur = 0;
    for (int64_t i = 0; i < s->nlinks; i++) {
      if (dec[i] == KEEP) continue;
      hr_link *l = &s->links[i];
      dec[ncur] = dec[i]; /* ncur <= i */
      cur[ncur++] = *l;
      l->H = -1; /* dead */
      l->F = 0;
      if (i < s->nsorted) s->lfo[i] = 0;
    }
    s->ndead += ncur;
  } else {
    s->sorted = 0;
    ncur = s->nlinks;
    cur = s->links;
    s->links = NULL;
    s->cap_links = 0;
  }
  int64_t nkeep = 0, capkeep = 0;
  int64_t *slot = NULL;
  uint8_t *mark = NULL;
  int64_t capmark = 0;
  hr_status st = HR_OK;
  int64_t rays = 0;
  /* dec[0, ncur) holds the decisions of the first round already. */
  for (int round = 0; ncur > 0; round++) {
    if (round > 0) {
      uint8_t *d2 = realloc(dec, (size_t)ncur);
      if (!d2) goto nomem;
      dec = d2;
#pragma omp parallel for schedule(static) if (ncur > PAR_MIN)
      for (int64_t i = 0; i < ncur; i++) dec[i] = decide(s, &cur[i], bf_e);
    }
    slot = realloc(slot, (size_t)ncur * sizeof *slot);
    if (!slot) goto nomem;
    if (build_lists(s, cur, ncur, dec) != HR_OK) goto nomem;
    /* Subdivide the marked elements in link order (deterministic element indices). */
    if (capmark < s->nel) {
      uint8_t *m = realloc(mark, (size_t)s->nel);
      if (!m) goto nomem;
      mark = m;
      capmark = s->nel;
    }
    memset(mark, 0, (size_t)s->nel);
    int64_t nsplit = 0, nchild_cand = 0, nk = 0;
    for (int64_t i = 0; i < ncur; i++) {
      if (dec[i] == KEEP) {
        slot[i] = nk++;
        continue;
      }
      int32_t e = dec[i] == SPLIT_R ? cur[i].r : cur[i].s;
      if (!mark[e]) {
        mark[e] = 1;
        if (hr_elem_subdivide(s, e) != HR_OK) goto nomem;
      }
      slot[i] = nsplit++;
      nchild_cand += 4 * (int64_t)cur[i].ncand;
    }
    /* Keep: append in order. */
    if (nkeep + nk > capkeep) {
      int64_t nc = capkeep ? capkeep : 1024;
      while (nc < nkeep + nk) nc *= 2;
      hr_link *k2 = realloc(keep, (size_t)nc * sizeof *k2);
      if (!k2) goto nomem;
      keep = k2;
      capkeep = nc;
    }
#pragma omp parallel for schedule(static) if (ncur > PAR_MIN)
    for (int64_t i = 0; i < ncur; i++)
      if (dec[i] == KEEP) keep[nkeep + slot[i]] = cur[i];
    nkeep += nk;
    if (nsplit == 0) break;
    /* Children: 4 per split link, candidate capacity = parent's count each. */
    next = malloc((size_t)(4 * nsplit) * sizeof *next);
    int64_t pool0 = s->npool;
    if (!next || !pool_reserve(&s->pool, &s->cap_pool, pool0 + nchild_cand)) goto nomem;
    /* Offsets of each split link's candidate area: prefix sum in link order. */
    int64_t *coff = malloc((size_t)nsplit * sizeof *coff);
    if (!coff) goto nomem;
    {
      int64_t acc = pool0;
      for (int64_t i = 0; i < ncur; i++)
        if (dec[i] != KEEP) {
          coff[slot[i]] = acc;
          acc += 4 * (int64_t)cur[i].ncand;
        }
    }
#pragma omp parallel for schedule(dynamic, 64) reduction(+ : rays) if (nsplit > 16)
    for (int64_t i = 0; i < ncur; i++) {
      if (dec[i] == KEEP) continue;
      const hr_link *pl = &cur[i];
      int32_t parent = dec[i] == SPLIT_R ? pl->r : pl->s;
      int32_t first = s->el[parent].child;
      for (int k = 0; k < 4; k++) {
        hr_link *cl = &next[4 * slot[i] + k];
        cl->r = dec[i] == SPLIT_R ? first + k : pl->r;
        cl->s = dec[i] == SPLIT_S ? first + k : pl->s;
        int64_t off = coff[slot[i]] + (int64_t)k * pl->ncand;
        cl->cand_off = (uint32_t)off;
        hr_vec3 pa[4], pb[4];
        int na = elem_poly(s, &s->el[cl->r], pa), nb = elem_poly(s, &s->el[cl->s], pb);
        /* Children shrink the parent's list to their own shaft. Always worth it (measured):
         * an emptied list means H = 1 with no rays. */
        cl->ncand = pl->ncand == 0 ? 0
                                   : hr_shaft_filter(s->scene, pa, na, s->el[cl->r].surf, pb, nb,
                                                     s->el[cl->s].surf, s->pool + pl->cand_off,
                                                     pl->ncand, s->pool + off);
        link_eval(s, s->pool, cl, &rays);
      }
    }
    free(coff);
    s->npool = pool0 + nchild_cand;
    *nnew += 4 * nsplit;
    free(cur);
    cur = next;
    next = NULL;
    ncur = 4 * nsplit;
  }
  free(cur);
  cur = NULL;
  s->rays += rays;
  if (incremental) {
    if (!links_reserve(s, s->nlinks + nkeep)) goto nomem;
    memcpy(s->links + s->nlinks, keep, (size_t)nkeep * sizeof *keep);
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
  if (s->npool > (int64_t)UINT32_MAX) goto nomem;
  free(dec);
  free(slot);
  free(mark);
  return st;
nomem:
  free(dec);
  free(slot);
  free(mark);
  free(next);
  free(cur);
  free(keep);
  return hr_err_set(err, HR_ERR_NOMEM, "out of memory during refinement");
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
    int64_t nx = s->nlinks - s->nsorted;
    int64_t *xs = realloc(s->xstart, (size_t)(s->nel + 1) * sizeof *xs);
    int64_t *xi = realloc(s->xidx, (size_t)(nx > 0 ? nx : 1) * sizeof *xi);
    if (xs) s->xstart = xs;
    if (xi) s->xidx = xi;
    if (!xs || !xi) return HR_ERR_NOMEM;
    group_by_receiver(s, s->nsorted, s->nlinks, s->xstart, s->xidx);
    return HR_OK;
  }
  /* Full sort: drop dead links, group by receiver, compact the candidate pool. */
  int64_t n = 0;
  for (int64_t i = 0; i < s->nlinks; i++)
    if (s->links[i].H >= 0) s->links[n++] = s->links[i];
  s->nlinks = n;
  s->ndead = 0;
  int64_t *st = realloc(s->rstart, (size_t)(s->nel + 1) * sizeof *st);
  if (!st) return HR_ERR_NOMEM;
  s->rstart = st;
  s->nrstart = s->nel;
  int64_t *order = malloc((size_t)(n > 0 ? n : 1) * sizeof *order);
  hr_link *out = malloc((size_t)(n > 0 ? n : 1) * sizeof *out);
  int64_t tot = 0;
  for (int64_t i = 0; i < n; i++) tot += s->links[i].ncand > 0 ? s->links[i].ncand : 0;
  int32_t *np = malloc((size_t)(tot > 0 ? tot : 1) * sizeof *np);
  if (!order || !out || !np) {
    free(order);
    free(out);
    free(np);
    return HR_ERR_NOMEM;
  }
  group_by_receiver(s, 0, n, st, order);
  /* New pool offsets in receiver order (serial prefix sum), then the copies in parallel. */
  int64_t *noff = malloc((size_t)(n > 0 ? n : 1) * sizeof *noff);
  if (!noff) {
    free(order);
    free(out);
    free(np);
    return HR_ERR_NOMEM;
  }
  int64_t o = 0;
  for (int64_t k = 0; k < n; k++) {
    int32_t nc = s->links[order[k]].ncand;
    noff[k] = o;
    o += nc > 0 ? nc : 0;
  }
#pragma omp parallel for schedule(static) if (n > PAR_MIN)
  for (int64_t k = 0; k < n; k++) {
    hr_link l = s->links[order[k]];
    if (l.ncand > 0) memcpy(np + noff[k], s->pool + l.cand_off, (size_t)l.ncand * sizeof *np);
    if (l.ncand >= 0) l.cand_off = (uint32_t)noff[k];
    out[k] = l;
  }
  free(noff);
  free(order);
  /* Compact copies for the decision pass (see hr_link_refine). */
  int32_t *ls = realloc(s->ls, (size_t)(n > 0 ? n : 1) * sizeof *ls);
  if (ls) s->ls = ls;
  float *lfo = ls ? realloc(s->lfo, (size_t)(n > 0 ? n : 1) * sizeof *lfo) : NULL;
  if (lfo) s->lfo = lfo;
  if (!ls || !lfo) {
    free(out);
    free(np);
    return HR_ERR_NOMEM;
  }
#pragma omp parallel for schedule(static) if (n > PAR_MIN)
  for (int64_t k = 0; k < n; k++) {
    double f = out[k].H > 0 ? oracle_f(s, &out[k]) : 0;
    float fu = (float)f;
    if ((double)fu < f) fu = nextafterf(fu, INFINITY);
    s->ls[k] = out[k].s;
    s->lfo[k] = fu;
  }
  free(s->links);
  free(s->pool);
  s->links = out;
  s->cap_links = n > 0 ? n : 1;
  s->pool = np;
  s->npool = tot;
  s->cap_pool = tot > 0 ? tot : 1;
  s->nsorted = n;
  s->sorted = 1;
  return HR_OK;
}
