/* The natural logarithm with the same bits on every C library, and fast everywhere.
 *
 * MinGW's logf goes through an x87 long-double log (about 6x glibc's time per call, which
 * made the per-pixel depth edges 2.6x slower on Windows), and C libraries need not agree
 * in the last bit. This uses only exact IEEE operations: x = 2^e m with m in
 * [sqrt(1/2), sqrt(2)), log m = 2 atanh(s), s = (m - 1) / (m + 1), |s| < 0.172, by its odd
 * series to s^15 in double (truncation below 1e-12 relative), rounded once to float. */
#ifndef LIBFX_MATH_LOG_H
#define LIBFX_MATH_LOG_H

#include <stdint.h>
#include <string.h>

/* log(x) for a positive, normal, finite x (callers clamp: no zero, denormal, Inf or NaN) */
static inline float fx_logf_pos(float x)
{
    uint32_t u;
    memcpy(&u, &x, sizeof u);
    int e = (int)(u >> 23) - 127;
    u = (u & 0x007fffffu) | 0x3f800000u;   /* the mantissa as a float in [1, 2) */
    float mf;
    memcpy(&mf, &u, sizeof mf);
    double m = mf;
    if (m > 1.4142135623730951) {
        m *= 0.5;
        e += 1;
    }
    const double s = (m - 1.0) / (m + 1.0), s2 = s * s;
    const double series =
        2.0 + s2 * (2.0 / 3 + s2 * (2.0 / 5 + s2 * (2.0 / 7 + s2 * (2.0 / 9 + s2 * (2.0 / 11 + s2 * (2.0 / 13 + s2 * (2.0 / 15)))))));
    return (float)((double)e * 0.69314718055994530942 + s * series);
}

#endif
