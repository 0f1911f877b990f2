/* voronoi_caustics: water caustics from a Voronoi (Worley) pattern evaluated in world
 * space, so it sticks to the surface as the camera moves. docs/effects/voronoi_caustics.md.
 *
 * World position per pixel: the Position pass, or the Depth pass through the camera. The
 * pattern lives on the world XY plane (the pool's water and floor are horizontal): a
 * periodic tile of tile_size scene units holding `points` feature points (rounded to a
 * square grid; math/voronoi.h), animated by the frame's time. Distances in cell units.
 *  - mode seed: L = ln(1 + F1); alpha = 0.5 L; colour = (tint + 0.75 L) 0.6 noise
 *    sin(2 time); out = mix(src, colour, alpha * strength) (the seed's formula, literally:
 *    sin(2 time) < 0 half the time darkens the water; result clamped to >= 0).
 *  - mode physical: light focused onto the cell borders (where F2 - F1 is small):
 *    g = exp(-(F2 - F1) / line_width); out = src (1 + strength noise' (g / mean(g) - 1) tint'),
 *    clamped to >= 0, g / mean(g) at most 16. mean(g) is the pattern's mean over the tile at this time (a fixed
 *    64 x 64 lattice), so the pattern redistributes light without adding any on average,
 *    and it is the same for every camera.
 * Environment term (the seed's cubemap reflection): Schlick Fresnel (F0 0.02) times the
 * environment (a lat-long EXR in Blender's equirectangular mapping, or world_color) in the
 * reflected view direction, from the Normal pass; added with environment_strength. */
#include "core/effect.h"
#include "core/parallel.h"
#include "math/camera.h"
#include "math/voronoi.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

#define FOCUS_MAX 16.0

typedef struct caustics_params {
    int points;
    float tile_size;
    int metric;
    float exponent;
    int mode;
    float strength;
    float line_width;
    float tint[3];
    float speed;
    float noise_scale;
    int position_source;
    int method;
    float environment_strength;
    char environment[FX_STRING_PARAM_MAX];
    float world_color[3];
    int seed;
} caustics_params;

enum { METRIC_MINKOWSKI = 0, METRIC_CHEBYSHEV };
enum { MODE_PHYSICAL = 0, MODE_SEED };
enum { POS_POSITION = 0, POS_DEPTH };
enum { METHOD_GRID = 0, METHOD_BRUTE };

static const char *const metric_items[] = {"minkowski", "chebyshev"};
static const char *const mode_items[] = {"physical", "seed"};
static const char *const pos_items[] = {"position", "depth"};
static const char *const method_items[] = {"grid", "brute"};
static const float default_tint[3] = {0.8f, 0.95f, 1.0f};
static const float default_world[3] = {0.55f, 0.7f, 0.95f};

static const fx_param_def caustics_param_defs[] = {
    FX_P_INT(caustics_params, points, "points", 196, 1, 1000000, 16, 5000, "",
             "Feature points per tile (rounded to a square grid: 196 = 14 x 14; the seed: 200)"),
    FX_P_FLOAT(caustics_params, tile_size, "tile_size", 4.0, 1e-6, 1e9, 0.5, 50.0, "",
               "World size of the repeating tile (scene units): cells are tile_size / sqrt(points)"),
    FX_P_ENUM(caustics_params, metric, "metric", METRIC_MINKOWSKI, metric_items,
              "minkowski: exponent d; chebyshev: the limit d -> infinity"),
    FX_P_FLOAT(caustics_params, exponent, "exponent", 1.5, 0.01, 1e6, 0.5, 8.0, "",
               "Minkowski exponent d > 0 (the seed: 1.5; 2 Euclidean, 1 Manhattan; d < 1 is not a "
               "metric, still finite)"),
    FX_P_ENUM(caustics_params, mode, "mode", MODE_PHYSICAL, mode_items,
              "physical: light redistributed onto the cell borders (mean brightness kept); seed: "
              "the seed's alpha/colour formula"),
    FX_P_FLOAT(caustics_params, strength, "strength", 0.6, 0.0, 100.0, 0.0, 2.0, "",
               "Contrast of the caustics (0: identity)"),
    FX_P_FLOAT(caustics_params, line_width, "line_width", 0.12, 1e-4, 100.0, 0.02, 0.5, "",
               "physical: width of the bright lines, in cells"),
    FX_P_FLOATS(caustics_params, tint, "tint", 3, default_tint, 0.0, 100.0, "color",
               "Colour of the focused light (physical) / the seed's base colour (seed)"),
    FX_P_FLOAT(caustics_params, speed, "speed", 1.0, -1000.0, 1000.0, 0.0, 4.0, "",
               "How fast the points wander (radians of their sines per second of frame time)"),
    FX_P_FLOAT(caustics_params, noise_scale, "noise_scale", 1.5, 1e-6, 1e9, 0.1, 10.0, "",
               "World size of the brightness noise's cells (scene units)"),
    FX_P_ENUM(caustics_params, position_source, "position_source", POS_POSITION, pos_items,
              "position: the Position pass; depth: Depth reconstructed through the camera"),
    FX_P_ENUM(caustics_params, method, "method", METHOD_GRID, method_items,
              "grid: ring search of the jittered cells, O(1); brute: every point (same result)"),
    FX_P_FLOAT(caustics_params, environment_strength, "environment_strength", 0.0, 0.0, 100.0, 0.0, 2.0,
               "factor", "Environment reflection (Fresnel x environment); needs Normal and the camera"),
    FX_P_STRING(caustics_params, environment, "environment", "", "path",
                "Lat-long environment EXR (Blender's equirectangular mapping); empty: world_color"),
    FX_P_FLOATS(caustics_params, world_color, "world_color", 3, default_world, 0.0, 1e6, "color",
                "Environment colour when no environment EXR is given"),
    FX_P_INT(caustics_params, seed, "seed", 0, -2147483647, 2147483647, 0, 100, "", "Pattern seed"),
};

