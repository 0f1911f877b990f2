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
#include "core/buffers.h"
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
    int downsample;
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
    FX_P_INT(splash_params, downsample, "downsample", 1, 1, 16, 1, 8, "",
             "Quality: the splashes are evaluated every N pixels and interpolated where a lattice cell's "
             "four corners are all ground (rings blur by up to N pixels; a pixel that is not ground gets "
             "none), left out where none is (ground under N pixels is missed), evaluated exactly where "
             "some are. 1: every pixel"),
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

/* The splash added at pixel (x, y), index i: 0 where the pixel is no exposed ground. *ground:
 * whether it is ground (depth, an up-facing normal, a world position). */
static inline float splash_pixel(const splash_job *j, int x, int y, size_t i, splash_cells *sc, int *ground)
{
    const splash_params *p = j->p;
    fx_vec3 w, n;
    float d, v = 0.0f;
    *ground = 0;
    /* the cheap tests first (depth, an up-facing normal): most pixels are walls, sky or
     * objects, and never need their world position (the same answers as testing the world
     * position first: each test is pure) */
    const float dp = j->surf.depth[i];
    if (dp > 0.0f && dp < j->surf.far_limit && fx_surface_normal(&j->surf, x, y, &n) && n.z >= p->up_threshold &&
        fx_surface_world(&j->surf, x, y, &w, &d)) {
        *ground = 1;
        v = splash_at(j, w, sc);
        /* the rain map only where there is a splash to hide */
        if (v > 0.0f && !(fx_rain_map_exposed(&j->rm, fx_v3_add(w, fx_v3_scale(n, 0.05f))) > 0.0f))
            v = 0.0f;
    }
    return v;
}

/* The ground test without the normalisation (a lattice cell's inner pixels at downsample > 1):
 * n.z >= up |n| as n.z >= 0 and n.z^2 >= up^2 |n|^2 (equal to fx_surface_normal's test but
 * for rounding), a valid depth. */
static inline int ground_cheap(const splash_job *j, size_t i, float up2)
{
    const float dp = j->surf.depth[i];
    if (!(dp > 0.0f && dp < j->surf.far_limit) || !j->surf.normal)
        return 0;
    const float *n = j->surf.normal + 3 * i;
    const float l2 = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
    return l2 > 1e-8f && l2 <= 1e30f && n[2] >= 0.0f && n[2] * n[2] >= up2 * l2;
}

static inline void splash_write(const splash_job *j, const float *s, float *o, float v)
{
    const splash_params *p = j->p;
    if (o != s)
        memcpy(o, s, 4 * sizeof(float));
    if (v > 0.0f)
        for (int c = 0; c < 3; c++)
            o[c] = s[c] + v * p->brightness * p->color[c];
}

static void splash_rows(void *user, int y0, int y1)
{
    splash_job *j = user;
    const fx_effect_run *run = j->run;
    const fx_rect *roi = &run->roi;
    for (int y = roi->y0 + y0; y < roi->y0 + y1; y++) {
        splash_cells sc;
        memset(&sc, 0, sizeof sc);
        for (int x = roi->x0; x < roi->x1; x++) {
            size_t i = (size_t)y * run->width + x;
            int ground;
            const float v = splash_pixel(j, x, y, i, &sc, &ground);
            splash_write(j, run->src + 4 * i, run->dst + 4 * i, v);
            if (j->dbg)
                j->dbg[i] = v;
        }
    }
}

/* downsample N > 1: the lattice of every N-th pixel of the ROI (its last row and column
 * included), each node's splash and ground flag */
typedef struct splash_lattice {
    int n, nx, ny;
    float *v;              /* nx * ny */
    unsigned char *ground; /* nx * ny */
    /* per row of cells ky (ny - 1 of them): the cells with work, ncell[ky] of them from
     * cell[ky * (nx - 1)], as kx * 2 + exact (exact: some corners are ground, not all) */
    int *cell, *ncell;
} splash_lattice;

