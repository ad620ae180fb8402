/* mesh.c: vertex reconstruction from the leaf elements (a smooth, crack-free triangle mesh per
 * input polygon), the automatic exposure, and the PLY and GLB writers. See output.h.
 *
 * The surfaces of one input polygon (a split quad's two triangles, a fan-split polygon's
 * triangles: equal hr_surface.poly) form one group, reconstructed as one smooth region. A hash
 * map from vertex keys to vertex ids collects the group's leaf corners and their area-weighted
 * mean radiosity. A key is exact, never a rounded position: a surface corner is keyed by its
 * corner id (corners at bitwise equal positions are one), a lattice point strictly inside an edge
 * that two surfaces of the group share by the shared edge and the point's lattice parameter along
 * it (measured from the edge's lower corner id; lattice points along a shared edge correspond 1:1
 * by that parameter), any other point by its surface and lattice coordinates. Leaves of the whole
 * group are then visited from the largest to the smallest: for each leaf edge the midpoint is
 * looked up recursively (a dyadic subdivision has a vertex strictly inside an edge only if it has
 * one at the edge's midpoint; along a shared edge this finds the other surface's vertices too),
 * which finds the T-vertices in order along the edge; each gets the mean of its two neighbours
 * along the edge, i.e. the exact linear interpolation of the larger leaf's edge end values.
 * Largest first guarantees that a leaf's own corners are final (a corner can only be a T-vertex
 * of a strictly larger leaf; leaf sizes are lattice lengths along the shared edges on both
 * sides). The leaf polygon (corners + T-vertices, convex) is then fanned. Vertices are never
 * shared between groups. */
#include "output.h"
#include "vec.h"

#include <errno.h>
#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ------------------------------------------------------------------ growable arrays */

static int grow_bytes(void **p, int64_t *cap, int64_t need, size_t sz) {
  if (need <= *cap) return 1;
  int64_t nc = *cap ? *cap : 64;
  while (nc < need) nc *= 2;
  void *q = realloc(*p, (size_t)nc * sz);
  if (!q) return 0;
  *p = q;
  *cap = nc;
  return 1;
}

/* ------------------------------------------------------------------ vertex hash map */

/* Open addressing with keys (kh, kl): kh is 32 bits, a 2-bit tag (never 0) and a 30-bit id, kl 64
 * bits. A slot is 16 bytes, hi = kh << 32 | value, lo = kl; hi = 0 marks an empty slot. */
typedef struct kslot {
  uint64_t hi, lo;
} kslot;

typedef struct kmap {
  kslot *slots;
  uint64_t mask; /* capacity - 1 (power of two) */
  int64_t alloc; /* allocated slots */
} kmap;

static inline uint64_t key_hash(uint32_t kh, uint64_t kl) {
  return u64_mix(kl ^ ((uint64_t)kh * 0x9e3779b97f4a7c15ull));
}

/* Prepares the map for up to 'n' keys (load <= 1/2); clears only the part used. */
static int kmap_reset(kmap *m, int64_t n) {
  int64_t cap = 16;
  while (cap < 2 * n) cap *= 2;
  if (cap > m->alloc) {
    free(m->slots);
    m->slots = malloc((size_t)cap * sizeof *m->slots);
    if (!m->slots) {
      m->alloc = 0;
      return 0;
    }
    m->alloc = cap;
  }
  m->mask = (uint64_t)cap - 1;
  memset(m->slots, 0, (size_t)cap * sizeof *m->slots);
  return 1;
}

static inline int32_t kmap_get(const kmap *m, uint32_t kh, uint64_t kl) {
  uint64_t i = key_hash(kh, kl) & m->mask;
  for (;;) {
    const kslot *sl = &m->slots[i];
    uint32_t h = (uint32_t)(sl->hi >> 32);
    if (h == kh && sl->lo == kl) return (int32_t)(uint32_t)sl->hi;
    if (h == 0) return -1;
    i = (i + 1) & m->mask;
  }
}

/* Returns the value (>= 0) of the key, inserting 'val' when absent (*inserted = 1). */
static inline int32_t kmap_put(kmap *m, uint32_t kh, uint64_t kl, int32_t val, int *inserted) {
  uint64_t i = key_hash(kh, kl) & m->mask;
  for (;;) {
    kslot *sl = &m->slots[i];
    uint32_t h = (uint32_t)(sl->hi >> 32);
    if (h == kh && sl->lo == kl) {
      *inserted = 0;
      return (int32_t)(uint32_t)sl->hi;
    }
    if (h == 0) {
      sl->hi = ((uint64_t)kh << 32) | (uint32_t)val;
      sl->lo = kl;
      *inserted = 1;
      return val;
    }
    i = (i + 1) & m->mask;
  }
}

/* ------------------------------------------------------------------ polygon groups */

/* A surface of the current group (the surfaces of one input polygon). Corners at the same world
 * position (bitwise equal coordinates: the scene copies the polygon's vertices into its pieces)
 * get one corner id; an edge between two corner ids that occurs in more than one surface is a
 * shared edge, parametrised from its smaller to its larger corner id. */
typedef struct gsurf {
  int surf;          /* scene surface index */
  int nv;            /* 3 or 4 */
  uint8_t emit;      /* material emits */
  int32_t corner[4]; /* corner ids */
  int32_t edge[4];   /* edge c (corner c -> corner c+1): shared edge id, or -1 */
  uint8_t rev[4];    /* 1 when edge c runs from the larger to the smaller corner id */
} gsurf;

/* Vertex key tags (top two bits of kh; ids below 2^30). */
#define TAG_CORNER (1u << 30) /* kh |= corner id, kl = 0 */
#define TAG_EDGE (2u << 30)   /* kh |= shared edge id, kl = lattice parameter along it */
#define TAG_SURF (3u << 30)   /* kh |= group surface index, kl = (a << 25) | b */
#define MAX_GROUP (1 << 27)   /* surfaces per group: 4 * MAX_GROUP corner and edge ids < 2^30 */

/* The key of lattice point (a, b) of group surface 'ls'. A point on an edge of the surface at
 * lattice parameter t (0..L from corner c to corner c+1; both parametrisations of a surface are
 * linear along every edge) is the same world point in every surface holding that edge. */
static inline void vkey(const gsurf *gs, int ls, uint32_t a, uint32_t b, uint32_t *kh,
                        uint64_t *kl) {
  const uint32_t L = HR_LATTICE;
  const gsurf *g = &gs[ls];
  int corner = -1, e = -1;
  uint32_t t = 0;
  if (b == 0) {
    if (a == 0)
      corner = 0;
    else if (a == L)
      corner = 1;
    else
      e = 0, t = a;
  } else if (g->nv == 3) {
    if (a == 0) {
      if (b == L)
        corner = 2;
      else
        e = 2, t = L - b;
    } else if ((uint64_t)a + b == L) {
      e = 1, t = b;
    }
  } else if (b == L) {
    if (a == 0)
      corner = 3;
    else if (a == L)
      corner = 2;
    else
      e = 2, t = L - a;
  } else if (a == 0) {
    e = 3, t = L - b;
  } else if (a == L) {
    e = 1, t = b;
  }
  if (corner >= 0) {
    *kh = TAG_CORNER | (uint32_t)g->corner[corner];
    *kl = 0;
  } else if (e >= 0 && g->edge[e] >= 0) {
    *kh = TAG_EDGE | (uint32_t)g->edge[e];
    *kl = g->rev[e] ? L - t : t;
  } else {
    *kh = TAG_SURF | (uint32_t)ls;
    *kl = ((uint64_t)a << 25) | b;
  }
}

/* ------------------------------------------------------------------ build state */

typedef struct build {
  hr_mesh *m;
  int64_t cap_v, cap_t;
  /* per-group scratch, indexed by local vertex id */
  double *val;  /* 3 per vertex: B */
  double *wsum; /* area weight sum */
  int32_t *vsf; /* scene surface whose parametrisation places the vertex */
  double *par;  /* 2 per vertex: lattice coordinates on that surface (centres not integral) */
  int64_t cap_l;
  int64_t nloc;
  /* ring of the current leaf polygon (local ids) */
  int32_t *ring;
  int64_t cap_ring, nring;
  int32_t *lcid; /* 4 per leaf of the group (in idx order): local ids of its corners */
  int64_t cap_lcid;
  kmap map; /* vertex keys -> local ids */
  /* the current group's surfaces, corner positions and shared edges */
  gsurf *gs;
  int64_t cap_gs;
  hr_vec3 *cpos;   /* corner positions */
  int32_t *ctab;   /* open-addressing table of corner ids */
  int32_t *ecount; /* surfaces holding each edge */
  int64_t cap_c, cap_ctab;
  kmap emap; /* (smaller corner id, larger corner id) -> edge id */
} build;

static double lum(const double *b) { return 0.2126 * b[0] + 0.7152 * b[1] + 0.0722 * b[2]; }

