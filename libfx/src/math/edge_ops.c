/* Edge operators over render passes (math/edge_ops.h has the definitions). */
/* sqrt as the instruction, so the operator loops vectorise (errno is never read here; the
 * value is the same IEEE square root). Before the includes: the header helpers inlined
 * into the loops must carry the same optimisation options. */
#if defined(__GNUC__) && !defined(__clang__)
#  pragma GCC optimize("no-math-errno")
#endif
#include "math/edge_ops.h"

#include "core/parallel.h"
#include "math/color.h"
#include "math/srgb_lut.h"
#include "math/log.h"
#include "math/trig.h"
#include "core/simd8.h"
#include "core/simd4.h"

typedef uint32_t v8ui __attribute__((vector_size(32)));
#include "math/vec.h"
#include "core/frame.h"
#include "core/mem.h"
#include "math/clones.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

static int fx_edge_operator_radius(fx_edge_operator op)
{
    return op == FX_EDGE_SPARSE7 ? 3 : 1;
}

static inline int clampi(int v, int lo, int hi)
{
    return v < lo ? lo : v > hi ? hi : v;
}

/* The operator on the 3x3 differences from the centre (exactly 0 on a constant field). */
static inline float stencil(fx_edge_operator op, float nw, float n, float ne, float we, float ea, float sw, float s,
                            float se)
{
    float v;
    switch (op) {
    case FX_EDGE_LAPLACE4:
        v = fabsf((n + s) + (we + ea));
        break;
    case FX_EDGE_LAPLACE8:
    case FX_EDGE_SPARSE7:
        v = fabsf(((n + s) + (we + ea)) + ((nw + ne) + (sw + se))) * (1.0f / 3.0f);
        break;
    case FX_EDGE_SOBEL_X:
        v = fabsf((ne - nw) + 2.0f * (ea - we) + (se - sw)) * 0.25f;
        break;
    case FX_EDGE_SOBEL_Y:
        v = fabsf((sw - nw) + 2.0f * (s - n) + (se - ne)) * 0.25f;
        break;
    case FX_EDGE_SOBEL:
    default: {
        double gx = (double)(ne - nw) + 2.0 * (ea - we) + (se - sw);
        double gy = (double)(sw - nw) + 2.0 * (s - n) + (se - ne);
        v = (float)(sqrt(gx * gx + gy * gy) * 0.25);
        break;
    }
    }
    return v;
}

float fx_edge_response_at(const float *f, int stride, int w, int h, int x, int y, fx_edge_operator op)
{
    const int r = fx_edge_operator_radius(op);
    const int xm = clampi(x - r, 0, w - 1), xp = clampi(x + r, 0, w - 1);
    const int ym = clampi(y - r, 0, h - 1), yp = clampi(y + r, 0, h - 1);
    const size_t rm = (size_t)ym * w, r0 = (size_t)y * w, rp = (size_t)yp * w;
#define F(row, col) f[((row) + (size_t)(col)) * (size_t)stride]
    const float c = F(r0, x);
    /* differences from the centre: exactly 0 on a constant field */
    const float nw = F(rm, xm) - c, n = F(rm, x) - c, ne = F(rm, xp) - c;
    const float we = F(r0, xm) - c, ea = F(r0, xp) - c;
    const float sw = F(rp, xm) - c, s = F(rp, x) - c, se = F(rp, xp) - c;
#undef F
    float v = stencil(op, nw, n, ne, we, ea, sw, s, se);
    return v <= FLT_MAX ? v : FLT_MAX; /* also maps NaN (impossible: fields are finite) to itself */
}

fx_pass_set fx_edge_passes(const fx_edge_settings *s)
{
    fx_pass_set p = 0;
    if (s->use_depth)
        p |= FX_PASS_BIT(FX_PASS_DEPTH);
    if (s->use_normal)
        p |= FX_PASS_BIT(FX_PASS_NORMAL);
    if (s->use_object)
        p |= FX_PASS_BIT(s->id_source == FX_EDGE_ID_INDEX ? FX_PASS_INDEX_OB : FX_PASS_CRYPTO_OBJECT);
    if (s->use_material)
        p |= FX_PASS_BIT(s->id_source == FX_EDGE_ID_INDEX ? FX_PASS_INDEX_MA : FX_PASS_CRYPTO_MATERIAL);
    return p;
}

/* Disc radius rho of the line-width dilation, and its integer reach. */
static float dilation_rho(const fx_edge_settings *s)
{
    float lw = s->line_width;
    if (!(lw > 2.0f))
        return 0.0f;
    if (lw > FX_EDGE_MAX_WIDTH)
        lw = FX_EDGE_MAX_WIDTH;
    return 0.5f * (lw - 2.0f);
}

static int dilation_reach(float rho)
{
    return (int)floorf(rho + 0.5f);
}

int fx_edge_halo(const fx_edge_settings *s)
{
    int r = 0;
    if (s->use_luminance || s->use_depth)
        r = fx_edge_operator_radius(s->op);
    if ((s->use_normal || s->use_object || s->use_material) && r < 1)
        r = 1;
    return r + dilation_reach(dilation_rho(s));
}

static fx_result need_pass(const fx_frame *f, const char *name, int channels, const char *where,
                           const float **out)
{
    fx_pass *p = fx_frame_find_pass(f, name);
    if (!p)
        return fx_fail(f->ctx, FX_ERR_MISSING_PASS,
                       "%s: needs the %s pass, which the frame does not have (enable it in the view "
                       "layer's passes, or turn this edge source off)", where, name);
    if (p->channels < channels)
        return fx_fail(f->ctx, FX_ERR_BAD_FILE, "%s: pass %s has %d channels, expected %d", where, name,
                       p->channels, channels);
    *out = p->data;
    return FX_OK;
}

static fx_result crypto_ranks(const fx_frame *f, const char *type, const char *where,
                              const float **ranks, int *count)
{
    *count = 0;
    for (int i = 0; i < FX_EDGE_MAX_RANKS; i++) {
        char name[FX_NAME_MAX];
        snprintf(name, sizeof name, "%s%02d", type, i);
        fx_pass *p = fx_frame_find_pass(f, name);
        if (!p)
            break;
        if (p->channels != 4)
            return fx_fail(f->ctx, FX_ERR_BAD_FILE, "%s: Cryptomatte pass %s has %d channels, not 4",
                           where, name, p->channels);
        ranks[(*count)++] = p->data;
    }
    if (*count == 0)
        return fx_fail(f->ctx, FX_ERR_MISSING_PASS,
                       "%s: ID edges from Cryptomatte need the %s pass, which the frame does not have "
                       "(enable Cryptomatte %s in the view layer, or use id_source index with Cycles)",
                       where, type, strcmp(type, "CryptoObject") == 0 ? "Object" : "Material");
    return FX_OK;
}

fx_result fx_edge_sources_from_frame(const fx_frame *f, const float *rgba, const fx_edge_settings *s,
                                     fx_edge_sources *out, const char *where)
{
    memset(out, 0, sizeof *out);
    out->rgba = rgba;
    out->width = f->width;
    out->height = f->height;
    fx_result r = FX_OK;
    if (!r && s->use_depth)
        r = need_pass(f, "Depth", 1, where, &out->depth);
    if (!r && s->use_normal)
        r = need_pass(f, "Normal", 3, where, &out->normal);
    for (int k = 0; k < 2 && !r; k++) {
        if (!(k == 0 ? s->use_object : s->use_material))
            continue;
        if (s->id_source == FX_EDGE_ID_INDEX)
            r = need_pass(f, k == 0 ? "IndexOB" : "IndexMA", 1, where, &out->index[k]);
        else
            r = crypto_ranks(f, k == 0 ? "CryptoObject" : "CryptoMaterial", where, out->crypto[k],
                             &out->crypto_ranks[k]);
    }
    return r;
}

/* ---- the work ----
 * Streaming, one band of output rows at a time: each band computes its fields (encoded
 * luminance, log or inverse depth, unit normals) into small ring buffers of rows, the
 * thresholded strength of each row once its field rows exist, and the line-width dilation
 * of each output row once its strength rows exist, then hands the finished matte row to the
 * caller (which draws it while the row's colour is still in cache). No frame-size plane is
 * allocated; a band recomputes the few halo rows it shares with its neighbours (the same
 * expressions, so the same bits). Every value is a function of the pixel alone: any band
 * height and thread count gives the same matte. */

#define EDGE_BAND 32 /* output rows per band */

/* Vectorised clones (-O3's vectoriser): the baseline and an AVX2 one (no FMA: the same
 * bits), as sin_city. No optimize() attribute: it would stop the header helpers from being
 * inlined. */
#if defined(__GNUC__) && !defined(__clang__)
#  pragma GCC diagnostic ignored "-Wpsabi"
#endif

typedef struct edge_job {
    const fx_edge_sources *src;
    const fx_edge_settings *s;
    int w, h;
    int opr;               /* field rows read around a strength row (>= 1) */
    int reach;             /* dilation reach, rows and columns */
    fx_rect field_rect;    /* columns where fields are computed */
    fx_rect strength_rect; /* columns where strengths are computed */
    fx_rect roi;
    const float *lut;      /* sRGB encoding table (math/srgb_lut.h) */
    float *strengths;
    const int *span;       /* dilation: half-width of the disc at dy = -reach..reach */
    fx_edge_row_fn emit;
    void *user;
    /* rgba_written: encoded luminance of the rows within `hf` of each inner band boundary
     * (boundary k = 1..bands-1 at roi.y0 + k EDGE_BAND: rows [yb - hf, yb + hf), 2 hf rows
     * of w floats each, field_rect's columns valid), taken before the bands run */
    float *saved;
    int hf, bands;
    /* per-worker scratch: ring rows */
    int rf, rs;            /* ring sizes: field rows, strength rows */
    size_t scratch_floats;
    float **scratch;       /* one block per worker */
    int workers;
} edge_job;

/* Unit normal of (x, y, z), or 0 for background. */
static inline void unit_normal3(const float *n, float *u)
{
    float x = n[0], y = n[1], z = n[2];
    float l2 = x * x + y * y + z * z;
    if (!(l2 >= FX_EDGE_MIN_NORMAL * FX_EDGE_MIN_NORMAL) || !(l2 <= 1e30f)) {
        u[0] = u[1] = u[2] = 0.0f;
        return;
    }
    float inv = 1.0f / sqrtf(l2);
    u[0] = x * inv;
    u[1] = y * inv;
    u[2] = z * inv;
}

