/* partition.h: graph and weight partitioning, pure code (no radiosity types, no MPI). Issue 11
 * adds the paper's annealing on eq. (5), METIS and spatial bisection behind the same kind of
 * interface: weights and edges in, a part per node out, caller-owned. */
#ifndef HR_PARTITION_H
#define HR_PARTITION_H

#include <stdint.h>

/* Greedy largest-first: nodes in decreasing weight (ties by index), each to the part with the
 * least weight so far (ties to the lowest part). part[i] in [0, nparts). 0 when out of memory. */
int hr_partition_greedy(const double *weight, int n, int nparts, int32_t *part);

#endif
