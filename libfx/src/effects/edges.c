/* edges: outlines from colour luminance, relative depth jumps, normal angles and object /
 * material ID boundaries (the seed's Laplace M4/M8, Sobel, sparse 7x7), drawn over the
 * image or output as a matte; or (output gradient) the colour's Sobel gradient as Blender's
 * Filter node gives it. The operators live in math/edge_ops.c (shared with cel_shading and
 * the cel/edge mirror). docs/effects/edges.md. */
#include "core/effect.h"
#include "core/parallel.h"
#include "math/edge_ops.h"
#include "core/simd4.h"
#include "core/simd8.h"
#include "math/clones.h"

#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

typedef struct edges_params {
    int op;
    int luminance, depth, normal, object_id, material_id, id_source;
    float luminance_threshold, depth_threshold, normal_threshold, id_threshold;
    float softness, line_width;
    int depth_mode;
    float line_color[4];
    int output;
    float opacity;
} edges_params;

enum { OUT_OVER = 0, OUT_MATTE, OUT_GRADIENT };

static const char *const op_items[] = FX_EDGE_OPERATOR_ITEMS;
static const char *const id_items[] = { "cryptomatte", "index" };
static const char *const depth_mode_items[] = FX_EDGE_DEPTH_MODE_ITEMS;
static const char *const out_items[] = { "over", "matte", "gradient" };
static const float black4[4] = { 0, 0, 0, 1 };

static const fx_param_def edges_param_defs[] = {
    FX_P_ENUM(edges_params, op, "operator", FX_EDGE_SOBEL, op_items,
              "Kernel for luminance and depth: sobel (magnitude), sobel_x, sobel_y, laplace4 (M4), "
              "laplace8 (M8), sparse7 (8 taps 3 px away: thick depth outlines). Unit-step normalised"),
    FX_P_BOOL(edges_params, luminance, "luminance", 1, "Edges of the colour's luminance (sRGB-encoded)"),
    FX_P_FLOAT(edges_params, luminance_threshold, "luminance_threshold", 0.15, 0.0, 1000.0, 0.0, 1.0,
               "", "Encoded-luminance step that makes an edge"),
    FX_P_BOOL(edges_params, depth, "depth", 0, "Edges of the Depth pass, as relative depth jumps"),
    FX_P_FLOAT(edges_params, depth_threshold, "depth_threshold", 0.05, 0.0, 1000.0, 0.0, 1.0, "",
               "Relative depth jump ln(d1/d0) that makes an edge (0.05: 5%; scale-free)"),
    FX_P_ENUM(edges_params, depth_mode, "depth_mode", 0, depth_mode_items,
              "relative: the operator on ln(depth) (fires along planes seen at grazing angles too); "
              "planar: second differences of 1/depth, zero on any plane (no lines along floors or "
              "the sea's horizon), silhouettes and creases only"),
    FX_P_BOOL(edges_params, normal, "normal", 0, "Edges where the Normal pass turns"),
    FX_P_FLOAT(edges_params, normal_threshold, "normal_threshold", 30.0, 0.0, 180.0, 0.0, 90.0, "",
               "Angle in degrees between neighbouring normals that makes an edge"),
    FX_P_BOOL(edges_params, object_id, "object_id", 0, "Edges between objects"),
    FX_P_BOOL(edges_params, material_id, "material_id", 0, "Edges between materials"),
    FX_P_ENUM(edges_params, id_source, "id_source", FX_EDGE_ID_CRYPTOMATTE, id_items,
              "IDs from cryptomatte (both engines, coverage-aware at anti-aliased edges) or from the "
              "index passes IndexOB/IndexMA (Cycles only, hard)"),
    FX_P_FLOAT(edges_params, id_threshold, "id_threshold", 0.25, 0.0, 1.0, 0.0, 1.0, "factor",
               "Coverage difference between neighbours that makes an ID edge"),
    FX_P_FLOAT(edges_params, softness, "softness", 0.5, 0.0, 100.0, 0.0, 2.0, "",
               "Ramp from no line to full line, as a fraction of each threshold (0: hard)"),
    FX_P_FLOAT(edges_params, line_width, "line_width", 2.0, 0.0, 64.0, 1.0, 12.0, "pixels",
               "Line width; 2 is the operators' own width, wider lines grow by a disc"),
    FX_P_FLOATS(edges_params, line_color, "line_color", 4, black4, -65504.0, 65504.0, "color",
                "Line colour (RGBA) for output over"),
    FX_P_ENUM(edges_params, output, "output", OUT_OVER, out_items,
              "over: lines drawn over the image; matte: the edge matte as gray (alpha 1); gradient: "
              "Blender's Filter node (Sobel): per colour channel sqrt(gx^2 + gy^2) of the unnormalised "
              "Sobel kernels, borders extended, alpha kept (operator sobel only; edge sources, "
              "thresholds and lines do not apply)"),
    FX_P_FLOAT(edges_params, opacity, "opacity", 1.0, 0.0, 1.0, 0.0, 1.0, "factor",
               "Strength of the effect; 0 is the identity"),
};

