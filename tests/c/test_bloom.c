/* bloom through the public API: black stays black, a constant image gains exactly
 * intensity x its bright pass, energy added is bounded by intensity, the seed's pass and the
 * soft knee values, threshold 0 / luminance 0, huge and zero radii, 1x1, NaN/Inf/1e38,
 * identity, masks, thread invariance. */
#include "fx_effect_test.h"

#include <float.h>
#include <math.h>

static float *run_px(fx_context *ctx, const float *px, int w, int h, const char *params, const char *mask)
{
    return et_run_effect_px(ctx, "bloom", px, w, h, params, mask);
}

static float *filled(int w, int h, float r, float g, float b, float a)
{
    float *px = malloc((size_t)w * h * 4 * sizeof(float));
    for (int i = 0; i < w * h; i++) {
        px[4 * i] = r;
        px[4 * i + 1] = g;
        px[4 * i + 2] = b;
        px[4 * i + 3] = a;
    }
    return px;
}

static void test_energy(fx_context *ctx)
{
    const int w = 64, h = 48;
    float *px = filled(w, h, 0, 0, 0, 1);
    const char *ps[] = { "", "\"mode\":\"seed\"", "\"threshold\":0", "\"mode\":\"seed\",\"threshold\":0",
                         "\"composite\":\"screen\",\"radius\":1000" };
    for (int k = 0; k < 5; k++) {
        float *o = run_px(ctx, px, w, h, ps[k], NULL);
        CHECK(o && memcmp(o, px, (size_t)w * h * 16) == 0); /* black stays black */
        free(o);
    }
    free(px);
    /* constant 2.0 with threshold 1, knee 0: bright pass (2-1)/2 x 2 = 1; glow = intensity */
    px = filled(w, h, 2, 2, 2, 1);
    float *o = run_px(ctx, px, w, h, "\"knee\":0,\"intensity\":0.5", NULL);
    int ok = o != NULL;
    for (int i = 0; ok && i < w * h; i++)
        ok &= fabsf(o[4 * i] - 2.5f) < 1e-4f && o[4 * i + 3] == 1.0f;
    CHECK(ok);
    free(o);
    /* soft knee: b = threshold -> (k^2/4k) / b with k = t * knee */
    float one[4] = { 1, 1, 1, 1 };
    o = run_px(ctx, one, 1, 1, "\"knee\":0.5,\"intensity\":1,\"radius\":0", NULL);
    CHECK(o && fabsf(o[0] - (1.0f + 0.125f)) < 1e-4f);
    free(o);
    /* seed: middle grey 0.18 at scene luminance 0.18 (exposure 1), white 1: x = 2(1 + 2) - 0.5 = 5.5 -> 5.5/6.5 */
    float two[4] = { 2, 2, 2, 1 };
    o = run_px(ctx, two, 1, 1, "\"mode\":\"seed\",\"scene_luminance\":0.18,\"intensity\":1,\"radius\":0", NULL);
    CHECK(o && fabsf(o[0] - (2.0f + 5.5f / 6.5f)) < 1e-5f);
    free(o);
    /* measured scene luminance: a constant image's log-average is itself */
    o = run_px(ctx, two, 1, 1, "\"mode\":\"seed\",\"middle_grey\":2,\"intensity\":1,\"radius\":0", NULL);
    CHECK(o && fabsf(o[0] - (2.0f + 5.5f / 6.5f)) < 1e-4f);
    free(o);
    /* measured scene luminance of coloured pixels: the log-average of Rec.709 luminance
     * (0.2126 R + 0.7152 G + 0.0722 B) written out here; the same as giving that value */
    const float cols[12] = { 0.5f, 1, 4, 1, 2, 0.25f, 1, 1, 1, 1, 8, 1 };
    double lsum = 0;
    for (int i = 0; i < 3; i++)
        lsum += log(1e-6 + 0.2126 * cols[4 * i] + 0.7152 * cols[4 * i + 1] + 0.0722 * cols[4 * i + 2]);
    char given[160];
    snprintf(given, sizeof given, "\"mode\":\"seed\",\"middle_grey\":1,\"intensity\":1,\"radius\":0,\"scene_luminance\":%.9g",
             exp(lsum / 3) - 1e-6);
    float *om = run_px(ctx, cols, 3, 1, "\"mode\":\"seed\",\"middle_grey\":1,\"intensity\":1,\"radius\":0", NULL);
    float *og = run_px(ctx, cols, 3, 1, given, NULL);
    CHECK(om && og && tu_max_abs_diff(om, og, 12) < 1e-5 && tu_max_abs_diff(om, cols, 12) > 0.1);
    free(om);
    free(og);
    /* screen: white pixels gain nothing; the glow adds at most glow x (1 - colour) */
    o = run_px(ctx, px, w, h, "\"composite\":\"screen\"", NULL);
    CHECK(o && o[0] == 2.0f);
    free(o);
    free(px);
    /* energy: a bright spot; total added <= intensity x total of the bright pass <= intensity x total */
    px = filled(w, h, 0.1f, 0.1f, 0.1f, 1);
    for (int y = 20; y < 26; y++)
        for (int x = 30; x < 36; x++)
            px[(y * w + x) * 4] = px[(y * w + x) * 4 + 1] = px[(y * w + x) * 4 + 2] = 50.0f;
    double total = 0, bright = 0;
    for (int i = 0; i < w * h * 4; i++)
        if (i % 4 != 3) {
            total += px[i];
            bright += px[i] > 1 ? px[i] - 1 : 0; /* knee 0: (b - t) per channel for gray */
        }
    for (int r = 2; r <= 64; r *= 4) {
        char p[128];
        snprintf(p, sizeof p, "\"knee\":0,\"intensity\":0.8,\"radius\":%d", r);
        o = run_px(ctx, px, w, h, p, NULL);
        double added = 0;
        for (int i = 0; o && i < w * h * 4; i++)
            if (i % 4 != 3)
                added += (double)o[i] - px[i];
        /* bounded by intensity x bright pass (borders and odd level sizes lose a little) */
        CHECK(o && added >= 0.85 * 0.8 * bright && added <= 1.001 * 0.8 * bright && added <= 0.8 * total);
        free(o);
    }
    free(px);
}

