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
 * reflected view direction, from the Normal pass; added with environment_strength.
 *
 * Cost. The pattern's two smooth inputs, physical's F2 - F1 (seed's F1) and the
 * noise, are evaluated on a lattice of every `downsample`-th pixel of the ROI (at real
 * pixels: their own world positions, no position is ever interpolated across an edge) and
 * bilinearly interpolated; g = exp(-gap / line_width) is applied per pixel, after the
 * interpolation. F2 - F1 is a V across a cell border (the bright line): interpolation
 * rounds its kink, so with `refine` a pixel whose four corners do not share their nearest
 * two points gets its own exact search (sharp lines), except where no line can reach it
 * (gap bound, p >= 1); a lattice node's pixel keeps the node's values. A pixel is evaluated exactly instead when its corners are not on its surface:
 * a corner without a position, or the corners' interpolated world XY more than 0.1 cell
 * from the pixel's own (a silhouette, a step). The shading (Fresnel, environment, mix)
 * stays per pixel (normals carry detail), or with `lattice_shading` (draft) is done at the
 * nodes too and interpolated as a gain and an offset per channel, without the per-pixel
 * surface test inside lattice cells whose four corners have positions. Lattice nodes no masked
 * pixel reads are skipped. `distance fast` evaluates the Minkowski distance in float
 * without pow for p = 1, 1.5, 2 and inf (math/voronoi.h); the points are computed once per
 * frame. `reference` (downsample 1, distance exact) evaluates every pixel with double pow:
 * the setting errors are measured against. Physical mode without an environment shades a
 * row in segments of SEG pixels: the pattern pass per pixel, then loops without branches
 * (exp in float without libm, the gain, the clamp) that the compiler vectorises. With the
 * Position pass and a lattice without lattice_shading (final, preview) the pattern pass is
 * caustics_rows_lattice: the lattice columns once per row, the searches of a segment in one
 * batch (fx_voronoi_table_grid_n); the same bits as caustics_rows. With lattice_shading in
 * that case (draft) the nodes hold the focus gain s itself and caustics_rows_gain
 * interpolates it eight pixels at a time (an AVX2 clone where the CPU has one), with the
 * same surface test (no exp per pixel); the pixels that fail it are searched in batches. */
#include "core/effect.h"
#include "core/parallel.h"
#include "core/simd4.h"
#include "core/simd8.h"
#include "math/clones.h"
#include "math/camera.h"
#include "math/voronoi.h"
#include "math/wave_scale.h"
#include "math/caustic_map.h"
#include "scene/aux_view.h"
#include "scene/lights.h"

#include <cjson/cJSON.h>
#include <float.h>
#ifdef __SSE2__
#include <emmintrin.h>
#endif
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

#define FOCUS_MAX 16.0
#define NODE_MAX 8 /* floats per lattice node (lattice_shading; 4 without) */

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
    int downsample;
    int distance;
    int refine;
    int lattice_shading;
    char water[FX_STRING_PARAM_MAX];
    float ior;
    int fresnel;
    int refract_samples;
    int refract_step;
    int apply;
    float receiver_depth;
    float interior;
    float warp;
    int cell_scale;
    float wave_cell_ratio;
} caustics_params;

enum { METRIC_MINKOWSKI = 0, METRIC_CHEBYSHEV };
enum { MODE_PHYSICAL = 0, MODE_SEED, MODE_REFRACTIVE };
enum { CELL_MANUAL = 0, CELL_AUTO };
enum { POS_POSITION = 0, POS_DEPTH };
enum { METHOD_GRID = 0, METHOD_BRUTE };
enum { DIST_FAST = 0, DIST_EXACT };
enum { APPLY_SUN_DIFFUSE = 0, APPLY_COMBINED };

static const char *const metric_items[] = {"minkowski", "chebyshev"};
static const char *const mode_items[] = {"physical", "seed", "refractive"};
static const char *const pos_items[] = {"position", "depth"};
static const char *const method_items[] = {"grid", "brute"};
static const char *const distance_items[] = {"fast", "exact"};
static const char *const apply_items[] = {"sun_diffuse", "combined"};
static const char *const cell_scale_items[] = {"manual", "auto"};
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
              "the seed's alpha/colour formula; refractive: the Sun refracted by the water's surface "
              "(its normals seen from the Sun, an aux view) onto a horizontal floor"),
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
    FX_P_INT(caustics_params, downsample, "downsample", 2, 1, 16, 1, 8, "",
             "Quality: the pattern is evaluated every N pixels and interpolated (N x N fewer "
             "evaluations; exact at silhouettes); 1: every pixel"),
    FX_P_ENUM(caustics_params, distance, "distance", DIST_FAST, distance_items,
              "Quality: fast: float, no pow for d = 1, 1.5, 2 and chebyshev (other d: exact); "
              "exact: double precision pow"),
    FX_P_BOOL(caustics_params, refine, "refine", 1,
              "Quality (downsample > 1): pixels between lattice nodes that straddle a cell border "
              "get their own exact search (sharp lines); off: interpolated"),
    FX_P_BOOL(caustics_params, lattice_shading, "lattice_shading", 0,
              "Quality (downsample > 1): the whole effect (pattern, Fresnel, environment) shaded at "
              "the lattice nodes and interpolated as a per-pixel gain and offset; physical mode without "
              "environment from the Position pass (draft) keeps the per-pixel surface test (a pixel "
              "off its corners' surface gets its own search), other cases skip it where a lattice "
              "cell's corners all have positions; off: per pixel"),
    FX_P_STRING(caustics_params, water, "water", "Water", "",
                "refractive: the water's material; the add-on renders the objects that use it (even when "
                "hidden from the render) from the Sun: their Normal and Depth (aux view 'water:<material>')"),
    FX_P_FLOAT(caustics_params, ior, "ior", 1.33, 1.0, 4.0, 1.0, 2.0, "",
               "refractive: index of refraction of the water (Cycles' Glass IOR)"),
    FX_P_BOOL(caustics_params, fresnel, "fresnel", 1,
              "refractive: the light the surface reflects (Fresnel) does not reach the floor"),
    FX_P_INT(caustics_params, refract_samples, "refract_samples", 2, 1, 16, 1, 8, "",
             "Quality (refractive): sub-samples per side of each light-view cell splatted onto the floor "
             "(n x n; more: smoother, converged focal lines)"),
    FX_P_INT(caustics_params, refract_step, "refract_step", 1, 1, 16, 1, 4, "",
             "Quality (refractive): every n-th texel of the water's view is refracted (the map n times "
             "coarser per side)"),
    FX_P_ENUM(caustics_params, apply, "apply", APPLY_SUN_DIFFUSE, apply_items,
              "refractive: what the caustics' gain g scales: sun_diffuse: the sun's direct diffuse light, "
              "DiffCol x colour x energy x N.L / pi (out = src + strength (g - 1) tint x that; needs DiffCol, "
              "Normal and the scene's lights); combined: the whole pixel (out = src (1 + strength (g - 1) tint))"),
    FX_P_FLOAT(caustics_params, interior, "interior", 0.1, 0.0, 0.95, 0.0, 0.8, "",
               "physical: light inside a cell relative to the bright lines' peak (focus g = interior + "
               "(1 - interior) exp(-gap / line_width), then divided by its mean): lit interiors as real "
               "caustics have; 0: dark interiors (the look before params_version 2)"),
    FX_P_FLOAT(caustics_params, receiver_depth, "receiver_depth", 0.0, 0.0, 1e4, 0.0, 5.0, "",
               "refractive: 0: the masked pixels are the floor the light falls on; > 0: they are the water's "
               "surface and the floor lies this far (scene units) below their median height: each pixel's "
               "camera ray, refracted by a flat surface, finds its floor point there (use apply combined)"),
    FX_P_FLOAT(caustics_params, warp, "warp", 0.3, 0.0, 2.0, 0.0, 1.0, "",
               "physical, seed: the lookup position is displaced by a smooth periodic field of this "
               "amplitude (in cells, wavelength ~2 cells, drifting with speed): the cells' sides bend as a "
               "caustic network's do; 0: the Minkowski bisectors, nearly straight (the look before "
               "params_version 3)"),
    FX_P_ENUM(caustics_params, cell_scale, "cell_scale", CELL_MANUAL, cell_scale_items,
              "physical, seed: manual: cells are tile_size / sqrt(points); auto: wave_cell_ratio x the "
              "waves' mean wavelength, estimated from the water's normals in its view from the Sun (aux view "
              "'water:<water>', rendered by the add-on as for mode refractive); without that view: manual"),
    FX_P_FLOAT(caustics_params, wave_cell_ratio, "wave_cell_ratio", 1.5, 0.01, 100.0, 0.2, 5.0, "",
               "cell_scale auto: cell size over the waves' mean (Rice) wavelength (1: one bright line per "
               "wave crest, the network of a floor near the waves' first focus)"),
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
    if (p->mode == MODE_REFRACTIVE && !p->water[0]) {
        snprintf(err, err_size, "parameter 'water' must name the water's material for mode refractive");
        return FX_ERR_BAD_PARAM;
    }
    return FX_OK;
}

/* refractive: the water's normals and depth seen from the scene's first sun */
static int caustics_aux_views(const void *params, fx_aux_need *out, int max)
{
    const caustics_params *p = params;
    if ((p->mode != MODE_REFRACTIVE && p->cell_scale != CELL_AUTO) || max < 1)
        return 0;
    snprintf(out->name, sizeof out->name, "water:%.80s", p->water);
    out->kind = "water";
    out->light[0] = 0;
    return 1;
}

static fx_pass_set caustics_passes(const void *params)
{
    const caustics_params *p = params;
    fx_pass_set s = p->position_source == POS_POSITION ? FX_PASS_BIT(FX_PASS_POSITION) : FX_PASS_BIT(FX_PASS_DEPTH);
    if (p->environment_strength > 0.0f)
        s |= FX_PASS_BIT(FX_PASS_NORMAL);
    if (p->mode == MODE_REFRACTIVE && p->apply == APPLY_SUN_DIFFUSE)
        s |= FX_PASS_BIT(FX_PASS_NORMAL) | FX_PASS_BIT(FX_PASS_DIFF_COL);
    return s;
}

static int caustics_needs_camera(const void *params)
{
    const caustics_params *p = params;
    return p->position_source == POS_DEPTH || p->environment_strength > 0.0f ||
           (p->mode == MODE_REFRACTIVE && p->receiver_depth > 0.0f);
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
    fx_voronoi_table table; /* the frame's points */
    fx_voronoi_warp warp;   /* the lookup's domain warp (amp 0: none) */
    double cell;      /* world units per cell */
    double inv_cell_d;
    double mean_g;
    double time;
    float inv_mean, inv_lw, wave;
    float focus0; /* interior / mean: inv_mean is (1 - interior) / mean */
    float inv_cell, far_gap; /* far_gap: physical, p >= 1: a gap beyond which g is ~0 */
    float warp_lip;          /* the warp's Lipschitz factor (1: no warp) */
    const float *position; /* 3 or 4 channels */
    int pos_channels;
    const float *depth;
    const float *normal;
    fx_view view;
    int has_view;
    fx_vec3 eye;
    env_map env;
    /* the lattice: node (i, j) at pixel (nx_px[i], ny_px[j]) */
    int f, nx, ny;
    int *node_x, *node_y;
    unsigned char *cell_any; /* (nx) x (ny): a masked pixel in the cell right/below the node */
    int *col_i0, *col_i1;    /* per ROI column: its lattice corners ... */
    float *col_t;            /* ... and the weight of the second */
    int node_size;           /* floats per node: 4, or NODE_MAX with lattice_shading */
    float *nodes;            /* nx * ny * node_size: a (gap or F1), noise, world x, world y (NaN:
                                none), s, add[3] (lattice_shading: factors) */
    int has_add;             /* add is not always 0 (seed mode, environment) */
    int *node_id;            /* nx * ny * 2: the node's nearest two points */
    int cx, cy;              /* lattice cells per row (nx - 1, at least 1) and rows */
    unsigned char *smooth;   /* cx * cy (refine): smooth_rows' flags of each lattice cell */
    int gain_path;           /* lattice_shading, physical, no additive term, Position: the nodes
                                hold the focus gain s (node[0]) and caustics_rows_gain shades */
    int wide;                /* the CPU has AVX2: FX_CLONES runs caustics_rows_gain's AVX2 clone,
                                which takes its eight-lane path (gain_octet8) */
} caustics_job;

