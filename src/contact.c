/* contact.c: cutting large surfaces along the lines where other surfaces stand on them or pass
 * through them (hr_scene_cut_contacts), before the solver meshes them.
 *
 * Why: an element is a regular subdivision of its surface down to A_e. The conference room's
 * floor and ceiling are two triangles each and run through a closed pillar that the ceiling
 * (an emitter) lights from inside; their elements reach across the pillar's walls, so one
 * radiosity is the mean of the lit room and the dim inside, and the faces inside see the
 * room's light through it (a leak: +38-49% on them). Cutting the floor along the wall's foot
 * first puts every element on one side. This is the coarse end of discontinuity meshing
 * (Heckbert 1992; Lischinski, Tampieri & Greenberg 1992): the contact lines (D0
 * discontinuities of the radiosity) only, not the shadow lines.
 *
 * How, per surface S of at least len x len area (eps = len / 256, delta = len / 2):
 *  1. every surface Q whose box meets S's (a grid of cells, so O(n) in all), that is not
 *     parallel to S, touches or crosses S's plane and reaches at least len in front of it (a
 *     wall, not a chair's runner or a plinth) gives a segment: its points on the plane
 *     (vertices within eps, edge crossings), clipped to S;
 *  2. segments on one line (angle within half a degree, offset within delta / 2) merge into a
 *     line; parts shorter than len / 4 after bridging gaps up to delta (a table's leg) are
 *     dropped, and a line is kept if the rest covers at least len / 2 and S is open on both
 *     of its sides (side_open: rays from S at delta / 2 beside it reach open space, not only
 *     the backs of faces). Where one side is closed (the floor under a box, inside a cabinet)
 *     the open fraction (hr_vf_open) already keeps the hidden part's dark out of the light its
 *     elements send, and cutting there measured worse (BENCHMARKS.md, "Contact cuts");
 *  3. the kept lines, longest first, cut S's convex pieces, only over their covered part: a
 *     piece the line covers for at least len / 4 is cut across the line where the covered part
 *     ends (along a kept line crossing there, or square to it), then along it, if both sides
 *     keep a width of delta (a 9 mm plinth in front of a wall makes no 9 mm strip);
 *  4. pieces much longer than wide are chopped (chop);
 *  5. each piece becomes convex quads and triangles (a fan of quads) with S's material and
 *     polygon, marked 'cut': outputs per polygon keep their rows, and the solver gives a piece
 *     its polygon's importance. The CLI passes len = sqrt(A_e). */
#include "hrad.h"
#include "vec.h"
#include "vis.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define CUT_MAXV 64      /* vertices a piece may have (cuts add at most one each) */
#define CUT_ANGLE 0.0087 /* radians: half a degree, one line */
#define CHOP_RATIO 3.0    /* chop: diameter over width across it */
#define CUT_PARALLEL 0.985 /* |n_S . n_Q| above: parallel, no contact line */

typedef struct {
  double x, y;
} p2;

typedef struct {
  int n;
  p2 v[CUT_MAXV];
} piece;

typedef struct {
  p2 a, b;    /* endpoints in S's plane */
  int bucket; /* its direction's angle in [0, pi) over CUT_ANGLE, rounded */
  double off; /* signed offset of the line at the bucket's angle */
} seg;

typedef struct {
  p2 o, u;          /* a point and unit direction */
  double covered;   /* length covered by segments, gaps up to delta bridged */
  double *t;        /* covered intervals along u from o: [t[2k], t[2k+1]] */
  int nt;
} line2;

/* ---------------------------------------------------------------- a grid over the boxes */

typedef struct {
  uint64_t key;
  int id;
} cell_ref;

typedef struct {
  hr_vec3 lo;
  double h;       /* cell size */
  cell_ref *refs; /* sorted by key */
  int64_t nrefs;
  int *big;       /* surfaces over too many cells: checked always */
  int nbig;
} grid;

#define GRID_MAX_CELLS 4096 /* a surface over more cells goes into the 'big' list */

static uint64_t cell_key(int64_t x, int64_t y, int64_t z) {
  return ((uint64_t)x & 0x1fffff) | (((uint64_t)y & 0x1fffff) << 21) |
         (((uint64_t)z & 0x1fffff) << 42);
}

static void surf_box(const hr_surface *f, hr_vec3 *lo, hr_vec3 *hi) {
  *lo = *hi = f->v[0];
  for (int k = 1; k < f->nverts; k++) {
    *lo = v3_min(*lo, f->v[k]);
    *hi = v3_max(*hi, f->v[k]);
  }
}

