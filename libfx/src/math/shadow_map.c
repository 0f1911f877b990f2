/* Shadow maps: see shadow_map.h. */
#include "math/shadow_map.h"
#include "core/parallel.h"
#include "math/blur.h"
#include "math/sat.h"

#include <math.h>
#include <string.h>

typedef struct build_job {
    const float *raw;
    fx_shadow_map *sm;
    int bias;
} build_job;

static void norm_rows(void *user, int y0, int y1)
{
    build_job *j = user;
    fx_shadow_map *sm = j->sm;
    for (int y = y0; y < y1; y++)
        for (int x = 0; x < sm->width; x++) {
            size_t i = (size_t)y * sm->width + x;
            sm->depth[i] = fx_shadow_map_norm(sm, j->raw[i]);
        }
}

/* The smaller of the forward and backward differences (0 at a border). */
static float min_diff(const float *z, size_t i, int pos, int n, size_t step)
{
    float f = pos + 1 < n ? z[i + step] - z[i] : 0.0f;
    float b = pos > 0 ? z[i] - z[i - step] : 0.0f;
    if (pos + 1 >= n)
        return b;
    if (pos == 0)
        return f;
    return fabsf(f) < fabsf(b) ? f : b;
}

static void moment_rows(void *user, int y0, int y1)
{
    build_job *j = user;
    fx_shadow_map *sm = j->sm;
    const float *z = sm->depth;
    for (int y = y0; y < y1; y++)
        for (int x = 0; x < sm->width; x++) {
            size_t i = (size_t)y * sm->width + x;
            float m1 = z[i], m2 = m1 * m1;
            if (j->bias) {
                float dx = min_diff(z, i, x, sm->width, 1);
                float dy = min_diff(z, i, y, sm->height, (size_t)sm->width);
                m2 += 0.25f * (dx * dx + dy * dy);
            }
            sm->moments[2 * i] = m1;
            sm->moments[2 * i + 1] = m2;
        }
}

fx_result fx_shadow_map_build(fx_context *ctx, const float *raw_depth, int width, int height, float znear,
                              float zfar, int derivative_bias, fx_shadow_map *out, const char *where)
{
    memset(out, 0, sizeof *out);
    if (width <= 0 || height <= 0 || !(zfar > znear) || !isfinite(zfar) || !isfinite(znear))
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "%s: shadow map %d x %d with depth range [%g, %g]", where, width,
                       height, (double)znear, (double)zfar);
    size_t n = (size_t)width * height;
    fx_result r = fx_check_budget(ctx, (uint64_t)n * 3 * sizeof(float), "shadow map");
    if (r)
        return r;
    out->depth = fx_mem_alloc(n * sizeof(float));
    out->moments = fx_mem_alloc(n * 2 * sizeof(float));
    if (!out->depth || !out->moments) {
        fx_shadow_map_free(out);
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for a %d x %d shadow map", where, width, height);
    }
    out->width = width;
    out->height = height;
    out->znear = znear;
    out->zfar = zfar;
    build_job j = {raw_depth, out, derivative_bias};
    fx_parallel_for(ctx, height, fx_grain_for(ctx, height), norm_rows, &j);
    fx_parallel_for(ctx, height, fx_grain_for(ctx, height), moment_rows, &j);
    return FX_OK;
}

fx_result fx_shadow_map_filter(fx_context *ctx, fx_shadow_map *sm, fx_shadow_filter filter, float width,
                               const char *where)
{
    if (!(width > 1.0f))
        return FX_OK;
    if (filter == FX_SHADOW_FILTER_BOX_SAT) {
        int radius = (int)lrintf((width - 1.0f) * 0.5f);
        return fx_sat_box_filter(ctx, sm->moments, sm->moments, sm->width, sm->height, 2, radius, where);
    }
    fx_blur_spec spec = {width / sqrt(12.0), FX_BLUR_RECURSIVE, 3};
    return fx_blur_image(ctx, sm->moments, sm->moments, sm->width, sm->height, 2, &spec, NULL, where);
}

void fx_shadow_map_free(fx_shadow_map *sm)
{
    if (!sm)
        return;
    fx_mem_free(sm->depth);
    fx_mem_free(sm->moments);
    sm->depth = sm->moments = NULL;
}

float fx_shadow_map_pcf(const fx_shadow_map *sm, float px, float py, float t, int radius, float eps)
{
    int cx = (int)floorf(px), cy = (int)floorf(py);
    int x0 = cx - radius, x1 = cx + radius, y0 = cy - radius, y1 = cy + radius;
    x0 = x0 < 0 ? 0 : x0;
    y0 = y0 < 0 ? 0 : y0;
    x1 = x1 >= sm->width ? sm->width - 1 : x1;
    y1 = y1 >= sm->height ? sm->height - 1 : y1;
    if (x1 < x0 || y1 < y0)
        return fx_shadow_map_hard(sm, px, py, t, eps);
    int lit = 0, n = 0;
    for (int y = y0; y <= y1; y++) {
        const float *row = sm->depth + (size_t)y * sm->width;
        for (int x = x0; x <= x1; x++) {
            lit += t <= row[x] + eps;
            n++;
        }
    }
    return (float)lit / (float)n;
}
