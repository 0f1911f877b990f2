/* Fast sRGB encoding (linear -> sRGB-encoded) for per-pixel fields (edge luminance): a table
 * over the float's exponent and top FX_SRGB_LUT_BITS mantissa bits, linearly interpolated,
 * instead of powf. Exact (the formula's linear segment, bit for bit) below 2^-9, exact at every
 * power of two, and within FX_SRGB_LUT_MAX_ERR (absolute, measured by test_edges over
 * [2^-9, 1]; relative above 1) of the double-precision formula elsewhere. Input: a finite value
 * in [0, FX_SRGB_LUT_MAX); callers clamp. */
#ifndef LIBFX_MATH_SRGB_LUT_H
#define LIBFX_MATH_SRGB_LUT_H

#include <stdint.h>
#include <string.h>

#define FX_SRGB_LUT_MIN_EXP (-9) /* 2^-9 = 0.00195, inside the formula's linear segment */
#define FX_SRGB_LUT_MAX_EXP 20   /* table up to 2^20 */
#define FX_SRGB_LUT_MAX 1048576.0f
#define FX_SRGB_LUT_BITS 7       /* 128 segments per octave */
#define FX_SRGB_LUT_SIZE (((FX_SRGB_LUT_MAX_EXP - FX_SRGB_LUT_MIN_EXP) << FX_SRGB_LUT_BITS) + 1)
#define FX_SRGB_LUT_MAX_ERR 2.5e-6f /* bound checked by the test (measured: see docs/effects/edges.md) */

/* The table (built once, thread-safely, on first call). */
const float *fx_srgb_lut(void);

/* a in [0, FX_SRGB_LUT_MAX); lut = fx_srgb_lut(). */
static inline float fx_srgb_encode_lut(const float *lut, float a)
{
    if (a < 0.001953125f) /* 2^-9 */
        return 12.92f * a;
    uint32_t b;
    memcpy(&b, &a, sizeof b);
    uint32_t i = (b >> (23 - FX_SRGB_LUT_BITS)) - ((uint32_t)(127 + FX_SRGB_LUT_MIN_EXP) << FX_SRGB_LUT_BITS);
    float t = (float)(b & ((1u << (23 - FX_SRGB_LUT_BITS)) - 1u)) * (1.0f / (float)(1u << (23 - FX_SRGB_LUT_BITS)));
    return lut[i] + t * (lut[i + 1] - lut[i]);
}

#endif
