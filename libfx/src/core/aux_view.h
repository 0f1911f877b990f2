/* Auxiliary views: extra depth renders of the scene from another viewpoint (the
 * light view for shadow maps, the top-down rain map), delivered with their matrices.
 *
 * They reach a frame as metadata "libfx/aux_views" (a JSON list of {"name", "path",
 * "world_to_camera", "projection", "clip_start", "clip_end", "orthographic"}), set by
 * the scene sidecar's "aux_views" key or fx_frame_set_aux_view(); the key has no
 * "libfx:" prefix on purpose, so it is written to and read from EXR headers and a
 * processed file can be processed again. An effect loads a view when it runs
 * (fx_aux_view_load: the EXR's Depth pass) and reprojects the main camera's world
 * positions into it (fx_aux_view_project).
 *
 * Names: "light:<light name>" (the shadow view of a light; "light:" alone asks for the
 * first light view there is) and "rain_map" (top-down orthographic over the rain area). */
#ifndef LIBFX_AUX_VIEW_H
#define LIBFX_AUX_VIEW_H

#include "core/internal.h"
#include "math/camera.h"
#include "math/shadow_map.h"
#include "math/vec.h"

#define FX_AUX_META_KEY "libfx/aux_views"
#define FX_AUX_RAIN_MAP "rain_map"

/* The aux_views callback of every effect that reads the rain map. */
struct fx_aux_need;
int fx_aux_needs_rain_map(const void *params, struct fx_aux_need *out, int max);

typedef struct fx_aux_view {
    char name[FX_NAME_MAX];
    char path[1024];
    fx_frame *frame;   /* the EXR as read (owned) */
    const float *depth;/* its Depth pass: planar depth along the view's -Z, rows top down */
    int width, height;
    fx_view view;      /* the view's camera (from the sidecar, not the EXR) */
} fx_aux_view;

/* Loads the aux view `name` of frame f (see above for "light:"). `where` names the
 * caller in messages. Fails with FX_ERR_NO_CAMERA when the frame has no such view (the
 * message lists those it has and says where they come from), FX_ERR_MISSING_PASS when
 * the EXR has no Depth pass, and the reader's errors. */
fx_result fx_aux_view_load(const fx_frame *f, const char *name, const char *where, fx_aux_view **out);
void fx_aux_view_free(fx_aux_view *v);

/* World point -> continuous view pixel coordinates (pixel x's centre at x + 0.5) and the
 * point's planar depth in the view. Returns 0 when the point is behind a perspective
 * view (then px, py are meaningless). */
static inline int fx_aux_view_project(const fx_aux_view *v, fx_vec3 p, float *px, float *py, float *depth)
{
    fx_vec3 q = fx_world_to_view(&v->view, p);
    *depth = -q.z;
    fx_vec2 pix = {0.0f, 0.0f};
    float w = fx_view_project(&v->view, q, &pix);
    *px = pix.x;
    *py = pix.y;
    return w > 1e-30f;
}

/* Checks a sidecar's "aux_views" value and stores it as the frame's metadata
 * (core/camera.c calls this; also what fx_frame_set_aux_view does for one view). */
struct cJSON;
fx_result fx_aux_views_check(fx_context *ctx, const struct cJSON *list);
fx_result fx_aux_views_apply(fx_frame *f, const struct cJSON *list);

/* ---- the per-context cache of built maps ----
 * A light view (or the rain map) used as a shadow map costs an EXR read plus the normalised
 * depth, the moments and their filter (an SAT or a blur) every time an effect runs; in a
 * batch the views do not change between frames. fx_aux_map_acquire returns that map built
 * once per context and reused while the view's key is the same: its sidecar entry (name,
 * path, matrices, clip range, signature), the file's size and modification time (ns), and
 * the build parameters (derivative bias, filter, width). Entries are LRU, bounded by
 * fx_context_set_aux_cache (bytes; 0: no caching, each acquire builds a private map) and
 * freed with the context. The cache is touched only by the thread calling into the library
 * with the context (never by its workers), which the context's one-thread-at-a-time rule
 * makes safe; an entry in use (acquired and not released) is never evicted. */
typedef struct fx_aux_map {
    const fx_aux_view *av;   /* its camera and name; av->depth is NULL (the raw depth is dropped) */
    const fx_shadow_map *sm; /* normalised depth; moments only when a filter asked for them */
    int cached;              /* 1: came from (or went into) the cache; 0: private */
} fx_aux_map;

/* filter < 0 or width <= 1: no moments are made (PCF and the hard test read only the
 * depth; VSM asks for a width above 1). */
fx_result fx_aux_map_acquire(const fx_frame *f, const char *name, int derivative_bias, int filter, float width,
                             const char *where, fx_aux_map *out);
void fx_aux_map_release(fx_context *ctx, fx_aux_map *m);
/* Frees every entry (fx_context_free calls this). */
void fx_aux_cache_free(fx_context *ctx);
/* Counters since the context was made: maps built and maps reused (tests, benches). */
void fx_aux_cache_stats(const fx_context *ctx, long *built, long *reused);

#endif
