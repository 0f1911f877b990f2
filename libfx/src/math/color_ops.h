/* Named colour operators as 4x4 matrices on (R, G, B, A), row-major, alpha kept: the
 * one copy shared by color_matrix (whole-pixel operator) and ssr_mirror (applied to
 * the reflection only). */
#ifndef LIBFX_MATH_COLOR_OPS_H
#define LIBFX_MATH_COLOR_OPS_H

#include "math/color.h"

#include <string.h>

typedef enum fx_color_op {
    FX_COLOR_OP_GRAY_AVERAGE = 0,   /* (R + G + B) / 3 */
    FX_COLOR_OP_GRAY_LUMINANCE = 1, /* Rec.709 weights */
    FX_COLOR_OP_SEPIA = 2           /* the classic sepia matrix */
} fx_color_op;

/* Fills m with the operator's matrix; an unknown op gives the identity. */
static inline void fx_color_op_matrix(int op, float m[16])
{
    static const float sepia[9] = { 0.393f, 0.769f, 0.189f, 0.349f, 0.686f,
                                    0.168f, 0.272f, 0.534f, 0.131f };
    memset(m, 0, 16 * sizeof(float));
    m[0] = m[5] = m[10] = m[15] = 1.0f;
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++) {
            switch (op) {
            case FX_COLOR_OP_GRAY_AVERAGE:
                m[r * 4 + c] = 1.0f / 3.0f;
                break;
            case FX_COLOR_OP_GRAY_LUMINANCE:
                m[r * 4 + c] = c == 0 ? FX_LUMA_R : c == 1 ? FX_LUMA_G : FX_LUMA_B;
                break;
            case FX_COLOR_OP_SEPIA:
                m[r * 4 + c] = sepia[r * 3 + c];
                break;
            default:
                break;
            }
        }
}

/* rgb' = M rgb (the 3x3 block; alpha is not touched). */
static inline void fx_color_op_apply3(const float m[16], const float in[3], float out[3])
{
    float r = in[0], g = in[1], b = in[2];
    out[0] = m[0] * r + m[1] * g + m[2] * b;
    out[1] = m[4] * r + m[5] * g + m[6] * b;
    out[2] = m[8] * r + m[9] * g + m[10] * b;
}

#endif
