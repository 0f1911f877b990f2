/* sin_city: the Sin City look: gray (mean or luminance) in N levels (the seed's banding,
 * math/levels.h), with one colour kept: the seed's dot-product range test on the colour's
 * direction, or a smooth hue window (hue, width, softness, gated by saturation) so the kept
 * red does not alias; the kept colour may be limited to an object or material (keep only
 * the red coat). docs/effects/sin_city.md. */
#include "core/effect.h"
#include "core/mask.h"
#include "core/parallel.h"
#include "math/color.h"
#include "math/levels.h"
#include "core/simd8.h"
#include "math/vec.h"
#include "math/clones.h"

#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

typedef struct sin_city_params {
    int gray;
    int levels;
    int space;
    float white;
    float dither;
    int keep;
    float key_color[3];
    float dot_min, dot_max, dot_softness;
    float hue, hue_width, hue_softness;
    float min_saturation, saturation_softness;
    float keep_strength;
    char keep_object[FX_STRING_PARAM_MAX];
    char keep_material[FX_STRING_PARAM_MAX];
    float mix;
} sin_city_params;

enum { GRAY_LUMINANCE = 0, GRAY_MEAN };
enum { SPACE_SRGB = 0, SPACE_LINEAR };
enum { KEEP_HUE = 0, KEEP_DOT, KEEP_NONE };

static const char *const gray_items[] = { "luminance", "mean" };
static const char *const space_items[] = { "srgb", "linear" };
static const char *const keep_items[] = { "hue", "dot", "none" };
static const float red3[3] = { 1, 0, 0 };

static const fx_param_def sin_city_param_defs[] = {
    FX_P_ENUM(sin_city_params, gray, "gray", GRAY_LUMINANCE, gray_items,
              "Gray from Rec.709 luminance or from the mean (R+G+B)/3"),
    FX_P_INT(sin_city_params, levels, "levels", 0, 0, 256, 0, 16, "",
             "Gray levels (the seed's banding); 0 or 1: continuous gray"),
    FX_P_ENUM(sin_city_params, space, "space", SPACE_SRGB, space_items, "Level steps in sRGB-encoded or linear values"),
    FX_P_FLOAT(sin_city_params, white, "white", 1.0, 1e-6, 65504.0, 0.1, 16.0, "", "Linear value of the top level"),
    FX_P_FLOAT(sin_city_params, dither, "dither", 0.0, 0.0, 1.0, 0.0, 1.0, "factor", "Ordered dither amplitude, in bands"),
    FX_P_ENUM(sin_city_params, keep, "keep", KEEP_HUE, keep_items,
              "Which colours stay: hue: a smooth hue window; dot: the seed's test, the cosine between the "
              "colour and key_color in [dot_min, dot_max]; none: all gray"),
    FX_P_FLOATS(sin_city_params, key_color, "key_color", 3, red3, 0.0, 65504.0, "color", "Kept colour for keep dot"),
    FX_P_FLOAT(sin_city_params, dot_min, "dot_min", 0.9, -1.0, 1.0, 0.5, 1.0, "",
               "keep dot: smallest cosine between the colour and key_color that is kept"),
    FX_P_FLOAT(sin_city_params, dot_max, "dot_max", 1.0, -1.0, 1.0, 0.5, 1.0, "", "keep dot: largest cosine kept"),
    FX_P_FLOAT(sin_city_params, dot_softness, "dot_softness", 0.0, 0.0, 1.0, 0.0, 0.2, "",
               "keep dot: ramp width in cosine at both ends of the range (0: the seed's hard test)"),
    FX_P_FLOAT(sin_city_params, hue, "hue", 0.0, -360.0, 720.0, 0.0, 360.0, "angle",
               "keep hue: centre hue in degrees (0 red, 120 green, 240 blue)"),
    FX_P_FLOAT(sin_city_params, hue_width, "hue_width", 30.0, 0.0, 360.0, 0.0, 120.0, "angle",
               "keep hue: full width in degrees kept entirely"),
    FX_P_FLOAT(sin_city_params, hue_softness, "hue_softness", 20.0, 0.0, 180.0, 0.0, 60.0, "angle",
               "keep hue: smooth falloff in degrees beyond the width"),
    FX_P_FLOAT(sin_city_params, min_saturation, "min_saturation", 0.3, 0.0, 1.0, 0.0, 1.0, "factor",
               "keep hue: colours less saturated than this ((max-min)/max) turn gray (their hue is noise)"),
    FX_P_FLOAT(sin_city_params, saturation_softness, "saturation_softness", 0.15, 0.0, 1.0, 0.0, 0.5, "factor",
               "keep hue: ramp width of the saturation gate"),
    FX_P_FLOAT(sin_city_params, keep_strength, "keep_strength", 1.0, 0.0, 1.0, 0.0, 1.0, "factor",
               "How much of the kept colour returns (1: the original colour)"),
    FX_P_STRING(sin_city_params, keep_object, "keep_object", "", "",
                "Keep colour only on this object (Cryptomatte name; empty: everywhere)"),
    FX_P_STRING(sin_city_params, keep_material, "keep_material", "", "",
                "Keep colour only on this material (Cryptomatte name; empty: everywhere)"),
    FX_P_FLOAT(sin_city_params, mix, "mix", 1.0, 0.0, 1.0, 0.0, 1.0, "factor",
               "Blend between the original (0, the identity) and the result (1)"),
};

/* The keep-mask spec of the params (borrowing the names). */
static void keep_spec(const sin_city_params *p, fx_mask_spec *s, char *names[2])
{
    memset(s, 0, sizeof *s);
    names[0] = (char *)p->keep_object;
    names[1] = (char *)p->keep_material;
    if (p->keep_object[0]) {
        s->objects = &names[0];
        s->object_count = 1;
    }
    if (p->keep_material[0]) {
        s->materials = &names[1];
        s->material_count = 1;
    }
}

static fx_pass_set sin_city_passes(const void *params)
{
    const sin_city_params *p = params;
    if (p->keep == KEEP_NONE || !(p->mix > 0.0f))
        return 0;
    fx_mask_spec s;
    char *names[2];
    keep_spec(p, &s, names);
    return fx_mask_spec_passes(&s);
}