static void evaluate(const caustics_job *j, double wx, double wy, fx_voronoi_hit *h)
{
    /* the fast kinds (float searches) take the product by 1 / cell: no division per query;
     * the exact kind (reference) keeps the quotient */
    double cx = j->table.kind ? wx * j->inv_cell_d : wx / j->cell;
    double cy = j->table.kind ? wy * j->inv_cell_d : wy / j->cell;
    fx_voronoi_warp_apply(&j->warp, &cx, &cy);
    if (j->p->method == METHOD_BRUTE)
        fx_voronoi_table_brute(&j->table, cx, cy, h);
    else
        fx_voronoi_table_grid(&j->table, cx, cy, h);
}

static double pattern_g(const caustics_params *p, const fx_voronoi_hit *h)
{
    double gap = h->f2 - h->f1;
    if (!(gap >= 0.0))
        gap = 0.0;
    return exp(-gap / p->line_width);
}

/* World position of pixel (x, y); 0 if it has none (non-finite, or beyond 1e15) */
static inline int world_at(const caustics_job *j, int x, int y, fx_vec3 *P)
{
    size_t i = (size_t)y * j->run->width + x;
    if (j->position) {
        const float *q = j->position + i * j->pos_channels;
        *P = fx_v3(q[0], q[1], q[2]);
    } else {
        fx_vec2 ndc = fx_view_pixel_to_ndc(&j->view, x + 0.5f, y + 0.5f);
        *P = fx_view_to_world(&j->view, fx_view_position(&j->view, ndc, j->depth[i]));
    }
    return fabsf(P->x) <= 1e15f && fabsf(P->y) <= 1e15f && isfinite(P->z); /* NaN fails <= */
}

/* The noise at a world point (cache: the same bits, fewer hashes along a row) */
static inline float noise_at(const caustics_job *j, float wx, float wy, fx_noise_cache *cache)
{
    return (float)fx_value_noise2_cached(wx / j->p->noise_scale, wy / j->p->noise_scale,
                                         (uint32_t)j->p->seed ^ 0xc0ffeeu, cache);
}

static inline float value_of(const caustics_job *j, const fx_voronoi_hit *h)
{
    double v = j->p->mode == MODE_SEED ? h->f1 : h->f2 - h->f1;
    return !(v >= 0.0) ? 0.0f : v > 1e30 ? 1e30f : (float)v;
}

/* The pattern's value at a world point: a = F2 - F1 (physical) or F1 (seed) */
static inline float value_at(const caustics_job *j, float wx, float wy, int *ids)
{
    fx_voronoi_hit h;
    evaluate(j, wx, wy, &h);
    if (ids) {
        ids[0] = h.i1;
        ids[1] = h.i2;
    }
    return value_of(j, &h);
}

/* The effect at pixel i as out = src * gain + add per channel, gain from one scalar s
 * (gain_of): physical 1 + s tint, seed s. add is 0 without seed mode or environment. */
static inline void env_term(const caustics_job *j, size_t i, fx_vec3 P, float add[3]);
static inline void factors(const caustics_job *j, size_t i, fx_vec3 P, float a, float noise, float *s, float add[3])
{
    const caustics_params *p = j->p;
    if (p->mode == MODE_SEED) {
        /* double log1p: glibc 2.41 made the float one correctly rounded, and the same
         * recipe must give the same bits on every system libfx is built on */
        float L = (float)log1p((double)a);
        float alpha = 0.5f * L * p->strength;
        alpha = alpha > 0.0f ? (alpha < 1.0f ? alpha : 1.0f) : 0.0f;
        *s = 1.0f - alpha;
        for (int k = 0; k < 3; k++) {
            float colour = (p->tint[k] + 0.75f * L) * 0.6f * noise * j->wave;
            add[k] = colour * alpha;
        }
    } else {
        /* focus ratio bounded (16x the mean: d < 1 makes the mean tiny) */
        float g = expf(-a * j->inv_lw) * j->inv_mean + j->focus0;
        g = (g < (float)FOCUS_MAX ? g : (float)FOCUS_MAX) - 1.0f;
        float amp = p->strength * (0.4f + 1.2f * noise); /* noise' with mean ~1 */
        *s = amp * g;
        add[0] = add[1] = add[2] = 0.0f;
    }
    if (p->environment_strength > 0.0f && j->normal)
        env_term(j, i, P, add);
}

/* The environment term (Fresnel x environment) added to add[3] */
static inline void env_term(const caustics_job *j, size_t i, fx_vec3 P, float add[3])
{
    const caustics_params *p = j->p;
    {
        const float *nq = j->normal + i * 3;
        fx_vec3 N = fx_v3_normalize_or(fx_v3(nq[0], nq[1], nq[2]), fx_v3(0, 0, 1));
        fx_vec3 V = fx_v3_normalize_or(fx_v3_sub(j->eye, P), N);
        float c = 1.0f - fx_saturate(fx_v3_dot(N, V));
        float F = 0.02f + 0.98f * (c * c) * (c * c) * c; /* Schlick: (1 - cos)^5 without powf */
        float env[3];
        if (j->env.rgba) /* world_color alone needs no reflected direction */
            env_lookup(&j->env, p->world_color, fx_v3_reflect(fx_v3_scale(V, -1.0f), N), env);
        else
            env_lookup(&j->env, p->world_color, N, env);
        for (int k = 0; k < 3; k++)
            add[k] += p->environment_strength * F * env[k];
    }
}

static inline void gain_of(const caustics_job *j, float s, float gain[3])
{
    for (int k = 0; k < 3; k++)
        gain[k] = j->p->mode == MODE_SEED ? s : 1.0f + s * j->p->tint[k];
}

static inline void apply(const caustics_job *j, size_t i, const float gain[3], const float add[3])
{
    const float *s = j->run->src + i * 4;
    float *d = j->run->dst + i * 4;
    for (int k = 0; k < 3; k++) {
        float v = s[k] * gain[k] + add[k];
        d[k] = !(v > 0.0f) ? 0.0f : v > FLT_MAX ? FLT_MAX : v;
    }
    d[3] = s[3];
}

static inline void shade(const caustics_job *j, size_t i, fx_vec3 P, float a, float noise)
{
    float sc, gain[3], add[3];
    factors(j, i, P, a, noise, &sc, add);
    gain_of(j, sc, gain);
    apply(j, i, gain, add);
}

/* lattice_shading: out from a node's (or interpolated) s and add */
static inline void apply_s(const caustics_job *j, size_t i, const float *q)
{
    float gain[3];
    gain_of(j, q[0], gain);
    apply(j, i, gain, q + 1);
}

static inline int covered(const fx_effect_run *run, size_t i)
{
    return !run->mask || run->mask->coverage[i] > 0.0f;
}

/* Lattice cell of a coordinate: node index i (the left/top corner), the next one and the
 * weight of the next; the last node sits on the ROI's last pixel. */
static inline void lattice_pos(const int *node, int n, int f, int origin, int x, int *i0, int *i1, float *t)
{
    int i = (x - origin) / f;
    if (i > n - 2)
        i = n - 2;
    if (i < 0)
        i = 0;
    *i0 = i;
    *i1 = n > 1 ? i + 1 : 0;
    int span = node[*i1] - node[i];
    *t = span > 0 ? (float)(x - node[i]) / (float)span : 0.0f;
    if (*t > 1.0f)
        *t = 1.0f;
}

/* Which lattice cells hold a masked pixel (one row of cells per call item). */
static void cell_rows(void *user, int begin, int end)
{
    caustics_job *j = user;
    const fx_effect_run *run = j->run;
    for (int cj = begin; cj < end; cj++) {
        unsigned char *row = j->cell_any + (size_t)cj * j->nx;
        memset(row, 0, (size_t)j->nx);
        int y0 = j->node_y[cj], y1 = cj + 1 < j->ny ? j->node_y[cj + 1] : y0;
        for (int y = y0; y <= y1; y++)
            for (int x = run->roi.x0; x < run->roi.x1; x++)
                if (covered(run, (size_t)y * run->width + x)) {
                    int i0, i1;
                    float t;
                    lattice_pos(j->node_x, j->nx, j->f, run->roi.x0, x, &i0, &i1, &t);
                    row[i0] = 1;
                }
    }
}

static inline float focus_s(const caustics_job *j, float a, float noise);

/* The lattice nodes of rows [begin, end): a row's positions first, then (fast kinds, grid)
 * its searches as one batch (value_at's bits), then the noise and shading factors. */
static void node_rows(void *user, int begin, int end)
{
    caustics_job *j = user;
    const int ns = j->node_size, nx = j->nx;
    const int batch = j->table.kind && j->p->method == METHOD_GRID;
    fx_noise_cache cache = {0};
    /* per row: the queued nodes, their cell coordinates, distances and points */
    double *buf = batch ? fx_mem_alloc((size_t)nx * 4 * sizeof(double) + (size_t)nx * 3 * sizeof(int)) : NULL;
    double *qx = buf, *qy = buf ? buf + nx : NULL, *f1 = buf ? buf + 2 * nx : NULL, *f2 = buf ? buf + 3 * nx : NULL;
    int *qi = buf ? (int *)(buf + 4 * nx) : NULL, *i1 = qi ? qi + nx : NULL, *i2 = qi ? qi + 2 * nx : NULL;
    for (int nj = begin; nj < end; nj++) {
        int nq = 0;
        for (int ni = 0; ni < nx; ni++) {
            float *q = j->nodes + ((size_t)nj * nx + ni) * ns;
            for (int c = 0; c < ns; c++)
                q[c] = NAN;
            int *id = j->node_id + ((size_t)nj * nx + ni) * 2;
            id[0] = id[1] = -1;
            if (j->cell_any) { /* a masked pixel in one of the four cells around the node */
                int need = 0;
                for (int dj = -1; dj <= 0 && !need; dj++)
                    for (int di = -1; di <= 0 && !need; di++) {
                        int cj = nj + dj, ci = ni + di;
                        need = cj >= 0 && ci >= 0 && j->cell_any[(size_t)cj * nx + ci];
                    }
                if (!need)
                    continue;
            }
            fx_vec3 P;
            if (!world_at(j, j->node_x[ni], j->node_y[nj], &P))
                continue;
            q[2] = P.x;
            q[3] = P.y;
            if (buf) {
                qx[nq] = (double)P.x * j->inv_cell_d;
                qy[nq] = (double)P.y * j->inv_cell_d;
                fx_voronoi_warp_apply(&j->warp, &qx[nq], &qy[nq]);
                qi[nq++] = ni;
            } else {
                q[0] = value_at(j, P.x, P.y, id);
            }
        }
        if (buf) {
            fx_voronoi_table_grid_n(&j->table, nq, qx, qy, f1, f2, i1, i2);
            for (int k = 0; k < nq; k++) {
                const int ni = qi[k];
                fx_voronoi_hit h = {i1[k], i2[k], f1[k], f2[k]};
                j->nodes[((size_t)nj * nx + ni) * ns] = value_of(j, &h);
                int *id = j->node_id + ((size_t)nj * nx + ni) * 2;
                id[0] = h.i1;
                id[1] = h.i2;
            }
        }
        for (int ni = 0; ni < nx; ni++) {
            float *q = j->nodes + ((size_t)nj * nx + ni) * ns;
            if (isnan(q[2]))
                continue;
            q[1] = noise_at(j, q[2], q[3], &cache);
            if (j->gain_path) {
                q[0] = focus_s(j, q[0], q[1]);
            } else if (j->p->lattice_shading) {
                fx_vec3 P;
                world_at(j, j->node_x[ni], j->node_y[nj], &P);
                factors(j, (size_t)j->node_y[nj] * j->run->width + j->node_x[ni], P, q[0], q[1], q + 4, q + 5);
            }
        }
    }
    fx_mem_free(buf);
}

/* Whether lattice cell (i0..i1, j0..j1) is smooth: the same nearest points at its four
 * corners (physical: both; seed: the nearest), or no line can reach it: its pixels
 * interpolate; else (refine) a cell border (the bright line's kink) may cross: each pixel
 * gets its own search. (Testing only an edge's two nodes for the pixels on node rows and
 * columns was tried: 3 % fewer instructions, 19 % more error at final.) */