static void settings_of(const edges_params *p, fx_edge_settings *s)
{
    memset(s, 0, sizeof *s);
    s->op = (fx_edge_operator)p->op;
    s->use_luminance = p->luminance;
    s->use_depth = p->depth;
    s->use_normal = p->normal;
    s->use_object = p->object_id;
    s->use_material = p->material_id;
    s->id_source = p->id_source;
    s->luminance_threshold = p->luminance_threshold;
    s->depth_threshold = p->depth_threshold;
    s->normal_threshold = p->normal_threshold;
    s->id_threshold = p->id_threshold;
    s->softness = p->softness;
    s->line_width = p->line_width;
    s->depth_planar = p->depth_mode == 1;
}

static fx_pass_set edges_passes(const void *params)
{
    if (((const edges_params *)params)->output == OUT_GRADIENT)
        return 0; /* the colour alone */
    fx_edge_settings s;
    settings_of(params, &s);
    return ((const edges_params *)params)->opacity > 0.0f ? fx_edge_passes(&s) : 0;
}

static int edges_halo(const void *params, int width, int height)
{
    (void)width;
    (void)height;
    if (((const edges_params *)params)->output == OUT_GRADIENT)
        return 1; /* the 3x3 kernels */
    fx_edge_settings s;
    settings_of(params, &s);
    return fx_edge_halo(&s);
}

typedef struct draw_job {
    const fx_effect_run *run;
    const edges_params *p;
    float *matte_dbg; /* the debug matte pass, or NULL */
    float opacity;    /* p->opacity, thinned on a proxy (proxy_adjust) */
} draw_job;

/* On a proxy (run->proxy_factor f > 1) the stack has divided line_width by f, but the engine
 * draws any width up to 2 at its operator's own 2 pixels. A line under one proxy pixel wide
 * is drawn lighter, by its width: it stays a visible stroke, not a faint band (lines of one
 * to two proxy pixels come out up to twice as wide as on the full frame). Relative depth
 * jumps between neighbours grow with the pixel step (the sea towards the horizon): the
 * threshold grows with it, or the proxy draws lines along planes the full frame leaves
 * clean. Returns the opacity to draw with. */
static float proxy_adjust(const fx_effect_run *run, const edges_params *p, fx_edge_settings *s)
{
    const int f = run->proxy_factor;
    if (f <= 1)
        return p->opacity;
    if (!s->depth_planar)
        s->depth_threshold *= (float)f;
    return p->line_width < 1.0f ? p->opacity * (p->line_width > 0.0f ? p->line_width : 0.0f) : p->opacity;
}

/* One pixel of draw_row's "over" case. */
static inline void draw_px(const float *srow, float *drow, const float *matte, int x, float op, v4f lc,
                           int in_place)
{
    const v4f big = { FLT_MAX, FLT_MAX, FLT_MAX, FLT_MAX };
    const v4f s = ld4(srow + 4 * (size_t)x);
    const float a = matte[x] * op;
    if (a == 0.0f) {
        /* no line: the pixel as it is (made finite) */
        const v4i ok = (s == s) & (s <= big) & (s >= -big);
        if (all4(ok)) {
            if (!in_place)
                st4(drow + 4 * (size_t)x, s);
            return;
        }
    }
    st4(drow + 4 * (size_t)x, finite4(s + V4(a) * (lc - s)));
}

