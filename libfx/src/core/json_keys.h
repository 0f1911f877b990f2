/* Recipes and sidecars refuse an object that names a key twice: cJSON keeps both, and
 * which one wins would depend on the reader (the first for lookups, the last for loops). */
#ifndef LIBFX_CORE_JSON_KEYS_H
#define LIBFX_CORE_JSON_KEYS_H

#include "libfx/fx.h"

#include <cjson/cJSON.h>

#ifdef __cplusplus
extern "C" {
#endif

/* FX_OK when no object anywhere in `root` repeats a key; else FX_ERR_BAD_RECIPE naming the
 * key and the object holding it, prefixed with `what` ("recipe", "sidecar"). */
fx_result fx_json_check_unique_keys(const fx_context *ctx, const cJSON *root, const char *what);

#ifdef __cplusplus
}
#endif
#endif
