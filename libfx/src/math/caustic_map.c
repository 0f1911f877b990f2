/* Caustics mapping: the Sun refracted by the water into a gain map (math/caustic_map.h). */
#include "math/caustic_map.h"

#include "core/mem.h"
#include "core/parallel.h"

#include <math.h>
#include <string.h>

int fx_refract_into(fx_vec3 d, fx_vec3 n, float ior, fx_vec3 *out, float *t)
{
    float cos_i = -fx_v3_dot(d, n);
    cos_i = cos_i < 0.0f ? 0.0f : cos_i > 1.0f ? 1.0f : cos_i;
    float eta = 1.0f / ior;
    float sin2t = eta * eta * (1.0f - cos_i * cos_i);
    if (!(sin2t <= 1.0f))
        return 0;
    float cos_t = sqrtf(1.0f - sin2t);
    *out = fx_v3_add(fx_v3_scale(d, eta), fx_v3_scale(n, eta * cos_i - cos_t));
    if (t) {
        float a = cos_i + ior * cos_t, b = ior * cos_i + cos_t;
        float rs = a > 1e-12f ? (cos_i - ior * cos_t) / a : 1.0f;
        float rp = b > 1e-12f ? (ior * cos_i - cos_t) / b : 1.0f;
        float f = 0.5f * (rs * rs + rp * rp);
        *t = f < 0.0f ? 1.0f : f > 1.0f ? 0.0f : 1.0f - f;
    }
    return 1;
}

typedef struct node_job {
    const fx_caustic_input *in;
    int nx, ny;     /* the view's nodes */
    int gx, gy, ox, oy; /* the map's nodes; the view's node (0, 0) in it */
    fx_vec3 L;      /* the Sun's light travels along L (world, unit) */
    float far;      /* depth at or beyond: no water */
    float *img;     /* nx * ny * 4: image u, v (light-view pixels), weight, water (1 or 0) */
    long *water;    /* per node row: nodes with water */
    double *drop;   /* per node row: sum of the water's height above the plane */
    double mass[2]; /* 1-D mass of the bilinear basis at the sub-samples: same node, other node */
} node_job;

/* The image of one node: where its light meets the plane, in light-view pixels. */
static int node_image(const node_job *j, int x, int y, float *q, double *drop)
{
    const fx_caustic_input *in = j->in;
    float px = (float)x + 0.5f, py = (float)y + 0.5f;
    q[0] = px;
    q[1] = py;
    q[2] = q[3] = 0.0f; /* no water: no light the map knows of (the view holds only water) */
    size_t i = (size_t)y * in->width + x;
    float d = in->depth[i];
    const float *nq = in->normal + i * in->normal_channels;
    fx_vec3 n = fx_v3(nq[0], nq[1], nq[2]);
    float len = sqrtf(fx_v3_dot(n, n));
    if (!(d > 0.0f && d < j->far) || !(len >= 0.5f && len < 1e30f))
        return 0;
    q[2] = q[3] = 1.0f;
    n = fx_v3_scale(n, 1.0f / len);
    if (fx_v3_dot(n, j->L) > 0.0f)
        n = fx_v3_scale(n, -1.0f); /* the side the light comes from */
    fx_vec3 P = fx_view_to_world(in->view, fx_view_position(in->view, fx_view_pixel_to_ndc(in->view, px, py), d));
    fx_vec3 T;
    float w = 1.0f;
    if (!fx_refract_into(j->L, n, in->ior, &T, in->fresnel ? &w : NULL))
        return 1;
    if (!(T.z < -1e-6f) || !(P.z > in->plane_z))
        return 1; /* no way down to the receiver: the light goes on unrefracted */
    *drop += (double)(P.z - in->plane_z);
    float t = (in->plane_z - P.z) / T.z;
    fx_vec3 Y = fx_v3_add(P, fx_v3_scale(T, t));
    fx_vec2 pix = {0.0f, 0.0f};
    if (fx_view_project(in->view, fx_world_to_view(in->view, Y), &pix) <= 1e-30f || !(fabsf(pix.x) < 1e7f) ||
        !(fabsf(pix.y) < 1e7f))
        return 1;
    q[0] = pix.x;
    q[1] = pix.y;
    q[2] = w;
    return 1;
}

