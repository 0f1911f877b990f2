/* Periodic jittered-grid Voronoi: brute force and ring search (voronoi.h). */
#include "math/voronoi.h"

#include "math/hash.h"

#include <math.h>

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

void fx_voronoi_point(const fx_voronoi *v, int index, double *x, double *y)
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

static inline double wrap_tile(double a, double G)
{
    double r = a - G * floor(a / G);
    return r >= G ? 0.0 : r;
}

/* (d, k) < (f, i) lexicographically */
static inline int before(double d, int k, double f, int i)
{
    return d < f || (d == f && k < i);
}

static inline void consider(const fx_voronoi *v, double qx, double qy, int k, fx_voronoi_hit *h)
{
    if (k == h->i1 || k == h->i2)
        return;
    double px, py;
    fx_voronoi_point(v, k, &px, &py);
    double G = v->grid;
    double dx = qx - px, dy = qy - py;
    dx -= G * floor(dx / G + 0.5);
    dy -= G * floor(dy / G + 0.5);
    double d = fx_minkowski2(dx, dy, v->p);
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

static void finish(const fx_voronoi *v, fx_voronoi_hit *h)
{
    if (v->grid == 1) {
        h->i2 = h->i1;
        h->f2 = h->f1 + 1.0;
    }
}

void fx_voronoi_brute(const fx_voronoi *v, double x, double y, fx_voronoi_hit *out)
{
    const int G = v->grid;
    double qx = wrap_tile(x, G), qy = wrap_tile(y, G);
    fx_voronoi_hit h = {-1, -1, INFINITY, INFINITY};
    for (int k = 0; k < G * G; k++)
        consider(v, qx, qy, k, &h);
    finish(v, &h);
    *out = h;
}

void fx_voronoi_grid(const fx_voronoi *v, double x, double y, fx_voronoi_hit *out)
{
    const int G = v->grid;
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
                consider(v, qx, qy, gy * G + gx, &h);
                if (ring == 0)
                    break;
            }
        }
    }
    finish(v, &h);
    *out = h;
}

double fx_value_noise2(double x, double y, uint32_t seed)
{
    double fx = floor(x), fy = floor(y);
    double tx = x - fx, ty = y - fy;
    /* lattice coordinates kept in int range */
    double mx = fmod(fx, 1048576.0), my = fmod(fy, 1048576.0);
    int ix = (int)mx, iy = (int)my;
    double a = fx_rand4(ix, iy, (int32_t)seed, 7), b = fx_rand4(ix + 1, iy, (int32_t)seed, 7);
    double c = fx_rand4(ix, iy + 1, (int32_t)seed, 7), d = fx_rand4(ix + 1, iy + 1, (int32_t)seed, 7);
    tx = tx * tx * (3.0 - 2.0 * tx);
    ty = ty * ty * (3.0 - 2.0 * ty);
    return (a + (b - a) * tx) * (1.0 - ty) + (c + (d - c) * tx) * ty;
}
