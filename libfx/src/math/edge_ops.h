/* Edge operators over render passes: the one copy, shared by the `edges` and
 * `cel_shading` effects and the cel/edge mirror type.
 *
 * Sources, each giving a strength per pixel in its own unit, compared with its own
 * threshold:
 *  - luminance: the operator on sRGB-encoded Rec.709 luminance (perceptual: a threshold of
 *    0.1 is a 10% display step wherever it happens), unit-step normalised;
 *  - depth: the operator on ln(depth), unit-step normalised, so the strength is the
 *    relative depth jump (ln(d1/d0) ~ (d1-d0)/d0) and does not depend on scene units; or,
 *    depth_planar, second differences of 1/depth (zero on planes: see FX_EDGE_DEPTH_MODE_ITEMS).
 *    Depth >= FX_EDGE_FAR_DEPTH or non-finite is background (Cycles 1e10, Eevee 65504)
 *    and reads as FX_EDGE_FAR_DEPTH, so silhouettes against the sky are jumps too;
 *  - normal: the largest angle (degrees) between the pixel's normal and its 4 neighbours'
 *    (normalised with an epsilon: |N| ~ 0.5 at anti-aliased edges still has a direction;
 *    |N| < FX_EDGE_MIN_NORMAL is background, 90 degrees from any surface);
 *  - object / material ID: 1 - (coverage two neighbours share), the largest over the 4
 *    neighbours. From Cryptomatte ranks (coverage-aware: a half-covered anti-aliased pixel
 *    differs by 0.5 from its neighbours, a pixel-aligned boundary by 1; uncovered coverage
 *    counts as a "background" ID) or from IndexOB/IndexMA (0 or 1, Cycles only).
 * A pixel's edge value is the largest over the enabled sources of
 * clamp((strength - threshold) / max(softness * threshold, 1e-6), 0, 1), then grown to the
 * line width by a disc maximum. Kernels are written as sums of differences from the
 * centre, so a constant field gives exactly 0 (threshold 0 then draws nothing). Borders
 * replicate. Output is finite for any input and bit-identical for any thread count. */
#ifndef LIBFX_MATH_EDGE_OPS_H
#define LIBFX_MATH_EDGE_OPS_H

#include "core/context.h"
#include "core/passes.h"
#include "core/rect.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum fx_edge_operator {
    FX_EDGE_SOBEL = 0,   /* gradient magnitude sqrt(gx^2 + gy^2) / 4 */
    FX_EDGE_SOBEL_X,     /* |gx| / 4 (vertical edges) */
    FX_EDGE_SOBEL_Y,     /* |gy| / 4 (horizontal edges) */
    FX_EDGE_LAPLACE4,    /* |M4| with M4 = [0 1 0; 1 -4 1; 0 1 0], / 1 */
    FX_EDGE_LAPLACE8,    /* |M8| with M8 = [1 1 1; 1 -8 1; 1 1 1], / 3 */
    FX_EDGE_SPARSE7,     /* the sparse 7x7: the 8 taps 3 px away (+1) minus 8 x centre, / 3 */
    FX_EDGE_OPERATOR_COUNT
} fx_edge_operator;

/* Recipe names of the operators, in enum order (for FX_P_ENUM tables). */
#define FX_EDGE_OPERATOR_ITEMS { "sobel", "sobel_x", "sobel_y", "laplace4", "laplace8", "sparse7" }

#define FX_EDGE_FAR_DEPTH 6.0e4f   /* depth at or beyond this is background */
#define FX_EDGE_NEAR_DEPTH 1.0e-6f /* depth below this is clamped (ln stays finite) */
#define FX_EDGE_MIN_NORMAL 0.05f   /* |N| below this: no surface (background) */
#define FX_EDGE_MAX_RANKS 8        /* Cryptomatte ranks read per type (16 IDs) */
#define FX_EDGE_MAX_WIDTH 64.0f    /* widest line, pixels */

/* The operator at (x, y) of a 1-channel field (`stride` floats between pixels), replicate
 * borders, unit-step normalised (see the enum). */
float fx_edge_response_at(const float *field, int stride, int width, int height, int x, int y,
                          fx_edge_operator op);

enum { FX_EDGE_ID_CRYPTOMATTE = 0, FX_EDGE_ID_INDEX = 1 };

