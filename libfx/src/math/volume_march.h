/* Single scattering of a sun in a homogeneous medium, ray-marched from the camera through
 * each pixel's view ray up to its depth, with the sun's visibility at each sample looked up
 * in the sun's orthographic depth view (the light view vsm_shadows reads). god_rays'
 * method volumetric (docs/effects/god_rays.md).
 *
 * Units are those of Cycles' Volume Scatter: the density sigma is the scattering
 * coefficient per scene unit (metres) and, for Volume Scatter, also the extinction
 * coefficient; the phase is Henyey-Greenstein with anisotropy g (> 0: forward). A sun of
 * strength S (irradiance, W/m^2) adds the radiance
 *
 *     L = sigma p(cos) S colour  integral over the ray of  V(x) T_view(t) T_light(x) dt
 *
 * with cos the cosine between the light's travel direction and the direction towards the
 * camera, V the sun's visibility at x (the light view's depth test, bilinear over its 4
 * nearest texels), T_view = exp(-sigma t) (t the distance from the camera inside the
 * medium) and T_light = exp(-sigma l) (l the distance the light has travelled inside the
 * medium: from the light view's nearest surface, where the light first meets the scene
 * (a room's outer wall, a forest's canopy), to x). The medium fills the light view's box (its x, y extent and clip range: the add-on fits it to the shadow casters
 * within the camera's view) from where the light first meets the scene on (the entry: the
 * view's nearest surface), capped at max_distance from the camera.
 *
 * The march: n steps of equal length over the ray's part inside the medium; within each
 * step the transmittance is integrated exactly (it is exponential in t) and the visibility
 * taken at one point of the step, at a fraction `offset` of it (0.5: the midpoint;
 * interleaved sampling gives neighbouring pixels different offsets). The result is
 * exact for a ray that is wholly lit, and converges as the steps grow where shadows cut
 * it. */
#ifndef LIBFX_MATH_VOLUME_MARCH_H
#define LIBFX_MATH_VOLUME_MARCH_H

#include "core/context.h"
#include "core/rect.h"
#include "core/simd4.h"
#include "math/camera.h"
#include "math/shadow_map.h"
#include "math/vec.h"

#include <float.h>

/* Anisotropy is clamped to this (Henyey-Greenstein at |g| = 1 is a delta). */
#define FX_VOLUME_MAX_G 0.999f
/* Above this optical depth a sample adds nothing (exp(-40) ~ 4e-18): the march stops. */
#define FX_VOLUME_OPAQUE 40.0f
/* expf(-FX_VOLUME_OPAQUE), as a constant for the march's loop (test_march_steps checks it) */
#define FX_VOLUME_OPAQUE_T 4.2483543e-18f

typedef struct fx_volume {
    const fx_view *cam;        /* the frame's camera */
    const fx_view *light_view; /* the sun's view: orthographic */
    const fx_shadow_map *sm;   /* its normalised depth (sm->depth) */
    fx_vec3 light_dir;         /* world, unit: the way the light travels */
    float sigma;               /* density per scene unit (> 0) */
    float g;                   /* anisotropy, in [-FX_VOLUME_MAX_G, FX_VOLUME_MAX_G] */
    int view_extinction;       /* exp(-sigma t) towards the camera */
    int light_extinction;      /* exp(-sigma l) on the light's way in */
    float max_distance;        /* scene units from the camera (> 0) */
    float eps;                 /* depth-test bias, normalised (fx_shadow_map_norm_dist) */
    float far_limit;           /* planar depth at or beyond which a pixel is background */
    float entry;               /* light view planar depth where the light enters the medium
                                  (fx_volume_light_entry): the medium's near side */
    /* Filled by fx_volume_prepare: a pixel's ray is affine in its pixel coordinates (x, y):
     * origin o = o0 + x ox + y oy, direction per unit of planar depth d = d0 + x dx + y dy,
     * in world space (w*) and in the light view's coordinates (l*: pixel x, pixel y, planar
     * depth; an orthographic view is affine too). */
    fx_vec3 wd0, wdx, wdy;
    fx_vec3 lo0, lox, loy, ld0, ldx, ldy;
} fx_volume;

