/* bloom: a bright pass (the seed's middle-grey/white-point pass, or a soft-knee threshold),
 * a 2x downsample pyramid whose levels are blurred (math/blur.h) and summed back up with
 * tent upsampling, composited by add or screen. docs/effects/bloom.md.
 *
 * Energy: 2x2 box downsampling, blur and tent upsampling each keep the mean (up to the
 * replicated borders), and the pyramid's L levels are summed with weights 1/L, so the bloom
 * buffer carries the bright pass's energy spread out, and the bright pass never exceeds the
 * pixel (contribution in [0, 1]): the energy added is at most intensity x the image's. */
#include "core/effect.h"
#include "core/parallel.h"
#include "math/blur.h"
#include "math/color.h"
#include "core/simd4.h"
#include "core/simd8.h"
#include "math/clones.h"

#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

/* GCC vector extensions: one RGBA pixel per v4f (SSE2 in the baseline build), only inside
 * inline helpers and the row loops. */

typedef struct bloom_params {
    int mode;
    float threshold, knee, clamp_value;
    float middle_grey, scene_luminance;
    float radius;
    float level_sigma;
    float intensity;
    int composite;
    int fine_level;
} bloom_params;

enum { MODE_SOFT_KNEE = 0, MODE_SEED };
enum { COMP_ADD = 0, COMP_SCREEN };
enum { FINE_FULL = 0, FINE_FAST, FINE_COARSE };
#define MAX_LEVELS 16

static const char *const mode_items[] = { "soft_knee", "seed" };
static const char *const comp_items[] = { "add", "screen" };
static const char *const fine_items[] = { "full", "fast", "coarse" };

static const fx_param_def bloom_param_defs[] = {
    FX_P_ENUM(bloom_params, mode, "mode", MODE_SOFT_KNEE, mode_items,
              "soft_knee: colour x max(soft, b - threshold) / b with b the brightest channel and a "
              "quadratic knee; seed: colour *= middle_grey / scene luminance; colour *= 1 + colour / "
              "threshold^2; colour -= 0.5 (floored at 0); colour /= 1 + colour"),
    FX_P_FLOAT(bloom_params, threshold, "threshold", 1.0, 0.0, 65504.0, 0.0, 10.0, "",
               "soft_knee: brightness where bloom starts; seed: the white point"),
    FX_P_FLOAT(bloom_params, knee, "knee", 0.5, 0.0, 1.0, 0.0, 1.0, "factor",
               "soft_knee: knee width as a fraction of the threshold (0: hard cut)"),
    FX_P_FLOAT(bloom_params, clamp_value, "clamp", 65504.0, 0.0, 3.0e38, 1.0, 65504.0, "",
               "Channels are clamped to this before the bright pass (tames fireflies)"),
    FX_P_FLOAT(bloom_params, middle_grey, "middle_grey", 0.18, 0.0, 100.0, 0.0, 1.0, "",
               "seed: the key the scene luminance is scaled to"),
    FX_P_FLOAT(bloom_params, scene_luminance, "scene_luminance", 0.0, 0.0, 65504.0, 0.0, 10.0, "",
               "seed: the scene's luminance; 0: measured (log-average of the frame)"),
    FX_P_FLOAT(bloom_params, radius, "radius", 64.0, 0.0, 65536.0, 0.0, 512.0, "pixels",
               "Reach of the glow: the pyramid has floor(log2(radius)) levels (clamped to the image); "
               "below 2 there is no spread"),
    FX_P_FLOAT(bloom_params, level_sigma, "level_sigma", 1.25, 0.0, 8.0, 0.5, 3.0, "texels",
               "Gaussian sigma of each level's blur, in that level's pixels (smoothness)"),
    FX_P_FLOAT(bloom_params, intensity, "intensity", 0.5, 0.0, 100.0, 0.0, 2.0, "",
               "Strength of the glow; 0 is the identity"),
    FX_P_ENUM(bloom_params, composite, "composite", COMP_ADD, comp_items,
              "add: colour + glow; screen (the seed's): colour + glow x (1 - min(colour, 1))"),
    FX_P_ENUM(bloom_params, fine_level, "fine_level", FINE_FULL, fine_items,
              "The half-resolution level (a quality knob): full: the bright pass of every pixel, "
              "averaged 2x2, then blurred; fast: the bright pass of each 2x2 average, not blurred "
              "(about a third of bloom's work; the finest glow is a little less smooth); coarse: as "
              "fast, but the half-resolution level is never stored: the quarter-resolution level is "
              "made straight from the frame, carries the finest level's share of the glow too, and "
              "is interpolated to full size (the draft: cheapest, the glow a little wider)"),
};