typedef struct sc_job {
    const fx_effect_run *run;
    const sin_city_params *p;
    const float *keep_cov; /* NULL: everywhere */
    int quantise;
    float key[3];
    float hue_c, hue_half, hue_soft;
    float inv_hue_soft, inv_sat_soft; /* reciprocals: no division per pixel for the ramps */
    fx_levels q;
} sc_job;

/* The vector path's constants, splatted once per block of rows into a local (the stores to
 * the output could alias the job's floats, so values read through j would be reloaded and
 * splatted again in every chunk). */
typedef struct sc_vk {
    v8f ms, iss, hc, hh, ihs, ks, mix, inv_white;
    v8f gate0;                /* soft gate: d < gate0 * mx surely gives gate 0 (margin 1e-4) */
    v8f lw;                   /* hue pretest: half width in degrees surely outside the window */
    v8f off_r, off_g, off_b;  /* sector offsets minus the centre: 0, 120, 240 minus hue_c */
    v8f val[FX_LEVELS_VEC];   /* levels' values 1..n-1 */
    v8f thr[FX_LEVELS_VEC];   /* the row's dither thresholds per level, per lane */
    int soft_sat, soft_hue, lum, keep, dot, nt, quantise, mixing, pretest;
} sc_vk;

/* Weight in [0, 1] of keeping colour (r, g, b) (finite, may be negative). */
static inline __attribute__((always_inline)) float keep_weight(const sc_job *j, float r, float g, float b)
{
    const sin_city_params *p = j->p;
    r = r > 0.0f ? r : 0.0f;
    g = g > 0.0f ? g : 0.0f;
    b = b > 0.0f ? b : 0.0f;
    float mx = fmaxf(r, fmaxf(g, b)), mn = fminf(r, fminf(g, b));
    if (!(mx > 1e-20f))
        return 0.0f;
    if (p->keep == KEEP_DOT) {
        /* scale first: |c| of 1e38 squared would overflow */
        float inv = 1.0f / mx;
        float x = r * inv, y = g * inv, z = b * inv;
        float c = (x * j->key[0] + y * j->key[1] + z * j->key[2]) / sqrtf(x * x + y * y + z * z);
        float s = p->dot_softness;
        if (s <= 0.0f)
            return c >= p->dot_min && c <= p->dot_max ? 1.0f : 0.0f;
        float lo = fx_saturate((c - (p->dot_min - s)) / s);
        float hi = fx_saturate(((p->dot_max + s) - c) / s);
        return fminf(lo, hi);
    }
    /* hue window: hexcone hue in degrees, circular distance to the centre */
    float d = mx - mn;
    float gate;
    if (p->saturation_softness > 0.0f) {
        /* sat = d / mx, without the division: (sat - min) / soft + 0.5 */
        gate = fx_saturate((d / mx - p->min_saturation) * j->inv_sat_soft + 0.5f);
    } else {
        gate = d >= p->min_saturation * mx ? 1.0f : 0.0f;
    }
    if (!(gate > 0.0f) || !(d > 0.0f))
        return 0.0f;
    const float s60 = 60.0f / d;
    float h;
    if (mx == r)
        h = (g - b) * s60;
    else if (mx == g)
        h = (b - r) * s60 + 120.0f;
    else
        h = (r - g) * s60 + 240.0f;
    /* h in [-60, 360], hue_c in [0, 360): |h - c| in [0, 420], one wrap at most */
    float dist = fabsf(h - j->hue_c);
    dist = dist >= 360.0f ? dist - 360.0f : dist;
    dist = dist > 180.0f ? 360.0f - dist : dist;
    if (dist <= j->hue_half)
        return gate;
    if (!(j->hue_soft > 0.0f))
        return 0.0f;
    float t = fx_saturate((dist - j->hue_half) * j->inv_hue_soft);
    return (1.0f - t * t * (3.0f - 2.0f * t)) * gate;
}

/* The rows in chunks of 8 pixels, each step a loop over the 8 lanes with no branches
 * (selects); keep_weight() above is the scalar statement of the same weights (and does the
 * keep dot mode); test_sin_city checks the hue window's values at and around its edges. */
#define SC_LANES 8 /* keep_lanes' vectors have 8 lanes */
/* keep_lanes uses GCC vector types; the other lane loops are left to the vectoriser, whose
 * -O2 "very cheap" cost model leaves them scalar: the dynamic model here, with an AVX2
 * clone beside the baseline (no FMA in either: the same bits). Vectors live only inside
 * always-inline helpers, so GCC's ABI note for 32-byte vectors does not apply. */
#if defined(__GNUC__) && !defined(__clang__)
#  pragma GCC diagnostic ignored "-Wpsabi"
#endif

/* The hue window's weights of 8 lanes (finite colours), in vector registers throughout.
 * With pretest, a chunk whose lanes all surely weigh 0 (saturation surely under the gate,
 * or hue surely beyond the window; margins far above the rounding of the exact path) skips
 * the divisions and the window: its weights are then 0, as the exact path would give. */
