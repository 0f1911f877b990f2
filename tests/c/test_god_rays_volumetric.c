/* god_rays method volumetric (math/volume_march.h) against a scene whose in-scattered light
 * has a closed form: a camera looking straight down at a floor 10 m below (90 degrees wide),
 * a sun travelling (1, 0, -1)/sqrt(2) and a shelf at z = 5 over x in [-12, -6] whose
 * shadow cuts the air near the floor on the left of the frame (the dark band). The light
 * view is written here from the geometry (ray casts), and the expected radiance is
 * integrated here in closed form from the same geometry (not from the light view, not
 * with the library's code):
 *
 *     L = sigma p(cos) S  integral over the lit s of exp(-E(s)) ds,
 *     E(s) = sigma s (view) + sigma (ld(s) - entry) (light, extinction full)
 *
 * Also: the dark band is darker than the lit air; 1 and 2 threads give the same bits (with
 * interleaving and the reduced grid); density 0 is the identity; outputs stay finite at
 * density 1e6 and anisotropy +-0.999 / +-1; clear errors without the light view, with a
 * point light, with a screen-space light and for NaN parameters; the march (four samples a
 * turn) against its sum written out in double at any step count; a reduced map built again
 * in the last one's buffer. */
#include "fx_effect_test.h"
#include "io/exr_rows.h"
#include "math/hash.h"
#include "math/shadow_map.h"
#include "math/volume_march.h"
#include "scene/aux_map.h"

#include <float.h>
#include <math.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

#define W 64
#define H 16
#define LN 256          /* light view texels per side */
#define LHALF 12.0      /* light view half-extent (m) */
#define LDIST 20.0      /* light view origin: 20 m back from the world origin along the light */
#define SHELF_Z 5.0
#define SHELF_X0 (-12.0)
#define SHELF_X1 (-6.0606601717798213) /* its edge on a texel boundary of the light view */
#define CAM_Z 10.0
#define SIGMA 0.05
#define G 0.4
#define SUN_E 2.0

static const double A = 0.70710678118654752440; /* 1/sqrt(2) */

/* The light view: planar depth of the first surface (shelf or floor) along the light. */
static double light_depth(int i, int j)
{
    double cx = LHALF * (((i + 0.5) / LN) * 2.0 - 1.0);
    double cy = LHALF * (1.0 - ((j + 0.5) / LN) * 2.0);
    /* the view's axes: X = (a, 0, a), Y = (0, 1, 0), origin C = -LDIST d, d = (a, 0, -a) */
    double px = -LDIST * A + cx * A, py = cy, pz = LDIST * A + cx * A;
    (void)py;
    double best = 1e10;
    double ts = (pz - SHELF_Z) / A; /* shelf plane */
    double xs = px + ts * A;
    if (ts > 0 && xs >= SHELF_X0 && xs <= SHELF_X1)
        best = ts;
    double tf = pz / A; /* floor */
    if (tf > 0 && tf < best)
        best = tf;
    return best;
}

static const char *write_light_view(fx_context *ctx, double *entry)
{
    static char path[512];
    snprintf(path, sizeof path, "%s/light.exr", tu_tmpdir("god_rays_volumetric"));
    float *d = malloc((size_t)LN * LN * sizeof(float));
    double m = 1e30;
    for (int j = 0; j < LN; j++)
        for (int i = 0; i < LN; i++) {
            double v = light_depth(i, j);
            d[(size_t)j * LN + i] = (float)v;
            m = v < m ? v : m;
        }
    *entry = m;
    fx_frame *f = NULL;
    fx_frame_new(ctx, LN, LN, &f);
    fx_frame_add_pass(f, "Depth", 1, d);
    CHECK_OK(ctx, fx_frame_write_exr(f, path, NULL));
    fx_frame_free(f);
    free(d);
    return path;
}

static int box_x0 = W; /* columns x >= box_x0 see a box top 3 m below the camera (not in the light view) */
#define BOX_DEPTH 3.0

static int ramp; /* the rays end on a plane at a slant (not in the light view): depth 4 / (1 + 1.1 kx) */
static double ray_end(int x)
{
    if (ramp)
        return 4.0 / (1.0 + 1.1 * 0.5 * (((x + 0.5) / W) * 2.0 - 1.0)); /* kx of ray_of */
    return x >= box_x0 ? BOX_DEPTH : CAM_Z;
}
static int poison; /* scene_frame puts NaN, +-Inf and 1e38 into some source pixels */

/* The scene sidecar: the camera, the sun (or another light type) and the light view. */
static fx_frame *scene_frame(fx_context *ctx, const char *light_path, const char *type, float src)
{
    float *rgba = malloc((size_t)W * H * 4 * sizeof(float)), *d = malloc((size_t)W * H * sizeof(float));
    for (int i = 0; i < W * H; i++) {
        rgba[4 * i] = rgba[4 * i + 1] = rgba[4 * i + 2] = src;
        rgba[4 * i + 3] = 1.0f;
        d[i] = (float)ray_end(i % W);
    }
    static const float bad[] = {NAN, INFINITY, -INFINITY, 1e38f, -1e38f};
    for (int i = 0; poison && i < W * H; i += 37)
        rgba[4 * i + i % 4] = bad[(i / 37) % 5];
    fx_frame *f = et_frame(ctx, W, H, rgba);
    fx_frame_add_pass(f, "Depth", 1, d);
    free(rgba);
    free(d);
    double n = 0.1, fa = 100.0, ln = 0.1, lf = 40.0;
    char json[4096];
    int k = snprintf(json, sizeof json,
                     "{\"world_to_camera\": [[1,0,0,0],[0,1,0,0],[0,0,1,%.17g],[0,0,0,1]],"
                     " \"projection\": [[2,0,0,0],[0,%.17g,0,0],[0,0,%.17g,%.17g],[0,0,-1,0]],"
                     " \"clip_start\": %g, \"clip_end\": %g,"
                     " \"lights\": [{\"name\": \"Sun\", \"type\": \"%s\", \"position\": [-14, 0, 14],"
                     " \"direction\": [%.17g, 0, %.17g], \"color\": [1, 1, 1], \"energy\": %g}]",
                     -CAM_Z, 2.0 * W / H, (fa + n) / (n - fa), 2 * fa * n / (n - fa), n, fa, type, A, -A, SUN_E);
    if (light_path)
        k += snprintf(json + k, sizeof json - (size_t)k,
                      ", \"aux_views\": [{\"name\": \"light:Sun\", \"path\": \"%s\","
                      " \"world_to_camera\": [[%.17g,0,%.17g,0],[0,1,0,0],[%.17g,0,%.17g,%.17g],[0,0,0,1]],"
                      " \"projection\": [[%.17g,0,0,0],[0,%.17g,0,0],[0,0,%.17g,%.17g],[0,0,0,1]],"
                      " \"clip_start\": %g, \"clip_end\": %g, \"orthographic\": true}]",
                      light_path, A, A, -A, A, -LDIST, 1.0 / LHALF, 1.0 / LHALF, -2.0 / (lf - ln),
                      -(lf + ln) / (lf - ln), ln, lf);
    snprintf(json + k, sizeof json - (size_t)k, "}");
    CHECK_OK(ctx, fx_frame_apply_sidecar(f, json));
    return f;
}

/* The view ray of pixel (x, H / 2): the point at planar depth s is (s kx, s ky, 10 - s). */
static void ray_of(int x, double *kx, double *ky)
{
    *kx = 0.5 * (((x + 0.5) / W) * 2.0 - 1.0);
    *ky = 0.5 * H / W * (1.0 - ((H / 2 + 0.5) / H) * 2.0);
}

static int no_shelf; /* expected_L as if the shelf were not there */


