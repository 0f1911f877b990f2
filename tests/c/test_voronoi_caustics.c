/* voronoi_caustics: brute force == grid search exactly; Minkowski extremes (0.1 ... 1000,
 * infinity) finite and correct; d <= 0 rejected; the pattern is anchored to the world (two
 * cameras see the same value at the same world point, from Position and from Depth);
 * animated by the frame time; untouched outside the mask; threads. */
#include "fx_effect_test.h"
#include "math/hash.h"
#include "math/voronoi.h"
#include "math/wave_scale.h"

#include <float.h>
#include <math.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

static void test_brute_equals_grid(void)
{
    const int grids[] = {1, 2, 3, 5, 14, 40};
    const double ps[] = {0.1, 0.5, 1.0, 1.5, 2.0, 20.0, 1000.0, INFINITY};
    int mismatches = 0, total = 0;
    for (int gi = 0; gi < 6; gi++)
        for (int pi = 0; pi < 8; pi++) {
            fx_voronoi v = {grids[gi], 42u + (uint32_t)gi, 1.25 * pi, 1.3, ps[pi]};
            for (int q = 0; q < 400; q++) {
                double x = (fx_rand4(q, gi, pi, 1) - 0.3) * 3.0 * grids[gi];
                double y = (fx_rand4(q, gi, pi, 2) - 0.3) * 3.0 * grids[gi];
                if (q == 0) { x = 0.0; y = 0.0; }
                if (q == 1) { x = -1e-12; y = grids[gi]; }
                fx_voronoi_hit a, b;
                fx_voronoi_brute(&v, x, y, &a);
                fx_voronoi_grid(&v, x, y, &b);
                total++;
                if (a.i1 != b.i1 || a.i2 != b.i2 || memcmp(&a.f1, &b.f1, sizeof(double)) ||
                    memcmp(&a.f2, &b.f2, sizeof(double)) || !isfinite(a.f1) || !isfinite(a.f2)) {
                    if (mismatches++ < 5)
                        fprintf(stderr, "G %d p %g (%g, %g): brute %d/%d %.17g/%.17g grid %d/%d %.17g/%.17g\n",
                                grids[gi], ps[pi], x, y, a.i1, a.i2, a.f1, a.f2, b.i1, b.i2, b.f1, b.f2);
                }
            }
        }
    CHECK(mismatches == 0);
    CHECK(total == 6 * 8 * 400);
}

/* The per-frame point table: exact == the on-the-fly searches above, bit for bit; fast:
 * grid == brute bit for bit, and within float rounding of the exact distances. */
static void test_table(void)
{
    const int grids[] = {1, 2, 3, 5, 9, 10, 14, 40, 200};
    const double ps[] = {0.1, 1.0, 1.5, 2.0, 3.0, INFINITY};
    int exact_bad = 0, fast_bad = 0, near_bad = 0, fast_used = 0;
    for (int gi = 0; gi < 9; gi++)
        for (int pi = 0; pi < 6; pi++) {
            fx_voronoi v = {grids[gi], 7u + (uint32_t)gi, 0.75 * pi, 1.7, ps[pi]};
            fx_voronoi_table te, tf;
            CHECK(fx_voronoi_table_init(&te, &v, 0) == 0);
            CHECK(fx_voronoi_table_init(&tf, &v, 1) == 0);
            CHECK(te.kind == 0);
            fast_used += tf.kind != 0;
            int queries = grids[gi] >= 100 ? 40 : 600; /* brute force is O(G^2) */
            for (int q = 0; q < queries; q++) {
                double x = (fx_rand4(q, gi, pi, 3) - 0.3) * 3.0 * grids[gi];
                double y = (fx_rand4(q, gi, pi, 4) - 0.3) * 3.0 * grids[gi];
                if (q == 0) { x = 0.0; y = 0.0; }
                if (q == 1) { x = -1e-12; y = grids[gi]; }
                if (q == 2) { x = 1e9 + 0.25; y = -3e8; }
                fx_voronoi_hit a, b, c, d;
                fx_voronoi_grid(&v, x, y, &a);
                fx_voronoi_table_grid(&te, x, y, &b);
                fx_voronoi_table_brute(&te, x, y, &c);
                exact_bad += memcmp(&a, &b, sizeof a) != 0 || memcmp(&a, &c, sizeof a) != 0;
                fx_voronoi_table_grid(&tf, x, y, &b);
                fx_voronoi_table_brute(&tf, x, y, &d);
                fast_bad += b.i1 != d.i1 || b.i2 != d.i2 || memcmp(&b.f1, &d.f1, sizeof(double)) ||
                            memcmp(&b.f2, &d.f2, sizeof(double)) || !isfinite(b.f1) || !isfinite(b.f2);
                /* float: a few ulps of the tile coordinates (< G): 1e-6 (G + 1) cells */
                double tol = 1e-6 * (grids[gi] + 1);
                if (q != 2 && (fabs(b.f1 - a.f1) > tol || fabs(b.f2 - a.f2) > tol))
                    if (near_bad++ < 5)
                        fprintf(stderr, "G %d p %g (%g, %g): exact %d/%d %.9g/%.9g fast %d/%d %.9g/%.9g\n", grids[gi],
                                ps[pi], x, y, a.i1, a.i2, a.f1, a.f2, b.i1, b.i2, b.f1, b.f2);
            }
            fx_voronoi_table_free(&te);
            fx_voronoi_table_free(&tf);
        }
    if (exact_bad || fast_bad || near_bad)
        fprintf(stderr, "table: exact mismatches %d, fast grid != brute %d, fast far from exact %d\n", exact_bad,
                fast_bad, near_bad);
    CHECK(exact_bad == 0);
    CHECK(fast_bad == 0);
    CHECK(near_bad == 0);
    CHECK(fast_used == 4 * 4); /* G >= 10 and p in {1, 1.5, 2, inf} */
}

/* The fast kind's square lists (G <= 64): many queries, many on the squares' edges and
 * corners, equal to brute force bit for bit; lists built in two halves (as the effect
 * does in parallel) give the same. */
static void test_lists(void)
{
    const int grids[] = {10, 14, 33, 64};
    const double ps[] = {1.0, 1.5, 2.0, INFINITY};
    int bad = 0, used = 0;
    for (int gi = 0; gi < 4; gi++)
        for (int pi = 0; pi < 4; pi++) {
            fx_voronoi v = {grids[gi], 11u + (uint32_t)gi, 1.3 * pi, 2.0, ps[pi]};
            fx_voronoi_table t;
            CHECK(fx_voronoi_table_init(&t, &v, 2) == 0);
            fx_voronoi_table_build_lists(&t, 0, grids[gi] / 2);
            fx_voronoi_table_build_lists(&t, grids[gi] / 2, grids[gi]);
            used += t.sub > 0;
            for (int q = 0; q < 4000; q++) {
                double x = (fx_rand4(q, gi, pi, 5) - 0.2) * 1.5 * grids[gi];
                double y = (fx_rand4(q, gi, pi, 6) - 0.2) * 1.5 * grids[gi];
                if (q % 3 == 0) /* on a square's edge or corner */
                    x = floor(x * 4.0) / 4.0;
                if (q % 5 == 0)
                    y = floor(y * 2.0) / 2.0;
                fx_voronoi_hit a, b;
                fx_voronoi_table_grid(&t, x, y, &a);
                fx_voronoi_table_brute(&t, x, y, &b);
                if (memcmp(&a, &b, sizeof a) != 0 && bad++ < 5)
                    fprintf(stderr, "lists G %d p %g (%g, %g): grid %d/%d brute %d/%d\n", grids[gi], ps[pi], x, y,
                            a.i1, a.i2, b.i1, b.i2);
            }
            /* the batch (its wraps two at a time) gives fx_voronoi_table_grid's bits, also for
             * odd counts, negative, far (beyond int32 quotients) and tile-edge coordinates */
            enum { NB = 203 };
            double bx[NB], by[NB], f1[NB], f2[NB];
            int i1[NB], i2[NB];
            const double far[] = {-0.0, 1e12, -3.7e9, 2147483647.5, -2147483648.5, 1e15, (double)grids[gi]};
            for (int q = 0; q < NB; q++) {
                bx[q] = (fx_rand4(q, gi, pi, 8) - 0.5) * 3.0 * grids[gi];
                by[q] = q % 7 == 0 ? far[(q / 7) % 7] * (q % 2 ? 1.0 : 1.0 / grids[gi]) : (fx_rand4(q, gi, pi, 9) - 0.5) * 40.0;
                if (q % 11 == 0)
                    bx[q] = far[(q / 11) % 7];
            }
            fx_voronoi_table_grid_n(&t, NB, bx, by, f1, f2, i1, i2);
            for (int q = 0; q < NB; q++) {
                fx_voronoi_hit a;
                fx_voronoi_table_grid(&t, bx[q], by[q], &a);
                if ((memcmp(&a.f1, &f1[q], sizeof a.f1) || memcmp(&a.f2, &f2[q], sizeof a.f2) || a.i1 != i1[q] ||
                     a.i2 != i2[q]) &&
                    bad++ < 5)
                    fprintf(stderr, "batch G %d p %g (%g, %g): %d/%d vs %d/%d\n", grids[gi], ps[pi], bx[q], by[q],
                            a.i1, a.i2, i1[q], i2[q]);
            }
            fx_voronoi_table_free(&t);
        }
    CHECK(bad == 0);
    CHECK(used == 16);
}

