/* Inverse trigonometry with the same bits on every C library.
 *
 * glibc's atanf, atan2f and acosf changed in 2.41 (correctly rounded versions): Debian 12's
 * 2.36 and Debian 13's 2.41 give different last bits for the same input, and libfx's output
 * must not depend on the machine it runs on. These use only +, -, *, / and sqrtf (exact
 * IEEE operations everywhere) and a fixed polynomial; error below 2e-7 rad, ample for
 * texture lookups and angle thresholds. */
#ifndef LIBFX_MATH_TRIG_H
#define LIBFX_MATH_TRIG_H

#include <math.h>

#define FX_TRIG_PI 3.14159265358979323846f
#define FX_TRIG_PI_2 1.57079632679489661923f
#define FX_TRIG_PI_4 0.78539816339744830962f

/* atan(z) for z >= 0 (finite or +inf): reduced to |t| <= tan(pi/8) and an odd polynomial. */
static inline float fx_atan_pos(float z)
{
    float base = 0.0f, t = z;
    if (z > 2.414213562f) { /* tan(3 pi / 8) */
        base = FX_TRIG_PI_2;
        t = -1.0f / z;
    } else if (z > 0.414213562f) { /* tan(pi / 8) */
        base = FX_TRIG_PI_4;
        t = (z - 1.0f) / (z + 1.0f);
    }
    float s = t * t;
    float p = ((8.05374449538e-2f * s - 1.38776856032e-1f) * s + 1.99777106478e-1f) * s - 3.33329491539e-1f;
    return base + (p * s * t + t);
}

/* atan2(y, x) in [-pi, pi] for finite y and x (callers that know them finite skip the
 * NaN and infinity tests: the probe lookup); 0 for (0, 0). */
static inline float fx_atan2f_finite(float y, float x)
{
    float ax = fabsf(x), ay = fabsf(y);
    if (ax == 0.0f && ay == 0.0f)
        return 0.0f;
    float a = ay <= ax ? fx_atan_pos(ay / ax) : FX_TRIG_PI_2 - fx_atan_pos(ax / ay);
    if (x < 0.0f)
        a = FX_TRIG_PI - a;
    return signbit(y) ? -a : a;
}

/* atan2(y, x) in [-pi, pi]; 0 for (0, 0); NaN in, NaN out. */
static inline float fx_atan2f(float y, float x)
{
    if (isnan(x) || isnan(y))
        return NAN;
    if (!isinf(x) && !isinf(y))
        return fx_atan2f_finite(y, x);
    float a = fabsf(y) <= fabsf(x) ? (isinf(y) ? FX_TRIG_PI_4 : 0.0f) : FX_TRIG_PI_2;
    if (x < 0.0f)
        a = FX_TRIG_PI - a;
    return signbit(y) ? -a : a;
}

/* acos(c) for c in [-1, 1] (clamped), in [0, pi]. */
static inline float fx_acosf(float c)
{
    if (isnan(c))
        return NAN;
    c = c < -1.0f ? -1.0f : c > 1.0f ? 1.0f : c;
    return fx_atan2f(sqrtf((1.0f - c) * (1.0f + c)), c);
}

#endif
