/* vsm_shadows and the maths under it: a synthetic light view with a known occluder gives
 * shadow exactly where geometry says (hard limit) and soft edges of the requested width;
 * the variance clamp at constant depth; SAT precision at 4096^2; light-bleeding reduction
 * against the multi-occluder leak; aux views through the sidecar; threads; NaN input. */
#include "fx_effect_test.h"

#include "core/frame.h"
#include "core/mem.h"
#include "scene/aux_map.h"
#include "math/sat.h"
#include "math/shadow_map.h"

#include <float.h>
#include <math.h>

#define N 64          /* light-map and frame size */
#define L 5.0f        /* both views cover x, y in [-L, L] */
#define CAM_Z 10.0f   /* both look straight down from here */

/* Orthographic top-down camera at (0, 0, CAM_Z), near 0.1, far 20. */
static fx_camera top_camera(void)
{
    fx_camera c;
    memset(&c, 0, sizeof c);
    c.size = sizeof c;
    float w2c[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, -CAM_Z, 0, 0, 0, 1};
    float n = 0.1f, f = 20.0f;
    float proj[16] = {1 / L, 0, 0, 0, 0, 1 / L, 0, 0, 0, 0, -2 / (f - n), -(f + n) / (f - n), 0, 0, 0, 1};
    memcpy(c.world_to_camera, w2c, sizeof w2c);
    memcpy(c.projection, proj, sizeof proj);
    c.clip_start = n;
    c.clip_end = f;
    c.orthographic = 1;
    return c;
}

/* Writes a light view of heights h (N x N, z of the topmost surface per texel) and returns
 * the EXR path (static). */
static const char *write_light_view(fx_context *ctx, const float *height, const char *name)
{
    static char path[512];
    snprintf(path, sizeof path, "%s/%s.exr", tu_tmpdir("vsm_light_views"), name);
    fx_frame *f = NULL;
    fx_frame_new(ctx, N, N, &f);
    float *d = malloc(N * N * sizeof(float));
    for (int i = 0; i < N * N; i++)
        d[i] = CAM_Z - height[i];
    fx_frame_add_pass(f, "Depth", 1, d);
    CHECK_OK(ctx, fx_frame_write_exr(f, path, NULL));
    free(d);
    fx_frame_free(f);
    return path;
}

/* A frame seeing the floor (z = 0) everywhere through the same camera, Combined = 1. */
static fx_frame *floor_frame(fx_context *ctx, const char *light_path)
{
    float *rgba = malloc(N * N * 4 * sizeof(float)), *d = malloc(N * N * sizeof(float));
    for (int i = 0; i < N * N * 4; i++)
        rgba[i] = 1.0f;
    for (int i = 0; i < N * N; i++)
        d[i] = CAM_Z;
    fx_frame *f = et_frame(ctx, N, N, rgba);
    fx_frame_add_pass(f, "Depth", 1, d);
    fx_camera cam = top_camera();
    fx_frame_set_camera(f, &cam);
    CHECK_OK(ctx, fx_frame_set_aux_view(f, "light:Sun", light_path, &cam));
    free(rgba);
    free(d);
    return f;
}

/* Visibility per pixel (Combined R with apply combined, strength 1). */
static float *run_vsm(fx_context *ctx, fx_frame *f, const char *method, const char *filter, float size, float bleed,
                      float min_std)
{
    fx_stack *s = et_stack(ctx, "vsm_shadows");
    CHECK_OK(ctx, fx_stack_set_enum(s, 0, "apply", "combined"));
    CHECK_OK(ctx, fx_stack_set_enum(s, 0, "method", method));
    CHECK_OK(ctx, fx_stack_set_enum(s, 0, "filter", filter));
    CHECK_OK(ctx, fx_stack_set_float(s, 0, "filter_size", size));
    CHECK_OK(ctx, fx_stack_set_float(s, 0, "bleed_reduction", bleed));
    CHECK_OK(ctx, fx_stack_set_float(s, 0, "min_std", min_std));
    float *o = et_run(ctx, s, f);
    fx_stack_free(s);
    return o;
}

static void test_hard_limit(fx_context *ctx)
{
    /* a 2 m square occluder at z = 2 over x, y in [-1, 1] (texels 25.6 .. 38.4: 26..38) */
    float h[N * N];
    for (int y = 0; y < N; y++)
        for (int x = 0; x < N; x++) {
            float wx = -L + (x + 0.5f) * 2 * L / N, wy = L - (y + 0.5f) * 2 * L / N;
            h[y * N + x] = fabsf(wx) < 1.0f && fabsf(wy) < 1.0f ? 2.0f : 0.0f;
        }
    fx_frame *f = floor_frame(ctx, write_light_view(ctx, h, "square"));
    for (int m = 0; m < 3; m++) {
        const char *method = m == 0 ? "vsm" : m == 1 ? "pcf" : "hard";
        float *o = run_vsm(ctx, f, method, "box_sat", 1.0f, 0.3f, 0.01f);
        CHECK(o != NULL);
        int wrong = 0;
        for (int i = 0; o && i < N * N; i++)
            wrong += o[4 * i] != (h[i] > 0 ? 0.0f : 1.0f);
        if (wrong)
            fprintf(stderr, "hard limit (%s): %d pixels wrong\n", method, wrong);
        CHECK(wrong == 0);
        free(o);
    }
    fx_frame_free(f);
}

static void test_soft_edge_width(fx_context *ctx)
{
    /* half-plane occluder at z = 2 over texel columns x < 32 */
    float h[N * N];
    for (int i = 0; i < N * N; i++)
        h[i] = (i % N) < N / 2 ? 2.0f : 0.0f;
    fx_frame *f = floor_frame(ctx, write_light_view(ctx, h, "half"));
    int width = 9, r = 4;
    float *o = run_vsm(ctx, f, "vsm", "box_sat", (float)width, 0.0f, 0.0f);
    float *pcf = run_vsm(ctx, f, "pcf", "box_sat", (float)width, 0.0f, 0.0f);
    CHECK(o && pcf);
    double err = 0, perr = 0;
    int y = N / 2;
    for (int x = 0; o && pcf && x < N; x++) {
        int occ = 0;
        for (int k = x - r; k <= x + r; k++)
            occ += k < N / 2;
        /* the box is clipped at the map's border: count only texels inside */
        int inside = 0;
        for (int k = x - r; k <= x + r; k++)
            inside += k >= 0 && k < N;
        occ = 0;
        for (int k = x - r; k <= x + r; k++)
            occ += k >= 0 && k < N / 2;
        double want = 1.0 - (double)occ / inside;
        err = fmax(err, fabs(o[4 * (y * N + x)] - want));
        perr = fmax(perr, fabs(pcf[4 * (y * N + x)] - want));
    }
    /* one planar occluder over a planar receiver: VSM is exactly the box's lit fraction */
    fprintf(stderr, "soft edge: max |vsm - lit fraction| = %.2e, pcf %.2e\n", err, perr);
    CHECK(err < 1e-4);
    CHECK(perr < 1e-6);
    /* full shadow up to x = 27, full light from 36: the penumbra is the filter's width */
    CHECK(o && o[4 * (y * N + 27)] == 0.0f && o[4 * (y * N + 28)] > 0.0f);
    CHECK(o && o[4 * (y * N + 36)] == 1.0f && o[4 * (y * N + 35)] < 1.0f);
    free(o);
    free(pcf);
    /* the Gaussian of the same variance: monotone, 10-90 % over 2 * 1.2816 sigma */
    float *g = run_vsm(ctx, f, "vsm", "gaussian", 25.0f, 0.0f, 0.0f);
    CHECK(g != NULL);
    if (g) {
        int mono = 1;
        float x10 = -1, x90 = -1;
        for (int x = 1; x < N; x++) {
            float a = g[4 * (y * N + x - 1)], b = g[4 * (y * N + x)];
            mono &= b >= a - 1e-6f;
            if (a < 0.1f && b >= 0.1f)
                x10 = x - 1 + (0.1f - a) / (b - a);
            if (a < 0.9f && b >= 0.9f)
                x90 = x - 1 + (0.9f - a) / (b - a);
        }
        double want = 2 * 1.2816 * 25.0 / sqrt(12.0);
        fprintf(stderr, "gaussian 25: 10-90%% width %.2f texels (Gaussian CDF: %.2f)\n", x90 - x10, want);
        CHECK(mono);
        CHECK(fabs((x90 - x10) - want) < 0.15 * want);
    }
    free(g);
    fx_frame_free(f);
}

