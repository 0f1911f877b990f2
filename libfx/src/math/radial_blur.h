/* Radial blur towards a light (GPU Gems 3 ch. 13, "Volumetric Light Scattering as a
 * Post-Process"), in two methods that converge to the same integral.
 *
 * The continuous model: for an output pixel p and the light L (frame pixels),
 *
 *     rays(p) = scale * integral_0^1 occ(p - t * density * (p - L)) * decay^(100 t) dt
 *
 * where occ is the occlusion map (RGB, zero outside the image) and scale =
 * 100 * weight * exposure. `decay` is the per-sample decay at the seed's 100 samples:
 *  - naive (GPU Gems): N samples q_i = p - (i + j) * density * (p - L) / N, i = 0..N-1,
 *    j a per-pixel jitter in [0, 1) (0 without jitter), each weighted
 *    scale / N * decay^(100 i / N). At N = 100 this is exactly the book's loop (with the
 *    first sample weighted too, so weight 0 is the identity). Cost O(N) per pixel;
 *    samples outside the image are skipped by clipping the segment (a light far off
 *    screen costs no more than one inside it, and gives the same bounded sum).
 *  - polar (epipolar): the occlusion map is resampled along lines through L (one bin per
 *    pixel of radius, lines spaced `angular` px apart at the farthest pixel). Along a
 *    line the integral is a truncated exponential sum with rate a/(density r) (a = -100
 *    ln decay): computed for a bank of rates lambda_k = 2^(k / levels) by one recursion
 *    each (O(1) per bin), normalised by the kernel's exact discrete mass, and
 *    interpolated in log(rate) (cubic, clamped); decay 1 needs one rate (prefix sums).
 *    The result is resampled back to the pixels. Exact in the limit of fine lines and
 *    many levels; cost O(levels) per bin, independent of the sample count. No
 *    transcendental function per bin: the level of each radius and its weights come
 *    from tables built once per call; bins and sums are four-lane floats. Lines are
 *    spaced for the farthest pixel, so near the light they crowd: in octave bands of
 *    radius the back projection reads only every 2^k-th line, and a line evaluates its
 *    results only in the bands that read it (it still runs its sums from the light). With downsample f > 1 it runs on the
 *    occlusion map box-averaged f x f and the rays are interpolated back (the rays are
 *    smooth along the lines; shaft edges blur by about f pixels): ~f^2 less work.
 * Both are deterministic and bit-identical for any thread count. */
#ifndef LIBFX_MATH_RADIAL_BLUR_H
#define LIBFX_MATH_RADIAL_BLUR_H

#include "core/context.h"
#include "core/rect.h"

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* The book's reference sample count: decay is per sample at this count. */
#define FX_RAYS_REFERENCE_SAMPLES 100
/* The light is kept within this many pixels of the image centre (direction kept): a
 * light at infinity on screen, or with clip w -> 0, gives parallel, bounded rays. */
#define FX_RAYS_MAX_LIGHT_DISTANCE 1.0e6

typedef struct fx_radial_blur {
    double light_x, light_y; /* frame pixels, continuous (pixel x's centre is x + 0.5) */
    int samples;             /* naive: N >= 1 */
    double decay;            /* [0, 1], per sample at 100 samples */
    double density;          /* (0, 1]: fraction of the way to the light */
    double scale;            /* 100 * weight * exposure (>= 0) */
    int jitter;              /* naive: per-pixel jitter of the samples */
    uint32_t seed;           /* jitter hash seed (with the frame number) */
    int frame;
    double angular;          /* polar: line spacing in px at the farthest pixel (> 0) */
    int levels;              /* polar: rates per octave (>= 1) */
    int downsample;          /* polar: run on the occlusion map reduced f x f (box), rays
                                interpolated back bilinearly; <= 1: full resolution */
} fx_radial_blur;

/* Moves (lx, ly) towards the image centre so that it lies within
 * FX_RAYS_MAX_LIGHT_DISTANCE of it; non-finite positions become the centre. */
void fx_radial_blur_bound_light(double *lx, double *ly, int width, int height);

/* rays over roi (NULL: all) from occ, both width x height pixels of 4 floats (RGB and a
 * lane that occ holds at 0 and rays gets 0: four-lane vectors). Outside roi, rays is
 * untouched. Finite for finite occ. polar at full size (downsample <= 1) reads occ whole
 * before it writes rays, so rays may be occ itself; naive's may not. */
fx_result fx_radial_blur_naive(fx_context *ctx, const float *occ, float *rays, int width, int height,
                               const fx_radial_blur *rb, const fx_rect *roi, const char *where);
fx_result fx_radial_blur_polar(fx_context *ctx, const float *occ, float *rays, int width, int height,
                               const fx_radial_blur *rb, const fx_rect *roi, const char *where);

/* The reduced polar method in pieces, for callers that build the reduced map themselves
 * (no full-size occlusion or rays buffer): fx_radial_blur_polar with downsample f > 1 is
 * exactly reduce (f x f box means, summed in double in row order), then polar_reduced,
 * then fx_radial_blur_upsample per pixel.
 * fx_radial_blur_reduced_size: 1 and the reduced size if downsample applies (f > 1, the
 * frame at least 4 f each way, decay and density > 0), else 0. */
int fx_radial_blur_reduced_size(const fx_radial_blur *rb, int width, int height, int *lw, int *lh);
/* lo: lw x lh reduced map (4 floats a pixel); lrays: zeroed, same size, gets the reduced
 * rays around roi (NULL: all) of the width x height frame. */
fx_result fx_radial_blur_polar_reduced(fx_context *ctx, const float *lo, float *lrays, int width, int height,
                                       const fx_radial_blur *rb, const fx_rect *roi, const char *where);
/* The rays of pixel (x, y) (RGB and a 0 lane), bilinear from the reduced rays. */
static inline void fx_radial_blur_upsample(const float *lrays, int lw, int lh, int f, int x, int y, float out[4])
{
    const double inv_f = 1.0 / f;
    double v = (y + 0.5) * inv_f - 0.5;
    v = v < 0.0 ? 0.0 : v > lh - 1 ? lh - 1 : v;
    int Y0 = (int)v, Y1 = Y0 + 1 < lh ? Y0 + 1 : Y0;
    float ty = (float)(v - Y0);
    const float *r0 = lrays + (size_t)Y0 * lw * 4, *r1 = lrays + (size_t)Y1 * lw * 4;
    double u = (x + 0.5) * inv_f - 0.5;
    u = u < 0.0 ? 0.0 : u > lw - 1 ? lw - 1 : u;
    int X0 = (int)u, X1 = X0 + 1 < lw ? X0 + 1 : X0;
    float tx = (float)(u - X0);
    for (int ch = 0; ch < 3; ch++) {
        float a = r0[4 * X0 + ch] + tx * (r0[4 * X1 + ch] - r0[4 * X0 + ch]);
        float b = r1[4 * X0 + ch] + tx * (r1[4 * X1 + ch] - r1[4 * X0 + ch]);
        out[ch] = a + ty * (b - a);
    }
    out[3] = 0.0f;
}

/* One cell of the reduced occlusion map: the mean of `count` RGB sums, alpha 0. */
static inline void fx_radial_store_cell(float *o, const double acc[3], double count)
{
    double inv = 1.0 / count;
    o[0] = (float)(acc[0] * inv);
    o[1] = (float)(acc[1] * inv);
    o[2] = (float)(acc[2] * inv);
    o[3] = 0.0f;
}

#ifdef __cplusplus
}
#endif
#endif