/* Closed form for pixel (x, H / 2) (ext: 0 none, 1 view, 2 full). */
static double expected_L(int x, int ext, double entry)
{
    double kx, ky;
    ray_of(x, &kx, &ky);
    double len = sqrt(1.0 + kx * kx + ky * ky);
    /* the point at s is in the shelf's shadow when its way to the sun, (-1, 0, 1), meets
     * z = 5 over the shelf: x - (5 - z) = 5 + s (kx - 1) in [X0, X1], below it (s > 5) */
    double sa = (SHELF_X1 - SHELF_Z) / (kx - 1.0), sb = (SHELF_X0 - SHELF_Z) / (kx - 1.0); /* kx < 1 */
    sa = fmax(sa, CAM_Z - SHELF_Z);
    const double end = ray_end(x);
    sa = fmin(sa, end);
    sb = fmin(sb, end);
    double segs[2][2];
    int ns = 0;
    if (sb > sa && !no_shelf) {
        segs[ns][0] = 0.0, segs[ns++][1] = sa;
        if (sb < end)
            segs[ns][0] = sb, segs[ns++][1] = end;
    } else {
        segs[ns][0] = 0.0, segs[ns++][1] = end;
    }
    /* E(s) = alpha + beta s: view sigma len s; light sigma (ld(s) - entry), with
     * ld = LDIST + (x - z) a = LDIST + (s kx - 10 + s) a */
    double alpha = 0.0, beta = 0.0;
    if (ext >= 1)
        beta += SIGMA * len;
    if (ext == 2) {
        alpha += SIGMA * (LDIST - CAM_Z * A - entry);
        beta += SIGMA * (kx + 1.0) * A;
    }
    double integral = 0.0;
    for (int k = 0; k < ns; k++) {
        double a = segs[k][0], b = segs[k][1];
        integral += beta > 0 ? exp(-alpha) * (exp(-beta * a) - exp(-beta * b)) / beta : b - a;
    }
    /* cos between the light's travel (a, 0, -a) and the way to the camera (-kx, -ky, 1) / len */
    double g = G, c = (-A * kx - A) / len;
    double phase = (1 - g * g) / (4 * M_PI * pow(1 + g * g - 2 * g * c, 1.5));
    return SIGMA * phase * SUN_E * len * integral;
}

/* What is left of the floor's colour: exp(-sigma len 10) exp(-sigma (ld(floor) - entry)). */
static double expected_T(int x, double entry)
{
    double kx, ky;
    ray_of(x, &kx, &ky);
    double len = sqrt(1.0 + kx * kx + ky * ky);
    return exp(-SIGMA * len * CAM_Z) * exp(-SIGMA * (LDIST + CAM_Z * kx * A - entry));
}

static int quality_of(const char *q)
{
    static const char *const names[] = {"draft", "preview", "final", "reference"};
    for (int i = 0; i < 4; i++)
        if (strcmp(q, names[i]) == 0)
            return i;
    return -1;
}

static fx_stack *vol_stack(fx_context *ctx, const char *quality, const char *extinction)
{
    fx_stack *s = et_stack(ctx, "god_rays");
    CHECK_OK(ctx, fx_stack_set_enum(s, 0, "method", "volumetric"));
    CHECK_OK(ctx, fx_stack_set_float(s, 0, "volume_density", (float)SIGMA));
    CHECK_OK(ctx, fx_stack_set_float(s, 0, "anisotropy", (float)G));
    CHECK_OK(ctx, fx_stack_set_float(s, 0, "volume_bias", 0.0f));
    const float white[3] = {1.0f, 1.0f, 1.0f}; /* the closed form's sigma is the density */
    CHECK_OK(ctx, fx_stack_set_floats(s, 0, "volume_color", white, 3));
    CHECK_OK(ctx, fx_stack_set_enum(s, 0, "extinction", extinction));
    if (quality)
        CHECK_OK(ctx, fx_stack_set_quality(s, quality_of(quality)));
    return s;
}

/* The march at the reference preset (full resolution, 256 steps, midpoints) against the
 * closed form, with each extinction; the dark band of the shelf's shadow. */
static void test_closed_form(fx_context *ctx)
{
    double entry = 0;
    const char *path = write_light_view(ctx, &entry);
    static const char *const ext[] = {"none", "view", "full"};
    for (int e = 0; e < 3; e++) {
        fx_frame *f = scene_frame(ctx, path, "SUN", 0.0f);
        fx_stack *s = vol_stack(ctx, "reference", ext[e]);
        float *o = et_run(ctx, s, f);
        CHECK(o != NULL);
        double worst = 0.0;
        for (int x = 0; o && x < W; x++) {
            double want = expected_L(x, e, entry), got = o[4 * ((H / 2) * W + x)];
            double rel = fabs(got - want) / want;
            if (getenv("VOL_DEBUG"))
                fprintf(stderr, "%d %s x %d: got %.6f want %.6f rel %.4f\n", e, ext[e], x, got, want, rel);
            worst = rel > worst ? rel : worst;
        }
        CHECK(worst < 0.01);
        if (!(worst < 0.01))
            fprintf(stderr, "volumetric extinction %s: worst relative error %.4f\n", ext[e], worst);
        /* the dark band: the shaded air on the left adds less than the same air unshaded */
        if (o) {
            no_shelf = 1;
            double lit = expected_L(2, e, entry);
            no_shelf = 0;
            CHECK(o[4 * ((H / 2) * W + 2)] < 0.85 * lit);
            if (getenv("VOL_DEBUG"))
                fprintf(stderr, "band %s: %.5f of %.5f unshaded\n", ext[e], o[4 * ((H / 2) * W + 2)], lit);
        }
        free(o);
        fx_stack_free(s);
        fx_frame_free(f);
    }
    /* volume_color as Cycles' Volume Scatter Color: each channel scatters density x colour
     * (without extinction exactly the closed form times the colour); the default 0.8 grey is
     * the density x 0.8 */
    {
        fx_frame *f = scene_frame(ctx, path, "SUN", 0.0f);
        fx_stack *s = vol_stack(ctx, "reference", "none");
        const float col[3] = {1.0f, 0.5f, 0.25f};
        CHECK_OK(ctx, fx_stack_set_floats(s, 0, "volume_color", col, 3));
        float *o = et_run(ctx, s, f);
        double worst = 0.0;
        for (int x = 0; o && x < W; x++)
            for (int c = 0; c < 3; c++) {
                double want = col[c] * expected_L(x, 0, entry), got = o[4 * ((H / 2) * W + x) + c];
                double rel = fabs(got - want) / want;
                worst = rel > worst ? rel : worst;
            }
        CHECK(o && worst < 0.01);
        free(o);
        fx_stack_free(s);
        fx_stack *g = vol_stack(ctx, "reference", "full"), *h = vol_stack(ctx, "reference", "full");
        const float grey[3] = {0.8f, 0.8f, 0.8f};
        CHECK_OK(ctx, fx_stack_set_floats(g, 0, "volume_color", grey, 3));
        CHECK_OK(ctx, fx_stack_set_float(h, 0, "volume_density", (float)(SIGMA * 0.8)));
        float *a = et_run(ctx, g, f), *b = et_run(ctx, h, f);
        CHECK(a && b && tu_max_abs_diff(a, b, (size_t)W * H * 4) < 1e-6);
        free(a);
        free(b);
        fx_stack_free(g);
        fx_stack_free(h);
        fx_frame_free(f);
    }
    /* what lies behind the medium: src T_view T_light(surface) + L */
    fx_frame *f = scene_frame(ctx, path, "SUN", 1.0f);
    fx_stack *s = vol_stack(ctx, "reference", "full");
    float *o = et_run(ctx, s, f);
    double worst = 0.0;
    for (int x = 0; o && x < W; x++) {
        double want = expected_T(x, entry) + expected_L(x, 2, entry);
        double rel = fabs(o[4 * ((H / 2) * W + x)] - want) / want;
        worst = rel > worst ? rel : worst;
    }
    CHECK(o && worst < 0.01);
    if (!(worst < 0.01))
        fprintf(stderr, "volumetric with src 1: worst relative error %.4f\n", worst);
    free(o);
    fx_stack_free(s);
    fx_frame_free(f);
}

