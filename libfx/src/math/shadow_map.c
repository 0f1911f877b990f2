/* Shadow maps: see shadow_map.h. */
#include "math/shadow_map.h"
#include "core/parallel.h"
#include "math/blur.h"
#include "core/buffers.h"
#include "core/mem.h"
#include "core/simd4.h"
#include "math/clones.h"

#include <float.h>
#include <math.h>
#include <string.h>

typedef struct build_job {
    const float *raw;
    fx_shadow_map *sm;
    int bias;
    float *row_min; /* per row: its least normalised depth (1 at most) */
} build_job;

/* The least of n values (never NaN here) and 1, 4 lanes at a time: the minimum does not
 * depend on the order, so neither on the rows' split over threads. */
static float least(const float *z, size_t n)
{
    v4f m4 = V4(1.0f);
    size_t i = 0;
    for (; i + 4 <= n; i += 4)
        m4 = min4(ld4(z + i), m4);
    float m = 1.0f;
    for (int k = 0; k < 4; k++)
        m = m4[k] < m ? m4[k] : m;
    for (; i < n; i++)
        m = z[i] < m ? z[i] : m;
    return m;
}

/* fx_shadow_map_norm over n values, written branch-free so that the compiler vectorises it
 * (inlined into the callers' clones; range > 1e-20) */
static inline void norm_span(const float *restrict raw, float *restrict o, int n, float znear, float range)
{
    for (int x = 0; x < n; x++) {
        const float z = 2.0f * (raw[x] - znear) / range - 1.0f;
        const float c = z < -1.0f ? -1.0f : z > 1.0f ? 1.0f : z;
        o[x] = fabsf(z) <= FLT_MAX ? c : 1.0f; /* NaN, +-Inf: 1 (isfinite) */
    }
}

/* The same in place: one pointer, so the loop needs no overlap check */
static inline void norm_span_in_place(float *out, int n, float znear, float range)
{
    for (int x = 0; x < n; x++) {
        const float z = 2.0f * (out[x] - znear) / range - 1.0f;
        const float c = z < -1.0f ? -1.0f : z > 1.0f ? 1.0f : z;
        out[x] = fabsf(z) <= FLT_MAX ? c : 1.0f;
    }
}

/* fx_shadow_map_norm over rows, written branch-free so that the compiler vectorises it (the
 * same operations in the same order, so the same bits: IEEE division and comparisons are
 * exact lane by lane; 8 lanes in the AVX2 clone), and each row's least value while the row
 * is in cache (depth_min) */
