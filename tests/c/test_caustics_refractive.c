/* voronoi_caustics mode refractive and math/caustic_map against independent references:
 *  - a flat horizontal water under a slanted sun: a shifted uniform field, gain 1;
 *  - a tilted water plane under a vertical sun: parallel refracted rays, the gain is the
 *    beam's area ratio |N.L| |T.z| / |N.T| (T from Snell's law computed here in double);
 *  - a cylindrical sinusoidal surface h = A cos(kx): the gain along x is 1 / |dX/dx| of
 *    the refraction map X(x) computed here in double (before the focal line), and the crest's
 *    gain grows as the floor nears the focal line f = n / ((n - 1) A k^2) (Snell's law);
 *  - energy: a lens-shaped bump in flat water keeps the receiver's mean (strength 1);
 *  - finite at extremes, bit-identical for 1 and 3 threads, clear errors without the view,
 *    without water in it, without its Normal pass; the stack asks for the view. */
#include "fx_effect_test.h"

#include "math/caustic_map.h"

#include <float.h>
#include <math.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

#define NV 256      /* light-view texels per side */
#define LV 2.0f     /* the light view covers x, y in [-LV, LV] */
#define SUN_Z 10.0f /* the light camera's height */
#define NF 64       /* frame pixels per side: the frame covers [-LV / 2, LV / 2] */

/* An orthographic camera at (0, -SUN_Z tan(theta), SUN_Z) looking along the sun's
 * direction (0, sin theta, -cos theta), half-size half, far 40. */
static fx_camera sun_camera(double theta, float half)
{
    fx_camera c;
    memset(&c, 0, sizeof c);
    c.size = sizeof c;
    double s = sin(theta), co = cos(theta);
    double C[3] = {0.0, -SUN_Z * s / co, SUN_Z};
    double R[3][3] = {{1, 0, 0}, {0, co, s}, {0, -s, co}}; /* rows: camera X, Y, Z in world */
    for (int r = 0; r < 3; r++) {
        for (int k = 0; k < 3; k++)
            c.world_to_camera[r * 4 + k] = (float)R[r][k];
        c.world_to_camera[r * 4 + 3] = (float)-(R[r][0] * C[0] + R[r][1] * C[1] + R[r][2] * C[2]);
    }
    c.world_to_camera[15] = 1.0f;
    float n = 0.1f, f = 40.0f;
    float proj[16] = {1 / half, 0, 0, 0, 0, 1 / half, 0, 0, 0, 0, -2 / (f - n), -(f + n) / (f - n), 0, 0, 0, 1};
    memcpy(c.projection, proj, sizeof proj);
    c.clip_start = n;
    c.clip_end = f;
    c.orthographic = 1;
    return c;
}

/* World x, y of light-view texel centre (i, j) for a vertical sun. */
static double texel_x(int i) { return -LV + (i + 0.5) * 2.0 * LV / NV; }
static double texel_y(int j) { return LV - (j + 0.5) * 2.0 * LV / NV; }

typedef double (*height_fn)(double x, double y, double *dhdx, double *dhdy);

/* The water's Depth and Normal as the light camera (theta = 0) sees a height field h. */
static void water_view(height_fn h, float *depth, float *normal)
{
    for (int j = 0; j < NV; j++)
        for (int i = 0; i < NV; i++) {
            double gx, gy, z = h(texel_x(i), texel_y(j), &gx, &gy);
            double l = sqrt(gx * gx + gy * gy + 1.0);
            size_t k = (size_t)j * NV + i;
            depth[k] = (float)(SUN_Z - z);
            normal[3 * k] = (float)(-gx / l);
            normal[3 * k + 1] = (float)(-gy / l);
            normal[3 * k + 2] = (float)(1.0 / l);
        }
}

