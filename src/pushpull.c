/* pushpull.c: push-pull (paper 2.2.3, step {14} of Figure 3) in one process and over ranks.
 *
 * Push carries what an element gathered (RGB, the unoccluded Gu and the form-factor sum Gf) down
 * to its leaves; pull takes the area-weighted radiosity back up. In one process it is a
 * recursion per surface tree. In a distributed run an element's subtree may continue on other
 * ranks: a PUSH message carries the gathered light into a child held elsewhere, a PULL message
 * brings that child's result back, and once an element is complete its owner sends a STORE
 * message with its new radiosity to every rank that holds a ghost of it (docs/design.md,
 * "Messages"). Every rank knows in advance how many messages it will receive (one PUSH per own
 * element whose parent is remote, one PULL per remote child of an own element, one STORE per
 * ghost it subscribed to), so the phase ends on each rank without any termination protocol.
 * Arithmetic is the same as the recursion's, in the same order (children 0..3), so results do
 * not depend on the number of ranks or on the order in which messages arrive. */
#include "mpi/dist.h"
#include "solver_impl.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static inline double max3(const double *v) {
  double x = v[0] > v[1] ? v[0] : v[1];
  return x > v[2] ? x : v[2];
}

/* g = down + what 'idx' gathered; sets its bref (times its slack, solver_impl.h). */
static void pp_down(hr_solver *s, int32_t idx, const double down[5], double g[5]) {
  g[0] = down[0] + s->G[idx][0];
  g[1] = down[1] + s->G[idx][1];
  g[2] = down[2] + s->G[idx][2];
  g[3] = down[3] + s->Gu[idx];
  g[4] = down[4] + s->Gf[idx];
  const double floor = HR_BREF_FLOOR * s->unit, br = s->rho_max[idx] * g[3];
  s->bref[idx] = (br > floor ? br : floor) * hr_slack(s, hr_elem_imp_area(s, idx));
}

/* Extrapolation (docs/design.md, "Extrapolation"). Gathering and push-pull are a Jacobi step
 * x <- E + rho F x, whose error shrinks by about the spectral radius of rho F an iteration:
 * 0.9 and more in white rooms, where most iterations only creep towards the answer. Per leaf and
 * channel, Aitken's delta-squared estimate of the limit from three samples two iterations apart,
 * b(k-4), b(k-2) and b(k), D = b(k) - b(k-2) and D2 = b(k-2) - b(k-4):
 *   b <- b + D r / (1 - r),  r = D / D2,
 * applied only where the sequence contracts monotonically (0 < r < XMAX_R) and moves by more than
 * round-off, and kept only where the result stays between the emission and the bound that
 * check_physical (solve.c) holds every leaf to: a jump never makes what it would call an
 * error. Two iterations apart, not one: between two facing white surfaces light alternates, a
 * mode of eigenvalue near -1 that one-step ratios misread (measured: one-step extrapolation did
 * nothing on the conference room's white-board cavity). Samples need a window without new
 * links (solve.c): a new link changes the iteration being extrapolated. */
#define XMAX_R 0.995
#define XMIN_D 1e-9

static void pp_extrapolate(hr_solver *s, int32_t idx, const double emit[3], double b[3]) {
  double(*h)[3] = s->hist[idx];
  if (s->xmode != HR_X_APPLY) {
    memcpy(h[s->xmode == HR_X_SAMPLE1], b, sizeof h[0]);
    return;
  }
  for (int c = 0; c < 3; c++) {
    const double D = b[c] - h[1][c], D2 = h[1][c] - h[0][c];
    if (!(D * D2 > 0 && fabs(D) < XMAX_R * fabs(D2) && fabs(D) > XMIN_D * s->unit)) continue;
    const double r = D / D2, nb = b[c] + D * r / (1 - r);
    if (nb >= emit[c] && nb <= HR_BOUND_SLACK * s->bphys) b[c] = nb; /* physical, so finite */
  }
}

/* A leaf's radiosity from g into b; its range; returns the largest change against its B (the
 * Jacobi step, before any extrapolation). */
static double pp_leaf(hr_solver *s, int32_t idx, const double g[5], double b[3],
                      double range[2]) {
  const hr_material *m = &s->scene->mats[s->scene->surfs[s->el[idx].surf].material];
  double change = 0;
  for (int c = 0; c < 3; c++) {
    b[c] = m->emit[c] + m->rho[c] * g[c];
    double d = fabs(b[c] - s->B[idx][c]);
    change = d > change ? d : change;
  }
  if (s->xmode != HR_X_NONE) pp_extrapolate(s, idx, m->emit, b);
  range[0] = range[1] = max3(b);
  return change;
}

