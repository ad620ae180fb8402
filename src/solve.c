/* solve.c: the algorithm of the paper's Figure 3. Multigridding over a decreasing BF_e schedule
 * ({2}, {17}, {18}), the inner loop of refinement ({7..13}), gathering through the links
 * (do_link, {12}) and push-pull ({14}, paper 2.2.3), with the relaxed inner loop of section
 * 2.2.4 as an option, and a per-iteration callback for display ({15}).
 *
 * Iteration is Jacobi-style: every gather reads the radiosities of the previous push-pull, and
 * sums over a receiver's links in a fixed order, so results do not depend on thread count or
 * scheduling. */
#include "mpi/dist.h"
#include "partition/partition.h"
#include "cluster.h"
#include "scene_impl.h"
#include "solver_impl.h"
#include "vec.h"

#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>

double hr_now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

void hr_options_default(hr_options *o) {
  memset(o, 0, sizeof *o);
  o->bf_low = 1e-3;
  /* one level at the defaults: BF_e starts at BF_low (0: follows it). Two levels (0.05, then
   * BF_low) had been 10-25% faster than the paper's many; starting at BF_low took the
   * conference room from 4.74% to 4.03% RMS against the path tracer for 5% more time, and
   * 4.67% in 0.7 of the time at --bf-low 2e-3 --area-min 1e-3 (docs/design.md, "Algorithm
   * details") */
  o->bf_start = 0;
  o->bf_first = 0; /* follows bf_start: a quarter of it (BF_FIRST_DIV) */
  o->bf_factor = 50.0;
  o->area_min = 0; /* follows bf_low */
  o->b_eps = 0; /* follows bf_low */
  o->b_max = 2e-3;
  o->relax = 1;
  o->relax_links = 5;
  o->rays = 16;
  o->seed = 1;
  o->threads = 0;
  o->max_iters = 1000;
  o->max_links = 5e7;
  o->extrapolate = 1;
  /* receivers below A_e / 4 take (A_e / 4 / A)^0.7 times the tolerance: E = 0.5 took the
   * conference room 4.07% -> 4.52% RMS against the path tracer in 0.55 of the time, a better
   * trade than --bf-low gives; 0.7, since contact cuts, 3.59% -> 3.86% in 0.88 of the time,
   * under a minute (docs/design.md, "Importance") */
  o->importance = 0.7;
}

/* A clustered solve's first linking, before any light is gathered (--bf-first 0), refines at
 * this fraction of the first level's BF_e: the direct light, judged there against the floor of
 * the reference radiosity, resolved finer. The conference room at the defaults: 4.518% -> 4.223%
 * RMS against the path tracer at the same time (BF_e / 2: 4.345%, / 10: 4.147% in 1.16x the
 * time); the built-in scenes, where the emitters are small or their receivers open down to
 * surfaces at once, hardly notice it (docs/design.md, "The direct light's resolution"). */
#define BF_FIRST_DIV 4

/* Area-weighted mean emitted radiosity (largest channel): the radiosity unit before any light
 * has been gathered. */
static double emitted_mean(const hr_scene *sc, double area) {
  double m[3] = {0, 0, 0};
  for (int i = 0; i < sc->nsurfs; i++)
    for (int c = 0; c < 3; c++) m[c] += sc->surfs[i].area * sc->mats[sc->surfs[i].material].emit[c];
  double x = m[0] > m[1] ? m[0] : m[1];
  x = x > m[2] ? x : m[2];
  return x / area;
}

/* A_e (relative) equals BF_low unless given (--area-min): one setting moves both the accuracy of
 * the links and the finest mesh. Measured on the Cornell box against a path-traced reference
 * (area-weighted RMS error, time on 2 cores): BF_low = A_e = 1e-2: 3.6%, 0.03 s; 3e-3: 1.1%,
 * 0.1 s; 1e-3: 0.43%, 0.7 s; 3e-4: 0.25%, 4.3 s (BENCHMARKS.md). */

static hr_status check_options(const hr_options *o, hr_err *err) {
  const double d[] = {o->bf_low, o->bf_start, o->bf_factor, o->area_min, o->b_eps, o->b_max,
                      o->max_links, o->bf_first, o->importance};
  for (size_t k = 0; k < sizeof d / sizeof d[0]; k++)
    if (!isfinite(d[k])) return hr_err_set(err, HR_ERR_INVALID, "options must be finite numbers");
  if (!(o->bf_low > 0)) return hr_err_set(err, HR_ERR_INVALID, "--bf-low must be > 0");
  if (!(o->bf_start == 0 || o->bf_start >= o->bf_low))
    return hr_err_set(err, HR_ERR_INVALID, "--bf-start must be 0 (BF_low) or >= --bf-low");
  if (!(o->bf_factor > 1)) return hr_err_set(err, HR_ERR_INVALID, "--bf-factor must be > 1");
  if (!(o->bf_first >= 0))
    return hr_err_set(err, HR_ERR_INVALID, "--bf-first must be >= 0 (0: --bf-start / 4)");
  if (!(o->importance >= 0 && o->importance <= 1))
    return hr_err_set(err, HR_ERR_INVALID, "--importance must be in [0, 1] (0: off)");
  if (!(o->area_min >= 0 && o->area_min < 1))
    return hr_err_set(err, HR_ERR_INVALID, "--area-min must be in [0, 1) (0: BF_low)");
  if (!(o->b_eps >= 0))
    return hr_err_set(err, HR_ERR_INVALID, "--b-eps must be >= 0 (0: BF_low)");
  if (!(o->b_max > 0 && o->b_max >= o->b_eps))
    return hr_err_set(err, HR_ERR_INVALID, "--b-max must be > 0 and >= --b-eps");
  if (o->rays < 1 || o->rays > 4096)
    return hr_err_set(err, HR_ERR_INVALID, "--rays must be in 1..4096");
  if (o->threads < 0 || o->threads > 1024)
    return hr_err_set(err, HR_ERR_INVALID, "--threads must be in 0..1024 (0: all cores)");
  if (o->max_links < 0) return hr_err_set(err, HR_ERR_INVALID, "--max-links must be >= 0");
  if (o->max_iters < 1) return hr_err_set(err, HR_ERR_INVALID, "--max-iters must be >= 1");
  return HR_OK;
}

