/* scene.c: surfaces and materials, the immutable input of the solver (paper 2.2: "surface" or
 * "blocker"). Validates each input polygon: planar convex quads stay quads, other quads become two
 * triangles, larger convex polygons are fan-split, non-convex ones (keyhole polygons with holes
 * among them) are ear-clipped, self-crossing ones refused; degenerate pieces are reported, not
 * added. Scenes are small immutable arrays so that later every process can hold a replica. */
#include "hrad.h"
#include "vec.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

const char *hr_version(void) { return HR_VERSION_STRING; }

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
  s->cur_object = -1;
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
  free(s->inputs);
  for (int i = 0; i < s->nobjects; i++) free(s->objects[i]);
  free(s->objects);
  free(s->poly_object);
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
  for (int c = 0; c < 3; c++)
    if (!(rho[c] >= 0 && rho[c] <= 1) || !(emit[c] >= 0 && emit[c] <= HR_EMIT_MAX))
      return HR_ERR_INVALID;
  if (!grow((void **)&s->mats, &s->cap_mats, s->nmats + 1, sizeof *s->mats)) return HR_ERR_NOMEM;
  hr_material *m = &s->mats[s->nmats];
  m->name = strdup(name ? name : "");
  if (!m->name) return HR_ERR_NOMEM;
  for (int c = 0; c < 3; c++) {
    m->rho[c] = rho[c];
    m->emit[c] = emit[c];
  }
  m->base = s->nmats;
  if (idx) *idx = s->nmats;
  s->nmats++;
  return HR_OK;
}

hr_status hr_scene_add_variant(hr_scene *s, int base, const double rho[3], int *idx) {
  if (base < 0 || base >= s->nmats) return HR_ERR_INVALID;
  base = s->mats[base].base;
  int k;
  double emit[3]; /* a copy: adding may move s->mats */
  memcpy(emit, s->mats[base].emit, sizeof emit);
  hr_status st = hr_scene_add_material(s, s->mats[base].name, rho, emit, &k);
  if (st != HR_OK) return st;
  s->mats[k].base = base;
  if (idx) *idx = k;
  return HR_OK;
}

int hr_scene_material_count(const hr_scene *s) {
  int n = 0;
  for (int i = 0; i < s->nmats; i++) n += s->mats[i].base == i;
  return n;
}

int hr_scene_material_at(const hr_scene *s, int k) {
  for (int i = 0; i < s->nmats; i++)
    if (s->mats[i].base == i && k-- == 0) return i;
  return -1;
}

int hr_scene_find_material(const hr_scene *s, const char *name) {
  for (int i = 0; i < s->nmats; i++)
    if (s->mats[i].base == i && strcmp(s->mats[i].name, name) == 0) return i;
  return -1;
}

/* ---------------------------------------------------------------- objects */

/* Index of object 'name', added when missing; -1 when out of memory. */
static int find_or_add_object(hr_scene *s, const char *name) {
  for (int i = 0; i < s->nobjects; i++)
    if (strcmp(s->objects[i], name) == 0) return i;
  if (!grow((void **)&s->objects, &s->cap_objects, s->nobjects + 1, sizeof *s->objects))
    return -1;
  if (!(s->objects[s->nobjects] = strdup(name))) return -1;
  return s->nobjects++;
}

hr_status hr_scene_begin_object(hr_scene *s, const char *name) {
  if (!s || !name) return HR_ERR_INVALID;
  int o = find_or_add_object(s, name);
  if (o < 0) return HR_ERR_NOMEM;
  s->cur_object = o;
  return HR_OK;
}

int hr_scene_object_count(const hr_scene *s) { return s->nobjects; }

const char *hr_scene_object_name(const hr_scene *s, int obj) {
  return obj >= 0 && obj < s->nobjects ? s->objects[obj] : NULL;
}

int hr_scene_poly_object(const hr_scene *s, int poly) {
  return poly >= 0 && poly < s->npolys && s->poly_object ? s->poly_object[poly] : -1;
}

