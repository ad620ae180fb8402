/* orb.c: orthogonal recursive bisection (partition.h). Each step splits a set of points across
 * the longest side of its bounding box at the weight that gives each half its share of the
 * parts (k1 = nparts / 2 of them to the lower side), and recurses. Ties in a coordinate are
 * broken by index, so the result is deterministic. O(n log n log nparts). */
#include "partition/partition.h"
#include "partition/sort.h"

#include <stdlib.h>

static const double *g_xyz; /* qsort has no context argument in C11 */
static int g_axis;

static int cmp_axis(const void *a, const void *b) {
  const int32_t i = *(const int32_t *)a, j = *(const int32_t *)b;
  const double x = g_xyz[3 * i + g_axis], y = g_xyz[3 * j + g_axis];
  if (x != y) return x < y ? -1 : 1;
  return (i > j) - (i < j);
}

void hr_partition_sort_longest(const double *xyz, int32_t *idx, int32_t n) {
  if (n < 2) return;
  double lo[3], hi[3];
  for (int k = 0; k < 3; k++) lo[k] = hi[k] = xyz[3 * idx[0] + k];
  for (int32_t i = 1; i < n; i++)
    for (int k = 0; k < 3; k++) {
      const double v = xyz[3 * idx[i] + k];
      lo[k] = v < lo[k] ? v : lo[k];
      hi[k] = v > hi[k] ? v : hi[k];
    }
  int axis = 0;
  for (int k = 1; k < 3; k++) axis = hi[k] - lo[k] > hi[axis] - lo[axis] ? k : axis;
  g_xyz = xyz, g_axis = axis;
  qsort(idx, (size_t)n, sizeof *idx, cmp_axis);
}

static void bisect(const double *xyz, const double *w, int32_t *idx, int n, int first, int np,
                   int32_t *part) {
  if (np == 1 || n == 0) {
    for (int i = 0; i < n; i++) part[idx[i]] = first;
    return;
  }
  double total = 0;
  for (int i = 0; i < n; i++) total += w[idx[i]];
  hr_partition_sort_longest(xyz, idx, n);
  const int k1 = np / 2;
  const double want = total * k1 / np;
  /* the lower side takes points while its weight stays below its share (at least one point
   * each side when there are two or more) */
  int cut = 0;
  double acc = 0;
  while (cut < n && acc + 0.5 * w[idx[cut]] <= want) acc += w[idx[cut++]];
  if (cut == 0 && n > 1) cut = 1;
  if (cut == n && n > 1) cut = n - 1;
  bisect(xyz, w, idx, cut, first, k1, part);
  bisect(xyz, w, idx + cut, n - cut, first + k1, np - k1, part);
}

int hr_partition_orb(const double *xyz, const double *w, int n, int nparts, int32_t *part) {
  if (n < 0 || nparts < 1) return 0;
  int32_t *idx = malloc((size_t)(n > 0 ? n : 1) * sizeof *idx);
  if (!idx) return 0;
  for (int i = 0; i < n; i++) idx[i] = i;
  bisect(xyz, w, idx, n, 0, nparts, part);
  free(idx);
  return 1;
}
