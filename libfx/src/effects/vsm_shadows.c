/* vsm_shadows: shadows of a light from its auxiliary depth view (core/aux_view.h), as
 * variance shadow maps (Donnelly & Lauritzen 2006) filtered by a box (separable running
 * sums) or by a separable Gaussian, optionally on a mip of the moments (map_level), with
 * the min-variance clamp, the max-depth test with epsilon, light-bleeding reduction by
 * remapping p_max and the derivative bias on the second moment; PCF and the hard test as
 * references.
 * docs/effects/vsm_shadows.md.
 *
 * Each pixel's surface (math/surface.h) is moved along its normal by normal_offset (when
 * the frame has normals), projected into the light view, and gets a visibility v in
 * [0, 1]. Applied as:
 *  - sun_diffuse: removes the light's unshadowed direct diffuse, DiffCol * colour * energy
 *    * max(N.L, 0) / pi (Cycles' sun: strength is irradiance in W/m^2) times Burley's
 *    factor for the Principled BSDF (param diffuse; lambert: none), times (1 - v):
 *    for renders where the light casts no ray-traced shadow (the atrium's Sun);
 *  - combined: scales Combined by 1 - strength (1 - v): for any render. */
#include "scene/aux_map.h"
#include "core/effect.h"
#include "scene/lights.h"
#include "core/parallel.h"
#include "math/blur.h"
#include "math/shadow_map.h"
#include "math/surface.h"
#include "core/simd4.h"

#include <cjson/cJSON.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

typedef struct vsm_params {
    char light[FX_STRING_PARAM_MAX];
    int method;
    int filter;
    float filter_size;
    float min_std;
    float bleed;
    float depth_bias;
    int derivative_bias;
    float normal_offset;
    int apply;
    float strength;
    int diffuse;
    float roughness;
    int map_level;
    int screen_downsample;
    float bounce_loss;
    int remove_as;
    float bounce_reach;
} vsm_params;

enum { METHOD_VSM = 0, METHOD_PCF, METHOD_HARD };
enum { APPLY_SUN_DIFFUSE = 0, APPLY_COMBINED, APPLY_SUN_DIRECT, APPLY_LIGHT_GROUP };
enum { REMOVE_DIFFERENCE = 0, REMOVE_RATIO };
/* remove_as ratio: the neighbourhood (2 R + 1)^2 over which Combined (and the light group)
 * are averaged, on the same surface only */
#define RATIO_RADIUS 2
enum { DIFFUSE_PRINCIPLED = 0, DIFFUSE_LAMBERT };

static const char *const method_items[] = {"vsm", "pcf", "hard"};
static const char *const filter_items[] = {"box_sat", "gaussian"};
static const char *const apply_items[] = {"sun_diffuse", "combined", "sun_direct", "light_group"};
static const char *const remove_items[] = {"difference", "ratio"};
static const char *const diffuse_items[] = {"principled", "lambert"};

static const fx_param_def vsm_param_defs[] = {
    FX_P_STRING(vsm_params, light, "light", "", "",
                "The light's name in the scene (its aux view 'light:<name>'); empty: the first sun"),
    FX_P_ENUM(vsm_params, method, "method", METHOD_VSM, method_items,
              "vsm: variance shadow map (filtered moments, Chebyshev bound); pcf: percentage-closer "
              "filtering over the same box (cost grows with its area; the accuracy reference); hard: one "
              "depth test"),
    FX_P_ENUM(vsm_params, filter, "filter", 0, filter_items,
              "How the moments are filtered: box_sat: a box, as separable running sums in double (the "
              "means of a summed-area table without its table); gaussian: separable recursive Gaussian "
              "of the box's variance"),
    FX_P_FLOAT(vsm_params, filter_size, "filter_size", 5.0, 1.0, 1025.0, 1.0, 65.0, "texels",
               "Filter width in light-map texels (box: rounded to odd); sets the penumbra width"),
    FX_P_FLOAT(vsm_params, min_std, "min_std", 0.01, 0.0, 10.0, 0.0, 0.1, "",
               "Minimum standard deviation of the occluder depth, metres (the min-variance clamp)"),
    FX_P_FLOAT(vsm_params, bleed, "bleed_reduction", 0.3, 0.0, 0.99, 0.0, 0.8, "factor",
               "Light-bleeding reduction: p_max below this is shadow, above it is rescaled to [0, 1]"),
    FX_P_FLOAT(vsm_params, depth_bias, "depth_bias", 0.05, 0.0, 10.0, 0.0, 0.5, "",
               "Epsilon of the max-depth test, metres: receivers this close behind the mean occluder "
               "are lit"),
    FX_P_BOOL(vsm_params, derivative_bias, "derivative_bias", 1,
              "Add 0.25 (dz/dx^2 + dz/dy^2) to the second moment (slope-scaled bias against acne)"),
    FX_P_FLOAT(vsm_params, normal_offset, "normal_offset", 0.03, 0.0, 10.0, 0.0, 0.2, "",
               "Move each receiver this far along its normal (metres) before the lookup, when the "
               "frame has normals"),
    FX_P_ENUM(vsm_params, apply, "apply", APPLY_SUN_DIFFUSE, apply_items,
              "sun_diffuse: remove the light's direct diffuse where shadowed (needs Normal, DiffCol and "
              "the scene's lights; for lights that cast no ray-traced shadow); combined: darken "
              "Combined by strength; sun_direct: the light's direct diffuse and glossy (GGX of "
              "roughness, GlossCol) from the analytic BRDF; light_group: the light's own pass "
              "(Combined_libfx_light, the light group the add-on makes): its direct share (the analytic "
              "estimate's luminance over the pass's, at most 1) and bounce_loss of the rest"),
    FX_P_FLOAT(vsm_params, strength, "strength", 1.0, 0.0, 1.0, 0.0, 1.0, "factor",
               "How much of the shadowed light is removed (1: all)"),
    FX_P_ENUM(vsm_params, diffuse, "diffuse", DIFFUSE_PRINCIPLED, diffuse_items,
              "sun_diffuse's BRDF: principled: Cycles' Principled BSDF (v1, Blender < 4.0) diffuse, Burley's "
              "retro-reflection at grazing angles (up to ~20% brighter than Lambert on rough floors seen "
              "edge-on); lambert: Diffuse BSDF, DiffCol E N.L / pi"),
    FX_P_FLOAT(vsm_params, roughness, "roughness", 0.5, 0.0, 1.0, 0.0, 1.0, "",
               "The scene's typical Principled roughness for the principled diffuse (Blender writes no "
               "roughness pass)"),
    FX_P_INT(vsm_params, map_level, "map_level", 0, 0, FX_SHADOW_MAX_LEVEL, 0, 3, "",
             "vsm: the light map's moments averaged over blocks of 2^level x 2^level texels before the "
             "filter (a mip of the moments: cheaper filter and lookups, penumbrae at least 2^level texels "
             "wide); 0: full resolution"),
    FX_P_INT(vsm_params, screen_downsample, "screen_downsample", 1, 1, 8, 1, 4, "",
             "The visibility is looked up at one pixel of every f x f block and interpolated to the others "
             "from the neighbours on the same surface (depth within a few percent, similar normal); a pixel "
             "with no such neighbour (an edge, a thin object) is looked up itself. With remove_as ratio the "
             "removal factor is made at the same pixels and interpolated alike. ~f^2 fewer lookups; "
             "shadow edges soften by about f pixels. 1: every pixel"),
    FX_P_FLOAT(vsm_params, bounce_loss, "bounce_loss", 1.0, 0.0, 1.0, 0.0, 1.0, "factor",
               "light_group: the share of the light's indirect contribution (the pass less its direct "
               "share) removed with its direct light where shadowed (1: the light's whole share)"),
    FX_P_FLOAT(vsm_params, bounce_reach, "bounce_reach", 0.1, 0.0, 1.0, 0.0, 0.25, "frame widths",
               "light_group: 0: the bounce light is lost where the pixel is shadowed (bounce_loss (1 - v)); "
               "above 0: every pixel loses bounce_loss (1 - V) of it, V the visibility of the surfaces around "
               "it, averaged by a Gaussian of this sigma (a share of the frame's width): lit pixels amid "
               "shadow lose bounce too, shadowed ones near lit ground keep some"),
    FX_P_ENUM(vsm_params, remove_as, "remove_as", REMOVE_RATIO, remove_items,
              "difference: Combined less the removed light; ratio: Combined times (1 - removed / Combined), "
              "both averaged over the pixel's surface in a 5x5 neighbourhood (with screen_downsample f > 1: "
              "made at one pixel of every f x f block, over 5x5 for f >= 4, 3x3 below, and interpolated), so "
              "the noise of what is left "
              "is scaled with it, not laid bare (not for combined)"),
};

