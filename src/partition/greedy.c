/* greedy.c: largest-first greedy partition of weighted nodes (partition.h). Used for the
 * distributed solver's `--balance area` (surfaces weighted by area). O(n log n + n P). */
#include "partition/partition.h"

#include <stdlib.h>

static const double *g_w; /* qsort has no context argument in C11 */

static int cmp_desc(const void *a, const void *b) {
  const int32_t i = *(const int32_t *)a, j = *(const int32_t *)b;
  if (g_w[i] != g_w[j]) return g_w[i] > g_w[j] ? -1 : 1;
  return (i > j) - (i < j);
}

int hr_partition_greedy(const double *weight, int n, int nparts, int32_t *part) {
  int32_t *ord = malloc((size_t)(n > 0 ? n : 1) * sizeof *ord);
  double *load = calloc((size_t)nparts, sizeof *load);
  if (!ord || !load) {
    free(ord);
    free(load);
    return 0;
  }
  for (int i = 0; i < n; i++) ord[i] = i;
  g_w = weight;
  qsort(ord, (size_t)n, sizeof *ord, cmp_desc);
  for (int i = 0; i < n; i++) {
    int best = 0;
    for (int p = 1; p < nparts; p++) best = load[p] < load[best] ? p : best;
    part[ord[i]] = best;
    load[best] += weight[ord[i]];
  }
  free(ord);
  free(load);
  return 1;
}
