/* rain_splashes: splashes of raindrops on exposed up-facing surfaces, in world space.
 * docs/effects/rain_splashes.md.
 *
 * The ground plane (world XY) is cut into cells `spacing` metres wide. Each cell runs
 * splashes one after the other, each `lifetime` seconds long, with a per-cell phase; the
 * splash of cycle c in cell (i, j) exists with probability `rate` and sits at a point of
 * the cell, all from a hash of (i, j, c, seed): deterministic per (cell, cycle), so
 * consecutive frames of a batch render show the same splashes growing (temporally
 * coherent). A splash is an expanding ring on the surface (radius size * sqrt(age),
 * fading as (1 - age)^1.5) evaluated at each pixel's world position (from the Position
 * pass or Depth + camera): it is drawn in perspective by construction. Only pixels whose
 * surface faces up (normal Z >= up_threshold) and is exposed in the rain map get splashes.
 * Additive. */
#include "scene/aux_view.h"
#include "core/effect.h"
#include "core/parallel.h"
#include "effects/rain_common.h"
#include "math/hash.h"
#include "scene/rain_map.h"
#include "math/surface.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

typedef struct splash_params {
    float spacing;
    float rate;
    float size;
    float lifetime;
    float brightness;
    float up_threshold;
    float color[3];
    int seed;
} splash_params;

static const float default_splash_color[3] = {0.85f, 0.88f, 0.92f};

static const fx_param_def splash_param_defs[] = {
    FX_P_FLOAT(splash_params, spacing, "spacing", 0.35, 0.01, 100.0, 0.1, 2.0, "",
               "Cell size in metres: at most one splash per cell at a time (density = rate / spacing^2 per "
               "lifetime)"),
    FX_P_FLOAT(splash_params, rate, "rate", 0.7, 0.0, 1.0, 0.0, 1.0, "factor",
               "Probability that a cell shows a splash in a cycle"),
    FX_P_FLOAT(splash_params, size, "size", 0.12, 0.001, 10.0, 0.02, 0.5, "",
               "Final ring radius, metres (at most half the spacing)"),
    FX_P_FLOAT(splash_params, lifetime, "lifetime", 0.25, 0.01, 100.0, 0.05, 1.0, "", "Seconds a splash lasts"),
    FX_P_FLOAT(splash_params, brightness, "brightness", 0.6, 0.0, 100.0, 0.0, 2.0, "", "Added radiance of the ring"),
    FX_P_FLOAT(splash_params, up_threshold, "up_threshold", 0.7, 0.0, 1.0, 0.3, 0.99, "",
               "Surfaces with a world normal Z at least this are ground"),
    FX_P_FLOATS(splash_params, color, "color", 3, default_splash_color, 0.0, 1e4, "color", "Splash colour"),
    FX_P_INT(splash_params, seed, "seed", 11, -2147483647, 2147483647, 0, 100, "", "Seed"),
};

static fx_pass_set splash_passes(const void *params)
{
    (void)params;
    return FX_PASS_BIT(FX_PASS_DEPTH) | FX_PASS_BIT(FX_PASS_NORMAL);
}

static fx_result splash_validate(const void *params, char *err, size_t n)
{
    const splash_params *p = params;
    if (p->size > 0.5f * p->spacing) {
        snprintf(err, n, "size (%g) must be at most half the spacing (%g): a ring must stay within its cell's "
                 "neighbours", p->size, p->spacing);
        return FX_ERR_BAD_PARAM;
    }
    return FX_OK;
}

typedef struct splash_job {
    const fx_effect_run *run;
    const splash_params *p;
    fx_surface_src surf;
    fx_rain_map rm;
    double t;
    float *dbg;
} splash_job;

/* The splashes of the 3 x 3 cells around cell (ci, cj): centre, radius now and fade
 * factor (fade^1.5), or none. Pixels of a row mostly stay in one cell (a cell is spacing
 * metres, tens of pixels on the ground), so this is computed once per cell change: the
 * same values as per pixel, bit for bit. */
typedef struct splash_cells {
    int ci, cj, valid, n;
    float sx[9], sy[9], r[9], fade[9], sqf[9], amp[9];
} splash_cells;

static void cells_fill(const splash_job *j, splash_cells *sc, int ci, int cj)
{
    const splash_params *p = j->p;
    sc->ci = ci;
    sc->cj = cj;
    sc->valid = 1;
    sc->n = 0;
    for (int dj = -1; dj <= 1; dj++)
        for (int di = -1; di <= 1; di++) {
            int i = ci + di, k = cj + dj;
            float phase = fx_rand4(i, k, 0x5eed, p->seed);
            double cyc = j->t / p->lifetime + phase;
            double fc = floor(cyc);
            int c = (int)fc;
            float age = (float)(cyc - fc);
            uint32_t h = fx_hash4(i, k, c, p->seed);
            if (fx_hash_to_unit(h) >= p->rate)
                continue;
            uint32_t h1 = fx_hash_u32(h), h2 = fx_hash_u32(h1);
            int m = sc->n++;
            sc->sx[m] = ((float)i + 0.1f + 0.8f * fx_hash_to_unit(h1)) * p->spacing;
            sc->sy[m] = ((float)k + 0.1f + 0.8f * fx_hash_to_unit(h2)) * p->spacing;
            sc->r[m] = p->size * sqrtf(age);
            float fade = 1.0f - age;
            sc->fade[m] = fade;
            sc->sqf[m] = sqrtf(fade);
            sc->amp[m] = fade * sc->sqf[m]; /* >= expf(.) * fade * sqrt(fade): rounding is monotone */
        }
}

