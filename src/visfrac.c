/* visfrac.c: the visible fraction H_ij of a link (paper 1.2), by rays between jittered points of
 * the two elements, weighted by the form-factor kernel (see visfrac.h).
 *
 * The jitter comes from a counter-based hash of (seed, element gids, sample index), so the
 * estimate does not depend on call order or thread, and it is symmetric in the two elements. */
#include "visfrac.h"
#include "vec.h"

#include <math.h>
#include <string.h>

static inline uint64_t mix64(uint64_t z) {
  z = (z ^ (z >> 30)) * UINT64_C(0xbf58476d1ce4e5b9);
  z = (z ^ (z >> 27)) * UINT64_C(0x94d049bb133111eb);
  return z ^ (z >> 31);
}

uint64_t hr_hash4(uint64_t seed, uint64_t a, uint64_t b, uint64_t i) {
  uint64_t h = mix64(seed + UINT64_C(0x9e3779b97f4a7c15));
  h = mix64(h ^ a);
  h = mix64(h ^ (b + UINT64_C(0x632be59bd9b4e019)));
  return mix64(h ^ (i * UINT64_C(0xd1b54a32d192ed03)));
}

/* The 16-bit field of 'h' at bit 'shift', as the centre of one of 65536 equal bins of [0, 1). */
static inline double unit16(uint64_t h, int shift) {
  return ((double)((h >> shift) & 0xffff) + 0.5) * (1.0 / 65536.0);
}

/* Parameters (u_a, v_a, u_b, v_b) of sample i of the pair keyed 'key' with k samples: one mix of
 * (key, i), four 16-bit fields. Stratified in a's first and b's second parameter (strata i mod k
 * and (7 i + 3) mod k), uniform in the other two. */
static inline void sample_params(uint64_t key, int i, int k, double invk, double uv[4]) {
  uint64_t h = mix64(key + (uint64_t)(i + 1) * UINT64_C(0x9e3779b97f4a7c15));
  int si = i % k;
  uv[0] = (si + unit16(h, 0)) * invk;
  uv[1] = unit16(h, 16);
  uv[2] = unit16(h, 32);
  uv[3] = ((si * 7 + 3) % k + unit16(h, 48)) * invk;
}

/* Point on element 'e' at parameters (u, v) in [0,1)^2 (triangles fold the square). */
static inline hr_vec3 elem_point(const hr_ff_elem *e, double u, double v) {
  if (e->nv == 4) {
    hr_vec3 a = v3_lerp(e->p[0], e->p[1], u), b = v3_lerp(e->p[3], e->p[2], u);
    return v3_lerp(a, b, v);
  }
  if (u + v > 1) {
    u = 1 - u;
    v = 1 - v;
  }
  return v3_add(e->p[0], v3_add(v3_scale(v3_sub(e->p[1], e->p[0]), u),
                                v3_scale(v3_sub(e->p[2], e->p[0]), v)));
}

/* Kernel weight of the segment from x (on a, normal na) to y (on b, normal nb): cos_a cos_b /
 * (r^2 (r^2 + reg)), or 0 when the ends do not face each other (the sample does not count). */
static inline double seg_weight(hr_vec3 x, hr_vec3 na, hr_vec3 y, hr_vec3 nb, double reg) {
  hr_vec3 d = v3_sub(y, x);
  double r2 = v3_dot(d, d), ca = v3_dot(na, d), cb = -v3_dot(nb, d);
  if (!(ca > 0 && cb > 0 && r2 > 0)) return 0;
  return ca * cb / (r2 * (r2 + reg));
}

static inline void put3(float *o, hr_vec3 p) {
  o[0] = (float)p.x;
  o[1] = (float)p.y;
  o[2] = (float)p.z;
}

#define CAND_BRUTE_MAX 16 /* lists this short are tested directly (measured 45-60 Mrays/s) */
#define CHUNK 64

/* Tests n segments against the blocker cache (vis[i] = 0: closed). When some stay open, the
 * first of them goes to Embree at once as a nearest-hit query: a blocker it finds joins the
 * cache and closes what it can of the rest, so the next pairs of the row, hidden by the same
 * walls, find it there; an open one is visible (vis = 1). Returns the index after which open
 * segments are still undecided (n when none are). */
