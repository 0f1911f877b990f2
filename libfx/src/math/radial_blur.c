/* Radial blur towards a light: naive (GPU Gems 3 ch. 13) and polar (epipolar lines with
 * a bank of exponential recursions). The model and the two methods: radial_blur.h. */
#include "math/radial_blur.h"

#include "core/parallel.h"
#include "math/hash.h"
#include "core/simd4.h"
#include "core/buffers.h"
#include "core/mem.h"

#include <float.h>
#include <limits.h>
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

static double fx_radial_blur_mass(double decay)
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
            const float *q = occ + ((size_t)yi * w + xi) * 4;
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
            float *o = j->rays + ((size_t)y * j->w + x) * 4;
            double k = rb->scale * inv_n;
            o[0] = to_float(acc[0] * k);
            o[1] = to_float(acc[1] * k);
            o[2] = to_float(acc[2] * k);
            o[3] = 0.0f;
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
 * bins and the decay rate a / (d * rho) per bin. Bins, running sums and results are
 * four-lane floats (RGB + a zero lane): one vector operation per bin and level. */

typedef struct polar_line {
    int b0;        /* radius of bin 0, in bins */
    int count;     /* bins b0 .. b0 + count - 1; 0: the line misses the image */
    int out0;      /* results for bins out0 .. b0 + count - 1 (the line's bands, below) */
    int out_count;
    size_t offset; /* into the results (4 floats per bin) */
} polar_line;

/* Bands: the pixels at radius rho in band k (rho >= band_lo[k], band_lo[k] = far / 2^(k+1),
 * the last band reaching the light) interpolate between every 2^k-th line, so the lines'
 * spacing stays between 1/2 and 1 of the spacing at the farthest pixel everywhere, instead
 * of shrinking towards the light. A line a serves the bands k <= trailing zeros of a: it
 * gathers and runs its sums from the light (the paths need them) but evaluates its
 * results only from its innermost band outwards. */
#define POLAR_MAX_BANDS 24

/* A radius's output constants (they depend on rho only: the path starts at bin
 * ceil((1 - d) rho) of the line whatever its b0), pre-broadcast so the per-bin loop
 * multiplies from memory. For level q of the four around the radius's rate, the
 * trapezoid mean is v_q = ci F[m] - cl F[m0 - 1] + cc o[m] + ca o[m0] + cb olo, with
 * olo = o[m0] + f (o[m0 - 1] - o[m0]); the value is the Catmull-Rom mix of v_0..v_3
 * (weights cr) clamped to [v_1, v_2]. */
typedef struct rho_coef {
    v4f ci[4], cl[4], cc[4], ca[4], cb[4];
    v4f cr[4];
    v4f f;        /* fractional bin before the start */
    int start;    /* absolute start bin of the path: ceil((1 - density) rho) */
    int ident;    /* a path of one bin (or a degenerate kernel): the value is occ itself */
    int g[4];     /* level of q (clamped to the tables) */
} rho_coef;

typedef struct polar_job {
    const float *occ;
    int w, h;
    const fx_radial_blur *rb;
    double lx, ly;
    double hr;                  /* radial bin size, px */
    double phi0, dphi, theta_c; /* line a has angle theta_c + phi0 + a * dphi */
    int lines, full_circle;
    polar_line *line;
    int bands;                  /* 1 .. POLAR_MAX_BANDS; lines is a multiple of 2^(bands - 1) */
    double band_lo[POLAR_MAX_BANDS];
    float *res;
    double a;                   /* -100 ln(decay) (0: decay 1) */
    double hstep;               /* ln 2 / levels */
    int max_count;
    v4f *scratch;               /* per worker: max_count (occ) + max_count * n_levels (F) */
    size_t scratch_per_worker;
    fx_rect roi;
    float *rays;
    /* tables filled once per call (no transcendental per bin). Level g has the rate
     * lambda_{k_min + g} = exp((k_min + g) hstep) per bin: e1[g] = exp(-lambda), and
     * last[g] = the largest radius (bins) whose interpolation reads the level. Radii
     * rho_lo .. max_rho (those of the lines' bins, rho >= 1): kap[rho - rho_lo] = the
     * continuous level of the rate a / (d rho), rc[rho - rho_lo] its output constants. */
    int k_min, n_levels, rho_lo, max_rho;
    double *e1, *last, *kap;
    rho_coef *rc;
} polar_job;

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

