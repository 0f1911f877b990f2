/* Frames: named float passes, windows, camera, scene time and string metadata. */
#include "core/buffers.h"
#include "core/context.h"
#include "core/frame.h"
#include "core/mem.h"
#include "core/passes.h"
#include "core/parallel.h"

#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <string.h>

struct fx_pixels {
    atomic_int holders; /* passes pointing here, in any frames (a stack's output shares its
                           input's passes, and may be of another context: the last holder
                           returns the buffer to its own frame's context's store) */
    float *data;
    size_t bytes;
};

fx_result fx_frame_new(fx_context *ctx, int width, int height, fx_frame **out)
{
    if (!out)
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "fx_frame_new: out is NULL");
    *out = NULL;
    if (width < 0 || height < 0)
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "frame size %d x %d is negative", width, height);
    if (ctx && (width > ctx->max_width || height > ctx->max_height))
        return fx_fail(ctx, FX_ERR_LIMIT, "frame size %d x %d is over the limit of %d x %d", width,
                       height, ctx->max_width, ctx->max_height);
    fx_frame *f = fx_mem_calloc(1, sizeof *f);
    if (!f)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "out of memory for a frame");
    f->ctx = ctx;
    f->width = width;
    f->height = height;
    int win[4] = {0, 0, width - 1, height - 1};
    memcpy(f->data_window, win, sizeof win);
    memcpy(f->display_window, win, sizeof win);
    f->fps = 24.0;
    f->frame_number = 1.0;
    f->proxy_factor = 1;
    fx_context_frame_born(ctx);
    *out = f;
    return FX_OK;
}

/* Bytes of a pass's buffer: every pass holds width * height * channels floats. */
static size_t pass_bytes(const fx_frame *f, int channels)
{
    return (size_t)f->width * (size_t)f->height * (size_t)channels * sizeof(float);
}

/* Drops p's hold on its pixels; the last holder returns the buffer to the store. */
static void pass_release(fx_frame *f, fx_pass *p)
{
    fx_pixels *px = p->pixels;
    if (px && atomic_fetch_sub(&px->holders, 1) == 1) {
        fx_buffer_put(f->ctx, px->data, px->bytes);
        fx_mem_free(px);
    }
    p->pixels = NULL;
    p->data = NULL;
}

void fx_frame_free(fx_frame *f)
{
    if (!f)
        return;
    for (int i = 0; i < f->pass_count; i++)
        pass_release(f, &f->passes[i]);
    fx_mem_free(f->passes);
    for (int i = 0; i < f->meta_count; i++) {
        fx_mem_free(f->meta[i].key);
        fx_mem_free(f->meta[i].value);
    }
    fx_mem_free(f->meta);
    fx_context *ctx = f->ctx;
    fx_mem_free(f);
    fx_context_frame_died(ctx); /* last: may release a context freed before its frames */
}

int fx_frame_width(const fx_frame *f)
{
    return f ? f->width : 0;
}

int fx_frame_height(const fx_frame *f)
{
    return f ? f->height : 0;
}

fx_result fx_frame_set_windows(fx_frame *f, const int data_window[4], const int display_window[4])
{
    if (!f || !data_window || !display_window)
        return FX_ERR_INVALID_ARGUMENT;
    long long dw = (long long)data_window[2] - data_window[0] + 1;
    long long dh = (long long)data_window[3] - data_window[1] + 1;
    if (dw != f->width || dh != f->height)
        return fx_fail(f->ctx, FX_ERR_INVALID_ARGUMENT,
                       "data window (%d,%d)-(%d,%d) is not the frame's %d x %d", data_window[0],
                       data_window[1], data_window[2], data_window[3], f->width, f->height);
    if (display_window[2] < display_window[0] - 1 || display_window[3] < display_window[1] - 1)
        return fx_fail(f->ctx, FX_ERR_INVALID_ARGUMENT, "display window (%d,%d)-(%d,%d) is inverted",
                       display_window[0], display_window[1], display_window[2], display_window[3]);
    int same = memcmp(f->data_window, data_window, 4 * sizeof(int)) == 0 &&
               memcmp(f->display_window, display_window, 4 * sizeof(int)) == 0;
    memcpy(f->data_window, data_window, 4 * sizeof(int));
    memcpy(f->display_window, display_window, 4 * sizeof(int));
    if (f->proxy_factor > 1 && !same) {
        /* a proxy given new windows: the full frame's are these, f times larger */
        const long long k = f->proxy_factor;
        for (int i = 0; i < 2; i++) {
            long long a = data_window[i] * k, b = (data_window[i + 2] + 1LL) * k - 1;
            long long c = display_window[i] * k, d = (display_window[i + 2] + 1LL) * k - 1;
            f->full_data_window[i] = (int)(a < INT_MIN ? INT_MIN : a > INT_MAX ? INT_MAX : a);
            f->full_data_window[i + 2] = (int)(b < INT_MIN ? INT_MIN : b > INT_MAX ? INT_MAX : b);
            f->full_display_window[i] = (int)(c < INT_MIN ? INT_MIN : c > INT_MAX ? INT_MAX : c);
            f->full_display_window[i + 2] = (int)(d < INT_MIN ? INT_MIN : d > INT_MAX ? INT_MAX : d);
        }
    }
    return FX_OK;
}

