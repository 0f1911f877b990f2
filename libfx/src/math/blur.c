/* Separable Gaussian blur (see blur.h for the algorithms and their references).
 *
 * Every algorithm is written once, as a "lane kernel": it filters a buffer of n steps
 * x L lanes (element (i, l) at buf[i * L + l]) along i, with the inner loop running over
 * the lanes, in double. The vertical pass feeds it strips of columns straight from the
 * image rows; the horizontal pass gathers R rows into an x-major buffer (pixel by pixel,
 * 16-byte copies: a cheap partial transpose that lives in L2) so the same kernel runs
 * along x with R * channels lanes. Lanes never mix, so SSE2 and AVX2 builds of a kernel
 * give identical bits (ISO C mode: no FMA contraction).
 */
#include "math/blur.h"

#include "core/parallel.h"
#include "core/simd8.h"
#include "core/mem.h"
#include "math/clones.h"

#include <float.h>
#include <math.h>
#include <stdatomic.h>
#include <stdint.h>
#include <string.h>

#ifndef FX_BLUR_FLOAT
#  define FX_BLUR_FLOAT 1 /* 0: recursive always in double (for comparisons) */
#endif

#define FX_BLUR_MAX_SIGMA 1.0e5 /* larger sigmas are clamped: the result is already the limit */
#define V_LANES 32              /* floats per vertical strip (lane kernels) */
#define V_LANES_REC 32          /* floats per vertical strip (recursive, row-wise) */
#define H_LANES 16              /* target floats per horizontal block (rows * channels) */
#define PAD 4                   /* rows before/after the data in a lane buffer (recursion state) */
#define BOX_MIN_RING 32         /* box: ring slots at least (see blur_plan.ring) */

/* ---- kernels' parameters ------------------------------------------------------------- */

int fx_gaussian_radius(double sigma)
{
    if (!(sigma > 0))
        return 1;
    if (sigma > FX_BLUR_MAX_SIGMA)
        sigma = FX_BLUR_MAX_SIGMA;
    int r = (int)ceil(FX_BLUR_EXACT_SIGMAS * sigma);
    return r < 1 ? 1 : r;
}

void fx_gaussian_taps(double sigma, int radius, double *taps)
{
    double inv = 1.0 / (2.0 * sigma * sigma);
    for (int k = 0; k <= radius; k++) {
        double v = exp(-(double)k * (double)k * inv);
        taps[radius + k] = v;
        taps[radius - k] = v;
    }
    double sum = 0; /* small tails first */
    for (int k = radius; k >= 1; k--)
        sum += 2.0 * taps[radius + k];
    sum += taps[radius];
    for (int k = 0; k <= 2 * radius; k++)
        taps[k] /= sum;
}

void fx_extended_box(double var, int *r_out, double *alpha_out)
{
    /* Plain box of radius r has variance r(r+1)/3; take the largest r below var, then the
     * end-tap weight alpha that makes [1 ... 1] + alpha at +-(r+1) have variance var. */
    if (!(var > 0)) {
        *r_out = 0;
        *alpha_out = 0;
        return;
    }
    int r = (int)floor((sqrt(1.0 + 12.0 * var) - 1.0) * 0.5);
    if (r < 0)
        r = 0;
    while ((double)r * (r + 1) / 3.0 > var && r > 0)
        r--;
    while ((double)(r + 1) * (r + 2) / 3.0 <= var)
        r++;
    double rp1 = r + 1.0;
    double alpha = (2.0 * r + 1.0) * (var - r * rp1 / 3.0) / (2.0 * (rp1 * rp1 - var));
    if (alpha < 0)
        alpha = 0;
    if (alpha > 1)
        alpha = 1;
    *r_out = r;
    *alpha_out = alpha;
}

/* Deriche 4th-order coefficients, normalised to unit DC gain:
 * causal      y+[i] = n0 x[i] + n1 x[i-1] + n2 x[i-2] + n3 x[i-3] - sum_k d[k-1] y+[i-k]
 * anticausal  y-[i] = m0 x[i+1] + m1 x[i+2] + m2 x[i+3] + m3 x[i+4] - sum_k d[k-1] y-[i+k]
 * (k = 1..4), output y+ + y-. */
static void fx_deriche_coefficients(double sigma, double n[4], double m[4], double d[4])
{
    /* Deriche (1993), zero order, the optimised constants as tabulated in ITK's
     * RecursiveGaussianImageFilter; normalised to unit DC gain (causal + anticausal). */
    const double a1 = 1.3530, b1 = 1.8151, w1 = 0.6681, l1 = -1.3932;
    const double a2 = -0.3531, b2 = 0.0902, w2 = 2.0787, l2 = -1.3732;
    double s1 = sin(w1 / sigma), s2 = sin(w2 / sigma);
    double c1 = cos(w1 / sigma), c2 = cos(w2 / sigma);
    double e1 = exp(l1 / sigma), e2 = exp(l2 / sigma);
    double n0 = a1 + a2;
    double n1 = e2 * (b2 * s2 - (a2 + 2 * a1) * c2) + e1 * (b1 * s1 - (a1 + 2 * a2) * c1);
    double n2 = 2 * e1 * e2 * ((a1 + a2) * c2 * c1 - b1 * c2 * s1 - b2 * c1 * s2) +
                a2 * e1 * e1 + a1 * e2 * e2;
    double n3 = e2 * e1 * e1 * (b2 * s2 - a2 * c2) + e1 * e2 * e2 * (b1 * s1 - a1 * c1);
    double d4 = e1 * e1 * e2 * e2;
    double d3 = -2 * c1 * e1 * e2 * e2 - 2 * c2 * e2 * e1 * e1;
    double d2 = 4 * c2 * c1 * e1 * e2 + e1 * e1 + e2 * e2;
    double d1 = -2 * (e2 * c2 + e1 * c1);
    double sn = n0 + n1 + n2 + n3, sd = 1.0 + d1 + d2 + d3 + d4;
    double gain = 2.0 * sn / sd - n0; /* causal + anticausal DC gain */
    n0 /= gain, n1 /= gain, n2 /= gain, n3 /= gain;
    n[0] = n0, n[1] = n1, n[2] = n2, n[3] = n3;
    d[0] = d1, d[1] = d2, d[2] = d3, d[3] = d4;
    m[0] = n1 - d1 * n0;
    m[1] = n2 - d2 * n0;
    m[2] = n3 - d3 * n0;
    m[3] = -d4 * n0;
}

/* The same filter as two second-order sections in float (the form the float kernels run):
 * per section k, on d = x - c (c: the line's first sample, so constant lines are exact),
 *   causal      u[i] = (b0 d[i] + b1 d[i-1]) - (p1 u[i-1] + p2 u[i-2])
 *   anticausal  v[i] = (m1 d[i+1] + m2 d[i+2]) - (p1 v[i+1] + p2 v[i+2])
 * output (u0 + u1) + (v0 + v1) + c. ga: the anticausal steady state for a unit constant. */
typedef struct fx_deriche_sec {
    float b0[2], b1[2], m1[2], m2[2], p1[2], p2[2], ga[2];
} fx_deriche_sec;

static void fx_deriche_sections(double sigma, fx_deriche_sec *o)
{
    /* Deriche's impulse response is a sum of two damped cosine/sine terms,
     *   h(n) = e_k^n (a_k cos(w_k n / sigma) + b_k sin(w_k n / sigma)),  e_k = exp(l_k / sigma),
     * each one a second-order section (a_k + c1 z^-1) / (1 + p1 z^-1 + p2 z^-2) with
     * c1 = e (b sin - a cos), p1 = -2 e cos, p2 = e^2. The anticausal half (n >= 1, mirrored)
     * of the same section is (c1 - a p1) z^-1 - a p2 z^-2 over the same denominator.
     * The denominators are rounded to float first and the numerators normalised (in double)
     * for unit DC gain of the filter the float coefficients define. */
    const double A[2] = { 1.3530, -0.3531 }, B[2] = { 1.8151, 0.0902 };
    const double Wf[2] = { 0.6681, 2.0787 }, Lf[2] = { -1.3932, -1.3732 };
    double c0[2], c1[2], m1[2], m2[2], D[2], gain = 0.0;
    for (int k = 0; k < 2; k++) {
        double e = exp(Lf[k] / sigma), th = Wf[k] / sigma;
        float p1 = (float)(-2.0 * e * cos(th)), p2 = (float)(e * e);
        o->p1[k] = p1;
        o->p2[k] = p2;
        c0[k] = A[k];
        c1[k] = e * (B[k] * sin(th) - A[k] * cos(th));
        m1[k] = c1[k] - c0[k] * (double)p1;
        m2[k] = -c0[k] * (double)p2;
        D[k] = (1.0 + (double)p1) + (double)p2;
        gain += ((c0[k] + c1[k]) + (m1[k] + m2[k])) / D[k];
    }
    for (int k = 0; k < 2; k++) {
        o->b0[k] = (float)(c0[k] / gain);
        o->b1[k] = (float)(c1[k] / gain);
        o->m1[k] = (float)(m1[k] / gain);
        o->m2[k] = (float)(m2[k] / gain);
        /* The anticausal section's steady state for a unit constant, from the double
         * numerators: gcc 12 at -O3 (its SLP vectorizer) dropped the rounding of a float
         * round trip here, so a formula over the rounded o->m1/o->m2 gave other bits
         * than gcc 14 did. Pure double arithmetic is the same everywhere. */
        o->ga[k] = (float)((m1[k] / gain + m2[k] / gain) / D[k]);
    }
}

/* ---- plan: everything an algorithm needs for one sigma --------------------------------- */

typedef struct blur_plan {
    fx_blur_algorithm alg; /* effective algorithm */
    int identity;
    /* exact */
    int R;
    double *taps; /* 2R+1 */
    double *pre;  /* pre[m] = sum taps[0..m-1], 2R+2 entries */
    double *suf;  /* suf[m] = sum taps[m..2R], 2R+2 entries */
    /* box */
    int passes, r;
    double alpha, norm, normP; /* normP = norm^passes: the stages run unnormalised */
    int resum; /* recompute the running sums from scratch every `resum` steps */
    int ring;  /* slots of the v4d kernels' rings: >= 2r+2, and not tiny (fewer wraps) */
    int ext;   /* rows of a lane buffer before and after the data (>= PAD) */
    /* recursive (Deriche 4th order: causal n[], anticausal m[], shared d[]) */
    double dn[4], dm[4], dd[4], gain_c, gain_a;
    /* recursive in float (sigma <= FX_BLUR_FLOAT_MAX_SIGMA): the same filter as two
     * second-order sections (fx_deriche_sections) */
    int use_float;
    fx_deriche_sec sec;
    int halo;
} blur_plan;

static void plan_free(blur_plan *p)
{
    fx_mem_free(p->taps);
    fx_mem_free(p->pre);
    fx_mem_free(p->suf);
    p->taps = p->pre = p->suf = NULL;
}