/* Bilinear samples of occ along the line, bins 0..cnt-1 at radius (b0 + m) hr. */
static void gather_line(const polar_job *j, double c, double s, int b0, int cnt, v4f *o)
{
    const int w = j->w, h = j->h;
    const float *occ = j->occ;
    const double x0 = j->lx - 0.5, y0 = j->ly - 0.5;
    for (int m = 0; m < cnt; m++) {
        double r = (b0 + m) * j->hr;
        double fx = x0 + r * c, fy = y0 + r * s;
        if (!(fx >= -1.0 && fx < (double)w && fy >= -1.0 && fy < (double)h)) {
            o[m] = V4(0.0f);
            continue;
        }
        /* fx, fy >= -1: truncation of the shifted value is floor (no libm call) */
        int xi = (int)(fx + 1.0) - 1, yi = (int)(fy + 1.0) - 1;
        if (xi >= 0 && xi + 1 < w && yi >= 0 && yi + 1 < h) {
            /* interior: four taps, no bounds checks */
            v4f tx = V4((float)(fx - xi)), ty = V4((float)(fy - yi));
            const float *p0 = occ + ((size_t)yi * w + xi) * 4, *p1 = p0 + (size_t)w * 4;
            v4f a = ld4(p0), b = ld4(p1);
            a += tx * (ld4(p0 + 4) - a);
            b += tx * (ld4(p1 + 4) - b);
            o[m] = a + ty * (b - a);
        } else {
            double acc[3] = {0.0, 0.0, 0.0};
            sample_add(occ, w, h, fx + 0.5, fy + 0.5, 1.0, acc);
            o[m] = (v4f){(float)acc[0], (float)acc[1], (float)acc[2], 0.0f};
        }
    }
}

