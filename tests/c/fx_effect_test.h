/* Helpers shared by the effect tests (test_gaussian_blur, test_color_matrix, test_pixelate, ...):
 * run one effect through the public stack API on a frame built from pixels. Header-only
 * (static functions) so each test stays one CTest executable. */
#ifndef LIBFX_FX_EFFECT_TEST_H
#define LIBFX_FX_EFFECT_TEST_H

#include "testutil.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static inline fx_frame *et_frame(fx_context *ctx, int w, int h, const float *rgba)
{
    fx_frame *f = NULL;
    if (fx_frame_new(ctx, w, h, &f) != FX_OK)
        return NULL;
    if (fx_frame_add_pass(f, "Combined", 4, rgba) != FX_OK) {
        fx_frame_free(f);
        return NULL;
    }
    return f;
}

/* An aux view's EXR as the add-on writes one (probe, planar view): Combined from rgba and
 * a Depth pass from dep, w x h. */
static inline void et_write_view(fx_context *ctx, const char *path, int w, int h, const float *rgba,
                                 const float *dep)
{
    fx_frame *f = et_frame(ctx, w, h, rgba);
    CHECK(f != NULL);
    CHECK_OK(ctx, fx_frame_add_pass(f, "Depth", 1, dep));
    CHECK_OK(ctx, fx_frame_write_exr(f, path, NULL));
    fx_frame_free(f);
}

/* world_to_camera = R^T T(-pos) for a camera at pos whose axes are R's columns (row-major
 * 3x3): the 4x4 row-major matrix the sidecar and fx_camera hold. */
static inline void et_world_to_camera(const double R[9], const double pos[3], float m[16])
{
    memset(m, 0, 16 * sizeof(float));
    for (int i = 0; i < 3; i++) {
        double t = 0;
        for (int k = 0; k < 3; k++) {
            m[i * 4 + k] = (float)R[k * 3 + i];
            t -= R[k * 3 + i] * pos[k];
        }
        m[i * 4 + 3] = (float)t;
    }
    m[15] = 1;
}

/* A perspective camera as Blender's (OpenGL projection): tan_half the tangent of half the
 * vertical field of view, w x h pixels, clip planes nn and ff, seen through world_to_camera
 * w2c. */
static inline void et_perspective(fx_camera *c, const float w2c[16], double tan_half, int w, int h, double nn,
                                  double ff)
{
    memset(c, 0, sizeof *c);
    c->size = sizeof *c;
    memcpy(c->world_to_camera, w2c, 16 * sizeof(float));
    double fy = 1.0 / tan_half, asp = (double)w / h;
    c->projection[0] = (float)(fy / asp);
    c->projection[5] = (float)fy;
    c->projection[10] = (float)((ff + nn) / (nn - ff));
    c->projection[11] = (float)(2 * ff * nn / (nn - ff));
    c->projection[14] = -1;
    c->clip_start = (float)nn;
    c->clip_end = (float)ff;
}

/* Lists a reflection probe (an equirect panorama EXR at path, seen from world_to_camera
 * w2c) among the frame's aux views, as the add-on's sidecar does. */
static inline void et_add_probe(fx_context *ctx, fx_frame *f, const char *name, const char *path,
                                const float w2c[16])
{
    char json[4096];
    int n = snprintf(json, sizeof json, "{\"aux_views\": [{\"name\": \"%s\", \"path\": \"%s\", \"world_to_camera\": [",
                     name, path);
    for (int i = 0; i < 16; i++)
        n += snprintf(json + n, sizeof json - n, "%s%.9g", i ? ", " : "", w2c[i]);
    snprintf(json + n, sizeof json - n,
             "], \"projection\": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1], \"clip_start\": 0, \"clip_end\": 1e6, "
             "\"orthographic\": false, \"kind\": \"probe\", \"panorama\": \"equirect\"}]}");
    CHECK_OK(ctx, fx_frame_apply_sidecar(f, json));
}

static inline const float *et_combined(const fx_frame *f)
{
    float *d = NULL;
    int c = 0;
    if (!f || fx_frame_pass(f, "Combined", &d, &c) != FX_OK || c != 4)
        return NULL;
    return d;
}

