/* pixelate through the public API: slices pick centre samples, cells, average (coverage
 * weighted), identity, mask anchoring moves the grid with the object, extremes, threads. */
#include "fx_effect_test.h"

#include <float.h>
#include <math.h>

/* value = x + 100 y in R, y in G, x in B, 1 in A */
static float *gradient(int w, int h, int shift)
{
    float *p = malloc((size_t)w * h * 4 * sizeof(float));
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            float *q = p + ((size_t)y * w + x) * 4;
            q[0] = (float)(x - shift) + 100.0f * y;
            q[1] = (float)y;
            q[2] = (float)(x - shift);
            q[3] = 1.0f;
        }
    return p;
}

typedef struct { const char *mode; int columns, rows, cell, anchor_mask; const char *mask; } pset;

static float *run_px(fx_context *ctx, const float *px, int w, int h, pset p)
{
    fx_frame *f = et_frame(ctx, w, h, px);
    fx_stack *s = et_stack(ctx, "pixelate");
    float *o = NULL;
    if (fx_stack_set_enum(s, 0, "mode", p.mode) == FX_OK &&
        (!p.columns || fx_stack_set_int(s, 0, "columns", p.columns) == FX_OK) &&
        (!p.rows || fx_stack_set_int(s, 0, "rows", p.rows) == FX_OK) &&
        (!p.cell || fx_stack_set_int(s, 0, "cell_size", p.cell) == FX_OK) &&
        fx_stack_set_enum(s, 0, "anchor", p.anchor_mask ? "mask" : "image") == FX_OK &&
        (!p.mask || fx_stack_set_mask_json(s, 0, p.mask) == FX_OK))
        o = et_run(ctx, s, f);
    else
        fprintf(stderr, "setup: %s\n", fx_context_error(ctx));
    fx_stack_free(s);
    fx_frame_free(f);
    return o;
}

static void test_slices_and_cells(fx_context *ctx)
{
    int w = 40, h = 30;
    float *g = gradient(w, h, 0);
    /* 4 x 3 slices of 10 x 10: centre at pixel 4.5 -> mean of 4 and 5 */
    float *o = run_px(ctx, g, w, h, (pset){ "slices", 4, 3, 0, 0, NULL });
    int ok = o != NULL;
    for (int y = 0; o && y < h; y++)
        for (int x = 0; x < w; x++) {
            float cx = (x / 10) * 10 + 4.5f, cy = (y / 10) * 10 + 4.5f;
            const float *q = o + ((size_t)y * w + x) * 4;
            ok &= q[0] == cx + 100.0f * cy && q[1] == cy && q[2] == cx && q[3] == 1.0f;
        }
    CHECK(ok);
    free(o);
    /* uneven slices: 3 columns of 40 -> [0,13) [13,26) [26,40): centres 6, 19, 32.5 */
    o = run_px(ctx, g, w, h, (pset){ "slices", 3, 1, 0, 0, NULL });
    CHECK(o && o[2] == 6.0f && o[13 * 4 + 2] == 19.0f && o[39 * 4 + 2] == 32.5f && o[1] == 14.5f);
    free(o);
    /* cells of 5 (odd): the centre pixel exactly; the last partial row of cells clamps
     * its sample inside the image (rows 25..29 -> centre 27) */
    o = run_px(ctx, g, w, h, (pset){ "cells", 0, 0, 5, 0, NULL });
    ok = o != NULL;
    for (int y = 0; o && y < h; y++)
        for (int x = 0; x < w; x++)
            ok &= o[((size_t)y * w + x) * 4 + 2] == (float)((x / 5) * 5 + 2) &&
                  o[((size_t)y * w + x) * 4 + 1] == (float)((y / 5) * 5 + 2);
    CHECK(ok);
    free(o);
    /* cells of 16 on 40 px: the last cell [32, 48) has its centre 39.5 clamped to 39 */
    o = run_px(ctx, g, w, h, (pset){ "cells", 0, 0, 16, 0, NULL });
    CHECK(o && o[2] == 7.5f && o[35 * 4 + 2] == 39.0f);
    free(o);
    /* average of a linear ramp = its centre */
    o = run_px(ctx, g, w, h, (pset){ "average", 0, 0, 8, 0, NULL });
    CHECK(o && fabsf(o[2] - 3.5f) < 1e-6f && fabsf(o[(8 * w + 9) * 4 + 1] - 11.5f) < 1e-6f);
    free(o);
    /* identity: cell_size 1 (cells, average, anchored to a mask too), slices w x h */
    pset ids[] = { { "cells", 0, 0, 1, 0, NULL }, { "average", 0, 0, 1, 0, NULL },
                   { "cells", 0, 0, 1, 1, "{\"rect\": [3, 4, 17, 9]}" },
                   { "slices", 40, 30, 0, 0, NULL }, { "slices", 1000, 1000, 0, 0, NULL } };
    for (int k = 0; k < 5; k++) {
        o = run_px(ctx, g, w, h, ids[k]);
        CHECK(o && memcmp(o, g, (size_t)w * h * 16) == 0);
        free(o);
    }
    free(g);
}

