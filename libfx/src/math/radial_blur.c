/* Radial blur towards a light: naive (GPU Gems 3 ch. 13) and polar (epipolar lines with
 * a bank of exponential recursions). The model and the two methods: radial_blur.h. */
#include "math/radial_blur.h"

#include "core/parallel.h"
#include "math/hash.h"

#include <float.h>
#include <math.h>
#include <stdatomic.h>
#include <string.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

void fx_radial_blur_bound_light(double *lx, double *ly, int width, int height)
{
    double cx = 0.5 * width, cy = 0.5 * height;
    if (!isfinite(*lx) || !isfinite(*ly)) {
        *lx = cx;
        *ly = cy;
        return;
    }
    double dx = *lx - cx, dy = *ly - cy;
    double d = hypot(dx, dy);
    if (d > FX_RAYS_MAX_LIGHT_DISTANCE) {
        double s = FX_RAYS_MAX_LIGHT_DISTANCE / d;
        *lx = cx + dx * s;
        *ly = cy + dy * s;
    }
}

double fx_radial_blur_mass(double decay)
{
    if (!(decay > 0.0))
        return 0.0;
    if (decay >= 1.0)
        return 1.0;
    double a = -(double)FX_RAYS_REFERENCE_SAMPLES * log(decay); /* > 0 */
    return -expm1(-a) / a;
}

/* acc += wt * bilinear(occ, x, y), zero outside the image. (x, y) continuous frame pixels. */
static inline void sample_add(const float *occ, int w, int h, double x, double y, double wt, double acc[3])
{
    double fx = x - 0.5, fy = y - 0.5;
    double x0f = floor(fx), y0f = floor(fy);
    if (!(x0f >= -1.0 && x0f < (double)w && y0f >= -1.0 && y0f < (double)h))
        return;
    int x0 = (int)x0f, y0 = (int)y0f;
    double tx = fx - x0f, ty = fy - y0f;
    for (int dy = 0; dy < 2; dy++) {
        int yi = y0 + dy;
        if (yi < 0 || yi >= h)
            continue;
        double wy = (dy ? ty : 1.0 - ty) * wt;
        for (int dx = 0; dx < 2; dx++) {
            int xi = x0 + dx;
            if (xi < 0 || xi >= w)
                continue;
            double ww = (dx ? tx : 1.0 - tx) * wy;
            const float *q = occ + ((size_t)yi * w + xi) * 3;
            acc[0] += ww * q[0];
            acc[1] += ww * q[1];
            acc[2] += ww * q[2];
        }
    }
}

static inline float to_float(double v)
{
    if (!(v == v))
        return 0.0f;
    return v > FLT_MAX ? FLT_MAX : v < -FLT_MAX ? -FLT_MAX : (float)v;
}

/* Range of s where p - s * d lies in [lo, hi] on one axis, intersected into [*s0, *s1]. */
static void clip_axis(double p, double d, double lo, double hi, double *s0, double *s1)
{
    if (fabs(d) < 1e-300) {
        if (p < lo || p > hi) {
            *s0 = 1.0;
            *s1 = 0.0;
        }
        return;
    }
    double a = (p - hi) / d, b = (p - lo) / d;
    if (a > b) {
        double t = a;
        a = b;
        b = t;
    }
    if (a > *s0)
        *s0 = a;
    if (b < *s1)
        *s1 = b;
}

/* ---- naive ---- */

typedef struct naive_job {
    const float *occ;
    float *rays;
    int w, h;
    const fx_radial_blur *rb;
    fx_rect roi;
    double step_decay; /* decay^(100 / N) */
} naive_job;

static void naive_rows(void *user, int begin, int end)
{
    const naive_job *j = user;
    const fx_radial_blur *rb = j->rb;
    const int n = rb->samples;
    const double inv_n = 1.0 / n;
    for (int yy = begin; yy < end; yy++) {
        int y = j->roi.y0 + yy;
        for (int x = j->roi.x0; x < j->roi.x1; x++) {
            double px = x + 0.5, py = y + 0.5;
            double dx = (px - rb->light_x) * rb->density * inv_n;
            double dy = (py - rb->light_y) * rb->density * inv_n;
            double jit = rb->jitter ? fx_rand4(x, y, rb->frame, (int32_t)rb->seed) : 0.0;
            /* samples i with s = i + jit inside the slab where bilinear taps can be non-zero */
            double s0 = 0.0, s1 = (double)n;
            clip_axis(px, dx, -0.5, j->w + 0.5, &s0, &s1);
            clip_axis(py, dy, -0.5, j->h + 0.5, &s0, &s1);
            double acc[3] = {0, 0, 0};
            if (s1 >= s0) {
                double i0f = ceil(s0 - jit) - 1.0, i1f = floor(s1 - jit) + 1.0;
                int i0 = i0f < 0 ? 0 : (int)i0f;
                int i1 = i1f > n - 1 ? n - 1 : (int)i1f;
                double wt = i0 == 0 ? 1.0 : pow(j->step_decay, (double)i0);
                for (int i = i0; i <= i1; i++) {
                    double s = i + jit;
                    sample_add(j->occ, j->w, j->h, px - s * dx, py - s * dy, wt, acc);
                    wt *= j->step_decay;
                }
            }
            float *o = j->rays + ((size_t)y * j->w + x) * 3;
            double k = rb->scale * inv_n;
            o[0] = to_float(acc[0] * k);
            o[1] = to_float(acc[1] * k);
            o[2] = to_float(acc[2] * k);
        }
    }
}

