/* test_builtin.c: tests of the built-in scenes (src/builtin.c). Sizes (27 polygons for "room",
 * 280-300 for "floor", 3500-4500 for "museum"), emitters and cameras; well-formed surfaces (finite,
 * positive area, aspect ratio below 10); the room closed (its shell area equals the box area
 * computed here from its dimensions); and orientation, the bug that makes a surface silently
 * invisible: interior points lie in front of every enclosing surface and behind every face of a
 * furniture block, and rays shot in many directions from points known to be in the air (room
 * centres, museum cell centres, the cameras) always hit a surface first from its front side, and
 * in closed scenes always hit something. A small ray/triangle test written here is the
 * independent referee. Also: door openings in "floor" let rays through, unknown names fail with
 * HR_ERR_INVALID and the exact message, the name list, determinism. */
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

static void test_names_and_errors(void) {
  const char *const *names = hr_scene_builtin_names();
  const char *want[] = {"room", "floor", "museum", "cornell"};
  int n = 0;
  while (names && names[n]) n++;
  CHECK(n == 4, "%d built-in names, want 4", n);
  for (int i = 0; i < 4 && i < n; i++)
    CHECK(strcmp(names[i], want[i]) == 0, "name %d is '%s', want '%s'", i, names[i], want[i]);
  hr_scene *s = (hr_scene *)&n; /* must be reset to NULL */
  hr_err err = {{0}};
  hr_status st = hr_scene_builtin("nope", &s, &err);
  CHECK(st == HR_ERR_INVALID, "unknown name: status %d", (int)st);
  CHECK(s == NULL, "unknown name: *out not NULL");
  CHECK(strcmp(err.msg, "unknown scene 'nope' (built-in: room, floor, museum, cornell)") == 0,
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
  return t_done("test_builtin");
}
