/* god_rays: crepuscular rays as a screen-space radial blur of an occlusion map towards the
 * light (GPU Gems 3 ch. 13). docs/effects/god_rays.md.
 *
 * 1. Light: the scene's light (a sun's direction or a point/spot/area light's position,
 *    from the frame's lights, by name) projected with the frame's camera, or an artist's
 *    screen position. Light behind the camera fades the effect out (forward cosine over
 *    behind_fade; 0: identity); a light far off screen is bounded (radial_blur.h).
 * 2. Occlusion map: the colour of the pixels that emit the light. "luminance" (the seed's):
 *    pixels brighter than threshold; "sky": background pixels (Depth beyond sky_distance)
 *    brighter than threshold, plus the pixels of light_material, so bright walls cast no
 *    rays. A soft knee, a clamp of the source's luminance (HDR sun discs), an optional
 *    radial falloff around the light.
 * 3. Radial blur: naive (samples, jitter) or polar (exact in the limit, cost independent
 *    of samples); composite "add" (src + rays) or "screen" (src + rays (1 - sat(src))). */
#include "core/effect.h"
#include "scene/lights.h"
#include "core/parallel.h"
#include "math/camera.h"
#include "math/radial_blur.h"
#include "math/hash.h"
#include "core/simd8.h"
#include "math/clones.h"
#include "math/volume_march.h"
#include "scene/aux_map.h"
#include "core/simd4.h"
#include "math/vec.h"

#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

typedef struct god_rays_params {
    char light[FX_STRING_PARAM_MAX];
    int light_source;
    float light_position[2];
    float behind_fade;
    int occlusion;
    float threshold, knee, max_source;
    float sky_distance;
    char light_material[FX_STRING_PARAM_MAX];
    float source_radius;
    int method;
    int samples;
    float decay, weight, density, exposure;
    int composite;
    int jitter, seed;
    float polar_resolution;
    int polar_levels;
    int polar_downsample;
    float volume_density, anisotropy;
    float volume_color[3];
    int extinction;
    float max_distance;
    int volume_steps, volume_downsample, interleave;
    float volume_bias;
    int volume_upsample;
    int light_view_downsample;
} god_rays_params;

enum { SRC_SCENE = 0, SRC_SCREEN };
enum { OCC_SKY = 0, OCC_LUMINANCE };
enum { METHOD_POLAR = 0, METHOD_NAIVE, METHOD_VOLUMETRIC };
enum { EXT_NONE = 0, EXT_VIEW, EXT_FULL };
enum { COMP_ADD = 0, COMP_SCREEN };
enum { UPS_DEPTH = 0, UPS_EDGES };

static const char *const source_items[] = {"scene", "screen"};
static const char *const occlusion_items[] = {"sky", "luminance"};
static const char *const method_items[] = {"polar", "naive", "volumetric"};
static const char *const extinction_items[] = {"none", "view", "full"};
static const char *const composite_items[] = {"add", "screen"};
static const char *const upsample_items[] = {"depth", "edges"};
static const float default_position[2] = {0.5f, 0.3f};
static const float default_volume_color[3] = {0.8f, 0.8f, 0.8f}; /* Cycles' Volume Scatter default */

static const fx_param_def god_rays_param_defs[] = {
    FX_P_STRING(god_rays_params, light, "light", "", "",
                "Scene light the rays come from (by object name; empty: the first sun). The "
                "lights come with the scene sidecar (the add-on writes it; CLI --sidecar)"),
    FX_P_ENUM(god_rays_params, light_source, "light_source", SRC_SCENE, source_items,
              "scene: project the light with the frame's camera; screen: light_position"),
    FX_P_FLOATS(god_rays_params, light_position, "light_position", 2, default_position, -1000.0, 1000.0,
                "factor",
                "Artist override (light_source screen): x, y as fractions of the display window "
                "from its top-left corner; outside [0, 1] is off screen"),
    FX_P_FLOAT(god_rays_params, behind_fade, "behind_fade", 0.2, 0.0, 1.0, 0.0, 1.0, "factor",
               "The effect fades out as the light turns away from the view: full strength when "
               "the cosine between view axis and light is >= this, none at <= 0 (behind)"),
    FX_P_ENUM(god_rays_params, occlusion, "occlusion", OCC_SKY, occlusion_items,
              "sky: background pixels (Depth > sky_distance) and light_material emit; "
              "luminance: every pixel brighter than threshold (the seed's; bright walls glow too)"),
    FX_P_FLOAT(god_rays_params, threshold, "threshold", 0.8, 0.0, 1e6, 0.0, 10.0, "",
               "Luminance above which a pixel emits (both occlusion modes)"),
    FX_P_FLOAT(god_rays_params, knee, "knee", 0.25, 0.0, 1e6, 0.0, 2.0, "",
               "Soft ramp above threshold (0: a hard step)"),
    FX_P_FLOAT(god_rays_params, max_source, "max_source", 8.0, 0.0, 1e6, 0.5, 50.0, "",
               "Emitting colours are scaled down to at most this luminance (HDR sun discs)"),
    FX_P_FLOAT(god_rays_params, sky_distance, "sky_distance", 1000.0, 0.0, 1e30, 10.0, 1e5, "",
               "occlusion sky: planar depth (scene units) beyond which a pixel is sky"),
    FX_P_STRING(god_rays_params, light_material, "light_material", "", "",
                "occlusion sky: a material whose pixels also emit (an emissive window); empty: none"),
    FX_P_FLOAT(god_rays_params, source_radius, "source_radius", 0.0, 0.0, 100.0, 0.0, 1.0, "factor",
               "Emission falls off smoothly to 0 at this distance from the light, as a fraction "
               "of the frame's diagonal (0: no falloff)"),
    FX_P_ENUM(god_rays_params, method, "method", METHOD_POLAR, method_items,
              "The two radial blurs of the bright sky: polar: epipolar lines through the light, exact "
              "in the limit, cost independent of samples; naive: GPU Gems' per-pixel loop of `samples` "
              "samples. volumetric: single scattering of the sun in a homogeneous medium, marched along "
              "each pixel's view ray through the sun's light view (rendered by the add-on; shadowed air "
              "stays dark), in the units of Cycles' Volume Scatter (volume_density, anisotropy)"),
    FX_P_INT(god_rays_params, samples, "samples", 100, 1, 65536, 8, 400, "",
             "naive: samples per pixel (the seed: 100)"),
    FX_P_FLOAT(god_rays_params, decay, "decay", 0.97, 0.0, 1.0, 0.9, 1.0, "factor",
               "Illumination decay per sample at 100 samples (rescaled for other counts)"),
    FX_P_FLOAT(god_rays_params, weight, "weight", 1.0, 0.0, 1e4, 0.0, 10.0, "",
               "Weight of each sample (0: identity)"),
    FX_P_FLOAT(god_rays_params, density, "density", 0.9, 0.0, 1.0, 0.3, 1.0, "factor",
               "Fraction of the way to the light the samples cover"),
    FX_P_FLOAT(god_rays_params, exposure, "exposure", 0.01, 0.0, 1e4, 0.0, 0.1, "",
               "Overall scale (rays = 100 weight exposure x the decayed mean; 0: identity)"),
    FX_P_ENUM(god_rays_params, composite, "composite", COMP_ADD, composite_items,
              "add: src + rays; screen: src + rays (1 - clamp(src, 0, 1)) (no clipping of bright areas)"),
    FX_P_BOOL(god_rays_params, jitter, "jitter", 0,
              "naive: offset each pixel's samples by a seeded hash (banding becomes noise)"),
    FX_P_INT(god_rays_params, seed, "seed", 0, -2147483647, 2147483647, 0, 100, "", "Jitter seed"),
    FX_P_FLOAT(god_rays_params, polar_resolution, "polar_resolution", 1.0, 0.05, 16.0, 0.25, 4.0, "",
               "polar: lines per pixel of arc at the farthest pixel"),
    FX_P_INT(god_rays_params, polar_levels, "polar_levels", 2, 1, 32, 1, 8, "",
             "polar: decay rates per octave of distance (accuracy of the decay)"),
    FX_P_INT(god_rays_params, polar_downsample, "polar_downsample", 1, 1, 16, 1, 4, "",
             "polar: run on the occlusion map reduced by this factor per axis (box average), "
             "rays interpolated back; ~factor^2 faster, shaft edges soften by ~factor pixels"),
    FX_P_FLOAT(god_rays_params, volume_density, "volume_density", 0.03, 0.0, 1e6, 0.0, 0.3, "1/m",
               "volumetric: the medium's density per scene unit, as Cycles' Volume Scatter Density "
               "(times volume_color: the scattering and extinction coefficients; 0: identity)"),
    FX_P_FLOATS(god_rays_params, volume_color, "volume_color", 3, default_volume_color, 0.0, 1000.0, "color",
                "volumetric: as Cycles' Volume Scatter Color (default 0.8 grey, as the node's): the "
                "scattering and extinction coefficients are volume_density x this (a coloured medium "
                "scatters each channel by its own; extinction uses the channels' mean)"),
    FX_P_FLOAT(god_rays_params, anisotropy, "anisotropy", 0.6, -1.0, 1.0, -1.0, 1.0, "",
               "volumetric: Henyey-Greenstein anisotropy, as Cycles' Volume Scatter Anisotropy (> 0: "
               "forward, the shafts glow looking towards the sun; clamped to +-0.999)"),
    FX_P_ENUM(god_rays_params, extinction, "extinction", EXT_FULL, extinction_items,
              "volumetric: none: in-scattering only; view: the medium also dims what lies behind it "
              "(exp(-density distance)); full: and the sunlight on its way in, from where it first meets the "
              "scene (the light view's nearest surface), both in the air and to each surface (Cycles' "
              "Volume Scatter does both; bounce light is dimmed as the sun's direct light is)"),
    FX_P_FLOAT(god_rays_params, max_distance, "max_distance", 1e4, 0.0, 1e30, 1.0, 1e4, "m",
               "volumetric: the medium ends this far from the camera (it also ends at each pixel's "
               "surface and outside the light view's box)"),
    FX_P_INT(god_rays_params, volume_steps, "volume_steps", 24, 1, 4096, 4, 256, "",
             "volumetric: march steps per ray (with interleave n, n x n neighbours share their strata: "
             "n^2 x the steps' worth)"),
    FX_P_INT(god_rays_params, volume_downsample, "volume_downsample", 4, 1, 16, 1, 8, "",
             "volumetric: march one ray per factor x factor pixels, upsampled by depth likeness"),
    FX_P_INT(god_rays_params, interleave, "interleave", 2, 1, 8, 1, 8, "",
             "volumetric: interleaved sampling: an n x n block of rays marches with n^2 different step "
             "offsets, gathered back by a depth-aware n x n box (1: midpoints, no gather)"),
    FX_P_FLOAT(god_rays_params, volume_bias, "volume_bias", 0.02, 0.0, 100.0, 0.0, 0.5, "m",
               "volumetric: depth-test bias in the light view (scene units)"),
    FX_P_ENUM(god_rays_params, volume_upsample, "volume_upsample", UPS_DEPTH, upsample_items,
              "volumetric: how the reduced grid comes back to full resolution: depth: each pixel's 4 "
              "texels weighted by their depth's likeness to the pixel's; edges: a plain bilinear where "
              "the pixel lies within 5 % of the depth of the plane through its 4 texels (a floor or wall "
              "at any slant; fewer instructions where volume_downsample is a multiple of 8), the likeness "
              "weights only at depth edges and thin objects (draft)"),
    FX_P_INT(god_rays_params, light_view_downsample, "light_view_downsample", 1, 1, 8, 1, 4, "",
             "volumetric: march through the light view reduced by this factor per axis (every factor-th "
             "texel each way: shadows are neither widened nor narrowed, features below factor texels "
             "may drop out); only every factor-th row of the view is read, and the full map never "
             "exists: 1 / factor^2 of the memory and a faster first frame (draft: 2)"),
};

