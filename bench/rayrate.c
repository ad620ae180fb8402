/* rayrate.c: single-threaded ray rates on a built-in scene, for `make bench` (bench/run.sh).
 *
 *   rayrate [--links N] [--rays K] [--seed S] [--reps R] [--ref-links M] [--csv FILE] SCENE...
 *
 * Workload: N "links" between random pairs of mutually facing surfaces of the scene (each surface
 * has a vertex strictly in front of the other's plane, the test of the solver's initial linking),
 * K segments per link between uniform random points on the two surfaces (K = 16 is the solver's
 * default: one link = one 16-wide packet). The RNG is a fixed-seed xorshift, so every run casts
 * the same segments. Two link sets are measured:
 *   all      every random facing pair (what the solver's initial linking casts: in a large scene
 *            most pairs are hidden from each other, and blocked rays stop at the first hit);
 *   visible  only pairs with at least one unblocked segment (what refinement casts: its links
 *            survived initial linking). Unblocked rays must traverse the whole segment.
 * Methods (each the best of R repetitions; wall time and thread CPU time are both reported, the
 * CPU time being the robust one on a shared machine):
 *   embree-raw16  Embree's raw packet rate: our own device (threads=1) and triangle scene built
 *                 like vis.c, one rtcOccluded16 per link (COHERENT context), no filter function.
 *                 Rays can then hit the surfaces they start or end on, so its blocked fraction may
 *                 be higher than the others'.
 *   hr_vis        hr_vis_segments (src/vis.c) as the solver calls it: the same segments with
 *                 their ends lifted off their surfaces (hr_vis_lift), no skip filter.
 *   cand          hr_vis_segments_cand against the link's shaft-culled candidate list (lists
 *                 from hr_shaft_candidates, built outside the timed loop; their cost is printed).
 *   cand<=6       the same on the links whose list has at most 6 surfaces: the lists that the
 *                 solver (src/ff.c, CAND_BRUTE_MAX) tests by brute force instead of with Embree.
 * hr_vis_segments_ref (brute force against every surface) checks hr_vis and cand on the first M
 * links: the mismatch fraction is printed (a few are expected where a segment grazes an edge:
 * Embree works in float, the exact tests in double). */
#include "hrad.h"
#include "vis.h"
#include "../tests/xorshift.h"

#include <embree3/rtcore.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* ---------------------------------------------------------------- helpers */


