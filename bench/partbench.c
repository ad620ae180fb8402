/* partbench: graph balancing methods compared on a patch/link graph written by `hrad
 * --dump-graph FILE` (BENCHMARKS.md, "Graph balancing").
 *
 *   partbench GRAPH [ALPHA [LONG_EFFORT]]
 *
 * For P = 2, 4, 8, 16, 32, 64 parts: random (a rank per element from its gid, the solver's
 * --balance random), greedy by work alone, ORB of the element centres weighted by work, METIS
 * k-way, the paper's clustering + simulated annealing of the whole graph from ORB's partition,
 * (with LONG_EFFORT > 0) a long, cautious annealing with every proposal budget times
 * LONG_EFFORT, and dist-anneal, what the solver's --balance anneal does (dist_anneal below).
 * Prints Z (eq. (5) with ALPHA, default 0.5), the cut, the imbalance (max W / mean W), the
 * partitioning time, and the modelled time of one iteration on a current cluster:
 * max over parts of (W_p t_w + C_p t_c), t_w = 10 ns per unit of work (a link gathered and
 * tested; museum and room runs: 5-6 ns to gather, about as much to test), t_c = 18.4 ns per unit
 * of communication (a 184-byte store at 10 GB/s), and "P-rank ms": the time on P ranks, the
 * partitioning time except for dist-anneal, whose clustering and contraction each rank does
 * for its own elements (1/P of the measured time) before every rank runs a chain: here the P
 * chains run one after another ("time ms" is all of them), and "P-rank ms" counts the median
 * one. dist-anneal starts, as the solver does, from whole surfaces by recursive bisection of
 * their centres, or in a clustered run's graph (nodes with the top gid bit) from preorder runs
 * of the hierarchy, and cuts each part's tree into pieces (beyond HR_PARTITION_CHAINS
 * parts with neighbouring roots joined: hr_partition_tree_cut_near).
 *
 * Environment: PARTBENCH_METHOD=M only method M (0 random .. 6 dist-anneal), PARTBENCH_P=P only
 * P parts, PARTBENCH_PIECES=1 prints dist-anneal's piece count, PARTBENCH_GROW=1 makes its
 * pieces by the paper's growth (hr_partition_cluster) instead, as the solver did before,
 * PARTBENCH_EFFORT=E gives dist-anneal's chains effort E instead of the solver's
 * (hr_partition_chain_effort), PARTBENCH_NEAR=1 (0) cuts joining neighbouring roots (without)
 * at every P instead of the solver's choice, PARTBENCH_CLUSTERS=K aims at K pieces instead of
 * HR_PARTITION_CLUSTERS, PARTBENCH_SCATTER=1 starts an unclustered graph as the solver did
 * before the sixth pass: whole surfaces by weight, largest first, to the least loaded part. */
#include "hrad.h"
#include "partition/partition.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static double now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

typedef struct graph {
  hr_graph g;
  int64_t *xadj;
  int32_t *adj;
  double *w, *c, *xyz;
  uint64_t *gid, *pgid;
} graph;

static int load(const char *path, graph *G) {
  FILE *f = fopen(path, "r");
  if (!f) return 0;
  int n = 0;
  long long ne = 0;
  if (fscanf(f, "hrad-graph 1 nodes %d", &n) != 1 || n < 0) return fclose(f), 0;
  G->w = malloc((size_t)(n + 1) * sizeof *G->w);
  G->xyz = malloc((size_t)(3 * n + 1) * sizeof *G->xyz);
  G->gid = malloc((size_t)(n + 1) * sizeof *G->gid);
  G->pgid = malloc((size_t)(n + 1) * sizeof *G->pgid);
  for (int i = 0; i < n; i++) {
    unsigned long long g, p;
    if (fscanf(f, "%llx %llx %lf %lf %lf %lf", &g, &p, &G->w[i], &G->xyz[3 * i],
               &G->xyz[3 * i + 1], &G->xyz[3 * i + 2]) != 6)
      return fclose(f), 0;
    G->gid[i] = g, G->pgid[i] = p;
  }
  if (fscanf(f, " edges %lld", &ne) != 1 || ne < 0) return fclose(f), 0;
  int32_t *u = malloc((size_t)(ne + 1) * sizeof *u), *v = malloc((size_t)(ne + 1) * sizeof *v);
  double *c = malloc((size_t)(ne + 1) * sizeof *c);
  G->xadj = calloc((size_t)n + 1, sizeof *G->xadj);
  for (long long k = 0; k < ne; k++) {
    if (fscanf(f, "%d %d %lf", &u[k], &v[k], &c[k]) != 3 || u[k] < 0 || u[k] >= n || v[k] < 0 ||
        v[k] >= n)
      return fclose(f), 0;
    G->xadj[u[k] + 1]++, G->xadj[v[k] + 1]++;
  }
  fclose(f);
  for (int i = 0; i < n; i++) G->xadj[i + 1] += G->xadj[i];
  G->adj = malloc((size_t)(2 * ne + 1) * sizeof *G->adj);
  G->c = malloc((size_t)(2 * ne + 1) * sizeof *G->c);
  int64_t *at = malloc((size_t)(n + 1) * sizeof *at);
  memcpy(at, G->xadj, (size_t)(n + 1) * sizeof *at);
  for (long long k = 0; k < ne; k++) {
    G->adj[at[u[k]]] = v[k], G->c[at[u[k]]++] = c[k];
    G->adj[at[v[k]]] = u[k], G->c[at[v[k]]++] = c[k];
  }
  free(at), free(u), free(v), free(c);
  G->g = (hr_graph){n, G->xadj, G->adj, G->w, G->c};
  return 1;
}