static fx_rect whole_or(const fx_rect *roi, int w, int h)
{
    fx_rect r = {0, 0, w, h};
    if (roi) {
        r = *roi;
        if (r.x0 < 0) r.x0 = 0;
        if (r.y0 < 0) r.y0 = 0;
        if (r.x1 > w) r.x1 = w;
        if (r.y1 > h) r.y1 = h;
    }
    return r;
}

fx_result fx_radial_blur_naive(fx_context *ctx, const float *occ, float *rays, int width, int height,
                               const fx_radial_blur *rb, const fx_rect *roi, const char *where)
{
    (void)where;
    naive_job j = {occ, rays, width, height, rb, whole_or(roi, width, height), 0.0};
    if (j.roi.x1 <= j.roi.x0 || j.roi.y1 <= j.roi.y0)
        return FX_OK;
    j.step_decay = rb->decay >= 1.0 ? 1.0 : rb->decay <= 0.0 ? 0.0
                 : pow(rb->decay, (double)FX_RAYS_REFERENCE_SAMPLES / rb->samples);
    int rows = j.roi.y1 - j.roi.y0;
    fx_parallel_for(ctx, rows, fx_grain_for(ctx, rows), naive_rows, &j);
    return FX_OK;
}

/* ---- polar (epipolar lines through the light) ----
 * Everything along a line is in bin units: bin m of a line lies at radius (b0 + m) * hr
 * from the light (hr = 1 / resolution px); a pixel at rho bins has a path of d * rho
 * bins and the decay rate a / (d * rho) per bin. */

typedef struct polar_line {
    int b0;        /* radius of bin 0, in bins */
    int count;     /* bins b0 .. b0 + count - 1; 0: the line misses the image */
    size_t offset; /* into the results (3 floats per bin) */
} polar_line;

typedef struct polar_job {
    const float *occ;
    int w, h;
    const fx_radial_blur *rb;
    double lx, ly;
    double hr;                  /* radial bin size, px */
    double phi0, dphi, theta_c; /* line a has angle theta_c + phi0 + a * dphi */
    int lines, full_circle;
    polar_line *line;
    float *res;
    double a;                   /* -100 ln(decay) (0: decay 1) */
    double hstep;               /* ln 2 / levels */
    int max_levels, max_count;
    double *scratch;            /* per worker: max_count * 3 (occ) + max_levels * max_count * 3 (F) */
    size_t scratch_per_worker;
    fx_rect roi;
    float *rays;
    /* shared tables, filled once per call (no transcendentals per bin): level g (rate
     * lambda_{k_min + g}) has em1[g] = expm1(-lambda), e1[g] = exp(-lambda) and
     * pw[g * pw_len + j] = exp(-lambda j), pq[g * pw_len + j] = -expm1(-lambda j);
     * kap[rho] = the continuous level of the rate at rho bins (rho >= 1). */
    int k_min, n_levels, pw_len, max_rho;
    double *em1, *e1, *pw, *pq, *kap;
    /* per radius rho (bins) the output stage's constants, which depend on rho only (the
     * path starts at bin ceil((1 - d) rho) of the line whatever its b0): rc[rho] */
    struct rho_coef *rc;
} polar_job;

/* The four levels' trapezoid weights and Catmull-Rom weights of a radius. */
typedef struct rho_coef {
    int start;    /* absolute start bin of the path: ceil((1 - density) rho) */
    int ident;    /* a path of one bin (or a degenerate kernel): the value is occ itself */
    double f;     /* fractional bin before the start */
    int g[4];     /* global level of q (clamped to the tables) */
    double cr[4]; /* Catmull-Rom weights in log(rate) */
    double inv[4], en[4], e1n[4], ef[4];
} rho_coef;

/* [r_in, r_out] of the ray L + r (c, s), r >= 0, inside the slab [-0.5, w + 0.5] x [-0.5, h + 0.5]. */
static int clip_ray(double lx, double ly, double c, double s, int w, int h, double *r_in, double *r_out)
{
    double s0 = 0.0, s1 = 1e300;
    clip_axis(lx, -c, -0.5, w + 0.5, &s0, &s1);
    clip_axis(ly, -s, -0.5, h + 0.5, &s0, &s1);
    if (!(s1 >= s0))
        return 0;
    *r_in = s0;
    *r_out = s1;
    return 1;
}

/* Continuous level index of the rate a / (d rho) per bin: lambda_k = exp(k * hstep). */
static inline double level_of(const polar_job *j, double rho)
{
    return log(j->a / (j->rb->density * rho)) / j->hstep;
}

