/* color_matrix: a 4x4 colour matrix per pixel (grayscale, sepia or custom), mixed with
 * the original. Memory-bound: float arithmetic in a loop the compiler vectorises, with a
 * per-row check that redoes a row in double (clamped) if anything overflowed.
 * docs/effects/color_matrix.md. */
#include "core/effect.h"
#include "core/parallel.h"
#include "math/color.h"
#include "math/color_ops.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

typedef struct color_matrix_params {
    int op;
    float matrix[16];
    float mix;
} color_matrix_params;

enum { OP_GRAY_AVERAGE = 0, OP_GRAY_LUMINANCE, OP_SEPIA, OP_CUSTOM };

static const char *const op_items[] = { "grayscale_average", "grayscale_luminance", "sepia",
                                        "custom" };
static const float identity16[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };

static const fx_param_def color_matrix_param_defs[] = {
    FX_P_ENUM(color_matrix_params, op, "operator", OP_GRAY_LUMINANCE, op_items,
              "grayscale_average: (R+G+B)/3; grayscale_luminance: Rec.709 weights "
              "0.2126/0.7152/0.0722; sepia: the classic sepia matrix (rows 0.393 0.769 0.189 / "
              "0.349 0.686 0.168 / 0.272 0.534 0.131); custom: the matrix "
              "parameter. Named operators leave alpha untouched"),
    FX_P_FLOATS(color_matrix_params, matrix, "matrix", 16, identity16, -1000.0, 1000.0, "matrix4",
                "Row-major 4x4 matrix acting on (R,G,B,A) for operator custom (a 3x3 is accepted "
                "and embedded with alpha kept)"),
    FX_P_FLOAT(color_matrix_params, mix, "mix", 1.0, 0.0, 1.0, 0.0, 1.0, "factor",
               "Blend between the original (0: an exact copy) and the transformed colour (1): "
               "out = p + mix (M p - p)"),
};

/* The effective matrix of the params (row-major, on RGBA); named operators come from
 * math/color_ops.h (shared with ssr_mirror). */
static void matrix_of(const color_matrix_params *p, float m[16])
{
    switch (p->op) {
    case OP_GRAY_AVERAGE:
        fx_color_op_matrix(FX_COLOR_OP_GRAY_AVERAGE, m);
        break;
    case OP_GRAY_LUMINANCE:
        fx_color_op_matrix(FX_COLOR_OP_GRAY_LUMINANCE, m);
        break;
    case OP_SEPIA:
        fx_color_op_matrix(FX_COLOR_OP_SEPIA, m);
        break;
    case OP_CUSTOM:
    default:
        memcpy(m, p->matrix, sizeof identity16);
        break;
    }
}

typedef struct cm_job {
    const fx_effect_run *run;
    const float *src;
    float *dst;
    int width;
    fx_rect roi;
    float m[16];
    float mix;
    int keep_alpha;
} cm_job;

static inline float clamp_finite(double v)
{
    v = v > (double)FLT_MAX ? (double)FLT_MAX : v;
    v = v < -(double)FLT_MAX ? -(double)FLT_MAX : v;
    return (float)v;
}

/* One pixel is one 4-lane vector: out = c0*r + c1*g + c2*b + c3*a with the matrix's
 * columns, summed in the same order as the scalar form (so the bits are the same). */
typedef float cm_v4 __attribute__((vector_size(16)));

/* The slow path for a pixel where float overflowed: double arithmetic, clamped (a NaN
 * input stays NaN: the row's finish replaces it). */
static cm_v4 pixel_double(const cm_job *j, cm_v4 p)
{
    const float *m = j->m;
    cm_v4 o;
    for (int r = 0; r < 4; r++) {
        double v = (double)m[r * 4 + 0] * p[0] + (double)m[r * 4 + 1] * p[1] + (double)m[r * 4 + 2] * p[2] +
                   (double)m[r * 4 + 3] * p[3];
        if (j->mix != 1.0f)
            v = p[r] + (double)j->mix * (v - p[r]);
        o[r] = clamp_finite(v);
    }
    if (j->keep_alpha)
        o[3] = p[3];
    return o;
}

