/* hrad: the command line. Parses options, loads or builds the scene, runs the solver with one
 * progress line per iteration, and writes the results into the output directory atomically
 * (everything goes to a temporary directory inside it first and is renamed into place at the end,
 * so a failed run leaves no partial result files). The only part of hrad that prints. */
#include "hrad.h"
#include "output.h"
#include "report.h"

#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>
#include <dirent.h>

typedef struct cli {
  hr_options opt;
  const char *scene_arg;
  const char *outdir;
  int quiet;
  int snapshots;
  int hdr;
  int have_camera;
  hr_camera camera;
  int w, h;
  double exposure; /* 0 = automatic */
  int nemit, cap_emit;
  char **emit_name;
  double (*emit_rgb)[3];
  int64_t verify_paths; /* --verify N: path-traced reference per polygon (0 = off) */
  int verify_spp;       /* --verify-image SPP: path-traced reference image (0 = off) */
  /* run state */
  char tmpdir[4096];
  int outdir_made;
  const hr_scene *scene;
  hr_camera cam;
} cli;

static void die_usage(const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  fprintf(stderr, "hrad: ");
  vfprintf(stderr, fmt, ap);
  fprintf(stderr, "\nTry 'hrad --help'.\n");
  va_end(ap);
  exit(2);
}

static void usage(void) {
  hr_options d;
  hr_options_default(&d);
  printf(
      "Usage: hrad [OPTIONS] [SCENE]\n"
      "Hierarchical radiosity (Bohn & Garmann, WSCG'95). SCENE is a built-in name (room, floor,\n"
      "museum, cornell; default room) or a path to a Wavefront .obj file with its .mtl.\n"
      "\n"
      "Output (written atomically into DIR):\n"
      "  -o, --out DIR        output directory (default hrad-out): surfaces.csv, stats.json,\n"
      "                       SCENE.png, SCENE-elements.png, SCENE.ply, SCENE.glb, viewer.html\n"
      "  --size WxH           image size (default 800x600)\n"
      "  --camera E:A[:FOV]   camera eye and look-at point, 'ex,ey,ez:ax,ay,az[:fov]' (degrees)\n"
      "  --exposure X         linear exposure factor (default: automatic)\n"
      "  --hdr                also write SCENE.pfm (linear radiosity image)\n"
      "  --snapshots          write DIR/iter-NN.png after every iteration while solving\n"
      "  --quiet              no progress lines or timing table\n"
      "\n"
      "Checking (an independent Monte Carlo path tracer, README 'Checking the light'):\n"
      "  --verify N           after solving, estimate every polygon with N paths, print a\n"
      "                       per-polygon comparison and the area-weighted RMS error, write\n"
      "                       DIR/verify.csv\n"
      "  --verify-image SPP   path-trace the image at SPP samples per pixel, write\n"
      "                       DIR/SCENE-reference.png and print the mean per-pixel error\n"
      "\n"
      "Scene:\n"
      "  --emit NAME=R,G,B    make material NAME emit radiosity R,G,B (W/m^2); repeatable\n"
      "\n"
      "Solver (thresholds are dimensionless: errors relative to the light each element\n"
      "receives, B relative to the scene's mean radiosity, areas relative to the total area,\n"
      "so they suit scenes in any unit and any brightness):\n"
      "  --bf-low X           accuracy: the largest error a link may bring its receiver,\n"
      "                       relative to the receiver's light; the main quality setting\n"
      "                       (default %g; smaller is more accurate and slower)\n"
      "  --bf-start X         first BF_e of the multigrid schedule (default %g)\n"
      "  --bf-factor X        BF_e is divided by X per level (default %g)\n"
      "  --area-min X         minimum element area A_e, relative to the total area\n"
      "                       (default: equal to BF_low)\n"
      "  --b-eps X            convergence: max change of B below X (default %g)\n"
      "  --b-max X            B_max of the relaxed inner loop (default %g)\n"
      "  --no-relax           rigid inner loop (paper Figure 3) instead of section 2.2.4\n"
      "  --rays K             rays per link for the visible fraction H (default %d)\n"
      "  --seed N             jitter seed (default %llu)\n"
      "  --threads N          worker threads (default: all cores)\n"
      "  --max-iters N        stop after N iterations (default %d)\n"
      "  --max-pairs N        refuse scenes with more surface pairs than N (default %g)\n"
      "  -h, --help           this help\n",
      d.bf_low, d.bf_start, d.bf_factor, d.b_eps, d.b_max, d.rays, (unsigned long long)d.seed,
      d.max_iters, d.max_links);
}

