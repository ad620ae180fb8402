/* ff_ref.h: slow, exact reference form factors for tests (internal API). */
#ifndef HR_FF_REF_H
#define HR_FF_REF_H

#include "hrad.h"

/* Differential-area-to-polygon form factor from point 'p' with unit normal 'n' to the convex
 * polygon 'v' (nv vertices), unoccluded, by Lambert's contour formula. The polygon must lie
 * wholly in front of p's tangent plane. */
double hr_ff_ref_point_poly(hr_vec3 p, hr_vec3 n, const hr_vec3 *v, int nv);

/* Polygon-to-polygon form factor F(A -> B), unoccluded: the area average over A of the point
 * form factor, by Gauss-Legendre quadrature of order 'order' (1..8) on an m x m grid of cells. */
double hr_ff_ref_poly_poly(const hr_vec3 *a, int na, const hr_vec3 *b, int nb, int m, int order);

#endif