static inline __attribute__((always_inline)) v8f keep_hue8(const sc_vk *K, v8f r, v8f g, v8f b, int pretest)
{
#define SEL(m, a, b) SEL8(m, a, b)
#define SPLAT(v) S8(v)
    const v8f zero = SPLAT(0.0f), one = SPLAT(1.0f);
    const v8i abs8 = { 0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff,
                       0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff };
    r = SEL(r > zero, r, zero);
    g = SEL(g > zero, g, zero);
    b = SEL(b > zero, b, zero);
    v8f mx = SEL(r > g, r, g);
    mx = SEL(mx > b, mx, b);
    v8f mn = SEL(r < g, r, g);
    mn = SEL(mn < b, mn, b);
    const v8f d = mx - mn;
    const v8i ok = (mx > SPLAT(1e-20f)) & (d > zero);
    const v8i isr = mx == r, isg = mx == g;
    /* the hexcone hue's numerator per lane: h = num * 60 / d + offset */
    v8f num = SEL(isg, b - r, r - g);
    num = SEL(isr, g - b, num);
    if (pretest) {
        /* e = h - hue_c times d, without the division; the circular distance is the least
         * of |e|, |e + 360|, |e - 360| (the exact path's one wrap) */
        v8f off = SEL(isg, K->off_g, K->off_b);
        off = SEL(isr, K->off_r, off);
        const v8f e = SPLAT(60.0f) * num + off * d, lwd = K->lw * d, w360 = SPLAT(360.0f) * d;
        v8i maybe = ((v8f)((v8i)e & abs8) < lwd) | ((v8f)((v8i)(e + w360) & abs8) < lwd) |
                    ((v8f)((v8i)(e - w360) & abs8) < lwd);
        maybe |= d < SPLAT(1e-30f); /* tiny d: products near underflow; the exact path */
        maybe &= ok & (K->soft_sat ? (d >= K->gate0 * mx) : (d >= K->ms * mx));
        if (!fx_any8(maybe))
            return zero;
    }
    const v8f imx = one / SEL(ok, mx, one);
    v8f gate;
    if (K->soft_sat) {
        gate = (d * imx - K->ms) * K->iss + SPLAT(0.5f);
        gate = SEL(gate > zero, gate, zero);
        gate = SEL(gate < one, gate, one);
    } else {
        gate = SEL(d >= K->ms * mx, one, zero);
    }
    const v8f s60 = SPLAT(60.0f) / SEL(ok, d, one);
    v8f h = SEL(isg, num * s60 + SPLAT(120.0f), num * s60 + SPLAT(240.0f));
    h = SEL(isr, num * s60, h);
    v8f dist = h - K->hc;
    dist = (v8f)((v8i)dist & abs8); /* |dist|; a -0 here gives the same weight as +0 */
    dist = SEL(dist >= SPLAT(360.0f), dist - SPLAT(360.0f), dist);
    dist = SEL(dist > SPLAT(180.0f), SPLAT(360.0f) - dist, dist);
    v8f ws = zero;
    if (K->soft_hue) {
        v8f t = (dist - K->hh) * K->ihs;
        t = SEL(t > zero, t, zero);
        t = SEL(t < one, t, one);
        ws = one - t * t * (SPLAT(3.0f) - SPLAT(2.0f) * t);
    }
    const v8f w = SEL(dist <= K->hh, one, ws);
    return SEL(ok, w * gate, zero);
#undef SEL
#undef SPLAT
}

static inline __attribute__((always_inline)) void keep_lanes(const sc_job *j, const sc_vk *vk, const float *R,
                                                              const float *G, const float *B, float *K)
{
    const sin_city_params *p = j->p;
    if (p->keep == KEEP_DOT) {
        for (int i = 0; i < SC_LANES; i++)
            K[i] = keep_weight(j, R[i], G[i], B[i]);
        return;
    }
    v8f r, g, b;
    memcpy(&r, R, sizeof r);
    memcpy(&g, G, sizeof g);
    memcpy(&b, B, sizeof b);
    const v8f k = keep_hue8(vk, r, g, b, 0);
    memcpy(K, &k, sizeof k);
}

#define FIN8(v) (v = SEL8(v == v, v, S8(0.0f)), v = SEL8(v < S8(FLT_MAX), v, S8(FLT_MAX)), \
                 v = SEL8(v > S8(-FLT_MAX), v, S8(-FLT_MAX)))

/* Eight whole pixels at x of row s -> d with every value in vector registers: the lane
 * loops of sc_lanes_chunk op for op (the same bits), without the round trips through lane
 * arrays. K: the vector constants, with the row's dither thresholds per level, per lane. */
static inline __attribute__((always_inline)) void sc_vec_chunk(const sc_job *j, const sc_vk *K, const float *s,
                                                               float *d, const float *cov, int x)
{
    const v8i abs8 = { 0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff,
                       0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff };
    const float *sp = s + 4 * (size_t)x;
    v8f px[4]; /* 8 RGBA pixels to channel vectors (math/simd8.h) */
    fx_load8x4(sp, px);
    v8f r = px[0], g = px[1], b = px[2], a = px[3];
    /* Inputs within +-1e30 (NaN fails the test) keep every value below finite:
     * the clamps are then identities and are skipped (the same bits). */
    const v8i bounded = ((v8f)((v8i)r & abs8) <= S8(1e30f)) & ((v8f)((v8i)g & abs8) <= S8(1e30f)) &
                        ((v8f)((v8i)b & abs8) <= S8(1e30f)) & ((v8f)((v8i)a & abs8) <= S8(1e30f));
    const int guard = !fx_all8(bounded);
    if (guard) {
        FIN8(r);
        FIN8(g);
        FIN8(b);
        FIN8(a);
    }
    v8f yv = K->lum ? S8(FX_LUMA_R) * r + S8(FX_LUMA_G) * g + S8(FX_LUMA_B) * b
                    : r * S8(1.0f / 3.0f) + g * S8(1.0f / 3.0f) + b * S8(1.0f / 3.0f);
    if (K->quantise) {
        const v8f u = yv * K->inv_white;
        v8f o = S8(0.0f);
        for (int t = 0; t < K->nt; t++)
            o = SEL8(u >= K->thr[t], K->val[t], o);
        const v8f yc = SEL8(yv < S8(3.4e38f), yv, S8(3.4e38f));
        yv = SEL8(u >= S8(1.0f), yc, o);
    }
    v8f k = S8(0.0f);
    if (K->keep) {
        if (K->dot) {
            float R[SC_LANES], G[SC_LANES], B[SC_LANES], KW[SC_LANES];
            memcpy(R, &r, sizeof R);
            memcpy(G, &g, sizeof G);
            memcpy(B, &b, sizeof B);
            keep_lanes(j, K, R, G, B, KW);
            memcpy(&k, KW, sizeof k);
        } else {
            k = keep_hue8(K, r, g, b, K->pretest); /* no round trip through lane arrays */
        }
        v8f c = S8(1.0f);
        if (cov)
            memcpy(&c, cov + x, sizeof c);
        k = SEL8(c > S8(0.0f), k * K->ks * c, S8(0.0f));
    }
    const v8f k1 = S8(1.0f) - k;
    v8f p0 = k * r + k1 * yv, p1 = k * g + k1 * yv, p2 = k * b + k1 * yv;
    if (K->mixing) {
        p0 = r + K->mix * (p0 - r);
        p1 = g + K->mix * (p1 - g);
        p2 = b + K->mix * (p2 - b);
    }
    if (guard) {
        FIN8(p0);
        FIN8(p1);
        FIN8(p2);
    }
    const v8f po[4] = { p0, p1, p2, a };
    fx_store8x4(d + 4 * (size_t)x, po);
}
#undef FIN8

