/* wet_surfaces: the wet look where rain reaches (the seed's wet shading): surfaces exposed
 * to the sky per the rain map that face up (or walls, less) get darker albedo and a
 * Fresnel reflection of the sky, plus more of their own glossy light when the frame has
 * GlossDir/GlossCol. docs/effects/wet_surfaces.md.
 *
 * Exposure has soft edges at cover boundaries without a ring of lookups: the rain map is
 * read as a variance shadow map of rain falling straight down, its moments box-filtered
 * once through a summed-area table over edge_softness metres, and each pixel does one
 * Chebyshev lookup (math/rain_map.h). Wetness w = wetness * exposure * facing, where
 * facing is 1 for up-facing normals (N.z >= up_threshold), wall_wetness for walls,
 * smoothly between, 0 facing down. Output: src (1 - darken w) + w specular F(N.V) sky_color
 * + w gloss_boost GlossDir GlossCol, F Schlick's with F0 = 0.02 (water), N.V clamped. */
#include "core/aux_view.h"
#include "core/effect.h"
#include "core/parallel.h"
#include "math/rain_map.h"
#include "math/surface.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

typedef struct wet_params {
    float wetness;
    float darken;
    float specular;
    float sky[3];
    float up_threshold;
    float wall_wetness;
    float softness;
    float gloss_boost;
} wet_params;

static const float default_sky[3] = {0.55f, 0.62f, 0.72f};

static const fx_param_def wet_param_defs[] = {
    FX_P_FLOAT(wet_params, wetness, "wetness", 1.0, 0.0, 1.0, 0.0, 1.0, "factor",
               "Overall wetness; a pixel's wetness is this x its exposure in the rain map x "
               "its facing (up 1, walls wall_wetness, down 0); 0: identity"),
    FX_P_FLOAT(wet_params, darken, "darken", 0.35, 0.0, 1.0, 0.0, 0.8, "factor",
               "How much water darkens the surface: wet pixels are scaled by 1 - darken x "
               "wetness (0: no darkening)"),
    FX_P_FLOAT(wet_params, specular, "specular", 0.8, 0.0, 10.0, 0.0, 2.0, "",
               "Strength of the wet film's reflection of sky_color, times wetness and Schlick's "
               "Fresnel (F0 0.02, water): strongest at grazing angles"),
    FX_P_FLOATS(wet_params, sky, "sky_color", 3, default_sky, 0.0, 1e4, "color", "Radiance the wet film reflects"),
    FX_P_FLOAT(wet_params, up_threshold, "up_threshold", 0.7, 0.0, 1.0, 0.3, 0.95, "",
               "Normals with a world Z at least this face up (fully wet)"),
    FX_P_FLOAT(wet_params, wall_wetness, "wall_wetness", 0.4, 0.0, 1.0, 0.0, 1.0, "factor",
               "Wetness of exposed walls (normal Z about 0)"),
    FX_P_FLOAT(wet_params, softness, "edge_softness", 0.4, 0.0, 100.0, 0.0, 2.0, "",
               "Width of the wet/dry transition at cover boundaries, metres"),
    FX_P_FLOAT(wet_params, gloss_boost, "gloss_boost", 1.0, 0.0, 10.0, 0.0, 3.0, "",
               "Extra glossy direct light (GlossDir x GlossCol, when the frame has them)"),
};

static fx_pass_set wet_passes(const void *params)
{
    (void)params;
    return FX_PASS_BIT(FX_PASS_DEPTH) | FX_PASS_BIT(FX_PASS_NORMAL);
}

static int wet_needs_camera(const void *params)
{
    (void)params;
    return 1;
}

typedef struct wet_job {
    const fx_effect_run *run;
    const wet_params *p;
    fx_surface_src surf;
    fx_rain_map rm;
    const float *gdir, *gcol;
    float *dbg;
} wet_job;

