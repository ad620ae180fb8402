/* balance.c: graph balancing of a distributed run (paper 2.2.5): the patch/link graph with
 * measured weights, partitioned by the paper's clustering and simulated annealing, by METIS or
 * by orthogonal recursive bisection (src/partition/, pure graph code), and the elements moved to
 * their new ranks (hr_solver_migrate).
 *
 * The graph: one node per element (gid order), its weight W the work that stays with the
 * element's owner, per iteration: the links it receives (each is gathered and tested every
 * iteration), one (its push-pull), and the rays refinement cast for its links so far, per
 * iteration, at RAY_WORK links a ray (counted since the start: counted since the last
 * balancing, the work of a few iterations was too bursty to predict the next ones, and museum
 * at 2 ranks migrated at all 8 balancings); edges are the links (an element receives from
 * another: weight 1 per link, what a cut link costs in store messages and ghost state) and the
 * tree edges (parent and child: weight 2, a push and a pull). Rank 0 gathers it; for
 * annealing every rank runs its own chain from the same start (ORB's partition) with its own
 * seed, and the best Z wins (the paper's parallel annealing, its reference [1], one period). A
 * new partition is expressed as a subtree map: an element is listed only where its rank differs
 * from its parent's. */
#include "cluster.h"
#include "mpi/dist.h"
#include "partition/partition.h"
#include "solver_impl.h"
#include "vec.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* A new partition is taken only if it lowers Z below this fraction of the current one's, and,
 * after the first, if it pays for itself: see worth_moving. */
#define KEEP_GAIN 0.95
/* The work of a ray cast in refinement, in units of a link's work in one iteration (gathered and
 * tested): measured on museum at 2 ranks, about 130 ns of refinement a ray (shaft filtering and
 * decisions included) against about 17 ns a link an iteration. Without it, W missed most of the
 * work: on cornell the rays weigh about 4 times the links. */
#define RAY_WORK 8.0

/* What each rank sends rank 0 about one element: its own elements, and the work (rays) it did
 * for elements that it holds but another rank owns (parent EXTRA, added to the owner's). */
typedef struct node_rec {
  uint64_t gid, parent; /* parent gid, 0 for a root */
  double w, xyz[3];
} node_rec;
#define EXTRA UINT64_MAX

/* A link edge as rank 0 receives it (receiver and source gid). */
typedef struct edge_rec {
  uint64_t a, b;
} edge_rec;

/* The gathered graph on rank 0 (and, for annealing, on every rank). */
typedef struct bgraph {
  int32_t n;
  uint64_t *gid;   /* n, increasing */
  uint64_t *pgid;  /* n, parent gid or 0 */
  double *w, *xyz; /* n, 3n */
  int64_t *xadj;
  int32_t *adj;
  double *c;
} bgraph;

static void bgraph_free(bgraph *g) {
  free(g->gid), free(g->pgid), free(g->w), free(g->xyz), free(g->xadj), free(g->adj), free(g->c);
  memset(g, 0, sizeof *g);
}

static int cmp_node(const void *a, const void *b) { /* by gid, then the content: a total order */
  const node_rec *x = a, *y = b;
  if (x->gid != y->gid) return x->gid < y->gid ? -1 : 1;
  if (x->parent != y->parent) return x->parent < y->parent ? -1 : 1;
  return x->w < y->w ? -1 : x->w > y->w;
}

/* Sorts the records and merges each element's (its owner's, with any EXTRA work added);
 * returns the count left. An EXTRA without its owner's record is dropped. */
static int64_t merge_nodes(node_rec *nodes, int64_t nn) {
  qsort(nodes, (size_t)nn, sizeof *nodes, cmp_node);
  int64_t m = 0;
  for (int64_t i = 0; i < nn;) {
    int64_t j = i, own = -1;
    double extra = 0;
    for (; j < nn && nodes[j].gid == nodes[i].gid; j++) {
      if (nodes[j].parent == EXTRA) extra += nodes[j].w;
      else own = j;
    }
    if (own >= 0) {
      nodes[m] = nodes[own];
      nodes[m++].w += extra;
    }
    i = j;
  }
  return m;
}

static int32_t node_of(const bgraph *g, uint64_t gid) {
  int32_t lo = 0, hi = g->n;
  while (lo < hi) {
    int32_t m = lo + (hi - lo) / 2;
    if (g->gid[m] < gid) lo = m + 1;
    else hi = m;
  }
  return lo < g->n && g->gid[lo] == gid ? lo : -1;
}

