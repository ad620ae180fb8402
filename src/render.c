/* render.c: software rasteriser for the radiosity mesh, tone mapping, PNG and PFM writers.
 *
 * Pipeline: vertices go to clip space (camera looking along +w); each triangle is clipped in
 * homogeneous space against the near plane and a guard band (twice the view frustum's width, so
 * that clipped edges never show and fixed-point coordinates stay small), then snapped to 1/256
 * of a sample and rasterised with exact integer edge functions and a top-left fill rule
 * (watertight: shared edges cover every sample exactly once). Depth is 1/w, colours are
 * interpolated perspective-correctly (attribute/w). Samples lie on a ss x ss grid per pixel
 * (box filter). Triangles are binned into horizontal bands that are rasterised in parallel. */
#include "output.h"
#include "vec.h"

#include <errno.h>
#include <math.h>
#include <png.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ------------------------------------------------------------------ tone mapping */

double hr_tonemap(double v, double exposure) {
  double x = v * exposure;
  if (!(x > 0)) return 0; /* also NaN */
  if (x >= 1) return 1;
  return x <= 0.0031308 ? 12.92 * x : 1.055 * pow(x, 1.0 / 2.4) - 0.055;
}

uint8_t hr_tonemap8(double v, double exposure) {
  return (uint8_t)(hr_tonemap(v, exposure) * 255.0 + 0.5);
}

/* ------------------------------------------------------------------ rasteriser */

#define SUB_BITS 8
#define SUB (1 << SUB_BITS)
#define GUARD 2.0 /* clip |x|,|y| <= GUARD * w (NDC units) */
#define BAND 16   /* sample rows per band */

typedef struct cvert {
  double X, Y, W; /* clip space: NDC x = X/W, y = Y/W */
  float c[3];
} cvert;

typedef struct stri {
  int32_t x[3], y[3]; /* fixed point sample coordinates */
  float iw[3];        /* 1/w */
  float c[3][3];      /* colour * (1/w) */
  int32_t id;
  int32_t r0, r1; /* sample rows covered (inclusive) */
  int32_t c0, c1; /* sample columns covered (inclusive) */
} stri;

typedef struct raster {
  int W, H; /* samples */
  stri *t;
  int64_t nt, cap;
  int nomem;
} raster;

static inline int64_t floordiv(int64_t a, int64_t b) {
  int64_t q = a / b;
  if ((a % b != 0) && ((a < 0) != (b < 0))) q--;
  return q;
}

static void push_tri(raster *R, const cvert *v0, const cvert *v1, const cvert *v2, int32_t id) {
  const cvert *v[3] = {v0, v1, v2};
  stri t;
  for (int k = 0; k < 3; k++) {
    double iw = 1.0 / v[k]->W;
    double sx = (v[k]->X * iw + 1.0) * 0.5 * R->W;
    double sy = (1.0 - v[k]->Y * iw) * 0.5 * R->H;
    t.x[k] = (int32_t)llround(sx * SUB);
    t.y[k] = (int32_t)llround(sy * SUB);
    t.iw[k] = (float)iw;
    for (int c = 0; c < 3; c++) t.c[k][c] = (float)(v[k]->c[c] * iw);
  }
  int64_t area = (int64_t)(t.x[1] - t.x[0]) * (t.y[2] - t.y[0]) -
                 (int64_t)(t.y[1] - t.y[0]) * (t.x[2] - t.x[0]);
  if (area == 0) return;
  if (area < 0) { /* make the edge functions positive inside */
    int32_t a;
    float f;
    a = t.x[1], t.x[1] = t.x[2], t.x[2] = a;
    a = t.y[1], t.y[1] = t.y[2], t.y[2] = a;
    f = t.iw[1], t.iw[1] = t.iw[2], t.iw[2] = f;
    for (int c = 0; c < 3; c++) f = t.c[1][c], t.c[1][c] = t.c[2][c], t.c[2][c] = f;
  }
  int32_t xmin = t.x[0], xmax = t.x[0], ymin = t.y[0], ymax = t.y[0];
  for (int k = 1; k < 3; k++) {
    if (t.x[k] < xmin) xmin = t.x[k];
    if (t.x[k] > xmax) xmax = t.x[k];
    if (t.y[k] < ymin) ymin = t.y[k];
    if (t.y[k] > ymax) ymax = t.y[k];
  }
  /* sample i has its centre at i*SUB + SUB/2 */
  int64_t c0 = floordiv(xmin - SUB / 2 + SUB - 1, SUB), c1 = floordiv(xmax - SUB / 2, SUB);
  int64_t r0 = floordiv(ymin - SUB / 2 + SUB - 1, SUB), r1 = floordiv(ymax - SUB / 2, SUB);
  if (c0 < 0) c0 = 0;
  if (r0 < 0) r0 = 0;
  if (c1 > R->W - 1) c1 = R->W - 1;
  if (r1 > R->H - 1) r1 = R->H - 1;
  if (c0 > c1 || r0 > r1) return;
  t.c0 = (int32_t)c0;
  t.c1 = (int32_t)c1;
  t.r0 = (int32_t)r0;
  t.r1 = (int32_t)r1;
  t.id = id;
  if (R->nt == R->cap) {
    int64_t nc = R->cap ? 2 * R->cap : 4096;
    stri *q = realloc(R->t, (size_t)nc * sizeof *q);
    if (!q) {
      R->nomem = 1;
      return;
    }
    R->t = q;
    R->cap = nc;
  }
  R->t[R->nt++] = t;
}

