/* The frame's insides: named float passes sharing counted pixel buffers, windows, camera,
 * time, metadata and the proxy factor. */
#ifndef LIBFX_CORE_FRAME_H
#define LIBFX_CORE_FRAME_H

#include "libfx/fx.h"

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

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
/* Gives dst a pass named `name` holding src_pass's pixels: shared when the pass was never
 * handed out writable (in any two frames, of one context or two), else copied. Same sizes
 * only. */
fx_result fx_frame_share_pass(fx_frame *dst, const char *name, const fx_frame *src, const fx_pass *src_pass);
/* Takes the pixels of f's pass `name` out of the frame (the pass is removed) when the pass
 * alone holds them: the caller owns them (fx_mem_free or fx_buffer_put). NULL when there is
 * no such pass or another pass holds its pixels too (the frame is then unchanged). */
float *fx_frame_take_pass_data(fx_frame *f, const char *name);
/* How many passes (in any frames) hold p's pixels. */
int fx_frame_pixels_holders(const fx_pass *p);
/* New frame with f's size, windows, camera, time, metadata and proxy factor, no passes. */
fx_result fx_frame_new_like(const fx_frame *f, fx_frame **out);
/* The same, in context ctx (its buffer store takes the new frame's buffers back). */
fx_result fx_frame_new_like_in(fx_context *ctx, const fx_frame *f, fx_frame **out);

/* Replaces NaN with 0 and +-Inf with +-FLT_MAX in place; returns how many were replaced.
 * Runs in parallel on ctx's pool. */
size_t fx_sanitize_floats(fx_context *ctx, float *data, size_t count);
/* The same for one span on the calling thread; a branch-free scan first, so an all-finite
 * span (the usual case) costs one read. */
size_t fx_span_make_finite(float *data, size_t count);

#ifdef __cplusplus
}
#endif
#endif