static void cell_range(const grid *g, hr_vec3 lo, hr_vec3 hi, int64_t *a, int64_t *b) {
  double l[3] = {lo.x - g->lo.x, lo.y - g->lo.y, lo.z - g->lo.z};
  double h[3] = {hi.x - g->lo.x, hi.y - g->lo.y, hi.z - g->lo.z};
  for (int k = 0; k < 3; k++) {
    a[k] = (int64_t)floor(l[k] / g->h);
    b[k] = (int64_t)floor(h[k] / g->h);
    if (a[k] < 0) a[k] = 0;
    if (b[k] > 0x1fffff) b[k] = 0x1fffff;
    if (b[k] < a[k]) b[k] = a[k];
  }
}

static int64_t cell_count(const int64_t *a, const int64_t *b) {
  return (b[0] - a[0] + 1) * (b[1] - a[1] + 1) * (b[2] - a[2] + 1);
}

static int cmp_ref(const void *pa, const void *pb) {
  const cell_ref *a = pa, *b = pb;
  if (a->key != b->key) return a->key < b->key ? -1 : 1;
  return (a->id > b->id) - (a->id < b->id);
}

static int grid_build(const hr_scene *s, double eps, grid *g) {
  memset(g, 0, sizeof *g);
  hr_vec3 lo, hi;
  hr_scene_bounds(s, &lo, &hi);
  g->lo = v3_sub(lo, v3(eps, eps, eps));
  double ext = fmax(hi.x - lo.x, fmax(hi.y - lo.y, hi.z - lo.z)) + 2 * eps;
  /* about 2n cells' worth of side over the largest extent, at most 2^21 per axis */
  g->h = fmax(ext / 2e6, ext / fmax(1.0, cbrt(2.0 * s->nsurfs) * 4));
  int64_t total = 0;
  for (int i = 0; i < s->nsurfs; i++) {
    int64_t a[3], b[3];
    surf_box(&s->surfs[i], &lo, &hi);
    cell_range(g, lo, hi, a, b);
    int64_t c = cell_count(a, b);
    if (c <= GRID_MAX_CELLS) total += c;
  }
  g->refs = malloc((size_t)(total ? total : 1) * sizeof *g->refs);
  g->big = malloc((size_t)s->nsurfs * sizeof *g->big);
  if (!g->refs || !g->big) return 0;
  for (int i = 0; i < s->nsurfs; i++) {
    int64_t a[3], b[3];
    surf_box(&s->surfs[i], &lo, &hi);
    cell_range(g, lo, hi, a, b);
    if (cell_count(a, b) > GRID_MAX_CELLS) {
      g->big[g->nbig++] = i;
      continue;
    }
    for (int64_t x = a[0]; x <= b[0]; x++)
      for (int64_t y = a[1]; y <= b[1]; y++)
        for (int64_t z = a[2]; z <= b[2]; z++)
          g->refs[g->nrefs++] = (cell_ref){cell_key(x, y, z), i};
  }
  qsort(g->refs, (size_t)g->nrefs, sizeof *g->refs, cmp_ref);
  return 1;
}

static void grid_free(grid *g) {
  free(g->refs);
  free(g->big);
  memset(g, 0, sizeof *g);
}

/* ---------------------------------------------------------------- 2D helpers */

typedef struct {
  hr_vec3 o, u, w, n; /* S's plane: origin, in-plane axes, normal */
} frame;

static p2 to2(const frame *f, hr_vec3 p) {
  hr_vec3 d = v3_sub(p, f->o);
  return (p2){v3_dot(d, f->u), v3_dot(d, f->w)};
}

static hr_vec3 to3(const frame *f, p2 p) {
  return v3_add(f->o, v3_add(v3_scale(f->u, p.x), v3_scale(f->w, p.y)));
}

/* S's plane and its outline in it (counter-clockwise, as S is seen from the front). */
static void make_frame(const hr_surface *sf, frame *f, piece *outline) {
  f->o = sf->v[0];
  f->n = sf->normal;
  f->u = v3_norm(v3_sub(sf->v[1], sf->v[0]));
  f->w = v3_cross(f->n, f->u);
  outline->n = sf->nverts;
  for (int k = 0; k < sf->nverts; k++) outline->v[k] = to2(f, sf->v[k]);
}

static double cross2(p2 a, p2 b) { return a.x * b.y - a.y * b.x; }
static p2 sub2(p2 a, p2 b) { return (p2){a.x - b.x, a.y - b.y}; }

/* Narrows [*t0, *t1] to the parameters t of o + t d inside convex counter-clockwise polygon
 * 'pc' (Cyrus-Beck); 0 if nothing is left. */
