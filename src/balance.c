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
 * tree edges (parent and child: weight 2, a push and a pull). For METIS and ORB rank 0
 * gathers it whole (plan_gathered). For annealing (plan_clustered) it is never assembled: each
 * rank clusters its own elements and folds its links into cluster pairs, and every rank runs
 * its own chain on the graph of the clusters from the current owners with its own seed; the
 * best Z wins (the paper's parallel annealing, its reference [1], one period). A new partition
 * is expressed as a subtree map: an element is listed only where its rank differs from its
 * parent's. */
#include "cluster.h"
#include "mpi/dist.h"
#include "partition/partition.h"
#include "solver_impl.h"
#include "vec.h"

#include <assert.h>
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

/* What rank 0 receives for --balance anneal (plan_clustered): a cluster's work, and an
 * element's cluster (or, in the subtree map, its rank). */
typedef struct work_rec {
  int64_t id;
  double w;
} work_rec;
typedef struct centre_rec { /* a piece's centre, from the rank that cut it */
  int64_t id;
  double xyz[3];
} centre_rec;
typedef struct gid_cluster {
  uint64_t gid;
  int64_t id;
} gid_cluster;

/* A cluster's gid (cluster.h), as against an element's. */
static int is_cluster(uint64_t gid) { return (gid & HR_CLUSTER_GID) != 0; }

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

/* g's CSR arrays (g->n nodes) from the half-edges e (m, both directions of each edge; tmp
 * as large, scratch): each row's neighbours in index order with repeated pairs summed. Two
 * counting sorts (by neighbour, then stably by node): O(n + m). 0 when out of memory. */
static int csr_build(bgraph *g, half_edge *e, half_edge *tmp, int64_t m) {
  if (!count_sort(e, m, g->n, 1, tmp) || !count_sort(tmp, m, g->n, 0, e)) return 0;
  g->xadj = calloc((size_t)g->n + 1, sizeof *g->xadj);
  g->adj = malloc((size_t)(m + 1) * sizeof *g->adj);
  g->c = malloc((size_t)(m + 1) * sizeof *g->c);
  if (!g->xadj || !g->adj || !g->c) return 0;
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
  return 1;
}

/* g's CSR arrays (g->n nodes) from 'up', whose rows hold each edge once, at its lower end, in
 * neighbour order: both directions, each row in neighbour order (row x gets its lower
 * neighbours as the rows below x are read, then its own). The same graph as csr_build of both
 * directions, from a third of the memory: at 13.5 us a fresh page here, that was most of rank
 * 0's part of a balancing (BENCHMARKS.md, "Graph balancing, fourth pass"). 0 when out of
 * memory. */
static int csr_mirror(bgraph *g, const bgraph *up) {
  const int64_t m = 2 * up->xadj[up->n];
  g->xadj = calloc((size_t)g->n + 1, sizeof *g->xadj);
  int64_t *at = malloc(((size_t)g->n + 1) * sizeof *at);
  g->adj = malloc((size_t)(m + 1) * sizeof *g->adj);
  g->c = malloc((size_t)(m + 1) * sizeof *g->c);
  if (!g->xadj || !at || !g->adj || !g->c) {
    free(at);
    return 0;
  }
  for (int32_t a = 0; a < up->n; a++)
    for (int64_t k = up->xadj[a]; k < up->xadj[a + 1]; k++)
      g->xadj[a + 1]++, g->xadj[up->adj[k] + 1]++;
  for (int32_t i = 0; i < g->n; i++) g->xadj[i + 1] += g->xadj[i];
  memcpy(at, g->xadj, ((size_t)g->n + 1) * sizeof *at);
  for (int32_t a = 0; a < up->n; a++)
    for (int64_t k = up->xadj[a]; k < up->xadj[a + 1]; k++) {
      const int32_t b = up->adj[k];
      assert(b > a);
      g->adj[at[a]] = b, g->c[at[a]++] = up->c[k];
      g->adj[at[b]] = a, g->c[at[b]++] = up->c[k];
    }
  free(at);
  return 1;
}

/* Builds the CSR graph on rank 0 from the gathered nodes and link edges (both consumed): nodes
 * in gid order. O(nodes log nodes + edges): a comparison sort of the edges took about 2 s a
 * balancing on museum's 4 M links. */
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
    /* none for a cluster: its state is on every rank (cluster.h) */
    if (p < 0 || is_cluster(g->pgid[i])) continue;
    e[m++] = (half_edge){i, p, 2.0};
    e[m++] = (half_edge){p, i, 2.0};
  }
  free(map.key), free(map.val);
  ok = ok && csr_build(g, e, tmp, m);
  free(e), free(tmp);
  return ok;
}

/* The links each element receives here (element links and, gathered like them, cluster
 * links), by element index: malloc'd, NULL when out of memory. */
static int64_t *recv_counts(const hr_solver *s) {
  int64_t *recv = calloc((size_t)s->nel + 1, sizeof *recv);
  if (!recv) return NULL;
  for (int64_t k = 0; k < s->nlinks; k++)
    if (s->links[k].Fu >= 0) recv[s->links[k].r]++;
  hr_cluster_recv_counts(s, recv);
  return recv;
}

