/* Caustics mapping (Shah, Konttinen & Pattanaik 2007; Wyman 2006): the Sun's light
 * refracted by a water surface seen from the Sun, splatted onto a horizontal receiver
 * plane, as a gain map: refracted irradiance / the irradiance without the water.
 *
 * Input: an orthographic view along the Sun's direction (the water's planar Depth and
 * world Normal passes; texels without water: depth not in (0, clip_end), non-finite, or
 * a normal shorter than 0.5). Every `step`-th texel is a lattice node. A node with water
 * refracts the Sun's direction L through its normal (Snell, eta = 1 / ior) at its world
 * point and follows the refracted ray to the plane z = plane_z; a node without water
 * (or whose water is below the plane, or whose ray does not go down) sends its light
 * straight on. Either way the node's image is where that point of the plane lies in the
 * light view, so the gain map is indexed by light-view coordinates: a receiver point X
 * looks up the texel it projects to along L. The map reaches beyond the view as far as the
 * refracted light does (at most twice the view's size each side): under a low sun the
 * floor below the water projects far outside the water's own view.
 *
 * The flux between four nodes (a cell) is spread over the cell's image by s x s
 * sub-samples (the corners' images and weights interpolated bilinearly: the piecewise
 * bilinear map whose Jacobian is the caustic's intensity, converged as s grows), each
 * splatted with a tent (bilinear) kernel onto the nodes, then filtered by a [1 2 1] / 4
 * tent per axis. The same is done for the identity map in closed form (separable: a
 * per-axis profile), and the gain is their ratio: exactly 1 where the water is flat and
 * horizontal (and up to the light view's edge). Weights: 1, or the Fresnel
 * transmittance (unpolarised, exact dielectric formula) with `fresnel`.
 *
 * The splat's kernel: per cell, along each axis, tents whose half-width is a whole number
 * of the cell's sub-sample spacings (two blended, continuous in the spacing): over a
 * regular lattice they sum to a constant, so a uniformly scaled field has no ripple.
 *
 * A sun of angular diameter a spreads each refracted ray into a cone of half-angle
 * a / (2 ior) in the water: the gain map is blurred by a Gaussian of sigma half that cone's
 * radius on the floor at the water's mean height above it (a disc's sigma is R / 2).
 *
 * Node images are computed in parallel; the splat too, by chunks of the map's rows, each
 * adding its cells in the one fixed order: the map is bit-identical for any thread count. Gains are finite, >= 0, and at
 * most FX_CAUSTIC_GAIN_MAX. */
#ifndef LIBFX_MATH_CAUSTIC_MAP_H
#define LIBFX_MATH_CAUSTIC_MAP_H

#include "core/context.h"
#include "math/camera.h"

#define FX_CAUSTIC_GAIN_MAX 64.0f

typedef struct fx_caustic_input {
    int width, height;        /* the light view's texels */
    const float *depth;       /* width * height: planar depth along the view's -Z */
    const float *normal;      /* width * height * normal_channels: world normals */
    int normal_channels;      /* >= 3 */
    const fx_view *view;      /* the light view (orthographic along the Sun's direction) */
    float clip_end;           /* depth at or beyond: no water (<= 0: 1e9) */
    float ior;                /* water's index of refraction (>= 1) */
    float plane_z;            /* the receiver: world plane z = plane_z */
    int step;                 /* every step-th texel is a node (>= 1) */
    int samples;              /* sub-samples per cell side (>= 1) */
    int fresnel;              /* weight by the Fresnel transmittance */
    float sun_angle;          /* the sun disc's angular diameter (radians; 0: a point) */
} fx_caustic_input;

typedef struct fx_caustic_map {
    int nx, ny;               /* the map's nodes: the view's nodes and a margin around them */
    int ox, oy;               /* the view's node (0, 0) is the map's node (ox, oy) */
    int step;
    float *gain;              /* nx * ny */
    long water_nodes;         /* nodes that saw water */
    double mean_gain;         /* over the nodes away from the border */
    double mean_drop;         /* mean height of the water above the plane (water nodes) */
    double blur_sigma;        /* the sun disc's blur, nodes */
} fx_caustic_map;

/* Builds the map; FX_ERR_OUT_OF_MEMORY (message recorded with `where`) on failure. */
fx_result fx_caustic_map_build(fx_context *ctx, const fx_caustic_input *in, fx_caustic_map *out, const char *where);
void fx_caustic_map_free(fx_caustic_map *m);

/* The gain at continuous light-view pixel coordinates (texel x's centre at x + 0.5):
 * bilinear between nodes; 1 outside the nodes' range (no knowledge: no change). */
static inline float fx_caustic_map_gain(const fx_caustic_map *m, float px, float py)
{
    float gx = (px - 0.5f) / (float)m->step + (float)m->ox, gy = (py - 0.5f) / (float)m->step + (float)m->oy;
    if (!(gx >= 0.0f && gy >= 0.0f && gx <= (float)(m->nx - 1) && gy <= (float)(m->ny - 1)))
        return 1.0f; /* also NaN */
    int x0 = (int)gx, y0 = (int)gy;
    if (x0 > m->nx - 2)
        x0 = m->nx - 2 < 0 ? 0 : m->nx - 2;
    if (y0 > m->ny - 2)
        y0 = m->ny - 2 < 0 ? 0 : m->ny - 2;
    int x1 = x0 + 1 < m->nx ? x0 + 1 : x0, y1 = y0 + 1 < m->ny ? y0 + 1 : y0;
    float tx = gx - (float)x0, ty = gy - (float)y0;
    const float *g = m->gain;
    float a = g[(size_t)y0 * m->nx + x0] + (g[(size_t)y0 * m->nx + x1] - g[(size_t)y0 * m->nx + x0]) * tx;
    float b = g[(size_t)y1 * m->nx + x0] + (g[(size_t)y1 * m->nx + x1] - g[(size_t)y1 * m->nx + x0]) * tx;
    return a + (b - a) * ty;
}

/* The gain at the view's node (c, r) (texel (c step, r step)). */
static inline float fx_caustic_map_node(const fx_caustic_map *m, int c, int r)
{
    return m->gain[(size_t)(r + m->oy) * m->nx + (c + m->ox)];
}

/* Snell's refraction of unit direction d at unit normal n (n against d: n . d < 0) from
 * air into a medium of index ior; the Fresnel transmittance into *t (NULL: not wanted).
 * Returns 0 when there is no refracted ray (never for ior >= 1 from air). */
int fx_refract_into(fx_vec3 d, fx_vec3 n, float ior, fx_vec3 *out, float *t);

#endif