static fx_pass_set vsm_passes(const void *params)
{
    const vsm_params *p = params;
    fx_pass_set s = FX_PASS_BIT(FX_PASS_DEPTH);
    if (p->apply != APPLY_COMBINED)
        s |= FX_PASS_BIT(FX_PASS_NORMAL) | FX_PASS_BIT(FX_PASS_DIFF_COL);
    if (p->apply == APPLY_SUN_DIRECT || p->apply == APPLY_LIGHT_GROUP)
        s |= FX_PASS_BIT(FX_PASS_GLOSS_COL);
    if (p->apply == APPLY_LIGHT_GROUP)
        s |= FX_PASS_BIT(FX_PASS_LIGHT_GROUP);
    return s;
}

typedef struct vsm_job {
    const fx_effect_run *run;
    const vsm_params *p;
    const fx_aux_view *av;
    const fx_shadow_map *sm;
    fx_surface_src surf;
    const float *diffcol;
    const float *glosscol, *group; /* sun_direct, light_group (RGB), or NULL */
    int general; /* remove_share does the removal (any apply but the two old difference ones) */
    /* bounce_reach > 0 (light_group): first pass (vis_only) stores each pixel's visibility
     * v and surface flag as (v m, m) in vm (frame size, 2 channels), blurred in place
     * before the second pass reads it */
    int vis_only;
    float *vm;
    int vm_lo; /* screen_downsample > 1: vm is the lo grid's (lw x lh, from the lo texels) */
    fx_vec3 sun_rad; /* colour * energy / pi */
    fx_vec3 to_light;
    float min_var, eps, bias_norm;
    int pcf_radius;
    float *vis_out; /* debug, or NULL */
    /* screen_downsample f > 1: the visibility of pixel (x0 + f X + o, y0 + f Y + o) (clamped
     * to the ROI) of every lo texel (X, Y), with that pixel's depth (<= 0: no surface) and
     * normal (0 0 0: none) */
    int f, lw, lh;
    float *lo_v, *lo_a, *lo_d, *lo_n;
    /* remove_as ratio with screen_downsample: each lo texel's ratio factor (RGB, in [0, 1];
     * ratio_factor at its pixel), interpolated to the pixels as the visibility is */
    int lo_factor;
    float *lo_F;
    unsigned char *lo_flags; /* per lo cell: lo_flag_rows */
    int *col_X0;   /* per ROI column: its lo texel column (left) ... */
    float *col_tx; /* ... and the weight of the right one */
} vsm_job;

static float visibility_at(const vsm_job *j, int x, int y, int *has_surface)
{
    fx_vec3 w;
    float d;
    *has_surface = fx_surface_world(&j->surf, x, y, &w, &d);
    if (!*has_surface)
        return 1.0f;
    fx_vec3 n;
    if (j->p->normal_offset > 0.0f && fx_surface_normal(&j->surf, x, y, &n))
        w = fx_v3_add(w, fx_v3_scale(n, j->p->normal_offset));
    float px, py, ld;
    if (!fx_aux_view_project(j->av, w, &px, &py, &ld))
        return 1.0f;
    if (!(px >= 0.0f && py >= 0.0f && px <= (float)j->sm->width && py <= (float)j->sm->height))
        return 1.0f; /* outside the light view (or NaN): not shadowed by anything it saw */
    float t = fx_shadow_map_norm(j->sm, ld);
    switch (j->p->method) {
    case METHOD_HARD:
        return fx_shadow_map_hard(j->sm, px, py, t, j->eps);
    case METHOD_PCF: {
        /* derivative_bias: the receiver's plane (fx_shadow_map_pcf_plane) from two points a
         * little along its tangents, projected too: the slopes dt/dpx, dt/dpy solved from
         * their texel and depth offsets */
        float gx = 0.0f, gy = 0.0f;
        if (j->p->derivative_bias && fx_surface_normal(&j->surf, x, y, &n)) {
            fx_vec3 a = fabsf(n.x) < 0.9f ? fx_v3(1.0f, 0.0f, 0.0f) : fx_v3(0.0f, 1.0f, 0.0f);
            fx_vec3 t1 = fx_v3_normalize_or(fx_v3_cross(n, a), a);
            fx_vec3 t2 = fx_v3_cross(n, t1);
            const float h = 0.01f * (d > 1.0f ? d : 1.0f);
            float ax, ay, ad, bx, by, bd;
            if (fx_aux_view_project(j->av, fx_v3_add(w, fx_v3_scale(t1, h)), &ax, &ay, &ad) &&
                fx_aux_view_project(j->av, fx_v3_add(w, fx_v3_scale(t2, h)), &bx, &by, &bd)) {
                const float u1 = ax - px, v1 = ay - py, z1 = fx_shadow_map_norm(j->sm, ad) - t;
                const float u2 = bx - px, v2 = by - py, z2 = fx_shadow_map_norm(j->sm, bd) - t;
                const float det = u1 * v2 - u2 * v1;
                if (fabsf(det) > 1e-6f) {
                    gx = (z1 * v2 - z2 * v1) / det;
                    gy = (u1 * z2 - u2 * z1) / det;
                    /* grazing receivers: at most 0.05 normalised depth per texel */
                    gx = fx_clampf(gx, -0.05f, 0.05f);
                    gy = fx_clampf(gy, -0.05f, 0.05f);
                }
            }
        }
        return fx_shadow_map_pcf_plane(j->sm, px, py, t, j->pcf_radius, j->eps, gx, gy);
    }
    default: {
        float m1, m2;
        fx_shadow_map_moments(j->sm, px, py, &m1, &m2);
        return fx_vsm_visibility(m1, m2, t, j->min_var, j->p->bleed, j->eps);
    }
    }
}

/* Burley's diffuse over Lambert's, as Cycles' Principled BSDF v1 evaluates it:
 * (1 + (F90 - 1)(1 - N.L)^5)(1 + (F90 - 1)(1 - N.V)^5), F90 = 0.5 + 2 roughness (L.H)^2;
 * V towards the camera (N.V, L.H clamped to [0, 1]). Checked against a Cycles render of the
 * atrium's Sun alone in docs/effects/vsm_shadows.md. */
