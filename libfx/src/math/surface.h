/* The surface a frame pixel sees, in world space: from the Position pass when the frame
 * has it, else from planar Depth and the camera (math/camera.h); the normal from the
 * Normal pass when present. Background (depth beyond 1.01 x clip_end, Cycles' 1e10,
 * Eevee's 65504, non-finite or <= 0) has no surface. Shared by the shadow and rain
 * effects. */
#ifndef LIBFX_MATH_SURFACE_H
#define LIBFX_MATH_SURFACE_H

#include "core/context.h"
#include "core/frame.h"
#include "math/camera.h"

typedef struct fx_surface_src {
    fx_view view;
    const float *depth;    /* required */
    const float *position; /* optional (3 channels) */
    const float *normal;   /* optional (3 channels) */
    int width, height;
    float far_limit;
} fx_surface_src;

/* 0 when the frame lacks a camera or a Depth pass. */
static inline int fx_surface_src_init(fx_surface_src *s, const fx_frame *f)
{
    if (!fx_view_init(&s->view, f))
        return 0;
    fx_pass *d = fx_frame_find_pass(f, "Depth");
    fx_pass *p = fx_frame_find_pass(f, "Position");
    fx_pass *n = fx_frame_find_pass(f, "Normal");
    if (!d)
        return 0;
    s->depth = d->data;
    s->position = p && p->channels >= 3 ? p->data : NULL;
    s->normal = n && n->channels >= 3 ? n->data : NULL;
    s->width = f->width;
    s->height = f->height;
    s->far_limit = s->view.cam.clip_end > 0 ? 1.01f * s->view.cam.clip_end : 1e9f;
    return 1;
}

/* World position (and planar depth) of pixel (x, y); 0 for background. */
static inline int fx_surface_world(const fx_surface_src *s, int x, int y, fx_vec3 *world, float *depth)
{
    size_t i = (size_t)y * s->width + x;
    float d = s->depth[i];
    if (!(d > 0.0f) || !(d < s->far_limit))
        return 0;
    *depth = d;
    if (s->position) {
        const float *p = s->position + 3 * i;
        *world = fx_v3(p[0], p[1], p[2]);
        return 1;
    }
    fx_vec2 ndc = fx_view_pixel_to_ndc(&s->view, (float)x + 0.5f, (float)y + 0.5f);
    *world = fx_view_to_world(&s->view, fx_view_position(&s->view, ndc, d));
    return 1;
}

/* Unit world normal of pixel (x, y), or 0 when the frame has no Normal pass / none here. */
static inline int fx_surface_normal(const fx_surface_src *s, int x, int y, fx_vec3 *n)
{
    if (!s->normal)
        return 0;
    const float *p = s->normal + 3 * ((size_t)y * s->width + x);
    fx_vec3 v = fx_v3(p[0], p[1], p[2]);
    if (!(fx_v3_dot(v, v) > 1e-8f))
        return 0;
    *n = fx_v3_normalize_or(v, fx_v3(0, 0, 1));
    return 1;
}

#endif