void fx_frame_windows(const fx_frame *f, int data_window[4], int display_window[4])
{
    if (!f)
        return;
    if (data_window)
        memcpy(data_window, f->data_window, 4 * sizeof(int));
    if (display_window)
        memcpy(display_window, f->display_window, 4 * sizeof(int));
}

fx_pass *fx_frame_find_pass(const fx_frame *f, const char *name)
{
    if (!f || !name)
        return NULL;
    for (int i = 0; i < f->pass_count; i++)
        if (strcmp(f->passes[i].name, name) == 0)
            return &f->passes[i];
    return NULL;
}

/* The pass named `name`, its old pixels released, or a new empty one; NULL when the
 * list cannot grow (the error is set). */
static fx_pass *pass_slot(fx_frame *f, const char *name)
{
    fx_pass *p = fx_frame_find_pass(f, name);
    if (p) {
        pass_release(f, p);
    } else {
        if (f->pass_count == f->pass_cap) {
            int cap = f->pass_cap ? f->pass_cap * 2 : 8;
            fx_pass *np = fx_mem_realloc(f->passes, (size_t)cap * sizeof *np);
            if (!np) {
                fx_fail(f->ctx, FX_ERR_OUT_OF_MEMORY, "out of memory adding pass '%s'", name);
                return NULL;
            }
            f->passes = np;
            f->pass_cap = cap;
        }
        p = &f->passes[f->pass_count++];
        memset(p, 0, sizeof *p);
        strcpy(p->name, name);
    }
    p->from_half = 0;
    p->handed_out = 0;
    return p;
}

static fx_result check_pass_name(const fx_frame *f, const char *name, int channels)
{
    if (!f || !name || channels < 1 || channels > 4 || !name[0])
        return fx_fail(f ? f->ctx : NULL, FX_ERR_INVALID_ARGUMENT,
                       "pass '%s': needs a name and 1 to 4 channels (got %d)", name ? name : "(null)",
                       channels);
    if (strlen(name) >= FX_NAME_MAX)
        return fx_fail(f->ctx, FX_ERR_INVALID_ARGUMENT, "pass name '%.40s...' is longer than %d bytes",
                       name, FX_NAME_MAX - 1);
    return FX_OK;
}

fx_result fx_frame_adopt_pass(fx_frame *f, const char *name, int channels, float *data)
{
    fx_result r = data ? check_pass_name(f, name, channels)
                       : fx_fail(f ? f->ctx : NULL, FX_ERR_INVALID_ARGUMENT, "pass '%s': no pixels",
                                 name ? name : "(null)");
    fx_pixels *px = r ? NULL : fx_mem_alloc(sizeof *px);
    if (!r && !px)
        r = fx_fail(f->ctx, FX_ERR_OUT_OF_MEMORY, "out of memory adding pass '%s'", name);
    fx_pass *p = r ? NULL : pass_slot(f, name);
    if (!p) {
        fx_mem_free(px);
        fx_mem_free(data);
        return r ? r : FX_ERR_OUT_OF_MEMORY;
    }
    atomic_init(&px->holders, 1);
    px->data = data;
    px->bytes = pass_bytes(f, channels);
    p->channels = channels;
    p->data = data;
    p->pixels = px;
    return FX_OK;
}

float *fx_frame_take_pass_data(fx_frame *f, const char *name)
{
    fx_pass *p = fx_frame_find_pass(f, name);
    if (!p || !p->pixels || atomic_load(&p->pixels->holders) != 1)
        return NULL;
    float *data = p->pixels->data;
    fx_mem_free(p->pixels);
    const int i = (int)(p - f->passes);
    memmove(f->passes + i, f->passes + i + 1, (size_t)(f->pass_count - i - 1) * sizeof *f->passes);
    f->pass_count--;
    return data;
}

int fx_frame_pixels_holders(const fx_pass *p)
{
    return p && p->pixels ? atomic_load(&p->pixels->holders) : 0;
}

