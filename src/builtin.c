/* builtin.c: the built-in scenes, built from code so that runs, tests and benchmarks need no
 * files (paper section 2.3: the "room" of Figure 4, the "floor" of Figure 5, the ~4000-polygon
 * museum of Figures 8-11), plus the Cornell box as a community reference. Units are metres, y is
 * up, every polygon is counter-clockwise seen from its front (light leaves the front only), every
 * surface faces into the air that the light is in, and every scene is deterministic and carries
 * a camera.
 *
 *   room     A furnished room, 5 x 2.8 x 4 m (x, y, z), of exactly 27 polygons (Figure 4): floor,
 *            ceiling, four walls (the x = 0 wall red for colour bleeding), a 1.2 x 1 m ceiling
 *            light 1 cm below the ceiling (E = 100, 96, 88 W/m^2), a table, a cabinet, a
 *            two-block sofa, a picture, a door and a rug. Camera in a corner near the sofa.
 *   floor    12 such rooms in a 4 x 3 grid (Figure 5), 292 polygons (the paper's has 289),
 *            20.75 x 12.5 m: the walls between rooms are 0.25 m thick (each room has its own
 *            inward-facing wall; the gap between the two faces is solid). Door openings
 *            (0.9 x 2.1 m: left, right and lintel pieces on both sides, two jambs, a soffit and a
 *            threshold in the gap) join every room to its x neighbours and the rows in a snake,
 *            11 doors for one connected floor. Each room has its own light and a differently
 *            coloured accent wall; rooms alternate between two furniture sets. Camera in room
 *            (0,1) looking along +x through a row of aligned doors.
 *   museum   A four-storey gallery, 48 x 18 x 30 m, on a 16 x 10 grid of 3 m cells, 4302
 *            polygons (the paper's Figures 8-11 had about 4000). Each storey is tiled by
 *            rectangular halls (three to five; the layout changes between storeys), each an
 *            inward-facing box with 0.3 m walls between halls and 0.4 m slabs between storeys.
 *            The central hall holds an atrium, open from the ground floor to a skylight, with
 *            parapets along the upper galleries and interior window openings from the wings.
 *            Doors (with jambs, soffit and threshold in the wall gap) join the halls; the outer
 *            walls have windows and, on the ground floor, glass entrance doors (emitters,
 *            E = 40, 44, 52). Ceiling lamps (80, 76, 68), skylights over the atrium and the top
 *            wings (55, 60, 70), plinths, free-standing display walls and benches. Floors and
 *            ceilings are one polygon per cell and walls one panel per cell, so no polygon is
 *            larger than 3 x 4.3 m and no aspect ratio exceeds 9. Camera on the first-floor
 *            gallery behind the parapet, looking across and down the atrium.
 *   cornell  The Cornell box from the Cornell Program of Computer Graphics' published
 *            measurements (mm converted to m; the slightly non-planar red wall becomes two
 *            triangles, so 16 polygons give 17 surfaces), no front wall, McGuire's reflectances and light (E = 17, 12, 4), the
 *            light 0.1 mm below the ceiling, and the published camera (eye 278, 273, -800 mm,
 *            looking along +z, 39.3 degree field of view).
 *   office   A furnished office lit by small bright lamps, 6 x 3 x 5 m (x, y, z), 292 polygons (all
 *            axis-aligned rectangles), for the solver's accuracy where the lights are small and far
 *            brighter than everything else (the walls come out near 0.3-0.5). Four 0.3 m square
 *            ceiling lamps in housings on a 2 x 2 grid, emitting 4 cm below the ceiling
 *            (E = 90, 88, 80 W/m^2), and a desk lamp whose 0.18 m shade bottom emits (75, 65, 50)
 *            0.29 m above its desk: 0.39 m^2 of light, 0.25% of the area. Three desks on 0.08 m
 *            legs (one against the blue x = 0 accent wall, one in the corner at x = 6, z = 0, one
 *            free-standing), two monitors on necks, three chairs (seat, back, four legs), an open
 *            bookshelf against the accent wall (sides, plinth, three shelves, three blocks of
 *            books), a filing cabinet with three drawers and handles, a door, a whiteboard and a
 *            picture 1 cm off their walls and a rug 5 mm above the carpet. Faces that touch the
 *            floor, a wall, the ceiling or another block are left out; thin faces (desk and shelf
 *            edges) are cut into pieces at most 9 times longer than wide. Camera in the corner at
 *            x = 6, z = 5, looking over the free-standing desk toward the accent wall.
 *   hall:N   For scaling runs (N = 1..64; "hall" is hall:4): N x N cells of 4 x 4 m under a 3 m
 *            ceiling, 991 N^2 + 70 N triangles (1061 for N = 1, 1,017,024 for N = 32), every
 *            polygon a triangle, cut as real meshes are. Each cell: a floor of 6 x 6 pieces
 *            graded toward a corner (slivers; T-junctions where cells meet), a 4 x 4 ceiling, a
 *            1 x 0.5 m lamp facing down 0.1 m below the ceiling (E = 150, 144, 132 W/m^2) in a
 *            housing that runs into the ceiling, a table (legs through its top and into the
 *            floor) turned by up to 3 degrees, three chairs (one pushed in so far that its back
 *            passes through the table top), a bookshelf with 21 books whose faces touch, and on
 *            the inner cell lines partitions 2.2 m tall, through the floor, with openings. Thin
 *            faces are fans of slivers (aspect ratio up to 160). Deterministic variation per cell
 *            (book sizes, chair and table turns). The scene is named "hall-N". Camera above the
 *            first cell's corner, looking across the hall.
 */
#include "hrad.h"
#include "vec.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------- building helpers */

/* A scene under construction; the first failure sticks in 'st' and later calls do nothing.
 * 'bad' counts polygons that did not become surfaces: a bug in this file, reported as one. */
typedef struct bld {
  hr_scene *s;
  hr_status st;
  int bad;
} bld;

static int mat(bld *b, const char *name, double r, double g, double bl, double er, double eg,
               double eb) {
  if (b->st != HR_OK) return 0;
  const double rho[3] = {r, g, bl}, e[3] = {er, eg, eb};
  int idx = 0;
  b->st = hr_scene_add_material(b->s, name, rho, e, &idx);
  return idx;
}

static void poly(bld *b, const hr_vec3 *v, int n, int m) {
  if (b->st != HR_OK) return;
  hr_poly_result r;
  b->st = hr_scene_add_polygon(b->s, v, n, m, &r);
  if (b->st == HR_OK && r != HR_POLY_ADDED) b->bad++;
}

static void quad(bld *b, hr_vec3 p0, hr_vec3 p1, hr_vec3 p2, hr_vec3 p3, int m) {
  const hr_vec3 v[4] = {p0, p1, p2, p3};
  poly(b, v, 4, m);
}

/* Face directions: the axis (1 = x, 2 = y, 3 = z) the normal points along, negative for -. */
enum { XP = 1, YP = 2, ZP = 3, XN = -1, YN = -2, ZN = -3 };

static double comp(hr_vec3 p, int a) { return a == 0 ? p.x : a == 1 ? p.y : p.z; }

static void set_comp(hr_vec3 *p, int a, double v) {
  if (a == 0)
    p->x = v;
  else if (a == 1)
    p->y = v;
  else
    p->z = v;
}

/* Axis-aligned rectangle with normal 'dir', in the plane through 'lo' perpendicular to the
 * normal's axis, spanning lo..hi along the two other axes. With the in-plane axes u = a+1 and
 * v = a+2 (mod 3), u x v is +a, so (u0,v0) (u1,v0) (u1,v1) (u0,v1) faces +a. */
static void rect_corners(int dir, hr_vec3 lo, hr_vec3 hi, hr_vec3 q[4]) {
  int a = abs(dir) - 1, u = (a + 1) % 3, v = (a + 2) % 3;
  const double us[4] = {comp(lo, u), comp(hi, u), comp(hi, u), comp(lo, u)};
  const double vs[4] = {comp(lo, v), comp(lo, v), comp(hi, v), comp(hi, v)};
  for (int k = 0; k < 4; k++) {
    int idx = dir > 0 ? k : (4 - k) % 4; /* reversed order faces -a */
    q[k] = lo;
    set_comp(&q[k], u, us[idx]);
    set_comp(&q[k], v, vs[idx]);
  }
}

/* That rectangle as one quad. */
static void rect(bld *b, int dir, hr_vec3 lo, hr_vec3 hi, int m) {
  hr_vec3 q[4];
  rect_corners(dir, lo, hi, q);
  quad(b, q[0], q[1], q[2], q[3], m);
}

/* Vertical rectangle with normal 'dir' (+-x or +-z) in the plane at coordinate 'c', spanning
 * [a0,a1] along the other horizontal axis and [y0,y1] in height. */
static void vrect(bld *b, int dir, double c, double a0, double a1, double y0, double y1, int m) {
  if (abs(dir) == 1)
    rect(b, dir, v3(c, y0, a0), v3(c, y1, a1), m);
  else
    rect(b, dir, v3(a0, y0, c), v3(a1, y1, c), m);
}

/* A rectangular hole in a wall: [h0,h1] along the wall, [y0,y1] in height. */
typedef struct hole {
  double h0, h1, y0, y1;
} hole;

/* Wall face like vrect() with an optional hole: up to four pieces (sill below the hole, the
 * pieces left and right of it, the lintel above), each only where it has extent. When 'glass'
 * >= 0 the hole is filled with a quad of that material facing the same way (a window). */
static void wall(bld *b, int dir, double c, double a0, double a1, double y0, double y1,
                 const hole *h, int m, int glass) {
  if (!h) {
    vrect(b, dir, c, a0, a1, y0, y1, m);
    return;
  }
  if (h->y0 > y0) vrect(b, dir, c, a0, a1, y0, h->y0, m);
  if (h->h0 > a0) vrect(b, dir, c, a0, h->h0, h->y0, h->y1, m);
  if (h->h1 < a1) vrect(b, dir, c, h->h1, a1, h->y0, h->y1, m);
  if (h->y1 < y1) vrect(b, dir, c, a0, a1, h->y1, y1, m);
  if (glass >= 0) vrect(b, dir, c, h->h0, h->h1, h->y0, h->y1, glass);
}

