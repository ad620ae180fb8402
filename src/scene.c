/* scene.c: surfaces and materials, the immutable input of the solver (paper 2.2: "surface" or
 * "blocker"). Validates each input polygon: planar convex quads stay quads, other quads become two
 * triangles, larger polygons are fan-split; degenerate pieces are reported, not added. Scenes are
 * small immutable arrays so that later every process can hold a replica. */
#include "hrad.h"
#include "vec.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

hr_status hr_err_set(hr_err *err, hr_status st, const char *fmt, ...) {
  if (err) {
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(err->msg, sizeof err->msg, fmt, ap);
    va_end(ap);
  }
  return st;
}

void hr_log_warn(const hr_log *log, const char *fmt, ...) {
  if (!log || !log->fn) return;
  char buf[512];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(buf, sizeof buf, fmt, ap);
  va_end(ap);
  log->fn(log->ud, buf);
}

hr_status hr_scene_create(const char *name, hr_scene **out) {
  hr_scene *s = calloc(1, sizeof *s);
  if (!s) return HR_ERR_NOMEM;
  s->name = strdup(name ? name : "scene");
  if (!s->name) {
    free(s);
    return HR_ERR_NOMEM;
  }
  *out = s;
  return HR_OK;
}

void hr_scene_destroy(hr_scene **ps) {
  if (!ps || !*ps) return;
  hr_scene *s = *ps;
  for (int i = 0; i < s->nmats; i++) free(s->mats[i].name);
  free(s->mats);
  free(s->surfs);
  free(s->poly_area);
  free(s->name);
  free(s);
  *ps = NULL;
}

/* Grows '*p' (element size 'sz', capacity '*cap') to hold at least 'need' items. */
static int grow(void **p, int *cap, int need, size_t sz) {
  if (need <= *cap) return 1;
  int nc = *cap ? *cap : 16;
  while (nc < need) nc *= 2;
  void *q = realloc(*p, (size_t)nc * sz);
  if (!q) return 0;
  *p = q;
  *cap = nc;
  return 1;
}

hr_status hr_scene_add_material(hr_scene *s, const char *name, const double rho[3],
                                const double emit[3], int *idx) {
  if (!grow((void **)&s->mats, &s->cap_mats, s->nmats + 1, sizeof *s->mats)) return HR_ERR_NOMEM;
  hr_material *m = &s->mats[s->nmats];
  m->name = strdup(name ? name : "");
  if (!m->name) return HR_ERR_NOMEM;
  for (int c = 0; c < 3; c++) {
    m->rho[c] = rho[c];
    m->emit[c] = emit[c];
  }
  if (idx) *idx = s->nmats;
  s->nmats++;
  return HR_OK;
}

int hr_scene_find_material(const hr_scene *s, const char *name) {
  for (int i = 0; i < s->nmats; i++)
    if (strcmp(s->mats[i].name, name) == 0) return i;
  return -1;
}

hr_status hr_scene_set_emit(hr_scene *s, const char *name, const double rgb[3], hr_err *err) {
  int m = hr_scene_find_material(s, name);
  if (m < 0) return hr_err_set(err, HR_ERR_INVALID, "no material named '%s'", name);
  for (int c = 0; c < 3; c++) s->mats[m].emit[c] = rgb[c];
  return HR_OK;
}

/* Newell normal (not normalised): robust for any simple polygon. */
static hr_vec3 newell(const hr_vec3 *v, int n) {
  hr_vec3 r = {0, 0, 0};
  for (int i = 0; i < n; i++) {
    hr_vec3 a = v[i], b = v[(i + 1) % n];
    r.x += (a.y - b.y) * (a.z + b.z);
    r.y += (a.z - b.z) * (a.x + b.x);
    r.z += (a.x - b.x) * (a.y + b.y);
  }
  return r;
}

/* Relative tolerances: a vertex off the plane by more than PLANAR_TOL times the polygon's size
 * makes it non-planar; an area below AREA_TOL times size^2 is degenerate. */
#define PLANAR_TOL 1e-6
#define AREA_TOL 1e-10

static double poly_size(const hr_vec3 *v, int n) {
  double d = 0;
  for (int i = 0; i < n; i++)
    for (int j = i + 1; j < n; j++) d = fmax(d, v3_len(v3_sub(v[i], v[j])));
  return d;
}

static hr_status push_surface(hr_scene *s, const hr_vec3 *v, int n, int material, int poly,
                              int *added) {
  hr_vec3 nn = newell(v, n);
  double len = v3_len(nn);
  double size = poly_size(v, n);
  if (!(len * 0.5 > AREA_TOL * size * size) || size == 0) return HR_OK; /* degenerate piece */
  if (!grow((void **)&s->surfs, &s->cap_surfs, s->nsurfs + 1, sizeof *s->surfs))
    return HR_ERR_NOMEM;
  hr_surface *f = &s->surfs[s->nsurfs++];
  memset(f, 0, sizeof *f);
  f->nverts = n;
  for (int i = 0; i < n; i++) f->v[i] = v[i];
  f->normal = v3_scale(nn, 1.0 / len);
  f->area = 0.5 * len;
  f->material = material;
  f->poly = poly;
  (*added)++;
  return HR_OK;
}

/* 1 if every vertex lies within tolerance of the plane through v[0] with normal 'nrm'. */
static int is_planar(const hr_vec3 *v, int n, hr_vec3 nrm, double size) {
  for (int i = 1; i < n; i++)
    if (fabs(v3_dot(v3_sub(v[i], v[0]), nrm)) > PLANAR_TOL * size) return 0;
  return 1;
}

