/* Single scattering of a sun through its light view: see volume_march.h. */
#include "math/volume_march.h"

#include "core/parallel.h"
#include "core/simd4.h"
#include "math/clones.h"

#include <math.h>
#include <string.h>

/* A world point in the light view: pixel x, y and planar depth. */
static fx_vec3 light_coords(const fx_view *lv, fx_vec3 p)
{
    fx_vec3 q = fx_world_to_view(lv, p);
    fx_vec2 pix = {0.0f, 0.0f};
    fx_view_project(lv, q, &pix);
    return fx_v3(pix.x, pix.y, -q.z);
}

/* The world origin and direction (per unit of planar depth) of the ray at pixel position
 * (x, y). */
static void world_ray(const fx_view *cam, float x, float y, fx_vec3 *o, fx_vec3 *d)
{
    fx_vec2 ndc = fx_view_pixel_to_ndc(cam, x, y);
    *o = fx_view_to_world(cam, fx_view_position(cam, ndc, 0.0f));
    *d = fx_v3_sub(fx_view_to_world(cam, fx_view_position(cam, ndc, 1.0f)), *o);
}

void fx_volume_prepare(fx_volume *v)
{
    /* differences over 256 pixels: the maps are affine, the long baseline keeps the
     * rounding of the two ends small against the step */
    const float k = 256.0f, ik = 1.0f / 256.0f;
    fx_vec3 o[3], d[3];
    world_ray(v->cam, 0.0f, 0.0f, &o[0], &d[0]);
    world_ray(v->cam, k, 0.0f, &o[1], &d[1]);
    world_ray(v->cam, 0.0f, k, &o[2], &d[2]);
    v->wd0 = d[0];
    v->wdx = fx_v3_scale(fx_v3_sub(d[1], d[0]), ik);
    v->wdy = fx_v3_scale(fx_v3_sub(d[2], d[0]), ik);
    fx_vec3 lo[3], le[3];
    for (int i = 0; i < 3; i++) {
        lo[i] = light_coords(v->light_view, o[i]);
        le[i] = fx_v3_sub(light_coords(v->light_view, fx_v3_add(o[i], d[i])), lo[i]);
    }
    v->lo0 = lo[0];
    v->lox = fx_v3_scale(fx_v3_sub(lo[1], lo[0]), ik);
    v->loy = fx_v3_scale(fx_v3_sub(lo[2], lo[0]), ik);
    v->ld0 = le[0];
    v->ldx = fx_v3_scale(fx_v3_sub(le[1], le[0]), ik);
    v->ldy = fx_v3_scale(fx_v3_sub(le[2], le[0]), ik);
}

/* Clips [*a, *b] to the s where lo <= c0 + s c1 <= hi (float); 0 when nothing is left. */
static inline int clip_slab_f(float c0, float c1, float lo, float hi, float *a, float *b)
{
    if (fabsf(c1) < 1e-30f)
        return c0 >= lo && c0 <= hi && *a < *b;
    float inv = 1.0f / c1;
    float t0 = (lo - c0) * inv, t1 = (hi - c0) * inv;
    if (t0 > t1) {
        float t = t0;
        t0 = t1;
        t1 = t;
    }
    *a = t0 > *a ? t0 : *a;
    *b = t1 < *b ? t1 : *b;
    return *a < *b;
}

/* The ray's clip to the medium and its light view coordinates (not its phase nor its
 * optical depth). */
