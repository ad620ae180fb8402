/* texture.c: decoding diffuse textures (PNG through libpng's simplified API, JPEG through
 * libjpeg) into linear RGB, and their mean over a triangle of texture coordinates. See texture.h.
 * libjpeg reports errors through a callback that must not return; the only setjmp/longjmp of
 * the project lives in jpeg_decode, around that library's calls. */
#include "texture.h"

#include <dirent.h>
#include <errno.h>
#include <math.h>
#include <png.h>
#include <setjmp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

/* jpeglib.h needs FILE and size_t declared first */
#include <jpeglib.h>

double hr_srgb_to_linear(unsigned v) {
  double c = (v > 255 ? 255 : v) / 255.0;
  return c <= 0.04045 ? c / 12.92 : pow((c + 0.055) / 1.055, 2.4);
}

void hr_texture_free(hr_texture *t) {
  if (!t) return;
  free(t->rgb);
  memset(t, 0, sizeof *t);
}

/* Allocates t->rgb for w x h pixels after checking the size. */
static hr_status tex_alloc(hr_texture *t, int w, int h, const char *name, hr_err *err) {
  if (w <= 0 || h <= 0 || w > HR_TEX_MAX_SIDE || h > HR_TEX_MAX_SIDE)
    return hr_err_set(err, HR_ERR_TOO_BIG, "%s: texture of %dx%d pixels (each side 1..%d)", name,
                      w, h, HR_TEX_MAX_SIDE);
  t->rgb = malloc((size_t)w * (size_t)h * 3 * sizeof *t->rgb);
  if (!t->rgb) return hr_err_set(err, HR_ERR_NOMEM, "%s: out of memory", name);
  t->w = w;
  t->h = h;
  return HR_OK;
}

/* Converts 8-bit sRGB pixels with 'nc' channels (the first three are RGB; 1: grey) to linear. */
static void tex_fill(hr_texture *t, const unsigned char *px, int nc) {
  float lut[256];
  for (int i = 0; i < 256; i++) lut[i] = (float)hr_srgb_to_linear((unsigned)i);
  size_t n = (size_t)t->w * (size_t)t->h;
  for (size_t i = 0; i < n; i++)
    for (int c = 0; c < 3; c++) t->rgb[3 * i + c] = lut[px[nc * i + (nc >= 3 ? c : 0)]];
}

hr_status hr_texture_from_rgba8(const unsigned char *rgba, int w, int h, hr_texture *t,
                                hr_err *err) {
  memset(t, 0, sizeof *t);
  hr_status st = tex_alloc(t, w, h, "embedded texture", err);
  if (st == HR_OK) tex_fill(t, rgba, 4);
  return st;
}

static hr_status png_decode(const unsigned char *data, size_t len, const char *name,
                            hr_texture *t, hr_err *err) {
  png_image img;
  memset(&img, 0, sizeof img);
  img.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_memory(&img, data, len))
    return hr_err_set(err, HR_ERR_PARSE, "%s: bad PNG: %s", name, img.message);
  img.format = PNG_FORMAT_RGB;
  hr_status st = tex_alloc(t, (int)img.width, (int)img.height, name, err);
  unsigned char *px = st == HR_OK ? malloc((size_t)PNG_IMAGE_SIZE(img)) : NULL;
  if (st == HR_OK && !px) st = hr_err_set(err, HR_ERR_NOMEM, "%s: out of memory", name);
  if (st == HR_OK && !png_image_finish_read(&img, NULL, px, 0, NULL))
    st = hr_err_set(err, HR_ERR_PARSE, "%s: bad PNG: %s", name, img.message);
  if (st == HR_OK) tex_fill(t, px, 3);
  png_image_free(&img);
  free(px);
  if (st != HR_OK) hr_texture_free(t);
  return st;
}

typedef struct jerr {
  struct jpeg_error_mgr mgr;
  jmp_buf jb;
  char msg[JMSG_LENGTH_MAX];
} jerr;

static void jpeg_fail(j_common_ptr ci) {
  jerr *e = (jerr *)ci->err;
  (*ci->err->format_message)(ci, e->msg);
  longjmp(e->jb, 1);
}

static void jpeg_quiet(j_common_ptr ci, int level) { (void)ci, (void)level; }

/* The decoder's state lives in 'ci' and 'px' (static storage duration not needed: both are only
 * read after longjmp through the pointers passed in). */