/* Box faces for 'mask'; outward normals. The bottom is usually left out: it rests on a floor. */
enum { F_XN = 1, F_XP = 2, F_YN = 4, F_YP = 8, F_ZN = 16, F_ZP = 32, F_NOBOTTOM = 1 | 2 | 8 | 16 | 32 };

static void box_out(bld *b, hr_vec3 lo, hr_vec3 hi, int m, int mask) {
  if (mask & F_YP) rect(b, YP, v3(lo.x, hi.y, lo.z), hi, m);
  if (mask & F_YN) rect(b, YN, lo, v3(hi.x, lo.y, hi.z), m);
  if (mask & F_XN) rect(b, XN, lo, v3(lo.x, hi.y, hi.z), m);
  if (mask & F_XP) rect(b, XP, v3(hi.x, lo.y, lo.z), hi, m);
  if (mask & F_ZN) rect(b, ZN, lo, v3(hi.x, hi.y, lo.z), m);
  if (mask & F_ZP) rect(b, ZP, v3(lo.x, lo.y, hi.z), hi, m);
}

static void set_camera(hr_scene *s, hr_vec3 eye, hr_vec3 at, double fov) {
  s->has_camera = 1;
  s->camera.eye = eye;
  s->camera.at = at;
  s->camera.up = v3(0, 1, 0);
  s->camera.fov_deg = fov;
}

/* The gap of a door or window opening through a thick wall: the wall's two faces lie in the
 * planes 'axis' = c0 and c1 (c0 < c1; axis 0 = x, 2 = z) and both have hole 'h'. Adds the two
 * jambs, the soffit and the sill (the threshold, for a door), all facing into the opening. */
static void tunnel(bld *b, int axis, double c0, double c1, const hole *h, int m) {
  if (axis == 0) {
    rect(b, ZP, v3(c0, h->y0, h->h0), v3(c1, h->y1, h->h0), m);
    rect(b, ZN, v3(c0, h->y0, h->h1), v3(c1, h->y1, h->h1), m);
    rect(b, YN, v3(c0, h->y1, h->h0), v3(c1, h->y1, h->h1), m);
    rect(b, YP, v3(c0, h->y0, h->h0), v3(c1, h->y0, h->h1), m);
  } else {
    rect(b, XP, v3(h->h0, h->y0, c0), v3(h->h0, h->y1, c1), m);
    rect(b, XN, v3(h->h1, h->y0, c0), v3(h->h1, h->y1, c1), m);
    rect(b, YN, v3(h->h0, h->y1, c0), v3(h->h1, h->y1, c1), m);
    rect(b, YP, v3(h->h0, h->y0, c0), v3(h->h1, h->y0, c1), m);
  }
}

/* ---------------------------------------------------------------- room and floor */

#define ROOM_W 5.0 /* x */
#define ROOM_H 2.8 /* y */
#define ROOM_D 4.0 /* z */
#define DOOR_H 2.1
/* Door openings (and the room's door leaf) lie at local x in [0.5,1.4] in the z walls and at
 * local z in [D-1.4, D-0.5] in the x walls, so furniture never blocks them and the doors of a
 * row or column line up. */
#define DOOR_A0 0.5
#define DOOR_A1 1.4
#define FLOOR_T 0.25 /* thickness of the walls between the rooms of "floor" */

/* Walls of a room, in polygon order. */
enum { W_ZLO = 0, W_ZHI, W_XLO, W_XHI };

/* Furniture and decoration of a room. */
enum {
  RF_TABLE = 1,   /* 1.6 x 0.9 x 0.75 block: top and four sides (5 polygons) */
  RF_CABINET = 2, /* against the z = 0 wall: top, front, two sides (4) */
  RF_SOFA = 4,    /* seat and backrest against the x = W wall (8) */
  RF_PICTURE = 8, /* 1 cm in front of the x = 0 wall (1) */
  RF_DOOR = 16,   /* a closed door leaf 1 cm in front of the z = D wall, where "floor" has its
                     openings (1) */
  RF_RUG = 32     /* 5 mm above the floor (1) */
};

typedef struct room_mats {
  int floor, ceil, wall, accent, light, table, cabinet, sofa, picture, door, rug;
} room_mats;

/* Door holes of a room with its low corner at (x0, z0): in the z walls (along x) and in the x
 * walls (along z). */
static hole room_door_z(double x0) { return (hole){x0 + DOOR_A0, x0 + DOOR_A1, 0, DOOR_H}; }
static hole room_door_x(double z0) {
  return (hole){z0 + ROOM_D - DOOR_A1, z0 + ROOM_D - DOOR_A0, 0, DOOR_H};
}

/* One room (its inside is the box (x0,0,z0)-(x0+W,H,z0+D), all faces inward). Bit w of 'doors'
 * cuts a door opening into wall w (lintel, left and right pieces instead of one quad). Polygon
 * order: floor, ceiling, walls (z = 0, z = D, x = 0 (accent), x = W), light, table, cabinet, sofa
 * seat, backrest, picture, door leaf, rug: for "room" 0, 1, 2-5, 6, 7-11, 12-15, 16-19, 20-23,
 * 24, 25, 26. */
static void room(bld *b, double x0, double z0, unsigned doors, unsigned furn,
                 const room_mats *m) {
  const double W = ROOM_W, H = ROOM_H, D = ROOM_D;
  const double x1 = x0 + W, z1 = z0 + D;
  rect(b, YP, v3(x0, 0, z0), v3(x1, 0, z1), m->floor);
  rect(b, YN, v3(x0, H, z0), v3(x1, H, z1), m->ceil);
  const hole hz = room_door_z(x0), hx = room_door_x(z0);
  wall(b, ZP, z0, x0, x1, 0, H, (doors >> W_ZLO) & 1 ? &hz : NULL, m->wall, -1);
  wall(b, ZN, z1, x0, x1, 0, H, (doors >> W_ZHI) & 1 ? &hz : NULL, m->wall, -1);
  wall(b, XP, x0, z0, z1, 0, H, (doors >> W_XLO) & 1 ? &hx : NULL, m->accent, -1);
  wall(b, XN, x1, z0, z1, 0, H, (doors >> W_XHI) & 1 ? &hx : NULL, m->wall, -1);
  /* Ceiling light over the table, facing down, 1 cm below the ceiling. */
  rect(b, YN, v3(x0 + 1.9, H - 0.01, z0 + 1.5), v3(x0 + 3.1, H - 0.01, z0 + 2.5), m->light);
  if (furn & RF_TABLE)
    box_out(b, v3(x0 + 1.6, 0, z0 + 1.5), v3(x0 + 3.2, 0.75, z0 + 2.4), m->table, F_NOBOTTOM);
  if (furn & RF_CABINET) /* back against the wall: no back face */
    box_out(b, v3(x0 + 2.0, 0, z0), v3(x0 + 3.4, 0.9, z0 + 0.5), m->cabinet,
            F_YP | F_XN | F_XP | F_ZP);
  if (furn & RF_SOFA) {
    /* Seat in front of the backrest; the backrest's front starts above the seat. */
    box_out(b, v3(x0 + 4.1, 0, z0 + 0.6), v3(x0 + 4.75, 0.42, z0 + 2.4), m->sofa,
            F_YP | F_XN | F_ZN | F_ZP);
    box_out(b, v3(x0 + 4.75, 0, z0 + 0.6), v3(x1, 0.85, z0 + 2.4), m->sofa, F_YP | F_ZN | F_ZP);
    vrect(b, XN, x0 + 4.75, z0 + 0.6, z0 + 2.4, 0.42, 0.85, m->sofa);
  }
  if (furn & RF_PICTURE) vrect(b, XP, x0 + 0.01, z0 + 0.7, z0 + 2.1, 1.2, 2.0, m->picture);
  if (furn & RF_DOOR) vrect(b, ZN, z1 - 0.01, x0 + DOOR_A0, x0 + DOOR_A1, 0, DOOR_H, m->door);
  if (furn & RF_RUG)
    rect(b, YP, v3(x0 + 2.0, 0.005, z0 + 2.7), v3(x0 + 3.8, 0.005, z0 + 3.6), m->rug);
}

/* Materials shared by "room" and "floor"; the accent wall is red. */
static void room_materials(bld *b, room_mats *m) {
  m->floor = mat(b, "floor", 0.55, 0.40, 0.26, 0, 0, 0);
  m->ceil = mat(b, "ceiling", 0.80, 0.80, 0.78, 0, 0, 0);
  m->wall = mat(b, "wall", 0.75, 0.74, 0.70, 0, 0, 0);
  m->accent = mat(b, "wall_red", 0.70, 0.18, 0.12, 0, 0, 0);
  m->light = mat(b, "light", 0.80, 0.80, 0.80, 100, 96, 88);
  m->table = mat(b, "table", 0.45, 0.30, 0.18, 0, 0, 0);
  m->cabinet = mat(b, "cabinet", 0.62, 0.60, 0.55, 0, 0, 0);
  m->sofa = mat(b, "sofa", 0.20, 0.45, 0.25, 0, 0, 0);
  m->picture = mat(b, "picture", 0.80, 0.68, 0.20, 0, 0, 0);
  m->door = mat(b, "door", 0.40, 0.26, 0.15, 0, 0, 0);
  m->rug = mat(b, "rug", 0.20, 0.25, 0.60, 0, 0, 0);
}

static void build_room(bld *b) {
  room_mats m;
  room_materials(b, &m);
  room(b, 0, 0, 0, RF_TABLE | RF_CABINET | RF_SOFA | RF_PICTURE | RF_DOOR | RF_RUG, &m);
  /* From the corner beyond the sofa, over the rug, toward the red wall and the cabinet. */
  set_camera(b->s, v3(4.55, 1.65, 3.7), v3(1.6, 1.05, 0.9), 60);
}