/* Writes B, Bs and bvar of 'idx' from its new radiosity b and its leaves' range; g[4] is the sum
 * of the form factors of its links and its ancestors'.
 *
 * What the element sends (solver_impl.h, Bs): its reflected light over its open part. The open
 * fraction from rays is trusted only as far as the element's own links agree: the sum of their
 * form factors (g[4]) is what its hemisphere sees, which in a closed scene is its open part.
 * Where the ray test calls a part covered that still sees the scene, the links win; otherwise
 * such an element would send more light than it receives (measured: the house regr01 of
 * assimp's test models diverged). */
static void pp_store(hr_solver *s, int32_t idx, double gf, const double b[3],
                     const double range[2]) {
  const hr_material *m = &s->scene->mats[s->scene->surfs[s->el[idx].surf].material];
  double op = gf < 1 ? gf : 1;
  op = s->open[idx] > op ? s->open[idx] : op;
  const double inv = s->open[idx] > 0 ? 1.0 / op : 1.0; /* wholly closed: about 0 anyway */
  for (int c = 0; c < 3; c++) {
    s->B[idx][c] = b[c];
    s->Bs[idx][c] = m->emit[c] + (b[c] - m->emit[c]) * inv;
  }
  /* A leaf: how much the light of its own links may vary over it (fine sources, link.c),
   * negated, so that a rank holding a ghost of an element tells the two kinds apart without
   * knowing whether it has children. */
  s->bvar[idx] = s->el[idx].child < 0 ? -s->rho_max[idx] * s->Gv[idx] : range[1] - range[0];
}

/* An inner element's radiosity: the area-weighted mean of its children's (already new) B, in
 * child order; its range from the children's. */
static void pp_inner(const hr_solver *s, int32_t idx, const double (*crange)[2], double b[3],
                     double range[2]) {
  double acc[3] = {0, 0, 0}, area = 0;
  range[0] = INFINITY;
  range[1] = -INFINITY;
  for (int k = 0; k < 4; k++) {
    const int32_t ci = s->el[idx].child + k;
    const double a = s->el[ci].area;
    area += a;
    for (int c = 0; c < 3; c++) acc[c] += a * s->B[ci][c];
    range[0] = crange[k][0] < range[0] ? crange[k][0] : range[0];
    range[1] = crange[k][1] > range[1] ? crange[k][1] : range[1];
  }
  for (int c = 0; c < 3; c++) b[c] = acc[c] / area;
}

/* One process: the recursion. Writes the new B of 'idx' into 'bout' and its leaves' range, and
 * returns the largest change of B over its leaves. */
static double pushpull(hr_solver *s, int32_t idx, const double down[5], double bout[3],
                       double range[2]) {
  double g[5], change = 0;
  pp_down(s, idx, down, g);
  if (s->el[idx].child < 0) {
    change = pp_leaf(s, idx, g, bout, range);
  } else {
    double cr[4][2];
    for (int k = 0; k < 4; k++) {
      double bc[3];
      const double d = pushpull(s, s->el[idx].child + k, g, bc, cr[k]);
      change = d > change ? d : change;
    }
    pp_inner(s, idx, (const double(*)[2])cr, bout, range);
  }
  pp_store(s, idx, g[4], bout, range);
  return change;
}

static double push_pull_local(hr_solver *s) {
  double maxc = 0;
  int n = s->scene->nsurfs;
#pragma omp parallel for schedule(dynamic, 8) reduction(max : maxc) \
    if (s->nel > PAR_MIN) num_threads(s->threads)
  for (int i = 0; i < n; i++) {
    double zero[5] = {0, 0, 0, 0, 0}, b[3], range[2];
    double d = pushpull(s, i, zero, b, range);
    maxc = d > maxc ? d : maxc;
  }
  return maxc;
}

/* ---------------------------------------------------------------- over ranks */

enum { MSG_PUSH = 1, MSG_PULL = 2, MSG_STORE = 3 };
#define TAG_PUSHPULL 21

typedef struct msg_push {
  uint64_t type, gid;
  double g[5];
} msg_push;

typedef struct msg_pull {
  uint64_t type, gid;
  double B[3], Bs[3], range[2], change, bvar;
} msg_pull;

/* A ghost's new state: what refinement and gathering read at a source (Bs, bvar and whether it
 * has children) and the same of its children, which links with source shares gather. */