hr_status hr_solver_create(const hr_scene *scene, const hr_options *opt, hr_solver **out,
                           hr_err *err) {
  *out = NULL;
  hr_options o;
  if (opt)
    o = *opt;
  else
    hr_options_default(&o);
  hr_status st = check_options(&o, err);
  if (st != HR_OK) return st;
  if (scene->nsurfs == 0) return hr_err_set(err, HR_ERR_INVALID, "scene has no surfaces");
  if ((int64_t)scene->nsurfs > (INT64_C(1) << (64 - HR_GID_PATH_BITS)) - 1)
    return hr_err_set(err, HR_ERR_TOO_BIG, "%d surfaces: element ids hold at most %lld",
                      scene->nsurfs, (long long)((INT64_C(1) << (64 - HR_GID_PATH_BITS)) - 1));
  if ((st = hr_vis_check_range(scene, err)) != HR_OK) return st;
  double emax = hr_scene_max_emit(scene);
  if (!(emax > 0))
    return hr_err_set(err, HR_ERR_NO_EMITTER,
                      "%s: scene has no emitting surface (give a material Ke, or use --emit)",
                      scene->name);
  hr_solver *s = calloc(1, sizeof *s);
  if (!s) return hr_err_set(err, HR_ERR_NOMEM, "out of memory");
  s->scene = scene;
  s->opt = o;
  if (!(o.bf_start > 0)) s->opt.bf_start = o.bf_low; /* 0: one level, at BF_low */
  /* 0: a quarter of the first level's BF_e */
  if (!(o.bf_first > 0)) s->opt.bf_first = s->opt.bf_start / BF_FIRST_DIV;
  s->area_total = hr_scene_total_area(scene);
  s->area_min = (o.area_min > 0 ? o.area_min : o.bf_low) * s->area_total;
  s->b_eps = o.b_eps > 0 ? o.b_eps : fmin(o.bf_low, o.b_max);
  s->vf = (hr_vf_ctx){scene, NULL, hr_vis_lift(scene), o.seed};
  s->unit = emitted_mean(scene, s->area_total);
  s->threads = o.threads > 0 ? o.threads : omp_get_num_procs();
  if ((st = hr_elem_init(s)) != HR_OK) {
    hr_solver_destroy(&s);
    return hr_err_set(err, st, "out of memory");
  }
  *out = s;
  return HR_OK;
}

void hr_solver_destroy(hr_solver **ps) {
  if (!ps || !*ps) return;
  hr_solver *s = *ps;
  hr_solver_set_progress(s, NULL, NULL); /* drops its entry in progress.c's table */
  hr_vis_destroy(&s->vis);
  hr_shaft_index_destroy(&s->shaft);
  hr_cluster_free(&s->cl);
  free(s->el);
  free(s->B);
  free(s->Bs);
  free(s->G);
  free(s->Gu);
  free(s->Gf);
  free(s->Gv);
  free(s->erays);
  free(s->rho);
  free(s->rho_max);
  free(s->bref);
  free(s->bvar);
  free(s->hist);
  free(s->open);
  free(s->links);
  free(s->pool);
  free(s->rstart);
  free(s->xstart);
  free(s->xidx);
  free(s->ls);
  free(s->lfo);
  free(s->eown);
  free(s->esub);
  free(s->gkey);
  free(s->gval);
  free(s->subs);
  free(s->rootown);
  free(s->omap);
  free(s->coll);
  free(s);
  *ps = NULL;
}

/* Largest channel of an RGB value. */
static inline double max3(const double *v) {
  double x = v[0] > v[1] ? v[0] : v[1];
  return x > v[2] ? x : v[2];
}

/* do_link of one link: adds F B_j to g0..g2, Fu max(B_j) to gu, F to gf and dF max(B_j) to gv.
 * Dead links have F = 0 and add nothing to g; their Fu < 0 is skipped. */
static inline void gather_link(const hr_solver *s, const hr_link *l, double *g0, double *g1,
                               double *g2, double *gu, double *gf, double *gv) {
  const double *b = s->Bs[l->s];
  double bw[3];
  const int32_t c = s->el[l->s].child;
  if (c >= 0 && l->w[0] >= 0) {
    /* Source shares: the children's radiosities, weighted as the link sees them. */
    const double(*bc)[3] = s->Bs + c;
    for (int k = 0; k < 3; k++)
      bw[k] = l->w[0] * bc[0][k] + l->w[1] * bc[1][k] + l->w[2] * bc[2][k] + l->w[3] * bc[3][k];
    b = bw;
  }
  const double f = l->F;
  *g0 += f * b[0];
  *g1 += f * b[1];
  *g2 += f * b[2];
  *gf += f;
  if (l->Fu > 0) {
    const double bm = max3(b);
    *gu += l->Fu * bm;
    *gv += l->dF * bm;
  }
}

/* do_link for every link, grouped by receiver: G_i = sum_j F_ij B_j (previous B). */
static void gather(hr_solver *s) {
#pragma omp parallel for schedule(dynamic, 256) if (s->nlinks > PAR_MIN) num_threads(s->threads)
  for (int64_t e = 0; e < s->nel; e++) {
    double g0 = 0, g1 = 0, g2 = 0, gu = 0, gf = 0, gv = 0;
    /* The sorted links and the extras, each in source gid order, merged: the sum runs in the
     * order of the sources' gids however the links are stored (hr_link_sort). */
    int64_t k = e < s->nrstart ? s->rstart[e] : 0, ke = e < s->nrstart ? s->rstart[e + 1] : 0;
    int64_t x = 0, xe = 0;
    if (s->nlinks > s->nsorted) x = s->xstart[e], xe = s->xstart[e + 1];
    while (k < ke || x < xe) {
      const hr_link *l;
      if (x >= xe || (k < ke && s->el[s->links[k].s].gid < s->el[s->links[s->xidx[x]].s].gid))
        l = &s->links[k++];
      else
        l = &s->links[s->xidx[x++]];
      gather_link(s, l, &g0, &g1, &g2, &gu, &gf, &gv);
    }
    s->G[e][0] = g0;
    s->G[e][1] = g1;
    s->G[e][2] = g2;
    s->Gu[e] = gu;
    s->Gf[e] = gf;
    s->Gv[e] = gv;
  }
}

static int64_t count_leaves(const hr_solver *s) {
  int64_t n = 0;
  for (int64_t e = 0; e < s->nel; e++) n += s->el[e].child < 0 && hr_owns(s, e);
  return n;
}

