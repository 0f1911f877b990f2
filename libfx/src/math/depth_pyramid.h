/* A hierarchical depth buffer (Hi-Z): level l >= 1 holds, per cell of 2^l x 2^l frame
 * pixels, the nearest and the farthest planar depth of the cell's surfaces, as pairs
 * (min, max); background, NaN and <= 0 (fx_ssr_is_background) are no surface: a cell of
 * background only holds (+inf, -inf). Level 0 is the depth buffer itself and is not
 * stored. Used by the screen-space ray tracer to skip, in one step, a cell that the ray
 * crosses entirely in front of (or far behind) every surface (math/ssr_trace.h). */
#ifndef LIBFX_MATH_DEPTH_PYRAMID_H
#define LIBFX_MATH_DEPTH_PYRAMID_H

#include "libfx/fx.h"

#ifdef __cplusplus
extern "C" {
#endif

#define FX_DEPTH_PYRAMID_MAX_LEVELS 16

typedef struct fx_depth_pyramid {
    int levels;                                 /* stored levels 1..levels-1; levels >= 1 */
    int w[FX_DEPTH_PYRAMID_MAX_LEVELS];         /* level l: ceil(width / 2^l) */
    int h[FX_DEPTH_PYRAMID_MAX_LEVELS];
    float *level[FX_DEPTH_PYRAMID_MAX_LEVELS];  /* (min, max) pairs, w x h; level[0] is NULL */
    float *storage;
    size_t bytes;                               /* of storage (from the context's buffer store) */
} fx_depth_pyramid;

/* Builds up to max_levels levels (including level 0) from a width x height planar depth
 * buffer, stopping at a 1x1 level. Serial per level row blocks through the context's pool;
 * bit-identical for any thread count (min is exact). Returns FX_OK or an out-of-memory
 * error (named with `where`); on error *pyr is empty (free is still fine). */
fx_result fx_depth_pyramid_build(fx_context *ctx, const float *depth, int width, int height, int max_levels,
                                 const char *where, fx_depth_pyramid *pyr);
void fx_depth_pyramid_free(fx_context *ctx, fx_depth_pyramid *pyr);

#ifdef __cplusplus
}
#endif
#endif
