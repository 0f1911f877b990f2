/* math/blur: kernels, the three algorithms against each other and against the sampled
 * Gaussian, borders, extremes, ROI and thread-count invariance (internal API). */
#include "testutil.h"

#include "core/internal.h"
#include "math/blur.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

static fx_blur_spec spec(double sigma, fx_blur_algorithm a, int passes)
{
    fx_blur_spec s = { sigma, a, passes };
    return s;
}

/* Max |y - ref| relative to ref's peak for an impulse in the middle of n samples. */
static double impulse_error(fx_context *ctx, double sigma, fx_blur_algorithm a, int passes)
{
    int n = 1001;
    float *x = calloc(n, sizeof(float)), *y = calloc(n, sizeof(float)), *r = calloc(n, sizeof(float));
    x[n / 2] = 1.0f;
    fx_blur_spec e = spec(sigma, FX_BLUR_EXACT, 3), s = spec(sigma, a, passes);
    fx_blur_line(ctx, x, r, n, 1, &e, "test");
    fx_blur_line(ctx, x, y, n, 1, &s, "test");
    double err = tu_max_abs_diff(y, r, n) / r[n / 2];
    free(x), free(y), free(r);
    return err;
}

static void test_taps(void)
{
    double taps[61];
    fx_gaussian_taps(3.0, 30, taps);
    double sum = 0;
    for (int i = 0; i < 61; i++)
        sum += taps[i];
    CHECK(fabs(sum - 1.0) < 1e-14);
    CHECK(taps[0] == taps[60] && taps[29] == taps[31]);
    CHECK(fx_gaussian_radius(2.0) == 10);
    CHECK(fx_gaussian_radius(0.01) >= 1);
    /* the extended box has exactly the asked variance */
    double vars[] = { 0.05, 0.3, 1.0, 2.7, 10.0, 123.4, 5000.0 };
    for (int k = 0; k < 7; k++) {
        int r;
        double alpha;
        fx_extended_box(vars[k], &r, &alpha);
        double num = 2.0 * alpha * (r + 1.0) * (r + 1.0);
        for (int i = 1; i <= r; i++)
            num += 2.0 * i * i;
        double var = num / (2.0 * r + 1.0 + 2.0 * alpha);
        CHECK(alpha >= 0 && alpha < 1);
        CHECK(fabs(var - vars[k]) < 1e-9 * vars[k]);
    }
}

static void test_impulse(fx_context *ctx)
{
    /* exact = the sampled, normalised Gaussian */
    double sigmas[] = { 0.7, 1.0, 3.0, 10.0 };
    for (int k = 0; k < 4; k++) {
        double s = sigmas[k];
        int n = 201, R = fx_gaussian_radius(s);
        float x[201] = { 0 }, y[201];
        x[100] = 1.0f;
        fx_blur_spec e = spec(s, FX_BLUR_EXACT, 3);
        CHECK_OK(ctx, fx_blur_line(ctx, x, y, n, 1, &e, "test"));
        double *taps = malloc((2 * R + 1) * sizeof(double));
        fx_gaussian_taps(s, R, taps);
        double err = 0;
        for (int i = 0; i < n; i++) {
            int d = i - 100;
            double want = abs(d) <= R ? taps[d + R] : 0.0;
            err = fmax(err, fabs(y[i] - want));
        }
        CHECK(err < 1e-6);
        free(taps);
    }
    /* documented bounds (docs/effects/gaussian_blur.md), relative to the peak; 70 and 90:
     * above FX_BLUR_FLOAT_MAX_SIGMA, the double kernels */
    double sig[] = { 2.0, 3.0, 8.5, 17.0, 50.0, 70.0, 90.0 };
    for (int k = 0; k < 7; k++) {
        double rec = impulse_error(ctx, sig[k], FX_BLUR_RECURSIVE, 3);
        double b3 = impulse_error(ctx, sig[k], FX_BLUR_BOX, 3);
        double b4 = impulse_error(ctx, sig[k], FX_BLUR_BOX, 4);
        double b6 = impulse_error(ctx, sig[k], FX_BLUR_BOX, 6);
        CHECK(rec < 3.5e-3);
        CHECK(b3 < 6.5e-2);
        CHECK(b4 < 4.0e-2);
        CHECK(b6 < 3.2e-2);
        if (!(rec < 3.5e-3 && b3 < 6.5e-2 && b4 < 4e-2 && b6 < 3.2e-2))
            fprintf(stderr, "sigma %g: recursive %.3g box3 %.3g box4 %.3g box6 %.3g\n", sig[k], rec, b3,
                    b4, b6);
    }
    /* below sigma 2 recursive is the exact FIR */
    CHECK(impulse_error(ctx, 1.5, FX_BLUR_RECURSIVE, 3) == 0.0);
}

