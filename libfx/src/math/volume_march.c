/* Single scattering of a sun through its light view: see volume_march.h. */
#include "math/volume_march.h"

#include "core/parallel.h"

#include <math.h>
#include <string.h>

/* Clips [*a, *b] to the s where lo <= c0 + s c1 <= hi; 0 when nothing is left. */
static int clip_slab(double c0, double c1, double lo, double hi, double *a, double *b)
{
    if (fabs(c1) < 1e-30) {
        if (!(c0 >= lo && c0 <= hi))
            return 0;
        return *a < *b;
    }
    double t0 = (lo - c0) / c1, t1 = (hi - c0) / c1;
    if (t0 > t1) {
        double t = t0;
        t0 = t1;
        t1 = t;
    }
    if (t0 > *a)
        *a = t0;
    if (t1 < *b)
        *b = t1;
    return *a < *b;
}

/* A world point in the light view: pixel x, y and planar depth. */
static void light_coords(const fx_view *lv, fx_vec3 p, double out[3])
{
    fx_vec3 q = fx_world_to_view(lv, p);
    fx_vec2 pix = {0.0f, 0.0f};
    fx_view_project(lv, q, &pix);
    out[0] = pix.x;
    out[1] = pix.y;
    out[2] = -q.z;
}

int fx_volume_ray_init(const fx_volume *v, float x, float y, float depth, fx_volume_ray *r)
{
    memset(r, 0, sizeof *r);
    const fx_view *cam = v->cam;
    fx_vec2 ndc = fx_view_pixel_to_ndc(cam, x, y);
    fx_vec3 p0 = fx_view_to_world(cam, fx_view_position(cam, ndc, 0.0f));
    fx_vec3 p1 = fx_view_to_world(cam, fx_view_position(cam, ndc, 1.0f));
    fx_vec3 d = fx_v3_sub(p1, p0);
    float len = fx_v3_length(d);
    if (!(len > 1e-20f) || !isfinite(len))
        return 0;
    double a = 0.0, b = depth > 0.0f && depth < v->far_limit ? (double)depth : 1e30;
    double bmax = (double)v->max_distance / len;
    if (b > bmax)
        b = bmax;
    double c0[3], c1[3];
    light_coords(v->light_view, p0, c0);
    light_coords(v->light_view, p1, c1);
    for (int k = 0; k < 3; k++)
        c1[k] -= c0[k];
    const fx_shadow_map *sm = v->sm;
    if (!clip_slab(c0[0], c1[0], 0.0, sm->width, &a, &b) || !clip_slab(c0[1], c1[1], 0.0, sm->height, &a, &b) ||
        !clip_slab(c0[2], c1[2], v->entry, sm->zfar, &a, &b))
        return 0;
    if (!(b > a) || !isfinite(a) || !isfinite(b))
        return 0;
    double range = (double)sm->zfar - sm->znear;
    double kn = range > 1e-20 ? 2.0 / range : 0.0;
    r->s0 = (float)a;
    r->s1 = (float)b;
    r->len = len;
    r->px0 = (float)c0[0];
    r->dpx = (float)c1[0];
    r->py0 = (float)c0[1];
    r->dpy = (float)c1[1];
    r->tn0 = (float)((c0[2] - sm->znear) * kn - 1.0);
    r->dtn = (float)(c1[2] * kn);
    double e0 = 0.0, e1 = 0.0;
    if (v->view_extinction)
        e1 += (double)v->sigma * len;
    if (v->light_extinction) {
        e0 += (double)v->sigma * (c0[2] - v->entry);
        e1 += (double)v->sigma * c1[2];
    }
    if (e1 < 0.0) /* light extinction alone, looking towards the light: not offered */
        e1 = 0.0;
    r->ld0 = (float)c0[2];
    r->dld = (float)c1[2];
    r->e0 = (float)e0;
    r->e1 = (float)e1;
    r->phase = fx_hg_phase(v->g, -fx_v3_dot(v->light_dir, d) / len);
    return r->s1 > r->s0;
}

