/* Quantising values to N levels (posterize, sin_city, the seed's banding), in linear or
 * sRGB-encoded steps, with optional ordered (8x8 Bayer) dithering.
 *
 * u = v / white. Band k = floor(e(u) * N + delta), clamped to [0, N-1], where e is the
 * identity (linear) or the sRGB encoding and delta = dither x the pixel's Bayer offset; the
 * band's value is white * e^-1(k / (N-1)), so black stays 0, white stays white, and a ramp
 * over [0, white] takes exactly N values. Values above white are kept as they are when
 * keep_hdr (highlights survive for a following bloom), else they take the top level;
 * values <= 0 (and below FLT_MIN) and NaN take level 0.
 *
 * No encoding per pixel: band k is the number of thresholds t_j <= u, with
 * t_j = e^-1((j - delta) / N) computed once in double and rounded up to float, so
 * `u >= t_j` is exactly `e(u) N + delta >= j` evaluated in exact arithmetic (no
 * approximation error: the band edges are the formula's, for every Bayer phase). Without
 * dither all 64 phases share one row of thresholds. N <= FX_LEVELS_VEC runs a branch-free
 * compare/select chain over whole RGBA pixels in SIMD vectors (fx_levels_rgba_row); larger N
 * a branch-free binary search. */
#ifndef LIBFX_MATH_LEVELS_H
#define LIBFX_MATH_LEVELS_H

#include <math.h>
#include <stdint.h>

#define FX_LEVELS_MAX 256
#define FX_LEVELS_VEC 16 /* N up to this: the SIMD chain (N - 1 <= 15 thresholds) */

typedef struct fx_levels {
    int n;          /* levels, 2..FX_LEVELS_MAX */
    int srgb;       /* steps in sRGB-encoded values */
    int keep_hdr;
    int phase_mask; /* 63 with dither, 0 without */
    float white, inv_white;
    float dither;   /* 0..1: amplitude of the ordered dither, in bands */
    float value[FX_LEVELS_MAX];               /* linear output per band (times white) */
    /* thresholds per Bayer phase ((y & 7) * 8 + (x & 7)), padded with +Inf to 256 */
    float thr[64][FX_LEVELS_MAX];
    /* the same, 4 copies each, for the SIMD chain (N <= FX_LEVELS_VEC) */
    float thr4[64][FX_LEVELS_VEC][4] __attribute__((aligned(16)));
    /* pixel pairs (x, x + 1) from phase of x: thr of x (4 copies) then of x + 1 (4 copies) */
    float thr8[64][FX_LEVELS_VEC][8] __attribute__((aligned(32)));
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

/* Band of u (= v / white) at Bayer phase `phase` (already masked). */
static inline int fx_levels_band(const fx_levels *q, float u, int phase)
{
    const float *t = q->thr[phase];
    int k = 0;
    if (q->n <= FX_LEVELS_VEC) {
        for (int j = 0; j < q->n - 1; j++)
            k += u >= t[j];
        return k;
    }
    /* branch-free binary search over 255 thresholds (+Inf padded): largest k with t[k-1] <= u */
    for (int step = 128; step >= 1; step >>= 1)
        k += (u >= t[k + step - 1]) ? step : 0;
    return k;
}

/* Quantises v at pixel (x, y). */
static inline float fx_levels_apply(const fx_levels *q, float v, int x, int y)
{
    const float u = v * q->inv_white;
    if (q->keep_hdr && u >= 1.0f)
        return v < 3.4e38f ? v : 3.4e38f;
    return q->value[fx_levels_band(q, u, (((y & 7) << 3) | (x & 7)) & q->phase_mask)];
}

/* Quantises pixels x0..x1-1 of one RGBA row (src, dst point at the row's pixel 0) at image
 * row y. gray: 0 each of R, G, B; 1 Rec.709 luminance; 2 the mean (R+G+B)/3, quantised and
 * written to all three. mix < 1 blends from the source. Alpha passes (NaN -> 0, +-Inf ->
 * +-FLT_MAX); the output is always finite. */
void fx_levels_rgba_row(const fx_levels *q, const float *src, float *dst, int x0, int x1, int y,
                        int gray, float mix);

/* Reference (slow) quantiser: the formula with the sRGB encoding per value, in double. For
 * tests: equal to fx_levels_apply except within 1e-12 (relative) of a band edge. */
float fx_levels_apply_reference(const fx_levels *q, float v, int x, int y);

#endif