static void test_mask(fx_context *ctx1, fx_context *ctx2)
{
    int w = 64, h = 48;
    /* average weighted by coverage: left of x = 21 red, right blue, mask covers x < 21 */
    float *px = malloc((size_t)w * h * 16);
    for (int i = 0; i < w * h; i++) {
        int x = i % w;
        float *q = px + (size_t)i * 4;
        q[0] = x < 21 ? 1.0f : 0.0f, q[1] = 0, q[2] = x < 21 ? 0.0f : 1.0f, q[3] = 1;
    }
    float *o = run_px(ctx1, px, w, h, (pset){ "average", 0, 0, 8, 0, "{\"rect\": [0, 0, 21, 48]}" });
    /* the cell [16, 24) straddles the edge: its masked pixels 16..20 stay pure red */
    CHECK(o && o[(5 * w + 18) * 4] == 1.0f && o[(5 * w + 18) * 4 + 2] == 0.0f);
    CHECK(o && et_outside_equal(o, px, w, h, 0, 0, 21, 48));
    free(o);
    free(px);
    /* anchor mask: moving object + mask by 3 px moves the output by 3 px */
    float *g0 = gradient(w, h, 0), *g3 = gradient(w, h, 3);
    float *o0 = run_px(ctx1, g0, w, h, (pset){ "cells", 0, 0, 6, 1, "{\"rect\": [10, 8, 25, 20]}" });
    float *o3 = run_px(ctx1, g3, w, h, (pset){ "cells", 0, 0, 6, 1, "{\"rect\": [13, 8, 25, 20]}" });
    int moved = o0 && o3;
    for (int y = 8; moved && y < 28; y++)
        for (int x = 10; x < 35; x++)
            moved &= memcmp(o0 + ((size_t)y * w + x) * 4, o3 + ((size_t)y * w + x + 3) * 4, 16) == 0;
    CHECK(moved);
    CHECK(o0 && et_outside_equal(o0, g0, w, h, 10, 8, 25, 20));
    free(o0);
    free(o3);
    /* ... while anchor image does not follow (the grid crawls) */
    o0 = run_px(ctx1, g0, w, h, (pset){ "cells", 0, 0, 6, 0, "{\"rect\": [10, 8, 25, 20]}" });
    o3 = run_px(ctx1, g3, w, h, (pset){ "cells", 0, 0, 6, 0, "{\"rect\": [13, 8, 25, 20]}" });
    moved = o0 && o3;
    for (int y = 8; moved && y < 28; y++)
        for (int x = 10; x < 35; x++)
            moved &= memcmp(o0 + ((size_t)y * w + x) * 4, o3 + ((size_t)y * w + x + 3) * 4, 16) == 0;
    CHECK(!moved);
    free(o0);
    free(o3);
    /* thread invariance, every mode */
    pset modes[] = { { "slices", 7, 5, 0, 0, NULL }, { "cells", 0, 0, 7, 0, NULL },
                     { "average", 0, 0, 7, 0, NULL }, { "average", 0, 0, 4, 1, "{\"rect\": [9, 9, 30, 20]}" } };
    for (int k = 0; k < 4; k++) {
        float *a = run_px(ctx1, g0, w, h, modes[k]), *b = run_px(ctx2, g0, w, h, modes[k]);
        CHECK(a && b && memcmp(a, b, (size_t)w * h * 16) == 0);
        free(a);
        free(b);
    }
    free(g0);
    free(g3);
    /* huge values: finite */
    px = malloc((size_t)w * h * 16);
    for (int i = 0; i < w * h * 4; i++)
        px[i] = i % 2 ? FLT_MAX : 1e38f;
    for (int k = 0; k < 4; k++) {
        float *a = run_px(ctx2, px, w, h, modes[k]);
        CHECK(a && tu_all_finite(a, (size_t)w * h * 4));
        free(a);
    }
    free(px);
    /* 1x1 and 1xN */
    float one[4] = { 0.1f, 0.2f, 0.3f, 0.4f };
    o = run_px(ctx1, one, 1, 1, (pset){ "average", 0, 0, 16, 0, NULL });
    CHECK(o && memcmp(o, one, 16) == 0);
    free(o);
    o = run_px(ctx1, one, 1, 1, (pset){ "slices", 32, 18, 0, 0, NULL });
    CHECK(o && memcmp(o, one, 16) == 0);
    free(o);
}