static void test_variance_clamp(fx_context *ctx)
{
    /* constant depth: zero variance everywhere */
    float h[N * N];
    for (int i = 0; i < N * N; i++)
        h[i] = 0.0f;
    fx_frame *f = floor_frame(ctx, write_light_view(ctx, h, "flat"));
    float *o = run_vsm(ctx, f, "vsm", "box_sat", 17.0f, 0.0f, 0.0f);
    int lit = 1;
    for (int i = 0; o && i < N * N; i++)
        lit &= o[4 * i] == 1.0f;
    CHECK(o && lit);
    free(o);
    fx_frame_free(f);
    /* the bound itself: rounding that makes m2 < m1^2, zero variance, t just behind */
    float cases[][3] = {{0.5f, 0.2499999f, 0.6f}, {0.5f, 0.25f, 0.5000001f}, {-1, 1, 1}, {0.3f, 0.0f, 0.9f},
                        {NAN, 0.1f, 0.5f}, {0.1f, NAN, 0.5f}, {0.1f, 0.01f, NAN}, {1e30f, 1e30f, 1}};
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++)
        for (int b = 0; b < 2; b++) {
            float p = fx_vsm_visibility(cases[k][0], cases[k][1], cases[k][2], 1e-8f, b ? 0.5f : 0.0f, 0.0f);
            CHECK(isfinite(p) && p >= 0.0f && p <= 1.0f);
        }
    /* normalised, centred depth keeps the variance at raw depth ~1000 */
    float raw[N * N];
    for (int i = 0; i < N * N; i++)
        raw[i] = 1000.0f + ((i + i / N) % 2 ? 0.02f : -0.02f); /* checkerboard: std 0.02 m */
    fx_shadow_map sm;
    CHECK_OK(ctx, fx_shadow_map_build(ctx, raw, N, N, 990.0f, 1010.0f, 0, &sm, "test"));
    CHECK_OK(ctx, fx_shadow_map_filter(ctx, &sm, FX_SHADOW_FILTER_BOX_SAT, 5.0f, "test"));
    float m1, m2;
    fx_shadow_map_moments(&sm, N / 2 + 0.5f, N / 2 + 0.5f, &m1, &m2);
    double std_m = sqrt(fmax(0.0, m2 - (double)m1 * m1)) * (1010.0 - 990.0) / 2.0;
    /* raw float moments lose it: E[d^2] - E[d]^2 at d ~ 1000 in float */
    float e1 = 0, e2 = 0;
    for (int i = 0; i < 25; i++) {
        float d = raw[i];
        e1 += d / 25.0f;
        e2 += d * d / 25.0f;
    }
    fprintf(stderr, "std at depth 1000 (true 0.0196 over a 5x5 box): normalised %.5f m, raw float %.5f m\n",
            std_m, sqrt(fmax(0.0, (double)e2 - (double)e1 * e1)));
    CHECK(fabs(std_m - 0.02 * sqrt(1.0 - 1.0 / 625.0)) < 0.002);
    fx_shadow_map_free(&sm);
}

static void test_sat_precision(fx_context *ctx)
{
    const int S = 4096;
    float *img = malloc((size_t)S * S * sizeof(float));
    uint32_t st = 12345;
    for (size_t i = 0; i < (size_t)S * S; i++) {
        st = st * 1664525u + 1013904223u;
        img[i] = 500.0f + (float)(st >> 8) / 16777216.0f; /* depth-like: offset + detail */
    }
    fx_sat sat;
    CHECK_OK(ctx, fx_sat_build(ctx, img, S, S, 1, &sat, "test"));
    /* float32 SAT of the raw values, for the record */
    double worst = 0, worst_f = 0;
    int boxes[][4] = {{0, 0, S, S}, {S - 7, S - 9, S, S}, {1000, 2000, 1003, 2001}, {4000, 4000, 4096, 4096},
                      {17, 3000, 4090, 3011}, {2048, 0, 2049, 4096}, {100, 100, 3100, 3900}};
    float *colsum = NULL;
    (void)colsum;
    for (size_t b = 0; b < sizeof boxes / sizeof boxes[0]; b++) {
        int *q = boxes[b];
        double direct = 0;
        for (int y = q[1]; y < q[3]; y++)
            for (int x = q[0]; x < q[2]; x++)
                direct += img[(size_t)y * S + x];
        double n = (double)(q[2] - q[0]) * (q[3] - q[1]);
        direct /= n;
        double m;
        fx_sat_box_mean(&sat, q[0], q[1], q[2], q[3], &m);
        worst = fmax(worst, fabs(m - direct));
    }
    /* what a float32 SAT does at the far corner: S(4096, 4096) - S(4096, 4095) ... */
    {
        float acc = 0;
        for (size_t i = 0; i < (size_t)S * S; i++)
            acc += img[i];
        float acc2 = acc;
        for (int x = 0; x < S; x++)
            acc2 -= img[(size_t)(S - 1) * S + x];
        double last_row = 0;
        for (int x = 0; x < S; x++)
            last_row += img[(size_t)(S - 1) * S + x];
        worst_f = fabs(((double)acc - acc2) / S - last_row / S);
    }
    fprintf(stderr, "SAT 4096^2 (values 500 + [0,1)): max error of box means %.2e (double, centred); "
                    "float32 running sum, last-row mean: %.2e\n", worst, worst_f);
    CHECK(worst < 1e-9);
    CHECK(worst_f > 1e-3); /* why the guide insists */
    fx_sat_free(&sat);
    free(img);
}

static void test_bleeding(fx_context *ctx)
{
    /* two occluders: A at z = 8 over x < 32, B at z = 2 over x >= 32; the floor (z = 0)
     * everywhere is in full shadow. Where the filter mixes A and B, Chebyshev leaks. */
    float h[N * N];
    for (int i = 0; i < N * N; i++)
        h[i] = (i % N) < N / 2 ? 8.0f : 2.0f;
    fx_frame *f = floor_frame(ctx, write_light_view(ctx, h, "two"));
    float leak[3];
    float bleeds[3] = {0.0f, 0.3f, 0.6f};
    for (int b = 0; b < 3; b++) {
        float *o = run_vsm(ctx, f, "vsm", "box_sat", 15.0f, bleeds[b], 0.01f);
        CHECK(o != NULL);
        leak[b] = 0;
        for (int i = 0; o && i < N * N; i++)
            leak[b] = fmaxf(leak[b], o[4 * i]);
        free(o);
    }
    fprintf(stderr, "multi-occluder leak (max light on a fully shadowed floor): bleed 0 %.3f, 0.3 %.3f, 0.6 %.3f\n",
            leak[0], leak[1], leak[2]);
    CHECK(leak[0] > 0.1f);
    CHECK(leak[1] < 0.5f * leak[0]);
    CHECK(leak[2] <= leak[1] && leak[2] < 0.05f);
    fx_frame_free(f);
}

static void test_sidecar_threads_errors(fx_context *ctx)
{
    float h[N * N];
    for (int i = 0; i < N * N; i++)
        h[i] = (i / N) < N / 3 ? 3.0f : 0.0f;
    const char *path = write_light_view(ctx, h, "rows");
    fx_frame *f = floor_frame(ctx, path);
    /* the same view through the sidecar JSON */
    fx_frame *g = NULL;
    fx_frame_new(ctx, N, N, &g);
    fx_frame_copy_passes(g, f);
    char json[4096];
    snprintf(json, sizeof json,
             "{\"world_to_camera\": [[1,0,0,0],[0,1,0,0],[0,0,1,-10],[0,0,0,1]], \"projection\": "
             "[[0.2,0,0,0],[0,0.2,0,0],[0,0,%.9g,%.9g],[0,0,0,1]], \"clip_start\": 0.1, \"clip_end\": 20, "
             "\"aux_views\": [{\"name\": \"light:Sun\", \"path\": \"%s\", \"world_to_camera\": "
             "[[1,0,0,0],[0,1,0,0],[0,0,1,-10],[0,0,0,1]], \"projection\": [[0.2,0,0,0],[0,0.2,0,0],[0,0,%.9g,%.9g],"
             "[0,0,0,1]], \"clip_start\": 0.1, \"clip_end\": 20, \"orthographic\": true}]}",
             -2 / 19.9, -20.1 / 19.9, path, -2 / 19.9, -20.1 / 19.9);
    CHECK_OK(ctx, fx_frame_apply_sidecar(g, json));
    float *a = run_vsm(ctx, f, "vsm", "box_sat", 7.0f, 0.3f, 0.01f);
    float *b = run_vsm(ctx, g, "vsm", "box_sat", 7.0f, 0.3f, 0.01f);
    CHECK(a && b && tu_max_abs_diff(a, b, N * N * 4) < 1e-5);
    /* thread count does not change a bit */
    fx_context *c1 = NULL;
    fx_context_new(&c1, 1);
    fx_frame *f1 = floor_frame(c1, path);
    float *a1 = run_vsm(c1, f1, "vsm", "box_sat", 7.0f, 0.3f, 0.01f);
    float *g1 = run_vsm(c1, f1, "vsm", "gaussian", 7.0f, 0.3f, 0.01f);
    float *g2 = run_vsm(ctx, f, "vsm", "gaussian", 7.0f, 0.3f, 0.01f);
    CHECK(a && a1 && memcmp(a, a1, N * N * 4 * sizeof(float)) == 0);
    CHECK(g1 && g2 && memcmp(g1, g2, N * N * 4 * sizeof(float)) == 0);
    free(a1);
    free(g1);
    free(g2);
    fx_frame_free(f1);
    fx_context_free(c1);
    free(a);
    free(b);
    /* unknown keys in a view, no view, no Depth in the view: clear errors */
    CHECK_FAIL(ctx, fx_frame_apply_sidecar(g, "{\"aux_views\": [{\"name\": \"x\", \"path\": \"/p\", \"bogus\": 1}]}"),
               FX_ERR_BAD_RECIPE, "bogus");
    fx_frame *none = NULL;
    fx_frame_new(ctx, N, N, &none);
    fx_frame_copy_passes(none, f);
    fx_camera cam = top_camera();
    fx_frame_set_camera(none, &cam);
    fx_stack *s = et_stack(ctx, "vsm_shadows");
    fx_stack_set_enum(s, 0, "apply", "combined");
    fx_frame *out = NULL;
    CHECK_FAIL(ctx, fx_stack_run(s, none, &out), FX_ERR_NO_AUX_VIEW, "light:");
    /* required aux views */
    char *req = NULL;
    CHECK_OK(ctx, fx_stack_required_aux_views(s, &req));
    CHECK(req && tu_contains(req, "\"light:\""));
    fx_free(req);
    fx_stack_set_enabled(s, 0, 0);
    CHECK_OK(ctx, fx_stack_required_aux_views(s, &req));
    CHECK(req && strcmp(req, "{\"aux_views\":[]}") == 0);
    fx_free(req);
    fx_stack_free(s);
    /* A named light, and the rain map asked for once by three rain effects. */
    s = NULL;
    fx_stack_new(ctx, &s);
    CHECK_OK(ctx, fx_stack_load_json(s, "{\"version\": 1, \"effects\": ["
                                        "{\"effect\": \"vsm_shadows\", \"params\": {\"light\": \"Key\"}},"
                                        "{\"effect\": \"rain\"}, {\"effect\": \"wet_surfaces\"},"
                                        "{\"effect\": \"rain_splashes\"}]}"));
    CHECK_OK(ctx, fx_stack_required_aux_views(s, &req));
    CHECK(req && strcmp(req, "{\"aux_views\":[{\"name\":\"light:Key\",\"kind\":\"light\",\"light\":\"Key\"},"
                             "{\"name\":\"rain_map\",\"kind\":\"rain_map\"}]}") == 0);
    fx_free(req);
    fx_stack_free(s);
    fx_frame_free(none);
    /* NaN depth in the frame: finite output */
    float *d = NULL;
    int ch = 0;
    fx_frame_pass(f, "Depth", &d, &ch);
    d[5] = NAN;
    d[6] = INFINITY;
    d[7] = -1.0f;
    float *o = run_vsm(ctx, f, "vsm", "box_sat", 7.0f, 0.3f, 0.01f);
    CHECK(o && tu_all_finite(o, N * N * 4));
    free(o);
    fx_frame_free(f);
    fx_frame_free(g);
}