static void test_properties(fx_context *c1, fx_context *c2)
{
    int w = 90, h = 61;
    fx_frame *f = tu_pattern_frame(c1, w, h, 7);
    size_t n = (size_t)w * h * 4;
    float *px = malloc(n * sizeof(float));
    memcpy(px, et_combined(f), n * sizeof(float));
    for (size_t i = 0; i < n; i += 4)
        px[i] *= 4.0f;
    fx_frame_free(f);
    const char *ps[] = { "\"threshold\":0.8", "\"mode\":\"seed\",\"radius\":300", "\"composite\":\"screen\",\"radius\":7",
                         "\"threshold\":0.8,\"fine_level\":\"fast\"", "\"threshold\":0.8,\"fine_level\":\"coarse\"",
                         "\"composite\":\"screen\",\"fine_level\":\"coarse\",\"radius\":5" };
    for (int k = 0; k < 6; k++) {
        float *a = run_px(c1, px, w, h, ps[k], NULL), *b = run_px(c2, px, w, h, ps[k], NULL);
        CHECK(a && b && memcmp(a, b, n * sizeof(float)) == 0 && memcmp(a, px, n * sizeof(float)) != 0);
        float *m = run_px(c2, px, w, h, ps[k], "{\"rect\":[10,5,40,30]}");
        CHECK(m && et_outside_equal(m, px, w, h, 10, 5, 40, 30));
        int inside = m && a;
        for (int y = 5; inside && y < 35; y++)
            inside &= memcmp(m + ((size_t)y * w + 10) * 4, a + ((size_t)y * w + 10) * 4, 40 * 16) == 0;
        CHECK(inside); /* the glow comes from the whole frame */
        /* a rectangle starting and ending between coarse's 4-pixel spans (its generic
         * per-pixel ends and its span loop give the same bits as the whole frame's) */
        float *m2 = run_px(c1, px, w, h, ps[k], "{\"rect\":[11,3,37,29]}");
        CHECK(m2 && et_outside_equal(m2, px, w, h, 11, 3, 37, 29));
        inside = m2 && a;
        for (int y = 3; inside && y < 32; y++)
            inside &= memcmp(m2 + ((size_t)y * w + 11) * 4, a + ((size_t)y * w + 11) * 4, 37 * 16) == 0;
        CHECK(inside);
        free(m2);
        free(a);
        free(b);
        free(m);
    }
    float *o = run_px(c1, px, w, h, "\"intensity\":0", NULL);
    CHECK(o && memcmp(o, px, n * sizeof(float)) == 0);
    free(o);
    free(px);
    /* fine_level fast on a constant image: the bright pass of an average is the average's,
     * and blurring a constant changes nothing, so fast and full agree (to rounding) */
    float *cst = filled(w, h, 3.0f, 2.0f, 0.5f, 1.0f);
    float *full = run_px(c1, cst, w, h, "\"radius\":16", NULL), *fast = run_px(c1, cst, w, h, "\"radius\":16,\"fine_level\":\"fast\"", NULL);
    int close = full && fast;
    for (size_t i = 0; close && i < n; i++)
        close &= fabsf(full[i] - fast[i]) <= 1e-5f * (1.0f + fabsf(full[i]));
    CHECK(close);
    /* coarse too (level 2 carries level 1's share: the same energy), for 2 to 6 levels and
     * odd sizes, where the interpolation clamps at the edges */
    const float radii[] = { 4, 16, 100 };
    for (int k = 0; k < 3; k++) {
        char pc[96], pf[96];
        snprintf(pc, sizeof pc, "\"radius\":%g,\"fine_level\":\"coarse\"", radii[k]);
        snprintf(pf, sizeof pf, "\"radius\":%g", radii[k]);
        float *co = run_px(c1, cst, w, h, pc, NULL), *fu = run_px(c1, cst, w, h, pf, NULL);
        close = co && fu;
        for (size_t i = 0; close && i < n; i++)
            close &= fabsf(fu[i] - co[i]) <= 1e-5f * (1.0f + fabsf(fu[i]));
        CHECK(close);
        free(co);
        free(fu);
    }
    free(full);
    free(fast);
    free(cst);
    /* coarse on a single bright pixel: no energy lost or made but the bright pass's (of the
     * 4x4 block's mean instead of the pixel's) */
    {
        const int W = 129, H = 97;
        float *dot = filled(W, H, 0, 0, 0, 1);
        float *dp = dot + ((size_t)48 * W + 64) * 4;
        dp[0] = dp[1] = dp[2] = 1000.0f;
        float *co = run_px(c1, dot, W, H, "\"radius\":16,\"fine_level\":\"coarse\",\"knee\":0", NULL);
        float *fu = run_px(c1, dot, W, H, "\"radius\":16,\"knee\":0", NULL);
        double sc = 0, sf = 0;
        for (int i = 0; co && fu && i < W * H; i++) {
            sc += co[4 * i] - dot[4 * i];
            sf += fu[4 * i] - dot[4 * i];
        }
        /* full's bright pass of the dot: 1000 - 1 (threshold 1); coarse's, of its 4x4 block's
         * mean: 16 (1000 / 16 - 1) = 984 */
        CHECK(co && fu && sf > 100.0 && fabs(sc / sf - 984.0 / 999.0) < 1e-3);
        free(co);
        free(fu);
        free(dot);
    }
}

