/* cel_shading: the seed's q-map: a 1-D ramp (N bands, or a user ramp) applied to diffuse
 * lighting, times Sobel outlines from depth and normals (math/edge_ops.c).
 * Lighting "diffuse_passes" (Cycles' Diffuse Direct and Color; Eevee's Diffuse Light and
 * Color): the direct diffuse term DiffCol x DiffDir is replaced by DiffCol x q(l) x tint with
 * l = luminance(DiffDir) / white and tint = DiffDir / luminance (the light's colour), so
 * textures, indirect light, gloss and emission survive. Lighting "normal_light": l = N.L
 * from the Normal pass and the sun (the scene sidecar's light, or a direction), and
 * Combined is scaled by (ambient + q(l)) / (ambient + l). docs/effects/cel_shading.md. */
#include "core/effect.h"
#include "scene/lights.h"
#include "core/parallel.h"
#include "math/color.h"
#include "math/edge_ops.h"
#include "math/vec.h"
#include "core/simd4.h"
#include "core/simd8.h"
#include "math/clones.h"

#include <float.h>
#include <stdint.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#define RAMP_MAX 8

typedef struct cel_params {
    int lighting;
    int bands;
    int ramp_mode;
    float ramp[RAMP_MAX];
    float band_softness;
    float white;
    char light[FX_STRING_PARAM_MAX];
    float direction[3];
    int use_direction;
    float ambient;
    float outline_width;
    float outline_color[4];
    float depth_sensitivity, normal_sensitivity;
    int depth_mode;
    float mix;
} cel_params;

enum { LIGHT_DIFFUSE_PASSES = 0, LIGHT_NORMAL };
enum { RAMP_BANDS = 0, RAMP_CUSTOM };

static const char *const lighting_items[] = { "diffuse_passes", "normal_light" };
static const char *const depth_mode_items[] = FX_EDGE_DEPTH_MODE_ITEMS;
static const char *const ramp_items[] = { "bands", "custom" };
static const float ramp_default[RAMP_MAX] = { 0.0f, 0.35f, 0.7f, 1.0f, 1.0f, 1.0f, 1.0f, 1.0f };
static const float dir_default[3] = { 0.3f, 0.4f, -0.87f };
static const float black4[4] = { 0, 0, 0, 1 };

static const fx_param_def cel_param_defs[] = {
    FX_P_ENUM(cel_params, lighting, "lighting", LIGHT_DIFFUSE_PASSES, lighting_items,
              "diffuse_passes: re-band the DiffDir pass under DiffCol (textures survive; Cycles or Eevee "
              "with the diffuse passes on); normal_light: N.L from the Normal pass and the sun"),
    FX_P_INT(cel_params, bands, "bands", 3, 1, RAMP_MAX, 2, RAMP_MAX, "", "Number of bands of the ramp"),
    FX_P_ENUM(cel_params, ramp_mode, "ramp_mode", RAMP_BANDS, ramp_items,
              "bands: band k of N has the value k/(N-1); custom: band k takes ramp[k]"),
    FX_P_FLOATS(cel_params, ramp, "ramp", RAMP_MAX, ramp_default, 0.0, 100.0, "",
                "ramp_mode custom: the value of each band (the first `bands` entries)"),
    FX_P_FLOAT(cel_params, band_softness, "band_softness", 0.02, 0.0, 0.5, 0.0, 0.1, "",
               "Width of the transition between bands, in lighting units (anti-aliases band edges)"),
    FX_P_FLOAT(cel_params, white, "white", 1.0, 1e-6, 65504.0, 0.1, 10.0, "",
               "Lighting mapped to the top of the ramp (diffuse_passes: luminance of DiffDir)"),
    FX_P_STRING(cel_params, light, "light", "", "",
                "normal_light: the light's name in the scene sidecar (empty: the first sun)"),
    FX_P_BOOL(cel_params, use_direction, "use_direction", 0,
              "normal_light: use the direction parameter instead of the scene's light"),
    FX_P_FLOATS(cel_params, direction, "direction", 3, dir_default, -1e6, 1e6, "",
                "normal_light: world direction the light travels (with use_direction)"),
    FX_P_FLOAT(cel_params, ambient, "ambient", 0.15, 0.0, 10.0, 0.0, 1.0, "",
               "normal_light: light that N.L does not model (keeps shadow sides from going black)"),
    FX_P_FLOAT(cel_params, outline_width, "outline_width", 2.0, 0.0, 64.0, 0.0, 8.0, "pixels",
               "Outline thickness; 0: no outlines"),
    FX_P_FLOATS(cel_params, outline_color, "outline_color", 4, black4, -65504.0, 65504.0, "color", "Outline colour"),
    FX_P_FLOAT(cel_params, depth_sensitivity, "depth_sensitivity", 10.0, 0.0, 1e6, 0.0, 50.0, "",
               "Outlines where depth jumps by more than 1/sensitivity (relative); 0: off"),
    FX_P_FLOAT(cel_params, normal_sensitivity, "normal_sensitivity", 0.5, 0.0, 1.0, 0.0, 1.0, "factor",
               "Outlines where normals turn by more than 90 x (1 - sensitivity) degrees; 0: off"),
    FX_P_ENUM(cel_params, depth_mode, "depth_mode", 1, depth_mode_items,
              "Depth outlines: planar (default): second differences of 1/depth, no lines along floors or "
              "the sea's horizon; relative: Sobel of ln(depth) (math/edge_ops.h)"),
    FX_P_FLOAT(cel_params, mix, "mix", 1.0, 0.0, 1.0, 0.0, 1.0, "factor", "0: the identity; 1: the full effect"),
};

