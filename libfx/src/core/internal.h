/* Internal structures and helpers shared by the library's parts (never installed). */
#ifndef LIBFX_INTERNAL_H
#define LIBFX_INTERNAL_H

#include "libfx/fx.h"
#include "core/passes.h"

#include <pthread.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#if defined(__GNUC__)
#  define FX_PRINTF(a, b) __attribute__((format(printf, a, b)))
#else
#  define FX_PRINTF(a, b)
#endif

/* ---- memory: every allocation goes through here (failure injection in tests) ---- */
/* Blocks of 2 MiB and more come huge-page aligned and advised (fewer first-touch faults). */
void *fx_mem_alloc(size_t n);
void *fx_mem_calloc(size_t count, size_t size);
void *fx_mem_realloc(void *p, size_t n);
void fx_mem_free(void *p);
char *fx_mem_strdup(const char *s);
/* Test hook: the Nth allocation from now fails (0 disables). Not exported from the .so. */
void fx_mem_fail_after(long n);
/* a * b * c with overflow check; returns 0 and leaves *out untouched on overflow. */
int fx_size_mul(size_t *out, size_t a, size_t b, size_t c);

/* ---- context ---- */
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
    struct fx_aux_cache *aux_cache;/* built aux-view maps reused across frames (core/aux_view.c) */
    struct fx_buffer_slot *buffers; /* freed pixel buffers kept for reuse (core/buffers.c) */
    int buffer_count;
    int frames;                     /* live frames: they return buffers here when freed */
    int closed;                     /* fx_context_free was called; freed with the last frame */
};

/* Frees the context's aux-view cache (core/aux_view.c). */
void fx_aux_cache_free(fx_context *ctx);

/* Records the calling thread's error on ctx and returns code. ctx may be NULL. */
fx_result fx_fail(const fx_context *ctx, fx_result code, const char *fmt, ...) FX_PRINTF(3, 4);
fx_result fx_failv(const fx_context *ctx, fx_result code, const char *fmt, va_list ap);
void fx_warn(const fx_context *ctx, const char *fmt, ...) FX_PRINTF(2, 3);
/* Reports progress; returns FX_ERR_CANCELLED (with a message) if the callback asks to stop. */
fx_result fx_progress(const fx_context *ctx, const char *stage, double fraction);
/* Checks `bytes` against the context's budget; fails with FX_ERR_LIMIT naming `what`. */
fx_result fx_check_budget(const fx_context *ctx, uint64_t bytes, const char *what);

/* ---- pixel buffers ---- */
/* Large pixel buffers come from, and go back to, a small per-context store: a batch of
 * same-size frames then reuses memory that is already mapped instead of page-faulting
 * a fresh buffer for every pass and effect (a 1080p RGBA float buffer is 8100 faults).
 * Small buffers and a full store fall through to fx_mem. ctx may be NULL. */
void *fx_buffer_get(fx_context *ctx, size_t bytes);
void fx_buffer_put(fx_context *ctx, void *p, size_t bytes);
void fx_buffers_free(fx_context *ctx);
/* Frames keep their context alive: fx_context_free while frames live only marks it
 * closed, and the last fx_frame_free releases it (a binding's garbage collector may
 * free frames after their context). */
void fx_context_frame_born(fx_context *ctx);
void fx_context_frame_died(fx_context *ctx);

/* ---- frames ---- */
#define FX_NAME_MAX 96

/* A pass's pixel buffer, counted: frames of one context share it instead of copying
 * (an empty stack's output, fx_frame_copy_passes). It goes back to the buffer store with
 * its last holder; a holder that hands out a writable pointer gets its own copy first. */
typedef struct fx_pixels fx_pixels;

typedef struct fx_pass {
    char name[FX_NAME_MAX];  /* canonical name: "Combined", "Depth", "CryptoObject00", ... */
    int channels;            /* 1..4, interleaved */
    int from_half;           /* decoded from half floats (written back as half if asked) */
    int handed_out;          /* fx_frame_pass gave a writable pointer: never shared again */
    float *data;             /* width * height * channels; read-only while shared */
    fx_pixels *pixels;       /* the counted buffer data points into */
} fx_pass;

typedef struct fx_meta {
    char *key;
    char *value;
} fx_meta;

struct fx_frame {
    fx_context *ctx;
    int width, height;
    int data_window[4], display_window[4];
    fx_pass *passes;
    int pass_count, pass_cap;
    int has_camera;
    fx_camera camera;
    double frame_number, fps;
    fx_meta *meta;
    int meta_count, meta_cap;
    /* A proxy (fx_frame_reduce): frame pixel (x, y) covers the full frame's pixels
     * [x f, x f + f) x [y f, y f + f) of its data window, f = proxy_factor (1: a full frame).
     * full_*_window are the full frame's windows (valid when proxy_factor > 1): the camera
     * maps pixels through them exactly, also when a size is not a multiple of f. */
    int proxy_factor;
    int full_data_window[4], full_display_window[4];
};

/* Lookup without error reporting; NULL if absent. */
fx_pass *fx_frame_find_pass(const fx_frame *f, const char *name);
/* Adds a pass and hands its (uninitialised) buffer back; replaces one of the same name. */
fx_result fx_frame_alloc_pass(fx_frame *f, const char *name, int channels, float **out);
/* Takes ownership of `data`: width*height*channels floats from fx_mem_alloc or fx_buffer_get. */
fx_result fx_frame_adopt_pass(fx_frame *f, const char *name, int channels, float *data);
/* Gives dst a pass named `name` holding src_pass's pixels: shared when both frames have
 * one context and the pass was never handed out writable, else copied. Same sizes only. */
fx_result fx_frame_share_pass(fx_frame *dst, const char *name, const fx_frame *src, const fx_pass *src_pass);
/* How many passes (in any frames) hold p's pixels. */
int fx_frame_pixels_holders(const fx_pass *p);
/* New frame with f's size, windows, camera, time, metadata and proxy factor, no passes. */
fx_result fx_frame_new_like(const fx_frame *f, fx_frame **out);

/* Replaces NaN with 0 and +-Inf with +-FLT_MAX in place; returns how many were replaced.
 * Runs in parallel on ctx's pool. */
size_t fx_sanitize_floats(fx_context *ctx, float *data, size_t count);
/* The same for one span on the calling thread; a branch-free scan first, so an all-finite
 * span (the usual case) costs one read. */
size_t fx_span_make_finite(float *data, size_t count);

/* ---- cameras in JSON ---- */
struct cJSON;
/* Parses a camera object (sidecar or aux view); 0 with a message in err when malformed.
 * zero_clip_start_ok: aux depth views may start at clip 0. */
int fx_camera_parse(const struct cJSON *obj, int zero_clip_start_ok, fx_camera *cam, char *err, size_t err_size);

/* ---- text files ---- */
/* Reads a whole text file (NUL-terminated, freed with fx_mem_free); `what` names it in
 * messages ("recipe", "sidecar"). Larger than max_bytes: FX_ERR_BAD_RECIPE. */
fx_result fx_read_text_file(const fx_context *ctx, const char *path, size_t max_bytes, const char *what,
                            char **out);
/* Re-records the calling thread's last message as "<prefix>: <message>". */
void fx_fail_prefix(const fx_context *ctx, fx_result code, const char *prefix);

/* ---- stacks ---- */
/* Union of the passes the enabled effects and their masks need (Combined always). */
fx_pass_set fx_stack_pass_set(const fx_stack *s);

/* ---- JSON strings handed to callers ---- */
char *fx_json_strdup(const char *s); /* copy in fx_mem memory for fx_free */

#ifdef __cplusplus
}
#endif
#endif
