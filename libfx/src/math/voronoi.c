/* Periodic jittered-grid Voronoi: brute force and ring search (voronoi.h). */
#include "math/voronoi.h"

#include "core/mem.h"
#include "math/hash.h"

#include <math.h>
#include <string.h>
#ifdef __SSE2__
#include <emmintrin.h>
#endif

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

double fx_minkowski2(double dx, double dy, double p)
{
    double ax = fabs(dx), ay = fabs(dy);
    double m = ax > ay ? ax : ay;
    if (!(m > 0.0))
        return 0.0;
    if (isinf(p))
        return m;
    double s = pow(ax / m, p) + pow(ay / m, p); /* in [1, 2] */
    return m * pow(s, 1.0 / p);
}

int fx_voronoi_grid_for_points(int points)
{
    if (points < 1)
        return 1;
    int g = (int)floor(sqrt((double)points) + 0.5);
    return g < 1 ? 1 : g;
}

void fx_voronoi_warp_init(fx_voronoi_warp *w, int grid, uint32_t seed, double amp, double phase_shift)
{
    memset(w, 0, sizeof *w);
    w->grid = grid < 1 ? 1 : grid;
    w->amp = amp > 0.0 && isfinite(amp) ? amp : 0.0;
    w->lipschitz = 1.0;
    if (w->amp == 0.0)
        return;
    const double G = w->grid, len = 0.5 * G;
    for (int a = 0; a < 2; a++) {
        double lip = 0.0;
        for (int k = 0; k < FX_WARP_WAVES; k++) {
            uint32_t h = fx_hash4(a, k, (int32_t)seed, 0x3a7b);
            /* directions spread over a half turn, jittered: no axis is preferred */
            double th = M_PI * (k + 0.8 * fx_hash_to_unit(h) + 0.1) / FX_WARP_WAVES + 0.5 * M_PI * a;
            double m = floor(len * cos(th) + 0.5), n = floor(len * sin(th) + 0.5);
            if (m == 0.0 && n == 0.0)
                m = 1.0;
            w->kx[a][k] = 2.0 * M_PI * m / G;
            w->ky[a][k] = 2.0 * M_PI * n / G;
            w->ph[a][k] = 2.0 * M_PI * fx_hash_to_unit(fx_hash_u32(h ^ 0x51ed27u)) + phase_shift;
            lip += fmax(fabs(w->kx[a][k]), fabs(w->ky[a][k]));
        }
        w->lipschitz += w->amp / FX_WARP_WAVES * lip;
    }
}

static void warp_offset(const fx_voronoi_warp *w, double u, double v, double d[2])
{
    for (int a = 0; a < 2; a++) {
        double s = 0.0;
        for (int k = 0; k < FX_WARP_WAVES; k++)
            s += sin(w->kx[a][k] * u + w->ky[a][k] * v + w->ph[a][k]);
        d[a] = w->amp / FX_WARP_WAVES * s;
    }
}

int fx_voronoi_warp_table_alloc(fx_voronoi_warp *w)
{
    if (w->amp == 0.0 || w->tab || (double)w->grid * FX_WARP_SAMPLES > 1024.0)
        return 0;
    const int n = w->grid * FX_WARP_SAMPLES;
    w->tab = fx_mem_alloc((size_t)n * n * 2 * sizeof(double));
    if (!w->tab)
        return -1;
    w->n = n;
    return 1;
}

void fx_voronoi_warp_table_rows(fx_voronoi_warp *w, int row0, int row1)
{
    const int n = w->n;
    for (int j = row0; j < row1; j++)
        for (int i = 0; i < n; i++)
            warp_offset(w, (double)i / FX_WARP_SAMPLES, (double)j / FX_WARP_SAMPLES,
                        w->tab + ((size_t)j * n + i) * 2);
}

int fx_voronoi_warp_table(fx_voronoi_warp *w)
{
    int r = fx_voronoi_warp_table_alloc(w);
    if (r > 0)
        fx_voronoi_warp_table_rows(w, 0, w->n);
    return r < 0 ? -1 : 0;
}

void fx_voronoi_warp_free(fx_voronoi_warp *w)
{
    fx_mem_free(w->tab);
    w->tab = NULL;
    w->n = 0;
}