/* Encoded luminance of a pixel: finite, clamped to the encoder's useful range (NaN -> 0). */
static inline float lum_px(const float *p, const float *lut)
{
    float l = fx_luminance(p[0], p[1], p[2]);
    l = l > 0.0f ? (l < 1e6f ? l : 1e6f) : 0.0f;
    return fx_srgb_encode_lut(lut, l); /* no powf: math/srgb_lut.h */
}

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(FX_NO_CLONES)
#  include <immintrin.h>
#  define EDGE_LUM_AVX2 1
/* lum_row's 8-pixel loop in AVX2 intrinsics: the same operations lane by lane (no FMA: the
 * same bits), with the table's two reads per lane as two gathers and a shorter transpose
 * (R, G, B only, the lanes in the order 0 2 4 6 1 3 5 7, put back before the store). Returns
 * where it stopped. Called only when the CPU has AVX2. */
__attribute__((target("avx2"), noinline)) static int lum_row_avx2(const float *p, const float *lut, int x0,
                                                                 int x1, float *out)
{
    const __m256 kr = _mm256_set1_ps(FX_LUMA_R), kg = _mm256_set1_ps(FX_LUMA_G), kb = _mm256_set1_ps(FX_LUMA_B);
    const __m256 zero = _mm256_setzero_ps(), cap = _mm256_set1_ps(1e6f), lo = _mm256_set1_ps(0.001953125f);
    const __m256 lin = _mm256_set1_ps(12.92f), tscale = _mm256_set1_ps(1.0f / (float)(1u << (23 - FX_SRGB_LUT_BITS)));
    const __m256i mant = _mm256_set1_epi32((1 << (23 - FX_SRGB_LUT_BITS)) - 1);
    const __m256i base = _mm256_set1_epi32((int32_t)((uint32_t)(127 + FX_SRGB_LUT_MIN_EXP) << FX_SRGB_LUT_BITS));
    const __m256i order = _mm256_setr_epi32(0, 4, 1, 5, 2, 6, 3, 7);
    /* lanes 0 1 4 5 to the first gather, 2 3 6 7 to the second: _mm256_shuffle_ps then puts
     * them back in order */
    const __m256i pair_order = _mm256_setr_epi32(0, 1, 4, 5, 2, 3, 6, 7);
    int x = x0;
    for (; x + 8 <= x1; x += 8) {
        const float *q = p + 4 * (size_t)x;
        const __m256 m0 = _mm256_loadu_ps(q), m1 = _mm256_loadu_ps(q + 8);
        const __m256 m2 = _mm256_loadu_ps(q + 16), m3 = _mm256_loadu_ps(q + 24);
        /* m0 = r0 g0 b0 a0 r1 g1 b1 a1, ...: t0 = r0 r2 g0 g2 | r1 r3 g1 g3 */
        const __m256 t0 = _mm256_unpacklo_ps(m0, m1), t1 = _mm256_unpackhi_ps(m0, m1);
        const __m256 t2 = _mm256_unpacklo_ps(m2, m3), t3 = _mm256_unpackhi_ps(m2, m3);
        const __m256 r = _mm256_castpd_ps(_mm256_unpacklo_pd(_mm256_castps_pd(t0), _mm256_castps_pd(t2)));
        const __m256 g = _mm256_castpd_ps(_mm256_unpackhi_pd(_mm256_castps_pd(t0), _mm256_castps_pd(t2)));
        const __m256 b = _mm256_castpd_ps(_mm256_unpacklo_pd(_mm256_castps_pd(t1), _mm256_castps_pd(t3)));
        __m256 l = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(kr, r), _mm256_mul_ps(kg, g)), _mm256_mul_ps(kb, b));
        const __m256 pos = _mm256_cmp_ps(l, zero, _CMP_GT_OQ); /* false for NaN: 0, as lum_px */
        l = _mm256_and_ps(pos, _mm256_min_ps(l, cap));         /* l < 1e6 ? l : 1e6 where positive */
        const __m256 small = _mm256_cmp_ps(l, lo, _CMP_LT_OQ);
        const __m256i bits = _mm256_castps_si256(l);
        const __m256i i = _mm256_andnot_si256(_mm256_castps_si256(small),
                                              _mm256_sub_epi32(_mm256_srli_epi32(bits, 23 - FX_SRGB_LUT_BITS), base));
        const __m256 t = _mm256_mul_ps(_mm256_cvtepi32_ps(_mm256_and_si256(bits, mant)), tscale);
        /* the pairs (lut[i], lut[i + 1]) as 8-byte elements: 2 gathers of 4, then split */
        const __m256i ip = _mm256_permutevar8x32_epi32(i, pair_order);
        const __m256 r0 = _mm256_castsi256_ps(
            _mm256_i32gather_epi64((const long long *)(const void *)lut, _mm256_castsi256_si128(ip), 4));
        const __m256 r1 = _mm256_castsi256_ps(
            _mm256_i32gather_epi64((const long long *)(const void *)lut, _mm256_extracti128_si256(ip, 1), 4));
        const __m256 l0 = _mm256_shuffle_ps(r0, r1, 0x88), l1 = _mm256_shuffle_ps(r0, r1, 0xdd);
        const __m256 e = _mm256_add_ps(l0, _mm256_mul_ps(t, _mm256_sub_ps(l1, l0)));
        const __m256 v = _mm256_blendv_ps(e, _mm256_mul_ps(lin, l), small);
        _mm256_storeu_ps(out + x, _mm256_permutevar8x32_ps(v, order));
    }
    return x;
}
#endif

/* 8 pixels at a time in GCC vector types (the transpose of core/simd8.h, then lum_px's
 * operations lane by lane: the same bits), the table read per lane; the rest per pixel. */
FX_CLONES static void lum_row(const float *p, const float *lut, int x0, int x1, float *out)
{
    int x = x0;
#ifdef EDGE_LUM_AVX2
    if (__builtin_cpu_supports("avx2"))
        x = lum_row_avx2(p, lut, x0, x1, out);
#endif
    const v8f lo = S8(0.001953125f); /* 2^-9 */
    const v8i imask = { 0, 0, 0, 0, 0, 0, 0, 0 };
    for (; x + 8 <= x1; x += 8) {
        v8f c[4];
        fx_load8x4(p + 4 * (size_t)x, c);
        v8f l = S8(FX_LUMA_R) * c[0] + S8(FX_LUMA_G) * c[1] + S8(FX_LUMA_B) * c[2];
        const v8i pos = l > S8(0.0f); /* false for NaN: 0, as lum_px */
        l = SEL8(pos, SEL8(l < S8(1e6f), l, S8(1e6f)), S8(0.0f));
        const v8i small = l < lo;
        v8i b;
        memcpy(&b, &l, sizeof b);
        v8i i = (v8i)(((v8ui)b >> (23 - FX_SRGB_LUT_BITS)) -
                      (v8ui)S8I((int32_t)((uint32_t)(127 + FX_SRGB_LUT_MIN_EXP) << FX_SRGB_LUT_BITS)));
        i = (i & ~small) | (imask & small);
        const v8f t = __builtin_convertvector(b & S8I((1 << (23 - FX_SRGB_LUT_BITS)) - 1), v8f) *
                      S8(1.0f / (float)(1u << (23 - FX_SRGB_LUT_BITS)));
        int32_t ii[8];
        memcpy(ii, &i, sizeof ii);
        v8f l0, l1;
        float a0[8], a1[8];
        for (int k = 0; k < 8; k++) {
            a0[k] = lut[ii[k]];
            a1[k] = lut[ii[k] + 1];
        }
        memcpy(&l0, a0, sizeof l0);
        memcpy(&l1, a1, sizeof l1);
        const v8f e = l0 + t * (l1 - l0);
        const v8f v = SEL8(small, S8(12.92f) * l, e);
        memcpy(out + x, &v, sizeof v);
    }
    for (; x < x1; x++)
        out[x] = lum_px(p + 4 * (size_t)x, lut);
}

static void depth_row(const float *d, int planar, int x0, int x1, float *out)
{
    for (int x = x0; x < x1; x++) {
        float v = d[x];
        v = v > FX_EDGE_NEAR_DEPTH ? (v < FX_EDGE_FAR_DEPTH ? v : FX_EDGE_FAR_DEPTH)
                                   : (v == v ? FX_EDGE_NEAR_DEPTH : FX_EDGE_FAR_DEPTH);
        out[x] = planar ? 1.0f / v : fx_logf_pos(v);
    }
}

/* Unit normals of a row into three planes (x, y, z components: out, out + w, out + 2 w). */
FX_CLONES static void normal_row(const float *n, int w, int x0, int x1, float *out)
{
    for (int x = x0; x < x1; x++) {
        float u[3];
        unit_normal3(n + 3 * (size_t)x, u);
        out[x] = u[0];
        out[x + w] = u[1];
        out[x + 2 * (size_t)w] = u[2];
    }
}

/* Smallest cosine between the pixel's unit normal and its 4 neighbours' (rows of unit
 * normals in planes (see normal_row): above, this, below, each already clamped to the
 * image), and whether surface and background meet there. */
static inline float normal_min_dot(const float *um, const float *u0, const float *up, int w, int x, int *mixed)
{
    const size_t W = (size_t)w;
    const float c0 = u0[x], c1 = u0[x + W], c2 = u0[x + 2 * W];
    const int hc = c0 != 0.0f || c1 != 0.0f || c2 != 0.0f;
    const float *rows[4] = { u0, u0, um, up };
    const int cols[4] = { clampi(x - 1, 0, w - 1), clampi(x + 1, 0, w - 1), x, x };
    float min_dot = 1.0f;
    int mx = 0;
    for (int k = 0; k < 4; k++) {
        const float q0 = rows[k][cols[k]], q1 = rows[k][cols[k] + W], q2 = rows[k][cols[k] + 2 * W];
        const int hq = q0 != 0.0f || q1 != 0.0f || q2 != 0.0f;
        if (hc != hq)
            mx = 1;
        else if (hc) {
            float d = c0 * q0 + c1 * q1 + c2 * q2;
            min_dot = d < min_dot ? d : min_dot;
        }
    }
    *mixed = mx;
    return min_dot;
}

/* normal_min_dot over a row's columns [x0, x1) into md[x] and mixed[x] (0 or -1): the
 * interior 8 columns at a time in GCC vector types (compares that may raise FE_INVALID are
 * not if-converted by the auto-vectoriser), the rest per pixel; the same values. */
