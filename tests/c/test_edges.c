/* edges (and math/edge_ops) through the public API: exact kernel responses on steps and
 * impulses, scale-free depth, normals at AA edges, coverage-aware Cryptomatte IDs, index IDs,
 * identity, masks, extremes, thread invariance. */
#include "fx_effect_test.h"
#include "math/srgb_lut.h"

#include <float.h>
#include <stdint.h>
#include <string.h>
#include <math.h>

/* Runs a one-effect stack from a recipe JSON on f; returns a copy of `pass` of the output
 * (NULL: Combined). */
static float *run_pass(fx_context *ctx, const fx_frame *f, const char *recipe, const char *pass)
{
    fx_stack *s = NULL;
    float *copy = NULL;
    fx_frame *out = NULL;
    if (fx_stack_new(ctx, &s) != FX_OK || fx_stack_load_json(s, recipe) != FX_OK) {
        fprintf(stderr, "recipe: %s\n", fx_context_error(ctx));
        goto done;
    }
    fx_stack_set_debug_outputs(s, pass != NULL);
    if (fx_stack_run(s, f, &out) != FX_OK) {
        fprintf(stderr, "run: %s\n", fx_context_error(ctx));
        goto done;
    }
    float *d = NULL;
    int c = 0;
    if (fx_frame_pass(out, pass ? pass : "Combined", &d, &c) != FX_OK) {
        fprintf(stderr, "pass %s: %s\n", pass ? pass : "Combined", fx_context_error(ctx));
        goto done;
    }
    size_t n = (size_t)fx_frame_width(out) * fx_frame_height(out) * c;
    copy = malloc(n * sizeof(float));
    memcpy(copy, d, n * sizeof(float));
done:
    fx_frame_free(out);
    fx_stack_free(s);
    return copy;
}

static char *recipe(const char *params, const char *mask)
{
    static char buf[2048];
    snprintf(buf, sizeof buf, "{\"version\":1,\"effects\":[{\"effect\":\"edges\",\"params\":{%s}%s%s}]}",
             params, mask ? ",\"mask\":" : "", mask ? mask : "");
    return buf;
}

static fx_frame *step_frame(fx_context *ctx, int w, int h, int step_x, float lo, float hi)
{
    float *px = malloc((size_t)w * h * 4 * sizeof(float));
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            float v = x < step_x ? lo : hi;
            float *p = px + ((size_t)y * w + x) * 4;
            p[0] = p[1] = p[2] = v;
            p[3] = 1;
        }
    fx_frame *f = et_frame(ctx, w, h, px);
    free(px);
    return f;
}

static void test_kernels(fx_context *ctx)
{
    const int w = 10, h = 6;
    fx_frame *f = step_frame(ctx, w, h, 5, 0.0f, 1.0f); /* step between columns 4 and 5 */
    struct { const char *op; int x0, x1; } cases[] = {
        { "sobel", 4, 5 }, { "sobel_x", 4, 5 }, { "laplace4", 4, 5 }, { "laplace8", 4, 5 }, { "sparse7", 2, 7 },
    };
    for (int c = 0; c < 5; c++) {
        char p[256];
        snprintf(p, sizeof p, "\"operator\":\"%s\"", cases[c].op);
        float *st = run_pass(ctx, f, recipe(p, NULL), "fx0_edges_strengths");
        int ok = st != NULL;
        for (int y = 0; ok && y < h; y++)
            for (int x = 0; x < w; x++) {
                float want = x >= cases[c].x0 && x <= cases[c].x1 ? 1.0f : 0.0f;
                if (fabsf(st[((size_t)y * w + x) * 4] - want) > 1e-6f) {
                    fprintf(stderr, "%s (%d,%d): %g want %g\n", cases[c].op, x, y, st[((size_t)y * w + x) * 4], want);
                    ok = 0;
                    break;
                }
            }
        CHECK(ok);
        free(st);
    }
    /* sobel_y sees nothing on a vertical step */
    float *st = run_pass(ctx, f, recipe("\"operator\":\"sobel_y\"", NULL), "fx0_edges_strengths");
    int zero = st != NULL;
    for (int i = 0; st && i < w * h; i++)
        zero &= st[4 * i] == 0.0f;
    CHECK(zero);
    free(st);
    /* matte: threshold 0.5, hard */
    float *m = run_pass(ctx, f, recipe("\"output\":\"matte\",\"luminance_threshold\":0.5,\"softness\":0", NULL), NULL);
    int ok = m != NULL;
    for (int y = 0; ok && y < h; y++)
        for (int x = 0; x < w; x++) {
            float want = (x == 4 || x == 5) ? 1.0f : 0.0f;
            ok &= m[((size_t)y * w + x) * 4] == want && m[((size_t)y * w + x) * 4 + 3] == 1.0f;
        }
    CHECK(ok);
    free(m);
    /* over with red lines, width 4 (disc radius 1: a 3x3 square) -> columns 3..6 */
    m = run_pass(ctx, f, recipe("\"luminance_threshold\":0.5,\"softness\":0,\"line_width\":4,\"line_color\":[1,0,0,1]", NULL), NULL);
    ok = m != NULL;
    for (int y = 0; ok && y < h; y++)
        for (int x = 0; x < w; x++) {
            const float *o = m + ((size_t)y * w + x) * 4;
            int line = x >= 3 && x <= 6;
            float base = x < 5 ? 0.0f : 1.0f;
            ok &= line ? (o[0] == 1 && o[1] == 0 && o[2] == 0) : (o[0] == base && o[1] == base);
        }
    CHECK(ok);
    free(m);
    fx_frame_free(f);

    /* impulse: Sobel at the diagonal neighbour is sqrt(2)/4 */
    float px[9 * 7 * 4] = { 0 };
    px[(3 * 9 + 4) * 4 + 0] = px[(3 * 9 + 4) * 4 + 1] = px[(3 * 9 + 4) * 4 + 2] = 1.0f;
    f = et_frame(ctx, 9, 7, px);
    st = run_pass(ctx, f, recipe("\"operator\":\"sobel\"", NULL), "fx0_edges_strengths");
    CHECK(st && fabsf(st[(4 * 9 + 5) * 4] - sqrtf(2.0f) / 4) < 1e-6f);
    CHECK(st && fabsf(st[(3 * 9 + 5) * 4] - 0.5f) < 1e-6f); /* gx = 2 */
    CHECK(st && st[(3 * 9 + 4) * 4] == 0.0f);                /* centre: symmetric */
    free(st);
    st = run_pass(ctx, f, recipe("\"operator\":\"laplace4\"", NULL), "fx0_edges_strengths");
    CHECK(st && fabsf(st[(3 * 9 + 4) * 4] - 4.0f) < 1e-6f && fabsf(st[(3 * 9 + 5) * 4] - 1.0f) < 1e-6f && st[(4 * 9 + 5) * 4] == 0.0f);
    free(st);
    st = run_pass(ctx, f, recipe("\"operator\":\"laplace8\"", NULL), "fx0_edges_strengths");
    CHECK(st && fabsf(st[(3 * 9 + 4) * 4] - 8.0f / 3) < 1e-6f && fabsf(st[(4 * 9 + 5) * 4] - 1.0f / 3) < 1e-6f);
    free(st);
    fx_frame_free(f);
}