/* Signed distances to the 5 clip planes (>= 0 inside). */
static inline double plane_dist(const cvert *v, int p, double near) {
  switch (p) {
  case 0: return v->W - near;
  case 1: return GUARD * v->W - v->X;
  case 2: return GUARD * v->W + v->X;
  case 3: return GUARD * v->W - v->Y;
  default: return GUARD * v->W + v->Y;
  }
}

static inline int outcode(const cvert *v, double near) {
  int o = 0;
  for (int p = 0; p < 5; p++)
    if (plane_dist(v, p, near) < 0) o |= 1 << p;
  return o;
}

static void clip_and_push(raster *R, const cvert *in, int32_t id, double near) {
  cvert a[9], b[9];
  int na = 3;
  memcpy(a, in, 3 * sizeof *a);
  for (int p = 0; p < 5 && na >= 3; p++) {
    int nb = 0;
    for (int i = 0; i < na; i++) {
      const cvert *P = &a[i], *Q = &a[(i + 1) % na];
      double dp = plane_dist(P, p, near), dq = plane_dist(Q, p, near);
      if (dp >= 0) b[nb++] = *P;
      if ((dp >= 0) != (dq >= 0)) {
        /* interpolate from the inside point so that shared edges clip identically */
        const cvert *I = dp >= 0 ? P : Q, *O = dp >= 0 ? Q : P;
        double di = dp >= 0 ? dp : dq, dout = dp >= 0 ? dq : dp;
        double t = di / (di - dout);
        cvert *r = &b[nb++];
        r->X = I->X + t * (O->X - I->X);
        r->Y = I->Y + t * (O->Y - I->Y);
        r->W = I->W + t * (O->W - I->W);
        for (int c = 0; c < 3; c++) r->c[c] = (float)(I->c[c] + t * (O->c[c] - I->c[c]));
      }
    }
    memcpy(a, b, (size_t)nb * sizeof *a);
    na = nb;
  }
  for (int i = 1; i + 1 < na; i++) push_tri(R, &a[0], &a[i], &a[i + 1], id);
}

static inline int topleft(int32_t xa, int32_t ya, int32_t xb, int32_t yb) {
  int32_t dy = yb - ya, dx = xb - xa;
  return dy < 0 || (dy == 0 && dx > 0);
}

/* Rasterises triangle t into rows [y0, y1) of the buffers. */
static void raster_tri(const stri *t, int W, int y0, int y1, float *zb, float *cb, int32_t *ib) {
  int r0 = t->r0 > y0 ? t->r0 : y0, r1 = t->r1 < y1 - 1 ? t->r1 : y1 - 1;
  if (r0 > r1) return;
  int64_t A[3], Bq[3], E[3], bias[3];
  int64_t px = (int64_t)t->c0 * SUB + SUB / 2, py = (int64_t)r0 * SUB + SUB / 2;
  for (int k = 0; k < 3; k++) {
    int a = (k + 1) % 3, b = (k + 2) % 3;
    int64_t dx = t->x[b] - t->x[a], dy = t->y[b] - t->y[a];
    A[k] = -dy * SUB;
    Bq[k] = dx * SUB;
    E[k] = dx * (py - t->y[a]) - dy * (px - t->x[a]);
    bias[k] = topleft(t->x[a], t->y[a], t->x[b], t->y[b]) ? 0 : -1;
  }
  int64_t area = (int64_t)(t->x[1] - t->x[0]) * (t->y[2] - t->y[0]) -
                 (int64_t)(t->y[1] - t->y[0]) * (t->x[2] - t->x[0]);
  float ia = (float)(1.0 / (double)area);
  for (int r = r0; r <= r1; r++) {
    int64_t e0 = E[0] + bias[0], e1 = E[1] + bias[1], e2 = E[2] + bias[2];
    size_t row = (size_t)r * (size_t)W;
    for (int c = t->c0; c <= t->c1; c++, e0 += A[0], e1 += A[1], e2 += A[2]) {
      if ((e0 | e1 | e2) < 0) continue;
      float l0 = (float)(e0 - bias[0]) * ia, l1 = (float)(e1 - bias[1]) * ia;
      float l2 = (float)(e2 - bias[2]) * ia;
      float iw = l0 * t->iw[0] + l1 * t->iw[1] + l2 * t->iw[2];
      size_t i = row + (size_t)c;
      if (!(iw > zb[i])) continue;
      zb[i] = iw;
      float w = 1.0f / iw;
      for (int ch = 0; ch < 3; ch++)
        cb[3 * i + ch] = (l0 * t->c[0][ch] + l1 * t->c[1][ch] + l2 * t->c[2][ch]) * w;
      if (ib) ib[i] = t->id;
    }
    for (int k = 0; k < 3; k++) E[k] += Bq[k];
  }
}

