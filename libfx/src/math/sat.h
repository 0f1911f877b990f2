/* Summed-area tables (Crow 1984) for box filters of any size at a cost independent of
 * the size. Values are centred (the image's mean per channel is subtracted
 * before summing) and accumulated in double: a float32 SAT of a 4096^2 image errs ~1e-2
 * and gives VSM negative variances; centred doubles err ~1e-12 relative there
 * (tests/c/test_vsm_shadows.c measures it). Non-finite inputs are taken as the mean (one
 * NaN would poison a whole quadrant). Built row prefix sums then column prefix sums, each
 * line by the same code whatever thread runs it: bit-identical for any thread count. */
#ifndef LIBFX_MATH_SAT_H
#define LIBFX_MATH_SAT_H

#include "core/context.h"
#include "core/rect.h"

typedef struct fx_sat {
    int width, height, channels;
    double mean[4];  /* subtracted before summing */
    double *sum;     /* (width + 1) * (height + 1) * channels; row 0 and column 0 are zero:
                        sum[(y * (width + 1) + x) * c + k] = sum over [0,x) x [0,y) */
} fx_sat;

/* Builds the table of `channels` (1..4) interleaved float pixels. */
fx_result fx_sat_build(fx_context *ctx, const float *src, int width, int height, int channels, fx_sat *out,
                       const char *where);
void fx_sat_free(fx_sat *sat);

/* Mean of channel values over the half-open box [x0, x1) x [y0, y1), clipped to the image
 * (an empty box gives the image mean). out has `channels` entries. */
static inline void fx_sat_box_mean(const fx_sat *s, int x0, int y0, int x1, int y1, double *out)
{
    x0 = x0 < 0 ? 0 : x0 > s->width ? s->width : x0;
    x1 = x1 < x0 ? x0 : x1 > s->width ? s->width : x1;
    y0 = y0 < 0 ? 0 : y0 > s->height ? s->height : y0;
    y1 = y1 < y0 ? y0 : y1 > s->height ? s->height : y1;
    const int c = s->channels;
    const size_t stride = (size_t)(s->width + 1);
    const double *a = s->sum + ((size_t)y0 * stride + (size_t)x0) * c;
    const double *b = s->sum + ((size_t)y0 * stride + (size_t)x1) * c;
    const double *d = s->sum + ((size_t)y1 * stride + (size_t)x0) * c;
    const double *e = s->sum + ((size_t)y1 * stride + (size_t)x1) * c;
    double n = (double)(x1 - x0) * (double)(y1 - y0);
    for (int k = 0; k < c; k++)
        out[k] = s->mean[k] + (n > 0 ? ((e[k] - b[k]) - (d[k] - a[k])) / n : 0.0);
}

/* Box filter of (2 radius + 1)^2 pixels through a SAT: dst (width x height x channels)
 * gets each pixel's box mean, the box clipped to the image (the mean of the pixels inside:
 * no replicated border). roi: NULL for all. dst may equal src. */
fx_result fx_sat_box_filter(fx_context *ctx, const float *src, float *dst, int width, int height, int channels,
                            int radius, const char *where);

#endif