/* Modelled seconds of one iteration: the slowest part's work and communication. */
static double model(const hr_graph *g, const int32_t *part, int P) {
  double *W = calloc((size_t)P, sizeof *W), *C = calloc((size_t)P, sizeof *C), t = 0;
  for (int v = 0; v < g->n; v++) {
    W[part[v]] += g->w[v];
    for (int64_t k = g->xadj[v]; k < g->xadj[v + 1]; k++)
      if (part[g->adj[k]] != part[v]) C[part[v]] += g->c[k];
  }
  for (int p = 0; p < P; p++) {
    const double x = W[p] * 10e-9 + C[p] * 18.4e-9;
    t = x > t ? x : t;
  }
  free(W), free(C);
  return t;
}

/* The index of gid in G (gids are written in increasing order), -1 if absent. */
static int32_t index_of(const graph *G, uint64_t gid) {
  int32_t lo = 0, hi = G->g.n;
  while (lo < hi) {
    const int32_t m = lo + (hi - lo) / 2;
    if (G->gid[m] < gid) lo = m + 1;
    else hi = m;
  }
  return lo < G->g.n && G->gid[lo] == gid ? lo : -1;
}

/* A cluster of a clustered run's graph (cluster.h: gids with the top bit). */
static int is_cluster(uint64_t gid) { return (int)(gid >> 63); }

/* The start of a run's first balancing: whole surfaces (an element's tree with its root) by
 * recursive bisection of the roots' centres, here weighted by the work of the tree (the solver,
 * before any work is known, by area); with PARTBENCH_SCATTER by that work, largest first, each
 * to the least loaded part. */
static void whole_surfaces(const graph *G, int P, int32_t *part) {
  const int n = G->g.n;
  int32_t *root = malloc((size_t)(n + 1) * sizeof *root);
  double *tw = calloc((size_t)n + 1, sizeof *tw);
  int32_t *rpart = malloc((size_t)(n + 1) * sizeof *rpart);
  for (int v = 0; v < n; v++) { /* parents have smaller gids? not assumed: follow the chain */
    int32_t r = v, p;
    while (G->pgid[r] && !is_cluster(G->pgid[r]) && (p = index_of(G, G->pgid[r])) >= 0) r = p;
    root[v] = r;
    tw[r] += G->g.w[v];
  }
  /* non-roots weigh 0 here and go anywhere */
  if (getenv("PARTBENCH_SCATTER")) hr_partition_greedy(tw, n, P, rpart);
  else hr_partition_orb(G->xyz, tw, n, P, rpart);
  for (int v = 0; v < n; v++) part[v] = rpart[root[v]];
  free(root), free(tw), free(rpart);
}

/* The tree edges of G (parent and child, weight 2) as a graph of their own: the solver's
 * clustering follows them only. The arrays are malloc'd into t (free xadj, adj, c). */
static void tree_graph(const graph *G, hr_graph *t) {
  const int n = G->g.n;
  int64_t *xadj = calloc((size_t)n + 1, sizeof *xadj), *at = malloc((size_t)(n + 1) * sizeof *at);
  int32_t *adj = malloc((size_t)(2 * n + 1) * sizeof *adj);
  int32_t *par = malloc((size_t)(n + 1) * sizeof *par);
  double *c = malloc((size_t)(2 * n + 1) * sizeof *c);
  for (int v = 0; v < n; v++) {
    par[v] = G->pgid[v] ? index_of(G, G->pgid[v]) : -1;
    if (par[v] >= 0) xadj[v + 1]++, xadj[par[v] + 1]++;
  }
  for (int v = 0; v < n; v++) xadj[v + 1] += xadj[v];
  memcpy(at, xadj, (size_t)(n + 1) * sizeof *at);
  for (int v = 0; v < n; v++)
    if (par[v] >= 0) {
      adj[at[v]] = par[v], c[at[v]++] = 2;
      adj[at[par[v]]] = v, c[at[par[v]]++] = 2;
    }
  free(at), free(par);
  *t = (hr_graph){n, xadj, adj, G->g.w, c};
}

