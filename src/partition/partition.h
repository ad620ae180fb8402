/* partition.h: graph and weight partitioning, pure code (no radiosity types, no MPI): weights
 * and edges in, a part per node out, caller-owned arrays. The distributed solver's balancing
 * (paper 2.2.5, issue 11) chooses among these; every function is deterministic for a given
 * input (and seed). Functions return 1 on success, 0 when out of memory or given bad input. */
#ifndef HR_PARTITION_H
#define HR_PARTITION_H

#include <stdint.h>

/* An undirected graph in CSR form: the neighbours of node i are adj[xadj[i] .. xadj[i+1]),
 * each edge stored in both directions with the same weight c[k] (communication); w[i] is node
 * i's weight (work). No self-loops. */
typedef struct hr_graph {
  int n;
  const int64_t *xadj; /* n + 1 offsets */
  const int32_t *adj;
  const double *w;     /* n node weights, >= 0 */
  const double *c;     /* xadj[n] edge weights, >= 0 */
} hr_graph;

/* Greedy largest-first: nodes in decreasing weight (ties by index), each to the part with the
 * least weight so far (ties to the lowest part). part[i] in [0, nparts). */
int hr_partition_greedy(const double *weight, int n, int nparts, int32_t *part);

/* The paper's cost, eq. (5): Z = max over parts p of alpha C_p + (1 - alpha) W_p, with W_p the
 * weight of p's nodes and C_p the weight of the edges with one end in p and the other outside
 * (each cut edge counts for both its parts). Also, when not NULL: cut = the weight of all cut
 * edges (each once), and imbalance = max W_p / mean W_p. */
double hr_partition_cost(const hr_graph *g, const int32_t *part, int nparts, double alpha,
                         double *cut, double *imbalance);

/* METIS k-way (METIS_PartGraphKway, weights scaled to its integer types), minimising the cut
 * with parts of equal weight within 3%. */
int hr_partition_metis(const hr_graph *g, int nparts, int32_t *part);

/* Orthogonal recursive bisection of points xyz (n x 3) with weights w: the longest extent of
 * the bounding box is split at the weighted median, parts in proportion (nparts need not be a
 * power of two). */
int hr_partition_orb(const double *xyz, const double *w, int n, int nparts, int32_t *part);

/* The paper's clustering (2.2.5): from each node not yet in a cluster (in index order), grows a
 * cluster by adding the unclustered neighbour most strongly connected to it, until it weighs
 * 'bound' (when > 0) or holds 'cap' (>= 1) nodes or has no such neighbour left; with 'within'
 * (n values, or NULL) only across edges whose two ends have the same value there, so that
 * clusters stay inside the parts of a partition. cluster[v] in [0, count); returns the count,
 * -1 on bad input or out of memory. */
int hr_partition_cluster(const hr_graph *g, const int32_t *within, double bound, int64_t cap,
                         int32_t *cluster);

/* Clustering of a forest (parent[v]: v's parent, -1 for a root; n nodes, weights w): pieces
 * cut bottom-up, each a node with what hangs below it uncut, closed where that weighs 'bound'
 * or more, at a root, or where the parent is in another part of 'within' (n values, or NULL).
 * Every piece is connected, and all but the ones closed at a root or a part's edge weigh at
 * least 'bound', so there are at most total / bound of those (growth from seeds, as
 * hr_partition_cluster, strands pieces of a tree: 14,787 clusters where 1,024 were meant on
 * the conference room's graph at 64 parts). cluster[v] in [0, count), pieces numbered in
 * preorder (roots, then children, in index order); returns the count, -1 on bad input (a
 * parent out of range, a cycle) or out of memory. */
int hr_partition_tree_cut(const int32_t *parent, const double *w, int32_t n,
                          const int32_t *within, double bound, int32_t *cluster);

/* hr_partition_tree_cut with the roots joined where they are close: the roots of each part of
 * 'within' (nodes without a parent, or whose parent is in another part; all of them when
 * 'within' is NULL) first hang under a binary tree of weightless nodes made by halving them,
 * again and again, across the longest side of their centres' box (xyz: n x 3), so that light
 * trees next to each other (the whole surfaces of an unclustered scene, each its own tree) make
 * one piece rather than a piece each: museum's final graph at 64 parts had 4,302 pieces, one a
 * surface, where 1,024 were meant. Pieces are numbered as the cut numbers them, without the
 * ones that hold no node of the forest; returns the count, -1 as hr_partition_tree_cut. */