static void edge_settings(const cel_params *p, fx_edge_settings *s)
{
    memset(s, 0, sizeof *s);
    s->op = FX_EDGE_SOBEL;
    s->use_depth = p->outline_width > 0.0f && p->depth_sensitivity > 0.0f;
    s->use_normal = p->outline_width > 0.0f && p->normal_sensitivity > 0.0f;
    s->depth_threshold = p->depth_sensitivity > 0.0f ? 1.0f / p->depth_sensitivity : 0.0f;
    s->normal_threshold = 90.0f * (1.0f - p->normal_sensitivity);
    s->softness = 0.5f;
    s->line_width = p->outline_width;
    s->depth_planar = p->depth_mode == 1;
}

static fx_pass_set cel_passes(const void *params)
{
    const cel_params *p = params;
    if (!(p->mix > 0.0f))
        return 0;
    fx_edge_settings s;
    edge_settings(p, &s);
    fx_pass_set set = fx_edge_passes(&s);
    if (p->lighting == LIGHT_DIFFUSE_PASSES)
        set |= FX_PASS_BIT(FX_PASS_DIFF_DIR) | FX_PASS_BIT(FX_PASS_DIFF_COL);
    else
        set |= FX_PASS_BIT(FX_PASS_NORMAL);
    return set;
}

static int cel_halo(const void *params, int w, int h)
{
    (void)w;
    (void)h;
    fx_edge_settings s;
    edge_settings(params, &s);
    return fx_edge_halo(&s);
}

typedef struct cel_job {
    const fx_effect_run *run;
    const cel_params *p;
    const float *diff_dir, *diff_col, *normal;
    int dd_ch, dc_ch;
    fx_vec3 to_light;
    float values[RAMP_MAX];
    float band_lo[RAMP_MAX]; /* band k's smoothstep starts here (edge k/n - softness/2) */
    float band_inv;          /* 1 / softness (0: hard bands) */
    float outline_weight;    /* 1; on a proxy, outlines under a pixel drawn lighter (edges.c's proxy_adjust) */
    int n;
} cel_job;

/* The ramp q(t), t = lighting / white: band floor(t N) with smooth steps of width soft. */
/* The ramp at t: values[0] plus each band step, smoothed over band_softness around the
 * edges k/n (a smoothstep without a division: (t - lo) / softness, clamped). */
static inline float ramp_q(const cel_job *j, float t)
{
    const int n = j->n;
    if (n <= 1)
        return j->values[0];
    float v = j->values[0];
    if (j->band_inv > 0.0f) {
        for (int k = 1; k < n; k++) {
            float u = (t - j->band_lo[k]) * j->band_inv;
            u = u > 0.0f ? (u < 1.0f ? u : 1.0f) : 0.0f;
            v += u * u * (3.0f - 2.0f * u) * (j->values[k] - j->values[k - 1]);
        }
    } else {
        for (int k = 1; k < n; k++)
            v += (t >= (float)k / (float)n ? 1.0f : 0.0f) * (j->values[k] - j->values[k - 1]);
    }
    return v;
}

/* GCC vector helpers: one RGBA pixel per v4f (SSE2 in the baseline build). */

static inline v4f load3(const float *p, int ch) /* 3 channels (of ch >= 3), lane 3 = 0 */
{
    v4f v = { p[0], p[1], p[2], 0.0f };
    (void)ch;
    return v;
}

/* diffuse_passes: one vector per pixel (same formula as the scalar statement in the doc);
 * matte: the row's outline matte (indexed by x), or NULL. */