typedef struct level {
    int w, h;
    float *px; /* RGBA (A unused, 0) */
} level;

typedef struct bloom_job {
    const fx_effect_run *run;
    const bloom_params *p;
    float exposure; /* seed: middle_grey / scene luminance */
    float inv_4k;   /* soft knee: 1 / (4 knee + 1e-5) */
    int *tx[2];     /* tent upsampling taps per fine column (a, b) for the level being read */
    level lv[MAX_LEVELS + 1];
    int nlev;
    int from, to;   /* the levels a step reads and writes */
    int coarse;     /* fine_level coarse with at least 2 levels: level 1 is not stored */
    float self;     /* up_rows: level `to` = self x itself + the upsampled level `from` */
    int *cx;        /* coarse composite: left tap of each full-resolution column */
    float *cw;      /* and its weight towards the right tap */
    double *row_sums;
} bloom_job;

static inline float clamp_in(float v, float hi)
{
    return v > 0.0f ? (v < hi ? v : hi) : 0.0f; /* NaN -> 0 */
}

/* The bright pass of one pixel (rgb finite, >= 0 after clamping); out[3] = 0. */
static inline v4f bright4(const bloom_job *j, const float *s)
{
    const bloom_params *p = j->p;
    const float cv = p->clamp_value;
    v4f c = ld4(s);
    c = clamp4_pos(c, V4(cv)); /* NaN -> 0 */
    c[3] = 0.0f;
    if (p->mode == MODE_SOFT_KNEE) {
        float b = c[0] > c[1] ? c[0] : c[1];
        b = b > c[2] ? b : c[2];
        const float t = p->threshold, k = t * p->knee + 1e-5f;
        float soft = b - t + k;
        soft = soft > 0.0f ? (soft < 2.0f * k ? soft : 2.0f * k) : 0.0f;
        soft = soft * soft * j->inv_4k;
        float hard = b - t;
        float contrib = (soft > hard ? soft : hard) / (b > 1e-5f ? b : 1e-5f);
        contrib = contrib > 0.0f ? (contrib < 1.0f ? contrib : 1.0f) : 0.0f;
        return c * V4(contrib);
    }
    double t2 = (double)p->threshold * p->threshold;
    t2 = t2 > 1e-12 ? t2 : 1e-12;
    v4f o = V4(0.0f);
    for (int k2 = 0; k2 < 3; k2++) {
        double x = (double)c[k2] * j->exposure;
        x = x * (1.0 + x / t2);
        x -= 0.5;
        x = x > 0.0 ? x : 0.0;
        o[k2] = (float)(x < 1e300 ? x / (1.0 + x) : 1.0); /* < 1, finite */
    }
    return o;
}

static void luminance_rows(void *user, int begin, int end)
{
    bloom_job *j = user;
    const fx_effect_run *run = j->run;
    for (int y = begin; y < end; y++) {
        const float *s = run->src + (size_t)y * run->width * 4;
        double acc = 0.0;
        for (int x = 0; x < run->width; x++) {
            float l = fx_luminance(clamp_in(s[4 * x], j->p->clamp_value), clamp_in(s[4 * x + 1], j->p->clamp_value),
                                   clamp_in(s[4 * x + 2], j->p->clamp_value));
            acc += log(1e-6 + (double)l);
        }
        j->row_sums[y] = acc;
    }
}

/* fine_level fast's level-1 texel from the source's 2x2 block (rows r0, r1, columns x0, x1):
 * the bright pass of the block's mean (inputs clamped first: NaN -> 0). */
static inline v4f fast_texel(const bloom_job *j, const float *r0, const float *r1, int x0, int x1)
{
    const float cv = j->p->clamp_value;
    v4f a0 = ld4(r0 + 4 * x0), a1 = ld4(r0 + 4 * x1), a2 = ld4(r1 + 4 * x0), a3 = ld4(r1 + 4 * x1);
#define CL(v) v = clamp4_pos(v, V4(cv))
    CL(a0);
    CL(a1);
    CL(a2);
    CL(a3);
#undef CL
    float m[4];
    st4(m, ((a0 + a1) + (a2 + a3)) * V4(0.25f));
    v4f acc = bright4(j, m) * V4(4.0f) * V4(0.25f); /* as down_rows: x 4, then its 0.25 */
    acc[3] = 0.0f;
    return acc;
}

