/* dist.h: what the solver needs from MPI, without mpi.h (only src/mpi/dist.c includes it).
 *
 * A NULL handle is one process: rank 0 of 1, every collective a no-op. All collectives must be
 * called by every rank in the same order; those that allocate agree on failure across ranks
 * (every rank gets the same status), so an out-of-memory on one rank cannot leave the others
 * waiting. The public start/finish/rank/size calls are declared in hrad.h. */
#ifndef HR_MPI_DIST_H
#define HR_MPI_DIST_H

#include "hrad.h"

#include <stdint.h>

void hr_dist_barrier(const hr_dist *d);
/* In-place reductions over all ranks of n values. */
void hr_dist_sum_f64(const hr_dist *d, double *v, int64_t n);
void hr_dist_max_f64(const hr_dist *d, double *v, int64_t n);
void hr_dist_sum_i64(const hr_dist *d, int64_t *v, int64_t n);
void hr_dist_max_i64(const hr_dist *d, int64_t *v, int64_t n);
/* Personalised exchange: sbytes[p] bytes of 'send' (consecutive, in rank order) go to rank p;
 * '*recv' (malloc'd, caller frees) gets what the ranks sent here, in rank order,
 * '*rbytes_total' bytes in all. Sparse: ranks that send nothing to each other exchange nothing
 * (NBX, dist.c). d must not be NULL. */
hr_status hr_dist_alltoall(const hr_dist *d, const void *send, const int64_t *sbytes,
                           void **recv, int64_t *rbytes_total);
/* The same, agreeing on a failure before it: 'failed' non-zero on any rank (which then sends
 * nothing, sbytes all 0) makes every rank return HR_ERR_REMOTE (the failing rank reports its
 * own error); a failed allocation here gives HR_ERR_NOMEM on every rank. */
hr_status hr_dist_alltoall_st(const hr_dist *d, const void *send, const int64_t *sbytes,
                              int failed, void **recv, int64_t *rbytes_total);
/* What this rank spent in the collectives above so far: calls, bytes sent, seconds. */
void hr_dist_counters(const hr_dist *d, int64_t *calls, int64_t *bytes, double *secs);
/* Rank 0 gets every rank's 'n' bytes of 'mine' in rank order in 'all' (n P bytes; others may
 * pass NULL). */
hr_status hr_dist_gather(const hr_dist *d, const void *mine, size_t n, void *all);

/* 'n' bytes of rank 0's (or rank 'root''s) 'buf' to every rank's 'buf'. d may be NULL. */
void hr_dist_bcast(const hr_dist *d, void *buf, size_t n);
void hr_dist_bcast_from(const hr_dist *d, int root, void *buf, size_t n);
/* The rank whose 'v' is smallest (ties: the lowest rank); 0 for NULL. */
int hr_dist_argmin(const hr_dist *d, double v);

/* Point-to-point messages for the asynchronous phases (docs/design.md, "Messages"): records
 * are put into one buffer per destination, which goes out as one MPI_Isend when it is full or
 * at hr_dist_mq_flush; hr_dist_mq_poll hands over one received batch without waiting. A queue
 * is local to one phase: the caller knows how many records it must receive (every phase that
 * uses one counts them), so no termination detection is needed; hr_dist_mq_close waits until
 * this rank's sends are received. d must not be NULL. */
typedef struct hr_dist_mq hr_dist_mq;
hr_status hr_dist_mq_open(const hr_dist *d, int tag, hr_dist_mq **q);
/* Room for 'n' bytes of a record to rank 'dest' (valid until the next call on q); NULL when out
 * of memory. */
void *hr_dist_mq_put(hr_dist_mq *q, int dest, size_t n);
void hr_dist_mq_flush(hr_dist_mq *q);
/* One received batch: 1 and '*buf' (owned by q until the next poll), '*n' bytes, '*src'; 0 when
 * nothing has arrived. With 'wait', blocks until something arrives. */
int hr_dist_mq_poll(hr_dist_mq *q, int wait, const void **buf, int64_t *n, int *src);
/* Flushes, waits for every send of q to complete, frees q; adds its counts to the handle's. */
void hr_dist_mq_close(hr_dist_mq **q);
/* Point-to-point batches and bytes this rank sent so far. */
void hr_dist_msg_counters(const hr_dist *d, int64_t *msgs, int64_t *bytes);

#endif
