/* Equirectangular probe lookups (math/panorama.h). */
#include "math/panorama.h"
#include "core/simd4.h"
#include "math/clones.h"

#include <float.h>

/* Image img (RGBA, the probe's size) along probe-space direction d: bilinear, wrapping
 * around horizontally and clamped at the poles. */
static void pano_bilinear(const fx_pano *p, const float *img, fx_vec3 d, float rgb[3])
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
    const float *a = img + ((size_t)y0 * p->w + x0) * 4, *b = img + ((size_t)y0 * p->w + x1) * 4;
    const float *c = img + ((size_t)y1 * p->w + x0) * 4, *e = img + ((size_t)y1 * p->w + x1) * 4;
    for (int k = 0; k < 3; k++) {
        float top = a[k] + (b[k] - a[k]) * ax, bot = c[k] + (e[k] - c[k]) * ax;
        rgb[k] = top + (bot - top) * ay;
    }
}

void fx_pano_color(const fx_pano *p, fx_vec3 d, float rgb[3])
{
    pano_bilinear(p, p->color, d, rgb);
}

/* The fill for a ray whose hit is hidden from the probe (a disocclusion: it passed behind an
 * occluder the probe sees and never came out). The hidden surface is estimated as the
 * background beside the occluder continued behind it: the ray's point at the background's
 * radial depth there (the texel of the last point t_front where the probe saw the ray in
 * front of the background). Its colour is the probe's background around that point's
 * direction: a weighted mean of the centre (weight 256) and rings of 12 samples at 4, 8,
 * 16 and 32 texel angles (weights 64, 16, 4, 1 per sample: 1 / angle^2, the nearest
 * background first), counting only samples whose surface lies no nearer than that point
 * (less 10 %): the occluder itself, nearer, never counts, nor the sky beside a surface.
 * With the sky beside the silhouette the hidden point is at infinity: the probe's world
 * image along the ray's direction where the add-on rendered one (fx_pano.sky), else the
 * rings around the silhouette point, the sky's samples only. The result is smooth in the ray, so it cannot
 * streak: every ray that passes behind the occluder gets a mean of the background around
 * its own hidden point, not the one texel beside the silhouette where it disappeared
 * (before: stretched bands of that texel, and of the silhouette's anti-aliased colour,
 * along the rays). No background sample at all: the same samples' plain mean. */
#define FILL_RINGS 4
/* A sample of the hidden point's background: a surface no nearer than `near` (the sky
 * does not continue a surface), or, beside the sky (near = +inf), the sky. */
static inline int fill_background(float D, float near)
{
    return isfinite(near) ? D >= near && isfinite(D) : !isfinite(D);
}

#define FILL_DIRS 12
/* A fill sample at direction d: the bilinear colour over the four texels around d that are
 * the hidden point's background (each texel's depth tested, its bilinear weight kept), so
 * the occluder's texels never blend into a background sample and the mean moves smoothly
 * with the ray (nearest texels made bands a texel wide across the grazing mirror's sky;
 * a plain bilinear colour blends the occluder into the samples beside it).
 * rgb_bg: the masked sum (weights included), rgb_all: the plain bilinear colour. Returns
 * the background's share of the weight (0..1). */