static int cell_smooth(const caustics_job *j, int j0, int j1, int i0, int i1)
{
    const int ns = j->node_size;
    const int *d00 = j->node_id + ((size_t)j0 * j->nx + i0) * 2;
    const int *d10 = j->node_id + ((size_t)j0 * j->nx + i1) * 2;
    const int *d01 = j->node_id + ((size_t)j1 * j->nx + i0) * 2;
    const int *d11 = j->node_id + ((size_t)j1 * j->nx + i1) * 2;
    int same = d00[0] == d10[0] && d00[0] == d01[0] && d00[0] == d11[0];
    if (j->p->mode == MODE_PHYSICAL)
        same = same && d00[1] == d10[1] && d00[1] == d01[1] && d00[1] == d11[1];
    if (!same && j->far_gap > 0.0f) {
        /* no line can reach the cell: gap is 2-Lipschitz (p >= 1) over the corners'
         * footprint (its L1 extent), so gap >= min corner gap - 2 ext (NaN: not far) */
        const float *q00 = j->nodes + ((size_t)j0 * j->nx + i0) * ns;
        const float *q10 = j->nodes + ((size_t)j0 * j->nx + i1) * ns;
        const float *q01 = j->nodes + ((size_t)j1 * j->nx + i0) * ns;
        const float *q11 = j->nodes + ((size_t)j1 * j->nx + i1) * ns;
        float ext = fabsf(q00[2] - q11[2]) + fabsf(q00[3] - q11[3]) + fabsf(q10[2] - q01[2]) + fabsf(q10[3] - q01[3]);
        float lo = q00[0] < q10[0] ? q00[0] : q10[0];
        lo = lo < q01[0] ? lo : q01[0];
        lo = lo < q11[0] ? lo : q11[0];
        /* the warp stretches the footprint by at most its Lipschitz factor */
        same = lo - 2.0f * ext * j->inv_cell * j->warp_lip > j->far_gap;
    }
    return same;
}

/* The smooth flags of the lattice cells whose top row is cj (one row per call item) */
static void smooth_rows(void *user, int begin, int end)
{
    caustics_job *j = user;
    for (int cj = begin; cj < end; cj++) {
        int j1 = j->ny > 1 ? cj + 1 : 0;
        for (int ci = 0; ci < j->cx; ci++)
            j->smooth[(size_t)cj * j->cx + ci] = (unsigned char)cell_smooth(j, cj, j1, ci, j->nx > 1 ? ci + 1 : 0);
    }
}

/* A lattice column's node values interpolated to a pixel row: (1 - ty) top + ty bottom per
 * channel (a NaN node makes the channel NaN: such a pixel is evaluated exactly) */
static inline void column_at(const caustics_job *j, int j0, int j1, float ty, int i, float *out)
{
    const int ns = j->node_size;
    const float *a = j->nodes + ((size_t)j0 * j->nx + i) * ns, *b = j->nodes + ((size_t)j1 * j->nx + i) * ns;
    const float uy = 1.0f - ty;
    for (int c = 0; c < 4; c++)
        out[c] = a[c] * uy + b[c] * ty;
    for (int c = 4; c < ns; c++)
        out[c] = a[c] * uy + b[c] * ty;
}


#define GAIN_TOL 0.1
#define SEG 256 /* pixels per row segment: the shading pass's buffers */

/* A segment pixel's state after the pattern pass */
enum { PX_COPY = 0, PX_PATTERN, PX_GAIN, PX_DONE };

/* exp(x) for x in [-87, 0] (the caller clamps) in float without libm (glibc picks an FMA variant of expf at run time;
 * this is the same bits on every system and compiler, and vectorises): 2^k exp(r) with k = round(x / ln 2), r = x - k ln 2 (ln 2 in two parts, exact
 * products), exp(r) by its Taylor polynomial to degree 6 (|r| <= 0.35: truncation below
 * 2e-7 relative). One operation per statement: no contraction into FMA by any compiler. */
static inline float exp_neg(float x)
{
    float t = x * 1.44269504f;
    float k = t + 12582912.0f; /* 1.5 2^23: rounds t to the nearest integer */
    k = k - 12582912.0f;
    float hi = k * 0.693145752f; /* ln 2's top 17 bits: exact for |k| <= 127 */
    float lo = k * 1.42860677e-6f;
    float r = x - hi;
    r = r - lo;
    float q = r * (1.0f / 720.0f);
    q = q + (1.0f / 120.0f);
    q = q * r;
    q = q + (1.0f / 24.0f);
    q = q * r;
    q = q + (1.0f / 6.0f);
    q = q * r;
    q = q + 0.5f;
    q = q * r;
    q = q + 1.0f;
    q = q * r;
    q = q + 1.0f;
    int32_t e = ((int32_t)k + 127) << 23; /* k in [-126, 0]: a normal power of 2 */
    float scale;
    memcpy(&scale, &e, sizeof scale);
    return q * scale;
}


/* physical mode without an additive term (no environment): out = src (1 + s tint) per
 * pixel of a segment, s from the pattern (a, noise) or given (lattice_shading), or src
 * copied; loops without calls or branches (auto-vectorised). src and dst may be the same
 * pixels (in place: each is read just before it is written), hence no restrict. */
static void shade_segment(const caustics_job *j, const float *src, float *dst, int n,
                          const int32_t *restrict st, const float *restrict av, const float *restrict nz,
                          float *restrict sv, int patterns)
{
    const float inv_lw = j->inv_lw, inv_mean = j->inv_mean, strength = j->p->strength;
    const float t0 = j->p->tint[0], t1 = j->p->tint[1], t2 = j->p->tint[2];
    if (patterns) {
        float xs[SEG];
        for (int c = 0; c < n; c++) { /* a >= 0: the argument in [-87, 0] (a separate loop: both vectorise) */
            float x = -av[c] * inv_lw;
            x = x > -87.0f ? x : -87.0f;
            xs[c] = x < 0.0f ? x : 0.0f;
        }
        for (int c = 0; c < n; c++)
            xs[c] = exp_neg(xs[c]);
        /* the focus gain s = strength noise' (min(g / mean, 16) - 1) of pattern pixels, four
         * at a time (gcc does not vectorise the scalar loop: "control flow"), the rest of
         * the segment one at a time by the same operations */
        int c = 0;
#ifdef __SSE2__
        const v4f vmean = {inv_mean, inv_mean, inv_mean, inv_mean}, vcap = {16.0f, 16.0f, 16.0f, 16.0f};
        const float f0 = j->focus0;
        for (; c + 4 <= n; c += 4) {
            v4f g = ld4(xs + c) * vmean;
            g = g + f0;
            g = _mm_min_ps(g, vcap); /* g < 16 ? g : 16 (g is never NaN) */
            g = g - 1.0f;
            const v4f amp = strength * (0.4f + 1.2f * ld4(nz + c));
            const v4f sn = amp * g;
            v4i m;
            memcpy(&m, st + c, sizeof m);
            m = m == PX_PATTERN;
            const v4i r = ((v4i)sn & m) | ((v4i)ld4(sv + c) & ~m);
            memcpy(sv + c, &r, sizeof r);
        }
#endif
        for (; c < n; c++)
            if (st[c] == PX_PATTERN)
                sv[c] = focus_s(j, av[c], nz[c]);
    }
    /* per pixel, its four channels as one vector: the gain (alpha's 1 + s 0 = 1: the same
     * product), the clamp to [0, FLT_MAX] (NaN to 0) by masks, alpha and copied pixels
     * taken from src: the same values as a channel at a time */
    const v4f tint = {t0, t1, t2, 0.0f}, zero = {0.0f, 0.0f, 0.0f, 0.0f};
    const v4f fmax = {FLT_MAX, FLT_MAX, FLT_MAX, FLT_MAX};
    const v4i alpha = {0, 0, 0, -1};
    for (int c = 0; c < n; c++) {
        const v4f sc = {sv[c], sv[c], sv[c], sv[c]};
        const v4f in = ld4(src + 4 * c);
        const v4f gain = 1.0f + sc * tint;
        v4f v = in * gain;
#ifdef __SSE2__ /* maxps(v, 0) is 0 for NaN (its second operand), minps(v, FLT_MAX) caps +inf */
        v4i vi = (v4i)_mm_min_ps(_mm_max_ps(v, zero), fmax);
#else
        v4i vi = (v4i)v & (v > zero);                 /* !(v > 0): 0 */
        v4i big = (v4i)((v4f)vi > fmax);              /* > FLT_MAX: FLT_MAX */
        vi = (vi & ~big) | ((v4i)fmax & big);
#endif
        const int32_t k = st[c] == PX_COPY ? -1 : 0;
        const v4i keep = alpha | (v4i){k, k, k, k};
        vi = (vi & ~keep) | ((v4i)in & keep);
        memcpy(dst + 4 * c, &vi, sizeof vi);
    }
}

/* lattice_shading (draft's trade): a lattice cell whose four corners have positions gives its
 * pixels the interpolated shading without their own surface test (a silhouette or step
 * between two lattice nodes is not seen; a pixel without a position is still left as is) */
static inline int cell_coherent(const float *q00, const float *q10, const float *q01, const float *q11)
{
    return !isnan(q00[2]) && !isnan(q10[2]) && !isnan(q01[2]) && !isnan(q11[2]);
}

/* caustics_rows moves to lattice cell i0 (next i1) of rows j0, j1 at weight ty: its
 * columns interpolated to the row (c0 kept from the previous cell's c1 when adjacent), its
 * first node, the node pixel's column on this row (-1: none), smooth and coherent flags. */
static inline __attribute__((always_inline)) void enter_cell(const caustics_job *j, int i0, int i1, int j0, int j1,
                                                             float ty, int node_row, float *c0, float *c1,
                                                             const float **q00, int *cur, int *smooth,
                                                             int *node_col, int *coherent)
{
    const float *nodes = j->nodes;
    const int ns = j->node_size, nx = j->nx;
    if (i0 == *cur + 1 && i0 != 0)
        memcpy(c0, c1, NODE_MAX * sizeof(float));
    else
        column_at(j, j0, j1, ty, i0, c0);
    column_at(j, j0, j1, ty, i1, c1);
    *smooth = j->smooth ? j->smooth[(size_t)j0 * j->cx + i0] : 1;
    *q00 = nodes + ((size_t)j0 * nx + i0) * ns;
    *node_col = node_row && !isnan((*q00)[2]) ? j->node_x[i0] : -1;
    *coherent = j->p->lattice_shading &&
                cell_coherent(*q00, nodes + ((size_t)j0 * nx + i1) * ns, nodes + ((size_t)j1 * nx + i0) * ns,
                              nodes + ((size_t)j1 * nx + i1) * ns);
    *cur = i0;
}

/* lattice_shading's s and add (0 without seed mode or environment) at weight tx between
 * the cell's interpolated columns c0 and c1. */
static inline __attribute__((always_inline)) void lerp_s(int has_add, const float *c0, const float *c1, float tx,
                                                         float v[4])
{
    const float ux = 1.0f - tx;
    v[0] = c0[4] * ux + c1[4] * tx;
    if (!has_add) {
        v[1] = v[2] = v[3] = 0.0f;
        return;
    }
    for (int k = 1; k < 4; k++)
        v[k] = c0[4 + k] * ux + c1[4 + k] * tx;
}

/* A pixel shaded from s (and add) v: into the segment's lists, or at once. */
static inline __attribute__((always_inline)) void put_gain(const caustics_job *j, size_t i, const float *v,
                                                           int seg_shade, int32_t *st, float *sv, float *av,
                                                           float *nz)
{
    if (seg_shade) {
        *st = PX_GAIN;
        *sv = v[0];
        *av = *nz = 0.0f;
    } else {
        apply_s(j, i, v);
    }
}

/* A Position pass pixel as a world point; 0 when it is not one (far or not finite). */
static inline __attribute__((always_inline)) int position_at(const float *pq, fx_vec3 *P)
{
    *P = fx_v3(pq[0], pq[1], pq[2]);
    return fabsf(P->x) <= 1e15f && fabsf(P->y) <= 1e15f && isfinite(P->z);
}

/* Row y of dst is done: its NaN/Inf (an overflowing gain, or a non-finite source pixel of a
 * frame built through the API) replaced and counted while the row is in cache, so the stack
 * need not read the whole output again (FX_EFFECT_OWN_FINITE). */
static inline void finish_row(const fx_effect_run *run, int y)
{
    fx_effect_finish_row(run, run->dst + ((size_t)y * run->width + run->roi.x0) * 4,
                         (size_t)(run->roi.x1 - run->roi.x0) * 4);
}

