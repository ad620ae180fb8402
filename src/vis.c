/* vis.c: segment visibility (paper 1.2, the rays that estimate H_ij).
 *
 * hr_vis_segments casts the segments with Embree 3: one triangle geometry holds every surface
 * (a quad as two triangles; measured ~20% faster than Embree's quad primitive for packets), and a
 * table maps Embree's primID back to the surface id. Hits on the two skipped surfaces are
 * rejected by a context filter function that is only installed when a skip id is given.
 * Segments go in packets of 16 (COHERENT context); a remainder of up to 8 goes through the
 * stream API (rtcOccluded1M).
 *
 * hr_vis_segments_cand / hr_vis_segments_ref are exact double-precision segment/convex polygon
 * tests: a segment is blocked by a polygon when it crosses the polygon's plane at t in
 * [HR_VIS_EPS, 1 - HR_VIS_EPS] inside the closed polygon. Segments lying in a polygon's plane do
 * not hit it (grazing). Both faces block. */
#include "vis.h"
#include "vec.h"

#include <embree3/rtcore.h>
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Build settings (overridable when compiling the benchmark). */
#ifndef HR_VIS_BUILD_QUALITY
#define HR_VIS_BUILD_QUALITY RTC_BUILD_QUALITY_MEDIUM /* HIGH: same ray rate, 3x build time */
#endif
#ifndef HR_VIS_SCENE_FLAGS
#define HR_VIS_SCENE_FLAGS RTC_SCENE_FLAG_NONE
#endif

struct hr_vis {
  RTCDevice dev;
  RTCScene scene;
  int nsurfs;
  int *tri2surf; /* Embree primID (triangle) -> surface id */
};

/* ------------------------------------------------------------------ Embree errors */

typedef struct {
  hr_err *err;
  int failed;
  enum RTCError code;
} err_sink;

static const char *rtc_err_name(enum RTCError e) {
  switch (e) {
  case RTC_ERROR_NONE: return "no error";
  case RTC_ERROR_UNKNOWN: return "unknown error";
  case RTC_ERROR_INVALID_ARGUMENT: return "invalid argument";
  case RTC_ERROR_INVALID_OPERATION: return "invalid operation";
  case RTC_ERROR_OUT_OF_MEMORY: return "out of memory";
  case RTC_ERROR_UNSUPPORTED_CPU: return "unsupported CPU";
  case RTC_ERROR_CANCELLED: return "cancelled";
  }
  return "error";
}

/* Error callback while building: remembers the first error as an hr_err message. */
static void on_build_error(void *ud, enum RTCError code, const char *str) {
  err_sink *sink = ud;
  if (!sink || sink->failed) return;
  sink->failed = 1;
  sink->code = code;
  hr_err_set(sink->err, code == RTC_ERROR_OUT_OF_MEMORY ? HR_ERR_NOMEM : HR_ERR_INVALID,
             "embree: %s%s%s", rtc_err_name(code), str ? ": " : "", str ? str : "");
}

/* Error callback after building: queries on a committed scene do not fail; swallow anything
 * rather than letting Embree print. */
static void on_query_error(void *ud, enum RTCError code, const char *str) {
  (void)ud;
  (void)code;
  (void)str;
}

void hr_vis_destroy(hr_vis **pv) {
  if (!pv || !*pv) return;
  hr_vis *v = *pv;
  if (v->scene) rtcReleaseScene(v->scene);
  if (v->dev) rtcReleaseDevice(v->dev);
  free(v->tri2surf);
  free(v);
  *pv = NULL;
}

/* ------------------------------------------------------------------ skip filter */

typedef struct {
  struct RTCIntersectContext ctx; /* must be first: Embree hands back a pointer to it */
  const int *tri2surf;
  int skip_a, skip_b;
} vis_ctx;

