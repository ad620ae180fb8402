/* test_partition_anneal: the paper's cost Z (eq. (5)) against hand-computed values, and the
 * clustering + simulated annealing partitioner (partition/anneal.c) on a 32x32 grid graph:
 * from width-1 stripes it must come near the quadrants' optimum, from the quadrants it must not
 * get worse, it repeats itself for a seed, and it rejects bad input; on a random graph with
 * planted groups it finds them. The clustering and contraction that distributed balancing uses
 * (hr_partition_cluster, hr_partition_contract): clusters stay inside the given parts and under
 * the bound, and Z of the contracted graph equals Z of the projected partition. */
#include "partition/partition.h"
#include "testutil.h"
#include "xorshift.h"

#include <stdlib.h>
#include <string.h>
#include <time.h>

#define SIDE 32
#define NODES (SIDE * SIDE)
#define PARTS 4
#define ALPHA 0.5
/* The quadrants: W_p = 256, C_p = 32, so Z = 0.5 * (256 + 32) = 144, with the least cut of a
 * balanced 4-way split of the grid, 64 edges. */
#define QUADRANT_Z 144.0
#define QUADRANT_CUT 64.0

/* A CSR graph with its own storage. */
typedef struct test_graph {
  hr_graph g;
  int64_t xadj[NODES + 1];
  int32_t adj[4 * NODES];
  double w[NODES], c[4 * NODES];
} test_graph;

static void add_edge_end(test_graph *t, int64_t *e, int32_t u, double c) {
  t->adj[*e] = u;
  t->c[*e] = c;
  ++*e;
}

/* SIDE x SIDE nodes of weight 1, 4-neighbour edges of weight 1. */
static void make_grid(test_graph *t) {
  int64_t e = 0;
  for (int y = 0; y < SIDE; y++)
    for (int x = 0; x < SIDE; x++) {
      const int v = y * SIDE + x;
      t->xadj[v] = e;
      t->w[v] = 1.0;
      if (x > 0) add_edge_end(t, &e, v - 1, 1.0);
      if (x < SIDE - 1) add_edge_end(t, &e, v + 1, 1.0);
      if (y > 0) add_edge_end(t, &e, v - SIDE, 1.0);
      if (y < SIDE - 1) add_edge_end(t, &e, v + SIDE, 1.0);
    }
  t->xadj[NODES] = e;
  t->g = (hr_graph){NODES, t->xadj, t->adj, t->w, t->c};
}

/* Columns of width 1 dealt round-robin: every horizontal edge is cut (992 of 1984). */
static void stripes(int32_t *part) {
  for (int v = 0; v < NODES; v++) part[v] = (v % SIDE) % PARTS;
}

static void quadrants(int32_t *part) {
  for (int v = 0; v < NODES; v++)
    part[v] = (v % SIDE >= SIDE / 2) + 2 * (v / SIDE >= SIDE / 2);
}

