/* elem.c: element quadtrees (paper 2.2: "patchtree", "toppatch", "elements"). Each surface is the
 * root of a tree; subdivision splits a quad into 4 quads at its edge midpoints (in the bilinear
 * parameter space) and a triangle into 4 triangles at its edge midpoints. An element's corners
 * are integer lattice points of its surface (see hr_leaf in hrad.h), so its geometry follows
 * from (surface, lattice corners) alone, and its global id from (surface, path). */
#include "cluster.h"
#include "solver_impl.h"
#include "vec.h"

#include <assert.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* World position of lattice point (a, b) on surface 'f'. */
static hr_vec3 lattice_point(const hr_surface *f, uint32_t a, uint32_t b) {
  double u = (double)a / HR_LATTICE, v = (double)b / HR_LATTICE;
  if (f->nverts == 4) {
    hr_vec3 p0 = v3_lerp(f->v[0], f->v[1], u), p1 = v3_lerp(f->v[3], f->v[2], u);
    return v3_lerp(p0, p1, v);
  }
  return v3_add(f->v[0], v3_add(v3_scale(v3_sub(f->v[1], f->v[0]), u),
                                v3_scale(v3_sub(f->v[2], f->v[0]), v)));
}

/* Fills world corners, centroid and area from the lattice corners. */
static void elem_geometry(const hr_scene *sc, hr_elem *e) {
  const hr_surface *f = &sc->surfs[e->surf];
  int n = f->nverts;
  hr_vec3 c = {0, 0, 0};
  for (int k = 0; k < n; k++) {
    e->p[k] = lattice_point(f, e->lat[k][0], e->lat[k][1]);
    c = v3_add(c, e->p[k]);
  }
  if (n == 3) e->p[3] = e->p[2];
  e->c = v3_scale(c, 1.0 / n);
  hr_vec3 cr = n == 4 ? v3_cross(v3_sub(e->p[2], e->p[0]), v3_sub(e->p[3], e->p[1]))
                      : v3_cross(v3_sub(e->p[1], e->p[0]), v3_sub(e->p[2], e->p[0]));
  e->area = 0.5 * v3_len(cr);
}

/* ---------------------------------------------------------------- gid -> idx */

static void gmap_put(hr_solver *s, uint64_t gid, int32_t idx) {
  size_t i = (size_t)u64_mix(gid) & (size_t)(s->gcap - 1);
  while (s->gkey[i] && s->gkey[i] != gid) i = (i + 1) & (size_t)(s->gcap - 1);
  s->gkey[i] = gid; /* gids are never 0: the heap index has a sentinel bit */
  s->gval[i] = idx;
}

int32_t hr_elem_find(const hr_solver *s, uint64_t gid) {
  size_t i = (size_t)u64_mix(gid) & (size_t)(s->gcap - 1);
  while (s->gkey[i]) {
    if (s->gkey[i] == gid) return s->gval[i];
    i = (i + 1) & (size_t)(s->gcap - 1);
  }
  return -1;
}

/* At least 'slots' slots (rounded up to a power of 2), rehashing the elements held. */
static int gmap_grow(hr_solver *s, int64_t slots) {
  if (slots <= s->gcap) return 1;
  int64_t nc = 64;
  while (nc < slots) nc *= 2;
  uint64_t *k = calloc((size_t)nc, sizeof *k);
  int32_t *v = malloc((size_t)nc * sizeof *v);
  if (!k || !v) {
    free(k), free(v);
    return 0;
  }
  free(s->gkey), free(s->gval);
  s->gkey = k, s->gval = v, s->gcap = nc;
  for (int64_t e = 0; e < s->nel; e++) gmap_put(s, s->el[e].gid, (int32_t)e);
  return 1;
}

/* ---------------------------------------------------------------- ownership */