/* Up to eight pixels at x (n of them; a tail is padded) through lane arrays: the statement
 * of the arithmetic, for tails and for quantising with more levels than vectors hold. */
static inline __attribute__((always_inline)) void sc_lanes_chunk(const sc_job *j, const sc_vk *vk, const float *s,
                                                                 float *d,
                                                                 const float *cov, int x, int y,
                                                                 float T[FX_LEVELS_VEC][SC_LANES])
{
    const fx_effect_run *run = j->run;
    const sin_city_params *p = j->p;
    const float mix = p->mix, ks = p->keep_strength;
    const int lum = p->gray == GRAY_LUMINANCE, keep = p->keep != KEEP_NONE;
    const fx_levels *q = &j->q;
    const int nt = j->quantise ? q->n - 1 : 0;
    const int vec = nt < FX_LEVELS_VEC;
    const int n = run->roi.x1 - x < SC_LANES ? run->roi.x1 - x : SC_LANES;
    float R[SC_LANES], G[SC_LANES], B[SC_LANES], A[SC_LANES], Y[SC_LANES], K[SC_LANES];
    float tail[SC_LANES * 4], tcov[SC_LANES];
    const float *sp = s + 4 * (size_t)x, *cp = cov ? cov + x : NULL;
    if (n < SC_LANES) { /* the tail: a padded copy (zeros) */
        memset(tail, 0, sizeof tail);
        memset(tcov, 0, sizeof tcov);
        memcpy(tail, sp, (size_t)n * 4 * sizeof(float));
        if (cp)
            memcpy(tcov, cp, (size_t)n * sizeof(float));
        sp = tail;
        cp = cp ? tcov : NULL;
    }
    for (int i = 0; i < SC_LANES; i++) {
        R[i] = fx_finitef(sp[4 * i]);
        G[i] = fx_finitef(sp[4 * i + 1]);
        B[i] = fx_finitef(sp[4 * i + 2]);
        A[i] = fx_finitef(sp[4 * i + 3]);
    }
    for (int i = 0; i < SC_LANES; i++)
        Y[i] = lum ? fx_luminance(R[i], G[i], B[i])
                   : R[i] * (1.0f / 3.0f) + G[i] * (1.0f / 3.0f) + B[i] * (1.0f / 3.0f);
    if (j->quantise) {
        if (vec) {
            /* GCC vector types: compares that may raise FE_INVALID are not if-converted
             * by the auto-vectoriser, and branches on real images mispredict */
            typedef float v8f __attribute__((vector_size(32)));
            typedef int32_t v8i __attribute__((vector_size(32)));
            const float iw = q->inv_white;
            v8f y8, t8, big = { 3.4e38f, 3.4e38f, 3.4e38f, 3.4e38f, 3.4e38f, 3.4e38f, 3.4e38f, 3.4e38f };
            memcpy(&y8, Y, sizeof y8);
            const v8f u = y8 * (v8f){ iw, iw, iw, iw, iw, iw, iw, iw };
            v8f o = { 0 };
            for (int t = 0; t < nt; t++) {
                const float vt = q->value[t + 1];
                const v8f v8 = { vt, vt, vt, vt, vt, vt, vt, vt };
                memcpy(&t8, T[t], sizeof t8);
                const v8i m = u >= t8;
                o = (v8f)(((v8i)v8 & m) | ((v8i)o & ~m));
            }
            /* HDR kept (keep_hdr is on here), clamped to 3.4e38 */
            const v8i hb = y8 < big;
            const v8f yc = (v8f)(((v8i)y8 & hb) | ((v8i)big & ~hb));
            const v8i hm = u >= (v8f){ 1, 1, 1, 1, 1, 1, 1, 1 };
            o = (v8f)(((v8i)yc & hm) | ((v8i)o & ~hm));
            memcpy(Y, &o, sizeof o);
        } else {
            for (int i = 0; i < n; i++)
                Y[i] = fx_levels_apply(q, Y[i], x + i, y);
        }
    }
    if (keep) {
        keep_lanes(j, vk, R, G, B, K);
        for (int i = 0; i < SC_LANES; i++) {
            float c = cp ? cp[i] : 1.0f;
            K[i] = c > 0.0f ? K[i] * ks * c : 0.0f;
        }
    } else {
        for (int i = 0; i < SC_LANES; i++)
            K[i] = 0.0f;
    }
    float P0[SC_LANES], P1[SC_LANES], P2[SC_LANES];
    for (int i = 0; i < SC_LANES; i++) {
        const float k = K[i], k1 = 1.0f - k; /* k = 1 gives the colour exactly, k = 0 the gray */
        P0[i] = k * R[i] + k1 * Y[i];
        P1[i] = k * G[i] + k1 * Y[i];
        P2[i] = k * B[i] + k1 * Y[i];
    }
    if (mix < 1.0f)
        for (int i = 0; i < SC_LANES; i++) {
            P0[i] = R[i] + mix * (P0[i] - R[i]);
            P1[i] = G[i] + mix * (P1[i] - G[i]);
            P2[i] = B[i] + mix * (P2[i] - B[i]);
        }
    for (int i = 0; i < SC_LANES; i++) {
        P0[i] = fx_finitef(P0[i]);
        P1[i] = fx_finitef(P1[i]);
        P2[i] = fx_finitef(P2[i]);
    }
    /* direct stores (a staging buffer read back wider than written stalls store forwarding) */
    float *dp = d + 4 * (size_t)x;
    for (int i = 0; i < n; i++) {
        dp[4 * i] = P0[i];
        dp[4 * i + 1] = P1[i];
        dp[4 * i + 2] = P2[i];
        dp[4 * i + 3] = A[i];
    }
}

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(FX_NO_CLONES)
#  include <immintrin.h>
#  define SC_AVX2 1
/* sc_row_avx2's parts: AVX2 target code inlined into it (an always_inline callee with the
 * caller's target), so the row stays one loop with its constants in registers. */
#  define SC_AVX2_PART static inline __attribute__((target("avx2"), always_inline))

/* sc_row_avx2's constants, made once per row from the job's (sc_vk) and held in locals. */
typedef struct sc8_const {
    __m256 zero, one, absm, c0, c1, c2;
    __m256 ms, iss, hc, hh, ihs, ks, mix, iw, gate0, lw, off_r, off_g, off_b;
    __m256 k60, k120, k240, k360, k180, k3, k2, khalf, tiny, tiny30, top;
    __m256i big, perm;
} sc8_const;