/* Rank 0 gets every rank's records ('mine', n of 'size' bytes): '*all', '*nall'. A collective. */
static hr_status to_rank0(hr_solver *s, const void *mine, int64_t n, size_t size, void **all,
                          int64_t *nall) {
  *all = NULL;
  *nall = 0;
  if (!s->dist) {
    void *c = malloc((size_t)(n > 0 ? n : 1) * size);
    if (!c) return HR_ERR_NOMEM;
    if (n > 0) memcpy(c, mine, (size_t)n * size);
    *all = c;
    *nall = n;
    return HR_OK;
  }
  int64_t *sb = calloc((size_t)s->nranks, sizeof *sb);
  if (!sb) hr_dist_abort(s->dist, 1);
  sb[0] = n * (int64_t)size;
  int64_t tot = 0;
  hr_status st = hr_dist_alltoall(s->dist, mine, sb, all, &tot);
  free(sb);
  *nall = tot / (int64_t)size;
  return st;
}

/* gid -> node index, open addressing (gids are never 0, which marks a free slot). */
typedef struct gid_map {
  uint64_t mask, *key;
  int32_t *val;
} gid_map;

static int gid_map_build(gid_map *m, const uint64_t *gid, int32_t n) {
  uint64_t cap = 16;
  while (cap < 2 * (uint64_t)n) cap *= 2;
  m->mask = cap - 1;
  m->key = calloc(cap, sizeof *m->key);
  m->val = malloc(cap * sizeof *m->val);
  if (!m->key || !m->val) return 0;
  for (int32_t i = 0; i < n; i++) {
    uint64_t h = u64_mix(gid[i]) & m->mask;
    while (m->key[h]) h = (h + 1) & m->mask;
    m->key[h] = gid[i], m->val[h] = i;
  }
  return 1;
}

static int32_t gid_map_get(const gid_map *m, uint64_t gid) {
  for (uint64_t h = u64_mix(gid) & m->mask; m->key[h]; h = (h + 1) & m->mask)
    if (m->key[h] == gid) return m->val[h];
  return -1;
}

/* One direction of an edge, for the counting sorts of build_graph. */
typedef struct half_edge {
  int32_t a, b;
  double c;
} half_edge;

/* Stable counting sort of e (m entries) into out by the field at 'by' (0: a, 1: b) in [0, n). */
static int count_sort(const half_edge *e, int64_t m, int32_t n, int by, half_edge *out) {
  int64_t *at = calloc((size_t)n + 1, sizeof *at);
  if (!at) return 0;
  for (int64_t k = 0; k < m; k++) at[(by ? e[k].b : e[k].a) + 1]++;
  for (int32_t i = 0; i < n; i++) at[i + 1] += at[i];
  for (int64_t k = 0; k < m; k++) out[at[by ? e[k].b : e[k].a]++] = e[k];
  free(at);
  return 1;
}

/* Builds the CSR graph on rank 0 from the gathered nodes and link edges (both consumed): nodes
 * in gid order, each row's neighbours in index order with repeated pairs summed. O(nodes log
 * nodes + edges): two counting sorts (by neighbour, then stably by node) instead of a
 * comparison sort of the edges, which took about 2 s a balancing on museum's 4 M links. */
