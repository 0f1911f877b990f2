/* Equirectangular probe lookups (math/panorama.h). */
#include "math/panorama.h"

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

int fx_pano_trace(const fx_pano *p, const fx_pano_trace_settings *st, fx_vec3 o, fx_vec3 dir, float rgb[3])
{
    fx_vec3 po = fx_m4_point(p->to_probe, o);
    fx_vec3 pd = fx_m4_dir(p->to_probe, dir);
    if (!isfinite(po.x + po.y + po.z + pd.x + pd.y + pd.z)) {
        fx_pano_color(p, fx_v3(0.0f, 0.0f, -1.0f), rgb);
        return 0;
    }
    pd = fx_v3_normalize_or(pd, fx_v3(0.0f, 0.0f, -1.0f));
    const int steps = st->steps;
    const float t0 = st->t0, g = st->growth;
    float gap;
    int prev_front = in_front(p, po, &gap);
    float prev_t = 0.0f, t = t0;
    for (int k = 0; k < steps; k++, t *= g) {
        int front = in_front(p, fx_v3_add(po, fx_v3_scale(pd, t)), &gap);
        if (prev_front && !front && gap <= st->thickness + (t - prev_t)) {
            float lo = prev_t, hi = t;
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
        prev_front = front;
        prev_t = t;
    }
    fx_pano_color(p, pd, rgb);
    return 0;
}
