/* Quantising to N levels (math/levels.h). */
#include "math/levels.h"

#include "math/color.h"
#include "core/simd4.h"
#include "core/simd8.h"
#include "math/clones.h"

#include <float.h>
#include <string.h>

static double dec(double e, int srgb)
{
    if (!srgb)
        return e;
    return e <= 0.04045 ? e / 12.92 : pow((e + 0.055) / 1.055, 2.4);
}

static double enc(double u, int srgb)
{
    if (!srgb)
        return u;
    return u <= 0.0031308 ? 12.92 * u : 1.055 * pow(u, 1.0 / 2.4) - 0.055;
}

/* Smallest float >= t (t in (0, 1)), at least FLT_MIN. */
static float round_up(double t)
{
    if (!(t > (double)FLT_MIN))
        return FLT_MIN;
    float f = (float)t;
    if ((double)f < t)
        f = nextafterf(f, 2.0f);
    return f;
}

void fx_levels_init(fx_levels *q, int n, int srgb, float white, float dither, int keep_hdr)
{
    n = n < 2 ? 2 : n > FX_LEVELS_MAX ? FX_LEVELS_MAX : n;
    if (!(white > 0.0f) || !(white <= 3.4e38f))
        white = 1.0f;
    q->n = n;
    q->srgb = srgb;
    q->keep_hdr = keep_hdr;
    q->white = white;
    q->inv_white = 1.0f / white;
    q->dither = dither > 0.0f ? (dither < 1.0f ? dither : 1.0f) : 0.0f;
    q->phase_mask = q->dither > 0.0f ? 63 : 0;
    for (int k = 0; k < FX_LEVELS_MAX; k++) {
        int kk = k < n ? k : n - 1;
        q->value[k] = (float)(dec((double)kk / (n - 1), srgb) * white);
    }
    q->value[0] = 0.0f;
    for (int k = n - 1; k < FX_LEVELS_MAX; k++)
        q->value[k] = white;
    const int phases = q->phase_mask + 1;
    for (int b = 0; b < 64; b++) {
        float *t = q->thr[b];
        if (b < phases) {
            /* the dither of phase b: Bayer offset of the pixel (x, y) = (b & 7, b >> 3) */
            double delta = (double)q->dither * (double)fx_bayer8(b & 7, b >> 3);
            for (int j = 1; j < n; j++)
                t[j - 1] = round_up(dec(((double)j - delta) / n, srgb));
            for (int j = n; j <= FX_LEVELS_MAX; j++)
                t[j - 1] = INFINITY;
        } else {
            memcpy(t, q->thr[0], sizeof q->thr[0]);
        }
        for (int j = 0; j < FX_LEVELS_VEC; j++)
            for (int c = 0; c < 4; c++)
                q->thr4[b][j][c] = t[j];
    }
    for (int b = 0; b < 64; b++) {
        int b1 = (b & ~7) | ((b + 1) & 7); /* the next pixel's phase in the same row */
        for (int j = 0; j < FX_LEVELS_VEC; j++)
            for (int c = 0; c < 4; c++) {
                q->thr8[b][j][c] = q->thr[b][j];
                q->thr8[b][j][4 + c] = q->thr[b1][j];
            }
    }
}

float fx_levels_apply_reference(const fx_levels *q, float v, int x, int y)
{
    double u = (double)(v * q->inv_white);
    if (q->keep_hdr && u >= 1.0)
        return v < 3.4e38f ? v : 3.4e38f;
    if (!(u >= (double)FLT_MIN))
        return q->value[0];
    double d = q->phase_mask ? (double)q->dither * (double)fx_bayer8(x, y) : 0.0;
    double kf = floor(enc(u < 1.0 ? u : 1.0, q->srgb) * q->n + d);
    int k = kf < 0.0 ? 0 : kf > q->n - 1 ? q->n - 1 : (int)kf;
    return q->value[k];
}

