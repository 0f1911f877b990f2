/* The per-context store of large pixel buffers.
 *
 * Large pixel buffers come from, and go back to, a small per-context store: a batch of
 * same-size frames then reuses memory that is already mapped instead of page-faulting
 * a fresh buffer for every pass and effect (a 1080p RGBA float buffer is 8100 faults).
 * Small buffers and a full store fall through to fx_mem. ctx may be NULL. */
#ifndef LIBFX_CORE_BUFFERS_H
#define LIBFX_CORE_BUFFERS_H

#include "libfx/fx.h"

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

void *fx_buffer_get(fx_context *ctx, size_t bytes);
/* A buffer of at least `bytes` for a caller that can use a bigger one: exactly that size if
 * held, else the smallest held one up to 4x as big (already mapped: a process's first frame
 * need not fault in a fresh one while a larger buffer of the frame sits idle), else a new
 * one. *capacity: its real size, to give back to fx_buffer_put (0 on failure). */
void *fx_buffer_get_at_least(fx_context *ctx, size_t bytes, size_t *capacity);
/* As fx_buffer_get, but a new buffer comes as whole huge pages from 256 KiB up
 * (fx_mem_alloc_whole): for maps that are faulted in row by row as they are built. */
void *fx_buffer_get_whole(fx_context *ctx, size_t bytes);
void fx_buffer_put(fx_context *ctx, void *p, size_t bytes);
void fx_buffers_free(fx_context *ctx);

#ifdef __cplusplus
}
#endif
#endif