static int clip_param(const piece *pc, p2 o, p2 d, double *t0, double *t1) {
  for (int i = 0; i < pc->n; i++) {
    p2 e = sub2(pc->v[(i + 1) % pc->n], pc->v[i]);
    /* inside: cross(e, p - v_i) >= 0 */
    double num = cross2(e, sub2(o, pc->v[i])), den = cross2(e, d);
    if (den == 0) {
      if (num < 0) return 0;
      continue;
    }
    double t = -num / den;
    if (den > 0) {
      if (t > *t0) *t0 = t;
    } else if (t < *t1) {
      *t1 = t;
    }
  }
  return *t0 < *t1;
}

/* Clips segment a-b to convex counter-clockwise polygon 'pc'; 0 if nothing is left. */
static int clip_seg(const piece *pc, p2 *a, p2 *b) {
  double t0 = 0, t1 = 1;
  p2 a0 = *a, d = sub2(*b, *a);
  if (!clip_param(pc, a0, d, &t0, &t1)) return 0;
  *a = (p2){a0.x + t0 * d.x, a0.y + t0 * d.y};
  *b = (p2){a0.x + t1 * d.x, a0.y + t1 * d.y};
  return 1;
}

/* The chord of line (o, u) through convex piece 'pc': [*ta, *tb]; 0 if it misses. */
static int chord(const piece *pc, p2 o, p2 u, double *ta, double *tb) {
  *ta = -HUGE_VAL;
  *tb = HUGE_VAL;
  return clip_param(pc, o, u, ta, tb);
}

/* Drops vertices that repeat the previous one or lie on the line through their neighbours
 * (a cut through a corner); 0 if fewer than 3 remain. */
static int tidy(piece *pc) {
  int changed = 1;
  while (changed && pc->n >= 3) {
    changed = 0;
    for (int i = 0; i < pc->n && pc->n >= 3; i++) {
      p2 a = pc->v[(i + pc->n - 1) % pc->n], b = pc->v[i], c = pc->v[(i + 1) % pc->n];
      p2 e = sub2(c, a);
      double l2 = e.x * e.x + e.y * e.y;
      double h = cross2(e, sub2(b, a));
      if (h * h <= 1e-20 * l2 * l2) {
        memmove(&pc->v[i], &pc->v[i + 1], (size_t)(pc->n - i - 1) * sizeof *pc->v);
        pc->n--;
        changed = 1;
      }
    }
  }
  return pc->n >= 3;
}

/* Splits convex piece 'pc' by line (o, u) into left (cross(u, p - o) > 0) and right parts,
 * unless either would be narrower than 'delta' (then returns 0). */
static int split(const piece *pc, p2 o, p2 u, double delta, piece *l, piece *r) {
  double d[CUT_MAXV], dmin = 0, dmax = 0;
  for (int i = 0; i < pc->n; i++) {
    d[i] = cross2(u, sub2(pc->v[i], o));
    if (d[i] < dmin) dmin = d[i];
    if (d[i] > dmax) dmax = d[i];
  }
  if (dmax < delta || -dmin < delta || pc->n + 2 > CUT_MAXV) return 0;
  l->n = r->n = 0;
  for (int i = 0; i < pc->n; i++) {
    int j = (i + 1) % pc->n;
    if (d[i] >= 0) l->v[l->n++] = pc->v[i];
    if (d[i] <= 0) r->v[r->n++] = pc->v[i];
    if ((d[i] > 0 && d[j] < 0) || (d[i] < 0 && d[j] > 0)) {
      double t = d[i] / (d[i] - d[j]);
      p2 p = {pc->v[i].x + t * (pc->v[j].x - pc->v[i].x),
              pc->v[i].y + t * (pc->v[j].y - pc->v[i].y)};
      l->v[l->n++] = p;
      r->v[r->n++] = p;
    }
  }
  return tidy(l) && tidy(r);
}

/* ---------------------------------------------------------------- one surface */

/* The segment where surface 'q' meets S's plane, clipped to S ('outline'), if q reaches at
 * least 'tall' in front of S; 0 if none. */
