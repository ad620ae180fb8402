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

#include "ff.h"
#include "hrad.h"
#include "vis.h"
#include "visfrac.h"

#include <math.h>
#include <stdint.h>

/* Deepest quadtree level: a gid holds the surface in its top 23 bits and the path as a heap index
 * (1 sentinel bit + 2 bits per level) in the low 41 bits. */
#define HR_GID_DEPTH 20
#define HR_GID_PATH_BITS 41

/* The oracle's reference radiosity (bref) is at least this fraction of the radiosity unit, so
 * that elements in the dark are not refined for light nobody sees (pushpull.c, cluster.c). */
#define HR_BREF_FLOOR 0.1

typedef struct hr_clusters hr_clusters;

/* Loops shorter than this run on one thread: a parallel region costs more than the work. */
#define PAR_MIN 100000

/* x rounded up to float: the compact bounds that the refinement oracles test before their exact
 * tests (link.c, cluster.c) never fall below what they bound. */
static inline float hr_float_up(double x) {
  const float xf = (float)x;
  return (double)xf < x ? nextafterf(xf, INFINITY) : xf;
}

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
  float F;            /* form factor: unoccluded quadrature times the visible fraction H */
  float Fu;           /* the unoccluded form factor (quadrature); < 0: dead (refined away) */
  float dF;           /* how much the received light may vary over the receiver, as a form
                         factor: the refinement oracle's receiver measure (see link.c) */
  float dS;           /* how much the received light depends on where on the source it comes
                         from, as a form factor: the oracle's source measure (see link.c) */
  float w[4];         /* source shares: how the link's light divides among the four children of
                         its source (w[0] < 0: none); once the source has children, the link
                         gathers their radiosities with these weights instead of the source's
                         mean (link.c, source_shares) */
  uint32_t cand_off;  /* candidate blockers: pool[cand_off .. cand_off+ncand) */
  int32_t ncand;
} hr_link;

/* hr_solver.lazy: refine at every iteration; gather until B converges, then refine; or
 * refinement has settled at this BF_e (docs/design.md, "Lazy refinement"). */
enum { HR_REFINE_EVERY, HR_REFINE_LAZY, HR_REFINE_SETTLED };

/* hr_solver.xmode: what push-pull does with a leaf's new radiosity besides storing it: nothing,
 * keep it as the window's first or second sample, or extrapolate from them (pushpull.c). In a
 * window of iterations without new links, counted from 1, samples are taken at 1 and 3 modulo
 * HR_XPERIOD and the extrapolation at 0: 5, the shortest period whose samples all follow the
 * last jump (measured on the conference room: 108 iterations, against 121 every 8). */
enum { HR_X_NONE, HR_X_SAMPLE0, HR_X_SAMPLE1, HR_X_APPLY };
#define HR_XPERIOD 5

/* A leaf's radiosity above this many times E_max / (1 - rho_max) is an error (solve.c,
 * check_physical): the slack leaves room for the discretisation (closed boxes' row sums, about
 * 0.8% above 1, move B = E / (1 - rho) by 18% at rho 0.95). */
#define HR_BOUND_SLACK 2.0