static double clock_s(clockid_t id) {
  struct timespec ts;
  clock_gettime(id, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static hr_vec3 vsub(hr_vec3 a, hr_vec3 b) { return (hr_vec3){a.x - b.x, a.y - b.y, a.z - b.z}; }
static double vdot(hr_vec3 a, hr_vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }

/* Uniform random point on a triangle, or on a convex quad (split by the diagonal 0-2, halves
 * chosen by area). */
static hr_vec3 surf_point(const hr_surface *f) {
  int t0 = 0;
  if (f->nverts == 4) {
    hr_vec3 e1 = vsub(f->v[1], f->v[0]), e2 = vsub(f->v[2], f->v[0]), e3 = vsub(f->v[3], f->v[0]);
    hr_vec3 c1 = {e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z, e1.x * e2.y - e1.y * e2.x};
    hr_vec3 c2 = {e2.y * e3.z - e2.z * e3.y, e2.z * e3.x - e2.x * e3.z, e2.x * e3.y - e2.y * e3.x};
    double a1 = sqrt(vdot(c1, c1)), a2 = sqrt(vdot(c2, c2));
    t0 = rnd() * (a1 + a2) < a1 ? 0 : 1;
  }
  hr_vec3 p0 = f->v[0], p1 = f->v[1 + t0], p2 = f->v[2 + t0];
  double a = rnd(), b = rnd();
  if (a + b > 1) a = 1 - a, b = 1 - b;
  return (hr_vec3){p0.x + a * (p1.x - p0.x) + b * (p2.x - p0.x),
                   p0.y + a * (p1.y - p0.y) + b * (p2.y - p0.y),
                   p0.z + a * (p1.z - p0.z) + b * (p2.z - p0.z)};
}

/* 1 if some vertex of 'b' lies in front of the plane of 'a' (as in src/link.c). */
static int in_front(const hr_surface *a, const hr_surface *b) {
  double size = sqrt(a->area + b->area);
  for (int k = 0; k < b->nverts; k++)
    if (vdot(vsub(b->v[k], a->v[0]), a->normal) > 1e-9 * size) return 1;
  return 0;
}

/* ---------------------------------------------------------------- raw Embree scene */

typedef struct {
  RTCDevice dev;
  RTCScene scene;
} raw_embree;

static int raw_create(const hr_scene *s, raw_embree *r) {
  r->dev = rtcNewDevice("threads=1");
  if (!r->dev) return 0;
  r->scene = rtcNewScene(r->dev);
  rtcSetSceneBuildQuality(r->scene, RTC_BUILD_QUALITY_MEDIUM);
  size_t ntri = 0;
  for (int i = 0; i < s->nsurfs; i++) ntri += (size_t)(s->surfs[i].nverts - 2);
  RTCGeometry g = rtcNewGeometry(r->dev, RTC_GEOMETRY_TYPE_TRIANGLE);
  rtcSetGeometryBuildQuality(g, RTC_BUILD_QUALITY_MEDIUM);
  float *vb = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                      3 * sizeof(float), (size_t)s->nsurfs * 4);
  unsigned *ib = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                         3 * sizeof(unsigned), ntri);
  if (!vb || !ib) return 0;
  size_t t = 0;
  for (int i = 0; i < s->nsurfs; i++) {
    const hr_surface *f = &s->surfs[i];
    for (int k = 0; k < 4; k++) {
      hr_vec3 p = f->v[k < f->nverts ? k : f->nverts - 1];
      float *q = vb + ((size_t)i * 4 + (size_t)k) * 3;
      q[0] = (float)p.x, q[1] = (float)p.y, q[2] = (float)p.z;
    }
    for (int k = 1; k + 1 < f->nverts; k++, t++) {
      ib[3 * t] = (unsigned)i * 4u;
      ib[3 * t + 1] = (unsigned)i * 4u + (unsigned)k;
      ib[3 * t + 2] = (unsigned)i * 4u + (unsigned)k + 1;
    }
  }
  rtcCommitGeometry(g);
  rtcAttachGeometry(r->scene, g);
  rtcReleaseGeometry(g);
  rtcCommitScene(r->scene);
  return rtcGetDeviceError(r->dev) == RTC_ERROR_NONE;
}

static void raw_destroy(raw_embree *r) {
  if (r->scene) rtcReleaseScene(r->scene);
  if (r->dev) rtcReleaseDevice(r->dev);
}

/* K rays of one link in packets of 16 (the last one masked when K is not a multiple of 16). */
static void raw_occluded16(const raw_embree *r, int n, const float *org, const float *dst,
                           uint8_t *vis) {
  struct RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  for (int i0 = 0; i0 < n; i0 += 16) {
    struct RTCRay16 R; /* 64-byte aligned by its type */
    _Alignas(64) int valid[16];
    int cnt = n - i0 < 16 ? n - i0 : 16;
    for (int k = 0; k < 16; k++) {
      int i = i0 + (k < cnt ? k : cnt - 1);
      const float *o = org + 3 * (size_t)i, *d = dst + 3 * (size_t)i;
      R.org_x[k] = o[0], R.org_y[k] = o[1], R.org_z[k] = o[2];
      R.dir_x[k] = d[0] - o[0], R.dir_y[k] = d[1] - o[1], R.dir_z[k] = d[2] - o[2];
      R.tnear[k] = (float)HR_VIS_EPS, R.tfar[k] = (float)(1.0 - HR_VIS_EPS);
      R.time[k] = 0, R.mask[k] = 0xFFFFFFFFu, R.id[k] = (unsigned)k, R.flags[k] = 0;
      valid[k] = k < cnt ? -1 : 0;
    }
    rtcOccluded16(valid, r->scene, &ctx, &R);
    for (int k = 0; k < cnt; k++) vis[i0 + k] = R.tfar[k] >= 0.0f;
  }
}

/* ---------------------------------------------------------------- workload */

typedef struct {
  int L, K;
  int *a, *b;       /* surfaces of each link */
  float *org, *dst;   /* L*K*3 */
  float *lorg, *ldst; /* the same, ends lifted off their surfaces as the solver casts them */
  uint8_t *vis;     /* L*K */
  int32_t *cand;    /* concatenated shaft lists */
  int64_t *coff;    /* L+1 offsets into cand */
} workload;

