/* test_output.c: mesh reconstruction (cracks, areas, vertex counts, T-vertex values), the PLY,
 * GLB (Khronos glTF-Validator), PNG/PFM writers, the software renderer, and viewer.html opened
 * in headless Chromium; split polygons (several surfaces of one input polygon) as one smooth
 * region. Synthetic leaves are built here with non-uniform (unbalanced) quadtree
 * and triangle subdivisions so that T-vertices occur at several nesting depths. */
#include "output.h"
#include "vec.h"

#include <math.h>
#include <png.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

static int failures = 0;
#define CHECK(cond, ...)                                                                           \
  do {                                                                                             \
    if (!(cond)) {                                                                                 \
      failures++;                                                                                  \
      fprintf(stderr, "%s:%d: CHECK(%s) failed: ", __FILE__, __LINE__, #cond);                     \
      fprintf(stderr, __VA_ARGS__);                                                                \
      fputc('\n', stderr);                                                                         \
    }                                                                                              \
  } while (0)

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

/* ------------------------------------------------------------------ synthetic leaves */

typedef struct leafvec {
  hr_leaf *v;
  int64_t n, cap;
} leafvec;

static hr_leaf *leaf_push(leafvec *lv) {
  if (lv->n == lv->cap) {
    lv->cap = lv->cap ? 2 * lv->cap : 256;
    lv->v = realloc(lv->v, (size_t)lv->cap * sizeof *lv->v);
    if (!lv->v) abort();
  }
  hr_leaf *l = &lv->v[lv->n++];
  memset(l, 0, sizeof *l);
  return l;
}

static hr_vec3 surf_pt(const hr_surface *f, double a, double b) {
  a /= HR_LATTICE;
  b /= HR_LATTICE;
  if (f->nverts == 4)
    return v3_add(v3_add(v3_scale(f->v[0], (1 - a) * (1 - b)), v3_scale(f->v[1], a * (1 - b))),
                  v3_add(v3_scale(f->v[2], a * b), v3_scale(f->v[3], (1 - a) * b)));
  return v3_add(f->v[0], v3_add(v3_scale(v3_sub(f->v[1], f->v[0]), a),
                                v3_scale(v3_sub(f->v[2], f->v[0]), b)));
}

/* The linear test field. */
static void field(hr_vec3 p, double B[3]) {
  B[0] = 6 + 2 * p.x + 3 * p.y + p.z;
  B[1] = 0.5 + p.x - 0.2 * p.y + 0.1 * p.z;
  B[2] = 2 - p.y + 0.1 * p.x + 0.05 * p.z;
}

static double poly_area(const hr_vec3 *p, int n) {
  hr_vec3 s = {0, 0, 0};
  for (int i = 1; i + 1 < n; i++)
    s = v3_add(s, v3_cross(v3_sub(p[i], p[0]), v3_sub(p[i + 1], p[0])));
  return 0.5 * v3_len(s);
}

typedef void (*bfun)(hr_vec3 centroid, double B[3]);

static void finish_leaf(const hr_scene *s, hr_leaf *l, bfun bf) {
  const hr_surface *f = &s->surfs[l->surf];
  hr_vec3 c = {0, 0, 0};
  for (int k = 0; k < l->nverts; k++) {
    l->p[k] = surf_pt(f, l->lat[k][0], l->lat[k][1]);
    c = v3_add(c, l->p[k]);
  }
  l->area = poly_area(l->p, l->nverts);
  c = v3_scale(c, 1.0 / l->nverts);
  bf(c, l->B);
}

/* Refinement predicate: parameter-space cell [a0,a0+s]x[b0,b0+s] (or a triangle's bounding box)
 * at 'depth' is split when it returns 1. */
typedef int (*refine_fn)(int surf, double a0, double b0, double s, int depth);

static void gen_quad(const hr_scene *sc, leafvec *lv, int surf, uint32_t a, uint32_t b, uint32_t s,
                     int depth, refine_fn rf, bfun bf) {
  double L = HR_LATTICE;
  if (s > 1 && rf(surf, a / L, b / L, s / L, depth)) {
    uint32_t h = s / 2;
    gen_quad(sc, lv, surf, a, b, h, depth + 1, rf, bf);
    gen_quad(sc, lv, surf, a + h, b, h, depth + 1, rf, bf);
    gen_quad(sc, lv, surf, a + h, b + h, h, depth + 1, rf, bf);
    gen_quad(sc, lv, surf, a, b + h, h, depth + 1, rf, bf);
    return;
  }
  hr_leaf *l = leaf_push(lv);
  l->surf = surf;
  l->nverts = 4;
  uint32_t c[4][2] = {{a, b}, {a + s, b}, {a + s, b + s}, {a, b + s}};
  memcpy(l->lat, c, sizeof c);
  finish_leaf(sc, l, bf);
}

static void gen_tri(const hr_scene *sc, leafvec *lv, int surf, const uint32_t A[2],
                    const uint32_t B[2], const uint32_t C[2], int depth, refine_fn rf, bfun bf) {
  double L = HR_LATTICE;
  double amin = fmin(A[0], fmin(B[0], C[0])), bmin = fmin(A[1], fmin(B[1], C[1]));
  double amax = fmax(A[0], fmax(B[0], C[0]));
  uint32_t s = (uint32_t)(amax - amin);
  if (s > 1 && rf(surf, amin / L, bmin / L, s / L, depth)) {
    uint32_t ab[2] = {(A[0] + B[0]) / 2, (A[1] + B[1]) / 2};
    uint32_t bc[2] = {(B[0] + C[0]) / 2, (B[1] + C[1]) / 2};
    uint32_t ca[2] = {(C[0] + A[0]) / 2, (C[1] + A[1]) / 2};
    gen_tri(sc, lv, surf, A, ab, ca, depth + 1, rf, bf);
    gen_tri(sc, lv, surf, ab, B, bc, depth + 1, rf, bf);
    gen_tri(sc, lv, surf, ca, bc, C, depth + 1, rf, bf);
    gen_tri(sc, lv, surf, bc, ca, ab, depth + 1, rf, bf); /* middle, flipped */
    return;
  }
  hr_leaf *l = leaf_push(lv);
  l->surf = surf;
  l->nverts = 3;
  l->lat[0][0] = A[0], l->lat[0][1] = A[1];
  l->lat[1][0] = B[0], l->lat[1][1] = B[1];
  l->lat[2][0] = C[0], l->lat[2][1] = C[1];
  finish_leaf(sc, l, bf);
}

static int contains(double a0, double b0, double s, double pa, double pb) {
  return pa >= a0 && pa <= a0 + s && pb >= b0 && pb <= b0 + s;
}

/* Unbalanced refinement: every surface to depth 1; surface 0 quadrant (0,0) to depth 3 and deep
 * spots at (0.49,0.26) (depth 7, next to the depth-1 quadrant: nested T-vertices) and
 * (0.9,0.9); the trapezoid to depth 2 with a spot at (0.7,0.3); the triangle's middle child
 * and a spot near (0.3,0.2). */
static int refine_main(int surf, double a0, double b0, double s, int depth) {
  if (depth < 1) return 1;
  if (surf == 0) {
    if (depth < 3 && a0 < 0.5 && b0 < 0.5) return 1;
    if (depth < 7 && contains(a0, b0, s, 0.49, 0.26)) return 1;
    if (depth < 5 && contains(a0, b0, s, 0.9, 0.9)) return 1;
    return 0;
  }
  if (surf == 1) {
    if (depth < 2) return 1;
    /* cell [0.25,0.5]x[0.5,0.75] gets finer neighbours left and right: a centre vertex */
    if (depth < 3 && (contains(a0, b0, s, 0.1, 0.6) || contains(a0, b0, s, 0.6, 0.6))) return 1;
    return depth < 6 && contains(a0, b0, s, 0.7, 0.3);
  }
  /* triangle: bounding box is [a0,a0+s]x[b0,b0+s] */
  if (depth < 2) return 1;
  /* the middle triangle (0.25,0),(0.25,0.25),(0,0.25) gets finer neighbours on two edges */
  if (depth < 3 && (contains(a0, b0, s, 0.4, 0.02) || contains(a0, b0, s, 0.02, 0.4))) return 1;
  if (depth < 6 && contains(a0, b0, s, 0.3, 0.6)) return 1;
  return depth < 4 && contains(a0, b0, s, 0.05, 0.9);
}

static hr_scene *make_scene(void) {
  hr_scene *s;
  if (hr_scene_create("test", &s) != HR_OK) abort();
  double rho[3] = {0.5, 0.5, 0.5}, zero[3] = {0, 0, 0}, e[3] = {5, 5, 5};
  int grey, lamp;
  hr_scene_add_material(s, "grey", rho, zero, &grey);
  hr_scene_add_material(s, "lamp", rho, e, &lamp);
  hr_poly_result r;
  hr_vec3 q[4] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  hr_scene_add_polygon(s, q, 4, grey, &r);
  hr_vec3 t[4] = {{-2.5, 0, 1}, {-0.5, 0, 1}, {-1, 1, 1}, {-2, 1, 1}}; /* trapezoid: bilinear */
  hr_scene_add_polygon(s, t, 4, grey, &r);
  hr_vec3 tr[3] = {{2, 0, 0}, {3, 0.2, 0.5}, {2.1, 1, 0.1}};
  hr_scene_add_polygon(s, tr, 3, grey, &r);
  hr_vec3 lp[4] = {{0, 1.5, -1}, {1, 1.5, -1}, {1, 2.5, -1}, {0, 2.5, -1}}; /* emitter, faces +z */
  hr_scene_add_polygon(s, lp, 4, lamp, &r);
  if (s->nsurfs != 4) abort();
  return s;
}

static void gen_all(const hr_scene *s, leafvec *lv, refine_fn rf, bfun bf) {
  const uint32_t L = HR_LATTICE;
  gen_quad(s, lv, 0, 0, 0, L, 0, rf, bf);
  gen_quad(s, lv, 1, 0, 0, L, 0, rf, bf);
  uint32_t A[2] = {0, 0}, B[2] = {L, 0}, C[2] = {0, L};
  gen_tri(s, lv, 2, A, B, C, 0, rf, bf);
  gen_quad(s, lv, 3, 0, 0, L, 0, rf, bf);
}

/* ------------------------------------------------------------------ mesh checks */

typedef struct edge {
  uint32_t a, b; /* directed */
} edge;

static int cmp_edge_undirected(const void *pa, const void *pb) {
  const edge *x = pa, *y = pb;
  uint32_t x0 = x->a < x->b ? x->a : x->b, x1 = x->a < x->b ? x->b : x->a;
  uint32_t y0 = y->a < y->b ? y->a : y->b, y1 = y->a < y->b ? y->b : y->a;
  if (x0 != y0) return x0 < y0 ? -1 : 1;
  if (x1 != y1) return x1 < y1 ? -1 : 1;
  return 0;
}

static int cmp_u64(const void *pa, const void *pb) {
  uint64_t a = *(const uint64_t *)pa, b = *(const uint64_t *)pb;
  return (a > b) - (a < b);
}

static hr_vec3 vpos(const hr_mesh *m, uint32_t v) {
  return v3(m->pos[3 * v], m->pos[3 * v + 1], m->pos[3 * v + 2]);
}

/* Mesh vertex of surface 'f' at position p (brute force), or -1. */
static int64_t find_vertex(const hr_mesh *m, const int32_t *vsurf, int f, hr_vec3 p) {
  for (int64_t v = 0; v < m->nverts; v++)
    if (vsurf[v] == f && v3_len(v3_sub(vpos(m, (uint32_t)v), p)) < 1e-6) return v;
  return -1;
}

static void check_mesh(const hr_scene *s, const hr_leaf *lv, int64_t n, const hr_mesh *m) {
  /* vertex -> surface, consistent over triangles */
  int32_t *vsurf = malloc((size_t)m->nverts * sizeof *vsurf);
  for (int64_t v = 0; v < m->nverts; v++) vsurf[v] = -1;
  int bad_share = 0;
  for (int64_t t = 0; t < m->ntris; t++)
    for (int k = 0; k < 3; k++) {
      uint32_t v = m->tri[3 * t + k];
      if (v >= m->nverts) {
        bad_share++;
        continue;
      }
      if (vsurf[v] == -1)
        vsurf[v] = m->tri_surf[t];
      else if (vsurf[v] != m->tri_surf[t])
        bad_share++;
    }
  CHECK(bad_share == 0, "%d vertices shared across surfaces or out of range", bad_share);
  int unused = 0;
  for (int64_t v = 0; v < m->nverts; v++) unused += vsurf[v] == -1;
  CHECK(unused == 0, "%d unused vertices", unused);

  int64_t total_corners = 0;
  for (int f = 0; f < s->nsurfs; f++) {
    const hr_surface *sf = &s->surfs[f];
    /* (b) area and orientation */
    double area = 0;
    int flipped = 0, degenerate = 0;
    int64_t nt = 0;
    for (int64_t t = 0; t < m->ntris; t++) {
      if (m->tri_surf[t] != f) continue;
      nt++;
      hr_vec3 a = vpos(m, m->tri[3 * t]), b = vpos(m, m->tri[3 * t + 1]),
              c = vpos(m, m->tri[3 * t + 2]);
      hr_vec3 nn = v3_cross(v3_sub(b, a), v3_sub(c, a));
      double ta = 0.5 * v3_len(nn);
      if (!(ta > 1e-14)) degenerate++;
      if (v3_dot(nn, sf->normal) <= 0) flipped++;
      area += ta;
    }
    CHECK(nt > 0, "surface %d has no triangles", f);
    CHECK(flipped == 0, "surface %d: %d triangles face backwards", f, flipped);
    CHECK(degenerate == 0, "surface %d: %d degenerate triangles", f, degenerate);
    CHECK(fabs(area - sf->area) < 1e-6 * sf->area, "surface %d: mesh area %.9g != %.9g", f, area,
          sf->area);
    /* (a) edges: each shared by exactly two triangles in opposite directions, except the
     * boundary, whose length is the perimeter */
    edge *E = malloc((size_t)nt * 3 * sizeof *E);
    int64_t ne = 0;
    for (int64_t t = 0; t < m->ntris; t++) {
      if (m->tri_surf[t] != f) continue;
      for (int k = 0; k < 3; k++) E[ne++] = (edge){m->tri[3 * t + k], m->tri[3 * t + (k + 1) % 3]};
    }
    qsort(E, (size_t)ne, sizeof *E, cmp_edge_undirected);
    double blen = 0;
    int over = 0, samedir = 0;
    int64_t nboundary = 0;
    for (int64_t i = 0; i < ne;) {
      int64_t j = i + 1;
      while (j < ne && cmp_edge_undirected(&E[i], &E[j]) == 0) j++;
      if (j - i == 1) {
        blen += v3_len(v3_sub(vpos(m, E[i].a), vpos(m, E[i].b)));
        nboundary++;
      } else if (j - i == 2) {
        if (E[i].a == E[i + 1].a) samedir++;
      } else {
        over++;
      }
      i = j;
    }
    double perim = 0;
    for (int k = 0; k < sf->nverts; k++)
      perim += v3_len(v3_sub(sf->v[(k + 1) % sf->nverts], sf->v[k]));
    CHECK(over == 0, "surface %d: %d edges shared by more than 2 triangles", f, over);
    CHECK(samedir == 0, "surface %d: %d interior edges with inconsistent orientation", f, samedir);
    CHECK(fabs(blen - perim) < 1e-6 * perim, "surface %d: boundary length %.9g != perimeter %.9g",
          f, blen, perim);
    free(E);
    /* (c) distinct lattice corners */
    int64_t nl = 0;
    for (int64_t i = 0; i < n; i++) nl += lv[i].surf == f ? lv[i].nverts : 0;
    uint64_t *keys = malloc((size_t)(nl ? nl : 1) * sizeof *keys);
    int64_t k = 0;
    for (int64_t i = 0; i < n; i++)
      if (lv[i].surf == f)
        for (int c = 0; c < lv[i].nverts; c++)
          keys[k++] = ((uint64_t)lv[i].lat[c][0] << 32) | lv[i].lat[c][1];
    qsort(keys, (size_t)k, sizeof *keys, cmp_u64);
    int64_t distinct = 0;
    for (int64_t i = 0; i < k; i++) distinct += (i == 0 || keys[i] != keys[i - 1]);
    total_corners += distinct;
    /* (d) T-vertices: a distinct corner strictly inside a leaf edge must carry the linear
     * interpolation of that edge's end values; other corners the area-weighted mean */
    int ntv = 0, tbad = 0, cbad = 0, missing = 0;
    double worst = 0;
    for (int64_t i = 0; i < k; i++) {
      if (i > 0 && keys[i] == keys[i - 1]) continue;
      uint32_t ca = (uint32_t)(keys[i] >> 32), cb = (uint32_t)keys[i];
      int64_t cv = find_vertex(m, vsurf, f, surf_pt(sf, ca, cb));
      if (cv < 0) {
        missing++;
        continue;
      }
      int is_t = 0;
      double wsum = 0, bsum[3] = {0, 0, 0};
      for (int64_t li = 0; li < n; li++) {
        const hr_leaf *l = &lv[li];
        if (l->surf != f) continue;
        for (int e = 0; e < l->nverts; e++) {
          const uint32_t *P = l->lat[e], *Q = l->lat[(e + 1) % l->nverts];
          if (P[0] == ca && P[1] == cb) {
            wsum += l->area;
            for (int c = 0; c < 3; c++) bsum[c] += l->area * l->B[c];
          }
          double dqa = (double)Q[0] - P[0], dqb = (double)Q[1] - P[1];
          double dca = (double)ca - P[0], dcb = (double)cb - P[1];
          if (dqa * dcb - dqb * dca != 0) continue; /* not collinear */
          double len2 = dqa * dqa + dqb * dqb, tt = (dca * dqa + dcb * dqb) / len2;
          if (!(tt > 0 && tt < 1)) continue;
          is_t = 1;
          int64_t pv = find_vertex(m, vsurf, f, surf_pt(sf, P[0], P[1]));
          int64_t qv = find_vertex(m, vsurf, f, surf_pt(sf, Q[0], Q[1]));
          if (pv < 0 || qv < 0) {
            missing++;
            continue;
          }
          for (int c = 0; c < 3; c++) {
            double want = (1 - tt) * m->B[3 * pv + c] + tt * m->B[3 * qv + c];
            double got = m->B[3 * cv + c], d = fabs(got - want);
            if (d > worst) worst = d;
            if (d > 1e-6 * fmax(1.0, fabs(want))) tbad++;
          }
        }
      }
      ntv += is_t;
      if (!is_t)
        for (int c = 0; c < 3; c++)
          if (fabs(m->B[3 * cv + c] - bsum[c] / wsum) > 1e-6 * fmax(1.0, fabs(bsum[c] / wsum)))
            cbad++;
    }
    CHECK(missing == 0, "surface %d: %d lattice corners without a mesh vertex", f, missing);
    CHECK(tbad == 0, "surface %d: %d T-vertex values off the coarse edge (worst %.3g)", f, tbad,
          worst);
    CHECK(cbad == 0, "surface %d: %d corner values differ from the area-weighted mean", f, cbad);
    if (f <= 2) CHECK(ntv >= 8, "surface %d: only %d T-vertices exercised", f, ntv);
    printf("surface %d: %lld triangles, %lld corners, %d T-vertices (worst deviation %.2g), "
           "area %.6f, boundary %.6f\n",
           f, (long long)nt, (long long)distinct, ntv, worst, area, blen);
    free(keys);
  }
  CHECK(m->nverts == total_corners + m->ncentre, "vertex count %lld != %lld corners + %lld centres",
        (long long)m->nverts, (long long)total_corners, (long long)m->ncentre);
  /* no duplicate vertices within a surface */
  int dups = 0;
  for (int64_t a = 0; a < m->nverts; a++)
    for (int64_t b = a + 1; b < m->nverts && b < a + 4096; b++)
      if (vsurf[a] == vsurf[b] && v3_len(v3_sub(vpos(m, (uint32_t)a), vpos(m, (uint32_t)b))) < 1e-9)
        dups++;
  CHECK(dups == 0, "%d duplicate vertices", dups);
  free(vsurf);
}

/* Leaves down to HR_MAX_DEPTH: a 1024-wide square (its lattice points are exact floats) refined
 * to depth 24 towards a corner and along the line a = 1/2 next to a depth-1 quadrant, so that
 * one coarse edge holds T-vertices nested 23 levels deep. */
static int refine_deep(int surf, double a0, double b0, double s, int depth) {
  (void)surf;
  if (depth < 1) return 1;
  if (contains(a0, b0, s, 0, 0)) return 1;
  return contains(a0, b0, s, 0.5 - 1e-9, 0.3);
}

/* A scene of one grey quad q (material 0, polygon 0); *r: how the quad was added. */
static hr_scene *grey_quad(const char *name, const hr_vec3 q[4], hr_poly_result *r) {
  hr_scene *s;
  hr_scene_create(name, &s);
  double rho[3] = {0.5, 0.5, 0.5}, zero[3] = {0, 0, 0};
  int grey;
  hr_scene_add_material(s, "grey", rho, zero, &grey);
  if (hr_scene_add_polygon(s, q, 4, grey, r) != HR_OK) *r = HR_POLY_DEGENERATE;
  return s;
}

static void deep_B(hr_vec3 c, double B[3]) {
  B[0] = 1 + c.x / 1024;
  B[1] = 2 - c.y / 1024;
  B[2] = 0.5;
}

static void test_deep(void) {
  hr_poly_result r;
  const hr_vec3 q[4] = {{0, 0, 0}, {1024, 0, 0}, {1024, 1024, 0}, {0, 1024, 0}};
  hr_scene *s = grey_quad("deep", q, &r);
  leafvec lv = {0};
  gen_quad(s, &lv, 0, 0, 0, HR_LATTICE, 0, refine_deep, deep_B);
  uint32_t smin = HR_LATTICE;
  for (int64_t i = 0; i < lv.n; i++)
    if (lv.v[i].lat[1][0] - lv.v[i].lat[0][0] < smin) smin = lv.v[i].lat[1][0] - lv.v[i].lat[0][0];
  CHECK(smin == 1, "deep test: smallest leaf %u lattice units", smin);
  hr_mesh *m = NULL;
  CHECK(hr_mesh_build(s, lv.v, lv.n, &m) == HR_OK, "deep mesh");
  if (m) {
    printf("deep: %lld leaves -> %lld vertices, %lld triangles\n", (long long)lv.n,
           (long long)m->nverts, (long long)m->ntris);
    check_mesh(s, lv.v, lv.n, m);
  }
  hr_mesh_destroy(&m);
  free(lv.v);
  hr_scene_destroy(&s);
}

/* ------------------------------------------------------------------ file read-back */

static unsigned char *slurp(const char *path, size_t *len) {
  FILE *fp = fopen(path, "rb");
  if (!fp) return NULL;
  fseek(fp, 0, SEEK_END);
  long n = ftell(fp);
  fseek(fp, 0, SEEK_SET);
  unsigned char *b = malloc((size_t)n + 1);
  if (fread(b, 1, (size_t)n, fp) != (size_t)n) {
    free(b);
    fclose(fp);
    return NULL;
  }
  b[n] = 0;
  fclose(fp);
  *len = (size_t)n;
  return b;
}

static uint32_t get_u32(const unsigned char *p) {
  return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}
static float get_f32(const unsigned char *p) {
  uint32_t u = get_u32(p);
  float f;
  memcpy(&f, &u, 4);
  return f;
}

static void check_ply(const char *path, const hr_mesh *m, double exposure) {
  size_t len;
  unsigned char *b = slurp(path, &len);
  CHECK(b != NULL, "cannot read %s", path);
  if (!b) return;
  const char *hdr_end = strstr((const char *)b, "end_header\n");
  CHECK(hdr_end != NULL, "PLY: no end_header");
  if (!hdr_end) {
    free(b);
    return;
  }
  size_t body = (size_t)(hdr_end - (const char *)b) + strlen("end_header\n");
  char *hdr = malloc(body + 1);
  memcpy(hdr, b, body);
  hdr[body] = 0;
  CHECK(strncmp(hdr, "ply\nformat binary_little_endian 1.0\n", 36) == 0, "PLY: bad magic/format");
  long long nv = -1, nf = -1;
  const char *p = strstr(hdr, "element vertex ");
  if (p) nv = atoll(p + 15);
  p = strstr(hdr, "element face ");
  if (p) nf = atoll(p + 13);
  CHECK(nv == m->nverts, "PLY: %lld vertices, mesh has %lld", nv, (long long)m->nverts);
  CHECK(nf == m->ntris, "PLY: %lld faces, mesh has %lld", nf, (long long)m->ntris);
  const char *props = "property float x\nproperty float y\nproperty float z\n"
                      "property uchar red\nproperty uchar green\nproperty uchar blue\n"
                      "property float radiosity_r\nproperty float radiosity_g\n"
                      "property float radiosity_b\nelement face";
  CHECK(strstr(hdr, props) != NULL, "PLY: unexpected vertex properties");
  CHECK(strstr(hdr, "property list uchar int vertex_indices\nend_header\n") != NULL,
        "PLY: unexpected face properties");
  CHECK(strstr(hdr, "comment exposure ") != NULL, "PLY: no exposure comment");
  size_t need = body + (size_t)m->nverts * 27 + (size_t)m->ntris * 13;
  CHECK(len == need, "PLY: %zu bytes, expected %zu", len, need);
  if (len == need && nv == m->nverts && nf == m->ntris) {
    const unsigned char *q = b + body;
    int pbad = 0, cbad = 0, fbad = 0;
    for (int64_t v = 0; v < m->nverts; v++, q += 27) {
      for (int c = 0; c < 3; c++) {
        if (get_f32(q + 4 * c) != m->pos[3 * v + c]) pbad++;
        if (q[12 + c] != hr_tonemap8(m->B[3 * v + c], exposure)) cbad++;
        if (get_f32(q + 15 + 4 * c) != m->B[3 * v + c]) cbad++;
      }
    }
    for (int64_t t = 0; t < m->ntris; t++, q += 13) {
      if (q[0] != 3) fbad++;
      for (int c = 0; c < 3; c++)
        if (get_u32(q + 1 + 4 * c) != m->tri[3 * t + c]) fbad++;
    }
    CHECK(pbad == 0 && cbad == 0 && fbad == 0,
          "PLY read-back: %d position, %d colour, %d face "
          "mismatches",
          pbad, cbad, fbad);
  }
  free(hdr);
  free(b);
}

static void check_glb(const char *path, int full) {
  size_t len;
  unsigned char *b = slurp(path, &len);
  CHECK(b != NULL && len >= 28, "cannot read %s", path);
  if (!b || len < 28) {
    free(b);
    return;
  }
  CHECK(get_u32(b) == 0x46546C67u && get_u32(b + 4) == 2 && get_u32(b + 8) == len,
        "GLB header wrong");
  uint32_t jl = get_u32(b + 12);
  CHECK(jl % 4 == 0 && get_u32(b + 16) == 0x4E4F534Au, "GLB JSON chunk wrong");
  if (20 + jl + 8 <= len) {
    CHECK(get_u32(b + 20 + jl) % 4 == 0 && get_u32(b + 24 + jl) == 0x004E4942u,
          "GLB BIN chunk wrong");
    CHECK(20 + jl + 8 + get_u32(b + 20 + jl) == len, "GLB length mismatch");
  }
  char *json = malloc(jl + 1);
  memcpy(json, b + 20, jl);
  json[jl] = 0;
  CHECK(strstr(json, "\"generator\":\"hrad\"") && strstr(json, "\"exposure\":") &&
            (!full || (strstr(json, "\"extensionsUsed\":[\"KHR_materials_unlit\"]") &&
                       strstr(json, "\"doubleSided\":false") && strstr(json, "\"COLOR_0\""))),
        "GLB JSON lacks required fields: %s", json);
  free(json);
  free(b);
  char cmd[4096];
  snprintf(cmd, sizeof cmd, "node '%s/tests/validate_glb.mjs' '%s' --max-warnings 0", HR_SOURCE_DIR,
           path);
  fflush(stdout);
  int rc = system(cmd);
  CHECK(rc != -1 && WIFEXITED(rc) && WEXITSTATUS(rc) == 0,
        "glTF-Validator reported errors or warnings (or could not run): status %d", rc);
}

/* ------------------------------------------------------------------ rendering */

static void gradient_B(hr_vec3 c, double B[3]) {
  B[0] = 1 + c.x;
  B[1] = 0.5 + 0.25 * c.x;
  B[2] = 0.2;
}

static void const_B(hr_vec3 c, double B[3]) {
  (void)c;
  B[0] = 0.5;
  B[1] = 0.25;
  B[2] = 0.1;
}

static int uniform8(int surf, double a0, double b0, double s, int depth) {
  (void)surf, (void)a0, (void)b0, (void)s;
  return depth < 3;
}
static int norefine(int surf, double a0, double b0, double s, int depth) {
  (void)surf, (void)a0, (void)b0, (void)s, (void)depth;
  return 0;
}

static int read_png(const char *path, int *w, int *h, unsigned char **px) {
  png_image img;
  memset(&img, 0, sizeof img);
  img.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&img, path)) return 0;
  img.format = PNG_FORMAT_RGB;
  *px = malloc(PNG_IMAGE_SIZE(img));
  if (!png_image_finish_read(&img, NULL, *px, 0, NULL)) {
    free(*px);
    return 0;
  }
  *w = (int)img.width;
  *h = (int)img.height;
  return 1;
}

