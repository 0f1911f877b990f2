/* rain: falling streaks in three layers at distances near/mid/far (the seed's double cone
 * of rain particles around the camera, reproduced in screen space), each depth-tested
 * against the Depth pass and against the rain map, plus rain on the scene's cover quads
 * when the camera stands under cover. docs/effects/rain.md.
 *
 * Layer k lies at planar distance d_k: its pattern is scaled by d_0 / d_k (nearer:
 * larger, faster) and a streak pixel shows only where the scene is farther than d_k and
 * the streak's world point (the pixel's ray at d_k) is exposed in the rain map. The
 * pattern: rotated by the wind angle, cut into cells (spacing wide, 1.5 streak lengths
 * tall) that scroll down with time; a cell holds a streak with probability `density`,
 * its place and length from a hash of (cell, layer, seed): the same frame gives the same
 * bits, consecutive frames move the same streaks. Cover quads (material cover_material,
 * found through Cryptomatte, coverage normalised by cover_opacity) get the nearest layer's
 * pattern, unclipped, when the camera is under cover (rain map at the camera). Additive. */
#include "core/aux_view.h"
#include "core/effect.h"
#include "core/parallel.h"
#include "math/hash.h"
#include "math/rain_map.h"
#include "math/surface.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

typedef struct rain_params {
    float density;
    float length;
    float width;
    float brightness;
    float wind;
    float speed;
    float distances[3];
    float color[3];
    char cover_material[FX_STRING_PARAM_MAX];
    float cover_opacity;
    float cover_brightness;
    int seed;
    int layers;
} rain_params;

static const float default_color[3] = {0.8f, 0.85f, 0.9f};

static const fx_param_def rain_param_defs[] = {
    FX_P_FLOAT(rain_params, density, "density", 0.35, 0.0, 1.0, 0.0, 1.0, "factor",
               "Fraction of pattern cells holding a streak"),
    FX_P_FLOAT(rain_params, length, "streak_length", 40.0, 1.0, 2000.0, 5.0, 200.0, "texels",
               "Streak length of the near layer, in pixels of a 720-line image (scales with the height)"),
    FX_P_FLOAT(rain_params, width, "streak_width", 1.2, 0.3, 20.0, 0.5, 4.0, "texels",
               "Streak width of the near layer (720-line pixels)"),
    FX_P_FLOAT(rain_params, brightness, "brightness", 0.35, 0.0, 10.0, 0.0, 2.0, "",
               "Added radiance of a streak's core (times colour)"),
    FX_P_FLOAT(rain_params, wind, "wind_angle", 10.0, -80.0, 80.0, -45.0, 45.0, "angle",
               "Slant of the streaks from vertical, degrees"),
    FX_P_FLOAT(rain_params, speed, "speed", 1800.0, 0.0, 100000.0, 0.0, 5000.0, "",
               "Fall speed of the near layer, 720-line pixels per second (farther layers slower)"),
    FX_P_FLOAT(rain_params, distances[0], "near", 2.0, 0.05, 1e5, 0.5, 10.0, "",
               "Planar distance of the near layer, metres"),
    FX_P_FLOAT(rain_params, distances[1], "mid", 5.0, 0.05, 1e5, 1.0, 30.0, "",
               "Planar distance of the middle layer, metres"),
    FX_P_FLOAT(rain_params, distances[2], "far", 12.0, 0.05, 1e5, 2.0, 100.0, "",
               "Planar distance of the far layer, metres"),
    FX_P_FLOATS(rain_params, color, "color", 3, default_color, 0.0, 1e4, "color", "Streak colour"),
    FX_P_STRING(rain_params, cover_material, "cover_material", "Rain_Cover", "",
                "Material of the cover quads (Cryptomatte); empty: none"),
    FX_P_FLOAT(rain_params, cover_opacity, "cover_opacity", 0.07, 0.001, 1.0, 0.01, 1.0, "factor",
               "The quads' coverage in Cryptomatte that counts as fully on the quad"),
    FX_P_FLOAT(rain_params, cover_brightness, "cover_brightness", 0.6, 0.0, 10.0, 0.0, 2.0, "",
               "Brightness of the rain drawn on cover quads, relative to brightness"),
    FX_P_INT(rain_params, seed, "seed", 7, -2147483647, 2147483647, 0, 100, "", "Pattern seed"),
    FX_P_INT(rain_params, layers, "layers", 3, 1, 3, 1, 3, "",
             "How many of the near/mid/far layers are drawn, nearest first (the cost is about one "
             "layer's per layer; fewer layers: less distant rain)"),
};

static fx_pass_set rain_passes(const void *params)
{
    const rain_params *p = params;
    fx_pass_set s = FX_PASS_BIT(FX_PASS_DEPTH);
    if (p->cover_material[0])
        s |= FX_PASS_BIT(FX_PASS_CRYPTO_MATERIAL);
    return s;
}

