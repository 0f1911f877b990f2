/* The extremes suite (issue 8, hardening), table-driven over the registry: every effect
 * (fx_effect_count/fx_effect_name, so new effects are covered without edits) and every
 * numeric parameter (fx_effect_param).
 *
 *  - Refused: NaN, +-Inf, just below min, just above max, non-integers for ints, through
 *    the C setters and through recipe JSON (1e999 parses as Inf): FX_ERR_BAD_PARAM with
 *    a message naming the parameter.
 *  - Run: min, max, 0, +-denormal, -1 and the soft-range midpoint when in range, on a
 *    hostile 17x13 frame at quality draft.
 *  - Inputs: a small synthetic scene with every pass an effect could need (Combined,
 *    Depth, Normal, Position, IndexOB/IndexMA, Cryptomatte ranks, diffuse/glossy/...
 *    lights), a scene sidecar (camera, sun, point, spot lights) and aux views (light
 *    depth view, rain map); "hostile" variants put NaN/+-Inf/1e38/65504/denormals in a
 *    third of the pixels of every pass (NaN/Inf through the EXR reader, which replaces
 *    them, and finite extremes straight through the API), background depth
 *    1e10/1e11/65504, zero-length and non-unit normals; 1x1, 1xN, Nx1 frames;
 *    singular/huge/NaN camera matrices (NaN refused); lights behind and at the camera.
 *  - Every case: no crash, every float of every output pass finite (debug outputs on),
 *    a wall limit per case (SIGALRM names the case that hangs), or a clear error.
 *  - A few reference-quality cases.
 */
#include "fx_effect_test.h"

#include "core/internal.h"

#include <float.h>
#include <math.h>
#include <signal.h>
#include <stdint.h>
#include <time.h>
#include <unistd.h>

/* Hard per-case limit (the process exits naming the case) and the soft one that is
 * checked: generous for ASan on a loaded 2-core machine, each case is a few ms. */
#define CASE_HARD_LIMIT_S 120
#define FX_COUNT_OF(a) ((int)(sizeof(a) / sizeof((a)[0])))
#define CASE_SOFT_LIMIT_S 30.0

static char current_case[512];
static int runs_ok, runs_refused;

static void on_alarm(int sig)
{
    (void)sig;
    static const char msg[] = "\ntest_extremes: case over the wall limit (hang?): ";
    if (write(2, msg, sizeof msg - 1) < 0 || write(2, current_case, strlen(current_case)) < 0 ||
        write(2, "\n", 1) < 0) { /* nothing more to do */ }
    _exit(3);
}