/* Eight-lane helpers for draw_row (core/simd8.h's types), in the clones below. */
static inline __attribute__((always_inline)) v8f ld8f(const float *p)
{
    v8f v;
    memcpy(&v, p, sizeof v);
    return v;
}


#if defined(__clang__)
#  define SHUF8I(a, i0, i1, i2, i3, i4, i5, i6, i7) __builtin_shufflevector(a, a, i0, i1, i2, i3, i4, i5, i6, i7)
#else
#  define SHUF8I(a, i0, i1, i2, i3, i4, i5, i6, i7) __builtin_shuffle(a, (v8i){ i0, i1, i2, i3, i4, i5, i6, i7 })
#endif

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(FX_NO_CLONES)
#  include <immintrin.h>
#  define EDGES_LIST_AVX2 1
/* draw_row's pass 1 in AVX2: the chunks of 8 pixels from x to x_end (whole chunks) with a
 * matte value other than 0 or a value whose exponent is all ones (Inf or NaN) go on the
 * list; the same chunks as the vector loop (the largest masked exponent of the 32 values
 * equals the all-ones one exactly when one of them does), with a test of the whole chunk
 * instead of the lanes taken apart. Returns the list's length. */
__attribute__((target("avx2"), noinline)) static int draw_list_avx2(const float *srow, const float *matte, int x,
                                                                   int x_end, int *list)
{
    const __m256i expo = _mm256_set1_epi32(0x7f800000);
    const __m256 zero = _mm256_setzero_ps();
    int nl = 0;
    for (; x < x_end; x += 8) {
        const float *sp = srow + 4 * (size_t)x;
        const __m256i e0 = _mm256_and_si256(_mm256_loadu_si256((const __m256i *)(const void *)sp), expo);
        const __m256i e1 = _mm256_and_si256(_mm256_loadu_si256((const __m256i *)(const void *)(sp + 8)), expo);
        const __m256i e2 = _mm256_and_si256(_mm256_loadu_si256((const __m256i *)(const void *)(sp + 16)), expo);
        const __m256i e3 = _mm256_and_si256(_mm256_loadu_si256((const __m256i *)(const void *)(sp + 24)), expo);
        const __m256i e = _mm256_max_epi32(_mm256_max_epi32(e0, e1), _mm256_max_epi32(e2, e3));
        const __m256i any = _mm256_or_si256(_mm256_cmpeq_epi32(e, expo),
                                            _mm256_castps_si256(_mm256_cmp_ps(_mm256_loadu_ps(matte + x), zero,
                                                                              _CMP_NEQ_UQ)));
        list[nl] = x;
        nl += !_mm256_testz_si256(any, any);
    }
    return nl;
}
#endif

/* d = s + a (t - s) per pixel; NaN -> 0, +-Inf -> +-FLT_MAX. Where a is 0 and the pixel is
 * finite (most pixels) d = s: eight such pixels in a row are not written at all in place (the
 * cache lines stay clean: no write back). Eight pixels at a time as four vectors of two
 * pixels each, draw_px's operations lane by lane (the same bits), the rest per pixel. Called
 * by the edge engine with each finished matte row (math/edge_ops.h). The source is read again
 * after the copy of a row not in place: src and dst are different buffers then. */
