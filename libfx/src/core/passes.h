/* The canonical render passes libfx knows, and how Blender names them. */
#ifndef LIBFX_PASSES_H
#define LIBFX_PASSES_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef enum fx_pass_id {
    FX_PASS_COMBINED = 0,
    FX_PASS_DEPTH,
    FX_PASS_MIST,
    FX_PASS_NORMAL,
    FX_PASS_POSITION,
    FX_PASS_VECTOR,
    FX_PASS_UV,
    FX_PASS_INDEX_OB,
    FX_PASS_INDEX_MA,
    FX_PASS_ALPHA,
    FX_PASS_DIFF_DIR,
    FX_PASS_DIFF_IND,
    FX_PASS_DIFF_COL,
    FX_PASS_GLOSS_DIR,
    FX_PASS_GLOSS_IND,
    FX_PASS_GLOSS_COL,
    FX_PASS_TRANS_DIR,
    FX_PASS_TRANS_IND,
    FX_PASS_TRANS_COL,
    FX_PASS_EMIT,
    FX_PASS_ENV,
    FX_PASS_AO,
    FX_PASS_SHADOW,
    FX_PASS_CRYPTO_OBJECT,   /* all ranks: CryptoObject00, CryptoObject01, ... */
    FX_PASS_CRYPTO_MATERIAL,
    FX_PASS_CRYPTO_ASSET,
    /* The light group "libfx_light" (Blender 3.2+): the whole contribution (direct and
     * indirect) of the light(s) the add-on puts in that group: vsm_shadows' shadowed
     * light. Blender names it Combined_<group> on both routes. */
    FX_PASS_LIGHT_GROUP,
    FX_PASS_COUNT
} fx_pass_id;

/* The light group's name, and the blender_setting that asks the add-on to create it and put
 * the shadowed light in it (not a view-layer property: the add-on handles it by name). */
#define FX_LIGHT_GROUP_NAME "libfx_light"
#define FX_LIGHT_GROUP_SETTING "lightgroup:libfx_light"

typedef uint64_t fx_pass_set; /* bit (1 << fx_pass_id) */
#define FX_PASS_BIT(id) ((fx_pass_set)1 << (id))

typedef struct fx_pass_desc {
    const char *name;          /* canonical name, as Blender's render output names it */
    int channels;              /* channels libfx stores, interleaved */
    const char *channel_names; /* one letter each, in storage order: "RGBA", "Z", "XYZ" */
    int categorical;           /* index/ID data: never blurred, resampled or written as half */
    int is_color;              /* may be written as half */
    int is_crypto;             /* stored as NAME00, NAME01, ... RGBA ranks */
    const char *blender_setting; /* view layer property that enables it ("use_pass_z") */
} fx_pass_desc;

const fx_pass_desc *fx_pass_describe(fx_pass_id id);
/* Canonical id from a pass name as found in a file: also accepts the File Output
 * node's names ("Image" -> Combined) and Cryptomatte ranks ("CryptoObject01").
 * Returns -1 for names libfx does not know (they are still read when all passes are). */
int fx_pass_lookup(const char *name);

/* How a pass is reduced to a proxy resolution (fx_frame_reduce) and resampled for display
 * (fx_frame_read_pixels): 1 for colour and light passes (Combined, Alpha, Diff*, Gloss*,
 * Trans*, Emit, Env, AO, Shadow, and passes named Volume*), whose values may be averaged
 * and interpolated; 0 for everything else: categorical passes (IndexOB, IndexMA, Crypto*)
 * and geometric ones (Depth, Mist, Normal, Position, Vector, UV) take whole pixels, so IDs
 * are never mixed and depth, normal and IDs stay consistent with each other. Unknown names
 * (debug passes, other software's AOVs) are not blended either. */
int fx_pass_is_blendable(const char *name);

#ifdef __cplusplus
}
#endif
#endif