/* Splash intensity at world point w (on an up-facing surface): the brightest ring of the
 * 3 x 3 cells around w's. */
static float splash_at(const splash_job *j, fx_vec3 w, splash_cells *sc)
{
    const splash_params *p = j->p;
    /* Cells are int: a point further than ~1e8 cells away (hostile positions such as
     * 1e38) has no splash, rather than an overflowing cell index. */
    float cx = floorf(w.x / p->spacing), cy = floorf(w.y / p->spacing);
    double cyc_all = j->t / p->lifetime + 1.0;
    if (!(fabsf(cx) < 1e8f) || !(fabsf(cy) < 1e8f) || !(fabs(cyc_all) < 1e9))
        return 0.0f;
    int ci = (int)cx, cj = (int)cy;
    if (!sc->valid || sc->ci != ci || sc->cj != cj)
        cells_fill(j, sc, ci, cj);
    float best = 0.0f;
    float ring_w = 0.2f * p->size;
    for (int m = 0; m < sc->n; m++) {
        /* exp(-e^2) <= 1: a ring whose fade cannot beat the best so far is skipped, and
         * one with e^2 > 110 gives exactly 0 in float: the maximum is the same bits */
        if (!(sc->amp[m] > best))
            continue;
        float dx = w.x - sc->sx[m], dy = w.y - sc->sy[m];
        float dist = sqrtf(dx * dx + dy * dy);
        float e = (dist - sc->r[m]) / ring_w;
        if (!(e * e <= 110.0f))
            continue;
        float v = expf(-e * e) * sc->fade[m] * sc->sqf[m];
        best = v > best ? v : best;
    }
    return best;
}

static void splash_rows(void *user, int y0, int y1)
{
    splash_job *j = user;
    const fx_effect_run *run = j->run;
    const splash_params *p = j->p;
    const fx_rect *roi = &run->roi;
    for (int y = roi->y0 + y0; y < roi->y0 + y1; y++) {
        splash_cells sc;
        memset(&sc, 0, sizeof sc);
        for (int x = roi->x0; x < roi->x1; x++) {
            size_t i = (size_t)y * run->width + x;
            const float *s = run->src + 4 * i;
            float *o = run->dst + 4 * i;
            memcpy(o, s, 4 * sizeof(float));
            fx_vec3 w, n;
            float d, v = 0.0f;
            /* the cheap tests first (depth, an up-facing normal): most pixels are walls, sky
             * or objects, and never need their world position (the same answers as testing
             * the world position first: each test is pure) */
            const float dp = j->surf.depth[i];
            if (dp > 0.0f && dp < j->surf.far_limit && fx_surface_normal(&j->surf, x, y, &n) &&
                n.z >= p->up_threshold && fx_surface_world(&j->surf, x, y, &w, &d)) {
                v = splash_at(j, w, &sc);
                /* the rain map only where there is a splash to hide */
                if (v > 0.0f && !(fx_rain_map_exposed(&j->rm, fx_v3_add(w, fx_v3_scale(n, 0.05f))) > 0.0f))
                    v = 0.0f;
                if (v > 0.0f)
                    for (int c = 0; c < 3; c++)
                        o[c] = s[c] + v * p->brightness * p->color[c];
            }
            if (j->dbg)
                j->dbg[i] = v;
        }
    }
}

static fx_result splash_process(const fx_effect_run *run)
{
    const splash_params *p = run->params;
    const fx_rect *roi = &run->roi;
    splash_job j;
    memset(&j, 0, sizeof j);
    j.run = run;
    j.p = p;
    fx_result r = fx_rain_effect_begin(run, 1, 0.0f, "splashes", &j.surf, &j.rm, &j.dbg);
    if (r)
        return r;
    j.t = fx_effect_scene_time(run);
    int rows = roi->y1 - roi->y0;
    fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), splash_rows, &j);
    return fx_rain_effect_end(run, &j.rm, FX_OK);
}

const fx_effect_class fx_effect_rain_splashes = {
    .name = "rain_splashes",
    .doc = "Raindrop splashes (expanding rings) on exposed up-facing surfaces, deterministic per cell and cycle",
    .params_size = sizeof(splash_params),
    .params = splash_param_defs,
    .param_count = FX_COUNT_OF(splash_param_defs),
    .presets = {NULL, NULL, NULL, NULL},
    .passes = splash_passes,
    .flags = FX_EFFECT_NEEDS_CAMERA,
    .aux_views = fx_aux_needs_rain_map, /* what is under cover */
    .halo = NULL,
    .validate = splash_validate,
    .process = splash_process,
};
