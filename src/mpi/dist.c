/* dist.c: the solver's only contact with MPI (the one file that includes mpi.h). The solver
 * calls the few collectives of dist.h at fixed points of an iteration (docs/design.md,
 * "Distribution"); in one process the handle is NULL and every call is a no-op, so the
 * one-process path makes no MPI call at all.
 *
 * MPI is started only when this process was launched by an MPI launcher (its environment says
 * so): plain `hrad SCENE` never initialises MPI, which costs about 0.35 s and refuses to run as
 * root without extra settings. Counts above INT_MAX travel in chunks. */
#include "mpi/dist.h"

#include <mpi.h>
#include <limits.h>
#include <stdlib.h>
#include <string.h>

struct hr_dist {
  MPI_Comm comm;
  int rank, size;
  int own_init; /* MPI_Init was ours: finalize it */
  /* what this rank spent in MPI (hr_dist_counters): calls, bytes it sent (a reduction counts
   * its whole vector), seconds inside them, waiting for the slowest rank included */
  int64_t calls, bytes;
  double secs;
  int64_t msgs, msg_bytes; /* point-to-point batches and bytes sent (hr_dist_mq) */
};

/* Counts one collective that sent 'bytes' and started at 't0'. */
static void count(hr_dist *d, int64_t bytes, double t0) {
  d->calls++;
  d->bytes += bytes;
  d->secs += MPI_Wtime() - t0;
}

/* Elements per collective call: well below INT_MAX, in any MPI type used here. */
#define CHUNK (INT64_C(1) << 26)

/* Environment variables by which Open MPI, MPICH (Hydra) and PMIx launchers mark their
 * processes. */
static int launched_by_mpi(void) {
  static const char *const vars[] = {"OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_SIZE",
                                     "PMI_RANK", "MPI_LOCALNRANKS"};
  for (size_t i = 0; i < sizeof vars / sizeof vars[0]; i++)
    if (getenv(vars[i])) return 1;
  return 0;
}

hr_status hr_dist_start(int *argc, char ***argv, hr_dist **out, hr_err *err) {
  *out = NULL;
  if (!launched_by_mpi()) return HR_OK;
  int inited = 0, provided = 0;
  MPI_Initialized(&inited);
  if (!inited && MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &provided) != MPI_SUCCESS)
    return hr_err_set(err, HR_ERR_IO, "MPI_Init failed");
  hr_dist *d = calloc(1, sizeof *d);
  if (!d) {
    if (!inited) MPI_Finalize();
    return hr_err_set(err, HR_ERR_NOMEM, "out of memory");
  }
  d->own_init = !inited;
  MPI_Comm_dup(MPI_COMM_WORLD, &d->comm);
  MPI_Comm_rank(d->comm, &d->rank);
  MPI_Comm_size(d->comm, &d->size);
  *out = d;
  return HR_OK;
}

void hr_dist_finish(hr_dist **pd) {
  if (!pd || !*pd) return;
  hr_dist *d = *pd;
  MPI_Comm_free(&d->comm);
  if (d->own_init) MPI_Finalize();
  free(d);
  *pd = NULL;
}

void hr_dist_abort(const hr_dist *d, int code) {
  if (d) MPI_Abort(d->comm, code);
}

int hr_dist_rank(const hr_dist *d) { return d ? d->rank : 0; }
int hr_dist_size(const hr_dist *d) { return d ? d->size : 1; }

void hr_dist_barrier(const hr_dist *d) {
  if (d) MPI_Barrier(d->comm);
}

static void allreduce(const hr_dist *d, void *v, int64_t n, MPI_Datatype t, size_t sz, MPI_Op op) {
  if (!d || d->size == 1) return;
  const double t0 = MPI_Wtime();
  char *p = v;
  for (int64_t o = 0; o < n; o += CHUNK) {
    int64_t k = n - o < CHUNK ? n - o : CHUNK;
    MPI_Allreduce(MPI_IN_PLACE, p + (size_t)o * sz, (int)k, t, op, d->comm);
  }
  count((hr_dist *)d, n * (int64_t)sz, t0);
}

int hr_dist_any(const hr_dist *d, int flag) {
  int64_t v = flag != 0;
  hr_dist_max_i64(d, &v, 1);
  return v != 0;
}

void hr_dist_counters(const hr_dist *d, int64_t *calls, int64_t *bytes, double *secs) {
  *calls = d ? d->calls : 0;
  *bytes = d ? d->bytes : 0;
  *secs = d ? d->secs : 0;
}

