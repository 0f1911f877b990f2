/* god_rays through the public API: rays brighten towards the light and shafts follow
 * occluders; weight/exposure 0 and a light behind the camera are the identity; the scene
 * light is projected with the camera; extremes (samples 1..2000, decay/density 0 and 1, a
 * light far off screen) stay finite and bounded; naive and polar converge to the same
 * image; bit-identical for 1 and 2 threads. */
#include "fx_effect_test.h"

#include <float.h>
#include <math.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

#define W 96
#define H 64

/* black image with a bright disc (radius 4) around (cx, cy) and a grey floor */
static float *spot_image(double cx, double cy)
{
    float *p = calloc((size_t)W * H * 4, sizeof(float));
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            float *q = p + ((size_t)y * W + x) * 4;
            double d = hypot(x + 0.5 - cx, y + 0.5 - cy);
            float v = d < 4.0 ? 4.0f : 0.05f;
            q[0] = q[1] = q[2] = v;
            q[3] = 1.0f;
        }
    return p;
}

static float lum(const float *img, int x, int y)
{
    const float *q = img + ((size_t)y * W + x) * 4;
    return 0.2126f * q[0] + 0.7152f * q[1] + 0.0722f * q[2];
}

typedef struct rset {
    const char *method;
    int samples;
    double decay, density, weight, exposure;
    float lx, ly;
    int jitter;
    double polar_res;
    int levels;
    int down;
} rset;

static rset defaults(void)
{
    rset r = {"naive", 100, 0.97, 0.9, 1.0, 0.02, 0.5f, 0.3f, 0, 0, 0, 0};
    return r;
}

static fx_stack *rays_stack(fx_context *ctx, rset r)
{
    fx_stack *s = et_stack(ctx, "god_rays");
    float pos[2] = {r.lx, r.ly};
    if (!s)
        return NULL;
    fx_result e = FX_OK;
    e |= fx_stack_set_enum(s, 0, "light_source", "screen");
    e |= fx_stack_set_enum(s, 0, "occlusion", "luminance");
    e |= fx_stack_set_floats(s, 0, "light_position", pos, 2);
    e |= fx_stack_set_enum(s, 0, "method", r.method);
    e |= fx_stack_set_int(s, 0, "samples", r.samples);
    e |= fx_stack_set_float(s, 0, "decay", r.decay);
    e |= fx_stack_set_float(s, 0, "density", r.density);
    e |= fx_stack_set_float(s, 0, "weight", r.weight);
    e |= fx_stack_set_float(s, 0, "exposure", r.exposure);
    e |= fx_stack_set_int(s, 0, "jitter", r.jitter);
    if (r.polar_res > 0)
        e |= fx_stack_set_float(s, 0, "polar_resolution", r.polar_res);
    if (r.levels > 0)
        e |= fx_stack_set_int(s, 0, "polar_levels", r.levels);
    if (r.down > 0)
        e |= fx_stack_set_int(s, 0, "polar_downsample", r.down);
    if (e != FX_OK) {
        fprintf(stderr, "setup: %s\n", fx_context_error(ctx));
        fx_stack_free(s);
        return NULL;
    }
    return s;
}

static float *run_rays(fx_context *ctx, const float *img, rset r)
{
    fx_frame *f = et_frame(ctx, W, H, img);
    fx_stack *s = rays_stack(ctx, r);
    float *o = s && f ? et_run(ctx, s, f) : NULL;
    fx_stack_free(s);
    fx_frame_free(f);
    return o;
}

static void test_brighter_towards_light(fx_context *ctx)
{
    for (int m = 0; m < 2; m++) {
        rset r = defaults();
        r.method = m ? "polar" : "naive";
        double cx = 0.5 * W, cy = 0.3 * H;
        float *img = spot_image(cx, cy);
        float *o = run_rays(ctx, img, r);
        CHECK(o != NULL);
        if (!o) {
            free(img);
            continue;
        }
        int ok = 1;
        for (int k = 0; k < 8; k++) {
            double a = k * M_PI / 4 + 0.3;
            float prev = FLT_MAX;
            for (int rad = 8; rad <= 36; rad += 4) {
                int x = (int)floor(cx + rad * cos(a)), y = (int)floor(cy + rad * sin(a));
                if (x < 0 || x >= W || y < 0 || y >= H)
                    break;
                float v = lum(o, x, y) - lum(img, x, y);
                if (!(v > 0.0f && v < prev)) {
                    fprintf(stderr, "%s: dir %d r %d: rays %g (prev %g)\n", r.method, k, rad, v, prev);
                    ok = 0;
                }
                prev = v;
            }
        }
        CHECK(ok);
        free(o);
        free(img);
    }
}

