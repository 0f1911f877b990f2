/* The per-context store of freed pixel buffers (core/buffers.h). */
#include "core/buffers.h"
#include "core/context.h"
#include "core/mem.h"

#include <string.h>

#define BUFFER_MIN ((size_t)1 << 20) /* smaller ones are cheap to map: plain fx_mem */
/* A whole frame's buffers (its passes, the stack's two images, the effects' planes): the
 * greek bath's stack puts 17 back per 1080p frame (7 of 33 MB, 4 of 25 MB, ...); with 6 slots
 * most were evicted and every frame faulted them in afresh (~900 minor faults and their
 * zeroing per warm frame). The byte cap below bounds what is held. */
#define BUFFER_SLOTS 32
#define BUFFER_MAX_BYTES ((uint64_t)1 << 30)

typedef struct fx_buffer_slot {
    void *p;
    size_t bytes;
} fx_buffer_slot;

/* A held buffer of exactly `bytes`, or with slack > 1 the smallest of [bytes, slack x bytes]
 * (taken out of the store; its size in *got), or NULL. */
static void *take(fx_context *ctx, size_t bytes, size_t slack, size_t *got)
{
    void *p = NULL;
    pthread_mutex_lock(&ctx->lock);
    int best = -1;
    for (int i = 0; i < ctx->buffer_count; i++) {
        const size_t b = ctx->buffers[i].bytes;
        if (b == bytes) {
            best = i;
            break;
        }
        if (slack > 1 && b > bytes && b / slack <= bytes && (best < 0 || b < ctx->buffers[best].bytes))
            best = i;
    }
    if (best >= 0) {
        p = ctx->buffers[best].p;
        *got = ctx->buffers[best].bytes;
        ctx->buffers[best] = ctx->buffers[--ctx->buffer_count];
    }
    pthread_mutex_unlock(&ctx->lock);
    return p;
}

void *fx_buffer_get(fx_context *ctx, size_t bytes)
{
    size_t got = 0;
    void *p = ctx && bytes >= BUFFER_MIN ? take(ctx, bytes, 1, &got) : NULL;
    return p ? p : fx_mem_alloc(bytes);
}

void *fx_buffer_get_whole(fx_context *ctx, size_t bytes)
{
    size_t got = 0;
    void *p = ctx && bytes >= BUFFER_MIN ? take(ctx, bytes, 1, &got) : NULL;
    return p ? p : fx_mem_alloc_whole(bytes);
}

void *fx_buffer_get_at_least(fx_context *ctx, size_t bytes, size_t *capacity)
{
    size_t got = 0;
    void *p = ctx && bytes >= BUFFER_MIN ? take(ctx, bytes, 4, &got) : NULL;
    if (!p) {
        p = fx_mem_alloc(bytes);
        got = bytes;
    }
    *capacity = p ? got : 0;
    return p;
}

void fx_buffer_put(fx_context *ctx, void *p, size_t bytes)
{
    if (!p)
        return;
    if (ctx && bytes >= BUFFER_MIN) {
        pthread_mutex_lock(&ctx->lock);
        if (!ctx->buffers)
            ctx->buffers = fx_mem_calloc(BUFFER_SLOTS, sizeof *ctx->buffers);
        uint64_t held = 0;
        for (int i = 0; i < ctx->buffer_count; i++)
            held += ctx->buffers[i].bytes;
        uint64_t cap = ctx->max_bytes / 4 < BUFFER_MAX_BYTES ? ctx->max_bytes / 4 : BUFFER_MAX_BYTES;
        int kept = 0;
        if (ctx->buffers && held + bytes <= cap) {
            if (ctx->buffer_count == BUFFER_SLOTS) {
                /* full: the oldest goes */
                fx_mem_free(ctx->buffers[0].p);
                memmove(ctx->buffers, ctx->buffers + 1, (BUFFER_SLOTS - 1) * sizeof *ctx->buffers);
                ctx->buffer_count--;
            }
            ctx->buffers[ctx->buffer_count].p = p;
            ctx->buffers[ctx->buffer_count].bytes = bytes;
            ctx->buffer_count++;
            kept = 1;
        }
        pthread_mutex_unlock(&ctx->lock);
        if (kept)
            return;
    }
    fx_mem_free(p);
}

void fx_buffers_free(fx_context *ctx)
{
    if (!ctx)
        return;
    for (int i = 0; i < ctx->buffer_count; i++)
        fx_mem_free(ctx->buffers[i].p);
    fx_mem_free(ctx->buffers);
    ctx->buffers = NULL;
    ctx->buffer_count = 0;
}