static int cache_first(const hr_vf_ctx *c, hr_blockers *blk, int n, const float *org,
                       const float *dst, int sa, int sb, uint8_t *vis) {
  memset(vis, 1, (size_t)n);
  if (hr_blockers_test(blk, n, org, dst, sa, sb, vis) == 0) return n;
  int i0 = 0;
  while (!vis[i0]) i0++;
  int hit = hr_vis_first_hit(c->vis, org + 3 * i0, dst + 3 * i0);
  vis[i0] = hit < 0;
  if (hit >= 0) {
    hr_blockers_add(blk, c->scene, hit);
    hr_blockers_test(blk, n - i0 - 1, org + 3 * (i0 + 1), dst + 3 * (i0 + 1), sa, sb,
                     vis + i0 + 1);
  }
  return i0 + 1;
}

/* Gathers the segments from index 'from' on that are still open into o2/d2 (from slot *m on,
 * their indices plus 'base' into idx). */
static void collect_open(int n, int from, int base, const float *org, const float *dst,
                         const uint8_t *vis, float *o2, float *d2, int *idx, int *m) {
  for (int i = from; i < n; i++) {
    if (!vis[i]) continue;
    memcpy(o2 + 3 * *m, org + 3 * i, 3 * sizeof(float));
    memcpy(d2 + 3 * *m, dst + 3 * i, 3 * sizeof(float));
    idx[(*m)++] = base + i;
  }
}

/* Segments through the blocker cache (cache_first), the rest through Embree. */
static void cast_cached(const hr_vf_ctx *c, hr_blockers *blk, int n, const float *org,
                        const float *dst, int sa, int sb, uint8_t *vis) {
  int from = cache_first(c, blk, n, org, dst, sa, sb, vis);
  float o2[CHUNK * 3], d2[CHUNK * 3];
  int idx[CHUNK], m = 0;
  uint8_t v2[CHUNK];
  collect_open(n, from, 0, org, dst, vis, o2, d2, idx, &m);
  if (m == 0) return;
  hr_vis_segments(c->vis, m, o2, d2, -1, -1, v2);
  for (int r = 0; r < m; r++) vis[idx[r]] = v2[r];
}

/* The visibility of n segments: none blocks without candidates; lists of at most
 * CAND_BRUTE_MAX surfaces are tested exactly on the unlifted ends (skipping the pair's own
 * surfaces); longer lists and no list go to Embree (behind the cache when there is one). */
static void cast(const hr_vf_ctx *c, const int32_t *cand, int ncand, hr_blockers *blk, int n,
                 const float *org, const float *dst, int sa, int sb, uint8_t *vis) {
  if (ncand == 0)
    memset(vis, 1, (size_t)n);
  else if (ncand > 0 && ncand <= CAND_BRUTE_MAX)
    hr_vis_segments_cand(c->scene, cand, ncand, n, org, dst, sa, sb, vis);
  else if (blk)
    cast_cached(c, blk, n, org, dst, sa, sb, vis);
  else
    hr_vis_segments(c->vis, n, org, dst, -1, -1, vis);
}

double hr_vf_pair(const hr_vf_ctx *c, hr_vf_elem a, hr_vf_elem b, const int32_t *cand, int ncand,
                  int k, int stream, hr_blockers *blk, int64_t *rays) {
  if (ncand == 0) return 1.0;
  /* Order the pair by gid so that H(a,b) == H(b,a). */
  if (a.gid > b.gid) {
    hr_vf_elem t = a;
    a = b;
    b = t;
  }
  const hr_ff_elem *ga = a.g, *gb = b.g;
  const double invk = 1.0 / k; /* exact for the default k = 16 */
  const double reg = (ga->area + gb->area) * invk / (2 * M_PI);
  /* Segments cast with Embree start and end a few float ulps in front of their elements (lift
   * along each normal; a sample counts only when each end is in front of the other element, so
   * the segment leaves both planes on their front sides). After rounding to float, the segment
   * then crosses neither surface's plane between its ends and cannot hit either surface, so no
   * per-hit filter is needed to skip them. The exact candidate-list test works on the exact
   * points and skips the two surfaces by id. */
  const int lifted = ncand < 0 || ncand > CAND_BRUTE_MAX;
  const hr_vec3 la = v3_scale(ga->n, lifted ? c->lift : 0), lb = v3_scale(gb->n, lifted ? c->lift : 0);
  const uint64_t key = hr_hash4(c->seed, a.gid, b.gid, 2 + (uint64_t)stream);
  float org[CHUNK * 3], dst[CHUNK * 3];
  uint8_t vis[CHUNK];
  double w[CHUNK];
  double wsum = 0, wvis = 0;
  /* Sample index i runs on until k samples count (or 8k were drawn: the front parts are then
   * a sliver and H hardly matters), so that H always rests on k segments. */
  int i = 0, counted = 0;
  const int maxi = 8 * k;
  while (counted < k && i < maxi) {
    int n = 0;
    for (; n < CHUNK && counted + n < k && i < maxi; i++) {
      double uv[4];
      sample_params(key, i, k, invk, uv);
      hr_vec3 x = elem_point(ga, uv[0], uv[1]), y = elem_point(gb, uv[2], uv[3]);
      /* Only the parts of the two elements in front of each other exchange light: a sample
       * with an end behind the other element's plane does not count (when an element straddles
       * the other's plane, such segments run through whatever solid the straddled surface
       * bounds). */
      double wq = seg_weight(x, ga->n, y, gb->n, reg);
      if (wq == 0) continue;
      w[n] = wq;
      put3(org + 3 * n, v3_add(x, la));
      put3(dst + 3 * n, v3_add(y, lb));
      n++;
    }
    if (n == 0) continue;
    cast(c, cand, ncand, blk, n, org, dst, a.surf, b.surf, vis);
    for (int q = 0; q < n; q++) {
      wsum += w[q];
      wvis += vis[q] ? w[q] : 0;
    }
    counted += n;
    *rays += n;
  }
  /* No sample counted: the front parts are slivers. That is no evidence of blocking: H = 1
   * keeps the link, whose unoccluded form factor is then almost surely 0. */
  return wsum > 0 ? wvis / wsum : 1.0;
}