int32_t hr_owner_of(const hr_solver *s, uint64_t gid) {
  if (!s->dist) return 0;
  if (s->own_seed) { /* splitmix64 of (seed, gid) */
    uint64_t z = s->own_seed ^ (gid * UINT64_C(0x9e3779b97f4a7c15));
    z = (z ^ (z >> 30)) * UINT64_C(0xbf58476d1ce4e5b9);
    z = (z ^ (z >> 27)) * UINT64_C(0x94d049bb133111eb);
    return (int32_t)((z ^ (z >> 31)) % (uint64_t)s->nranks);
  }
  const uint64_t pathmask = (UINT64_C(1) << HR_GID_PATH_BITS) - 1, top = gid & ~pathmask;
  for (uint64_t h = gid & pathmask; h >= 1 && s->nomap > 0; h >>= 2) {
    int64_t lo = 0, hi = s->nomap; /* binary search of top | h */
    const uint64_t g = top | h;
    while (lo < hi) {
      int64_t m = (lo + hi) / 2;
      if (s->omap[m][0] < g) lo = m + 1;
      else hi = m;
    }
    if (lo < s->nomap && s->omap[lo][0] == g) return (int32_t)s->omap[lo][1];
  }
  return s->rootown[gid >> HR_GID_PATH_BITS];
}

void hr_owners_recompute(hr_solver *s) {
  for (int64_t e = 0; e < s->nel; e++) s->eown[e] = hr_owner_of(s, s->el[e].gid);
}

/* ---------------------------------------------------------------- storage */

static int reserve(hr_solver *s, int64_t need) {
  if (need <= s->cap_el) return 1;
  int64_t nc = s->cap_el ? s->cap_el : 64;
  while (nc < need) nc *= 2;
  hr_elem *el = realloc(s->el, (size_t)nc * sizeof *el);
  if (!el) return 0;
  s->el = el;
  double(*B)[3] = realloc(s->B, (size_t)nc * sizeof *B);
  if (!B) return 0;
  s->B = B;
  double(*Bs)[3] = realloc(s->Bs, (size_t)nc * sizeof *Bs);
  if (!Bs) return 0;
  s->Bs = Bs;
  double(*G)[3] = realloc(s->G, (size_t)nc * sizeof *G);
  if (!G) return 0;
  s->G = G;
  double *Gu = realloc(s->Gu, (size_t)nc * sizeof *Gu);
  if (!Gu) return 0;
  s->Gu = Gu;
  double *Gf = realloc(s->Gf, (size_t)nc * sizeof *Gf);
  if (!Gf) return 0;
  s->Gf = Gf;
  double *Gv = realloc(s->Gv, (size_t)nc * sizeof *Gv);
  if (!Gv) return 0;
  s->Gv = Gv;
  float *er = realloc(s->erays, (size_t)nc * sizeof *er);
  if (!er) return 0;
  s->erays = er;
  double(*rho)[3] = realloc(s->rho, (size_t)nc * sizeof *rho);
  if (!rho) return 0;
  s->rho = rho;
  double *rm = realloc(s->rho_max, (size_t)nc * sizeof *rm);
  if (!rm) return 0;
  s->rho_max = rm;
  double *br = realloc(s->bref, (size_t)nc * sizeof *br);
  if (!br) return 0;
  s->bref = br;
  double(*hi)[2][3] = realloc(s->hist, (size_t)nc * sizeof *hi);
  if (!hi) return 0;
  s->hist = hi;
  double *bv = realloc(s->bvar, (size_t)nc * sizeof *bv);
  if (!bv) return 0;
  s->bvar = bv;
  double *op = realloc(s->open, (size_t)nc * sizeof *op);
  if (!op) return 0;
  s->open = op;
  int32_t *ow = realloc(s->eown, (size_t)nc * sizeof *ow);
  if (!ow) return 0;
  s->eown = ow;
  uint8_t *sb = realloc(s->esub, (size_t)nc);
  if (!sb) return 0;
  s->esub = sb;
  if (!gmap_grow(s, 2 * nc)) return 0;

  s->cap_el = nc;
  return 1;
}

