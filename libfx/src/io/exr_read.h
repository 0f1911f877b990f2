/* Reading an EXR into a frame of float passes. The caller says which passes to decode
 * (the public fx_frame_read_exr asks the stack, scene/read_input.c); io never asks. */
#ifndef LIBFX_IO_EXR_READ_H
#define LIBFX_IO_EXR_READ_H

#include "libfx/fx.h"
#include "core/passes.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct fx_exr_read_request {
    const char *layer;  /* view layer to read; NULL: the only one (error if several) */
    const char *view;   /* stereo view; NULL: the default view */
    int all;            /* 1: every pass, also ones libfx does not know */
    fx_pass_set wanted; /* when !all: the passes to decode (Combined is always decoded) */
} fx_exr_read_request;

/* req NULL: every pass of the default layer and view. */
fx_result fx_exr_read(fx_context *ctx, const char *path, const fx_exr_read_request *req, fx_frame **out);

/* The layer and view req asks for, checked against an opened file (exr_common.h): the row
 * reader (exr_rows.h) names passes as fx_exr_read does. */
struct fx_exr_file;
fx_result fx_exr_resolve_layer_view(fx_context *ctx, const struct fx_exr_file *f, const fx_exr_read_request *req,
                                    const char **layer, const char **view);

#ifdef __cplusplus
}
#endif
#endif