void fx_voronoi_warp_apply(const fx_voronoi_warp *w, double *x, double *y)
{
    if (w->amp == 0.0)
        return;
    const double G = w->grid;
    double u = *x, v = *y;
    if (w->tab && fabs(u) < 4e15 && fabs(v) < 4e15) {
        const int n = w->n;
        double tu = (u - G * floor(u / G)) * FX_WARP_SAMPLES, tv = (v - G * floor(v / G)) * FX_WARP_SAMPLES;
        double fu = floor(tu), fv = floor(tv);
        int i0 = (int)fu, j0 = (int)fv;
        double au = tu - fu, av = tv - fv;
        i0 = i0 >= n ? i0 - n : i0 < 0 ? i0 + n : i0;
        j0 = j0 >= n ? j0 - n : j0 < 0 ? j0 + n : j0;
        int i1 = i0 + 1 == n ? 0 : i0 + 1, j1 = j0 + 1 == n ? 0 : j0 + 1;
        const double *p00 = w->tab + ((size_t)j0 * n + i0) * 2, *p10 = w->tab + ((size_t)j0 * n + i1) * 2;
        const double *p01 = w->tab + ((size_t)j1 * n + i0) * 2, *p11 = w->tab + ((size_t)j1 * n + i1) * 2;
        for (int a = 0; a < 2; a++) {
            double top = p00[a] + au * (p10[a] - p00[a]), bot = p01[a] + au * (p11[a] - p01[a]);
            double d = top + av * (bot - top);
            if (a == 0)
                *x += d;
            else
                *y += d;
        }
        return;
    }
    /* reduced to the tile first: the same offset for every image of a point, and sin's
     * argument stays small (precision) */
    if (fabs(u) < 4e15 && fabs(v) < 4e15) {
        u -= G * floor(u / G);
        v -= G * floor(v / G);
    }
    double d[2];
    warp_offset(w, u, v, d);
    *x += d[0];
    *y += d[1];
}

static void fx_voronoi_point(const fx_voronoi *v, int index, double *x, double *y)
{
    int G = v->grid;
    int cx = index % G, cy = index / G;
    uint32_t h = fx_hash4(cx, cy, (int32_t)v->seed, 0x5eed);
    double h1 = fx_hash_to_unit(h), h2 = fx_hash_to_unit(fx_hash_u32(h ^ 0x1234567u));
    double h3 = fx_hash_to_unit(fx_hash_u32(h ^ 0x89abcdefu)), h4 = fx_hash_to_unit(fx_hash_u32(h + 77u));
    double w1 = v->speed * (0.6 + 0.8 * h3), w2 = v->speed * (0.6 + 0.8 * h4);
    *x = cx + 0.5 + 0.44 * sin(2.0 * M_PI * h1 + w1 * v->time);
    *y = cy + 0.5 + 0.44 * sin(2.0 * M_PI * h2 + w2 * v->time);
}

/* floor(t) without a libm call (x86-64 without SSE4.1 has no rounding instruction): the
 * same value for every t (|t| < 2^52 through an integer; beyond, or NaN, libm's floor) */
static inline double floor_fast(double t)
{
    if (!(fabs(t) < 4503599627370496.0))
        return floor(t);
    double f = (double)(long long)t;
    return f > t ? f - 1.0 : f;
}

static inline double wrap_tile(double a, double G)
{
    double r = a - G * floor_fast(a / G);
    return r >= G ? 0.0 : r;
}

/* (d, k) < (f, i) lexicographically */
static inline int before(double d, int k, double f, int i)
{
    return d < f || (d == f && k < i);
}

/* Where the exact searches read a point: computed now (fx_voronoi_brute/grid) or from a
 * frame's table (the same doubles, fx_voronoi_table_init). */
typedef struct point_source {
    const fx_voronoi *v; /* NULL: read x, y */
    const double *x, *y;
    int grid;
    double p;
} point_source;

static inline void consider(const point_source *s, double qx, double qy, int k, fx_voronoi_hit *h)
{
    if (k == h->i1 || k == h->i2)
        return;
    double px, py;
    if (s->v)
        fx_voronoi_point(s->v, k, &px, &py);
    else
        px = s->x[k], py = s->y[k];
    double G = s->grid;
    double dx = qx - px, dy = qy - py;
    dx -= G * floor(dx / G + 0.5);
    dy -= G * floor(dy / G + 0.5);
    double d = fx_minkowski2(dx, dy, s->p);
    if (before(d, k, h->f1, h->i1)) {
        h->f2 = h->f1;
        h->i2 = h->i1;
        h->f1 = d;
        h->i1 = k;
    } else if (before(d, k, h->f2, h->i2)) {
        h->f2 = d;
        h->i2 = k;
    }
}

static void finish(int G, fx_voronoi_hit *h)
{
    if (G == 1) {
        h->i2 = h->i1;
        h->f2 = h->f1 + 1.0;
    }
}

static void exact_brute(const point_source *s, double x, double y, fx_voronoi_hit *out)
{
    const int G = s->grid;
    double qx = wrap_tile(x, G), qy = wrap_tile(y, G);
    fx_voronoi_hit h = {-1, -1, INFINITY, INFINITY};
    for (int k = 0; k < G * G; k++)
        consider(s, qx, qy, k, &h);
    finish(G, &h);
    *out = h;
}

