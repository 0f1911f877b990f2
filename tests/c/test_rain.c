/* rain, wet_surfaces, rain_splashes on synthetic frames with a synthetic rain map: rain
 * draws nothing in front of nearer geometry or under cover; the same frame twice gives
 * the same bits (and any thread count); splashes and wetness only on exposed (up-facing)
 * pixels; finite output; clear errors without a rain map. */
#include "fx_effect_test.h"

#include "scene/aux_map.h"
#include "core/mask.h"

#include <math.h>

#define N 64

static void ortho(fx_camera *c, const float w2c[16], float half, float n, float f)
{
    memset(c, 0, sizeof *c);
    c->size = sizeof *c;
    memcpy(c->world_to_camera, w2c, 16 * sizeof(float));
    float p[16] = {1 / half, 0, 0, 0, 0, 1 / half, 0, 0, 0, 0, -2 / (f - n), -(f + n) / (f - n), 0, 0, 0, 1};
    memcpy(c->projection, p, sizeof p);
    c->clip_start = n;
    c->clip_end = f;
    c->orthographic = 1;
}

/* The frames' camera: orthographic, 10 m wide, at (0, -10, 1) looking along +y, world z up. */
static void set_ground_camera(fx_frame *f)
{
    float w2c[16] = {1, 0, 0, 0, 0, 0, 1, -1, 0, -1, 0, -10, 0, 0, 0, 1};
    fx_camera cam;
    ortho(&cam, w2c, 5.0f, 0.1f, 100.0f);
    fx_frame_set_camera(f, &cam);
}

/* Rain map: top-down from z = 40 over x, y in [-20, 20]; cover at height `roof_z` where
 * world y < roof_y (else ground at 0). */
static const char *rain_map(fx_context *ctx, float roof_y, float roof_z, fx_camera *cam, const char *name)
{
    static char path[512];
    snprintf(path, sizeof path, "%s/%s.exr", tu_tmpdir("rain_maps"), name);
    float w2c[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, -40, 0, 0, 0, 1};
    ortho(cam, w2c, 20.0f, 1.0f, 60.0f);
    float *d = malloc(N * N * sizeof(float));
    for (int y = 0; y < N; y++) {
        float wy = 20.0f - (y + 0.5f) * 40.0f / N;
        for (int x = 0; x < N; x++)
            d[y * N + x] = 40.0f - (wy < roof_y ? roof_z : 0.0f);
    }
    fx_frame *f = NULL;
    fx_frame_new(ctx, N, N, &f);
    fx_frame_add_pass(f, "Depth", 1, d);
    CHECK_OK(ctx, fx_frame_write_exr(f, path, NULL));
    fx_frame_free(f);
    free(d);
    return path;
}

/* Camera at (0, -10, 1) looking along +Y (orthographic, 10 m wide): left half sees a wall
 * at planar depth `wall`, right half the sky. */
static fx_frame *street_frame(fx_context *ctx, float wall, const char *map, const fx_camera *map_cam, double frame)
{
    float *rgba = malloc(N * N * 4 * sizeof(float)), *d = malloc(N * N * sizeof(float));
    for (int i = 0; i < N * N; i++) {
        rgba[4 * i] = 0.2f;
        rgba[4 * i + 1] = 0.3f;
        rgba[4 * i + 2] = 0.4f;
        rgba[4 * i + 3] = 1.0f;
        d[i] = (i % N) < N / 2 ? wall : 1e10f;
    }
    fx_frame *f = et_frame(ctx, N, N, rgba);
    fx_frame_add_pass(f, "Depth", 1, d);
    set_ground_camera(f);
    fx_frame_set_time(f, frame, 24.0);
    CHECK_OK(ctx, fx_frame_set_aux_view(f, "rain_map", map, map_cam));
    free(rgba);
    free(d);
    return f;
}

static float *run_rain(fx_context *ctx, const fx_frame *f)
{
    fx_stack *s = et_stack(ctx, "rain");
    CHECK_OK(ctx, fx_stack_set_string(s, 0, "cover_material", ""));
    CHECK_OK(ctx, fx_stack_set_float(s, 0, "density", 1.0));
    CHECK_OK(ctx, fx_stack_set_float(s, 0, "streak_length", 8.0));
    CHECK_OK(ctx, fx_stack_set_float(s, 0, "streak_width", 2.0));
    float *o = et_run(ctx, s, f);
    fx_stack_free(s);
    return o;
}

static int count_changed(const float *a, const fx_frame *in, int half) /* half: 0 left, 1 right, 2 all */
{
    const float *src = et_combined(in);
    int n = 0;
    for (int i = 0; i < N * N; i++) {
        int right = (i % N) >= N / 2;
        if (half != 2 && right != half)
            continue;
        n += memcmp(a + 4 * i, src + 4 * i, 4 * sizeof(float)) != 0;
    }
    return n;
}

static void test_rain(fx_context *ctx)
{
    fx_camera mc;
    /* open sky: a wall nearer than every layer hides them all; the sky shows streaks */
    const char *open = rain_map(ctx, -100.0f, 0.0f, &mc, "open");
    fx_frame *f = street_frame(ctx, 1.5f, open, &mc, 10);
    float *o = run_rain(ctx, f);
    CHECK(o && tu_all_finite(o, N * N * 4));
    CHECK(o && count_changed(o, f, 0) == 0);
    CHECK(o && count_changed(o, f, 1) > 50);
    int sky_changed = o ? count_changed(o, f, 1) : 0;
    /* the same frame twice: the same bits; one thread: the same bits; next frame: moved */
    float *o2 = run_rain(ctx, f);
    CHECK(o && o2 && memcmp(o, o2, N * N * 4 * sizeof(float)) == 0);
    fx_context *c1 = NULL;
    fx_context_new(&c1, 1);
    fx_frame *f1 = street_frame(c1, 1.5f, open, &mc, 10);
    float *o1 = run_rain(c1, f1);
    CHECK(o && o1 && memcmp(o, o1, N * N * 4 * sizeof(float)) == 0);
    fx_frame *fn = street_frame(ctx, 1.5f, open, &mc, 11);
    float *on = run_rain(ctx, fn);
    CHECK(o && on && memcmp(o, on, N * N * 4 * sizeof(float)) != 0);
    free(o1);
    free(on);
    fx_frame_free(f1);
    fx_frame_free(fn);
    fx_context_free(c1);
    free(o2);
    free(o);
    fx_frame_free(f);
    /* a wall at 3 m: only the near layer (2 m) may show in front of it */
    f = street_frame(ctx, 3.0f, open, &mc, 10);
    o = run_rain(ctx, f);
    CHECK(o && count_changed(o, f, 0) > 0);
    free(o);
    fx_frame_free(f);
    /* a roof over everything (y < 100 at z 50): nothing anywhere */
    const char *roofed = rain_map(ctx, 100.0f, 50.0f, &mc, "roofed");
    f = street_frame(ctx, 3.0f, roofed, &mc, 10);
    o = run_rain(ctx, f);
    CHECK(o && count_changed(o, f, 2) == 0);
    free(o);
    fx_frame_free(f);
    /* a roof over y < -6 at z = 5: the near layer (y = -8) is covered below z = 5; above the
     * roof's height and on farther layers streaks remain */
    const char *arcade = rain_map(ctx, -6.0f, 5.0f, &mc, "arcade");
    f = street_frame(ctx, 3.0f, arcade, &mc, 10);
    o = run_rain(ctx, f);
    int below_left = 0;
    for (int y = 0; o && y < N; y++) {
        float wz = 1.0f + 5.0f - (y + 0.5f) * 10.0f / N;
        for (int x = 0; x < N / 2; x++)
            if (wz < 4.8f)
                below_left += memcmp(o + 4 * (y * N + x), et_combined(f) + 4 * (y * N + x), 16) != 0;
    }
    CHECK(o && below_left == 0);
    CHECK(o && count_changed(o, f, 1) > 0 && count_changed(o, f, 1) <= sky_changed);
    free(o);
    fx_frame_free(f);
    /* no rain map: a clear error */
    fx_frame *bare = NULL;
    fx_frame_new(ctx, N, N, &bare);
    f = street_frame(ctx, 3.0f, open, &mc, 10);
    fx_frame_copy_passes(bare, f);
    fx_camera cam;
    fx_frame_camera(f, &cam);
    fx_frame_set_camera(bare, &cam);
    fx_stack *s = et_stack(ctx, "rain");
    fx_stack_set_string(s, 0, "cover_material", "");
    fx_frame *out = NULL;
    CHECK_FAIL(ctx, fx_stack_run(s, bare, &out), FX_ERR_NO_AUX_VIEW, "rain_map");
    char *req = NULL;
    CHECK_OK(ctx, fx_stack_required_aux_views(s, &req));
    CHECK(req && tu_contains(req, "rain_map"));
    fx_free(req);
    fx_stack_free(s);
    fx_frame_free(bare);
    fx_frame_free(f);
}

/* Top-down camera at z = 10 over x, y in [-5, 5] seeing the floor (z = 0, normal up),
 * except a band of wall (normal +X) at columns 40..47; the rain map covers y > 1 at z = 3. */
