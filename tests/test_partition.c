/* test_partition: the pure partitioners of src/partition against hand-computed and measured
 * numbers: greedy on known weights, ORB on grids (quadrants, weighted shares), METIS on a grid
 * graph (cut near the optimum, balance, determinism), the tree cut and preorder runs of
 * clustered runs' graphs (hand-computed pieces, connectivity, weight bounds, parts kept), the
 * cut with neighbouring roots joined (a grid of roots into 2 x 2 blocks), and bad input. */
#include "partition/partition.h"
#include "xorshift.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int fails;
#define CHECK(c, ...)                                                                              \
  do {                                                                                             \
    if (!(c)) {                                                                                    \
      fails++;                                                                                     \
      printf("FAIL %s:%d: ", __FILE__, __LINE__);                                                  \
      printf(__VA_ARGS__);                                                                         \
      printf("\n");                                                                                \
    }                                                                                              \
  } while (0)

/* An s x s grid graph, 4 neighbours, unit node and edge weights (caller frees the arrays). */
typedef struct grid {
  hr_graph g;
  int64_t *xadj;
  int32_t *adj;
  double *w, *c, *xyz;
} grid;

static grid make_grid(int s) {
  grid G;
  const int n = s * s;
  G.xadj = malloc((size_t)(n + 1) * sizeof *G.xadj);
  G.adj = malloc((size_t)(4 * n) * sizeof *G.adj);
  G.c = malloc((size_t)(4 * n) * sizeof *G.c);
  G.w = malloc((size_t)n * sizeof *G.w);
  G.xyz = malloc((size_t)(3 * n) * sizeof *G.xyz);
  int64_t k = 0;
  for (int y = 0; y < s; y++)
    for (int x = 0; x < s; x++) {
      const int i = y * s + x;
      G.xadj[i] = k;
      const int nb[4][2] = {{x - 1, y}, {x + 1, y}, {x, y - 1}, {x, y + 1}};
      for (int d = 0; d < 4; d++)
        if (nb[d][0] >= 0 && nb[d][0] < s && nb[d][1] >= 0 && nb[d][1] < s)
          G.c[k] = 1, G.adj[k++] = nb[d][1] * s + nb[d][0];
      G.w[i] = 1;
      G.xyz[3 * i] = x + 0.5, G.xyz[3 * i + 1] = y + 0.5, G.xyz[3 * i + 2] = 0;
    }
  G.xadj[n] = k;
  G.g = (hr_graph){n, G.xadj, G.adj, G.w, G.c};
  return G;
}

static void free_grid(grid *G) {
  free(G->xadj), free(G->adj), free(G->c), free(G->w), free(G->xyz);
}

/* Cut edges (each once) and max part weight over mean, computed here independently. */
static void measure(const hr_graph *g, const int32_t *part, int np, double *cut, double *imb) {
  double *W = calloc((size_t)np, sizeof *W), tot = 0;
  *cut = 0;
  for (int i = 0; i < g->n; i++) {
    W[part[i]] += g->w[i], tot += g->w[i];
    for (int64_t k = g->xadj[i]; k < g->xadj[i + 1]; k++)
      if (part[g->adj[k]] != part[i] && g->adj[k] > i) *cut += g->c[k];
  }
  double mx = 0;
  for (int p = 0; p < np; p++) mx = W[p] > mx ? W[p] : mx;
  *imb = mx / (tot / np);
  free(W);
}

static void test_greedy(void) {
  const double w[5] = {5, 4, 3, 3, 3};
  int32_t part[5];
  CHECK(hr_partition_greedy(w, 5, 2, part), "greedy failed");
  /* 5 -> 0; 4 -> 1; 3 (node 2) -> 1 (4 < 5); 3 (node 3) -> 0 (5 < 7); 3 (node 4) -> 1 (7 < 8) */
  const int32_t want[5] = {0, 1, 1, 0, 1};
  CHECK(!memcmp(part, want, sizeof want), "greedy parts %d %d %d %d %d", part[0], part[1],
        part[2], part[3], part[4]);
}

