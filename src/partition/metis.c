/* metis.c: METIS k-way behind partition.h (Debian's libmetis-dev, METIS 5.1: 32-bit idx_t).
 * METIS wants integer weights: node and edge weights are scaled so the largest becomes about
 * 1e6 while every sum stays far below 2^31 (and edge weights at least 1: METIS drops nothing,
 * a zero-weight edge would still tie parts together in the cut it reports). A fixed seed makes
 * it deterministic (METIS is single-threaded here). */
#include "partition/partition.h"

#include <metis.h>
#include <math.h>
#include <stdlib.h>

/* Integer weights for v[0, n): scaled so that max -> about 'top', the sum below 'sum_max'. */
static void to_idx(const double *v, int64_t n, double top, double sum_max, idx_t lo, idx_t *out) {
  double mx = 0, sum = 0;
  for (int64_t i = 0; i < n; i++) {
    mx = v[i] > mx ? v[i] : mx;
    sum += v[i];
  }
  double scale = mx > 0 ? top / mx : 1;
  if (sum * scale > sum_max) scale = sum_max / sum;
  for (int64_t i = 0; i < n; i++) {
    const double x = floor(v[i] * scale + 0.5);
    out[i] = x < (double)lo ? lo : (idx_t)x;
  }
}

int hr_partition_metis(const hr_graph *g, int nparts, int32_t *part) {
  if (!g || g->n < 0 || nparts < 1) return 0;
  const int64_t m = g->n > 0 ? g->xadj[g->n] : 0;
  if (m > INT32_MAX / 2 || g->n > INT32_MAX / 2) return 0;
  if (nparts == 1 || g->n <= nparts || m == 0) {
    /* nothing to cut (METIS refuses some of these): the greedy split of the weights */
    if (nparts == 1 || m == 0) return hr_partition_greedy(g->w, g->n, nparts, part);
    for (int i = 0; i < g->n; i++) part[i] = i; /* one node a part */
    return 1;
  }
  idx_t nv = g->n, ncon = 1, np = nparts, objval = 0;
  idx_t *xadj = malloc((size_t)(g->n + 1) * sizeof *xadj);
  idx_t *adj = malloc((size_t)m * sizeof *adj), *vw = malloc((size_t)g->n * sizeof *vw);
  idx_t *ew = malloc((size_t)m * sizeof *ew), *pt = malloc((size_t)g->n * sizeof *pt);
  int ok = xadj && adj && vw && ew && pt;
  if (ok) {
    for (int i = 0; i <= g->n; i++) xadj[i] = (idx_t)g->xadj[i];
    for (int64_t k = 0; k < m; k++) adj[k] = g->adj[k];
    to_idx(g->w, g->n, 1e6, 1e9, 0, vw);
    to_idx(g->c, m, 1e6, 1e9, 1, ew);
    idx_t opt[METIS_NOPTIONS];
    METIS_SetDefaultOptions(opt);
    opt[METIS_OPTION_SEED] = 1;
    ok = METIS_PartGraphKway(&nv, &ncon, xadj, adj, vw, NULL, ew, &np, NULL, NULL, opt, &objval,
                             pt) == METIS_OK;
    for (int i = 0; ok && i < g->n; i++) part[i] = (int32_t)pt[i];
  }
  free(xadj);
  free(adj);
  free(vw);
  free(ew);
  free(pt);
  return ok;
}