FX_CLONES_VECTORIZE static void norm_rows(void *user, int y0, int y1)
{
    build_job *j = user;
    fx_shadow_map *sm = j->sm;
    const float znear = sm->znear, range = sm->zfar - sm->znear;
    if (!(range > 1e-20f)) { /* as fx_shadow_map_norm: z = 0 */
        for (int y = y0; y < y1; y++) {
            memset(sm->depth + (size_t)y * sm->width, 0, (size_t)sm->width * sizeof(float));
            j->row_min[y] = 0.0f;
        }
        return;
    }
    for (int y = y0; y < y1; y++) {
        float *out = sm->depth + (size_t)y * sm->width;
        if (j->raw == sm->depth)
            norm_span_in_place(out, sm->width, znear, range);
        else
            norm_span(j->raw + (size_t)y * sm->width, out, sm->width, znear, range);
        j->row_min[y] = least(out, (size_t)sm->width);
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

/* The moments (z, z^2 + derivative bias) of texel (x, y). */
static inline void texel_moments(const fx_shadow_map *sm, int x, int y, float *m1, float *m2)
{
    const float *z = sm->depth;
    size_t i = (size_t)y * sm->width + x;
    float a = z[i], b = a * a;
    if (sm->derivative_bias) {
        float dx = min_diff(z, i, x, sm->width, 1);
        float dy = min_diff(z, i, y, sm->height, (size_t)sm->width);
        b += 0.25f * (dx * dx + dy * dy);
    }
    *m1 = a;
    *m2 = b;
}

static void moment_rows(void *user, int y0, int y1)
{
    build_job *j = user;
    fx_shadow_map *sm = j->sm;
    for (int y = y0; y < y1; y++)
        for (int x = 0; x < sm->width; x++) {
            size_t i = (size_t)y * sm->width + x;
            texel_moments(sm, x, y, &sm->moments[2 * i], &sm->moments[2 * i + 1]);
        }
}

static fx_result build(fx_context *ctx, const float *raw_depth, float *in_place, int width, int height, float znear,
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
    out->depth = in_place ? in_place : fx_mem_alloc(n * sizeof(float));
    float *row_min = fx_mem_alloc((size_t)height * sizeof(float));
    if (!out->depth || !row_min) {
        fx_mem_free(row_min);
        if (in_place)
            out->depth = NULL; /* the caller's still */
        fx_shadow_map_free(out);
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for a %d x %d shadow map", where, width, height);
    }
    out->width = out->mwidth = width;
    out->height = out->mheight = height;
    out->level = 0;
    out->derivative_bias = derivative_bias != 0;
    out->znear = znear;
    out->zfar = zfar;
    build_job j = {raw_depth, out, derivative_bias, row_min};
    fx_parallel_for(ctx, height, fx_grain_for(ctx, height), norm_rows, &j);
    out->depth_min = least(row_min, (size_t)height);
    fx_mem_free(row_min);
    return FX_OK;
}

fx_result fx_shadow_map_build(fx_context *ctx, const float *raw_depth, int width, int height, float znear,
                              float zfar, int derivative_bias, fx_shadow_map *out, const char *where)
{
    return build(ctx, raw_depth, NULL, width, height, znear, zfar, derivative_bias, out, where);
}

fx_result fx_shadow_map_build_in_place(fx_context *ctx, float *raw_depth, int width, int height, float znear,
                                       float zfar, int derivative_bias, fx_shadow_map *out, const char *where)
{
    return build(ctx, raw_depth, raw_depth, width, height, znear, zfar, derivative_bias, out, where);
}

/* ---- a map reduced per axis (shadow_map.h) ---- */

fx_result fx_shadow_map_reduced_begin(fx_context *ctx, int width, int height, int factor, float znear, float zfar,
                                      fx_shadow_map *out, const char *where)
{
    memset(out, 0, sizeof *out);
    if (width <= 0 || height <= 0 || factor < 1 || !(zfar > znear) || !isfinite(zfar) || !isfinite(znear))
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "%s: shadow map %d x %d / %d with depth range [%g, %g]", where,
                       width, height, factor, (double)znear, (double)zfar);
    const int w = (width + factor - 1) / factor, h = (height + factor - 1) / factor;
    const size_t n = (size_t)w * h;
    fx_result r = fx_check_budget(ctx, (uint64_t)n * sizeof(float), "shadow map");
    if (r)
        return r;
    /* whole huge pages from 256 KiB up: a first frame's 1080p light view at half resolution
     * (1.6 MB) faulted 380 small pages here, 3-4 ms of system time; one huge page ~1 ms. A
     * map built again (the aux cache off, or a new light view each frame) takes the last
     * one's buffer back from the store (the aux cache puts it there): no fresh page at all */
    out->depth = fx_buffer_get_whole(ctx, n * sizeof(float));
    out->row_min = fx_mem_alloc((size_t)h * sizeof(float));
    if (!out->depth || !out->row_min) {
        fx_shadow_map_free(out);
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for a %d x %d shadow map", where, w, h);
    }
    out->width = out->mwidth = w;
    out->height = out->mheight = h;
    out->factor = factor;
    out->znear = znear;
    out->zfar = zfar;
    return FX_OK;
}

/* The least of n raw values (finite here), 4 lanes at a time. */
static float least_raw(const float *z, size_t n)
{
    v4f m4 = ld4(z);
    size_t i = 4;
    for (; i + 4 <= n; i += 4)
        m4 = min4(ld4(z + i), m4);
    float m = m4[0];
    for (int k = 1; k < 4; k++)
        m = m4[k] < m ? m4[k] : m;
    for (; i < n; i++)
        m = z[i] < m ? z[i] : m;
    return m;
}

/* The least of a raw row's normalised values (norm_rows' least) from its least raw value:
 * the normalisation is monotone wherever its z is finite, and a value whose z is not
 * (|raw| near FLT_MAX) normalises to 1, the top; only a least raw value whose z is not
 * finite (a depth of -FLT_MAX, the reader's -Inf) needs the row normalised. */
static float row_least(float *row, int n, float znear, float range)
{
    if (n < 4) {
        norm_span_in_place(row, n, znear, range);
        return least(row, (size_t)n);
    }
    const float m = least_raw(row, (size_t)n);
    const float z = 2.0f * (m - znear) / range - 1.0f;
    if (fabsf(z) <= FLT_MAX)
        return z < -1.0f ? -1.0f : z > 1.0f ? 1.0f : z;
    norm_span_in_place(row, n, znear, range);
    return least(row, (size_t)n);
}

/* Row Y of the map from its kept raw row (raw_width floats; normalised in place where its
 * least value overflows): the kept texels normalised (norm_rows' arithmetic: the same bits),
 * a point sample (fx_shadow_map_sample_offset), and the row's least normalised value over
 * every texel of it. */
FX_CLONES_VECTORIZE void fx_shadow_map_reduced_row(fx_shadow_map *sm, int Y, float *row, int raw_width)
{
    const int k = sm->factor, w = sm->width;
    const int s = fx_shadow_map_sample_offset(k);
    const float znear = sm->znear, range = sm->zfar - sm->znear;
    float *out = sm->depth + (size_t)Y * w;
    if (!(range > 1e-20f)) { /* as fx_shadow_map_norm: z = 0 */
        memset(out, 0, (size_t)w * sizeof(float));
        sm->row_min[Y] = 0.0f;
        return;
    }
    const int inside = (raw_width - 1 - s) / k + 1; /* kept texels inside the row */
    if (k == 2)
        for (int X = 0; X < inside; X++)
            out[X] = row[2 * X + s];
    else
        for (int X = 0; X < inside; X++)
            out[X] = row[k * X + s];
    for (int X = inside; X < w; X++)
        out[X] = row[raw_width - 1];
    norm_span_in_place(out, w, znear, range);
    const float m = row_least(row, raw_width, znear, range);
    sm->row_min[Y] = m < 1.0f ? m : 1.0f;
}

void fx_shadow_map_reduced_end(fx_shadow_map *sm)
{
    sm->depth_min = least(sm->row_min, (size_t)sm->height);
    fx_mem_free(sm->row_min);
    sm->row_min = NULL;
}

typedef struct reduced_job {
    const float *raw;
    fx_shadow_map *sm;
    int raw_width, raw_height;
    float *scratch; /* per worker: one raw row */
} reduced_job;

static void reduced_rows(void *user, int Y0, int Y1, int worker)
{
    reduced_job *j = user;
    const int k = j->sm->factor, s = fx_shadow_map_sample_offset(k);
    float *row = j->scratch + (size_t)worker * j->raw_width;
    for (int Y = Y0; Y < Y1; Y++) {
        const long long y = (long long)k * Y + s;
        memcpy(row, j->raw + (size_t)(y < j->raw_height ? y : j->raw_height - 1) * j->raw_width,
               (size_t)j->raw_width * sizeof(float));
        fx_shadow_map_reduced_row(j->sm, Y, row, j->raw_width);
    }
}

fx_result fx_shadow_map_build_reduced(fx_context *ctx, const float *raw_depth, int width, int height, int factor,
                                      float znear, float zfar, fx_shadow_map *out, const char *where)
{
    fx_result r = fx_shadow_map_reduced_begin(ctx, width, height, factor, znear, zfar, out, where);
    if (r)
        return r;
    const int workers = fx_parallel_workers(ctx);
    float *scratch = fx_mem_alloc((size_t)workers * width * sizeof(float));
    if (!scratch) {
        fx_shadow_map_free(out);
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for a reduced shadow map", where);
    }
    reduced_job j = {raw_depth, out, width, height, scratch};
    fx_parallel_for_worker(ctx, out->height, 1, reduced_rows, &j);
    fx_mem_free(scratch);
    fx_shadow_map_reduced_end(out);
    return FX_OK;
}

/* ---- the moments' reduction (mip) ---- */

typedef struct reduce_job {
    const fx_shadow_map *sm;
    float *dst; /* mw x mh x 2 */
    int mw, step;
} reduce_job;

/* One row's texel moments (texel_moments) into t1, t2: inside the map without the border
 * tests, in a loop the compiler vectorises (the same operations, so the same values). */
static void row_moments(const fx_shadow_map *sm, int y, float *t1, float *t2)
{
    const int w = sm->width;
    const float *z = sm->depth + (size_t)y * w;
    if (!sm->derivative_bias) {
        for (int x = 0; x < w; x++) {
            t1[x] = z[x];
            t2[x] = z[x] * z[x];
        }
        return;
    }
    if (y == 0 || y == sm->height - 1 || w < 3) {
        for (int x = 0; x < w; x++)
            texel_moments(sm, x, y, &t1[x], &t2[x]);
        return;
    }
    const float *restrict up = z - w, *restrict dn = z + w;
    for (int x = 1; x < w - 1; x++) {
        const float c = z[x];
        float f = z[x + 1] - c, k = c - z[x - 1];
        const float dx = fabsf(f) < fabsf(k) ? f : k;
        f = dn[x] - c;
        k = c - up[x];
        const float dy = fabsf(f) < fabsf(k) ? f : k;
        t1[x] = c;
        t2[x] = c * c + 0.25f * (dx * dx + dy * dy);
    }
    texel_moments(sm, 0, y, &t1[0], &t2[0]);
    texel_moments(sm, w - 1, y, &t1[w - 1], &t2[w - 1]);
}

/* Each reduced texel is the mean of its block's texels' moments (clipped at the far
 * borders), summed in double in a fixed order (the block's rows, each left to right), the
 * moments made a row at a time from the depth. */
static void reduce_rows(void *user, int y0, int y1)
{
    reduce_job *j = user;
    const fx_shadow_map *sm = j->sm;
    const int w = sm->width, mw = j->mw, step = j->step;
    /* per call: the row's moments (2 w floats) and the blocks' sums (2 mw doubles) */
    double *acc = fx_mem_alloc((size_t)mw * 2 * sizeof(double) + (size_t)w * 2 * sizeof(float));
    if (!acc) { /* no memory for the scratch: the same sums texel by texel */
        for (int my = y0; my < y1; my++) {
            int by0 = my * step, by1 = by0 + step < sm->height ? by0 + step : sm->height;
            for (int mx = 0; mx < mw; mx++) {
                int bx0 = mx * step, bx1 = bx0 + step < w ? bx0 + step : w;
                double a = 0.0, b = 0.0;
                for (int y = by0; y < by1; y++)
                    for (int x = bx0; x < bx1; x++) {
                        float m1, m2;
                        texel_moments(sm, x, y, &m1, &m2);
                        a += m1;
                        b += m2;
                    }
                double n = (double)(by1 - by0) * (double)(bx1 - bx0);
                float *o = j->dst + ((size_t)my * mw + mx) * 2;
                o[0] = (float)(a / n);
                o[1] = (float)(b / n);
            }
        }
        return;
    }
    float *t1 = (float *)(acc + 2 * (size_t)mw), *t2 = t1 + w;
    for (int my = y0; my < y1; my++) {
        int by0 = my * step, by1 = by0 + step < sm->height ? by0 + step : sm->height;
        memset(acc, 0, (size_t)mw * 2 * sizeof(double));
        for (int y = by0; y < by1; y++) {
            row_moments(sm, y, t1, t2);
            for (int mx = 0; mx < mw; mx++) {
                int bx0 = mx * step, bx1 = bx0 + step < w ? bx0 + step : w;
                double a = acc[2 * mx], b = acc[2 * mx + 1];
                for (int x = bx0; x < bx1; x++) {
                    a += t1[x];
                    b += t2[x];
                }
                acc[2 * mx] = a;
                acc[2 * mx + 1] = b;
            }
        }
        for (int mx = 0; mx < mw; mx++) {
            int bx0 = mx * step, bx1 = bx0 + step < w ? bx0 + step : w;
            double n = (double)(by1 - by0) * (double)(bx1 - bx0);
            float *o = j->dst + ((size_t)my * mw + mx) * 2;
            o[0] = (float)(acc[2 * mx] / n);
            o[1] = (float)(acc[2 * mx + 1] / n);
        }
    }
    fx_mem_free(acc);
}

/* The moments at level `level` (0: every texel) into sm->moments. */
static fx_result make_moments(fx_context *ctx, fx_shadow_map *sm, int level, const char *where)
{
    int step = 1 << level;
    int mw = (sm->width + step - 1) / step, mh = (sm->height + step - 1) / step;
    float *m = fx_mem_alloc((size_t)mw * mh * 2 * sizeof(float));
    if (!m)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for a %d x %d shadow map's moments", where, mw,
                       mh);
    fx_mem_free(sm->moments);
    sm->moments = m;
    sm->mwidth = mw;
    sm->mheight = mh;
    sm->level = level;
    if (level == 0) {
        build_job j = {NULL, sm, sm->derivative_bias, NULL};
        fx_parallel_for(ctx, mh, fx_grain_for(ctx, mh), moment_rows, &j);
    } else {
        reduce_job j = {sm, m, mw, step};
        fx_parallel_for(ctx, mh, fx_grain_for(ctx, mh), reduce_rows, &j);
    }
    return FX_OK;
}