#define FLOOR_NI 4 /* rooms along x */
#define FLOOR_NJ 3 /* rooms along z */

/* Doors of "floor": every room opens to its x neighbours (rows are chains); row 0 joins row 1
 * in column 0 and row 1 joins row 2 in column 3, so all 12 rooms form one path of 11 doors. */
static int floor_zdoor(int i, int j) { return (j == 0 && i == 0) || (j == 1 && i == FLOOR_NI - 1); }

static void build_floor(bld *b) {
  const double PX = ROOM_W + FLOOR_T, PZ = ROOM_D + FLOOR_T; /* room pitch */
  room_mats m;
  room_materials(b, &m);
  int accents[4];
  accents[0] = m.accent;
  accents[1] = mat(b, "wall_blue", 0.20, 0.30, 0.62, 0, 0, 0);
  accents[2] = mat(b, "wall_green", 0.22, 0.50, 0.28, 0, 0, 0);
  accents[3] = mat(b, "wall_ochre", 0.78, 0.58, 0.25, 0, 0, 0);
  for (int j = 0; j < FLOOR_NJ; j++)
    for (int i = 0; i < FLOOR_NI; i++) {
      double x0 = i * PX, z0 = j * PZ;
      unsigned doors = 0;
      if (i > 0) doors |= 1u << W_XLO;
      if (i < FLOOR_NI - 1) doors |= 1u << W_XHI;
      if (j > 0 && floor_zdoor(i, j - 1)) doors |= 1u << W_ZLO;
      if (j < FLOOR_NJ - 1 && floor_zdoor(i, j)) doors |= 1u << W_ZHI;
      /* Two furniture sets in a checkerboard, 11 and 9 polygons. Total: 12 rooms x 7 (shell
       * and light) + 11 doors x 8 (2 x 2 extra wall pieces, 2 jambs, soffit, threshold)
       * + 6 x 11 + 6 x 9 = 292. */
      unsigned furn = (i + j) % 2 == 0 ? RF_TABLE | RF_CABINET | RF_PICTURE | RF_RUG
                                       : RF_SOFA | RF_PICTURE;
      room_mats rm = m;
      rm.accent = accents[(i + 2 * j) % 4];
      room(b, x0, z0, doors, furn, &rm);
      /* The door gaps through the walls to the +x and +z neighbours. */
      if (i < FLOOR_NI - 1) {
        hole h = room_door_x(z0);
        tunnel(b, 0, x0 + ROOM_W, x0 + PX, &h, m.wall);
      }
      if (j < FLOOR_NJ - 1 && floor_zdoor(i, j)) {
        hole h = room_door_z(x0);
        tunnel(b, 2, z0 + ROOM_D, z0 + PZ, &h, m.wall);
      }
    }
  /* In room (0,1) at its x = 0 wall, looking along +x through the row of aligned doors. */
  double zc = PZ + ROOM_D - 0.5 * (DOOR_A0 + DOOR_A1);
  set_camera(b->s, v3(0.35, 1.55, zc + 0.1), v3(FLOOR_NI * PX, 1.05, zc), 62);
}

/* ---------------------------------------------------------------- museum */

#define MU_C 3.0  /* cell size */
#define MU_NX 16  /* cells along x */
#define MU_NZ 10  /* cells along z */
#define MU_NS 4   /* storeys */
#define MU_SH 4.5 /* storey height (slab centre to slab centre) */
#define MU_T 0.3  /* wall thickness between halls, centred on cell lines */
#define MU_S 0.4  /* slab thickness between storeys, centred on k * MU_SH */
#define MU_P 0.4  /* parapet thickness */
#define MU_PH 1.1 /* parapet height */

/* Halls: rectangles of cells [i0,i1) x [j0,j1), tiling the storey. Hall 'C' (index MU_CENTRE)
 * is the central hall [6,10) x [0,10); above the ground floor its cells [6,10) x [3,7) are the
 * atrium void, open from the ground floor to the skylight. */
typedef struct mu_rect {
  int i0, j0, i1, j1;
} mu_rect;
#define MU_CENTRE 0
#define MU_MAXH 5
static const int mu_nhalls[MU_NS] = {5, 5, 5, 3};
static const mu_rect mu_halls[MU_NS][MU_MAXH] = {
    {{6, 0, 10, 10}, {0, 0, 6, 5}, {0, 5, 6, 10}, {10, 0, 16, 5}, {10, 5, 16, 10}},
    {{6, 0, 10, 10}, {0, 0, 6, 5}, {0, 5, 6, 10}, {10, 0, 13, 10}, {13, 0, 16, 10}},
    {{6, 0, 10, 10}, {0, 0, 6, 5}, {0, 5, 6, 10}, {10, 0, 16, 5}, {10, 5, 16, 10}},
    {{6, 0, 10, 10}, {0, 0, 6, 10}, {10, 0, 16, 10}, {0, 0, 0, 0}, {0, 0, 0, 0}}};
#define MU_VI0 6 /* void cells [6,10) x [3,7) */
#define MU_VI1 10
#define MU_VJ0 3
#define MU_VJ1 7

static int mu_is_void(int k, int i, int j) {
  return k > 0 && i >= MU_VI0 && i < MU_VI1 && j >= MU_VJ0 && j < MU_VJ1;
}

/* Hall index of cell (i,j) on storey 'k', or -1 outside the building. */
static int mu_hall_at(int k, int i, int j) {
  for (int h = 0; h < mu_nhalls[k]; h++) {
    const mu_rect *r = &mu_halls[k][h];
    if (i >= r->i0 && i < r->i1 && j >= r->j0 && j < r->j1) return h;
  }
  return -1;
}

typedef struct mu_mats {
  int stone, wood, ceil, white, hall[5], parapet, plinth, display, bench, lamp, sky, window;
} mu_mats;

static double mu_floor_y(int k) { return k * MU_SH + (k > 0 ? 0.5 * MU_S : 0); }
static double mu_ceil_y(int k) { return (k + 1) * MU_SH - (k < MU_NS - 1 ? 0.5 * MU_S : 0); }

/* Inner box of hall 'r': cell bounds, pulled in by half a wall where another hall is beyond. */
static void mu_inner(const mu_rect *r, double *x0, double *x1, double *z0, double *z1) {
  *x0 = r->i0 * MU_C + (r->i0 > 0 ? 0.5 * MU_T : 0);
  *x1 = r->i1 * MU_C - (r->i1 < MU_NX ? 0.5 * MU_T : 0);
  *z0 = r->j0 * MU_C + (r->j0 > 0 ? 0.5 * MU_T : 0);
  *z1 = r->j1 * MU_C - (r->j1 < MU_NZ ? 0.5 * MU_T : 0);
}

/* Kinds of wall panels (one cell wide). */
enum { E_WALL, E_DOOR, E_OPENING, E_WINDOW, E_ENTRANCE };

/* Panel kind at cell 'c' along a wall line between halls 'a' and 'b' (b = -1: outside) on
 * storey 'k'; 'vd' marks a panel whose far or near side is the atrium void; 'south' marks the
 * building's z = max facade. */
static int mu_panel_kind(int k, int b, int c, int vd, int south) {
  if (b < 0) {
    if (k == 0 && south && (c == 7 || c == 8)) return E_ENTRANCE;
    return c % 3 == 1 ? E_WALL : E_WINDOW;
  }
  if (vd) return c % 2 == 0 ? E_OPENING : E_WALL;
  return c % 3 == 1 ? E_DOOR : E_WALL;
}

static hole mu_hole(int kind, double a0, double y0) {
  switch (kind) {
  case E_DOOR: return (hole){a0 + 0.9, a0 + MU_C - 0.9, y0, y0 + 2.7};
  case E_ENTRANCE: return (hole){a0 + 0.6, a0 + MU_C - 0.6, y0, y0 + 3.2};
  default: return (hole){a0 + 0.6, a0 + MU_C - 0.6, y0 + 1.0, y0 + 3.4};
  }
}

/* Material of the walls of hall 'h' on storey 'k'. */
static int mu_wall_mat(const mu_mats *m, int k, int h) {
  return h == MU_CENTRE ? m->white : m->hall[(h + 2 * k) % 5];
}

/* One side of hall 'h' on storey 'k': the wall line 'axis' = 'c' (axis 0: x = c, facing 'dir'
 * into the hall; axis 2: z = c), made of one panel per cell 'q' in [q0, q1) along it, clipped
 * to [a0, a1]. 'nq' is the cell index just beyond the line (on the far side). Openings to the
 * neighbour get their tunnel from the hall on the low side only. */
static void mu_side(bld *b, const mu_mats *m, int k, int h, int axis, int dir, double c,
                    int q0, int q1, double a0, double a1, int nq) {
  double y0 = mu_floor_y(k), y1 = mu_ceil_y(k);
  int wm = mu_wall_mat(m, k, h);
  int d = dir > 0 ? 1 : -1; /* from the far cell's row or column to the near one's */
  for (int q = q0; q < q1; q++) {
    int ni = axis == 0 ? nq : q, nj = axis == 0 ? q : nq;         /* far cell */
    int hi = axis == 0 ? nq + d : q, hj = axis == 0 ? q : nq + d; /* near cell */
    int nb = (ni < 0 || nj < 0 || ni >= MU_NX || nj >= MU_NZ) ? -1 : mu_hall_at(k, ni, nj);
    int vd = mu_is_void(k, ni, nj) || mu_is_void(k, hi, hj);
    int kind = mu_panel_kind(k, nb, q, vd, axis == 2 && nj == MU_NZ);
    double p0 = fmax(a0, q * MU_C), p1 = fmin(a1, (q + 1) * MU_C);
    if (kind == E_WALL) {
      vrect(b, dir, c, p0, p1, y0, y1, wm);
      continue;
    }
    hole ho = mu_hole(kind, q * MU_C, y0);
    int glass = nb < 0 ? m->window : -1;
    wall(b, dir, c, p0, p1, y0, y1, &ho, wm, glass);
    /* The gap between the two halls' faces is added once, by the hall on the low side (whose
     * face here points toward -axis). */
    if (nb >= 0 && dir < 0) tunnel(b, axis, c, c + MU_T, &ho, wm);
  }
}