static int contact_seg(const frame *f, const piece *outline, const hr_surface *q, double eps,
                       double tall, p2 *a, p2 *b) {
  if (fabs(v3_dot(q->normal, f->n)) > CUT_PARALLEL) return 0;
  double d[4], dmin = HUGE_VAL, dmax = -HUGE_VAL;
  for (int k = 0; k < q->nverts; k++) {
    d[k] = v3_dot(v3_sub(q->v[k], f->o), f->n);
    dmin = fmin(dmin, d[k]);
    dmax = fmax(dmax, d[k]);
  }
  /* behind S or in its plane, above it, or lower than 'tall' (a chair's runner, a plinth) */
  if (!(dmax > eps) || dmin > eps || dmax < tall) return 0;
  p2 pts[8];
  int np = 0;
  for (int k = 0; k < q->nverts; k++) {
    int j = (k + 1) % q->nverts;
    if (fabs(d[k]) <= eps) pts[np++] = to2(f, q->v[k]);
    if ((d[k] < -eps && d[j] > eps) || (d[k] > eps && d[j] < -eps)) {
      double t = d[k] / (d[k] - d[j]);
      pts[np++] = to2(f, v3_lerp(q->v[k], q->v[j], t));
    }
  }
  double best = 0;
  for (int i = 0; i < np; i++)
    for (int j = i + 1; j < np; j++) {
      p2 e = sub2(pts[j], pts[i]);
      double l2 = e.x * e.x + e.y * e.y;
      if (l2 > best) {
        best = l2;
        *a = pts[i];
        *b = pts[j];
      }
    }
  if (!(best > 0)) return 0;
  return clip_seg(outline, a, b);
}

static int cmp_seg(const void *pa, const void *pb) {
  const seg *a = pa, *b = pb;
  if (a->bucket != b->bucket) return a->bucket < b->bucket ? -1 : 1;
  if (a->off != b->off) return a->off < b->off ? -1 : 1;
  return 0;
}

static int cmp_dbl(const void *pa, const void *pb) {
  double a = *(const double *)pa, b = *(const double *)pb;
  return (a > b) - (a < b);
}

/* Merges segments [lo, hi) (one angle bucket, offsets within delta / 2) into a line: its
 * direction is the longest segment's; intervals along it, gaps up to delta bridged, those
 * shorter than min_part dropped. */
static int make_line(const seg *sg, int lo, int hi, double delta, double min_part,
                     line2 *ln) {
  int longest = lo;
  double lmax = -1;
  for (int i = lo; i < hi; i++) {
    p2 e = sub2(sg[i].b, sg[i].a);
    double l = sqrt(e.x * e.x + e.y * e.y);
    if (l > lmax) {
      lmax = l;
      longest = i;
    }
  }
  p2 e = sub2(sg[longest].b, sg[longest].a);
  ln->o = sg[longest].a;
  ln->u = (p2){e.x / lmax, e.y / lmax};
  int n = hi - lo;
  double *iv = malloc((size_t)n * 2 * sizeof *iv);
  if (!iv) return 0;
  for (int i = 0; i < n; i++) {
    double ta = ln->u.x * (sg[lo + i].a.x - ln->o.x) + ln->u.y * (sg[lo + i].a.y - ln->o.y);
    double tb = ln->u.x * (sg[lo + i].b.x - ln->o.x) + ln->u.y * (sg[lo + i].b.y - ln->o.y);
    iv[2 * i] = fmin(ta, tb);
    iv[2 * i + 1] = fmax(ta, tb);
  }
  /* sort intervals by start: pairs of doubles, sorted as 16-byte records */
  qsort(iv, (size_t)n, 2 * sizeof *iv, cmp_dbl);
  int m = 0;
  for (int i = 0; i < n; i++) {
    if (m > 0 && iv[2 * i] <= iv[2 * m - 1] + delta) {
      if (iv[2 * i + 1] > iv[2 * m - 1]) iv[2 * m - 1] = iv[2 * i + 1];
    } else {
      iv[2 * m] = iv[2 * i];
      iv[2 * m + 1] = iv[2 * i + 1];
      m++;
    }
  }
  /* contacts shorter than min_part (a table's leg) count for nothing: the cut would stop at
   * them and leave a piece's corner where they stand */
  int kept = 0;
  ln->covered = 0;
  for (int k = 0; k < m; k++) {
    if (iv[2 * k + 1] - iv[2 * k] < min_part) continue;
    iv[2 * kept] = iv[2 * k];
    iv[2 * kept + 1] = iv[2 * k + 1];
    ln->covered += iv[2 * kept + 1] - iv[2 * kept];
    kept++;
  }
  ln->t = iv;
  ln->nt = kept;
  return 1;
}

static int cmp_line(const void *pa, const void *pb) {
  const line2 *a = pa, *b = pb;
  if (a->covered != b->covered) return a->covered > b->covered ? -1 : 1;
  if (a->o.x != b->o.x) return a->o.x < b->o.x ? -1 : 1;
  return (a->o.y > b->o.y) - (a->o.y < b->o.y);
}

typedef struct {
  piece *p;
  int n, cap;
} piece_list;