static int64_t count_own(const hr_solver *s) {
  if (!s->dist) return s->nel;
  int64_t n = 0;
  for (int64_t e = 0; e < s->nel; e++) n += hr_owns(s, e);
  return n;
}

/* The counts reported (links, rays, leaves, elements) over all ranks. */
void hr_solver_sync_counts(hr_solver *s) {
  int64_t v[6] = {s->nlinks - s->ndead, s->rays, s->initial_links, count_leaves(s),
                  count_own(s), hr_cluster_links(s)};
  hr_dist_sum_i64(s->dist, v, 6);
  s->g_links = v[0], s->g_rays = v[1], s->g_initial = v[2], s->g_leaves = v[3], s->g_nel = v[4];
  s->g_clinks = v[5];
}

hr_status hr_dist_agree(const hr_solver *s, hr_status st, hr_err *err) {
  if (!s->dist) return st;
  int64_t bad = st != HR_OK;
  hr_dist_max_i64(s->dist, &bad, 1);
  if (bad && st == HR_OK)
    return hr_err_set(err, HR_ERR_REMOTE, "stopped: another rank failed");
  return st;
}

/* Every local element's owner from the owner function (after it changed). */

int hr_solver_clustered(const hr_solver *s) {
  return hr_cluster_wanted(&s->opt, s->scene->nsurfs);
}

hr_status hr_solver_set_dist(hr_solver *s, hr_dist *d, const int32_t *owner, uint64_t scatter,
                             hr_err *err) {
  if (s->started) return hr_err_set(err, HR_ERR_INVALID, "hr_solver_set_dist: solver has run");
  const int P = hr_dist_size(d), n = s->scene->nsurfs;
  if (!d || P == 1) return HR_OK; /* one process: nothing to spread */
  if (owner)
    for (int i = 0; i < n; i++)
      if (owner[i] < 0 || owner[i] >= P)
        return hr_err_set(err, HR_ERR_INVALID, "surface %d: owner %d is not a rank (0..%d)", i,
                          owner[i], P - 1);
  s->rootown = malloc((size_t)n * sizeof *s->rootown);
  if (!s->rootown) return hr_err_set(err, HR_ERR_NOMEM, "out of memory");
  s->rank = hr_dist_rank(d);
  s->nranks = P;
  s->own_seed = scatter;
  s->own_given = owner != NULL;
  if (owner) {
    memcpy(s->rootown, owner, (size_t)n * sizeof *owner);
  } else {
    /* by area, largest first (ties by index), each to the rank with the least so far: the
     * work of a surface's tree grows with its area over A_e */
    double *area = malloc((size_t)n * sizeof *area);
    int ok = area != NULL;
    for (int i = 0; ok && i < n; i++) area[i] = s->scene->surfs[i].area;
    ok = ok && hr_partition_greedy(area, n, P, s->rootown);
    free(area);
    if (!ok) return hr_err_set(err, HR_ERR_NOMEM, "out of memory");
  }
  s->dist = d;
  hr_owners_recompute(s);
  const char *tm = getenv("HRAD_TEST_MIGRATE");
  if (tm) s->migrate_seed = strtoull(tm, NULL, 10);
  const char *tf = getenv("HRAD_TEST_FAIL");
  if (tf) {
    static const char *const names[] = {"", "init", "refine", "push-pull", "cluster"};
    char ph[16] = "";
    if (sscanf(tf, "%d:%15[a-z-]:%d", &s->fail_rank, ph, &s->fail_iter) >= 2)
      for (int k = 1; k < 5; k++)
        if (!strcmp(ph, names[k])) s->fail_phase = k;
  }
  return HR_OK;
}

/* The guard against a wrong answer: every leaf's radiosity must be finite and at most
 * HR_BOUND_SLACK times the physical bound E_max / (1 - rho_max) (no scene, open or closed, can
 * exceed it; the slack leaves room for the discretisation). A solution that breaks it is an
 * error, never a result. */
static hr_status check_physical(const hr_solver *s, hr_err *err) {
  const hr_scene *sc = s->scene;
  const double bound = HR_BOUND_SLACK * s->bphys;
  for (int64_t e = 0; e < s->nel; e++) {
    if (s->el[e].child >= 0 || !hr_owns(s, e)) continue;
    for (int c = 0; c < 3; c++) {
      const double b = s->B[e][c];
      if (isfinite(b) && b <= bound && b >= 0) continue;
      const hr_surface *f = &sc->surfs[s->el[e].surf];
      return hr_err_set(err, HR_ERR_UNPHYSICAL,
                        "the solution is not physical after %d iterations: radiosity %g on a "
                        "polygon of material '%s' (input polygon %d), where at most %g (E/(1-rho)) "
                        "is possible; please report this scene",
                        s->iterations + 1, b, sc->mats[f->material].name,
                        hr_scene_poly_input(sc, f->poly), s->bphys);
    }
  }
  return HR_OK;
}

/* The guard against a solve that cannot end: the iteration contracts by the spectral radius of
 * rho F, which is below 1 only while the scene absorbs some light. In a closed scene whose
 * materials reflect everything (exports that write Kd 1 1 1) it is 1, and the discretisation
 * error of the form factors (row sums of a closed box about 0.8% above 1) can take it above 1: B
 * then grows without bound (a white box reached 2e4 times its emission after 1000 iterations).
 * The contraction is measured over windows of STALL_N iterations without new links, q = (change
 * at the end / change at the start)^(1 / STALL_N): a whole number of extrapolation periods, so
 * that both ends sit at the same phase of its jumps (step by step, each jump and the drop after
 * it broke any run of slow steps, and a white box at one level of BF_e, q = 0.995, ran its 1000
 * iterations to a result several times too bright, exit 0). An error naming the most reflective
 * material when q >= STALL_Q (converging would take more than 1e4 iterations), or at BF_low when
 * q >= SLOW_Q (the scene absorbs less than 1%) and strict convergence (advance) would need more
 * iterations than --max-iters leaves. */
/* Whether the current BF_e is the last level's, BF_low (within rounding of the schedule). */
static int at_bf_low(const hr_solver *s) { return s->bf_e <= s->opt.bf_low * (1 + 1e-12); }