/* A bright sky band at the top with a dark column in it: the column's shaft is darker. */
static void test_shafts_follow_occluders(fx_context *ctx)
{
    float *img = calloc((size_t)W * H * 4, sizeof(float));
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            float *q = img + ((size_t)y * W + x) * 4;
            float v = (y < 20 && !(x >= 44 && x < 52)) ? 3.0f : 0.02f;
            q[0] = q[1] = q[2] = v;
            q[3] = 1;
        }
    for (int m = 0; m < 2; m++) {
        rset r = defaults();
        r.method = m ? "polar" : "naive";
        r.lx = 0.5f;
        r.ly = 0.05f; /* light above the column */
        float *o = run_rays(ctx, img, r);
        CHECK(o != NULL);
        if (o) {
            /* below the column (x = 48) vs beside it (x = 30), same row */
            float shadow = lum(o, 48, 45) - lum(img, 48, 45);
            float lit = lum(o, 28, 45) - lum(img, 28, 45);
            CHECK(lit > 2.0f * shadow && lit > 0.0f);
            free(o);
        }
    }
    free(img);
}

static void test_identity(fx_context *ctx)
{
    float *img = spot_image(40, 20);
    const char *methods[2] = {"naive", "polar"};
    for (int m = 0; m < 2; m++) {
        rset r = defaults();
        r.method = methods[m];
        r.weight = 0.0;
        float *o = run_rays(ctx, img, r);
        CHECK(o && memcmp(o, img, (size_t)W * H * 4 * sizeof(float)) == 0);
        free(o);
        r = defaults();
        r.method = methods[m];
        r.exposure = 0.0;
        o = run_rays(ctx, img, r);
        CHECK(o && memcmp(o, img, (size_t)W * H * 4 * sizeof(float)) == 0);
        free(o);
    }
    free(img);
}

/* Camera at the origin looking down -Z, 60 degree vertical field of view. */
static const char *camera_json(const char *sun_direction, char *buf, size_t n)
{
    double f = 1.0 / tan(M_PI / 6), aspect = (double)W / H, zn = 0.1, zf = 100;
    snprintf(buf, n,
             "{\"world_to_camera\": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]],"
             " \"projection\": [[%.17g,0,0,0],[0,%.17g,0,0],[0,0,%.17g,%.17g],[0,0,-1,0]],"
             " \"clip_start\": 0.1, \"clip_end\": 100,"
             " \"lights\": [{\"name\": \"Sun\", \"type\": \"SUN\", \"direction\": %s}]}",
             f / aspect, f, (zf + zn) / (zn - zf), 2 * zf * zn / (zn - zf), sun_direction);
    return buf;
}

static float *run_scene_light(fx_context *ctx, const float *img, const char *sun_dir, const char *method)
{
    char json[1024];
    fx_frame *f = et_frame(ctx, W, H, img);
    fx_stack *s = et_stack(ctx, "god_rays");
    float *o = NULL;
    if (f && s && fx_frame_apply_sidecar(f, camera_json(sun_dir, json, sizeof json)) == FX_OK &&
        fx_stack_set_enum(s, 0, "occlusion", "luminance") == FX_OK &&
        fx_stack_set_enum(s, 0, "method", method) == FX_OK &&
        fx_stack_set_string(s, 0, "light", "Sun") == FX_OK && fx_stack_set_float(s, 0, "exposure", 0.02) == FX_OK)
        o = et_run(ctx, s, f);
    else
        fprintf(stderr, "scene light setup: %s\n", fx_context_error(ctx));
    fx_stack_free(s);
    fx_frame_free(f);
    return o;
}

