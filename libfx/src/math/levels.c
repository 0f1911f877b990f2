/* Quantising to N levels (math/levels.h). */
#include "math/levels.h"

#include "math/color.h"

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
    for (int k = 0; k < n; k++) {
        double t = (double)k / (n - 1);
        q->value[k] = (float)((srgb ? (double)fx_srgb_decode((float)t) : t) * white);
    }
    q->value[0] = 0.0f;
    q->value[n - 1] = white;
    if (srgb) {
        /* band edges in linear u: decode(k / n), k = 1..n-1 */
        float edges[FX_LEVELS_MAX + 1];
        for (int k = 1; k < n; k++)
            edges[k] = fx_srgb_decode((float)k / (float)n);
        edges[n] = 2.0f;
        int k = 0; /* band at the bucket's start */
        for (int i = 0; i < FX_LEVELS_LUT; i++) {
            float u0 = (float)i / (float)FX_LEVELS_LUT;
            float u1 = (float)(i + 1) / (float)FX_LEVELS_LUT;
            while (k + 1 < n && edges[k + 1] <= u0)
                k++;
            q->first[i] = (uint8_t)(k < 255 ? k : 255);
            q->edge[i] = (k + 1 < n && edges[k + 1] < u1) ? edges[k + 1] : 2.0f;
        }
    }
}

float fx_levels_apply_slow(const fx_levels *q, float v, float d)
{
    float u = v * q->inv_white;
    if (!(u > 0.0f))
        return q->value[0];
    if (u >= 1.0f)
        return q->keep_hdr ? (v < 3.4e38f ? v : 3.4e38f) : q->value[q->n - 1];
    float e = q->srgb ? fx_srgb_encode(u) : u;
    float kf = floorf(e * (float)q->n + d * q->dither);
    int k = kf < 0.0f ? 0 : kf > (float)(q->n - 1) ? q->n - 1 : (int)kf;
    return q->value[k];
}
