/* The per-context cache of shadow maps built from aux views.
 *
 * A light view (or the rain map) used as a shadow map costs an EXR read plus the normalised
 * depth, the moments and their filter (an SAT or a blur) every time an effect runs; in a
 * batch the views do not change between frames. fx_aux_map_acquire returns that map built
 * once per context and reused while the view's key is the same: its sidecar entry (name,
 * path, matrices, clip range, signature), the file's size and modification time (ns), and
 * the build parameters (derivative bias, filter, width). A filtered map made from moments
 * (reduced levels, the Gaussian) is a filtered copy of the view's unfiltered moments, an
 * entry of its own: a new width filters again without reading the view (a slider in the
 * live loop). Entries are LRU, bounded by
 * fx_context_set_aux_cache (bytes; 0: no caching, each acquire builds a private map) and
 * freed with the context. The cache is touched only by the thread calling into the library
 * with the context (never by its workers), which the context's one-thread-at-a-time rule
 * makes safe; an entry in use (acquired and not released) is never evicted. */
#ifndef LIBFX_SCENE_AUX_MAP_H
#define LIBFX_SCENE_AUX_MAP_H

#include "math/shadow_map.h"
#include "scene/aux_view.h"

typedef struct fx_aux_map {
    const fx_aux_view *av;   /* its camera and name; av->depth is NULL (the raw depth is dropped)
                              * except from fx_aux_view_acquire */
    const fx_shadow_map *sm; /* normalised depth; moments only when a filter asked for them;
                              * a map filtered from moments has moments only (depth NULL) */
    int cached;              /* 1: came from (or went into) the cache; 0: private */
    fx_context *ctx;         /* the frame's context, whose cache holds it: release goes there
                              * whichever context runs the stack */
} fx_aux_map;

/* filter < 0 or width <= 1: no moments are made (PCF and the hard test read only the
 * depth; VSM asks for a width above 1). */
fx_result fx_aux_map_acquire(const fx_frame *f, const char *name, int derivative_bias, int filter, float width,
                             const char *where, fx_aux_map *out);
/* The view's normalised depth reduced by `factor` per axis (math/shadow_map.h: every
 * factor-th texel each way, depth_min the kept rows' least; no moments), for a reader that
 * needs less than the view's resolution (god_rays' volumetric march at draft). Only the kept
 * rows are read, without ever holding the full map, when the view's EXR allows it
 * (io/exr_rows.h: what the add-on writes), else read whole and reduced: the same bits.
 * out->av's view and size are the reduced map's (fx_view_reduce_sampled: its pixel
 * coordinates address the kept texels). An entry of its own, keyed by the factor: a stack whose vsm_shadows reads the
 * full view gets both maps. factor <= 1: fx_aux_map_acquire's. */
fx_result fx_aux_map_acquire_reduced(const fx_frame *f, const char *name, int factor, const char *where,
                                     fx_aux_map *out);
/* The view itself, as read (colour, depth, camera; no shadow map): reflection probes and
 * planar views, which are looked up as images. Cached and keyed as the maps are, so a
 * batch or a live session decodes each probe once. out->av stays valid until release;
 * out->sm is only the handle release needs. */
fx_result fx_aux_view_acquire(const fx_frame *f, const char *name, const char *where, fx_aux_map *out);
/* Gives the map back to the cache of the context it was acquired from (m->ctx). */
void fx_aux_map_release(fx_aux_map *m);
/* Counters since the context was made: maps built and maps reused (tests, benches). */
void fx_aux_cache_stats(const fx_context *ctx, long *built, long *reused);

#endif
