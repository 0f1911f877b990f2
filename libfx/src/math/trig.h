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

#include "core/simd4.h"

#define FX_TRIG_PI 3.14159265358979323846f
#define FX_TRIG_PI_2 1.57079632679489661923f
#define FX_TRIG_PI_4 0.78539816339744830962f

/* fx_atan_pos's reduction thresholds and polynomial, shared by its four-lane form */
#define FX_ATAN_TAN_3PI_8 2.414213562f
#define FX_ATAN_TAN_PI_8 0.414213562f
#define FX_ATAN_P3 8.05374449538e-2f
#define FX_ATAN_P2 1.38776856032e-1f
#define FX_ATAN_P1 1.99777106478e-1f
#define FX_ATAN_P0 3.33329491539e-1f

/* atan(z) for z >= 0 (finite or +inf): reduced to |t| <= tan(pi/8) and an odd polynomial. */
static inline float fx_atan_pos(float z)
{
    float base = 0.0f, t = z;
    if (z > FX_ATAN_TAN_3PI_8) {
        base = FX_TRIG_PI_2;
        t = -1.0f / z;
    } else if (z > FX_ATAN_TAN_PI_8) {
        base = FX_TRIG_PI_4;
        t = (z - 1.0f) / (z + 1.0f);
    }
    float s = t * t;
    float p = ((FX_ATAN_P3 * s - FX_ATAN_P2) * s + FX_ATAN_P1) * s - FX_ATAN_P0;
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

/* fx_atan_pos and fx_atan2f_finite lane by lane: every branch computed, selects choose (the
 * same IEEE operations per lane, so the same bits; the probe march, math/panorama.c) */
static inline v4f fx_atan_pos4(v4f z)
{
    const v4i big = z > V4(FX_ATAN_TAN_3PI_8), mid = ~big & (z > V4(FX_ATAN_TAN_PI_8));
    v4f base = sel4(big, V4(FX_TRIG_PI_2), sel4(mid, V4(FX_TRIG_PI_4), V4(0.0f)));
    v4f num = sel4(big, V4(-1.0f), sel4(mid, z - V4(1.0f), z));
    v4f den = sel4(big, z, sel4(mid, z + V4(1.0f), V4(1.0f)));
    v4f t = num / den;
    v4f s = t * t;
    v4f p = ((V4(FX_ATAN_P3) * s - V4(FX_ATAN_P2)) * s + V4(FX_ATAN_P1)) * s - V4(FX_ATAN_P0);
    return base + (p * s * t + t);
}

static inline v4f fx_atan2f_finite4(v4f y, v4f x)
{
    const v4i sign = (v4i)V4(-0.0f);
    v4f ax = (v4f)((v4i)x & ~sign), ay = (v4f)((v4i)y & ~sign);
    v4i swap = ~(ay <= ax);
    v4f a = fx_atan_pos4(sel4(swap, ax, ay) / sel4(swap, ay, ax));
    a = sel4(swap, V4(FX_TRIG_PI_2) - a, a);
    a = sel4(x < V4(0.0f), V4(FX_TRIG_PI) - a, a);
    a = (v4f)((v4i)a ^ ((v4i)y & sign));
    return sel4((ax == V4(0.0f)) & (ay == V4(0.0f)), V4(0.0f), a);
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
