/* pt.c: the reference path tracer, the slow and obviously correct twin of the whole radiosity
 * solver (docs/design.md). It estimates the radiosity of the same scene model independently:
 *
 *   B(x) = E(x) + rho(x) * integral over the front hemisphere of B(y(x, w)) / pi * cos dw,
 *
 * with one-sided surfaces (light leaves the front only; a ray reaching a back face, or leaving
 * the scene, carries nothing; nothing is transmitted). A sample at x is E(x) plus a random walk:
 * at every vertex, next-event estimation (an emitting surface picked with probability
 * proportional to area * (E_r + E_g + E_b), a uniform point on it, a shadow ray) and a
 * cosine-weighted continuation ray whose hit on an emitter's front adds its emission, the two
 * combined by multiple importance sampling (power heuristic). The throughput is multiplied by
 * rho at every front hit; Russian roulette (survival from the largest throughput channel, at
 * most 0.95) ends paths without bias after PT_RR_DEPTH bounces.
 *
 * Rays are Embree closest hits (hr_vis_hit). Ray origins are lifted off their surface along its
 * front normal by hr_vis_lift, so that a ray cannot hit its own surface after rounding to float.
 * Random numbers are counter-based (splitmix64 keyed by a hash of seed, item and sample), work
 * is split into fixed blocks and blocks are combined in a fixed order: results are bit-identical
 * for any thread count. The library never prints. */
#include "hrad.h"
#include "vec.h"
#include "vis.h"

#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

#define PT_BLOCK 4096    /* paths per work block of hr_pt_polys */
#define PT_RR_DEPTH 3    /* bounces before Russian roulette starts */
#define PT_RR_MAX 0.95   /* largest survival probability */
#define PT_RR_REF 0.25   /* throughput to which roulette survivors are raised */
#define PT_MAX_DEPTH 10000 /* safety cap; Russian roulette ends paths long before */

/* ------------------------------------------------------------------ random numbers */

typedef struct pt_rng {
  uint64_t key, ctr;
} pt_rng;

/* A generator for sample 'b' of item 'a' (a polygon or a pixel) under 'seed'; 'domain' keeps
 * the polygon and image streams apart. */
static pt_rng rng_make(uint64_t seed, uint64_t domain, uint64_t a, uint64_t b) {
  uint64_t h = u64_mix(seed ^ u64_mix(domain + 0x9e3779b97f4a7c15ull));
  h = u64_mix(h ^ (a * 0xbf58476d1ce4e5b9ull + 1));
  h = u64_mix(h ^ (b * 0x94d049bb133111ebull + 2));
  return (pt_rng){h, 0};
}

/* The next uniform number in [0, 1) (53 bits): splitmix64 with the key as its state. */
static double rng_u(pt_rng *r) {
  r->ctr++;
  return (double)(u64_mix(r->key + r->ctr * 0x9e3779b97f4a7c15ull) >> 11) * 0x1p-53;
}

/* ------------------------------------------------------------------ sampling tables */

typedef struct pt_ctx {
  const hr_scene *s;
  hr_vis *vis;
  double lift;
  double *split;    /* [nsurfs] probability of a quad's first triangle (v0 v1 v2); 1: triangle */
  int *poly_first;  /* [npolys+1]: polygon p's surfaces are poly_surf[poly_first[p] .. [p+1]) */
  int *poly_surf;   /* [nsurfs] */
  double *poly_cdf; /* [nsurfs] cumulative area fraction within the polygon, as poly_surf */
  int nlight;
  int *light_surf;  /* [nlight] emitting surfaces */
  double *light_cdf;/* [nlight] cumulative selection probability */
  double *light_pdf;/* [nsurfs] area density of the light sample on a surface (0: not a light) */
} pt_ctx;

static double tri_area(hr_vec3 a, hr_vec3 b, hr_vec3 c) {
  return 0.5 * v3_len(v3_cross(v3_sub(b, a), v3_sub(c, a)));
}

