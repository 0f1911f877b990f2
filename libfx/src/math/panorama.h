/* Equirectangular panoramas with depth: the reflection probe aux view (scene/aux_view.h)
 * and the parallax-corrected lookup into it.
 *
 * Conventions (Cycles' equirectangular panoramic camera, full 360 x 180 degrees, as the
 * add-on renders it; tests/blender/test_probe_view.py checks them on a real render):
 * directions are in the probe camera's space, Blender's camera axes (-Z forward, +Y up,
 * +X right). The image's centre column looks forward (-Z), x grows to the right (a quarter
 * of the width right of the centre is +X), row 0 is straight up (+Y) and the last row
 * straight down; rows are stored top down as libfx stores every image:
 *   u = 0.5 - atan2(-d.x, -d.z) / (2 pi)      (x = u W)
 *   v = acos(d.y / |d|) / pi                  (y = v H)
 * The Depth pass of a panoramic Cycles camera is the radial distance from the camera's
 * centre (not a planar depth). Background (the sky: 1e10), zero, negative or non-finite
 * depth is "no surface there". */
#ifndef LIBFX_MATH_PANORAMA_H
#define LIBFX_MATH_PANORAMA_H

#include "math/trig.h"
#include "math/vec.h"

#include <math.h>

#ifdef __cplusplus
extern "C" {
#endif

#define FX_PANO_PI 3.14159265358979323846f

/* Probe-space direction (any non-zero length) -> continuous pixel coordinates (pixel
 * x's centre at x + 0.5): x in [0, w], y in [0, h]. A zero or non-finite direction
 * maps to the image's centre. */
static inline void fx_pano_dir_to_pixel(fx_vec3 d, int w, int h, float *px, float *py)
{
    float len = sqrtf(fx_v3_dot(d, d));
    if (!(len > 1e-30f) || !isfinite(len)) {
        *px = 0.5f * (float)w;
        *py = 0.5f * (float)h;
        return;
    }
    /* a finite length: every component is finite, so fx_atan2f and fx_acosf (the same bits
     * on every libc) without their NaN and infinity tests; cy is clamped already */
    float u = 0.5f - fx_atan2f_finite(-d.x, -d.z) / (2.0f * FX_PANO_PI);
    float cy = fx_clampf(d.y / len, -1.0f, 1.0f);
    float v = fx_atan2f_finite(sqrtf((1.0f - cy) * (1.0f + cy)), cy) / FX_PANO_PI;
    *px = fx_clampf(u, 0.0f, 1.0f) * (float)w;
    *py = fx_clampf(v, 0.0f, 1.0f) * (float)h;
}

/* Continuous pixel coordinates -> unit probe-space direction (the inverse). */
static inline fx_vec3 fx_pano_pixel_to_dir(float px, float py, int w, int h)
{
    float phi = (0.5f - px / (float)w) * 2.0f * FX_PANO_PI;
    float theta = fx_clampf(py / (float)h, 0.0f, 1.0f) * FX_PANO_PI;
    float s = sinf(theta);
    return fx_v3(-s * sinf(phi), cosf(theta), -s * cosf(phi));
}

/* A loaded probe: colour and radial depth, rows top down, and where it sits. */
typedef struct fx_pano {
    const float *color; /* RGBA, w * h * 4, finite (sanitised at load) */
    const float *depth; /* radial distance, w * h; <= 0 or huge: no surface */
    int w, h;
    /* from the caller's space (e.g. the main camera's view space) to the probe's camera
     * space: a rigid transform (row-major, as math/vec.h) */
    float to_probe[16];
    /* the world alone (the sky, no objects) in the same directions, RGBA, finite; or NULL.
     * A ray hidden from the probe behind a wall it passed over meets the sky, which the
     * probe cannot show there (the wall hides the sky's lower part from the probe) */
    const float *sky;
} fx_pano;

/* Radial depth of the texel a direction falls in (nearest: depth is never blended
 * across an edge); +inf where there is no surface. */
static inline float fx_pano_depth(const fx_pano *p, fx_vec3 d)
{
    float px, py;
    fx_pano_dir_to_pixel(d, p->w, p->h, &px, &py);
    int x = (int)px, y = (int)py;
    x = x < 0 ? 0 : x >= p->w ? p->w - 1 : x;
    y = y < 0 ? 0 : y >= p->h ? p->h - 1 : y;
    float v = p->depth[(size_t)y * p->w + x];
    return v > 0.0f && v < 6.0e4f ? v : INFINITY;
}

/* Colour along probe-space direction d: bilinear, wrapping around horizontally and
 * clamped at the poles. */
void fx_pano_color(const fx_pano *p, fx_vec3 d, float rgb[3]);

typedef struct fx_pano_trace_settings {
    int steps;          /* march steps (>= 1), geometric from min_distance to max_distance */
    int refine;         /* bisection iterations after a crossing */
    float min_distance; /* metres: the first step (> 0) */
    float max_distance; /* metres along the ray */
    float thickness;    /* metres: a crossing further behind the probe's surface than this
                           (plus the step) passes behind an occluder, not a hit */
    /* derived by fx_pano_trace_setup, once per run: the clamped range and the step ratio */
    float t0, tmax, growth;
} fx_pano_trace_settings;

/* The settings with their derived fields (one powf per run, not one per ray). */
fx_pano_trace_settings fx_pano_trace_setup(int steps, int refine, float min_distance, float max_distance,
                                           float thickness);

/* Parallax-corrected reflection: marches the ray o + t dir (the caller's space, dir unit)
 * and returns the probe's colour where the ray meets the probe's depth surface (the
 * first crossing from in front of it to behind it, refined by bisection); where it meets
 * none within max_distance, the colour along dir as seen from the probe (infinitely far:
 * the sky, or a room too big for the march); where it passes behind an occluder the probe
 * sees and never comes out (its hit is hidden from the probe: a disocclusion), a wide,
 * depth-tested mean of the probe's background around the hidden point (never one texel
 * drawn out along the rays). Returns 1 for a hit, 0 for the far lookup or the fill.
 * Finite for any input (a non-finite ray gives the colour of the probe's forward view). */
int fx_pano_trace(const fx_pano *p, const fx_pano_trace_settings *st, fx_vec3 o, fx_vec3 dir, float rgb[3]);

/* A pixel's ray differentials (Igehy, "Tracing Ray Differentials", 1999), the caller's
 * space: the neighbouring pixels' reflected rays differ from this one by do_ in origin
 * and dd_ in direction, so the pixel's footprint at distance t along the ray spans
 * do_x + t dd_x by do_y + t dd_y. All zero: a point (no footprint). */
typedef struct fx_ray_diff {
    fx_vec3 dox, ddx, doy, ddy;
} fx_ray_diff;

/* Most taps along one axis of a footprint (fx_pano_trace_footprint, ssr_mirror's lookup). */
#define FX_FOOTPRINT_TAPS_MAX 8

/* Taps along an axis spanning `texels` texels (or pixels): one per texel, at least one, at
 * most FX_FOOTPRINT_TAPS_MAX; 1 for a non-finite span. */
static inline int fx_footprint_taps(float texels)
{
    if (!(texels > 1.0f))
        return 1;
    if (!(texels < (float)FX_FOOTPRINT_TAPS_MAX))
        return FX_FOOTPRINT_TAPS_MAX;
    return (int)ceilf(texels);
}

/* fx_pano_trace over a pixel's footprint: where the ray meets the probe's surface (or
 * meets none: the far lookup), the mean of a grid of bilinear taps spread over the
 * footprint there, one tap per texel it spans along each axis (at most
 * FX_FOOTPRINT_TAPS_MAX each): a convex mirror shrinks the room into few pixels, and one
 * tap per pixel would alias it and keep the probe's full noise, where the pixel sees the
 * mean. A footprint within one texel takes the one tap of fx_pano_trace (the same bits);
 * the hidden fill is wide already and stays. */
int fx_pano_trace_footprint(const fx_pano *p, const fx_pano_trace_settings *st, fx_vec3 o, fx_vec3 dir,
                            const fx_ray_diff *diff, float rgb[3]);

/* The distance along the ray (dir unit, the caller's units) at which fx_pano_trace meets
 * the probe's depth surface; +inf where it meets none (or the ray is not finite). The
 * probe's evidence of where the ray ends, for a screen-space hit to agree with. */
float fx_pano_trace_dist(const fx_pano *p, const fx_pano_trace_settings *st, fx_vec3 o, fx_vec3 dir);

#ifdef __cplusplus
}
#endif
#endif