/* Rejects hits on triangles of the context's skipped surfaces. */
static void skip_filter(const struct RTCFilterFunctionNArguments *args) {
  const vis_ctx *c = (const vis_ctx *)args->context;
  const unsigned N = args->N;
  /* RTCHitN layout: Ng_x, Ng_y, Ng_z, u, v, primID, geomID, ... each N wide. */
  const unsigned *prim = (const unsigned *)args->hit + 5 * N;
  for (unsigned i = 0; i < N; i++) {
    if (args->valid[i] == 0) continue;
    int sid = c->tri2surf[prim[i]];
    if (sid == c->skip_a || sid == c->skip_b) args->valid[i] = 0;
  }
}

static void ctx_init(vis_ctx *c, const hr_vis *v, int skip_a, int skip_b, int coherent) {
  rtcInitIntersectContext(&c->ctx);
  c->ctx.flags =
      coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
  c->tri2surf = v->tri2surf;
  c->skip_a = skip_a >= 0 ? skip_a : -2; /* -2 matches no surface (tri2surf >= 0) */
  c->skip_b = skip_b >= 0 ? skip_b : -2;
  c->ctx.filter = (skip_a >= 0 || skip_b >= 0) ? skip_filter : NULL;
}

/* ------------------------------------------------------------------ build */

hr_status hr_vis_create(const hr_scene *s, hr_vis **out, hr_err *err) {
  *out = NULL;
  hr_vis *v = calloc(1, sizeof *v);
  if (!v) return hr_err_set(err, HR_ERR_NOMEM, "out of memory creating the ray caster");
  v->nsurfs = s->nsurfs;
  err_sink sink = {err, 0, RTC_ERROR_NONE};
  v->dev = rtcNewDevice("threads=1");
  if (!v->dev) {
    enum RTCError code = rtcGetDeviceError(NULL);
    hr_vis_destroy(&v);
    return hr_err_set(err, code == RTC_ERROR_OUT_OF_MEMORY ? HR_ERR_NOMEM : HR_ERR_INVALID,
                      "embree: cannot create device: %s", rtc_err_name(code));
  }
  rtcSetDeviceErrorFunction(v->dev, on_build_error, &sink);
  v->scene = rtcNewScene(v->dev);
  if (v->scene) {
    rtcSetSceneFlags(v->scene, RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION | HR_VIS_SCENE_FLAGS);
    rtcSetSceneBuildQuality(v->scene, HR_VIS_BUILD_QUALITY);
  }
  size_t ntri = 0;
  for (int i = 0; i < s->nsurfs; i++) ntri += (size_t)(s->surfs[i].nverts - 2);
  if (v->scene && ntri > 0) {
    v->tri2surf = malloc(ntri * sizeof *v->tri2surf);
    RTCGeometry g = v->tri2surf ? rtcNewGeometry(v->dev, RTC_GEOMETRY_TYPE_TRIANGLE) : NULL;
    float *vb = NULL;
    unsigned *ib = NULL;
    if (g) {
      rtcSetGeometryBuildQuality(g, HR_VIS_BUILD_QUALITY);
      vb = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                   3 * sizeof(float), (size_t)s->nsurfs * 4);
      ib = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                   3 * sizeof(unsigned), ntri);
    }
    if (vb && ib) {
      size_t t = 0;
      for (int i = 0; i < s->nsurfs; i++) {
        const hr_surface *f = &s->surfs[i];
        for (int k = 0; k < 4; k++) {
          const hr_vec3 p = f->v[k < f->nverts ? k : f->nverts - 1];
          float *q = vb + ((size_t)i * 4 + (size_t)k) * 3;
          q[0] = (float)p.x;
          q[1] = (float)p.y;
          q[2] = (float)p.z;
        }
        /* a quad is the fan (0,1,2), (0,2,3): it is convex, so both halves are inside it */
        unsigned b = (unsigned)i * 4u;
        for (int k = 1; k + 1 < f->nverts; k++, t++) {
          ib[3 * t] = b;
          ib[3 * t + 1] = b + (unsigned)k;
          ib[3 * t + 2] = b + (unsigned)k + 1;
          v->tri2surf[t] = i;
        }
      }
      rtcCommitGeometry(g);
      rtcAttachGeometryByID(v->scene, g, 0);
    }
    if (g) rtcReleaseGeometry(g);
    if (!v->tri2surf) {
      hr_vis_destroy(&v);
      return hr_err_set(err, HR_ERR_NOMEM, "out of memory creating the ray caster");
    }
  }
  if (v->scene) rtcCommitScene(v->scene);
  if (!v->scene || sink.failed) {
    hr_status st = sink.code == RTC_ERROR_OUT_OF_MEMORY ? HR_ERR_NOMEM : HR_ERR_INVALID;
    if (!sink.failed) hr_err_set(err, st, "embree: cannot build the scene");
    hr_vis_destroy(&v);
    return st;
  }
  rtcSetDeviceErrorFunction(v->dev, on_query_error, NULL);
  *out = v;
  return HR_OK;
}

