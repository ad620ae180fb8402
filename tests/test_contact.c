/* test_contact.c: cutting surfaces along contact lines (hr_scene_cut_contacts, contact.c).
 *  - a closed pillar in a room's corner, lit inside by the ceiling that runs through it: the
 *    floor and ceiling are cut along its walls, every piece lies wholly inside or outside it,
 *    polygons keep their rows and areas, pieces are marked, cutting again changes nothing;
 *  - a board inside the pillar against the path tracer: the leak through floor elements that
 *    reach under the pillar's walls is gone (63% too bright without the cut, measured);
 *  - the Cornell box: its blocks are closed, so nothing is cut (the open fraction already keeps
 *    the floor under them dark) and the scene is unchanged;
 *  - bad lengths refused. */
#include "testutil.h"

#include <string.h>

/* A 4 x 4 x 2.5 room (ceiling emitting); a pillar over x, z in [0, P] from floor to ceiling,
 * its two walls facing out (the room's walls close it); inside, a board 0.8 x 0.2 at x = P - 0.02
 * facing in. Polygons: 0 floor, 1 ceiling, 2-5 walls, 6-7 the pillar's walls, 8 the board. */
#define P 1.1
static hr_scene *pillar(void) {
  hr_scene *s;
  if (hr_scene_create("pillar", &s) != HR_OK) abort();
  int floor_m = t_mat(s, "floor", 0.6, 0), light = t_mat(s, "light", 0.2, 1);
  int wall = t_mat(s, "wall", 0.5, 0), board = t_mat(s, "board", 0.5, 0);
  const double H = 2.5;
  t_quad(s, floor_m, tv(0, 0, 0), tv(0, 0, 4), tv(4, 0, 4), tv(4, 0, 0));
  t_quad(s, light, tv(0, H, 0), tv(4, H, 0), tv(4, H, 4), tv(0, H, 4));
  t_quad(s, wall, tv(0, 0, 0), tv(4, 0, 0), tv(4, H, 0), tv(0, H, 0));
  t_quad(s, wall, tv(4, 0, 0), tv(4, 0, 4), tv(4, H, 4), tv(4, H, 0));
  t_quad(s, wall, tv(4, 0, 4), tv(0, 0, 4), tv(0, H, 4), tv(4, H, 4));
  t_quad(s, wall, tv(0, 0, 4), tv(0, 0, 0), tv(0, H, 0), tv(0, H, 4));
  t_quad(s, wall, tv(P, 0, 0), tv(P, H, 0), tv(P, H, P), tv(P, 0, P));
  t_quad(s, wall, tv(0, 0, P), tv(P, 0, P), tv(P, H, P), tv(0, H, P));
  t_quad(s, board, tv(P - 0.02, 0, 0.1), tv(P - 0.02, 0, 0.9), tv(P - 0.02, 0.2, 0.9),
         tv(P - 0.02, 0.2, 0.1));
  return s;
}

/* sqrt(A_e) at the default BF_low, as the CLI passes it */
static double default_len(const hr_scene *s) {
  hr_options o;
  hr_options_default(&o);
  return sqrt(o.bf_low * hr_scene_total_area(s));
}

