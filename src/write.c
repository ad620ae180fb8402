/* write.c: the public file writers (hrad.h, "writing results"): the solver's current solution
 * as PNG, PLY, GLB, surfaces.csv and stats.json through the internal writers of render.c,
 * mesh.c and report.c, each from its own leaves and smooth mesh. tools/hrad.c uses the internal
 * ones directly, to build the mesh once for all its files. */
#include "output.h"
#include "report.h"

#include <stdlib.h>

#define IMAGE_SIDE_MIN 16
#define IMAGE_SIDE_MAX 16384
#define IMAGE_PIXELS_MAX (1L << 26)

/* The solver's leaves and smooth mesh (caller frees both), and the exposure to use ('want' > 0
 * or the automatic one). */
static hr_status solution(const hr_solver *s, double want, hr_leaf **leaves, int64_t *n,
                          hr_mesh **m, double *expo, hr_err *err) {
  if (!s) return hr_err_set(err, HR_ERR_INVALID, "no solver");
  *m = NULL;
  hr_status st = hr_solver_leaves(s, leaves, n);
  if (st == HR_OK) st = hr_mesh_build(hr_solver_scene(s), *leaves, *n, m);
  if (st != HR_OK) {
    free(*leaves);
    *leaves = NULL;
    return hr_err_set(err, st, "building the mesh failed%s",
                      st == HR_ERR_NOMEM ? ": out of memory" : "");
  }
  *expo = want > 0 ? want : hr_exposure_auto(*m);
  return HR_OK;
}

hr_status hr_solver_exposure(const hr_solver *s, double *exposure, hr_err *err) {
  hr_leaf *leaves;
  int64_t n;
  hr_mesh *m;
  hr_status st = solution(s, 0, &leaves, &n, &m, exposure, err);
  if (st != HR_OK) return st;
  hr_mesh_destroy(&m);
  free(leaves);
  return HR_OK;
}

void hr_image_options_default(hr_image_options *o) {
  o->width = 800;
  o->height = 600;
  o->camera = NULL;
  o->exposure = 0;
  o->elements = 0;
}

static hr_status check_image(const hr_image_options *o, hr_err *err) {
  if (o->width < IMAGE_SIDE_MIN || o->width > IMAGE_SIDE_MAX || o->height < IMAGE_SIDE_MIN ||
      o->height > IMAGE_SIDE_MAX || (long)o->width * o->height > IMAGE_PIXELS_MAX)
    return hr_err_set(err, HR_ERR_INVALID, "image size %dx%d: each side must be in %d..%d, at "
                      "most %ld pixels", o->width, o->height, IMAGE_SIDE_MIN, IMAGE_SIDE_MAX,
                      IMAGE_PIXELS_MAX);
  if (o->elements != 0 && o->elements != 1)
    return hr_err_set(err, HR_ERR_INVALID, "image mode %d: 0 (smooth) or 1 (elements)",
                      o->elements);
  return HR_OK;
}

hr_status hr_solver_write_png(const hr_solver *s, const char *path, const hr_image_options *o,
                              hr_err *err) {
  hr_image_options d;
  if (!o) hr_image_options_default(&d), o = &d;
  hr_status st = check_image(o, err);
  if (st != HR_OK) return st;
  if (!path) return hr_err_set(err, HR_ERR_INVALID, "hr_solver_write_png: no path");
  hr_leaf *leaves;
  int64_t n;
  hr_mesh *m;
  double expo = 1;
  st = solution(s, o->exposure, &leaves, &n, &m, &expo, err);
  if (st != HR_OK) return st;
  const hr_scene *sc = hr_solver_scene(s);
  hr_camera cam;
  if (o->camera)
    cam = *o->camera;
  else if (sc->has_camera)
    cam = sc->camera;
  else
    hr_scene_auto_camera(sc, &cam);
  float *img = malloc((size_t)o->width * (size_t)o->height * 3 * sizeof *img);
  if (!img) st = hr_err_set(err, HR_ERR_NOMEM, "%s: out of memory for the image", path);
  /* samples clamped at 1/exposure, as the display sees them (output.h, hr_render_ex) */
  if (st == HR_OK)
    st = hr_render_ex(sc, m, leaves, n, &cam, o->width, o->height, o->elements, 2, 1.0 / expo,
                      img);
  if (st != HR_OK && img) st = hr_err_set(err, st, "%s: rendering failed", path);
  if (st == HR_OK) st = hr_png_write(path, o->width, o->height, img, expo, err);
  free(img);
  hr_mesh_destroy(&m);
  free(leaves);
  return st;
}

/* Builds the mesh and writes it with 'put' (hr_ply_write or hr_glb_write). */
static hr_status write_mesh(const hr_solver *s, const char *path, double exposure,
                            hr_status (*put)(const char *, const hr_mesh *, double, hr_err *),
                            hr_err *err) {
  if (!path) return hr_err_set(err, HR_ERR_INVALID, "no path");
  hr_leaf *leaves;
  int64_t n;
  hr_mesh *m;
  double expo = 1;
  hr_status st = solution(s, exposure, &leaves, &n, &m, &expo, err);
  if (st != HR_OK) return st;
  st = put(path, m, expo, err);
  hr_mesh_destroy(&m);
  free(leaves);
  return st;
}

hr_status hr_solver_write_ply(const hr_solver *s, const char *path, double exposure,
                              hr_err *err) {
  return write_mesh(s, path, exposure, hr_ply_write, err);
}

hr_status hr_solver_write_glb(const hr_solver *s, const char *path, double exposure,
                              hr_err *err) {
  return write_mesh(s, path, exposure, hr_glb_write, err);
}

hr_status hr_solver_write_csv(const hr_solver *s, const char *path, hr_err *err) {
  if (!s || !path) return hr_err_set(err, HR_ERR_INVALID, "hr_solver_write_csv: no solver or path");
  return hr_report_csv(path, s, err);
}

hr_status hr_solver_write_json(const hr_solver *s, const hr_options *o, const char *path,
                               hr_err *err) {
  if (!s || !o || !path)
    return hr_err_set(err, HR_ERR_INVALID, "hr_solver_write_json: no solver, options or path");
  return hr_report_json(path, s, o, err);
}
