/* sin_city through the public API: the kept hue survives and others turn gray, the seed's
 * dot test, a smooth hue window (no aliasing), keep limited to a Cryptomatte object,
 * levels, identity, masks, extremes, thread invariance. */
#include "fx_effect_test.h"

#include <float.h>
#include <math.h>

float fx_cryptomatte_id(const char *name); /* internal (core/mask.h) */

static float *run_frame(fx_context *ctx, const fx_frame *f, const char *params, const char *mask)
{
    return et_run_effect(ctx, "sin_city", f, params, mask);
}

static float *run_px(fx_context *ctx, const float *px, int w, int h, const char *params, const char *mask)
{
    return et_run_effect_px(ctx, "sin_city", px, w, h, params, mask);
}

static int is_gray(const float *o, float g)
{
    return fabsf(o[0] - g) < 1e-6f && fabsf(o[1] - g) < 1e-6f && fabsf(o[2] - g) < 1e-6f;
}

static void test_keep(fx_context *ctx)
{
    const float px[] = { 0.8f, 0.05f, 0.05f, 1,   /* red: kept */
                         0.1f, 0.8f, 0.1f, 0.5f,  /* green: gray */
                         0.4f, 0.4f, 0.4f, 1,     /* gray: gray */
                         0.8f, 0.7f, 0.7f, 1,     /* pale red: below the saturation gate */
                         0.05f, 0.02f, 0.8f, 1 }; /* blue: gray */
    float *o = run_px(ctx, px, 5, 1, "", NULL);
    CHECK(o && memcmp(o, px, 4 * sizeof(float)) == 0);
    CHECK(o && is_gray(o + 4, 0.2126f * 0.1f + 0.7152f * 0.8f + 0.0722f * 0.1f) && o[7] == 0.5f);
    CHECK(o && is_gray(o + 8, 0.4f));
    CHECK(o && is_gray(o + 12, 0.2126f * 0.8f + 0.7152f * 0.7f + 0.0722f * 0.7f));
    CHECK(o && is_gray(o + 16, 0.2126f * 0.05f + 0.7152f * 0.02f + 0.0722f * 0.8f));
    free(o);
    /* mean gray, keep none */
    o = run_px(ctx, px, 5, 1, "\"gray\":\"mean\",\"keep\":\"none\"", NULL);
    CHECK(o && is_gray(o, (0.8f + 0.05f + 0.05f) / 3));
    free(o);
    /* keep green instead */
    o = run_px(ctx, px, 5, 1, "\"hue\":120", NULL);
    CHECK(o && memcmp(o + 4, px + 4, 4 * sizeof(float)) == 0 && !(o[0] == px[0] && o[1] == px[1]));
    free(o);
    /* the seed's dot test: cos((1,0.2,0),(1,0,0)) = 0.9806 kept at dot_min 0.95; (1,1,0) 0.707 not */
    const float d[] = { 1, 0.2f, 0, 1, 1, 1, 0, 1 };
    o = run_px(ctx, d, 2, 1, "\"keep\":\"dot\",\"dot_min\":0.95", NULL);
    CHECK(o && memcmp(o, d, 4 * sizeof(float)) == 0 && is_gray(o + 4, 0.2126f + 0.7152f));
    free(o);
    o = run_px(ctx, d, 2, 1, "\"keep\":\"dot\",\"dot_min\":0.99", NULL);
    CHECK(o && is_gray(o, 0.2126f + 0.7152f * 0.2f));
    free(o);
    /* dot range upper bound: only colours between 0.7 and 0.75 */
    o = run_px(ctx, d, 2, 1, "\"keep\":\"dot\",\"dot_min\":0.7,\"dot_max\":0.75", NULL);
    CHECK(o && !memcmp(o + 4, d + 4, 16) && is_gray(o, 0.2126f + 0.7152f * 0.2f));
    free(o);
    /* dot_min above dot_max is refused */
    fx_stack *s = NULL;
    fx_stack_new(ctx, &s);
    CHECK_FAIL(ctx, fx_stack_load_json(s, "{\"version\":1,\"effects\":[{\"effect\":\"sin_city\",\"params\":{\"keep\":\"dot\",\"dot_min\":0.9,\"dot_max\":0.5}}]}"),
               FX_ERR_BAD_PARAM, "dot_min");
    fx_stack_free(s);
}

/* A hue sweep at full saturation: the keep weight (recovered from the output's chroma) is 1
 * inside the window, 0 far away, and changes by small steps (no aliasing). */
