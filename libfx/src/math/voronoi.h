/* Periodic 2-D Voronoi (Worley) noise over a jittered grid, with a Minkowski metric.
 *
 * The feature points: a G x G grid of cells over a periodic tile of G x G cell units, one
 * point per cell, wandering inside its cell with time (each coordinate 0.5 + 0.44 sin(...)
 * of the cell, so a point never leaves it). Two searches find the nearest and second
 * nearest point of a query:
 *  - brute force: every point, O(G^2);
 *  - grid: rings of cells around the query's cell, stopping once a ring's nearest
 *    possible point (ring - 1 cells away along an axis: every Minkowski norm, p > 0, is at
 *    least the largest coordinate) is farther than the second best. O(1) for p >= 1.
 * Both compute each candidate's distance by the same code from the same wrapped offset and
 * order candidates by (distance, index), so they return the same indices and the same
 * distance bits (tested).
 *
 * Minkowski distance in the scaled form m (sum (|x_i| / m)^p)^(1/p), m = max |x_i|: no
 * overflow or underflow of the sum for any p; p = INFINITY is Chebyshev (m); p <= 0 or NaN
 * is rejected by callers (for p < 1 it is not a metric: no triangle inequality; the grid's
 * bound still holds, it only needs |x|_p >= |x|_inf). */
#ifndef LIBFX_MATH_VORONOI_H
#define LIBFX_MATH_VORONOI_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct fx_voronoi {
    int grid;       /* G >= 1: G x G cells, one point each; the tile is G cell units wide */
    uint32_t seed;
    double time;    /* animation time (seconds) */
    double speed;   /* wandering speed (radians per second of the points' sines) */
    double p;       /* Minkowski exponent > 0; INFINITY: Chebyshev */
} fx_voronoi;

typedef struct fx_voronoi_hit {
    int i1, i2;     /* nearest and second nearest point (index y * G + x); i2 = i1 if G == 1 */
    double f1, f2;  /* their distances in cell units (f2 = f1 + 1 if G == 1) */
} fx_voronoi_hit;

double fx_minkowski2(double dx, double dy, double p);
/* Nearest two points of (x, y) (cell units, any real: the tile repeats). */
void fx_voronoi_brute(const fx_voronoi *v, double x, double y, fx_voronoi_hit *out);
void fx_voronoi_grid(const fx_voronoi *v, double x, double y, fx_voronoi_hit *out);
/* Rounded square root of a point count: the grid size G (>= 1). */
int fx_voronoi_grid_for_points(int points);

/* A smooth periodic domain warp of the lookup position (cell units): the cells' sides bend
 * like a caustic network's instead of staying (nearly) straight Minkowski bisectors.
 * offset = amp / FX_WARP_WAVES x sum_k sin(2 pi (m_k x + n_k y) / G + phase_k + drift t),
 * per axis, with whole wave numbers (m_k, n_k) of length ~ G / 2 (a wavelength of ~2 cells)
 * in directions from the seed: periodic over the tile, the same bits for every query order. */
#define FX_WARP_WAVES 3
typedef struct fx_voronoi_warp {
    double amp;                      /* cells; 0: no warp (the query is left as it is) */
    int grid;
    double kx[2][FX_WARP_WAVES], ky[2][FX_WARP_WAVES], ph[2][FX_WARP_WAVES];
    double lipschitz; /* L1 extent of a warped footprint <= lipschitz x its L1 extent */
    double *tab;      /* fx_voronoi_warp_table: n x n samples (2 doubles each) over the tile */
    int n;            /* FX_WARP_SAMPLES x grid */
} fx_voronoi_warp;
/* Samples per cell of the offsets' table: ~16 per wave of the field; the bilinear
 * interpolation between them stays within a few % of the offsets, is as periodic and
 * continuous, and keeps the Lipschitz bound (its slopes are averages of the samples'
 * differences). */
#define FX_WARP_SAMPLES 8
void fx_voronoi_warp_init(fx_voronoi_warp *w, int grid, uint32_t seed, double amp, double phase_shift);
/* (x, y) in cell units -> the warped position (the identity when amp is 0) */
void fx_voronoi_warp_apply(const fx_voronoi_warp *w, double *x, double *y);
/* Tabulates the offsets (then fx_voronoi_warp_apply interpolates: no sines per query) when the
 * table has at most 2^20 samples (grid <= 128); 0, or -1 out of memory. */
int fx_voronoi_warp_table(fx_voronoi_warp *w);
/* The same in two steps, for a parallel fill: allocate (0: no table wanted or made; 1: fill
 * rows 0 .. w->n - 1 with fx_voronoi_warp_table_rows; -1 out of memory) */
int fx_voronoi_warp_table_alloc(fx_voronoi_warp *w);
void fx_voronoi_warp_table_rows(fx_voronoi_warp *w, int row0, int row1);
void fx_voronoi_warp_free(fx_voronoi_warp *w);