static void test_scene_light(fx_context *ctx)
{
    float *img = spot_image(0.5 * W, 0.5 * H);
    /* the sun travels +Z: it shines from -Z, straight ahead: symmetric rays about the centre */
    float *o = run_scene_light(ctx, img, "[0, 0, 1]", "naive");
    CHECK(o != NULL);
    if (o) {
        float a = lum(o, W / 2 + 12, H / 2) - lum(img, W / 2 + 12, H / 2);
        float b = lum(o, W / 2 - 13, H / 2) - lum(img, W / 2 - 13, H / 2);
        CHECK(a > 0.0f && fabsf(a - b) < 0.02f * a);
        free(o);
    }
    /* the sun travels -Z: it is behind the camera: identity, bit for bit, both methods */
    for (int m = 0; m < 2; m++) {
        o = run_scene_light(ctx, img, "[0, 0, -1]", m ? "polar" : "naive");
        CHECK(o && memcmp(o, img, (size_t)W * H * 4 * sizeof(float)) == 0);
        free(o);
        /* sideways (90 degrees): also faded out completely */
        o = run_scene_light(ctx, img, "[1, 0, 0]", m ? "polar" : "naive");
        CHECK(o && memcmp(o, img, (size_t)W * H * 4 * sizeof(float)) == 0);
        free(o);
    }
    /* almost sideways: light far off screen, w -> 0+: finite and bounded */
    o = run_scene_light(ctx, img, "[0.99999, 0, 0.0045]", "polar");
    CHECK(o && tu_all_finite(o, (size_t)W * H * 4));
    free(o);
    /* no lights in the frame: a clear error */
    fx_frame *f = et_frame(ctx, W, H, img);
    fx_stack *s = et_stack(ctx, "god_rays");
    fx_stack_set_enum(s, 0, "occlusion", "luminance");
    fx_frame *out = NULL;
    CHECK_FAIL(ctx, fx_stack_run(s, f, &out), FX_ERR_NO_CAMERA, "camera");
    fx_frame_free(out);
    out = NULL;
    /* the sky occlusion without Depth names the pass */
    fx_stack_set_enum(s, 0, "occlusion", "sky");
    fx_stack_set_enum(s, 0, "light_source", "screen");
    CHECK_FAIL(ctx, fx_stack_run(s, f, &out), FX_ERR_MISSING_PASS, "Depth");
    fx_frame_free(out);
    fx_stack_free(s);
    fx_frame_free(f);
    free(img);
}

static void test_extremes(fx_context *ctx)
{
    float *img = spot_image(30, 20);
    /* bound: rays <= scale * max(occ) * mass; max luminance of the source 4 (<= max_source 8) */
    const int samples[] = {1, 2, 7, 100, 2000};
    const double decays[] = {0.0, 0.5, 1.0};
    const double dens[] = {0.0, 0.01, 1.0};
    const float far[][2] = {{0.5f, 0.3f}, {1000.0f, -1000.0f}, {-1000.0f, 0.5f}, {1.2f, 0.5f}};
    int ok = 1;
    for (int m = 0; m < 2; m++)
        for (int si = 0; si < 5; si++)
            for (int di = 0; di < 3; di++)
                for (int ni = 0; ni < 3; ni++)
                    for (int fi = 0; fi < 4; fi++) {
                        if (m == 1 && si != 3)
                            continue; /* polar ignores samples */
                        rset r = defaults();
                        r.method = m ? "polar" : "naive";
                        r.samples = samples[si];
                        r.decay = decays[di];
                        r.density = dens[ni];
                        r.lx = far[fi][0];
                        r.ly = far[fi][1];
                        r.weight = 3.0;
                        float *o = run_rays(ctx, img, r);
                        /* rays <= scale * max(occ): the sample weights are <= 1 / N each */
                        double bound = 100.0 * 3.0 * 0.02 * 4.0 + 4.0 + 1e-3;
                        int good = o && tu_all_finite(o, (size_t)W * H * 4);
                        for (size_t i = 0; good && i < (size_t)W * H * 4; i++)
                            if (o[i] > bound || o[i] < 0.0f)
                                good = 0;
                        if (!good) {
                            fprintf(stderr, "extreme: %s samples %d decay %g density %g light %g,%g\n", r.method,
                                    r.samples, r.decay, r.density, r.lx, r.ly);
                            ok = 0;
                        }
                        free(o);
                    }
    CHECK(ok);
    /* inputs with Inf/NaN/huge values: finite output */
    float *bad = spot_image(30, 20);
    bad[0] = INFINITY;
    bad[5] = NAN;
    bad[4 * 200] = 1e38f;
    bad[4 * 201 + 1] = -1e38f;
    for (int m = 0; m < 2; m++) {
        rset r = defaults();
        r.method = m ? "polar" : "naive";
        float *o = run_rays(ctx, bad, r);
        CHECK(o && tu_all_finite(o, (size_t)W * H * 4));
        free(o);
    }
    free(bad);
    free(img);
}