float fx_volume_light_entry(const fx_shadow_map *sm)
{
    float m = 1.0f;
    const size_t n = (size_t)sm->width * sm->height;
    for (size_t i = 0; i < n; i++)
        m = sm->depth[i] < m ? sm->depth[i] : m;
    if (!(m >= -1.0f))
        m = -1.0f;
    return sm->znear + (m + 1.0f) * 0.5f * (sm->zfar - sm->znear);
}

/* The sun's visibility at light view pixel (px, py) for normalised depth t: the depth test
 * at the 4 nearest texels, bilinearly weighted. */
static inline float visibility(const fx_shadow_map *sm, float px, float py, float t)
{
    const int w = sm->width, h = sm->height;
    float fx = fx_clampf(px - 0.5f, 0.0f, (float)(w - 1)), fy = fx_clampf(py - 0.5f, 0.0f, (float)(h - 1));
    int x0 = (int)fx, y0 = (int)fy;
    int x1 = x0 + 1 < w ? x0 + 1 : x0;
    const float *r0 = sm->depth + (size_t)y0 * w, *r1 = y0 + 1 < h ? r0 + w : r0;
    float tx = fx - (float)x0, ty = fy - (float)y0;
    float a = (t <= r0[x0] ? 1.0f - tx : 0.0f) + (t <= r0[x1] ? tx : 0.0f);
    float b = (t <= r1[x0] ? 1.0f - tx : 0.0f) + (t <= r1[x1] ? tx : 0.0f);
    return a + (b - a) * ty;
}

float fx_volume_march(const fx_volume *v, const fx_volume_ray *r, int steps, float offset)
{
    if (!(r->s1 > r->s0) || steps < 1)
        return 0.0f;
    const float h = (r->s1 - r->s0) / (float)steps;
    /* exact integral of exp(-(e0 + e1 s)) over one step, relative to its start */
    const float q = r->e1 * h;
    const float step_int = q > 1e-4f ? -expm1f(-q) / r->e1 : h * (1.0f - 0.5f * q);
    const float decay = expf(-q);
    float od = r->e0 + r->e1 * r->s0;
    if (!(od < FX_VOLUME_OPAQUE))
        return 0.0f;
    float att = expf(-od);
    const float stop = expf(-FX_VOLUME_OPAQUE);
    const float t_eps = v->eps;
    float acc = 0.0f;
    for (int i = 0; i < steps && att > stop; i++) {
        float s = r->s0 + ((float)i + offset) * h;
        float vis = visibility(v->sm, r->px0 + s * r->dpx, r->py0 + s * r->dpy, r->tn0 + s * r->dtn - t_eps);
        acc += vis * att;
        att *= decay;
    }
    float out = v->sigma * r->phase * r->len * step_int * acc;
    return isfinite(out) ? out : 0.0f;
}

float fx_volume_transmittance(const fx_volume *v, const fx_volume_ray *r)
{
    if (!v->view_extinction || !(r->s1 > r->s0))
        return 1.0f;
    float od = v->sigma * r->len * (r->s1 - r->s0);
    return od < FX_VOLUME_OPAQUE ? expf(-od) : 0.0f;
}

float fx_volume_surface_light(const fx_volume *v, const fx_volume_ray *r, float depth)
{
    if (!v->light_extinction || !(depth > 0.0f && depth < v->far_limit))
        return 1.0f;
    float l = r->ld0 + depth * r->dld - v->entry;
    if (!(l > 0.0f))
        return 1.0f;
    float od = v->sigma * l;
    return od < FX_VOLUME_OPAQUE ? expf(-od) : 0.0f;
}

/* ---- the reduced grid: march with interleaved offsets, then the depth-aware gather ---- */

typedef struct lo_job {
    const fx_volume *v;
    const float *depth;
    int w, h, f, steps, n, lw, lh;
    int mult;         /* the strata's permutation: k -> (k mult + rot) mod n^2 */
    unsigned rot;
    float *lo, *lo_depth, *out;
} lo_job;