/* The solver's --balance anneal (src/balance.c), here on one core: each part of the start (a
 * rank's elements) is clustered along its own tree edges, the graph of the clusters is annealed
 * from the start by P chains with the ranks' seeds, the lowest Z wins, and it is projected.
 * '*local' gets the time of the clustering and the contraction, which each rank does for its own
 * part (1/P of it each, in the model); '*chain' the median time of a chain (the ranks run theirs
 * at once). */
static int dist_anneal(const graph *G, int P, double alpha, int32_t *part, double *local,
                       double *chain) {
  const hr_graph *g = &G->g;
  /* the start is given in a run: not timed. With clusters, preorder runs of the tree (here by
   * W; the solver, before any work is known, by the surfaces' area): a compact start lets the
   * cut along the tree (clusters included) make pieces of the scene, where whole surfaces
   * scattered by area leave at least one piece per surface; without clusters, surfaces by
   * bisection, whose neighbouring roots the cut joins */
  int clustered = 0;
  for (int v = 0; v < g->n && !clustered; v++) clustered = is_cluster(G->gid[v]);
  int32_t *par = malloc((size_t)(g->n + 1) * sizeof *par);
  for (int v = 0; v < g->n; v++) par[v] = G->pgid[v] ? index_of(G, G->pgid[v]) : -1;
  if (clustered) hr_partition_preorder(par, g->w, g->n, P, part);
  else whole_surfaces(G, P, part);
  const double t1 = now();
  int32_t *cl = malloc((size_t)(g->n + 1) * sizeof *cl);
  double total = 0;
  for (int v = 0; v < g->n; v++) total += g->w[v];
  const char *pc = getenv("PARTBENCH_CLUSTERS");
  int per = (pc ? atoi(pc) : HR_PARTITION_CLUSTERS) / P;
  per = per > HR_PARTITION_CLUSTERS_MIN ? per : HR_PARTITION_CLUSTERS_MIN;
  int nc;
  if (getenv("PARTBENCH_GROW")) {
    hr_graph t;
    tree_graph(G, &t);
    nc = hr_partition_cluster(&t, part, total / ((double)P * per), g->n, cl);
    free((void *)t.xadj), free((void *)t.adj), free((void *)t.c);
  } else {
    /* as the solver (cluster_own in src/balance.c): roots joined beyond full-effort chains */
    const int near = getenv("PARTBENCH_NEAR")  ? atoi(getenv("PARTBENCH_NEAR"))
                                               : P > HR_PARTITION_CHAINS;
    nc = near ? hr_partition_tree_cut_near(par, g->w, G->xyz, g->n, part,
                                           total / ((double)P * per), cl)
              : hr_partition_tree_cut(par, g->w, g->n, part, total / ((double)P * per), cl);
  }
  free(par);
  if (getenv("PARTBENCH_PIECES")) fprintf(stderr, "P %d: %d pieces\n", P, nc);
  int64_t *xadj;
  int32_t *adj, *cpart = malloc((size_t)(nc + 1) * sizeof *cpart);
  int32_t *won = malloc((size_t)(nc + 1) * sizeof *won);
  double *w, *c, *times = malloc((size_t)P * sizeof *times), best = -1;
  int ok = nc >= 0 && hr_partition_contract(g, cl, nc, &xadj, &adj, &w, &c);
  *local = now() - t1;
  if (ok) {
    const hr_graph cg = {nc, xadj, adj, w, c};
    const char *e = getenv("PARTBENCH_EFFORT");
    const double effort = e ? atof(e) : hr_partition_chain_effort(P);
    /* as the solver: the start is the better (Z) of the current parts and the bisection of
     * the pieces' centres (their nodes' centres weighted by W + 1) weighted by W; not timed
     * (a few ms) */
    int32_t *start = malloc((size_t)(nc + 1) * sizeof *start);
    int32_t *orb = malloc((size_t)(nc + 1) * sizeof *orb);
    double *cx = calloc((size_t)(4 * nc) + 1, sizeof *cx);
    for (int v = 0; v < g->n; v++) {
      start[cl[v]] = part[v];
      for (int k = 0; k < 3; k++) cx[4 * cl[v] + k] += (g->w[v] + 1) * G->xyz[3 * v + k];
      cx[4 * cl[v] + 3] += g->w[v] + 1;
    }
    for (int a = 0; a < nc; a++)
      for (int k = 0; k < 3; k++) cx[3 * a + k] = cx[4 * a + k] / cx[4 * a + 3];
    ok = hr_partition_orb(cx, w, nc, P, orb);
    if (ok && hr_partition_cost(&cg, orb, P, alpha, NULL, NULL) <
                  hr_partition_cost(&cg, start, P, alpha, NULL, NULL))
      memcpy(start, orb, (size_t)nc * sizeof *start);
    free(orb), free(cx);
    for (int r = 0; ok && r < P; r++) {
      memcpy(cpart, start, (size_t)nc * sizeof *cpart);
      const double t2 = now();
      ok = hr_partition_anneal_effort(&cg, P, alpha, UINT64_C(1000003) + (uint64_t)r, effort,
                                      cpart);
      times[r] = now() - t2;
      const double z = hr_partition_cost(&cg, cpart, P, alpha, NULL, NULL);
      if (best < 0 || z < best) best = z, memcpy(won, cpart, (size_t)nc * sizeof *won);
    }
    for (int v = 0; ok && v < g->n; v++) part[v] = won[cl[v]];
    free(start);
    free(xadj), free(adj), free(w), free(c);
  }
  for (int i = 1; i < P; i++) /* insertion sort, for the median */
    for (int j = i; j > 0 && times[j] < times[j - 1]; j--) {
      const double x = times[j];
      times[j] = times[j - 1], times[j - 1] = x;
    }
  *chain = times[P / 2];
  free(cl), free(cpart), free(won), free(times);
  return ok;
}