/* Deterministic per-cell selector in [0, 12). */
static int mu_hash(int k, int i, int j) { return (i * 5 + j * 11 + k * 7 + (i * j) % 3) % 12; }

/* Floor tile, ceiling tile (or skylight), lamp and furniture of cell (i,j) of hall 'h'. */
static void mu_cell(bld *b, const mu_mats *m, int k, int h, int i, int j, double x0, double x1,
                    double z0, double z1) {
  const mu_rect *r = &mu_halls[k][h];
  double cx0 = fmax(x0, i * MU_C), cx1 = fmin(x1, (i + 1) * MU_C);
  double cz0 = fmax(z0, j * MU_C), cz1 = fmin(z1, (j + 1) * MU_C);
  double yf = mu_floor_y(k), yc = mu_ceil_y(k), xc = (i + 0.5) * MU_C, zc = (j + 0.5) * MU_C;
  int top = k == MU_NS - 1, vd = mu_is_void(k, i, j);
  if (!vd) {
    /* Upper-floor galleries stop at the parapets beside the void. */
    double fz0 = cz0, fz1 = cz1;
    if (k > 0 && h == MU_CENTRE && j == MU_VJ0 - 1) fz1 = MU_VJ0 * MU_C - MU_P;
    if (k > 0 && h == MU_CENTRE && j == MU_VJ1) fz0 = MU_VJ1 * MU_C + MU_P;
    rect(b, YP, v3(cx0, yf, fz0), v3(cx1, yf, fz1), k == 0 ? m->stone : m->wood);
  }
  if (top || !mu_is_void(k + 1, i, j)) {
    /* Skylights over the void and over every other top-floor wing cell; lamps elsewhere. */
    int sky = top && (vd || (h != MU_CENTRE && (i + j) % 2 == 0));
    rect(b, YN, v3(cx0, yc, cz0), v3(cx1, yc, cz1), sky ? m->sky : m->ceil);
    if (!sky && (i + j + k) % 2 == 0)
      rect(b, YN, v3(xc - 0.6, yc - 0.02, zc - 0.6), v3(xc + 0.6, yc - 0.02, zc + 0.6), m->lamp);
  }
  if (vd) return;
  if (h == MU_CENTRE && j >= MU_VJ0 && j < MU_VJ1) { /* ground floor of the atrium */
    if ((i + j) % 2 == 0)
      box_out(b, v3(xc - 0.9, yf, zc - 0.25), v3(xc + 0.9, yf + 0.45, zc + 0.25), m->bench,
              F_NOBOTTOM);
    return;
  }
  int sel = mu_hash(k, i, j);
  int inner = i > r->i0 && i < r->i1 - 1 && j > r->j0 && j < r->j1 - 1;
  if (h != MU_CENTRE && inner && (sel == 0 || sel == 6)) { /* display wall, 3 m tall */
    if ((i + j) % 2)
      box_out(b, v3(xc - 1.1, yf, zc - 0.2), v3(xc + 1.1, yf + 3.0, zc + 0.2), m->display,
              F_NOBOTTOM);
    else
      box_out(b, v3(xc - 0.2, yf, zc - 1.1), v3(xc + 0.2, yf + 3.0, zc + 1.1), m->display,
              F_NOBOTTOM);
  } else if (sel % 3 == 1 || sel == 8) { /* plinth, 0.6-1.0 m wide, 0.8-1.2 m tall */
    double w = 0.3 + 0.1 * (sel % 3), ht = 0.8 + 0.1 * (sel % 5);
    box_out(b, v3(xc - w, yf, zc - w), v3(xc + w, yf + ht, zc + w), m->plinth, F_NOBOTTOM);
  }
}

/* The central hall's share of the atrium on storey k >= 1: parapets along the void's north and
 * south edges (their void-side face reaches down to the ceiling of the storey below, covering
 * the slab's edge), and the slab-thick strips of its walls beside the void below this floor. */
static void mu_atrium(bld *b, const mu_mats *m, int k, double x0, double x1) {
  double yf = mu_floor_y(k), yb = mu_ceil_y(k - 1), yp = yf + MU_PH;
  double zn = MU_VJ0 * MU_C, zs = MU_VJ1 * MU_C;
  for (int i = MU_VI0; i < MU_VI1; i++) {
    double a0 = fmax(x0, i * MU_C), a1 = fmin(x1, (i + 1) * MU_C);
    vrect(b, ZP, zn, a0, a1, yb, yp, m->parapet);          /* into the void */
    vrect(b, ZN, zn - MU_P, a0, a1, yf, yp, m->parapet);   /* into the gallery */
    rect(b, YP, v3(a0, yp, zn - MU_P), v3(a1, yp, zn), m->parapet);
    vrect(b, ZN, zs, a0, a1, yb, yp, m->parapet);
    vrect(b, ZP, zs + MU_P, a0, a1, yf, yp, m->parapet);
    rect(b, YP, v3(a0, yp, zs), v3(a1, yp, zs + MU_P), m->parapet);
  }
  for (int j = MU_VJ0; j < MU_VJ1; j++) {
    vrect(b, XP, x0, j * MU_C, (j + 1) * MU_C, yb, yf, m->white);
    vrect(b, XN, x1, j * MU_C, (j + 1) * MU_C, yb, yf, m->white);
  }
}

static void build_museum(bld *b) {
  mu_mats m;
  m.stone = mat(b, "stone", 0.55, 0.52, 0.48, 0, 0, 0);
  m.wood = mat(b, "parquet", 0.50, 0.36, 0.22, 0, 0, 0);
  m.ceil = mat(b, "ceiling", 0.80, 0.80, 0.80, 0, 0, 0);
  m.white = mat(b, "wall_white", 0.78, 0.77, 0.74, 0, 0, 0);
  m.hall[0] = mat(b, "wall_warm", 0.76, 0.70, 0.60, 0, 0, 0);
  m.hall[1] = mat(b, "wall_red", 0.62, 0.20, 0.15, 0, 0, 0);
  m.hall[2] = mat(b, "wall_blue", 0.22, 0.32, 0.58, 0, 0, 0);
  m.hall[3] = mat(b, "wall_green", 0.28, 0.48, 0.32, 0, 0, 0);
  m.hall[4] = mat(b, "wall_ochre", 0.76, 0.60, 0.30, 0, 0, 0);
  m.parapet = mat(b, "parapet", 0.60, 0.60, 0.62, 0, 0, 0);
  m.plinth = mat(b, "plinth", 0.85, 0.85, 0.82, 0, 0, 0);
  m.display = mat(b, "display_wall", 0.35, 0.35, 0.38, 0, 0, 0);
  m.bench = mat(b, "bench", 0.40, 0.28, 0.18, 0, 0, 0);
  m.lamp = mat(b, "lamp", 0.80, 0.80, 0.80, 80, 76, 68);
  m.sky = mat(b, "skylight", 0.10, 0.10, 0.10, 55, 60, 70);
  m.window = mat(b, "window", 0.10, 0.10, 0.10, 40, 44, 52);
  for (int k = 0; k < MU_NS; k++)
    for (int h = 0; h < mu_nhalls[k]; h++) {
      const mu_rect *r = &mu_halls[k][h];
      double x0, x1, z0, z1;
      mu_inner(r, &x0, &x1, &z0, &z1);
      for (int j = r->j0; j < r->j1; j++)
        for (int i = r->i0; i < r->i1; i++) mu_cell(b, &m, k, h, i, j, x0, x1, z0, z1);
      mu_side(b, &m, k, h, 2, ZP, z0, r->i0, r->i1, x0, x1, r->j0 - 1);
      mu_side(b, &m, k, h, 2, ZN, z1, r->i0, r->i1, x0, x1, r->j1);
      mu_side(b, &m, k, h, 0, XP, x0, r->j0, r->j1, z0, z1, r->i0 - 1);
      mu_side(b, &m, k, h, 0, XN, x1, r->j0, r->j1, z0, z1, r->i1);
      if (h == MU_CENTRE && k > 0) mu_atrium(b, &m, k, x0, x1);
    }
  /* On the first-floor north gallery behind the parapet, looking across and down the atrium. */
  set_camera(b->s, v3(20.0, mu_floor_y(1) + 1.8, 8.25), v3(27.0, 1.0, 19.0), 70);
}

/* ---------------------------------------------------------------- cornell */

/* The Cornell box, published data in mm (x, y, z); quads in published order and winding. */
static const double cb_floor[4][3] = {
    {552.8, 0.0, 0.0}, {0.0, 0.0, 0.0}, {0.0, 0.0, 559.2}, {549.6, 0.0, 559.2}};
static const double cb_ceiling[4][3] = {
    {556.0, 548.8, 0.0}, {556.0, 548.8, 559.2}, {0.0, 548.8, 559.2}, {0.0, 548.8, 0.0}};
static const double cb_back[4][3] = {
    {549.6, 0.0, 559.2}, {0.0, 0.0, 559.2}, {0.0, 548.8, 559.2}, {556.0, 548.8, 559.2}};
static const double cb_right[4][3] = { /* green, x = 0 */
    {0.0, 0.0, 559.2}, {0.0, 0.0, 0.0}, {0.0, 548.8, 0.0}, {0.0, 548.8, 559.2}};
static const double cb_left[4][3] = { /* red, x ~ 556 */
    {552.8, 0.0, 0.0}, {549.6, 0.0, 559.2}, {556.0, 548.8, 559.2}, {556.0, 548.8, 0.0}};
/* Published at y = 548.8 like the ceiling; lowered 0.1 mm so the two do not coincide. */
static const double cb_light[4][3] = {
    {343.0, 548.7, 227.0}, {343.0, 548.7, 332.0}, {213.0, 548.7, 332.0}, {213.0, 548.7, 227.0}};
