/* Equirectangular probe lookups (math/panorama.h). */
#include "math/panorama.h"
#include "core/simd4.h"
#include "math/clones.h"

#include <float.h>

void fx_pano_color(const fx_pano *p, fx_vec3 d, float rgb[3])
{
    float px, py;
    fx_pano_dir_to_pixel(d, p->w, p->h, &px, &py);
    float fx = px - 0.5f, fy = fx_clampf(py - 0.5f, 0.0f, (float)(p->h - 1));
    int x0 = (int)floorf(fx), y0 = (int)fy;
    float ax = fx - (float)x0, ay = fy - (float)y0;
    /* wrap horizontally: the seam at u = 0 / 1 is the view straight back */
    x0 = ((x0 % p->w) + p->w) % p->w;
    int x1 = x0 + 1 < p->w ? x0 + 1 : 0;
    int y1 = y0 + 1 < p->h ? y0 + 1 : y0;
    const float *a = p->color + ((size_t)y0 * p->w + x0) * 4, *b = p->color + ((size_t)y0 * p->w + x1) * 4;
    const float *c = p->color + ((size_t)y1 * p->w + x0) * 4, *e = p->color + ((size_t)y1 * p->w + x1) * 4;
    for (int k = 0; k < 3; k++) {
        float top = a[k] + (b[k] - a[k]) * ax, bot = c[k] + (e[k] - c[k]) * ax;
        rgb[k] = top + (bot - top) * ay;
    }
}

/* Whether probe-space point q lies in front of the probe's surface in its direction. */
static inline int in_front(const fx_pano *p, fx_vec3 q, float *gap)
{
    float dist = sqrtf(fx_v3_dot(q, q));
    float D = fx_pano_depth(p, q);
    *gap = dist - D; /* > 0: behind the surface the probe sees */
    return !(dist >= D);
}

fx_pano_trace_settings fx_pano_trace_setup(int steps, int refine, float min_distance, float max_distance,
                                           float thickness)
{
    fx_pano_trace_settings st = {steps < 1 ? 1 : steps, refine, min_distance, max_distance, thickness, 0, 0, 0};
    st.t0 = min_distance > 1e-4f ? min_distance : 1e-4f;
    st.tmax = max_distance > 2.0f * st.t0 ? max_distance : 2.0f * st.t0;
    st.growth = powf(st.tmax / st.t0, 1.0f / (float)st.steps);
    return st;
}

/* fx_clampf lane by lane */
static inline v4f clamp4(v4f v, float lo, float hi)
{
    return sel4(v < V4(lo), V4(lo), sel4(v > V4(hi), V4(hi), v));
}

/* Four march steps at once: the lanes of in_front for the points po + t pd, with the same
 * IEEE operations as the scalar path (fx_pano_depth, fx_atan2f_finite; ISO C contracts
 * nothing and there is no FMA), so the same texel and the same bits per lane. Branches
 * become selects: every lane computes each branch's operands and one division takes the
 * chosen ones (x / 1 and 0 + x are exact, so the untaken forms change no bit; math/trig.h's
 * fx_atan2f_finite4). front: the lanes in front of the surface (all ones); gap: dist - D. */
static inline v4i in_front4(const fx_pano *p, fx_vec3 po, fx_vec3 pd, v4f t, v4f *gap)
{
    v4f qx = V4(po.x) + V4(pd.x) * t, qy = V4(po.y) + V4(pd.y) * t, qz = V4(po.z) + V4(pd.z) * t;
    v4f dist = sqrt4(qx * qx + qy * qy + qz * qz);
    const float fw = (float)p->w, fh = (float)p->h;
    v4f u = V4(0.5f) - fx_atan2f_finite4(-qx, -qz) / V4(2.0f * FX_PANO_PI);
    v4f cy = clamp4(qy / dist, -1.0f, 1.0f);
    v4f v = fx_atan2f_finite4(sqrt4((V4(1.0f) - cy) * (V4(1.0f) + cy)), cy) / V4(FX_PANO_PI);
    v4i ok = (dist > V4(1e-30f)) & (dist <= V4(FLT_MAX)); /* fx_pano_dir_to_pixel's test */
    v4f px = sel4(ok, clamp4(u, 0.0f, 1.0f) * V4(fw), V4(0.5f * fw));
    v4f py = sel4(ok, clamp4(v, 0.0f, 1.0f) * V4(fh), V4(0.5f * fh));
    v4i x = __builtin_convertvector(px, v4i), y = __builtin_convertvector(py, v4i);
    float d[4];
    for (int k = 0; k < 4; k++) {
        int xx = x[k] < 0 ? 0 : x[k] >= p->w ? p->w - 1 : x[k];
        int yy = y[k] < 0 ? 0 : y[k] >= p->h ? p->h - 1 : y[k];
        d[k] = p->depth[(size_t)yy * p->w + xx];
    }
    v4f D = ld4(d);
    D = sel4((D > V4(0.0f)) & (D < V4(6.0e4f)), D, V4(INFINITY));
    *gap = dist - D;
    return ~(dist >= D);
}

/* an AVX2 clone: VEX's three-operand forms drop the register copies of the selects */
FX_CLONES int fx_pano_trace(const fx_pano *p, const fx_pano_trace_settings *st, fx_vec3 o, fx_vec3 dir,
                            float rgb[3])
{
    fx_vec3 po = fx_m4_point(p->to_probe, o);
    fx_vec3 pd = fx_m4_dir(p->to_probe, dir);
    if (!isfinite(po.x + po.y + po.z + pd.x + pd.y + pd.z)) {
        fx_pano_color(p, fx_v3(0.0f, 0.0f, -1.0f), rgb);
        return 0;
    }
    pd = fx_v3_normalize_or(pd, fx_v3(0.0f, 0.0f, -1.0f));
    const int steps = st->steps;
    const float g = st->growth;
    float gap;
    int prev_front = in_front(p, po, &gap);
    float prev_t = 0.0f, t = st->t0;
    for (int k0 = 0; k0 < steps; k0 += 4) {
        /* t_k = t_{k-1} g as the one-step loop multiplied it */
        float ts[4];
        for (int l = 0; l < 4; l++, t *= g)
            ts[l] = t;
        v4f gaps;
        v4i front = in_front4(p, po, pd, ld4(ts), &gaps);
        const int n = steps - k0 < 4 ? steps - k0 : 4;
        if (n == 4 && all4(front)) {
            prev_front = 1; /* no crossing: every step in front */
            prev_t = ts[3];
            continue;
        }
        for (int l = 0; l < n; l++) {
            const float tl = ts[l];
            if (prev_front && !front[l] && gaps[l] <= st->thickness + (tl - prev_t)) {
                float lo = prev_t, hi = tl;
                for (int r = 0; r < st->refine; r++) {
                    float mid = 0.5f * (lo + hi), gm;
                    if (in_front(p, fx_v3_add(po, fx_v3_scale(pd, mid)), &gm))
                        lo = mid;
                    else
                        hi = mid;
                }
                fx_pano_color(p, fx_v3_add(po, fx_v3_scale(pd, hi)), rgb);
                return 1;
            }
            prev_front = front[l] != 0;
            prev_t = tl;
        }
    }
    fx_pano_color(p, pd, rgb);
    return 0;
}