static void node_rows(void *user, int begin, int end)
{
    node_job *j = user;
    const int step = j->in->step;
    for (int r = begin; r < end; r++) {
        long n = 0;
        double drop = 0.0;
        for (int c = 0; c < j->nx; c++)
            n += node_image(j, c * step, r * step, j->img + ((size_t)r * j->nx + c) * 4, &drop);
        j->water[r] = n;
        j->drop[r] = drop;
    }
}

#define AXIS_MAX 16.0f /* widest tent half-width, nodes (a cell's image spread over more) */

/* A sub-sample's weights along one axis, at node coordinate g, for sub-samples h nodes
 * apart. A tent of half-width m h (m whole) sums to a constant over a regular lattice of
 * spacing h, so there is no ripple whatever the cell's scale; with q = 1 / h the weights
 * blend the tents of m = floor(q) and m + 1 spacings by the fraction of q (continuous in
 * h, at most 2 nodes wide); h >= 1 (light spread out): one tent of half-width h. */
typedef struct axis_w {
    int i0, n;
    float w[2 * (int)AXIS_MAX + 3];
} axis_w;

/* The two tents of one axis of a cell (its sub-samples h nodes apart) */
typedef struct axis_k {
    float ra, rb, t;  /* half-widths; rb's share */
    float wa, wb;     /* (1 - t) / ra, t / rb: the tents' peaks */
    float ia, ib;     /* 1 / ra, 1 / rb */
} axis_k;

static inline void axis_kernel(float h, axis_k *k)
{
    if (!(h > 1e-6f))
        h = 1e-6f;
    if (h >= 1.0f) {
        k->ra = k->rb = h < AXIS_MAX ? h : AXIS_MAX;
        k->t = 0.0f;
    } else {
        float q = 1.0f / h, m = floorf(q);
        k->t = q - m;
        k->ra = m * h;
        k->rb = (m + 1.0f) * h;
    }
    k->ia = 1.0f / k->ra;
    k->ib = 1.0f / k->rb;
    k->wa = (1.0f - k->t) * k->ia;
    k->wb = k->t * k->ib;
}

static inline void axis_weights(float g, const axis_k *k, axis_w *a)
{
    a->i0 = (int)ceilf(g - k->rb);
    int i1 = (int)floorf(g + k->rb);
    a->n = i1 - a->i0 + 1;
    if (a->n > (int)(sizeof a->w / sizeof a->w[0]))
        a->n = (int)(sizeof a->w / sizeof a->w[0]);
    for (int m = 0; m < a->n; m++) {
        float d = fabsf((float)(a->i0 + m) - g);
        float wa = 1.0f - d * k->ia, wb = 1.0f - d * k->ib;
        a->w[m] = (wa > 0.0f ? k->wa * wa : 0.0f) + (wb > 0.0f ? k->wb * wb : 0.0f);
    }
}

/* One sub-sample's weight w at node coordinates (gx, gy), by its cell's kernels kx, ky */
static inline void splat(double *g, int nx, int ylo, int yhi, float gx, float gy, const axis_k *kx, const axis_k *ky,
                         float w)
{
    const int ny = yhi + 1;
    if (!(gx > -2.0f * AXIS_MAX && gy > -2.0f * AXIS_MAX && gx < (float)nx + 2.0f * AXIS_MAX &&
          gy < (float)ny + 2.0f * AXIS_MAX))
        return;
    axis_w ax, ay;
    axis_weights(gx, kx, &ax);
    axis_weights(gy, ky, &ay);
    for (int k = 0; k < ay.n; k++) {
        int y = ay.i0 + k;
        if (y < ylo || y > yhi || !(ay.w[k] > 0.0f))
            continue;
        double *row = g + (size_t)y * nx;
        const float wr = w * ay.w[k];
        for (int m = 0; m < ax.n; m++) {
            int x = ax.i0 + m;
            if (x >= 0 && x < nx)
                row[x] += (double)(wr * ax.w[m]);
        }
    }
}

