/* color_matrix: a 4x4 colour matrix per pixel (grayscale, sepia or custom), mixed with
 * the original. Memory-bound: eight pixels at a time as channel vectors (core/simd8.h), with
 * one finite test per eight pixels; a chunk that overflowed is redone pixel by pixel in double
 * (clamped).
 * docs/effects/color_matrix.md. */
#include "core/effect.h"
#include "core/parallel.h"
#include "math/color.h"
#include "math/color_ops.h"
#include "core/simd8.h"
#include "math/clones.h"

#include <float.h>
#include <math.h>
#include <stdint.h>
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

/* One pixel through the 4-lane form (the tail of a row, and any pixel of a chunk that
 * overflowed): returns 1 when it took the double path. */
static inline __attribute__((always_inline)) int cm_pixel(const cm_job *j, const cm_v4 c[4], const float *s,
                                                          float *d)
{
    cm_v4 p;
    memcpy(&p, s, sizeof p);
    cm_v4 t = c[0] * p[0] + c[1] * p[1] + c[2] * p[2] + c[3] * p[3];
    if (j->mix != 1.0f)
        t = p + j->mix * (t - p);
    if (j->keep_alpha)
        t[3] = p[3];
    /* |v| <= FLT_MAX is false for +-Inf and NaN */
    int ok = (fabsf(t[0]) <= FLT_MAX) & (fabsf(t[1]) <= FLT_MAX) & (fabsf(t[2]) <= FLT_MAX) &
             (fabsf(t[3]) <= FLT_MAX);
    if (__builtin_expect(!ok, 0))
        t = pixel_double(j, p);
    memcpy(d, &t, sizeof t);
    return !ok;
}

/* Eight pixels at a time as four channel vectors (core/simd8.h's transposes), in an AVX2
 * clone beside the baseline one (no FMA in either: the same bits). Each output channel is
 * m[r][0] R + m[r][1] G + m[r][2] B + m[r][3] A summed left to right, as cm_pixel's lanes
 * are, so both give the same bits. The finite check is one test per chunk; a chunk that
 * overflowed is redone pixel by pixel from the values still in registers. */

/* src and dst may be the same buffer (FX_EFFECT_IN_PLACE): each chunk is read, then
 * written, and the overflow path works from the pixels it read. */
FX_CLONES static void cm_rows(void *user, int begin, int end)
{
    const cm_job *j = user;
    const float *m = j->m;
    const cm_v4 c[4] = { {m[0], m[4], m[8], m[12]}, {m[1], m[5], m[9], m[13]},
                         {m[2], m[6], m[10], m[14]}, {m[3], m[7], m[11], m[15]} };
    v8f mm[16];
    for (int i = 0; i < 16; i++)
        mm[i] = S8(m[i]);
    const float mix = j->mix;
    const v8f mix8 = S8(mix), big = S8(FLT_MAX);
    const v8i abs_mask = { 0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff,
                           0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff };
    const int keep_alpha = j->keep_alpha, has_mix = mix != 1.0f;
    const int n = j->roi.x1 - j->roi.x0;
    for (int y = j->roi.y0 + begin; y < j->roi.y0 + end; y++) {
        const float *s = j->src + ((size_t)y * j->width + j->roi.x0) * 4;
        float *d = j->dst + ((size_t)y * j->width + j->roi.x0) * 4;
        int slow = 0, x = 0;
        for (; x + 8 <= n; x += 8) {
            v8f p[4], o[4];
            fx_load8x4(s + 4 * (size_t)x, p);
            for (int r = 0; r < 3; r++)
                o[r] = mm[r * 4] * p[0] + mm[r * 4 + 1] * p[1] + mm[r * 4 + 2] * p[2] + mm[r * 4 + 3] * p[3];
            if (keep_alpha)
                o[3] = p[3];
            else
                o[3] = mm[12] * p[0] + mm[13] * p[1] + mm[14] * p[2] + mm[15] * p[3];
            if (has_mix) {
                for (int r = 0; r < 3; r++)
                    o[r] = p[r] + mix8 * (o[r] - p[r]);
                if (!keep_alpha)
                    o[3] = p[3] + mix8 * (o[3] - p[3]);
            }
            /* |v| <= FLT_MAX is false for +-Inf and NaN */
            const v8i ok = ((v8f)((v8i)o[0] & abs_mask) <= big) & ((v8f)((v8i)o[1] & abs_mask) <= big) &
                           ((v8f)((v8i)o[2] & abs_mask) <= big) & ((v8f)((v8i)o[3] & abs_mask) <= big);
            fx_store8x4(d + 4 * (size_t)x, o);
            if (__builtin_expect(!fx_all8(ok), 0)) {
                for (int i = 0; i < 8; i++) {
                    const float px[4] = { p[0][i], p[1][i], p[2][i], p[3][i] };
                    slow |= cm_pixel(j, c, px, d + 4 * (size_t)(x + i));
                }
            }
        }
        for (; x < n; x++)
            slow |= cm_pixel(j, c, s + 4 * (size_t)x, d + 4 * (size_t)x);
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
