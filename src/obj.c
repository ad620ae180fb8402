/* obj.c: loads Wavefront OBJ scenes (with their MTL material libraries) into an hr_scene, the
 * way third-party geometry such as the Cornell box or the conference room reaches the solver.
 * Only what radiosity needs is kept: vertex positions, polygon faces (split by
 * hr_scene_add_polygon), and per material the diffuse reflectance rho (MTL `Kd`) and emitted
 * radiosity E (MTL `Ke`). The parser works in place on one NUL-terminated copy of the text, keeps
 * vertices and the current face in growable arrays, and does no allocation per line, so the
 * 69k-triangle conference room parses in a few tens of milliseconds.
 *
 * Accepted OBJ: `v x y z [w ...]` (every number must be finite, and x, y, z at most 1e12 in
 * magnitude, see "Range" below; extra components such as vertex colours are ignored), `f` with >= 3
 * references of the forms `v`, `v/vt`, `v//vn`, `v/vt/vn` (negative = relative to the vertices read
 * so far; vt/vn are checked for syntax only), `usemtl NAME`, `mtllib FILE`, `#` comments, LF or
 * CRLF line ends, a leading UTF-8 byte order mark, and a backslash at the end of a line joining it
 * with the next. Material and file names are the rest of the line, trimmed, so they may contain
 * spaces and '#'. On numeric statements a '#' token starts a comment.
 * `s vn vp l p` and the free-form curve/surface statements are ignored silently; other
 * unknown statements are ignored with one warning per keyword (at most 32 different keywords).
 * Objects: `o NAME` makes the following faces belong to object NAME (the rest of the line,
 * trimmed); so does `g NAME` while no `o` has been read (files of exporters that write only
 * groups), after which groups are ignored (Blender writes `o` per object and `g` per material
 * group). Faces before any get the default object, named like the scene; `o`/`g` without a name
 * are ignored. A name used again continues its object.
 *
 * Materials and fallbacks (deliberate, so that incomplete downloads still load):
 *  - every `newmtl` of every MTL library read becomes a scene material, used or not; a name
 *    defined twice is redefined (last definition wins). A material without `Kd` is grey 0.5,
 *    without `Ke` it emits 0. `Kd`/`Ke` take 1 value (grey) or 3 (RGB); rho outside [0,1],
 *    negative Ke and NaN/Inf are errors at that MTL line. Other MTL keys are ignored.
 *  - `mtllib` names are resolved relative to the OBJ's directory. The whole rest of the line is
 *    tried first as one file name; if that cannot be opened and it contains blanks, each
 *    blank-separated word is tried as a separate library (if no word names a readable file,
 *    the whole line counts as the one missing name). A library that cannot be opened gives the
 *    warning "PATH:LINE: cannot open material library 'X'; using grey default" and loading
 *    continues.
 *  - `Ke` components are 0 or between 1e-30 and 1e30 (an error at that MTL line otherwise): the
 *    solver is linear in E, but E times areas (up to 1e24, below) must neither overflow nor
 *    underflow: `Ke 1e300` on a scene of size 1e14 gave infinite radiosities with exit status 0.
 *  - `usemtl` of a name no library defined creates a grey material (rho 0.5, E 0) with that
 *    name and warns once per name ("PATH:LINE: unknown material 'X'; using grey default").
 *  - faces before any `usemtl` use a material named "default" (rho 0.5, E 0), created only when
 *    such a face exists (or the library's own "default" if one defines it).
 *  - textures: `map_Kd [OPTIONS] FILE` (the last word, relative to the MTL file; options such as
 *    -s and -o are not applied) gives each face of the material whose every vertex has a `vt`
 *    the mean of the PNG or JPEG texture over its UV footprint times Kd, as a variant material
 *    (texture.c; hr_scene_add_variant). `vt u v` pairs are kept for this; a malformed one only
 *    leaves its faces untextured (vt was never an error). A texture that cannot be read warns
 *    once and leaves Kd alone; in memory mode (hr_scene_parse_obj_mtl) none is read, with one
 *    warning.
 * Polygons: hr_scene_add_polygon splits them; degenerate ones are skipped with the warning
 * "PATH:LINE: degenerate polygon skipped"; non-planar ones with more than 4 vertices, ones that are
 * not simple (edges crossing or touching, a vertex revisited other than at the ends of a bridge)
 * and non-convex ones with more than HR_EAR_MAX vertices are errors at their line. A keyhole face
 * (a hole joined to the outside by a bridge, an edge traversed once each way, as LightWave exports
 * holes) loads without the hole's area. A face whose set of vertex positions (sorted, repeated
 * positions counted once, compared exactly) equals that of an earlier polygon facing the same way
 * (positive dot product of their Newell normals) is a duplicate: it is skipped with the warning
 * "PATH:LINE: duplicate of the polygon on line N; skipped" (the Cornell box data repeats a side
 * face of each box as its "bottom"; two coincident surfaces would count that area twice). The
 * material does not matter. A face with the same positions but the opposite facing is kept: back to
 * back, the two make a two-sided panel, which one-sided surfaces can only model that way. Found
 * through a hash table of the sorted positions: O(total face vertices). A file without any
 * surviving polygon is an error ("PATH: no polygons"). Emitters are not required here (the solver
 * checks). Numbers are read with strtod, so the caller must not have switched LC_NUMERIC to a
 * locale with a decimal comma.
 * Limits: a file (OBJ or MTL) of at most 4 GiB (OBJ_MAX_BYTES; about 40 million triangles), and
 * only regular files (a FIFO would block, /dev/zero never ends); lines of any length within that
 * (the parse makes no copy per line); a face of any number of vertices up to 2^31 - 1 when convex
 * (split in linear time: 40,000 vertices load in 0.1 s), at most HR_EAR_MAX (4096) when not
 * (ear clipping is quadratic).
 * Range (found with the checks of the fuzz targets in tests/fuzz, and by solving scaled copies of a
 * box): a coordinate beyond +-1e12 is an error at its `v` line ("PATH:LINE: coordinate X out of
 * range (magnitude at most 1e+12)"). Areas and normals square the coordinates in double precision
 * (at 1e100 the area was infinite), and Embree's single-precision ray-triangle test multiplies
 * three lengths (FLT_MAX = 3.4e38): a box scaled to 1e13 solved 4% off, to 1e12 it matched the unit
 * box. No real scene, in metres or millimetres, comes near 1e12. A face whose vertices all lie
 * within 1e-30 of its first vertex on every axis is degenerate (skipped with the warning
 * "PATH:LINE: degenerate polygon skipped (extent X below 1e-30)"): squares of such sizes underflow,
 * which gave normals of length 1.0000056 (extent 1e-80) or silently zero areas.
 */
#include "scene_impl.h"
#include "hrad.h"
#include "texture.h"
#include "vec.h"

