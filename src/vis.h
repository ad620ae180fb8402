/* vis.h: visibility between points on surfaces (paper 1.2: H_ij, the visible fraction, estimated
 * by rays) and shaft-culled candidate blocker lists (paper 2.2.1). Internal API.
 *
 * A "segment" runs from org to dst, both lying on surfaces of the scene. It is unoccluded when no
 * surface other than 'skip_a' and 'skip_b' (the receiver's and source's surfaces; -1 for none)
 * crosses it strictly between its ends (parameter t in [HR_VIS_EPS, 1 - HR_VIS_EPS]).
 * All functions here are thread-safe for concurrent calls on the same const objects. */
#ifndef HR_VIS_H
#define HR_VIS_H

#include "hrad.h"
#include <stdint.h>

#define HR_VIS_EPS 1e-5

typedef struct hr_vis hr_vis;

/* Builds the ray-casting structure (Embree 3, its own device with threads=1 so that hrad's
 * threads do the parallelism). On error returns non-OK with a message in 'err'. */
hr_status hr_vis_create(const hr_scene *s, hr_vis **out, hr_err *err);
void hr_vis_destroy(hr_vis **v);

/* Largest ratio of the scene's largest absolute coordinate to its size (bounding-box diagonal)
 * that ray casting in float resolves: measured on the Cornell box moved away from the origin,
 * polygon radiosities stay within 0.14% up to a ratio of 1450 and one is 7% off at 2900. */
#define HR_VIS_RANGE_MAX 1000.0
/* HR_ERR_INVALID, with a message, when the scene lies too far from the origin for its size. */
hr_status hr_vis_check_range(const hr_scene *s, hr_err *err);

/* Offset by which callers lift segment ends off their surfaces (along the front normal) so that
 * after rounding to float a segment cannot hit its own end surfaces and needs no skip filter:
 * 16 float epsilons of the scene's largest absolute coordinate. */
double hr_vis_lift(const hr_scene *s);

/* Tests 'n' segments (org[i] -> dst[i]; 3 floats each) with Embree, in packets; vis[i] = 1 when
 * unoccluded, else 0. Any n >= 0. */
void hr_vis_segments(const hr_vis *v, int n, const float *org, const float *dst, int skip_a,
                     int skip_b, uint8_t *vis);

/* The same test, brute force against only the surfaces listed in 'cand' (ncand of them). Exact
 * ray/polygon tests in double precision. */
void hr_vis_segments_cand(const hr_scene *s, const int32_t *cand, int ncand, int n,
                          const float *org, const float *dst, int skip_a, int skip_b,
                          uint8_t *vis);

/* The surface that blocks the segment nearest to org (Embree, ends as in hr_vis_segments and no
 * skipped surfaces), or -1 when it is unoccluded. */
int hr_vis_first_hit(const hr_vis *v, const float org[3], const float dst[3]);

/* Closest hit of the ray org + t dir, t in [0, tfar] (Embree, single precision, no skipped
 * surfaces, either face): returns the surface id and sets '*t' (in units of |dir|), or returns
 * -1 and leaves '*t' alone when nothing is hit. tfar may be INFINITY. Used by the reference path
 * tracer (pt.c), whose callers lift ray origins off their surface (hr_vis_lift). */
int hr_vis_hit(const hr_vis *v, const float org[3], const float dir[3], float tfar, float *t);

/* A small cache of recent blockers (HR_BLK_MAX surfaces, newest first), tested like
 * hr_vis_segments_cand (in single precision, as Embree tests) before a segment goes to Embree. Consecutive pairs from one surface are
 * mostly hidden by the same few walls, so most of their segments stop here. */
#define HR_BLK_MAX 8
typedef struct hr_blockers {
  int n; /* slots in use, newest first */
  int id[HR_BLK_MAX];
  /* Planes and inward edge planes in float: the cache only stands in for Embree, whose tests
   * are single precision too, and 8 lanes fit a vector. */
  float nx[HR_BLK_MAX], ny[HR_BLK_MAX], nz[HR_BLK_MAX], d[HR_BLK_MAX];
  float ex[4][HR_BLK_MAX], ey[4][HR_BLK_MAX], ez[4][HR_BLK_MAX], c[4][HR_BLK_MAX];
} hr_blockers;
void hr_blockers_clear(hr_blockers *b);
/* Adds surface 'id' (replacing the oldest entry when full); no-op if it is cached already. */
void hr_blockers_add(hr_blockers *b, const hr_scene *s, int id);
/* Sets vis[i] = 0 for the segments with vis[i] != 0 that a cached surface other than skip_a and
 * skip_b blocks; returns how many remain visible. */
int hr_blockers_test(const hr_blockers *b, int n, const float *org, const float *dst, int skip_a,
                     int skip_b, uint8_t *vis);

/* Slow reference: brute force against every surface of the scene. */
void hr_vis_segments_ref(const hr_scene *s, int n, const float *org, const float *dst,
                         int skip_a, int skip_b, uint8_t *vis);

/* ---- shaft culling (shaft.c) ----
 * The shaft of two convex polygons is (a conservative superset of) their convex hull. A surface
 * is a candidate blocker when it may intersect the shaft; surfaces entirely behind the plane of
 * either polygon (on its back side) or the polygons' own surfaces cannot block and are left out.
 * Conservative: a surface that can block any segment between the two polygons is always listed. */
typedef struct hr_shaft_index hr_shaft_index;

/* Builds a bounding-volume hierarchy over the surfaces' bounding boxes. */
hr_status hr_shaft_index_create(const hr_scene *s, hr_shaft_index **out);
void hr_shaft_index_destroy(hr_shaft_index **x);

/* Candidate blockers between polygon pa (na vertices, surface id sa) and pb (nb, sb), found
 * through the BVH (not by testing every surface). Appends surface ids in increasing order to
 * '*out' (a growable array with '*nout' used and '*cap' allocated; realloc'd as needed).
 * Returns HR_ERR_NOMEM if growing fails. */
hr_status hr_shaft_candidates(const hr_shaft_index *x, const hr_vec3 *pa, int na, int sa,
                              const hr_vec3 *pb, int nb, int sb, int32_t **out, int *nout,
                              int *cap);

/* Shrinks a parent's list for a sub-shaft: writes to 'out' (room for ncand) those of
 * cand[0..ncand) that may intersect the shaft of pa and pb, keeping their order; returns the
 * count. */
int hr_shaft_filter(const hr_scene *s, const hr_vec3 *pa, int na, int sa, const hr_vec3 *pb,
                    int nb, int sb, const int32_t *cand, int ncand, int32_t *out);

/* The shaft tests run in AVX2 when the CPU has it (chosen per call; the answers are the same bit
 * for bit). 'allow' 0 makes every later call take the baseline kernels, 1 restores the choice
 * (for tests and benchmarks; not thread-safe against concurrent shaft calls). Returns whether
 * later calls take the AVX2 kernels. */
int hr_shaft_use_avx2(int allow);

#endif