static double emit_sum(const pt_ctx *c, int surf) {
  const double *e = c->s->mats[c->s->surfs[surf].material].emit;
  return e[0] + e[1] + e[2];
}

static void ctx_destroy(pt_ctx *c) {
  hr_vis_destroy(&c->vis);
  free(c->split);
  free(c->poly_first);
  free(c->poly_surf);
  free(c->poly_cdf);
  free(c->light_surf);
  free(c->light_cdf);
  free(c->light_pdf);
  memset(c, 0, sizeof *c);
}

/* Fills split[]: a convex planar quad is sampled as its two fan triangles, chosen by area. */
static void build_split(pt_ctx *c) {
  for (int i = 0; i < c->s->nsurfs; i++) {
    const hr_surface *f = &c->s->surfs[i];
    c->split[i] = 1;
    if (f->nverts == 4) {
      double a1 = tri_area(f->v[0], f->v[1], f->v[2]), a2 = tri_area(f->v[0], f->v[2], f->v[3]);
      c->split[i] = a1 + a2 > 0 ? a1 / (a1 + a2) : 1;
    }
  }
}

/* Groups the surfaces by polygon (CSR, in surface order) with their cumulative area fractions.
 * poly_first must be zeroed. */
static void build_polys(pt_ctx *c) {
  const hr_scene *s = c->s;
  for (int i = 0; i < s->nsurfs; i++) c->poly_first[s->surfs[i].poly + 1]++;
  for (int p = 0; p < s->npolys; p++) c->poly_first[p + 1] += c->poly_first[p];
  /* Counting sort, stable: poly_first[p] serves as polygon p's cursor, which leaves it at the
   * start of p + 1; shifting the array by one restores the starts. */
  for (int i = 0; i < s->nsurfs; i++) c->poly_surf[c->poly_first[s->surfs[i].poly]++] = i;
  memmove(c->poly_first + 1, c->poly_first, (size_t)s->npolys * sizeof *c->poly_first);
  c->poly_first[0] = 0;
  for (int p = 0; p < s->npolys; p++) {
    double tot = 0, acc = 0;
    for (int k = c->poly_first[p]; k < c->poly_first[p + 1]; k++)
      tot += s->surfs[c->poly_surf[k]].area;
    for (int k = c->poly_first[p]; k < c->poly_first[p + 1]; k++) {
      acc += s->surfs[c->poly_surf[k]].area;
      c->poly_cdf[k] = tot > 0 ? acc / tot : 1;
    }
  }
}

/* Lists the emitting surfaces with selection probability proportional to area * sum(E). */
static void build_lights(pt_ctx *c) {
  const hr_scene *s = c->s;
  double tot = 0;
  for (int i = 0; i < s->nsurfs; i++)
    if (emit_sum(c, i) > 0 && s->surfs[i].area > 0) tot += s->surfs[i].area * emit_sum(c, i);
  double acc = 0;
  for (int i = 0; i < s->nsurfs; i++) {
    c->light_pdf[i] = 0;
    if (!(emit_sum(c, i) > 0 && s->surfs[i].area > 0)) continue;
    acc += s->surfs[i].area * emit_sum(c, i);
    c->light_surf[c->nlight] = i;
    c->light_cdf[c->nlight++] = acc / tot;
    c->light_pdf[i] = emit_sum(c, i) / tot; /* (A_i sum E_i / tot) / A_i */
  }
}

/* Validates the scene and builds the ray caster and the sampling tables. On error 'c' holds
 * nothing and the message is in 'err'. */