hr_status hr_elem_init(hr_solver *s) {
  const hr_scene *sc = s->scene;
  if (!reserve(s, sc->nsurfs)) return HR_ERR_NOMEM;
  for (int i = 0; i < sc->nsurfs; i++) {
    hr_elem *e = &s->el[i];
    memset(e, 0, sizeof *e);
    e->gid = ((uint64_t)i << HR_GID_PATH_BITS) | 1u;
    s->eown[i] = 0; /* hr_solver_set_dist spreads them */
    s->esub[i] = 0;
    gmap_put(s, e->gid, i);
    e->surf = i;
    e->parent = -1;
    e->child = -1;
    e->depth = 0;
    uint32_t L = HR_LATTICE;
    if (sc->surfs[i].nverts == 4) {
      uint32_t q[4][2] = {{0, 0}, {L, 0}, {L, L}, {0, L}};
      memcpy(e->lat, q, sizeof q);
    } else {
      uint32_t t[4][2] = {{0, 0}, {L, 0}, {0, L}, {0, L}};
      memcpy(e->lat, t, sizeof t);
    }
    elem_geometry(sc, e);
    const double *E = sc->mats[sc->surfs[i].material].emit;
    const double *R = sc->mats[sc->surfs[i].material].rho;
    for (int c = 0; c < 3; c++) {
      s->B[i][c] = s->Bs[i][c] = E[c];
      s->G[i][c] = 0;
      s->rho[i][c] = R[c];
    }
    s->rho_max[i] = fmax(R[0], fmax(R[1], R[2]));
    s->bref[i] = 1; /* set by push-pull */
    s->Gu[i] = s->Gf[i] = s->Gv[i] = 0;
    s->erays[i] = 0;
    s->bvar[i] = 0;
    memset(s->hist[i], 0, sizeof s->hist[i]);
    s->open[i] = 1; /* hr_elem_open, once the ray caster exists */
  }
  s->nel = sc->nsurfs;
  return HR_OK;
}

static void mid(const uint32_t a[2], const uint32_t b[2], uint32_t m[2]) {
  m[0] = (a[0] + b[0]) / 2;
  m[1] = (a[1] + b[1]) / 2;
}