static fx_result plan_init(blur_plan *p, const fx_blur_spec *spec)
{
    memset(p, 0, sizeof *p);
    double sigma = spec->sigma;
    if (!(sigma >= FX_BLUR_MIN_SIGMA)) { /* also NaN */
        p->identity = 1;
        return FX_OK;
    }
    if (sigma > FX_BLUR_MAX_SIGMA)
        sigma = FX_BLUR_MAX_SIGMA;
    p->alg = spec->algorithm;
    p->ext = PAD;
    if (p->alg == FX_BLUR_RECURSIVE && sigma < FX_BLUR_RECURSIVE_MIN_SIGMA)
        p->alg = FX_BLUR_EXACT;
    if (p->alg == FX_BLUR_BOX) {
        int passes = spec->box_passes < 2 ? 2 : spec->box_passes > 6 ? 6 : spec->box_passes;
        p->passes = passes;
        fx_extended_box(sigma * sigma / passes, &p->r, &p->alpha);
        p->norm = 1.0 / (2.0 * p->r + 1.0 + 2.0 * p->alpha);
        p->normP = 1.0;
        for (int k = 0; k < passes; k++)
            p->normP *= p->norm;
        p->resum = 4 * (2 * p->r + 1) < 64 ? 64 : 4 * (2 * p->r + 1);
        p->halo = passes * (p->r + 1);
        p->ring = 2 * p->r + 2 < BOX_MIN_RING ? BOX_MIN_RING : 2 * p->r + 2;
        return FX_OK;
    }
    if (p->alg == FX_BLUR_RECURSIVE) {
        fx_deriche_coefficients(sigma, p->dn, p->dm, p->dd);
        double sd = 1.0 + p->dd[0] + p->dd[1] + p->dd[2] + p->dd[3];
        p->gain_c = (p->dn[0] + p->dn[1] + p->dn[2] + p->dn[3]) / sd;
        p->gain_a = (p->dm[0] + p->dm[1] + p->dm[2] + p->dm[3]) / sd;
        p->halo = (int)ceil(FX_BLUR_RECURSIVE_HALO_SIGMAS * sigma);
        p->use_float = FX_BLUR_FLOAT && sigma <= FX_BLUR_FLOAT_MAX_SIGMA;
        if (p->use_float)
            fx_deriche_sections(sigma, &p->sec);
        return FX_OK;
    }
    p->alg = FX_BLUR_EXACT;
    int R = fx_gaussian_radius(sigma);
    p->R = R;
    p->halo = R;
    p->taps = fx_mem_alloc((2 * (size_t)R + 1) * sizeof(double));
    p->pre = fx_mem_alloc((2 * (size_t)R + 2) * sizeof(double));
    p->suf = fx_mem_alloc((2 * (size_t)R + 2) * sizeof(double));
    if (!p->taps || !p->pre || !p->suf) {
        plan_free(p);
        return FX_ERR_OUT_OF_MEMORY;
    }
    fx_gaussian_taps(sigma, R, p->taps);
    p->pre[0] = 0;
    for (int m = 1; m <= 2 * R + 1; m++)
        p->pre[m] = p->pre[m - 1] + p->taps[m - 1];
    p->suf[2 * R + 1] = 0;
    for (int m = 2 * R; m >= 0; m--)
        p->suf[m] = p->suf[m + 1] + p->taps[m];
    return FX_OK;
}

int fx_blur_is_identity(const fx_blur_spec *spec)
{
    return !spec || !(spec->sigma >= FX_BLUR_MIN_SIGMA);
}

int fx_blur_halo(const fx_blur_spec *spec)
{
    if (fx_blur_is_identity(spec))
        return 0;
    double sigma = spec->sigma > FX_BLUR_MAX_SIGMA ? FX_BLUR_MAX_SIGMA : spec->sigma;
    if (spec->algorithm == FX_BLUR_BOX) {
        int passes = spec->box_passes < 2 ? 2 : spec->box_passes > 6 ? 6 : spec->box_passes;
        int r;
        double alpha;
        fx_extended_box(sigma * sigma / passes, &r, &alpha);
        return passes * (r + 1);
    }
    if (spec->algorithm == FX_BLUR_RECURSIVE && sigma >= FX_BLUR_RECURSIVE_MIN_SIGMA)
        return (int)ceil(FX_BLUR_RECURSIVE_HALO_SIGMAS * sigma);
    return fx_gaussian_radius(sigma);
}

/* ---- lane kernels ---------------------------------------------------------------------- */
/* A lane buffer holds rows -ext .. n+ext-1 of L doubles (plan.ext >= PAD); `buf` points at row 0. */

FX_CLONES
static void exact_lanes(const blur_plan *p, const double *restrict in, double *restrict out, int n,
                        int L)
{
    const int R = p->R;
    const double *last = in + (size_t)(n - 1) * L;
    for (int i = 0; i < n; i++) {
        double *restrict o = out + (size_t)i * L;
        int j0 = i - R < 0 ? 0 : i - R;
        int j1 = i + R > n - 1 ? n - 1 : i + R;
        /* taps falling left of 0 / right of n-1 all read the edge sample (replicate) */
        double wl = i - R < 0 ? p->pre[R - i] : 0.0;
        double wr = i + R > n - 1 ? p->suf[n - i + R] : 0.0;
        for (int l = 0; l < L; l++)
            o[l] = wl * in[l] + wr * last[l];
        for (int j = j0; j <= j1; j++) {
            const double w = p->taps[j - i + R];
            const double *restrict x = in + (size_t)j * L;
            for (int l = 0; l < L; l++)
                o[l] += w * x[l];
        }
    }
}

/* Extended boxes, all passes fused in one sweep. Stage k (k = 0..passes-1) keeps the last
 * M = 2r+2 samples of its input in a ring and the running sum s of the inner 2r+1; fed
 * input position t it emits (unnormalised) position t - (r+1):
 *     s += x[t-1] - x[t-2r-2];   u = s + alpha (x[t-2r-2] + x[t])
 * (x[t-2r-2] is both the sample leaving the sum and the left end tap), and u feeds stage
 * k+1. The last stage's output times normP = norm^passes is position t - passes (r+1).
 * Replicate borders: the stages start in the steady state of the first sample (rings full
 * of it: what an infinitely long run of it leaves), and past the end the last sample is
 * fed, so the cascade sees the replicate extension (exact: every pass of the old padded
 * cascade saw the same). Every `resum` steps each s is recomputed from its ring (fixed
 * order: oldest first) instead of updated, so that a huge value (1e38) leaving the window
 * cannot leave its rounding residue behind for long. Per lane the operations are the same
 * in every version of the kernel (lanes here, v4d below), so they give the same bits.
 * st holds passes * (2r+3) * L doubles. */
FX_CLONES
static void box_lanes(const blur_plan *p, const double *restrict in, double *restrict out, int n,
                      int L, double *restrict st)
{
    const int P = p->passes, r = p->r, M = 2 * r + 2, W = 2 * r + 1, lag = P * (r + 1);
    const double a = p->alpha, g = p->normP;
    double *restrict ring = st, *restrict S = st + (size_t)P * M * L;
    for (int l = 0; l < L; l++) {
        double c = in[l];
        for (int k = 0; k < P; k++) {
            double *rk = ring + (size_t)k * M * L;
            for (int m = 0; m < M; m++)
                rk[(size_t)m * L + l] = c;
            double s = c;
            for (int j = 1; j < W; j++)
                s += c;
            c = s + a * (c + c);
        }
    }
    int slot = 0, pslot = M - 1, rc = 0;
    for (int t = 0; t < n + lag; t++) {
        if (rc == 0) /* re-sum: inner window = every slot but the current one, oldest first */
            for (int k = 0; k < P; k++) {
                const double *rk = ring + (size_t)k * M * L;
                double *sk = S + (size_t)k * L;
                int m = slot + 1 == M ? 0 : slot + 1;
                for (int l = 0; l < L; l++)
                    sk[l] = rk[(size_t)m * L + l];
                for (int j = 1; j < W; j++) {
                    m = m + 1 == M ? 0 : m + 1;
                    for (int l = 0; l < L; l++)
                        sk[l] += rk[(size_t)m * L + l];
                }
            }
        const double *xin = in + (size_t)(t < n ? t : n - 1) * L;
        double *o = t >= lag ? out + (size_t)(t - lag) * L : NULL;
        for (int l = 0; l < L; l++) {
            double x = xin[l];
            for (int k = 0; k < P; k++) {
                double *rk = ring + (size_t)k * M * L;
                double old = rk[(size_t)slot * L + l];
                double s = S[(size_t)k * L + l];
                if (rc != 0)
                    s = s + (rk[(size_t)pslot * L + l] - old);
                S[(size_t)k * L + l] = s;
                rk[(size_t)slot * L + l] = x;
                x = s + a * (old + x);
            }
            if (o)
                o[l] = x * g;
        }
        pslot = slot;
        slot = slot + 1 == M ? 0 : slot + 1;
        rc = rc + 1 == p->resum ? 0 : rc + 1;
    }
}

/* Deriche: causal + anticausal 4th-order recursions, summed. The replicate extension is
 * exact: the causal part only sees the left constant (its steady state is x0 * gain_c),
 * the anticausal part only the right one. x has PAD rows each side (overwritten with
 * the edge values); the result goes to y; s holds 4 * L doubles. */
FX_CLONES
static void deriche_lanes(const blur_plan *p, double *x, double *y, int n, int L,
                          double *restrict s)
{
    const double n0 = p->dn[0], n1 = p->dn[1], n2 = p->dn[2], n3 = p->dn[3];
    const double m1 = p->dm[0], m2 = p->dm[1], m3 = p->dm[2], m4 = p->dm[3];
    const double d1 = p->dd[0], d2 = p->dd[1], d3 = p->dd[2], d4 = p->dd[3];
    const ptrdiff_t Ls = L;
    const double *first = x, *last = x + (n - 1) * Ls;
    for (int k = 1; k <= 4; k++) {
        double *restrict xl = x - k * Ls, *restrict yl = y - k * Ls;
        double *restrict xr = x + (n - 1 + k) * Ls;
        for (int l = 0; l < L; l++) {
            xl[l] = first[l];
            yl[l] = first[l] * p->gain_c;
            xr[l] = last[l];
        }
    }
    for (int i = 0; i < n; i++) {
        const double *restrict x0 = x + i * Ls, *restrict x1 = x0 - Ls, *restrict x2 = x0 - 2 * Ls,
                            *restrict x3 = x0 - 3 * Ls;
        const double *restrict y1 = y + (i - 1) * Ls, *restrict y2 = y1 - Ls, *restrict y3 = y1 - 2 * Ls,
                            *restrict y4 = y1 - 3 * Ls;
        double *restrict y0 = y + i * Ls;
        for (int l = 0; l < L; l++)
            y0[l] = (n0 * x0[l] + n1 * x1[l] + n2 * x2[l] + n3 * x3[l]) -
                    ((d4 * y4[l] + d3 * y3[l] + d2 * y2[l]) + d1 * y1[l]);
    }
    double *s1 = s, *s2 = s + Ls, *s3 = s + 2 * Ls, *s4 = s + 3 * Ls;
    for (int l = 0; l < L; l++)
        s1[l] = s2[l] = s3[l] = s4[l] = last[l] * p->gain_a;
    for (int i = n - 1; i >= 0; i--) {
        const double *restrict xa = x + (i + 1) * Ls, *restrict xb = xa + Ls, *restrict xc = xa + 2 * Ls,
                            *restrict xd = xa + 3 * Ls;
        double *restrict y0 = y + i * Ls;
        double *restrict o = s4; /* the oldest state becomes the newest */
        const double *restrict q1 = s1, *restrict q2 = s2, *restrict q3 = s3;
        for (int l = 0; l < L; l++) {
            double v = (m1 * xa[l] + m2 * xb[l] + m3 * xc[l] + m4 * xd[l]) -
                       ((d4 * o[l] + d3 * q3[l] + d2 * q2[l]) + d1 * q1[l]);
            o[l] = v;
            y0[l] += v;
        }
        s4 = s3;
        s3 = s2;
        s2 = s1;
        s1 = o;
    }
}

