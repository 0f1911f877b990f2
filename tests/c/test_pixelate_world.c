/* pixelate anchor "world": the grid follows a world point through a camera pan (cells stay
 * on the object) even when the mask's silhouette changes; anchor "mask" shifts with the
 * bounds instead. Needs the camera; falls back to the mask's bounds when the point is
 * behind the camera. */
#include "fx_effect_test.h"

#include <math.h>

#define N 64
#define SHIFT 5

static const char *sidecar(double cam_x, char *buf, size_t n)
{
    /* camera looking down -Z at x = cam_x; f = 1, square: a point at depth 2 moves 16 px per unit */
    snprintf(buf, n,
             "{\"world_to_camera\": [[1,0,0,%.17g],[0,1,0,0],[0,0,1,0],[0,0,0,1]],"
             " \"projection\": [[1,0,0,0],[0,1,0,0],[0,0,-1.002002,-0.2002002],[0,0,-1,0]],"
             " \"clip_start\": 0.1, \"clip_end\": 100}", -cam_x);
    return buf;
}

static fx_frame *frame_at(fx_context *ctx, int shift, double cam_x)
{
    float *px = malloc((size_t)N * N * 4 * sizeof(float));
    float *pos = malloc((size_t)N * N * 3 * sizeof(float));
    for (int y = 0; y < N; y++)
        for (int x = 0; x < N; x++) {
            float *q = px + ((size_t)y * N + x) * 4;
            int u = x - shift;
            q[0] = (float)(u * 7 % 23);
            q[1] = (float)(y * 5 % 19);
            q[2] = (float)((u + y) % 11);
            q[3] = 1;
            float *p = pos + ((size_t)y * N + x) * 3;
            p[0] = 0;
            p[1] = 0;
            p[2] = -2;
        }
    fx_frame *f = et_frame(ctx, N, N, px);
    char json[512];
    if (f && (fx_frame_add_pass(f, "Position", 3, pos) != FX_OK || fx_frame_apply_sidecar(f, sidecar(cam_x, json, sizeof json)) != FX_OK)) {
        fx_frame_free(f);
        f = NULL;
    }
    free(px);
    free(pos);
    return f;
}

static float *run_anchor(fx_context *ctx, fx_frame *f, const char *anchor, int auto_point, const char *mask)
{
    fx_stack *s = et_stack(ctx, "pixelate");
    float wp[3] = {0, 0, -2};
    float *o = NULL;
    if (fx_stack_set_enum(s, 0, "mode", "cells") == FX_OK && fx_stack_set_int(s, 0, "cell_size", 6) == FX_OK &&
        fx_stack_set_enum(s, 0, "anchor", anchor) == FX_OK && fx_stack_set_int(s, 0, "world_point_auto", auto_point) == FX_OK &&
        fx_stack_set_floats(s, 0, "world_point", wp, 3) == FX_OK && fx_stack_set_mask_json(s, 0, mask) == FX_OK)
        o = et_run(ctx, s, f);
    else
        fprintf(stderr, "setup: %s\n", fx_context_error(ctx));
    fx_stack_free(s);
    return o;
}

/* out2 at (x + SHIFT, y) equals out1 at (x, y) over the object's common area */
static int follows(const float *o1, const float *o2)
{
    for (int y = 20; y < 36; y++)
        for (int x = 20; x < 36; x++)
            if (memcmp(o1 + ((size_t)y * N + x) * 4, o2 + ((size_t)y * N + x + SHIFT) * 4, 4 * sizeof(float)))
                return 0;
    return 1;
}

int main(void)
{
    fx_context *ctx = NULL;
    if (fx_context_new(&ctx, 2) != FX_OK)
        return 1;
    fx_frame *f1 = frame_at(ctx, 0, 0.0), *f2 = frame_at(ctx, SHIFT, -SHIFT / 16.0);
    CHECK(f1 && f2);
    /* frame 2's silhouette has one more column on the left (a hand coming into view) */
    const char *m1 = "{\"rect\": [20, 20, 16, 16]}", *m2 = "{\"rect\": [24, 20, 17, 16]}";
    for (int au = 0; au < 2; au++) {
        float *a = run_anchor(ctx, f1, "world", au, m1), *b = run_anchor(ctx, f2, "world", au, m2);
        CHECK(a && b && follows(a, b));
        free(a);
        free(b);
    }
    float *a = run_anchor(ctx, f1, "mask", 0, m1), *b = run_anchor(ctx, f2, "mask", 0, m2);
    CHECK(a && b && !follows(a, b)); /* the bounds' midpoint moved by 4.5 px, not 5 */
    free(a);
    free(b);
    /* behind the camera: falls back to the mask anchor, no failure */
    fx_stack *s = et_stack(ctx, "pixelate");
    float behind[3] = {0, 0, 5};
    CHECK_OK(ctx, fx_stack_set_enum(s, 0, "mode", "cells"));
    CHECK_OK(ctx, fx_stack_set_int(s, 0, "cell_size", 6));
    CHECK_OK(ctx, fx_stack_set_enum(s, 0, "anchor", "world"));
    CHECK_OK(ctx, fx_stack_set_int(s, 0, "world_point_auto", 0));
    CHECK_OK(ctx, fx_stack_set_floats(s, 0, "world_point", behind, 3));
    CHECK_OK(ctx, fx_stack_set_mask_json(s, 0, m1));
    float *c = et_run(ctx, s, f1);
    float *d = run_anchor(ctx, f1, "mask", 0, m1);
    CHECK(c && d && memcmp(c, d, (size_t)N * N * 4 * sizeof(float)) == 0);
    free(c);
    free(d);
    /* no camera: a clear error */
    fx_frame *bare = et_frame(ctx, N, N, et_combined(f1));
    fx_frame *out = NULL;
    CHECK_FAIL(ctx, fx_stack_run(s, bare, &out), FX_ERR_NO_CAMERA, "camera");
    fx_frame_free(out);
    fx_frame_free(bare);
    fx_stack_free(s);
    fx_frame_free(f1);
    fx_frame_free(f2);
    fx_context_free(ctx);
    return tu_finish("test_pixelate_world");
}