static inline double oat(const double *o, int m, int ch)
{
    return m >= 0 ? o[3 * m + ch] : 0.0;
}

/* Kernel-weighted mean of occ over the path [m0 - f, m] (bins), kernel exp(-lam (m - x)),
 * trapezoid rule over the whole bins and the fractional end (kernel linear across it).
 * Fk: running sums Fk[i] = sum_{i' <= i} o[i'] exp(-lam (i - i')); pw/pq: the level's
 * tables exp(-lam j) and -expm1(-lam j); em1 = expm1(-lam) (0: lam = 0). */
static inline void path_mean(const double *Fk, const double *o, const double *pw, const double *pq, double em1,
                             int m, int m0, double f, double out[3])
{
    int n = m - m0 + 1;
    if (n <= 1 && f < 1e-9) {
        for (int ch = 0; ch < 3; ch++)
            out[ch] = o[3 * m + ch];
        return;
    }
    double e1n = pw[n - 1];
    double en = pw[n];
    double ef = e1n * (1.0 + f * em1);
    double t1 = em1 == 0.0 ? (double)n : -pq[n] / em1; /* (1 - e^-lam n) / (1 - e^-lam) */
    double den = t1 - 0.5 - 0.5 * e1n + 0.5 * f * (e1n + ef);
    double inv = den > 1e-300 ? 1.0 / den : 0.0;
    for (int ch = 0; ch < 3; ch++) {
        double t = Fk[3 * m + ch] - (m0 >= 1 ? en * Fk[3 * (m0 - 1) + ch] : 0.0);
        double om0 = oat(o, m0, ch);
        double olo = f * oat(o, m0 - 1, ch) + (1.0 - f) * om0;
        double num = t - 0.5 * o[3 * m + ch] - 0.5 * om0 * e1n + 0.5 * f * (om0 * e1n + olo * ef);
        out[ch] = den > 1e-300 ? num * inv : o[3 * m + ch];
    }
}

/* Bilinear samples of occ along the line, bins 0..cnt-1 at radius (b0 + m) hr. */
static void gather_line(const polar_job *j, double c, double s, int b0, int cnt, double *o)
{
    const int w = j->w, h = j->h;
    const float *occ = j->occ;
    for (int m = 0; m < cnt; m++) {
        double r = (b0 + m) * j->hr;
        double fx = j->lx + r * c - 0.5, fy = j->ly + r * s - 0.5;
        double x0f = floor(fx), y0f = floor(fy);
        double *q = o + 3 * m;
        q[0] = q[1] = q[2] = 0.0;
        if (!(x0f >= -1.0 && x0f < (double)w && y0f >= -1.0 && y0f < (double)h))
            continue;
        int x0 = (int)x0f, y0 = (int)y0f;
        double tx = fx - x0f, ty = fy - y0f;
        if (x0 >= 0 && x0 + 1 < w && y0 >= 0 && y0 + 1 < h) {
            /* interior: four taps, no bounds checks */
            const float *p0 = occ + ((size_t)y0 * w + x0) * 3, *p1 = p0 + (size_t)w * 3;
            double w00 = (1.0 - tx) * (1.0 - ty), w01 = tx * (1.0 - ty), w10 = (1.0 - tx) * ty, w11 = tx * ty;
            for (int ch = 0; ch < 3; ch++)
                q[ch] = w00 * p0[ch] + w01 * p0[3 + ch] + w10 * p1[ch] + w11 * p1[3 + ch];
        } else {
            sample_add(occ, w, h, fx + 0.5, fy + 0.5, 1.0, q);
        }
    }
}