int hr_scene_poly_first(const hr_scene *s, int poly) {
  int lo = 0, hi = s->nsurfs;
  while (lo < hi) {
    int mid = lo + (hi - lo) / 2;
    if (s->surfs[mid].poly < poly)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo < s->nsurfs && s->surfs[lo].poly == poly ? lo : s->nsurfs;
}

int hr_scene_poly_material(const hr_scene *s, int poly) {
  if (poly < 0 || poly >= s->npolys) return -1;
  const int i = hr_scene_poly_first(s, poly);
  return i < s->nsurfs ? s->mats[s->surfs[i].material].base : -1;
}

/* Records the object of the polygon just kept (the last one): 0 when out of memory. */
static int record_object(hr_scene *s) {
  if (s->cur_object < 0 && (s->cur_object = find_or_add_object(s, s->name)) < 0) return 0;
  if (!grow((void **)&s->poly_object, &s->cap_poly_object, s->npolys, sizeof *s->poly_object))
    return 0;
  s->poly_object[s->npolys - 1] = s->cur_object;
  return 1;
}

hr_status hr_scene_scale(hr_scene *s, double f) {
  if (!(f > 0) || !isfinite(f)) return HR_ERR_INVALID;
  for (int i = 0; i < s->nsurfs; i++)
    for (int k = 0; k < s->surfs[i].nverts; k++) {
      hr_vec3 p = v3_scale(s->surfs[i].v[k], f);
      if (!(fabs(p.x) <= HR_COORD_MAX && fabs(p.y) <= HR_COORD_MAX && fabs(p.z) <= HR_COORD_MAX))
        return HR_ERR_INVALID;
    }
  for (int i = 0; i < s->nsurfs; i++) {
    hr_surface *sf = &s->surfs[i];
    for (int k = 0; k < sf->nverts; k++) sf->v[k] = v3_scale(sf->v[k], f);
    sf->area *= f * f;
  }
  for (int p = 0; p < s->npolys; p++) s->poly_area[p] *= f * f;
  s->camera.eye = v3_scale(s->camera.eye, f);
  s->camera.at = v3_scale(s->camera.at, f);
  return HR_OK;
}

hr_status hr_scene_set_emit(hr_scene *s, const char *name, const double rgb[3], hr_err *err) {
  int m = hr_scene_find_material(s, name);
  if (m < 0) return hr_err_set(err, HR_ERR_INVALID, "no material named '%s'", name);
  for (int c = 0; c < 3; c++)
    if (!(rgb[c] >= 0 && rgb[c] <= HR_EMIT_MAX))
      return hr_err_set(err, HR_ERR_INVALID,
                        "emission of '%s' must be in [0, 1e30] (got %g, %g, %g)", name, rgb[0],
                        rgb[1], rgb[2]);
  for (int i = 0; i < s->nmats; i++)
    if (s->mats[i].base == m)
      for (int c = 0; c < 3; c++) s->mats[i].emit[c] = rgb[c];
  return HR_OK;
}

/* Relative tolerances: a vertex off the plane by more than PLANAR_TOL times the polygon's size
 * makes it non-planar; an area below AREA_TOL times size^2 is degenerate. */
#define PLANAR_TOL 1e-6
#define AREA_TOL 1e-10

/* A polygon's size: the diagonal of its bounding box (linear in n; within a factor sqrt(3) of
 * its diameter). */
static double poly_size(const hr_vec3 *v, int n) {
  hr_vec3 lo = v[0], hi = v[0];
  for (int i = 1; i < n; i++) {
    lo = v3_min(lo, v[i]);
    hi = v3_max(hi, v[i]);
  }
  return v3_len(v3_sub(hi, lo));
}

static hr_status push_surface(hr_scene *s, const hr_vec3 *v, int n, int material, int poly,
                              int *added) {
  hr_vec3 nn = v3_newell(v, n);
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

/* 1 if the polygon turns the same way (along 'nrm') at every vertex and its turns add up to
 * one whole turn (a pentagram turns the same way at every vertex but winds twice). */
static int is_convex(const hr_vec3 *v, int n, hr_vec3 nrm) {
  double turn = 0;
  for (int i = 0; i < n; i++) {
    hr_vec3 e0 = v3_sub(v[(i + 1) % n], v[i]);
    hr_vec3 e1 = v3_sub(v[(i + 2) % n], v[(i + 1) % n]);
    double sn = v3_dot(v3_cross(e0, e1), nrm);
    if (sn <= 0) return 0;
    turn += atan2(sn, v3_dot(e0, e1));
  }
  return turn < 3 * M_PI; /* 2 pi for a convex polygon, 4 pi or more for a star */
}

/* Appends an input record; 0 when out of memory. */
static int push_input(hr_scene *s, int poly, hr_input_kind kind) {
  if (!grow((void **)&s->inputs, &s->cap_inputs, s->ninputs + 1, sizeof *s->inputs)) return 0;
  s->inputs[s->ninputs++] = (hr_input){poly, kind};
  return 1;
}

hr_status hr_scene_add_duplicate(hr_scene *s, int poly) {
  if (poly < 0 || poly >= s->npolys) return HR_ERR_INVALID;
  return push_input(s, poly, HR_INPUT_DUPLICATE) ? HR_OK : HR_ERR_NOMEM;
}

int hr_scene_poly_input(const hr_scene *s, int poly) {
  for (int i = 0; i < s->ninputs; i++)
    if (s->inputs[i].kind == HR_INPUT_SOLVED && s->inputs[i].poly == poly) return i;
  return -1;
}

static hr_status add_polygon(hr_scene *s, const hr_vec3 *v, int n, int material,
                             hr_poly_result *res);

/* ---------------------------------------------------------------- non-convex polygons */

/* A non-convex polygon projected on its plane, counter-clockwise seen from the front. Exporters
 * write a polygon with a hole as one loop (a "keyhole"): the outer boundary, a cut to the hole
 * (the bridge), the hole the other way round, and back along the same cut. Such a polygon
 * revisits the positions at both ends of the bridge; 'pid' finds the revisits, 'back' pairs the
 * bridge's two traversals. */
typedef struct flat_poly {
  int m;        /* vertices left after dropping repeats of the previous one (zero-length edges) */
  int npos;     /* distinct positions */
  double *x;    /* coordinates of vertex k in the plane: x[2 * k], x[2 * k + 1] */
  int *src;     /* index in the input of vertex k */
  int *pid;     /* position number of vertex k: equal coordinates, equal numbers */
  int *by_pos;  /* the vertices sorted by position: the visits of one position are adjacent */
  int *back;    /* edge k runs from vertex k to k + 1 (mod m); back[k] is the edge that traverses
                   it the other way when k is a bridge, -1 otherwise */
} flat_poly;

static void flat_free(flat_poly *p) {
  free(p->x);
  free(p->src);
  free(p->pid);
  free(p->by_pos);
  free(p->back);
}

/* Twice the signed area of triangle (a, b, c) of 'x': positive when counter-clockwise. */
static double orient(const double *x, int a, int b, int c) {
  return (x[2 * b] - x[2 * a]) * (x[2 * c + 1] - x[2 * a + 1]) -
         (x[2 * b + 1] - x[2 * a + 1]) * (x[2 * c] - x[2 * a]);
}

static int same_xy(const double *x, int a, int b) {
  return x[2 * a] == x[2 * b] && x[2 * a + 1] == x[2 * b + 1];
}

/* Projects v[0..n) on the plane of the two axes other than the normal's largest, keeping the
 * front's counter-clockwise order, and drops every vertex at the position of the one before it:
 * a zero-length edge touches nothing and would only block ears. 1 on success, -1 when out of
 * memory. */
static int flat_init(flat_poly *p, const hr_vec3 *v, int n, hr_vec3 nrm) {
  int ax = fabs(nrm.x) > fabs(nrm.y) ? (fabs(nrm.x) > fabs(nrm.z) ? 0 : 2)
                                     : (fabs(nrm.y) > fabs(nrm.z) ? 1 : 2);
  double sign = (ax == 0 ? nrm.x : ax == 1 ? nrm.y : nrm.z) > 0 ? 1 : -1;
  p->m = p->npos = 0;
  p->x = malloc((size_t)n * 2 * sizeof *p->x);
  p->src = malloc((size_t)n * sizeof *p->src);
  p->pid = malloc((size_t)n * sizeof *p->pid);
  p->by_pos = malloc((size_t)n * sizeof *p->by_pos);
  p->back = malloc((size_t)n * sizeof *p->back);
  if (!p->x || !p->src || !p->pid || !p->by_pos || !p->back) return -1;
  for (int i = 0; i < n; i++) {
    const double c[3] = {v[i].x, v[i].y, v[i].z};
    int k = p->m;
    p->x[2 * k] = c[(ax + 1) % 3];
    p->x[2 * k + 1] = sign * c[(ax + 2) % 3];
    p->src[k] = i;
    if (k == 0 || !same_xy(p->x, k, k - 1)) p->m++;
  }
  while (p->m > 1 && same_xy(p->x, p->m - 1, 0)) p->m--;
  return 1;
}

typedef struct pos_key {
  double x, y;
  int k;
} pos_key;

static int cmp_pos(const void *pa, const void *pb) {
  const pos_key *a = pa, *b = pb;
  if (a->x != b->x) return a->x < b->x ? -1 : 1;
  if (a->y != b->y) return a->y < b->y ? -1 : 1;
  return (a->k > b->k) - (a->k < b->k);
}

/* Numbers the distinct positions (p->pid, p->npos, p->by_pos) by sorting: O(m log m). 1, or -1
 * when out of memory. */
static int number_positions(flat_poly *p) {
  pos_key *key = malloc((size_t)p->m * sizeof *key);
  if (!key) return -1;
  for (int k = 0; k < p->m; k++) key[k] = (pos_key){p->x[2 * k], p->x[2 * k + 1], k};
  qsort(key, (size_t)p->m, sizeof *key, cmp_pos);
  p->npos = 0;
  for (int r = 0; r < p->m; r++) {
    if (r > 0 && (key[r].x != key[r - 1].x || key[r].y != key[r - 1].y)) p->npos++;
    p->pid[key[r].k] = p->npos;
    p->by_pos[r] = key[r].k;
  }
  p->npos++;
  free(key);
  return 1;
}

typedef struct edge_key {
  int lo, hi, k; /* the edge's two position numbers, lower first, and the edge */
} edge_key;

static int cmp_edge(const void *pa, const void *pb) {
  const edge_key *a = pa, *b = pb;
  if (a->lo != b->lo) return a->lo < b->lo ? -1 : 1;
  if (a->hi != b->hi) return a->hi < b->hi ? -1 : 1;
  return (a->k > b->k) - (a->k < b->k);
}

/* Pairs the traversals of each bridge (p->back) and checks that bridges are the only way the
 * polygon revisits a position: every segment is traversed once, or twice the opposite ways and
 * not one right after the other (that would be a spike, enclosing nothing), and a position is
 * visited once plus once per bridge ending there. A square written twice over, a side traversed
 * three times or two loops touching at a vertex fail. 1, 0 when they fail, -1 when out of memory.
 * O(m log m). */
static int find_bridges(flat_poly *p) {
  const int m = p->m;
  edge_key *e = malloc((size_t)m * sizeof *e);
  int *extra = calloc((size_t)p->npos, sizeof *extra); /* visits minus bridges ending there */
  int ok = e && extra ? 1 : -1;
  for (int k = 0; ok > 0 && k < m; k++) {
    int a = p->pid[k], b = p->pid[(k + 1) % m];
    e[k] = (edge_key){a < b ? a : b, a < b ? b : a, k};
    p->back[k] = -1;
    extra[a]++;
  }
  if (ok > 0) qsort(e, (size_t)m, sizeof *e, cmp_edge);
  for (int g = 0, h; ok > 0 && g < m; g = h) {
    for (h = g + 1; h < m && e[h].lo == e[g].lo && e[h].hi == e[g].hi;) h++;
    if (h - g == 1) continue;
    int k1 = e[g].k, k2 = e[g + 1].k; /* k1 < k2 */
    if (h - g > 2 || p->pid[k1] == p->pid[k2] || k2 == k1 + 1 || (k1 == 0 && k2 == m - 1)) {
      ok = 0;
    } else {
      p->back[k1] = k2;
      p->back[k2] = k1;
      extra[p->pid[k1]]--;
      extra[p->pid[k2]]--;
    }
  }
  for (int q = 0; ok > 0 && q < p->npos; q++)
    if (extra[q] != 1) ok = 0;
  free(e);
  free(extra);
  return ok;
}

/* 1 if a and b have opposite signs (neither zero). */
static int opposite(double a, double b) { return (a > 0 && b < 0) || (a < 0 && b > 0); }

/* 1 if vertex r lies in the bounding box of edge (a, b); with orient(a, b, r) == 0: on it. */
static int in_box(const double *x, int a, int b, int r) {
  for (int t = 0; t < 2; t++)
    if (x[2 * r + t] < fmin(x[2 * a + t], x[2 * b + t]) ||
        x[2 * r + t] > fmax(x[2 * a + t], x[2 * b + t]))
      return 0;
  return 1;
}

/* 1 if edges (a, b) and (c, d), on one line, share at most an end point. */
static int collinear_apart(const double *x, int a, int b, int c, int d) {
  int t = fabs(x[2 * b] - x[2 * a]) >= fabs(x[2 * b + 1] - x[2 * a + 1]) ? 0 : 1;
  double lo = fmax(fmin(x[2 * a + t], x[2 * b + t]), fmin(x[2 * c + t], x[2 * d + t]));
  double hi = fmin(fmax(x[2 * a + t], x[2 * b + t]), fmax(x[2 * c + t], x[2 * d + t]));
  return hi <= lo;
}

/* 1 if edges k and l meet nowhere but at end positions they share: no crossing, no end of one
 * on the inside of the other (a vertex touching an edge), no overlap along a common line. */
static int edges_apart(const flat_poly *p, int k, int l) {
  const double *x = p->x;
  const int *pid = p->pid;
  const int a = k, b = (k + 1) % p->m, c = l, d = (l + 1) % p->m;
  for (int t = 0; t < 2; t++) /* bounding boxes apart: the common case, and cheap */
    if (fmax(x[2 * a + t], x[2 * b + t]) < fmin(x[2 * c + t], x[2 * d + t]) ||
        fmax(x[2 * c + t], x[2 * d + t]) < fmin(x[2 * a + t], x[2 * b + t]))
      return 1;
  double oc = orient(x, a, b, c), od = orient(x, a, b, d);
  if (oc == 0 && od == 0) return collinear_apart(x, a, b, c, d);
  double oa = orient(x, c, d, a), ob = orient(x, c, d, b);
  if (opposite(oc, od) && opposite(oa, ob)) return 0; /* they cross */
  int shared_c = pid[c] == pid[a] || pid[c] == pid[b];
  int shared_d = pid[d] == pid[a] || pid[d] == pid[b];
  int shared_a = pid[a] == pid[c] || pid[a] == pid[d];
  int shared_b = pid[b] == pid[c] || pid[b] == pid[d];
  return !((oc == 0 && !shared_c && in_box(x, a, b, c)) ||
           (od == 0 && !shared_d && in_box(x, a, b, d)) ||
           (oa == 0 && !shared_a && in_box(x, c, d, a)) ||
           (ob == 0 && !shared_b && in_box(x, c, d, b)));
}

/* 1 if no two edges meet except consecutive ones at their common vertex, edges at a revisited
 * position at that position, and a bridge's two traversals (one segment). O(m^2). */
static int edges_meet_at_ends(const flat_poly *p) {
  for (int k = 0; k < p->m; k++)
    for (int l = k + 1; l < p->m; l++)
      if (p->back[k] != l && !edges_apart(p, k, l)) return 0;
  return 1;
}

/* 1 if the direction from vertex 'at' to vertex w lies strictly inside the counter-clockwise turn
 * from the direction at -> u to the direction at -> t (w, u and t may be vertices at other visits
 * of at's position: only directions count). */
static int inside_turn(const double *x, int at, int u, int t, int w) {
  double ut = orient(x, at, u, t);
  if (ut > 0) return orient(x, at, u, w) > 0 && orient(x, at, w, t) > 0;
  if (ut < 0) return !(orient(x, at, t, w) >= 0 && orient(x, at, w, u) >= 0); /* over half a turn */
  double dot = (x[2 * u] - x[2 * at]) * (x[2 * t] - x[2 * at]) +
               (x[2 * u + 1] - x[2 * at + 1]) * (x[2 * t + 1] - x[2 * at + 1]);
  return dot < 0 && orient(x, at, u, w) > 0; /* half a turn; a spike (dot > 0) has no edges */
}

/* 1 if the polygon's passes through each revisited position do not cross there: no edge of one
 * visit starts strictly inside the turn of another (the polygon's inside at a visit is the turn
 * from its outgoing edge counter-clockwise to its incoming one). A keyhole that leaves a vertex
 * for two holes must take the one nearer the incoming edge first; in the other order the two
 * passes cross at the vertex. O(visits^2) per position. */
static int passes_apart(const flat_poly *p) {
  const int m = p->m;
  for (int g = 0, h; g < m; g = h) {
    for (h = g + 1; h < m && p->pid[p->by_pos[h]] == p->pid[p->by_pos[g]];) h++;
    for (int r = g; r < h; r++) {
      int j = p->by_pos[r], out = (j + 1) % m, in = (j + m - 1) % m;
      for (int q = g; q < h; q++) {
        int k = p->by_pos[q];
        if (q != r && (inside_turn(p->x, j, out, in, (k + 1) % m) ||
                       inside_turn(p->x, j, out, in, (k + m - 1) % m)))
          return 0;
      }
    }
  }
  return 1;
}

/* 1 if vertex j, at the position of corner 'at' of counter-clockwise triangle (at, nx, pv), has
 * an edge that starts into the triangle: then the polygon passes through that corner again and
 * into the triangle, which is no ear. */
static int enters_corner(const double *x, const int *next, const int *prev, int j, int at, int nx,
                         int pv) {
  return inside_turn(x, at, nx, pv, prev[j]) || inside_turn(x, at, nx, pv, next[j]);
}

/* 1 if triangle (a, i, c) of the remaining polygon is an ear: it turns left at i, and no other
 * vertex lies inside it or on its sides. A vertex at the position of a corner (the other visit
 * of a bridge's end) is not inside; it blocks the ear only when one of its edges starts into the
 * triangle. */
static int is_ear(const flat_poly *p, const int *next, const int *prev, int a, int i, int c) {
  const double *x = p->x;
  const int *pid = p->pid;
  if (!(orient(x, a, i, c) > 0)) return 0;
  for (int j = next[c]; j != a; j = next[j]) {
    if (pid[j] == pid[a] || pid[j] == pid[i] || pid[j] == pid[c]) {
      int at = pid[j] == pid[a] ? a : pid[j] == pid[i] ? i : c;
      int nx = at == a ? i : at == i ? c : a, pv = at == a ? c : at == i ? a : i;
      if (enters_corner(x, next, prev, j, at, nx, pv)) return 0;
    } else if (orient(x, a, i, j) >= 0 && orient(x, i, c, j) >= 0 && orient(x, c, a, j) >= 0) {
      return 0;
    }
  }
  return 1;
}

/* Ear clipping of the checked polygon into m - 2 triangles (indices into the input, three per
 * triangle, counter-clockwise seen from the front) in 'tri', in the standard order: walking
 * round the polygon and cutting every ear met. 1, 0 when a whole turn finds no ear (the
 * polygon is not simple), -1 when out of memory. O(m^2) for the usual polygons. */
static int ear_clip(const flat_poly *p, int *tri) {
  const int m = p->m;
  int *next = malloc((size_t)m * sizeof *next), *prev = malloc((size_t)m * sizeof *prev);
  int ok = next && prev ? 1 : -1;
  for (int k = 0; ok > 0 && k < m; k++) {
    next[k] = (k + 1) % m;
    prev[k] = (k + m - 1) % m;
  }
  int left = m, i = 0, nt = 0, miss = 0;
  while (ok > 0 && left > 3) {
    const int a = prev[i], c = next[i];
    if (is_ear(p, next, prev, a, i, c)) {
      tri[3 * nt] = p->src[a], tri[3 * nt + 1] = p->src[i], tri[3 * nt + 2] = p->src[c];
      nt++;
      next[a] = c;
      prev[c] = a;
      left--;
      miss = 0;
      i = c;
    } else if (++miss > left) {
      ok = 0; /* a whole turn without an ear: not a simple polygon */
    } else {
      i = c;
    }
  }
  if (ok > 0) {
    tri[3 * nt] = p->src[prev[i]], tri[3 * nt + 1] = p->src[i], tri[3 * nt + 2] = p->src[next[i]];
  }
  free(next);
  free(prev);
  return ok;
}

/* Triangulates a planar non-convex polygon v[0..n) with normal 'nrm' into at most n - 2
 * triangles in 'tri' (indices into v). Accepted: simple polygons and keyhole polygons whose only
 * contacts with themselves are bridges. find_bridges, edges_meet_at_ends and passes_apart
 * together mean that the two traversals of every bridge can be pulled a little apart, leaving
 * a simple polygon: the polygon covers each point of its region once. That fails for a hole
 * wound the same way as the outside (the passes through the bridge's end on the hole cross
 * there), for a bridge that leaves the region, and for edges that cross or touch elsewhere.
 * Returns the number of triangles, 0 when not simple, -1 when out of memory. O(n^2). */
static int triangulate(const hr_vec3 *v, int n, hr_vec3 nrm, int *tri) {
  flat_poly p;
  int r = flat_init(&p, v, n, nrm);
  if (r > 0 && p.m < 3) r = 0;
  if (r > 0) r = number_positions(&p);
  if (r > 0) r = find_bridges(&p);
  if (r > 0) r = edges_meet_at_ends(&p);
  if (r > 0) r = passes_apart(&p);
  if (r > 0) r = ear_clip(&p, tri);
  int nt = r > 0 ? p.m - 2 : r;
  flat_free(&p);
  return nt;
}

hr_status hr_scene_add_polygon(hr_scene *s, const hr_vec3 *v, int n, int material,
                               hr_poly_result *res) {
  hr_status st = add_polygon(s, v, n, material, res);
  if (st != HR_OK) return st;
  if (*res == HR_POLY_NONPLANAR || *res == HR_POLY_NOT_SIMPLE) return HR_OK; /* caller errs */
  if (*res == HR_POLY_ADDED && !record_object(s)) return HR_ERR_NOMEM;
  int ok = *res == HR_POLY_ADDED ? push_input(s, s->npolys - 1, HR_INPUT_SOLVED)
                                 : push_input(s, -1, HR_INPUT_DEGENERATE);
  return ok ? HR_OK : HR_ERR_NOMEM;
}

static hr_status add_polygon(hr_scene *s, const hr_vec3 *v, int n, int material,
                             hr_poly_result *res) {
  *res = HR_POLY_DEGENERATE;
  if (n < 3 || material < 0 || material >= s->nmats) return HR_ERR_INVALID;
  for (int i = 0; i < n; i++)
    if (!(fabs(v[i].x) <= HR_COORD_MAX && fabs(v[i].y) <= HR_COORD_MAX &&
          fabs(v[i].z) <= HR_COORD_MAX))
      return HR_ERR_INVALID;
  hr_vec3 nn = v3_newell(v, n);
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
    int ok02 = v3_dot(v3_newell(a, 3), nrm) > 0 && v3_dot(v3_newell(b, 3), nrm) > 0;
    int ok13 = v3_dot(v3_newell(c, 3), nrm) > 0 && v3_dot(v3_newell(d, 3), nrm) > 0;
    if (!ok02 && !ok13) { /* a bow-tie: it crosses itself */
      *res = HR_POLY_NOT_SIMPLE;
      return HR_OK;
    }
    int use13 = ok13 && (!ok02 || v3_len(v3_sub(v[1], v[3])) < v3_len(v3_sub(v[0], v[2])));
    if (use13) {
      st = push_surface(s, c, 3, material, poly, &added);
      if (st == HR_OK) st = push_surface(s, d, 3, material, poly, &added);
    } else {
      st = push_surface(s, a, 3, material, poly, &added);
      if (st == HR_OK) st = push_surface(s, b, 3, material, poly, &added);
    }
  } else if (is_convex(v, n, nrm)) {
    for (int i = 1; i + 1 < n && st == HR_OK; i++) {
      hr_vec3 t[3] = {v[0], v[i], v[i + 1]};
      st = push_surface(s, t, 3, material, poly, &added);
    }
  } else {
    /* Not convex: ear clipping; the ears must cover exactly the polygon's area (outer
     * boundary less holes), a last check that every triangle faces the front. */
    if (n > HR_EAR_MAX) {
      *res = HR_POLY_NOT_SIMPLE;
      return HR_OK;
    }
    int *tri = malloc((size_t)(n - 2) * 3 * sizeof *tri);
    if (!tri) return HR_ERR_NOMEM;
    int nt = triangulate(v, n, nrm, tri);
    if (nt < 0) {
      free(tri);
      return HR_ERR_NOMEM;
    }
    double sum = 0;
    for (int k = 0; k < nt; k++) {
      hr_vec3 t[3] = {v[tri[3 * k]], v[tri[3 * k + 1]], v[tri[3 * k + 2]]};
      sum += 0.5 * v3_len(v3_newell(t, 3));
    }
    if (nt == 0 || fabs(sum - 0.5 * len) > 1e-9 * sum + AREA_TOL * size * size) {
      free(tri);
      *res = HR_POLY_NOT_SIMPLE;
      return HR_OK;
    }
    for (int k = 0; k < nt && st == HR_OK; k++) {
      hr_vec3 t[3] = {v[tri[3 * k]], v[tri[3 * k + 1]], v[tri[3 * k + 2]]};
      st = push_surface(s, t, 3, material, poly, &added);
    }
    free(tri);
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

/* ---------------------------------------------------------------- automatic camera */

/* A tiny z-buffer that tells, per pixel, whether the nearest surface shows its front or its back:
 * enough to score candidate views with occlusion. */
#define ACAM_W 64
#define ACAM_H 48

typedef struct acam_buf {
  float invz[ACAM_W * ACAM_H]; /* 1/depth of the nearest surface, 0 = none */
  signed char side[ACAM_W * ACAM_H]; /* +1 front, -1 back, 0 none */
} acam_buf;

typedef struct acam_view {
  hr_vec3 eye, r, u, f; /* position and orthonormal basis (right, up, forward) */
  double focal;         /* pixels per unit of x/z */
  double znear;
} acam_view;

static int acam_setup(const hr_camera *c, double znear, acam_view *v) {
  v->eye = c->eye;
  v->f = v3_norm(v3_sub(c->at, c->eye));
  v->r = v3_cross(v->f, c->up);
  if (!(v3_len(v->r) > 1e-9)) return 0;
  v->r = v3_norm(v->r);
  v->u = v3_cross(v->r, v->f);
  v->focal = 0.5 * ACAM_H / tan(0.5 * c->fov_deg * M_PI / 180.0);
  v->znear = znear;
  return 1;
}

/* Rasterises a convex polygon given in camera space (x right, y up, z forward; all z >= znear). */
static void acam_raster(acam_buf *b, const acam_view *v, const hr_vec3 *q, int n, int side) {
  double sx[8], sy[8], iz[8];
  for (int i = 0; i < n; i++) {
    iz[i] = 1.0 / q[i].z;
    sx[i] = 0.5 * ACAM_W + q[i].x * iz[i] * v->focal;
    sy[i] = 0.5 * ACAM_H - q[i].y * iz[i] * v->focal;
  }
  for (int t = 1; t + 1 < n; t++) {
    int k[3] = {0, t, t + 1};
    double area = (sx[k[1]] - sx[k[0]]) * (sy[k[2]] - sy[k[0]]) -
                  (sx[k[2]] - sx[k[0]]) * (sy[k[1]] - sy[k[0]]);
    if (!(fabs(area) > 1e-12)) continue;
    double x0 = fmin(sx[k[0]], fmin(sx[k[1]], sx[k[2]]));
    double x1 = fmax(sx[k[0]], fmax(sx[k[1]], sx[k[2]]));
    double y0 = fmin(sy[k[0]], fmin(sy[k[1]], sy[k[2]]));
    double y1 = fmax(sy[k[0]], fmax(sy[k[1]], sy[k[2]]));
    int px0 = (int)fmax(0, floor(x0)), px1 = (int)fmin(ACAM_W - 1, ceil(x1));
    int py0 = (int)fmax(0, floor(y0)), py1 = (int)fmin(ACAM_H - 1, ceil(y1));
    for (int py = py0; py <= py1; py++)
      for (int px = px0; px <= px1; px++) {
        double cx = px + 0.5, cy = py + 0.5, w[3];
        for (int e = 0; e < 3; e++) {
          int i = k[(e + 1) % 3], j = k[(e + 2) % 3];
          w[e] = ((sx[j] - sx[i]) * (cy - sy[i]) - (sy[j] - sy[i]) * (cx - sx[i])) / area;
        }
        if (w[0] < 0 || w[1] < 0 || w[2] < 0) continue;
        float z = (float)(w[0] * iz[k[0]] + w[1] * iz[k[1]] + w[2] * iz[k[2]]);
        int pi = py * ACAM_W + px;
        if (z > b->invz[pi]) {
          b->invz[pi] = z;
          b->side[pi] = (signed char)side;
        }
      }
  }
}

/* Renders all surfaces from 'cam' and counts the pixels showing fronts and backs; '*open' gets
 * the sum over front pixels minus the sum over back pixels of their depth (an open view that
 * sees far scores higher than one blocked by a near object). 0 if the camera is unusable. */
static int acam_count(const hr_scene *s, const hr_camera *cam, double znear, acam_buf *b,
                      int *front, int *back, double *open) {
  acam_view v;
  *front = *back = 0;
  *open = 0;
  if (!acam_setup(cam, znear, &v)) return 0;
  memset(b, 0, sizeof *b);
  for (int i = 0; i < s->nsurfs; i++) {
    const hr_surface *f = &s->surfs[i];
    double facing = v3_dot(f->normal, v3_sub(v.eye, f->v[0]));
    if (facing == 0) continue; /* edge-on */
    hr_vec3 q[4], c[8];
    int in = 0;
    for (int k = 0; k < f->nverts; k++) {
      hr_vec3 d = v3_sub(f->v[k], v.eye);
      q[k] = v3(v3_dot(d, v.r), v3_dot(d, v.u), v3_dot(d, v.f));
      in += q[k].z >= znear;
    }
    if (in == 0) continue;
    int n = 0; /* clip against z = znear (Sutherland-Hodgman, one plane) */
    for (int k = 0; k < f->nverts; k++) {
      hr_vec3 a = q[k], bb = q[(k + 1) % f->nverts];
      int ia = a.z >= znear, ib = bb.z >= znear;
      if (ia) c[n++] = a;
      if (ia != ib) c[n++] = v3_lerp(a, bb, (znear - a.z) / (bb.z - a.z));
    }
    if (n >= 3) acam_raster(b, &v, c, n, facing > 0 ? 1 : -1);
  }
  for (int p = 0; p < ACAM_W * ACAM_H; p++) {
    *front += b->side[p] > 0;
    *back += b->side[p] < 0;
    if (b->side[p]) *open += b->side[p] / (double)b->invz[p];
  }
  return 1;
}

/* Chooses a camera for a scene without one. The heuristic:
 *  - Up is +y, unless the scene is clearly z-up: its z extent is not larger than its y extent
 *    (scenes are usually flatter vertically) and at least 1.5 times as much surface area faces
 *    along +-z as along +-y (floors, ceilings and table tops are the largest surfaces facing
 *    along the up axis); then up is +z. "Horizontal" below means perpendicular to up.
 *  - Outside views: the camera looks at the centre of the bounding box from one of the 4
 *    horizontal axis directions and the 4 horizontal diagonals, each from 10 degrees above the
 *    horizon and once more looking down from 35 degrees, at the distance where the bounding
 *    sphere fits a 50 degree field of view. Each candidate is scored by what it would see:
 *    the scene is rendered into a 64x48 z-buffer and the score is the number of pixels showing
 *    the front of a surface minus those showing a back (surfaces are one-sided, backs look dark
 *    and usually mean the camera is on the wrong side of a wall). The first best candidate wins
 *    (order: +z, +x, -z, -x for y-up (+y, +x, -y, -x for z-up), then the diagonals; 10 degrees
 *    before 35). An open box is thus seen through its opening.
 *  - Inside views: when even the best outside view shows more backs than fronts (a closed room:
 *    every wall faces inwards and occludes the rest from outside), the camera goes inside the
 *    bounding box, near one of its 4 upper corners: 15% of the extent in from both walls, at 60%
 *    of the height, looking at the centre of the floor plan at 30% of the height with a 70
 *    degree field of view. The corner whose view sees the most fronts and the fewest backs,
 *    each pixel weighted by its depth, wins (a corner inside an object sees backs, one right
 *    behind an object sees little of the room); it is used only if it shows more fronts minus
 *    backs than the best outside view.
 * O(surfaces) per candidate (20 candidates). */
void hr_scene_auto_camera(const hr_scene *s, hr_camera *cam) {
  hr_vec3 lo, hi;
  hr_scene_bounds(s, &lo, &hi);
  if (s->nsurfs == 0 || !(hi.x >= lo.x && hi.y >= lo.y && hi.z >= lo.z)) {
    lo = v3(-1, -1, -1);
    hi = v3(1, 1, 1);
  }
  hr_vec3 c = v3_scale(v3_add(lo, hi), 0.5), ext = v3_sub(hi, lo);
  double r = 0.5 * v3_len(ext);
  if (!(r > 0)) r = 1;
  /* up axis */
  double ay = 0, az = 0;
  for (int i = 0; i < s->nsurfs; i++) {
    const hr_surface *f = &s->surfs[i];
    if (fabs(f->normal.y) > 0.9) ay += f->area;
    if (fabs(f->normal.z) > 0.9) az += f->area;
  }
  int zup = ext.z <= ext.y && az > 1.5 * ay;
  hr_vec3 up = zup ? v3(0, 0, 1) : v3(0, 1, 0);
  hr_vec3 h1 = zup ? v3(0, 1, 0) : v3(0, 0, 1); /* first horizontal direction (+z or +y) */
  hr_vec3 h2 = v3(1, 0, 0);
  double hup = zup ? ext.z : ext.y;
  double lo_up = zup ? lo.z : lo.y;

  /* outside views fit the bounding sphere into a 50 degree field of view */
  double dist = r / tan(25 * M_PI / 180) * 1.05;
  /* fallback (no memory, or no usable candidate): the fixed diagonal */
  hr_vec3 diag = zup ? v3(0.55, 1.0, 0.45) : v3(0.55, 0.45, 1.0);
  hr_camera best = {v3_add(c, v3_scale(v3_norm(diag), dist)), c, up, 50};
  acam_buf *buf = malloc(sizeof *buf);
  if (!buf) {
    *cam = best;
    return;
  }
  double znear = 1e-4 * r;
  int best_score = INT32_MIN, best_front = 0, best_back = 0;
  /* outside candidates */
  const double dirs[8][2] = {{1, 0}, {0, 1}, {-1, 0}, {0, -1}, {1, 1}, {1, -1}, {-1, 1}, {-1, -1}};
  const double elev[2] = {10, 35};
  for (int e = 0; e < 2; e++)
    for (int d = 0; d < 8; d++) {
      hr_vec3 hd = v3_norm(v3_add(v3_scale(h1, dirs[d][0]), v3_scale(h2, dirs[d][1])));
      double el = elev[e] * M_PI / 180;
      hr_vec3 dir = v3_add(v3_scale(hd, cos(el)), v3_scale(up, sin(el)));
      hr_camera cand = {v3_add(c, v3_scale(dir, dist)), c, up, 50};
      int fr, bk;
      double op;
      if (!acam_count(s, &cand, znear, buf, &fr, &bk, &op)) continue;
      if (fr - bk > best_score) {
        best_score = fr - bk;
        best_front = fr;
        best_back = bk;
        best = cand;
      }
    }
  if (best_front < best_back) {
    /* inside candidates: the 4 upper corners */
    int in_score = INT32_MIN;
    double in_open = -INFINITY;
    hr_camera in_best = best;
    for (int k = 0; k < 4; k++) {
      double t1 = (k & 1) ? 0.85 : 0.15, t2 = (k & 2) ? 0.85 : 0.15;
      /* horizontal coordinates along h1 and h2 */
      double l1 = v3_dot(lo, h1), e1 = v3_dot(ext, h1), l2 = v3_dot(lo, h2), e2 = v3_dot(ext, h2);
      hr_vec3 eye = v3_add(v3_scale(h1, l1 + t1 * e1), v3_scale(h2, l2 + t2 * e2));
      eye = v3_add(eye, v3_scale(up, lo_up + 0.6 * hup));
      hr_vec3 at = v3_add(v3_scale(h1, v3_dot(c, h1)), v3_scale(h2, v3_dot(c, h2)));
      at = v3_add(at, v3_scale(up, lo_up + 0.3 * hup));
      hr_camera cand = {eye, at, up, 70};
      int fr, bk;
      double op;
      if (!acam_count(s, &cand, znear, buf, &fr, &bk, &op)) continue;
      if (op > in_open) {
        in_open = op;
        in_score = fr - bk;
        in_best = cand;
      }
    }
    if (in_score > best_score) best = in_best;
  }
  free(buf);
  *cam = best;
}