static double parse_num(const char *opt, const char *v) {
  char *end;
  errno = 0;
  double x = strtod(v, &end);
  if (errno || end == v || *end || x != x) die_usage("%s: not a number: '%s'", opt, v);
  return x;
}

/* An integer option value in [1, max]; anything else is a usage error. */
static double parse_count(const char *opt, const char *v, double max) {
  double x = parse_num(opt, v);
  if (!(x >= 1 && x <= max && x == floor(x)))
    die_usage("%s: expected a whole number from 1 to %g, got '%s'", opt, max, v);
  return x;
}

static int parse_vec(const char *s, double *out, int n) {
  for (int i = 0; i < n; i++) {
    char *end;
    out[i] = strtod(s, &end);
    if (end == s || !(out[i] == out[i])) return 0;
    s = end;
    if (i + 1 < n) {
      if (*s != ',') return 0;
      s++;
    }
  }
  return *s == 0 || *s == ':';
}

static void parse_camera(cli *c, const char *v) {
  double e[3], a[3];
  const char *colon = strchr(v, ':');
  if (!colon || !parse_vec(v, e, 3) || !parse_vec(colon + 1, a, 3))
    die_usage("--camera: expected 'ex,ey,ez:ax,ay,az[:fov]', got '%s'", v);
  c->camera.eye = (hr_vec3){e[0], e[1], e[2]};
  c->camera.at = (hr_vec3){a[0], a[1], a[2]};
  c->camera.up = (hr_vec3){0, 1, 0};
  c->camera.fov_deg = 50;
  const char *c2 = strchr(colon + 1, ':');
  if (c2) c->camera.fov_deg = parse_num("--camera fov", c2 + 1);
  if (!(c->camera.fov_deg > 1 && c->camera.fov_deg < 179)) die_usage("--camera: fov out of range");
  c->have_camera = 1;
}

static void parse_emit(cli *c, const char *v) {
  const char *eq = strrchr(v, '=');
  double rgb[3];
  if (!eq || eq == v || !parse_vec(eq + 1, rgb, 3) || strchr(eq + 1, ':'))
    die_usage("--emit: expected NAME=R,G,B, got '%s'", v);
  for (int k = 0; k < 3; k++)
    if (rgb[k] < 0) die_usage("--emit: negative radiosity in '%s'", v);
  if (c->nemit == c->cap_emit) {
    c->cap_emit = c->cap_emit ? 2 * c->cap_emit : 8;
    c->emit_name = realloc(c->emit_name, (size_t)c->cap_emit * sizeof *c->emit_name);
    c->emit_rgb = realloc(c->emit_rgb, (size_t)c->cap_emit * sizeof *c->emit_rgb);
    if (!c->emit_name || !c->emit_rgb) die_usage("out of memory");
  }
  c->emit_name[c->nemit] = strndup(v, (size_t)(eq - v));
  memcpy(c->emit_rgb[c->nemit], rgb, sizeof rgb);
  c->nemit++;
}