static void exact_grid(const point_source *s, double x, double y, fx_voronoi_hit *out)
{
    const int G = s->grid;
    double qx = wrap_tile(x, G), qy = wrap_tile(y, G);
    int cx = (int)floor(qx), cy = (int)floor(qy);
    if (cx >= G) cx = G - 1;
    if (cy >= G) cy = G - 1;
    fx_voronoi_hit h = {-1, -1, INFINITY, INFINITY};
    int max_ring = G / 2 + 1;
    for (int ring = 0; ring <= max_ring; ring++) {
        if (ring >= 1 && (double)(ring - 1) > h.f2)
            break;
        for (int dy = -ring; dy <= ring; dy++) {
            int edge_row = dy == -ring || dy == ring;
            for (int dx = -ring; dx <= ring; dx += edge_row ? 1 : 2 * ring) {
                int gx = ((cx + dx) % G + G) % G, gy = ((cy + dy) % G + G) % G;
                consider(s, qx, qy, gy * G + gx, &h);
                if (ring == 0)
                    break;
            }
        }
    }
    finish(G, &h);
    *out = h;
}

void fx_voronoi_brute(const fx_voronoi *v, double x, double y, fx_voronoi_hit *out)
{
    point_source s = {v, NULL, NULL, v->grid, v->p};
    exact_brute(&s, x, y, out);
}

void fx_voronoi_grid(const fx_voronoi *v, double x, double y, fx_voronoi_hit *out)
{
    point_source s = {v, NULL, NULL, v->grid, v->p};
    exact_grid(&s, x, y, out);
}

/* ---- per-frame point table ---- */

static void cbrt_table(double *lut);

/* The fast kinds' ordering key of an offset, in double (for the lists' bounds) */
static double key_d(int kind, double ax, double ay)
{
    ax = fabs(ax);
    ay = fabs(ay);
    switch (kind) {
    case 1:
        return ax + ay;
    case 2:
        return ax * sqrt(ax) + ay * sqrt(ay);
    case 3:
        return ax * ax + ay * ay;
    default:
        return ax > ay ? ax : ay;
    }
}

/* Neighbour (dx, dy) of cell (cx, cy): its point's index and the image's coordinates */
static inline int neighbour(const fx_voronoi_table *t, int cx, int cy, int dx, int dy, double *px, double *py,
                            int *e)
{
    const int G = t->grid;
    int gx = cx + dx, sx = gx < 0 ? -1 : gx >= G ? 1 : 0;
    int gy = cy + dy, sy = gy < 0 ? -1 : gy >= G ? 1 : 0;
    int k = (gy - sy * G) * G + (gx - sx * G);
    *px = t->x[k] + sx * (double)G;
    *py = t->y[k] + sy * (double)G;
    e[0] = k * 3 + sx + 1;
    e[1] = k * 3 + sy + 1;
    return k;
}

/* The lists of cell (cx, cy)'s squares. Bounds in double with a margin of 1e-3 (+1e-4
 * relative) in key units: the float keys err by below 1e-4 (coordinates < 130 rounded to
 * float, |offsets| < 3). A square whose limit reaches 2.05 cells (points beyond the 5 x 5
 * cells are >= 2.06 away along an axis: >= 0.06 inside their cell), or whose list would
 * exceed FX_VORONOI_LIST_MAX, keeps the ring search (-1). */
static inline double max_d(double a, double b)
{
    return a > b ? a : b;
}

