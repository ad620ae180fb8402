/* Physical invariants of the whole solver (../shared/REFERENCE-VALUES.md): closed-box furnace
 * B = E / (1 - rho), energy balance sum(B A) = sum(E A) / (1 - rho) with one emitting face,
 * reciprocity A_i F_ij = A_j F_ji through the whole program, partial occlusion against the exact
 * reference, both inner-loop modes (paper Figure 3 and section 2.2.4), and identical results for
 * 1, 2, 3 and 4 threads and for repeated runs. */
#include "ff_ref.h"
#include "testutil.h"

#include <string.h>

static hr_scene *furnace_box(double rho, double e, int blocker) {
  hr_scene *s;
  hr_scene_create("furnace", &s);
  int m = t_mat(s, "all", rho, e);
  int mats[6] = {m, m, m, m, m, m};
  t_box(s, mats, tv(0, 0, 0), tv(2, 3, 4), 1);
  if (blocker) t_box(s, mats, tv(0.5, 1, 1), tv(1.5, 2, 2.5), 0);
  return s;
}

static void check_all_polys(const hr_solver *sv, const hr_scene *s, double want, double tol,
                            const char *what) {
  double worst = 0;
  for (int p = 0; p < s->npolys; p++) {
    double b[3];
    hr_solver_poly_radiosity(sv, p, b);
    for (int c = 0; c < 3; c++) {
      double e = fabs(b[c] - want) / want;
      worst = e > worst ? e : worst;
    }
  }
  printf("  %-48s worst rel.err %.2e over %d polygons (tol %.0e)\n", what, worst, s->npolys, tol);
  CHECK(worst <= tol, "%s: worst relative error %.3e", what, worst);
}

static void furnace(void) {
  printf("furnace: closed box, E=1, rho=0.5 -> B=2\n");
  for (int blocker = 0; blocker < 2; blocker++) {
    hr_scene *s = furnace_box(0.5, 1, blocker);
    hr_solver *sv = t_solve(s, NULL);
    /* Inner box: 2%. Eq. (2) sums a receiver's form factors about 1% short at the default BF_low
     * (near-field links at the A_e limit; see docs/design.md); the box adds elements that
     * straddle another surface's plane. The error shrinks with BF_low (test_ff). */
    check_all_polys(sv, s, 2.0, blocker ? 0.02 : 0.01,
                    blocker ? "box with an inner box (2%)" : "empty box");
    hr_solver_destroy(&sv);
    hr_scene_destroy(&s);
  }
  /* White walls: rho 0.95 -> B = 20. Each bounce absorbs only 5%, so the iteration contracts
   * slowly (q = 0.95) and a run that stopped when one step fell below B_eps would be about
   * 20 steps short; the test at BF_low estimates the error left (see advance in solve.c). B_eps
   * 1e-4, a tenth of the default (BF_low), so that stopping on the step would fail the test. */
  {
    hr_scene *w = furnace_box(0.95, 1, 0);
    hr_options o;
    hr_options_default(&o);
    o.extrapolate = 0;
    o.b_eps = 1e-4;
    hr_solver *sw = t_solve(w, &o);
    check_all_polys(sw, w, 20.0, 5e-4, "white box, rho 0.95 (5e-4; 1.6e-3 stopping on the step)");
    hr_stats plain;
    hr_solver_stats(sw, &plain);
    hr_solver_destroy(&sw);
    /* Aitken extrapolation (pushpull.c) reaches the same answer in fewer iterations (12 of 179
     * measured; 15 while jumps above the physical bound were kept). */
    sw = t_solve(w, NULL);
    check_all_polys(sw, w, 20.0, 5e-4, "white box, extrapolated (5e-4)");
    hr_stats ex;
    hr_solver_stats(sw, &ex);
    printf("  white box: %d iterations plain, %d extrapolated\n", plain.iterations, ex.iterations);
    CHECK(ex.converged && ex.iterations * 4 < plain.iterations * 3,
          "extrapolation: %d iterations, plain %d: not a quarter fewer", ex.iterations,
          plain.iterations);
    hr_solver_destroy(&sw);
    hr_scene_destroy(&w);
  }
  /* A closed tetrahedron of triangles (acute edges), faces inward, rho 0.5: B = 2. */
  hr_scene *s;
  hr_scene_create("tet", &s);
  int m = t_mat(s, "all", 0.5, 1);
  hr_vec3 P[4] = {tv(0, 0, 0), tv(2, 0, 0), tv(0, 2, 0), tv(0, 0, 2)};
  int F[4][3] = {{0, 1, 2}, {0, 3, 1}, {0, 2, 3}, {1, 3, 2}}; /* facing inward */
  for (int k = 0; k < 4; k++) {
    hr_vec3 v[3] = {P[F[k][0]], P[F[k][1]], P[F[k][2]]};
    t_poly(s, m, 3, v);
  }
  hr_solver *sv = t_solve(s, NULL);
  check_all_polys(sv, s, 2.0, 0.02, "tetrahedron (2%: acute edges)");
  hr_solver_destroy(&sv);
  hr_scene_destroy(&s);
}

