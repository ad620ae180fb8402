/* mpimodel: models the distributed solver's time at P ranks from one recorded one-process run
 * (BENCHMARKS.md, "Distributed solver: measured and modelled").
 *
 *   mpimodel SCENE [BF_LOW [T1_TARGET]]
 *
 * It solves SCENE on one thread, records the phase times, the iterations and, per element, the
 * links it receives at the end (the work that goes with the element's owner), then for each P
 * assigns the elements as `--balance area` does (roots by area, children with their parent) and
 * as `--balance random` does (every element at random), and models
 *
 *   T(P) = T_init / P + (T_refine + T_gather) * I(P) / P + T_pushpull + C(P)
 *
 * with I(P) the largest rank's share of the links over the mean (load imbalance), push-pull
 * spread over the ranks (T_pushpull / P) and C(P) the messages (see comm() and
 * pushpull_traffic(): docs/design.md, "Distribution", has the protocol): per iteration the
 * push, pull and store messages of the distributed push-pull, computed exactly for the
 * assignment, the sum of the roots' radiosities and K small collectives and exchanges; once,
 * the initial exchange of the links (48 bytes a link, (P-1)/P of them leave their rank); and,
 * with random owners, the links refinement makes, which travel with their candidate lists
 * ((P-1)/P of them, spread over the ranks). Two machines:
 * the paper's CM-5 (5 MB/s per node link, 88 us per message; the processors' speed scaled so
 * that one processor takes T1_TARGET seconds, the paper's table 2 time for "floor" when given) and a current cluster (10 GB/s, 2 us, this
 * machine's processor speed). The assumptions are stated in BENCHMARKS.md. */
#include "hrad.h"
#include "partition/partition.h"
#include "solver_impl.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define K_SMALL 54 /* collectives per iteration, counted in a 2-rank run of room (2,482 in 46) */

typedef struct machine {
  const char *name;
  double alpha, beta, cpu; /* seconds per message, bytes per second, time factor */
} machine;

static int cmp_u64(const void *a, const void *b) {
  const uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
  return (x > y) - (x < y);
}

static uint64_t mix(uint64_t z) {
  z = (z ^ (z >> 30)) * UINT64_C(0xbf58476d1ce4e5b9);
  z = (z ^ (z >> 27)) * UINT64_C(0x94d049bb133111eb);
  return z ^ (z >> 31);
}

/* Owner of every element at P ranks: 'random' as hr_elem_owner with a scatter seed of 1, else
 * roots greedily by area and children with their parents (elements come after their parents). */
static void assign(const hr_solver *s, int P, int random, int32_t *own) {
  const int n = s->scene->nsurfs;
  if (random) {
    for (int64_t e = 0; e < s->nel; e++)
      own[e] = (int32_t)(mix(UINT64_C(1) ^ (s->el[e].gid * UINT64_C(0x9e3779b97f4a7c15))) %
                         (uint64_t)P);
    return;
  }
  double *area = malloc((size_t)n * sizeof *area);
  for (int i = 0; i < n; i++) area[i] = s->scene->surfs[i].area;
  hr_partition_greedy(area, n, P, own);
  free(area);
  for (int64_t e = n; e < s->nel; e++) own[e] = own[s->el[e].parent];
}

/* What the message protocol of push-pull sends in one iteration at assignment 'own' (P ranks;
 * docs/design.md, "Messages"): a PUSH (56 bytes) and a PULL (88) for every tree edge between
 * ranks, a STORE (184) to every rank that holds a link from an element it does not own. Gives
 * the largest rank's bytes and destinations, and the most rank changes on a path from a root to
 * a leaf (the critical path of pushes down and pulls up). */
typedef struct traffic {
  double bytes_max, dest_max, depth, stores, edges;
} traffic;

