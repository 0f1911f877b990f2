/* Proxy resolutions: frames reduced by a whole factor for interactive previews, and
 * reading a pass back as RGBA at any size (the add-on shows a proxy's result at the
 * full size of its image).
 *
 * A proxy pixel stands for a factor x factor block of the full frame. Colour passes
 * average the block (only what lies inside the frame, only finite values). All other
 * passes (IDs, Cryptomatte, depth, normals, positions...) copy one pixel of the block,
 * the same one for all of them, so IDs are never mixed and a proxy pixel's depth, normal
 * and IDs belong to one surface. The representative is the in-frame pixel nearest the
 * block's centre: offset (f - 1) / 2 in each axis, clamped to the frame. */
#include "core/context.h"
#include "core/frame.h"
#include "core/mem.h"
#include "core/passes.h"
#include "core/parallel.h"
#include "core/simd4.h"

#include <float.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#define FX_PROXY_FACTOR_MAX 16
/* A proxy of a proxy multiplies the factors; beyond this the frame is a few pixels anyway. */
#define FX_PROXY_PRODUCT_MAX 65536

int fx_frame_proxy_factor(const fx_frame *f)
{
    return f ? (f->proxy_factor > 1 ? f->proxy_factor : 1) : 0;
}

/* floor(a / b) for b > 0 */
static int floor_div(int a, int b)
{
    int q = a / b;
    return (a % b != 0 && a < 0) ? q - 1 : q;
}

static float finite_or(float v)
{
    return isfinite(v) ? v : isnan(v) ? 0.0f : (v > 0 ? FLT_MAX : -FLT_MAX);
}

typedef struct reduce_pass {
    const float *src;
    float *dst;
    int ch;
    int blend;
} reduce_pass;

typedef struct reduce_job {
    const reduce_pass *passes;
    int count;
    int w, h;   /* input */
    int ow;     /* output width */
    int f;
} reduce_job;

/* The mean of a block's finite values per channel; a channel without any takes the
 * representative's value, made finite. All-finite blocks (the usual case) take one pass
 * with a branch-free check; ch is a constant in each caller, so the loops unroll. */
static inline void block_mean(const float *src, int w, int ch, int bx0, int bx1, int by0, int by1,
                              const float *rep, float *o)
{
    double sum[4] = {0, 0, 0, 0};
    uint32_t bad = 0;
    for (int y = by0; y < by1; y++) {
        const float *s = src + ((size_t)y * w + bx0) * ch;
        for (int x = bx0; x < bx1; x++, s += ch)
            for (int c = 0; c < ch; c++) {
                uint32_t b;
                memcpy(&b, s + c, sizeof b);
                bad |= (uint32_t)((b & 0x7f800000u) == 0x7f800000u);
                sum[c] += s[c];
            }
    }
    if (!bad) {
        const double n = (double)(bx1 - bx0) * (by1 - by0);
        for (int c = 0; c < ch; c++)
            o[c] = (float)(sum[c] / n);
        return;
    }
    int n[4] = {0, 0, 0, 0};
    for (int c = 0; c < 4; c++)
        sum[c] = 0;
    for (int y = by0; y < by1; y++) {
        const float *s = src + ((size_t)y * w + bx0) * ch;
        for (int x = bx0; x < bx1; x++, s += ch)
            for (int c = 0; c < ch; c++)
                if (isfinite(s[c])) {
                    sum[c] += s[c];
                    n[c]++;
                }
    }
    for (int c = 0; c < ch; c++)
        o[c] = n[c] ? (float)(sum[c] / n[c]) : finite_or(rep[c]);
}

