/* visfrac.h: the visible fraction H_ij of a link (paper 1.2), estimated by rays between jittered
 * points of the two elements, on element geometry alone (no solver state). Internal API. */
#ifndef HR_VISFRAC_H
#define HR_VISFRAC_H

#include "ff.h"
#include "vis.h"

#include <stdint.h>

/* What the estimator needs of the scene: its surfaces (for candidate lists), the ray caster, the
 * lift of ray ends off their surfaces (hr_vis_lift) and the jitter seed. */
typedef struct hr_vf_ctx {
  const hr_scene *scene;
  const hr_vis *vis;
  double lift;
  uint64_t seed;
} hr_vf_ctx;

/* One end of a link: its geometry, its stable global id (which keys the jitter) and its surface
 * (which cannot block its own rays). */
typedef struct hr_vf_elem {
  const hr_ff_elem *g;
  uint64_t gid;
  int32_t surf;
} hr_vf_elem;

/* Counter-based hash of (seed, a, b, i): the only source of randomness. */
uint64_t hr_hash4(uint64_t seed, uint64_t a, uint64_t b, uint64_t i);

/* Kernel-weighted visible fraction between elements a and b: over k segments between jittered
 * points x on a and y on b that face each other (y in front of a, x in front of b; samples are
 * drawn until k count, at most 8k), H = sum w V / sum w with V = 1 for an unblocked segment and
 * the weight w = cos_a cos_b / (r^2 (r^2 + (A_a + A_b) / (2 pi k))) (the form-factor kernel,
 * regularised like the point-to-disk formula so that one sample near a shared edge does not
 * dominate). Weighting by the kernel makes the product F_unoccluded * H the occluded form factor
 * where visibility and the kernel vary together (a block standing on a floor). Blockers come from
 * the candidate list 'cand' (ncand surfaces; 0: H = 1 without rays) or, for ncand < 0, from
 * Embree behind the optional blocker cache 'blk'. Symmetric: H(a,b) == H(b,a) exactly. Adds the
 * segments cast to *rays. When no sample counts, returns 1 (the front parts are slivers; the
 * unoccluded form factor is then about 0 anyway). 'stream' selects one of independent sets of
 * samples (the solver decides with one and estimates with another, see link.c). This function
 * can't fail. */
double hr_vf_pair(const hr_vf_ctx *c, hr_vf_elem a, hr_vf_elem b, const int32_t *cand, int ncand,
                  int k, int stream, hr_blockers *blk, int64_t *rays);

/* hr_vf_pair with the samples drawn by the kernel instead of weighted by it: rays leave jittered
 * points of the smaller element in cosine-distributed directions, and those that land on the
 * other element count; H is the fraction of them unblocked. The weighted estimator rests on a
 * few samples near where the elements come closest when the kernel peaks there, and its ratio
 * is then biased toward the visibility of the rest (measured in `office`: a desk leg 4 cm from a
 * wall, H = 0.13 from 16 samples where 1024 give 0.96, as the wall above the leg is behind the
 * desk top); here every sample carries the same weight. Worth it where a ray from the smaller
 * element lands on the larger with some chance, the form factor from the smaller to the larger
 * at least HR_VF_LAND_MIN (near pairs); when fewer than k of 64 k tries land, it returns
 * hr_vf_pair's estimate. Symmetric, deterministic and can't fail, as hr_vf_pair. */
#define HR_VF_LAND_MIN 0.05
double hr_vf_pair_land(const hr_vf_ctx *c, hr_vf_elem a, hr_vf_elem b, const int32_t *cand,
                       int ncand, int k, int stream, hr_blockers *blk, int64_t *rays);

/* hr_vf_pair for 'np' pairs (a, bs[q]) with ks[q] samples each, without candidate lists (Embree
 * behind the blocker cache), a.gid < bs[q].gid: what the cache leaves open goes to Embree in one
 * call for the whole batch, in full packets. A pair with a sample that does not count gets
 * h[q] = -1: the caller then calls hr_vf_pair, which draws further samples. */
/* Fraction of element e's area that is open: points on it, lifted off along the front normal,
 * from which a ray along the normal leaves the scene or first meets the front of a surface. A
 * point from which it meets the back of a surface lies under a solid (a floor under a box
 * standing on it, a wall behind a cupboard) or a one-sided surface right in front of it (a
 * ceiling over a lamp): it gathers no light and sends none out. Estimated from m x m stratified
 * jittered points (1 when all are open). This function can't fail. */
double hr_vf_open(const hr_vf_ctx *c, hr_vf_elem e, int m);

#define HR_VF_BATCH_PAIRS 32
#define HR_VF_BATCH_SEGS 256
void hr_vf_batch(const hr_vf_ctx *c, hr_vf_elem a, const hr_vf_elem *bs, const int *ks, int np,
                 int stream, hr_blockers *blk, int64_t *rays, double *h);

#endif