fx_result fx_frame_share_pass(fx_frame *dst, const char *name, const fx_frame *src, const fx_pass *sp)
{
    if (!dst || !src || !sp || dst->width != src->width || dst->height != src->height)
        return fx_fail(dst ? dst->ctx : NULL, FX_ERR_INVALID_ARGUMENT, "fx_frame_share_pass: frames differ in size");
    /* frames of different contexts share too: the count is atomic, and the last holder
     * returns the buffer to its own frame's context's store */
    if (sp->handed_out || !sp->pixels) {
        fx_result r = fx_frame_add_pass(dst, name, sp->channels, sp->data);
        if (!r)
            fx_frame_find_pass(dst, name)->from_half = sp->from_half;
        return r;
    }
    fx_result r = check_pass_name(dst, name, sp->channels);
    if (r)
        return r;
    fx_pixels *px = sp->pixels;
    atomic_fetch_add(&px->holders, 1); /* before pass_slot: dst may hold this very buffer */
    fx_pass *p = pass_slot(dst, name);
    if (!p) {
        fx_pass tmp = {.pixels = px};
        pass_release(dst, &tmp);
        return FX_ERR_OUT_OF_MEMORY;
    }
    p->channels = sp->channels;
    p->from_half = sp->from_half;
    p->data = px->data;
    p->pixels = px;
    return FX_OK;
}

fx_result fx_frame_alloc_pass(fx_frame *f, const char *name, int channels, float **out)
{
    if (!f || !out)
        return FX_ERR_INVALID_ARGUMENT;
    *out = NULL;
    size_t bytes;
    if (!fx_size_mul(&bytes, (size_t)f->width * (size_t)f->height, (size_t)(channels > 0 ? channels : 1),
                     sizeof(float)))
        return fx_fail(f->ctx, FX_ERR_LIMIT, "pass '%s' of %d x %d is too large", name, f->width, f->height);
    char what[160];
    snprintf(what, sizeof what, "pass '%s'", name ? name : "");
    fx_result r = fx_check_budget(f->ctx, bytes, what);
    if (r)
        return r;
    float *data = fx_buffer_get(f->ctx, bytes);
    if (!data)
        return fx_fail(f->ctx, FX_ERR_OUT_OF_MEMORY, "out of memory for pass '%s' (%.1f MiB)", name,
                       (double)bytes / (1 << 20));
    r = fx_frame_adopt_pass(f, name, channels, data);
    if (r == FX_OK)
        *out = data;
    return r;
}

fx_result fx_frame_add_pass(fx_frame *f, const char *name, int channels, const float *data)
{
    if (!f)
        return FX_ERR_INVALID_ARGUMENT;
    if (channels < 1 || channels > 4)
        return fx_fail(f->ctx, FX_ERR_INVALID_ARGUMENT, "pass '%s': %d channels (1 to 4 allowed)",
                       name ? name : "(null)", channels);
    float *dst;
    fx_result r = fx_frame_alloc_pass(f, name, channels, &dst);
    if (r)
        return r;
    size_t n = (size_t)f->width * f->height * channels;
    if (data)
        memcpy(dst, data, n * sizeof(float));
    else
        memset(dst, 0, n * sizeof(float));
    return FX_OK;
}

fx_result fx_frame_pass(const fx_frame *f, const char *name, float **data, int *channels)
{
    if (!f || !name)
        return FX_ERR_INVALID_ARGUMENT;
    fx_pass *p = fx_frame_find_pass(f, name);
    if (!p)
        return fx_fail(f->ctx, FX_ERR_MISSING_PASS, "the frame has no pass '%s'", name);
    if (data) {
        if (p->pixels && atomic_load(&p->pixels->holders) > 1) {
            /* another frame holds these pixels: the caller may write, so it gets a copy */
            size_t bytes = pass_bytes(f, p->channels);
            float *own = fx_buffer_get(f->ctx, bytes);
            fx_pixels *px = own ? fx_mem_alloc(sizeof *px) : NULL;
            if (!px) {
                fx_buffer_put(f->ctx, own, bytes);
                return fx_fail(f->ctx, FX_ERR_OUT_OF_MEMORY, "out of memory for a copy of pass '%s'", name);
            }
            memcpy(own, p->data, bytes);
            atomic_init(&px->holders, 1);
            px->data = own;
            px->bytes = bytes;
            pass_release((fx_frame *)f, p); /* asking for write access makes the caller f's owner */
            p->data = own;
            p->pixels = px;
        }
        p->handed_out = 1;
        *data = p->data;
    }
    if (channels)
        *channels = p->channels;
    return FX_OK;
}

