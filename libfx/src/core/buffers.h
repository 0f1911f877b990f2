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
void fx_buffer_put(fx_context *ctx, void *p, size_t bytes);
void fx_buffers_free(fx_context *ctx);

#ifdef __cplusplus
}
#endif
#endif
