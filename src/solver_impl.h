/* solver_impl.h: the solver's internal data model (paper 2.2: the patch/link graph).
 *
 * Elements (patches) are nodes of per-surface quadtrees kept in growable arrays and referred to by
 * index ('idx'); each also has a stable global id ('gid') computed from its surface and its path
 * in the tree, so that a later distributed version can name an element on any process. Geometry
 * is a pure function of (surface, lattice corners); radiosity state lives in separate arrays.
 * Links are an array of (receiver, source, F, H, candidate list) records; candidate lists are
 * ranges of one int32 pool. Nothing here is a pointer graph. */
#ifndef HR_SOLVER_IMPL_H
#define HR_SOLVER_IMPL_H

#include "hrad.h"
#include "vis.h"

#include <stdint.h>

/* Deepest quadtree level: a gid holds the surface in its top 23 bits and the path as a heap index
 * (1 sentinel bit + 2 bits per level) in the low 41 bits. */
#define HR_GID_DEPTH 20
#define HR_GID_PATH_BITS 41

/* Loops shorter than this run on one thread: a parallel region costs more than the work. */
#define PAR_MIN 100000

typedef struct hr_elem {
  uint64_t gid;
  int32_t surf;
  int32_t parent; /* idx, -1 at the root */
  int32_t child;  /* idx of the first of 4 consecutive children, -1 for a leaf */
  int32_t depth;
  uint32_t lat[4][2];
  hr_vec3 p[4];   /* world corners (p[3] unused for triangles) */
  hr_vec3 c;      /* centroid */
  double area;
} hr_elem;

typedef struct hr_link {
  int32_t r, s;       /* receiver and source element idx */
  float F;            /* form factor of eq. (2) times H */
  float H;            /* visible fraction */
  float Fu;           /* eq. (2) at the centres, unoccluded (for the refinement oracle) */
  uint32_t cand_off;  /* candidate blockers: pool[cand_off .. cand_off+ncand) */
  int32_t ncand;
} hr_link;

struct hr_solver {
  const hr_scene *scene;
  hr_options opt;
  hr_vis *vis;
  hr_shaft_index *shaft;
  double emax;        /* largest emitted radiosity: the unit of BF_e and B_e */
  double area_total;
  double area_min;    /* A_e in scene units */
  double lift;        /* offset of ray ends off their surfaces, scene units */
  /* elements */
  hr_elem *el;
  int64_t nel, cap_el;
  double (*B)[3];     /* radiosity per element */
  double (*G)[3];     /* gathered (irradiance-like, before rho) per element */
  double (*rho)[3];   /* reflectance per element (its surface's), beside B for the oracle */
  double *rho_max;    /* largest channel of rho per element */
  /* Links. [0, nsorted) are grouped by receiver: rstart[idx]..rstart[idx+1] (rstart has
   * nrstart+1 entries; elements created since have none there). Links refined away in an
   * incremental pass stay in place, dead (H < 0, F = 0), until the next full sort; their
   * descendants are appended after nsorted ("extra" links), grouped by receiver in
   * xstart/xidx. All orders follow from the data alone, never from thread scheduling. */
  hr_link *links;
  int64_t nlinks, cap_links;
  int32_t *pool;
  int64_t npool, cap_pool;
  int64_t *rstart, nrstart;
  int64_t nsorted, ndead;
  int64_t *xstart, *xidx; /* extras by receiver: xidx[xstart[e]..xstart[e+1]) index links */
  int sorted;             /* 0: a full sort is due */
  /* For the decision pass, per sorted link: its source and the oracle's form factor rounded up
   * to float (0 for dead links). */
  int32_t *ls;
  float *lfo;
  /* counters */
  int64_t rays, initial_links;
  int iterations, converged, threads;
  hr_timing t;
  double t_start;
};

/* elem.c */
hr_status hr_elem_init(hr_solver *s);                  /* one root per surface, idx == surface */
hr_status hr_elem_subdivide(hr_solver *s, int32_t idx); /* creates 4 children if a leaf */

/* ff.c */
/* Unoccluded point-to-disk form factor of eq. (2) from receiver r to source j (source area A_j in
 * the denominator); 0 when the elements face away at their centres. */
double hr_ff_unoccluded(const hr_solver *s, const hr_elem *r, const hr_elem *j);
/* Visible fraction H between elements a and b with candidate list 'cand' (0 candidates: 1, no
 * rays; ncand < 0: no list, rays against the whole scene). Symmetric: H(a,b) == H(b,a) exactly.
 * Adds the number of rays cast to *rays. Only segments whose ends lie in front of the other
 * element count. If 'fmc' is non-NULL it receives the ray-cast point-to-disk form factors
 * (Wallace et al.) F(a <- b) and F(b <- a) over the same segments, for links whose centres face
 * away (eq. (2) gives 0 there although parts of the elements face each other). */
double hr_ff_visibility(const hr_solver *s, const hr_elem *a, const hr_elem *b,
                        const int32_t *cand, int ncand, int k, hr_blockers *blk, int64_t *rays,
                        double fmc[2]);
/* Batches of hr_ff_visibility_batch: at most this many pairs and segments (k <= 4096 each, so
 * a pair with more rays than HR_FF_BATCH_SEGS goes alone through hr_ff_visibility). */
#define HR_FF_BATCH_PAIRS 32
#define HR_FF_BATCH_SEGS 256
void hr_ff_visibility_batch(const hr_solver *s, const hr_elem *a, const hr_elem *const *bs,
                            const int *ks, int np, hr_blockers *blk, int64_t *rays, double *h);
/* Counter-based hash of (seed, a, b, i): the only source of randomness. */
uint64_t hr_hash4(uint64_t seed, uint64_t a, uint64_t b, uint64_t i);

/* link.c */
hr_status hr_link_init(hr_solver *s, hr_err *err);          /* paper 2.2.1 */
/* One refinement pass at threshold 'bf_e' (relative); returns new link count through 'nnew'. */
hr_status hr_link_refine(hr_solver *s, double bf_e, int64_t *nnew, hr_err *err); /* 2.2.2 */
hr_status hr_link_sort(hr_solver *s); /* groups links by receiver (rstart, xstart/xidx) */

/* solve.c */
double hr_now(void);

#endif