/* Point of surface 'f' at parameters (a, b) in [0,1] (exactly a vertex at a corner). */
static hr_vec3 surf_point(const hr_surface *f, double a, double b) {
  if (f->nverts == 4) {
    if (a == 0 && b == 0) return f->v[0];
    if (a == 1 && b == 0) return f->v[1];
    if (a == 1 && b == 1) return f->v[2];
    if (a == 0 && b == 1) return f->v[3];
    hr_vec3 p = v3_scale(f->v[0], (1 - a) * (1 - b));
    p = v3_add(p, v3_scale(f->v[1], a * (1 - b)));
    p = v3_add(p, v3_scale(f->v[2], a * b));
    return v3_add(p, v3_scale(f->v[3], (1 - a) * b));
  }
  if (a == 0 && b == 0) return f->v[0];
  if (a == 1 && b == 0) return f->v[1];
  if (a == 0 && b == 1) return f->v[2];
  hr_vec3 p = v3_add(f->v[0], v3_scale(v3_sub(f->v[1], f->v[0]), a));
  return v3_add(p, v3_scale(v3_sub(f->v[2], f->v[0]), b));
}

static int local_grow(build *bd, int64_t need) {
  if (need <= bd->cap_l) return 1;
  int64_t nc = bd->cap_l ? bd->cap_l : 256;
  while (nc < need) nc *= 2;
  double *v = realloc(bd->val, (size_t)nc * 3 * sizeof *v);
  if (!v) return 0;
  bd->val = v;
  double *w = realloc(bd->wsum, (size_t)nc * sizeof *w);
  if (!w) return 0;
  bd->wsum = w;
  int32_t *sf = realloc(bd->vsf, (size_t)nc * sizeof *sf);
  if (!sf) return 0;
  bd->vsf = sf;
  double *pp = realloc(bd->par, (size_t)nc * 2 * sizeof *pp);
  if (!pp) return 0;
  bd->par = pp;
  bd->cap_l = nc;
  return 1;
}

static int ring_push(build *bd, int32_t id) {
  if (!grow_bytes((void **)&bd->ring, &bd->cap_ring, bd->nring + 1, sizeof *bd->ring)) return 0;
  bd->ring[bd->nring++] = id;
  return 1;
}

/* Appends the T-vertices strictly inside segment P-Q (lattice coordinates on group surface 'ls',
 * local ids pid, qid) to the ring in order from P to Q, setting their values to the midpoint
 * means. Along a shared edge the keys find the other surface's vertices too. 0 on NOMEM. */
static int probe(build *bd, int ls, const uint32_t P[2], const uint32_t Q[2], int32_t pid,
                 int32_t qid, int *found) {
  uint32_t sa = P[0] + Q[0], sb = P[1] + Q[1];
  if ((sa | sb) & 1u) return 1;
  if (P[0] == Q[0] && P[1] == Q[1]) return 1;
  const uint32_t M[2] = {sa / 2, sb / 2};
  uint32_t kh;
  uint64_t kl;
  vkey(bd->gs, ls, M[0], M[1], &kh, &kl);
  int32_t mid = kmap_get(&bd->map, kh, kl);
  if (mid < 0) return 1;
  *found = 1;
  for (int c = 0; c < 3; c++)
    bd->val[3 * mid + c] = 0.5 * (bd->val[3 * pid + c] + bd->val[3 * qid + c]);
  if (!probe(bd, ls, P, M, pid, mid, found)) return 0;
  if (!ring_push(bd, mid)) return 0;
  return probe(bd, ls, M, Q, mid, qid, found);
}

static int tris_grow(build *bd, int64_t need) {
  if (need <= bd->cap_t) return 1;
  hr_mesh *m = bd->m;
  int64_t nc = bd->cap_t ? bd->cap_t : 256;
  while (nc < need) nc *= 2;
  uint32_t *t = realloc(m->tri, (size_t)nc * 3 * sizeof *t);
  if (!t) return 0;
  m->tri = t;
  int32_t *ts = realloc(m->tri_surf, (size_t)nc * sizeof *ts);
  if (!ts) return 0;
  m->tri_surf = ts;
  int64_t *tl = realloc(m->tri_leaf, (size_t)nc * sizeof *tl);
  if (!tl) return 0;
  m->tri_leaf = tl;
  uint8_t *te = realloc(m->tri_emit, (size_t)nc * sizeof *te);
  if (!te) return 0;
  m->tri_emit = te;
  bd->cap_t = nc;
  return 1;
}

static int emit_tri(build *bd, int64_t vbase, int32_t a, int32_t b, int32_t c, int surf,
                    int64_t leaf, uint8_t emit) {
  hr_mesh *m = bd->m;
  int64_t t = m->ntris;
  if (!tris_grow(bd, t + 1)) return 0;
  m->tri[3 * t] = (uint32_t)(vbase + a);
  m->tri[3 * t + 1] = (uint32_t)(vbase + b);
  m->tri[3 * t + 2] = (uint32_t)(vbase + c);
  m->tri_surf[t] = surf;
  m->tri_leaf[t] = leaf;
  m->tri_emit[t] = emit;
  m->ntris = t + 1;
  return 1;
}

static int verts_grow(build *bd, int64_t need) {
  if (need <= bd->cap_v) return 1;
  int64_t nc = bd->cap_v ? bd->cap_v : 256;
  while (nc < need) nc *= 2;
  float *p = realloc(bd->m->pos, (size_t)nc * 3 * sizeof *p);
  if (!p) return 0;
  bd->m->pos = p;
  float *b = realloc(bd->m->B, (size_t)nc * 3 * sizeof *b);
  if (!b) return 0;
  bd->m->B = b;
  bd->cap_v = nc;
  return 1;
}

/* Lattice edge length of a leaf (max-norm over its edges). For the dyadic subdivisions of
 * hrad.h this is also the lattice-parameter length of each of its edges lying on a surface
 * edge, so sizes compare across the surfaces of a group. */
static uint32_t leaf_size(const hr_leaf *l) {
  uint32_t s = 0;
  for (int i = 0; i < l->nverts; i++) {
    int j = (i + 1) % l->nverts;
    int64_t da = (int64_t)l->lat[j][0] - l->lat[i][0], db = (int64_t)l->lat[j][1] - l->lat[i][1];
    uint32_t d = (uint32_t)(llabs(da) > llabs(db) ? llabs(da) : llabs(db));
    if (d > s) s = d;
  }
  return s;
}

static int log2u(uint32_t s) {
  int k = 0;
  while (s > 1) {
    s >>= 1;
    k++;
  }
  return k;
}

static uint64_t pos_hash(hr_vec3 p) { return v3_hash(0x9e3779b97f4a7c15ull, p); }

/* Fills bd->gs for the 'ng' scene surfaces 'surfs' of one group: corner ids and shared edges.
 * O(ng) expected. */
static hr_status group_setup(build *bd, const hr_scene *s, const int *surfs, int ng) {
  int64_t nc4 = 4 * (int64_t)ng;
  if (!grow_bytes((void **)&bd->gs, &bd->cap_gs, ng, sizeof *bd->gs)) return HR_ERR_NOMEM;
  if (nc4 > bd->cap_c) {
    int64_t cap = bd->cap_c;
    hr_vec3 *cp = bd->cpos;
    if (!grow_bytes((void **)&cp, &cap, nc4, sizeof *cp)) return HR_ERR_NOMEM;
    bd->cpos = cp;
    int32_t *ec = realloc(bd->ecount, (size_t)cap * sizeof *ec);
    if (!ec) return HR_ERR_NOMEM;
    bd->ecount = ec;
    bd->cap_c = cap;
  }
  int64_t tcap = 16;
  while (tcap < 2 * nc4) tcap *= 2;
  if (!grow_bytes((void **)&bd->ctab, &bd->cap_ctab, tcap, sizeof *bd->ctab))
    return HR_ERR_NOMEM;
  memset(bd->ctab, 0xff, (size_t)tcap * sizeof *bd->ctab);
  uint64_t tmask = (uint64_t)tcap - 1;
  int32_t ncorner = 0;
  for (int ls = 0; ls < ng; ls++) {
    const hr_surface *f = &s->surfs[surfs[ls]];
    const double *em = s->mats[f->material].emit;
    gsurf *g = &bd->gs[ls];
    g->surf = surfs[ls];
    g->nv = f->nverts;
    g->emit = (em[0] > 0 || em[1] > 0 || em[2] > 0) ? 1 : 0;
    for (int c = 0; c < g->nv; c++) {
      hr_vec3 p = f->v[c];
      uint64_t h = pos_hash(p) & tmask;
      for (;;) {
        int32_t id = bd->ctab[h];
        if (id < 0) {
          bd->ctab[h] = ncorner;
          bd->cpos[ncorner] = p;
          g->corner[c] = ncorner++;
          break;
        }
        hr_vec3 q = bd->cpos[id];
        if (q.x == p.x && q.y == p.y && q.z == p.z) {
          g->corner[c] = id;
          break;
        }
        h = (h + 1) & tmask;
      }
    }
  }
  if (!kmap_reset(&bd->emap, nc4)) return HR_ERR_NOMEM;
  int32_t nedge = 0;
  for (int ls = 0; ls < ng; ls++) {
    gsurf *g = &bd->gs[ls];
    for (int c = 0; c < g->nv; c++) {
      int32_t a = g->corner[c], b = g->corner[(c + 1) % g->nv];
      g->rev[c] = a > b;
      g->edge[c] = -1;
      if (a == b) continue;
      uint64_t lo = (uint64_t)(a < b ? a : b), hi = (uint64_t)(a < b ? b : a);
      int ins;
      int32_t id = kmap_put(&bd->emap, TAG_EDGE, (lo << 32) | hi, nedge, &ins);
      if (ins) bd->ecount[nedge++] = 0;
      bd->ecount[id]++;
      g->edge[c] = id;
    }
  }
  for (int ls = 0; ls < ng; ls++) {
    gsurf *g = &bd->gs[ls];
    for (int c = 0; c < g->nv; c++)
      if (g->edge[c] >= 0 && bd->ecount[g->edge[c]] < 2) g->edge[c] = -1;
  }
  return HR_OK;
}