static float burley(const vsm_job *j, int x, int y, fx_vec3 n, float ndl)
{
    fx_vec2 ndc = fx_view_pixel_to_ndc(&j->surf.view, (float)x + 0.5f, (float)y + 0.5f);
    fx_vec3 v = fx_v3_scale(fx_view_dir_to_world(&j->surf.view, fx_view_ray(&j->surf.view, ndc)), -1.0f);
    v = fx_v3_normalize_or(v, n);
    float ndv = fx_clampf(fx_v3_dot(n, v), 0.0f, 1.0f);
    fx_vec3 h = fx_v3_normalize_or(fx_v3_add(v, j->to_light), n);
    float ldh = fx_clampf(fx_v3_dot(j->to_light, h), 0.0f, 1.0f);
    float f90 = 0.5f + 2.0f * j->p->roughness * ldh * ldh;
    float a = 1.0f - ndl, b = 1.0f - ndv;
    float a5 = a * a * a * a * a, b5 = b * b * b * b * b;
    return (1.0f + (f90 - 1.0f) * a5) * (1.0f + (f90 - 1.0f) * b5);
}

/* The visibility v of pixel (x, y) and the fraction a of the light it loses: combined:
 * strength (1 - v); sun_diffuse: that times max(N.L, 0) (times Burley's factor). */
/* The sun's diffuse cosine at (x, y), Burley's factor included with the principled model;
 * 0 where nothing is removed (k <= 0) or the surface faces away. */
static float sun_cosine(const vsm_job *j, int x, int y, float k)
{
    fx_vec3 n;
    float ndl = 0.0f;
    if (k > 0.0f && fx_surface_normal(&j->surf, x, y, &n))
        ndl = fx_v3_dot(n, j->to_light);
    ndl = ndl > 0.0f ? ndl : 0.0f;
    if (ndl > 0.0f && j->p->diffuse == DIFFUSE_PRINCIPLED)
        ndl *= burley(j, x, y, n, ndl);
    return ndl;
}

static float shade_at(const vsm_job *j, int x, int y, int *has, float *a)
{
    float v = visibility_at(j, x, y, has);
    float k = j->p->strength * (1.0f - v);
    if (j->p->apply == APPLY_SUN_DIFFUSE && !j->general)
        k *= sun_cosine(j, x, y, k);
    *a = k;
    return v;
}

/* The unit direction from the surface at pixel (x, y) towards the camera (n if degenerate). */
static fx_vec3 view_dir(const vsm_job *j, int x, int y, fx_vec3 n)
{
    fx_vec2 ndc = fx_view_pixel_to_ndc(&j->surf.view, (float)x + 0.5f, (float)y + 0.5f);
    fx_vec3 v = fx_v3_scale(fx_view_dir_to_world(&j->surf.view, fx_view_ray(&j->surf.view, ndc)), -1.0f);
    return fx_v3_normalize_or(v, n);
}

/* The light's unshadowed direct light at (x, y), RGB: the diffuse of sun_diffuse
 * (DiffCol sun_rad N.L, Burley's factor with the principled model) and, for sun_direct and
 * light_group, a glossy estimate: GlossCol E D G / (4 N.V) of GGX (alpha = roughness^2)
 * with the separable Smith masking. 0 without a normal or facing away. */
static void direct_light(const vsm_job *j, int x, int y, size_t i, float out[3])
{
    out[0] = out[1] = out[2] = 0.0f;
    fx_vec3 n;
    if (!fx_surface_normal(&j->surf, x, y, &n))
        return;
    const float ndl = fx_v3_dot(n, j->to_light);
    if (!(ndl > 0.0f))
        return;
    const float fd = j->p->diffuse == DIFFUSE_PRINCIPLED ? ndl * burley(j, x, y, n, ndl) : ndl;
    const float *dc = j->diffcol + 3 * i;
    const float rad[3] = {j->sun_rad.x, j->sun_rad.y, j->sun_rad.z};
    float fs = 0.0f;
    if (j->glosscol) {
        const fx_vec3 v = view_dir(j, x, y, n);
        const float ndv = fx_clampf(fx_v3_dot(n, v), 1e-3f, 1.0f);
        const fx_vec3 h = fx_v3_normalize_or(fx_v3_add(v, j->to_light), n);
        const float ndh = fx_clampf(fx_v3_dot(n, h), 0.0f, 1.0f);
        float a2 = j->p->roughness * j->p->roughness;
        a2 = a2 * a2 > 1e-6f ? a2 * a2 : 1e-6f;
        const float den = ndh * ndh * (a2 - 1.0f) + 1.0f;
        const float d = a2 / (3.14159265f * den * den);
        const float nl = ndl < 1.0f ? ndl : 1.0f;
        const float g1l = 2.0f * nl / (nl + sqrtf(a2 + (1.0f - a2) * nl * nl));
        const float g1v = 2.0f * ndv / (ndv + sqrtf(a2 + (1.0f - a2) * ndv * ndv));
        /* times pi: sun_rad is E / pi */
        fs = 3.14159265f * d * g1l * g1v / (4.0f * ndv);
        fs = fs < 1e4f ? fs : 1e4f;
    }
    const float *gc = j->glosscol ? j->glosscol + 3 * i : NULL;
    for (int c = 0; c < 3; c++) {
        float t = fd * dc[c] + (gc ? fs * gc[c] : 0.0f);
        t *= rad[c];
        out[c] = fabsf(t) <= FLT_MAX ? t : (t > 0.0f ? FLT_MAX : 0.0f);
    }
}

/* light_group: the direct share t of the pass g, lum(d) / lum(g) in [0, 1] (d: the direct
 * estimate); the pass splits into t g direct and (1 - t) g bounce light, both in the pass's
 * own hue (a per-channel min(d, g) left the estimate's hue errors in the bounce part: red
 * walls under the atrium's arcades). */
static inline double direct_share(const float d[3], const double g[3])
{
    const double ld = 0.2126 * d[0] + 0.7152 * d[1] + 0.0722 * d[2];
    const double lg = 0.2126 * (g[0] > 0 ? g[0] : 0) + 0.7152 * (g[1] > 0 ? g[1] : 0) + 0.0722 * (g[2] > 0 ? g[2] : 0);
    if (!(lg > 1e-12))
        return 1.0;
    const double t = ld / lg;
    return t > 0.0 ? (t < 1.0 ? t : 1.0) : 0.0;
}

/* What is removed from (x, y) of channel c, given the direct light d and, for light_group,
 * the pass g and its direct share t: k d, or g (k t + ib (1 - t)) (ib: the bounce share lost). */
static inline double removed_of(const vsm_job *j, double k, double ib, double t, double d, double g)
{
    if (!j->group)
        return k * d;
    g = g > 0.0 ? g : 0.0;
    return g * (k * t + ib * (1.0 - t));
}

/* The share of the light's indirect part lost at (x, y): bounce_loss k, or bounce_loss (1 - V)
 * with the surroundings' visibility V (bounce_reach) */