#include <errno.h>
#include <limits.h>
#include <stdint.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#define MAX_WARNED_KEYWORDS 32
/* The largest OBJ or MTL file read (see "Limits" in the file comment). */
#define OBJ_MAX_BYTES (UINT64_C(4) << 30)
/* Range of geometry (see the file comment): the largest coordinate magnitude, and the smallest
 * face extent below which a face counts as degenerate. */
#define COORD_MAX 1e12
#define FACE_EXTENT_MIN 1e-30
/* Range of emitted radiosity, other than 0 (see the file comment). */
#define KE_MIN 1e-30
#define KE_MAX 1e30

/* One parse of one OBJ file (plus its MTL libraries). */
typedef struct obj_ctx {
  const char *path; /* OBJ path as given, for messages */
  const hr_log *log;
  hr_err *err;
  hr_scene *s;
  hr_vec3 *verts; /* vertex positions read so far */
  size_t nverts, cap_verts;
  hr_vec3 *face; /* scratch: the current face's vertices */
  size_t cap_face;
  int cur_mat;  /* material of following faces; -1 = none chosen yet ("default") */
  int seen_o;   /* an `o` statement was read: `g` no longer names objects */
  int warned_map; /* map_Kd in memory mode already reported */
  /* textures (map_Kd): texture coordinates read so far (NaN for a malformed `vt`), the current
   * face's, each material's texture slot (-1: none), and the textures, each read once */
  double (*uvs)[2];
  size_t nuvs, cap_uvs;
  double (*face_uv)[2];
  size_t cap_face_uv;
  int *mat_tex;
  size_t cap_mat_tex;
  struct obj_tex *texs;
  int ntexs;
  char *warned; /* unknown keywords already reported, each NUL-terminated */
  size_t warned_len, warned_cap;
  int nwarned;
  /* polygons added so far, for finding duplicates (see the file comment) */
  struct face_rec *recs;
  size_t nrecs, cap_recs;
  hr_vec3 *rpos; /* each record's sorted, de-duplicated positions, concatenated */
  size_t nrpos, cap_rpos;
  size_t *rtab; /* open-addressing table of record indices (SIZE_MAX = empty) */
  size_t cap_rtab;
  hr_vec3 *sorted; /* scratch: the current face's sorted positions */
  size_t cap_sorted;
  /* hr_scene_parse_obj_mtl: mtllib never touches the disk; every library is 'mem_mtl' (NULL:
   * none can be opened) */
  int mem_mode;
  const char *mem_mtl;
  size_t mem_mtl_len;
} obj_ctx;

typedef struct obj_tex {
  char *path; /* resolved against the MTL file's directory */
  int tried, ok;
  hr_texture tex;
} obj_tex;

typedef struct face_rec {
  uint64_t hash; /* of the sorted positions */
  size_t off, n; /* positions rpos[off .. off+n) */
  hr_vec3 nrm;   /* Newell normal (not normalised) */
  long line;
  int poly;      /* the kept polygon it became */
} face_rec;

/* Iterator over the logical lines of a mutable NUL-terminated buffer. */
typedef struct line_iter {
  char *p, *end;
  long line; /* physical lines consumed so far */
} line_iter;

static int is_blank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

static char *skip_blanks(char *p) {
  while (is_blank(*p)) p++;
  return p;
}

/* Starts iterating over 'buf' (mutable, NUL-terminated at buf[len]); skips a UTF-8 BOM. */
static line_iter lines_begin(char *buf, size_t len) {
  line_iter it = {buf, buf + len, 0};
  if (len >= 3 && memcmp(buf, "\xEF\xBB\xBF", 3) == 0) it.p += 3; /* UTF-8 byte order mark */
  return it;
}

/* Returns the next logical line, NUL-terminated in place with trailing blanks removed, or NULL
 * at the end of the buffer. A line ending in '\' (before an optional CR) is joined with the next
 * (the backslash and line break become blanks). '*lineno' gets the number of its first physical
 * line; '*has_nul' is set when the line contains a NUL byte (binary junk). */
static char *next_line(line_iter *it, long *lineno, int *has_nul) {
  if (it->p >= it->end) return NULL;
  char *start = it->p, *seg = it->p, *le;
  *lineno = ++it->line;
  for (;;) {
    char *nl = memchr(seg, '\n', (size_t)(it->end - seg));
    le = nl ? nl : it->end;
    char *q = le;
    if (q > seg && q[-1] == '\r') q--;
    if (nl && q > seg && q[-1] == '\\') {
      for (char *r = q - 1; r <= nl; r++) *r = ' ';
      seg = nl + 1;
      it->line++;
      continue;
    }
    it->p = nl ? nl + 1 : it->end;
    break;
  }
  *has_nul = memchr(start, '\0', (size_t)(le - start)) != NULL;
  while (le > start && is_blank(le[-1])) le--;
  *le = '\0';
  return start;
}

/* Grows array '*p' of 'sz'-byte items (capacity '*cap') to hold 'need'; 0 on allocation failure. */
static int grow(void **p, size_t *cap, size_t need, size_t sz) {
  if (need <= *cap) return 1;
  size_t nc = *cap ? *cap : 64;
  while (nc < need) nc *= 2;
  void *q = realloc(*p, nc * sz);
  if (!q) return 0;
  *p = q;
  *cap = nc;
  return 1;
}

/* Length of the blank-delimited token at 'p'. */
static size_t token_len(const char *p) {
  size_t n = 0;
  while (p[n] && !is_blank(p[n])) n++;
  return n;
}

/* Shown length of a token in messages (messages stay one short line). */
static int shown(size_t n) { return n > 40 ? 40 : (int)n; }

/* Reads the next number on a line. Returns 0 at the end of the line or at a '#' comment token,
 * 1 with '*out' set, -1 if the next token is not a number, -2 if it is NaN or infinite; '*tok'
 * points at the token either way. Advances '*pp' past the token. */
static int next_number(char **pp, double *out, char **tok) {
  char *p = skip_blanks(*pp);
  *tok = p;
  if (*p == '\0' || *p == '#') {
    *pp = p;
    return 0;
  }
  char *e;
  double d = strtod(p, &e);
  size_t n = token_len(p);
  *pp = p + n;
  if (e != p + n || e == p) return -1;
  if (!isfinite(d)) return -2;
  *out = d;
  return 1;
}

/* Reports a number-parsing failure 'r' (-1 or -2 from next_number) at FILE:LINE. */
static hr_status number_error(obj_ctx *c, const char *file, long line, int r, const char *tok) {
  size_t n = token_len(tok);
  if (r == -2)
    return hr_err_set(c->err, HR_ERR_PARSE, "%s:%ld: non-finite number '%.*s'", file, line,
                      shown(n), tok);
  return hr_err_set(c->err, HR_ERR_PARSE, "%s:%ld: bad number '%.*s'", file, line, shown(n), tok);
}