static double exponent_of(const caustics_params *p)
{
    return p->metric == METRIC_CHEBYSHEV ? INFINITY : (double)p->exponent;
}

static fx_result caustics_validate(const void *params, char *err, size_t err_size)
{
    const caustics_params *p = params;
    if (p->metric == METRIC_MINKOWSKI && !(p->exponent > 0.0f)) {
        snprintf(err, err_size,
                 "parameter 'exponent' must be > 0 (got %g); use metric chebyshev for d = infinity",
                 (double)p->exponent);
        return FX_ERR_BAD_PARAM;
    }
    return FX_OK;
}

static fx_pass_set caustics_passes(const void *params)
{
    const caustics_params *p = params;
    fx_pass_set s = p->position_source == POS_POSITION ? FX_PASS_BIT(FX_PASS_POSITION) : FX_PASS_BIT(FX_PASS_DEPTH);
    if (p->environment_strength > 0.0f)
        s |= FX_PASS_BIT(FX_PASS_NORMAL);
    return s;
}

static int caustics_needs_camera(const void *params)
{
    const caustics_params *p = params;
    return p->position_source == POS_DEPTH || p->environment_strength > 0.0f;
}

typedef struct env_map {
    const float *rgba;
    int w, h;
} env_map;

static void env_lookup(const env_map *e, const float world[3], fx_vec3 d, float out[3])
{
    if (!e->rgba) {
        out[0] = world[0];
        out[1] = world[1];
        out[2] = world[2];
        return;
    }
    double u = -atan2(d.y, d.x) / (2.0 * M_PI) + 0.5;
    double v = atan2(d.z, hypot(d.x, d.y)) / M_PI + 0.5;
    int x = (int)floor(u * e->w), y = (int)floor((1.0 - v) * e->h);
    x = ((x % e->w) + e->w) % e->w;
    y = y < 0 ? 0 : y >= e->h ? e->h - 1 : y;
    const float *q = e->rgba + ((size_t)y * e->w + x) * 4;
    for (int k = 0; k < 3; k++)
        out[k] = isfinite(q[k]) ? q[k] : 0.0f;
}

typedef struct caustics_job {
    const fx_effect_run *run;
    const caustics_params *p;
    fx_voronoi vor;
    double cell;      /* world units per cell */
    double mean_g;
    double time;
    const float *position; /* 3 or 4 channels */
    int pos_channels;
    const float *depth;
    const float *normal;
    fx_view view;
    int has_view;
    fx_vec3 eye;
    env_map env;
} caustics_job;

static void evaluate(const caustics_job *j, double wx, double wy, fx_voronoi_hit *h)
{
    if (j->p->method == METHOD_BRUTE)
        fx_voronoi_brute(&j->vor, wx / j->cell, wy / j->cell, h);
    else
        fx_voronoi_grid(&j->vor, wx / j->cell, wy / j->cell, h);
}