/* Interleaved sampling and the reduced grid: the same bits for 1 and 2 threads, and close
 * to the closed form (the air is smooth here). */
static void test_threads_presets(fx_context *ctx)
{
    double entry = 0;
    const char *path = write_light_view(ctx, &entry);
    static const char *const q[] = {"draft", "preview", "final"};
    for (int k = 0; k < 3; k++) {
        fx_context *c1 = NULL;
        fx_context_new(&c1, 1);
        fx_frame *f1 = scene_frame(c1, path, "SUN", 0.25f), *f2 = scene_frame(ctx, path, "SUN", 0.25f);
        fx_stack *s1 = vol_stack(c1, q[k], "full"), *s2 = vol_stack(ctx, q[k], "full");
        float *a = et_run(c1, s1, f1), *b = et_run(ctx, s2, f2);
        CHECK(a && b && memcmp(a, b, (size_t)W * H * 4 * sizeof(float)) == 0);
        double sum = 0.0, want = 0.0;
        for (int x = 0; b && x < W; x++) {
            sum += b[4 * ((H / 2) * W + x)];
            want += expected_L(x, 2, entry);
        }
        /* the mean over the row, src 0.25 T included */
        double t_sum = 0.0;
        for (int x = 0; x < W; x++)
            t_sum += 0.25 * expected_T(x, entry);
        double rel = fabs(sum - want - t_sum) / (want + t_sum);
        CHECK(rel < 0.01);
        if (getenv("VOL_DEBUG") || !(rel < 0.01))
            fprintf(stderr, "volumetric %s: row mean relative error %.4f\n", q[k], rel);
        free(a);
        free(b);
        fx_stack_free(s1);
        fx_stack_free(s2);
        fx_frame_free(f1);
        fx_frame_free(f2);
        fx_context_free(c1);
    }
}

/* The reduced presets at a depth edge: a box top 3 m below the camera over the right half
 * (the light view does not hold it: only the rays' ends change). The gather and the
 * upsample take the air's light from rays of like depth, so the columns beside the edge
 * match the closed form of their own depth (a plain bilinear/box would mix in the 10 m
 * rays' light, 2-3x brighter). */
static void test_depth_edge(fx_context *ctx)
{
    double entry = 0;
    const char *path = write_light_view(ctx, &entry);
    box_x0 = W / 2 + 3; /* not on a lo texel boundary */
    static const char *const q[] = {"preview", "final"};
    for (int k = 0; k < 2; k++) {
        fx_frame *f = scene_frame(ctx, path, "SUN", 0.0f);
        fx_stack *s = vol_stack(ctx, q[k], "full");
        float *o = et_run(ctx, s, f);
        double worst = 0.0;
        for (int x = box_x0 - 4; o && x < box_x0 + 4; x++)
            for (int y = 0; y < H; y++) {
                double want = expected_L(x, 2, entry), got = o[4 * (y * W + x)];
                double rel = fabs(got - want) / want;
                worst = rel > worst ? rel : worst;
            }
        CHECK(o && worst < 0.1);
        if (getenv("VOL_DEBUG") || !(worst < 0.1))
            fprintf(stderr, "volumetric %s at a depth edge: worst relative error %.4f\n", q[k], worst);
        free(o);
        fx_stack_free(s);
        fx_frame_free(f);
    }
    /* volume_upsample edges (draft's): the plain bilinear only where a cell and its pixels
     * are alike in depth, so each side of the edge keeps its own depth's light; on the
     * floor, where every depth is alike, it is the likeness upsample's value (both are the
     * bilinear there) */
    fx_frame *f = scene_frame(ctx, path, "SUN", 0.0f);
    fx_stack *se = vol_stack(ctx, "final", "full"), *sd = vol_stack(ctx, "final", "full");
    for (int k = 0; k < 2; k++) {
        fx_stack *s = k ? sd : se;
        CHECK_OK(ctx, fx_stack_set_int(s, 0, "volume_downsample", 8));
        CHECK_OK(ctx, fx_stack_set_int(s, 0, "interleave", 1));
        CHECK_OK(ctx, fx_stack_set_enum(s, 0, "volume_upsample", k ? "depth" : "edges"));
    }
    float *oe = et_run(ctx, se, f), *od = et_run(ctx, sd, f);
    double worst = 0.0, floor_diff = 0.0;
    for (int y = 0; oe && od && y < H; y++) {
        for (int x = box_x0 - 4; x < box_x0 + 4; x++) {
            double want = expected_L(x, 2, entry), rel = fabs(oe[4 * (y * W + x)] - want) / want;
            worst = rel > worst ? rel : worst;
        }
        for (int x = 0; x < box_x0 - 16; x++) {
            double a = oe[4 * (y * W + x)], b = od[4 * (y * W + x)], d = fabs(a - b) / b;
            floor_diff = d > floor_diff ? d : floor_diff;
        }
    }
    CHECK(oe && od && worst < 0.1 && floor_diff < 1e-5);
    if (getenv("VOL_DEBUG") || !(worst < 0.1 && floor_diff < 1e-5))
        fprintf(stderr, "volume_upsample edges at a depth edge: worst relative error %.4f; on the floor %.2e "
                        "from the likeness upsample\n", worst, floor_diff);
    free(oe);
    free(od);
    fx_stack_free(se);
    fx_stack_free(sd);
    fx_frame_free(f);
    box_x0 = W;
}

/* volume_upsample edges on a plane at a slant: its depth changes by 6-11 % across a cell
 * of 8 pixels, yet the pixels lie on the plane through the cell's texels, so edges takes the
 * plain bilinear there. Against the same march at full resolution (the upsample's own
 * error) it errs less than the likeness upsample (depth), whose weights lean to the texels
 * nearest in depth (the first version's test of the cell's depth range took those weights
 * here too); both stay near the closed form. */
static void test_slanted_plane(fx_context *ctx)
{
    double entry = 0;
    const char *path = write_light_view(ctx, &entry);
    ramp = 1;
    fx_frame *f = scene_frame(ctx, path, "SUN", 0.0f);
    float *o[3] = {NULL, NULL, NULL}; /* edges, depth, full resolution */
    for (int k = 0; k < 3; k++) {
        fx_stack *s = vol_stack(ctx, "final", "full");
        CHECK_OK(ctx, fx_stack_set_int(s, 0, "volume_downsample", k < 2 ? 8 : 1));
        CHECK_OK(ctx, fx_stack_set_int(s, 0, "interleave", 1));
        CHECK_OK(ctx, fx_stack_set_enum(s, 0, "volume_upsample", k == 1 ? "depth" : "edges"));
        o[k] = et_run(ctx, s, f);
        fx_stack_free(s);
    }
    double up[2] = {0, 0}, closed[2] = {0, 0};
    int n = 0;
    for (int y = 0; o[0] && o[1] && o[2] && y < H; y++)
        for (int x = 0; x < W; x++, n++)
            for (int k = 0; k < 2; k++) {
                const double full = o[2][4 * (y * W + x)], got = o[k][4 * (y * W + x)];
                up[k] += fabs(got - full) / full;
                if (y == H / 2 && x >= 4 && x < W - 4) { /* the borders clamp the reduced grid */
                    const double want = expected_L(x, 2, entry);
                    closed[k] = fmax(closed[k], fabs(got - want) / want);
                }
            }
    up[0] /= n > 0 ? n : 1;
    up[1] /= n > 0 ? n : 1;
    const int ok = n > 0 && up[0] < 0.5 * up[1] && closed[0] < 0.03;
    CHECK(ok);
    if (getenv("VOL_DEBUG") || !ok)
        fprintf(stderr, "slanted plane: upsample's mean relative error edges %.2e, depth %.2e; closed form: "
                        "worst %.4f, %.4f\n", up[0], up[1], closed[0], closed[1]);
    for (int k = 0; k < 3; k++)
        free(o[k]);
    fx_frame_free(f);
    ramp = 0;
}