static void parse_args(cli *c, int argc, char **argv) {
  hr_options_default(&c->opt);
  c->outdir = "hrad-out";
  c->w = 800;
  c->h = 600;
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
#define NEXT() (i + 1 < argc ? argv[++i] : (die_usage("%s needs a value", a), ""))
    if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
      usage();
      exit(0);
    } else if (!strcmp(a, "-o") || !strcmp(a, "--out")) c->outdir = NEXT();
    else if (!strcmp(a, "--quiet")) c->quiet = 1;
    else if (!strcmp(a, "--snapshots")) c->snapshots = 1;
    else if (!strcmp(a, "--hdr")) c->hdr = 1;
    else if (!strcmp(a, "--no-relax")) c->opt.relax = 0;
    else if (!strcmp(a, "--bf-low")) c->opt.bf_low = parse_num(a, NEXT());
    else if (!strcmp(a, "--bf-start")) c->opt.bf_start = parse_num(a, NEXT());
    else if (!strcmp(a, "--bf-factor")) c->opt.bf_factor = parse_num(a, NEXT());
    else if (!strcmp(a, "--area-min")) c->opt.area_min = parse_num(a, NEXT());
    else if (!strcmp(a, "--b-eps")) c->opt.b_eps = parse_num(a, NEXT());
    else if (!strcmp(a, "--b-max")) c->opt.b_max = parse_num(a, NEXT());
    else if (!strcmp(a, "--rays")) c->opt.rays = (int)parse_num(a, NEXT());
    else if (!strcmp(a, "--seed")) c->opt.seed = (uint64_t)parse_num(a, NEXT());
    else if (!strcmp(a, "--threads")) c->opt.threads = (int)parse_num(a, NEXT());
    else if (!strcmp(a, "--max-iters")) c->opt.max_iters = (int)parse_num(a, NEXT());
    else if (!strcmp(a, "--max-pairs")) c->opt.max_links = parse_num(a, NEXT());
    else if (!strcmp(a, "--verify")) c->verify_paths = (int64_t)parse_count(a, NEXT(), 1e12);
    else if (!strcmp(a, "--verify-image")) c->verify_spp = (int)parse_count(a, NEXT(), 1e6);
    else if (!strcmp(a, "--exposure")) {
      c->exposure = parse_num(a, NEXT());
      if (!(c->exposure > 0)) die_usage("--exposure must be > 0");
    } else if (!strcmp(a, "--camera")) parse_camera(c, NEXT());
    else if (!strcmp(a, "--emit")) parse_emit(c, NEXT());
    else if (!strcmp(a, "--size")) {
      const char *v = NEXT();
      if (sscanf(v, "%dx%d", &c->w, &c->h) != 2 || c->w < 16 || c->h < 16 || c->w > 16384 ||
          c->h > 16384)
        die_usage("--size: expected WxH between 16 and 16384, got '%s'", v);
    } else if (a[0] == '-' && a[1] != 0) die_usage("unknown option '%s'", a);
    else if (c->scene_arg) die_usage("more than one scene given ('%s' and '%s')", c->scene_arg, a);
    else c->scene_arg = a;
#undef NEXT
  }
  if (!c->scene_arg) c->scene_arg = "room";
}

static void warn_cb(void *ud, const char *msg) {
  (void)ud;
  fprintf(stderr, "hrad: warning: %s\n", msg);
}

/* ---------------------------------------------------------------- output files */

static void rm_tree_flat(const char *dir) {
  DIR *d = opendir(dir);
  if (!d) return;
  struct dirent *e;
  char p[8192];
  while ((e = readdir(d))) {
    if (!strcmp(e->d_name, ".") || !strcmp(e->d_name, "..")) continue;
    snprintf(p, sizeof p, "%s/%s", dir, e->d_name);
    unlink(p);
  }
  closedir(d);
  rmdir(dir);
}

static cli *g_cli; /* for cleanup on error */

static void fail(const char *msg) {
  fprintf(stderr, "hrad: %s\n", msg);
  if (g_cli && g_cli->tmpdir[0]) rm_tree_flat(g_cli->tmpdir);
  exit(1);
}

static void ensure_outdir(cli *c) {
  if (c->outdir_made) return;
  if (mkdir(c->outdir, 0777) != 0 && errno != EEXIST) {
    char m[4200];
    snprintf(m, sizeof m, "%s: cannot create directory: %s", c->outdir, strerror(errno));
    fail(m);
  }
  struct stat st;
  if (stat(c->outdir, &st) != 0 || !S_ISDIR(st.st_mode)) {
    char m[4200];
    snprintf(m, sizeof m, "%s: not a directory", c->outdir);
    fail(m);
  }
  snprintf(c->tmpdir, sizeof c->tmpdir, "%s/.hrad-tmp-%ld", c->outdir, (long)getpid());
  if (mkdir(c->tmpdir, 0777) != 0) {
    char m[8300];
    snprintf(m, sizeof m, "%s: cannot create directory: %s", c->tmpdir, strerror(errno));
    c->tmpdir[0] = 0;
    fail(m);
  }
  c->outdir_made = 1;
}