fx_result fx_frame_pass_read(const fx_frame *f, const char *name, const float **data, int *channels)
{
    if (!f || !name)
        return FX_ERR_INVALID_ARGUMENT;
    const fx_pass *p = fx_frame_find_pass(f, name);
    if (!p)
        return fx_fail(f->ctx, FX_ERR_MISSING_PASS, "the frame has no pass '%s'", name);
    if (data)
        *data = p->data;
    if (channels)
        *channels = p->channels;
    return FX_OK;
}

int fx_frame_pass_count(const fx_frame *f)
{
    return f ? f->pass_count : 0;
}

const char *fx_frame_pass_name(const fx_frame *f, int index)
{
    if (!f || index < 0 || index >= f->pass_count)
        return NULL;
    return f->passes[index].name;
}

int fx_frame_pass_channels(const fx_frame *f, int index)
{
    if (!f || index < 0 || index >= f->pass_count)
        return 0;
    return f->passes[index].channels;
}

static int all_finite(const float *v, int n)
{
    for (int i = 0; i < n; i++)
        if (!isfinite(v[i]))
            return 0;
    return 1;
}

fx_result fx_frame_set_camera(fx_frame *f, const fx_camera *camera)
{
    if (!f)
        return FX_ERR_INVALID_ARGUMENT;
    if (!camera) {
        f->has_camera = 0;
        return FX_OK;
    }
    if (camera->size != sizeof(fx_camera))
        return fx_fail(f->ctx, FX_ERR_INVALID_ARGUMENT, "fx_camera.size is %zu, expected %zu",
                       camera->size, sizeof(fx_camera));
    if (!all_finite(camera->world_to_camera, 16) || !all_finite(camera->projection, 16) ||
        !isfinite(camera->clip_start) || !isfinite(camera->clip_end))
        return fx_fail(f->ctx, FX_ERR_INVALID_ARGUMENT, "camera matrices contain NaN or Inf");
    f->camera = *camera;
    f->has_camera = 1;
    return FX_OK;
}

int fx_frame_camera(const fx_frame *f, fx_camera *out)
{
    if (!f || !f->has_camera)
        return 0;
    if (out)
        *out = f->camera;
    return 1;
}

void fx_frame_set_time(fx_frame *f, double frame, double fps)
{
    if (!f)
        return;
    f->frame_number = isfinite(frame) ? frame : 0.0;
    f->fps = isfinite(fps) && fps > 0 ? fps : 24.0;
}

void fx_frame_time(const fx_frame *f, double *frame, double *fps)
{
    if (!f)
        return;
    if (frame)
        *frame = f->frame_number;
    if (fps)
        *fps = f->fps;
}

fx_result fx_frame_set_meta(fx_frame *f, const char *key, const char *value)
{
    if (!f || !key)
        return FX_ERR_INVALID_ARGUMENT;
    for (int i = 0; i < f->meta_count; i++) {
        if (strcmp(f->meta[i].key, key) != 0)
            continue;
        if (!value) {
            fx_mem_free(f->meta[i].key);
            fx_mem_free(f->meta[i].value);
            f->meta[i] = f->meta[--f->meta_count];
            return FX_OK;
        }
        char *v = fx_mem_strdup(value);
        if (!v)
            return fx_fail(f->ctx, FX_ERR_OUT_OF_MEMORY, "out of memory for metadata '%s'", key);
        fx_mem_free(f->meta[i].value);
        f->meta[i].value = v;
        return FX_OK;
    }
    if (!value)
        return FX_OK;
    if (f->meta_count == f->meta_cap) {
        int cap = f->meta_cap ? f->meta_cap * 2 : 8;
        fx_meta *m = fx_mem_realloc(f->meta, (size_t)cap * sizeof *m);
        if (!m)
            return fx_fail(f->ctx, FX_ERR_OUT_OF_MEMORY, "out of memory for metadata '%s'", key);
        f->meta = m;
        f->meta_cap = cap;
    }
    char *k = fx_mem_strdup(key), *v = fx_mem_strdup(value);
    if (!k || !v) {
        fx_mem_free(k);
        fx_mem_free(v);
        return fx_fail(f->ctx, FX_ERR_OUT_OF_MEMORY, "out of memory for metadata '%s'", key);
    }
    f->meta[f->meta_count].key = k;
    f->meta[f->meta_count].value = v;
    f->meta_count++;
    return FX_OK;
}