static double pattern_g(const caustics_params *p, const fx_voronoi_hit *h)
{
    double gap = h->f2 - h->f1;
    if (!(gap >= 0.0))
        gap = 0.0;
    return exp(-gap / p->line_width);
}

static void caustics_rows(void *user, int begin, int end)
{
    const caustics_job *j = user;
    const fx_effect_run *run = j->run;
    const caustics_params *p = j->p;
    const int w = run->width;
    for (int y = run->roi.y0 + begin; y < run->roi.y0 + end; y++)
        for (int x = run->roi.x0; x < run->roi.x1; x++) {
            size_t i = (size_t)y * w + x;
            const float *s = run->src + i * 4;
            float *d = run->dst + i * 4;
            if (run->mask && !(run->mask->coverage[i] > 0.0f)) {
                memcpy(d, s, 4 * sizeof(float));
                continue;
            }
            fx_vec3 P;
            if (j->position) {
                const float *q = j->position + i * j->pos_channels;
                P = fx_v3(q[0], q[1], q[2]);
            } else {
                fx_vec2 ndc = fx_view_pixel_to_ndc(&j->view, x + 0.5f, y + 0.5f);
                P = fx_view_to_world(&j->view, fx_view_position(&j->view, ndc, j->depth[i]));
            }
            if (!isfinite(P.x) || !isfinite(P.y) || !isfinite(P.z) || fabsf(P.x) > 1e15f || fabsf(P.y) > 1e15f) {
                memcpy(d, s, 4 * sizeof(float));
                continue;
            }
            fx_voronoi_hit h;
            evaluate(j, P.x, P.y, &h);
            double noise = fx_value_noise2(P.x / p->noise_scale, P.y / p->noise_scale, (uint32_t)p->seed ^ 0xc0ffeeu);
            double out[3];
            if (p->mode == MODE_SEED) {
                double L = log1p(h.f1);
                double alpha = fmin(fmax(0.5 * L * p->strength, 0.0), 1.0);
                double wave = sin(2.0 * j->time);
                for (int k = 0; k < 3; k++) {
                    double colour = (p->tint[k] + 0.75 * L) * 0.6 * noise * wave;
                    out[k] = s[k] * (1.0 - alpha) + colour * alpha;
                }
            } else {
                /* focus ratio bounded (16x the mean: d < 1 makes the mean tiny) */
                double g = fmin(pattern_g(p, &h) / j->mean_g, FOCUS_MAX) - 1.0;
                double amp = p->strength * (0.4 + 1.2 * noise); /* noise' with mean ~1 */
                for (int k = 0; k < 3; k++)
                    out[k] = s[k] * (1.0 + amp * g * p->tint[k]);
            }
            if (p->environment_strength > 0.0f && j->normal) {
                const float *nq = j->normal + i * 3;
                fx_vec3 N = fx_v3_normalize_or(fx_v3(nq[0], nq[1], nq[2]), fx_v3(0, 0, 1));
                fx_vec3 V = fx_v3_normalize_or(fx_v3_sub(j->eye, P), N);
                float cosv = fx_saturate(fx_v3_dot(N, V));
                float F = 0.02f + 0.98f * powf(1.0f - cosv, 5.0f);
                fx_vec3 R = fx_v3_reflect(fx_v3_scale(V, -1.0f), N);
                float env[3];
                env_lookup(&j->env, p->world_color, R, env);
                for (int k = 0; k < 3; k++)
                    out[k] += p->environment_strength * F * env[k];
            }
            for (int k = 0; k < 3; k++) {
                double v = out[k];
                d[k] = !(v > 0.0) ? 0.0f : v > FLT_MAX ? FLT_MAX : (float)v;
            }
            d[3] = s[3];
        }
}

/* Mean of g over the tile at this time: a fixed lattice, independent of the camera. */
typedef struct mean_job {
    const caustics_job *cj;
    double *partial; /* per row */
    int n;
} mean_job;

static void mean_rows(void *user, int begin, int end)
{
    mean_job *m = user;
    const fx_voronoi *v = &m->cj->vor;
    for (int r = begin; r < end; r++) {
        double acc = 0.0;
        for (int c = 0; c < m->n; c++) {
            fx_voronoi_hit h;
            fx_voronoi_grid(v, (c + 0.5) * v->grid / m->n, (r + 0.5) * v->grid / m->n, &h);
            acc += pattern_g(m->cj->p, &h);
        }
        m->partial[r] = acc;
    }
}

