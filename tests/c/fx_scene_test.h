/* A small synthetic scene for the hardening tests (test_extremes, test_oom_effects): every
 * pass an effect could need (Combined, Depth, Normal, Position, IndexOB/IndexMA,
 * Cryptomatte ranks with manifests, diffuse/glossy/... light passes), a scene sidecar
 * (camera, sun, point and spot lights, time) and aux views (a light depth view and a rain
 * map), plus "hostile" variants with NaN/+-Inf/1e38/65504/denormals in every pass.
 * Header-only (static functions) so each test stays one CTest executable. */
#ifndef LIBFX_FX_SCENE_TEST_H
#define LIBFX_FX_SCENE_TEST_H

#include "fx_effect_test.h"

#include <float.h>
#include <math.h>
#include <stdint.h>

#if defined(__GNUC__)
#pragma GCC diagnostic ignored "-Wunused-function"
#endif

#ifndef FX_COUNT_OF
#define FX_COUNT_OF(a) ((int)(sizeof(a) / sizeof((a)[0])))
#endif
/* ---- the synthetic scene ------------------------------------------------------------- */

/* Camera at (0, -10, 2) looking along +Y (Blender: rotation X 90 deg), 60 deg vertical fov. */
static void scene_camera(fx_camera *c, int w, int h)
{
    memset(c, 0, sizeof *c);
    c->size = sizeof *c;
    /* world_to_camera = R^T * T(-pos), R = rot_x(90) */
    const float w2c[16] = {1, 0, 0, 0, 0, 0, 1, -2, 0, -1, 0, -10, 0, 0, 0, 1};
    memcpy(c->world_to_camera, w2c, sizeof w2c);
    float n = 0.1f, fa = 1000.0f, f = 1.0f / tanf(0.5236f), aspect = (float)w / (float)h;
    const float p[16] = {f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (fa + n) / (n - fa), 2 * fa * n / (n - fa),
                         0, 0, -1, 0};
    memcpy(c->projection, p, sizeof p);
    c->clip_start = n;
    c->clip_end = fa;
}

typedef struct scene {
    int w, h;
    float *combined, *depth, *normal, *position, *index_ob, *index_ma, *crypto_ob, *crypto_ma, *rgb;
} scene;

static void scene_free(scene *s)
{
    free(s->combined);
    free(s->depth);
    free(s->normal);
    free(s->position);
    free(s->index_ob);
    free(s->index_ma);
    free(s->crypto_ob);
    free(s->crypto_ma);
    free(s->rgb);
}

static float bits_float(uint32_t u)
{
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}

static const float ID_GROUND = 1.5e-5f, ID_WALL = -2.25e3f;

/* The plausible scene: ground z = 0 below the horizon, a wall at y = 5 on the left, sky
 * (background depth 1e10, bright) elsewhere. */
static void scene_build(scene *s, int w, int h)
{
    size_t n = (size_t)w * h;
    s->w = w;
    s->h = h;
    s->combined = malloc(n * 4 * sizeof(float));
    s->depth = malloc(n * sizeof(float));
    s->normal = malloc(n * 3 * sizeof(float));
    s->position = malloc(n * 3 * sizeof(float));
    s->index_ob = malloc(n * sizeof(float));
    s->index_ma = malloc(n * sizeof(float));
    s->crypto_ob = malloc(n * 4 * sizeof(float));
    s->crypto_ma = malloc(n * 4 * sizeof(float));
    s->rgb = malloc(n * 3 * sizeof(float));
    float t = tanf(0.5236f), aspect = (float)w / (float)h;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            float xn = 2.0f * (x + 0.5f) / w - 1.0f, yn = 1.0f - 2.0f * (y + 0.5f) / h;
            /* camera-space direction (z = -1), to world: (x, y, z)_cam -> (x, -z, y) */
            float dx = xn * t * aspect, dy = 1.0f, dz = yn * t;
            float depth = 1e10f, nx = 0, ny = 0, nz = 0, id = 0;
            int obj = 0;
            if (x < w / 2 && dy > 0) { /* wall at y = 5: t = 15 */
                float tw = 15.0f / dy;
                if (2.0f + tw * dz > 0.0f) {
                    depth = tw, ny = -1, obj = 2, id = ID_WALL;
                }
            }
            if (obj == 0 && dz < 0) { /* ground */
                depth = -2.0f / dz, nz = 1, obj = 1, id = ID_GROUND;
            }
            float *c = s->combined + 4 * i;
            if (obj == 0) {
                c[0] = 4.0f, c[1] = 4.5f, c[2] = 6.0f, c[3] = 1.0f;
            } else {
                c[0] = 0.2f + 0.1f * obj, c[1] = 0.3f + 0.01f * x, c[2] = 0.25f + 0.02f * y, c[3] = 1.0f;
            }
            s->depth[i] = depth;
            s->normal[3 * i] = nx, s->normal[3 * i + 1] = ny, s->normal[3 * i + 2] = nz;
            float dd = obj ? depth : 0.0f;
            s->position[3 * i] = dd * dx, s->position[3 * i + 1] = -10.0f + dd * dy;
            s->position[3 * i + 2] = 2.0f + dd * dz;
            s->index_ob[i] = (float)obj;
            s->index_ma[i] = (float)obj;
            float *co = s->crypto_ob + 4 * i, *cm = s->crypto_ma + 4 * i;
            co[0] = id, co[1] = obj ? 1.0f : 0.0f, co[2] = 0, co[3] = 0;
            cm[0] = id, cm[1] = obj ? 1.0f : 0.0f, cm[2] = 0, cm[3] = 0;
            s->rgb[3 * i] = 0.5f, s->rgb[3 * i + 1] = 0.4f + 0.01f * y, s->rgb[3 * i + 2] = 0.3f;
        }
}