/* x in world units of the pixel centre of column 'col' on the plane z=0 seen from (0,0,5). */
static double pixel_world_x(int col, int w, int h, double fov) {
  double ndc = (col + 0.5) / w * 2 - 1;
  return ndc * tan(0.5 * fov * M_PI / 180) * (double)w / h * 5.0;
}

static void test_render(const char *dir) {
  hr_poly_result r;
  const hr_vec3 q[4] = {{-1, -1, 0}, {1, -1, 0}, {1, 1, 0}, {-1, 1, 0}};
  hr_scene *s = grey_quad("quad", q, &r);
  const int w = 160, h = 120;
  hr_camera cam = {{0, 0, 5}, {0, 0, 0}, {0, 1, 0}, 40};
  float *rgb = malloc((size_t)w * h * 3 * sizeof *rgb);
  char path[1024];
  hr_err err;

  /* (g1) one lit leaf: the centre pixel is B, tone-mapped within 1 level; outside is 0 */
  leafvec lv = {0};
  gen_quad(s, &lv, 0, 0, 0, HR_LATTICE, 0, norefine, const_B);
  hr_mesh *m = NULL;
  CHECK(hr_mesh_build(s, lv.v, lv.n, &m) == HR_OK, "mesh build");
  double ex = hr_exposure_auto(m);
  double Y = 0.2126 * 0.5 + 0.7152 * 0.25 + 0.0722 * 0.1;
  CHECK(fabs(ex - 0.8 / Y) < 1e-5 * ex, "auto exposure %g != %g", ex, 0.8 / Y);
  CHECK(hr_render(s, m, lv.v, lv.n, &cam, w, h, 0, rgb) == HR_OK, "render");
  const float *c = &rgb[3 * ((size_t)(h / 2) * w + w / 2)];
  CHECK(fabsf(c[0] - 0.5f) < 1e-5f && fabsf(c[1] - 0.25f) < 1e-5f && fabsf(c[2] - 0.1f) < 1e-5f,
        "centre pixel %g %g %g", c[0], c[1], c[2]);
  CHECK(rgb[0] == 0 && rgb[1] == 0 && rgb[2] == 0, "corner pixel is not background");
  snprintf(path, sizeof path, "%s/quad.png", dir);
  CHECK(hr_png_write(path, w, h, rgb, ex, &err) == HR_OK, "png: %s", err.msg);
  int pw, ph;
  unsigned char *px = NULL;
  CHECK(read_png(path, &pw, &ph, &px) && pw == w && ph == h, "PNG read-back");
  if (px) {
    const unsigned char *pc = &px[3 * ((size_t)(h / 2) * w + w / 2)];
    int want[3] = {hr_tonemap8(0.5, ex), hr_tonemap8(0.25, ex), hr_tonemap8(0.1, ex)};
    double lin = 0.5 * ex; /* independent sRGB formula */
    int ref = (int)lround(255 * (lin >= 1           ? 1
                                 : lin <= 0.0031308 ? 12.92 * lin
                                                    : 1.055 * pow(lin, 1 / 2.4) - 0.055));
    CHECK(abs(pc[0] - want[0]) <= 1 && abs(pc[1] - want[1]) <= 1 && abs(pc[2] - want[2]) <= 1 &&
              abs(pc[0] - ref) <= 1,
          "PNG centre %d %d %d, want %d %d %d", pc[0], pc[1], pc[2], want[0], want[1], want[2]);
    CHECK(px[0] == 0 && px[1] == 0 && px[2] == 0, "PNG corner is not background");
    free(px);
  }
  /* PFM read-back: bottom row first, little-endian, scale -1 */
  snprintf(path, sizeof path, "%s/quad.pfm", dir);
  CHECK(hr_pfm_write(path, w, h, rgb, &err) == HR_OK, "pfm: %s", err.msg);
  {
    size_t len;
    unsigned char *b = slurp(path, &len);
    char hdr[64];
    int hl = snprintf(hdr, sizeof hdr, "PF\n%d %d\n-1.0\n", w, h);
    CHECK(b && len == (size_t)hl + (size_t)w * h * 12 && memcmp(b, hdr, (size_t)hl) == 0,
          "PFM header/size");
    if (b && len == (size_t)hl + (size_t)w * h * 12) {
      int bad = 0;
      for (int y = 0; y < h; y++)
        for (int i = 0; i < 3 * w; i++)
          if (get_f32(b + hl + 4 * ((size_t)(h - 1 - y) * w * 3 + i)) != rgb[(size_t)y * w * 3 + i])
            bad++;
      CHECK(bad == 0, "PFM: %d values differ", bad);
    }
    free(b);
  }
  /* back face: dark grey 0.04/exposure */
  hr_camera back = {{0, 0, -5}, {0, 0, 0}, {0, 1, 0}, 40};
  CHECK(hr_render(s, m, lv.v, lv.n, &back, w, h, 0, rgb) == HR_OK, "render back");
  c = &rgb[3 * ((size_t)(h / 2) * w + w / 2)];
  CHECK(fabs(c[0] - 0.04 / ex) < 1e-6 && c[0] == c[1] && c[1] == c[2], "back face %g", c[0]);
  hr_mesh_destroy(&m);
  free(lv.v);

  /* (g2) 8x8 leaves with B linear in x: smooth mode interpolates exactly inside; flat mode
   * shows each leaf's own B with dark outlines between leaves */
  lv = (leafvec){0};
  gen_quad(s, &lv, 0, 0, 0, HR_LATTICE, 0, uniform8, gradient_B);
  CHECK(hr_mesh_build(s, lv.v, lv.n, &m) == HR_OK, "mesh build");
  CHECK(hr_render(s, m, lv.v, lv.n, &cam, w, h, 0, rgb) == HR_OK, "render smooth");
  int bad = 0;
  for (int col = 0; col < w; col++) {
    double x = pixel_world_x(col, w, h, 40);
    if (fabs(x) > 0.7) continue; /* the outer vertices are not exact (one-sided averages) */
    const float *p = &rgb[3 * ((size_t)(h / 2) * w + col)];
    if (fabs(p[0] - (1 + x)) > 2e-4 || fabs(p[1] - (0.5 + 0.25 * x)) > 2e-4) bad++;
  }
  CHECK(bad == 0, "smooth interpolation: %d pixels off the linear ramp", bad);
  ex = hr_exposure_auto(m);
  snprintf(path, sizeof path, "%s/ramp_smooth.png", dir);
  hr_png_write(path, w, h, rgb, ex, &err);
  CHECK(hr_render_ex(s, m, lv.v, lv.n, &cam, w, h, 1, 2, -1, rgb) == HR_OK, "render flat");
  snprintf(path, sizeof path, "%s/ramp_flat.png", dir);
  hr_png_write(path, w, h, rgb, ex, &err);
  /* leaf k covers x in [-1 + k/4, -1 + (k+1)/4]; its B is 1 + its centre */
  int inside = 0;
  double px_size = pixel_world_x(1, w, h, 40) - pixel_world_x(0, w, h, 40);
  for (int col = 0; col < w; col++) {
    double x = pixel_world_x(col, w, h, 40);
    if (fabs(x) >= 1) continue;
    double k = floor((x + 1) * 4), xc = -1 + (k + 0.5) / 4;
    double dist_edge = fabs((x + 1) * 4 - floor((x + 1) * 4 + 0.5)) / 4; /* to nearest line */
    const float *p = &rgb[3 * ((size_t)(h / 2 + 3) * w + col)];
    if (dist_edge > 1.5 * px_size) {
      inside++;
      CHECK(fabs(p[0] - (1 + xc)) < 1e-5, "flat: column %d is %g, want leaf value %g", col, p[0],
            1 + xc);
    }
  }
  /* every line between leaves (x = -0.75 .. 0.75) darkens the pixel column nearest to it */
  int dark = 0;
  for (int i = 1; i < 8; i++) {
    double xl = -1 + i / 4.0, best = INFINITY;
    int bc = 0;
    for (int col = 0; col < w; col++) {
      double d = fabs(pixel_world_x(col, w, h, 40) - xl);
      if (d < best) best = d, bc = col;
    }
    const float *p = &rgb[3 * ((size_t)(h / 2 + 3) * w + bc)];
    dark += p[0] < 0.75 * (1 + xl - 0.125);
  }
  CHECK(inside > 30 && dark == 7, "flat mode: %d interior columns, %d of 7 dark outlines", inside,
        dark);
  hr_mesh_destroy(&m);
  free(lv.v);
  free(rgb);
  hr_scene_destroy(&s);
}