/* apply sun_diffuse: where fully shadowed, the removed light is DiffCol E N.L / pi times
 * Burley's factor (principled) or 1 (lambert); N.L = N.V = 1 makes them equal. A sun
 * tilted 60 degrees off the floor's normal, camera straight down (V = +z). */
static void test_sun_diffuse(fx_context *ctx)
{
    float h[N * N];
    for (int i = 0; i < N * N; i++)
        h[i] = 3.0f; /* a roof over everything: all shadowed (the light view is straight down) */
    const char *path = write_light_view(ctx, h, "roof");
    const float dc = 0.5f, energy = 3.0f, rough = 0.7f;
    const double tilt[2] = {0.0, 60.0};
    for (int t = 0; t < 2; t++) {
        double a = tilt[t] * 3.14159265358979 / 180.0;
        /* the light travels along -to_light; to_light = (sin a, 0, cos a) */
        float lx = (float)sin(a), lz = (float)cos(a);
        float out[2] = {0, 0};
        for (int model = 0; model < 2; model++) {
            fx_frame *f = floor_frame(ctx, path);
            float *nrm = malloc(N * N * 3 * sizeof(float)), *col = malloc(N * N * 3 * sizeof(float));
            for (int i = 0; i < N * N; i++) {
                nrm[3 * i] = nrm[3 * i + 1] = 0.0f;
                nrm[3 * i + 2] = 1.0f;
                col[3 * i] = col[3 * i + 1] = col[3 * i + 2] = dc;
            }
            fx_frame_add_pass(f, "Normal", 3, nrm);
            fx_frame_add_pass(f, "DiffCol", 3, col);
            free(nrm);
            free(col);
            char json[1024];
            snprintf(json, sizeof json,
                     "{\"world_to_camera\": [[1,0,0,0],[0,1,0,0],[0,0,1,-10],[0,0,0,1]], \"projection\": "
                     "[[0.2,0,0,0],[0,0.2,0,0],[0,0,%.9g,%.9g],[0,0,0,1]], \"clip_start\": 0.1, \"clip_end\": 20, "
                     "\"orthographic\": true, \"lights\": [{\"name\": \"Sun\", \"type\": \"SUN\", \"position\": "
                     "[0,0,10], \"direction\": [%.9g, 0, %.9g], \"color\": [1,1,1], \"energy\": %g}]}",
                     -2 / 19.9, -20.1 / 19.9, -lx, -lz, energy);
            CHECK_OK(ctx, fx_frame_apply_sidecar(f, json));
            fx_stack *s = et_stack(ctx, "vsm_shadows");
            CHECK_OK(ctx, fx_stack_set_string(s, 0, "light", "Sun"));
            CHECK_OK(ctx, fx_stack_set_enum(s, 0, "method", "hard"));
            CHECK_OK(ctx, fx_stack_set_enum(s, 0, "diffuse", model ? "lambert" : "principled"));
            CHECK_OK(ctx, fx_stack_set_float(s, 0, "roughness", rough));
            CHECK_OK(ctx, fx_stack_set_float(s, 0, "normal_offset", 0.0));
            float *o = et_run(ctx, s, f);
            CHECK(o != NULL);
            out[model] = o ? o[4 * (N / 2 * N + N / 2)] : 0.0f;
            free(o);
            fx_stack_free(s);
            fx_frame_free(f);
        }
        double ndl = cos(a), lambert = dc * energy * ndl / 3.14159265358979;
        /* Burley: V = +z, H = normalize(V + L), L.H = cos(a / 2) */
        double ldh = cos(a / 2), f90 = 0.5 + 2 * rough * ldh * ldh;
        double burley = (1 + (f90 - 1) * pow(1 - ndl, 5)) * (1 + (f90 - 1) * 0.0);
        CHECK(fabs((1.0 - out[1]) - lambert) < 1e-5);
        CHECK(fabs((1.0 - out[0]) - lambert * burley) < 1e-5);
        if (t == 0)
            CHECK(out[0] == out[1]);
        printf("sun_diffuse tilt %.0f: removed lambert %.5f, principled %.5f (Burley %.4f)\n", tilt[t],
                1.0 - out[1], 1.0 - out[0], burley);
    }
}

/* The apply modes that remove more than the direct diffuse, on synthetic passes: a roof
 * over everything (all shadowed), a floor seen straight down, the Sun straight down
 * (N.L = N.V = N.H = 1), lambert diffuse. Combined c(x) (checkerboard noise around `base`
 * when `noise`), DiffCol dc, GlossCol gc, the light group g. */
typedef struct share_case {
    const char *apply, *remove_as;
    float gc, g, bounce;
    int noise, downsample;
    const char *drop; /* a pass left out */
    float base;
    float reach;  /* bounce_reach */
    int half;     /* the roof over x < N / 2 only */
} share_case;

static int share_sky; /* run_share: rows y < share_sky see no surface (the background's Depth 1e10) */

