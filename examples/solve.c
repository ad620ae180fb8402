/* solve.c: hrad's C API in one small program: load a scene (a built-in name or a scene file),
 * solve it, print each polygon's material and radiosity, and write a PNG.
 *
 *   cc solve.c $(pkg-config --cflags --libs hrad) -o solve      # or CMake: see CMakeLists.txt
 *   ./solve cornell cornell.png
 *
 * Output: one line per polygon, "poly ID MATERIAL area A B r g b" (radiosity in W/m^2), then
 * "wrote PATH". Errors: one line on stderr, exit status 1. */
#include <hrad.h>

#include <stdio.h>
#include <string.h>

static int fail(const char *what, const hr_err *err) {
  fprintf(stderr, "solve: %s: %s\n", what, err->msg);
  return 1;
}

/* A built-in scene, or a scene file (OBJ, or glTF, PLY, 3DS, FBX, Collada, STL through assimp). */
static hr_status load(const char *name, hr_scene **scene, hr_err *err) {
  for (const char *const *b = hr_scene_builtin_names(); *b; b++)
    if (!strcmp(name, *b)) return hr_scene_builtin(name, scene, err);
  return hr_scene_load(name, NULL, scene, err);
}

/* Prints every kept polygon: its material and area-weighted mean radiosity. */
static void print_polygons(const hr_solver *solver) {
  const hr_scene *scene = hr_solver_scene(solver);
  for (int p = 0; p < scene->npolys; p++) {
    int m = hr_scene_poly_material(scene, p); /* its input material */
    double b[3];
    hr_solver_poly_radiosity(solver, p, b);
    printf("poly %d %s area %.6g B %.6g %.6g %.6g\n", p, scene->mats[m].name,
           scene->poly_area[p], b[0], b[1], b[2]);
  }
}

int main(int argc, char **argv) {
  const char *name = argc > 1 ? argv[1] : "cornell", *png = argc > 2 ? argv[2] : "solve.png";
  hr_err err = {{0}};
  hr_scene *scene = NULL;
  hr_solver *solver = NULL;
  printf("hrad library %s (headers %s)\n", hr_version(), HR_VERSION_STRING);
  if (load(name, &scene, &err) != HR_OK) return fail(name, &err);
  hr_options opt;
  hr_options_default(&opt); /* the defaults of the hrad command */
  int rc = 0;
  if (hr_solver_create(scene, &opt, &solver, &err) != HR_OK ||
      hr_solver_run(solver, NULL, NULL, &err) != HR_OK) {
    rc = fail("solving", &err);
  } else {
    print_polygons(solver);
    hr_image_options img;
    hr_image_options_default(&img); /* 800x600, the scene's camera, automatic exposure */
    if (hr_solver_write_png(solver, png, &img, &err) != HR_OK)
      rc = fail("writing", &err);
    else
      printf("wrote %s\n", png);
  }
  hr_solver_destroy(&solver);
  hr_scene_destroy(&scene);
  return rc;
}
