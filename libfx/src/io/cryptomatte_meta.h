/* Cryptomatte header attributes (cryptomatte/<key>/name, hash, conversion, manifest,
 * manif_file) <-> libfx's frame metadata "cryptomatte/<Type>/manifest" and
 * "cryptomatte/<Type>/layer", Type being CryptoObject/CryptoMaterial/CryptoAsset or,
 * for other tools' names, the name's last component. */
#ifndef LIBFX_IO_CRYPTOMATTE_META_H
#define LIBFX_IO_CRYPTOMATTE_META_H

#include "io/exr_common.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Fills f->cryptos from every part's attributes, loading sidecar manifests (relative
 * paths beside the EXR only). A missing or unreadable sidecar is a warning. */
fx_result fx_exr_read_cryptos(fx_context *ctx, fx_exr_file *f);
void fx_exr_free_cryptos(fx_exr_crypto *c, int count);

/* Chooses which Cryptomatte of each type belongs to `layer` and stores its manifest
 * and full name in the frame's metadata. */
fx_result fx_exr_cryptos_to_meta(const fx_exr_file *f, const char *layer, fx_frame *frame);

/* Writes cryptomatte/<key>/{name,hash,conversion,manifest} for every
 * "cryptomatte/<Type>/manifest" metadata entry of the frame. */
exr_result_t fx_exr_write_cryptos(exr_context_t exr, int part, const fx_frame *frame);

#ifdef __cplusplus
}
#endif
#endif
