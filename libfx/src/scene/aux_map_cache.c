/* The per-context LRU cache of shadow maps built from aux views (scene/aux_map.h). */
#include "core/buffers.h"
#include "core/context.h"
#include "core/frame.h"
#include "core/mem.h"
#include "core/platform.h"
#include "io/exr_rows.h"
#include "scene/aux_map.h"

#include <cjson/cJSON.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#define AUX_CACHE_DEFAULT_BYTES ((uint64_t)768 << 20) /* a 4096^2 light map is 192 MiB */
#define AUX_CACHE_MAX_ENTRIES 32 /* light views, the rain map, a probe and a planar view per mirror */

typedef struct aux_entry {
    char *key;
    fx_aux_view *av;
    fx_shadow_map sm;
    float *pixels; /* a view kept as read: its colour and depth, copied out of its EXR */
    uint64_t bytes, last_use;
    int refs;
} aux_entry;

struct fx_aux_cache {
    uint64_t limit;
    int limit_set;
    aux_entry e[AUX_CACHE_MAX_ENTRIES];
    int n;
    uint64_t clock;
    long built, reused;
};

/* The map's normalised depth (a light view's frame-sized buffer, or its copy: both from
 * fx_mem_alloc) goes back to the context's buffer store: with the cache off (each acquire
 * builds a private map, freed at release) the next read of the view takes it instead of
 * fresh pages. */
static void entry_free(fx_context *ctx, aux_entry *e)
{
    if (e->sm.depth) {
        fx_buffer_put(ctx, e->sm.depth, (size_t)e->sm.width * (size_t)e->sm.height * sizeof(float));
        e->sm.depth = NULL;
    }
    fx_mem_free(e->key);
    fx_mem_free(e->pixels);
    fx_aux_view_free(e->av);
    fx_shadow_map_free(&e->sm);
    memset(e, 0, sizeof *e);
}

static void aux_cache_free(fx_context *ctx);

static struct fx_aux_cache *cache_of(fx_context *ctx)
{
    if (!ctx->aux_cache) {
        ctx->aux_cache = fx_mem_calloc(1, sizeof *ctx->aux_cache);
        if (ctx->aux_cache)
            ctx->aux_cache_free = aux_cache_free;
    }
    return ctx->aux_cache;
}

static uint64_t cache_limit(const fx_context *ctx)
{
    uint64_t lim = ctx->aux_cache && ctx->aux_cache->limit_set ? ctx->aux_cache->limit : AUX_CACHE_DEFAULT_BYTES;
    return lim < ctx->max_bytes ? lim : ctx->max_bytes;
}

/* Evicts unused entries, least recently used first, until `need` more bytes and one more
 * entry fit; returns 0 when they cannot. */
static int cache_make_room(fx_context *ctx, uint64_t need)
{
    struct fx_aux_cache *c = ctx->aux_cache;
    uint64_t lim = cache_limit(ctx);
    if (need > lim)
        return 0;
    for (;;) {
        uint64_t used = 0;
        int victim = -1;
        for (int i = 0; i < c->n; i++) {
            used += c->e[i].bytes;
            if (!c->e[i].refs && (victim < 0 || c->e[i].last_use < c->e[victim].last_use))
                victim = i;
        }
        if (used + need <= lim && c->n < AUX_CACHE_MAX_ENTRIES)
            return 1;
        if (victim < 0)
            return 0;
        entry_free(ctx, &c->e[victim]);
        c->e[victim] = c->e[--c->n];
        memset(&c->e[c->n], 0, sizeof c->e[c->n]);
    }
}

fx_result fx_context_set_aux_cache(fx_context *ctx, uint64_t max_bytes)
{
    if (!ctx)
        return FX_ERR_INVALID_ARGUMENT;
    struct fx_aux_cache *c = cache_of(ctx);
    if (!c)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "fx_context_set_aux_cache: out of memory");
    c->limit = max_bytes;
    c->limit_set = 1;
    for (int i = c->n - 1; i >= 0; i--)
        if (!c->e[i].refs) {
            entry_free(ctx, &c->e[i]);
            c->e[i] = c->e[--c->n];
            memset(&c->e[c->n], 0, sizeof c->e[c->n]);
        }
    return FX_OK;
}

/* Frees every entry; fx_context_free calls it through the context's aux_cache_free. */
static void aux_cache_free(fx_context *ctx)
{
    if (!ctx || !ctx->aux_cache)
        return;
    for (int i = 0; i < ctx->aux_cache->n; i++)
        entry_free(ctx, &ctx->aux_cache->e[i]);
    fx_mem_free(ctx->aux_cache);
    ctx->aux_cache = NULL;
}