static inline int node_coord(int k, int n, int lo, int hi)
{
    const int c = lo + k * n;
    return c < hi - 1 ? c : hi - 1;
}

typedef struct lattice_job {
    splash_job *j;
    splash_lattice *l;
} lattice_job;

static void lattice_rows(void *user, int k0, int k1)
{
    lattice_job *lj = user;
    const splash_job *j = lj->j;
    const splash_lattice *l = lj->l;
    const fx_effect_run *run = j->run;
    const fx_rect *roi = &run->roi;
    for (int ky = k0; ky < k1; ky++) {
        const int y = node_coord(ky, l->n, roi->y0, roi->y1);
        splash_cells sc;
        memset(&sc, 0, sizeof sc);
        for (int kx = 0; kx < l->nx; kx++) {
            const int x = node_coord(kx, l->n, roi->x0, roi->x1);
            int ground;
            l->v[(size_t)ky * l->nx + kx] = splash_pixel(j, x, y, (size_t)y * run->width + x, &sc, &ground);
            l->ground[(size_t)ky * l->nx + kx] = (unsigned char)ground;
        }
    }
}

/* The cells with work of cell rows [k0, k1): some corners ground but not all (exact), or all
 * four ground with a splash at one of them at least (interpolated). The others (no corner on
 * the ground: a patch of ground under N pixels is missed; or no splash at any corner) keep
 * their pixels. */
static void cell_rows(void *user, int k0, int k1)
{
    lattice_job *lj = user;
    splash_lattice *l = lj->l;
    for (int ky = k0; ky < k1; ky++) {
        const size_t a = (size_t)ky * l->nx, b = a + (size_t)l->nx;
        int *list = l->cell + (size_t)ky * (l->nx - 1), m = 0;
        for (int kx = 0; kx + 1 < l->nx; kx++) {
            const int g = l->ground[a + kx] + l->ground[a + kx + 1] + l->ground[b + kx] + l->ground[b + kx + 1];
            const int any = l->v[a + kx] > 0.0f || l->v[a + kx + 1] > 0.0f || l->v[b + kx] > 0.0f || l->v[b + kx + 1] > 0.0f;
            list[m] = kx * 2 + (g != 4);
            m += g != 0 && (g != 4 || any);
        }
        l->ncell[ky] = m;
    }
}

typedef struct interp_job {
    splash_job *j;
    const splash_lattice *l;
} interp_job;

/* Pixels from the lattice: bilinear where the cell's four nodes are ground (a pixel that is
 * not ground gets 0), exactly where some are; the other cells' pixels as they are. */