/* fine_level coarse: level 2 straight from the source: the bright pass of each 4x4 block's
 * mean (inputs clamped first: NaN -> 0; rows and columns past the edge replicated, as the
 * 2x2 steps do). One bright pass per 16 pixels: the frame is read once, at memory speed.
 * Blocks inside the frame take two pixels per 8-lane vector (down2_inner, cloned). */
static inline __attribute__((always_inline)) v8f clamp8_pos(v8f v, v8f hi)
{
    v = (v8f)((v8i)v & (v > S8(0.0f))); /* NaN, <= 0 -> +0 */
    return SEL8(v < hi, v, hi);
}

/* The 4x4 block sums of texels [0, n) of one level-2 row (n blocks fully inside the
 * frame's columns), rows r[0..3], into sum (RGBA per texel). */
FX_CLONES
static void down2_inner(const float *const r[4], int n, float cv, float *restrict sum)
{
    const v8f hi = S8(cv);
    for (int x = 0; x < n; x++) {
        const size_t o = 16 * (size_t)x;
        v8f acc = S8(0.0f);
        for (int k = 0; k < 4; k++)
            acc += clamp8_pos(fx_load8(r[k] + o), hi) + clamp8_pos(fx_load8(r[k] + o + 8), hi);
        float t[8];
        memcpy(t, &acc, sizeof t);
        for (int c = 0; c < 4; c++)
            sum[4 * (size_t)x + c] = t[c] + t[4 + c];
    }
}

static void down2_rows(void *user, int begin, int end)
{
    const bloom_job *j = user;
    const fx_effect_run *run = j->run;
    const int sw = run->width, sh = run->height;
    const level *d = &j->lv[2];
    const float cv = j->p->clamp_value;
    const int inner = sw / 4 < d->w ? sw / 4 : d->w; /* blocks with all four columns inside */
    for (int y = begin; y < end; y++) {
        const float *r[4];
        for (int k = 0; k < 4; k++) {
            int sy = 4 * y + k < sh ? 4 * y + k : sh - 1;
            r[k] = run->src + (size_t)sy * sw * 4;
        }
        float *o = d->px + (size_t)y * d->w * 4;
        down2_inner(r, inner, cv, o); /* block sums, then their bright pass in place */
        for (int x = 0; x < d->w; x++) {
            v4f acc;
            if (x < inner) {
                acc = ld4(o + 4 * (size_t)x);
            } else {
                int c[4];
                for (int k = 0; k < 4; k++)
                    c[k] = 4 * (4 * x + k < sw ? 4 * x + k : sw - 1);
                v4f lo = V4(0.0f), hi = V4(0.0f); /* as down2_inner's two halves */
                for (int k = 0; k < 4; k++) {
                    v4f a0 = ld4(r[k] + c[0]), a1 = ld4(r[k] + c[1]), a2 = ld4(r[k] + c[2]), a3 = ld4(r[k] + c[3]);
#define CL(v) v = clamp4_pos(v, V4(cv))
                    CL(a0);
                    CL(a1);
                    CL(a2);
                    CL(a3);
#undef CL
                    lo += a0 + a2;
                    hi += a1 + a3;
                }
                acc = lo + hi;
            }
            float m[4];
            st4(m, acc * V4(1.0f / 16.0f));
            acc = bright4(j, m);
            acc[3] = 0.0f;
            st4(o + 4 * (size_t)x, acc);
        }
    }
}

