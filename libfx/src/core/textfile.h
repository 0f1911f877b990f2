/* Small text files (recipes, sidecars) read whole, with a size cap. */
#ifndef LIBFX_CORE_TEXTFILE_H
#define LIBFX_CORE_TEXTFILE_H

#include "libfx/fx.h"

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Reads a whole text file (NUL-terminated, freed with fx_mem_free); `what` names it in
 * messages ("recipe", "sidecar"). Larger than max_bytes: FX_ERR_BAD_RECIPE. */
fx_result fx_read_text_file(const fx_context *ctx, const char *path, size_t max_bytes, const char *what,
                            char **out);

#ifdef __cplusplus
}
#endif
#endif
