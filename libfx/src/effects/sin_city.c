/* sin_city: the Sin City look: gray (mean or luminance) in N levels (the seed's banding,
 * math/levels.h), with one colour kept: the seed's dot-product range test on the colour's
 * direction, or a smooth hue window (hue, width, softness, gated by saturation) so the kept
 * red does not alias; the kept colour may be limited to an object or material (keep only
 * the red coat). docs/effects/sin_city.md. */
#include "core/effect.h"
#include "core/mask.h"
#include "core/parallel.h"
#include "math/color.h"
#include "math/levels.h"
#include "math/vec.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

typedef struct sin_city_params {
    int gray;
    int levels;
    int space;
    float white;
    float dither;
    int keep;
    float key_color[3];
    float dot_min, dot_max, dot_softness;
    float hue, hue_width, hue_softness;
    float min_saturation, saturation_softness;
    float keep_strength;
    char keep_object[FX_STRING_PARAM_MAX];
    char keep_material[FX_STRING_PARAM_MAX];
    float mix;
} sin_city_params;

enum { GRAY_LUMINANCE = 0, GRAY_MEAN };
enum { SPACE_SRGB = 0, SPACE_LINEAR };
enum { KEEP_HUE = 0, KEEP_DOT, KEEP_NONE };

static const char *const gray_items[] = { "luminance", "mean" };
static const char *const space_items[] = { "srgb", "linear" };
static const char *const keep_items[] = { "hue", "dot", "none" };
static const float red3[3] = { 1, 0, 0 };

static const fx_param_def sin_city_param_defs[] = {
    FX_P_ENUM(sin_city_params, gray, "gray", GRAY_LUMINANCE, gray_items,
              "Gray from Rec.709 luminance or from the mean (R+G+B)/3"),
    FX_P_INT(sin_city_params, levels, "levels", 0, 0, 256, 0, 16, "",
             "Gray levels (the seed's banding); 0 or 1: continuous gray"),
    FX_P_ENUM(sin_city_params, space, "space", SPACE_SRGB, space_items, "Level steps in sRGB-encoded or linear values"),
    FX_P_FLOAT(sin_city_params, white, "white", 1.0, 1e-6, 65504.0, 0.1, 16.0, "", "Linear value of the top level"),
    FX_P_FLOAT(sin_city_params, dither, "dither", 0.0, 0.0, 1.0, 0.0, 1.0, "factor", "Ordered dither amplitude, in bands"),
    FX_P_ENUM(sin_city_params, keep, "keep", KEEP_HUE, keep_items,
              "Which colours stay: hue: a smooth hue window; dot: the seed's test, the cosine between the "
              "colour and key_color in [dot_min, dot_max]; none: all gray"),
    FX_P_FLOATS(sin_city_params, key_color, "key_color", 3, red3, 0.0, 65504.0, "color", "Kept colour for keep dot"),
    FX_P_FLOAT(sin_city_params, dot_min, "dot_min", 0.9, -1.0, 1.0, 0.5, 1.0, "",
               "keep dot: smallest cosine between the colour and key_color that is kept"),
    FX_P_FLOAT(sin_city_params, dot_max, "dot_max", 1.0, -1.0, 1.0, 0.5, 1.0, "", "keep dot: largest cosine kept"),
    FX_P_FLOAT(sin_city_params, dot_softness, "dot_softness", 0.0, 0.0, 1.0, 0.0, 0.2, "",
               "keep dot: ramp width in cosine at both ends of the range (0: the seed's hard test)"),
    FX_P_FLOAT(sin_city_params, hue, "hue", 0.0, -360.0, 720.0, 0.0, 360.0, "angle",
               "keep hue: centre hue in degrees (0 red, 120 green, 240 blue)"),
    FX_P_FLOAT(sin_city_params, hue_width, "hue_width", 30.0, 0.0, 360.0, 0.0, 120.0, "angle",
               "keep hue: full width in degrees kept entirely"),
    FX_P_FLOAT(sin_city_params, hue_softness, "hue_softness", 20.0, 0.0, 180.0, 0.0, 60.0, "angle",
               "keep hue: smooth falloff in degrees beyond the width"),
    FX_P_FLOAT(sin_city_params, min_saturation, "min_saturation", 0.3, 0.0, 1.0, 0.0, 1.0, "factor",
               "keep hue: colours less saturated than this ((max-min)/max) turn gray (their hue is noise)"),
    FX_P_FLOAT(sin_city_params, saturation_softness, "saturation_softness", 0.15, 0.0, 1.0, 0.0, 0.5, "factor",
               "keep hue: ramp width of the saturation gate"),
    FX_P_FLOAT(sin_city_params, keep_strength, "keep_strength", 1.0, 0.0, 1.0, 0.0, 1.0, "factor",
               "How much of the kept colour returns (1: the original colour)"),
    FX_P_STRING(sin_city_params, keep_object, "keep_object", "", "",
                "Keep colour only on this object (Cryptomatte name; empty: everywhere)"),
    FX_P_STRING(sin_city_params, keep_material, "keep_material", "", "",
                "Keep colour only on this material (Cryptomatte name; empty: everywhere)"),
    FX_P_FLOAT(sin_city_params, mix, "mix", 1.0, 0.0, 1.0, 0.0, 1.0, "factor",
               "Blend between the original (0, the identity) and the result (1)"),
};

