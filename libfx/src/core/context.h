/* The context's insides: threads, limits, progress, the per-thread last error and the
 * warnings, plus the per-context stores other parts hang on it. */
#ifndef LIBFX_CORE_CONTEXT_H
#define LIBFX_CORE_CONTEXT_H

#include "libfx/fx.h"

#include <pthread.h>
#include <stdarg.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#if defined(__MINGW32__)
/* MinGW's stdio is the C99 one in C11 mode (__USE_MINGW_ANSI_STDIO), not msvcrt's: %zu works */
#  define FX_PRINTF(a, b) __attribute__((format(gnu_printf, a, b)))
#elif defined(__GNUC__)
#  define FX_PRINTF(a, b) __attribute__((format(printf, a, b)))
#else
#  define FX_PRINTF(a, b)
#endif

typedef struct fx_thread_error {
    pthread_t thread;
    int used;
    char message[1024];
} fx_thread_error;

#define FX_MAX_ERROR_SLOTS 32

typedef struct fx_pool fx_pool;

struct fx_context {
    int threads;
    int max_width, max_height;
    uint64_t max_bytes;
    fx_progress_fn progress;
    void *progress_user;
    pthread_mutex_t lock;          /* guards errors and warnings */
    fx_thread_error errors[FX_MAX_ERROR_SLOTS];
    int next_error_slot;
    char **warnings;
    int warning_count, warning_cap;
    fx_pool *pool;                 /* worker threads, created on first parallel loop */
    /* Built aux-view maps reused across frames. The scene layer owns the cache and sets
     * its destructor here when it makes one, so the context frees it without knowing it. */
    struct fx_aux_cache *aux_cache;
    void (*aux_cache_free)(fx_context *ctx);
    struct fx_buffer_slot *buffers; /* freed pixel buffers kept for reuse (core/buffers.c) */
    int buffer_count;
    int frames;                     /* live frames: they return buffers here when freed */
    int closed;                     /* fx_context_free was called; freed with the last frame */
};

/* Records the calling thread's error on ctx and returns code. ctx may be NULL. */
fx_result fx_fail(const fx_context *ctx, fx_result code, const char *fmt, ...) FX_PRINTF(3, 4);
/* Re-records the calling thread's last message as "<prefix>: <message>". */
void fx_fail_prefix(const fx_context *ctx, fx_result code, const char *prefix);
void fx_warn(const fx_context *ctx, const char *fmt, ...) FX_PRINTF(2, 3);
/* Reports progress; returns FX_ERR_CANCELLED (with a message) if the callback asks to stop. */
fx_result fx_progress(const fx_context *ctx, const char *stage, double fraction);
/* Checks `bytes` against the context's budget; fails with FX_ERR_LIMIT naming `what`. */
fx_result fx_check_budget(const fx_context *ctx, uint64_t bytes, const char *what);

/* Frames keep their context alive: fx_context_free while frames live only marks it
 * closed, and the last fx_frame_free releases it (a binding's garbage collector may
 * free frames after their context). */
void fx_context_frame_born(fx_context *ctx);
void fx_context_frame_died(fx_context *ctx);

#ifdef __cplusplus
}
#endif
#endif