const char *fx_frame_meta(const fx_frame *f, const char *key)
{
    if (!f || !key)
        return NULL;
    for (int i = 0; i < f->meta_count; i++)
        if (strcmp(f->meta[i].key, key) == 0)
            return f->meta[i].value;
    return NULL;
}

fx_result fx_frame_new_like(const fx_frame *f, fx_frame **out)
{
    return fx_frame_new_like_in(f ? f->ctx : NULL, f, out);
}

fx_result fx_frame_new_like_in(fx_context *ctx, const fx_frame *f, fx_frame **out)
{
    if (!f || !out || !ctx)
        return FX_ERR_INVALID_ARGUMENT;
    fx_frame *o;
    fx_result r = fx_frame_new(ctx, f->width, f->height, &o);
    if (r)
        return r;
    memcpy(o->data_window, f->data_window, sizeof o->data_window);
    memcpy(o->display_window, f->display_window, sizeof o->display_window);
    o->has_camera = f->has_camera;
    o->camera = f->camera;
    o->frame_number = f->frame_number;
    o->fps = f->fps;
    o->proxy_factor = f->proxy_factor;
    memcpy(o->full_data_window, f->full_data_window, sizeof o->full_data_window);
    memcpy(o->full_display_window, f->full_display_window, sizeof o->full_display_window);
    for (int i = 0; i < f->meta_count; i++) {
        r = fx_frame_set_meta(o, f->meta[i].key, f->meta[i].value);
        if (r) {
            fx_frame_free(o);
            return r;
        }
    }
    *out = o;
    return FX_OK;
}

fx_result fx_frame_copy_passes(fx_frame *dst, const fx_frame *src)
{
    if (!dst || !src)
        return FX_ERR_INVALID_ARGUMENT;
    if (dst->width != src->width || dst->height != src->height)
        return fx_fail(dst->ctx, FX_ERR_INVALID_ARGUMENT, "cannot copy passes from a %d x %d frame into a %d x %d one",
                       src->width, src->height, dst->width, dst->height);
    for (int i = 0; i < src->pass_count; i++) {
        const fx_pass *p = &src->passes[i];
        if (fx_frame_find_pass(dst, p->name))
            continue;
        fx_result r = fx_frame_share_pass(dst, p->name, src, p);
        if (r)
            return r;
    }
    return FX_OK;
}

/* ---- sanitising ---- */

#define SANITIZE_CHUNK 65536

size_t fx_span_make_finite(float *data, size_t count)
{
    uint32_t any = 0;
    for (size_t i = 0; i < count; i++) {
        uint32_t b;
        memcpy(&b, data + i, sizeof b);
        any |= (uint32_t)((b & 0x7f800000u) == 0x7f800000u); /* exponent all ones: NaN or Inf */
    }
    if (!any)
        return 0;
    size_t replaced = 0;
    for (size_t i = 0; i < count; i++)
        if (!isfinite(data[i])) {
            data[i] = isnan(data[i]) ? 0.0f : (data[i] > 0 ? FLT_MAX : -FLT_MAX);
            replaced++;
        }
    return replaced;
}

typedef struct sanitize_job {
    float *data;
    size_t count;
    size_t *replaced; /* per chunk: summed in chunk order, so the total is exact */
} sanitize_job;

static void sanitize_range(void *user, int begin, int end)
{
    sanitize_job *j = user;
    for (int c = begin; c < end; c++) {
        size_t lo = (size_t)c * SANITIZE_CHUNK, hi = lo + SANITIZE_CHUNK;
        if (hi > j->count)
            hi = j->count;
        j->replaced[c] = fx_span_make_finite(j->data + lo, hi - lo);
    }
}

size_t fx_sanitize_floats(fx_context *ctx, float *data, size_t count)
{
    if (!data || count == 0)
        return 0;
    size_t chunks = (count + SANITIZE_CHUNK - 1) / SANITIZE_CHUNK;
    if (chunks > (size_t)1 << 30)
        return 0;
    size_t *replaced = fx_mem_calloc(chunks, sizeof *replaced);
    size_t total = 0;
    if (!replaced) {
        /* No memory for per-chunk counts: still make the data finite, serially. */
        for (size_t i = 0; i < count; i++)
            if (!isfinite(data[i])) {
                data[i] = isnan(data[i]) ? 0.0f : (data[i] > 0 ? FLT_MAX : -FLT_MAX);
                total++;
            }
        return total;
    }
    sanitize_job job = {data, count, replaced};
    fx_parallel_for(ctx, (int)chunks, 1, sanitize_range, &job);
    for (size_t c = 0; c < chunks; c++)
        total += replaced[c];
    fx_mem_free(replaced);
    return total;
}