/* Processes the leaves (indices idx[0..k)) of one group: the 'ng' scene surfaces 'surfs' of one
 * input polygon. 'slocal' maps scene surface -> group surface index; 'order' is scratch of k. */
static hr_status build_group(build *bd, const hr_scene *s, const int *surfs, int ng,
                             int32_t *slocal, const hr_leaf *leaves, const int64_t *idx, int64_t k,
                             int64_t *order) {
  hr_mesh *m = bd->m;
  if (ng > MAX_GROUP) return HR_ERR_TOO_BIG;
  hr_status st = group_setup(bd, s, surfs, ng);
  if (st != HR_OK) return st;
  for (int ls = 0; ls < ng; ls++) slocal[surfs[ls]] = ls;
  if (k * 5 >= INT32_MAX) return HR_ERR_TOO_BIG;
  if (!kmap_reset(&bd->map, k * 4)) return HR_ERR_NOMEM;
  if (!local_grow(bd, k * 5)) return HR_ERR_NOMEM;
  if (!grow_bytes((void **)&bd->lcid, &bd->cap_lcid, 4 * k, sizeof *bd->lcid)) return HR_ERR_NOMEM;
  bd->nloc = 0;
  /* 1. corners and their area-weighted sums */
  for (int64_t i = 0; i < k; i++) {
    const hr_leaf *l = &leaves[idx[i]];
    int ls = slocal[l->surf];
    /* what is seen of the leaf: its open part's radiosity, weighted by the open area (a wall
     * element half behind a board it touches would otherwise shade the visible wall beside
     * the board with its mean); a tiny weight keeps zero-area and covered leaves meaningful
     * without disturbing real weights */
    const double op = l->open > 0 && l->open <= 1 ? l->open : 1;
    const double *E = s->mats[s->surfs[l->surf].material].emit;
    double Bv[3];
    for (int ch = 0; ch < 3; ch++) Bv[ch] = E[ch] + (l->B[ch] - E[ch]) / op;
    const double w = (l->area > 0 && isfinite(l->area)) ? fmax(l->area * op, 1e-300) : 1e-300;
    for (int c = 0; c < l->nverts; c++) {
      int ins;
      uint32_t kh;
      uint64_t kl;
      vkey(bd->gs, ls, l->lat[c][0], l->lat[c][1], &kh, &kl);
      int32_t id = kmap_put(&bd->map, kh, kl, (int32_t)bd->nloc, &ins);
      bd->lcid[4 * i + c] = id;
      if (ins) {
        bd->vsf[id] = l->surf;
        bd->par[2 * id] = l->lat[c][0];
        bd->par[2 * id + 1] = l->lat[c][1];
        bd->val[3 * id] = bd->val[3 * id + 1] = bd->val[3 * id + 2] = 0;
        bd->wsum[id] = 0;
        bd->nloc++;
      }
      for (int ch = 0; ch < 3; ch++) bd->val[3 * id + ch] += w * Bv[ch];
      bd->wsum[id] += w;
    }
  }
  for (int64_t v = 0; v < bd->nloc; v++)
    for (int ch = 0; ch < 3; ch++) bd->val[3 * v + ch] /= bd->wsum[v];
  /* 2. leaves from the largest to the smallest (counting sort on log2 of the size) */
  int64_t start[33] = {0};
  for (int64_t i = 0; i < k; i++) start[32 - log2u(leaf_size(&leaves[idx[i]]))]++;
  int64_t acc = 0;
  for (int b = 0; b < 33; b++) {
    int64_t c = start[b];
    start[b] = acc;
    acc += c;
  }
  for (int64_t i = 0; i < k; i++) order[start[32 - log2u(leaf_size(&leaves[idx[i]]))]++] = i;
  /* 3. T-vertices and triangulation */
  int64_t vbase = m->nverts;
  for (int64_t oi = 0; oi < k; oi++) {
    int64_t i = order[oi], li = idx[i];
    const hr_leaf *l = &leaves[li];
    int ls = slocal[l->surf];
    int nv = l->nverts;
    uint8_t emit = bd->gs[ls].emit;
    /* keep counter-clockwise in lattice space */
    double sa = 0;
    for (int c = 0; c < nv; c++) {
      int d = (c + 1) % nv;
      sa += (double)l->lat[c][0] * l->lat[d][1] - (double)l->lat[d][0] * l->lat[c][1];
    }
    if (sa == 0) continue; /* degenerate leaf: nothing to draw */
    uint32_t cl[4][2];
    int32_t cid[4];
    for (int c = 0; c < nv; c++) {
      int from = sa < 0 ? nv - 1 - c : c;
      cl[c][0] = l->lat[from][0];
      cl[c][1] = l->lat[from][1];
      cid[c] = bd->lcid[4 * i + from];
    }
    int64_t rpos[4];
    int edge_t[4];
    bd->nring = 0;
    for (int c = 0; c < nv; c++) {
      int d = (c + 1) % nv;
      rpos[c] = bd->nring;
      if (!ring_push(bd, cid[c])) return HR_ERR_NOMEM;
      edge_t[c] = 0;
      if (!probe(bd, ls, cl[c], cl[d], cid[c], cid[d], &edge_t[c])) return HR_ERR_NOMEM;
    }
    int64_t r = bd->nring;
    /* a corner whose two edges hold no T-vertex can be the fan's apex; for quads take the one
     * whose diagonal joins the closer values (data-dependent diagonal, fewer shading streaks) */
    int best = -1;
    double bestd = INFINITY;
    for (int c = 0; c < nv; c++) {
      if (edge_t[c] || edge_t[(c + nv - 1) % nv]) continue;
      double d = 0;
      if (nv == 4) d = fabs(lum(&bd->val[3 * cid[c]]) - lum(&bd->val[3 * cid[(c + 2) % 4]]));
      if (d < bestd * (1 - 1e-9)) {
        bestd = d;
        best = c;
      }
    }
    if (best >= 0) {
      int64_t p0 = rpos[best];
      for (int64_t j = 1; j + 1 < r; j++)
        if (!emit_tri(bd, vbase, bd->ring[p0], bd->ring[(p0 + j) % r], bd->ring[(p0 + j + 1) % r],
                      l->surf, li, emit))
          return HR_ERR_NOMEM;
    } else {
      /* centre vertex: mean of the corners' parameters and values (exact for linear fields) */
      int32_t cv = (int32_t)bd->nloc++;
      double ca = 0, cb = 0, cval[3] = {0, 0, 0};
      for (int c = 0; c < nv; c++) {
        ca += cl[c][0];
        cb += cl[c][1];
        for (int ch = 0; ch < 3; ch++) cval[ch] += bd->val[3 * cid[c] + ch];
      }
      bd->vsf[cv] = l->surf;
      bd->par[2 * cv] = ca / nv;
      bd->par[2 * cv + 1] = cb / nv;
      for (int ch = 0; ch < 3; ch++) bd->val[3 * cv + ch] = cval[ch] / nv;
      m->ncentre++;
      for (int64_t j = 0; j < r; j++)
        if (!emit_tri(bd, vbase, cv, bd->ring[j], bd->ring[(j + 1) % r], l->surf, li, emit))
          return HR_ERR_NOMEM;
    }
  }
  /* 4. vertices of this group */
  if (vbase + bd->nloc > (int64_t)UINT32_MAX) return HR_ERR_TOO_BIG;
  if (!verts_grow(bd, vbase + bd->nloc)) return HR_ERR_NOMEM;
  const double inv = 1.0 / (double)HR_LATTICE;
  for (int64_t v = 0; v < bd->nloc; v++) {
    hr_vec3 p = surf_point(&s->surfs[bd->vsf[v]], bd->par[2 * v] * inv, bd->par[2 * v + 1] * inv);
    float *P = &m->pos[3 * (vbase + v)], *B = &m->B[3 * (vbase + v)];
    P[0] = (float)p.x;
    P[1] = (float)p.y;
    P[2] = (float)p.z;
    for (int ch = 0; ch < 3; ch++) B[ch] = (float)bd->val[3 * v + ch];
  }
  m->nverts = vbase + bd->nloc;
  return HR_OK;
}