static traffic pushpull_traffic(const hr_solver *s, int P, const int32_t *own) {
  traffic tr = {0, 0, 0, 0, 0};
  double *bytes = calloc((size_t)P, sizeof *bytes);
  uint8_t *dest = calloc((size_t)P * (size_t)P, 1);
  int32_t *hops = calloc((size_t)s->nel, sizeof *hops);
  for (int64_t e = 0; e < s->nel; e++) {
    const int32_t par = s->el[e].parent;
    if (par < 0 || own[par] == own[e]) {
      if (par >= 0) hops[e] = hops[par];
      continue;
    }
    hops[e] = hops[par] + 1; /* parents come before their children */
    tr.depth = hops[e] > tr.depth ? hops[e] : tr.depth;
    tr.edges++;
    bytes[own[par]] += 56, bytes[own[e]] += 88;
    dest[(size_t)own[par] * P + own[e]] = dest[(size_t)own[e] * P + own[par]] = 1;
  }
  /* subscriptions: (source, rank) pairs, from the links grouped by receiver */
  uint64_t *pairs = malloc((size_t)(s->nlinks > 0 ? s->nlinks : 1) * sizeof *pairs);
  int64_t np = 0;
  for (int64_t k = 0; k < s->nlinks; k++) {
    const hr_link *l = &s->links[k];
    if (l->Fu < 0 || own[l->s] == own[l->r]) continue;
    pairs[np++] = (uint64_t)l->s * (uint64_t)P + (uint64_t)own[l->r];
  }
  qsort(pairs, (size_t)np, sizeof *pairs, cmp_u64);
  for (int64_t i = 0; i < np; i++) {
    if (i > 0 && pairs[i] == pairs[i - 1]) continue;
    const int64_t j = (int64_t)(pairs[i] / (uint64_t)P);
    const int r = (int)(pairs[i] % (uint64_t)P);
    tr.stores++;
    bytes[own[j]] += 184;
    dest[(size_t)own[j] * P + r] = 1;
  }
  for (int p = 0; p < P; p++) {
    double d = 0;
    for (int q = 0; q < P; q++) d += dest[(size_t)p * P + q];
    tr.dest_max = d > tr.dest_max ? d : tr.dest_max;
    tr.bytes_max = bytes[p] > tr.bytes_max ? bytes[p] : tr.bytes_max;
  }
  free(bytes), free(dest), free(hops), free(pairs);
  return tr;
}

/* Communication time at P ranks on machine m: per iteration the push-pull messages (critical
 * path of 2 x depth latencies, the largest rank's bytes and one latency per destination), the
 * sum of the roots' radiosities (ring allreduce of 24 bytes a surface) and K small collectives
 * and exchanges (2 log2 P latencies each); once, the initial exchange of the links; and the
 * links refinement moves ('routed' of 'lbytes' bytes), spread over the ranks. */
static double comm(const hr_solver *s, const machine *m, int P, int64_t links0, double routed,
                   double lbytes, const traffic *tr) {
  if (P == 1) return 0;
  const double lg = ceil(log2((double)P)), it = s->iterations;
  const double roots = 24.0 * s->scene->nsurfs;
  const double pp = 2 * tr->depth * m->alpha + tr->bytes_max / m->beta + tr->dest_max * m->alpha;
  const double per_iter = pp + 2 * lg * m->alpha + 2.0 * (P - 1) / P * roots / m->beta +
                          K_SMALL * 2 * lg * m->alpha;
  const double init = 48.0 * (double)links0 / P * (P - 1) / P / m->beta + (P - 1) * m->alpha;
  return it * per_iter + init + routed / P * lbytes / m->beta;
}