/* Runs the plan on buffer a (rows 0..n-1 of L lanes, plan.ext rows each side); b is scratch of
 * the same shape; s holds lane_state_doubles(p, L). Returns the buffer holding the result. */
static double *filter_lanes(const blur_plan *p, double *a, double *b, int n, int L, double *s)
{
    switch (p->alg) {
    case FX_BLUR_EXACT:
        exact_lanes(p, a, b, n, L);
        return b;
    case FX_BLUR_RECURSIVE:
        deriche_lanes(p, a, b, n, L, s);
        return b;
    case FX_BLUR_BOX:
    default:
        box_lanes(p, a, b, n, L, s);
        return b;
    }
}

/* Doubles of state filter_lanes needs for L lanes. */
static size_t lane_state_doubles(const blur_plan *p, int L)
{
    if (p->alg == FX_BLUR_BOX)
        return (size_t)p->passes * (2 * (size_t)p->r + 3) * (size_t)L;
    return 4 * (size_t)L;
}

static inline float to_float_clamped(double v)
{
    /* finite in, finite out: double sums of floats cannot overflow, the cast could.
     * Written as selects so the loops around it vectorise (min/max). */
    v = v > (double)FLT_MAX ? (double)FLT_MAX : v;
    v = v < -(double)FLT_MAX ? -(double)FLT_MAX : v;
    return (float)v;
}

/* ---- the image passes ------------------------------------------------------------------ */

/* GCC vector extensions: one RGBA pixel in double is a v4d (one AVX register, two SSE2
 * ones in the baseline clone; the same IEEE operations either way). */
/* Only used inside always-inline helpers and the kernels: no v4d crosses a call (the
 * ABI note GCC gives for that case does not apply). */
#if defined(__GNUC__) && !defined(__clang__)
#  pragma GCC diagnostic ignored "-Wpsabi"
#endif
typedef double v4d __attribute__((vector_size(32)));
typedef long long v4di __attribute__((vector_size(32)));
typedef float v4f __attribute__((vector_size(16)));

#define H_ROWS 4 /* rows per block of the RGBA horizontal recursive pass */

typedef struct blur_job {
    const blur_plan *plan;
    const float *src;
    float *dst;
    float *vbuf;      /* vertical result: rows oy0..oy1-1, columns sx0..sx1-1 */
    size_t vstride;   /* floats per vbuf row */
    float *vorigin;   /* vbuf address of (row oy0, column 0), may point before vbuf */
    int width, height, channels;
    int ox0, ox1, oy0, oy1; /* output region */
    int sx0, sx1, sy0, sy1; /* computed (halo-grown, clamped) region */
    int strip_lanes;  /* vertical: floats per strip */
    int block_rows;   /* horizontal: rows per block */
    int fast_v, fast_h; /* recursive: direct row-wise kernels */
    int use_float;      /* recursive in float (plan.use_float) */
    atomic_int fallback; /* a vertical strip went to the double kernels: so does the rest */
    char *scratch;    /* per worker: scratch_bytes each */
    size_t scratch_bytes;
} blur_job;

static double *lane_buffer(int n, int L, int ext)
{
    return fx_mem_alloc(((size_t)n + 2 * (size_t)ext) * (size_t)L * sizeof(double));
}

static void *worker_scratch(const blur_job *j, int worker)
{
    return j->scratch + (size_t)worker * j->scratch_bytes;
}

static size_t round_up64(size_t b)
{
    return (b + 63) & ~(size_t)63;
}

static inline __attribute__((always_inline)) v4d load4(const float *p)
{
    /* element-wise: GCC 12 turns this into one vcvtps2pd ymm, [mem] in the AVX2 clone (a
     * __builtin_convertvector of a v4f gives two halves and an insert) */
    v4d r = { p[0], p[1], p[2], p[3] };
    return r;
}

static inline __attribute__((always_inline)) void store4_clamped(float *p, v4d v)
{
    const v4d hi = { (double)FLT_MAX, (double)FLT_MAX, (double)FLT_MAX, (double)FLT_MAX };
    v4di mh = v > hi, ml = v < -hi;
    v4di b = (v4di)v;
    b = (b & ~mh) | ((v4di)hi & mh);
    b = (b & ~ml) | ((v4di)(-hi) & ml);
    v4f f = __builtin_convertvector((v4d)b, v4f);
    memcpy(p, &f, sizeof f);
}

/* Deriche, vertical, straight from the image rows: strip of L floats (any channels), rows
 * 0..n-1 of `in` (`stride` floats apart), output rows o0..o1-1 to out (row o0 at `out`).
 * The causal pass copies the strip to xs (contiguous, (n + 7) x L4 floats, L4 = L rounded
 * up to 4: 3 edge rows before, 4 after; strided rows would thrash L2's sets on the way
 * back) and keeps the output rows' y+ in cb ((o1-o0) x L4/4 v4d); the anticausal pass adds
 * y- and stores. Same operations as deriche_lanes, lane by lane, so the same bits.
 * out may alias in (in is only read in the causal pass). st holds 5 x L4/4 v4d. */
FX_CLONES
static void deriche_vertical(const blur_plan *p, const float *in, size_t stride, int n, int o0,
                             int o1, float *out, size_t ostride, int L, v4d *cb, v4d *st,
                             float *xs)
{
    const double n0 = p->dn[0], n1 = p->dn[1], n2 = p->dn[2], n3 = p->dn[3];
    const double m1 = p->dm[0], m2 = p->dm[1], m3 = p->dm[2], m4 = p->dm[3];
    const double d1 = p->dd[0], d2 = p->dd[1], d3 = p->dd[2], d4 = p->dd[3];
    const int V = (L + 3) / 4, L4 = 4 * V;
    const ptrdiff_t Ls = L4;
    v4d *y1 = st, *y2 = st + V, *y3 = st + 2 * V, *y4 = st + 3 * V, *dummy = st + 4 * V;
    float *x = xs + 3 * Ls; /* row 0 */
    for (int i = -3; i < 0; i++) {
        memcpy(x + i * Ls, in, (size_t)L * sizeof(float));
        memset(x + i * Ls + L, 0, (size_t)(L4 - L) * sizeof(float));
    }
    for (int v = 0; v < V; v++)
        y1[v] = y2[v] = y3[v] = y4[v] = load4(x - Ls + 4 * v) * p->gain_c;
    for (int i = 0; i < n; i++) {
        const float *f = in + (size_t)i * stride;
        if (i + 8 < n) /* rows are a page or more apart: no prefetcher follows that stride */
            for (int l = 0; l < L; l += 16)
                __builtin_prefetch(f + 8 * stride + l);
        float *x0 = x + i * Ls;
        memcpy(x0, f, (size_t)L * sizeof(float));
        memset(x0 + L, 0, (size_t)(L4 - L) * sizeof(float));
        v4d *c = i >= o0 && i < o1 ? cb + (size_t)(i - o0) * V : dummy;
        for (int v = 0; v < V; v++) {
            const float *xv = x0 + 4 * v;
            v4d r = (n0 * load4(xv) + n1 * load4(xv - Ls) + n2 * load4(xv - 2 * Ls) +
                     n3 * load4(xv - 3 * Ls)) -
                    ((d4 * y4[v] + d3 * y3[v] + d2 * y2[v]) + d1 * y1[v]);
            y4[v] = r; /* the oldest slot becomes the newest */
            c[v] = r;
        }
        v4d *t = y4;
        y4 = y3, y3 = y2, y2 = y1, y1 = t;
    }
    for (int k = 0; k < 4; k++)
        memcpy(x + (n + k) * Ls, x + (n - 1) * Ls, (size_t)L4 * sizeof(float));
    /* anticausal: q1..q4 hold y-[i+1..i+4] */
    v4d *q1 = y1, *q2 = y2, *q3 = y3, *q4 = y4;
    for (int v = 0; v < V; v++)
        q1[v] = q2[v] = q3[v] = q4[v] = load4(x + (n - 1) * Ls + 4 * v) * p->gain_a;
    for (int i = n - 1; i >= o0; i--) {
        const float *x1 = x + (i + 1) * Ls;
        if (i < o1) {
            const v4d *c = cb + (size_t)(i - o0) * V;
            float *o = out + (size_t)(i - o0) * ostride;
            for (int v = 0; v < V; v++) {
                const float *xv = x1 + 4 * v;
                v4d r = (m1 * load4(xv) + m2 * load4(xv + Ls) + m3 * load4(xv + 2 * Ls) +
                         m4 * load4(xv + 3 * Ls)) -
                        ((d4 * q4[v] + d3 * q3[v] + d2 * q2[v]) + d1 * q1[v]);
                q4[v] = r;
                if (4 * v + 4 <= L) {
                    store4_clamped(o + 4 * v, c[v] + r);
                } else {
                    float tail[4];
                    store4_clamped(tail, c[v] + r);
                    memcpy(o + 4 * v, tail, (size_t)(L - 4 * v) * sizeof(float));
                }
            }
        } else {
            for (int v = 0; v < V; v++) {
                const float *xv = x1 + 4 * v;
                q4[v] = (m1 * load4(xv) + m2 * load4(xv + Ls) + m3 * load4(xv + 2 * Ls) +
                         m4 * load4(xv + 3 * Ls)) -
                        ((d4 * q4[v] + d3 * q3[v] + d2 * q2[v]) + d1 * q1[v]);
            }
        }
        v4d *t = q4;
        q4 = q3, q3 = q2, q2 = q1, q1 = t;
    }
}

/* Deriche, horizontal, RGBA: H_ROWS rows at once, one v4d per pixel and row (independent
 * recursions to hide the latency). in[r]: row r at column sx0 (n pixels); out[r]: row r
 * at column sx0 (NULL: row absent), written for pixels o0..o1-1; cb holds (o1-o0) x H_ROWS
 * v4d. Same operations as deriche_lanes per lane. out may alias in. */
