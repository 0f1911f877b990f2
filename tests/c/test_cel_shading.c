/* cel_shading through the public API: diffuse-pass re-banding keeps texture and the other
 * light, N.L with a direction, outlines from depth, passes declared per params, identity,
 * masks, extremes, thread invariance. */
#include "fx_effect_test.h"

#include <float.h>
#include <math.h>

static float *run_frame(fx_context *ctx, const fx_frame *f, const char *params, const char *mask)
{
    return et_run_effect(ctx, "cel_shading", f, params, mask);
}

/* w x 1: DiffDir ramps 0..1 (white light), DiffCol 0.5 red-ish, Combined = col x dir + 0.1 */
static fx_frame *diffuse_frame(fx_context *ctx, int w, int h)
{
    fx_frame *f = NULL;
    fx_frame_new(ctx, w, h, &f);
    float *c = malloc((size_t)w * h * 4 * sizeof(float)), *dd = malloc((size_t)w * h * 3 * sizeof(float)),
          *dc = malloc((size_t)w * h * 3 * sizeof(float)), *dep = malloc((size_t)w * h * sizeof(float)),
          *n = malloc((size_t)w * h * 3 * sizeof(float));
    for (int i = 0; i < w * h; i++) {
        float l = ((float)(i % w) + 0.5f) / (float)w;
        const float col[3] = { 0.8f, 0.4f, 0.2f };
        for (int k = 0; k < 3; k++) {
            dd[3 * i + k] = l;
            dc[3 * i + k] = col[k];
            c[4 * i + k] = col[k] * l + 0.1f;
            n[3 * i + k] = k == 2 ? 1.0f : 0.0f;
        }
        c[4 * i + 3] = 1;
        dep[i] = 5.0f;
    }
    fx_frame_add_pass(f, "Combined", 4, c);
    fx_frame_add_pass(f, "DiffDir", 3, dd);
    fx_frame_add_pass(f, "DiffCol", 3, dc);
    fx_frame_add_pass(f, "Depth", 1, dep);
    fx_frame_add_pass(f, "Normal", 3, n);
    free(c);
    free(dd);
    free(dc);
    free(dep);
    free(n);
    return f;
}

static void test_values(fx_context *ctx)
{
    const int w = 30;
    fx_frame *f = diffuse_frame(ctx, w, 1);
    float *o = run_frame(ctx, f, "\"bands\":3,\"band_softness\":0,\"outline_width\":0", NULL);
    int ok = o != NULL;
    const float col[3] = { 0.8f, 0.4f, 0.2f };
    for (int x = 0; ok && x < w; x++) {
        float l = ((float)x + 0.5f) / (float)w;
        float q = l < 1.0f / 3 ? 0.0f : l < 2.0f / 3 ? 0.5f : 1.0f;
        for (int k = 0; k < 3; k++)
            ok &= fabsf(o[4 * x + k] - (col[k] * q + 0.1f)) < 1e-5f;
    }
    CHECK(ok); /* texture (DiffCol) and the other light (0.1) survive, direct light banded */
    free(o);
    o = run_frame(ctx, f, "\"bands\":2,\"ramp_mode\":\"custom\",\"ramp\":[0.25,0.75,0,0,0,0,0,0],\"band_softness\":0,\"outline_width\":0", NULL);
    CHECK(o && fabsf(o[0] - (0.8f * 0.25f + 0.1f)) < 1e-5f && fabsf(o[4 * (w - 1)] - (0.8f * 0.75f + 0.1f)) < 1e-5f);
    free(o);
    /* N.L with a direction straight down onto +Z normals: l = 1 -> top band, ratio 1 */
    o = run_frame(ctx, f, "\"lighting\":\"normal_light\",\"use_direction\":true,\"direction\":[0,0,-1],\"outline_width\":0", NULL);
    int same = o != NULL; /* every pixel, every channel (alpha too): the input */
    for (int i = 0; same && i < w * 4; i++)
        same &= fabsf(o[i] - et_combined(f)[i]) < 1e-5f;
    CHECK(same);
    free(o);
    /* light at 60 degrees: l = 0.5 -> band 1 of 3 (0.5): ratio (0.15 + 0.5) / (0.15 + 0.5) */
    o = run_frame(ctx, f, "\"lighting\":\"normal_light\",\"use_direction\":true,\"direction\":[0.8660254,0,-0.5],\"band_softness\":0,\"outline_width\":0,\"bands\":2", NULL);
    /* bands 2: l = 0.5 -> band 1 -> q = 1: ratio (0.15 + 1) / (0.15 + 0.5) */
    CHECK(o && fabsf(o[0] - et_combined(f)[0] * (1.15f / 0.65f)) < 1e-4f);
    free(o);
    /* no lights in the frame and no direction: a clear error */
    fx_stack *s = NULL;
    fx_frame *out = NULL;
    fx_stack_new(ctx, &s);
    fx_stack_load_json(s, "{\"version\":1,\"effects\":[{\"effect\":\"cel_shading\",\"params\":{\"lighting\":\"normal_light\"}}]}");
    CHECK(fx_stack_run(s, f, &out) != FX_OK && strlen(fx_context_error(ctx)) > 0);
    /* passes declared per params */
    char *req = NULL;
    fx_stack_required_passes(s, &req);
    CHECK(req && tu_contains(req, "Normal") && !tu_contains(req, "DiffDir") && tu_contains(req, "Depth"));
    fx_free(req);
    fx_stack_set_enum(s, 0, "lighting", "diffuse_passes");
    fx_stack_set_float(s, 0, "outline_width", 0);
    fx_stack_required_passes(s, &req);
    CHECK(req && tu_contains(req, "DiffDir") && tu_contains(req, "DiffCol") && !tu_contains(req, "Depth") && !tu_contains(req, "Normal"));
    fx_free(req);
    fx_stack_free(s);
    fx_frame_free(f);
}