static fx_frame *depth_frame(fx_context *ctx, int w, int h, float near, float far)
{
    fx_frame *f = tu_pattern_frame(ctx, w, h, 3);
    float *d = malloc((size_t)w * h * sizeof(float));
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            d[y * w + x] = x < w / 2 ? near : far;
    fx_frame_add_pass(f, "Depth", 1, d);
    free(d);
    return f;
}

/* depth_mode planar: a plane seen at a grazing angle (1/d affine in x and y, depth from 1 to
 * ~130) gives 0 everywhere, where relative fires; a step 2 -> 4 gives d1/d0 - 1 = 1 on its
 * far side and 1 - d0/d1 = 0.5 on the near side; scale-free. */
static void test_depth_planar(fx_context *ctx)
{
    const int w = 12, h = 8;
    fx_frame *f = tu_pattern_frame(ctx, w, h, 3);
    float *d = malloc((size_t)w * h * sizeof(float));
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            d[y * w + x] = 1.0f / (1.0f - 0.0899f * (float)x - 0.0005f * (float)y); /* 1/d affine: d 1 .. ~130 */
    fx_frame_add_pass(f, "Depth", 1, d);
    const char *pp = "\"luminance\":false,\"depth\":true,\"depth_mode\":\"planar\"";
    const char *pr = "\"luminance\":false,\"depth\":true,\"depth_mode\":\"relative\"";
    float *sp = run_pass(ctx, f, recipe(pp, NULL), "fx0_edges_strengths");
    float *sr = run_pass(ctx, f, recipe(pr, NULL), "fx0_edges_strengths");
    float mp = 0, mr = 0;
    for (int i = 0; sp && sr && i < w * h; i++) {
        mp = sp[4 * i + 1] > mp ? sp[4 * i + 1] : mp;
        mr = sr[4 * i + 1] > mr ? sr[4 * i + 1] : mr;
    }
    CHECK(sp && sr && mp < 1e-3f && mr > 0.5f);
    free(sp);
    free(sr);
    fx_frame_free(f);
    for (int k = 0; k < 2; k++) {
        float sc = k ? 100.0f : 1.0f;
        f = tu_pattern_frame(ctx, w, h, 3);
        for (int i = 0; i < w * h; i++)
            d[i] = (i % w < 6 ? 2.0f : 4.0f) * sc;
        fx_frame_add_pass(f, "Depth", 1, d);
        sp = run_pass(ctx, f, recipe(pp, NULL), "fx0_edges_strengths");
        CHECK(sp && fabsf(sp[(3 * w + 6) * 4 + 1] - 1.0f) < 1e-5f && fabsf(sp[(3 * w + 5) * 4 + 1] - 0.5f) < 1e-5f &&
              sp[(3 * w + 2) * 4 + 1] == 0.0f);
        free(sp);
        fx_frame_free(f);
    }
    free(d);
}