static void reduce_rows(void *user, int y0, int y1)
{
    const reduce_job *j = user;
    const int f = j->f, w = j->w, h = j->h;
    for (int oy = y0; oy < y1; oy++) {
        const int by0 = oy * f, by1 = by0 + f < h ? by0 + f : h;
        const int ry = by0 + (f - 1) / 2 < h ? by0 + (f - 1) / 2 : h - 1;
        for (int p = 0; p < j->count; p++) {
            const reduce_pass *rp = &j->passes[p];
            const int ch = rp->ch;
            float *out = rp->dst + (size_t)oy * j->ow * ch;
            const float *rep_row = rp->src + (size_t)ry * w * ch;
            for (int ox = 0; ox < j->ow; ox++) {
                const int bx0 = ox * f, bx1 = bx0 + f < w ? bx0 + f : w;
                const int rx = bx0 + (f - 1) / 2 < w ? bx0 + (f - 1) / 2 : w - 1;
                const float *rep = rep_row + (size_t)rx * ch;
                float *o = out + (size_t)ox * ch;
                if (!rp->blend) {
                    for (int c = 0; c < ch; c++) /* a call to memcpy per pixel costs more */
                        o[c] = rep[c];
                    continue;
                }
                switch (ch) {
                case 1: block_mean(rp->src, w, 1, bx0, bx1, by0, by1, rep, o); break;
                case 3: block_mean(rp->src, w, 3, bx0, bx1, by0, by1, rep, o); break;
                case 4: block_mean(rp->src, w, 4, bx0, bx1, by0, by1, rep, o); break;
                default: block_mean(rp->src, w, ch, bx0, bx1, by0, by1, rep, o); break;
                }
            }
        }
    }
}

/* The windows of a proxy: origins floor-divided, sizes rounded up. */
static void reduce_window(const int in[4], int f, int out[4])
{
    long long wd = (long long)in[2] - in[0] + 1, ht = (long long)in[3] - in[1] + 1;
    out[0] = floor_div(in[0], f);
    out[1] = floor_div(in[1], f);
    out[2] = out[0] + (int)((wd + f - 1) / f) - 1;
    out[3] = out[1] + (int)((ht + f - 1) / f) - 1;
}

fx_result fx_frame_reduce(const fx_frame *in, int factor, fx_frame **out)
{
    if (!out)
        return fx_fail(in ? in->ctx : NULL, FX_ERR_INVALID_ARGUMENT, "fx_frame_reduce: out is NULL");
    *out = NULL;
    if (!in)
        return fx_fail(NULL, FX_ERR_INVALID_ARGUMENT, "fx_frame_reduce: the frame is NULL");
    fx_context *ctx = in->ctx;
    if (factor < 1 || factor > FX_PROXY_FACTOR_MAX)
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "fx_frame_reduce: factor %d is outside 1..%d", factor,
                       FX_PROXY_FACTOR_MAX);
    const int in_factor = in->proxy_factor > 1 ? in->proxy_factor : 1;
    if ((long long)in_factor * factor > FX_PROXY_PRODUCT_MAX)
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT,
                       "fx_frame_reduce: a proxy of 1/%d reduced by %d is over 1/%d", in_factor, factor,
                       FX_PROXY_PRODUCT_MAX);
    fx_frame *o = NULL;
    fx_result r;
    if (factor == 1) {
        r = fx_frame_new_like(in, &o);
        if (!r)
            r = fx_frame_copy_passes(o, in);
        if (r) {
            fx_frame_free(o);
            return r;
        }
        *out = o;
        return FX_OK;
    }
    const int w = in->width, h = in->height;
    const int ow = (int)(((long long)w + factor - 1) / factor), oh = (int)(((long long)h + factor - 1) / factor);
    r = fx_frame_new(ctx, ow, oh, &o);
    if (r)
        return r;
    reduce_window(in->data_window, factor, o->data_window);
    reduce_window(in->display_window, factor, o->display_window);
    o->has_camera = in->has_camera;
    o->camera = in->camera;
    o->frame_number = in->frame_number;
    o->fps = in->fps;
    o->proxy_factor = in_factor * factor;
    memcpy(o->full_data_window, in_factor > 1 ? in->full_data_window : in->data_window, sizeof o->full_data_window);
    memcpy(o->full_display_window, in_factor > 1 ? in->full_display_window : in->display_window,
           sizeof o->full_display_window);
    for (int i = 0; i < in->meta_count && !r; i++)
        r = fx_frame_set_meta(o, in->meta[i].key, in->meta[i].value);
    reduce_pass *passes = NULL;
    if (!r && in->pass_count > 0) {
        passes = fx_mem_calloc((size_t)in->pass_count, sizeof *passes);
        if (!passes)
            r = fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "fx_frame_reduce: out of memory");
    }
    for (int i = 0; i < in->pass_count && !r; i++) {
        const fx_pass *p = &in->passes[i];
        float *dst = NULL;
        r = fx_frame_alloc_pass(o, p->name, p->channels, &dst);
        if (r)
            break;
        fx_frame_find_pass(o, p->name)->from_half = p->from_half;
        passes[i].src = p->data;
        passes[i].dst = dst;
        passes[i].ch = p->channels;
        passes[i].blend = fx_pass_is_blendable(p->name);
    }
    if (!r && ow > 0 && oh > 0 && in->pass_count > 0) {
        reduce_job job = {passes, in->pass_count, w, h, ow, factor};
        /* rows are independent: any grain gives the same bits */
        fx_parallel_for(ctx, oh, fx_grain_for(ctx, oh), reduce_rows, &job);
    }
    fx_mem_free(passes);
    if (r) {
        fx_frame_free(o);
        return r;
    }
    *out = o;
    return FX_OK;
}