static void polar_lines(void *user, int begin, int end, int worker)
{
    polar_job *j = user;
    const fx_radial_blur *rb = j->rb;
    const double d = rb->density;
    const double mass = fx_radial_blur_mass(rb->decay);
    const double k_out = rb->scale * mass;
    double *o = j->scratch + (size_t)worker * j->scratch_per_worker;
    double *F = o + (size_t)j->max_count * 3;
    const size_t fstride = (size_t)j->max_count * 3;
    for (int a = begin; a < end; a++) {
        const polar_line *ln = &j->line[a];
        if (ln->count <= 0)
            continue;
        double th = j->theta_c + j->phi0 + a * j->dphi;
        const int cnt = ln->count;
        gather_line(j, cos(th), sin(th), ln->b0, cnt, o);
        float *out = j->res + ln->offset * 3;
        if (j->a <= 0.0) {
            /* decay 1: one rate, 0: prefix sums */
            double run[3] = {0, 0, 0};
            for (int m = 0; m < cnt; m++)
                for (int ch = 0; ch < 3; ch++) {
                    run[ch] += o[3 * m + ch];
                    F[3 * m + ch] = run[ch];
                }
            for (int m = 0; m < cnt; m++) {
                double rho = ln->b0 + m, v[3];
                double b_lo = m - d * rho, m0f = ceil(b_lo);
                path_mean(F, o, j->pw, j->pq, 0.0, m, (int)m0f, m0f - b_lo, v);
                for (int ch = 0; ch < 3; ch++)
                    out[3 * m + ch] = to_float(rb->scale * v[ch]);
            }
            continue;
        }
        /* levels g_lo .. g_hi cover the rates of every bin (rho >= 1) with the cubic's
         * neighbours; level k runs only up to the last bin that uses it */
        int rho_min = ln->b0 < 1 ? 1 : ln->b0;
        int rho_max = ln->b0 + cnt - 1 > rho_min ? ln->b0 + cnt - 1 : rho_min;
        int g_lo = (int)floor(j->kap[rho_max]) - 1 - j->k_min;
        int g_hi = (int)floor(j->kap[rho_min]) + 2 - j->k_min;
        if (g_lo < 0) g_lo = 0;
        if (g_hi > j->n_levels - 1) g_hi = j->n_levels - 1;
        int K = g_hi - g_lo + 1;
        if (K > j->max_levels)
            K = j->max_levels;
        for (int kk = 0; kk < K; kk++) {
            int g = g_lo + kk;
            double e1 = j->e1[g];
            double last = j->a / (d * exp((j->k_min + g - 2) * j->hstep)) - ln->b0;
            int e_k = last >= cnt - 2 ? cnt - 1 : last < 0 ? 0 : (int)floor(last) + 1;
            double *Fk = F + (size_t)kk * fstride;
            double r0 = 0, r1 = 0, r2 = 0;
            for (int m = 0; m <= e_k; m++) {
                r0 = r0 * e1 + o[3 * m];
                r1 = r1 * e1 + o[3 * m + 1];
                r2 = r2 * e1 + o[3 * m + 2];
                Fk[3 * m] = r0;
                Fk[3 * m + 1] = r1;
                Fk[3 * m + 2] = r2;
            }
        }
        static const double zero3[3] = {0.0, 0.0, 0.0};
        for (int m = 0; m < cnt; m++) {
            int rho = ln->b0 + m;
            const double *om = o + 3 * m;
            const rho_coef *rc = rho >= 1 ? &j->rc[rho] : NULL;
            if (!rc || rc->ident) { /* at the light, or a path of one bin */
                for (int ch = 0; ch < 3; ch++)
                    out[3 * m + ch] = to_float(k_out * om[ch]);
                continue;
            }
            /* the level-independent parts of the trapezoid (path_mean, expanded):
             * num = F[m] - en F[m0-1] - o[m]/2 + e1n A + ef B, with the path's start bins */
            const int m0 = rc->start - ln->b0;
            const double f = rc->f;
            const double *o0 = m0 >= 0 ? o + 3 * m0 : zero3, *o1 = m0 >= 1 ? o + 3 * (m0 - 1) : zero3;
            double A[3], B[3], C[3];
            for (int ch = 0; ch < 3; ch++) {
                double olo = f * o1[ch] + (1.0 - f) * o0[ch];
                A[ch] = 0.5 * (f - 1.0) * o0[ch];
                B[ch] = 0.5 * f * olo;
                C[ch] = -0.5 * om[ch];
            }
            double v[4][3];
            for (int q = 0; q < 4; q++) {
                int kk = rc->g[q] - g_lo;
                kk = kk < 0 ? 0 : kk >= K ? K - 1 : kk;
                const double *Fk = F + (size_t)kk * fstride;
                const double *Fm = Fk + 3 * m, *Fl = m0 >= 1 ? Fk + 3 * (m0 - 1) : zero3;
                const double en = rc->en[q], e1n = rc->e1n[q], ef = rc->ef[q], inv = rc->inv[q];
                for (int ch = 0; ch < 3; ch++)
                    v[q][ch] = (Fm[ch] - en * Fl[ch] + C[ch] + e1n * A[ch] + ef * B[ch]) * inv;
            }
            const double w0 = rc->cr[0], w1 = rc->cr[1], w2 = rc->cr[2], w3 = rc->cr[3];
            for (int ch = 0; ch < 3; ch++) {
                /* Catmull-Rom in log(rate), clamped to the two middle values */
                double p1 = v[1][ch], p2 = v[2][ch];
                double val = w0 * v[0][ch] + w1 * p1 + w2 * p2 + w3 * v[3][ch];
                double lo = p1 < p2 ? p1 : p2, hi = p1 < p2 ? p2 : p1;
                val = val < lo ? lo : val > hi ? hi : val;
                out[3 * m + ch] = to_float(k_out * val);
            }
        }
    }
}

/* atan2 by a minimax polynomial (|error| < 2e-6 rad, continuous): the back projection's
 * angle only picks the two nearest lines (spaced >= 1 / r_far rad), so 2e-6 rad moves a
 * pixel by < 0.005 px at 2000 px. Pure arithmetic: the same on every thread and machine. */