/* ------------------------------------------------------------------ viewer */

static int b64val(int c) {
  if (c >= 'A' && c <= 'Z') return c - 'A';
  if (c >= 'a' && c <= 'z') return c - 'a' + 26;
  if (c >= '0' && c <= '9') return c - '0' + 52;
  if (c == '+') return 62;
  if (c == '/') return 63;
  return -1;
}

static const char *find_chromium(void) {
  static const char *cands[] = {"/usr/bin/chromium", "/usr/bin/chromium-browser",
                                "/usr/bin/google-chrome", NULL};
  const char *e = getenv("HRAD_CHROMIUM");
  if (e && access(e, X_OK) == 0) return e;
  for (int i = 0; cands[i]; i++)
    if (access(cands[i], X_OK) == 0) return cands[i];
  return NULL;
}

static void test_viewer(const char *dir, const char *glb) {
  char html[1024], shot[1024], dom[1024], cmd[8192];
  snprintf(html, sizeof html, "%s/viewer.html", dir);
  hr_err err = {{0}};
  hr_status st = hr_viewer_write(html, "mesh.glb", &err);
  CHECK(st == HR_OK, "viewer: %s", err.msg);
  if (st != HR_OK) return;
  /* the embedded .glb decodes to the file's bytes */
  size_t hl, gl;
  unsigned char *h = slurp(html, &hl), *g = slurp(glb, &gl);
  const char *tag = "const HRAD_GLB = \"";
  const char *p = h ? strstr((const char *)h, tag) : NULL;
  CHECK(p != NULL, "viewer.html has no embedded glb");
  if (p && g) {
    p += strlen(tag);
    size_t k = 0;
    int okb = 1;
    uint32_t acc = 0;
    int nb = 0;
    for (; *p && *p != '"'; p++) {
      if (*p == '=') continue;
      int v = b64val(*p);
      if (v < 0) {
        okb = 0;
        break;
      }
      acc = acc << 6 | (uint32_t)v;
      if (++nb == 4) {
        unsigned char o[3] = {(unsigned char)(acc >> 16), (unsigned char)(acc >> 8),
                              (unsigned char)acc};
        for (int i = 0; i < 3; i++, k++)
          if (k < gl && o[i] != g[k]) okb = 0;
        nb = 0;
        acc = 0;
      }
    }
    if (nb == 3) {
      if (k < gl && (unsigned char)(acc >> 10) != g[k]) okb = 0;
      k++;
      if (k < gl && (unsigned char)(acc >> 2) != g[k]) okb = 0;
      k++;
    } else if (nb == 2) {
      if (k < gl && (unsigned char)(acc >> 4) != g[k]) okb = 0;
      k++;
    }
    CHECK(okb && k == gl, "embedded glb differs from the file (%zu of %zu bytes)", k, gl);
  }
  CHECK(h && strstr((const char *)h, "OrbitControls") && strstr((const char *)h, "three.js"),
        "viewer.html lacks three.js/OrbitControls");
  free(h);
  free(g);
  /* headless Chromium: the page must reach state "ok" and draw something */
  const char *chrome = find_chromium();
  CHECK(chrome != NULL, "chromium not installed (scripts/setup.sh installs it)");
  if (!chrome) return;
  const char *flags = "--headless --no-sandbox --disable-gpu --disable-quic --no-first-run "
                      "--disable-background-networking --disable-component-update --disable-sync "
                      "--window-size=512,512 --virtual-time-budget=10000";
  char prof[1024];
  snprintf(prof, sizeof prof, "%s/chrome-profile", dir);
  snprintf(shot, sizeof shot, "%s/viewer.png", dir);
  snprintf(dom, sizeof dom, "%s/viewer-dom.html", dir);
  snprintf(cmd, sizeof cmd,
           "timeout 120 '%s' %s --user-data-dir='%s' --screenshot='%s' 'file://%s' >/dev/null 2>&1"
           " && timeout 120 '%s' %s --user-data-dir='%s' --dump-dom 'file://%s' >'%s' 2>/dev/null",
           chrome, flags, prof, shot, html, chrome, flags, prof, html, dom);
  fflush(stdout);
  double t0 = now_s();
  int rc = system(cmd);
  printf("chromium: %.1f s\n", now_s() - t0);
  CHECK(rc != -1 && WIFEXITED(rc) && WEXITSTATUS(rc) == 0, "chromium failed: status %d", rc);
  size_t dl;
  unsigned char *d = slurp(dom, &dl);
  CHECK(d && strstr((const char *)d, "data-state=\"ok\""), "viewer did not reach state ok: %s",
        d ? (const char *)d + (dl > 400 ? dl - 400 : 0) : "(no DOM)");
  free(d);
  int w, hh;
  unsigned char *px = NULL;
  CHECK(read_png(shot, &w, &hh, &px), "cannot read the screenshot %s", shot);
  if (px) {
    /* background #1e1e24 */
    int64_t differ = 0;
    for (int64_t i = 0; i < (int64_t)w * hh; i++) {
      const unsigned char *q = &px[3 * i];
      if (abs(q[0] - 0x1e) + abs(q[1] - 0x1e) + abs(q[2] - 0x24) > 24) differ++;
    }
    double frac = (double)differ / ((double)w * hh);
    printf("viewer screenshot %dx%d: %.1f%% of pixels differ from the background\n", w, hh,
           100 * frac);
    CHECK(frac > 0.03, "viewer canvas looks blank (%.2f%% non-background)", 100 * frac);
    free(px);
  }
}