static int build_graph(bgraph *g, node_rec *nodes, int64_t nn, edge_rec *ed, int64_t ne) {
  nn = merge_nodes(nodes, nn);
  g->n = (int32_t)nn;
  g->gid = malloc((size_t)(nn + 1) * sizeof *g->gid);
  g->pgid = malloc((size_t)(nn + 1) * sizeof *g->pgid);
  g->w = malloc((size_t)(nn + 1) * sizeof *g->w);
  g->xyz = malloc((size_t)(3 * nn + 1) * sizeof *g->xyz);
  if (!g->gid || !g->pgid || !g->w || !g->xyz) return 0;
  for (int64_t i = 0; i < nn; i++) {
    g->gid[i] = nodes[i].gid, g->pgid[i] = nodes[i].parent, g->w[i] = nodes[i].w;
    memcpy(g->xyz + 3 * i, nodes[i].xyz, sizeof nodes[i].xyz);
  }
  gid_map map = {0};
  /* both directions of every link (weight 1) and tree edge (weight 2), a != b */
  half_edge *e = malloc((size_t)(2 * ne + 2 * nn + 1) * sizeof *e);
  half_edge *tmp = malloc((size_t)(2 * ne + 2 * nn + 1) * sizeof *tmp);
  int ok = e && tmp && gid_map_build(&map, g->gid, g->n);
  int64_t m = 0;
  for (int64_t k = 0; ok && k < ne; k++) {
    const int32_t a = gid_map_get(&map, ed[k].a), b = gid_map_get(&map, ed[k].b);
    if (a < 0 || b < 0 || a == b) continue;
    e[m++] = (half_edge){a, b, 1.0};
    e[m++] = (half_edge){b, a, 1.0};
  }
  for (int32_t i = 0; ok && i < g->n; i++) {
    const int32_t p = g->pgid[i] ? gid_map_get(&map, g->pgid[i]) : -1;
    if (p < 0) continue;
    e[m++] = (half_edge){i, p, 2.0};
    e[m++] = (half_edge){p, i, 2.0};
  }
  free(map.key), free(map.val);
  ok = ok && count_sort(e, m, g->n, 1, tmp) && count_sort(tmp, m, g->n, 0, e);
  free(tmp);
  g->xadj = calloc((size_t)g->n + 1, sizeof *g->xadj);
  g->adj = malloc((size_t)(m + 1) * sizeof *g->adj);
  g->c = malloc((size_t)(m + 1) * sizeof *g->c);
  if (!ok || !g->xadj || !g->adj || !g->c) {
    free(e);
    return 0;
  }
  int64_t u = 0;
  for (int64_t k = 0; k < m; k++) {
    if (k > 0 && e[k].a == e[k - 1].a && e[k].b == e[k - 1].b) {
      g->c[u - 1] += e[k].c; /* the same pair again: add */
      continue;
    }
    g->adj[u] = e[k].b;
    g->c[u] = e[k].c;
    g->xadj[e[k].a + 1]++;
    u++;
  }
  for (int32_t i = 0; i < g->n; i++) g->xadj[i + 1] += g->xadj[i];
  free(e);
  return 1;
}

/* Gathers the graph on rank 0 ('g' filled there; zeroed elsewhere). A collective. */
static hr_status gather_graph(hr_solver *s, bgraph *g, hr_err *err) {
  memset(g, 0, sizeof *g);
  int64_t nrec = 0, nl = 0; /* node records: own elements, and others' with rays cast here */
  for (int64_t e = 0; e < s->nel; e++) nrec += hr_owns(s, e) || s->erays[e] > 0;
  for (int64_t k = 0; k < s->nlinks; k++) nl += s->links[k].Fu >= 0;
  node_rec *nodes = malloc((size_t)(nrec + 1) * sizeof *nodes);
  edge_rec *ed = malloc((size_t)(nl + 1) * sizeof *ed);
  int64_t *recv = calloc((size_t)s->nel + 1, sizeof *recv);
  if (!nodes || !ed || !recv) hr_dist_abort(s->dist, 1); /* every rank must take part */
  for (int64_t k = 0; k < s->nlinks; k++)
    if (s->links[k].Fu >= 0) recv[s->links[k].r]++;
  hr_cluster_recv_counts(s, recv); /* gathered like element links */
  int64_t i = 0;
  const int iters = s->iterations > 1 ? s->iterations : 1;
  for (int64_t e = 0; e < s->nel; e++) {
    const double rw = RAY_WORK * s->erays[e] / iters;
    if (!hr_owns(s, e)) {
      if (s->erays[e] > 0) nodes[i++] = (node_rec){s->el[e].gid, EXTRA, rw, {0, 0, 0}};
      continue;
    }
    const int32_t p = s->el[e].parent;
    nodes[i++] = (node_rec){s->el[e].gid, p >= 0 ? s->el[p].gid : 0, (double)recv[e] + 1.0 + rw,
                            {s->el[e].c.x, s->el[e].c.y, s->el[e].c.z}};
  }
  i = 0;
  for (int64_t k = 0; k < s->nlinks; k++)
    if (s->links[k].Fu >= 0)
      ed[i++] = (edge_rec){s->el[s->links[k].r].gid, s->el[s->links[k].s].gid};
  free(recv);
  void *an = NULL, *ae = NULL;
  int64_t nn = 0, ne = 0;
  hr_status st = to_rank0(s, nodes, nrec, sizeof *nodes, &an, &nn);
  free(nodes);
  if (st == HR_OK) st = to_rank0(s, ed, nl, sizeof *ed, &ae, &ne);
  free(ed);
  if (st == HR_OK && s->rank == 0 && !build_graph(g, an, nn, ae, ne)) st = HR_ERR_NOMEM;
  free(an), free(ae);
  if (st != HR_OK) bgraph_free(g);
  return hr_dist_agree(s, st == HR_OK ? st : hr_err_set(err, st, "out of memory (balancing)"),
                       err);
}

/* After the first migration, one more is worth it only if the time it is predicted to save
 * over the iterations left, the last iteration's wall time times the relative drop of Z, is
 * more than the last migration took. Measured on museum at 2 ranks: with the idle-time trigger
 * alone, 4 of 6 balancings migrated (each 0.3 s or more, and the iterations after it slower
 * while ghosts are fetched anew), late in the run when little was left to gain. */
