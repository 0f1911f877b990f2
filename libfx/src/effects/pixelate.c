/* pixelate: the image as a grid of flat cells (slices, square cells with a centre sample,
 * or square cells with the cell's average). docs/effects/pixelate.md.
 *
 * Grid: cells are whole pixels. "slices" cuts the image into columns x rows slices
 * (cell i spans floor(i W / N) .. floor((i+1) W / N)); "cells"/"average" use square cells
 * of cell_size px whose grid has a corner at the origin: (0, 0) for anchor "image", the
 * centre of the mask's bounds (rounded down to a pixel) for anchor "mask", so the grid
 * travels with a masked object instead of crawling over it as it moves; for anchor "world"
 * the projection of a world point (world_point, or the coverage-weighted mean of the mask's
 * Position pass), so the grid sticks to the object as the camera moves even when its
 * silhouette changes (the bounds' midpoint jumps whenever an extreme pixel appears).
 * Centre sample: the continuous centre of the cell (clamped into the image for cells that
 * straddle the border): a pixel for odd sizes, the mean of the 2 (or 2x2) middle pixels for
 * even ones. Average: the mean of the cell's pixels inside the image, weighted by the
 * mask's coverage when there is a mask (so a censored object keeps its own colours instead
 * of bleeding the background into the cells on its edge); a cell with no coverage at all
 * takes the plain mean. Sums in double: finite for any finite input. */
#include "core/effect.h"
#include "core/parallel.h"
#include "math/camera.h"

#include <math.h>

#include <stdatomic.h>
#include <stdio.h>
#include <string.h>

typedef struct pixelate_params {
    int mode;
    int columns, rows;
    int cell_size;
    int anchor;
    float world_point[3];
    int world_point_auto;
} pixelate_params;

enum { MODE_SLICES = 0, MODE_CELLS, MODE_AVERAGE };
enum { ANCHOR_IMAGE = 0, ANCHOR_MASK, ANCHOR_WORLD };

static const char *const mode_items[] = { "slices", "cells", "average" };
static const char *const anchor_items[] = { "image", "mask", "world" };
static const float default_world_point[3] = { 0.0f, 0.0f, 0.0f };

static const fx_param_def pixelate_param_defs[] = {
    FX_P_ENUM(pixelate_params, mode, "mode", MODE_SLICES, mode_items,
              "slices: columns x rows slices, each the colour at its centre; cells: square cells "
              "of cell_size px, centre sample; average: square cells, mean colour (weighted by the "
              "mask's coverage)"),
    FX_P_INT(pixelate_params, columns, "columns", 32, 1, 65536, 1, 256, "",
             "Vertical slices across the image (mode slices; at most the width)"),
    FX_P_INT(pixelate_params, rows, "rows", 18, 1, 65536, 1, 256, "",
             "Horizontal slices down the image (mode slices; at most the height)"),
    FX_P_INT(pixelate_params, cell_size, "cell_size", 16, 1, 65536, 1, 128, "pixels",
             "Cell edge in pixels (modes cells and average); 1 is the identity"),
    FX_P_ENUM(pixelate_params, anchor, "anchor", ANCHOR_IMAGE, anchor_items,
              "Grid origin for cells/average: image: the top-left corner; mask: the centre of the "
              "mask's bounds, so the grid moves with the object (no mask: image); world: the "
              "projection of a world point, so the grid sticks to the object as the camera moves "
              "(needs the camera)"),
    FX_P_FLOATS(pixelate_params, world_point, "world_point", 3, default_world_point, -1e30, 1e30, "",
                "anchor world: the world point a cell corner sits on (with world_point_auto off)"),
    FX_P_BOOL(pixelate_params, world_point_auto, "world_point_auto", 1,
              "anchor world: use the coverage-weighted mean of the mask's Position pass instead of "
              "world_point"),
};

static fx_pass_set pixelate_passes(const void *params)
{
    const pixelate_params *p = params;
    return p->anchor == ANCHOR_WORLD && p->world_point_auto ? FX_PASS_BIT(FX_PASS_POSITION) : 0;
}

static int pixelate_needs_camera(const void *params)
{
    const pixelate_params *p = params;
    return p->anchor == ANCHOR_WORLD;
}

