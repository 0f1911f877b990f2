/* Opening an EXR with OpenEXRCore and summarising its header: shared by the reader
 * (exr_read.c) and the header report (exr_info.c). */
#ifndef LIBFX_IO_EXR_COMMON_H
#define LIBFX_IO_EXR_COMMON_H

#include "core/context.h"
#include "core/frame.h"
#include "io/exr_channels.h"

#include <openexr.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct fx_exr_part {
    exr_storage_t storage;
    exr_compression_t compression;
    int dw[4], disp[4];  /* xmin, ymin, xmax, ymax (inclusive) */
    const char *name;    /* borrowed from the OpenEXR context; NULL if none */
    const char *view;    /* "view" attribute of multipart files; NULL if none */
    int channel_count;
    int first_chan;      /* index of its first channel in fx_exr_file.chans */
} fx_exr_part;

typedef struct fx_exr_file {
    exr_context_t exr;
    const char *path;
    int part_count;
    fx_exr_part *parts;
    const char **views;       /* default first; borrowed strings; NULL if no views */
    int view_count;
    fx_exr_chan *chans;       /* every channel of every part */
    int chan_count;
    fx_exr_crypto *cryptos;
    int crypto_count;
} fx_exr_file;

/* Opens `path` for reading and summarises it (parts, channels parsed, views, Cryptomatte
 * attributes). Rejects missing (FX_ERR_IO), empty, non-EXR, damaged and deep files with a
 * message naming the file. On failure nothing stays allocated. */
fx_result fx_exr_file_open(fx_context *ctx, const char *path, fx_exr_file *f);
void fx_exr_file_close(fx_exr_file *f);

/* Fails with FX_ERR_BAD_FILE "'<path>': <what>: <OpenEXR message or code name>". */
fx_result fx_exr_fail(fx_context *ctx, fx_exr_file *f, exr_result_t rv, const char *what);

/* OpenEXR's error callback for every context libfx opens: keeps the calling thread's
 * last message (OpenEXR would print it to stderr otherwise). */
void fx_exr_capture_error(exr_const_context_t exr, exr_result_t code, const char *msg);
const char *fx_exr_last_error(void);
void fx_exr_clear_error(void);

/* "none", "rle", "zips", "zip", "piz", "pxr24", "b44", "b44a", "dwaa", "dwab". */
const char *fx_exr_compression_name(exr_compression_t c);

/* ---- parallel chunk loops (decoding and encoding chunks on the context's pool) ----
 * Workers cannot record errors on the context (messages are per calling thread), so a
 * loop collects its first error here and the calling thread reports it afterwards.
 * "First" is the failed chunk of the lowest index, not the earliest in time: chunks
 * are handed out in increasing order and every chunk below a failure still runs, so
 * the message is the one the serial loop gives, whatever the thread count. */
typedef struct fx_exr_job_error {
    pthread_mutex_t lock;
    int first;           /* lowest failed chunk; INT_MAX: none (under lock) */
    fx_result code;
    char message[1024];
} fx_exr_job_error;

void fx_exr_job_error_init(fx_exr_job_error *e);
void fx_exr_job_error_destroy(fx_exr_job_error *e);
/* Whether `chunk` should still run: no chunk below it has failed. */
int fx_exr_job_should_run(fx_exr_job_error *e, int chunk);
/* Records the failure of `chunk` (kept if it is the lowest so far). Any thread. */
void fx_exr_job_fail(fx_exr_job_error *e, int chunk, fx_result code, const char *fmt, ...) FX_PRINTF(4, 5);
/* The same with the calling thread's OpenEXR message, worded as fx_exr_fail does:
 * "'<path>': <what>: <message>" (FX_ERR_BAD_FILE). */
void fx_exr_job_fail_exr(fx_exr_job_error *e, int chunk, const char *path, exr_result_t rv, const char *what);
/* After the loop, on the calling thread: FX_OK, or the kept error recorded on ctx. */
fx_result fx_exr_job_result(const fx_context *ctx, fx_exr_job_error *e);

/* A string attribute of a part, or NULL. */
const char *fx_exr_string_attr(const fx_exr_file *f, int part, const char *name);

#ifdef __cplusplus
}
#endif
#endif