typedef struct fx_edge_settings {
    fx_edge_operator op;   /* for luminance and depth */
    int use_luminance, use_depth, use_normal, use_object, use_material;
    int id_source;         /* FX_EDGE_ID_CRYPTOMATTE or FX_EDGE_ID_INDEX */
    float luminance_threshold; /* encoded luminance step */
    float depth_threshold;     /* relative depth jump */
    float normal_threshold;    /* degrees */
    float id_threshold;        /* coverage difference, 0..1 */
    float softness;            /* ramp width as a fraction of each threshold */
    float line_width;          /* pixels; <= 2 draws the operator's own width */
    int depth_planar;          /* depth: FX_EDGE_DEPTH_PLANAR instead of the operator on ln(depth) */
} fx_edge_settings;

/* Depth modes. RELATIVE: the operator on ln(depth) (a jump of ln(d1/d0)); it also fires along
 * planes seen at grazing angles (a floor or the sea towards the horizon), whose depth grows
 * fast from pixel to pixel. PLANAR: inverse depth is affine in screen space on any plane, so
 * its second differences vanish there: strength = max over x and y of |1/d(-1) - 2/d + 1/d(+1)|
 * x d (both neighbours inside the image; a border axis gives 0). Scale-free; a small jump
 * reads eps as in RELATIVE, a step from d0 to d1 > d0 gives d1/d0 - 1 on its far side and
 * 1 - d0/d1 on the near side; creases (a kink in 1/d) draw too, grazing planes never. */
#define FX_EDGE_DEPTH_MODE_ITEMS { "relative", "planar" }

/* The passes these settings read, beyond Combined. */
fx_pass_set fx_edge_passes(const fx_edge_settings *s);
/* Pixels read around an output pixel. */
int fx_edge_halo(const fx_edge_settings *s);

typedef struct fx_edge_sources {
    const float *rgba;      /* Combined, 4 channels (luminance) */
    const float *depth;     /* 1 channel */
    const float *normal;    /* 3 channels */
    const float *index[2];  /* IndexOB, IndexMA: 1 channel */
    const float *crypto[2][FX_EDGE_MAX_RANKS]; /* CryptoObjectNN, CryptoMaterialNN: RGBA */
    int crypto_ranks[2];
    int width, height;
    /* Non-zero when the caller's emit writes into rgba while the matte streams (an in-place
     * effect): the luminance of the rows where bands meet is then taken before any band
     * runs, so no band reads a row another band has drawn. Needs fx_edge_halo(s) <=
     * FX_EDGE_IN_PLACE_MAX_HALO (fx_edge_matte_rows fails otherwise). */
    int rgba_written;
} fx_edge_sources;

/* Largest halo for which rgba_written is allowed (half a band of rows). */
#define FX_EDGE_IN_PLACE_MAX_HALO 16

/* Fills `out` from a frame (rgba: the current Combined). Fails with FX_ERR_MISSING_PASS
 * naming `where` and the pass when the settings need a pass the frame lacks. */
fx_result fx_edge_sources_from_frame(const fx_frame *f, const float *rgba, const fx_edge_settings *s,
                                     fx_edge_sources *out, const char *where);

/* The same matte, streamed: emit(user, y, row) for each row y of roi (row[x] valid for x in
 * roi's columns; borrowed until emit returns), called from the worker threads in any order,
 * each row once. No frame-size buffer is allocated: a caller that consumes the matte at once
 * (draws it over the image) saves a plane's write and read. */
typedef void (*fx_edge_row_fn)(void *user, int y, const float *row);
fx_result fx_edge_matte_rows(fx_context *ctx, const fx_edge_sources *src, const fx_edge_settings *s,
                             const fx_rect *roi, float *strengths, fx_edge_row_fn emit, void *user,
                             const char *where);

/* Blender's compositor Filter node, type Sobel, with Factor `factor` (the edges effect's
 * output gradient; docs/effects/edges.md): per colour channel the magnitude sqrt(gx^2 + gy^2)
 * of the unnormalised 3x3 Sobel kernels, neighbours clamped to the image, mixed as
 * c (1 - factor) + g factor, alpha kept; the same bits as Blender 5.2's CPU compositor on
 * finite input, finite for any input. Rows and columns of roi (NULL: the frame) of dst,
 * nothing else; dst may be src (in place: each pixel read before it is written). */
fx_result fx_edge_gradient(fx_context *ctx, const float *src, float *dst, int width, int height, const fx_rect *roi,
                           float factor, const char *where);

#ifdef __cplusplus
}
#endif
#endif