static void tmp_path(const cli *c, const char *name, char *out, size_t n) {
  snprintf(out, n, "%s/%s", c->tmpdir, name);
}

static void check(hr_status st, const hr_err *err) {
  if (st != HR_OK) fail(err->msg);
}

/* The current solution's leaves ('*leaves', '*n'; caller frees) and smooth mesh (returned;
 * caller destroys), and the exposure of the PNGs: --exposure, else automatic. Exits on error. */
static hr_mesh *solution_mesh(const cli *c, const hr_solver *s, hr_leaf **leaves, int64_t *n,
                              double *expo) {
  if (hr_solver_leaves(s, leaves, n) != HR_OK) fail("out of memory");
  hr_mesh *m;
  check(hr_mesh_build(c->scene, *leaves, *n, &m), &(hr_err){.msg = "out of memory building mesh"});
  *expo = c->exposure > 0 ? c->exposure : hr_exposure_auto(m);
  return m;
}

/* Renders the current solution from the run's camera and writes 'name' (PNG) into tmpdir. With
 * 'all' it also writes the elements image, PLY, GLB, viewer and PFM. */
static void write_pictures(cli *c, const hr_solver *s, const char *png_name, int all) {
  hr_err err = {{0}};
  hr_leaf *leaves;
  int64_t n;
  double expo;
  hr_mesh *m = solution_mesh(c, s, &leaves, &n, &expo);
  float *img = malloc((size_t)c->w * c->h * 3 * sizeof *img);
  if (!img) fail("out of memory");
  char path[8400];
  check(hr_render_ex(c->scene, m, leaves, n, &c->cam, c->w, c->h, 0, 2, 1.0 / expo, img),
        &(hr_err){.msg = "render failed"});
  tmp_path(c, png_name, path, sizeof path);
  check(hr_png_write(path, c->w, c->h, img, expo, &err), &err);
  if (all) {
    const char *nm = c->scene->name;
    char name[4200];
    if (c->hdr) {
      check(hr_render_ex(c->scene, m, leaves, n, &c->cam, c->w, c->h, 0, 2, 0, img),
            &(hr_err){.msg = "render failed"});
      snprintf(name, sizeof name, "%s.pfm", nm);
      tmp_path(c, name, path, sizeof path);
      check(hr_pfm_write(path, c->w, c->h, img, &err), &err);
    }
    check(hr_render_ex(c->scene, m, leaves, n, &c->cam, c->w, c->h, 1, 2, 1.0 / expo, img),
          &(hr_err){.msg = "render failed"});
    snprintf(name, sizeof name, "%s-elements.png", nm);
    tmp_path(c, name, path, sizeof path);
    check(hr_png_write(path, c->w, c->h, img, expo, &err), &err);
    snprintf(name, sizeof name, "%s.ply", nm);
    tmp_path(c, name, path, sizeof path);
    check(hr_ply_write(path, m, expo, &err), &err);
    snprintf(name, sizeof name, "%s.glb", nm);
    tmp_path(c, name, path, sizeof path);
    check(hr_glb_write(path, m, expo, &err), &err);
    tmp_path(c, "viewer.html", path, sizeof path);
    if (hr_viewer_write(path, name, &err) != HR_OK)
      fprintf(stderr, "hrad: warning: viewer.html not written: %s\n", err.msg);
  }
  free(img);
  hr_mesh_destroy(&m);
  free(leaves);
}

/* ---------------------------------------------------------------- --verify, --verify-image */