static void test_depth_normals(fx_context *ctx)
{
    const char *p = "\"luminance\":false,\"depth\":true,\"operator\":\"sobel\"";
    fx_frame *a = depth_frame(ctx, 8, 4, 2.0f, 4.0f), *b = depth_frame(ctx, 8, 4, 20.0f, 40.0f);
    float *sa = run_pass(ctx, a, recipe(p, NULL), "fx0_edges_strengths");
    float *sb = run_pass(ctx, b, recipe(p, NULL), "fx0_edges_strengths");
    CHECK(sa && sb && fabsf(sa[(1 * 8 + 3) * 4 + 1] - logf(2.0f)) < 1e-5f);
    CHECK(sa && sb && fabsf(sa[(1 * 8 + 3) * 4 + 1] - sb[(1 * 8 + 3) * 4 + 1]) < 1e-5f); /* scale-free */
    free(sa);
    free(sb);
    fx_frame_free(a);
    fx_frame_free(b);
    /* background: Cycles 1e10 and Eevee 65504 read the same */
    a = depth_frame(ctx, 8, 4, 5.0f, 1e10f);
    b = depth_frame(ctx, 8, 4, 5.0f, 65504.0f);
    sa = run_pass(ctx, a, recipe(p, NULL), "fx0_edges_strengths");
    sb = run_pass(ctx, b, recipe(p, NULL), "fx0_edges_strengths");
    CHECK(sa && sb && memcmp(sa, sb, 8 * 4 * 4 * sizeof(float)) == 0 && sa[(1 * 8 + 3) * 4 + 1] > 5.0f);
    free(sa);
    free(sb);
    fx_frame_free(a);
    fx_frame_free(b);
    /* missing pass: a clear error */
    fx_frame *f = tu_pattern_frame(ctx, 4, 4, 1);
    fx_stack *s = NULL;
    fx_stack_new(ctx, &s);
    fx_stack_load_json(s, recipe(p, NULL));
    fx_frame *out = NULL;
    CHECK_FAIL(ctx, fx_stack_run(s, f, &out), FX_ERR_MISSING_PASS, "Depth");
    fx_stack_free(s);

    /* normals: (0,0,1) | (1,0,0) at 90 degrees; half-length (AA) and zero (background) */
    float n[8 * 4 * 3] = { 0 };
    for (int y = 0; y < 4; y++)
        for (int x = 0; x < 8; x++) {
            float *v = n + (y * 8 + x) * 3;
            if (x < 3)
                v[2] = 1.0f;
            else if (x == 3)
                v[2] = 0.5f; /* anti-aliased: shorter, same direction */
            else if (x < 6)
                v[0] = 1.0f;
            /* x >= 6: background, zero */
        }
    fx_frame_add_pass(f, "Normal", 3, NULL);
    fx_frame *g = NULL;
    fx_frame_new(ctx, 8, 4, &g);
    float *rgba = calloc(8 * 4 * 4, sizeof(float));
    fx_frame_add_pass(g, "Combined", 4, rgba);
    fx_frame_add_pass(g, "Normal", 3, n);
    float *st = run_pass(ctx, g, recipe("\"luminance\":false,\"normal\":true", NULL), "fx0_edges_strengths");
    CHECK(st && st[(1 * 8 + 1) * 4 + 2] == 0.0f);                       /* flat */
    CHECK(st && st[(1 * 8 + 2) * 4 + 2] == 0.0f);                       /* next to the AA pixel */
    CHECK(st && fabsf(st[(1 * 8 + 3) * 4 + 2] - 90.0f) < 1e-3f);        /* the turn */
    CHECK(st && fabsf(st[(1 * 8 + 4) * 4 + 2] - 90.0f) < 1e-3f);
    CHECK(st && st[(1 * 8 + 7) * 4 + 2] == 0.0f);                       /* background inside */
    CHECK(st && tu_all_finite(st, 8 * 4 * 4));
    free(st);
    free(rgba);
    fx_frame_free(g);
    fx_frame_free(f);
}

static void test_ids(fx_context *ctx)
{
    /* CryptoObject00: ids A | half A half B | B; coverage-aware differences */
    const int w = 7, h = 3;
    const float A = 1.5f, B = -2.25f;
    float c[7 * 3 * 4] = { 0 }, idx[7 * 3];
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            float *p = c + (y * w + x) * 4;
            if (x < 3) {
                p[0] = A; p[1] = 1.0f;
            } else if (x == 3) {
                p[0] = A; p[1] = 0.5f; p[2] = B; p[3] = 0.5f;
            } else {
                p[0] = B; p[1] = 1.0f;
            }
            idx[y * w + x] = x < 4 ? 1.0f : 2.0f;
        }
    fx_frame *f = tu_pattern_frame(ctx, w, h, 2);
    fx_frame_add_pass(f, "CryptoObject00", 4, c);
    fx_frame_add_pass(f, "IndexOB", 1, idx);
    float *st = run_pass(ctx, f, recipe("\"luminance\":false,\"object_id\":true", NULL), "fx0_edges_strengths");
    CHECK(st && st[(1 * w + 1) * 4 + 3] == 0.0f);
    CHECK(st && fabsf(st[(1 * w + 2) * 4 + 3] - 0.5f) < 1e-6f);
    CHECK(st && fabsf(st[(1 * w + 3) * 4 + 3] - 0.5f) < 1e-6f);
    CHECK(st && fabsf(st[(1 * w + 4) * 4 + 3] - 0.5f) < 1e-6f);
    CHECK(st && st[(1 * w + 5) * 4 + 3] == 0.0f);
    free(st);
    st = run_pass(ctx, f, recipe("\"luminance\":false,\"object_id\":true,\"id_source\":\"index\"", NULL),
                  "fx0_edges_strengths");
    CHECK(st && st[(1 * w + 2) * 4 + 3] == 0.0f && st[(1 * w + 3) * 4 + 3] == 1.0f &&
          st[(1 * w + 4) * 4 + 3] == 1.0f && st[(1 * w + 5) * 4 + 3] == 0.0f);
    free(st);
    /* an uncovered pixel is background, distinct from any object, equal to another uncovered one */
    memset(c, 0, sizeof c);
    for (int y = 0; y < h; y++) {
        c[(y * w + 6) * 4] = A;
        c[(y * w + 6) * 4 + 1] = 1.0f;
    }
    fx_frame_add_pass(f, "CryptoObject00", 4, c);
    st = run_pass(ctx, f, recipe("\"luminance\":false,\"object_id\":true", NULL), "fx0_edges_strengths");
    CHECK(st && st[(1 * w + 2) * 4 + 3] == 0.0f && st[(1 * w + 5) * 4 + 3] == 1.0f);
    free(st);
    fx_frame_free(f);
}