static hr_status ctx_create(pt_ctx *c, const hr_scene *s, hr_err *err) {
  memset(c, 0, sizeof *c);
  if (!s || s->nsurfs < 1 || s->npolys < 1)
    return hr_err_set(err, HR_ERR_INVALID, "path tracer: empty scene");
  for (int i = 0; i < s->nsurfs; i++)
    if (s->surfs[i].poly < 0 || s->surfs[i].poly >= s->npolys || s->surfs[i].material < 0 ||
        s->surfs[i].material >= s->nmats || (s->surfs[i].nverts != 3 && s->surfs[i].nverts != 4))
      return hr_err_set(err, HR_ERR_INVALID, "path tracer: surface %d is malformed", i);
  hr_status rs = hr_vis_check_range(s, err);
  if (rs != HR_OK) return rs;
  c->s = s;
  c->lift = hr_vis_lift(s);
  size_t n = (size_t)s->nsurfs;
  c->split = malloc(n * sizeof *c->split);
  c->poly_first = calloc((size_t)s->npolys + 1, sizeof *c->poly_first);
  c->poly_surf = malloc(n * sizeof *c->poly_surf);
  c->poly_cdf = malloc(n * sizeof *c->poly_cdf);
  c->light_surf = malloc(n * sizeof *c->light_surf);
  c->light_cdf = malloc(n * sizeof *c->light_cdf);
  c->light_pdf = malloc(n * sizeof *c->light_pdf);
  if (!c->split || !c->poly_first || !c->poly_surf || !c->poly_cdf || !c->light_surf ||
      !c->light_cdf || !c->light_pdf) {
    ctx_destroy(c);
    return hr_err_set(err, HR_ERR_NOMEM, "path tracer: out of memory");
  }
  build_split(c);
  build_polys(c);
  build_lights(c);
  hr_status st = hr_vis_create(s, &c->vis, err);
  if (st != HR_OK) ctx_destroy(c);
  return st;
}

/* The first index k of cdf[0..n) with u < cdf[k] (the last one if rounding leaves none). */
static int pick(const double *cdf, int n, double u) {
  int lo = 0, hi = n - 1;
  while (lo < hi) {
    int mid = (lo + hi) / 2;
    if (u < cdf[mid])
      hi = mid;
    else
      lo = mid + 1;
  }
  return lo;
}

/* A point uniformly distributed by area on surface 'i' (three uniform numbers from 'r'). */
static hr_vec3 surf_point(const pt_ctx *c, int i, pt_rng *r) {
  const hr_surface *f = &c->s->surfs[i];
  hr_vec3 a = f->v[0], b = f->v[1], d = f->v[2];
  if (f->nverts == 4 && rng_u(r) >= c->split[i]) b = f->v[2], d = f->v[3];
  double su = sqrt(rng_u(r)), v = rng_u(r);
  /* barycentric (1 - su, su (1 - v), su v): uniform over the triangle */
  return v3_add(a, v3_add(v3_scale(v3_sub(b, a), su * (1 - v)), v3_scale(v3_sub(d, a), su * v)));
}

/* ------------------------------------------------------------------ rays */

/* A direction about unit normal 'n' with density cos(theta) / pi. */
static hr_vec3 cos_sample(hr_vec3 n, pt_rng *r) {
  /* orthonormal basis (Duff et al. 2017) */
  double sg = n.z >= 0 ? 1.0 : -1.0, a = -1.0 / (sg + n.z), b = n.x * n.y * a;
  hr_vec3 t = v3(1 + sg * n.x * n.x * a, sg * b, -sg * n.x);
  hr_vec3 u = v3(b, sg + n.y * n.y * a, -n.y);
  double u1 = rng_u(r), phi = 2 * M_PI * rng_u(r), rr = sqrt(u1);
  double z = sqrt(1 - u1);
  return v3_add(v3_scale(n, z), v3_add(v3_scale(t, rr * cos(phi)), v3_scale(u, rr * sin(phi))));
}

/* The closest surface hit by the ray from 'org' (already off any surface) in unit direction
 * 'w' up to distance 'tfar'; sets '*y' to the hit point moved exactly onto the surface's plane.
 * Returns -1 on a miss. */
