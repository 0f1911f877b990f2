/* ssr_mirror's hit confidence (issue 27): a screen-space hit is trusted only as far as its
 * evidence goes, and faded into the fallback (the probe, or environment_color here, whose
 * value is exact) by it. Synthetic frames ray-cast here from a small analytic scene: a
 * 6 x 6 x 3 m room whose +Y wall (y = 3) is the mirror (IndexMA 1), boxes and spheres in
 * front of it, the camera at (-1.2, -1.5, 1.5) looking along +Y.
 *  - thin post: a mirror pixel whose reflected ray passes behind a 2 cm post (0.15 m behind
 *    its front at the post's middle, 5 cm at its silhouette: within the 0.35 m thickness, so
 *    the old tracer took the post's colour) takes the fallback exactly; no mirror pixel
 *    takes the post's colour where its exact reflection is not the post (the old tracer:
 *    a band of 286 pixels);
 *  - back face: a surface whose Normal pass faces along the ray (n . r = +0.15) is not a
 *    hit (the old test let up to +0.25 through). A Normal pass that disagrees with the
 *    depth also tilts the tangent plane the thickness term extends, so here that term
 *    rejects the hit too: without the back-face term this check still passes (checked by
 *    a temporary edit); it fails on the old tracer;
 *  - a genuine hit on the floor keeps its colour (the confidence is 1: no false fades);
 *  - a ray leaving the screen takes the fallback exactly; hits in the border band fade;
 *  - smear scene: a sphere and a block just in front of the mirror (rays pass behind their
 *    silhouettes) with an analytic probe: with the texture fallback no mirror pixel shows
 *    a foreground object's colour where its exact reflection is not that object (the old
 *    tracer drew 30 such pixels: the sphere and block smeared), with the probe under 1 %
 *    (its single viewpoint's parallax), and the probe's error is under half the texture's;
 *  - bit-identical output for 1, 2 and 3 threads. */
#include "fx_effect_test.h"
#include "math/panorama.h"

#include <math.h>

#define PI 3.14159265358979

enum { FW = 96, FH = 54 };
static const double CAM[3] = { -1.2, -1.5, 1.5 };
static const double LO[3] = { -3, -3, 0 }, HI[3] = { 3, 3, 3 };
static const float ENV[3] = { 0.2f, 0.4f, 0.6f };

typedef struct prim {
    int sphere;          /* 0: box lo..hi; 1: sphere c, r (lo = centre, hi[0] = radius) */
    double lo[3], hi[3];
    float col[3];
} prim;

typedef struct world {
    prim p[4];
    int n;
    int flip_floor;      /* the floor's Normal pass written as `floor_normal` (a back face) */
    int open_top;        /* no ceiling: the sky (background depth) above the room */
    double floor_normal[3];
} world;

