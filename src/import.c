/* import.c: scenes in the formats of other tools (glTF 2.0, PLY, 3DS, FBX, Collada, STL) read
 * through assimp's C API into an hr_scene, and hr_scene_load, which picks the reader by the
 * file's extension (OBJ stays on obj.c: fuzzed, exact, with line numbers in its messages).
 *
 * What is kept, and how (see hrad.h, hr_scene_import):
 *  - polygons as stored: assimp runs with aiProcess_JoinIdenticalVertices (one vertex per
 *    position and attributes), aiProcess_TransformUVCoords (texture transforms baked into the
 *    UVs) and aiProcess_ValidateDataStructure (corrupt files fail at import), never Triangulate;
 *    quads stay quads and larger polygons go through hr_scene_add_polygon (fan or ear clipping).
 *    Points and lines are skipped. A node transform with a negative determinant (a mirror)
 *    reverses the vertex order, so that faces keep facing out.
 *  - objects: the scene graph is walked depth first; every node holding meshes is an object,
 *    named after the node (or, for an unnamed node, its first mesh; "object N" when neither
 *    has a name). Vertices go to world space through the product of the node transforms.
 *  - materials: one scene material per assimp material, in file order, named after it
 *    ("material N" when unnamed; "NAME#N" when the name repeats). Reflectance: the base colour
 *    (glTF baseColorFactor) or the diffuse colour (3DS, FBX, Collada, MTL), grey 0.5 when there
 *    is none, clamped to [0, 1] with a warning. Emission: the emissive colour times the glTF
 *    KHR_materials_emissive_strength (assimp 5.2.5 drops it: gltfext.c reads it from the JSON;
 *    a later assimp's $mat.emissiveIntensity wins); channels below 1e-30 are 0, above 1e30 or
 *    not finite an error. Materials no mesh uses (assimp's added default) are left out.
 *  - textures: a material with a diffuse (base colour) texture and texture coordinates gives
 *    each polygon the mean of the texture over the polygon's UV footprint (texture.c; sRGB
 *    decoded to linear, alpha ignored, the texture repeating), times the colour factor, as a
 *    variant of the material. Textures are read once each: from the file named (relative to the
 *    scene's directory; a path that does not exist is tried by its base name there too) or
 *    embedded ("*N" in glTF binary). A texture that cannot be read gives one warning and the
 *    factor alone.
 * assimp keeps its messages in a global string: imports are serialised by a mutex. */
#include "hrad.h"
#include "gltfext.h"
#include "scene_impl.h"
#include "texture.h"

#include <assimp/cimport.h>
#include <assimp/material.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

/* Extensions read through assimp (lower case, without the dot). */
static const char *const IMPORT_EXT[] = {"gltf", "glb", "ply", "3ds", "fbx", "dae", "stl", NULL};

#define EMIT_MIN 1e-30
#define EMIT_MAX 1e30
#define NAME_MAX_LEN 200

/* One texture, read at most once per import. */
typedef struct tex_slot {
  char *key;      /* the path as the material names it */
  int tried, ok;
  hr_texture tex;
} tex_slot;

typedef struct imp_ctx {
  const char *path;
  const hr_log *log;
  hr_err *err;
  hr_scene *s;
  const struct aiScene *ai;
  int *mat_of;        /* assimp material -> scene material */
  int *tex_of;        /* assimp material -> texture slot or -1 */
  unsigned *uv_of;    /* assimp material -> UV channel of its diffuse texture */
  double *strength;   /* assimp material -> glTF emissive strength (1 for other formats) */
  tex_slot *tex;
  int ntex;
  hr_vec3 *poly;      /* scratch: one face's world positions */
  double (*uv)[2];    /* and texture coordinates */
  unsigned cap_poly;
  int *vtab;          /* the variants made so far (variant_of) */
  size_t cap_vtab, nvariants;
  long ndegen, nskipped, nclamped;
  int objects_made;
} imp_ctx;

static pthread_mutex_t g_ai_lock = PTHREAD_MUTEX_INITIALIZER;

/* ---------------------------------------------------------------- names and paths */