/* Grid origin for anchor world: the projected anchor point, rounded down to a pixel.
 * Returns 0 (fall back to the mask's bounds) when the point is behind the camera or the
 * mask has no Position coverage. */
static fx_result world_origin(const fx_effect_run *run, const pixelate_params *p, const char *where, int *ox,
                              int *oy, int *ok)
{
    *ok = 0;
    fx_view v;
    if (!fx_view_init(&v, run->frame))
        return fx_fail(run->ctx, FX_ERR_NO_CAMERA,
                       "%s: anchor world needs the frame's camera (give the scene sidecar with --sidecar)", where);
    fx_vec3 P = fx_v3(p->world_point[0], p->world_point[1], p->world_point[2]);
    if (p->world_point_auto) {
        const fx_pass *pp = fx_frame_find_pass(run->frame, "Position");
        if (!pp || pp->channels < 3)
            return fx_fail(run->ctx, FX_ERR_MISSING_PASS,
                           "%s: anchor world with world_point_auto needs the Position pass", where);
        double acc[3] = {0, 0, 0}, wsum = 0;
        const fx_rect b = run->mask ? run->mask->bounds : (fx_rect){0, 0, run->width, run->height};
        for (int y = b.y0; y < b.y1; y++)
            for (int x = b.x0; x < b.x1; x++) {
                size_t i = (size_t)y * run->width + x;
                double c = run->mask ? run->mask->coverage[i] : 1.0;
                const float *q = pp->data + i * pp->channels;
                if (!(c > 0.0) || !isfinite(q[0]) || !isfinite(q[1]) || !isfinite(q[2]))
                    continue;
                acc[0] += c * q[0];
                acc[1] += c * q[1];
                acc[2] += c * q[2];
                wsum += c;
            }
        if (!(wsum > 0.0))
            return FX_OK;
        P = fx_v3((float)(acc[0] / wsum), (float)(acc[1] / wsum), (float)(acc[2] / wsum));
    }
    fx_vec2 px = {0.0f, 0.0f};
    float w = fx_view_project(&v, fx_world_to_view(&v, P), &px);
    if (!(w > 1e-6f) || !isfinite(px.x) || !isfinite(px.y) || fabsf(px.x) > 1e9f || fabsf(px.y) > 1e9f)
        return FX_OK;
    *ox = (int)floorf(px.x);
    *oy = (int)floorf(px.y);
    *ok = 1;
    return FX_OK;
}

/* One cell along one axis. */
typedef struct axis_cell {
    int p0, p1;  /* image pixels [p0, p1) of the cell (clipped to the image) */
    int s0, s1;  /* centre sample: mean of pixels s0 and s1 (equal for odd sizes) */
} axis_cell;

static long long floor_div(long long a, long long b)
{
    long long q = a / b;
    return (a % b != 0 && ((a < 0) != (b < 0))) ? q - 1 : q;
}

static int clampi(long long v, int lo, int hi)
{
    return v < lo ? lo : v > hi ? hi : (int)v;
}

/* The cells of an axis of `size` pixels that meet [r0, r1). Returns the count, or -1 when
 * out of memory. */
static int build_axis(const pixelate_params *p, int slices, int size, int origin, int r0, int r1,
                      axis_cell **out)
{
    long long first, last;
    int n_slices = 0;
    if (p->mode == MODE_SLICES) {
        n_slices = slices < 1 ? 1 : slices > size ? size : slices;
        first = floor_div((long long)r0 * n_slices, size);
        last = floor_div((long long)(r1 - 1) * n_slices, size) + 1; /* a cell or two extra: filtered */
        if (last > n_slices - 1)
            last = n_slices - 1;
        if (first > 0)
            first--;
    } else {
        first = floor_div((long long)r0 - origin, p->cell_size);
        last = floor_div((long long)r1 - 1 - origin, p->cell_size);
    }
    int cap = (int)(last - first + 1);
    axis_cell *cells = fx_mem_alloc((size_t)(cap > 0 ? cap : 1) * sizeof *cells);
    if (!cells)
        return -1;
    int n = 0;
    for (long long i = first; i <= last; i++) {
        long long c0, c1;
        if (p->mode == MODE_SLICES) {
            c0 = i * size / n_slices;
            c1 = (i + 1) * size / n_slices;
        } else {
            c0 = (long long)origin + i * p->cell_size;
            c1 = c0 + p->cell_size;
        }
        if (c1 <= r0 || c0 >= r1)
            continue;
        axis_cell *c = &cells[n++];
        c->p0 = clampi(c0, 0, size);
        c->p1 = clampi(c1, 0, size);
        /* twice the continuous centre, minus one: twice the sample's pixel index */
        long long u2 = c0 + c1 - 1;
        if (u2 % 2 == 0) {
            c->s0 = c->s1 = clampi(u2 / 2, 0, size - 1);
        } else {
            c->s0 = clampi(floor_div(u2 - 1, 2), 0, size - 1);
            c->s1 = clampi(floor_div(u2 + 1, 2), 0, size - 1);
        }
    }
    *out = cells;
    return n;
}