static double max_rays_diff(const float *a, const float *b, const float *img, double *peak)
{
    double m = 0, pk = 0;
    for (size_t i = 0; i < (size_t)W * H; i++)
        for (int k = 0; k < 3; k++) {
            double ra = a[i * 4 + k] - img[i * 4 + k], rb = b[i * 4 + k] - img[i * 4 + k];
            m = fmax(m, fabs(ra - rb));
            pk = fmax(pk, fabs(rb));
        }
    *peak = pk;
    return m;
}

/* What the reduced path implies: the reference rays box-averaged over f x f cells (the
 * reduced map's cells) and interpolated back bilinearly at the reduced texel centres
 * ((x + 0.5) / f - 0.5, clamped to the edge texels): the resampling alone, no polar error.
 * Returns max |(down - img) - that| over RGB. */
static double reduced_resampling_error(const float *down, const float *ref, const float *img, int f)
{
    int lw = (W + f - 1) / f, lh = (H + f - 1) / f;
    double *lo = calloc((size_t)lw * lh * 3, sizeof(double));
    for (int Y = 0; Y < lh; Y++)
        for (int X = 0; X < lw; X++) {
            int n = 0;
            for (int y = Y * f; y < Y * f + f && y < H; y++)
                for (int x = X * f; x < X * f + f && x < W; x++, n++)
                    for (int ch = 0; ch < 3; ch++) {
                        size_t i = ((size_t)y * W + x) * 4 + ch;
                        lo[((size_t)Y * lw + X) * 3 + ch] += ref[i] - img[i];
                    }
            for (int ch = 0; ch < 3; ch++)
                lo[((size_t)Y * lw + X) * 3 + ch] /= n;
        }
    double e = 0;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            double u = fmin(fmax((x + 0.5) / f - 0.5, 0), lw - 1), v = fmin(fmax((y + 0.5) / f - 0.5, 0), lh - 1);
            int X0 = (int)u, Y0 = (int)v, X1 = X0 + 1 < lw ? X0 + 1 : X0, Y1 = Y0 + 1 < lh ? Y0 + 1 : Y0;
            double tx = u - X0, ty = v - Y0;
            for (int ch = 0; ch < 3; ch++) {
                const double *L = lo;
                double a = L[((size_t)Y0 * lw + X0) * 3 + ch] * (1 - tx) + L[((size_t)Y0 * lw + X1) * 3 + ch] * tx;
                double b = L[((size_t)Y1 * lw + X0) * 3 + ch] * (1 - tx) + L[((size_t)Y1 * lw + X1) * 3 + ch] * tx;
                size_t i = ((size_t)y * W + x) * 4 + ch;
                e = fmax(e, fabs((down[i] - img[i]) - (a * (1 - ty) + b * ty)));
            }
        }
    free(lo);
    return e;
}