static int worth_moving(const hr_solver *s, double z_now, double z_new) {
  if (s->t_migrate <= 0 || !(z_now > 0) || s->bal_idle == 0) return 1; /* idle 0: always */
  const double saving = (1 - z_new / z_now) * s->iter_wall * hr_solver_iters_left(s);
  return saving > s->t_migrate;
}

static hr_graph view(const bgraph *g) {
  return (hr_graph){g->n, g->xadj, g->adj, g->w, g->c};
}

/* Every rank gets rank 0's graph (annealing runs a chain on each). A collective. */
static void share_graph(hr_solver *s, bgraph *g) {
  int64_t hdr[2] = {g->n, g->n ? g->xadj[g->n] : 0};
  hr_dist_bcast(s->dist, hdr, sizeof hdr);
  if (s->rank != 0) {
    g->n = (int32_t)hdr[0];
    g->gid = malloc((size_t)(hdr[0] + 1) * sizeof *g->gid);
    g->w = malloc((size_t)(hdr[0] + 1) * sizeof *g->w);
    g->xyz = malloc((size_t)(3 * hdr[0] + 1) * sizeof *g->xyz);
    g->xadj = malloc((size_t)(hdr[0] + 1) * sizeof *g->xadj);
    g->adj = malloc((size_t)(hdr[1] + 1) * sizeof *g->adj);
    g->c = malloc((size_t)(hdr[1] + 1) * sizeof *g->c);
    if (!g->gid || !g->w || !g->xyz || !g->xadj || !g->adj || !g->c) hr_dist_abort(s->dist, 1);
  }
  hr_dist_bcast(s->dist, g->w, (size_t)hdr[0] * sizeof *g->w);
  hr_dist_bcast(s->dist, g->xyz, (size_t)(3 * hdr[0]) * sizeof *g->xyz);
  hr_dist_bcast(s->dist, g->xadj, (size_t)(hdr[0] + 1) * sizeof *g->xadj);
  hr_dist_bcast(s->dist, g->adj, (size_t)hdr[1] * sizeof *g->adj);
  hr_dist_bcast(s->dist, g->c, (size_t)hdr[1] * sizeof *g->c);
}

/* The partition of 'method' for P parts into part[] (rank 0's graph; for annealing every
 * rank's). 0 when out of memory. */
static int partition(hr_solver *s, const bgraph *g, int method, int P, int32_t *part) {
  const hr_graph v = view(g);
  switch (method) {
  case HR_BALANCE_METIS:
    return hr_partition_metis(&v, P, part);
  case HR_BALANCE_ORB:
    return hr_partition_orb(g->xyz, g->w, g->n, P, part);
  default: /* annealing from ORB's partition */
    if (!hr_partition_orb(g->xyz, g->w, g->n, P, part)) return 0;
    return hr_partition_anneal(&v, P, s->bal_alpha, s->opt.seed * 1000003 + (uint64_t)s->rank +
                                                        (uint64_t)s->nbalance * 7919,
                               part);
  }
}

/* The subtree map of a partition: roots always, other elements where their part differs from
 * their parent's. Returns the count; gids and ranks (n each) filled. */
static int64_t subtree_map(const bgraph *g, const int32_t *part, uint64_t *gids, int32_t *ranks) {
  int64_t m = 0;
  for (int32_t i = 0; i < g->n; i++) {
    const int32_t p = g->pgid[i] ? node_of(g, g->pgid[i]) : -1;
    if (p >= 0 && part[p] == part[i]) continue;
    gids[m] = g->gid[i], ranks[m++] = part[i];
  }
  return m;
}