static void wl_free(workload *w) {
  free(w->a), free(w->b), free(w->org), free(w->dst), free(w->vis), free(w->cand), free(w->coff);
  free(w->lorg), free(w->ldst);
  memset(w, 0, sizeof *w);
}

static int wl_alloc(workload *w, int L, int K) {
  memset(w, 0, sizeof *w);
  w->L = L, w->K = K;
  w->a = malloc(sizeof(int) * (size_t)L), w->b = malloc(sizeof(int) * (size_t)L);
  w->org = malloc(sizeof(float) * 3 * (size_t)L * (size_t)K);
  w->dst = malloc(sizeof(float) * 3 * (size_t)L * (size_t)K);
  w->lorg = malloc(sizeof(float) * 3 * (size_t)L * (size_t)K);
  w->ldst = malloc(sizeof(float) * 3 * (size_t)L * (size_t)K);
  w->vis = malloc((size_t)L * (size_t)K);
  w->coff = calloc((size_t)L + 1, sizeof(int64_t));
  return w->a && w->b && w->org && w->dst && w->lorg && w->ldst && w->vis && w->coff;
}

/* Random facing pairs with random segments. Returns 0 if the scene has (almost) none. */
static int wl_make(const hr_scene *s, workload *w, int L, int K) {
  if (!wl_alloc(w, L, K)) return 0;
  const double lift = hr_vis_lift(s);
  for (int l = 0; l < L; l++) {
    int a, b, tries = 0;
    do {
      if (++tries > 10000000) return 0;
      a = rnd_int(s->nsurfs), b = rnd_int(s->nsurfs);
    } while (a == b || !in_front(&s->surfs[a], &s->surfs[b]) ||
             !in_front(&s->surfs[b], &s->surfs[a]));
    w->a[l] = a, w->b[l] = b;
    const hr_surface *A = &s->surfs[a], *B = &s->surfs[b];
    double tol = 1e-9 * sqrt(A->area + B->area);
    for (int i = 0; i < K; i++) {
      /* Radiosity-style: each end in front of the other's plane (light can pass from A's front
       * to B's front); pairs that only just face each other may need many draws. */
      hr_vec3 p, q;
      int ok = 0;
      for (int t = 0; t < 1000 && !ok; t++) {
        p = surf_point(A), q = surf_point(B);
        ok = vdot(vsub(q, A->v[0]), A->normal) > tol && vdot(vsub(p, B->v[0]), B->normal) > tol;
      }
      if (!ok) { /* degenerate pair: draw another one */
        l--;
        goto next;
      }
      float *o = w->org + 3 * ((size_t)l * K + i), *d = w->dst + 3 * ((size_t)l * K + i);
      o[0] = (float)p.x, o[1] = (float)p.y, o[2] = (float)p.z;
      d[0] = (float)q.x, d[1] = (float)q.y, d[2] = (float)q.z;
      float *lo = w->lorg + 3 * ((size_t)l * K + i), *ld = w->ldst + 3 * ((size_t)l * K + i);
      lo[0] = (float)(p.x + lift * A->normal.x), lo[1] = (float)(p.y + lift * A->normal.y);
      lo[2] = (float)(p.z + lift * A->normal.z);
      ld[0] = (float)(q.x + lift * B->normal.x), ld[1] = (float)(q.y + lift * B->normal.y);
      ld[2] = (float)(q.z + lift * B->normal.z);
    }
  next:;
  }
  return 1;
}

/* Copies the links of 'src' with at least one segment unblocked (per src->vis) into 'dst'. */
static int wl_visible(const workload *src, workload *dst) {
  int K = src->K, n = 0;
  for (int l = 0; l < src->L; l++)
    for (int i = 0; i < K; i++)
      if (src->vis[(size_t)l * K + i]) {
        n++;
        break;
      }
  if (!wl_alloc(dst, n > 0 ? n : 1, K)) return 0;
  dst->L = n;
  int m = 0;
  for (int l = 0; l < src->L; l++) {
    int any = 0;
    for (int i = 0; i < K; i++) any |= src->vis[(size_t)l * K + i];
    if (!any) continue;
    dst->a[m] = src->a[l], dst->b[m] = src->b[l];
    memcpy(dst->org + 3 * (size_t)m * K, src->org + 3 * (size_t)l * K, sizeof(float) * 3 * K);
    memcpy(dst->dst + 3 * (size_t)m * K, src->dst + 3 * (size_t)l * K, sizeof(float) * 3 * K);
    memcpy(dst->lorg + 3 * (size_t)m * K, src->lorg + 3 * (size_t)l * K, sizeof(float) * 3 * K);
    memcpy(dst->ldst + 3 * (size_t)m * K, src->ldst + 3 * (size_t)l * K, sizeof(float) * 3 * K);
    m++;
  }
  return 1;
}