/* ---- the box: separable running sums in double ----
 * Each output is the mean of the texels of its (2r+1)^2 box inside the map (as the SAT box
 * it replaces: no replicated border). Per line a running sum in double: O(1) per texel
 * whatever the radius, each line by the same code whatever thread runs it (bit-identical
 * for any thread count), and no (w+1)(h+1)x2 table of doubles. Values are normalised
 * depths in [-1, 1] and their squares: the running sums keep ~1e-15 relative precision. */

typedef struct box_job {
    const float *src;        /* w x h x 2 moments, or NULL: the full-resolution moments of sm */
    const fx_shadow_map *sm; /* (src NULL) computed row by row from its depth ... */
    float *rows;             /* ... into one row of w x 2 floats per worker */
    float *dst;
    int w, h, r;
} box_job;

static void box_h_range(box_job *j, int y0, int y1, float *row)
{
    const int w = j->w, r = j->r;
    for (int y = y0; y < y1; y++) {
        const float *s = j->src ? j->src + (size_t)y * w * 2 : row;
        if (!j->src)
            for (int x = 0; x < w; x++)
                texel_moments(j->sm, x, y, &row[2 * x], &row[2 * x + 1]);
        float *d = j->dst + (size_t)y * w * 2;
        double a = 0.0, b = 0.0, inv = 1.0;
        int lo = 0, hi = 0, n = 0; /* the window [lo, hi), its size and 1 / size */
        for (int x = 0; x < w; x++) {
            int want_hi = x + r + 1 < w ? x + r + 1 : w, want_lo = x - r > 0 ? x - r : 0;
            for (; hi < want_hi; hi++) {
                a += s[2 * hi];
                b += s[2 * hi + 1];
            }
            for (; lo < want_lo; lo++) {
                a -= s[2 * lo];
                b -= s[2 * lo + 1];
            }
            if (hi - lo != n) { /* only near the ends of the line */
                n = hi - lo;
                inv = 1.0 / (double)n;
            }
            d[2 * x] = (float)(a * inv);
            d[2 * x + 1] = (float)(b * inv);
        }
    }
}