hr_status hr_render_ex(const hr_scene *s, const hr_mesh *m, const hr_leaf *leaves, int64_t n,
                       const hr_camera *cam, int w, int h, int elements_mode, int ss,
                       double sample_clamp, float *rgb) {
  if (!cam || !rgb || w < 1 || h < 1 || w > 16384 || h > 16384 || ss < 1 || ss > 4)
    return HR_ERR_INVALID;
  if (!(cam->fov_deg > 0 && cam->fov_deg < 180)) return HR_ERR_INVALID;
  if ((int64_t)w * h * ss * ss > ((int64_t)1 << 28)) return HR_ERR_TOO_BIG;
  hr_mesh *tmp = NULL;
  if (!m) {
    if (!s) return HR_ERR_INVALID;
    hr_status st = hr_mesh_build(s, leaves, n, &tmp);
    if (st != HR_OK) return st;
    m = tmp;
  }
  if (elements_mode) { /* the mesh must come from these leaves */
    int ok = m->ntris == 0 || (leaves && m->tri_leaf);
    for (int64_t t = 0; t < m->ntris && ok; t++) ok = m->tri_leaf[t] >= 0 && m->tri_leaf[t] < n;
    if (!ok) {
      hr_mesh_destroy(&tmp);
      return HR_ERR_INVALID;
    }
  }
  /* camera frame */
  hr_vec3 fwd = v3_sub(cam->at, cam->eye);
  if (!(v3_len(fwd) > 0)) {
    hr_mesh_destroy(&tmp);
    return HR_ERR_INVALID;
  }
  fwd = v3_norm(fwd);
  hr_vec3 right = v3_cross(fwd, cam->up);
  if (!(v3_len(right) > 1e-9 * v3_len(cam->up))) {
    right = v3_cross(fwd, fabs(fwd.y) < 0.9 ? v3(0, 1, 0) : v3(1, 0, 0));
  }
  right = v3_norm(right);
  hr_vec3 up = v3_cross(right, fwd);
  double fy = 1.0 / tan(0.5 * cam->fov_deg * M_PI / 180.0), fx = fy * h / (double)w;
  const int W = w * ss, H = h * ss;

  /* near plane relative to the scene's size and distance */
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (int64_t v = 0; v < m->nverts; v++)
    for (int c = 0; c < 3; c++) {
      double x = m->pos[3 * v + c];
      if (x < lo[c]) lo[c] = x;
      if (x > hi[c]) hi[c] = x;
    }
  double near = 1e-6;
  if (m->nverts > 0) {
    hr_vec3 L = v3(lo[0], lo[1], lo[2]), Hh = v3(hi[0], hi[1], hi[2]);
    double diag = v3_len(v3_sub(Hh, L));
    double dist = v3_len(v3_sub(v3_scale(v3_add(L, Hh), 0.5), cam->eye));
    near = 1e-5 * (diag + dist);
    if (!(near > 0)) near = 1e-6;
  }
  double ex_auto = hr_exposure_auto(m);
  float back = (float)(0.04 / ex_auto);
  /* outlines on very bright leaves only show when samples are clamped to the display range */
  if (elements_mode && sample_clamp == 0) sample_clamp = 1.0 / ex_auto;

  raster R = {.W = W, .H = H};
  cvert *cv = malloc((size_t)(m->nverts > 0 ? m->nverts : 1) * sizeof *cv);
  float *zb = calloc((size_t)W * H, sizeof *zb);
  float *cb = calloc((size_t)W * H * 3, sizeof *cb);
  int32_t *ib = elements_mode ? malloc((size_t)W * H * sizeof *ib) : NULL;
  hr_status st = HR_OK;
  int64_t *bcount = NULL, *bidx = NULL;
  if (!cv || !zb || !cb || (elements_mode && !ib)) {
    st = HR_ERR_NOMEM;
    goto done;
  }
  if (ib)
    for (size_t i = 0; i < (size_t)W * H; i++) ib[i] = -1;
  for (int64_t v = 0; v < m->nverts; v++) {
    hr_vec3 d = v3_sub(v3(m->pos[3 * v], m->pos[3 * v + 1], m->pos[3 * v + 2]), cam->eye);
    cv[v].X = v3_dot(d, right) * fx;
    cv[v].Y = v3_dot(d, up) * fy;
    cv[v].W = v3_dot(d, fwd);
    for (int c = 0; c < 3; c++) cv[v].c[c] = m->B[3 * v + c];
  }
  /* setup: clip, project, snap */
  for (int64_t t = 0; t < m->ntris && !R.nomem; t++) {
    cvert tv[3];
    int oc[3];
    const float *p[3];
    for (int k = 0; k < 3; k++) {
      uint32_t vi = m->tri[3 * t + k];
      tv[k] = cv[vi];
      p[k] = &m->pos[3 * vi];
    }
    for (int k = 0; k < 3; k++) oc[k] = outcode(&tv[k], near);
    if (oc[0] & oc[1] & oc[2]) continue;
    hr_vec3 e1 = v3(p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]);
    hr_vec3 e2 = v3(p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]);
    hr_vec3 to_eye = v3_sub(cam->eye, v3(p[0][0], p[0][1], p[0][2]));
    int is_back = v3_dot(v3_cross(e1, e2), to_eye) <= 0;
    int32_t id = (int32_t)(elements_mode ? m->tri_leaf[t] : 0);
    if (is_back) {
      id = -2;
      for (int k = 0; k < 3; k++) tv[k].c[0] = tv[k].c[1] = tv[k].c[2] = back;
    } else if (elements_mode) {
      const double *B = leaves[m->tri_leaf[t]].B;
      for (int k = 0; k < 3; k++)
        for (int c = 0; c < 3; c++) tv[k].c[c] = (float)B[c];
    }
    if ((oc[0] | oc[1] | oc[2]) == 0)
      push_tri(&R, &tv[0], &tv[1], &tv[2], id);
    else
      clip_and_push(&R, tv, id, near);
  }
  if (R.nomem) {
    st = HR_ERR_NOMEM;
    goto done;
  }
  /* bin into bands */
  int nb = (H + BAND - 1) / BAND;
  bcount = calloc((size_t)nb + 1, sizeof *bcount);
  if (!bcount) {
    st = HR_ERR_NOMEM;
    goto done;
  }
  for (int64_t t = 0; t < R.nt; t++)
    for (int b = R.t[t].r0 / BAND; b <= R.t[t].r1 / BAND; b++) bcount[b + 1]++;
  for (int b = 0; b < nb; b++) bcount[b + 1] += bcount[b];
  bidx = malloc((size_t)(bcount[nb] > 0 ? bcount[nb] : 1) * sizeof *bidx);
  if (!bidx) {
    st = HR_ERR_NOMEM;
    goto done;
  }
  {
    int64_t *fill = malloc((size_t)nb * sizeof *fill);
    if (!fill) {
      st = HR_ERR_NOMEM;
      goto done;
    }
    memcpy(fill, bcount, (size_t)nb * sizeof *fill);
    for (int64_t t = 0; t < R.nt; t++)
      for (int b = R.t[t].r0 / BAND; b <= R.t[t].r1 / BAND; b++) bidx[fill[b]++] = t;
    free(fill);
  }