static fx_frame *ground_frame(fx_context *ctx, const char *map, const fx_camera *map_cam, double frame)
{
    float *rgba = malloc(N * N * 4 * sizeof(float)), *d = malloc(N * N * sizeof(float));
    float *nrm = malloc(N * N * 3 * sizeof(float));
    for (int i = 0; i < N * N; i++) {
        int x = i % N;
        for (int c = 0; c < 3; c++)
            rgba[4 * i + c] = 0.3f;
        rgba[4 * i + 3] = 1.0f;
        d[i] = 10.0f;
        int wall = x >= 40 && x < 48;
        nrm[3 * i] = wall ? 1.0f : 0.0f;
        nrm[3 * i + 1] = 0.0f;
        nrm[3 * i + 2] = wall ? 0.0f : 1.0f;
    }
    fx_frame *f = et_frame(ctx, N, N, rgba);
    fx_frame_add_pass(f, "Depth", 1, d);
    fx_frame_add_pass(f, "Normal", 3, nrm);
    float w2c[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, -10, 0, 0, 0, 1};
    fx_camera cam;
    ortho(&cam, w2c, 5.0f, 0.1f, 100.0f);
    fx_frame_set_camera(f, &cam);
    fx_frame_set_time(f, frame, 24.0);
    CHECK_OK(ctx, fx_frame_set_aux_view(f, "rain_map", map, map_cam));
    free(rgba);
    free(d);
    free(nrm);
    return f;
}

/* ground_frame's pixel (x, y) on the ground: world (-5 + (x + 0.5) 10 / N, 5 - (y + 0.5) 10 / N, 0);
 * its columns 40..47 are a wall */
static double ground_wx(int x) { return -5.0 + (x + 0.5) * 10.0 / N; }
static double ground_wy(int y) { return 5.0 - (y + 0.5) * 10.0 / N; }
static int ground_wall(int x) { return x >= 40 && x < 48; }

/* the roof covers world y > 1 (top of the image is y = 5), up to a rain-map texel */
static int covered_row(int y) { return 5.0f - (y + 0.5f) * 10.0f / N > 1.0f + 0.16f; }

/* A rain map with a roof over world y > 1 at z = 3 (rain_map() covers y < roof_y, so it is
 * mirrored here), written into a fresh temporary directory: its path in path. */
static void roof_map(fx_context *ctx, const char *dir, fx_camera *mcp, char *path, size_t n)
{
    fx_camera mc;
    snprintf(path, n, "%s/roof_north.exr", tu_tmpdir(dir));
    {
        float w2c[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, -40, 0, 0, 0, 1};
        ortho(&mc, w2c, 20.0f, 1.0f, 60.0f);
        const int M = 256; /* texel 0.156 m */
        float *d = malloc(M * M * sizeof(float));
        for (int y = 0; y < M; y++) {
            float wy = 20.0f - (y + 0.5f) * 40.0f / M;
            for (int x = 0; x < M; x++)
                d[y * M + x] = 40.0f - (wy > 1.0f ? 3.0f : 0.0f);
        }
        fx_frame *m = NULL;
        fx_frame_new(ctx, M, M, &m);
        fx_frame_add_pass(m, "Depth", 1, d);
        CHECK_OK(ctx, fx_frame_write_exr(m, path, NULL));
        fx_frame_free(m);
        free(d);
    }
    *mcp = mc;
}

static void test_splashes_and_wet(fx_context *ctx)
{
    fx_camera mc;
    char path[512];
    roof_map(ctx, "rain_maps2", &mc, path, sizeof path);
    int total = 0;
    for (int fr = 1; fr <= 6; fr++) {
        fx_frame *f = ground_frame(ctx, path, &mc, fr);
        fx_stack *s = et_stack(ctx, "rain_splashes");
        CHECK_OK(ctx, fx_stack_set_float(s, 0, "spacing", 1.0));
        CHECK_OK(ctx, fx_stack_set_float(s, 0, "size", 0.45));
        CHECK_OK(ctx, fx_stack_set_float(s, 0, "rate", 1.0));
        float *o = et_run(ctx, s, f);
        float *o2 = et_run(ctx, s, f);
        CHECK(o && o2 && memcmp(o, o2, N * N * 4 * sizeof(float)) == 0);
        const float *src = et_combined(f);
        int bad = 0;
        for (int y = 0; o && y < N; y++)
            for (int x = 0; x < N; x++) {
                int changed = memcmp(o + 4 * (y * N + x), src + 4 * (y * N + x), 16) != 0;
                int allowed = !covered_row(y) && !(x >= 40 && x < 48);
                if (changed && !allowed && bad++ < 3)
                    fprintf(stderr, "splash at covered/wall pixel %d,%d\n", x, y);
                total += changed;
            }
        CHECK(bad == 0);
        CHECK(o && tu_all_finite(o, N * N * 4));
        free(o);
        free(o2);
        fx_stack_free(s);
        fx_frame_free(f);
    }
    CHECK(total > 20);
    /* wet: covered floor (more than edge_softness from the edge) untouched, open floor darker
     * or brighter, walls less wet than floors */
    fx_frame *f = ground_frame(ctx, path, &mc, 1);
    fx_stack *s = et_stack(ctx, "wet_surfaces");
    CHECK_OK(ctx, fx_stack_set_float(s, 0, "edge_softness", 1.0));
    fx_stack_set_debug_outputs(s, 1);
    fx_frame *out = NULL;
    CHECK_OK(ctx, fx_stack_run(s, f, &out));
    float *wet = NULL;
    int ch = 0;
    CHECK_OK(ctx, fx_frame_pass(out, "fx0_wet_surfaces_wetness", &wet, &ch));
    const float *o = et_combined(out);
    const float *src = et_combined(f);
    int bad = 0;
    for (int y = 0; wet && y < N; y++)
        for (int x = 0; x < N; x++) {
            float wy = 5.0f - (y + 0.5f) * 10.0f / N;
            int i = y * N + x;
            if (wy > 1.0f + 0.8f)
                bad += wet[i] != 0.0f || memcmp(o + 4 * i, src + 4 * i, 16) != 0;
            if (wy < 1.0f - 0.8f)
                bad += x >= 40 && x < 48 ? !(wet[i] > 0.2f && wet[i] < 0.6f) : !(wet[i] > 0.99f);
        }
    CHECK(bad == 0);
    /* soft edge: the wetness rises monotonically across the cover boundary on the floor */
    int mono = 1;
    for (int y = 1; wet && y < N; y++)
        mono &= wet[y * N + 10] >= wet[(y - 1) * N + 10] - 1e-6f;
    CHECK(mono);
    if (wet)
        fprintf(stderr, "wet column 10: rows 20 %.3f 26 %.3f 34 %.3f\n", wet[20 * N + 10], wet[26 * N + 10], wet[34 * N + 10]);
    int partial = 0;
    for (int y = 0; wet && y < N; y++)
        partial += wet[y * N + 10] > 0.05f && wet[y * N + 10] < 0.95f;
    CHECK(partial >= 3); /* about 1 m of transition at 0.156 m per pixel */
    CHECK(o && tu_all_finite(o, N * N * 4));
    fx_frame_free(out);
    fx_stack_free(s);
    fx_frame_free(f);
}

/* rain_splashes' downsample knob (the splashes on a lattice of every n-th pixel, interpolated
 * where a cell's corners are all ground): no splash on walls or far under the roof, close to
 * every pixel's splashes, the same bits on 1 and 2 threads and in place (a consumed input),
 * the pixels outside a mask untouched. */
/* What rain_splashes' downsample n implies for ground_frame (docs/effects/rain_splashes.md,
 * "Speed and presets"): nodes at every n-th pixel and the last one (k n clamped to N - 1,
 * ceil((N - 1) / n) + 1 per axis), each with the exact splash v_node (the exact run's
 * light at that pixel: its own rain-map test included); a pixel in a lattice cell whose
 * four nodes are ground gets the bilinear of the nodes' v (0 where no node has one), one in a
 * cell with some ground nodes its exact value, a cell without ground nothing. Ground here:
 * every column but the wall's 40..47. From the exact output e: the predicted output's
 * largest difference from o, and the predicted added light (channel 0) in *pred. */
static double splashes_predicted(const float *o, const float *e, const float *src, int n, double *pred)
{
    const int nn = (N - 1 + n - 1) / n + 1;
    double md = 0;
    *pred = 0;
    for (int y = 0; y < N; y++)
        for (int x = 0; x < N; x++) {
            const int ky = y / n < nn - 1 ? y / n : nn - 2, kx = x / n < nn - 1 ? x / n : nn - 2;
            const int ya = ky * n, yb = (ky + 1) * n < N - 1 ? (ky + 1) * n : N - 1;
            const int xa = kx * n, xb = (kx + 1) * n < N - 1 ? (kx + 1) * n : N - 1;
            const int g = !ground_wall(xa) * 2 + !ground_wall(xb) * 2;
            const int i = y * N + x;
            for (int c = 0; c < 3; c++) {
                double want = src[4 * i + c];
                if (g == 4 && !ground_wall(x)) {
                    /* the nodes' added light (v brightness colour_c: linear in v) */
                    double v00 = e[4 * (ya * N + xa) + c] - src[4 * (ya * N + xa) + c];
                    double v10 = e[4 * (ya * N + xb) + c] - src[4 * (ya * N + xb) + c];
                    double v01 = e[4 * (yb * N + xa) + c] - src[4 * (yb * N + xa) + c];
                    double v11 = e[4 * (yb * N + xb) + c] - src[4 * (yb * N + xb) + c];
                    double fx = (double)(x - xa) / (xb - xa), fy = (double)(y - ya) / (yb - ya);
                    double top = v00 + fx * (v10 - v00), bot = v01 + fx * (v11 - v01);
                    want += top + fy * (bot - top);
                } else if (g > 0 && g < 4) {
                    want = e[4 * i + c];
                }
                md = fmax(md, fabs(o[4 * i + c] - want));
                if (c == 0)
                    *pred += want - src[4 * i];
            }
        }
    return md;
}