static void caustics_rows(void *user, int begin, int end)
{
    const caustics_job *j = user;
    const fx_effect_run *run = j->run;
    const int w = run->width;
    const float tol = (float)(0.1 * j->cell); /* world units: a tenth of a cell */
    const int lattice_shading = j->p->lattice_shading;
    /* the segment shading: physical mode, no additive term; else each pixel is shaded at once */
    const int seg_shade = j->p->mode == MODE_PHYSICAL && !j->has_add, has_add = j->has_add;
    const float *cov = run->mask ? run->mask->coverage : NULL;
    const float *nodes = j->nodes, *position = j->position;
    const int pc = j->pos_channels;
    const int *col_i0 = j->col_i0, *col_i1 = j->col_i1;
    const float *col_t = j->col_t;
    fx_noise_cache cache = {0};
    int32_t st[SEG]; /* int32: shade_segment's loops vectorise */
    float av[SEG], nz[SEG], sv[SEG];
    for (int y = run->roi.y0 + begin; y < run->roi.y0 + end; y++) {
        int j0 = 0, j1 = 0;
        float ty = 0.0f;
        if (nodes)
            lattice_pos(j->node_y, j->ny, j->f, run->roi.y0, y, &j0, &j1, &ty);
        const int node_row = nodes && y == j->node_y[j0];
        /* the current lattice cell: its columns interpolated to this row, its node pixel's
         * column (-1: none on this row), its smooth and coherent flags */
        float c0[NODE_MAX], c1[NODE_MAX];
        const float *q00 = NULL;
        int cur = -1, smooth = 1, node_col = -1, coherent = 0;
        for (int xs = run->roi.x0; xs < run->roi.x1; xs += SEG) {
            const int n = run->roi.x1 - xs < SEG ? run->roi.x1 - xs : SEG;
            int patterns = 0;
            for (int c = 0; c < n; c++) {
                const int x = xs + c;
                const size_t i = (size_t)y * w + x;
                const int col = x - run->roi.x0;
                st[c] = PX_DONE;
                if (nodes && col_i0[col] != cur)
                    enter_cell(j, col_i0[col], col_i1[col], j0, j1, ty, node_row, c0, c1, &q00, &cur, &smooth,
                               &node_col, &coherent);
                fx_vec3 P;
                const int ok = position ? position_at(position + i * pc, &P) : world_at(j, x, y, &P);
                if ((cov && !(cov[i] > 0.0f)) || !ok) {
                    if (seg_shade) {
                        st[c] = PX_COPY;
                        sv[c] = av[c] = nz[c] = 0.0f;
                    } else if (run->dst != run->src) { /* in place: already the source */
                        memcpy(run->dst + i * 4, run->src + i * 4, 4 * sizeof(float));
                    }
                    continue;
                }
                if (coherent) { /* lattice_shading: no surface test */
                    float v[4];
                    lerp_s(has_add, c0, c1, col_t[col], v);
                    put_gain(j, i, v, seg_shade, st + c, sv + c, av + c, nz + c);
                    continue;
                }
                float a, noise;
                if (nodes) {
                    if (x == node_col) {
                        /* a lattice node: its own values (what interpolation would give) */
                        if (lattice_shading) {
                            put_gain(j, i, q00 + 4, seg_shade, st + c, sv + c, av + c, nz + c);
                            continue;
                        }
                        a = q00[0];
                        noise = q00[1];
                        goto emit;
                    }
                    const float tx = col_t[col], ux = 1.0f - tx;
#define LERP2(ch) (c0[ch] * ux + c1[ch] * tx)
                    /* a pixel whose corners are not on its surface (NaN corners fail too): exact */
                    if (fabsf(LERP2(2) - P.x) <= tol && fabsf(LERP2(3) - P.y) <= tol) {
                        if (lattice_shading) { /* s, and add (0 without seed mode or environment) */
                            float v[4];
                            lerp_s(has_add, c0, c1, tx, v);
                            put_gain(j, i, v, seg_shade, st + c, sv + c, av + c, nz + c);
                            continue;
                        }
                        noise = LERP2(1);
                        a = smooth ? LERP2(0) : value_at(j, P.x, P.y, NULL);
#undef LERP2
                        goto emit;
                    }
                }
                a = value_at(j, P.x, P.y, NULL);
                noise = noise_at(j, P.x, P.y, &cache);
            emit:
                if (seg_shade) {
                    st[c] = PX_PATTERN;
                    patterns = 1;
                    av[c] = a;
                    nz[c] = noise;
                } else {
                    shade(j, i, P, a, noise);
                }
            }
            if (seg_shade) {
                size_t i = (size_t)y * w + xs;
                shade_segment(j, run->src + i * 4, run->dst + i * 4, n, st, av, nz, sv, patterns);
            }
        }
        finish_row(run, y);
    }
}


/* The default path's rows (physical mode without an additive term, the Position pass, a
 * lattice without lattice_shading): the same values as caustics_rows, in passes over a
 * segment of SEG pixels: the lattice's columns interpolated to the row once (a node's
 * four channels as one vector), then per pixel its validity, its interpolated pattern and
 * its surface test with vector arithmetic, the pixels that need a search queued; then the
 * searches; then the shading (shade_segment). Each value is computed by the same float
 * operations, in the same order, as caustics_rows: the same bits. */
static void caustics_rows_lattice(void *user, int begin, int end)
{
    const caustics_job *j = user;
    const fx_effect_run *run = j->run;
    const int w = run->width, x0 = run->roi.x0, nx = j->nx;
    const float tol = (float)(0.1 * j->cell);
    const float *cov = run->mask ? run->mask->coverage : NULL;
    const float *nodes = j->nodes, *position = j->position;
    const int pc = j->pos_channels;
    const int *col_i0 = j->col_i0, *col_i1 = j->col_i1, *node_x = j->node_x;
    const float *col_t = j->col_t;
    const unsigned char *smooth_flags = j->smooth;
    const int batch = j->table.kind && j->p->method == METHOD_GRID;
    fx_noise_cache cache = {0};
    int32_t st[SEG]; /* int32: shade_segment's loops vectorise */
    float av[SEG], nz[SEG], sv[SEG];
    int queue[SEG];
    unsigned char exact[SEG];
    v4f *colv = NULL;
    /* a thread's row of interpolated lattice columns (nx vectors) */
    colv = fx_mem_alloc((size_t)nx * sizeof(v4f));
    if (!colv) { /* no memory for the row buffer: the per-pixel code, same bits */
        caustics_rows(user, begin, end);
        return;
    }
    for (int y = run->roi.y0 + begin; y < run->roi.y0 + end; y++) {
        int j0, j1;
        float ty;
        lattice_pos(j->node_y, j->ny, j->f, run->roi.y0, y, &j0, &j1, &ty);
        const int node_row = y == j->node_y[j0];
        {
            const float uy = 1.0f - ty;
            const float *a = nodes + (size_t)j0 * nx * 4, *b = nodes + (size_t)j1 * nx * 4;
            for (int i = 0; i < nx; i++)
                colv[i] = ld4(a + 4 * i) * uy + ld4(b + 4 * i) * ty;
        }
        const unsigned char *srow = smooth_flags ? smooth_flags + (size_t)j0 * j->cx : NULL;
        const float *nrow = nodes + (size_t)j0 * nx * 4;
        for (int xs = x0; xs < run->roi.x1; xs += SEG) {
            const int n = run->roi.x1 - xs < SEG ? run->roi.x1 - xs : SEG;
            int nq = 0, patterns = 0;
            for (int c = 0; c < n; c++) {
                const int x = xs + c, col = x - x0;
                const size_t i = (size_t)y * w + x;
                const float *pq = position + i * pc;
                const float px = pq[0], py = pq[1], pz = pq[2];
                const int ok = fabsf(px) <= 1e15f && fabsf(py) <= 1e15f && isfinite(pz);
                if ((cov && !(cov[i] > 0.0f)) || !ok) {
                    st[c] = PX_COPY;
                    sv[c] = av[c] = nz[c] = 0.0f;
                    continue;
                }
                const int i0 = col_i0[col];
                const float *q00 = nrow + 4 * i0;
                st[c] = PX_PATTERN;
                if (node_row && x == node_x[i0] && !isnan(q00[2])) { /* a lattice node: its own values */
                    av[c] = q00[0];
                    nz[c] = q00[1];
                    continue;
                }
                const float tx = col_t[col], ux = 1.0f - tx;
                const v4f v = colv[i0] * ux + colv[col_i1[col]] * tx;
                if (fabsf(v[2] - px) <= tol && fabsf(v[3] - py) <= tol) {
                    nz[c] = v[1];
                    if (!srow || srow[i0]) {
                        av[c] = v[0];
                        continue;
                    }
                    exact[nq] = 0;
                } else {
                    exact[nq] = 1;
                }
                queue[nq++] = c;
            }
            if (batch) { /* the searches in one batch (fast kinds, grid): value_at's bits */
                double qx[SEG], qy[SEG], f1[SEG], f2[SEG];
                for (int k = 0; k < nq; k++) {
                    const float *pq = position + ((size_t)y * w + xs + queue[k]) * pc;
                    qx[k] = (double)pq[0] * j->inv_cell_d;
                    qy[k] = (double)pq[1] * j->inv_cell_d;
                    fx_voronoi_warp_apply(&j->warp, &qx[k], &qy[k]);
                }
                fx_voronoi_table_grid_n(&j->table, nq, qx, qy, f1, f2, NULL, NULL);
                for (int k = 0; k < nq; k++) {
                    const double v = f2[k] - f1[k];
                    av[queue[k]] = !(v >= 0.0) ? 0.0f : v > 1e30 ? 1e30f : (float)v;
                }
            }
            for (int k = 0; k < nq; k++) {
                const int c = queue[k];
                const float *pq = position + ((size_t)y * w + xs + c) * pc;
                if (!batch)
                    av[c] = value_at(j, pq[0], pq[1], NULL);
                if (exact[k])
                    nz[c] = noise_at(j, pq[0], pq[1], &cache);
            }
            for (int c = 0; c < n && !patterns; c++)
                patterns = st[c] == PX_PATTERN;
            size_t i = (size_t)y * w + xs;
            shade_segment(j, run->src + i * 4, run->dst + i * 4, n, st, av, nz, sv, patterns);
        }
        finish_row(run, y);
    }
    fx_mem_free(colv);
}

/* The focus gain s = strength noise' (min(g / mean, 16) - 1), g = exp(-a / line_width): the
 * operations of shade_segment's pattern pixels, one pixel. */
static inline float focus_s(const caustics_job *j, float a, float noise)
{
    float x = -a * j->inv_lw;
    x = x > -87.0f ? x : -87.0f;
    x = x < 0.0f ? x : 0.0f;
    float g = exp_neg(x) * j->inv_mean;
    g = g + j->focus0;
    g = (g < (float)FOCUS_MAX ? g : (float)FOCUS_MAX) - 1.0f;
    const float amp = j->p->strength * (0.4f + 1.2f * noise);
    return amp * g;
}

/* out = src (1 + s tint) (s4: s in every lane), colour clamped to [0, FLT_MAX] (NaN to 0); alpha: src x (1 + s 0),
 * the source's finite alpha bit for bit (lo's -FLT_MAX lane keeps it) */
static inline __attribute__((always_inline)) void apply_gain(const float *src, float *dst, v4f s4, v4f tint)
{
    const v4f in = ld4(src);
    const v4f v = in * (1.0f + s4 * tint);
    const v4f lo = {0.0f, 0.0f, 0.0f, -FLT_MAX}, hi = {FLT_MAX, FLT_MAX, FLT_MAX, FLT_MAX};
#ifdef __SSE2__ /* maxps(v, lo) is lo for NaN (its second operand) */
    const v4f r = _mm_min_ps(_mm_max_ps(v, lo), hi);
#else
    v4f r = (v4f)(((v4i)v & (v > lo)) | ((v4i)lo & ~(v > lo)));
    r = (v4f)(((v4i)r & (r < hi)) | ((v4i)hi & ~(r < hi)));
#endif
    memcpy(dst, &r, sizeof r);
}

#define GAIN_QUEUE 128 /* caustics_rows_gain's pixels waiting for their own search */

/* caustics_rows_gain's pixels off their corners' surface, searched in batches: the
 * searches of fx_voronoi_table_grid_n (value_at's bits), then noise and s one pixel after
 * the other in short loops (no long dependency chain per pixel). */
typedef struct gain_queue {
    int n;
    size_t at[GAIN_QUEUE]; /* pixel index */
    float px[GAIN_QUEUE], py[GAIN_QUEUE];
    double qx[GAIN_QUEUE], qy[GAIN_QUEUE], f1[GAIN_QUEUE], f2[GAIN_QUEUE]; /* gain_flush's */
    fx_noise_cache cache;
} gain_queue;