static void box_h_rows(void *user, int y0, int y1)
{
    box_h_range(user, y0, y1, NULL);
}

static void box_h_rows_fused(void *user, int y0, int y1, int worker)
{
    box_job *j = user;
    box_h_range(j, y0, y1, j->rows + (size_t)worker * j->w * 2);
}

#define BOX_COLS 64 /* columns per job of the vertical pass (running sums side by side) */

static void box_v_cols(void *user, int c0, int c1)
{
    box_job *j = user;
    const int w = j->w, h = j->h, r = j->r;
    double a[BOX_COLS * 2];
    for (int cb = c0; cb < c1; cb++) {
        int x0 = cb * BOX_COLS, x1 = x0 + BOX_COLS < w ? x0 + BOX_COLS : w, n = x1 - x0;
        memset(a, 0, sizeof a);
        int lo = 0, hi = 0;
        for (int y = 0; y < h; y++) {
            int want_hi = y + r + 1 < h ? y + r + 1 : h, want_lo = y - r > 0 ? y - r : 0;
            for (; hi < want_hi; hi++) {
                const float *s = j->src + ((size_t)hi * w + x0) * 2;
                for (int k = 0; k < 2 * n; k++)
                    a[k] += s[k];
            }
            for (; lo < want_lo; lo++) {
                const float *s = j->src + ((size_t)lo * w + x0) * 2;
                for (int k = 0; k < 2 * n; k++)
                    a[k] -= s[k];
            }
            double inv = 1.0 / (double)(hi - lo);
            float *d = j->dst + ((size_t)y * w + x0) * 2;
            for (int k = 0; k < 2 * n; k++)
                d[k] = (float)(a[k] * inv);
        }
    }
}