/* The refinement work done here for element e's links, per iteration (see RAY_WORK). */
static double ray_work(const hr_solver *s, int64_t e) {
  return RAY_WORK * s->erays[e] / (s->iterations > 1 ? s->iterations : 1);
}

/* W of an element this rank owns (the file's header comment): without the ray work other
 * ranks did for it. */
static double own_work(const hr_solver *s, int64_t e, const int64_t *recv) {
  return (double)recv[e] + 1.0 + ray_work(s, e);
}

/* The work this rank accounts for element e: its W where it owns e, else the ray work it did
 * for e's links (0 if none), which goes to the owner's total. */
static double held_work(const hr_solver *s, int64_t e, const int64_t *recv) {
  return hr_owns(s, e) ? own_work(s, e, recv) : ray_work(s, e);
}

/* The clusters as graph nodes (hr_cluster_graph), with the rays cast for each cluster's links
 * summed over the ranks (a rank counts what it refined; a cluster's links may have moved
 * since), and above[e] the cluster over surface root e: malloc'd, every rank. A collective. */
static hr_cluster_node *cluster_nodes(hr_solver *s, uint64_t *above) {
  const int64_t K = hr_cluster_count(s);
  hr_cluster_node *cn = malloc((size_t)(K + 1) * sizeof *cn);
  double *rays = malloc((size_t)(K + 1) * sizeof *rays);
  if (!cn || !rays || hr_cluster_graph(s, cn, above) < 0) hr_dist_abort(s->dist, 1);
  for (int64_t c = 0; c < K; c++) rays[c] = cn[c].rays;
  hr_dist_sum_f64(s->dist, rays, K);
  for (int64_t c = 0; c < K; c++) cn[c].rays = rays[c];
  free(rays);
  return cn;
}

/* W of a cluster (as own_work of an element, without the push-pull: the clusters' is done
 * alike on every rank). */
static double cluster_work(const hr_solver *s, const hr_cluster_node *c) {
  return (double)c->recv + RAY_WORK * c->rays / (s->iterations > 1 ? s->iterations : 1);
}

/* The clusters as graph nodes (with_clusters in gather_graph): this rank's records of the
 * clusters whose links it holds, at 'nodes'; above[e] gets the cluster over surface root e.
 * Returns the count. A collective. */
static int64_t cluster_records(hr_solver *s, node_rec *nodes, uint64_t *above) {
  const int64_t K = hr_cluster_count(s);
  hr_cluster_node *cn = cluster_nodes(s, above);
  int64_t m = 0;
  for (int64_t c = 0; c < K; c++)
    if (cn[c].mine)
      nodes[m++] = (node_rec){cn[c].gid, cn[c].parent, cluster_work(s, &cn[c]),
                              {cn[c].xyz[0], cn[c].xyz[1], cn[c].xyz[2]}};
  free(cn);
  return m;
}

/* Gathers the graph on rank 0 ('g' filled there; zeroed elsewhere). A collective. With
 * 'with_clusters' (--dump-graph of a clustered run) the clusters are nodes too: W the links
 * they receive and the rays cast for them, parents their parent clusters (a surface root's is
 * the cluster above it), and edges the links they receive from surfaces (links from clusters,
 * and tree edges to clusters, cost no messages: the clusters' state is on every rank). */