/* Reads the numbers at 'p' up to the end of the line (or a comment) into v[0..max) and their
 * count into '*n'. With 'stop', a number beyond the first 'max' ends the reading with *n = max+1
 * (the caller reports too many); otherwise further numbers are checked and counted only. */
static hr_status read_numbers(obj_ctx *c, const char *file, long line, char *p, double *v,
                              int max, int stop, int *n) {
  *n = 0;
  for (;;) {
    double d;
    char *tok;
    int r = next_number(&p, &d, &tok);
    if (r == 0) return HR_OK;
    if (r < 0) return number_error(c, file, line, r, tok);
    if (*n < max) {
      v[*n] = d;
    } else if (stop) {
      *n = max + 1;
      return HR_OK;
    }
    ++*n;
  }
}

/* ---------------------------------------------------------------- files */

/* Reads the whole file into a fresh NUL-terminated buffer. On failure returns 0 with '*errnum'
 * set and '*at_open' telling whether opening (1) or reading (0) failed, or 2 (errnum 0) for a
 * path that is not a regular file: a FIFO would block the open for ever and /dev/zero never ends,
 * so only regular files are read (checked before opening). */
static int read_whole(const char *path, char **buf, size_t *len, int *errnum, int *at_open) {
  *buf = NULL;
  *len = 0;
  *at_open = 1;
  struct stat pst;
  if (stat(path, &pst) != 0) {
    *errnum = errno;
    return 0;
  }
  if (!S_ISREG(pst.st_mode)) {
    *errnum = 0;
    *at_open = 2;
    return 0;
  }
  if ((uint64_t)pst.st_size > OBJ_MAX_BYTES) {
    *errnum = EFBIG;
    *at_open = 3;
    return 0;
  }
  FILE *f = fopen(path, "rb");
  if (!f) {
    *errnum = errno;
    return 0;
  }
  *at_open = 0;
  size_t cap = 1 << 16, n = 0;
  struct stat st;
  if (fstat(fileno(f), &st) == 0 && S_ISREG(st.st_mode) && st.st_size > 0)
    cap = (size_t)st.st_size + 2; /* room to see EOF without growing */
  char *b = malloc(cap);
  if (!b) {
    fclose(f);
    *errnum = ENOMEM;
    return 0;
  }
  for (;;) {
    if (n + 1 >= cap) {
      char *nb = cap > SIZE_MAX / 2 ? NULL : realloc(b, cap * 2);
      if (!nb) {
        free(b);
        fclose(f);
        *errnum = ENOMEM;
        return 0;
      }
      b = nb;
      cap *= 2;
    }
    size_t got = fread(b + n, 1, cap - 1 - n, f);
    n += got;
    if (got == 0) {
      if (ferror(f)) {
        *errnum = errno ? errno : EIO;
        free(b);
        fclose(f);
        return 0;
      }
      break;
    }
  }
  fclose(f);
  b[n] = '\0';
  *buf = b;
  *len = n;
  return 1;
}

/* Joins the directory part of 'objpath' (up to and including its last '/') with 'name'; an
 * absolute 'name' is copied as is. Returns a fresh string or NULL. */
static char *resolve_path(const char *objpath, const char *name, size_t name_len) {
  size_t dl = 0;
  if (name[0] != '/') {
    const char *slash = strrchr(objpath, '/');
    if (slash) dl = (size_t)(slash - objpath) + 1;
  }
  char *r = malloc(dl + name_len + 1);
  if (!r) return NULL;
  memcpy(r, objpath, dl);
  memcpy(r + dl, name, name_len);
  r[dl + name_len] = '\0';
  return r;
}

/* ---------------------------------------------------------------- materials */

static const double GREY[3] = {0.5, 0.5, 0.5}, BLACK[3] = {0, 0, 0};

/* Index of material 'name', adding it grey and non-emitting if missing; '*added' tells which.
 * Returns -1 when out of memory. */
static int find_or_add_material(hr_scene *s, const char *name, int *added) {
  int m = hr_scene_find_material(s, name);
  *added = 0;
  if (m >= 0) return m;
  if (hr_scene_add_material(s, name, GREY, BLACK, &m) != HR_OK) return -1;
  *added = 1;
  return m;
}

/* Parses `Kd`/`Ke` values after the key at 'p' into 'rgb' (1 value = grey, 3 = RGB) and checks
 * them: Kd in [0,1], Ke >= 0, all finite. Errors name MTL file 'mpath' and 'line'. */
static hr_status parse_color(obj_ctx *c, const char *mpath, long line, const char *key, char *p,
                             int is_kd, double rgb[3]) {
  double v[3] = {0, 0, 0};
  int n;
  hr_status st = read_numbers(c, mpath, line, p, v, 3, 1, &n);
  if (st != HR_OK) return st;
  if (n > 3)
    return hr_err_set(c->err, HR_ERR_PARSE, "%s:%ld: %s needs 1 or 3 numbers, got more", mpath,
                      line, key);
  if (n != 1 && n != 3)
    return hr_err_set(c->err, HR_ERR_PARSE, "%s:%ld: %s needs 1 or 3 numbers, got %d", mpath, line,
                      key, n);
  for (int k = 0; k < 3; k++) {
    rgb[k] = v[n == 1 ? 0 : k];
    if (is_kd && !(rgb[k] >= 0 && rgb[k] <= 1))
      return hr_err_set(c->err, HR_ERR_PARSE, "%s:%ld: rho must be in [0,1] (Kd %g)", mpath, line,
                        rgb[k]);
    if (!is_kd && !(rgb[k] >= 0))
      return hr_err_set(c->err, HR_ERR_PARSE, "%s:%ld: Ke must not be negative (Ke %g)", mpath,
                        line, rgb[k]);
    if (!is_kd && rgb[k] != 0 && !(rgb[k] >= KE_MIN && rgb[k] <= KE_MAX))
      return hr_err_set(c->err, HR_ERR_PARSE, "%s:%ld: Ke must be 0 or in [%g,%g] (Ke %g)", mpath,
                        line, KE_MIN, KE_MAX, rgb[k]);
  }
  return HR_OK;
}

/* Gives material 'mat' texture slot 'slot' (-1: none); 0 when out of memory. */
static int set_texture(obj_ctx *c, int mat, int slot) {
  size_t need = (size_t)c->s->nmats;
  if (need > c->cap_mat_tex) {
    size_t old = c->cap_mat_tex;
    if (!grow((void **)&c->mat_tex, &c->cap_mat_tex, need, sizeof *c->mat_tex)) return 0;
    for (size_t i = old; i < c->cap_mat_tex; i++) c->mat_tex[i] = -1;
  }
  c->mat_tex[mat] = slot;
  return 1;
}

/* Handles `map_Kd [OPTIONS] FILE` of material 'cur' in MTL file 'mpath': the last word names
 * the texture, relative to the MTL file. In memory mode no file is read: one warning. */