FX_CLONES static void normal_min_dot_row(const float *um, const float *u0, const float *up, int w, int x0, int x1,
                                        float *md, int32_t *mixed)
{
    const size_t W = (size_t)w;
    int xa = x0 > 1 ? x0 : 1, xb = x1 < w - 1 ? x1 : w - 1;
    if (xb < xa)
        xa = xb = x1;
    int x = x0;
    for (; x < xa && x < x1; x++) {
        int m;
        md[x] = normal_min_dot(um, u0, up, w, x, &m);
        mixed[x] = -m;
    }
    const v8f zero = { 0 }, one = { 1, 1, 1, 1, 1, 1, 1, 1 };
    for (; x + 8 <= xb; x += 8) {
        const v8f c0 = fx_load8(u0 + x), c1 = fx_load8(u0 + W + x), c2 = fx_load8(u0 + 2 * W + x);
        const v8i hc = (c0 != zero) | (c1 != zero) | (c2 != zero);
        v8f mn = one;
        v8i mx = { 0 };
#define NB(p)                                                                                   \
    do {                                                                                        \
        const v8f q0 = fx_load8(p), q1 = fx_load8((p) + W), q2 = fx_load8((p) + 2 * W);                        \
        const v8i hq = (q0 != zero) | (q1 != zero) | (q2 != zero);                              \
        const v8f d = c0 * q0 + c1 * q1 + c2 * q2;                                              \
        mx |= hc ^ hq;                                                                          \
        const v8i take = hc & hq & (d < mn);                                                    \
        mn = (v8f)(((v8i)d & take) | ((v8i)mn & ~take));                                        \
    } while (0)
        NB(u0 + x - 1);
        NB(u0 + x + 1);
        NB(um + x);
        NB(up + x);
#undef NB
        memcpy(md + x, &mn, sizeof mn);
        memcpy(mixed + x, &mx, sizeof mx);
    }
    for (; x < x1; x++) {
        int m;
        md[x] = normal_min_dot(um, u0, up, w, x, &m);
        mixed[x] = -m;
    }
}
/* fx_acosf: glibc 2.41 rounds acosf differently from 2.36 (math/trig.h), and the ramp is continuous */

static inline float normal_angle(float min_dot, int mixed)
{
    float a = fx_acosf(min_dot) * (float)(180.0 / 3.14159265358979323846);
    return mixed && a < 90.0f ? 90.0f : a;
}

/* Coverage two pixels share, 1 minus it: index pass (exact IDs) or Cryptomatte. */
static float id_difference(const fx_edge_sources *src, int k, size_t a, size_t b)
{
    if (src->index[k])
        return src->index[k][a] == src->index[k][b] ? 0.0f : 1.0f;
    const int nr = src->crypto_ranks[k];
    float shared = 0.0f, cov_a = 0.0f, cov_b = 0.0f;
    for (int ra = 0; ra < nr; ra++) {
        const float *pa = src->crypto[k][ra] + a * 4;
        for (int ia = 0; ia < 2; ia++) {
            float ca = pa[2 * ia + 1];
            if (!(ca > 0.0f))
                continue;
            cov_a += ca;
            float id = pa[2 * ia];
            for (int rb = 0; rb < nr; rb++) {
                const float *pb = src->crypto[k][rb] + b * 4;
                if (pb[0] == id && pb[1] > 0.0f)
                    shared += fminf(ca, pb[1]);
                if (pb[2] == id && pb[3] > 0.0f)
                    shared += fminf(ca, pb[3]);
            }
        }
    }
    for (int rb = 0; rb < nr; rb++) {
        const float *pb = src->crypto[k][rb] + b * 4;
        if (pb[1] > 0.0f)
            cov_b += pb[1];
        if (pb[3] > 0.0f)
            cov_b += pb[3];
    }
    /* what the ranks do not cover is the background "ID" */
    float bg_a = 1.0f - fminf(cov_a, 1.0f), bg_b = 1.0f - fminf(cov_b, 1.0f);
    shared += fminf(bg_a, bg_b);
    float d = 1.0f - shared;
    return d > 0.0f ? (d < 1.0f ? d : 1.0f) : 0.0f;
}

static float id_strength(const fx_edge_sources *src, int k, int w, int h, int x, int y)
{
    size_t c = (size_t)y * w + x;
    size_t nb[4] = { (size_t)y * w + clampi(x - 1, 0, w - 1), (size_t)y * w + clampi(x + 1, 0, w - 1),
                     (size_t)clampi(y - 1, 0, h - 1) * w + x, (size_t)clampi(y + 1, 0, h - 1) * w + x };
    float m = 0.0f;
    for (int i = 0; i < 4; i++) {
        if (nb[i] == c)
            continue;
        float d = id_difference(src, k, c, nb[i]);
        m = d > m ? d : m;
    }
    return m;
}

/* clamp((s - t) / max(softness t, 1e-6), 0, 1), with the reciprocal taken once. */
typedef struct ramp_k {
    float t, inv;
} ramp_k;

static ramp_k ramp_of(float t, float softness)
{
    float wdt = softness * t;
    wdt = wdt > 1e-6f ? wdt : 1e-6f;
    return (ramp_k){ t, 1.0f / wdt };
}

static inline float ramp(ramp_k r, float s)
{
    float e = (s - r.t) * r.inv;
    return e > 0.0f ? (e < 1.0f ? e : 1.0f) : 0.0f;
}

/* The operator at column x from the rows A = y - r, B = y, C = y + r (clamped to the image),
 * columns clamped: the expressions of fx_edge_response_at, so the same bits. */
static inline float response_at_rows(const float *A, const float *B, const float *C, int w, int x, int r,
                                     fx_edge_operator op)
{
    const int xm = clampi(x - r, 0, w - 1), xp = clampi(x + r, 0, w - 1);
    const float c = B[x];
    const float nw = A[xm] - c, n = A[x] - c, ne = A[xp] - c;
    const float we = B[xm] - c, ea = B[xp] - c;
    const float sw = C[xm] - c, s = C[x] - c, se = C[xp] - c;
    float v = stencil(op, nw, n, ne, we, ea, sw, s, se);
    return v <= FLT_MAX ? v : FLT_MAX;
}

#if defined(__SSE2__)
#  include <emmintrin.h>
#  define EDGE_SSE2 1
/* Sobel magnitude, r = 1, 4 interior columns at a time from xa; returns where it stopped.
 * The scalar loop's operations in the same order (float differences, then double sums, the
 * double square root as an instruction, rounded to float): the same bits. */
static inline __attribute__((always_inline)) int sobel_row_sse2(const float *A, const float *B, const float *C,
                                                                int xa, int xb, float *out)
{
    const __m128d two = _mm_set1_pd(2.0), quarter = _mm_set1_pd(0.25);
    const __m128 big = _mm_set1_ps(FLT_MAX);
    int x = xa;
    for (; x + 4 <= xb; x += 4) {
        const __m128 c = _mm_loadu_ps(B + x);
        const __m128 n = _mm_sub_ps(_mm_loadu_ps(A + x), c), s = _mm_sub_ps(_mm_loadu_ps(C + x), c);
        const __m128 we = _mm_sub_ps(_mm_loadu_ps(B + x - 1), c), ea = _mm_sub_ps(_mm_loadu_ps(B + x + 1), c);
        const __m128 nw = _mm_sub_ps(_mm_loadu_ps(A + x - 1), c), ne = _mm_sub_ps(_mm_loadu_ps(A + x + 1), c);
        const __m128 sw = _mm_sub_ps(_mm_loadu_ps(C + x - 1), c), se = _mm_sub_ps(_mm_loadu_ps(C + x + 1), c);
        const __m128 gx1 = _mm_sub_ps(ne, nw), gx2 = _mm_sub_ps(ea, we), gx3 = _mm_sub_ps(se, sw);
        const __m128 gy1 = _mm_sub_ps(sw, nw), gy2 = _mm_sub_ps(s, n), gy3 = _mm_sub_ps(se, ne);
        __m128 half[2];
        for (int k = 0; k < 2; k++) {
#define LANES(v) (k == 0 ? _mm_cvtps_pd(v) : _mm_cvtps_pd(_mm_movehl_ps((v), (v))))
            const __m128d gx = _mm_add_pd(_mm_add_pd(LANES(gx1), _mm_mul_pd(two, LANES(gx2))), LANES(gx3));
            const __m128d gy = _mm_add_pd(_mm_add_pd(LANES(gy1), _mm_mul_pd(two, LANES(gy2))), LANES(gy3));
#undef LANES
            const __m128d m = _mm_mul_pd(_mm_sqrt_pd(_mm_add_pd(_mm_mul_pd(gx, gx), _mm_mul_pd(gy, gy))), quarter);
            half[k] = _mm_cvtpd_ps(m);
        }
        __m128 v = _mm_movelh_ps(half[0], half[1]);
        v = _mm_min_ps(v, big); /* v <= FLT_MAX ? v : FLT_MAX (v is never NaN) */
        _mm_storeu_ps(out + x, v);
    }
    return x;
}

#  if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(FX_NO_CLONES)
#    include <immintrin.h>
#    define EDGE_AVX2 1
/* sobel_row_sse2 8 columns at a time in AVX2 (4 doubles per register): the same operations
 * in the same order, so the same bits. Called only when the CPU has AVX2. */
/* The Sobel magnitude of 8 pixels from their column differences, in doubles (as the scalar
 * response_at_rows: gx = g1 + 2 g2 + g3, the same for gy, |g| / 4), back to floats. */
__attribute__((target("avx2"), always_inline)) static inline __m256 sobel_mag8_pd(__m256 gx1, __m256 gx2, __m256 gx3,
                                                                                   __m256 gy1, __m256 gy2, __m256 gy3)
{
    const __m256d two = _mm256_set1_pd(2.0), quarter = _mm256_set1_pd(0.25);
    __m128 half[2];
    for (int k = 0; k < 2; k++) {
#define LANES(v) _mm256_cvtps_pd(k == 0 ? _mm256_castps256_ps128(v) : _mm256_extractf128_ps((v), 1))
        const __m256d gx = _mm256_add_pd(_mm256_add_pd(LANES(gx1), _mm256_mul_pd(two, LANES(gx2))), LANES(gx3));
        const __m256d gy = _mm256_add_pd(_mm256_add_pd(LANES(gy1), _mm256_mul_pd(two, LANES(gy2))), LANES(gy3));
#undef LANES
        const __m256d q = _mm256_add_pd(_mm256_mul_pd(gx, gx), _mm256_mul_pd(gy, gy));
        half[k] = _mm256_cvtpd_ps(_mm256_mul_pd(_mm256_sqrt_pd(q), quarter));
    }
    return _mm256_set_m128(half[1], half[0]);
}

