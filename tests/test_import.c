/* test_import.c: scenes through assimp (src/import.c), textures (src/texture.c), the GLB that
 * keeps objects and materials (src/mesh.c), and smooth shading across coplanar polygons.
 *  - tests/data/lamp_floor.gltf: a unit floor (object "Floor", material "floor paint", base colour
 *    0.5, 0.25, 0.125) under a unit lamp 3 above it (object "Lamp", emissive (1, 0.5, 0.25) times
 *    KHR_materials_emissive_strength 4, black): the floor's mean radiosity is rho E F with F the
 *    form factor of two parallel unit squares 3 apart (Howell's closed form), since nothing else
 *    reflects. Its solved output GLB must keep both names and hold the unclamped radiosity.
 *  - tests/data/textured.glb: one quad (two triangles along the UV diagonal) with an embedded
 *    64x64 PNG, sRGB 255 for u < 0.5 and 128 beyond, base colour factor 0.8: each triangle's
 *    reflectance is 0.8 times the texture's mean over it (a quarter and three quarters white).
 *  - a floor made of four triangles around its centre beside a wall: after smoothing, coincident
 *    vertices of the floor's triangles agree, the floor-wall crease does not. */
#include "hrad.h"
#include "output.h"
#include "testutil.h"
#include "texture.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>


static const char *data(const char *name) {
  static char path[1024];
  snprintf(path, sizeof path, "%s/tests/data/%s", HR_SOURCE_DIR, name);
  return path;
}

/* Howell C-11: parallel, directly opposed rectangles a x b at distance c. */
static double f_parallel(double a, double b, double c) {
  double x = a / c, y = b / c, x1 = sqrt(1 + x * x), y1 = sqrt(1 + y * y);
  return 2 / (M_PI * x * y) *
         (log(sqrt((1 + x * x) * (1 + y * y) / (1 + x * x + y * y))) + x * y1 * atan(x / y1) +
          y * x1 * atan(y / x1) - x * atan(x) - y * atan(y));
}

/* Area-weighted mean radiosity of object 'name'. */
static void object_radiosity(const hr_solver *sv, const hr_scene *s, const char *name,
                             double out[3]) {
  double a = 0;
  out[0] = out[1] = out[2] = 0;
  for (int p = 0; p < s->npolys; p++) {
    const char *on = hr_scene_object_name(s, hr_scene_poly_object(s, p));
    if (!on || strcmp(on, name)) continue;
    double b[3];
    hr_solver_poly_radiosity(sv, p, b);
    for (int c = 0; c < 3; c++) out[c] += s->poly_area[p] * b[c];
    a += s->poly_area[p];
  }
  for (int c = 0; c < 3 && a > 0; c++) out[c] /= a;
}

/* Reads the GLB at 'path': its JSON text (NUL-terminated) and BIN chunk; 0 on failure. */
static int read_glb(const char *path, char **json, unsigned char **bin, size_t *binlen) {
  FILE *fp = fopen(path, "rb");
  if (!fp) return 0;
  unsigned char h[20];
  int ok = fread(h, 1, 20, fp) == 20 && !memcmp(h, "glTF", 4);
  size_t jl = ok ? (size_t)h[12] | (size_t)h[13] << 8 | (size_t)h[14] << 16 : 0;
  *json = calloc(jl + 1, 1);
  ok = ok && *json && fread(*json, 1, jl, fp) == jl && fread(h, 1, 8, fp) == 8;
  *binlen = ok ? (size_t)h[0] | (size_t)h[1] << 8 | (size_t)h[2] << 16 | (size_t)h[3] << 24 : 0;
  *bin = ok ? malloc(*binlen + 1) : NULL;
  ok = ok && *bin && fread(*bin, 1, *binlen, fp) == *binlen;
  fclose(fp);
  return ok;
}