/* Nearest hit of o + t d (t > 1e-6): t, unit normal, colour, and whether it is the mirror. */
static double cast(const world *wd, const double o[3], const double d[3], double nrm[3], float col[3], int *mirror)
{
    double best = 1e30;
    *mirror = 0;
    nrm[0] = nrm[1] = nrm[2] = 0;
    col[0] = col[1] = col[2] = 0;
    /* the room from inside */
    for (int a = 0; a < 3; a++) {
        if (fabs(d[a]) < 1e-12 || (a == 2 && d[a] > 0 && wd->open_top))
            continue;
        double t = ((d[a] > 0 ? HI[a] : LO[a]) - o[a]) / d[a];
        if (wd->open_top && o[2] + t * d[2] > HI[2])
            continue; /* no wall above the room's top */
        if (t > 1e-6 && t < best) {
            best = t;
            double q[3] = { o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2] };
            nrm[0] = nrm[1] = nrm[2] = 0;
            nrm[a] = d[a] > 0 ? -1 : 1;
            *mirror = a == 0 && d[a] < 0;
            /* smooth gradients per wall, none near the post's magenta */
            double g = 0.55 + 0.35 * sin(1.3 * q[0] + 0.7) * cos(0.9 * q[1] - 0.4) * cos(1.1 * q[2]);
            int wall = a * 2 + (d[a] > 0);
            static const float base[6][3] = { { 0.3f, 0.7f, 0.3f }, { 0.7f, 0.5f, 0.3f }, { 0.6f, 0.6f, 0.6f },
                                              { 0.1f, 0.1f, 0.1f }, { 0.8f, 0.8f, 0.75f }, { 0.9f, 0.9f, 0.9f } };
            for (int k = 0; k < 3; k++)
                col[k] = (float)(base[wall][k] * g);
        }
    }
    for (int i = 0; i < wd->n; i++) {
        const prim *p = &wd->p[i];
        double t = 1e30, nn[3] = { 0, 0, 0 };
        if (p->sphere) {
            double oc[3] = { o[0] - p->lo[0], o[1] - p->lo[1], o[2] - p->lo[2] }, r = p->hi[0];
            double b = oc[0] * d[0] + oc[1] * d[1] + oc[2] * d[2];
            double c = oc[0] * oc[0] + oc[1] * oc[1] + oc[2] * oc[2] - r * r, disc = b * b - c;
            if (disc > 0) {
                double t0 = -b - sqrt(disc), t1 = -b + sqrt(disc);
                t = t0 > 1e-6 ? t0 : t1 > 1e-6 ? t1 : 1e30;
                for (int k = 0; k < 3; k++)
                    nn[k] = (o[k] + t * d[k] - p->lo[k]) / r;
            }
        } else {
            double tn = -1e30, tf = 1e30;
            int an = 0, af = 0;
            for (int a = 0; a < 3; a++) {
                if (fabs(d[a]) < 1e-12) {
                    if (o[a] < p->lo[a] || o[a] > p->hi[a])
                        tn = 1e30;
                    continue;
                }
                double t0 = (p->lo[a] - o[a]) / d[a], t1 = (p->hi[a] - o[a]) / d[a];
                if (t0 > t1) {
                    double s = t0;
                    t0 = t1, t1 = s;
                }
                if (t0 > tn)
                    tn = t0, an = a;
                if (t1 < tf)
                    tf = t1, af = a;
            }
            if (tn <= tf && tf > 1e-6) {
                int a = tn > 1e-6 ? an : af;
                t = tn > 1e-6 ? tn : tf;
                nn[a] = d[a] > 0 ? -1 : 1;
            }
        }
        if (t < best) {
            best = t;
            memcpy(nrm, nn, sizeof nn);
            memcpy(col, p->col, sizeof p->col);
            *mirror = 0;
        }
    }
    return best;
}

/* Camera: Blender's, looking along +Y (rotation X 90 deg): camera to world x -> x, y -> z,
 * z -> -y. 60 deg vertical field of view. */
static void cam_ray(double px, double py, double d[3])
{
    double fy = tan(30 * PI / 180), asp = (double)FW / FH;
    double v[3] = { (px / FW * 2 - 1) * fy * asp, (1 - py / FH * 2) * fy, -1 };
    double r[3] = { v[0], -v[2], v[1] }, l = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
    for (int i = 0; i < 3; i++)
        d[i] = r[i] / l;
}

static void cam_w2c(const double pos[3], float m[16])
{
    /* world_to_camera = R^T T(-pos); R's columns: x, z-up -> camera y, -y -> camera z */
    static const double R[9] = { 1, 0, 0, 0, 0, -1, 0, 1, 0 };
    et_world_to_camera(R, pos, m);
}

/* The frame of world wd; want: the exact one-bounce reflection of each mirror pixel (and
 * whether it is a primitive's colour: want_prim, 1 + its index), mirror: IndexMA. */
