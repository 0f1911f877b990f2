/* Separable Gaussian blur: the one copy of the machinery, shared by every effect that
 * blurs (gaussian_blur, bloom, glossy mirrors, VSM moments). Never write a second kernel.
 *
 * Three algorithms, all with clamp-to-edge (replicate) borders, so they converge to the
 * same result (docs/effects/gaussian_blur.md has the measured errors):
 *  - FX_BLUR_EXACT: FIR with sampled, normalised taps exp(-k^2 / 2 sigma^2) over |k| <= ceil(5 sigma),
 *    accumulated in double. Cost O(min(radius, size)) per pixel: the reference.
 *  - FX_BLUR_RECURSIVE: Deriche's (1993) fourth-order recursive Gaussian (causal +
 *    anticausal sum, the optimised constants ITK uses), normalised to unit DC gain. Up to
 *    FX_BLUR_FLOAT_MAX_SIGMA it runs in float as two second-order sections
 *    (fx_deriche_sections); above, and for strips holding |x| >= FX_BLUR_FLOAT_MAX_VALUE or
 *    non-finite values, in double. In the parallel (sum) form the replicate extension is exact: the causal
 *    filter starts in the steady state of the left edge value, the anticausal one in that
 *    of the right (the role Triggs-Sdika conditions play for the cascaded Young-van Vliet
 *    form, which we measured at 2-5% of the peak against 2.9e-3 here for any sigma).
 *    Cost independent of sigma. Below sigma 2 its fit is poor, so it switches to the exact
 *    FIR (at most 21 taps there).
 *  - FX_BLUR_BOX: `passes` extended box filters (Gwosdek et al. 2011: integer box plus
 *    fractional end taps, so the variance matches sigma^2 exactly and the result is
 *    continuous in sigma, unlike integer-width box cascades that jump as sigma moves).
 *    All passes fused in one sweep (cascaded running sums in double, per-pass rings, periodic
 *    re-sum). Cost independent of sigma.
 *
 * Layout: interleaved float pixels of 1..4 channels, rows top to bottom. The vertical
 * pass runs on strips of columns (the inner loop runs across a strip's lanes, so it
 * vectorises); the horizontal pass gathers blocks of rows into an x-major buffer and
 * runs the very same lane kernel. Recursive and box have direct row-wise kernels (vertical:
 * any channels; horizontal: 4 channels, 4 rows at once) giving the same bits. No transposes.
 */
#ifndef LIBFX_MATH_BLUR_H
#define LIBFX_MATH_BLUR_H

#include "core/context.h"
#include "core/rect.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Below this sigma every algorithm is the identity (an exact copy). */
#define FX_BLUR_MIN_SIGMA 0.2
/* The exact FIR's radius in sigmas (tail mass beyond: 5.7e-7). */
#define FX_BLUR_EXACT_SIGMAS 5.0
/* The recursive filter's halo in sigmas: its impulse response (a fit, with small
 * oscillating tails) truncated there changes the result by < 2e-5 of the signal. */
#define FX_BLUR_RECURSIVE_HALO_SIGMAS 8.0
/* recursive switches to the exact FIR below this sigma. */
#define FX_BLUR_RECURSIVE_MIN_SIGMA 2.0
/* recursive runs in float up to this sigma (above: in double; see fx_deriche_sections). */
#define FX_BLUR_FLOAT_MAX_SIGMA 64.0
/* The float kernels take lines whose every |value| is below this (finite); a strip or
 * line holding a larger or non-finite value is filtered in double instead. */
#define FX_BLUR_FLOAT_MAX_VALUE 1.0e30f

typedef enum fx_blur_algorithm {
    FX_BLUR_BOX = 0,
    FX_BLUR_RECURSIVE = 1,
    FX_BLUR_EXACT = 2
} fx_blur_algorithm;

typedef struct fx_blur_spec {
    double sigma;                /* pixels; < FX_BLUR_MIN_SIGMA: identity */
    fx_blur_algorithm algorithm;
    int box_passes;              /* FX_BLUR_BOX: 2..6 (clamped) */
} fx_blur_spec;

/* Pixels read on each side of an output pixel: the exact support for box and exact,
 * ceil(8 sigma) for recursive (whose impulse response never ends). 0 for the identity. */
int fx_blur_halo(const fx_blur_spec *spec);
int fx_blur_is_identity(const fx_blur_spec *spec);

/* Blurs `channels`-channel interleaved pixels (width x height) from src into dst.
 * roi (NULL: everything) is the region of dst to write; the rest of dst is untouched.
 * Rows and columns are computed only over roi grown by the halo, so for box and exact
 * the roi's result is exactly the full-image one; for recursive it differs by the
 * filter's tail beyond the halo (< 2e-5 of the signal). dst may equal src.
 * Output is finite for any finite input (double accumulation, clamped to +-FLT_MAX) and
 * bit-identical for any thread count. `where` names the caller in error messages. */
fx_result fx_blur_image(fx_context *ctx, const float *src, float *dst, int width, int height,
                        int channels, const fx_blur_spec *spec, const fx_rect *roi,
                        const char *where);

/* fx_blur_image that also says whether every value it wrote is finite by construction:
 * *finite = 1 when the float recursive kernels did all the work (they check that every
 * input is finite and below FX_BLUR_FLOAT_MAX_VALUE), else 0 (the caller checks). */
fx_result fx_blur_image_finite(fx_context *ctx, const float *src, float *dst, int width, int height,
                               int channels, const fx_blur_spec *spec, const fx_rect *roi,
                               const char *where, int *finite);

/* One 1-D line of n samples, `stride` floats apart (in and out may be equal), with the
 * same code as fx_blur_image (for tests and small users). */
fx_result fx_blur_line(fx_context *ctx, const float *in, float *out, int n, int stride,
                       const fx_blur_spec *spec, const char *where);

/* Sampled Gaussian taps exp(-k^2 / (2 sigma^2)) for k = -radius..radius, normalised to
 * sum 1 (taps has 2 * radius + 1 entries). */
void fx_gaussian_taps(double sigma, int radius, double *taps);
/* Radius of the exact FIR: ceil(FX_BLUR_EXACT_SIGMAS * sigma), at least 1. */
int fx_gaussian_radius(double sigma);

/* Extended box of variance var: integer radius r and end-tap weight alpha in [0, 1). */
void fx_extended_box(double var, int *r, double *alpha);

/* General small 2-D convolution (odd ksize <= 15, kernel row-major, used as given: the
 * caller normalises), replicate borders, double accumulation, over roi (NULL: all).
 * dst must not alias src. */
fx_result fx_convolve_2d(fx_context *ctx, const float *src, float *dst, int width, int height,
                         int channels, const double *kernel, int ksize, const fx_rect *roi,
                         const char *where);

#ifdef __cplusplus
}
#endif
#endif