static hr_status do_map_kd(obj_ctx *c, const char *mpath, long line, int cur, char *rest) {
  if (c->mem_mode) {
    if (!c->warned_map)
      hr_log_warn(c->log, "%s:%ld: texture map_Kd '%.60s' not read (no files in memory mode)",
                  mpath, line, rest);
    c->warned_map = 1;
    return HR_OK;
  }
  char *name = rest, *q = rest;
  for (; *q; q += token_len(q), q = skip_blanks(q)) name = q;
  size_t nl = token_len(name);
  if (nl == 0) return HR_OK;
  char *raw = strndup(name, nl), full[8400];
  if (raw) hr_texture_resolve(mpath, raw, full, sizeof full);
  char *path = raw ? strdup(full) : NULL;
  free(raw);
  if (!path) return hr_err_set(c->err, HR_ERR_NOMEM, "%s:%ld: out of memory", mpath, line);
  int slot = 0;
  while (slot < c->ntexs && strcmp(c->texs[slot].path, path)) slot++;
  if (slot == c->ntexs) {
    obj_tex *t = realloc(c->texs, (size_t)(c->ntexs + 1) * sizeof *t);
    if (!t) {
      free(path);
      return hr_err_set(c->err, HR_ERR_NOMEM, "%s:%ld: out of memory", mpath, line);
    }
    c->texs = t;
    memset(&t[slot], 0, sizeof *t);
    t[slot].path = path;
    c->ntexs++;
  } else {
    free(path);
  }
  if (!set_texture(c, cur, slot))
    return hr_err_set(c->err, HR_ERR_NOMEM, "%s:%ld: out of memory", mpath, line);
  return HR_OK;
}

/* Parses the MTL text 'buf' (mutable, NUL-terminated, 'len' bytes) read from 'mpath' and adds or
 * redefines its materials in the scene. Errors are "MPATH:LINE: what". */
static hr_status parse_mtl(obj_ctx *c, const char *mpath, char *buf, size_t len) {
  line_iter it = lines_begin(buf, len);
  long line;
  int has_nul, cur = -1;
  char *p;
  while ((p = next_line(&it, &line, &has_nul))) {
    if (has_nul)
      return hr_err_set(c->err, HR_ERR_PARSE, "%s:%ld: NUL byte in text file", mpath, line);
    p = skip_blanks(p);
    if (*p == '\0' || *p == '#') continue;
    size_t kl = token_len(p);
    char *rest = skip_blanks(p + kl);
    if (kl == 6 && memcmp(p, "newmtl", 6) == 0) {
      if (*rest == '\0')
        return hr_err_set(c->err, HR_ERR_PARSE, "%s:%ld: newmtl needs a name", mpath, line);
      int added;
      cur = find_or_add_material(c->s, rest, &added);
      if (cur < 0) return hr_err_set(c->err, HR_ERR_NOMEM, "%s:%ld: out of memory", mpath, line);
      for (int k = 0; k < 3; k++) {
        c->s->mats[cur].rho[k] = GREY[k];
        c->s->mats[cur].emit[k] = BLACK[k];
      }
      if (!set_texture(c, cur, -1))
        return hr_err_set(c->err, HR_ERR_NOMEM, "%s:%ld: out of memory", mpath, line);
    } else if (kl == 2 && (memcmp(p, "Kd", 2) == 0 || memcmp(p, "Ke", 2) == 0)) {
      int is_kd = p[1] == 'd';
      const char *key = is_kd ? "Kd" : "Ke";
      if (cur < 0)
        return hr_err_set(c->err, HR_ERR_PARSE, "%s:%ld: %s before any newmtl", mpath, line, key);
      double rgb[3] = {0, 0, 0};
      hr_status st = parse_color(c, mpath, line, key, rest, is_kd, rgb);
      if (st != HR_OK) return st;
      for (int k = 0; k < 3; k++) {
        if (is_kd)
          c->s->mats[cur].rho[k] = rgb[k];
        else
          c->s->mats[cur].emit[k] = rgb[k];
      }
    } else if (kl == 6 && memcmp(p, "map_Kd", 6) == 0 && cur >= 0) {
      hr_status st = do_map_kd(c, mpath, line, cur, rest);
      if (st != HR_OK) return st;
    }
    /* every other key (Ka, Ks, Ns, d, illum, map_*, ...) is irrelevant to diffuse radiosity */
  }
  return HR_OK;
}

/* Tries to read one material library 'name' (length 'nl', not NUL-terminated) named on OBJ line
 * 'line'. '*opened' tells whether the file could be read; parse errors are returned. */
static hr_status load_mtl(obj_ctx *c, long line, const char *name, size_t nl, int *opened) {
  *opened = 0;
  char *mpath = resolve_path(c->path, name, nl);
  if (!mpath) return hr_err_set(c->err, HR_ERR_NOMEM, "%s:%ld: out of memory", c->path, line);
  char *buf;
  size_t len;
  int errnum, at_open;
  hr_status st = HR_OK;
  if (c->mem_mode) {
    /* the library text comes from memory: a fresh mutable copy per mtllib statement */
    if (c->mem_mtl) {
      buf = c->mem_mtl_len < SIZE_MAX ? malloc(c->mem_mtl_len + 1) : NULL;
      if (!buf) st = hr_err_set(c->err, HR_ERR_NOMEM, "%s: out of memory", mpath);
      else {
        if (c->mem_mtl_len) memcpy(buf, c->mem_mtl, c->mem_mtl_len);
        buf[c->mem_mtl_len] = '\0';
        *opened = 1;
        st = parse_mtl(c, mpath, buf, c->mem_mtl_len);
        free(buf);
      }
    }
  } else if (read_whole(mpath, &buf, &len, &errnum, &at_open)) {
    *opened = 1;
    st = parse_mtl(c, mpath, buf, len);
    free(buf);
  } else if (errnum == ENOMEM) {
    st = hr_err_set(c->err, HR_ERR_NOMEM, "%s: out of memory", mpath);
  } else if (at_open == 3) {
    st = hr_err_set(c->err, HR_ERR_TOO_BIG, "%s: larger than %llu bytes (4 GiB), the limit", mpath,
                    (unsigned long long)OBJ_MAX_BYTES);
  }
  free(mpath);
  return st;
}