#pragma omp parallel for schedule(dynamic, 1)
  for (int b = 0; b < nb; b++) {
    int y0 = b * BAND, y1 = y0 + BAND < H ? y0 + BAND : H;
    for (int64_t k = bcount[b]; k < bcount[b + 1]; k++)
      raster_tri(&R.t[bidx[k]], W, y0, y1, zb, cb, ib);
  }
  /* resolve: box filter; in elements mode samples whose 4-neighbours see another leaf are
   * outline samples (black) */
  {
    float cl = sample_clamp > 0 ? (float)sample_clamp : INFINITY;
    float norm = 1.0f / (float)(ss * ss);
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++)
      for (int x = 0; x < w; x++) {
        float acc[3] = {0, 0, 0};
        for (int sy = 0; sy < ss; sy++)
          for (int sx = 0; sx < ss; sx++) {
            int X = x * ss + sx, Y = y * ss + sy;
            size_t i = (size_t)Y * W + X;
            if (ib && ib[i] != -1) {
              int32_t id = ib[i];
              if ((X > 0 && ib[i - 1] != id) || (X + 1 < W && ib[i + 1] != id) ||
                  (Y > 0 && ib[i - W] != id) || (Y + 1 < H && ib[i + W] != id))
                continue; /* outline: contributes black */
            }
            for (int c = 0; c < 3; c++) {
              float v = cb[3 * i + c];
              acc[c] += v < cl ? v : cl;
            }
          }
        for (int c = 0; c < 3; c++) rgb[3 * ((size_t)y * w + x) + c] = acc[c] * norm;
      }
  }
