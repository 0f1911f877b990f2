/* Depth edge kernel (the seed's §3.5 outline test): a 3x3 Sobel on planar depth,
 * normalised by the centre depth so the threshold is scale-free (a step of 10 % of the
 * distance is an edge near or far). Background depth counts as a very far surface.
 * Used by ssr_mirror's cel operator on the reflected image. Kept in its own file until
 * the shared edge/cel module of the stylization work (math/edge_ops) lands; then this
 * moves there. */
#ifndef LIBFX_MATH_DEPTH_EDGE_H
#define LIBFX_MATH_DEPTH_EDGE_H

#include <math.h>
#include <stddef.h>

/* Relative depth gradient |Sobel(d)| / (8 d) at (x, y), clamp-to-edge; finite. */
static inline float fx_depth_edge_strength(const float *depth, int w, int h, int x, int y, float bg)
{
    float d[3][3];
    for (int j = -1; j <= 1; j++)
        for (int i = -1; i <= 1; i++) {
            int xx = x + i < 0 ? 0 : x + i >= w ? w - 1 : x + i;
            int yy = y + j < 0 ? 0 : y + j >= h ? h - 1 : y + j;
            float v = depth[(size_t)yy * w + xx];
            d[j + 1][i + 1] = (v > 0.0f && v < bg) ? v : bg;
        }
    float gx = (d[0][2] + 2.0f * d[1][2] + d[2][2]) - (d[0][0] + 2.0f * d[1][0] + d[2][0]);
    float gy = (d[2][0] + 2.0f * d[2][1] + d[2][2]) - (d[0][0] + 2.0f * d[0][1] + d[0][2]);
    float c = d[1][1] > 1e-6f ? d[1][1] : 1e-6f;
    float g = sqrtf(gx * gx + gy * gy) / (8.0f * c);
    return isfinite(g) ? g : 0.0f;
}

#endif