typedef struct px_job {
    const fx_effect_run *run;
    const pixelate_params *p;
    const axis_cell *cx, *cy;
    int ncx, ncy;
    atomic_int failed;
} px_job;

static void centre_colour(const float *src, int w, const axis_cell *cx, const axis_cell *cy,
                          float out[4])
{
    const float *a = src + ((size_t)cy->s0 * w + cx->s0) * 4;
    const float *b = src + ((size_t)cy->s0 * w + cx->s1) * 4;
    const float *c = src + ((size_t)cy->s1 * w + cx->s0) * 4;
    const float *d = src + ((size_t)cy->s1 * w + cx->s1) * 4;
    int two_x = cx->s0 != cx->s1, two_y = cy->s0 != cy->s1;
    for (int k = 0; k < 4; k++) {
        float top = two_x ? 0.5f * a[k] + 0.5f * b[k] : a[k];
        float bot = two_x ? 0.5f * c[k] + 0.5f * d[k] : c[k];
        out[k] = two_y ? 0.5f * top + 0.5f * bot : top;
    }
}

static void px_cell_rows(void *user, int begin, int end)
{
    px_job *j = user;
    const fx_effect_run *run = j->run;
    const int w = run->width;
    const fx_rect *roi = &run->roi;
    const fx_mask *mask = run->mask;
    float *colour = fx_mem_alloc((size_t)j->ncx * 4 * sizeof(float));
    double *acc = j->p->mode == MODE_AVERAGE ? fx_mem_alloc((size_t)j->ncx * 10 * sizeof(double)) : NULL;
    if (!colour || (j->p->mode == MODE_AVERAGE && !acc)) {
        atomic_store(&j->failed, 1);
        fx_mem_free(colour);
        fx_mem_free(acc);
        return;
    }
    for (int cj = begin; cj < end; cj++) {
        const axis_cell *cy = &j->cy[cj];
        if (j->p->mode != MODE_AVERAGE) {
            for (int ci = 0; ci < j->ncx; ci++)
                centre_colour(run->src, w, &j->cx[ci], cy, colour + 4 * ci);
        } else {
            /* per cell: weighted sums [0..3], weight [4], plain sums [5..8], count [9] */
            memset(acc, 0, (size_t)j->ncx * 10 * sizeof(double));
            for (int y = cy->p0; y < cy->p1; y++) {
                const float *row = run->src + (size_t)y * w * 4;
                const float *cov = mask ? mask->coverage + (size_t)y * w : NULL;
                for (int ci = 0; ci < j->ncx; ci++) {
                    double *a = acc + 10 * ci;
                    for (int x = j->cx[ci].p0; x < j->cx[ci].p1; x++) {
                        const float *px = row + (size_t)x * 4;
                        double m = cov ? cov[x] : 1.0;
                        a[0] += m * px[0];
                        a[1] += m * px[1];
                        a[2] += m * px[2];
                        a[3] += m * px[3];
                        a[4] += m;
                        a[5] += px[0];
                        a[6] += px[1];
                        a[7] += px[2];
                        a[8] += px[3];
                        a[9] += 1.0;
                    }
                }
            }
            for (int ci = 0; ci < j->ncx; ci++) {
                const double *a = acc + 10 * ci;
                for (int k = 0; k < 4; k++) {
                    double v = a[4] > 0 ? a[k] / a[4] : (a[9] > 0 ? a[5 + k] / a[9] : 0.0);
                    colour[4 * ci + k] = (float)v; /* a mean of finite floats: finite */
                }
            }
        }
        int y0 = cy->p0 > roi->y0 ? cy->p0 : roi->y0;
        int y1 = cy->p1 < roi->y1 ? cy->p1 : roi->y1;
        for (int y = y0; y < y1; y++) {
            float *drow = run->dst + (size_t)y * w * 4;
            for (int ci = 0; ci < j->ncx; ci++) {
                int x0 = j->cx[ci].p0 > roi->x0 ? j->cx[ci].p0 : roi->x0;
                int x1 = j->cx[ci].p1 < roi->x1 ? j->cx[ci].p1 : roi->x1;
                const float *c = colour + 4 * ci;
                for (int x = x0; x < x1; x++)
                    memcpy(drow + (size_t)x * 4, c, 4 * sizeof(float));
            }
        }
    }
    fx_mem_free(colour);
    fx_mem_free(acc);
}