static inline __attribute__((always_inline)) double bounce_lost(const vsm_job *j, int x, int y, float k)
{
    const fx_effect_run *run = j->run;
    const size_t i = (size_t)y * run->width + x;
    double ib = (double)j->p->bounce_loss * k;
    if (j->vm) {
        float num, den;
        if (j->vm_lo) { /* bilinear on the lo grid (lo texel X sits at pixel x0 + f X + f / 2) */
            const fx_rect *roi = &run->roi;
            const float inv_f = 1.0f / (float)j->f;
            float u = (float)(x - roi->x0 - j->f / 2) * inv_f, w = (float)(y - roi->y0 - j->f / 2) * inv_f;
            u = u > 0.0f ? (u < (float)(j->lw - 1) ? u : (float)(j->lw - 1)) : 0.0f;
            w = w > 0.0f ? (w < (float)(j->lh - 1) ? w : (float)(j->lh - 1)) : 0.0f;
            const int X0 = (int)u, Y0 = (int)w;
            const int X1 = X0 + 1 < j->lw ? X0 + 1 : X0, Y1 = Y0 + 1 < j->lh ? Y0 + 1 : Y0;
            const float tx = u - (float)X0, ty = w - (float)Y0;
            const float *a = j->vm + 2 * ((size_t)Y0 * j->lw + X0), *b = j->vm + 2 * ((size_t)Y0 * j->lw + X1);
            const float *c = j->vm + 2 * ((size_t)Y1 * j->lw + X0), *e = j->vm + 2 * ((size_t)Y1 * j->lw + X1);
            const float n0 = a[0] + tx * (b[0] - a[0]), n1 = c[0] + tx * (e[0] - c[0]);
            const float d0 = a[1] + tx * (b[1] - a[1]), d1 = c[1] + tx * (e[1] - c[1]);
            num = n0 + ty * (n1 - n0);
            den = d0 + ty * (d1 - d0);
        } else {
            num = j->vm[2 * i];
            den = j->vm[2 * i + 1];
        }
        const double vl = den > 1e-6f ? fx_saturate(num / den) : 1.0;
        ib = (double)j->p->bounce_loss * (1.0 - vl);
    }
    return ib;
}

/* remove_as ratio's factor per channel at (x, y), in [0, 1]: 1 - removed' / C', both averaged
 * over the pixels of the (2 rr + 1)^2 neighbourhood on the same surface (depth within 2 %,
 * normals within ~25 degrees); d: the direct estimate at (x, y) */
static inline __attribute__((always_inline)) void ratio_factor(const vsm_job *j, int x, int y, float k, double ib,
                                                              const float d[3], int rr, double f3[3])
{
    const fx_effect_run *run = j->run;
    const size_t i = (size_t)y * run->width + x;
    const fx_surface_src *sf = &j->surf;
    const float dz = sf->depth[i];
    /* normals as stored (unnormalised): the likeness test compares squares, c > 0 and
     * c^2 >= 0.81 |n|^2 |m|^2 (cosine at least 0.9) */
    const float *pn = sf->normal ? sf->normal + 3 * i : NULL;
    const float nn = pn ? pn[0] * pn[0] + pn[1] * pn[1] + pn[2] * pn[2] : 0.0f;
    const int has_n = nn > 1e-8f;
    const float *g = j->group;
    double cs[3] = {0, 0, 0}, gs[3] = {0, 0, 0};
    int cnt = 0;
    const int ya = y - rr > 0 ? y - rr : 0;
    const int yb = y + rr < run->height - 1 ? y + rr : run->height - 1;
    const int xa = x - rr > 0 ? x - rr : 0;
    const int xb = x + rr < run->width - 1 ? x + rr : run->width - 1;
    for (int yy = ya; yy <= yb; yy++)
        for (int xx = xa; xx <= xb; xx++) {
            const size_t q = (size_t)yy * run->width + xx;
            if (q != i) {
                const float dq = sf->depth[q];
                if (!(fabsf(dq - dz) <= 0.02f * dz))
                    continue;
                if (has_n) {
                    const float *m = sf->normal + 3 * q;
                    const float c = pn[0] * m[0] + pn[1] * m[1] + pn[2] * m[2];
                    const float mm = m[0] * m[0] + m[1] * m[1] + m[2] * m[2];
                    if (!(c > 0.0f && c * c >= 0.81f * nn * mm))
                        continue;
                }
            }
            const float *sq = run->src + 4 * q;
            for (int c = 0; c < 3; c++) {
                cs[c] += sq[c];
                if (g)
                    gs[c] += g[3 * q + c];
            }
            cnt++;
        }
    const double gm3[3] = {gs[0] / cnt, gs[1] / cnt, gs[2] / cnt};
    const double t = g ? direct_share(d, gm3) : 1.0;
    for (int c = 0; c < 3; c++) {
        const double cm = cs[c] / cnt, gm = gm3[c];
        const double r = removed_of(j, k, ib, t, d[c], gm);
        double f = cm > 1e-12 ? 1.0 - r / cm : 0.0;
        f3[c] = f > 0.0 ? (f < 1.0 ? f : 1.0) : 0.0;
    }
}

/* The removal of a share k (strength (1 - v), in (0, 1]) of the light at pixel (x, y), from
 * s into o (RGBA; alpha kept), for every apply but the old difference paths:
 * difference: s - removed; ratio: s (1 - removed' / C') (ratio_factor: 5x5, 3x3 with
 * screen_downsample): the averages make the factor smooth, so the noise in s is scaled with
 * its mean rather than left whole on a smaller mean. */
static void remove_share(const vsm_job *j, int x, int y, float k, const float *s, float *o)
{
    const fx_effect_run *run = j->run;
    const size_t i = (size_t)y * run->width + x;
    const double ib = bounce_lost(j, x, y, k);
    float d[3];
    direct_light(j, x, y, i, d);
    o[3] = s[3];
    if (j->p->remove_as == REMOVE_RATIO) {
        double f3[3];
        /* 5x5; 3x3 with screen_downsample (the draft and preview presets) */
        ratio_factor(j, x, y, k, ib, d, j->f > 1 ? 1 : RATIO_RADIUS, f3);
        for (int c = 0; c < 3; c++)
            o[c] = (float)(s[c] * f3[c]);
        return;
    }
    const float *g = j->group ? j->group + 3 * i : NULL;
    const double g3[3] = {g ? g[0] : 0.0, g ? g[1] : 0.0, g ? g[2] : 0.0};
    const double t = g ? direct_share(d, g3) : 1.0;
    for (int c = 0; c < 3; c++) {
        double r = (double)s[c] - removed_of(j, k, ib, t, d[c], g3[c]);
        r = r > FLT_MAX ? FLT_MAX : r < -FLT_MAX ? -FLT_MAX : r;
        o[c] = s[c] >= 0.0f && r < 0.0 ? 0.0f : (float)r;
    }
}

/* The representative pixel of lo texel index X along an axis of the ROI [a, b). */
static inline int lo_pixel(const vsm_job *j, int X, int a, int b)
{
    int x = a + j->f * X + j->f / 2;
    return x < b ? x : b - 1;
}

static void lo_rows(void *user, int y0, int y1)
{
    vsm_job *j = user;
    const fx_rect *roi = &j->run->roi;
    for (int Y = y0; Y < y1; Y++) {
        const int y = lo_pixel(j, Y, roi->y0, roi->y1);
        for (int X = 0; X < j->lw; X++) {
            const int x = lo_pixel(j, X, roi->x0, roi->x1);
            const size_t k = (size_t)Y * j->lw + X;
            int has;
            j->lo_v[k] = shade_at(j, x, y, &has, &j->lo_a[k]);
            j->lo_d[k] = has ? j->surf.depth[(size_t)y * j->surf.width + x] : -1.0f;
            fx_vec3 n = fx_v3(0.0f, 0.0f, 0.0f);
            if (has)
                fx_surface_normal(&j->surf, x, y, &n);
            j->lo_n[3 * k] = n.x;
            j->lo_n[3 * k + 1] = n.y;
            j->lo_n[3 * k + 2] = n.z;
        }
    }
}

