/* Parameters: values in an effect's params struct, set and read through its table
 * (core/params.c); their migration from older versions (core/registry.c). */
#ifndef LIBFX_PARAMS_H
#define LIBFX_PARAMS_H

#include "core/effect.h"

#include <cjson/cJSON.h>

/* Sets every member of a JSON object; marks each set parameter in `explicit_set`
 * (indexed like the table) when non-NULL. Unknown names are errors. */
fx_result fx_params_set_object(fx_context *ctx, const fx_effect_class *cls, void *params,
                               const cJSON *object, unsigned char *explicit_set, const char *where);
/* The value of one parameter as JSON (a new item). */
cJSON *fx_param_to_json(const fx_param_def *def, const void *params);
/* Copies one parameter's storage from src to dst. */
void fx_param_copy(const fx_param_def *def, void *dst, const void *src);
/* For a run on a proxy of 1/factor: every parameter whose hint is "pixels" divided by
 * factor (ints rounded), kept inside its hard range (so never below its min). */
void fx_params_scale_pixels(const fx_effect_class *cls, void *params, int factor);
/* Parameter info and defaults as JSON (used by describe). */
cJSON *fx_param_info_json(const fx_param_def *def);
/* Brings a "params" object written at from_version up to the class's params_version
 * (core/registry.c), in place, with a warning per migrated parameter. A version newer
 * than the class's is an error. */
fx_result fx_params_migrate(fx_context *ctx, const fx_effect_class *cls, int from_version, cJSON *params,
                            const char *where);

#endif