static void test_splashes_downsample(fx_context *ctx)
{
    fx_camera mc;
    char path[512];
    roof_map(ctx, "rain_maps3", &mc, path, sizeof path);
    fx_context *c2 = NULL;
    CHECK_OK(ctx, fx_context_new(&c2, 2));
    const int ns[] = {2, 3, 4};
    for (size_t k = 0; k < sizeof ns / sizeof ns[0]; k++) {
        int total = 0, bad = 0;
        double err = 0.0, mass = 0.0, pred = 0.0, pixel_err = 0.0;
        for (int fr = 1; fr <= 4; fr++) {
            fx_frame *f = ground_frame(ctx, path, &mc, fr);
            char params[320], exact[256];
            snprintf(exact, sizeof exact, "\"spacing\": 1.0, \"size\": 0.45, \"rate\": 1.0");
            snprintf(params, sizeof params, "%s, \"downsample\": %d", exact, ns[k]);
            float *o = et_run_effect(ctx, "rain_splashes", f, params, NULL);
            float *o2 = et_run_effect(c2, "rain_splashes", f, params, NULL);
            float *e = et_run_effect(ctx, "rain_splashes", f, exact, NULL);
            float *m = et_run_effect(ctx, "rain_splashes", f, params, "{\"rect\":[5,9,30,40]}");
            CHECK(o && o2 && memcmp(o, o2, N * N * 4 * sizeof(float)) == 0);
            CHECK(e != NULL);
            const float *src = et_combined(f);
            CHECK(m && et_outside_equal(m, src, N, N, 5, 9, 30, 40));
            for (int y = 0; o && e && y < N; y++)
                for (int x = 0; x < N; x++) {
                    const int i = y * N + x;
                    const int changed = memcmp(o + 4 * i, src + 4 * i, 16) != 0;
                    /* under the roof by more than n pixels (plus a texel) or on the wall: none */
                    const int deep = covered_row(y) && (y + ns[k] < N ? covered_row(y + ns[k]) : 1) &&
                                     (y >= ns[k] ? covered_row(y - ns[k]) : 1);
                    bad += changed && (deep || (x >= 40 && x < 48));
                    total += changed;
                    err += (double)o[4 * i] - src[4 * i]; /* light added */
                    mass += (double)e[4 * i] - src[4 * i];
                }
            CHECK(o && tu_all_finite(o, N * N * 4));
            if (o && e) {
                double p1 = 0;
                pixel_err = fmax(pixel_err, splashes_predicted(o, e, src, ns[k], &p1));
                pred += p1;
            }
            /* in place: the stack consumes a frame of its own */
            fx_frame *g = ground_frame(ctx, path, &mc, fr);
            fx_stack *s = NULL;
            char buf[512];
            snprintf(buf, sizeof buf, "{\"version\":1,\"effects\":[{\"effect\":\"rain_splashes\",\"params\":{%s}}]}",
                     params);
            fx_frame *out = NULL;
            CHECK_OK(ctx, fx_stack_new(ctx, &s));
            CHECK_OK(ctx, fx_stack_load_json(s, buf));
            CHECK_OK(ctx, fx_stack_run_consume(s, g, 0, &out));
            CHECK(o && out && memcmp(o, et_combined(out), N * N * 4 * sizeof(float)) == 0);
            fx_frame_free(out);
            fx_stack_free(s);
            free(o);
            free(o2);
            free(e);
            free(m);
            fx_frame_free(f);
        }
        fprintf(stderr, "splashes downsample %d: %d pixels changed, %d bad, light added / every pixel's %.3f "
                "(predicted %.3f; per pixel within %.1e of the prediction)\n",
                ns[k], total, bad, mass > 0 ? err / mass : 0.0, mass > 0 ? pred / mass : 0.0, pixel_err);
        CHECK(bad == 0 && total > 20);
        /* The light added, derived instead of the old 0.4x-2.5x band: the rings are 0.6 px
         * wide here, so the lattice samples them or not and the ratio to every pixel's light
         * is whatever the lattice implies (measured 1.012-1.021 over n = 2, 3, 4: inside any band wide enough for the sampling); that is
         * computed exactly by splashes_predicted from the exact run's node values, so the
         * only freedom left is float rounding: per pixel 1e-5 of values ~0.8, the sum 1e-4
         * of the light. (Mutations: the bilinear's fy off by half a pixel, a cell's last
         * column not drawn, and the nodes' exact value kept only at the cell's top-left all
         * fail this and passed the band.) */
        CHECK(pixel_err < 1e-5);
        CHECK(mass > 0 && fabs(err - pred) < 1e-4 * mass);
    }
    fx_context_free(c2);
}

/* ---- rain_splashes against an independent reference ----
 * docs/effects/rain_splashes.md and the effect's definition, evaluated here in double:
 * cells of `spacing` metres; cell (i, j) runs splashes of `lifetime` seconds with phase
 * unit(hash4(i, j, 0x5eed, seed)); cycle c = floor(t / lifetime + phase), age the
 * fraction; the splash exists when unit(h = hash4(i, j, c, seed)) < rate and sits at
 * ((i + 0.1 + 0.8 unit(h1)) spacing, (j + 0.1 + 0.8 unit(h2)) spacing), h1 = lowbias32(h),
 * h2 = lowbias32(h1); its ring: radius size sqrt(age), profile exp(-((dist - radius) /
 * (0.2 size))^2), fade (1 - age)^1.5; a pixel takes the brightest ring of the 3 x 3 cells
 * around its own and adds it times brightness x colour. t = frame / fps. */
static double ref_splash(double wx, double wy, double t, double spacing, double rate, double size, double life,
                         int seed)
{
    int ci = (int)floor(wx / spacing), cj = (int)floor(wy / spacing);
    double best = 0;
    for (int dj = -1; dj <= 1; dj++)
        for (int di = -1; di <= 1; di++) {
            int i = ci + di, k = cj + dj;
            double cyc = t / life + tu_ref_unit(tu_ref_hash4(i, k, 0x5eed, seed));
            int c = (int)floor(cyc);
            double age = cyc - c;
            uint32_t h = tu_ref_hash4(i, k, c, seed);
            if (tu_ref_unit(h) >= rate)
                continue;
            uint32_t h1 = tu_ref_hash_u32(h), h2 = tu_ref_hash_u32(h1);
            double sx = (i + 0.1 + 0.8 * tu_ref_unit(h1)) * spacing, sy = (k + 0.1 + 0.8 * tu_ref_unit(h2)) * spacing;
            double e = (hypot(wx - sx, wy - sy) - size * sqrt(age)) / (0.2 * size);
            best = fmax(best, exp(-e * e) * pow(1 - age, 1.5));
        }
    return best;
}


static void test_splashes_reference(fx_context *ctx)
{
    fx_camera mc;
    const char *open_map = rain_map(ctx, -100.0f, 3.0f, &mc, "open_sky"); /* nothing covered */
    const float color[3] = {0.85f, 0.88f, 0.92f};
    const double bright = 1.5;
    int lit = 0;
    for (int fr = 1; fr <= 4; fr++) {
        fx_frame *f = ground_frame(ctx, open_map, &mc, 5 * fr);
        float *o = et_run_effect(ctx, "rain_splashes", f,
                                 "\"spacing\": 0.8, \"size\": 0.35, \"rate\": 0.8, \"lifetime\": 0.3, "
                                 "\"brightness\": 1.5, \"seed\": 5",
                                 NULL);
        const float *src = et_combined(f);
        double e = o ? 0 : INFINITY, peak = 0;
        for (int y = 0; o && y < N; y++)
            for (int x = 0; x < N; x++) {
                const int i = y * N + x;
                double v = ground_wall(x) ? 0.0 : ref_splash(ground_wx(x), ground_wy(y), 5 * fr / 24.0, 0.8, 0.8, 0.35, 0.3, 5);
                peak = fmax(peak, v);
                lit += v > 0.05;
                for (int c = 0; c < 3; c++)
                    e = fmax(e, fabs(o[4 * i + c] - (src[4 * i + c] + v * bright * color[c])));
                e = fmax(e, fabs(o[4 * i + 3] - src[4 * i + 3]));
            }
        fprintf(stderr, "splashes reference frame %d: max error %.2e (peak ring %.3f)\n", 5 * fr, e, peak);
        CHECK(e < 2e-5); /* float evaluation of values <= 1.4 */
        free(o);
        fx_frame_free(f);
    }
    CHECK(lit > 100); /* rings in the frames */
}

/* rate is the probability that a cell's cycle has a splash: the splash exists when
 * unit(hash) < rate, so at a rate of exactly a cell's unit(hash) that cell has none. The
 * cell is picked where the tie shows (the reference at rate and at the next float above
 * differs by > 0.1 somewhere in the open ground), then the effect is held to the
 * reference at that rate. */
