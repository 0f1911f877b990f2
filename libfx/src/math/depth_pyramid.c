/* Hi-Z min-depth pyramid: see depth_pyramid.h. */
#include "math/depth_pyramid.h"

#include "core/buffers.h"
#include "core/context.h"
#include "core/mem.h"
#include "core/parallel.h"
#include "math/ssr_trace.h"

#include <math.h>
#include <string.h>

typedef struct pyr_job {
    const float *src; /* finer level (or the depth buffer for level 1) */
    int sw, sh;
    float *dst;
    int dw, dh;
    int from_depth;
} pyr_job;

static void pyr_rows(void *user, int begin, int end)
{
    const pyr_job *j = user;
    for (int y = begin; y < end; y++) {
        int y0 = 2 * y, y1 = 2 * y + 1 < j->sh ? 2 * y + 1 : 2 * y;
        float *o = j->dst + (size_t)y * j->dw * 2;
        for (int x = 0; x < j->dw; x++) {
            int x0 = 2 * x, x1 = 2 * x + 1 < j->sw ? 2 * x + 1 : 2 * x;
            int xs[4] = { x0, x1, x0, x1 }, ys[4] = { y0, y0, y1, y1 };
            float lo = INFINITY, hi = -INFINITY;
            for (int k = 0; k < 4; k++) {
                float a, b;
                if (j->from_depth) {
                    float d = j->src[(size_t)ys[k] * j->sw + xs[k]];
                    int bg = fx_ssr_is_background(d);
                    a = bg ? INFINITY : d;
                    b = bg ? -INFINITY : d;
                } else {
                    a = j->src[((size_t)ys[k] * j->sw + xs[k]) * 2];
                    b = j->src[((size_t)ys[k] * j->sw + xs[k]) * 2 + 1];
                }
                lo = a < lo ? a : lo;
                hi = b > hi ? b : hi;
            }
            o[2 * x] = lo;
            o[2 * x + 1] = hi;
        }
    }
}

fx_result fx_depth_pyramid_build(fx_context *ctx, const float *depth, int width, int height, int max_levels,
                                 const char *where, fx_depth_pyramid *pyr)
{
    memset(pyr, 0, sizeof *pyr);
    pyr->levels = 1;
    if (width <= 0 || height <= 0 || !depth)
        return FX_OK;
    if (max_levels > FX_DEPTH_PYRAMID_MAX_LEVELS)
        max_levels = FX_DEPTH_PYRAMID_MAX_LEVELS;
    int n = 1;
    size_t total = 0;
    int w = width, h = height;
    pyr->w[0] = w;
    pyr->h[0] = h;
    while (n < max_levels && (w > 1 || h > 1)) {
        w = (w + 1) / 2;
        h = (h + 1) / 2;
        pyr->w[n] = w;
        pyr->h[n] = h;
        total += (size_t)w * h;
        n++;
    }
    if (n == 1)
        return FX_OK;
    pyr->bytes = total * 2 * sizeof(float);
    pyr->storage = fx_buffer_get(ctx, pyr->bytes);
    if (!pyr->storage) {
        memset(pyr, 0, sizeof *pyr);
        pyr->levels = 1;
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the depth pyramid", where);
    }
    float *p = pyr->storage;
    for (int l = 1; l < n; l++) {
        pyr->level[l] = p;
        p += (size_t)pyr->w[l] * pyr->h[l] * 2;
        pyr_job j = { l == 1 ? depth : pyr->level[l - 1], pyr->w[l - 1], pyr->h[l - 1], pyr->level[l],
                      pyr->w[l], pyr->h[l], l == 1 };
        fx_parallel_for(ctx, pyr->h[l], fx_grain_for(ctx, pyr->h[l]), pyr_rows, &j);
    }
    pyr->levels = n;
    return FX_OK;
}

void fx_depth_pyramid_free(fx_context *ctx, fx_depth_pyramid *pyr)
{
    if (!pyr)
        return;
    fx_buffer_put(ctx, pyr->storage, pyr->bytes);
    memset(pyr, 0, sizeof *pyr);
    pyr->levels = 1;
}