static void test_extremes_errors(fx_context *ctx)
{
    double entry = 0;
    const char *path = write_light_view(ctx, &entry);
    fx_frame *f = scene_frame(ctx, path, "SUN", 0.5f);
    const float dens[] = {1e6f, 1e6f, 1e-6f, 0.05f, 0.05f, 0.05f, 0.05f};
    const float aniso[] = {0.999f, -0.999f, 0.0f, 0.999f, -0.999f, 1.0f, -1.0f};
    static const char *const ext[] = {"full", "none", "view"};
    for (int k = 0; k < 7; k++)
        for (int e = 0; e < 3; e++) {
            fx_stack *s = vol_stack(ctx, e == 1 ? "draft" : "reference", ext[e]);
            CHECK_OK(ctx, fx_stack_set_float(s, 0, "volume_density", dens[k]));
            CHECK_OK(ctx, fx_stack_set_float(s, 0, "anisotropy", aniso[k]));
            fx_context_clear_warnings(ctx);
            float *o = et_run(ctx, s, f);
            /* finite by itself: the stack replaced nothing (it would warn) and nothing is huge */
            CHECK(o && tu_all_finite(o, (size_t)W * H * 4) && fx_context_warning_count(ctx) == 0);
            for (size_t i = 0; o && i < (size_t)W * H * 4; i++)
                if (!(fabsf(o[i]) < 1e30f)) {
                    CHECK(!"an output value beyond 1e30");
                    break;
                }
            free(o);
            fx_stack_free(s);
        }
    /* density 1e6, extinction view: the air right at the camera is lit and opaque, so the
     * in-scatter is the limit p S (sigma / sigma), the floor hidden */
    for (int k = 0; k < 2; k++) {
        fx_stack *s = vol_stack(ctx, "reference", "view");
        CHECK_OK(ctx, fx_stack_set_float(s, 0, "volume_density", 1e6f));
        CHECK_OK(ctx, fx_stack_set_float(s, 0, "anisotropy", k ? -0.999f : 0.999f));
        float *o = et_run(ctx, s, f);
        double kx, ky;
        ray_of(W / 2, &kx, &ky);
        double g = k ? -0.999 : 0.999, c = (-A * kx - A) / sqrt(1.0 + kx * kx + ky * ky);
        double want = SUN_E * (1 - g * g) / (4 * M_PI * pow(1 + g * g - 2 * g * c, 1.5));
        CHECK(o && fabs(o[4 * ((H / 2) * W + W / 2)] - want) < 0.02 * want);
        free(o);
        fx_stack_free(s);
    }
    /* density 0: the identity, bit for bit */
    fx_stack *s = vol_stack(ctx, "final", "full");
    CHECK_OK(ctx, fx_stack_set_float(s, 0, "volume_density", 0.0f));
    float *o = et_run(ctx, s, f);
    CHECK(o && memcmp(o, et_combined(f), (size_t)W * H * 4 * sizeof(float)) == 0);
    free(o);
    /* NaN parameters are refused, naming the parameter */
    CHECK_FAIL(ctx, fx_stack_set_float(s, 0, "volume_density", NAN), FX_ERR_BAD_PARAM, "volume_density");
    CHECK_FAIL(ctx, fx_stack_set_float(s, 0, "anisotropy", NAN), FX_ERR_BAD_PARAM, "anisotropy");
    /* a screen-space light cannot be marched */
    CHECK_OK(ctx, fx_stack_set_float(s, 0, "volume_density", 0.05f));
    fx_result r = fx_stack_set_enum(s, 0, "light_source", "screen");
    fx_frame *out = NULL;
    if (r == FX_OK)
        CHECK_FAIL(ctx, fx_stack_run(s, f, &out), FX_ERR_BAD_PARAM, "light_source");
    else
        CHECK(tu_contains(fx_context_error(ctx), "light_source"));
    fx_stack_free(s);
    fx_frame_free(f);
    /* no light view: FX_ERR_NO_AUX_VIEW naming it; the stack asks for it */
    f = scene_frame(ctx, NULL, "SUN", 0.5f);
    s = vol_stack(ctx, "final", "full");
    CHECK_FAIL(ctx, fx_stack_run(s, f, &out), FX_ERR_NO_AUX_VIEW, "light:");
    char *req = NULL;
    CHECK_OK(ctx, fx_stack_required_aux_views(s, &req));
    CHECK(req && strcmp(req, "{\"aux_views\":[{\"name\":\"light:\",\"kind\":\"light\",\"light\":\"\"}]}") == 0);
    fx_free(req);
    CHECK_OK(ctx, fx_stack_set_enum(s, 0, "method", "polar"));
    CHECK_OK(ctx, fx_stack_required_aux_views(s, &req));
    CHECK(req && strcmp(req, "{\"aux_views\":[]}") == 0);
    fx_free(req);
    fx_stack_free(s);
    fx_frame_free(f);
    /* a point light: not yet */
    f = scene_frame(ctx, path, "POINT", 0.5f);
    s = vol_stack(ctx, "final", "full");
    CHECK_FAIL(ctx, fx_stack_run(s, f, &out), FX_ERR_BAD_PARAM, "point light");
    fx_stack_free(s);
    fx_frame_free(f);
}

/* In place and finite by itself (god_rays_volumetric_only): on a consumed frame the
 * volumetric method writes over the frame's own Combined with the bits of the run that keeps
 * its input, at every reduced preset, both composites, 1 and 2 threads; source pixels with
 * NaN, +-Inf and +-1e38 give finite outputs although the stack no longer scans them, and
 * no warning (nothing was left for the stack to replace). The polar method is neither: it
 * takes a buffer of its own and still gives the same bits. */
static void test_in_place_finite(fx_context *c2)
{
    double entry = 0;
    const char *path = write_light_view(c2, &entry);
    fx_context *c1 = NULL;
    fx_context_new(&c1, 1);
    static const char *const q[] = {"draft", "preview", "final"};
    poison = 1;
    for (int t = 0; t < 2; t++)
        for (int k = 0; k < 4; k++)
            for (int screen = 0; screen < 2; screen++) {
                fx_context *ctx = t ? c2 : c1;
                fx_stack *s = vol_stack(ctx, k < 3 ? q[k] : "final", "full");
                if (screen)
                    CHECK_OK(ctx, fx_stack_set_enum(s, 0, "composite", "screen"));
                if (k == 3) {
                    CHECK_OK(ctx, fx_stack_set_enum(s, 0, "method", "polar"));
                    CHECK_OK(ctx, fx_stack_set_enum(s, 0, "light_source", "screen"));
                }
                fx_frame *f = scene_frame(ctx, path, "SUN", 0.25f);
                fx_context_clear_warnings(ctx);
                float *o = et_run(ctx, s, f);
                if (k < 3)
                    CHECK(o && tu_all_finite(o, (size_t)W * H * 4) && fx_context_warning_count(ctx) == 0);
                CHECK(et_in_place_equal(ctx, s, f, k < 3)); /* f is consumed */
                free(o);
                fx_stack_free(s);
            }
    poison = 0;
    fx_context_free(c1);
    /* the aux cache off: each run reads and builds a private light map, whose buffer goes back
     * to the context's store at release and is taken again by the next read: the same bits
     * run after run as with the cache */
    fx_context *nc = NULL;
    fx_context_new(&nc, 2);
    CHECK_OK(nc, fx_context_set_aux_cache(nc, 0));
    fx_frame *f = scene_frame(c2, path, "SUN", 0.25f), *g = scene_frame(nc, path, "SUN", 0.25f);
    fx_stack *s = vol_stack(c2, "final", "full"), *t = vol_stack(nc, "final", "full");
    float *want = et_run(c2, s, f);
    for (int k = 0; k < 3; k++) {
        float *o = et_run(nc, t, g);
        CHECK(want && o && memcmp(want, o, (size_t)W * H * 4 * sizeof(float)) == 0);
        free(o);
    }
    free(want);
    fx_stack_free(s);
    fx_stack_free(t);
    fx_frame_free(f);
    fx_frame_free(g);
    fx_context_free(nc);
}