static void test_orb(void) {
  grid G = make_grid(4);
  int32_t part[16];
  CHECK(hr_partition_orb(G.xyz, G.w, 16, 4, part), "orb failed");
  /* 4 parts of a 4 x 4 grid: the 2 x 2 quadrants */
  for (int i = 0; i < 16; i++) {
    const int q = (i % 4) / 2 + 2 * ((i / 4) / 2);
    for (int j = 0; j < 16; j++) {
      const int qj = (j % 4) / 2 + 2 * ((j / 4) / 2);
      CHECK((q == qj) == (part[i] == part[j]), "orb: nodes %d and %d", i, j);
    }
  }
  free_grid(&G);
  /* 3 parts of 300 points on a line with weights 1..300: shares within one point's weight */
  double xyz[900], w[300], W[3] = {0, 0, 0}, tot = 0;
  int32_t p3[300];
  for (int i = 0; i < 300; i++)
    xyz[3 * i] = i, xyz[3 * i + 1] = xyz[3 * i + 2] = 0, w[i] = i + 1, tot += w[i];
  CHECK(hr_partition_orb(xyz, w, 300, 3, p3), "orb 3 failed");
  for (int i = 0; i < 300; i++) W[p3[i]] += w[i];
  for (int p = 0; p < 3; p++)
    CHECK(W[p] > tot / 3 - 300 && W[p] < tot / 3 + 300, "orb part %d weight %g of %g", p, W[p],
          tot);
  for (int i = 1; i < 300; i++) CHECK(p3[i] >= p3[i - 1], "orb 3: not contiguous at %d", i);
}

static void test_metis(void) {
  grid G = make_grid(32);
  int32_t *a = malloc(1024 * sizeof *a), *b = malloc(1024 * sizeof *b);
  CHECK(hr_partition_metis(&G.g, 4, a), "metis failed");
  double cut, imb;
  measure(&G.g, a, 4, &cut, &imb);
  /* the optimum (quadrants) cuts 64 edges; measured: METIS 5.1 cuts 69 */
  printf("metis 32x32 grid, 4 parts: cut %g (optimum 64), imbalance %.3f\n", cut, imb);
  CHECK(cut <= 80, "metis cut %g", cut);
  CHECK(imb <= 1.031, "metis imbalance %g", imb);
  CHECK(hr_partition_metis(&G.g, 4, b) && !memcmp(a, b, 1024 * sizeof *a), "metis not repeatable");
  CHECK(hr_partition_metis(&G.g, 1, a), "metis 1 part");
  for (int i = 0; i < 1024; i++) CHECK(a[i] == 0, "metis 1 part: node %d in %d", i, a[i]);
  /* 7 parts: all used, balanced */
  CHECK(hr_partition_metis(&G.g, 7, a), "metis 7 parts");
  measure(&G.g, a, 7, &cut, &imb);
  printf("metis 32x32 grid, 7 parts: cut %g, imbalance %.3f\n", cut, imb);
  CHECK(imb <= 1.04, "metis 7 imbalance %g", imb);
  CHECK(!hr_partition_metis(&G.g, 0, a), "metis accepted 0 parts");
  free(a), free(b);
  free_grid(&G);
}

/* Piece checks of hr_partition_tree_cut: every piece connected (one head, whose parent is
 * outside it or none; everyone else's parent inside), inside one part of 'within', and every
 * piece not closed at a root or a part's edge weighing at least 'bound'. Returns the count of
 * heads closed by weight. */
static int check_pieces(const int32_t *par, const double *w, int n, const int32_t *within,
                        double bound, const int32_t *cl, int nc, const char *what) {
  int *heads = calloc((size_t)nc + 1, sizeof *heads), by_weight = 0;
  double *pw = calloc((size_t)nc + 1, sizeof *pw);
  for (int v = 0; v < n; v++) {
    CHECK(cl[v] >= 0 && cl[v] < nc, "%s: node %d in piece %d of %d", what, v, cl[v], nc);
    if (cl[v] < 0 || cl[v] >= nc) continue;
    pw[cl[v]] += w[v];
    if (par[v] < 0 || cl[par[v]] != cl[v]) heads[cl[v]]++;
    if (within && par[v] >= 0 && within[par[v]] != within[v])
      CHECK(cl[par[v]] != cl[v], "%s: piece %d crosses parts", what, cl[v]);
  }
  for (int c = 0; c < nc; c++) CHECK(heads[c] == 1, "%s: piece %d has %d heads", what, c, heads[c]);
  for (int v = 0; v < n; v++) {
    if (cl[v] < 0 || cl[v] >= nc || !(par[v] >= 0 && cl[par[v]] != cl[v])) continue;
    if (within && within[par[v]] != within[v]) continue;
    CHECK(pw[cl[v]] >= bound, "%s: piece %d closed at %g < %g", what, cl[v], pw[cl[v]], bound);
    by_weight++;
  }
  free(heads), free(pw);
  return by_weight;
}

