/* color_matrix through the public API: the named operators' exact values, custom 4x4 and
 * 3x3, mix, alpha, overflow, mask, thread invariance. */
#include "fx_effect_test.h"

#include <float.h>
#include <math.h>

static float *run_on(fx_context *ctx, const float *px, int w, int h, const char *op,
                     const float *m, int mcount, double mix, const char *mask)
{
    fx_frame *f = et_frame(ctx, w, h, px);
    fx_stack *s = et_stack(ctx, "color_matrix");
    float *o = NULL;
    if (f && s && fx_stack_set_enum(s, 0, "operator", op) == FX_OK &&
        (!m || fx_stack_set_floats(s, 0, "matrix", m, mcount) == FX_OK) &&
        fx_stack_set_float(s, 0, "mix", mix) == FX_OK &&
        (!mask || fx_stack_set_mask_json(s, 0, mask) == FX_OK))
        o = et_run(ctx, s, f);
    else
        fprintf(stderr, "setup: %s\n", fx_context_error(ctx));
    fx_stack_free(s);
    fx_frame_free(f);
    return o;
}

static int near4(const float *o, float r, float g, float b, float a, float tol)
{
    return fabsf(o[0] - r) <= tol && fabsf(o[1] - g) <= tol && fabsf(o[2] - b) <= tol &&
           fabsf(o[3] - a) <= tol;
}

static void test_values(fx_context *ctx)
{
    const float red[4] = { 1, 0, 0, 0.5f };
    float *o = run_on(ctx, red, 1, 1, "sepia", NULL, 0, 1.0, NULL);
    CHECK(o && near4(o, 0.393f, 0.349f, 0.272f, 0.5f, 1e-7f));
    free(o);
    o = run_on(ctx, red, 1, 1, "grayscale_luminance", NULL, 0, 1.0, NULL);
    CHECK(o && near4(o, 0.2126f, 0.2126f, 0.2126f, 0.5f, 1e-7f));
    free(o);
    const float green[4] = { 0, 1, 0, 1 };
    o = run_on(ctx, green, 1, 1, "grayscale_luminance", NULL, 0, 1.0, NULL);
    CHECK(o && near4(o, 0.7152f, 0.7152f, 0.7152f, 1, 1e-7f));
    free(o);
    const float c3[4] = { 0.3f, 0.6f, 0.9f, 0.25f };
    o = run_on(ctx, c3, 1, 1, "grayscale_average", NULL, 0, 1.0, NULL);
    CHECK(o && near4(o, 0.6f, 0.6f, 0.6f, 0.25f, 1e-6f));
    free(o);
    /* mix 0.5: halfway between original and sepia */
    o = run_on(ctx, red, 1, 1, "sepia", NULL, 0, 0.5, NULL);
    CHECK(o && near4(o, 0.6965f, 0.1745f, 0.136f, 0.5f, 1e-6f));
    free(o);
    /* custom 4x4: swap R and B, alpha halved (custom acts on alpha too) */
    const float m4[16] = { 0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0.5f };
    o = run_on(ctx, c3, 1, 1, "custom", m4, 16, 1.0, NULL);
    CHECK(o && near4(o, 0.9f, 0.6f, 0.3f, 0.125f, 0)); 
    free(o);
    /* custom 3x3 (the recipe parser embeds it, alpha kept) */
    const float m3[9] = { 0, 0, 1, 0, 1, 0, 1, 0, 0 };
    o = run_on(ctx, c3, 1, 1, "custom", m3, 9, 1.0, NULL);
    CHECK(o && near4(o, 0.9f, 0.6f, 0.3f, 0.25f, 0));
    free(o);
}

static void test_properties(fx_context *ctx1, fx_context *ctx2)
{
    int w = 67, h = 45;
    fx_frame *f = tu_pattern_frame(ctx1, w, h, 5);
    size_t n = (size_t)w * h * 4;
    float *px = malloc(n * sizeof(float));
    memcpy(px, et_combined(f), n * sizeof(float));
    for (size_t i = 3; i < n; i += 4)
        px[i] = (float)(i % 17) / 17.0f;
    fx_frame_free(f);
    const char *ops[] = { "grayscale_average", "grayscale_luminance", "sepia", "custom" };
    const float m4[16] = { 0.5f, 0.2f, 0.1f, 0.3f, -1, 2, 0.5f, 0, 0.1f, 0.1f, 0.1f, 0, 0.2f, 0, 0, 0.9f };
    for (int k = 0; k < 4; k++) {
        /* mix 0: identity */
        float *o = run_on(ctx1, px, w, h, ops[k], m4, 16, 0.0, NULL);
        CHECK(o && memcmp(o, px, n * sizeof(float)) == 0);
        free(o);
        /* threads */
        float *a = run_on(ctx1, px, w, h, ops[k], m4, 16, 0.7, NULL);
        float *b = run_on(ctx2, px, w, h, ops[k], m4, 16, 0.7, NULL);
        CHECK(a && b && memcmp(a, b, n * sizeof(float)) == 0);
        /* named operators leave alpha untouched */
        if (k < 3 && a) {
            int kept = 1;
            for (size_t i = 3; i < n; i += 4)
                kept &= a[i] == px[i];
            CHECK(kept);
        }
        free(a);
        free(b);
        /* mask: outside bit-identical */
        o = run_on(ctx2, px, w, h, ops[k], m4, 16, 1.0, "{\"rect\": [5, 7, 20, 11]}");
        CHECK(o && et_outside_equal(o, px, w, h, 5, 7, 20, 11));
        CHECK(o && memcmp(o + ((size_t)10 * w + 10) * 4, px + ((size_t)10 * w + 10) * 4, 12) != 0);
        free(o);
    }
    /* overflow: huge values through a large custom matrix stay finite */
    for (size_t i = 0; i < n; i++)
        px[i] = (i % 3 == 0) ? FLT_MAX : (i % 3 == 1 ? -1e38f : 2e38f);
    const float big[16] = { 1000, 1000, 1000, 1000, -1000, 1000, -1000, 1000, 1, 1, 1, 1, 0, 0, 0, 1 };
    for (int k = 0; k < 4; k++) {
        fx_context_clear_warnings(ctx2);
        float *o = run_on(ctx2, px, w, h, ops[k], big, 16, 0.37, NULL);
        CHECK(o && tu_all_finite(o, n));
        CHECK(fx_context_warning_count(ctx2) == 0);
        free(o);
    }
    free(px);
    /* a non-finite matrix is refused, naming the parameter */
    fx_stack *s = et_stack(ctx1, "color_matrix");
    float bad[16] = { 0 };
    bad[5] = NAN;
    CHECK(fx_stack_set_floats(s, 0, "matrix", bad, 16) != FX_OK);
    CHECK_FAIL(ctx1, fx_stack_set_float(s, 0, "mix", 1.5), FX_ERR_BAD_PARAM, "mix");
    fx_stack_free(s);
}