static void test_splashes_rate_tie(fx_context *ctx)
{
    fx_camera mc;
    const char *open_map = rain_map(ctx, -100.0f, 3.0f, &mc, "open_sky_tie");
    const float color[3] = {0.85f, 0.88f, 0.92f};
    const double t = 10 / 24.0, spacing = 0.8, size = 0.35, life = 0.3;
    const int seed = 5;
    double rate = -1;
    for (int k = -6; k <= 5 && rate < 0; k++)
        for (int i = -6; i <= 3 && rate < 0; i++) { /* cells over x < 40 (the wall's columns are 40..47) */
            const int c = (int)floor(t / life + tu_ref_unit(tu_ref_hash4(i, k, 0x5eed, seed)));
            const double u = tu_ref_unit(tu_ref_hash4(i, k, c, seed)), above = u + 1.0 / 16777216.0;
            if (!(u > 0.2 && above <= 1.0))
                continue;
            double diff = 0;
            for (int y = 0; y < N; y++)
                for (int x = 0; x < 40; x++)
                    diff = fmax(diff, fabs(ref_splash(ground_wx(x), ground_wy(y), t, spacing, above, size, life, seed) -
                                           ref_splash(ground_wx(x), ground_wy(y), t, spacing, u, size, life, seed)));
            if (diff > 0.1)
                rate = u;
        }
    CHECK(rate > 0);
    fx_frame *f = ground_frame(ctx, open_map, &mc, 10);
    char params[256];
    snprintf(params, sizeof params,
             "\"spacing\": 0.8, \"size\": 0.35, \"rate\": %.9g, \"lifetime\": 0.3, \"brightness\": 1.5, "
             "\"seed\": 5",
             rate);
    float *o = rate > 0 ? et_run_effect(ctx, "rain_splashes", f, params, NULL) : NULL;
    const float *src = et_combined(f);
    double e = o ? 0 : INFINITY;
    for (int y = 0; o && y < N; y++)
        for (int x = 0; x < N; x++) {
            const int i = y * N + x;
            double v = ground_wall(x) ? 0.0 : ref_splash(ground_wx(x), ground_wy(y), t, spacing, rate, size, life, seed);
            for (int c = 0; c < 3; c++)
                e = fmax(e, fabs(o[4 * i + c] - (src[4 * i + c] + v * 1.5 * color[c])));
        }
    fprintf(stderr, "splashes at rate = a cell's unit(hash) %.9g: max error %.2e\n", rate, e);
    CHECK(e < 2e-5);
    free(o);
    fx_frame_free(f);
}

/* A pixel without a surface (Depth 0: nothing rendered there) gets no splash, at every
 * downsample: holes of depth 0 between the lattice nodes (x, y = 2 mod 4) of an open floor
 * full of splashes keep their source bits at downsample 1 and 4. */
static void test_splashes_no_depth(fx_context *ctx)
{
    fx_camera mc;
    const char *open_map = rain_map(ctx, -100.0f, 3.0f, &mc, "open_sky_holes");
    for (int ds = 1; ds <= 4; ds += 3) {
        fx_frame *f = ground_frame(ctx, open_map, &mc, 10);
        float *dep = NULL;
        int ch = 0;
        CHECK_OK(ctx, fx_frame_pass(f, "Depth", &dep, &ch));
        for (int y = 2; dep && y < N; y += 4)
            for (int x = 2; x < 40; x += 4)
                dep[y * N + x] = 0.0f;
        char params[256];
        snprintf(params, sizeof params,
                 "\"spacing\": 0.8, \"size\": 0.35, \"rate\": 1.0, \"lifetime\": 0.3, \"brightness\": 1.5, "
                 "\"seed\": 5, \"downsample\": %d",
                 ds);
        float *o = et_run_effect(ctx, "rain_splashes", f, params, NULL);
        const float *src = et_combined(f);
        int holes_changed = 0, floor_changed = 0;
        for (int y = 0; o && y < N; y++)
            for (int x = 0; x < 40; x++) {
                const int i = y * N + x, changed = memcmp(o + 4 * i, src + 4 * i, 16) != 0;
                if (y % 4 == 2 && x % 4 == 2)
                    holes_changed += changed;
                else
                    floor_changed += changed;
            }
        fprintf(stderr, "splashes downsample %d: %d holes changed, %d floor pixels changed\n", ds, holes_changed,
                floor_changed);
        CHECK(o && holes_changed == 0 && floor_changed > 500);
        free(o);
        fx_frame_free(f);
    }
}

/* ---- rain (streaks) against an independent reference ----
 * The documented model (docs/effects/rain.md, the effect's definition) in double: frame
 * pixel centre (x, y) in pattern space of layer l (scale s = near / d_l, k = (height /
 * 720) s): u = (x cos w - y sin w) / k, v = (x sin w + y cos w) / k - t speed s; cells
 * 14 x 1.5 streak_length; cell (i, j) of layer l holds a streak when unit(h = hash4(i, j,
 * l, seed)) < density, at x0 = (i + 0.15 + 0.7 unit(h1)) 14, from y0 = (j + unit(h2)) 1.5
 * length, of length length (0.7 + 0.6 unit(h3)) (h1, h2, h3 successive lowbias32 of h);
 * at a = (v - y0) / len in (0, 1) its value is (1 - |u - x0| / we) (width / we) 4 a (1 - a),
 * we = max(width, 1 / k) (drawn at least a pixel wide, dimmer); a layer shows the largest
 * of its streaks where the scene's depth is beyond d_l (and the point is exposed: the map
 * here is open), weighted 0.5 + 0.5 s; out = src + brightness colour sum. The layers' points below the
 * ground are under cover (the map is the ground plane). */
/* one layer's largest streak at (x, y): layer l (3: the cover quads) at scale sc */
static double ref_layer(double x, double y, int h, double t, int l, double sc)
{
    const double len = 12.0, width = 3.0, density = 0.6, speed = 1800.0, wind = 10.0 * 3.14159265358979323846 / 180.0;
    const int seed = 9;
    double k = h / 720.0 * sc;
    double u = (x * cos(wind) - y * sin(wind)) / k, v = (x * sin(wind) + y * cos(wind)) / k - t * speed * sc;
    double we = fmax(width, 1.0 / k), best = 0;
    int ci = (int)floor(u / 14.0), cj = (int)floor(v / (1.5 * len));
    for (int j = cj - 2; j <= cj; j++)
        for (int i = ci - 4; i <= ci + 4; i++) {
            uint32_t h0 = tu_ref_hash4(i, j, l, seed);
            if (tu_ref_unit(h0) >= density)
                continue;
            uint32_t h1 = tu_ref_hash_u32(h0), h2 = tu_ref_hash_u32(h1), h3 = tu_ref_hash_u32(h2);
            double x0 = (i + 0.15 + 0.7 * tu_ref_unit(h1)) * 14.0, y0 = (j + tu_ref_unit(h2)) * 1.5 * len;
            double a = (v - y0) / (len * (0.7 + 0.6 * tu_ref_unit(h3)));
            double across = 1.0 - fabs(u - x0) / we;
            if (a > 0 && a < 1 && across > 0)
                best = fmax(best, across * (width / we) * 4 * a * (1 - a));
        }
    return best;
}

static double ref_streaks(double x, double y, int h, double t, const double *d, int layers, double depth)
{
    double sum = 0;
    for (int l = 0; l < layers; l++) {
        if (!(depth > d[l]))
            continue;
        double sc = d[0] / d[l];
        sum += ref_layer(x, y, h, t, l, sc) * (0.5 + 0.5 * sc);
    }
    return sum;
}

static void test_rain_reference(fx_context *ctx)
{
    enum { RW = 96, RH = 240 };
    fx_camera mc;
    const char *open_map = rain_map(ctx, -100.0f, 3.0f, &mc, "open_sky_streaks");
    const double dist[3] = {2.0, 5.0, 12.0};
    const float color[3] = {0.8f, 0.85f, 0.9f};
    float *rgba = malloc((size_t)RW * RH * 4 * sizeof(float)), *dep = malloc((size_t)RW * RH * sizeof(float));
    for (int i = 0; i < RW * RH; i++) {
        for (int c = 0; c < 3; c++)
            rgba[4 * i + c] = 0.1f * (c + 1);
        rgba[4 * i + 3] = 1.0f;
        /* a wall at 3.5 m on the left third (the near layer only), one at 8 m in the middle
         * (near and mid), sky on the right */
        int x = i % RW;
        dep[i] = x < RW / 3 ? 3.5f : x < 2 * RW / 3 ? 8.0f : 1e10f;
    }
    int lit = 0;
    for (int fr = 1; fr <= 3; fr++) {
        fx_frame *f = et_frame(ctx, RW, RH, rgba);
        fx_frame_add_pass(f, "Depth", 1, dep);
        set_ground_camera(f);
        fx_frame_set_time(f, 7 * fr, 24.0);
        CHECK_OK(ctx, fx_frame_set_aux_view(f, "rain_map", open_map, &mc));
        float *o = et_run_effect(ctx, "rain", f,
                                 "\"cover_material\": \"\", \"density\": 0.6, \"streak_length\": 12.0, "
                                 "\"streak_width\": 3.0, \"brightness\": 0.7, \"seed\": 9",
                                 NULL);
        double e = o ? 0 : INFINITY, peak = 0;
        for (int y = 0; o && y < RH; y++)
            for (int x = 0; x < RW; x++) {
                const int i = y * RW + x;
                /* the layers' points lie at height z = 1 + 5 (1 - 2 (y + 0.5) / RH) (the camera at
                 * z = 1, 5 m half height): below the ground (z < 0: the open map's floor is
                 * above them) they are under cover; a band of the map's depth bias left out */
                double z = 1.0 + 5.0 * (1.0 - 2.0 * (y + 0.5) / RH);
                if (fabs(z) < 0.2)
                    continue;
                double sum = z > 0 ? ref_streaks(x + 0.5, y + 0.5, RH, 7 * fr / 24.0, dist, 3, dep[i]) : 0.0;
                peak = fmax(peak, sum);
                lit += sum > 0.1;
                for (int c = 0; c < 3; c++)
                    e = fmax(e, fabs(o[4 * i + c] - (rgba[4 * i + c] + 0.7 * sum * color[c])));
                e = fmax(e, fabs(o[4 * i + 3] - rgba[4 * i + 3]));
            }
        fprintf(stderr, "rain reference frame %d: max error %.2e (peak streak sum %.3f)\n", 7 * fr, e, peak);
        /* float pattern coordinates: u, v of ~1e3 carry ~1e-4 of rounding, a streak's edge
         * (slope 1 / we per pattern pixel) moves by that: 1e-4 of a value <= ~1.3 */
        CHECK(e < 2e-4);
        free(o);
        fx_frame_free(f);
    }
    CHECK(lit > 500);
    free(rgba);
    free(dep);
}

