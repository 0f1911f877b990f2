/* The EXR writer's internal entry: fx_frame_write_exr with the encoding choices the
 * public options do not (yet) carry. */
#ifndef LIBFX_IO_EXR_WRITE_H
#define LIBFX_IO_EXR_WRITE_H

#include "core/context.h"
#include "core/frame.h"

#include <openexr.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Level for ZIP/ZIPS output (zlib's scale; libdeflate, when libfx has it, takes the
 * same number: io/exr_zip.c). Measured on Blender renders (docs/performance.md, "EXR
 * I/O" and "Writing EXR: ZIP through libfx's compressor"): with zlib, level 1 writes
 * ~3x faster than the default 6 for files a few percent larger; with libdeflate,
 * levels 1..6 cost about the same on renders (within the machine's noise) and the
 * sizes differ by under 0.5%, level 1 being the fastest on Combined alone. */
#define FX_EXR_DEFAULT_ZIP_LEVEL 1

typedef struct fx_exr_write_params {
    /* EXR_COMPRESSION_NONE, _RLE, _ZIPS, _ZIP or _PIZ (the lossless ones OpenEXRCore
     * 3.1 encodes); anything else is FX_ERR_INVALID_ARGUMENT. */
    exr_compression_t compression;
    int zip_level; /* 1..9 for ZIP/ZIPS; ignored otherwise */
} fx_exr_write_params;

/* EXR_COMPRESSION_ZIP at FX_EXR_DEFAULT_ZIP_LEVEL. */
fx_exr_write_params fx_exr_write_defaults(void);

/* fx_frame_write_exr with explicit encoding; params NULL: the defaults. */
fx_result fx_exr_write(const fx_frame *f, const char *path, const fx_write_options *opts,
                       const fx_exr_write_params *params);

/* Who deflates ZIP/ZIPS chunks. AUTO: libdeflate when built with it (io/exr_zip.h),
 * else OpenEXRCore's zlib; STOCK: OpenEXRCore's zlib always; LIBDEFLATE: refused
 * (FX_ERR_INVALID_ARGUMENT) when built without it. For tests and benchmarks. */
typedef enum fx_exr_zip_impl { FX_EXR_ZIP_AUTO, FX_EXR_ZIP_STOCK, FX_EXR_ZIP_LIBDEFLATE } fx_exr_zip_impl;
fx_result fx_exr_write_with(const fx_frame *f, const char *path, const fx_write_options *opts,
                            const fx_exr_write_params *params, fx_exr_zip_impl impl);

#ifdef __cplusplus
}
#endif
#endif