static double now_s(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static double norm3(const double v[3]) { return sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }

/* One polygon of the comparison between hrad and the path tracer. */
typedef struct vrow {
  double hrad[3], ref[3], se[3];
  double rel;  /* |hrad - ref| / |ref| over the RGB vector; NaN when the reference is 0 */
  int mat;     /* material of the polygon's first surface */
  int emitter; /* some surface of the polygon emits */
} vrow;

/* |a - ref| / |ref| (RGB norms), NaN when ref is 0. */
static double rel_err(const double a[3], const double ref[3]) {
  double d[3] = {a[0] - ref[0], a[1] - ref[1], a[2] - ref[2]}, r = norm3(ref);
  return r > 0 ? norm3(d) / r : NAN;
}

/* Fills the material and emitter flag of every polygon from its surfaces. */
static void poly_materials(const hr_scene *sc, vrow *rows) {
  for (int p = 0; p < sc->npolys; p++) rows[p].mat = -1, rows[p].emitter = 0;
  for (int i = 0; i < sc->nsurfs; i++) {
    const hr_surface *f = &sc->surfs[i];
    const double *e = sc->mats[f->material].emit;
    if (rows[f->poly].mat < 0) rows[f->poly].mat = f->material;
    rows[f->poly].emitter |= e[0] > 0 || e[1] > 0 || e[2] > 0;
  }
}

static const char *mat_name(const hr_scene *sc, int m) {
  return m >= 0 && sc->mats[m].name ? sc->mats[m].name : "-";
}

/* Writes 's' as one CSV field, quoted when it holds a comma, quote or line break. */
static void csv_field(FILE *f, const char *s) {
  if (!strpbrk(s, ",\"\r\n")) {
    fputs(s, f);
    return;
  }
  fputc('"', f);
  for (; *s; s++) {
    if (*s == '"') fputc('"', f);
    fputc(*s, f);
  }
  fputc('"', f);
}

/* verify.csv in tmpdir: one row per polygon (rel_err is nan where the reference is 0). */
static void write_verify_csv(const cli *c, const vrow *rows) {
  char path[8400];
  tmp_path(c, "verify.csv", path, sizeof path);
  FILE *f = fopen(path, "w");
  if (!f) fail("verify.csv: cannot write");
  fprintf(f, "id,area,material,emitter,hrad_r,hrad_g,hrad_b,ref_r,ref_g,ref_b,se_r,se_g,se_b,"
             "rel_err\n");
  for (int p = 0; p < c->scene->npolys; p++) {
    const vrow *r = &rows[p];
    fprintf(f, "%d,%.9g,", hr_scene_poly_input(c->scene, p), c->scene->poly_area[p]);
    csv_field(f, mat_name(c->scene, r->mat));
    fprintf(f, ",%d,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.6g,%.6g,%.6g,%.6g\n", r->emitter, r->hrad[0],
            r->hrad[1], r->hrad[2], r->ref[0], r->ref[1], r->ref[2], r->se[0], r->se[1], r->se[2],
            r->rel);
  }
  int bad = ferror(f);
  if (fclose(f) != 0 || bad) fail("verify.csv: write failed");
}

/* The per-polygon table on stderr: hrad's radiosity, the reference with its 95% confidence
 * interval (1.96 standard errors) per channel, and the relative error. */
static void print_verify_table(const hr_scene *sc, const vrow *rows, int64_t paths) {
  fprintf(stderr, "verify: %lld paths per polygon\n", (long long)paths);
  fprintf(stderr, "verify:   id material           area       hrad r, g, b                 "
                  "reference r, g, b (+- 95%%)                  rel.err\n");
  for (int p = 0; p < sc->npolys; p++) {
    const vrow *r = &rows[p];
    fprintf(stderr, "verify: %4d %-16.16s %9.4g  %8.4g %8.4g %8.4g  ", hr_scene_poly_input(sc, p),
            mat_name(sc, r->mat),
            sc->poly_area[p], r->hrad[0], r->hrad[1], r->hrad[2]);
    for (int k = 0; k < 3; k++) fprintf(stderr, " %8.4g+-%-7.2g", r->ref[k], 1.96 * r->se[k]);
    if (isnan(r->rel))
      fprintf(stderr, "       -");
    else
      fprintf(stderr, " %7.2f%%", 100 * r->rel);
    fprintf(stderr, "%s\n", r->emitter ? " emitter" : "");
  }
}

/* The summary line: area-weighted RMS of the relative error over non-emitting polygons with a
 * non-zero reference, the worst of them, and the reference's own noise (area-weighted RMS of
 * |se| / |ref|). */
static void print_verify_summary(const hr_scene *sc, const vrow *rows, double secs,
                                 int64_t paths) {
  double sa = 0, se2 = 0, sn2 = 0, worst = -1;
  int cnt = 0, wp = -1;
  for (int p = 0; p < sc->npolys; p++) {
    const vrow *r = &rows[p];
    double A = sc->poly_area[p], nr = norm3(r->ref);
    if (r->emitter || !(nr > 0)) continue;
    sa += A;
    se2 += A * r->rel * r->rel;
    sn2 += A * (norm3(r->se) / nr) * (norm3(r->se) / nr);
    cnt++;
    if (r->rel > worst) worst = r->rel, wp = p;
  }
  double rate = secs > 0 ? (double)paths * sc->npolys / secs : 0;
  if (cnt == 0 || !(sa > 0)) {
    fprintf(stderr, "verify: no lit non-emitting polygon to compare; path tracer %.1f s\n", secs);
    return;
  }
  fprintf(stderr,
          "verify: area-weighted RMS error %.2f%% over %d non-emitting polygons, worst %.2f%% "
          "(polygon %d, %s); reference noise %.2f%%; path tracer %.1f s (%.3g paths/s)\n",
          100 * sqrt(se2 / sa), cnt, 100 * worst, hr_scene_poly_input(sc, wp),
          mat_name(sc, rows[wp].mat),
          100 * sqrt(sn2 / sa), secs, rate);
}

/* --verify: traces every polygon with c->verify_paths paths, compares with the solution 's',
 * prints the table (unless --quiet) and the summary, and writes verify.csv into tmpdir. */
static void verify_polys(cli *c, const hr_solver *s) {
  const hr_scene *sc = c->scene;
  hr_err err = {{0}};
  vrow *rows = calloc((size_t)sc->npolys, sizeof *rows);
  double (*mean)[3] = malloc((size_t)sc->npolys * sizeof *mean);
  double (*se)[3] = malloc((size_t)sc->npolys * sizeof *se);
  if (!rows || !mean || !se) fail("out of memory");
  hr_pt_options o = {c->verify_paths, c->opt.seed, c->opt.threads};
  double t0 = now_s();
  check(hr_pt_polys(sc, &o, mean, se, &err), &err);
  double secs = now_s() - t0;
  poly_materials(sc, rows);
  for (int p = 0; p < sc->npolys; p++) {
    hr_solver_poly_radiosity(s, p, rows[p].hrad);
    memcpy(rows[p].ref, mean[p], sizeof rows[p].ref);
    memcpy(rows[p].se, se[p], sizeof rows[p].se);
    rows[p].rel = rel_err(rows[p].hrad, rows[p].ref);
  }
  if (!c->quiet) print_verify_table(sc, rows, c->verify_paths);
  print_verify_summary(sc, rows, secs, c->verify_paths);
  write_verify_csv(c, rows);
  free(rows);
  free(mean);
  free(se);
}

static double normf3(const float *v) {
  return sqrt((double)v[0] * v[0] + (double)v[1] * v[1] + (double)v[2] * v[2]);
}

/* The mean relative per-pixel error |img - ref| / |ref| (RGB norms) over the pixels whose
 * reference exceeds 1% of the image's mean |ref|, with the mean relative noise of the reference
 * over the same pixels, as one line on stderr. */
static void print_image_error(const cli *c, const float *img, const float *ref, const float *se,
                              double secs) {
  size_t np = (size_t)c->w * c->h, cnt = 0;
  double mean = 0, err = 0, noise = 0;
  for (size_t i = 0; i < np; i++) mean += normf3(ref + 3 * i) / np;
  for (size_t i = 0; i < np; i++) {
    double r = normf3(ref + 3 * i);
    if (!(r > 0.01 * mean)) continue;
    float d[3] = {img[3 * i] - ref[3 * i], img[3 * i + 1] - ref[3 * i + 1],
                  img[3 * i + 2] - ref[3 * i + 2]};
    err += normf3(d) / r;
    noise += normf3(se + 3 * i) / r;
    cnt++;
  }
  if (cnt == 0) {
    fprintf(stderr, "verify-image: the reference image is black; path tracer %.1f s\n", secs);
    return;
  }
  fprintf(stderr,
          "verify-image: mean relative per-pixel error %.2f%% over %zu of %zu pixels (reference "
          "above 1%% of its mean); reference noise %.2f%%; %dx%d at %d spp, path tracer %.1f s\n",
          100 * err / cnt, cnt, np, 100 * noise / cnt, c->w, c->h, c->verify_spp, secs);
}

/* --verify-image: path-traces the run's view at c->verify_spp samples per pixel, writes
 * SCENE-reference.png (the exposure of SCENE.png) into tmpdir, and compares hrad's smooth
 * rendering (linear, unclamped) with it. */
static void verify_image(cli *c, const hr_solver *s) {
  hr_err err = {{0}};
  hr_leaf *leaves;
  int64_t n;
  double expo;
  hr_mesh *m = solution_mesh(c, s, &leaves, &n, &expo);
  size_t np = (size_t)c->w * c->h;
  float *img = malloc(3 * np * sizeof *img), *ref = malloc(3 * np * sizeof *ref);
  float *se = malloc(3 * np * sizeof *se);
  if (!img || !ref || !se) fail("out of memory");
  check(hr_render_ex(c->scene, m, leaves, n, &c->cam, c->w, c->h, 0, 2, -1, img),
        &(hr_err){.msg = "render failed"});
  hr_pt_options o = {1, c->opt.seed, c->opt.threads};
  double t0 = now_s();
  check(hr_pt_image(c->scene, &c->cam, c->w, c->h, c->verify_spp, &o, ref, se, &err), &err);
  double secs = now_s() - t0;
  char name[4200], path[8400];
  snprintf(name, sizeof name, "%s-reference.png", c->scene->name);
  tmp_path(c, name, path, sizeof path);
  check(hr_png_write(path, c->w, c->h, ref, expo, &err), &err);
  print_image_error(c, img, ref, se, secs);
  free(img);
  free(ref);
  free(se);
  hr_mesh_destroy(&m);
  free(leaves);
}

/* Moves every file of tmpdir into outdir, then removes tmpdir. */
static void commit_outputs(cli *c) {
  DIR *d = opendir(c->tmpdir);
  if (!d) fail("cannot read the temporary output directory");
  struct dirent *e;
  char from[8400], to[8400];
  while ((e = readdir(d))) {
    if (e->d_name[0] == '.') continue;
    snprintf(from, sizeof from, "%s/%s", c->tmpdir, e->d_name);
    snprintf(to, sizeof to, "%s/%s", c->outdir, e->d_name);
    if (rename(from, to) != 0) {
      char m[9000];
      snprintf(m, sizeof m, "%s: cannot rename into place: %s", to, strerror(errno));
      closedir(d);
      fail(m);
    }
  }
  closedir(d);
  rmdir(c->tmpdir);
  c->tmpdir[0] = 0;
}

static int on_iter(void *ud, const hr_solver *s, const hr_iter_info *it) {
  cli *c = ud;
  if (!c->quiet)
    fprintf(stderr,
            "iter %3d  BF_e %.3e  elements %9lld  links %10lld  max change %.3e  %8.3f s\n",
            it->iter, it->bf_e, (long long)it->elements, (long long)it->links, it->max_change,
            it->elapsed_s);
  if (c->snapshots) {
    /* Snapshots go straight into DIR (renamed into place one by one) so a long run can be
     * watched; they are progress, not results. */
    ensure_outdir(c);
    char name[64], from[8400], to[8400];
    snprintf(name, sizeof name, "iter-%02d.png", it->iter);
    write_pictures(c, s, name, 0);
    tmp_path(c, name, from, sizeof from);
    snprintf(to, sizeof to, "%s/%s", c->outdir, name);
    if (rename(from, to) != 0) fail("cannot write snapshot");
  }
  return 0;
}

static int is_builtin(const char *name) {
  for (const char *const *n = hr_scene_builtin_names(); *n; n++)
    if (!strcmp(*n, name)) return 1;
  return 0;
}

int main(int argc, char **argv) {
  cli c;
  memset(&c, 0, sizeof c);
  g_cli = &c;
  parse_args(&c, argc, argv);
  hr_err err = {{0}};
  hr_log log = {c.quiet ? NULL : warn_cb, NULL};
  hr_scene *scene = NULL;
  hr_status st;
  if (is_builtin(c.scene_arg)) {
    st = hr_scene_builtin(c.scene_arg, &scene, &err);
  } else {
    size_t l = strlen(c.scene_arg);
    struct stat sb;
    if (stat(c.scene_arg, &sb) != 0 && !(l > 4 && !strcmp(c.scene_arg + l - 4, ".obj")) &&
        !strchr(c.scene_arg, '/')) {
      fprintf(stderr,
              "hrad: unknown scene '%s' (built-in: room, floor, museum, cornell; or a path to an "
              ".obj file)\n",
              c.scene_arg);
      return 1;
    }
    st = hr_scene_load_obj(c.scene_arg, &log, &scene, &err);
  }
  check(st, &err);
  for (int i = 0; i < c.nemit; i++) {
    check(hr_scene_set_emit(scene, c.emit_name[i], c.emit_rgb[i], &err), &err);
    free(c.emit_name[i]);
  }
  free(c.emit_name);
  free(c.emit_rgb);
  c.scene = scene;
  if (c.have_camera) c.cam = c.camera;
  else if (scene->has_camera) c.cam = scene->camera;
  else hr_scene_auto_camera(scene, &c.cam);
  hr_solver *s = NULL;
  check(hr_solver_create(scene, &c.opt, &s, &err), &err);
  if (!c.quiet) {
    hr_vec3 lo, hi;
    hr_scene_bounds(scene, &lo, &hi);
    fprintf(stderr,
            "hrad: scene '%s': %d polygons, %d surfaces, %d materials, area %.4g, bounds "
            "(%.3g %.3g %.3g)-(%.3g %.3g %.3g)\n",
            scene->name, scene->npolys, scene->nsurfs, scene->nmats, hr_scene_total_area(scene),
            lo.x, lo.y, lo.z, hi.x, hi.y, hi.z);
  }
  check(hr_solver_run(s, on_iter, &c, &err), &err);
  ensure_outdir(&c);
  char path[8400], name[4200];
  tmp_path(&c, "surfaces.csv", path, sizeof path);
  check(hr_report_csv(path, s, &err), &err);
  tmp_path(&c, "stats.json", path, sizeof path);
  check(hr_report_json(path, s, &c.opt, &err), &err);
  snprintf(name, sizeof name, "%s.png", scene->name);
  write_pictures(&c, s, name, 1);
  if (c.verify_paths) verify_polys(&c, s);
  if (c.verify_spp) verify_image(&c, s);
  commit_outputs(&c);
  hr_stats stats;
  hr_solver_stats(s, &stats);
  if (!c.quiet) {
    hr_report_table(stderr, &stats);
    if (!stats.converged)
      fprintf(stderr, "hrad: warning: stopped after %d iterations without converging\n",
              stats.iterations);
    fprintf(stderr, "hrad: wrote %s/{surfaces.csv,stats.json,%s.png,%s-elements.png,%s.ply,%s.glb,"
            "viewer.html%s%s%s%s}\n", c.outdir, scene->name, scene->name, scene->name, scene->name,
            c.verify_paths ? ",verify.csv" : "", c.verify_spp ? "," : "",
            c.verify_spp ? scene->name : "", c.verify_spp ? "-reference.png" : "");
  }
  hr_solver_destroy(&s);
  hr_scene_destroy(&scene);
  return 0;
}