static int push_piece(piece_list *pl, const piece *p) {
  if (pl->n == pl->cap) {
    int cap = pl->cap ? 2 * pl->cap : 8;
    piece *q = realloc(pl->p, (size_t)cap * sizeof *q);
    if (!q) return 0;
    pl->p = q;
    pl->cap = cap;
  }
  pl->p[pl->n++] = *p;
  return 1;
}

/* The covered length of line 'ln' within [ta, tb], and the hull [*c0, *c1] of its covered
 * intervals there. */
static double covered_in(const line2 *ln, double ta, double tb, double *c0, double *c1) {
  double c = 0;
  *c0 = tb;
  *c1 = ta;
  for (int k = 0; k < ln->nt; k++) {
    double a = fmax(ln->t[2 * k], ta), b = fmin(ln->t[2 * k + 1], tb);
    if (b > a) {
      c += b - a;
      *c0 = fmin(*c0, a);
      *c1 = fmax(*c1, b);
    }
  }
  return c;
}

static p2 at_t(const line2 *ln, double t) {
  return (p2){ln->o.x + t * ln->u.x, ln->o.y + t * ln->u.y};
}

/* Splits 'mid' by line (o, dir) when both sides keep 'delta': the side holding point 'away'
 * goes to *outside, the other stays in 'mid'. 1 if it split. */
static int bound(piece *mid, p2 o, p2 dir, p2 away, double delta, piece *outside) {
  piece l, r;
  if (!split(mid, o, dir, delta, &l, &r)) return 0;
  int away_left = cross2(dir, sub2(away, o)) > 0;
  *outside = away_left ? l : r;
  *mid = away_left ? r : l;
  return 1;
}

/* The line a cut along 'ln' should stop at near parameter t: another kept line crossing it at
 * an angle of 30 degrees or more within delta of t (a box's next side), or else the
 * perpendicular at t. */
static void stop_line(const line2 *ln, const line2 *lines, int nl, double t, double delta,
                      p2 *o, p2 *dir) {
  double best = delta;
  *o = at_t(ln, t);
  *dir = (p2){-ln->u.y, ln->u.x};
  for (int k = 0; k < nl; k++) {
    const line2 *m = &lines[k];
    double den = cross2(ln->u, m->u);
    if (m == ln || fabs(den) < 0.5) continue;
    /* ln->o + s u = m->o + r m->u: s = cross(m->o - ln->o, m->u) / cross(u, m->u) */
    double sx = cross2(sub2(m->o, ln->o), m->u) / den;
    if (fabs(sx - t) <= best) {
      best = fabs(sx - t);
      *o = m->o;
      *dir = m->u;
    }
  }
}

/* Cuts piece i of 'out' along line 'ln' over the line's covered part only: first across it
 * where that part ends (at a crossing contact line there, or square to it) if the piece
 * reaches at least delta beyond, then along it; nothing unless the cut along the line keeps
 * both sides delta wide. *cut = 1 when it cut. 0 when out of memory. */
static int cut_piece(piece_list *out, int i, const line2 *ln, const line2 *lines, int nl,
                     double len, double delta, int *cut) {
  double ta, tb, c0, c1;
  if (!chord(&out->p[i], ln->o, ln->u, &ta, &tb)) return 1;
  if (covered_in(ln, ta, tb, &c0, &c1) < len / 4) return 1;
  piece mid = out->p[i], before, after, l, r;
  int has_before = 0, has_after = 0;
  p2 o, dir;
  if (c0 - ta >= delta) {
    stop_line(ln, lines, nl, c0, delta, &o, &dir);
    has_before = bound(&mid, o, dir, at_t(ln, ta), delta, &before);
  }
  if (tb - c1 >= delta) {
    stop_line(ln, lines, nl, c1, delta, &o, &dir);
    has_after = bound(&mid, o, dir, at_t(ln, tb), delta, &after);
  }
  if (!split(&mid, ln->o, ln->u, delta, &l, &r)) return 1;
  out->p[i] = l;
  *cut = 1;
  return push_piece(out, &r) && (!has_before || push_piece(out, &before)) &&
         (!has_after || push_piece(out, &after));
}

/* Chops piece i of 'out' across its diameter into pieces about twice as long as wide when the
 * diameter is more than 'ratio' times the piece's width across it (a rectangle about twice
 * 'ratio' as long as wide: a strip along a wall, whose regular subdivision would make sliver
 * elements). 0 when out of memory. Chopping squarer pieces, or across the longest side
 * instead of the diameter, measured worse (BENCHMARKS.md, "Contact cuts"). */
