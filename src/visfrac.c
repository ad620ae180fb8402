/* ff.c: form factors (paper 1.2, equation 2) and the visible fraction H_ij.
 *
 * F_ij = H_ij * cos(theta_i) cos(theta_j) A_j / (pi r^2 + A_j): the point-to-disk form factor of
 * Wallace et al. (the paper's reference [12]) from the receiver's centre to a disk of the
 * source's area. The paper prints A_i in the denominator; the cited formula has the source area,
 * which is what makes it tend to 1 as the receiver approaches a large source. H_ij is the
 * fraction of k segments between jittered points on the two elements that no candidate blocker
 * cuts. The jitter comes from a counter-based hash of (seed, element gids, sample index), so the
 * estimate does not depend on call order or thread, and it is symmetric in the two elements. */
#include "solver_impl.h"
#include "vec.h"

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

double hr_ff_unoccluded(const hr_solver *s, const hr_elem *r, const hr_elem *j) {
  const hr_surface *fr = &s->scene->surfs[r->surf], *fj = &s->scene->surfs[j->surf];
  hr_vec3 d = v3_sub(j->c, r->c);
  double r2 = v3_dot(d, d);
  if (!(r2 > 0)) return 0;
  double inv = 1.0 / sqrt(r2);
  double ci = v3_dot(fr->normal, d) * inv, cj = -v3_dot(fj->normal, d) * inv;
  if (ci <= 0 || cj <= 0) return 0;
  return ci * cj * j->area / (M_PI * r2 + j->area);
}