/* Specials put into every channel of a third of the pixels. */
static const float *special_values(int with_nonfinite, int *count)
{
    static float v[16];
    int n = 0;
    v[n++] = 1e38f;
    v[n++] = -1e38f;
    v[n++] = 65504.0f;
    v[n++] = -65504.0f;
    v[n++] = bits_float(0x00000001u); /* smallest denormal */
    v[n++] = -1e-40f;
    v[n++] = 0.0f;
    v[n++] = FLT_MAX;
    v[n++] = 1e10f;
    v[n++] = 1e11f;
    if (with_nonfinite) {
        v[n++] = NAN;
        v[n++] = INFINITY;
        v[n++] = -INFINITY;
    }
    *count = n;
    return v;
}

static void poison(float *d, size_t n, int ch, int with_nonfinite, unsigned salt)
{
    int k;
    const float *sv = special_values(with_nonfinite, &k);
    for (size_t i = 0; i < n; i++) {
        uint32_t h = (uint32_t)i * 2654435761u ^ salt * 40503u;
        h ^= h >> 15;
        if (h % 3)
            continue;
        for (int c = 0; c < ch; c++)
            d[i * ch + c] = sv[(h / 3 + (unsigned)c * 5u + salt) % (unsigned)k];
    }
}

/* Hostile geometry on top of the specials: background depth variants, zero-length and
 * non-unit normals. */
static void scene_make_hostile(scene *s, int with_nonfinite)
{
    size_t n = (size_t)s->w * s->h;
    poison(s->combined, n, 4, with_nonfinite, 1);
    poison(s->depth, n, 1, with_nonfinite, 2);
    poison(s->position, n, 3, with_nonfinite, 3);
    poison(s->index_ob, n, 1, with_nonfinite, 4);
    poison(s->index_ma, n, 1, with_nonfinite, 5);
    poison(s->crypto_ob, n, 4, with_nonfinite, 6);
    poison(s->crypto_ma, n, 4, with_nonfinite, 7);
    poison(s->rgb, n, 3, with_nonfinite, 8);
    static const float bg[] = {1e10f, 1e11f, 65504.0f};
    for (size_t i = 0; i < n; i++) {
        if (i % 5 == 1)
            s->depth[i] = bg[(i / 5) % 3];
        float *nn = s->normal + 3 * i;
        switch (i % 7) {
        case 0: nn[0] = nn[1] = nn[2] = 0.0f; break;         /* background / zero length */
        case 1: nn[0] *= 0.5f, nn[1] *= 0.5f, nn[2] *= 0.5f; break; /* AA edge */
        case 2: nn[0] = 7.0f, nn[1] = -3.0f, nn[2] = 1e-30f; break; /* non-unit */
        case 3: nn[0] = bits_float(1), nn[1] = 0, nn[2] = -bits_float(3); break; /* denormal */
        case 4: nn[0] = 1e38f, nn[1] = 1e38f, nn[2] = -1e38f; break;
        case 5:
            if (with_nonfinite)
                nn[0] = NAN, nn[1] = INFINITY, nn[2] = 0;
            break;
        default: break;
        }
    }
}