static void test_methods_converge(fx_context *ctx)
{
    float *img = calloc((size_t)W * H * 4, sizeof(float));
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            float *q = img + ((size_t)y * W + x) * 4;
            float v = (y < 24 && ((x / 8) % 3 != 0)) ? 2.0f : 0.0f;
            q[0] = v;
            q[1] = 0.8f * v;
            q[2] = 0.5f * v;
            q[3] = 1;
        }
    const float lights[][2] = {{0.45f, 0.12f}, {0.3f, -0.4f}, {1.5f, 0.2f}};
    const double decays[] = {1.0, 0.97, 0.9};
    for (int li = 0; li < 3; li++)
        for (int di = 0; di < 3; di++) {
            rset r = defaults();
            r.lx = lights[li][0];
            r.ly = lights[li][1];
            r.decay = decays[di];
            r.samples = 2000;
            float *ref = run_rays(ctx, img, r);
            r.method = "polar";
            r.polar_res = 8;
            r.levels = 8;
            float *fine = run_rays(ctx, img, r);
            r.polar_res = 1;
            r.levels = 2;
            float *coarse = run_rays(ctx, img, r);
            r.down = 2;
            float *down = run_rays(ctx, img, r);
            r.down = 0;
            CHECK(ref && fine && coarse && down);
            if (ref && fine && coarse) {
                double peak, ef = max_rays_diff(fine, ref, img, &peak), ec = max_rays_diff(coarse, ref, img, &peak);
                fprintf(stderr, "light %g,%g decay %g: polar fine %.4f coarse %.4f of peak %.3f\n", r.lx, r.ly, r.decay,
                        ef, ec, peak);
                CHECK(ef < 0.06 * peak);
                CHECK(ec < 0.25 * peak);
                double ed = max_rays_diff(down, ref, img, &peak);
                fprintf(stderr, "  polar downsample 2: %.4f of peak\n", ed);
                /* The bound the parameters imply. downsample f = 2 runs the coarse polar
                 * (resolution 1, levels 2) on the f x f box means with the light at L / f and
                 * interpolates the rays back bilinearly, so against the reference resampled
                 * the same way (box means, bilinear at (x + 0.5) / f - 0.5: what is left is the
                 * polar's own error) it errs as the coarse polar at full size would with lines
                 * f times farther apart: the line spacing is f / resolution full pixels and the
                 * polar's error (interpolation across lines at the shafts' edges) grows about
                 * linearly with it, so er <= f ec, plus 2 % of the peak for the resampling
                 * not commuting exactly with the blur (its kernel stretches along the lines).
                 * Measured (2026-12-02): er / ec 1.14-1.98 over these 9 cases, er <= 0.25 peak
                 * where ec = 0.19 peak (decay 0.9, peak 0.38). The old check, ed < 0.5 peak
                 * (ed measured 0.07-0.38 peak), failed a quarter-pixel shift of the upsampling in
                 * 1 case of 9 at 0.505 peak; this one fails it in 4, a half-pixel shift in 7 (old:
                 * 2), the reduced light at 1.1 L / f in 6 (old: 1). */
                double er = reduced_resampling_error(down, ref, img, 2);
                fprintf(stderr, "  from the resampled reference %.4f of peak (bound %.4f)\n", er / peak,
                        (2.0 * ec + 0.02 * peak) / peak);
                CHECK(er <= 2.0 * ec + 0.02 * peak);
            }
            free(down);
            free(ref);
            free(fine);
            free(coarse);
        }
    free(img);
}

/* ---- an independent reference: the documented model evaluated naively in double ----
 * docs/effects/god_rays.md: occlusion (luminance) occ = c * smoothstep(threshold,
 * threshold + knee, lum(c)) * min(1, max_source / lum(c)), lum = Rec.709 weights;
 * rays(p) = 100 weight exposure / N * sum_{i<N} decay^(100 i / N) occ~(p - i density (p - L) / N)
 * (the naive method; occ~ the bilinear interpolation of occ at pixel centres x + 0.5,
 * zero outside the image), whose N -> infinity limit is the integral both methods compute;
 * output = src + rays (add) or src + rays (1 - clamp(src, 0, 1)) (screen), alpha kept. */

static double ref_smoothstep(double e0, double e1, double x)
{
    double t = (x - e0) / (e1 - e0);
    t = t < 0 ? 0 : t > 1 ? 1 : t;
    return t * t * (3 - 2 * t);
}

/* occ of the test image (double, 3 channels) for threshold, knee, max_source */
static double *ref_occlusion(const float *img, double thr, double knee, double max_src)
{
    double *occ = calloc((size_t)W * H * 3, sizeof(double));
    for (int i = 0; i < W * H; i++) {
        const float *c = img + (size_t)i * 4;
        double l = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
        double k = ref_smoothstep(thr, thr + knee, l) * (l > max_src ? max_src / l : 1.0);
        for (int ch = 0; ch < 3; ch++)
            occ[(size_t)i * 3 + ch] = c[ch] * k;
    }
    return occ;
}

static void ref_bilinear(const double *occ, double x, double y, double wt, double acc[3])
{
    double fx = x - 0.5, fy = y - 0.5;
    int x0 = (int)floor(fx), y0 = (int)floor(fy);
    for (int j = 0; j < 2; j++)
        for (int i = 0; i < 2; i++) {
            int xi = x0 + i, yi = y0 + j;
            if (xi < 0 || yi < 0 || xi >= W || yi >= H)
                continue;
            double wgt = wt * (i ? fx - x0 : 1 - (fx - x0)) * (j ? fy - y0 : 1 - (fy - y0));
            for (int ch = 0; ch < 3; ch++)
                acc[ch] += wgt * occ[((size_t)yi * W + xi) * 3 + ch];
        }
}