/* ------------------------------------------------------------------ split polygons */

/* Refinement of the split-polygon scenes: every surface of one input polygon is subdivided
 * differently, with deep spots on the shared edges (a == 0 is edge 2 of the first triangle of a
 * split, b == 0 edge 0 of the next one: hr_scene_add_polygon splits into (x,y,z), (x,z,w)), so
 * that each side holds T-vertices of the other. */
static int refine_split(int surf, double a0, double b0, double s, int depth) {
  if (depth < 1) return 1;
  switch (surf) {
  case 0:
    if (depth < 2) return 1;
    if (depth < 6 && contains(a0, b0, s, 0, 0.3)) return 1;
    return depth < 4 && contains(a0, b0, s, 0.4, 0.4);
  case 1:
    if (depth < 6 && contains(a0, b0, s, 0.7, 0)) return 1;
    if (depth < 3 && contains(a0, b0, s, 0.2, 0)) return 1;
    return depth < 4 && contains(a0, b0, s, 0, 0.55);
  default:
    if (depth < 3) return 1;
    return depth < 5 && contains(a0, b0, s, 0.3, 0);
  }
}

static int64_t find_pos(const hr_mesh *m, hr_vec3 p) {
  for (int64_t v = 0; v < m->nverts; v++)
    if (v3_len(v3_sub(vpos(m, (uint32_t)v), p)) < 1e-6) return v;
  return -1;
}