static fx_pass_set god_rays_passes(const void *params)
{
    const god_rays_params *p = params;
    fx_pass_set s = 0;
    if (p->method == METHOD_VOLUMETRIC)
        return FX_PASS_BIT(FX_PASS_DEPTH);
    if (p->occlusion == OCC_SKY) {
        s |= FX_PASS_BIT(FX_PASS_DEPTH);
        if (p->light_material[0])
            s |= FX_PASS_BIT(FX_PASS_CRYPTO_MATERIAL);
    }
    return s;
}

static int god_rays_needs_camera(const void *params)
{
    const god_rays_params *p = params;
    return p->light_source == SRC_SCENE || p->method == METHOD_VOLUMETRIC;
}

static int god_rays_halo(const void *params, int width, int height)
{
    const god_rays_params *p = params;
    if (p->method == METHOD_VOLUMETRIC) /* the gather and the upsample */
        return (p->interleave / 2 + 2) * p->volume_downsample;
    return width > height ? width : height; /* rays come from anywhere in the frame */
}

/* Zero weight or exposure is the identity: the stack skips the effect. */
static int god_rays_identity(const void *params)
{
    const god_rays_params *p = params;
    if (p->method == METHOD_VOLUMETRIC)
        return p->volume_density == 0.0f ||
               (p->volume_color[0] == 0.0f && p->volume_color[1] == 0.0f && p->volume_color[2] == 0.0f);
    return p->weight == 0.0f || p->exposure == 0.0f;
}

/* Method volumetric writes each output pixel from its own source pixel only (vol_put,
 * vol_put4_add: read, then written) and makes it finite there (finite4, fx_finite8): the
 * stack may hand it its own buffer as dst (no fresh frame-sized buffer on a consumed
 * frame's first run) and skip its whole-frame NaN/Inf scan. The radial methods read
 * neighbours (the blur) and are neither. */
static int god_rays_volumetric_only(const void *params)
{
    return ((const god_rays_params *)params)->method == METHOD_VOLUMETRIC;
}

/* volumetric: the light's depth view, by the light's name ("" = the scene's first sun). */
static int god_rays_aux_views(const void *params, fx_aux_need *out, int max)
{
    const god_rays_params *p = params;
    if (p->method != METHOD_VOLUMETRIC || max < 1)
        return 0;
    snprintf(out->name, sizeof out->name, "light:%.80s", p->light);
    out->kind = "light";
    snprintf(out->light, sizeof out->light, "%.80s", p->light);
    return 1;
}

static fx_result god_rays_validate(const void *params, char *err, size_t err_size)
{
    const god_rays_params *p = params;
    if (p->method == METHOD_VOLUMETRIC && p->light_source != SRC_SCENE) {
        snprintf(err, err_size, "method volumetric marches the scene's light (light_source scene), not a "
                                "screen position: set light_source to scene or choose method polar");
        return FX_ERR_BAD_PARAM;
    }
    if (p->method == METHOD_VOLUMETRIC && !(p->max_distance > 0.0f) && p->volume_density > 0.0f) {
        snprintf(err, err_size, "max_distance must be above 0 with method volumetric");
        return FX_ERR_BAD_PARAM;
    }
    return FX_OK;
}