static __attribute__((noinline)) void gain_flush(const caustics_job *j, gain_queue *q)
{
    const fx_effect_run *run = j->run;
    const v4f tint = {j->p->tint[0], j->p->tint[1], j->p->tint[2], 0.0f};
    const int n = q->n;
    float a[GAIN_QUEUE], sv[GAIN_QUEUE];
    if (j->table.kind && j->p->method == METHOD_GRID) {
        double *qx = q->qx, *qy = q->qy, *f1 = q->f1, *f2 = q->f2;
        for (int k = 0; k < n; k++) {
            qx[k] = (double)q->px[k] * j->inv_cell_d;
            qy[k] = (double)q->py[k] * j->inv_cell_d;
            fx_voronoi_warp_apply(&j->warp, &qx[k], &qy[k]);
        }
        fx_voronoi_table_grid_n(&j->table, n, qx, qy, f1, f2, NULL, NULL);
        for (int k = 0; k < n; k++) {
            const double v = f2[k] - f1[k];
            a[k] = !(v >= 0.0) ? 0.0f : v > 1e30 ? 1e30f : (float)v;
        }
    } else {
        for (int k = 0; k < n; k++)
            a[k] = value_at(j, q->px[k], q->py[k], NULL);
    }
    for (int k = 0; k < n; k++)
        sv[k] = noise_at(j, q->px[k], q->py[k], &q->cache);
    for (int k = 0; k < n; k++)
        sv[k] = focus_s(j, a[k], sv[k]);
    for (int k = 0; k < n; k++) {
        const float sk = sv[k];
        apply_gain(run->src + q->at[k] * 4, run->dst + q->at[k] * 4, (v4f){sk, sk, sk, sk}, tint);
    }
    q->n = 0;
}

/* caustics_rows_gain's pixel x of row y whose corners, interpolated to it, give s and world
 * XY (wx, wy): no position or outside the mask: the source; its corners on its surface
 * (interpolated world XY within a tenth of a cell of its own): s; else queued for its own
 * search, noise and s (gain_flush). */
static __attribute__((noinline)) void gain_pixel(const caustics_job *j, int x, int y, float s, float wx, float wy,
                                                 gain_queue *q)
{
    const fx_effect_run *run = j->run;
    const size_t i = (size_t)y * run->width + x;
    const float *pq = j->position + i * j->pos_channels;
    const float px = pq[0], py = pq[1], pz = pq[2];
    const int ok = fabsf(px) <= 1e15f && fabsf(py) <= 1e15f && isfinite(pz);
    if ((run->mask && !(run->mask->coverage[i] > 0.0f)) || !ok) {
        if (run->dst != run->src) /* in place: already the source */
            memcpy(run->dst + i * 4, run->src + i * 4, 4 * sizeof(float));
        return;
    }
    const float tol = (float)(GAIN_TOL * j->cell);
    if (fabsf(wx - px) <= tol && fabsf(wy - py) <= tol) { /* NaN corners fail */
        const v4f tint = {j->p->tint[0], j->p->tint[1], j->p->tint[2], 0.0f};
        apply_gain(run->src + i * 4, run->dst + i * 4, (v4f){s, s, s, s}, tint);
        return;
    }
    if (q->n == GAIN_QUEUE)
        gain_flush(j, q);
    q->at[q->n] = i;
    q->px[q->n] = px;
    q->py[q->n++] = py;
}

#define GAIN_CHUNK 1024 /* pixels of a row per pass of caustics_rows_gain's general path */

/* Two four-lane vectors as one of eight lanes (a register pair in the baseline clone, one
 * AVX register in the AVX2 clone), and lane k of a four-lane vector in every lane. */
static inline __attribute__((always_inline)) v8f cat8(v4f a, v4f b)
{
    return (v8f){a[0], a[1], a[2], a[3], b[0], b[1], b[2], b[3]};
}
#ifdef __SSE2__
#define BCAST4(v, k) ((v4f)_mm_shuffle_ps((v), (v), _MM_SHUFFLE(k, k, k, k)))
#else
#define BCAST4(v, k) ((v4f){(v)[k], (v)[k], (v)[k], (v)[k]})
#endif

/* caustics_rows_gain's constants, and its eight pixels at a time. */
typedef struct gain_ctx {
    const caustics_job *j;
    const float *cov;
    int pc;
    int in_place; /* dst == src */
    v4f tint, vtol;
} gain_ctx;

/* Pixels x .. x + 7 of row y with their s, world x and y interpolated from their corners,
 * four at a time (the baseline clone compares eight lanes one by one): positions,
 * validity, mask and surface test, then apply_gain per pixel; the pixels that fail the test
 * (no position, masked out, off their corners' surface: a silhouette, a step) are instead
 * done one at a time by gain_pixel (the same operations: no pixel's bits depend on its
 * neighbours). */
static inline __attribute__((always_inline)) void gain_octet4(const gain_ctx *g, int x, int y, v8f s8, v8f wx8,
                                                             v8f wy8, gain_queue *q)
{
    const caustics_job *j = g->j;
    const fx_effect_run *run = j->run;
    const int pc = g->pc;
    const v4i absm = {0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff};
    const v4f big = V4(1e15f), zero = V4(0.0f), vtol = g->vtol;
    for (int h = 0; h < 2; h++) {
        const v4f s4 = h ? (v4f){s8[4], s8[5], s8[6], s8[7]} : (v4f){s8[0], s8[1], s8[2], s8[3]};
        const v4f wx = h ? (v4f){wx8[4], wx8[5], wx8[6], wx8[7]} : (v4f){wx8[0], wx8[1], wx8[2], wx8[3]};
        const v4f wy = h ? (v4f){wy8[4], wy8[5], wy8[6], wy8[7]} : (v4f){wy8[0], wy8[1], wy8[2], wy8[3]};
        const size_t i = (size_t)y * run->width + x + 4 * h;
        const float *pq = j->position + i * pc;
        v4f px, py, pz;
        if (pc == 3) {
            ld3x4(pq, &px, &py, &pz);
        } else {
            px = (v4f){pq[0], pq[pc], pq[2 * pc], pq[3 * pc]};
            py = (v4f){pq[1], pq[pc + 1], pq[2 * pc + 1], pq[3 * pc + 1]};
            pz = (v4f){pq[2], pq[pc + 2], pq[2 * pc + 2], pq[3 * pc + 2]};
        }
        v4i ok = ((v4f)((v4i)px & absm) <= big) & ((v4f)((v4i)py & absm) <= big) & ((pz - pz) == zero) &
                 ((v4f)((v4i)(wx - px) & absm) <= vtol) & ((v4f)((v4i)(wy - py) & absm) <= vtol);
        if (g->cov)
            ok &= ld4(g->cov + i) > zero;
        const float *src = run->src + i * 4;
        float *dst = run->dst + i * 4;
        if (all4(ok)) {
            apply_gain(src, dst, BCAST4(s4, 0), g->tint);
            apply_gain(src + 4, dst + 4, BCAST4(s4, 1), g->tint);
            apply_gain(src + 8, dst + 8, BCAST4(s4, 2), g->tint);
            apply_gain(src + 12, dst + 12, BCAST4(s4, 3), g->tint);
        } else { /* a failing pixel is not written here: in place, gain_pixel reads its source */
            for (int l = 0; l < 4; l++)
                if (ok[l])
                    apply_gain(src + 4 * l, dst + 4 * l, (v4f){s4[l], s4[l], s4[l], s4[l]}, g->tint);
                else
                    gain_pixel(j, x + 4 * h + l, y, s4[l], wx[l], wy[l], q);
        }
    }
}

/* gain_octet4 in eight lanes (the AVX2 clone; the baseline clone would compare lane by lane):
 * positions, validity, mask and surface test, then out = src (1 + s tint) clamped, by
 * apply_gain's operations lane by lane (colour in [0, FLT_MAX], NaN to 0; alpha in
 * [-FLT_MAX, FLT_MAX], NaN to -FLT_MAX); the pixels that fail the test (no position,
 * masked out, off their corners' surface: a silhouette, a step) keep their source and are
 * then done one at a time by gain_pixel (the same operations: no pixel's bits depend on its
 * neighbours). */
static inline __attribute__((always_inline)) void gain_octet8(const gain_ctx *g, int x, int y, v8f s8, v8f wx,
                                                             v8f wy, gain_queue *q)
{
    const caustics_job *j = g->j;
    const fx_effect_run *run = j->run;
    const int pc = g->pc;
    const v8i absm = {0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff};
    const v8f big = S8(1e15f), zero = S8(0.0f), one = S8(1.0f), fmax = S8(FLT_MAX), amin = S8(-FLT_MAX);
    const v8f vtol8 = S8(g->vtol[0]);
    const size_t i = (size_t)y * run->width + x;
    const float *pq = j->position + i * pc;
    v8f px, py, pz;
    if (pc == 3) {
        const v8f m0 = fx_load8(pq), m1 = fx_load8(pq + 8), m2 = fx_load8(pq + 16);
        const v8f ux = FX_SHUF8(m0, m1, 0, 3, 6, 9, 12, 15, 0, 0);
        const v8f uy = FX_SHUF8(m0, m1, 1, 4, 7, 10, 13, 0, 0, 0);
        const v8f uz = FX_SHUF8(m0, m1, 2, 5, 8, 11, 14, 0, 0, 0);
        px = FX_SHUF8(ux, m2, 0, 1, 2, 3, 4, 5, 10, 13);
        py = FX_SHUF8(uy, m2, 0, 1, 2, 3, 4, 8, 11, 14);
        pz = FX_SHUF8(uz, m2, 0, 1, 2, 3, 4, 9, 12, 15);
    } else if (pc == 4) {
        v8f m[4];
        fx_load8x4(pq, m);
        px = m[0];
        py = m[1];
        pz = m[2];
    } else { /* other channel counts (not written by Blender) */
        float q[3][8];
        for (int ch = 0; ch < 3; ch++)
            for (int l = 0; l < 8; l++)
                q[ch][l] = pq[(size_t)l * pc + ch];
        px = fx_load8(q[0]);
        py = fx_load8(q[1]);
        pz = fx_load8(q[2]);
    }
    v8i ok = ((v8f)((v8i)px & absm) <= big) & ((v8f)((v8i)py & absm) <= big) & ((pz - pz) == zero) &
             ((v8f)((v8i)(wx - px) & absm) <= vtol8) & ((v8f)((v8i)(wy - py) & absm) <= vtol8);
    if (g->cov)
        ok &= fx_load8(g->cov + i) > zero;
    v8f p[4];
    fx_load8x4(run->src + i * 4, p);
    v8f o[4] = {p[0] * (one + s8 * S8(g->tint[0])), p[1] * (one + s8 * S8(g->tint[1])), p[2] * (one + s8 * S8(g->tint[2])),
                p[3] * (one + s8 * zero)};
    for (int ch = 0; ch < 3; ch++) {
        const v8f m = (v8f)((v8i)o[ch] & (o[ch] > zero));
        o[ch] = SEL8(m < fmax, m, fmax);
    }
    o[3] = SEL8(o[3] > amin, o[3], amin);
    o[3] = SEL8(o[3] < fmax, o[3], fmax);
    const int all = fx_all8(ok);
    if (!all && g->in_place) /* in place: a failing pixel keeps its source for gain_pixel */
        for (int ch = 0; ch < 4; ch++)
            o[ch] = SEL8(ok, o[ch], p[ch]);
    fx_store8x4(run->dst + i * 4, o);
    if (!all)
        for (int l = 0; l < 8; l++)
            if (!ok[l])
                gain_pixel(j, x + l, y, s8[l], wx[l], wy[l], q);
}

/* caustics_rows_gain's parts, inlined into each of its clones. */
#define GAIN_PART static inline __attribute__((always_inline))

/* downsample 4: the row's columns' s, world x and y (cs, cx, cy), each node's value at this
 * row (ld4(a) uy + ld4(b) ty), eight nodes at a time where the clone is wide. */