struct hr_solver {
  const hr_scene *scene;
  hr_options opt;
  hr_vis *vis;
  hr_shaft_index *shaft;
  hr_vf_ctx vf;       /* what the visible-fraction estimator needs (scene, vis, lift, seed) */
  double unit;        /* radiosity unit of B_e and of the oracle's floor: the area-weighted mean
                         radiosity of the latest solution (largest channel), at least the mean
                         emitted radiosity */
  double area_total;
  double area_min;    /* A_e in scene units */
  double b_eps;       /* B_eps in effect (hr_options.b_eps, or BF_low at most B_max) */
  /* elements */
  hr_elem *el;
  int64_t nel, cap_el;
  double (*B)[3];     /* radiosity per element */
  double (*Bs)[3];    /* the radiosity it sends, E + (B - E) / open: its open part (hr_vf_open)
                         reflects what the whole element gathers; links gather this */
  double (*G)[3];     /* gathered (irradiance-like, before rho) per element */
  double *Gu;         /* gathered without occlusion, largest channel of the sources: sum of
                         Fu max(B_j), for the oracle's reference radiosity (bref) */
  double *Gf;         /* sum of the element's own links' form factors (what it sees) */
  double *Gv;         /* sum over the element's own links of dF max(B_j): how much the light
                         they bring may vary over it (a leaf's bvar, see pushpull.c) */
  double (*rho)[3];   /* reflectance per element (its surface's), beside B for the oracle */
  double *rho_max;    /* largest channel of rho per element */
  double *bref;       /* per element: the radiosity the oracle measures errors against: what
                         it would reflect with nothing in the way (rho_max times Gu here and at
                         its ancestors), at least BREF_FLOOR times the radiosity unit; set by
                         push-pull */
  double *open;       /* per element: the fraction of its area that light reaches and leaves
                         (hr_vf_open), estimated when it is created */
  float *erays;       /* per element: rays cast in refinement for links it receives (this
                         rank's share; balance.c's measured work) */
  double (*hist)[2][3]; /* per element: a leaf's radiosity at two earlier iterations of the
                         extrapolation window (pushpull.c); its owner's, moved and saved with
                         it */
  double *bvar;       /* per element: largest minus smallest radiosity of the leaves below it
                         (largest channel), from the latest push-pull; for a leaf, minus how
                         much its radiosity may vary over it, -rho_max Gv (<= 0: read only for
                         fine sources, link.c) */
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
  int64_t xfor[2];        /* nlinks and nel when xstart/xidx were built ({-1, -1}: not since
                             the last full sort) */
  /* For the decision pass, per sorted link: its source and max(dF, dS) rounded up to float (0
   * for dead links). */
  int32_t *ls;
  float *lfo;
  hr_clusters *cl;    /* clustering (cluster.c); NULL without */
  /* progress of Figure 3 (what a checkpoint holds beside the graph) */
  int started;        /* initial linking done */
  int done;           /* the last iteration has run */
  int stopped;        /* the caller's callback stopped the run */
  double bf_e;        /* BF_e of the next iteration */
  double prev_change; /* the last iteration's change at BF_low if it made no links, else 0 */
  double conv_first;  /* the first change at BF_low and the share of the way from it down to
                         b_eps done so far (track_convergence, solve.c): for progress reports
                         only, so not in checkpoints (a resumed run measures anew) */
  double conv_done;
  double stall_abs;   /* the largest change of B (absolute) where the contraction guard's
                         window began (check_contracting) */
  int64_t stall;      /* iterations in that window so far, none of them with new links (-1:
                         the window begins with the next iteration) */
  int lazy;           /* HR_REFINE_*: whether the next iteration refines (solve.c) */
  int refined;        /* the last iteration refined */
  int xwin;           /* iterations in a row without new links, the last one included: the
                         extrapolation window (pushpull.c) */
  int xmode;          /* the current push-pull's part in it: HR_X_* */
  int xlast;          /* the last iteration extrapolated */
  int xprev;          /* the one before the last did (the last one's step is not a contraction
                         step: solve.c reads no convergence from it) */
  double bphys;       /* E_max / (1 - rho_max) over the materials (infinite at rho_max 1): the
                         physical bound on radiosity, which check_physical (solve.c) holds
                         leaves to with HR_BOUND_SLACK, and extrapolation too; set in prepare */
  /* counters */
  int64_t rays, initial_links;
  int iterations, converged, threads;
  hr_timing t;
  double t_start;
  /* Distribution (docs/design.md, "Distribution"): NULL in one process. A rank holds the
   * elements it owns, every root, and ghosts: copies of other ranks' elements that it needs (the
   * sources of its links, the parents and children of its own elements, and their ancestors and
   * siblings, since the local tree is closed under parent and sibling). Elements are found by gid
   * (gmap); local indices differ between ranks and nothing depends on them. */
  hr_dist *dist;
  int32_t *eown;      /* per element: the rank that owns it and the links it receives */
  uint8_t *esub;      /* per ghost: 1 once this rank subscribed to its owner's stores */
  uint64_t *gkey;     /* gid -> idx map (open addressing, gkey 0 = empty) */
  int32_t *gval;
  int64_t gcap;       /* slots (a power of 2), at least 2 cap_el */
  int32_t (*subs)[2]; /* at the owner: (element idx, rank) pairs, ranks that hold a subscribed
                         ghost of its element and get its stores after every push-pull */
  int64_t nsubs, cap_subs;
  /* The owner function (hr_owner_of), the same on every rank: a rank drawn from (own_seed, gid)
   * when own_seed != 0, else the rank of the deepest ancestor listed in omap (sorted gid, rank
   * pairs; hr_solver_migrate), else rootown[surface]. */
  uint64_t own_seed;
  int own_given;   /* the caller chose the surfaces' ranks (hr_solver_set_dist's 'owner') */
  int64_t ncmoved; /* clusters given another owner by balancing (hr_cluster_set_owners) */
  int32_t *rootown;
  uint64_t (*omap)[2];
  int64_t nomap;
  int rank, nranks;
  int64_t g_links, g_rays, g_initial, g_leaves, g_nel; /* over all ranks */
  int64_t g_clinks;   /* cluster links over all ranks (g_links counts element links only) */
  double mpi_t[4];    /* seconds inside MPI per phase: init graph, refine, gather, push-pull */
  int64_t msgs, msg_bytes; /* point-to-point messages (batches) and bytes this rank sent */
  /* distributed runs: every leaf (gid order) gathered on rank 0 by hr_solver_collect */
  hr_leaf *coll;
  int64_t ncoll;
  /* graph balancing (balance.c): method, alpha of eq. (5), idle threshold, balancings done */
  int bal_method;
  double bal_alpha, bal_idle;
  int64_t nbalance, nmoved; /* balancings done, and those that moved elements */
  int bal_last;       /* the iteration after which it last balanced */
  int64_t bal_links;  /* the link count (all ranks) then */
  double iter_busy;   /* this rank's busy seconds in the last iteration (outside MPI) */
  double iter_wall;   /* wall seconds of the last iteration (balance.c's migration gate) */
  double t_migrate;   /* seconds the last migration took (rank 0), 0 before the first */
  double t_bal_last;  /* seconds the last balancing took on this rank (with its migration) */
  uint64_t migrate_seed; /* test hook HRAD_TEST_MIGRATE=SEED: new random owners every iteration */
  /* Test hook (HRAD_TEST_FAIL=RANK:PHASE:ITER, read by hr_solver_set_dist): rank 'fail_rank'
   * fails with "out of memory" in phase fail_phase (HR_PHASE_*) of iteration fail_iter (the
   * refinement phases: of the first iteration from fail_iter on that refines, solve.c). */
  int fail_rank, fail_phase, fail_iter;
};

