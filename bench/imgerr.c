/* imgerr.c: per-pixel accuracy per second, hrad's rendering against the path tracer's image.
 *   build/bench/imgerr SCENE W H REF_SPP REF.pfm [--hrad BF_LOW ...] [--pt SPP ...]
 * Makes (or reads, when REF.pfm exists with the right size) a reference image of the scene's
 * camera with REF_SPP paths per pixel, then for each --hrad setting solves (BF_low = A_e, all
 * cores) and renders the smooth linear image, and for each --pt setting path-traces the image
 * with another seed. For every image it prints one CSV line
 *   method,setting,seconds,mean_rel_err_pct
 * with the mean over pixels whose reference exceeds 1% of the image mean of |img - ref| / |ref|
 * (RGB norms), and the seconds the solve (or trace) took. With --png PREFIX it also writes
 * PREFIX-ref.png and PREFIX-hrad-SETTING.png / PREFIX-pt-SPP.png at the reference's exposure. */
#include "hrad.h"
#include "output.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static double now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* Reads a PFM written by hr_pfm_write (bottom row first) into rgb (top row first); 0 on any
 * mismatch. */
static int read_pfm(const char *path, int w, int h, float *rgb) {
  FILE *f = fopen(path, "rb");
  if (!f) return 0;
  int fw, fh;
  double scale;
  char tag[3] = {0};
  int ok = fscanf(f, "%2s %d %d %lf", tag, &fw, &fh, &scale) == 4 && !strcmp(tag, "PF") &&
           fw == w && fh == h && fgetc(f) != EOF;
  for (int y = h - 1; ok && y >= 0; y--)
    ok = fread(rgb + (size_t)y * w * 3, sizeof(float), (size_t)w * 3, f) == (size_t)w * 3;
  fclose(f);
  return ok;
}

static double norm3(const float *v) {
  return sqrt((double)v[0] * v[0] + (double)v[1] * v[1] + (double)v[2] * v[2]);
}

static double image_error(const float *img, const float *ref, size_t np) {
  double mean = 0, err = 0;
  size_t cnt = 0;
  for (size_t i = 0; i < np; i++) mean += norm3(ref + 3 * i) / (double)np;
  for (size_t i = 0; i < np; i++) {
    double r = norm3(ref + 3 * i);
    if (!(r > 0.01 * mean)) continue;
    float d[3] = {img[3 * i] - ref[3 * i], img[3 * i + 1] - ref[3 * i + 1],
                  img[3 * i + 2] - ref[3 * i + 2]};
    err += norm3(d) / r;
    cnt++;
  }
  return cnt ? 100 * err / (double)cnt : 0;
}

static int cmpf(const void *a, const void *b) {
  float x = *(const float *)a, z = *(const float *)b;
  return x < z ? -1 : x > z;
}

/* The exposure that maps the image's 95th-percentile luminance to 0.8 (like the solver's). */
static double exposure_of(const float *img, size_t np) {
  float *y = malloc(np * sizeof *y);
  if (!y) return 1;
  for (size_t i = 0; i < np; i++)
    y[i] = 0.2126f * img[3 * i] + 0.7152f * img[3 * i + 1] + 0.0722f * img[3 * i + 2];
  qsort(y, np, sizeof *y, cmpf);
  double v = y[(size_t)(0.95 * (double)(np - 1))];
  free(y);
  return v > 0 ? 0.8 / v : 1;
}

int main(int argc, char **argv) {
  if (argc < 6) {
    fprintf(stderr, "usage: imgerr SCENE W H REF_SPP REF.pfm [--hrad BF ...] [--pt SPP ...] "
                    "[--png PREFIX]\n");
    return 2;
  }
  hr_err err = {{0}};
  hr_scene *s = NULL;
  if ((strstr(argv[1], ".obj") ? hr_scene_load_obj(argv[1], NULL, &s, &err)
                               : hr_scene_builtin(argv[1], &s, &err)) != HR_OK) {
    fprintf(stderr, "imgerr: %s\n", err.msg);
    return 1;
  }
  const int w = atoi(argv[2]), h = atoi(argv[3]), ref_spp = atoi(argv[4]);
  const size_t np = (size_t)w * h;
  hr_camera cam;
  if (s->has_camera)
    cam = s->camera;
  else
    hr_scene_auto_camera(s, &cam);
  float *ref = malloc(3 * np * sizeof *ref), *img = malloc(3 * np * sizeof *img);
  if (!ref || !img) return 1;
  hr_pt_options po;
  hr_pt_options_default(&po);
  po.seed = 7;
  if (!read_pfm(argv[5], w, h, ref)) {
    double t0 = now();
    if (hr_pt_image(s, &cam, w, h, ref_spp, &po, ref, NULL, &err) != HR_OK ||
        hr_pfm_write(argv[5], w, h, ref, &err) != HR_OK) {
      fprintf(stderr, "imgerr: %s\n", err.msg);
      return 1;
    }
    fprintf(stderr, "imgerr: reference %dx%d at %d spp in %.1f s\n", w, h, ref_spp, now() - t0);
  }
  const double expo = exposure_of(ref, np);
  const char *png = NULL;
  for (int i = 6; i + 1 < argc; i += 2)
    if (!strcmp(argv[i], "--png")) png = argv[i + 1];
  char path[4096];
  if (png) {
    snprintf(path, sizeof path, "%s-ref.png", png);
    hr_png_write(path, w, h, ref, expo, &err);
  }
  printf("method,setting,seconds,mean_rel_err_pct\n");
  for (int i = 6; i + 1 < argc; i += 2) {
    double secs;
    const char *what = argv[i + 1];
    if (!strcmp(argv[i], "--hrad")) {
      hr_options o;
      hr_options_default(&o);
      o.bf_low = atof(what);
      hr_solver *sv = NULL;
      if (hr_solver_create(s, &o, &sv, &err) != HR_OK || hr_solver_run(sv, NULL, NULL, &err)) {
        fprintf(stderr, "imgerr: %s\n", err.msg);
        return 1;
      }
      hr_stats st;
      hr_solver_stats(sv, &st);
      secs = st.time_s.total;
      hr_leaf *lv;
      int64_t n;
      hr_mesh *m;
      if (hr_solver_leaves(sv, &lv, &n) != HR_OK || hr_mesh_build(s, lv, n, &m) != HR_OK) return 1;
      hr_render_ex(s, m, lv, n, &cam, w, h, 0, 2, -1, img);
      hr_mesh_destroy(&m);
      free(lv);
      hr_solver_destroy(&sv);
      printf("hrad,%s,%.4f,%.3f\n", what, secs, image_error(img, ref, np));
      if (png) snprintf(path, sizeof path, "%s-hrad-%s.png", png, what);
    } else if (!strcmp(argv[i], "--pt")) {
      po.seed = 11;
      double t0 = now();
      if (hr_pt_image(s, &cam, w, h, atoi(what), &po, img, NULL, &err) != HR_OK) {
        fprintf(stderr, "imgerr: %s\n", err.msg);
        return 1;
      }
      secs = now() - t0;
      printf("pathtracer,%s,%.4f,%.3f\n", what, secs, image_error(img, ref, np));
      if (png) snprintf(path, sizeof path, "%s-pt-%s.png", png, what);
    } else {
      continue;
    }
    fflush(stdout);
    if (png) hr_png_write(path, w, h, img, expo, &err);
  }
  free(ref);
  free(img);
  hr_scene_destroy(&s);
  return 0;
}
