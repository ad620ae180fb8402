/* texture.h: diffuse textures for reflectance (internal API, texture.c).
 *
 * A texture is decoded once (PNG with libpng, JPEG with libjpeg) into linear RGB floats: the
 * 8-bit sRGB values are converted with the sRGB transfer function, alpha is dropped. Loaders then
 * ask for the mean over a polygon's UV footprint, which becomes the polygon's reflectance (times
 * the material's factor): radiosity needs one reflectance per element, not a texel pattern.
 */
#ifndef HR_TEXTURE_H
#define HR_TEXTURE_H

#include "hrad.h"

#include <stddef.h>

/* The largest texture accepted, in pixels per side (a 16k texture is 1 GiB of floats). */
#define HR_TEX_MAX_SIDE 16384

typedef struct hr_texture {
  int w, h;
  float *rgb; /* 3*w*h linear RGB, row 0 at the top (v = 1 in UV terms) */
} hr_texture;

/* Decodes PNG or JPEG bytes (found by their signature); 'name' names them in messages.
 * HR_ERR_PARSE ("NAME: not a PNG or JPEG image", or the decoder's message), HR_ERR_TOO_BIG,
 * HR_ERR_NOMEM. On success 't' owns its pixels (hr_texture_free). */
hr_status hr_texture_decode(const unsigned char *data, size_t len, const char *name,
                            hr_texture *t, hr_err *err);
/* Reads and decodes the file at 'path'; HR_ERR_IO when it cannot be read. */
hr_status hr_texture_load(const char *path, hr_texture *t, hr_err *err);
/* The path of texture 'name' as a model file 'from' names it, into 'out' (n bytes): backslashes
 * become slashes, a relative name is taken from the directory of 'from'; when that does not
 * exist, the base name in that directory, then the same ignoring case (exporters on Windows
 * write ".\\IMAGE1.JPG" for image1.jpg). Can't fail (a path that does not exist is left for
 * hr_texture_load to report). */
void hr_texture_resolve(const char *from, const char *name, char *out, size_t n);
/* Builds a texture from 8-bit sRGB RGBA texels (w*h*4 bytes, row 0 at the top). */
hr_status hr_texture_from_rgba8(const unsigned char *rgba, int w, int h, hr_texture *t,
                                hr_err *err);
void hr_texture_free(hr_texture *t);

/* The linear value of an 8-bit sRGB channel. */
double hr_srgb_to_linear(unsigned v);

/* Mean of 't' over the triangle with texture coordinates uv[0..2] (u to the right, v up, the
 * texture repeating outside [0,1]), by nearest-texel samples at the centroids of a regular
 * subdivision of the triangle into k^2 similar triangles, k about the square root of the
 * triangle's area in texels (1..64): exact for a texture constant on each sub-triangle, every
 * texel of a small triangle sampled about once, at most 4096 samples. Can't fail. */
void hr_texture_mean_tri(const hr_texture *t, const double uv[3][2], double out[3]);
/* Mean of 't' over polygon 'p' (n >= 3 vertices, texture coordinates 'uv'): the fan triangles'
 * means (hr_texture_mean_tri) weighted by their world areas. Can't fail. */
void hr_texture_mean_poly(const hr_texture *t, const hr_vec3 *p, const double (*uv)[2], int n,
                          double out[3]);

#endif