/* Handles `mtllib REST`: see the file comment for how names with blanks are treated. */
static hr_status do_mtllib(obj_ctx *c, long line, char *rest) {
  if (*rest == '\0')
    return hr_err_set(c->err, HR_ERR_PARSE, "%s:%ld: mtllib needs a file name", c->path, line);
  int opened;
  hr_status st = load_mtl(c, line, rest, strlen(rest), &opened);
  if (st != HR_OK || opened) return st;
  if (c->mem_mode) { /* no library in memory: nothing to look for on the disk either */
    hr_log_warn(c->log, "%s:%ld: cannot open material library '%s'; using grey default", c->path,
                line, rest);
    return HR_OK;
  }
  /* several names, or one name with blanks that does not exist: if no word names a readable
   * file either, report the whole line as one missing library */
  int readable = 0;
  for (char *p = rest; token_len(rest) != strlen(rest) && *(p = skip_blanks(p));) {
    size_t n = token_len(p);
    char *mpath = resolve_path(c->path, p, n);
    if (!mpath) return hr_err_set(c->err, HR_ERR_NOMEM, "%s:%ld: out of memory", c->path, line);
    readable += access(mpath, R_OK) == 0;
    free(mpath);
    p += n;
  }
  if (!readable) {
    hr_log_warn(c->log, "%s:%ld: cannot open material library '%s'; using grey default", c->path,
                line, rest);
    return HR_OK;
  }
  for (char *p = rest; *(p = skip_blanks(p));) {
    size_t n = token_len(p);
    st = load_mtl(c, line, p, n, &opened);
    if (st != HR_OK) return st;
    if (!opened)
      hr_log_warn(c->log, "%s:%ld: cannot open material library '%.*s'; using grey default",
                  c->path, line, (int)n, p);
    p += n;
  }
  return HR_OK;
}

/* Handles `usemtl NAME`. */
static hr_status do_usemtl(obj_ctx *c, long line, const char *name) {
  if (*name == '\0')
    return hr_err_set(c->err, HR_ERR_PARSE, "%s:%ld: usemtl needs a material name", c->path, line);
  int added;
  c->cur_mat = find_or_add_material(c->s, name, &added);
  if (c->cur_mat < 0)
    return hr_err_set(c->err, HR_ERR_NOMEM, "%s:%ld: out of memory", c->path, line);
  if (added)
    hr_log_warn(c->log, "%s:%ld: unknown material '%s'; using grey default", c->path, line, name);
  return HR_OK;
}

/* ---------------------------------------------------------------- geometry */

/* Handles `v x y z [w ...]` with the numbers at 'p'. */
static hr_status do_vertex(obj_ctx *c, long line, char *p) {
  double x[3] = {0, 0, 0};
  int n;
  hr_status st = read_numbers(c, c->path, line, p, x, 3, 0, &n);
  if (st != HR_OK) return st;
  if (n < 3)
    return hr_err_set(c->err, HR_ERR_PARSE, "%s:%ld: vertex needs 3 coordinates, got %d", c->path,
                      line, n);
  for (int k = 0; k < 3; k++)
    if (!(fabs(x[k]) <= COORD_MAX))
      return hr_err_set(c->err, HR_ERR_PARSE,
                        "%s:%ld: coordinate %g out of range (magnitude at most %g)", c->path, line,
                        x[k], COORD_MAX);
  if (!grow((void **)&c->verts, &c->cap_verts, c->nverts + 1, sizeof *c->verts))
    return hr_err_set(c->err, HR_ERR_NOMEM, "%s:%ld: out of memory", c->path, line);
  c->verts[c->nverts++] = (hr_vec3){x[0], x[1], x[2]};
  return HR_OK;
}

/* Parses an optionally signed decimal integer at '*pp' (clamped to +-LLONG_MAX/2 on overflow);
 * 0 if there are no digits. */
static int parse_int(char **pp, long long *out) {
  char *p = *pp;
  int neg = 0;
  if (*p == '-' || *p == '+') neg = *p++ == '-';
  if (*p < '0' || *p > '9') return 0;
  long long v = 0;
  while (*p >= '0' && *p <= '9') {
    if (v < LLONG_MAX / 20) v = v * 10 + (*p - '0');
    p++;
  }
  *out = neg ? -v : v;
  *pp = p;
  return 1;
}

/* Parses one face reference token `v`, `v/vt`, `v//vn` or `v/vt/vn` at 'p' (length 'n');
 * returns 1 with the vertex index in '*vi', 0 if malformed. */
static int parse_ref(char *p, size_t n, long long *vi, long long *ti) {
  char *end = p + n;
  long long dummy;
  *ti = 0;
  if (!parse_int(&p, vi)) return 0;
  if (p == end) return 1;
  if (*p++ != '/') return 0;
  if (*p == '/') {
    p++;
    return parse_int(&p, &dummy) && p == end;
  }
  if (!parse_int(&p, ti)) return 0;
  if (p == end) return 1;
  if (*p++ != '/') return 0;
  return parse_int(&p, &dummy) && p == end;
}

/* ---------------------------------------------------------------- duplicate polygons */

static int cmp_pos(const void *pa, const void *pb) {
  const hr_vec3 *a = pa, *b = pb;
  if (a->x != b->x) return a->x < b->x ? -1 : 1;
  if (a->y != b->y) return a->y < b->y ? -1 : 1;
  if (a->z != b->z) return a->z < b->z ? -1 : 1;
  return 0;
}

/* Sorts and de-duplicates the current face's 'n' positions into c->sorted ('*m' of them) and
 * hashes them; 0 when out of memory. */
static int face_key(obj_ctx *c, size_t n, size_t *m, uint64_t *hash) {
  if (!grow((void **)&c->sorted, &c->cap_sorted, n, sizeof *c->sorted)) return 0;
  memcpy(c->sorted, c->face, n * sizeof *c->sorted);
  if (n <= 16) { /* typical faces: insertion sort, no qsort call overhead */
    for (size_t i = 1; i < n; i++) {
      hr_vec3 t = c->sorted[i];
      size_t j = i;
      for (; j > 0 && cmp_pos(&c->sorted[j - 1], &t) > 0; j--) c->sorted[j] = c->sorted[j - 1];
      c->sorted[j] = t;
    }
  } else {
    qsort(c->sorted, n, sizeof *c->sorted, cmp_pos);
  }
  size_t k = 0;
  for (size_t i = 0; i < n; i++)
    if (k == 0 || cmp_pos(&c->sorted[k - 1], &c->sorted[i]) != 0) c->sorted[k++] = c->sorted[i];
  uint64_t h = 0x9e3779b97f4a7c15ull ^ k;
  for (size_t i = 0; i < k; i++) h = v3_hash(h, c->sorted[i]);
  *m = k;
  *hash = h;
  return 1;
}

/* The record of an earlier polygon with the same positions (c->sorted[0..m)) facing along 'nrm',
 * or NULL. */
static const face_rec *find_duplicate(const obj_ctx *c, size_t m, uint64_t hash, hr_vec3 nrm) {
  if (c->cap_rtab == 0) return NULL;
  size_t mask = c->cap_rtab - 1;
  for (size_t i = (size_t)hash & mask; c->rtab[i] != SIZE_MAX; i = (i + 1) & mask) {
    const face_rec *r = &c->recs[c->rtab[i]];
    if (r->hash != hash || r->n != m) continue;
    if (r->nrm.x * nrm.x + r->nrm.y * nrm.y + r->nrm.z * nrm.z <= 0) continue;
    size_t j = 0;
    while (j < m && cmp_pos(&c->rpos[r->off + j], &c->sorted[j]) == 0) j++;
    if (j == m) return r;
  }
  return NULL;
}