static uint64_t mix(uint64_t z) {
  z = (z ^ (z >> 30)) * UINT64_C(0xbf58476d1ce4e5b9);
  z = (z ^ (z >> 27)) * UINT64_C(0x94d049bb133111eb);
  return z ^ (z >> 31);
}

int main(int argc, char **argv) {
  if (argc < 2) return fprintf(stderr, "usage: partbench GRAPH [ALPHA [LONG_EFFORT]]\n"), 2;
  graph G;
  memset(&G, 0, sizeof G);
  if (!load(argv[1], &G)) return fprintf(stderr, "partbench: %s: cannot read\n", argv[1]), 1;
  const double alpha = argc > 2 ? atof(argv[2]) : 0.5, effort = argc > 3 ? atof(argv[3]) : 0;
  const hr_graph *g = &G.g;
  printf("graph %s: %d nodes, %lld edge entries, alpha %g\n", argv[1], g->n,
         (long long)g->xadj[g->n], alpha);
  printf("   P  method         Z          cut  imbalance   time ms  model us/iter  P-rank ms\n");
  int32_t *part = malloc((size_t)(g->n + 1) * sizeof *part);
  static const char *const names[] = {"random", "greedy", "orb",        "metis",
                                      "anneal", "anneal-long", "dist-anneal"};
  for (int P = 2; P <= 64; P *= 2)
    for (int m = 0; m < 7; m++) {
      if (m == 5 && !(effort > 0)) continue;
      if (getenv("PARTBENCH_METHOD") && atoi(getenv("PARTBENCH_METHOD")) != m) continue;
      if (getenv("PARTBENCH_P") && atoi(getenv("PARTBENCH_P")) != P) continue;
      const double t0 = now();
      int ok = 1;
      double local = 0, chain = 0;
      if (m == 6) ok = dist_anneal(&G, P, alpha, part, &local, &chain);
      else if (m == 0)
        for (int v = 0; v < g->n; v++)
          part[v] = (int32_t)(mix(1 ^ (G.gid[v] * UINT64_C(0x9e3779b97f4a7c15))) % (uint64_t)P);
      else if (m == 1) ok = hr_partition_greedy(g->w, g->n, P, part);
      else if (m == 2) ok = hr_partition_orb(G.xyz, g->w, g->n, P, part);
      else if (m == 3) ok = hr_partition_metis(g, P, part);
      else if (m < 6) {
        ok = hr_partition_orb(G.xyz, g->w, g->n, P, part) &&
             hr_partition_anneal_effort(g, P, alpha, 1, m == 5 ? effort : 1.0, part);
      }
      const double dt = now() - t0;
      double cut = 0, imb = 0;
      const double z = ok ? hr_partition_cost(g, part, P, alpha, &cut, &imb) : -1;
      /* on P ranks: the distributed method's local work is split over them */
      const double ranks_ms = 1e3 * (m == 6 ? local / P + chain : dt);
      printf("%4d  %-11s %10.0f %12.0f %10.3f %9.1f %14.1f %10.1f\n", P, names[m], z, cut, imb,
             1e3 * dt, ok ? 1e6 * model(g, part, P) : -1, ranks_ms);
    }
  free(part);
  free(G.xadj), free(G.adj), free(G.w), free(G.c), free(G.xyz), free(G.gid), free(G.pgid);
  return 0;
}