/* Level `to` from level `from` (from == 0: the source through the bright pass, fused). */
static void down_rows(void *user, int begin, int end)
{
    const bloom_job *j = user;
    const fx_effect_run *run = j->run;
    const int sw = j->from == 0 ? run->width : j->lv[j->from].w;
    const int sh = j->from == 0 ? run->height : j->lv[j->from].h;
    const level *d = &j->lv[j->to];
    const float *base = j->from == 0 ? run->src : j->lv[j->from].px;
    for (int y = begin; y < end; y++) {
        const int y0 = 2 * y, y1 = 2 * y + 1 < sh ? 2 * y + 1 : sh - 1;
        const float *r0 = base + (size_t)y0 * sw * 4, *r1 = base + (size_t)y1 * sw * 4;
        float *o = d->px + (size_t)y * d->w * 4;
        for (int x = 0; x < d->w; x++) {
            const int x0 = 2 * x, x1 = 2 * x + 1 < sw ? 2 * x + 1 : sw - 1;
            v4f acc;
            if (j->from == 0 && j->p->fine_level != FINE_FULL) {
                st4(o + 4 * (size_t)x, fast_texel(j, r0, r1, x0, x1));
                continue;
            } else if (j->from == 0)
                acc = (bright4(j, r0 + 4 * x0) + bright4(j, r0 + 4 * x1)) +
                      (bright4(j, r1 + 4 * x0) + bright4(j, r1 + 4 * x1));
            else
                acc = (ld4(r0 + 4 * x0) + ld4(r0 + 4 * x1)) + (ld4(r1 + 4 * x0) + ld4(r1 + 4 * x1));
            acc *= V4(0.25f);
            acc[3] = 0.0f;
            st4(o + 4 * (size_t)x, acc);
        }
    }
}

/* Tent 2x upsampling: fine index i reads coarse i/2 (0.75) and its neighbour toward i (0.25). */
static inline void tent(int i, int n, int *a, int *b)
{
    int c = i >> 1;
    *a = c < n ? c : n - 1;
    int o = (i & 1) ? c + 1 : c - 1;
    *b = o < 0 ? 0 : o >= n ? n - 1 : o;
}

/* Tent taps of every fine column for coarse level c (fine width fw): j->tx[0][x], j->tx[1][x]. */
static void tent_columns(const level *c, int fw, int *ta, int *tb)
{
    for (int x = 0; x < fw; x++)
        tent(x, c->w, &ta[x], &tb[x]);
}

static inline v4f up4(const level *c, const int *ta, const int *tb, int x, const float *ra, const float *rb)
{
    (void)c;
    const int xa = 4 * ta[x], xb = 4 * tb[x];
    return V4(0.5625f) * ld4(ra + xa) + V4(0.1875f) * (ld4(ra + xb) + ld4(rb + xa)) + V4(0.0625f) * ld4(rb + xb);
}

/* level `to` += upsampled level `from` (= to + 1) */
static void up_rows(void *user, int begin, int end)
{
    const bloom_job *j = user;
    const level *c = &j->lv[j->from], *f = &j->lv[j->to];
    for (int y = begin; y < end; y++) {
        int ya, yb;
        tent(y, c->h, &ya, &yb);
        const float *ra = c->px + (size_t)ya * c->w * 4, *rb = c->px + (size_t)yb * c->w * 4;
        float *o = f->px + (size_t)y * f->w * 4;
        if (j->self != 1.0f) {
            const v4f k = V4(j->self);
            for (int x = 0; x < f->w; x++)
                st4(o + 4 * (size_t)x, k * ld4(o + 4 * (size_t)x) + up4(c, j->tx[0], j->tx[1], x, ra, rb));
            continue;
        }
        for (int x = 0; x < f->w; x++)
            st4(o + 4 * (size_t)x, ld4(o + 4 * (size_t)x) + up4(c, j->tx[0], j->tx[1], x, ra, rb));
    }
}

static void composite_rows(void *user, int begin, int end)
{
    const bloom_job *j = user;
    const fx_effect_run *run = j->run;
    const bloom_params *p = j->p;
    const float scale = p->intensity / (float)(j->nlev > 0 ? j->nlev : 1);
    const level *c = &j->lv[1];
    for (int y = run->roi.y0 + begin; y < run->roi.y0 + end; y++) {
        int ya = 0, yb = 0;
        if (j->nlev > 0)
            tent(y, c->h, &ya, &yb);
        const float *ra = j->nlev > 0 ? c->px + (size_t)ya * c->w * 4 : NULL;
        const float *rb = j->nlev > 0 ? c->px + (size_t)yb * c->w * 4 : NULL;
        const float *srow = run->src + (size_t)y * run->width * 4;
        float *drow = run->dst + (size_t)y * run->width * 4;
        if (j->nlev > 0 && p->composite == COMP_ADD) {
            /* the common case in its own loop: no per-pixel tests of the settings */
            const int *ta = j->tx[0], *tb = j->tx[1];
            const v4f sc = { scale, scale, scale, 0.0f }; /* alpha passes */
            for (int x = run->roi.x0; x < run->roi.x1; x++) {
                const v4f s = finite4(ld4(srow + 4 * (size_t)x));
                const v4f g = up4(c, ta, tb, x, ra, rb) * sc;
                st4(drow + 4 * (size_t)x, finite4(s + g));
            }
            continue;
        }
        for (int x = run->roi.x0; x < run->roi.x1; x++) {
            const v4f s = finite4(ld4(srow + 4 * (size_t)x));
            v4f g = j->nlev > 0 ? up4(c, j->tx[0], j->tx[1], x, ra, rb) : bright4(j, srow + 4 * (size_t)x);
            g *= V4(scale);
            g[3] = 0.0f; /* alpha passes */
            v4f o;
            if (p->composite == COMP_ADD) {
                o = s + g;
            } else {
                v4f s01 = sel4(s > V4(0.0f), s, V4(0.0f));
                s01 = sel4(s01 < V4(1.0f), s01, V4(1.0f));
                o = s + g * (V4(1.0f) - s01);
            }
            st4(drow + 4 * (size_t)x, finite4(o));
        }
    }
}