FX_CLONES
static void deriche_rows4(const blur_plan *p, const float *const *in, float *const *out, int n,
                          int o0, int o1, v4d *cb)
{
    const double n0 = p->dn[0], n1 = p->dn[1], n2 = p->dn[2], n3 = p->dn[3];
    const double m1 = p->dm[0], m2 = p->dm[1], m3 = p->dm[2], m4 = p->dm[3];
    const double d1 = p->dd[0], d2 = p->dd[1], d3 = p->dd[2], d4 = p->dd[3];
    v4d X1[H_ROWS], X2[H_ROWS], X3[H_ROWS], X4[H_ROWS], Y1[H_ROWS], Y2[H_ROWS], Y3[H_ROWS],
        Y4[H_ROWS];
    for (int r = 0; r < H_ROWS; r++) {
        v4d v = load4(in[r]);
        X1[r] = X2[r] = X3[r] = v;
        Y1[r] = Y2[r] = Y3[r] = Y4[r] = v * p->gain_c;
    }
    for (int i = 0; i < n; i++) {
        v4d *c = i >= o0 && i < o1 ? cb + (size_t)(i - o0) * H_ROWS : NULL;
#pragma GCC unroll 4
        for (int r = 0; r < H_ROWS; r++) {
            v4d x0 = load4(in[r] + (size_t)i * 4);
            v4d v = (n0 * x0 + n1 * X1[r] + n2 * X2[r] + n3 * X3[r]) -
                    ((d4 * Y4[r] + d3 * Y3[r] + d2 * Y2[r]) + d1 * Y1[r]);
            X3[r] = X2[r], X2[r] = X1[r], X1[r] = x0;
            Y4[r] = Y3[r], Y3[r] = Y2[r], Y2[r] = Y1[r], Y1[r] = v;
            if (c)
                c[r] = v;
        }
    }
    for (int r = 0; r < H_ROWS; r++) {
        v4d v = load4(in[r] + (size_t)(n - 1) * 4);
        X1[r] = X2[r] = X3[r] = X4[r] = v;
        Y1[r] = Y2[r] = Y3[r] = Y4[r] = v * p->gain_a;
    }
    for (int i = n - 1; i >= o0; i--) {
        const v4d *c = i < o1 ? cb + (size_t)(i - o0) * H_ROWS : NULL;
#pragma GCC unroll 4
        for (int r = 0; r < H_ROWS; r++) {
            v4d v = (m1 * X1[r] + m2 * X2[r] + m3 * X3[r] + m4 * X4[r]) -
                    ((d4 * Y4[r] + d3 * Y3[r] + d2 * Y2[r]) + d1 * Y1[r]);
            v4d x0 = load4(in[r] + (size_t)i * 4); /* before out[r] is written */
            X4[r] = X3[r], X3[r] = X2[r], X2[r] = X1[r], X1[r] = x0;
            Y4[r] = Y3[r], Y3[r] = Y2[r], Y2[r] = Y1[r], Y1[r] = v;
            if (c && out[r])
                store4_clamped(out[r] + (size_t)i * 4, c[r] + v);
        }
    }
}

/* ---- recursive in float ------------------------------------------------------------------
 * Deriche's filter as two second-order sections (fx_deriche_sections), run on d = x - c with
 * c the line's first sample: the causal half then starts at rest (its steady state for the
 * left edge is 0), constant lines come out exact, and the rounding of the states follows the
 * line's contrast, not its level. Eight lanes per vector (one AVX register in the AVX2 clone,
 * two SSE ones in the baseline: the same IEEE operations lane by lane, no FMA, so the same
 * bits). Per lane every kernel below does exactly these operations in this order:
 *   d = x - c
 *   u_k = (b0_k d + b1_k d[-1]) - (p1_k u_k[-1] + p2_k u_k[-2])       k = 0, 1
 *   yc = u_0 + u_1
 *   v_k = (m1_k d[+1] + m2_k d[+2]) - (p1_k v_k[+1] + p2_k v_k[+2])
 *   out = (yc + (v_0 + v_1)) + c
 * with u = 0 and d[-1] = 0 before the first sample, d = d[n-1] and v_k = ga_k d[n-1] past the
 * last. Inputs must be finite and below FX_BLUR_FLOAT_MAX_VALUE (checked: the kernels report
 * a failure and the caller runs the double kernels); the states are then bounded by the
 * filter's gain, far from overflow, and the outputs need no clamp. */

#define VF_MAX_G 8 /* v8f groups of a float vertical strip at most */
#define V_LANES_F 64 /* floats per vertical strip (float recursive) */
#define VF_PREFETCH 32 /* rows ahead the float vertical pass prefetches */
#define HF_ROWS 4   /* rows per block of the float RGBA horizontal pass (two per v8f) */

/* all 8 lanes finite and |x| < FX_BLUR_FLOAT_MAX_VALUE: -1 per lane, else 0 */
static inline __attribute__((always_inline)) v8i small8(v8f x)
{
    const v8i absmask = { 0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff,
                          0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff };
    v8f a = (v8f)((v8i)x & absmask);
    return a < S8(FX_BLUR_FLOAT_MAX_VALUE); /* false for NaN */
}

static inline __attribute__((always_inline)) int all8(v8i m)
{
    int32_t t[8];
    memcpy(t, &m, sizeof t);
    return (t[0] & t[1] & t[2] & t[3] & t[4] & t[5] & t[6] & t[7]) != 0;
}

/* Vertical, straight from the image rows: strip of L <= V_LANES_F floats (any channels),
 * rows 0..n-1 of `in` (`stride` floats apart), output rows o0..o1-1 to out (row o0 at `out`,
 * `ostride` apart). xs: (n + 3) x L8 floats (L8 = L rounded up to 8): the strip's d, contiguous
 * (strided rows would thrash L2's sets on the way back), after a row of zeros (d[-1]) and
 * before the two replicated rows past the end; cb: (o1 - o0) x L8 floats, the causal result of the output rows. Returns 0,
 * having written nothing, when the strip holds a value the float kernels do not take.
 * out may alias in (in is only read in the causal pass). */
FX_CLONES
static int derf_vertical(const fx_deriche_sec *p, const float *in, size_t stride, int n, int o0, int o1,
                         float *out, size_t ostride, int L, float *xs, float *cb)
{
    const int G = (L + 7) / 8, L8 = 8 * G;
    const v8f b00 = S8(p->b0[0]), b01 = S8(p->b0[1]), b10 = S8(p->b1[0]), b11 = S8(p->b1[1]);
    const v8f m10 = S8(p->m1[0]), m11 = S8(p->m1[1]), m20 = S8(p->m2[0]), m21 = S8(p->m2[1]);
    const v8f p10 = S8(p->p1[0]), p11 = S8(p->p1[1]), p20 = S8(p->p2[0]), p21 = S8(p->p2[1]);
    /* states: section 0 in s0a/s0b, section 1 in s1a/s1b; the newer of each pair is the one
     * `a` points at, the step writes over the older and the pointers swap (no copies) */
    v8f c[VF_MAX_G], s0a[VF_MAX_G], s0b[VF_MAX_G], s1a[VF_MAX_G], s1b[VF_MAX_G];
    v8f *n0 = s0a, *o0s = s0b, *n1 = s1a, *o1s = s1b;
    v8i ok = (v8i){ -1, -1, -1, -1, -1, -1, -1, -1 };
    float *x0 = xs + L8; /* row -1 (d = 0) at xs */
    memset(xs, 0, (size_t)L8 * sizeof(float));
    memcpy(x0, in, (size_t)L * sizeof(float));
    if (L < L8)
        memset(x0 + L, 0, (size_t)(L8 - L) * sizeof(float));
    for (int g = 0; g < G; g++) {
        c[g] = fx_load8(x0 + 8 * g);
        s0a[g] = s0b[g] = s1a[g] = s1b[g] = S8(0.0f);
    }
    for (int i = 0; i < n; i++) {
        const float *f = in + (size_t)i * stride;
        if (i + VF_PREFETCH < n) /* rows are a page or more apart: no prefetcher follows that stride */
            for (int l = 0; l < L; l += 16)
                __builtin_prefetch(f + VF_PREFETCH * stride + l);
        float *x = x0 + (size_t)i * L8;
        memcpy(x, f, (size_t)L * sizeof(float));
        if (L < L8)
            memset(x + L, 0, (size_t)(L8 - L) * sizeof(float));
        float *cr = i >= o0 && i < o1 ? cb + (size_t)(i - o0) * L8 : NULL;
        for (int g = 0; g < G; g++) {
            const v8f xv = fx_load8(x + 8 * g), dp = fx_load8(x - L8 + 8 * g);
            ok &= small8(xv);
            const v8f d = xv - c[g];
            fx_store8(x + 8 * g, d);
            const v8f u0 = (b00 * d + b10 * dp) - (p10 * n0[g] + p20 * o0s[g]);
            const v8f u1 = (b01 * d + b11 * dp) - (p11 * n1[g] + p21 * o1s[g]);
            o0s[g] = u0;
            o1s[g] = u1;
            if (cr)
                fx_store8(cr + 8 * g, u0 + u1);
        }
        v8f *t = n0;
        n0 = o0s, o0s = t;
        t = n1, n1 = o1s, o1s = t;
    }
    if (!all8(ok))
        return 0;
    /* anticausal: e1 = d[i+1], e2 = d[i+2] (replicated past the end) */
    const float *xl = x0 + (size_t)(n - 1) * L8;
    memcpy(x0 + (size_t)n * L8, xl, (size_t)L8 * sizeof(float));
    memcpy(x0 + (size_t)(n + 1) * L8, xl, (size_t)L8 * sizeof(float));
    for (int g = 0; g < G; g++) {
        const v8f dl = fx_load8(xl + 8 * g);
        n0[g] = o0s[g] = S8(p->ga[0]) * dl;
        n1[g] = o1s[g] = S8(p->ga[1]) * dl;
    }
    for (int i = n - 1; i >= o0; i--) {
        const float *e1p = x0 + (size_t)(i + 1) * L8, *e2p = e1p + L8;
        if (i < o1) {
            float *o = out + (size_t)(i - o0) * ostride;
            const float *cr = cb + (size_t)(i - o0) * L8;
            for (int g = 0; g < G; g++) {
                const v8f e1 = fx_load8(e1p + 8 * g), e2 = fx_load8(e2p + 8 * g);
                const v8f v0 = (m10 * e1 + m20 * e2) - (p10 * n0[g] + p20 * o0s[g]);
                const v8f v1 = (m11 * e1 + m21 * e2) - (p11 * n1[g] + p21 * o1s[g]);
                o0s[g] = v0;
                o1s[g] = v1;
                const v8f r = (fx_load8(cr + 8 * g) + (v0 + v1)) + c[g];
                if (8 * g + 8 <= L) {
                    fx_store8(o + 8 * g, r);
                } else {
                    float tl[8];
                    fx_store8(tl, r);
                    memcpy(o + 8 * g, tl, (size_t)(L - 8 * g) * sizeof(float));
                }
            }
        } else {
            for (int g = 0; g < G; g++) {
                const v8f e1 = fx_load8(e1p + 8 * g), e2 = fx_load8(e2p + 8 * g);
                o0s[g] = (m10 * e1 + m20 * e2) - (p10 * n0[g] + p20 * o0s[g]);
                o1s[g] = (m11 * e1 + m21 * e2) - (p11 * n1[g] + p21 * o1s[g]);
            }
        }
        v8f *t = n0;
        n0 = o0s, o0s = t;
        t = n1, n1 = o1s, o1s = t;
    }
    return 1;
}