/* 1 if p lies strictly inside segment a-b, up to float rounding (1e-6 absolute, for coordinates
 * of order 1; the segments tested are longer than 1e-2), with its parameter in *tt. */
static int inside_seg(hr_vec3 a, hr_vec3 b, hr_vec3 p, double *tt) {
  hr_vec3 d = v3_sub(b, a), e = v3_sub(p, a);
  double len2 = v3_dot(d, d), len = sqrt(len2);
  if (!(len2 > 0)) return 0;
  double t = v3_dot(e, d) / len2;
  if (!(t * len > 1e-6 && (1 - t) * len > 1e-6)) return 0;
  if (v3_len(v3_sub(e, v3_scale(d, t))) > 1e-6) return 0;
  *tt = t;
  return 1;
}

/* Checks the mesh of a scene whose surfaces all come from the one input polygon 'pv' (n
 * vertices): one smooth region without cracks or seams across the surfaces' shared edges. */
static void check_poly_mesh(const char *what, const hr_scene *s, const hr_leaf *lv, int64_t n,
                            const hr_mesh *m, const hr_vec3 *pv, int npv) {
  for (int f = 0; f < s->nsurfs; f++)
    CHECK(s->surfs[f].poly == s->surfs[0].poly, "%s: surfaces of different polygons", what);
  /* triangles: orientation, areas per surface, every vertex used */
  double *area = calloc((size_t)s->nsurfs, sizeof *area);
  uint8_t *used = calloc((size_t)m->nverts, 1);
  int32_t *vsurf = malloc((size_t)m->nverts * sizeof *vsurf);
  for (int64_t v = 0; v < m->nverts; v++) vsurf[v] = -1;
  int flipped = 0, degenerate = 0, range = 0;
  int64_t nmulti = 0; /* vertices used by triangles of several surfaces */
  for (int64_t t = 0; t < m->ntris; t++) {
    const uint32_t *T = &m->tri[3 * t];
    if (T[0] >= m->nverts || T[1] >= m->nverts || T[2] >= m->nverts) {
      range++;
      continue;
    }
    int f = m->tri_surf[t];
    hr_vec3 a = vpos(m, T[0]), b = vpos(m, T[1]), c = vpos(m, T[2]);
    hr_vec3 nn = v3_cross(v3_sub(b, a), v3_sub(c, a));
    if (!(0.5 * v3_len(nn) > 1e-14)) degenerate++;
    if (v3_dot(nn, s->surfs[f].normal) <= 0) flipped++;
    area[f] += 0.5 * v3_len(nn);
    for (int k = 0; k < 3; k++) {
      used[T[k]] = 1;
      if (vsurf[T[k]] == -1)
        vsurf[T[k]] = f;
      else if (vsurf[T[k]] >= 0 && vsurf[T[k]] != f) {
        vsurf[T[k]] = -2;
        nmulti++;
      }
    }
  }
  CHECK(range == 0 && flipped == 0 && degenerate == 0,
        "%s: %d bad indices, %d flipped, %d degenerate triangles", what, range, flipped,
        degenerate);
  for (int f = 0; f < s->nsurfs; f++)
    CHECK(fabs(area[f] - s->surfs[f].area) < 1e-6 * s->surfs[f].area,
          "%s: surface %d mesh area %.9g != %.9g", what, f, area[f], s->surfs[f].area);
  int unused = 0;
  for (int64_t v = 0; v < m->nverts; v++) unused += !used[v];
  CHECK(unused == 0, "%s: %d unused vertices", what, unused);
  /* edges: interior ones shared by exactly two triangles in opposite directions; the boundary is
   * the polygon's outline (no crack along the surfaces' shared edges) */
  edge *E = malloc((size_t)m->ntris * 3 * sizeof *E);
  int64_t ne = 0;
  for (int64_t t = 0; t < m->ntris; t++)
    for (int k = 0; k < 3; k++) E[ne++] = (edge){m->tri[3 * t + k], m->tri[3 * t + (k + 1) % 3]};
  qsort(E, (size_t)ne, sizeof *E, cmp_edge_undirected);
  double blen = 0;
  int over = 0, samedir = 0, crack = 0;
  int64_t ncross = 0; /* interior edges between triangles of different surfaces */
  for (int64_t i = 0; i < ne;) {
    int64_t j = i + 1;
    while (j < ne && cmp_edge_undirected(&E[i], &E[j]) == 0) j++;
    if (j - i == 1) {
      hr_vec3 a = vpos(m, E[i].a), b = vpos(m, E[i].b), mid = v3_scale(v3_add(a, b), 0.5);
      blen += v3_len(v3_sub(a, b));
      int on = 0;
      double tt;
      for (int k = 0; k < npv && !on; k++) {
        hr_vec3 p = pv[k], q = pv[(k + 1) % npv];
        on = inside_seg(p, q, mid, &tt);
      }
      crack += !on;
    } else if (j - i == 2) {
      if (E[i].a == E[i + 1].a) samedir++;
      int fa = vsurf[E[i].a], fb = vsurf[E[i].b];
      ncross += fa == -2 && fb == -2;
    } else {
      over++;
    }
    i = j;
  }
  double perim = 0;
  for (int k = 0; k < npv; k++) perim += v3_len(v3_sub(pv[(k + 1) % npv], pv[k]));
  CHECK(over == 0, "%s: %d edges shared by more than 2 triangles", what, over);
  CHECK(samedir == 0, "%s: %d interior edges with inconsistent orientation", what, samedir);
  CHECK(crack == 0, "%s: %d boundary edges inside the polygon (cracks)", what, crack);
  CHECK(fabs(blen - perim) < 1e-6 * perim, "%s: boundary length %.9g != perimeter %.9g", what,
        blen, perim);
  CHECK(nmulti >= 8 && ncross >= 8, "%s: only %lld shared vertices, %lld shared edges", what,
        (long long)nmulti, (long long)ncross);
  free(E);
  /* vertices: one per position */
  int dups = 0;
  for (int64_t a = 0; a < m->nverts; a++)
    for (int64_t b = a + 1; b < m->nverts; b++)
      dups += v3_len(v3_sub(vpos(m, (uint32_t)a), vpos(m, (uint32_t)b))) < 1e-6;
  CHECK(dups == 0, "%s: %d duplicate vertices", what, dups);
  /* every leaf corner has a vertex; values: T-vertices (strictly inside an edge of a leaf of any
   * surface) interpolate that edge, other corners are the area-weighted mean over all leaves of
   * the polygon touching them; the rest are centres */
  int missing = 0, tbad = 0, cbad = 0;
  int64_t ncorner = 0, ntv = 0, ncross_t = 0;
  double worst = 0;
  for (int64_t i = 0; i < n; i++)
    for (int c = 0; c < lv[i].nverts; c++) missing += find_pos(m, lv[i].p[c]) < 0;
  for (int64_t v = 0; v < m->nverts; v++) {
    hr_vec3 p = vpos(m, (uint32_t)v);
    double wsum = 0, bsum[3] = {0, 0, 0};
    int is_t = 0, touched = 0;
    uint32_t touch_mask = 0, t_mask = 0;
    for (int64_t li = 0; li < n; li++) {
      const hr_leaf *l = &lv[li];
      for (int e = 0; e < l->nverts; e++) {
        hr_vec3 P = l->p[e], Q = l->p[(e + 1) % l->nverts];
        double tt;
        if (v3_len(v3_sub(P, p)) < 1e-6) {
          touched = 1;
          touch_mask |= 1u << (l->surf & 31);
          wsum += l->area;
          for (int k = 0; k < 3; k++) bsum[k] += l->area * l->B[k];
        } else if (inside_seg(P, Q, p, &tt)) {
          is_t = 1;
          t_mask |= 1u << (l->surf & 31);
          int64_t pv_ = find_pos(m, P), qv = find_pos(m, Q);
          if (pv_ < 0 || qv < 0) {
            missing++;
            continue;
          }
          for (int k = 0; k < 3; k++) {
            double want = (1 - tt) * m->B[3 * pv_ + k] + tt * m->B[3 * qv + k];
            double d = fabs(m->B[3 * v + k] - want);
            if (d > worst) worst = d;
            if (d > 1e-5 * fmax(1.0, fabs(want))) tbad++;
          }
        }
      }
    }
    ncorner += touched;
    ntv += is_t;
    ncross_t += is_t && (t_mask & ~touch_mask) && (touch_mask & ~t_mask); /* across surfaces */
    if (touched && !is_t)
      for (int k = 0; k < 3; k++)
        if (fabs(m->B[3 * v + k] - bsum[k] / wsum) > 1e-5 * fmax(1.0, fabs(bsum[k] / wsum)))
          cbad++;
  }
  CHECK(missing == 0, "%s: %d leaf corners without a vertex", what, missing);
  CHECK(tbad == 0, "%s: %d T-vertex values off the coarse edge (worst %.3g): seams", what, tbad,
        worst);
  CHECK(cbad == 0, "%s: %d corner values differ from the polygon's area-weighted mean", what,
        cbad);
  CHECK(m->nverts == ncorner + m->ncentre, "%s: %lld vertices != %lld corners + %lld centres",
        what, (long long)m->nverts, (long long)ncorner, (long long)m->ncentre);
  CHECK(ncross_t >= 4, "%s: only %lld T-vertices across the shared edges", what,
        (long long)ncross_t);
  printf("%s: %lld leaves -> %lld vertices (%lld shared by surfaces, %lld T-vertices, %lld across "
         "surfaces, worst %.2g), %lld triangles, %lld shared interior edges\n",
         what, (long long)n, (long long)m->nverts, (long long)nmulti, (long long)ntv,
         (long long)ncross_t, worst, (long long)m->ntris, (long long)ncross);
  free(area);
  free(used);
  free(vsurf);
}

