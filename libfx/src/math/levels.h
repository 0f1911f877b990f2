/* Quantising values to N levels (posterize, sin_city, the seed's banding), in linear or
 * sRGB-encoded steps, with optional ordered (8x8 Bayer) dithering.
 *
 * u = v / white. Band k = floor(e(u) * N + dither), clamped to [0, N-1], where e is the
 * identity (linear) or the sRGB encoding; the band's value is white * e^-1(k / (N-1)), so
 * black stays 0, white stays white, and a ramp over [0, white] takes exactly N values.
 * Values above white are kept as they are when keep_hdr (highlights survive for a following
 * bloom), else they take the top level; values <= 0 and NaN take level 0.
 * Without dither the sRGB case runs from tables (FX_LEVELS_LUT buckets over [0, 1], each
 * holding at most one band edge for N <= 256): k = first[i] + (u >= edge[i]), exact to
 * the band edges decode(k/N) and branch-free; with dither it encodes per value (powf). */
#ifndef LIBFX_MATH_LEVELS_H
#define LIBFX_MATH_LEVELS_H

#include <math.h>
#include <stdint.h>

#define FX_LEVELS_MAX 256
#define FX_LEVELS_LUT 8192

typedef struct fx_levels {
    int n;          /* levels, 2..FX_LEVELS_MAX */
    int srgb;       /* steps in sRGB-encoded values */
    int keep_hdr;
    float white, inv_white;
    float dither;   /* 0..1: amplitude of the ordered dither, in bands */
    float value[FX_LEVELS_MAX];        /* linear output per band (times white) */
    uint8_t first[FX_LEVELS_LUT];      /* sRGB: band at each bucket's start */
    float edge[FX_LEVELS_LUT];         /* sRGB: the band edge inside the bucket, or 2 */
} fx_levels;

/* n clamped to [2, FX_LEVELS_MAX]; white <= 0 or not finite reads as 1. */
void fx_levels_init(fx_levels *q, int n, int srgb, float white, float dither, int keep_hdr);

/* The ordered-dither offset of pixel (x, y), in [-0.5, 0.5). */
static inline float fx_bayer8(int x, int y)
{
    static const uint8_t m[8][8] = {
        { 0, 32, 8, 40, 2, 34, 10, 42 },   { 48, 16, 56, 24, 50, 18, 58, 26 },
        { 12, 44, 4, 36, 14, 46, 6, 38 },  { 60, 28, 52, 20, 62, 30, 54, 22 },
        { 3, 35, 11, 43, 1, 33, 9, 41 },   { 51, 19, 59, 27, 49, 17, 57, 25 },
        { 15, 47, 7, 39, 13, 45, 5, 37 },  { 63, 31, 55, 23, 61, 29, 53, 21 } };
    return ((float)m[y & 7][x & 7] + 0.5f) * (1.0f / 64.0f) - 0.5f;
}

/* Quantises v; d is the pixel's dither offset (fx_bayer8), ignored when q->dither is 0. */
float fx_levels_apply_slow(const fx_levels *q, float v, float d);

static inline float fx_levels_apply(const fx_levels *q, float v, float d)
{
    float u = v * q->inv_white;
    if (!(u > 0.0f))
        return q->value[0];
    if (u >= 1.0f)
        return q->keep_hdr ? (v < 3.4e38f ? v : 3.4e38f) : q->value[q->n - 1];
    if (q->dither > 0.0f)
        return fx_levels_apply_slow(q, v, d);
    int k;
    if (q->srgb) {
        int i = (int)(u * (float)FX_LEVELS_LUT);
        i = i < FX_LEVELS_LUT - 1 ? i : FX_LEVELS_LUT - 1;
        k = q->first[i] + (u >= q->edge[i]);
    } else {
        k = (int)(u * (float)q->n);
    }
    k = k < q->n - 1 ? k : q->n - 1;
    return q->value[k];
}

#endif