static int rain_needs_camera(const void *params)
{
    (void)params;
    return 1;
}

static fx_result rain_validate(const void *params, char *err, size_t n)
{
    const rain_params *p = params;
    if (!(p->distances[0] < p->distances[1] && p->distances[1] < p->distances[2])) {
        snprintf(err, n, "near < mid < far is required (got %g, %g, %g)", p->distances[0], p->distances[1],
                 p->distances[2]);
        return FX_ERR_BAD_PARAM;
    }
    return FX_OK;
}

typedef struct rain_job {
    const fx_effect_run *run;
    const rain_params *p;
    fx_surface_src surf;
    fx_rain_map rm;
    const fx_mask *cover;
    int camera_covered;
    float t, res, cs, sn;
    float *dbg;
} rain_job;

/* The streaks of the cells a pixel can see, per layer: the cells (ci + di, cj + dj) for
 * di in [-reach, reach], dj in {-1, 0}, with the streak each holds (x0 < 0 marks none).
 * Consecutive pixels of a row mostly fall in the same cells (a cell is 14 x 60 pattern
 * pixels, 1.5 to 9 frame pixels per pattern pixel), so the hashes are computed once per
 * cell change: the same values as per pixel, bit for bit. */
typedef struct cell_cache {
    int ci, cj, valid;
    int n;
    float x0[6], y0[6], len[6];
    int has[6];
} cell_cache;

static void cells_fill(const rain_job *j, cell_cache *cc, int ci, int cj, int layer, int reach)
{
    const rain_params *p = j->p;
    float cw = 14.0f, ch = 1.5f * p->length;
    cc->ci = ci;
    cc->cj = cj;
    cc->valid = 1;
    cc->n = 0;
    for (int di = -reach; di <= reach; di++)
        for (int dj = -1; dj <= 0; dj++) {
            int cy = cj + dj, cx = ci + di, k = cc->n++;
            uint32_t h = fx_hash4(cx, cy, layer, p->seed);
            cc->has[k] = fx_hash_to_unit(h) < p->density;
            if (!cc->has[k])
                continue;
            uint32_t h1 = fx_hash_u32(h), h2 = fx_hash_u32(h1), h3 = fx_hash_u32(h2);
            cc->x0[k] = ((float)cx + 0.15f + 0.7f * fx_hash_to_unit(h1)) * cw;
            cc->y0[k] = ((float)cy + fx_hash_to_unit(h2)) * ch;
            cc->len[k] = p->length * (0.7f + 0.6f * fx_hash_to_unit(h3));
        }
}

/* Streak intensity in [0, 1] of layer `layer` at frame pixel (x, y) (continuous). */
static float streak(const rain_job *j, float x, float y, int layer, float scale, cell_cache *cc)
{
    const rain_params *p = j->p;
    float k = j->res * scale;
    /* pattern space: rotated so streaks are vertical, in near-layer 720-line pixels */
    float u = (x * j->cs - y * j->sn) / k;
    float v = (x * j->sn + y * j->cs) / k - j->t * p->speed * scale;
    float cw = 14.0f, ch = 1.5f * p->length;
    int ci = (int)floorf(u / cw), cj = (int)floorf(v / ch);
    float best = 0.0f;
    float wmin = 1.0f / k, we = p->width > wmin ? p->width : wmin;
    int reach = we > 0.15f * cw ? 1 : 0; /* wide streaks reach into the next columns */
    if (!cc->valid || cc->ci != ci || cc->cj != cj)
        cells_fill(j, cc, ci, cj, layer, reach);
    for (int c = 0; c < cc->n; c++) {
        if (!cc->has[c])
            continue;
        float a = (v - cc->y0[c]) / cc->len[c];
        if (a <= 0.0f || a >= 1.0f)
            continue;
        /* a streak narrower than a pixel is drawn a pixel wide and dimmer (its coverage),
         * so it does not alias into speckle at small sizes */
        float across = 1.0f - fabsf(u - cc->x0[c]) / we;
        if (across <= 0.0f)
            continue;
        float i = across * (p->width / we) * 4.0f * a * (1.0f - a);
        best = i > best ? i : best;
    }
    return best;
}