static void test_borders_and_extremes(fx_context *ctx)
{
    /* ramp + step near the border: recursive (exact replicate conditions) stays close */
    int n = 300;
    float *x = malloc(n * sizeof(float)), *y = malloc(n * sizeof(float)), *r = malloc(n * sizeof(float));
    for (int i = 0; i < n; i++)
        x[i] = (float)i / n + (i < 7 ? 1.0f : 0.0f);
    fx_blur_spec e = spec(8.0, FX_BLUR_EXACT, 3), rc = spec(8.0, FX_BLUR_RECURSIVE, 3);
    fx_blur_line(ctx, x, r, n, 1, &e, "t");
    fx_blur_line(ctx, x, y, n, 1, &rc, "t");
    CHECK(tu_max_abs_diff(y, r, n) < 3e-3);
    /* constant line: every algorithm returns it (to rounding) */
    for (int i = 0; i < n; i++)
        x[i] = 0.37f;
    for (int a = 0; a < 3; a++) {
        fx_blur_spec s = spec(25.0, a, 4);
        fx_blur_line(ctx, x, y, n, 1, &s, "t");
        CHECK(tu_max_abs_diff(y, x, n) < 1e-6);
    }
    /* 1e38 spike: finite everywhere; box's periodic re-sum removes the rounding residue
     * once the spike has left the window (far samples exactly 0) */
    for (int i = 0; i < n; i++)
        x[i] = 0.0f;
    x[50] = 1e38f;
    x[51] = -3e38f;
    x[52] = 3e38f;
    for (int a = 0; a < 3; a++) {
        fx_blur_spec s = spec(3.0, a, 3);
        fx_blur_line(ctx, x, y, n, 1, &s, "t");
        CHECK(tu_all_finite(y, n));
        if (a != FX_BLUR_RECURSIVE)
            CHECK(y[n - 1] == 0.0f && y[200] == 0.0f);
    }
    /* all FLT_MAX: stays finite and == FLT_MAX-ish */
    for (int i = 0; i < n; i++)
        x[i] = FLT_MAX;
    for (int a = 0; a < 3; a++) {
        fx_blur_spec s = spec(40.0, a, 3);
        fx_blur_line(ctx, x, y, n, 1, &s, "t");
        CHECK(tu_all_finite(y, n));
        CHECK(y[n / 2] > 3.3e38f);
    }
    /* sigma below 0.2: exact copy */
    for (int i = 0; i < n; i++)
        x[i] = (float)sin(i * 0.37);
    fx_blur_spec id = spec(0.19, FX_BLUR_EXACT, 3);
    fx_blur_line(ctx, x, y, n, 1, &id, "t");
    CHECK(memcmp(x, y, n * sizeof(float)) == 0);
    free(x), free(y), free(r);
}

static float *pattern(int w, int h, int c, unsigned seed)
{
    float *p = malloc((size_t)w * h * c * sizeof(float));
    uint32_t s = seed * 2654435761u + 1;
    for (size_t i = 0; i < (size_t)w * h * c; i++) {
        s ^= s << 13, s ^= s >> 17, s ^= s << 5;
        p[i] = (float)(s & 0xffff) / 65535.0f;
    }
    return p;
}