static void test_outlines_properties(fx_context *c1, fx_context *c2)
{
    const int w = 40, h = 30;
    fx_frame *f = diffuse_frame(c1, w, h);
    float *dep = NULL;
    int ch = 0;
    fx_frame_pass(f, "Depth", &dep, &ch);
    for (int y = 10; y < 20; y++)
        for (int x = 12; x < 28; x++)
            dep[y * w + x] = 2.0f; /* a box in front */
    float *o = run_frame(c1, f, "\"outline_width\":2,\"outline_color\":[0,0,1,1],\"normal_sensitivity\":0", NULL);
    CHECK(o && o[(10 * w + 20) * 4 + 2] == 1.0f && o[(10 * w + 20) * 4] == 0.0f); /* on the box's edge */
    CHECK(o && o[(15 * w + 20) * 4 + 2] != 1.0f);                                  /* inside: no line */
    free(o);
    size_t n = (size_t)w * h * 4;
    const float *src = et_combined(f);
    float *a = run_frame(c1, f, "\"outline_width\":3", NULL), *b = run_frame(c2, f, "\"outline_width\":3", NULL);
    CHECK(a && b && memcmp(a, b, n * sizeof(float)) == 0);
    float *m = run_frame(c2, f, "\"outline_width\":3", "{\"rect\":[5,5,20,10]}");
    CHECK(m && et_outside_equal(m, src, w, h, 5, 5, 20, 10));
    free(a);
    free(b);
    free(m);
    o = run_frame(c1, f, "\"mix\":0", NULL);
    CHECK(o && memcmp(o, src, n * sizeof(float)) == 0);
    free(o);
    fx_frame_free(f);
}

/* In place (a consumed frame: the output is the input's buffer, FX_EFFECT_IN_PLACE) equals
 * the separate-buffer run bit for bit, for 1 and 2 threads, both lightings, outlines across
 * the edge engine's 32-row bands, and a width off the 8-pixel vectors. */
static void test_in_place(fx_context *c1, fx_context *c2)
{
    const int w = 45, h = 77;
    const char *params[] = { "\"outline_width\":3", "\"outline_width\":0,\"band_softness\":0",
                             "\"lighting\":\"normal_light\",\"use_direction\":true,\"direction\":[0.3,0.2,-0.9]",
                             "\"mix\":0.6,\"outline_color\":[1,0,0,0.5]" };
    for (int k = 0; k < 4; k++)
        for (int t = 0; t < 2; t++) {
            fx_context *ctx = t ? c2 : c1;
            fx_frame *f = diffuse_frame(ctx, w, h);
            float *dep = NULL, *nrm = NULL;
            int ch = 0;
            fx_frame_pass(f, "Depth", &dep, &ch);
            fx_frame_pass(f, "Normal", &nrm, &ch);
            for (int y = 20; y < 60; y++)
                for (int x = 10; x < 33; x++) {
                    dep[y * w + x] = 2.0f + 0.01f * (float)x; /* a box in front, across bands */
                    nrm[3 * (y * w + x)] = y < 40 ? 0.6f : -0.6f;
                    nrm[3 * (y * w + x) + 2] = 0.8f;
                }
            char buf[512];
            snprintf(buf, sizeof buf, "{\"version\":1,\"effects\":[{\"effect\":\"cel_shading\",\"params\":{%s}}]}",
                     params[k]);
            fx_stack *s = NULL;
            CHECK_OK(ctx, fx_stack_new(ctx, &s));
            CHECK_OK(ctx, fx_stack_load_json(s, buf));
            CHECK(et_in_place_equal(ctx, s, f, 1)); /* f is consumed */
            fx_stack_free(s);
        }
}