/* Records the polygon just added (c->sorted[0..m), 'hash', 'nrm', 'line', kept polygon 'poly');
 * 0 on NOMEM. */
static int record_face(obj_ctx *c, size_t m, uint64_t hash, hr_vec3 nrm, long line, int poly) {
  if (!grow((void **)&c->recs, &c->cap_recs, c->nrecs + 1, sizeof *c->recs) ||
      !grow((void **)&c->rpos, &c->cap_rpos, c->nrpos + m, sizeof *c->rpos))
    return 0;
  if (2 * (c->nrecs + 1) > c->cap_rtab) { /* keep the load <= 1/2: rebuild twice as large */
    size_t nc = c->cap_rtab ? 2 * c->cap_rtab : 64;
    size_t *t = malloc(nc * sizeof *t);
    if (!t) return 0;
    memset(t, 0xff, nc * sizeof *t);
    for (size_t r = 0; r < c->nrecs; r++) {
      size_t i = (size_t)c->recs[r].hash & (nc - 1);
      while (t[i] != SIZE_MAX) i = (i + 1) & (nc - 1);
      t[i] = r;
    }
    free(c->rtab);
    c->rtab = t;
    c->cap_rtab = nc;
  }
  face_rec *r = &c->recs[c->nrecs];
  r->hash = hash;
  r->off = c->nrpos;
  r->n = m;
  r->nrm = nrm;
  r->line = line;
  r->poly = poly;
  memcpy(&c->rpos[c->nrpos], c->sorted, m * sizeof *c->rpos);
  c->nrpos += m;
  size_t i = (size_t)hash & (c->cap_rtab - 1);
  while (c->rtab[i] != SIZE_MAX) i = (i + 1) & (c->cap_rtab - 1);
  c->rtab[i] = c->nrecs++;
  return 1;
}

/* Handles `f ref ref ref ...` with the references at 'p'. */
/* The material of the current face (its 'n' vertices and, with 'has_uv', texture coordinates in
 * c->face, c->face_uv): the current one, or, when that has a readable map_Kd, a variant whose
 * reflectance is Kd times the texture's mean over the face (texture.c). A texture that cannot be
 * read warns once and leaves Kd alone. */
static hr_status textured_material(obj_ctx *c, long line, size_t n, int has_uv, int *mat) {
  int m = *mat;
  if (!has_uv || m < 0 || (size_t)m >= c->cap_mat_tex || c->mat_tex[m] < 0) return HR_OK;
  obj_tex *t = &c->texs[c->mat_tex[m]];
  if (!t->tried) {
    hr_err e = {{0}};
    t->tried = 1;
    t->ok = hr_texture_load(t->path, &t->tex, &e) == HR_OK;
    if (!t->ok)
      hr_log_warn(c->log, "%s:%ld: texture of material '%.60s' not used (%s); Kd alone is the "
                          "reflectance", c->path, line, c->s->mats[m].name, e.msg);
  }
  if (!t->ok) return HR_OK;
  double mean[3], rho[3];
  hr_texture_mean_poly(&t->tex, c->face, (const double(*)[2])c->face_uv, (int)n, mean);
  for (int k = 0; k < 3; k++) {
    rho[k] = c->s->mats[m].rho[k] * mean[k];
    rho[k] = rho[k] < 0 ? 0 : rho[k] > 1 ? 1 : rho[k];
  }
  if (hr_scene_add_variant(c->s, m, rho, mat) != HR_OK)
    return hr_err_set(c->err, HR_ERR_NOMEM, "%s:%ld: out of memory", c->path, line);
  return HR_OK;
}