static float fill_sample(const fx_pano *p, fx_vec3 d, float near, float rgb_bg[3], float rgb_all[3])
{
    float px, py;
    fx_pano_dir_to_pixel(d, p->w, p->h, &px, &py);
    float fx = px - 0.5f, fy = fx_clampf(py - 0.5f, 0.0f, (float)(p->h - 1));
    int x0 = (int)floorf(fx), y0 = (int)fy;
    float ax = fx - (float)x0, ay = fy - (float)y0;
    x0 = ((x0 % p->w) + p->w) % p->w;
    const int xs[2] = { x0, x0 + 1 < p->w ? x0 + 1 : 0 }, ys[2] = { y0, y0 + 1 < p->h ? y0 + 1 : y0 };
    const float wx[2] = { 1.0f - ax, ax }, wy[2] = { 1.0f - ay, ay };
    float wbg = 0.0f;
    for (int k = 0; k < 3; k++)
        rgb_bg[k] = rgb_all[k] = 0.0f;
    for (int j = 0; j < 2; j++)
        for (int i = 0; i < 2; i++) {
            const size_t t = (size_t)ys[j] * p->w + xs[i];
            const float wt = wx[i] * wy[j], *c = p->color + t * 4, v = p->depth[t];
            int bg = fill_background(v > 0.0f && v < 6.0e4f ? v : INFINITY, near);
            if (bg && !isfinite(near)) {
                /* the sky beside the silhouette: only sky texels whose four neighbours are sky
                 * (the silhouette's texels blend the occluder's anti-aliased colour into the
                 * sky, and the rings' centre sits on the silhouette here: drawn out along the
                 * rays they made a fan of light and dark bands in the grazing mirror's sky) */
                static const int nb[4][2] = { { -1, 0 }, { 1, 0 }, { 0, -1 }, { 0, 1 } };
                for (int q = 0; q < 4 && bg; q++) {
                    int xx = (xs[i] + nb[q][0] + p->w) % p->w, yy = ys[j] + nb[q][1];
                    yy = yy < 0 ? 0 : yy >= p->h ? p->h - 1 : yy;
                    float u = p->depth[(size_t)yy * p->w + xx];
                    bg = fill_background(u > 0.0f && u < 6.0e4f ? u : INFINITY, near);
                }
            }
            for (int k = 0; k < 3; k++) {
                rgb_all[k] += wt * c[k];
                rgb_bg[k] += bg ? wt * c[k] : 0.0f;
            }
            wbg += bg ? wt : 0.0f;
        }
    return wbg;
}