/* Shaft candidate lists for every link; returns seconds (thread CPU) per pair. */
static double wl_cands(const hr_scene *s, const hr_shaft_index *x, workload *w) {
  int32_t *tmp = NULL;
  int ntmp = 0, cap = 0;
  int64_t tot = 0, capc = 0;
  double t0 = clock_s(CLOCK_THREAD_CPUTIME_ID);
  for (int l = 0; l < w->L; l++) {
    const hr_surface *A = &s->surfs[w->a[l]], *B = &s->surfs[w->b[l]];
    ntmp = 0;
    if (hr_shaft_candidates(x, A->v, A->nverts, w->a[l], B->v, B->nverts, w->b[l], &tmp, &ntmp,
                            &cap) != HR_OK) {
      fprintf(stderr, "rayrate: out of memory\n");
      exit(1);
    }
    if (tot + ntmp > capc) {
      capc = (tot + ntmp) * 2 + 1024;
      w->cand = realloc(w->cand, sizeof(int32_t) * (size_t)capc);
      if (!w->cand) {
        fprintf(stderr, "rayrate: out of memory\n");
        exit(1);
      }
    }
    if (ntmp > 0) memcpy(w->cand + tot, tmp, sizeof(int32_t) * (size_t)ntmp);
    tot += ntmp;
    w->coff[l + 1] = tot;
  }
  double t = clock_s(CLOCK_THREAD_CPUTIME_ID) - t0;
  free(tmp);
  return w->L > 0 ? t / w->L : 0;
}

/* ---------------------------------------------------------------- measurement */

enum { M_RAW, M_VIS, M_CAND, M_CAND6, M_REF };
static const char *method_name[] = {"embree-raw16", "hr_vis", "cand", "cand<=6", "ref"};

typedef struct {
  double mrays_wall, mrays_cpu, blocked;
  long rays;
} result;

static void cast_link(int method, const hr_scene *s, const hr_vis *v, const raw_embree *raw,
                      const workload *w, int l) {
  size_t o = (size_t)l * w->K;
  const float *org = w->org + 3 * o, *dst = w->dst + 3 * o;
  uint8_t *vis = w->vis + o;
  switch (method) {
  case M_RAW: raw_occluded16(raw, w->K, org, dst, vis); break;
  case M_VIS: /* as the solver casts: ends lifted, no skip filter */
    hr_vis_segments(v, w->K, w->lorg + 3 * o, w->ldst + 3 * o, -1, -1, vis);
    break;
  case M_CAND:
  case M_CAND6:
    hr_vis_segments_cand(s, w->cand + w->coff[l], (int)(w->coff[l + 1] - w->coff[l]), w->K, org,
                         dst, w->a[l], w->b[l], vis);
    break;
  default: hr_vis_segments_ref(s, w->K, org, dst, w->a[l], w->b[l], vis); break;
  }
}

static result measure(int method, const hr_scene *s, const hr_vis *v, const raw_embree *raw,
                      workload *w, int reps, int nlinks) {
  result r = {0, 0, 0, 0};
  double bw = 1e30, bc = 1e30;
  long rays = 0;
  for (int rep = 0; rep < reps; rep++) {
    rays = 0;
    double w0 = clock_s(CLOCK_MONOTONIC), c0 = clock_s(CLOCK_THREAD_CPUTIME_ID);
    for (int l = 0; l < nlinks; l++) {
      if (method == M_CAND6 && w->coff[l + 1] - w->coff[l] > 6) continue;
      cast_link(method, s, v, raw, w, l);
      rays += w->K;
    }
    double tw = clock_s(CLOCK_MONOTONIC) - w0, tc = clock_s(CLOCK_THREAD_CPUTIME_ID) - c0;
    bw = tw < bw ? tw : bw;
    bc = tc < bc ? tc : bc;
  }
  long nb = 0;
  for (int l = 0; l < nlinks; l++) {
    if (method == M_CAND6 && w->coff[l + 1] - w->coff[l] > 6) continue;
    for (int i = 0; i < w->K; i++) nb += !w->vis[(size_t)l * w->K + i];
  }
  r.rays = rays;
  r.blocked = rays > 0 ? (double)nb / (double)rays : 0;
  r.mrays_wall = rays > 0 && bw > 0 ? 1e-6 * (double)rays / bw : 0;
  r.mrays_cpu = rays > 0 && bc > 0 ? 1e-6 * (double)rays / bc : 0;
  return r;
}