static fx_frame *make_frame(fx_context *ctx, const world *wd, float *want, int *want_prim)
{
    size_t n = (size_t)FW * FH;
    float *rgba = calloc(n * 4, sizeof(float)), *dep = calloc(n, sizeof(float));
    float *nor = calloc(n * 3, sizeof(float)), *ima = calloc(n, sizeof(float));
    for (int y = 0; y < FH; y++)
        for (int x = 0; x < FW; x++) {
            size_t i = (size_t)y * FW + x;
            double d[3], nn[3];
            cam_ray(x + 0.5, y + 0.5, d);
            int mir;
            float col[3];
            double t = cast(wd, CAM, d, nn, col, &mir);
            double p[3] = { CAM[0] + t * d[0], CAM[1] + t * d[1], CAM[2] + t * d[2] };
            dep[i] = t > 1e29 ? 1e10f : (float)(p[1] - CAM[1]); /* planar: the camera looks along +Y */
            if (t > 1e29)
                col[0] = 0.3f, col[1] = 0.5f, col[2] = 0.9f; /* the sky */
            if (wd->flip_floor && nn[2] > 0.5 && p[2] < 1e-6)
                memcpy(nn, wd->floor_normal, sizeof nn);
            for (int k = 0; k < 3; k++)
                nor[i * 3 + k] = (float)nn[k];
            rgba[i * 4 + 3] = 1;
            if (mir) {
                ima[i] = 1;
                rgba[i * 4] = rgba[i * 4 + 1] = rgba[i * 4 + 2] = 0.1f;
                double r[3] = { -d[0], d[1], d[2] }, n2[3];
                int m2;
                float c2[3];
                double t2 = cast(wd, p, r, n2, c2, &m2);
                if (want)
                    memcpy(want + i * 3, c2, sizeof c2);
                if (want_prim) {
                    want_prim[i] = 0;
                    for (int k = 0; k < wd->n; k++) {
                        double q[3] = { p[0] + t2 * r[0], p[1] + t2 * r[1], p[2] + t2 * r[2] };
                        const prim *pr = &wd->p[k];
                        int in = 1;
                        if (pr->sphere) {
                            double dd = 0;
                            for (int a = 0; a < 3; a++)
                                dd += (q[a] - pr->lo[a]) * (q[a] - pr->lo[a]);
                            in = fabs(sqrt(dd) - pr->hi[0]) < 1e-6;
                        } else {
                            for (int a = 0; a < 3; a++)
                                in &= q[a] > pr->lo[a] - 1e-6 && q[a] < pr->hi[a] + 1e-6;
                        }
                        if (in)
                            want_prim[i] = k + 1;
                    }
                }
            } else {
                memcpy(rgba + i * 4, col, sizeof col);
            }
        }
    fx_frame *f = et_frame(ctx, FW, FH, rgba);
    fx_camera c;
    float cw[16];
    cam_w2c(CAM, cw);
    et_perspective(&c, cw, tan(30 * PI / 180), FW, FH, 0.1, 100.0);
    CHECK_OK(ctx, fx_frame_add_pass(f, "Depth", 1, dep));
    CHECK_OK(ctx, fx_frame_add_pass(f, "Normal", 3, nor));
    CHECK_OK(ctx, fx_frame_add_pass(f, "IndexMA", 1, ima));
    CHECK_OK(ctx, fx_frame_set_camera(f, &c));
    free(rgba), free(dep), free(nor), free(ima);
    return f;
}

/* The world point of mirror pixel (x, y) and its reflected ray. */
static void mirror_ray(int x, int y, double p[3], double r[3])
{
    double d[3];
    cam_ray(x + 0.5, y + 0.5, d);
    double t = (LO[0] - CAM[0]) / d[0];
    for (int k = 0; k < 3; k++)
        p[k] = CAM[k] + t * d[k];
    r[0] = -d[0], r[1] = d[1], r[2] = d[2];
}

/* ssr_mirror on the mirror, sharp, reflectivity 1, one bounce, fallback environment ENV
 * (its colour is exact where the confidence is 0), `extra` more parameters. */
static float *run_env(fx_context *ctx, const fx_frame *f, const char *extra)
{
    char params[512];
    snprintf(params, sizeof params,
             "\"fallback\": \"environment\", \"environment_color\": [%.9g, %.9g, %.9g], \"bounces\": 1%s%s",
             ENV[0], ENV[1], ENV[2], extra ? ", " : "", extra ? extra : "");
    return et_run_effect(ctx, "ssr_mirror", f, params, "{\"material_index\": 1}");
}

static double dist3(const float *a, const float *b)
{
    return fabs(a[0] - b[0]) + fabs(a[1] - b[1]) + fabs(a[2] - b[2]);
}

/* A post 2 cm deep stands where pixel (PX, PY)'s reflected ray passes 0.15 m behind its
 * front (planar depth: the post's front face is 0.15 m nearer the camera than the ray
 * there), 0.7 m out from the mirror: within the default thickness (0.35 m) of the post's
 * front, so the old tracer's slab test took the post; the ray misses it (exactly). */
enum { PX = 6, PY = 27 };
static const float MAGENTA[3] = { 1.0f, 0.0f, 1.0f };