/* A 4-node path 0-1-2-3, node weights 1, 2, 3, 4 and edge weights 1, 2, 3. */
static void test_cost_by_hand(void) {
  static const int64_t xadj[] = {0, 1, 3, 5, 6};
  static const int32_t adj[] = {1, 0, 2, 1, 3, 2};
  static const double w[] = {1, 2, 3, 4}, c[] = {1, 1, 2, 2, 3, 3};
  const hr_graph g = {4, xadj, adj, w, c};
  /* {0,1 | 2,3}: W = 3, 7; C = 2, 2 (the 1-2 edge); cut 2; imbalance 7 / 5 */
  const int32_t halves[] = {0, 0, 1, 1};
  /* {0,2 | 1,3}: W = 4, 6; every edge cut, C = 6, 6; cut 6; imbalance 6 / 5 */
  const int32_t alternate[] = {0, 1, 0, 1};
  const struct {
    const int32_t *part;
    double alpha, z, cut, imbalance;
  } cases[] = {
      {halves, 0.0, 7.0, 2.0, 1.4},    {halves, 0.5, 4.5, 2.0, 1.4},
      {halves, 1.0, 2.0, 2.0, 1.4},    {alternate, 0.0, 6.0, 6.0, 1.2},
      {alternate, 0.5, 6.0, 6.0, 1.2}, {alternate, 1.0, 6.0, 6.0, 1.2},
  };
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    double cut = 0.0, imbalance = 0.0;
    const double z = hr_partition_cost(&g, cases[i].part, 2, cases[i].alpha, &cut, &imbalance);
    CHECK(fabs(z - cases[i].z) < 1e-12, "case %zu: Z %g want %g", i, z, cases[i].z);
    CHECK(fabs(cut - cases[i].cut) < 1e-12, "case %zu: cut %g want %g", i, cut, cases[i].cut);
    CHECK(fabs(imbalance - cases[i].imbalance) < 1e-12, "case %zu: imbalance %g want %g", i,
          imbalance, cases[i].imbalance);
  }
  CHECK(hr_partition_cost(&g, halves, 2, 0.5, NULL, NULL) == 4.5, "NULL outputs");
  const int32_t outside[] = {0, 0, 2, 1};
  CHECK(hr_partition_cost(&g, outside, 2, 0.5, NULL, NULL) < 0.0, "part 2 of 2 accepted");
  CHECK(hr_partition_cost(&g, halves, 0, 0.5, NULL, NULL) < 0.0, "0 parts accepted");
}

/* Every part non-empty, part weights within 10% of the mean, cut at most twice the optimum and
 * Z within 12% of the quadrants'. Measured from the stripes over 1000 seeds, the worst were
 * imbalance 1.059, cut 118 and Z 157.5 (1.094 of the optimum); seeds 1 and 2 give 149.5/85 and
 * 149.0/82. */
static void check_good(const test_graph *t, const int32_t *part, const char *what) {
  int count[PARTS] = {0};
  for (int v = 0; v < NODES; v++) count[part[v]]++;
  for (int p = 0; p < PARTS; p++) CHECK(count[p] > 0, "%s: part %d empty", what, p);
  double cut, imbalance;
  const double z = hr_partition_cost(&t->g, part, PARTS, ALPHA, &cut, &imbalance);
  printf("  %-28s Z %.1f cut %.0f imbalance %.3f\n", what, z, cut, imbalance);
  CHECK(imbalance <= 1.10, "%s: imbalance %.3f", what, imbalance);
  CHECK(cut <= 2.0 * QUADRANT_CUT, "%s: cut %.0f", what, cut);
  CHECK(z <= 1.12 * QUADRANT_Z, "%s: Z %.1f", what, z);
}

static void test_grid_from_stripes(test_graph *t) {
  static int32_t part[NODES], again[NODES];
  stripes(part);
  double cut0, imb0;
  const double z0 = hr_partition_cost(&t->g, part, PARTS, ALPHA, &cut0, &imb0);
  printf("  %-28s Z %.1f cut %.0f imbalance %.3f\n", "stripes", z0, cut0, imb0);
  CHECK(z0 == 384.0 && cut0 == 992.0, "stripes: Z %g cut %g", z0, cut0);
  const clock_t t0 = clock();
  CHECK(hr_partition_anneal(&t->g, PARTS, ALPHA, 1, part) == 1, "anneal failed");
  printf("  anneal of %d nodes: %.3f s\n", NODES, (double)(clock() - t0) / CLOCKS_PER_SEC);
  check_good(t, part, "annealed, seed 1");
  const double z1 = hr_partition_cost(&t->g, part, PARTS, ALPHA, NULL, NULL);
  CHECK(z1 <= 0.40 * z0, "Z %.1f not below 0.40 of the start's %.1f", z1, z0); /* 0.389 */

  stripes(again);
  CHECK(hr_partition_anneal(&t->g, PARTS, ALPHA, 1, again) == 1, "anneal failed");
  CHECK(memcmp(part, again, sizeof part) == 0, "seed 1 twice: different partitions");
  const uint64_t others[] = {2, 0xdeadbeefcafeull};
  for (int i = 0; i < 2; i++) {
    char what[64];
    snprintf(what, sizeof what, "annealed, seed %llu", (unsigned long long)others[i]);
    stripes(again);
    CHECK(hr_partition_anneal(&t->g, PARTS, ALPHA, others[i], again) == 1, "anneal failed");
    check_good(t, again, what);
  }
}

