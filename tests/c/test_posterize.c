/* posterize through the public API: a ramp takes exactly N levels (linear and sRGB steps,
 * the table path equal to the formula), gray modes, dither mean, HDR, identity, masks,
 * extremes, thread invariance. */
#include "fx_effect_test.h"

#include "math/levels.h"

#include <float.h>
#include <math.h>

static float *run_recipe(fx_context *ctx, const float *px, int w, int h, const char *params, const char *mask)
{
    return et_run_effect_px(ctx, "posterize", px, w, h, params, mask);
}

static float enc(double v) /* sRGB encode in double, for expectations */
{
    return (float)(v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1 / 2.4) - 0.055);
}
static double dec(double v)
{
    return v <= 0.04045 ? v / 12.92 : pow((v + 0.055) / 1.055, 2.4);
}

static int count_distinct(const float *o, int n, float *vals, int cap)
{
    int c = 0;
    for (int i = 0; i < n; i++) {
        int seen = 0;
        for (int k = 0; k < c; k++)
            seen |= vals[k] == o[4 * i];
        if (!seen && c < cap)
            vals[c++] = o[4 * i];
    }
    return c;
}

static void test_ramp(fx_context *ctx)
{
    const int w = 4096;
    float *px = malloc((size_t)w * 4 * sizeof(float));
    for (int x = 0; x < w; x++) {
        px[4 * x] = px[4 * x + 1] = px[4 * x + 2] = ((float)x + 0.5f) / (float)w;
        px[4 * x + 3] = 1;
    }
    for (int n = 2; n <= 16; n += 7) {
        char p[128];
        float vals[64];
        snprintf(p, sizeof p, "\"levels\":%d,\"space\":\"linear\"", n);
        float *o = run_recipe(ctx, px, w, 1, p, NULL);
        CHECK(o && count_distinct(o, w, vals, 64) == n);
        int ok = o != NULL;
        for (int x = 0; ok && x < w; x++) {
            int k = (int)floor(((x + 0.5) / w) * n);
            k = k > n - 1 ? n - 1 : k;
            ok &= fabsf(o[4 * x] - (float)k / (n - 1)) < 1e-6f && o[4 * x + 3] == 1.0f;
        }
        CHECK(ok);
        free(o);
        snprintf(p, sizeof p, "\"levels\":%d", n); /* sRGB steps (default) */
        o = run_recipe(ctx, px, w, 1, p, NULL);
        CHECK(o && count_distinct(o, w, vals, 64) == n);
        ok = o != NULL;
        int mism = 0;
        for (int x = 0; ok && x < w; x++) {
            double u = (x + 0.5) / w;
            double e = enc(u) * n;
            if (fabs(e - floor(e + 0.5)) < 1e-4)
                continue; /* on a band edge: either side is right */
            int k = (int)floor(e);
            k = k > n - 1 ? n - 1 : k;
            float want = (float)(dec((double)k / (n - 1)));
            if (fabsf(o[4 * x] - want) > 1e-6f)
                mism++;
        }
        CHECK(mism == 0);
        free(o);
    }
    free(px);
}

static void test_modes(fx_context *ctx)
{
    const float c[8] = { 1, 0, 0, 0.5f, 0.2f, 0.5f, 0.8f, 1 };
    float *o = run_recipe(ctx, c, 2, 1, "\"mode\":\"luminance\",\"levels\":2,\"space\":\"linear\"", NULL);
    /* red: luminance 0.2126 -> level 0; second: 0.1986*... -> gray 0.4... -> 0 */
    CHECK(o && o[0] == 0 && o[1] == 0 && o[2] == 0 && o[3] == 0.5f);
    free(o);
    o = run_recipe(ctx, c, 2, 1, "\"mode\":\"mean\",\"levels\":3,\"space\":\"linear\"", NULL);
    /* mean 1/3 -> band 1 -> 0.5; mean 0.5 -> band 1 -> 0.5 */
    CHECK(o && o[0] == 0.5f && o[1] == 0.5f && o[2] == 0.5f && o[4] == 0.5f && o[7] == 1);
    free(o);
    o = run_recipe(ctx, c, 2, 1, "\"levels\":2,\"space\":\"linear\"", NULL);
    CHECK(o && o[0] == 1 && o[1] == 0 && o[4] == 0 && o[5] == 1 && o[6] == 1);
    free(o);
    /* HDR: kept by default, clamped to the top level when asked */
    const float hdr[4] = { 5, 2, -1, 1 };
    o = run_recipe(ctx, hdr, 1, 1, "\"levels\":4", NULL);
    CHECK(o && o[0] == 5 && o[1] == 2 && o[2] == 0);
    free(o);
    o = run_recipe(ctx, hdr, 1, 1, "\"levels\":4,\"keep_hdr\":false", NULL);
    CHECK(o && o[0] == 1 && o[1] == 1 && o[2] == 0);
    free(o);
    o = run_recipe(ctx, hdr, 1, 1, "\"levels\":4,\"keep_hdr\":false,\"white\":10", NULL);
    CHECK(o && fabsf(o[0] - 10.0f * (float)dec(2.0 / 3)) < 1e-5f); /* 5/10 -> enc 0.735 -> band 2 of 0..3 */
    free(o);
    /* dither: mid-gray at 2 linear levels averages back to the gray over each 8x8 tile */
    float *px = malloc(16 * 16 * 4 * sizeof(float));
    for (int i = 0; i < 16 * 16 * 4; i++)
        px[i] = 0.5f;
    o = run_recipe(ctx, px, 16, 16, "\"levels\":2,\"space\":\"linear\",\"dither\":1", NULL);
    double sum = 0;
    int binary = o != NULL;
    for (int i = 0; o && i < 16 * 16; i++) {
        sum += o[4 * i];
        binary &= o[4 * i] == 0.0f || o[4 * i] == 1.0f;
    }
    CHECK(o && binary && sum == 128.0);
    free(o);
    o = run_recipe(ctx, px, 16, 16, "\"levels\":5,\"dither\":0.7", NULL); /* sRGB dither: finite */
    CHECK(o && tu_all_finite(o, 16 * 16 * 4));
    free(o);
    free(px);
}