static void test_hue_window(fx_context *ctx)
{
    const int n = 720;
    float *px = malloc((size_t)n * 4 * sizeof(float));
    for (int i = 0; i < n; i++) {
        float h = (float)i * 0.5f, c = 1.0f, x = c * (1 - fabsf(fmodf(h / 60.0f, 2.0f) - 1));
        float r = 0, g = 0, b = 0;
        int seg = (int)(h / 60.0f);
        switch (seg) {
        case 0: r = c; g = x; break;
        case 1: r = x; g = c; break;
        case 2: g = c; b = x; break;
        case 3: g = x; b = c; break;
        case 4: r = x; b = c; break;
        default: r = c; b = x; break;
        }
        px[4 * i] = r;
        px[4 * i + 1] = g;
        px[4 * i + 2] = b;
        px[4 * i + 3] = 1;
    }
    float *o = run_px(ctx, px, n, 1, "\"hue\":0,\"hue_width\":30,\"hue_softness\":20", NULL);
    int ok = o != NULL;
    float prev = -1, maxstep = 0;
    for (int i = 0; ok && i < n; i++) {
        float gray = 0.2126f * px[4 * i] + 0.7152f * px[4 * i + 1] + 0.0722f * px[4 * i + 2];
        float k = (o[4 * i] - gray) / (px[4 * i] - gray + 1e-30f);
        if (fabsf(px[4 * i] - gray) < 0.05f)
            continue;
        float h = i * 0.5f, dist = h > 180 ? 360 - h : h;
        if (dist <= 15)
            ok &= fabsf(k - 1) < 1e-4f;
        if (dist >= 35.01f)
            ok &= fabsf(k) < 1e-4f;
        if (prev >= 0 && fabsf(k - prev) > maxstep)
            maxstep = fabsf(k - prev);
        prev = k;
    }
    CHECK(ok);
    CHECK(maxstep < 0.05f); /* 0.5 degree steps across a 20 degree smoothstep */
    free(o);
    free(px);
}

static void test_keep_object(fx_context *ctx)
{
    /* red everywhere, the Coat object covers the left half (half coverage in column 2) */
    const int w = 6, h = 2;
    float px[6 * 2 * 4], crypto[6 * 2 * 4] = { 0 };
    float coat = fx_cryptomatte_id("Coat"), wall = fx_cryptomatte_id("Wall");
    for (int i = 0; i < w * h; i++) {
        int x = i % w;
        px[4 * i] = 0.9f;
        px[4 * i + 1] = 0.05f;
        px[4 * i + 2] = 0.02f;
        px[4 * i + 3] = 1;
        if (x < 2) {
            crypto[4 * i] = coat;
            crypto[4 * i + 1] = 1;
        } else if (x == 2) {
            crypto[4 * i] = coat;
            crypto[4 * i + 1] = 0.5f;
            crypto[4 * i + 2] = wall;
            crypto[4 * i + 3] = 0.5f;
        } else {
            crypto[4 * i] = wall;
            crypto[4 * i + 1] = 1;
        }
    }
    fx_frame *f = et_frame(ctx, w, h, px);
    fx_frame_add_pass(f, "CryptoObject00", 4, crypto);
    float *o = run_frame(ctx, f, "\"keep_object\":\"Coat\"", NULL);
    float gray = 0.2126f * 0.9f + 0.7152f * 0.05f + 0.0722f * 0.02f;
    CHECK(o && memcmp(o, px, 8 * sizeof(float)) == 0);
    CHECK(o && fabsf(o[8] - (gray + 0.5f * (0.9f - gray))) < 1e-6f);
    CHECK(o && is_gray(o + 12, gray) && is_gray(o + 20, gray));
    free(o);
    /* the pass it needs is named when missing */
    fx_frame *g = et_frame(ctx, w, h, px);
    fx_stack *s = NULL;
    fx_frame *out = NULL;
    fx_stack_new(ctx, &s);
    fx_stack_load_json(s, "{\"version\":1,\"effects\":[{\"effect\":\"sin_city\",\"params\":{\"keep_material\":\"Red\"}}]}");
    CHECK(fx_stack_run(s, g, &out) == FX_ERR_MISSING_PASS && tu_contains(fx_context_error(ctx), "CryptoMaterial"));
    char *req = NULL;
    fx_stack_required_passes(s, &req);
    CHECK(req && tu_contains(req, "CryptoMaterial"));
    fx_free(req);
    fx_stack_set_enum(s, 0, "keep", "none");
    fx_stack_required_passes(s, &req);
    CHECK(req && !tu_contains(req, "Crypto")); /* only what the params use */
    fx_free(req);
    fx_stack_free(s);
    fx_frame_free(g);
    fx_frame_free(f);
}

