/* A small persistent thread pool owned by the context.
 *
 * fx_parallel_for cuts [0, n) into chunks of `grain` items and threads take chunks
 * from an atomic counter, the calling thread included. Which thread computes a chunk
 * never changes what it computes, so results are bit-identical for any thread count.
 * Nested calls, or a second thread calling while the pool is busy, run serially on
 * the caller rather than deadlock. Denormals are flushed to zero inside loops: the
 * workers set it once; the caller's floating-point state is saved and restored, since
 * the caller may be Blender's own thread (through ctypes). */
#include "core/parallel.h"
#include "core/mem.h"

#include <stdatomic.h>
#include <stdlib.h>

#if defined(__SSE__) || defined(__x86_64__)
#include <xmmintrin.h>
#define FX_HAVE_MXCSR 1
#define FX_MXCSR_FTZ_DAZ 0x8040u
#endif

struct fx_pool {
    pthread_t *threads;
    struct worker_start *starts;
    int count;
    pthread_mutex_t mutex;
    pthread_cond_t work_cv, done_cv;
    pthread_mutex_t busy; /* held by the thread running a loop on this pool */
    unsigned generation;
    int quit;
    int pending;
    /* the current loop */
    fx_worker_range_fn fn;
    void *user;
    int n, grain, chunks;
    atomic_int next;
};

static _Thread_local int in_parallel_loop;

static void run_chunks(fx_pool *p, int worker)
{
    for (;;) {
        int c = atomic_fetch_add(&p->next, 1);
        if (c >= p->chunks)
            break;
        int begin = c * p->grain;
        int end = begin + p->grain;
        if (end > p->n || end < begin)
            end = p->n;
        p->fn(p->user, begin, end, worker);
    }
}

typedef struct worker_start {
    fx_pool *pool;
    int index;
} worker_start;

static void *worker_main(void *arg)
{
    worker_start *ws = arg;
    fx_pool *p = ws->pool;
    int worker = ws->index;
#ifdef FX_HAVE_MXCSR
    _mm_setcsr(_mm_getcsr() | FX_MXCSR_FTZ_DAZ);
#endif
    in_parallel_loop = 1;
    unsigned seen = 0;
    pthread_mutex_lock(&p->mutex);
    for (;;) {
        while (!p->quit && p->generation == seen)
            pthread_cond_wait(&p->work_cv, &p->mutex);
        if (p->quit)
            break;
        seen = p->generation;
        pthread_mutex_unlock(&p->mutex);
        run_chunks(p, worker);
        pthread_mutex_lock(&p->mutex);
        if (--p->pending == 0)
            pthread_cond_signal(&p->done_cv);
    }
    pthread_mutex_unlock(&p->mutex);
    return NULL;
}

static fx_pool *pool_new(int workers)
{
    fx_pool *p = fx_mem_calloc(1, sizeof *p);
    if (!p)
        return NULL;
    p->threads = fx_mem_calloc((size_t)workers, sizeof *p->threads);
    p->starts = fx_mem_calloc((size_t)workers, sizeof *p->starts);
    if (!p->threads || !p->starts) {
        fx_mem_free(p->threads);
        fx_mem_free(p->starts);
        fx_mem_free(p);
        return NULL;
    }
    pthread_mutex_init(&p->mutex, NULL);
    pthread_mutex_init(&p->busy, NULL);
    pthread_cond_init(&p->work_cv, NULL);
    pthread_cond_init(&p->done_cv, NULL);
    for (int i = 0; i < workers; i++) {
        p->starts[i].pool = p;
        p->starts[i].index = i + 1; /* worker 0 is the calling thread */
        if (pthread_create(&p->threads[i], NULL, worker_main, &p->starts[i]) != 0)
            break;
        p->count++;
    }
    if (p->count == 0) {
        fx_pool_free(p);
        return NULL;
    }
    return p;
}

void fx_pool_free(fx_pool *p)
{
    if (!p)
        return;
    pthread_mutex_lock(&p->mutex);
    p->quit = 1;
    pthread_cond_broadcast(&p->work_cv);
    pthread_mutex_unlock(&p->mutex);
    for (int i = 0; i < p->count; i++)
        pthread_join(p->threads[i], NULL);
    pthread_cond_destroy(&p->work_cv);
    pthread_cond_destroy(&p->done_cv);
    pthread_mutex_destroy(&p->mutex);
    pthread_mutex_destroy(&p->busy);
    fx_mem_free(p->threads);
    fx_mem_free(p->starts);
    fx_mem_free(p);
}

static void run_serial(int n, int grain, fx_worker_range_fn fn, void *user)
{
    for (int begin = 0; begin < n; begin += grain) {
        int end = begin + grain;
        if (end > n || end < begin)
            end = n;
        fn(user, begin, end, 0);
    }
}

int fx_parallel_workers(const fx_context *ctx)
{
    return ctx && ctx->threads > 1 ? ctx->threads : 1;
}

void fx_parallel_for_worker(fx_context *ctx, int n, int grain, fx_worker_range_fn fn, void *user)
{
    if (n <= 0 || !fn)
        return;
    if (grain < 1)
        grain = 1;
#ifdef FX_HAVE_MXCSR
    unsigned saved_csr = _mm_getcsr();
    _mm_setcsr(saved_csr | FX_MXCSR_FTZ_DAZ);
#endif
    int chunks = (int)(((long long)n + grain - 1) / grain);
    if (!ctx || ctx->threads <= 1 || chunks <= 1 || in_parallel_loop) {
        run_serial(n, grain, fn, user);
    } else {
        fx_pool *p = ctx->pool;
        if (!p) {
            /* Created on first use; the context is used by one thread at a time. */
            p = ctx->pool = pool_new(ctx->threads - 1);
        }
        if (!p || pthread_mutex_trylock(&p->busy) != 0) {
            run_serial(n, grain, fn, user);
        } else {
            pthread_mutex_lock(&p->mutex);
            p->fn = fn;
            p->user = user;
            p->n = n;
            p->grain = grain;
            p->chunks = chunks;
            atomic_store(&p->next, 0);
            p->pending = p->count;
            p->generation++;
            pthread_cond_broadcast(&p->work_cv);
            pthread_mutex_unlock(&p->mutex);

            in_parallel_loop = 1;
            run_chunks(p, 0);
            in_parallel_loop = 0;

            pthread_mutex_lock(&p->mutex);
            while (p->pending > 0)
                pthread_cond_wait(&p->done_cv, &p->mutex);
            pthread_mutex_unlock(&p->mutex);
            pthread_mutex_unlock(&p->busy);
        }
    }
#ifdef FX_HAVE_MXCSR
    _mm_setcsr(saved_csr);
#endif
}

/* Plain loops ride on the worker-aware one. */
typedef struct plain_loop {
    fx_range_fn fn;
    void *user;
} plain_loop;

static void plain_range(void *user, int begin, int end, int worker)
{
    (void)worker;
    plain_loop *l = user;
    l->fn(l->user, begin, end);
}

void fx_parallel_for(fx_context *ctx, int n, int grain, fx_range_fn fn, void *user)
{
    if (!fn)
        return;
    plain_loop l = {fn, user};
    fx_parallel_for_worker(ctx, n, grain, plain_range, &l);
}

int fx_grain_for(const fx_context *ctx, int n)
{
    int t = ctx && ctx->threads > 0 ? ctx->threads : 1;
    int g = n / (8 * t);
    return g < 1 ? 1 : g;
}