/* Fills the ray basis of v from its cameras (call once the other fields are set). */
void fx_volume_prepare(fx_volume *v);

/* The light view's nearest surface depth (planar, scene units): where its light enters. */
float fx_volume_light_entry(const fx_shadow_map *sm);

/* One view ray, parametrised by planar depth s (the Depth pass's unit). */
typedef struct fx_volume_ray {
    float s0, s1;      /* the part inside the medium (s1 <= s0: none) */
    float len;         /* scene units per unit of s */
    float px0, dpx;    /* light view pixel x at s: px0 + s dpx */
    float py0, dpy;
    float tn0, dtn;    /* normalised light depth at s */
    float e0, e1;      /* optical depth (view and light) at s: e0 + e1 s, e1 >= 0 */
    float ld0, dld;    /* light view planar depth at s (scene units) */
    float phase;       /* Henyey-Greenstein value for this ray */
} fx_volume_ray;

/* Henyey-Greenstein phase function (per steradian, integrates to 1 over the sphere);
 * cos_t between the light's travel direction and the scattered direction. Finite for
 * |g| <= FX_VOLUME_MAX_G. */
static inline float fx_hg_phase(float g, float cos_t)
{
    g = fx_clampf(g, -FX_VOLUME_MAX_G, FX_VOLUME_MAX_G);
    cos_t = fx_clampf(cos_t, -1.0f, 1.0f);
    float d = 1.0f + g * g - 2.0f * g * cos_t;
    d = d > 1e-12f ? d : 1e-12f;
    return (1.0f - g * g) / (4.0f * 3.14159265358979f * d * sqrtf(d));
}

/* The ray of frame pixel position (x, y) (pixel centres at + 0.5) whose surface lies at
 * planar depth `depth` (background: beyond far_limit, non-finite or <= 0). Returns 0 when
 * the ray has no part inside the medium. */
int fx_volume_ray_init(const fx_volume *v, float x, float y, float depth, fx_volume_ray *r);

/* The in-scattered radiance of ray r per unit of the sun's radiance (multiply by
 * S colour): sigma p integral V T_view T_light dt, marched in `steps` steps with the
 * visibility at fraction `offset` in [0, 1) of each. */
float fx_volume_march(const fx_volume *v, const fx_volume_ray *r, int steps, float offset);

/* The view transmittance of ray r: exp(-sigma (length inside the medium)), 1 without
 * view extinction. */
float fx_volume_transmittance(const fx_volume *v, const fx_volume_ray *r);

/* With light extinction, the transmittance of the light that lights the surface at planar
 * depth `depth` of ray r: exp(-sigma (light depth - entry)), the sun's own way to it
 * through the medium (exact for the sun's direct light, taken for the bounce light too);
 * 1 without light extinction, for background and outside the light view's depth range. */
float fx_volume_surface_light(const fx_volume *v, const fx_volume_ray *r, float depth);

/* fx_volume_transmittance * fx_volume_surface_light in one exponential; _at: of the ray
 * at pixel position (x, y) (1 where it misses the medium). */
float fx_volume_behind(const fx_volume *v, const fx_volume_ray *r, float depth);
float fx_volume_behind_at(const fx_volume *v, float x, float y, float depth);

/* The in-scattered light (and what is left of the surface behind: fx_volume_behind) over a
 * frame (w x h, planar depth `depth`) on a grid reduced by
 * `factor` (lo texel X stands for pixel column min(factor X + factor / 2, w - 1)), with
 * interleaved sampling over `interleave` x `interleave` texels (each texel of a block
 * marches with its own offset, a fixed permutation of the block's strata turned by
 * `rotate`) gathered back by a depth-aware box of the block's size. lo (lw x lh) gets the
 * result, lo_t the transmittance, lo_depth the texels' depths (background:
 * FX_VOLUME_BG_DEPTH). tmp: lw x lh floats of scratch (interleave > 1). roi (NULL: the
 * whole frame): only the texels its pixels read (fx_volume_lo_coord: a pixel's texel and the
 * next) are valid, the same as the whole frame's. */
#define FX_VOLUME_BG_DEPTH 1e10f
void fx_volume_scatter_lo(fx_context *ctx, const fx_volume *v, const float *depth, int w, int h, int factor,
                          int steps, int interleave, unsigned rotate, const fx_rect *roi, float *lo, float *lo_t,
                          float *lo_depth, float *tmp);