static void test_minkowski(void)
{
    CHECK(fx_minkowski2(3, 4, 2.0) == 5.0);
    CHECK(fabs(fx_minkowski2(3, -4, 1.0) - 7.0) < 1e-12);
    CHECK(fx_minkowski2(3, 4, INFINITY) == 4.0);
    CHECK(fabs(fx_minkowski2(3, 4, 1000.0) - 4.0) < 1e-9);
    CHECK(fabs(fx_minkowski2(3, 4, 1.5) - pow(pow(3, 1.5) + pow(4, 1.5), 1 / 1.5)) < 1e-12);
    CHECK(fabs(fx_minkowski2(1, 1, 0.1) - 1024.0) < 1e-9);
    CHECK(fabs(fx_minkowski2(1, 1, 20.0) - pow(2.0, 0.05)) < 1e-12);
    CHECK(fx_minkowski2(0, 0, 0.1) == 0.0);
    double tiny = fx_minkowski2(1e-300, 1e-300, 2.0), huge = fx_minkowski2(1e300, -1e300, 2.0);
    CHECK(tiny > 0 && isfinite(tiny) && fabs(tiny / 1e-300 - sqrt(2.0)) < 1e-12);
    CHECK(isfinite(huge) && fabs(huge / 1e300 - sqrt(2.0)) < 1e-12);
    CHECK(isfinite(fx_minkowski2(1e300, 1e300, 0.1))); /* 1e300 * 1024 */
    /* monotone in p (for p >= 1 the unit ball grows towards the square) */
    const double ps[] = {0.1, 1.0, 1.5, 2.0, 20.0, 1000.0, INFINITY};
    for (int i = 0; i + 1 < 7; i++)
        CHECK(fx_minkowski2(0.3, 0.7, ps[i]) >= fx_minkowski2(0.3, 0.7, ps[i + 1]));
}

/* ---- frames seen by a camera looking straight down at the plane z = 0 ---- */

#define W 160
#define H 120

typedef struct cam {
    double pos[3];
    double yaw; /* rotation about world Z */
    double f;   /* projection focal (y) */
} cam;

static void cam_axes(const cam *c, double R[3][3])
{
    /* camera -Z = world -Z; camera X rotated by yaw in the XY plane */
    double cs = cos(c->yaw), sn = sin(c->yaw);
    double r[3][3] = {{cs, -sn, 0}, {sn, cs, 0}, {0, 0, 1}}; /* columns: camera axes in world */
    memcpy(R, r, sizeof r);
}

static void camera_sidecar(const cam *c, char *buf, size_t n)
{
    double R[3][3];
    cam_axes(c, R);
    double t[3];
    for (int i = 0; i < 3; i++) /* -R^T pos */
        t[i] = -(R[0][i] * c->pos[0] + R[1][i] * c->pos[1] + R[2][i] * c->pos[2]);
    double aspect = (double)W / H, zn = 0.1, zf = 100;
    snprintf(buf, n,
             "{\"world_to_camera\": [[%.17g,%.17g,%.17g,%.17g],[%.17g,%.17g,%.17g,%.17g],[%.17g,%.17g,%.17g,%.17g],[0,0,0,1]],"
             " \"projection\": [[%.17g,0,0,0],[0,%.17g,0,0],[0,0,%.17g,%.17g],[0,0,-1,0]],"
             " \"clip_start\": 0.1, \"clip_end\": 100, \"frame\": 3, \"fps\": 24}",
             R[0][0], R[1][0], R[2][0], t[0], R[0][1], R[1][1], R[2][1], t[1], R[0][2], R[1][2], R[2][2], t[2],
             c->f / aspect, c->f, (zf + zn) / (zn - zf), 2 * zf * zn / (zn - zf));
}

/* world point seen at continuous pixel (px, py) on z = 0, and its planar depth */
static double pixel_to_world(const cam *c, double px, double py, double X[3])
{
    double aspect = (double)W / H;
    double nx = px / W * 2 - 1, ny = 1 - py / H * 2;
    double dv[3] = {nx * aspect / c->f, ny / c->f, -1.0};
    double R[3][3];
    cam_axes(c, R);
    double dw[3];
    for (int i = 0; i < 3; i++)
        dw[i] = R[i][0] * dv[0] + R[i][1] * dv[1] + R[i][2] * dv[2];
    double t = -c->pos[2] / dw[2];
    for (int i = 0; i < 3; i++)
        X[i] = c->pos[i] + t * dw[i];
    return t; /* dv.z = -1: planar depth = t */
}

static int world_to_pixel(const cam *c, const double X[3], double *px, double *py)
{
    double R[3][3];
    cam_axes(c, R);
    double d[3] = {X[0] - c->pos[0], X[1] - c->pos[1], X[2] - c->pos[2]}, v[3];
    for (int i = 0; i < 3; i++)
        v[i] = R[0][i] * d[0] + R[1][i] * d[1] + R[2][i] * d[2];
    if (v[2] >= 0)
        return 0;
    double aspect = (double)W / H;
    double nx = v[0] / -v[2] * c->f / aspect, ny = v[1] / -v[2] * c->f;
    *px = (nx + 1) * 0.5 * W;
    *py = (1 - ny) * 0.5 * H;
    return 1;
}

static fx_frame *plane_frame(fx_context *ctx, const cam *c)
{
    float *rgba = malloc((size_t)W * H * 4 * sizeof(float));
    float *pos = malloc((size_t)W * H * 3 * sizeof(float));
    float *depth = malloc((size_t)W * H * sizeof(float));
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            size_t i = (size_t)y * W + x;
            double X[3];
            depth[i] = (float)pixel_to_world(c, x + 0.5, y + 0.5, X);
            pos[i * 3] = (float)X[0];
            pos[i * 3 + 1] = (float)X[1];
            pos[i * 3 + 2] = (float)X[2];
            rgba[i * 4] = rgba[i * 4 + 1] = rgba[i * 4 + 2] = 0.5f;
            rgba[i * 4 + 3] = 1.0f;
        }
    fx_frame *f = et_frame(ctx, W, H, rgba);
    char json[2048];
    camera_sidecar(c, json, sizeof json);
    if (f && (fx_frame_add_pass(f, "Position", 3, pos) != FX_OK || fx_frame_add_pass(f, "Depth", 1, depth) != FX_OK ||
              fx_frame_apply_sidecar(f, json) != FX_OK)) {
        fprintf(stderr, "plane frame: %s\n", fx_context_error(ctx));
        fx_frame_free(f);
        f = NULL;
    }
    free(rgba);
    free(pos);
    free(depth);
    return f;
}

static float *run_caustics(fx_context *ctx, fx_frame *f, const char *source, const char *extra_json)
{
    char recipe[1024];
    /* extra_json may set "points" itself: a recipe names each key once */
    int own_points = extra_json && strstr(extra_json, "\"points\"");
    snprintf(recipe, sizeof recipe,
             "{\"version\": 1, \"effects\": [{\"effect\": \"voronoi_caustics\", \"params\": {\"position_source\": "
             "\"%s\", %s\"line_width\": 0.3%s%s}}]}",
             source, own_points ? "" : "\"points\": 100, ", extra_json ? ", " : "", extra_json ? extra_json : "");
    fx_stack *s = NULL;
    float *o = NULL;
    if (fx_stack_new(ctx, &s) == FX_OK && fx_stack_load_json(s, recipe) == FX_OK)
        o = et_run(ctx, s, f);
    else
        fprintf(stderr, "caustics recipe: %s\n", fx_context_error(ctx));
    fx_stack_free(s);
    return o;
}