/* ------------------------------------------------------------------ smoothing across polygons */

static double tri_area(const hr_mesh *m, int64_t t);

/* Largest angle between the normals of two polygons shaded as one surface: cos(0.8 degrees).
 * Exporters' triangles of one flat wall agree to about 1e-6; the facets of a tessellated
 * cylinder or sphere differ by several degrees and stay apart, like any crease. */
#define SMOOTH_COS 0.9999

static int64_t uf_find(int64_t *par, int64_t v) {
  while (par[v] != v) v = par[v] = par[par[v]];
  return v;
}

/* Cell of position 'p' on the grid of side 'eps'. */
static void cell_of(const float *p, double eps, int64_t c[3]) {
  for (int k = 0; k < 3; k++) c[k] = (int64_t)floor(p[k] / eps);
}

static uint64_t cell_hash(const int64_t c[3]) {
  uint64_t h = u64_mix((uint64_t)c[0] * 0x9e3779b97f4a7c15ull);
  h = u64_mix(h ^ (uint64_t)c[1]);
  return u64_mix(h ^ (uint64_t)c[2] * 0xc2b2ae3d27d4eb4full);
}

/* Per vertex of 'm': a surface holding it, its base material, and its weight (a third of the
 * area of its triangles); -1 as the surface of a vertex without triangles. */
static void vertex_info(const hr_mesh *m, const hr_scene *s, int32_t *vsurf, int32_t *vmat,
                       double *vw) {
  for (int64_t v = 0; v < m->nverts; v++) vsurf[v] = -1, vw[v] = 0;
  for (int64_t t = 0; t < m->ntris; t++) {
    const hr_surface *f = &s->surfs[m->tri_surf[t]];
    double a = tri_area(m, t) / 3;
    for (int c = 0; c < 3; c++) {
      uint32_t v = m->tri[3 * t + c];
      vsurf[v] = m->tri_surf[t];
      vmat[v] = s->mats[f->material].base;
      vw[v] += a > 0 ? a : 1e-300;
    }
  }
}

/* Joins (union-find 'par') every vertex with the vertices within 'eps' of it (max norm) that
 * belong to another polygon with the same input material and a normal within SMOOTH_COS. The
 * grid cells (side 2 eps: the box of +-eps around a vertex meets at most 2 per axis) hold the
 * vertices in chains 'next' from 'head' (open addressing on 'ckey'). */
static void join_close(const hr_mesh *m, const hr_scene *s, const int32_t *vsurf,
                       const int32_t *vmat, double eps, const int64_t *ckey, const int64_t *head,
                       uint64_t mask, const int64_t *next, int64_t *par) {
  for (int64_t v = 0; v < m->nverts; v++) {
    if (vsurf[v] < 0) continue;
    const float *p = &m->pos[3 * v];
    const hr_surface *fv = &s->surfs[vsurf[v]];
    int64_t lo[3], hi[3], c[3];
    for (int k = 0; k < 3; k++) {
      lo[k] = (int64_t)floor((p[k] - eps) / (2 * eps));
      hi[k] = (int64_t)floor((p[k] + eps) / (2 * eps));
    }
    for (c[0] = lo[0]; c[0] <= hi[0]; c[0]++)
      for (c[1] = lo[1]; c[1] <= hi[1]; c[1]++)
        for (c[2] = lo[2]; c[2] <= hi[2]; c[2]++) {
          uint64_t i = cell_hash(c) & mask;
          while (head[i] >= 0 && memcmp(&ckey[3 * i], c, sizeof c)) i = (i + 1) & mask;
          for (int64_t w = head[i]; w >= 0; w = next[w]) {
            if (w <= v || vmat[w] != vmat[v]) continue;
            const hr_surface *fw = &s->surfs[vsurf[w]];
            if (fw->poly == fv->poly || v3_dot(fv->normal, fw->normal) < SMOOTH_COS) continue;
            const float *q = &m->pos[3 * w];
            if (fabs(p[0] - q[0]) > eps || fabs(p[1] - q[1]) > eps || fabs(p[2] - q[2]) > eps)
              continue;
            int64_t a = uf_find(par, v), b = uf_find(par, w);
            if (a != b) par[a < b ? b : a] = a < b ? a : b;
          }
        }
  }
}

/* Two vertices closer than this are one point: a millionth of the scene's size, or a few float
 * steps of its largest coordinate (the mesh stores floats), whichever is larger. */
static double merge_eps(const hr_mesh *m) {
  float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  double amax = 0;
  for (int64_t v = 0; v < m->nverts; v++)
    for (int c = 0; c < 3; c++) {
      float x = m->pos[3 * v + c];
      lo[c] = x < lo[c] ? x : lo[c];
      hi[c] = x > hi[c] ? x : hi[c];
      amax = fabs(x) > amax ? fabs(x) : amax;
    }
  double d = sqrt(pow(hi[0] - lo[0], 2) + pow(hi[1] - lo[1], 2) + pow(hi[2] - lo[2], 2));
  double e = fmax(1e-6 * d, 8 * FLT_EPSILON * amax);
  return e > 0 && isfinite(e) ? e : 1;
}

/* A surface edge for finding edges shared by two polygons: its ends in a fixed order. */
typedef struct sedge {
  hr_vec3 a, b;
  int surf;
} sedge;

static int cmp_v3(hr_vec3 p, hr_vec3 q) {
  if (p.x != q.x) return p.x < q.x ? -1 : 1;
  if (p.y != q.y) return p.y < q.y ? -1 : 1;
  if (p.z != q.z) return p.z < q.z ? -1 : 1;
  return 0;
}

static int cmp_sedge(const void *pa, const void *pb) {
  const sedge *x = pa, *y = pb;
  int c = cmp_v3(x->a, y->a);
  if (!c) c = cmp_v3(x->b, y->b);
  return c ? c : (x->surf > y->surf) - (x->surf < y->surf);
}

/* A vertex on a shared edge: its parameter along the edge, index and value. */
typedef struct evert {
  double t;
  int64_t v;
} evert;

static int cmp_evert(const void *pa, const void *pb) {
  double a = ((const evert *)pa)->t, b = ((const evert *)pb)->t;
  return (a > b) - (a < b);
}

/* The vertices of polygon 'poly' (CSR 'pstart'/'pverts') on segment a-b, sorted by parameter. */
static int64_t on_edge(const hr_mesh *m, const int64_t *pstart, const int64_t *pverts, int poly,
                       hr_vec3 a, hr_vec3 b, double eps, evert *out) {
  hr_vec3 d = v3_sub(b, a);
  double dd = v3_dot(d, d), len = sqrt(dd);
  int64_t k = 0;
  for (int64_t i = pstart[poly]; i < pstart[poly + 1]; i++) {
    const float *x = &m->pos[3 * pverts[i]];
    hr_vec3 r = v3_sub(v3(x[0], x[1], x[2]), a);
    double t = v3_dot(r, d) / dd;
    if (t * len < -eps || (t - 1) * len > eps) continue;
    if (v3_len(v3_sub(r, v3_scale(d, t))) > eps) continue;
    out[k++] = (evert){t, pverts[i]};
  }
  qsort(out, (size_t)k, sizeof *out, cmp_evert);
  return k;
}

/* Gives each vertex of list 'x' that list 'y' lacks (no vertex within 'et' in parameter) the
 * value of y's shading there (linear between y's neighbours), written to 'nb'. */
static void take_other_side(const hr_mesh *m, const evert *x, int64_t nx, const evert *y,
                            int64_t ny, double et, float *nb) {
  int64_t k = 0;
  for (int64_t i = 0; i < nx && ny >= 2; i++) {
    while (k + 1 < ny && y[k + 1].t <= x[i].t) k++;
    if (fabs(y[k].t - x[i].t) <= et || (k + 1 < ny && fabs(y[k + 1].t - x[i].t) <= et)) continue;
    if (k + 1 >= ny || y[k].t > x[i].t) continue; /* beyond y's ends */
    double w = (x[i].t - y[k].t) / (y[k + 1].t - y[k].t);
    for (int c = 0; c < 3; c++)
      nb[3 * x[i].v + c] = (float)((1 - w) * m->B[3 * y[k].v + c] + w * m->B[3 * y[k + 1].v + c]);
  }
}

/* T-vertices across polygons: where two smoothed polygons share a whole surface edge (equal end
 * positions), the finer side's vertices along it take the coarser side's linear interpolation,
 * as T-vertices inside one polygon do (hr_mesh_build), so the shading is continuous across the
 * edge. The element subdivisions of both sides are dyadic along the edge, so where one side has
 * extra vertices the other has one longer leaf edge. O(sum over shared edges of the vertices of
 * their two polygons). */