static void test_extremes(fx_context *ctx)
{
    const float bad[] = { NAN, INFINITY, -INFINITY, 1e38f, -1e38f, 1e-40f, 0.0f, FLT_MAX };
    float px[13 * 7 * 4];
    for (int i = 0; i < 13 * 7 * 4; i++)
        px[i] = bad[(i * 3) % 8];
    const char *ps[] = { "", "\"mode\":\"seed\"", "\"threshold\":0,\"knee\":0", "\"mode\":\"seed\",\"threshold\":0",
                         "\"radius\":65536,\"intensity\":100,\"clamp\":3e38", "\"radius\":0",
                         "\"composite\":\"screen\",\"level_sigma\":8", "\"mode\":\"seed\",\"scene_luminance\":65504,\"middle_grey\":100",
                         "\"fine_level\":\"fast\",\"radius\":65536,\"clamp\":3e38", "\"fine_level\":\"fast\",\"mode\":\"seed\"",
                         "\"fine_level\":\"coarse\",\"radius\":65536,\"clamp\":3e38", "\"fine_level\":\"coarse\",\"radius\":3",
                         "\"fine_level\":\"coarse\",\"composite\":\"screen\"" };
    for (int k = 0; k < 13; k++) {
        float *o = run_px(ctx, px, 13, 7, ps[k], NULL);
        CHECK(o && tu_all_finite(o, 13 * 7 * 4));
        free(o);
        o = run_px(ctx, px, 1, 1, ps[k], NULL);
        CHECK(o && tu_all_finite(o, 4));
        free(o);
        o = run_px(ctx, px, 1, 13, ps[k], NULL);
        CHECK(o && tu_all_finite(o, 13 * 4));
        free(o);
        o = run_px(ctx, px, 13, 1, ps[k], NULL);
        CHECK(o && tu_all_finite(o, 13 * 4));
        free(o);
    }
}