/* Tiny and degenerate shapes, sigma 1000, the mean kept. */
static void test_images_extremes(fx_context *ctx2)
{
    /* tiny and degenerate shapes, every algorithm, channels 1..4 */
    int shapes[][2] = { { 1, 1 }, { 1, 37 }, { 37, 1 }, { 2, 3 }, { 64, 64 } };
    for (int k = 0; k < 5; k++)
        for (int c = 1; c <= 4; c++)
            for (int a = 0; a < 3; a++) {
                int w = shapes[k][0], h = shapes[k][1];
                float *src = malloc((size_t)w * h * c * sizeof(float));
                float *dst = malloc((size_t)w * h * c * sizeof(float));
                for (size_t i = 0; i < (size_t)w * h * c; i++)
                    src[i] = 0.25f;
                fx_blur_spec s = spec(5.0, a, 3);
                CHECK_OK(ctx2, fx_blur_image(ctx2, src, dst, w, h, c, &s, NULL, "t"));
                CHECK(tu_max_abs_diff(src, dst, (size_t)w * h * c) < 1e-6);
                free(src), free(dst);
            }
    /* sigma 1000 on 64x64: finite, flat, algorithms agree (replicate borders converge to
     * the mean of the four corners, see docs) */
    {
        int w = 64, h = 64;
        float *src = pattern(w, h, 4, 3), *out[3];
        for (int a = 0; a < 3; a++) {
            out[a] = malloc((size_t)w * h * 16);
            fx_blur_spec s = spec(1000.0, a, 3);
            CHECK_OK(ctx2, fx_blur_image(ctx2, src, out[a], w, h, 4, &s, NULL, "t"));
            CHECK(tu_all_finite(out[a], (size_t)w * h * 4));
            float lo = out[a][0], hi = out[a][0];
            for (size_t i = 0; i < (size_t)w * h * 4; i += 4)
                lo = fminf(lo, out[a][i]), hi = fmaxf(hi, out[a][i]);
            CHECK(hi - lo < 0.03f); /* ~ 64 / (1000 sqrt(2 pi)) of the corner spread */
        }
        CHECK(tu_max_abs_diff(out[0], out[2], (size_t)w * h * 4) < 2e-2); /* box's flatter shape */
        CHECK(tu_max_abs_diff(out[1], out[2], (size_t)w * h * 4) < 2e-4);
        double corners = (src[0] + src[(w - 1) * 4] + src[(size_t)(h - 1) * w * 4] +
                          src[((size_t)(h - 1) * w + w - 1) * 4]) / 4.0;
        CHECK(fabs(out[2][(32 * w + 32) * 4] - corners) < 0.02);
        for (int a = 0; a < 3; a++)
            free(out[a]);
        free(src);
    }
    /* mean preserved when the borders are flat (replicate adds nothing) */
    {
        int w = 160, h = 120;
        float *src = calloc((size_t)w * h, sizeof(float)), *dst = malloc((size_t)w * h * 4);
        float *p = pattern(40, 30, 1, 9);
        for (int y = 0; y < 30; y++)
            for (int x = 0; x < 40; x++)
                src[(y + 45) * w + x + 60] = p[y * 40 + x];
        double s0 = 0;
        for (int i = 0; i < w * h; i++)
            s0 += src[i];
        for (int a = 0; a < 3; a++) {
            fx_blur_spec s = spec(6.0, a, 4);
            fx_blur_image(ctx2, src, dst, w, h, 1, &s, NULL, "t");
            double s1 = 0;
            for (int i = 0; i < w * h; i++)
                s1 += dst[i];
            CHECK(fabs(s1 - s0) < 1e-5 * s0);
        }
        free(src), free(dst), free(p);
    }
}

/* The thread count does not change a bit; a ROI equals the full result there; in place
 * equals out of place; the fast kernels give the lane kernels' bits. */