static void post_world(world *wd)
{
    memset(wd, 0, sizeof *wd);
    double m[3], r[3];
    mirror_ray(PX, PY, m, r);
    double t = (-2.3 - m[0]) / r[0]; /* P.x = -2.3: 0.7 m out from the mirror, 0.3 m before the back wall */
    double P[3] = { m[0] + t * r[0], m[1] + t * r[1], m[2] + t * r[2] };
    double yp = P[1] - 0.15;
    /* where the camera's line of sight to P crosses the post's front face */
    double s = (yp - CAM[1]) / (P[1] - CAM[1]);
    double qx = CAM[0] + s * (P[0] - CAM[0]);
    prim post = { 0, { qx - 0.12, yp, 0.0 }, { qx + 0.12, yp + 0.02, 3.0 }, { 1.0f, 0.0f, 1.0f } };
    wd->p[0] = post;
    wd->n = 1;
}

static void test_thin_post(fx_context *ctx)
{
    world wd;
    post_world(&wd);
    float *want = calloc((size_t)FW * FH * 3, sizeof(float));
    int *wprim = calloc((size_t)FW * FH, sizeof(int));
    fx_frame *f = make_frame(ctx, &wd, want, wprim);
    size_t i = (size_t)PY * FW + PX;
    CHECK(wprim[i] == 0); /* the exact reflection misses the post (the scene is right) */
    float *o = run_env(ctx, f, NULL);
    CHECK(o != NULL);
    if (o) {
        printf("thin post: pixel (%d, %d) reflects (%.3f %.3f %.3f); the exact reflection (%.3f %.3f %.3f), "
               "the post (1 0 1), the fallback (%.1f %.1f %.1f)\n",
               PX, PY, o[i * 4], o[i * 4 + 1], o[i * 4 + 2], want[i * 3], want[i * 3 + 1], want[i * 3 + 2], ENV[0],
               ENV[1], ENV[2]);
        /* hand-worked: the ray passes behind the post: confidence 0, the fallback exactly */
        CHECK(dist3(o + i * 4, ENV) < 1e-5);
        /* and nowhere on the mirror the post's colour where the exact reflection is not the
         * post: no smear of its silhouette along the rays that pass behind it */
        int smear = 0, mirror = 0;
        float *ima;
        int c;
        fx_frame_pass(f, "IndexMA", &ima, &c);
        for (size_t k = 0; k < (size_t)FW * FH; k++)
            if (ima[k] == 1) {
                mirror++;
                smear += wprim[k] == 0 && dist3(o + k * 4, MAGENTA) < 0.5 * dist3(want + k * 3, MAGENTA);
            }
        printf("thin post: %d of %d mirror pixels take the post's colour where their reflection is not the post\n",
               smear, mirror);
        CHECK(smear == 0);
    }
    free(o), free(want), free(wprim);
    fx_frame_free(f);
}

/* The floor seen in the mirror: pixel (FX0, FY0) (lower half, its ray falls to the floor
 * in front of the mirror, nothing in the way). A genuine front hit: the floor's colour
 * where the ray meets it, confidence 1 (the border is far). Then the same frame with the
 * floor's Normal pass turned so that it faces along that ray (n . r = +0.15: a back face)
 * and otherwise still a plane the ray crosses from its front: the fallback. */
enum { FX0 = 8, FY0 = 46 };