static inline int volume_ray_geometry(const fx_volume *v, float x, float y, float depth, fx_volume_ray *r)
{
    fx_vec3 d = fx_v3_add(v->wd0, fx_v3_add(fx_v3_scale(v->wdx, x), fx_v3_scale(v->wdy, y)));
    fx_vec3 c0 = fx_v3_add(v->lo0, fx_v3_add(fx_v3_scale(v->lox, x), fx_v3_scale(v->loy, y)));
    fx_vec3 c1 = fx_v3_add(v->ld0, fx_v3_add(fx_v3_scale(v->ldx, x), fx_v3_scale(v->ldy, y)));
    float len = fx_v3_length(d);
    r->s0 = r->s1 = 0.0f;
    if (!(len > 1e-20f) || !(len < 1e30f))
        return 0;
    float a = 0.0f, b = depth > 0.0f && depth < v->far_limit ? depth : 1e30f;
    float bmax = v->max_distance / len;
    b = b < bmax ? b : bmax;
    const fx_shadow_map *sm = v->sm;
    if (!clip_slab_f(c0.x, c1.x, 0.0f, (float)sm->width, &a, &b) ||
        !clip_slab_f(c0.y, c1.y, 0.0f, (float)sm->height, &a, &b) ||
        !clip_slab_f(c0.z, c1.z, v->entry, sm->zfar, &a, &b) || !(b < 1e29f))
        return 0;
    float range = sm->zfar - sm->znear;
    float kn = range > 1e-20f ? 2.0f / range : 0.0f;
    r->s0 = a;
    r->s1 = b;
    r->len = len;
    r->px0 = c0.x;
    r->dpx = c1.x;
    r->py0 = c0.y;
    r->dpy = c1.y;
    r->tn0 = (c0.z - sm->znear) * kn - 1.0f;
    r->dtn = c1.z * kn;
    r->ld0 = c0.z;
    r->dld = c1.z;
    return 1;
}

int fx_volume_ray_init(const fx_volume *v, float x, float y, float depth, fx_volume_ray *r)
{
    if (!volume_ray_geometry(v, x, y, depth, r))
        return 0;
    const float len = r->len, c0z = r->ld0, c1z = r->dld;
    float e0 = 0.0f, e1 = 0.0f;
    if (v->view_extinction)
        e1 += v->sigma * len;
    if (v->light_extinction) {
        e0 += v->sigma * (c0z - v->entry);
        e1 += v->sigma * c1z;
    }
    r->e0 = e0;
    r->e1 = e1 > 0.0f ? e1 : 0.0f; /* light extinction alone, towards the light: not offered */
    fx_vec3 d = fx_v3_add(v->wd0, fx_v3_add(fx_v3_scale(v->wdx, x), fx_v3_scale(v->wdy, y)));
    r->phase = fx_hg_phase(v->g, -fx_v3_dot(v->light_dir, d) / len);
    return 1;
}

float fx_volume_light_entry(const fx_shadow_map *sm)
{
    /* the least normalised depth, taken when the map was built (and cached with it) */
    float m = sm->depth_min;
    if (!(m >= -1.0f))
        m = -1.0f;
    return sm->znear + (m + 1.0f) * 0.5f * (sm->zfar - sm->znear);
}

/* The light view as the 4-sample march reads it (its fields hoisted out of the loop). */
typedef struct lit_map {
    const float *depth;
    int w, h;
    v4f wm1, hm1; /* the last column and row */
} lit_map;

/* The visibility of 4 consecutive samples at once (p = light view position - 0.5, t the
 * sample's normalised depth less the bias): the depth test at each one's 4 nearest texels,
 * bilinearly weighted, the position clamped to the map. Lane by lane; the 16 texels are
 * loaded one by one (no gather in the baseline target). */
static inline v4f lit4(const lit_map *m, v4f px, v4f py, v4f t)
{
    const v4f fx = clamp4_pos(px, m->wm1), fy = clamp4_pos(py, m->hm1);
    const v4i x0 = __builtin_convertvector(fx, v4i), y0 = __builtin_convertvector(fy, v4i);
    const v4f tx = fx - __builtin_convertvector(x0, v4f), ty = fy - __builtin_convertvector(y0, v4f);
    /* the right and lower neighbours, or the texel itself on the map's last column / row */
    const v4i dx = (x0 < m->w - 1) & 1, dy = (y0 < m->h - 1) & m->w;
    float d00[4], d01[4], d10[4], d11[4];
    for (int k = 0; k < 4; k++) {
        const float *q = m->depth + (size_t)y0[k] * (size_t)m->w + (size_t)x0[k];
        d00[k] = q[0];
        d01[k] = q[dx[k]];
        d10[k] = q[dy[k]];
        d11[k] = q[dy[k] + dx[k]];
    }
    const v4f one_tx = V4(1.0f) - tx, zero = V4(0.0f);
    const v4f a = sel4(t <= ld4(d00), one_tx, zero) + sel4(t <= ld4(d01), tx, zero);
    const v4f b = sel4(t <= ld4(d10), one_tx, zero) + sel4(t <= ld4(d11), tx, zero);
    return a + (b - a) * ty;
}