static int cast(const pt_ctx *c, hr_vec3 org, hr_vec3 w, double tfar, hr_vec3 *y) {
  float o[3] = {(float)org.x, (float)org.y, (float)org.z};
  float d[3] = {(float)w.x, (float)w.y, (float)w.z};
  float t;
  int k = hr_vis_hit(c->vis, o, d, (float)tfar, &t);
  if (k < 0) return -1;
  const hr_surface *g = &c->s->surfs[k];
  hr_vec3 p = v3_add(v3(o[0], o[1], o[2]), v3_scale(v3(d[0], d[1], d[2]), t));
  *y = v3_sub(p, v3_scale(g->normal, v3_dot(g->normal, v3_sub(p, g->v[0]))));
  return k;
}

/* Point x on surface 'sf' lifted off it along the front normal. */
static hr_vec3 lifted(const pt_ctx *c, int sf, hr_vec3 x) {
  return v3_add(x, v3_scale(c->s->surfs[sf].normal, c->lift));
}

/* 1 when nothing lies between x (on surface 'sf', lifted) and y on light surface 'j'. */
static int unoccluded(const pt_ctx *c, int sf, hr_vec3 x, int j, hr_vec3 y) {
  hr_vec3 o = lifted(c, sf, x);
  hr_vec3 d = v3_sub(y, o);
  double len = v3_len(d);
  if (!(len > 0)) return 1;
  hr_vec3 hit;
  /* The segment ends on the light: reaching it (or nothing, after rounding) means visible. A
   * planar surface is crossed once, so a hit on 'j' is the sampled point itself. */
  int k = cast(c, o, v3_scale(d, 1.0 / len), len, &hit);
  return k < 0 || k == j;
}

static double power2(double a, double b) { return a * a / (a * a + b * b); }

/* ------------------------------------------------------------------ the estimator */

/* Next-event estimation at x (surface 'sf', normal n): adds beta * (the light of one sampled
 * emitter point, MIS-weighted against cosine sampling) to Y. */
static void add_light(const pt_ctx *c, pt_rng *r, int sf, hr_vec3 x, const double beta[3],
                      double Y[3]) {
  if (c->nlight == 0) return;
  int j = c->light_surf[pick(c->light_cdf, c->nlight, rng_u(r))];
  hr_vec3 y = surf_point(c, j, r), d = v3_sub(y, x);
  double d2 = v3_dot(d, d);
  if (!(d2 > 0)) return;
  hr_vec3 w = v3_scale(d, 1.0 / sqrt(d2));
  double cos_x = v3_dot(c->s->surfs[sf].normal, w), cos_y = -v3_dot(c->s->surfs[j].normal, w);
  if (!(cos_x > 0 && cos_y > 0) || !unoccluded(c, sf, x, j, y)) return;
  double pl = c->light_pdf[j] * d2 / cos_y, pb = cos_x / M_PI; /* solid-angle densities */
  double g = cos_x * cos_y / (M_PI * d2) / c->light_pdf[j] * power2(pl, pb);
  const double *E = c->s->mats[c->s->surfs[j].material].emit;
  for (int ch = 0; ch < 3; ch++) Y[ch] += beta[ch] * E[ch] * g;
}

/* The emission of a front hit on surface 'k' at y, reached from x by cosine sampling
 * (cos_x at x, cos_y at y), times beta and its MIS weight, added to Y. */
static void add_hit_emission(const pt_ctx *c, int k, hr_vec3 x, hr_vec3 y, double cos_x,
                             double cos_y, const double beta[3], double Y[3]) {
  if (!(c->light_pdf[k] > 0)) return;
  hr_vec3 d = v3_sub(y, x);
  double pl = c->light_pdf[k] * v3_dot(d, d) / cos_y, pb = cos_x / M_PI;
  double wb = power2(pb, pl);
  const double *E = c->s->mats[c->s->surfs[k].material].emit;
  for (int ch = 0; ch < 3; ch++) Y[ch] += beta[ch] * E[ch] * wb;
}