/* ---- reading a pass as RGBA -------------------------------------------- */

typedef struct read_job {
    const float *src;
    int ch, w, h;     /* source */
    float *dst;
    int W, H;         /* output */
    int bottom_up;
    int nearest;
    const int *x0, *x1; /* per output column: source columns */
    const float *tx;    /* weight of x1 */
} read_job;

/* RGBA of one source pixel */
static inline void expand(const float *s, int ch, float o[4])
{
    switch (ch) {
    case 1:
        o[0] = o[1] = o[2] = s[0];
        o[3] = 1.0f;
        break;
    case 2:
        o[0] = s[0];
        o[1] = s[1];
        o[2] = 0.0f;
        o[3] = 1.0f;
        break;
    case 3:
        o[0] = s[0];
        o[1] = s[1];
        o[2] = s[2];
        o[3] = 1.0f;
        break;
    default:
        o[0] = s[0];
        o[1] = s[1];
        o[2] = s[2];
        o[3] = s[3];
        break;
    }
}

/* One source row as RGBA (the expansion of 1..3 channels). */
static void expand_row(const float *s, int ch, int w, float *o)
{
    if (ch == 4) {
        memcpy(o, s, (size_t)w * 4 * sizeof(float));
        return;
    }
    for (int x = 0; x < w; x++)
        expand(s + (size_t)x * ch, ch, o + (size_t)x * 4);
}

/* Bilinear, separable: the two source rows blended vertically into one RGBA row of the
 * source's width (`mix`, per chunk), then each output pixel from two of its pixels. */
static void read_rows(void *user, int y0, int y1)
{
    const read_job *j = user;
    const int ch = j->ch, w = j->w, h = j->h, W = j->W, H = j->H;
    float *mix = NULL, *ra4 = NULL, *rb4 = NULL;
    if (!j->nearest && !(w == W && h == H)) {
        mix = fx_mem_alloc((size_t)w * 4 * sizeof(float) * 3);
        if (!mix) { /* no scratch: nearest rather than nothing (still finite) */
            read_job k = *j;
            k.nearest = 1;
            read_rows(&k, y0, y1);
            return;
        }
        ra4 = mix + (size_t)w * 4;
        rb4 = ra4 + (size_t)w * 4;
    }
    int have_a = -1, have_b = -1;
    for (int y = y0; y < y1; y++) {
        float *out = j->dst + (size_t)(j->bottom_up ? H - 1 - y : y) * W * 4;
        if (w == W && h == H) {
            expand_row(j->src + (size_t)y * w * ch, ch, w, out);
        } else if (j->nearest) {
            long long sy = ((long long)2 * y + 1) * h / (2LL * H);
            const float *row = j->src + (size_t)(sy < h ? sy : h - 1) * w * ch;
            for (int x = 0; x < W; x++)
                expand(row + (size_t)j->x0[x] * ch, ch, out + (size_t)x * 4);
        } else {
            double fy = (y + 0.5) * h / H - 0.5;
            int ya = (int)floor(fy);
            const float ty = (float)(fy - ya), sy = 1.0f - ty;
            int yb = ya + 1;
            ya = ya < 0 ? 0 : ya >= h ? h - 1 : ya;
            yb = yb < 0 ? 0 : yb >= h ? h - 1 : yb;
            if (have_a != ya) {
                if (have_b == ya) { /* the next output row moved down by one source row */
                    float *t = ra4;
                    ra4 = rb4;
                    rb4 = t;
                    have_b = -1;
                } else {
                    expand_row(j->src + (size_t)ya * w * ch, ch, w, ra4);
                }
                have_a = ya;
            }
            if (have_b != yb) {
                expand_row(j->src + (size_t)yb * w * ch, ch, w, rb4);
                have_b = yb;
            }
            /* weights, not differences: FLT_MAX neighbours do not overflow */
            const v4f vs = V4(sy), vt = V4(ty);
            for (int x = 0; x < w; x++)
                st4(mix + (size_t)x * 4, ld4(ra4 + (size_t)x * 4) * vs + ld4(rb4 + (size_t)x * 4) * vt);
            for (int x = 0; x < W; x++) {
                const float tx = j->tx[x];
                v4f v = ld4(mix + (size_t)j->x0[x] * 4) * V4(1.0f - tx) + ld4(mix + (size_t)j->x1[x] * 4) * V4(tx);
                st4(out + (size_t)x * 4, finite4(v));
            }
            continue; /* finite already */
        }
        fx_span_make_finite(out, (size_t)W * 4);
    }
    fx_mem_free(mix);
}