/* fine_level coarse: the glow is level 2 interpolated bilinearly (4x, texel centres
 * aligned). Per row: its two level-2 rows blended (and scaled) into `row2`, each texel
 * stored twice (8 floats); then the composite walks the row four pixels per texel span,
 * two pixels per 8-lane vector (math/clones.h: one AVX2 register in the AVX2 clone): the
 * span's texels a and d = b - a, the glow a + w d with the fixed weights 1/8, 3/8 | 5/8,
 * 7/8 (the same values as the per-pixel formula, which the borders and the ROI's ends
 * use). Every value is the same bits in either clone and for any thread count. */
typedef struct coarse_comp {
    const bloom_job *j;
    float **scratch; /* per worker: level 2's width x 8 floats */
} coarse_comp;

/* dst = finite(finite(src) + glow), screen: glow x (1 - clamp(src, 0, 1)) */
static inline __attribute__((always_inline)) v8f comp8(v8f s, v8f g, int screen)
{
    s = fx_finite8(s);
    if (screen) {
        v8f s01 = SEL8(s > S8(0.0f), s, S8(0.0f));
        s01 = SEL8(s01 < S8(1.0f), s01, S8(1.0f));
        g *= S8(1.0f) - s01;
    }
    return fx_finite8(s + g);
}

static inline __attribute__((always_inline)) v4f comp4(v4f s, v4f g, int screen)
{
    s = finite4(s);
    if (screen) {
        v4f s01 = sel4(s > V4(0.0f), s, V4(0.0f));
        s01 = sel4(s01 < V4(1.0f), s01, V4(1.0f));
        g *= V4(1.0f) - s01;
    }
    return finite4(s + g);
}

/* Pixels [xa, xb) of one row: src, dst point at pixel 0 of the row; row2 holds cw texels,
 * each twice. */
FX_CLONES
static void coarse_row(const int *restrict cx, const float *restrict wt, const float *restrict row2, int cw,
                       const float *src, float *dst, int xa, int xb, int screen) /* dst may be src */
{
    const int last = cw - 1;
    int x = xa;
#define GENERIC(x)                                                                                             \
    do {                                                                                                       \
        const int x0_ = cx[x], x1_ = x0_ < last ? x0_ + 1 : x0_;                                               \
        const v4f a_ = ld4(row2 + 8 * (size_t)x0_);                                                            \
        const v4f g_ = a_ + V4(wt[x]) * (ld4(row2 + 8 * (size_t)x1_) - a_);                                    \
        st4(dst + 4 * (size_t)(x), comp4(ld4(src + 4 * (size_t)(x)), g_, screen));                             \
    } while (0)
    for (; x < xb && (x < 2 || ((x - 2) & 3)); x++)
        GENERIC(x);
    const v8f w01 = { 0.125f, 0.125f, 0.125f, 0.125f, 0.375f, 0.375f, 0.375f, 0.375f };
    const v8f w23 = { 0.625f, 0.625f, 0.625f, 0.625f, 0.875f, 0.875f, 0.875f, 0.875f };
    if (screen) {
        for (int k = (x - 2) >> 2; k < last && x + 4 <= xb; k++, x += 4) {
            const v8f a = fx_load8(row2 + 8 * (size_t)k), d = fx_load8(row2 + 8 * (size_t)k + 8) - a;
            const size_t o = 4 * (size_t)x;
            fx_store8(dst + o, comp8(fx_load8(src + o), a + w01 * d, 1));
            fx_store8(dst + o + 8, comp8(fx_load8(src + o + 8), a + w23 * d, 1));
        }
    } else {
        for (int k = (x - 2) >> 2; k < last && x + 4 <= xb; k++, x += 4) {
            const v8f a = fx_load8(row2 + 8 * (size_t)k), d = fx_load8(row2 + 8 * (size_t)k + 8) - a;
            const size_t o = 4 * (size_t)x;
            fx_store8(dst + o, comp8(fx_load8(src + o), a + w01 * d, 0));
            fx_store8(dst + o + 8, comp8(fx_load8(src + o + 8), a + w23 * d, 0));
        }
    }
    for (; x < xb; x++)
        GENERIC(x);
#undef GENERIC
}