static double bilinear_r(const float *img, double px, double py)
{
    double fx = px - 0.5, fy = py - 0.5;
    int x0 = (int)floor(fx), y0 = (int)floor(fy);
    double tx = fx - x0, ty = fy - y0;
    const float *a = img + ((size_t)y0 * W + x0) * 4, *b = a + 4, *c = a + W * 4, *d = c + 4;
    return (a[0] * (1 - tx) + b[0] * tx) * (1 - ty) + (c[0] * (1 - tx) + d[0] * tx) * ty;
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static void test_world_anchoring(fx_context *ctx)
{
    cam A = {{0.3, -0.2, 4.0}, 0.0, 1.2}, B = {{1.0, 0.4, 5.0}, 0.35, 1.5};
    fx_frame *fa = plane_frame(ctx, &A), *fb = plane_frame(ctx, &B);
    CHECK(fa && fb);
    const char *sources[2] = {"position", "depth"};
    for (int si = 0; fa && fb && si < 2; si++) {
        /* cells of ~1.2 m: ~20 px, so that comparing through bilinear interpolation is fair */
        const char *big = "\"tile_size\": 12";
        float *oa = run_caustics(ctx, fa, sources[si], big), *ob = run_caustics(ctx, fb, sources[si], big);
        CHECK(oa && ob);
        if (!oa || !ob) {
            free(oa);
            free(ob);
            continue;
        }
        double *err = malloc(sizeof(double) * W * H), *screen = malloc(sizeof(double) * W * H);
        int n = 0;
        double range_lo = 1e9, range_hi = -1e9;
        for (int y = 2; y < H - 2; y++)
            for (int x = 2; x < W - 2; x++) {
                double X[3], qx, qy;
                pixel_to_world(&A, x + 0.5, y + 0.5, X);
                if (!world_to_pixel(&B, X, &qx, &qy) || qx < 2 || qy < 2 || qx > W - 2 || qy > H - 2)
                    continue;
                double va = oa[((size_t)y * W + x) * 4];
                err[n] = fabs(va - bilinear_r(ob, qx, qy));
                screen[n] = fabs(va - ob[((size_t)y * W + x) * 4]); /* same pixel: not the same point */
                range_lo = fmin(range_lo, va);
                range_hi = fmax(range_hi, va);
                n++;
            }
        qsort(err, (size_t)n, sizeof(double), cmp_double);
        qsort(screen, (size_t)n, sizeof(double), cmp_double);
        double med = err[n / 2], p95 = err[(int)(n * 0.95)], smed = screen[n / 2];
        fprintf(stderr, "anchoring (%s): %d shared pixels, value range %.3f..%.3f, |A - B| median %.5f p95 %.5f; "
                        "same pixel (unanchored) median %.4f\n",
                sources[si], n, range_lo, range_hi, med, p95, smed);
        CHECK(n > W * H / 4);
        CHECK(range_hi - range_lo > 0.2);  /* there is a pattern to compare */
        CHECK(med < 0.005 && p95 < 0.03);  /* same world point, same value */
        CHECK(smed > 10 * med);            /* the test can tell */
        free(err);
        free(screen);
        free(oa);
        free(ob);
    }
    /* animated: another frame time changes the pattern; the same time reproduces it */
    if (fa) {
        float *o1 = run_caustics(ctx, fa, "position", NULL);
        fx_frame_set_time(fa, 9, 24);
        float *o2 = run_caustics(ctx, fa, "position", NULL);
        fx_frame_set_time(fa, 3, 24);
        float *o3 = run_caustics(ctx, fa, "position", NULL);
        CHECK(o1 && o2 && o3 && tu_max_abs_diff(o1, o2, (size_t)W * H * 4) > 0.05);
        CHECK(o1 && o3 && memcmp(o1, o3, (size_t)W * H * 4 * sizeof(float)) == 0);
        free(o1);
        free(o2);
        free(o3);
    }
    fx_frame_free(fa);
    fx_frame_free(fb);
}

static void test_extremes_and_mask(fx_context *ctx)
{
    cam A = {{0.3, -0.2, 4.0}, 0.0, 1.2};
    fx_frame *f = plane_frame(ctx, &A);
    CHECK(f != NULL);
    if (!f)
        return;
    const char *exps[] = {"\"exponent\": 0.1", "\"exponent\": 1", "\"exponent\": 1.5", "\"exponent\": 2",
                          "\"exponent\": 20", "\"exponent\": 1000", "\"metric\": \"chebyshev\"",
                          "\"exponent\": 1.5, \"mode\": \"seed\"", "\"exponent\": 0.1, \"mode\": \"seed\"",
                          "\"exponent\": 2, \"method\": \"brute\"", "\"points\": 1", "\"points\": 5000",
                          "\"environment_strength\": 1.0"};
    float *first = NULL;
    for (int i = 0; i < (int)(sizeof exps / sizeof exps[0]); i++) {
        if (i == 12) { /* environment needs Normal */
            float *nrm = malloc((size_t)W * H * 3 * sizeof(float));
            for (size_t k = 0; k < (size_t)W * H; k++) {
                nrm[k * 3] = nrm[k * 3 + 1] = 0.0f;
                nrm[k * 3 + 2] = 1.0f;
            }
            fx_frame_add_pass(f, "Normal", 3, nrm);
            free(nrm);
        }
        float *o = run_caustics(ctx, f, "position", exps[i]);
        int ok = o && tu_all_finite(o, (size_t)W * H * 4);
        /* physical mode (the entries without seed or environment), defaults strength 0.6,
         * tint (0.8, 0.95, 1): out = 0.5 (1 + 0.6 noise' (r - 1) tint_k), noise' = 0.4 +
         * 1.2 noise with noise in [0, 1] (so [0.4, 1.6]), r = min(g / mean, 16) in [0, 16]:
         * channel k in [0.5 (1 - 0.96 tint_k), 0.5 (1 + 14.4 tint_k)], alpha untouched (1).
         * Seed and environment add terms this does not bound: there only finite and in
         * [0, 100). */
        const int physical = !strstr(exps[i], "seed") && !strstr(exps[i], "environment");
        const double tint[3] = {0.8, 0.95, 1.0}, slack = 1e-5;
        for (size_t k = 0; ok && k < (size_t)W * H * 4; k++) {
            const int c = (int)(k % 4);
            if (!physical)
                ok = o[k] >= 0.0f && o[k] < 100.0f;
            else if (c == 3)
                ok = o[k] == 1.0f;
            else
                ok = o[k] >= 0.5 * (1.0 - 0.96 * tint[c]) - slack && o[k] <= 0.5 * (1.0 + 14.4 * tint[c]) + slack;
        }
        if (!ok)
            fprintf(stderr, "extreme %s: not finite/bounded\n", exps[i]);
        CHECK(ok);
        if (i == 3)
            first = o; /* exponent 2 grid ... */
        else if (i == 9) {
            CHECK(first && o && memcmp(first, o, (size_t)W * H * 4 * sizeof(float)) == 0); /* ... == brute */
            free(o);
        } else
            free(o);
    }
    free(first);
    /* strength 0: identity */
    float *o = run_caustics(ctx, f, "position", "\"strength\": 0");
    const float *in = et_combined(f);
    CHECK(o && memcmp(o, in, (size_t)W * H * 4 * sizeof(float)) == 0);
    free(o);
    /* cell_scale auto without the water's view: the manual cell, the same bits (a warning);
     * warp changes the image, warp 0 named in a version-1 recipe is the migrated default */
    {
        float *man = run_caustics(ctx, f, "position", "\"warp\": 0.3");
        float *aut = run_caustics(ctx, f, "position", "\"warp\": 0.3, \"cell_scale\": \"auto\"");
        float *w0 = run_caustics(ctx, f, "position", "\"warp\": 0.0");
        float *old = run_caustics(ctx, f, "position", NULL);
        CHECK(man && aut && memcmp(man, aut, (size_t)W * H * 4 * sizeof(float)) == 0);
        CHECK(w0 && old && memcmp(w0, old, (size_t)W * H * 4 * sizeof(float)) == 0);
        CHECK(man && w0 && memcmp(man, w0, (size_t)W * H * 4 * sizeof(float)) != 0);
        free(man);
        free(aut);
        free(w0);
        free(old);
    }
    /* d <= 0 rejected, with the parameter named */
    fx_stack *s = et_stack(ctx, "voronoi_caustics");
    CHECK_FAIL(ctx, fx_stack_set_float(s, 0, "exponent", -1.0), FX_ERR_BAD_PARAM, "exponent");
    CHECK_FAIL(ctx, fx_stack_set_float(s, 0, "exponent", NAN), FX_ERR_BAD_PARAM, "exponent");
    fx_result r = fx_stack_set_float(s, 0, "exponent", 0.0);
    fx_frame *out = NULL;
    if (r == FX_OK)
        r = fx_stack_run(s, f, &out);
    CHECK(r == FX_ERR_BAD_PARAM && tu_contains(fx_context_error(ctx), "exponent"));
    fx_frame_free(out);
    fx_stack_free(s);
    /* outside the mask: untouched, bit for bit */
    s = et_stack(ctx, "voronoi_caustics");
    CHECK_OK(ctx, fx_stack_set_mask_json(s, 0, "{\"rect\": [40, 30, 50, 40]}"));
    o = et_run(ctx, s, f);
    CHECK(o && et_outside_equal(o, in, W, H, 40, 30, 50, 40));
    CHECK(o && tu_max_abs_diff(o, in, (size_t)W * H * 4) > 0.05);
    free(o);
    fx_stack_free(s);
    /* threads: bit-identical */
    fx_context *c1 = NULL;
    fx_context_new(&c1, 1);
    fx_frame *f1 = plane_frame(c1, &A);
    float *a = run_caustics(c1, f1, "depth", NULL);
    float *b = run_caustics(ctx, f, "depth", NULL);
    CHECK(a && b && memcmp(a, b, (size_t)W * H * 4 * sizeof(float)) == 0);
    free(a);
    free(b);
    fx_frame_free(f1);
    fx_context_free(c1);
    /* missing Position names the pass */
    fx_frame *bare = et_frame(ctx, W, H, in);
    s = et_stack(ctx, "voronoi_caustics");
    out = NULL;
    CHECK_FAIL(ctx, fx_stack_run(s, bare, &out), FX_ERR_MISSING_PASS, "Position");
    fx_frame_free(out);
    fx_stack_free(s);
    fx_frame_free(bare);
    fx_frame_free(f);
}

/* A w x h frame of a plane seen from above (positions from a continuous camera-like map),
 * Normal +Z, Combined 0.5 grey; nan_every > 0 puts NaN/Inf positions on every n-th pixel. */
static fx_frame *small_frame(fx_context *ctx, int w, int h, int nan_every)
{
    float *rgba = malloc((size_t)w * h * 4 * sizeof(float)), *pos = malloc((size_t)w * h * 3 * sizeof(float));
    float *nrm = malloc((size_t)w * h * 3 * sizeof(float));
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            double u = (x + 0.5) / 7.0, v = (y + 0.5) / 7.0;
            pos[i * 3] = (float)(u + 0.05 * u * v); /* mildly non-linear, as perspective is */
            pos[i * 3 + 1] = (float)(v - 0.03 * u * u);
            pos[i * 3 + 2] = 0.0f;
            if (nan_every > 0 && i % (size_t)nan_every == 3)
                pos[i * 3 + (i & 1)] = (i & 2) ? NAN : INFINITY;
            nrm[i * 3] = nrm[i * 3 + 1] = 0.0f;
            nrm[i * 3 + 2] = 1.0f;
            rgba[i * 4] = rgba[i * 4 + 1] = rgba[i * 4 + 2] = 0.5f;
            rgba[i * 4 + 3] = 1.0f;
        }
    fx_frame *f = et_frame(ctx, w, h, rgba);
    cam c = {{0.3, -0.2, 4.0}, 0.0, 1.2}; /* any camera: the environment term needs one */
    char json[2048];
    camera_sidecar(&c, json, sizeof json);
    if (f && (fx_frame_add_pass(f, "Position", 3, pos) != FX_OK || fx_frame_add_pass(f, "Normal", 3, nrm) != FX_OK ||
              fx_frame_apply_sidecar(f, json) != FX_OK)) {
        fx_frame_free(f);
        f = NULL;
    }
    free(rgba);
    free(pos);
    free(nrm);
    return f;
}

