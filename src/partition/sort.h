/* sort.h: what the partitioners share inside src/partition (not part of partition.h's
 * interface). */
#ifndef HR_PARTITION_SORT_H
#define HR_PARTITION_SORT_H

#include <stdint.h>

/* Sorts the n point indices idx[] by their coordinate (xyz: 3 a point) along the longest side of
 * their bounding box, ties by index: the step of recursive bisection (orb.c) and of the halving
 * of roots (treecut.c). Not reentrant (qsort without a context). */
void hr_partition_sort_longest(const double *xyz, int32_t *idx, int32_t n);

#endif