/* The box over the full-resolution moments computed on the fly (fused: no moments array
 * written and read back before the filter); the result lands in sm->moments. */
static fx_result box_from_depth(fx_context *ctx, fx_shadow_map *sm, int radius, const char *where)
{
    int w = sm->width, h = sm->height, workers = fx_parallel_workers(ctx);
    workers = workers > 0 ? workers : 1;
    size_t bytes = (size_t)w * h * 2 * sizeof(float);
    float *m = fx_mem_alloc(bytes), *tmp = fx_buffer_get(ctx, bytes);
    float *rows = fx_mem_alloc((size_t)workers * w * 2 * sizeof(float));
    if (!m || !tmp || !rows) {
        fx_mem_free(m);
        fx_mem_free(rows);
        if (tmp)
            fx_buffer_put(ctx, tmp, bytes);
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory filtering a %d x %d shadow map", where, w, h);
    }
    box_job j = {NULL, sm, rows, tmp, w, h, radius};
    fx_parallel_for_worker(ctx, h, fx_grain_for(ctx, h), box_h_rows_fused, &j);
    fx_mem_free(rows);
    box_job v = {tmp, NULL, NULL, m, w, h, radius};
    int blocks = (w + BOX_COLS - 1) / BOX_COLS;
    fx_parallel_for(ctx, blocks, 1, box_v_cols, &v);
    fx_buffer_put(ctx, tmp, bytes);
    fx_mem_free(sm->moments);
    sm->moments = m;
    sm->mwidth = w;
    sm->mheight = h;
    sm->level = 0;
    return FX_OK;
}