SC_AVX2_PART void sc8_const_init(const sc_vk *K, sc8_const *c)
{
    c->zero = _mm256_setzero_ps();
    c->one = _mm256_set1_ps(1.0f);
    c->absm = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
    c->big = _mm256_set1_epi32(0x7149f2ca); /* the bits of 1e30f */
    c->perm = _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7);
    c->c0 = K->lum ? _mm256_set1_ps(FX_LUMA_R) : _mm256_set1_ps(1.0f / 3.0f);
    c->c1 = K->lum ? _mm256_set1_ps(FX_LUMA_G) : _mm256_set1_ps(1.0f / 3.0f);
    c->c2 = K->lum ? _mm256_set1_ps(FX_LUMA_B) : _mm256_set1_ps(1.0f / 3.0f);
    c->ms = K->ms, c->iss = K->iss, c->hc = K->hc, c->hh = K->hh, c->ihs = K->ihs, c->ks = K->ks, c->mix = K->mix;
    c->iw = K->inv_white, c->gate0 = K->gate0, c->lw = K->lw;
    c->off_r = K->off_r, c->off_g = K->off_g, c->off_b = K->off_b;
    c->k60 = _mm256_set1_ps(60.0f), c->k120 = _mm256_set1_ps(120.0f), c->k240 = _mm256_set1_ps(240.0f);
    c->k360 = _mm256_set1_ps(360.0f), c->k180 = _mm256_set1_ps(180.0f), c->k3 = _mm256_set1_ps(3.0f);
    c->k2 = _mm256_set1_ps(2.0f), c->khalf = _mm256_set1_ps(0.5f), c->tiny = _mm256_set1_ps(1e-20f);
    c->tiny30 = _mm256_set1_ps(1e-30f), c->top = _mm256_set1_ps(3.4e38f);
}

/* Eight pixels' channels from q (lanes in the order 0 2 4 6 1 3 5 7); 0 when a value is
 * beyond +-1e30 or NaN (the OR of the magnitudes' bits bounds them all): then nothing. */
SC_AVX2_PART int sc8_load(const sc8_const *c, const float *q, __m256 *r, __m256 *g, __m256 *b, __m256 *a)
{
    const __m256 m0 = _mm256_loadu_ps(q), m1 = _mm256_loadu_ps(q + 8);
    const __m256 m2 = _mm256_loadu_ps(q + 16), m3 = _mm256_loadu_ps(q + 24);
    const __m256i ob = _mm256_castps_si256(
        _mm256_and_ps(_mm256_or_ps(_mm256_or_ps(m0, m1), _mm256_or_ps(m2, m3)), c->absm));
    if (!_mm256_testz_si256(_mm256_cmpgt_epi32(ob, c->big), _mm256_cmpgt_epi32(ob, c->big)))
        return 0;
    const __m256 t0 = _mm256_unpacklo_ps(m0, m1), t1 = _mm256_unpackhi_ps(m0, m1);
    const __m256 t2 = _mm256_unpacklo_ps(m2, m3), t3 = _mm256_unpackhi_ps(m2, m3);
    *r = _mm256_castpd_ps(_mm256_unpacklo_pd(_mm256_castps_pd(t0), _mm256_castps_pd(t2)));
    *g = _mm256_castpd_ps(_mm256_unpackhi_pd(_mm256_castps_pd(t0), _mm256_castps_pd(t2)));
    *b = _mm256_castpd_ps(_mm256_unpacklo_pd(_mm256_castps_pd(t1), _mm256_castps_pd(t3)));
    *a = _mm256_castpd_ps(_mm256_unpackhi_pd(_mm256_castps_pd(t1), _mm256_castps_pd(t3)));
    return 1;
}

/* The gray y quantised to the levels (thresholds thrp, in the lanes' order); HDR kept,
 * clamped to 3.4e38. */
SC_AVX2_PART __m256 sc8_quantise(const sc8_const *c, const sc_vk *K, const v8f *thrp, __m256 y)
{
    const __m256 u = _mm256_mul_ps(y, c->iw);
    __m256 o = c->zero;
    for (int t = 0; t < K->nt; t++)
        o = _mm256_blendv_ps(o, K->val[t], _mm256_cmp_ps(u, thrp[t], _CMP_GE_OQ));
    return _mm256_blendv_ps(o, _mm256_min_ps(y, c->top), _mm256_cmp_ps(u, c->one, _CMP_GE_OQ));
}

/* The hue keep's view of eight colours: over the non-negative channels, the max, the
 * max - min, which channel is the max, the hue's numerator in its sector, and whether
 * the hue is defined at all (ok). */
typedef struct sc8_hue {
    __m256 mx, dd, num, ok, isr, isg;
} sc8_hue;

SC_AVX2_PART sc8_hue sc8_hue_of(const sc8_const *c, __m256 r, __m256 g, __m256 b)
{
    sc8_hue h;
    const __m256 rp = _mm256_max_ps(r, c->zero), gp = _mm256_max_ps(g, c->zero), bp = _mm256_max_ps(b, c->zero);
    h.mx = _mm256_max_ps(_mm256_max_ps(rp, gp), bp);
    const __m256 mn = _mm256_min_ps(_mm256_min_ps(rp, gp), bp);
    h.dd = _mm256_sub_ps(h.mx, mn);
    h.ok = _mm256_and_ps(_mm256_cmp_ps(h.mx, c->tiny, _CMP_GT_OQ), _mm256_cmp_ps(h.dd, c->zero, _CMP_GT_OQ));
    h.isr = _mm256_cmp_ps(h.mx, rp, _CMP_EQ_OQ);
    h.isg = _mm256_cmp_ps(h.mx, gp, _CMP_EQ_OQ);
    h.num = _mm256_blendv_ps(_mm256_sub_ps(rp, gp), _mm256_sub_ps(bp, rp), h.isg);
    h.num = _mm256_blendv_ps(h.num, _mm256_sub_ps(gp, bp), h.isr);
    return h;
}

/* The hue window's pretest (keep_hue8): 1 when no lane can be kept (the hue surely outside
 * the window, or the saturation surely under the gate), so the chunk is gray. */