hr_status hr_dist_gather(const hr_dist *d, const void *mine, size_t n, void *all) {
  if (!d) {
    memcpy(all, mine, n);
    return HR_OK;
  }
  if (n > INT_MAX) return HR_ERR_TOO_BIG;
  MPI_Gather(mine, (int)n, MPI_BYTE, all, (int)n, MPI_BYTE, 0, d->comm);
  return HR_OK;
}

void hr_dist_bcast_from(const hr_dist *d, int root, void *buf, size_t n) {
  if (!d || d->size == 1) return;
  const double t0 = MPI_Wtime();
  for (size_t o = 0; o < n; o += (size_t)CHUNK) {
    const size_t k = n - o < (size_t)CHUNK ? n - o : (size_t)CHUNK;
    MPI_Bcast((char *)buf + o, (int)k, MPI_BYTE, root, d->comm);
  }
  count((hr_dist *)d, d->rank == root ? (int64_t)n : 0, t0);
}

void hr_dist_bcast(const hr_dist *d, void *buf, size_t n) { hr_dist_bcast_from(d, 0, buf, n); }

int hr_dist_argmin(const hr_dist *d, double v) {
  if (!d || d->size == 1) return 0;
  struct {
    double v;
    int rank;
  } in = {v, d->rank}, out;
  const double t0 = MPI_Wtime();
  MPI_Allreduce(&in, &out, 1, MPI_DOUBLE_INT, MPI_MINLOC, d->comm);
  count((hr_dist *)d, (int64_t)sizeof in, t0);
  return out.rank;
}

void hr_dist_sum_f64(const hr_dist *d, double *v, int64_t n) {
  allreduce(d, v, n, MPI_DOUBLE, sizeof *v, MPI_SUM);
}
void hr_dist_max_f64(const hr_dist *d, double *v, int64_t n) {
  allreduce(d, v, n, MPI_DOUBLE, sizeof *v, MPI_MAX);
}
void hr_dist_sum_i64(const hr_dist *d, int64_t *v, int64_t n) {
  allreduce(d, v, n, MPI_INT64_T, sizeof *v, MPI_SUM);
}
void hr_dist_max_i64(const hr_dist *d, int64_t *v, int64_t n) {
  allreduce(d, v, n, MPI_INT64_T, sizeof *v, MPI_MAX);
}

/* One received message of a sparse exchange. */
typedef struct piece {
  int src;
  int64_t seq, n;
  char *buf;
} piece;

static int cmp_piece(const void *a, const void *b) {
  const piece *x = a, *y = b;
  if (x->src != y->src) return x->src < y->src ? -1 : 1;
  return (x->seq > y->seq) - (x->seq < y->seq);
}

/* Sparse personalised exchange without any count exchange (Hoefler, Siebert and Lumsdaine's
 * NBX, "Scalable communication protocols for dynamic sparse data exchange", PPoPP 2010): each
 * message goes out as a synchronous send (it completes only once received); a rank that sees
 * all its sends complete enters a nonblocking barrier, and keeps receiving whatever arrives
 * until the barrier completes, which happens only when every rank's sends have been received.
 * No rank waits for a message that will not come, and no P^2 count table is needed. Messages
 * of more than CHUNK bytes go in pieces (MPI keeps their order between one pair). What arrives
 * is put in rank order, so the result is that of an all-to-all. Every rank gets the same
 * status (a failed allocation is agreed on after the exchange). */
hr_status hr_dist_alltoall(const hr_dist *d, const void *send, const int64_t *sbytes,
                           void **recv, int64_t *rbytes_total) {
  return hr_dist_alltoall_st(d, send, sbytes, 0, recv, rbytes_total);
}