static void energy_balance(void) {
  printf("energy balance: closed box, rho=0.5, ceiling emits\n");
  hr_scene *s;
  hr_scene_create("balance", &s);
  int w = t_mat(s, "wall", 0.5, 0), l = t_mat(s, "light", 0.5, 10);
  int mats[6] = {w, w, w, l, w, w};
  t_box(s, mats, tv(0, 0, 0), tv(3, 2, 4), 1);
  hr_solver *sv = t_solve(s, NULL);
  double pow_b = 0, pow_e = 0;
  for (int p = 0; p < s->npolys; p++) {
    double b[3];
    hr_solver_poly_radiosity(sv, p, b);
    pow_b += b[0] * s->poly_area[p];
  }
  pow_e = 10 * 3 * 4;
  /* 2%: the walls' radiosity is well below the emitter's, so their links stay coarser at the
   * relative BF_low and the eq. (2) row-sum shortfall is larger than in the furnace. */
  CHECK_REL(pow_b, pow_e / (1 - 0.5), 0.02, "sum(B A) = sum(E A)/(1-rho) (2%)");
  hr_solver_destroy(&sv);
  hr_scene_destroy(&s);
}

/* One-bounce form factor from polygon 'rec' to polygon 'em' through the solver. */
static double one_bounce(const hr_vec3 *rec, int nr, const hr_vec3 *em, int ne,
                         const hr_vec3 *blk, int nb) {
  hr_scene *s;
  hr_scene_create("pair", &s);
  int mr = t_mat(s, "receiver", 0.5, 0), me = t_mat(s, "emitter", 0, 1);
  t_poly(s, mr, nr, rec);
  t_poly(s, me, ne, em);
  if (blk) t_poly(s, t_mat(s, "blocker", 0, 0), nb, blk);
  hr_solver *sv = t_solve(s, NULL);
  double b[3];
  hr_solver_poly_radiosity(sv, 0, b);
  hr_solver_destroy(&sv);
  hr_scene_destroy(&s);
  return b[0] / 0.5;
}

static double quad_area(const hr_vec3 *q) {
  hr_vec3 d1 = {q[2].x - q[0].x, q[2].y - q[0].y, q[2].z - q[0].z};
  hr_vec3 d2 = {q[3].x - q[1].x, q[3].y - q[1].y, q[3].z - q[1].z};
  hr_vec3 c = {d1.y * d2.z - d1.z * d2.y, d1.z * d2.x - d1.x * d2.z, d1.x * d2.y - d1.y * d2.x};
  return 0.5 * sqrt(c.x * c.x + c.y * c.y + c.z * c.z);
}

static void reciprocity(void) {
  printf("reciprocity: A_1 F_12 = A_2 F_21 on an unoccluded, unequal pair\n");
  /* Plate 1: 1 x 1 on the floor facing up; plate 2: 2 x 0.5, tilted, facing down-ish. */
  hr_vec3 p1[4] = {tv(0, 0, 0), tv(0, 0, 1), tv(1, 0, 1), tv(1, 0, 0)};
  hr_vec3 p2[4] = {tv(-0.3, 1.0, 0.2), tv(1.7, 1.0, 0.2), tv(1.7, 1.3, 0.6), tv(-0.3, 1.3, 0.6)};
  double a1 = quad_area(p1), a2 = quad_area(p2);
  double f12 = one_bounce(p1, 4, p2, 4, NULL, 0), f21 = one_bounce(p2, 4, p1, 4, NULL, 0);
  double ref12 = hr_ff_ref_poly_poly(p1, 4, p2, 4, 8, 6);
  CHECK_REL(f12, ref12, 0.01, "F_12 against the reference quadrature");
  CHECK_REL(a1 * f12, a2 * f21, 0.01, "A_1 F_12 against A_2 F_21");
}