#define STALL_Q 0.9995
#define SLOW_Q 0.99
#define STALL_N (10 * HR_XPERIOD)
static hr_status check_contracting(hr_solver *s, double abs, int64_t nnew, hr_err *err) {
  if (nnew > 0) { /* the window begins after the next iteration: this one's step has the new
                     links in it */
    s->stall = -1;
    return HR_OK;
  }
  if (s->stall < 0 || !(s->stall_abs > 0)) {
    s->stall = 0, s->stall_abs = abs;
    return HR_OK;
  }
  if (++s->stall < STALL_N) return HR_OK;
  const double q = pow(abs / s->stall_abs, 1.0 / STALL_N), change = abs / s->unit;
  s->stall = 0, s->stall_abs = abs;
  const int at_low = at_bf_low(s);
  /* iterations until change q / (1 - q) < b_eps at this rate (advance's strict test) */
  const double need = q < 1 && change * q / (1 - q) >= s->b_eps
                          ? log(s->b_eps * (1 - q) / (change * q)) / log(q)
                          : 0;
  const double left = (double)s->opt.max_iters - s->iterations - 1;
  const int slow = at_low && q >= SLOW_Q && need > left;
  if (q < STALL_Q && !slow) return HR_OK;
  const hr_scene *sc = s->scene;
  int mw = 0;
  double rw = -1;
  for (int m = 0; m < sc->nmats; m++)
    for (int c = 0; c < 3; c++)
      if (sc->mats[m].rho[c] > rw) rw = sc->mats[m].rho[c], mw = m;
  char within[96] = "";
  if (q < STALL_Q)
    snprintf(within, sizeof within, " within --max-iters %d (about %.0f more iterations needed)",
             s->opt.max_iters, need);
  return hr_err_set(err, HR_ERR_UNPHYSICAL,
                    "the solution does not converge%s: the scene keeps nearly all its light "
                    "(over iterations %d to %d the largest change of radiosity went by a factor "
                    "of %.6f an iteration); its most reflective material is '%s' (reflectance %g): "
                    "lower the reflectances (real surfaces reflect at most about 0.9)",
                    within, s->iterations + 2 - STALL_N, s->iterations + 1, q,
                    sc->mats[mw].name, rw);
}

/* The radiosity unit (see solver_impl.h): the area-weighted mean radiosity of the surfaces,
 * largest channel, at least the mean emitted radiosity. */
static void update_unit(hr_solver *s) {
  const hr_scene *sc = s->scene;
  double m[3] = {0, 0, 0};
  for (int i = 0; i < sc->nsurfs; i++)
    for (int c = 0; c < 3; c++) m[c] += s->el[i].area * s->B[i][c];
  double x = m[0] > m[1] ? m[0] : m[1];
  x = x > m[2] ? x : m[2];
  x /= s->area_total;
  double e = emitted_mean(sc, s->area_total);
  s->unit = x > e ? x : e;
}


/* Seconds this rank spent inside MPI so far (0 in one process). */
static double mpi_secs(const hr_solver *s) {
  int64_t c, b;
  double t;
  hr_dist_counters(s->dist, &c, &b, &t);
  return t;
}


/* Builds what the iterations need that a checkpoint does not hold: the physical bound, the ray
 * caster, the shaft hierarchy and the open fractions of the surfaces. */
static hr_status prepare(hr_solver *s, hr_err *err) {
  hr_status st;
  double emax = 0, rmax = 0;
  for (int m = 0; m < s->scene->nmats; m++)
    for (int c = 0; c < 3; c++) {
      emax = fmax(emax, s->scene->mats[m].emit[c]);
      rmax = fmax(rmax, s->scene->mats[m].rho[c]);
    }
  s->bphys = rmax < 1 ? emax / (1 - rmax) : INFINITY;
  if (!s->vis && (st = hr_vis_create(s->scene, &s->vis, err)) != HR_OK) return st;
  if (!s->shaft && (st = hr_shaft_index_create(s->scene, &s->shaft)) != HR_OK)
    return hr_err_set(err, st, "cannot build the shaft-culling hierarchy");
  s->vf.vis = s->vis;
  return hr_cluster_prepare(s, err);
}

/* The extrapolation window (pushpull.c) after this iteration's refinement made 'nnew' links
 * over all ranks: the same on every rank, and saved in a checkpoint. */
static void set_window(hr_solver *s, int64_t nnew) {
  s->xprev = s->xlast;
  s->xlast = 0;
  if (nnew > 0) s->xwin = 0;
  s->xwin++;
  const int ph = s->xwin % HR_XPERIOD;
  s->xmode = !s->opt.extrapolate     ? HR_X_NONE
             : ph == HR_XPERIOD - 4 ? HR_X_SAMPLE0
             : ph == HR_XPERIOD - 2 ? HR_X_SAMPLE1
             : ph == 0              ? HR_X_APPLY
                                    : HR_X_NONE;
}

/* One iteration of Figure 3 at s->bf_e ({7..15}): refinement (not in the first iteration, which
 * only gathers through the initial links: the oracle measures errors against the light each
 * element would get, bref, which needs one gather), gather, push-pull and the physical guard.
 * Returns the largest change of B relative to the radiosity unit and the new links. */
static hr_status iterate(hr_solver *s, double *change, int64_t *nnew, hr_err *err) {
  hr_status st;
  double ta = hr_now(), ma = mpi_secs(s);
  *nnew = 0;
  s->refined = s->iterations > 0 && s->lazy == HR_REFINE_EVERY;
  if (s->refined && (st = hr_link_refine(s, s->bf_e, nnew, err)) != HR_OK) return st;
  if (s->refined && (st = hr_cluster_refine(s, s->bf_e, nnew, err)) != HR_OK) return st;
  st = hr_link_sort(s);
  if ((st = hr_dist_agree(s, st == HR_OK ? st : hr_err_set(err, st, "out of memory"), err)))
    return st;
  hr_dist_sum_i64(s->dist, nnew, 1);
  set_window(s, *nnew);
  double tb = hr_now(), mb = mpi_secs(s);
  gather(s);
  hr_cluster_gather(s);
  double tc = hr_now(), mc = mpi_secs(s), abs = 0;
  if ((st = hr_push_pull(s, &abs, err)) != HR_OK) return st;
  hr_cluster_pull(s);
  s->xlast = s->xmode == HR_X_APPLY;
  s->xmode = HR_X_NONE;
  hr_solver_sync_counts(s);
  *change = abs / s->unit;
  if ((st = hr_dist_agree(s, check_physical(s, err), err)) != HR_OK) return st;
  if ((st = check_contracting(s, abs, *nnew, err)) != HR_OK) return st;
  update_unit(s);
  double td = hr_now();
  s->iter_busy = (td - ta) - (mpi_secs(s) - ma);
  s->iter_wall = td - ta;
  s->mpi_t[1] += mb - ma, s->mpi_t[2] += mc - mb, s->mpi_t[3] += mpi_secs(s) - mc;
  s->t.refine += tb - ta;
  s->t.gather += tc - tb;
  s->t.push_pull += td - tc;
  s->iterations++;
  return HR_OK;
}