static int chop(piece_list *out, int i, double ratio) {
  const piece *pc = &out->p[i];
  double best = 0;
  p2 u = {1, 0}, o = pc->v[0];
  for (int a = 0; a < pc->n; a++)
    for (int b = a + 1; b < pc->n; b++) {
      p2 e = sub2(pc->v[b], pc->v[a]);
      double l2 = e.x * e.x + e.y * e.y;
      if (l2 > best) {
        best = l2;
        u = (p2){e.x / sqrt(l2), e.y / sqrt(l2)};
        o = pc->v[a];
      }
    }
  double t0 = 0, t1 = 0, w0 = 0, w1 = 0;
  for (int a = 0; a < pc->n; a++) {
    p2 d = sub2(pc->v[a], o);
    double t = u.x * d.x + u.y * d.y, w = cross2(u, d);
    t0 = fmin(t0, t), t1 = fmax(t1, t), w0 = fmin(w0, w), w1 = fmax(w1, w);
  }
  double length = t1 - t0, width = w1 - w0;
  if (!(width > 0) || !(length > ratio * width)) return 1;
  int k = (int)fmin(32, ceil(length / (2 * width)));
  p2 n = {-u.y, u.x};
  line2 ln = {.o = o, .u = u};
  for (int j = k - 1; j >= 1; j--) {
    piece l, r;
    if (!split(&out->p[i], at_t(&ln, t0 + j * length / k), n, 0, &l, &r)) continue;
    out->p[i] = l;
    if (!push_piece(out, &r)) return 0;
  }
  return 1;
}

/* What cutting one surface after another shares. */
typedef struct {
  const hr_scene *s;
  grid g;
  hr_vis *vis;  /* the uncut scene's, for the open test (NULL until a line needs it) */
  double lift;  /* hr_vis_lift */
  double len;
  int *stamp;   /* stamp[q] = the surface that last looked at q */
  seg *segs;
  int capsegs;
  piece_list out;
} cut_ctx;

/* 1 if a point of S (lifted off it) sees open space: of five rays, along S's normal and 60
 * degrees from it towards its four in-plane axes, one leaves the scene or meets the front of a
 * surface. A point under a box or inside a closed cabinet meets only backs. */
static int point_open(const cut_ctx *c, const frame *f, const float org[3]) {
  const double ct = 0.5, st = 0.8660254037844386;
  for (int r = 0; r < 5; r++) {
    hr_vec3 d = f->n;
    if (r > 0) {
      hr_vec3 a = r <= 2 ? f->u : f->w;
      d = v3_add(v3_scale(f->n, ct), v3_scale(a, r % 2 ? st : -st));
    }
    const float dir[3] = {(float)d.x, (float)d.y, (float)d.z};
    float t;
    int hit = hr_vis_hit(c->vis, org, dir, INFINITY, &t);
    if (hit < 0 || v3_dot(c->s->surfs[hit].normal, d) < 0) return 1;
  }
  return 0;
}

/* 1 if most points of S at distance h from line 'ln' on side 'side' (+1: left, -1: right),
 * beside the line's covered part, are open (point_open). Where one side is closed (the floor
 * under a box, inside a cabinet), the open fraction of the elements that reach there
 * (hr_vf_open) already keeps its dark from the light they send; only a contact line with open
 * space on both sides (a thin wall, a closed pillar's inside lit by the ceiling that runs
 * through it) leaks. */
static int side_open(const cut_ctx *c, const frame *f, const piece *outline, const line2 *ln,
                     int side, double h) {
  const p2 nn = {-ln->u.y * side * h, ln->u.x * side * h};
  int tried = 0, open = 0;
  for (int k = 0; k < ln->nt && tried < 16; k++) {
    const double a = ln->t[2 * k], L = ln->t[2 * k + 1] - a;
    const int m = (int)fmin(4, ceil(L / h));
    for (int j = 0; j < m && tried < 16; j++) {
      p2 p = at_t(ln, a + (j + 0.5) * L / m);
      p.x += nn.x;
      p.y += nn.y;
      p2 q = p; /* inside S? (a zero-length clip of the point) */
      if (!clip_seg(outline, &p, &q)) continue;
      hr_vec3 x = v3_add(to3(f, p), v3_scale(f->n, c->lift));
      const float org[3] = {(float)x.x, (float)x.y, (float)x.z};
      tried++;
      open += point_open(c, f, org);
    }
  }
  return tried > 0 && 2 * open > tried;
}

/* Appends the contact segment of every surface near S (surface si) to c->segs; their number,
 * or -1 when out of memory. */