static hr_status do_face(obj_ctx *c, long line, char *p) {
  size_t n = 0;
  int has_uv = 1; /* every vertex has a texture coordinate */
  for (;;) {
    p = skip_blanks(p);
    if (*p == '\0' || *p == '#') break;
    size_t tl = token_len(p);
    long long vi, ti;
    if (!parse_ref(p, tl, &vi, &ti))
      return hr_err_set(c->err, HR_ERR_PARSE, "%s:%ld: malformed vertex reference '%.*s'", c->path,
                        line, shown(tl), p);
    if (vi == 0)
      return hr_err_set(c->err, HR_ERR_PARSE,
                        "%s:%ld: vertex index 0 is invalid (indices start at 1)", c->path, line);
    long long abs_i = vi > 0 ? vi : (long long)c->nverts + vi + 1;
    if (abs_i < 1 || abs_i > (long long)c->nverts) {
      /* the index as written (parse_int clamps beyond 18 digits) */
      size_t il = (*p == '-' || *p == '+') + strspn(p + (*p == '-' || *p == '+'), "0123456789");
      return hr_err_set(c->err, HR_ERR_PARSE,
                        "%s:%ld: vertex index %.*s out of range (%zu vertices so far)", c->path,
                        line, shown(il), p, c->nverts);
    }
    if (!grow((void **)&c->face, &c->cap_face, n + 1, sizeof *c->face) ||
        !grow((void **)&c->face_uv, &c->cap_face_uv, n + 1, sizeof *c->face_uv))
      return hr_err_set(c->err, HR_ERR_NOMEM, "%s:%ld: out of memory", c->path, line);
    long long abs_t = ti > 0 ? ti : (long long)c->nuvs + ti + 1;
    has_uv = has_uv && ti != 0 && abs_t >= 1 && abs_t <= (long long)c->nuvs &&
             !isnan(c->uvs[abs_t - 1][0]);
    if (has_uv) memcpy(c->face_uv[n], c->uvs[abs_t - 1], sizeof c->face_uv[n]);
    c->face[n++] = c->verts[abs_i - 1];
    p += tl;
  }
  if (n < 3)
    return hr_err_set(c->err, HR_ERR_PARSE, "%s:%ld: face with %zu vertices (needs at least 3)",
                      c->path, line, n);
  if (n > INT_MAX)
    return hr_err_set(c->err, HR_ERR_PARSE, "%s:%ld: face with too many vertices", c->path, line);
  if (c->cur_mat < 0) {
    int added;
    c->cur_mat = find_or_add_material(c->s, "default", &added);
    if (c->cur_mat < 0)
      return hr_err_set(c->err, HR_ERR_NOMEM, "%s:%ld: out of memory", c->path, line);
  }
  /* a face too small for the arithmetic of hr_scene_add_polygon (its area or normal would
   * underflow) is degenerate; it is recorded as such by adding it collapsed to its first vertex */
  double ext = 0;
  for (size_t i = 1; i < n; i++) {
    hr_vec3 d = v3_sub(c->face[i], c->face[0]);
    ext = fmax(ext, fmax(fabs(d.x), fmax(fabs(d.y), fabs(d.z))));
  }
  if (ext < FACE_EXTENT_MIN) {
    for (size_t i = 1; i < n; i++) c->face[i] = c->face[0];
    hr_poly_result res;
    hr_status st = hr_scene_add_polygon(c->s, c->face, (int)n, c->cur_mat, &res);
    if (st == HR_ERR_NOMEM) return hr_err_set(c->err, st, "%s:%ld: out of memory", c->path, line);
    if (st != HR_OK || res != HR_POLY_DEGENERATE)
      return hr_err_set(c->err, st != HR_OK ? st : HR_ERR_INVALID, "%s:%ld: invalid polygon",
                        c->path, line);
    if (ext > 0)
      hr_log_warn(c->log, "%s:%ld: degenerate polygon skipped (extent %g below %g)", c->path, line,
                  ext, FACE_EXTENT_MIN);
    else
      hr_log_warn(c->log, "%s:%ld: degenerate polygon skipped", c->path, line);
    return HR_OK;
  }
  size_t m;
  uint64_t hash;
  if (!face_key(c, n, &m, &hash))
    return hr_err_set(c->err, HR_ERR_NOMEM, "%s:%ld: out of memory", c->path, line);
  hr_vec3 nrm = v3_newell(c->face, (int)n);
  const face_rec *dup = find_duplicate(c, m, hash, nrm);
  if (dup) {
    hr_log_warn(c->log, "%s:%ld: duplicate of the polygon on line %ld; skipped", c->path, line,
                dup->line);
    if (hr_scene_add_duplicate(c->s, dup->poly) != HR_OK)
      return hr_err_set(c->err, HR_ERR_NOMEM, "%s:%ld: out of memory", c->path, line);
    return HR_OK;
  }
  int mat = c->cur_mat;
  hr_status st = textured_material(c, line, n, has_uv, &mat);
  if (st != HR_OK) return st;
  hr_poly_result res;
  st = hr_scene_add_polygon(c->s, c->face, (int)n, mat, &res);
  if (st == HR_ERR_NOMEM) return hr_err_set(c->err, st, "%s:%ld: out of memory", c->path, line);
  if (st != HR_OK) return hr_err_set(c->err, st, "%s:%ld: invalid polygon", c->path, line);
  if (res == HR_POLY_DEGENERATE)
    hr_log_warn(c->log, "%s:%ld: degenerate polygon skipped", c->path, line);
  else if (res == HR_POLY_NONPLANAR)
    return hr_err_set(c->err, HR_ERR_PARSE, "%s:%ld: non-planar polygon with %zu vertices", c->path,
                      line, n);
  else if (res == HR_POLY_NOT_SIMPLE && n > HR_EAR_MAX)
    return hr_err_set(c->err, HR_ERR_PARSE,
                      "%s:%ld: non-convex polygon with %zu vertices (at most %d are triangulated)",
                      c->path, line, n, HR_EAR_MAX);
  else if (res == HR_POLY_NOT_SIMPLE)
    return hr_err_set(c->err, HR_ERR_PARSE,
                      "%s:%ld: polygon with %zu vertices is not simple (its edges cross, or it "
                      "revisits a vertex)",
                      c->path, line, n);
  else if (res != HR_POLY_ADDED)
    return hr_err_set(c->err, HR_ERR_INVALID, "%s:%ld: invalid polygon", c->path, line);
  else if (!record_face(c, m, hash, nrm, line, c->s->npolys - 1))
    return hr_err_set(c->err, HR_ERR_NOMEM, "%s:%ld: out of memory", c->path, line);
  return HR_OK;
}

/* ---------------------------------------------------------------- statements */

/* Statements that carry nothing radiosity needs and are skipped without a warning. */
static const char *const IGNORED[] = {
    "s",     "vn",     "vp",         "l",         "p",
    "cstype",   "deg",      "bmat", "step",   "curv",   "curv2",      "surf",      "parm",
    "trim",     "hole",     "scrv", "sp",     "end",    "con",        "mg",        "bevel",
    "c_interp", "d_interp", "lod",  "usemap", "maplib", "shadow_obj", "trace_obj", "ctech",
    "stech",    "call",     "csh",  NULL};

/* Handles `vt u v [w]`: kept for map_Kd; a malformed one is kept as NaN (no texture for faces
 * that use it), never an error, as before textures were read. */
static hr_status do_texcoord(obj_ctx *c, long line, char *p) {
  double uv[2] = {NAN, NAN};
  for (int k = 0; k < 2; k++) {
    p = skip_blanks(p);
    char *end;
    double x = strtod(p, &end);
    if (end == p || !isfinite(x)) {
      uv[0] = uv[1] = NAN;
      break;
    }
    uv[k] = x;
    p = end;
  }
  if (!grow((void **)&c->uvs, &c->cap_uvs, c->nuvs + 1, sizeof *c->uvs))
    return hr_err_set(c->err, HR_ERR_NOMEM, "%s:%ld: out of memory", c->path, line);
  c->uvs[c->nuvs][0] = uv[0];
  c->uvs[c->nuvs][1] = uv[1];
  c->nuvs++;
  return HR_OK;
}

/* Handles `o NAME` and `g NAME` (see the file comment). */
static hr_status do_object(obj_ctx *c, long line, char kw, const char *name) {
  if (kw == 'o') c->seen_o = 1;
  else if (c->seen_o) return HR_OK;
  if (*name == '\0') return HR_OK;
  if (hr_scene_begin_object(c->s, name) != HR_OK)
    return hr_err_set(c->err, HR_ERR_NOMEM, "%s:%ld: out of memory", c->path, line);
  return HR_OK;
}

/* Warns about unknown keyword 'kw' (length 'kl') once per keyword, for at most
 * MAX_WARNED_KEYWORDS different keywords. */
static void warn_unknown(obj_ctx *c, long line, const char *kw, size_t kl) {
  for (int i = 0; IGNORED[i]; i++)
    if (strlen(IGNORED[i]) == kl && memcmp(IGNORED[i], kw, kl) == 0) return;
  if (c->nwarned > MAX_WARNED_KEYWORDS) return;
  for (size_t off = 0; off < c->warned_len; off += strlen(c->warned + off) + 1)
    if (strlen(c->warned + off) == kl && memcmp(c->warned + off, kw, kl) == 0) return;
  if (c->nwarned == MAX_WARNED_KEYWORDS) {
    c->nwarned++;
    hr_log_warn(c->log, "%s:%ld: more unknown statements; not reporting further ones", c->path,
                line);
    return;
  }
  if (!grow((void **)&c->warned, &c->warned_cap, c->warned_len + kl + 1, 1)) return;
  memcpy(c->warned + c->warned_len, kw, kl);
  c->warned[c->warned_len + kl] = '\0';
  c->warned_len += kl + 1;
  c->nwarned++;
  hr_log_warn(c->log, "%s:%ld: unknown statement '%.*s' ignored", c->path, line, shown(kl), kw);
}