/* Light in frame pixels and the fade factor; returns FX_OK or an error. */
static fx_result find_light(const fx_effect_run *run, const god_rays_params *p, const char *where, double *lx,
                            double *ly, double *fade)
{
    const fx_frame *f = run->frame;
    if (p->light_source == SRC_SCREEN) {
        double dw = f->display_window[2] - f->display_window[0] + 1;
        double dh = f->display_window[3] - f->display_window[1] + 1;
        *lx = p->light_position[0] * dw - (f->data_window[0] - f->display_window[0]);
        *ly = p->light_position[1] * dh - (f->data_window[1] - f->display_window[1]);
        *fade = 1.0;
        return FX_OK;
    }
    fx_view v;
    if (!fx_view_init(&v, f))
        return fx_fail(run->ctx, FX_ERR_NO_CAMERA,
                       "%s needs the frame's camera (light_source scene); give the scene sidecar with "
                       "--sidecar, or set light_source to screen",
                       where);
    fx_light L;
    fx_result r = fx_frame_find_light(f, p->light, where, &L);
    if (r != FX_OK)
        return r;
    fx_vec3 to_light; /* view space, from the eye */
    int at_infinity = L.type == FX_LIGHT_SUN;
    if (at_infinity)
        to_light = fx_world_dir_to_view(&v, fx_v3_scale(L.direction, -1.0f));
    else
        to_light = fx_world_to_view(&v, L.position);
    double len = sqrt((double)to_light.x * to_light.x + (double)to_light.y * to_light.y +
                      (double)to_light.z * to_light.z);
    double cosv = len > 1e-30 ? -to_light.z / len : 0.0;
    *fade = p->behind_fade > 0.0f ? fx_smoothstep(0.0f, p->behind_fade, (float)cosv) : (cosv > 0.0 ? 1.0 : 0.0);
    if (*fade <= 0.0) {
        *lx = *ly = 0.0;
        return FX_OK;
    }
    /* clip coordinates in double: w -> 0 gives a far (bounded) light, not Inf */
    const float *P = v.cam.projection;
    double hw = at_infinity ? 0.0 : 1.0;
    double cx = P[0] * to_light.x + P[1] * to_light.y + P[2] * to_light.z + P[3] * hw;
    double cy = P[4] * to_light.x + P[5] * to_light.y + P[6] * to_light.z + P[7] * hw;
    double cw = P[12] * to_light.x + P[13] * to_light.y + P[14] * to_light.z + P[15] * hw;
    double nx, ny;
    if (v.orthographic || !(cw > 0.0)) {
        /* no finite projection (orthographic camera and a sun): parallel rays, light far
         * along the light's on-screen direction */
        double dx = to_light.x, dy = to_light.y, l2 = hypot(dx, dy);
        if (l2 < 1e-30) {
            nx = ny = 0.0;
        } else {
            nx = dx / l2 * 1e9;
            ny = dy / l2 * 1e9;
        }
    } else {
        nx = cx / fmax(cw, 1e-300);
        ny = cy / fmax(cw, 1e-300);
        if (!isfinite(nx) || !isfinite(ny) || fabs(nx) > 1e12 || fabs(ny) > 1e12) {
            double l2 = hypot(cx, cy);
            nx = l2 > 0 ? cx / l2 * 1e12 : 0.0;
            ny = l2 > 0 ? cy / l2 * 1e12 : 0.0;
        }
    }
    *lx = (nx + 1.0) * 0.5 * v.disp_w - v.off_x;
    *ly = (1.0 - ny) * 0.5 * v.disp_h - v.off_y;
    return FX_OK;
}

typedef struct occ_job {
    const fx_effect_run *run;
    const god_rays_params *p;
    const float *depth;
    const fx_mask *material;
    float *occ;
    double lx, ly, radius;
} occ_job;

/* The emitting colour of pixel (x, y) (a zero fourth lane) */
static inline v4f occ_pixel(const occ_job *j, int x, int y)
{
    const god_rays_params *p = j->p;
    const int w = j->run->width;
    size_t i = (size_t)y * w + x;
    /* occlusion sky: a pixel that is neither sky nor light_material emits nothing (the
     * general path below gives exactly 0 there too: the colour is finite and >= 0) */
    if (p->occlusion == OCC_SKY && !(j->depth && j->depth[i] > p->sky_distance) &&
        !(j->material && j->material->coverage[i] > 0.0f))
        return V4(0.0f);
    /* emitting colour: negative, NaN and +Inf channels count as 0 */
    v4f c = ld4(j->run->src + i * 4);
    c = sel4(c > V4(0.0f), c, V4(0.0f));
    c = sel4(c <= V4(FLT_MAX), c, V4(0.0f));
    float lum = 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2];
    float m = p->knee > 0.0f ? fx_smoothstep(p->threshold, p->threshold + p->knee, lum)
                             : (lum > p->threshold ? 1.0f : 0.0f);
    if (p->occlusion == OCC_SKY) {
        float sky = j->depth && j->depth[i] > p->sky_distance ? 1.0f : 0.0f;
        if (j->material)
            sky = fmaxf(sky, j->material->coverage[i]);
        m *= sky;
    }
    if (j->radius > 0.0 && m > 0.0f) {
        double d = hypot(x + 0.5 - j->lx, y + 0.5 - j->ly) / j->radius;
        m *= d >= 1.0 ? 0.0f : (float)((1.0 - d * d) * (1.0 - d * d));
    }
    float k = m;
    if (lum > p->max_source && lum > 0.0f)
        k *= p->max_source / lum;
    return c * (v4f){k, k, k, 0.0f};
}

static void occ_rows(void *user, int begin, int end)
{
    const occ_job *j = user;
    const int w = j->run->width;
    for (int y = begin; y < end; y++)
        for (int x = 0; x < w; x++)
            st4(j->occ + ((size_t)y * w + x) * 4, occ_pixel(j, x, y));
}

/* The reduced map straight from the pixels (the f x f box means radial_blur's reduction
 * computes from a full-size map: the same sums in the same order, no full-size buffer) */
typedef struct occ_lo_job {
    const occ_job *oj;
    float *lo;
    int lw, f;
} occ_lo_job;

static void occ_lo_rows(void *user, int begin, int end)
{
    const occ_lo_job *j = user;
    const int w = j->oj->run->width, h = j->oj->run->height, f = j->f;
    for (int Y = begin; Y < end; Y++) {
        int y0 = Y * f, y1 = y0 + f > h ? h : y0 + f;
        for (int X = 0; X < j->lw; X++) {
            int x0 = X * f, x1 = x0 + f > w ? w : x0 + f;
            double acc[3] = {0, 0, 0};
            for (int y = y0; y < y1; y++)
                for (int x = x0; x < x1; x++) {
                    v4f q = occ_pixel(j->oj, x, y);
                    acc[0] += q[0];
                    acc[1] += q[1];
                    acc[2] += q[2];
                }
            fx_radial_store_cell(j->lo + ((size_t)Y * j->lw + X) * 4, acc, (double)(y1 - y0) * (x1 - x0));
        }
    }
}

typedef struct comp_job {
    const fx_effect_run *run;
    const float *rays;   /* full size (may be run->dst itself: read before written), or NULL: */
    const float *lrays;  /* the reduced rays (lw x lh, factor f), interpolated here */
    int lw, lh, f;
    double fade;
    int screen;
    const int *cx;       /* reduced: per column, the left texel and its weight towards the */
    const float *ctx;    /* right one (the per-pixel arithmetic of the bilinear, done once) */
} comp_job;

/* The column part of the reduced composite's bilinear for columns [x0, x1). */
static void comp_columns(int x0, int x1, int lw, int f, int *cx, float *ctx)
{
    double inv_f = 1.0 / f;
    for (int x = x0; x < x1; x++) {
        double u = (x + 0.5) * inv_f - 0.5;
        u = u < 0.0 ? 0.0 : u > lw - 1 ? lw - 1 : u;
        int X0 = (int)u;
        cx[x - x0] = X0;
        ctx[x - x0] = (float)(u - X0);
    }
}