/* Refinement turns lazy after a sweep that made at most 1 / LAZY_DIV of the links, and has
 * settled after one that made at most 1 / SETTLE_DIV of them (none below SETTLE_DIV links). */
#define LAZY_DIV 1e3
#define SETTLE_DIV 1e4

/* The convergence tests after an iteration at s->bf_e ({16}, {17}, {18}): moves s->bf_e to the
 * next level when this one is done, or sets s->done (and s->converged at BF_low). */
static void advance(hr_solver *s, double change, int64_t nnew, int stop) {
  const hr_options *o = &s->opt;
  const int at_low = at_bf_low(s);
  /* Strict convergence ({16}, and {18} at BF_low): B settled and no link refined. At BF_low,
   * "settled" means the error left, not the last step: the iteration contracts by about
   * q = change / previous change, so the remaining error is about change q / (1 - q), which
   * is far larger than the last step when little light is absorbed (q near 1: white rooms).
   * Stopping on the step alone left a closed box of rho = 1 walls 5% dark. */
  const double links = (double)(s->g_links + s->g_clinks);
  /* "No link refined" (see lazy refinement below): a few links in a large graph flip with each
   * last digit of B. An iteration that did not refine made none. */
  const int settled = (double)nnew * SETTLE_DIV <= links;
  /* The step after an extrapolation measures how far it jumped, not the contraction: nothing
   * converges on it, and it is the ratio's base for the next one. */
  int strict = change < s->b_eps && settled && !s->xprev;
  if (at_low) {
    const double prev = s->prev_change;
    s->prev_change = settled ? change : 0;
    if (strict && change > 0) {
      const double q = prev > 0 ? change / prev : 1;
      strict = q < 1 && change * q / (1 - q) < s->b_eps;
    }
  }
  int level_done = strict;
  if (o->relax && !at_low) {
    /* Section 2.2.4: at an intermediate level, a change below B_max counts as approximately
     * converged once the links settle, or at once while many new links still appear (the next,
     * lower BF_e will refine them anyway). */
    int many = (double)nnew * 100.0 >= (double)o->relax_links * (double)s->g_links;
    level_done = change < o->b_max && (settled || many) && !s->xprev;
  }
  /* Lazy refinement. Once a sweep makes few links, the iterations only
   * gather until B has converged for this level, and then one sweep checks the links again.
   * Once a sweep makes almost none (settled), the level ends when B converges, without another
   * sweep. Refining at every iteration was 20 of the conference room's 150 s: its 29 M links
   * gained a few hundred to a few at each of its last twenty sweeps, as B settled, and each
   * sweep's new links moved some small element's B by more than B_eps. */
  if (s->refined) {
    s->lazy = settled                            ? HR_REFINE_SETTLED
              : (double)nnew * LAZY_DIV <= links ? HR_REFINE_LAZY
                                                 : HR_REFINE_EVERY;
  } else if (level_done && s->lazy == HR_REFINE_LAZY) {
    s->lazy = HR_REFINE_EVERY, level_done = 0;
  }
  if (level_done && at_low) { /* at BF_low only strict convergence ends a level */
    s->converged = 1;
    s->done = 1;
    return;
  }
  if (level_done) {
    /* The next level; a last step shorter than half a level goes straight to BF_low. */
    s->bf_e = s->bf_e / o->bf_factor;
    if (s->bf_e < o->bf_low * sqrt(o->bf_factor)) s->bf_e = o->bf_low;
    s->lazy = HR_REFINE_EVERY;
  }
  /* Stopped early: s->bf_e is already the next iteration's, so a run resumed with a larger
   * max_iters goes on exactly as an uninterrupted one. */
  if (stop || s->iterations >= o->max_iters) s->done = 1;
}

static hr_status test_migrate(hr_solver *s, hr_err *err);

/* Iterations between two balancings at least (the first iterations after one show its effect),
 * and the growth of the link count since the last one that makes another worth its cost; it
 * grows fourfold with every balancing that kept the partition (found nothing better: measured
 * on museum at 2 ranks, 6 of 7 balancings kept it, at 1-2.4 s each to gather and partition
 * 1-4 M links), up to 5 x 4^3 = 320%. */
#define BALANCE_GAP 3
#define BALANCE_GROWTH 0.05
#define BALANCE_GROWTH_STEPS 3
/* Balancing's budget: at most this share of the run so far, counting the balancing it would start,
 * predicted as the last one's time times the square root of the links' growth since: a balancing's
 * cost grows more slowly than the links, the pieces being capped (measured at 2 ranks: floor 7.7
 * ms at 4.5 k links, 19 ms at 347 k; museum 0.34 s at 0.5 M, 0.24 s at 2.1 M, without a
 * migration). A rank's share of the run falls as 1 / P, a balancing's cost does not: at 64 ranks
 * one balancing of floor's graph is 20 ms against a modelled run of 0.15 s (BENCHMARKS.md, "Graph
 * balancing, sixth pass"). The paper spent 60 of 144 s annealing on 64 nodes. */
#define BALANCE_BUDGET 0.1

/* The paper's trigger (2.2.5): balance when the last iteration's idle time, 1 - mean / max of
 * the ranks' busy seconds, exceeds the threshold, and the graph grew since the last balancing
 * (measured: on a busy machine idle time alone fired 10 times in a 46-iteration room run, 7 of
 * them finding nothing better to move to), and the time that idleness would lose over the
 * iterations left is more than the last balancing took (museum at 2 ranks: 2-3 s a balancing,
 * 5-7 of them a run without this), and the budget allows it. A collective in distributed
 * runs. */
