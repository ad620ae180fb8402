/* report.c: surfaces.csv, stats.json and the per-phase timing table (paper 2.3, tables 1-2:
 * init graph, refine, push-pull, sum). The paper's "refine" column covers steps {7..13}, which
 * include do_link; here it is split into refine (subdivision and visibility) and gather. */
#include "output.h"
#include "report.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>

static hr_status open_out(const char *path, FILE **f, hr_err *err) {
  *f = fopen(path, "w");
  if (!*f) return hr_err_set(err, HR_ERR_IO, "%s: cannot write: %s", path, strerror(errno));
  return HR_OK;
}


/* Writes 's' as a JSON string (quoted, with '"', '\\' and control characters escaped): scene
 * names come from file names, which may hold any of them. */
static void json_string(FILE *f, const char *s) {
  fputc('"', f);
  for (; *s; s++) {
    unsigned char c = (unsigned char)*s;
    if (c == '"' || c == '\\')
      fprintf(f, "\\%c", c);
    else if (c < 0x20 || c == 0x7f)
      fprintf(f, "\\u%04x", c);
    else
      fputc(c, f);
  }
  fputc('"', f);
}

hr_status hr_report_csv(const char *path, const hr_solver *s, hr_err *err) {
  FILE *f;
  hr_status st = open_out(path, &f, err);
  if (st != HR_OK) return st;
  const hr_scene *sc = hr_solver_scene(s);
  /* test hook HRAD_TEST_EXACT=1: every bit of the numbers (hexadecimal floats), so that tests
   * compare solutions exactly, not to the 9 digits written otherwise */
  const char *ex = getenv("HRAD_TEST_EXACT");
  const int exact = ex && *ex && strcmp(ex, "0") != 0;
  fprintf(f, "id,area,r,g,b,status\n");
  for (int i = 0; i < sc->ninputs; i++) {
    const hr_input *in = &sc->inputs[i];
    double b[3] = {0, 0, 0}, area = 0;
    if (in->poly >= 0) {
      hr_solver_poly_radiosity(s, in->poly, b);
      area = sc->poly_area[in->poly];
    }
    fprintf(f, exact ? "%d,%a,%a,%a,%a," : "%d,%.9g,%.9g,%.9g,%.9g,", i, area, b[0], b[1], b[2]);
    if (in->kind == HR_INPUT_SOLVED)
      fprintf(f, "solved\n");
    else if (in->kind == HR_INPUT_DUPLICATE)
      fprintf(f, "duplicate:%d\n", hr_scene_poly_input(sc, in->poly));
    else
      fprintf(f, "degenerate\n");
  }
  return hr_file_close(f, path, 1, 0, err);
}

hr_status hr_report_json(const char *path, const hr_solver *s, const hr_options *o,
                         hr_err *err) {
  FILE *f;
  hr_status st = open_out(path, &f, err);
  if (st != HR_OK) return st;
  hr_stats t;
  hr_solver_stats(s, &t);
  const hr_scene *sc = hr_solver_scene(s);
  fprintf(f, "{\n");
  fprintf(f, "  \"scene\": ");
  json_string(f, sc->name);
  fprintf(f, ",\n");
  fprintf(f, "  \"surfaces\": %d,\n", t.npolys);
  fprintf(f, "  \"input_polygons\": %d,\n", sc->ninputs);
  fprintf(f, "  \"split_surfaces\": %d,\n", t.nsurfaces);
  fprintf(f, "  \"elements\": %lld,\n", (long long)t.elements);
  fprintf(f, "  \"elements_all\": %lld,\n", (long long)t.elements_all);
  fprintf(f, "  \"links\": %lld,\n", (long long)t.links);
  fprintf(f, "  \"initial_links\": %lld,\n", (long long)t.initial_links);
  fprintf(f, "  \"clusters\": %lld,\n", (long long)t.clusters);
  fprintf(f, "  \"cluster_links\": %lld,\n", (long long)t.cluster_links);
  fprintf(f, "  \"iterations\": %d,\n", t.iterations);
  fprintf(f, "  \"rays\": %lld,\n", (long long)t.rays);
  fprintf(f, "  \"converged\": %s,\n", t.converged ? "true" : "false");
  fprintf(f, "  \"threads\": %d,\n", t.threads);
  fprintf(f, "  \"ranks\": %d,\n", t.ranks);
  if (t.ranks > 1)
    fprintf(f,
            "  \"balance\": {\"method\": \"%s\", \"balancings\": %lld, "
            "\"migrations\": %lld},\n",
            t.balance, (long long)t.balancings, (long long)t.migrations);
  else
    fprintf(f, "  \"balance\": null,\n");
  fprintf(f, "  \"peak_rss_mb\": %.1f,\n", t.peak_rss_mb);
  fprintf(f, "  \"links_per_s\": %.0f,\n", t.time_s.total > 0 ? t.links / t.time_s.total : 0);
  fprintf(f, "  \"rays_per_s\": %.0f,\n", t.time_s.total > 0 ? t.rays / t.time_s.total : 0);
  fprintf(f,
          "  \"options\": {\"bf_low\": %g, \"bf_start\": %g, \"bf_first\": %g, "
          "\"bf_factor\": %g, \"area_min\": %g, \"b_eps\": %g, \"b_max\": %g, "
          "\"relax\": %s, \"rays\": %d, \"seed\": %llu, \"extrapolate\": %s, "
          "\"cluster\": \"%s\", \"importance\": %g},\n",
          o->bf_low, o->bf_start, o->bf_first, o->bf_factor, o->area_min, o->b_eps, o->b_max,
          o->relax ? "true" : "false", o->rays, (unsigned long long)o->seed,
          o->extrapolate ? "true" : "false",
          o->cluster == HR_CLUSTER_ON ? "on" : o->cluster == HR_CLUSTER_OFF ? "off" : "auto",
          o->importance);
  fprintf(f,
          "  \"time_s\": {\"init_graph\": %.6f, \"refine\": %.6f, \"gather\": %.6f, "
          "\"push_pull\": %.6f, \"balance\": %.6f, \"total\": %.6f}\n",
          t.time_s.init_graph, t.time_s.refine, t.time_s.gather, t.time_s.push_pull,
          t.time_s.balance, t.time_s.total);
  fprintf(f, "}\n");
  return hr_file_close(f, path, 1, 0, err);
}

void hr_report_table(FILE *f, const hr_stats *t) {
  fprintf(f, "%7s %10s %10s %10s %10s %10s %10s %9s %9s %11s %11s\n", "threads", "init graph",
          "refine", "gather", "push-pull", "sim. ann.", "sum", "elements", "links", "rays",
          "links/s");
  fprintf(f, "%7d %10.3f %10.3f %10.3f %10.3f %10.3f %10.3f %9lld %9lld %11lld %11.0f\n",
          t->threads, t->time_s.init_graph, t->time_s.refine, t->time_s.gather,
          t->time_s.push_pull, t->time_s.balance, t->time_s.total, (long long)t->elements,
          (long long)t->links, (long long)t->rays,
          t->time_s.total > 0 ? t->links / t->time_s.total : 0);
}