static void wet_rows(void *user, int y0, int y1)
{
    wet_job *j = user;
    const fx_effect_run *run = j->run;
    const wet_params *p = j->p;
    const fx_rect *roi = &run->roi;
    for (int y = roi->y0 + y0; y < roi->y0 + y1; y++)
        for (int x = roi->x0; x < roi->x1; x++) {
            size_t i = (size_t)y * run->width + x;
            const float *s = run->src + 4 * i;
            float *o = run->dst + 4 * i;
            memcpy(o, s, 4 * sizeof(float));
            fx_vec3 w, n;
            float d;
            float wet = 0.0f;
            if (fx_surface_world(&j->surf, x, y, &w, &d) && fx_surface_normal(&j->surf, x, y, &n)) {
                float facing = n.z >= 0.0f ? fx_lerpf(p->wall_wetness, 1.0f, fx_smoothstep(0.0f, p->up_threshold, n.z))
                                           : p->wall_wetness * (1.0f - fx_smoothstep(0.0f, 0.3f, -n.z));
                if (facing > 0.0f) {
                    /* off the surface a little, so the surface itself does not cover it */
                    fx_vec3 q = fx_v3_add(w, fx_v3_scale(n, 0.05f));
                    wet = p->wetness * facing * fx_rain_map_soft(&j->rm, q);
                    if (!(wet > 0.0f))
                        wet = 0.0f; /* also NaN */
                }
                if (wet > 0.0f) {
                    fx_vec3 eye = fx_v3(j->surf.view.camera_to_world[3], j->surf.view.camera_to_world[7],
                                        j->surf.view.camera_to_world[11]);
                    fx_vec3 v = fx_v3_normalize_or(fx_v3_sub(eye, w), n);
                    if (j->surf.view.orthographic)
                        v = fx_v3_normalize_or(fx_v3(j->surf.view.camera_to_world[2], j->surf.view.camera_to_world[6],
                                                     j->surf.view.camera_to_world[10]), n);
                    float ndv = fx_saturate(fx_v3_dot(n, v));
                    float m = 1.0f - ndv, m2 = m * m;
                    float fres = 0.02f + 0.98f * m2 * m2 * m;
                    for (int c = 0; c < 3; c++) {
                        float add = p->specular * fres * p->sky[c];
                        if (j->gdir && j->gcol)
                            add += p->gloss_boost * j->gdir[3 * i + c] * j->gcol[3 * i + c];
                        float r = s[c] * (1.0f - p->darken * wet) + wet * add;
                        /* hostile 1e38 glossy passes overflow the product: keep it finite */
                        o[c] = r != r ? s[c] : fx_clampf(r, -FLT_MAX, FLT_MAX);
                    }
                }
            }
            if (j->dbg)
                j->dbg[i] = wet;
        }
}

static fx_result wet_process(const fx_effect_run *run)
{
    const wet_params *p = run->params;
    const fx_rect *roi = &run->roi;
    if (roi->x1 <= roi->x0 || roi->y1 <= roi->y0)
        return FX_OK;
    const char *where = run->where;
    wet_job j;
    memset(&j, 0, sizeof j);
    j.run = run;
    j.p = p;
    if (!fx_surface_src_init(&j.surf, run->frame) || !j.surf.normal)
        return fx_fail(run->ctx, FX_ERR_NO_CAMERA, "%s needs the camera and the Depth and Normal passes", where);
    /* the rain map's moments box-filtered over `softness` metres (cached per context) */
    fx_result r = fx_rain_map_load(run->frame, p->softness, where, &j.rm);
    if (r)
        return r;
    fx_pass *gd = fx_frame_find_pass(run->frame, "GlossDir"), *gc = fx_frame_find_pass(run->frame, "GlossCol");
    if (gd && gc && gd->channels >= 3 && gc->channels >= 3 && gd->channels == gc->channels && gd->channels == 3) {
        j.gdir = gd->data;
        j.gcol = gc->data;
    }
    j.dbg = fx_effect_debug_pass(run, "wetness", 1, &r);
    if (!j.dbg && r) {
        fx_rain_map_free(run->ctx, &j.rm);
        return r;
    }
    int rows = roi->y1 - roi->y0;
    fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), wet_rows, &j);
    fx_rain_map_free(run->ctx, &j.rm);
    return FX_OK;
}

const fx_effect_class fx_effect_wet_surfaces = {
    .name = "wet_surfaces",
    .doc = "Wet look where rain reaches (rain map): darker albedo, Fresnel sky reflection, soft edges at covers",
    .params_size = sizeof(wet_params),
    .params = wet_param_defs,
    .param_count = FX_COUNT_OF(wet_param_defs),
    .presets = {NULL, NULL, NULL, NULL},
    .passes = wet_passes,
    .needs_camera = wet_needs_camera,
    .aux_views = fx_aux_needs_rain_map, /* what is under cover */
    .halo = NULL,
    .validate = NULL,
    .process = wet_process,
};