int hr_partition_tree_cut_near(const int32_t *parent, const double *w, const double *xyz,
                               int32_t n, const int32_t *within, double bound,
                               int32_t *cluster);

/* A forest's nodes in preorder (as hr_partition_tree_cut's) cut into nparts runs of equal
 * weight: node v goes to the part where the middle of its weight falls. A run of a preorder
 * is a union of subtrees and the path above them: where the tree is spatial (clusters over
 * surfaces), each part is compact and its tree splits into few pieces. */
int hr_partition_preorder(const int32_t *parent, const double *w, int32_t n, int nparts,
                          int32_t *part);

/* The graph of the clusters (cluster[v] in [0, nc)): a node per cluster weighing the sum of its
 * members, an edge between two clusters weighing the sum of their members' edges between them
 * (edges inside a cluster are left out). Z of a partition of the clusters equals Z of its
 * projection on g. The arrays (nc + 1 offsets, then the CSR) are malloc'd for the caller to
 * free; 0 on bad input or out of memory (and all four NULL). */
int hr_partition_contract(const hr_graph *g, const int32_t *cluster, int nc, int64_t **xadj,
                          int32_t **adj, double **w, double **c);

/* The distributed balancing (src/balance.c) clusters each rank's elements into this many
 * clusters over all ranks (at least HR_PARTITION_CLUSTERS_MIN a rank) before annealing:
 * measured with bench/partbench (BENCHMARKS.md, "Graph balancing, third pass"). */
#define HR_PARTITION_CLUSTERS 1024
#define HR_PARTITION_CLUSTERS_MIN 16

/* The parallel annealing (the solver's --balance anneal) runs one chain a rank from the same
 * start and keeps the best. The proposal budget of each of 'nchains' chains (the effort of
 * hr_partition_anneal_effort) is HR_PARTITION_CHAINS / nchains: the chains together make as
 * many proposals at any P. With few chains each searches longer (at 2-4 ranks a chain's time is
 * mostly its fixed passes over the graph, and effort 4 instead of 1 lowered the conference
 * room's Z by 2.5%); with many, each is shorter, as it must be, since a rank's share of the run
 * falls as 1 / P while a chain's work does not. Beyond HR_PARTITION_CHAINS ranks the solver
 * also joins neighbouring roots into pieces (hr_partition_tree_cut_near). Measured with
 * bench/partbench on floor, room, museum and the conference room: BENCHMARKS.md, "Graph
 * balancing, sixth pass". */
#define HR_PARTITION_CHAINS 16
double hr_partition_chain_effort(int nchains);

/* The paper's method: clustering (traverse maximum-weight edges from unvisited nodes until a
 * cluster reaches a size bound), simulated annealing of the clustered graph on Z with Metropolis
 * acceptance and a cooling schedule, then the same on the unclustered graph to refine. 'part'
 * holds a starting partition on entry (for example ORB's or greedy's) and the result on exit;
 * never worse in Z than the start. */
int hr_partition_anneal(const hr_graph *g, int nparts, double alpha, uint64_t seed,
                        int32_t *part);

/* The same with every proposal budget times 'effort' (> 0): the paper's "very cautious"
 * annealing is a long one (effort 16, say). */
int hr_partition_anneal_effort(const hr_graph *g, int nparts, double alpha, uint64_t seed,
                               double effort, int32_t *part);

/* Test of the annealer's bookkeeping: a Metropolis walk of 'moves' proposals (moves and swaps)
 * at a fixed, warm temperature from 'part' (left at the walk's end), then the relative
 * difference between the Z the walk kept incrementally and Z recomputed from scratch. -1 on
 * bad input or out of memory. */
double hr_partition_anneal_drift(const hr_graph *g, int nparts, double alpha, uint64_t seed,
                                 int64_t moves, int32_t *part);

#endif