/* Snell in double: the refracted direction of d (unit) at normal n (unit, against d). */
static void snell(const double d[3], const double n[3], double ior, double t[3])
{
    double ci = -(d[0] * n[0] + d[1] * n[1] + d[2] * n[2]), eta = 1.0 / ior;
    double ct = sqrt(1.0 - eta * eta * (1.0 - ci * ci));
    for (int k = 0; k < 3; k++)
        t[k] = eta * d[k] + (eta * ci - ct) * n[k];
}

static fx_frame *view_frame(fx_context *ctx, const fx_camera *cam)
{
    fx_frame *f = NULL;
    CHECK_OK(ctx, fx_frame_new(ctx, NV, NV, &f));
    CHECK_OK(ctx, fx_frame_set_camera(f, cam));
    return f;
}

static float sun_angle; /* the next builds' sun disc (radians) */

static fx_caustic_map build(fx_context *ctx, const fx_camera *cam, const float *depth, const float *normal,
                            float plane_z, int samples, int fresnel)
{
    fx_frame *f = view_frame(ctx, cam);
    fx_view v;
    CHECK(fx_view_init(&v, f));
    fx_caustic_input in = {NV, NV, depth, normal, 3, &v, cam->clip_end, 1.33f, plane_z, 1, samples, fresnel,
                           sun_angle};
    fx_caustic_map m;
    CHECK_OK(ctx, fx_caustic_map_build(ctx, &in, &m, "test"));
    fx_frame_free(f);
    return m;
}

/* Flat horizontal water, sun 25 deg from vertical: every gain of the interior is 1 (the
 * light lands shifted, uniformly); with Fresnel, the transmittance at 25 deg (exact). */
static void test_flat_slanted_sun(fx_context *ctx)
{
    const double theta = 25.0 * M_PI / 180.0;
    fx_camera cam = sun_camera(theta, LV);
    float *depth = malloc(NV * NV * sizeof(float)), *normal = malloc(NV * NV * 3 * sizeof(float));
    for (int j = 0; j < NV; j++)
        for (int i = 0; i < NV; i++) {
            /* the view's texel ray meets z = 0 at depth (SUN_Z + v sin theta) / cos theta */
            double v = texel_y(j);
            depth[(size_t)j * NV + i] = (float)((SUN_Z + v * sin(theta)) / cos(theta));
            normal[3 * ((size_t)j * NV + i)] = 0.0f;
            normal[3 * ((size_t)j * NV + i) + 1] = 0.0f;
            normal[3 * ((size_t)j * NV + i) + 2] = 1.0f;
        }
    double ci = cos(theta), ct = sqrt(1.0 - (1.0 - ci * ci) / (1.33 * 1.33));
    double rs = (ci - 1.33 * ct) / (ci + 1.33 * ct), rp = (1.33 * ci - ct) / (1.33 * ci + ct);
    double tf = 1.0 - 0.5 * (rs * rs + rp * rp);
    for (int fresnel = 0; fresnel < 2; fresnel++) {
        fx_caustic_map m = build(ctx, &cam, depth, normal, -1.0f, 2, fresnel);
        double want = fresnel ? tf : 1.0, worst = 0.0;
        /* the light lands 1 m x (tan theta - tan theta_t) = 0.14 m = 9 texels downwind: skip 16 */
        for (int j = 16; j < NV - 16; j++)
            for (int i = 16; i < NV - 16; i++)
                worst = fmax(worst, fabs(fx_caustic_map_node(&m, i, j) - want));
        CHECK(worst < 1e-4);
        if (!(worst < 1e-4))
            fprintf(stderr, "flat water, fresnel %d: worst |gain - %.6f| = %g\n", fresnel, want, worst);
        CHECK(m.water_nodes == NV * NV);
        fx_caustic_map_free(&m);
    }
    free(depth);
    free(normal);
}

static double tilt_a;
static double tilted_h(double x, double y, double *gx, double *gy)
{
    (void)y;
    *gx = tilt_a;
    *gy = 0.0;
    return tilt_a * x;
}