static int jpeg_run(struct jpeg_decompress_struct *ci, jerr *je, const unsigned char *data,
                    size_t len, unsigned char **px, int *w, int *h) {
  if (setjmp(je->jb)) return 0;
  jpeg_create_decompress(ci);
  jpeg_mem_src(ci, data, (unsigned long)len);
  jpeg_read_header(ci, TRUE);
  ci->out_color_space = JCS_RGB;
  jpeg_start_decompress(ci);
  *w = (int)ci->output_width;
  *h = (int)ci->output_height;
  if (*w > HR_TEX_MAX_SIDE || *h > HR_TEX_MAX_SIDE) {
    snprintf(je->msg, sizeof je->msg, "texture of %dx%d pixels (each side 1..%d)", *w, *h,
             HR_TEX_MAX_SIDE);
    return 0;
  }
  *px = malloc((size_t)*w * (size_t)*h * 3);
  if (!*px) {
    snprintf(je->msg, sizeof je->msg, "out of memory");
    return 0;
  }
  while (ci->output_scanline < ci->output_height) {
    JSAMPROW row = *px + (size_t)ci->output_scanline * (size_t)*w * 3;
    jpeg_read_scanlines(ci, &row, 1);
  }
  jpeg_finish_decompress(ci);
  return 1;
}

static hr_status jpeg_decode(const unsigned char *data, size_t len, const char *name,
                             hr_texture *t, hr_err *err) {
  struct jpeg_decompress_struct ci;
  jerr je;
  memset(&ci, 0, sizeof ci);
  memset(&je, 0, sizeof je);
  ci.err = jpeg_std_error(&je.mgr);
  je.mgr.error_exit = jpeg_fail;
  je.mgr.emit_message = jpeg_quiet;
  unsigned char *px = NULL;
  int w = 0, h = 0;
  int ok = jpeg_run(&ci, &je, data, len, &px, &w, &h);
  jpeg_destroy_decompress(&ci);
  hr_status st = ok ? tex_alloc(t, w, h, name, err)
                    : hr_err_set(err, HR_ERR_PARSE, "%s: bad JPEG: %s", name, je.msg);
  if (st == HR_OK) tex_fill(t, px, 3);
  free(px);
  return st;
}

hr_status hr_texture_decode(const unsigned char *data, size_t len, const char *name,
                            hr_texture *t, hr_err *err) {
  memset(t, 0, sizeof *t);
  if (len >= 8 && !memcmp(data, "\x89PNG\r\n\x1a\n", 8)) return png_decode(data, len, name, t, err);
  if (len >= 3 && data[0] == 0xff && data[1] == 0xd8 && data[2] == 0xff)
    return jpeg_decode(data, len, name, t, err);
  return hr_err_set(err, HR_ERR_PARSE, "%s: not a PNG or JPEG image", name);
}