/* 8 pixels in lanes (math/simd8.h; an AVX2 clone beside the baseline, no FMA: the same
 * bits): the statement of cel_row_diffuse_px below, lane by lane, with selects. */
static inline __attribute__((always_inline)) v8f ramp_q8(const cel_job *j, v8f t)
{
    const int n = j->n;
    if (n <= 1)
        return S8(j->values[0]);
    v8f v = S8(j->values[0]);
    if (j->band_inv > 0.0f) {
        for (int k = 1; k < n; k++) {
            v8f u = (t - S8(j->band_lo[k])) * S8(j->band_inv);
            u = SEL8(u > S8(0.0f), SEL8(u < S8(1.0f), u, S8(1.0f)), S8(0.0f));
            v += u * u * (S8(3.0f) - S8(2.0f) * u) * S8(j->values[k] - j->values[k - 1]);
        }
    } else {
        for (int k = 1; k < n; k++)
            v += SEL8(t >= S8((float)k / (float)n), S8(1.0f), S8(0.0f)) * S8(j->values[k] - j->values[k - 1]);
    }
    return v;
}

/* 8 pixels of ch >= 3 channels: the first 3 into out[0..2] (out[3] = 0). */
static inline __attribute__((always_inline)) void gather8x3(const float *p, int ch, v8f out[4])
{
    float L[3][8];
    for (int k = 0; k < 8; k++)
        for (int c = 0; c < 3; c++)
            L[c][k] = p[ch * k + c];
    for (int c = 0; c < 3; c++)
        memcpy(&out[c], L[c], sizeof out[c]);
    out[3] = (v8f){ 0 };
}

/* One pixel (the tail of a row): the per-pixel statement. */
static inline void cel_row_diffuse_px(const cel_job *j, int y, int x, const float *matte)
{
    const fx_effect_run *run = j->run;
    const cel_params *p = j->p;
    const float inv_white = 1.0f / p->white, white = p->white, mix = p->mix;
    v4f oc;
    memcpy(&oc, p->outline_color, sizeof oc);
    const size_t i = (size_t)y * run->width + x;
    v4f s;
    memcpy(&s, run->src + i * 4, sizeof s);
    const v4f c = finite4(s);
    v4f l3 = finite4(load3(j->diff_dir + i * j->dd_ch, j->dd_ch));
    l3 = sel4(l3 > V4(0.0f), l3, V4(0.0f));
    const float l = fx_luminance(l3[0], l3[1], l3[2]);
    const float l_c = l < 1e30f ? l : 1e30f;
    const float q = ramp_q(j, l_c * inv_white) * white;
    const v4f col = finite4(load3(j->diff_col + i * j->dc_ch, j->dc_ch));
    const v4f tint = l > 1e-8f ? l3 * V4(1.0f / l) : V4(1.0f); /* the light's colour */
    v4f o = c + col * (V4(q) * tint - l3); /* lane 3: c + 0 */
    if (matte) {
        const float e = matte[x] * j->outline_weight;
        o += V4(e) * (oc - o); /* lane 3: alpha toward the outline's alpha */
    }
    o = finite4(c + V4(mix) * (o - c));
    if (!matte)
        o[3] = c[3];
    memcpy(run->dst + i * 4, &o, sizeof o);
}