static inline int fx_volume_lo_size(int n, int factor) { return (n + factor - 1) / factor; }

/* Depth-aware weight of a sample at planar depth ds for a pixel at depth d, given
 * inv = 1 / (0.1 d) (background: d = FX_VOLUME_BG_DEPTH): 1 at equal depths, 1/4 at a
 * relative difference of 10 %, 0 from 20 % on (no division: it runs per tap). */
static inline float fx_volume_depth_weight(float d, float inv, float ds)
{
    float r = fabsf(d - ds) * inv;
    float q = 1.0f - 0.5f * r;
    q = q > 0.0f ? q : 0.0f;
    return q * q;
}

/* A pixel's planar depth as the weights read it. */
static inline float fx_volume_weight_depth(float d, float far_limit)
{
    return d > 0.0f && d < far_limit ? d : FX_VOLUME_BG_DEPTH;
}

/* Where full-resolution column (or row) x falls on the reduced grid of n texels: texel
 * *x0 and the weight *t of texel x0 + 1 (lo texel X stands for pixel factor X + factor / 2). */
static inline void fx_volume_lo_coord(int x, int factor, int n, int *x0, float *t)
{
    float u = (float)(x - factor / 2) / (float)factor;
    u = u > 0.0f ? u : 0.0f;
    u = u < (float)(n - 1) ? u : (float)(n - 1);
    *x0 = (int)u;
    *t = u - (float)*x0;
}

/* The upsample's fallback where no tap's depth is alike (a thin object): the index of the
 * tap (of 4 depths) nearest in depth to d; the first one on a tie. */
static inline int fx_volume_likest(const float taps[4], float d)
{
    int bi = 0;
    float best = FLT_MAX;
    for (int k = 0; k < 4; k++) {
        const float e = fabsf(d - taps[k]);
        if (e < best) {
            best = e;
            bi = k;
        }
    }
    return bi;
}

/* The reduced in-scatter and transmittance at a full-resolution pixel of depth d
 * (fx_volume_weight_depth) between lo rows r0 and r1 (offsets of rows Y0, Y1; weight ty of
 * r1) and columns X0, X0 + 1 (weight tx): bilinear, each texel weighted by its depth's
 * likeness; where none is alike (a thin object), the likest one. */
static inline void fx_volume_upsample(const float *lo, const float *lo_t, const float *lo_depth, size_t r0,
                                      size_t r1, int X0, int X1, float tx, float ty, float d, float *L, float *T)
{
    const size_t i[4] = {r0 + (size_t)X0, r0 + (size_t)X1, r1 + (size_t)X0, r1 + (size_t)X1};
    const float b[4] = {(1.0f - tx) * (1.0f - ty), tx * (1.0f - ty), (1.0f - tx) * ty, tx * ty};
    const float inv = 10.0f / d;
    float ws = 0.0f, sl = 0.0f, st = 0.0f;
    for (int k = 0; k < 4; k++) {
        float wk = b[k] * fx_volume_depth_weight(d, inv, lo_depth[i[k]]);
        ws += wk;
        sl += wk * lo[i[k]];
        st += wk * lo_t[i[k]];
    }
    if (ws > 1e-6f) {
        float iw = 1.0f / ws;
        *L = sl * iw;
        *T = st * iw;
        return;
    }
    const float taps[4] = {lo_depth[i[0]], lo_depth[i[1]], lo_depth[i[2]], lo_depth[i[3]]};
    const int bi = fx_volume_likest(taps, d);
    *L = lo[i[bi]];
    *T = lo_t[i[bi]];
}

/* Four horizontal sums in a scalar loop's order: lane k is (((0 + v[0]) + v[1]) + v[2]) +
 * v[3] for v the k-th argument (a 4 x 4 transpose, then vertical adds). */