static const double cb_short[5][4][3] = {
    {{130.0, 165.0, 65.0}, {82.0, 165.0, 225.0}, {240.0, 165.0, 272.0}, {290.0, 165.0, 114.0}},
    {{290.0, 0.0, 114.0}, {290.0, 165.0, 114.0}, {240.0, 165.0, 272.0}, {240.0, 0.0, 272.0}},
    {{130.0, 0.0, 65.0}, {130.0, 165.0, 65.0}, {290.0, 165.0, 114.0}, {290.0, 0.0, 114.0}},
    {{82.0, 0.0, 225.0}, {82.0, 165.0, 225.0}, {130.0, 165.0, 65.0}, {130.0, 0.0, 65.0}},
    {{240.0, 0.0, 272.0}, {240.0, 165.0, 272.0}, {82.0, 165.0, 225.0}, {82.0, 0.0, 225.0}}};
static const double cb_tall[5][4][3] = {
    {{423.0, 330.0, 247.0}, {265.0, 330.0, 296.0}, {314.0, 330.0, 456.0}, {472.0, 330.0, 406.0}},
    {{423.0, 0.0, 247.0}, {423.0, 330.0, 247.0}, {472.0, 330.0, 406.0}, {472.0, 0.0, 406.0}},
    {{472.0, 0.0, 406.0}, {472.0, 330.0, 406.0}, {314.0, 330.0, 456.0}, {314.0, 0.0, 456.0}},
    {{314.0, 0.0, 456.0}, {314.0, 330.0, 456.0}, {265.0, 330.0, 296.0}, {265.0, 0.0, 296.0}},
    {{265.0, 0.0, 296.0}, {265.0, 330.0, 296.0}, {423.0, 330.0, 247.0}, {423.0, 0.0, 247.0}}};

static void cb_quad(bld *b, const double q[4][3], int m) {
  hr_vec3 v[4];
  for (int k = 0; k < 4; k++) v[k] = v3(q[k][0] * 1e-3, q[k][1] * 1e-3, q[k][2] * 1e-3);
  poly(b, v, 4, m);
}

/* Polygon order: floor, ceiling, back, right (green), left (red), light, short block (top
 * first, 6-10), tall block (top first, 11-15). Material names follow McGuire's OBJ. */
static void build_cornell(bld *b) {
  int floor = mat(b, "floor", 0.725, 0.71, 0.68, 0, 0, 0);
  int ceiling = mat(b, "ceiling", 0.725, 0.71, 0.68, 0, 0, 0);
  int back = mat(b, "backWall", 0.725, 0.71, 0.68, 0, 0, 0);
  int right = mat(b, "rightWall", 0.14, 0.45, 0.091, 0, 0, 0);
  int left = mat(b, "leftWall", 0.63, 0.065, 0.05, 0, 0, 0);
  int light = mat(b, "light", 0.78, 0.78, 0.78, 17, 12, 4);
  int sbox = mat(b, "shortBox", 0.725, 0.71, 0.68, 0, 0, 0);
  int tbox = mat(b, "tallBox", 0.725, 0.71, 0.68, 0, 0, 0);
  cb_quad(b, cb_floor, floor);
  cb_quad(b, cb_ceiling, ceiling);
  cb_quad(b, cb_back, back);
  cb_quad(b, cb_right, right);
  cb_quad(b, cb_left, left);
  cb_quad(b, cb_light, light);
  for (int f = 0; f < 5; f++) cb_quad(b, cb_short[f], sbox);
  for (int f = 0; f < 5; f++) cb_quad(b, cb_tall[f], tbox);
  /* Published camera: 35 mm focal length, 25 mm film: fov = 2 atan(12.5 / 35). */
  set_camera(b->s, v3(0.278, 0.273, -0.800), v3(0.278, 0.273, 0.2796),
             2.0 * atan(12.5 / 35.0) * 180.0 / M_PI);
}

/* ---------------------------------------------------------------- office */

#define OF_W 6.0       /* x */
#define OF_H 3.0       /* y */
#define OF_D 5.0       /* z */
#define OF_SPLIT 9.0   /* furniture faces longer than this many widths are cut into pieces */
#define OF_DESK_H 0.75 /* desk top height */
#define OF_DESK_T 0.06 /* desk top thickness */

enum { F_ALL = F_NOBOTTOM | F_YN, F_SIDES = F_XN | F_XP | F_ZN | F_ZP };

typedef struct of_mats {
  int floor, ceil, wall, accent, lamp, desk_lamp, housing, shade, desk, metal, monitor, screen,
      chair, shelf, book[3], cabinet, door, whiteboard, picture, rug;
} of_mats;

/* The box_out() bit of the face with normal 'dir'. */
static int face_bit(int dir) {
  switch (dir) {
  case XN: return F_XN;
  case XP: return F_XP;
  case YN: return F_YN;
  case YP: return F_YP;
  case ZN: return F_ZN;
  default: return F_ZP;
  }
}

/* rect(), cut across its longer side into the fewest equal pieces that are at most OF_SPLIT
 * times longer than wide (a desk top's edge, a shelf's front): no slivers. Neighbouring pieces
 * get their common coordinate from the same expression, so they share edges exactly. */
static void rect_split(bld *b, int dir, hr_vec3 lo, hr_vec3 hi, int m) {
  int a = abs(dir) - 1, u = (a + 1) % 3, v = (a + 2) % 3;
  double du = comp(hi, u) - comp(lo, u), dv = comp(hi, v) - comp(lo, v);
  int ax = du >= dv ? u : v;
  double l = fmax(du, dv), w = fmin(du, dv);
  int n = w > 0 ? (int)ceil(l / (OF_SPLIT * w)) : 1;
  if (n < 1) n = 1;
  for (int k = 0; k < n; k++) {
    hr_vec3 p = lo, q = hi;
    set_comp(&p, ax, comp(lo, ax) + l * k / n);
    if (k + 1 < n) set_comp(&q, ax, comp(lo, ax) + l * (k + 1) / n);
    rect(b, dir, p, q, m);
  }
}

/* box_out() with rect_split() faces, in the same face order (+y, -y, -x, +x, -z, +z). */
static void of_box(bld *b, hr_vec3 lo, hr_vec3 hi, int m, int mask) {
  if (mask & F_YP) rect_split(b, YP, v3(lo.x, hi.y, lo.z), hi, m);
  if (mask & F_YN) rect_split(b, YN, lo, v3(hi.x, lo.y, hi.z), m);
  if (mask & F_XN) rect_split(b, XN, lo, v3(lo.x, hi.y, hi.z), m);
  if (mask & F_XP) rect_split(b, XP, v3(hi.x, lo.y, lo.z), hi, m);
  if (mask & F_ZN) rect_split(b, ZN, lo, v3(hi.x, hi.y, lo.z), m);
  if (mask & F_ZP) rect_split(b, ZP, v3(lo.x, lo.y, hi.z), hi, m);
}

/* Ceiling lamp centred on (cx, cz): a 0.3 m square emitter facing down 4 cm below the ceiling,
 * then the four sides of its housing (5 polygons). */
static void of_ceiling_lamp(bld *b, double cx, double cz, const of_mats *m) {
  const double h = 0.15, y = OF_H - 0.04;
  rect(b, YN, v3(cx - h, y, cz - h), v3(cx + h, y, cz + h), m->lamp);
  of_box(b, v3(cx - h, y, cz - h), v3(cx + h, OF_H, cz + h), m->housing, F_SIDES);
}

/* Desk: a 0.06 m top at 0.75 m over [x0,x1] x [z0,z1] (its edges cut by rect_split), without
 * the edge faces in 'against' (they touch a wall), then four 0.08 m square legs inset 4 cm
 * (4 sides each: they stand on the floor and carry the top). */
static void of_desk(bld *b, double x0, double z0, double x1, double z1, int against,
                    const of_mats *m) {
  const double yb = OF_DESK_H - OF_DESK_T, lw = 0.08, li = 0.04;
  of_box(b, v3(x0, yb, z0), v3(x1, OF_DESK_H, z1), m->desk, F_ALL & ~against);
  for (int i = 0; i < 4; i++) {
    double x = i & 1 ? x1 - li - lw : x0 + li, z = i & 2 ? z1 - li - lw : z0 + li;
    of_box(b, v3(x, 0, z), v3(x + lw, yb, z + lw), m->metal, F_SIDES);
  }
}

/* Monitor on a desk top, centred on (cx, cz) and facing 'dir' (+-x or +-z): a 0.52 x 0.32 x
 * 0.06 m case whose front is the screen, on a 0.10 x 0.14 x 0.03 m neck. Polygons: case (5),
 * screen (1), neck (4). */
static void of_monitor(bld *b, double cx, double cz, int dir, const of_mats *m) {
  const double y0 = OF_DESK_H, yn = y0 + 0.14, y1 = yn + 0.32;
  const double hw = 0.26, hd = 0.03, nw = 0.05, nd = 0.015;
  int fx = abs(dir) == 1; /* facing along x: the width runs along z */
  double wx = fx ? hd : hw, wz = fx ? hw : hd, nx = fx ? nd : nw, nz = fx ? nw : nd;
  hr_vec3 lo = v3(cx - wx, yn, cz - wz), hi = v3(cx + wx, y1, cz + wz);
  of_box(b, lo, hi, m->monitor, F_ALL & ~face_bit(dir));
  of_box(b, lo, hi, m->screen, face_bit(dir));
  of_box(b, v3(cx - nx, y0, cz - nz), v3(cx + nx, yn, cz + nz), m->monitor, F_SIDES);
}

/* Chair centred on (cx, cz): a 0.46 x 0.06 x 0.46 m seat (top at 0.48 m, all 6 faces), a
 * 0.45 m tall, 0.06 m thick back standing on the seat's edge on side 'back' (a direction; 5
 * faces), and four 0.05 m square legs from the floor to the seat (4 sides each): 27 polygons. */
