/* Shadow maps from a depth view (a light's, or the rain map seen as a light shining
 * straight down): variance shadow maps (Donnelly & Lauritzen 2006; GPU Gems 3 ch. 8),
 * percentage-closer filtering as the accuracy reference, and the hard test.
 *
 * Depth is normalised and centred: z = 2 (d - near) / (far - near) - 1 in
 * [-1, 1] (d beyond far, e.g. Cycles' 1e10 background, is 1: nothing occludes), so the
 * second moment keeps its precision in float (at raw depths ~1000 the variance of a few
 * centimetres vanishes in float32 cancellation). Moments may get the derivative bias
 * m2 += 0.25 (dz/dx^2 + dz/dy^2) (GPU Gems 3, "ComputeMoments"), with each derivative the
 * smaller of the forward and backward difference so depth edges do not blow it up. */
#ifndef LIBFX_MATH_SHADOW_MAP_H
#define LIBFX_MATH_SHADOW_MAP_H

#include "core/context.h"
#include "core/frame.h"
#include "math/vec.h"

typedef enum fx_shadow_filter {
    FX_SHADOW_FILTER_BOX_SAT = 0,  /* box of (2r+1)^2 texels: separable running sums in double (the
                                      name is historical: it was a summed-area table, same means) */
    FX_SHADOW_FILTER_GAUSSIAN = 1  /* separable recursive Gaussian (math/blur), sigma = width / sqrt(12) */
} fx_shadow_filter;

/* A filter value may carry a reduction level of the moments (bits 4..7): the moments are
 * averaged over 2^level x 2^level texel blocks (a mip of the moments, which are linear, so
 * the mean and variance of each block are exact) before the filter, whose width stays in
 * full-resolution texels. The aux-map cache (scene/aux_map.h) keys on the whole value. */
#define FX_SHADOW_FILTER_KIND(f) ((f) & 15)
#define FX_SHADOW_FILTER_LEVEL(f) (((f) >> 4) & 15)
#define FX_SHADOW_FILTER_WITH_LEVEL(kind, level) ((kind) | ((level) << 4))
#define FX_SHADOW_MAX_LEVEL 4

typedef struct fx_shadow_map {
    int width, height;
    float znear, zfar;
    float *depth;    /* normalised depth, width * height */
    float depth_min; /* its least value, at most 1 (fx_shadow_map_build: the rows' minima
                        taken while they are in cache; a copy of the map keeps it) */
    float *moments;  /* filtered (E[z], E[z^2]), mwidth * mheight * 2; NULL until filtered */
    int mwidth, mheight; /* the moments' grid: ceil(width / 2^level) x ceil(height / 2^level) */
    int level;       /* the moments' reduction level (0: full resolution) */
    int derivative_bias;
    int factor;      /* the depth's reduction per axis (fx_shadow_map_reduced_*): a texel is one
                        kept texel of each factor x factor block of the view; 0 or 1: as rendered */
    float *row_min;  /* during a reduced build: each row's least value */
} fx_shadow_map;

/* Normalised depth of a raw planar depth. */
static inline float fx_shadow_map_norm(const fx_shadow_map *sm, float d)
{
    float range = sm->zfar - sm->znear;
    float z = range > 1e-20f ? 2.0f * (d - sm->znear) / range - 1.0f : 0.0f;
    return isfinite(z) ? fx_clampf(z, -1.0f, 1.0f) : 1.0f;
}

/* A world distance along the view's axis as a normalised depth difference. */
static inline float fx_shadow_map_norm_dist(const fx_shadow_map *sm, float metres)
{
    float range = sm->zfar - sm->znear;
    return range > 1e-20f ? 2.0f * metres / range : 0.0f;
}

/* Builds the normalised depth from raw planar depth. The moments are made by
 * fx_shadow_map_filter (any width, even <= 1), at the level it asks for: without that call
 * moments is NULL (PCF and the hard test read only the depth). */
fx_result fx_shadow_map_build(fx_context *ctx, const float *raw_depth, int width, int height, float znear,
                              float zfar, int derivative_bias, fx_shadow_map *out, const char *where);
/* The same over raw_depth itself (fx_mem_alloc'ed, width * height): on success it becomes
 * out->depth (the map owns it: no second buffer, no fresh pages); on failure the caller
 * keeps it. The same bits as fx_shadow_map_build. */
fx_result fx_shadow_map_build_in_place(fx_context *ctx, float *raw_depth, int width, int height, float znear,
                                       float zfar, int derivative_bias, fx_shadow_map *out, const char *where);
/* A map reduced by `factor` per axis, for a reader that needs less than the view's
 * resolution (god_rays' volumetric march at draft): texel (X, Y) of the ceil(width /
 * factor) x ceil(height / factor) map is the full map's texel (f X + o, f Y + o), o =
 * fx_shadow_map_sample_offset(f) (clamped to the map), bit for bit, and depth_min is the
 * least of every texel of the kept rows (f Y + o): the rows between are never read. A
 * point sample, not the
 * block's least or mean: on the Greek bath at half resolution the least (nearest occluder)
 * narrowed the shafts, the gaps between occluders (MAE against the reference 3.1e-2,
 * 1.9e-2 for the mean, 1.1e-2 for the point sample, 9.2e-3 at full resolution;
 * docs/effects/god_rays.md); a point sample widens neither occluders nor gaps, and keeps
 * a one-texel feature at one phase in f. The reader must address the kept texels' centres
 * (fx_view_reduce_sampled). Built row by row (the kept raw row -> one row of the map), so
 * the view's full map never exists: _begin allocates the map, _row (any thread, each row
 * once) takes the kept raw row (raw_width floats, normalised in place where its least
 * value overflows) and writes map row Y, _end takes depth_min. Moments are not offered on
 * it. */