/* Two RGBA pixels (rows a and b) as one v8f, and back. Halves by memcpy rather than
 * __builtin_shufflevector, which gcc has only from 12 (the release build uses gcc 10). */
static inline __attribute__((always_inline)) v8f ld2px(const float *a, const float *b)
{
    v8f v;
    memcpy(&v, a, 4 * sizeof(float));
    memcpy((char *)&v + 4 * sizeof(float), b, 4 * sizeof(float));
    return v;
}

static inline __attribute__((always_inline)) void st2px(float *a, float *b, v8f v)
{
    if (a)
        memcpy(a, &v, 4 * sizeof(float));
    if (b)
        memcpy(b, (const char *)&v + 4 * sizeof(float), 4 * sizeof(float));
}

/* Horizontal, RGBA: HF_ROWS rows at once, rows 2q and 2q+1 in one v8f (as deriche_rows4:
 * in[r] row r at column sx0, n pixels; out[r] row r at column sx0, NULL: row absent; pixels
 * o0..o1-1 written). cb: (o1 - o0) x 4 HF_ROWS floats. out may alias in: pixel i is read
 * before it is written. The inputs are the vertical pass's float outputs, which passed its
 * check: no test here. */
FX_CLONES
static void derf_rows4(const fx_deriche_sec *p, const float *const *in, float *const *out, int n, int o0,
                       int o1, float *cb)
{
    enum { Q = HF_ROWS / 2 };
    const v8f b00 = S8(p->b0[0]), b01 = S8(p->b0[1]), b10 = S8(p->b1[0]), b11 = S8(p->b1[1]);
    const v8f m10 = S8(p->m1[0]), m11 = S8(p->m1[1]), m20 = S8(p->m2[0]), m21 = S8(p->m2[1]);
    const v8f p10 = S8(p->p1[0]), p11 = S8(p->p1[1]), p20 = S8(p->p2[0]), p21 = S8(p->p2[1]);
    v8f c[Q], d1[Q], ua[Q], ub[Q], uc[Q], ud[Q];
    for (int q = 0; q < Q; q++) {
        c[q] = ld2px(in[2 * q], in[2 * q + 1]);
        d1[q] = ua[q] = ub[q] = uc[q] = ud[q] = S8(0.0f);
    }
    for (int i = 0; i < n; i++) {
        float *cr = i >= o0 && i < o1 ? cb + (size_t)(i - o0) * 4 * HF_ROWS : NULL;
#pragma GCC unroll 2
        for (int q = 0; q < Q; q++) {
            const v8f d = ld2px(in[2 * q] + (size_t)i * 4, in[2 * q + 1] + (size_t)i * 4) - c[q];
            const v8f u0 = (b00 * d + b10 * d1[q]) - (p10 * ua[q] + p20 * ub[q]);
            const v8f u1 = (b01 * d + b11 * d1[q]) - (p11 * uc[q] + p21 * ud[q]);
            ub[q] = ua[q], ua[q] = u0;
            ud[q] = uc[q], uc[q] = u1;
            d1[q] = d;
            if (cr)
                fx_store8(cr + 8 * q, u0 + u1);
        }
    }
    v8f e1[Q], e2[Q];
    for (int q = 0; q < Q; q++) {
        const v8f dl = ld2px(in[2 * q] + (size_t)(n - 1) * 4, in[2 * q + 1] + (size_t)(n - 1) * 4) - c[q];
        e1[q] = e2[q] = dl;
        ua[q] = ub[q] = S8(p->ga[0]) * dl;
        uc[q] = ud[q] = S8(p->ga[1]) * dl;
    }
    for (int i = n - 1; i >= o0; i--) {
        const float *cr = i < o1 ? cb + (size_t)(i - o0) * 4 * HF_ROWS : NULL;
#pragma GCC unroll 2
        for (int q = 0; q < Q; q++) {
            const v8f v0 = (m10 * e1[q] + m20 * e2[q]) - (p10 * ua[q] + p20 * ub[q]);
            const v8f v1 = (m11 * e1[q] + m21 * e2[q]) - (p11 * uc[q] + p21 * ud[q]);
            ub[q] = ua[q], ua[q] = v0;
            ud[q] = uc[q], uc[q] = v1;
            const v8f d = ld2px(in[2 * q] + (size_t)i * 4, in[2 * q + 1] + (size_t)i * 4) - c[q]; /* before out is written */
            e2[q] = e1[q], e1[q] = d;
            if (cr) {
                const v8f r = (fx_load8(cr + 8 * q) + (v0 + v1)) + c[q];
                st2px(out[2 * q] ? out[2 * q] + (size_t)i * 4 : NULL,
                      out[2 * q + 1] ? out[2 * q + 1] + (size_t)i * 4 : NULL, r);
            }
        }
    }
}

/* Lanes: x holds n + 2 steps x L lanes (step i at x + i L; the input in steps 0..n-1),
 * overwritten with d; the result goes to y (n x L); st holds 7 L floats. Returns 0, having
 * written nothing, when a value is not taken (see above). The lane loops vectorise (any
 * width: the same bits). */
FX_CLONES
static int derf_lanes(const fx_deriche_sec *p, float *restrict x, float *restrict y, int n, int L,
                      float *restrict st)
{
    int ok = 1;
    for (size_t i = 0; i < (size_t)n * L; i++)
        ok &= fabsf(x[i]) < FX_BLUR_FLOAT_MAX_VALUE;
    if (!ok)
        return 0;
    const float b00 = p->b0[0], b01 = p->b0[1], b10 = p->b1[0], b11 = p->b1[1];
    const float m10 = p->m1[0], m11 = p->m1[1], m20 = p->m2[0], m21 = p->m2[1];
    const float p10 = p->p1[0], p11 = p->p1[1], p20 = p->p2[0], p21 = p->p2[1];
    float *restrict c = st, *restrict d1 = st + L, *restrict ua = st + 2 * L, *restrict ub = st + 3 * L;
    float *restrict uc = st + 4 * L, *restrict ud = st + 5 * L;
    for (int l = 0; l < L; l++) {
        c[l] = x[l];
        d1[l] = ua[l] = ub[l] = uc[l] = ud[l] = 0.0f;
    }
    for (int i = 0; i < n; i++) {
        float *restrict xi = x + (size_t)i * L, *restrict yi = y + (size_t)i * L;
        for (int l = 0; l < L; l++) {
            const float d = xi[l] - c[l];
            xi[l] = d;
            const float u0 = (b00 * d + b10 * d1[l]) - (p10 * ua[l] + p20 * ub[l]);
            const float u1 = (b01 * d + b11 * d1[l]) - (p11 * uc[l] + p21 * ud[l]);
            ub[l] = ua[l], ua[l] = u0;
            ud[l] = uc[l], uc[l] = u1;
            d1[l] = d;
            yi[l] = u0 + u1;
        }
    }
    const float *last = x + (size_t)(n - 1) * L;
    for (int l = 0; l < L; l++) {
        x[(size_t)n * L + l] = x[(size_t)(n + 1) * L + l] = last[l];
        ua[l] = ub[l] = p->ga[0] * last[l];
        uc[l] = ud[l] = p->ga[1] * last[l];
    }
    for (int i = n - 1; i >= 0; i--) {
        const float *restrict e1 = x + (size_t)(i + 1) * L, *restrict e2 = e1 + L;
        float *restrict yi = y + (size_t)i * L;
        for (int l = 0; l < L; l++) {
            const float v0 = (m10 * e1[l] + m20 * e2[l]) - (p10 * ua[l] + p20 * ub[l]);
            const float v1 = (m11 * e1[l] + m21 * e2[l]) - (p11 * uc[l] + p21 * ud[l]);
            ub[l] = ua[l], ua[l] = v0;
            ud[l] = uc[l], uc[l] = v1;
            yi[l] = (yi[l] + (v0 + v1)) + c[l];
        }
    }
    return 1;
}

/* box_lanes on groups of 4 lanes straight from float rows, one group at a time over blocks
 * of BOX_BLOCK positions (the running sums and the previous inputs stay in registers; the
 * rows of a block stay in L1 while the groups go by). Group v of input position i is at
 * in[v] + i * istep (k[v] floats, 4 but for a partial last group); output position o0 + j
 * of group v goes to out[v] + j * ostep. Same operations per lane as box_lanes, so the
 * same bits. out may alias in: position i is written after every read of it, and the
 * last sample (fed past the end) is read once up front. Group v's stage k ring, slot m,
 * is ring[(v * passes + k) * M + m] (M = plan.ring; group-major: slot-major rings put a
 * group's slots NV * 32 bytes apart, on a quarter of L1's sets for NV = 8, and thrashed
 * them); S: passes * NV; last: NV. */
#define BOX_V_NV (V_LANES / 4) /* groups of a vertical strip */
#define BOX_MAX_NV (BOX_V_NV > H_ROWS ? BOX_V_NV : H_ROWS)

/* n floats (n <= V_LANES; V_LANES the usual case, copied inline, no call) */
static inline __attribute__((always_inline)) void copy_row(float *restrict d, const float *restrict s,
                                                           int n)
{
    if (n == V_LANES) {
        float t[V_LANES];
        memcpy(t, s, sizeof t);
        memcpy(d, t, sizeof t);
    } else {
        memcpy(d, s, (size_t)n * sizeof(float));
    }
}

typedef struct box_args {
    const float *in[BOX_MAX_NV]; /* position t of group v at in[v] + (t - ib) * istep */
    size_t istep;
    float *out[BOX_MAX_NV];      /* output of step t of group v at out[v] + (t - ob) * ostep */
    ptrdiff_t ostep;
    int ib, ob;
    int k[BOX_MAX_NV];
    int groups, NV, n, o0, o1;
    v4d *ring, *S, *last;
    /* staged (vertical): rows go through xin / xout (BOX_BLOCK x L floats, contiguous) */
    float *xin, *xout;
    int L;
} box_args;

#define BOX_BLOCK 64

/* The first k floats of p (k < 4: the rest 0), and the store of the first k. */
static inline __attribute__((always_inline)) v4d loadn(const float *p, int k)
{
    if (k >= 4)
        return load4(p);
    float t[4] = { 0, 0, 0, 0 };
    if (k > 0)
        memcpy(t, p, (size_t)k * sizeof(float));
    return load4(t);
}

static inline __attribute__((always_inline)) void storen_clamped(float *p, v4d v, int k)
{
    if (k >= 4) {
        store4_clamped(p, v);
    } else {
        float t[4];
        store4_clamped(t, v);
        memcpy(p, t, (size_t)k * sizeof(float));
    }
}

/* Positions t0..t1-1 of one group; LOAD: t < n (else the last sample is fed); STORE: the
 * output position t - lag is >= o0. slot, rc: ring slot and re-sum counter at t0. The
 * inner loop runs between ring wraps and re-sums, with no test but its own. */