static hr_status smooth_edges(hr_mesh *m, const hr_scene *s, const int32_t *vsurf, double eps) {
  int64_t n = m->nverts, ne = 0, np = s->npolys;
  sedge *e = malloc((size_t)s->nsurfs * 4 * sizeof *e + 1);
  int64_t *pstart = calloc((size_t)np + 2, sizeof *pstart), *pverts = malloc((size_t)n * 8 + 8);
  evert *ea = malloc((size_t)n * sizeof *ea + 1), *eb = malloc((size_t)n * sizeof *eb + 1);
  float *nb = malloc((size_t)n * 3 * sizeof *nb + 1);
  hr_status st = HR_ERR_NOMEM;
  if (!e || !pstart || !pverts || !ea || !eb || !nb) goto out;
  for (int i = 0; i < s->nsurfs; i++)
    for (int k = 0; k < s->surfs[i].nverts; k++) {
      hr_vec3 a = s->surfs[i].v[k], b = s->surfs[i].v[(k + 1) % s->surfs[i].nverts];
      e[ne++] = cmp_v3(a, b) < 0 ? (sedge){a, b, i} : (sedge){b, a, i};
    }
  qsort(e, (size_t)ne, sizeof *e, cmp_sedge);
  for (int64_t v = 0; v < n; v++) /* vertices by polygon */
    if (vsurf[v] >= 0) pstart[s->surfs[vsurf[v]].poly + 1]++;
  for (int64_t p = 0; p < np; p++) pstart[p + 1] += pstart[p];
  for (int64_t v = 0; v < n; v++)
    if (vsurf[v] >= 0) pverts[pstart[s->surfs[vsurf[v]].poly]++] = v;
  for (int64_t p = np; p > 0; p--) pstart[p] = pstart[p - 1];
  pstart[0] = 0;
  memcpy(nb, m->B, (size_t)n * 3 * sizeof *nb);
  for (int64_t i = 0; i + 1 < ne; i++) {
    const sedge *x = &e[i], *y = &e[i + 1];
    if (cmp_v3(x->a, y->a) || cmp_v3(x->b, y->b)) continue;
    const hr_surface *fx = &s->surfs[x->surf], *fy = &s->surfs[y->surf];
    if (fx->poly == fy->poly || s->mats[fx->material].base != s->mats[fy->material].base ||
        v3_dot(fx->normal, fy->normal) < SMOOTH_COS)
      continue;
    double len = v3_len(v3_sub(x->b, x->a));
    if (!(len > 2 * eps)) continue;
    int64_t na = on_edge(m, pstart, pverts, fx->poly, x->a, x->b, eps, ea);
    int64_t nbv = on_edge(m, pstart, pverts, fy->poly, x->a, x->b, eps, eb);
    take_other_side(m, ea, na, eb, nbv, eps / len, nb);
    take_other_side(m, eb, nbv, ea, na, eps / len, nb);
  }
  memcpy(m->B, nb, (size_t)n * 3 * sizeof *nb);
  st = HR_OK;
out:
  free(e);
  free(pstart);
  free(pverts);
  free(ea);
  free(eb);
  free(nb);
  return st;
}

/* Smooth shading across polygons (real models arrive as triangle soups: a wall of many
 * triangles): vertices of different polygons at one position (within merge_eps), with the same
 * input material and parallel normals (SMOOTH_COS) all get the weighted mean of their values.
 * Vertices stay separate (each polygon keeps its own); creases, other materials and back-to-back
 * panels keep their own values. O(nverts) expected. */
static hr_status smooth_across(hr_mesh *m, const hr_scene *s) {
  if (m->nverts <= 0 || s->npolys < 2) return HR_OK;
  int64_t n = m->nverts, cap = 16;
  while (cap < 2 * n) cap *= 2;
  int32_t *vsurf = malloc((size_t)n * sizeof *vsurf), *vmat = malloc((size_t)n * sizeof *vmat);
  double *vw = malloc((size_t)n * sizeof *vw), *acc = malloc((size_t)n * 4 * sizeof *acc);
  int64_t *par = malloc((size_t)n * sizeof *par), *next = malloc((size_t)n * sizeof *next);
  int64_t *head = malloc((size_t)cap * sizeof *head);
  int64_t *ckey = malloc((size_t)cap * 3 * sizeof *ckey);
  hr_status st = HR_ERR_NOMEM;
  if (!vsurf || !vmat || !vw || !acc || !par || !next || !head || !ckey) goto out;
  vertex_info(m, s, vsurf, vmat, vw);
  double eps = merge_eps(m);
  uint64_t mask = (uint64_t)cap - 1;
  for (int64_t i = 0; i < cap; i++) head[i] = -1;
  for (int64_t v = 0; v < n; v++) {
    par[v] = v;
    next[v] = -1;
    if (vsurf[v] < 0) continue;
    int64_t c[3];
    cell_of(&m->pos[3 * v], 2 * eps, c);
    uint64_t i = cell_hash(c) & mask;
    while (head[i] >= 0 && memcmp(&ckey[3 * i], c, sizeof c)) i = (i + 1) & mask;
    memcpy(&ckey[3 * i], c, sizeof c);
    next[v] = head[i];
    head[i] = v;
  }
  join_close(m, s, vsurf, vmat, eps, ckey, head, mask, next, par);
  memset(acc, 0, (size_t)n * 4 * sizeof *acc);
  for (int64_t v = 0; v < n; v++) {
    int64_t r = uf_find(par, v);
    for (int c = 0; c < 3; c++) acc[4 * r + c] += vw[v] * m->B[3 * v + c];
    acc[4 * r + 3] += vw[v];
  }
  for (int64_t v = 0; v < n; v++) {
    int64_t r = uf_find(par, v);
    if (r != v || acc[4 * r + 3] != vw[v]) /* joined with others */
      for (int c = 0; c < 3; c++) m->B[3 * v + c] = (float)(acc[4 * r + c] / acc[4 * r + 3]);
  }
  st = smooth_edges(m, s, vsurf, eps);
out:
  free(vsurf);
  free(vmat);
  free(vw);
  free(acc);
  free(par);
  free(next);
  free(head);
  free(ckey);
  return st;
}

void hr_mesh_destroy(hr_mesh **pm) {
  if (!pm || !*pm) return;
  hr_mesh *m = *pm;
  free(m->pos);
  free(m->B);
  free(m->tri);
  free(m->tri_surf);
  free(m->tri_leaf);
  free(m->tri_emit);
  free(m);
  *pm = NULL;
}

hr_status hr_mesh_build(const hr_scene *s, const hr_leaf *leaves, int64_t n, hr_mesh **out) {
  *out = NULL;
  if (!s || n < 0 || (n > 0 && !leaves)) return HR_ERR_INVALID;
  for (int64_t i = 0; i < n; i++) {
    const hr_leaf *l = &leaves[i];
    if (l->surf < 0 || l->surf >= s->nsurfs) return HR_ERR_INVALID;
    if (l->nverts != s->surfs[l->surf].nverts) return HR_ERR_INVALID;
    for (int c = 0; c < l->nverts; c++)
      if (l->lat[c][0] > HR_LATTICE || l->lat[c][1] > HR_LATTICE) return HR_ERR_INVALID;
  }
  int ns = s->nsurfs, np = s->npolys > 0 ? s->npolys : 0;
  hr_mesh *m = calloc(1, sizeof *m);
  if (m) m->scene = s;
  int64_t *cnt = calloc((size_t)ns + 1, sizeof *cnt);
  int64_t *idx = malloc((size_t)(n > 0 ? n : 1) * sizeof *idx);
  int64_t *order = malloc((size_t)(n > 0 ? n : 1) * sizeof *order);
  int *pc = calloc((size_t)np + 2, sizeof *pc);
  int *sorder = malloc((size_t)(ns > 0 ? ns : 1) * sizeof *sorder);
  int *rank = malloc((size_t)(ns > 0 ? ns : 1) * sizeof *rank);
  int32_t *slocal = malloc((size_t)(ns > 0 ? ns : 1) * sizeof *slocal);
  build bd;
  memset(&bd, 0, sizeof bd);
  bd.m = m;
  hr_status st = HR_OK;
  if (!m || !cnt || !idx || !order || !pc || !sorder || !rank || !slocal) {
    st = HR_ERR_NOMEM;
    goto done;
  }
  /* surfaces grouped by input polygon, stable counting sort (surfaces with an out-of-range
   * poly index go last, each a group of its own) */
#define POLY_OF(f) (s->surfs[f].poly >= 0 && s->surfs[f].poly < np ? s->surfs[f].poly : np)
  for (int f = 0; f < ns; f++) pc[POLY_OF(f) + 1]++;
  for (int p = 0; p <= np; p++) pc[p + 1] += pc[p];
  for (int f = 0; f < ns; f++) sorder[pc[POLY_OF(f)]++] = f;
  for (int r = 0; r < ns; r++) rank[sorder[r]] = r;
  /* leaves by surface rank, stable */
  for (int64_t i = 0; i < n; i++) cnt[rank[leaves[i].surf] + 1]++;
  for (int r = 0; r < ns; r++) cnt[r + 1] += cnt[r];
  for (int64_t i = 0; i < n; i++) idx[cnt[rank[leaves[i].surf]]++] = i;
  /* cnt[r] is now the end of the leaves of rank r */
  for (int r0 = 0; r0 < ns && st == HR_OK;) {
    int p = POLY_OF(sorder[r0]), r1 = r0 + 1;
    if (p < np)
      while (r1 < ns && POLY_OF(sorder[r1]) == p) r1++;
    int64_t b = r0 > 0 ? cnt[r0 - 1] : 0, e = cnt[r1 - 1];
    if (e > b)
      st = build_group(&bd, s, sorder + r0, r1 - r0, slocal, leaves, idx + b, e - b, order);
    r0 = r1;
  }
#undef POLY_OF
  if (st == HR_OK) st = smooth_across(m, s);
  if (st == HR_OK) {
    /* trim */
    if (m->nverts > 0) {
      float *p = realloc(m->pos, (size_t)m->nverts * 3 * sizeof *p);
      if (p) m->pos = p;
      float *q = realloc(m->B, (size_t)m->nverts * 3 * sizeof *q);
      if (q) m->B = q;
    }
  }
done:
  free(cnt);
  free(idx);
  free(order);
  free(pc);
  free(sorder);
  free(rank);
  free(slocal);
  free(bd.val);
  free(bd.wsum);
  free(bd.vsf);
  free(bd.par);
  free(bd.ring);
  free(bd.lcid);
  free(bd.gs);
  free(bd.cpos);
  free(bd.ctab);
  free(bd.ecount);
  free(bd.map.slots);
  free(bd.emap.slots);
  if (st != HR_OK) {
    hr_mesh_destroy(&m);
    return st;
  }
  *out = m;
  return HR_OK;
}