hr_status hr_elem_subdivide(hr_solver *s, int32_t idx) {
  if (s->el[idx].child >= 0) return HR_OK;
  if (s->el[idx].depth >= HR_GID_DEPTH) return HR_OK;
  if (s->nel + 4 > INT32_MAX) return HR_ERR_TOO_BIG; /* element indices are int32 */
  if (!reserve(s, s->nel + 4)) return HR_ERR_NOMEM;
  hr_elem *p = &s->el[idx];
  int n = s->scene->surfs[p->surf].nverts;
  uint32_t ch[4][4][2];
  if (n == 4) {
    uint32_t m01[2], m12[2], m23[2], m30[2], mc[2];
    mid(p->lat[0], p->lat[1], m01);
    mid(p->lat[1], p->lat[2], m12);
    mid(p->lat[2], p->lat[3], m23);
    mid(p->lat[3], p->lat[0], m30);
    mid(p->lat[0], p->lat[2], mc);
    const uint32_t *q[4][4] = {{p->lat[0], m01, mc, m30},
                               {m01, p->lat[1], m12, mc},
                               {mc, m12, p->lat[2], m23},
                               {m30, mc, m23, p->lat[3]}};
    for (int k = 0; k < 4; k++)
      for (int j = 0; j < 4; j++) memcpy(ch[k][j], q[k][j], sizeof ch[k][j]);
  } else {
    uint32_t m01[2], m12[2], m20[2];
    mid(p->lat[0], p->lat[1], m01);
    mid(p->lat[1], p->lat[2], m12);
    mid(p->lat[2], p->lat[0], m20);
    const uint32_t *t[4][3] = {{p->lat[0], m01, m20},
                               {m01, p->lat[1], m12},
                               {m20, m12, p->lat[2]},
                               {m12, m20, m01}};
    for (int k = 0; k < 4; k++) {
      for (int j = 0; j < 3; j++) memcpy(ch[k][j], t[k][j], sizeof ch[k][j]);
      memcpy(ch[k][3], ch[k][2], sizeof ch[k][3]);
    }
  }
  int32_t first = (int32_t)s->nel;
  uint64_t surfbits = p->gid & ~((UINT64_C(1) << HR_GID_PATH_BITS) - 1);
  uint64_t heap = p->gid & ((UINT64_C(1) << HR_GID_PATH_BITS) - 1);
  for (int k = 0; k < 4; k++) {
    hr_elem *e = &s->el[first + k];
    memset(e, 0, sizeof *e);
    e->gid = surfbits | (heap * 4 + (uint64_t)k);
    e->surf = p->surf;
    e->parent = idx;
    e->child = -1;
    e->depth = p->depth + 1;
    memcpy(e->lat, ch[k], sizeof e->lat);
    elem_geometry(s->scene, e);
    for (int c = 0; c < 3; c++) {
      s->B[first + k][c] = s->B[idx][c];
      s->Bs[first + k][c] = s->Bs[idx][c];
      s->G[first + k][c] = 0;
      s->Gu[first + k] = s->Gf[first + k] = s->Gv[first + k] = 0;
      s->erays[first + k] = 0;
      s->rho[first + k][c] = s->rho[idx][c];
    }
    s->rho_max[first + k] = s->rho_max[idx];
    s->bref[first + k] = s->bref[idx];
    s->bvar[first + k] = 0;
    memset(s->hist[first + k], 0, sizeof s->hist[first + k]); /* new links: a new window */
    s->open[first + k] = s->open[idx]; /* hr_elem_open, after the round's subdivisions */
    s->eown[first + k] = hr_owner_of(s, e->gid);
    s->esub[first + k] = 0;
    gmap_put(s, e->gid, first + k);
  }
  p->child = first;
  s->nel += 4;
  return HR_OK;
}

int32_t hr_elem_ensure(hr_solver *s, uint64_t gid) {
  int32_t e = hr_elem_find(s, gid);
  if (e >= 0) return e;
  const uint64_t pathmask = (UINT64_C(1) << HR_GID_PATH_BITS) - 1;
  const uint64_t heap = gid & pathmask, surf = gid >> HR_GID_PATH_BITS;
  if (surf >= (uint64_t)s->scene->nsurfs || heap < 4) return -1;
  const int32_t parent = hr_elem_ensure(s, (gid & ~pathmask) | (heap >> 2));
  if (parent < 0) return parent;
  if (s->el[parent].child >= 0) return -1; /* its children exist, and 'gid' is none of them */
  if (s->el[parent].depth >= HR_GID_DEPTH) return -1;
  if (hr_elem_subdivide(s, parent) != HR_OK) return -2;
  return hr_elem_find(s, gid);
}

/* Points per side for the open fraction: roots are whole input surfaces, where a box standing on
 * a floor covers a small part; children are smaller. */
#define OPEN_M_ROOT 8
#define OPEN_M 4

void hr_elem_open(hr_solver *s, int64_t lo, int64_t hi) {
#pragma omp parallel for schedule(dynamic, 64) if (hi - lo > 256) num_threads(s->threads)
  for (int64_t e = lo; e < hi; e++) {
    if (e >= s->scene->nsurfs && !hr_owns(s, e)) continue; /* a ghost: its owner's business */
    /* A child of a wholly open element is wholly open. */
    if (s->el[e].parent >= 0 && s->open[s->el[e].parent] == 1) {
      s->open[e] = 1;
      continue;
    }
    const hr_ff_elem g = hr_elem_geom(s, &s->el[e]);
    const hr_vf_elem ve = {&g, s->el[e].gid, s->el[e].surf};
    s->open[e] = hr_vf_open(&s->vf, ve, s->el[e].parent < 0 ? OPEN_M_ROOT : OPEN_M);
  }
}