static int gather_segs(cut_ctx *c, int si, const frame *f, const piece *outline, double eps) {
  const hr_scene *s = c->s;
  const grid *g = &c->g;
  hr_vec3 lo, hi;
  surf_box(&s->surfs[si], &lo, &hi);
  lo = v3_sub(lo, v3(eps, eps, eps));
  hi = v3_add(hi, v3(eps, eps, eps));
  int64_t a[3], b[3];
  cell_range(g, lo, hi, a, b);
  int ns = 0;
  /* pass 0: the surfaces over too many cells; pass 1: the cells of S's box */
  for (int pass = 0; pass < 2; pass++) {
    int64_t x = a[0], y = a[1], z = a[2];
    const int64_t nb = pass == 0 ? g->nbig : cell_count(a, b);
    for (int64_t cell = 0; cell < nb; cell++) {
      int64_t r0 = cell, r1 = cell + 1;
      if (pass == 1) {
        const uint64_t key = cell_key(x, y, z);
        int64_t l = 0, h = g->nrefs;
        while (l < h) {
          int64_t m = (l + h) / 2;
          if (g->refs[m].key < key) l = m + 1;
          else h = m;
        }
        for (r0 = r1 = l; r1 < g->nrefs && g->refs[r1].key == key; r1++) {}
        if (++z > b[2]) {
          z = a[2];
          if (++y > b[1]) {
            y = a[1];
            x++;
          }
        }
      }
      for (int64_t r = r0; r < r1; r++) {
        const int qi = pass == 0 ? g->big[r] : g->refs[r].id;
        if (qi == si || c->stamp[qi] == si) continue;
        c->stamp[qi] = si;
        const hr_surface *q = &s->surfs[qi];
        hr_vec3 ql, qh;
        surf_box(q, &ql, &qh);
        if (ql.x > hi.x || ql.y > hi.y || ql.z > hi.z || qh.x < lo.x || qh.y < lo.y ||
            qh.z < lo.z)
          continue;
        p2 pa, pb;
        if (!contact_seg(f, outline, q, eps, c->len, &pa, &pb)) continue;
        if (ns == c->capsegs) {
          int cap = c->capsegs ? 2 * c->capsegs : 64;
          seg *ng = realloc(c->segs, (size_t)cap * sizeof *ng);
          if (!ng) return -1;
          c->segs = ng;
          c->capsegs = cap;
        }
        p2 e = sub2(pb, pa);
        double ang = atan2(e.y, e.x);
        if (ang < 0) ang += M_PI;
        int bucket = (int)floor(ang / CUT_ANGLE + 0.5);
        if (bucket >= (int)floor(M_PI / CUT_ANGLE + 0.5)) bucket = 0; /* pi is 0 */
        const double ab = bucket * CUT_ANGLE;
        c->segs[ns++] = (seg){pa, pb, bucket, -sin(ab) * pa.x + cos(ab) * pa.y};
      }
    }
  }
  return ns;
}

/* Merges the 'ns' segments of c->segs into lines and keeps those that cover enough of S with
 * open space on both sides (lines[0 .. return value)); -1 when out of memory. */
static int keep_lines(cut_ctx *c, int ns, const frame *f, const piece *outline, line2 *lines) {
  const double len = c->len, delta = len / 2;
  qsort(c->segs, (size_t)ns, sizeof *c->segs, cmp_seg);
  int nl = 0;
  for (int i = 0; i < ns;) {
    int j = i + 1;
    while (j < ns && c->segs[j].bucket == c->segs[i].bucket &&
           c->segs[j].off - c->segs[i].off <= delta / 2)
      j++;
    line2 ln;
    if (!make_line(c->segs, i, j, delta, len / 4, &ln)) {
      for (int k = 0; k < nl; k++) free(lines[k].t);
      return -1;
    }
    /* the ray casting structure, built when a first line needs the open test */
    if (ln.covered >= len / 2 && !c->vis) {
      hr_err err;
      if (hr_vis_create(c->s, &c->vis, &err) != HR_OK) {
        free(ln.t);
        for (int k = 0; k < nl; k++) free(lines[k].t);
        return -1;
      }
    }
    if (ln.covered >= len / 2 && side_open(c, f, outline, &ln, 1, delta / 2) &&
        side_open(c, f, outline, &ln, -1, delta / 2))
      lines[nl++] = ln;
    else
      free(ln.t);
    i = j;
  }
  return nl;
}

/* Cuts surface 'si' into pieces (c->out; one piece, S itself, when nothing cuts it). Counts the
 * lines it cut along in *nlines. 0 when out of memory. */