fx_result fx_frame_read_pixels(const fx_frame *f, const char *pass, int width, int height, int bottom_up,
                               float *rgba)
{
    if (!f)
        return fx_fail(NULL, FX_ERR_INVALID_ARGUMENT, "fx_frame_read_pixels: the frame is NULL");
    fx_context *ctx = f->ctx;
    if (!rgba)
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "fx_frame_read_pixels: the pixel buffer is NULL");
    if (width < 1 || height < 1)
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "fx_frame_read_pixels: size %d x %d is empty", width,
                       height);
    const char *name = pass ? pass : "Combined";
    const fx_pass *p = fx_frame_find_pass(f, name);
    if (!p)
        return fx_fail(ctx, FX_ERR_MISSING_PASS, "fx_frame_read_pixels: the frame has no pass '%s'", name);
    const int w = f->width, h = f->height;
    if (w < 1 || h < 1) {
        memset(rgba, 0, (size_t)width * height * 4 * sizeof(float));
        return FX_OK;
    }
    read_job j = {p->data, p->channels, w, h, rgba, width, height, bottom_up != 0,
                  !fx_pass_is_blendable(name), NULL, NULL, NULL};
    int *x0 = NULL, *x1 = NULL;
    float *tx = NULL;
    if (w != width || h != height) {
        x0 = fx_mem_alloc((size_t)width * sizeof *x0);
        x1 = fx_mem_alloc((size_t)width * sizeof *x1);
        tx = fx_mem_alloc((size_t)width * sizeof *tx);
        if (!x0 || !x1 || !tx) {
            fx_mem_free(x0);
            fx_mem_free(x1);
            fx_mem_free(tx);
            return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "fx_frame_read_pixels: out of memory");
        }
        for (int x = 0; x < width; x++) {
            if (j.nearest) {
                long long sx = ((long long)2 * x + 1) * w / (2LL * width);
                x0[x] = x1[x] = (int)(sx < w ? sx : w - 1);
                tx[x] = 0.0f;
                continue;
            }
            double fx = (x + 0.5) * w / width - 0.5;
            int a = (int)floor(fx);
            tx[x] = (float)(fx - a);
            int b = a + 1;
            x0[x] = a < 0 ? 0 : a >= w ? w - 1 : a;
            x1[x] = b < 0 ? 0 : b >= w ? w - 1 : b;
        }
        j.x0 = x0;
        j.x1 = x1;
        j.tx = tx;
    }
    fx_parallel_for(ctx, height, fx_grain_for(ctx, height), read_rows, &j);
    fx_mem_free(x0);
    fx_mem_free(x1);
    fx_mem_free(tx);
    return FX_OK;
}