/* ---- rain on the cover quads against the same reference ----
 * docs/effects/rain.md: with the camera under cover, a pixel on a cover quad (Cryptomatte
 * coverage c of cover_material) adds brightness colour saturate(c / cover_opacity)
 * cover_brightness times the near layer's pattern at scale 1 (layer index 3 in the hash),
 * unclipped; the layers themselves are all under the roof here. downsample n: the pattern
 * evaluated on every n-th row of the ROI (the last on its last row) at every column and a
 * pixel between two such rows interpolating them along the slant: row r0 above, r1 below
 * at weights 1 - ty, ty, in each the columns floor(o), floor(o) + 1 of o = col + tan(wind)
 * (row - y) at weights 1 - frac(o), frac(o) (clamped to the ROI). Run on a rect mask that
 * starts at (5, 9): the ROI's columns count from its own left edge. */
enum { CW = 72, CH = 160 };

static fx_frame *cover_frame(fx_context *ctx, const char *map, const fx_camera *map_cam, const float *rgba)
{
    float *dep = malloc((size_t)CW * CH * sizeof(float)), *cr = calloc((size_t)CW * CH * 4, sizeof(float));
    float id = fx_cryptomatte_id("Rain_Cover"), other = fx_cryptomatte_id("Wall");
    for (int i = 0; i < CW * CH; i++) {
        int y = i / CW;
        dep[i] = (i % CW) < CW / 2 ? 3.0f : 1e10f;
        cr[4 * i] = y >= 30 && y < 130 ? id : other;
        cr[4 * i + 1] = y == 30 ? 0.03f : 1.0f; /* a partly covered edge row */
    }
    fx_frame *f = et_frame(ctx, CW, CH, rgba);
    fx_frame_add_pass(f, "Depth", 1, dep);
    fx_frame_add_pass(f, "CryptoMaterial00", 4, cr);
    set_ground_camera(f);
    fx_frame_set_time(f, 11, 24.0);
    CHECK_OK(ctx, fx_frame_set_aux_view(f, "rain_map", map, map_cam));
    free(dep);
    free(cr);
    return f;
}

static double cover_weight(int y) /* saturate(coverage / cover_opacity 0.07) x cover_brightness 0.6 */
{
    return y >= 30 && y < 130 ? (y == 30 ? 0.03 / 0.07 : 1.0) * 0.6 : 0.0;
}

static void test_rain_cover_reference(fx_context *ctx)
{
    fx_camera mc;
    const char *roofed = rain_map(ctx, 100.0f, 50.0f, &mc, "roofed_cover_ref");
    const float color[3] = {0.8f, 0.85f, 0.9f};
    const double t = 11 / 24.0, slant = tan(10.0 * 3.14159265358979323846 / 180.0);
    float *rgba = malloc((size_t)CW * CH * 4 * sizeof(float));
    for (int i = 0; i < CW * CH; i++) {
        for (int c = 0; c < 3; c++)
            rgba[4 * i + c] = 0.1f * (c + 1);
        rgba[4 * i + 3] = 1.0f;
    }
    const char *base = "\"cover_material\": \"Rain_Cover\", \"density\": 0.6, \"streak_length\": 12.0, "
                       "\"streak_width\": 3.0, \"brightness\": 0.7, \"seed\": 9";
    const int rx = 5, ry = 9, rw = 60, rh = 140; /* the rect mask of the downsampled runs */
    for (int ds = 1; ds <= 4; ds += 3) {
        fx_frame *f = cover_frame(ctx, roofed, &mc, rgba);
        char params[512], mask[64];
        snprintf(params, sizeof params, "%s, \"downsample\": %d", base, ds);
        snprintf(mask, sizeof mask, "{\"rect\": [%d, %d, %d, %d]}", rx, ry, rw, rh);
        float *o = et_run_effect(ctx, "rain", f, params, ds > 1 ? mask : NULL);
        const int x0 = ds > 1 ? rx : 0, y0 = ds > 1 ? ry : 0, x1 = ds > 1 ? rx + rw : CW, y1 = ds > 1 ? ry + rh : CH;
        const int gh = (y1 - y0 - 2) / ds + 2, gw = x1 - x0;
        /* the pattern at the evaluated rows (every row at downsample 1) */
        double *node = calloc((size_t)gh * gw, sizeof(double));
        int *row_y = malloc((size_t)gh * sizeof(int));
        for (int r = 0; r < gh; r++) {
            row_y[r] = r == gh - 1 ? y1 - 1 : y0 + r * ds;
            for (int c = 0; c < gw; c++)
                node[(size_t)r * gw + c] = ref_layer(x0 + c + 0.5, row_y[r] + 0.5, CH, t, 3, 1.0);
        }
        double e = o ? 0 : INFINITY, peak = 0;
        int lit = 0;
        for (int y = 0; o && y < CH; y++)
            for (int x = 0; x < CW; x++) {
                const int i = y * CW + x;
                double sum = 0;
                if (x >= x0 && x < x1 && y >= y0 && y < y1) {
                    int r0 = (y - y0) / ds;
                    r0 = r0 > gh - 2 ? gh - 2 : r0;
                    const int r1 = r0 + 1, col = x - x0;
                    const double span = row_y[r1] - row_y[r0], ty = fmin((y - row_y[r0]) / span, 1.0);
                    double cs = 0;
                    for (int k = 0; k < 2; k++) {
                        const int r = k ? r1 : r0;
                        const double oc = slant * (row_y[r] - y), w = floor(oc), fr = oc - w;
                        const int a = col + (int)w < 0 ? 0 : col + (int)w >= gw ? gw - 1 : col + (int)w;
                        const int b = col + (int)w + 1 < 0 ? 0 : col + (int)w + 1 >= gw ? gw - 1 : col + (int)w + 1;
                        cs += (k ? ty : 1 - ty) * ((1 - fr) * node[(size_t)r * gw + a] + fr * node[(size_t)r * gw + b]);
                    }
                    sum = cover_weight(y) * cs;
                }
                peak = fmax(peak, sum);
                lit += sum > 0.1;
                for (int c = 0; c < 3; c++)
                    e = fmax(e, fabs(o[4 * i + c] - (rgba[4 * i + c] + 0.7 * sum * color[c])));
                e = fmax(e, fabs(o[4 * i + 3] - rgba[4 * i + 3]));
            }
        fprintf(stderr, "rain cover reference, downsample %d: max error %.2e (peak %.3f, %d pixels lit)\n", ds, e,
                peak, lit);
        CHECK(e < 2e-4 && lit > 300); /* as test_rain_reference: float pattern coordinates */
        free(node);
        free(row_y);
        free(o);
        fx_frame_free(f);
    }
    free(rgba);
}

/* ---- wet_surfaces on a hand-worked input ----
 * docs/effects/wet_surfaces.md: w = wetness x exposure x facing, facing = lerp(wall_wetness,
 * 1, smoothstep(0, up_threshold, N.z)) for N.z >= 0 and wall_wetness (1 - smoothstep(0,
 * 0.3, -N.z)) facing down; out = src (1 - darken w) + w specular F sky_color, F = 0.02 +
 * 0.98 (1 - clamp(N.V, 0, 1))^5. The frame: a plane at z = 1 seen straight down by an
 * orthographic camera (V = +Z, so N.V = N.z), the open rain map's ground at z = 0 (exposure
 * 1 everywhere), column x with the unit normal (sqrt(1 - nz^2), 0, nz), nz from -0.5 to 1. */
static double ref_smooth(double e0, double e1, double x)
{
    double t = fmin(fmax((x - e0) / (e1 - e0), 0.0), 1.0);
    return t * t * (3 - 2 * t);
}