static float *run_share(fx_context *ctx, const share_case *c, fx_result *res)
{
    float h[N * N];
    for (int i = 0; i < N * N; i++)
        h[i] = !c->half || (i % N) < N / 2 ? 3.0f : 0.0f;
    fx_frame *f = floor_frame(ctx, write_light_view(ctx, h, "roof_share"));
    float *rgba = malloc(N * N * 4 * sizeof(float));
    float *nrm = malloc(N * N * 3 * sizeof(float)), *dcol = malloc(N * N * 3 * sizeof(float));
    float *gcol = malloc(N * N * 3 * sizeof(float)), *grp = malloc(N * N * 3 * sizeof(float));
    for (int i = 0; i < N * N; i++) {
        float v = c->base + (c->noise ? (((i % N) + (i / N)) % 2 ? 0.2f : -0.2f) : 0.0f);
        for (int k = 0; k < 3; k++) {
            rgba[4 * i + k] = v;
            nrm[3 * i + k] = k == 2 ? 1.0f : 0.0f;
            dcol[3 * i + k] = 0.5f;
            gcol[3 * i + k] = c->gc;
            grp[3 * i + k] = c->g;
        }
        rgba[4 * i + 3] = 1.0f;
    }
    if (c->base > 1e30f) { /* the extreme case: NaN and Inf in the passes too */
        grp[3 * 5] = NAN;
        grp[3 * 6 + 1] = INFINITY;
        gcol[3 * 7] = NAN;
        dcol[3 * 8 + 2] = -INFINITY;
        rgba[4 * 9] = NAN;
    }
    fx_frame *g = et_frame(ctx, N, N, rgba);
    /* the floor frame's passes with this Combined */
    float *d = malloc(N * N * sizeof(float));
    for (int i = 0; i < N * N; i++)
        d[i] = i / N < share_sky ? 1e10f : CAM_Z;
    fx_frame_add_pass(g, "Depth", 1, d);
    fx_camera cam = top_camera();
    fx_frame_set_camera(g, &cam);
    CHECK_OK(ctx, fx_frame_set_aux_view(g, "light:Sun", write_light_view(ctx, h, "roof_share"), &cam));
    if (!c->drop || strcmp(c->drop, "Normal"))
        fx_frame_add_pass(g, "Normal", 3, nrm);
    fx_frame_add_pass(g, "DiffCol", 3, dcol);
    if (!c->drop || strcmp(c->drop, "GlossCol"))
        fx_frame_add_pass(g, "GlossCol", 3, gcol);
    if (!c->drop || strcmp(c->drop, "Combined_libfx_light"))
        fx_frame_add_pass(g, "Combined_libfx_light", 3, grp);
    CHECK_OK(ctx, fx_frame_apply_sidecar(g,
        "{\"world_to_camera\": [[1,0,0,0],[0,1,0,0],[0,0,1,-10],[0,0,0,1]], \"projection\": "
        "[[0.2,0,0,0],[0,0.2,0,0],[0,0,-0.100502513,-1.01005025],[0,0,0,1]], \"clip_start\": 0.1, "
        "\"clip_end\": 20, \"orthographic\": true, \"lights\": [{\"name\": \"Sun\", \"type\": \"SUN\", "
        "\"position\": [0,0,10], \"direction\": [0, 0, -1], \"color\": [1,1,1], \"energy\": 3}]}"));
    fx_stack *s = et_stack(ctx, "vsm_shadows");
    CHECK_OK(ctx, fx_stack_set_string(s, 0, "light", "Sun"));
    CHECK_OK(ctx, fx_stack_set_enum(s, 0, "method", "hard"));
    CHECK_OK(ctx, fx_stack_set_enum(s, 0, "diffuse", "lambert"));
    CHECK_OK(ctx, fx_stack_set_enum(s, 0, "apply", c->apply));
    CHECK_OK(ctx, fx_stack_set_enum(s, 0, "remove_as", c->remove_as));
    CHECK_OK(ctx, fx_stack_set_float(s, 0, "roughness", 0.5f));
    CHECK_OK(ctx, fx_stack_set_float(s, 0, "bounce_loss", c->bounce));
    CHECK_OK(ctx, fx_stack_set_float(s, 0, "bounce_reach", c->reach));
    CHECK_OK(ctx, fx_stack_set_float(s, 0, "normal_offset", 0.0));
    CHECK_OK(ctx, fx_stack_set_int(s, 0, "screen_downsample", c->downsample));
    fx_frame *out = NULL;
    *res = fx_stack_run(s, g, &out);
    float *o = NULL;
    if (*res == FX_OK) {
        const fx_pass *p = fx_frame_find_pass(out, "Combined");
        o = malloc(N * N * 4 * sizeof(float));
        memcpy(o, p->data, N * N * 4 * sizeof(float));
    }
    fx_frame_free(out);
    fx_stack_free(s);
    fx_frame_free(g);
    fx_frame_free(f);
    free(rgba); free(nrm); free(dcol); free(gcol); free(grp); free(d);
    return o;
}

static void test_share_modes(fx_context *ctx)
{
    const double E = 3.0, pi = 3.14159265358979, diff = 0.5 * E / pi;
    const double a2 = 0.0625; /* alpha = roughness^2 = 0.25 */
    const double gloss_f = E / pi * (1.0 / (4.0 * a2)); /* times GlossCol: D G / (4 N.V) pi E/pi */
    const int mid = 4 * (N / 2 * N + N / 2);
    fx_result r;
    /* sun_direct: diffuse + glossy; with GlossCol 0 exactly sun_diffuse's lambert */
    for (int k = 0; k < 2; k++) {
        share_case c = {"sun_direct", "difference", k ? 0.04f : 0.0f, 0, 0, 0, 1, NULL, 4.0f, 0.0f, 0};
        float *o = run_share(ctx, &c, &r);
        CHECK(o != NULL);
        double want = diff + c.gc * gloss_f;
        if (o) {
            CHECK(fabs((4.0 - o[mid]) - want) < 1e-4);
            printf("sun_direct gc %.2f: removed %.5f (want %.5f)\n", c.gc, 4.0 - o[mid], want);
        }
        free(o);
    }
    /* light_group: min(direct, g) + bounce (g - min(direct, g)) */
    const float gs[2] = {0.2f, 1.5f}, bs[3] = {0.0f, 0.5f, 1.0f};
    for (int gi = 0; gi < 2; gi++)
        for (int bi = 0; bi < 3; bi++) {
            share_case c = {"light_group", "difference", 0.04f, gs[gi], bs[bi], 0, 1, NULL, 4.0f, 0.0f, 0};
            float *o = run_share(ctx, &c, &r);
            CHECK(o != NULL);
            double dd = diff + c.gc * gloss_f, dm = dd < c.g ? dd : c.g;
            double want = dm + c.bounce * (c.g - dm);
            if (o)
                CHECK(fabs((4.0 - o[mid]) - want) < 1e-4);
            free(o);
            /* screen_downsample 2: the same in a uniform shadow */
            c.downsample = 2;
            o = run_share(ctx, &c, &r);
            CHECK(o != NULL);
            if (o)
                CHECK(fabs((4.0 - o[mid]) - want) < 1e-4);
            free(o);
        }
    /* the passes each mode needs, by name */
    const char *drop[2][2] = {{"light_group", "Combined_libfx_light"}, {"sun_direct", "GlossCol"}};
    for (int k = 0; k < 2; k++) {
        share_case c = {drop[k][0], "difference", 0.04f, 1.0f, 0.5f, 0, 1, drop[k][1], 4.0f, 0.0f, 0};
        float *o = run_share(ctx, &c, &r);
        CHECK(o == NULL && r == FX_ERR_MISSING_PASS);
        CHECK(strstr(fx_context_error(ctx), drop[k][1]) != NULL);
        free(o);
    }
    /* ratio: on a uniform frame the same as difference; on a noisy one the noise is scaled
     * with the mean (difference keeps its whole amplitude on a smaller mean) */
    for (int m = 0; m < 3; m++) {
        const char *ap = m == 2 ? "light_group" : m ? "sun_direct" : "sun_diffuse";
        share_case c = {ap, "difference", 0.04f, 1.0f, 1.0f, 0, 1, NULL, 2.0f, 0.0f, 0};
        float *od = run_share(ctx, &c, &r);
        c.remove_as = "ratio";
        float *or_ = run_share(ctx, &c, &r);
        CHECK(od && or_);
        if (od && or_)
            CHECK(fabsf(od[mid] - or_[mid]) < 1e-5f);
        free(od);
        free(or_);
        c.noise = 1;
        c.remove_as = "difference";
        od = run_share(ctx, &c, &r);
        c.remove_as = "ratio";
        or_ = run_share(ctx, &c, &r);
        CHECK(od && or_);
        if (od && or_) {
            /* neighbours mid and mid + 1 pixel: amplitude over the mean */
            double ad = fabs(od[mid] - od[mid + 4]) / (od[mid] + od[mid + 4]);
            double ar = fabs(or_[mid] - or_[mid + 4]) / (or_[mid] + or_[mid + 4]);
            CHECK(fabs(ar - 0.2 / 2.0) < 0.006); /* about the input's own relative amplitude (the 5x5 mean of a checkerboard is off by 1/25) */
            CHECK(ad > ar * 1.2);
            printf("%s: relative noise difference %.4f, ratio %.4f (input 0.1000)\n", ap, ad, ar);
        }
        free(od);
        free(or_);
    }
    /* bounce_reach: under a roof over everything the same as 0 (V = 0); a half roof: a lit
     * pixel far from it loses a little of the bounce (0 < loss < the whole), one deep
     * under it most but not all of it; 0 keeps the lit pixel whole */
    {
        share_case c = {"light_group", "difference", 0.0f, 1.5f, 1.0f, 0, 1, NULL, 4.0f, 0.0f, 0};
        float *o0 = run_share(ctx, &c, &r);
        c.reach = 0.1f;
        float *o1 = run_share(ctx, &c, &r);
        CHECK(o0 && o1);
        if (o0 && o1)
            CHECK(fabsf(o0[mid] - o1[mid]) < 1e-5f);
        free(o0);
        free(o1);
        c.half = 1;
        c.reach = 0.0f;
        o0 = run_share(ctx, &c, &r);
        c.reach = 0.2f;
        o1 = run_share(ctx, &c, &r);
        CHECK(o0 && o1);
        const int lit = 4 * (N / 2 * N + N - 4), dark = 4 * (N / 2 * N + 4);
        if (o0 && o1) {
            const double ind = 1.5 - diff; /* the bounce part of g */
            CHECK(o0[lit] == 4.0f);
            CHECK(4.0 - o1[lit] > 0.01 * ind && 4.0 - o1[lit] < 0.5 * ind);
            CHECK(4.0 - o1[dark] > diff + 0.5 * ind && 4.0 - o1[dark] < 1.5 - 1e-3);
            printf("bounce_reach 0.2, half roof: lit pixel loses %.4f, shadowed %.4f (direct %.4f, bounce %.4f)\n",
                   4.0 - o1[lit], 4.0 - o1[dark], diff, ind);
        }
        free(o0);
        free(o1);
    }
    /* 1 and 2 threads: the same bits (ratio, bounce_reach's blur, screen_downsample 1 and 3) */
    {
        fx_context *one = NULL;
        fx_context_new(&one, 1);
        for (int ds = 1; ds <= 3; ds += 2) {
            share_case c = {"light_group", "ratio", 0.04f, 1.5f, 1.0f, 1, ds, NULL, 4.0f, 0.1f, 1};
            float *o2 = run_share(ctx, &c, &r);
            float *o1 = run_share(one, &c, &r);
            CHECK(o1 && o2 && memcmp(o1, o2, N * N * 4 * sizeof(float)) == 0);
            free(o1);
            free(o2);
        }
        fx_context_free(one);
    }
    /* ratio with screen_downsample: the lo texels' factors interpolated to the pixels. Under
     * a uniform roof the same as difference; under half a roof with bounce_reach close to
     * every pixel's own removal (screen_downsample 1) at the lit and the shadowed probe */
    {
        share_case c = {"light_group", "difference", 0.04f, 1.5f, 1.0f, 0, 1, NULL, 4.0f, 0.0f, 0};
        float *od = run_share(ctx, &c, &r);
        c.remove_as = "ratio";
        c.downsample = 3;
        float *or_ = run_share(ctx, &c, &r);
        CHECK(od && or_);
        if (od && or_)
            CHECK(fabsf(od[mid] - or_[mid]) < 1e-4f);
        free(od);
        free(or_);
        c.half = 1;
        c.reach = 0.2f;
        c.downsample = 1;
        float *o1 = run_share(ctx, &c, &r);
        c.downsample = 3;
        float *o3 = run_share(ctx, &c, &r);
        CHECK(o1 && o3 && tu_all_finite(o3, N * N * 4));
        const int lit = 4 * (N / 2 * N + N - 4), dark = 4 * (N / 2 * N + 4);
        if (o1 && o3) {
            CHECK(fabsf(o1[lit] - o3[lit]) < 0.02f * o1[lit]);
            CHECK(fabsf(o1[dark] - o3[dark]) < 0.02f * o1[dark] + 1e-3f);
            printf("ratio, half roof, reach 0.2: screen_downsample 1: lit %.4f dark %.4f; 3: lit %.4f dark %.4f\n",
                   o1[lit], o1[dark], o3[lit], o3[dark]);
        }
        free(o1);
        free(o3);
    }
    /* huge values stay finite */
    for (int m = 0; m < 2; m++) {
        share_case c = {"light_group", m ? "ratio" : "difference", 3e38f, 3e38f, 0.5f, 1, 2, NULL, 3e38f, (float)m * 0.1f, m};
        float *o = run_share(ctx, &c, &r);
        CHECK(o && tu_all_finite(o, N * N * 4));
        free(o);
    }
}