static void test_properties(fx_context *c1, fx_context *c2)
{
    int w = 71, h = 53;
    fx_frame *f = tu_pattern_frame(c1, w, h, 4);
    size_t n = (size_t)w * h * 4;
    const float *px = et_combined(f);
    const char *ps[] = { "\"levels\":4", "\"levels\":3,\"dither\":1,\"hue\":200,\"hue_width\":60",
                         "\"keep\":\"dot\",\"dot_softness\":0.05,\"mix\":0.7" };
    for (int k = 0; k < 3; k++) {
        float *a = run_frame(c1, f, ps[k], NULL), *b = run_frame(c2, f, ps[k], NULL);
        CHECK(a && b && memcmp(a, b, n * sizeof(float)) == 0 && memcmp(a, px, n * sizeof(float)) != 0);
        float *m = run_frame(c2, f, ps[k], "{\"rect\":[3,4,30,20]}");
        CHECK(m && et_outside_equal(m, px, w, h, 3, 4, 30, 20));
        free(a);
        free(b);
        free(m);
    }
    float *o = run_frame(c1, f, "\"levels\":4,\"mix\":0", NULL);
    CHECK(o && memcmp(o, px, n * sizeof(float)) == 0);
    free(o);
    /* levels: a gray ramp takes N values */
    float ramp[256 * 4];
    for (int x = 0; x < 256; x++) {
        ramp[4 * x] = ramp[4 * x + 1] = ramp[4 * x + 2] = (x + 0.5f) / 256;
        ramp[4 * x + 3] = 1;
    }
    o = run_px(c1, ramp, 256, 1, "\"levels\":5,\"space\":\"linear\"", NULL);
    int ok = o != NULL;
    for (int x = 0; ok && x < 256; x++)
        ok &= is_gray(o + 4 * x, (float)floor((x + 0.5) * 5 / 256.0) / 4.0f);
    CHECK(ok);
    free(o);
    fx_frame_free(f);
}

static void test_extremes(fx_context *ctx)
{
    const float bad[] = { NAN, INFINITY, -INFINITY, 1e38f, -1e38f, 1e-40f, 0.0f, FLT_MAX };
    float px[16 * 4];
    for (int i = 0; i < 64; i++)
        px[i] = bad[(i * 5) % 8];
    const char *ps[] = { "", "\"levels\":4", "\"keep\":\"dot\"", "\"keep\":\"dot\",\"dot_softness\":0.1,\"levels\":2,\"dither\":1",
                         "\"gray\":\"mean\",\"hue_softness\":0,\"saturation_softness\":0" };
    for (int k = 0; k < 5; k++) {
        float *o = run_px(ctx, px, 16, 1, ps[k], NULL);
        CHECK(o && tu_all_finite(o, 64));
        free(o);
        o = run_px(ctx, px, 1, 1, ps[k], NULL);
        CHECK(o && tu_all_finite(o, 4));
        free(o);
    }
}

/* The whole-row paths (8-pixel chunks: the AVX2 rows with the division-free pretest that
 * skips chunks surely outside the hue window or under the gate, and the vector-type chunks)
 * against the same pixels run one by one (1x1 frames: the padded lane path, no pretest):
 * the same bits, on colours placed at the pretest's margins (hues within a fraction of a
 * degree of width/2 + softness, saturations at the gate's ramp ends, magnitudes 1e-25 to
 * 1e4). */
static void hsv_to_rgb(float h, float sat, float v, float *o)
{
    h = fmodf(h, 360.0f);
    h = h < 0.0f ? h + 360.0f : h;
    const float c = v * sat, hp = h / 60.0f, x = c * (1.0f - fabsf(fmodf(hp, 2.0f) - 1.0f)), m = v - c;
    float r = 0, g = 0, b = 0;
    if (hp < 1) r = c, g = x;
    else if (hp < 2) r = x, g = c;
    else if (hp < 3) g = c, b = x;
    else if (hp < 4) g = x, b = c;
    else if (hp < 5) r = x, b = c;
    else r = c, b = x;
    o[0] = r + m, o[1] = g + m, o[2] = b + m, o[3] = 1.0f;
}