static void test_grid_from_optimum(test_graph *t) {
  static int32_t part[NODES];
  quadrants(part);
  const double z0 = hr_partition_cost(&t->g, part, PARTS, ALPHA, NULL, NULL);
  CHECK(z0 == QUADRANT_Z, "quadrants: Z %g", z0);
  CHECK(hr_partition_anneal(&t->g, PARTS, ALPHA, 1, part) == 1, "anneal failed");
  const double z1 = hr_partition_cost(&t->g, part, PARTS, ALPHA, NULL, NULL);
  printf("  %-28s Z %.1f -> %.1f\n", "from the quadrants", z0, z1);
  CHECK(z1 <= z0, "quadrants got worse: Z %g -> %g", z0, z1);
}

/* Random weights on the grid's nodes and edges, a greedy start, several alphas and seeds: the
 * result is never worse in Z than the start. */
static void test_never_worse(test_graph *t) {
  static int32_t part[NODES];
  for (int v = 0; v < NODES; v++) t->w[v] = rnd_in(0.0, 10.0);
  for (int v = 0; v < NODES; v++) /* the same weight in both directions */
    for (int64_t k = t->xadj[v]; k < t->xadj[v + 1]; k++)
      if (t->adj[k] > v) {
        const double c = rnd_in(0.0, 5.0);
        t->c[k] = c;
        for (int64_t j = t->xadj[t->adj[k]]; j < t->xadj[t->adj[k] + 1]; j++)
          if (t->adj[j] == v) t->c[j] = c;
      }
  const double alphas[] = {0.0, 0.3, 0.9};
  for (int a = 0; a < 3; a++)
    for (uint64_t seed = 1; seed <= 3; seed++) {
      CHECK(hr_partition_greedy(t->w, NODES, 7, part) == 1, "greedy failed");
      const double z0 = hr_partition_cost(&t->g, part, 7, alphas[a], NULL, NULL);
      CHECK(hr_partition_anneal(&t->g, 7, alphas[a], seed, part) == 1, "anneal failed");
      const double z1 = hr_partition_cost(&t->g, part, 7, alphas[a], NULL, NULL);
      CHECK(z1 <= z0, "alpha %g seed %llu: Z %g -> %g", alphas[a], (unsigned long long)seed,
            z0, z1);
    }
}

static void test_bad_input(test_graph *t) {
  static int32_t part[NODES], kept[NODES];
  quadrants(part);
  memcpy(kept, part, sizeof part);
  CHECK(hr_partition_anneal(&t->g, 0, ALPHA, 1, part) == 0, "0 parts accepted");
  part[5] = PARTS;
  CHECK(hr_partition_anneal(&t->g, PARTS, ALPHA, 1, part) == 0, "part %d accepted", PARTS);
  part[5] = -1;
  CHECK(hr_partition_anneal(&t->g, PARTS, ALPHA, 1, part) == 0, "part -1 accepted");
  part[5] = kept[5];
  CHECK(memcmp(part, kept, sizeof part) == 0, "rejected input changed the partition");
  hr_graph negative = t->g;
  negative.n = -1;
  CHECK(hr_partition_anneal(&negative, PARTS, ALPHA, 1, part) == 0, "n = -1 accepted");
  hr_graph empty = t->g;
  empty.n = 0;
  CHECK(hr_partition_anneal(&empty, PARTS, ALPHA, 1, part) == 1, "n = 0 refused");
}

