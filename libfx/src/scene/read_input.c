/* fx_frame_read_exr: the public reader of a run's input. It asks the stack which passes
 * its effects and masks need and hands io a plain pass set, so io never calls the stack. */
#include "core/context.h"
#include "core/stack_passes.h"
#include "io/exr_read.h"

#include <stddef.h>

fx_result fx_frame_read_exr(fx_context *ctx, const char *path, const fx_read_options *opts, fx_frame **out)
{
    if (out)
        *out = NULL;
    if (!ctx || !path || !out)
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "fx_frame_read_exr: ctx, path and out must not be NULL");
    if (opts && opts->size < sizeof(fx_read_options))
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT,
                       "fx_frame_read_exr: opts->size is %zu, expected %zu (set it to sizeof(fx_read_options))",
                       opts->size, sizeof(fx_read_options));
    fx_exr_read_request req = {NULL, NULL, 1, 0};
    if (opts) {
        req.layer = opts->layer;
        req.view = opts->view;
        if (opts->stack) {
            req.all = 0;
            req.wanted = fx_stack_pass_set(opts->stack);
        }
    }
    return fx_exr_read(ctx, path, &req, out);
}