static int all_finite_bounded(const float *o, size_t n)
{
    for (size_t k = 0; o && k < n; k++)
        if (!isfinite(o[k]) || o[k] < 0.0f || o[k] >= 100.0f)
            return 0;
    return o != NULL;
}

/* The reduced-resolution lattice (downsample > 1): tiny and odd sizes, each quality, masks
 * smaller than a lattice step, NaN/Inf positions; thread count; close to every-pixel. */
/* The lattice on tiny and odd frames, with NaN positions, at every preset and knob: finite,
 * the same for 1 and 2 threads, pixels without a position untouched. */
static void test_lattice_shapes(fx_context *ctx)
{
    fx_context *c1 = NULL;
    CHECK(fx_context_new(&c1, 1) == FX_OK);
    /* 300 x 7: rows longer than the shading's 256-pixel segments */
    const int sizes[][2] = {{1, 1}, {1, 9}, {9, 1}, {2, 2}, {7, 5}, {13, 11}, {64, 37}, {300, 7}};
    const char *settings[] = {
        "\"quality\": \"draft\"", "\"quality\": \"preview\"", "\"quality\": \"final\"",
        "\"downsample\": 3", "\"downsample\": 16", "\"downsample\": 5, \"mode\": \"seed\"",
        "\"downsample\": 4, \"lattice_shading\": true, \"exponent\": 0.5",
        "\"downsample\": 2, \"method\": \"brute\"", "\"downsample\": 2, \"distance\": \"exact\""};
    const int ns = (int)(sizeof settings / sizeof settings[0]);
    int bad_finite = 0, bad_threads = 0, bad_pass = 0;
    /* environment 0.3: per-pixel shading; 0: the segment shading (physical, no additive term) */
    for (int env = 0; env <= 1; env++)
    for (int si = 0; si < 8; si++)
        for (int nan = 0; nan <= 1; nan++) {
            int w = sizes[si][0], h = sizes[si][1];
            fx_frame *f = small_frame(ctx, w, h, nan ? 5 : 0), *f1 = small_frame(c1, w, h, nan ? 5 : 0);
            CHECK(f && f1);
            if (!f || !f1) {
                fx_frame_free(f);
                fx_frame_free(f1);
                continue;
            }
            for (int k = 0; k < ns; k++) {
                char params[512];
                /* "quality" is a recipe field; the others are params */
                int is_q = strncmp(settings[k], "\"quality\"", 9) == 0;
                snprintf(params, sizeof params,
                         "{\"version\": 1, %s%s\"effects\": [{\"effect\": \"voronoi_caustics\", \"params\": "
                         "{\"points\": 100, \"tile_size\": 2, \"line_width\": 0.2, \"environment_strength\": %s%s%s}}]}",
                         is_q ? settings[k] : "", is_q ? ", " : "", env ? "0" : "0.3", is_q ? "" : ", ",
                         is_q ? "" : settings[k]);
                fx_stack *s = NULL, *s1 = NULL;
                float *o = NULL, *o1 = NULL;
                if (fx_stack_new(ctx, &s) == FX_OK && fx_stack_load_json(s, params) == FX_OK)
                    o = et_run(ctx, s, f);
                else
                    fprintf(stderr, "lattice recipe %s: %s\n", params, fx_context_error(ctx));
                if (fx_stack_new(c1, &s1) == FX_OK && fx_stack_load_json(s1, params) == FX_OK)
                    o1 = et_run(c1, s1, f1);
                fx_stack_free(s);
                fx_stack_free(s1);
                size_t n = (size_t)w * h * 4;
                if (!all_finite_bounded(o, n)) {
                    if (bad_finite++ < 3)
                        fprintf(stderr, "lattice %dx%d nan %d %s: not finite/bounded\n", w, h, nan, settings[k]);
                }
                if (!o || !o1 || memcmp(o, o1, n * sizeof(float)))
                    bad_threads++;
                /* pixels without a position pass through untouched */
                const float *in = et_combined(f);
                for (size_t i = 3; nan && o && i < (size_t)w * h; i += 5)
                    bad_pass += memcmp(o + i * 4, in + i * 4, 4 * sizeof(float)) != 0;
                free(o);
                free(o1);
            }
            fx_frame_free(f);
            fx_frame_free(f1);
        }
    CHECK(bad_finite == 0);
    CHECK(bad_threads == 0);
    CHECK(bad_pass == 0);
    fx_context_free(c1);
}