typedef struct msg_store {
  uint64_t type, gid, nchild;
  double Bs[3], bvar;
  double cBs[4][3], cbvar[4];
} msg_store;

typedef struct dpp {
  hr_solver *s;
  hr_dist_mq *q;
  double (*g)[5];     /* per own element, once pushed: its gathered light with its ancestors' */
  double (*range)[2]; /* per own element and remote child of one: its leaves' range */
  double *change;     /* the same: the largest change below */
  int8_t *wait;       /* per own inner element: children not complete yet */
  int32_t *stack;     /* own elements pushed, waiting to be visited */
  int64_t nstack;
  int64_t *sstart;    /* subscribers of element e: subs[sorder[sstart[e] .. sstart[e+1])] */
  int64_t *sorder;
  int64_t done, got;  /* own elements complete; messages received */
  double maxc;
  int oom;
} dpp;

static void dpp_put(dpp *p, int dest, const void *rec, size_t n) {
  void *w = hr_dist_mq_put(p->q, dest, n);
  if (!w) {
    p->oom = 1; /* the receiver would wait for ever: the caller aborts the run */
    return;
  }
  memcpy(w, rec, n);
}

/* Own inner element 'e', whose children are all complete: its radiosity, range and change. */
static void dpp_inner(dpp *p, int32_t e) {
  hr_solver *s = p->s;
  double b[3], range[2], change = 0;
  const int32_t ch = s->el[e].child;
  for (int k = 0; k < 4; k++) change = p->change[ch + k] > change ? p->change[ch + k] : change;
  pp_inner(s, e, (const double(*)[2])(p->range + ch), b, range);
  pp_store(s, e, p->g[e][4], b, range);
  memcpy(p->range[e], range, sizeof range);
  p->change[e] = change;
}

/* Own element 'e' is complete: its subscribers get its state, and its parent learns of it. */
static void dpp_complete(dpp *p, int32_t e) {
  hr_solver *s = p->s;
  for (;;) {
    p->done++;
    msg_store st;
    memset(&st, 0, sizeof st);
    st.type = MSG_STORE, st.gid = s->el[e].gid;
    memcpy(st.Bs, s->Bs[e], sizeof st.Bs);
    st.bvar = s->bvar[e];
    const int32_t c = s->el[e].child;
    if (c >= 0) {
      st.nchild = 4;
      for (int k = 0; k < 4; k++) {
        memcpy(st.cBs[k], s->Bs[c + k], sizeof st.cBs[k]);
        st.cbvar[k] = s->bvar[c + k];
      }
    }
    for (int64_t i = p->sstart[e]; i < p->sstart[e + 1]; i++)
      dpp_put(p, s->subs[p->sorder[i]][1], &st, sizeof st);
    const int32_t par = s->el[e].parent;
    if (par < 0) return;
    if (!hr_owns(s, par)) {
      msg_pull m = {MSG_PULL, s->el[e].gid, {0}, {0}, {0}, p->change[e], 0};
      memcpy(m.B, s->B[e], sizeof m.B);
      memcpy(m.Bs, s->Bs[e], sizeof m.Bs);
      memcpy(m.range, p->range[e], sizeof m.range);
      m.bvar = s->bvar[e];
      dpp_put(p, s->eown[par], &m, sizeof m);
      return;
    }
    if (--p->wait[par] > 0) return;
    e = par; /* the parent is complete too */
    dpp_inner(p, e);
  }
}

/* Visits own element 'e' (pushed): a leaf is computed and complete; an inner element pushes to
 * its children, its own ones onto the stack, the others by message. */
static void dpp_visit(dpp *p, int32_t e) {
  hr_solver *s = p->s;
  const int32_t c = s->el[e].child;
  if (c < 0) {
    double b[3];
    p->change[e] = pp_leaf(s, e, p->g[e], b, p->range[e]);
    p->maxc = p->change[e] > p->maxc ? p->change[e] : p->maxc;
    pp_store(s, e, p->g[e][4], b, p->range[e]);
    dpp_complete(p, e);
    return;
  }
  p->wait[e] = 4;
  for (int k = 0; k < 4; k++) {
    const int32_t ci = c + k;
    if (hr_owns(s, ci)) {
      pp_down(s, ci, p->g[e], p->g[ci]);
      p->stack[p->nstack++] = ci;
    } else {
      msg_push m = {MSG_PUSH, s->el[ci].gid, {0}};
      memcpy(m.g, p->g[e], sizeof m.g);
      dpp_put(p, s->eown[ci], &m, sizeof m);
    }
  }
}