/* Russian roulette on the throughput: returns 0 to end the path, else 1 with beta divided by
 * the survival probability q = min(PT_RR_MAX, max(beta) / PT_RR_REF). A path whose throughput
 * fell below PT_RR_REF survives with a probability that raises it back to PT_RR_REF, so no
 * surviving path carries more than that: measured against q = min(0.95, max(beta)), this cut the
 * variance per unit time 6x in a rho 0.5 furnace, 5x at rho 0.9 and 2-4x in the Cornell box
 * (the survivors' large weights dominated the noise). The cap keeps bright closed scenes from
 * tracing forever. Unbiased either way. */
static int roulette(pt_rng *r, double beta[3]) {
  double q = fmax(beta[0], fmax(beta[1], beta[2])) / PT_RR_REF;
  if (q > PT_RR_MAX) q = PT_RR_MAX;
  if (!(q > 0) || rng_u(r) >= q) return 0;
  for (int ch = 0; ch < 3; ch++) beta[ch] /= q;
  return 1;
}

/* One unbiased sample of B(x) for x on the front of surface 'sf': E(x) plus a path. */
static void radiosity_sample(const pt_ctx *c, pt_rng *r, int sf, hr_vec3 x, double Y[3]) {
  const hr_material *m = &c->s->mats[c->s->surfs[sf].material];
  double beta[3];
  for (int ch = 0; ch < 3; ch++) Y[ch] = m->emit[ch], beta[ch] = m->rho[ch];
  for (int depth = 0; depth < PT_MAX_DEPTH; depth++) {
    if (!(beta[0] > 0 || beta[1] > 0 || beta[2] > 0)) return;
    add_light(c, r, sf, x, beta, Y);
    hr_vec3 n = c->s->surfs[sf].normal, w = cos_sample(n, r), y;
    double cos_x = v3_dot(n, w);
    if (!(cos_x > 0)) return; /* only when rounding puts w in the plane: density 0 */
    int k = cast(c, lifted(c, sf, x), w, INFINITY, &y);
    if (k < 0) return;
    double cos_y = -v3_dot(c->s->surfs[k].normal, w);
    if (!(cos_y > 0)) return; /* back face: black, absorbing */
    add_hit_emission(c, k, x, y, cos_x, cos_y, beta, Y);
    const double *rho = c->s->mats[c->s->surfs[k].material].rho;
    for (int ch = 0; ch < 3; ch++) beta[ch] *= rho[ch];
    sf = k, x = y;
    if (depth + 1 >= PT_RR_DEPTH && !roulette(r, beta)) return;
  }
}

/* ------------------------------------------------------------------ per-polygon means */

/* Count, mean and sum of squared deviations of a set of samples (Welford / Chan et al.). */
typedef struct pt_stat {
  double n, mean[3], m2[3];
} pt_stat;

static void stat_add(pt_stat *a, const double y[3]) {
  a->n += 1;
  for (int ch = 0; ch < 3; ch++) {
    double d = y[ch] - a->mean[ch];
    a->mean[ch] += d / a->n;
    a->m2[ch] += d * (y[ch] - a->mean[ch]);
  }
}

/* a = a merged with b (Chan et al.'s pairwise update). */
static void stat_merge(pt_stat *a, const pt_stat *b) {
  if (b->n == 0) return;
  double n = a->n + b->n;
  for (int ch = 0; ch < 3; ch++) {
    double d = b->mean[ch] - a->mean[ch];
    a->mean[ch] += d * b->n / n;
    a->m2[ch] += b->m2[ch] + d * d * a->n * b->n / n;
  }
  a->n = n;
}