static void cell_lists(fx_voronoi_table *t, int cx, int cy)
{
    const int S = t->sub, GS = t->grid * S;
    double px[25], py[25];
    int k[25], e[25][2];
    for (int n = 0; n < 25; n++)
        k[n] = neighbour(t, cx, cy, n % 5 - 2, n / 5 - 2, &px[n], &py[n], e[n]);
    const double far_key = key_d(t->kind, 2.05, 0.0);
    for (int sy = 0; sy < S; sy++)
        for (int sx = 0; sx < S; sx++) {
            const int ux = cx * S + sx, uy = cy * S + sy;
            const double x0 = (double)ux / S, x1 = (double)(ux + 1) / S;
            const double y0 = (double)uy / S, y1 = (double)(uy + 1) / S;
            double u1 = INFINITY, u2 = INFINITY;
            for (int dy = -1; dy <= 1; dy++)
                for (int dx = -1; dx <= 1; dx++) {
                    int n = (dy + 2) * 5 + dx + 2;
                    double f = key_d(t->kind, max_d(fabs(x0 - px[n]), fabs(x1 - px[n])),
                                     max_d(fabs(y0 - py[n]), fabs(y1 - py[n])));
                    if (f < u1) {
                        u2 = u1;
                        u1 = f;
                    } else if (f < u2) {
                        u2 = f;
                    }
                }
            const double lim = u2 + 1e-3 + 1e-4 * u2;
            const size_t sq = (size_t)uy * GS + ux, base = sq * FX_VORONOI_LIST_MAX;
            int cnt = 0;
            if (!(lim < far_key))
                cnt = -1;
            /* the largest offset along one axis within the limit (a cheap first test) */
            const double axis = t->kind == 1 || t->kind == 4 ? lim : t->kind == 3 ? sqrt(lim) : cbrt(lim * lim);
            for (int n = 0; n < 25 && cnt >= 0; n++) {
                double ox = max_d(0.0, max_d(x0 - px[n], px[n] - x1)), oy = max_d(0.0, max_d(y0 - py[n], py[n] - y1));
                if (ox > axis * 1.0001 || oy > axis * 1.0001 || key_d(t->kind, ox, oy) > lim)
                    continue;
                if (cnt == FX_VORONOI_LIST_MAX) {
                    cnt = -1;
                    break;
                }
                int at = cnt++;
                while (at > 0 && t->lk[base + at - 1] > k[n]) { /* insertion: increasing k */
                    t->lk[base + at] = t->lk[base + at - 1];
                    t->lx[base + at] = t->lx[base + at - 1];
                    t->ly[base + at] = t->ly[base + at - 1];
                    at--;
                }
                t->lk[base + at] = k[n];
                t->lx[base + at] = t->fx[e[n][0]];
                t->ly[base + at] = t->fy[e[n][1]];
            }
            t->list_n[sq] = cnt;
            /* dummies up to a multiple of 4 (the vectorised key loop reads them; the selection
             * does not): far away, finite keys for every kind */
            for (int c = cnt < 0 ? 0 : cnt; c < FX_VORONOI_LIST_MAX && (c & 3); c++) {
                t->lx[base + c] = t->ly[base + c] = 1e9f;
                t->lk[base + c] = -1;
            }
        }
}

void fx_voronoi_table_build_lists(fx_voronoi_table *t, int row0, int row1)
{
    if (!t->sub)
        return;
    for (int cy = row0; cy < row1 && cy < t->grid; cy++)
        for (int cx = 0; cx < t->grid; cx++)
            cell_lists(t, cx, cy);
}

int fx_voronoi_table_init(fx_voronoi_table *t, const fx_voronoi *v, int fast)
{
    memset(t, 0, sizeof *t);
    const int G = v->grid;
    const size_t n = (size_t)G * G;
    t->grid = G;
    t->inv_grid = 1.0 / G;
    t->p = v->p;
    if (fast && G >= 10)
        t->kind = v->p == 1.0 ? 1 : v->p == 1.5 ? 2 : v->p == 2.0 ? 3 : isinf(v->p) ? 4 : 0;
    t->x = fx_mem_alloc(n * sizeof(double));
    t->y = fx_mem_alloc(n * sizeof(double));
    if (t->kind) {
        t->fx = fx_mem_alloc(n * 3 * sizeof(float));
        t->fy = fx_mem_alloc(n * 3 * sizeof(float));
    }
    if (!t->x || !t->y || (t->kind && (!t->fx || !t->fy))) {
        fx_voronoi_table_free(t);
        return -1;
    }
    for (size_t k = 0; k < n; k++) {
        fx_voronoi_point(v, (int)k, &t->x[k], &t->y[k]);
        if (t->kind)
            for (int s = -1; s <= 1; s++) {
                t->fx[k * 3 + s + 1] = (float)(t->x[k] + s * (double)G);
                t->fy[k * 3 + s + 1] = (float)(t->y[k] + s * (double)G);
            }
    }
    if (t->kind == 2) {
        cbrt_table(t->cbrt_lut);
        for (int eb = 0; eb < 256; eb++) { /* cbrt23's exponent split, once per table */
            int e = eb - 127;
            int q = (e + 129) / 3 - 43; /* floor(e / 3), e in [-126, 127] */
            int r = e - 3 * q;
            uint64_t sb = (uint64_t)(q + 1023) << 52;
            memcpy(&t->cbrt_scale[eb], &sb, sizeof sb);
            t->cbrt_off[eb] = r * (FX_VORONOI_CBRT_BINS + 1); /* CBRT_ROW */
            if (eb == 0) { /* not read: cbrt23_t returns 0 first */
                t->cbrt_scale[eb] = 0.0;
                t->cbrt_off[eb] = 0;
            }
        }
    }
    if (t->kind && G <= 64 && fast != 3) {
        t->sub = G <= 32 ? 4 : 2;
        const size_t squares = n * t->sub * t->sub;
        t->list_n = fx_mem_alloc(squares * sizeof(int));
        t->lx = fx_mem_alloc(squares * FX_VORONOI_LIST_MAX * sizeof(float));
        t->ly = fx_mem_alloc(squares * FX_VORONOI_LIST_MAX * sizeof(float));
        t->lk = fx_mem_alloc(squares * FX_VORONOI_LIST_MAX * sizeof(int));
        if (!t->list_n || !t->lx || !t->ly || !t->lk) {
            fx_voronoi_table_free(t);
            return -1;
        }
        if (fast != 2)
            fx_voronoi_table_build_lists(t, 0, G);
    }
    return 0;
}