/* The extension of 'path' in lower case ("" when none), in 'out' of 'n' bytes. */
static void ext_of(const char *path, char *out, size_t n) {
  const char *b = strrchr(path, '/');
  b = b ? b + 1 : path;
  const char *dot = strrchr(b, '.');
  out[0] = '\0';
  if (!dot || dot == b) return;
  size_t k = 0;
  for (dot++; *dot && k + 1 < n; dot++) out[k++] = (char)tolower((unsigned char)*dot);
  out[k] = '\0';
}

static int is_import_ext(const char *ext) {
  for (int i = 0; IMPORT_EXT[i]; i++)
    if (!strcmp(ext, IMPORT_EXT[i])) return 1;
  return 0;
}

int hr_scene_format_known(const char *path) {
  char ext[16];
  ext_of(path, ext, sizeof ext);
  return !strcmp(ext, "obj") || !ext[0] || is_import_ext(ext);
}

/* 1 when the first 'n' bytes 'h' of a file of 'size' bytes can start a file of format 'ext'.
 * assimp, when the reader for the extension refuses a file, tries every reader on its content
 * (an OBJ text named .gltf loaded as OBJ): this check keeps a file to its extension's format. */
static int sniff(const char *ext, const unsigned char *h, size_t n, long long size) {
  size_t i = 0;
  if (n >= 3 && h[0] == 0xef && h[1] == 0xbb && h[2] == 0xbf) i = 3; /* UTF-8 BOM */
  while (i < n && isspace(h[i])) i++;
  const char *t = (const char *)h + i;
  size_t m = n - i;
  if (!strcmp(ext, "glb")) return n >= 4 && !memcmp(h, "glTF", 4);
  if (!strcmp(ext, "gltf")) return m >= 1 && t[0] == '{';
  if (!strcmp(ext, "ply")) return n >= 3 && !memcmp(h, "ply", 3);
  if (!strcmp(ext, "dae")) return m >= 1 && t[0] == '<';
  if (!strcmp(ext, "3ds")) return n >= 2 && h[0] == 0x4d && h[1] == 0x4d;
  if (!strcmp(ext, "fbx"))
    return (n >= 18 && !memcmp(h, "Kaydara FBX Binary", 18)) || (m >= 1 && (t[0] == ';' ||
                                                                            isalpha(t[0])));
  if (!strcmp(ext, "stl")) {
    if (m >= 5 && !strncasecmp(t, "solid", 5)) return 1;
    if (size < 84 || n < 84) return 0;
    unsigned long long ntri = h[80] | (unsigned)h[81] << 8 | (unsigned)h[82] << 16 |
                              (unsigned long long)h[83] << 24;
    return (unsigned long long)size == 84 + 50 * ntri;
  }
  return 0;
}

