/* EXR's ZIP/ZIPS chunk compression through libdeflate, for the writer's encode
 * pipeline (io/exr_write.c sets it as the exr_encode_pipeline_t's compress_fn).
 *
 * The format (OpenEXR's file layout, "ZIP compression"): the chunk's packed bytes
 * are split into the bytes at even offsets followed by those at odd offsets, every
 * byte but the first becomes (b[i] - b[i-1] + 128) mod 256 over that reordered
 * array, and the result is one zlib stream (RFC 1950: header, deflate, Adler-32).
 * A chunk whose stream would not be smaller than its packed bytes is stored raw;
 * readers tell the two apart by size alone.
 *
 * Without libdeflate at build time (LIBFX_HAVE_LIBDEFLATE undefined) the functions
 * exist but fx_exr_zip_available() is 0 and the writer keeps OpenEXRCore's own
 * zlib path. */
#ifndef LIBFX_IO_EXR_ZIP_H
#define LIBFX_IO_EXR_ZIP_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct fx_exr_zip fx_exr_zip; /* one per thread: a compressor and a scratch buffer */

/* 1 when libfx was built with libdeflate. */
int fx_exr_zip_available(void);

/* NULL when out of memory or without libdeflate. fx_exr_zip_free(NULL) is fine. */
fx_exr_zip *fx_exr_zip_new(int zip_level);
void fx_exr_zip_free(fx_exr_zip *z);

/* Bytes `out` must hold for a chunk of n packed bytes (at least n: a raw chunk). */
size_t fx_exr_zip_bound(fx_exr_zip *z, size_t n);

/* One chunk: in[0..n) -> out (capacity cap >= fx_exr_zip_bound(z, n)); *out_size is
 * the stream's size, or n when the chunk is stored raw. 0 on success, -1 when out of
 * memory or cap is too small. */
int fx_exr_zip_compress(fx_exr_zip *z, const uint8_t *in, size_t n, uint8_t *out, size_t cap, size_t *out_size);

/* The reorder + predictor step alone (out holds n bytes; in and out do not overlap):
 * exposed for the tests. */
void fx_exr_zip_predict(const uint8_t *in, size_t n, uint8_t *out);

#ifdef __cplusplus
}
#endif
#endif
