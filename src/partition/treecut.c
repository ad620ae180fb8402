/* treecut.c: partitions and clusterings of a forest (see partition.h): the order of a forest
 * and two uses of it, pieces of a bound's weight cut bottom-up, and runs of equal weight in
 * preorder. For the graphs of clustered runs, whose tree (clusters over surfaces over
 * elements) spans the scene. */
#include "partition.h"

#include <stdlib.h>

/* The forest's nodes in preorder, roots in index order and each node's children in index
 * order, into 'order' (n). 0 on bad input (a parent out of range or a cycle) or out of
 * memory. */
static int preorder(const int32_t *parent, int32_t n, int32_t *order) {
  int32_t *head = malloc((size_t)(n + 1) * sizeof *head);
  int32_t *next = malloc((size_t)(n + 1) * sizeof *next);
  int32_t *stack = malloc((size_t)(n + 1) * sizeof *stack);
  int ok = head && next && stack;
  for (int32_t v = 0; ok && v < n; v++) {
    head[v] = -1;
    ok = parent[v] >= -1 && parent[v] < n && parent[v] != v;
  }
  for (int32_t v = n - 1; ok && v >= 0; v--) /* lists in increasing index order */
    if (parent[v] >= 0) next[v] = head[parent[v]], head[parent[v]] = v;
  int32_t m = 0;
  for (int32_t r = 0; ok && r < n; r++) {
    if (parent[r] >= 0) continue;
    int32_t sp = 0;
    stack[sp++] = r;
    while (sp > 0) {
      const int32_t v = stack[--sp];
      order[m++] = v;
      int32_t k = 0; /* the children pushed so that the first comes out first */
      for (int32_t c = head[v]; c >= 0; c = next[c]) k++;
      sp += k;
      int32_t j = sp - 1;
      for (int32_t c = head[v]; c >= 0; c = next[c]) stack[j--] = c;
    }
  }
  ok = ok && m == n; /* a node left out hangs on a cycle */
  free(head), free(next), free(stack);
  return ok;
}

int hr_partition_tree_cut(const int32_t *parent, const double *w, int32_t n,
                          const int32_t *within, double bound, int32_t *cluster) {
  if (!parent || !w || !cluster || n < 0) return -1;
  int32_t *order = malloc((size_t)(n + 1) * sizeof *order);
  double *acc = malloc((size_t)(n + 1) * sizeof *acc);
  int nc = -1;
  if (order && acc && preorder(parent, n, order)) {
    /* bottom-up (reverse preorder: children before parents): what hangs below v uncut */
    for (int32_t v = 0; v < n; v++) acc[v] = w[v];
    for (int32_t k = n - 1; k >= 0; k--) {
      const int32_t v = order[k], p = parent[v];
      const int head = p < 0 || (within && within[p] != within[v]) || !(acc[v] < bound);
      cluster[v] = head ? -2 : -1; /* -2: heads a piece */
      if (!head) acc[p] += acc[v];
    }
    /* top-down: a head starts a piece, the rest join their parent's */
    nc = 0;
    for (int32_t k = 0; k < n; k++) {
      const int32_t v = order[k];
      cluster[v] = cluster[v] == -2 ? nc++ : cluster[parent[v]];
    }
  }
  free(order), free(acc);
  return nc;
}

int hr_partition_preorder(const int32_t *parent, const double *w, int32_t n, int nparts,
                          int32_t *part) {
  if (!parent || !w || !part || n < 0 || nparts < 1) return 0;
  int32_t *order = malloc((size_t)(n + 1) * sizeof *order);
  if (!order || !preorder(parent, n, order)) return free(order), 0;
  double total = 0, acc = 0;
  for (int32_t v = 0; v < n; v++) total += w[v];
  for (int32_t k = 0; k < n; k++) {
    const int32_t v = order[k];
    /* the part where the node's middle falls */
    const int p = total > 0 ? (int)((acc + 0.5 * w[v]) / total * nparts) : 0;
    part[v] = p < nparts ? p : nparts - 1;
    acc += w[v];
  }
  free(order);
  return 1;
}