/* diffuse_passes: matte: the row's outline matte (indexed by x), or NULL. */
FX_CLONES static void cel_row_diffuse(const cel_job *j, int y, const float *matte)
{
    const fx_effect_run *run = j->run;
    const cel_params *p = j->p;
    const float inv_white = 1.0f / p->white, white = p->white, mix = p->mix;
    const int dd = j->dd_ch, dc = j->dc_ch;
    const size_t row = (size_t)y * run->width;
    int x = run->roi.x0;
    for (; x + 8 <= run->roi.x1; x += 8) {
        const float *sp = run->src + (row + x) * 4, *lp = j->diff_dir + (row + x) * dd, *cp = j->diff_col + (row + x) * dc;
        v8f c[4], l3[4], col[4];
        fx_load8x4(sp, c);
        if (dd == 4)
            fx_load8x4(lp, l3);
        else
            gather8x3(lp, dd, l3);
        if (dc == 4)
            fx_load8x4(cp, col);
        else
            gather8x3(cp, dc, col);
        for (int ch = 0; ch < 4; ch++)
            c[ch] = fx_finite8(c[ch]);
        for (int ch = 0; ch < 3; ch++) {
            l3[ch] = fx_finite8(l3[ch]);
            l3[ch] = SEL8(l3[ch] > S8(0.0f), l3[ch], S8(0.0f));
            col[ch] = fx_finite8(col[ch]);
        }
        const v8f l = S8(FX_LUMA_R) * l3[0] + S8(FX_LUMA_G) * l3[1] + S8(FX_LUMA_B) * l3[2];
        const v8f l_c = SEL8(l < S8(1e30f), l, S8(1e30f));
        const v8f q = ramp_q8(j, l_c * S8(inv_white)) * S8(white);
        const v8i lit = l > S8(1e-8f);
        const v8f il = S8(1.0f) / SEL8(lit, l, S8(1.0f));
        v8f o[4];
        for (int ch = 0; ch < 3; ch++) {
            const v8f tint = SEL8(lit, l3[ch] * il, S8(1.0f));
            o[ch] = c[ch] + col[ch] * (q * tint - l3[ch]);
        }
        {   /* lane 3 of the per-pixel statement: colour and lighting alpha are 0 */
            const v8f t3 = SEL8(lit, S8(0.0f) * il, S8(1.0f));
            o[3] = c[3] + S8(0.0f) * (q * t3 - S8(0.0f));
        }
        if (matte) {
            v8f e;
            memcpy(&e, matte + x, sizeof e);
            e = e * S8(j->outline_weight);
            for (int ch = 0; ch < 4; ch++)
                o[ch] += e * (S8(p->outline_color[ch]) - o[ch]);
        }
        for (int ch = 0; ch < 4; ch++)
            o[ch] = fx_finite8(c[ch] + S8(mix) * (o[ch] - c[ch]));
        if (!matte)
            o[3] = c[3];
        fx_store8x4(run->dst + (row + x) * 4, o);
    }
    for (; x < run->roi.x1; x++)
        cel_row_diffuse_px(j, y, x, matte);
}

/* One row of the result; matte: the row's outline matte (indexed by x), or NULL. */
static void cel_row(void *user, int y, const float *matte)
{
    const cel_job *j = user;
    const fx_effect_run *run = j->run;
    const cel_params *p = j->p;
    if (p->lighting == LIGHT_DIFFUSE_PASSES) {
        cel_row_diffuse(j, y, matte);
        return;
    }
    const float inv_white = 1.0f / p->white;
    {
        for (int x = run->roi.x0; x < run->roi.x1; x++) {
            size_t i = (size_t)y * run->width + x;
            const float *s = run->src + i * 4;
            float *d = run->dst + i * 4;
            float c[3] = { fx_finitef(s[0]), fx_finitef(s[1]), fx_finitef(s[2]) };
            float o[3] = { c[0], c[1], c[2] };
            {
                const float *nn = j->normal + i * 3;
                fx_vec3 n = fx_v3_normalize_or(fx_v3(fx_finitef(nn[0]), fx_finitef(nn[1]), fx_finitef(nn[2])), fx_v3(0, 0, 0));
                if (fx_v3_dot(n, n) > 0.5f) {
                    float l = fx_saturate(fx_v3_dot(n, j->to_light));
                    float q = ramp_q(j, l * inv_white) * p->white;
                    float ratio = (p->ambient + q) / (p->ambient + l + 1e-6f);
                    for (int k = 0; k < 3; k++)
                        o[k] = c[k] * ratio;
                }
            }
            if (matte) {
                float e = matte[x] * j->outline_weight;
                for (int k = 0; k < 3; k++)
                    o[k] += e * (p->outline_color[k] - o[k]);
            }
            for (int k = 0; k < 3; k++)
                d[k] = fx_finitef(c[k] + p->mix * (o[k] - c[k]));
            float a = fx_finitef(s[3]);
            d[3] = matte ? fx_finitef(a + p->mix * (matte[x] * j->outline_weight) * (p->outline_color[3] - a)) : a;
        }
    }
}

static void cel_rows(void *user, int begin, int end)
{
    const cel_job *j = user;
    for (int y = j->run->roi.y0 + begin; y < j->run->roi.y0 + end; y++)
        cel_row(user, y, NULL);
}

/* Zero strength is the identity: the stack skips the effect. */
static int cel_identity(const void *params)
{
    const cel_params *p = params;
    return !(p->mix > 0.0f);
}