/* A masked entry (a rectangle) marches only the texels its pixels read, around them the
 * interleave's block: inside the rectangle every preset gives the unmasked run's bits, and
 * outside it the input's. Rectangles at odd offsets, at the frame's corners and one pixel
 * wide. */
static void test_masked_march(fx_context *ctx)
{
    double entry = 0;
    const char *path = write_light_view(ctx, &entry);
    fx_frame *f = scene_frame(ctx, path, "SUN", 0.0f);
    const float *src = NULL;
    int ch = 0;
    fx_frame_pass(f, "Combined", (float **)&src, &ch);
    static const char *const q[] = {"draft", "preview", "final", "reference"};
    static const int rects[][4] = {{21, 3, 17, 9}, {0, 0, 9, 5}, {50, 10, 14, 6}, {33, 7, 1, 1}};
    long differ = 0, leaked = 0;
    for (int k = 0; k < 4; k++) {
        fx_stack *s = vol_stack(ctx, q[k], "full");
        float *want = et_run(ctx, s, f);
        for (int m = 0; m < 4; m++) {
            const int *r = rects[m];
            char json[96];
            snprintf(json, sizeof json, "{\"rect\": [%d, %d, %d, %d]}", r[0], r[1], r[2], r[3]);
            CHECK_OK(ctx, fx_stack_set_mask_json(s, 0, json));
            float *got = et_run(ctx, s, f);
            for (int y = 0; got && want && src && y < H; y++)
                for (int x = 0; x < W; x++) {
                    const int in = x >= r[0] && x < r[0] + r[2] && y >= r[1] && y < r[1] + r[3];
                    const float *g = got + 4 * ((size_t)y * W + x);
                    differ += in && memcmp(g, want + 4 * ((size_t)y * W + x), 4 * sizeof(float)) != 0;
                    leaked += !in && memcmp(g, src + 4 * ((size_t)y * W + x), 4 * sizeof(float)) != 0;
                }
            CHECK(got != NULL);
            free(got);
        }
        free(want);
        fx_stack_free(s);
    }
    CHECK(differ == 0 && leaked == 0);
    if (differ || leaked)
        fprintf(stderr, "masked march: %ld pixels inside differ from the unmasked run, %ld outside changed\n", differ,
                leaked);
    fx_frame_free(f);
}

/* The march's sum, written out here in double: step i's visibility at s0 + (i + offset) h
 * (the depth test at the 4 nearest texels, bilinear; rows alike in these maps, so only the
 * columns matter), times its exact transmittance integral, the steps after the medium
 * turns opaque left out, as the library does. */
static double march_by_hand(const fx_shadow_map *sm, const fx_volume_ray *r, int steps, double offset, double sigma)
{
    const double h = ((double)r->s1 - r->s0) / steps, e1 = r->e1;
    const double step_int = e1 * h > 1e-9 ? (1.0 - exp(-e1 * h)) / e1 : h;
    double sum = 0.0;
    for (int i = 0; i < steps; i++) {
        const double od = r->e0 + e1 * (r->s0 + i * h);
        if (!(exp(-od) > exp(-(double)FX_VOLUME_OPAQUE)))
            break;
        const double s = r->s0 + (i + offset) * h;
        double px = r->px0 + s * r->dpx - 0.5, t = r->tn0 + s * r->dtn;
        px = px < 0 ? 0 : px > sm->width - 1 ? sm->width - 1 : px;
        const int x0 = (int)floor(px), x1 = x0 < sm->width - 1 ? x0 + 1 : x0;
        const double tx = px - x0;
        const double vis = (t <= sm->depth[x0] ? 1 - tx : 0) + (t <= sm->depth[x1] ? tx : 0);
        sum += vis * exp(-od) * step_int;
    }
    return sigma * r->phase * r->len * sum;
}

/* fx_volume_march, four samples at a time, against march_by_hand at step counts that are
 * and are not multiples of 4, two offsets, with and without extinction, on a map lit on
 * one side and shaded on the other with a ramp between; a wholly lit ray against the
 * closed form (the march is exact there); and a ray that turns opaque part way. */
static void test_march_steps(void)
{
    enum { MW = 16, MH = 4 };
    float depth[MW * MH];
    for (int y = 0; y < MH; y++)
        for (int x = 0; x < MW; x++) /* shaded (the surface at -1) left, lit right, between: in part */
            depth[y * MW + x] = x < 6 ? -1.0f : x >= 10 ? 1.0f : -0.9f + 0.3f * (float)(x - 6);
    fx_shadow_map sm = {0};
    sm.width = MW;
    sm.height = MH;
    sm.znear = 0.0f;
    sm.zfar = 10.0f;
    sm.depth = depth;
    fx_volume v = {0};
    v.sm = &sm;
    v.sigma = 0.3f;
    fx_volume_ray r = {0};
    r.s0 = 1.0f;
    r.s1 = 7.0f;
    r.len = 1.25f;
    r.px0 = -1.0f; /* across the whole map, off both ends */
    r.dpx = 2.6f;
    r.py0 = 2.0f;
    r.tn0 = -0.3f; /* the normalised depth climbs through the ramp's tests */
    r.dtn = 0.05f;
    r.phase = 0.2f;
    CHECK(FX_VOLUME_OPAQUE_T == expf(-FX_VOLUME_OPAQUE)); /* the march's stop, a constant */
    static const int steps[] = {1, 2, 3, 4, 5, 7, 13, 24, 257};
    double worst = 0.0;
    for (int e = 0; e < 2; e++)
        for (int k = 0; k < (int)(sizeof steps / sizeof steps[0]); k++)
            for (int o = 0; o < 2; o++) {
                r.e0 = e ? 0.4f : 0.0f;
                r.e1 = e ? 0.35f : 0.0f;
                const double off = o ? 0.13 : 0.5;
                const double want = march_by_hand(&sm, &r, steps[k], off, v.sigma);
                const double got = fx_volume_march(&v, &r, steps[k], (float)off);
                const double rel = fabs(got - want) / (want + 1e-9);
                worst = rel > worst || rel != rel ? rel : worst;
                if (!(rel < 2e-5))
                    fprintf(stderr, "march: %d steps, offset %.2f, extinction %d: %.7g, by hand %.7g\n", steps[k], off,
                            e, got, want);
            }
    CHECK(worst < 2e-5);
    /* wholly lit: sigma p len (exp(-(e0 + e1 s0)) - exp(-(e0 + e1 s1))) / e1, any steps;
     * past the map's last column and row (AddressSanitizer: no read beyond them) */
    r.tn0 = -0.95f;
    r.dtn = 0.0f;
    r.px0 = 11.0f;
    r.dpx = 1.0f;
    r.py0 = 10.0f;
    r.e0 = 0.4f;
    r.e1 = 0.35f;
    const double lit = v.sigma * r.phase * r.len * (exp(-(0.4 + 0.35 * 1.0)) - exp(-(0.4 + 0.35 * 7.0))) / 0.35;
    for (int k = 0; k < (int)(sizeof steps / sizeof steps[0]); k++)
        CHECK(fabs(fx_volume_march(&v, &r, steps[k], 0.5f) - lit) < 2e-5 * lit);
    /* opaque part way: the optical depth passes FX_VOLUME_OPAQUE at s = 4 */
    r.e0 = 0.0f;
    r.e1 = FX_VOLUME_OPAQUE / 4.0f;
    for (int k = 0; k < (int)(sizeof steps / sizeof steps[0]); k++) {
        const double want = march_by_hand(&sm, &r, steps[k], 0.5, v.sigma);
        CHECK(fabs(fx_volume_march(&v, &r, steps[k], 0.5f) - want) < 2e-5 * want);
    }
}