/* bounce_reach with screen_downsample: the surroundings' visibility V is the mean of the
 * visibility over the pixels with a surface (a Gaussian of v m over one of m, m = 1 on a
 * surface); on the reduced grid both blurred fields are interpolated to the pixel before
 * the division. Where the weight m varies (the floor's edge against the sky, rows 0..23
 * here, under half a roof) the removal still follows every pixel's own (screen_downsample
 * 1) within 5 % of the light group's bounce part, at every floor pixel away from the roof's
 * edge (whose direct shadow has its own reduced-grid edge). */
static void test_bounce_reach_sky_edge(fx_context *ctx)
{
    const double E = 3.0, pi = 3.14159265358979, ind = 1.5 - 0.5 * E / pi; /* the bounce part of g */
    fx_result r;
    share_case c = {"light_group", "difference", 0.0f, 1.5f, 1.0f, 0, 1, NULL, 4.0f, 0.2f, 1};
    share_sky = 24;
    float *o1 = run_share(ctx, &c, &r);
    for (int ds = 2; ds <= 3; ds++) {
        c.downsample = ds;
        float *o = run_share(ctx, &c, &r);
        double e = o && o1 ? 0 : INFINITY, lost = 0;
        int ex = -1, ey = -1;
        for (int i = share_sky * N; o && o1 && i < N * N; i++) {
            if (abs(i % N - N / 2) <= 3)
                continue; /* the roof's edge: the direct shadow's own reduced-grid edge */
            if (fabs((double)o[4 * i] - o1[4 * i]) > e)
                ex = i % N, ey = i / N;
            e = fmax(e, fabs((double)o[4 * i] - o1[4 * i]));
            lost = fmax(lost, 4.0 - o1[4 * i]);
        }
        printf("bounce_reach 0.2 at the sky's edge, screen_downsample %d: max |removal - every pixel's| %.4f at "
               "%d,%d (bounce part %.4f, largest removal %.4f)\n",
               ds, e, ex, ey, ind, lost);
        /* measured 0.015 (2) and 0.031 (3); the interpolated weight extrapolated the wrong
         * way between two rows of the reduced grid gives 0.12 and 0.22 */
        CHECK(e < 0.05 * ind && lost > 0.5);
        free(o);
    }
    share_sky = 0;
    free(o1);
}

/* params_version 2 made remove_as ratio the default: a version-1 recipe keeps difference
 * unless it names one; a version-2 recipe gets ratio. */
static void test_migration(fx_context *ctx)
{
    const char *recipes[3] = {
        "{\"version\": 1, \"effects\": [{\"effect\": \"vsm_shadows\", \"params\": {\"apply\": \"sun_diffuse\"}}]}",
        "{\"version\": 1, \"effects\": [{\"effect\": \"vsm_shadows\", \"params\": {\"remove_as\": \"ratio\"}}]}",
        "{\"version\": 1, \"effects\": [{\"effect\": \"vsm_shadows\", \"params_version\": 2, \"params\": "
        "{\"apply\": \"sun_diffuse\"}}]}"};
    const char *want[3] = {"\"remove_as\":\"difference\"", "\"remove_as\":\"ratio\"", "\"remove_as\":\"ratio\""};
    for (int i = 0; i < 3; i++) {
        fx_stack *s = NULL;
        CHECK_OK(ctx, fx_stack_new(ctx, &s));
        CHECK_OK(ctx, fx_stack_load_json(s, recipes[i]));
        char *e = NULL;
        CHECK_OK(ctx, fx_stack_effective_params_json(s, 0, &e));
        CHECK(e && strstr(e, want[i]) != NULL);
        if (e && !strstr(e, want[i]))
            fprintf(stderr, "migration %d: %s\n", i, e);
        fx_free(e);
        fx_stack_free(s);
    }
}

/* The per-context cache of built light maps (scene/aux_map.h): frames 2..N reuse the map
 * and give the same bits as an uncached context (1 and 2 threads, box and Gaussian); a
 * replaced view file, other filter parameters or a too small limit build again. */