/* In place (a consumed frame: the output written over the input's Combined,
 * FX_EFFECT_IN_PLACE) equals the separate-buffer run bit for bit: slices (even, uneven, a
 * slice per pixel), cells odd and even with partial cells at the borders, average, anchored
 * to a mask (a second buffer then), 1 and 2 threads; without a mask no second buffer. */
static void test_in_place(fx_context *c1, fx_context *c2)
{
    const int w = 61, h = 47;
    pset sets[] = { { "slices", 4, 3, 0, 0, NULL }, { "slices", 37, 21, 0, 0, NULL }, { "slices", 61, 2, 0, 0, NULL },
                    { "cells", 0, 0, 5, 0, NULL }, { "cells", 0, 0, 16, 0, NULL }, { "average", 0, 0, 7, 0, NULL },
                    { "average", 0, 0, 64, 0, NULL }, { "cells", 0, 0, 6, 1, "{\"rect\": [10, 8, 25, 20]}" },
                    { "average", 0, 0, 4, 1, "{\"rect\": [9, 9, 30, 20]}" } };
    float *g = gradient(w, h, 2);
    for (int i = 0; i < w * h; i++)
        g[4 * i + 3] = 0.25f + 0.01f * (float)(i % 37); /* alpha varies too */
    for (int t = 0; t < 2; t++)
        for (int k = 0; k < (int)(sizeof sets / sizeof sets[0]); k++) {
            fx_context *ctx = t ? c2 : c1;
            float *sep = run_px(ctx, g, w, h, sets[k]);
            fx_frame *f = et_frame(ctx, w, h, g);
            fx_stack *s = et_stack(ctx, "pixelate");
            CHECK_OK(ctx, fx_stack_set_enum(s, 0, "mode", sets[k].mode));
            if (sets[k].columns)
                CHECK_OK(ctx, fx_stack_set_int(s, 0, "columns", sets[k].columns));
            if (sets[k].rows)
                CHECK_OK(ctx, fx_stack_set_int(s, 0, "rows", sets[k].rows));
            if (sets[k].cell)
                CHECK_OK(ctx, fx_stack_set_int(s, 0, "cell_size", sets[k].cell));
            CHECK_OK(ctx, fx_stack_set_enum(s, 0, "anchor", sets[k].anchor_mask ? "mask" : "image"));
            if (sets[k].mask)
                CHECK_OK(ctx, fx_stack_set_mask_json(s, 0, sets[k].mask));
            /* f is consumed; no mask: written over it. sep (run_px, the parameters' own run)
             * pins the stack's separate-buffer run too */
            float *kept = et_run(ctx, s, f);
            int ok = sep && kept && memcmp(sep, kept, (size_t)w * h * 16) == 0 &&
                     et_in_place_equal(ctx, s, f, !sets[k].mask);
            if (!ok)
                fprintf(stderr, "pixelate in place differs: threads %d, set %d\n", t + 1, k);
            CHECK(ok);
            fx_stack_free(s);
            free(kept);
            free(sep);
        }
    free(g);
}

int main(void)
{
    fx_context *c1 = NULL, *c2 = NULL;
    if (fx_context_new(&c1, 1) != FX_OK || fx_context_new(&c2, 2) != FX_OK)
        return 1;
    test_slices_and_cells(c1);
    test_mask(c1, c2);
    test_in_place(c1, c2);
    fx_context_free(c1);
    fx_context_free(c2);
    return tu_finish("test_pixelate");
}