/* src and dst may be the same buffer (FX_EFFECT_IN_PLACE): each pixel is read, then
 * written, and the overflow path works from the pixel it read. */
static void cm_rows(void *user, int begin, int end)
{
    const cm_job *j = user;
    const float *m = j->m;
    const cm_v4 c0 = {m[0], m[4], m[8], m[12]}, c1 = {m[1], m[5], m[9], m[13]};
    const cm_v4 c2 = {m[2], m[6], m[10], m[14]}, c3 = {m[3], m[7], m[11], m[15]};
    const float mix = j->mix;
    const int keep_alpha = j->keep_alpha;
    const int n = j->roi.x1 - j->roi.x0;
    for (int y = j->roi.y0 + begin; y < j->roi.y0 + end; y++) {
        const float *s = j->src + ((size_t)y * j->width + j->roi.x0) * 4;
        float *d = j->dst + ((size_t)y * j->width + j->roi.x0) * 4;
        int slow = 0;
        for (int x = 0; x < n; x++) {
            cm_v4 p;
            memcpy(&p, s + 4 * x, sizeof p);
            cm_v4 t = c0 * p[0] + c1 * p[1] + c2 * p[2] + c3 * p[3];
            if (mix != 1.0f)
                t = p + mix * (t - p);
            if (keep_alpha)
                t[3] = p[3];
            /* |v| <= FLT_MAX is false for +-Inf and NaN */
            int ok = (fabsf(t[0]) <= FLT_MAX) & (fabsf(t[1]) <= FLT_MAX) & (fabsf(t[2]) <= FLT_MAX) &
                     (fabsf(t[3]) <= FLT_MAX);
            if (__builtin_expect(!ok, 0)) {
                t = pixel_double(j, p);
                slow = 1;
            }
            memcpy(d + 4 * x, &t, sizeof t);
        }
        if (slow)
            fx_effect_finish_row(j->run, d, (size_t)n * 4);
    }
}

/* Zero strength is the identity: the stack skips the effect. */
static int color_matrix_identity(const void *params)
{
    const color_matrix_params *p = params;
    return p->mix <= 0.0f;
}

static fx_result color_matrix_process(const fx_effect_run *run)
{
    const color_matrix_params *p = run->params;
    const fx_rect *roi = &run->roi;
    cm_job j;
    j.run = run;
    j.src = run->src;
    j.dst = run->dst;
    j.width = run->width;
    j.roi = *roi;
    matrix_of(p, j.m);
    j.mix = p->mix > 1.0f ? 1.0f : p->mix;
    j.keep_alpha = p->op != OP_CUSTOM;
    int rows = roi->y1 - roi->y0;
    fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), cm_rows, &j);
    return FX_OK;
}

static fx_result color_matrix_validate(const void *params, char *err, size_t err_size)
{
    const color_matrix_params *p = params;
    for (int i = 0; i < 16; i++)
        if (!isfinite(p->matrix[i])) {
            snprintf(err, err_size, "matrix[%d] is not finite", i);
            return FX_ERR_BAD_PARAM;
        }
    return FX_OK;
}

const fx_effect_class fx_effect_color_matrix = {
    .name = "color_matrix",
    .doc = "Colour matrix per pixel: grayscale (average or Rec.709 luminance), sepia or a custom 4x4",
    .params_size = sizeof(color_matrix_params),
    .params = color_matrix_param_defs,
    .param_count = FX_COUNT_OF(color_matrix_param_defs),
    .presets = { NULL, NULL, NULL, NULL },
    .flags = FX_EFFECT_OWN_FINITE | FX_EFFECT_IN_PLACE,
    .passes = NULL,
    .needs_camera = NULL,
    .halo = NULL,
    .validate = color_matrix_validate,
    .process = color_matrix_process,
    .identity = color_matrix_identity,
};