static void rain_rows(void *user, int y0, int y1)
{
    rain_job *j = user;
    const fx_effect_run *run = j->run;
    const rain_params *p = j->p;
    const fx_rect *roi = &run->roi;
    for (int y = roi->y0 + y0; y < roi->y0 + y1; y++) {
        cell_cache cc[4];
        for (int l = 0; l < 4; l++)
            cc[l].valid = 0;
        for (int x = roi->x0; x < roi->x1; x++) {
            size_t i = (size_t)y * run->width + x;
            const float *s = run->src + 4 * i;
            float *o = run->dst + 4 * i;
            float d = j->surf.depth[i];
            if (!(d > 0.0f))
                d = 0.0f;
            if (!isfinite(d))
                d = 3.0e38f;
            float sum = 0.0f;
            for (int l = 0; l < p->layers; l++) {
                float dl = p->distances[l];
                if (!(d > dl))
                    continue; /* the scene is nearer than the layer */
                float scale = p->distances[0] / dl;
                float st = streak(j, (float)x + 0.5f, (float)y + 0.5f, l, scale, &cc[l]);
                if (st <= 0.0f)
                    continue;
                fx_vec2 ndc = fx_view_pixel_to_ndc(&j->surf.view, (float)x + 0.5f, (float)y + 0.5f);
                fx_vec3 w = fx_view_to_world(&j->surf.view, fx_view_position(&j->surf.view, ndc, dl));
                if (fx_rain_map_exposed(&j->rm, w) <= 0.0f)
                    continue; /* under cover */
                sum += st * (0.5f + 0.5f * scale);
            }
            if (j->cover && j->camera_covered) {
                float c = fx_saturate(j->cover->coverage[i] / p->cover_opacity);
                if (c > 0.0f)
                    sum += c * p->cover_brightness * streak(j, (float)x + 0.5f, (float)y + 0.5f, 3, 1.0f, &cc[3]);
            }
            if (j->dbg)
                j->dbg[i] = sum;
            float a = sum * p->brightness;
            for (int c = 0; c < 3; c++)
                o[c] = s[c] + a * p->color[c];
            o[3] = s[3];
        }
    }
}

static fx_result rain_process(const fx_effect_run *run)
{
    const rain_params *p = run->params;
    const fx_rect *roi = &run->roi;
    if (roi->x1 <= roi->x0 || roi->y1 <= roi->y0)
        return FX_OK;
    const char *where = run->where;
    rain_job j;
    memset(&j, 0, sizeof j);
    j.run = run;
    j.p = p;
    if (!fx_surface_src_init(&j.surf, run->frame))
        return fx_fail(run->ctx, FX_ERR_NO_CAMERA, "%s needs the camera and the Depth pass", where);
    fx_result r = fx_rain_map_load(run->frame, 0.0f, where, &j.rm);
    if (r)
        return r;
    double frame = 1, fps = 24;
    fx_frame_time(run->frame, &frame, &fps);
    j.t = (float)(frame / (fps > 0 ? fps : 24.0));
    j.res = (float)run->height / 720.0f;
    float a = p->wind * 0.017453293f;
    j.cs = cosf(a);
    j.sn = sinf(a);
    fx_mask *cover = NULL;
    fx_vec3 cam = fx_v3(j.surf.view.camera_to_world[3], j.surf.view.camera_to_world[7],
                        j.surf.view.camera_to_world[11]);
    /* the cover quads get rain only when the camera stands under cover: otherwise their
     * mask (a Cryptomatte match over the frame) is not built */
    if (p->cover_material[0] && fx_rain_map_exposed(&j.rm, cam) <= 0.0f) {
        fx_mask_spec spec;
        memset(&spec, 0, sizeof spec);
        char *names[1] = {(char *)p->cover_material};
        spec.materials = names;
        spec.material_count = 1;
        r = fx_mask_build(run->ctx, &spec, run->frame, where, &cover);
        if (r) {
            fx_rain_map_free(run->ctx, &j.rm);
            return r;
        }
        j.cover = cover;
        j.camera_covered = 1;
    }
    j.dbg = fx_effect_debug_pass(run, "streaks", 1, &r);
    if (!j.dbg && r) {
        fx_mask_free(cover);
        fx_rain_map_free(run->ctx, &j.rm);
        return r;
    }
    int rows = roi->y1 - roi->y0;
    fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), rain_rows, &j);
    fx_mask_free(cover);
    fx_rain_map_free(run->ctx, &j.rm);
    return FX_OK;
}

const fx_effect_class fx_effect_rain = {
    .name = "rain",
    .doc = "Rain streaks in three depth layers, depth-tested and hidden under cover (rain map); rain on cover quads",
    .params_size = sizeof(rain_params),
    .params = rain_param_defs,
    .param_count = FX_COUNT_OF(rain_param_defs),
    .presets = {"{\"layers\": 1}", "{\"layers\": 2}", "{\"layers\": 3}", "{\"layers\": 3}"},
    .passes = rain_passes,
    .needs_camera = rain_needs_camera,
    .aux_views = fx_aux_needs_rain_map, /* what is under cover */
    .halo = NULL,
    .validate = rain_validate,
    .process = rain_process,
};