static void composite_coarse_rows(void *user, int begin, int end, int worker)
{
    const coarse_comp *cc = user;
    const bloom_job *j = cc->j;
    const fx_effect_run *run = j->run;
    const bloom_params *p = j->p;
    const level *c = &j->lv[2];
    const float scale = p->intensity / (float)j->nlev;
    const v4f sc = { scale, scale, scale, 0.0f }; /* alpha passes */
    float *row2 = cc->scratch[worker];
    for (int y = run->roi.y0 + begin; y < run->roi.y0 + end; y++) {
        float v = ((float)y + 0.5f) * 0.25f - 0.5f;
        v = v > 0.0f ? (v < (float)(c->h - 1) ? v : (float)(c->h - 1)) : 0.0f;
        const int y0 = (int)v, y1 = y0 + 1 < c->h ? y0 + 1 : y0;
        const v4f ty = V4(v - (float)y0);
        const float *ra = c->px + (size_t)y0 * c->w * 4, *rb = c->px + (size_t)y1 * c->w * 4;
        for (int x = 0; x < c->w; x++) {
            const v4f a = ld4(ra + 4 * (size_t)x);
            const v4f t = (a + ty * (ld4(rb + 4 * (size_t)x) - a)) * sc;
            st4(row2 + 8 * (size_t)x, t);
            st4(row2 + 8 * (size_t)x + 4, t);
        }
        const size_t o = (size_t)y * run->width * 4;
        coarse_row(j->cx, j->cw, row2, c->w, run->src + o, run->dst + o, run->roi.x0, run->roi.x1,
                   p->composite == COMP_SCREEN);
    }
}

static int levels_for(const bloom_params *p, int w, int h)
{
    int n = 0;
    float r = p->radius;
    while (n < MAX_LEVELS && r >= 2.0f && (w > 1 || h > 1)) {
        n++;
        r *= 0.5f;
        w = (w + 1) / 2;
        h = (h + 1) / 2;
    }
    return n;
}

static int bloom_halo(const void *params, int width, int height)
{
    const bloom_params *p = params;
    int n = levels_for(p, width, height);
    double reach = (3.0 * p->level_sigma + 2.0) * ldexp(1.0, n);
    int m = width > height ? width : height;
    return reach < m ? (int)reach : m;
}

/* Zero intensity is the identity: the stack skips the effect. */
static int bloom_identity(const void *params)
{
    const bloom_params *p = params;
    return !(p->intensity > 0.0f);
}

/* mode seed: the exposure taking the scene's luminance (given, or the frame's log-average)
 * to middle grey. */
static fx_result bloom_seed_exposure(const fx_effect_run *run, bloom_job *j)
{
    const bloom_params *p = j->p;
    const int w = run->width, h = run->height;
    double lum = p->scene_luminance;
    if (!(lum > 0.0)) {
        j->row_sums = fx_mem_alloc((size_t)h * sizeof(double));
        if (!j->row_sums)
            return fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", run->where);
        fx_parallel_for(run->ctx, h, fx_grain_for(run->ctx, h), luminance_rows, j);
        double acc = 0.0;
        for (int y = 0; y < h; y++) /* in order: the same sum for any thread count */
            acc += j->row_sums[y];
        fx_mem_free(j->row_sums);
        j->row_sums = NULL;
        lum = exp(acc / ((double)w * h)) - 1e-6;
    }
    lum = lum > 1e-6 ? lum : 1e-6;
    double e = p->middle_grey / lum;
    j->exposure = (float)(e < 1e30 ? e : 1e30);
    return FX_OK;
}

