/* Contexts: thread count, limits, progress callback, per-thread last error, warnings. */
#include "core/buffers.h"
#include "core/context.h"
#include "core/mem.h"
#include "core/parallel.h"
#include "core/platform.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifndef LIBFX_VERSION
#define LIBFX_VERSION "0.0.0"
#endif

/* Defaults that keep a hostile header from asking for absurd buffers. */
#define DEFAULT_MAX_DIM 65536
#define DEFAULT_MAX_BYTES ((uint64_t)16 << 30)

int fx_abi_version(void)
{
    return FX_ABI_VERSION;
}

const char *fx_version_string(void)
{
    return LIBFX_VERSION;
}

const char *fx_result_name(fx_result r)
{
    switch (r) {
    case FX_OK: return "FX_OK";
    case FX_ERR_INVALID_ARGUMENT: return "FX_ERR_INVALID_ARGUMENT";
    case FX_ERR_OUT_OF_MEMORY: return "FX_ERR_OUT_OF_MEMORY";
    case FX_ERR_IO: return "FX_ERR_IO";
    case FX_ERR_BAD_FILE: return "FX_ERR_BAD_FILE";
    case FX_ERR_LIMIT: return "FX_ERR_LIMIT";
    case FX_ERR_MISSING_PASS: return "FX_ERR_MISSING_PASS";
    case FX_ERR_UNKNOWN_EFFECT: return "FX_ERR_UNKNOWN_EFFECT";
    case FX_ERR_BAD_PARAM: return "FX_ERR_BAD_PARAM";
    case FX_ERR_BAD_RECIPE: return "FX_ERR_BAD_RECIPE";
    case FX_ERR_NO_CAMERA: return "FX_ERR_NO_CAMERA";
    case FX_ERR_CANCELLED: return "FX_ERR_CANCELLED";
    case FX_ERR_INTERNAL: return "FX_ERR_INTERNAL";
    case FX_ERR_NO_AUX_VIEW: return "FX_ERR_NO_AUX_VIEW";
    case FX_ERR_NO_LIGHTS: return "FX_ERR_NO_LIGHTS";
    }
    return "FX_ERR_UNKNOWN";
}

fx_result fx_context_new(fx_context **out, int threads)
{
    if (!out)
        return FX_ERR_INVALID_ARGUMENT;
    *out = NULL;
    fx_context *c = fx_mem_calloc(1, sizeof *c);
    if (!c)
        return FX_ERR_OUT_OF_MEMORY;
    if (threads <= 0)
        threads = fx_os_cpu_count();
    if (threads > 256)
        threads = 256;
    c->threads = threads;
    c->max_width = DEFAULT_MAX_DIM;
    c->max_height = DEFAULT_MAX_DIM;
    c->max_bytes = DEFAULT_MAX_BYTES;
    if (pthread_mutex_init(&c->lock, NULL) != 0) {
        fx_mem_free(c);
        return FX_ERR_INTERNAL;
    }
    *out = c;
    return FX_OK;
}

static void context_destroy(fx_context *ctx)
{
    fx_pool_free(ctx->pool);
    if (ctx->aux_cache_free)
        ctx->aux_cache_free(ctx);
    fx_buffers_free(ctx);
    for (int i = 0; i < ctx->warning_count; i++)
        fx_mem_free(ctx->warnings[i]);
    fx_mem_free(ctx->warnings);
    pthread_mutex_destroy(&ctx->lock);
    fx_mem_free(ctx);
}

void fx_context_free(fx_context *ctx)
{
    if (!ctx)
        return;
    pthread_mutex_lock(&ctx->lock);
    ctx->closed = 1;
    int live = ctx->frames;
    pthread_mutex_unlock(&ctx->lock);
    if (live == 0)
        context_destroy(ctx);
}

void fx_context_frame_born(fx_context *ctx)
{
    if (!ctx)
        return;
    pthread_mutex_lock(&ctx->lock);
    ctx->frames++;
    pthread_mutex_unlock(&ctx->lock);
}

void fx_context_frame_died(fx_context *ctx)
{
    if (!ctx)
        return;
    pthread_mutex_lock(&ctx->lock);
    int destroy = --ctx->frames == 0 && ctx->closed;
    pthread_mutex_unlock(&ctx->lock);
    if (destroy)
        context_destroy(ctx);
}

int fx_context_threads(const fx_context *ctx)
{
    return ctx ? ctx->threads : 0;
}

fx_result fx_context_set_limits(fx_context *ctx, int max_width, int max_height, uint64_t max_bytes)
{
    if (!ctx)
        return FX_ERR_INVALID_ARGUMENT;
    if (max_width <= 0 || max_height <= 0 || max_bytes == 0)
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT,
                       "limits must be positive (got %d x %d, %llu bytes)", max_width, max_height,
                       (unsigned long long)max_bytes);
    ctx->max_width = max_width;
    ctx->max_height = max_height;
    ctx->max_bytes = max_bytes;
    return FX_OK;
}

