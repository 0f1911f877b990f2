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
#include "math/camera.h"
#include "math/shadow_map.h"
#include "math/vec.h"

/* Anisotropy is clamped to this (Henyey-Greenstein at |g| = 1 is a delta). */
#define FX_VOLUME_MAX_G 0.999f
/* Above this optical depth a sample adds nothing (exp(-40) ~ 4e-18): the march stops. */
#define FX_VOLUME_OPAQUE 40.0f

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
} fx_volume;

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

/* The in-scattered light over a frame (w x h, planar depth `depth`) on a grid reduced by
 * `factor` (lo texel X stands for pixel column min(factor X + factor / 2, w - 1)), with
 * interleaved sampling over `interleave` x `interleave` texels (each texel of a block
 * marches with its own offset, a fixed permutation of the block's strata turned by
 * `rotate`) gathered back by a depth-aware box of the block's size. lo (lw x lh) gets the
 * result, lo_depth the texels' depths (background: FX_VOLUME_BG_DEPTH). tmp: lw x lh
 * floats of scratch (interleave > 1). */
#define FX_VOLUME_BG_DEPTH 1e10f
void fx_volume_scatter_lo(fx_context *ctx, const fx_volume *v, const float *depth, int w, int h, int factor,
                          int steps, int interleave, unsigned rotate, float *lo, float *lo_depth, float *tmp);

static inline int fx_volume_lo_size(int n, int factor) { return (n + factor - 1) / factor; }

/* Depth-aware weight of a sample at planar depth ds for a pixel at depth d (both > 0;
 * background FX_VOLUME_BG_DEPTH): 1 at equal depths, 1/4 at a relative difference of 10 %. */
static inline float fx_volume_depth_weight(float d, float ds)
{
    float m = d < ds ? d : ds;
    float r = fabsf(d - ds) / (0.1f * m + 1e-6f);
    float q = 1.0f + r * r;
    return 1.0f / (q * q);
}

/* A pixel's planar depth as the weights read it. */
static inline float fx_volume_weight_depth(float d, float far_limit)
{
    return d > 0.0f && d < far_limit ? d : FX_VOLUME_BG_DEPTH;
}

/* The reduced in-scatter at full-resolution pixel (x, y) of depth d (fx_volume_weight_depth):
 * bilinear over the 2 x 2 nearest lo texels, each weighted by its depth's likeness. */
static inline float fx_volume_upsample(const float *lo, const float *lo_depth, int lw, int lh, int factor, int x,
                                       int y, float d)
{
    float u = (float)(x - factor / 2) / (float)factor, v = (float)(y - factor / 2) / (float)factor;
    u = fx_clampf(u, 0.0f, (float)(lw - 1));
    v = fx_clampf(v, 0.0f, (float)(lh - 1));
    int X0 = (int)u, Y0 = (int)v;
    int X1 = X0 + 1 < lw ? X0 + 1 : X0, Y1 = Y0 + 1 < lh ? Y0 + 1 : Y0;
    float tx = u - (float)X0, ty = v - (float)Y0;
    const size_t i00 = (size_t)Y0 * lw + X0, i01 = (size_t)Y0 * lw + X1;
    const size_t i10 = (size_t)Y1 * lw + X0, i11 = (size_t)Y1 * lw + X1;
    float w00 = (1.0f - tx) * (1.0f - ty) * fx_volume_depth_weight(d, lo_depth[i00]);
    float w01 = tx * (1.0f - ty) * fx_volume_depth_weight(d, lo_depth[i01]);
    float w10 = (1.0f - tx) * ty * fx_volume_depth_weight(d, lo_depth[i10]);
    float w11 = tx * ty * fx_volume_depth_weight(d, lo_depth[i11]);
    float ws = w00 + w01 + w10 + w11;
    float s = w00 * lo[i00] + w01 * lo[i01] + w10 * lo[i10] + w11 * lo[i11];
    return ws > 1e-30f ? s / ws : lo[i00];
}

#endif