/* Takes one received batch; 0 if it names an element this rank cannot hold (a bug). */
static int dpp_receive(dpp *p, const char *buf, int64_t n) {
  hr_solver *s = p->s;
  for (int64_t o = 0; o < n;) {
    uint64_t type, gid;
    memcpy(&type, buf + o, sizeof type);
    memcpy(&gid, buf + o + 8, sizeof gid);
    const int32_t e = hr_elem_find(s, gid);
    if (e < 0) return 0;
    p->got++;
    if (type == MSG_PUSH) {
      msg_push m;
      memcpy(&m, buf + o, sizeof m);
      o += (int64_t)sizeof m;
      pp_down(s, e, m.g, p->g[e]);
      p->stack[p->nstack++] = e;
    } else if (type == MSG_PULL) {
      msg_pull m;
      memcpy(&m, buf + o, sizeof m);
      o += (int64_t)sizeof m;
      memcpy(s->B[e], m.B, sizeof m.B);
      memcpy(s->Bs[e], m.Bs, sizeof m.Bs);
      memcpy(p->range[e], m.range, sizeof m.range);
      s->bvar[e] = m.bvar;
      p->change[e] = m.change;
      p->maxc = m.change > p->maxc ? m.change : p->maxc;
      const int32_t par = s->el[e].parent;
      if (--p->wait[par] == 0) {
        dpp_inner(p, par);
        dpp_complete(p, par);
      }
    } else if (type == MSG_STORE) {
      msg_store m;
      memcpy(&m, buf + o, sizeof m);
      o += (int64_t)sizeof m;
      memcpy(s->Bs[e], m.Bs, sizeof m.Bs);
      s->bvar[e] = m.bvar;
      if (m.nchild) {
        if (s->el[e].child < 0 && hr_elem_subdivide(s, e) != HR_OK) {
          p->oom = 1;
          continue;
        }
        const int32_t c = s->el[e].child;
        for (int k = 0; k < 4; k++) {
          memcpy(s->Bs[c + k], m.cBs[k], sizeof m.cBs[k]);
          s->bvar[c + k] = m.cbvar[k];
        }
      }
    } else {
      return 0;
    }
  }
  return 1;
}

/* The subscribers of each element as a CSR index over s->subs. */
static int index_subs(dpp *p) {
  hr_solver *s = p->s;
  p->sstart = calloc((size_t)s->nel + 1, sizeof *p->sstart);
  p->sorder = malloc((size_t)(s->nsubs > 0 ? s->nsubs : 1) * sizeof *p->sorder);
  if (!p->sstart || !p->sorder) return 0;
  for (int64_t i = 0; i < s->nsubs; i++) p->sstart[s->subs[i][0] + 1]++;
  for (int64_t e = 0; e < s->nel; e++) p->sstart[e + 1] += p->sstart[e];
  int64_t *at = malloc((size_t)(s->nel + 1) * sizeof *at);
  if (!at) return 0;
  memcpy(at, p->sstart, (size_t)(s->nel + 1) * sizeof *at);
  for (int64_t i = 0; i < s->nsubs; i++) p->sorder[at[s->subs[i][0]]++] = i;
  free(at);
  return 1;
}

/* Own elements visited between looks at the network, and the stack size below which a rank
 * sends at once (productive) rather than batching (economical). */
#define SCHED_CHUNK 256
#define SCHED_LOW 1024

/* Push-pull over ranks; returns the largest change over this rank's leaves in '*maxc'. A
 * collective (the message phase, then the agreement on failure). */