GAIN_PART void gain_row_columns(const caustics_job *j, const float *a, const float *b, float uy, float ty, float *cs,
                                float *cx, float *cy)
{
    const int nx = j->nx;
    int i = 0;
    if (j->wide) { /* eight nodes at a time: ld4(a) uy + ld4(b) ty, channel by channel */
        const v8f uy8 = S8(uy), ty8 = S8(ty);
        for (; i + 8 <= nx; i += 8) {
            v8f na[4], nb[4];
            fx_load8x4(a + 4 * i, na);
            fx_load8x4(b + 4 * i, nb);
            fx_store8(cs + i, na[0] * uy8 + nb[0] * ty8);
            fx_store8(cx + i, na[2] * uy8 + nb[2] * ty8);
            fx_store8(cy + i, na[3] * uy8 + nb[3] * ty8);
        }
    }
    for (; i < nx; i++) { /* the general path's L, channel by channel */
        const v4f c = ld4(a + 4 * i) * uy + ld4(b + 4 * i) * ty;
        cs[i] = c[0];
        cx[i] = c[2];
        cy[i] = c[3];
    }
}

/* downsample 4: octets of two cells of 4 pixels from the row's columns (cs, cx, cy), all
 * but the row's last cell (x1 - 1's, which may be longer). Returns the first cell left to
 * the general path. */
GAIN_PART int gain_row_octets(const gain_ctx *g, int y, const float *cs, const float *cx, const float *cy,
                              gain_queue *q)
{
    const caustics_job *j = g->j;
    const int x0 = j->run->roi.x0, ncx = j->nx > 1 ? j->nx - 1 : 1;
    const float *col_t = j->col_t;
    int cfirst = 0;
    for (; cfirst + 2 < ncx; cfirst += 2) {
        const int x = x0 + 4 * cfirst;
        const v8f t = fx_load8(col_t + (x - x0));
        v8f ls, rs, lx, rx, ly, ry;
        if (j->wide) { /* one permute per vector in the AVX2 clone */
            const v8f vs = fx_load8(cs + cfirst), vx = fx_load8(cx + cfirst), vy = fx_load8(cy + cfirst);
            ls = FX_SHUF8(vs, vs, 0, 0, 0, 0, 1, 1, 1, 1);
            rs = FX_SHUF8(vs, vs, 1, 1, 1, 1, 2, 2, 2, 2);
            lx = FX_SHUF8(vx, vx, 0, 0, 0, 0, 1, 1, 1, 1);
            rx = FX_SHUF8(vx, vx, 1, 1, 1, 1, 2, 2, 2, 2);
            ly = FX_SHUF8(vy, vy, 0, 0, 0, 0, 1, 1, 1, 1);
            ry = FX_SHUF8(vy, vy, 1, 1, 1, 1, 2, 2, 2, 2);
        } else { /* broadcasts: the baseline clone has no eight-lane shuffles */
            const v4f s0 = V4(cs[cfirst]), s1 = V4(cs[cfirst + 1]), s2 = V4(cs[cfirst + 2]);
            const v4f p0 = V4(cx[cfirst]), p1 = V4(cx[cfirst + 1]), p2 = V4(cx[cfirst + 2]);
            const v4f q0 = V4(cy[cfirst]), q1 = V4(cy[cfirst + 1]), q2 = V4(cy[cfirst + 2]);
            ls = cat8(s0, s1);
            rs = cat8(s1, s2);
            lx = cat8(p0, p1);
            rx = cat8(p1, p2);
            ly = cat8(q0, q1);
            ry = cat8(q1, q2);
        }
        const v8f sv8 = ls + t * (rs - ls), xv8 = lx + t * (rx - lx), yv8 = ly + t * (ry - ly);
        if (j->wide)
            gain_octet8(g, x, y, sv8, xv8, yv8, q);
        else
            gain_octet4(g, x, y, sv8, xv8, yv8, q);
    }
    return cfirst;
}

/* The n pixels from xa of row y with their values in sv, xv, yv: eight at a time, the rest
 * one at a time (an octet overlapping the one before would read, in place, pixels that one
 * wrote). */
GAIN_PART void gain_chunk(const gain_ctx *g, int xa, int y, int n, const float *sv, const float *xv, const float *yv,
                          gain_queue *q)
{
    const int noct = n / 8, wide = g->j->wide;
    for (int k = 0; k < noct; k++) {
        const int c = 8 * k;
        if (wide)
            gain_octet8(g, xa + c, y, fx_load8(sv + c), fx_load8(xv + c), fx_load8(yv + c), q);
        else
            gain_octet4(g, xa + c, y, fx_load8(sv + c), fx_load8(xv + c), fx_load8(yv + c), q);
    }
    for (int c = 8 * noct; c < n; c++)
        gain_pixel(g->j, xa + c, y, sv[c], xv[c], yv[c], q);
}

/* lattice_shading's path (draft) in physical mode without an additive term, from the
 * Position pass: the nodes hold the focus gain s (focus_s of their pattern and noise); a
 * pixel's s and world XY are its corners' bilinear interpolation (row first: L and R, the
 * lattice cell's columns at this row; then L + t (R - L)), then gain_octet. FX_CLONES: one
 * AVX2 register per channel where the CPU has it. downsample 4 (the draft): per row, the
 * columns' s, x, y as arrays, and eight pixels (two lattice cells) take theirs by constant
 * shuffles; the row's last cell (up to 5 pixels) and other downsamples: per chunk of whole
 * cells, the pixels' values into arrays four at a time, then eight pixels at a time. */
FX_CLONES static void caustics_rows_gain(void *user, int begin, int end)
{
    const caustics_job *j = user;
    const fx_effect_run *run = j->run;
    const int x0 = run->roi.x0, x1 = run->roi.x1, nx = j->nx, f = j->f;
    const int ncx = nx > 1 ? nx - 1 : 1;
    const int per_chunk = (GAIN_CHUNK - 1) / f; /* cells: each has at most f + 1 pixels */
    const float *col_t = j->col_t;
    const float tol = (float)(GAIN_TOL * j->cell);
    const gain_ctx g = {j, run->mask ? run->mask->coverage : NULL, j->pos_channels, run->dst == run->src,
                        {j->p->tint[0], j->p->tint[1], j->p->tint[2], 0.0f}, V4(tol)};
    gain_queue q;
    q.n = 0;
    memset(&q.cache, 0, sizeof q.cache);
    /* downsample 4: the row's columns (8 more for the last octet's loads) */
    const int quick = f == 4 && nx > 1;
    float *cols = quick ? fx_mem_alloc((size_t)3 * (nx + 8) * sizeof(float)) : NULL;
    float *cs = cols, *cx = cols ? cols + nx + 8 : NULL, *cy = cols ? cols + 2 * (nx + 8) : NULL;
    float sv[GAIN_CHUNK], xv[GAIN_CHUNK], yv[GAIN_CHUNK];
    for (int y = run->roi.y0 + begin; y < run->roi.y0 + end; y++) {
        int j0, j1;
        float ty;
        lattice_pos(j->node_y, j->ny, f, run->roi.y0, y, &j0, &j1, &ty);
        const float uy = 1.0f - ty;
        const float *a = j->nodes + (size_t)j0 * nx * 4, *b = j->nodes + (size_t)j1 * nx * 4;
        int cfirst = 0; /* the first lattice cell left to the general path */
        if (cols) {
            gain_row_columns(j, a, b, uy, ty, cs, cx, cy);
            cfirst = gain_row_octets(&g, y, cs, cx, cy, &q);
        }
        for (int cc0 = cfirst; cc0 < ncx; cc0 += per_chunk) {
            const int cc1 = cc0 + per_chunk < ncx ? cc0 + per_chunk : ncx;
            const int xa = x0 + cc0 * f, xb = cc1 == ncx ? x1 : x0 + cc1 * f;
            /* the pixels' s, world x, y (four at a time: a cell of 4 pixels or more ends
             * with the quad at xe - 4, overlapping: the same values written again) */
            v4f L = ld4(a + 4 * cc0) * uy + ld4(b + 4 * cc0) * ty;
            for (int cc = cc0; cc < cc1; cc++) {
                const int i1 = nx > 1 ? cc + 1 : 0;
                const v4f R = ld4(a + 4 * i1) * uy + ld4(b + 4 * i1) * ty;
                const v4f D = R - L;
                const int xs = x0 + cc * f, xe = cc == ncx - 1 ? x1 : xs + f;
                const v4f ls = V4(L[0]), ds = V4(D[0]), lx = V4(L[2]), dx = V4(D[2]), ly = V4(L[3]), dy = V4(D[3]);
                const int nquad = xe - xs >= 4 ? (xe - xs + 3) / 4 : 0;
                for (int k = 0; k < nquad; k++) {
                    const int x = xs + 4 * k + 4 <= xe ? xs + 4 * k : xe - 4;
                    const v4f t4 = ld4(col_t + (x - x0));
                    st4(sv + (x - xa), ls + t4 * ds);
                    st4(xv + (x - xa), lx + t4 * dx);
                    st4(yv + (x - xa), ly + t4 * dy);
                }
                for (int x = nquad ? xe : xs; x < xe; x++) {
                    const float t = col_t[x - x0];
                    sv[x - xa] = L[0] + t * D[0];
                    xv[x - xa] = L[2] + t * D[2];
                    yv[x - xa] = L[3] + t * D[3];
                }
                L = R;
            }
            gain_chunk(&g, xa, y, xb - xa, sv, xv, yv, &q);
        }
        if (q.n)
            gain_flush(j, &q);
        finish_row(run, y);
    }
    fx_mem_free(cols);
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
    const fx_voronoi_table *t = &m->cj->table;
    for (int r = begin; r < end; r++) {
        double acc = 0.0;
        for (int c = 0; c < m->n; c++) {
            fx_voronoi_hit h;
            double x = (c + 0.5) * t->grid / m->n, y = (r + 0.5) * t->grid / m->n;
            fx_voronoi_warp_apply(&m->cj->warp, &x, &y);
            fx_voronoi_table_grid(t, x, y, &h);
            acc += pattern_g(m->cj->p, &h);
        }
        m->partial[r] = acc;
    }
}

static void list_rows(void *user, int begin, int end)
{
    fx_voronoi_table_build_lists(user, begin, end);
}

static void job_free(caustics_job *j)
{
    fx_voronoi_table_free(&j->table);
    fx_voronoi_warp_free(&j->warp);
    fx_mem_free(j->node_x);
    fx_mem_free(j->node_y);
    fx_mem_free(j->cell_any);
    fx_mem_free(j->nodes);
    fx_mem_free(j->node_id);
    fx_mem_free(j->smooth);
    fx_mem_free(j->col_i0);
    fx_mem_free(j->col_i1);
    fx_mem_free(j->col_t);
}

/* Lattice positions along one axis of the ROI [a, b): every f-th pixel, the last on b - 1 */
static int *lattice_axis(int a, int b, int f, int *n)
{
    int len = b - a;
    *n = len <= 1 ? 1 : (len - 2) / f + 2;
    int *v = fx_mem_alloc((size_t)*n * sizeof(int));
    if (!v)
        return NULL;
    for (int i = 0; i < *n; i++)
        v[i] = i == *n - 1 ? b - 1 : a + i * f;
    return v;
}

/* Process stage 1: the job's constants from the parameters and the frame's time. */
/* cell_scale auto: the cell from the waves' mean wavelength in the water's view (world
 * normals, the texels' world points from its Depth); without the view, or with nothing to
 * estimate from, the manual cell stays (a warning says why). */
static void auto_cell(const fx_effect_run *run, const caustics_params *p, double *cell)
{
    char name[FX_NAME_MAX];
    snprintf(name, sizeof name, "water:%.80s", p->water);
    if (fx_aux_view_has(run->frame, name) != FX_AUX_LISTED) {
        fx_warn(run->ctx, "%s: cell_scale auto: no aux view '%s' (the water's view from the Sun): the manual cell "
                "(tile_size / sqrt(points)) is used", run->where, name);
        return;
    }
    fx_aux_view *av = NULL;
    if (fx_aux_view_load(run->frame, name, run->where, &av) != FX_OK) {
        fx_warn(run->ctx, "%s: cell_scale auto: the view '%s' could not be read: the manual cell is used", run->where,
                name);
        return;
    }
    const fx_pass *np = fx_frame_find_pass(av->frame, "Normal");
    const int w = av->width, h = av->height;
    float *xy = np && np->channels >= 3 ? fx_mem_alloc((size_t)w * h * 2 * sizeof(float)) : NULL;
    unsigned char *valid = xy ? fx_mem_alloc((size_t)w * h) : NULL;
    double lambda = 0.0;
    int ok = -1;
    if (valid) {
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                size_t i = (size_t)y * w + x;
                float d = av->depth[i];
                valid[i] = isfinite(d) && d > 0.0f && d < 1e9f;
                fx_vec3 P = fx_view_to_world(
                    &av->view, fx_view_position(&av->view, fx_view_pixel_to_ndc(&av->view, x + 0.5f, y + 0.5f),
                                                valid[i] ? d : 1.0f));
                xy[2 * i] = P.x;
                xy[2 * i + 1] = P.y;
            }
        ok = fx_wave_length(np->data, np->channels, xy, valid, w, h, &lambda);
    }
    fx_mem_free(xy);
    fx_mem_free(valid);
    fx_aux_view_free(av);
    double c = (double)p->wave_cell_ratio * lambda;
    if (ok || !(c > 1e-9) || !(c < 1e9)) {
        fx_warn(run->ctx, "%s: cell_scale auto: no wavelength could be estimated from '%s' (%s): the manual cell is "
                "used", run->where, name, np && np->channels >= 3 ? "a flat or too small water surface" : "no Normal pass");
        return;
    }
    *cell = c;
}