hr_status hr_vis_check_range(const hr_scene *s, hr_err *err) {
  hr_vec3 lo, hi;
  hr_scene_bounds(s, &lo, &hi);
  double size = v3_len(v3_sub(hi, lo));
  double mag = fmax(fmax(fmax(fabs(lo.x), fabs(hi.x)), fmax(fabs(lo.y), fabs(hi.y))),
                    fmax(fabs(lo.z), fabs(hi.z)));
  if (mag > HR_VIS_RANGE_MAX * size)
    return hr_err_set(err, HR_ERR_INVALID,
                      "%s: coordinates reach %g, %.0f times the scene's size %g; rays are cast in "
                      "single precision, which loses the scene's detail beyond %g times: move "
                      "the model near the origin",
                      s->name, mag, mag / size, size, HR_VIS_RANGE_MAX);
  return HR_OK;
}

double hr_vis_lift(const hr_scene *s) {
  double mag = 0;
  for (int i = 0; i < s->nsurfs; i++)
    for (int k = 0; k < s->surfs[i].nverts; k++) {
      hr_vec3 v = s->surfs[i].v[k];
      mag = fmax(mag, fmax(fabs(v.x), fmax(fabs(v.y), fabs(v.z))));
    }
  return 16.0 * FLT_EPSILON * mag;
}

/* ------------------------------------------------------------------ Embree queries */

#define FILL_LANE(R, k, i)                                                                         \
  do {                                                                                             \
    const float *o_ = org + 3 * (size_t)(i), *d_ = dst + 3 * (size_t)(i);                          \
    (R).org_x[k] = o_[0];                                                                          \
    (R).org_y[k] = o_[1];                                                                          \
    (R).org_z[k] = o_[2];                                                                          \
    (R).dir_x[k] = d_[0] - o_[0];                                                                  \
    (R).dir_y[k] = d_[1] - o_[1];                                                                  \
    (R).dir_z[k] = d_[2] - o_[2];                                                                  \
    (R).tnear[k] = (float)HR_VIS_EPS;                                                              \
    (R).tfar[k] = (float)(1.0 - HR_VIS_EPS);                                                       \
    (R).time[k] = 0.0f;                                                                            \
    (R).mask[k] = 0xFFFFFFFFu;                                                                     \
    (R).id[k] = (unsigned)(k);                                                                     \
    (R).flags[k] = 0;                                                                              \
  } while (0)

static void occluded16(const hr_vis *v, vis_ctx *c, int cnt, const float *org, const float *dst,
                       uint8_t *vis) {
  struct RTCRay16 r;          /* RTC_ALIGN(64) in the header: 64-byte aligned on the stack */
  _Alignas(64) int valid[16]; /* Embree loads the mask with aligned vector loads */
  for (int k = 0; k < 16; k++) {
    int i = k < cnt ? k : cnt - 1; /* inactive lanes repeat a valid ray (finite data) */
    FILL_LANE(r, k, i);
    valid[k] = k < cnt ? -1 : 0;
  }
  rtcOccluded16(valid, v->scene, &c->ctx, &r);
  for (int k = 0; k < cnt; k++) vis[k] = r.tfar[k] >= 0.0f;
}

