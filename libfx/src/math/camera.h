/* The frame's camera as effects use it: pixels <-> NDC <-> view <-> world.
 *
 * Conventions: frame pixel (x, y) has its centre at (x + 0.5, y + 0.5), rows top to
 * bottom, in the data window; NDC is [-1, 1] over the display window with y up, as
 * Blender's projection (calc_matrix_camera) maps it; view space is Blender's camera
 * space (looking down -Z). Depth is planar: the distance along -Z (Cycles writes
 * planar depth: a test checks it against the Position pass). */
#ifndef LIBFX_MATH_CAMERA_H
#define LIBFX_MATH_CAMERA_H

#include "core/context.h"
#include "core/frame.h"
#include "math/vec.h"

typedef struct fx_view {
    fx_camera cam;
    float camera_to_world[16]; /* inverse of world_to_camera */
    float clip_to_view[16];    /* inverse of projection */
    float world_to_clip[16];   /* projection * world_to_camera */
    float disp_w, disp_h;      /* display window size in pixels */
    float off_x, off_y;        /* data window origin minus display window origin */
    int orthographic;
} fx_view;

/* Fills v from the frame's camera and windows; returns 0 without a camera or if a
 * matrix is singular (the caller reports FX_ERR_NO_CAMERA / a bad camera). */
static inline int fx_view_init(fx_view *v, const fx_frame *f)
{
    if (!f->has_camera)
        return 0;
    v->cam = f->camera;
    if (!fx_m4_inverse(v->cam.world_to_camera, v->camera_to_world) ||
        !fx_m4_inverse(v->cam.projection, v->clip_to_view))
        return 0;
    fx_m4_mul(v->cam.projection, v->cam.world_to_camera, v->world_to_clip);
    v->disp_w = (float)(f->display_window[2] - f->display_window[0] + 1);
    v->disp_h = (float)(f->display_window[3] - f->display_window[1] + 1);
    v->off_x = (float)(f->data_window[0] - f->display_window[0]);
    v->off_y = (float)(f->data_window[1] - f->display_window[1]);
    if (f->proxy_factor > 1) {
        /* a proxy: its pixel x spans the full frame's [x f, x f + f), whatever the rounding
         * of its windows */
        const int *dw = f->full_data_window, *dp = f->full_display_window;
        const float k = (float)f->proxy_factor;
        v->disp_w = (float)(dp[2] - dp[0] + 1) / k;
        v->disp_h = (float)(dp[3] - dp[1] + 1) / k;
        v->off_x = (float)(dw[0] - dp[0]) / k;
        v->off_y = (float)(dw[1] - dp[1]) / k;
    }
    v->orthographic = v->cam.orthographic;
    return v->disp_w > 0 && v->disp_h > 0;
}

/* The view of a map that keeps every factor-th pixel of this one, pixel X being the view's
 * pixel f X + s (s = (f - 1) / 2, integer: the one nearest the block's centre): pixel
 * coordinates then put kept pixel X's centre at X + 0.5. Without the offset a point would
 * land half a pixel of the view away from the pixel it samples for even f (a shift of the
 * shadows: MAE 1.23e-2 instead of 1.11e-2 on the Greek bath at f = 2). */
static inline void fx_view_reduce_sampled(fx_view *v, int factor)
{
    if (factor <= 1)
        return;
    const float k = (float)factor, s = (float)((factor - 1) / 2);
    v->disp_w /= k;
    v->disp_h /= k;
    v->off_x = (v->off_x + s + 0.5f) / k - 0.5f;
    v->off_y = (v->off_y + s + 0.5f) / k - 0.5f;
}

/* Continuous frame pixel coordinates (centre of pixel x is x + 0.5) -> NDC. */
static inline fx_vec2 fx_view_pixel_to_ndc(const fx_view *v, float px, float py)
{
    fx_vec2 r = {(px + v->off_x) / v->disp_w * 2.0f - 1.0f, 1.0f - (py + v->off_y) / v->disp_h * 2.0f};
    return r;
}

static inline fx_vec2 fx_view_ndc_to_pixel(const fx_view *v, fx_vec2 ndc)
{
    fx_vec2 r = {(ndc.x + 1.0f) * 0.5f * v->disp_w - v->off_x, (1.0f - ndc.y) * 0.5f * v->disp_h - v->off_y};
    return r;
}

/* View-space position of the surface seen at NDC (nx, ny) at planar depth d. */
static inline fx_vec3 fx_view_position(const fx_view *v, fx_vec2 ndc, float depth)
{
    if (v->orthographic) {
        fx_vec4 c = fx_m4_mul_v4(v->clip_to_view, (fx_vec4){ndc.x, ndc.y, 0.0f, 1.0f});
        float w = fabsf(c.w) > 1e-30f ? c.w : 1.0f;
        return fx_v3(c.x / w, c.y / w, -depth);
    }
    fx_vec4 c = fx_m4_mul_v4(v->clip_to_view, (fx_vec4){ndc.x, ndc.y, -1.0f, 1.0f});
    /* the near-plane point scaled so that z = -1, then to the depth */
    float z = fabsf(c.z) > 1e-30f ? -c.z : 1.0f;
    return fx_v3(c.x / z * depth, c.y / z * depth, -depth);
}

/* Unit view-space direction from the eye through NDC (nx, ny). */
static inline fx_vec3 fx_view_ray(const fx_view *v, fx_vec2 ndc)
{
    if (v->orthographic)
        return fx_v3(0.0f, 0.0f, -1.0f);
    return fx_v3_normalize_or(fx_view_position(v, ndc, 1.0f), fx_v3(0.0f, 0.0f, -1.0f));
}

/* Projects a view-space point to frame pixels; returns the clip w (<= 0: behind the
 * eye, the pixel is then meaningless). */
static inline float fx_view_project(const fx_view *v, fx_vec3 p, fx_vec2 *pixel)
{
    fx_vec4 c = fx_m4_mul_v4(v->cam.projection, (fx_vec4){p.x, p.y, p.z, 1.0f});
    if (c.w > 1e-30f) {
        fx_vec2 ndc = {c.x / c.w, c.y / c.w};
        *pixel = fx_view_ndc_to_pixel(v, ndc);
    }
    return c.w;
}

static inline fx_vec3 fx_view_to_world(const fx_view *v, fx_vec3 p) { return fx_m4_point(v->camera_to_world, p); }
static inline fx_vec3 fx_world_to_view(const fx_view *v, fx_vec3 p) { return fx_m4_point(v->cam.world_to_camera, p); }
static inline fx_vec3 fx_view_dir_to_world(const fx_view *v, fx_vec3 d) { return fx_m4_dir(v->camera_to_world, d); }
static inline fx_vec3 fx_world_dir_to_view(const fx_view *v, fx_vec3 d) { return fx_m4_dir(v->cam.world_to_camera, d); }

#endif