#define CHUNK_ROWS 16 /* map rows per chunk of the parallel splat */

/* The identity map's density of each cell's water corners: the bilinear basis' mass matrix
 * at the sub-samples (a cell of water: 1/4 per node). */
static void identity_density(const node_job *j, double *den)
{
    const int nx = j->nx, ny = j->ny, gw = j->gx;
    const double *M = j->mass;
    for (int r = 0; r + 1 < ny; r++)
        for (int c = 0; c + 1 < nx; c++) {
            const float *a = j->img + ((size_t)r * nx + c) * 4, *b = a + 4;
            const float *d = a + (size_t)nx * 4, *e = d + 4;
            if (!(a[3] + b[3] + d[3] + e[3] > 0.0f))
                continue;
            double *q = den + (size_t)(r + j->oy) * gw + (c + j->ox);
            q[0] += a[3] * M[0] * M[0] + b[3] * M[1] * M[0] + d[3] * M[0] * M[1] + e[3] * M[1] * M[1];
            q[1] += a[3] * M[1] * M[0] + b[3] * M[0] * M[0] + d[3] * M[1] * M[1] + e[3] * M[0] * M[1];
            q[gw] += a[3] * M[0] * M[1] + b[3] * M[1] * M[1] + d[3] * M[0] * M[0] + e[3] * M[1] * M[0];
            q[gw + 1] += a[3] * M[1] * M[1] + b[3] * M[0] * M[1] + d[3] * M[1] * M[0] + e[3] * M[0] * M[0];
        }
}

/* A cell's kernels and the map rows its splat can reach; 0 for a cell without water. */
static int cell_reach(const node_job *j, int cell, axis_k *kx, axis_k *ky, int *y0, int *y1)
{
    const int nx = j->nx, s = j->in->samples;
    const float *a = j->img + (size_t)cell * 4, *b = a + 4, *d = a + (size_t)nx * 4, *e = d + 4;
    if (!(a[3] + b[3] + d[3] + e[3] > 0.0f))
        return 0;
    const float inv_step = 1.0f / (float)j->in->step;
    float ux = fmaxf(fmaxf(a[0], b[0]), fmaxf(d[0], e[0])) - fminf(fminf(a[0], b[0]), fminf(d[0], e[0]));
    float vlo = fminf(fminf(a[1], b[1]), fminf(d[1], e[1])), vhi = fmaxf(fmaxf(a[1], b[1]), fmaxf(d[1], e[1]));
    axis_kernel(ux * inv_step / (float)s, kx);
    axis_kernel((vhi - vlo) * inv_step / (float)s, ky);
    float lo = (vlo - 0.5f) * inv_step + (float)j->oy - ky->rb, hi = (vhi - 0.5f) * inv_step + (float)j->oy + ky->rb;
    lo = lo > -1.0f ? lo : -1.0f;
    hi = hi < (float)j->gy ? hi : (float)j->gy;
    *y0 = (int)ceilf(lo);
    *y1 = (int)floorf(hi);
    *y0 = *y0 < 0 ? 0 : *y0;
    *y1 = *y1 > j->gy - 1 ? j->gy - 1 : *y1;
    return *y0 <= *y1;
}