static void occluded8(const hr_vis *v, vis_ctx *c, int cnt, const float *org, const float *dst,
                      uint8_t *vis) {
  struct RTCRay8 r;
  _Alignas(32) int valid[8];
  for (int k = 0; k < 8; k++) {
    int i = k < cnt ? k : cnt - 1;
    FILL_LANE(r, k, i);
    valid[k] = k < cnt ? -1 : 0;
  }
  rtcOccluded8(valid, v->scene, &c->ctx, &r);
  for (int k = 0; k < cnt; k++) vis[k] = r.tfar[k] >= 0.0f;
}

static void occluded4(const hr_vis *v, vis_ctx *c, int cnt, const float *org, const float *dst,
                      uint8_t *vis) {
  struct RTCRay4 r;
  _Alignas(16) int valid[4];
  for (int k = 0; k < 4; k++) {
    int i = k < cnt ? k : cnt - 1;
    FILL_LANE(r, k, i);
    valid[k] = k < cnt ? -1 : 0;
  }
  rtcOccluded4(valid, v->scene, &c->ctx, &r);
  for (int k = 0; k < cnt; k++) vis[k] = r.tfar[k] >= 0.0f;
}

static void occluded1(const hr_vis *v, vis_ctx *c, const float *o, const float *d, uint8_t *vis) {
  struct RTCRay r;
  r.org_x = o[0];
  r.org_y = o[1];
  r.org_z = o[2];
  r.dir_x = d[0] - o[0];
  r.dir_y = d[1] - o[1];
  r.dir_z = d[2] - o[2];
  r.tnear = (float)HR_VIS_EPS;
  r.tfar = (float)(1.0 - HR_VIS_EPS);
  r.time = 0.0f;
  r.mask = 0xFFFFFFFFu;
  r.id = 0;
  r.flags = 0;
  rtcOccluded1(v->scene, &c->ctx, &r);
  *vis = r.tfar >= 0.0f;
}

/* Up to 16 rays through the stream API (incoherent): the fastest for a few rays. */
static void occluded_stream(const hr_vis *v, vis_ctx *c, int cnt, const float *org,
                            const float *dst, uint8_t *vis) {
  struct RTCRay r[16]; /* RTC_ALIGN(16) in the header */
  for (int k = 0; k < cnt; k++) {
    const float *o = org + 3 * (size_t)k, *d = dst + 3 * (size_t)k;
    r[k].org_x = o[0];
    r[k].org_y = o[1];
    r[k].org_z = o[2];
    r[k].dir_x = d[0] - o[0];
    r[k].dir_y = d[1] - o[1];
    r[k].dir_z = d[2] - o[2];
    r[k].tnear = (float)HR_VIS_EPS;
    r[k].tfar = (float)(1.0 - HR_VIS_EPS);
    r[k].time = 0.0f;
    r[k].mask = 0xFFFFFFFFu;
    r[k].id = (unsigned)k;
    r[k].flags = 0;
  }
  c->ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
  rtcOccluded1M(v->scene, &c->ctx, r, (unsigned)cnt, sizeof(struct RTCRay));
  c->ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  for (int k = 0; k < cnt; k++) vis[k] = r[k].tfar >= 0.0f;
}

/* Ray batching policy. 0 (used by hr_vis_segments): packets of 16, a remainder of up to 8
 * rays through the stream API (measured: for 4 rays, stream ~5 Mrays/s, rtcOccluded4 ~3.5,
 * rtcOccluded1 ~4.3; for 16 rays packet16 and stream are on par, ~7). Fixed widths 1, 4, 8, 16
 * (masked last packet) and 2 (stream of up to 16) exist for the benchmark. */