static void test_properties(fx_context *c1, fx_context *c2)
{
    int w = 83, h = 47;
    fx_frame *f = tu_pattern_frame(c1, w, h, 9);
    size_t n = (size_t)w * h * 4;
    float *px = malloc(n * sizeof(float));
    memcpy(px, et_combined(f), n * sizeof(float));
    for (size_t i = 0; i < n; i += 4)
        px[i] *= 3.0f; /* some HDR */
    fx_frame_free(f);
    const char *ps[] = { "\"levels\":5", "\"levels\":3,\"mode\":\"luminance\",\"dither\":0.5",
                         "\"levels\":7,\"mode\":\"mean\",\"space\":\"linear\",\"mix\":0.4" };
    for (int k = 0; k < 3; k++) {
        float *a = run_recipe(c1, px, w, h, ps[k], NULL), *b = run_recipe(c2, px, w, h, ps[k], NULL);
        CHECK(a && b && memcmp(a, b, n * sizeof(float)) == 0 && memcmp(a, px, n * sizeof(float)) != 0);
        float *m = run_recipe(c2, px, w, h, ps[k], "{\"rect\":[5,6,20,11]}");
        CHECK(m && et_outside_equal(m, px, w, h, 5, 6, 20, 11));
        int inside = m && a;
        for (int y = 6; inside && y < 17; y++)
            inside &= memcmp(m + ((size_t)y * w + 5) * 4, a + ((size_t)y * w + 5) * 4, 20 * 16) == 0;
        CHECK(inside);
        free(a);
        free(b);
        free(m);
    }
    float *o = run_recipe(c1, px, w, h, "\"levels\":4,\"mix\":0", NULL);
    CHECK(o && memcmp(o, px, n * sizeof(float)) == 0);
    free(o);
    free(px);
}

static void test_extremes(fx_context *ctx)
{
    const float bad[] = { NAN, INFINITY, -INFINITY, 1e38f, -1e38f, 1e-40f, 0.0f, FLT_MAX };
    float px[8 * 4];
    for (int i = 0; i < 32; i++)
        px[i] = bad[(i * 3) % 8];
    const char *ps[] = { "\"levels\":4", "\"levels\":256,\"mode\":\"luminance\"", "\"levels\":2,\"mode\":\"mean\",\"dither\":1",
                         "\"levels\":4,\"keep_hdr\":false,\"mix\":0.5", "\"levels\":9,\"white\":65504" };
    for (int k = 0; k < 5; k++) {
        float *o = run_recipe(ctx, px, 8, 1, ps[k], NULL);
        CHECK(o && tu_all_finite(o, 32));
        free(o);
        o = run_recipe(ctx, px, 1, 1, ps[k], NULL);
        CHECK(o && tu_all_finite(o, 4));
        free(o);
    }
}

/* The value of level k of n written out from the sRGB standard (IEC 61966-2-1's decoding,
 * white 1) or linear steps: not the library's table. */
static double level_value(int k, int n, int srgb)
{
    const double e = (double)k / (n - 1);
    if (!srgb)
        return e;
    return e <= 0.04045 ? e / 12.92 : pow((e + 0.055) / 1.055, 2.4);
}

/* The threshold quantiser (SIMD chain for N <= 16, binary search above, 2-pixel and
 * 1-pixel paths) against the formula written out here in double: band k = floor(enc(u) N
 * + dither d) clamped to [0, N - 1], value level_value(k), u >= 1 kept (keep_hdr), u <= 0
 * level 0. Equal to the float of that value (within 2 ulp) except within 1e-6 of a band
 * edge, for every Bayer phase: the row kernel, fx_levels_apply and the double-precision
 * fx_levels_apply_reference. */