static void of_chair(bld *b, double cx, double cz, int back, const of_mats *m) {
  const double h = 0.23, ys = 0.42, yt = 0.48, yb = 0.93, t = 0.06, lw = 0.05, li = 0.02;
  of_box(b, v3(cx - h, ys, cz - h), v3(cx + h, yt, cz + h), m->chair, F_ALL);
  hr_vec3 lo = v3(cx - h, yt, cz - h), hi = v3(cx + h, yb, cz + h);
  switch (back) {
  case XP: lo.x = cx + h - t; break;
  case XN: hi.x = cx - h + t; break;
  case ZP: lo.z = cz + h - t; break;
  default: hi.z = cz - h + t; break;
  }
  of_box(b, lo, hi, m->chair, F_NOBOTTOM);
  for (int i = 0; i < 4; i++) {
    double x = i & 1 ? cx + h - li - lw : cx - h + li, z = i & 2 ? cz + h - li - lw : cz - h + li;
    of_box(b, v3(x, 0, z), v3(x + lw, ys, z + lw), m->metal, F_SIDES);
  }
}

/* Desk lamp on a desk top, its base centred on (cx, cz): a 0.16 m square base (5 polygons), a
 * 0.05 m square stem 0.38 m tall (5), an arm reaching 0.225 m along +z from the stem to the
 * head's side (4), and the head: a 0.18 m square emitter facing down 0.29 m above the desk
 * (1), then the shade's top and sides (5). */
static void of_desk_lamp(bld *b, double cx, double cz, const of_mats *m) {
  const double y0 = OF_DESK_H, z0 = cz + 0.025, z1 = z0 + 0.225;
  of_box(b, v3(cx - 0.08, y0, cz - 0.08), v3(cx + 0.08, y0 + 0.025, cz + 0.08), m->metal,
         F_NOBOTTOM);
  of_box(b, v3(cx - 0.025, y0 + 0.025, cz - 0.025), v3(cx + 0.025, y0 + 0.405, cz + 0.025),
         m->metal, F_NOBOTTOM);
  of_box(b, v3(cx - 0.02, y0 + 0.33, z0), v3(cx + 0.02, y0 + 0.37, z1), m->metal,
         F_XN | F_XP | F_YN | F_YP);
  hr_vec3 lo = v3(cx - 0.09, y0 + 0.29, z1), hi = v3(cx + 0.09, y0 + 0.39, z1 + 0.18);
  rect(b, YN, lo, v3(hi.x, lo.y, hi.z), m->desk_lamp);
  of_box(b, lo, hi, m->shade, F_NOBOTTOM);
}

/* Open bookshelf against the x = 0 wall over z in [z0, z1], 0.35 m deep and 1.9 m tall; the
 * wall is its back. Two 0.06 m sides (7 polygons each: top, front in 4 pieces, two faces), a
 * 0.08 m plinth (top, front in 2), three 0.04 m shelves (top, bottom, front in 3; the top
 * shelf flush with the sides) and three blocks of books (top, front, two sides): 44 polygons. */
static void of_bookshelf(bld *b, double z0, double z1, const of_mats *m) {
  const double d = 0.35, h = 1.9, t = 0.06, a0 = z0 + t, a1 = z1 - t;
  of_box(b, v3(0, 0, z0), v3(d, h, a0), m->shelf, F_YP | F_XP | F_ZN | F_ZP);
  of_box(b, v3(0, 0, a1), v3(d, h, z1), m->shelf, F_YP | F_XP | F_ZN | F_ZP);
  of_box(b, v3(0, 0, a0), v3(d, 0.08, a1), m->shelf, F_YP | F_XP);
  static const double sy[3] = {0.64, 1.24, 1.86};
  for (int i = 0; i < 3; i++)
    of_box(b, v3(0, sy[i], a0), v3(d, sy[i] + 0.04, a1), m->shelf, F_YP | F_YN | F_XP);
  /* y0, y1 and z (from z0) of the books on the plinth, the first and the second shelf. */
  static const double bk[3][4] = {
      {0.08, 0.36, 0.12, 0.55}, {0.68, 0.93, 0.50, 0.98}, {1.28, 1.58, 0.10, 0.45}};
  for (int i = 0; i < 3; i++)
    of_box(b, v3(0, bk[i][0], z0 + bk[i][2]), v3(0.27, bk[i][1], z0 + bk[i][3]), m->book[i],
           F_YP | F_XP | F_ZN | F_ZP);
}

/* Filing cabinet against the z = 0 wall from x0: 0.5 x 1.05 x 0.6 m; top and sides (3), the
 * front as three drawer fronts (3), and a 0.16 m handle on each drawer (5 each): 21 polygons. */
static void of_cabinet(bld *b, double x0, const of_mats *m) {
  const double w = 0.5, h = 1.05, d = 0.6, dh = h / 3;
  of_box(b, v3(x0, 0, 0), v3(x0 + w, h, d), m->cabinet, F_YP | F_XN | F_XP);
  for (int i = 0; i < 3; i++)
    vrect(b, ZP, d, x0, x0 + w, i * dh, i == 2 ? h : (i + 1) * dh, m->cabinet);
  for (int i = 0; i < 3; i++) {
    double y = (i + 1) * dh - 0.08;
    of_box(b, v3(x0 + 0.17, y, d), v3(x0 + 0.33, y + 0.03, d + 0.03), m->metal,
           F_YP | F_YN | F_XN | F_XP | F_ZP);
  }
}

static void build_office(bld *b) {
  const double W = OF_W, H = OF_H, D = OF_D;
  of_mats m;
  m.floor = mat(b, "carpet", 0.38, 0.36, 0.33, 0, 0, 0);
  m.ceil = mat(b, "ceiling", 0.80, 0.80, 0.78, 0, 0, 0);
  m.wall = mat(b, "wall", 0.74, 0.72, 0.68, 0, 0, 0);
  m.accent = mat(b, "wall_blue", 0.18, 0.30, 0.58, 0, 0, 0);
  m.lamp = mat(b, "lamp", 0.80, 0.80, 0.80, 90, 88, 80);
  m.desk_lamp = mat(b, "desk_lamp", 0.80, 0.80, 0.80, 75, 65, 50);
  m.housing = mat(b, "lamp_housing", 0.70, 0.70, 0.70, 0, 0, 0);
  m.shade = mat(b, "lamp_shade", 0.25, 0.42, 0.30, 0, 0, 0);
  m.desk = mat(b, "desk", 0.58, 0.44, 0.30, 0, 0, 0);
  m.metal = mat(b, "metal", 0.40, 0.40, 0.42, 0, 0, 0);
  m.monitor = mat(b, "monitor", 0.15, 0.15, 0.16, 0, 0, 0);
  m.screen = mat(b, "screen", 0.10, 0.10, 0.12, 0, 0, 0);
  m.chair = mat(b, "chair", 0.62, 0.24, 0.12, 0, 0, 0);
  m.shelf = mat(b, "bookshelf", 0.45, 0.32, 0.20, 0, 0, 0);
  m.book[0] = mat(b, "books_red", 0.55, 0.14, 0.12, 0, 0, 0);
  m.book[1] = mat(b, "books_green", 0.18, 0.42, 0.22, 0, 0, 0);
  m.book[2] = mat(b, "books_ochre", 0.72, 0.55, 0.20, 0, 0, 0);
  m.cabinet = mat(b, "cabinet", 0.55, 0.56, 0.58, 0, 0, 0);
  m.door = mat(b, "door", 0.42, 0.28, 0.16, 0, 0, 0);
  m.whiteboard = mat(b, "whiteboard", 0.80, 0.80, 0.80, 0, 0, 0);
  m.picture = mat(b, "picture", 0.75, 0.50, 0.18, 0, 0, 0);
  m.rug = mat(b, "rug", 0.22, 0.45, 0.38, 0, 0, 0);
  /* Shell, all faces inward (0-5). */
  rect(b, YP, v3(0, 0, 0), v3(W, 0, D), m.floor);
  rect(b, YN, v3(0, H, 0), v3(W, H, D), m.ceil);
  vrect(b, ZP, 0, 0, W, 0, H, m.wall);
  vrect(b, ZN, D, 0, W, 0, H, m.wall);
  vrect(b, XP, 0, 0, D, 0, H, m.accent);
  vrect(b, XN, W, 0, D, 0, H, m.wall);
  /* Four ceiling lamps on a 2 x 2 grid (6-25). */
  for (int k = 0; k < 4; k++) of_ceiling_lamp(b, k & 1 ? 4.2 : 1.8, k & 2 ? 3.5 : 1.5, &m);
  /* Door, whiteboard and picture 1 cm in front of their walls, rug 5 mm above the floor
   * (26-29). */
  vrect(b, ZP, 0.01, 3.3, 4.2, 0, 2.1, m.door);
  vrect(b, ZP, 0.01, 1.1, 2.9, 0.95, 2.05, m.whiteboard);
  vrect(b, XP, 0.01, 1.3, 2.3, 1.3, 2.0, m.picture);
  rect(b, YP, v3(0.8, 0.005, 3.2), v3(2.4, 0.005, 4.5), m.rug);
  /* Desks: A against the blue wall, B in the corner at x = W, z = 0, C free-standing
   * (30-54, 55-77, 78-105). */
  of_desk(b, 0, 1.0, 0.75, 2.6, F_XN, &m);
  of_desk(b, W - 1.6, 0, W, 0.75, F_XP | F_ZN, &m);
  of_desk(b, 2.2, 2.3, 3.8, 3.05, 0, &m);
  /* Monitors on A and B (106-115, 116-125), the desk lamp on C (126-145). */
  of_monitor(b, 0.25, 1.8, XP, &m);
  of_monitor(b, W - 0.8, 0.25, ZP, &m);
  of_desk_lamp(b, 2.6, 2.45, &m);
  /* A chair at each desk, its back away from the desk (146-172, 173-199, 200-226). */
  of_chair(b, 1.05, 1.8, XP, &m);
  of_chair(b, W - 0.8, 1.05, ZP, &m);
  of_chair(b, 3.0, 3.35, ZP, &m);
  of_bookshelf(b, 3.0, 4.1, &m); /* 227-270 */
  of_cabinet(b, 0.15, &m);       /* 271-291 */
  /* From the corner at x = W, z = D, over desk C toward the blue wall and the whiteboard. */
  set_camera(b->s, v3(5.85, 1.95, 4.85), v3(2.6, 0.8, 1.2), 68);
}