/* Keeps the elements with keep[e] != 0 (which must hold every root and whole sibling groups,
 * and be closed under parent), in their order; links (element and cluster links), the gid map
 * and the children of kept elements whose children go are renumbered or cut. Subscriptions
 * must be empty. */
void hr_elem_compact(hr_solver *s, const uint8_t *keep) {
  int32_t *nu = malloc((size_t)(s->nel > 0 ? s->nel : 1) * sizeof *nu);
  if (!nu) return; /* nothing lost but memory: keep everything */
  int32_t n = 0;
  for (int64_t e = 0; e < s->nel; e++) nu[e] = keep[e] ? n++ : -1;
  for (int64_t e = 0; e < s->nel; e++) {
    const int32_t d = nu[e];
    if (d < 0) continue;
    hr_elem el = s->el[e];
    el.parent = el.parent >= 0 ? nu[el.parent] : -1;
    el.child = el.child >= 0 ? nu[el.child] : -1; /* whole groups: the first decides */
    s->el[d] = el;
    memcpy(s->B[d], s->B[e], sizeof s->B[d]);
    memcpy(s->Bs[d], s->Bs[e], sizeof s->Bs[d]);
    memcpy(s->G[d], s->G[e], sizeof s->G[d]);
    memcpy(s->rho[d], s->rho[e], sizeof s->rho[d]);
    s->Gu[d] = s->Gu[e], s->Gf[d] = s->Gf[e], s->Gv[d] = s->Gv[e], s->rho_max[d] = s->rho_max[e];
    s->bref[d] = s->bref[e], s->open[d] = s->open[e], s->bvar[d] = s->bvar[e];
    s->erays[d] = s->erays[e];
    memcpy(s->hist[d], s->hist[e], sizeof s->hist[d]);
    s->eown[d] = s->eown[e], s->esub[d] = s->esub[e];
  }
  for (int64_t i = 0; i < s->nlinks; i++) {
    s->links[i].r = nu[s->links[i].r];
    s->links[i].s = nu[s->links[i].s];
    assert(s->links[i].r >= 0 && s->links[i].s >= 0);
  }
  hr_cluster_renumber(s, nu);
  free(nu);
  s->nel = n;
  memset(s->gkey, 0, (size_t)s->gcap * sizeof *s->gkey);
  for (int32_t e = 0; e < n; e++) gmap_put(s, s->el[e].gid, e);
  s->sorted = 0;
  s->nsorted = s->ndead = 0;
}

void hr_elem_prune(hr_solver *s) {
  uint8_t *keep = calloc((size_t)s->nel + 1, 1);
  if (!keep) return; /* nothing lost but memory */
  for (int64_t e = 0; e < s->nel; e++) keep[e] |= e < s->scene->nsurfs || hr_owns(s, e);
  for (int64_t i = 0; i < s->nlinks; i++) keep[s->links[i].s] = 1;
  hr_cluster_keep(s, keep); /* the elements at the ends of cluster links */
  for (int64_t e = 0; e < s->nel; e++) /* children of own elements and of sources */
    if (keep[e] && s->el[e].child >= 0)
      for (int k = 0; k < 4; k++) keep[s->el[e].child + k] |= 2;
  for (int64_t e = s->nel - 1; e >= 0; e--) /* ancestors (parents come first) */
    if (keep[e] && s->el[e].parent >= 0) keep[s->el[e].parent] |= 4;
  for (int64_t e = 0; e < s->nel; e++) { /* whole sibling groups */
    const int32_t c = s->el[e].child;
    if (c >= 0 && (keep[c] | keep[c + 1] | keep[c + 2] | keep[c + 3]))
      for (int k = 0; k < 4; k++) keep[c + k] |= 8;
  }
  hr_elem_compact(s, keep);
  free(keep);
}