void fx_voronoi_table_free(fx_voronoi_table *t)
{
    fx_mem_free(t->x);
    fx_mem_free(t->y);
    fx_mem_free(t->fx);
    fx_mem_free(t->fy);
    fx_mem_free(t->list_n);
    fx_mem_free(t->lx);
    fx_mem_free(t->ly);
    fx_mem_free(t->lk);
    t->x = t->y = NULL;
    t->fx = t->fy = NULL;
    t->list_n = t->lk = NULL;
    t->lx = t->ly = NULL;
    t->sub = 0;
}

/* fast: ordering key, monotone in the distance (correctly rounded sqrt, products and sums
 * of non-negative floats keep the order of their exact values, ties aside) */
static inline float key_of(int kind, float dx, float dy)
{
    float ax = fabsf(dx), ay = fabsf(dy);
    switch (kind) {
    case 1:
        return ax + ay;
    case 2:
        return ax * sqrtf(ax) + ay * sqrtf(ay);
    case 3:
        return ax * ax + ay * ay;
    default:
        return ax > ay ? ax : ay;
    }
}

/* The cube root without libm (its bits differ between systems): Kahan's exponent / 3 bit
 * trick (error < 4%) and three Halley steps in double (cubic convergence). For the table. */
static double cbrt_iter(double k)
{
    uint64_t b;
    memcpy(&b, &k, sizeof b);
    b = b / 3 + UINT64_C(0x2A9F7893782DA1CE);
    double r;
    memcpy(&r, &b, sizeof r);
    for (int it = 0; it < 3; it++) {
        double r3 = r * r * r;
        r *= (r3 + 2.0 * k) / (2.0 * r3 + k);
    }
    return r;
}

#define CBRT_ROW (FX_VORONOI_CBRT_BINS + 1)

static void cbrt_table(double *lut)
{
    for (int r = 0; r < 3; r++)
        for (int i = 0; i <= FX_VORONOI_CBRT_BINS; i++)
            lut[r * CBRT_ROW + i] = cbrt_iter((1.0 + (double)i / FX_VORONOI_CBRT_BINS) * (double)(1 << r));
}

/* k^(2/3) for the p = 1.5 key (a float key: k = 2^(3q + r) m, m in [1, 2)): 2^q times
 * cbrt(2^r m) interpolated linearly between the table's nodes (1024 bins: m's top 10
 * mantissa bits pick the bin, the other 13 the weight; the error of the chord, h^2 / 8
 * max |f''|, is below 5e-8 relative: the float key's own rounding), squared. No division
 * and no libm: the same bits everywhere. The exponent's split (q = floor(e / 3), r, 2^q and
 * r's row) is read from the table's per-exponent entries, made once per table. */
static inline double cbrt23(const fx_voronoi_table *t, float kf)
{
    uint32_t b;
    memcpy(&b, &kf, sizeof b);
    if (!(kf > 0.0f) || (b >> 23) == 0)
        return 0.0;
    const uint32_t eb = b >> 23; /* kf > 0: the sign bit is 0, eb in [1, 255] */
    const double scale = t->cbrt_scale[eb];
    const double *row = t->cbrt_lut + t->cbrt_off[eb] + ((b >> 13) & (FX_VORONOI_CBRT_BINS - 1));
    double tt = (double)(b & 0x1FFFu) * (1.0 / 8192.0);
    double x = scale * (row[0] + (row[1] - row[0]) * tt);
    return x * x;
}

static inline double dist_of_key(const fx_voronoi_table *t, float k)
{
    switch (t->kind) {
    case 2:
        return cbrt23(t, k);
    case 3:
        return sqrtf(k);
    default:
        return k;
    }
}

typedef struct fast_hit {
    float k1, k2;
    int i1, i2;
} fast_hit;

static inline void consider_fast(const fx_voronoi_table *t, float qx, float qy, int k, int sx, int sy, fast_hit *h)
{
    float key = key_of(t->kind, qx - t->fx[k * 3 + sx + 1], qy - t->fy[k * 3 + sy + 1]);
    if (key < h->k1 || (key == h->k1 && k < h->i1)) {
        h->k2 = h->k1;
        h->i2 = h->i1;
        h->k1 = key;
        h->i1 = k;
    } else if (key < h->k2 || (key == h->k2 && k < h->i2)) {
        h->k2 = key;
        h->i2 = k;
    }
}