static int cut_surface(cut_ctx *c, int si, int *nlines) {
  const double len = c->len, eps = len / 256, delta = len / 2;
  piece_list *out = &c->out;
  frame f;
  piece outline;
  make_frame(&c->s->surfs[si], &f, &outline);
  out->n = 0;
  *nlines = 0;
  const int ns = gather_segs(c, si, &f, &outline, eps);
  if (ns < 0 || !push_piece(out, &outline)) return 0;
  if (ns == 0) return 1;
  line2 *lines = malloc((size_t)ns * sizeof *lines);
  if (!lines) return 0;
  const int nl = keep_lines(c, ns, &f, &outline, lines);
  int ok = nl >= 0;
  if (ok) qsort(lines, (size_t)nl, sizeof *lines, cmp_line);
  for (int k = 0; k < nl && ok; k++) {
    int cut = 0, n0 = out->n;
    for (int i = 0; i < n0 && ok; i++)
      ok = cut_piece(out, i, &lines[k], lines, nl, len, delta, &cut);
    *nlines += cut;
  }
  for (int k = 0; k < nl; k++) free(lines[k].t);
  free(lines);
  if (*nlines > 0)
    for (int i = 0, n0 = out->n; i < n0 && ok; i++) ok = chop(out, i, CHOP_RATIO);
  return ok;
}

/* A piece's corner in 3D: S's own vertex, bit for bit, where it is one. */
static hr_vec3 corner(const frame *f, const hr_surface *sf, const piece *outline, p2 p) {
  for (int k = 0; k < outline->n; k++)
    if (outline->v[k].x == p.x && outline->v[k].y == p.y) return sf->v[k];
  return to3(f, p);
}

/* Appends piece 'pc' of surface 'sf' as convex quads and triangles (a fan of quads from its
 * first vertex), marked as pieces. 0 when out of memory. */
static int emit_piece(const frame *f, const hr_surface *sf, const piece *outline,
                      const piece *pc, hr_surface **dst, int *n, int *cap) {
  for (int i = 1; i + 1 < pc->n; i += 2) {
    int nv = i + 2 < pc->n ? 4 : 3;
    if (*n == *cap) {
      int c = 2 * *cap + 16;
      hr_surface *d = realloc(*dst, (size_t)c * sizeof *d);
      if (!d) return 0;
      *dst = d;
      *cap = c;
    }
    hr_surface *o = &(*dst)[(*n)++];
    *o = *sf;
    o->nverts = nv;
    o->v[0] = corner(f, sf, outline, pc->v[0]);
    for (int k = 1; k < nv; k++) o->v[k] = corner(f, sf, outline, pc->v[i + k - 1]);
    hr_vec3 nn = v3_newell(o->v, nv);
    o->area = 0.5 * v3_len(nn);
    o->normal = sf->normal;
    o->cut = 1;
  }
  return 1;
}

hr_status hr_scene_cut_contacts(hr_scene *s, double len, hr_cut_stats *stats) {
  hr_cut_stats st = {0, 0, 0};
  if (stats) *stats = st;
  if (!(len > 0) || !isfinite(len)) return HR_ERR_INVALID;
  cut_ctx c;
  memset(&c, 0, sizeof c);
  c.s = s;
  c.len = len;
  c.lift = hr_vis_lift(s);
  hr_surface *dst = NULL;
  int nd = 0, capd = 0;
  hr_status ret = HR_ERR_NOMEM;
  c.stamp = malloc((size_t)(s->nsurfs ? s->nsurfs : 1) * sizeof *c.stamp);
  if (!c.stamp || !grid_build(s, len / 256, &c.g)) goto done;
  for (int i = 0; i < s->nsurfs; i++) c.stamp[i] = -1;
  for (int i = 0; i < s->nsurfs; i++) {
    const hr_surface *sf = &s->surfs[i];
    int nlines = 0;
    if (sf->area >= len * len && !cut_surface(&c, i, &nlines)) goto done;
    if (nlines == 0) {
      if (nd == capd) {
        int cap = 2 * capd + 16;
        hr_surface *d = realloc(dst, (size_t)cap * sizeof *d);
        if (!d) goto done;
        dst = d;
        capd = cap;
      }
      dst[nd++] = *sf;
      continue;
    }
    frame f;
    piece outline;
    make_frame(sf, &f, &outline);
    int before = nd;
    for (int k = 0; k < c.out.n; k++)
      if (!emit_piece(&f, sf, &outline, &c.out.p[k], &dst, &nd, &capd)) goto done;
    st.surfaces++;
    st.lines += nlines;
    st.pieces += nd - before;
  }
  free(s->surfs);
  s->surfs = dst;
  s->nsurfs = nd;
  s->cap_surfs = capd;
  dst = NULL;
  ret = HR_OK;
  if (stats) *stats = st;
done:
  hr_vis_destroy(&c.vis);
  grid_free(&c.g);
  free(c.stamp);
  free(dst);
  free(c.segs);
  free(c.out.p);
  return ret;
}