/* ------------------------------------------------------------------ exposure */

typedef struct lw {
  double y, a;
} lw;

static int cmp_lw(const void *pa, const void *pb) {
  double a = ((const lw *)pa)->y, b = ((const lw *)pb)->y;
  return (a > b) - (a < b);
}

static double tri_area(const hr_mesh *m, int64_t t) {
  const float *a = &m->pos[3 * m->tri[3 * t]], *b = &m->pos[3 * m->tri[3 * t + 1]],
              *c = &m->pos[3 * m->tri[3 * t + 2]];
  hr_vec3 e1 = v3(b[0] - a[0], b[1] - a[1], b[2] - a[2]);
  hr_vec3 e2 = v3(c[0] - a[0], c[1] - a[1], c[2] - a[2]);
  return 0.5 * v3_len(v3_cross(e1, e2));
}

static double vlum(const hr_mesh *m, uint32_t v) {
  const float *b = &m->B[3 * v];
  return 0.2126 * b[0] + 0.7152 * b[1] + 0.0722 * b[2];
}

/* Area-weighted 'q'-quantile of the triangle luminance; 'which' 0 = non-emitting only, 1 = all. */
static double lum_quantile(const hr_mesh *m, lw *buf, int which, double q) {
  int64_t k = 0;
  double total = 0;
  for (int64_t t = 0; t < m->ntris; t++) {
    if (which == 0 && m->tri_emit && m->tri_emit[t]) continue;
    double a = tri_area(m, t);
    if (!(a > 0)) continue;
    double y =
        (vlum(m, m->tri[3 * t]) + vlum(m, m->tri[3 * t + 1]) + vlum(m, m->tri[3 * t + 2])) / 3;
    if (!isfinite(y)) continue;
    buf[k].y = y;
    buf[k].a = a;
    total += a;
    k++;
  }
  if (k == 0) return 0;
  qsort(buf, (size_t)k, sizeof *buf, cmp_lw);
  double acc = 0, lim = q * total;
  for (int64_t i = 0; i < k; i++) {
    acc += buf[i].a;
    if (acc >= lim) return buf[i].y;
  }
  return buf[k - 1].y;
}

double hr_exposure_auto(const hr_mesh *m) {
  if (!m || m->ntris <= 0) return 1.0;
  lw *buf = malloc((size_t)m->ntris * sizeof *buf);
  if (!buf) return 1.0;
  double y = lum_quantile(m, buf, 0, 0.95);
  if (!(y > 0)) y = lum_quantile(m, buf, 1, 0.95);
  if (!(y > 0)) y = lum_quantile(m, buf, 1, 1.0);
  free(buf);
  if (!(y > 0) || !isfinite(y)) return 1.0;
  return 0.8 / y;
}

/* ------------------------------------------------------------------ little-endian packing */

static void put_u32(uint8_t *p, uint32_t v) {
  p[0] = (uint8_t)v;
  p[1] = (uint8_t)(v >> 8);
  p[2] = (uint8_t)(v >> 16);
  p[3] = (uint8_t)(v >> 24);
}

static void put_f32(uint8_t *p, float f) {
  uint32_t u;
  memcpy(&u, &f, 4);
  put_u32(p, u);
}

/* ------------------------------------------------------------------ PLY */

hr_status hr_ply_write(const char *path, const hr_mesh *m, double exposure, hr_err *err) {
  if (!m || !path) return hr_err_set(err, HR_ERR_INVALID, "hr_ply_write: no mesh or path");
  if (!isfinite(exposure) || exposure < 0)
    return hr_err_set(err, HR_ERR_INVALID, "%s: bad exposure %g", path, exposure);
  FILE *fp = fopen(path, "wb");
  if (!fp)
    return hr_err_set(err, HR_ERR_IO, "%s: cannot open for writing: %s", path, strerror(errno));
  int ok = fprintf(fp,
                   "ply\nformat binary_little_endian 1.0\n"
                   "comment generated by hrad (hierarchical radiosity)\n"
                   "comment red green blue: 8-bit sRGB of radiosity * exposure, clamped\n"
                   "comment radiosity_r radiosity_g radiosity_b: linear radiosity B (no exposure)\n"
                   "comment exposure %.17g\n"
                   "element vertex %lld\n"
                   "property float x\nproperty float y\nproperty float z\n"
                   "property uchar red\nproperty uchar green\nproperty uchar blue\n"
                   "property float radiosity_r\nproperty float radiosity_g\n"
                   "property float radiosity_b\n"
                   "element face %lld\n"
                   "property list uchar int vertex_indices\n"
                   "end_header\n",
                   exposure, (long long)m->nverts, (long long)m->ntris) > 0;
  int e = ok ? 0 : errno;
  enum { VREC = 12 + 3 + 12, FREC = 13, CHUNK = 4096 };
  uint8_t buf[CHUNK * VREC];
  for (int64_t v0 = 0; v0 < m->nverts && ok; v0 += CHUNK) {
    int64_t v1 = v0 + CHUNK < m->nverts ? v0 + CHUNK : m->nverts;
    uint8_t *p = buf;
    for (int64_t v = v0; v < v1; v++, p += VREC) {
      for (int c = 0; c < 3; c++) put_f32(p + 4 * c, m->pos[3 * v + c]);
      for (int c = 0; c < 3; c++) p[12 + c] = hr_tonemap8(m->B[3 * v + c], exposure);
      for (int c = 0; c < 3; c++) put_f32(p + 15 + 4 * c, m->B[3 * v + c]);
    }
    ok = fwrite(buf, 1, (size_t)(p - buf), fp) == (size_t)(p - buf);
    if (!ok) e = errno;
  }
  for (int64_t t0 = 0; t0 < m->ntris && ok; t0 += CHUNK) {
    int64_t t1 = t0 + CHUNK < m->ntris ? t0 + CHUNK : m->ntris;
    uint8_t *p = buf;
    for (int64_t t = t0; t < t1; t++, p += FREC) {
      p[0] = 3;
      for (int c = 0; c < 3; c++) put_u32(p + 1 + 4 * c, m->tri[3 * t + c]);
    }
    ok = fwrite(buf, 1, (size_t)(p - buf), fp) == (size_t)(p - buf);
    if (!ok) e = errno;
  }
  return hr_file_close(fp, path, ok, e, err);
}

/* ------------------------------------------------------------------ GLB */

typedef struct sbuf {
  char *s;
  size_t len, cap;
  int nomem;
} sbuf;

