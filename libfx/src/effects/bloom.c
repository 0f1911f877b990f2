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

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

typedef struct bloom_params {
    int mode;
    float threshold, knee, clamp_value;
    float middle_grey, scene_luminance;
    float radius;
    float level_sigma;
    float intensity;
    int composite;
} bloom_params;

enum { MODE_SOFT_KNEE = 0, MODE_SEED };
enum { COMP_ADD = 0, COMP_SCREEN };
#define MAX_LEVELS 16

static const char *const mode_items[] = { "soft_knee", "seed" };
static const char *const comp_items[] = { "add", "screen" };

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
    FX_P_FLOAT(bloom_params, level_sigma, "level_sigma", 1.25, 0.0, 8.0, 0.5, 3.0, "pixels",
               "Gaussian sigma of each level's blur, in that level's pixels (smoothness)"),
    FX_P_FLOAT(bloom_params, intensity, "intensity", 0.5, 0.0, 100.0, 0.0, 2.0, "",
               "Strength of the glow; 0 is the identity"),
    FX_P_ENUM(bloom_params, composite, "composite", COMP_ADD, comp_items,
              "add: colour + glow; screen (the seed's): colour + glow x (1 - min(colour, 1))"),
};

typedef struct level {
    int w, h;
    float *px; /* RGBA (A unused, 0) */
} level;

typedef struct bloom_job {
    const fx_effect_run *run;
    const bloom_params *p;
    float exposure; /* seed: middle_grey / scene luminance */
    level lv[MAX_LEVELS + 1];
    int nlev;
    int from, to;   /* the levels a step reads and writes */
    double *row_sums;
} bloom_job;

static inline float finite_or(float v)
{
    v = v == v ? v : 0.0f;
    return v > FLT_MAX ? FLT_MAX : v < -FLT_MAX ? -FLT_MAX : v;
}

static inline float clamp_in(float v, float hi)
{
    return v > 0.0f ? (v < hi ? v : hi) : 0.0f; /* NaN -> 0 */
}