__attribute__((target("avx2"), noinline)) static int sobel_row_avx2(const float *A, const float *B,
                                                                   const float *C, int xa, int xb,
                                                                   float *out)
{
    const __m256 big = _mm256_set1_ps(FLT_MAX);
    int x = xa;
    for (; x + 8 <= xb; x += 8) {
        const __m256 c = _mm256_loadu_ps(B + x);
        const __m256 n = _mm256_sub_ps(_mm256_loadu_ps(A + x), c), s = _mm256_sub_ps(_mm256_loadu_ps(C + x), c);
        const __m256 we = _mm256_sub_ps(_mm256_loadu_ps(B + x - 1), c), ea = _mm256_sub_ps(_mm256_loadu_ps(B + x + 1), c);
        const __m256 nw = _mm256_sub_ps(_mm256_loadu_ps(A + x - 1), c), ne = _mm256_sub_ps(_mm256_loadu_ps(A + x + 1), c);
        const __m256 sw = _mm256_sub_ps(_mm256_loadu_ps(C + x - 1), c), se = _mm256_sub_ps(_mm256_loadu_ps(C + x + 1), c);
        const __m256 gx1 = _mm256_sub_ps(ne, nw), gx2 = _mm256_sub_ps(ea, we), gx3 = _mm256_sub_ps(se, sw);
        const __m256 gy1 = _mm256_sub_ps(sw, nw), gy2 = _mm256_sub_ps(s, n), gy3 = _mm256_sub_ps(se, ne);
        __m256 v = sobel_mag8_pd(gx1, gx2, gx3, gy1, gy2, gy3);
        v = _mm256_min_ps(v, big); /* v <= FLT_MAX ? v : FLT_MAX (v is never NaN) */
        _mm256_storeu_ps(out + x, v);
    }
    return x;
}

/* Sobel magnitude and the threshold ramp in one pass (luminance edges without the debug
 * strengths: the strengths are not kept), 8 interior columns at a time from xa; returns where
 * it stopped. Most pixels are far from the threshold: float bounds on |gx| and |gy| tell the
 * lanes whose ramp is surely 0 or surely 1; only chunks with a lane in between take
 * sobel_row_avx2's double path (the same operations, then ramp()'s), so every lane gets
 * exactly what the exact path gives it: the same bits. */
__attribute__((target("avx2"), noinline)) static int sobel_ramp_row_avx2(const float *A, const float *B,
                                                                        const float *C, int xa, int xb,
                                                                        float t, float inv, float *out)
{
    const __m256 big = _mm256_set1_ps(FLT_MAX), tv = _mm256_set1_ps(t), iv = _mm256_set1_ps(inv);
    const __m256 one = _mm256_set1_ps(1.0f), zero = _mm256_setzero_ps();
    const double qs = 16.0 * (double)t * (double)t * (1.0 - 1.0 / 524288.0);
    const __m256 qskipf = _mm256_set1_ps((float)(qs * (1.0 - 1.0 / 4096.0)));
    const __m256 absm = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
    /* ramp 1 for sure: v >= (t + W)(1 + 1e-5), W = 1 / inv, then (v - t) inv >= 1 after its two
     * roundings; v = sqrt(q) / 4 rounded: q >= 16 (t + W)^2 (1 + 2e-5)^2 is enough, and the float
     * bound takes a further 2^-10 (an infinite bound when that overflows float: never taken) */
    const double wq = (double)t + 1.0 / (double)inv;
    const double qh = 16.0 * wq * wq * (1.0 + 2e-5) * (1.0 + 2e-5) * (1.0 + 1.0 / 1024.0);
    const __m256 qhighf = _mm256_set1_ps(qh < 1e38 ? (float)qh : INFINITY);
#define SOBEL_TERMS(x)                                                                                          \
    const __m256 c = _mm256_loadu_ps(B + (x));                                                                  \
    const __m256 n = _mm256_sub_ps(_mm256_loadu_ps(A + (x)), c), s = _mm256_sub_ps(_mm256_loadu_ps(C + (x)), c); \
    const __m256 we = _mm256_sub_ps(_mm256_loadu_ps(B + (x) - 1), c);                                           \
    const __m256 ea = _mm256_sub_ps(_mm256_loadu_ps(B + (x) + 1), c);                                           \
    const __m256 nw = _mm256_sub_ps(_mm256_loadu_ps(A + (x) - 1), c);                                           \
    const __m256 ne = _mm256_sub_ps(_mm256_loadu_ps(A + (x) + 1), c);                                           \
    const __m256 sw = _mm256_sub_ps(_mm256_loadu_ps(C + (x) - 1), c);                                           \
    const __m256 se = _mm256_sub_ps(_mm256_loadu_ps(C + (x) + 1), c);                                           \
    const __m256 gx1 = _mm256_sub_ps(ne, nw), gx2 = _mm256_sub_ps(ea, we), gx3 = _mm256_sub_ps(se, sw);         \
    const __m256 gy1 = _mm256_sub_ps(sw, nw), gy2 = _mm256_sub_ps(s, n), gy3 = _mm256_sub_ps(se, ne)
    /* Pass 1, branch-free: float bounds on |gx| and |gy| from above and below, from the
     * column differences (8 loads, no centre subtracted: the sums of the exact path in another
     * order). Every value of a luminance field is in [0, 341] (lum_row: luminance clamped to
     * 1e6, encoded; L = 512 below). The exact path's gx (float differences from the centre,
     * then the double sum) is within 16 u L of the real sum over the inputs (u = 2^-24: each
     * of its 3 float differences per term errs by at most 4 u L, weights 1 + 2 + 1), and gxf
     * here within 10 u L of it: |gx - gxf| <= 26 u L = 7.9e-4, plus the rounding of ax +- M
     * (u 8 L = 2.4e-4): the margin M = 2^-9 = 1.95e-3 covers both (likewise gy). qskipf is
     * below qs and qhighf above qh's exact bound, so a lane under qskipf has ramp 0 (v <= t)
     * and one over qhighf ramp 1. Those values are stored; a chunk with any other lane goes on
     * a list (no branch: edges cut across chunks at random and mispredicted). */
    const __m256 mg = _mm256_set1_ps(0.001953125f);
    enum { SEG = 256 }; /* chunks per list */
    int list[SEG];
    int x = xa;
    while (x + 8 <= xb) {
        int nl = 0;
        const int x_end = x + 8 * SEG <= xb ? x + 8 * SEG : xb;
        for (; x + 8 <= x_end; x += 8) {
            const __m256 am = _mm256_loadu_ps(A + x - 1), a0 = _mm256_loadu_ps(A + x), ap = _mm256_loadu_ps(A + x + 1);
            const __m256 bm = _mm256_loadu_ps(B + x - 1), bp = _mm256_loadu_ps(B + x + 1);
            const __m256 cm = _mm256_loadu_ps(C + x - 1), c0 = _mm256_loadu_ps(C + x), cp = _mm256_loadu_ps(C + x + 1);
            const __m256 db = _mm256_sub_ps(bp, bm), dc = _mm256_sub_ps(c0, a0);
            const __m256 gxf = _mm256_add_ps(_mm256_add_ps(_mm256_sub_ps(ap, am), _mm256_sub_ps(cp, cm)),
                                             _mm256_add_ps(db, db));
            const __m256 gyf = _mm256_add_ps(_mm256_add_ps(_mm256_sub_ps(cm, am), _mm256_sub_ps(cp, ap)),
                                             _mm256_add_ps(dc, dc));
            const __m256 ax = _mm256_and_ps(gxf, absm), ay = _mm256_and_ps(gyf, absm);
            const __m256 bx = _mm256_add_ps(ax, mg), by = _mm256_add_ps(ay, mg);
            const __m256 lx = _mm256_max_ps(_mm256_sub_ps(ax, mg), zero), ly = _mm256_max_ps(_mm256_sub_ps(ay, mg), zero);
            const __m256 qf = _mm256_add_ps(_mm256_mul_ps(bx, bx), _mm256_mul_ps(by, by));
            const __m256 qlo = _mm256_add_ps(_mm256_mul_ps(lx, lx), _mm256_mul_ps(ly, ly));
            const __m256 lo = _mm256_cmp_ps(qf, qskipf, _CMP_LT_OQ), hi = _mm256_cmp_ps(qlo, qhighf, _CMP_GT_OQ);
            _mm256_storeu_ps(out + x, _mm256_and_ps(hi, one));
            list[nl] = x;
            nl += _mm256_movemask_ps(_mm256_or_ps(lo, hi)) != 255;
        }
        /* Pass 2: the listed chunks exactly: sobel_row_avx2's double path (the same
         * operations), then ramp()'s; the sure lanes get what this path would give them. */
        for (int i = 0; i < nl; i++) {
            const int xc = list[i];
            SOBEL_TERMS(xc);
            __m256 v = sobel_mag8_pd(gx1, gx2, gx3, gy1, gy2, gy3);
            v = _mm256_min_ps(v, big); /* v <= FLT_MAX ? v : FLT_MAX (v is never NaN) */
            /* ramp: e > 0 ? (e < 1 ? e : 1) : 0 is max(min(e, 1), +0) (maxps gives its second
             * operand, +0, for e = -0) */
            const __m256 e = _mm256_mul_ps(_mm256_sub_ps(v, tv), iv);
            _mm256_storeu_ps(out + xc, _mm256_max_ps(_mm256_min_ps(e, one), zero));
        }
    }
#undef SOBEL_TERMS
    return x;
}
#  endif
#endif

/* The operator on one row for x in [x0, x1) into out[x]: the interior without any clamping
 * (the same expressions, so the same bits), the borders through response_at_rows. */