/* One pixel (4 lanes): the tail of a row. */
static inline void pixel4(const fx_levels *q, const float *sp, float *dp, int ph, int gray, float mix)
{
    v4f s;
    memcpy(&s, sp, sizeof s);
    v4f v = s;
    if (gray) {
        float g = gray == 1 ? fx_luminance(s[0], s[1], s[2]) : (s[0] + s[1] + s[2]) * (1.0f / 3.0f);
        v = (v4f){ g, g, g, g };
    }
    const float iw = q->inv_white;
    const v4f u = v * (v4f){ iw, iw, iw, iw };
    v4f o = { 0, 0, 0, 0 };
    for (int c = 0; c < 3; c++)
        o[c] = q->value[fx_levels_band(q, u[c], ph)];
    const v4f top = { 3.4e38f, 3.4e38f, 3.4e38f, 3.4e38f };
    const v4i hdr = { -q->keep_hdr, -q->keep_hdr, -q->keep_hdr, -q->keep_hdr };
    o = sel4(hdr & (u >= (v4f){ 1, 1, 1, 1 }), sel4(v < top, v, top), o);
    if (mix < 1.0f)
        o = s + (v4f){ mix, mix, mix, mix } * (o - s);
    o = sel4((v4i){ 0, 0, 0, -1 }, s, o);
    o = finite4(o);
    memcpy(dp, &o, sizeof o);
}

/* The same as pixel4 on two pixels at once, SIMD chain (n <= FX_LEVELS_VEC). Same bits. */
FX_CLONES
void fx_levels_rgba_row(const fx_levels *q, const float *src, float *dst, int x0, int x1, int y,
                        int gray, float mix)
{
    const int nt = q->n - 1;
    const int pm = q->phase_mask;
    const int yph = (y & 7) << 3;
    int x = x0;
    if (nt < FX_LEVELS_VEC) {
        const float iw = q->inv_white;
        const v8f iw8 = { iw, iw, iw, iw, iw, iw, iw, iw }, one = { 1, 1, 1, 1, 1, 1, 1, 1 };
        const v8f top = { 3.4e38f, 3.4e38f, 3.4e38f, 3.4e38f, 3.4e38f, 3.4e38f, 3.4e38f, 3.4e38f };
        const int kh = -q->keep_hdr;
        const v8i hdr = { kh, kh, kh, kh, kh, kh, kh, kh };
        const v8i alpha = { 0, 0, 0, -1, 0, 0, 0, -1 };
        const v8f mix8 = { mix, mix, mix, mix, mix, mix, mix, mix };
        v8f val[FX_LEVELS_VEC];
        for (int j = 0; j < FX_LEVELS_VEC; j++) {
            float v = q->value[j];
            val[j] = (v8f){ v, v, v, v, v, v, v, v };
        }
        for (; x + 1 < x1; x += 2) {
            v8f s;
            memcpy(&s, src + 4 * (size_t)x, sizeof s);
            v8f v = s;
            if (gray) {
                float g0 = gray == 1 ? fx_luminance(s[0], s[1], s[2]) : (s[0] + s[1] + s[2]) * (1.0f / 3.0f);
                float g1 = gray == 1 ? fx_luminance(s[4], s[5], s[6]) : (s[4] + s[5] + s[6]) * (1.0f / 3.0f);
                v = (v8f){ g0, g0, g0, g0, g1, g1, g1, g1 };
            }
            const v8f u = v * iw8;
            const float(*t)[8] = q->thr8[(yph | (x & 7)) & pm];
            v8f o = { 0 };
            for (int j = 0; j < nt; j++) {
                v8f tj;
                memcpy(&tj, t[j], sizeof tj);
                o = SEL8(u >= tj, val[j + 1], o);
            }
            o = SEL8(hdr & (u >= one), SEL8(v < top, v, top), o);
            if (mix < 1.0f) {
                o = s + mix8 * (o - s);
                o = SEL8(alpha, s, o);
                o = fx_finite8(o);
            } else {
                o = SEL8(alpha, fx_finite8(s), o); /* o is finite already */
            }
            memcpy(dst + 4 * (size_t)x, &o, sizeof o);
        }
    }
    for (; x < x1; x++)
        pixel4(q, src + 4 * (size_t)x, dst + 4 * (size_t)x, (yph | (x & 7)) & pm, gray, mix);
}
