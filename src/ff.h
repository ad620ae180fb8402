/* ff.h: form-factor kernels (paper 1.2: the F_ij of the links), on element geometry alone.
 *
 * These functions know nothing of the solver: they take two elements as polygons and return
 * numbers, so that tests can hold them against the exact reference (ff_ref.c) and a distributed
 * solver can call them on any process. Internal API. */
#ifndef HR_FF_H
#define HR_FF_H

#include "hrad.h"

/* An element as the kernels see it: a planar convex polygon, counter-clockwise seen from its
 * front, which alone emits and receives light. */
typedef struct hr_ff_elem {
  int nv;       /* 3 or 4 */
  hr_vec3 p[4]; /* corners (p[3] unused for triangles) */
  hr_vec3 n;    /* unit front normal */
  double area;
} hr_ff_elem;

/* Differential-area-to-polygon form factor from the point x (unit normal nx) to the front of
 * polygon 's', unoccluded, exact (Lambert's contour integral over the part of 's' in front of
 * x's tangent plane). 0 when x is not in front of 's'. This function can't fail. */
double hr_ff_point(hr_vec3 x, hr_vec3 nx, const hr_ff_elem *s);

/* hr_ff_point at the n points x (all with normal nx) into out[0, n), bit for bit: on CPUs with
 * AVX2 four points at a time, the same operations in the same order (ff.c is built without
 * contraction into fused multiply-adds). This function can't fail. */
void hr_ff_point_many(const hr_vec3 *x, int n, hr_vec3 nx, const hr_ff_elem *s, double *out);

/* hr_ff_point at n (point x[q], source s[q]) pairs, all points with normal nx, into out[0, n),
 * bit for bit as hr_ff_point_many (four pairs at a time on CPUs with AVX2, whatever their
 * sources): for many small sources seen from few points. This function can't fail. */
void hr_ff_point_pairs(const hr_vec3 *const *x, const hr_ff_elem *const *s, int n, hr_vec3 nx,
                       double *out);

/* Whether hr_ff_point_many may take its AVX2 kernel (1, the default, where the CPU has it; 0:
 * the scalar loop, for tests). Returns whether it now does. */
int hr_ff_use_avx2(int allow);

/* 1 when the point form factor from 's' is 0 at every point of 'r' (whatever the quadrature):
 * all of 's' lies on or behind r's plane, or all of 'r' on or behind s's. At most 8 dot
 * products: hr_ff_point's own tests, made on the corners (at points computed from corners that
 * lie in the other's plane, rounding can let hr_ff_point return a few 1e-16 instead of 0). */
int hr_ff_pair_dark(const hr_ff_elem *r, const hr_ff_elem *s);

/* Quadrature order on the receiver (1 = one point, 2 = 2x2 or 3 points, 3 = 3x3 or 6 points)
 * that makes the unoccluded polygon-to-polygon form factor of hr_ff_elem_pair accurate for
 * receiver 'r' and source 's'; chosen from their separation relative to the receiver's size. */
int hr_ff_order(const hr_ff_elem *r, const hr_ff_elem *s);

/* What hr_ff_order reads of an element that does not depend on the other: its diameter and
 * vertex centroid. */
typedef struct hr_ff_shape {
  double diam;
  hr_vec3 c;
} hr_ff_shape;
hr_ff_shape hr_ff_shape_of(const hr_ff_elem *e);

/* hr_ff_pair_dark and hr_ff_order at once, with the shapes made once for elements met in many
 * pairs: 0 where hr_ff_pair_dark(r, s), else hr_ff_order(r, s), the same numbers (each corner
 * tested against the other's plane once instead of twice). */
int hr_ff_pair_class(const hr_ff_elem *r, const hr_ff_elem *s, const hr_ff_shape *rs,
                     const hr_ff_shape *ss);

/* Quadrature points of order 'order' (1..3) on element 'e': up to 9 points 'x' with weights 'w'
 * summing to 1 (area measure). Returns the number of points. */
int hr_ff_points(const hr_ff_elem *e, int order, hr_vec3 *x, double *w);

/* Most points hr_ff_clip_points gives: the clipped receiver (at most 5 corners) as a fan of at
 * most 3 triangles, 6 points each. */
#define HR_FF_CLIP_POINTS 18

/* Quadrature points of the part of receiver 'r' in front of the plane of source 's', where r
 * reaches through that plane (corners strictly on both sides) and is not a sliver (squared
 * diameter at most HR_FF_CLIP_ELONGATION times its area): up to HR_FF_CLIP_POINTS points 'x'
 * with weights 'w' summing to the share of r's area in front (order 3 on each triangle).
 * Returns their number, 0 where the rule does not apply (use hr_ff_points). */
int hr_ff_clip_points(const hr_ff_elem *r, const hr_ff_elem *s, hr_vec3 *x, double *w);

/* 1 where F(r <- s) of a near pair (order 3) is better integrated over the source and taken
 * back by reciprocity (hr_ff_recip): s's diameter 'ds' under half r's 'dr', neither a sliver. */
int hr_ff_recip_applies(const hr_ff_elem *r, const hr_ff_elem *s, double dr, double ds);
/* F(r <- s) as A_s / A_r times F(s <- r) by quadrature over s (order 3, or over its part in
 * front of r's plane where it reaches through: hr_ff_clip_points). */
double hr_ff_recip(const hr_ff_elem *r, const hr_ff_elem *s);

/* Unoccluded form factor F(r <- s): the area mean over the receiver of hr_ff_point, by the
 * quadrature rule of order 'order' (0: hr_ff_order), or where r reaches through the plane of s,
 * over the part in front (hr_ff_clip_points, whatever 'order'); for a small source near a
 * large receiver, by reciprocity (hr_ff_recip_applies). '*spread' (may be NULL) receives an
 * estimate of how much the point form factor varies over the receiver (largest minus smallest):
 * from the quadrature points, extrapolated to the element's sides, or for one point from the
 * point-to-disk estimate at the receiver's corners. This function can't fail. */
double hr_ff_pair(const hr_ff_elem *r, const hr_ff_elem *s, int order, double *spread);

/* How much the light a receiver 'r' gets from source 's' depends on where on 's' it comes from,
 * as a factor in (0, 1] on the unoccluded form factor: 1 where 's' reaches behind the plane of
 * 'r' or lies within its own size of it, else size / clearance. A link uses the mean radiosity
 * of its source; this factor times the variation of the source's radiosity bounds the error
 * that makes (refinement splits the source when it is large). This function can't fail. */
double hr_ff_source_weight(const hr_ff_elem *r, const hr_ff_elem *s);

/* The unoccluded form factor as hr_ff_pair, and how it divides among the four children of the
 * source (elem.c's subdivision), share[0..3] summing to 1 (all -1 when it is 0). */
double hr_ff_pair_shares(const hr_ff_elem *r, const hr_ff_elem *s, int order, float share[4]);

/* The paper's eq. (2) without H: the point-to-disk estimate from the receiver's vertex centroid,
 * cos_i cos_j A_j / (pi r^2 + A_j), 0 when the centres face away. Kept for comparison. */
double hr_ff_disk(const hr_ff_elem *r, const hr_ff_elem *s);

#endif