FX_CLONES static void response_row(const float *A, const float *B, const float *C, int w, int x0, int x1,
                                  fx_edge_operator op, float *out)
{
    const int r = fx_edge_operator_radius(op);
    int xa = x0 > r ? x0 : r, xb = x1 < w - r ? x1 : w - r;
    if (xb < xa)
        xa = xb = x1;
    for (int x = x0; x < xa && x < x1; x++)
        out[x] = response_at_rows(A, B, C, w, x, r, op);
    switch (op) {
    case FX_EDGE_LAPLACE4:
        for (int x = xa; x < xb; x++) {
            const float c = B[x];
            float v = fabsf(((A[x] - c) + (C[x] - c)) + ((B[x - r] - c) + (B[x + r] - c)));
            out[x] = v <= FLT_MAX ? v : FLT_MAX;
        }
        break;
    case FX_EDGE_LAPLACE8:
    case FX_EDGE_SPARSE7:
        for (int x = xa; x < xb; x++) {
            const float c = B[x];
            const float n = A[x] - c, s = C[x] - c, we = B[x - r] - c, ea = B[x + r] - c;
            const float nw = A[x - r] - c, ne = A[x + r] - c, sw = C[x - r] - c, se = C[x + r] - c;
            float v = fabsf(((n + s) + (we + ea)) + ((nw + ne) + (sw + se))) * (1.0f / 3.0f);
            out[x] = v <= FLT_MAX ? v : FLT_MAX;
        }
        break;
    case FX_EDGE_SOBEL_X:
        for (int x = xa; x < xb; x++) {
            const float c = B[x];
            const float we = B[x - r] - c, ea = B[x + r] - c;
            const float nw = A[x - r] - c, ne = A[x + r] - c, sw = C[x - r] - c, se = C[x + r] - c;
            float v = fabsf((ne - nw) + 2.0f * (ea - we) + (se - sw)) * 0.25f;
            out[x] = v <= FLT_MAX ? v : FLT_MAX;
        }
        break;
    case FX_EDGE_SOBEL_Y:
        for (int x = xa; x < xb; x++) {
            const float c = B[x];
            const float n = A[x] - c, s = C[x] - c;
            const float nw = A[x - r] - c, ne = A[x + r] - c, sw = C[x - r] - c, se = C[x + r] - c;
            float v = fabsf((sw - nw) + 2.0f * (s - n) + (se - ne)) * 0.25f;
            out[x] = v <= FLT_MAX ? v : FLT_MAX;
        }
        break;
    case FX_EDGE_SOBEL:
    default:
#ifdef EDGE_AVX2
        if (__builtin_cpu_supports("avx2"))
            xa = sobel_row_avx2(A, B, C, xa, xb, out);
#endif
#ifdef EDGE_SSE2
        xa = sobel_row_sse2(A, B, C, xa, xb, out);
#endif
        for (int x = xa; x < xb; x++) {
            const float c = B[x];
            const float n = A[x] - c, s = C[x] - c, we = B[x - r] - c, ea = B[x + r] - c;
            const float nw = A[x - r] - c, ne = A[x + r] - c, sw = C[x - r] - c, se = C[x + r] - c;
            double gx = (double)(ne - nw) + 2.0 * (ea - we) + (se - sw);
            double gy = (double)(sw - nw) + 2.0 * (s - n) + (se - ne);
            float v = (float)(sqrt(gx * gx + gy * gy) * 0.25);
            out[x] = v <= FLT_MAX ? v : FLT_MAX;
        }
        break;
    }
    for (int x = xb > x0 ? xb : x0; x < x1; x++)
        out[x] = response_at_rows(A, B, C, w, x, r, op);
}

/* max of two non-NaN values, inline (fmaxf is a libm call here) */
static inline float maxf(float a, float b)
{
    return a > b ? a : b;
}

/* Planar depth strength (field: 1/depth, finite and > 0; see edge_ops.h) on one row: A, C
 * the rows above and below (used when has_v: both inside the image). */
static void planar_row(const float *A, const float *B, const float *C, int has_v, int w, int x0, int x1, float *out)
{
    for (int x = x0; x < x1; x++) {
        const float c = B[x];
        float sx = 0.0f, sy = 0.0f;
        if (x > 0 && x + 1 < w)
            sx = fabsf((B[x - 1] - c) + (B[x + 1] - c));
        if (has_v)
            sy = fabsf((A[x] - c) + (C[x] - c));
        float v = (sx > sy ? sx : sy) / c; /* x depth */
        out[x] = v <= FLT_MAX ? v : FLT_MAX;
    }
}

/* Per-band state: ring rows of the worker's scratch. */
typedef struct band_rings {
    float *lum, *ldepth, *unorm, *str, *sl, *sd, *out, *nmd;
    int32_t *nmx;
} band_rings;

static inline const float *ring_row(const float *ring, int rows, size_t row_floats, int y)
{
    return ring + (size_t)(y % rows) * row_floats;
}

/* The saved luminance row y (see edge_job.saved), or NULL. */
static const float *saved_row(const edge_job *j, int y)
{
    if (!j->saved)
        return NULL;
    const int k = (y - j->roi.y0 + j->hf) / EDGE_BAND; /* y - roi.y0 + hf >= 0: fields start there at most */
    const int yb = j->roi.y0 + k * EDGE_BAND;
    if (y - j->roi.y0 + j->hf < 0 || k < 1 || k >= j->bands || y < yb - j->hf || y >= yb + j->hf)
        return NULL;
    return j->saved + ((size_t)(k - 1) * 2 * j->hf + (size_t)(y - (yb - j->hf))) * (size_t)j->w;
}

static void save_boundaries(void *user, int begin, int end)
{
    const edge_job *j = user;
    const size_t w = (size_t)j->w;
    for (int k = begin + 1; k < end + 1; k++) {
        const int yb = j->roi.y0 + k * EDGE_BAND;
        for (int y = yb - j->hf; y < yb + j->hf; y++)
            if (y >= 0 && y < j->h)
                lum_row(j->src->rgba + (size_t)y * w * 4, j->lut, j->field_rect.x0, j->field_rect.x1,
                        j->saved + ((size_t)(k - 1) * 2 * j->hf + (size_t)(y - (yb - j->hf))) * w);
    }
}

static void field_row(const edge_job *j, const band_rings *b, int y)
{
    const fx_rect *fr = &j->field_rect;
    const size_t w = (size_t)j->w, row = (size_t)y * w;
    const float *sv = b->lum ? saved_row(j, y) : NULL;
    if (sv)
        memcpy(b->lum + (size_t)(y % j->rf) * w + fr->x0, sv + fr->x0, (size_t)(fr->x1 - fr->x0) * sizeof(float));
    else if (b->lum)
        lum_row(j->src->rgba + row * 4, j->lut, fr->x0, fr->x1, b->lum + (size_t)(y % j->rf) * w);
    if (b->ldepth)
        depth_row(j->src->depth + row, j->s->depth_planar, fr->x0, fr->x1, b->ldepth + (size_t)(y % j->rf) * w);
    if (b->unorm)
        normal_row(j->src->normal + row * 3, j->w, fr->x0, fr->x1, b->unorm + (size_t)(y % j->rf) * w * 3);
}

/* Strength stage 1: the luminance and depth responses of row y into b->sl and b->sd. With
 * Sobel on luminance alone (the defaults) the AVX2 path writes the ramped strengths to out
 * at once and returns 1 (nothing left to do). */
static int raw_responses(const edge_job *j, const band_rings *b, int y, float *out, int dbg)
{
    const fx_edge_settings *s = j->s;
    const fx_rect *sr = &j->strength_rect;
    const int w = j->w, h = j->h, rf = j->rf;
    const size_t ws = (size_t)w;
    const int r = fx_edge_operator_radius(s->op);
    if (s->use_luminance) {
        const float *A = ring_row(b->lum, rf, ws, clampi(y - r, 0, h - 1));
        const float *B = ring_row(b->lum, rf, ws, y), *C = ring_row(b->lum, rf, ws, clampi(y + r, 0, h - 1));
#ifdef EDGE_AVX2
        if (s->op == FX_EDGE_SOBEL && !s->use_depth && !s->use_normal && !s->use_object && !s->use_material &&
            !dbg && __builtin_cpu_supports("avx2")) {
            /* the common case (the defaults): the Sobel magnitude and its ramp in one pass */
            const ramp_k rl = ramp_of(s->luminance_threshold, s->softness);
            int xa = sr->x0 > 1 ? sr->x0 : 1, xb = sr->x1 < w - 1 ? sr->x1 : w - 1;
            if (xb < xa)
                xa = xb = sr->x1;
            int x = sr->x0;
            for (; x < xa && x < sr->x1; x++)
                out[x] = ramp(rl, response_at_rows(A, B, C, w, x, 1, s->op));
            x = sobel_ramp_row_avx2(A, B, C, x, xb, rl.t, rl.inv, out);
            for (; x < sr->x1; x++)
                out[x] = ramp(rl, response_at_rows(A, B, C, w, x, 1, s->op));
            return 1;
        }
#else
        (void)out;
        (void)dbg;
#endif
        response_row(A, B, C, w, sr->x0, sr->x1, s->op, b->sl);
    }
    if (s->use_depth) {
        if (s->depth_planar) {
            const int has_v = y > 0 && y + 1 < h;
            const float *B = ring_row(b->ldepth, rf, ws, y);
            const float *A = has_v ? ring_row(b->ldepth, rf, ws, y - 1) : B;
            const float *C = has_v ? ring_row(b->ldepth, rf, ws, y + 1) : B;
            planar_row(A, B, C, has_v, w, sr->x0, sr->x1, b->sd);
        } else {
            const float *A = ring_row(b->ldepth, rf, ws, clampi(y - r, 0, h - 1));
            const float *B = ring_row(b->ldepth, rf, ws, y), *C = ring_row(b->ldepth, rf, ws, clampi(y + r, 0, h - 1));
            response_row(A, B, C, w, sr->x0, sr->x1, s->op, b->sd);
        }
    }
    return 0;
}

/* Strength stage 3: normals and IDs, per pixel, on top of the ramped luminance and depth
 * in out; the raw strengths into j->strengths on debug rows. */