/* A non-planar quad (two triangle surfaces of one polygon) and a planar pentagon (a fan of three
 * triangles), each surface subdivided differently, with a linear field. */
static void test_split(void) {
  for (int which = 0; which < 2; which++) {
    hr_scene *s;
    hr_scene_create("split", &s);
    double rho[3] = {0.5, 0.5, 0.5}, zero[3] = {0, 0, 0};
    int grey;
    hr_scene_add_material(s, "grey", rho, zero, &grey);
    hr_poly_result r;
    hr_vec3 quad[4] = {{0, 0, 0}, {1, 0, 0}, {1.1, 1, 0.25}, {0, 0.9, 0}}; /* non-planar */
    hr_vec3 pent[5];
    for (int k = 0; k < 5; k++) { /* regular pentagon in a tilted plane */
      double a = 2 * M_PI * k / 5;
      pent[k] = v3(cos(a), 0.6 * sin(a), 0.8 * sin(a) + 0.3);
    }
    const hr_vec3 *pv = which == 0 ? quad : pent;
    int npv = which == 0 ? 4 : 5;
    CHECK(hr_scene_add_polygon(s, pv, npv, grey, &r) == HR_OK && r == HR_POLY_ADDED, "split add");
    CHECK(s->nsurfs == npv - 2 && s->npolys == 1, "%d-gon became %d surfaces", npv, s->nsurfs);
    leafvec lv = {0};
    uint32_t A[2] = {0, 0}, B[2] = {HR_LATTICE, 0}, C[2] = {0, HR_LATTICE};
    for (int f = 0; f < s->nsurfs; f++) gen_tri(s, &lv, f, A, B, C, 0, refine_split, field);
    hr_mesh *m = NULL;
    CHECK(hr_mesh_build(s, lv.v, lv.n, &m) == HR_OK, "split mesh");
    if (m) check_poly_mesh(which == 0 ? "split quad" : "pentagon fan", s, lv.v, lv.n, m, pv, npv);
    hr_mesh_destroy(&m);
    /* two separate polygons sharing an edge stay separate: no vertex shared */
    if (which == 0) {
      hr_vec3 q2[3] = {quad[1], {2, 0.5, 0}, quad[2]};
      hr_scene_add_polygon(s, q2, 3, grey, &r);
      leafvec l2 = lv;
      l2.v = malloc((size_t)lv.cap * sizeof *l2.v);
      memcpy(l2.v, lv.v, (size_t)lv.n * sizeof *l2.v);
      gen_tri(s, &l2, s->nsurfs - 1, A, B, C, 0, uniform8, field);
      CHECK(hr_mesh_build(s, l2.v, l2.n, &m) == HR_OK, "split + neighbour mesh");
      if (m) {
        int shared = 0;
        int32_t *vs = malloc((size_t)m->nverts * sizeof *vs);
        for (int64_t v = 0; v < m->nverts; v++) vs[v] = -1;
        for (int64_t t = 0; t < m->ntris; t++)
          for (int k = 0; k < 3; k++) {
            uint32_t v = m->tri[3 * t + k];
            int p = s->surfs[m->tri_surf[t]].poly;
            if (vs[v] == -1)
              vs[v] = p;
            else if (vs[v] != p)
              shared++;
          }
        CHECK(shared == 0, "%d vertices shared between different polygons", shared);
        free(vs);
      }
      hr_mesh_destroy(&m);
      free(l2.v);
    }
    free(lv.v);
    hr_scene_destroy(&s);
  }
}