/* The keep-mask spec of the params (borrowing the names). */
static void keep_spec(const sin_city_params *p, fx_mask_spec *s, char *names[2])
{
    memset(s, 0, sizeof *s);
    names[0] = (char *)p->keep_object;
    names[1] = (char *)p->keep_material;
    if (p->keep_object[0]) {
        s->objects = &names[0];
        s->object_count = 1;
    }
    if (p->keep_material[0]) {
        s->materials = &names[1];
        s->material_count = 1;
    }
}

static fx_pass_set sin_city_passes(const void *params)
{
    const sin_city_params *p = params;
    if (p->keep == KEEP_NONE || !(p->mix > 0.0f))
        return 0;
    fx_mask_spec s;
    char *names[2];
    keep_spec(p, &s, names);
    return fx_mask_spec_passes(&s);
}

typedef struct sc_job {
    const fx_effect_run *run;
    const sin_city_params *p;
    const float *keep_cov; /* NULL: everywhere */
    int quantise;
    float key[3];
    float hue_c, hue_half, hue_soft;
    fx_levels q;
} sc_job;

static inline float finite_or(float v)
{
    v = v == v ? v : 0.0f;
    return v > FLT_MAX ? FLT_MAX : v < -FLT_MAX ? -FLT_MAX : v;
}

/* Weight in [0, 1] of keeping colour (r, g, b) (finite, may be negative). */
static inline float keep_weight(const sc_job *j, float r, float g, float b)
{
    const sin_city_params *p = j->p;
    r = r > 0.0f ? r : 0.0f;
    g = g > 0.0f ? g : 0.0f;
    b = b > 0.0f ? b : 0.0f;
    float mx = fmaxf(r, fmaxf(g, b)), mn = fminf(r, fminf(g, b));
    if (!(mx > 1e-20f))
        return 0.0f;
    if (p->keep == KEEP_DOT) {
        /* scale first: |c| of 1e38 squared would overflow */
        float inv = 1.0f / mx;
        float x = r * inv, y = g * inv, z = b * inv;
        float c = (x * j->key[0] + y * j->key[1] + z * j->key[2]) / sqrtf(x * x + y * y + z * z);
        float s = p->dot_softness;
        if (s <= 0.0f)
            return c >= p->dot_min && c <= p->dot_max ? 1.0f : 0.0f;
        float lo = fx_saturate((c - (p->dot_min - s)) / s);
        float hi = fx_saturate(((p->dot_max + s) - c) / s);
        return fminf(lo, hi);
    }
    /* hue window: hexcone hue in degrees, circular distance to the centre */
    float d = mx - mn;
    float sat = d / mx;
    float gate = p->saturation_softness > 0.0f
                     ? fx_saturate((sat - p->min_saturation) / p->saturation_softness + 0.5f)
                     : (sat >= p->min_saturation ? 1.0f : 0.0f);
    if (!(gate > 0.0f) || !(d > 0.0f))
        return 0.0f;
    float h;
    if (mx == r)
        h = 60.0f * ((g - b) / d);
    else if (mx == g)
        h = 60.0f * ((b - r) / d) + 120.0f;
    else
        h = 60.0f * ((r - g) / d) + 240.0f;
    float dist = fabsf(h - j->hue_c);
    dist = fmodf(dist, 360.0f);
    dist = dist > 180.0f ? 360.0f - dist : dist;
    float w = dist <= j->hue_half ? 1.0f
              : j->hue_soft > 0.0f ? 1.0f - fx_smoothstep(j->hue_half, j->hue_half + j->hue_soft, dist)
                                   : 0.0f;
    return w * gate;
}