static void test_cache(void)
{
    float h[N * N];
    for (int i = 0; i < N * N; i++)
        h[i] = ((i % N) > N / 4 && (i % N) < N / 2 && (i / N) > N / 4 && (i / N) < 3 * N / 4) ? 2.0f : 0.0f;
    fx_context *cached = NULL, *plain = NULL, *one = NULL;
    fx_context_new(&cached, 2);
    fx_context_new(&plain, 2);
    fx_context_new(&one, 1);
    CHECK_OK(plain, fx_context_set_aux_cache(plain, 0));
    CHECK_OK(one, fx_context_set_aux_cache(one, 0));
    const char *path = write_light_view(cached, h, "cache");
    fx_frame *fc = floor_frame(cached, path), *fp = floor_frame(plain, path), *f1 = floor_frame(one, path);
    const char *filters[] = {"box_sat", "gaussian"};
    for (int k = 0; k < 2; k++) {
        float *ref = run_vsm(plain, fp, "vsm", filters[k], 9.0f, 0.3f, 0.01f);
        float *ref1 = run_vsm(one, f1, "vsm", filters[k], 9.0f, 0.3f, 0.01f);
        CHECK(ref && ref1 && memcmp(ref, ref1, N * N * 4 * sizeof(float)) == 0);
        for (int frame = 0; frame < 3; frame++) {
            float *o = run_vsm(cached, fc, "vsm", filters[k], 9.0f, 0.3f, 0.01f);
            CHECK(o && ref && memcmp(o, ref, N * N * 4 * sizeof(float)) == 0);
            free(o);
        }
        free(ref);
        free(ref1);
    }
    long built, reused;
    fx_aux_cache_stats(cached, &built, &reused);
    /* each filter: the view's base (box: its normalised depth; Gaussian: its moments) and
     * the filtered copy; frames 2 and 3 reuse the filtered maps */
    CHECK(built == 4 && reused == 4);
    fx_aux_cache_stats(plain, &built, &reused);
    CHECK(built == 4 && reused == 0);
    /* pcf reads the unfiltered depth: another entry, same bits as uncached */
    float *p1 = run_vsm(cached, fc, "pcf", "box_sat", 5.0f, 0.3f, 0.01f);
    float *p2 = run_vsm(plain, fp, "pcf", "box_sat", 5.0f, 0.3f, 0.01f);
    CHECK(p1 && p2 && memcmp(p1, p2, N * N * 4 * sizeof(float)) == 0);
    free(p1);
    free(p2);
    /* a new filter width (a slider moved in the live loop) filters the cached moments again:
     * one build (the filtered copy), no read of the view, the bits of an uncached run */
    fx_aux_cache_stats(cached, &built, &reused);
    long b1 = built;
    float *g1 = run_vsm(cached, fc, "vsm", "gaussian", 13.0f, 0.3f, 0.01f);
    float *g2 = run_vsm(plain, fp, "vsm", "gaussian", 13.0f, 0.3f, 0.01f);
    fx_aux_cache_stats(cached, &built, &reused);
    CHECK(built == b1 + 1);
    CHECK(g1 && g2 && memcmp(g1, g2, N * N * 4 * sizeof(float)) == 0);
    free(g1);
    free(g2);
    /* the full-resolution box: from the cached normalised depth */
    g1 = run_vsm(cached, fc, "vsm", "box_sat", 13.0f, 0.3f, 0.01f);
    g2 = run_vsm(plain, fp, "vsm", "box_sat", 13.0f, 0.3f, 0.01f);
    fx_aux_cache_stats(cached, &built, &reused);
    CHECK(built == b1 + 2);
    CHECK(g1 && g2 && memcmp(g1, g2, N * N * 4 * sizeof(float)) == 0);
    free(g1);
    free(g2);
    /* the view re-rendered to the same path: built again, and the new shadow shows */
    float *before = run_vsm(cached, fc, "vsm", "box_sat", 9.0f, 0.3f, 0.01f);
    for (int i = 0; i < N * N; i++)
        h[i] = (i % N) > N / 2 ? 2.0f : 0.0f;
    write_light_view(cached, h, "cache");
    fx_aux_cache_stats(cached, &built, &reused);
    long b0 = built;
    float *after = run_vsm(cached, fc, "vsm", "box_sat", 9.0f, 0.3f, 0.01f);
    float *after_ref = run_vsm(plain, fp, "vsm", "box_sat", 9.0f, 0.3f, 0.01f);
    fx_aux_cache_stats(cached, &built, &reused);
    CHECK(built == b0 + 2); /* the new file's base and its filtered map */
    CHECK(before && after && memcmp(before, after, N * N * 4 * sizeof(float)) != 0);
    CHECK(after && after_ref && memcmp(after, after_ref, N * N * 4 * sizeof(float)) == 0);
    free(before);
    free(after_ref);
    /* a limit below one map: nothing is kept, every run builds, same bits */
    CHECK_OK(cached, fx_context_set_aux_cache(cached, 1000));
    for (int r = 0; r < 2; r++) {
        float *o = run_vsm(cached, fc, "vsm", "box_sat", 9.0f, 0.3f, 0.01f);
        CHECK(o && after && memcmp(o, after, N * N * 4 * sizeof(float)) == 0);
        free(o);
    }
    fx_aux_cache_stats(cached, &built, &reused);
    CHECK(built == b0 + 2 + 2 * 2);
    free(after);
    fx_frame_free(fc);
    fx_frame_free(fp);
    fx_frame_free(f1);
    fx_context_free(cached); /* frees the entries (leak-checked under ASan) */
    fx_context_free(plain);
    fx_context_free(one);
}


/* A stack run in one context on frames read by another (a reader context and a context per
 * render thread): the maps live in the frames' context's cache and go back to it when the
 * run ends, so that cache stays within its limit: with room for one map, views 1, 2, 1
 * build three times, as in one context. (Released through the running context, view 1's
 * entry stayed in use: view 2's map was not cached and the third run reused view 1's.) */
static void test_cache_cross_context(void)
{
    float h[N * N];
    fx_context *writer = NULL;
    fx_context_new(&writer, 1);
    for (int i = 0; i < N * N; i++)
        h[i] = (i % N) > N / 3 ? 2.0f : 0.0f;
    /* each write_light_view empties its folder: the first view moves to a folder of its own */
    char written[600], path1[600];
    snprintf(written, sizeof written, "%s", write_light_view(writer, h, "cross1"));
    snprintf(path1, sizeof path1, "%s/cross1.exr", tu_tmpdir("vsm_cross_context"));
    CHECK(rename(written, path1) == 0);
    for (int i = 0; i < N * N; i++)
        h[i] = (i % N) > 2 * N / 3 ? 2.0f : 0.0f;
    const char *p2 = write_light_view(writer, h, "cross2");
    fx_context_free(writer);
    for (int cross = 0; cross < 2; cross++) {
        fx_context *reader = NULL, *runner = NULL;
        fx_context_new(&reader, 2);
        fx_context_new(&runner, 2);
        /* room for one view's entry, not two (the cache counts a depth map's entry as 3
         * floats a texel and the view) */
        const uint64_t entry = (uint64_t)N * N * 3 * sizeof(float) + sizeof(fx_aux_view);
        CHECK_OK(reader, fx_context_set_aux_cache(reader, entry * 3 / 2));
        fx_frame *f1 = floor_frame(reader, path1), *f2 = floor_frame(reader, p2);
        fx_context *run_in = cross ? runner : reader;
        float *o[3];
        for (int k = 0; k < 3; k++) /* views 1, 2, 1 */
            o[k] = run_vsm(run_in, k == 1 ? f2 : f1, "pcf", "box_sat", 5.0f, 0.3f, 0.01f);
        long built = 0, reused = 0;
        fx_aux_cache_stats(reader, &built, &reused);
        CHECK(built == 3 && reused == 0);
        CHECK(o[0] && o[1] && o[2] && memcmp(o[0], o[2], N * N * 4 * sizeof(float)) == 0 &&
              memcmp(o[0], o[1], N * N * 4 * sizeof(float)) != 0);
        if (built != 3 || reused != 0)
            fprintf(stderr, "cache across contexts (%s): built %ld, reused %ld\n", cross ? "two" : "one", built,
                    reused);
        for (int k = 0; k < 3; k++)
            free(o[k]);
        fx_frame_free(f1);
        fx_frame_free(f2);
        fx_context_free(runner);
        fx_context_free(reader); /* frees the entries (leak-checked under ASan) */
    }
}

/* The box filter (separable running sums in double) gives the SAT's box means on odd
 * sizes, 1x1, 1xN and radii beyond the map; the moments' reduction levels are the block
 * means of the moments (partial blocks at the far borders) with finite lookups. */
static void test_box_and_levels(fx_context *ctx)
{
    int sizes[][2] = {{37, 23}, {1, 1}, {1, 9}, {9, 1}, {5, 3}};
    uint32_t st = 99;
    for (size_t k = 0; k < sizeof sizes / sizeof sizes[0]; k++) {
        int w = sizes[k][0], h = sizes[k][1];
        float *raw = malloc((size_t)w * h * sizeof(float));
        for (int i = 0; i < w * h; i++) {
            st = st * 1664525u + 1013904223u;
            raw[i] = 3.0f + 4.0f * (float)(st >> 8) / 16777216.0f;
        }
        raw[0] = NAN; /* a hostile texel: normalised to 1 (nothing occludes) */
        int radii[] = {0, 1, 2, 5, 40};
        for (int ri = 0; ri < 5; ri++) {
            fx_shadow_map sm;
            CHECK_OK(ctx, fx_shadow_map_build(ctx, raw, w, h, 1.0f, 10.0f, 1, &sm, "test"));
            CHECK(sm.moments == NULL); /* made by the filter call */
            fx_shadow_map unf;
            CHECK_OK(ctx, fx_shadow_map_build(ctx, raw, w, h, 1.0f, 10.0f, 1, &unf, "test"));
            CHECK_OK(ctx, fx_shadow_map_filter(ctx, &unf, FX_SHADOW_FILTER_BOX_SAT, 1.0f, "test"));
            CHECK(unf.moments != NULL);
            float *want = malloc((size_t)w * h * 2 * sizeof(float));
            CHECK_OK(ctx, fx_sat_box_filter(ctx, unf.moments, want, w, h, 2, radii[ri], "test"));
            fx_shadow_map_free(&unf);
            /* fused (moments made row by row inside the box) and on an existing array */
            CHECK_OK(ctx, fx_shadow_map_filter(ctx, &sm, FX_SHADOW_FILTER_BOX_SAT, 2.0f * radii[ri] + 1.0f, "test"));
            fx_shadow_map two;
            CHECK_OK(ctx, fx_shadow_map_build(ctx, raw, w, h, 1.0f, 10.0f, 1, &two, "test"));
            CHECK_OK(ctx, fx_shadow_map_filter(ctx, &two, FX_SHADOW_FILTER_BOX_SAT, 1.0f, "test"));
            CHECK_OK(ctx, fx_shadow_map_filter(ctx, &two, FX_SHADOW_FILTER_BOX_SAT, 2.0f * radii[ri] + 1.0f, "test"));
            CHECK(memcmp(two.moments, sm.moments, (size_t)w * h * 2 * sizeof(float)) == 0);
            fx_shadow_map_free(&two);
            double worst = 0;
            for (int i = 0; i < w * h * 2; i++)
                worst = fmax(worst, isfinite(sm.moments[i]) ? fabs(sm.moments[i] - want[i]) : 1e9);
            if (worst > 1e-6)
                fprintf(stderr, "box %dx%d r %d: max |running sums - SAT| = %.2e\n", w, h, radii[ri], worst);
            CHECK(worst < 1e-6);
            free(want);
            fx_shadow_map_free(&sm);
        }
        for (int level = 1; level <= 3; level++) {
            fx_shadow_map full, red;
            CHECK_OK(ctx, fx_shadow_map_build(ctx, raw, w, h, 1.0f, 10.0f, 1, &full, "test"));
            CHECK_OK(ctx, fx_shadow_map_filter(ctx, &full, FX_SHADOW_FILTER_BOX_SAT, 1.0f, "test"));
            CHECK_OK(ctx, fx_shadow_map_build(ctx, raw, w, h, 1.0f, 10.0f, 1, &red, "test"));
            CHECK_OK(ctx, fx_shadow_map_filter(ctx, &red, FX_SHADOW_FILTER_WITH_LEVEL(FX_SHADOW_FILTER_BOX_SAT, level),
                                               1.5f, "test"));
            int step = 1 << level, mw = (w + step - 1) / step, mh = (h + step - 1) / step;
            CHECK(red.mwidth == mw && red.mheight == mh && red.level == level);
            double worst = 0;
            for (int my = 0; my < mh; my++)
                for (int mx = 0; mx < mw; mx++) {
                    double a = 0, b = 0;
                    int n = 0;
                    for (int y = my * step; y < my * step + step && y < h; y++)
                        for (int x = mx * step; x < mx * step + step && x < w; x++) {
                            a += full.moments[2 * (y * w + x)];
                            b += full.moments[2 * (y * w + x) + 1];
                            n++;
                        }
                    worst = fmax(worst, fabs(red.moments[2 * (my * mw + mx)] - a / n));
                    worst = fmax(worst, fabs(red.moments[2 * (my * mw + mx) + 1] - b / n));
                }
            CHECK(worst < 1e-6);
            /* lookups anywhere on (and off) the full map's coordinates: finite */
            float coords[] = {-5.0f, 0.0f, 0.5f, (float)w * 0.5f, (float)w, (float)w + 7.0f};
            for (int a = 0; a < 6; a++)
                for (int b = 0; b < 6; b++) {
                    float m1, m2;
                    fx_shadow_map_moments(&red, coords[a], coords[b] * (float)h / (float)w, &m1, &m2);
                    CHECK(isfinite(m1) && isfinite(m2));
                }
            fx_shadow_map_free(&full);
            fx_shadow_map_free(&red);
        }
        free(raw);
    }
}