/* A tilted plane z = a x under a vertical sun: the beam's area ratio. */
static void test_tilted_plane(fx_context *ctx)
{
    fx_camera cam = sun_camera(0.0, LV);
    float *depth = malloc(NV * NV * sizeof(float)), *normal = malloc(NV * NV * 3 * sizeof(float));
    const double as[] = {0.1, 0.3, -0.5};
    for (int k = 0; k < 3; k++) {
        tilt_a = as[k];
        water_view(tilted_h, depth, normal);
        double l = sqrt(1.0 + tilt_a * tilt_a), n[3] = {-tilt_a / l, 0.0, 1.0 / l}, d[3] = {0, 0, -1}, t[3];
        snell(d, n, 1.33, t);
        double ndt = n[0] * t[0] + n[2] * t[2];
        double want = (1.0 / l) * fabs(t[2]) / fabs(ndt);
        /* the floor well below the plane's lowest point in the view */
        fx_caustic_map m = build(ctx, &cam, depth, normal, -1.5f, 2, 0);
        double worst = 0.0;
        for (int j = 40; j < NV - 40; j++)
            for (int i = 40; i < NV - 40; i++)
                worst = fmax(worst, fabs(fx_caustic_map_node(&m, i, j) - want));
        CHECK(worst < 1e-4 && fabs(want - 1.0) > 0.002);
        if (getenv("DBG") || !(worst < 1e-4))
            fprintf(stderr, "tilted plane a = %g: want %.5f, worst error %g\n", tilt_a, want, worst);
        fx_caustic_map_free(&m);
    }
    free(depth);
    free(normal);
}

#define SA 0.05  /* amplitude, m */
#define SK (2.0 * M_PI / 1.0) /* 1 m period: 64 texels */

static double sine_h(double x, double y, double *gx, double *gy)
{
    (void)y;
    *gx = -SA * SK * sin(SK * x);
    *gy = 0.0;
    return SA * cos(SK * x);
}

/* Where the ray entering the water at x lands on the floor z = -depth (vertical sun). */
static double land_x(double x, double depth)
{
    double gx, gy, z = sine_h(x, 0.0, &gx, &gy), l = sqrt(1.0 + gx * gx);
    double n[3] = {-gx / l, 0.0, 1.0 / l}, d[3] = {0, 0, -1}, t[3];
    snell(d, n, 1.33, t);
    return x + t[0] * (z + depth) / -t[2];
}

/* The sinusoid: the gain along a row is 1 / |dX/dx| at the preimage of each texel's floor
 * point (one-to-one before the focal line), and the crest's gain follows Snell's focal
 * length: 1 / (1 - (depth + A) / f) paraxially, the exact derivative measured here. */