/* A random graph with planted groups: 4 groups of 64 nodes (weight 1), an edge inside a group
 * with probability 0.3 and between groups with 0.01 (weight 1). From a random start, annealing
 * (and its long variant) must find the groups: every group mostly in one part of its own, and Z
 * within 2% of the planted partition's. */
#define PL_GROUPS 4
#define PL_SIZE 64
#define PL_N (PL_GROUPS * PL_SIZE)
static void test_planted(void) {
  static int64_t xadj[PL_N + 1];
  static int32_t adj[PL_N * PL_N], part[PL_N], planted[PL_N];
  static double w[PL_N], c[PL_N * PL_N];
  static uint8_t edge[PL_N][PL_N];
  for (int u = 0; u < PL_N; u++)
    for (int v = u + 1; v < PL_N; v++)
      edge[u][v] = edge[v][u] = rnd_in(0.0, 1.0) < (u / PL_SIZE == v / PL_SIZE ? 0.3 : 0.01);
  int64_t e = 0;
  for (int u = 0; u < PL_N; u++) {
    xadj[u] = e;
    w[u] = 1.0;
    planted[u] = u / PL_SIZE;
    for (int v = 0; v < PL_N; v++)
      if (edge[u][v]) adj[e] = v, c[e++] = 1.0;
  }
  xadj[PL_N] = e;
  const hr_graph g = {PL_N, xadj, adj, w, c};
  const double zp = hr_partition_cost(&g, planted, PL_GROUPS, ALPHA, NULL, NULL);
  for (int run = 0; run < 2; run++) {
    for (int v = 0; v < PL_N; v++) part[v] = (int32_t)(rnd_in(0.0, PL_GROUPS - 1e-9));
    const int ok = run == 0 ? hr_partition_anneal(&g, PL_GROUPS, ALPHA, 5, part)
                            : hr_partition_anneal_effort(&g, PL_GROUPS, ALPHA, 5, 8.0, part);
    CHECK(ok == 1, "anneal failed");
    const double z = hr_partition_cost(&g, part, PL_GROUPS, ALPHA, NULL, NULL);
    CHECK(z <= 1.02 * zp, "%s: Z %g against the planted %g", run ? "long" : "normal", z, zp);
    /* each group's majority part, distinct for the groups, holding >= 90% of it */
    int seen[PL_GROUPS] = {0};
    for (int grp = 0; grp < PL_GROUPS; grp++) {
      int cnt[PL_GROUPS] = {0}, best = 0;
      for (int v = grp * PL_SIZE; v < (grp + 1) * PL_SIZE; v++) cnt[part[v]]++;
      for (int p = 1; p < PL_GROUPS; p++) best = cnt[p] > cnt[best] ? p : best;
      CHECK(cnt[best] >= 0.9 * PL_SIZE, "group %d: %d of %d in one part", grp, cnt[best],
            PL_SIZE);
      CHECK(!seen[best], "two groups share part %d", best);
      seen[best] = 1;
    }
  }
}

/* Z kept incrementally by the annealer equals Z recomputed from scratch after 200,000 warm
 * proposals (moves and swaps) on the grid with random weights, for several part counts. */
static void test_incremental(test_graph *t) {
  static int32_t part[NODES];
  for (int parts = 2; parts <= 64; parts *= 4) {
    for (int v = 0; v < NODES; v++) part[v] = v % parts;
    const double d = hr_partition_anneal_drift(&t->g, parts, 0.3, 9, 200000, part);
    CHECK(d >= 0 && d < 1e-9, "%d parts: incremental Z off by %g (relative)", parts, d);
  }
}

/* Clusters of the grid inside slanted bands (which 16-node clusters grown in index order would
 * cross), bound 16 nodes; then Z of random partitions of the clusters on the contracted graph
 * against Z of their projections on the grid. */