/* map_level through the effect: the square occluder's shadow stays (centre dark, far
 * corners lit), every level within a few texels of the full map's picture, the same bits
 * on 1 and 2 threads; odd and 1x1 frames with NaN depth stay finite. */
static void test_map_level_effect(fx_context *ctx)
{
    float h[N * N];
    for (int y = 0; y < N; y++)
        for (int x = 0; x < N; x++) {
            float wx = -L + (x + 0.5f) * 2 * L / N, wy = L - (y + 0.5f) * 2 * L / N;
            h[y * N + x] = fabsf(wx) < 1.5f && fabsf(wy) < 1.5f ? 2.0f : 0.0f;
        }
    const char *path = write_light_view(ctx, h, "square_levels");
    fx_frame *f = floor_frame(ctx, path);
    fx_context *c1 = NULL;
    fx_context_new(&c1, 1);
    fx_frame *f1 = floor_frame(c1, path);
    float *ref = NULL;
    for (int level = 0; level <= 4; level++) {
        char params[160];
        snprintf(params, sizeof params, "\"apply\": \"combined\", \"filter_size\": 5, \"map_level\": %d", level);
        float *o = et_run_effect(ctx, "vsm_shadows", f, params, NULL);
        float *o1 = et_run_effect(c1, "vsm_shadows", f1, params, NULL);
        CHECK(o && o1 && memcmp(o, o1, N * N * 4 * sizeof(float)) == 0);
        CHECK(o && tu_all_finite(o, N * N * 4));
        if (o && level <= 2) {
            CHECK(o[4 * (N / 2 * N + N / 2)] < 0.05f);
            CHECK(o[0] > 0.95f && o[4 * (N * N - 1)] > 0.95f);
        }
        if (level == 0)
            ref = o;
        else if (o && ref) {
            double mae = 0;
            for (int i = 0; i < N * N; i++)
                mae += fabs(o[4 * i] - ref[4 * i]);
            mae /= N * N;
            fprintf(stderr, "map_level %d: mean |visibility - level 0| = %.4f\n", level, mae);
            CHECK(mae < 0.02 * (1 << level));
        }
        if (o != ref)
            free(o);
        free(o1);
    }
    free(ref);
    fx_frame_free(f1);
    fx_context_free(c1);
    fx_frame_free(f);
    /* odd and 1x1 frames, NaN / Inf / negative depth, through the same light view */
    int sizes[][2] = {{1, 1}, {7, 5}, {1, 13}, {13, 1}};
    for (size_t k = 0; k < sizeof sizes / sizeof sizes[0]; k++) {
        int w = sizes[k][0], hh = sizes[k][1];
        float *rgba = malloc((size_t)w * hh * 4 * sizeof(float)), *d = malloc((size_t)w * hh * sizeof(float));
        for (int i = 0; i < w * hh * 4; i++)
            rgba[i] = 1.0f;
        for (int i = 0; i < w * hh; i++)
            d[i] = i % 4 == 1 ? NAN : i % 4 == 2 ? INFINITY : i % 4 == 3 ? -1.0f : CAM_Z;
        fx_frame *g = et_frame(ctx, w, hh, rgba);
        fx_frame_add_pass(g, "Depth", 1, d);
        fx_camera cam = top_camera();
        fx_frame_set_camera(g, &cam);
        CHECK_OK(ctx, fx_frame_set_aux_view(g, "light:Sun", path, &cam));
        for (int level = 0; level <= 4; level += 2) {
            char params[160];
            snprintf(params, sizeof params,
                     "\"apply\": \"combined\", \"filter_size\": 5, \"map_level\": %d, \"screen_downsample\": %d", level,
                     1 + 3 * level / 2);
            float *o = et_run_effect(ctx, "vsm_shadows", g, params, NULL);
            CHECK(o && tu_all_finite(o, (size_t)w * hh * 4));
            free(o);
        }
        float *o = et_run_effect(ctx, "vsm_shadows", g, "\"apply\": \"combined\", \"map_level\": 3, \"filter_size\": 1",
                                 NULL);
        CHECK(o && tu_all_finite(o, (size_t)w * hh * 4));
        free(o);
        fx_frame_free(g);
        free(rgba);
        free(d);
    }
}

/* screen_downsample: the square's shadow through the reduced lookups stays (centre dark,
 * corners lit), close to every pixel's own lookup, the same bits on 1 and 2 threads, the
 * same inside a mask whose ROI does not start on the lo grid; pixels with no surface stay
 * untouched. */
static void test_screen_downsample(fx_context *ctx)
{
    float h[N * N];
    for (int y = 0; y < N; y++)
        for (int x = 0; x < N; x++) {
            float wx = -L + (x + 0.5f) * 2 * L / N, wy = L - (y + 0.5f) * 2 * L / N;
            h[y * N + x] = fabsf(wx) < 1.5f && fabsf(wy) < 1.5f ? 2.0f : 0.0f;
        }
    const char *path = write_light_view(ctx, h, "square_screen");
    fx_frame *f = floor_frame(ctx, path);
    fx_context *c1 = NULL;
    fx_context_new(&c1, 1);
    fx_frame *f1 = floor_frame(c1, path);
    float *ref = et_run_effect(ctx, "vsm_shadows", f, "\"apply\": \"combined\", \"filter_size\": 5", NULL);
    CHECK(ref != NULL);
    const int fs[] = {2, 3, 4, 5, 8}; /* 5: the draft's (an odd block: its centre texel) */
    for (int k = 0; ref && k < 5; k++) {
        char params[160];
        snprintf(params, sizeof params, "\"apply\": \"combined\", \"filter_size\": 5, \"screen_downsample\": %d", fs[k]);
        float *o = et_run_effect(ctx, "vsm_shadows", f, params, NULL);
        float *o1 = et_run_effect(c1, "vsm_shadows", f1, params, NULL);
        CHECK(o && o1 && memcmp(o, o1, N * N * 4 * sizeof(float)) == 0);
        CHECK(o && tu_all_finite(o, N * N * 4));
        if (o) {
            CHECK(o[4 * (N / 2 * N + N / 2)] < 0.05f);
            CHECK(o[0] > 0.95f && o[4 * (N * N - 1)] > 0.95f);
            double mae = 0;
            for (int i = 0; i < N * N; i++)
                mae += fabs(o[4 * i] - ref[4 * i]);
            mae /= N * N;
            fprintf(stderr, "screen_downsample %d: mean |visibility - every pixel| = %.4f\n", fs[k], mae);
            CHECK(mae < 0.01 * fs[k]);
        }
        /* a mask: the same ROI logic, finite, untouched outside */
        float *m = et_run_effect(ctx, "vsm_shadows", f, params, "{\"rect\": [5, 7, 31, 29]}");
        CHECK(m && tu_all_finite(m, N * N * 4));
        free(m);
        free(o);
        free(o1);
    }
    free(ref);
    fx_frame_free(f1);
    fx_context_free(c1);
    fx_frame_free(f);
}

