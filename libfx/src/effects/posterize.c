/* posterize: N colour levels per channel, or of the gray (mean or Rec.709 luminance): the
 * seed's banding, in sRGB-encoded or linear steps, with optional ordered dithering.
 * Memory-bound: one pass, SIMD threshold chain from math/levels.h (no encoding per pixel). docs/effects/posterize.md. */
#include "core/effect.h"
#include "core/parallel.h"
#include "math/color.h"
#include "math/levels.h"

#include <float.h>
#include <stdio.h>
#include <string.h>

typedef struct posterize_params {
    int mode;
    int levels;
    int space;
    float white;
    float dither;
    int keep_hdr;
    float mix;
} posterize_params;

enum { MODE_COLOR = 0, MODE_LUMINANCE, MODE_MEAN };
enum { SPACE_SRGB = 0, SPACE_LINEAR };

static const char *const mode_items[] = { "color", "luminance", "mean" };
static const char *const space_items[] = { "srgb", "linear" };

static const fx_param_def posterize_param_defs[] = {
    FX_P_ENUM(posterize_params, mode, "mode", MODE_COLOR, mode_items,
              "color: each of R, G, B quantised; luminance: gray from Rec.709 luminance, quantised; "
              "mean: gray from (R+G+B)/3, quantised"),
    FX_P_INT(posterize_params, levels, "levels", 4, 2, 256, 2, 16, "",
             "Number of levels (a ramp from 0 to white takes exactly this many values)"),
    FX_P_ENUM(posterize_params, space, "space", SPACE_SRGB, space_items,
              "Steps equal in sRGB-encoded values (even to the eye) or in linear values"),
    FX_P_FLOAT(posterize_params, white, "white", 1.0, 1e-6, 65504.0, 0.1, 16.0, "",
               "Linear value of the top level"),
    FX_P_FLOAT(posterize_params, dither, "dither", 0.0, 0.0, 1.0, 0.0, 1.0, "factor",
               "Ordered (8x8 Bayer) dither amplitude in bands: 0 hard bands, 1 full dither"),
    FX_P_BOOL(posterize_params, keep_hdr, "keep_hdr", 1,
              "Values above white pass unchanged (highlights stay for bloom); off: they take the top level"),
    FX_P_FLOAT(posterize_params, mix, "mix", 1.0, 0.0, 1.0, 0.0, 1.0, "factor",
               "Blend between the original (0, the identity) and the posterized colour (1)"),
};

typedef struct post_job {
    const fx_effect_run *run;
    const posterize_params *p;
    fx_levels q;
} post_job;

static void post_rows(void *user, int begin, int end)
{
    const post_job *j = user;
    const fx_effect_run *run = j->run;
    const int gray = j->p->mode == MODE_COLOR ? 0 : j->p->mode == MODE_LUMINANCE ? 1 : 2;
    /* fx_levels_rgba_row clamps every value it writes: the output is finite (OWN_FINITE) */
    for (int y = run->roi.y0 + begin; y < run->roi.y0 + end; y++)
        fx_levels_rgba_row(&j->q, run->src + (size_t)y * run->width * 4, run->dst + (size_t)y * run->width * 4,
                           run->roi.x0, run->roi.x1, y, gray, j->p->mix);
}

/* Zero strength is the identity: the stack skips the effect. */
static int posterize_identity(const void *params)
{
    const posterize_params *p = params;
    return !(p->mix > 0.0f);
}

static fx_result posterize_process(const fx_effect_run *run)
{
    const posterize_params *p = run->params;
    const fx_rect *roi = &run->roi;
    post_job *j = fx_mem_alloc(sizeof *j);
    if (!j)
        return fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", run->where);
    j->run = run;
    j->p = p;
    fx_levels_init(&j->q, p->levels, p->space == SPACE_SRGB, p->white, p->dither, p->keep_hdr);
    int rows = roi->y1 - roi->y0;
    fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), post_rows, j);
    fx_mem_free(j);
    return FX_OK;
}

const fx_effect_class fx_effect_posterize = {
    .name = "posterize",
    .doc = "Posterize: N levels per channel or of the gray (mean or luminance), sRGB or linear steps, ordered dither",
    .params_size = sizeof(posterize_params),
    .params = posterize_param_defs,
    .param_count = FX_COUNT_OF(posterize_param_defs),
    .presets = { NULL, NULL, NULL, NULL },
    .flags = FX_EFFECT_OWN_FINITE | FX_EFFECT_IN_PLACE,
    .passes = NULL,
    .needs_camera = NULL,
    .halo = NULL,
    .validate = NULL,
    .process = posterize_process,
    .identity = posterize_identity,
};