/* wrap_tile with a product by 1 / G (no division); a rounding below 0 is 0, at G is 0 */
static inline double wrap_tile_inv(double a, double G, double inv)
{
    double r = a - G * floor_fast(a * inv);
    return r >= G || !(r > 0.0) ? 0.0 : r;
}

/* shared by brute and grid: the same float query */
static inline void fast_query(const fx_voronoi_table *t, double x, double y, float *qx, float *qy)
{
    double G = t->grid;
    *qx = (float)wrap_tile_inv(x, G, t->inv_grid);
    *qy = (float)wrap_tile_inv(y, G, t->inv_grid);
}

static inline void fast_out(const fx_voronoi_table *t, const fast_hit *h, fx_voronoi_hit *out)
{
    out->i1 = h->i1;
    out->i2 = h->i2;
    out->f1 = dist_of_key(t, h->k1);
    out->f2 = dist_of_key(t, h->k2);
}

static void fast_brute(const fx_voronoi_table *t, float qx, float qy, fx_voronoi_hit *out)
{
    const int G = t->grid;
    const float half = 0.5f * (float)G;
    fast_hit h = {INFINITY, INFINITY, -1, -1};
    for (int k = 0; k < G * G; k++) {
        /* the point's image nearest the query */
        float dx = qx - t->fx[k * 3 + 1], dy = qy - t->fy[k * 3 + 1];
        int sx = dx > half ? 1 : dx < -half ? -1 : 0, sy = dy > half ? 1 : dy < -half ? -1 : 0;
        consider_fast(t, qx, qy, k, sx, sy, &h);
    }
    fast_out(t, &h, out);
}

void fx_voronoi_table_brute(const fx_voronoi_table *t, double x, double y, fx_voronoi_hit *out)
{
    const int G = t->grid;
    if (t->kind) {
        float qx, qy;
        fast_query(t, x, y, &qx, &qy);
        fast_brute(t, qx, qy, out);
        return;
    }
    point_source s = {NULL, t->x, t->y, G, t->p};
    exact_brute(&s, x, y, out);
}

static inline float bound_key(int kind, float b)
{
    return kind == 2 ? b * sqrtf(b) : kind == 3 ? b * b : b;
}

/* The keys of a list's candidates, four at a time (lists are padded to a multiple of 4 with
 * far dummies, cell_lists): a loop without branches or calls that the compiler vectorises
 * (sqrt is correctly rounded in its scalar and vector forms alike: the same bits). Then the
 * real candidates' selection, each as one integer, key bits (a float >= 0: its bits order
 * as its value) above the point index: the brute force's (key, index) order exactly, the
 * nearest two kept by min/max without branches. */
#define KEY_LOOP(KEY)                                                                                     \
    for (int c = 0; c < n4; c++) {                                                                       \
        float ax = fabsf(qx - lx[c]), ay = fabsf(qy - ly[c]);                                            \
        key[c] = KEY;                                                                                    \
    }

static inline uint64_t packed(float key, int k)
{
    uint32_t b;
    memcpy(&b, &key, sizeof b);
    return (uint64_t)b << 32 | (uint32_t)k;
}

static void list_search(const fx_voronoi_table *t, float qx, float qy, int n, size_t base, fast_hit *h)
{
    const float *restrict lx = t->lx + base, *restrict ly = t->ly + base;
    const int *lk = t->lk + base;
    float key[FX_VORONOI_LIST_MAX];
    const int n4 = (n + 3) & ~3;
    switch (t->kind) {
    case 1:
        KEY_LOOP(ax + ay)
        break;
    case 2:
        KEY_LOOP(ax * sqrtf(ax) + ay * sqrtf(ay))
        break;
    case 3:
        KEY_LOOP(ax * ax + ay * ay)
        break;
    default:
        KEY_LOOP(ax > ay ? ax : ay)
        break;
    }
    uint64_t m1 = UINT64_MAX, m2 = UINT64_MAX;
    for (int c = 0; c < n; c++) {
        uint64_t v = packed(key[c], lk[c]);
        uint64_t hi = v > m1 ? v : m1;
        m1 = v < m1 ? v : m1;
        m2 = hi < m2 ? hi : m2;
    }
    uint32_t b1 = (uint32_t)(m1 >> 32), b2 = (uint32_t)(m2 >> 32);
    memcpy(&h->k1, &b1, sizeof b1);
    memcpy(&h->k2, &b2, sizeof b2);
    h->i1 = (int)(uint32_t)m1;
    h->i2 = (int)(uint32_t)m2;
}