/* the rays (3 channels per pixel) by the documented N-sample sum */
static double *ref_rays(const double *occ, rset r, int n)
{
    double *rays = calloc((size_t)W * H * 3, sizeof(double));
    double lx = r.lx * W, ly = r.ly * H, scale = 100.0 * r.weight * r.exposure;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            double px = x + 0.5, py = y + 0.5, acc[3] = {0, 0, 0};
            for (int i = 0; i < n; i++) {
                double t = (double)i / n;
                ref_bilinear(occ, px - t * r.density * (px - lx), py - t * r.density * (py - ly),
                             pow(r.decay, 100.0 * t), acc);
            }
            for (int ch = 0; ch < 3; ch++)
                rays[((size_t)y * W + x) * 3 + ch] = acc[ch] * scale / n;
        }
    return rays;
}

/* max |out - expected| over RGB and |alpha change|, relative to the peak of the rays */
static double ref_error(const float *o, const float *img, const double *rays, int screen, double *peak)
{
    double e = 0, pk = 0;
    for (int i = 0; i < W * H; i++) {
        for (int ch = 0; ch < 3; ch++) {
            double s = img[(size_t)i * 4 + ch], rv = rays[(size_t)i * 3 + ch];
            double want = s + rv * (screen ? 1.0 - (s < 0 ? 0 : s > 1 ? 1 : s) : 1.0);
            e = fmax(e, fabs(o[(size_t)i * 4 + ch] - want));
            pk = fmax(pk, rv);
        }
        e = fmax(e, fabs(o[(size_t)i * 4 + 3] - img[(size_t)i * 4 + 3]));
    }
    *peak = pk;
    return pk > 0 ? e / pk : INFINITY;
}

/* A coloured sky band with a hole, a sun disc brighter than max_source, pixels inside the
 * knee (lum 0.9) and below the threshold (lum 0.5); threshold 0.8, knee 0.25, max_source 8. */
static float *ref_image(void)
{
    float *img = malloc((size_t)W * H * 4 * sizeof(float));
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            float *q = img + ((size_t)y * W + x) * 4;
            double d = hypot(x + 0.5 - 60, y + 0.5 - 12);
            float r = 0.2f, g = 0.2f, b = 0.2f;
            if (d < 5)
                r = 30.0f, g = 24.0f, b = 12.0f; /* lum ~ 24: scaled down to 8 */
            else if (y < 22 && !(x >= 20 && x < 30))
                r = 1.6f + 0.01f * x, g = 1.3f, b = 0.9f + 0.02f * y;
            else if (y < 30)
                r = g = b = (x % 4 < 2) ? 0.9f : 0.5f; /* in the knee / below the threshold */
            q[0] = r, q[1] = g, q[2] = b;
            q[3] = 0.75f;
        }
    return img;
}