static const char *RGB_PASSES[] = {"DiffDir", "DiffInd", "DiffCol", "GlossDir", "GlossInd", "GlossCol",
                                   "TransDir", "TransInd", "TransCol", "Emit", "Env", "AO", "Shadow"};

static char aux_light_path[512], aux_rain_path[512];

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

/* The aux views' camera: top-down from z = 40 (both the sun's view and the rain map). */
static void aux_camera(fx_camera *c)
{
    const float w2c[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, -40, 0, 0, 0, 1};
    ortho(c, w2c, 30.0f, 1.0f, 80.0f);
}

/* Depth maps of the aux views; the hostile one has specials (NaN/Inf replaced on read). */
static void write_aux_views(fx_context *ctx, const char *dir)
{
    enum { A = 16 };
    float d[A * A];
    for (int i = 0; i < A * A; i++)
        d[i] = (i % A) < A / 2 ? 35.0f : 40.0f;
    poison(d, A * A, 1, 1, 9);
    for (int k = 0; k < 2; k++) {
        char *path = k ? aux_rain_path : aux_light_path;
        snprintf(path, 512, "%s/%s.exr", dir, k ? "rain_map" : "light_sun");
        fx_frame *f = NULL;
        CHECK_OK(ctx, fx_frame_new(ctx, A, A, &f));
        CHECK_OK(ctx, fx_frame_add_pass(f, "Depth", 1, d));
        CHECK_OK(ctx, fx_frame_write_exr(f, path, NULL));
        fx_frame_free(f);
    }
}

__attribute__((unused)) static const char *SIDECAR_LIGHTS_FRONT =
    "\"lights\": [{\"name\": \"Sun\", \"type\": \"SUN\", \"position\": [0, 40, 30], \"direction\": [0, -0.6, -0.8],"
    " \"color\": [1, 0.95, 0.9], \"energy\": 3, \"angle\": 0.01},"
    " {\"name\": \"Lamp\", \"type\": \"POINT\", \"position\": [0, -10, 2], \"direction\": [0, 0, -1],"
    " \"color\": [1, 1, 1], \"energy\": 1000, \"angle\": 0},"
    " {\"name\": \"Spot\", \"type\": \"SPOT\", \"position\": [1, 0, 5], \"direction\": [0, 0, -1],"
    " \"color\": [1, 1, 1], \"energy\": 1e38, \"angle\": 0}]";
/* The sun shines towards the camera from behind it (its screen position is behind, w < 0). */
__attribute__((unused)) static const char *SIDECAR_LIGHTS_BEHIND =
    "\"lights\": [{\"name\": \"Sun\", \"type\": \"SUN\", \"position\": [0, -100, 30], \"direction\": [0, 0.6, -0.8],"
    " \"color\": [1, 1, 1], \"energy\": 5, \"angle\": 0.2}]";
/* Straight down the view axis, exactly at infinity behind the camera: w == 0. */
__attribute__((unused)) static const char *SIDECAR_LIGHTS_GRAZING =
    "\"lights\": [{\"name\": \"Sun\", \"type\": \"SUN\", \"position\": [0, 0, 0], \"direction\": [0, -1, 0],"
    " \"color\": [0, 0, 0], \"energy\": 0, \"angle\": 0}]";