static void comp_rows(void *user, int begin, int end)
{
    const comp_job *j = user;
    const fx_effect_run *run = j->run;
    const int w = run->width;
    const v4f fade = V4((float)j->fade);
    for (int y = run->roi.y0 + begin; y < run->roi.y0 + end; y++) {
        /* reduced: fx_radial_blur_upsample's bilinear, its row part once per row */
        const float *r0 = NULL, *r1 = NULL;
        v4f ty = V4(0.0f);
        double inv_f = 1.0 / j->f;
        if (!j->rays) {
            double v = (y + 0.5) * inv_f - 0.5;
            v = v < 0.0 ? 0.0 : v > j->lh - 1 ? j->lh - 1 : v;
            int Y0 = (int)v, Y1 = Y0 + 1 < j->lh ? Y0 + 1 : Y0;
            ty = V4((float)(v - Y0));
            r0 = j->lrays + (size_t)Y0 * j->lw * 4;
            r1 = j->lrays + (size_t)Y1 * j->lw * 4;
        }
        for (int x = run->roi.x0; x < run->roi.x1; x++) {
            size_t i = (size_t)y * w + x;
            const v4f s = ld4(run->src + i * 4);
            v4f r;
            if (j->rays) {
                r = ld4(j->rays + i * 4);
            } else {
                int X0 = j->cx[x - run->roi.x0], X1 = X0 + 1 < j->lw ? X0 + 1 : X0;
                v4f tx = V4(j->ctx[x - run->roi.x0]);
                v4f a0 = ld4(r0 + 4 * X0), a1 = ld4(r0 + 4 * X1), b0 = ld4(r1 + 4 * X0), b1 = ld4(r1 + 4 * X1);
                v4f a = a0 + tx * (a1 - a0), b = b0 + tx * (b1 - b0);
                r = a + ty * (b - a); /* the zero lane stays 0 */
            }
            v4f add = r * fade; /* alpha lane: rays hold 0 there */
            if (j->screen)
                add *= V4(1.0f) - min4(max4(s, V4(0.0f)), V4(1.0f));
            st4(run->dst + i * 4, finite4(s + add));
        }
    }
}

/* RGB of n four-lane pixels into a 3-channel pass */
static void copy_rgb(float *dst, const float *src4, size_t n)
{
    for (size_t i = 0; i < n; i++)
        memcpy(dst + i * 3, src4 + i * 4, 3 * sizeof(float));
}

/* Process stage 1: what occludes the light. With occlusion sky, the Depth pass (and the
 * light material's mask when one is named; *material is the caller's to free). */
static fx_result occlusion_setup(const fx_effect_run *run, const god_rays_params *p, double lx, double ly,
                                 occ_job *oj, fx_mask **material)
{
    memset(oj, 0, sizeof *oj);
    *material = NULL;
    oj->run = run;
    oj->p = p;
    oj->lx = lx;
    oj->ly = ly;
    oj->radius = p->source_radius * hypot(run->width, run->height);
    if (p->occlusion != OCC_SKY)
        return FX_OK;
    const fx_pass *dp = fx_frame_find_pass(run->frame, "Depth");
    if (!dp)
        return fx_fail(run->ctx, FX_ERR_MISSING_PASS,
                       "%s: occlusion sky needs the Depth pass (or set occlusion to luminance)", run->where);
    oj->depth = dp->data;
    if (!p->light_material[0])
        return FX_OK;
    char *names[1] = {(char *)p->light_material};
    fx_mask_spec spec;
    memset(&spec, 0, sizeof spec);
    spec.materials = names;
    spec.material_count = 1;
    fx_result r = fx_mask_build(run->ctx, &spec, run->frame, run->where, material);
    oj->material = *material;
    return r;
}

/* Process stage 2: the radial blur's settings from the parameters. */
static void blur_setup(const fx_effect_run *run, const god_rays_params *p, double lx, double ly,
                       fx_radial_blur *rb)
{
    memset(rb, 0, sizeof *rb);
    rb->light_x = lx;
    rb->light_y = ly;
    rb->samples = p->samples;
    rb->decay = p->decay;
    rb->density = p->density;
    rb->scale = (double)FX_RAYS_REFERENCE_SAMPLES * p->weight * p->exposure;
    rb->jitter = p->jitter;
    rb->seed = (uint32_t)p->seed;
    double frame_no = fx_effect_scene_frame(run);
    rb->frame = isfinite(frame_no) && fabs(frame_no) < 2e9 ? (int)floor(frame_no) : 0;
    rb->angular = 1.0 / p->polar_resolution;
    rb->levels = p->polar_levels;
    rb->downsample = p->polar_downsample;
}

/* Process stage 3a, reduced: the map built reduced, the rays interpolated in the
 * composite; no frame-sized temporary (the same bits as through full-size buffers). */
static fx_result run_reduced(const fx_effect_run *run, const god_rays_params *p, occ_job *oj,
                             const fx_radial_blur *rb, int lw, int lh, double fade)
{
    const char *where = run->where;
    const size_t lbytes = (size_t)lw * lh * 4 * sizeof(float);
    fx_result r = fx_check_budget(run->ctx, (uint64_t)lbytes * 2, where);
    float *lo = r == FX_OK ? fx_buffer_get(run->ctx, lbytes) : NULL;
    float *lrays = r == FX_OK ? fx_buffer_get(run->ctx, lbytes) : NULL;
    if (r == FX_OK && (!lo || !lrays))
        r = fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the reduced occlusion map", where);
    if (r == FX_OK) {
        memset(lrays, 0, lbytes);
        occ_lo_job lj = {oj, lo, lw, rb->downsample};
        fx_parallel_for(run->ctx, lh, fx_grain_for(run->ctx, lh), occ_lo_rows, &lj);
        r = fx_radial_blur_polar_reduced(run->ctx, lo, lrays, run->width, run->height, rb, &run->roi, where);
    }
    int cols = run->roi.x1 - run->roi.x0;
    int *cx = r == FX_OK ? fx_mem_alloc((size_t)cols * sizeof(int)) : NULL;
    float *ctx = r == FX_OK ? fx_mem_alloc((size_t)cols * sizeof(float)) : NULL;
    if (r == FX_OK && (!cx || !ctx))
        r = fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where);
    if (r == FX_OK) {
        comp_columns(run->roi.x0, run->roi.x1, lw, rb->downsample, cx, ctx);
        comp_job cj = {run, NULL, lrays, lw, lh, rb->downsample, fade, p->composite == COMP_SCREEN, cx, ctx};
        int rows = run->roi.y1 - run->roi.y0;
        fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), comp_rows, &cj);
    }
    fx_mem_free(cx);
    fx_mem_free(ctx);
    fx_buffer_put(run->ctx, lo, lbytes);
    fx_buffer_put(run->ctx, lrays, lbytes);
    return r;
}

/* Process stage 3b, full size: occlusion and rays as RGB + a zero lane per pixel
 * (four-lane vectors), the rays in dst unless the debug passes want them whole. */
static fx_result run_full(const fx_effect_run *run, const god_rays_params *p, occ_job *oj,
                          const fx_radial_blur *rb, double fade)
{
    const int w = run->width, h = run->height;
    const char *where = run->where;
    size_t n4 = 0;
    if (!fx_size_mul(&n4, (size_t)w, (size_t)h, 4))
        return fx_fail(run->ctx, FX_ERR_LIMIT, "%s: frame too large", where);
    /* frame-sized: from the context's buffer store (no page faults frame after frame);
     * occ is written whole, rays inside the ROI (the debug pass wants it whole) */
    const size_t bytes = n4 * sizeof(float);
    /* polar over the whole frame reads occ whole before it writes any ray: occ can be dst
     * too, so the first frame of a process touches one fresh frame-sized buffer, not two
     * (the map outside a smaller ROI would stay in dst: then a buffer of its own) */
    const int whole = run->roi.x0 == 0 && run->roi.y0 == 0 && run->roi.x1 == w && run->roi.y1 == h;
    const int in_dst = p->method == METHOD_POLAR && !run->debug && whole;
    float *occ = in_dst ? run->dst : fx_buffer_get(run->ctx, bytes);
    /* the rays go to dst (same layout; the composite reads each pixel before writing it)
     * unless the debug pass wants them whole */
    float *rays = run->debug ? fx_buffer_get(run->ctx, bytes) : run->dst;
    if (occ && rays && run->debug)
        memset(rays, 0, bytes);
    if (!occ || !rays) {
        if (!in_dst)
            fx_buffer_put(run->ctx, occ, bytes);
        if (run->debug)
            fx_buffer_put(run->ctx, rays, bytes);
        return fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the occlusion map", where);
    }
    oj->occ = occ;
    fx_parallel_for(run->ctx, h, fx_grain_for(run->ctx, h), occ_rows, oj);

    fx_result r;
    if (p->method == METHOD_NAIVE)
        r = fx_radial_blur_naive(run->ctx, occ, rays, w, h, rb, &run->roi, where);
    else
        r = fx_radial_blur_polar(run->ctx, occ, rays, w, h, rb, &run->roi, where);
    if (r == FX_OK) {
        comp_job cj = {run, rays, NULL, 0, 0, 1, fade, p->composite == COMP_SCREEN, NULL, NULL};
        int rows = run->roi.y1 - run->roi.y0;
        fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), comp_rows, &cj);
        if (run->debug) {
            float *dbg = fx_effect_debug_pass(run, "occlusion", 3, &r);
            if (dbg)
                copy_rgb(dbg, occ, (size_t)w * h);
            float *dr = r == FX_OK ? fx_effect_debug_pass(run, "rays", 3, &r) : NULL;
            if (dr)
                copy_rgb(dr, rays, (size_t)w * h);
        }
    }
    if (!in_dst)
        fx_buffer_put(run->ctx, occ, bytes);
    if (run->debug)
        fx_buffer_put(run->ctx, rays, bytes);
    return r;
}