static fx_result box_filter(fx_context *ctx, float *m, int w, int h, int radius, const char *where)
{
    if (radius <= 0)
        return FX_OK;
    size_t bytes = (size_t)w * h * 2 * sizeof(float);
    float *tmp = fx_buffer_get(ctx, bytes);
    if (!tmp)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory filtering a %d x %d shadow map", where, w, h);
    box_job j = {m, NULL, NULL, tmp, w, h, radius};
    fx_parallel_for(ctx, h, fx_grain_for(ctx, h), box_h_rows, &j);
    box_job v = {tmp, NULL, NULL, m, w, h, radius};
    int blocks = (w + BOX_COLS - 1) / BOX_COLS;
    fx_parallel_for(ctx, blocks, 1, box_v_cols, &v);
    fx_buffer_put(ctx, tmp, bytes);
    return FX_OK;
}

fx_result fx_shadow_map_filter(fx_context *ctx, fx_shadow_map *sm, fx_shadow_filter filter, float width,
                               const char *where)
{
    int level = FX_SHADOW_FILTER_LEVEL((int)filter), kind = FX_SHADOW_FILTER_KIND((int)filter);
    if (level > FX_SHADOW_MAX_LEVEL)
        level = FX_SHADOW_MAX_LEVEL;
    if (sm->moments)
        level = sm->level; /* already made (filtered again: on the grid it has) */
    else if (level == 0 && kind == FX_SHADOW_FILTER_BOX_SAT && width > 1.0f && lrintf((width - 1.0f) * 0.5f) > 0)
        return box_from_depth(ctx, sm, (int)lrintf((width - 1.0f) * 0.5f), where);
    else {
        fx_result r = make_moments(ctx, sm, level, where);
        if (r)
            return r;
    }
    width /= (float)(1 << level);
    if (!(width > 1.0f))
        return FX_OK;
    if (kind == FX_SHADOW_FILTER_BOX_SAT) {
        int radius = (int)lrintf((width - 1.0f) * 0.5f);
        return box_filter(ctx, sm->moments, sm->mwidth, sm->mheight, radius, where);
    }
    fx_blur_spec spec = {width / sqrt(12.0), FX_BLUR_RECURSIVE, 3};
    return fx_blur_image(ctx, sm->moments, sm->moments, sm->mwidth, sm->mheight, 2, &spec, NULL, where);
}