/* The bright pass of one pixel (rgb finite, >= 0 after clamping). */
static inline void bright(const bloom_job *j, const float *s, float out[3])
{
    const bloom_params *p = j->p;
    float c[3] = { clamp_in(s[0], p->clamp_value), clamp_in(s[1], p->clamp_value), clamp_in(s[2], p->clamp_value) };
    if (p->mode == MODE_SOFT_KNEE) {
        float b = fmaxf(c[0], fmaxf(c[1], c[2]));
        float t = p->threshold, k = t * p->knee + 1e-5f;
        float soft = b - t + k;
        soft = soft > 0.0f ? (soft < 2.0f * k ? soft : 2.0f * k) : 0.0f;
        soft = soft * soft / (4.0f * k + 1e-5f);
        float contrib = fmaxf(soft, b - t) / fmaxf(b, 1e-5f);
        contrib = contrib > 0.0f ? (contrib < 1.0f ? contrib : 1.0f) : 0.0f;
        for (int k2 = 0; k2 < 3; k2++)
            out[k2] = c[k2] * contrib;
    } else {
        double t2 = (double)p->threshold * p->threshold;
        t2 = t2 > 1e-12 ? t2 : 1e-12;
        for (int k2 = 0; k2 < 3; k2++) {
            double x = (double)c[k2] * j->exposure;
            x = x * (1.0 + x / t2);
            x -= 0.5;
            x = x > 0.0 ? x : 0.0;
            out[k2] = (float)(x < 1e300 ? x / (1.0 + x) : 1.0); /* < 1, finite */
        }
    }
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

/* Level `to` from level `from` (from == 0: the source through the bright pass). */
static void down_rows(void *user, int begin, int end)
{
    const bloom_job *j = user;
    const fx_effect_run *run = j->run;
    const int sw = j->from == 0 ? run->width : j->lv[j->from].w;
    const int sh = j->from == 0 ? run->height : j->lv[j->from].h;
    const level *d = &j->lv[j->to];
    for (int y = begin; y < end; y++) {
        int y0 = 2 * y, y1 = 2 * y + 1 < sh ? 2 * y + 1 : sh - 1;
        for (int x = 0; x < d->w; x++) {
            int x0 = 2 * x, x1 = 2 * x + 1 < sw ? 2 * x + 1 : sw - 1;
            float acc[3] = { 0, 0, 0 };
            const int xs[2] = { x0, x1 }, ys[2] = { y0, y1 };
            for (int a = 0; a < 2; a++)
                for (int b = 0; b < 2; b++) {
                    float c[3];
                    if (j->from == 0) {
                        bright(j, run->src + ((size_t)ys[a] * sw + xs[b]) * 4, c);
                    } else {
                        const float *s = j->lv[j->from].px + ((size_t)ys[a] * sw + xs[b]) * 4;
                        c[0] = s[0];
                        c[1] = s[1];
                        c[2] = s[2];
                    }
                    acc[0] += c[0];
                    acc[1] += c[1];
                    acc[2] += c[2];
                }
            float *o = d->px + ((size_t)y * d->w + x) * 4;
            o[0] = acc[0] * 0.25f;
            o[1] = acc[1] * 0.25f;
            o[2] = acc[2] * 0.25f;
            o[3] = 0.0f;
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

static inline void up_sample(const level *c, int x, int y, float out[3])
{
    int xa, xb, ya, yb;
    tent(x, c->w, &xa, &xb);
    tent(y, c->h, &ya, &yb);
    const float *p00 = c->px + ((size_t)ya * c->w + xa) * 4, *p01 = c->px + ((size_t)ya * c->w + xb) * 4;
    const float *p10 = c->px + ((size_t)yb * c->w + xa) * 4, *p11 = c->px + ((size_t)yb * c->w + xb) * 4;
    for (int k = 0; k < 3; k++)
        out[k] = 0.5625f * p00[k] + 0.1875f * (p01[k] + p10[k]) + 0.0625f * p11[k];
}

/* level `to` += upsampled level `from` (= to + 1) */
static void up_rows(void *user, int begin, int end)
{
    const bloom_job *j = user;
    const level *c = &j->lv[j->from], *f = &j->lv[j->to];
    for (int y = begin; y < end; y++)
        for (int x = 0; x < f->w; x++) {
            float u[3];
            up_sample(c, x, y, u);
            float *o = f->px + ((size_t)y * f->w + x) * 4;
            o[0] += u[0];
            o[1] += u[1];
            o[2] += u[2];
        }
}

static void composite_rows(void *user, int begin, int end)
{
    const bloom_job *j = user;
    const fx_effect_run *run = j->run;
    const bloom_params *p = j->p;
    const float scale = p->intensity / (float)(j->nlev > 0 ? j->nlev : 1);
    for (int y = run->roi.y0 + begin; y < run->roi.y0 + end; y++)
        for (int x = run->roi.x0; x < run->roi.x1; x++) {
            const float *s = run->src + ((size_t)y * run->width + x) * 4;
            float *d = run->dst + ((size_t)y * run->width + x) * 4;
            float g[3];
            if (j->nlev > 0)
                up_sample(&j->lv[1], x, y, g);
            else
                bright(j, s, g);
            for (int k = 0; k < 3; k++) {
                float sv = finite_or(s[k]);
                float b = g[k] * scale;
                d[k] = finite_or(p->composite == COMP_ADD ? sv + b : sv + b * (1.0f - fx_clamp01(sv)));
            }
            d[3] = finite_or(s[3]);
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

static fx_result bloom_process(const fx_effect_run *run)
{
    const bloom_params *p = run->params;
    const fx_rect *roi = &run->roi;
    if (roi->x1 <= roi->x0 || roi->y1 <= roi->y0)
        return FX_OK;
    const int w = run->width, h = run->height;
    if (!(p->intensity > 0.0f)) {
        for (int y = roi->y0; y < roi->y1; y++)
            memcpy(run->dst + ((size_t)y * w + roi->x0) * 4, run->src + ((size_t)y * w + roi->x0) * 4,
                   (size_t)(roi->x1 - roi->x0) * 4 * sizeof(float));
        return FX_OK;
    }
    char where[96];
    snprintf(where, sizeof where, "effect %d (bloom)", run->index);
    bloom_job j;
    memset(&j, 0, sizeof j);
    j.run = run;
    j.p = p;
    j.exposure = 1.0f;
    fx_result r = FX_OK;
    if (p->mode == MODE_SEED) {
        double lum = p->scene_luminance;
        if (!(lum > 0.0)) {
            j.row_sums = fx_mem_alloc((size_t)h * sizeof(double));
            if (!j.row_sums)
                return fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where);
            fx_parallel_for(run->ctx, h, fx_grain_for(run->ctx, h), luminance_rows, &j);
            double acc = 0.0;
            for (int y = 0; y < h; y++) /* in order: the same sum for any thread count */
                acc += j.row_sums[y];
            fx_mem_free(j.row_sums);
            j.row_sums = NULL;
            lum = exp(acc / ((double)w * h)) - 1e-6;
        }
        lum = lum > 1e-6 ? lum : 1e-6;
        double e = p->middle_grey / lum;
        j.exposure = (float)(e < 1e30 ? e : 1e30);
    }
    j.nlev = levels_for(p, w, h);
    int lw = w, lh = h;
    for (int l = 1; l <= j.nlev; l++) {
        lw = (lw + 1) / 2;
        lh = (lh + 1) / 2;
        j.lv[l].w = lw;
        j.lv[l].h = lh;
        j.lv[l].px = fx_mem_alloc((size_t)lw * lh * 4 * sizeof(float));
        if (!j.lv[l].px) {
            r = fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for pyramid level %d", where, l);
            goto out;
        }
    }
    for (int l = 1; l <= j.nlev; l++) {
        j.from = l - 1;
        j.to = l;
        fx_parallel_for(run->ctx, j.lv[l].h, fx_grain_for(run->ctx, j.lv[l].h), down_rows, &j);
    }
    fx_blur_spec spec = { p->level_sigma, FX_BLUR_RECURSIVE, 3 };
    for (int l = 1; l <= j.nlev && !r; l++)
        r = fx_blur_image(run->ctx, j.lv[l].px, j.lv[l].px, j.lv[l].w, j.lv[l].h, 4, &spec, NULL, where);
    for (int l = j.nlev - 1; l >= 1 && !r; l--) {
        j.from = l + 1;
        j.to = l;
        fx_parallel_for(run->ctx, j.lv[l].h, fx_grain_for(run->ctx, j.lv[l].h), up_rows, &j);
    }
    if (!r) {
        int rows = roi->y1 - roi->y0;
        fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), composite_rows, &j);
    }
out:
    for (int l = 1; l <= MAX_LEVELS; l++)
        fx_mem_free(j.lv[l].px);
    return r;
}

const fx_effect_class fx_effect_bloom = {
    .name = "bloom",
    .doc = "Bloom: bright pass (soft knee or the seed's), blurred 2x pyramid summed back up, added or screened",
    .params_size = sizeof(bloom_params),
    .params = bloom_param_defs,
    .param_count = FX_COUNT_OF(bloom_param_defs),
    .presets = { "{\"level_sigma\": 0.8}", "{\"level_sigma\": 1.0}", "{\"level_sigma\": 1.25}",
                 "{\"level_sigma\": 2.0}" },
    .passes = NULL,
    .needs_camera = NULL,
    .halo = bloom_halo,
    .validate = NULL,
    .process = bloom_process,
};