/* ---- method volumetric (math/volume_march.h) ---- */

typedef struct vol_job {
    const fx_effect_run *run;
    const fx_volume *vol;
    const float *depth;
    const float *lo, *lo_t, *lo_depth; /* the reduced in-scatter and transmittance (f > 1) or
                                          the full ones (f = 1) */
    int lw, lh, f;
    v4f rad;                    /* the sun's colour * strength */
    int screen;
    float *dbg;                 /* debug "inscatter" (RGB), or NULL */
    const int *col_x0;          /* per ROI column: its lo texel (left) and the right one's weight */
    const float *col_t;
    int edges;                  /* volume_upsample edges */
} vol_job;

/* volume_upsample edges: a plain bilinear where each pixel's depth lies within this relative
 * distance of the depth that the cell's 4 texels give it if they and the pixel lie on one
 * plane (inverse depth is affine in screen space on a plane, so its bilinear is exact
 * there): a floor or wall seen at any slant, not only one facing the camera; depth edges
 * and thin objects keep the likeness weights. */
#define VOL_ALIKE 0.05f

/* The cells of lo rows r0, r1 gathered once into vectors (row: 12 lw floats: per column
 * the 4 texels' depths, in-scatter and transmittance; bcast: each of them broadcast). */
static void vol_row_cells(const vol_job *j, size_t r0, size_t r1, float *row, v4f *bcast)
{
    const int lw = j->lw;
    const float *restrict lo = j->lo, *restrict lt = j->lo_t, *restrict ld = j->lo_depth;
    for (int X = 0; X < lw; X++) {
        const int X1 = X + 1 < lw ? X + 1 : X;
        st4(row + 12 * X, (v4f){ld[r0 + X], ld[r0 + X1], ld[r1 + X], ld[r1 + X1]});
        st4(row + 12 * X + 4, (v4f){lo[r0 + X], lo[r0 + X1], lo[r1 + X], lo[r1 + X1]});
        st4(row + 12 * X + 8, (v4f){lt[r0 + X], lt[r0 + X1], lt[r1 + X], lt[r1 + X1]});
        for (int m = 0; m < 12; m++)
            bcast[12 * X + m] = V4(row[12 * X + m]);
    }
}

/* Row y's place on the reduced grid (lo rows r0, r1; ty: r1's weight), its cells gathered
 * (vol_row_cells) when they changed since the last row; returns whether they did. */
static int vol_row_begin(const vol_job *j, int y, float *row, v4f *bcast, int *cached_Y0, size_t *r0, size_t *r1,
                         float *ty)
{
    int Y0 = 0;
    fx_volume_lo_coord(y, j->f, j->lh, &Y0, ty);
    *r0 = (size_t)Y0 * j->lw;
    *r1 = Y0 + 1 < j->lh ? *r0 + (size_t)j->lw : *r0;
    const int changed = Y0 != *cached_Y0;
    if (changed)
        vol_row_cells(j, *r0, *r1, row, bcast);
    *cached_Y0 = Y0;
    return changed;
}

/* volume_upsample edges, per lo column X of the row (ty: the row's weight of lo row r1):
 * the vertical lerps of L, T and inverse depth and their steps to column X + 1 (e: 6 lw
 * floats); inv: the two lo rows' inverse depths (2 lw), made when the cells change (every
 * f rows). */
static void vol_row_edges(const vol_job *j, size_t r0, size_t r1, float ty, int cells_changed, float *e,
                          float *inv)
{
    const int lw = j->lw;
    float *Lv = e, *dL = e + lw, *Tv = e + 2 * lw, *dT = e + 3 * lw, *Iv = e + 4 * lw, *dI = e + 5 * lw;
    float *i0 = inv, *i1 = inv + lw;
    const float *lo = j->lo, *lt = j->lo_t, *ld = j->lo_depth;
    int X = 0;
    if (cells_changed) { /* lo depths are > 0 (fx_volume_weight_depth) */
        for (; X + 4 <= lw; X += 4) {
            st4(i0 + X, V4(1.0f) / ld4(ld + r0 + X));
            st4(i1 + X, V4(1.0f) / ld4(ld + r1 + X));
        }
        for (; X < lw; X++) {
            i0[X] = 1.0f / ld[r0 + X];
            i1[X] = 1.0f / ld[r1 + X];
        }
    }
    const v4f t4 = V4(ty);
    for (X = 0; X + 4 <= lw; X += 4) { /* the lerps, 4 columns at a time (lane by lane: the same bits) */
        const v4f a = ld4(lo + r0 + X), b = ld4(lt + r0 + X), c = ld4(i0 + X);
        st4(Lv + X, a + t4 * (ld4(lo + r1 + X) - a));
        st4(Tv + X, b + t4 * (ld4(lt + r1 + X) - b));
        st4(Iv + X, c + t4 * (ld4(i1 + X) - c));
    }
    for (; X < lw; X++) {
        Lv[X] = lo[r0 + X] + ty * (lo[r1 + X] - lo[r0 + X]);
        Tv[X] = lt[r0 + X] + ty * (lt[r1 + X] - lt[r0 + X]);
        Iv[X] = i0[X] + ty * (i1[X] - i0[X]);
    }
    for (X = 0; X + 5 <= lw; X += 4) {
        st4(dL + X, ld4(Lv + X + 1) - ld4(Lv + X));
        st4(dT + X, ld4(Tv + X + 1) - ld4(Tv + X));
        st4(dI + X, ld4(Iv + X + 1) - ld4(Iv + X));
    }
    for (; X + 1 < lw; X++) {
        dL[X] = Lv[X + 1] - Lv[X];
        dT[X] = Tv[X + 1] - Tv[X];
        dI[X] = Iv[X + 1] - Iv[X];
    }
    dL[lw - 1] = dT[lw - 1] = dI[lw - 1] = 0.0f;
}

/* One row's L and T (n pixels from roi.x0) from the reduced grid: the cells of the row's two
 * lo rows gathered once into vectors (row: 12 lw floats), then 4 pixels at a time
 * (fx_volume_upsample_same4 on one cell, fx_volume_upsample_cell4 across cells: the
 * depth-aware bilinear, bit for bit fx_volume_upsample's). */