/* Four samples per turn (the positions from the start, not summed step by step); the
 * lanes past the last step, or past where the medium turns opaque, add nothing. */
FX_CLONES float fx_volume_march(const fx_volume *v, const fx_volume_ray *r, int steps, float offset)
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
    const float stop = FX_VOLUME_OPAQUE_T;
    const lit_map m = { v->sm->depth, v->sm->width, v->sm->height, V4((float)(v->sm->width - 1)),
                        V4((float)(v->sm->height - 1)) };
    /* the sample positions in the light view (texel centres at + 0.5: the bilinear's
     * corner texel is floor(p - 0.5)) */
    const float s = r->s0 + offset * h;
    const float px = r->px0 + s * r->dpx - 0.5f, py = r->py0 + s * r->dpy - 0.5f;
    const float t = r->tn0 + s * r->dtn - v->eps;
    const float spx = h * r->dpx, spy = h * r->dpy, st = h * r->dtn;
    const float d2 = decay * decay;
    const float att0 = expf(-od), d4 = d2 * d2;
    v4f att = V4(att0) * (v4f){ 1.0f, decay, d2, d2 * decay };
    const v4f vpx = V4(px), vpy = V4(py), vt = V4(t), vspx = V4(spx), vspy = V4(spy), vst = V4(st);
    const v4f decay4 = V4(d4), vstop = V4(stop);
    v4f acc = V4(0.0f);
    for (int i = 0; i < steps && att[0] > stop; i += 4) {
        const v4f k = (v4f){ 0.0f, 1.0f, 2.0f, 3.0f } + V4((float)i);
        const v4f vis = lit4(&m, vpx + k * vspx, vpy + k * vspy, vt + k * vst);
        const v4i live = ((v4i){ 0, 1, 2, 3 } < steps - i) & (att > vstop);
        acc += sel4(live, vis * att, V4(0.0f));
        att *= decay4;
    }
    const float sum = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    float out = v->sigma * r->phase * r->len * step_int * sum;
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

float fx_volume_behind_at(const fx_volume *v, float x, float y, float depth)
{
    fx_volume_ray r;
    if (!volume_ray_geometry(v, x, y, depth, &r))
        return 1.0f;
    return fx_volume_behind(v, &r, depth);
}

float fx_volume_behind(const fx_volume *v, const fx_volume_ray *r, float depth)
{
    float od = 0.0f;
    if (v->view_extinction && r->s1 > r->s0)
        od += v->sigma * r->len * (r->s1 - r->s0);
    if (v->light_extinction && depth > 0.0f && depth < v->far_limit) {
        float l = r->ld0 + depth * r->dld - v->entry;
        od += l > 0.0f ? v->sigma * l : 0.0f;
    }
    return od < FX_VOLUME_OPAQUE ? expf(-od) : 0.0f;
}

/* ---- the reduced grid: march with interleaved offsets, then the depth-aware gather ---- */

typedef struct lo_job {
    const fx_volume *v;
    const float *depth;
    int w, h, f, steps, n, lw, lh;
    int mx0, mx1, my0; /* the texels marched: columns [mx0, mx1), rows from my0 */
    int gx0, gx1, gy0; /* the texels gathered (interleave > 1) */
    int mult;         /* the strata's permutation: k -> (k mult + rot) mod n^2 */
    unsigned rot;
    float *lo, *lo_t, *lo_depth, *out;
} lo_job;