int main(int argc, char **argv) {
  if (argc < 2) {
    fprintf(stderr, "usage: mpimodel SCENE [BF_LOW [T1_TARGET]]\n");
    return 2;
  }
  hr_err err = {{0}};
  hr_scene *sc = NULL;
  if (hr_scene_builtin(argv[1], &sc, &err) != HR_OK && hr_scene_load_obj(argv[1], NULL, &sc, &err))
    return fprintf(stderr, "mpimodel: %s\n", err.msg), 1;
  hr_options o;
  hr_options_default(&o);
  o.threads = 1;
  if (argc > 2) o.bf_low = atof(argv[2]);
  if (o.bf_start < o.bf_low) o.bf_start = o.bf_low;
  hr_solver *s = NULL;
  if (hr_solver_create(sc, &o, &s, &err) || hr_solver_run(s, NULL, NULL, &err))
    return fprintf(stderr, "mpimodel: %s\n", err.msg), 1;
  const hr_timing t = s->t;
  int64_t *recv = calloc((size_t)s->nel, sizeof *recv), live = 0;
  for (int64_t k = 0; k < s->nlinks; k++)
    if (s->links[k].Fu >= 0) recv[s->links[k].r]++, live++;
  const double t1 = t.init_graph + t.refine + t.gather + t.push_pull;
  const double target = argc > 3 ? atof(argv[3]) : 0;
  printf("scene %s, bf_low %g: %d iterations, %lld elements, %lld links, initial %lld\n", argv[1],
         o.bf_low, s->iterations, (long long)s->nel, (long long)live,
         (long long)s->initial_links);
  printf("one thread: init %.3f s, refine %.3f s, gather %.3f s, push-pull %.3f s, sum %.3f s\n",
         t.init_graph, t.refine, t.gather, t.push_pull, t1);
  const machine ms[2] = {{"CM-5 (5 MB/s, 88 us)", 88e-6, 5e6, target > 0 ? target / t1 : 1},
                         {"cluster (10 GB/s, 2 us)", 2e-6, 10e9, 1}};
  int32_t *own = malloc((size_t)s->nel * sizeof *own);
  for (int mi = 0; mi < 2; mi++) {
    const machine *m = &ms[mi];
    printf("\n%s, processor time x %.4g\n", m->name, m->cpu);
    printf("   P  balance  imbalance  init s  refine+gather s  push-pull s  comm s    sum s  "
           "speed-up  efficiency  pp-depth  stores/it\n");
    for (int random = 0; random < 2; random++)
      for (int P = 1; P <= 64; P *= 2) {
        assign(s, P, random, own);
        int64_t *lr = calloc((size_t)P, sizeof *lr), mx = 0;
        for (int64_t e = 0; e < s->nel; e++) lr[own[e]] += recv[e];
        for (int p = 0; p < P; p++) mx = lr[p] > mx ? lr[p] : mx;
        const double imb = live > 0 ? (double)mx * P / (double)live : 1;
        const double ti = m->cpu * t.init_graph / P, trg = m->cpu * (t.refine + t.gather) * imb / P;
        /* with random owners, (P-1)/P of the links made by refinement change rank (about
         * all of them come from receiver splits: an upper bound) */
        const double routed = random ? (double)(live - s->initial_links) * (P - 1) / P : 0;
        const double lbytes = 48.0 + 4.0 * (double)s->npool / (double)(live > 0 ? live : 1);
        const double tp = m->cpu * t.push_pull / P;
        const traffic tr = pushpull_traffic(s, P, own);
        const double tc = comm(s, m, P, s->initial_links, routed > 0 ? routed : 0, lbytes, &tr);
        const double sum = ti + trg + tp + tc;
        printf("%4d  %-7s  %9.3f  %6.2f  %15.2f  %11.2f  %6.2f  %7.2f  %8.2f  %9.0f%%  %8.0f  "
               "%9.0f\n", P, random ? "random" : "area", imb, ti, trg, tp, tc, sum,
               m->cpu * t1 / sum, 100 * m->cpu * t1 / sum / P, tr.depth, tr.stores);
        free(lr);
      }
  }
  free(own);
  free(recv);
  hr_solver_destroy(&s);
  hr_scene_destroy(&sc);
  return 0;
}