void fx_voronoi_table_grid(const fx_voronoi_table *t, double x, double y, fx_voronoi_hit *out)
{
    const int G = t->grid;
    if (t->kind) {
        float qx, qy;
        fast_query(t, x, y, &qx, &qy);
        if (t->sub) {
            const int GS = G * t->sub;
            int ux = (int)(qx * (float)t->sub), uy = (int)(qy * (float)t->sub); /* exact: sub = 2^j */
            ux = ux < GS ? ux : GS - 1;
            uy = uy < GS ? uy : GS - 1;
            size_t sq = (size_t)uy * GS + ux;
            int n = t->list_n[sq];
            if (n >= 2) {
                fast_hit h;
                list_search(t, qx, qy, n, sq * FX_VORONOI_LIST_MAX, &h);
                fast_out(t, &h, out);
                return;
            }
        }
        int cx = (int)qx, cy = (int)qy;
        if (cx >= G) cx = G - 1;
        if (cy >= G) cy = G - 1;
        float ex = qx - (float)cx, ey = qy - (float)cy;
        float edge = fminf(fminf(ex, 1.0f - ex), fminf(ey, 1.0f - ey));
        if (!(edge >= 0.0f))
            edge = 0.0f;
        fast_hit h = {INFINITY, INFINITY, -1, -1};
        /* rings up to G/2 - 1 see only nearest images (|d| < ring + 1 <= G/2) */
        for (int ring = 0;; ring++) {
            if (ring >= 1 && bound_key(t->kind, (float)(ring - 1) + 0.05f + edge) > h.k2)
                break;
            if (ring > G / 2 - 1) { /* not reached for p >= 1 in practice; exact anyway */
                fast_brute(t, qx, qy, out);
                return;
            }
            for (int dy = -ring; dy <= ring; dy++) {
                int edge_row = dy == -ring || dy == ring;
                int gy = cy + dy, sy = gy < 0 ? -1 : gy >= G ? 1 : 0;
                gy -= sy * G;
                for (int dx = -ring; dx <= ring; dx += edge_row ? 1 : 2 * ring) {
                    int gx = cx + dx, sx = gx < 0 ? -1 : gx >= G ? 1 : 0;
                    gx -= sx * G;
                    consider_fast(t, qx, qy, gy * G + gx, sx, sy, &h);
                    if (ring == 0)
                        break;
                }
            }
        }
        fast_out(t, &h, out);
        return;
    }
    point_source s = {NULL, t->x, t->y, G, t->p};
    exact_grid(&s, x, y, out);
}

/* wrap_tile_inv of n values into floats, two at a time in SSE2 where both quotients lie
 * within int32 (floor by truncation and a correction, as floor_fast does below 2^52): the
 * same operations on the same values, the same bits; others one at a time. */
static void wrap_tile_n(const double *a, int n, double G, double inv, float *out)
{
    int q = 0;
#ifdef __SSE2__
    const __m128d vg = _mm_set1_pd(G), vinv = _mm_set1_pd(inv), lim = _mm_set1_pd(2147483647.0);
    const __m128d one = _mm_set1_pd(1.0), zero = _mm_setzero_pd();
    const __m128d absmask = _mm_castsi128_pd(_mm_set1_epi64x(0x7FFFFFFFFFFFFFFFLL));
    for (; q + 2 <= n; q += 2) {
        const __m128d va = _mm_loadu_pd(a + q);
        const __m128d t = _mm_mul_pd(va, vinv);
        if (_mm_movemask_pd(_mm_cmplt_pd(_mm_and_pd(t, absmask), lim)) != 3) { /* large or NaN */
            out[q] = (float)wrap_tile_inv(a[q], G, inv);
            out[q + 1] = (float)wrap_tile_inv(a[q + 1], G, inv);
            continue;
        }
        __m128d f = _mm_cvtepi32_pd(_mm_cvttpd_epi32(t));
        f = _mm_sub_pd(f, _mm_and_pd(_mm_cmpgt_pd(f, t), one)); /* f > t ? f - 1 : f */
        __m128d r = _mm_sub_pd(va, _mm_mul_pd(vg, f));
        /* r >= G || !(r > 0) ? 0 : r */
        const __m128d keep = _mm_andnot_pd(_mm_cmpge_pd(r, vg), _mm_cmpgt_pd(r, zero));
        r = _mm_and_pd(r, keep);
        float o[4];
        _mm_storeu_ps(o, _mm_cvtpd_ps(r));
        out[q] = o[0];
        out[q + 1] = o[1];
    }
#endif
    for (; q < n; q++)
        out[q] = (float)wrap_tile_inv(a[q], G, inv);
}

/* n queries at once (the caller's batch of a row): the same candidates, order and bits as
 * n calls of fx_voronoi_table_grid, with the per-query switches hoisted: the keys of every
 * query with a square list first, then their distances in one loop per kind. */