SC_AVX2_PART int sc8_pretest_gray(const sc8_const *c, const sc8_hue *h, int soft_sat)
{
    const __m256 off = _mm256_blendv_ps(_mm256_blendv_ps(c->off_b, c->off_g, h->isg), c->off_r, h->isr);
    const __m256 e = _mm256_add_ps(_mm256_mul_ps(c->k60, h->num), _mm256_mul_ps(off, h->dd));
    const __m256 lwd = _mm256_mul_ps(c->lw, h->dd), w360 = _mm256_mul_ps(c->k360, h->dd);
    __m256 maybe = _mm256_or_ps(
        _mm256_or_ps(_mm256_cmp_ps(_mm256_and_ps(e, c->absm), lwd, _CMP_LT_OQ),
                     _mm256_cmp_ps(_mm256_and_ps(_mm256_add_ps(e, w360), c->absm), lwd, _CMP_LT_OQ)),
        _mm256_or_ps(_mm256_cmp_ps(_mm256_and_ps(_mm256_sub_ps(e, w360), c->absm), lwd, _CMP_LT_OQ),
                     _mm256_cmp_ps(h->dd, c->tiny30, _CMP_LT_OQ)));
    const __m256 gt = soft_sat ? _mm256_cmp_ps(h->dd, _mm256_mul_ps(c->gate0, h->mx), _CMP_GE_OQ)
                               : _mm256_cmp_ps(h->dd, _mm256_mul_ps(c->ms, h->mx), _CMP_GE_OQ);
    maybe = _mm256_and_ps(_mm256_and_ps(maybe, h->ok), gt);
    return _mm256_testz_si256(_mm256_castps_si256(maybe), _mm256_castps_si256(maybe));
}

/* The keep weight of the hue window: the saturation gate (soft or hard) times the hue's
 * weight (1 within hue_width / 2 of the centre, a smoothstep down over hue_softness). */
SC_AVX2_PART __m256 sc8_hue_weight(const sc8_const *c, const sc8_hue *h, int soft_sat, int soft_hue)
{
    const __m256 imx = _mm256_div_ps(c->one, _mm256_blendv_ps(c->one, h->mx, h->ok));
    __m256 gate;
    if (soft_sat) {
        gate = _mm256_add_ps(_mm256_mul_ps(_mm256_sub_ps(_mm256_mul_ps(h->dd, imx), c->ms), c->iss), c->khalf);
        gate = _mm256_min_ps(_mm256_max_ps(gate, c->zero), c->one);
    } else {
        gate = _mm256_and_ps(_mm256_cmp_ps(h->dd, _mm256_mul_ps(c->ms, h->mx), _CMP_GE_OQ), c->one);
    }
    const __m256 s60 = _mm256_div_ps(c->k60, _mm256_blendv_ps(c->one, h->dd, h->ok));
    const __m256 ns = _mm256_mul_ps(h->num, s60);
    __m256 hue = _mm256_blendv_ps(_mm256_add_ps(ns, c->k240), _mm256_add_ps(ns, c->k120), h->isg);
    hue = _mm256_blendv_ps(hue, ns, h->isr);
    __m256 dist = _mm256_and_ps(_mm256_sub_ps(hue, c->hc), c->absm);
    dist = _mm256_blendv_ps(dist, _mm256_sub_ps(dist, c->k360), _mm256_cmp_ps(dist, c->k360, _CMP_GE_OQ));
    dist = _mm256_blendv_ps(dist, _mm256_sub_ps(c->k360, dist), _mm256_cmp_ps(dist, c->k180, _CMP_GT_OQ));
    __m256 ws = c->zero;
    if (soft_hue) {
        __m256 t = _mm256_mul_ps(_mm256_sub_ps(dist, c->hh), c->ihs);
        t = _mm256_min_ps(_mm256_max_ps(t, c->zero), c->one);
        const __m256 tsq = _mm256_mul_ps(t, t), tr = _mm256_sub_ps(c->k3, _mm256_mul_ps(c->k2, t));
        ws = _mm256_sub_ps(c->one, _mm256_mul_ps(tsq, tr));
    }
    const __m256 w = _mm256_blendv_ps(ws, c->one, _mm256_cmp_ps(dist, c->hh, _CMP_LE_OQ));
    return _mm256_and_ps(_mm256_mul_ps(w, gate), h->ok);
}

/* Eight pixels' keep weight k (keep hue): the hue window's, unless the pretest spares the
 * chunk (*nskip counts it), times keep_strength and the keep coverage (cov + x, if cov). */
SC_AVX2_PART __m256 sc8_keep(const sc8_const *c, const sc_vk *K, __m256 r, __m256 g, __m256 b, int pretest,
                            const float *cov, int x, int *nskip)
{
    const sc8_hue h = sc8_hue_of(c, r, g, b);
    __m256 k = c->zero;
    int skip = 0;
    if (pretest) {
        skip = sc8_pretest_gray(c, &h, K->soft_sat);
        *nskip += skip;
    }
    if (!skip)
        k = sc8_hue_weight(c, &h, K->soft_sat, K->soft_hue);
    k = _mm256_mul_ps(k, c->ks);
    if (cov) {
        const __m256 cv = _mm256_permutevar8x32_ps(_mm256_loadu_ps(cov + x), c->perm);
        k = _mm256_and_ps(_mm256_mul_ps(k, cv), _mm256_cmp_ps(cv, c->zero, _CMP_GT_OQ));
    }
    return k;
}

/* Back to pixels (lane pairs (r g) and (b a), then their 64-bit halves) and stored at o;
 * stream: non-temporal stores. */
SC_AVX2_PART void sc8_store(float *o, __m256 p0, __m256 p1, __m256 p2, __m256 a, int stream)
{
    const __m256 u0 = _mm256_unpacklo_ps(p0, p1), u1 = _mm256_unpackhi_ps(p0, p1);
    const __m256 u2 = _mm256_unpacklo_ps(p2, a), u3 = _mm256_unpackhi_ps(p2, a);
    const __m256 o0 = _mm256_castpd_ps(_mm256_unpacklo_pd(_mm256_castps_pd(u0), _mm256_castps_pd(u2)));
    const __m256 o1 = _mm256_castpd_ps(_mm256_unpackhi_pd(_mm256_castps_pd(u0), _mm256_castps_pd(u2)));
    const __m256 o2 = _mm256_castpd_ps(_mm256_unpacklo_pd(_mm256_castps_pd(u1), _mm256_castps_pd(u3)));
    const __m256 o3 = _mm256_castpd_ps(_mm256_unpackhi_pd(_mm256_castps_pd(u1), _mm256_castps_pd(u3)));
    if (stream) {
        _mm256_stream_ps(o, o0);
        _mm256_stream_ps(o + 8, o1);
        _mm256_stream_ps(o + 16, o2);
        _mm256_stream_ps(o + 24, o3);
    } else {
        _mm256_storeu_ps(o, o0);
        _mm256_storeu_ps(o + 8, o1);
        _mm256_storeu_ps(o + 16, o2);
        _mm256_storeu_ps(o + 24, o3);
    }
}