static void sb_printf(sbuf *b, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

static void sb_printf(sbuf *b, const char *fmt, ...) {
  if (b->nomem) return;
  for (;;) {
    va_list ap;
    va_start(ap, fmt);
    int k = vsnprintf(b->s ? b->s + b->len : NULL, b->s ? b->cap - b->len : 0, fmt, ap);
    va_end(ap);
    if (k < 0) {
      b->nomem = 1;
      return;
    }
    if (b->s && b->len + (size_t)k < b->cap) {
      b->len += (size_t)k;
      return;
    }
    size_t nc = b->cap ? b->cap : 1024;
    while (nc <= b->len + (size_t)k) nc *= 2;
    char *q = realloc(b->s, nc);
    if (!q) {
      b->nomem = 1;
      return;
    }
    b->s = q;
    b->cap = nc;
  }
}

/* Appends 'str' as a JSON string: quotes, backslashes and control characters escaped, bytes
 * that are not UTF-8 replaced by '?' (the validator rejects them; OBJ names may hold any byte). */
static void sb_json_string(sbuf *b, const char *str) {
  const unsigned char *p = (const unsigned char *)str;
  sb_printf(b, "\"");
  while (*p) {
    int n = *p < 0x80 ? 1 : (*p >> 5) == 6 ? 2 : (*p >> 4) == 14 ? 3 : (*p >> 3) == 30 ? 4 : 0;
    for (int k = 1; k < n; k++)
      if ((p[k] & 0xc0) != 0x80) n = 0;
    if (n == 0) {
      sb_printf(b, "?");
      p++;
    } else if (n == 1 && (*p < 32 || *p == '"' || *p == '\\')) {
      sb_printf(b, *p < 32 ? "\\u%04x" : "\\%c", *p);
      p++;
    } else {
      sb_printf(b, "%.*s", n, (const char *)p);
      p += n;
    }
  }
  sb_printf(b, "\"");
}

/* One glTF primitive: the triangles of one (object, input material) pair, and their vertices,
 * both contiguous in the writer's order. */
typedef struct gprim {
  int obj, mat;            /* object, index of the input material among hr_scene_material_at */
  int64_t v0, nv, t0, nt;  /* first vertex and count, first triangle and count */
  float lo[3], hi[3];      /* position bounds */
} gprim;

/* The writer's layout of mesh 'm': primitives sorted by object, then material; 'vorder' the
 * vertices in writer order, 'vnew' a vertex's writer index, 'torder' the triangles. */
typedef struct glayout {
  gprim *prim;
  int nprim;
  int64_t *vorder, *vnew, *torder;
  int *mat_slot; /* scene material -> position among the input materials */
  int nmat;
} glayout;

static void glayout_free(glayout *g) {
  free(g->prim);
  free(g->vorder);
  free(g->vnew);
  free(g->torder);
  free(g->mat_slot);
  memset(g, 0, sizeof *g);
}

/* Key of triangle 't': (object, material slot), or one key for all when there is no scene. */
static int64_t tri_key(const hr_mesh *m, const glayout *g, int64_t t) {
  const hr_scene *s = m->scene;
  if (!s) return 0;
  const hr_surface *f = &s->surfs[m->tri_surf[t]];
  int o = hr_scene_poly_object(s, f->poly);
  return (int64_t)(o < 0 ? 0 : o) * g->nmat + g->mat_slot[f->material];
}

/* Fills 'g' for 'm' (see glayout). 0 when out of memory. */
static int glayout_build(const hr_mesh *m, glayout *g) {
  const hr_scene *s = m->scene;
  int nobj = s && s->nobjects > 0 ? s->nobjects : 1;
  g->nmat = s ? hr_scene_material_count(s) : 1;
  if (g->nmat < 1) g->nmat = 1;
  int64_t nkeys = (int64_t)nobj * g->nmat;
  g->mat_slot = calloc(s ? (size_t)s->nmats + 1 : 1, sizeof *g->mat_slot);
  int64_t *cnt = calloc((size_t)nkeys + 1, sizeof *cnt);
  int64_t *vk = malloc((size_t)m->nverts * sizeof *vk + 1);
  g->vorder = malloc((size_t)m->nverts * sizeof *g->vorder + 1);
  g->vnew = malloc((size_t)m->nverts * sizeof *g->vnew + 1);
  g->torder = malloc((size_t)m->ntris * sizeof *g->torder + 1);
  g->prim = malloc((size_t)(nkeys < m->ntris ? nkeys : m->ntris) * sizeof *g->prim + 1);
  if (!g->mat_slot || !cnt || !vk || !g->vorder || !g->vnew || !g->torder || !g->prim) {
    free(cnt);
    free(vk);
    return 0;
  }
  if (s)
    for (int i = 0; i < s->nmats; i++) {
      int b = s->mats[i].base, k = 0;
      for (int j = 0; j < b; j++) k += s->mats[j].base == j;
      g->mat_slot[i] = k;
    }
  for (int64_t v = 0; v < m->nverts; v++) vk[v] = -1;
  for (int64_t t = 0; t < m->ntris; t++) {
    int64_t k = tri_key(m, g, t);
    cnt[k + 1]++;
    for (int c = 0; c < 3; c++) vk[m->tri[3 * t + c]] = k;
  }
  for (int64_t k = 0; k < nkeys; k++) cnt[k + 1] += cnt[k];
  g->nprim = 0;
  for (int64_t k = 0; k < nkeys; k++) /* primitives, triangles in key order */
    if (cnt[k + 1] > cnt[k]) {
      gprim *p = &g->prim[g->nprim++];
      memset(p, 0, sizeof *p);
      p->obj = (int)(k / g->nmat);
      p->mat = (int)(k % g->nmat);
      p->t0 = cnt[k];
      p->nt = cnt[k + 1] - cnt[k];
    }
  int64_t *fill = malloc((size_t)nkeys * sizeof *fill + 1);
  if (!fill) {
    free(cnt);
    free(vk);
    return 0;
  }
  memcpy(fill, cnt, (size_t)nkeys * sizeof *fill);
  for (int64_t t = 0; t < m->ntris; t++) g->torder[fill[tri_key(m, g, t)]++] = t;
  /* vertices: counted by key, placed in key order (unused vertices are not written) */
  memset(cnt, 0, (size_t)(nkeys + 1) * sizeof *cnt);
  for (int64_t v = 0; v < m->nverts; v++)
    if (vk[v] >= 0) cnt[vk[v] + 1]++;
  for (int64_t k = 0; k < nkeys; k++) cnt[k + 1] += cnt[k];
  memcpy(fill, cnt, (size_t)nkeys * sizeof *fill);
  for (int64_t v = 0; v < m->nverts; v++) {
    g->vnew[v] = -1;
    if (vk[v] >= 0) {
      g->vnew[v] = fill[vk[v]];
      g->vorder[fill[vk[v]]++] = v;
    }
  }
  for (int i = 0; i < g->nprim; i++) {
    gprim *p = &g->prim[i];
    int64_t k = (int64_t)p->obj * g->nmat + p->mat;
    p->v0 = cnt[k];
    p->nv = cnt[k + 1] - cnt[k];
    for (int c = 0; c < 3; c++) p->lo[c] = INFINITY, p->hi[c] = -INFINITY;
    for (int64_t j = p->v0; j < p->v0 + p->nv; j++)
      for (int c = 0; c < 3; c++) {
        float x = m->pos[3 * g->vorder[j] + c];
        if (x < p->lo[c]) p->lo[c] = x;
        if (x > p->hi[c]) p->hi[c] = x;
      }
  }
  free(fill);
  free(cnt);
  free(vk);
  return 1;
}

/* The name of object 'o' and of material slot 'k' for the glTF. */
static const char *obj_name(const hr_scene *s, int o) {
  const char *n = s ? hr_scene_object_name(s, o) : NULL;
  return n ? n : "radiosity";
}

static const char *mat_name(const hr_scene *s, int k) {
  int i = s ? hr_scene_material_at(s, k) : -1;
  return i >= 0 ? s->mats[i].name : "radiosity";
}

/* The JSON chunk of the GLB: nodes and meshes per object, materials, buffer views, accessors. */
static void glb_json(sbuf *j, const hr_mesh *m, const glayout *g, double exposure,
                     size_t npos, size_t nidx) {
  const hr_scene *s = m->scene;
  sb_printf(j, "\"extensionsUsed\":[\"KHR_materials_unlit\"],\"scene\":0,\"scenes\":[{\"nodes\":[");
  int nmesh = 0; /* objects without triangles get no node */
  for (int i = 0; i < g->nprim; i++)
    if (i == 0 || g->prim[i].obj != g->prim[i - 1].obj) {
      sb_printf(j, "%s%d", nmesh ? "," : "", nmesh);
      nmesh++;
    }
  sb_printf(j, "]}],\"nodes\":[");
  for (int i = 0, k = 0; i < g->nprim; k++) {
    int o = g->prim[i].obj;
    sb_printf(j, "%s{\"mesh\":%d,\"name\":", k ? "," : "", k);
    sb_json_string(j, obj_name(s, o));
    sb_printf(j, "}");
    while (i < g->nprim && g->prim[i].obj == o) i++;
  }
  sb_printf(j, "],\"meshes\":[");
  for (int i = 0, k = 0; i < g->nprim; k++) {
    int o = g->prim[i].obj;
    sb_printf(j, "%s{\"name\":", k ? "," : "");
    sb_json_string(j, obj_name(s, o));
    sb_printf(j, ",\"primitives\":[");
    for (int first = 1; i < g->nprim && g->prim[i].obj == o; i++, first = 0)
      sb_printf(j,
                "%s{\"attributes\":{\"POSITION\":%d,\"COLOR_0\":%d,\"_RADIOSITY\":%d},"
                "\"indices\":%d,\"material\":%d,\"mode\":4}",
                first ? "" : ",", 4 * i, 4 * i + 1, 4 * i + 2, 4 * i + 3, g->prim[i].mat);
    sb_printf(j, "]}");
  }
  sb_printf(j, "],\"materials\":[");
  for (int k = 0; k < g->nmat; k++) {
    int mi = s ? hr_scene_material_at(s, k) : -1;
    const double *r = mi >= 0 ? s->mats[mi].rho : NULL, *e = mi >= 0 ? s->mats[mi].emit : NULL;
    sb_printf(j, "%s{\"name\":", k ? "," : "");
    sb_json_string(j, mat_name(s, k));
    sb_printf(j, ",\"pbrMetallicRoughness\":{\"baseColorFactor\":[1,1,1,1],\"metallicFactor\":0,"
                 "\"roughnessFactor\":1},\"doubleSided\":false,"
                 "\"extensions\":{\"KHR_materials_unlit\":{}}");
    if (r)
      sb_printf(j, ",\"extras\":{\"reflectance\":[%.9g,%.9g,%.9g],\"emission\":[%.9g,%.9g,%.9g]}",
                r[0], r[1], r[2], e[0], e[1], e[2]);
    sb_printf(j, "}");
  }
  size_t binlen = 3 * npos + nidx;
  sb_printf(j,
            "],\"buffers\":[{\"byteLength\":%zu}],\"bufferViews\":["
            "{\"buffer\":0,\"byteOffset\":0,\"byteLength\":%zu,\"byteStride\":12,"
            "\"target\":34962},"
            "{\"buffer\":0,\"byteOffset\":%zu,\"byteLength\":%zu,\"byteStride\":12,"
            "\"target\":34962},"
            "{\"buffer\":0,\"byteOffset\":%zu,\"byteLength\":%zu,\"byteStride\":12,"
            "\"target\":34962},"
            "{\"buffer\":0,\"byteOffset\":%zu,\"byteLength\":%zu,\"target\":34963}],"
            "\"accessors\":[",
            binlen, npos, npos, npos, 2 * npos, npos, 3 * npos, nidx);
  for (int i = 0; i < g->nprim; i++) {
    const gprim *p = &g->prim[i];
    long long vo = (long long)p->v0 * 12, nv = (long long)p->nv;
    sb_printf(j,
              "%s{\"bufferView\":0,\"byteOffset\":%lld,\"componentType\":5126,\"count\":%lld,"
              "\"type\":\"VEC3\",\"min\":[%.9g,%.9g,%.9g],\"max\":[%.9g,%.9g,%.9g]},"
              "{\"bufferView\":1,\"byteOffset\":%lld,\"componentType\":5126,\"count\":%lld,"
              "\"type\":\"VEC3\"},"
              "{\"bufferView\":2,\"byteOffset\":%lld,\"componentType\":5126,\"count\":%lld,"
              "\"type\":\"VEC3\"},"
              "{\"bufferView\":3,\"byteOffset\":%lld,\"componentType\":5125,\"count\":%lld,"
              "\"type\":\"SCALAR\"}",
              i ? "," : "", vo, nv, (double)p->lo[0], (double)p->lo[1], (double)p->lo[2],
              (double)p->hi[0], (double)p->hi[1], (double)p->hi[2], vo, nv, vo, nv,
              (long long)p->t0 * 12, (long long)p->nt * 3);
  }
  sb_printf(j, "]}");
  (void)exposure;
}

/* Writes the BIN chunk's vertex arrays in writer order: pass 0 positions, 1 COLOR_0, 2 B. */
static int glb_put_verts(FILE *fp, const hr_mesh *m, const glayout *g, int64_t nv,
                         double exposure, int *e) {
  enum { CHUNK = 4096 };
  uint8_t buf[CHUNK * 12];
  for (int pass = 0; pass < 3; pass++)
    for (int64_t v0 = 0; v0 < nv; v0 += CHUNK) {
      int64_t v1 = v0 + CHUNK < nv ? v0 + CHUNK : nv;
      uint8_t *p = buf;
      for (int64_t w = v0; w < v1; w++)
        for (int c = 0; c < 3; c++, p += 4) {
          int64_t v = g->vorder[w];
          float x = pass == 0 ? m->pos[3 * v + c] : m->B[3 * v + c];
          if (pass == 1) {
            x = (float)(m->B[3 * v + c] * exposure);
            if (!(x > 0)) x = 0; /* also NaN */
            if (x > 1) x = 1;
          }
          put_f32(p, x);
        }
      if (fwrite(buf, 1, (size_t)(p - buf), fp) != (size_t)(p - buf)) {
        *e = errno;
        return 0;
      }
    }
  return 1;
}

/* Writes the indices, each relative to its primitive's first vertex. */
static int glb_put_tris(FILE *fp, const hr_mesh *m, const glayout *g, int *e) {
  enum { CHUNK = 4096 };
  uint8_t buf[CHUNK * 12];
  for (int i = 0; i < g->nprim; i++) {
    const gprim *pr = &g->prim[i];
    for (int64_t t0 = pr->t0; t0 < pr->t0 + pr->nt; t0 += CHUNK) {
      int64_t t1 = t0 + CHUNK < pr->t0 + pr->nt ? t0 + CHUNK : pr->t0 + pr->nt;
      uint8_t *p = buf;
      for (int64_t w = t0; w < t1; w++)
        for (int c = 0; c < 3; c++, p += 4)
          put_u32(p, (uint32_t)(g->vnew[m->tri[3 * g->torder[w] + c]] - pr->v0));
      if (fwrite(buf, 1, (size_t)(p - buf), fp) != (size_t)(p - buf)) {
        *e = errno;
        return 0;
      }
    }
  }
  return 1;
}

hr_status hr_glb_write(const char *path, const hr_mesh *m, double exposure, hr_err *err) {
  if (!m || !path) return hr_err_set(err, HR_ERR_INVALID, "hr_glb_write: no mesh or path");
  if (!isfinite(exposure) || exposure < 0)
    return hr_err_set(err, HR_ERR_INVALID, "%s: bad exposure %g", path, exposure);
  int has = m->nverts > 0 && m->ntris > 0;
  glayout g;
  memset(&g, 0, sizeof g);
  if (has && !glayout_build(m, &g)) {
    glayout_free(&g);
    return hr_err_set(err, HR_ERR_NOMEM, "%s: out of memory", path);
  }
  int64_t nv = 0;
  for (int i = 0; i < g.nprim; i++) nv += g.prim[i].nv;
  size_t npos = has ? (size_t)nv * 12 : 0, nidx = has ? (size_t)m->ntris * 12 : 0;
  size_t binlen = 3 * npos + nidx; /* all multiples of 4 */
  sbuf j = {0};
  sb_printf(&j,
            "{\"asset\":{\"version\":\"2.0\",\"generator\":\"hrad\","
            "\"extras\":{\"exposure\":%.17g,\"colors\":\"COLOR_0 = linear radiosity * exposure, "
            "clamped to [0,1]; _RADIOSITY = linear radiosity B in W/m^2, unclamped\"}},",
            exposure);
  if (!has) {
    j.len--; /* an empty model: the asset alone */
    sb_printf(&j, "}");
  } else {
    glb_json(&j, m, &g, exposure, npos, nidx);
  }
  if (j.nomem) {
    free(j.s);
    glayout_free(&g);
    return hr_err_set(err, HR_ERR_NOMEM, "%s: out of memory", path);
  }
  size_t jlen = (j.len + 3) & ~(size_t)3;
  size_t total = 12 + 8 + jlen + (has ? 8 + binlen : 0);
  if (total > UINT32_MAX) {
    free(j.s);
    glayout_free(&g);
    return hr_err_set(err, HR_ERR_TOO_BIG, "%s: mesh too large for GLB (%zu bytes)", path, total);
  }
  FILE *fp = fopen(path, "wb");
  if (!fp) {
    int e = errno;
    free(j.s);
    glayout_free(&g);
    return hr_err_set(err, HR_ERR_IO, "%s: cannot open for writing: %s", path, strerror(e));
  }
  uint8_t hdr[20];
  put_u32(hdr, 0x46546C67u); /* "glTF" */
  put_u32(hdr + 4, 2);
  put_u32(hdr + 8, (uint32_t)total);
  put_u32(hdr + 12, (uint32_t)jlen);
  put_u32(hdr + 16, 0x4E4F534Au); /* "JSON" */
  int ok = fwrite(hdr, 1, 20, fp) == 20 && fwrite(j.s, 1, j.len, fp) == j.len;
  for (size_t i = j.len; i < jlen && ok; i++) ok = fputc(' ', fp) != EOF;
  int e = ok ? 0 : errno;
  free(j.s);
  if (has && ok) {
    uint8_t ch[8];
    put_u32(ch, (uint32_t)binlen);
    put_u32(ch + 4, 0x004E4942u); /* "BIN\0" */
    ok = fwrite(ch, 1, 8, fp) == 8;
    if (!ok) e = errno;
    ok = ok && glb_put_verts(fp, m, &g, nv, exposure, &e) && glb_put_tris(fp, m, &g, &e);
  }
  glayout_free(&g);
  return hr_file_close(fp, path, ok, e, err);
}