/* PCF with derivative_bias on a receiver tilted both ways (z = 0.3 x + 0.6 y) that the light
 * sees unoccluded: the plane fitted from the two tangent points follows it exactly, so every
 * tap agrees with its depth and every pixel away from the map's border is fully lit. */
static void test_pcf_tilted_plane(fx_context *ctx)
{
    float h[N * N], *nrm = malloc(N * N * 3 * sizeof(float)), *d = NULL;
    const float len = sqrtf(0.3f * 0.3f + 0.6f * 0.6f + 1.0f);
    for (int y = 0; y < N; y++)
        for (int x = 0; x < N; x++) {
            const float wx = -L + (x + 0.5f) * 2 * L / N, wy = L - (y + 0.5f) * 2 * L / N;
            h[y * N + x] = 0.3f * wx + 0.6f * wy;
            nrm[3 * (y * N + x)] = -0.3f / len;
            nrm[3 * (y * N + x) + 1] = -0.6f / len;
            nrm[3 * (y * N + x) + 2] = 1.0f / len;
        }
    fx_frame *f = floor_frame(ctx, write_light_view(ctx, h, "tilted"));
    int ch = 0;
    fx_frame_pass(f, "Depth", &d, &ch);
    for (int i = 0; i < N * N; i++)
        d[i] = CAM_Z - h[i];
    fx_frame_add_pass(f, "Normal", 3, nrm);
    float *o = run_vsm(ctx, f, "pcf", "box_sat", 4.0f, 0.0f, 0.01f);
    float least = 1.0f;
    for (int y = 8; o && y < N - 8; y++)
        for (int x = 8; x < N - 8; x++)
            least = o[4 * (y * N + x)] < least ? o[4 * (y * N + x)] : least;
    CHECK(o && least > 0.999f);
    if (!(least > 0.999f))
        fprintf(stderr, "pcf on a tilted plane: least visibility %.4f\n", least);
    free(o);
    free(nrm);
    fx_frame_free(f);
}

/* depth_min (the medium's entry in god_rays volumetric) is the least normalised depth
 * wherever it lies (first, middle or last row, first or last column, a row's tail past its
 * 4-lane part), 1 and 2 threads; 1 when every texel is background or non-finite. */
static void test_depth_min(fx_context *c2)
{
    fx_context *c1 = NULL;
    fx_context_new(&c1, 1);
    const int w = 37, h = 29;
    float *raw = malloc((size_t)w * h * sizeof(float));
    const int at[][2] = {{0, 0}, {w - 1, h - 1}, {5, h / 2}, {w - 1, 0}, {0, h - 1}, {-1, -1}};
    for (size_t k = 0; k < sizeof at / sizeof at[0]; k++)
        for (int t = 0; t < 2; t++) {
            for (int i = 0; i < w * h; i++)
                raw[i] = at[k][0] < 0 ? (i % 2 ? 1e10f : NAN) : 5.0f + (float)((i * 7919) % 13) * 0.1f;
            if (at[k][0] >= 0)
                raw[at[k][1] * w + at[k][0]] = 2.5f;
            fx_shadow_map sm;
            fx_context *ctx = t ? c2 : c1;
            CHECK_OK(ctx, fx_shadow_map_build(ctx, raw, w, h, 1.0f, 10.0f, 0, &sm, "test"));
            float want = 1.0f;
            for (int i = 0; i < w * h; i++)
                want = sm.depth[i] < want ? sm.depth[i] : want;
            CHECK(sm.depth_min == want);
            CHECK(at[k][0] < 0 ? want == 1.0f : want == fx_shadow_map_norm(&sm, 2.5f));
            /* in place over the raw buffer (the aux-map cache's light views): the same bits */
            float *own = fx_mem_alloc((size_t)w * h * sizeof(float));
            memcpy(own, raw, (size_t)w * h * sizeof(float));
            fx_shadow_map ip;
            CHECK_OK(ctx, fx_shadow_map_build_in_place(ctx, own, w, h, 1.0f, 10.0f, 0, &ip, "test"));
            CHECK(ip.depth == own && ip.depth_min == sm.depth_min &&
                  memcmp(ip.depth, sm.depth, (size_t)w * h * sizeof(float)) == 0);
            fx_shadow_map_free(&ip);
            /* reduced (every f-th texel, god_rays' light_view_downsample): the kept texels'
             * bits and the least of the kept rows, every texel of them, wherever it lies */
            for (int f = 2; f <= 3; f++) {
                fx_shadow_map rm;
                CHECK_OK(ctx, fx_shadow_map_build_reduced(ctx, raw, w, h, f, 1.0f, 10.0f, &rm, "test"));
                const int o = (f - 1) / 2;
                float kept_min = 1.0f;
                for (int Y = 0; Y < rm.height; Y++)
                    for (int x = 0, y = f * Y + o < h ? f * Y + o : h - 1; x < w; x++)
                        kept_min = sm.depth[y * w + x] < kept_min ? sm.depth[y * w + x] : kept_min;
                CHECK(rm.depth_min == kept_min);
                /* the least on a kept row: the view's least; else above it */
                const int on_kept = at[k][0] >= 0 && (at[k][1] == h - 1 || at[k][1] % f == o);
                CHECK(on_kept ? kept_min == sm.depth_min : kept_min > sm.depth_min || at[k][0] < 0);
                for (int Y = 0; Y < rm.height; Y++)
                    for (int X = 0; X < rm.width; X++) {
                        const int x = f * X + o < w ? f * X + o : w - 1, y = f * Y + o < h ? f * Y + o : h - 1;
                        CHECK(memcmp(&rm.depth[Y * rm.width + X], &sm.depth[y * w + x], sizeof(float)) == 0);
                    }
                fx_shadow_map_free(&rm);
            }
            fx_shadow_map_free(&sm);
        }
    /* a depth range under 2: the reader's -Inf (-FLT_MAX) normalises to 1, not -1 (its z
     * overflows), so the row's least raw value is not its least normalised one */
    for (int i = 0; i < w * h; i++)
        raw[i] = 1.5f + (float)(i % 5) * 0.1f;
    raw[4 * w + 7] = -FLT_MAX; /* row 4: kept at f = 2 and 3 */
    raw[4 * w + 8] = 1.05f;
    for (int f = 1; f <= 3; f += 2) {
        fx_shadow_map sm, rm;
        CHECK_OK(c2, fx_shadow_map_build(c2, raw, w, h, 1.0f, 2.0f, 0, &sm, "test"));
        CHECK_OK(c2, fx_shadow_map_build_reduced(c2, raw, w, h, f == 1 ? 2 : f, 1.0f, 2.0f, &rm, "test"));
        CHECK(sm.depth_min == fx_shadow_map_norm(&sm, 1.05f) && rm.depth_min == sm.depth_min);
        fx_shadow_map_free(&sm);
        fx_shadow_map_free(&rm);
    }
    free(raw);
    fx_context_free(c1);
    /* fx_frame_take_pass_data: the pass leaves the frame with its pixels; not when shared */
    fx_frame *f = NULL, *g = NULL;
    fx_frame_new(c2, 8, 4, &f);
    fx_frame_new(c2, 8, 4, &g);
    float ones[32];
    for (int i = 0; i < 32; i++)
        ones[i] = 1.0f + (float)i;
    CHECK_OK(c2, fx_frame_add_pass(f, "Depth", 1, ones));
    CHECK_OK(c2, fx_frame_add_pass(f, "Normal", 3, NULL));
    CHECK_OK(c2, fx_frame_share_pass(g, "Depth", f, fx_frame_find_pass(f, "Depth")));
    CHECK(!fx_frame_take_pass_data(f, "Depth") && fx_frame_pass_count(f) == 2); /* g holds it too */
    fx_frame_free(g);
    const float *was = fx_frame_find_pass(f, "Depth")->data;
    float *got = fx_frame_take_pass_data(f, "Depth");
    CHECK(got == was && got && got[31] == 32.0f && fx_frame_pass_count(f) == 1 && !fx_frame_find_pass(f, "Depth") &&
          fx_frame_find_pass(f, "Normal"));
    CHECK(!fx_frame_take_pass_data(f, "Depth"));
    fx_mem_free(got);
    fx_frame_free(f);
}

int main(void)
{
    fx_context *ctx = NULL;
    fx_context_new(&ctx, 2);
    test_depth_min(ctx);
    test_hard_limit(ctx);
    test_pcf_tilted_plane(ctx);
    test_soft_edge_width(ctx);
    test_variance_clamp(ctx);
    test_bleeding(ctx);
    test_sidecar_threads_errors(ctx);
    test_sat_precision(ctx);
    test_sun_diffuse(ctx);
    test_share_modes(ctx);
    test_migration(ctx);
    test_cache();
    test_cache_cross_context();
    test_box_and_levels(ctx);
    test_map_level_effect(ctx);
    test_screen_downsample(ctx);
    test_bounce_reach_sky_edge(ctx);
    fx_context_free(ctx);
    return tu_finish("test_vsm_shadows");
}