/* sc_vec_chunk's hue and gray path in AVX2 intrinsics: the same operations lane by lane
 * (max/min are the selects SEL(a > b, a, b) and SEL(a < b, a, b), no FMA: the same bits),
 * with a shorter transpose that leaves the lanes in the order 0 2 4 6 1 3 5 7 (the dither
 * thresholds and the coverage follow it) and puts them back before the store. Chunks with a
 * value beyond +-1e30 or NaN go through sc_vec_chunk. Returns where it stopped. Called only
 * when the CPU has AVX2, for keep hue or none. pretest: try the hue window's pretest
 * (keep_hue8) on each chunk; *skipped counts the chunks it spared. stream: write with
 * non-temporal stores (d 32-byte aligned, not the source, a frame larger than the caches):
 * no read of the output's lines before they are written, as a large memcpy does. */
__attribute__((target("avx2"), noinline)) static int sc_row_avx2(const sc_job *j, const sc_vk *K,
                                                                const v8f *thrp, const float *s, float *d,
                                                                const float *cov, int x0, int x1, int pretest,
                                                                int stream, int *skipped)
{
    sc8_const c;
    sc8_const_init(K, &c);
    const int quantise = K->quantise, keep = K->keep, mixing = K->mixing;
    int nskip = 0;
    int x = x0;
    for (; x + 8 <= x1; x += 8) {
        __m256 r, g, b, a;
        if (!sc8_load(&c, s + 4 * (size_t)x, &r, &g, &b, &a)) {
            sc_vec_chunk(j, K, s, d, cov, x);
            continue;
        }
        /* the mean's r * (1/3) + ...: the same products (multiplication commutes) */
        __m256 y = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(c.c0, r), _mm256_mul_ps(c.c1, g)),
                                 _mm256_mul_ps(c.c2, b));
        if (quantise)
            y = sc8_quantise(&c, K, thrp, y);
        const __m256 k = keep ? sc8_keep(&c, K, r, g, b, pretest, cov, x, &nskip) : c.zero;
        const __m256 k1 = _mm256_sub_ps(c.one, k), ky = _mm256_mul_ps(k1, y);
        __m256 p0 = _mm256_add_ps(_mm256_mul_ps(k, r), ky), p1 = _mm256_add_ps(_mm256_mul_ps(k, g), ky);
        __m256 p2 = _mm256_add_ps(_mm256_mul_ps(k, b), ky);
        if (mixing) {
            p0 = _mm256_add_ps(r, _mm256_mul_ps(c.mix, _mm256_sub_ps(p0, r)));
            p1 = _mm256_add_ps(g, _mm256_mul_ps(c.mix, _mm256_sub_ps(p1, g)));
            p2 = _mm256_add_ps(b, _mm256_mul_ps(c.mix, _mm256_sub_ps(p2, b)));
        }
        sc8_store(d + 4 * (size_t)x, p0, p1, p2, a, stream);
    }
    if (stream)
        _mm_sfence(); /* the streamed stores visible before the pool's join */
    *skipped = nskip;
    return x;
}
#endif

/* The vector constants of the job (sc_vk). */
static inline __attribute__((always_inline)) void sc_vk_init(const sc_job *j, sc_vk *K)
{
    const sin_city_params *p = j->p;
    const fx_levels *q = &j->q;
    memset(K, 0, sizeof *K);
    K->ms = S8(p->min_saturation);
    K->iss = S8(j->inv_sat_soft);
    K->hc = S8(j->hue_c);
    K->hh = S8(j->hue_half);
    K->ihs = S8(j->inv_hue_soft);
    K->ks = S8(p->keep_strength);
    K->mix = S8(p->mix);
    K->mixing = p->mix < 1.0f;
    K->soft_sat = p->saturation_softness > 0.0f;
    K->soft_hue = j->hue_soft > 0.0f;
    K->lum = p->gray == GRAY_LUMINANCE;
    K->keep = p->keep != KEEP_NONE;
    K->dot = p->keep == KEEP_DOT;
    K->quantise = j->quantise;
    K->nt = j->quantise ? q->n - 1 : 0;
    if (j->quantise) {
        K->inv_white = S8(q->inv_white);
        for (int t = 0; t < K->nt && t < FX_LEVELS_VEC; t++)
            K->val[t] = S8(q->value[t + 1]);
    }
    /* the pretest's margins: 1e-4 in saturation, 0.05 degrees in hue (the exact path errs
     * by about 1e-4 degrees); a gate threshold near 0 is taken as 0 (tests nothing) */
    float g0 = p->min_saturation - 0.5f * p->saturation_softness - 1e-4f;
    K->gate0 = S8(g0 > 1e-6f ? g0 : 0.0f);
    const float lw = j->hue_half + (j->hue_soft > 0.0f ? j->hue_soft : 0.0f) + 0.05f;
    K->lw = S8(lw);
    K->pretest = lw < 180.0f;
    K->off_r = S8(0.0f - j->hue_c);
    K->off_g = S8(120.0f - j->hue_c);
    K->off_b = S8(240.0f - j->hue_c);
}

