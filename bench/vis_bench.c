/* vis_bench.c: ray rates of the visibility module (not built by CMake). It includes vis.c to
 * reach the internal ray-batching modes. Build and run (Release flags like the library):
 *
 *   gcc -std=c11 -O3 -DNDEBUG -mavx2 -mfma -D_GNU_SOURCE -Iinclude -Isrc bench/vis_bench.c \
 *       src/scene.c src/shaft.c -lembree3 -lm -o /tmp/vis_bench && /tmp/vis_bench [nboxes ntris]
 *
 * Add -DHR_VIS_BUILD_QUALITY=RTC_BUILD_QUALITY_HIGH or -DHR_VIS_SCENE_FLAGS=RTC_SCENE_FLAG_ROBUST
 * to compare Embree build settings. Times are thread CPU time (the 2-core machine is shared).
 *
 * Measured (4006 surfaces: room + 600 boxes + 400 triangles, one core, load ~3 on 2 cores, so
 * +-15%): hr_vis_segments with 16 rays/link 6-8 Mrays/s (7-9 without skip filter), rtcOccluded1
 * 4.5-5.5, stream rtcOccluded1M 6.3-8; with 4 rays/link stream 4.3-5.3, rtcOccluded4 3-3.6.
 * Candidate brute force (16 rays/link): list of 1: 45-70, 4: 21-30, 16: 12-17, 64: 5.5-9 Mrays/s.
 * Shaft candidates: 5-10 us per pair (lists of 20-45), filter for a child pair 1.7-2.4 us. */
#include "../src/vis.c"
#include "../tests/xorshift.h"

#include <stdio.h>
#include <time.h>


static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts); /* CPU time: robust to a busy machine */
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void add_quad(hr_scene *s, hr_vec3 a, hr_vec3 b, hr_vec3 c, hr_vec3 d) {
  hr_vec3 v[4] = {a, b, c, d};
  hr_poly_result r;
  hr_scene_add_polygon(s, v, 4, 0, &r);
}