static void normal_id_strengths(const edge_job *j, const band_rings *b, int y, float *out, int dbg)
{
    const fx_edge_settings *s = j->s;
    const fx_rect *sr = &j->strength_rect;
    const int w = j->w, h = j->h, rf = j->rf;
    const size_t ws = (size_t)w;
    const ramp_k rn = ramp_of(s->normal_threshold, s->softness), ri = ramp_of(s->id_threshold, s->softness);
    /* normals turning by less than the threshold give 0 without an acos: cos(threshold)
     * plus a margin so that rounding never hides a value ramp() would make positive */
    const float cos_skip = cosf(fx_clampf(s->normal_threshold, 0.0f, 180.0f) * (float)(3.14159265358979323846 / 180.0)) + 1e-5f;
    const float *sl_row = b->sl, *sd_row = b->sd;
    const float *um = NULL, *u0 = NULL, *up = NULL;
    if (s->use_normal) {
        um = ring_row(b->unorm, rf, ws * 3, clampi(y - 1, 0, h - 1));
        u0 = ring_row(b->unorm, rf, ws * 3, y);
        up = ring_row(b->unorm, rf, ws * 3, clampi(y + 1, 0, h - 1));
    }
    const int dbg_row = dbg && y >= j->roi.y0 && y < j->roi.y1;
    if (!s->use_normal && !s->use_object && !s->use_material && !dbg_row)
        return;
    float *nmd = b->nmd;
    int32_t *nmx = b->nmx;
    if (s->use_normal) {
        normal_min_dot_row(um, u0, up, w, sr->x0, sr->x1, nmd, nmx);
        if (!s->use_object && !s->use_material && !dbg_row) {
            /* only the pixels where the normals turn enough (few): the acos */
            for (int x = sr->x0; x < sr->x1; x++)
                if (nmx[x] || nmd[x] < cos_skip)
                    out[x] = maxf(out[x], ramp(rn, normal_angle(nmd[x], nmx[x])));
            return;
        }
    }
    for (int x = sr->x0; x < sr->x1; x++) {
        float sn = 0, si = 0, e = out[x];
        if (s->use_normal) {
            const int mixed = nmx[x];
            const float md = nmd[x];
            if (mixed || md < cos_skip || dbg_row) {
                sn = normal_angle(md, mixed);
                e = maxf(e, ramp(rn, sn));
            }
        }
        for (int k = 0; k < 2; k++)
            if (k == 0 ? s->use_object : s->use_material) {
                float d = id_strength(j->src, k, w, h, x, y);
                si = maxf(si, d);
                e = maxf(e, ramp(ri, d));
            }
        out[x] = e;
        if (dbg_row && x >= j->roi.x0 && x < j->roi.x1) {
            float *o = j->strengths + ((size_t)y * w + x) * 4;
            o[0] = s->use_luminance ? sl_row[x] : 0.0f;
            o[1] = s->use_depth ? sd_row[x] : 0.0f;
            o[2] = sn;
            o[3] = si;
        }
    }
}

/* Thresholded strength of row y into out[x] for x in strength_rect's columns; the raw
 * strengths into j->strengths when write_dbg (row y inside the ROI and owned by this band). */
static void strength_row(const edge_job *j, const band_rings *b, int y, float *out, int write_dbg)
{
    const fx_edge_settings *s = j->s;
    const fx_rect *sr = &j->strength_rect;
    const ramp_k rl = ramp_of(s->luminance_threshold, s->softness), rd = ramp_of(s->depth_threshold, s->softness);
    const float *sl_row = b->sl, *sd_row = b->sd;
    const int dbg = write_dbg && j->strengths;
    if (raw_responses(j, b, y, out, dbg))
        return;
    /* stage 2: luminance and depth ramped (simple loops) */
    if (s->use_luminance && s->use_depth) {
        for (int x = sr->x0; x < sr->x1; x++) {
            float a = ramp(rl, sl_row[x]), c = ramp(rd, sd_row[x]);
            out[x] = a > c ? a : c;
        }
    } else if (s->use_luminance) {
        for (int x = sr->x0; x < sr->x1; x++)
            out[x] = ramp(rl, sl_row[x]);
    } else if (s->use_depth) {
        for (int x = sr->x0; x < sr->x1; x++)
            out[x] = ramp(rd, sd_row[x]);
    } else {
        for (int x = sr->x0; x < sr->x1; x++)
            out[x] = 0.0f;
    }
    if (s->use_normal || s->use_object || s->use_material || dbg)
        normal_id_strengths(j, b, y, out, dbg);
}

/* m[x] = max(m[x], row[x + dx]) for |dx| <= hw, x + dx inside the image, x in [x0, x1). */
FX_CLONES static void max_span(float *m, const float *row, int w, int x0, int x1, int hw)
{
    for (int dx = -hw; dx <= hw; dx++) {
        int a = x0, b = x1;
        if (a + dx < 0)
            a = -dx;
        if (b + dx > w)
            b = w - dx;
        for (int x = a; x < b; x++) {
            float v = row[x + dx];
            m[x] = v > m[x] ? v : m[x];
        }
    }
}

static void band_rows(void *user, int begin, int end, int worker)
{
    const edge_job *j = user;
    const int w = j->w, h = j->h, reach = j->reach;
    const size_t ws = (size_t)w;
    float *sc = j->scratch[worker];
    band_rings b = { 0 };
    /* carve the worker's block (sizes as in fx_edge_matte_rows) */
    if (j->s->use_luminance) {
        b.lum = sc;
        sc += (size_t)j->rf * ws;
        b.sl = sc;
        sc += ws;
    }
    if (j->s->use_depth) {
        b.ldepth = sc;
        sc += (size_t)j->rf * ws;
        b.sd = sc;
        sc += ws;
    }
    if (j->s->use_normal) {
        b.unorm = sc;
        sc += (size_t)j->rf * ws * 3;
        b.nmd = sc;
        sc += ws;
        b.nmx = (int32_t *)sc;
        sc += ws;
    }
    b.str = sc;
    sc += (size_t)j->rs * ws;
    b.out = sc;
    const int y0 = j->roi.y0 + begin * EDGE_BAND, y1 = j->roi.y0 + end * EDGE_BAND < j->roi.y1 ? j->roi.y0 + end * EDGE_BAND : j->roi.y1;
    const int s_first = y0 - reach > 0 ? y0 - reach : 0;
    const int f_first = s_first - j->opr > 0 ? s_first - j->opr : 0;
    int next_s = s_first, next_f = f_first;
    const int fields = j->s->use_luminance || j->s->use_depth || j->s->use_normal;
    for (int y = y0; y < y1; y++) {
        const int s_need = y + reach < h - 1 ? y + reach : h - 1;
        while (next_s <= s_need) {
            const int f_need = next_s + j->opr < h - 1 ? next_s + j->opr : h - 1;
            while (fields && next_f <= f_need)
                field_row(j, &b, next_f++);
            strength_row(j, &b, next_s, b.str + (size_t)(next_s % j->rs) * ws, next_s >= y0 && next_s < y1);
            next_s++;
        }
        const float *row;
        if (reach == 0) {
            row = b.str + (size_t)(y % j->rs) * ws;
        } else {
            float *m = b.out;
            for (int x = j->roi.x0; x < j->roi.x1; x++)
                m[x] = 0.0f;
            for (int dy = -reach; dy <= reach; dy++) {
                const int yy = y + dy;
                if (yy < 0 || yy >= h)
                    continue;
                max_span(m, b.str + (size_t)(yy % j->rs) * ws, w, j->roi.x0, j->roi.x1, j->span[dy + reach]);
            }
            row = m;
        }
        j->emit(j->user, y, row);
    }
}

static fx_rect grow(const fx_rect *r, int by, int w, int h)
{
    fx_rect g = { r->x0 - by, r->y0 - by, r->x1 + by, r->y1 + by };
    g.x0 = g.x0 < 0 ? 0 : g.x0;
    g.y0 = g.y0 < 0 ? 0 : g.y0;
    g.x1 = g.x1 > w ? w : g.x1;
    g.y1 = g.y1 > h ? h : g.y1;
    return g;
}

fx_result fx_edge_matte_rows(fx_context *ctx, const fx_edge_sources *src, const fx_edge_settings *s,
                             const fx_rect *roi_in, float *strengths, fx_edge_row_fn emit, void *user,
                             const char *where)
{
    const int w = src->width, h = src->height;
    fx_rect roi = roi_in ? *roi_in : (fx_rect){ 0, 0, w, h };
    roi = grow(&roi, 0, w, h);
    if (roi.x1 <= roi.x0 || roi.y1 <= roi.y0)
        return FX_OK;
    if (s->use_luminance && !src->rgba)
        return fx_fail(ctx, FX_ERR_INTERNAL, "%s: no colour for luminance edges", where);
    if (s->use_depth && !src->depth)
        return fx_fail(ctx, FX_ERR_MISSING_PASS, "%s: no Depth pass for depth edges", where);
    if (s->use_normal && !src->normal)
        return fx_fail(ctx, FX_ERR_MISSING_PASS, "%s: no Normal pass for normal edges", where);
    for (int k = 0; k < 2; k++)
        if ((k == 0 ? s->use_object : s->use_material) && !src->index[k] && src->crypto_ranks[k] < 1)
            return fx_fail(ctx, FX_ERR_MISSING_PASS, "%s: no ID pass for %s edges", where,
                           k == 0 ? "object" : "material");
    edge_job j;
    memset(&j, 0, sizeof j);
    j.src = src;
    j.s = s;
    j.w = w;
    j.h = h;
    j.roi = roi;
    j.strengths = strengths;
    j.emit = emit;
    j.user = user;
    const float rho = dilation_rho(s);
    j.reach = dilation_reach(rho);
    j.opr = fx_edge_operator_radius(s->op); /* >= 1: normals and planar depth read 1 row away */
    j.strength_rect = grow(&roi, j.reach, w, h);
    j.field_rect = grow(&j.strength_rect, j.opr, w, h);
    j.rf = 2 * j.opr + 1;
    j.rs = 2 * j.reach + 1;
    int span[2 * 33 + 1];
    {
        const float lim = (rho + 0.5f) * (rho + 0.5f);
        for (int dy = -j.reach; dy <= j.reach; dy++) {
            int hw = -1;
            for (int dx = 0; dx <= j.reach; dx++)
                if ((float)(dx * dx + dy * dy) <= lim)
                    hw = dx;
            span[dy + j.reach] = hw; /* -1: no tap in this row (max_span does nothing) */
        }
    }
    j.span = span;
    const size_t ws = (size_t)w;
    size_t floats = (size_t)j.rs * ws + ws;
    if (s->use_luminance)
        floats += (size_t)j.rf * ws + ws;
    if (s->use_depth)
        floats += (size_t)j.rf * ws + ws;
    if (s->use_normal)
        floats += (size_t)j.rf * ws * 3 + 2 * ws; /* + min dots, mixed flags */
    j.scratch_floats = floats;
    j.workers = fx_parallel_workers(ctx);
    fx_result r = FX_OK;
    j.scratch = fx_mem_calloc((size_t)j.workers, sizeof *j.scratch);
    if (!j.scratch)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the edge rows", where);
    for (int i = 0; i < j.workers && !r; i++)
        if (!(j.scratch[i] = fx_mem_alloc(floats * sizeof(float))))
            r = fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the edge rows", where);
    const int bands = (roi.y1 - roi.y0 + EDGE_BAND - 1) / EDGE_BAND;
    if (!r && s->use_luminance && src->rgba_written && bands > 1) {
        j.hf = j.opr + j.reach;
        j.bands = bands;
        if (j.hf > FX_EDGE_IN_PLACE_MAX_HALO)
            r = fx_fail(ctx, FX_ERR_INTERNAL, "%s: edges in place with a halo of %d rows (at most %d)", where,
                        j.hf, FX_EDGE_IN_PLACE_MAX_HALO);
        else if (!(j.saved = fx_mem_alloc((size_t)(bands - 1) * 2 * (size_t)j.hf * ws * sizeof(float))))
            r = fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the edge rows", where);
    }
    if (!r) {
        if (s->use_luminance)
            j.lut = fx_srgb_lut();
        if (j.saved)
            fx_parallel_for(ctx, bands - 1, 1, save_boundaries, &j);
        fx_parallel_for_worker(ctx, bands, 1, band_rows, &j);
    }
    fx_mem_free(j.saved);
    for (int i = 0; i < j.workers; i++)
        fx_mem_free(j.scratch[i]);
    fx_mem_free(j.scratch);
    return r;
}