/* ---------------------------------------------------------------- hall */

#define HA_C 4.0   /* cell size along x and z */
#define HA_H 3.0   /* ceiling height */
#define HA_NMAX 64 /* largest N of "hall:N" (4 million triangles) */
#define HA_NDEF 4  /* N of "hall" */

typedef struct ha_mats {
  int floor, ceil, wall, partition, lamp, housing, table, metal, chair, shelf, book[4];
} ha_mats;

/* A placement: local (x, y, z) goes to o + the rotation by 'yaw' about +y of (x, y, z). */
typedef struct ha_frame {
  hr_vec3 o;
  double c, s;
} ha_frame;

static ha_frame ha_at(double x, double z, double yaw) {
  return (ha_frame){v3(x, 0, z), cos(yaw), sin(yaw)};
}

static hr_vec3 ha_world(const ha_frame *f, hr_vec3 p) {
  return v3(f->o.x + f->c * p.x + f->s * p.z, f->o.y + p.y, f->o.z - f->s * p.x + f->c * p.z);
}

/* A number in [0, 1) fixed by (i, j, k): the per-cell variation (splitmix64's finaliser). */
static double ha_rand(int i, int j, int k) {
  uint64_t x = (uint64_t)i * 0x9E3779B97F4A7C15u + (uint64_t)j * 0xC2B2AE3D27D4EB4Fu +
               (uint64_t)k * 0x165667B19E3779F9u + 1u;
  x ^= x >> 30;
  x *= 0xBF58476D1CE4E5B9u;
  x ^= x >> 27;
  x *= 0x94D049BB133111EBu;
  x ^= x >> 31;
  return (double)(x >> 11) * 0x1.0p-53;
}

static void tri(bld *b, hr_vec3 p, hr_vec3 q, hr_vec3 r, int m) {
  const hr_vec3 v[3] = {p, q, r};
  poly(b, v, 3, m);
}

static hr_vec3 ha_point(hr_vec3 p0, hr_vec3 e1, hr_vec3 e2, double s, double t) {
  return v3_add(p0, v3_add(v3_scale(e1, s), v3_scale(e2, t)));
}

/* The parallelogram p0, p0 + e1, p0 + e1 + e2, p0 + e2 (counter-clockwise seen from its front)
 * as n1 x n2 cells of two triangles, the diagonals alternating like a checkerboard. The cuts
 * along e1 lie at (k / n1)^g: g > 1 crowds thin cells, and sliver triangles, toward p0. A point
 * comes from the same expression in every cell that has it, so neighbours share edges exactly. */
static void ha_grid(bld *b, hr_vec3 p0, hr_vec3 e1, hr_vec3 e2, int n1, int n2, double g,
                    int m) {
  for (int i = 0; i < n1; i++) {
    double s0 = pow((double)i / n1, g), s1 = pow((double)(i + 1) / n1, g);
    for (int j = 0; j < n2; j++) {
      double t0 = (double)j / n2, t1 = (double)(j + 1) / n2;
      hr_vec3 a = ha_point(p0, e1, e2, s0, t0), c = ha_point(p0, e1, e2, s1, t0);
      hr_vec3 d = ha_point(p0, e1, e2, s1, t1), e = ha_point(p0, e1, e2, s0, t1);
      if ((i + j) & 1) {
        tri(b, a, c, e, m);
        tri(b, c, d, e, m);
      } else {
        tri(b, a, c, d, m);
        tri(b, a, d, e, m);
      }
    }
  }
}

/* The same parallelogram as k >= 2 triangles fanned from p0 to points spread evenly along the
 * two far edges (k / 2 cuts on the edge from p0 + e1, the rest on the edge to p0 + e2): on a
 * thin face, a fan of long slivers, as exporters write them. */
static void ha_fan(bld *b, hr_vec3 p0, hr_vec3 e1, hr_vec3 e2, int k, int m) {
  int k1 = k / 2, k2 = k - k1;
  hr_vec3 prev = v3_add(p0, e1);
  for (int q = 1; q <= k; q++) {
    hr_vec3 p = q <= k1 ? ha_point(p0, e1, e2, 1, (double)q / k1)
                        : ha_point(p0, e1, e2, 1 - (double)(q - k1) / k2, 1);
    tri(b, p0, prev, p, m);
    prev = p;
  }
}

/* The faces 'mask' (box_out()'s bits, outward) of the box lo..hi placed by 'f', each cut into
 * n[axis] pieces along each of its two axes (two triangles a piece), or, for the faces in
 * 'fans', fanned into as many triangles as the face has pieces along its two sides together. */
static void ha_box(bld *b, const ha_frame *f, hr_vec3 lo, hr_vec3 hi, const int n[3], int mask,
                   int fans, int m) {
  static const int dirs[6] = {YP, YN, XN, XP, ZN, ZP};
  for (int k = 0; k < 6; k++) {
    int dir = dirs[k], bit = face_bit(dir);
    if (!(mask & bit)) continue;
    int a = abs(dir) - 1, u = (a + 1) % 3, v = (a + 2) % 3;
    hr_vec3 plo = lo, phi = hi, q[4];
    if (dir > 0)
      set_comp(&plo, a, comp(hi, a));
    else
      set_comp(&phi, a, comp(lo, a));
    rect_corners(dir, plo, phi, q);
    for (int i = 0; i < 4; i++) q[i] = ha_world(f, q[i]);
    int n1 = dir > 0 ? n[u] : n[v], n2 = dir > 0 ? n[v] : n[u];
    hr_vec3 e1 = v3_sub(q[1], q[0]), e2 = v3_sub(q[3], q[0]);
    if (fans & bit)
      ha_fan(b, q[0], e1, e2, n1 + n2, m);
    else
      ha_grid(b, q[0], e1, e2, n1, n2, 1.0, m);
  }
}

/* Chair seen from its frame: the sitter faces -z. A 0.45 m square seat (top at 0.48 m; 28
 * triangles), a back standing on the seat's +z edge up to 0.93 m (25), and four 0.04 m legs from
 * 1 cm below the floor to the seat (8 each): 85 triangles. */
static void ha_chair(bld *b, const ha_frame *f, const ha_mats *m) {
  const double h = 0.225, lw = 0.04, li = 0.02;
  static const int ns[3] = {2, 1, 2}, nb[3] = {2, 2, 1}, nl[3] = {1, 1, 1};
  ha_box(b, f, v3(-h, 0.43, -h), v3(h, 0.48, h), ns, F_ALL, F_SIDES, m->chair);
  ha_box(b, f, v3(-h, 0.48, h - 0.04), v3(h, 0.93, h), nb, F_NOBOTTOM, F_YP | F_XN | F_XP,
         m->chair);
  for (int k = 0; k < 4; k++) {
    double x = k & 1 ? h - li - lw : -h + li, z = k & 2 ? h - li - lw : -h + li;
    ha_box(b, f, v3(x, -0.01, z), v3(x + lw, 0.43, z + lw), nl, F_SIDES, 0, m->metal);
  }
}

/* Cell (i, j) of "hall": x in [4i, 4i + 4], z in [4j, 4j + 4]. Polygon order and triangles:
 * floor (72), ceiling (32), lamp (16 emitting, 16 housing), table (112), three chairs (255),
 * bookshelf with 21 books (366), then the partition on the cell's x line when i > 0 and on its z
 * line when j > 0 (61 each): 869 + 61 per partition. */