void fx_voronoi_table_grid_n(const fx_voronoi_table *t, int n, const double *x, const double *y, double *f1,
                             double *f2, int *i1, int *i2)
{
    if (!t->kind || !t->sub) {
        for (int q = 0; q < n; q++) {
            fx_voronoi_hit h;
            fx_voronoi_table_grid(t, x[q], y[q], &h);
            f1[q] = h.f1;
            f2[q] = h.f2;
            if (i1) {
                i1[q] = h.i1;
                i2[q] = h.i2;
            }
        }
        return;
    }
    const int G = t->grid, GS = G * t->sub;
    const float subf = (float)t->sub;
    const double Gd = G, inv = t->inv_grid;
    float k1[FX_VORONOI_BATCH], k2[FX_VORONOI_BATCH], wx[FX_VORONOI_BATCH], wy[FX_VORONOI_BATCH];
    for (int q0 = 0; q0 < n; q0 += FX_VORONOI_BATCH) {
        const int m = n - q0 < FX_VORONOI_BATCH ? n - q0 : FX_VORONOI_BATCH;
        wrap_tile_n(x + q0, m, Gd, inv, wx);
        wrap_tile_n(y + q0, m, Gd, inv, wy);
        for (int q = 0; q < m; q++) {
            const float qx = wx[q], qy = wy[q];
            int ux = (int)(qx * subf), uy = (int)(qy * subf);
            ux = ux < GS ? ux : GS - 1;
            uy = uy < GS ? uy : GS - 1;
            const size_t sq = (size_t)uy * GS + ux;
            const int nl = t->list_n[sq];
            if (nl >= 2) {
                fast_hit h;
                list_search(t, qx, qy, nl, sq * FX_VORONOI_LIST_MAX, &h);
                k1[q] = h.k1;
                k2[q] = h.k2;
                if (i1) {
                    i1[q0 + q] = h.i1;
                    i2[q0 + q] = h.i2;
                }
            } else { /* the ring search (no list): its distances directly; key NaN marks it */
                fx_voronoi_hit h;
                fx_voronoi_table_grid(t, x[q0 + q], y[q0 + q], &h);
                f1[q0 + q] = h.f1;
                f2[q0 + q] = h.f2;
                if (i1) {
                    i1[q0 + q] = h.i1;
                    i2[q0 + q] = h.i2;
                }
                k1[q] = k2[q] = NAN;
            }
        }
        double *o1 = f1 + q0, *o2 = f2 + q0;
        switch (t->kind) {
        case 2:
            for (int q = 0; q < m; q++)
                if (k1[q] == k1[q]) {
                    o1[q] = cbrt23(t, k1[q]);
                    o2[q] = cbrt23(t, k2[q]);
                }
            break;
        case 3:
            for (int q = 0; q < m; q++)
                if (k1[q] == k1[q]) {
                    o1[q] = sqrtf(k1[q]);
                    o2[q] = sqrtf(k2[q]);
                }
            break;
        default:
            for (int q = 0; q < m; q++)
                if (k1[q] == k1[q]) {
                    o1[q] = k1[q];
                    o2[q] = k2[q];
                }
            break;
        }
    }
}

static inline void noise_corners(double fx, double fy, uint32_t seed, double *a, double *b, double *c, double *d)
{
    /* lattice coordinates kept in int range (fmod is the identity below 2^20: skip its cost) */
    double mx = fabs(fx) < 1048576.0 ? fx : fmod(fx, 1048576.0);
    double my = fabs(fy) < 1048576.0 ? fy : fmod(fy, 1048576.0);
    int ix = (int)mx, iy = (int)my;
    *a = fx_rand4(ix, iy, (int32_t)seed, 7);
    *b = fx_rand4(ix + 1, iy, (int32_t)seed, 7);
    *c = fx_rand4(ix, iy + 1, (int32_t)seed, 7);
    *d = fx_rand4(ix + 1, iy + 1, (int32_t)seed, 7);
}

static inline double noise_blend(double tx, double ty, double a, double b, double c, double d)
{
    tx = tx * tx * (3.0 - 2.0 * tx);
    ty = ty * ty * (3.0 - 2.0 * ty);
    return (a + (b - a) * tx) * (1.0 - ty) + (c + (d - c) * tx) * ty;
}

double fx_value_noise2_cached(double x, double y, uint32_t seed, fx_noise_cache *cache)
{
    double fx = floor_fast(x), fy = floor_fast(y);
    if (!cache->valid || fx != cache->fx || fy != cache->fy || seed != cache->seed) {
        noise_corners(fx, fy, seed, &cache->a, &cache->b, &cache->c, &cache->d);
        cache->fx = fx;
        cache->fy = fy;
        cache->seed = seed;
        cache->valid = 1;
    }
    return noise_blend(x - fx, y - fy, cache->a, cache->b, cache->c, cache->d);
}