static void test_properties(fx_context *c1, fx_context *c2)
{
    const int w = 97, h = 61;
    fx_frame *f = tu_pattern_frame(c1, w, h, 11);
    float *d = malloc((size_t)w * h * sizeof(float)), *n = malloc((size_t)w * h * 3 * sizeof(float));
    for (int i = 0; i < w * h; i++) {
        d[i] = 1.0f + (float)((i * 7919) % 97) * 0.05f;
        n[3 * i] = sinf((float)i * 0.01f);
        n[3 * i + 1] = cosf((float)i * 0.013f);
        n[3 * i + 2] = 0.3f;
    }
    fx_frame_add_pass(f, "Depth", 1, d);
    fx_frame_add_pass(f, "Normal", 3, n);
    const float *src = et_combined(f);
    size_t np = (size_t)w * h * 4;
    const char *all = "\"depth\":true,\"normal\":true,\"line_width\":5.5,\"line_color\":[0.2,0.1,0,1]";
    /* identity at zero opacity */
    char p[512];
    snprintf(p, sizeof p, "%s,\"opacity\":0", all);
    float *o = run_pass(c1, f, recipe(p, NULL), NULL);
    CHECK(o && memcmp(o, src, np * sizeof(float)) == 0);
    free(o);
    /* threads */
    float *a = run_pass(c1, f, recipe(all, NULL), NULL), *b = run_pass(c2, f, recipe(all, NULL), NULL);
    CHECK(a && b && memcmp(a, b, np * sizeof(float)) == 0 && memcmp(a, src, np * sizeof(float)) != 0);
    /* mask: outside bit-exact, inside equal to the unmasked run (the halo reads outside) */
    float *m = run_pass(c1, f, recipe(all, "{\"rect\":[10,7,30,20]}"), NULL);
    CHECK(m && et_outside_equal(m, src, w, h, 10, 7, 30, 20));
    int inside = m && a;
    for (int y = 7; inside && y < 27; y++)
        inside &= memcmp(m + ((size_t)y * w + 10) * 4, a + ((size_t)y * w + 10) * 4, 30 * 4 * sizeof(float)) == 0;
    CHECK(inside);
    free(a);
    free(b);
    free(m);
    /* the matte is streamed in bands of 32 rows: wide lines (reach 19) and planar depth read
     * across band borders; threads and a mask must not change a bit */
    const char *wide = "\"depth\":true,\"depth_mode\":\"planar\",\"normal\":true,\"line_width\":40,\"output\":\"matte\"";
    a = run_pass(c1, f, recipe(wide, NULL), NULL);
    b = run_pass(c2, f, recipe(wide, NULL), NULL);
    CHECK(a && b && memcmp(a, b, np * sizeof(float)) == 0);
    m = run_pass(c2, f, recipe(wide, "{\"rect\":[3,29,50,5]}"), NULL);
    inside = m && a;
    for (int y = 29; inside && y < 34; y++)
        inside &= memcmp(m + ((size_t)y * w + 3) * 4, a + ((size_t)y * w + 3) * 4, 50 * 4 * sizeof(float)) == 0;
    CHECK(inside);
    free(a);
    free(b);
    free(m);
    free(d);
    free(n);
    fx_frame_free(f);
}