typedef struct matte_copy {
    float *matte;
    int w, x0, x1;
} matte_copy;


/* ---- the gradient: Blender's Filter node, type Sobel ----
 * Per colour channel g = sqrt(gx^2 + gy^2) of the unnormalised 3x3 Sobel kernels, the
 * neighbours clamped to the image (Blender's "extended" reads), mixed with the pixel as
 * Blender's Factor mixes (c (1 - f) + g f: exactly g at f = 1), alpha kept. The sums in
 * Blender's order (its loop over the 3x3 window, rows from the bottom (its y axis points
 * up), zero weights skipped: adding +-0 changes no sum but a zero's sign, which squares
 * away): P the row below, M the pixel's row, Q the row above, in libfx's top-down rows
 *   gx = ((((P[-1] - P[+1]) + 2 M[-1]) - 2 M[+1]) + Q[-1]) - Q[+1]
 *   gy = ((((P[-1] + 2 P[0]) + P[+1]) - Q[-1]) - 2 Q[0]) - Q[+1]
 * in float, the same bits as Blender's CPU compositor on finite input. A pixel whose result
 * is not finite (NaN or Inf in its neighbourhood, or an overflow) is redone in double from
 * its neighbours made finite (NaN 0, +-Inf +-FLT_MAX), then clamped to +-FLT_MAX: NaN and
 * Inf never reach the output, and the choice is a function of the pixel's neighbourhood
 * alone (any band or thread count gives the same bits). */

/* One channel's gradient: the taps at (columns) a = x - 1, c = x, b = x + 1, clamped. */
static inline float grad_ch(const float *P, const float *M, const float *Q, size_t a, size_t c, size_t b)
{
    const float gx = ((((P[a] - P[b]) + 2.0f * M[a]) - 2.0f * M[b]) + Q[a]) - Q[b];
    const float gy = ((((P[a] + 2.0f * P[c]) + P[b]) - Q[a]) - 2.0f * Q[c]) - Q[b];
    return sqrtf(gx * gx + gy * gy);
}

/* fx_finitef's value, for the sums in double */
static inline double finite_d(float v)
{
    return fx_finitef(v);
}

static inline float clamp_fd(double v)
{
    return v < (double)FLT_MAX ? (v > -(double)FLT_MAX ? (float)v : -FLT_MAX) : FLT_MAX;
}

/* The pixel from neighbours made finite, in double (see above): always finite. */
static void grad_px_safe(const float *P, const float *M, const float *Q, int w, int x, float fac, float *o)
{
    const int xm = x > 0 ? x - 1 : 0, xp = x + 1 < w ? x + 1 : w - 1;
    const size_t a = 4 * (size_t)xm, c = 4 * (size_t)x, b = 4 * (size_t)xp;
    for (int k = 0; k < 3; k++) {
        const double gx = ((((finite_d(P[a + k]) - finite_d(P[b + k])) + 2.0 * finite_d(M[a + k])) -
                            2.0 * finite_d(M[b + k])) + finite_d(Q[a + k])) - finite_d(Q[b + k]);
        const double gy = ((((finite_d(P[a + k]) + 2.0 * finite_d(P[c + k])) + finite_d(P[b + k])) -
                            finite_d(Q[a + k])) - 2.0 * finite_d(Q[c + k])) - finite_d(Q[b + k]);
        const double g = clamp_fd(sqrt(gx * gx + gy * gy));
        o[k] = clamp_fd(fac == 1.0f ? g : finite_d(M[c + k]) * (1.0 - (double)fac) + g * (double)fac);
    }
    o[3] = (float)finite_d(M[c + 3]);
}

static inline int finite4f(const float *o)
{
    return o[0] - o[0] == 0.0f && o[1] - o[1] == 0.0f && o[2] - o[2] == 0.0f && o[3] - o[3] == 0.0f;
}

/* The pixel at column x (neighbours clamped to [0, w)) into o[4] (o may not alias M). At
 * factor 1 the colour is g itself (c 0 + g in Blender: the same bits for a finite c). */
static inline void grad_px(const float *P, const float *M, const float *Q, int w, int x, float fac, float keep,
                           float *o)
{
    const int xm = x > 0 ? x - 1 : 0, xp = x + 1 < w ? x + 1 : w - 1;
    const size_t a = 4 * (size_t)xm, c = 4 * (size_t)x, b = 4 * (size_t)xp;
    for (int k = 0; k < 3; k++) {
        const float g = grad_ch(P + k, M + k, Q + k, a, c, b);
        o[k] = fac == 1.0f ? g : M[c + k] * keep + g * fac;
    }
    o[3] = M[c + 3];
    if (!finite4f(o))
        grad_px_safe(P, M, Q, w, x, fac, o);
}

/* How far ahead in P (floats) the loops prefetch: the row below comes from memory, and
 * without it the hardware's prefetch left the loop waiting (in place, one thread, greek bath
 * 1080p: 4.2 -> 1.8 ms of CPU from 2048 on, flat to 8192; 256: 2.8, 1024: 1.9). P's rows are
 * consecutive in the frame, so the prefetch runs on into the next row. */
#define GRAD_PREFETCH 2048

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(FX_NO_CLONES)
#  include <immintrin.h>
#  define EDGE_GRAD_AVX2 1
/* The left taps of a chunk are the right taps of the chunk before it (pixels x - 1, x):
 * carried in registers, not loaded again (P's, Q's and 2 M's). */
typedef struct grad_carry {
    __m256 pa, ma2, qa;
} grad_carry;

/* grad_px's operations on two pixels (lanes r g b a r g b a) at columns x, x + 1 (c = 4 x; no
 * clamping); *bad collects the exponent bits (all ones: NaN or Inf). Reads columns x to
 * x + 2 only (the carry holds x - 1): out may be M (in place), stored at once. */
__attribute__((target("avx2"), always_inline)) static inline void grad2_avx2(const float *P, const float *M,
                                                                              const float *Q, size_t c, __m256 f,
                                                                              __m256 kp, __m256 two, int unit,
                                                                              float *out, float *save, grad_carry *k,
                                                                              __m256i *bad)
{
    const __m256 pc = _mm256_loadu_ps(P + c), pb = _mm256_loadu_ps(P + c + 4);
    const __m256 mc = _mm256_loadu_ps(M + c), mb2 = _mm256_mul_ps(two, _mm256_loadu_ps(M + c + 4));
    const __m256 qc = _mm256_loadu_ps(Q + c), qb = _mm256_loadu_ps(Q + c + 4);
    /* 2 v as a product (v + v is the same value): the adder ports are the busy ones */
    const __m256 gx = _mm256_sub_ps(
        _mm256_add_ps(_mm256_sub_ps(_mm256_add_ps(_mm256_sub_ps(k->pa, pb), k->ma2), mb2), k->qa), qb);
    const __m256 gy = _mm256_sub_ps(
        _mm256_sub_ps(_mm256_sub_ps(_mm256_add_ps(_mm256_add_ps(k->pa, _mm256_mul_ps(two, pc)), pb), k->qa),
                      _mm256_mul_ps(two, qc)), qb);
    const __m256 g = _mm256_sqrt_ps(_mm256_add_ps(_mm256_mul_ps(gx, gx), _mm256_mul_ps(gy, gy)));
    const __m256 o = _mm256_blend_ps(unit ? g : _mm256_add_ps(_mm256_mul_ps(mc, kp), _mm256_mul_ps(g, f)), mc,
                                     0x88); /* alpha kept */
    *bad = _mm256_max_epi32(*bad, _mm256_and_si256(_mm256_castps_si256(o), _mm256_set1_epi32(0x7f800000)));
    if (save)
        _mm256_storeu_ps(save + c, mc);
    _mm256_storeu_ps(out + c, o);
    k->pa = pb;
    k->ma2 = mb2;
    k->qa = qb;
}

/* The loop over [xa, xb) (xb - xa even, >= 2), two chunks per step. Returns non-zero when a
 * value came out NaN or Inf. */
__attribute__((target("avx2"), always_inline)) static inline int grad_loop_avx2(const float *P, const float *M,
                                                                                 const float *Q, int xa, int xb,
                                                                                 float fac, float keep, float *out,
                                                                                 float *save, int unit)
{
    const __m256 f = _mm256_set1_ps(fac), kp = _mm256_set1_ps(keep);
    __m256 two = _mm256_set1_ps(2.0f);
    __asm__("" : "+x"(two)); /* an opaque 2: gcc would turn 2 v into v + v, on the adders */
    __m256i bad = _mm256_setzero_si256();
    const size_t c0 = 4 * (size_t)xa;
    grad_carry k = { _mm256_loadu_ps(P + c0 - 4), _mm256_mul_ps(two, _mm256_loadu_ps(M + c0 - 4)),
                     _mm256_loadu_ps(Q + c0 - 4) };
    int x = xa;
    for (; x + 4 <= xb; x += 4) {
        _mm_prefetch((const char *)(P + 4 * (size_t)x + GRAD_PREFETCH), _MM_HINT_T0); /* a line a step */
        grad2_avx2(P, M, Q, 4 * (size_t)x, f, kp, two, unit, out, save, &k, &bad);
        grad2_avx2(P, M, Q, 4 * (size_t)x + 8, f, kp, two, unit, out, save, &k, &bad);
    }
    if (x < xb)
        grad2_avx2(P, M, Q, 4 * (size_t)x, f, kp, two, unit, out, save, &k, &bad);
    const __m256i e = _mm256_cmpeq_epi32(bad, _mm256_set1_epi32(0x7f800000));
    return !_mm256_testz_si256(e, e);
}