hr_status hr_solver_balance(hr_solver *s, int method, hr_err *err) {
  if (!s->dist || method == HR_BALANCE_NONE) return HR_OK;
  const double t0 = hr_now();
  bgraph g;
  hr_status st = gather_graph(s, &g, err);
  if (st != HR_OK) return st;
  const int P = s->nranks;
  if (method == HR_BALANCE_ANNEAL) share_graph(s, &g);
  int32_t *part = NULL;
  int ok = 1;
  if (s->rank == 0 || method == HR_BALANCE_ANNEAL) {
    part = malloc((size_t)(g.n + 1) * sizeof *part);
    ok = part && partition(s, &g, method, P, part);
  }
  if (!hr_dist_any(s->dist, !ok)) {
    if (method == HR_BALANCE_ANNEAL) { /* the chain with the lowest Z wins (ties: lowest rank) */
      const hr_graph v = view(&g);
      const double z = hr_partition_cost(&v, part, P, s->bal_alpha, NULL, NULL);
      const int win = hr_dist_argmin(s->dist, z);
      hr_dist_bcast_from(s->dist, win, part, (size_t)g.n * sizeof *part);
    }
  } else {
    st = hr_err_set(err, HR_ERR_NOMEM, "out of memory (balancing)");
  }
  /* rank 0 makes the subtree map; every rank gets it and migrates */
  int64_t m = 0;
  uint64_t *gids = NULL;
  int32_t *ranks = NULL;
  if (st == HR_OK && s->rank == 0) {
    gids = malloc((size_t)(g.n + 1) * sizeof *gids);
    ranks = malloc((size_t)(g.n + 1) * sizeof *ranks);
    int32_t *now = malloc((size_t)(g.n + 1) * sizeof *now);
    if (!gids || !ranks || !now) hr_dist_abort(s->dist, 1);
    /* a partition that does not lower Z by KEEP_GAIN is not worth moving the graph */
    for (int32_t i = 0; i < g.n; i++) now[i] = hr_owner_of(s, g.gid[i]);
    const hr_graph v = view(&g);
    const double z_now = hr_partition_cost(&v, now, P, s->bal_alpha, NULL, NULL);
    const double z_new = hr_partition_cost(&v, part, P, s->bal_alpha, NULL, NULL);
    m = z_new < KEEP_GAIN * z_now && worth_moving(s, z_now, z_new)
            ? subtree_map(&g, part, gids, ranks)
            : -1;
    free(now);
  }
  free(part);
  if (st == HR_OK) {
    hr_dist_bcast(s->dist, &m, sizeof m);
    if (m < 0) { /* kept */
      free(gids), free(ranks);
      bgraph_free(&g);
      s->nbalance++;
      s->t_bal_last = hr_now() - t0;
      s->t.balance += s->t_bal_last;
      return HR_OK;
    }
    if (s->rank != 0) {
      gids = malloc((size_t)(m + 1) * sizeof *gids);
      ranks = malloc((size_t)(m + 1) * sizeof *ranks);
      if (!gids || !ranks) hr_dist_abort(s->dist, 1);
    }
    hr_dist_bcast(s->dist, gids, (size_t)m * sizeof *gids);
    hr_dist_bcast(s->dist, ranks, (size_t)m * sizeof *ranks);
    const double tm = hr_now();
    st = hr_solver_migrate(s, gids, ranks, m, err);
    s->t_migrate = hr_now() - tm;
  }
  free(gids), free(ranks);
  bgraph_free(&g);
  s->nbalance++;
  s->nmoved++;
  s->t_bal_last = hr_now() - t0;
  s->t.balance += s->t_bal_last;
  return st;
}

hr_status hr_solver_dump_graph(hr_solver *s, const char *path, hr_err *err) {
  bgraph g;
  hr_status st = gather_graph(s, &g, err);
  if (st != HR_OK || s->rank != 0) return st;
  char tmp[4200];
  snprintf(tmp, sizeof tmp, "%s.tmp", path);
  FILE *f = fopen(tmp, "w");
  int bad = !f;
  if (f) {
    /* nodes (gid, parent gid, work, centre) and edges (each once, u < v, weight) */
    fprintf(f, "hrad-graph 1\nnodes %d\n", g.n);
    for (int32_t i = 0; i < g.n; i++)
      fprintf(f, "%llx %llx %.17g %.17g %.17g %.17g\n", (unsigned long long)g.gid[i],
              (unsigned long long)g.pgid[i], g.w[i], g.xyz[3 * i], g.xyz[3 * i + 1],
              g.xyz[3 * i + 2]);
    int64_t ne = 0;
    for (int32_t i = 0; i < g.n; i++)
      for (int64_t k = g.xadj[i]; k < g.xadj[i + 1]; k++) ne += g.adj[k] > i;
    fprintf(f, "edges %lld\n", (long long)ne);
    for (int32_t i = 0; i < g.n; i++)
      for (int64_t k = g.xadj[i]; k < g.xadj[i + 1]; k++)
        if (g.adj[k] > i) fprintf(f, "%d %d %.17g\n", i, g.adj[k], g.c[k]);
    bad = ferror(f) != 0;
    if (fclose(f) != 0) bad = 1;
  }
  bgraph_free(&g);
  if (bad || rename(tmp, path) != 0) {
    const int e = errno;
    remove(tmp);
    return hr_err_set(err, HR_ERR_IO, "%s: cannot write the graph: %s", path, strerror(e));
  }
  return HR_OK;
}