/* The levels' sizes, and where each stored level starts in one block (at[l]); returns the
 * block's size. Every stored level in one block from the context's buffer store: the same
 * size frame after frame, already mapped; and one block of huge pages (core/mem.h) where
 * levels of their own took 4 KiB pages below 2 MiB: a process's first 1080p frame faulted
 * ~680 pages for levels 2-7. Each level starts on a 64-byte boundary; every level is
 * written whole before it is read, so a recycled block's old contents never show. */
static size_t bloom_layout(bloom_job *j, int w, int h, size_t at[MAX_LEVELS + 1])
{
    size_t bytes = 0;
    int lw = w, lh = h;
    for (int l = 1; l <= j->nlev; l++) {
        lw = (lw + 1) / 2;
        lh = (lh + 1) / 2;
        j->lv[l].w = lw;
        j->lv[l].h = lh;
        at[l] = bytes;
        if (!(l == 1 && j->coarse)) /* coarse: level 1 is never stored */
            bytes += ((size_t)lw * lh * 4 * sizeof(float) + 63) & ~(size_t)63;
    }
    return bytes;
}

/* Down the pyramid (the bright pass into level 1, each level halving the one above;
 * coarse: level 2 straight from the frame), then each level blurred in place. */
static fx_result bloom_pyramid_down(const fx_effect_run *run, bloom_job *j)
{
    for (int l = j->coarse ? 2 : 1; l <= j->nlev; l++) {
        j->from = l - 1;
        j->to = l;
        fx_parallel_for(run->ctx, j->lv[l].h, fx_grain_for(run->ctx, j->lv[l].h),
                        l == 2 && j->coarse ? down2_rows : down_rows, j);
    }
    /* extended-box cascade (3 passes): cost independent of sigma, and at the small per-level
     * sigmas (~1.25) several times cheaper than the exact FIR recursive switches to */
    fx_blur_spec spec = { j->p->level_sigma, FX_BLUR_BOX, 3 };
    fx_result r = FX_OK;
    for (int l = j->p->fine_level != FINE_FULL ? 2 : 1; l <= j->nlev && !r; l++)
        r = fx_blur_image(run->ctx, j->lv[l].px, j->lv[l].px, j->lv[l].w, j->lv[l].h, 4, &spec, NULL, run->where);
    return r;
}

/* Up the pyramid: each level plus the tent upsampling of the one below it, coarsest first
 * (j->tx holds the taps). */
static void bloom_pyramid_up(const fx_effect_run *run, bloom_job *j)
{
    /* coarse: level 2 stands in for level 1 too (its own glow counts twice: the same energy) */
    if (j->coarse && j->nlev == 2) {
        float *q = j->lv[2].px;
        for (size_t i = 0, n = (size_t)j->lv[2].w * j->lv[2].h * 4; i < n; i++)
            q[i] *= 2.0f;
    }
    for (int l = j->nlev - 1; l >= (j->coarse ? 2 : 1); l--) {
        j->from = l + 1;
        j->to = l;
        j->self = j->coarse && l == 2 ? 2.0f : 1.0f;
        tent_columns(&j->lv[l + 1], j->lv[l].w, j->tx[0], j->tx[1]);
        fx_parallel_for(run->ctx, j->lv[l].h, fx_grain_for(run->ctx, j->lv[l].h), up_rows, j);
    }
}

/* fine_level coarse: level 2 upsampled 4x straight into the frame (composite_coarse_rows),
 * each worker with a row of scratch. */
static fx_result bloom_composite_coarse(const fx_effect_run *run, bloom_job *j)
{
    const int w = run->width;
    int workers = fx_parallel_workers(run->ctx);
    coarse_comp cc = { j, fx_mem_alloc((size_t)workers * sizeof(float *)) };
    j->cx = fx_mem_alloc((size_t)w * sizeof(int));
    j->cw = fx_mem_alloc((size_t)w * sizeof(float));
    if (cc.scratch)
        memset(cc.scratch, 0, (size_t)workers * sizeof(float *));
    int ok = cc.scratch && j->cx && j->cw;
    for (int k = 0; ok && k < workers; k++)
        ok = (cc.scratch[k] = fx_mem_alloc((size_t)j->lv[2].w * 8 * sizeof(float))) != NULL;
    fx_result r = FX_OK;
    if (ok) {
        for (int x = 0; x < w; x++) {
            float u = ((float)x + 0.5f) * 0.25f - 0.5f;
            u = u > 0.0f ? (u < (float)(j->lv[2].w - 1) ? u : (float)(j->lv[2].w - 1)) : 0.0f;
            j->cx[x] = (int)u;
            j->cw[x] = u - (float)j->cx[x];
        }
        int rows = run->roi.y1 - run->roi.y0;
        fx_parallel_for_worker(run->ctx, rows, fx_grain_for(run->ctx, rows), composite_coarse_rows, &cc);
    } else {
        r = fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", run->where);
    }
    for (int k = 0; cc.scratch && k < workers; k++)
        fx_mem_free(cc.scratch[k]);
    fx_mem_free(cc.scratch);
    return r;
}