static void test_tree_cut(void) {
  /* a path 0 <- 1 <- 2 <- 3 <- 4, unit weights, bound 2: bottom up {3, 4} and {1, 2} close
   * by weight, {0} at the root; numbered in preorder */
  const int32_t path[5] = {-1, 0, 1, 2, 3}, want[5] = {0, 1, 1, 2, 2};
  const double one[5] = {1, 1, 1, 1, 1};
  int32_t cl[1023];
  CHECK(hr_partition_tree_cut(path, one, 5, NULL, 2, cl) == 3 && !memcmp(cl, want, sizeof want),
        "path: pieces %d %d %d %d %d", cl[0], cl[1], cl[2], cl[3], cl[4]);
  /* a complete binary tree of 1023 nodes, unit weights, bound 32: connected pieces of at
   * least 32 but the root's, so at most 1023 / 32 of them and the root's */
  int32_t par[1023], within[1023];
  double w[1023];
  for (int v = 0; v < 1023; v++) par[v] = v ? (v - 1) / 2 : -1, w[v] = 1;
  int nc = hr_partition_tree_cut(par, w, 1023, NULL, 32, cl);
  int full = check_pieces(par, w, 1023, NULL, 32, cl, nc, "binary tree");
  CHECK(nc >= 16 && nc <= 1023 / 32 + 1 && full == nc - 1, "binary tree: %d pieces, %d full",
        nc, full);
  /* the same tree in two parts by subtree (left and right of the root, root with the left),
   * and a forest with random parents and weights in 3 random parts */
  for (int v = 0; v < 1023; v++) {
    int u = v;
    while (u > 2) u = (u - 1) / 2;
    within[v] = u == 2;
  }
  nc = hr_partition_tree_cut(par, w, 1023, within, 32, cl);
  check_pieces(par, w, 1023, within, 32, cl, nc, "binary tree, two parts");
  CHECK(nc <= 1023 / 32 + 2, "binary tree, two parts: %d pieces", nc);
  rng_state = 7;
  for (int v = 0; v < 1023; v++) {
    par[v] = v < 5 ? -1 : rnd_int(v);
    w[v] = rnd_in(0, 3);
    within[v] = rnd_int(3);
  }
  nc = hr_partition_tree_cut(par, w, 1023, within, 20, cl);
  check_pieces(par, w, 1023, within, 20, cl, nc, "random forest, 3 parts");
  nc = hr_partition_tree_cut(par, w, 1023, NULL, 20, cl);
  double tot = 0;
  for (int v = 0; v < 1023; v++) tot += w[v];
  full = check_pieces(par, w, 1023, NULL, 20, cl, nc, "random forest");
  CHECK(full <= tot / 20 && nc == full + 5, "random forest: %d pieces, %d full, total %g", nc,
        full, tot);
  /* bad input: a cycle, a parent out of range */
  const int32_t cyc[3] = {1, 0, -1}, far[3] = {-1, 7, 0};
  CHECK(hr_partition_tree_cut(cyc, one, 3, NULL, 2, cl) == -1, "a cycle was accepted");
  CHECK(hr_partition_tree_cut(far, one, 3, NULL, 2, cl) == -1, "a parent out of range");
}