/* lo_factor: each lo texel's ratio factor at its pixel (after the bounce visibility's blur,
 * which it reads), over a 5x5 neighbourhood (3x3 for f < 4: about the texel's block); 1
 * where there is no surface */
static void lo_factor_rows(void *user, int y0, int y1)
{
    vsm_job *j = user;
    const fx_rect *roi = &j->run->roi;
    const int rr = j->f >= 4 ? RATIO_RADIUS : 1;
    for (int Y = y0; Y < y1; Y++) {
        const int y = lo_pixel(j, Y, roi->y0, roi->y1);
        for (int X = 0; X < j->lw; X++) {
            const size_t k = (size_t)Y * j->lw + X;
            float *F = j->lo_F + 3 * k;
            F[0] = F[1] = F[2] = 1.0f;
            if (!(j->lo_d[k] > 0.0f))
                continue;
            const int x = lo_pixel(j, X, roi->x0, roi->x1);
            const float a = j->lo_a[k];
            if (!j->vm && a == 0.0f)
                continue;
            const double ib = bounce_lost(j, x, y, a);
            float d[3];
            double f3[3];
            direct_light(j, x, y, (size_t)y * j->run->width + x, d);
            ratio_factor(j, x, y, a, ib, d, rr, f3);
            for (int c = 0; c < 3; c++)
                F[c] = (float)f3[c];
        }
    }
}

/* Per lo cell (texels X, X + 1 of rows Y, Y + 1, clamped to the grid): bit 0, its four
 * texels alike in value (visibility and lost fraction); bit 1, coherent (see lo_cell). */
static void lo_flag_rows(void *user, int y0, int y1)
{
    vsm_job *j = user;
    for (int Y = y0; Y < y1; Y++)
        for (int X = 0; X < j->lw; X++) {
            const int X1 = X + 1 < j->lw ? X + 1 : X, Y1 = Y + 1 < j->lh ? Y + 1 : Y;
            const size_t id[4] = {(size_t)Y * j->lw + X, (size_t)Y * j->lw + X1, (size_t)Y1 * j->lw + X,
                                  (size_t)Y1 * j->lw + X1};
            const float v0 = j->lo_v[id[0]], a0 = j->lo_a[id[0]];
            int uniform = 1;
            for (int k = 1; k < 4; k++)
                uniform &= j->lo_v[id[k]] == v0 && j->lo_a[id[k]] == a0;
            const float d0 = j->lo_d[id[0]], *n0 = j->lo_n + 3 * id[0];
            int coh = d0 > 0.0f;
            for (int k = 1; k < 4 && coh; k++) {
                const float dk = j->lo_d[id[k]], *nk = j->lo_n + 3 * id[k];
                coh = dk > 0.0f && fabsf(dk - d0) < 0.015f * (float)j->f * d0 &&
                      n0[0] * nk[0] + n0[1] * nk[1] + n0[2] * nk[2] >= 0.9f;
            }
            j->lo_flags[(size_t)Y * j->lw + X] = (unsigned char)(uniform | coh << 1);
        }
}

/* shade_lo's per-row and per-cell values: the lo row pair (Y0, Y1, ty) of the row, and for
 * the lo cell column X0 last used, its four texels' indices, whether they are alike in
 * value (uniform), and their depths and normals */
typedef struct lo_cell {
    int y, X0; /* the row and cell these are for (X0 -1: none yet) */
    int Y0, Y1;
    float ty;
    size_t id[4];
    int uniform;
    float v0, a0; /* the first texel's visibility and lost fraction, in [0, 1] */
    /* coherent: the four texels have a surface, normals within ~25 degrees of the first's
     * and depths within 1.5 % x f of it: the row's bilinear values at the cell's left edge
     * (l) and their change to its right edge (r - l): visibility, lost fraction, depth */
    int coherent;
    float vl, vd, al, ad, dl, dd;
    float Fl[3], Fd[3]; /* lo_factor: the ratio factor's, likewise */
} lo_cell;

static void lo_cell_row(const vsm_job *j, int y, lo_cell *c)
{
    const fx_rect *roi = &j->run->roi;
    const float inv_f = 1.0f / (float)j->f;
    const int o = j->f / 2;
    float v = (float)(y - roi->y0 - o) * inv_f;
    v = v > 0.0f ? (v < (float)(j->lh - 1) ? v : (float)(j->lh - 1)) : 0.0f;
    c->y = y;
    c->X0 = -1;
    c->Y0 = (int)v;
    c->Y1 = c->Y0 + 1 < j->lh ? c->Y0 + 1 : c->Y0;
    c->ty = v - (float)c->Y0;
}

static void lo_cell_at(const vsm_job *j, int X0, lo_cell *c)
{
    const int X1 = X0 + 1 < j->lw ? X0 + 1 : X0;
    const int xs[4] = {X0, X1, X0, X1}, ys[4] = {c->Y0, c->Y0, c->Y1, c->Y1};
    for (int k = 0; k < 4; k++)
        c->id[k] = (size_t)ys[k] * j->lw + xs[k];
    c->v0 = fx_saturate(j->lo_v[c->id[0]]);
    c->a0 = fx_saturate(j->lo_a[c->id[0]]);
    const unsigned char fl = j->lo_flags[(size_t)c->Y0 * j->lw + X0];
    c->uniform = fl & 1;
    c->coherent = (fl >> 1) & 1;
    c->X0 = X0;
    if (c->coherent) {
        const float ty = c->ty;
#define ROWL(arr, k0, k1) (arr[c->id[k0]] + ty * (arr[c->id[k1]] - arr[c->id[k0]]))
        const float vl = ROWL(j->lo_v, 0, 2), vr = ROWL(j->lo_v, 1, 3);
        const float al = ROWL(j->lo_a, 0, 2), ar = ROWL(j->lo_a, 1, 3);
        const float dl = ROWL(j->lo_d, 0, 2), dr = ROWL(j->lo_d, 1, 3);
#undef ROWL
        c->vl = vl;
        c->vd = vr - vl;
        c->al = al;
        c->ad = ar - al;
        c->dl = dl;
        c->dd = dr - dl;
        if (j->lo_factor)
            for (int k = 0; k < 3; k++) {
                const float *F = j->lo_F;
                const float fl = F[3 * c->id[0] + k] + ty * (F[3 * c->id[2] + k] - F[3 * c->id[0] + k]);
                const float fr = F[3 * c->id[1] + k] + ty * (F[3 * c->id[3] + k] - F[3 * c->id[1] + k]);
                c->Fl[k] = fl;
                c->Fd[k] = fr - fl;
            }
    }
}

/* shade_at for pixel (x, y) from the lo texels around it: bilinear weights times a depth
 * likeness (relative difference under tol, falling linearly to 0) and a normal likeness
 * (cosine above 0.8); the pixel's own shade_at when no neighbour is alike. `cell` carries
 * the row's and the last cell's values (lo_cell_row for each row first). */