static void interp_rows(void *user, int y0, int y1)
{
    interp_job *ij = user;
    const splash_job *j = ij->j;
    const splash_lattice *l = ij->l;
    const fx_effect_run *run = j->run;
    const fx_rect *roi = &run->roi;
    const int n = l->n;
    const float up2 = j->p->up_threshold * j->p->up_threshold;
    for (int y = roi->y0 + y0; y < roi->y0 + y1; y++) {
        const int ky = (y - roi->y0) / n < l->ny - 1 ? (y - roi->y0) / n : l->ny - 2; /* the last row: its cell's bottom */
        const int ya = node_coord(ky, n, roi->y0, roi->y1), yb = node_coord(ky + 1, n, roi->y0, roi->y1);
        const float fy = (float)(y - ya) / (float)(yb - ya);
        const size_t a = (size_t)ky * l->nx, b = a + (size_t)l->nx, row = (size_t)y * run->width;
        if (run->dst != run->src)
            memcpy(run->dst + 4 * (row + roi->x0), run->src + 4 * (row + roi->x0),
                   (size_t)(roi->x1 - roi->x0) * 4 * sizeof(float));
        if (j->dbg)
            memset(j->dbg + row + roi->x0, 0, (size_t)(roi->x1 - roi->x0) * sizeof(float));
        splash_cells sc;
        memset(&sc, 0, sizeof sc);
        const int *list = l->cell + (size_t)ky * (l->nx - 1);
        /* one cell's span of the row at a time: [xa, xb), the last one [xa, xb] */
        for (int c = 0; c < l->ncell[ky]; c++) {
            const int kx = list[c] >> 1, exact = list[c] & 1;
            const int xa = node_coord(kx, n, roi->x0, roi->x1), xb = node_coord(kx + 1, n, roi->x0, roi->x1);
            const int xe = kx + 2 < l->nx ? xb : xb + 1;
            const float v00 = l->v[a + kx], v10 = l->v[a + kx + 1], v01 = l->v[b + kx], v11 = l->v[b + kx + 1];
            const float inv = 1.0f / (float)(xb - xa);
            for (int x = xa; x < xe; x++) {
                const size_t i = row + x;
                float v = 0.0f;
                if (!exact) {
                    if (ground_cheap(j, i, up2)) {
                        const float fx = (float)(x - xa) * inv;
                        const float top = v00 + fx * (v10 - v00), bot = v01 + fx * (v11 - v01);
                        v = top + fy * (bot - top);
                    }
                } else {
                    int ground;
                    v = splash_pixel(j, x, y, i, &sc, &ground);
                }
                splash_write(j, run->src + 4 * i, run->dst + 4 * i, v);
                if (j->dbg)
                    j->dbg[i] = v;
            }
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
    const int n = p->downsample;
    if (n <= 1 || roi->x1 - roi->x0 < 2 || rows < 2) {
        fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), splash_rows, &j);
        return fx_rain_effect_end(&j.rm, FX_OK);
    }
    splash_lattice l = { n, (roi->x1 - roi->x0 - 1 + n - 1) / n + 1, (rows - 1 + n - 1) / n + 1, NULL, NULL, NULL, NULL };
    const size_t nodes = (size_t)l.nx * l.ny, cells = (size_t)(l.nx - 1) * (l.ny - 1);
    /* one block from the context's store (core/buffers.h): later frames of the same size reuse
     * its pages instead of faulting fresh ones in */
    const size_t bytes = (nodes + cells + (size_t)(l.ny - 1)) * 4 + nodes;
    unsigned char *block = fx_buffer_get(run->ctx, bytes);
    if (!block)
        return fx_rain_effect_end(&j.rm,
                                  fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the lattice", run->where));
    l.v = (float *)block;
    l.cell = (int *)(block + nodes * 4);
    l.ncell = (int *)(block + (nodes + cells) * 4);
    l.ground = block + (nodes + cells + (size_t)(l.ny - 1)) * 4;
    lattice_job lj = { &j, &l };
    fx_parallel_for(run->ctx, l.ny, fx_grain_for(run->ctx, l.ny), lattice_rows, &lj);
    fx_parallel_for(run->ctx, l.ny - 1, fx_grain_for(run->ctx, l.ny - 1), cell_rows, &lj);
    interp_job ij = { &j, &l };
    fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), interp_rows, &ij);
    fx_buffer_put(run->ctx, block, bytes);
    return fx_rain_effect_end(&j.rm, FX_OK);
}

const fx_effect_class fx_effect_rain_splashes = {
    .name = "rain_splashes",
    .doc = "Raindrop splashes (expanding rings) on exposed up-facing surfaces, deterministic per cell and cycle",
    .params_size = sizeof(splash_params),
    .params = splash_param_defs,
    .param_count = FX_COUNT_OF(splash_param_defs),
    .presets = {
        /* draft at least 3x faster than final; final and reference: every pixel */
        "{\"downsample\": 4}",
        "{\"downsample\": 2}",
        "{\"downsample\": 1}",
        "{\"downsample\": 1}",
    },
    .passes = splash_passes,
    /* each pixel reads its own input pixel before writing it */
    .flags = FX_EFFECT_NEEDS_CAMERA | FX_EFFECT_IN_PLACE,
    .aux_views = fx_aux_needs_rain_map, /* what is under cover */
    .halo = NULL,
    .validate = splash_validate,
    .process = splash_process,
};