static void job_init(const fx_effect_run *run, const caustics_params *p, caustics_job *j)
{
    memset(j, 0, sizeof *j);
    j->run = run;
    j->p = p;
    j->vor.grid = fx_voronoi_grid_for_points(p->points);
    j->vor.seed = (uint32_t)p->seed;
    j->time = fx_effect_scene_time(run);
    j->vor.time = j->time;
    j->vor.speed = p->speed;
    j->vor.p = exponent_of(p);
    j->cell = (double)p->tile_size / j->vor.grid;
    if (p->mode != MODE_REFRACTIVE && p->cell_scale == CELL_AUTO)
        auto_cell(run, p, &j->cell);
    j->inv_lw = (float)(1.0 / p->line_width);
    j->inv_cell = (float)(1.0 / j->cell);
    j->inv_cell_d = 1.0 / j->cell;
    /* the warp's waves drift at a fifth of the points' speed: the network flows as they wander */
    fx_voronoi_warp_init(&j->warp, j->vor.grid, (uint32_t)p->seed, p->mode == MODE_REFRACTIVE ? 0.0 : p->warp,
                         0.2 * p->speed * j->time);
    j->warp_lip = (float)j->warp.lipschitz;
    /* exp(-10) = 5e-5: below any visible change of the focus ratio */
    j->far_gap = p->mode == MODE_PHYSICAL && exponent_of(p) >= 1.0 ? (float)(10.0 * p->line_width) : 0.0f;
    j->wave = (float)sin(2.0 * j->time);
    j->has_view = fx_view_init(&j->view, run->frame);
    /* caustics_rows_gain's eight-lane path where its code is AVX2 code: the whole build
     * targets AVX2, or FX_CLONES (math/clones.h: gcc on x86) has made an AVX2 clone, which
     * its resolver picks under this condition. Either path gives the same bits. */
#if defined(__AVX2__)
    j->wide = 1;
#elif defined(FX_CLONES_AVX2)
    j->wide = __builtin_cpu_supports("avx2") != 0;
#endif
}

/* Process stage 2: the passes the parameters read (Position or Depth, Normal) and the
 * environment image; *envf is the caller's to free. */
static fx_result job_inputs(const fx_effect_run *run, const caustics_params *p, caustics_job *j, fx_frame **envf)
{
    const char *where = run->where;
    if (caustics_needs_camera(p) && !j->has_view)
        return fx_fail(run->ctx, FX_ERR_NO_CAMERA,
                       "%s needs the frame's camera (position_source depth, environment_strength > 0 or "
                       "refractive with receiver_depth > 0); "
                       "give the scene sidecar with --sidecar",
                       where);
    if (p->position_source == POS_POSITION) {
        const fx_pass *pp = fx_frame_find_pass(run->frame, "Position");
        if (!pp || pp->channels < 3)
            return fx_fail(run->ctx, FX_ERR_MISSING_PASS,
                           "%s: needs the Position pass (or set position_source to depth)", where);
        j->position = pp->data;
        j->pos_channels = pp->channels;
    } else {
        const fx_pass *dp = fx_frame_find_pass(run->frame, "Depth");
        if (!dp)
            return fx_fail(run->ctx, FX_ERR_MISSING_PASS, "%s: position_source depth needs the Depth pass", where);
        j->depth = dp->data;
    }
    if (p->environment_strength > 0.0f) {
        const fx_pass *np = fx_frame_find_pass(run->frame, "Normal");
        if (!np || np->channels < 3)
            return fx_fail(run->ctx, FX_ERR_MISSING_PASS, "%s: environment_strength > 0 needs the Normal pass", where);
        j->normal = np->data;
        j->eye = fx_v3(j->view.camera_to_world[3], j->view.camera_to_world[7], j->view.camera_to_world[11]);
        if (p->environment[0]) {
            fx_result r = fx_frame_read_exr(run->ctx, p->environment, NULL, envf);
            if (r != FX_OK)
                return r;
            const fx_pass *ep = fx_frame_find_pass(*envf, "Combined");
            if (!ep || ep->channels != 4) {
                fx_frame_free(*envf);
                *envf = NULL;
                return fx_fail(run->ctx, FX_ERR_MISSING_PASS, "%s: environment '%s' has no RGBA image", where,
                               p->environment);
            }
            j->env.rgba = ep->data;
            j->env.w = (*envf)->width;
            j->env.h = (*envf)->height;
        }
    }
    return FX_OK;
}

/* Process stage 3: the Voronoi table; the square lists cost about two ring searches per
 * square: built (in parallel) only when the ROI has many more pixels than squares (same
 * bits either way). -1: out of memory. */
static void warp_rows(void *user, int begin, int end)
{
    fx_voronoi_warp_table_rows(user, begin, end);
}

static int job_table(const fx_effect_run *run, const caustics_params *p, caustics_job *j)
{
    double area = (double)(run->roi.x1 - run->roi.x0) * (run->roi.y1 - run->roi.y0);
    double squares = 16.0 * j->vor.grid * j->vor.grid;
    int fast = p->distance != DIST_FAST ? 0 : area >= 16.0 * squares ? 2 : 3;
    if (fx_voronoi_table_init(&j->table, &j->vor, fast) != 0)
        return -1;
    int wt = fx_voronoi_warp_table_alloc(&j->warp);
    if (wt < 0)
        return -1;
    if (wt > 0) /* each sample computed alone: the same bits for any thread count */
        fx_parallel_for(run->ctx, j->warp.n, 8, warp_rows, &j->warp);
    if (j->table.sub)
        fx_parallel_for(run->ctx, j->vor.grid, 1, list_rows, &j->table);
    return 0;
}

/* Process stage 4 (physical mode): the pattern's mean focus, the normalisation. */
static int job_mean(const fx_effect_run *run, const caustics_params *p, caustics_job *j)
{
    j->mean_g = 1.0;
    if (p->mode == MODE_PHYSICAL) {
        mean_job m = {j, NULL, 64};
        m.partial = fx_mem_alloc((size_t)m.n * sizeof(double));
        if (!m.partial)
            return -1;
        fx_parallel_for(run->ctx, m.n, 1, mean_rows, &m);
        double acc = 0.0;
        for (int r = 0; r < m.n; r++)
            acc += m.partial[r];
        fx_mem_free(m.partial);
        j->mean_g = acc / ((double)m.n * m.n);
        if (!(j->mean_g > 1e-12))
            j->mean_g = 1e-12;
    }
    /* the focus interior + (1 - interior) g over its mean interior + (1 - interior) mean(g) */
    double in = p->mode == MODE_PHYSICAL ? (double)p->interior : 0.0;
    double m = in + (1.0 - in) * j->mean_g;
    j->inv_mean = (float)fmin((1.0 - in) / m, 1e30);
    j->focus0 = (float)(in / m);
    return 0;
}

/* Process stage 5 (downsample > 1): the lattice's axes, nodes and smooth-cell flags. */
static int job_lattice(const fx_effect_run *run, const caustics_params *p, caustics_job *j)
{
    if (p->downsample <= 1)
        return 0;
    j->f = p->downsample;
    j->node_x = lattice_axis(run->roi.x0, run->roi.x1, j->f, &j->nx);
    j->node_y = lattice_axis(run->roi.y0, run->roi.y1, j->f, &j->ny);
    int roi_w = run->roi.x1 - run->roi.x0;
    j->col_i0 = fx_mem_alloc((size_t)roi_w * sizeof(int));
    j->col_i1 = fx_mem_alloc((size_t)roi_w * sizeof(int));
    j->col_t = fx_mem_alloc((size_t)roi_w * sizeof(float));
    if (!j->node_x || !j->node_y || !j->col_i0 || !j->col_i1 || !j->col_t)
        return -1;
    for (int c = 0; c < roi_w; c++)
        lattice_pos(j->node_x, j->nx, j->f, run->roi.x0, run->roi.x0 + c, &j->col_i0[c], &j->col_i1[c], &j->col_t[c]);
    size_t count = (size_t)j->nx * j->ny;
    j->node_size = p->lattice_shading && !j->gain_path ? NODE_MAX : 4;
    /* plain fx_mem_alloc: huge pages (fx_mem_alloc_whole) cut a process's first draft frame
     * from 904 to 146 faults but cost every warm fx_stack_run 0.4-0.5 ms; the buffer store
     * evicted frame buffers (docs/effects/voronoi_caustics.md, "In place") */
    j->nodes = fx_mem_alloc(count * j->node_size * sizeof(float));
    j->node_id = fx_mem_alloc(count * 2 * sizeof(int));
    if (!j->nodes || !j->node_id)
        return -1;
    if (run->mask) {
        j->cell_any = fx_mem_alloc(count);
        if (!j->cell_any)
            return -1;
        fx_parallel_for(run->ctx, j->ny, 1, cell_rows, j);
    }
    fx_parallel_for(run->ctx, j->ny, 1, node_rows, j);
    if (p->refine && !p->lattice_shading) {
        j->cx = j->nx > 1 ? j->nx - 1 : 1;
        j->cy = j->ny > 1 ? j->ny - 1 : 1;
        j->smooth = fx_mem_alloc((size_t)j->cx * j->cy);
        if (!j->smooth)
            return -1;
        fx_parallel_for(run->ctx, j->cy, 1, smooth_rows, j);
    }
    return 0;
}

/* ---- mode refractive ------------------------------------------------------------------ */

typedef struct refract_job {
    const caustics_job *cj;
    const fx_aux_view *av;
    fx_caustic_map map;
    const float *diffcol, *normal; /* apply sun_diffuse */
    int diffcol_channels, normal_channels;
    fx_vec3 sun_rad, to_sun;        /* the sun's colour x energy / pi, towards the sun */
    float floor_z;                  /* receiver_depth > 0: the floor's height */
    fx_vec3 eye, forward;           /* the camera (orthographic: forward is the rays' direction) */
    float *debug_gain;              /* debug output "gain": the map's gain per pixel (1 unmasked) */
} refract_job;

/* receiver_depth > 0: the floor point a masked water pixel at P shows, along the camera's
 * ray refracted by a flat surface (normal +z); P itself when the ray does not go down. */
static fx_vec3 seen_floor(const refract_job *rj, fx_vec3 P)
{
    const caustics_job *j = rj->cj;
    fx_vec3 d = j->view.orthographic ? rj->forward : fx_v3_normalize_or(fx_v3_sub(P, rj->eye), rj->forward);
    fx_vec3 t;
    if (!(d.z < -1e-6f) || !fx_refract_into(d, fx_v3(0.0f, 0.0f, 1.0f), j->p->ior, &t, NULL) || !(t.z < -1e-6f) ||
        !(P.z > rj->floor_z))
        return P;
    return fx_v3_add(P, fx_v3_scale(t, (rj->floor_z - P.z) / t.z));
}