/* The four loops (factor 1 or not, in place or not). */
__attribute__((target("avx2"), noinline)) static int grad_row_avx2(const float *P, const float *M, const float *Q,
                                                                  int xa, int xb, float fac, float keep, float *out,
                                                                  float *save)
{
    if (fac == 1.0f)
        return save ? grad_loop_avx2(P, M, Q, xa, xb, fac, keep, out, save, 1)
                    : grad_loop_avx2(P, M, Q, xa, xb, fac, keep, out, NULL, 1);
    return save ? grad_loop_avx2(P, M, Q, xa, xb, fac, keep, out, save, 0)
                : grad_loop_avx2(P, M, Q, xa, xb, fac, keep, out, NULL, 0);
}
#endif

/* The baseline (no AVX2, or FX_NO_CLONES): grad2_avx2's loop one pixel per 4-lane vector
 * (core/simd4.h), the same operations lane by lane, so the same bits. */
static int grad_row_v4(const float *P, const float *M, const float *Q, int xa, int xb, float fac, float keep,
                       float *out, float *save)
{
    const v4i alpha = { 0, 0, 0, -1 }, expo = { 0x7f800000, 0x7f800000, 0x7f800000, 0x7f800000 };
    const v4f two = V4(2.0f);
    v4i bad = { 0, 0, 0, 0 };
    const size_t c0 = 4 * (size_t)xa;
    v4f pa = ld4(P + c0 - 4), ma2 = two * ld4(M + c0 - 4), qa = ld4(Q + c0 - 4);
    for (int x = xa; x < xb; x++) {
        const size_t c = 4 * (size_t)x;
        __builtin_prefetch(P + c + GRAD_PREFETCH);
        const v4f pc = ld4(P + c), pb = ld4(P + c + 4), mc = ld4(M + c), mb2 = two * ld4(M + c + 4);
        const v4f qc = ld4(Q + c), qb = ld4(Q + c + 4);
        const v4f gx = ((((pa - pb) + ma2) - mb2) + qa) - qb;
        const v4f gy = ((((pa + two * pc) + pb) - qa) - two * qc) - qb;
        const v4f g = sqrt4(gx * gx + gy * gy);
        const v4f o = sel4(alpha, mc, fac == 1.0f ? g : mc * V4(keep) + g * V4(fac));
        bad |= ((v4i)o & expo) == expo;
        if (save)
            st4(save + c, mc);
        st4(out + c, o);
        /* one pixel per step: the next pixel's left taps are this one's centre */
        pa = pc;
        ma2 = two * mc;
        qa = qc;
    }
    return (bad[0] | bad[1] | bad[2] | bad[3]) != 0;
}

/* Row y's columns [x0, x1) of the gradient into out; out may be M (in place: the vector
 * loops read columns x to x + 2 for pixel x, the left taps carried), then save gets M's
 * values in [x0 - 1, x1 + 1) (clamped) as they were, for the next row's Q. */
static void grad_row(const float *P, const float *M, const float *Q, int w, int x0, int x1, float fac,
                     float *out, float *save)
{
    const float keep = 1.0f - fac;
    /* the columns the vector loops leave (the image's first and last, where the taps clamp,
     * and an odd one) go through grad_px into t first, from the row as it was */
    int xa = x0 > 1 ? x0 : 1, xb = x1 < w - 1 ? x1 : w - 1;
    if (xb < xa)
        xa = xb = x1;
    xb = xa + ((xb - xa) & ~1);
    float t[4 * 4];
    int tx[4], nt = 0;
    for (int x = x0; x < xa; x++, nt++) {
        grad_px(P, M, Q, w, x, fac, keep, t + 4 * nt);
        tx[nt] = x;
    }
    for (int x = xb; x < x1; x++, nt++) {
        grad_px(P, M, Q, w, x, fac, keep, t + 4 * nt);
        tx[nt] = x;
    }
    const float *Morig = M;
    if (save) {
        /* the values the loops below do not save: [x0 - 1, xa) and [xb, x1 + 1) */
        const int s0 = x0 > 0 ? x0 - 1 : 0, s1 = x1 < w ? x1 + 1 : w;
        if (xa > s0)
            memcpy(save + 4 * (size_t)s0, M + 4 * (size_t)s0, (size_t)(xa - s0) * 4 * sizeof(float));
        if (s1 > xb)
            memcpy(save + 4 * (size_t)xb, M + 4 * (size_t)xb, (size_t)(s1 - xb) * 4 * sizeof(float));
        Morig = save;
    }
    int bad = 0;
    if (xb > xa) {
#ifdef EDGE_GRAD_AVX2
        if (__builtin_cpu_supports("avx2"))
            bad = grad_row_avx2(P, M, Q, xa, xb, fac, keep, out, save);
        else
#endif
            bad = grad_row_v4(P, M, Q, xa, xb, fac, keep, out, save);
    }
    for (int i = 0; i < nt; i++)
        memcpy(out + 4 * (size_t)tx[i], t + 4 * i, 4 * sizeof(float));
    if (bad)
        /* rare: NaN or Inf came out (a non-finite input or an overflow); those pixels again
         * from the row as it was (save, in place) */
        for (int x = xa; x < xb; x++)
            if (!finite4f(out + 4 * (size_t)x))
                grad_px_safe(P == M ? Morig : P, Morig, Q == M ? Morig : Q, w, x, fac, out + 4 * (size_t)x);
}

typedef struct grad_job {
    const float *src;
    float *dst;
    int w, h;
    fx_rect roi;
    float fac;
    int band;          /* rows per band */
    int in_place;      /* dst == src */
    /* in place: the rows yb - 1 and yb of each inner band boundary yb = roi.y0 + k band
     * (k = 1..bands-1) as they were, taken before the bands run (a band reads one row of
     * each neighbour, which that band may have written already) */
    float *saved;
    float **ring;      /* in place: per worker, two rows (the row above as it was) */
} grad_job;

/* Row y of the source as it was: the saved copy when another band owns it. */
static const float *grad_src_row(const grad_job *j, int y, int y0, int y1)
{
    const size_t rowf = 4 * (size_t)j->w;
    const int yb = y < y0 ? y0 : y >= y1 ? y1 : -1; /* an inner boundary's row, or -1 */
    if (j->in_place && yb > j->roi.y0 && yb < j->roi.y1)
        return j->saved + ((size_t)((yb - j->roi.y0) / j->band - 1) * 2 + (y < y0 ? 0 : 1)) * rowf;
    return j->src + (size_t)y * rowf;
}

static void grad_bands(void *user, int begin, int end, int worker)
{
    const grad_job *j = user;
    const int w = j->w, h = j->h;
    const size_t rowf = 4 * (size_t)w;
    for (int band = begin; band < end; band++) {
        const int y0 = j->roi.y0 + band * j->band;
        const int y1 = y0 + j->band < j->roi.y1 ? y0 + j->band : j->roi.y1;
        const float *above = NULL; /* in place: row y - 1 as it was (the ring) */
        for (int y = y0; y < y1; y++) {
            const int ya = y > 0 ? y - 1 : 0, yb = y + 1 < h ? y + 1 : h - 1;
            const float *M = j->src + (size_t)y * rowf;
            /* Q the row above, P the row below (see the block comment) */
            const float *Q = ya == y ? M : above ? above : grad_src_row(j, ya, y0, y1);
            const float *P = yb == y ? M : grad_src_row(j, yb, y0, y1);
            float *save = j->in_place ? j->ring[worker] + (size_t)(y & 1) * rowf : NULL;
            grad_row(P, M, Q, w, j->roi.x0, j->roi.x1, j->fac, j->dst + (size_t)y * rowf, save);
            above = save;
        }
    }
}

fx_result fx_edge_gradient(fx_context *ctx, const float *src, float *dst, int w, int h, const fx_rect *roi_in,
                           float factor, const char *where)
{
    fx_rect roi = roi_in ? grow(roi_in, 0, w, h) : (fx_rect){ 0, 0, w, h };
    if (roi.x1 <= roi.x0 || roi.y1 <= roi.y0)
        return FX_OK;
    grad_job j;
    memset(&j, 0, sizeof j);
    j.src = src;
    j.dst = dst;
    j.w = w;
    j.h = h;
    j.roi = roi;
    j.fac = factor;
    j.in_place = dst == src;
    const int workers = fx_parallel_workers(ctx);
    const int rows = roi.y1 - roi.y0;
    /* a few bands per worker for balance; in place each inner boundary costs two saved
     * rows (and fresh pages for them), so two per worker there (the bits do not depend on
     * the bands) */
    int bands = workers > 1 ? (j.in_place ? 2 : 4) * workers : 1;
    if (bands > (rows + 15) / 16)
        bands = (rows + 15) / 16;
    if (bands < 1)
        bands = 1;
    j.band = (rows + bands - 1) / bands;
    bands = (rows + j.band - 1) / j.band;
    const size_t rowf = 4 * (size_t)w;
    fx_result r = FX_OK;
    if (j.in_place) {
        if (bands > 1 && !(j.saved = fx_mem_alloc((size_t)(bands - 1) * 2 * rowf * sizeof(float))))
            r = fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the gradient rows", where);
        if (!r && !(j.ring = fx_mem_calloc((size_t)workers, sizeof *j.ring)))
            r = fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the gradient rows", where);
        for (int i = 0; !r && i < workers; i++)
            if (!(j.ring[i] = fx_mem_alloc(2 * rowf * sizeof(float))))
                r = fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the gradient rows", where);
        for (int k = 1; !r && k < bands; k++) {
            const int yb = roi.y0 + k * j.band;
            float *sv = j.saved + (size_t)(k - 1) * 2 * rowf;
            memcpy(sv, src + (size_t)(yb - 1) * rowf, rowf * sizeof(float));
            memcpy(sv + rowf, src + (size_t)yb * rowf, rowf * sizeof(float));
        }
    }
    if (!r)
        fx_parallel_for_worker(ctx, bands, 1, grad_bands, &j);
    if (j.ring)
        for (int i = 0; i < workers; i++)
            fx_mem_free(j.ring[i]);
    fx_mem_free(j.ring);
    fx_mem_free(j.saved);
    return r;
}