static inline __attribute__((always_inline)) float shade_lo(const vsm_job *j, int x, int y, lo_cell *cell,
                                                            int *has_surface, float *a, float *F)
{
    if (F)
        F[0] = -1.0f; /* none: the pixel's own removal */
    const fx_surface_src *sf = &j->surf;
    const float d = sf->depth[(size_t)y * sf->width + x];
    if (!(d > 0.0f) || !(d < sf->far_limit)) {
        *has_surface = 0;
        *a = 0.0f;
        return 1.0f; /* as visibility_at */
    }
    const int col = x - j->run->roi.x0, X0 = j->col_X0[col];
    if (X0 != cell->X0)
        lo_cell_at(j, X0, cell);
    const float tx = j->col_tx[col], ty = cell->ty;
    /* the pixel's normal as stored (unnormalised: the likeness test compares squares) */
    const float *pn = sf->normal ? sf->normal + 3 * ((size_t)y * sf->width + x) : NULL;
    const float nn = pn ? pn[0] * pn[0] + pn[1] * pn[1] + pn[2] * pn[2] : 0.0f;
    const int has_n = nn > 1e-8f;
    /* |d - ds| / d < tol, weight 1 - |d - ds| / (tol d) */
    const float tol = 0.015f * (float)j->f, lim = tol * d;
    /* the four texels alike in value (a lit or evenly shadowed area: most pixels): the
     * first one on the pixel's surface gives the answer */
    if (cell->uniform && !F) { /* (with F the factor varies where the visibility does not) */
        for (int k = 0; k < 4; k++) {
            const size_t i = cell->id[k];
            const float ds = j->lo_d[i];
            if (!(ds > 0.0f) || !(fabsf(d - ds) < lim))
                continue;
            if (has_n) { /* cosine above 0.8 (the lo normals are unit or 0) */
                const float *m = j->lo_n + 3 * i;
                const float c = pn[0] * m[0] + pn[1] * m[1] + pn[2] * m[2];
                if (!(c > 0.0f && c * c > 0.64f * nn))
                    continue;
            }
            *has_surface = 1;
            *a = cell->a0; /* saturated already */
            return cell->v0;
        }
        return shade_at(j, x, y, has_surface, a);
    }
    if (cell->coherent) {
        /* one smooth surface: the pixel on it (depth within tol of the interpolated depth,
         * normal within ~37 degrees of the first texel's) takes the bilinear values */
        const float dz = cell->dl + tx * cell->dd;
        int on = fabsf(d - dz) < lim;
        if (on && has_n) {
            const float *m = j->lo_n + 3 * cell->id[0];
            const float c = pn[0] * m[0] + pn[1] * m[1] + pn[2] * m[2];
            on = c > 0.0f && c * c > 0.64f * nn;
        }
        if (on) {
            *has_surface = 1;
            if (F)
                for (int c = 0; c < 3; c++)
                    F[c] = fx_saturate(cell->Fl[c] + tx * cell->Fd[c]);
            *a = fx_saturate(cell->al + tx * cell->ad);
            return fx_saturate(cell->vl + tx * cell->vd);
        }
    }
    const float inv_lim = 1.0f / lim;
    const float bw[4] = {(1.0f - tx) * (1.0f - ty), tx * (1.0f - ty), (1.0f - tx) * ty, tx * ty};
    float acc = 0.0f, acc_a = 0.0f, wsum = 0.0f, acc_f[3] = {0.0f, 0.0f, 0.0f};
    for (int k = 0; k < 4; k++) {
        const size_t i = cell->id[k];
        const float ds = j->lo_d[i];
        if (!(ds > 0.0f))
            continue;
        const float dd = fabsf(d - ds);
        if (!(dd < lim))
            continue;
        if (has_n) {
            const float *m = j->lo_n + 3 * i;
            const float c = pn[0] * m[0] + pn[1] * m[1] + pn[2] * m[2];
            if (!(c > 0.0f && c * c > 0.64f * nn))
                continue;
        }
        const float w = (bw[k] + 1e-3f) * (1.0f - dd * inv_lim);
        acc += w * j->lo_v[i];
        acc_a += w * j->lo_a[i];
        if (F)
            for (int c = 0; c < 3; c++)
                acc_f[c] += w * j->lo_F[3 * i + c];
        wsum += w;
    }
    if (wsum > 1e-6f) {
        const float inv = 1.0f / wsum;
        *has_surface = 1;
        if (F)
            for (int c = 0; c < 3; c++)
                F[c] = fx_saturate(acc_f[c] * inv);
        *a = fx_saturate(acc_a * inv);
        return fx_saturate(acc * inv);
    }
    return shade_at(j, x, y, has_surface, a);
}

/* vsm_rows for screen_downsample > 1: shade_lo per pixel, the lost fraction applied (the
 * sun_diffuse subtraction on one RGBA vector: the same products, lane by lane, as the
 * per-channel loop it falls back to when a channel overflows) */
static void vsm_rows_lo(vsm_job *j, int y0, int y1)
{
    const fx_effect_run *run = j->run;
    const fx_rect *roi = &run->roi;
    const int combined = j->p->apply == APPLY_COMBINED;
    const v4f rad = {j->sun_rad.x, j->sun_rad.y, j->sun_rad.z, 0.0f};
    lo_cell cell;
    memset(&cell, 0, sizeof cell);
    for (int y = roi->y0 + y0; y < roi->y0 + y1; y++) {
        lo_cell_row(j, y, &cell);
        const float *srow = run->src + (size_t)y * run->width * 4;
        float *drow = run->dst + (size_t)y * run->width * 4;
        const float *dcrow = combined ? NULL : j->diffcol + (size_t)y * run->width * 3;
        float *vrow = j->vis_out ? j->vis_out + (size_t)y * run->width : NULL;
        for (int x = roi->x0; x < roi->x1; x++) {
            const float *s = srow + 4 * (size_t)x;
            float *o = drow + 4 * (size_t)x;
            int has;
            float a, F[3] = {-1.0f, 1.0f, 1.0f};
            const float v = j->lo_factor ? shade_lo(j, x, y, &cell, &has, &a, F)
                                         : shade_lo(j, x, y, &cell, &has, &a, NULL);
            if (vrow)
                vrow[x] = v;
            if (j->lo_factor && ((j->vm && has) || a != 0.0f)) {
                if (F[0] >= 0.0f) { /* the lo texels' ratio factor */
                    for (int c = 0; c < 3; c++)
                        o[c] = s[c] * F[c];
                    o[3] = s[3];
                } else {
                    remove_share(j, x, y, a, s, o);
                }
                continue;
            }
            if (j->vis_only) {
                const size_t q = (size_t)y * run->width + x;
                j->vm[2 * q] = has ? v : 0.0f;
                j->vm[2 * q + 1] = has ? 1.0f : 0.0f;
                continue;
            }
            if (j->vm && has) { /* every surface pixel may lose bounce light */
                remove_share(j, x, y, a, s, o);
                continue;
            }
            if (a == 0.0f) {
                /* nothing lost (most lit pixels): both formulas below give s itself */
                if (o != s)
                    memcpy(o, s, 4 * sizeof(float));
                continue;
            }
            if (j->general) { /* a is strength (1 - v) here */
                remove_share(j, x, y, a, s, o);
                continue;
            }
            if (combined) {
                for (int c = 0; c < 3; c++)
                    o[c] = s[c] * (1.0f - a);
                o[3] = s[3];
                continue;
            }
            const float *dc = dcrow + 3 * (size_t)x;
            const v4f sv = ld4(s), dcv = {dc[0], dc[1], dc[2], 0.0f};
            v4f r = sv - V4(a) * dcv * rad;
            const v4f ar = (v4f)((v4i)r & (v4i){0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff});
            const v4i fin = ar <= V4(FLT_MAX);
            if (fin[0] & fin[1] & fin[2]) {
                r = sel4((sv >= V4(0.0f)) & (r < V4(0.0f)), V4(0.0f), r);
                r[3] = s[3];
                st4(o, r);
                continue;
            }
            const float rd[3] = {j->sun_rad.x, j->sun_rad.y, j->sun_rad.z};
            for (int c = 0; c < 3; c++) {
                float rc = s[c] - a * dc[c] * rd[c];
                if (!(fabsf(rc) <= FLT_MAX)) {
                    double t = (double)s[c] - (double)a * dc[c] * rd[c];
                    rc = (float)(t > FLT_MAX ? FLT_MAX : t < -FLT_MAX ? -FLT_MAX : t);
                }
                o[c] = s[c] >= 0.0f && rc < 0.0f ? 0.0f : rc;
            }
            o[3] = s[3];
        }
    }
}