/* 1 if point y of the plane of element e lies inside it (convex, corners in either order). */
static int elem_contains(const hr_ff_elem *e, hr_vec3 y) {
  int pos = 0, neg = 0;
  for (int k = 0; k < e->nv; k++) {
    const hr_vec3 a = e->p[k], b = e->p[(k + 1) % e->nv];
    const double d = v3_dot(v3_cross(v3_sub(b, a), v3_sub(y, a)), e->n);
    pos |= d > 0;
    neg |= d < 0;
  }
  return !(pos && neg);
}

/* Trials per counted sample before hr_vf_pair_land gives up on its estimator: a landing chance
 * below 1/LAND_TRIALS is far below what the caller picks it for (HR_VF_LAND_MIN). */
#define LAND_TRIALS 64

double hr_vf_pair_land(const hr_vf_ctx *c, hr_vf_elem a, hr_vf_elem b, const int32_t *cand,
                       int ncand, int k, int stream, hr_blockers *blk, int64_t *rays) {
  if (ncand == 0) return 1.0;
  /* Rays leave the smaller element (by area, then gid): the pair, not the call, decides. */
  if (b.g->area < a.g->area || (b.g->area == a.g->area && b.gid < a.gid)) {
    hr_vf_elem t = a;
    a = b;
    b = t;
  }
  const hr_ff_elem *ga = a.g, *gb = b.g;
  const double invk = 1.0 / k;
  const int lifted = ncand < 0 || ncand > CAND_BRUTE_MAX;
  const double lift = lifted ? c->lift : 0;
  const hr_vec3 la = v3_scale(ga->n, lift), lb = v3_scale(gb->n, lift);
  hr_vec3 t1 = fabs(ga->n.x) < 0.9 ? (hr_vec3){1, 0, 0} : (hr_vec3){0, 1, 0};
  const hr_vec3 e1 = v3_norm(v3_cross(ga->n, t1)), e2 = v3_cross(ga->n, e1);
  const uint64_t key = hr_hash4(c->seed, a.gid, b.gid, 64 + (uint64_t)stream);
  float org[CHUNK * 3], dst[CHUNK * 3];
  uint8_t vis[CHUNK];
  int landed = 0, seen = 0, i = 0;
  const int maxi = LAND_TRIALS * k;
  while (landed < k && i < maxi) {
    int n = 0;
    for (; n < CHUNK && landed + n < k && i < maxi; i++) {
      double uv[4];
      sample_params(key, i, k, invk, uv);
      /* a point of a, a cosine-distributed direction: rays that land on b sample b with the
       * density of the form-factor kernel */
      const hr_vec3 x = elem_point(ga, uv[0], uv[1]);
      const double phi = 2 * M_PI * uv[3], sr = sqrt(uv[2]);
      const hr_vec3 d = v3_add(v3_scale(ga->n, sqrt(1 - uv[2])),
                               v3_add(v3_scale(e1, sr * cos(phi)), v3_scale(e2, sr * sin(phi))));
      const double dn = v3_dot(d, gb->n), h = v3_dot(v3_sub(x, gb->p[0]), gb->n);
      if (!(dn < 0 && h > 0)) continue; /* b's back, or x behind b's plane */
      const hr_vec3 y = v3_add(x, v3_scale(d, -h / dn));
      if (!elem_contains(gb, y)) continue;
      put3(org + 3 * n, v3_add(x, la));
      put3(dst + 3 * n, v3_add(y, lb));
      n++;
    }
    if (n == 0) continue;
    cast(c, cand, ncand, blk, n, org, dst, a.surf, b.surf, vis);
    for (int q = 0; q < n; q++) seen += vis[q] != 0;
    landed += n;
    *rays += n;
  }
  /* Too few landed: b is a sliver as seen from a; the kernel-weighted estimator decides. */
  if (landed < k) return hr_vf_pair(c, a, b, cand, ncand, k, stream, blk, rays);
  return (double)seen / landed;
}