static void test_lamp_floor(void) {
  hr_err err = {{0}};
  hr_scene *s = NULL;
  hr_status st = hr_scene_load(data("lamp_floor.gltf"), NULL, &s, &err);
  CHECK(st == HR_OK, "load: %s", err.msg);
  if (st != HR_OK) return;
  CHECK(hr_scene_object_count(s) == 2 && !strcmp(hr_scene_object_name(s, 0), "Floor") &&
            !strcmp(hr_scene_object_name(s, 1), "Lamp"),
        "objects %d", hr_scene_object_count(s));
  int lamp = hr_scene_find_material(s, "lamp"), floor = hr_scene_find_material(s, "floor paint");
  CHECK(hr_scene_material_count(s) == 2 && lamp >= 0 && floor >= 0, "materials %d",
        hr_scene_material_count(s));
  if (lamp < 0 || floor < 0) return;
  CHECK(s->mats[lamp].emit[0] == 4 && s->mats[lamp].emit[1] == 2 && s->mats[lamp].emit[2] == 1,
        "lamp emission %g %g %g: emissiveFactor times emissiveStrength 4", s->mats[lamp].emit[0],
        s->mats[lamp].emit[1], s->mats[lamp].emit[2]);
  CHECK(s->mats[floor].rho[0] == 0.5 && s->mats[floor].rho[2] == 0.125, "floor rho %g %g",
        s->mats[floor].rho[0], s->mats[floor].rho[2]);
  hr_vec3 lo, hi;
  hr_scene_bounds(s, &lo, &hi);
  CHECK(lo.y == 0 && hi.y == 3, "the lamp's node translation: y %g..%g, want 0..3", lo.y, hi.y);
  hr_options o;
  hr_options_default(&o);
  o.threads = 2;
  hr_solver *sv = NULL;
  st = hr_solver_create(s, &o, &sv, &err);
  if (st == HR_OK) st = hr_solver_run(sv, NULL, NULL, &err);
  CHECK(st == HR_OK, "solve: %s", err.msg);
  if (st == HR_OK) {
    double b[3], f = f_parallel(1, 1, 3);
    object_radiosity(sv, s, "Floor", b);
    const double want[3] = {0.5 * 4 * f, 0.25 * 2 * f, 0.125 * 1 * f};
    for (int c = 0; c < 3; c++)
      CHECK(fabs(b[c] - want[c]) <= 0.01 * want[c], "Floor channel %d: B %.6g, rho E F %.6g", c,
            b[c], want[c]);
    printf("lamp_floor: Floor B %.6g %.6g %.6g, rho E F %.6g %.6g %.6g (F = %.6f)\n", b[0], b[1],
           b[2], want[0], want[1], want[2], f);
    hr_leaf *lv = NULL;
    int64_t n = 0;
    hr_mesh *m = NULL;
    CHECK(hr_solver_leaves(sv, &lv, &n) == HR_OK && hr_mesh_build(s, lv, n, &m) == HR_OK, "mesh");
    char path[256], *json = NULL;
    unsigned char *bin = NULL;
    size_t binlen = 0;
    snprintf(path, sizeof path, "%s/hrad-test-import-%d.glb",
             getenv("TMPDIR") ? getenv("TMPDIR") : "/tmp", (int)getpid());
    double ex = m ? hr_exposure_auto(m) : 1;
    CHECK(m && hr_glb_write(path, m, ex, &err) == HR_OK, "glb: %s", err.msg);
    CHECK(read_glb(path, &json, &bin, &binlen), "reading %s back", path);
    if (json && bin && m) {
      CHECK(strstr(json, "\"name\":\"Floor\"") && strstr(json, "\"name\":\"Lamp\"") &&
                strstr(json, "\"name\":\"floor paint\"") && strstr(json, "\"name\":\"lamp\"") &&
                strstr(json, "\"_RADIOSITY\""),
            "names or _RADIOSITY missing: %.300s", json);
      /* BIN: positions, COLOR_0, _RADIOSITY (npos bytes each), then the indices */
      size_t npos = (binlen - (size_t)m->ntris * 12) / 3;
      float rmax = 0, cmax = 0;
      for (size_t i = 0; i < npos / 4; i += 3) {
        float r, c;
        memcpy(&c, bin + npos + 4 * i, 4);
        memcpy(&r, bin + 2 * npos + 4 * i, 4);
        rmax = r > rmax ? r : rmax;
        cmax = c > cmax ? c : cmax;
      }
      CHECK(rmax == 4.0f && cmax == 1.0f && rmax * ex > 1,
            "_RADIOSITY red max %g (want the lamp's 4, unclamped), COLOR_0 max %g (clamped to 1), "
            "exposure %g",
            rmax, cmax, ex);
    }
    unlink(path);
    free(json);
    free(bin);
    hr_mesh_destroy(&m);
    free(lv);
  }
  hr_solver_destroy(&sv);
  hr_scene_destroy(&s);
}

