/* test_builtin.c: tests of the built-in scenes (src/builtin.c). Sizes (27 polygons for "room",
 * 280-300 for "floor", 3500-4500 for "museum", 292 for "office"), emitters and cameras;
 * well-formed surfaces (finite, positive area, aspect ratio below 10); the room closed (its
 * shell area equals the box area computed here from its dimensions); and orientation, the bug
 * that makes a surface silently invisible: interior points lie in front of every enclosing
 * surface and behind every face of a furniture block, and rays shot in many directions from
 * points known to be in the air (room centres, museum cell centres, the cameras) always hit a
 * surface first from its front side, and in closed scenes always hit something. A small
 * ray/triangle test written here is the independent referee. Also: door openings in "floor" let
 * rays through, unknown names fail with HR_ERR_INVALID and the exact message, the name list,
 * determinism. For "office": its small downward lamps, furniture that stands on the floor,
 * touches what holds it up and leaves out only faces that lie against something, and no two
 * coplanar overlapping surfaces. For "hall:N": golden triangle counts, emitted power N^2 times
 * a cell's, closed and front-facing from the air despite interpenetrating furniture, bad N. */
#include "hrad.h"
#include "testutil.h"

#include <string.h>

/* ---------------------------------------------------------------- geometry */

static hr_vec3 sub(hr_vec3 a, hr_vec3 b) { return tv(a.x - b.x, a.y - b.y, a.z - b.z); }
static double dot(hr_vec3 a, hr_vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static hr_vec3 cross(hr_vec3 a, hr_vec3 b) {
  return tv(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static double len(hr_vec3 a) { return sqrt(dot(a, a)); }

/* Two-sided Moller-Trumbore; returns 1 and the ray parameter for hits at t > 1e-9. */
static int tri_hit(hr_vec3 o, hr_vec3 d, hr_vec3 a, hr_vec3 b, hr_vec3 c, double *t) {
  hr_vec3 e1 = sub(b, a), e2 = sub(c, a), p = cross(d, e2);
  double det = dot(e1, p);
  if (fabs(det) < 1e-300) return 0;
  double inv = 1.0 / det;
  hr_vec3 s = sub(o, a);
  double u = dot(s, p) * inv;
  if (u < 0 || u > 1) return 0;
  hr_vec3 q = cross(s, e1);
  double v = dot(d, q) * inv;
  if (v < 0 || u + v > 1) return 0;
  double tt = dot(e2, q) * inv;
  if (!(tt > 1e-9)) return 0;
  *t = tt;
  return 1;
}

/* Nearest surface hit by the ray o + t d (t > 0), or -1; its parameter in '*tbest'. */
static int cast(const hr_scene *s, hr_vec3 o, hr_vec3 d, double *tbest) {
  int best = -1;
  double bt = INFINITY;
  for (int i = 0; i < s->nsurfs; i++) {
    const hr_surface *f = &s->surfs[i];
    double t;
    for (int k = 1; k + 1 < f->nverts; k++)
      if (tri_hit(o, d, f->v[0], f->v[k], f->v[k + 1], &t) && t < bt) {
        bt = t;
        best = i;
      }
  }
  *tbest = bt;
  return best;
}

/* Direction i of n, spread evenly over the sphere (golden spiral); slightly tilted so that no
 * ray runs exactly along a wall plane. */
static hr_vec3 sphere_dir(int i, int n) {
  double z = 1.0 - 2.0 * (i + 0.5) / n, r = sqrt(fmax(0.0, 1.0 - z * z));
  double phi = 2.399963229728653 * i + 0.1234;
  return tv(r * cos(phi), z, r * sin(phi));
}

/* Shoots 'n' rays from 'p': counts rays that hit nothing and rays whose first hit is the back
 * of a surface (reported once per probe point, with the surface). */
static void probe(const hr_scene *s, const char *what, hr_vec3 p, int n, int *miss, int *back) {
  int reported = 0;
  for (int i = 0; i < n; i++) {
    hr_vec3 d = sphere_dir(i, n);
    double t;
    int h = cast(s, p, d, &t);
    if (h < 0) {
      (*miss)++;
      continue;
    }
    if (dot(d, s->surfs[h].normal) >= 0) {
      (*back)++;
      if (!reported++)
        fprintf(stderr, "  %s: from (%.3f %.3f %.3f) the ray (%.3f %.3f %.3f) first hits the back "
                "of surface %d (poly %d, material %s)\n", what, p.x, p.y, p.z, d.x, d.y, d.z, h,
                s->surfs[h].poly, s->mats[s->surfs[h].material].name);
    }
  }
}

/* Signed distance of 'p' from the plane of surface 'f' (positive: in front). */
static double side(const hr_surface *f, hr_vec3 p) { return dot(sub(p, f->v[0]), f->normal); }

/* Checks that 'p' is in front of every surface of polygons [p0, p1]. */
static void check_in_front(const hr_scene *s, const char *what, hr_vec3 p, int p0, int p1) {
  for (int i = 0; i < s->nsurfs; i++) {
    const hr_surface *f = &s->surfs[i];
    if (f->poly < p0 || f->poly > p1) continue;
    CHECK(side(f, p) > 1e-6, "%s: interior point is behind poly %d (material %s), distance %g",
          what, f->poly, s->mats[f->material].name, side(f, p));
  }
}

/* For a convex block made of polygons [p0, p1]: the mean of their vertices lies inside, so it
 * must be behind every face (the faces point outward). */
static void check_block(const hr_scene *s, const char *what, int p0, int p1) {
  hr_vec3 c = tv(0, 0, 0);
  int n = 0;
  for (int i = 0; i < s->nsurfs; i++) {
    const hr_surface *f = &s->surfs[i];
    if (f->poly < p0 || f->poly > p1) continue;
    for (int k = 0; k < f->nverts; k++) {
      c = tv(c.x + f->v[k].x, c.y + f->v[k].y, c.z + f->v[k].z);
      n++;
    }
  }
  CHECK(n > 0, "%s: no surfaces in polys %d..%d", what, p0, p1);
  if (!n) return;
  c = tv(c.x / n, c.y / n, c.z / n);
  for (int i = 0; i < s->nsurfs; i++) {
    const hr_surface *f = &s->surfs[i];
    if (f->poly < p0 || f->poly > p1) continue;
    CHECK(side(f, c) < -1e-6, "%s: block centre is in front of poly %d (faces inward?)", what,
          f->poly);
  }
}

/* ---------------------------------------------------------------- common checks */

static hr_scene *load(const char *name) {
  hr_scene *s = NULL;
  hr_err err = {{0}};
  hr_status st = hr_scene_builtin(name, &s, &err);
  CHECK(st == HR_OK && s, "loading '%s': status %d: %s", name, (int)st, err.msg);
  return st == HR_OK ? s : NULL;
}

static int finite3(hr_vec3 v) { return isfinite(v.x) && isfinite(v.y) && isfinite(v.z); }

/* Well-formed surfaces, an emitter, a camera in the air. Returns the number of emitting polys. */
static int check_common(const hr_scene *s, const char *name, double max_aspect) {
  CHECK(strcmp(s->name, name) == 0, "scene name '%s', want '%s'", s->name, name);
  CHECK(s->nsurfs >= s->npolys && s->npolys > 0, "%s: %d surfaces for %d polys", name, s->nsurfs,
        s->npolys);
  int bad = 0, nemit = 0, last_emit_poly = -1;
  double worst_aspect = 0;
  for (int i = 0; i < s->nsurfs; i++) {
    const hr_surface *f = &s->surfs[i];
    int ok = (f->nverts == 3 || f->nverts == 4) && isfinite(f->area) && f->area > 0 &&
             fabs(len(f->normal) - 1) < 1e-9 && f->material >= 0 && f->material < s->nmats &&
             f->poly >= 0 && f->poly < s->npolys;
    double lmax = 0;
    for (int k = 0; k < f->nverts && ok; k++) {
      ok = finite3(f->v[k]);
      lmax = fmax(lmax, len(sub(f->v[(k + 1) % f->nverts], f->v[k])));
    }
    if (!ok && bad++ < 5) fprintf(stderr, "  %s: surface %d is malformed\n", name, i);
    /* Rectangle a x b: lmax^2 / area = a / b; right triangle with legs a, b (a >= b): about
     * 2 a / b + 2 b / a, so halve it for triangles to compare alike. */
    double aspect = lmax * lmax / f->area / (f->nverts == 3 ? 2.0 : 1.0);
    worst_aspect = fmax(worst_aspect, aspect);
    const double *e = s->mats[f->material].emit;
    if ((e[0] > 0 || e[1] > 0 || e[2] > 0) && f->poly != last_emit_poly) {
      nemit++;
      last_emit_poly = f->poly;
    }
  }
  CHECK(bad == 0, "%s: %d malformed surfaces", name, bad);
  CHECK(worst_aspect < max_aspect, "%s: worst aspect ratio %.2f (limit %.1f)", name,
        worst_aspect, max_aspect);
  for (int p = 0; p < s->npolys; p++)
    CHECK(isfinite(s->poly_area[p]) && s->poly_area[p] > 0, "%s: poly %d area %g", name, p,
          s->poly_area[p]);
  double area = hr_scene_total_area(s);
  CHECK(isfinite(area) && area > 0, "%s: total area %g", name, area);
  CHECK(hr_scene_max_emit(s) > 0, "%s: no emitter", name);
  CHECK(s->has_camera, "%s: no camera", name);
  const hr_camera *c = &s->camera;
  CHECK(finite3(c->eye) && finite3(c->at) && finite3(c->up) && len(sub(c->at, c->eye)) > 0.1 &&
            len(c->up) > 0.5 && c->fov_deg > 10 && c->fov_deg < 120,
        "%s: bad camera", name);
  /* Up must not be parallel to the view direction. */
  CHECK(len(cross(c->up, sub(c->at, c->eye))) > 0.1 * len(c->up) * len(sub(c->at, c->eye)),
        "%s: camera up is parallel to its view direction", name);
  printf("  %-8s %5d polys %5d surfaces %4d emitting polys  area %9.3f m^2  worst aspect %.2f\n",
         name, s->npolys, s->nsurfs, nemit, area, worst_aspect);
  return nemit;
}

static void check_bounds(const hr_scene *s, const char *name, hr_vec3 lo, hr_vec3 hi,
                         double tol) {
  hr_vec3 a, b;
  hr_scene_bounds(s, &a, &b);
  CHECK(len(sub(a, lo)) < tol && len(sub(b, hi)) < tol,
        "%s: bounds (%g %g %g)-(%g %g %g), want (%g %g %g)-(%g %g %g)", name, a.x, a.y, a.z, b.x,
        b.y, b.z, lo.x, lo.y, lo.z, hi.x, hi.y, hi.z);
}

/* A closed scene seen from an air point: every ray hits, and hits a front first. */
static void check_closed_from(const hr_scene *s, const char *what, hr_vec3 p, int nrays) {
  int miss = 0, back = 0;
  probe(s, what, p, nrays, &miss, &back);
  CHECK(miss == 0 && back == 0, "%s from (%.2f %.2f %.2f): %d of %d rays escape, %d hit a back",
        what, p.x, p.y, p.z, miss, nrays, back);
}

/* ---------------------------------------------------------------- scenes */

static void test_room(void) {
  /* The room's dimensions as documented in builtin.c: 5 x 2.8 x 4 m, low corner at the origin. */
  const double W = 5.0, H = 2.8, D = 4.0;
  hr_scene *s = load("room");
  if (!s) return;
  int nemit = check_common(s, "room", 10.0);
  CHECK(s->npolys == 27, "room has %d polygons, want 27", s->npolys);
  CHECK(nemit == 1, "room has %d emitting polygons, want 1 (the ceiling light)", nemit);
  check_bounds(s, "room", tv(0, 0, 0), tv(W, H, D), 1e-9);
  /* Polygons 0-5 are the shell (floor, ceiling, 4 walls): closed box area. */
  double shell = 0;
  for (int p = 0; p <= 5; p++) shell += s->poly_area[p];
  CHECK_REL(shell, 2 * (W * H + W * D + H * D), 1e-12, "room shell area (m^2)");
  /* Colour bleeding needs a clearly coloured wall in the shell. */
  int coloured = 0;
  for (int i = 0; i < s->nsurfs; i++) {
    const double *r = s->mats[s->surfs[i].material].rho;
    if (s->surfs[i].poly <= 5 && r[0] > 2 * r[1]) coloured = 1;
  }
  CHECK(coloured, "room: no coloured wall");
  CHECK(s->nmats >= 6, "room: only %d materials", s->nmats);
  /* Orientation. Room centre above the table, below the light. */
  hr_vec3 c = tv(W / 2, 1.6, D / 2);
  check_in_front(s, "room shell+light", c, 0, 6);
  check_in_front(s, "room picture/door/rug", c, 24, 26);
  for (int i = 0; i < s->nsurfs; i++)
    if (s->surfs[i].poly == 6)
      CHECK(s->surfs[i].normal.y < -0.999, "room: light does not face down");
  check_block(s, "room table", 7, 11);
  check_block(s, "room cabinet", 12, 15);
  check_block(s, "room sofa seat", 16, 19);
  check_block(s, "room sofa back", 20, 23);
  /* Watertight and front-facing from the centre, a low point, and the camera. */
  check_closed_from(s, "room centre", c, 2000);
  check_closed_from(s, "room low point", tv(0.7, 0.3, 0.4), 1000);
  check_closed_from(s, "room camera", s->camera.eye, 1000);
  hr_scene_destroy(&s);
}

/* "floor" as documented in builtin.c: 4 x 3 rooms of 5 x 2.8 x 4 m with 0.25 m walls between
 * them; every room opens to its x neighbours, and z doors join rooms (0,0)-(0,1) and
 * (3,1)-(3,2). Doors: local z in [D-1.4, D-0.5] in x walls, local x in [0.5, 1.4] in z walls,
 * 2.1 m high. */
static int floor_has_zdoor(int i, int j) { return (i == 0 && j == 0) || (i == 3 && j == 1); }

static void test_floor(void) {
  const double W = 5.0, H = 2.8, D = 4.0, T = 0.25;
  const int NI = 4, NJ = 3;
  hr_scene *s = load("floor");
  if (!s) return;
  int nemit = check_common(s, "floor", 10.0);
  CHECK(s->npolys >= 280 && s->npolys <= 300, "floor has %d polygons, want 280..300",
        s->npolys);
  CHECK(nemit == NI * NJ, "floor has %d emitting polygons, want one per room", nemit);
  check_bounds(s, "floor", tv(0, 0, 0), tv(NI * W + (NI - 1) * T, H, NJ * D + (NJ - 1) * T),
               1e-9);
  /* Floor-level area: the rooms' floors and the 11 door thresholds (0.9 x T). */
  double ground = 0;
  for (int i = 0; i < s->nsurfs; i++)
    if (s->surfs[i].normal.y > 0.999 && fabs(s->surfs[i].v[0].y) < 1e-12)
      ground += s->surfs[i].area;
  CHECK_REL(ground, NI * W * NJ * D + 11 * 0.9 * T, 1e-12, "floor: floors + thresholds (m^2)");
  char what[64];
  for (int j = 0; j < NJ; j++)
    for (int i = 0; i < NI; i++) {
      double x0 = i * (W + T), z0 = j * (D + T);
      hr_vec3 c = tv(x0 + W / 2, 1.6, z0 + D / 2);
      snprintf(what, sizeof what, "floor room (%d,%d)", i, j);
      check_closed_from(s, what, c, 400);
      /* A ray from the centre through the middle of a door passes into the neighbour room
       * (t > 1 + wall); where there is no door it stops at the wall (t = 1). */
      double t;
      hr_vec3 east = tv(x0 + W, 1.05, z0 + D - 0.95), south = tv(x0 + 0.95, 1.05, z0 + D);
      cast(s, c, sub(east, c), &t);
      if (i + 1 < NI)
        CHECK(t > 1.1, "%s: the east door is closed (hit at t=%.3f)", what, t);
      else
        CHECK(fabs(t - 1) < 1e-9, "%s: the outer east wall has a hole (t=%.3f)", what, t);
      cast(s, c, sub(south, c), &t);
      if (j + 1 < NJ && floor_has_zdoor(i, j))
        CHECK(t > 1.1, "%s: the south door is closed (hit at t=%.3f)", what, t);
      else
        CHECK(fabs(t - 1) < 1e-9, "%s: the south wall has an unexpected hole (t=%.3f)", what, t);
    }
  check_closed_from(s, "floor camera", s->camera.eye, 400);
  /* From inside a door gap (between two rooms, mid-wall) everything is seen from the front. */
  check_closed_from(s, "floor door gap", tv(W + T / 2, 1.0, D - 0.95), 400);
  hr_scene_destroy(&s);
}

static void test_museum(void) {
  /* The museum's grid as documented in builtin.c: 16 x 10 cells of 3 m, 4 storeys of 4.5 m,
   * 0.4 m slabs (floors at y = k * 4.5 + 0.2 above the ground floor), walls on cell lines.
   * Cell centres 3.3 m above each storey's floor are in the air: above plinths (<= 1.2 m),
   * benches and display walls (3 m), below the lamps. */
  const double C = 3.0, SH = 4.5, S = 0.4;
  const int NX = 16, NZ = 10, NS = 4;
  hr_scene *s = load("museum");
  if (!s) return;
  int nemit = check_common(s, "museum", 10.0);
  CHECK(s->npolys >= 3500 && s->npolys <= 4500, "museum has %d polygons, want 3500..4500",
        s->npolys);
  check_bounds(s, "museum", tv(0, 0, 0), tv(NX * C, NS * SH, NZ * C), 1e-9);
  double amax = 0;
  for (int p = 0; p < s->npolys; p++) amax = fmax(amax, s->poly_area[p]);
  CHECK(amax <= C * SH + 1e-9, "museum: largest polygon %.2f m^2 (limit: one wall panel)", amax);
  printf("  museum: largest polygon %.2f m^2\n", amax);
  CHECK(nemit >= 100, "museum: only %d emitting polygons", nemit);
  /* Lamps, skylights and windows: at least three emitting materials, all used. */
  int emitting_mats = 0;
  for (int m = 0; m < s->nmats; m++) {
    const double *e = s->mats[m].emit;
    if (!(e[0] > 0 || e[1] > 0 || e[2] > 0)) continue;
    int used = 0;
    for (int i = 0; i < s->nsurfs && !used; i++) used = s->surfs[i].material == m;
    emitting_mats += used;
  }
  CHECK(emitting_mats >= 3, "museum: %d emitting materials in use, want lamps, skylights and "
        "windows", emitting_mats);
  int miss = 0, back = 0, npts = 0;
  for (int k = 0; k < NS; k++)
    for (int j = 0; j < NZ; j++)
      for (int i = 0; i < NX; i++) {
        char what[64];
        snprintf(what, sizeof what, "museum storey %d cell (%d,%d)", k, i, j);
        double yf = k * SH + (k > 0 ? S / 2 : 0);
        probe(s, what, tv((i + 0.5) * C, yf + 3.3, (j + 0.5) * C), 24, &miss, &back);
        npts++;
      }
  CHECK(miss == 0 && back == 0, "museum: from %d cell centres, %d rays escape and %d hit a back",
        npts, miss, back);
  check_closed_from(s, "museum camera", s->camera.eye, 500);
  /* Deterministic: a second build is identical. */
  hr_scene *s2 = load("museum");
  if (s2) {
    int same = s2->nsurfs == s->nsurfs && s2->nmats == s->nmats;
    for (int i = 0; same && i < s->nsurfs; i++) {
      same = s->surfs[i].material == s2->surfs[i].material &&
             s->surfs[i].nverts == s2->surfs[i].nverts;
      for (int k = 0; same && k < s->surfs[i].nverts; k++)
        same = memcmp(&s->surfs[i].v[k], &s2->surfs[i].v[k], sizeof(hr_vec3)) == 0;
    }
    CHECK(same, "museum: two builds differ");
    hr_scene_destroy(&s2);
  }
  hr_scene_destroy(&s);
}

static void test_cornell(void) {
  hr_scene *s = load("cornell");
  if (!s) return;
  int nemit = check_common(s, "cornell", 10.0);
  CHECK(s->npolys == 16, "cornell has %d polygons, want 16 (5 walls, light, 2 x 5 block faces)",
        s->npolys);
  CHECK(nemit == 1, "cornell has %d emitting polygons", nemit);
  check_bounds(s, "cornell", tv(0, 0, 0), tv(0.556, 0.5488, 0.5592), 1e-9);
  /* Published camera. */
  CHECK(len(sub(s->camera.eye, tv(0.278, 0.273, -0.8))) < 1e-9, "cornell: camera eye");
  hr_vec3 dir = sub(s->camera.at, s->camera.eye);
  CHECK(dir.z > 0 && fabs(dir.x) < 1e-9 && fabs(dir.y) < 1e-9, "cornell: camera looks along +z");
  CHECK(fabs(s->camera.fov_deg - 39.31) < 0.05, "cornell: fov %g", s->camera.fov_deg);
  /* Light: 130 x 105 mm, facing down, just under the ceiling. */
  CHECK_REL(s->poly_area[5], 0.130 * 0.105, 1e-9, "cornell light area (m^2)");
  for (int i = 0; i < s->nsurfs; i++)
    if (s->surfs[i].poly == 5)
      CHECK(s->surfs[i].normal.y < -0.999 && s->surfs[i].v[0].y < 0.5488,
            "cornell: light must face down below the ceiling");
  /* Red on the x ~ 0.556 side, green at x = 0. */
  for (int i = 0; i < s->nsurfs; i++) {
    const hr_surface *f = &s->surfs[i];
    const double *r = s->mats[f->material].rho;
    if (f->poly == 3) CHECK(f->v[0].x == 0 && r[1] > 2 * r[0], "cornell: green wall at x=0");
    if (f->poly == 4) CHECK(f->v[0].x > 0.5 && r[0] > 5 * r[1], "cornell: red wall at x~0.556");
  }
  /* Orientation: a point above the blocks at the box centre; blocks face outward. */
  hr_vec3 p = tv(0.278, 0.45, 0.28);
  check_in_front(s, "cornell walls+light", p, 0, 5);
  check_in_front(s, "cornell walls+light (look-at)", s->camera.at, 0, 5);
  check_block(s, "cornell short block", 6, 10);
  check_block(s, "cornell tall block", 11, 15);
  /* Open front: some rays escape, but no ray meets a back first. */
  int miss = 0, back = 0, n = 1000;
  probe(s, "cornell centre", p, n, &miss, &back);
  CHECK(back == 0, "cornell: %d rays from the centre hit a back first", back);
  CHECK(miss > 0 && miss < n / 3, "cornell: %d of %d rays escape (want the open front only)",
        miss, n);
  miss = back = 0;
  probe(s, "cornell camera", s->camera.eye, n, &miss, &back);
  CHECK(back == 0, "cornell: %d rays from the camera hit a back first", back);
  hr_scene_destroy(&s);
}

/* "office" as documented in builtin.c: 6 x 3 x 5 m, 292 polygons in a fixed order (the ranges
 * below). Furniture blocks are convex boxes; 'floor' marks those that stand on the floor. */
typedef struct of_blk {
  char what[40];
  int p0, p1;
  const char *mat; /* material of every polygon in the block, or NULL (lamps: emitter + housing) */
  int floor;
} of_blk;

static void of_add(of_blk *B, int *n, const char *what, int p0, int p1, const char *mat,
                   int floor) {
  of_blk *k = &B[(*n)++];
  snprintf(k->what, sizeof k->what, "%s", what);
  k->p0 = p0;
  k->p1 = p1;
  k->mat = mat;
  k->floor = floor;
}

/* Four legs of 4 polygons each from polygon 'p'. */
static void of_add_legs(of_blk *B, int *n, const char *what, int p) {
  char w[40];
  for (int i = 0; i < 4; i++) {
    snprintf(w, sizeof w, "%s leg %d", what, i);
    of_add(B, n, w, p + 4 * i, p + 4 * i + 3, "metal", 1);
  }
}

/* The blocks of "office" in polygon order; returns their number. */
static int office_blocks(of_blk *B) {
  int n = 0;
  char w[40];
  for (int k = 0; k < 4; k++) {
    snprintf(w, sizeof w, "ceiling lamp %d", k);
    of_add(B, &n, w, 6 + 5 * k, 10 + 5 * k, NULL, 0);
  }
  of_add(B, &n, "desk A top", 30, 38, "desk", 0);
  of_add_legs(B, &n, "desk A", 39);
  of_add(B, &n, "desk B top", 55, 61, "desk", 0);
  of_add_legs(B, &n, "desk B", 62);
  of_add(B, &n, "desk C top", 78, 89, "desk", 0);
  of_add_legs(B, &n, "desk C", 90);
  of_add(B, &n, "monitor A case", 106, 111, NULL, 0);
  of_add(B, &n, "monitor A neck", 112, 115, "monitor", 0);
  of_add(B, &n, "monitor B case", 116, 121, NULL, 0);
  of_add(B, &n, "monitor B neck", 122, 125, "monitor", 0);
  of_add(B, &n, "desk lamp base", 126, 130, "metal", 0);
  of_add(B, &n, "desk lamp stem", 131, 135, "metal", 0);
  of_add(B, &n, "desk lamp arm", 136, 139, "metal", 0);
  of_add(B, &n, "desk lamp head", 140, 145, NULL, 0);
  static const char *const chairs[3] = {"chair A", "chair B", "chair C"};
  for (int c = 0; c < 3; c++) {
    int p = 146 + 27 * c;
    snprintf(w, sizeof w, "%s seat", chairs[c]);
    of_add(B, &n, w, p, p + 5, "chair", 0);
    snprintf(w, sizeof w, "%s back", chairs[c]);
    of_add(B, &n, w, p + 6, p + 10, "chair", 0);
    of_add_legs(B, &n, chairs[c], p + 11);
  }
  of_add(B, &n, "bookshelf side 0", 227, 233, "bookshelf", 1);
  of_add(B, &n, "bookshelf side 1", 234, 240, "bookshelf", 1);
  of_add(B, &n, "bookshelf plinth", 241, 243, "bookshelf", 1);
  for (int i = 0; i < 3; i++) {
    snprintf(w, sizeof w, "shelf %d", i);
    of_add(B, &n, w, 244 + 5 * i, 248 + 5 * i, "bookshelf", 0);
  }
  of_add(B, &n, "red books", 259, 262, "books_red", 0);
  of_add(B, &n, "green books", 263, 266, "books_green", 0);
  of_add(B, &n, "ochre books", 267, 270, "books_ochre", 0);
  of_add(B, &n, "filing cabinet", 271, 276, "cabinet", 1);
  for (int i = 0; i < 3; i++) {
    snprintf(w, sizeof w, "cabinet handle %d", i);
    of_add(B, &n, w, 277 + 5 * i, 281 + 5 * i, "metal", 0);
  }
  return n;
}

/* Axis-aligned bounds of polygons [p0, p1]. */
static void poly_bounds(const hr_scene *s, int p0, int p1, double lo[3], double hi[3]) {
  for (int a = 0; a < 3; a++) {
    lo[a] = INFINITY;
    hi[a] = -INFINITY;
  }
  for (int i = 0; i < s->nsurfs; i++) {
    const hr_surface *f = &s->surfs[i];
    if (f->poly < p0 || f->poly > p1) continue;
    for (int k = 0; k < f->nverts; k++) {
      const double c[3] = {f->v[k].x, f->v[k].y, f->v[k].z};
      for (int a = 0; a < 3; a++) {
        lo[a] = fmin(lo[a], c[a]);
        hi[a] = fmax(hi[a], c[a]);
      }
    }
  }
}

/* Axis-aligned bounds of one surface. */
static void surf_bounds(const hr_surface *f, double lo[3], double hi[3]) {
  for (int a = 0; a < 3; a++) {
    lo[a] = INFINITY;
    hi[a] = -INFINITY;
  }
  for (int k = 0; k < f->nverts; k++) {
    const double c[3] = {f->v[k].x, f->v[k].y, f->v[k].z};
    for (int a = 0; a < 3; a++) {
      lo[a] = fmin(lo[a], c[a]);
      hi[a] = fmax(hi[a], c[a]);
    }
  }
}

/* Two boxes touch: they meet in a plane of one axis and overlap (with area) in the others. */
static int boxes_touch(const double alo[3], const double ahi[3], const double blo[3],
                       const double bhi[3]) {
  for (int a = 0; a < 3; a++) {
    if (!(fabs(ahi[a] - blo[a]) < 1e-9 || fabs(bhi[a] - alo[a]) < 1e-9)) continue;
    int ok = 1;
    for (int c = 0; c < 3; c++)
      if (c != a && fmin(ahi[c], bhi[c]) - fmax(alo[c], blo[c]) < 1e-6) ok = 0;
    if (ok) return 1;
  }
  return 0;
}

/* No two surfaces lie in one plane and overlap (with area), whichever way they face: for
 * scenes made only of axis-aligned rectangles, which this checks first. */
static void check_no_coplanar_overlap(const hr_scene *s, const char *name) {
  int nonrect = 0, overlaps = 0;
  double(*lo)[3] = calloc((size_t)s->nsurfs, sizeof *lo);
  double(*hi)[3] = calloc((size_t)s->nsurfs, sizeof *hi);
  int *axis = calloc((size_t)s->nsurfs, sizeof *axis);
  if (!lo || !hi || !axis) abort();
  for (int i = 0; i < s->nsurfs; i++) {
    const hr_surface *f = &s->surfs[i];
    surf_bounds(f, lo[i], hi[i]);
    const double n[3] = {f->normal.x, f->normal.y, f->normal.z};
    int a = fabs(n[0]) > 0.5 ? 0 : fabs(n[1]) > 0.5 ? 1 : 2;
    axis[i] = a;
    int u = (a + 1) % 3, v = (a + 2) % 3;
    double span = (hi[i][u] - lo[i][u]) * (hi[i][v] - lo[i][v]);
    if (f->nverts != 4 || fabs(n[a]) < 1 - 1e-12 || hi[i][a] - lo[i][a] > 1e-12 ||
        fabs(span - f->area) > 1e-9 * span)
      nonrect++;
  }
  CHECK(nonrect == 0, "%s: %d surfaces are not axis-aligned rectangles", name, nonrect);
  for (int i = 0; i < s->nsurfs && !nonrect; i++)
    for (int j = i + 1; j < s->nsurfs; j++) {
      int a = axis[i], u = (a + 1) % 3, v = (a + 2) % 3;
      if (axis[j] != a || fabs(lo[i][a] - lo[j][a]) > 1e-9) continue;
      double ou = fmin(hi[i][u], hi[j][u]) - fmax(lo[i][u], lo[j][u]);
      double ov = fmin(hi[i][v], hi[j][v]) - fmax(lo[i][v], lo[j][v]);
      if (ou > 1e-9 && ov > 1e-9 && overlaps++ < 5)
        fprintf(stderr, "  %s: polys %d (%s) and %d (%s) overlap in one plane (%.4g x %.4g m)\n",
                name, s->surfs[i].poly, s->mats[s->surfs[i].material].name, s->surfs[j].poly,
                s->mats[s->surfs[j].material].name, ou, ov);
    }
  free(lo);
  free(hi);
  free(axis);
  CHECK(overlaps == 0, "%s: %d pairs of coplanar overlapping surfaces", name, overlaps);
}

/* Every box face that a block leaves out lies against the shell (the box [0, rhi]) or inside
 * the opposite face of another block, so no gap opens into the block; and a face is either
 * all there (its pieces add up to it) or left out. */
static void check_left_out_faces(const hr_scene *s, const of_blk *B, int nb,
                                 const double (*lo)[3], const double (*hi)[3],
                                 const double rhi[3]) {
  for (int k = 0; k < nb; k++)
    for (int a = 0; a < 3; a++)
      for (int sg = -1; sg <= 1; sg += 2) {
        int u = (a + 1) % 3, v = (a + 2) % 3;
        double c = sg > 0 ? hi[k][a] : lo[k][a];
        double full = (hi[k][u] - lo[k][u]) * (hi[k][v] - lo[k][v]), got = 0;
        for (int i = 0; i < s->nsurfs; i++) {
          const hr_surface *f = &s->surfs[i];
          const double n[3] = {f->normal.x, f->normal.y, f->normal.z};
          const double p[3] = {f->v[0].x, f->v[0].y, f->v[0].z};
          if (f->poly >= B[k].p0 && f->poly <= B[k].p1 && n[a] * sg > 0.999 &&
              fabs(p[a] - c) < 1e-9)
            got += f->area;
        }
        if (got > 0) {
          CHECK(fabs(got - full) < 1e-9 * full, "office %s: face %c%c is %.6g of %.6g m^2",
                B[k].what, sg > 0 ? '+' : '-', "xyz"[a], got, full);
          continue;
        }
        int covered = sg < 0 ? fabs(c) < 1e-12 : fabs(c - rhi[a]) < 1e-12;
        for (int j = 0; j < nb && !covered; j++) {
          if (j == k || fabs((sg > 0 ? lo[j][a] : hi[j][a]) - c) > 1e-9) continue;
          covered = lo[j][u] <= lo[k][u] + 1e-9 && hi[j][u] >= hi[k][u] - 1e-9 &&
                    lo[j][v] <= lo[k][v] + 1e-9 && hi[j][v] >= hi[k][v] - 1e-9;
        }
        CHECK(covered, "office %s: its %c%c face is left out but lies against nothing",
              B[k].what, sg > 0 ? '+' : '-', "xyz"[a]);
      }
}

static void test_office(void) {
  const double W = 6.0, H = 3.0, D = 5.0;
  hr_scene *s = load("office");
  if (!s) return;
  int nemit = check_common(s, "office", 10.0);
  CHECK(s->npolys == 292, "office has %d polygons, want 292", s->npolys);
  CHECK(s->nsurfs == s->npolys, "office: %d surfaces for %d polygons (all convex quads)",
        s->nsurfs, s->npolys);
  CHECK(nemit == 5, "office has %d emitting polygons, want 5 (4 ceiling lamps, a desk lamp)",
        nemit);
  check_bounds(s, "office", tv(0, 0, 0), tv(W, H, D), 1e-9);
  double shell = 0;
  for (int p = 0; p <= 5; p++) shell += s->poly_area[p];
  CHECK_REL(shell, 2 * (W * H + W * D + H * D), 1e-12, "office shell area (m^2)");
  int coloured = 0;
  for (int i = 0; i < s->nsurfs; i++) {
    const double *r = s->mats[s->surfs[i].material].rho;
    if (s->surfs[i].poly <= 5 && r[2] > 2 * r[0]) coloured = 1;
  }
  CHECK(coloured, "office: no coloured (blue) wall");
  CHECK(s->nmats >= 15, "office: only %d materials", s->nmats);
  for (int m = 0; m < s->nmats; m++)
    for (int c = 0; c < 3; c++)
      CHECK(s->mats[m].rho[c] >= 0.1 && s->mats[m].rho[c] <= 0.8,
            "office: material %s rho %g outside 0.1..0.8", s->mats[m].name, s->mats[m].rho[c]);
  /* Small bright lamps: every emitter faces down, is at most 0.3 m across, emits 50..100 W/m^2
   * with rho about 0.8; four hang 4 cm below the ceiling, one (the desk lamp) under 1.2 m. */
  int ceiling_lamps = 0, desk_lamps = 0;
  double emit_area = 0;
  for (int i = 0; i < s->nsurfs; i++) {
    const hr_surface *f = &s->surfs[i];
    const hr_material *mt = &s->mats[f->material];
    if (!(mt->emit[0] > 0 || mt->emit[1] > 0 || mt->emit[2] > 0)) continue;
    double lo[3], hi[3];
    poly_bounds(s, f->poly, f->poly, lo, hi);
    CHECK(f->normal.y < -0.999, "office: emitter poly %d does not face down", f->poly);
    CHECK(hi[0] - lo[0] <= 0.3 + 1e-9 && hi[2] - lo[2] <= 0.3 + 1e-9,
          "office: emitter poly %d is %.2f x %.2f m", f->poly, hi[0] - lo[0], hi[2] - lo[2]);
    for (int c = 0; c < 3; c++)
      CHECK(mt->emit[c] >= 50 && mt->emit[c] <= 100 && fabs(mt->rho[c] - 0.8) < 0.05,
            "office: emitter %s E %g rho %g", mt->name, mt->emit[c], mt->rho[c]);
    if (fabs(lo[1] - (H - 0.04)) < 1e-9) ceiling_lamps++;
    if (lo[1] > 0.75 && lo[1] < 1.2) desk_lamps++;
    emit_area += f->area;
  }
  CHECK(ceiling_lamps == 4 && desk_lamps == 1, "office: %d ceiling lamps, %d desk lamps",
        ceiling_lamps, desk_lamps);
  CHECK(emit_area < 5e-3 * hr_scene_total_area(s), "office: lamps are %.4f m^2 of %.1f m^2",
        emit_area, hr_scene_total_area(s));
  printf("  office: emitting area %.4f m^2 (%.3f%% of the total)\n", emit_area,
         100 * emit_area / hr_scene_total_area(s));
  /* Shell, emitters and the flat things on walls and floor face the room centre. */
  hr_vec3 c = tv(W / 2, 2.0, D / 2);
  check_in_front(s, "office shell", c, 0, 5);
  check_in_front(s, "office door/whiteboard/picture/rug", c, 26, 29);
  for (int k = 0; k < 4; k++) check_in_front(s, "office ceiling lamp", c, 6 + 5 * k, 6 + 5 * k);
  /* Furniture: convex blocks facing outward, each of one material; those on the floor reach
   * y = 0; and every block touches another block or the shell (nothing floats). */
  of_blk B[80];
  int nb = office_blocks(B);
  double (*lo)[3] = calloc((size_t)nb, sizeof *lo), (*hi)[3] = calloc((size_t)nb, sizeof *hi);
  int *reach = calloc((size_t)nb, sizeof *reach);
  if (!lo || !hi || !reach) abort();
  int covered = 0;
  for (int k = 0; k < nb; k++) {
    check_block(s, B[k].what, B[k].p0, B[k].p1);
    covered += B[k].p1 - B[k].p0 + 1;
    poly_bounds(s, B[k].p0, B[k].p1, lo[k], hi[k]);
    for (int i = 0; i < s->nsurfs && B[k].mat; i++)
      if (s->surfs[i].poly >= B[k].p0 && s->surfs[i].poly <= B[k].p1)
        CHECK(strcmp(s->mats[s->surfs[i].material].name, B[k].mat) == 0,
              "office %s: poly %d is %s, want %s", B[k].what, s->surfs[i].poly,
              s->mats[s->surfs[i].material].name, B[k].mat);
    if (B[k].floor)
      CHECK(fabs(lo[k][1]) < 1e-12, "office %s: lowest point at y = %g, not on the floor",
            B[k].what, lo[k][1]);
  }
  /* Everything but the shell (6) and the door, whiteboard, picture and rug (4) is in a block. */
  CHECK(covered == s->npolys - 10, "office: blocks cover %d polygons, want %d", covered,
        s->npolys - 10);
  const double rlo[3] = {0, 0, 0}, rhi[3] = {W, H, D};
  for (int k = 0; k < nb; k++)
    for (int a = 0; a < 3; a++)
      if (fabs(lo[k][a] - rlo[a]) < 1e-9 || fabs(hi[k][a] - rhi[a]) < 1e-9) reach[k] = 1;
  for (int grew = 1; grew;) {
    grew = 0;
    for (int k = 0; k < nb; k++)
      for (int j = 0; j < nb && !reach[k]; j++)
        if (reach[j] && boxes_touch(lo[k], hi[k], lo[j], hi[j])) reach[k] = grew = 1;
  }
  for (int k = 0; k < nb; k++)
    CHECK(reach[k], "office %s floats: it touches nothing that reaches the shell", B[k].what);
  check_left_out_faces(s, B, nb, (const double(*)[3])lo, (const double(*)[3])hi, rhi);
  free(lo);
  free(hi);
  free(reach);
  check_no_coplanar_overlap(s, "office");
  /* Closed and front-facing from points in the air: the centre, under the desk C, under a
   * chair seat, inside a bookshelf compartment, just under a ceiling lamp and under the desk
   * lamp's head, behind a monitor, near the door, and the camera. */
  check_closed_from(s, "office centre", c, 2000);
  check_closed_from(s, "office under desk C", tv(3.0, 0.35, 2.7), 1000);
  check_closed_from(s, "office under chair A", tv(1.05, 0.2, 1.8), 1000);
  check_closed_from(s, "office bookshelf", tv(0.2, 0.9, 3.3), 1000);
  check_closed_from(s, "office under a lamp", tv(1.8, 2.9, 1.5), 1000);
  check_closed_from(s, "office under the desk lamp", tv(2.6, 0.9, 2.79), 1000);
  check_closed_from(s, "office behind monitor B", tv(5.2, 1.0, 0.1), 1000);
  check_closed_from(s, "office by the door", tv(4.0, 0.3, 0.5), 1000);
  check_closed_from(s, "office camera", s->camera.eye, 1000);
  /* Deterministic: a second build is identical. */
  hr_scene *s2 = load("office");
  if (s2) {
    int same = s2->nsurfs == s->nsurfs && s2->nmats == s->nmats;
    for (int i = 0; same && i < s->nsurfs; i++) {
      same = s->surfs[i].material == s2->surfs[i].material &&
             s->surfs[i].poly == s2->surfs[i].poly && s->surfs[i].nverts == s2->surfs[i].nverts;
      for (int k = 0; same && k < s->surfs[i].nverts; k++)
        same = memcmp(&s->surfs[i].v[k], &s2->surfs[i].v[k], sizeof(hr_vec3)) == 0;
    }
    CHECK(same, "office: two builds differ");
    hr_scene_destroy(&s2);
  }
  hr_scene_destroy(&s);
}

/* "hall:N" as documented in builtin.c: N x N cells of 4 x 4 x 3 m, 991 N^2 + 70 N triangles
 * (golden counts for N = 1 and 4, the formula for 2 and 3), each cell's 1 x 0.5 m lamp facing
 * down at E = (150, 144, 132), so the emitted power is N^2 times one cell's; the hall is closed
 * and every surface that the air sees faces it (from the camera, above and under a table,
 * inside a bookshelf), despite the interpenetrating furniture; bounds show the partitions
 * running into the floor and the outer walls; "hall" is "hall:4"; bad N fail; deterministic. */
static void test_hall(void) {
  const double E[3] = {150, 144, 132}, C = 4.0, H = 3.0;
  for (int n = 1; n <= 4; n++) {
    char name[16], sname[16];
    snprintf(name, sizeof name, "hall:%d", n);
    snprintf(sname, sizeof sname, "hall-%d", n);
    hr_scene *s = load(name);
    if (!s) continue;
    int nemit = check_common(s, sname, 1000.0); /* slivers of aspect 160 by design */
    int want = n == 1 ? 1061 : n == 4 ? 16136 : 991 * n * n + 70 * n;
    CHECK(s->npolys == want && s->nsurfs == want && s->ninputs == want,
          "%s: %d polygons, %d surfaces, %d inputs, want %d triangles", name, s->npolys,
          s->nsurfs, s->ninputs, want);
    CHECK(nemit == 16 * n * n, "%s: %d emitting triangles, want %d", name, nemit, 16 * n * n);
    double P[3] = {0, 0, 0};
    for (int i = 0; i < s->nsurfs; i++) {
      const hr_surface *f = &s->surfs[i];
      const double *e = s->mats[f->material].emit;
      for (int c = 0; c < 3; c++) P[c] += f->area * e[c];
      if (e[0] > 0) CHECK(f->normal.y < -0.999, "%s: lamp surface %d does not face down", name, i);
    }
    for (int c = 0; c < 3; c++)
      CHECK_REL(P[c], 0.5 * E[c] * n * n, 1e-12, "hall emitted power (W)");
    double L = n * C;
    if (n == 1)
      check_bounds(s, name, tv(0, -0.01, 0), tv(L, H + 0.01, L), 1e-9);
    else
      check_bounds(s, name, tv(0, -0.02, -0.05), tv(L + 0.05, H + 0.01, L), 1e-9);
    if (n <= 2) {
      check_closed_from(s, "hall camera", s->camera.eye, 1000);
      for (int j = 0; j < n; j++)
        for (int i = 0; i < n; i++) {
          double x0 = i * C, z0 = j * C;
          check_closed_from(s, "hall above the table", tv(x0 + 0.8, 1.5, z0 + 3.3), 500);
          check_closed_from(s, "hall under the table", tv(x0 + 1.5, 0.35, z0 + 2.3), 500);
          check_closed_from(s, "hall in the bookshelf", tv(x0 + 3.6, 0.45, z0 + 1.5), 500);
        }
    }
    if (n == 2) { /* deterministic */
      hr_scene *s2 = load(name);
      int same = s2 && s2->nsurfs == s->nsurfs;
      for (int i = 0; same && i < s->nsurfs; i++)
        same = memcmp(s->surfs[i].v, s2->surfs[i].v, sizeof s->surfs[i].v) == 0 &&
               s->surfs[i].material == s2->surfs[i].material;
      CHECK(same, "hall:2: two builds differ");
      hr_scene_destroy(&s2);
    }
    hr_scene_destroy(&s);
  }
  hr_scene *s = load("hall");
  if (s) {
    CHECK(strcmp(s->name, "hall-4") == 0 && s->npolys == 16136, "'hall' is '%s', %d polygons",
          s->name, s->npolys);
    hr_scene_destroy(&s);
  }
  const char *bad[] = {"hall:0", "hall:65", "hall:", "hall:x", "hall:-1", "hall:4x", "hall:+4",
                       "hall: 4", "hall:99999999999999999999", "hall4", "Hall:4"};
  for (size_t k = 0; k < sizeof bad / sizeof *bad; k++) {
    hr_err err = {{0}};
    s = (hr_scene *)&err; /* must be reset to NULL */
    hr_status st = hr_scene_builtin(bad[k], &s, &err);
    CHECK(st == HR_ERR_INVALID && s == NULL && err.msg[0] && !strchr(err.msg, '\n'),
          "'%s': status %d, message '%s'", bad[k], (int)st, err.msg);
  }
  hr_err err = {{0}};
  hr_scene_builtin("hall:0", &s, &err);
  CHECK(strcmp(err.msg, "scene 'hall:0': hall:N needs N, a whole number in 1..64 (N x N cells, "
                        "about 1000 N^2 triangles)") == 0,
        "message '%s'", err.msg);
}

static void test_names_and_errors(void) {
  const char *const *names = hr_scene_builtin_names();
  const char *want[] = {"room", "floor", "museum", "cornell", "office", "hall"};
  int n = 0;
  while (names && names[n]) n++;
  CHECK(n == 6, "%d built-in names, want 6", n);
  for (int i = 0; i < 6 && i < n; i++)
    CHECK(strcmp(names[i], want[i]) == 0, "name %d is '%s', want '%s'", i, names[i], want[i]);
  hr_scene *s = (hr_scene *)&n; /* must be reset to NULL */
  hr_err err = {{0}};
  hr_status st = hr_scene_builtin("nope", &s, &err);
  CHECK(st == HR_ERR_INVALID, "unknown name: status %d", (int)st);
  CHECK(s == NULL, "unknown name: *out not NULL");
  CHECK(strcmp(err.msg, "unknown scene 'nope' (built-in: room, floor, museum, cornell, office, "
                        "hall:N)") == 0,
        "message '%s'", err.msg);
  st = hr_scene_builtin("Room", &s, NULL); /* case matters; a NULL err is fine */
  CHECK(st == HR_ERR_INVALID && s == NULL, "'Room': status %d", (int)st);
  st = hr_scene_builtin(NULL, &s, &err);
  CHECK(st == HR_ERR_INVALID && s == NULL, "NULL name: status %d", (int)st);
}

int main(void) {
  test_names_and_errors();
  test_room();
  test_floor();
  test_cornell();
  test_museum();
  test_office();
  test_hall();
  return t_done("test_builtin");
}