hr_status hr_dist_alltoall_st(const hr_dist *d, const void *send, const int64_t *sbytes,
                              int failed, void **recv, int64_t *rbytes_total) {
  const int P = d->size, TAG = 7;
  const double t0 = MPI_Wtime();
  int64_t nreq = 0, sent = 0, off = 0, bad = failed ? 2 : 0;
  for (int p = 0; p < P; p++) nreq += (sbytes[p] + CHUNK - 1) / CHUNK;
  MPI_Request *rq = malloc((size_t)(nreq > 0 ? nreq : 1) * sizeof *rq);
  piece *pc = NULL;
  int64_t npc = 0, cappc = 0, seq = 0;
  if (!rq) MPI_Abort(d->comm, 1); /* the others may already wait for these messages */
  const char *sb = send;
  for (int p = 0, k = 0; p < P; off += sbytes[p], p++)
    for (int64_t o = 0; o < sbytes[p]; o += CHUNK, k++) {
      const int64_t n = sbytes[p] - o < CHUNK ? sbytes[p] - o : CHUNK;
      MPI_Issend(sb + off + o, (int)n, MPI_BYTE, p, TAG, d->comm, &rq[k]);
      sent += n;
    }
  MPI_Request barrier = MPI_REQUEST_NULL;
  int in_barrier = 0;
  for (;;) {
    int flag = 0;
    MPI_Status st;
    MPI_Iprobe(MPI_ANY_SOURCE, TAG, d->comm, &flag, &st);
    if (flag) {
      int n = 0;
      MPI_Get_count(&st, MPI_BYTE, &n);
      char *buf = malloc((size_t)(n > 0 ? n : 1));
      if (npc == cappc) {
        int64_t nc = cappc ? 2 * cappc : 16;
        piece *q = realloc(pc, (size_t)nc * sizeof *q);
        if (q) pc = q, cappc = nc;
      }
      if (!buf || npc == cappc) { /* receive into a scratch byte and drop it: agreed below */
        bad = 1;
        char scratch[1];
        free(buf);
        buf = n > 1 ? malloc((size_t)n) : NULL;
        MPI_Recv(buf ? buf : scratch, n, MPI_BYTE, st.MPI_SOURCE, TAG, d->comm,
                 MPI_STATUS_IGNORE);
        free(buf);
        continue;
      }
      MPI_Recv(buf, n, MPI_BYTE, st.MPI_SOURCE, TAG, d->comm, MPI_STATUS_IGNORE);
      pc[npc++] = (piece){st.MPI_SOURCE, seq++, n, buf};
      continue;
    }
    if (!in_barrier) {
      int done = 0;
      MPI_Testall((int)nreq, rq, &done, MPI_STATUSES_IGNORE);
      if (done) {
        MPI_Ibarrier(d->comm, &barrier);
        in_barrier = 1;
      }
    } else {
      int done = 0;
      MPI_Test(&barrier, &done, MPI_STATUS_IGNORE);
      if (done) break;
    }
  }
  free(rq);
  /* in rank order (and, within a rank, in arrival order: MPI does not reorder one pair) */
  if (npc > 1) qsort(pc, (size_t)npc, sizeof *pc, cmp_piece);
  int64_t tot = 0;
  for (int64_t i = 0; i < npc; i++) tot += pc[i].n;
  char *rb = bad ? NULL : malloc((size_t)(tot > 0 ? tot : 1));
  if (!rb && !bad) bad = 1; /* (a failure before, 2, stays: the others get HR_ERR_REMOTE) */
  for (int64_t i = 0, o = 0; i < npc; o += pc[i].n, i++) {
    if (rb && pc[i].n) memcpy(rb + o, pc[i].buf, (size_t)pc[i].n);
    free(pc[i].buf);
  }
  free(pc);
  count((hr_dist *)d, sent - sbytes[d->rank], t0);
  hr_dist_max_i64(d, &bad, 1);
  if (bad) {
    free(rb);
    return bad == 2 ? HR_ERR_REMOTE : HR_ERR_NOMEM;
  }
  *recv = rb;
  *rbytes_total = tot;
  return HR_OK;
}

/* ---------------------------------------------------------------- message queues */

/* A batch goes out when its buffer reaches this size. */
#define MQ_BATCH (64 * 1024)

typedef struct mq_send {
  MPI_Request rq;
  char *buf;
} mq_send;

struct hr_dist_mq {
  hr_dist *d;
  int tag;
  char **buf;       /* per destination: the batch being filled */
  size_t *len, *cap;
  mq_send *sends;   /* batches in flight */
  int nsends, capsends;
  char *rbuf;       /* the last received batch */
  double t_mpi;
};

hr_status hr_dist_mq_open(const hr_dist *d, int tag, hr_dist_mq **out) {
  hr_dist_mq *q = calloc(1, sizeof *q);
  if (q) {
    q->buf = calloc((size_t)d->size, sizeof *q->buf);
    q->len = calloc((size_t)d->size, sizeof *q->len);
    q->cap = calloc((size_t)d->size, sizeof *q->cap);
  }
  if (!q || !q->buf || !q->len || !q->cap) {
    if (q) free(q->buf), free(q->len), free(q->cap);
    free(q);
    return HR_ERR_NOMEM;
  }
  q->d = (hr_dist *)d;
  q->tag = tag;
  *out = q;
  return HR_OK;
}