/* Fraction of segments of the first 'n' links where 'method' disagrees with the reference. */
static double mismatch(int method, const hr_scene *s, const hr_vis *v, workload *w, int n) {
  size_t nr = (size_t)n * w->K;
  uint8_t *ref = malloc(nr ? nr : 1);
  if (!ref) return -1;
  for (int l = 0; l < n; l++) cast_link(M_REF, s, v, NULL, w, l);
  memcpy(ref, w->vis, nr);
  for (int l = 0; l < n; l++) cast_link(method, s, v, NULL, w, l);
  long bad = 0;
  for (size_t i = 0; i < nr; i++) bad += ref[i] != w->vis[i];
  free(ref);
  return nr ? (double)bad / (double)nr : 0;
}

static FILE *csv;

static void report(const char *scene, const char *set, int method, result r) {
  printf("  %-8s %-13s %9ld rays  blocked %5.1f%%  %7.2f Mrays/s wall  %7.2f Mrays/s cpu\n", set,
         method_name[method], r.rays, 100 * r.blocked, r.mrays_wall, r.mrays_cpu);
  if (csv)
    fprintf(csv, "%s,%s,%s,%ld,%.4f,%.3f,%.3f\n", scene, set, method_name[method], r.rays,
            r.blocked, r.mrays_wall, r.mrays_cpu);
}

static int run_scene(const char *name, int L, int K, uint64_t seed, int reps, int nref) {
  hr_scene *s = NULL;
  hr_err err = {{0}};
  if (hr_scene_builtin(name, &s, &err) != HR_OK) {
    fprintf(stderr, "rayrate: %s\n", err.msg);
    return 1;
  }
  rng_state = seed ? seed : 0x9e3779b97f4a7c15ull;
  hr_vis *v = NULL;
  double t0 = clock_s(CLOCK_MONOTONIC);
  if (hr_vis_create(s, &v, &err) != HR_OK) {
    fprintf(stderr, "rayrate: %s\n", err.msg);
    hr_scene_destroy(&s);
    return 1;
  }
  double t_vis = clock_s(CLOCK_MONOTONIC) - t0;
  raw_embree raw = {NULL, NULL};
  t0 = clock_s(CLOCK_MONOTONIC);
  if (!raw_create(s, &raw)) {
    fprintf(stderr, "rayrate: cannot build the Embree scene\n");
    return 1;
  }
  double t_raw = clock_s(CLOCK_MONOTONIC) - t0;
  hr_shaft_index *x = NULL;
  if (hr_shaft_index_create(s, &x) != HR_OK) {
    fprintf(stderr, "rayrate: cannot build the shaft index\n");
    return 1;
  }
  workload all, vis;
  if (!wl_make(s, &all, L, K)) {
    fprintf(stderr, "rayrate: %s: no mutually facing surface pairs found\n", name);
    return 1;
  }
  printf("%s: %d surfaces; %d links x %d rays between random facing surface pairs (seed %llu), "
         "best of %d, one thread\n",
         name, s->nsurfs, L, K, (unsigned long long)seed, reps);
  printf("  build: hr_vis_create %.1f ms, raw Embree scene %.1f ms\n", 1e3 * t_vis, 1e3 * t_raw);

  double tq = wl_cands(s, x, &all);
  int n6 = 0;
  for (int l = 0; l < all.L; l++) n6 += all.coff[l + 1] - all.coff[l] <= 6;
  printf("  shaft lists: %.1f us per pair, mean length %.1f, %.0f%% of links have <= 6\n",
         1e6 * tq, (double)all.coff[all.L] / all.L, 100.0 * n6 / all.L);

  /* hr_vis first: its vis[] selects the visible set */
  result rv = measure(M_VIS, s, v, &raw, &all, reps, all.L);
  if (!wl_visible(&all, &vis)) return 1;
  result rr = measure(M_RAW, s, v, &raw, &all, reps, all.L);
  result rc = measure(M_CAND, s, v, &raw, &all, reps, all.L);
  result r6 = measure(M_CAND6, s, v, &raw, &all, reps, all.L);
  report(name, "all", M_RAW, rr);
  report(name, "all", M_VIS, rv);
  report(name, "all", M_CAND, rc);
  report(name, "all", M_CAND6, r6);
  if (vis.L > 0) {
    wl_cands(s, x, &vis);
    report(name, "visible", M_RAW, measure(M_RAW, s, v, &raw, &vis, reps, vis.L));
    report(name, "visible", M_VIS, measure(M_VIS, s, v, &raw, &vis, reps, vis.L));
    report(name, "visible", M_CAND, measure(M_CAND, s, v, &raw, &vis, reps, vis.L));
    report(name, "visible", M_CAND6, measure(M_CAND6, s, v, &raw, &vis, reps, vis.L));
  }
  int nr = nref < all.L ? nref : all.L;
  if (nr > 0) {
    result rf = measure(M_REF, s, v, &raw, &all, 1, nr);
    report(name, "all", M_REF, rf);
    printf("  check vs hr_vis_segments_ref on %d links: hr_vis differs on %.3f%% of segments, "
           "cand on %.3f%%\n",
           nr, 100 * mismatch(M_VIS, s, v, &all, nr), 100 * mismatch(M_CAND, s, v, &all, nr));
  }
  wl_free(&all);
  wl_free(&vis);
  hr_shaft_index_destroy(&x);
  raw_destroy(&raw);
  hr_vis_destroy(&v);
  hr_scene_destroy(&s);
  return 0;
}