/* In place (a consumed frame: the output is the input's buffer, FX_EFFECT_IN_PLACE) equals
 * the separate-buffer run bit for bit, for 1 and 2 threads, every fine_level (coarse's
 * composite runs two pixels per vector), both composites and the seed's pass, on a width
 * off the vectors' multiples, with bright pixels over 1. */
static void test_in_place(fx_context *c1, fx_context *c2)
{
    const int w = 83, h = 61;
    const char *params[] = { "\"radius\":16", "\"radius\":16,\"fine_level\":\"fast\"",
                             "\"radius\":32,\"fine_level\":\"coarse\",\"composite\":\"screen\"",
                             "\"radius\":8,\"fine_level\":\"coarse\"", "\"mode\":\"seed\",\"radius\":1" };
    for (int k = 0; k < 5; k++)
        for (int t = 0; t < 2; t++) {
            fx_context *ctx = t ? c2 : c1;
            fx_frame *f = tu_pattern_frame(ctx, w, h, 23 + k);
            float *px = NULL;
            fx_frame_pass(f, "Combined", &px, NULL);
            for (int i = 0; i < w * h; i += 7)
                px[4 * i + i % 3] = 6.0f; /* bright pixels */
            char buf[512];
            snprintf(buf, sizeof buf, "{\"version\":1,\"effects\":[{\"effect\":\"bloom\",\"params\":{%s}}]}",
                     params[k]);
            fx_stack *s = NULL;
            CHECK_OK(ctx, fx_stack_new(ctx, &s));
            CHECK_OK(ctx, fx_stack_load_json(s, buf));
            /* a copy whose Combined is not handed out writable: the stack may consume it */
            fx_frame *g = NULL;
            fx_frame_new(ctx, w, h, &g);
            CHECK_OK(ctx, fx_frame_add_pass(g, "Combined", 4, px));
            CHECK(et_in_place_equal(ctx, s, g, 1)); /* g is consumed */
            fx_frame_free(f);
            fx_stack_free(s);
        }
}

int main(void)
{
    fx_context *c1 = NULL, *c2 = NULL;
    fx_context_new(&c1, 1);
    fx_context_new(&c2, 2);
    test_energy(c1);
    test_properties(c1, c2);
    test_extremes(c1);
    test_in_place(c1, c2);
    fx_context_free(c1);
    fx_context_free(c2);
    return tu_finish("test_bloom");
}