static void sc_rows(void *user, int begin, int end)
{
    const sc_job *j = user;
    const fx_effect_run *run = j->run;
    const sin_city_params *p = j->p;
    const float mix = p->mix, ks = p->keep_strength;
    for (int y = run->roi.y0 + begin; y < run->roi.y0 + end; y++) {
        const float *s = run->src + (size_t)y * run->width * 4;
        float *d = run->dst + (size_t)y * run->width * 4;
        const float *cov = j->keep_cov ? j->keep_cov + (size_t)y * run->width : NULL;
        for (int x = run->roi.x0; x < run->roi.x1; x++) {
            const float r = finite_or(s[4 * x]), g = finite_or(s[4 * x + 1]), b = finite_or(s[4 * x + 2]);
            float gray = p->gray == GRAY_LUMINANCE ? fx_luminance(r, g, b)
                                                   : r * (1.0f / 3.0f) + g * (1.0f / 3.0f) + b * (1.0f / 3.0f);
            if (j->quantise)
                gray = fx_levels_apply(&j->q, gray, x, y);
            float k = 0.0f;
            if (p->keep != KEEP_NONE && (!cov || cov[x] > 0.0f))
                k = keep_weight(j, r, g, b) * ks * (cov ? cov[x] : 1.0f);
            const float k1 = 1.0f - k; /* k = 1 gives the colour exactly, k = 0 the gray */
            float o[3] = { k * r + k1 * gray, k * g + k1 * gray, k * b + k1 * gray };
            const float in[3] = { r, g, b };
            for (int c = 0; c < 3; c++)
                d[4 * x + c] = finite_or(mix < 1.0f ? in[c] + mix * (o[c] - in[c]) : o[c]);
            d[4 * x + 3] = finite_or(s[4 * x + 3]);
        }
    }
}

static fx_result sin_city_process(const fx_effect_run *run)
{
    const sin_city_params *p = run->params;
    const fx_rect *roi = &run->roi;
    if (roi->x1 <= roi->x0 || roi->y1 <= roi->y0)
        return FX_OK;
    if (!(p->mix > 0.0f)) {
        for (int y = roi->y0; y < roi->y1; y++)
            memcpy(run->dst + ((size_t)y * run->width + roi->x0) * 4,
                   run->src + ((size_t)y * run->width + roi->x0) * 4,
                   (size_t)(roi->x1 - roi->x0) * 4 * sizeof(float));
        return FX_OK;
    }
    char where[96];
    snprintf(where, sizeof where, "effect %d (sin_city) keep mask", run->index);
    sc_job *j = fx_mem_alloc(sizeof *j);
    if (!j)
        return fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where);
    memset(j, 0, sizeof *j);
    j->run = run;
    j->p = p;
    j->quantise = p->levels >= 2;
    if (j->quantise)
        fx_levels_init(&j->q, p->levels, p->space == SPACE_SRGB, p->white, p->dither, 1);
    float kl = sqrtf(p->key_color[0] * p->key_color[0] + p->key_color[1] * p->key_color[1] +
                     p->key_color[2] * p->key_color[2]);
    for (int c = 0; c < 3; c++)
        j->key[c] = kl > 1e-20f ? p->key_color[c] / kl : 0.0f;
    j->hue_c = fmodf(p->hue, 360.0f);
    j->hue_c = j->hue_c < 0.0f ? j->hue_c + 360.0f : j->hue_c;
    j->hue_half = 0.5f * p->hue_width;
    j->hue_soft = p->hue_softness;
    fx_mask *keep = NULL;
    fx_result r = FX_OK;
    if (p->keep != KEEP_NONE && (p->keep_object[0] || p->keep_material[0])) {
        fx_mask_spec spec;
        char *names[2];
        keep_spec(p, &spec, names);
        r = fx_mask_build(run->ctx, &spec, run->frame, where, &keep);
        if (!r && keep)
            j->keep_cov = keep->coverage;
    }
    if (!r) {
        int rows = roi->y1 - roi->y0;
        fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), sc_rows, j);
    }
    fx_mask_free(keep);
    fx_mem_free(j);
    return r;
}

static fx_result sin_city_validate(const void *params, char *err, size_t err_size)
{
    const sin_city_params *p = params;
    if (p->dot_min > p->dot_max) {
        snprintf(err, err_size, "dot_min (%g) is above dot_max (%g)", p->dot_min, p->dot_max);
        return FX_ERR_BAD_PARAM;
    }
    for (int i = 0; i < 3; i++)
        if (!isfinite(p->key_color[i])) {
            snprintf(err, err_size, "key_color[%d] is not finite", i);
            return FX_ERR_BAD_PARAM;
        }
    return FX_OK;
}

const fx_effect_class fx_effect_sin_city = {
    .name = "sin_city",
    .doc = "Sin City look: gray in N levels with one colour kept (hue window or the seed's dot test), optionally on one object",
    .params_size = sizeof(sin_city_params),
    .params = sin_city_param_defs,
    .param_count = FX_COUNT_OF(sin_city_param_defs),
    .presets = { NULL, NULL, NULL, NULL },
    .passes = sin_city_passes,
    .needs_camera = NULL,
    .halo = NULL,
    .validate = sin_city_validate,
    .process = sin_city_process,
};