void fx_aux_cache_stats(const fx_context *ctx, long *built, long *reused)
{
    *built = ctx && ctx->aux_cache ? ctx->aux_cache->built : 0;
    *reused = ctx && ctx->aux_cache ? ctx->aux_cache->reused : 0;
}

/* filter value of an entry that keeps the view as read (fx_aux_view_acquire) */
#define AUX_RAW_VIEW (-2)
/* filter value of an entry holding a view's unfiltered moments at reduction level L, the
 * base its filtered maps are made from (entry_from_base) */
#define AUX_MOMENTS(level) (-16 - (level))
#define AUX_MOMENTS_LEVEL(filter) (-16 - (filter))

static fx_result acquire(const fx_frame *f, const char *name, int derivative_bias, int filter, float width,
                         int factor, const char *where, fx_aux_map *out);

/* Filtered maps made from the cached moments: those whose moments are made first and
 * filtered after (fx_shadow_map_filter). The full-resolution box filters straight from the
 * depth instead (box_from_depth: other bits): it starts from the cached normalised depth. */
static int from_moments(int filter)
{
    return !(FX_SHADOW_FILTER_LEVEL(filter) == 0 && FX_SHADOW_FILTER_KIND(filter) == FX_SHADOW_FILTER_BOX_SAT);
}

/* Entry e (a filtered map) from the view's cached base entry: a copy of its unfiltered
 * moments (then the map has moments only, depth NULL: the VSM lookup reads nothing else),
 * or for the full-resolution box a copy of its normalised depth, then the filter. The same
 * operations as building the map whole, so the same bits; a new width (a slider moved in
 * the live loop) reads no view and makes no moments. */
