/* Colour helpers: Rec.709 luminance and the sRGB transfer functions (IEC 61966-2-1).
 * libfx works on Blender's scene-linear Rec.709 values; sRGB is for previews and for
 * effects defined on display values. All finite for finite input; never NaN. */
#ifndef LIBFX_MATH_COLOR_H
#define LIBFX_MATH_COLOR_H

#include <math.h>

/* Rec.709 / sRGB primaries, D65: Y = 0.2126 R + 0.7152 G + 0.0722 B. */
#define FX_LUMA_R 0.2126f
#define FX_LUMA_G 0.7152f
#define FX_LUMA_B 0.0722f

static inline float fx_luminance(float r, float g, float b)
{
    return FX_LUMA_R * r + FX_LUMA_G * g + FX_LUMA_B * b;
}

static inline float fx_luminance_rgb(const float *rgb)
{
    return fx_luminance(rgb[0], rgb[1], rgb[2]);
}

/* Linear -> sRGB-encoded. Negative values mirror (keeps the function odd and invertible);
 * NaN maps to 0. */
static inline float fx_srgb_encode(float v)
{
    if (!(v == v))
        return 0.0f;
    float a = v < 0 ? -v : v;
    float e = a <= 0.0031308f ? 12.92f * a : 1.055f * powf(a, 1.0f / 2.4f) - 0.055f;
    return v < 0 ? -e : e;
}

/* sRGB-encoded -> linear. Negative values mirror; NaN maps to 0. */
static inline float fx_srgb_decode(float v)
{
    if (!(v == v))
        return 0.0f;
    float a = v < 0 ? -v : v;
    float l = a <= 0.04045f ? a / 12.92f : powf((a + 0.055f) / 1.055f, 2.4f);
    if (!(l <= 3.4e38f))
        l = 3.4e38f; /* powf of a huge value overflows */
    return v < 0 ? -l : l;
}

static inline float fx_clamp01(float v)
{
    return v > 0.0f ? (v < 1.0f ? v : 1.0f) : 0.0f; /* NaN -> 0 */
}

#endif