static void vol_row_lt(const vol_job *j, int y, float *row, v4f *bcast, int *cached_Y0, float *restrict Lr,
                       float *restrict Tr)
{
    const int lw = j->lw, x0 = j->run->roi.x0, n = j->run->roi.x1 - x0;
    size_t r0 = 0, r1 = 0;
    float ty = 0.0f;
    vol_row_begin(j, y, row, bcast, cached_Y0, &r0, &r1, &ty);
    const v4f by = {1.0f - ty, 1.0f - ty, ty, ty};
    const float *restrict dep = j->depth + (size_t)y * j->run->width + x0;
    const int *restrict cx = j->col_x0;
    const float *restrict ct = j->col_t;
    const float far = j->vol->far_limit;
    int k = 0;
    while (k + 4 <= n) {
        const v4f dk = ld4(dep + k); /* fx_volume_weight_depth, 4 lanes */
        const v4f d = sel4((dk > V4(0.0f)) & (dk < V4(far)), dk, V4(FX_VOLUME_BG_DEPTH));
        v4f L, T;
        if (cx[k] == cx[k + 3]) { /* 4 pixels on one cell: with f >= 4, the runs are aligned below */
            fx_volume_upsample_same4(row + 12 * cx[k], bcast + 12 * cx[k], ty, ld4(ct + k), d, &L, &T);
        } else if (j->f >= 4) { /* the rest of this cell's run, one by one: the next group starts a run */
            for (const int X0 = cx[k]; cx[k] == X0; k++)
                fx_volume_upsample(j->lo, j->lo_t, j->lo_depth, r0, r1, X0, X0 + 1 < lw ? X0 + 1 : X0, ct[k],
                                   ty, fx_volume_weight_depth(dep[k], far), &Lr[k], &Tr[k]);
            continue;
        } else {
            const float *cell[4] = {row + 12 * cx[k], row + 12 * cx[k + 1], row + 12 * cx[k + 2],
                                    row + 12 * cx[k + 3]};
            fx_volume_upsample_cell4(cell, by, ld4(ct + k), d, &L, &T);
        }
        st4(Lr + k, L);
        st4(Tr + k, T);
        k += 4;
    }
    for (; k < n; k++) {
        const int X0 = cx[k];
        fx_volume_upsample(j->lo, j->lo_t, j->lo_depth, r0, r1, X0, X0 + 1 < lw ? X0 + 1 : X0, ct[k],
                           ty, fx_volume_weight_depth(dep[k], far), &Lr[k], &Tr[k]);
    }
}

/* One pixel's output: src T + L (T: the view transmittance, with extinction full times the
 * light's transmittance on its way to the surface; L: the in-scatter), screened or added;
 * the debug pass gets what was added. */
static inline void vol_put(const vol_job *j, size_t i, float L, float T)
{
    v4f base = ld4(j->run->src + i * 4) * (v4f){T, T, T, 1.0f};
    v4f add = j->rad * V4(L);
    if (j->screen)
        add *= V4(1.0f) - min4(max4(base, V4(0.0f)), V4(1.0f));
    st4(j->run->dst + i * 4, finite4(base + add));
    if (j->dbg) {
        j->dbg[3 * i] = add[0];
        j->dbg[3 * i + 1] = add[1];
        j->dbg[3 * i + 2] = add[2];
    }
}

/* vol_put for 4 pixels from i on, added, no debug: two pixels per 8-lane vector (one AVX
 * register in vol_rows' AVX2 clone), {T,T,T,1} and L spread from the lanes of T4 and L4;
 * the same products and sums as vol_put, so the same bits. */
static inline __attribute__((always_inline)) void vol_put4_add_at(v4f rad, const float *src, float *dst, v4f L4,
                                                                   v4f T4)
{
    const v4f one = V4(1.0f);
    const v8f rad8 = __builtin_shufflevector(rad, rad, 0, 1, 2, 3, 0, 1, 2, 3);
    const v8f t01 = __builtin_shufflevector(T4, one, 0, 0, 0, 4, 1, 1, 1, 4);
    const v8f t23 = __builtin_shufflevector(T4, one, 2, 2, 2, 4, 3, 3, 3, 4);
    const v8f l01 = __builtin_shufflevector(L4, L4, 0, 0, 0, 0, 1, 1, 1, 1);
    const v8f l23 = __builtin_shufflevector(L4, L4, 2, 2, 2, 2, 3, 3, 3, 3);
    fx_store8(dst, fx_finite8(fx_load8(src) * t01 + rad8 * l01)); /* src may be dst (god_rays_in_place) */
    fx_store8(dst + 8, fx_finite8(fx_load8(src + 8) * t23 + rad8 * l23));
}

static inline __attribute__((always_inline)) void vol_put4_add(const vol_job *j, size_t i, v4f L4, v4f T4)
{
    vol_put4_add_at(j->rad, j->run->src + i * 4, j->run->dst + i * 4, L4, T4);
}

/* The groups off vol_row_edges_body's bilinear path, out of line (inlined, their registers
 * crowded the bilinear path's into spills): the likeness upsample on one cell
 * (fx_volume_upsample_same4) and across cells (fx_volume_upsample per pixel); the same
 * functions, so the same bits. */
FX_CLONES __attribute__((noinline)) static void vol_group_same4(const float *cell, const v4f *bc, float ty, v4f tx,
                                                               v4f d, v4f *L, v4f *T)
{
    fx_volume_upsample_same4(cell, bc, ty, tx, d, L, T);
}

FX_CLONES __attribute__((noinline)) static void vol_group_across(const vol_job *j, const float *dep, int k, size_t r0,
                                                                size_t r1, float ty, v4f *L, v4f *T)
{
    float Ls[4], Ts[4]; /* (a vector's lanes have no address in clang) */
    for (int m = 0; m < 4; m++) {
        const int X0 = j->col_x0[k + m];
        fx_volume_upsample(j->lo, j->lo_t, j->lo_depth, r0, r1, X0, X0 + 1 < j->lw ? X0 + 1 : X0, j->col_t[k + m],
                           ty, fx_volume_weight_depth(dep[k + m], j->vol->far_limit), &Ls[m], &Ts[m]);
    }
    *L = ld4(Ls);
    *T = ld4(Ts);
}

/* One group's put (pixels i0 + k ..., srow / drow: the row's src and dst at i0): added
 * (vol_put4_add_at) or per pixel (vol_put). */
static inline __attribute__((always_inline)) void vol_put_group(const vol_job *j, v4f rad, const float *srow,
                                                                 float *drow, size_t i0, int k, v4f L, v4f T,
                                                                 const int add)
{
    if (add) {
        vol_put4_add_at(rad, srow + 4 * (size_t)k, drow + 4 * (size_t)k, L, T);
    } else {
        for (int m = 0; m < 4; m++)
            vol_put(j, i0 + (size_t)(k + m), L[m], T[m]);
    }
}

/* volume_upsample edges: one row, 4 pixels at a time, put at once. A group on one cell
 * whose 4 pixels lie within VOL_ALIKE of the depth the cell's plane gives them takes the
 * plain bilinear (vol_row_edges' lerps); any other takes vol_row_lt's likeness weights (the
 * same functions, so the same bits). Two passes: the bilinear groups first, in a loop
 * without calls (a call in it made the compiler keep every vector on the stack), the
 * others listed (defer: n / 4 ints) and put after; each pixel is still read once, before
 * its write. */