static fx_result bloom_process(const fx_effect_run *run)
{
    const bloom_params *p = run->params;
    const int w = run->width, h = run->height;
    const char *where = run->where;
    bloom_job j;
    memset(&j, 0, sizeof j);
    j.run = run;
    j.p = p;
    j.exposure = 1.0f;
    j.inv_4k = 1.0f / (4.0f * (p->threshold * p->knee + 1e-5f) + 1e-5f);
    fx_result r = p->mode == MODE_SEED ? bloom_seed_exposure(run, &j) : FX_OK;
    if (r)
        return r;
    j.nlev = levels_for(p, w, h);
    j.coarse = p->fine_level == FINE_COARSE && j.nlev >= 2;
    j.self = 1.0f;
    size_t at[MAX_LEVELS + 1] = { 0 }, pyramid_capacity = 0;
    const size_t pyramid_bytes = bloom_layout(&j, w, h, at);
    unsigned char *pyramid = NULL;
    if (pyramid_bytes) {
        /* (or a larger idle buffer of the frame: in a stack, a process's first frame then
         * zeroes no fresh 12 MB, which on these VMs took up to ~13 ms of CPU) */
        pyramid = fx_buffer_get_at_least(run->ctx, pyramid_bytes, &pyramid_capacity);
        if (!pyramid)
            return fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the pyramid (%zu bytes)", where,
                           pyramid_bytes);
        for (int l = j.coarse ? 2 : 1; l <= j.nlev; l++)
            j.lv[l].px = (float *)(pyramid + at[l]);
    }
    r = bloom_pyramid_down(run, &j);
    if (!r && j.nlev > 0) {
        j.tx[0] = fx_mem_alloc((size_t)w * sizeof(int));
        j.tx[1] = fx_mem_alloc((size_t)w * sizeof(int));
        if (!j.tx[0] || !j.tx[1])
            r = fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where);
    }
    if (!r)
        bloom_pyramid_up(run, &j);
    if (!r && j.coarse) {
        r = bloom_composite_coarse(run, &j);
    } else if (!r) {
        if (j.nlev > 0)
            tent_columns(&j.lv[1], w, j.tx[0], j.tx[1]);
        int rows = run->roi.y1 - run->roi.y0;
        fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), composite_rows, &j);
    }
    fx_mem_free(j.cx);
    fx_mem_free(j.cw);
    fx_mem_free(j.tx[0]);
    fx_mem_free(j.tx[1]);
    fx_buffer_put(run->ctx, pyramid, pyramid_capacity);
    return r;
}

const fx_effect_class fx_effect_bloom = {
    .name = "bloom",
    .doc = "Bloom: bright pass (soft knee or the seed's), blurred 2x pyramid summed back up, added or screened",
    .params_size = sizeof(bloom_params),
    .params = bloom_param_defs,
    .param_count = FX_COUNT_OF(bloom_param_defs),
    .presets = { "{\"level_sigma\": 0.8, \"fine_level\": \"coarse\"}", "{\"level_sigma\": 1.0, \"fine_level\": \"fast\"}",
                 "{\"level_sigma\": 1.25, \"fine_level\": \"full\"}", "{\"level_sigma\": 2.0, \"fine_level\": \"full\"}" },
    .passes = NULL,
    .needs_camera = NULL,
    .halo = bloom_halo,
    .validate = NULL,
    .process = bloom_process,
    .identity = bloom_identity,
    /* the composite writes finite4() of every pixel; in place: the pyramid is built before
     * the composite, which reads each pixel of the image just before writing it (on a
     * consumed frame no fresh frame-sized output: a process's first frame) */
    .flags = FX_EFFECT_OWN_FINITE | FX_EFFECT_IN_PLACE,
};