/* The composite's 4-pixel upsamples (fx_volume_upsample_cell4 across cells,
 * fx_volume_upsample_same4 on one cell) give fx_volume_upsample's bits: random cells mixing alike depths, depth edges, background and thin objects (no
 * texel alike: the likest one), random tx/ty, including exact 0 and 1. */
static void test_upsample_cell4(void)
{
    enum { LW = 9, LH = 3 };
    float lo[LW * LH], lt[LW * LH], ld[LW * LH];
    long bad = 0, fallback = 0, n = 0;
    for (int rep = 0; rep < 400; rep++) {
        for (int i = 0; i < LW * LH; i++) {
            float u = fx_rand4(rep, i, 1, 7);
            ld[i] = u < 0.15f ? FX_VOLUME_BG_DEPTH : 2.0f + 40.0f * u * u;
            if (fx_rand4(rep, i, 2, 7) < 0.5f && i > 0)
                ld[i] = ld[i - 1] * (1.0f + 0.01f * fx_rand4(rep, i, 3, 7)); /* alike */
            lo[i] = 3.0f * fx_rand4(rep, i, 4, 7);
            lt[i] = fx_rand4(rep, i, 5, 7);
        }
        const int Y0 = rep % (LH - 1);
        const size_t r0 = (size_t)Y0 * LW, r1 = r0 + LW;
        float ty = fx_rand4(rep, 0, 6, 7);
        ty = rep % 7 == 0 ? 0.0f : rep % 7 == 1 ? 1.0f : ty;
        float cell[LW][12];
        for (int X = 0; X < LW; X++) {
            const int X1 = X + 1 < LW ? X + 1 : X;
            const size_t t[4] = {r0 + X, r0 + X1, r1 + X, r1 + X1};
            for (int m = 0; m < 4; m++) {
                cell[X][m] = ld[t[m]];
                cell[X][4 + m] = lo[t[m]];
                cell[X][8 + m] = lt[t[m]];
            }
        }
        const v4f by = {1.0f - ty, 1.0f - ty, ty, ty};
        for (int blk = 0; blk < 8; blk++) {
            int X0[4];
            float tx[4], d[4];
            const float *c[4];
            for (int k = 0; k < 4; k++) {
                X0[k] = (int)(fx_hash4(rep, blk, k, 8) % LW);
                tx[k] = fx_rand4(rep, blk, k, 9);
                tx[k] = (blk + k) % 5 == 0 ? 0.0f : tx[k];
                float u = fx_rand4(rep, blk, k, 10);
                d[k] = u < 0.3f ? cell[X0[k]][k] * (1.0f + 0.05f * u) : u < 0.4f ? FX_VOLUME_BG_DEPTH
                                                                                  : 1.0f + 60.0f * u;
                c[k] = cell[X0[k]];
            }
            v4f L, T, Ls, Ts, bc[12];
            const v4f tx4 = {tx[0], tx[1], tx[2], tx[3]}, d4 = {d[0], d[1], d[2], d[3]};
            fx_volume_upsample_cell4(c, by, tx4, d4, &L, &T);
            for (int m = 0; m < 12; m++) /* the same 4 pixels all on X0[0]'s cell */
                bc[m] = V4(c[0][m]);
            fx_volume_upsample_same4(c[0], bc, ty, tx4, d4, &Ls, &Ts);
            for (int k = 0; k < 4; k++) {
                float l1, t1, l0, t0;
                fx_volume_upsample(lo, lt, ld, r0, r1, X0[k], X0[k] + 1 < LW ? X0[k] + 1 : X0[k], tx[k], ty, d[k],
                                   &l1, &t1);
                fx_volume_upsample(lo, lt, ld, r0, r1, X0[0], X0[0] + 1 < LW ? X0[0] + 1 : X0[0], tx[k], ty, d[k],
                                   &l0, &t0);
                bad += memcmp(&l1, &L[k], sizeof l1) != 0 || memcmp(&t1, &T[k], sizeof t1) != 0;
                bad += memcmp(&l0, &Ls[k], sizeof l0) != 0 || memcmp(&t0, &Ts[k], sizeof t0) != 0;
                float e = 0.0f;
                for (int m = 0; m < 4; m++) {
                    float r = fabsf(d[k] - c[k][m]) * (10.0f / d[k]), q = 1.0f - 0.5f * r;
                    e += q > 0.0f ? q * q : 0.0f;
                }
                fallback += e == 0.0f;
                n++;
            }
        }
    }
    CHECK(bad == 0);
    CHECK(fallback > 20); /* the likest-texel lane was exercised */
    if (getenv("VOL_DEBUG") || bad)
        fprintf(stderr, "upsample_cell4: %ld of %ld pixels differ (%ld with no texel alike)\n", bad, n, fallback);
}

/* A light view of w x h raw depths written with `compression` ("none": the layout that
 * streams row by row, io/exr_rows.h; "zip": read whole). */
static const char *write_raw_view(fx_context *ctx, const float *d, int w, int h, const char *name,
                                  const char *compression)
{
    static char path[4][512];
    static int next;
    char *p = path[next++ % 4];
    snprintf(p, 512, "%s/%s_%s.exr", tu_tmpdir("god_rays_volumetric"), name, compression);
    fx_frame *f = NULL;
    fx_frame_new(ctx, w, h, &f);
    fx_frame_add_pass(f, "Depth", 1, d);
    fx_write_options o = {sizeof o, 0, 0, NULL, compression};
    CHECK_OK(ctx, fx_frame_write_exr(f, p, &o));
    fx_frame_free(f);
    return p;
}

/* light_view_downsample (draft: 2): the reduced map is the full map's texels (f X + o,
 * f Y + o), o = (f - 1) / 2, bit for bit, its kept rows read alone (uncompressed) or the
 * view whole (zip), with NaN/Inf made finite as the reader makes them; depth_min is the
 * least of the kept rows, every texel of them (the view's least, on a row between, is never
 * read); the reduced view puts a kept texel's centre at X + 0.5. */