static void vsm_rows(void *user, int y0, int y1)
{
    vsm_job *j = user;
    const fx_effect_run *run = j->run;
    const fx_rect *roi = &run->roi;
    if (j->f > 1) {
        vsm_rows_lo(j, y0, y1);
        return;
    }
    for (int y = roi->y0 + y0; y < roi->y0 + y1; y++) {
        for (int x = roi->x0; x < roi->x1; x++) {
            size_t i = (size_t)y * run->width + x;
            const float *s = run->src + 4 * i;
            float *o = run->dst + 4 * i;
            int has;
            float v = visibility_at(j, x, y, &has);
            if (j->vis_out)
                j->vis_out[i] = v;
            if (j->vis_only) {
                j->vm[2 * i] = has ? v : 0.0f;
                j->vm[2 * i + 1] = has ? 1.0f : 0.0f;
                continue;
            }
            float k = j->p->strength * (1.0f - v);
            if (j->general) {
                if (k > 0.0f || (j->vm && has))
                    remove_share(j, x, y, k, s, o);
                else
                    memcpy(o, s, 3 * sizeof(float));
            } else if (j->p->apply == APPLY_COMBINED) {
                for (int c = 0; c < 3; c++)
                    o[c] = s[c] * (1.0f - k);
            } else {
                const float ndl = sun_cosine(j, x, y, k);
                const float *dc = j->diffcol + 3 * i;
                float rad[3] = {j->sun_rad.x, j->sun_rad.y, j->sun_rad.z};
                for (int c = 0; c < 3; c++) {
                    float r = s[c] - k * ndl * dc[c] * rad[c];
                    if (!(fabsf(r) <= FLT_MAX)) { /* a huge DiffCol overflowed: again in double */
                        double t = (double)s[c] - (double)k * ndl * dc[c] * rad[c];
                        r = (float)(t > FLT_MAX ? FLT_MAX : t < -FLT_MAX ? -FLT_MAX : t);
                    }
                    o[c] = s[c] >= 0.0f && r < 0.0f ? 0.0f : r;
                }
            }
            o[3] = s[3];
        }
    }
}

/* apply other than combined: the light the view belongs to (its radiance colour * energy /
 * pi and the direction towards it) and the passes the removal reads: DiffCol, GlossCol for
 * sun_direct and light_group, the light group's Combined for light_group. */
static fx_result vsm_light_inputs(const fx_effect_run *run, vsm_job *j)
{
    const vsm_params *p = j->p;
    const char *where = run->where;
    fx_light light;
    fx_result r = fx_frame_find_light(run->frame, j->av->name + 6, where, &light);
    if (r)
        return r;
    fx_pass *dc = fx_frame_find_pass(run->frame, "DiffCol");
    if (!dc || dc->channels < 3)
        return fx_fail(run->ctx, FX_ERR_MISSING_PASS, "%s: apply %s needs the DiffCol pass", where,
                       apply_items[p->apply]);
    j->diffcol = dc->data;
    static const char *const extra[2] = {"GlossCol", "Combined_" FX_LIGHT_GROUP_NAME};
    for (int e = 0; e < 2 && p->apply >= APPLY_SUN_DIRECT; e++) {
        if (e == 1 && p->apply != APPLY_LIGHT_GROUP)
            break;
        fx_pass *ps = fx_frame_find_pass(run->frame, extra[e]);
        if (!ps || ps->channels < 3)
            return fx_fail(run->ctx, FX_ERR_MISSING_PASS, "%s: apply %s needs the %s pass%s", where,
                           apply_items[p->apply], extra[e],
                           e ? " (the light group '" FX_LIGHT_GROUP_NAME "' holding the light: the add-on "
                               "makes it; else use apply sun_direct)"
                             : "");
        if (e == 0)
            j->glosscol = ps->data;
        else
            j->group = ps->data;
    }
    float e = light.energy * 0.318309886f /* 1/pi */;
    j->sun_rad = fx_v3(light.color.x * e, light.color.y * e, light.color.z * e);
    j->to_light = fx_v3_scale(light.direction, -1.0f);
    if (light.type != FX_LIGHT_SUN)
        fx_warn(run->ctx, "%s: light '%s' is not a sun: %s treats it as one", where, light.name,
                apply_items[p->apply]);
    return FX_OK;
}

/* screen_downsample f > 1: the lo grid (lw x lh texels: visibility, alpha, depth, normal,
 * the ratio factors with remove_as ratio) and the per-column lookups, in one block from the
 * context's buffer store (no fresh pages frame after frame), filled by lo_rows and
 * lo_flag_rows. *block and *bytes: the block, for fx_buffer_put (NULL when out of memory). */
static fx_result vsm_lo_grid(const fx_effect_run *run, vsm_job *j, float **block, size_t *bytes)
{
    const fx_rect *roi = &run->roi;
    const int rows = roi->y1 - roi->y0, cols = roi->x1 - roi->x0;
    j->lw = (cols + j->f - 1) / j->f;
    j->lh = rows / j->f + (rows % j->f ? 1 : 0);
    const size_t lo_n = (size_t)j->lw * j->lh;
    j->lo_factor = j->general && j->p->remove_as == REMOVE_RATIO;
    const size_t per = j->lo_factor ? 9 : 6; /* floats per lo texel */
    *bytes = lo_n * per * sizeof(float) + (size_t)cols * 2 * sizeof(float) + lo_n;
    float *lo = *block = fx_buffer_get(run->ctx, *bytes);
    if (!lo)
        return fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", run->where);
    j->lo_v = lo;
    j->lo_a = lo + lo_n;
    j->lo_d = lo + 2 * lo_n;
    j->lo_n = lo + 3 * lo_n;
    j->lo_F = j->lo_factor ? lo + 6 * lo_n : NULL;
    j->col_tx = lo + per * lo_n;
    j->col_X0 = (int *)(j->col_tx + cols);
    j->lo_flags = (unsigned char *)(j->col_X0 + cols);
    for (int x = roi->x0; x < roi->x1; x++) {
        /* the lo texel coordinate of column x (lo texel X sits at pixel f X + f / 2) */
        float u = (float)(x - roi->x0 - j->f / 2) * (1.0f / (float)j->f);
        u = u > 0.0f ? (u < (float)(j->lw - 1) ? u : (float)(j->lw - 1)) : 0.0f;
        j->col_X0[x - roi->x0] = (int)u;
        j->col_tx[x - roi->x0] = u - (float)(int)u;
    }
    fx_parallel_for(run->ctx, j->lh, fx_grain_for(run->ctx, j->lh), lo_rows, j);
    fx_parallel_for(run->ctx, j->lh, fx_grain_for(run->ctx, j->lh), lo_flag_rows, j);
    return FX_OK;
}