static void test_cluster_contract(test_graph *t) {
  static int32_t quad[NODES], cl[NODES], part[NODES];
  for (int v = 0; v < NODES; v++) quad[v] = (v % SIDE + 2 * (v / SIDE)) / 7 % 3;
  const int nc = hr_partition_cluster(&t->g, quad, 16.0, NODES, cl);
  CHECK(nc >= NODES / 16 && nc <= NODES, "cluster count %d", nc);
  if (nc < 1 || nc > NODES) return;
  static double weight[NODES];
  static int32_t quad_of[NODES];
  memset(weight, 0, sizeof weight);
  for (int a = 0; a < nc; a++) quad_of[a] = -1;
  int bad = 0;
  for (int v = 0; v < NODES; v++) {
    if (cl[v] < 0 || cl[v] >= nc) {
      bad++;
      continue;
    }
    weight[cl[v]] += t->w[v];
    if (quad_of[cl[v]] >= 0 && quad_of[cl[v]] != quad[v]) bad++;
    quad_of[cl[v]] = quad[v];
  }
  double wmax = 0;
  for (int a = 0; a < nc; a++) wmax = weight[a] > wmax ? weight[a] : wmax;
  CHECK(bad == 0, "%d nodes in a cluster across bands (or out of range)", bad);
  CHECK(wmax <= 16.0 + 1e-9, "a cluster weighs %g, above the bound 16", wmax);
  int64_t *xadj;
  int32_t *adj;
  double *w, *c;
  CHECK(hr_partition_contract(&t->g, cl, nc, &xadj, &adj, &w, &c), "contraction failed");
  const hr_graph cg = {nc, xadj, adj, w, c};
  double wsum = 0, csum = 0, cut_grid = 0;
  for (int a = 0; a < nc; a++) wsum += w[a];
  for (int64_t k = 0; k < xadj[nc]; k++) csum += c[k];
  for (int v = 0; v < NODES; v++)
    for (int64_t k = t->xadj[v]; k < t->xadj[v + 1]; k++) cut_grid += cl[t->adj[k]] != cl[v];
  CHECK(fabs(wsum - NODES) < 1e-9, "contracted weight %g, want %d", wsum, NODES);
  CHECK(fabs(csum - cut_grid) < 1e-9, "contracted edges %g, want %g", csum, cut_grid);
  static int32_t cpart[NODES];
  for (int trial = 0; trial < 5; trial++) {
    const int parts = 2 + trial * 3;
    for (int a = 0; a < nc; a++) cpart[a] = rnd_int(parts);
    for (int v = 0; v < NODES; v++) part[v] = cpart[cl[v]];
    const double zc = hr_partition_cost(&cg, cpart, parts, 0.3, NULL, NULL);
    const double zg = hr_partition_cost(&t->g, part, parts, 0.3, NULL, NULL);
    CHECK(fabs(zc - zg) <= 1e-12 * zg, "%d parts: Z %g on the clusters, %g on the grid", parts,
          zc, zg);
  }
  free(xadj), free(adj), free(w), free(c);
  CHECK(hr_partition_cluster(&t->g, NULL, 16.0, 0, cl) == -1, "cap 0 accepted");
  cl[5] = nc; /* out of range */
  CHECK(!hr_partition_contract(&t->g, cl, nc, &xadj, &adj, &w, &c) && !xadj,
        "a cluster id out of range accepted");
}

int main(void) {
  static test_graph t;
  test_planted();
  make_grid(&t);
  test_cost_by_hand();
  test_grid_from_stripes(&t);
  test_grid_from_optimum(&t);
  test_bad_input(&t);
  test_never_worse(&t); /* it reweights the grid */
  test_incremental(&t);
  make_grid(&t);
  test_cluster_contract(&t);
  return t_done("test_partition_anneal");
}