static hr_status maybe_balance(hr_solver *s, hr_err *err) {
  if (!s->dist || s->bal_method == HR_BALANCE_NONE) return HR_OK;
  double v[6] = {s->iter_busy, s->iter_wall * hr_solver_iters_left(s), s->t_bal_last,
                 s->t.balance, hr_now() - s->t_start, s->iter_busy};
  hr_dist_max_f64(s->dist, v, 5);
  hr_dist_sum_f64(s->dist, v + 5, 1);
  const double idle = v[0] > 0 ? 1 - v[5] / s->nranks / v[0] : 0;
  if (s->bal_idle > 0) { /* 0: whatever it costs */
    const double grew = s->bal_links > 0 ? (double)s->g_links / (double)s->bal_links : 1;
    const double next = v[2] * sqrt(fmax(grew, 1)); /* the next one's time, predicted */
    if (idle * v[1] <= v[2] || v[3] + next > BALANCE_BUDGET * v[4]) return HR_OK;
  }
  /* the graph changes only by refinement: the same graph would give the same partition */
  const int kept = s->nbalance - s->nmoved;
  const double growth =
      ldexp(BALANCE_GROWTH, 2 * (kept < BALANCE_GROWTH_STEPS ? kept : BALANCE_GROWTH_STEPS));
  const int grown = (double)s->g_links > (1 + growth) * (double)s->bal_links;
  if (idle <= s->bal_idle || s->iterations - s->bal_last < BALANCE_GAP || !grown) return HR_OK;
  s->bal_last = s->iterations;
  s->bal_links = s->g_links;
  return hr_solver_balance(s, s->bal_method, err);
}

hr_status hr_solver_set_balance(hr_solver *s, int method, double alpha, double idle,
                                hr_err *err) {
  if (method < HR_BALANCE_NONE || method > HR_BALANCE_ORB)
    return hr_err_set(err, HR_ERR_INVALID, "unknown balancing method %d", method);
  if (!(alpha >= 0 && alpha <= 1) || !(idle >= 0 && idle <= 1))
    return hr_err_set(err, HR_ERR_INVALID, "balancing: alpha and idle must be in [0, 1]");
  s->bal_method = method;
  s->bal_alpha = alpha;
  s->bal_idle = idle;
  return HR_OK;
}

/* Progress of the convergence at BF_low, after an iteration (advance not yet run) that changed
 * B by at most 'change': how far the change has fallen from the first one at BF_low toward b_eps,
 * on a log scale (the iteration contracts the error by a factor, so equal steps on it are about
 * equal numbers of iterations), at most 0.99 until the run ends, never decreasing. Without it a
 * run of one level (the defaults) reported 0% until its end. */
static void track_convergence(hr_solver *s, double change) {
  if (!at_bf_low(s) || !(change > 0)) return;
  if (!(s->conv_first > 0)) s->conv_first = change;
  const double span = log(s->conv_first / s->b_eps);
  const double f = span > 0 ? log(s->conv_first / change) / span : 1;
  s->conv_done = fmax(s->conv_done, fmin(f, 0.99));
}

/* The share of the multigrid schedule done: the levels of BF_e passed from bf_start down to
 * bf_low, plus 'conv' (the share of the convergence at BF_low, counted as one more level) once
 * at BF_low, over their number plus one; 1 when the run is done. For HR_PHASE_SOLVE
 * (schedule_done, never decreasing) it is not a share of the time: refinement makes most
 * links in the first iterations of a level. */
static double schedule_share(const hr_solver *s, double conv) {
  if (s->done) return 1;
  const hr_options *o = &s->opt;
  double lf = log(o->bf_factor), total = log(o->bf_start / o->bf_low) / lf + 1;
  double passed = log(o->bf_start / s->bf_e) / lf + (at_bf_low(s) ? conv : 0);
  return total > 0 ? fmin(fmax(passed / total, 0), 1) : 0;
}

static double schedule_done(const hr_solver *s) { return schedule_share(s, s->conv_done); }

double hr_solver_iters_left(const hr_solver *s) {
  /* the schedule's share alone errs long in the first level of BF_e, which iterates to
   * convergence (museum: 19 -> 399 left over its first 21 iterations): no more than done */
  const double f = fmax(schedule_share(s, 0), 0.05);
  return fmin(s->iterations * (1 - f) / f, s->iterations);
}

hr_status hr_solver_run(hr_solver *s, hr_iter_fn cb, void *ud, hr_err *err) {
  hr_status st;
  /* threads: every parallel loop says num_threads(s->threads); the process-wide OpenMP
   * setting is the program's to choose, not the library's */
  s->t_start = hr_now() - s->t.total; /* a resumed run goes on counting */
  if ((st = prepare(s, err)) != HR_OK) return st;
  if (!s->started) {
    const double t0 = hr_now(), m0 = mpi_secs(s);
    hr_elem_open(s, 0, s->nel);
    if ((st = hr_link_init(s, err)) != HR_OK) return st;
    if ((st = hr_link_subscribe(s, err)) != HR_OK) return st;
    if ((st = hr_solver_balance(s, s->bal_method, err)) != HR_OK) return st;
    hr_solver_sync_counts(s);
    s->bal_last = 0;
    s->bal_links = s->g_links;
    s->t.init_graph = hr_now() - t0;
    s->mpi_t[0] = mpi_secs(s) - m0;
    s->bf_e = s->opt.bf_start;
    s->lazy = HR_REFINE_EVERY; /* (gathering to convergence before the first sweep left the
                                  white box of test_solver 3.5e-3 off, not 1.7e-4) */
    s->converged = 0;
    s->started = 1;
  }
  double t_report = -1; /* the last HR_PHASE_SOLVE report */
  while (!s->done) {
    const double bf_e = s->bf_e;
    double change = 0;
    int64_t nnew = 0;
    if ((st = iterate(s, &change, &nnew, err)) != HR_OK) return st;
    track_convergence(s, change);
    advance(s, change, nnew, 0);
    if (s->migrate_seed && !s->done && (st = test_migrate(s, err)) != HR_OK) return st;
    if (!s->done && (st = maybe_balance(s, err)) != HR_OK) return st;
    s->t.total = hr_now() - s->t_start;
    if (s->done || s->t.total - t_report >= 0.1) {
      t_report = s->t.total;
      hr_solver_progress_report(s, HR_PHASE_SOLVE, schedule_done(s));
    }
    /* Display ({15}) and checkpoints: the state is complete here, and s->bf_e is already the
     * next iteration's. */
    if (cb) {
      hr_iter_info info = {s->iterations, bf_e, s->dist ? s->g_leaves : count_leaves(s),
                           s->dist ? s->g_links + s->g_clinks
                                   : s->nlinks - s->ndead + hr_cluster_links(s),
                           change, s->t.total};
      int64_t stop = cb(ud, s, &info) != 0;
      hr_dist_max_i64(s->dist, &stop, 1); /* every rank stops after the same iteration */
      if (stop && !s->done) {
        s->done = 1;
        s->stopped = 1;
      }
    }
  }
  s->t.total = hr_now() - s->t_start;
  return HR_OK;
}

