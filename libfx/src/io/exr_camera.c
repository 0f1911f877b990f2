/* fx_camera <-> the EXR header's worldToCamera / worldToNDC attributes (io/exr_camera.h). */
#include "io/exr_camera.h"

#include <math.h>
#include <string.h>

/* 4x4 inverse by Gauss-Jordan elimination with partial pivoting, in double: the
 * matrices hold translations of hundreds of units next to unit rotations. */
static int invert4(const double m[16], double inv[16])
{
    double a[4][8];
    for (int r = 0; r < 4; r++)
        for (int c = 0; c < 8; c++)
            a[r][c] = c < 4 ? m[r * 4 + c] : (c - 4 == r ? 1.0 : 0.0);
    for (int col = 0; col < 4; col++) {
        int piv = col;
        for (int r = col + 1; r < 4; r++)
            if (fabs(a[r][col]) > fabs(a[piv][col]))
                piv = r;
        if (!(fabs(a[piv][col]) > 1e-300))
            return 0;
        if (piv != col)
            for (int c = 0; c < 8; c++) {
                double t = a[col][c];
                a[col][c] = a[piv][c];
                a[piv][c] = t;
            }
        double d = a[col][col];
        for (int c = 0; c < 8; c++)
            a[col][c] /= d;
        for (int r = 0; r < 4; r++) {
            if (r == col)
                continue;
            double f = a[r][col];
            if (f != 0.0)
                for (int c = 0; c < 8; c++)
                    a[r][c] -= f * a[col][c];
        }
    }
    for (int r = 0; r < 4; r++)
        for (int c = 0; c < 4; c++)
            inv[r * 4 + c] = a[r][c + 4];
    return 1;
}

static void mul4(const double a[16], const double b[16], double out[16])
{
    for (int r = 0; r < 4; r++)
        for (int c = 0; c < 4; c++) {
            double s = 0;
            for (int k = 0; k < 4; k++)
                s += a[r * 4 + k] * b[k * 4 + c];
            out[r * 4 + c] = s;
        }
}

int fx_exr_camera_from_file(const float w2c_file[16], const float ndc_file[16], fx_camera *out)
{
    double w[16], n[16], winv[16], p[16];
    for (int r = 0; r < 4; r++)
        for (int c = 0; c < 4; c++) {
            w[r * 4 + c] = w2c_file[c * 4 + r]; /* transpose: row vectors -> column vectors */
            n[r * 4 + c] = ndc_file[c * 4 + r];
        }
    if (!invert4(w, winv))
        return 0;
    mul4(n, winv, p); /* worldToNDC = P * W  =>  P = worldToNDC * W^-1 */
    memset(out, 0, sizeof *out);
    out->size = sizeof *out;
    for (int i = 0; i < 16; i++) {
        out->world_to_camera[i] = (float)w[i];
        out->projection[i] = (float)p[i];
    }
    double m22 = p[10], m23 = p[11];
    out->orthographic = fabs(p[15] - 1.0) < 1e-6 && fabs(p[14]) < 1e-6;
    double n_, f_;
    if (out->orthographic) { /* m22 = -2/(f-n), m23 = -(f+n)/(f-n) */
        n_ = m22 != 0 ? (m23 + 1.0) / m22 : 0;
        f_ = m22 != 0 ? (m23 - 1.0) / m22 : 0;
    } else { /* m22 = -(f+n)/(f-n), m23 = -2fn/(f-n) */
        n_ = m22 != 1.0 ? m23 / (m22 - 1.0) : 0;
        f_ = m22 != -1.0 ? m23 / (m22 + 1.0) : 0;
    }
    out->clip_start = isfinite(n_) ? (float)n_ : 0.0f;
    out->clip_end = isfinite(f_) ? (float)f_ : 0.0f;
    return 1;
}

void fx_exr_camera_to_file(const fx_camera *cam, float w2c_file[16], float ndc_file[16])
{
    double w[16], p[16], n[16];
    for (int i = 0; i < 16; i++) {
        w[i] = cam->world_to_camera[i];
        p[i] = cam->projection[i];
    }
    mul4(p, w, n);
    for (int r = 0; r < 4; r++)
        for (int c = 0; c < 4; c++) {
            w2c_file[c * 4 + r] = (float)w[r * 4 + c];
            ndc_file[c * 4 + r] = (float)n[r * 4 + c];
        }
}
