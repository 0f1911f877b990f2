/* Screen-space ray tracing against a depth buffer (McGuire & Mara 2014, "Efficient GPU
 * Screen-Space Ray Tracing", JCGT 3(4)): the ray is clipped to the near plane and to
 * the screen, projected, and marched along its 2-D line in pixels while the view-space
 * depth is interpolated perspective-correctly (z/w and 1/w are linear in screen space).
 * Steps start at `stride` pixels and grow by `growth` per step (the seed's distance-
 * growing steps); a step whose depth interval meets the surface interval
 * [depth, depth + thickness] is refined by bisection (`refine` halvings).
 *
 * Robustness: every loop is bounded (max_steps, refine); rays towards the
 * camera end at the near plane; a 2-D line shorter than 0.01 px is nudged (so rays
 * along the view direction march in depth and still terminate); non-finite input is
 * a miss; background depth (Cycles 1e10/1e11, Eevee 65504, <= 0, NaN) is "infinitely
 * far", never a hit. A hit reports its evidence (fx_ssr_hit.behind): whether the ray
 * crossed the surface from its front or came at it from behind a depth discontinuity. Depth is planar (distance along -Z), as Blender writes it. */
#ifndef LIBFX_MATH_SSR_TRACE_H
#define LIBFX_MATH_SSR_TRACE_H

#include "math/camera.h"
#include "math/depth_pyramid.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Depth at or beyond this is background (Eevee writes 65504, Cycles 1e10 / 1e11). */
#define FX_SSR_BACKGROUND_DEPTH 6.0e4f

typedef struct fx_ssr_scene {
    const fx_view *view;
    const float *depth;    /* planar depth, width * height */
    int width, height;
    /* Optional: a candidate hit on pixel (x, y) for the unit view-space ray direction
     * `dir` is kept only if this returns non-zero; otherwise the march goes on past it
     * (e.g. surfaces seen from behind: a ray leaving a mirror seen at a grazing angle
     * otherwise "hits" the far half of its own start pixel). NULL: every hit counts. */
    int (*accept)(const void *user, int x, int y, fx_vec3 dir);
    /* Optional: the tangent plane of pixel (x, y)'s surface in view space, n . p = c as
     * plane = {n.x, n.y, n.z, c}; returns 0 if it has none (then its depth sample is used).
     * The refinement and the final thickness test take the plane's depth under the ray
     * (within [0.5, 2] x the sample) instead of the pixel's one depth sample: a surface
     * seen at a grazing angle spans decimetres of depth per pixel, more than any useful
     * thickness. NULL: the samples. */
    int (*surface_plane)(const void *user, int x, int y, double plane[4]);
    const void *user;
    /* Optional: the min-depth pyramid of `depth` (math/depth_pyramid.h). Given, the
     * tracer walks it (Hi-Z): it steps over cells the ray crosses in front of every
     * surface and tests every pixel it does not skip exactly (as stride 1); stride and
     * growth are unused and max_steps caps the walk's steps (level changes included).
     * NULL: the linear march with growing strides. */
    const fx_depth_pyramid *hiz;
} fx_ssr_scene;

typedef struct fx_ssr_settings {
    int max_steps;      /* >= 1 */
    float stride;       /* first step, pixels (>= 0.5) */
    float growth;       /* stride multiplier per step (>= 1) */
    int refine;         /* bisection iterations after a hit (>= 0) */
    float thickness;    /* metres: how far behind its visible front a surface is assumed solid */
    float max_distance; /* metres along the ray */
} fx_ssr_settings;

typedef struct fx_ssr_hit {
    int hit;            /* 1: the ray met a surface; 0: miss */
    float px, py;       /* continuous frame pixel coordinates of the hit (pixel centre = +0.5) */
    int ix, iy;         /* the hit pixel */
    float length;       /* view-space distance from the origin to the hit (metres) */
    int steps;          /* march steps taken (not counting refinement) */
    int left_screen;    /* the ray's 2-D line was clipped by the screen border (miss cause) */
    /* The hit's evidence (for the caller's confidence, e.g. ssr_mirror's): how far (metres,
     * planar depth) the ray already lay behind the hit pixel's surface (its tangent plane,
     * or its depth sample) at the last point of the march it was still in front of the
     * depth buffer. A ray that meets a surface crosses it from the front: ~0. A ray that
     * passes behind a foreground object and "meets" its silhouette from behind (a depth
     * discontinuity: it was in front of the background pixel beside the silhouette, and is
     * behind the object's front) lies behind the object already there: > 0, up to the
     * thickness. Such a hit is the ray passing behind (or through) the object, never the
     * object's visible front: the smears of a screen-space tracer. */
    float behind;
    float slack;        /* metres of depth the ray itself moved between that point and the
                           hit (a genuine crossing's `behind` stays below it) */
    float hit_depth;    /* planar depth of the hit pixel's surface at the hit (metres) */
} fx_ssr_hit;

static inline int fx_ssr_is_background(float d)
{
    return !(d > 0.0f) || !(d < FX_SSR_BACKGROUND_DEPTH);
}

/* Planar depth of a pixel, +inf for background. */
static inline float fx_ssr_depth_at(const fx_ssr_scene *s, int x, int y)
{
    float d = s->depth[(size_t)y * s->width + x];
    return fx_ssr_is_background(d) ? INFINITY : d;
}

/* View-space size of one pixel at planar depth d (for offsets measured in pixels). */
float fx_ssr_pixel_footprint(const fx_view *v, float depth);

/* Traces the view-space ray origin + t dir (dir need not be unit). Returns out->hit. */
int fx_ssr_trace(const fx_ssr_scene *s, const fx_ssr_settings *st, fx_vec3 origin, fx_vec3 dir,
                 fx_ssr_hit *out);

#ifdef __cplusplus
}
#endif
#endif