static void occlusion(void) {
  printf("partial occlusion: a black plate hides half of the emitter\n");
  hr_vec3 rec[4] = {tv(0, 0, 0), tv(0, 0, 1), tv(1, 0, 1), tv(1, 0, 0)};
  hr_vec3 em[4] = {tv(0, 1, 0), tv(1, 1, 0), tv(1, 1, 1), tv(0, 1, 1)};
  /* Blocker just below the emitter's x < 0.5 half (facing down, black). */
  hr_vec3 blk[4] = {tv(-0.2, 0.99, -0.2), tv(0.5, 0.99, -0.2), tv(0.5, 0.99, 1.2),
                    tv(-0.2, 0.99, 1.2)};
  hr_vec3 vis_half[4] = {tv(0.5, 1, 0), tv(1, 1, 0), tv(1, 1, 1), tv(0.5, 1, 1)};
  double f = one_bounce(rec, 4, em, 4, blk, 4);
  /* The gap of 0.01 between blocker and emitter lets a little more through: bound both ways. */
  double ref = hr_ff_ref_poly_poly(rec, 4, vis_half, 4, 8, 6);
  CHECK_REL(f, ref, 0.03, "F to the visible half (3%: sampled visibility)");
  hr_vec3 blk_full[4] = {tv(-0.2, 0.99, -0.2), tv(1.2, 0.99, -0.2), tv(1.2, 0.99, 1.2),
                         tv(-0.2, 0.99, 1.2)};
  double f0 = one_bounce(rec, 4, em, 4, blk_full, 4);
  printf("  fully blocked: F = %.3g\n", f0);
  CHECK(f0 == 0, "fully blocked emitter still gives F = %g", f0);
}

/* A room with a light, a blocker and coloured walls, for invariance tests. */
/* A partly visible link is estimated without bias: a small emitter far above a receiver, half
 * hidden by a black plate. Refinement decides on one set of visibility samples and the form
 * factor rests on another (link.c), so the mean over many seeds matches the exact quadrature. */
static void partly_visible_unbiased(void) {
  printf("partly visible link: the mean over seeds is unbiased\n");
  hr_scene *s;
  hr_scene_create("gap", &s);
  int mr = t_mat(s, "receiver", 0.5, 0), me = t_mat(s, "emitter", 0, 1);
  hr_vec3 rec[4] = {tv(0, 0, 0), tv(0, 0, 1), tv(1, 0, 1), tv(1, 0, 0)};
  hr_vec3 em[4] = {tv(0.45, 6, 0.45), tv(0.55, 6, 0.45), tv(0.55, 6, 0.55), tv(0.45, 6, 0.55)};
  hr_vec3 blk[4] = {tv(0.3, 5.99, 0.3), tv(0.5, 5.99, 0.3), tv(0.5, 5.99, 0.7), tv(0.3, 5.99, 0.7)};
  hr_vec3 vis_half[4] = {tv(0.5, 6, 0.45), tv(0.55, 6, 0.45), tv(0.55, 6, 0.55),
                         tv(0.5, 6, 0.55)};
  t_poly(s, mr, 4, rec);
  t_poly(s, me, 4, em);
  t_poly(s, t_mat(s, "blocker", 0, 0), 4, blk);
  double ref = hr_ff_ref_poly_poly(rec, 4, vis_half, 4, 8, 6);
  hr_options o;
  hr_options_default(&o);
  double mean = 0, sq = 0;
  const int nseed = 256;
  for (int seed = 1; seed <= nseed; seed++) {
    o.seed = (uint64_t)seed;
    hr_solver *sv = t_solve(s, &o);
    double b[3];
    hr_solver_poly_radiosity(sv, 0, b);
    mean += b[0] / 0.5 / nseed;
    sq += (b[0] / 0.5) * (b[0] / 0.5) / nseed;
    hr_solver_destroy(&sv);
  }
  double se = sqrt((sq - mean * mean) / (nseed - 1));
  printf("  F = %.5e +- %.1e over %d seeds, reference %.5e\n", mean, se, nseed, ref);
  /* 4 standard errors of the mean, at most 2% */
  CHECK(fabs(mean - ref) <= 4 * se + 1e-12 && fabs(mean - ref) <= 0.02 * ref,
        "mean F %.5e, reference %.5e, standard error %.1e", mean, ref, se);
  hr_scene_destroy(&s);
}