/* Meshes show what is seen of a leaf: a wall element half behind a board it touches (open 0.5)
 * has a mean radiosity of half its open part's, and its vertices beside the board must show the
 * open part's, as the lit neighbour does (not the mean: a dark smudge next to the board). */
static void test_open(void) {
  hr_poly_result r;
  const hr_vec3 quad[4] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  hr_scene *s = grey_quad("open", quad, &r);
  CHECK(r == HR_POLY_ADDED, "open add");
  const uint32_t L = HR_LATTICE, H = HR_LATTICE / 2;
  hr_leaf lv[2] = {{.surf = 0, .nverts = 4, .lat = {{0, 0}, {H, 0}, {H, L}, {0, L}},
                    .p = {{0, 0, 0}, {0.5, 0, 0}, {0.5, 1, 0}, {0, 1, 0}}, .area = 0.5,
                    .B = {0.2, 0.2, 0.2}, .open = 0.5},
                   {.surf = 0, .nverts = 4, .lat = {{H, 0}, {L, 0}, {L, L}, {H, L}},
                    .p = {{0.5, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0.5, 1, 0}}, .area = 0.5,
                    .B = {0.4, 0.4, 0.4}, .open = 0}}; /* 0: not given, counts as wholly open */
  hr_mesh *m = NULL;
  CHECK(hr_mesh_build(s, lv, 2, &m) == HR_OK && m, "open mesh");
  double worst = 0;
  for (int64_t v = 0; m && v < m->nverts; v++)
    for (int c = 0; c < 3; c++) worst = fmax(worst, fabs(m->B[3 * v + c] - 0.4));
  CHECK(m && m->nverts >= 6 && worst < 1e-6, "open parts: %lld vertices, off by %g",
        m ? (long long)m->nverts : 0LL, worst);
  hr_mesh_destroy(&m);
  hr_scene_destroy(&s);
}

/* ------------------------------------------------------------------ performance */

static int refine_room(int surf, double a0, double b0, double s, int depth) {
  (void)s;
  if (depth < 6) return 1;
  /* deeper towards one corner of each wall: unbalanced like a solver's output */
  double d = hypot(a0 - 0.2 * (surf % 3), b0 - 0.1 * (surf % 2));
  return depth < 9 && d < 0.6 / (depth - 4);
}

static void room_B(hr_vec3 c, double B[3]) {
  B[0] = 0.3 + 0.2 * sin(3 * c.x) * cos(2 * c.z) + 0.1 * c.y;
  B[1] = 0.3 + 0.1 * c.x;
  B[2] = 0.25 + 0.05 * c.z;
}

