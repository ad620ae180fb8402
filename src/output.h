/* output.h: turning the solver's leaf elements into pictures and files (internal API).
 *
 * mesh.c    - vertex reconstruction: a crack-free, seam-free smooth triangle mesh from the leaves
 *             (hr_mesh_build), the automatic exposure, and the PLY and GLB writers.
 * render.c  - a software rasteriser (z-buffer, perspective-correct Gouraud shading of the mesh,
 *             or flat leaves with dark outlines), tone mapping and the PNG/PFM writers.
 * viewer.c  - viewer.html: a self-contained three.js page with the .glb embedded.
 *
 * Colour conventions: all float colours are linear radiosity B (W/m^2, RGB). Tone mapping for
 * display is   display = srgb_oetf(clamp(B * exposure, 0, 1))   and is applied only by the
 * writers that produce display colours (PNG, the uchar colours of the PLY, COLOR_0 of the GLB,
 * which stays linear but has the exposure applied and is clamped to [0,1]).
 */
#ifndef HR_OUTPUT_H
#define HR_OUTPUT_H

#include "hrad.h"

#include <stdio.h>
#include <stdint.h>

/* A triangle mesh over all surfaces. Vertices belong to exactly one input polygon: the surfaces
 * one polygon was split into (a non-planar quad's two triangles, a fan) share the vertices along
 * their common edges, so the polygon is one smooth region; different polygons, whose normals and
 * materials differ, never share vertices. Within a surface, leaf corners with equal lattice
 * coordinates are one vertex. Triangles are counter-clockwise seen from the front of their
 * surface. */
typedef struct hr_mesh {
  int64_t nverts, ntris;
  float *pos;        /* 3*nverts, world coordinates */
  float *B;          /* 3*nverts, reconstructed linear radiosity */
  uint32_t *tri;     /* 3*ntris, vertex indices */
  int32_t *tri_surf; /* ntris, surface index */
  int64_t *tri_leaf; /* ntris, index of the leaf (in the array given to hr_mesh_build) the
                        triangle lies in; used by the flat "elements" rendering */
  uint8_t *tri_emit; /* ntris, 1 when the triangle's material emits (emit > 0 in any channel) */
  int64_t ncentre;   /* how many of the vertices are added leaf centres (see hr_mesh_build) */
  const hr_scene *scene; /* the scene it was built from (objects and materials for the GLB);
                            must outlive the mesh */
} hr_mesh;

/* Builds the smooth mesh from 'n' leaves (in any order) of scene 's'.
 *  - Per input polygon, vertices are keyed by lattice coordinates within a surface and matched
 *    exactly along edges shared by the polygon's surfaces; positions come from the surface's
 *    parametrisation (bilinear for quads, barycentric for triangles, see hrad.h).
 *  - A vertex's value is the area-weighted mean of B over the leaves having it as a corner.
 *  - T-vertices (a corner of smaller leaves lying inside an edge of a larger leaf) are found by
 *    probing edge midpoints recursively in a hash map (stopping where no vertex exists, which is
 *    exact for dyadic subdivisions); they get the linear interpolation of the larger leaf's edge
 *    end values (no colour seams) and split the larger leaf's polygon (no cracks).
 *  - A leaf polygon (its corners plus T-vertices) is fanned from a corner whose two edges hold
 *    no T-vertices (for quads without T-vertices: the corner giving the diagonal with the smaller
 *    luminance difference); when no corner qualifies, a centre vertex is added (mean of the
 *    corners' positions and values, exact for linear fields) and the polygon is fanned from it.
 * Leaves with a bad surface index or corner count give HR_ERR_INVALID. O(n) expected time. */
hr_status hr_mesh_build(const hr_scene *s, const hr_leaf *leaves, int64_t n, hr_mesh **out);
void hr_mesh_destroy(hr_mesh **m);

/* Automatic exposure: returns the factor e such that the area-weighted 95th percentile of the
 * luminance (Y = 0.2126 R + 0.7152 G + 0.0722 B, per triangle the mean of its vertices) over
 * non-emitting triangles maps to 0.8 in linear units after scaling, i.e. e = 0.8 / Y95 (display
 * value about 231 of 255). Falls back to all triangles when no non-emitting triangle is lit, and
 * returns 1 for an empty or black mesh. */
double hr_exposure_auto(const hr_mesh *m);

/* The tone-mapping transfer for one linear channel: srgb_oetf(clamp(v * exposure, 0, 1)) as a
 * value in [0,1] (NaN -> 0), and its 8-bit rounding. */
double hr_tonemap(double v, double exposure);
uint8_t hr_tonemap8(double v, double exposure);