static hr_scene *room(void) {
  hr_scene *s;
  hr_scene_create("room", &s);
  double wr[3] = {0.7, 0.2, 0.2}, z[3] = {0, 0, 0};
  int red;
  hr_scene_add_material(s, "red", wr, z, &red);
  int w = t_mat(s, "white", 0.7, 0), l = t_mat(s, "light", 0.5, 50), g = t_mat(s, "grey", 0.4, 0);
  int mats[6] = {red, w, w, w, w, w};
  t_box(s, mats, tv(0, 0, 0), tv(4, 3, 5), 1);
  t_quad(s, l, tv(1.5, 2.99, 2), tv(2.5, 2.99, 2), tv(2.5, 2.99, 3), tv(1.5, 2.99, 3));
  int gm[6] = {g, g, g, g, g, g};
  t_box(s, gm, tv(1, 0, 1), tv(2, 1, 2.5), 0);
  hr_vec3 tri[3] = {tv(3, 0.01, 4), tv(3.8, 0.01, 4.2), tv(3.2, 1.5, 4.5)};
  t_poly(s, g, 3, tri);
  return s;
}

typedef struct {
  double *b;
  hr_stats st;
} run_result;

static run_result run_room(int threads, int relax) {
  hr_scene *s = room();
  hr_options o;
  hr_options_default(&o);
  o.threads = threads;
  o.relax = relax;
  hr_solver *sv = t_solve(s, &o);
  run_result r;
  r.b = malloc(sizeof(double) * 3 * (size_t)s->npolys);
  for (int p = 0; p < s->npolys; p++) hr_solver_poly_radiosity(sv, p, r.b + 3 * p);
  hr_solver_stats(sv, &r.st);
  hr_solver_destroy(&sv);
  hr_scene_destroy(&s);
  return r;
}

static void invariance(void) {
  printf("identical results for 1, 2, 3, 4 threads and repeated runs\n");
  hr_scene *s = room();
  int np = s->npolys;
  hr_scene_destroy(&s);
  run_result base = run_room(1, 1);
  printf("  1 thread: %lld elements, %lld links, %d iterations, %lld rays\n",
         (long long)base.st.elements, (long long)base.st.links, base.st.iterations,
         (long long)base.st.rays);
  int threads[] = {2, 3, 4, 1};
  for (int k = 0; k < 4; k++) {
    run_result r = run_room(threads[k], 1);
    int same = memcmp(r.b, base.b, sizeof(double) * 3 * (size_t)np) == 0 &&
               r.st.elements == base.st.elements && r.st.links == base.st.links &&
               r.st.iterations == base.st.iterations && r.st.rays == base.st.rays;
    printf("  %d threads: %s\n", threads[k], same ? "bit-identical" : "DIFFERENT");
    CHECK(same, "%d threads differ from 1 thread", threads[k]);
    free(r.b);
  }
  printf("both inner-loop modes converge to the same answer\n");
  run_result rigid = run_room(0, 0);
  /* The two modes refine along different paths, so they are two discretisations of the same
   * answer: total power must agree closely, single small polygons within the per-polygon
   * discretisation noise (a few percent at the default BF_low; see docs/design.md). */
  hr_scene *rs = room();
  double worst = 0, pw_relax = 0, pw_rigid = 0;
  for (int p = 0; p < np; p++)
    for (int c = 0; c < 3; c++) {
      int i = 3 * p + c;
      double e = fabs(rigid.b[i] - base.b[i]) / (fabs(base.b[i]) + 1e-3);
      worst = e > worst ? e : worst;
      pw_relax += base.b[i] * rs->poly_area[p];
      pw_rigid += rigid.b[i] * rs->poly_area[p];
    }
  hr_scene_destroy(&rs);
  double dpow = fabs(pw_rigid - pw_relax) / pw_relax;
  printf("  relaxed: %d iterations, rigid: %d iterations; total power differs by %.2e, worst "
         "polygon by %.2e\n",
         base.st.iterations, rigid.st.iterations, dpow, worst);
  CHECK(base.st.converged && rigid.st.converged, "a mode did not converge");
  CHECK(dpow < 0.005, "relaxed and rigid total power differ by %.3e", dpow);
  CHECK(worst < 0.05, "relaxed and rigid differ by %.3e on a polygon", worst);
  free(rigid.b);
  free(base.b);
}

int main(void) {
  furnace();
  energy_balance();
  reciprocity();
  occlusion();
  partly_visible_unbiased();
  invariance();
  return t_done("test_solver");
}