void fx_shadow_map_free(fx_shadow_map *sm)
{
    if (!sm)
        return;
    fx_mem_free(sm->depth);
    fx_mem_free(sm->moments);
    fx_mem_free(sm->row_min);
    sm->depth = sm->moments = sm->row_min = NULL;
}

float fx_shadow_map_pcf_plane(const fx_shadow_map *sm, float px, float py, float t, int radius, float eps, float gx,
                              float gy)
{
    if (!(fabsf(gx) <= 1e30f && fabsf(gy) <= 1e30f)) /* NaN or overflowed slopes: no plane */
        gx = gy = 0.0f;
    int cx = (int)floorf(px), cy = (int)floorf(py);
    int x0 = cx - radius, x1 = cx + radius, y0 = cy - radius, y1 = cy + radius;
    x0 = x0 < 0 ? 0 : x0;
    y0 = y0 < 0 ? 0 : y0;
    x1 = x1 >= sm->width ? sm->width - 1 : x1;
    y1 = y1 >= sm->height ? sm->height - 1 : y1;
    const float e = eps + 0.5f * (fabsf(gx) + fabsf(gy));
    if (x1 < x0 || y1 < y0)
        return fx_shadow_map_hard(sm, px, py, t, e);
    int lit = 0, n = 0;
    for (int y = y0; y <= y1; y++) {
        const float *row = sm->depth + (size_t)y * sm->width;
        const float ty = t + gy * ((float)y + 0.5f - py);
        for (int x = x0; x <= x1; x++) {
            lit += ty + gx * ((float)x + 0.5f - px) <= row[x] + e;
            n++;
        }
    }
    return (float)lit / (float)n;
}