static void vis_segments_mode(const hr_vis *v, int n, const float *org, const float *dst,
                              int skip_a, int skip_b, uint8_t *vis, int mode) {
  if (n <= 0) return;
  vis_ctx c;
  ctx_init(&c, v, skip_a, skip_b, 1);
  for (int i = 0; i < n;) {
    int left = n - i, w;
    if (mode == 0)
      w = left > 8 ? 16 : 2;
    else
      w = mode;
    int cnt = left < w ? left : w;
    const float *o = org + 3 * (size_t)i, *d = dst + 3 * (size_t)i;
    switch (w) {
    case 16: occluded16(v, &c, cnt, o, d, vis + i); break;
    case 8: occluded8(v, &c, cnt, o, d, vis + i); break;
    case 4: occluded4(v, &c, cnt, o, d, vis + i); break;
    case 2:
      cnt = left < 16 ? left : 16;
      occluded_stream(v, &c, cnt, o, d, vis + i);
      break;
    default:
      c.ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
      occluded1(v, &c, o, d, vis + i);
      c.ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
      cnt = 1;
      break;
    }
    i += cnt;
  }
}

void hr_vis_segments(const hr_vis *v, int n, const float *org, const float *dst, int skip_a,
                     int skip_b, uint8_t *vis) {
  vis_segments_mode(v, n, org, dst, skip_a, skip_b, vis, 0);
}