static void test_sinusoid(fx_context *ctx)
{
    fx_camera cam = sun_camera(0.0, LV);
    float *depth = malloc(NV * NV * sizeof(float)), *normal = malloc(NV * NV * 3 * sizeof(float));
    water_view(sine_h, depth, normal);
    const double f = 1.33 / (0.33 * SA * SK * SK); /* paraxial focal length below the crest */
    const double fracs[] = {0.4, 0.6, 0.75};
    double last_crest = 1.0;
    for (int k = 0; k < 3; k++) {
        double dep = fracs[k] * f - SA; /* the floor fracs f below the crest */
        fx_caustic_map m = build(ctx, &cam, depth, normal, (float)-dep, 4, 0);
        double worst = 0.0, crest = 0.0, want_crest = 0.0;
        const int row = NV / 2;
        for (int i = 24; i < NV - 24; i++) {
            double X = texel_x(i), lo = X - 0.5, hi = X + 0.5;
            for (int it = 0; it < 60; it++) { /* X(x) increases: bisection */
                double mid = 0.5 * (lo + hi);
                if (land_x(mid, dep) < X)
                    lo = mid;
                else
                    hi = mid;
            }
            double x = 0.5 * (lo + hi), e = 1e-5;
            double want = 2.0 * e / fabs(land_x(x + e, dep) - land_x(x - e, dep));
            double got = fx_caustic_map_node(&m, i, row);
            worst = fmax(worst, fabs(got - want) / want);
            if (fabs(X - 0.0) < 1e-3 + LV / NV) { /* the crest at x = 0 */
                crest = fmax(crest, got);
                want_crest = fmax(want_crest, want);
            }
        }
        double paraxial = 1.0 / (1.0 - fracs[k]);
        CHECK(worst < 0.03);
        CHECK(fabs(crest - want_crest) / want_crest < 0.03);
        CHECK(fabs(want_crest - paraxial) / paraxial < 0.1); /* the reference agrees with Snell's focal length */
        CHECK(crest > last_crest);
        if (getenv("DBG") || !(worst < 0.03) || !(fabs(crest - want_crest) / want_crest < 0.03))
            fprintf(stderr, "sinusoid at %.2f f: worst relative error %.4f, crest %.3f want %.3f (paraxial %.3f)\n",
                    fracs[k], worst, crest, want_crest, paraxial);
        last_crest = crest;
        fx_caustic_map_free(&m);
    }
    /* a sun disc of 0.1 rad: the floor 0.75 f - A below the crest sees each point of the
     * water as a disc of radius (0.75 f) tan(0.05 / 1.33) = 12 cm = 8 texels: the crest's
     * focus spreads (lower), the row's mean stays */
    sun_angle = 0.1f;
    double dep = 0.75 * f - SA, sum[2] = {0, 0}, peak[2] = {0, 0};
    for (int k = 0; k < 2; k++) {
        if (k == 1)
            sun_angle = 0.0f;
        fx_caustic_map m = build(ctx, &cam, depth, normal, (float)-dep, 4, 0);
        for (int i = 32; i < NV - 32; i++) {
            sum[k] += fx_caustic_map_node(&m, i, NV / 2);
            peak[k] = fmax(peak[k], fx_caustic_map_node(&m, i, NV / 2));
        }
        CHECK(k == 1 || fabs(m.blur_sigma - 0.5 * dep * tan(0.05 / 1.33) / (2.0 * LV / NV)) < 0.02); /* the mean drop: dep */
        fx_caustic_map_free(&m);
    }
    CHECK(peak[0] < 0.8 * peak[1] && fabs(sum[0] - sum[1]) < 0.01 * sum[1]);
    if (getenv("DBG") || !(peak[0] < 0.8 * peak[1] && fabs(sum[0] - sum[1]) < 0.01 * sum[1]))
        fprintf(stderr, "sun disc: peak %.3f -> %.3f, row sum %.2f -> %.2f\n", peak[1], peak[0], sum[1], sum[0]);
    free(depth);
    free(normal);
}

/* ---- through the effect ------------------------------------------------------------- */

static double bump_h(double x, double y, double *gx, double *gy)
{
    /* a Gaussian lens 0.25 m wide, 12 cm high, in flat water */
    double s2 = 0.25 * 0.25, e = 0.12 * exp(-(x * x + y * y) / (2 * s2));
    *gx = -x / s2 * e;
    *gy = -y / s2 * e;
    return e;
}

/* The floor (z = -1) seen straight down over [-LV / 2, LV / 2], grey, with its Position
 * pass, and the water view (written to an EXR) of height field h; normal_pass 0: without
 * the Normal pass; h NULL: no water at all (background depth). */
static float frame_z = -1.0f; /* the masked pixels' height */
static double frame_theta, frame_shift_y; /* the frame camera's slant; the positions' y shift */

