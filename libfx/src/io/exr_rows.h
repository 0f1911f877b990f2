/* Reading one row in every `step` of a pass of an EXR, without the whole pass in memory: a
 * caller that keeps only a reduction of it (the light view at draft's resolution,
 * scene/aux_map.h) gets each row in a small per-worker scratch that stays in cache, reads
 * only the rows it keeps, and never touches a frame-sized buffer (on a first frame its
 * fresh pages cost more than the read).
 *
 * Only the layout Blender's add-on writes streams: one scanline part, uncompressed, the
 * pass one float channel without subsampling, on a little-endian host. Anything else
 * (compressed, tiled, multipart, half) opens as "not streamable": the caller reads the file
 * whole with fx_exr_read and reduces that. The pass is named as fx_exr_read names it with
 * every pass of the default layer and view, and its values are made finite as fx_exr_read
 * makes them (NaN -> 0, +-Inf -> +-FLT_MAX), so both ways give the same numbers. */
#ifndef LIBFX_IO_EXR_ROWS_H
#define LIBFX_IO_EXR_ROWS_H

#include "libfx/fx.h"

#include <stddef.h>

typedef struct fx_exr_rows fx_exr_rows;

typedef struct fx_exr_rows_info {
    int width, height;       /* the data window's size */
    int data_window[4];      /* xmin, ymin, xmax, ymax (inclusive) */
    int display_window[4];
} fx_exr_rows_info;

/* Opens `path` to stream its pass `pass` (e.g. "Depth"). *out NULL with FX_OK: the file is
 * valid but not streamable (read it whole). Errors: the reader's (missing or damaged file,
 * over the context's size limits), FX_ERR_MISSING_PASS when the pass is not there. */
fx_result fx_exr_rows_open(fx_context *ctx, const char *path, const char *pass, fx_exr_rows **out,
                           fx_exr_rows_info *info);

/* fn(user, band, row, worker) for each band of `step` rows: its row `offset` (0 <= offset <
 * step; the pass's last row when the last band is shorter), width floats in worker's scratch
 * (fn may overwrite it). Only those rows are read: a reduction that keeps one row in `step`
 * reads 1 / step of the pass. Bands run on the context's threads in any order; what fn
 * computes must not depend on `worker`. *replaced: how many non-finite values of the rows
 * read were made finite. */
typedef void (*fx_exr_row_fn)(void *user, int band, float *row, int worker);
fx_result fx_exr_rows_read_sampled(fx_exr_rows *r, int step, int offset, fx_exr_row_fn fn, void *user,
                                   size_t *replaced);

void fx_exr_rows_close(fx_exr_rows *r);

#endif