static fx_result cel_process(const fx_effect_run *run)
{
    const cel_params *p = run->params;
    const fx_rect *roi = &run->roi;
    const char *where = run->where;
    cel_job j;
    memset(&j, 0, sizeof j);
    j.run = run;
    j.p = p;
    j.n = p->bands;
    j.band_inv = p->band_softness > 0.0f ? 1.0f / p->band_softness : 0.0f;
    for (int k = 0; k < RAMP_MAX; k++)
        j.band_lo[k] = (float)k / (float)(j.n > 0 ? j.n : 1) - 0.5f * p->band_softness;
    for (int k = 0; k < j.n; k++)
        j.values[k] = p->ramp_mode == RAMP_CUSTOM ? p->ramp[k] : (j.n > 1 ? (float)k / (float)(j.n - 1) : 1.0f);
    const fx_frame *f = run->frame;
    if (p->lighting == LIGHT_DIFFUSE_PASSES) {
        fx_pass *dd = fx_frame_find_pass(f, "DiffDir"), *dc = fx_frame_find_pass(f, "DiffCol");
        if (!dd || !dc)
            return fx_fail(run->ctx, FX_ERR_MISSING_PASS,
                           "%s: lighting diffuse_passes needs the %s pass (Diffuse %s), which the frame does "
                           "not have; enable it, or use lighting normal_light",
                           where, !dd ? "DiffDir" : "DiffCol", !dd ? "Direct / Light" : "Color");
        j.diff_dir = dd->data;
        j.dd_ch = dd->channels;
        j.diff_col = dc->data;
        j.dc_ch = dc->channels;
        if (j.dd_ch < 3 || j.dc_ch < 3)
            return fx_fail(run->ctx, FX_ERR_BAD_FILE, "%s: DiffDir/DiffCol need 3 channels", where);
    } else {
        fx_pass *n = fx_frame_find_pass(f, "Normal");
        if (!n || n->channels < 3)
            return fx_fail(run->ctx, FX_ERR_MISSING_PASS, "%s: lighting normal_light needs the Normal pass", where);
        j.normal = n->data;
        fx_vec3 dir;
        if (p->use_direction) {
            dir = fx_v3(p->direction[0], p->direction[1], p->direction[2]);
        } else {
            fx_light L;
            fx_result r = fx_frame_find_light(f, p->light, where, &L);
            if (r)
                return r;
            dir = L.direction;
        }
        j.to_light = fx_v3_normalize_or(fx_v3_scale(dir, -1.0f), fx_v3(0, 0, 1));
    }
    fx_edge_settings es;
    edge_settings(p, &es);
    j.outline_weight = 1.0f;
    if (run->proxy_factor > 1) {
        /* as edges.c's proxy_adjust: the width was divided, the engine draws 2 pixels at least */
        if (!es.depth_planar)
            es.depth_threshold *= (float)run->proxy_factor;
        if (p->outline_width < 1.0f)
            j.outline_weight = p->outline_width;
    }
    if (es.use_depth || es.use_normal) {
        /* the outline matte streams row by row into the shading: no frame-size plane */
        fx_edge_sources src;
        fx_result r = fx_edge_sources_from_frame(f, run->src, &es, &src, where);
        if (r)
            return r;
        return fx_edge_matte_rows(run->ctx, &src, &es, roi, NULL, cel_row, &j, where);
    }
    int rows = roi->y1 - roi->y0;
    fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), cel_rows, &j);
    return FX_OK;
}

static fx_result cel_validate(const void *params, char *err, size_t err_size)
{
    const cel_params *p = params;
    for (int i = 0; i < 4; i++)
        if (!isfinite(p->outline_color[i])) {
            snprintf(err, err_size, "outline_color[%d] is not finite", i);
            return FX_ERR_BAD_PARAM;
        }
    if (p->lighting == LIGHT_NORMAL && p->use_direction &&
        !(fabsf(p->direction[0]) + fabsf(p->direction[1]) + fabsf(p->direction[2]) > 1e-12f)) {
        snprintf(err, err_size, "direction is zero");
        return FX_ERR_BAD_PARAM;
    }
    return FX_OK;
}

const fx_effect_class fx_effect_cel_shading = {
    .name = "cel_shading",
    .doc = "Cel shading: a banded ramp over diffuse lighting (diffuse passes or N.L) with Sobel outlines from depth and normals",
    .params_size = sizeof(cel_params),
    .params = cel_param_defs,
    .param_count = FX_COUNT_OF(cel_param_defs),
    .presets = { NULL, NULL, NULL, NULL },
    .passes = cel_passes,
    .needs_camera = NULL,
    .halo = cel_halo,
    .validate = cel_validate,
    .process = cel_process,
    .identity = cel_identity,
    /* each pixel's shading reads only that pixel of the image (the outlines come from depth
     * and normals, never the colour): on a consumed frame the stack writes over the input
     * instead of faulting in a fresh frame-sized buffer (a process's first frame) */
    .flags = FX_EFFECT_IN_PLACE,
};