void hr_vf_batch(const hr_vf_ctx *c, hr_vf_elem a, const hr_vf_elem *bs, const int *ks, int np,
                 int stream, hr_blockers *blk, int64_t *rays, double *h) {
  enum { MAXSEG = HR_VF_BATCH_SEGS };
  float org[MAXSEG * 3], dst[MAXSEG * 3], o2[MAXSEG * 3], d2[MAXSEG * 3];
  uint8_t vis[MAXSEG], v2[MAXSEG];
  double w[MAXSEG];
  int first[HR_VF_BATCH_PAIRS + 1], idx[MAXSEG];
  const hr_ff_elem *ga = a.g;
  const hr_vec3 la = v3_scale(ga->n, c->lift);
  int nseg = 0, m = 0;
  for (int q = 0; q < np; q++) {
    const hr_ff_elem *gb = bs[q].g;
    const int k = ks[q];
    const double invk = 1.0 / k;
    const double reg = (ga->area + gb->area) * invk / (2 * M_PI);
    const hr_vec3 lb = v3_scale(gb->n, c->lift);
    const uint64_t key = hr_hash4(c->seed, a.gid, bs[q].gid, 2 + (uint64_t)stream);
    first[q] = nseg;
    h[q] = 0;
    for (int i = 0; i < k; i++) {
      double uv[4];
      sample_params(key, i, k, invk, uv);
      hr_vec3 x = elem_point(ga, uv[0], uv[1]), y = elem_point(gb, uv[2], uv[3]);
      double wq = seg_weight(x, ga->n, y, gb->n, reg);
      if (wq == 0) {
        h[q] = -1; /* a sample that does not count: left to hr_vf_pair */
        nseg = first[q];
        break;
      }
      w[nseg] = wq;
      put3(org + 3 * nseg, v3_add(x, la));
      put3(dst + 3 * nseg, v3_add(y, lb));
      nseg++;
    }
    if (h[q] < 0) continue;
    /* The cache first (the pair's own surfaces cannot block: both ends are lifted in front of
     * them); what is still open waits for one Embree call for the whole batch. */
    const int f = first[q], n = nseg - f;
    const float *of = org + 3 * f, *df = dst + 3 * f;
    int from = cache_first(c, blk, n, of, df, a.surf, -1, vis + f);
    collect_open(n, from, f, of, df, vis + f, o2, d2, idx, &m);
  }
  first[np] = nseg;
  if (nseg == 0) return;
  *rays += nseg;
  if (m > 0) {
    hr_vis_segments(c->vis, m, o2, d2, -1, -1, v2);
    for (int r = 0; r < m; r++) vis[idx[r]] = v2[r];
  }
  for (int q = 0; q < np; q++) {
    if (h[q] < 0) continue;
    double ws = 0, wv = 0;
    for (int i = first[q]; i < first[q + 1]; i++) {
      ws += w[i];
      wv += vis[i] ? w[i] : 0;
    }
    h[q] = ws > 0 ? wv / ws : 1.0;
  }
}

double hr_vf_open(const hr_vf_ctx *c, hr_vf_elem e, int m) {
  const hr_ff_elem *g = e.g;
  const hr_vec3 lift = v3_scale(g->n, c->lift);
  const float dir[3] = {(float)g->n.x, (float)g->n.y, (float)g->n.z};
  const uint64_t key = hr_hash4(c->seed, e.gid, e.gid, 1);
  int open = 0;
  for (int i = 0; i < m; i++)
    for (int j = 0; j < m; j++) {
      uint64_t h = mix64(key + (uint64_t)(i * m + j + 1) * UINT64_C(0x9e3779b97f4a7c15));
      hr_vec3 x = v3_add(elem_point(g, (i + unit16(h, 0)) / m, (j + unit16(h, 16)) / m), lift);
      float org[3];
      put3(org, x);
      float t;
      int hit = hr_vis_hit(c->vis, org, dir, INFINITY, &t);
      open += hit < 0 || v3_dot(c->scene->surfs[hit].normal, g->n) < 0;
    }
  return (double)open / (m * m);
}
