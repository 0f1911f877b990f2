/* gaussian_blur: separable Gaussian (box / recursive / exact, math/blur.c) or the paper's
 * exact 5x5 kernel, with replicate borders. docs/effects/gaussian_blur.md. */
#include "core/effect.h"
#include "core/parallel.h"
#include "math/blur.h"

#include <stdio.h>
#include <string.h>

typedef struct gaussian_blur_params {
    float sigma;
    int kernel;
    int algorithm;
    int box_passes;
    int alpha;
} gaussian_blur_params;

enum { KERNEL_GAUSSIAN = 0, KERNEL_PAPER_5X5 = 1 };

static const char *const kernel_items[] = { "gaussian", "paper_5x5" };
/* Order matches fx_blur_algorithm. */
static const char *const algorithm_items[] = { "box", "recursive", "exact" };

static const fx_param_def gaussian_blur_param_defs[] = {
    FX_P_FLOAT(gaussian_blur_params, sigma, "sigma", 5.0, 0.0, 2000.0, 0.0, 100.0, "pixels",
               "Standard deviation of the Gaussian in pixels; below 0.2 the effect is the identity "
               "(also for paper_5x5)"),
    FX_P_ENUM(gaussian_blur_params, kernel, "kernel", KERNEL_GAUSSIAN, kernel_items,
              "gaussian: separable Gaussian of the given sigma; paper_5x5: the fixed 5x5 kernel "
              "1/273 [1 4 7 4 1; 4 16 26 16 4; 7 26 41 26 7; ...] applied as a true 2-D kernel "
              "(not separable); it ignores sigma and algorithm, except that sigma below 0.2 "
              "is still the identity"),
    FX_P_ENUM(gaussian_blur_params, algorithm, "algorithm", FX_BLUR_RECURSIVE, algorithm_items,
              "box: repeated extended box filters (fast, cost independent of sigma); recursive: "
              "Deriche 4th-order IIR (cost independent of sigma, max error 0.3% of the peak); "
              "exact: FIR over 5 sigma in double (the reference, cost grows with sigma)"),
    FX_P_INT(gaussian_blur_params, box_passes, "box_passes", 3, 2, 6, 2, 6, "",
             "Number of box passes for algorithm box (more: closer to a Gaussian)"),
    FX_P_BOOL(gaussian_blur_params, alpha, "alpha", 1, "Blur alpha too (off: alpha is kept)"),
};

/* The paper's kernel, used as given (its integer weights sum to 273). */
static const double paper_5x5[25] = {
    1 / 273.0, 4 / 273.0,  7 / 273.0,  4 / 273.0,  1 / 273.0,
    4 / 273.0, 16 / 273.0, 26 / 273.0, 16 / 273.0, 4 / 273.0,
    7 / 273.0, 26 / 273.0, 41 / 273.0, 26 / 273.0, 7 / 273.0,
    4 / 273.0, 16 / 273.0, 26 / 273.0, 16 / 273.0, 4 / 273.0,
    1 / 273.0, 4 / 273.0,  7 / 273.0,  4 / 273.0,  1 / 273.0,
};

static fx_blur_spec spec_of(const gaussian_blur_params *p)
{
    fx_blur_spec s;
    s.sigma = p->sigma;
    s.algorithm = (fx_blur_algorithm)p->algorithm;
    s.box_passes = p->box_passes;
    return s;
}

static int gaussian_blur_halo(const void *params, int width, int height)
{
    const gaussian_blur_params *p = params;
    if (p->sigma < FX_BLUR_MIN_SIGMA)
        return 0;
    if (p->kernel == KERNEL_PAPER_5X5)
        return 2;
    fx_blur_spec s = spec_of(p);
    int h = fx_blur_halo(&s);
    int m = width > height ? width : height;
    return h > m ? m : h;
}

static void finish_rows(void *user, int begin, int end)
{
    const fx_effect_run *run = user;
    const fx_rect *roi = &run->roi;
    for (int y = roi->y0 + begin; y < roi->y0 + end; y++)
        fx_effect_finish_row(run, run->dst + ((size_t)y * run->width + roi->x0) * 4,
                             (size_t)(roi->x1 - roi->x0) * 4);
}

/* A sigma below FX_BLUR_MIN_SIGMA is the identity (libvips' no-op path for tiny sigma):
 * the stack skips the effect. */
static int gaussian_blur_identity(const void *params)
{
    const gaussian_blur_params *p = params;
    return p->sigma < FX_BLUR_MIN_SIGMA;
}

static fx_result gaussian_blur_process(const fx_effect_run *run)
{
    const gaussian_blur_params *p = run->params;
    const char *where = run->where;
    const int w = run->width;
    const fx_rect *roi = &run->roi;
    fx_result r;
    int finite = 0;
    if (p->kernel == KERNEL_PAPER_5X5) {
        r = fx_convolve_2d(run->ctx, run->src, run->dst, w, run->height, 4, paper_5x5, 5, roi, where);
        if (r != FX_OK)
            return r;
    } else {
        fx_blur_spec s = spec_of(p);
        r = fx_blur_image_finite(run->ctx, run->src, run->dst, w, run->height, 4, &s, roi, where, &finite);
        if (r != FX_OK)
            return r;
    }
    if (!p->alpha)
        for (int y = roi->y0; y < roi->y1; y++)
            for (int x = roi->x0; x < roi->x1; x++)
                run->dst[((size_t)y * w + x) * 4 + 3] = run->src[((size_t)y * w + x) * 4 + 3];
    /* FX_EFFECT_OWN_FINITE: the float recursive blur writes finite values by construction
     * (and kept alpha was finite: the stack hands effects finite images); any other path
     * goes through the stack's check, here */
    if (!finite)
        fx_parallel_for(run->ctx, roi->y1 - roi->y0, fx_grain_for(run->ctx, roi->y1 - roi->y0), finish_rows,
                        (void *)run);
    return FX_OK;
}

/* fx_blur_image may write over its input (each pixel after its last read); keeping the
 * input's alpha needs it intact, and the 5x5 convolution reads neighbours it wrote. */
static int gaussian_blur_in_place(const void *params)
{
    const gaussian_blur_params *p = params;
    return p->alpha && p->kernel == KERNEL_GAUSSIAN;
}

const fx_effect_class fx_effect_gaussian_blur = {
    .name = "gaussian_blur",
    .doc = "Gaussian blur (box, recursive or exact algorithm; or the paper's 5x5 kernel)",
    .params_size = sizeof(gaussian_blur_params),
    .params = gaussian_blur_param_defs,
    .param_count = FX_COUNT_OF(gaussian_blur_param_defs),
    .flags = FX_EFFECT_OWN_FINITE,
    /* draft and preview are final: the float recursive blur is faster than the box cascade
     * (bench_blur: 0.55-0.65 of box 3's time at sigma 2-50) and closer to exact, so the
     * box presets were slower and worse (docs/effects/gaussian_blur.md) */
    .presets = {
        "{\"algorithm\": \"recursive\"}",
        "{\"algorithm\": \"recursive\"}",
        "{\"algorithm\": \"recursive\"}",
        "{\"algorithm\": \"exact\"}",
    },
    .passes = NULL,
    .needs_camera = NULL,
    .in_place = gaussian_blur_in_place,
    .halo = gaussian_blur_halo,
    .validate = NULL,
    .process = gaussian_blur_process,
    .identity = gaussian_blur_identity,
};