static inline __attribute__((always_inline)) void vol_row_edges_body(const vol_job *j, int y, float *row, v4f *bcast,
                                                                      float *edges, int *defer, int *cached_Y0,
                                                                      const int add)
{
    const int lw = j->lw, x0 = j->run->roi.x0, n = j->run->roi.x1 - x0;
    size_t r0 = 0, r1 = 0;
    float ty = 0.0f;
    const int changed = vol_row_begin(j, y, row, bcast, cached_Y0, &r0, &r1, &ty);
    vol_row_edges(j, r0, r1, ty, changed, edges, edges + 6 * lw);
    const float *Lv = edges, *dL = edges + lw, *Tv = edges + 2 * lw, *dT = edges + 3 * lw, *Iv = edges + 4 * lw,
                *dI = edges + 5 * lw;
    const float *restrict dep = j->depth + (size_t)y * j->run->width + x0;
    const int *restrict cx = j->col_x0;
    const float *restrict ct = j->col_t;
    const float far = j->vol->far_limit;
    const size_t i0 = (size_t)y * j->run->width + x0;
    const float *srow = j->run->src + i0 * 4;
    float *drow = j->run->dst + i0 * 4;
    const v4f rad = j->rad;
    int Xc = -1, nd = 0;
    v4f lv = V4(0.0f), dl = lv, tv = lv, dt = lv, iv = lv, di = lv;
    int k = 0;
    for (; k + 4 <= n; k += 4) {
        const int X = cx[k];
        if (X != cx[k + 3]) { /* across cells */
            defer[nd++] = k;
            continue;
        }
        if (X != Xc) {
            Xc = X;
            lv = V4(Lv[X]), dl = V4(dL[X]), tv = V4(Tv[X]), dt = V4(dT[X]);
            iv = V4(Iv[X]), di = V4(dI[X]);
        }
        const v4f dk = ld4(dep + k); /* fx_volume_weight_depth, 4 lanes */
        const v4f d = sel4((dk > V4(0.0f)) & (dk < V4(far)), dk, V4(FX_VOLUME_BG_DEPTH));
        const v4f tx = ld4(ct + k);
        const v4f rel = d * (iv + tx * di); /* the pixel's depth over the plane's */
        if (!all4((rel <= V4(1.0f + VOL_ALIKE)) & (rel >= V4(1.0f - VOL_ALIKE)))) {
            defer[nd++] = k;
            continue;
        }
        vol_put_group(j, rad, srow, drow, i0, k, lv + tx * dl, tv + tx * dt, add);
    }
    for (int q = 0; q < nd; q++) {
        const int g = defer[q], X = cx[g];
        v4f L, T;
        if (X == cx[g + 3]) {
            const v4f dk = ld4(dep + g);
            const v4f d = sel4((dk > V4(0.0f)) & (dk < V4(far)), dk, V4(FX_VOLUME_BG_DEPTH));
            vol_group_same4(row + 12 * X, bcast + 12 * X, ty, ld4(ct + g), d, &L, &T);
        } else { /* across cells: one by one */
            vol_group_across(j, dep, g, r0, r1, ty, &L, &T);
        }
        vol_put_group(j, rad, srow, drow, i0, g, L, T, add);
    }
    for (; k < n; k++) {
        const int X0 = cx[k];
        float L, T;
        fx_volume_upsample(j->lo, j->lo_t, j->lo_depth, r0, r1, X0, X0 + 1 < lw ? X0 + 1 : X0, ct[k], ty,
                           fx_volume_weight_depth(dep[k], far), &L, &T);
        vol_put(j, i0 + (size_t)k, L, T);
    }
}

/* the body twice: with the composite add and no debug pass as a constant (the usual case,
 * the loop then tests nothing per group), and the general one */
FX_CLONES static void vol_row_edges_put(const vol_job *j, int y, float *row, v4f *bcast, float *edges, int *defer,
                                        int *cached_Y0)
{
    if (!j->screen && !j->dbg)
        vol_row_edges_body(j, y, row, bcast, edges, defer, cached_Y0, 1);
    else
        vol_row_edges_body(j, y, row, bcast, edges, defer, cached_Y0, 0);
}

/* The output rows: the in-scatter and transmittance upsampled from the reduced grid by
 * depth likeness (vol_row_lt, or vol_row_edges_put for volume_upsample edges), then put. */
FX_CLONES static void vol_rows(void *user, int begin, int end)
{
    const vol_job *j = user;
    const fx_effect_run *run = j->run;
    const int w = run->width, lw = j->lw, x0 = run->roi.x0, n = run->roi.x1 - x0;
    /* per lo column: the cell's texels, also broadcast (vol_row_cells); per pixel of the
     * row: L and T (vol_row_lt); per lo column: vol_row_edges' 8 floats; per group of 4
     * pixels: vol_row_edges_body's deferred list */
    float *row = j->f > 1 ? fx_mem_alloc((size_t)(12 * lw + 2 * n + 48 * lw + 4 + 8 * lw + n / 4 + 1) * sizeof(float))
                          : NULL;
    v4f *bcast = row ? (v4f *)(((uintptr_t)(row + 12 * lw + 2 * n) + 15) & ~(uintptr_t)15) : NULL;
    float *edges = row ? (float *)(bcast + 12 * lw) : NULL;
    int *defer = row ? (int *)(edges + 8 * lw) : NULL;
    int cached_Y0 = -1;
    for (int y = run->roi.y0 + begin; y < run->roi.y0 + end; y++) {
        const size_t i0 = (size_t)y * w + x0;
        const float *Lr, *Tr;
        if (j->f > 1 && row && j->edges) {
            vol_row_edges_put(j, y, row, bcast, edges, defer, &cached_Y0);
            continue;
        } else if (j->f > 1 && row) {
            float *L = row + 12 * lw, *T = L + n;
            vol_row_lt(j, y, row, bcast, &cached_Y0, L, T);
            Lr = L;
            Tr = T;
        } else if (j->f > 1) {
            continue; /* no scratch: handled below, pixel by pixel */
        } else {
            Lr = j->lo + i0;
            Tr = j->lo_t + i0;
        }
        int k = 0;
        if (!j->screen && !j->dbg)
            for (; k + 4 <= n; k += 4)
                vol_put4_add(j, i0 + (size_t)k, ld4(Lr + k), ld4(Tr + k));
        for (; k < n; k++)
            vol_put(j, i0 + (size_t)k, Lr[k], Tr[k]);
    }
    if (j->f > 1 && !row) /* out of memory for a row's scratch: the exact upsample, per pixel */
        for (int y = run->roi.y0 + begin; y < run->roi.y0 + end; y++) {
            int Y0 = 0;
            float ty = 0.0f;
            fx_volume_lo_coord(y, j->f, j->lh, &Y0, &ty);
            const size_t r0 = (size_t)Y0 * lw, r1 = Y0 + 1 < j->lh ? r0 + (size_t)lw : r0;
            for (int x = x0; x < run->roi.x1; x++) {
                const size_t i = (size_t)y * w + x;
                const int X0 = j->col_x0[x - x0];
                float L, T;
                fx_volume_upsample(j->lo, j->lo_t, j->lo_depth, r0, r1, X0, X0 + 1 < lw ? X0 + 1 : X0,
                                   j->col_t[x - x0], ty, fx_volume_weight_depth(j->depth[i], j->vol->far_limit),
                                   &L, &T);
                vol_put(j, i, L, T);
            }
        }
    fx_mem_free(row);
}

/* The sun and its light view for method volumetric: a sun only (spot and point lights
 * come later), its orthographic depth view from the aux views. */
static fx_result vol_light(const fx_effect_run *run, const god_rays_params *p, fx_light *L, fx_aux_map *map)
{
    const char *where = run->where;
    fx_result r = fx_frame_find_light(run->frame, p->light, where, L);
    if (r != FX_OK)
        return r;
    if (L->type != FX_LIGHT_SUN) {
        static const char *const kinds[] = {"sun", "point", "spot", "area"};
        return fx_fail(run->ctx, FX_ERR_BAD_PARAM,
                       "%s: method volumetric: light '%s' is a %s light; only a sun is supported for now "
                       "(spot and point lights come later): name a sun in 'light' or use method polar",
                       where, L->name, kinds[L->type]);
    }
    char name[FX_STRING_PARAM_MAX + 8];
    snprintf(name, sizeof name, "light:%s", p->light);
    /* a reduced view is its own cache entry: a vsm_shadows in the stack keeps the full one */
    r = fx_aux_map_acquire_reduced(run->frame, name, p->light_view_downsample, where, map);
    if (r != FX_OK)
        return r;
    if (!map->av->view.orthographic) {
        fx_aux_map_release(map);
        return fx_fail(run->ctx, FX_ERR_BAD_PARAM,
                       "%s: method volumetric: the light view '%s' is not orthographic (a sun's is)", where,
                       map->av->name);
    }
    return FX_OK;
}

/* The mean of volume_color: the grey part of the coefficients (> 0 unless identity). */
static float vol_color_mean(const god_rays_params *p)
{
    return (p->volume_color[0] + p->volume_color[1] + p->volume_color[2]) * (1.0f / 3.0f);
}