static void test_extremes(fx_context *ctx)
{
    /* 1x1, any operator, any width */
    const float one[4] = { 0.5f, 0.2f, 0.1f, 1 };
    fx_frame *f = et_frame(ctx, 1, 1, one);
    const char *ops[] = { "sobel", "sobel_x", "sobel_y", "laplace4", "laplace8", "sparse7" };
    for (int k = 0; k < 6; k++) {
        char p[256];
        snprintf(p, sizeof p, "\"operator\":\"%s\",\"line_width\":64,\"luminance_threshold\":0", ops[k]);
        float *o = run_pass(ctx, f, recipe(p, NULL), NULL);
        CHECK(o && memcmp(o, one, sizeof one) == 0); /* no neighbours, no edge */
        free(o);
    }
    fx_frame_free(f);
    /* constant image, threshold 0: nothing drawn */
    float *px = malloc(16 * 16 * 4 * sizeof(float));
    for (int i = 0; i < 16 * 16 * 4; i++)
        px[i] = 0.3337f;
    f = et_frame(ctx, 16, 16, px);
    float *o = run_pass(ctx, f, recipe("\"luminance_threshold\":0,\"softness\":0,\"line_color\":[1,0,0,1]", NULL), NULL);
    CHECK(o && memcmp(o, px, 16 * 16 * 4 * sizeof(float)) == 0);
    free(o);
    fx_frame_free(f);
    /* NaN / Inf / 1e38 / denormals in colour and depth: finite */
    const float bad[] = { NAN, INFINITY, -INFINITY, 1e38f, -1e38f, 1e-40f, 0.0f, 3.4e38f };
    for (int i = 0; i < 16 * 16; i++)
        for (int k = 0; k < 4; k++)
            px[i * 4 + k] = bad[(i * 3 + k) % 8];
    f = et_frame(ctx, 16, 16, px);
    float dep[256], nor[256 * 3];
    for (int i = 0; i < 256; i++) {
        dep[i] = bad[i % 8];
        for (int k = 0; k < 3; k++)
            nor[i * 3 + k] = bad[(i + k) % 8];
    }
    fx_frame_add_pass(f, "Depth", 1, dep);
    fx_frame_add_pass(f, "Normal", 3, nor);
    const char *ps[] = { "\"depth\":true,\"normal\":true", "\"operator\":\"laplace8\",\"depth\":true,\"output\":\"matte\"",
                         "\"operator\":\"sparse7\",\"depth\":true,\"line_width\":9" };
    for (int k = 0; k < 3; k++) {
        float *st = run_pass(ctx, f, recipe(ps[k], NULL), "fx0_edges_strengths");
        CHECK(st && tu_all_finite(st, 256 * 4));
        free(st);
        fx_frame *out = NULL;
        fx_stack *s = NULL;
        fx_stack_new(ctx, &s);
        fx_stack_load_json(s, recipe(ps[k], NULL));
        int before = fx_context_warning_count(ctx);
        CHECK_OK(ctx, fx_stack_run(s, f, &out));
        /* the effect itself produced nothing non-finite (the stack would warn) */
        int warned = 0;
        for (int i = before; i < fx_context_warning_count(ctx); i++)
            warned |= tu_contains(fx_context_warning(ctx, i), "non-finite");
        CHECK(!warned);
        CHECK(out && tu_all_finite(et_combined(out), 256 * 4) == 1);
        fx_frame_free(out);
        fx_stack_free(s);
    }
    free(px);
    fx_frame_free(f);
}

/* The sRGB table encoder (luminance edges) against the formula in double: over every 61st
 * float in [2^-9, 2^20) the error is below FX_SRGB_LUT_MAX_ERR (absolute up to 1, relative
 * above); exact below 2^-9 and at powers of two; monotone. */
static void test_srgb_lut(void)
{
    const float *lut = fx_srgb_lut();
    double max_abs = 0, max_rel = 0;
    int mono = 1, exact = 1;
    float prev = -1.0f;
    uint32_t b0, b1;
    float lo = 0.001953125f, hi = FX_SRGB_LUT_MAX;
    memcpy(&b0, &lo, 4);
    memcpy(&b1, &hi, 4);
    for (uint32_t b = b0; b < b1; b += 61) {
        float a;
        memcpy(&a, &b, 4);
        double want = a <= 0.0031308 ? 12.92 * a : 1.055 * pow(a, 1 / 2.4) - 0.055;
        float got = fx_srgb_encode_lut(lut, a);
        double e = fabs(got - want);
        if (a <= 1.0f)
            max_abs = e > max_abs ? e : max_abs;
        else
            max_rel = e / want > max_rel ? e / want : max_rel;
        mono &= got >= prev;
        prev = got;
    }
    for (int e = -9; e < 20; e++) {
        float a = ldexpf(1.0f, e);
        double want = a <= 0.0031308 ? 12.92 * a : 1.055 * pow(a, 1 / 2.4) - 0.055;
        exact &= fx_srgb_encode_lut(lut, a) == (float)want;
    }
    for (float a = 0.0f; a < 0.00195f; a += 1.3e-5f)
        exact &= fx_srgb_encode_lut(lut, a) == 12.92f * a;
    printf("srgb lut: max abs error %.3g on [2^-9, 1], max relative %.3g above 1\n", max_abs, max_rel);
    CHECK(max_abs < FX_SRGB_LUT_MAX_ERR && max_rel < FX_SRGB_LUT_MAX_ERR && mono && exact);
    CHECK(fx_srgb_encode_lut(lut, 1.0f) == 1.0f && fx_srgb_encode_lut(lut, 0.0f) == 0.0f);
}

/* In place (a consumed frame: the output is the input's buffer) equals the separate-buffer
 * run bit for bit, with lines across the 32-row band boundaries, for 1 and 2 threads and
 * several halos (sobel; laplace8 width 5; sparse7 width 9; matte output). */
