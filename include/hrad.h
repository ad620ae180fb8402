/* hrad: hierarchical radiosity after Bohn & Garmann, "A Parallel Approach to Hierarchical
 * Radiosity" (WSCG'95). Public API: scenes, the solver, results and writers.
 *
 * Conventions: fallible functions return an hr_status and hand results back through their last
 * pointer argument; an hr_err receives a one-line message "FILE:LINE: what is wrong" (or just
 * "what is wrong" when there is no file). The library never prints; warnings go to an optional
 * hr_log callback. create/destroy pairs: destroy accepts NULL.
 */
#ifndef HRAD_H
#define HRAD_H

#include <stddef.h>
#include <stdint.h>

#include "hrad_version.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum {
  HR_OK = 0,
  HR_ERR_IO,        /* file missing or unreadable/unwritable */
  HR_ERR_PARSE,     /* malformed input */
  HR_ERR_INVALID,   /* bad values: NaN, out of range, bad option */
  HR_ERR_NOMEM,     /* allocation failed */
  HR_ERR_NO_EMITTER,/* scene has nothing that emits light */
  HR_ERR_TOO_BIG,   /* refused: work would exceed a stated limit */
  HR_ERR_UNPHYSICAL,/* the solution became non-finite or broke the physical bound E/(1-rho) */
  HR_ERR_REMOTE     /* another MPI rank failed (it reports why); this one stopped with it */
} hr_status;

/* The library's version, "MAJOR.MINOR.PATCH": HR_VERSION_STRING of the build that made it (a
 * program can compare it with the HR_VERSION_STRING it was compiled against). Can't fail. */
const char *hr_version(void);

typedef struct hr_err {
  char msg[512];
} hr_err;

/* Warning sink; 'msg' is one line without a trailing newline. */
typedef void (*hr_log_fn)(void *ud, const char *msg);
typedef struct hr_log {
  hr_log_fn fn;
  void *ud;
} hr_log;