static void test_images_threads_roi(fx_context *ctx1, fx_context *ctx2)
{
    {
        int w = 203, h = 157;
        float *src = pattern(w, h, 4, 5);
        size_t n = (size_t)w * h * 4;
        float *a1 = malloc(n * 4), *a2 = malloc(n * 4), *ro = malloc(n * 4);
        double sigmas[] = { 0.5, 2.5, 9.0, 40.0 };
        for (int a = 0; a < 3; a++)
            for (int k = 0; k < 4; k++) {
                fx_blur_spec s = spec(sigmas[k], a, 3);
                fx_blur_image(ctx1, src, a1, w, h, 4, &s, NULL, "t");
                fx_blur_image(ctx2, src, a2, w, h, 4, &s, NULL, "t");
                CHECK(memcmp(a1, a2, n * sizeof(float)) == 0);
                /* roi: only roi written, and equal to the full blur there */
                for (size_t i = 0; i < n; i++)
                    ro[i] = -7.0f;
                fx_rect roi = { 40, 30, 111, 77 };
                fx_blur_image(ctx2, src, ro, w, h, 4, &s, &roi, "t");
                double err = 0;
                int outside_ok = 1;
                for (int y = 0; y < h; y++)
                    for (int x = 0; x < w; x++)
                        for (int c = 0; c < 4; c++) {
                            size_t i = ((size_t)y * w + x) * 4 + c;
                            if (x >= roi.x0 && x < roi.x1 && y >= roi.y0 && y < roi.y1)
                                err = fmax(err, fabs(ro[i] - a1[i]));
                            else if (ro[i] != -7.0f)
                                outside_ok = 0;
                        }
                CHECK(outside_ok);
                CHECK(err < (a == FX_BLUR_EXACT ? 1e-7 : 1e-5));
            }
        /* in place (src == dst): the fast row-wise kernels of box and recursive (RGBA,
         * full width: the vertical result goes straight to dst) and their ROI path; 1-3
         * channels take the lane kernels horizontally */
        const fx_blur_algorithm ip_alg[] = { FX_BLUR_BOX, FX_BLUR_BOX, FX_BLUR_RECURSIVE,
                                             FX_BLUR_RECURSIVE };
        const double ip_sigma[] = { 4.0, 30.0, 4.0, 30.0 };
        const fx_rect ip_roi[] = { { 0, 0, w, h }, { 0, 30, w, 77 }, { 40, 30, 111, 77 } };
        for (int k = 0; k < 4; k++)
            for (int ri = 0; ri < 3; ri++)
                for (int c = 1; c <= 4; c += 3) {
                    fx_blur_spec s = spec(ip_sigma[k], ip_alg[k], 3 + k % 2);
                    size_t m = (size_t)w * h * c;
                    memcpy(a1, src, m * sizeof(float));
                    fx_blur_image(ctx2, src, a1, w, h, c, &s, &ip_roi[ri], "t");
                    memcpy(a2, src, m * sizeof(float));
                    CHECK_OK(ctx2, fx_blur_image(ctx2, a2, a2, w, h, c, &s, &ip_roi[ri], "t"));
                    CHECK(memcmp(a1, a2, m * sizeof(float)) == 0);
                }
        /* the fast kernels give the lane kernels' bits: an RGBA row (horizontal, 4 rows at
         * once) and a 1-channel column (vertical strip of one lane) against fx_blur_line */
        for (int k = 0; k < 4; k++) {
            fx_blur_spec s = spec(ip_sigma[k], ip_alg[k], 3 + k % 2);
            float *line = malloc((size_t)w * 4 * sizeof(float));
            fx_blur_image(ctx2, src, a1, w, 1, 4, &s, NULL, "t");
            for (int c = 0; c < 4; c++)
                fx_blur_line(ctx2, src + c, line + c, w, 4, &s, "t");
            CHECK(memcmp(a1, line, (size_t)w * 4 * sizeof(float)) == 0);
            fx_blur_image(ctx2, src, a1, 1, h, 1, &s, NULL, "t");
            fx_blur_line(ctx2, src, line, h, 1, &s, "t");
            CHECK(memcmp(a1, line, (size_t)h * sizeof(float)) == 0);
            free(line);
        }
        free(src), free(a1), free(a2), free(ro);
    }
}

static void test_images(fx_context *ctx1, fx_context *ctx2)
{
    test_images_extremes(ctx2);
    test_images_threads_roi(ctx1, ctx2);
}

/* The float recursive kernels: a strip holding a huge or non-finite value goes to the double
 * kernels (and so does the horizontal pass); thread counts agree bit for bit. */