static void test_reference_formula(fx_context *ctx)
{
    float *img = ref_image();
    double *occ = ref_occlusion(img, 0.8, 0.25, 8.0);
    const float lights[][2] = {{0.45f, 0.2f}, {0.3f, -0.4f}, {1.4f, 0.6f}};
    for (int li = 0; li < 3; li++) {
        rset r = defaults();
        r.lx = lights[li][0];
        r.ly = lights[li][1];
        r.decay = 0.96;
        r.density = 0.8;
        r.weight = 1.3;
        /* naive at N = 100 and N = 37 against the documented sum at the same N: the same
         * arithmetic up to float rounding of the output (1e-6 of values <= ~10) */
        const int ns[2] = {100, 37};
        for (int k = 0; k < 2; k++) {
            r.samples = ns[k];
            double *rays = ref_rays(occ, r, ns[k]);
            float *o = run_rays(ctx, img, r);
            double peak = 0, e = o ? ref_error(o, img, rays, 0, &peak) : INFINITY;
            fprintf(stderr, "reference: light %g,%g naive %d: max error %.2e of peak %.3f\n", r.lx, r.ly, ns[k], e,
                    peak);
            CHECK(peak > 0.5 && e < 1e-5);
            free(o);
            free(rays);
        }
        /* the limit (N = 4000: the sum's own error O(decay mass / N) < 1e-3 of the peak)
         * against polar at 8 lines per pixel / 8 levels (documented: 0.05-0.06 % of the peak
         * from naive 2000) and the screen composite */
        double *lim = ref_rays(occ, r, 4000);
        r.method = "polar";
        r.polar_res = 8;
        r.levels = 8;
        float *o = run_rays(ctx, img, r);
        double peak = 0, e = o ? ref_error(o, img, lim, 0, &peak) : INFINITY;
        fprintf(stderr, "reference: light %g,%g polar 8/8: max error %.2e of peak\n", r.lx, r.ly, e);
        CHECK(e < 2.5e-3);
        free(o);
        r.method = "naive";
        r.samples = 2000;
        fx_frame *f = et_frame(ctx, W, H, img);
        fx_stack *s = rays_stack(ctx, r);
        o = s && f && fx_stack_set_enum(s, 0, "composite", "screen") == FX_OK ? et_run(ctx, s, f) : NULL;
        e = o ? ref_error(o, img, lim, 1, &peak) : INFINITY;
        fprintf(stderr, "reference: light %g,%g naive 2000 screen: max error %.2e of peak\n", r.lx, r.ly, e);
        CHECK(e < 2.5e-3);
        free(o);
        fx_stack_free(s);
        fx_frame_free(f);
        free(lim);
    }
    free(occ);
    free(img);
}

/* The light given on the display window of a frame whose data window starts elsewhere
 * (a cropped or border render): light_position is a fraction of the display window, so in
 * the data window's pixels the light sits at position * display size - data origin. The
 * documented sum (ref_rays, in the data window's pixels) with the light there: (0.5, 0.25)
 * of a 126 x 84 display window is (63, 21), the data window starts at (30, 20), so the light
 * is at (33, 1) of the data (exact in float, so the same 1e-5 as test_reference_formula). */
static void test_cropped_data_window(fx_context *ctx)
{
    float *img = ref_image();
    double *occ = ref_occlusion(img, 0.8, 0.25, 8.0);
    rset r = defaults();
    r.decay = 0.96;
    r.density = 0.8;
    r.weight = 1.3;
    r.lx = 0.5f; /* of the display window */
    r.ly = 0.25f;
    fx_frame *f = et_frame(ctx, W, H, img);
    const int data[4] = {30, 20, 30 + W - 1, 20 + H - 1}, disp[4] = {0, 0, 30 + W - 1, 20 + H - 1};
    CHECK_OK(ctx, fx_frame_set_windows(f, data, disp));
    fx_stack *s = rays_stack(ctx, r);
    float *o = s && f ? et_run(ctx, s, f) : NULL;
    rset in_data = r;
    in_data.lx = 33.0f / W; /* ref_rays places the light at lx W, ly H of the data window */
    in_data.ly = 1.0f / H;
    double *rays = ref_rays(occ, in_data, r.samples);
    double peak = 0, e = o ? ref_error(o, img, rays, 0, &peak) : INFINITY;
    fprintf(stderr, "cropped data window: max error %.2e of peak %.3f\n", e, peak);
    CHECK(peak > 0.5 && e < 1e-5);
    free(rays);
    free(o);
    fx_stack_free(s);
    fx_frame_free(f);
    free(occ);
    free(img);
}

/* A light behind the camera is the identity bit for bit, negative zeros too (an added +0
 * would turn -0.0 into +0.0: the effect must not run at all). */
static void test_behind_keeps_signed_zeros(fx_context *ctx)
{
    float *img = spot_image(0.5 * W, 0.5 * H);
    for (int i = 0; i < W * H; i += 7)
        for (int c = 0; c < 4; c++)
            img[4 * i + c] = -0.0f;
    for (int m = 0; m < 2; m++) {
        float *o = run_scene_light(ctx, img, "[0, 0, -1]", m ? "polar" : "naive");
        CHECK(o && memcmp(o, img, (size_t)W * H * 4 * sizeof(float)) == 0);
        free(o);
    }
    free(img);
}