/* A cell's flux, s x s sub-samples, onto the map rows [ylo, yhi] only. */
static void splat_cell(const node_job *j, double *g, int cell, const axis_k *kx, const axis_k *ky, int ylo, int yhi)
{
    const int nx = j->nx, s = j->in->samples, gw = j->gx;
    const float ox = (float)j->ox, oy = (float)j->oy;
    const float inv_step = 1.0f / (float)j->in->step, ws = 1.0f / (float)(s * s);
    const float *a = j->img + (size_t)cell * 4, *b = a + 4, *d = a + (size_t)nx * 4, *e = d + 4;
    for (int sy = 0; sy < s; sy++) {
        float ty = ((float)sy + 0.5f) / (float)s;
        float l[3], m[3];
        for (int k = 0; k < 3; k++) {
            l[k] = a[k] + (d[k] - a[k]) * ty;
            m[k] = b[k] + (e[k] - b[k]) * ty;
        }
        for (int sx = 0; sx < s; sx++) {
            float tx = ((float)sx + 0.5f) / (float)s;
            float u = l[0] + (m[0] - l[0]) * tx, v = l[1] + (m[1] - l[1]) * tx;
            float w = l[2] + (m[2] - l[2]) * tx;
            splat(g, gw, ylo, yhi, (u - 0.5f) * inv_step + ox, (v - 0.5f) * inv_step + oy, kx, ky, w * ws);
        }
    }
}

/* The parallel splat: the map's rows in chunks of CHUNK_ROWS, each chunk splatting every
 * cell that reaches it (its list, in increasing cell order) onto its own rows only. Each
 * map node so adds its contributions in the same order as one thread walking every cell:
 * the same bits for any thread count (a sub-sample reaching two chunks is weighed twice). */
typedef struct splat_job {
    const node_job *j;
    double *g;
    const int *start, *cells; /* per chunk: its cells at cells[start[k] .. start[k + 1]) */
} splat_job;

static void splat_chunks(void *user, int begin, int end)
{
    const splat_job *sj = user;
    for (int k = begin; k < end; k++) {
        int ylo = k * CHUNK_ROWS, yhi = ylo + CHUNK_ROWS - 1;
        yhi = yhi < sj->j->gy - 1 ? yhi : sj->j->gy - 1;
        for (int q = sj->start[k]; q < sj->start[k + 1]; q++) {
            axis_k kx, ky;
            int y0, y1;
            if (cell_reach(sj->j, sj->cells[q], &kx, &ky, &y0, &y1))
                splat_cell(sj->j, sj->g, sj->cells[q], &kx, &ky, y0 > ylo ? y0 : ylo, y1 < yhi ? y1 : yhi);
        }
    }
}

/* Every cell's flux into g (and the identity's density into den); 0, or -1 out of memory. */
static int splat_cells(fx_context *ctx, const node_job *j, double *g, double *den)
{
    identity_density(j, den);
    const int nx = j->nx, ny = j->ny, chunks = (j->gy + CHUNK_ROWS - 1) / CHUNK_ROWS;
    int *start = fx_mem_calloc((size_t)chunks + 1, sizeof(int));
    if (!start)
        return -1;
    size_t total = 0;
    for (int pass = 0; pass < 2; pass++) {
        int *cells = NULL, *fill = NULL;
        if (pass == 1) {
            for (int k = 0; k < chunks; k++)
                start[k + 1] += start[k];
            cells = fx_mem_alloc((total ? total : 1) * sizeof(int));
            fill = fx_mem_calloc((size_t)chunks, sizeof(int));
            if (!cells || !fill) {
                fx_mem_free(cells);
                fx_mem_free(fill);
                fx_mem_free(start);
                return -1;
            }
        }
        for (int r = 0; r + 1 < ny; r++)
            for (int c = 0; c + 1 < nx; c++) {
                axis_k kx, ky;
                int y0, y1, cell = r * nx + c;
                if (!cell_reach(j, cell, &kx, &ky, &y0, &y1))
                    continue;
                for (int k = y0 / CHUNK_ROWS; k <= y1 / CHUNK_ROWS; k++) {
                    if (pass == 0) {
                        start[k + 1]++;
                        total++;
                    } else {
                        cells[start[k] + fill[k]++] = cell;
                    }
                }
            }
        if (pass == 1) {
            splat_job sj = {j, g, start, cells};
            fx_parallel_for(ctx, chunks, 1, splat_chunks, &sj);
            fx_mem_free(cells);
            fx_mem_free(fill);
        }
    }
    fx_mem_free(start);
    return 0;
}