static inline int fx_shadow_map_sample_offset(int factor) { return factor > 1 ? (factor - 1) / 2 : 0; }
fx_result fx_shadow_map_reduced_begin(fx_context *ctx, int width, int height, int factor, float znear, float zfar,
                                      fx_shadow_map *out, const char *where);
void fx_shadow_map_reduced_row(fx_shadow_map *sm, int Y, float *row, int raw_width);
void fx_shadow_map_reduced_end(fx_shadow_map *sm);
/* The same from a whole raw depth (a view that cannot be read row by row). */
fx_result fx_shadow_map_build_reduced(fx_context *ctx, const float *raw_depth, int width, int height, int factor,
                                      float znear, float zfar, fx_shadow_map *out, const char *where);
/* Filters the moments with a box (width rounded to an odd number of texels) or a Gaussian
 * of the same variance (first making the moments when there are none). width <= 1:
 * unfiltered. `filter` may carry a reduction level
 * (FX_SHADOW_FILTER_WITH_LEVEL): the moments are first reduced, then filtered with
 * width / 2^level texels of the reduced grid (unfiltered when that is <= 1; the bilinear
 * lookup of blocks of 2^level texels is then the filter). */
fx_result fx_shadow_map_filter(fx_context *ctx, fx_shadow_map *sm, fx_shadow_filter filter, float width,
                               const char *where);
void fx_shadow_map_free(fx_shadow_map *sm);

/* Bilinear lookup of the filtered moments at continuous texel coordinates of the full
 * map (texel x's centre at x + 0.5), clamped to the map; on a reduced grid (level > 0)
 * the coordinates are scaled by 2^-level. */
static inline void fx_shadow_map_moments(const fx_shadow_map *sm, float px, float py, float *m1, float *m2)
{
    if (sm->level > 0) {
        float s = 1.0f / (float)(1 << sm->level);
        px *= s;
        py *= s;
    }
    const int w = sm->mwidth, h = sm->mheight;
    float fx = px - 0.5f, fy = py - 0.5f;
    fx = fx_clampf(fx, 0.0f, (float)(w - 1));
    fy = fx_clampf(fy, 0.0f, (float)(h - 1));
    int x0 = (int)fx, y0 = (int)fy;
    int x1 = x0 + 1 < w ? x0 + 1 : x0, y1 = y0 + 1 < h ? y0 + 1 : y0;
    float tx = fx - (float)x0, ty = fy - (float)y0;
    const float *a = sm->moments + ((size_t)y0 * w + x0) * 2;
    const float *b = sm->moments + ((size_t)y0 * w + x1) * 2;
    const float *c = sm->moments + ((size_t)y1 * w + x0) * 2;
    const float *d = sm->moments + ((size_t)y1 * w + x1) * 2;
    float top0 = a[0] + (b[0] - a[0]) * tx, bot0 = c[0] + (d[0] - c[0]) * tx;
    float top1 = a[1] + (b[1] - a[1]) * tx, bot1 = c[1] + (d[1] - c[1]) * tx;
    *m1 = top0 + (bot0 - top0) * ty;
    *m2 = top1 + (bot1 - top1) * ty;
}

/* Chebyshev's upper bound p_max = var / (var + (t - m1)^2) for a receiver at normalised
 * depth t, with var clamped below at min_var (also when m2 < m1^2 by rounding), 1 where
 * t <= m1 + eps (the max-depth test), light-bleeding reduction by remapping p_max from
 * [bleed, 1] to [0, 1] (GPU Gems 3, 8.4.3; bleed in [0, 1)). Always in [0, 1], finite. */
static inline float fx_vsm_visibility(float m1, float m2, float t, float min_var, float bleed, float eps)
{
    if (!(t > m1 + eps))
        return 1.0f; /* also for NaN */
    float var = m2 - m1 * m1;
    if (!(var > min_var))
        var = min_var > 0.0f ? min_var : 1e-12f;
    float d = t - m1;
    float p = var / (var + d * d);
    if (bleed > 0.0f)
        p = (p - bleed) / (1.0f - bleed);
    return isfinite(p) ? fx_saturate(p) : 0.0f;
}

/* Hard test at the nearest texel: 1 lit, 0 shadowed. */
static inline float fx_shadow_map_hard(const fx_shadow_map *sm, float px, float py, float t, float eps)
{
    int x = (int)floorf(px), y = (int)floorf(py);
    x = x < 0 ? 0 : x >= sm->width ? sm->width - 1 : x;
    y = y < 0 ? 0 : y >= sm->height ? sm->height - 1 : y;
    return t <= sm->depth[(size_t)y * sm->width + x] + eps ? 1.0f : 0.0f;
}

/* Percentage-closer filtering: the lit fraction of the (2r+1)^2 texels around the nearest
 * one (clipped to the map), cost O(r^2), the reference VSM is measured against; with a
 * receiver-plane depth bias: each texel (x, y) is tested against the receiver's
 * plane extended under it, t + gx (x + 0.5 - px) + gy (y + 0.5 - py) (gx, gy: the
 * receiver's normalised depth per texel), plus eps and half a texel of its slope
 * (0.5 (|gx| + |gy|): the depth a texel's centre may differ from the plane within it). A
 * lit flat receiver far from occluders is then lit at every tap, where the plain test
 * compares the far taps of a tilted receiver with its centre's depth (acne). gx = gy = 0:
 * the plain test against t + eps. */
float fx_shadow_map_pcf_plane(const fx_shadow_map *sm, float px, float py, float t, int radius, float eps, float gx,
                              float gy);

#endif