static fx_result caustics_process(const fx_effect_run *run)
{
    const caustics_params *p = run->params;
    const char *where = run->where;
    if (run->roi.x1 <= run->roi.x0 || run->roi.y1 <= run->roi.y0)
        return FX_OK;
    caustics_job j;
    memset(&j, 0, sizeof j);
    j.run = run;
    j.p = p;
    j.vor.grid = fx_voronoi_grid_for_points(p->points);
    j.vor.seed = (uint32_t)p->seed;
    double frame_no = run->frame->frame_number, fps = run->frame->fps > 0 ? run->frame->fps : 24.0;
    j.time = isfinite(frame_no) ? frame_no / fps : 0.0;
    j.vor.time = j.time;
    j.vor.speed = p->speed;
    j.vor.p = exponent_of(p);
    j.cell = (double)p->tile_size / j.vor.grid;
    j.has_view = fx_view_init(&j.view, run->frame);
    if (caustics_needs_camera(p) && !j.has_view)
        return fx_fail(run->ctx, FX_ERR_NO_CAMERA,
                       "%s needs the frame's camera (position_source depth or environment_strength > 0); "
                       "give the scene sidecar with --camera",
                       where);
    if (p->position_source == POS_POSITION) {
        const fx_pass *pp = fx_frame_find_pass(run->frame, "Position");
        if (!pp || pp->channels < 3)
            return fx_fail(run->ctx, FX_ERR_MISSING_PASS,
                           "%s: needs the Position pass (or set position_source to depth)", where);
        j.position = pp->data;
        j.pos_channels = pp->channels;
    } else {
        const fx_pass *dp = fx_frame_find_pass(run->frame, "Depth");
        if (!dp)
            return fx_fail(run->ctx, FX_ERR_MISSING_PASS, "%s: position_source depth needs the Depth pass", where);
        j.depth = dp->data;
    }
    fx_frame *envf = NULL;
    if (p->environment_strength > 0.0f) {
        const fx_pass *np = fx_frame_find_pass(run->frame, "Normal");
        if (!np || np->channels < 3)
            return fx_fail(run->ctx, FX_ERR_MISSING_PASS, "%s: environment_strength > 0 needs the Normal pass", where);
        j.normal = np->data;
        j.eye = fx_v3(j.view.camera_to_world[3], j.view.camera_to_world[7], j.view.camera_to_world[11]);
        if (p->environment[0]) {
            fx_result r = fx_frame_read_exr(run->ctx, p->environment, NULL, &envf);
            if (r != FX_OK)
                return r;
            const fx_pass *ep = fx_frame_find_pass(envf, "Combined");
            if (!ep || ep->channels != 4) {
                fx_frame_free(envf);
                return fx_fail(run->ctx, FX_ERR_MISSING_PASS, "%s: environment '%s' has no RGBA image", where,
                               p->environment);
            }
            j.env.rgba = ep->data;
            j.env.w = envf->width;
            j.env.h = envf->height;
        }
    }
    j.mean_g = 1.0;
    if (p->mode == MODE_PHYSICAL) {
        mean_job m = {&j, NULL, 64};
        m.partial = fx_mem_alloc((size_t)m.n * sizeof(double));
        if (!m.partial) {
            fx_frame_free(envf);
            return fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where);
        }
        fx_parallel_for(run->ctx, m.n, 1, mean_rows, &m);
        double acc = 0.0;
        for (int r = 0; r < m.n; r++)
            acc += m.partial[r];
        fx_mem_free(m.partial);
        j.mean_g = acc / ((double)m.n * m.n);
        if (!(j.mean_g > 1e-12))
            j.mean_g = 1e-12;
    }
    int rows = run->roi.y1 - run->roi.y0;
    fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), caustics_rows, &j);
    fx_frame_free(envf);
    return FX_OK;
}

const fx_effect_class fx_effect_voronoi_caustics = {
    .name = "voronoi_caustics",
    .doc = "Water caustics: a world-anchored, animated Voronoi pattern (Minkowski metric) on the masked surface",
    .params_size = sizeof(caustics_params),
    .params = caustics_param_defs,
    .param_count = FX_COUNT_OF(caustics_param_defs),
    .presets = {NULL, NULL, NULL, NULL},
    .passes = caustics_passes,
    .needs_camera = caustics_needs_camera,
    .halo = NULL,
    .validate = caustics_validate,
    .process = caustics_process,
};