static void hidden_fill(const fx_pano *p, fx_vec3 po, fx_vec3 pd, float t_front, float rgb[3])
{
    /* cos and sin of k x 15 deg: a ring's 12 directions at 30 deg, odd rings turned 15 deg */
    static const float cs[24][2] = {
        { 1.0f, 0.0f }, { 0.96592583f, 0.25881905f }, { 0.86602540f, 0.5f }, { 0.70710678f, 0.70710678f },
        { 0.5f, 0.86602540f }, { 0.25881905f, 0.96592583f }, { 0.0f, 1.0f }, { -0.25881905f, 0.96592583f },
        { -0.5f, 0.86602540f }, { -0.70710678f, 0.70710678f }, { -0.86602540f, 0.5f },
        { -0.96592583f, 0.25881905f }, { -1.0f, 0.0f }, { -0.96592583f, -0.25881905f },
        { -0.86602540f, -0.5f }, { -0.70710678f, -0.70710678f }, { -0.5f, -0.86602540f },
        { -0.25881905f, -0.96592583f }, { 0.0f, -1.0f }, { 0.25881905f, -0.96592583f },
        { 0.5f, -0.86602540f }, { 0.70710678f, -0.70710678f }, { 0.86602540f, -0.5f },
        { 0.96592583f, -0.25881905f } };
    fx_vec3 qf = fx_v3_add(po, fx_v3_scale(pd, t_front));
    float dbg = fx_pano_depth(p, qf); /* the background beside the silhouette */
    if (!isfinite(dbg) && p->sky) {
        /* the sky beside the silhouette: the ray meets the sky, at infinity along pd */
        pano_bilinear(p, p->sky, pd, rgb);
        return;
    }
    float tc = t_front;
    if (isfinite(dbg)) {
        /* |po + t pd| = dbg, the root past t_front (pd unit) */
        float b = fx_v3_dot(po, pd), c = fx_v3_dot(po, po) - dbg * dbg, disc = b * b - c;
        float t = disc >= 0.0f ? -b + sqrtf(disc) : t_front;
        if (t > t_front && isfinite(t))
            tc = t;
    }
    fx_vec3 q = fx_v3_add(po, fx_v3_scale(pd, tc));
    float dist = sqrtf(fx_v3_dot(q, q));
    /* around the hidden point's direction (the sky beside the silhouette: tc = t_front,
     * the silhouette point; its sky samples are the sky nearest the ray's direction) */
    fx_vec3 c = fx_v3_normalize_or(q, pd);
    /* an orthonormal frame around c */
    fx_vec3 a = fabsf(c.y) < 0.9f ? fx_v3(0.0f, 1.0f, 0.0f) : fx_v3(1.0f, 0.0f, 0.0f);
    fx_vec3 e1 = fx_v3_normalize_or(fx_v3_cross(a, c), fx_v3(1.0f, 0.0f, 0.0f));
    fx_vec3 e2 = fx_v3_cross(c, e1);
    const float texel = 2.0f * FX_PANO_PI / (float)(p->w > p->h ? p->w : 2 * p->h);
    const float near = isfinite(dbg) ? 0.9f * dist : INFINITY;
    double sum[3] = { 0, 0, 0 }, wsum = 0, all[3] = { 0, 0, 0 }, wall = 0;
    for (int r = -1; r < FILL_RINGS; r++) {
        /* r = -1: the centre itself (weight 256); then the rings */
        float ang = r < 0 ? 0.0f : fminf(texel * (float)(4 << r), 1.2f);
        float ca = cosf(ang), sa = sinf(ang), wr = r < 0 ? 256.0f : (float)(64 >> (2 * r));
        for (int k = 0; k < (r < 0 ? 1 : FILL_DIRS); k++) {
            const float *e = cs[2 * k + (r & 1)];
            fx_vec3 d = r < 0 ? c
                              : fx_v3_add(fx_v3_scale(c, ca),
                                          fx_v3_add(fx_v3_scale(e1, sa * e[0]), fx_v3_scale(e2, sa * e[1])));
            float bgc[3], allc[3];
            float wb = fill_sample(p, d, near, bgc, allc);
            for (int ch = 0; ch < 3; ch++) {
                all[ch] += (double)(wr * allc[ch]);
                sum[ch] += (double)(wr * bgc[ch]); /* the occluder's texels (nearer than the hidden
                                                      point), or the sky beside a surface: weight 0 */
            }
            wall += wr;
            wsum += (double)(wr * wb);
        }
    }
    for (int ch = 0; ch < 3; ch++)
        rgb[ch] = (float)(wsum > 1e-6 ? sum[ch] / wsum : all[ch] / wall);
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

/* A crossing between march points a (in front of the probe's surface) and b (behind it),
 * refined by bisection: 1 and *t_hit if the ray meets the surface there. The refined point
 * must lie behind the surface of its texel by no more than the thickness, the bracket's
 * length and the depth step between neighbouring texels of a surface seen obliquely from
 * the probe (4 texel angles x its distance: up to 76 deg). Further behind, the bracket
 * straddles a silhouette: the ray passed behind an occluder (in front of the background
 * on one side, behind the occluder's front on the other), which is not a hit, however
 * long the step that found it (a long step's slack let rays passing half a metre behind
 * a block near the probe take its colour: the probe's own smear). */
static int refined_crossing(const fx_pano *p, const fx_pano_trace_settings *st, fx_vec3 po, fx_vec3 pd, float a,
                            float b, float *t_hit, float *t_front)
{
    float lo = a, hi = b, gm;
    for (int r = 0; r < st->refine; r++) {
        float mid = 0.5f * (lo + hi);
        if (in_front(p, fx_v3_add(po, fx_v3_scale(pd, mid)), &gm))
            lo = mid;
        else
            hi = mid;
    }
    fx_vec3 q = fx_v3_add(po, fx_v3_scale(pd, hi));
    in_front(p, q, &gm);
    float dist = sqrtf(fx_v3_dot(q, q));
    float texel = 2.0f * FX_PANO_PI / (float)(p->w > p->h ? p->w : 2 * p->h);
    if (!(gm <= st->thickness + (hi - lo) + 4.0f * texel * (dist - gm))) {
        *t_front = lo; /* the last point the probe saw in front of the background */
        return 0;
    }
    *t_hit = hi;
    return 1;
}

/* The march of fx_pano_trace: 1 and *t_hit (the crossing, refined) for a hit; 2 and *t_hit
 * for a ray that passed behind an occluder (seen from the probe), or started behind one,
 * and is still behind it when the march ends (a ray that comes out in front again, into the sky or a room too
 * big for the march, is the far lookup's as any other): its hit is hidden from the probe,
 * and *t_hit is the last point of the ray in front of the background beside the occluder's
 * silhouette, where hidden_fill starts (the ray's direction from the probe would look at
 * the occluder itself, drawing it out over every ray that passes behind it); 0 for none,
 * -1 for a non-finite ray. *po_out, *pd_out: the ray in the probe's space (pd unit). An
 * AVX2 clone: VEX's three-operand forms drop the register copies of the selects. */
FX_CLONES static int pano_march(const fx_pano *p, const fx_pano_trace_settings *st, fx_vec3 o, fx_vec3 dir,
                                fx_vec3 *po_out, fx_vec3 *pd_out, float *t_hit)
{
    fx_vec3 po = fx_m4_point(p->to_probe, o);
    fx_vec3 pd = fx_m4_dir(p->to_probe, dir);
    if (!isfinite(po.x + po.y + po.z + pd.x + pd.y + pd.z)) {
        *po_out = fx_v3(0.0f, 0.0f, 0.0f);
        *pd_out = fx_v3(0.0f, 0.0f, -1.0f);
        return -1;
    }
    pd = fx_v3_normalize_or(pd, fx_v3(0.0f, 0.0f, -1.0f));
    *po_out = po;
    *pd_out = pd;
    const int steps = st->steps;
    const float g = st->growth;
    float gap;
    int prev_front = in_front(p, po, &gap);
    /* an origin the probe does not see (behind a surface it sees: a mirror slab's side face,
     * a point behind the mirror's own frame) is hidden from the start: the fill unless the
     * ray comes out in front (before, such a ray met no crossing and took the far lookup,
     * the probe's colour along the ray's direction: the occluder's or the wall's) */
    float prev_t = 0.0f, t = st->t0, t_hidden = prev_front ? -1.0f : 0.0f;
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
            t_hidden = -1.0f; /* out from behind any occluder */
            continue;
        }
        for (int l = 0; l < n; l++) {
            const float tl = ts[l];
            /* a crossing: refined, a hit, or the ray passing behind an occluder */
            if (prev_front && !front[l] && refined_crossing(p, st, po, pd, prev_t, tl, t_hit, &t_hidden))
                return 1;
            prev_front = front[l] != 0;
            prev_t = tl;
            if (prev_front)
                t_hidden = -1.0f; /* out from behind the occluder: the probe sees the ray again */
        }
    }
    if (t_hidden >= 0.0f) {
        *t_hit = t_hidden;
        return 2;
    }
    return 0;
}