static hr_status push_pull_dist(hr_solver *s, double *maxc, hr_err *err) {
  const int64_t n0 = s->nel;
  dpp p;
  memset(&p, 0, sizeof p);
  p.s = s;
  p.g = malloc((size_t)n0 * sizeof *p.g);
  p.range = malloc((size_t)n0 * sizeof *p.range);
  p.change = malloc((size_t)n0 * sizeof *p.change);
  p.wait = calloc((size_t)n0, sizeof *p.wait);
  p.stack = malloc((size_t)n0 * sizeof *p.stack);
  const int injected = hr_test_fail(s, HR_PHASE_PUSHPULL);
  const int ok = !injected && p.g && p.range && p.change && p.wait && p.stack &&
                 index_subs(&p) && hr_dist_mq_open(s->dist, TAG_PUSHPULL, &p.q) == HR_OK;
  const char *why = injected ? " (injected by HRAD_TEST_FAIL)" : "";
  hr_status st = hr_dist_agree(
      s, ok ? HR_OK : hr_err_set(err, HR_ERR_NOMEM, "out of memory%s", why), err);
  if (st == HR_OK) {
    /* what this rank will complete and receive */
    int64_t own = 0, expect = 0;
    for (int64_t e = 0; e < n0; e++) {
      const int32_t par = s->el[e].parent;
      if (hr_owns(s, e)) {
        own++;
        if (par < 0) {
          const double zero[5] = {0, 0, 0, 0, 0};
          pp_down(s, (int32_t)e, zero, p.g[e]);
          p.stack[p.nstack++] = (int32_t)e;
        } else {
          expect += !hr_owns(s, par); /* a PUSH */
        }
      } else {
        expect += par >= 0 && hr_owns(s, par); /* a PULL */
        expect += s->esub[e];                  /* a STORE */
      }
    }
    /* The scheduler (paper 2.2.2): arrived messages first (a PULL completes a parent, the
     * paper's highest priority), then a chunk of own elements from the stack. While few own
     * elements wait, this rank is about to run dry and others may wait for its pushes: the
     * productive order sends what it has after every chunk. With many waiting, the economical
     * order lets records collect into full batches (fewer, larger messages). Own elements are
     * visited in stack order; no order changes any value. */
    while (!p.oom && (p.done < own || p.got < expect)) {
      const void *buf;
      int64_t n;
      int src;
      while (!p.oom && hr_dist_mq_poll(p.q, 0, &buf, &n, &src))
        if (!dpp_receive(&p, buf, n)) p.oom = 2;
      if (p.nstack > 0) {
        for (int k = 0; k < SCHED_CHUNK && p.nstack > 0 && !p.oom; k++)
          dpp_visit(&p, p.stack[--p.nstack]);
        if (p.nstack < SCHED_LOW) hr_dist_mq_flush(p.q); /* productive */
        continue;
      }
      if (p.done < own || p.got < expect) {
        hr_dist_mq_flush(p.q);
        if (hr_dist_mq_poll(p.q, 1, &buf, &n, &src) && !dpp_receive(&p, buf, n)) p.oom = 2;
      }
    }
    if (p.oom) hr_dist_abort(s->dist, 1); /* a lost message would leave another rank waiting */
    hr_dist_mq_close(&p.q);
    *maxc = p.maxc;
  }
  free(p.g), free(p.range), free(p.change), free(p.wait), free(p.stack);
  free(p.sstart), free(p.sorder);
  if (p.q) hr_dist_mq_close(&p.q);
  return st;
}

/* Every root's radiosity on every rank (outputs and the radiosity unit read them); with
 * clustering also what the clusters' pull reads of every root (cluster.c): the radiosity it
 * sends, its leaves' range and its reference radiosity. One sum in which each root's values
 * come from its owner and zeros from every other rank (x + 0 == x: exact). */
static hr_status share_roots(hr_solver *s, hr_err *err) {
  const int n = s->scene->nsurfs, m = s->cl ? 8 : 3;
  double *b = calloc((size_t)n * (size_t)m, sizeof *b);
  hr_status st = hr_dist_agree(s, b ? HR_OK : hr_err_set(err, HR_ERR_NOMEM, "out of memory"),
                               err);
  if (st != HR_OK) {
    free(b);
    return st;
  }
  for (int i = 0; i < n; i++) {
    if (!hr_owns(s, i)) continue;
    double *v = b + (size_t)m * (size_t)i;
    memcpy(v, s->B[i], 3 * sizeof *b);
    if (m == 3) continue;
    memcpy(v + 3, s->Bs[i], 3 * sizeof *b);
    v[6] = s->bvar[i], v[7] = s->bref[i];
  }
  hr_dist_sum_f64(s->dist, b, m * (int64_t)n);
  for (int i = 0; i < n; i++) {
    const double *v = b + (size_t)m * (size_t)i;
    memcpy(s->B[i], v, 3 * sizeof *b);
    if (m == 3 || hr_owns(s, i)) continue;
    memcpy(s->Bs[i], v + 3, 3 * sizeof *b);
    s->bvar[i] = v[6], s->bref[i] = v[7];
  }
  free(b);
  return HR_OK;
}

hr_status hr_push_pull(hr_solver *s, double *maxc, hr_err *err) {
  if (!s->dist) {
    *maxc = push_pull_local(s);
    return HR_OK;
  }
  hr_status st = push_pull_dist(s, maxc, err);
  if (st == HR_OK) st = share_roots(s, err);
  if (st == HR_OK) hr_dist_max_f64(s->dist, maxc, 1);
  return st;
}
