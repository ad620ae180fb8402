/* vec.h: small inline 3-vector helpers (and a hash mixer) shared by all modules (internal). */
#ifndef HR_VEC_H
#define HR_VEC_H

#include "hrad.h"
#include <math.h>
#include <stdint.h>
#include <string.h>

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

/* A 64-bit mixing function (the murmur3 finaliser with Stafford's variant-13 constants) for
 * hash tables. */
static inline uint64_t u64_mix(uint64_t x) {
  x ^= x >> 31;
  x *= 0x7fb5d329728ea185ull;
  x ^= x >> 27;
  x *= 0x81dadef4bc2dd44dull;
  x ^= x >> 33;
  return x;
}

/* Mixes the coordinates of p into hash state h (-0 and +0 hash alike, as they compare equal). */
static inline uint64_t v3_hash(uint64_t h, hr_vec3 p) {
  double c[3] = {p.x + 0.0, p.y + 0.0, p.z + 0.0};
  for (int i = 0; i < 3; i++) {
    uint64_t u;
    memcpy(&u, &c[i], sizeof u);
    h = u64_mix(h ^ u);
  }
  return h;
}

/* Newell normal of a polygon (not normalised; its length is twice the area): robust for any
 * simple polygon, planar or slightly not. */
static inline hr_vec3 v3_newell(const hr_vec3 *v, int n) {
  hr_vec3 r = {0, 0, 0};
  for (int i = 0; i < n; i++) {
    hr_vec3 a = v[i], b = v[(i + 1) % n];
    r.x += (a.y - b.y) * (a.z + b.z);
    r.y += (a.z - b.z) * (a.x + b.x);
    r.z += (a.x - b.x) * (a.y + b.y);
  }
  return r;
}

#endif