int fx_pano_trace(const fx_pano *p, const fx_pano_trace_settings *st, fx_vec3 o, fx_vec3 dir, float rgb[3])
{
    fx_vec3 po, pd;
    float t = 0.0f;
    int hit = pano_march(p, st, o, dir, &po, &pd, &t);
    if (hit == 1) {
        fx_pano_color(p, fx_v3_add(po, fx_v3_scale(pd, t)), rgb);
        return 1;
    }
    if (hit == 2) { /* hidden from the probe: the background around the hidden point, wide (hidden_fill) */
        hidden_fill(p, po, pd, t, rgb);
        return 0;
    }
    fx_pano_color(p, pd, rgb);
    return 0;
}

/* Texels between the probe's pixels of probe-space directions a and b (the shorter way
 * round horizontally): the larger of the two axes. */
static float texel_span(const fx_pano *p, fx_vec3 a, fx_vec3 b)
{
    float ax, ay, bx, by;
    fx_pano_dir_to_pixel(a, p->w, p->h, &ax, &ay);
    fx_pano_dir_to_pixel(b, p->w, p->h, &bx, &by);
    float dx = fabsf(ax - bx);
    dx = fminf(dx, (float)p->w - dx);
    return fmaxf(dx, fabsf(ay - by));
}

/* The mean colour over a grid of taps at c + s ex + r ey (probe space), s and r the cells'
 * centres across [-1/2, 1/2]: the axes' texel spans set the grid (fx_footprint_taps). */