static fx_frame *floor_with_water(fx_context *ctx, height_fn h, int normal_pass, const char *name)
{
    float *rgba = malloc(NF * NF * 4 * sizeof(float)), *pos = malloc(NF * NF * 3 * sizeof(float));
    for (int j = 0; j < NF; j++)
        for (int i = 0; i < NF; i++) {
            size_t k = (size_t)j * NF + i;
            rgba[4 * k] = 0.5f;
            rgba[4 * k + 1] = 0.4f;
            rgba[4 * k + 2] = 0.3f;
            rgba[4 * k + 3] = 1.0f;
            pos[3 * k] = (float)(-LV / 2 + (i + 0.5) * LV / NF);
            pos[3 * k + 1] = (float)(LV / 2 - (j + 0.5) * LV / NF + frame_shift_y);
            pos[3 * k + 2] = frame_z;
        }
    fx_frame *f = et_frame(ctx, NF, NF, rgba);
    CHECK_OK(ctx, fx_frame_add_pass(f, "Position", 3, pos));
    fx_camera cam = sun_camera(frame_theta, LV / 2);
    CHECK_OK(ctx, fx_frame_set_camera(f, &cam));
    float *depth = malloc(NV * NV * sizeof(float)), *normal = malloc(NV * NV * 3 * sizeof(float));
    if (h) {
        water_view(h, depth, normal);
    } else {
        for (int k = 0; k < NV * NV; k++) {
            depth[k] = 1e10f;
            normal[3 * k] = normal[3 * k + 1] = normal[3 * k + 2] = 0.0f;
        }
    }
    char path[600];
    snprintf(path, sizeof path, "%s/%s.exr", tu_tmpdir("caustics_refractive"), name);
    fx_frame *v = NULL;
    CHECK_OK(ctx, fx_frame_new(ctx, NV, NV, &v));
    CHECK_OK(ctx, fx_frame_add_pass(v, "Depth", 1, depth));
    if (normal_pass)
        CHECK_OK(ctx, fx_frame_add_pass(v, "Normal", 3, normal));
    CHECK_OK(ctx, fx_frame_write_exr(v, path, NULL));
    fx_frame_free(v);
    fx_camera sun = sun_camera(0.0, LV);
    CHECK_OK(ctx, fx_frame_set_aux_view(f, "water:Water", path, &sun));
    free(rgba);
    free(pos);
    free(depth);
    free(normal);
    return f;
}

#define REFRACTIVE                                                                                          \
    "\"mode\": \"refractive\", \"strength\": 1, \"tint\": [1, 1, 1], \"fresnel\": false, \"apply\": \"combined\""

/* A lens in flat water focuses light into a bright spot and darkens its surroundings,
 * and the receiver's mean stays: what the lens takes it gives back. */
static void test_energy(fx_context *ctx)
{
    fx_frame *f = floor_with_water(ctx, bump_h, 1, "bump");
    float *o = et_run_effect(ctx, "voronoi_caustics", f, REFRACTIVE, NULL);
    CHECK(o != NULL);
    if (o) {
        double sum = 0.0, most = 0.0, least = 1e9;
        for (int k = 0; k < NF * NF; k++) {
            double g = o[4 * k] / 0.5;
            sum += g;
            most = fmax(most, g);
            least = fmin(least, g);
            CHECK(fabsf(o[4 * k + 1] / o[4 * k] - 0.8f) < 1e-5f); /* one gain for every channel */
        }
        double mean = sum / (NF * NF);
        CHECK(fabs(mean - 1.0) < 0.002 && most > 2.5 && least < 0.95);
        if (!(fabs(mean - 1.0) < 0.002 && most > 2.5 && least < 0.95))
            fprintf(stderr, "lens: mean gain %.5f (want 1), max %.3f, min %.3f\n", mean, most, least);
    }
    free(o);
    fx_frame_free(f);
}