/* Checks with sniff() that 'path' holds its extension's format. */
static hr_status check_format(const char *path, const char *ext, long long size, hr_err *err) {
  unsigned char h[128];
  FILE *fp = fopen(path, "rb");
  if (!fp) return hr_err_set(err, HR_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
  size_t n = fread(h, 1, sizeof h, fp);
  fclose(fp);
  if (!sniff(ext, h, n, size))
    return hr_err_set(err, HR_ERR_PARSE, "%s: not a .%s file (its first bytes do not fit)", path,
                      ext);
  return HR_OK;
}


/* 'name' from assimp as a C string in 'out': control characters become '?' (messages and
 * outputs stay one line), long names are cut. */
static void clean_name(const struct aiString *name, char *out, size_t n) {
  size_t k = 0;
  for (unsigned i = 0; i < name->length && i < MAXLEN && k + 1 < n && k < NAME_MAX_LEN; i++)
    out[k++] = (unsigned char)name->data[i] < 32 ? '?' : name->data[i];
  out[k] = '\0';
}

/* assimp's error string as one line in 'out'. */
static void one_line(const char *msg, char *out, size_t n) {
  snprintf(out, n, "%s", msg && *msg ? msg : "unknown error");
  for (char *p = out; *p; p++)
    if (*p == '\n' || *p == '\r') *p = ' ';
  size_t l = strlen(out);
  while (l > 0 && out[l - 1] == ' ') out[--l] = '\0';
}

/* ---------------------------------------------------------------- materials and textures */

/* Reads colour 'key' of 'm' into rgb; 1 when present. */
static int mat_color(const struct aiMaterial *m, const char *key, unsigned type, unsigned idx,
                     double rgb[3]) {
  struct aiColor4D c;
  if (aiGetMaterialColor(m, key, type, idx, &c) != aiReturn_SUCCESS) return 0;
  rgb[0] = c.r, rgb[1] = c.g, rgb[2] = c.b;
  return 1;
}

/* The texture slot for 'key' (added, not yet read, when new); -1 when out of memory. */
static int tex_slot_of(imp_ctx *c, const char *key) {
  for (int i = 0; i < c->ntex; i++)
    if (!strcmp(c->tex[i].key, key)) return i;
  tex_slot *t = realloc(c->tex, (size_t)(c->ntex + 1) * sizeof *t);
  if (!t) return -1;
  c->tex = t;
  memset(&t[c->ntex], 0, sizeof *t);
  if (!(t[c->ntex].key = strdup(key))) return -1;
  return c->ntex++;
}

/* The embedded texture a material's texture path names ("*N", or its file name), or NULL. */
static const struct aiTexture *embedded(const imp_ctx *c, const char *key) {
  const struct aiScene *ai = c->ai;
  if (key[0] == '*') {
    char *end;
    long i = strtol(key + 1, &end, 10);
    return *end == '\0' && i >= 0 && i < (long)ai->mNumTextures ? ai->mTextures[i] : NULL;
  }
  for (unsigned i = 0; i < ai->mNumTextures; i++)
    if (ai->mTextures[i]->mFilename.length && !strcmp(ai->mTextures[i]->mFilename.data, key))
      return ai->mTextures[i];
  return NULL;
}

/* Decodes embedded texture 'et' into 't'. */
static hr_status decode_embedded(const imp_ctx *c, const struct aiTexture *et, hr_texture *t,
                                 hr_err *err) {
  char name[512];
  snprintf(name, sizeof name, "%s: embedded texture", c->path);
  if (et->mHeight == 0)
    return hr_texture_decode((const unsigned char *)et->pcData, et->mWidth, name, t, err);
  if (et->mWidth > HR_TEX_MAX_SIDE || et->mHeight > HR_TEX_MAX_SIDE)
    return hr_err_set(err, HR_ERR_TOO_BIG, "%s too large", name);
  size_t n = (size_t)et->mWidth * et->mHeight;
  unsigned char *rgba = malloc(4 * n);
  if (!rgba) return hr_err_set(err, HR_ERR_NOMEM, "%s: out of memory", name);
  for (size_t i = 0; i < n; i++) { /* aiTexel is BGRA */
    rgba[4 * i] = et->pcData[i].r;
    rgba[4 * i + 1] = et->pcData[i].g;
    rgba[4 * i + 2] = et->pcData[i].b;
    rgba[4 * i + 3] = et->pcData[i].a;
  }
  hr_status st = hr_texture_from_rgba8(rgba, (int)et->mWidth, (int)et->mHeight, t, err);
  free(rgba);
  return st;
}

/* Reads slot 'i' if it has not been tried; 1 when it holds a texture. Failures warn once. */
static int tex_ready(imp_ctx *c, int i) {
  tex_slot *ts = &c->tex[i];
  if (ts->tried) return ts->ok;
  ts->tried = 1;
  hr_err e = {{0}};
  const struct aiTexture *et = embedded(c, ts->key);
  char full[8400];
  if (!et) hr_texture_resolve(c->path, ts->key, full, sizeof full);
  hr_status st = et ? decode_embedded(c, et, &ts->tex, &e) : hr_texture_load(full, &ts->tex, &e);
  ts->ok = st == HR_OK;
  if (!ts->ok)
    hr_log_warn(c->log, "%s: texture '%.100s' not used (%s); the colour factor alone is the "
                        "reflectance", c->path, ts->key, e.msg);
  return ts->ok;
}

/* A name for assimp material 'i' that no earlier material has. */
static void material_name(imp_ctx *c, unsigned i, char *out, size_t n) {
  struct aiString nm;
  char base[NAME_MAX_LEN + 1] = "";
  if (aiGetMaterialString(c->ai->mMaterials[i], AI_MATKEY_NAME, &nm) == aiReturn_SUCCESS)
    clean_name(&nm, base, sizeof base);
  char ext[16];
  ext_of(c->path, ext, sizeof ext);
  if (!strcmp(ext, "ply") || !strcmp(ext, "stl")) snprintf(base, sizeof base, "default");
  if (!base[0]) snprintf(base, sizeof base, "material %u", i);
  snprintf(out, n, "%s", base);
  for (int k = 2; hr_scene_find_material(c->s, out) >= 0; k++) snprintf(out, n, "%s#%d", base, k);
}

/* Emission of 'm': the emissive colour times the emissive intensity, checked. */
static hr_status material_emit(imp_ctx *c, unsigned idx, const char *name, double e[3]) {
  const struct aiMaterial *m = c->ai->mMaterials[idx];
  e[0] = e[1] = e[2] = 0;
  mat_color(m, AI_MATKEY_COLOR_EMISSIVE, e);
  ai_real ki = 1;
  unsigned one = 1;
  double k = c->strength[idx];
  if (aiGetMaterialFloatArray(m, AI_MATKEY_EMISSIVE_INTENSITY, &ki, &one) == aiReturn_SUCCESS)
    k = ki; /* assimp 5.3 and later read the extension themselves */
  for (int ch = 0; ch < 3; ch++) {
    e[ch] *= k;
    if (!(e[ch] >= 0 && e[ch] <= EMIT_MAX))
      return hr_err_set(c->err, HR_ERR_PARSE,
                        "%s: material '%s': emission %g must be 0 or in [%g, %g]", c->path, name,
                        e[ch], EMIT_MIN, EMIT_MAX);
    if (e[ch] < EMIT_MIN) e[ch] = 0;
  }
  return HR_OK;
}

/* Reflectance of 'm': base colour, else diffuse, else grey; clamped to [0,1]. PLY and STL have
 * no materials (assimp makes a white one): grey 0.5, as for OBJ faces without a material. */
static hr_status material_rho(imp_ctx *c, const struct aiMaterial *m, const char *name,
                              double r[3]) {
  char ext[16];
  ext_of(c->path, ext, sizeof ext);
  int none = !strcmp(ext, "ply") || !strcmp(ext, "stl");
  if (none || (!mat_color(m, AI_MATKEY_BASE_COLOR, r) && !mat_color(m, AI_MATKEY_COLOR_DIFFUSE, r)))
    r[0] = r[1] = r[2] = 0.5;
  for (int ch = 0; ch < 3; ch++) {
    if (!isfinite(r[ch]))
      return hr_err_set(c->err, HR_ERR_PARSE, "%s: material '%s': colour is not finite", c->path,
                        name);
    if (r[ch] < 0 || r[ch] > 1) {
      r[ch] = r[ch] < 0 ? 0 : 1;
      c->nclamped++;
    }
  }
  return HR_OK;
}

/* The diffuse texture of assimp material 'i' into c->tex_of / c->uv_of. */
static hr_status material_texture(imp_ctx *c, unsigned i) {
  const struct aiMaterial *m = c->ai->mMaterials[i];
  struct aiString tp;
  unsigned uvi = 0;
  c->tex_of[i] = -1;
  c->uv_of[i] = 0;
  enum aiTextureType types[2] = {aiTextureType_BASE_COLOR, aiTextureType_DIFFUSE};
  for (int k = 0; k < 2; k++) {
    if (aiGetMaterialTexture(m, types[k], 0, &tp, NULL, &uvi, NULL, NULL, NULL, NULL) !=
            aiReturn_SUCCESS ||
        tp.length == 0)
      continue;
    int slot = tex_slot_of(c, tp.data);
    if (slot < 0) return hr_err_set(c->err, HR_ERR_NOMEM, "%s: out of memory", c->path);
    c->tex_of[i] = slot;
    c->uv_of[i] = uvi < AI_MAX_NUMBER_OF_TEXTURECOORDS ? uvi : 0;
    break;
  }
  return HR_OK;
}

static hr_status add_material(imp_ctx *c, unsigned i);

/* Adds the materials that some mesh uses (assimp adds a default one that may be unused), in
 * file order. */
static hr_status add_materials(imp_ctx *c) {
  unsigned n = c->ai->mNumMaterials;
  c->mat_of = malloc((n ? n : 1) * sizeof *c->mat_of);
  c->tex_of = malloc((n ? n : 1) * sizeof *c->tex_of);
  c->uv_of = malloc((n ? n : 1) * sizeof *c->uv_of);
  c->strength = malloc((n ? n : 1) * sizeof *c->strength);
  if (!c->mat_of || !c->tex_of || !c->uv_of || !c->strength)
    return hr_err_set(c->err, HR_ERR_NOMEM, "%s: out of memory", c->path);
  char ext[16];
  ext_of(c->path, ext, sizeof ext);
  for (unsigned i = 0; i < n; i++) c->strength[i] = 1;
  if (!strcmp(ext, "gltf") || !strcmp(ext, "glb"))
    hr_gltf_emissive_strength(c->path, c->strength, n);
  char *used = calloc(n ? n : 1, 1);
  if (!used) return hr_err_set(c->err, HR_ERR_NOMEM, "%s: out of memory", c->path);
  for (unsigned i = 0; i < c->ai->mNumMeshes; i++)
    if (c->ai->mMeshes[i]->mMaterialIndex < n) used[c->ai->mMeshes[i]->mMaterialIndex] = 1;
  hr_status st = HR_OK;
  for (unsigned i = 0; i < n && st == HR_OK; i++) {
    c->mat_of[i] = -1;
    c->tex_of[i] = -1;
    c->uv_of[i] = 0;
    if (used[i]) st = add_material(c, i);
  }
  free(used);
  if (st != HR_OK) return st;
  if (c->nclamped)
    hr_log_warn(c->log, "%s: %ld colour channel%s outside [0, 1] clamped to reflectance 0 or 1",
                c->path, c->nclamped, c->nclamped > 1 ? "s" : "");
  return HR_OK;
}

/* Adds assimp material 'i' to the scene (c->mat_of[i]) with its texture slot. */
static hr_status add_material(imp_ctx *c, unsigned i) {
  const struct aiMaterial *m = c->ai->mMaterials[i];
  char name[NAME_MAX_LEN + 16];
  material_name(c, i, name, sizeof name);
  double rho[3], e[3];
  hr_status st = material_rho(c, m, name, rho);
  if (st == HR_OK) st = material_emit(c, i, name, e);
  if (st == HR_OK) st = material_texture(c, i);
  if (st != HR_OK) return st;
  if (hr_scene_add_material(c->s, name, rho, e, &c->mat_of[i]) != HR_OK)
    return hr_err_set(c->err, HR_ERR_NOMEM, "%s: out of memory", c->path);
  return HR_OK;
}

/* ---------------------------------------------------------------- geometry */

static hr_vec3 xform(const struct aiMatrix4x4 *t, struct aiVector3D p) {
  return (hr_vec3){t->a1 * p.x + t->a2 * p.y + t->a3 * p.z + t->a4,
                   t->b1 * p.x + t->b2 * p.y + t->b3 * p.z + t->b4,
                   t->c1 * p.x + t->c2 * p.y + t->c3 * p.z + t->c4};
}

static double det3(const struct aiMatrix4x4 *t) {
  return t->a1 * (t->b2 * t->c3 - t->b3 * t->c2) - t->a2 * (t->b1 * t->c3 - t->b3 * t->c1) +
         t->a3 * (t->b1 * t->c2 - t->b2 * t->c1);
}

static size_t variant_hash(int base, const double rho[3]) {
  uint64_t h = (uint64_t)base * 0x9e3779b97f4a7c15ull;
  for (int k = 0; k < 3; k++) {
    uint64_t u;
    memcpy(&u, &rho[k], sizeof u);
    h = (h ^ u) * 0xff51afd7ed558ccdull;
    h ^= h >> 33;
  }
  return (size_t)h;
}

/* Material 'base' with reflectance 'rho' (rounded to float: polygons of one colour share it):
 * an earlier variant with exactly that reflectance, or a new one. The variants are found through
 * an open-addressing table of their indices (c->vtab, kept at most half full). */
static hr_status variant_of(imp_ctx *c, int base, const double rho[3], int *mat) {
  if (2 * (c->nvariants + 1) > c->cap_vtab) {
    size_t cap = c->cap_vtab ? 2 * c->cap_vtab : 1024;
    int *t = malloc(cap * sizeof *t);
    if (!t) return hr_err_set(c->err, HR_ERR_NOMEM, "%s: out of memory", c->path);
    for (size_t i = 0; i < cap; i++) t[i] = -1;
    for (size_t i = 0; i < c->cap_vtab; i++) /* rehash */
      if (c->vtab[i] >= 0) {
        const hr_material *v = &c->s->mats[c->vtab[i]];
        size_t h = variant_hash(v->base, v->rho) & (cap - 1);
        while (t[h] >= 0) h = (h + 1) & (cap - 1);
        t[h] = c->vtab[i];
      }
    free(c->vtab);
    c->vtab = t;
    c->cap_vtab = cap;
  }
  size_t h = variant_hash(base, rho) & (c->cap_vtab - 1);
  for (; c->vtab[h] >= 0; h = (h + 1) & (c->cap_vtab - 1)) {
    const hr_material *v = &c->s->mats[c->vtab[h]];
    if (v->base == base && !memcmp(v->rho, rho, sizeof v->rho)) {
      *mat = c->vtab[h];
      return HR_OK;
    }
  }
  if (hr_scene_add_variant(c->s, base, rho, mat) != HR_OK)
    return hr_err_set(c->err, HR_ERR_NOMEM, "%s: out of memory", c->path);
  c->vtab[h] = *mat;
  c->nvariants++;
  return HR_OK;
}

/* The material of one face: the mesh's, or a variant with the texture's mean. */
static hr_status face_material(imp_ctx *c, const struct aiMesh *mesh, unsigned n, int *mat) {
  unsigned mi = mesh->mMaterialIndex;
  *mat = c->mat_of[mi];
  int slot = c->tex_of[mi];
  if (slot < 0 || !mesh->mTextureCoords[c->uv_of[mi]] || !tex_ready(c, slot)) return HR_OK;
  double m[3], rho[3];
  hr_texture_mean_poly(&c->tex[slot].tex, c->poly, (const double(*)[2])c->uv, (int)n, m);
  for (int ch = 0; ch < 3; ch++) {
    rho[ch] = c->s->mats[*mat].rho[ch] * m[ch];
    rho[ch] = rho[ch] < 0 ? 0 : rho[ch] > 1 ? 1 : (double)(float)rho[ch];
  }
  return variant_of(c, *mat, rho, mat);
}

/* Adds face 'f' of 'mesh' under world transform 't' ('flip': reverse the order). */
static hr_status add_face(imp_ctx *c, const struct aiMesh *mesh, const struct aiFace *f,
                          const struct aiMatrix4x4 *t, int flip, const char *obj) {
  unsigned n = f->mNumIndices;
  if (n < 3) {
    c->nskipped++;
    return HR_OK;
  }
  if (n > c->cap_poly) {
    hr_vec3 *p = realloc(c->poly, n * sizeof *p);
    if (p) c->poly = p;
    double(*uv)[2] = realloc(c->uv, n * sizeof *uv);
    if (uv) c->uv = uv;
    if (!p || !uv) return hr_err_set(c->err, HR_ERR_NOMEM, "%s: out of memory", c->path);
    c->cap_poly = n;
  }
  const struct aiVector3D *tc = mesh->mTextureCoords[c->uv_of[mesh->mMaterialIndex]];
  for (unsigned k = 0; k < n; k++) {
    unsigned v = f->mIndices[flip ? n - 1 - k : k];
    if (v >= mesh->mNumVertices)
      return hr_err_set(c->err, HR_ERR_PARSE, "%s: object '%s': vertex index %u out of range",
                        c->path, obj, v);
    c->poly[k] = xform(t, mesh->mVertices[v]);
    if (!(fabs(c->poly[k].x) <= HR_COORD_MAX && fabs(c->poly[k].y) <= HR_COORD_MAX &&
          fabs(c->poly[k].z) <= HR_COORD_MAX))
      return hr_err_set(c->err, HR_ERR_PARSE,
                        "%s: object '%s': coordinate out of range (magnitude at most %g)",
                        c->path, obj, HR_COORD_MAX);
    c->uv[k][0] = tc ? tc[v].x : 0;
    c->uv[k][1] = tc ? tc[v].y : 0;
  }
  int mat;
  hr_status st = face_material(c, mesh, n, &mat);
  hr_poly_result res;
  if (st == HR_OK) st = hr_scene_add_polygon(c->s, c->poly, (int)n, mat, &res);
  if (st == HR_ERR_NOMEM) return hr_err_set(c->err, st, "%s: out of memory", c->path);
  if (st != HR_OK) return hr_err_set(c->err, st, "%s: object '%s': bad polygon", c->path, obj);
  if (res == HR_POLY_DEGENERATE) c->ndegen++;
  if (res == HR_POLY_NONPLANAR || res == HR_POLY_NOT_SIMPLE)
    return hr_err_set(c->err, HR_ERR_PARSE, "%s: object '%s': a polygon of %u vertices is %s",
                      c->path, obj, n, res == HR_POLY_NONPLANAR ? "not planar"
                                                                : "not simple (it crosses itself)");
  return HR_OK;
}

/* The object name of 'node' (see the file comment). */
static void object_name(imp_ctx *c, const struct aiNode *node, char *out, size_t n) {
  clean_name(&node->mName, out, n);
  if (!out[0] && node->mNumMeshes > 0)
    clean_name(&c->ai->mMeshes[node->mMeshes[0]]->mName, out, n);
  if (!out[0]) snprintf(out, n, "object %d", c->objects_made);
}

static hr_status add_node(imp_ctx *c, const struct aiNode *node, struct aiMatrix4x4 parent,
                          int depth) {
  if (depth > 1000)
    return hr_err_set(c->err, HR_ERR_PARSE, "%s: scene graph deeper than 1000 nodes", c->path);
  struct aiMatrix4x4 t = parent;
  aiMultiplyMatrix4(&t, &node->mTransformation); /* t = parent * node */
  if (node->mNumMeshes > 0) {
    char obj[NAME_MAX_LEN + 1];
    object_name(c, node, obj, sizeof obj);
    c->objects_made++;
    if (hr_scene_begin_object(c->s, obj) != HR_OK)
      return hr_err_set(c->err, HR_ERR_NOMEM, "%s: out of memory", c->path);
    int flip = det3(&t) < 0;
    for (unsigned i = 0; i < node->mNumMeshes; i++) {
      if (node->mMeshes[i] >= c->ai->mNumMeshes)
        return hr_err_set(c->err, HR_ERR_PARSE, "%s: node '%s': bad mesh index", c->path, obj);
      const struct aiMesh *mesh = c->ai->mMeshes[node->mMeshes[i]];
      if (mesh->mMaterialIndex >= c->ai->mNumMaterials)
        return hr_err_set(c->err, HR_ERR_PARSE, "%s: mesh of '%s': bad material", c->path, obj);
      for (unsigned f = 0; f < mesh->mNumFaces; f++) {
        hr_status st = add_face(c, mesh, &mesh->mFaces[f], &t, flip, obj);
        if (st != HR_OK) return st;
      }
    }
  }
  for (unsigned i = 0; i < node->mNumChildren; i++) {
    hr_status st = add_node(c, node->mChildren[i], t, depth + 1);
    if (st != HR_OK) return st;
  }
  return HR_OK;
}

static hr_status build(imp_ctx *c) {
  hr_status st = add_materials(c);
  if (st != HR_OK) return st;
  struct aiMatrix4x4 id;
  memset(&id, 0, sizeof id);
  id.a1 = id.b2 = id.c3 = id.d4 = 1;
  if (!c->ai->mRootNode) return hr_err_set(c->err, HR_ERR_PARSE, "%s: no scene graph", c->path);
  st = add_node(c, c->ai->mRootNode, id, 0);
  if (st != HR_OK) return st;
  if (c->ndegen)
    hr_log_warn(c->log, "%s: %ld degenerate polygon%s skipped", c->path, c->ndegen,
                c->ndegen > 1 ? "s" : "");
  if (c->nskipped)
    hr_log_warn(c->log, "%s: %ld point%s and line%s skipped", c->path, c->nskipped,
                c->nskipped > 1 ? "s" : "", c->nskipped > 1 ? "s" : "");
  if (c->s->npolys == 0) return hr_err_set(c->err, HR_ERR_PARSE, "%s: no polygons", c->path);
  return HR_OK;
}

/* ---------------------------------------------------------------- entry points */

/* Checks that 'path' is a readable regular file (assimp would read a FIFO forever). */
static hr_status check_file(const char *path, hr_err *err) {
  struct stat sb;
  if (stat(path, &sb) != 0)
    return hr_err_set(err, HR_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
  if (!S_ISREG(sb.st_mode)) return hr_err_set(err, HR_ERR_IO, "%s: not a regular file", path);
  if (access(path, R_OK) != 0)
    return hr_err_set(err, HR_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
  if (sb.st_size == 0) return hr_err_set(err, HR_ERR_PARSE, "%s: empty file", path);
  char ext[16];
  ext_of(path, ext, sizeof ext);
  return check_format(path, ext, (long long)sb.st_size, err);
}

hr_status hr_scene_import(const char *path, const hr_log *log, hr_scene **out, hr_err *err) {
  if (!out) return hr_err_set(err, HR_ERR_INVALID, "hr_scene_import: no output pointer");
  *out = NULL;
  if (!path) return hr_err_set(err, HR_ERR_INVALID, "hr_scene_import: no path");
  hr_status st = check_file(path, err);
  if (st != HR_OK) return st;
  imp_ctx c;
  memset(&c, 0, sizeof c);
  c.path = path;
  c.log = log;
  c.err = err;
  char *name = hr_scene_name_of(path);
  if (!name || hr_scene_create(name, &c.s) != HR_OK) {
    free(name);
    return hr_err_set(err, HR_ERR_NOMEM, "%s: out of memory", path);
  }
  free(name);
  pthread_mutex_lock(&g_ai_lock);
  c.ai = aiImportFile(path, aiProcess_JoinIdenticalVertices | aiProcess_TransformUVCoords |
                                aiProcess_ValidateDataStructure);
  if (!c.ai) {
    char msg[400];
    one_line(aiGetErrorString(), msg, sizeof msg);
    st = hr_err_set(err, HR_ERR_PARSE, "%s: %s", path, msg);
  }
  pthread_mutex_unlock(&g_ai_lock);
  if (st == HR_OK) st = build(&c);
  if (c.ai) aiReleaseImport(c.ai);
  for (int i = 0; i < c.ntex; i++) {
    free(c.tex[i].key);
    hr_texture_free(&c.tex[i].tex);
  }
  free(c.tex);
  free(c.mat_of);
  free(c.tex_of);
  free(c.uv_of);
  free(c.strength);
  free(c.vtab);
  free(c.poly);
  free(c.uv);
  if (st != HR_OK) {
    hr_scene_destroy(&c.s);
    return st;
  }
  *out = c.s;
  return HR_OK;
}

hr_status hr_scene_load(const char *path, const hr_log *log, hr_scene **out, hr_err *err) {
  if (!out) return hr_err_set(err, HR_ERR_INVALID, "hr_scene_load: no output pointer");
  *out = NULL;
  if (!path) return hr_err_set(err, HR_ERR_INVALID, "hr_scene_load: no path");
  char ext[16];
  ext_of(path, ext, sizeof ext);
  if (!strcmp(ext, "obj") || !ext[0]) return hr_scene_load_obj(path, log, out, err);
  if (is_import_ext(ext)) return hr_scene_import(path, log, out, err);
  return hr_err_set(err, HR_ERR_INVALID,
                    "%s: unknown scene format '.%s' (known: .obj .gltf .glb .ply .3ds .fbx .dae "
                    ".stl; no extension: .obj)",
                    path, ext);
}