/* The frame: scene passes, camera, lights, time, aux views, Cryptomatte manifests. */
static fx_frame *frame_from_scene(fx_context *ctx, const scene *s, const char *lights)
{
    fx_frame *f = NULL;
    if (fx_frame_new(ctx, s->w, s->h, &f))
        return NULL;
    size_t n = (size_t)s->w * s->h;
    fx_frame_add_pass(f, "Combined", 4, s->combined);
    fx_frame_add_pass(f, "Depth", 1, s->depth);
    fx_frame_add_pass(f, "Normal", 3, s->normal);
    fx_frame_add_pass(f, "Position", 3, s->position);
    fx_frame_add_pass(f, "IndexOB", 1, s->index_ob);
    fx_frame_add_pass(f, "IndexMA", 1, s->index_ma);
    fx_frame_add_pass(f, "CryptoObject00", 4, s->crypto_ob);
    fx_frame_add_pass(f, "CryptoObject01", 4, s->crypto_ma);
    fx_frame_add_pass(f, "CryptoMaterial00", 4, s->crypto_ma);
    fx_frame_add_pass(f, "CryptoMaterial01", 4, s->crypto_ob);
    fx_frame_add_pass(f, "Mist", 1, s->depth);
    for (int i = 0; i < FX_COUNT_OF(RGB_PASSES); i++)
        fx_frame_add_pass(f, RGB_PASSES[i], 3, s->rgb);
    (void)n;
    fx_camera cam;
    scene_camera(&cam, s->w, s->h);
    char json[4096];
    snprintf(json, sizeof json,
             "{\"world_to_camera\": [[%g,%g,%g,%g],[%g,%g,%g,%g],[%g,%g,%g,%g],[%g,%g,%g,%g]],"
             " \"projection\": [[%.9g,%g,%g,%g],[%g,%.9g,%g,%g],[%g,%g,%.9g,%.9g],[%g,%g,%g,%g]],"
             " \"clip_start\": %g, \"clip_end\": %g, \"frame\": 12, \"fps\": 24, %s}",
             cam.world_to_camera[0], cam.world_to_camera[1], cam.world_to_camera[2], cam.world_to_camera[3],
             cam.world_to_camera[4], cam.world_to_camera[5], cam.world_to_camera[6], cam.world_to_camera[7],
             cam.world_to_camera[8], cam.world_to_camera[9], cam.world_to_camera[10], cam.world_to_camera[11],
             cam.world_to_camera[12], cam.world_to_camera[13], cam.world_to_camera[14], cam.world_to_camera[15],
             cam.projection[0], cam.projection[1], cam.projection[2], cam.projection[3], cam.projection[4],
             cam.projection[5], cam.projection[6], cam.projection[7], cam.projection[8], cam.projection[9],
             cam.projection[10], cam.projection[11], cam.projection[12], cam.projection[13],
             cam.projection[14], cam.projection[15], cam.clip_start, cam.clip_end, lights);
    CHECK_OK(ctx, fx_frame_apply_sidecar(f, json));
    fx_camera ac;
    aux_camera(&ac);
    CHECK_OK(ctx, fx_frame_set_aux_view(f, "light:Sun", aux_light_path, &ac));
    CHECK_OK(ctx, fx_frame_set_aux_view(f, "rain_map", aux_rain_path, &ac));
    char manifest[128];
    snprintf(manifest, sizeof manifest, "{\"Ground\": \"%08x\", \"Wall\": \"%08x\", \"Rain_Cover\": \"%08x\"}",
             0x37fba882u, 0xc50ca000u, 0xc50ca000u);
    fx_frame_set_meta(f, "cryptomatte/CryptoObject/manifest", manifest);
    fx_frame_set_meta(f, "cryptomatte/CryptoMaterial/manifest", manifest);
    return f;
}

/* Through the EXR writer and reader (the path every user takes): NaN/Inf are replaced
 * by the reader (and counted in a warning). */
static fx_frame *through_exr(fx_context *ctx, fx_frame *f, const char *dir, const char *name)
{
    char path[600];
    snprintf(path, sizeof path, "%s/%s.exr", dir, name);
    fx_frame *r = NULL;
    CHECK_OK(ctx, fx_frame_write_exr(f, path, NULL));
    CHECK_OK(ctx, fx_frame_read_exr(ctx, path, NULL, &r));
    fx_context_clear_warnings(ctx);
    if (r) {
        char manifest[128];
        snprintf(manifest, sizeof manifest, "{\"Ground\": \"%08x\", \"Wall\": \"%08x\"}", 0x37fba882u,
                 0xc50ca000u);
        if (!fx_frame_meta(r, "cryptomatte/CryptoObject/manifest"))
            fx_frame_set_meta(r, "cryptomatte/CryptoObject/manifest", manifest);
        if (!fx_frame_meta(r, "cryptomatte/CryptoMaterial/manifest"))
            fx_frame_set_meta(r, "cryptomatte/CryptoMaterial/manifest", manifest);
        fx_camera c;
        CHECK(fx_frame_camera(r, &c)); /* the camera survives the round trip */
    }
    fx_frame_free(f);
    return r;
}

#endif
