/* Summed-area tables: see sat.h. */
#include "math/sat.h"
#include "core/parallel.h"
#include "core/mem.h"

#include <float.h>
#include <math.h>
#include <string.h>

typedef struct sat_job {
    const float *src;
    fx_sat *s;
    double *row_sums; /* per row, per channel: sum of centred values (for nothing but checks) */
} sat_job;

/* Row prefix sums of the centred values into row y + 1 of the table. */
static void sat_rows(void *user, int y0, int y1)
{
    sat_job *j = user;
    fx_sat *s = j->s;
    const int c = s->channels, w = s->width;
    const size_t stride = (size_t)(w + 1) * c;
    for (int y = y0; y < y1; y++) {
        double acc[4] = {0, 0, 0, 0};
        const float *in = j->src + (size_t)y * w * c;
        double *out = s->sum + (size_t)(y + 1) * stride;
        for (int k = 0; k < c; k++)
            out[k] = 0.0;
        for (int x = 0; x < w; x++)
            for (int k = 0; k < c; k++) {
                float v = in[(size_t)x * c + k];
                acc[k] += isfinite(v) ? (double)v - s->mean[k] : 0.0;
                out[(size_t)(x + 1) * c + k] = acc[k];
            }
    }
}

/* Column prefix sums over a block of table columns (entries [e0, e1) of each row). */
static void sat_cols(void *user, int e0, int e1)
{
    sat_job *j = user;
    fx_sat *s = j->s;
    const size_t stride = (size_t)(s->width + 1) * s->channels;
    for (int y = 2; y <= s->height; y++) {
        double *row = s->sum + (size_t)y * stride;
        const double *prev = row - stride;
        for (int e = e0; e < e1; e++)
            row[e] += prev[e];
    }
}

typedef struct mean_job {
    const float *src;
    int width, channels;
    double *partial; /* per row */
} mean_job;

static void mean_rows(void *user, int y0, int y1)
{
    mean_job *j = user;
    for (int y = y0; y < y1; y++) {
        double acc[4] = {0, 0, 0, 0};
        const float *in = j->src + (size_t)y * j->width * j->channels;
        for (int x = 0; x < j->width; x++)
            for (int k = 0; k < j->channels; k++) {
                float v = in[(size_t)x * j->channels + k];
                if (isfinite(v))
                    acc[k] += v;
            }
        memcpy(j->partial + (size_t)y * 4, acc, sizeof acc);
    }
}

fx_result fx_sat_build(fx_context *ctx, const float *src, int width, int height, int channels, fx_sat *out,
                       const char *where)
{
    memset(out, 0, sizeof *out);
    if (width <= 0 || height <= 0 || channels < 1 || channels > 4)
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "%s: summed-area table of %d x %d x %d", where, width, height,
                       channels);
    size_t n;
    if (!fx_size_mul(&n, (size_t)width + 1, (size_t)height + 1, (size_t)channels * sizeof(double)))
        return fx_fail(ctx, FX_ERR_LIMIT, "%s: summed-area table too large", where);
    fx_result r = fx_check_budget(ctx, n, "summed-area table");
    if (r)
        return r;
    double *partial = fx_mem_alloc((size_t)height * 4 * sizeof(double));
    out->sum = fx_mem_alloc(n);
    if (!partial || !out->sum) {
        fx_mem_free(partial);
        fx_mem_free(out->sum);
        out->sum = NULL;
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for a %d x %d summed-area table", where, width,
                       height);
    }
    out->width = width;
    out->height = height;
    out->channels = channels;
    /* the mean: per-row sums (parallel), then rows added in order (deterministic) */
    mean_job mj = {src, width, channels, partial};
    fx_parallel_for(ctx, height, fx_grain_for(ctx, height), mean_rows, &mj);
    double tot[4] = {0, 0, 0, 0};
    for (int y = 0; y < height; y++)
        for (int k = 0; k < 4; k++)
            tot[k] += partial[(size_t)y * 4 + k];
    for (int k = 0; k < channels; k++)
        out->mean[k] = tot[k] / ((double)width * height);
    fx_mem_free(partial);
    memset(out->sum, 0, (size_t)(width + 1) * channels * sizeof(double)); /* row 0 */
    sat_job j = {src, out, NULL};
    fx_parallel_for(ctx, height, fx_grain_for(ctx, height), sat_rows, &j);
    int entries = (width + 1) * channels;
    fx_parallel_for(ctx, entries, 256, sat_cols, &j);
    return FX_OK;
}

void fx_sat_free(fx_sat *sat)
{
    if (sat) {
        fx_mem_free(sat->sum);
        sat->sum = NULL;
    }
}

typedef struct box_job {
    const fx_sat *s;
    float *dst;
    int radius;
} box_job;

static void box_rows(void *user, int y0, int y1)
{
    box_job *j = user;
    const fx_sat *s = j->s;
    const int c = s->channels, r = j->radius;
    for (int y = y0; y < y1; y++)
        for (int x = 0; x < s->width; x++) {
            double m[4];
            fx_sat_box_mean(s, x - r, y - r, x + r + 1, y + r + 1, m);
            float *o = j->dst + ((size_t)y * s->width + x) * c;
            for (int k = 0; k < c; k++)
                o[k] = (float)fmax(-FLT_MAX, fmin(FLT_MAX, m[k]));
        }
}

fx_result fx_sat_box_filter(fx_context *ctx, const float *src, float *dst, int width, int height, int channels,
                            int radius, const char *where)
{
    if (radius <= 0) {
        if (dst != src)
            memmove(dst, src, (size_t)width * height * channels * sizeof(float));
        return FX_OK;
    }
    fx_sat s;
    fx_result r = fx_sat_build(ctx, src, width, height, channels, &s, where);
    if (r)
        return r;
    box_job j = {&s, dst, radius};
    fx_parallel_for(ctx, height, fx_grain_for(ctx, height), box_rows, &j);
    fx_sat_free(&s);
    return FX_OK;
}