/* Completed sends: their buffers freed, the slots reused. */
static void mq_reap(hr_dist_mq *q) {
  for (int i = 0; i < q->nsends;) {
    int done = 0;
    MPI_Test(&q->sends[i].rq, &done, MPI_STATUS_IGNORE);
    if (done) {
      free(q->sends[i].buf);
      q->sends[i] = q->sends[--q->nsends];
    } else {
      i++;
    }
  }
}

/* Sends the batch for 'p' (if any); 0 when out of memory (then MPI_Abort: a lost batch would
 * leave its receiver waiting). */
static void mq_send_batch(hr_dist_mq *q, int p) {
  if (q->len[p] == 0) return;
  if (q->nsends == q->capsends) {
    int nc = q->capsends ? 2 * q->capsends : 16;
    mq_send *ns = realloc(q->sends, (size_t)nc * sizeof *ns);
    if (!ns) MPI_Abort(q->d->comm, 1);
    q->sends = ns, q->capsends = nc;
  }
  const double t0 = MPI_Wtime();
  mq_send *sd = &q->sends[q->nsends++];
  sd->buf = q->buf[p];
  MPI_Isend(sd->buf, (int)q->len[p], MPI_BYTE, p, q->tag, q->d->comm, &sd->rq);
  q->d->msgs++;
  q->d->msg_bytes += (int64_t)q->len[p];
  q->buf[p] = NULL;
  q->len[p] = q->cap[p] = 0;
  q->t_mpi += MPI_Wtime() - t0;
}

void *hr_dist_mq_put(hr_dist_mq *q, int dest, size_t n) {
  if (q->len[dest] + n > MQ_BATCH && q->len[dest] > 0) mq_send_batch(q, dest);
  if (q->len[dest] + n > q->cap[dest]) {
    size_t nc = q->cap[dest] ? q->cap[dest] : 4096;
    while (nc < q->len[dest] + n) nc *= 2;
    char *b = realloc(q->buf[dest], nc);
    if (!b) return NULL;
    q->buf[dest] = b, q->cap[dest] = nc;
  }
  void *r = q->buf[dest] + q->len[dest];
  q->len[dest] += n;
  return r;
}

void hr_dist_mq_flush(hr_dist_mq *q) {
  for (int p = 0; p < q->d->size; p++) mq_send_batch(q, p);
  mq_reap(q);
}

int hr_dist_mq_poll(hr_dist_mq *q, int wait, const void **buf, int64_t *n, int *src) {
  const double t0 = MPI_Wtime();
  free(q->rbuf);
  q->rbuf = NULL;
  int flag = 0, cnt = 0;
  MPI_Status st;
  if (wait) {
    MPI_Probe(MPI_ANY_SOURCE, q->tag, q->d->comm, &st);
    flag = 1;
  } else {
    MPI_Iprobe(MPI_ANY_SOURCE, q->tag, q->d->comm, &flag, &st);
  }
  if (flag) {
    MPI_Get_count(&st, MPI_BYTE, &cnt);
    q->rbuf = malloc((size_t)(cnt > 0 ? cnt : 1));
    if (!q->rbuf) MPI_Abort(q->d->comm, 1);
    MPI_Recv(q->rbuf, cnt, MPI_BYTE, st.MPI_SOURCE, q->tag, q->d->comm, MPI_STATUS_IGNORE);
    *buf = q->rbuf, *n = cnt, *src = st.MPI_SOURCE;
  }
  q->t_mpi += MPI_Wtime() - t0;
  return flag;
}

void hr_dist_mq_close(hr_dist_mq **pq) {
  hr_dist_mq *q = *pq;
  if (!q) return;
  hr_dist_mq_flush(q);
  const double t0 = MPI_Wtime();
  for (int i = 0; i < q->nsends; i++) {
    MPI_Wait(&q->sends[i].rq, MPI_STATUS_IGNORE);
    free(q->sends[i].buf);
  }
  q->t_mpi += MPI_Wtime() - t0;
  q->d->secs += q->t_mpi;
  for (int p = 0; p < q->d->size; p++) free(q->buf[p]);
  free(q->buf), free(q->len), free(q->cap), free(q->sends), free(q->rbuf);
  free(q);
  *pq = NULL;
}

void hr_dist_msg_counters(const hr_dist *d, int64_t *msgs, int64_t *bytes) {
  *msgs = d ? d->msgs : 0;
  *bytes = d ? d->msg_bytes : 0;
}