/* Sets err->msg printf-style (if err is non-NULL) and returns 'st'. */
hr_status hr_err_set(hr_err *err, hr_status st, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;
/* Sends a formatted warning to 'log' (ignored when log or log->fn is NULL). */
void hr_log_warn(const hr_log *log, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

typedef struct hr_vec3 {
  double x, y, z;
} hr_vec3;

/* ---------------------------------------------------------------- scene (scene.c) */

typedef struct hr_material {
  char *name;
  double rho[3];  /* diffuse reflectance, RGB, 0..1 */
  double emit[3]; /* emitted radiosity E, RGB, W/m^2 */
  int base;       /* the input material this one was made from: its own index for a material
                     of the input; another material's for a per-polygon variant (a textured
                     polygon's mean reflectance, hr_scene_add_variant), which shares its name */
} hr_material;

/* A surface is a planar triangle or convex planar quad (the paper's "surface"/"blocker").
 * Vertices are counter-clockwise seen from the front; light leaves the front only. */
typedef struct hr_surface {
  int nverts;     /* 3 or 4 */
  hr_vec3 v[4];
  hr_vec3 normal; /* unit, front side */
  double area;
  int material;   /* index into scene->mats */
  int poly;       /* index of the input polygon it came from (row of surfaces.csv) */
  int cut;        /* 1: a piece of a larger surface that hr_scene_cut_contacts cut (it takes the
                     importance, --importance, of its polygon, not of the piece); else 0 */
} hr_surface;

typedef struct hr_camera {
  hr_vec3 eye, at, up;
  double fov_deg; /* vertical field of view */
} hr_camera;

/* What became of one input polygon (an OBJ face, a built-in polygon), in input order. */
typedef enum {
  HR_INPUT_SOLVED = 0,   /* became kept polygon 'poly' */
  HR_INPUT_DUPLICATE,    /* repeats kept polygon 'poly' (same positions, same side): skipped, and
                            reported with that polygon's radiosity */
  HR_INPUT_DEGENERATE    /* no area: skipped, 'poly' is -1 */
} hr_input_kind;
typedef struct hr_input {
  int poly;              /* index of the kept polygon (row of hr_solver_poly_radiosity) or -1 */
  hr_input_kind kind;
} hr_input;

typedef struct hr_scene {
  char *name;          /* "room", or the OBJ's base name without extension */
  hr_material *mats;
  int nmats, cap_mats;
  hr_surface *surfs;
  int nsurfs, cap_surfs;
  int npolys;          /* number of kept polygons (>= 1 surface each) */
  double *poly_area;   /* [npolys] */
  hr_input *inputs;    /* every input polygon in input order, kept or skipped (surfaces.csv) */
  int ninputs, cap_inputs;
  int has_camera;
  hr_camera camera;
  /* Objects (OBJ `o`/`g`, the nodes of a glTF, FBX, ...), in order of first use. Every kept
   * polygon belongs to one: the current object when it was added (hr_scene_begin_object), or,
   * before any, a default object named like the scene. */
  char **objects;
  int nobjects, cap_objects;
  int cur_object;      /* object of polygons added now; -1: the default object */
  int *poly_object;    /* [npolys] */
  int cap_poly_object;
} hr_scene;

hr_status hr_scene_create(const char *name, hr_scene **out);
void hr_scene_destroy(hr_scene **s);
/* Largest emission accepted (radiosities, their squares in error estimates and float outputs
 * then stay finite). */
#define HR_EMIT_MAX 1e30
/* Adds a material (name copied); returns its index through 'idx'. HR_ERR_INVALID unless every
 * rho is in [0, 1] and every emit in [0, HR_EMIT_MAX]. */
hr_status hr_scene_add_material(hr_scene *s, const char *name, const double rho[3],
                                const double emit[3], int *idx);
/* Finds an input material (not a variant) by exact name; returns its index or -1. */
int hr_scene_find_material(const hr_scene *s, const char *name);
/* Adds a variant of input material 'base': the same name and emission, reflectance 'rho' (in
 * [0, 1], HR_ERR_INVALID otherwise). Loaders give a textured polygon one (the solver takes one
 * reflectance per surface); writers and hr_scene_set_emit treat it as its base. */
hr_status hr_scene_add_variant(hr_scene *s, int base, const double rho[3], int *idx);
/* Number of input materials (variants not counted) and the index of the k-th (k in
 * 0..count-1, input order), or -1. */
int hr_scene_material_count(const hr_scene *s);
int hr_scene_material_at(const hr_scene *s, int k);

/* Makes polygons added from now on belong to object 'name' (found by exact name, or added).
 * HR_ERR_NOMEM, or HR_ERR_INVALID for a NULL name. */
hr_status hr_scene_begin_object(hr_scene *s, const char *name);
/* Objects: their number, the name of object 'obj' (NULL when out of range), the object of kept
 * polygon 'poly' (-1 when out of range), and its material (the input material of its first
 * surface, -1 when out of range). */
int hr_scene_object_count(const hr_scene *s);
const char *hr_scene_object_name(const hr_scene *s, int obj);
int hr_scene_poly_object(const hr_scene *s, int poly);
int hr_scene_poly_material(const hr_scene *s, int poly);
/* Multiplies every coordinate (and the camera) by 'f' > 0: a scene in millimetres becomes one
 * in metres with f = 0.001. Emission (W/m^2) is per area and unchanged. HR_ERR_INVALID for a
 * bad factor or coordinates that would exceed HR_COORD_MAX. */
hr_status hr_scene_scale(hr_scene *s, double f);
/* What hr_scene_cut_contacts did: surfaces cut, lines cut along, surfaces they became. */
typedef struct hr_cut_stats {
  int surfaces, lines, pieces;
} hr_cut_stats;
/* Cuts every surface of at least len x len area along the lines where other surfaces at least
 * len tall stand on it or pass through it in front (a pillar's wall on a floor; not a chair's
 * runner), where there is open space on both sides of the line (not under a closed box: the
 * solver's open fractions deal with that), so that no element the solver makes from it
 * carries light across such a wall. Contacts within len / 256 of the plane, lines whose
 * contacts cover at least len / 2, no piece narrower than len / 2. The pieces are convex quads
 * and triangles with the surface's material and polygon (hr_surface.cut = 1), so outputs per
 * polygon keep their rows. The CLI passes len = sqrt(A_e) (--cut-contacts, docs/design.md
 * "Contact cuts"). Deterministic; HR_ERR_INVALID for a len not finite and > 0, HR_ERR_NOMEM
 * (also when the ray casting structure cannot be built; the scene unchanged). */
hr_status hr_scene_cut_contacts(hr_scene *s, double len, hr_cut_stats *stats);

/* Result of adding a polygon. */
typedef enum {
  HR_POLY_ADDED = 0,    /* became one or more surfaces */
  HR_POLY_DEGENERATE,   /* zero area (or collinear); nothing added, caller should warn */
  HR_POLY_NONPLANAR,    /* > 4 vertices and not planar within tolerance; nothing added */
  HR_POLY_NOT_SIMPLE    /* not convex and crossing itself (or not convex with more than
                           HR_EAR_MAX vertices); nothing added */
} hr_poly_result;

/* Largest coordinate magnitude accepted (areas and distances then stay far from overflow). */
#define HR_COORD_MAX 1e15
/* Largest non-convex polygon triangulated (ear clipping is quadratic in the vertex count). */
#define HR_EAR_MAX 4096
/* Adds one input polygon with 'n' >= 3 vertices (counter-clockwise from the front) and the
 * given material. A planar convex quad stays one surface; a non-planar or non-convex quad is
 * split into two triangles; a convex polygon with more than 4 vertices is fan-split into
 * triangles (degenerate fan triangles dropped), a non-convex one is triangulated by ear clipping
 * (linear time for convex polygons of any size). All surfaces created get the same 'poly' index.
 * Coordinates must be finite and at most HR_COORD_MAX in magnitude (HR_ERR_INVALID otherwise).
 * '*res' tells what happened; every call
 * that returns HR_OK records one input polygon (s->inputs). */
hr_status hr_scene_add_polygon(hr_scene *s, const hr_vec3 *v, int n, int material,
                               hr_poly_result *res);
/* Records an input polygon skipped as a duplicate of kept polygon 'poly'. */
hr_status hr_scene_add_duplicate(hr_scene *s, int poly);
/* The input row of kept polygon 'poly' (its first input polygon), or -1. */
int hr_scene_poly_input(const hr_scene *s, int poly);
/* Total area of all surfaces, largest emitted radiosity over surfaces and channels. */
double hr_scene_total_area(const hr_scene *s);
double hr_scene_max_emit(const hr_scene *s);
/* Axis-aligned bounds of all vertices. */
void hr_scene_bounds(const hr_scene *s, hr_vec3 *lo, hr_vec3 *hi);
/* Chooses a camera looking at the whole scene (used when a scene has none). */
void hr_scene_auto_camera(const hr_scene *s, hr_camera *cam);

/* ---------------------------------------------------------------- loading (obj.c, builtin.c) */

/* Parses Wavefront OBJ text 'buf' (length 'len'); 'path' names it in messages and locates
 * mtllib files (relative to its directory). Errors are "PATH:LINE: what". Warnings (degenerate
 * polygons, missing MTL, unknown statements) go to 'log'. */
hr_status hr_scene_parse_obj(const char *buf, size_t len, const char *path, const hr_log *log,
                             hr_scene **out, hr_err *err);
/* Reads the file at 'path' and parses it. */
hr_status hr_scene_load_obj(const char *path, const hr_log *log, hr_scene **out, hr_err *err);
/* Reads a scene through assimp (import.c): glTF 2.0 (.gltf, .glb), PLY, 3DS, FBX, Collada
 * (.dae) and STL. Polygons stay as stored (no triangulation; identical vertices joined), in world
 * space (node transforms applied); every node that holds meshes becomes an object (its name, or
 * the mesh's), every material a scene material: reflectance from the diffuse or base colour
 * (times the mean of its diffuse texture over each polygon's UV footprint, PNG or JPEG, external
 * or embedded: a per-polygon variant), emission from the emissive colour (times
 * KHR_materials_emissive_strength). Errors are "PATH: what" (assimp's message for files it
 * cannot read); warnings (degenerate polygons, clamped colours, unreadable textures) go to 'log'.
 * Nothing is kept on error. */
hr_status hr_scene_import(const char *path, const hr_log *log, hr_scene **out, hr_err *err);
/* Loads 'path' by its extension (case-insensitive): .obj (or no extension) with
 * hr_scene_load_obj, the formats of hr_scene_import with it; any other extension is
 * HR_ERR_INVALID ("PATH: unknown scene format '.X' (...)"). hr_scene_import also checks the
 * first bytes against the extension's format, so that no file is read as a format it is not
 * (assimp alone would read an OBJ text named .gltf as OBJ). */
hr_status hr_scene_load(const char *path, const hr_log *log, hr_scene **out, hr_err *err);
/* 1 if hr_scene_load takes a file named 'path' (by its extension). */
int hr_scene_format_known(const char *path);
/* Like hr_scene_parse_obj, but never touches the disk: every `mtllib` statement reads the MTL
 * text 'mtl' ('mlen' bytes, parsed once per statement) as if it were the named file (messages
 * name that file, resolved against 'path' as usual). 'mtl' NULL (mlen 0) means no library can be
 * opened: each mtllib statement warns "PATH:LINE: cannot open material library 'X'; using grey
 * default". For tests, fuzzing and callers that hold both texts in memory. */
hr_status hr_scene_parse_obj_mtl(const char *obj, size_t olen, const char *mtl, size_t mlen,
                                 const char *path, const hr_log *log, hr_scene **out,
                                 hr_err *err);
/* Builds a built-in scene: "room", "floor", "museum", "cornell", "office", or "hall:N" (N x N
 * furnished cells of small triangles, N in 1..64; "hall" is "hall:4"). HR_ERR_INVALID if
 * unknown or N is bad. */
hr_status hr_scene_builtin(const char *name, hr_scene **out, hr_err *err);
/* NULL-terminated list of built-in scene names. */
const char *const *hr_scene_builtin_names(void);
/* Makes material 'name' (and its variants) emit 'rgb'; HR_ERR_INVALID if no such material or a
 * value is not in [0, HR_EMIT_MAX]. */
hr_status hr_scene_set_emit(hr_scene *s, const char *name, const double rgb[3], hr_err *err);

/* ---------------------------------------------------------------- solver (solve.c) */

typedef struct hr_options {
  double bf_low;      /* final refinement threshold BF_low: the largest error (variation of the
                         light over the receiver, or from the source's variation) a link may
                         bring its receiver, relative to the light the receiver gets */
  double bf_start;    /* first BF_e of the multigrid schedule (relative); 0: equal to bf_low
                         (one level, the default) */
  double bf_factor;   /* BF_e is divided by this each outer step (> 1) */
  double area_min;    /* A_e, relative to the total scene area; 0: equal to bf_low */
  double b_eps;       /* B_e: convergence when the max change of B, relative to the scene's mean
                         radiosity, is below; 0: equal to bf_low (at most b_max) */
  double b_max;       /* B_max of section 2.2.4 (relative like b_eps), > b_eps */
  int relax;          /* section 2.2.4 relaxed inner loop on/off */
  int relax_links;    /* "many new links": relative growth threshold in percent */
  int rays;           /* k: rays per link for the visibility fraction H */
  uint64_t seed;      /* jitter seed */
  int threads;        /* 0 = all cores */
  int max_iters;      /* safety limit on total iterations */
  double max_links;   /* more surface pairs than this: clustered under HR_CLUSTER_AUTO, refused
                         under HR_CLUSTER_OFF (0 = no limit) */
  int cluster;        /* HR_CLUSTER_AUTO, _ON or _OFF: hierarchical clustering (issue 12) */
  int extrapolate;    /* Aitken extrapolation of the leaves' radiosity every few iterations
                         without new links (docs/design.md, "Extrapolation"); default on */
  double bf_first;    /* BF_e of a clustered solve's linking before the first gather, when
                         only the emitters have light: the resolution of the direct light
                         (may be below bf_low); 0: a quarter of the first level's BF_e
                         (bf_start) */
  double importance;  /* E in [0, 1]: a receiver smaller than the finest regular element
                         (A_e / 4) may take errors (A_e / 4 / A)^E times larger, for it weighs
                         that much less in the picture and in area-weighted error; 0: every
                         receiver alike (docs/design.md, "Importance"); default 0.7 */
} hr_options;

enum { HR_CLUSTER_AUTO = 0, HR_CLUSTER_ON = 1, HR_CLUSTER_OFF = 2 };

/* Fills 'o' with the defaults. */
void hr_options_default(hr_options *o);

typedef struct hr_solver hr_solver;

/* Per-iteration report, for progress lines and snapshots (paper step {15}). */
typedef struct hr_iter_info {
  int iter;          /* 1-based */
  double bf_e;       /* current BF_e (relative) */
  int64_t elements;  /* leaf elements */
  int64_t links;
  double max_change; /* relative to the scene's mean radiosity */
  double elapsed_s;
} hr_iter_info;
/* Called after each push-pull; return non-zero to stop. */
typedef int (*hr_iter_fn)(void *ud, const hr_solver *s, const hr_iter_info *info);

typedef struct hr_timing {
  double init_graph, refine, gather, push_pull, total;
  double balance; /* graph balancing (distributed runs; the paper's "sim. ann." column) */
} hr_timing;

typedef struct hr_stats {
  int nsurfaces, npolys;
  int64_t elements;     /* leaves */
  int64_t elements_all; /* all nodes of all quadtrees */
  int64_t links;        /* element links and cluster links */
  int64_t initial_links;
  int iterations;
  int64_t rays;
  int converged;        /* 1 if B_e reached at BF_low */
  int threads;
  double peak_rss_mb;
  hr_timing time_s;
  int64_t clusters;      /* cluster nodes (0 without clustering) */
  int64_t cluster_links; /* links with a cluster at one end or both (counted in 'links') */
  int ranks;             /* processes (hr_solver_set_dist); 1 without */
  /* how elements were given to ranks: "anneal", "metis" or "orb" (graph balancing), "random"
   * (scattered by gid), "given" (the caller's owners, never moved), "area" (whole surfaces by
   * area, never moved); "" in one process */
  const char *balance;
  int64_t balancings, migrations; /* graph balancings done, and those that moved elements */
} hr_stats;

hr_status hr_solver_create(const hr_scene *scene, const hr_options *opt, hr_solver **out,
                           hr_err *err);
void hr_solver_destroy(hr_solver **s);
/* Runs Figure 3 to completion. 'cb' may be NULL. */
hr_status hr_solver_run(hr_solver *s, hr_iter_fn cb, void *ud, hr_err *err);

/* Progress of hr_solver_run, for progress bars and ETAs. */
typedef enum {
  HR_PHASE_LINK = 0, /* initial linking (paper step {1}): 'fraction' of the surface pairs done */
  HR_PHASE_SOLVE     /* refinement iterations: 'fraction' is the share of the multigrid schedule
                        done (levels of BF_e from bf_start down to bf_low, and convergence at
                        BF_low: the change's fall from the first at BF_low toward b_eps, on a
                        log scale), reaching 1 when the run ends; not a share of the time
                        (refinement front-loads the work), so no base for an ETA */
} hr_phase;
/* Called on the thread that called hr_solver_run, with 'fraction' in [0, 1] never decreasing
 * within a phase; at most about 10 times a second, and once with fraction 1 at the end of each
 * phase. It must not call into the solver. */
typedef void (*hr_progress_fn)(void *ud, hr_phase phase, double fraction);
/* Sets (or with fn NULL, removes) the progress callback of 's'; call it before hr_solver_run,
 * and with fn NULL before destroying 's'. HR_ERR_INVALID when 's' is NULL, HR_ERR_NOMEM.
 * Initial linking reports HR_PHASE_LINK, the iterations HR_PHASE_SOLVE (in a distributed run,
 * each rank reports its own share of the linking). */
hr_status hr_solver_set_progress(hr_solver *s, hr_progress_fn fn, void *ud);
/* Delivers one report to the callback set for 's' (none: nothing happens). For the solver's
 * own use; can't fail. */
void hr_solver_progress_report(const hr_solver *s, hr_phase phase, double fraction);
void hr_solver_stats(const hr_solver *s, hr_stats *st);
/* 1 if the solver clusters (hr_options.cluster; decided at creation), in one process or over
 * several. */
int hr_solver_clustered(const hr_solver *s);

/* Writes the solver's state at an iteration boundary (from the iteration callback, or after
 * hr_solver_run) to 'path', atomically (PATH.tmp, then renamed). The file names elements and
 * links by global ids in a canonical order: it does not depend on the thread count, the number
 * of ranks or the assignment. In a distributed run every rank calls it (a collective) and rank 0
 * writes the file. HR_ERR_IO with a message on a write failure. */
hr_status hr_solver_checkpoint(const hr_solver *s, const char *path, hr_err *err);
/* Loads a checkpoint into a solver just made by hr_solver_create for the same scene and
 * options (and given its ranks by hr_solver_set_dist, if distributed: every rank reads the file
 * and keeps the links of its elements; any number of ranks may resume any checkpoint);
 * hr_solver_run then continues from it and ends with the result of an uninterrupted run, bit
 * for bit. Refused with a message (HR_ERR_INVALID) when the file was written for
 * another scene or other options, HR_ERR_PARSE when it is damaged. On any error the solver must
 * be destroyed. A checkpoint of a run that ended without converging (its max_iters, or its
 * callback) continues up to this solver's max_iters (not part of "the options"). */
hr_status hr_solver_resume(hr_solver *s, const char *path, hr_err *err);

/* Distributed solving over MPI processes (paper 2.2; docs/design.md, "Distribution").
 * hr_dist_start starts MPI when this process was launched by mpirun (or another MPI launcher)
 * and sets '*out'; otherwise '*out' is NULL (one process) and MPI is never touched. */
typedef struct hr_dist hr_dist;
hr_status hr_dist_start(int *argc, char ***argv, hr_dist **out, hr_err *err);
void hr_dist_finish(hr_dist **d);       /* MPI_Finalize if hr_dist_start initialised MPI */
void hr_dist_abort(const hr_dist *d, int code); /* ends every rank (MPI_Abort); no-op for NULL */
int hr_dist_rank(const hr_dist *d);     /* 0 for NULL */
int hr_dist_size(const hr_dist *d);     /* 1 for NULL */
/* 1 if 'flag' is non-zero on any rank: a collective (every rank calls it); 'flag' for NULL. */
int hr_dist_any(const hr_dist *d, int flag);
/* Spreads the solve over the ranks of 'd' (call on every rank, before hr_solver_run, with the
 * same scene, options and arguments). An element is owned by a rank, which holds the links it
 * receives. owner[i] is the rank of surface i's root; new elements belong to their parent's
 * rank; NULL spreads the surfaces by area, largest first, each to the rank with the least area
 * so far, or, when a balancing method is set (hr_solver_set_balance), by recursive bisection of
 * their centroids weighted by area (a compact piece of the scene a rank; in a clustered run,
 * runs of the cluster hierarchy), before initial linking. A non-zero 'scatter' instead sends
 * every element, at any depth, to a rank drawn from (scatter, its gid): one surface's tree
 * spread over every rank. Every rank then calls hr_solver_run; each holds its own elements and
 * links and ghost copies of what its links see, every root's radiosity afterwards
 * (hr_solver_poly_radiosity works on every rank), and, after hr_solver_collect, rank 0 every
 * leaf. Results, counts and outputs are bit-identical to one process for any assignment.
 * HR_ERR_INVALID for a bad owner. */
hr_status hr_solver_set_dist(hr_solver *s, hr_dist *d, const int32_t *owner, uint64_t scatter,
                             hr_err *err);

/* Moves elements to other ranks with the links they receive, between iterations: a collective
 * (every rank passes the same arrays). The element with global id gids[i] and every element
 * below it go to rank ranks[i], the deepest listed ancestor deciding; elements below no listed
 * gid go with their surface's root (hr_solver_set_dist). Global ids: hr_solver_leaf_gid. In a
 * clustered run an entry whose gid has the top bit set, 1 << 63 | c, names cluster c (of the
 * solver's hierarchy) instead, and sends the links it receives to rank ranks[i]. The result of
 * the run does not change (graph balancing, paper 2.2.5, uses it). HR_ERR_INVALID for a bad gid
 * or rank or a solver that is not distributed. */
hr_status hr_solver_migrate(hr_solver *s, const uint64_t *gids, const int32_t *ranks, int64_t n,
                            hr_err *err);
/* Graph balancing (paper 2.2.5; docs/design.md, "Balancing"): the patch/link graph with
 * measured weights partitioned, and the elements moved to their new ranks. */
enum { HR_BALANCE_NONE, HR_BALANCE_ANNEAL, HR_BALANCE_METIS, HR_BALANCE_ORB };
/* Balances with 'method' (HR_BALANCE_*) after initial linking and whenever an iteration's idle
 * time (1 - mean over max of the ranks' busy seconds in refinement, gathering and push-pull)
 * exceeds 'idle' (in [0, 1]), if what that idleness would lose pays for a balancing and the
 * balancings stay within 10% of the run (idle 0: every third iteration, whatever it costs);
 * 'alpha' weighs communication against work in the paper's cost (eq. (5)), in [0, 1]. Call
 * before hr_solver_run on every rank. HR_ERR_INVALID for bad values. The hrad program uses
 * HR_BALANCE_ANNEAL, 0.5 and 0.1 unless told otherwise. */
hr_status hr_solver_set_balance(hr_solver *s, int method, double alpha, double idle,
                                hr_err *err);
/* Balances now (a collective; a no-op in one process or for HR_BALANCE_NONE). */
hr_status hr_solver_balance(hr_solver *s, int method, hr_err *err);
/* Writes the patch/link graph (nodes with gid, parent gid, work and centre; edges with their
 * weights) to 'path' as text (rank 0 writes; a collective). Format: docs/design.md. */
hr_status hr_solver_dump_graph(hr_solver *s, const char *path, hr_err *err);

/* Distributed runs: brings every leaf to rank 0 (a collective), where hr_solver_leaves then
 * returns all of them; call it after hr_solver_run (and in the iteration callback before
 * per-iteration pictures). A no-op in one process. */
hr_status hr_solver_collect(hr_solver *s, hr_err *err);

/* One rank's share of a distributed run (hr_solver_rank_stats). */
typedef struct hr_rank_stats {
  int rank;
  int surfaces;          /* surfaces (element trees) it owns */
  int64_t links;         /* links it holds (live) */
  int64_t leaves;        /* leaf elements it owns */
  int64_t elements;      /* elements (tree nodes) it owns */
  int64_t ghosts;        /* other ranks' elements it holds a copy of */
  double elem_mb, link_mb; /* memory of its elements (own and ghosts) and of its links */
  int64_t msgs, msg_bytes; /* point-to-point message batches and bytes it sent */
  int64_t balancings, migrations; /* graph balancings, and those that moved elements */
  int64_t cluster_moves;  /* clusters whose links balancing moved to another rank (all ranks) */
  int64_t rays;          /* rays it cast */
  int64_t mpi_calls;     /* collectives it took part in */
  int64_t mpi_bytes;     /* bytes it sent in them */
  double busy_s;         /* solve time outside MPI */
  double mpi_s;          /* time inside MPI, waiting for the slowest rank included */
  double phase_busy[4];  /* per phase (init graph, refine, gather, push-pull): outside MPI */
  double phase_mpi[4];   /* and inside it */
  double peak_rss_mb;
} hr_rank_stats;
/* Every rank's share after hr_solver_run: a collective (every rank calls it); rank 0 gets
 * hr_dist_size entries in 'all', the others may pass NULL. One process: one entry. */
hr_status hr_solver_rank_stats(const hr_solver *s, hr_rank_stats *all, hr_err *err);

/* Area-weighted mean radiosity of input polygon 'poly' (rgb out). */
void hr_solver_poly_radiosity(const hr_solver *s, int poly, double rgb[3]);

/* Leaf elements, for rendering and meshes. Corner lattice coordinates are integers on the
 * surface's parameter lattice of side HR_LATTICE (= 2^HR_MAX_DEPTH): for a quad, (a,b) are
 * (u,v)*HR_LATTICE with corners v0=(0,0), v1=(L,0), v2=(L,L), v3=(0,L); for a triangle, (a,b)
 * are the barycentric weights of v1 and v2 times HR_LATTICE (v0 = (0,0), v1 = (L,0),
 * v2 = (0,L)). Corners are counter-clockwise like the surface. Two leaves of one surface share
 * a vertex exactly when their lattice coordinates are equal. */
#define HR_MAX_DEPTH 24
#define HR_LATTICE (1u << HR_MAX_DEPTH)
typedef struct hr_leaf {
  int surf;
  int nverts;          /* 3 or 4 */
  uint32_t lat[4][2];
  hr_vec3 p[4];        /* world positions of the corners */
  double area;
  double B[3];         /* radiosity, RGB: the mean over the leaf, covered parts included */
  double open;         /* the fraction of its area that nothing covers (0, 1] (a wall behind a
                          board it touches is covered); 0 counts as 1. Meshes show the open
                          part's radiosity E + (B - E) / open, weighted by open area */
} hr_leaf;

/* Copies the current leaves (any order stable for a given solution); caller frees *leaves. */
hr_status hr_solver_leaves(const hr_solver *s, hr_leaf **leaves, int64_t *nleaves);
const hr_scene *hr_solver_scene(const hr_solver *s);

/* ---------------------------------------------------------------- writing results (write.c) */

/* The files hrad writes, for a solved (or partly solved) solver: each writer reads the current
 * leaves, builds the smooth vertex mesh (seamless and crack-free; README "Outputs") and writes
 * one file. On error nothing is left at 'path' (a failed write removes the partial file) and
 * 'err' names the path and the cause (HR_ERR_IO); HR_ERR_NOMEM; HR_ERR_INVALID for bad
 * arguments. Display colours are srgb(clamp(B * exposure, 0, 1)); an exposure <= 0 means the
 * automatic one (hr_solver_exposure), so files written with 0 agree with each other. */

/* The automatic exposure: the factor that maps the area-weighted 95th percentile of the
 * luminance of non-emitting surfaces to 0.8 (1 for a black solution). */
hr_status hr_solver_exposure(const hr_solver *s, double *exposure, hr_err *err);

typedef struct hr_image_options {
  int width, height;       /* pixels: each 16..16384, at most 2^26 in all (default 800 x 600) */
  const hr_camera *camera; /* NULL (default): the scene's camera, else hr_scene_auto_camera */
  double exposure;         /* linear factor, <= 0 (default): automatic */
  int elements;            /* 0 (default): smooth image; 1: every element flat, with outlines */
} hr_image_options;
/* Fills 'o' with the defaults. */
void hr_image_options_default(hr_image_options *o);

/* SCENE.png: an 8-bit sRGB image of the solution (2x2 supersampled); 'o' NULL: the defaults. */
hr_status hr_solver_write_png(const hr_solver *s, const char *path, const hr_image_options *o,
                              hr_err *err);
/* SCENE.ply: binary little-endian PLY of the smooth mesh; per vertex float x,y,z, uchar
 * red,green,blue (display colour) and float radiosity_r/g/b (linear B, W/m^2). */
hr_status hr_solver_write_ply(const hr_solver *s, const char *path, double exposure,
                              hr_err *err);
/* SCENE.glb: glTF 2.0 binary of the smooth mesh: one node and mesh per object of the scene
 * (names kept), one unlit material per input material; COLOR_0 is linear B * exposure clamped to
 * [0, 1], _RADIOSITY the unclamped linear B; asset.extras.exposure records the exposure. */
hr_status hr_solver_write_glb(const hr_solver *s, const char *path, double exposure,
                              hr_err *err);
/* surfaces.csv: "id,area,r,g,b,status", one row per input polygon in input order (README). */
hr_status hr_solver_write_csv(const hr_solver *s, const char *path, hr_err *err);
/* stats.json: counts, per-phase times and the options 'o' the solver was made with. */
hr_status hr_solver_write_json(const hr_solver *s, const hr_options *o, const char *path,
                               hr_err *err);
/* viewer.html at 'path': a self-contained page (three.js inlined, from the copy built into the
 * library, or from $HRAD_THREE_DIR when set) showing the .glb 'glb_name' (relative to the
 * directory of 'path' unless absolute; read and embedded) with orbit controls; works offline
 * from file://. HR_ERR_IO naming the path when three.js or the .glb is missing. */
hr_status hr_viewer_write(const char *path, const char *glb_name, hr_err *err);

/* ---------------------------------------------------------------- reference path tracer (pt.c) */

/* An independent Monte Carlo estimate of the same radiosity the solver computes, for checking it:
 * the slow, obviously correct twin of the whole solver. Same scene model: one-sided diffuse
 * surfaces; light leaves the front only; a ray that reaches a back face or leaves the scene
 * carries nothing; B(x) = E(x) + rho(x) * integral over the front hemisphere of B(y)/pi cos dw.
 * Paths use next-event estimation (an emitting surface picked by area * (E_r+E_g+E_b), a uniform
 * point on it) and cosine-weighted hemisphere sampling, combined by MIS (power heuristic), and
 * Russian roulette (unbiased). Random numbers are a counter-based hash of (seed, item, sample),
 * so results are bit-identical for any thread count. */
typedef struct hr_pt_options {
  int64_t paths; /* samples per polygon (hr_pt_polys), >= 1 */
  uint64_t seed;
  int threads;   /* 0 = all cores */
} hr_pt_options;

/* Fills 'o' with the defaults: 10000 paths, seed 1, all cores. */
void hr_pt_options_default(hr_pt_options *o);

/* Mean radiosity of every input polygon (s->npolys rows of RGB) over o->paths points drawn
 * uniformly by area on its surfaces, and the standard error of each mean (sqrt of the sample
 * variance / paths; NaN when paths == 1). 'o' NULL means the defaults; 'stderr_' may be NULL.
 * HR_ERR_INVALID for bad arguments, HR_ERR_NOMEM, or the ray caster's error. Never prints. */
hr_status hr_pt_polys(const hr_scene *s, const hr_pt_options *o, double (*mean)[3],
                      double (*stderr_)[3], hr_err *err);

/* Radiosity image from camera 'cam' (w*h*3 floats, linear, row 0 at the top; the same camera
 * model and pixel grid as hr_render: pixel (x, y) spans NDC [2x/w-1, 2(x+1)/w-1] and rows run
 * from NDC y = 1 down). Each pixel is the mean of 'spp' camera rays, stratified and jittered
 * over the pixel; a ray that first hits a front face gives that point's radiosity estimate,
 * a back face or a miss gives 0. 'se' (w*h*3, may be NULL) receives each pixel's standard error
 * as if its samples were independent (stratification makes the true error smaller; NaN when
 * spp == 1). o->paths is not used. Errors as for hr_pt_polys. */
hr_status hr_pt_image(const hr_scene *s, const hr_camera *cam, int w, int h, int spp,
                      const hr_pt_options *o, float *rgb, float *se, hr_err *err);

#ifdef __cplusplus
}
#endif
#endif