static void test_threads(void)
{
    float *img = spot_image(50, 10);
    for (int m = 0; m < 3; m++) {
        float *outs[2] = {NULL, NULL};
        for (int t = 0; t < 2; t++) {
            fx_context *c = NULL;
            fx_context_new(&c, t + 1);
            rset r = defaults();
            r.method = m ? "polar" : "naive";
            r.down = m == 2 ? 2 : 0;
            r.jitter = 1;
            outs[t] = run_rays(c, img, r);
            fx_context_free(c);
        }
        CHECK(outs[0] && outs[1] && memcmp(outs[0], outs[1], (size_t)W * H * 4 * sizeof(float)) == 0);
        free(outs[0]);
        free(outs[1]);
    }
    free(img);
}

/* The reduced path (no full-size buffers: the map built reduced, the rays interpolated in
 * the composite) and the full-size one (the occlusion map and the rays both in the output)
 * give the bits of the buffered path the debug outputs take (light inside the frame and off
 * screen); naive too (its map must not be the output: it reads the map while it writes). */
static void test_fused_equals_buffered(fx_context *ctx)
{
    float *img = spot_image(40, 12);
    int bad = 0;
    for (int k = 0; k < 8; k++) {
        rset r = defaults();
        r.method = k < 6 ? "polar" : "naive";
        r.down = k % 3 == 0 ? 1 : k % 3 == 1 ? 2 : 4;
        r.lx = k < 3 ? 0.5f : 1.7f; /* inside, and off screen */
        float *o[2] = {NULL, NULL};
        for (int dbg = 0; dbg < 2; dbg++) {
            fx_frame *f = et_frame(ctx, W, H, img);
            fx_stack *s = rays_stack(ctx, r);
            if (s)
                fx_stack_set_debug_outputs(s, dbg);
            o[dbg] = s && f ? et_run(ctx, s, f) : NULL;
            fx_stack_free(s);
            fx_frame_free(f);
        }
        bad += !o[0] || !o[1] || memcmp(o[0], o[1], (size_t)W * H * 4 * sizeof(float)) != 0;
        free(o[0]);
        free(o[1]);
    }
    CHECK(bad == 0);
    free(img);
}

/* occlusion sky: with every pixel beyond sky_distance it is luminance's picture bit for bit
 * (at full size and reduced); with none (and NaN depth) the identity: the pixels that are
 * not sky are skipped before their colour is looked at, which must change nothing. */
static void test_sky_skip(fx_context *ctx)
{
    float *img = spot_image(40, 12);
    float *far = malloc((size_t)W * H * sizeof(float)), *near = malloc((size_t)W * H * sizeof(float));
    for (int i = 0; i < W * H; i++) {
        far[i] = 1e10f;
        near[i] = i % 7 == 3 ? NAN : 5.0f;
    }
    for (int k = 0; k < 3; k++) {
        rset r = defaults();
        r.method = "polar";
        r.down = k == 0 ? 1 : k == 1 ? 2 : 4;
        float *lum_out = run_rays(ctx, img, r);
        float *o[2] = {NULL, NULL};
        for (int d = 0; d < 2; d++) {
            fx_frame *f = et_frame(ctx, W, H, img);
            fx_frame_add_pass(f, "Depth", 1, d ? near : far);
            fx_stack *s = rays_stack(ctx, r);
            if (s && fx_stack_set_enum(s, 0, "occlusion", "sky") == FX_OK)
                o[d] = et_run(ctx, s, f);
            fx_stack_free(s);
            fx_frame_free(f);
        }
        CHECK(lum_out && o[0] && memcmp(lum_out, o[0], (size_t)W * H * 4 * sizeof(float)) == 0);
        CHECK(o[1] && memcmp(img, o[1], (size_t)W * H * 4 * sizeof(float)) == 0);
        free(lum_out);
        free(o[0]);
        free(o[1]);
    }
    free(far);
    free(near);
    free(img);
}

int main(void)
{
    fx_context *ctx = NULL;
    if (fx_context_new(&ctx, 2) != FX_OK)
        return 1;
    test_brighter_towards_light(ctx);
    test_shafts_follow_occluders(ctx);
    test_identity(ctx);
    test_scene_light(ctx);
    test_extremes(ctx);
    test_methods_converge(ctx);
    test_reference_formula(ctx);
    test_cropped_data_window(ctx);
    test_behind_keeps_signed_zeros(ctx);
    test_threads();
    test_fused_equals_buffered(ctx);
    test_sky_skip(ctx);
    fx_context_free(ctx);
    return tu_finish("test_god_rays");
}