static void test_quantiser_exact(void)
{
    const int ns[] = { 2, 3, 4, 6, 16, 17, 64, 256 };
    const float dith[] = { 0.0f, 0.7f, 1.0f };
    fx_levels *q = malloc(sizeof *q);
    enum { W = 67 };
    float *src = malloc(W * 4 * sizeof(float)), *dst = malloc(W * 4 * sizeof(float));
    unsigned seed = 12345;
    int bad = 0, checked = 0;
    for (int in = 0; in < 8; in++)
        for (int sp = 0; sp < 2; sp++)
            for (int di = 0; di < 3; di++) {
                int n = ns[in];
                fx_levels_init(q, n, sp == 0, 1.0f, dith[di], 1);
                for (int y = 0; y < 8; y++)
                    for (int rep = 0; rep < 30; rep++) {
                        for (int i = 0; i < W * 4; i++) {
                            seed = seed * 1664525u + 1013904223u;
                            src[i] = (float)(seed >> 8) * (1.0f / 16777216.0f) * 1.1f;
                        }
                        fx_levels_rgba_row(q, src, dst, 0, W, y, 0, 1.0f);
                        for (int x = 0; x < W; x++)
                            for (int c = 0; c < 3; c++) {
                                float v = src[4 * x + c];
                                double e = (sp == 0 ? (double)(v <= 0.0031308f ? 12.92 * v
                                                                                : 1.055 * pow(v, 1 / 2.4) - 0.055)
                                                    : (double)v) * n +
                                           (di ? (double)dith[di] * fx_bayer8(x, y) : 0.0);
                                if (fabs(e - floor(e + 0.5)) < 1e-6 * n)
                                    continue;
                                checked++;
                                const double kf = floor(e);
                                const int k = kf < 0.0 ? 0 : kf > n - 1 ? n - 1 : (int)kf;
                                const double want = v >= 1.0f ? (double)v : v <= 0.0f ? 0.0 : level_value(k, n, sp == 0);
                                const double tol = 2.0 * FLT_EPSILON * want;
                                bad += !(fabs(dst[4 * x + c] - want) <= tol) ||
                                       !(fabs(fx_levels_apply(q, v, x, y) - want) <= tol) ||
                                       !(fabs(fx_levels_apply_reference(q, v, x, y) - want) <= tol);
                            }
                    }
            }
    CHECK(bad == 0 && checked > 900000);
    if (bad)
        fprintf(stderr, "quantiser: %d of %d differ from the formula\n", bad, checked);
    free(q);
    free(src);
    free(dst);
}

/* The gray modes on coloured pixels, in the 2-pixel vectors and the 1-pixel tail (width 5)
 * and above 16 levels (every pixel per pixel): gray = (R + G + B) / 3 or Rec.709 luminance,
 * linear steps: level floor(gray N) of N, value k / (N - 1), alpha kept. */
static void test_gray_modes_paths(fx_context *ctx)
{
    enum { W = 5 };
    const float px[W * 4] = { 0.9f, 0.1f, 0.2f, 1, 0.05f, 0.7f, 0.3f, 0.5f, 0.3f, 0.2f, 0.95f, 1,
                              0.6f, 0.6f, 0.1f, 0.25f, 0.15f, 0.02f, 0.8f, 1 };
    const int ns[2] = { 3, 17 };
    for (int m = 0; m < 2; m++)
        for (int k = 0; k < 2; k++) {
            char p[128];
            snprintf(p, sizeof p, "\"mode\":\"%s\",\"levels\":%d,\"space\":\"linear\"", m ? "luminance" : "mean", ns[k]);
            float *o = run_recipe(ctx, px, W, 1, p, NULL);
            int ok = o != NULL, checked = 0;
            for (int x = 0; ok && x < W; x++) {
                const float *c = px + 4 * x;
                const double g = m ? 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2] : (c[0] + c[1] + c[2]) / 3.0;
                const double e = g * ns[k];
                if (fabs(e - floor(e + 0.5)) < 1e-4)
                    continue; /* on a band edge */
                const double want = floor(e) / (ns[k] - 1);
                for (int ch = 0; ch < 3; ch++)
                    ok &= fabs(o[4 * x + ch] - want) < 1e-6;
                ok &= o[4 * x + 3] == c[3];
                checked++;
            }
            CHECK(ok && checked >= 4);
            free(o);
        }
}

int main(void)
{
    test_quantiser_exact();
    fx_context *c1 = NULL, *c2 = NULL;
    fx_context_new(&c1, 1);
    fx_context_new(&c2, 2);
    test_ramp(c1);
    test_modes(c1);
    test_gray_modes_paths(c1);
    test_properties(c1, c2);
    test_extremes(c1);
    fx_context_free(c1);
    fx_context_free(c2);
    return tu_finish("test_posterize");
}
