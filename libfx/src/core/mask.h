/* Masks: which pixels an effect may change, as coverage in [0,1].
 * Selected by material/object name (Cryptomatte), material/object pass index, and a
 * screen rectangle (in pixels, or as fractions of the display window). Names and indices are unioned; the rectangle then restricts
 * them (alone it selects itself); invert applies last. */
#ifndef LIBFX_MASK_H
#define LIBFX_MASK_H

#include "core/context.h"
#include "core/frame.h"
#include "core/passes.h"
#include "core/rect.h"

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct fx_mask_spec {
    char **materials;
    int material_count;
    char **objects;
    int object_count;
    int *material_indices;
    int material_index_count;
    int *object_indices;
    int object_index_count;
    int has_rect;
    int rect[4];   /* x, y, w, h in display-window pixels, top-left origin */
    int has_rect_relative;
    float rect_relative[4]; /* the same as fractions of the display window (survives resizing) */
    int invert;
} fx_mask_spec;

typedef struct fx_mask {
    float *coverage; /* width * height */
    int width, height;
    fx_rect bounds;  /* smallest rect holding every pixel with coverage > 0 (empty: x0 == x1) */
} fx_mask;

int fx_mask_spec_is_empty(const fx_mask_spec *spec); /* selects everything */
/* Parses {"material": ..., "object": ..., "material_index": ..., "object_index": ...,
 * "rect": [x,y,w,h], "invert": bool}; `where` names the effect in messages. */
struct cJSON;
fx_result fx_mask_spec_parse(fx_context *ctx, const struct cJSON *json, const char *where,
                             fx_mask_spec *out);
/* The same from JSON text; `what` names it in messages ("the mask", "parameter
 * 'mirror_surfaces'"). Text that is not JSON is FX_ERR_BAD_RECIPE. */
fx_result fx_mask_spec_parse_text(fx_context *ctx, const char *json, const char *where, const char *what,
                                  fx_mask_spec *out);
struct cJSON *fx_mask_spec_to_json(const fx_mask_spec *spec); /* NULL if empty or out of memory */
void fx_mask_spec_clear(fx_mask_spec *spec);
fx_pass_set fx_mask_spec_passes(const fx_mask_spec *spec);

/* Evaluates a spec on a frame. An empty spec gives *out = NULL (everything). */
fx_result fx_mask_build(fx_context *ctx, const fx_mask_spec *spec, const fx_frame *frame,
                        const char *where, fx_mask **out);
void fx_mask_free(fx_mask *mask);

/* Cryptomatte ID of a name: MurmurHash3_x86_32 (seed 0) as a float whose exponent is
 * neither 0 nor 255 (the Cryptomatte specification's conversion). */
uint32_t fx_murmur3_32(const void *data, size_t len, uint32_t seed);
float fx_cryptomatte_id(const char *name);

#ifdef __cplusplus
}
#endif
#endif