static void test_in_place(fx_context *c1, fx_context *c2)
{
    const int w = 97, h = 141;
    const char *params[] = { "", "\"line_width\": 5, \"operator\": \"laplace8\"",
                             "\"operator\": \"sparse7\", \"line_width\": 9",
                             "\"output\": \"matte\", \"opacity\": 0.6" };
    for (int k = 0; k < 4; k++)
        for (int t = 0; t < 2; t++) {
            fx_context *ctx = t ? c2 : c1;
            char buf[512];
            snprintf(buf, sizeof buf, "{\"version\":1,\"effects\":[{\"effect\":\"edges\",\"params\":{%s}}]}",
                     params[k]);
            fx_stack *s = NULL;
            CHECK_OK(ctx, fx_stack_new(ctx, &s));
            CHECK_OK(ctx, fx_stack_load_json(s, buf));
            fx_frame *f = tu_pattern_frame(ctx, w, h, 17);
            CHECK(et_in_place_equal(ctx, s, f, 0)); /* f is consumed */
            fx_stack_free(s);
        }
}

/* The default luminance Sobel takes a fast path (AVX2 where the CPU has it: bounds that skip
 * the exact magnitude for pixels surely under or over the ramp); the debug strengths force
 * the exact path. Both must give the same bits, for thresholds from 0 to 300, hard and soft
 * ramps, on a field with gradients of every size (noise on ramps, steps near the
 * thresholds, values up to the encoder's clamp, non-finite pixels). */
static void test_fast_path(fx_context *ctx)
{
    const int w = 203, h = 71;
    float *px = malloc((size_t)w * h * 4 * sizeof(float));
    uint32_t st = 12345u;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            float *p = px + ((size_t)y * w + x) * 4;
            st = st * 1664525u + 1013904223u;
            const float r = (float)(st >> 8) * (1.0f / 16777216.0f);
            float v;
            switch ((x / 29 + y / 13) % 5) {
            case 0: v = 0.2f + 0.01f * (float)x + 0.02f * r; break;              /* ramp + fine noise */
            case 1: v = (x % 7 < 3 ? 0.1f : 0.1f + 0.05f * (float)(y % 9)) + 1e-4f * r; break; /* steps */
            case 2: v = r * r * 4.0f; break;                                       /* coarse noise */
            case 3: v = (x + y) % 11 == 0 ? 1e6f * r : 1e-3f * r; break;          /* huge values */
            default: v = r < 0.02f ? (r < 0.01f ? NAN : INFINITY) : 50.0f * r; break;
            }
            p[0] = v;
            p[1] = v * (0.5f + r);
            p[2] = v * 0.25f;
            p[3] = 1.0f;
        }
    fx_frame *f = et_frame(ctx, w, h, px);
    free(px);
    const float ts[] = { 0.0f, 1e-4f, 0.003f, 0.05f, 0.15f, 0.5f, 2.0f, 30.0f, 300.0f };
    const float sf[] = { 0.0f, 0.5f, 3.0f };
    int same = 1, lines = 0;
    for (size_t i = 0; i < sizeof ts / sizeof ts[0]; i++)
        for (size_t k = 0; k < sizeof sf / sizeof sf[0]; k++) {
            char p[256];
            snprintf(p, sizeof p, "\"luminance_threshold\":%.9g,\"softness\":%.9g,\"line_color\":[1,0,0,1]",
                     (double)ts[i], (double)sf[k]);
            float *a = run_pass(ctx, f, recipe(p, NULL), NULL);
            fx_stack *s = NULL;
            fx_frame *out = NULL;
            float *b = NULL;
            if (fx_stack_new(ctx, &s) == FX_OK && fx_stack_load_json(s, recipe(p, NULL)) == FX_OK) {
                fx_stack_set_debug_outputs(s, 1);
                if (fx_stack_run(s, f, &out) == FX_OK) {
                    b = malloc((size_t)w * h * 4 * sizeof(float));
                    memcpy(b, et_combined(out), (size_t)w * h * 4 * sizeof(float));
                }
            }
            same &= a && b && memcmp(a, b, (size_t)w * h * 4 * sizeof(float)) == 0;
            for (int q = 0; a && q < w * h; q++)
                lines += a[4 * q] == 1.0f && a[4 * q + 1] == 0.0f;
            fx_frame_free(out);
            fx_stack_free(s);
            free(a);
            free(b);
        }
    CHECK(same);
    CHECK(lines > 1000);
    fx_frame_free(f);
}

/* output gradient (Blender's Filter Sobel; the numpy reference is in
 * tests/python/test_edges_gradient.py): raw NaN / Inf / FLT_MAX / denormal colour give finite
 * output without the stack's non-finite warning; the bits do not depend on the thread count
 * or on in place (consumed input) vs a separate buffer; pixels whose 3x3 neighbourhood is
 * finite and small get the float formula in Blender's order; a mask keeps what it leaves. */
static float grad_ref(const float *px, int w, int h, int x, int y, int k)
{
#define T(dx, dy) px[((size_t)(y + (dy) < 0 ? 0 : y + (dy) >= h ? h - 1 : y + (dy)) * w + \
                      (x + (dx) < 0 ? 0 : x + (dx) >= w ? w - 1 : x + (dx))) * 4 + k]
    /* P the row below, Q the row above (Blender's order) */
    const float gx = ((((T(-1, 1) - T(1, 1)) + 2.0f * T(-1, 0)) - 2.0f * T(1, 0)) + T(-1, -1)) - T(1, -1);
    const float gy = ((((T(-1, 1) + 2.0f * T(0, 1)) + T(1, 1)) - T(-1, -1)) - 2.0f * T(0, -1)) - T(1, -1);