static void test_floor_and_back_face(fx_context *ctx)
{
    world wd;
    memset(&wd, 0, sizeof wd);
    float *want = calloc((size_t)FW * FH * 3, sizeof(float));
    fx_frame *f = make_frame(ctx, &wd, want, NULL);
    size_t i = (size_t)FY0 * FW + FX0;
    double m[3], r[3];
    mirror_ray(FX0, FY0, m, r);
    double t = -m[2] / r[2];
    double q[3] = { m[0] + t * r[0], m[1] + t * r[1], 0.0 };
    CHECK(r[2] < 0 && q[0] > -3.0 && q[0] < 3.0 && q[1] > 0.0 && q[1] < 3.0); /* it meets the floor in view */
    float *o = run_env(ctx, f, NULL);
    CHECK(o != NULL);
    if (o) {
        printf("floor: pixel (%d, %d) reflects (%.3f %.3f %.3f), exact (%.3f %.3f %.3f)\n", FX0, FY0, o[i * 4],
               o[i * 4 + 1], o[i * 4 + 2], want[i * 3], want[i * 3 + 1], want[i * 3 + 2]);
        CHECK(dist3(o + i * 4, want + i * 3) < 0.03); /* the floor's colour, not faded */
        CHECK(dist3(o + i * 4, ENV) > 0.3);
    }
    free(o);
    fx_frame_free(f);
    /* the back face: n = the floor's normal tilted towards the ray until n . r = 0.15 */
    double up[3] = { 0, 0, 1 }, rr = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
    double rn[3] = { r[0] / rr, r[1] / rr, r[2] / rr };
    /* n = a up + b rn with |n| = 1 and n . rn = 0.15: solve for a, b */
    double c = rn[2]; /* up . rn */
    /* n . rn = a c + b = 0.15 and |n|^2 = a^2 + b^2 + 2 a b c = 1 give a^2 (1 - c^2) = 1 - 0.15^2 */
    double a = sqrt((1.0 - 0.15 * 0.15) / (1.0 - c * c)), bb = 0.15 - a * c;
    wd.flip_floor = 1;
    for (int k = 0; k < 3; k++)
        wd.floor_normal[k] = a * up[k] + bb * rn[k];
    double ndr = wd.floor_normal[0] * rn[0] + wd.floor_normal[1] * rn[1] + wd.floor_normal[2] * rn[2];
    printf("back face: floor normal (%.3f %.3f %.3f), n . r = %.3f\n", wd.floor_normal[0], wd.floor_normal[1],
           wd.floor_normal[2], ndr);
    CHECK(fabs(ndr - 0.15) < 1e-3);
    f = make_frame(ctx, &wd, NULL, NULL);
    o = run_env(ctx, f, NULL);
    CHECK(o != NULL);
    if (o) {
        printf("back face: pixel (%d, %d) reflects (%.3f %.3f %.3f)\n", FX0, FY0, o[i * 4], o[i * 4 + 1],
               o[i * 4 + 2]);
        CHECK(dist3(o + i * 4, ENV) < 1e-5);
    }
    free(o), free(want);
    fx_frame_free(f);
}

/* Rays leaving the screen (the room open to the sky): mirror pixels whose exact reflection
 * lies off the frame (the sky above its top, the room behind the camera) take the fallback
 * exactly. Hits in the border band (edge_fade) fade:
 * the debug confidence is below 1 there and 0 at the border, and 1 well inside. */
/* Whether the exact reflection of the ray p + t r lies off the frame (2 px margin). */
static int off_frame(const world *wd, const double p[3], const double r[3])
{
    double nn[3];
    float col[3];
    int m;
    double t = cast(wd, p, r, nn, col, &m);
    double q[3] = { p[0] + t * r[0] - CAM[0], p[1] + t * r[1] - CAM[1], p[2] + t * r[2] - CAM[2] };
    if (t > 1e29 || q[1] < 0.2)
        return 1; /* the sky (above the frame's top), or behind the camera */
    double fy = tan(30 * PI / 180), asp = (double)FW / FH;
    double px = (q[0] / q[1] / (fy * asp) + 1) * 0.5 * FW, py = (1 - q[2] / q[1] / fy) * 0.5 * FH;
    return px < -2 || px > FW + 2 || py < -2 || py > FH + 2;
}

