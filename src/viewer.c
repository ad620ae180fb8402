/* viewer.c: writes viewer.html, a self-contained three.js page showing the .glb with orbit
 * controls. Everything is inside the page (works from file:// with no network or server):
 * three.js, OrbitControls, GLTFLoader and BufferGeometryUtils are embedded base64-encoded;
 * at load time a small classic script turns them into blob: module URLs (rewriting their
 * 'three' and relative imports to those URLs) and imports them; the .glb is embedded
 * base64-encoded as well and handed to GLTFLoader.parse (fetch() of file:// is blocked).
 * The three.js files come from the copy embedded at build time (cmake/viewer_assets.cmake,
 * hr_viewer_assets), so an installed or copied binary needs no source tree; $HRAD_THREE_DIR, when
 * set, names a node_modules/three directory to read them from instead. */
#include "output.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

const char *hr_viewer_three_dir(void) {
  const char *e = getenv("HRAD_THREE_DIR");
  return e && *e ? e : NULL;
}

/* The embedded file 'name' (relative to the three directory), or NULL. */
static const hr_asset *find_asset(const char *name) {
  for (int i = 0; i < hr_viewer_nassets; i++)
    if (!strcmp(hr_viewer_assets[i].name, name)) return &hr_viewer_assets[i];
  return NULL;
}

/* Reads a whole file; NULL when it cannot. */
static unsigned char *read_all(const char *path, size_t *len) {
  FILE *fp = fopen(path, "rb");
  if (!fp) return NULL;
  size_t cap = 1 << 16, n = 0;
  unsigned char *b = malloc(cap);
  while (b) {
    size_t k = fread(b + n, 1, cap - n, fp);
    n += k;
    if (n < cap) {
      if (ferror(fp)) {
        free(b);
        b = NULL;
      }
      break;
    }
    unsigned char *q = realloc(b, cap * 2);
    if (!q) {
      free(b);
      b = NULL;
      break;
    }
    b = q;
    cap *= 2;
  }
  fclose(fp);
  if (b) *len = n;
  return b;
}