hr_status hr_texture_load(const char *path, hr_texture *t, hr_err *err) {
  memset(t, 0, sizeof *t);
  struct stat sb;
  if (stat(path, &sb) == 0 && !S_ISREG(sb.st_mode)) /* a FIFO would block */
    return hr_err_set(err, HR_ERR_IO, "%s: not a regular file", path);
  FILE *fp = fopen(path, "rb");
  if (!fp) return hr_err_set(err, HR_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
  unsigned char *buf = NULL;
  size_t n = 0, cap = 0;
  hr_status st = HR_OK;
  for (;;) {
    if (n == cap) {
      size_t nc = cap ? 2 * cap : 1 << 16;
      unsigned char *q = nc <= ((size_t)1 << 31) ? realloc(buf, nc) : NULL;
      if (!q) {
        st = hr_err_set(err, HR_ERR_NOMEM, "%s: out of memory", path);
        break;
      }
      buf = q;
      cap = nc;
    }
    size_t k = fread(buf + n, 1, cap - n, fp);
    n += k;
    if (k == 0) break;
  }
  if (st == HR_OK && ferror(fp))
    st = hr_err_set(err, HR_ERR_IO, "%s: cannot read: %s", path, strerror(errno));
  fclose(fp);
  if (st == HR_OK) st = hr_texture_decode(buf, n, path, t, err);
  free(buf);
  return st;
}

/* Nearest texel to (u, v), the texture repeating. */
static const float *texel(const hr_texture *t, double u, double v) {
  double x = (u - floor(u)) * t->w, y = (1 - (v - floor(v))) * t->h;
  int ix = (int)x, iy = (int)y;
  if (ix >= t->w) ix = t->w - 1;
  if (iy >= t->h) iy = t->h - 1;
  if (ix < 0) ix = 0;
  if (iy < 0) iy = 0;
  return &t->rgb[3 * ((size_t)iy * (size_t)t->w + (size_t)ix)];
}

void hr_texture_mean_tri(const hr_texture *t, const double uv[3][2], double out[3]) {
  out[0] = out[1] = out[2] = 0;
  double e1u = uv[1][0] - uv[0][0], e1v = uv[1][1] - uv[0][1];
  double e2u = uv[2][0] - uv[0][0], e2v = uv[2][1] - uv[0][1];
  double texels = 0.5 * fabs(e1u * e2v - e1v * e2u) * t->w * t->h;
  if (!isfinite(texels) || !isfinite(uv[0][0] + uv[0][1])) return;
  int k = texels > 1 ? (int)ceil(sqrt(texels)) : 1;
  if (k > 64) k = 64;
  double sum[3] = {0, 0, 0};
  int n = 0;
  /* sub-triangles pointing up have centroid (i + 1/3, j + 1/3) / k in the barycentric
   * coordinates of v1 and v2, those pointing down (i + 2/3, j + 2/3) / k */
  for (int i = 0; i < k; i++)
    for (int j = 0; i + j < k; j++)
      for (int down = 0; down < 2 && (down == 0 || i + j + 1 < k); down++) {
        double a = (i + (down ? 2.0 : 1.0) / 3) / k, b = (j + (down ? 2.0 : 1.0) / 3) / k;
        const float *px = texel(t, uv[0][0] + a * e1u + b * e2u, uv[0][1] + a * e1v + b * e2v);
        for (int c = 0; c < 3; c++) sum[c] += px[c];
        n++;
      }
  for (int c = 0; c < 3; c++) out[c] = sum[c] / n;
}

void hr_texture_mean_poly(const hr_texture *t, const hr_vec3 *p, const double (*uv)[2], int n,
                          double out[3]) {
  double sum[3] = {0, 0, 0}, wsum = 0, first[3] = {0, 0, 0};
  for (int i = 1; i + 1 < n; i++) {
    const double tri[3][2] = {{uv[0][0], uv[0][1]}, {uv[i][0], uv[i][1]},
                              {uv[i + 1][0], uv[i + 1][1]}};
    double m[3];
    hr_texture_mean_tri(t, tri, m);
    hr_vec3 a = p[0], b = p[i], d = p[i + 1];
    hr_vec3 e1 = {b.x - a.x, b.y - a.y, b.z - a.z}, e2 = {d.x - a.x, d.y - a.y, d.z - a.z};
    double w = sqrt(pow(e1.y * e2.z - e1.z * e2.y, 2) + pow(e1.z * e2.x - e1.x * e2.z, 2) +
                    pow(e1.x * e2.y - e1.y * e2.x, 2));
    if (i == 1) memcpy(first, m, sizeof first);
    for (int ch = 0; ch < 3; ch++) sum[ch] += w * m[ch];
    wsum += w;
  }
  for (int ch = 0; ch < 3; ch++) out[ch] = wsum > 0 ? sum[ch] / wsum : first[ch];
}

/* A file in directory 'dir' (ending in '/', or "" for the working directory) whose name equals
 * 'name' but for case: its path into 'out', which is left alone when there is none. */
static void find_nocase(const char *dir, const char *name, char *out, size_t n) {
  DIR *d = opendir(dir[0] ? dir : ".");
  if (!d) return;
  struct dirent *e;
  while ((e = readdir(d)))
    if (!strcasecmp(e->d_name, name)) {
      snprintf(out, n, "%s%s", dir, e->d_name);
      break;
    }
  closedir(d);
}

void hr_texture_resolve(const char *from, const char *name, char *out, size_t n) {
  char rel[4096], dir[4096];
  snprintf(rel, sizeof rel, "%s", name);
  for (char *p = rel; *p; p++)
    if (*p == '\\') *p = '/';
  snprintf(dir, sizeof dir, "%s", from);
  char *slash = strrchr(dir, '/');
  if (slash) slash[1] = '\0';
  else dir[0] = '\0';
  snprintf(out, n, "%s%s", rel[0] == '/' ? "" : dir, rel);
  struct stat sb;
  if (stat(out, &sb) == 0) return;
  const char *b = strrchr(rel, '/');
  b = b ? b + 1 : rel;
  snprintf(out, n, "%s%s", dir, b);
  if (stat(out, &sb) != 0) find_nocase(dir, b, out, n);
}
