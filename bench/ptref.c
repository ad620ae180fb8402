/* ptref.c: a path-traced reference of every solved polygon of a scene, written as CSV for the
 * accuracy benchmarks: id,area,emitter,ref_r,ref_g,ref_b,se_r,se_g,se_b (id: the row of
 * surfaces.csv).
 *   build/bench/ptref SCENE PATHS OUT.csv [SEED [NAME=R,G,B ...]]
 * (NAME=R,G,B: make material NAME emit, like hrad --emit)
 * SCENE is a built-in name or an .obj path. All cores; prints the time taken to stderr. */
#include "hrad.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static double now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int main(int argc, char **argv) {
  if (argc < 4) {
    fprintf(stderr, "usage: ptref SCENE PATHS OUT.csv [SEED]\n");
    return 2;
  }
  hr_err err = {{0}};
  hr_scene *s = NULL;
  hr_status st = strstr(argv[1], ".obj") ? hr_scene_load_obj(argv[1], NULL, &s, &err)
                                         : hr_scene_builtin(argv[1], &s, &err);
  if (st != HR_OK) {
    fprintf(stderr, "ptref: %s\n", err.msg);
    return 1;
  }
  for (int a = 5; a < argc; a++) {
    char name[256];
    double rgb[3];
    const char *eq = strrchr(argv[a], '=');
    if (!eq || eq - argv[a] >= (long)sizeof name ||
        sscanf(eq + 1, "%lf,%lf,%lf", &rgb[0], &rgb[1], &rgb[2]) != 3) {
      fprintf(stderr, "ptref: expected NAME=R,G,B, got '%s'\n", argv[a]);
      return 2;
    }
    memcpy(name, argv[a], (size_t)(eq - argv[a]));
    name[eq - argv[a]] = 0;
    if (hr_scene_set_emit(s, name, rgb, &err) != HR_OK) {
      fprintf(stderr, "ptref: %s\n", err.msg);
      return 1;
    }
  }
  hr_pt_options o;
  hr_pt_options_default(&o);
  o.paths = atoll(argv[2]);
  if (argc > 4) o.seed = strtoull(argv[4], NULL, 10);
  double (*mean)[3] = calloc((size_t)s->npolys, sizeof *mean);
  double (*se)[3] = calloc((size_t)s->npolys, sizeof *se);
  double t0 = now();
  if (!mean || !se || hr_pt_polys(s, &o, mean, se, &err) != HR_OK) {
    fprintf(stderr, "ptref: %s\n", err.msg);
    return 1;
  }
  double t = now() - t0;
  FILE *f = fopen(argv[3], "w");
  if (!f) {
    perror(argv[3]);
    return 1;
  }
  fprintf(f, "id,area,emitter,ref_r,ref_g,ref_b,se_r,se_g,se_b\n");
  for (int p = 0; p < s->npolys; p++) {
    int em = 0;
    for (int i = 0; i < s->nsurfs; i++)
      if (s->surfs[i].poly == p) {
        const double *e = s->mats[s->surfs[i].material].emit;
        em |= e[0] > 0 || e[1] > 0 || e[2] > 0;
      }
    fprintf(f, "%d,%.9g,%d,%.9g,%.9g,%.9g,%.6g,%.6g,%.6g\n", hr_scene_poly_input(s, p),
            s->poly_area[p], em, mean[p][0],
            mean[p][1], mean[p][2], se[p][0], se[p][1], se[p][2]);
  }
  fclose(f);
  fprintf(stderr, "ptref: %s, %d polygons x %lld paths in %.2f s\n", argv[1], s->npolys,
          (long long)o.paths, t);
  free(mean);
  free(se);
  hr_scene_destroy(&s);
  return 0;
}