void hr_solver_stats(const hr_solver *s, hr_stats *st) {
  memset(st, 0, sizeof *st);
  st->nsurfaces = s->scene->nsurfs;
  st->npolys = s->scene->npolys;
  st->elements = s->dist ? s->g_leaves : count_leaves(s);
  st->elements_all = s->dist ? s->g_nel : s->nel;
  st->links = s->dist ? s->g_links + s->g_clinks : s->nlinks - s->ndead + hr_cluster_links(s);
  st->clusters = hr_cluster_count(s);
  st->cluster_links = s->dist ? s->g_clinks : hr_cluster_links(s);
  st->initial_links = s->dist ? s->g_initial : s->initial_links;
  st->iterations = s->iterations;
  st->rays = s->dist ? s->g_rays : s->rays;
  st->converged = s->converged;
  st->threads = s->threads;
  struct rusage ru;
  if (getrusage(RUSAGE_SELF, &ru) == 0) st->peak_rss_mb = (double)ru.ru_maxrss / 1024.0;
  st->time_s = s->t;
  static const char *const method[] = {"", "anneal", "metis", "orb"};
  st->ranks = s->dist ? s->nranks : 1;
  st->balance = !s->dist                           ? ""
                : s->bal_method != HR_BALANCE_NONE ? method[s->bal_method]
                : s->own_seed                      ? "random"
                : s->own_given                     ? "given"
                                                   : "area";
  st->balancings = s->nbalance, st->migrations = s->nmoved;
}

static int cmp_omap(const void *a, const void *b) {
  const uint64_t *x = a, *y = b;
  return x[0] < y[0] ? -1 : x[0] > y[0];
}

hr_status hr_solver_migrate(hr_solver *s, const uint64_t *gids, const int32_t *ranks, int64_t n,
                            hr_err *err) {
  if (!s->dist) return hr_err_set(err, HR_ERR_INVALID, "hr_solver_migrate: not distributed");
  int bad = n < 0;
  const uint64_t top = HR_CLUSTER_GID;
  for (int64_t i = 0; i < n && !bad; i++) {
    if (gids[i] & top) {
      bad = ranks[i] < 0 || ranks[i] >= s->nranks;
      continue;
    }
    const uint64_t surf = gids[i] >> HR_GID_PATH_BITS;
    bad = ranks[i] < 0 || ranks[i] >= s->nranks || surf >= (uint64_t)s->scene->nsurfs ||
          (gids[i] & ((UINT64_C(1) << HR_GID_PATH_BITS) - 1)) == 0;
  }
  bad = bad || !hr_cluster_set_owners(s, gids, ranks, n);
  if (hr_dist_any(s->dist, bad))
    return hr_err_set(err, HR_ERR_INVALID, "hr_solver_migrate: a bad element id or rank");
  uint64_t(*m)[2] = malloc((size_t)(n > 0 ? n : 1) * sizeof *m);
  hr_status st = hr_dist_agree(s, m ? HR_OK : hr_err_set(err, HR_ERR_NOMEM, "out of memory"),
                               err);
  if (st != HR_OK) {
    free(m);
    return st;
  }
  int64_t ne = 0; /* the elements' entries */
  for (int64_t i = 0; i < n; i++)
    if (!(gids[i] & top)) m[ne][0] = gids[i], m[ne++][1] = (uint64_t)ranks[i];
  n = ne;
  qsort(m, (size_t)n, sizeof *m, cmp_omap);
  free(s->omap);
  s->omap = m;
  s->nomap = n;
  s->own_seed = 0;
  return hr_link_migrate(s, err);
}

/* The test hook HRAD_TEST_MIGRATE=SEED: after every iteration, every element to a rank drawn
 * from (SEED, the iteration, its gid). */
static hr_status test_migrate(hr_solver *s, hr_err *err) {
  uint64_t z = s->migrate_seed + (uint64_t)s->iterations * UINT64_C(0x632be59bd9b4e019);
  s->own_seed = z ? z : 1;
  return hr_link_migrate(s, err);
}

hr_status hr_solver_rank_stats(const hr_solver *s, hr_rank_stats *all, hr_err *err) {
  hr_rank_stats me;
  memset(&me, 0, sizeof me);
  me.rank = s->rank;
  for (int i = 0; i < s->scene->nsurfs; i++) me.surfaces += hr_owns(s, i);
  me.links = s->nlinks - s->ndead + hr_cluster_links(s);
  me.leaves = count_leaves(s);
  me.elements = count_own(s);
  me.ghosts = s->nel - me.elements;
  /* what the elements and links take in use (allocations round up to powers of 2): their
   * records, the per-element arrays and map, the candidate pool and the link index */
  const double per_el = sizeof(hr_elem) + 15 * sizeof(double) + 2 * sizeof(int32_t) + 1 +
                        2 * (sizeof(uint64_t) + sizeof(int32_t));
  me.elem_mb = (double)s->nel * per_el / 1e6;
  me.link_mb = ((double)s->nlinks * sizeof(hr_link) + (double)s->npool * 4 +
                (double)s->nrstart * 16 + (double)s->nsorted * 8 +
                (double)hr_cluster_links(s) * (double)hr_cluster_link_bytes(s)) / 1e6;
  hr_dist_msg_counters(s->dist, &me.msgs, &me.msg_bytes);
  me.balancings = s->nbalance, me.migrations = s->nmoved, me.cluster_moves = s->ncmoved;
  me.rays = s->rays;
  hr_dist_counters(s->dist, &me.mpi_calls, &me.mpi_bytes, &me.mpi_s);
  me.busy_s = s->t.total - me.mpi_s;
  const double ph[4] = {s->t.init_graph, s->t.refine, s->t.gather, s->t.push_pull};
  for (int k = 0; k < 4; k++) me.phase_mpi[k] = s->mpi_t[k], me.phase_busy[k] = ph[k] - s->mpi_t[k];
  struct rusage ru;
  if (getrusage(RUSAGE_SELF, &ru) == 0) me.peak_rss_mb = (double)ru.ru_maxrss / 1024.0;
  if (hr_dist_gather(s->dist, &me, sizeof me, all) != HR_OK)
    return hr_err_set(err, HR_ERR_TOO_BIG, "too many ranks");
  return HR_OK;
}