enum { HR_PHASE_NONE, HR_PHASE_INIT, HR_PHASE_REFINE, HR_PHASE_PUSHPULL, HR_PHASE_CLUSTER };
/* The slack of a receiver of this area, by which the refinement oracles multiply its tolerance
 * (its reference radiosity bref): 1 down to a regular leaf's area A_e / 4, (A_e / 4 / area)^E
 * below it, E = --importance (docs/design.md, "Importance"). A degenerate receiver gets 1. */
static inline double hr_slack(const hr_solver *s, double area) {
  const double a0 = 0.25 * s->area_min, e = s->opt.importance;
  return e > 0 && area > 0 && area < a0 ? pow(a0 / area, e) : 1;
}

/* The area by which element 'idx' takes its slack: its own, but the root of a piece of a
 * surface cut along contact lines (hr_surface.cut) counts its polygon's: cutting does not make a
 * floor less important. */
static inline double hr_elem_imp_area(const hr_solver *s, int32_t idx) {
  const hr_elem *e = &s->el[idx];
  const hr_surface *f = &s->scene->surfs[e->surf];
  if (e->parent < 0 && f->cut)
    return fmax(e->area, s->scene->poly_area[f->poly]);
  return e->area;
}

/* 1 if the test hook makes this rank fail now, in 'phase'. */
static inline int hr_test_fail(const hr_solver *s, int phase) {
  const int it = s->iterations + 1;
  return s->fail_phase == phase && s->rank == s->fail_rank &&
         (phase == HR_PHASE_INIT || it == s->fail_iter ||
          (phase != HR_PHASE_PUSHPULL && it > s->fail_iter));
}

/* 1 if this rank owns element 'e' (always in one process). */
static inline int hr_owns(const hr_solver *s, int64_t e) {
  return !s->dist || s->eown[e] == s->rank;
}
/* The rank that owns the element with global id 'gid' (0 in one process). */
int32_t hr_owner_of(const hr_solver *s, uint64_t gid);
/* eown[] of every element again from hr_owner_of, after the rules it reads changed. */
void hr_owners_recompute(hr_solver *s);
/* 1 where a distributed run starts from a compact piece of the scene a rank, as graph balancing
 * wants (a method set, and the caller neither chose the surfaces' ranks nor scatters them):
 * spread_by_hierarchy (cluster.c) or spread_by_space (link.c), before any link exists. */
static inline int hr_start_compact(const hr_solver *s) {
  return s->dist && s->bal_method != HR_BALANCE_NONE && !s->own_seed && !s->own_given;
}
/* Makes every rank see a failure of any: returns 'st' where this rank failed, HR_ERR_REMOTE
 * (with a message) where another did, HR_OK where none did. A collective in distributed runs. */