/* The lattice's exact cases (segments, masks smaller than a step) and its error on a
 * smooth surface. */
static void test_lattice_accuracy(fx_context *ctx)
{
    /* the segment shading (no environment) across segment boundaries: grid == brute force at
     * final for d = 1.5 and 2, and finite (the default quality: final) */
    {
        fx_frame *fs = small_frame(ctx, 300, 7, 5);
        CHECK(fs != NULL);
        const char *exps[] = {"1.5", "2"};
        for (int e = 0; fs && e < 2; e++) {
            char pg[256], pb[256];
            snprintf(pg, sizeof pg, "\"points\": 100, \"tile_size\": 2, \"exponent\": %s, \"method\": \"grid\"", exps[e]);
            snprintf(pb, sizeof pb, "\"points\": 100, \"tile_size\": 2, \"exponent\": %s, \"method\": \"brute\"", exps[e]);
            float *og = et_run_effect(ctx, "voronoi_caustics", fs, pg, NULL);
            float *ob = et_run_effect(ctx, "voronoi_caustics", fs, pb, NULL);
            CHECK(og && ob && memcmp(og, ob, (size_t)300 * 7 * 4 * sizeof(float)) == 0);
            CHECK(all_finite_bounded(og, (size_t)300 * 7 * 4));
            free(og);
            free(ob);
            /* the row passes' batched searches (grid) against value_at's one at a time (brute)
             * under a mask whose ROI starts off the lattice's origin and spans two segments */
            og = et_run_effect(ctx, "voronoi_caustics", fs, pg, "{\"rect\": [3, 1, 290, 5]}");
            ob = et_run_effect(ctx, "voronoi_caustics", fs, pb, "{\"rect\": [3, 1, 290, 5]}");
            CHECK(og && ob && memcmp(og, ob, (size_t)300 * 7 * 4 * sizeof(float)) == 0);
            free(og);
            free(ob);
        }
        fx_frame_free(fs);
    }

    /* a mask smaller than a lattice step (1 x 1, 2 x 2 at odd places): the lattice shrinks
     * to the ROI (its first and last pixels are nodes), so these pixels are lattice nodes:
     * exactly the every-pixel result */
    fx_frame *f = small_frame(ctx, 64, 37, 0);
    CHECK(f != NULL);
    const char *rects[] = {"{\"rect\": [5, 7, 1, 1]}", "{\"rect\": [63, 36, 1, 1]}", "{\"rect\": [30, 11, 2, 2]}"};
    const int rx[] = {5, 63, 30}, ry[] = {7, 36, 11}, rw[] = {1, 1, 2}, rh[] = {1, 1, 2};
    for (int r = 0; f && r < 3; r++) {
        float *full = et_run_effect(ctx, "voronoi_caustics", f,
                                    "\"points\": 100, \"tile_size\": 2, \"downsample\": 1, \"distance\": \"fast\"", rects[r]);
        float *lat = et_run_effect(ctx, "voronoi_caustics", f,
                                   "\"points\": 100, \"tile_size\": 2, \"downsample\": 8, \"distance\": \"fast\"", rects[r]);
        const float *in = et_combined(f);
        CHECK(full && lat && memcmp(full, lat, (size_t)64 * 37 * 4 * sizeof(float)) == 0);
        CHECK(lat && et_outside_equal(lat, in, 64, 37, rx[r], ry[r], rw[r], rh[r]));
        CHECK(lat && tu_max_abs_diff(lat, in, (size_t)64 * 37 * 4) > 0.0);
        free(full);
        free(lat);
    }
    fx_frame_free(f);

    /* on a smooth surface the lattice stays close to every pixel (final: mean error small) */
    cam A = {{0.3, -0.2, 4.0}, 0.0, 1.2};
    fx_frame *pf = plane_frame(ctx, &A);
    float *ref = run_caustics(ctx, pf, "position", "\"downsample\": 1, \"distance\": \"exact\"");
    const char *qs[] = {"\"downsample\": 2", "\"downsample\": 2, \"refine\": false",
                        "\"downsample\": 4, \"refine\": false, \"lattice_shading\": true"};
    double mae[3] = {0, 0, 0};
    CHECK(pf && ref);
    for (int q = 0; pf && ref && q < 3; q++) {
        float *o = run_caustics(ctx, pf, "position", qs[q]);
        CHECK(o != NULL);
        for (size_t k = 0; o && k < (size_t)W * H * 4; k++)
            mae[q] += fabs(o[k] - ref[k]);
        mae[q] /= (double)W * H * 3;
        free(o);
    }
    fprintf(stderr, "lattice MAE vs every pixel: final %.5f, no refine %.5f, lattice shading x4 %.5f\n", mae[0],
            mae[1], mae[2]);
    /* cells of ~7 px here: refinement matters, lattice shading at 4 blurs (draft) */
    CHECK(mae[0] < 0.004 && mae[0] < mae[1] && mae[1] < mae[2] && mae[1] < 0.06 && mae[2] < 0.15);
    free(ref);
    fx_frame_free(pf);
}

static void test_lattice(fx_context *ctx)
{
    test_lattice_shapes(ctx);
    test_lattice_accuracy(ctx);
}

/* small_frame with a varied colour (so a pixel shaded twice would show), a step in the
 * positions right of a slanted line (pixels off their corners' surface) and a Depth pass
 * (some of it far); its Combined never handed out writable, so the stack may consume it. */
static fx_frame *in_place_frame(fx_context *ctx, int w, int h)
{
    fx_frame *base = small_frame(ctx, w, h, 37);
    const float *p0 = NULL, *n0 = NULL;
    fx_frame_pass_read(base, "Position", &p0, NULL);
    fx_frame_pass_read(base, "Normal", &n0, NULL);
    float *rgba = malloc((size_t)w * h * 4 * sizeof(float)), *pos = malloc((size_t)w * h * 3 * sizeof(float));
    float *dep = malloc((size_t)w * h * sizeof(float));
    memcpy(pos, p0, (size_t)w * h * 3 * sizeof(float));
    for (int i = 0; i < w * h; i++) {
        rgba[4 * i] = 0.1f + 0.01f * (float)(i % 71);
        rgba[4 * i + 1] = 0.2f + 0.003f * (float)(i % 113);
        rgba[4 * i + 2] = 0.5f;
        rgba[4 * i + 3] = 0.5f + 0.001f * (float)(i % 7);
        if (i % w > w / 2 + (i / w) / 3)
            pos[3 * i + 1] += 2.5f;
        dep[i] = 3.0f + 0.01f * (float)(i % w) + (i % 53 == 5 ? 1e10f : 0.0f);
    }
    fx_frame *f = et_frame(ctx, w, h, rgba);
    cam c = {{0.3, -0.2, 4.0}, 0.0, 1.2}; /* small_frame's */
    char json[2048];
    camera_sidecar(&c, json, sizeof json);
    CHECK_OK(ctx, fx_frame_add_pass(f, "Position", 3, pos));
    CHECK_OK(ctx, fx_frame_add_pass(f, "Normal", 3, n0));
    CHECK_OK(ctx, fx_frame_add_pass(f, "Depth", 1, dep));
    CHECK_OK(ctx, fx_frame_apply_sidecar(f, json));
    free(rgba);
    free(pos);
    free(dep);
    fx_frame_free(base);
    return f;
}

/* In place (a consumed frame: the output written over the input's Combined,
 * FX_EFFECT_IN_PLACE) equals the separate-buffer run bit for bit on every path: the gain
 * path (draft: downsample 4's octets and the general path's chunks, whose last octet used
 * to overlap the one before), the lattice and per-pixel paths, seed mode, the environment,
 * depth positions; on frames with a varied colour, invalid positions and a step in the
 * positions (pixels handed to gain_pixel and gain_flush), widths off the octets, a mask
 * (a second buffer then), 1 and 2 threads. */