/* Samples [i0, i1) of polygon p: each a point uniform by area on the polygon and its B. */
static void poly_block(const pt_ctx *c, uint64_t seed, int p, int64_t i0, int64_t i1,
                       pt_stat *out) {
  memset(out, 0, sizeof *out);
  const int k0 = c->poly_first[p], nk = c->poly_first[p + 1] - k0;
  if (nk == 0) return;
  for (int64_t i = i0; i < i1; i++) {
    pt_rng r = rng_make(seed, 1, (uint64_t)p, (uint64_t)i);
    int sf = c->poly_surf[k0 + pick(c->poly_cdf + k0, nk, rng_u(&r))];
    double y[3];
    radiosity_sample(c, &r, sf, surf_point(c, sf, &r), y);
    stat_add(out, y);
  }
}

static int nthreads(const hr_pt_options *o) {
  return o->threads > 0 ? o->threads : omp_get_num_procs();
}

void hr_pt_options_default(hr_pt_options *o) {
  o->paths = 10000;
  o->seed = 1;
  o->threads = 0;
}

hr_status hr_pt_polys(const hr_scene *s, const hr_pt_options *o, double (*mean)[3],
                      double (*stderr_)[3], hr_err *err) {
  hr_pt_options def;
  hr_pt_options_default(&def);
  if (!o) o = &def;
  if (!mean || o->paths < 1 || o->threads < 0)
    return hr_err_set(err, HR_ERR_INVALID, "path tracer: bad arguments (paths %lld)",
                      (long long)o->paths);
  pt_ctx c;
  hr_status st = ctx_create(&c, s, err);
  if (st != HR_OK) return st;
  const int64_t nb = (o->paths + PT_BLOCK - 1) / PT_BLOCK, nitems = nb * s->npolys;
  pt_stat *blk = malloc((size_t)nitems * sizeof *blk);
  if (!blk) {
    ctx_destroy(&c);
    return hr_err_set(err, HR_ERR_NOMEM, "path tracer: out of memory");
  }
  /* Each block depends only on (polygon, block index): any schedule gives the same blocks. */
#pragma omp parallel for schedule(dynamic, 1) num_threads(nthreads(o))
  for (int64_t it = 0; it < nitems; it++) {
    int64_t b = it % nb, i0 = b * PT_BLOCK;
    int64_t i1 = i0 + PT_BLOCK < o->paths ? i0 + PT_BLOCK : o->paths;
    poly_block(&c, o->seed, (int)(it / nb), i0, i1, &blk[it]);
  }
  for (int p = 0; p < s->npolys; p++) { /* fixed order of combination */
    pt_stat acc = blk[(int64_t)p * nb];
    for (int64_t b = 1; b < nb; b++) stat_merge(&acc, &blk[(int64_t)p * nb + b]);
    for (int ch = 0; ch < 3; ch++) {
      mean[p][ch] = acc.mean[ch];
      if (stderr_)
        stderr_[p][ch] = acc.n > 1 ? sqrt(acc.m2[ch] / (acc.n - 1) / acc.n) : NAN;
    }
  }
  free(blk);
  ctx_destroy(&c);
  return HR_OK;
}

/* ------------------------------------------------------------------ image */

/* The camera frame of hr_render: forward, right, up, and the projection scales fx, fy. */
typedef struct pt_cam {
  hr_vec3 eye, fwd, right, up;
  double fx, fy;
} pt_cam;

/* Sets up 'k' as render.c does; returns 0 for a degenerate camera. */
static int cam_setup(const hr_camera *cam, int w, int h, pt_cam *k) {
  if (!(cam->fov_deg > 0 && cam->fov_deg < 180)) return 0;
  hr_vec3 fwd = v3_sub(cam->at, cam->eye);
  if (!(v3_len(fwd) > 0)) return 0;
  fwd = v3_norm(fwd);
  hr_vec3 right = v3_cross(fwd, cam->up);
  if (!(v3_len(right) > 1e-9 * v3_len(cam->up)))
    right = v3_cross(fwd, fabs(fwd.y) < 0.9 ? v3(0, 1, 0) : v3(1, 0, 0));
  right = v3_norm(right);
  k->eye = cam->eye;
  k->fwd = fwd;
  k->right = right;
  k->up = v3_cross(right, fwd);
  k->fy = 1.0 / tan(0.5 * cam->fov_deg * M_PI / 180.0);
  k->fx = k->fy * h / (double)w;
  return 1;
}