static void test_pretest_margins(fx_context *ctx)
{
    static const struct { float hue, width, soft, minsat, satsoft; } ps[] = {
        { 0, 30, 20, 0.3f, 0.15f }, { 0, 20, 10, 0.45f, 0.15f }, { 200, 0, 0.5f, 0, 0 },
        { 359, 2, 1, 0.2f, 0 }, { 120, 60, 0, 0.05f, 0.3f }, { -30, 100, 5, 0.5f, 0.01f },
    };
    enum { W = 96, H = 8 };
    float *px = malloc(sizeof(float) * 4 * W * H);
    for (size_t k = 0; k < sizeof ps / sizeof ps[0]; k++) {
        const float L = 0.5f * ps[k].width + ps[k].soft, g0 = ps[k].minsat - 0.5f * ps[k].satsoft;
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++) {
                /* hue: the window's edges plus -0.3 .. 0.3 degrees; some lanes well inside */
                const float dh = ((float)(x % 24) - 12.0f) * 0.025f;
                const float side = (x / 24) % 2 ? 1.0f : -1.0f;
                const float h = x % 7 == 0 ? ps[k].hue : ps[k].hue + side * (L + dh);
                /* saturation at the gate's ends (and at its threshold), in steps of 1e-4 */
                const float sats[8] = { g0 - 2e-4f, g0 - 1e-4f, g0, g0 + 1e-4f, ps[k].minsat,
                                        ps[k].minsat + 0.5f * ps[k].satsoft, 0.9f, 1.0f };
                float sat = sats[(x + y) % 8];
                sat = sat < 0.0f ? 0.0f : sat > 1.0f ? 1.0f : sat;
                const float mags[4] = { 1e-25f, 0.5f, 7.0f, 1e4f };
                hsv_to_rgb(h, sat, mags[y % 4], px + 4 * ((size_t)y * W + x));
            }
        char params[256];
        snprintf(params, sizeof params,
                 "\"hue\":%g,\"hue_width\":%g,\"hue_softness\":%g,\"min_saturation\":%g,\"saturation_softness\":%g",
                 ps[k].hue, ps[k].width, ps[k].soft, ps[k].minsat, ps[k].satsoft);
        float *o = run_px(ctx, px, W, H, params, NULL);
        CHECK(o != NULL);
        int diff = 0;
        for (int i = 0; o && i < W * H; i++) {
            float *o1 = run_px(ctx, px + 4 * i, 1, 1, params, NULL);
            CHECK(o1 != NULL);
            if (o1 && memcmp(o1, o + 4 * i, 4 * sizeof(float)) != 0)
                diff++;
            free(o1);
        }
        if (diff)
            fprintf(stderr, "test_pretest_margins: %s: %d pixels differ from their 1x1 runs\n", params, diff);
        CHECK(diff == 0);
        free(o);
    }
    free(px);
}

/* keep dot with a blue key: the cosine takes all three channels, (0.2, 0.2, 1) is at
 * 1 / sqrt(1.08) = 0.962 of (0, 0, 1) and kept at dot_min 0.9, (1, 0.5, 0.6) at 0.473 turns
 * to its Rec.709 luminance Y; at mix 0.5 the gray one is halfway (c + 0.5 (Y - c)) and the
 * kept one unchanged. */
static void test_dot_blue_mix(fx_context *ctx)
{
    const float px[8] = { 0.2f, 0.2f, 1, 1, 1, 0.5f, 0.6f, 0.5f };
    const float y1 = 0.2126f * 1 + 0.7152f * 0.5f + 0.0722f * 0.6f;
    const char *base = "\"keep\":\"dot\",\"key_color\":[0,0,1],\"dot_min\":0.9";
    float *o = run_px(ctx, px, 2, 1, base, NULL);
    CHECK(o && memcmp(o, px, 4 * sizeof(float)) == 0 && is_gray(o + 4, y1) && o[7] == 0.5f);
    free(o);
    char p[160];
    snprintf(p, sizeof p, "%s,\"mix\":0.5", base);
    o = run_px(ctx, px, 2, 1, p, NULL);
    int ok = o && memcmp(o, px, 4 * sizeof(float)) == 0;
    for (int c = 0; ok && c < 3; c++)
        ok &= fabsf(o[4 + c] - (px[4 + c] + 0.5f * (y1 - px[4 + c]))) < 1e-6f;
    CHECK(ok);
    free(o);
}

int main(void)
{
    fx_context *c1 = NULL, *c2 = NULL;
    fx_context_new(&c1, 1);
    fx_context_new(&c2, 2);
    test_keep(c1);
    test_dot_blue_mix(c1);
    test_hue_window(c1);
    test_keep_object(c1);
    test_properties(c1, c2);
    test_extremes(c1);
    test_pretest_margins(c1);
    test_pretest_margins(c2);
    fx_context_free(c1);
    fx_context_free(c2);
    return tu_finish("test_sin_city");
}