void fx_context_set_progress(fx_context *ctx, fx_progress_fn fn, void *user)
{
    if (!ctx)
        return;
    ctx->progress = fn;
    ctx->progress_user = user;
}

/* The slot of the calling thread, creating one (evicting round-robin) if needed.
 * Called with the lock held. The context is logically const: errors are a cache. */
static fx_thread_error *thread_slot(fx_context *c, int create)
{
    pthread_t self = pthread_self();
    for (int i = 0; i < FX_MAX_ERROR_SLOTS; i++)
        if (c->errors[i].used && pthread_equal(c->errors[i].thread, self))
            return &c->errors[i];
    if (!create)
        return NULL;
    fx_thread_error *e = &c->errors[c->next_error_slot];
    c->next_error_slot = (c->next_error_slot + 1) % FX_MAX_ERROR_SLOTS;
    e->used = 1;
    e->thread = self;
    e->message[0] = '\0';
    return e;
}

static fx_result failv(const fx_context *ctx, fx_result code, const char *fmt, va_list ap)
{
    if (!ctx)
        return code;
    fx_context *c = (fx_context *)ctx;
    pthread_mutex_lock(&c->lock);
    fx_thread_error *e = thread_slot(c, 1);
    vsnprintf(e->message, sizeof e->message, fmt, ap);
    pthread_mutex_unlock(&c->lock);
    return code;
}

fx_result fx_fail(const fx_context *ctx, fx_result code, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    failv(ctx, code, fmt, ap);
    va_end(ap);
    return code;
}

const char *fx_context_error(const fx_context *ctx)
{
    if (!ctx)
        return "no context";
    fx_context *c = (fx_context *)ctx;
    pthread_mutex_lock(&c->lock);
    fx_thread_error *e = thread_slot(c, 0);
    const char *m = e ? e->message : "";
    pthread_mutex_unlock(&c->lock);
    return m;
}

void fx_fail_prefix(const fx_context *ctx, fx_result code, const char *prefix)
{
    char msg[1024];
    snprintf(msg, sizeof msg, "%s", fx_context_error(ctx));
    fx_fail(ctx, code, "%s: %s", prefix, msg);
}

void fx_warn(const fx_context *ctx, const char *fmt, ...)
{
    if (!ctx)
        return;
    fx_context *c = (fx_context *)ctx;
    char buf[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    pthread_mutex_lock(&c->lock);
    if (c->warning_count < 10000) { /* a runaway loop must not eat memory */
        if (c->warning_count == c->warning_cap) {
            int cap = c->warning_cap ? c->warning_cap * 2 : 8;
            char **w = fx_mem_realloc(c->warnings, (size_t)cap * sizeof *w);
            if (w) {
                c->warnings = w;
                c->warning_cap = cap;
            }
        }
        if (c->warning_count < c->warning_cap) {
            char *copy = fx_mem_strdup(buf);
            if (copy)
                c->warnings[c->warning_count++] = copy;
        }
    }
    pthread_mutex_unlock(&c->lock);
}

int fx_context_warning_count(const fx_context *ctx)
{
    return ctx ? ctx->warning_count : 0;
}

const char *fx_context_warning(const fx_context *ctx, int index)
{
    if (!ctx || index < 0 || index >= ctx->warning_count)
        return NULL;
    return ctx->warnings[index];
}

void fx_context_clear_warnings(fx_context *ctx)
{
    if (!ctx)
        return;
    pthread_mutex_lock(&ctx->lock);
    for (int i = 0; i < ctx->warning_count; i++)
        fx_mem_free(ctx->warnings[i]);
    ctx->warning_count = 0;
    pthread_mutex_unlock(&ctx->lock);
}

fx_result fx_progress(const fx_context *ctx, const char *stage, double fraction)
{
    if (!ctx || !ctx->progress)
        return FX_OK;
    if (fraction < 0)
        fraction = 0;
    if (fraction > 1)
        fraction = 1;
    if (ctx->progress(ctx->progress_user, stage, fraction) != 0)
        return fx_fail(ctx, FX_ERR_CANCELLED, "cancelled during %s", stage);
    return FX_OK;
}

fx_result fx_check_budget(const fx_context *ctx, uint64_t bytes, const char *what)
{
    uint64_t max = ctx ? ctx->max_bytes : DEFAULT_MAX_BYTES;
    if (bytes > max)
        return fx_fail(ctx, FX_ERR_LIMIT, "%s needs %.1f MiB, over the memory budget of %.1f MiB",
                       what, (double)bytes / (1 << 20), (double)max / (1 << 20));
    return FX_OK;
}