static void test_wet_reference(fx_context *ctx)
{
    fx_camera mc;
    const char *open_map = rain_map(ctx, -100.0f, 3.0f, &mc, "open_sky_wet");
    float *rgba = malloc(N * N * 4 * sizeof(float)), *d = malloc(N * N * sizeof(float));
    float *nrm = malloc(N * N * 3 * sizeof(float));
    for (int i = 0; i < N * N; i++) {
        const double nz = -0.5 + 1.5 * (i % N) / (N - 1.0);
        for (int c = 0; c < 3; c++)
            rgba[4 * i + c] = 0.2f + 0.1f * c + 0.002f * (i / N);
        rgba[4 * i + 3] = 0.9f;
        d[i] = 9.0f;
        nrm[3 * i] = (float)sqrt(1 - nz * nz);
        nrm[3 * i + 1] = 0.0f;
        nrm[3 * i + 2] = (float)nz;
    }
    fx_frame *f = et_frame(ctx, N, N, rgba);
    fx_frame_add_pass(f, "Depth", 1, d);
    fx_frame_add_pass(f, "Normal", 3, nrm);
    float w2c[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, -10, 0, 0, 0, 1};
    fx_camera cam;
    ortho(&cam, w2c, 5.0f, 0.1f, 100.0f);
    fx_frame_set_camera(f, &cam);
    CHECK_OK(ctx, fx_frame_set_aux_view(f, "rain_map", open_map, &mc));
    const double wetness = 0.9, darken = 0.3, specular = 1.2, wall = 0.4, up = 0.7, sky[3] = {0.5, 0.6, 0.7};
    {
        float *o = et_run_effect(ctx, "wet_surfaces", f,
                                 "\"wetness\": 0.9, \"darken\": 0.3, \"specular\": 1.2, \"wall_wetness\": 0.4, "
                                 "\"up_threshold\": 0.7, \"sky_color\": [0.5, 0.6, 0.7], \"edge_softness\": 0.0, "
                                 "\"downsample\": 1",
                                 NULL);
        double e = o ? 0 : INFINITY;
        for (int i = 0; o && i < N * N; i++) {
            const double nz = nrm[3 * i + 2];
            const double facing = nz >= 0 ? wall + (1 - wall) * ref_smooth(0, up, nz)
                                          : wall * (1 - ref_smooth(0, 0.3, -nz));
            const double w = wetness * facing, F = 0.02 + 0.98 * pow(1 - fmin(fmax(nz, 0), 1), 5);
            for (int c = 0; c < 3; c++)
                e = fmax(e, fabs(o[4 * i + c] - (rgba[4 * i + c] * (1 - darken * w) + w * specular * F * sky[c])));
            e = fmax(e, fabs(o[4 * i + 3] - rgba[4 * i + 3]));
        }
        fprintf(stderr, "wet_surfaces reference: max error %.2e\n", e);
        CHECK(e < 2e-6); /* float arithmetic on values <= ~1 (downsample 1: every pixel exact) */
        free(o);
    }
    fx_frame_free(f);
    free(rgba);
    free(d);
    free(nrm);
}

/* The rain map goes through the context's cache (scene/aux_map.h): a stack of wet_surfaces,
 * rain_splashes and rain over frames 1..4 in one context builds the map once (plus the
 * filtered copy for the soft edges) and gives the same bits as a context without cache. */
static void test_cache(void)
{
    fx_context *cached = NULL, *plain = NULL;
    fx_context_new(&cached, 2);
    fx_context_new(&plain, 1);
    CHECK_OK(plain, fx_context_set_aux_cache(plain, 0));
    fx_camera mc;
    const char *map = rain_map(cached, 1.0f, 3.0f, &mc, "cache");
    const char *names[] = {"wet_surfaces", "rain_splashes", "rain"};
    for (int fr = 1; fr <= 4; fr++) {
        float *out[2] = {NULL, NULL};
        fx_context *cs[2] = {cached, plain};
        for (int k = 0; k < 2; k++) {
            fx_frame *f = ground_frame(cs[k], map, &mc, fr);
            fx_stack *s = NULL;
            CHECK_OK(cs[k], fx_stack_new(cs[k], &s));
            for (int e = 0; e < 3; e++) {
                int idx;
                CHECK_OK(cs[k], fx_stack_append(s, names[e], &idx));
            }
            CHECK_OK(cs[k], fx_stack_set_string(s, 2, "cover_material", ""));
            CHECK_OK(cs[k], fx_stack_set_float(s, 0, "edge_softness", 2.0)); /* 3.2 texels: filtered */
            out[k] = et_run(cs[k], s, f);
            fx_stack_free(s);
            fx_frame_free(f);
        }
        CHECK(out[0] && out[1] && memcmp(out[0], out[1], N * N * 4 * sizeof(float)) == 0);
        free(out[0]);
        free(out[1]);
    }
    long built, reused;
    fx_aux_cache_stats(cached, &built, &reused);
    /* 4 acquires a frame (wet: 2), 2 builds; the filtered map's build takes the unfiltered
     * one from the cache (one more reuse) */
    CHECK(built == 2 && reused == 4 * 4 - 2 + 1);
    fx_aux_cache_stats(plain, &built, &reused);
    CHECK(built == 16 + 4 && reused == 0); /* uncached: the filtered map builds its base too */
    fx_context_free(cached);
    fx_context_free(plain);
}


/* rain's layers knob: fewer layers add a subset of the streaks (never more light than
 * three), the near layer alone is the same at every count where only it can show (wall at
 * 3 m), bit-identical on 1 and 2 threads; 1x1, 1xN and odd frames with NaN / Inf depth
 * stay finite for rain, rain_splashes and wet_surfaces. */
static void test_rain_layers_extremes(fx_context *ctx)
{
    fx_camera mc;
    const char *open = rain_map(ctx, -100.0f, 0.0f, &mc, "open_layers");
    fx_frame *f = street_frame(ctx, 1e10f, open, &mc, 10);
    const char *base = "\"cover_material\": \"\", \"density\": 1.0, \"streak_length\": 8.0, \"streak_width\": 2.0";
    float *o[3];
    for (int l = 1; l <= 3; l++) {
        char params[256];
        snprintf(params, sizeof params, "%s, \"layers\": %d", base, l);
        o[l - 1] = et_run_effect(ctx, "rain", f, params, NULL);
        CHECK(o[l - 1] && tu_all_finite(o[l - 1], N * N * 4));
    }
    const float *src = et_combined(f);
    int more = 0, changed[3] = {0, 0, 0};
    for (int i = 0; o[0] && o[1] && o[2] && i < N * N; i++)
        for (int c = 0; c < 3; c++) {
            more += o[0][4 * i + c] > o[1][4 * i + c] || o[1][4 * i + c] > o[2][4 * i + c];
            for (int l = 0; l < 3; l++)
                changed[l] += o[l][4 * i + c] != src[4 * i + c];
        }
    CHECK(more == 0);
    CHECK(changed[0] > 0 && changed[0] < changed[1] && changed[1] < changed[2]);
    fx_context *c1 = NULL;
    fx_context_new(&c1, 1);
    fx_frame *f1 = street_frame(c1, 1e10f, open, &mc, 10);
    char params[256];
    snprintf(params, sizeof params, "%s, \"layers\": 2", base);
    float *o1 = et_run_effect(c1, "rain", f1, params, NULL);
    CHECK(o1 && o[1] && memcmp(o1, o[1], N * N * 4 * sizeof(float)) == 0);
    free(o1);
    fx_frame_free(f1);
    fx_context_free(c1);
    for (int l = 0; l < 3; l++)
        free(o[l]);
    fx_frame_free(f);
    /* a wall at 3 m: only the near layer can show on the left half; layers 1 and 3 agree there */
    f = street_frame(ctx, 3.0f, open, &mc, 10);
    snprintf(params, sizeof params, "%s, \"layers\": 1", base);
    float *a = et_run_effect(ctx, "rain", f, params, NULL);
    snprintf(params, sizeof params, "%s, \"layers\": 3", base);
    float *b = et_run_effect(ctx, "rain", f, params, NULL);
    int differ = 0;
    for (int y = 0; a && b && y < N; y++)
        for (int x = 0; x < N / 2; x++)
            differ += memcmp(a + 4 * (y * N + x), b + 4 * (y * N + x), 16) != 0;
    CHECK(a && b && differ == 0);
    free(a);
    free(b);
    fx_frame_free(f);
    /* tiny and odd frames with hostile depth and normals */
    int sizes[][2] = {{1, 1}, {1, 7}, {7, 1}, {5, 3}};
    for (size_t k = 0; k < sizeof sizes / sizeof sizes[0]; k++) {
        int w = sizes[k][0], h = sizes[k][1];
        float *rgba = malloc((size_t)w * h * 4 * sizeof(float)), *d = malloc((size_t)w * h * sizeof(float));
        float *nrm = malloc((size_t)w * h * 3 * sizeof(float));
        for (int i = 0; i < w * h * 4; i++)
            rgba[i] = 0.5f;
        for (int i = 0; i < w * h; i++) {
            d[i] = i % 3 == 1 ? NAN : i % 3 == 2 ? INFINITY : 4.0f;
            nrm[3 * i] = 0.0f;
            nrm[3 * i + 1] = i % 2 ? NAN : 0.0f;
            nrm[3 * i + 2] = 1.0f;
        }
        fx_frame *g = et_frame(ctx, w, h, rgba);
        fx_frame_add_pass(g, "Depth", 1, d);
        fx_frame_add_pass(g, "Normal", 3, nrm);
        set_ground_camera(g);
        CHECK_OK(ctx, fx_frame_set_aux_view(g, "rain_map", open, &mc));
        const char *runs[][2] = {{"rain", "\"cover_material\": \"\", \"layers\": 1"},
                                 {"rain", "\"cover_material\": \"\", \"layers\": 3"},
                                 {"rain", "\"cover_material\": \"\", \"downsample\": 8"},
                                 {"rain", "\"cover_material\": \"\", \"downsample\": 2"},
                                 {"rain_splashes", ""},
                                 {"rain_splashes", "\"downsample\": 2"},
                                 {"rain_splashes", "\"downsample\": 16"},
                                 {"wet_surfaces", ""},
                                 {"wet_surfaces", "\"downsample\": 2"}};
        for (int r = 0; r < (int)(sizeof runs / sizeof runs[0]); r++) {
            float *out = et_run_effect(ctx, runs[r][0], g, runs[r][1], NULL);
            CHECK(out && tu_all_finite(out, (size_t)w * h * 4));
            free(out);
        }
        fx_frame_free(g);
        free(rgba);
        free(d);
        free(nrm);
    }
}