static inline double atan2_fast(double y, double x)
{
    double ax = fabs(x), ay = fabs(y);
    double mx = ax > ay ? ax : ay, mn = ax > ay ? ay : ax;
    if (mx == 0.0)
        return 0.0;
    double q = mn / mx, q2 = q * q;
    double r = q * (0.99997726 + q2 * (-0.33262347 + q2 * (0.19354346 + q2 * (-0.11643287 + q2 * (0.05265332 + q2 * -0.01172120)))));
    if (ay > ax)
        r = 1.5707963267948966 - r;
    if (x < 0.0)
        r = M_PI - r;
    return y < 0.0 ? -r : r;
}

/* A line as the back projection reads it: its bins (3 floats each) from radius b0 on,
 * `last` + 1 >= 1 intervals; lines that miss the image read a zero line. */
typedef struct back_line {
    const float *bins;
    double b0, last; /* double: a far light has b0 ~ 1e6 bins */
} back_line;

typedef struct back_job {
    const polar_job *pj;
    const back_line *bl; /* lines + 1 entries: the last repeats line 0 (full circle) or is zero */
} back_job;

/* b >= 0 here, so truncation is floor (no libm call, no SSE4.1 needed) */
static inline const float *line_at(const back_line *l, double rho, float *t)
{
    double b = rho - l->b0;
    b = b > 0.0 ? b : 0.0;
    b = b < l->last + 1.0 ? b : l->last + 1.0;
    int i = (int)b;
    i = i < (int)l->last ? i : (int)l->last;
    *t = (float)(b - i);
    return l->bins + 3 * i;
}

static void polar_back(void *user, int begin, int end)
{
    const back_job *bj = user;
    const polar_job *j = bj->pj;
    const back_line *bl = bj->bl;
    const double inv_hr = 1.0 / j->hr, inv_dphi = 1.0 / j->dphi;
    const double amax = j->lines - 1;
    for (int yy = begin; yy < end; yy++) {
        int y = j->roi.y0 + yy;
        double vy = y + 0.5 - j->ly;
        float *o = j->rays + ((size_t)y * j->w + j->roi.x0) * 3;
        for (int x = j->roi.x0; x < j->roi.x1; x++, o += 3) {
            double vx = x + 0.5 - j->lx;
            double rho = sqrt(vx * vx + vy * vy) * inv_hr;
            double th = atan2_fast(vy, vx) - j->theta_c;
            if (!j->full_circle) {
                if (th > M_PI) th -= 2 * M_PI;
                else if (th <= -M_PI) th += 2 * M_PI;
            }
            double af = (th - j->phi0) * inv_dphi;
            af = af > 0.0 ? af : 0.0;
            af = af < amax + 1.0 ? af : amax + 1.0;
            int a0 = (int)af;
            a0 = a0 < (int)amax ? a0 : (int)amax;
            float t = (float)(af - a0);
            float t0, t1;
            const float *q0 = line_at(&bl[a0], rho, &t0), *q1 = line_at(&bl[a0 + 1], rho, &t1);
            for (int ch = 0; ch < 3; ch++) {
                /* convex combinations of finite floats: finite after the clamp */
                float v0 = (1.0f - t0) * q0[ch] + t0 * q0[3 + ch];
                float v1 = (1.0f - t1) * q1[ch] + t1 * q1[3 + ch];
                float v = (1.0f - t) * v0 + t * v1;
                o[ch] = fminf(fmaxf(v, -FLT_MAX), FLT_MAX);
            }
        }
    }
}