static int put_b64(FILE *fp, const unsigned char *d, size_t n) {
  static const char T[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  char buf[4096];
  size_t k = 0;
  for (size_t i = 0; i < n; i += 3) {
    uint32_t v = (uint32_t)d[i] << 16;
    if (i + 1 < n) v |= (uint32_t)d[i + 1] << 8;
    if (i + 2 < n) v |= d[i + 2];
    buf[k++] = T[(v >> 18) & 63];
    buf[k++] = T[(v >> 12) & 63];
    buf[k++] = i + 1 < n ? T[(v >> 6) & 63] : '=';
    buf[k++] = i + 2 < n ? T[v & 63] : '=';
    if (k + 4 > sizeof buf) {
      if (fwrite(buf, 1, k, fp) != k) return 0;
      k = 0;
    }
  }
  return fwrite(buf, 1, k, fp) == k;
}

/* Writes 's' for an HTML text/comment context: only '<', '>' and '&' escaped, and "--"
 * broken up so that it cannot end a comment. */
static void put_html_text(FILE *fp, const unsigned char *s, size_t n) {
  for (size_t i = 0; i < n; i++) {
    unsigned char c = s[i];
    if (c == '<')
      fputs("&lt;", fp);
    else if (c == '>')
      fputs("&gt;", fp);
    else if (c == '&')
      fputs("&amp;", fp);
    else if (c == '-' && i + 1 < n && s[i + 1] == '-')
      fputs("- ", fp);
    else
      fputc(c, fp);
  }
}

/* Module sources embedded in the page, in dependency order. */
typedef struct modsrc {
  const char *key;    /* name in the page */
  const char *rel[2]; /* candidates relative to the three directory */
  const char *spec;   /* import specifier others use for it ("" = none) */
} modsrc;

static const modsrc MODS[] = {
    {"three", {"build/three.module.min.js", "build/three.module.js"}, "three"},
    {"bgu", {"examples/jsm/utils/BufferGeometryUtils.js", NULL}, "../utils/BufferGeometryUtils.js"},
    {"orbit", {"examples/jsm/controls/OrbitControls.js", NULL}, ""},
    {"gltf", {"examples/jsm/loaders/GLTFLoader.js", NULL}, ""},
};
#define NMODS (int)(sizeof MODS / sizeof MODS[0])

static const char PAGE_HEAD[] =
    "<!DOCTYPE html>\n"
    "<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
    "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
    "<title>hrad viewer</title>\n"
    "<style>\n"
    "html, body { margin: 0; height: 100%; overflow: hidden; background: #1e1e24; color: #c8c8d0;"
    " font: 13px/1.4 sans-serif; }\n"
    "canvas { display: block; }\n"
    "#info { position: absolute; left: 8px; bottom: 6px; pointer-events: none;"
    " text-shadow: 0 0 3px #000; }\n"
    "</style>\n</head>\n<body>\n"
    "<div id=\"info\">loading&hellip;</div>\n"
    "<div id=\"status\" data-state=\"loading\" hidden></div>\n";

static const char PAGE_SCRIPT[] =
    "<script>\n"
    "(async function () {\n"
    "  'use strict';\n"
    "  const info = document.getElementById('info');\n"
    "  const status = document.getElementById('status');\n"
    "  function setState(state, text) { status.dataset.state = state; status.textContent = text;"
    " info.textContent = text; }\n"
    "  function bytes(b64) { const s = atob(b64); const u = new Uint8Array(s.length);"
    " for (let i = 0; i < s.length; i++) u[i] = s.charCodeAt(i); return u; }\n"
    "  const dec = new TextDecoder();\n"
    "  try {\n"
    "    const specs = {}, urls = {};\n"
    "    for (const m of HRAD_MODULES) {\n"
    "      let text = dec.decode(bytes(m.src));\n"
    "      if (m.key !== 'three')\n"
    "        text = text.replace(/(\\bfrom\\s*)(['\"])([^'\"\\n]+)\\2/g,\n"
    "          (all, f, q, spec) => (spec in specs) ? f + q + specs[spec] + q : all);\n"
    "      urls[m.key] = URL.createObjectURL(new Blob([text], { type: 'text/javascript' }));\n"
    "      if (m.spec) specs[m.spec] = urls[m.key];\n"
    "    }\n"
    "    const THREE = await import(urls.three);\n"
    "    const { OrbitControls } = await import(urls.orbit);\n"
    "    const { GLTFLoader } = await import(urls.gltf);\n"
    "    const glb = bytes(HRAD_GLB);\n"
    "    const gltf = await new Promise((ok, bad) =>\n"
    "      new GLTFLoader().parse(glb.buffer, '', ok, bad));\n"
    "    const renderer = new THREE.WebGLRenderer({ antialias: true });\n"
    "    renderer.setPixelRatio(window.devicePixelRatio);\n"
    "    renderer.setSize(window.innerWidth, window.innerHeight);\n"
    "    renderer.setClearColor(0x1e1e24);\n"
    "    document.body.appendChild(renderer.domElement);\n"
    "    const scene = new THREE.Scene();\n"
    "    scene.add(gltf.scene);\n"
    "    const box = new THREE.Box3().setFromObject(gltf.scene);\n"
    "    const centre = box.getCenter(new THREE.Vector3());\n"
    "    const radius = Math.max(box.getSize(new THREE.Vector3()).length() / 2, 1e-6);\n"
    "    const camera = new THREE.PerspectiveCamera(50, window.innerWidth / window.innerHeight,\n"
    "      radius / 1000, radius * 100);\n"
    "    const dir = new THREE.Vector3(0.55, 0.45, 1).normalize();\n"
    "    camera.position.copy(centre).addScaledVector(dir,\n"
    "      1.05 * radius / Math.tan(THREE.MathUtils.degToRad(25)));\n"
    "    camera.lookAt(centre);\n"
    "    const controls = new OrbitControls(camera, renderer.domElement);\n"
    "    controls.target.copy(centre);\n"
    "    controls.enableDamping = true;\n"
    "    controls.update();\n"
    "    window.addEventListener('resize', () => {\n"
    "      camera.aspect = window.innerWidth / window.innerHeight;\n"
    "      camera.updateProjectionMatrix();\n"
    "      renderer.setSize(window.innerWidth, window.innerHeight);\n"
    "    });\n"
    "    let ntri = 0;\n"
    "    gltf.scene.traverse(o => { if (o.isMesh) ntri += (o.geometry.index ?"
    " o.geometry.index.count : o.geometry.attributes.position.count) / 3; });\n"
    "    const ex = (gltf.parser.json.asset.extras || {}).exposure;\n"
    "    let first = true;\n"
    "    renderer.setAnimationLoop(() => {\n"
    "      controls.update();\n"
    "      renderer.render(scene, camera);\n"
    "      if (first) {\n"
    "        first = false;\n"
    "        setState('ok', HRAD_NAME + ': ' + ntri + ' triangles' +\n"
    "          (ex !== undefined ? ', exposure ' + Number(ex).toPrecision(4) : '') +\n"
    "          ' \\u2014 drag to orbit, wheel to zoom, right-drag to pan');\n"
    "      }\n"
    "    });\n"
    "  } catch (e) {\n"
    "    setState('error', 'hrad viewer: ' + (e && e.message ? e.message : e));\n"
    "  }\n"
    "})();\n"
    "</script>\n"
    "</body>\n</html>\n";

/* Writes 's' as a JavaScript string literal body (for the file name). */
static void put_js_string(FILE *fp, const char *s) {
  fputc('"', fp);
  for (; *s; s++) {
    unsigned char c = (unsigned char)*s;
    if (c == '"' || c == '\\')
      fprintf(fp, "\\%c", c);
    else if (c == '<')
      fputs("\\x3c", fp);
    else if (c < 0x20)
      fprintf(fp, "\\x%02x", c);
    else
      fputc(c, fp);
  }
  fputc('"', fp);
}

/* Finds module 'm': in directory 'three' when it is not NULL (the bytes read are also returned
 * through 'owned', for the caller to free), else in the embedded copy. HR_ERR_IO naming the
 * path when it is missing. */
static hr_status module_source(const char *three, const modsrc *m, const unsigned char **src,
                               size_t *len, unsigned char **owned, hr_err *err) {
  char p[4096];
  if (!three) {
    const hr_asset *a = find_asset(m->rel[0]);
    if (a) {
      *src = a->data, *len = a->len;
      return HR_OK;
    }
    return hr_err_set(err, HR_ERR_IO,
                      "%s: three.js was not embedded when hrad was built (run scripts/setup.sh "
                      "and rebuild, or set HRAD_THREE_DIR to a node_modules/three directory)",
                      m->rel[0]);
  }
  for (int c = 0; c < 2 && !*owned && m->rel[c]; c++) {
    snprintf(p, sizeof p, "%s/%s", three, m->rel[c]);
    *owned = read_all(p, len);
  }
  if (*owned) {
    *src = *owned;
    return HR_OK;
  }
  snprintf(p, sizeof p, "%s/%s", three, m->rel[0]);
  return hr_err_set(err, HR_ERR_IO,
                    "%s: three.js not found (set HRAD_THREE_DIR to a node_modules/three "
                    "directory, or unset it to use the copy built in)",
                    p);
}

/* three.js's licence, from the directory 'three' or the embedded copy; stays NULL if missing. */
static void module_license(const char *three, const unsigned char **lic, size_t *len,
                           unsigned char **owned) {
  if (three) {
    char p[4096];
    snprintf(p, sizeof p, "%s/LICENSE", three);
    *lic = *owned = read_all(p, len);
  } else {
    const hr_asset *a = find_asset("LICENSE");
    if (a) *lic = a->data, *len = a->len;
  }
}

int hr_viewer_available(void) {
  const char *three = hr_viewer_three_dir();
  hr_status st = HR_OK;
  for (int i = 0; i < NMODS && st == HR_OK; i++) {
    const unsigned char *src = NULL;
    unsigned char *owned = NULL;
    size_t len = 0;
    st = module_source(three, &MODS[i], &src, &len, &owned, NULL);
    free(owned);
  }
  return st == HR_OK;
}

hr_status hr_viewer_write(const char *path, const char *glb_name, hr_err *err) {
  if (!path || !glb_name || !*glb_name)
    return hr_err_set(err, HR_ERR_INVALID, "hr_viewer_write: no path or glb name");
  const char *three = hr_viewer_three_dir();
  /* the .glb: relative to the page's directory unless absolute */
  char glb_path[4096];
  if (glb_name[0] == '/') {
    snprintf(glb_path, sizeof glb_path, "%s", glb_name);
  } else {
    const char *slash = strrchr(path, '/');
    if (slash)
      snprintf(glb_path, sizeof glb_path, "%.*s/%s", (int)(slash - path), path, glb_name);
    else
      snprintf(glb_path, sizeof glb_path, "%s", glb_name);
  }
  const unsigned char *src[NMODS] = {0}, *lic = NULL;
  size_t srclen[NMODS] = {0}, liclen = 0, glblen = 0;
  unsigned char *owned[NMODS + 1] = {0}, *glb = NULL; /* what was read from files */
  hr_status st = HR_OK;
  for (int i = 0; i < NMODS && st == HR_OK; i++)
    st = module_source(three, &MODS[i], &src[i], &srclen[i], &owned[i], err);
  if (st == HR_OK) {
    module_license(three, &lic, &liclen, &owned[NMODS]); /* optional */
    glb = read_all(glb_path, &glblen);
    if (!glb) st = hr_err_set(err, HR_ERR_IO, "%s: cannot read the .glb to embed", glb_path);
  }
  FILE *fp = NULL;
  if (st == HR_OK) {
    fp = fopen(path, "wb");
    if (!fp)
      st = hr_err_set(err, HR_ERR_IO, "%s: cannot open for writing: %s", path, strerror(errno));
  }
  if (st == HR_OK) {
    /* Every write below is checked through the stream's error flag, the flush and the close; a
     * failed page is removed rather than left half written. */
    int ok = fputs(PAGE_HEAD, fp) >= 0, e = ok ? 0 : errno;
    fputs("<!--\nWritten by hrad. Embedded below (base64): three.js", fp);
    fputs(", OrbitControls, GLTFLoader and BufferGeometryUtils from the three.js distribution"
          " (MIT licence, reproduced here), and the model '",
          fp);
    put_html_text(fp, (const unsigned char *)glb_name, strlen(glb_name));
    fputs("'.\n\n", fp);
    if (lic) put_html_text(fp, lic, liclen);
    fputs("\n-->\n<script>\nconst HRAD_NAME = ", fp);
    const char *base = strrchr(glb_name, '/');
    put_js_string(fp, base ? base + 1 : glb_name);
    fputs(";\nconst HRAD_MODULES = [\n", fp);
    for (int i = 0; i < NMODS && ok; i++) {
      fprintf(fp, "{ key: \"%s\", spec: \"%s\", src: \"", MODS[i].key, MODS[i].spec);
      ok = put_b64(fp, src[i], srclen[i]);
      fputs("\" },\n", fp);
    }
    fputs("];\nconst HRAD_GLB = \"", fp);
    if (ok) ok = put_b64(fp, glb, glblen);
    fputs("\";\n</script>\n", fp);
    if (ok) ok = fputs(PAGE_SCRIPT, fp) >= 0;
    if (!ok && !e) e = errno;
    st = hr_file_close(fp, path, ok, e, err);
  }
  for (int i = 0; i <= NMODS; i++) free(owned[i]);
  free(glb);
  return st;
}