static void test_textured(void) {
  hr_err err = {{0}};
  hr_scene *s = NULL;
  hr_status st = hr_scene_load(data("textured.glb"), NULL, &s, &err);
  CHECK(st == HR_OK, "load: %s", err.msg);
  if (st != HR_OK) return;
  double grey = hr_srgb_to_linear(128); /* 0.2158 */
  CHECK(fabs(grey - 0.2158605) < 1e-6, "sRGB 128 is linear %g", grey);
  CHECK(s->npolys == 2 && hr_scene_material_count(s) == 1, "%d polygons %d materials", s->npolys,
        hr_scene_material_count(s));
  for (int p = 0; p < s->npolys; p++) {
    const hr_material *m = &s->mats[s->surfs[p].material];
    /* the triangle's centroid tells which one it is: u < v (upper) has 3/4 of its area at
     * u < 0.5, the other 1/4 */
    const hr_surface *f = &s->surfs[p];
    double cx = (f->v[0].x + f->v[1].x + f->v[2].x) / 3;
    double cz = (f->v[0].z + f->v[1].z + f->v[2].z) / 3;
    double white = cx < cz ? 0.75 : 0.25, want = 0.8 * (white + (1 - white) * grey);
    CHECK(fabs(m->rho[0] - want) < 0.01 * want && m->base == hr_scene_material_at(s, 0) &&
              !strcmp(m->name, "painted"),
          "polygon %d: rho %g, want %g (0.8 x texture mean)", p, m->rho[0], want);
    CHECK(hr_scene_poly_material(s, p) == hr_scene_material_at(s, 0), "poly material");
  }
  hr_scene_destroy(&s);
}

/* A JPEG from assimp-testmodels decodes to its size with values in [0, 1]; skipped without it. */
static void test_jpeg(void) {
  const char *path = "/usr/share/assimp/models/3DS/IMAGE1.jpg";
  if (access(path, R_OK) != 0) {
    printf("jpeg: skipped (%s missing)\n", path);
    return;
  }
  hr_texture t;
  hr_err err = {{0}};
  CHECK(hr_texture_load(path, &t, &err) == HR_OK, "%s", err.msg);
  double sum = 0, lo = 1, hi = 0;
  for (size_t i = 0; i < (size_t)t.w * t.h * 3; i++) {
    sum += t.rgb[i];
    lo = t.rgb[i] < lo ? t.rgb[i] : lo;
    hi = t.rgb[i] > hi ? t.rgb[i] : hi;
  }
  CHECK(t.w > 0 && t.h > 0 && lo >= 0 && hi <= 1 && hi > lo, "%dx%d values %g..%g", t.w, t.h, lo,
        hi);
  printf("jpeg: %s %dx%d, linear mean %.4f\n", path, t.w, t.h, sum / (3.0 * t.w * t.h));
  hr_texture_free(&t);
  const unsigned char junk[] = {0xff, 0xd8, 0xff, 0x00, 0x01};
  CHECK(hr_texture_decode(junk, sizeof junk, "junk.jpg", &t, &err) == HR_ERR_PARSE &&
            strstr(err.msg, "junk.jpg: bad JPEG"),
        "truncated JPEG: %s", err.msg);
  CHECK(hr_texture_decode(junk + 1, 3, "x.png", &t, &err) == HR_ERR_PARSE, "not an image");
}

/* Floor (y = 0, 2 x 2) as four triangles around its centre, a wall (x = 0) beside it, a lamp
 * facing down. */