static fx_result polar_full(fx_context *ctx, const float *occ, float *rays, int width, int height,
                            const fx_radial_blur *rb, const fx_rect *roi, const char *where)
{
    polar_job j;
    memset(&j, 0, sizeof j);
    j.occ = occ;
    j.w = width;
    j.h = height;
    j.rb = rb;
    j.roi = whole_or(roi, width, height);
    j.rays = rays;
    if (j.roi.x1 <= j.roi.x0 || j.roi.y1 <= j.roi.y0)
        return FX_OK;
    j.lx = rb->light_x;
    j.ly = rb->light_y;
    const double W = width + 0.5, H = height + 0.5, X0 = -0.5, Y0 = -0.5;
    const double cx[4] = {X0, W, W, X0}, cy[4] = {Y0, Y0, H, H};
    double r_far = 0.0;
    for (int i = 0; i < 4; i++)
        r_far = fmax(r_far, hypot(cx[i] - j.lx, cy[i] - j.ly));
    j.hr = rb->angular > 0.0 ? rb->angular : 1.0;
    double dphi_target = j.hr / fmax(r_far, 1.0);
    int inside = j.lx >= X0 - 1.0 && j.lx <= W + 1.0 && j.ly >= Y0 - 1.0 && j.ly <= H + 1.0;
    if (inside) {
        j.full_circle = 1;
        j.theta_c = 0.0;
        double n = ceil(2 * M_PI / dphi_target);
        j.lines = n < 8 ? 8 : n > 4e6 ? 4000000 : (int)n;
        j.dphi = 2 * M_PI / j.lines;
        j.phi0 = -M_PI;
    } else {
        j.theta_c = atan2(0.5 * height - j.ly, 0.5 * width - j.lx);
        double lo = M_PI, hi = -M_PI;
        for (int i = 0; i < 4; i++) {
            double t = atan2(cy[i] - j.ly, cx[i] - j.lx) - j.theta_c;
            while (t > M_PI) t -= 2 * M_PI;
            while (t <= -M_PI) t += 2 * M_PI;
            lo = fmin(lo, t);
            hi = fmax(hi, t);
        }
        j.dphi = dphi_target;
        double n = ceil((hi - lo) / j.dphi) + 5.0;
        if (n > 4e6) {
            n = 4e6;
            j.dphi = (hi - lo) / (n - 5.0);
        }
        j.lines = (int)n;
        j.phi0 = lo - 2.0 * j.dphi;
    }
    j.line = fx_mem_calloc((size_t)j.lines, sizeof *j.line);
    if (!j.line)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for %d polar lines", where, j.lines);
    size_t total = 0;
    int max_count = 1;
    for (int a = 0; a < j.lines; a++) {
        double th = j.theta_c + j.phi0 + a * j.dphi;
        double r_in, r_out;
        polar_line *ln = &j.line[a];
        ln->offset = total;
        if (!clip_ray(j.lx, j.ly, cos(th), sin(th), width, height, &r_in, &r_out))
            continue;
        double b0 = floor(r_in / j.hr);
        ln->b0 = (int)b0;
        ln->count = (int)(floor(r_out / j.hr) - b0) + 2; /* one bin past the end for interpolation */
        total += (size_t)ln->count;
        if (ln->count > max_count)
            max_count = ln->count;
    }
    j.a = rb->decay >= 1.0 ? 0.0 : rb->decay <= 0.0 ? 0.0 : -(double)FX_RAYS_REFERENCE_SAMPLES * log(rb->decay);
    int levels = rb->levels < 1 ? 1 : rb->levels;
    j.hstep = log(2.0) / levels;
    /* levels per line: from the rate at the line's far end to the rate at r = 1 */
    int max_levels = 1;
    if (j.a > 0.0 && rb->density > 0.0) {
        double span = log(fmax(r_far / j.hr + 2.0, 2.0)) / j.hstep;
        max_levels = (int)ceil(span) + 6;
    }
    j.max_levels = max_levels;
    j.max_count = max_count;
    j.scratch_per_worker = (size_t)max_count * 3 * (1 + (size_t)max_levels);
    /* level tables: every rate any bin can use (rho in 1 .. max_rho, the cubic's
     * neighbours), powers exp(-lambda j) for path lengths j <= max_rho + 2 */
    int max_rho = 1;
    for (int a = 0; a < j.lines; a++)
        if (j.line[a].count > 0 && j.line[a].b0 + j.line[a].count - 1 > max_rho)
            max_rho = j.line[a].b0 + j.line[a].count - 1;
    j.max_rho = max_rho;
    j.pw_len = max_rho + 3;
    int use_levels = j.a > 0.0 && rb->density > 0.0 && rb->decay > 0.0;
    if (use_levels) {
        j.k_min = (int)floor(level_of(&j, (double)max_rho)) - 2;
        j.n_levels = (int)floor(level_of(&j, 1.0)) + 3 - j.k_min + 1;
    } else {
        j.k_min = 0;
        j.n_levels = 1;
    }
    int workers = fx_parallel_workers(ctx);
    uint64_t table_doubles = (uint64_t)j.n_levels * (2 + 2 * (uint64_t)j.pw_len) + (uint64_t)max_rho + 1;
    uint64_t bytes = (uint64_t)total * 3 * sizeof(float) + ((uint64_t)max_rho + 1) * sizeof(rho_coef) +
                     (uint64_t)workers * j.scratch_per_worker * sizeof(double) + table_doubles * sizeof(double);
    fx_result r = fx_check_budget(ctx, bytes, where);
    if (r != FX_OK) {
        fx_mem_free(j.line);
        return r;
    }
    j.res = fx_mem_alloc((total ? total : 1) * 3 * sizeof(float));
    j.scratch = fx_mem_alloc((size_t)workers * j.scratch_per_worker * sizeof(double));
    double *tables = fx_mem_alloc((size_t)table_doubles * sizeof(double));
    j.rc = fx_mem_calloc((size_t)max_rho + 1, sizeof *j.rc);
    if (!j.res || !j.scratch || !tables || !j.rc) {
        fx_mem_free(j.rc);
        fx_mem_free(j.res);
        fx_mem_free(j.scratch);
        fx_mem_free(tables);
        fx_mem_free(j.line);
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the polar grid (%zu bins)", where, total);
    }
    j.em1 = tables;
    j.e1 = j.em1 + j.n_levels;
    j.pw = j.e1 + j.n_levels;
    j.pq = j.pw + (size_t)j.n_levels * j.pw_len;
    j.kap = j.pq + (size_t)j.n_levels * j.pw_len;
    for (int g = 0; g < j.n_levels; g++) {
        double lam = use_levels ? exp((j.k_min + g) * j.hstep) : 0.0;
        j.em1[g] = expm1(-lam);
        j.e1[g] = exp(-lam);
        double *pw = j.pw + (size_t)g * j.pw_len, *pq = j.pq + (size_t)g * j.pw_len;
        for (int i = 0; i < j.pw_len; i++) {
            double x = lam * i;
            pw[i] = x > 745.0 ? 0.0 : exp(-x);
            pq[i] = -expm1(-x);
        }
    }
    j.kap[0] = 0.0;
    for (int rho = 1; rho <= max_rho; rho++)
        j.kap[rho] = use_levels ? level_of(&j, (double)rho) : 0.0;
    if (use_levels) {
        for (int rho = 1; rho <= max_rho; rho++) {
            rho_coef *rc = &j.rc[rho];
            double b_lo = (1.0 - rb->density) * rho, sf = ceil(b_lo);
            double f = sf - b_lo;
            int n = rho - (int)sf + 1;
            rc->start = (int)sf;
            rc->f = f;
            rc->ident = n <= 1 && f < 1e-9;
            double kappa = j.kap[rho];
            int kb = (int)floor(kappa);
            double t = kappa - kb;
            rc->cr[0] = 0.5 * t * (-1.0 + t * (2.0 - t));
            rc->cr[1] = 1.0 + t * t * (-2.5 + 1.5 * t);
            rc->cr[2] = 0.5 * t * (1.0 + t * (4.0 - 3.0 * t));
            rc->cr[3] = 0.5 * t * t * (t - 1.0);
            for (int q = 0; q < 4 && !rc->ident; q++) {
                int g = kb - 1 + q - j.k_min;
                g = g < 0 ? 0 : g > j.n_levels - 1 ? j.n_levels - 1 : g;
                rc->g[q] = g;
                if (n < 1 || n >= j.pw_len) { /* cannot happen (0 < n <= rho + 1): be safe */
                    rc->ident = 1;
                    break;
                }
                const double *pw = j.pw + (size_t)g * j.pw_len;
                double em1 = j.em1[g];
                double e1n = pw[n - 1], en = pw[n];
                double ef = e1n * (1.0 + f * em1);
                double t1 = em1 == 0.0 ? (double)n : -j.pq[(size_t)g * j.pw_len + n] / em1;
                double den = t1 - 0.5 - 0.5 * e1n + 0.5 * f * (e1n + ef);
                if (!(den > 1e-300)) {
                    rc->ident = 1;
                    break;
                }
                rc->inv[q] = 1.0 / den;
                rc->en[q] = en;
                rc->e1n[q] = e1n;
                rc->ef[q] = ef;
            }
        }
    }
    if (rb->decay <= 0.0 || rb->density <= 0.0) {
        /* decay 0: the kernel has no mass (the limit of the naive sum). density 0: every
         * sample is the pixel itself. Both are plain per-pixel products. */
        double k = rb->decay <= 0.0 ? 0.0 : rb->scale * fx_radial_blur_mass(rb->decay);
        for (int y = j.roi.y0; y < j.roi.y1; y++)
            for (int x = j.roi.x0; x < j.roi.x1; x++)
                for (int ch = 0; ch < 3; ch++) {
                    size_t i = ((size_t)y * width + x) * 3 + ch;
                    rays[i] = to_float(k * occ[i]);
                }
    } else {
        fx_parallel_for_worker(ctx, j.lines, 16, polar_lines, &j);
        back_line *bl = fx_mem_alloc(((size_t)j.lines + 1) * sizeof *bl);
        if (!bl) {
            fx_mem_free(j.res);
            fx_mem_free(j.scratch);
            fx_mem_free(tables);
            fx_mem_free(j.rc);
            fx_mem_free(j.line);
            return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for %d polar lines", where, j.lines);
        }
        static const float zero_line[6] = {0};
        for (int a = 0; a <= j.lines; a++) {
            const polar_line *ln = a < j.lines ? &j.line[a] : j.full_circle ? &j.line[0] : NULL;
            if (ln && ln->count >= 2) {
                bl[a].bins = j.res + ln->offset * 3;
                bl[a].b0 = ln->b0;
                bl[a].last = ln->count - 2;
            } else {
                bl[a].bins = zero_line;
                bl[a].b0 = 0.0;
                bl[a].last = 0.0;
            }
        }
        back_job bj = {&j, bl};
        int rows = j.roi.y1 - j.roi.y0;
        fx_parallel_for(ctx, rows, fx_grain_for(ctx, rows), polar_back, &bj);
        fx_mem_free(bl);
    }
    fx_mem_free(j.res);
    fx_mem_free(j.scratch);
    fx_mem_free(tables);
    fx_mem_free(j.rc);
    fx_mem_free(j.line);
    return FX_OK;
}