/* Unit direction through continuous pixel coordinates (px, py) (pixel x spans [x, x+1), row 0
 * at the top), the inverse of render.c's projection. */
static hr_vec3 cam_dir(const pt_cam *k, int w, int h, double px, double py) {
  double nx = 2.0 * px / w - 1.0, ny = 1.0 - 2.0 * py / h;
  hr_vec3 side = v3_add(v3_scale(k->right, nx / k->fx), v3_scale(k->up, ny / k->fy));
  return v3_norm(v3_add(k->fwd, side));
}

/* Largest divisor of n not above sqrt(n): the strata grid is sx x (n / sx). */
static int strata_x(int n) {
  int best = 1;
  for (int d = 1; (int64_t)d * d <= n; d++)
    if (n % d == 0) best = d;
  return best;
}

/* Pixel (x, y): 'spp' stratified jittered camera rays; mean and standard error. */
static void pixel(const pt_ctx *c, const pt_cam *k, int w, int h, int x, int y, int spp,
                  uint64_t seed, double mean[3], double se[3]) {
  pt_stat st;
  memset(&st, 0, sizeof st);
  const int sx = strata_x(spp), sy = spp / sx;
  for (int i = 0; i < spp; i++) {
    pt_rng r = rng_make(seed, 2, (uint64_t)y * (uint64_t)w + (uint64_t)x, (uint64_t)i);
    double px = x + (i % sx + rng_u(&r)) / sx, py = y + (i / sx + rng_u(&r)) / sy;
    hr_vec3 d = cam_dir(k, w, h, px, py), p;
    double v[3] = {0, 0, 0};
    int sf = cast(c, k->eye, d, INFINITY, &p);
    if (sf >= 0 && v3_dot(c->s->surfs[sf].normal, d) < 0) radiosity_sample(c, &r, sf, p, v);
    stat_add(&st, v);
  }
  for (int ch = 0; ch < 3; ch++) {
    mean[ch] = st.mean[ch];
    se[ch] = spp > 1 ? sqrt(st.m2[ch] / (spp - 1) / spp) : NAN;
  }
}

hr_status hr_pt_image(const hr_scene *s, const hr_camera *cam, int w, int h, int spp,
                      const hr_pt_options *o, float *rgb, float *se, hr_err *err) {
  hr_pt_options def;
  hr_pt_options_default(&def);
  if (!o) o = &def;
  pt_cam k;
  if (!cam || !rgb || w < 1 || h < 1 || w > 16384 || h > 16384 || spp < 1 || o->threads < 0 ||
      !cam_setup(cam, w, h, &k))
    return hr_err_set(err, HR_ERR_INVALID, "path tracer: bad image arguments");
  pt_ctx c;
  hr_status st = ctx_create(&c, s, err);
  if (st != HR_OK) return st;
#pragma omp parallel for schedule(dynamic, 1) num_threads(nthreads(o))
  for (int y = 0; y < h; y++)
    for (int x = 0; x < w; x++) {
      double m[3], e[3];
      pixel(&c, &k, w, h, x, y, spp, o->seed, m, e);
      size_t i = 3 * ((size_t)y * w + x);
      for (int ch = 0; ch < 3; ch++) {
        rgb[i + ch] = (float)m[ch];
        if (se) se[i + ch] = (float)e[ch];
      }
    }
  ctx_destroy(&c);
  return HR_OK;
}
