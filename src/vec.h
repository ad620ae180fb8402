/* vec.h: small inline 3-vector helpers shared by all modules (internal). */
#ifndef HR_VEC_H
#define HR_VEC_H

#include "hrad.h"
#include <math.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

static inline hr_vec3 v3(double x, double y, double z) { return (hr_vec3){x, y, z}; }
static inline hr_vec3 v3_add(hr_vec3 a, hr_vec3 b) { return v3(a.x + b.x, a.y + b.y, a.z + b.z); }
static inline hr_vec3 v3_sub(hr_vec3 a, hr_vec3 b) { return v3(a.x - b.x, a.y - b.y, a.z - b.z); }
static inline hr_vec3 v3_scale(hr_vec3 a, double s) { return v3(a.x * s, a.y * s, a.z * s); }
static inline double v3_dot(hr_vec3 a, hr_vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline hr_vec3 v3_cross(hr_vec3 a, hr_vec3 b) {
  return v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static inline double v3_len(hr_vec3 a) { return sqrt(v3_dot(a, a)); }
static inline hr_vec3 v3_norm(hr_vec3 a) {
  double l = v3_len(a);
  return l > 0 ? v3_scale(a, 1.0 / l) : a;
}
static inline hr_vec3 v3_lerp(hr_vec3 a, hr_vec3 b, double t) {
  return v3(a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t, a.z + (b.z - a.z) * t);
}
static inline hr_vec3 v3_min(hr_vec3 a, hr_vec3 b) {
  return v3(a.x < b.x ? a.x : b.x, a.y < b.y ? a.y : b.y, a.z < b.z ? a.z : b.z);
}
static inline hr_vec3 v3_max(hr_vec3 a, hr_vec3 b) {
  return v3(a.x > b.x ? a.x : b.x, a.y > b.y ? a.y : b.y, a.z > b.z ? a.z : b.z);
}

#endif
