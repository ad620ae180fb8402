/* ff_ref.c: the slow twin of ff.c. Exact point-to-polygon form factors by Lambert's contour
 * integral and polygon-to-polygon form factors by Gauss-Legendre quadrature over the receiver;
 * tests compare the solver against these and against closed forms. */
#include "ff_ref.h"
#include "vec.h"

double hr_ff_ref_point_poly(hr_vec3 p, hr_vec3 n, const hr_vec3 *v, int nv) {
  double sum = 0;
  for (int k = 0; k < nv; k++) {
    hr_vec3 a = v3_norm(v3_sub(v[k], p)), b = v3_norm(v3_sub(v[(k + 1) % nv], p));
    double c = v3_dot(a, b);
    c = c > 1 ? 1 : (c < -1 ? -1 : c);
    hr_vec3 g = v3_cross(a, b);
    double gl = v3_len(g);
    if (gl == 0) continue;
    sum += acos(c) * v3_dot(n, g) / gl;
  }
  return fabs(sum) / (2 * M_PI);
}

static const double GL_X[8][8] = {
    {0},
    {-0.5773502691896257, 0.5773502691896257},
    {-0.7745966692414834, 0, 0.7745966692414834},
    {-0.8611363115940526, -0.3399810435848563, 0.3399810435848563, 0.8611363115940526},
    {-0.9061798459386640, -0.5384693101056831, 0, 0.5384693101056831, 0.9061798459386640},
    {-0.9324695142031521, -0.6612093864662645, -0.2386191860831969, 0.2386191860831969,
     0.6612093864662645, 0.9324695142031521},
    {-0.9491079123427585, -0.7415311855993945, -0.4058451513773972, 0, 0.4058451513773972,
     0.7415311855993945, 0.9491079123427585},
    {-0.9602898564975363, -0.7966664774136267, -0.5255324099163290, -0.1834346424956498,
     0.1834346424956498, 0.5255324099163290, 0.7966664774136267, 0.9602898564975363}};
static const double GL_W[8][8] = {
    {2},
    {1, 1},
    {0.5555555555555556, 0.8888888888888888, 0.5555555555555556},
    {0.3478548451374538, 0.6521451548625461, 0.6521451548625461, 0.3478548451374538},
    {0.2369268850561891, 0.4786286704993665, 0.5688888888888889, 0.4786286704993665,
     0.2369268850561891},
    {0.1713244923791704, 0.3607615730481386, 0.4679139345726910, 0.4679139345726910,
     0.3607615730481386, 0.1713244923791704},
    {0.1294849661688697, 0.2797053914892766, 0.3818300505051189, 0.4179591836734694,
     0.3818300505051189, 0.2797053914892766, 0.1294849661688697},
    {0.1012285362903763, 0.2223810344533745, 0.3137066553286861, 0.3626837833783620,
     0.3626837833783620, 0.3137066553286861, 0.2223810344533745, 0.1012285362903763}};

double hr_ff_ref_poly_poly(const hr_vec3 *a, int na, const hr_vec3 *b, int nb, int m, int order) {
  if (order < 1) order = 1;
  if (order > 8) order = 8;
  const double *X = GL_X[order - 1], *W = GL_W[order - 1];
  hr_vec3 n = v3_norm(v3_cross(v3_sub(a[1], a[0]), v3_sub(a[na - 1], a[0])));
  double acc = 0, area = 0;
  /* Map the unit square onto A: bilinear for a quad, collapsed (Duffy) for a triangle. */
  for (int ci = 0; ci < m; ci++)
    for (int cj = 0; cj < m; cj++)
      for (int qi = 0; qi < order; qi++)
        for (int qj = 0; qj < order; qj++) {
          double u = (ci + 0.5 + 0.5 * X[qi]) / m, v = (cj + 0.5 + 0.5 * X[qj]) / m;
          double w = W[qi] * W[qj] * 0.25 / ((double)m * m);
          hr_vec3 p, du, dv;
          if (na == 4) {
            p = v3_lerp(v3_lerp(a[0], a[1], u), v3_lerp(a[3], a[2], u), v);
            du = v3_lerp(v3_sub(a[1], a[0]), v3_sub(a[2], a[3]), v);
            dv = v3_sub(v3_lerp(a[3], a[2], u), v3_lerp(a[0], a[1], u));
          } else {
            /* (u, v) -> a0 + u (a1 - a0) + u v (a2 - a1) */
            hr_vec3 e1 = v3_sub(a[1], a[0]), e2 = v3_sub(a[2], a[1]);
            p = v3_add(a[0], v3_add(v3_scale(e1, u), v3_scale(e2, u * v)));
            du = v3_add(e1, v3_scale(e2, v));
            dv = v3_scale(e2, u);
          }
          double jac = v3_len(v3_cross(du, dv));
          acc += w * jac * hr_ff_ref_point_poly(p, n, b, nb);
          area += w * jac;
        }
  return acc / area;
}