/* A frame's points, computed once (they depend only on time): the per-query searches
 * below then cost no sin/hash per candidate. Two distance kinds:
 *  - exact (fast = 0, or p not in {1, 1.5, 2, inf}): double, fx_minkowski2, the same
 *    candidates, order and bits as fx_voronoi_brute/grid above (tested);
 *  - fast (fast = 1 and p in {1, 1.5, 2, inf}): float, no pow: each candidate is ordered by
 *    the key sum |d_i|^p (|x| sqrt|x| for p = 1.5, x^2 for 2, max for inf), which is
 *    monotone in the distance, and only F1 and F2 are turned into distances (key^(1/p)).
 *    Candidates are the points' periodic images stored at x - G, x, x + G, so brute force
 *    and the ring search compute a candidate's key from the same floats: same bits. Float
 *    tile coordinates (< G) err by a few ulps: 2e-5 cells at 40 000 points (tested within
 *    1e-6 (G + 1) of exact). The
 *    ring search stops on the tight bound (ring - 1) + 0.05 + (query's distance to its
 *    cell's nearest side): a point stays at least 0.06 inside its cell. For G < 10 (rings
 *    could reach a non-nearest image) the fast kind uses brute force (<= 81 points). */
typedef struct fx_voronoi_table {
    int grid;
    double p;
    int kind;          /* 0 exact; 1: p = 1, 2: p = 1.5, 3: p = 2, 4: inf */
    double *x, *y;     /* G*G point positions (fx_voronoi_point's doubles) */
    float *fx, *fy;    /* fast: 3 per point (x - G, x, x + G), index point * 3 + s + 1 */
    /* fast, 10 <= G <= 64: per square candidate lists. Each cell is split into sub x sub
     * squares (sub = 4 up to G = 32, 2 up to 64: at most 16 384 squares); a
     * square's list holds every point that can be the nearest or second nearest of some
     * query inside it (a point is left out only if its distance lower bound over the
     * square exceeds, by a margin far above float rounding, the second smallest distance
     * upper bound among the 3 x 3 cells' points), at the image the brute force uses, in
     * increasing point index: a query visits about 4 points (G = 14, sub 4) instead of 9
     * to 25, and gets the brute force's bits. Each list is padded to a multiple of 4
     * entries with far dummies (index -1): its keys are computed in a vectorised loop, the
     * selection reads the real entries only. */
    int sub;           /* squares per cell side; 0: no lists (ring search) */
    int *list_n;       /* per square (row-major over G * sub columns): count; -1: ring search */
    float *lx, *ly;    /* FX_VORONOI_LIST_MAX per square: the candidate's coordinates (its image) */
    int *lk;           /* ... and its point index */
    double inv_grid;   /* 1 / G: the fast kinds wrap queries with a product, no division */
    double cbrt_lut[3 * (1024 + 1)]; /* p = 1.5: cbrt(2^r m) at m = 1 + i / FX_VORONOI_CBRT_BINS */
    /* p = 1.5, per biased float exponent eb (1..254, e = eb - 127 = 3 q + r): 2^q, and r's
     * row offset in cbrt_lut (eb 0: scale 0) */
    double cbrt_scale[256];
    int cbrt_off[256];
} fx_voronoi_table;

#define FX_VORONOI_CBRT_BINS 1024

#define FX_VORONOI_LIST_MAX 12

/* Fills t (allocates; 0 on success, -1 out of memory). fast: 0 exact; 1 the fast kind when
 * p allows; 2 the same, but the square lists (if any) are left for the caller to build
 * with fx_voronoi_table_build_lists over all cell rows [0, G) (in parallel, say) before
 * any query; 3 the fast kind without lists (a few queries: not worth building them). */
int fx_voronoi_table_init(fx_voronoi_table *t, const fx_voronoi *v, int fast);
/* Builds the lists of the squares of cell rows [row0, row1) (no-op without lists). */
void fx_voronoi_table_build_lists(fx_voronoi_table *t, int row0, int row1);
void fx_voronoi_table_free(fx_voronoi_table *t);
void fx_voronoi_table_brute(const fx_voronoi_table *t, double x, double y, fx_voronoi_hit *out);
void fx_voronoi_table_grid(const fx_voronoi_table *t, double x, double y, fx_voronoi_hit *out);

/* n queries of fx_voronoi_table_grid at once: their F1 and F2 and (i1 not NULL) the
 * points' indices, the same bits. */
#define FX_VORONOI_BATCH 64
void fx_voronoi_table_grid_n(const fx_voronoi_table *t, int n, const double *x, const double *y, double *f1,
                             double *f2, int *i1, int *i2);

/* Smooth value noise in [0, 1] (bilinear over hashed lattice values, smoothstep weights),
 * keeping the last lattice cell's four hashed values: nearby queries (a row of pixels
 * inside one noise cell) hash nothing. Initialise the cache with valid = 0. */
typedef struct fx_noise_cache {
    int valid;
    double fx, fy;
    uint32_t seed;
    double a, b, c, d;
} fx_noise_cache;
double fx_value_noise2_cached(double x, double y, uint32_t seed, fx_noise_cache *cache);

#ifdef __cplusplus
}
#endif
#endif