/* bounce_reach (light_group): the visibility of every pixel first (with screen_downsample,
 * the lo texels'), then its surroundings' mean (a Gaussian of v m over one of m), which the
 * removal reads. *block and *bytes: the (v m, m) buffer, for fx_buffer_put. */
static fx_result vsm_bounce(const fx_effect_run *run, vsm_job *j, float **block, size_t *bytes)
{
    const int vm_lo = j->f > 1, rows = run->roi.y1 - run->roi.y0;
    *bytes = (vm_lo ? (size_t)j->lw * j->lh : (size_t)run->width * run->height) * 2 * sizeof(float);
    float *vm = *block = fx_buffer_get(run->ctx, *bytes);
    if (!vm)
        return fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", run->where);
    memset(vm, 0, *bytes);
    j->vm = vm;
    j->vm_lo = vm_lo;
    double sigma = j->p->bounce_reach * (double)run->width;
    if (vm_lo) {
        for (size_t k = 0; k < (size_t)j->lw * j->lh; k++) {
            const int has = j->lo_d[k] > 0.0f;
            vm[2 * k] = has ? fx_saturate(j->lo_v[k]) : 0.0f;
            vm[2 * k + 1] = has ? 1.0f : 0.0f;
        }
        sigma /= (double)j->f;
    } else {
        j->vis_only = 1;
        fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), vsm_rows, j);
        j->vis_only = 0;
    }
    fx_blur_spec bs = {sigma, FX_BLUR_RECURSIVE, 3};
    return fx_blur_image(run->ctx, vm, vm, vm_lo ? j->lw : run->width, vm_lo ? j->lh : run->height, 2, &bs,
                         vm_lo ? NULL : &run->roi, run->where);
}

static fx_result vsm_process(const fx_effect_run *run)
{
    const vsm_params *p = run->params;
    const char *where = run->where;
    vsm_job j;
    memset(&j, 0, sizeof j);
    j.run = run;
    j.p = p;
    if (!fx_surface_src_init(&j.surf, run->frame))
        return fx_fail(run->ctx, FX_ERR_NO_CAMERA, "%s needs the camera and the Depth pass", where);
    char name[FX_STRING_PARAM_MAX + 8];
    snprintf(name, sizeof name, "light:%s", p->light);
    /* the light view's map, built once per context and reused while the view is the same
     * (core/aux_view.h); PCF and hard read only the normalised depth */
    fx_aux_map map;
    int filtered = p->method == METHOD_VSM;
    /* the moments are made by the filter call, which width <= 1 skips: 1.5 texels rounds
     * to no box */
    int level = filtered ? p->map_level : 0;
    float width = filtered ? p->filter_size : 0.0f;
    if (filtered && !(width > 1.0f))
        width = 1.5f;
    fx_result r = fx_aux_map_acquire(run->frame, name, p->derivative_bias,
                                     filtered ? FX_SHADOW_FILTER_WITH_LEVEL(p->filter, level) : -1, width, where,
                                     &map);
    if (r)
        return r;
    /* from here on, every way out goes through done: (the buffers and the map given back) */
    float *lo = NULL, *vm = NULL;
    size_t lo_bytes = 0, vm_bytes = 0;
    j.av = map.av;
    j.general = !(p->apply == APPLY_COMBINED || (p->apply == APPLY_SUN_DIFFUSE && p->remove_as == REMOVE_DIFFERENCE));
    if (p->apply != APPLY_COMBINED && (r = vsm_light_inputs(run, &j)))
        goto done;
    j.sm = map.sm;
    float ms = fx_shadow_map_norm_dist(j.sm, p->min_std);
    j.min_var = ms * ms > 1e-12f ? ms * ms : 1e-12f;
    j.eps = fx_shadow_map_norm_dist(j.sm, p->depth_bias);
    j.pcf_radius = (int)lrintf((p->filter_size - 1.0f) * 0.5f);
    j.vis_out = fx_effect_debug_pass(run, "visibility", 1, &r);
    if (!j.vis_out && r)
        goto done;
    j.f = p->screen_downsample > 1 ? p->screen_downsample : 1;
    if (j.f > 1 && (r = vsm_lo_grid(run, &j, &lo, &lo_bytes)))
        goto done;
    if (p->apply == APPLY_LIGHT_GROUP && p->bounce_reach > 0.0f && p->bounce_loss > 0.0f &&
        (r = vsm_bounce(run, &j, &vm, &vm_bytes)))
        goto done;
    if (j.lo_factor) {
        /* the lo texels' ratio factors (reading the blurred bounce visibility) */
        fx_parallel_for(run->ctx, j.lh, fx_grain_for(run->ctx, j.lh), lo_factor_rows, &j);
    }
    const int rows = run->roi.y1 - run->roi.y0;
    fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), vsm_rows, &j);
done:
    fx_buffer_put(run->ctx, vm, vm_bytes);
    fx_buffer_put(run->ctx, lo, lo_bytes);
    fx_aux_map_release(&map);
    return r;
}

/* The light's depth view, by the light's name ("" = the scene's first sun). */
static int vsm_aux_views(const void *params, fx_aux_need *out, int max)
{
    const vsm_params *p = params;
    if (max < 1)
        return 0;
    snprintf(out->name, sizeof out->name, "light:%.80s", p->light);
    out->kind = "light";
    snprintf(out->light, sizeof out->light, "%.80s", p->light);
    return 1;
}

/* params_version 2 added remove_as with the default ratio: a recipe of version 1 keeps the
 * subtraction it was made with (remove_as difference unless it names one). Silent: the
 * output is the same as before, nothing for the user to act on. */
static fx_result vsm_migrate(int from_version, cJSON *params, char *note, size_t note_size)
{
    (void)note;
    (void)note_size;
    if (from_version == 1 && params && !cJSON_GetObjectItemCaseSensitive(params, "remove_as") &&
        !cJSON_AddStringToObject(params, "remove_as", "difference"))
        return FX_ERR_OUT_OF_MEMORY;
    return FX_OK;
}

/* remove_as ratio averages over a 5x5 neighbourhood */
static int vsm_halo(const void *params, int width, int height)
{
    const vsm_params *p = params;
    (void)width;
    (void)height;
    return p->remove_as == REMOVE_RATIO && p->apply != APPLY_COMBINED ? RATIO_RADIUS : 0;
}

const fx_effect_class fx_effect_vsm_shadows = {
    .name = "vsm_shadows",
    .doc = "Shadows of a light from its depth view: variance shadow maps (box or Gaussian), PCF or hard",
    .params_size = sizeof(vsm_params),
    .params = vsm_param_defs,
    .param_count = FX_COUNT_OF(vsm_param_defs),
    .presets = {"{\"map_level\": 2, \"screen_downsample\": 5, \"normal_offset\": 0}",
                "{\"map_level\": 1, \"screen_downsample\": 2, \"normal_offset\": 0}", "{\"map_level\": 0}", "{\"method\": \"pcf\"}"},
    .passes = vsm_passes,
    .flags = FX_EFFECT_NEEDS_CAMERA,
    .aux_views = vsm_aux_views,
    .halo = vsm_halo,
    .validate = NULL,
    .process = vsm_process,
    .params_version = 2,
    .migrate = vsm_migrate,
};