FX_CLONES_VECTORIZE static void sc_rows(void *user, int begin, int end)
{
    const sc_job *j = user;
    const fx_effect_run *run = j->run;
    const fx_levels *q = &j->q;
    const int nt = j->quantise ? q->n - 1 : 0;
    const int vec = nt < FX_LEVELS_VEC;
    float T[FX_LEVELS_VEC][SC_LANES];
    sc_vk K; /* a local copy: read once per block of rows, not through j after every store */
    sc_vk_init(j, &K);
#ifdef SC_AVX2
    const int avx2 = __builtin_cpu_supports("avx2");
    int pre_off = 0; /* rows to go without the hue pretest */
    /* not in place, and a frame past the caches (8 MiB): stream the output (sc_row_avx2) */
    const int big = run->dst != run->src && (size_t)run->width * (size_t)(run->roi.y1 - run->roi.y0) * 4 *
                                                    sizeof(float) >= ((size_t)8 << 20);
#endif
    for (int y = run->roi.y0 + begin; y < run->roi.y0 + end; y++) {
        const float *s = run->src + (size_t)y * run->width * 4;
        float *d = run->dst + (size_t)y * run->width * 4;
        const float *cov = j->keep_cov ? j->keep_cov + (size_t)y * run->width : NULL;
        /* chunks start at x0 + 8 m: lane i always has Bayer phase (x0 + i) & 7 in this row */
        if (j->quantise && vec)
            for (int t = 0; t < nt; t++)
                for (int i = 0; i < SC_LANES; i++)
                    T[t][i] = q->thr[(((y & 7) << 3) | ((run->roi.x0 + i) & 7)) & q->phase_mask][t];
        int x = run->roi.x0;
        const int x1 = run->roi.x1;
        if (!j->quantise || vec) {
            for (int t = 0; t < nt; t++)
                memcpy(&K.thr[t], T[t], sizeof K.thr[t]);
#ifdef SC_AVX2
            if (avx2 && !K.dot) {
                v8f thrp[FX_LEVELS_VEC]; /* the thresholds in sc_row_avx2's lane order */
                static const int order[SC_LANES] = { 0, 2, 4, 6, 1, 3, 5, 7 };
                for (int t = 0; t < nt; t++)
                    for (int i = 0; i < SC_LANES; i++)
                        thrp[t][i] = T[t][order[i]];
                /* the pretest costs about 30 instructions, a skip spares about 50: a row
                 * where it spared under 3/8 of the chunks is followed by 8 rows without it
                 * (the bits are the same either way) */
                const int use = K.pretest && pre_off == 0;
                int skipped = 0;
                const int x_start = x;
                const int stream = big && !(((uintptr_t)(d + 4 * (size_t)x)) & 31);
                x = sc_row_avx2(j, &K, thrp, s, d, cov, x, x1, use, stream, &skipped);
                if (use)
                    pre_off = skipped * 8 < 3 * ((x - x_start) / SC_LANES) ? 8 : 0;
                else if (pre_off > 0)
                    pre_off--;
            }
#endif
            for (; x + SC_LANES <= x1; x += SC_LANES)
                sc_vec_chunk(j, &K, s, d, cov, x);
        }
        for (; x < x1; x += SC_LANES)
            sc_lanes_chunk(j, &K, s, d, cov, x, y, T);
    }
}

/* Zero strength is the identity: the stack skips the effect. */
static int sin_city_identity(const void *params)
{
    const sin_city_params *p = params;
    return !(p->mix > 0.0f);
}

static fx_result sin_city_process(const fx_effect_run *run)
{
    const sin_city_params *p = run->params;
    const fx_rect *roi = &run->roi;
    char where[96];
    snprintf(where, sizeof where, "%s keep mask", run->where);
    sc_job *j = fx_mem_alloc(sizeof *j);
    if (!j)
        return fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where);
    memset(j, 0, sizeof *j);
    j->run = run;
    j->p = p;
    j->quantise = p->levels >= 2;
    if (j->quantise)
        fx_levels_init(&j->q, p->levels, p->space == SPACE_SRGB, p->white, p->dither, 1);
    float kl = sqrtf(p->key_color[0] * p->key_color[0] + p->key_color[1] * p->key_color[1] +
                     p->key_color[2] * p->key_color[2]);
    for (int c = 0; c < 3; c++)
        j->key[c] = kl > 1e-20f ? p->key_color[c] / kl : 0.0f;
    j->hue_c = fmodf(p->hue, 360.0f);
    j->hue_c = j->hue_c < 0.0f ? j->hue_c + 360.0f : j->hue_c;
    j->hue_half = 0.5f * p->hue_width;
    j->hue_soft = p->hue_softness;
    j->inv_hue_soft = p->hue_softness > 0.0f ? 1.0f / p->hue_softness : 0.0f;
    j->inv_sat_soft = p->saturation_softness > 0.0f ? 1.0f / p->saturation_softness : 0.0f;
    fx_mask *keep = NULL;
    fx_result r = FX_OK;
    if (p->keep != KEEP_NONE && (p->keep_object[0] || p->keep_material[0])) {
        fx_mask_spec spec;
        char *names[2];
        keep_spec(p, &spec, names);
        r = fx_mask_build(run->ctx, &spec, run->frame, where, &keep);
        if (!r && keep)
            j->keep_cov = keep->coverage;
    }
    if (!r) {
        int rows = roi->y1 - roi->y0;
        fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), sc_rows, j);
    }
    fx_mask_free(keep);
    fx_mem_free(j);
    return r;
}

static fx_result sin_city_validate(const void *params, char *err, size_t err_size)
{
    const sin_city_params *p = params;
    if (p->dot_min > p->dot_max) {
        snprintf(err, err_size, "dot_min (%g) is above dot_max (%g)", p->dot_min, p->dot_max);
        return FX_ERR_BAD_PARAM;
    }
    for (int i = 0; i < 3; i++)
        if (!isfinite(p->key_color[i])) {
            snprintf(err, err_size, "key_color[%d] is not finite", i);
            return FX_ERR_BAD_PARAM;
        }
    return FX_OK;
}

const fx_effect_class fx_effect_sin_city = {
    .name = "sin_city",
    .doc = "Sin City look: gray in N levels with one colour kept (hue window or the seed's dot test), optionally on one object",
    .params_size = sizeof(sin_city_params),
    .params = sin_city_param_defs,
    .param_count = FX_COUNT_OF(sin_city_param_defs),
    .presets = { NULL, NULL, NULL, NULL },
    /* every value written is clamped finite; each 8-pixel chunk is read before it is written */
    .flags = FX_EFFECT_OWN_FINITE | FX_EFFECT_IN_PLACE,
    .passes = sin_city_passes,
    .needs_camera = NULL,
    .halo = NULL,
    .validate = sin_city_validate,
    .process = sin_city_process,
    .identity = sin_city_identity,
};