/* 1 and 3 threads give the same bits; finite at extremes (ior 4, grazing normals, NaN). */
static void test_threads_extremes(void)
{
    float *out[2] = {NULL, NULL};
    for (int t = 0; t < 2; t++) {
        fx_context *c = NULL;
        CHECK_OK(c, fx_context_new(&c, t ? 3 : 1));
        fx_frame *f = floor_with_water(c, sine_h, 1, t ? "sine3" : "sine1");
        out[t] = et_run_effect(c, "voronoi_caustics", f, REFRACTIVE ", \"refract_samples\": 3", NULL);
        fx_frame_free(f);
        fx_context_free(c);
    }
    CHECK(out[0] && out[1] && memcmp(out[0], out[1], NF * NF * 4 * sizeof(float)) == 0);
    free(out[0]);
    free(out[1]);

    fx_context *ctx = NULL;
    CHECK_OK(ctx, fx_context_new(&ctx, 2));
    const char *cases[] = {"\"mode\": \"refractive\", \"apply\": \"combined\", \"ior\": 4, \"strength\": 100",
                           "\"mode\": \"refractive\", \"apply\": \"combined\", \"ior\": 1, \"refract_step\": 16",
                           "\"mode\": \"refractive\", \"apply\": \"combined\", \"refract_samples\": 16, "
                           "\"strength\": 100"};
    for (int k = 0; k < 3; k++) {
        tilt_a = 30.0; /* nearly vertical water */
        fx_frame *f = floor_with_water(ctx, k == 2 ? tilted_h : sine_h, 1, "extreme");
        float *o = et_run_effect(ctx, "voronoi_caustics", f, cases[k], NULL);
        int finite = o != NULL;
        for (int i = 0; o && i < NF * NF * 4; i++)
            finite &= isfinite(o[i]) && o[i] >= 0.0f;
        CHECK(finite);
        free(o);
        fx_frame_free(f);
    }
    fx_context_free(ctx);
}

/* The map itself with hostile views: NaN normals and depths, zero normals, a floor above
 * the water, a sun along the horizon: finite gains in [0, FX_CAUSTIC_GAIN_MAX]. */
static void test_hostile_map(fx_context *ctx)
{
    float *depth = malloc(NV * NV * sizeof(float)), *normal = malloc(NV * NV * 3 * sizeof(float));
    water_view(sine_h, depth, normal);
    for (int k = 0; k < NV * NV; k += 7) {
        depth[k] = k % 2 ? NAN : -1.0f;
        normal[3 * k + (k % 3)] = k % 5 ? INFINITY : NAN;
    }
    for (int k = 3; k < NV * NV; k += 11)
        normal[3 * k] = normal[3 * k + 1] = normal[3 * k + 2] = 0.0f;
    const float planes[] = {-1.0f, 5.0f, -1e30f};
    for (int p = 0; p < 3; p++) {
        fx_camera cam = sun_camera(p == 2 ? 1.5707 : 0.3, LV);
        fx_caustic_map m = build(ctx, &cam, depth, normal, planes[p], 2, 1);
        int ok = m.gain != NULL;
        for (int k = 0; ok && k < m.nx * m.ny; k++)
            ok &= m.gain[k] >= 0.0f && m.gain[k] <= FX_CAUSTIC_GAIN_MAX;
        CHECK(ok);
        fx_caustic_map_free(&m);
    }
    free(depth);
    free(normal);
}

/* apply sun_diffuse: the gain scales the sun's direct diffuse DiffCol E N.L / pi only; the
 * rest of the pixel (sky, bounce) stays. Here the floor is 0.5 sun + 0.2 sky, DiffCol 0.5,
 * a vertical sun of energy pi: out - 0.7 is 0.5 (g - 1), g from apply combined on 0.5. */