static void footprint_mean(const fx_pano *p, fx_vec3 c, fx_vec3 ex, fx_vec3 ey, float rgb[3])
{
    fx_vec3 hx = fx_v3_scale(ex, 0.5f), hy = fx_v3_scale(ey, 0.5f);
    int nx = fx_footprint_taps(texel_span(p, fx_v3_sub(c, hx), fx_v3_add(c, hx)));
    int ny = fx_footprint_taps(texel_span(p, fx_v3_sub(c, hy), fx_v3_add(c, hy)));
    if (nx == 1 && ny == 1) {
        fx_pano_color(p, c, rgb);
        return;
    }
    float sum[3] = { 0.0f, 0.0f, 0.0f }, tap[3];
    for (int b = 0; b < ny; b++)
        for (int a = 0; a < nx; a++) {
            float s = ((float)a + 0.5f) / (float)nx - 0.5f, r = ((float)b + 0.5f) / (float)ny - 0.5f;
            fx_pano_color(p, fx_v3_add(c, fx_v3_add(fx_v3_scale(ex, s), fx_v3_scale(ey, r))), tap);
            for (int k = 0; k < 3; k++)
                sum[k] += tap[k];
        }
    for (int k = 0; k < 3; k++)
        rgb[k] = sum[k] / (float)(nx * ny);
}

/* A footprint axis turned into the probe's space; none (a point) where it is not finite. */
static fx_vec3 probe_axis(const fx_pano *p, fx_vec3 e)
{
    fx_vec3 r = fx_m4_dir(p->to_probe, e);
    return isfinite(r.x + r.y + r.z) ? r : fx_v3(0.0f, 0.0f, 0.0f);
}

int fx_pano_trace_footprint(const fx_pano *p, const fx_pano_trace_settings *st, fx_vec3 o, fx_vec3 dir,
                            const fx_ray_diff *diff, float rgb[3])
{
    fx_vec3 po, pd;
    float t = 0.0f;
    int hit = pano_march(p, st, o, dir, &po, &pd, &t);
    if (hit == 2) {
        hidden_fill(p, po, pd, t, rgb);
        return 0;
    }
    if (hit == 1) { /* the footprint on the surface the ray meets */
        fx_vec3 ex = probe_axis(p, fx_v3_add(diff->dox, fx_v3_scale(diff->ddx, t)));
        fx_vec3 ey = probe_axis(p, fx_v3_add(diff->doy, fx_v3_scale(diff->ddy, t)));
        footprint_mean(p, fx_v3_add(po, fx_v3_scale(pd, t)), ex, ey, rgb);
        return 1;
    }
    /* infinitely far: only the directions spread (pd unit) */
    footprint_mean(p, pd, probe_axis(p, diff->ddx), probe_axis(p, diff->ddy), rgb);
    return 0;
}

float fx_pano_trace_dist(const fx_pano *p, const fx_pano_trace_settings *st, fx_vec3 o, fx_vec3 dir)
{
    fx_vec3 po, pd;
    float t = 0.0f;
    return pano_march(p, st, o, dir, &po, &pd, &t) == 1 ? t : INFINITY;
}