/* rain's downsample knob (streaks on every N-th row, interpolated along their slant): the
 * depth test stays per pixel (a wall nearer than every layer gets nothing), close to every
 * row, bit-identical on 1 and 2 threads, light only added; the cover quads' coverage read
 * lazily from Cryptomatte gives the same bits as the whole-frame mask (forced with more
 * than 8 rank passes). */
static void add_crypto(fx_frame *f, int ranks)
{
    float id = fx_cryptomatte_id("Rain_Cover"), other = fx_cryptomatte_id("Wall");
    for (int r = 0; r < ranks; r++) {
        float *c = calloc((size_t)N * N * 4, sizeof(float));
        for (int i = 0; r == 0 && i < N * N; i++) {
            int y = i / N;
            c[4 * i] = y >= 20 && y < 40 ? id : other;
            c[4 * i + 1] = y == 20 ? 0.03f : 1.0f; /* a partly covered edge row */
        }
        char name[32];
        snprintf(name, sizeof name, "CryptoMaterial%02d", r);
        fx_frame_add_pass(f, name, 4, c);
        free(c);
    }
}

static void test_rain_downsample(fx_context *ctx)
{
    fx_camera mc;
    const char *open = rain_map(ctx, -100.0f, 0.0f, &mc, "open_ds");
    const char *base = "\"cover_material\": \"\", \"density\": 1.0, \"streak_length\": 30.0, \"streak_width\": 2.0";
    char params[256];
    /* a wall at 1.5 m (nearer than every layer) on the left half: nothing there */
    fx_frame *f = street_frame(ctx, 1.5f, open, &mc, 10);
    snprintf(params, sizeof params, "%s, \"downsample\": 4", base);
    float *o = et_run_effect(ctx, "rain", f, params, NULL);
    CHECK(o && tu_all_finite(o, N * N * 4));
    CHECK(o && count_changed(o, f, 0) == 0 && count_changed(o, f, 1) > 0);
    free(o);
    fx_frame_free(f);
    /* open street: close to every row, never darker, thread count invariant */
    f = street_frame(ctx, 1e10f, open, &mc, 10);
    snprintf(params, sizeof params, "%s, \"downsample\": 1", base);
    float *full = et_run_effect(ctx, "rain", f, params, NULL);
    snprintf(params, sizeof params, "%s, \"downsample\": 4", base);
    float *ds = et_run_effect(ctx, "rain", f, params, NULL);
    const float *src = et_combined(f);
    double err = 0.0, sum = 0.0;
    int darker = 0;
    for (int i = 0; full && ds && i < N * N * 4; i++) {
        err += fabs((double)ds[i] - full[i]);
        sum += full[i] - src[i];
        darker += ds[i] < src[i];
    }
    CHECK(full && ds && darker == 0 && sum > 0.0 && err < 0.5 * sum);
    fx_context *c1 = NULL;
    fx_context_new(&c1, 1);
    fx_frame *f1 = street_frame(c1, 1e10f, open, &mc, 10);
    float *ds1 = et_run_effect(c1, "rain", f1, params, NULL);
    CHECK(ds1 && ds && memcmp(ds1, ds, N * N * 4 * sizeof(float)) == 0);
    free(ds1);
    fx_frame_free(f1);
    fx_context_free(c1);
    free(full);
    free(ds);
    fx_frame_free(f);
    /* the camera under a roof: only the cover quads (rows 20..39) get rain */
    const char *roofed = rain_map(ctx, 100.0f, 50.0f, &mc, "roofed_ds");
    const char *cov = "\"cover_material\": \"Rain_Cover\", \"density\": 1.0, \"streak_length\": 30.0, "
                      "\"streak_width\": 2.0, \"downsample\": 4";
    fx_frame *a = street_frame(ctx, 3.0f, roofed, &mc, 10), *b = street_frame(ctx, 3.0f, roofed, &mc, 10);
    add_crypto(a, 2);
    add_crypto(b, 9);
    float *oa = et_run_effect(ctx, "rain", a, cov, NULL), *ob = et_run_effect(ctx, "rain", b, cov, NULL);
    CHECK(oa && ob && memcmp(oa, ob, N * N * 4 * sizeof(float)) == 0);
    const float *sa = et_combined(a);
    int outside = 0, inside = 0;
    for (int i = 0; oa && i < N * N; i++) {
        int y = i / N, changed = memcmp(oa + 4 * i, sa + 4 * i, 16) != 0;
        outside += changed && !(y >= 20 && y < 40);
        inside += changed;
    }
    CHECK(outside == 0 && inside > 0);
    free(oa);
    free(ob);
    fx_frame_free(a);
    fx_frame_free(b);
}

/* wet_surfaces' downsample: the lattice cells on one smooth surface interpolate, the
 * others (across the wall band's creases) take the corners on each pixel's own surface:
 * the wall's edge columns and the rest are close to final (the cover edge's soft wetness
 * interpolated over 3 pixels), 1 and 2 threads agree. */
static void test_wet_downsample(fx_context *ctx)
{
    fx_camera mc;
    const char *map = rain_map(ctx, 1.0f, 3.0f, &mc, "wet_ds");
    fx_frame *f = ground_frame(ctx, map, &mc, 1);
    float *full = et_run_effect(ctx, "wet_surfaces", f, "\"edge_softness\": 1.0, \"downsample\": 1", NULL);
    float *ds = et_run_effect(ctx, "wet_surfaces", f, "\"edge_softness\": 1.0, \"downsample\": 3", NULL);
    CHECK(full && ds && tu_all_finite(ds, N * N * 4));
    float maxd = 0.0f, wall_d = 0.0f;
    int changed = 0;
    const float *src = et_combined(f);
    for (int i = 0; full && ds && i < N * N; i++) {
        int x = i % N;
        for (int c = 0; c < 4; c++) {
            float d = fabsf(ds[4 * i + c] - full[4 * i + c]);
            maxd = d > maxd ? d : maxd;
            if (x == 40 || x == 47) { /* the crease columns: in cells with floor and wall corners */
                wall_d = d > wall_d ? d : wall_d;
            }
            changed += ds[4 * i + c] != src[4 * i + c];
        }
    }
    /* the crease columns take the corners on their own surface (the wall's or the floor's),
     * never the other one's look: as close to final as the rest (measured 0.027) */
    CHECK(maxd < 0.05f && wall_d < 0.035f && changed > 0);
    fx_context *c1 = NULL;
    fx_context_new(&c1, 1);
    fx_frame *f1 = ground_frame(c1, map, &mc, 1);
    float *ds1 = et_run_effect(c1, "wet_surfaces", f1, "\"edge_softness\": 1.0, \"downsample\": 3", NULL);
    CHECK(ds1 && ds && memcmp(ds1, ds, N * N * 4 * sizeof(float)) == 0);
    free(ds1);
    fx_frame_free(f1);
    fx_context_free(c1);
    free(full);
    free(ds);
    fx_frame_free(f);
}

/* wet_surfaces' downsample against its documented model (docs/effects/wet_surfaces.md:
 * the look computed on a lattice of every N-th pixel, the last on the ROI's edge; inside a
 * cell whose four corners' normals agree (dot >= 0.9) a pixel whose depth is within 2 % of
 * the corners' and whose normal is within about 25 degrees of the first corner's (n.a > 0,
 * (n.a)^2 >= 0.81 |n|^2) interpolates the corners bilinearly; any other pixel takes the
 * corners on its own surface (depth within 1.5 % x N, normal within about 25 degrees of that
 * corner's) at their bilinear weights + 1e-3, and is computed exactly when none is). With
 * one source colour everywhere the output is linear in the look, so the model works on the
 * exact (downsample 1) outputs: a corner's is its pixel's. The frame: a floor seen straight
 * down, tilted 15 degrees towards -X, under the soft edge of a roof (the wetness, and so the
 * look, changes across rows 19..32), with single pixels off the lattice (x, y = 1 mod 12)
 * tilted +12 degrees in X (27 degrees from the floor, but only 12 from its Z axis), -45
 * (30 from the floor, 45 from Z) and +7.5 (22.5 from the floor: inside the 25 degrees). */
static void tilt_normal(float *n, double deg)
{
    n[0] = (float)sin(deg * 3.14159265358979323846 / 180.0);
    n[1] = 0.0f;
    n[2] = (float)cos(deg * 3.14159265358979323846 / 180.0);
}

static int bump_kind(int x, int y) /* 0: floor; 1..3: the three tilts */
{
    return x % 12 == 1 && y % 12 == 1 ? 1 + (x / 12 + y / 12) % 3 : 0;
}