static void usage(FILE *f) {
  fprintf(f, "usage: rayrate [--links N] [--rays K] [--seed S] [--reps R] [--ref-links M] "
             "[--csv FILE] SCENE...\n"
             "  Single-threaded occlusion-ray rates on built-in scenes (room, floor, museum, "
             "cornell).\n"
             "  Defaults: --links 20000 --rays 16 --seed 1 --reps 3 --ref-links 500.\n");
}

int main(int argc, char **argv) {
  int L = 20000, K = 16, reps = 3, nref = 500;
  uint64_t seed = 1;
  const char *csv_path = NULL;
  int first = argc;
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
    int has = i + 1 < argc;
    if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
      usage(stdout);
      return 0;
    } else if (!strcmp(a, "--links") && has) {
      L = atoi(argv[++i]);
    } else if (!strcmp(a, "--rays") && has) {
      K = atoi(argv[++i]);
    } else if (!strcmp(a, "--seed") && has) {
      seed = strtoull(argv[++i], NULL, 10);
    } else if (!strcmp(a, "--reps") && has) {
      reps = atoi(argv[++i]);
    } else if (!strcmp(a, "--ref-links") && has) {
      nref = atoi(argv[++i]);
    } else if (!strcmp(a, "--csv") && has) {
      csv_path = argv[++i];
    } else if (a[0] == '-') {
      fprintf(stderr, "rayrate: unknown option '%s'\n", a);
      usage(stderr);
      return 2;
    } else {
      first = i;
      break;
    }
  }
  if (L < 1 || K < 1 || K > 1024 || reps < 1 || nref < 0 || first >= argc) {
    usage(stderr);
    return 2;
  }
  if (csv_path) {
    csv = fopen(csv_path, "w");
    if (!csv) {
      fprintf(stderr, "rayrate: cannot write %s\n", csv_path);
      return 1;
    }
    fprintf(csv, "scene,set,method,rays,blocked_frac,mrays_wall,mrays_cpu\n");
  }
  int rc = 0;
  for (int i = first; i < argc && rc == 0; i++) rc = run_scene(argv[i], L, K, seed, reps, nref);
  if (csv && fclose(csv) != 0) {
    fprintf(stderr, "rayrate: cannot write %s\n", csv_path);
    rc = 1;
  }
  return rc;
}