static inline __attribute__((always_inline)) void
box_seg(const blur_plan *p, const int P, const int NV, const int LOAD, const int STORE,
        const box_args *A, int v, int t0, int t1, int slot, int rc)
{
    const int M = p->ring, D2 = 2 * p->r + 2, W = 2 * p->r + 1;
    const int kv = A->k[v], resum = p->resum;
    const double a = p->alpha, g = p->normP;
    const ptrdiff_t RS = M, SL = 1; /* group-major rings: stage stride, slot stride */
    v4d *const ring = A->ring + (ptrdiff_t)v * P * M, *const rend = ring + RS;
    const size_t istep = A->istep;
    const ptrdiff_t ostep = A->ostep;
    const float *in = A->in[v] + (LOAD ? (size_t)(t0 - A->ib) * istep : 0);
    float *out = A->out[v] + (STORE ? (ptrdiff_t)(t0 - A->ob) * ostep : 0);
    const v4d xl = A->last[v];
    v4d S[6], pr[6];
    /* rs: slot of position t (written), ro: of position t - (2r+2) (leaving) */
    int os = slot - D2 < 0 ? slot - D2 + M : slot - D2;
    v4d *rs = ring + (ptrdiff_t)slot * SL, *ro = ring + (ptrdiff_t)os * SL;
    {
        const v4d *rp = slot == 0 ? rend - SL : rs - SL;
        for (int k = 0; k < P; k++) {
            S[k] = A->S[k * NV + v];
            pr[k] = rp[k * RS];
        }
    }
    int t = t0;
    while (t < t1) {
        int len;
        if (rc == 0) { /* re-sum positions t-2r-1 .. t-1, oldest first */
            v4d x = LOAD ? loadn(in, kv) : xl;
            for (int k = 0; k < P; k++) {
                const v4d *rk = ring + k * RS;
                int m = slot - W < 0 ? slot - W + M : slot - W;
                v4d sum = rk[(ptrdiff_t)m * SL];
                int e1 = m + W < M ? m + W : M; /* slots m+1 .. e1-1, then 0 .. W-1-(e1-m) */
                for (int q = m + 1; q < e1; q++)
                    sum += rk[(ptrdiff_t)q * SL];
                for (int q = 0, e2 = W - (e1 - m); q < e2; q++)
                    sum += rk[(ptrdiff_t)q * SL];
                v4d old = ro[k * RS];
                S[k] = sum;
                rs[k * RS] = x;
                pr[k] = x;
                x = S[k] + a * (old + x);
            }
            if (STORE) {
                storen_clamped(out, x * g, kv);
                out += ostep;
            }
            if (LOAD)
                in += istep;
            rs += SL;
            ro += SL;
            len = 1;
        } else {
            len = t1 - t;
            if (M - slot < len)
                len = M - slot;
            if (M - os < len)
                len = M - os;
            if (resum - rc < len)
                len = resum - rc;
            if (kv == 4) {
                for (int i = 0; i < len; i++) {
                    v4d x = LOAD ? load4(in) : xl;
#pragma GCC unroll 6
                    for (int k = 0; k < P; k++) {
                        v4d old = ro[k * RS];
                        S[k] = S[k] + (pr[k] - old);
                        rs[k * RS] = x;
                        pr[k] = x;
                        x = S[k] + a * (old + x);
                    }
                    if (STORE) {
                        store4_clamped(out, x * g);
                        out += ostep;
                    }
                    if (LOAD)
                        in += istep;
                    rs += SL;
                    ro += SL;
                }
            } else {
                for (int i = 0; i < len; i++) {
                    v4d x = LOAD ? loadn(in, kv) : xl;
                    for (int k = 0; k < P; k++) {
                        v4d old = ro[k * RS];
                        S[k] = S[k] + (pr[k] - old);
                        rs[k * RS] = x;
                        pr[k] = x;
                        x = S[k] + a * (old + x);
                    }
                    if (STORE) {
                        storen_clamped(out, x * g, kv);
                        out += ostep;
                    }
                    if (LOAD)
                        in += istep;
                    rs += SL;
                    ro += SL;
                }
            }
        }
        t += len;
        slot += len;
        if (slot == M)
            rs = ring, slot = 0;
        os += len;
        if (os == M)
            ro = ring, os = 0;
        rc += len;
        if (rc == resum)
            rc = 0;
    }
    for (int k = 0; k < P; k++)
        A->S[k * NV + v] = S[k];
}

/* All positions of all groups. Staged (the vertical pass): each block of rows is first
 * copied to xin (L floats a row, contiguous) and its outputs gathered in xout, then
 * copied to the rows: walking the groups down 64 rows a page apart, straight from the
 * image, costs a TLB miss per row and group. */
static inline __attribute__((always_inline)) void box_sweep(const blur_plan *p, const int P,
                                                            const int NV, const int STAGED,
                                                            const box_args *A)
{
    const int M = p->ring, W = 2 * p->r + 1, lag = P * (p->r + 1);
    const double a = p->alpha;
    const int n = A->n, s0 = A->o0 + lag, T = A->o1 + lag;
    for (int v = 0; v < A->groups; v++) {
        v4d c = loadn(A->in[v], A->k[v]);
        A->last[v] = loadn(A->in[v] + (size_t)(n - 1) * A->istep, A->k[v]);
        for (int k = 0; k < P; k++) {
            v4d *rk = A->ring + ((ptrdiff_t)v * P + k) * M;
            for (int m = 0; m < M; m++)
                rk[m] = c;
            A->S[k * NV + v] = c - c;
            v4d s = c;
            for (int j = 1; j < W; j++)
                s += c;
            c = s + a * (c + c);
        }
    }
    box_args B = *A;
    B.ib = 0;
    B.ob = lag + A->o0;
    const size_t XL = (size_t)NV * 4; /* floats per staged row */
    if (STAGED) {
        for (int v = 0; v < A->groups; v++) {
            B.in[v] = A->xin + 4 * v;
            B.out[v] = A->xout + 4 * v;
        }
        B.istep = XL;
        B.ostep = (ptrdiff_t)XL;
    }
    int slot = 0, rc = 0;
    for (int tb = 0; tb < T; tb += BOX_BLOCK) {
        const int te = T - tb < BOX_BLOCK ? T : tb + BOX_BLOCK;
        if (STAGED) {
            const size_t bytes = (size_t)A->L * sizeof(float);
            for (int t = tb; t < te && t < n; t++) {
                const float *row = A->in[0] + (size_t)t * A->istep;
                if (t + BOX_BLOCK < n) /* rows a page apart: no prefetcher follows that */
                    for (size_t c = 0; c < bytes; c += 64)
                        __builtin_prefetch((const char *)row + (size_t)BOX_BLOCK * A->istep * sizeof(float) + c);
                copy_row(A->xin + (size_t)(t - tb) * XL, row, A->L);
            }
            /* and the rows the next block writes, for writing */
            for (int t = te > s0 ? te : s0; t < te + BOX_BLOCK && t < T; t++)
                for (size_t c = 0; c < bytes; c += 64)
                    __builtin_prefetch((const char *)(A->out[0] + (ptrdiff_t)(t - s0) * A->ostep) + c, 1);
            B.ib = tb;
            B.ob = tb;
        }
        for (int v = 0; v < A->groups; v++) {
            int t = tb, sl = slot, r = rc;
            while (t < te) {
                int tend = te;
                if (t < n && n < tend)
                    tend = n;
                if (t < s0 && s0 < tend)
                    tend = s0;
                if (t < n) {
                    if (t >= s0)
                        box_seg(p, P, NV, 1, 1, &B, v, t, tend, sl, r);
                    else
                        box_seg(p, P, NV, 1, 0, &B, v, t, tend, sl, r);
                } else {
                    if (t >= s0)
                        box_seg(p, P, NV, 0, 1, &B, v, t, tend, sl, r);
                    else
                        box_seg(p, P, NV, 0, 0, &B, v, t, tend, sl, r);
                }
                sl = (int)(((long long)sl + (tend - t)) % M);
                r = (int)(((long long)r + (tend - t)) % p->resum);
                t = tend;
            }
        }
        if (STAGED)
            for (int t = tb > s0 ? tb : s0; t < te; t++)
                copy_row(A->out[0] + (ptrdiff_t)(t - s0) * A->ostep, A->xout + (size_t)(t - tb) * XL, A->L);
        slot = (int)(((long long)slot + (te - tb)) % M);
        rc = (int)(((long long)rc + (te - tb)) % p->resum);
    }
}

#define BOX_SWEEP(P)                                                                            \
    FX_CLONES static void box_sweep##P##v(const blur_plan *p, const box_args *A)               \
    {                                                                                           \
        box_sweep(p, P, BOX_V_NV, 1, A);                                                           \
    }                                                                                           \
    FX_CLONES static void box_sweep##P##h(const blur_plan *p, const box_args *A)               \
    {                                                                                           \
        box_sweep(p, P, H_ROWS, 0, A);                                                             \
    }
BOX_SWEEP(2)
BOX_SWEEP(3)
BOX_SWEEP(4)
BOX_SWEEP(5)
BOX_SWEEP(6)

static void box_run(const blur_plan *p, box_args *A, int h, v4d *scratch)
{
    const size_t ring = (size_t)p->passes * (size_t)p->ring * (size_t)A->NV;
    A->ring = scratch;
    A->S = scratch + ring;
    A->last = A->S + (size_t)p->passes * A->NV;
    A->xin = (float *)(A->last + A->NV);          /* BOX_BLOCK x 4 NV floats */
    A->xout = A->xin + (size_t)BOX_BLOCK * 4 * A->NV; /* the same */
    switch (p->passes) {
    case 2: h ? box_sweep2h(p, A) : box_sweep2v(p, A); break;
    case 3: h ? box_sweep3h(p, A) : box_sweep3v(p, A); break;
    case 4: h ? box_sweep4h(p, A) : box_sweep4v(p, A); break;
    case 5: h ? box_sweep5h(p, A) : box_sweep5v(p, A); break;
    default: h ? box_sweep6h(p, A) : box_sweep6v(p, A); break;
    }
}

/* Box, vertical: strip of L <= V_LANES floats (any channels), rows 0..n-1 of `in` (`stride`
 * floats apart), output rows o0..o1-1 to out (row o0 at `out`, `ostride` apart). */
static void box_vertical(const blur_plan *p, const float *in, size_t stride, int n, int o0, int o1,
                         float *out, size_t ostride, int L, v4d *scratch)
{
    box_args A;
    A.NV = BOX_V_NV;
    A.groups = (L + 3) / 4;
    for (int v = 0; v < A.groups; v++) {
        A.in[v] = in + 4 * v;
        A.out[v] = out + 4 * v;
        A.k[v] = L - 4 * v < 4 ? L - 4 * v : 4;
    }
    A.istep = stride;
    A.ostep = (ptrdiff_t)ostride;
    A.n = n, A.o0 = o0, A.o1 = o1;
    A.L = L;
    box_run(p, &A, 0, scratch);
}

/* Box, horizontal, RGBA: H_ROWS rows at once (as deriche_rows4: in[r] row r at column sx0,
 * out[r] row r at column sx0, NULL rows absent and last). */
static void box_rows4(const blur_plan *p, const float *const *in, float *const *out, int n, int o0,
                      int o1, v4d *scratch)
{
    box_args A;
    A.NV = H_ROWS;
    A.groups = 0;
    for (int r = 0; r < H_ROWS && out[r]; r++) {
        A.in[r] = in[r];
        A.out[r] = out[r] + (size_t)o0 * 4;
        A.k[r] = 4;
        A.groups++;
    }
    A.istep = 4;
    A.ostep = 4;
    A.n = n, A.o0 = o0, A.o1 = o1;
    A.L = 4 * A.groups;
    box_run(p, &A, 1, scratch);
}