static void test_screen_border(fx_context *ctx)
{
    world wd;
    memset(&wd, 0, sizeof wd);
    wd.open_top = 1;
    fx_frame *f = make_frame(ctx, &wd, NULL, NULL);
    fx_stack *s = NULL;
    char json[512];
    snprintf(json, sizeof json,
             "{\"version\":1,\"effects\":[{\"effect\":\"ssr_mirror\",\"params\":{\"fallback\": \"environment\", "
             "\"environment_color\": [%.9g, %.9g, %.9g], \"bounces\": 1},\"mask\":{\"material_index\": 1}}]}",
             ENV[0], ENV[1], ENV[2]);
    CHECK_OK(ctx, fx_stack_new(ctx, &s));
    CHECK_OK(ctx, fx_stack_load_json(s, json));
    fx_stack_set_debug_outputs(s, 1);
    fx_frame *out = NULL;
    CHECK_OK(ctx, fx_stack_run(s, f, &out));
    float *conf = NULL, *xy = NULL, *ima = NULL;
    int c;
    const float *o = et_combined(out);
    CHECK(out && fx_frame_pass(out, "fx0_ssr_mirror_hit", &conf, &c) == FX_OK);
    CHECK(out && fx_frame_pass(out, "fx0_ssr_mirror_hit_xy", &xy, &c) == FX_OK);
    fx_frame_pass(f, "IndexMA", &ima, &c);
    int top = 0, top_env = 0, band = 0, band_faded = 0, inner = 0, inner_full = 0;
    for (int y = 0; conf && xy && o && y < FH; y++)
        for (int x = 0; x < FW; x++) {
            size_t i = (size_t)y * FW + x;
            if (ima[i] != 1)
                continue;
            double p[3], r[3];
            mirror_ray(x, y, p, r);
            if (off_frame(&wd, p, r)) {
                top++;
                top_env += dist3(o + i * 4, ENV) < 1e-5;
            }
            if (conf[i] > 0) {
                float hx = xy[i * 3], hy = xy[i * 3 + 1];
                float e = fminf(fminf(hx, FW - hx) / (0.08f * FW), fminf(hy, FH - hy) / (0.08f * FH));
                if (e < 0.5f) {
                    band++;
                    band_faded += conf[i] < 0.5f + 1e-4f;
                } else if (e > 1.0f) {
                    inner++;
                    inner_full += conf[i] > 0.999f;
                }
            }
        }
    printf("screen border: %d of %d rays leaving the frame take the fallback; %d of %d hits in the border band "
           "faded, %d of %d inside kept whole\n", top_env, top, band_faded, band, inner_full, inner);
    CHECK(top > 20 && top_env == top);
    CHECK(band > 0 && band_faded == band);
    CHECK(inner > 50 && inner_full == inner);
    fx_frame_free(out);
    fx_stack_free(s);
    fx_frame_free(f);
}

/* ---- the smear scene: a sphere and a block in front of the mirror, with a probe ---- */

static void smear_world(world *wd)
{
    memset(wd, 0, sizeof *wd);
    prim sphere = { 1, { -2.1, 2.0, 0.6 }, { 0.45, 0, 0 }, { 0.95f, 0.85f, 0.05f } };
    prim block = { 0, { -2.3, 1.0, 0.0 }, { -1.9, 1.4, 1.1 }, { 0.05f, 0.75f, 0.1f } };
    wd->p[0] = sphere;
    wd->p[1] = block;
    wd->n = 2;
}

/* The probe from pos (probe camera along +Y as the frame's): colour and radial depth. */
static void write_probe(fx_context *ctx, const world *wd, const char *path, const double pos[3], int w, int h)
{
    float *rgba = malloc((size_t)w * h * 4 * sizeof(float)), *dep = malloc((size_t)w * h * sizeof(float));
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            fx_vec3 dc = fx_pano_pixel_to_dir(x + 0.5f, y + 0.5f, w, h);
            double d[3] = { dc.x, -dc.z, dc.y }, nn[3];
            int mir;
            float col[3];
            double t = cast(wd, pos, d, nn, col, &mir);
            size_t i = (size_t)y * w + x;
            memcpy(rgba + i * 4, col, sizeof col);
            if (mir)
                rgba[i * 4] = rgba[i * 4 + 1] = rgba[i * 4 + 2] = 0.1f;
            rgba[i * 4 + 3] = 1;
            dep[i] = (float)t;
        }
    et_write_view(ctx, path, w, h, rgba, dep);
    free(rgba), free(dep);
}

static void add_probe(fx_context *ctx, fx_frame *f, const char *name, const char *path, const double pos[3])
{
    float m[16];
    cam_w2c(pos, m);
    et_add_probe(ctx, f, name, path, m);
}

/* Mirror MAE against want, and the smear count: mirror pixels whose output is nearer a
 * foreground primitive's colour than half the exact reflection's distance from it (L1),
 * where the exact reflection is not that primitive: the primitive drawn where it is not. */
static void score(const fx_frame *f, const float *o, const float *want, const int *wprim, const world *wd,
                  double *mae, int *smear)
{
    float *ima;
    int c;
    fx_frame_pass(f, "IndexMA", &ima, &c);
    double e = 0;
    int n = 0;
    *smear = 0;
    for (size_t i = 0; i < (size_t)FW * FH; i++) {
        if (ima[i] != 1)
            continue;
        for (int k = 0; k < 3; k++)
            e += fabs(o[i * 4 + k] - want[i * 3 + k]);
        n += 3;
        for (int k = 0; k < wd->n; k++)
            if (wprim[i] != k + 1 && dist3(o + i * 4, wd->p[k].col) < 0.5 * dist3(want + i * 3, wd->p[k].col)) {
                (*smear)++;
                break;
            }
    }
    *mae = n ? e / n : 1e9;
}

