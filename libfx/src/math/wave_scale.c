/* Dominant wavelength of a water surface from its normals (wave_scale.h). */
#include "math/wave_scale.h"

#include <math.h>
#include <stddef.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

static int slope_at(const float *normal, int nc, size_t i, double *sx, double *sy)
{
    const float *n = normal + i * (size_t)nc;
    double nz = n[2];
    if (!(nz > 0.05) || !isfinite(n[0]) || !isfinite(n[1]) || !(nz < 2.0))
        return 0; /* vertical or downward: not a wave's normal */
    *sx = -n[0] / nz;
    *sy = -n[1] / nz;
    return 1;
}

int fx_wave_length(const float *normal, int nc, const float *xy, const unsigned char *valid, int w, int h,
                   double *lambda)
{
    if (!normal || !xy || nc < 3 || w < 2 || h < 2 || !lambda)
        return -1;
    /* m0: the slope's variance about its mean */
    double s1x = 0.0, s1y = 0.0, s2 = 0.0;
    size_t n0 = 0;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            double sx, sy;
            if ((valid && !valid[i]) || !slope_at(normal, nc, i, &sx, &sy))
                continue;
            s1x += sx;
            s1y += sy;
            s2 += sx * sx + sy * sy;
            n0++;
        }
    if (n0 < 16)
        return -1;
    double m0 = s2 / n0 - (s1x / n0) * (s1x / n0) - (s1y / n0) * (s1y / n0);
    /* m2: along x, then along y */
    double m2 = 0.0;
    for (int axis = 0; axis < 2; axis++) {
        double acc = 0.0;
        size_t cnt = 0;
        for (int y = 0; y + axis < h; y++)
            for (int x = 0; x + (1 - axis) < w; x++) {
                size_t i = (size_t)y * w + x, k = axis ? i + (size_t)w : i + 1;
                double ax, ay, bx, by;
                if ((valid && (!valid[i] || !valid[k])) || !slope_at(normal, nc, i, &ax, &ay) ||
                    !slope_at(normal, nc, k, &bx, &by))
                    continue;
                double dx = (double)xy[2 * k] - xy[2 * i], dy = (double)xy[2 * k + 1] - xy[2 * i + 1];
                double l2 = dx * dx + dy * dy;
                if (!(l2 > 0.0) || !isfinite(l2))
                    continue;
                acc += ((bx - ax) * (bx - ax) + (by - ay) * (by - ay)) / l2;
                cnt++;
            }
        if (cnt < 16)
            return -1;
        m2 += acc / cnt;
    }
    if (!(m0 > 1e-12) || !(m2 > 0.0) || !isfinite(m0) || !isfinite(m2))
        return -1;
    double l = 2.0 * M_PI * sqrt(m0 / m2);
    if (!isfinite(l) || !(l > 0.0))
        return -1;
    *lambda = l;
    return 0;
}