static void test_performance(const char *dir) {
  hr_scene *s;
  hr_scene_create("room", &s);
  double rho[3] = {0.5, 0.5, 0.5}, zero[3] = {0, 0, 0}, e[3] = {10, 10, 10};
  int grey, lamp;
  hr_scene_add_material(s, "grey", rho, zero, &grey);
  hr_scene_add_material(s, "lamp", rho, e, &lamp);
  hr_poly_result r;
  /* box walls (reversed below so that they face inwards) */
  hr_vec3 W[6][4] = {{{0, 0, 0}, {4, 0, 0}, {4, 0, 4}, {0, 0, 4}},  /* floor y=0 */
                     {{0, 3, 0}, {0, 3, 4}, {4, 3, 4}, {4, 3, 0}},  /* ceiling y=3 */
                     {{0, 0, 0}, {0, 3, 0}, {4, 3, 0}, {4, 0, 0}},  /* z=0 */
                     {{0, 0, 4}, {4, 0, 4}, {4, 3, 4}, {0, 3, 4}},  /* z=4 */
                     {{0, 0, 0}, {0, 0, 4}, {0, 3, 4}, {0, 3, 0}},  /* x=0 */
                     {{4, 0, 0}, {4, 3, 0}, {4, 3, 4}, {4, 0, 4}}}; /* x=4 */
  for (int i = 0; i < 6; i++) { /* listed clockwise from inside: reverse */
    hr_vec3 rev[4] = {W[i][3], W[i][2], W[i][1], W[i][0]};
    hr_scene_add_polygon(s, rev, 4, grey, &r);
  }
  hr_vec3 lp[4] = {{1.5, 2.99, 1.5}, {2.5, 2.99, 1.5}, {2.5, 2.99, 2.5}, {1.5, 2.99, 2.5}};
  hr_scene_add_polygon(s, lp, 4, lamp, &r); /* faces down */
  for (int i = 0; i < s->nsurfs; i++)
    CHECK(s->surfs[i].normal.y > 0.5 || i != 0, "room floor faces %g", s->surfs[i].normal.y);
  CHECK(s->surfs[6].normal.y < -0.5, "room lamp faces up");
  leafvec lv = {0};
  for (int f = 0; f < s->nsurfs; f++) gen_quad(s, &lv, f, 0, 0, HR_LATTICE, 0, refine_room, room_B);
  hr_mesh *m = NULL;
  double t0 = now_s();
  CHECK(hr_mesh_build(s, lv.v, lv.n, &m) == HR_OK, "room mesh");
  double t1 = now_s();
  if (!m) return;
  double ex = hr_exposure_auto(m);
  double t2 = now_s();
  const int w = 1024, h = 768;
  float *rgb = malloc((size_t)w * h * 3 * sizeof *rgb);
  hr_camera cam = {{3.6, 1.6, 3.7}, {1.0, 1.0, 0.5}, {0, 1, 0}, 60};
  CHECK(hr_render(s, m, lv.v, lv.n, &cam, w, h, 0, rgb) == HR_OK, "room render");
  double t3 = now_s();
  CHECK(hr_render(s, m, lv.v, lv.n, &cam, w, h, 1, rgb) == HR_OK, "room render flat");
  double t4 = now_s();
  printf("performance: %lld leaves -> %lld vertices, %lld triangles; mesh %.3f s, exposure "
         "%.3f s, render %dx%d smooth %.3f s, elements %.3f s\n",
         (long long)lv.n, (long long)m->nverts, (long long)m->ntris, t1 - t0, t2 - t1, w, h,
         t3 - t2, t4 - t3);
  char path[1024];
  hr_err err;
  snprintf(path, sizeof path, "%s/room_flat.png", dir);
  hr_png_write(path, w, h, rgb, ex, &err);
  hr_render(s, m, lv.v, lv.n, &cam, w, h, 0, rgb);
  snprintf(path, sizeof path, "%s/room_smooth.png", dir);
  hr_png_write(path, w, h, rgb, ex, &err);
  /* camera inside the room, walls crossing the near plane: every pixel must see a lit
   * front face (no holes, no back faces) */
  int holes = 0;
  float back = (float)(0.04 / ex);
  for (size_t i = 0; i < (size_t)w * h; i++)
    holes += !(rgb[3 * i + 1] > 0) || fabsf(rgb[3 * i + 1] - back) < 1e-7f;
  CHECK(holes == 0, "room render has %d holes or back-face pixels", holes);
  free(rgb);
  hr_mesh_destroy(&m);
  free(lv.v);
  hr_scene_destroy(&s);
}

/* ------------------------------------------------------------------ main */

int main(void) {
  char dir[] = "/tmp/hrad_test_output_XXXXXX";
  if (!mkdtemp(dir)) {
    perror("mkdtemp");
    return 1;
  }
  printf("output directory %s\n", dir);
  test_open();
  hr_scene *s = make_scene();
  leafvec lv = {0};
  gen_all(s, &lv, refine_main, field);
  for (int64_t i = 0; i < lv.n; i++) /* a bright emitter: must not drive the exposure */
    if (lv.v[i].surf == 3)
      for (int c = 0; c < 3; c++) lv.v[i].B[c] *= 50;
  hr_mesh *m = NULL;
  CHECK(hr_mesh_build(s, lv.v, lv.n, &m) == HR_OK, "hr_mesh_build failed");
  if (!m) return 1;
  printf("%lld leaves -> %lld vertices (%lld centres), %lld triangles\n", (long long)lv.n,
         (long long)m->nverts, (long long)m->ncentre, (long long)m->ntris);
  check_mesh(s, lv.v, lv.n, m);
  CHECK(m->ncentre >= 2, "only %lld centre vertices exercised", (long long)m->ncentre);

  /* the same leaves shuffled give the same vertex values (order independence) */
  {
    hr_leaf *sh = malloc((size_t)lv.n * sizeof *sh);
    for (int64_t i = 0; i < lv.n; i++) sh[i] = lv.v[(i * 7919) % lv.n];
    int coprime = lv.n % 7919 != 0;
    hr_mesh *m2 = NULL;
    CHECK(coprime && hr_mesh_build(s, sh, lv.n, &m2) == HR_OK, "shuffled build");
    if (m2) {
      CHECK(m2->nverts == m->nverts && m2->ntris == m->ntris, "shuffled: different sizes");
      check_mesh(s, sh, lv.n, m2);
    }
    hr_mesh_destroy(&m2);
    free(sh);
  }
  /* invalid input */
  {
    hr_leaf bad = lv.v[0];
    bad.surf = 99;
    hr_mesh *m3 = NULL;
    CHECK(hr_mesh_build(s, &bad, 1, &m3) == HR_ERR_INVALID && !m3, "bad surface accepted");
    bad = lv.v[0];
    bad.nverts = 3;
    CHECK(hr_mesh_build(s, &bad, 1, &m3) == HR_ERR_INVALID && !m3, "bad nverts accepted");
    CHECK(hr_mesh_build(s, NULL, 0, &m3) == HR_OK && m3 && m3->ntris == 0, "empty mesh");
    hr_mesh_destroy(&m3);
  }
  double ex = hr_exposure_auto(m);
  CHECK(ex > 0 && isfinite(ex), "exposure %g", ex);
  /* the emitter (its B comes from the same field) must not drive the exposure: compare with the
   * mesh without it */
  {
    int64_t k = 0;
    hr_leaf *ne = malloc((size_t)lv.n * sizeof *ne);
    for (int64_t i = 0; i < lv.n; i++)
      if (lv.v[i].surf != 3) ne[k++] = lv.v[i];
    hr_mesh *m4 = NULL;
    hr_mesh_build(s, ne, k, &m4);
    CHECK(m4 && fabs(hr_exposure_auto(m4) - ex) < 1e-9 * ex, "exposure depends on the emitter");
    hr_mesh_destroy(&m4);
    free(ne);
  }
  char path[1024];
  hr_err err = {{0}};
  snprintf(path, sizeof path, "%s/mesh.ply", dir);
  CHECK(hr_ply_write(path, m, ex, &err) == HR_OK, "ply: %s", err.msg);
  check_ply(path, m, ex);
  char glb[1024];
  snprintf(glb, sizeof glb, "%s/mesh.glb", dir);
  CHECK(hr_glb_write(glb, m, ex, &err) == HR_OK, "glb: %s", err.msg);
  check_glb(glb, 1);
  /* an empty mesh is a valid GLB too */
  {
    hr_mesh *m0 = NULL;
    hr_mesh_build(s, NULL, 0, &m0);
    snprintf(path, sizeof path, "%s/empty.glb", dir);
    CHECK(m0 && hr_glb_write(path, m0, 1.0, &err) == HR_OK, "empty glb: %s", err.msg);
    check_glb(path, 0);
    hr_mesh_destroy(&m0);
  }
  /* a render of the test scene in both modes, for looking at */
  {
    const int w = 480, h = 320;
    float *rgb = malloc((size_t)w * h * 3 * sizeof *rgb);
    hr_camera cam = {{0.25, 1.2, 5.5}, {0.25, 0.9, 0}, {0, 1, 0}, 45};
    CHECK(hr_render(s, m, lv.v, lv.n, &cam, w, h, 0, rgb) == HR_OK, "render");
    snprintf(path, sizeof path, "%s/scene_smooth.png", dir);
    CHECK(hr_png_write(path, w, h, rgb, ex, &err) == HR_OK, "png: %s", err.msg);
    CHECK(hr_render(s, m, lv.v, lv.n, &cam, w, h, 1, rgb) == HR_OK, "render flat");
    snprintf(path, sizeof path, "%s/scene_flat.png", dir);
    CHECK(hr_png_write(path, w, h, rgb, ex, &err) == HR_OK, "png: %s", err.msg);
    free(rgb);
  }
  test_deep();
  test_split();
  test_render(dir);
  test_viewer(dir, glb);
  /* missing three.js is an error naming the path */
  {
    const char *old = getenv("HRAD_THREE_DIR");
    char *saved = old ? strdup(old) : NULL;
    setenv("HRAD_THREE_DIR", "/nonexistent/three", 1);
    snprintf(path, sizeof path, "%s/viewer2.html", dir);
    hr_status st = hr_viewer_write(path, "mesh.glb", &err);
    CHECK(st == HR_ERR_IO && strstr(err.msg, "/nonexistent/three"), "missing three.js: %d %s", st,
          err.msg);
    if (saved)
      setenv("HRAD_THREE_DIR", saved, 1);
    else
      unsetenv("HRAD_THREE_DIR");
    free(saved);
  }
  test_performance(dir);

  hr_mesh_destroy(&m);
  free(lv.v);
  hr_scene_destroy(&s);
  if (failures) {
    fprintf(stderr, "test_output: %d failures (files kept in %s)\n", failures, dir);
    return 1;
  }
  if (!getenv("HRAD_KEEP_TEST_OUTPUT")) {
    char cmd[1200];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", dir);
  } else {
    printf("kept %s\n", dir);
  }
  printf("test_output: all checks passed\n");
  return 0;
}