/* v4d of scratch box_vertical (NV = BOX_V_NV) / box_rows4 (NV = H_ROWS) need. */
static size_t box_scratch_v4d(const blur_plan *p, int NV)
{
    /* rings, S, last, xin + xout (2 x BOX_BLOCK x 4 NV floats = BOX_BLOCK x NV v4d) */
    return ((size_t)p->passes * ((size_t)p->ring + 1) + 1 + BOX_BLOCK) * (size_t)NV;
}

/* Vertical pass: strips of columns [c, c + L) (in floats) of rows sy0..sy1-1 -> vbuf rows
 * oy0..oy1-1. */
static void vertical_range(void *user, int begin, int end, int worker)
{
    blur_job *j = user;
    const int C = j->channels;
    const size_t row = (size_t)j->width * C;
    const int n = j->sy1 - j->sy0;
    const int c_first = j->sx0 * C, c_end = j->sx1 * C;
    const int Lmax = j->strip_lanes;
    const int ext = j->plan->ext;
    double *A = worker_scratch(j, worker);
    for (int strip = begin; strip < end; strip++) {
        int c0 = c_first + strip * Lmax;
        int L = c_end - c0 < Lmax ? c_end - c0 : Lmax;
        if (j->fast_v && j->plan->alg == FX_BLUR_BOX) {
            box_vertical(j->plan, j->src + (size_t)j->sy0 * row + c0, row, n, j->oy0 - j->sy0,
                         j->oy1 - j->sy0, j->vorigin + c0, j->vstride, L, (v4d *)A);
            continue;
        }
        if (j->fast_v && j->use_float) {
            float *xs = (float *)A, *cb = xs + ((size_t)n + 3) * Lmax;
            if (derf_vertical(&j->plan->sec, j->src + (size_t)j->sy0 * row + c0, row, n, j->oy0 - j->sy0,
                              j->oy1 - j->sy0, j->vorigin + c0, j->vstride, L, xs, cb))
                continue;
            atomic_store(&j->fallback, 1);
        }
        if (j->fast_v) {
            v4d *st = (v4d *)A, *cb = st + 5 * (size_t)(Lmax / 4);
            float *xs = (float *)(cb + (size_t)(j->oy1 - j->oy0) * (Lmax / 4));
            deriche_vertical(j->plan, j->src + (size_t)j->sy0 * row + c0, row, n, j->oy0 - j->sy0,
                             j->oy1 - j->sy0, j->vorigin + c0, j->vstride, L, cb, st, xs);
            continue;
        }
        size_t lb = ((size_t)n + 2 * (size_t)ext) * (size_t)Lmax;
        double *a = A + (size_t)ext * L, *b = A + lb + (size_t)ext * L, *s = A + 2 * lb;
        for (int i = 0; i < n; i++) {
            const float *restrict in = j->src + (size_t)(j->sy0 + i) * row + c0;
            double *restrict o = a + (size_t)i * L;
            if (i + 8 < n)
                __builtin_prefetch(in + 8 * row);
            for (int l = 0; l < L; l++)
                o[l] = in[l];
        }
        const double *res = filter_lanes(j->plan, a, b, n, L, s);
        for (int y = j->oy0; y < j->oy1; y++) {
            const double *restrict v = res + (size_t)(y - j->sy0) * L;
            float *restrict o = j->vorigin + (size_t)(y - j->oy0) * j->vstride + c0;
            for (int l = 0; l < L; l++)
                o[l] = to_float_clamped(v[l]);
        }
    }
}

/* Horizontal pass: blocks of block_rows rows of vbuf -> dst, columns sx0..sx1-1 computed,
 * ox0..ox1-1 written. */
static void horizontal_range(void *user, int begin, int end, int worker)
{
    blur_job *j = user;
    const int C = j->channels;
    const size_t row = (size_t)j->width * C;
    const int n = j->sx1 - j->sx0;
    const int R = j->block_rows, Lmax = R * C;
    const int rows = j->oy1 - j->oy0;
    const int ext = j->plan->ext;
    const int float_h = j->use_float && !atomic_load(&j->fallback);
    double *A = worker_scratch(j, worker);
    for (int blk = begin; blk < end; blk++) {
        int r0 = blk * R;
        int nr = rows - r0 < R ? rows - r0 : R;
        if (float_h && !j->fast_h) { /* 1-3 channels: rows gathered x-major, float lanes */
            const int L = nr * C;
            float *xa = (float *)A, *ya = xa + ((size_t)n + 2) * L, *st = ya + (size_t)n * L;
            for (int r = 0; r < nr; r++) {
                const float *restrict in = j->vorigin + (size_t)(r0 + r) * j->vstride + (size_t)j->sx0 * C;
                for (int i = 0; i < n; i++)
                    for (int c = 0; c < C; c++)
                        xa[(size_t)i * L + r * C + c] = in[(size_t)i * C + c];
            }
            if (derf_lanes(&j->plan->sec, xa, ya, n, L, st)) { /* always: the vertical pass checked */
                for (int r = 0; r < nr; r++) {
                    float *restrict o = j->dst + (size_t)(j->oy0 + r0 + r) * row + (size_t)j->ox0 * C;
                    const float *restrict v = ya + (size_t)(j->ox0 - j->sx0) * L + r * C;
                    for (int x = 0; x < j->ox1 - j->ox0; x++)
                        for (int c = 0; c < C; c++)
                            o[(size_t)x * C + c] = v[(size_t)x * L + c];
                }
                continue;
            }
        }
        if (j->fast_h) {
            const float *in[H_ROWS];
            float *out[H_ROWS];
            for (int r = 0; r < H_ROWS; r++) {
                int rr = r < nr ? r : 0;
                in[r] = j->vorigin + (size_t)(r0 + rr) * j->vstride + (size_t)j->sx0 * 4;
                out[r] = r < nr ? j->dst + (size_t)(j->oy0 + r0 + r) * row + (size_t)j->sx0 * 4 : NULL;
            }
            if (j->plan->alg == FX_BLUR_BOX)
                box_rows4(j->plan, in, out, n, j->ox0 - j->sx0, j->ox1 - j->sx0, (v4d *)A);
            else if (float_h)
                derf_rows4(&j->plan->sec, in, out, n, j->ox0 - j->sx0, j->ox1 - j->sx0, (float *)A);
            else
                deriche_rows4(j->plan, in, out, n, j->ox0 - j->sx0, j->ox1 - j->sx0, (v4d *)A);
            continue;
        }
        int L = nr * C;
        size_t lb = ((size_t)n + 2 * (size_t)ext) * (size_t)Lmax;
        double *a = A + (size_t)ext * L, *b = A + lb + (size_t)ext * L, *s = A + 2 * lb;
        for (int r = 0; r < nr; r++) {
            const float *restrict in = j->vorigin + (size_t)(r0 + r) * j->vstride + (size_t)j->sx0 * C;
            double *restrict o = a + r * C;
            if (C == 4)
                for (int i = 0; i < n; i++)
                    for (int c = 0; c < 4; c++)
                        o[(size_t)i * L + c] = in[(size_t)i * 4 + c];
            else
                for (int i = 0; i < n; i++)
                    for (int c = 0; c < C; c++)
                        o[(size_t)i * L + c] = in[(size_t)i * C + c];
        }
        const double *res = filter_lanes(j->plan, a, b, n, L, s);
        for (int r = 0; r < nr; r++) {
            float *restrict o = j->dst + (size_t)(j->oy0 + r0 + r) * row + (size_t)j->ox0 * C;
            const double *restrict v = res + (size_t)(j->ox0 - j->sx0) * L + r * C;
            if (C == 4)
                for (int x = 0; x < j->ox1 - j->ox0; x++)
                    for (int c = 0; c < 4; c++)
                        o[(size_t)x * 4 + c] = to_float_clamped(v[(size_t)x * L + c]);
            else
                for (int x = 0; x < j->ox1 - j->ox0; x++)
                    for (int c = 0; c < C; c++)
                        o[(size_t)x * C + c] = to_float_clamped(v[(size_t)x * L + c]);
        }
    }
}

static void copy_roi(const float *src, float *dst, int width, int channels, const fx_rect *r)
{
    if (src == dst)
        return;
    size_t row = (size_t)width * channels;
    for (int y = r->y0; y < r->y1; y++)
        memcpy(dst + y * row + (size_t)r->x0 * channels, src + y * row + (size_t)r->x0 * channels,
               (size_t)(r->x1 - r->x0) * channels * sizeof(float));
}

static int clampi(int v, int lo, int hi)
{
    return v < lo ? lo : v > hi ? hi : v;
}

#ifndef FX_BLUR_FAST
#  define FX_BLUR_FAST 1 /* 0: every algorithm through the lane kernels (for comparisons) */
#endif

fx_result fx_blur_image(fx_context *ctx, const float *src, float *dst, int width, int height,
                        int channels, const fx_blur_spec *spec, const fx_rect *roi,
                        const char *where)
{
    return fx_blur_image_finite(ctx, src, dst, width, height, channels, spec, roi, where, NULL);
}

/* Scratch bytes per worker, enough for both passes and for the double fallback of the
 * float kernels (rounded up to whole cache lines). */
static size_t scratch_per_worker(const blur_job *j, const fx_rect *r)
{
    const blur_plan *plan = j->plan;
    const int channels = j->channels;
    const size_t d = sizeof(double);
    size_t nv = (size_t)(j->sy1 - j->sy0), nh = (size_t)(j->sx1 - j->sx0), ext = (size_t)plan->ext;
    size_t sv, sh;
    if (j->fast_v && plan->alg == FX_BLUR_BOX)
        sv = box_scratch_v4d(plan, BOX_V_NV) * sizeof(v4d);
    else if (j->fast_v)
        sv = (5 + (size_t)(r->y1 - r->y0)) * j->strip_lanes * d + (nv + 7) * j->strip_lanes * sizeof(float);
    else
        sv = (2 * (nv + 2 * ext) * (size_t)j->strip_lanes + lane_state_doubles(plan, j->strip_lanes)) * d;
    size_t Lh = (size_t)j->block_rows * channels;
    if (j->fast_h && plan->alg == FX_BLUR_BOX)
        sh = box_scratch_v4d(plan, H_ROWS) * sizeof(v4d);
    else if (j->fast_h)
        sh = (size_t)(r->x1 - r->x0) * H_ROWS * sizeof(v4d);
    else
        sh = (2 * (nh + 2 * ext) * Lh + lane_state_doubles(plan, (int)Lh)) * d;
    if (j->use_float) { /* the float kernels' buffers (the double ones stay for the fallback) */
        size_t fv = ((nv + 3) + (size_t)(r->y1 - r->y0)) * j->strip_lanes * sizeof(float);
        size_t fh = j->fast_h ? (size_t)(r->x1 - r->x0) * 4 * HF_ROWS * sizeof(float)
                              : ((nh + 2) + nh + 8) * Lh * sizeof(float);
        sv = sv > fv ? sv : fv;
        sh = sh > fh ? sh : fh;
    }
    return round_up64(sv > sh ? sv : sh);
}