static void test_sun_diffuse(fx_context *ctx)
{
    fx_frame *f = floor_with_water(ctx, sine_h, 1, "sun_diffuse");
    float *rgba = malloc(NF * NF * 4 * sizeof(float)), *dc = malloc(NF * NF * 3 * sizeof(float));
    float *nrm = malloc(NF * NF * 3 * sizeof(float));
    for (int k = 0; k < NF * NF; k++) {
        for (int c = 0; c < 3; c++) {
            rgba[4 * k + c] = 0.7f;
            dc[3 * k + c] = 0.5f;
            nrm[3 * k + c] = c == 2 ? 1.0f : 0.0f;
        }
        rgba[4 * k + 3] = 1.0f;
    }
    float *comb = et_run_effect(ctx, "voronoi_caustics", f, REFRACTIVE, NULL); /* Combined 0.5, 0.4, 0.3 */
    float *cd = NULL;
    int cc = 0;
    CHECK_OK(ctx, fx_frame_pass(f, "Combined", &cd, &cc));
    memcpy(cd, rgba, NF * NF * 4 * sizeof(float));
    CHECK_OK(ctx, fx_frame_add_pass(f, "DiffCol", 3, dc));
    CHECK_OK(ctx, fx_frame_add_pass(f, "Normal", 3, nrm));
    const char *sun = "{\"lights\": [{\"name\": \"Sun\", \"type\": \"SUN\", \"position\": [0, 0, 10], "
                      "\"direction\": [0, 0, -1], \"color\": [1, 1, 1], \"energy\": 3.14159265, \"angle\": 0}]}";
    const char *params = "\"mode\": \"refractive\", \"strength\": 1, \"tint\": [1, 1, 1], \"fresnel\": false";
    fx_stack *s = NULL;
    char buf[512];
    snprintf(buf, sizeof buf, "{\"version\":1,\"effects\":[{\"effect\":\"voronoi_caustics\",\"params\":{%s}}]}",
             params);
    CHECK_OK(ctx, fx_stack_new(ctx, &s));
    CHECK_OK(ctx, fx_stack_load_json(s, buf));
    fx_frame *out = NULL;
    CHECK_FAIL(ctx, fx_stack_run(s, f, &out), FX_ERR_NO_LIGHTS, "");
    CHECK_OK(ctx, fx_frame_apply_sidecar(f, sun));
    float *o = et_run(ctx, s, f);
    double worst = 0.0, spread = 0.0;
    for (int k = 0; o && comb && k < NF * NF; k++) {
        double g = comb[4 * k] / 0.5;
        worst = fmax(worst, fabs((o[4 * k + 1] - 0.7) - 0.5 * (g - 1.0)));
        spread = fmax(spread, fabs(g - 1.0));
    }
    CHECK(o && comb && worst < 1e-5 && spread > 0.3);
    if (!(worst < 1e-5 && spread > 0.3))
        fprintf(stderr, "sun_diffuse: worst %g, gain spread %g\n", worst, spread);
    fx_stack_free(s);
    free(o);
    free(comb);
    free(rgba);
    free(dc);
    free(nrm);
    fx_frame_free(f);
}

/* receiver_depth: the masked pixels are the water's surface (z = 0), the floor lies 1
 * below and an orthographic camera looks down slanted by 0.5 rad: each pixel shows the
 * floor where its ray, refracted (Snell, here in double), meets z = -1, a shift in y. The
 * output equals that of the floor itself masked at those points. */
static void test_receiver_depth(fx_context *ctx)
{
    double d[3] = {0.0, sin(0.5), -cos(0.5)}, n[3] = {0.0, 0.0, 1.0}, t[3];
    snell(d, n, 1.33, t);
    frame_theta = 0.5;
    frame_z = 0.0f;
    fx_frame *f = floor_with_water(ctx, bump_h, 1, "surface_seen");
    float *b = et_run_effect(ctx, "voronoi_caustics", f, REFRACTIVE ", \"receiver_depth\": 1", NULL);
    float *c = et_run_effect(ctx, "voronoi_caustics", f, REFRACTIVE, NULL); /* the floor at the surface */
    fx_frame_free(f);
    frame_z = -1.0f;
    frame_shift_y = t[1] / -t[2];
    f = floor_with_water(ctx, bump_h, 1, "floor_seen");
    float *a = et_run_effect(ctx, "voronoi_caustics", f, REFRACTIVE, NULL);
    fx_frame_free(f);
    frame_theta = frame_shift_y = 0.0;
    double worst = 0.0, moved = 0.0;
    for (int k = 0; a && b && c && k < NF * NF * 4; k++) {
        worst = fmax(worst, fabs(a[k] - b[k]));
        moved = fmax(moved, fabs(a[k] - c[k]));
    }
    CHECK(a && b && c && worst < 2e-4 && moved > 0.05);
    if (getenv("DBG") || !(worst < 2e-4 && moved > 0.05))
        fprintf(stderr, "receiver_depth: worst %g, without it %g\n", worst, moved);
    free(a);
    free(b);
    free(c);
}