static int mirror_pixels(const fx_frame *f)
{
    float *ima;
    int c, n = 0;
    fx_frame_pass(f, "IndexMA", &ima, &c);
    for (size_t i = 0; i < (size_t)FW * FH; i++)
        n += ima[i] == 1;
    return n;
}

static float *run_probe(fx_context *ctx, const fx_frame *f, const char *fallback)
{
    char params[256];
    snprintf(params, sizeof params, "\"fallback\": \"%s\", \"bounces\": 1", fallback);
    return et_run_effect(ctx, "ssr_mirror", f, params, "{\"material_index\": 1}");
}

static void test_smear_scene(fx_context *ctx)
{
    world wd;
    smear_world(&wd);
    float *want = calloc((size_t)FW * FH * 3, sizeof(float));
    int *wprim = calloc((size_t)FW * FH, sizeof(int));
    fx_frame *f = make_frame(ctx, &wd, want, wprim);
    /* the probe as the add-on places it: in front of the mirror, towards the camera */
    fx_stack *s = et_stack(ctx, "ssr_mirror");
    CHECK_OK(ctx, fx_stack_set_mask_json(s, 0, "{\"material_index\": 1}"));
    CHECK_OK(ctx, fx_stack_set_enum(s, 0, "fallback", "probe"));
    char *req = NULL;
    CHECK_OK(ctx, fx_stack_required_aux_views(s, &req));
    const char *at = req ? strstr(req, "probe:") : NULL;
    char pname[64] = "probe:?";
    if (at)
        snprintf(pname, sizeof pname, "%.18s", at);
    fx_free(req);
    fx_stack_free(s);
    const char *dir = tu_tmpdir("ssr_confidence");
    char path[600];
    snprintf(path, sizeof path, "%s/probe.exr", dir);
    const double ppos[3] = { -2.5, 1.5, 1.4 };
    write_probe(ctx, &wd, path, ppos, 512, 256);
    add_probe(ctx, f, pname, path, ppos);
    float *o_tex = run_probe(ctx, f, "texture"), *o = run_probe(ctx, f, "probe");
    CHECK(o && o_tex);
    if (o && o_tex) {
        double e_tex, e;
        int s_tex, s_probe;
        score(f, o_tex, want, wprim, &wd, &e_tex, &s_tex);
        score(f, o, want, wprim, &wd, &e, &s_probe);
        printf("smear scene (sphere and block before the mirror): MAE vs exact reflection %.4f (texture "
               "fallback: %.4f); smear pixels %d (texture fallback: %d)\n", e, e_tex, s_probe, s_tex);
        /* screen space never draws a foreground object where it is not (the tracer before
         * issue 27: 30 pixels, the sphere and block drawn out behind their silhouettes); the
         * probe, one viewpoint 0.7 m from the sphere, misplaces a few of its pixels (its
         * parallax limit, not a smear: 11 of 1384 here, the old tracer's probe path 30) */
        CHECK(s_tex == 0);
        CHECK(s_probe * 100 < mirror_pixels(f));
        CHECK(e < 0.5 * e_tex);
        /* thread count: the same bits */
        for (int th = 1; th <= 3; th++) {
            fx_context *c2 = NULL;
            CHECK_OK(c2, fx_context_new(&c2, th));
            float *o2 = run_probe(c2, f, "probe");
            CHECK(o2 && memcmp(o2, o, (size_t)FW * FH * 4 * sizeof(float)) == 0);
            free(o2);
            fx_context_free(c2);
        }
    }
    free(o), free(o_tex), free(want), free(wprim);
    fx_frame_free(f);
}

int main(void)
{
    fx_context *ctx = NULL;
    CHECK_OK(ctx, fx_context_new(&ctx, 2));
    test_thin_post(ctx);
    test_floor_and_back_face(ctx);
    test_screen_border(ctx);
    test_smear_scene(ctx);
    fx_context_free(ctx);
    return tu_finish("test_ssr_confidence");
}