FX_CLONES static void draw_row(void *user, int y, const float *matte)
{
    const draw_job *j = user;
    const fx_effect_run *run = j->run;
    const fx_rect *roi = &run->roi;
    const float op = j->opacity;
    const int matte_out = j->p->output == OUT_MATTE;
    const int in_place = run->dst == run->src;
    v4f lc;
    memcpy(&lc, j->p->line_color, sizeof lc);
    const size_t row = (size_t)y * run->width;
    const float *srow = run->src + row * 4;
    float *drow = run->dst + row * 4;
    if (j->matte_dbg)
        memcpy(j->matte_dbg + row + roi->x0, matte + roi->x0, (size_t)(roi->x1 - roi->x0) * sizeof(float));
    if (matte_out) {
        for (int x = roi->x0; x < roi->x1; x++) {
            const float e = matte[x];
            const v4f s = ld4(srow + 4 * x), t = { e, e, e, 1.0f };
            st4(drow + 4 * x, finite4(s + V4(op) * (t - s)));
        }
        return;
    }
    const v8f lc8 = { lc[0], lc[1], lc[2], lc[3], lc[0], lc[1], lc[2], lc[3] };
    const v8i expo = S8I(0x7f800000);
    /* Not in place: the row as it is first; the chunks with a line or a non-finite value are
     * then redone. Pass 1 lists those chunks without a branch (lines cross chunks at random:
     * a branch per chunk mispredicted); pass 2 blends them. */
    const int xe = roi->x0 + ((roi->x1 - roi->x0) & ~7);
    if (!in_place)
        memcpy(drow + 4 * (size_t)roi->x0, srow + 4 * (size_t)roi->x0, (size_t)(xe - roi->x0) * 4 * sizeof(float));
    enum { SEG = 256 }; /* chunks per list */
    int list[SEG];
    int x = roi->x0;
#ifdef EDGES_LIST_AVX2
    const int avx2 = __builtin_cpu_supports("avx2");
#endif
    while (x < xe) {
        int nl = 0;
        const int x_end = x + 8 * SEG <= xe ? x + 8 * SEG : xe;
#ifdef EDGES_LIST_AVX2
        if (avx2) {
            nl = draw_list_avx2(srow, matte, x, x_end, list);
            x = x_end;
        }
#endif
        for (; x < x_end; x += 8) {
            const float *sp = srow + 4 * (size_t)x;
            v8i any = ld8f(matte + x) != S8(0.0f);
            for (int k = 0; k < 4; k++)
                any |= ((v8i)ld8f(sp + 8 * k) & expo) == expo; /* Inf or NaN */
            list[nl] = x;
            nl += fx_any8(any);
        }
        for (int i = 0; i < nl; i++) {
            const int xc = list[i];
            const float *sp = srow + 4 * (size_t)xc;
            v8f s[4];
            v8i inf[4];
            for (int k = 0; k < 4; k++) {
                s[k] = ld8f(sp + 8 * k);
                inf[k] = ((v8i)s[k] & expo) == expo;
            }
            const v8f a8 = ld8f(matte + xc) * S8(op); /* the products draw_px takes, lane by lane */
            const int finite = !fx_any8(inf[0] | inf[1] | inf[2] | inf[3]);
            const v8f pair[4] = { FX_SHUF8(a8, a8, 0, 0, 0, 0, 1, 1, 1, 1), FX_SHUF8(a8, a8, 2, 2, 2, 2, 3, 3, 3, 3),
                                  FX_SHUF8(a8, a8, 4, 4, 4, 4, 5, 5, 5, 5), FX_SHUF8(a8, a8, 6, 6, 6, 6, 7, 7, 7, 7) };
            if (finite) {
                /* finite pixels: s + a (lc - s) is finite (a in [0, 1], |lc| <= 65504), fx_finite8
                 * would leave it as it is */
                for (int k = 0; k < 4; k++) {
                    const v8f a = pair[k];
                    const v8f o = SEL8(a == S8(0.0f), s[k], s[k] + a * (lc8 - s[k]));
                    memcpy(drow + 4 * (size_t)xc + 8 * k, &o, sizeof o);
                }
                continue;
            }
            for (int k = 0; k < 4; k++) {
                const v8f a = pair[k]; /* pixels 2k and 2k + 1's opacities, four lanes each */
                const v8f t = fx_finite8(s[k] + a * (lc8 - s[k]));
                /* a pixel stays as it is where a is 0 and its four values are finite */
                v8i keep = a == S8(0.0f);
                if (!finite) {
                    v8i bad = inf[k];
                    bad |= SHUF8I(bad, 1, 0, 3, 2, 5, 4, 7, 6);
                    bad |= SHUF8I(bad, 2, 3, 0, 1, 6, 7, 4, 5);
                    keep &= ~bad;
                }
                const v8f o = SEL8(keep, s[k], t);
                memcpy(drow + 4 * (size_t)xc + 8 * k, &o, sizeof o);
            }
        }
    }
    for (; x < roi->x1; x++)
        draw_px(srow, drow, matte, x, op, lc, in_place);
}