static fx_result entry_from_base(const fx_frame *f, const char *name, int bias, int filter, float width,
                                 const char *where, aux_entry *e)
{
    int level = FX_SHADOW_FILTER_LEVEL(filter);
    level = level > FX_SHADOW_MAX_LEVEL ? FX_SHADOW_MAX_LEVEL : level;
    const int moments = from_moments(filter);
    fx_aux_map base;
    fx_result r = acquire(f, name, bias, moments ? AUX_MOMENTS(level) : -1, 0.0f, 1, where, &base);
    if (r)
        return r;
    const float *src = moments ? base.sm->moments : base.sm->depth;
    const size_t floats = moments ? (size_t)base.sm->mwidth * base.sm->mheight * 2
                                  : (size_t)base.sm->width * base.sm->height;
    e->av = fx_mem_alloc(sizeof *e->av);
    float *copy = fx_mem_alloc(floats * sizeof(float));
    if (!e->av || !copy) {
        fx_mem_free(copy);
        fx_aux_map_release(&base);
        return fx_fail(f->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for aux view '%s'", where, name);
    }
    *e->av = *base.av; /* its camera and name; no frame, depth or colour of its own */
    e->av->frame = NULL;
    e->av->depth = e->av->color = NULL;
    memcpy(copy, src, floats * sizeof(float));
    e->sm = *base.sm;
    e->sm.depth = moments ? NULL : copy;
    e->sm.moments = moments ? copy : NULL;
    fx_aux_map_release(&base);
    r = fx_shadow_map_filter(f->ctx, &e->sm, (fx_shadow_filter)filter, width, where);
    e->bytes = ((e->sm.depth ? (uint64_t)e->sm.width * e->sm.height : 0) +
                (e->sm.moments ? (uint64_t)e->sm.mwidth * e->sm.mheight * 2 : 0)) * sizeof(float) + sizeof *e->av;
    return r;
}

typedef struct reduce_ctx {
    fx_shadow_map *sm;
    int raw_width;
} reduce_ctx;

static void reduce_row(void *user, int Y, float *row, int worker)
{
    (void)worker;
    const reduce_ctx *c = user;
    fx_shadow_map_reduced_row(c->sm, Y, row, c->raw_width);
}

/* Entry e as the view's depth reduced by factor per axis: only its kept rows read from its
 * EXR, straight into the reduced map, when the file allows it (no frame-sized buffer is
 * ever touched: on a first frame their fresh pages cost more than the read), else read
 * whole and reduced; the same bits either way. Its view addresses the kept texels
 * (fx_view_reduce_sampled). */
static fx_result entry_build_reduced(const fx_frame *f, const char *name, int factor, const char *where,
                                     aux_entry *e)
{
    fx_exr_rows *rows = NULL;
    fx_result r = fx_aux_view_open_rows(f, name, where, &e->av, &rows);
    if (r)
        return r;
    fx_aux_view *av = e->av;
    const float zn = av->view.cam.clip_start, zf = av->view.cam.clip_end;
    if (rows) {
        size_t bad = 0;
        r = fx_shadow_map_reduced_begin(f->ctx, av->width, av->height, factor, zn, zf, &e->sm, where);
        if (!r)
            r = fx_exr_rows_read_sampled(rows, factor, fx_shadow_map_sample_offset(factor), reduce_row,
                                         &(reduce_ctx){&e->sm, av->width}, &bad);
        if (!r)
            fx_shadow_map_reduced_end(&e->sm);
        if (!r && bad)
            fx_warn(f->ctx, "'%s': %zu NaN/Inf values in pass Depth replaced", av->path, bad);
        fx_exr_rows_close(rows);
    } else {
        r = fx_shadow_map_build_reduced(f->ctx, av->depth, av->width, av->height, factor, zn, zf, &e->sm, where);
    }
    if (r)
        return r;
    fx_frame_free(av->frame);
    av->frame = NULL;
    av->depth = NULL;
    fx_view_reduce_sampled(&av->view, factor);
    av->width = e->sm.width;
    av->height = e->sm.height;
    e->bytes = (uint64_t)e->sm.width * e->sm.height * sizeof(float) + sizeof *av;
    return FX_OK;
}

/* Builds the map of entry e (key already set). keep_frame: a view kept as read stays in
 * its EXR's frame (an entry that cannot go into the cache: released within the run). */
static fx_result entry_build(const fx_frame *f, const char *name, int bias, int filter, float width, int factor,
                             const char *where, int keep_frame, aux_entry *e)
{
    if (factor > 1)
        return entry_build_reduced(f, name, factor, where, e);
    if (filter >= 0 && width > 1.0f)
        return entry_from_base(f, name, bias, filter, width, where, e);
    fx_result r = fx_aux_view_load(f, name, where, &e->av);
    if (r)
        return r;
    fx_aux_view *av = e->av;
    if (filter == AUX_RAW_VIEW && keep_frame) {
        e->bytes = (uint64_t)av->width * av->height * 5 * sizeof(float) + sizeof *av;
        return FX_OK;
    }
    if (filter == AUX_RAW_VIEW) {
        /* Its pixels move out of the EXR's frame, which is freed: a frame kept here would
         * keep its context alive (fx_context_free waits for the last frame), and with it
         * this cache, which only the context's end frees. */
        const size_t n = (size_t)av->width * av->height;
        const size_t floats = (av->color ? 4 * n : 0) + (av->depth ? n : 0);
        if (floats && !(e->pixels = fx_mem_alloc(floats * sizeof(float))))
            return fx_fail(f->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for aux view '%s'", where, name);
        float *q = e->pixels;
        if (av->color) {
            memcpy(q, av->color, 4 * n * sizeof(float));
            av->color = q;
            q += 4 * n;
        }
        if (av->depth) {
            memcpy(q, av->depth, n * sizeof(float));
            av->depth = q;
        }
        fx_frame_free(av->frame);
        av->frame = NULL;
        e->bytes = (uint64_t)floats * sizeof(float) + sizeof *av;
        return FX_OK;
    }
    /* the EXR's depth is dropped below: the map normalises it where it lies (one buffer
     * fewer, no fresh pages on a first frame) when the pass alone holds it */
    float *own = fx_frame_take_pass_data(av->frame, "Depth");
    if (own) {
        r = fx_shadow_map_build_in_place(f->ctx, own, av->width, av->height, av->view.cam.clip_start,
                                         av->view.cam.clip_end, bias, &e->sm, where);
        if (r)
            fx_mem_free(own);
        av->depth = NULL;
    } else {
        r = fx_shadow_map_build(f->ctx, av->depth, av->width, av->height, av->view.cam.clip_start,
                                av->view.cam.clip_end, bias, &e->sm, where);
    }
    if (!r && filter <= AUX_MOMENTS(0))
        /* width 1: the moments at the level, unfiltered */
        r = fx_shadow_map_filter(f->ctx, &e->sm,
                                 (fx_shadow_filter)FX_SHADOW_FILTER_WITH_LEVEL(FX_SHADOW_FILTER_BOX_SAT,
                                                                               AUX_MOMENTS_LEVEL(filter)),
                                 1.0f, where);
    else if (!r && filter >= 0 && width > 1.0f)
        r = fx_shadow_map_filter(f->ctx, &e->sm, (fx_shadow_filter)filter, width, where);
    if (r)
        return r;
    /* the raw depth is in the map now: drop the EXR */
    fx_frame_free(av->frame);
    av->frame = NULL;
    av->depth = NULL;
    if (filter <= AUX_MOMENTS(0)) {
        /* only the moments are copied out of a base: its normalised depth goes too */
        fx_mem_free(e->sm.depth);
        e->sm.depth = NULL;
        e->bytes = (uint64_t)e->sm.mwidth * e->sm.mheight * 2 * sizeof(float) + sizeof *av;
        return FX_OK;
    }
    e->bytes = (uint64_t)av->width * av->height * 3 * sizeof(float) + sizeof *av;
    return FX_OK;
}

static fx_result acquire(const fx_frame *f, const char *name, int derivative_bias, int filter, float width,
                         int factor, const char *where, fx_aux_map *out)
{
    memset(out, 0, sizeof *out);
    fx_context *ctx = f->ctx;
    char path[1024];
    fx_result r = FX_OK;
    char *entry = fx_aux_view_entry(f, name, where, path, sizeof path, &r);
    if (!entry)
        return r;
    fx_os_stat st;
    char *key = NULL;
    struct fx_aux_cache *c = cache_of(ctx);
    if (c && cache_limit(ctx) > 0 && fx_os_stat_path(path, &st) == 0) {
        char tail[160];
        if (filter != AUX_RAW_VIEW && filter > AUX_MOMENTS(0) && !(filter >= 0 && width > 1.0f)) {
            filter = -1;
            width = 0.0f;
        }
        /* device + inode too: writers replace the file (temp + rename), which gives it a new
         * inode even when size and the coarse mtime clock are the same */
        int n = snprintf(tail, sizeof tail, "|%llu:%llu|%lld|%lld.%09ld|%d|%d|%.9g|%d", (unsigned long long)st.dev,
                         (unsigned long long)st.ino, (long long)st.size, (long long)st.mtime_sec,
                         st.mtime_nsec, derivative_bias ? 1 : 0, filter, (double)width, factor);
        size_t len = strlen(entry);
        key = fx_mem_alloc(len + (size_t)n + 1);
        if (key) {
            memcpy(key, entry, len);
            memcpy(key + len, tail, (size_t)n + 1);
        }
    }
    cJSON_free(entry);
    if (key) {
        for (int i = 0; i < c->n; i++)
            if (strcmp(c->e[i].key, key) == 0) {
                c->e[i].refs++;
                c->e[i].last_use = ++c->clock;
                c->reused++;
                out->av = c->e[i].av;
                out->sm = &c->e[i].sm;
                out->cached = 1;
                out->ctx = ctx;
                fx_mem_free(key);
                return FX_OK;
            }
    }
    aux_entry tmp;
    memset(&tmp, 0, sizeof tmp);
    /* without a key (no caching) the entry is private: the copy out of the frame is skipped */
    r = entry_build(f, name, derivative_bias, filter, width, factor, where, !key, &tmp);
    if (r) {
        entry_free(ctx, &tmp);
        fx_mem_free(key);
        return r;
    }
    if (c)
        c->built++;
    if (key && cache_make_room(ctx, tmp.bytes)) {
        aux_entry *e = &c->e[c->n++];
        *e = tmp;
        e->key = key;
        e->refs = 1;
        e->last_use = ++c->clock;
        out->av = e->av;
        out->sm = &e->sm;
        out->cached = 1;
        out->ctx = ctx;
        return FX_OK;
    }
    fx_mem_free(key);
    /* private: owned by the caller until release */
    aux_entry *e = fx_mem_alloc(sizeof *e);
    if (!e) {
        entry_free(ctx, &tmp);
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where);
    }
    *e = tmp;
    out->av = e->av;
    out->sm = &e->sm;
    out->cached = 0;
    out->ctx = ctx;
    return FX_OK;
}

fx_result fx_aux_map_acquire(const fx_frame *f, const char *name, int derivative_bias, int filter, float width,
                             const char *where, fx_aux_map *out)
{
    return acquire(f, name, derivative_bias, filter < 0 ? -1 : filter, width, 1, where, out);
}

fx_result fx_aux_map_acquire_reduced(const fx_frame *f, const char *name, int factor, const char *where,
                                     fx_aux_map *out)
{
    return acquire(f, name, 0, -1, 0.0f, factor > 1 ? factor : 1, where, out);
}

fx_result fx_aux_view_acquire(const fx_frame *f, const char *name, const char *where, fx_aux_map *out)
{
    return acquire(f, name, 0, AUX_RAW_VIEW, 0.0f, 1, where, out);
}

void fx_aux_map_release(fx_aux_map *m)
{
    if (!m || !m->sm)
        return;
    fx_context *ctx = m->ctx;
    if (m->cached) {
        struct fx_aux_cache *c = ctx ? ctx->aux_cache : NULL;
        /* by the view's address: an entry's own moves when an eviction compacts the table */
        for (int i = 0; c && i < c->n; i++)
            if (c->e[i].av == m->av && c->e[i].refs > 0)
                c->e[i].refs--;
    } else {
        /* the private entry: sm is its first field after key and av */
        aux_entry *e = (aux_entry *)((char *)m->sm - offsetof(aux_entry, sm));
        entry_free(ctx, e);
        fx_mem_free(e);
    }
    memset(m, 0, sizeof *m);
}