static void test_in_place(void)
{
    const char *params[] = {
        "\"downsample\": 4, \"refine\": false, \"lattice_shading\": true",
        "\"downsample\": 3, \"refine\": false, \"lattice_shading\": true",
        "\"downsample\": 2, \"refine\": true",
        "\"downsample\": 2, \"refine\": false",
        "\"downsample\": 1, \"distance\": \"exact\"",
        "\"downsample\": 2, \"mode\": \"seed\"",
        "\"downsample\": 4, \"lattice_shading\": true, \"environment_strength\": 0.5",
        "\"downsample\": 1, \"environment_strength\": 0.5, \"mode\": \"seed\"",
        "\"downsample\": 2, \"position_source\": \"depth\"",
        "\"downsample\": 4, \"refine\": false, \"lattice_shading\": true, \"warp\": 0.3",
        "\"downsample\": 2, \"refine\": true, \"warp\": 0.6",
        "\"downsample\": 1, \"distance\": \"exact\", \"warp\": 0.3, \"mode\": \"seed\"",
    };
    const int sizes[][2] = {{83, 29}, {1100, 9}};
    const char *masks[] = {NULL, "{\"rect\": [6, 3, 61, 17]}"};
    for (int t = 1; t <= 2; t++) {
        fx_context *ctx = NULL;
        CHECK(fx_context_new(&ctx, t) == FX_OK);
        for (int z = 0; z < 2; z++)
            for (int m = 0; m < 2; m++)
                for (int k = 0; k < (int)(sizeof params / sizeof params[0]); k++) {
                    const int w = sizes[z][0], h = sizes[z][1];
                    fx_frame *f = in_place_frame(ctx, w, h);
                    char buf[1024];
                    snprintf(buf, sizeof buf,
                             "{\"version\":1,\"effects\":[{\"effect\":\"voronoi_caustics\",\"params\":{\"points\": 60, "
                             "\"tile_size\": 2.0, %s}%s%s}]}",
                             params[k], masks[m] ? ",\"mask\":" : "", masks[m] ? masks[m] : "");
                    fx_stack *s = NULL;
                    CHECK_OK(ctx, fx_stack_new(ctx, &s));
                    CHECK_OK(ctx, fx_stack_load_json(s, buf));
                    /* f is consumed; no mask: written over it */
                    const int ok = et_in_place_equal(ctx, s, f, !masks[m]);
                    if (!ok)
                        fprintf(stderr, "caustics in place differs: threads %d, %d x %d, mask %d, %s\n", t, w, h, m,
                                params[k]);
                    CHECK(ok);
                    fx_stack_free(s);
                }
        fx_context_free(ctx);
    }
}

/* A Position pass of four channels (XYZ and a fourth, as some exporters write it) is read
 * as its first three: the same bits as the three-channel pass on every path (the gain
 * path's octets and chunks, the lattice and per-pixel paths, seed mode, the environment),
 * on in_place_frame (invalid positions, a step), widths off the octets, with a mask. */
static void test_position_four_channels(fx_context *ctx)
{
    const char *params[] = {
        "\"downsample\": 4, \"refine\": false, \"lattice_shading\": true",
        "\"downsample\": 3, \"refine\": false, \"lattice_shading\": true",
        "\"downsample\": 6, \"refine\": false, \"lattice_shading\": true",
        "\"downsample\": 2, \"refine\": true",
        "\"downsample\": 1, \"distance\": \"exact\"",
        "\"downsample\": 2, \"mode\": \"seed\"",
        "\"downsample\": 4, \"lattice_shading\": true, \"environment_strength\": 0.5",
    };
    const int w = 83, h = 29;
    for (int m = 0; m < 2; m++)
        for (int k = 0; k < (int)(sizeof params / sizeof params[0]); k++) {
            fx_frame *f3 = in_place_frame(ctx, w, h), *f4 = in_place_frame(ctx, w, h);
            const float *p3 = NULL;
            fx_frame_pass_read(f3, "Position", &p3, NULL);
            float *p4 = malloc((size_t)w * h * 4 * sizeof(float));
            for (int i = 0; p3 && i < w * h; i++) {
                memcpy(p4 + 4 * i, p3 + 3 * i, 3 * sizeof(float));
                p4[4 * i + 3] = (float)(i % 5) - 2.0f; /* anything: not a coordinate */
            }
            CHECK_OK(ctx, fx_frame_add_pass(f4, "Position", 4, p4)); /* replaces the three-channel one */
            char pr[512];
            snprintf(pr, sizeof pr, "\"points\": 60, \"tile_size\": 2.0, %s", params[k]);
            const char *mask = m ? "{\"rect\": [6, 3, 61, 17]}" : NULL;
            float *o3 = et_run_effect(ctx, "voronoi_caustics", f3, pr, mask);
            float *o4 = et_run_effect(ctx, "voronoi_caustics", f4, pr, mask);
            const int same = o3 && o4 && memcmp(o3, o4, (size_t)w * h * 4 * sizeof(float)) == 0;
            if (!same)
                fprintf(stderr, "four-channel Position differs: mask %d, %s\n", m, params[k]);
            CHECK(same);
            free(o3);
            free(o4);
            free(p4);
            fx_frame_free(f3);
            fx_frame_free(f4);
        }
}

/* ---- an independent reference: the pattern evaluated directly at every pixel ----
 * From the documented definitions (docs/effects/voronoi_caustics.md, the hash's definition in math/hash.h,
 * tu_ref_hash4 in testutil.c), written out here with no library call: a G x G grid of cells
 * (G = round(sqrt(points))), cell size tile_size / G, one point per cell at (cx + 0.5 +
 * 0.44 sin(2 pi h1 + w1 t), cy + 0.5 + 0.44 sin(2 pi h2 + w2 t)), w = speed (0.6 + 0.8 h),
 * h1..h4 the cell's hash lowbias32-combined from (cx, cy, seed, 0x5eed) and its three
 * re-hashes; the tile repeats; distances are the plain Minkowski (|dx|^d + |dy|^d)^(1/d)
 * in cell units; F1, F2 the nearest and second nearest point's distances.
 *  - seed mode at time 0 (sin(2 time) = 0: no colour term): out = src (1 - clamp(0.5
 *    strength ln(1 + F1), 0, 1));
 *  - physical: out = src (1 + strength noise' (min(g / mean(g), 16) - 1) tint), g =
 *    exp(-(F2 - F1) / line_width), mean(g) over the 64 x 64 lattice ((c + 0.5) G / 64) of
 *    the tile. With noise_scale 1e9 the noise is one constant over the frame (the frame
 *    lies inside one noise cell, at its corner), so noise' is a single unknown amp in
 *    [0.4, 1.6] strength: it is fitted (least squares) and everything else must match. */
typedef struct ref_vor {
    int G;
    double px[64], py[64]; /* G <= 8 */
    double d;
} ref_vor;

static void ref_points(ref_vor *v, int points, int seed, double t, double speed, double d)
{
    v->G = (int)floor(sqrt((double)points) + 0.5);
    v->d = d;
    for (int cy = 0; cy < v->G; cy++)
        for (int cx = 0; cx < v->G; cx++) {
            uint32_t h = tu_ref_hash4(cx, cy, seed, 0x5eed);
            double h1 = tu_ref_unit(h), h2 = tu_ref_unit(tu_ref_hash_u32(h ^ 0x1234567u));
            double h3 = tu_ref_unit(tu_ref_hash_u32(h ^ 0x89abcdefu)), h4 = tu_ref_unit(tu_ref_hash_u32(h + 77u));
            v->px[cy * v->G + cx] = cx + 0.5 + 0.44 * sin(2 * M_PI * h1 + speed * (0.6 + 0.8 * h3) * t);
            v->py[cy * v->G + cx] = cy + 0.5 + 0.44 * sin(2 * M_PI * h2 + speed * (0.6 + 0.8 * h4) * t);
        }
}

/* F1, F2 at (x, y) in cell units: every point's nearest periodic image */
static void ref_f12(const ref_vor *v, double x, double y, double *f1, double *f2)
{
    double G = v->G;
    x -= G * floor(x / G);
    y -= G * floor(y / G);
    *f1 = *f2 = INFINITY;
    for (int k = 0; k < v->G * v->G; k++) {
        double best = INFINITY;
        for (int oy = -1; oy <= 1; oy++)
            for (int ox = -1; ox <= 1; ox++) {
                double dx = fabs(x - (v->px[k] + ox * G)), dy = fabs(y - (v->py[k] + oy * G));
                double dist = isinf(v->d) ? fmax(dx, dy) : pow(pow(dx, v->d) + pow(dy, v->d), 1.0 / v->d);
                best = fmin(best, dist);
            }
        if (best < *f1) {
            *f2 = *f1;
            *f1 = best;
        } else if (best < *f2) {
            *f2 = best;
        }
    }
}