static void test_wet_lattice_model(fx_context *ctx)
{
    fx_camera mc;
    char path[512];
    roof_map(ctx, "wet_model", &mc, path, sizeof path);
    const double tilt[4] = {-15.0, 12.0, -45.0, 7.5};
    float *rgba = malloc(N * N * 4 * sizeof(float)), *d = malloc(N * N * sizeof(float));
    float *nrm = malloc(N * N * 3 * sizeof(float));
    for (int i = 0; i < N * N; i++) {
        rgba[4 * i] = 0.9f, rgba[4 * i + 1] = 0.8f, rgba[4 * i + 2] = 0.7f, rgba[4 * i + 3] = 1.0f;
        d[i] = 10.0f;
        tilt_normal(nrm + 3 * i, tilt[bump_kind(i % N, i / N)]);
    }
    fx_frame *f = et_frame(ctx, N, N, rgba);
    fx_frame_add_pass(f, "Depth", 1, d);
    fx_frame_add_pass(f, "Normal", 3, nrm);
    float w2c[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, -10, 0, 0, 0, 1};
    fx_camera cam;
    ortho(&cam, w2c, 5.0f, 0.1f, 100.0f);
    fx_frame_set_camera(f, &cam);
    fx_frame_set_time(f, 1, 24.0);
    CHECK_OK(ctx, fx_frame_set_aux_view(f, "rain_map", path, &mc));
    const char *look = "\"edge_softness\": 1.0, \"darken\": 1.0, \"up_threshold\": 1.0";
    char params[256];
    snprintf(params, sizeof params, "%s, \"downsample\": 1", look);
    float *ex = et_run_effect(ctx, "wet_surfaces", f, params, NULL);
    CHECK(ex != NULL);
    for (int ds = 3; ex && ds <= 4; ds++) {
        snprintf(params, sizeof params, "%s, \"downsample\": %d", look, ds);
        float *o = et_run_effect(ctx, "wet_surfaces", f, params, NULL);
        const int n = (N - 2) / ds + 2;
        int node[N];
        for (int k = 0; k < n; k++)
            node[k] = k == n - 1 ? N - 1 : k * ds;
        double err[4] = {0, 0, 0, 0}, spread = 0;
        for (int y = 0; o && y < N; y++)
            for (int x = 0; x < N; x++) {
                const int kx = x / ds < n - 2 ? x / ds : n - 2, ky = y / ds < n - 2 ? y / ds : n - 2;
                const double tx = (double)(x - node[kx]) / (node[kx + 1] - node[kx]);
                const double ty = (double)(y - node[ky]) / (node[ky + 1] - node[ky]);
                const int cx[4] = {node[kx], node[kx + 1], node[kx], node[kx + 1]};
                const int cy[4] = {node[ky], node[ky], node[ky + 1], node[ky + 1]};
                const double bw[4] = {(1 - tx) * (1 - ty), tx * (1 - ty), (1 - tx) * ty, tx * ty};
                const float *np = nrm + 3 * (y * N + x);
                const double nn = (double)np[0] * np[0] + (double)np[1] * np[1] + (double)np[2] * np[2];
                double dots[4], first[4];
                int smooth = 1;
                for (int m = 0; m < 4; m++) {
                    const float *nc = nrm + 3 * (cy[m] * N + cx[m]), *n0 = nrm + 3 * (cy[0] * N + cx[0]);
                    dots[m] = (double)np[0] * nc[0] + (double)np[1] * nc[1] + (double)np[2] * nc[2];
                    first[m] = (double)n0[0] * nc[0] + (double)n0[1] * nc[1] + (double)n0[2] * nc[2];
                    smooth &= first[m] >= 0.9;
                }
                double want[3] = {0, 0, 0}, ws = 0;
                if (smooth && dots[0] > 0 && dots[0] * dots[0] >= 0.81 * nn) {
                    for (int m = 0; m < 4; m++)
                        for (int c = 0; c < 3; c++)
                            want[c] += bw[m] * ex[4 * (cy[m] * N + cx[m]) + c];
                    ws = 1;
                } else {
                    for (int m = 0; m < 4; m++)
                        if (dots[m] > 0 && dots[m] * dots[m] >= 0.81 * nn) {
                            for (int c = 0; c < 3; c++)
                                want[c] += (bw[m] + 1e-3) * ex[4 * (cy[m] * N + cx[m]) + c];
                            ws += bw[m] + 1e-3;
                        }
                }
                for (int c = 0; c < 3; c++) {
                    const double w = ws > 0 ? want[c] / ws : ex[4 * (y * N + x) + c];
                    err[bump_kind(x, y)] = fmax(err[bump_kind(x, y)], fabs(o[4 * (y * N + x) + c] - w));
                    if (ws > 0)
                        spread = fmax(spread, fabs(w - ex[4 * (y * N + x) + c]));
                }
            }
        fprintf(stderr,
                "wet lattice model, downsample %d: max error floor %.2e, +12 %.2e, -45 %.2e, +7.5 %.2e (model "
                "against exact up to %.3f)\n",
                ds, err[0], err[1], err[2], err[3], spread);
        CHECK(o && err[0] < 1e-5 && err[1] < 1e-5 && err[2] < 1e-5 && err[3] < 1e-5 && spread > 0.01);
        free(o);
    }
    free(ex);
    fx_frame_free(f);
    free(rgba);
    free(d);
    free(nrm);
}

/* In place (a consumed frame: rain writes over the input's Combined, FX_EFFECT_IN_PLACE)
 * equals the separate-buffer run bit for bit, the debug pass too; without a mask no second
 * buffer (the output is the input's). A mask runs on a second buffer (the blend needs the
 * old pixels): the same bits all the same. */
static int consume_equal(fx_context *ctx, fx_frame *f, const char *params, const char *mask, int debug)
{
    char buf[1024];
    snprintf(buf, sizeof buf, "{\"version\":1,\"effects\":[{\"effect\":\"rain\",\"params\":{%s}%s%s}]}", params,
             mask ? ",\"mask\":" : "", mask ? mask : "");
    fx_stack *s = NULL;
    CHECK_OK(ctx, fx_stack_new(ctx, &s));
    CHECK_OK(ctx, fx_stack_load_json(s, buf));
    fx_stack_set_debug_outputs(s, debug);
    fx_frame *sep = NULL, *out = NULL;
    CHECK_OK(ctx, fx_stack_run(s, f, &sep));
    const float *given = NULL; /* read-only: a pass handed out writable is never consumed */
    fx_frame_pass_read(f, "Combined", &given, NULL);
    CHECK_OK(ctx, fx_stack_run_consume(s, f, 0, &out));
    const float *a = et_combined(sep), *b = et_combined(out);
    int ok = a && b && memcmp(a, b, (size_t)N * N * 4 * sizeof(float)) == 0 && (mask || b == given);
    if (debug) {
        float *da = NULL, *db = NULL;
        int ca = 0, cb = 0;
        ok &= fx_frame_pass(sep, "fx0_rain_streaks", &da, &ca) == FX_OK &&
              fx_frame_pass(out, "fx0_rain_streaks", &db, &cb) == FX_OK && ca == 1 && cb == 1 &&
              memcmp(da, db, (size_t)N * N * sizeof(float)) == 0;
    }
    fx_frame_free(sep);
    fx_frame_free(out);
    fx_stack_free(s);
    return ok;
}

static void test_rain_in_place(fx_context *mctx)
{
    fx_camera mc;
    const char *base = "\"density\": 0.8, \"streak_length\": 30.0, \"streak_width\": 2.0";
    /* params, roofed map (camera under cover), Cryptomatte ranks (9: the whole-frame cover
     * mask instead of the lazy reads), mask, debug outputs */
    struct { const char *params; int roofed, ranks; const char *mask; int debug; } cases[] = {
        { "\"cover_material\": \"\", \"downsample\": 1", 0, 0, NULL, 0 },
        { "\"cover_material\": \"\", \"downsample\": 4", 0, 0, NULL, 0 },
        { "\"cover_material\": \"\", \"downsample\": 3, \"wind_angle\": -35, \"layers\": 2", 0, 0, NULL, 1 },
        { "\"cover_material\": \"Rain_Cover\", \"downsample\": 4", 1, 2, NULL, 0 },
        { "\"cover_material\": \"Rain_Cover\", \"downsample\": 4", 1, 9, NULL, 1 },
        { "\"cover_material\": \"Rain_Cover\", \"downsample\": 1", 1, 2, NULL, 0 },
        { "\"cover_material\": \"\", \"downsample\": 1", 0, 0, "{\"rect\": [5, 9, 40, 30]}", 0 },
        { "\"cover_material\": \"\", \"downsample\": 4", 0, 0, "{\"rect\": [5, 9, 40, 30]}", 1 },
    };
    for (int roofed = 0; roofed <= 1; roofed++) {
        /* one map at a time: each rain_map call empties the maps' directory */
        const char *map = rain_map(mctx, roofed ? 100.0f : -100.0f, roofed ? 50.0f : 0.0f, &mc,
                                   roofed ? "roofed_ip" : "open_ip");
        for (int t = 1; t <= 2; t++) {
            fx_context *ctx = NULL;
            fx_context_new(&ctx, t);
            for (int k = 0; k < (int)(sizeof cases / sizeof cases[0]); k++) {
                if (cases[k].roofed != roofed)
                    continue;
                fx_frame *f = street_frame(ctx, 3.0f, map, &mc, 10);
                if (cases[k].ranks)
                    add_crypto(f, cases[k].ranks);
                char params[512];
                snprintf(params, sizeof params, "%s, %s", base, cases[k].params);
                int ok = consume_equal(ctx, f, params, cases[k].mask, cases[k].debug);
                if (!ok)
                    fprintf(stderr, "rain in place differs: threads %d, case %d\n", t, k);
                CHECK(ok);
            }
            fx_context_free(ctx);
        }
    }
}

int main(void)
{
    fx_context *ctx = NULL;
    fx_context_new(&ctx, 2);
    test_rain(ctx);
    test_splashes_and_wet(ctx);
    test_splashes_downsample(ctx);
    test_splashes_reference(ctx);
    test_splashes_rate_tie(ctx);
    test_splashes_no_depth(ctx);
    test_rain_reference(ctx);
    test_wet_reference(ctx);
    test_cache();
    test_rain_layers_extremes(ctx);
    test_rain_downsample(ctx);
    test_rain_cover_reference(ctx);
    test_wet_downsample(ctx);
    test_wet_lattice_model(ctx);
    test_rain_in_place(ctx);
    fx_context_free(ctx);
    return tu_finish("test_rain");
}