static inline v4f fx_hsum4x4(v4f a, v4f b, v4f c, v4f d)
{
#ifdef __SSE__
    __m128 r0 = (__m128)a, r1 = (__m128)b, r2 = (__m128)c, r3 = (__m128)d;
    _MM_TRANSPOSE4_PS(r0, r1, r2, r3);
    return (((V4(0.0f) + (v4f)r0) + (v4f)r1) + (v4f)r2) + (v4f)r3;
#else
    return (v4f){0.0f + a[0] + a[1] + a[2] + a[3], 0.0f + b[0] + b[1] + b[2] + b[3],
                 0.0f + c[0] + c[1] + c[2] + c[3], 0.0f + d[0] + d[1] + d[2] + d[3]};
#endif
}

/* fx_volume_upsample for 4 pixels at once, each on one cell held as 12 floats (the 4
 * texels in the order r0 X0, r0 X1, r1 X0, r1 X1: depths, in-scatter, transmittance;
 * by = {1 - ty, 1 - ty, ty, ty}; tx and d per pixel): the same weights and the same sums
 * in the same order, so the same bits, in a fraction of the instructions (the composite
 * runs it per pixel). */
static inline void fx_volume_upsample_cell4(const float *const cell[4], v4f by, v4f tx, v4f d, v4f *L, v4f *T)
{
    const v4f inv = V4(10.0f) / d;
    v4f wk[4], pl[4], pt[4];
    for (int k = 0; k < 4; k++) {
        const v4f D = ld4(cell[k]);
        const v4f b = (v4f){1.0f - tx[k], tx[k], 1.0f - tx[k], tx[k]} * by;
        v4f r = D - V4(d[k]);
        r = (v4f)((v4i)r & (v4i){0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff}) * V4(inv[k]);
        const v4f q = max4(V4(1.0f) - V4(0.5f) * r, V4(0.0f));
        wk[k] = b * (q * q);
        pl[k] = wk[k] * ld4(cell[k] + 4);
        pt[k] = wk[k] * ld4(cell[k] + 8);
    }
    const v4f ws = fx_hsum4x4(wk[0], wk[1], wk[2], wk[3]);
    const v4f iw = V4(1.0f) / max4(ws, V4(1e-6f));
    *L = fx_hsum4x4(pl[0], pl[1], pl[2], pl[3]) * iw;
    *T = fx_hsum4x4(pt[0], pt[1], pt[2], pt[3]) * iw;
    if (all4(ws > V4(1e-6f)))
        return;
    for (int k = 0; k < 4; k++)
        if (!(ws[k] > 1e-6f)) { /* none alike (a thin object): the likest texel */
            const int bi = fx_volume_likest(cell[k], d[k]);
            (*L)[k] = cell[k][4 + bi];
            (*T)[k] = cell[k][8 + bi];
        }
}

/* fx_volume_upsample_cell4 for 4 pixels on the same cell: the lanes are the pixels, so the
 * taps need no transpose (the same products and sums in the same order: the same bits).
 * bc: the cell's 12 floats, each broadcast to a vector (built once per cell row). */
static inline void fx_volume_upsample_same4(const float *cell, const v4f *bc, float ty, v4f tx, v4f d, v4f *L,
                                            v4f *T)
{
    const v4f inv = V4(10.0f) / d, ux = V4(1.0f) - tx;
    const v4f b[4] = {ux * V4(1.0f - ty), tx * V4(1.0f - ty), ux * V4(ty), tx * V4(ty)};
    v4f ws = V4(0.0f), sl = V4(0.0f), st = V4(0.0f);
    for (int m = 0; m < 4; m++) {
        v4f r = d - bc[m];
        r = (v4f)((v4i)r & (v4i){0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff}) * inv;
        const v4f q = max4(V4(1.0f) - V4(0.5f) * r, V4(0.0f));
        const v4f wk = b[m] * (q * q);
        ws += wk;
        sl += wk * bc[4 + m];
        st += wk * bc[8 + m];
    }
    const v4f iw = V4(1.0f) / max4(ws, V4(1e-6f));
    *L = sl * iw;
    *T = st * iw;
    if (all4(ws > V4(1e-6f)))
        return;
    for (int k = 0; k < 4; k++)
        if (!(ws[k] > 1e-6f)) { /* none alike (a thin object): the likest texel */
            const int bi = fx_volume_likest(cell, d[k]);
            (*L)[k] = cell[4 + bi];
            (*T)[k] = cell[8 + bi];
        }
}

#endif
