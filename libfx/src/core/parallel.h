/* The library's own parallel loop. Work is cut into fixed chunks independent of the
 * thread count, so every chunk is computed by the same code whatever thread runs it:
 * output is bit-identical for 1 and N threads. Denormals are flushed to zero while a
 * loop runs (in workers, and on the calling thread with its FP state restored after). */
#ifndef LIBFX_PARALLEL_H
#define LIBFX_PARALLEL_H

#include "core/context.h"

#ifdef __cplusplus
extern "C" {
#endif

/* fn(user, begin, end) for consecutive ranges of at most `grain` items covering [0, n). */
typedef void (*fx_range_fn)(void *user, int begin, int end);

/* Runs on ctx's threads; if the pool cannot start, the loop runs on the calling thread. */
void fx_parallel_for(fx_context *ctx, int n, int grain, fx_range_fn fn, void *user);

/* The same, telling fn which worker runs it: 0 <= worker < fx_parallel_workers(ctx),
 * for per-worker scratch buffers. Which worker runs a chunk varies between runs, so
 * the result must not depend on it. */
typedef void (*fx_worker_range_fn)(void *user, int begin, int end, int worker);
void fx_parallel_for_worker(fx_context *ctx, int n, int grain, fx_worker_range_fn fn, void *user);
int fx_parallel_workers(const fx_context *ctx);

void fx_pool_free(fx_pool *pool);

/* A grain that gives each thread several chunks for balance: ~n / (8 * threads), >= 1.
 * Only for loops whose items are independent: a reduction must use a fixed grain so
 * its partial sums do not depend on the thread count. */
int fx_grain_for(const fx_context *ctx, int n);

#ifdef __cplusplus
}
#endif
#endif