static void test_errors_and_needs(fx_context *ctx)
{
    /* no view at all */
    float rgba[4 * 4 * 4] = {0};
    fx_frame *bare = et_frame(ctx, 4, 4, rgba);
    float pos[4 * 4 * 3] = {0};
    fx_frame_add_pass(bare, "Position", 3, pos);
    fx_stack *s = NULL;
    CHECK_OK(ctx, fx_stack_new(ctx, &s));
    CHECK_OK(ctx, fx_stack_load_json(
                      s, "{\"version\":1,\"effects\":[{\"effect\":\"voronoi_caustics\",\"params\":{\"mode\":"
                         "\"refractive\",\"water\":\"Pool water\",\"apply\":\"combined\"}}]}"));
    fx_frame *out = NULL;
    CHECK_FAIL(ctx, fx_stack_run(s, bare, &out), FX_ERR_NO_AUX_VIEW, "water:Pool water");
    CHECK(tu_contains(fx_context_error(ctx), "material 'Pool water'"));
    char *req = NULL;
    CHECK_OK(ctx, fx_stack_required_aux_views(s, &req));
    CHECK(req && strcmp(req, "{\"aux_views\":[{\"name\":\"water:Pool water\",\"kind\":\"water\"}]}") == 0);
    if (req && !tu_contains(req, "water:Pool water"))
        fprintf(stderr, "required aux views: %s\n", req);
    fx_free(req);
    CHECK_OK(ctx, fx_stack_set_enum(s, 0, "mode", "physical"));
    CHECK_OK(ctx, fx_stack_required_aux_views(s, &req));
    CHECK(req && strcmp(req, "{\"aux_views\":[]}") == 0);
    fx_free(req);
    CHECK_OK(ctx, fx_stack_set_string(s, 0, "water", "")); /* not read by the Voronoi modes */
    CHECK_FAIL(ctx, fx_stack_set_enum(s, 0, "mode", "refractive"), FX_ERR_BAD_PARAM, "water");
    fx_stack_free(s);
    fx_frame_free(bare);

    /* a view without water, a view without its Normal pass */
    fx_frame *f = floor_with_water(ctx, NULL, 1, "dry");
    CHECK_OK(ctx, fx_stack_new(ctx, &s));
    CHECK_OK(ctx, fx_stack_load_json(s, "{\"version\":1,\"effects\":[{\"effect\":\"voronoi_caustics\",\"params\":{"
                                        "\"mode\":\"refractive\",\"apply\":\"combined\"}}]}"));
    CHECK_FAIL(ctx, fx_stack_run(s, f, &out), FX_ERR_MISSING_PASS, "shows no water");
    CHECK(tu_contains(fx_context_error(ctx), "'Water'"));
    fx_frame_free(f);
    f = floor_with_water(ctx, sine_h, 0, "no_normal");
    CHECK_FAIL(ctx, fx_stack_run(s, f, &out), FX_ERR_MISSING_PASS, "has no Normal pass");
    fx_frame_free(f);
    fx_stack_free(s);
}

int main(void)
{
    fx_context *ctx = NULL;
    fx_context_new(&ctx, 2);
    test_flat_slanted_sun(ctx);
    test_tilted_plane(ctx);
    test_sinusoid(ctx);
    test_energy(ctx);
    test_threads_extremes();
    test_hostile_map(ctx);
    test_errors_and_needs(ctx);
    test_sun_diffuse(ctx);
    test_receiver_depth(ctx);
    fx_context_free(ctx);
    return tu_finish("test_caustics_refractive");
}