fx_result fx_blur_image_finite(fx_context *ctx, const float *src, float *dst, int width, int height,
                               int channels, const fx_blur_spec *spec, const fx_rect *roi,
                               const char *where, int *finite)
{
    if (finite)
        *finite = 0;
    if (!where)
        where = "blur";
    if (!src || !dst || !spec || width <= 0 || height <= 0 || channels < 1 || channels > 4)
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "%s: bad blur arguments", where);
    fx_rect r = { 0, 0, width, height };
    if (roi) {
        r.x0 = clampi(roi->x0, 0, width);
        r.x1 = clampi(roi->x1, r.x0, width);
        r.y0 = clampi(roi->y0, 0, height);
        r.y1 = clampi(roi->y1, r.y0, height);
    }
    if (r.x0 >= r.x1 || r.y0 >= r.y1)
        return FX_OK;
    blur_plan plan;
    if (plan_init(&plan, spec) != FX_OK)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the blur kernel (sigma %g)",
                       where, spec->sigma);
    if (plan.identity) {
        copy_roi(src, dst, width, channels, &r);
        return FX_OK;
    }
    const int H = plan.halo;
    blur_job job, *j = &job;
    memset(j, 0, sizeof *j);
    j->plan = &plan;
    j->src = src;
    j->dst = dst;
    j->width = width;
    j->height = height;
    j->channels = channels;
    j->ox0 = r.x0, j->ox1 = r.x1, j->oy0 = r.y0, j->oy1 = r.y1;
    /* Halo growth in 64-bit: H can be large. */
    j->sx0 = (int)((long long)r.x0 - H < 0 ? 0 : (long long)r.x0 - H);
    j->sx1 = (int)((long long)r.x1 + H > width ? width : (long long)r.x1 + H);
    j->sy0 = (int)((long long)r.y0 - H < 0 ? 0 : (long long)r.y0 - H);
    j->sy1 = (int)((long long)r.y1 + H > height ? height : (long long)r.y1 + H);
    j->fast_v = FX_BLUR_FAST && (plan.alg == FX_BLUR_RECURSIVE || plan.alg == FX_BLUR_BOX);
    j->fast_h = j->fast_v && channels == 4;
    j->use_float = plan.alg == FX_BLUR_RECURSIVE && plan.use_float;
    atomic_init(&j->fallback, 0);
    j->strip_lanes = j->fast_v && plan.alg == FX_BLUR_RECURSIVE ? (j->use_float ? V_LANES_F : V_LANES_REC) : V_LANES;
    j->block_rows = j->fast_h ? H_ROWS : (H_LANES / channels < 1 ? 1 : H_LANES / channels);

    const int workers = fx_parallel_workers(ctx);
    j->scratch_bytes = scratch_per_worker(j, &r);
    size_t nh = (size_t)(j->sx1 - j->sx0);

    /* The vertical result goes straight to dst when the computed columns are the written
     * ones (a full-width roi: the usual case), else to a buffer of the roi's rows. */
    fx_result res = FX_OK;
    float *tmp = NULL;
    size_t tmp_bytes = 0, scratch_total;
    if (!fx_size_mul(&scratch_total, j->scratch_bytes, (size_t)workers, 1) ||
        !fx_size_mul(&tmp_bytes, (size_t)(r.y1 - r.y0), nh * channels, sizeof(float))) {
        plan_free(&plan);
        return fx_fail(ctx, FX_ERR_LIMIT, "%s: blur buffer size overflows", where);
    }
    int direct = j->sx0 == j->ox0 && j->sx1 == j->ox1;
    if (direct)
        tmp_bytes = 0;
    res = fx_check_budget(ctx, tmp_bytes + scratch_total, where);
    if (res != FX_OK)
        goto out;
    /* 1080p at 2 workers: 1.7 MB, one huge page (a single first-touch fault, not ~280) */
    void *scratch_raw = fx_mem_alloc_whole(scratch_total + 64);
    if (!scratch_raw || (!direct && !(tmp = fx_mem_alloc(tmp_bytes)))) {
        fx_mem_free(scratch_raw);
        scratch_raw = NULL;
        res = fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for blur buffers (%zu bytes)",
                      where, tmp_bytes + scratch_total);
        goto out;
    }
    j->scratch = (char *)(((uintptr_t)scratch_raw + 63) & ~(uintptr_t)63);
    if (direct) {
        j->vstride = (size_t)width * channels;
        j->vorigin = dst + (size_t)r.y0 * j->vstride;
    } else {
        j->vstride = nh * channels;
        j->vorigin = tmp - (size_t)j->sx0 * channels;
    }
    int cols = (j->sx1 - j->sx0) * channels;
    int strips = (cols + j->strip_lanes - 1) / j->strip_lanes;
    fx_parallel_for_worker(ctx, strips, fx_grain_for(ctx, strips), vertical_range, j);
    int blocks = (r.y1 - r.y0 + j->block_rows - 1) / j->block_rows;
    fx_parallel_for_worker(ctx, blocks, fx_grain_for(ctx, blocks), horizontal_range, j);
    if (finite)
        *finite = j->use_float && !atomic_load(&j->fallback);
    fx_mem_free(scratch_raw);
out:
    fx_mem_free(tmp);
    plan_free(&plan);
    return res;
}

fx_result fx_blur_line(fx_context *ctx, const float *in, float *out, int n, int stride,
                       const fx_blur_spec *spec, const char *where)
{
    if (!where)
        where = "blur";
    if (!in || !out || !spec || n <= 0 || stride < 1)
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "%s: bad blur arguments", where);
    blur_plan plan;
    if (plan_init(&plan, spec) != FX_OK)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the blur kernel", where);
    if (plan.identity) {
        if (in != out)
            for (int i = 0; i < n; i++)
                out[(size_t)i * stride] = in[(size_t)i * stride];
        return FX_OK;
    }
    if (plan.alg == FX_BLUR_RECURSIVE && plan.use_float) {
        float *fb = fx_mem_alloc(((size_t)n * 2 + 2 + 8) * sizeof(float));
        if (!fb) {
            plan_free(&plan);
            return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where);
        }
        float *y = fb + (size_t)n + 2;
        for (int i = 0; i < n; i++)
            fb[i] = in[(size_t)i * stride];
        int done = derf_lanes(&plan.sec, fb, y, n, 1, y + n);
        if (done)
            for (int i = 0; i < n; i++)
                out[(size_t)i * stride] = y[i];
        fx_mem_free(fb);
        if (done) {
            plan_free(&plan);
            return FX_OK;
        }
    }
    double *A = lane_buffer(n, 1, plan.ext), *Bf = lane_buffer(n, 1, plan.ext);
    double *s = fx_mem_alloc(lane_state_doubles(&plan, 1) * sizeof(double));
    if (!A || !Bf || !s) {
        fx_mem_free(A);
        fx_mem_free(Bf);
        fx_mem_free(s);
        plan_free(&plan);
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where);
    }
    double *a = A + plan.ext, *b = Bf + plan.ext;
    for (int i = 0; i < n; i++)
        a[i] = in[(size_t)i * stride];
    const double *res = filter_lanes(&plan, a, b, n, 1, s);
    for (int i = 0; i < n; i++)
        out[(size_t)i * stride] = to_float_clamped(res[i]);
    fx_mem_free(A);
    fx_mem_free(Bf);
    fx_mem_free(s);
    plan_free(&plan);
    return FX_OK;
}

/* ---- small 2-D convolution ------------------------------------------------------------- */

typedef struct conv_job {
    const float *src;
    float *dst;
    int width, height, channels;
    const double *kernel;
    int ksize;
    fx_rect roi;
    atomic_int failed;
} conv_job;

FX_CLONES
static void conv_rows(void *user, int begin, int end)
{
    conv_job *j = user;
    const int C = j->channels, h = j->ksize / 2, W = j->width;
    const int rw = j->roi.x1 - j->roi.x0;
    const size_t row = (size_t)W * C;
    double *acc = fx_mem_alloc((size_t)rw * C * sizeof(double));
    double *pad = fx_mem_alloc(((size_t)rw + 2 * h) * C * sizeof(double));
    if (!acc || !pad) {
        atomic_store(&j->failed, 1);
        fx_mem_free(acc);
        fx_mem_free(pad);
        return;
    }
    for (int y = j->roi.y0 + begin; y < j->roi.y0 + end; y++) {
        memset(acc, 0, (size_t)rw * C * sizeof(double));
        for (int ky = 0; ky < j->ksize; ky++) {
            int ys = clampi(y + ky - h, 0, j->height - 1);
            const float *in = j->src + (size_t)ys * row;
            for (int i = 0; i < rw + 2 * h; i++) {
                int xs = clampi(j->roi.x0 + i - h, 0, W - 1);
                for (int c = 0; c < C; c++)
                    pad[(size_t)i * C + c] = in[(size_t)xs * C + c];
            }
            for (int kx = 0; kx < j->ksize; kx++) {
                const double w = j->kernel[ky * j->ksize + kx];
                const double *restrict p = pad + (size_t)kx * C;
                double *restrict a = acc;
                for (int i = 0; i < rw * C; i++)
                    a[i] += w * p[i];
            }
        }
        float *o = j->dst + (size_t)y * row + (size_t)j->roi.x0 * C;
        for (int i = 0; i < rw * C; i++)
            o[i] = to_float_clamped(acc[i]);
    }
    fx_mem_free(acc);
    fx_mem_free(pad);
}

fx_result fx_convolve_2d(fx_context *ctx, const float *src, float *dst, int width, int height,
                         int channels, const double *kernel, int ksize, const fx_rect *roi,
                         const char *where)
{
    if (!where)
        where = "convolve";
    if (!src || !dst || src == dst || !kernel || width <= 0 || height <= 0 || channels < 1 ||
        channels > 4 || ksize < 1 || ksize > 15 || ksize % 2 == 0)
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "%s: bad convolution arguments", where);
    conv_job *j = fx_mem_calloc(1, sizeof *j);
    if (!j)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where);
    j->src = src;
    j->dst = dst;
    j->width = width;
    j->height = height;
    j->channels = channels;
    j->kernel = kernel;
    j->ksize = ksize;
    j->roi = (fx_rect){ 0, 0, width, height };
    if (roi) {
        j->roi.x0 = clampi(roi->x0, 0, width);
        j->roi.x1 = clampi(roi->x1, j->roi.x0, width);
        j->roi.y0 = clampi(roi->y0, 0, height);
        j->roi.y1 = clampi(roi->y1, j->roi.y0, height);
    }
    atomic_init(&j->failed, 0);
    int rows = j->roi.y1 - j->roi.y0;
    fx_result res = FX_OK;
    if (rows > 0 && j->roi.x1 > j->roi.x0) {
        fx_parallel_for(ctx, rows, fx_grain_for(ctx, rows), conv_rows, j);
        if (atomic_load(&j->failed))
            res = fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for convolution rows", where);
    }
    fx_mem_free(j);
    return res;
}