/* Renders the scene into 'rgb' (w*h*3 floats, linear radiosity, row 0 at the top) with 2x2
 * supersampling (box filter). The camera looks from eye to at with vertical fov_deg; aspect w/h.
 *  elements_mode = 0: the smooth mesh 'm', perspective-correct interpolation of vertex B.
 *  elements_mode = 1: every leaf flat with its own B, leaf outlines drawn as dark lines (one
 *                     pixel wide, found where neighbouring samples see different leaves).
 * 'm' must have been built from 'leaves'/'n' (needed for elements mode); when m is NULL a
 * temporary mesh is built. Back faces of the one-sided surfaces are drawn dark grey
 * (0.04 / hr_exposure_auto(m) linear, i.e. about 56/255 at the automatic exposure); the
 * background is 0. Smooth mode gives a true linear image (write it as PFM as is); for PNG
 * output prefer hr_render_ex with sample_clamp = 1/exposure (see there). */
hr_status hr_render(const hr_scene *s, const hr_mesh *m, const hr_leaf *leaves, int64_t n,
                    const hr_camera *cam, int w, int h, int elements_mode, float *rgb);

/* Like hr_render with more control: 'ss' samples per pixel side (1..4; hr_render uses 2) and
 * 'sample_clamp': > 0 clamps every sample to [0, sample_clamp] before the box filter (pass
 * 1/exposure for PNG output, so that the edges of emitters and the outlines on bright leaves
 * are anti-aliased the way the display sees them); < 0 never clamps (a true linear image, for
 * PFM); 0 = the default of hr_render: no clamp in smooth mode, 1/hr_exposure_auto(m) in
 * elements mode (outlines must stay visible on emitters). */
hr_status hr_render_ex(const hr_scene *s, const hr_mesh *m, const hr_leaf *leaves, int64_t n,
                       const hr_camera *cam, int w, int h, int elements_mode, int ss,
                       double sample_clamp, float *rgb);

/* 8-bit sRGB PNG (libpng) of the tone-mapped linear image; row 0 at the top. */
hr_status hr_png_write(const char *path, int w, int h, const float *rgb, double exposure,
                       hr_err *err);
/* Linear colour PFM: "PF", little-endian floats (scale -1), bottom row first as the format says
 * ('rgb' itself has row 0 at the top). */
hr_status hr_pfm_write(const char *path, int w, int h, const float *rgb, hr_err *err);

/* Binary little-endian PLY. Vertex properties: float x,y,z; uchar red,green,blue (sRGB 8-bit of
 * B * exposure); float radiosity_r, radiosity_g, radiosity_b (linear B, no exposure). Faces:
 * list uchar int vertex_indices. The header carries "comment exposure X". */
hr_status hr_ply_write(const char *path, const hr_mesh *m, double exposure, hr_err *err);

/* glTF 2.0 binary that keeps the input's identity: one node and one mesh per object of the scene
 * (named like it; objects without triangles left out), one primitive per material used in it;
 * one material per input material (named like it, in input order; single-sided,
 * KHR_materials_unlit with base colour white, so that COLOR_0 is what a viewer shows; the
 * material's reflectance and emission in its extras). Attributes: POSITION, COLOR_0 (linear B *
 * exposure clamped to [0,1]), _RADIOSITY (linear B in W/m^2, float VEC3, unclamped); UNSIGNED_INT
 * indices. asset.generator "hrad", asset.extras {"exposure": X, "colors": ...}. A mesh without a
 * scene (m->scene NULL) is one node, mesh and material named "radiosity". */
hr_status hr_glb_write(const char *path, const hr_mesh *m, double exposure, hr_err *err);

/* hr_viewer_write (viewer.c) is public: hrad.h. */

/* Flushes and closes 'fp' (written to 'path'); 'ok' == 0 means an earlier write failed with
 * errno 'e'. On any failure the partial file is removed and HR_ERR_IO names the cause. Every
 * writer ends with it (output.c). */
hr_status hr_file_close(FILE *fp, const char *path, int ok, int e, hr_err *err);

/* The three.js directory hr_viewer_write reads ($HRAD_THREE_DIR), or NULL when it uses the
 * embedded copy. */
const char *hr_viewer_three_dir(void);
/* 1 when hr_viewer_write finds every three.js file it embeds, else 0. */
int hr_viewer_available(void);

/* A file embedded at build time: its path relative to node_modules/three, its bytes. */
typedef struct hr_asset {
  const char *name;
  const unsigned char *data;
  size_t len;
} hr_asset;
/* The three.js files viewer.html inlines (generated by cmake/embed.cmake; empty when
 * node_modules/three was missing at build time). */
extern const hr_asset hr_viewer_assets[];
extern const int hr_viewer_nassets;

#endif