/* Pixels read around an output pixel: up to a cell away (the sample or the average). */
static int pixelate_halo(const void *params, int width, int height)
{
    const pixelate_params *p = params;
    if (p->mode == MODE_SLICES) {
        int cw = (width + p->columns - 1) / (p->columns > 0 ? p->columns : 1);
        int ch = (height + p->rows - 1) / (p->rows > 0 ? p->rows : 1);
        return cw > ch ? cw : ch;
    }
    int m = width > height ? width : height;
    return p->cell_size < m ? p->cell_size : m;
}

static fx_result pixelate_process(const fx_effect_run *run)
{
    const pixelate_params *p = run->params;
    const fx_rect *roi = &run->roi;
    const char *where = run->where;
    int ox = 0, oy = 0, have_origin = 0;
    if (p->anchor == ANCHOR_WORLD && p->mode != MODE_SLICES) {
        fx_result wr = world_origin(run, p, where, &ox, &oy, &have_origin);
        if (wr != FX_OK)
            return wr;
    }
    if (!have_origin && p->anchor != ANCHOR_IMAGE && run->mask && run->mask->bounds.x1 > run->mask->bounds.x0) {
        const fx_rect *b = &run->mask->bounds;
        ox = (int)floor_div((long long)b->x0 + b->x1, 2);
        oy = (int)floor_div((long long)b->y0 + b->y1, 2);
    }
    px_job j;
    memset(&j, 0, sizeof j);
    j.run = run;
    j.p = p;
    axis_cell *cx = NULL, *cy = NULL;
    j.ncx = build_axis(p, p->columns, run->width, ox, roi->x0, roi->x1, &cx);
    j.ncy = j.ncx < 0 ? -1 : build_axis(p, p->rows, run->height, oy, roi->y0, roi->y1, &cy);
    fx_result r = FX_OK;
    if (j.ncx < 0 || j.ncy < 0) {
        r = fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the cell grid", where);
        goto out;
    }
    j.cx = cx;
    j.cy = cy;
    atomic_init(&j.failed, 0);
    fx_parallel_for(run->ctx, j.ncy, fx_grain_for(run->ctx, j.ncy), px_cell_rows, &j);
    if (atomic_load(&j.failed))
        r = fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for cell colours", where);
out:
    fx_mem_free(cx);
    fx_mem_free(cy);
    return r;
}

const fx_effect_class fx_effect_pixelate = {
    .name = "pixelate",
    .doc = "Pixelate: slices or square cells, centre sample or average, grid anchored to the image or the mask",
    .params_size = sizeof(pixelate_params),
    .params = pixelate_param_defs,
    .param_count = FX_COUNT_OF(pixelate_param_defs),
    .presets = { NULL, NULL, NULL, NULL },
    /* in place (dst == src: no mask) for every parameter set: a row of cells is one work
     * item, its colours (centre samples or averages, read only from its own cells: a clamped
     * centre stays inside its cell) all computed before any of its pixels is written, and
     * cells never overlap, so no item reads a pixel another writes */
    .flags = FX_EFFECT_IN_PLACE,
    .passes = pixelate_passes,
    .needs_camera = pixelate_needs_camera,
    .halo = pixelate_halo,
    .validate = NULL,
    .process = pixelate_process,
};