/* Point on element 'e' at parameters (u, v) in [0,1)^2 (triangles fold the square). */
static inline hr_vec3 elem_point(const hr_elem *e, int nverts, double u, double v) {
  if (nverts == 4) {
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

#define CAND_BRUTE_MAX 16 /* lists this short are tested directly (measured 45-60 Mrays/s) */
#define CHUNK 64

/* Tests n segments against the blocker cache (vis[i] = 0: closed). When some stay open, the
 * first of them goes to Embree at once as a nearest-hit query: a blocker it finds joins the
 * cache and closes what it can of the rest, so the next pairs of the row, hidden by the same
 * walls, find it there; an open one is visible (vis = 1). Returns the index after which open
 * segments are still undecided (n when none are). */
static int cache_first(const hr_solver *s, hr_blockers *blk, int n, const float *org,
                       const float *dst, int sa, int sb, uint8_t *vis) {
  memset(vis, 1, (size_t)n);
  if (hr_blockers_test(blk, n, org, dst, sa, sb, vis) == 0) return n;
  int i0 = 0;
  while (!vis[i0]) i0++;
  int hit = hr_vis_first_hit(s->vis, org + 3 * i0, dst + 3 * i0);
  vis[i0] = hit < 0;
  if (hit >= 0) {
    hr_blockers_add(blk, s->scene, hit);
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
static void cast_cached(const hr_solver *s, hr_blockers *blk, int n, const float *org,
                        const float *dst, int sa, int sb, uint8_t *vis) {
  int from = cache_first(s, blk, n, org, dst, sa, sb, vis);
  float o2[CHUNK * 3], d2[CHUNK * 3];
  int idx[CHUNK], m = 0;
  uint8_t v2[CHUNK];
  collect_open(n, from, 0, org, dst, vis, o2, d2, idx, &m);
  if (m == 0) return;
  hr_vis_segments(s->vis, m, o2, d2, -1, -1, v2);
  for (int r = 0; r < m; r++) vis[idx[r]] = v2[r];
}

double hr_ff_visibility(const hr_solver *s, const hr_elem *a, const hr_elem *b,
                        const int32_t *cand, int ncand, int k, hr_blockers *blk, int64_t *rays,
                        double fmc[2]) {
  if (ncand == 0 && !fmc) return 1.0;
  /* Order the pair by gid so that H(a,b) == H(b,a); fmc follows the caller's order. */
  int swapped = a->gid > b->gid;
  if (swapped) {
    const hr_elem *t = a;
    a = b;
    b = t;
  }
  /* Ray-cast point-to-disk sums (Wallace et al.), over all samples drawn: kab for a receiving
   * from b, kba for b receiving from a. */
  double kab = 0, kba = 0;
  if (k <= 0) k = s->opt.rays;
  const double invk = 1.0 / k; /* exact for the default k = 16 */
  int visible = 0, counted = 0;
  const hr_vec3 na = s->scene->surfs[a->surf].normal, nb = s->scene->surfs[b->surf].normal;
  const int nva = s->scene->surfs[a->surf].nverts, nvb = s->scene->surfs[b->surf].nverts;
  /* Segments cast with Embree start and end a few float ulps in front of their elements (s->lift
   * along each normal; a sample counts only when each end is in front of the other element, so
   * the segment leaves both planes on their front sides). After rounding to float, the segment
   * then crosses neither surface's plane between its ends and cannot hit either surface, so no
   * per-hit filter is needed to skip them. The exact candidate-list test works on the exact
   * points and skips the two surfaces by id. */
  const int embree = ncand < 0 || ncand > CAND_BRUTE_MAX;
  const hr_vec3 la = v3_scale(na, s->lift), lb = v3_scale(nb, s->lift);
  /* One hash of (seed, pair) keys the pair; each sample's two words are one mix away. */
  uint64_t key = hr_hash4(s->opt.seed, a->gid, b->gid, 0);
  float org[CHUNK * 3], dst[CHUNK * 3];
  uint8_t vis[CHUNK];
  double wab[CHUNK], wba[CHUNK];
  /* Sample index i runs on until k samples count (or 8k were drawn: the front parts are then
   * a sliver and H hardly matters), so that H always rests on k segments. */
  int i = 0, maxi = 8 * k;
  while (counted < k && i < maxi) {
    int n = 0;
    for (; n < CHUNK && counted + n < k && i < maxi; i++) {
      double uv[4];
      sample_params(key, i, k, invk, uv);
      hr_vec3 p = elem_point(a, nva, uv[0], uv[1]), t = elem_point(b, nvb, uv[2], uv[3]);
      /* Only the parts of the two elements in front of each other exchange light: a sample
       * with an end behind the other element's plane is not counted (when an element straddles
       * the other's plane, such segments run through whatever solid the straddled surface
       * bounds, and would make H a matter of chance). */
      if (v3_dot(v3_sub(p, b->c), nb) <= 0 || v3_dot(v3_sub(t, a->c), na) <= 0) continue;
      int q = n++;
      if (fmc) {
        hr_vec3 d = v3_sub(t, p);
        double r2 = v3_dot(d, d), ca = v3_dot(na, d), cb = -v3_dot(nb, d);
        if (ca > 0 && cb > 0 && r2 > 0) {
          double g = ca * cb / r2; /* cos_a cos_b times r^2 */
          wab[q] = g / (M_PI * r2 + b->area / k);
          wba[q] = g / (M_PI * r2 + a->area / k);
        } else {
          wab[q] = wba[q] = 0;
        }
      }
      if (embree) {
        p = v3_add(p, la);
        t = v3_add(t, lb);
      }
      org[3 * q] = (float)p.x;
      org[3 * q + 1] = (float)p.y;
      org[3 * q + 2] = (float)p.z;
      dst[3 * q] = (float)t.x;
      dst[3 * q + 1] = (float)t.y;
      dst[3 * q + 2] = (float)t.z;
    }
    if (n == 0) continue;
    if (ncand == 0)
      memset(vis, 1, (size_t)n);
    else if (embree && blk)
      cast_cached(s, blk, n, org, dst, a->surf, b->surf, vis);
    else if (embree)
      hr_vis_segments(s->vis, n, org, dst, -1, -1, vis);
    else
      hr_vis_segments_cand(s->scene, cand, ncand, n, org, dst, a->surf, b->surf, vis);
    for (int q = 0; q < n; q++) {
      visible += vis[q];
      if (fmc && vis[q]) {
        kab += wab[q];
        kba += wba[q];
      }
    }
    counted += n;
    if (ncand != 0) *rays += n;
  }
  if (fmc) {
    /* Each drawn sample stands for 1/i of both areas: F_ab ~ A_b/i sum(cos cos / (pi r^2 +
     * A_b/k)) over the visible front-facing ones. */
    double fab = i > 0 ? b->area * kab / i : 0, fba = i > 0 ? a->area * kba / i : 0;
    fmc[0] = swapped ? fba : fab;
    fmc[1] = swapped ? fab : fba;
  }
  /* No sample counted: the front parts are slivers. That is no evidence of blocking: H = 1
   * keeps the link, whose centre form factor is then almost surely 0; the refinement oracle
   * bounds it, and its children sample their own front parts. */
  return counted > 0 ? (double)visible / counted : 1.0;
}

/* Visible fractions of 'np' pairs (a, bs[q]) with ks[q] rays each, for initial linking: no
 * candidate lists (Embree behind the blocker cache), a->gid < bs[q]->gid, and no straddle
 * estimate. Samples, segments and H are those hr_ff_visibility computes when every sample counts;
 * what the cache leaves open is cast in one call for the whole batch, so Embree gets full
 * packets. A pair with a sample that does not count gets h[q] = -1: the caller computes it with
 * hr_ff_visibility, which draws further samples. */
void hr_ff_visibility_batch(const hr_solver *s, const hr_elem *a, const hr_elem *const *bs,
                            const int *ks, int np, hr_blockers *blk, int64_t *rays, double *h) {
  enum { MAXSEG = HR_FF_BATCH_SEGS };
  float org[MAXSEG * 3], dst[MAXSEG * 3], o2[MAXSEG * 3], d2[MAXSEG * 3];
  uint8_t vis[MAXSEG], v2[MAXSEG];
  int first[HR_FF_BATCH_PAIRS + 1], idx[MAXSEG];
  const hr_vec3 na = s->scene->surfs[a->surf].normal;
  const int nva = s->scene->surfs[a->surf].nverts;
  const hr_vec3 la = v3_scale(na, s->lift);
  int nseg = 0, m = 0;
  for (int q = 0; q < np; q++) {
    const hr_elem *b = bs[q];
    const int k = ks[q];
    const double invk = 1.0 / k;
    const hr_vec3 nb = s->scene->surfs[b->surf].normal, lb = v3_scale(nb, s->lift);
    const int nvb = s->scene->surfs[b->surf].nverts;
    const uint64_t key = hr_hash4(s->opt.seed, a->gid, b->gid, 0);
    first[q] = nseg;
    h[q] = 0;
    for (int i = 0; i < k; i++) {
      double uv[4];
      sample_params(key, i, k, invk, uv);
      hr_vec3 p = elem_point(a, nva, uv[0], uv[1]), t = elem_point(b, nvb, uv[2], uv[3]);
      if (v3_dot(v3_sub(p, b->c), nb) <= 0 || v3_dot(v3_sub(t, a->c), na) <= 0) {
        h[q] = -1; /* a sample that does not count: left to hr_ff_visibility */
        nseg = first[q];
        break;
      }
      p = v3_add(p, la);
      t = v3_add(t, lb);
      float *o = org + 3 * nseg, *d = dst + 3 * nseg;
      o[0] = (float)p.x, o[1] = (float)p.y, o[2] = (float)p.z;
      d[0] = (float)t.x, d[1] = (float)t.y, d[2] = (float)t.z;
      nseg++;
    }
    if (h[q] < 0) continue;
    /* The cache first (the pair's own surfaces cannot block: both ends are lifted in front of
     * them); what is still open waits for one Embree call for the whole batch. */
    const int f = first[q], n = nseg - f;
    const float *of = org + 3 * f, *df = dst + 3 * f;
    int from = cache_first(s, blk, n, of, df, a->surf, -1, vis + f);
    collect_open(n, from, f, of, df, vis + f, o2, d2, idx, &m);
  }
  first[np] = nseg;
  if (nseg == 0) return;
  *rays += nseg;
  if (m > 0) {
    hr_vis_segments(s->vis, m, o2, d2, -1, -1, v2);
    for (int r = 0; r < m; r++) vis[idx[r]] = v2[r];
  }
  for (int q = 0; q < np; q++) {
    if (h[q] < 0) continue;
    int visible = 0;
    for (int i = first[q]; i < first[q + 1]; i++) visible += vis[i];
    h[q] = (double)visible / ks[q];
  }
}
