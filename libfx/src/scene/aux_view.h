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
 * first light view there is), "rain_map" (top-down orthographic over the rain area) and
 * "probe:<key>" (a reflection probe for the mirror of the stack entry whose mask hashes
 * to <key>: the stack's fx_effect_run.mask_key).
 *
 * Probes are entries with "panorama": "equirect": an equirectangular panorama (colour in
 * its Combined pass, radial distance in its Depth pass, math/panorama.h) rendered from
 * the camera position of "world_to_camera" (its "projection" is unused: identity).
 * "planar:<key>" is the scene seen by the camera mirrored in a planar mirror's plane
 * (a perspective view with colour and Depth), with "plane": [nx, ny, nz, d], the world
 * plane n . x = d of the mirror (n towards the main camera). A mirror whose faces lie in
 * several planes (a facing pair in one entry) has one such view per plane:
 * "planar:<key>", then "planar:<key>#2", "planar:<key>#3", ...
 *
 * An entry {"name", "absent": reason} says the view was asked for and not rendered on
 * purpose (the add-on's planar view of a curved mirror): effects that read it only where
 * it helps pass over it without a warning. */
#ifndef LIBFX_SCENE_AUX_VIEW_H
#define LIBFX_SCENE_AUX_VIEW_H

#include "core/frame.h"
#include "math/camera.h"
#include "math/vec.h"

#include <stddef.h>

#define FX_AUX_META_KEY "libfx/aux_views"
#define FX_AUX_RAIN_MAP "rain_map"
#define FX_AUX_PROBE "probe:"
#define FX_AUX_PLANAR "planar:"

typedef struct fx_aux_view {
    char name[FX_NAME_MAX];
    char path[1024];
    fx_frame *frame;   /* the EXR as read (owned) */
    const float *depth;/* its Depth pass: planar depth along the view's -Z, rows top down */
    int width, height;
    fx_view view;      /* the view's camera (from the sidecar, not the EXR) */
    int panorama;      /* 1: an equirectangular probe (depth is then radial) */
    const float *color;/* its Combined pass (RGBA, non-finite values replaced by 0), or NULL */
    const float *sky;  /* a probe's Sky pass (the world alone, RGBA, finite), or NULL */
    int has_plane;     /* "plane" given (planar mirror views) */
    float plane[4];    /* world plane n . x = d: nx, ny, nz (unit), d */
} fx_aux_view;

/* Loads the aux view `name` of frame f (see above for "light:"). `where` names the
 * caller in messages. Fails with FX_ERR_NO_AUX_VIEW when the frame has no such view (the
 * message lists those it has and says where they come from), FX_ERR_MISSING_PASS when
 * the EXR has no Depth pass, and the reader's errors. */
fx_result fx_aux_view_load(const fx_frame *f, const char *name, const char *where, fx_aux_view **out);
void fx_aux_view_free(fx_aux_view *v);
/* The same for a map built row by row (scene/aux_map.h): when the view's EXR streams its
 * Depth pass (io/exr_rows.h), *rows is that stream and the view's frame has its windows and
 * camera but no pass (depth NULL); otherwise *rows is NULL and the view is loaded whole. */
struct fx_exr_rows;
fx_result fx_aux_view_open_rows(const fx_frame *f, const char *name, const char *where, fx_aux_view **out,
                                struct fx_exr_rows **rows);
/* Whether frame f lists a view named exactly `name`: FX_AUX_LISTED (with its file),
 * FX_AUX_ABSENT ({"name", "absent": reason}: the add-on was asked for it and did not render
 * it on purpose, a planar view of a mirror that is not flat; loading it fails with that
 * reason), 0 not at all, -1 out of memory. */
enum { FX_AUX_LISTED = 1, FX_AUX_ABSENT = 2 };
int fx_aux_view_has(const fx_frame *f, const char *name);
/* The frame's entry for view `name` (matched as fx_aux_view_load does) as unformatted JSON,
 * and its path; NULL with the error recorded in *res when there is none. Freed with
 * cJSON_free. */
char *fx_aux_view_entry(const fx_frame *f, const char *name, const char *where, char *path, size_t path_size,
                        fx_result *res);

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

/* Checks a sidecar's "aux_views" value and stores it as the frame's metadata (the sidecar
 * calls these; fx_frame_set_aux_view applies a list of one view). */
struct cJSON;
fx_result fx_aux_views_check(fx_context *ctx, const struct cJSON *list);
fx_result fx_aux_views_apply(fx_frame *f, const struct cJSON *list);

#endif