static void add_box(hr_scene *s, hr_vec3 c, hr_vec3 h, double ang) {
  hr_vec3 p[8];
  double ca = cos(ang), sa = sin(ang);
  for (int i = 0; i < 8; i++) {
    double x = (i & 1) ? h.x : -h.x, y = (i & 2) ? h.y : -h.y, z = (i & 4) ? h.z : -h.z;
    p[i] = v3(c.x + ca * x + sa * z, c.y + y, c.z - sa * x + ca * z);
  }
  static const int f[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4},
                              {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
  for (int k = 0; k < 6; k++) add_quad(s, p[f[k][0]], p[f[k][1]], p[f[k][2]], p[f[k][3]]);
}

static hr_scene *make_scene(int nboxes, int ntris) {
  hr_scene *s;
  hr_scene_create("bench", &s);
  const double rho[3] = {.5, .5, .5}, e[3] = {0, 0, 0};
  hr_scene_add_material(s, "m", rho, e, NULL);
  double W = 10, H = 4, D = 10;
  add_quad(s, v3(0, 0, 0), v3(0, 0, D), v3(W, 0, D), v3(W, 0, 0));
  add_quad(s, v3(0, H, 0), v3(W, H, 0), v3(W, H, D), v3(0, H, D));
  add_quad(s, v3(0, 0, 0), v3(0, H, 0), v3(0, H, D), v3(0, 0, D));
  add_quad(s, v3(W, 0, 0), v3(W, 0, D), v3(W, H, D), v3(W, H, 0));
  add_quad(s, v3(0, 0, 0), v3(W, 0, 0), v3(W, H, 0), v3(0, H, 0));
  add_quad(s, v3(0, 0, D), v3(0, H, D), v3(W, H, D), v3(W, 0, D));
  for (int i = 0; i < nboxes; i++) {
    hr_vec3 h = v3(rnd_in(0.05, 0.3), rnd_in(0.05, 0.4), rnd_in(0.05, 0.3));
    hr_vec3 c = v3(rnd_in(1, 9), rnd() < 0.5 ? h.y : rnd_in(0.5, 3.5), rnd_in(1, 9));
    add_box(s, c, h, rnd_in(0, M_PI));
  }
  for (int i = 0; i < ntris; i++) {
    hr_vec3 c = v3(rnd_in(1, 9), rnd_in(0.5, 3.5), rnd_in(1, 9)), v[3];
    for (int k = 0; k < 3; k++)
      v[k] = v3_add(c, v3(rnd_in(-.3, .3), rnd_in(-.3, .3), rnd_in(-.3, .3)));
    hr_poly_result r;
    hr_scene_add_polygon(s, v, 3, 0, &r);
  }
  return s;
}

static hr_vec3 poly_point(const hr_surface *f) {
  if (f->nverts == 3) {
    double a = rnd(), b = rnd();
    if (a + b > 1) a = 1 - a, b = 1 - b;
    return v3_add(f->v[0], v3_add(v3_scale(v3_sub(f->v[1], f->v[0]), a),
                                  v3_scale(v3_sub(f->v[2], f->v[0]), b)));
  }
  double u = rnd(), w = rnd();
  return v3_lerp(v3_lerp(f->v[0], f->v[1], u), v3_lerp(f->v[3], f->v[2], u), w);
}

static hr_vec3 centroid(const hr_surface *f) {
  hr_vec3 c = {0, 0, 0};
  for (int i = 0; i < f->nverts; i++) c = v3_add(c, f->v[i]);
  return v3_scale(c, 1.0 / f->nverts);
}

static int facing(const hr_surface *A, const hr_surface *B) {
  hr_vec3 ca = centroid(A), cb = centroid(B);
  return v3_dot(v3_sub(cb, ca), A->normal) > 1e-9 && v3_dot(v3_sub(ca, cb), B->normal) > 1e-9;
}

typedef struct {
  int L, R;   /* links, rays per link */
  int *a, *b; /* surfaces */
  float *org, *dst;
  uint8_t *vis;
} workload;

static void make_links(const hr_scene *s, workload *w, int L, int R, double maxdist) {
  w->L = L, w->R = R;
  w->a = malloc(sizeof(int) * L), w->b = malloc(sizeof(int) * L);
  w->org = malloc(sizeof(float) * 3 * L * R), w->dst = malloc(sizeof(float) * 3 * L * R);
  w->vis = malloc((size_t)L * R);
  for (int l = 0; l < L; l++) {
    int a, b;
    do {
      a = rnd_int(s->nsurfs), b = rnd_int(s->nsurfs);
    } while (a == b || !facing(&s->surfs[a], &s->surfs[b]) ||
             v3_len(v3_sub(centroid(&s->surfs[a]), centroid(&s->surfs[b]))) > maxdist);
    w->a[l] = a, w->b[l] = b;
    for (int i = 0; i < R; i++) {
      hr_vec3 p = poly_point(&s->surfs[a]), q = poly_point(&s->surfs[b]);
      float *o = w->org + 3 * ((size_t)l * R + i), *d = w->dst + 3 * ((size_t)l * R + i);
      o[0] = (float)p.x, o[1] = (float)p.y, o[2] = (float)p.z;
      d[0] = (float)q.x, d[1] = (float)q.y, d[2] = (float)q.z;
    }
  }
}

static void free_links(workload *w) {
  free(w->a), free(w->b), free(w->org), free(w->dst), free(w->vis);
}

/* Best of 3 runs, Mrays/s. mode: packet policy of vis_segments_mode; skip: use the link's
 * surfaces as skip ids (filter on) or -1 (filter off). */
static double rate_embree(const hr_vis *v, workload *w, int mode, int skip, double *blocked) {
  double best = 1e30;
  for (int rep = 0; rep < 3; rep++) {
    double t0 = now_s();
    for (int l = 0; l < w->L; l++)
      vis_segments_mode(v, w->R, w->org + 3 * (size_t)l * w->R, w->dst + 3 * (size_t)l * w->R,
                        skip ? w->a[l] : -1, skip ? w->b[l] : -1, w->vis + (size_t)l * w->R, mode);
    double t = now_s() - t0;
    best = t < best ? t : best;
  }
  long nb = 0;
  for (long i = 0; i < (long)w->L * w->R; i++) nb += !w->vis[i];
  if (blocked) *blocked = (double)nb / ((double)w->L * w->R);
  return (double)w->L * w->R / best * 1e-6;
}

/* Stream API for comparison: rtcOccluded1M on the link's rays (INCOHERENT). */
static double rate_stream(const hr_vis *v, workload *w, int coherent) {
  struct RTCRay *rays = aligned_alloc(64, sizeof(struct RTCRay) * (size_t)w->R + 64);
  double best = 1e30;
  for (int rep = 0; rep < 3; rep++) {
    double t0 = now_s();
    for (int l = 0; l < w->L; l++) {
      vis_ctx c;
      ctx_init(&c, v, w->a[l], w->b[l], coherent);
      for (int i = 0; i < w->R; i++) {
        const float *o = w->org + 3 * ((size_t)l * w->R + i),
                    *d = w->dst + 3 * ((size_t)l * w->R + i);
        struct RTCRay *r = &rays[i];
        r->org_x = o[0], r->org_y = o[1], r->org_z = o[2];
        r->dir_x = d[0] - o[0], r->dir_y = d[1] - o[1], r->dir_z = d[2] - o[2];
        r->tnear = (float)HR_VIS_EPS, r->tfar = (float)(1 - HR_VIS_EPS);
        r->time = 0, r->mask = ~0u, r->id = (unsigned)i, r->flags = 0;
      }
      rtcOccluded1M(v->scene, &c.ctx, rays, (unsigned)w->R, sizeof(struct RTCRay));
      for (int i = 0; i < w->R; i++) w->vis[(size_t)l * w->R + i] = rays[i].tfar >= 0;
    }
    double t = now_s() - t0;
    best = t < best ? t : best;
  }
  free(rays);
  return (double)w->L * w->R / best * 1e-6;
}

int main(int argc, char **argv) {
  rng_state = 0x9e3779b97f4a7c15ull;
  int nboxes = argc > 1 ? atoi(argv[1]) : 600, ntris = argc > 2 ? atoi(argv[2]) : 400;
  hr_scene *s = make_scene(nboxes, ntris);
  hr_vis *v = NULL;
  hr_err err;
  double t0 = now_s();
  if (hr_vis_create(s, &v, &err) != HR_OK) {
    fprintf(stderr, "vis: %s\n", err.msg);
    return 1;
  }
  double tvis = now_s() - t0;
  hr_shaft_index *x = NULL;
  t0 = now_s();
  hr_shaft_index_create(s, &x);
  double tbvh = now_s() - t0;
  printf("scene: %d surfaces; Embree build %.1f ms, shaft BVH build %.1f ms\n", s->nsurfs,
         1e3 * tvis, 1e3 * tbvh);

  const double dists[2] = {1e9, 1.5};
  const char *dname[2] = {"any distance", "centroids < 1.5 apart"};
  for (int di = 0; di < 2; di++) {
    printf("\n== links between random facing surfaces, %s ==\n", dname[di]);
    workload w16, w4;
    make_links(s, &w16, 20000, 16, dists[di]);
    make_links(s, &w4, 40000, 4, dists[di]);
    double bl;
    printf("Embree, 16 rays/link: hr_vis_segments (packet16) %.2f Mrays/s",
           rate_embree(v, &w16, 0, 1, &bl));
    printf(" (blocked %.0f%%)", 100 * bl);
    printf(", packet16 no skip filter %.2f", rate_embree(v, &w16, 16, 0, NULL));
    printf(", packet8 %.2f", rate_embree(v, &w16, 8, 1, NULL));
    printf(", packet4 %.2f", rate_embree(v, &w16, 4, 1, NULL));
    printf(", scalar rtcOccluded1 %.2f", rate_embree(v, &w16, 1, 1, NULL));
    printf(", stream 1M %.2f, stream 1M coherent %.2f\n", rate_stream(v, &w16, 0),
           rate_stream(v, &w16, 1));
    printf("Embree, 4 rays/link: hr_vis_segments (stream) %.2f Mrays/s",
           rate_embree(v, &w4, 0, 1, &bl));
    printf(", packet4 %.2f", rate_embree(v, &w4, 4, 1, NULL));
    printf(" (blocked %.0f%%)", 100 * bl);
    printf(", packet16 masked %.2f", rate_embree(v, &w4, 16, 1, NULL));
    printf(", scalar %.2f", rate_embree(v, &w4, 1, 1, NULL));
    printf(", stream 1M %.2f, stream 1M coherent %.2f\n", rate_stream(v, &w4, 0),
           rate_stream(v, &w4, 1));

    /* shaft lists for these links */
    int32_t *cand = NULL;
    int ncand = 0, cap = 0;
    long tot = 0;
    int Lq = 5000;
    t0 = now_s();
    for (int l = 0; l < Lq; l++) {
      const hr_surface *A = &s->surfs[w16.a[l]], *B = &s->surfs[w16.b[l]];
      ncand = 0;
      hr_shaft_candidates(x, A->v, A->nverts, w16.a[l], B->v, B->nverts, w16.b[l], &cand, &ncand,
                          &cap);
      tot += ncand;
    }
    double tq = now_s() - t0;
    printf("shaft candidates: %.1f us per pair, mean list %.1f of %d surfaces\n", 1e6 * tq / Lq,
           (double)tot / Lq, s->nsurfs);
    /* filter of a parent's list for a quarter-size child pair */
    int32_t *sub = malloc(sizeof(int32_t) * (size_t)s->nsurfs);
    long tots = 0;
    t0 = now_s();
    for (int l = 0; l < Lq; l++) {
      const hr_surface *A = &s->surfs[w16.a[l]], *B = &s->surfs[w16.b[l]];
      ncand = 0;
      hr_shaft_candidates(x, A->v, A->nverts, w16.a[l], B->v, B->nverts, w16.b[l], &cand, &ncand,
                          &cap);
      hr_vec3 pa[4], pb[4];
      for (int k = 0; k < A->nverts; k++) pa[k] = v3_lerp(A->v[0], A->v[k], 0.5);
      for (int k = 0; k < B->nverts; k++) pb[k] = v3_lerp(B->v[0], B->v[k], 0.5);
      tots +=
          hr_shaft_filter(s, pa, A->nverts, w16.a[l], pb, B->nverts, w16.b[l], cand, ncand, sub);
    }
    double tf = now_s() - t0 - tq;
    printf("shaft filter for a quarter child pair: %.1f us per pair (net), mean list %.1f\n",
           1e6 * tf / Lq, (double)tots / Lq);

    /* candidate brute force: lists of k surfaces drawn from the link's shaft list, padded with
     * random surfaces */
    int ks[4] = {1, 4, 16, 64};
    int32_t *lists = malloc(sizeof(int32_t) * 64 * (size_t)w16.L);
    for (int ki = 0; ki < 4; ki++) {
      int k = ks[ki];
      for (int l = 0; l < w16.L; l++) {
        const hr_surface *A = &s->surfs[w16.a[l]], *B = &s->surfs[w16.b[l]];
        ncand = 0;
        hr_shaft_candidates(x, A->v, A->nverts, w16.a[l], B->v, B->nverts, w16.b[l], &cand, &ncand,
                            &cap);
        for (int j = 0; j < k; j++)
          lists[(size_t)l * 64 + j] = j < ncand ? cand[rnd_int(ncand)] : rnd_int(s->nsurfs);
      }
      double best = 1e30;
      long nb = 0;
      for (int rep = 0; rep < 3; rep++) {
        t0 = now_s();
        for (int l = 0; l < w16.L; l++)
          hr_vis_segments_cand(s, lists + (size_t)l * 64, k, 16, w16.org + 48 * (size_t)l,
                               w16.dst + 48 * (size_t)l, w16.a[l], w16.b[l], w16.vis + 16 * l);
        double t = now_s() - t0;
        best = t < best ? t : best;
      }
      for (long i = 0; i < 16L * w16.L; i++) nb += !w16.vis[i];
      printf("candidate brute force, 16 rays/link, list of %2d: %.2f Mrays/s (blocked %.0f%%)\n", k,
             16.0 * w16.L / best * 1e-6, 100.0 * nb / (16.0 * w16.L));
    }
    free(lists);
    free(sub);
    free(cand);
    free_links(&w16);
    free_links(&w4);
  }
  hr_shaft_index_destroy(&x);
  hr_vis_destroy(&v);
  hr_scene_destroy(&s);
  return 0;
}
