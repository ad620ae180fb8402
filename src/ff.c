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

static inline double unit(uint64_t h) { return (double)(h >> 11) * (1.0 / 9007199254740992.0); }

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

#define CAND_BRUTE_MAX 6 /* lists this short are tested directly instead of through Embree */
#define CHUNK 64

double hr_ff_visibility(const hr_solver *s, const hr_elem *a, const hr_elem *b,
                        const int32_t *cand, int ncand, int64_t *rays) {
  if (ncand == 0) return 1.0;
  /* Order the pair by gid so that H(a,b) == H(b,a). */
  if (a->gid > b->gid) {
    const hr_elem *t = a;
    a = b;
    b = t;
  }
  int k = s->opt.rays;
  int visible = 0;
  float org[CHUNK * 3], dst[CHUNK * 3];
  uint8_t vis[CHUNK];
  for (int i0 = 0; i0 < k; i0 += CHUNK) {
    int n = k - i0 < CHUNK ? k - i0 : CHUNK;
    for (int q = 0; q < n; q++) {
      int i = i0 + q;
      uint64_t h1 = hr_hash4(s->opt.seed, a->gid, b->gid, (uint64_t)i * 2);
      uint64_t h2 = hr_hash4(s->opt.seed, a->gid, b->gid, (uint64_t)i * 2 + 1);
      /* Stratified in the first parameter of each end, uniform in the second. */
      double ua = (i + unit(h1)) / k, va = unit(h1 << 26 | h1 >> 38);
      double ub = unit(h2), vb = ((i * 7 + 3) % k + unit(h2 << 26 | h2 >> 38)) / k;
      hr_vec3 p = hr_elem_point(s, a, ua, va), t = hr_elem_point(s, b, ub, vb);
      org[3 * q] = (float)p.x;
      org[3 * q + 1] = (float)p.y;
      org[3 * q + 2] = (float)p.z;
      dst[3 * q] = (float)t.x;
      dst[3 * q + 1] = (float)t.y;
      dst[3 * q + 2] = (float)t.z;
    }
    if (ncand < 0)
      hr_vis_segments(s->vis, n, org, dst, a->surf, b->surf, vis);
    else if (ncand <= CAND_BRUTE_MAX)
      hr_vis_segments_cand(s->scene, cand, ncand, n, org, dst, a->surf, b->surf, vis);
    else
      hr_vis_segments(s->vis, n, org, dst, a->surf, b->surf, vis);
    for (int q = 0; q < n; q++) visible += vis[q];
  }
  *rays += k;
  return (double)visible / k;
}