static void march_rows(void *user, int y0, int y1)
{
    const lo_job *j = user;
    const int n = j->n, nn = n * n;
    for (int Y = y0; Y < y1; Y++) {
        int y = Y * j->f + j->f / 2;
        y = y < j->h ? y : j->h - 1;
        for (int X = 0; X < j->lw; X++) {
            int x = X * j->f + j->f / 2;
            x = x < j->w ? x : j->w - 1;
            float d = j->depth[(size_t)y * j->w + x];
            float offset = 0.5f;
            if (n > 1) {
                unsigned k = (unsigned)((X % n) + n * (Y % n));
                k = (k * (unsigned)j->mult + j->rot) % (unsigned)nn;
                offset = ((float)k + 0.5f) / (float)nn;
            }
            fx_volume_ray r;
            float L = fx_volume_ray_init(j->v, (float)x + 0.5f, (float)y + 0.5f, d, &r)
                          ? fx_volume_march(j->v, &r, j->steps, offset)
                          : 0.0f;
            size_t i = (size_t)Y * j->lw + X;
            j->lo[i] = L;
            j->lo_depth[i] = fx_volume_weight_depth(d, j->v->far_limit);
        }
    }
}

/* The n x n block around each texel (columns X - n/2 .. X - n/2 + n - 1: every stratum
 * once), weighted by depth likeness. */
static void gather_rows(void *user, int y0, int y1)
{
    const lo_job *j = user;
    const int n = j->n, lw = j->lw, lh = j->lh;
    for (int Y = y0; Y < y1; Y++)
        for (int X = 0; X < lw; X++) {
            const float d = j->lo_depth[(size_t)Y * lw + X];
            float s = 0.0f, ws = 0.0f;
            for (int b = 0; b < n; b++) {
                int yy = Y - n / 2 + b;
                yy = yy < 0 ? 0 : yy >= lh ? lh - 1 : yy;
                const float *L = j->lo + (size_t)yy * lw, *D = j->lo_depth + (size_t)yy * lw;
                for (int a = 0; a < n; a++) {
                    int xx = X - n / 2 + a;
                    xx = xx < 0 ? 0 : xx >= lw ? lw - 1 : xx;
                    float wt = fx_volume_depth_weight(d, D[xx]);
                    s += wt * L[xx];
                    ws += wt;
                }
            }
            j->out[(size_t)Y * lw + X] = ws > 1e-30f ? s / ws : j->lo[(size_t)Y * lw + X];
        }
}

static int gcd(int a, int b)
{
    while (b) {
        int t = a % b;
        a = b;
        b = t;
    }
    return a;
}

void fx_volume_scatter_lo(fx_context *ctx, const fx_volume *v, const float *depth, int w, int h, int factor,
                          int steps, int interleave, unsigned rotate, float *lo, float *lo_depth, float *tmp)
{
    lo_job j;
    memset(&j, 0, sizeof j);
    j.v = v;
    j.depth = depth;
    j.w = w;
    j.h = h;
    j.f = factor > 1 ? factor : 1;
    j.steps = steps;
    j.n = interleave > 1 ? interleave : 1;
    j.lw = fx_volume_lo_size(w, j.f);
    j.lh = fx_volume_lo_size(h, j.f);
    const int nn = j.n * j.n;
    /* a multiplier coprime with n^2 scatters neighbouring texels' strata */
    j.mult = 1;
    for (int m = nn / 2 + 1; m < 4 * nn + 8; m++)
        if (gcd(m, nn) == 1) {
            j.mult = m;
            break;
        }
    j.rot = nn > 1 ? rotate % (unsigned)nn : 0;
    j.lo = j.n > 1 ? tmp : lo;
    j.lo_depth = lo_depth;
    fx_parallel_for(ctx, j.lh, fx_grain_for(ctx, j.lh), march_rows, &j);
    if (j.n > 1) {
        j.out = lo;
        fx_parallel_for(ctx, j.lh, fx_grain_for(ctx, j.lh), gather_rows, &j);
    }
}