static void geometry(void) {
  hr_scene *s = pillar();
  const int npolys = s->npolys, n0 = s->nsurfs;
  double *area0 = malloc((size_t)npolys * sizeof *area0);
  memcpy(area0, s->poly_area, (size_t)npolys * sizeof *area0);
  hr_cut_stats st;
  CHECK(hr_scene_cut_contacts(s, default_len(s), &st) == HR_OK, "cut");
  printf("pillar: %d surfaces -> %d; %d cut along %d lines into %d pieces\n", n0, s->nsurfs,
         st.surfaces, st.lines, st.pieces);
  /* the floor, the ceiling and the two room walls the pillar stands against; lines counted
   * where a cut ran along them (the second wall of a corner bounds the first's cut) */
  CHECK(st.surfaces == 4 && st.lines == 4, "cut %d surfaces along %d lines", st.surfaces,
        st.lines);
  CHECK(s->npolys == npolys, "polygons %d -> %d", npolys, s->npolys);
  CHECK(s->nsurfs == n0 - st.surfaces + st.pieces, "surface count");
  double *sum = calloc((size_t)npolys, sizeof *sum), inside[6] = {0};
  int pieces = 0, last = -1;
  for (int i = 0; i < s->nsurfs; i++) {
    const hr_surface *f = &s->surfs[i];
    CHECK(f->poly >= last, "surface %d: polygon %d after %d", i, f->poly, last);
    last = f->poly;
    CHECK(f->nverts == 3 || f->nverts == 4, "surface %d: %d vertices", i, f->nverts);
    sum[f->poly] += f->area;
    /* the area from the vertices, and the normal unchanged */
    hr_vec3 c = {0, 0, 0};
    double a = 0;
    for (int k = 1; k + 1 < f->nverts; k++) {
      hr_vec3 e1 = {f->v[k].x - f->v[0].x, f->v[k].y - f->v[0].y, f->v[k].z - f->v[0].z};
      hr_vec3 e2 = {f->v[k + 1].x - f->v[0].x, f->v[k + 1].y - f->v[0].y,
                    f->v[k + 1].z - f->v[0].z};
      hr_vec3 x = {e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z, e1.x * e2.y - e1.y * e2.x};
      a += 0.5 * (x.x * f->normal.x + x.y * f->normal.y + x.z * f->normal.z);
    }
    CHECK(fabs(a - f->area) <= 1e-12 * f->area && a > 0, "surface %d: area %g, vertices %g", i,
          f->area, a);
    if (f->cut) pieces++;
    /* cut: the floor, the ceiling and the walls at z = 0 and x = 0 */
    const int cut = f->poly <= 2 || f->poly == 5;
    CHECK(f->cut == cut, "surface %d of polygon %d: marked %d, want %d", i, f->poly, f->cut, cut);
    if (f->poly > 5) continue;
    /* floor, ceiling and wall pieces: wholly inside the pillar or wholly outside */
    int in = 0, out = 0;
    for (int k = 0; k < f->nverts; k++) {
      c = f->v[k];
      if (c.x < P - 1e-9 && c.z < P - 1e-9) in++;
      if (c.x > P + 1e-9 || c.z > P + 1e-9) out++;
    }
    CHECK(!(in && out), "surface %d of polygon %d reaches across the pillar's wall", i, f->poly);
    if (!out) inside[f->poly] += f->area;
  }
  for (int p = 0; p < npolys; p++)
    CHECK(fabs(sum[p] - area0[p]) <= 1e-12 * area0[p], "polygon %d: area %g -> %g", p, area0[p],
          sum[p]);
  CHECK(fabs(inside[0] - P * P) < 1e-9 && fabs(inside[1] - P * P) < 1e-9,
        "inside the pillar: floor %g, ceiling %g, want %g", inside[0], inside[1], P * P);
  CHECK(fabs(inside[2] - P * 2.5) < 1e-9 && fabs(inside[5] - P * 2.5) < 1e-9,
        "inside the pillar: walls %g and %g, want %g", inside[2], inside[5], P * 2.5);
  CHECK(pieces == st.pieces, "%d surfaces marked as pieces, %d made", pieces, st.pieces);
  /* a second pass finds every contact line on a piece's edge: nothing to cut */
  const int n1 = s->nsurfs;
  CHECK(hr_scene_cut_contacts(s, default_len(s), &st) == HR_OK && st.surfaces == 0 &&
            s->nsurfs == n1,
        "second pass cut %d surfaces", st.surfaces);
  CHECK(hr_scene_cut_contacts(s, 0, &st) == HR_ERR_INVALID, "len 0 accepted");
  CHECK(hr_scene_cut_contacts(s, NAN, &st) == HR_ERR_INVALID, "len NaN accepted");
  CHECK(hr_scene_cut_contacts(s, INFINITY, &st) == HR_ERR_INVALID, "len inf accepted");
  free(sum);
  free(area0);
  hr_scene_destroy(&s);
}

/* The board inside the pillar against the path tracer, with and without the cut. */
static void leak(void) {
  hr_scene *s = pillar(), *c = pillar();
  CHECK(hr_scene_cut_contacts(c, default_len(c), NULL) == HR_OK, "cut");
  hr_options o;
  hr_options_default(&o);
  o.threads = 2;
  hr_solver *a = t_solve(s, &o), *b = t_solve(c, &o);
  double ref[9][3], se[9][3], x[3], y[3];
  hr_pt_options po;
  hr_pt_options_default(&po);
  po.paths = 200000;
  po.threads = 2;
  hr_err err = {{0}};
  CHECK(hr_pt_polys(s, &po, ref, se, &err) == HR_OK, "path tracer: %s", err.msg);
  hr_solver_poly_radiosity(a, 8, x);
  hr_solver_poly_radiosity(b, 8, y);
  const double eoff = fabs(x[0] - ref[8][0]) / ref[8][0];
  const double eon = fabs(y[0] - ref[8][0]) / ref[8][0];
  printf("pillar: the board inside (path tracer %.5f +- %.5f): uncut %.5f (%.1f%%), cut %.5f "
         "(%.1f%%, tol 5%%)\n",
         ref[8][0], se[8][0], x[0], 100 * eoff, y[0], 100 * eon);
  CHECK(eon <= 0.05, "board with the cut: %.1f%% off the path tracer", 100 * eon);
  CHECK(eoff >= 3 * eon, "the cut should take most of the leak: %.1f%% -> %.1f%%", 100 * eoff,
        100 * eon);
  /* the other polygons agree with the tracer either way (the room's light hardly moves) */
  for (int p = 0; p < 8; p++) {
    if (p == 1) continue; /* the emitter */
    hr_solver_poly_radiosity(b, p, y);
    CHECK(fabs(y[0] - ref[p][0]) <= 0.03 * ref[p][0], "polygon %d: %.5f, path tracer %.5f", p,
          y[0], ref[p][0]);
  }
  hr_solver_destroy(&a);
  hr_solver_destroy(&b);
  hr_scene_destroy(&s);
  hr_scene_destroy(&c);
}

/* The Cornell box's blocks are closed boxes: the floor under them is closed, nothing is cut. */
static void closed_boxes(void) {
  hr_scene *s;
  hr_err err = {{0}};
  CHECK(hr_scene_builtin("cornell", &s, &err) == HR_OK, "%s", err.msg);
  const int n0 = s->nsurfs;
  hr_cut_stats st;
  CHECK(hr_scene_cut_contacts(s, default_len(s), &st) == HR_OK, "cut");
  printf("cornell: %d surfaces cut, %d -> %d surfaces\n", st.surfaces, n0, s->nsurfs);
  CHECK(st.surfaces == 0 && s->nsurfs == n0, "cornell: %d surfaces cut", st.surfaces);
  hr_scene_destroy(&s);
}

int main(void) {
  geometry();
  leak();
  closed_boxes();
  return t_done("test_contact");
}