/* gain = the refracted light's density + the unrefracted light the view does not hold: 1 -
 * the identity's density of its water (1 under water: the gain is the density; 0 where the
 * view has no water: the light reaches that point straight, plus what the water sends it) */
static void finish_gain(fx_caustic_map *m, const double *g, const double *dens)
{
    double sum = 0.0;
    long count = 0;
    for (int r = 0; r < m->ny; r++)
        for (int c = 0; c < m->nx; c++) {
            double den = dens[(size_t)r * m->nx + c], num = g[(size_t)r * m->nx + c];
            double v = num + (den < 1.0 ? 1.0 - den : 0.0);
            float f = !(v >= 0.0) ? 0.0f : v > FX_CAUSTIC_GAIN_MAX ? FX_CAUSTIC_GAIN_MAX : (float)v;
            m->gain[(size_t)r * m->nx + c] = f;
            if (r >= 2 && c >= 2 && r + 2 < m->ny && c + 2 < m->nx) {
                sum += f;
                count++;
            }
        }
    m->mean_gain = count ? sum / (double)count : 1.0;
}

/* The sun disc's blur: a separable Gaussian (clamped at the edges) of the gain, in place */
static void sun_blur(fx_caustic_map *m, double *line)
{
    double sigma = m->blur_sigma;
    if (!(sigma >= 0.2))
        return;
    int radius = (int)ceil(3.0 * sigma);
    if (radius > 64)
        radius = 64;
    double taps[129];
    double sum = 0.0;
    for (int k = -radius; k <= radius; k++)
        sum += taps[k + radius] = exp(-(double)(k * k) / (2.0 * sigma * sigma));
    for (int k = 0; k <= 2 * radius; k++)
        taps[k] /= sum;
    for (int pass = 0; pass < 2; pass++) {
        int n = pass ? m->ny : m->nx, lines = pass ? m->nx : m->ny;
        size_t stride = pass ? (size_t)m->nx : 1, next = pass ? 1 : (size_t)m->nx;
        for (int l = 0; l < lines; l++) {
            float *g = m->gain + (size_t)l * next;
            for (int i = 0; i < n; i++)
                line[i] = g[(size_t)i * stride];
            for (int i = 0; i < n; i++) {
                double acc = 0.0;
                for (int k = -radius; k <= radius; k++) {
                    int q = i + k < 0 ? 0 : i + k >= n ? n - 1 : i + k;
                    acc += taps[k + radius] * line[q];
                }
                g[(size_t)i * stride] = (float)acc;
            }
        }
    }
}

/* The map's nodes: the view's, widened to every water node's image (whole nodes, at most
 * twice the view's size each side; images beyond are dropped by the splat) */
static void map_extent(node_job *j)
{
    float lo_x = 0.0f, hi_x = (float)(j->nx - 1), lo_y = 0.0f, hi_y = (float)(j->ny - 1);
    const float inv_step = 1.0f / (float)j->in->step;
    for (size_t k = 0; k < (size_t)j->nx * j->ny; k++) {
        const float *q = j->img + k * 4;
        if (!(q[3] > 0.0f))
            continue;
        float u = (q[0] - 0.5f) * inv_step, v = (q[1] - 0.5f) * inv_step;
        lo_x = fminf(lo_x, u);
        hi_x = fmaxf(hi_x, u);
        lo_y = fminf(lo_y, v);
        hi_y = fmaxf(hi_y, v);
    }
    float mx = 2.0f * (float)j->nx, my = 2.0f * (float)j->ny;
    j->ox = (int)ceilf(fminf(-lo_x, mx)) + 1;
    j->oy = (int)ceilf(fminf(-lo_y, my)) + 1;
    j->gx = j->ox + (int)ceilf(fminf(hi_x, (float)(j->nx - 1) + mx)) + 2;
    j->gy = j->oy + (int)ceilf(fminf(hi_y, (float)(j->ny - 1) + my)) + 2;
}