done:
  free(cv);
  free(zb);
  free(cb);
  free(ib);
  free(R.t);
  free(bcount);
  free(bidx);
  hr_mesh_destroy(&tmp);
  return st;
}

hr_status hr_render(const hr_scene *s, const hr_mesh *m, const hr_leaf *leaves, int64_t n,
                    const hr_camera *cam, int w, int h, int elements_mode, float *rgb) {
  return hr_render_ex(s, m, leaves, n, cam, w, h, elements_mode, 2, 0, rgb);
}

/* ------------------------------------------------------------------ image writers */

hr_status hr_png_write(const char *path, int w, int h, const float *rgb, double exposure,
                       hr_err *err) {
  if (!path || !rgb || w < 1 || h < 1)
    return hr_err_set(err, HR_ERR_INVALID, "hr_png_write: bad arguments");
  if (!isfinite(exposure) || exposure < 0)
    return hr_err_set(err, HR_ERR_INVALID, "%s: bad exposure %g", path, exposure);
  size_t n = (size_t)w * h * 3;
  uint8_t *buf = malloc(n);
  if (!buf) return hr_err_set(err, HR_ERR_NOMEM, "%s: out of memory", path);
  /* 8-bit output: a 4096-entry table over [0,1] of the scaled value is not exact near 0, so
   * evaluate the transfer per value (a few million pow calls at most). */
  for (size_t i = 0; i < n; i++) buf[i] = hr_tonemap8(rgb[i], exposure);
  png_image img;
  memset(&img, 0, sizeof img);
  img.version = PNG_IMAGE_VERSION;
  img.width = (png_uint_32)w;
  img.height = (png_uint_32)h;
  img.format = PNG_FORMAT_RGB;
  /* libpng checks every write, the flush and the close, and removes the file on failure; its
   * message for a failed write is only "Write Error", so the cause comes from errno */
  errno = 0;
  int ok = png_image_write_to_file(&img, path, 0, buf, 0, NULL);
  int e = errno;
  free(buf);
  if (!ok) {
    hr_status st = e ? hr_err_set(err, HR_ERR_IO, "%s: cannot write: %s", path, strerror(e))
                     : hr_err_set(err, HR_ERR_IO, "%s: cannot write PNG (%s)", path, img.message);
    png_image_free(&img);
    return st;
  }
  return HR_OK;
}

hr_status hr_pfm_write(const char *path, int w, int h, const float *rgb, hr_err *err) {
  if (!path || !rgb || w < 1 || h < 1)
    return hr_err_set(err, HR_ERR_INVALID, "hr_pfm_write: bad arguments");
  uint8_t *row = malloc((size_t)w * 12);
  if (!row) return hr_err_set(err, HR_ERR_NOMEM, "%s: out of memory", path);
  FILE *fp = fopen(path, "wb");
  if (!fp) {
    int e = errno;
    free(row);
    return hr_err_set(err, HR_ERR_IO, "%s: cannot open for writing: %s", path, strerror(e));
  }
  int ok = fprintf(fp, "PF\n%d %d\n-1.0\n", w, h) > 0, e = ok ? 0 : errno;
  for (int y = h - 1; y >= 0 && ok; y--) {
    const float *src = &rgb[(size_t)y * w * 3];
    for (int i = 0; i < 3 * w; i++) {
      uint32_t u;
      memcpy(&u, &src[i], 4);
      row[4 * i] = (uint8_t)u;
      row[4 * i + 1] = (uint8_t)(u >> 8);
      row[4 * i + 2] = (uint8_t)(u >> 16);
      row[4 * i + 3] = (uint8_t)(u >> 24);
    }
    ok = fwrite(row, 1, (size_t)w * 12, fp) == (size_t)w * 12;
    if (!ok) e = errno;
  }
  free(row);
  return hr_file_close(fp, path, ok, e, err);
}