static void march_rows(void *user, int y0, int y1)
{
    const lo_job *j = user;
    const int n = j->n, nn = n * n;
    for (int Y = j->my0 + y0; Y < j->my0 + y1; Y++) {
        int y = Y * j->f + j->f / 2;
        y = y < j->h ? y : j->h - 1;
        for (int X = j->mx0; X < j->mx1; X++) {
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
            int in = fx_volume_ray_init(j->v, (float)x + 0.5f, (float)y + 0.5f, d, &r);
            size_t i = (size_t)Y * j->lw + X;
            j->lo[i] = in ? fx_volume_march(j->v, &r, j->steps, offset) : 0.0f;
            j->lo_t[i] = in ? fx_volume_behind(j->v, &r, d) : 1.0f;
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
    for (int Y = j->gy0 + y0; Y < j->gy0 + y1; Y++)
        for (int X = j->gx0; X < j->gx1; X++) {
            const float d = j->lo_depth[(size_t)Y * lw + X], inv = 10.0f / d;
            float s = 0.0f, ws = 0.0f;
            for (int b = 0; b < n; b++) {
                int yy = Y - n / 2 + b;
                yy = yy < 0 ? 0 : yy >= lh ? lh - 1 : yy;
                const float *L = j->lo + (size_t)yy * lw, *D = j->lo_depth + (size_t)yy * lw;
                for (int a = 0; a < n; a++) {
                    int xx = X - n / 2 + a;
                    xx = xx < 0 ? 0 : xx >= lw ? lw - 1 : xx;
                    float wt = fx_volume_depth_weight(d, inv, D[xx]);
                    s += wt * L[xx];
                    ws += wt;
                }
            }
            j->out[(size_t)Y * lw + X] = ws > 1e-6f ? s / ws : j->lo[(size_t)Y * lw + X]; /* ws >= 1: itself */
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

/* The texels [*a, *b) of a grid of n that pixels [p0, p1) read (each pixel its texel and
 * the next one: fx_volume_lo_coord), `margin` more each way, within the grid. */
static void lo_span(int p0, int p1, int factor, int n, int margin, int *a, int *b)
{
    int t0 = 0, t1 = 0;
    float u;
    fx_volume_lo_coord(p0, factor, n, &t0, &u);
    fx_volume_lo_coord(p1 - 1, factor, n, &t1, &u);
    *a = t0 - margin > 0 ? t0 - margin : 0;
    *b = t1 + 2 + margin < n ? t1 + 2 + margin : n;
}

void fx_volume_scatter_lo(fx_context *ctx, const fx_volume *v, const float *depth, int w, int h, int factor,
                          int steps, int interleave, unsigned rotate, const fx_rect *roi, float *lo, float *lo_t,
                          float *lo_depth, float *tmp)
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
    j.lo_t = lo_t;
    /* only the texels the roi's pixels read, and around them the gather's block: a
     * masked entry marches its mask's part of the frame (the texels it reads are the
     * whole frame's bit for bit) */
    const fx_rect whole = {0, 0, w, h}, *r = roi && roi->x1 > roi->x0 && roi->y1 > roi->y0 ? roi : &whole;
    int my1 = 0, gy1 = 0;
    lo_span(r->x0, r->x1, j.f, j.lw, 0, &j.gx0, &j.gx1);
    lo_span(r->y0, r->y1, j.f, j.lh, 0, &j.gy0, &gy1);
    lo_span(r->x0, r->x1, j.f, j.lw, j.n, &j.mx0, &j.mx1);
    lo_span(r->y0, r->y1, j.f, j.lh, j.n, &j.my0, &my1);
    fx_parallel_for(ctx, my1 - j.my0, fx_grain_for(ctx, my1 - j.my0), march_rows, &j);
    if (j.n > 1) {
        j.out = lo;
        fx_parallel_for(ctx, gy1 - j.gy0, fx_grain_for(ctx, gy1 - j.gy0), gather_rows, &j);
    }
    /* the texels no pixel reads: defined (no light, nothing dimmed, background), as the
     * composite's row set-up reads whole rows */
    if (j.gx0 > 0 || j.gx1 < j.lw || j.gy0 > 0 || gy1 < j.lh)
        for (int Y = 0; Y < j.lh; Y++)
            for (int X = 0; X < j.lw; X++)
                if (Y < j.gy0 || Y >= gy1 || X < j.gx0 || X >= j.gx1) {
                    const size_t i = (size_t)Y * j.lw + X;
                    lo[i] = 0.0f;
                    lo_t[i] = 1.0f;
                    lo_depth[i] = FX_VOLUME_BG_DEPTH;
                }
}
