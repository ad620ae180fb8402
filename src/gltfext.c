/* gltfext.c: KHR_materials_emissive_strength from a glTF's JSON (assimp 5.2.5, Debian 12's,
 * drops it, and a glTF lamp brighter than 1 needs it). A small JSON scanner that walks the
 * document, skipping every value but materials[i].extensions.KHR_materials_emissive_strength.
 * emissiveStrength; anything malformed leaves the strengths at 1 (assimp reports the error). */
#include "gltfext.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define JSON_MAX_BYTES (256u << 20) /* larger JSON chunks are not scanned */
#define JSON_MAX_DEPTH 64

typedef struct js {
  const char *p, *end;
} js;

/* 1 if 'c' is one of the characters of 'set' (never for NUL). */
static int in_set(char c, const char *set) { return c != '\0' && strchr(set, c) != NULL; }

static void ws(js *j) {
  while (j->p < j->end && (*j->p == ' ' || *j->p == '\t' || *j->p == '\n' || *j->p == '\r'))
    j->p++;
}

static int eat(js *j, char c) {
  ws(j);
  if (j->p < j->end && *j->p == c) {
    j->p++;
    return 1;
  }
  return 0;
}

/* Skips a string at j->p; 'key' non-NULL: returns 1 if it equals 'key' (no escapes in keys we
 * look for). -1 when malformed. */
static int string(js *j, const char *key) {
  ws(j);
  if (j->p >= j->end || *j->p != '"') return -1;
  const char *s = ++j->p;
  while (j->p < j->end && *j->p != '"') j->p += *j->p == '\\' && j->end - j->p > 1 ? 2 : 1;
  if (j->p >= j->end) return -1;
  int eq = key && (size_t)(j->p - s) == strlen(key) && !memcmp(s, key, strlen(key));
  j->p++;
  return eq;
}

static int skip(js *j, int depth);

/* Skips the members or elements of an object or array (after its opening bracket). */
static int skip_items(js *j, char close, int depth) {
  if (eat(j, close)) return 1;
  do {
    if (close == '}' && (string(j, NULL) < 0 || !eat(j, ':'))) return 0;
    if (!skip(j, depth + 1)) return 0;
  } while (eat(j, ','));
  return eat(j, close);
}

static int skip(js *j, int depth) {
  ws(j);
  if (j->p >= j->end || depth > JSON_MAX_DEPTH) return 0;
  if (*j->p == '"') return string(j, NULL) >= 0;
  if (eat(j, '{')) return skip_items(j, '}', depth);
  if (eat(j, '[')) return skip_items(j, ']', depth);
  const char *s = j->p;
  while (j->p < j->end && !in_set(*j->p, ",]} \t\r\n")) j->p++;
  return j->p > s;
}

/* In the object at j->p, finds member 'key' and leaves j->p at its value; 0 if absent. */
static int member(js *j, const char *key) {
  if (!eat(j, '{')) return 0;
  if (eat(j, '}')) return 0;
  do {
    int eq = string(j, key);
    if (eq < 0 || !eat(j, ':')) return 0;
    if (eq) return 1;
    if (!skip(j, 1)) return 0;
  } while (eat(j, ','));
  return 0;
}

/* The emissive strength of the material object at j->p (j is a copy), or 1. */
static double strength(js j) {
  if (!member(&j, "extensions") || !member(&j, "KHR_materials_emissive_strength") ||
      !member(&j, "emissiveStrength"))
    return 1;
  ws(&j);
  char num[64];
  size_t n = 0;
  while (j.p < j.end && n + 1 < sizeof num && in_set(*j.p, "0123456789+-.eE")) num[n++] = *j.p++;
  num[n] = '\0';
  char *e;
  double k = strtod(num, &e);
  return n > 0 && *e == '\0' && isfinite(k) && k >= 0 ? k : 1;
}

void hr_gltf_emissive_strength_json(const char *json, size_t len, double *k, unsigned n) {
  js j = {json, json + len};
  if (!member(&j, "materials") || !eat(&j, '[') || eat(&j, ']')) return;
  unsigned i = 0;
  do {
    ws(&j);
    if (i < n) k[i] = strength(j);
    i++;
    if (!skip(&j, 1)) return;
  } while (eat(&j, ','));
}

/* The JSON text of a .gltf (the whole file) or .glb (its first chunk); NULL when unreadable. */
static char *read_json(const char *path, size_t *len) {
  FILE *fp = fopen(path, "rb");
  if (!fp) return NULL;
  unsigned char h[20];
  size_t n = fread(h, 1, sizeof h, fp), off = 0, want = 0;
  if (n >= 20 && !memcmp(h, "glTF", 4) && !memcmp(h + 16, "JSON", 4)) {
    want = (size_t)h[12] | (size_t)h[13] << 8 | (size_t)h[14] << 16 | (size_t)h[15] << 24;
    off = 20;
  } else if (fseek(fp, 0, SEEK_END) == 0 && ftell(fp) > 0) {
    want = (size_t)ftell(fp);
  }
  char *buf = want > 0 && want <= JSON_MAX_BYTES ? malloc(want) : NULL;
  if (buf && (fseek(fp, (long)off, SEEK_SET) != 0 || fread(buf, 1, want, fp) != want)) {
    free(buf);
    buf = NULL;
  }
  fclose(fp);
  *len = want;
  return buf;
}

void hr_gltf_emissive_strength(const char *path, double *k, unsigned n) {
  for (unsigned i = 0; i < n; i++) k[i] = 1;
  size_t len;
  char *json = read_json(path, &len);
  if (!json) return;
  hr_gltf_emissive_strength_json(json, len, k, n);
  free(json);
}