/* A custom 4x4 over a row of 19 pixels (two 8-pixel vector chunks and a 3-pixel tail), mix 1
 * and 0.6: every channel, alpha too, is p + mix (M p - p) computed here in double. */
static void test_custom_row(fx_context *ctx)
{
    enum { W = 19 };
    float px[W * 4];
    for (int i = 0; i < W * 4; i++)
        px[i] = 0.05f + 0.9f * (float)((i * 7) % 23) / 23.0f;
    const float m[16] = { 0.5f, 0.2f, 0.1f, 0.3f, -1, 2, 0.5f, 0.25f, 0.1f, 0.3f, 0.7f, -0.2f, 0.2f, 0.4f, -0.3f, 0.9f };
    const double mixes[2] = { 1.0, 0.6 };
    for (int k = 0; k < 2; k++) {
        float *o = run_on(ctx, px, W, 1, "custom", m, 16, mixes[k], NULL);
        int ok = o != NULL;
        for (int x = 0; ok && x < W; x++)
            for (int r = 0; r < 4; r++) {
                const float *p = px + 4 * x;
                double v = 0;
                for (int c = 0; c < 4; c++)
                    v += (double)m[r * 4 + c] * p[c];
                v = p[r] + mixes[k] * (v - p[r]);
                ok &= fabs(o[4 * x + r] - v) <= 1e-6 * (1 + fabs(v));
            }
        CHECK(ok);
        free(o);
    }
}

/* Overflow: a channel past FLT_MAX goes through the double path: mixed there as everywhere
 * (R: 1e38 through x10 at mix 0.1 is 1e38 + 0.1 (1e39 - 1e38) = 1.9e38, finite), clamped to
 * +-FLT_MAX when even the mix overflows, and alpha's overflow caught like the colours'
 * (alone in its pixel, in a 1-pixel image and in a 9-pixel one). */
static void test_overflow_values(fx_context *ctx)
{
    const float diag10[16] = { 10, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
    const float r[4] = { 1e38f, 0.5f, 0.25f, 1 };
    float *o = run_on(ctx, r, 1, 1, "custom", diag10, 16, 0.1, NULL);
    CHECK(o && fabsf(o[0] - 1.9e38f) <= 1e-6f * 1.9e38f && o[1] == 0.5f && o[2] == 0.25f && o[3] == 1);
    free(o);
    o = run_on(ctx, r, 1, 1, "custom", diag10, 16, 1.0, NULL);
    CHECK(o && o[0] == FLT_MAX && o[1] == 0.5f);
    free(o);
    const float a10[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 10 };
    for (int w = 1; w <= 9; w += 8) {
        float px[9 * 4];
        for (int x = 0; x < w; x++) {
            px[4 * x] = 0.1f, px[4 * x + 1] = 0.2f, px[4 * x + 2] = 0.3f;
            px[4 * x + 3] = x == w - 1 ? 1e38f : 0.5f;
        }
        o = run_on(ctx, px, w, 1, "custom", a10, 16, 1.0, NULL);
        CHECK(o && o[4 * (w - 1) + 3] == FLT_MAX && o[4 * (w - 1)] == 0.1f && (w == 1 || o[3] == 5.0f));
        free(o);
    }
}

int main(void)
{
    fx_context *c1 = NULL, *c2 = NULL;
    if (fx_context_new(&c1, 1) != FX_OK || fx_context_new(&c2, 2) != FX_OK)
        return 1;
    test_values(c1);
    test_custom_row(c1);
    test_overflow_values(c1);
    test_properties(c1, c2);
    fx_context_free(c1);
    fx_context_free(c2);
    return tu_finish("test_color_matrix");
}