static void vol_setup(const god_rays_params *p, const fx_view *cam, const fx_aux_map *map, const fx_light *L,
                      fx_volume *vol)
{
    memset(vol, 0, sizeof *vol);
    vol->cam = cam;
    vol->light_view = &map->av->view;
    vol->sm = map->sm;
    vol->light_dir = fx_v3_normalize_or(L->direction, fx_v3(0.0f, 0.0f, -1.0f));
    vol->sigma = p->volume_density * vol_color_mean(p);
    vol->g = fx_clampf(p->anisotropy, -FX_VOLUME_MAX_G, FX_VOLUME_MAX_G);
    vol->view_extinction = p->extinction != EXT_NONE;
    vol->light_extinction = p->extinction == EXT_FULL;
    vol->max_distance = p->max_distance;
    vol->eps = fx_shadow_map_norm_dist(map->sm, p->volume_bias);
    vol->far_limit = cam->cam.clip_end > 0.0f ? 1.01f * cam->cam.clip_end : 1e9f;
    vol->entry = fx_volume_light_entry(map->sm);
    fx_volume_prepare(vol);
}

static fx_result run_volumetric(const fx_effect_run *run, const god_rays_params *p)
{
    const char *where = run->where;
    const int w = run->width, h = run->height;
    fx_view cam;
    if (!fx_view_init(&cam, run->frame))
        return fx_fail(run->ctx, FX_ERR_NO_CAMERA,
                       "%s: method volumetric needs the frame's camera (the scene sidecar: --sidecar)", where);
    const fx_pass *dp = fx_frame_find_pass(run->frame, "Depth");
    if (!dp)
        return fx_fail(run->ctx, FX_ERR_MISSING_PASS, "%s: method volumetric needs the Depth pass", where);
    fx_light L;
    fx_aux_map map;
    fx_result r = vol_light(run, p, &L, &map);
    if (r != FX_OK)
        return r;
    fx_volume vol;
    vol_setup(p, &cam, &map, &L, &vol);
    const int f = p->volume_downsample > 1 ? p->volume_downsample : 1;
    const int lw = fx_volume_lo_size(w, f), lh = fx_volume_lo_size(h, f);
    const size_t ln = (size_t)lw * lh, bytes = ln * 4 * sizeof(float);
    r = fx_check_budget(run->ctx, (uint64_t)bytes, where);
    float *buf = r == FX_OK ? fx_buffer_get(run->ctx, bytes) : NULL;
    if (r == FX_OK && !buf)
        r = fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the in-scatter", where);
    if (r == FX_OK) {
        double frame_no = fx_effect_scene_frame(run);
        int fr = isfinite(frame_no) && fabs(frame_no) < 2e9 ? (int)floor(frame_no) : 0;
        unsigned rot = fx_hash4(fr, p->seed, 0x766f6c, 0);
        fx_volume_scatter_lo(run->ctx, &vol, dp->data, w, h, f, p->volume_steps, p->interleave, rot, &run->roi,
                             buf, buf + ln, buf + 2 * ln, buf + 3 * ln);
        /* the march scatters with the grey sigma; each channel scatters by its own colour */
        const float cm = vol_color_mean(p), e = L.energy;
        const float kc[3] = {p->volume_color[0] / cm, p->volume_color[1] / cm, p->volume_color[2] / cm};
        vol_job j = {run, &vol, dp->data, buf, buf + ln, buf + 2 * ln, lw, lh, f,
                     (v4f){L.color.x * e * kc[0], L.color.y * e * kc[1], L.color.z * e * kc[2], 0.0f},
                     p->composite == COMP_SCREEN, NULL, NULL, NULL, p->volume_upsample == UPS_EDGES};
        if (run->debug)
            j.dbg = fx_effect_debug_pass(run, "inscatter", 3, &r);
        const int cols = run->roi.x1 - run->roi.x0;
        int *cx = r == FX_OK ? fx_mem_alloc((size_t)cols * sizeof(int)) : NULL;
        float *ct = r == FX_OK ? fx_mem_alloc((size_t)cols * sizeof(float)) : NULL;
        if (r == FX_OK && (!cx || !ct))
            r = fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where);
        for (int x = run->roi.x0; r == FX_OK && x < run->roi.x1; x++)
            fx_volume_lo_coord(x, f, lw, &cx[x - run->roi.x0], &ct[x - run->roi.x0]);
        j.col_x0 = cx;
        j.col_t = ct;
        if (r == FX_OK) {
            int rows = run->roi.y1 - run->roi.y0;
            fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), vol_rows, &j);
        }
        fx_mem_free(cx);
        fx_mem_free(ct);
    }
    fx_buffer_put(run->ctx, buf, bytes);
    fx_aux_map_release(&map);
    return r;
}

static fx_result god_rays_process(const fx_effect_run *run)
{
    const god_rays_params *p = run->params;
    if (p->method == METHOD_VOLUMETRIC)
        return run_volumetric(run, p);
    const int w = run->width, h = run->height;
    double lx = 0, ly = 0, fade = 0;
    fx_result r = find_light(run, p, run->where, &lx, &ly, &fade);
    if (r != FX_OK)
        return r;
    if (!(fade > 0.0))
        return fx_effect_pass_through(run); /* the light is behind the camera */
    fx_radial_blur_bound_light(&lx, &ly, w, h);
    occ_job oj;
    fx_mask *material = NULL;
    r = occlusion_setup(run, p, lx, ly, &oj, &material);
    if (r == FX_OK) {
        fx_radial_blur rb;
        blur_setup(run, p, lx, ly, &rb);
        int lw = 0, lh = 0;
        if (p->method == METHOD_POLAR && !run->debug && fx_radial_blur_reduced_size(&rb, w, h, &lw, &lh))
            r = run_reduced(run, p, &oj, &rb, lw, lh, fade);
        else
            r = run_full(run, p, &oj, &rb, fade);
    }
    fx_mask_free(material);
    return r;
}

const fx_effect_class fx_effect_god_rays = {
    .name = "god_rays",
    .doc = "Crepuscular rays: radial blur of the sky/bright pixels towards the scene's light (GPU Gems 3 ch. 13)",
    .params_size = sizeof(god_rays_params),
    .params = god_rays_param_defs,
    .param_count = FX_COUNT_OF(god_rays_param_defs),
    .presets = {
        /* chosen from the time/error sweep (docs/effects/god_rays.md): at 1080p resolution
         * 0.5 has the scene-relative line density of 1.5 at 640x360; at equal time a reduced
         * map with finer lines errs less than coarser lines at full size */
        "{\"method\": \"polar\", \"polar_resolution\": 0.75, \"polar_levels\": 2, \"polar_downsample\": 4, "
        "\"volume_downsample\": 16, \"volume_steps\": 16, \"interleave\": 1, \"volume_upsample\": \"edges\", "
        "\"light_view_downsample\": 2}",
        "{\"method\": \"polar\", \"polar_resolution\": 0.75, \"polar_levels\": 2, \"polar_downsample\": 2, "
        "\"volume_downsample\": 4, \"volume_steps\": 16, \"interleave\": 2}",
        "{\"method\": \"polar\", \"polar_resolution\": 0.5, \"polar_levels\": 2, \"polar_downsample\": 1, "
        "\"volume_downsample\": 2, \"volume_steps\": 24, \"interleave\": 2}",
        "{\"method\": \"naive\", \"samples\": 2000, \"jitter\": false, "
        "\"volume_downsample\": 1, \"volume_steps\": 256, \"interleave\": 1}",
    },
    .passes = god_rays_passes,
    .needs_camera = god_rays_needs_camera,
    .halo = god_rays_halo,
    .validate = god_rays_validate,
    .aux_views = god_rays_aux_views,
    .process = god_rays_process,
    .identity = god_rays_identity,
    .in_place = god_rays_volumetric_only,
    .own_finite = god_rays_volumetric_only,
};