#define RW 64
#define RH 48
/* A flat floor: Position = (0.05 x + 0.013, 0.05 y + 0.021, 0) (two tiles of 1.6 across),
 * colour (0.5, 0.4, 0.3, 1) */
static fx_frame *ref_floor(fx_context *ctx, double frame)
{
    float *rgba = malloc((size_t)RW * RH * 4 * sizeof(float)), *pos = malloc((size_t)RW * RH * 3 * sizeof(float));
    for (int i = 0; i < RW * RH; i++) {
        pos[i * 3] = (float)(0.05 * (i % RW) + 0.013);
        pos[i * 3 + 1] = (float)(0.05 * (i / RW) + 0.021);
        pos[i * 3 + 2] = 0.0f;
        rgba[i * 4] = 0.5f, rgba[i * 4 + 1] = 0.4f, rgba[i * 4 + 2] = 0.3f, rgba[i * 4 + 3] = 1.0f;
    }
    fx_frame *f = et_frame(ctx, RW, RH, rgba);
    if (f && fx_frame_add_pass(f, "Position", 3, pos) != FX_OK) {
        fx_frame_free(f);
        f = NULL;
    }
    if (f)
        fx_frame_set_time(f, frame, 24.0);
    free(rgba);
    free(pos);
    return f;
}

static float *ref_run(fx_context *ctx, double frame, const char *quality, const char *params)
{
    char recipe[1024];
    snprintf(recipe, sizeof recipe,
             "{\"version\": 1, \"quality\": \"%s\", \"effects\": [{\"effect\": \"voronoi_caustics\", \"params\": "
             "{\"points\": 16, \"tile_size\": 1.6, %s}}]}",
             quality, params);
    fx_frame *f = ref_floor(ctx, frame);
    fx_stack *s = NULL;
    float *o = NULL;
    if (f && fx_stack_new(ctx, &s) == FX_OK && fx_stack_load_json(s, recipe) == FX_OK)
        o = et_run(ctx, s, f);
    else
        fprintf(stderr, "reference recipe: %s\n", fx_context_error(ctx));
    fx_stack_free(s);
    fx_frame_free(f);
    return o;
}

static void test_reference_seed_mode(fx_context *ctx)
{
    const double ds[3] = {1.5, 1.0, INFINITY};
    const char *metric[3] = {"\"exponent\": 1.5", "\"exponent\": 1.0", "\"metric\": \"chebyshev\""};
    const float src[3] = {0.5f, 0.4f, 0.3f};
    for (int k = 0; k < 3; k++) {
        ref_vor v;
        ref_points(&v, 16, 7, 0.0, 1.0, ds[k]);
        char params[256];
        snprintf(params, sizeof params, "\"mode\": \"seed\", \"strength\": 1.0, \"seed\": 7, %s", metric[k]);
        {
            float *o = ref_run(ctx, 0.0, "reference", params);
            double e = INFINITY, fmin1 = INFINITY, fmax1 = 0;
            if (o) {
                e = 0;
                for (int i = 0; i < RW * RH; i++) {
                    double f1, f2;
                    ref_f12(&v, (0.05 * (i % RW) + 0.013) / 0.4, (0.05 * (i / RW) + 0.021) / 0.4, &f1, &f2);
                    double a = fmin(fmax(0.5 * log1p(f1), 0), 1);
                    fmin1 = fmin(fmin1, f1);
                    fmax1 = fmax(fmax1, f1);
                    for (int ch = 0; ch < 3; ch++)
                        e = fmax(e, fabs(o[(size_t)i * 4 + ch] - src[ch] * (1 - a)));
                    e = fmax(e, fabs(o[(size_t)i * 4 + 3] - 1.0));
                }
            }
            fprintf(stderr, "reference seed mode d %g: max error %.2e (F1 %.3f..%.3f)\n", ds[k], e, fmin1, fmax1);
            /* the reference preset: double all through, a float output of values ~0.5 */
            CHECK(e < 1e-6);
            CHECK(fmax1 > 0.4); /* the pattern spans a range of F1 (not a constant) */
            free(o);
        }
    }
}

static void test_reference_physical_mode(fx_context *ctx)
{
    const double frame = 30.0, t = frame / 24.0, lw = 0.15, strength = 0.5; /* amp < 1: nothing clamped at 0 */
    const float src[3] = {0.5f, 0.4f, 0.3f}, tint[3] = {0.8f, 0.95f, 1.0f};
    ref_vor v;
    ref_points(&v, 16, 3, t, 1.7, 2.0);
    /* mean(g) over the 64 x 64 lattice of the tile */
    double mean = 0;
    for (int r = 0; r < 64; r++)
        for (int c = 0; c < 64; c++) {
            double f1, f2;
            ref_f12(&v, (c + 0.5) * v.G / 64.0, (r + 0.5) * v.G / 64.0, &f1, &f2);
            mean += exp(-(f2 - f1) / lw) / 4096.0;
        }
    float *o = ref_run(ctx, frame, "reference",
                       "\"mode\": \"physical\", \"strength\": 0.5, \"line_width\": 0.15, \"seed\": 3, \"speed\": 1.7, "
                       "\"exponent\": 2.0, \"noise_scale\": 1e9");
    CHECK(o != NULL);
    if (!o)
        return;
    /* out / (src tint) - 1 / tint = amp x, x = min(g / mean, 16) - 1: fit amp, then the residual */
    double *x = malloc((size_t)RW * RH * sizeof(double)), sxy = 0, sxx = 0;
    for (int i = 0; i < RW * RH; i++) {
        double f1, f2;
        ref_f12(&v, (0.05 * (i % RW) + 0.013) / 0.4, (0.05 * (i / RW) + 0.021) / 0.4, &f1, &f2);
        x[i] = fmin(exp(-(f2 - f1) / lw) / mean, 16.0) - 1.0;
        for (int ch = 0; ch < 3; ch++) {
            double y = (o[(size_t)i * 4 + ch] / src[ch] - 1.0) / tint[ch];
            sxy += x[i] * y;
            sxx += x[i] * x[i];
        }
    }
    double amp = sxy / sxx, e = 0, xmax = 0;
    for (int i = 0; i < RW * RH; i++) {
        xmax = fmax(xmax, x[i]);
        for (int ch = 0; ch < 3; ch++)
            e = fmax(e, fabs(o[(size_t)i * 4 + ch] - fmax(0.0, src[ch] * (1.0 + amp * x[i] * tint[ch]))));
    }
    fprintf(stderr, "reference physical mode: mean(g) %.4f, fitted noise' %.4f, max error %.2e (focus up to %.2f)\n",
            mean, amp / strength, e, xmax + 1);
    CHECK(amp >= 0.4 * strength && amp <= 1.6 * strength);
    CHECK(xmax > 2.0); /* bright lines in the frame */
    CHECK(e < 1e-5);   /* float arithmetic on values <= ~4 */
    free(x);
    free(o);
}

/* The domain warp (params_version 3, warp): identity at 0 (old recipes' bits), periodic over
 * the tile, bounded by its amplitude, its Lipschitz factor (cell_smooth's skip) a true bound,
 * and it bends a cell side. Two points on one row, under the p = 1.5 distance: the
 * analytic bisector is the straight line x = mid (symmetry), for any Minkowski exponent;
 * with the warp, the edge found by bisection satisfies x + dx(x, y) = mid, so it bends by
 * the warp's x offset (of order amp: curved, not a polygon side). */
static double edge_x(const fx_voronoi_warp *w, double y, double ax, double bx, double ay)
{
    double lo = ax + 0.05, hi = bx - 0.05;
    for (int it = 0; it < 80; it++) {
        double x = 0.5 * (lo + hi), u = x, v = y;
        fx_voronoi_warp_apply(w, &u, &v);
        double da = fx_minkowski2(u - ax, v - ay, 1.5), db = fx_minkowski2(u - bx, v - ay, 1.5);
        if (da < db)
            lo = x;
        else
            hi = x;
    }
    return 0.5 * (lo + hi);
}