/* 1 if the polygon turns the same way (along 'nrm') at every vertex. */
static int is_convex(const hr_vec3 *v, int n, hr_vec3 nrm) {
  for (int i = 0; i < n; i++) {
    hr_vec3 e0 = v3_sub(v[(i + 1) % n], v[i]);
    hr_vec3 e1 = v3_sub(v[(i + 2) % n], v[(i + 1) % n]);
    if (v3_dot(v3_cross(e0, e1), nrm) <= 0) return 0;
  }
  return 1;
}

hr_status hr_scene_add_polygon(hr_scene *s, const hr_vec3 *v, int n, int material,
                               hr_poly_result *res) {
  *res = HR_POLY_DEGENERATE;
  if (n < 3 || material < 0 || material >= s->nmats) return HR_ERR_INVALID;
  for (int i = 0; i < n; i++)
    if (!isfinite(v[i].x) || !isfinite(v[i].y) || !isfinite(v[i].z)) return HR_ERR_INVALID;
  hr_vec3 nn = newell(v, n);
  double len = v3_len(nn), size = poly_size(v, n);
  if (size == 0 || !(0.5 * len > AREA_TOL * size * size)) return HR_OK;
  hr_vec3 nrm = v3_scale(nn, 1.0 / len);
  int planar = is_planar(v, n, nrm, size);
  if (n > 4 && !planar) {
    *res = HR_POLY_NONPLANAR;
    return HR_OK;
  }
  int poly = s->npolys, added = 0;
  hr_status st = HR_OK;
  if (n == 3 || (n == 4 && planar && is_convex(v, n, nrm))) {
    st = push_surface(s, v, n, material, poly, &added);
  } else if (n == 4) {
    /* Split along the diagonal whose two triangles both face along the polygon normal;
     * of two valid diagonals take the shorter (better-shaped triangles). */
    hr_vec3 a[3] = {v[0], v[1], v[2]}, b[3] = {v[0], v[2], v[3]};
    hr_vec3 c[3] = {v[1], v[2], v[3]}, d[3] = {v[1], v[3], v[0]};
    int ok02 = v3_dot(newell(a, 3), nrm) > 0 && v3_dot(newell(b, 3), nrm) > 0;
    int ok13 = v3_dot(newell(c, 3), nrm) > 0 && v3_dot(newell(d, 3), nrm) > 0;
    int use13 = ok13 && (!ok02 || v3_len(v3_sub(v[1], v[3])) < v3_len(v3_sub(v[0], v[2])));
    if (use13) {
      st = push_surface(s, c, 3, material, poly, &added);
      if (st == HR_OK) st = push_surface(s, d, 3, material, poly, &added);
    } else {
      st = push_surface(s, a, 3, material, poly, &added);
      if (st == HR_OK) st = push_surface(s, b, 3, material, poly, &added);
    }
  } else {
    for (int i = 1; i + 1 < n && st == HR_OK; i++) {
      hr_vec3 t[3] = {v[0], v[i], v[i + 1]};
      st = push_surface(s, t, 3, material, poly, &added);
    }
  }
  if (st != HR_OK) return st;
  if (added == 0) return HR_OK;
  /* poly_area doubles whenever npolys reaches a power of two (its capacity). */
  int np = s->npolys;
  if (np == 0 || (np & (np - 1)) == 0) {
    double *pa = realloc(s->poly_area, (size_t)(np ? 2 * np : 1) * sizeof *pa);
    if (!pa) return HR_ERR_NOMEM;
    s->poly_area = pa;
  }
  double area = 0;
  for (int i = s->nsurfs - added; i < s->nsurfs; i++) area += s->surfs[i].area;
  s->poly_area[s->npolys++] = area;
  *res = HR_POLY_ADDED;
  return HR_OK;
}

double hr_scene_total_area(const hr_scene *s) {
  double a = 0;
  for (int i = 0; i < s->nsurfs; i++) a += s->surfs[i].area;
  return a;
}

double hr_scene_max_emit(const hr_scene *s) {
  double m = 0;
  for (int i = 0; i < s->nsurfs; i++)
    for (int c = 0; c < 3; c++) m = fmax(m, s->mats[s->surfs[i].material].emit[c]);
  return m;
}

void hr_scene_bounds(const hr_scene *s, hr_vec3 *lo, hr_vec3 *hi) {
  hr_vec3 a = {INFINITY, INFINITY, INFINITY}, b = {-INFINITY, -INFINITY, -INFINITY};
  for (int i = 0; i < s->nsurfs; i++)
    for (int k = 0; k < s->surfs[i].nverts; k++) {
      a = v3_min(a, s->surfs[i].v[k]);
      b = v3_max(b, s->surfs[i].v[k]);
    }
  *lo = a;
  *hi = b;
}

void hr_scene_auto_camera(const hr_scene *s, hr_camera *cam) {
  hr_vec3 lo, hi;
  hr_scene_bounds(s, &lo, &hi);
  hr_vec3 c = v3_scale(v3_add(lo, hi), 0.5), ext = v3_sub(hi, lo);
  double r = 0.5 * v3_len(ext);
  if (!(r > 0)) r = 1;
  /* Up is the axis with the smallest extent among y and z when one is clearly flat; default y. */
  cam->up = (hr_vec3){0, 1, 0};
  cam->fov_deg = 50;
  double dist = r / tan(0.5 * cam->fov_deg * M_PI / 180.0) * 1.05;
  hr_vec3 dir = v3_norm((hr_vec3){0.55, 0.45, 1.0});
  cam->at = c;
  cam->eye = v3_add(c, v3_scale(dir, dist));
}