static void test_tree_cut_near(void) {
  /* 256 lone roots on a 16 x 16 grid, unit weights, bound 4: the plain cut leaves a piece a
   * root; joined by halving, 64 pieces of 4, each a 2 x 2 block */
  int32_t par[1023], within[1023], cl[1023], nc;
  double w[1023], xyz[3 * 1023];
  for (int v = 0; v < 256; v++)
    par[v] = -1, w[v] = 1, xyz[3 * v] = v % 16, xyz[3 * v + 1] = v / 16, xyz[3 * v + 2] = 0;
  CHECK(hr_partition_tree_cut(par, w, 256, NULL, 4, cl) == 256, "grid: plain cut");
  nc = hr_partition_tree_cut_near(par, w, xyz, 256, NULL, 4, cl);
  CHECK(nc == 64, "grid: %d pieces, not 64", nc);
  int count[64] = {0};
  for (int v = 0; nc == 64 && v < 256; v++) {
    CHECK(cl[v] >= 0 && cl[v] < 64, "grid: root %d in piece %d", v, cl[v]);
    if (cl[v] < 0 || cl[v] >= 64) continue;
    count[cl[v]]++;
    for (int u = 0; u < v; u++) /* members of a piece at most a 2 x 2 block's diagonal apart */
      if (cl[u] == cl[v])
        CHECK(abs(u % 16 - v % 16) <= 1 && abs(u / 16 - v / 16) <= 1,
              "grid: %d and %d in piece %d", u, v, cl[v]);
  }
  for (int c = 0; nc == 64 && c < 64; c++)
    CHECK(count[c] == 4, "grid: piece %d of %d", c, count[c]);
  /* a random forest in 3 random parts: pieces stay in a part, and all but each part's last
   * weigh the bound; far fewer than the plain cut's, whose roots each make one */
  rng_state = 11;
  double tot = 0;
  for (int v = 0; v < 1023; v++) {
    par[v] = v < 300 ? -1 : rnd_int(v);
    w[v] = rnd_in(0, 3);
    within[v] = rnd_int(3);
    for (int k = 0; k < 3; k++) xyz[3 * v + k] = rnd_in(-1, 1);
    tot += w[v];
  }
  const int plain = hr_partition_tree_cut(par, w, 1023, within, 20, cl);
  nc = hr_partition_tree_cut_near(par, w, xyz, 1023, within, 20, cl);
  double pw[1023] = {0};
  int pin[1023];
  for (int c = 0; c < 1023; c++) pin[c] = -1;
  for (int v = 0; nc > 0 && v < 1023; v++) {
    CHECK(cl[v] >= 0 && cl[v] < nc, "forest: node %d in piece %d of %d", v, cl[v], nc);
    if (cl[v] < 0 || cl[v] >= nc) continue;
    CHECK(pin[cl[v]] < 0 || pin[cl[v]] == within[v], "forest: piece %d crosses parts", cl[v]);
    pin[cl[v]] = within[v], pw[cl[v]] += w[v];
  }
  int light = 0;
  for (int c = 0; c < nc; c++) light += pw[c] < 20;
  CHECK(nc > 0 && light <= 3 && nc <= tot / 20 + 3 && nc < plain / 4,
        "forest: %d pieces (plain cut %d), %d light, total %g", nc, plain, light, tot);
  /* bad input: a parent out of range, no centres */
  const int32_t far[3] = {-1, 7, 0};
  CHECK(hr_partition_tree_cut_near(far, w, xyz, 3, NULL, 2, cl) == -1, "a parent out of range");
  CHECK(hr_partition_tree_cut_near(par, w, NULL, 3, NULL, 2, cl) == -1, "no centres");
}

static void test_preorder(void) {
  /* the path in 2 parts: the middles 0.5 .. 4.5 of 5 split at 2.5 */
  const int32_t path[5] = {-1, 0, 1, 2, 3}, want[5] = {0, 0, 1, 1, 1};
  const double one[5] = {1, 1, 1, 1, 1};
  int32_t part[1023], par[1023];
  CHECK(hr_partition_preorder(path, one, 5, 2, part) && !memcmp(part, want, sizeof want),
        "path: parts %d %d %d %d %d", part[0], part[1], part[2], part[3], part[4]);
  /* the binary tree in 4 parts: nondecreasing along the preorder (a run each), within one
   * node of equal */
  double w[1023], W[4] = {0, 0, 0, 0};
  for (int v = 0; v < 1023; v++) par[v] = v ? (v - 1) / 2 : -1, w[v] = 1;
  CHECK(hr_partition_preorder(par, w, 1023, 4, part), "binary tree: failed");
  int32_t stack[64], sp = 0, last = 0;
  stack[sp++] = 0;
  while (sp > 0) { /* preorder, left child first */
    const int32_t v = stack[--sp];
    CHECK(part[v] >= last, "binary tree: part %d after %d in preorder at %d", part[v], last, v);
    last = part[v];
    W[part[v]] += w[v];
    if (2 * v + 2 < 1023) stack[sp++] = 2 * v + 2, stack[sp++] = 2 * v + 1;
  }
  for (int p = 0; p < 4; p++)
    CHECK(W[p] >= 254 && W[p] <= 257, "binary tree: part %d weighs %g", p, W[p]);
  CHECK(!hr_partition_preorder(path, one, 5, 0, part), "0 parts accepted");
}

int main(void) {
  test_greedy();
  test_orb();
  test_metis();
  test_tree_cut();
  test_tree_cut_near();
  test_preorder();
  if (fails) printf("%d failures\n", fails);
  else printf("test_partition: all passed\n");
  return fails != 0;
}