/* A stack holding one effect; the caller sets parameters on index 0. */
static inline fx_stack *et_stack(fx_context *ctx, const char *effect)
{
    fx_stack *s = NULL;
    int idx = -1;
    if (fx_stack_new(ctx, &s) != FX_OK)
        return NULL;
    if (fx_stack_append(s, effect, &idx) != FX_OK || idx != 0) {
        fprintf(stderr, "append %s: %s\n", effect, fx_context_error(ctx));
        fx_stack_free(s);
        return NULL;
    }
    return s;
}

/* Runs s on in; returns a malloc'ed copy of the output Combined (NULL on failure). */
static inline float *et_run(fx_context *ctx, fx_stack *s, const fx_frame *in)
{
    fx_frame *out = NULL;
    if (fx_stack_run(s, in, &out) != FX_OK) {
        fprintf(stderr, "fx_stack_run: %s\n", fx_context_error(ctx));
        return NULL;
    }
    const float *d = et_combined(out);
    size_t n = (size_t)fx_frame_width(out) * fx_frame_height(out) * 4;
    float *copy = d ? malloc(n * sizeof(float)) : NULL;
    if (copy)
        memcpy(copy, d, n * sizeof(float));
    fx_frame_free(out);
    return copy;
}

/* In place: s run on f as the CLI and the add-on run it (fx_stack_run_consume, which takes f)
 * gives the bits of the run that keeps its input (et_run), and with `shared` writes over f's
 * own Combined (no second frame-sized buffer). f's Combined must not have been handed out
 * writable (such a pass is never consumed). 1 when both hold. */
static inline int et_in_place_equal(fx_context *ctx, fx_stack *s, fx_frame *f, int shared)
{
    const size_t n = (size_t)fx_frame_width(f) * fx_frame_height(f) * 4;
    float *sep = et_run(ctx, s, f);
    const float *given = NULL;
    fx_frame_pass_read(f, "Combined", &given, NULL);
    fx_frame *out = NULL;
    if (fx_stack_run_consume(s, f, 0, &out) != FX_OK)
        fprintf(stderr, "fx_stack_run_consume: %s\n", fx_context_error(ctx));
    const float *ip = out ? et_combined(out) : NULL;
    const int ok = sep && ip && memcmp(sep, ip, n * sizeof(float)) == 0 && (!shared || ip == given);
    fx_frame_free(out);
    free(sep);
    return ok;
}

/* Runs one effect with the given params (the inside of a JSON object, e.g. "\"sigma\": 2")
 * and optional mask JSON on frame f; returns a malloc'ed copy of the output Combined. */
static inline float *et_run_effect(fx_context *ctx, const char *effect, const fx_frame *f, const char *params,
                                   const char *mask)
{
    char buf[2048];
    snprintf(buf, sizeof buf, "{\"version\":1,\"effects\":[{\"effect\":\"%s\",\"params\":{%s}%s%s}]}",
             effect, params, mask ? ",\"mask\":" : "", mask ? mask : "");
    fx_stack *s = NULL;
    float *o = NULL;
    if (f && fx_stack_new(ctx, &s) == FX_OK && fx_stack_load_json(s, buf) == FX_OK)
        o = et_run(ctx, s, f);
    else
        fprintf(stderr, "setup: %s\n", fx_context_error(ctx));
    fx_stack_free(s);
    return o;
}

/* The same on a w x h frame with Combined = px. */
static inline float *et_run_effect_px(fx_context *ctx, const char *effect, const float *px, int w, int h,
                                      const char *params, const char *mask)
{
    fx_frame *f = et_frame(ctx, w, h, px);
    float *o = et_run_effect(ctx, effect, f, params, mask);
    fx_frame_free(f);
    return o;
}

/* 1 if every pixel outside rect [x, y, w, h] is bit-identical in a and b. */
static inline int et_outside_equal(const float *a, const float *b, int W, int H, int rx, int ry, int rw, int rh)
{
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            if (x >= rx && x < rx + rw && y >= ry && y < ry + rh)
                continue;
            if (memcmp(a + ((size_t)y * W + x) * 4, b + ((size_t)y * W + x) * 4, 4 * sizeof(float)))
                return 0;
        }
    return 1;
}

#endif