static hr_scene *soup_scene(void) {
  hr_scene *s = NULL;
  hr_scene_create("soup", &s);
  const double grey[3] = {0.5, 0.5, 0.5}, black[3] = {0, 0, 0}, e[3] = {5, 5, 5};
  int mg, ml;
  hr_scene_add_material(s, "grey", grey, black, &mg);
  hr_scene_add_material(s, "lamp", black, e, &ml);
  hr_poly_result r;
  hr_vec3 c = {0.3, 0, 0.5}, q[4] = {{0, 0, 0}, {0, 0, 2}, {2, 0, 2}, {2, 0, 0}};
  hr_scene_begin_object(s, "floor");
  for (int i = 0; i < 4; i++) {
    hr_vec3 t[3] = {q[i], q[(i + 1) % 4], c};
    hr_scene_add_polygon(s, t, 3, mg, &r);
  }
  hr_scene_begin_object(s, "wall");
  hr_vec3 w[4] = {{0, 0, 0}, {0, 2, 0}, {0, 2, 2}, {0, 0, 2}};
  hr_scene_add_polygon(s, w, 4, mg, &r);
  hr_scene_begin_object(s, "lamp");
  hr_vec3 l[4] = {{0.8, 1.5, 0.8}, {1.2, 1.5, 0.8}, {1.2, 1.5, 1.2}, {0.8, 1.5, 1.2}};
  hr_scene_add_polygon(s, l, 4, ml, &r);
  return s;
}

/* Largest jump of the red channel across the shared edge from P to Q (floor corner and centre)
 * between the triangles of the soup on either side (polygons 'pa', 'pb'): each side's shading
 * along the edge is linear between its own vertices on it; both are sampled at every vertex of
 * either side. */
static double edge_jump(const hr_mesh *m, const int *vp, int pa, int pb, const float P[3],
                        const float Q[3]) {
  enum { MAXV = 4096 };
  static double t[2][MAXV], val[2][MAXV];
  int n[2] = {0, 0};
  double d[3] = {Q[0] - P[0], Q[1] - P[1], Q[2] - P[2]};
  double dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
  for (int64_t v = 0; v < m->nverts; v++) {
    int side = vp[v] == pa ? 0 : vp[v] == pb ? 1 : -1;
    if (side < 0 || n[side] == MAXV) continue;
    const float *x = &m->pos[3 * v];
    double r[3] = {x[0] - P[0], x[1] - P[1], x[2] - P[2]};
    double tt = (r[0] * d[0] + r[1] * d[1] + r[2] * d[2]) / dd, off = 0;
    for (int k = 0; k < 3; k++) off += pow(r[k] - tt * d[k], 2);
    if (off > 1e-12 * dd || tt < -1e-9 || tt > 1 + 1e-9) continue;
    int i = n[side]++; /* insertion sort by t */
    while (i > 0 && t[side][i - 1] > tt) {
      t[side][i] = t[side][i - 1];
      val[side][i] = val[side][i - 1];
      i--;
    }
    t[side][i] = tt;
    val[side][i] = m->B[3 * v];
  }
  double worst = 0;
  for (int s = 0; s < 2; s++)
    for (int i = 0; i < n[s]; i++) { /* side s's vertex against the other side's shading */
      const double *ot = t[1 - s], *ov = val[1 - s];
      int k = 1;
      while (k < n[1 - s] - 1 && ot[k] < t[s][i]) k++;
      if (n[1 - s] < 2) continue;
      double w = (t[s][i] - ot[k - 1]) / (ot[k] - ot[k - 1]);
      double other = ov[k - 1] + w * (ov[k] - ov[k - 1]);
      worst = fmax(worst, fabs(other - val[s][i]) / fmax(fabs(val[s][i]), 1e-30));
    }
  return worst;
}