hr_status hr_dist_agree(const hr_solver *s, hr_status st, hr_err *err);
/* The reported counts (links, rays, initial links) summed over the ranks: a collective. */
void hr_solver_sync_counts(hr_solver *s);
/* The iterations the run has left, estimated from the share of the BF_e schedule done so far,
 * and at most as many as are done (a cautious guess for what a balancing can earn back). */
double hr_solver_iters_left(const hr_solver *s);

/* elem.c */
hr_status hr_elem_init(hr_solver *s);                  /* one root per surface, idx == surface */
hr_status hr_elem_subdivide(hr_solver *s, int32_t idx); /* creates 4 children if a leaf */
/* The local index of element 'gid', or -1 when this rank does not hold it. */
int32_t hr_elem_find(const hr_solver *s, uint64_t gid);
/* The local index of element 'gid', creating it (and the missing ancestors and their siblings,
 * by subdivision: values copied from the parents) if needed; -1 for a gid that cannot be an
 * element of this scene, -2 when out of memory or past a limit. */
int32_t hr_elem_ensure(hr_solver *s, uint64_t gid);
/* Drops the elements with keep[e] == 0 (see elem.c for what 'keep' must satisfy). */
void hr_elem_compact(hr_solver *s, const uint8_t *keep);
/* Distributed runs: drops the ghosts this rank no longer needs (it keeps the roots, its own
 * elements, the sources of its links, their children, and what holds the tree together).
 * Subscriptions must be empty (the caller subscribes afresh). */
void hr_elem_prune(hr_solver *s);
/* Estimates the open fraction (hr_vf_open) of elements [lo, hi), in parallel; needs s->vis. */
void hr_elem_open(hr_solver *s, int64_t lo, int64_t hi);

/* 1 if links at element 'e' may move to its children: it has some (below A_e only where a fine
 * source was split, link.c), or it is above A_e and not at the deepest level. */
static inline int hr_elem_splittable(const hr_solver *s, const hr_elem *e) {
  return e->child >= 0 || (e->area > s->area_min && e->depth < HR_GID_DEPTH);
}

/* The geometry of element 'e' for the form-factor and visibility kernels. */
static inline hr_ff_elem hr_elem_geom(const hr_solver *s, const hr_elem *e) {
  const hr_surface *f = &s->scene->surfs[e->surf];
  hr_ff_elem g;
  g.nv = f->nverts;
  for (int k = 0; k < 4; k++) g.p[k] = e->p[k];
  g.n = f->normal;
  g.area = e->area;
  return g;
}

/* link.c */
hr_status hr_link_init(hr_solver *s, hr_err *err);          /* paper 2.2.1 */
/* One refinement pass at threshold 'bf_e' (relative); returns new link count through 'nnew'. */
hr_status hr_link_refine(hr_solver *s, double bf_e, int64_t *nnew, hr_err *err); /* 2.2.2 */
hr_status hr_link_sort(hr_solver *s); /* groups links by receiver (rstart, xstart/xidx) */
/* Clustering: the element link i <- j between elements of two surfaces (see link.c). */
int hr_link_pair(const hr_solver *s, int32_t i, int32_t j, hr_link *out, int64_t *rays);
/* Distributed runs (collectives): elements and links to their owners after the owner function
 * changed; and subscriptions of this rank's ghost sources at their owners. */
hr_status hr_link_migrate(hr_solver *s, hr_err *err);
hr_status hr_link_subscribe(hr_solver *s, hr_err *err);
/* Subscriptions of the ghost sources of the links s->links[lo, nlinks) and of the ghosts
 * elems[0, ne) (cluster links' sources); 'st' is this rank's status so far. A collective in
 * distributed runs (every rank returns the same status); returns st in one process. */
hr_status hr_link_subscribe_new(hr_solver *s, int64_t lo, const int32_t *elems, int64_t ne,
                                hr_status st, hr_err *err);
/* Subdivides the elements marked in mark[0, n) (own ones and ghosts; the owners of ghosts split
 * theirs, and tell the subscribers and the owners of the children), then the new own elements'
 * open fractions. A collective in distributed runs; every rank returns the same status. */
hr_status hr_link_split_marked(hr_solver *s, const uint8_t *mark, int64_t n, hr_err *err);

/* pushpull.c: push-pull of every tree ({14}); the largest change of B over the leaves in
 * '*maxc'. A collective in distributed runs (every rank gets the same status and maxc). */
hr_status hr_push_pull(hr_solver *s, double *maxc, hr_err *err);

/* solve.c */
double hr_now(void);

#endif
