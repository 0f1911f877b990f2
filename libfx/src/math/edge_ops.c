/* Edge operators over render passes (math/edge_ops.h has the definitions). */
#include "math/edge_ops.h"

#include "core/parallel.h"
#include "math/color.h"
#include "math/srgb_lut.h"
#include "math/vec.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

int fx_edge_operator_radius(fx_edge_operator op)
{
    return op == FX_EDGE_SPARSE7 ? 3 : 1;
}

static inline int clampi(int v, int lo, int hi)
{
    return v < lo ? lo : v > hi ? hi : v;
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

/* ---- the work ---- */

typedef struct edge_job {
    const fx_edge_sources *src;
    const fx_edge_settings *s;
    int w, h;
    fx_rect field_rect;  /* where the luminance / log-depth fields are computed */
    fx_rect strength_rect; /* where the thresholded strength is computed */
    fx_rect roi;
    float *lum, *ldepth;  /* fields (full-size planes, filled inside field_rect) */
    float *unorm;         /* unit normals (3 per pixel; 0 0 0: background), inside field_rect */
    const float *lut;     /* sRGB encoding table (math/srgb_lut.h) */
    float *plane;         /* thresholded strength (full-size), when dilating */
    float *matte;
    float *strengths;
    const int *disc;      /* dilation offsets (dx, dy) pairs */
    int disc_count;
} edge_job;

/* Unit normal of pixel i, or 0 for background. */
static inline int unit_normal(const float *n, size_t i, float u[3])
{
    float x = n[3 * i], y = n[3 * i + 1], z = n[3 * i + 2];
    float l2 = x * x + y * y + z * z;
    if (!(l2 >= FX_EDGE_MIN_NORMAL * FX_EDGE_MIN_NORMAL) || !(l2 <= 1e30f))
        return 0;
    float inv = 1.0f / sqrtf(l2);
    u[0] = x * inv;
    u[1] = y * inv;
    u[2] = z * inv;
    return 1;
}

static void fields_rows(void *user, int begin, int end)
{
    const edge_job *j = user;
    const fx_rect *fr = &j->field_rect;
    for (int y = fr->y0 + begin; y < fr->y0 + end; y++) {
        size_t row = (size_t)y * j->w;
        if (j->lum) {
            const float *p = j->src->rgba + row * 4;
            for (int x = fr->x0; x < fr->x1; x++) {
                float l = fx_luminance(p[4 * x], p[4 * x + 1], p[4 * x + 2]);
                /* finite, clamped to the encoder's useful range (NaN -> 0) */
                l = l > 0.0f ? (l < 1e6f ? l : 1e6f) : 0.0f;
                j->lum[row + x] = fx_srgb_encode_lut(j->lut, l); /* no powf: math/srgb_lut.h */
            }
        }
        if (j->ldepth) {
            const float *d = j->src->depth + row;
            for (int x = fr->x0; x < fr->x1; x++) {
                float v = d[x];
                v = v > FX_EDGE_NEAR_DEPTH ? (v < FX_EDGE_FAR_DEPTH ? v : FX_EDGE_FAR_DEPTH)
                                           : (v == v ? FX_EDGE_NEAR_DEPTH : FX_EDGE_FAR_DEPTH);
                j->ldepth[row + x] = j->s->depth_planar ? 1.0f / v : logf(v);
            }
        }
        if (j->unorm) {
            const float *n = j->src->normal;
            for (int x = fr->x0; x < fr->x1; x++) {
                float u[3] = { 0.0f, 0.0f, 0.0f };
                unit_normal(n, row + x, u);
                memcpy(j->unorm + (row + x) * 3, u, sizeof u);
            }
        }
    }
}

/* Smallest cosine between the pixel's unit normal and its 4 neighbours' (from the plane of
 * unit normals), and whether surface and background meet there. */
static inline float normal_min_dot(const float *un, int w, int h, int x, int y, int *mixed)
{
    const float *c = un + ((size_t)y * w + x) * 3;
    const int hc = c[0] != 0.0f || c[1] != 0.0f || c[2] != 0.0f;
    const size_t nb[4] = { (size_t)y * w + clampi(x - 1, 0, w - 1), (size_t)y * w + clampi(x + 1, 0, w - 1),
                           (size_t)clampi(y - 1, 0, h - 1) * w + x, (size_t)clampi(y + 1, 0, h - 1) * w + x };
    float min_dot = 1.0f;
    int mx = 0;
    for (int k = 0; k < 4; k++) {
        const float *q = un + nb[k] * 3;
        const int hq = q[0] != 0.0f || q[1] != 0.0f || q[2] != 0.0f;
        if (hc != hq)
            mx = 1;
        else if (hc) {
            float d = c[0] * q[0] + c[1] * q[1] + c[2] * q[2];
            min_dot = d < min_dot ? d : min_dot;
        }
    }
    *mixed = mx;
    return min_dot;
}

static inline float normal_angle(float min_dot, int mixed)
{
    float a = acosf(fx_clampf(min_dot, -1.0f, 1.0f)) * (float)(180.0 / 3.14159265358979323846);
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

/* The operator on row y of a field for x in [x0, x1) into out[x]: the interior without any
 * clamping (the same expressions as fx_edge_response_at, so the same bits), the borders
 * through fx_edge_response_at. */
static void response_row(const float *f, int w, int h, int y, int x0, int x1, fx_edge_operator op, float *out)
{
    const int r = fx_edge_operator_radius(op);
    const float *A = f + (size_t)clampi(y - r, 0, h - 1) * w, *B = f + (size_t)y * w;
    const float *C = f + (size_t)clampi(y + r, 0, h - 1) * w;
    int xa = x0 > r ? x0 : r, xb = x1 < w - r ? x1 : w - r;
    if (xb < xa)
        xa = xb = x1;
    for (int x = x0; x < xa && x < x1; x++)
        out[x] = fx_edge_response_at(f, 1, w, h, x, y, op);
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
        out[x] = fx_edge_response_at(f, 1, w, h, x, y, op);
}

/* max of two non-NaN values, inline (fmaxf is a libm call here) */
static inline float maxf(float a, float b)
{
    return a > b ? a : b;
}

/* Planar depth strength at (x, y) (field: 1/depth, finite and > 0): see edge_ops.h. */
static inline float planar_at(const float *f, int w, int h, int x, int y)
{
    const float *B = f + (size_t)y * w;
    const float c = B[x];
    float sx = 0.0f, sy = 0.0f;
    if (x > 0 && x + 1 < w)
        sx = fabsf((B[x - 1] - c) + (B[x + 1] - c));
    if (y > 0 && y + 1 < h)
        sy = fabsf((B[x - w] - c) + (B[x + w] - c));
    float v = (sx > sy ? sx : sy) / c; /* x depth */
    return v <= FLT_MAX ? v : FLT_MAX;
}

static void planar_row(const float *f, int w, int h, int y, int x0, int x1, float *out)
{
    for (int x = x0; x < x1; x++)
        out[x] = planar_at(f, w, h, x, y);
}

static void strength_rows(void *user, int begin, int end)
{
    const edge_job *j = user;
    const fx_edge_settings *s = j->s;
    const fx_rect *sr = &j->strength_rect;
    const int w = j->w, h = j->h;
    const ramp_k rl = ramp_of(s->luminance_threshold, s->softness), rd = ramp_of(s->depth_threshold, s->softness);
    const ramp_k rn = ramp_of(s->normal_threshold, s->softness), ri = ramp_of(s->id_threshold, s->softness);
    /* normals turning by less than the threshold give 0 without an acos: cos(threshold)
     * plus a margin so that rounding never hides a value ramp() would make positive */
    const float cos_skip = cosf(fx_clampf(s->normal_threshold, 0.0f, 180.0f) * (float)(3.14159265358979323846 / 180.0)) + 1e-5f;
    float *sl_row = NULL, *sd_row = NULL;
    if (s->use_luminance)
        sl_row = fx_mem_alloc((size_t)w * sizeof(float));
    if (s->use_depth)
        sd_row = fx_mem_alloc((size_t)w * sizeof(float));
    for (int y = sr->y0 + begin; y < sr->y0 + end; y++) {
        const int in_roi_y = y >= j->roi.y0 && y < j->roi.y1;
        float *out = j->plane ? j->plane + (size_t)y * w : j->matte + (size_t)y * w;
        if (s->use_luminance) {
            if (sl_row)
                response_row(j->lum, w, h, y, sr->x0, sr->x1, s->op, sl_row);
        }
        if (s->use_depth) {
            if (sd_row && s->depth_planar)
                planar_row(j->ldepth, w, h, y, sr->x0, sr->x1, sd_row);
            else if (sd_row)
                response_row(j->ldepth, w, h, y, sr->x0, sr->x1, s->op, sd_row);
        }
        if (sl_row && sd_row && !s->use_normal && !s->use_object && !s->use_material && !j->strengths) {
            for (int x = sr->x0; x < sr->x1; x++) { /* the common cases: simple loops */
                float a = ramp(rl, sl_row[x]), b = ramp(rd, sd_row[x]);
                out[x] = a > b ? a : b;
            }
            continue;
        }
        if (sl_row && !s->use_depth && !s->use_normal && !s->use_object && !s->use_material && !j->strengths) {
            for (int x = sr->x0; x < sr->x1; x++)
                out[x] = ramp(rl, sl_row[x]);
            continue;
        }
        for (int x = sr->x0; x < sr->x1; x++) {
            float sl = 0, sd = 0, sn = 0, si = 0, e = 0;
            if (s->use_luminance) {
                sl = sl_row ? sl_row[x] : fx_edge_response_at(j->lum, 1, w, h, x, y, s->op);
                e = maxf(e, ramp(rl, sl));
            }
            if (s->use_depth) {
                if (sd_row)
                    sd = sd_row[x];
                else if (s->depth_planar)
                    sd = planar_at(j->ldepth, w, h, x, y);
                else
                    sd = fx_edge_response_at(j->ldepth, 1, w, h, x, y, s->op);
                e = maxf(e, ramp(rd, sd));
            }
            if (s->use_normal) {
                int mixed;
                float md = normal_min_dot(j->unorm, w, h, x, y, &mixed);
                if (mixed || md < cos_skip || j->strengths) {
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
            if (j->strengths && in_roi_y && x >= j->roi.x0 && x < j->roi.x1) {
                float *o = j->strengths + ((size_t)y * w + x) * 4;
                o[0] = sl;
                o[1] = sd;
                o[2] = sn;
                o[3] = si;
            }
        }
    }
    fx_mem_free(sl_row);
    fx_mem_free(sd_row);
}

static void dilate_rows(void *user, int begin, int end)
{
    const edge_job *j = user;
    const int w = j->w, h = j->h;
    for (int y = j->roi.y0 + begin; y < j->roi.y0 + end; y++) {
        float *out = j->matte + (size_t)y * w;
        for (int x = j->roi.x0; x < j->roi.x1; x++) {
            float m = 0.0f;
            for (int k = 0; k < j->disc_count; k++) {
                int xx = x + j->disc[2 * k], yy = y + j->disc[2 * k + 1];
                if (xx < 0 || yy < 0 || xx >= w || yy >= h)
                    continue;
                float v = j->plane[(size_t)yy * w + xx];
                m = v > m ? v : m;
            }
            out[x] = m;
        }
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

fx_result fx_edge_matte(fx_context *ctx, const fx_edge_sources *src, const fx_edge_settings *s,
                        const fx_rect *roi_in, float *matte, float *strengths, const char *where)
{
    const int w = src->width, h = src->height;
    fx_rect roi = roi_in ? *roi_in : (fx_rect){ 0, 0, w, h };
    roi = grow(&roi, 0, w, h);
    if (roi.x1 <= roi.x0 || roi.y1 <= roi.y0)
        return FX_OK;
    edge_job j;
    memset(&j, 0, sizeof j);
    j.src = src;
    j.s = s;
    j.w = w;
    j.h = h;
    j.roi = roi;
    j.matte = matte;
    j.strengths = strengths;
    const float rho = dilation_rho(s);
    const int reach = dilation_reach(rho);
    j.strength_rect = grow(&roi, reach, w, h);
    j.field_rect = grow(&j.strength_rect, fx_edge_operator_radius(s->op), w, h);
    const size_t n = (size_t)w * h;
    fx_result r = FX_OK;
    int disc[2 * (2 * 33 + 1) * (2 * 33 + 1)];
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
    if ((s->use_luminance && !(j.lum = fx_mem_alloc(n * sizeof(float)))) ||
        (s->use_depth && !(j.ldepth = fx_mem_alloc(n * sizeof(float)))) ||
        (s->use_normal && !(j.unorm = fx_mem_alloc(n * 3 * sizeof(float)))) ||
        (reach > 0 && !(j.plane = fx_mem_alloc(n * sizeof(float))))) {
        r = fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the edge planes", where);
        goto out;
    }
    if (j.lum)
        j.lut = fx_srgb_lut();
    /* field_rect (strength rect + the operator's radius >= 1) covers the normals' 4-neighbourhood too */
    if (j.lum || j.ldepth || j.unorm) {
        int rows = j.field_rect.y1 - j.field_rect.y0;
        fx_parallel_for(ctx, rows, fx_grain_for(ctx, rows), fields_rows, &j);
    }
    {
        int rows = j.strength_rect.y1 - j.strength_rect.y0;
        fx_parallel_for(ctx, rows, fx_grain_for(ctx, rows), strength_rows, &j);
    }
    if (reach > 0) {
        int c = 0;
        const float lim = (rho + 0.5f) * (rho + 0.5f);
        for (int dy = -reach; dy <= reach; dy++)
            for (int dx = -reach; dx <= reach; dx++)
                if ((float)(dx * dx + dy * dy) <= lim) {
                    disc[2 * c] = dx;
                    disc[2 * c + 1] = dy;
                    c++;
                }
        j.disc = disc;
        j.disc_count = c;
        int rows = roi.y1 - roi.y0;
        fx_parallel_for(ctx, rows, fx_grain_for(ctx, rows), dilate_rows, &j);
    }
out:
    fx_mem_free(j.lum);
    fx_mem_free(j.ldepth);
    fx_mem_free(j.unorm);
    fx_mem_free(j.plane);
    return r;
}