/* Parses the OBJ text in 'c' from mutable NUL-terminated 'buf' of 'len' bytes into c->s. */
static hr_status parse_obj_text(obj_ctx *c, char *buf, size_t len) {
  line_iter it = lines_begin(buf, len);
  long line;
  int has_nul;
  char *p;
  hr_status st = HR_OK;
  while (st == HR_OK && (p = next_line(&it, &line, &has_nul))) {
    if (has_nul)
      return hr_err_set(c->err, HR_ERR_PARSE, "%s:%ld: NUL byte in text file", c->path, line);
    p = skip_blanks(p);
    size_t kl = token_len(p);
    char *rest = skip_blanks(p + kl);
    if (kl == 1 && p[0] == 'v')
      st = do_vertex(c, line, rest);
    else if (kl == 1 && p[0] == 'f')
      st = do_face(c, line, rest);
    else if (kl == 0 || p[0] == '#')
      continue;
    else if (kl == 6 && memcmp(p, "usemtl", 6) == 0)
      st = do_usemtl(c, line, rest);
    else if (kl == 1 && (p[0] == 'o' || p[0] == 'g'))
      st = do_object(c, line, p[0], rest);
    else if (kl == 2 && p[0] == 'v' && p[1] == 't')
      st = do_texcoord(c, line, rest);
    else if (kl == 6 && memcmp(p, "mtllib", 6) == 0)
      st = do_mtllib(c, line, rest);
    else
      warn_unknown(c, line, p, kl);
  }
  if (st != HR_OK) return st;
  if (c->s->npolys == 0) return hr_err_set(c->err, HR_ERR_PARSE, "%s: no polygons", c->path);
  return HR_OK;
}

char *hr_scene_name_of(const char *path) {
  const char *b = strrchr(path, '/');
  b = b ? b + 1 : path;
  size_t n = strlen(b);
  const char *dot = strrchr(b, '.');
  if (dot && dot > b) n = (size_t)(dot - b);
  if (n == 0) return strdup("scene");
  char *r = malloc(n + 1);
  if (!r) return NULL;
  memcpy(r, b, n);
  r[n] = '\0';
  return r;
}

/* Parses mutable NUL-terminated 'buf' (len bytes, owned by the caller) named 'path'. With
 * 'mem_mode', mtllib statements read 'mtl' (mlen bytes; NULL: no library) instead of files. */
static hr_status parse_owned(char *buf, size_t len, const char *path, const hr_log *log,
                             int mem_mode, const char *mtl, size_t mlen, hr_scene **out,
                             hr_err *err) {
  obj_ctx c;
  memset(&c, 0, sizeof c);
  c.path = path;
  c.log = log;
  c.err = err;
  c.cur_mat = -1;
  c.mem_mode = mem_mode;
  c.mem_mtl = mtl;
  c.mem_mtl_len = mlen;
  char *name = hr_scene_name_of(path);
  if (!name || hr_scene_create(name, &c.s) != HR_OK) {
    free(name);
    return hr_err_set(err, HR_ERR_NOMEM, "%s: out of memory", path);
  }
  free(name);
  hr_status st = parse_obj_text(&c, buf, len);
  free(c.verts);
  free(c.face);
  free(c.warned);
  free(c.recs);
  free(c.rpos);
  free(c.rtab);
  free(c.sorted);
  free(c.uvs);
  free(c.face_uv);
  free(c.mat_tex);
  for (int i = 0; i < c.ntexs; i++) {
    free(c.texs[i].path);
    hr_texture_free(&c.texs[i].tex);
  }
  free(c.texs);
  if (st != HR_OK) {
    hr_scene_destroy(&c.s);
    return st;
  }
  *out = c.s;
  return HR_OK;
}

/* Copies the OBJ text and parses it (hr_scene_parse_obj and hr_scene_parse_obj_mtl). */
static hr_status parse_copy(const char *fn, const char *buf, size_t len, int mem_mode,
                            const char *mtl, size_t mlen, const char *path, const hr_log *log,
                            hr_scene **out, hr_err *err) {
  if (!out) return hr_err_set(err, HR_ERR_INVALID, "%s: no output pointer", fn);
  *out = NULL;
  if (!path) path = "<obj>";
  if (!buf && len > 0) return hr_err_set(err, HR_ERR_INVALID, "%s: no text", path);
  if (len == SIZE_MAX) return hr_err_set(err, HR_ERR_NOMEM, "%s: out of memory", path);
  char *copy = malloc(len + 1);
  if (!copy) return hr_err_set(err, HR_ERR_NOMEM, "%s: out of memory", path);
  if (len) memcpy(copy, buf, len);
  copy[len] = '\0';
  hr_status st = parse_owned(copy, len, path, log, mem_mode, mtl, mlen, out, err);
  free(copy);
  return st;
}

hr_status hr_scene_parse_obj(const char *buf, size_t len, const char *path, const hr_log *log,
                             hr_scene **out, hr_err *err) {
  return parse_copy("hr_scene_parse_obj", buf, len, 0, NULL, 0, path, log, out, err);
}

hr_status hr_scene_parse_obj_mtl(const char *obj, size_t olen, const char *mtl, size_t mlen,
                                 const char *path, const hr_log *log, hr_scene **out,
                                 hr_err *err) {
  if (!mtl && mlen > 0) {
    if (out) *out = NULL;
    return hr_err_set(err, HR_ERR_INVALID, "%s: no material library text", path ? path : "<obj>");
  }
  return parse_copy("hr_scene_parse_obj_mtl", obj, olen, 1, mtl, mlen, path, log, out, err);
}

hr_status hr_scene_load_obj(const char *path, const hr_log *log, hr_scene **out, hr_err *err) {
  if (!out) return hr_err_set(err, HR_ERR_INVALID, "hr_scene_load_obj: no output pointer");
  *out = NULL;
  if (!path) return hr_err_set(err, HR_ERR_INVALID, "hr_scene_load_obj: no path");
  char *buf;
  size_t len;
  int errnum, at_open;
  if (!read_whole(path, &buf, &len, &errnum, &at_open)) {
    if (errnum == ENOMEM) return hr_err_set(err, HR_ERR_NOMEM, "%s: out of memory", path);
    if (at_open == 2) return hr_err_set(err, HR_ERR_IO, "%s: not a regular file", path);
    if (at_open == 3)
      return hr_err_set(err, HR_ERR_TOO_BIG, "%s: larger than %llu bytes (4 GiB), the limit", path,
                        (unsigned long long)OBJ_MAX_BYTES);
    return hr_err_set(err, HR_ERR_IO, "%s: cannot %s: %s", path, at_open ? "open" : "read",
                      strerror(errnum));
  }
  hr_status st = parse_owned(buf, len, path, log, 0, NULL, 0, out, err);
  free(buf);
  return st;
}