/* Zero opacity or no edge source is the identity: the stack skips the effect. */
static int edges_identity(const void *params)
{
    const edges_params *p = params;
    if (p->output == OUT_GRADIENT)
        return !(p->opacity > 0.0f); /* the gradient needs no edge source */
    return !(p->opacity > 0.0f) || !(p->luminance || p->depth || p->normal || p->object_id || p->material_id);
}

static fx_result edges_process(const fx_effect_run *run)
{
    const edges_params *p = run->params;
    const fx_rect *roi = &run->roi;
    const char *where = run->where;
    if (p->output == OUT_GRADIENT)
        /* factor = opacity, as Blender's Factor; on a proxy the same gradient of the proxy's
         * pixels (a sharp edge keeps its height; see docs/effects/edges.md) */
        return fx_edge_gradient(run->ctx, run->src, run->dst, run->width, run->height, roi, p->opacity, where);
    fx_edge_settings s;
    settings_of(p, &s);
    const float opacity = proxy_adjust(run, p, &s);
    fx_edge_sources src;
    fx_result r = fx_edge_sources_from_frame(run->frame, run->src, &s, &src, where);
    if (r)
        return r;
    src.rgba_written = run->dst == run->src; /* in place (edges_in_place) */
    fx_result dr = FX_OK;
    float *strengths = fx_effect_debug_pass(run, "strengths", 4, &dr);
    if (dr)
        return dr;
    float *matte = fx_effect_debug_pass(run, "matte", 1, &dr);
    if (dr)
        return dr;
    /* the matte streams row by row into the drawing: no frame-size plane */
    draw_job j = { run, p, matte, opacity };
    return fx_edge_matte_rows(run->ctx, &src, &s, roi, strengths, draw_row, &j, where);
}

/* In place (FX_EFFECT_IN_PLACE's contract: each pixel read before it is written) when the
 * edge engine can take the luminance of the rows where its bands meet first: a small halo. */
static int edges_in_place(const void *params)
{
    if (((const edges_params *)params)->output == OUT_GRADIENT)
        return 1; /* fx_edge_gradient keeps the rows it still reads */
    fx_edge_settings s;
    settings_of(params, &s);
    return fx_edge_halo(&s) <= FX_EDGE_IN_PLACE_MAX_HALO;
}

static fx_result edges_validate(const void *params, char *err, size_t err_size)
{
    const edges_params *p = params;
    for (int i = 0; i < 4; i++)
        if (!isfinite(p->line_color[i])) {
            snprintf(err, err_size, "line_color[%d] is not finite", i);
            return FX_ERR_BAD_PARAM;
        }
    if (p->output == OUT_GRADIENT && p->op != FX_EDGE_SOBEL) {
        snprintf(err, err_size, "operator must be sobel for output gradient (Blender's Filter Sobel), not %s",
                 op_items[p->op]);
        return FX_ERR_BAD_PARAM;
    }
    return FX_OK;
}

const fx_effect_class fx_effect_edges = {
    .name = "edges",
    .doc = "Outlines from luminance, relative depth, normals and object/material IDs (Sobel, Laplace, sparse 7x7), "
           "or the colour's Sobel gradient (Blender's Filter Sobel)",
    .params_size = sizeof(edges_params),
    .params = edges_param_defs,
    .param_count = FX_COUNT_OF(edges_param_defs),
    .presets = { NULL, NULL, NULL, NULL },
    .flags = FX_EFFECT_OWN_FINITE, /* draw_row writes finite values */
    .passes = edges_passes,
    .needs_camera = NULL,
    .in_place = edges_in_place,
    .halo = edges_halo,
    .validate = edges_validate,
    .process = edges_process,
    .identity = edges_identity,
};
