/* partbench: graph balancing methods compared on a patch/link graph written by `hrad
 * --dump-graph FILE` (BENCHMARKS.md, "Graph balancing").
 *
 *   partbench GRAPH [ALPHA [LONG_EFFORT]]
 *
 * For P = 2, 4, 8, 16, 32, 64 parts: random (a rank per element from its gid, the solver's
 * --balance random), greedy by work alone, ORB of the element centres weighted by work, METIS
 * k-way, the paper's clustering + simulated annealing from ORB's partition, and (with
 * LONG_EFFORT > 0) a long, cautious annealing with every proposal budget times LONG_EFFORT.
 * Prints Z (eq. (5) with ALPHA, default 0.5), the cut, the imbalance (max W / mean W), the
 * partitioning time, and the modelled time of one iteration on a current cluster:
 * max over parts of (W_p t_w + C_p t_c), t_w = 10 ns per unit of work (a link gathered and
 * tested; museum and room runs: 5-6 ns to gather, about as much to test), t_c = 18.4 ns per unit
 * of communication (a 184-byte store at 10 GB/s). */
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
  uint64_t *gid;
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
  for (int i = 0; i < n; i++) {
    unsigned long long g, p;
    if (fscanf(f, "%llx %llx %lf %lf %lf %lf", &g, &p, &G->w[i], &G->xyz[3 * i],
               &G->xyz[3 * i + 1], &G->xyz[3 * i + 2]) != 6)
      return fclose(f), 0;
    G->gid[i] = g;
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
  printf("   P  method         Z          cut  imbalance   time ms  model us/iter\n");
  int32_t *part = malloc((size_t)(g->n + 1) * sizeof *part);
  static const char *const names[] = {"random", "greedy", "orb", "metis", "anneal", "anneal-long"};
  for (int P = 2; P <= 64; P *= 2)
    for (int m = 0; m < 6; m++) {
      if (m == 5 && !(effort > 0)) continue;
      const double t0 = now();
      int ok = 1;
      if (m == 0)
        for (int v = 0; v < g->n; v++)
          part[v] = (int32_t)(mix(1 ^ (G.gid[v] * UINT64_C(0x9e3779b97f4a7c15))) % (uint64_t)P);
      else if (m == 1) ok = hr_partition_greedy(g->w, g->n, P, part);
      else if (m == 2) ok = hr_partition_orb(G.xyz, g->w, g->n, P, part);
      else if (m == 3) ok = hr_partition_metis(g, P, part);
      else {
        ok = hr_partition_orb(G.xyz, g->w, g->n, P, part) &&
             hr_partition_anneal_effort(g, P, alpha, 1, m == 5 ? effort : 1.0, part);
      }
      const double dt = now() - t0;
      double cut = 0, imb = 0;
      const double z = ok ? hr_partition_cost(g, part, P, alpha, &cut, &imb) : -1;
      printf("%4d  %-11s %10.0f %12.0f %10.3f %9.1f %14.1f\n", P, names[m], z, cut, imb,
             1e3 * dt, ok ? 1e6 * model(g, part, P) : -1);
    }
  free(part);
  free(G.xadj), free(G.adj), free(G.w), free(G.c), free(G.xyz), free(G.gid);
  return 0;
}