static hr_status gather_graph(hr_solver *s, bgraph *g, int with_clusters, hr_err *err) {
  memset(g, 0, sizeof *g);
  const int64_t K = with_clusters ? hr_cluster_count(s) : 0;
  const int64_t ncl = K > 0 ? hr_cluster_links(s) : 0;
  int64_t nrec = 0, nl = 0; /* node records: own elements, and others' with rays cast here */
  for (int64_t e = 0; e < s->nel; e++) nrec += hr_owns(s, e) || s->erays[e] > 0;
  for (int64_t k = 0; k < s->nlinks; k++) nl += s->links[k].Fu >= 0;
  node_rec *nodes = malloc((size_t)(nrec + K + 1) * sizeof *nodes);
  edge_rec *ed = malloc((size_t)(nl + ncl + 1) * sizeof *ed);
  uint64_t *above = calloc((size_t)(K > 0 ? s->scene->nsurfs : 0) + 1, sizeof *above);
  int64_t *recv = recv_counts(s);
  if (!nodes || !ed || !recv || !above) hr_dist_abort(s->dist, 1); /* all must take part */
  int64_t i = K > 0 ? cluster_records(s, nodes + nrec, above) : 0;
  nrec += i;
  i = 0;
  for (int64_t e = 0; e < s->nel; e++) {
    if (!hr_owns(s, e)) {
      if (s->erays[e] > 0) nodes[i++] = (node_rec){s->el[e].gid, EXTRA, ray_work(s, e), {0}};
      continue;
    }
    const int32_t p = s->el[e].parent;
    nodes[i++] = (node_rec){s->el[e].gid, p >= 0 ? s->el[p].gid : K > 0 ? above[e] : 0,
                            own_work(s, e, recv), {s->el[e].c.x, s->el[e].c.y, s->el[e].c.z}};
  }
  i = 0;
  for (int64_t k = 0; k < s->nlinks; k++)
    if (s->links[k].Fu >= 0)
      ed[i++] = (edge_rec){s->el[s->links[k].r].gid, s->el[s->links[k].s].gid};
  if (K > 0) {
    uint64_t(*pair)[2] = malloc((size_t)(ncl + 1) * sizeof *pair);
    if (!pair) hr_dist_abort(s->dist, 1);
    const int64_t np = hr_cluster_elem_sources(s, pair);
    for (int64_t k = 0; k < np; k++) ed[i++] = (edge_rec){pair[k][0], pair[k][1]};
    free(pair);
    nl = i;
  }
  free(recv), free(above);
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

/* The partition of 'method' (METIS or ORB) for P parts into part[] (rank 0's graph). 0 when
 * out of memory. */
static int partition(const bgraph *g, int method, int P, int32_t *part) {
  const hr_graph v = view(g);
  return method == HR_BALANCE_METIS ? hr_partition_metis(&v, P, part)
                                    : hr_partition_orb(g->xyz, g->w, g->n, P, part);
}

/* The subtree map of a partition: roots always, other elements where their part differs from
 * their parent's. Returns the count; gids and ranks (n each) filled. */
static int64_t subtree_map(const bgraph *g, const int32_t *part, uint64_t *gids, int32_t *ranks) {
  int64_t m = 0;
  for (int32_t i = 0; i < g->n; i++) {
    /* clusters always (their owners are not inherited), and surface roots under them */
    const int32_t p = g->pgid[i] && !is_cluster(g->pgid[i]) ? node_of(g, g->pgid[i]) : -1;
    if (!is_cluster(g->gid[i]) && p >= 0 && part[p] == part[i]) continue;
    gids[m] = g->gid[i], ranks[m++] = part[i];
  }
  return m;
}

/* Every rank gets rank 0's subtree map ('*m' entries of '*gids' and '*ranks'). A collective. */
static hr_status share_map(hr_solver *s, int64_t *m, uint64_t **gids, int32_t **ranks) {
  hr_dist_bcast(s->dist, m, sizeof *m);
  if (s->rank != 0) {
    *gids = malloc((size_t)(*m + 1) * sizeof **gids);
    *ranks = malloc((size_t)(*m + 1) * sizeof **ranks);
    if (!*gids || !*ranks) hr_dist_abort(s->dist, 1);
  }
  hr_dist_bcast(s->dist, *gids, (size_t)*m * sizeof **gids);
  hr_dist_bcast(s->dist, *ranks, (size_t)*m * sizeof **ranks);
  return HR_OK;
}

/* A clustered run's hierarchy as --balance anneal sees it (H clusters, 0 without): the nodes
 * (cluster_nodes), the cluster above each surface root, and each cluster's piece (ccl, -1 where
 * another rank owns it). */
typedef struct hier {
  int64_t H;
  hr_cluster_node *cn;
  uint64_t *above;
  int32_t *ccl;
} hier;

static void hier_free(hier *h) {
  free(h->cn), free(h->above), free(h->ccl);
  memset(h, 0, sizeof *h);
}

/* The subtree map of a partition of the pieces: each rank lists its own elements that are
 * roots or go to another rank than their parent (whose piece it knows) and its own clusters,
 * rank 0 collects them and every rank gets the map. A collective. */
static hr_status cluster_map(hr_solver *s, const int32_t *ecl, const hier *h,
                             const int32_t *part, int64_t *m, uint64_t **gids, int32_t **ranks) {
  gid_cluster *mine = malloc((size_t)(s->nel + h->H + 1) * sizeof *mine);
  if (!mine) hr_dist_abort(s->dist, 1);
  int64_t n = 0;
  for (int64_t i = 0; i < s->nel; i++) {
    if (!hr_owns(s, i) || ecl[i] < 0) continue;
    const int32_t p = s->el[i].parent, r = part[ecl[i]];
    if (p >= 0 && ecl[p] >= 0 && part[ecl[p]] == r) continue;
    mine[n++] = (gid_cluster){s->el[i].gid, r};
  }
  for (int64_t c = 0; c < h->H; c++)
    if (h->ccl[c] >= 0) mine[n++] = (gid_cluster){h->cn[c].gid, part[h->ccl[c]]};
  void *all = NULL;
  int64_t nall = 0;
  hr_status st = to_rank0(s, mine, n, sizeof *mine, &all, &nall);
  free(mine);
  if (st != HR_OK) return st;
  *m = nall;
  if (s->rank == 0) {
    *gids = malloc((size_t)(nall + 1) * sizeof **gids);
    *ranks = malloc((size_t)(nall + 1) * sizeof **ranks);
    if (!*gids || !*ranks) hr_dist_abort(s->dist, 1);
    const gid_cluster *got = all;
    for (int64_t j = 0; j < nall; j++) (*gids)[j] = got[j].gid, (*ranks)[j] = (int32_t)got[j].id;
  }
  free(all);
  return share_map(s, m, gids, ranks);
}

/* Is the partition with Z z_new worth moving to from z_now? Rank 0 decides (the timings the
 * second gate reads are rank 0's) and every rank gets the answer. A collective. */
static int take_partition(hr_solver *s, double z_now, double z_new) {
  int take = s->rank == 0 && z_new < KEEP_GAIN * z_now && worth_moving(s, z_now, z_new);
  hr_dist_bcast(s->dist, &take, sizeof take);
  return take;
}

/* METIS or ORB on the whole graph, gathered on rank 0: '*m' gets the subtree map's length (on
 * every rank, with its gids and ranks), or -1 when the partition is not worth moving to. */
static hr_status plan_gathered(hr_solver *s, int method, int64_t *m, uint64_t **gids,
                               int32_t **ranks, hr_err *err) {
  bgraph g;
  hr_status st = gather_graph(s, &g, s->cl != NULL, err);
  if (st != HR_OK) return st;
  const int P = s->nranks;
  double z_now = 0, z_new = 0;
  int32_t *part = NULL, *now = NULL;
  int ok = 1;
  if (s->rank == 0) {
    part = malloc((size_t)(g.n + 1) * sizeof *part);
    now = malloc((size_t)(g.n + 1) * sizeof *now);
    ok = part && now && partition(&g, method, P, part);
  }
  if (hr_dist_any(s->dist, !ok)) {
    free(part), free(now);
    bgraph_free(&g);
    return hr_err_set(err, HR_ERR_NOMEM, "out of memory (balancing)");
  }
  if (s->rank == 0) {
    for (int32_t i = 0; i < g.n; i++)
      now[i] = is_cluster(g.gid[i]) ? hr_cluster_owner(s, (int32_t)(g.gid[i] & ~HR_CLUSTER_GID))
                                    : hr_owner_of(s, g.gid[i]);
    const hr_graph v = view(&g);
    z_now = hr_partition_cost(&v, now, P, s->bal_alpha, NULL, NULL);
    z_new = hr_partition_cost(&v, part, P, s->bal_alpha, NULL, NULL);
  }
  *m = -1;
  if (take_partition(s, z_now, z_new)) {
    if (s->rank == 0) {
      *gids = malloc((size_t)(g.n + 1) * sizeof **gids);
      *ranks = malloc((size_t)(g.n + 1) * sizeof **ranks);
      if (!*gids || !*ranks) hr_dist_abort(s->dist, 1);
      *m = subtree_map(&g, part, *gids, *ranks);
    }
    st = share_map(s, m, gids, ranks);
  }
  free(part), free(now);
  bgraph_free(&g);
  return st;
}

/* ---- the paper's clustering, where the elements are (--balance anneal) -------------------- */

/* The nodes of the tree that this rank owns, as graph balancing's clustering sees them: its own
 * elements and, in a clustered run, its own clusters (cn, K of them; 'above' from
 * cluster_nodes). Local node i is element elem[i] for i < ne, else cluster elem[i]; par[i] is
 * the local parent (an element's parent, a surface root's cluster above, a cluster's parent)
 * where this rank owns it, else -1. */
typedef struct local_tree {
  int32_t n, ne;
  int64_t *elem;
  int32_t *par;
  double *w, *xyz; /* n, 3n: work and centre */
} local_tree;

static int local_tree_make(const hr_solver *s, const int64_t *recv, const hr_cluster_node *cn,
                           int64_t K, const uint64_t *above, local_tree *lt) {
  int32_t *lix = malloc((size_t)(s->nel + 1) * sizeof *lix); /* element -> local node */
  int32_t *cix = malloc((size_t)(K + 1) * sizeof *cix);        /* cluster -> local node */
  lt->elem = malloc((size_t)(s->nel + K + 1) * sizeof *lt->elem);
  lt->par = malloc((size_t)(s->nel + K + 1) * sizeof *lt->par);
  lt->w = malloc((size_t)(s->nel + K + 1) * sizeof *lt->w);
  lt->xyz = malloc((size_t)(3 * (s->nel + K) + 1) * sizeof *lt->xyz);
  const int ok = lix && cix && lt->elem && lt->par && lt->w && lt->xyz;
  lt->n = 0;
  for (int64_t i = 0; ok && i < s->nel; i++)
    lix[i] = hr_owns(s, i) ? (lt->elem[lt->n] = i, lt->n++) : -1;
  lt->ne = lt->n;
  for (int64_t c = 0; ok && c < K; c++)
    cix[c] = cn[c].mine ? (lt->elem[lt->n] = c, lt->n++) : -1;
  for (int32_t i = 0; ok && i < lt->n; i++) {
    int32_t p = -1;
    if (i < lt->ne) {
      const int64_t e = lt->elem[i];
      const int32_t ep = s->el[e].parent;
      lt->w[i] = own_work(s, e, recv);
      lt->xyz[3 * i] = s->el[e].c.x, lt->xyz[3 * i + 1] = s->el[e].c.y;
      lt->xyz[3 * i + 2] = s->el[e].c.z;
      if (ep >= 0) p = lix[ep];
      else if (K > 0) p = cix[above[e] & ~HR_CLUSTER_GID];
    } else {
      const hr_cluster_node *c = &cn[lt->elem[i]];
      lt->w[i] = cluster_work(s, c);
      for (int k = 0; k < 3; k++) lt->xyz[3 * i + k] = c->xyz[k];
      if (c->parent) p = cix[c->parent & ~HR_CLUSTER_GID];
    }
    lt->par[i] = p;
  }
  free(lix), free(cix);
  return ok;
}

static void local_tree_free(local_tree *lt) {
  free(lt->elem), free(lt->par), free(lt->w), free(lt->xyz);
  memset(lt, 0, sizeof *lt);
}

/* Clusters this rank's own nodes (local_tree) into pieces of about 'bound' of work, cut from
 * their tree bottom-up (hr_partition_tree_cut): ecl[e] gets the piece (from 0) of each element
 * it owns, -1 for the others, and ccl[c] each cluster's (K of them). Returns the count, -1
 * when out of memory. Along the tree only, not the links: the pieces are subtrees, spatially
 * compact, the pass is O(nodes), and measured on museum's final graph the partitions came out
 * as good or better than with the links (BENCHMARKS.md, "Graph balancing, third pass"), whose
 * pass took 0.4-0.9 s a balancing at 2 ranks. Cut rather than grown from seeds: growth
 * strands pieces of a tree (BENCHMARKS.md, "Graph balancing, fifth pass"). */
static int32_t cluster_own(const hr_solver *s, const int64_t *recv, const hier *h, double bound,
                           int32_t *ecl) {
  local_tree lt = {0};
  int32_t *lcl = malloc((size_t)(s->nel + h->H + 1) * sizeof *lcl), nc = -1;
  if (lcl && local_tree_make(s, recv, h->cn, h->H, h->above, &lt))
    nc = s->nranks > HR_PARTITION_CHAINS
             ? hr_partition_tree_cut_near(lt.par, lt.w, lt.xyz, lt.n, NULL, bound, lcl)
             : hr_partition_tree_cut(lt.par, lt.w, lt.n, NULL, bound, lcl);
  for (int64_t i = 0; nc >= 0 && i < s->nel; i++) ecl[i] = -1;
  for (int64_t c = 0; nc >= 0 && c < h->H; c++) h->ccl[c] = -1;
  for (int32_t i = 0; nc >= 0 && i < lt.n; i++) {
    if (i < lt.ne) ecl[lt.elem[i]] = lcl[i];
    else h->ccl[lt.elem[i]] = lcl[i];
  }
  free(lcl);
  local_tree_free(&lt);
  return nc;
}

/* Every rank learns the cluster of every element it holds but does not own (ecl[e] < 0 on
 * entry): each rank's (gid, cluster) pairs go to all. A collective. */
static hr_status share_clusters(hr_solver *s, int32_t *ecl) {
  int64_t n = 0;
  for (int64_t i = 0; i < s->nel; i++) n += ecl[i] >= 0;
  gid_cluster *mine = malloc((size_t)(n + 1) * sizeof *mine);
  if (!mine) hr_dist_abort(s->dist, 1);
  n = 0;
  for (int64_t i = 0; i < s->nel; i++)
    if (ecl[i] >= 0) mine[n++] = (gid_cluster){s->el[i].gid, ecl[i]};
  void *all = NULL;
  int64_t nall = 0;
  hr_status st = to_rank0(s, mine, n, sizeof *mine, &all, &nall);
  free(mine);
  if (st != HR_OK) return st;
  hr_dist_bcast(s->dist, &nall, sizeof nall);
  gid_cluster *pairs = s->rank == 0 ? all : malloc((size_t)(nall + 1) * sizeof *pairs);
  if (s->rank != 0) free(all); /* (what the others receive is empty) */
  uint64_t *gid = malloc((size_t)(nall + 1) * sizeof *gid);
  if (!pairs || !gid) hr_dist_abort(s->dist, 1);
  hr_dist_bcast(s->dist, pairs, (size_t)nall * sizeof *pairs);
  for (int64_t j = 0; j < nall; j++) gid[j] = pairs[j].gid;
  gid_map map = {0};
  if (!gid_map_build(&map, gid, (int32_t)nall)) hr_dist_abort(s->dist, 1);
  for (int64_t i = 0; i < s->nel; i++) {
    if (ecl[i] >= 0) continue;
    const int32_t j = gid_map_get(&map, s->el[i].gid);
    ecl[i] = j >= 0 ? (int32_t)pairs[j].id : -1;
  }
  free(map.key), free(map.val), free(gid), free(pairs);
  return HR_OK;
}

/* Up to this many pieces, fold_clusters counts the pairs in a dense triangle (4 bytes a pair:
 * 32 MB at 4,096) instead of listing every link and sorting the list: at 2 ranks the list of
 * the conference room's 11 M links a rank took 1.6 s a balancing, most of it fresh pages. */
#define FOLD_DENSE_MAX 4096

/* Index of pair (a, b), a < b, in the triangle of K pieces. */
static int64_t tri_at(int64_t a, int64_t b, int64_t K) {
  return a * (2 * K - a - 1) / 2 + b - a - 1;
}

/* The pairs of pieces that edges join, summed as the edges come: a dense triangle of counts
 * where K is small (the weights are 1 and 2, so the counts are the sums exactly), else a list
 * of the edges that acc_pairs sorts and merges (csr_build). */
typedef struct pair_acc {
  int32_t K;
  uint32_t *cnt;
  half_edge *e;
  int64_t m;
} pair_acc;

/* Room for up to 'cap' edges; 0 when out of memory. */
static int acc_init(pair_acc *p, int32_t K, int64_t cap) {
  memset(p, 0, sizeof *p);
  p->K = K;
  if (K <= FOLD_DENSE_MAX) {
    p->cnt = calloc((size_t)K * (size_t)(K > 0 ? K - 1 : 0) / 2 + 1, sizeof *p->cnt);
    return p->cnt != NULL;
  }
  return (p->e = malloc((size_t)(cap + 1) * sizeof *p->e)) != NULL;
}

static void acc_add(pair_acc *p, int32_t a, int32_t b, double c) {
  if (a > b) {
    const int32_t x = a;
    a = b, b = x;
  }
  if (p->cnt) p->cnt[tri_at(a, b, p->K)] += (uint32_t)c;
  else p->e[p->m++] = (half_edge){a, b, c};
}

/* The summed pairs (a < b) in row order, neighbours in index order, as a new array '*out';
 * returns their count (p is freed), -1 when out of memory. */
static int64_t acc_pairs(pair_acc *p, half_edge **out) {
  int64_t np = 0;
  *out = NULL;
  if (p->cnt) {
    const int64_t nt = (int64_t)p->K * (p->K > 0 ? p->K - 1 : 0) / 2;
    for (int64_t k = 0; k < nt; k++) np += p->cnt[k] != 0;
    *out = malloc((size_t)(np + 1) * sizeof **out);
    np = 0;
    for (int32_t a = 0; *out && a < p->K; a++)
      for (int32_t b = a + 1; b < p->K; b++) {
        const uint32_t c = p->cnt[tri_at(a, b, p->K)];
        if (c) (*out)[np++] = (half_edge){a, b, (double)c};
      }
    free(p->cnt);
    return *out ? np : -1;
  }
  half_edge *tmp = malloc((size_t)(p->m + 1) * sizeof *tmp);
  bgraph lg = {.n = p->K};
  const int ok = tmp && csr_build(&lg, p->e, tmp, p->m);
  for (int32_t a = 0; ok && a < p->K; a++)
    for (int64_t k = lg.xadj[a]; k < lg.xadj[a + 1]; k++)
      p->e[np++] = (half_edge){a, lg.adj[k], lg.c[k]};
  free(tmp);
  bgraph_free(&lg);
  *out = p->e;
  if (!ok) free(p->e), *out = NULL;
  return ok ? np : -1;
}

/* The graph of the clusters, assembled on rank 0 from what each rank folds of its own links,
 * tree edges and work (cluster pairs and sums: the graph's edge and node weights as
 * gather_graph's, summed over the clusters) and given to every rank. A collective. */
static hr_status fold_clusters(hr_solver *s, const int32_t *ecl, const hier *h, int32_t K,
                               const int64_t *recv, bgraph *g) {
  const int64_t ncl = h->H > 0 ? hr_cluster_links(s) : 0;
  pair_acc acc; /* one edge a link and a tree edge at most */
  double *w = calloc((size_t)K + 1, sizeof *w);
  uint64_t(*pair)[2] = malloc((size_t)(ncl + 1) * sizeof *pair);
  if (!acc_init(&acc, K, s->nlinks + ncl + s->nel) || !w || !pair) hr_dist_abort(s->dist, 1);
  for (int64_t k = 0; k < s->nlinks; k++) {
    const int32_t a = ecl[s->links[k].r], b = ecl[s->links[k].s];
    if (s->links[k].Fu >= 0 && a >= 0 && b >= 0 && a != b) acc_add(&acc, a, b, 1.0);
  }
  /* the clusters' links from surfaces (gather_graph's edges), and the clusters' work */
  const int64_t np0 = h->H > 0 ? hr_cluster_elem_sources(s, pair) : 0;
  for (int64_t k = 0; k < np0; k++) {
    const int32_t src = hr_elem_find(s, pair[k][1]);
    const int32_t a = h->ccl[pair[k][0] & ~HR_CLUSTER_GID], b = src >= 0 ? ecl[src] : -1;
    if (a >= 0 && b >= 0 && a != b) acc_add(&acc, a, b, 1.0);
  }
  free(pair);
  /* the centres of this rank's pieces: of their nodes, weighted by W + 1 */
  double *cs = calloc((size_t)(4 * K) + 1, sizeof *cs);
  if (!cs) hr_dist_abort(s->dist, 1);
  for (int64_t c = 0; c < h->H; c++) {
    if (h->ccl[c] < 0) continue;
    const double wc = cluster_work(s, &h->cn[c]);
    double *x = cs + 4 * h->ccl[c];
    w[h->ccl[c]] += wc;
    for (int k = 0; k < 3; k++) x[k] += (wc + 1) * h->cn[c].xyz[k];
    x[3] += wc + 1;
  }
  for (int64_t i = 0; i < s->nel; i++) {
    if (ecl[i] < 0) continue;
    const double wi = held_work(s, i, recv);
    w[ecl[i]] += wi;
    if (!hr_owns(s, i)) continue;
    double *x = cs + 4 * ecl[i];
    x[0] += (wi + 1) * s->el[i].c.x, x[1] += (wi + 1) * s->el[i].c.y;
    x[2] += (wi + 1) * s->el[i].c.z, x[3] += wi + 1;
    const int32_t p = s->el[i].parent, b = p >= 0 ? ecl[p] : -1;
    if (b >= 0 && b != ecl[i]) acc_add(&acc, ecl[i], b, 2.0);
  }
  /* one record per pair (a < b) and per cluster with work: O(links / P) folded to O(pairs) */
  half_edge *e = NULL, *tmp = NULL;
  const int64_t np = acc_pairs(&acc, &e);
  if (np < 0) hr_dist_abort(s->dist, 1);
  int64_t nw = 0;
  for (int32_t a = 0; a < K; a++) nw += w[a] > 0;
  work_rec *wr = malloc((size_t)(nw + 1) * sizeof *wr);
  if (!wr) hr_dist_abort(s->dist, 1);
  nw = 0;
  for (int32_t a = 0; a < K; a++)
    if (w[a] > 0) wr[nw++] = (work_rec){a, w[a]};
  int64_t nx = 0;
  for (int32_t a = 0; a < K; a++) nx += cs[4 * a + 3] > 0;
  centre_rec *xr = malloc((size_t)(nx + 1) * sizeof *xr);
  if (!xr) hr_dist_abort(s->dist, 1);
  nx = 0;
  for (int32_t a = 0; a < K; a++) {
    const double *x = cs + 4 * a;
    if (x[3] > 0) xr[nx++] = (centre_rec){a, {x[0] / x[3], x[1] / x[3], x[2] / x[3]}};
  }
  free(cs);
  void *ae = NULL, *aw = NULL, *ax = NULL;
  int64_t ne = 0, nwall = 0, nxall = 0;
  hr_status st = to_rank0(s, e, np, sizeof *e, &ae, &ne);
  free(e);
  if (st == HR_OK) st = to_rank0(s, wr, nw, sizeof *wr, &aw, &nwall);
  free(wr);
  if (st == HR_OK) st = to_rank0(s, xr, nx, sizeof *xr, &ax, &nxall);
  free(xr);
  memset(g, 0, sizeof *g);
  if (st == HR_OK && s->rank == 0) {
    g->n = K;
    g->w = calloc((size_t)K + 1, sizeof *g->w);
    g->xyz = calloc((size_t)(3 * K) + 1, sizeof *g->xyz);
    tmp = malloc((size_t)(ne + 1) * sizeof *tmp);
    if (!g->w || !g->xyz || !tmp) hr_dist_abort(s->dist, 1);
    for (int64_t j = 0; j < nwall; j++) g->w[((work_rec *)aw)[j].id] += ((work_rec *)aw)[j].w;
    for (int64_t j = 0; j < nxall; j++) {
      const centre_rec *x = (const centre_rec *)ax + j;
      memcpy(g->xyz + 3 * x->id, x->xyz, sizeof x->xyz);
    }
    /* the ranks' pairs (a < b), merged, then both directions */
    bgraph up = {.n = K};
    if (!csr_build(&up, ae, tmp, ne) || !csr_mirror(g, &up)) hr_dist_abort(s->dist, 1);
    bgraph_free(&up);
    free(tmp);
  }
  free(ae), free(aw), free(ax), free(w);
  if (st == HR_OK) share_graph(s, g);
  return st;
}

/* The paper's method, where the elements are: each rank clusters its own elements
 * (HR_PARTITION_CLUSTERS over all ranks), the graph of the clusters (a few thousand nodes, its
 * edges folded by each rank from its own links) goes to every rank, each anneals it from the
 * current owners with its own seed, and the chain with the lowest Z wins (the paper's parallel
 * annealing, its reference [1], one period). O(links / P) a rank instead of the whole graph
 * on rank 0 (docs/design.md, "Balancing"). '*m' as plan_gathered's. */
static hr_status plan_clustered(hr_solver *s, int64_t *m, uint64_t **gids, int32_t **ranks,
                                hr_err *err) {
  const int P = s->nranks;
  int64_t *recv = recv_counts(s), *first = calloc((size_t)P + 1, sizeof *first);
  int32_t *ecl = malloc((size_t)(s->nel + 1) * sizeof *ecl);
  if (!recv || !first || !ecl) hr_dist_abort(s->dist, 1);
  hier h = {0};
  if (s->cl) { /* a clustered run: its clusters are nodes too */
    h.H = hr_cluster_count(s);
    h.above = calloc((size_t)s->scene->nsurfs + 1, sizeof *h.above);
    h.ccl = malloc((size_t)(h.H + 1) * sizeof *h.ccl);
    if (!h.above || !h.ccl) hr_dist_abort(s->dist, 1);
    h.cn = cluster_nodes(s, h.above);
  }
  double total = 0;
  for (int64_t i = 0; i < s->nel; i++) total += held_work(s, i, recv);
  for (int64_t c = 0; c < h.H; c++) total += h.cn[c].mine ? cluster_work(s, &h.cn[c]) : 0;
  hr_dist_sum_f64(s->dist, &total, 1);
  const int per = HR_PARTITION_CLUSTERS / P > HR_PARTITION_CLUSTERS_MIN
                      ? HR_PARTITION_CLUSTERS / P
                      : HR_PARTITION_CLUSTERS_MIN;
  const int32_t nc = cluster_own(s, recv, &h, total / ((double)P * per), ecl);
  if (nc < 0) hr_dist_abort(s->dist, 1);
  first[s->rank + 1] = nc; /* cluster ids: rank r's from first[r] */
  hr_dist_sum_i64(s->dist, first + 1, P);
  for (int r = 0; r < P; r++) first[r + 1] += first[r];
  for (int64_t i = 0; i < s->nel; i++)
    if (ecl[i] >= 0) ecl[i] += (int32_t)first[s->rank];
  for (int64_t c = 0; c < h.H; c++)
    if (h.ccl[c] >= 0) h.ccl[c] += (int32_t)first[s->rank];
  const int32_t K = (int32_t)first[P];
  bgraph g;
  hr_status st = share_clusters(s, ecl);
  if (st == HR_OK) st = fold_clusters(s, ecl, &h, K, recv, &g);
  free(recv);
  *m = -1;
  if (st != HR_OK) {
    free(first), free(ecl);
    hier_free(&h);
    return hr_dist_agree(s, hr_err_set(err, st, "out of memory (balancing)"), err);
  }
  int32_t *now = malloc((size_t)(K + 1) * sizeof *now);
  int32_t *part = malloc((size_t)(K + 1) * sizeof *part);
  if (!now || !part) hr_dist_abort(s->dist, 1);
  for (int r = 0; r < P; r++)
    for (int64_t c = first[r]; c < first[r + 1]; c++) now[c] = part[c] = r;
  const hr_graph v = view(&g);
  /* the chains start from the current owners or from the bisection of the pieces' centres
   * weighted by W, whichever has the lower Z (the conference room at 8 ranks: 1.043 -> 1.015 of
   * the best Z found by any method; BENCHMARKS.md, "Graph balancing, sixth pass") */
  int32_t *orb = malloc((size_t)(K + 1) * sizeof *orb);
  if (!orb || !hr_partition_orb(g.xyz, g.w, K, P, orb)) hr_dist_abort(s->dist, 1);
  if (hr_partition_cost(&v, orb, P, s->bal_alpha, NULL, NULL) <
      hr_partition_cost(&v, part, P, s->bal_alpha, NULL, NULL))
    memcpy(part, orb, (size_t)K * sizeof *part);
  free(orb);
  const uint64_t seed =
      s->opt.seed * 1000003 + (uint64_t)s->rank + (uint64_t)s->nbalance * 7919;
  const double effort = hr_partition_chain_effort(P); /* P chains: each may be shorter */
  if (hr_dist_any(s->dist,
                  !hr_partition_anneal_effort(&v, P, s->bal_alpha, seed, effort, part)))
    st = hr_err_set(err, HR_ERR_NOMEM, "out of memory (balancing)");
  if (st == HR_OK) { /* the chain with the lowest Z wins (ties: the lowest rank) */
    const int win = hr_dist_argmin(s->dist, hr_partition_cost(&v, part, P, s->bal_alpha, NULL,
                                                                NULL));
    hr_dist_bcast_from(s->dist, win, part, (size_t)K * sizeof *part);
    const double z_now = hr_partition_cost(&v, now, P, s->bal_alpha, NULL, NULL);
    const double z_new = hr_partition_cost(&v, part, P, s->bal_alpha, NULL, NULL);
    if (take_partition(s, z_now, z_new)) st = cluster_map(s, ecl, &h, part, m, gids, ranks);
  }
  free(now), free(part), free(first), free(ecl);
  hier_free(&h);
  bgraph_free(&g);
  return st;
}

hr_status hr_solver_balance(hr_solver *s, int method, hr_err *err) {
  if (!s->dist || method == HR_BALANCE_NONE) return HR_OK;
  const double t0 = hr_now();
  int64_t m = -1;
  uint64_t *gids = NULL;
  int32_t *ranks = NULL;
  hr_status st = method == HR_BALANCE_ANNEAL ? plan_clustered(s, &m, &gids, &ranks, err)
                                             : plan_gathered(s, method, &m, &gids, &ranks, err);
  if (st == HR_OK && m >= 0) {
    const double tm = hr_now();
    st = hr_solver_migrate(s, gids, ranks, m, err);
    s->t_migrate = hr_now() - tm;
    s->nmoved++;
  }
  free(gids), free(ranks);
  s->nbalance++;
  s->t_bal_last = hr_now() - t0;
  s->t.balance += s->t_bal_last;
  return st;
}

hr_status hr_solver_dump_graph(hr_solver *s, const char *path, hr_err *err) {
  bgraph g;
  hr_status st = gather_graph(s, &g, s->cl != NULL, err);
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