static int float_cmp(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

/* The receiver's height: the median world z of the masked pixels (at most ~64k of them,
 * on a fixed stride). 0 when no pixel has a position; -1 out of memory. */
static int receiver_height(const caustics_job *j, float *z)
{
    const fx_effect_run *run = j->run;
    size_t w = (size_t)(run->roi.x1 - run->roi.x0), h = (size_t)(run->roi.y1 - run->roi.y0);
    size_t stride = 1;
    while ((w / stride + 1) * (h / stride + 1) > 65536)
        stride++;
    size_t cap = (w / stride + 1) * (h / stride + 1), n = 0;
    float *v = fx_mem_alloc(cap * sizeof(float));
    if (!v)
        return -1;
    for (int y = run->roi.y0; y < run->roi.y1; y += (int)stride)
        for (int x = run->roi.x0; x < run->roi.x1; x += (int)stride) {
            fx_vec3 P;
            if (covered(run, (size_t)y * run->width + x) && world_at(j, x, y, &P) && n < cap)
                v[n++] = P.z;
        }
    if (n)
        qsort(v, n, sizeof(float), float_cmp);
    *z = n ? v[n / 2] : 0.0f;
    fx_mem_free(v);
    return n ? 1 : 0;
}

static void refract_rows(void *user, int begin, int end)
{
    const refract_job *rj = user;
    const caustics_job *j = rj->cj;
    const fx_effect_run *run = j->run;
    const caustics_params *p = j->p;
    for (int y = run->roi.y0 + begin; y < run->roi.y0 + end; y++) {
        for (int x = run->roi.x0; x < run->roi.x1; x++) {
            size_t i = (size_t)y * run->width + x;
            fx_vec3 P;
            float gain[3] = {1.0f, 1.0f, 1.0f}, add[3] = {0.0f, 0.0f, 0.0f};
            if (covered(run, i) && world_at(j, x, y, &P)) {
                float px, py, d;
                if (p->receiver_depth > 0.0f)
                    P = seen_floor(rj, P);
                float g = fx_aux_view_project(rj->av, P, &px, &py, &d) ? fx_caustic_map_gain(&rj->map, px, py) : 1.0f;
                if (rj->debug_gain)
                    rj->debug_gain[i] = g;
                float s = p->strength * (g - 1.0f);
                if (rj->diffcol) {
                    /* the sun's direct diffuse: the light the gain redistributes */
                    const float *nq = rj->normal + i * rj->normal_channels;
                    const float *dc = rj->diffcol + i * rj->diffcol_channels;
                    fx_vec3 n = fx_v3_normalize_or(fx_v3(nq[0], nq[1], nq[2]), fx_v3(0.0f, 0.0f, 0.0f));
                    float ndl = fx_v3_dot(n, rj->to_sun);
                    ndl = ndl > 0.0f ? ndl : 0.0f;
                    const float rad[3] = {rj->sun_rad.x, rj->sun_rad.y, rj->sun_rad.z};
                    for (int k = 0; k < 3; k++) {
                        float d = dc[k] > 0.0f ? dc[k] * rad[k] * ndl : 0.0f;
                        add[k] = s * p->tint[k] * (d < 1e30f ? d : 1e30f);
                    }
                } else {
                    for (int k = 0; k < 3; k++)
                        gain[k] = 1.0f + s * p->tint[k];
                }
                if (p->environment_strength > 0.0f && j->normal)
                    env_term(j, i, P, add);
            }
            apply(j, i, gain, add);
        }
        finish_row(run, y);
    }
}

/* The water's view: loaded, with its Normal pass and at least one texel of water. */
static fx_result refract_view(const fx_effect_run *run, const caustics_params *p, fx_aux_view **av,
                              const fx_pass **np)
{
    char name[FX_NAME_MAX];
    snprintf(name, sizeof name, "water:%.80s", p->water);
    int has = fx_aux_view_has(run->frame, name);
    if (has < 0)
        return fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", run->where);
    if (!has)
        return fx_fail(run->ctx, FX_ERR_NO_AUX_VIEW,
                       "%s (mode refractive) needs the aux view '%s': the objects with the water material '%s' "
                       "seen from the Sun (Normal and Depth passes); the Blender add-on renders it when the "
                       "stack needs it and lists it in the scene sidecar's \"aux_views\"",
                       run->where, name, p->water);
    fx_result r = fx_aux_view_load(run->frame, name, run->where, av);
    if (r)
        return r;
    *np = fx_frame_find_pass((*av)->frame, "Normal");
    if (!*np || (*np)->channels < 3)
        return fx_fail(run->ctx, FX_ERR_MISSING_PASS, "%s: the water view '%s' (%s) has no Normal pass", run->where,
                       name, (*av)->path);
    if (!(*av)->view.orthographic)
        return fx_fail(run->ctx, FX_ERR_BAD_PARAM,
                       "%s: the water view '%s' must be orthographic (a sun's view); other lights are not "
                       "supported by mode refractive",
                       run->where, name);
    return FX_OK;
}

/* The scene's first sun (its disc's angle blurs the map; sun_diffuse: its light) and, for
 * apply sun_diffuse, the DiffCol and Normal passes. */
static fx_result refract_sun(const fx_effect_run *run, const caustics_params *p, refract_job *rj, float *angle)
{
    fx_light sun;
    *angle = 0.0f;
    if (p->apply == APPLY_COMBINED && !fx_frame_meta(run->frame, "libfx:lights"))
        return FX_OK; /* the sun's disc only blurs: without lights, a point */
    fx_result r = fx_frame_find_light(run->frame, "", run->where, &sun);
    if (r)
        return r;
    if (sun.type != FX_LIGHT_SUN)
        return fx_fail(run->ctx, FX_ERR_BAD_PARAM,
                       "%s: mode refractive refracts a sun's light; the frame's first light '%s' is not a sun "
                       "(spot and point lights are not supported yet)",
                       run->where, sun.name);
    *angle = sun.angle > 0.0f && sun.angle < 3.0f ? sun.angle : 0.0f;
    if (p->apply != APPLY_SUN_DIFFUSE)
        return FX_OK;
    const fx_pass *dc = fx_frame_find_pass(run->frame, "DiffCol");
    const fx_pass *np = fx_frame_find_pass(run->frame, "Normal");
    if (!dc || dc->channels < 3 || !np || np->channels < 3)
        return fx_fail(run->ctx, FX_ERR_MISSING_PASS,
                       "%s: apply sun_diffuse needs the %s pass (or set apply to combined)", run->where,
                       !dc || dc->channels < 3 ? "DiffCol" : "Normal");
    rj->diffcol = dc->data;
    rj->diffcol_channels = dc->channels;
    rj->normal = np->data;
    rj->normal_channels = np->channels;
    float e = sun.energy > 0.0f && sun.energy < 1e30f ? sun.energy * 0.318309886f /* 1/pi */ : 0.0f;
    rj->sun_rad = fx_v3(sun.color.x * e, sun.color.y * e, sun.color.z * e);
    rj->to_sun = fx_v3_scale(sun.direction, -1.0f);
    return FX_OK;
}

static fx_result refract_process(const fx_effect_run *run, const caustics_params *p, caustics_job *j)
{
    fx_aux_view *av = NULL;
    const fx_pass *np = NULL;
    refract_job rj;
    memset(&rj, 0, sizeof rj);
    rj.cj = j;
    float angle = 0.0f;
    fx_result r = refract_view(run, p, &av, &np);
    if (!r)
        r = refract_sun(run, p, &rj, &angle);
    rj.av = av;
    float plane_z = 0.0f;
    int found = r ? 0 : receiver_height(j, &plane_z);
    if (!r && found < 0)
        r = fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", run->where);
    if (!r) {
        rj.floor_z = plane_z - p->receiver_depth;
        rj.eye = fx_v3(j->view.camera_to_world[3], j->view.camera_to_world[7], j->view.camera_to_world[11]);
        rj.forward = fx_v3_normalize_or(fx_view_dir_to_world(&j->view, fx_v3(0.0f, 0.0f, -1.0f)), fx_v3(0, 0, -1));
        fx_caustic_input in = {av->width, av->height, av->depth, np->data, np->channels, &av->view,
                               av->view.cam.clip_end, p->ior, rj.floor_z, p->refract_step, p->refract_samples,
                               p->fresnel, angle};
        r = fx_caustic_map_build(run->ctx, &in, &rj.map, run->where);
    }
    if (!r && found && rj.map.water_nodes == 0)
        r = fx_fail(run->ctx, FX_ERR_MISSING_PASS,
                    "%s: the water view '%s' (%s) shows no water: no object with the material '%s' in the Sun's "
                    "view (the add-on renders the objects that use the effect's 'water' material)",
                    run->where, av->name, av->path, p->water);
    if (!r) {
        rj.debug_gain = fx_effect_debug_pass(run, "gain", 1, &r);
        for (size_t i = 0; rj.debug_gain && i < (size_t)run->width * run->height; i++)
            rj.debug_gain[i] = 1.0f;
    }
    if (!r) {
        int rows = run->roi.y1 - run->roi.y0;
        fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), refract_rows, &rj);
    }
    fx_caustic_map_free(&rj.map);
    fx_aux_view_free(av);
    return r;
}

static fx_result caustics_process(const fx_effect_run *run)
{
    const caustics_params *p = run->params;
    caustics_job j;
    job_init(run, p, &j);
    fx_frame *envf = NULL;
    fx_result r = job_inputs(run, p, &j, &envf);
    if (r != FX_OK)
        return r;
    if (p->mode == MODE_REFRACTIVE) {
        r = refract_process(run, p, &j);
        fx_frame_free(envf);
        return r;
    }
    if (job_table(run, p, &j) || job_mean(run, p, &j)) {
        r = fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", run->where);
    } else {
        j.has_add = p->mode == MODE_SEED || (p->environment_strength > 0.0f && j.normal);
        j.gain_path = p->downsample > 1 && p->lattice_shading && p->mode == MODE_PHYSICAL && !j.has_add && j.position;
        if (job_lattice(run, p, &j)) {
            r = fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", run->where);
        } else {
            int rows = run->roi.y1 - run->roi.y0;
            /* the default path (physical, no additive term, Position, lattice without
             * lattice_shading) in vector-friendly passes: the same bits */
            int lattice_path = j.nodes && !p->lattice_shading && p->mode == MODE_PHYSICAL && !j.has_add &&
                               j.position && j.node_size == 4;
            fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows),
                            j.gain_path      ? caustics_rows_gain
                            : lattice_path ? caustics_rows_lattice
                                           : caustics_rows,
                            &j);
        }
    }
    job_free(&j);
    fx_frame_free(envf);
    return r;
}

/* params_version 2 added interior (lit cell interiors, default 0.1): a recipe of version 1
 * keeps its dark interiors (interior 0) unless it names one; params_version 3 added warp
 * (curved cell sides, default 0.3): a recipe of version 1 or 2 keeps straight sides (warp 0)
 * unless it names one. Silent: its output is the same as before. */
static fx_result caustics_migrate(int from_version, cJSON *params, char *note, size_t note_size)
{
    (void)note;
    (void)note_size;
    if (from_version == 1 && params && !cJSON_GetObjectItemCaseSensitive(params, "interior") &&
        !cJSON_AddNumberToObject(params, "interior", 0.0))
        return FX_ERR_OUT_OF_MEMORY;
    if (from_version == 2 && params && !cJSON_GetObjectItemCaseSensitive(params, "warp") &&
        !cJSON_AddNumberToObject(params, "warp", 0.0))
        return FX_ERR_OUT_OF_MEMORY;
    return FX_OK;
}

const fx_effect_class fx_effect_voronoi_caustics = {
    .name = "voronoi_caustics",
    .doc = "Water caustics: a world-anchored, animated Voronoi pattern (Minkowski metric) on the masked surface",
    .params_size = sizeof(caustics_params),
    .params = caustics_param_defs,
    .param_count = FX_COUNT_OF(caustics_param_defs),
    .presets = {
        /* draft at least 3x faster than final; reference: every pixel, double pow */
        "{\"downsample\": 4, \"distance\": \"fast\", \"refine\": false, \"lattice_shading\": true, "
        "\"refract_samples\": 1, \"refract_step\": 2}",
        "{\"downsample\": 2, \"distance\": \"fast\", \"refine\": false, \"lattice_shading\": false, "
        "\"refract_samples\": 1, \"refract_step\": 1}",
        "{\"downsample\": 2, \"distance\": \"fast\", \"refine\": true, \"lattice_shading\": false, "
        "\"refract_samples\": 2, \"refract_step\": 1}",
        "{\"downsample\": 1, \"distance\": \"exact\", \"refine\": true, \"lattice_shading\": false, "
        "\"refract_samples\": 4, \"refract_step\": 1}",
    },
    /* in place (dst == src: no mask) for every parameter set: an output pixel reads only its
     * own colour pixel, just before writing it (the pattern, noise and shading come from
     * Position or Depth, Normal and the environment image); caustics_rows_gain writes no
     * pixel it defers to gain_pixel / gain_flush, and its octets never overlap. On a
     * consumed frame no fresh frame-sized output buffer */
    .flags = FX_EFFECT_IN_PLACE | FX_EFFECT_OWN_FINITE,
    .passes = caustics_passes,
    .needs_camera = caustics_needs_camera,
    .aux_views = caustics_aux_views,
    .halo = NULL,
    .validate = caustics_validate,
    .process = caustics_process,
    .params_version = 3,
    .migrate = caustics_migrate,
};