static void test_warp(void)
{
    const int G = 14;
    fx_voronoi_warp w0, w;
    fx_voronoi_warp_init(&w0, G, 3, 0.0, 0.0);
    double x = 3.3, y = -7.1;
    fx_voronoi_warp_apply(&w0, &x, &y);
    CHECK(x == 3.3 && y == -7.1);
    for (uint32_t seed = 0; seed < 4; seed++) {
        fx_voronoi_warp_init(&w, G, seed, 0.3, 0.7 * seed);
        fx_voronoi_warp direct = w;
        if (seed & 1) /* odd seeds: the tabulated offsets (what the effect runs) */
            CHECK(fx_voronoi_warp_table(&w) == 0 && w.tab);
        double lip = 0.0, tab_err = 0.0;
        for (int k = 0; k < 2000; k++) {
            double qx = G * fx_hash_to_unit(fx_hash4(k, 1, (int32_t)seed, 9));
            double qy = G * fx_hash_to_unit(fx_hash4(k, 2, (int32_t)seed, 9));
            double a = qx, b = qy, c = qx + G, d = qy - 2 * G;
            fx_voronoi_warp_apply(&w, &a, &b);
            fx_voronoi_warp_apply(&w, &c, &d);
            CHECK(fabs((c - G) - a) < 1e-9 && fabs((d + 2 * G) - b) < 1e-9); /* periodic */
            /* continuous across the tile's border (whole wave numbers: no seam) */
            double s0 = G - 1e-7, t0 = qy, s1 = G + 1e-7, t1 = qy, r0 = qx, u0 = -1e-7, r1 = qx, u1 = 1e-7;
            fx_voronoi_warp_apply(&w, &s0, &t0);
            fx_voronoi_warp_apply(&w, &s1, &t1);
            fx_voronoi_warp_apply(&w, &r0, &u0);
            fx_voronoi_warp_apply(&w, &r1, &u1);
            CHECK(fabs(s1 - s0) < 1e-5 && fabs(t1 - t0) < 1e-5 && fabs(r1 - r0) < 1e-5 && fabs(u1 - u0) < 1e-5);
            CHECK(fabs(a - qx) <= 0.3 + 1e-12 && fabs(b - qy) <= 0.3 + 1e-12);
            /* L1 stretch of a small step (finite differences) */
            double h = 1e-5, e = qx + h, f = qy + h;
            fx_voronoi_warp_apply(&w, &e, &f);
            double s = (fabs(e - a) + fabs(f - b)) / (2 * h);
            lip = s > lip ? s : lip;
            double g = qx, q2 = qy;
            fx_voronoi_warp_apply(&direct, &g, &q2);
            tab_err = fmax(tab_err, fmax(fabs(g - a), fabs(q2 - b)));
        }
        CHECK(tab_err < 0.03 * 0.3); /* the table's bilinear offsets: within 3 % of amp of the sines */
        fx_voronoi_warp_free(&w);
        CHECK(lip <= w.lipschitz * (1 + 1e-6));
        CHECK(lip > 1.2); /* the warp does stretch */
    }
    /* the edge between (5, 7.3) and (7, 7.3) over y in 6.3 .. 8.3 */
    const double ax = 5.0, bx = 7.0, ay = 7.3, mid = 6.0;
    double dev0 = 0.0, lo = INFINITY, hi = -INFINITY, err = 0.0;
    fx_voronoi_warp_init(&w, G, 1, 0.3, 0.0);
    CHECK(fx_voronoi_warp_table(&w) == 0);
    for (int k = 0; k <= 40; k++) {
        double yy = ay - 1.0 + k * 0.05;
        double e0 = edge_x(&w0, yy, ax, bx, ay), e1 = edge_x(&w, yy, ax, bx, ay);
        dev0 = fmax(dev0, fabs(e0 - mid));
        double u = e1, v = yy;
        fx_voronoi_warp_apply(&w, &u, &v);
        err = fmax(err, fabs(u - mid)); /* x + dx(x, y) = mid on the warped edge */
        lo = fmin(lo, e1);
        hi = fmax(hi, e1);
    }
    fx_voronoi_warp_free(&w);
    CHECK(dev0 < 1e-9);       /* no warp: the straight analytic bisector */
    CHECK(err < 1e-6);        /* warped: the analytic relation holds */
    CHECK(hi - lo > 0.1);     /* and the side bends by a visible part of a cell */
    if (!(hi - lo > 0.1))
        fprintf(stderr, "warped edge spans only %g cells\n", hi - lo);
}

/* cell_scale auto's estimate against a known wave: h = A sin(2 pi (x cos t + y sin t) / L)
 * sampled on a grid whose axes are orthogonal but scaled differently and rotated in the
 * plane, normals from the analytic gradient: the estimate is L (up to the finite
 * difference: 2 sin(k l / 2) / l for k, below 0.3 % at 20+ samples per wave) for every
 * direction; a hole in the water (valid) changes nothing; a flat surface gives no estimate. */
static void test_wave_length(void)
{
    const int w = 400, h = 300; /* 4 x 3.6 m and more: 7+ waves each way (an incomplete period biases m0) */
    float *nrm = malloc((size_t)w * h * 3 * sizeof(float)), *xy = malloc((size_t)w * h * 2 * sizeof(float));
    unsigned char *valid = malloc((size_t)w * h);
    double worst = 0.0;
    const double Ls[] = {0.56, 0.33, 0.21}, As[] = {0.02, 0.03, 0.004};
    for (int c = 0; c < 3; c++)
        for (int dir = 0; dir < 4; dir++) {
            const double L = Ls[c], A = As[c], t = 0.37 + dir * 0.61, rot = 0.2 * dir;
            const double sx = 0.01 + 0.002 * dir, sy = 0.012; /* metres per texel, each axis */
            for (int y = 0; y < h; y++)
                for (int x = 0; x < w; x++) {
                    size_t i = (size_t)y * w + x;
                    double u = x * sx, v = y * sy; /* the grid's axes, rotated by rot in the plane */
                    double X = u * cos(rot) - v * sin(rot), Y = u * sin(rot) + v * cos(rot);
                    double k = 2 * M_PI / L, ph = k * (X * cos(t) + Y * sin(t));
                    double gx = A * k * cos(t) * cos(ph) + 0.03, gy = A * k * sin(t) * cos(ph) - 0.02; /* on a tilted plane */
                    double n = sqrt(gx * gx + gy * gy + 1.0);
                    nrm[3 * i] = (float)(-gx / n);
                    nrm[3 * i + 1] = (float)(-gy / n);
                    nrm[3 * i + 2] = (float)(1.0 / n);
                    xy[2 * i] = (float)X;
                    xy[2 * i + 1] = (float)Y;
                    valid[i] = !(x > 100 && x < 170 && y > 60 && y < 120); /* a hole: an island */
                }
            double est = 0.0;
            CHECK(fx_wave_length(nrm, 3, xy, valid, w, h, &est) == 0);
            CHECK(fabs(est / L - 1.0) < 0.02);
            if (!(fabs(est / L - 1.0) < 0.02))
                fprintf(stderr, "wave length %g estimated as %g\n", L, est);
            worst = fmax(worst, fabs(est / L - 1.0));
        }
    for (size_t i = 0; i < (size_t)w * h; i++) {
        nrm[3 * i] = nrm[3 * i + 1] = 0.0f;
        nrm[3 * i + 2] = 1.0f;
    }
    printf("wave length: worst relative error %.4f (12 waves)\n", worst);
    double est = -1.0;
    CHECK(fx_wave_length(nrm, 3, xy, NULL, w, h, &est) == -1 && est == -1.0); /* flat: unknown */
    free(nrm);
    free(xy);
    free(valid);
}

int main(void)
{
    fx_context *ctx = NULL;
    if (fx_context_new(&ctx, 2) != FX_OK)
        return 1;
    test_brute_equals_grid();
    test_table();
    test_lists();
    test_minkowski();
    test_warp();
    test_wave_length();
    test_world_anchoring(ctx);
    test_extremes_and_mask(ctx);
    test_lattice(ctx);
    test_in_place();
    test_position_four_channels(ctx);
    test_reference_seed_mode(ctx);
    test_reference_physical_mode(ctx);
    fx_context_free(ctx);
    return tu_finish("test_voronoi_caustics");
}