/* ---- reduced resolution: the occlusion map box-averaged by f x f, the polar method on
 * that grid (light and lines scaled by 1 / f), the rays interpolated back (bilinear). */

typedef struct down_job {
    const float *occ;
    float *lo;
    int w, h, lw, f;
} down_job;

static void down_rows(void *user, int begin, int end)
{
    const down_job *j = user;
    const int f = j->f;
    for (int Y = begin; Y < end; Y++) {
        int y0 = Y * f, y1 = y0 + f > j->h ? j->h : y0 + f;
        for (int X = 0; X < j->lw; X++) {
            int x0 = X * f, x1 = x0 + f > j->w ? j->w : x0 + f;
            double acc[3] = {0, 0, 0};
            for (int y = y0; y < y1; y++) {
                const float *q = j->occ + ((size_t)y * j->w + x0) * 3;
                for (int x = x0; x < x1; x++, q += 3) {
                    acc[0] += q[0];
                    acc[1] += q[1];
                    acc[2] += q[2];
                }
            }
            double inv = 1.0 / ((double)(y1 - y0) * (x1 - x0));
            float *o = j->lo + ((size_t)Y * j->lw + X) * 3;
            o[0] = (float)(acc[0] * inv);
            o[1] = (float)(acc[1] * inv);
            o[2] = (float)(acc[2] * inv);
        }
    }
}