static void test_extremes(fx_context *ctx)
{
    const float bad[] = { NAN, INFINITY, -INFINITY, 1e38f, -1e38f, 1e-40f, 0.0f, FLT_MAX };
    fx_frame *f = diffuse_frame(ctx, 9, 5);
    const char *names[] = { "Combined", "DiffDir", "DiffCol", "Depth", "Normal" };
    for (int p = 0; p < 5; p++) {
        float *d = NULL;
        int ch = 0;
        fx_frame_pass(f, names[p], &d, &ch);
        for (int i = 0; i < 9 * 5 * ch; i++)
            d[i] = bad[(i * 3 + p) % 8];
    }
    const char *ps[] = { "", "\"lighting\":\"normal_light\",\"use_direction\":true", "\"bands\":1,\"outline_width\":64",
                         "\"white\":1e-6,\"band_softness\":0" };
    for (int k = 0; k < 4; k++) {
        float *o = run_frame(ctx, f, ps[k], NULL);
        CHECK(o && tu_all_finite(o, 9 * 5 * 4));
        free(o);
    }
    fx_frame_free(f);
    f = diffuse_frame(ctx, 1, 1);
    float *o = run_frame(ctx, f, "\"outline_width\":64", NULL);
    CHECK(o && tu_all_finite(o, 4));
    free(o);
    fx_frame_free(f);
}

/* Soft band edges (band_softness 0.02: each step is a smoothstep over [k/n - 0.01, k/n +
 * 0.01]) and hard ones (0): away from the edges the ramp takes its band's value, and light
 * at or above white takes the top value (1) on every pixel, in the 8-pixel lanes and in the
 * tail (w = 19). */
static void test_soft_bands(fx_context *ctx)
{
    const int w = 19;
    fx_frame *f = diffuse_frame(ctx, w, 2);
    float *dd = NULL, *c = NULL;
    int ch = 0;
    fx_frame_pass(f, "DiffDir", &dd, &ch);
    fx_frame_pass(f, "Combined", &c, &ch);
    const float col[3] = { 0.8f, 0.4f, 0.2f };
    for (int x = 0; x < w; x++) { /* row 1: light 1.0, 1.5 and 2.0 (white 1) */
        const float l = 1.0f + 0.5f * (float)(x % 3);
        for (int k = 0; k < 3; k++) {
            dd[3 * (w + x) + k] = l;
            c[4 * (w + x) + k] = col[k] * l + 0.1f;
        }
    }
    const char *ps[2] = { "\"bands\":3,\"band_softness\":0.02,\"outline_width\":0",
                          "\"bands\":3,\"band_softness\":0,\"outline_width\":0" };
    for (int k2 = 0; k2 < 2; k2++) {
        float *o = run_frame(ctx, f, ps[k2], NULL);
        int ok = o != NULL, checked = 0;
        for (int y = 0; ok && y < 2; y++)
            for (int x = 0; x < w; x++) {
                const float l = dd[3 * (y * w + x)];
                if (fabsf(l - 1.0f / 3) < 0.011f || fabsf(l - 2.0f / 3) < 0.011f)
                    continue; /* within a soft edge */
                const float q = l < 1.0f / 3 ? 0.0f : l < 2.0f / 3 ? 0.5f : 1.0f;
                for (int k = 0; k < 3; k++)
                    ok &= fabsf(o[4 * (y * w + x) + k] - (col[k] * q + 0.1f)) < 1e-5f;
                checked++;
            }
        CHECK(ok && checked >= 2 * w - 2);
        free(o);
    }
    fx_frame_free(f);
}

/* An outline pixel takes the outline colour (all four channels) in the 8-pixel lanes and in
 * the per-pixel tail: a box whose left edge is in the lanes and right edge in the tail of a
 * 43-pixel row (x 40..42). */
static void test_outline_tail(fx_context *ctx)
{
    const int w = 43, h = 30;
    fx_frame *f = diffuse_frame(ctx, w, h);
    float *dep = NULL;
    int ch = 0;
    fx_frame_pass(f, "Depth", &dep, &ch);
    for (int y = 10; y < 20; y++)
        for (int x = 12; x < 41; x++)
            dep[y * w + x] = 2.0f;
    float *o = run_frame(ctx, f, "\"outline_width\":2,\"outline_color\":[0,0,1,0.5],\"normal_sensitivity\":0", NULL);
    int left = 0, right = 0;
    for (int y = 12; o && y < 18; y++)
        for (int x = 0; x < w; x++) {
            const float *p = o + 4 * (y * w + x);
            const int full = fabsf(p[0]) < 1e-6f && fabsf(p[1]) < 1e-6f && fabsf(p[2] - 1) < 1e-6f &&
                             fabsf(p[3] - 0.5f) < 1e-6f;
            left += full && x < 16;
            right += full && x >= 40;
        }
    CHECK(o && left > 0 && right > 0);
    free(o);
    fx_frame_free(f);
}

int main(void)
{
    fx_context *c1 = NULL, *c2 = NULL;
    fx_context_new(&c1, 1);
    fx_context_new(&c2, 2);
    test_values(c1);
    test_soft_bands(c1);
    test_outline_tail(c1);
    test_outlines_properties(c1, c2);
    test_extremes(c1);
    test_in_place(c1, c2);
    fx_context_free(c1);
    fx_context_free(c2);
    return tu_finish("test_cel_shading");
}