static void ha_cell(bld *b, int i, int j, const ha_mats *m) {
  const double C = HA_C, H = HA_H, x0 = i * C, z0 = j * C;
  const ha_frame cell = ha_at(x0, z0, 0);
  /* Floor: 6 x 6 pieces crowded toward one corner (alternating between cells: T-junctions and
   * slivers where cells meet); ceiling 4 x 4. */
  if ((i + j) & 1)
    ha_grid(b, v3(x0, 0, z0), v3(0, 0, C), v3(C, 0, 0), 6, 6, 1.7, m->floor);
  else
    ha_grid(b, v3(x0 + C, 0, z0 + C), v3(0, 0, -C), v3(-C, 0, 0), 6, 6, 1.7, m->floor);
  ha_grid(b, v3(x0, H, z0), v3(C, 0, 0), v3(0, 0, C), 4, 4, 1.0, m->ceil);
  /* Lamp over the table: a 1 x 0.5 m emitter facing down 0.1 m below the ceiling, its
   * housing's sides running 1 cm into the ceiling. */
  const double cx = 1.9, cz = 2.3;
  static const int nlamp[3] = {4, 1, 2};
  ha_box(b, &cell, v3(cx - 0.5, H - 0.1, cz - 0.25), v3(cx + 0.5, H + 0.01, cz + 0.25), nlamp,
         F_YN, 0, m->lamp);
  ha_box(b, &cell, v3(cx - 0.5, H - 0.1, cz - 0.25), v3(cx + 0.5, H + 0.01, cz + 0.25), nlamp,
         F_SIDES, F_SIDES, m->housing);
  /* Table: a 1.8 x 0.9 m top 5 cm thick at 0.77 m, turned by up to 3 degrees, on four legs that
   * run through it and 1 cm into the floor. */
  const ha_frame tf = ha_at(x0 + cx, z0 + cz, 0.1 * (ha_rand(i, j, 0) - 0.5));
  static const int ntop[3] = {4, 1, 2}, nleg[3] = {1, 2, 1};
  ha_box(b, &tf, v3(-0.9, 0.72, -0.45), v3(0.9, 0.77, 0.45), ntop, F_ALL, F_SIDES, m->table);
  for (int k = 0; k < 4; k++) {
    double x = k & 1 ? 0.82 : -0.88, z = k & 2 ? 0.37 : -0.43;
    ha_box(b, &tf, v3(x, -0.01, z), v3(x + 0.06, 0.77, z + 0.06), nleg, F_SIDES, 0, m->metal);
  }
  /* Two chairs facing the table from -z, turned a little; the third pushed in from +z so far
   * that its back runs through the table top's edge. */
  ha_frame c1 = ha_at(x0 + 1.45, z0 + 1.45, M_PI + 0.2 * (ha_rand(i, j, 1) - 0.5));
  ha_frame c2 = ha_at(x0 + 2.35, z0 + 1.5, M_PI + 0.6 * (ha_rand(i, j, 2) - 0.5));
  ha_frame c3 = ha_at(x0 + 1.9, z0 + 2.545, 0);
  ha_chair(b, &c1, m);
  ha_chair(b, &c2, m);
  ha_chair(b, &c3, m);
  /* Bookshelf, open toward -x: x in [3.45, 3.77], z in [0.5, 1.7], 1.6 m tall. Two sides, a
   * back and four boards that run into them; on each of the three lower boards seven books
   * side by side (their faces touch), each 2.5-5 cm thick, 18-30 cm tall, 16-24 cm deep. */
  static const int nside[3] = {1, 3, 1}, nback[3] = {1, 3, 3}, nboard[3] = {1, 1, 3};
  static const int nbook[3] = {1, 1, 1};
  const double sx0 = 3.45, sx1 = 3.77, sz0 = 0.5, sz1 = 1.7, sh = 1.6, t = 0.02;
  ha_box(b, &cell, v3(sx0, 0, sz0), v3(sx1, sh, sz0 + t), nside, F_NOBOTTOM,
         F_YP | F_XN | F_XP, m->shelf);
  ha_box(b, &cell, v3(sx0, 0, sz1 - t), v3(sx1, sh, sz1), nside, F_NOBOTTOM, F_YP | F_XN | F_XP,
         m->shelf);
  ha_box(b, &cell, v3(sx1 - t, 0, sz0 + 0.01), v3(sx1, sh, sz1 - 0.01), nback, F_NOBOTTOM,
         F_YP | F_ZN | F_ZP, m->shelf);
  static const double by[4] = {0.06, 0.56, 1.06, 1.58};
  for (int k = 0; k < 4; k++)
    ha_box(b, &cell, v3(sx0, by[k], sz0 + 0.01), v3(sx1 - 0.01, by[k] + t, sz1 - 0.01), nboard,
           F_YP | F_YN | F_XN, F_XN, m->shelf);
  for (int k = 0; k < 3; k++) {
    double z = sz0 + t, y = by[k] + t;
    for (int n = 0; n < 7; n++) {
      int r = 3 + 21 * k + 3 * n;
      double th = 0.025 + 0.025 * ha_rand(i, j, r), hb = 0.18 + 0.12 * ha_rand(i, j, r + 1);
      double d = 0.16 + 0.08 * ha_rand(i, j, r + 2);
      ha_box(b, &cell, v3(sx0 + t, y, z), v3(sx0 + t + d, y + hb, z + th), nbook, F_NOBOTTOM, 0,
             m->book[(i + 2 * j + k + n) % 4]);
      z += th;
    }
  }
  /* Partitions 0.1 m thick and 2.2 m tall, from 2 cm below the floor: on the x line from the
   * cell's corner 2.45 m along z, and on the z line over x in [1.6, 4.05]; each runs 5 cm past
   * the corner it starts from, into the outer wall or the next partition. */
  static const int npx[3] = {1, 3, 4}, npz[3] = {4, 3, 1};
  if (i > 0)
    ha_box(b, &cell, v3(-0.05, -0.02, -0.05), v3(0.05, 2.2, 2.4), npx, F_NOBOTTOM,
           F_YP | F_ZN | F_ZP, m->partition);
  if (j > 0)
    ha_box(b, &cell, v3(1.6, -0.02, -0.05), v3(C + 0.05, 2.2, 0.05), npz, F_NOBOTTOM,
           F_YP | F_XN | F_XP, m->partition);
}

/* "hall:N": N x N cells of 4 x 4 m under a 3 m ceiling, then the outer walls, one 6 x 4 grid
 * (48 triangles) per cell side: 991 N^2 + 70 N triangles (1061 for N = 1, 1,017,024 for 32). */
static void build_hall(bld *b, int n) {
  ha_mats m;
  m.floor = mat(b, "floor", 0.50, 0.42, 0.33, 0, 0, 0);
  m.ceil = mat(b, "ceiling", 0.80, 0.80, 0.78, 0, 0, 0);
  m.wall = mat(b, "wall", 0.72, 0.70, 0.66, 0, 0, 0);
  m.partition = mat(b, "partition", 0.35, 0.45, 0.60, 0, 0, 0);
  m.lamp = mat(b, "lamp", 0.80, 0.80, 0.80, 150, 144, 132);
  m.housing = mat(b, "lamp_housing", 0.70, 0.70, 0.70, 0, 0, 0);
  m.table = mat(b, "table", 0.55, 0.40, 0.26, 0, 0, 0);
  m.metal = mat(b, "metal", 0.40, 0.40, 0.42, 0, 0, 0);
  m.chair = mat(b, "chair", 0.62, 0.24, 0.12, 0, 0, 0);
  m.shelf = mat(b, "bookshelf", 0.45, 0.32, 0.20, 0, 0, 0);
  m.book[0] = mat(b, "books_red", 0.55, 0.14, 0.12, 0, 0, 0);
  m.book[1] = mat(b, "books_green", 0.18, 0.42, 0.22, 0, 0, 0);
  m.book[2] = mat(b, "books_blue", 0.16, 0.24, 0.55, 0, 0, 0);
  m.book[3] = mat(b, "books_ochre", 0.72, 0.55, 0.20, 0, 0, 0);
  for (int j = 0; j < n; j++)
    for (int i = 0; i < n; i++) ha_cell(b, i, j, &m);
  const double C = HA_C, H = HA_H, L = n * C;
  for (int k = 0; k < n; k++) {
    double a = k * C;
    ha_grid(b, v3(a, 0, 0), v3(C, 0, 0), v3(0, H, 0), 6, 4, 1.0, m.wall);      /* faces +z */
    ha_grid(b, v3(a, 0, L), v3(0, H, 0), v3(C, 0, 0), 4, 6, 1.0, m.wall);      /* faces -z */
    ha_grid(b, v3(0, 0, a), v3(0, H, 0), v3(0, 0, C), 4, 6, 1.0, m.wall);      /* faces +x */
    ha_grid(b, v3(L, 0, a), v3(0, 0, C), v3(0, H, 0), 6, 4, 1.0, m.wall);      /* faces -x */
  }
  /* From above the first cell's corner, over its table, diagonally across the hall. */
  double k = 0.55 * C * (n < 4 ? n : 4);
  set_camera(b->s, v3(0.35, 2.6, 0.35), v3(k, 0.6, k), 60);
}

/* ---------------------------------------------------------------- public */

static const char *const builtin_names[] = {"room",   "floor", "museum", "cornell",
                                            "office", "hall",  NULL};

const char *const *hr_scene_builtin_names(void) { return builtin_names; }

/* The N of "hall" (HA_NDEF) or "hall:N" (decimal digits, 1..HA_NMAX) in '*n': 1 for a hall,
 * -1 for a hall with a bad N, 0 for another name. */
static int hall_size(const char *name, int *n) {
  if (strcmp(name, "hall") == 0) {
    *n = HA_NDEF;
    return 1;
  }
  if (strncmp(name, "hall:", 5) != 0) return 0;
  const char *p = name + 5;
  long v = 0;
  if (!*p) return -1;
  for (; *p; p++) {
    if (*p < '0' || *p > '9') return -1;
    v = 10 * v + (*p - '0');
    if (v > HA_NMAX) return -1;
  }
  if (v < 1) return -1;
  *n = (int)v;
  return 1;
}

hr_status hr_scene_builtin(const char *name, hr_scene **out, hr_err *err) {
  static void (*const builders[])(bld *) = {build_room, build_floor, build_museum,
                                            build_cornell, build_office};
  if (out) *out = NULL;
  int which = -1, n = 0, hall = name ? hall_size(name, &n) : 0;
  for (int i = 0; name && i < 5; i++)
    if (strcmp(name, builtin_names[i]) == 0) which = i;
  if (hall < 0)
    return hr_err_set(err, HR_ERR_INVALID,
                      "scene '%s': hall:N needs N, a whole number in 1..%d (N x N cells, "
                      "about 1000 N^2 triangles)",
                      name, HA_NMAX);
  if (which < 0 && !hall)
    return hr_err_set(err, HR_ERR_INVALID,
                      "unknown scene '%s' (built-in: room, floor, museum, cornell, office, "
                      "hall:N)",
                      name ? name : "");
  if (!out) return hr_err_set(err, HR_ERR_INVALID, "hr_scene_builtin: 'out' is NULL");
  char hname[32];
  if (hall) {
    snprintf(hname, sizeof hname, "hall-%d", n);
    name = hname;
  }
  bld b = {NULL, HR_OK, 0};
  if (hr_scene_create(name, &b.s) != HR_OK)
    return hr_err_set(err, HR_ERR_NOMEM, "out of memory building scene '%s'", name);
  if (hall)
    build_hall(&b, n);
  else
    builders[which](&b);
  if (b.st == HR_OK && b.bad)
    b.st = hr_err_set(err, HR_ERR_INVALID, "built-in scene '%s': %d degenerate polygon(s)",
                      name, b.bad);
  else if (b.st != HR_OK)
    hr_err_set(err, b.st, "building scene '%s' failed (status %d)", name, (int)b.st);
  if (b.st != HR_OK) {
    hr_scene_destroy(&b.s);
    return b.st;
  }
  *out = b.s;
  return HR_OK;
}