static void test_reduced_map(fx_context *ctx)
{
    const int w = 37, h = 23;
    float *d = malloc((size_t)w * h * sizeof(float));
    static const char *const comp[] = {"none", "zip"};
    for (int poisoned = 0; poisoned < 2; poisoned++) {
        for (int i = 0; i < w * h; i++)
            d[i] = 5.0f + (float)((i * 7919) % 251) * 0.1f;
        d[3 * w + 3] = 2.5f; /* the least, on a row neither f = 2 nor f = 3 keeps */
        d[4 * w + 3] = 3.0f; /* the kept rows' least: on a row both keep, a column neither keeps */
        static const float bad[] = {NAN, INFINITY, -INFINITY, 1e38f};
        for (int i = 0; poisoned && i < w * h; i += 17)
            d[i] = bad[(i / 17) % 4];
        for (int c = 0; c < 2; c++) {
            const char *path = write_raw_view(ctx, d, w, h, "reduced", comp[c]);
            fx_exr_rows *rows = NULL;
            fx_exr_rows_info info;
            CHECK_OK(ctx, fx_exr_rows_open(ctx, path, "Depth", &rows, &info));
            CHECK((rows != NULL) == (c == 0)); /* only the uncompressed file streams */
            CHECK(!rows || (info.width == w && info.height == h));
            fx_exr_rows_close(rows);
            fx_frame *f = scene_frame(ctx, path, "SUN", 0.0f);
            fx_aux_map full, red;
            CHECK_OK(ctx, fx_aux_map_acquire(f, "light:Sun", 0, -1, 0.0f, "test", &full));
            for (int k = 2; k <= 3; k++) {
                CHECK_OK(ctx, fx_aux_map_acquire_reduced(f, "light:Sun", k, "test", &red));
                const fx_shadow_map *a = full.sm, *b = red.sm;
                const int o = (k - 1) / 2;
                CHECK(b->width == (w + k - 1) / k && b->height == (h + k - 1) / k);
                long differ = 0;
                for (int Y = 0; Y < b->height; Y++)
                    for (int X = 0; X < b->width; X++) {
                        const int x = k * X + o < w ? k * X + o : w - 1, y = k * Y + o < h ? k * Y + o : h - 1;
                        differ += memcmp(&b->depth[(size_t)Y * b->width + X], &a->depth[(size_t)y * w + x], 4) != 0;
                    }
                float kept_min = 1.0f;
                for (int Y = 0; Y < b->height; Y++)
                    for (int x = 0, y = k * Y + o < h ? k * Y + o : h - 1; x < w; x++)
                        kept_min = a->depth[(size_t)y * w + x] < kept_min ? a->depth[(size_t)y * w + x] : kept_min;
                CHECK(differ == 0);
                CHECK(b->depth_min == kept_min);
                CHECK(poisoned || (a->depth_min == fx_shadow_map_norm(a, 2.5f) &&
                                   kept_min == fx_shadow_map_norm(a, 3.0f)));
                if (differ || b->depth_min != kept_min)
                    fprintf(stderr, "reduced map %s f %d poisoned %d: %ld texels differ, depth_min %g vs %g\n",
                            comp[c], k, poisoned, differ, (double)b->depth_min, (double)kept_min);
                /* a world point: its reduced coordinates are (full - o - 0.5) / k + 0.5 */
                const fx_vec3 pts[] = {fx_v3(-3.0f, 2.0f, 1.0f), fx_v3(4.5f, -7.25f, 0.0f)};
                for (int q = 0; q < 2; q++) {
                    float fx_, fy, fd, rx, ry, rd;
                    fx_aux_view_project(full.av, pts[q], &fx_, &fy, &fd);
                    fx_aux_view_project(red.av, pts[q], &rx, &ry, &rd);
                    const float ex = (fx_ - (float)o - 0.5f) / (float)k + 0.5f;
                    const float ey = (fy - (float)o - 0.5f) / (float)k + 0.5f;
                    CHECK(fabsf(rx - ex) < 1e-3f && fabsf(ry - ey) < 1e-3f && rd == fd);
                }
                fx_aux_map_release(&red);
            }
            fx_aux_map_release(&full);
            fx_frame_free(f);
        }
    }
    free(d);
}

/* A reduced map built again (the aux cache off, or a new light view every frame) takes the
 * previous map's buffer back from the context's store instead of fresh pages, and is built
 * over it whole: view B read into view A's old buffer is B's map in a context that never
 * held A. 1024 x 1024 at factor 2: a 1 MiB map, the store's least. */
static void test_reduced_map_recycled(void)
{
    enum { N = 1024 };
    float *d = malloc((size_t)N * N * sizeof(float));
    fx_context *plain = NULL, *fresh = NULL;
    fx_context_new(&plain, 2);
    fx_context_new(&fresh, 2);
    CHECK_OK(plain, fx_context_set_aux_cache(plain, 0));
    CHECK_OK(fresh, fx_context_set_aux_cache(fresh, 0));
    /* one view at a time: write_raw_view's folder is made afresh at each call */
    fx_aux_map a = {0}, b = {0}, want = {0};
    const float *first = NULL;
    for (int v = 0; v < 2; v++) {
        for (int i = 0; i < N * N; i++)
            d[i] = v ? 9.0f - (float)(i % 977) * 0.004f : 3.0f + (float)((i * 31) % 499) * 0.01f;
        const char *path = write_raw_view(plain, d, N, N, v ? "recycled_b" : "recycled_a", "none");
        fx_frame *f = scene_frame(plain, path, "SUN", 0.0f);
        if (v == 0) {
            CHECK_OK(plain, fx_aux_map_acquire_reduced(f, "light:Sun", 2, "test", &a));
            first = a.sm ? a.sm->depth : NULL;
            fx_aux_map_release(&a);
            fx_frame_free(f);
            continue;
        }
        fx_frame *ff = scene_frame(fresh, path, "SUN", 0.0f);
        CHECK_OK(plain, fx_aux_map_acquire_reduced(f, "light:Sun", 2, "test", &b));
        CHECK_OK(fresh, fx_aux_map_acquire_reduced(ff, "light:Sun", 2, "test", &want));
        fx_frame_free(f);
        fx_frame_free(ff);
    }
    CHECK(b.sm && first && b.sm->depth == first); /* the store's buffer, no fresh pages */
    CHECK(b.sm && want.sm && b.sm->width == N / 2 && want.sm->height == N / 2 &&
          memcmp(b.sm->depth, want.sm->depth, (size_t)(N / 2) * (N / 2) * sizeof(float)) == 0 &&
          b.sm->depth_min == want.sm->depth_min);
    fx_aux_map_release(&b);
    fx_aux_map_release(&want);
    fx_context_free(plain);
    fx_context_free(fresh);
    free(d);
}

/* A stack where vsm_shadows reads the full light view and god_rays draft the reduced one:
 * each gets its own map (the cache keys the factor), so the stack gives the bits of a
 * context without the cache, frame after frame; draft gives the same bits for 1 and 2
 * threads with the view's kept rows read alone. */
static void test_reduced_stack(fx_context *ctx)
{
    double entry = 0;
    const char *zip = write_light_view(ctx, &entry);
    /* the same view, uncompressed (the add-on's layout: its kept rows read alone) */
    fx_frame *lv = NULL;
    CHECK_OK(ctx, fx_frame_read_exr(ctx, zip, NULL, &lv));
    const fx_pass *lp = lv ? fx_frame_find_pass(lv, "Depth") : NULL;
    CHECK(lp != NULL);
    if (!lp)
        return;
    const char *path = write_raw_view(ctx, lp->data, LN, LN, "stack", "none");
    fx_frame_free(lv);
    fx_context *plain = NULL, *one = NULL;
    fx_context_new(&plain, 2);
    fx_context_new(&one, 1);
    CHECK_OK(plain, fx_context_set_aux_cache(plain, 0));
    const char *json = "{\"version\": 1, \"quality\": \"draft\", \"effects\": ["
                       "{\"effect\": \"vsm_shadows\", \"params\": {\"light\": \"Sun\", \"apply\": \"combined\"}},"
                       "{\"effect\": \"god_rays\", \"params\": {\"light\": \"Sun\", \"method\": \"volumetric\","
                       " \"volume_density\": 0.05, \"anisotropy\": 0.4, \"volume_bias\": 0}}]}";
    fx_stack *sc = NULL, *sp = NULL;
    CHECK_OK(ctx, fx_stack_new(ctx, &sc));
    CHECK_OK(plain, fx_stack_new(plain, &sp));
    CHECK_OK(ctx, fx_stack_load_json(sc, json));
    CHECK_OK(plain, fx_stack_load_json(sp, json));
    fx_frame *fc = scene_frame(ctx, path, "SUN", 0.5f), *fp = scene_frame(plain, path, "SUN", 0.5f);
    float *want = et_run(plain, sp, fp);
    long b0, r0, b1, r1;
    fx_aux_cache_stats(ctx, &b0, &r0);
    for (int frame = 0; frame < 2; frame++) {
        float *got = et_run(ctx, sc, fc);
        CHECK(got && want && memcmp(got, want, (size_t)W * H * 4 * sizeof(float)) == 0);
        free(got);
    }
    fx_aux_cache_stats(ctx, &b1, &r1);
    CHECK(r1 - r0 >= 2); /* the second frame reused both */
    /* god_rays draft alone: 1 and 2 threads, the view streamed */
    fx_stack *g1 = vol_stack(one, "draft", "full"), *g2 = vol_stack(ctx, "draft", "full");
    fx_frame *f1 = scene_frame(one, path, "SUN", 0.25f), *f2 = scene_frame(ctx, path, "SUN", 0.25f);
    float *a = et_run(one, g1, f1), *b = et_run(ctx, g2, f2);
    CHECK(a && b && memcmp(a, b, (size_t)W * H * 4 * sizeof(float)) == 0);
    free(a);
    free(b);
    free(want);
    fx_stack_free(g1);
    fx_stack_free(g2);
    fx_stack_free(sc);
    fx_stack_free(sp);
    fx_frame_free(f1);
    fx_frame_free(f2);
    fx_frame_free(fc);
    fx_frame_free(fp);
    fx_context_free(plain);
    fx_context_free(one);
}