static void test_float_fallback(fx_context *ctx1, fx_context *ctx2)
{
    int w = 150, h = 97;
    size_t n = (size_t)w * h * 4;
    float *src = pattern(w, h, 4, 21), *a1 = malloc(n * 4), *a2 = malloc(n * 4);
    fx_blur_spec s = spec(9.0, FX_BLUR_RECURSIVE, 3);
    int fin = -1;
    CHECK_OK(ctx2, fx_blur_image_finite(ctx2, src, a1, w, h, 4, &s, NULL, "t", &fin));
    CHECK(fin == 1);
    fx_blur_spec big = spec(FX_BLUR_FLOAT_MAX_SIGMA * 1.5, FX_BLUR_RECURSIVE, 3);
    CHECK_OK(ctx2, fx_blur_image_finite(ctx2, src, a1, w, h, 4, &big, NULL, "t", &fin));
    CHECK(fin == 0 && tu_all_finite(a1, n));
    const float bad[] = { 2e30f, -3e38f, FLT_MAX, NAN, INFINITY };
    for (int k = 0; k < 5; k++) {
        float *in = pattern(w, h, 4, 22);
        in[((size_t)40 * w + 77) * 4 + 1] = bad[k];
        CHECK_OK(ctx1, fx_blur_image_finite(ctx1, in, a1, w, h, 4, &s, NULL, "t", &fin));
        CHECK(fin == 0);
        CHECK_OK(ctx2, fx_blur_image(ctx2, in, a2, w, h, 4, &s, NULL, "t"));
        CHECK(memcmp(a1, a2, n * sizeof(float)) == 0);
        if (k < 3)
            CHECK(tu_all_finite(a1, n));
        free(in);
    }
    free(src), free(a1), free(a2);
}

static void test_convolve(fx_context *ctx)
{
    double k[9] = { 0, 0, 0, 0, 0, 1, 0, 0, 0 }; /* shift left by one, replicate at the edge */
    float src[5] = { 1, 2, 3, 4, 5 }, dst[5];
    CHECK_OK(ctx, fx_convolve_2d(ctx, src, dst, 5, 1, 1, k, 3, NULL, "t"));
    CHECK(dst[0] == 2 && dst[3] == 5 && dst[4] == 5);
    CHECK(fx_convolve_2d(ctx, src, src, 5, 1, 1, k, 3, NULL, "t") == FX_ERR_INVALID_ARGUMENT);
    CHECK(fx_convolve_2d(ctx, src, dst, 5, 1, 1, k, 4, NULL, "t") == FX_ERR_INVALID_ARGUMENT);
}

/* The double recursive kernels of the image path (sigma above FX_BLUR_FLOAT_MAX_SIGMA):
 * columns holding a ramp with a step near either end stay within 3e-3 of the exact FIR, as
 * fx_blur_line does (both borders: the causal and the anticausal pass's start). */
static void test_image_double_borders(fx_context *ctx)
{
    const int w = 5, h = 900;
    const double sg = FX_BLUR_FLOAT_MAX_SIGMA + 6.0;
    size_t n = (size_t)w * h * 4;
    float *src = malloc(n * sizeof(float)), *a = malloc(n * sizeof(float)), *b = malloc(n * sizeof(float));
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            for (int c = 0; c < 4; c++)
                src[((size_t)y * w + x) * 4 + c] =
                    (float)y / h + (y < 7 || y >= h - 9 ? 1.0f : 0.0f) + 0.1f * (float)c;
    fx_blur_spec e = spec(sg, FX_BLUR_EXACT, 3), rc = spec(sg, FX_BLUR_RECURSIVE, 3);
    CHECK_OK(ctx, fx_blur_image(ctx, src, a, w, h, 4, &e, NULL, "t"));
    CHECK_OK(ctx, fx_blur_image(ctx, src, b, w, h, 4, &rc, NULL, "t"));
    CHECK(tu_max_abs_diff(a, b, n) < 3e-3);
    free(src), free(a), free(b);
}

int main(void)
{
    fx_context *c1 = NULL, *c2 = NULL;
    if (fx_context_new(&c1, 1) != FX_OK || fx_context_new(&c2, 2) != FX_OK)
        return 1;
    test_taps();
    test_impulse(c1);
    test_borders_and_extremes(c1);
    test_images(c1, c2);
    test_float_fallback(c1, c2);
    test_image_double_borders(c1);
    test_convolve(c1);
    fx_context_free(c1);
    fx_context_free(c2);
    return tu_finish("test_blur_math");
}