static void test_smooth(void) {
  hr_scene *s = soup_scene();
  CHECK(s && s->npolys == 6 && hr_scene_object_count(s) == 3, "soup scene");
  if (!s || s->npolys != 6) return;
  hr_options o;
  hr_options_default(&o);
  o.threads = 2;
  hr_err err = {{0}};
  hr_solver *sv = NULL;
  hr_status st = hr_solver_create(s, &o, &sv, &err);
  if (st == HR_OK) st = hr_solver_run(sv, NULL, NULL, &err);
  CHECK(st == HR_OK, "solve: %s", err.msg);
  hr_leaf *lv = NULL;
  int64_t n = 0;
  hr_mesh *m = NULL;
  if (st == HR_OK) st = hr_solver_leaves(sv, &lv, &n);
  if (st == HR_OK) st = hr_mesh_build(s, lv, n, &m);
  CHECK(st == HR_OK, "mesh");
  if (st == HR_OK) {
    /* vertex -> polygon */
    int *vp = malloc((size_t)m->nverts * sizeof *vp);
    for (int64_t t = 0; t < m->ntris; t++)
      for (int k = 0; k < 3; k++) vp[m->tri[3 * t + k]] = s->surfs[m->tri_surf[t]].poly;
    int64_t same = 0, differ = 0, crease = 0, crease_differ = 0;
    for (int64_t a = 0; a < m->nverts; a++)
      for (int64_t b = a + 1; b < m->nverts; b++) {
        const float *pa = &m->pos[3 * a], *pb = &m->pos[3 * b];
        if (vp[a] == vp[b] || pa[0] != pb[0] || pa[1] != pb[1] || pa[2] != pb[2]) continue;
        int floor_a = vp[a] < 4, floor_b = vp[b] < 4;
        float d = fabsf(m->B[3 * a] - m->B[3 * b]);
        if (floor_a && floor_b) {
          same++;
          differ += d > 1e-6f * fabsf(m->B[3 * a]);
        } else if (floor_a != floor_b && vp[a] < 5 && vp[b] < 5) {
          crease++;
          crease_differ += d > 0.01f * fabsf(m->B[3 * a]);
        }
      }
    CHECK(same >= 8 && differ == 0, "%lld coincident floor vertex pairs, %lld differ",
          (long long)same, (long long)differ);
    CHECK(crease >= 2 && crease_differ == crease, "%lld floor-wall pairs, %lld differ by > 1%%",
          (long long)crease, (long long)crease_differ);
    printf("smooth: %lld coincident floor vertex pairs equal, %lld of %lld crease pairs apart\n",
           (long long)same, (long long)crease_differ, (long long)crease);
    /* the floor's four inner edges, from each corner to the centre */
    const float C[3] = {0.3f, 0, 0.5f}, corner[4][3] = {{0, 0, 0}, {0, 0, 2}, {2, 0, 2}, {2, 0, 0}};
    double jump = 0;
    for (int i = 0; i < 4; i++) jump = fmax(jump, edge_jump(m, vp, (i + 3) % 4, i, corner[i], C));
    printf("smooth: largest jump across the inner floor edges %.3g (relative)\n", jump);
    CHECK(jump < 1e-5, "shading jumps by %g (relative) across a shared edge", jump);
    free(vp);
  }
  hr_mesh_destroy(&m);
  free(lv);
  hr_solver_destroy(&sv);
  hr_scene_destroy(&s);
}

/* Extensions choose the reader; a file is never read as another format. */
static void test_formats(void) {
  hr_err err = {{0}};
  hr_scene *s = NULL;
  CHECK(hr_scene_format_known("a.GLB") && hr_scene_format_known("b.ply") &&
            hr_scene_format_known("c.obj") && hr_scene_format_known("noext") &&
            !hr_scene_format_known("d.xyz"),
        "format_known");
  CHECK(hr_scene_load("x.xyz", NULL, &s, &err) == HR_ERR_INVALID && !s &&
            strstr(err.msg, "x.xyz: unknown scene format '.xyz'"),
        "unknown extension: %s", err.msg);
  char path[256];
  snprintf(path, sizeof path, "%s/hrad-test-import-%d.gltf",
           getenv("TMPDIR") ? getenv("TMPDIR") : "/tmp", (int)getpid());
  FILE *fp = fopen(path, "w");
  if (fp) {
    fputs("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", fp);
    fclose(fp);
  }
  CHECK(hr_scene_load(path, NULL, &s, &err) == HR_ERR_PARSE && !s &&
            strstr(err.msg, "not a .gltf file"),
        "OBJ text named .gltf: %s", err.msg);
  unlink(path);
}

int main(void) {
  test_formats();
  test_lamp_floor();
  test_textured();
  test_jpeg();
  test_smooth();
  return t_done("test_import");
}