fx_result fx_caustic_map_build(fx_context *ctx, const fx_caustic_input *in, fx_caustic_map *out, const char *where)
{
    memset(out, 0, sizeof *out);
    node_job j;
    memset(&j, 0, sizeof j);
    j.in = in;
    const int step = in->step > 0 ? in->step : 1;
    j.nx = (in->width - 1) / step + 1;
    j.ny = (in->height - 1) / step + 1;
    j.far = in->clip_end > 0.0f ? in->clip_end : 1e9f;
    j.L = fx_v3_normalize_or(fx_view_dir_to_world(in->view, fx_v3(0.0f, 0.0f, -1.0f)), fx_v3(0.0f, 0.0f, -1.0f));
    out->nx = j.nx;
    out->ny = j.ny;
    out->step = step;
    size_t n = (size_t)j.nx * j.ny;
    j.img = fx_mem_alloc(n * 4 * sizeof(float));
    j.water = fx_mem_alloc((size_t)j.ny * sizeof(long));
    j.drop = fx_mem_alloc((size_t)j.ny * sizeof(double));
    double *g = NULL, *den = NULL, *prof = NULL;
    fx_result r = FX_OK;
    if (!j.img || !j.water || !j.drop) {
        r = fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory (caustics map %dx%d)", where, j.nx, j.ny);
    } else {
        fx_caustic_input local = *in;
        local.step = step;
        local.samples = in->samples > 0 ? in->samples : 1;
        j.in = &local;
        for (int k = 0; k < local.samples; k++) {
            double t = ((double)k + 0.5) / local.samples;
            j.mass[0] += (1.0 - t) * (1.0 - t) / local.samples;
            j.mass[1] += t * (1.0 - t) / local.samples;
        }
        fx_parallel_for(ctx, j.ny, 1, node_rows, &j);
        map_extent(&j);
        size_t gn = (size_t)j.gx * j.gy;
        out->nx = j.gx;
        out->ny = j.gy;
        out->ox = j.ox;
        out->oy = j.oy;
        g = fx_mem_calloc(2 * gn, sizeof(double));
        den = g ? g + gn : NULL;
        prof = fx_mem_alloc((size_t)(j.gx + j.gy) * sizeof(double));
        out->gain = fx_mem_alloc(gn * sizeof(float));
        if (!g || !prof || !out->gain) {
            r = fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory (caustics map %dx%d)", where, j.gx, j.gy);
            fx_caustic_map_free(out);
            goto done;
        }
        double drop = 0.0;
        for (int k = 0; k < j.ny; k++) {
            out->water_nodes += j.water[k];
            drop += j.drop[k];
        }
        out->mean_drop = out->water_nodes ? drop / (double)out->water_nodes : 0.0;
        if (splat_cells(ctx, &j, g, den)) {
            r = fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory (caustics map %dx%d)", where, j.gx, j.gy);
            fx_caustic_map_free(out);
            goto done;
        }
        finish_gain(out, g, den);
        /* the sun disc: a cone of half-angle a / (2 ior) in the water, its radius on the
         * floor over the world size of a node (an orthographic view: 2 / P[0] wide) */
        double node_w = 2.0 / fabs((double)in->view->cam.projection[0]) / in->view->disp_w * step;
        double radius = out->mean_drop * tan(0.5 * (double)in->sun_angle / (double)in->ior);
        out->blur_sigma = in->sun_angle > 0.0f && node_w > 0.0 && isfinite(radius) ? 0.5 * radius / node_w : 0.0;
        if (out->blur_sigma > 20.0)
            out->blur_sigma = 20.0;
        sun_blur(out, prof);
    }
done:
    fx_mem_free(j.img);
    fx_mem_free(j.water);
    fx_mem_free(j.drop);
    fx_mem_free(g);
    fx_mem_free(prof);
    return r;
}

void fx_caustic_map_free(fx_caustic_map *m)
{
    if (!m)
        return;
    fx_mem_free(m->gain);
    m->gain = NULL;
}