static void polar_lines(void *user, int begin, int end, int worker)
{
    polar_job *j = user;
    const fx_radial_blur *rb = j->rb;
    const v4f k_out = V4((float)(rb->scale * fx_radial_blur_mass(rb->decay)));
    const v4f zero = V4(0.0f);
    v4f *o = j->scratch + (size_t)worker * j->scratch_per_worker;
    v4f *F = o + j->max_count; /* F[m * K + k]: the levels of a bin side by side */
    for (int a = begin; a < end; a++) {
        const polar_line *ln = &j->line[a];
        if (ln->count <= 0)
            continue;
        double th = j->theta_c + j->phi0 + a * j->dphi;
        const int cnt = ln->count;
        gather_line(j, cos(th), sin(th), ln->b0, cnt, o);
        const int m_out = ln->out0 - ln->b0;
        float *out = j->res + ln->offset * 4; /* bin m's result at out + 4 (m - m_out) */
        /* levels g_lo .. g_hi cover the rates of every result bin (rho >= 1) with the
         * cubic's neighbours; level k runs only up to the last bin that reads it (decay 1:
         * one level of rate 0, prefix sums over the whole line) */
        int rho_min = ln->out0 < j->rho_lo ? j->rho_lo : ln->out0;
        int rho_max = ln->b0 + cnt - 1 > rho_min ? ln->b0 + cnt - 1 : rho_min;
        int g_lo = (int)floor(j->kap[rho_max - j->rho_lo]) - 1 - j->k_min;
        int g_hi = (int)floor(j->kap[rho_min - j->rho_lo]) + 2 - j->k_min;
        if (g_lo < 0) g_lo = 0;
        if (g_hi > j->n_levels - 1) g_hi = j->n_levels - 1;
        const int K = g_hi - g_lo + 1; /* <= n_levels */
        for (int kk = 0; kk < K; kk++) {
            const v4f e1 = V4((float)j->e1[g_lo + kk]);
            double last = j->last[g_lo + kk] - ln->b0;
            int e_k = last >= cnt - 2 ? cnt - 1 : last < 0 ? 0 : (int)last + 1;
            v4f run = zero;
            v4f *Fk = F + kk;
            for (int m = 0; m <= e_k; m++) {
                run = run * e1 + o[m];
                Fk[(size_t)m * K] = run;
            }
        }
        for (int m = m_out; m < cnt; m++) {
            const int rho = ln->b0 + m;
            const v4f om = o[m];
            const rho_coef *rc = rho >= j->rho_lo ? &j->rc[rho - j->rho_lo] : NULL;
            if (!rc || rc->ident) { /* at the light, or a path of one bin */
                st4(out + 4 * (m - m_out), finite4(k_out * om));
                continue;
            }
            const int m0 = rc->start - ln->b0;
            const v4f o0 = m0 >= 0 ? o[m0] : zero, o1 = m0 >= 1 ? o[m0 - 1] : zero;
            const v4f olo = o0 + rc->f * (o1 - o0);
            const v4f *Fm = F + (size_t)m * K, *Fl = m0 >= 1 ? F + (size_t)(m0 - 1) * K : NULL;
            v4f v[4];
            for (int q = 0; q < 4; q++) {
                int kk = rc->g[q] - g_lo;
                kk = kk < 0 ? 0 : kk >= K ? K - 1 : kk;
                v4f t = rc->ci[q] * Fm[kk] + rc->cc[q] * om + rc->ca[q] * o0 + rc->cb[q] * olo;
                v[q] = Fl ? t - rc->cl[q] * Fl[kk] : t;
            }
            v4f val = rc->cr[0] * v[0] + rc->cr[1] * v[1] + rc->cr[2] * v[2] + rc->cr[3] * v[3];
            val = min4(max4(val, min4(v[1], v[2])), max4(v[1], v[2]));
            st4(out + 4 * (m - m_out), finite4(k_out * val));
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

/* A line as the back projection reads it: its bins (4 floats each) from radius b0 on,
 * `last` + 1 >= 1 intervals; lines that miss the image read a zero line. */
typedef struct back_line {
    const float *bins;
    double b0, last; /* double: a far light has b0 ~ 1e6 bins */
} back_line;

typedef struct back_job {
    const polar_job *pj;
    const back_line *bl; /* lines + 2^(bands-1) + 1 entries: past the last line the circle
                            wraps (full circle) or zero lines */
} back_job;

/* The line's value at radius rho (bins), linear between bins. b >= 0 here, so
 * truncation is floor (no libm call, no SSE4.1 needed). */
static inline v4f line_at(const back_line *l, double rho)
{
    double b = rho - l->b0;
    b = b > 0.0 ? b : 0.0;
    b = b < l->last + 1.0 ? b : l->last + 1.0;
    int i = (int)b;
    i = i < (int)l->last ? i : (int)l->last;
    const float *q = l->bins + 4 * i;
    v4f a = ld4(q);
    return a + V4((float)(b - i)) * (ld4(q + 4) - a);
}

static void polar_back(void *user, int begin, int end)
{
    const back_job *bj = user;
    const polar_job *j = bj->pj;
    const back_line *bl = bj->bl;
    const double inv_hr = 1.0 / j->hr, inv_dphi = 1.0 / j->dphi;
    const double amax = j->lines - 1;
    const int top = j->bands - 1;
    double inv_step[POLAR_MAX_BANDS];
    for (int k = 0; k < j->bands; k++)
        inv_step[k] = 1.0 / (double)(1 << k);
    for (int yy = begin; yy < end; yy++) {
        int y = j->roi.y0 + yy;
        double vy = y + 0.5 - j->ly;
        float *o = j->rays + ((size_t)y * j->w + j->roi.x0) * 4;
        for (int x = j->roi.x0; x < j->roi.x1; x++, o += 4) {
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
            /* the pixel's band: between every 2^k-th line */
            int k = 0;
            while (k < top && rho < j->band_lo[k])
                k++;
            int a0 = ((int)af >> k) << k;
            v4f v0 = line_at(&bl[a0], rho), v1 = line_at(&bl[a0 + (1 << k)], rho);
            /* a convex combination of finite floats: finite after the clamp */
            st4(o, finite4(v0 + V4((float)((af - a0) * inv_step[k])) * (v1 - v0)));
        }
    }
}

/* Polar stage 1, geometry: the lines through the light (angles, spacing, count) so that
 * neighbouring lines are at most one radial bin apart at the farthest pixel. Returns the
 * distance to the farthest corner; *inside: the light is on the frame (a full circle). */
static double polar_geometry(polar_job *j, int *inside_out)
{
    const fx_radial_blur *rb = j->rb;
    j->lx = rb->light_x;
    j->ly = rb->light_y;
    const double W = j->w + 0.5, H = j->h + 0.5, X0 = -0.5, Y0 = -0.5;
    const double cx[4] = {X0, W, W, X0}, cy[4] = {Y0, Y0, H, H};
    double r_far = 0.0;
    for (int i = 0; i < 4; i++)
        r_far = fmax(r_far, hypot(cx[i] - j->lx, cy[i] - j->ly));
    j->hr = rb->angular > 0.0 ? rb->angular : 1.0;
    double dphi_target = j->hr / fmax(r_far, 1.0);
    int inside = j->lx >= X0 - 1.0 && j->lx <= W + 1.0 && j->ly >= Y0 - 1.0 && j->ly <= H + 1.0;
    if (inside) {
        j->full_circle = 1;
        j->theta_c = 0.0;
        double n = ceil(2 * M_PI / dphi_target);
        j->lines = n < 8 ? 8 : n > 4e6 ? 4000000 : (int)n;
        j->dphi = 2 * M_PI / j->lines;
        j->phi0 = -M_PI;
    } else {
        j->theta_c = atan2(0.5 * j->h - j->ly, 0.5 * j->w - j->lx);
        double lo = M_PI, hi = -M_PI;
        for (int i = 0; i < 4; i++) {
            double t = atan2(cy[i] - j->ly, cx[i] - j->lx) - j->theta_c;
            while (t > M_PI) t -= 2 * M_PI;
            while (t <= -M_PI) t += 2 * M_PI;
            lo = fmin(lo, t);
            hi = fmax(hi, t);
        }
        j->dphi = dphi_target;
        double n = ceil((hi - lo) / j->dphi) + 5.0;
        if (n > 4e6) {
            n = 4e6;
            j->dphi = (hi - lo) / (n - 5.0);
        }
        j->lines = (int)n;
        j->phi0 = lo - 2.0 * j->dphi;
    }
    *inside_out = inside;
    return r_far;
}

/* Polar stage 2, bands: how many, the line count rounded to their coarsest step, and
 * each line's bins (from its innermost band out). *total: bins over all lines. */
static fx_result polar_bands(fx_context *ctx, polar_job *j, double r_far, int inside, const char *where,
                             size_t *total_out, int *max_count_out)
{
    const double W = j->w + 0.5, H = j->h + 0.5, X0 = -0.5, Y0 = -0.5;
    /* bands (see polar_line): as many as leave >= 16 lines (full circle; 4 in a sector) in
     * the innermost one and reach the nearest pixel; the line count rounded up to a
     * multiple of the coarsest step */
    double r_near = 0.0;
    if (!inside) {
        double ex = j->lx < X0 ? X0 - j->lx : j->lx > W ? j->lx - W : 0.0;
        double ey = j->ly < Y0 ? Y0 - j->ly : j->ly > H ? j->ly - H : 0.0;
        r_near = hypot(ex, ey);
    }
    int top = 0;
    while (top + 1 < POLAR_MAX_BANDS && (j->lines >> (top + 1)) >= (j->full_circle ? 16 : 4) &&
           r_far / (double)(1 << (top + 1)) > r_near)
        top++;
    j->bands = top + 1;
    const int step_max = 1 << top;
    if (j->full_circle) {
        j->lines = (j->lines + step_max - 1) / step_max * step_max;
        j->dphi = 2 * M_PI / j->lines;
    } else {
        j->lines = (j->lines - 1 + step_max - 1) / step_max * step_max + 1;
    }
    for (int k = 0; k < j->bands; k++)
        j->band_lo[k] = k == top ? 0.0 : r_far / j->hr / (double)(2 << k);
    j->line = fx_mem_calloc((size_t)j->lines, sizeof *j->line);
    if (!j->line)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for %d polar lines", where, j->lines);
    size_t total = 0;
    int max_count = 1;
    for (int a = 0; a < j->lines; a++) {
        double th = j->theta_c + j->phi0 + a * j->dphi;
        double r_in, r_out;
        polar_line *ln = &j->line[a];
        ln->offset = total;
        if (!clip_ray(j->lx, j->ly, cos(th), sin(th), j->w, j->h, &r_in, &r_out))
            continue;
        double b0 = floor(r_in / j->hr);
        ln->b0 = (int)b0;
        ln->count = (int)(floor(r_out / j->hr) - b0) + 2; /* one bin past the end for interpolation */
        /* results from the line's innermost band on (one bin below it for interpolation) */
        int band = a == 0 ? top : __builtin_ctz((unsigned)a);
        band = band < top ? band : top;
        double lo = floor(j->band_lo[band]) - 1.0;
        ln->out0 = lo > ln->b0 ? (int)lo : ln->b0;
        if (ln->out0 > ln->b0 + ln->count - 2)
            ln->out0 = ln->b0 + ln->count - 2;
        ln->out_count = ln->b0 + ln->count - ln->out0;
        total += (size_t)ln->out_count;
        if (ln->count > max_count)
            max_count = ln->count;
    }
    *total_out = total;
    *max_count_out = max_count;
    return FX_OK;
}

/* One radius's output constants (rho_coef). */
static void polar_rho_coef(const polar_job *j, int use_levels, int i)
{
    const fx_radial_blur *rb = j->rb;
    const int rho_lo = j->rho_lo;
    const int rho = rho_lo + i;
    rho_coef *rc = &j->rc[i];
    double b_lo = (1.0 - rb->density) * rho, sf = ceil(b_lo);
    double f = sf - b_lo;
    int n = rho - (int)sf + 1; /* whole bins of the path, 1 .. rho + 1 */
    rc->start = (int)sf;
    rc->f = V4((float)f);
    rc->ident = n <= 1 && f < 1e-9;
    double kappa = j->kap[i];
    int kb = (int)floor(kappa);
    double t = kappa - kb;
    rc->cr[0] = V4((float)(0.5 * t * (-1.0 + t * (2.0 - t))));
    rc->cr[1] = V4((float)(1.0 + t * t * (-2.5 + 1.5 * t)));
    rc->cr[2] = V4((float)(0.5 * t * (1.0 + t * (4.0 - 3.0 * t))));
    rc->cr[3] = V4((float)(0.5 * t * t * (t - 1.0)));
    for (int q = 0; q < 4 && !rc->ident; q++) {
        int g = kb - 1 + q - j->k_min;
        g = g < 0 ? 0 : g > j->n_levels - 1 ? j->n_levels - 1 : g;
        rc->g[q] = g;
        /* the path [start - f, rho] under the kernel exp(-lambda (rho - x)), trapezoid
         * rule over whole bins and the fractional end (kernel linear across it) */
        double lam = use_levels ? exp((j->k_min + g) * j->hstep) : 0.0;
        double em1 = expm1(-lam);
        double e1n = exp(-lam * (n - 1)), en = exp(-lam * n);
        double ef = e1n * (1.0 + f * em1);
        double t1 = em1 == 0.0 ? (double)n : expm1(-lam * n) / em1; /* sum_{i<n} e^-lam i */
        double den = t1 - 0.5 - 0.5 * e1n + 0.5 * f * (e1n + ef);
        if (!(den > 1e-300)) {
            rc->ident = 1;
            break;
        }
        double inv = 1.0 / den;
        rc->ci[q] = V4((float)inv);
        rc->cl[q] = V4((float)(inv * en));
        rc->cc[q] = V4((float)(-0.5 * inv));
        rc->ca[q] = V4((float)(inv * 0.5 * (f - 1.0) * e1n));
        rc->cb[q] = V4((float)(inv * 0.5 * f * ef));
    }
}

/* Polar stage 3, tables: the decay's rate levels, the radii the lines reach, the
 * buffers (within the context's budget) and the per-level and per-radius constants. */
static fx_result polar_tables(fx_context *ctx, polar_job *j, size_t total, int max_count, const char *where,
                              size_t *res_bytes_out)
{
    const fx_radial_blur *rb = j->rb;
    j->a = rb->decay >= 1.0 ? 0.0 : rb->decay <= 0.0 ? 0.0 : -(double)FX_RAYS_REFERENCE_SAMPLES * log(rb->decay);
    int levels = rb->levels < 1 ? 1 : rb->levels;
    j->hstep = log(2.0) / levels;
    /* the radii of the lines' bins: rho_lo .. max_rho (rho >= 1; the light's own bin is
     * the identity). A far light has them all far out: the tables span only these. */
    int rho_lo = INT_MAX, max_rho = 1;
    for (int a = 0; a < j->lines; a++)
        if (j->line[a].count > 0) {
            int lo = j->line[a].out0 < 1 ? 1 : j->line[a].out0, hi = j->line[a].b0 + j->line[a].count - 1;
            rho_lo = lo < rho_lo ? lo : rho_lo;
            max_rho = hi > max_rho ? hi : max_rho;
        }
    if (rho_lo > max_rho)
        rho_lo = max_rho;
    j->rho_lo = rho_lo;
    j->max_rho = max_rho;
    const int n_rho = max_rho - rho_lo + 1;
    int use_levels = j->a > 0.0 && rb->density > 0.0 && rb->decay > 0.0;
    if (use_levels) {
        j->k_min = (int)floor(level_of(j, (double)max_rho)) - 2;
        j->n_levels = (int)floor(level_of(j, (double)rho_lo)) + 3 - j->k_min + 1;
    } else {
        j->k_min = 0;
        j->n_levels = 1;
    }
    /* a line reads at most every level (its bins' rates with the cubic's neighbours) */
    j->max_count = max_count;
    j->scratch_per_worker = (size_t)max_count * (1 + (size_t)j->n_levels);
    int workers = fx_parallel_workers(ctx);
    uint64_t table_doubles = 2 * (uint64_t)j->n_levels + (uint64_t)n_rho;
    uint64_t bytes = (uint64_t)total * 4 * sizeof(float) + (uint64_t)n_rho * sizeof(rho_coef) +
                     (uint64_t)workers * j->scratch_per_worker * sizeof(v4f) + table_doubles * sizeof(double);
    fx_result r = fx_check_budget(ctx, bytes, where);
    if (r != FX_OK) {
        fx_mem_free(j->line);
        return r;
    }
    const size_t res_bytes = (total ? total : 1) * 4 * sizeof(float);
    j->res = fx_buffer_get(ctx, res_bytes); /* the same size frame after frame: reused */
    j->scratch = fx_mem_alloc((size_t)workers * j->scratch_per_worker * sizeof(v4f));
    double *tables = fx_mem_alloc((size_t)table_doubles * sizeof(double));
    j->rc = fx_mem_calloc((size_t)n_rho, sizeof *j->rc);
    if (!j->res || !j->scratch || !tables || !j->rc) {
        fx_mem_free(j->rc);
        fx_buffer_put(ctx, j->res, res_bytes);
        fx_mem_free(j->scratch);
        fx_mem_free(tables);
        fx_mem_free(j->line);
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the polar grid (%zu bins)", where, total);
    }
    j->e1 = tables;
    j->last = j->e1 + j->n_levels;
    j->kap = j->last + j->n_levels;
    for (int g = 0; g < j->n_levels; g++) {
        double lam = use_levels ? exp((j->k_min + g) * j->hstep) : 0.0;
        j->e1[g] = exp(-lam);
        /* level g is read by radii whose level is >= g - 2: rho <= a / (d lambda_{g-2}) */
        j->last[g] = use_levels ? j->a / (rb->density * exp((j->k_min + g - 2) * j->hstep)) : 1e300;
    }
    for (int i = 0; i < n_rho; i++)
        j->kap[i] = use_levels ? level_of(j, (double)(rho_lo + i)) : 0.0;
    /* decay 1 (no levels): kap = 0 gives the Catmull-Rom weights (0, 1, 0, 0) on the one
     * level of rate 0, i.e. prefix sums */
    for (int i = 0; i < n_rho; i++)
        polar_rho_coef(j, use_levels, i);
    *res_bytes_out = res_bytes;
    return FX_OK;
}

/* Polar stage 4, sweep: each line's sums from the light outwards, then every ROI pixel
 * interpolated between the lines around it. */
static fx_result polar_sweep(fx_context *ctx, polar_job *j, const char *where)
{
    fx_parallel_for_worker(ctx, j->lines, 16, polar_lines, j);
    const int n_bl = j->lines + (1 << (j->bands - 1)) + 1;
    back_line *bl = fx_mem_alloc((size_t)n_bl * sizeof *bl);
    if (!bl)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for %d polar lines", where, j->lines);
    static const float zero_line[8] = {0};
    for (int a = 0; a < n_bl; a++) {
        /* past the last line: the circle wraps (lines is a multiple of every step) */
        const polar_line *ln = a < j->lines ? &j->line[a] : j->full_circle ? &j->line[a - j->lines] : NULL;
        if (ln && ln->count >= 2) {
            bl[a].bins = j->res + ln->offset * 4;
            bl[a].b0 = ln->out0;
            bl[a].last = ln->out_count - 2;
        } else {
            bl[a].bins = zero_line;
            bl[a].b0 = 0.0;
            bl[a].last = 0.0;
        }
    }
    back_job bj = {j, bl};
    int rows = j->roi.y1 - j->roi.y0;
    fx_parallel_for(ctx, rows, fx_grain_for(ctx, rows), polar_back, &bj);
    fx_mem_free(bl);
    return FX_OK;
}

static void polar_free(fx_context *ctx, polar_job *j, size_t res_bytes)
{
    fx_buffer_put(ctx, j->res, res_bytes);
    fx_mem_free(j->scratch);
    fx_mem_free(j->e1); /* the tables' block */
    fx_mem_free(j->rc);
    fx_mem_free(j->line);
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
    int inside = 0, max_count = 1;
    size_t total = 0, res_bytes = 0;
    double r_far = polar_geometry(&j, &inside);
    fx_result r = polar_bands(ctx, &j, r_far, inside, where, &total, &max_count);
    if (r)
        return r;
    if ((r = polar_tables(ctx, &j, total, max_count, where, &res_bytes)))
        return r;
    if (rb->decay <= 0.0 || rb->density <= 0.0) {
        /* decay 0: the kernel has no mass (the limit of the naive sum). density 0: every
         * sample is the pixel itself. Both are plain per-pixel products. */
        double k = rb->decay <= 0.0 ? 0.0 : rb->scale * fx_radial_blur_mass(rb->decay);
        for (int y = j.roi.y0; y < j.roi.y1; y++)
            for (int x = j.roi.x0; x < j.roi.x1; x++)
                for (int ch = 0; ch < 4; ch++) {
                    size_t i = ((size_t)y * width + x) * 4 + ch;
                    rays[i] = ch < 3 ? to_float(k * occ[i]) : 0.0f;
                }
    } else {
        r = polar_sweep(ctx, &j, where);
    }
    polar_free(ctx, &j, res_bytes);
    return r;
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
                const float *q = j->occ + ((size_t)y * j->w + x0) * 4;
                for (int x = x0; x < x1; x++, q += 4) {
                    acc[0] += q[0];
                    acc[1] += q[1];
                    acc[2] += q[2];
                }
            }
            fx_radial_store_cell(j->lo + ((size_t)Y * j->lw + X) * 4, acc, (double)(y1 - y0) * (x1 - x0));
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
    for (int yy = begin; yy < end; yy++) {
        int y = j->roi.y0 + yy;
        for (int x = j->roi.x0; x < j->roi.x1; x++)
            fx_radial_blur_upsample(j->lo, j->lw, j->lh, j->f, x, y, j->rays + ((size_t)y * j->w + x) * 4);
    }
}

int fx_radial_blur_reduced_size(const fx_radial_blur *rb, int width, int height, int *lw, int *lh)
{
    int f = rb->downsample;
    if (f <= 1 || width < 4 * f || height < 4 * f || rb->decay <= 0.0 || rb->density <= 0.0)
        return 0;
    *lw = (width + f - 1) / f;
    *lh = (height + f - 1) / f;
    return 1;
}

fx_result fx_radial_blur_polar_reduced(fx_context *ctx, const float *lo, float *lrays, int width, int height,
                                       const fx_radial_blur *rb, const fx_rect *roi, const char *where)
{
    int f = rb->downsample, lw = 0, lh = 0;
    fx_rect r = whole_or(roi, width, height);
    if (r.x1 <= r.x0 || r.y1 <= r.y0 || !fx_radial_blur_reduced_size(rb, width, height, &lw, &lh))
        return FX_OK;
    fx_radial_blur lrb = *rb;
    lrb.light_x = rb->light_x / f;
    lrb.light_y = rb->light_y / f;
    lrb.downsample = 1;
    /* the reduced pixels the bilinear interpolation reads */
    fx_rect lr = {r.x0 / f - 1, r.y0 / f - 1, (r.x1 + f - 1) / f + 1, (r.y1 + f - 1) / f + 1};
    return polar_full(ctx, lo, lrays, lw, lh, &lrb, &lr, where);
}

fx_result fx_radial_blur_polar(fx_context *ctx, const float *occ, float *rays, int width, int height,
                               const fx_radial_blur *rb, const fx_rect *roi, const char *where)
{
    int f = rb->downsample, lw = 0, lh = 0;
    fx_rect r = whole_or(roi, width, height);
    if (r.x1 <= r.x0 || r.y1 <= r.y0)
        return FX_OK;
    if (!fx_radial_blur_reduced_size(rb, width, height, &lw, &lh))
        return polar_full(ctx, occ, rays, width, height, rb, roi, where);
    size_t n = (size_t)lw * lh * 4;
    fx_result res = fx_check_budget(ctx, (uint64_t)n * 2 * sizeof(float), where);
    if (res != FX_OK)
        return res;
    float *lo = fx_buffer_get(ctx, n * sizeof(float));
    float *lrays = fx_buffer_get(ctx, n * sizeof(float));
    if (lrays)
        memset(lrays, 0, n * sizeof(float));
    if (!lo || !lrays) {
        fx_buffer_put(ctx, lo, n * sizeof(float));
        fx_buffer_put(ctx, lrays, n * sizeof(float));
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the reduced occlusion map", where);
    }
    down_job dj = {occ, lo, width, height, lw, f};
    fx_parallel_for(ctx, lh, fx_grain_for(ctx, lh), down_rows, &dj);
    res = fx_radial_blur_polar_reduced(ctx, lo, lrays, width, height, rb, roi, where);
    if (res == FX_OK) {
        up_job uj = {lrays, rays, width, lw, lh, f, r};
        int rows = r.y1 - r.y0;
        fx_parallel_for(ctx, rows, fx_grain_for(ctx, rows), up_rows, &uj);
    }
    fx_buffer_put(ctx, lo, n * sizeof(float));
    fx_buffer_put(ctx, lrays, n * sizeof(float));
    return res;
}