int hr_vis_first_hit(const hr_vis *v, const float org[3], const float dst[3]) {
  struct RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  struct RTCRayHit rh;
  rh.ray.org_x = org[0];
  rh.ray.org_y = org[1];
  rh.ray.org_z = org[2];
  rh.ray.dir_x = dst[0] - org[0];
  rh.ray.dir_y = dst[1] - org[1];
  rh.ray.dir_z = dst[2] - org[2];
  rh.ray.tnear = (float)HR_VIS_EPS;
  rh.ray.tfar = (float)(1.0 - HR_VIS_EPS);
  rh.ray.time = 0.0f;
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.id = 0;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(v->scene, &ctx, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return -1;
  return v->tri2surf[rh.hit.primID];
}

/* ------------------------------------------------------------------ exact tests */

/* Candidates are prepared in chunks of CHUNK on the stack (any number of chunks), in
 * structure-of-arrays form so that the per-segment loop over a chunk is branch-free and
 * vectorises: plane n.x = d (n unit, the surface's normal, d at vertex 0), inward edge normals
 * e[j] = n x (v[j+1] - v[j]) with e[j].x >= c[j] inside. A triangle repeats its last edge. */
#define CHUNK 64

typedef struct {
  double nx[CHUNK], ny[CHUNK], nz[CHUNK], d[CHUNK];
  double ex[4][CHUNK], ey[4][CHUNK], ez[4][CHUNK], c[4][CHUNK];
  int n;
} chunk_t;

/* Stores surface f in slot m of P: a chunk_t (double) or an hr_blockers (float). */
#define SLOT_SET(T, P, m, f)                                                                       \
  do {                                                                                             \
    const hr_vec3 n_ = (f)->normal;                                                                \
    (P)->nx[m] = (T)n_.x, (P)->ny[m] = (T)n_.y, (P)->nz[m] = (T)n_.z;                              \
    (P)->d[m] = (T)v3_dot(n_, (f)->v[0]);                                                          \
    for (int j_ = 0; j_ < 4; j_++) {                                                               \
      int k_ = j_ < (f)->nverts ? j_ : (f)->nverts - 1;                                            \
      hr_vec3 a_ = (f)->v[k_], b_ = (f)->v[(k_ + 1) % (f)->nverts];                                \
      hr_vec3 e_ = v3_cross(n_, v3_sub(b_, a_));                                                   \
      (P)->ex[j_][m] = (T)e_.x, (P)->ey[j_][m] = (T)e_.y, (P)->ez[j_][m] = (T)e_.z;                \
      (P)->c[j_][m] = (T)v3_dot(e_, a_);                                                           \
    }                                                                                              \
  } while (0)

/* OUT = 1 when the segment from (o0,o1,o2) to (e0,e1,e2) (d0,d1,d2 = e - o; all of type T)
 * crosses the plane of slot k of P at t = so / (so - se) in [lo, hi] (so, se: signed distances
 * of its ends) at a point inside or on every edge. A segment in the plane gives t = NaN or +-inf
 * and no hit. Branch-free, so that loops over slots vectorise. */
#define SLOT_HIT(T, P, k, OUT)                                                                     \
  do {                                                                                             \
    T so_ = (P)->nx[k] * o0 + (P)->ny[k] * o1 + (P)->nz[k] * o2 - (P)->d[k];                       \
    T se_ = (P)->nx[k] * e0 + (P)->ny[k] * e1 + (P)->nz[k] * e2 - (P)->d[k];                       \
    T t_ = so_ / (so_ - se_);                                                                      \
    T x_ = o0 + t_ * d0, y_ = o1 + t_ * d1, z_ = o2 + t_ * d2;                                     \
    int in_ = (t_ >= lo) & (t_ <= hi);                                                             \
    in_ &= (P)->ex[0][k] * x_ + (P)->ey[0][k] * y_ + (P)->ez[0][k] * z_ >= (P)->c[0][k];           \
    in_ &= (P)->ex[1][k] * x_ + (P)->ey[1][k] * y_ + (P)->ez[1][k] * z_ >= (P)->c[1][k];           \
    in_ &= (P)->ex[2][k] * x_ + (P)->ey[2][k] * y_ + (P)->ez[2][k] * z_ >= (P)->c[2][k];           \
    in_ &= (P)->ex[3][k] * x_ + (P)->ey[3][k] * y_ + (P)->ez[3][k] * z_ >= (P)->c[3][k];           \
    (OUT) = in_;                                                                                   \
  } while (0)

/* Loads segment i of org/dst as scalars of type T: o0..o2, e0..e2 and d = e - o. */
#define SEG_LOAD(T, i)                                                                             \
  const T o0 = org[3 * (size_t)(i)], o1 = org[3 * (size_t)(i) + 1], o2 = org[3 * (size_t)(i) + 2]; \
  const T e0 = dst[3 * (size_t)(i)], e1 = dst[3 * (size_t)(i) + 1], e2 = dst[3 * (size_t)(i) + 2]; \
  const T d0 = e0 - o0, d1 = e1 - o1, d2 = e2 - o2

static void chunk_add(chunk_t *ch, const hr_surface *f) {
  const int m = ch->n++;
  SLOT_SET(double, ch, m, f);
}

/* Tests the still-visible segments against one chunk: a segment is blocked by a polygon it
 * crosses at t in [HR_VIS_EPS, 1 - HR_VIS_EPS] (SLOT_HIT). */
static void chunk_test(const chunk_t *ch, int n, const float *org, const float *dst, uint8_t *vis) {
  const int m = ch->n;
  const double lo = HR_VIS_EPS, hi = 1.0 - HR_VIS_EPS;
  for (int i = 0; i < n; i++) {
    if (!vis[i]) continue;
    SEG_LOAD(double, i);
    int hit = 0;
    for (int kb = 0; kb < m && !hit; kb += 16) { /* blocks of 16: vector loop, early exit */
      const int ke = kb + 16 < m ? kb + 16 : m;
      for (int k = kb; k < ke; k++) {
        int in;
        SLOT_HIT(double, ch, k, in);
        hit |= in;
      }
    }
    if (hit) vis[i] = 0;
  }
}

static int any_visible(int n, const uint8_t *vis) {
  for (int i = 0; i < n; i++)
    if (vis[i]) return 1;
  return 0;
}

void hr_vis_segments_cand(const hr_scene *s, const int32_t *cand, int ncand, int n,
                          const float *org, const float *dst, int skip_a, int skip_b,
                          uint8_t *vis) {
  if (n <= 0) return;
  memset(vis, 1, (size_t)n);
  chunk_t ch;
  ch.n = 0;
  for (int j = 0; j < ncand; j++) {
    int id = cand[j];
    if (id == skip_a || id == skip_b || id < 0 || id >= s->nsurfs) continue;
    chunk_add(&ch, &s->surfs[id]);
    if (ch.n == CHUNK) {
      chunk_test(&ch, n, org, dst, vis);
      ch.n = 0;
      if (!any_visible(n, vis)) return;
    }
  }
  if (ch.n) chunk_test(&ch, n, org, dst, vis);
}

void hr_vis_segments_ref(const hr_scene *s, int n, const float *org, const float *dst, int skip_a,
                         int skip_b, uint8_t *vis) {
  if (n <= 0) return;
  memset(vis, 1, (size_t)n);
  chunk_t ch;
  ch.n = 0;
  for (int id = 0; id < s->nsurfs; id++) {
    if (id == skip_a || id == skip_b) continue;
    chunk_add(&ch, &s->surfs[id]);
    if (ch.n == CHUNK) {
      chunk_test(&ch, n, org, dst, vis);
      ch.n = 0;
    }
  }
  if (ch.n) chunk_test(&ch, n, org, dst, vis);
}

/* ------------------------------------------------------------------ blocker cache */

void hr_blockers_clear(hr_blockers *b) {
  b->n = 0;
  /* Empty slots hold a plane that no segment crosses (every point 1 behind it). */
  for (int m = 0; m < HR_BLK_MAX; m++) {
    b->id[m] = -1;
    b->nx[m] = b->ny[m] = b->nz[m] = 0;
    b->d[m] = 1;
    for (int j = 0; j < 4; j++) b->ex[j][m] = b->ey[j][m] = b->ez[j][m] = b->c[j][m] = 0;
  }
}

#define SHIFT1(a) memmove((a) + 1, (a), (HR_BLK_MAX - 1) * sizeof *(a))

void hr_blockers_add(hr_blockers *b, const hr_scene *s, int id) {
  if (id < 0 || id >= s->nsurfs) return;
  for (int k = 0; k < b->n; k++)
    if (b->id[k] == id) return;
  /* Newest in slot 0; the oldest falls off the end. */
  SHIFT1(b->id), SHIFT1(b->nx), SHIFT1(b->ny), SHIFT1(b->nz), SHIFT1(b->d);
  for (int j = 0; j < 4; j++) SHIFT1(b->ex[j]), SHIFT1(b->ey[j]), SHIFT1(b->ez[j]), SHIFT1(b->c[j]);
  if (b->n < HR_BLK_MAX) b->n++;
  b->id[0] = id;
  SLOT_SET(float, b, 0, &s->surfs[id]);
}

int hr_blockers_test(const hr_blockers *b, int n, const float *org, const float *dst, int skip_a,
                     int skip_b, uint8_t *vis) {
  const float lo = (float)HR_VIS_EPS, hi = (float)(1.0 - HR_VIS_EPS);
  /* All slots at once, branch-free (8 float lanes: one vector); empty slots never block. */
  int use[HR_BLK_MAX];
  for (int k = 0; k < HR_BLK_MAX; k++) use[k] = b->id[k] != skip_a && b->id[k] != skip_b;
  int left = 0;
  for (int i = 0; i < n; i++) {
    if (!vis[i]) continue;
    SEG_LOAD(float, i);
    int hit = 0;
    for (int k = 0; k < HR_BLK_MAX; k++) {
      int in;
      SLOT_HIT(float, b, k, in);
      hit |= in & use[k];
    }
    if (hit)
      vis[i] = 0;
    else
      left++;
  }
  return left;
}

/* ------------------------------------------------------------------ closest hit (pt.c) */

int hr_vis_hit(const hr_vis *v, const float org[3], const float dir[3], float tfar, float *t) {
  struct RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
  struct RTCRayHit rh;
  rh.ray.org_x = org[0];
  rh.ray.org_y = org[1];
  rh.ray.org_z = org[2];
  rh.ray.dir_x = dir[0];
  rh.ray.dir_y = dir[1];
  rh.ray.dir_z = dir[2];
  rh.ray.tnear = 0.0f;
  rh.ray.tfar = tfar;
  rh.ray.time = 0.0f;
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.id = 0;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(v->scene, &ctx, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return -1;
  *t = rh.ray.tfar;
  return v->tri2surf[rh.hit.primID];
}