#undef T
    return sqrtf(gx * gx + gy * gy);
}

static void test_gradient(fx_context *c1, fx_context *c2)
{
    const int w = 67, h = 90; /* several bands at 2 threads: the in-place saved rows */
    float *px = malloc((size_t)w * h * 4 * sizeof(float));
    uint32_t st = 777u;
    const float bad[] = { NAN, INFINITY, -INFINITY, FLT_MAX, -FLT_MAX, 1e38f, 1e-40f, -0.0f };
    for (int i = 0; i < w * h * 4; i++) {
        st = st * 1664525u + 1013904223u;
        px[i] = (float)(st >> 8) * (1.0f / 16777216.0f) * 3.0f - 1.0f;
        if (i / 4 / w >= 60 && (st >> 27) < 3) /* the lower third: extremes here and there */
            px[i] = bad[(st >> 5) % 8];
    }
    fx_frame *f = et_frame(c1, w, h, px);
    const char *ps[] = { "\"output\":\"gradient\"", "\"output\":\"gradient\",\"opacity\":0.35" };
    for (int k = 0; k < 2; k++) {
        float *ref = NULL;
        for (int t = 0; t < 2; t++)
            for (int consume = 0; consume < 2; consume++) {
                fx_context *ctx = t ? c2 : c1;
                fx_stack *s = NULL;
                fx_frame *out = NULL;
                CHECK_OK(ctx, fx_stack_new(ctx, &s));
                CHECK_OK(ctx, fx_stack_load_json(s, recipe(ps[k], NULL)));
                const int before = fx_context_warning_count(ctx);
                if (consume) {
                    fx_frame *in = et_frame(ctx, w, h, px);
                    CHECK_OK(ctx, fx_stack_run_consume(s, in, 0, &out));
                } else {
                    CHECK_OK(ctx, fx_stack_run(s, f, &out));
                }
                int warned = 0;
                for (int i = before; i < fx_context_warning_count(ctx); i++)
                    warned |= tu_contains(fx_context_warning(ctx, i), "non-finite");
                CHECK(!warned);
                const float *o = out ? et_combined(out) : NULL;
                CHECK(o && tu_all_finite(o, (size_t)w * h * 4));
                if (o && !ref) {
                    ref = malloc((size_t)w * h * 4 * sizeof(float));
                    memcpy(ref, o, (size_t)w * h * 4 * sizeof(float));
                } else if (o) {
                    CHECK(memcmp(o, ref, (size_t)w * h * 4 * sizeof(float)) == 0);
                }
                fx_frame_free(out);
                fx_stack_free(s);
            }
        /* the upper part (no extremes within reach): the formula, alpha kept */
        int same = ref != NULL;
        const float fac = k ? 0.35f : 1.0f;
        for (int y = 0; same && y < 58; y++)
            for (int x = 0; x < w; x++)
                for (int c = 0; c < 4; c++) {
                    const float *p = px + ((size_t)y * w + x) * 4;
                    const float want = c == 3 ? p[3] : k ? p[c] * (1.0f - fac) + grad_ref(px, w, h, x, y, c) * fac
                                                         : grad_ref(px, w, h, x, y, c);
                    if (memcmp(&want, &ref[((size_t)y * w + x) * 4 + c], sizeof want) != 0) {
                        fprintf(stderr, "gradient %d (%d,%d,%d): %.9g want %.9g\n", k, x, y, c,
                                (double)ref[((size_t)y * w + x) * 4 + c], (double)want);
                        same = 0;
                    }
                }
        CHECK(same);
        free(ref);
    }
    /* a mask: outside as the input (made finite by the stack, as an empty stack does), inside
     * as without one; opacity 0: the identity */
    float *keep = run_pass(c1, f, "{\"version\":1,\"effects\":[]}", NULL);
    float *all = run_pass(c2, f, recipe("\"output\":\"gradient\"", NULL), NULL);
    float *m = run_pass(c2, f, recipe("\"output\":\"gradient\"", "{\"rect\":[5,7,40,30]}"), NULL);
    int ok = keep && all && m;
    for (int y = 0; ok && y < h; y++)
        for (int x = 0; x < w; x++) {
            const size_t i = ((size_t)y * w + x) * 4;
            const int in = x >= 5 && x < 45 && y >= 7 && y < 37;
            ok &= memcmp(m + i, in ? all + i : keep + i, 4 * sizeof(float)) == 0;
        }
    CHECK(ok);
    free(all);
    free(m);
    /* opacity 0: the identity (the finite rows bit for bit; the stack makes the rest finite) */
    m = run_pass(c1, f, recipe("\"output\":\"gradient\",\"opacity\":0", NULL), NULL);
    CHECK(m && memcmp(m, px, (size_t)w * 60 * 4 * sizeof(float)) == 0 && tu_all_finite(m, (size_t)w * h * 4));
    free(m);
    free(keep);
    /* an operator other than sobel: refused, naming the parameter */
    fx_stack *s = NULL;
    CHECK_OK(c1, fx_stack_new(c1, &s));
    CHECK(fx_stack_load_json(s, recipe("\"output\":\"gradient\",\"operator\":\"laplace4\"", NULL)) == FX_ERR_BAD_PARAM);
    CHECK(tu_contains(fx_context_error(c1), "operator"));
    fx_stack_free(s);
    fx_frame_free(f);
    free(px);
}