static double now_s(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

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

static const char *SIDECAR_LIGHTS_FRONT =
    "\"lights\": [{\"name\": \"Sun\", \"type\": \"SUN\", \"position\": [0, 40, 30], \"direction\": [0, -0.6, -0.8],"
    " \"color\": [1, 0.95, 0.9], \"energy\": 3, \"angle\": 0.01},"
    " {\"name\": \"Lamp\", \"type\": \"POINT\", \"position\": [0, -10, 2], \"direction\": [0, 0, -1],"
    " \"color\": [1, 1, 1], \"energy\": 1000, \"angle\": 0},"
    " {\"name\": \"Spot\", \"type\": \"SPOT\", \"position\": [1, 0, 5], \"direction\": [0, 0, -1],"
    " \"color\": [1, 1, 1], \"energy\": 1e38, \"angle\": 0}]";
/* The sun shines towards the camera from behind it (its screen position is behind, w < 0). */
static const char *SIDECAR_LIGHTS_BEHIND =
    "\"lights\": [{\"name\": \"Sun\", \"type\": \"SUN\", \"position\": [0, -100, 30], \"direction\": [0, 0.6, -0.8],"
    " \"color\": [1, 1, 1], \"energy\": 5, \"angle\": 0.2}]";
/* Straight down the view axis, exactly at infinity behind the camera: w == 0. */
static const char *SIDECAR_LIGHTS_GRAZING =
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

/* ---- running one case ------------------------------------------------------------- */

/* A clear error: one of the expected codes and a message; for FX_ERR_BAD_PARAM from
 * cross-parameter checks the message names one of the effect's parameters. */
static int clear_error(const char *effect, fx_result r, const char *msg)
{
    if (!msg || strlen(msg) < 8)
        return 0;
    switch (r) {
    case FX_ERR_BAD_PARAM: {
        int n = fx_effect_param_count(effect);
        for (int i = 0; i < n; i++) {
            char quoted[128];
            snprintf(quoted, sizeof quoted, "'%s'", fx_effect_param(effect, i)->name);
            if (strstr(msg, quoted) || strstr(msg, fx_effect_param(effect, i)->name))
                return 1;
        }
        return 0;
    }
    case FX_ERR_NO_CAMERA:
    case FX_ERR_MISSING_PASS:
    case FX_ERR_LIMIT:
    case FX_ERR_INVALID_ARGUMENT:
    case FX_ERR_BAD_RECIPE:
        return 1;
    default:
        return 0; /* OOM on a 17x13 frame, INTERNAL, IO, ...: a bug */
    }
}

/* Runs s on f. must_run: FX_OK is required (else a clear error is accepted). Checks every
 * float of every output pass. Returns the result. */
static fx_result run_case(fx_context *ctx, fx_stack *s, const fx_frame *f, const char *effect, int must_run)
{
    fx_context_clear_warnings(ctx);
    alarm(CASE_HARD_LIMIT_S);
    double t0 = now_s();
    fx_frame *out = NULL;
    fx_result r = fx_stack_run(s, f, &out);
    double dt = now_s() - t0;
    alarm(0);
    tu_checks++;
    if (dt > CASE_SOFT_LIMIT_S) {
        tu_failures++;
        fprintf(stderr, "SLOW (%.1f s): %s\n", dt, current_case);
    }
    if (r == FX_OK) {
        runs_ok++;
        int bad = 0;
        CHECK(out != NULL && fx_frame_width(out) == fx_frame_width(f) && fx_frame_height(out) == fx_frame_height(f));
        for (int p = 0; out && p < fx_frame_pass_count(out); p++) {
            float *d = NULL;
            int ch = 0;
            const char *pn = fx_frame_pass_name(out, p);
            fx_frame_pass(out, pn, &d, &ch);
            size_t n = (size_t)fx_frame_width(out) * fx_frame_height(out) * ch;
            for (size_t i = 0; i < n; i++)
                if (!isfinite(d[i])) {
                    if (!bad)
                        fprintf(stderr, "NON-FINITE output: %s: pass '%s' [%zu] = %g\n", current_case, pn, i,
                                d[i]);
                    bad = 1;
                    break;
                }
        }
        tu_checks++;
        tu_failures += bad;
        /* The stack replaces non-finite values an effect produced (a safety net) and warns;
         * every input here is finite, so such a warning is the effect's own NaN/Inf. */
        for (int w = 0; w < fx_context_warning_count(ctx); w++) {
            const char *msg = fx_context_warning(ctx, w);
            tu_checks++;
            if (tu_contains(msg, "non-finite")) {
                tu_failures++;
                fprintf(stderr, "EFFECT MADE NaN/Inf (replaced by the stack): %s: %s\n", current_case, msg);
            }
        }
    } else {
        runs_refused++;
        const char *msg = fx_context_error(ctx);
        tu_checks++;
        if (must_run || !clear_error(effect, r, msg)) {
            tu_failures++;
            fprintf(stderr, "%s: %s: %s: \"%s\"\n", must_run ? "FAILED TO RUN" : "UNCLEAR ERROR", current_case,
                    fx_result_name(r), msg);
        } else {
            printf("refused (clear error): %s: %s: \"%s\"\n", current_case, fx_result_name(r), msg);
        }
    }
    fx_frame_free(out);
    return r;
}

static fx_stack *stack_for(fx_context *ctx, const char *effect, int quality)
{
    fx_stack *s = et_stack(ctx, effect);
    if (s) {
        fx_stack_set_quality(s, quality);
        fx_stack_set_debug_outputs(s, 1);
    }
    return s;
}

/* ---- parameter sweep ------------------------------------------------------------------ */

static int is_numeric(const fx_param_info *p)
{
    return p->type == FX_PARAM_FLOAT || p->type == FX_PARAM_INT || p->type == FX_PARAM_FLOATS;
}

static int has_range(const fx_param_info *p)
{
    return p->type != FX_PARAM_FLOATS || p->min < p->max;
}

/* Sets one numeric value (FLOATS: every element, or only the last one). */
static fx_result set_value(fx_stack *s, const fx_param_info *p, double v, int last_only)
{
    if (p->type == FX_PARAM_FLOAT)
        return fx_stack_set_float(s, 0, p->name, v);
    if (p->type == FX_PARAM_INT)
        return fx_stack_set_float(s, 0, p->name, v); /* through the JSON number: NaN, 0.5 too */
    float vals[64];
    for (int i = 0; i < p->count && i < 64; i++)
        vals[i] = p->default_floats ? p->default_floats[i] : 0.0f;
    for (int i = last_only ? p->count - 1 : 0; i < p->count && i < 64; i++)
        vals[i] = (float)v;
    return fx_stack_set_floats(s, 0, p->name, vals, p->count);
}

static int param_named(const char *msg, const char *name)
{
    char quoted[128];
    snprintf(quoted, sizeof quoted, "'%s'", name);
    return tu_contains(msg, quoted);
}

/* Values outside the hard range: the setter refuses them, the stack is unchanged. */
static void sweep_refused(fx_context *ctx, const char *effect, const fx_param_info *p)
{
    double bad[12];
    int n = 0;
    bad[n++] = NAN;
    bad[n++] = INFINITY;
    bad[n++] = -INFINITY;
    if (has_range(p)) {
        /* just outside: the next float (or integer) beyond each end */
        if (p->type == FX_PARAM_INT) {
            bad[n++] = p->min - 1;
            bad[n++] = p->max + 1;
            bad[n++] = fmin(p->max, fmax(p->min, p->default_value)) + 0.5; /* not an integer */
        } else {
            float lo = (float)p->min, hi = (float)p->max;
            double below = nextafterf(lo, -INFINITY), above = nextafterf(hi, INFINITY);
            if (below < p->min)
                bad[n++] = below;
            if (above > p->max && isfinite(above))
                bad[n++] = above;
            bad[n++] = p->min - fmax(1.0, fabs(p->min));
            bad[n++] = p->max + fmax(1.0, fabs(p->max));
        }
    }
    for (int i = 0; i < n; i++)
        for (int last = 0; last <= (p->type == FX_PARAM_FLOATS); last++) {
            snprintf(current_case, sizeof current_case, "%s.%s = %g%s (refused)", effect, p->name, bad[i],
                     last ? " (last element)" : "");
            fx_stack *s = stack_for(ctx, effect, FX_QUALITY_DRAFT);
            CHECK(s != NULL);
            if (!s)
                continue;
            fx_result r = set_value(s, p, bad[i], last);
            tu_checks++;
            if (r != FX_ERR_BAD_PARAM || !param_named(fx_context_error(ctx), p->name)) {
                tu_failures++;
                fprintf(stderr, "NOT REFUSED: %s: %s \"%s\"\n", current_case, fx_result_name(r),
                        fx_context_error(ctx));
            }
            /* the stack still holds the defaults: it serialises without the value */
            char *json = NULL;
            CHECK_OK(ctx, fx_stack_to_json(s, &json));
            char key[128];
            snprintf(key, sizeof key, "\"%s\":", p->name);
            tu_checks++;
            if (!json || tu_contains(json, key)) {
                tu_failures++;
                fprintf(stderr, "STACK CHANGED by a refused value: %s: %s\n", current_case, json ? json : "");
            }
            fx_free(json);
            fx_stack_free(s);
        }
    /* The recipe parser: out of range and overflowing numbers (1e999 is Inf to strtod). */
    const char *texts[4];
    char lo_txt[64], hi_txt[64];
    int m = 0;
    texts[m++] = "1e999";
    texts[m++] = "-1e999";
    if (has_range(p)) {
        snprintf(lo_txt, sizeof lo_txt, "%.17g", p->min - fmax(1.0, fabs(p->min)));
        snprintf(hi_txt, sizeof hi_txt, "%.17g", p->max + fmax(1.0, fabs(p->max)));
        texts[m++] = lo_txt;
        texts[m++] = hi_txt;
    }
    for (int i = 0; i < m; i++) {
        char value[1200], recipe[1600];
        if (p->type == FX_PARAM_FLOATS) {
            size_t len = 0;
            len += (size_t)snprintf(value + len, sizeof value - len, "[");
            for (int k = 0; k < p->count && len < sizeof value - 40; k++)
                len += (size_t)snprintf(value + len, sizeof value - len, "%s%s", k ? ", " : "", texts[i]);
            snprintf(value + len, sizeof value - len, "]");
        } else {
            snprintf(value, sizeof value, "%s", texts[i]);
        }
        snprintf(recipe, sizeof recipe,
                 "{\"version\": 1, \"effects\": [{\"effect\": \"%s\", \"params\": {\"%s\": %s}}]}", effect, p->name,
                 value);
        snprintf(current_case, sizeof current_case, "recipe %s.%s = %s (refused)", effect, p->name, texts[i]);
        fx_stack *s = NULL;
        CHECK_OK(ctx, fx_stack_new(ctx, &s));
        fx_result r = fx_stack_load_json(s, recipe);
        tu_checks++;
        if (r != FX_ERR_BAD_PARAM || !param_named(fx_context_error(ctx), p->name)) {
            tu_failures++;
            fprintf(stderr, "NOT REFUSED: %s: %s \"%s\"\n", current_case, fx_result_name(r), fx_context_error(ctx));
        }
        CHECK(fx_stack_count(s) == 0);
        fx_stack_free(s);
    }
}

/* Values inside the hard range: they must be accepted and run (or fail a documented
 * cross-parameter check, naming a parameter) with finite output. */
static void sweep_accepted(fx_context *ctx, const char *effect, const fx_param_info *p, const fx_frame *f)
{
    double vals[12];
    int n = 0;
    double lo = has_range(p) ? p->min : -1e3, hi = has_range(p) ? p->max : 1e3;
    vals[n++] = lo;
    vals[n++] = hi;
    const double extra[] = {0.0, 1.4e-45, -1.4e-45, 1e-40, -1.0, 1.0};
    for (int i = 0; i < FX_COUNT_OF(extra); i++) {
        double v = extra[i];
        if (p->type == FX_PARAM_INT && v != floor(v))
            continue;
        if (v >= lo && v <= hi && v != lo && v != hi)
            vals[n++] = v;
    }
    if (p->soft_min < p->soft_max && p->type != FX_PARAM_FLOATS) {
        double mid = 0.5 * (p->soft_min + p->soft_max);
        if (p->type == FX_PARAM_INT)
            mid = floor(mid);
        vals[n++] = mid;
    }
    for (int i = 0; i < n; i++) {
        snprintf(current_case, sizeof current_case, "%s.%s = %.9g (draft, hostile %dx%d)", effect, p->name, vals[i],
                 fx_frame_width(f), fx_frame_height(f));
        fx_stack *s = stack_for(ctx, effect, FX_QUALITY_DRAFT);
        CHECK(s != NULL);
        if (!s)
            continue;
        fx_result r = set_value(s, p, vals[i], 0);
        tu_checks++;
        if (r != FX_OK) {
            tu_failures++;
            fprintf(stderr, "IN-RANGE VALUE REFUSED: %s: %s \"%s\"\n", current_case, fx_result_name(r),
                    fx_context_error(ctx));
        } else {
            run_case(ctx, s, f, effect, 0);
        }
        fx_stack_free(s);
    }
}

/* ---- frames and cameras ----------------------------------------------------------------- */

static const char *dir;

typedef enum { PLAIN, HOSTILE_API, HOSTILE_EXR } variant;

static fx_frame *make_frame(fx_context *ctx, int w, int h, variant v, const char *lights)
{
    scene s;
    scene_build(&s, w, h);
    if (v != PLAIN)
        scene_make_hostile(&s, v == HOSTILE_EXR);
    fx_frame *f = frame_from_scene(ctx, &s, lights);
    scene_free(&s);
    if (f && v == HOSTILE_EXR) {
        char name[64];
        snprintf(name, sizeof name, "hostile_%dx%d", w, h);
        f = through_exr(ctx, f, dir, name);
    }
    return f;
}

static int needs_camera(fx_context *ctx, const char *effect)
{
    fx_stack *s = et_stack(ctx, effect);
    char *json = NULL;
    int yes = s && fx_stack_required_passes(s, &json) == FX_OK && tu_contains(json, "\"camera\":true");
    fx_free(json);
    fx_stack_free(s);
    return yes;
}

/* Cameras that are finite but degenerate: accepted by fx_frame_set_camera, and then the
 * effects must refuse clearly or produce finite output. NaN ones are refused up front. */
static void camera_cases(fx_context *ctx, const char *effect, fx_frame *f)
{
    fx_camera good;
    CHECK(fx_frame_camera(f, &good));
    for (int k = 0; k < 7; k++) {
        fx_camera c = good;
        const char *what = "";
        switch (k) {
        case 0: memset(c.world_to_camera, 0, sizeof c.world_to_camera), what = "zero world_to_camera"; break;
        case 1: memset(c.projection, 0, sizeof c.projection), what = "zero projection"; break;
        case 2: /* rank 2: one axis collapsed */
            c.world_to_camera[4] = c.world_to_camera[5] = c.world_to_camera[6] = 0;
            what = "singular world_to_camera";
            break;
        case 3:
            for (int i = 0; i < 16; i++)
                c.world_to_camera[i] *= 1e38f;
            what = "1e38 world_to_camera";
            break;
        case 4: c.projection[14] = 0, c.projection[15] = 0, what = "projection w row zero"; break;
        case 5: { /* orthographic, 10 m wide */
            fx_camera o;
            ortho(&o, good.world_to_camera, 5.0f, 0.1f, 1000.0f);
            c = o;
            what = "orthographic";
            break;
        }
        case 6: c.clip_start = 0, c.clip_end = 0, what = "zero clip range"; break;
        }
        snprintf(current_case, sizeof current_case, "%s: camera %s", effect, what);
        fx_frame *g = NULL;
        CHECK_OK(ctx, fx_frame_new_like(f, &g));
        CHECK_OK(ctx, fx_frame_copy_passes(g, f));
        fx_result r = fx_frame_set_camera(g, &c);
        if (r == FX_OK) {
            fx_stack *s = stack_for(ctx, effect, FX_QUALITY_DRAFT);
            if (s)
                run_case(ctx, s, g, effect, 0);
            fx_stack_free(s);
        } else {
            CHECK(strlen(fx_context_error(ctx)) > 8);
        }
        fx_frame_free(g);
    }
    /* NaN / Inf matrices are refused by the API and by the sidecar parser */
    fx_camera c = good;
    c.world_to_camera[5] = NAN;
    CHECK_FAIL(ctx, fx_frame_set_camera(f, &c), FX_ERR_INVALID_ARGUMENT, "NaN");
    c = good;
    c.projection[0] = INFINITY;
    CHECK_FAIL(ctx, fx_frame_set_camera(f, &c), FX_ERR_INVALID_ARGUMENT, "NaN or Inf");
    fx_camera tmp;
    CHECK(fx_camera_from_json(ctx,
                              "{\"world_to_camera\": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1e999]],"
                              " \"projection\": [[1,0,0,0],[0,1,0,0],[0,0,-1,-0.2],[0,0,-1,0]],"
                              " \"clip_start\": 0.1, \"clip_end\": 100}",
                              &tmp) != FX_OK);
    CHECK(fx_frame_camera(f, &tmp) && memcmp(&tmp, &good, sizeof tmp) == 0); /* unchanged */
}

int main(void)
{
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_alarm;
    sigaction(SIGALRM, &sa, NULL);
    double t_start = now_s();

    fx_context *ctx = NULL;
    CHECK_OK(ctx, fx_context_new(&ctx, 2));
    if (!ctx)
        return tu_finish("test_extremes");
    dir = tu_tmpdir("extremes");
    write_aux_views(ctx, dir);

    fx_frame *hostile = make_frame(ctx, 17, 13, HOSTILE_EXR, SIDECAR_LIGHTS_FRONT);
    CHECK(hostile != NULL);

    /* 1. every numeric parameter of every effect */
    for (int e = 0; e < fx_effect_count() && hostile; e++) {
        const char *effect = fx_effect_name(e);
        for (int i = 0; i < fx_effect_param_count(effect); i++) {
            const fx_param_info *p = fx_effect_param(effect, i);
            if (!is_numeric(p))
                continue;
            sweep_refused(ctx, effect, p);
            sweep_accepted(ctx, effect, p, hostile);
        }
    }
    double t_sweep = now_s();

    /* 2. defaults on every input variant and frame shape (draft, and final on 1x1) */
    static const int sizes[][2] = {{1, 1}, {1, 9}, {9, 1}, {2, 2}, {17, 13}};
    const char *lights[3] = {SIDECAR_LIGHTS_FRONT, SIDECAR_LIGHTS_BEHIND, SIDECAR_LIGHTS_GRAZING};
    const char *light_names[3] = {"lights in front", "sun behind the camera", "sun on the view axis, w = 0"};
    for (int z = 0; z < FX_COUNT_OF(sizes); z++)
        for (int v = PLAIN; v <= HOSTILE_EXR; v++)
            for (int l = 0; l < 3; l++) {
                if (l > 0 && (z < 4 || v == HOSTILE_API))
                    continue; /* light placement matters on the larger frame */
                fx_frame *f = make_frame(ctx, sizes[z][0], sizes[z][1], (variant)v, lights[l]);
                CHECK(f != NULL);
                for (int e = 0; f && e < fx_effect_count(); e++) {
                    const char *effect = fx_effect_name(e);
                    static const char *const vn[] = {"plain", "hostile finite (API)", "hostile NaN/Inf (EXR)"};
                    for (int q = FX_QUALITY_DRAFT; q <= FX_QUALITY_FINAL; q += 2) {
                        if (q == FX_QUALITY_FINAL && z != 0)
                            continue;
                        snprintf(current_case, sizeof current_case, "%s defaults (%s) on %dx%d %s, %s", effect,
                                 fx_quality_name(q), sizes[z][0], sizes[z][1], vn[v], light_names[l]);
                        fx_stack *s = stack_for(ctx, effect, q);
                        if (s)
                            run_case(ctx, s, f, effect, 1);
                        fx_stack_free(s);
                    }
                }
                fx_frame_free(f);
            }

    /* 3. degenerate cameras, for the effects that use one */
    for (int e = 0; e < fx_effect_count() && hostile; e++) {
        const char *effect = fx_effect_name(e);
        if (needs_camera(ctx, effect))
            camera_cases(ctx, effect, hostile);
    }

    /* 4. reference quality on the hostile frame (the slow, converged settings) */
    for (int e = 0; e < fx_effect_count() && hostile; e++) {
        const char *effect = fx_effect_name(e);
        snprintf(current_case, sizeof current_case, "%s defaults (reference) on hostile 17x13", effect);
        fx_stack *s = stack_for(ctx, effect, FX_QUALITY_REFERENCE);
        if (s)
            run_case(ctx, s, hostile, effect, 1);
        fx_stack_free(s);
    }

    /* 5. the whole registry as one stack (effects feed each other's extremes) */
    fx_stack *all = NULL;
    CHECK_OK(ctx, fx_stack_new(ctx, &all));
    for (int e = 0; e < fx_effect_count(); e++)
        CHECK_OK(ctx, fx_stack_append(all, fx_effect_name(e), NULL));
    fx_stack_set_quality(all, FX_QUALITY_DRAFT);
    fx_stack_set_debug_outputs(all, 1);
    snprintf(current_case, sizeof current_case, "every effect in one stack (draft) on hostile 17x13");
    if (hostile)
        run_case(ctx, all, hostile, "", 1);
    fx_stack_free(all);

    fx_frame_free(hostile);
    fx_context_free(ctx);
    printf("test_extremes: %d runs finished, %d refused with a clear error; sweep %.1f s, total %.1f s\n",
           runs_ok, runs_refused, t_sweep - t_start, now_s() - t_start);
    return tu_finish("test_extremes");
}