void hr_solver_poly_radiosity(const hr_solver *s, int poly, double rgb[3]) {
  const hr_scene *sc = s->scene;
  double acc[3] = {0, 0, 0}, area = 0;
  /* its surfaces only (a scan of all of them per polygon took the conference room 5 s) */
  for (int i = hr_scene_poly_first(sc, poly); i < sc->nsurfs && sc->surfs[i].poly == poly; i++) {
    double a = s->el[i].area;
    area += a;
    for (int c = 0; c < 3; c++) acc[c] += a * s->B[i][c];
  }
  for (int c = 0; c < 3; c++) rgb[c] = area > 0 ? acc[c] / area : 0;
}

/* A leaf with its gid, for the canonical order. */
typedef struct gid_leaf {
  uint64_t gid;
  hr_leaf l;
} gid_leaf;

static int cmp_gid_leaf(const void *a, const void *b) {
  const gid_leaf *x = a, *y = b;
  return x->gid < y->gid ? -1 : x->gid > y->gid;
}

/* The open fraction that element e's sent radiosity Bs rests on (pushpull.c, pp_store: the ray
 * test's, as far as the element's links agree), from Bs itself: 1 where nothing is covered. */
static double open_part(const hr_solver *s, int64_t e) {
  const double *E = s->scene->mats[s->scene->surfs[s->el[e].surf].material].emit;
  int c = 0;
  for (int k = 1; k < 3; k++) c = s->Bs[e][k] - E[k] > s->Bs[e][c] - E[c] ? k : c;
  const double num = s->B[e][c] - E[c], den = s->Bs[e][c] - E[c];
  const double op = den > 0 ? num / den : 1;
  return op > 0 && op <= 1 ? op : 1;
}

/* This rank's own leaves with their gids, in gid order: '*out' (malloc'd), '*n'. */
static int own_leaves(const hr_solver *s, gid_leaf **out, int64_t *n) {
  *n = count_leaves(s);
  gid_leaf *L = malloc((size_t)(*n > 0 ? *n : 1) * sizeof *L);
  if (!L) return 0;
  int64_t k = 0;
  for (int64_t e = 0; e < s->nel; e++) {
    const hr_elem *el = &s->el[e];
    if (el->child >= 0 || !hr_owns(s, e)) continue;
    gid_leaf *g = &L[k++];
    memset(g, 0, sizeof *g);
    g->gid = el->gid;
    hr_leaf *l = &g->l;
    l->surf = el->surf;
    l->nverts = s->scene->surfs[el->surf].nverts;
    memcpy(l->lat, el->lat, sizeof l->lat);
    memcpy(l->p, el->p, sizeof l->p);
    l->area = el->area;
    for (int c = 0; c < 3; c++) l->B[c] = s->B[e][c];
    l->open = open_part(s, e);
  }
  qsort(L, (size_t)*n, sizeof *L, cmp_gid_leaf);
  *out = L;
  return 1;
}

hr_status hr_solver_collect(hr_solver *s, hr_err *err) {
  if (!s->dist) return HR_OK;
  gid_leaf *L = NULL;
  int64_t n = 0;
  int64_t *sb = calloc((size_t)s->nranks, sizeof *sb);
  hr_status st = sb && own_leaves(s, &L, &n) ? HR_OK : HR_ERR_NOMEM;
  if ((st = hr_dist_agree(s, st ? hr_err_set(err, st, "out of memory") : st, err)) != HR_OK) {
    free(sb), free(L);
    return st;
  }
  sb[0] = n * (int64_t)sizeof *L;
  void *all = NULL;
  int64_t tot = 0;
  st = hr_dist_alltoall(s->dist, L, sb, &all, &tot);
  free(sb), free(L);
  if (st != HR_OK) return hr_err_set(err, st, "out of memory collecting the leaves");
  free(s->coll);
  s->coll = NULL;
  s->ncoll = 0;
  if (s->rank != 0) {
    free(all);
    return HR_OK;
  }
  gid_leaf *g = all;
  const int64_t m = tot / (int64_t)sizeof *g;
  qsort(g, (size_t)m, sizeof *g, cmp_gid_leaf);
  s->coll = malloc((size_t)(m > 0 ? m : 1) * sizeof *s->coll);
  if (s->coll)
    for (int64_t i = 0; i < m; i++) s->coll[i] = g[i].l;
  free(all);
  if (!s->coll) return hr_err_set(err, HR_ERR_NOMEM, "out of memory collecting the leaves");
  s->ncoll = m;
  return HR_OK;
}

/* Leaves in gid order (the same on any number of ranks): this process's own, or on rank 0 of a
 * distributed run what hr_solver_collect brought. */
hr_status hr_solver_leaves(const hr_solver *s, hr_leaf **leaves, int64_t *nleaves) {
  if (s->dist && s->coll) {
    hr_leaf *L = malloc((size_t)(s->ncoll > 0 ? s->ncoll : 1) * sizeof *L);
    if (!L) return HR_ERR_NOMEM;
    memcpy(L, s->coll, (size_t)s->ncoll * sizeof *L);
    *leaves = L;
    *nleaves = s->ncoll;
    return HR_OK;
  }
  gid_leaf *g;
  int64_t n;
  if (!own_leaves(s, &g, &n)) return HR_ERR_NOMEM;
  hr_leaf *L = malloc((size_t)(n > 0 ? n : 1) * sizeof *L);
  if (L)
    for (int64_t i = 0; i < n; i++) L[i] = g[i].l;
  free(g);
  if (!L) return HR_ERR_NOMEM;
  *leaves = L;
  *nleaves = n;
  return HR_OK;
}

const hr_scene *hr_solver_scene(const hr_solver *s) { return s->scene; }