typedef struct up_job {
    const float *lo;
    float *rays;
    int w, lw, lh, f;
    fx_rect roi;
} up_job;

static void up_rows(void *user, int begin, int end)
{
    const up_job *j = user;
    const double inv_f = 1.0 / j->f;
    for (int yy = begin; yy < end; yy++) {
        int y = j->roi.y0 + yy;
        double v = (y + 0.5) * inv_f - 0.5;
        v = v < 0.0 ? 0.0 : v > j->lh - 1 ? j->lh - 1 : v;
        int Y0 = (int)v, Y1 = Y0 + 1 < j->lh ? Y0 + 1 : Y0;
        float ty = (float)(v - Y0);
        const float *r0 = j->lo + (size_t)Y0 * j->lw * 3, *r1 = j->lo + (size_t)Y1 * j->lw * 3;
        for (int x = j->roi.x0; x < j->roi.x1; x++) {
            double u = (x + 0.5) * inv_f - 0.5;
            u = u < 0.0 ? 0.0 : u > j->lw - 1 ? j->lw - 1 : u;
            int X0 = (int)u, X1 = X0 + 1 < j->lw ? X0 + 1 : X0;
            float tx = (float)(u - X0);
            float *o = j->rays + ((size_t)y * j->w + x) * 3;
            for (int ch = 0; ch < 3; ch++) {
                float a = r0[3 * X0 + ch] + tx * (r0[3 * X1 + ch] - r0[3 * X0 + ch]);
                float b = r1[3 * X0 + ch] + tx * (r1[3 * X1 + ch] - r1[3 * X0 + ch]);
                o[ch] = a + ty * (b - a);
            }
        }
    }
}

fx_result fx_radial_blur_polar(fx_context *ctx, const float *occ, float *rays, int width, int height,
                               const fx_radial_blur *rb, const fx_rect *roi, const char *where)
{
    int f = rb->downsample;
    fx_rect r = whole_or(roi, width, height);
    if (r.x1 <= r.x0 || r.y1 <= r.y0)
        return FX_OK;
    if (f <= 1 || width < 4 * f || height < 4 * f || rb->decay <= 0.0 || rb->density <= 0.0)
        return polar_full(ctx, occ, rays, width, height, rb, roi, where);
    int lw = (width + f - 1) / f, lh = (height + f - 1) / f;
    size_t n = (size_t)lw * lh * 3;
    fx_result res = fx_check_budget(ctx, (uint64_t)n * 2 * sizeof(float), where);
    if (res != FX_OK)
        return res;
    float *lo = fx_mem_alloc(n * sizeof(float));
    float *lrays = fx_mem_calloc(n, sizeof(float));
    if (!lo || !lrays) {
        fx_mem_free(lo);
        fx_mem_free(lrays);
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the reduced occlusion map", where);
    }
    down_job dj = {occ, lo, width, height, lw, f};
    fx_parallel_for(ctx, lh, fx_grain_for(ctx, lh), down_rows, &dj);
    fx_radial_blur lrb = *rb;
    lrb.light_x = rb->light_x / f;
    lrb.light_y = rb->light_y / f;
    lrb.downsample = 1;
    /* the reduced pixels the bilinear interpolation reads */
    fx_rect lr = {r.x0 / f - 1, r.y0 / f - 1, (r.x1 + f - 1) / f + 1, (r.y1 + f - 1) / f + 1};
    res = polar_full(ctx, lo, lrays, lw, lh, &lrb, &lr, where);
    if (res == FX_OK) {
        up_job uj = {lrays, rays, width, lw, lh, f, r};
        int rows = r.y1 - r.y0;
        fx_parallel_for(ctx, rows, fx_grain_for(ctx, rows), up_rows, &uj);
    }
    fx_mem_free(lo);
    fx_mem_free(lrays);
    return res;
}