/* On a 1/2 proxy, line_width is halved (pixels): a line at least one proxy pixel wide keeps
 * the full opacity (2.1 -> 1.05: the most any pixel moves toward the line colour is exactly
 * opacity 0.5), a thinner one is drawn lighter by its width (1.0 -> 0.5: at most 0.25). */
static void test_proxy_opacity(fx_context *ctx)
{
    fx_frame *f = step_frame(ctx, 64, 16, 32, 0.1f, 0.9f), *px = NULL;
    CHECK_OK(ctx, fx_frame_reduce(f, 2, &px));
    const float *src = px ? et_combined(px) : NULL;
    const char *widths[2] = { "2.1", "1.0" };
    const float want[2] = { 0.5f, 0.25f };
    for (int k = 0; src && k < 2; k++) {
        char p[256];
        snprintf(p, sizeof p, "\"line_width\":%s,\"opacity\":0.5,\"softness\":0,\"line_color\":[0,1,0,1]", widths[k]);
        float *o = run_pass(ctx, px, recipe(p, NULL), NULL);
        float most = 0.0f;
        for (int i = 0; o && i < 32 * 8; i++) {
            const float s = src[4 * i + 1], frac = (o[4 * i + 1] - s) / (1.0f - s);
            most = frac > most ? frac : most;
        }
        CHECK(o && fabsf(most - want[k]) < 1e-5f);
        if (o && fabsf(most - want[k]) >= 1e-5f)
            fprintf(stderr, "proxy line_width %s: most %.6f, want %.6f\n", widths[k], most, want[k]);
        free(o);
    }
    fx_frame_free(px);
    fx_frame_free(f);
}

/* Rows wider than the drawing's lists of 256 chunks (2048 pixels): a pattern of period 64
 * gives the same output 2048 pixels further on (away from the borders), lines drawn there
 * as in the first list. */
static void test_wide_rows(fx_context *ctx)
{
    enum { W = 4400, H = 3 };
    float *px = malloc((size_t)W * H * 4 * sizeof(float));
    for (int i = 0; i < W * H; i++) {
        const float v = ((i % W) / 32) % 2 ? 0.9f : 0.1f;
        px[4 * i] = px[4 * i + 1] = px[4 * i + 2] = v;
        px[4 * i + 3] = 1;
    }
    fx_frame *f = et_frame(ctx, W, H, px);
    float *o = run_pass(ctx, f, recipe("\"line_width\":2,\"line_color\":[1,0,0,1]", NULL), NULL);
    int periodic = o != NULL, drawn_far = 0;
    for (int y = 0; o && y < H; y++)
        for (int x = 2048 + 64; x < W - 64; x++) { /* away from the frame's borders */
            const size_t i = (size_t)y * W + x;
            periodic &= memcmp(o + 4 * i, o + 4 * (i - 2048), 4 * sizeof(float)) == 0;
            drawn_far += o[4 * i] == 1.0f && o[4 * i + 1] == 0.0f;
        }
    CHECK(periodic && drawn_far > 0);
    if (!(periodic && drawn_far > 0))
        fprintf(stderr, "wide rows: periodic %d, drawn %d\n", periodic, drawn_far);
    free(o);
    fx_frame_free(f);
    free(px);
}

/* One non-finite pixel in the last pair of an 8-pixel chunk (lanes 6, 7), the rest of the
 * chunk finite: it is found and written finite like any other. */
static void test_nonfinite_last_pair(fx_context *ctx)
{
    enum { W = 16, H = 2 };
    float px[W * H * 4];
    for (int i = 0; i < W * H * 4; i++)
        px[i] = (i % 4) == 3 ? 1.0f : 0.5f;
    px[4 * 6] = INFINITY;             /* row 0, lane 6 */
    px[4 * 15 + 1] = NAN;             /* row 0, lane 7 of the second chunk */
    px[4 * (W + 7) + 2] = -INFINITY;  /* row 1, lane 7 */
    fx_frame *f = et_frame(ctx, W, H, px);
    const char *ps[] = { "\"line_color\":[1,0,0,1]", "\"luminance\":false,\"line_color\":[1,0,0,1]" };
    for (int k = 0; k < 2; k++) {
        float *o = run_pass(ctx, f, recipe(ps[k], NULL), NULL);
        CHECK(o && tu_all_finite(o, W * H * 4));
        free(o);
    }
    fx_frame_free(f);
}

int main(void)
{
    test_srgb_lut();
    fx_context *c1 = NULL, *c2 = NULL;
    fx_context_new(&c1, 1);
    fx_context_new(&c2, 2);
    test_kernels(c1);
    test_depth_normals(c1);
    test_depth_planar(c1);
    test_ids(c1);
    test_properties(c1, c2);
    test_extremes(c1);
    test_in_place(c1, c2);
    test_fast_path(c1);
    test_fast_path(c2);
    test_gradient(c1, c2);
    test_proxy_opacity(c1);
    test_wide_rows(c1);
    test_nonfinite_last_pair(c1);
    fx_context_free(c1);
    fx_context_free(c2);
    return tu_finish("test_edges");
}
