/* A C interface over OpenEXR's C++ reader, for what OpenEXRCore 3.1.5 cannot decode:
 * DWAA/DWAB parts (exr_decoding_run returns EXR_ERR_FEATURE_NOT_IMPLEMENTED there).
 * No C++ exception ever crosses this interface: each one becomes a message. */
#ifndef LIBFX_IO_EXR_DWA_FALLBACK_H
#define LIBFX_IO_EXR_DWA_FALLBACK_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* One channel to decode as float into caller memory: pixel (x, y) of the part's data
 * window, in file coordinates, goes to first + (y - origin_y) * line_stride
 * + (x - origin_x) * pixel_stride (strides in floats). The caller guarantees that
 * every pixel of the part's data window lands inside its buffer. */
typedef struct fx_dwa_channel {
    const char *name;
    float *first;
    int origin_x, origin_y;
    size_t pixel_stride, line_stride;
} fx_dwa_channel;

/* Reads level 0 of part `part` of `path`. Returns 0 on success; otherwise non-zero
 * with a message (no file name) in err. Never throws. */
int fx_dwa_read_part(const char *path, int part, const fx_dwa_channel *channels, int count,
                     char *err, size_t err_size);

#ifdef __cplusplus
}
#endif
#endif