static void count_row(void *user, int band, float *row, int worker)
{
    (void)band;
    (void)row;
    (void)worker;
    __atomic_add_fetch((int *)user, 1, __ATOMIC_RELAXED);
}

/* The band reader on damaged copies of a streamable view: cut short, and with bytes of its
 * chunk table and chunks overwritten (seeded): an error naming the file or, where the damage
 * lands in pixel bytes, a read of every row; never a crash (scripts/test.sh runs this under
 * AddressSanitizer). */
static void test_rows_damaged(fx_context *ctx)
{
    const int w = 37, h = 23;
    float d[37 * 23];
    for (int i = 0; i < w * h; i++)
        d[i] = 5.0f + (float)(i % 11);
    size_t size = 0;
    unsigned char *bytes = (unsigned char *)tu_slurp(write_raw_view(ctx, d, w, h, "damaged_src", "none"), &size);
    CHECK(bytes != NULL);
    if (!bytes)
        return;
    const long n = (long)size;
    unsigned char *copy = malloc(size);
    char path[600];
    snprintf(path, sizeof path, "%s/damaged_rows.exr", tu_tmpdir("god_rays_volumetric"));
    const long body = n - (long)h * (8 + w * 4) - 8L * h; /* the chunk table's start */
    int errors = 0, reads = 0;
    for (int k = 0; k < 160; k++) {
        memcpy(copy, bytes, (size_t)n);
        long len = n;
        if (k < 8) {
            len = n * (2 + k) / 10; /* cut at 20 % .. 90 % */
        } else {
            unsigned hsh = fx_hash4(k, 7, 3, 1);
            for (int b = 0; b < 4; b++) { /* 4 bytes in the table and the chunks' headers */
                long at = body + (long)(fx_hash4(k, b, 5, 2) % (unsigned)(n - body));
                copy[at] = (unsigned char)(hsh >> (8 * b));
            }
        }
        FILE *out = fopen(path, "wb");
        fwrite(copy, 1, (size_t)len, out);
        fclose(out);
        fx_exr_rows *rows = NULL;
        fx_exr_rows_info info;
        fx_result r = fx_exr_rows_open(ctx, path, "Depth", &rows, &info);
        if (!r && rows) {
            int got = 0;
            size_t bad = 0;
            r = fx_exr_rows_read_sampled(rows, 2, 0, count_row, &got, &bad);
            CHECK(r || got == (h + 1) / 2);
            fx_exr_rows_close(rows);
        }
        if (r) {
            errors++;
            CHECK(tu_contains(fx_context_error(ctx), "damaged_rows.exr"));
        } else {
            reads++;
        }
    }
    CHECK(errors >= 8); /* every cut file at least */
    if (getenv("VOL_DEBUG"))
        fprintf(stderr, "damaged band reads: %d errors, %d read\n", errors, reads);
    free(bytes);
    free(copy);
    fx_context_clear_warnings(ctx);
}

typedef struct rows_copy {
    float *rows;
    int width;
} rows_copy;

static void copy_row(void *user, int band, float *row, int worker)
{
    (void)worker;
    const rows_copy *c = user;
    memcpy(c->rows + (size_t)band * c->width, row, (size_t)c->width * sizeof(float));
}

/* The row reader's one pread per row (header and pixels where chunks follow each other in
 * order) trusts no layout: a valid file whose chunks 1 and 2 lie swapped (the offset table
 * says so) reads the same rows as the whole reader, the swapped ones through the table;
 * every row of the file as written reads the same too. */
static void test_rows_out_of_order(fx_context *ctx)
{
    const int w = 37, h = 23;
    float d[37 * 23];
    for (int i = 0; i < w * h; i++)
        d[i] = 5.0f + (float)i * 0.25f;
    const char *path = write_raw_view(ctx, d, w, h, "swapped", "none");
    size_t size = 0;
    unsigned char *bytes = (unsigned char *)tu_slurp(path, &size);
    CHECK(bytes != NULL);
    if (!bytes)
        return;
    const long n = (long)size;
    const long chunk = 8 + 4L * w, table = n - (long)h * chunk - 8L * h;
    for (int swapped = 0; swapped < 2; swapped++) {
        if (swapped) { /* chunks 1 and 2 change places, and so do their offsets */
            unsigned char tmp[8 + 4 * 37];
            uint64_t o1, o2;
            memcpy(tmp, bytes + table + 8L * h + chunk, (size_t)chunk);
            memmove(bytes + table + 8L * h + chunk, bytes + table + 8L * h + 2 * chunk, (size_t)chunk);
            memcpy(bytes + table + 8L * h + 2 * chunk, tmp, (size_t)chunk);
            memcpy(&o1, bytes + table + 8, 8);
            memcpy(&o2, bytes + table + 16, 8);
            memcpy(bytes + table + 8, &o2, 8);
            memcpy(bytes + table + 16, &o1, 8);
            FILE *out = fopen(path, "wb");
            fwrite(bytes, 1, (size_t)n, out);
            fclose(out);
        }
        fx_exr_rows *rows = NULL;
        fx_exr_rows_info info;
        CHECK_OK(ctx, fx_exr_rows_open(ctx, path, "Depth", &rows, &info));
        CHECK(rows != NULL);
        float got[37 * 23];
        memset(got, 0, sizeof got);
        size_t bad = 0;
        if (rows)
            CHECK_OK(ctx, fx_exr_rows_read_sampled(rows, 1, 0, copy_row, &(rows_copy){got, w}, &bad));
        fx_exr_rows_close(rows);
        fx_frame *f = NULL;
        CHECK_OK(ctx, fx_frame_read_exr(ctx, path, NULL, &f));
        const float *whole = NULL;
        int ch = 0;
        CHECK_OK(ctx, fx_frame_pass_read(f, "Depth", &whole, &ch));
        CHECK(whole && memcmp(got, whole, sizeof got) == 0 && memcmp(got, d, sizeof got) == 0);
        fx_frame_free(f);
    }
    free(bytes);
}

int main(void)
{
    fx_context *ctx = NULL;
    fx_context_new(&ctx, 2);
    test_closed_form(ctx);
    test_threads_presets(ctx);
    test_depth_edge(ctx);
    test_slanted_plane(ctx);
    test_extremes_errors(ctx);
    test_in_place_finite(ctx);
    test_march_steps();
    test_masked_march(ctx);
    test_upsample_cell4();
    test_reduced_map(ctx);
    test_reduced_stack(ctx);
    test_reduced_map_recycled();
    test_rows_damaged(ctx);
    test_rows_out_of_order(ctx);
    fx_context_free(ctx);
    return tu_finish("test_god_rays_volumetric");
}
