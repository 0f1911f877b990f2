/* EXR channel names -> libfx passes.
 *
 * A channel name is read from the right: the last token is the channel letter, the
 * token before it is a view when the file declares views and it names one, the next
 * is the pass, and everything left of that is the layer (layer names may contain dots
 * and spaces, so only the right end is reliable). Examples:
 *
 *   "ViewLayer.Combined.R"          layer "ViewLayer", pass "Combined", channel "R"
 *   "My.Layer 2.Depth.Z"            layer "My.Layer 2", pass "Depth"
 *   "ViewLayer.Combined.left.R"     ... view "left" (file with multiView right,left)
 *   "Image.R", "Depth.V"            File Output node: no layer
 *   "R", "left.R"                   plain RGBA file; in a multiView file a one-token
 *                                   name belongs to the default view (OpenEXR's rule)
 *
 * This file knows nothing of OpenEXR's API: the reader fills fx_exr_chan from the
 * headers, and fx_exr_plan() decides which frame pass and slot each channel feeds.
 */
#ifndef LIBFX_IO_EXR_CHANNELS_H
#define LIBFX_IO_EXR_CHANNELS_H

#include "core/context.h"
#include "core/frame.h"
#include "core/mem.h"
#include "core/passes.h"

#ifdef __cplusplus
extern "C" {
#endif

/* EXR names are at most 255 bytes (long-name files); these fit any part of one. */
#define FX_EXR_NAME_MAX 256

typedef struct fx_exr_chan {
    int part;        /* part index in the file */
    int index;       /* index in the part's channel list */
    int type;        /* exr_pixel_type_t: 0 uint, 1 half, 2 float */
    int x_sampling, y_sampling;
    char full[FX_EXR_NAME_MAX];  /* as in the file */
    char layer[FX_EXR_NAME_MAX]; /* "" when none */
    char pass[FX_EXR_NAME_MAX];  /* "" for a bare "R" */
    char view[FX_EXR_NAME_MAX];  /* "" when not tied to a view */
    char chan[FX_EXR_NAME_MAX];  /* the last token */
} fx_exr_chan;

/* Splits `full` into layer/pass/view/chan. views: the file's views (multiView attribute),
 * default first; part_view: the part's "view" attribute in multipart files (then names
 * carry no view token), or NULL. */
void fx_exr_split_channel(const char *full, const char *const *views, int view_count,
                          const char *part_view, fx_exr_chan *out);

/* One Cryptomatte found in the header (cryptomatte/<key>/name ...). */
typedef struct fx_exr_crypto {
    char key[16];                      /* the 7-hex key of the attributes */
    char name[FX_EXR_NAME_MAX];        /* name attribute: "ViewLayer.CryptoObject", "crypto_asset" */
    char file_type[FX_EXR_NAME_MAX];   /* its last component: the pass prefix in channel names */
    char type[FX_NAME_MAX];            /* canonical: CryptoObject/CryptoMaterial/CryptoAsset, or file_type */
    char layer[FX_EXR_NAME_MAX];       /* the part of name before the last '.', "" if none */
    char *manifest;                    /* JSON text (fx_mem), NULL if none */
    char manif_file[FX_EXR_NAME_MAX];  /* sidecar manifest path, relative to the EXR */
} fx_exr_crypto;

/* Canonical Cryptomatte type of a name attribute's last component: other tools'
 * "crypto_object" becomes "CryptoObject" so masks work on them; others are kept. */
void fx_exr_crypto_type(const char *file_type, char out[FX_NAME_MAX]);

/* What the reader fills into a frame pass. */
typedef struct fx_exr_plan_pass {
    char name[FX_NAME_MAX];
    int id;           /* fx_pass_id, -1 for passes libfx does not know */
    int channels;     /* 1..4 */
    int src[4];       /* index into the fx_exr_chan array, -1: not in the file */
    float fill[4];    /* value of slots with no source (Combined alpha: 1) */
    int copy_from[4]; /* >= 0: after decoding, this slot copies that slot (gray -> RGB) */
} fx_exr_plan_pass;

/* Selection of the layer and view, resolved against the file. */
typedef struct fx_exr_select {
    const char *layer; /* "" for channels without a layer */
    const char *view;  /* "" when the file has no views */
    int all;           /* 1: every pass, including unknown ones */
    fx_pass_set wanted;/* when !all: passes to decode (Combined always) */
} fx_exr_select;

/* Builds the list of frame passes. `path` is for warnings. On success *out (fx_mem)
 * holds *out_count passes (possibly 0). */
fx_result fx_exr_plan(fx_context *ctx, const char *path, const fx_exr_chan *chans, int count,
                      const fx_exr_crypto *cryptos, int crypto_count, const fx_exr_select *sel,
                      fx_exr_plan_pass **out, int *out_count);

/* Distinct layer names of the channels, in file order (borrowed pointers into chans).
 * Returns the number written (at most max). */
int fx_exr_layers(const fx_exr_chan *chans, int count, const char **out, int max);

/* Chooses the layer: `requested` if given (error listing the layers if unknown);
 * otherwise the only layer other than "Composite" ("" if there is none). */
fx_result fx_exr_choose_layer(fx_context *ctx, const char *path, const fx_exr_chan *chans,
                              int count, const char *requested, const char **out);

/* Canonical channel letter: "red" -> "R", "x" -> "X"; others unchanged (copied). */
void fx_exr_channel_letter(const char *chan, char out[FX_EXR_NAME_MAX]);

#ifdef __cplusplus
}
#endif
#endif
