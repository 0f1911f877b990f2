/* fx_exr_read: an EXR (Blender's multilayer output, a File Output node's file,
 * or any other tool's) into a frame of float passes.
 *
 * Steps: open and summarise the header (exr_common.c), choose the layer and view,
 * plan which channels feed which pass slots (exr_channels.c), allocate the passes
 * (budget-checked), decode only the planned channels of each part (OpenEXRCore; with
 * an OpenEXRCore older than 3.1.13, DWAA/DWAB parts through OpenEXR's C++ reader,
 * exr_dwa_fallback.cpp), then replace non-finite values and attach camera, time and
 * metadata. The frame is the union of the used parts' data windows; pixels a part does
 * not cover keep the fill value. */
#include "io/exr_read.h"

#include "core/context.h"
#include "core/frame.h"
#include "core/mem.h"
#include "core/parallel.h"
#include "core/passes.h"
#include "core/platform.h"
#include "io/cryptomatte_meta.h"
#include "io/exr_camera.h"
#include "io/exr_channels.h"
#include "io/exr_common.h"
#ifdef LIBFX_DWA_CXX_READER
#include "io/exr_dwa_fallback.h"
#endif

#include <errno.h>
#include <limits.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Where one planned channel lands. */
typedef struct chan_dest {
    float *base;  /* the frame pass's pixels */
    int stride;   /* the pass's channel count */
    int slot;
} chan_dest;

typedef struct reader {
    fx_context *ctx;
    fx_exr_file *f;
    fx_frame *frame;
    int dw[4];          /* the frame's data window */
    int width, height;
    chan_dest *dest;    /* per entry of f->chans; base NULL: not decoded */
} reader;

static fx_result resolve_view(fx_context *ctx, const fx_exr_file *f, const char *want, const char **out)
{
    *out = "";
    if (f->view_count == 0) {
        if (want && want[0])
            return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "'%s' has no view '%s' (the file has no views)",
                           f->path, want);
        return FX_OK;
    }
    if (!want || !want[0]) {
        *out = f->views[0];
        return FX_OK;
    }
    for (int i = 0; i < f->view_count; i++)
        if (strcmp(f->views[i], want) == 0) {
            *out = f->views[i];
            return FX_OK;
        }
    char list[512];
    size_t len = 0;
    list[0] = '\0';
    for (int i = 0; i < f->view_count && len < sizeof list; i++) {
        int w = snprintf(list + len, sizeof list - len, "%s'%s'", i ? ", " : "", f->views[i]);
        if (w < 0)
            break;
        len += (size_t)w;
    }
    return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "'%s' has no view '%s' (views: %s)", f->path, want, list);
}

/* Decoding one scanline or tiled part: its chunks are independent, so they are decoded
 * on the context's pool. OpenEXRCore allows it: a read context has parsed the whole
 * header when exr_start_read returns and may then be used by several threads at once
 * (openexr_context.h: the default file stream must give "thread-safe concurrent
 * access", and it reads with pread), the chunk table is loaded once with an atomic
 * swap (chunk.c), and an exr_decode_pipeline_t is per thread (openexr_decode.h). So
 * each worker keeps its own pipeline and scratch planes; chunks cover disjoint pixels
 * of the passes, and what a chunk decodes does not depend on the worker. */
typedef struct decode_job {
    reader *rd;
    int p;
    int tiled;
    int32_t lines;
    uint32_t tile_w, tile_h;
    int nx, chunks;
    int64_t cw, chh;               /* the largest chunk */
    size_t scratch_floats;         /* per worker */
    int decode_skipped;            /* skipped channels decoded too, as halves into scratch
                                      (see part_needs_all_channels) */
    float *scratch;                /* workers * scratch_floats */
    exr_decode_pipeline_t *dec;    /* per worker */
    unsigned char *have_dec;       /* per worker */
    atomic_int done;
    int reported;                  /* chunks done at the last progress report (worker 0) */
    fx_exr_job_error err;
    /* Uncompressed parts whose decoded channels are all float (see raw_chunk): */
    fx_os_file raw_fd;             /* != FX_OS_NO_FILE: read the chunks' bytes with pread */
    size_t raw_line;               /* bytes of one scanline of all channels */
    size_t *raw_off;               /* per part channel: its byte offset in a scanline */
} decode_job;

/* An uncompressed scanline chunk holds, for each of its lines, each channel's row in
 * the header's order. A pass file from Blender has some 35 channels of which a stack
 * may need 4: OpenEXRCore would read the whole chunk, so only the rows of the decoded
 * channels are read here, adjacent channels in one pread. Only for float channels
 * without subsampling on a little-endian host (the file's byte order), which is what
 * Blender writes; anything else takes OpenEXRCore's path. */
static int raw_part_ok(const reader *rd, const fx_exr_part *pt)
{
    const uint16_t probe = 1;
    if (pt->storage != EXR_STORAGE_SCANLINE || pt->compression != EXR_COMPRESSION_NONE ||
        *(const uint8_t *)&probe != 1)
        return 0;
    for (int c = 0; c < pt->channel_count; c++) {
        const fx_exr_chan *ch = &rd->f->chans[pt->first_chan + c];
        if (ch->x_sampling != 1 || ch->y_sampling != 1 ||
            (rd->dest[pt->first_chan + c].base && ch->type != EXR_PIXEL_FLOAT))
            return 0;
    }
    return 1;
}

static void raw_chunk(decode_job *j, int k, const exr_chunk_info_t *ci, int x0, int y0, float *scratch,
                      const char *what)
{
    reader *rd = j->rd;
    const fx_exr_part *pt = &rd->f->parts[j->p];
    size_t row = (size_t)ci->width * sizeof(float);
    if (ci->packed_size != (uint64_t)j->raw_line * (uint64_t)ci->height) {
        fx_exr_job_fail(&j->err, k, FX_ERR_BAD_FILE, "'%s': %s: uncompressed chunk of %llu bytes, expected %llu",
                        rd->f->path, what, (unsigned long long)ci->packed_size,
                        (unsigned long long)j->raw_line * (unsigned long long)ci->height);
        return;
    }
    for (int y = 0; y < ci->height; y++) {
        uint64_t line = ci->data_offset + (uint64_t)y * j->raw_line;
        for (int c = 0; c < pt->channel_count;) {
            if (!rd->dest[pt->first_chan + c].base) {
                c++;
                continue;
            }
            int end = c + 1; /* a run of decoded channels, adjacent in the line */
            while (end < pt->channel_count && rd->dest[pt->first_chan + end].base)
                end++;
            /* a lone one-channel pass (a light view's depth): its row is contiguous in the
             * pass, so the bytes go there at once, without the scratch and the copy */
            const chan_dest *d0 = &rd->dest[pt->first_chan + c];
            char *to = end - c == 1 && d0->stride == 1
                           ? (char *)(d0->base + (size_t)(y0 + y - rd->dw[1]) * (size_t)rd->width +
                                      (size_t)(x0 - rd->dw[0]))
                           : (char *)scratch;
            size_t want = (size_t)(end - c) * row, got = 0;
            while (got < want) {
                long long n = fx_os_pread(j->raw_fd, to + got, want - got, line + j->raw_off[c] + got);
                if (n <= 0) {
                    fx_exr_job_fail(&j->err, k, n < 0 ? FX_ERR_IO : FX_ERR_BAD_FILE, "'%s': %s: %s", rd->f->path,
                                    what, n < 0 ? strerror(errno) : "the file ends inside the chunk");
                    return;
                }
                got += (size_t)n;
            }
            for (int i = c; i < end && to == (char *)scratch; i++) {
                const chan_dest *d = &rd->dest[pt->first_chan + i];
                const float *src = scratch + (size_t)(i - c) * (size_t)ci->width;
                float *dst = d->base +
                             ((size_t)(y0 + y - rd->dw[1]) * (size_t)rd->width + (size_t)(x0 - rd->dw[0])) *
                                 (size_t)d->stride +
                             (size_t)d->slot;
                for (int x = 0; x < ci->width; x++)
                    dst[(size_t)x * (size_t)d->stride] = src[x];
            }
            c = end;
        }
    }
}

static void decode_chunk(decode_job *j, int k, int worker)
{
    reader *rd = j->rd;
    fx_exr_file *f = rd->f;
    const int p = j->p;
    const fx_exr_part *pt = &f->parts[p];
    exr_decode_pipeline_t *dec = &j->dec[worker];
    float *scratch = j->scratch + (size_t)worker * j->scratch_floats;
    char what[160];
    exr_chunk_info_t ci;
    exr_result_t rv;
    int x0, y0;

    fx_exr_clear_error(); /* this thread's OpenEXR message: never a stale one */
    if (j->tiled) {
        int tx = k % j->nx, ty = k / j->nx;
        rv = exr_read_tile_chunk_info(f->exr, p, tx, ty, 0, 0, &ci);
        /* Tile coordinates are counted from the data window's corner. */
        x0 = pt->dw[0] + tx * (int)j->tile_w;
        y0 = pt->dw[1] + ty * (int)j->tile_h;
        snprintf(what, sizeof what, "part %d, tile (%d, %d)", p, tx, ty);
    } else {
        y0 = pt->dw[1] + k * j->lines;
        x0 = pt->dw[0];
        rv = exr_read_scanline_chunk_info(f->exr, p, y0, &ci);
        snprintf(what, sizeof what, "part %d, scanlines from %d", p, y0);
    }
    if (rv != EXR_ERR_SUCCESS) {
        fx_exr_job_fail_exr(&j->err, k, f->path, rv, what);
        return;
    }
    if (j->raw_fd != FX_OS_NO_FILE) {
        if (ci.width != (int64_t)pt->dw[2] - pt->dw[0] + 1 || ci.height <= 0 || ci.height > j->chh ||
            y0 + (int64_t)ci.height - 1 > pt->dw[3]) {
            fx_exr_job_fail(&j->err, k, FX_ERR_BAD_FILE, "'%s': %s: chunk of %dx%d outside the data window",
                            f->path, what, ci.width, ci.height);
            return;
        }
        raw_chunk(j, k, &ci, x0, y0, scratch, what);
        return;
    }
    rv = j->have_dec[worker] ? exr_decoding_update(f->exr, p, &ci, dec)
                             : exr_decoding_initialize(f->exr, p, &ci, dec);
    if (rv != EXR_ERR_SUCCESS) {
        fx_exr_job_fail_exr(&j->err, k, f->path, rv, what);
        return;
    }
    j->have_dec[worker] = 1;
    /* Never trust the chunk's size: it must sit inside the part's window. */
    if (ci.width <= 0 || ci.height <= 0 || ci.width > j->cw || ci.height > j->chh ||
        x0 + (int64_t)ci.width - 1 > pt->dw[2] || y0 + (int64_t)ci.height - 1 > pt->dw[3]) {
        fx_exr_job_fail(&j->err, k, FX_ERR_BAD_FILE, "'%s': %s: chunk of %dx%d outside the data window",
                        f->path, what, ci.width, ci.height);
        return;
    }
    /* Decode into planes of a scratch buffer, then scatter into the passes.
     * Straight into the interleaved passes would be faster, but OpenEXRCore
     * 3.1.5's interleaved fast paths (unpack_half_to_float_4chan_interleave...)
     * assume the file's channel order is the memory order: a file stored as
     * A,B,G,R came out with alpha in red (ColorCodedLevels.exr). */
    int planes = 0;
    size_t plane = (size_t)ci.width * (size_t)ci.height;
    for (int c = 0; c < dec->channel_count; c++) {
        exr_coding_channel_info_t *ch = &dec->channels[c];
        const chan_dest *d = c < pt->channel_count ? &rd->dest[pt->first_chan + c] : NULL;
        if (d && !d->base && j->decode_skipped) {
            ch->decode_to_ptr = (uint8_t *)(scratch + (size_t)planes++ * plane);
            ch->user_pixel_stride = 2;
            ch->user_line_stride = ci.width * 2;
            ch->user_data_type = EXR_PIXEL_HALF;
            ch->user_bytes_per_element = 2;
            continue;
        }
        if (!d || !d->base) {
            ch->decode_to_ptr = NULL; /* skipped: not decoded at all */
            continue;
        }
        ch->decode_to_ptr = (uint8_t *)(scratch + (size_t)planes * plane);
        ch->user_pixel_stride = (int32_t)sizeof(float);
        ch->user_line_stride = ci.width * (int32_t)sizeof(float);
        ch->user_data_type = EXR_PIXEL_FLOAT;
        ch->user_bytes_per_element = sizeof(float);
        planes++;
    }
    if (!planes)
        return;
    if ((rv = exr_decoding_choose_default_routines(f->exr, p, dec)) != EXR_ERR_SUCCESS ||
        (rv = exr_decoding_run(f->exr, p, dec)) != EXR_ERR_SUCCESS) {
        fx_exr_job_fail_exr(&j->err, k, f->path, rv, what);
        return;
    }
    planes = 0;
    for (int c = 0; c < dec->channel_count && c < pt->channel_count; c++) {
        const chan_dest *d = &rd->dest[pt->first_chan + c];
        if (!d->base) {
            planes += j->decode_skipped;
            continue;
        }
        const float *src = scratch + (size_t)planes++ * plane;
        for (int y = 0; y < ci.height; y++) {
            float *dst = d->base +
                         ((size_t)(y0 + y - rd->dw[1]) * (size_t)rd->width + (size_t)(x0 - rd->dw[0])) *
                             (size_t)d->stride +
                         (size_t)d->slot;
            const float *row = src + (size_t)y * (size_t)ci.width;
            for (int x = 0; x < ci.width; x++)
                dst[(size_t)x * (size_t)d->stride] = row[x];
        }
    }
}

static void decode_range(void *user, int begin, int end, int worker)
{
    decode_job *j = user;
    for (int k = begin; k < end; k++) {
        if (!fx_exr_job_should_run(&j->err, k))
            continue;
        decode_chunk(j, k, worker);
        int done = atomic_fetch_add(&j->done, 1) + 1;
        /* Progress (and cancellation) from the calling thread only: it is worker 0. */
        if (worker == 0 && done - j->reported >= 16) {
            j->reported = done;
            if (fx_progress(j->rd->ctx, "read", (double)done / j->chunks) != FX_OK)
                fx_exr_job_fail(&j->err, k + 1, FX_ERR_CANCELLED, "%s", fx_context_error(j->rd->ctx));
        }
    }
}

static fx_result decode_core_part(reader *rd, int p)
{
    fx_exr_file *f = rd->f;
    const fx_exr_part *pt = &f->parts[p];
    exr_result_t rv;
    decode_job j;
    memset(&j, 0, sizeof j);
    j.rd = rd;
    j.p = p;
    j.tiled = pt->storage == EXR_STORAGE_TILED;
    j.lines = 1;
    j.nx = 1;
    int ny = 0;
    int64_t pw = (int64_t)pt->dw[2] - pt->dw[0] + 1, ph = (int64_t)pt->dw[3] - pt->dw[1] + 1;

    if (j.tiled) {
        int32_t tw = 0, th = 0;
        if ((rv = exr_get_tile_sizes(f->exr, p, 0, 0, &tw, &th)) != EXR_ERR_SUCCESS || tw <= 0 || th <= 0)
            return fx_exr_fail(rd->ctx, f, rv, "cannot read the tile size");
        j.tile_w = (uint32_t)tw, j.tile_h = (uint32_t)th;
        j.nx = (int)((pw + tw - 1) / tw);
        ny = (int)((ph + th - 1) / th);
    } else {
        if ((rv = exr_get_scanlines_per_chunk(f->exr, p, &j.lines)) != EXR_ERR_SUCCESS || j.lines <= 0)
            return fx_exr_fail(rd->ctx, f, rv, "cannot read the scanlines per chunk");
        ny = (int)((ph + j.lines - 1) / j.lines);
    }
    if ((int64_t)j.nx * ny > INT_MAX)
        return fx_fail(rd->ctx, FX_ERR_LIMIT, "'%s': part %d: too many chunks", f->path, p);
    j.chunks = j.nx * ny;

    /* Scratch for one chunk per worker: a plane per decoded channel. */
    int used = 0;
    for (int c = 0; c < pt->channel_count; c++)
        used += rd->dest[pt->first_chan + c].base != NULL;
    /* OpenEXRCore (3.1 to 3.4) picks its 3- and 4-channel half-to-float routines by the
     * part's channel count alone: they write every channel, so with one skipped (its
     * pointer NULL) they crash, and they ignore subsampling. In such a part the skipped
     * channels are decoded too, as halves: mixed output types take the generic routine. */
    if (used > 0 && used < pt->channel_count && pt->channel_count <= 4) {
        j.decode_skipped = 1;
        used = pt->channel_count;
    }
    j.cw = j.tiled ? (int64_t)j.tile_w : pw, j.chh = j.tiled ? (int64_t)j.tile_h : j.lines;
    if (j.cw > pw)
        j.cw = pw;
    if (j.chh > ph)
        j.chh = ph;
    int workers = fx_parallel_workers(rd->ctx);
    if (workers > j.chunks)
        workers = j.chunks > 0 ? j.chunks : 1;
    size_t scratch_bytes;
    if (!fx_size_mul(&j.scratch_floats, (size_t)j.cw, (size_t)j.chh, (size_t)used) ||
        !fx_size_mul(&scratch_bytes, j.scratch_floats, (size_t)workers, sizeof(float)))
        return fx_fail(rd->ctx, FX_ERR_LIMIT, "'%s': part %d: chunk size overflows", f->path, p);
    char what[1200];
    snprintf(what, sizeof what, "file '%s' part %d decoding", f->path, p);
    fx_result result = fx_check_budget(rd->ctx, scratch_bytes, what);
    if (result != FX_OK)
        return result;
    j.scratch = fx_mem_alloc(scratch_bytes ? scratch_bytes : 1);
    j.dec = fx_mem_calloc((size_t)workers, sizeof *j.dec);
    j.have_dec = fx_mem_calloc((size_t)workers, 1);
    if (!j.scratch || !j.dec || !j.have_dec) {
        fx_mem_free(j.scratch);
        fx_mem_free(j.dec);
        fx_mem_free(j.have_dec);
        return fx_fail(rd->ctx, FX_ERR_OUT_OF_MEMORY, "'%s': out of memory decoding part %d", f->path, p);
    }
    atomic_init(&j.done, 0);
    fx_exr_job_error_init(&j.err);
    j.raw_fd = FX_OS_NO_FILE;
    if (raw_part_ok(rd, pt) && (j.raw_off = fx_mem_calloc((size_t)pt->channel_count + 1, sizeof *j.raw_off))) {
        for (int c = 0; c < pt->channel_count; c++) {
            int type = f->chans[pt->first_chan + c].type;
            j.raw_off[c] = j.raw_line;
            j.raw_line += (size_t)pw * (type == EXR_PIXEL_HALF ? 2u : 4u);
        }
        j.raw_fd = fx_os_open_read(f->path); /* none: OpenEXRCore's path after all */
    }

    /* One chunk per task (a chunk is thousands of pixels); tasks are taken in
     * increasing order, which the error rule of fx_exr_job_error relies on. With
     * fewer chunks than threads the scratch is sized for fewer workers: serial. */
    if (workers < fx_parallel_workers(rd->ctx))
        decode_range(&j, 0, j.chunks, 0);
    else
        fx_parallel_for_worker(rd->ctx, j.chunks, 1, decode_range, &j);
    result = fx_exr_job_result(rd->ctx, &j.err);

    for (int w = 0; w < workers; w++)
        if (j.have_dec[w])
            exr_decoding_destroy(f->exr, &j.dec[w]);
    fx_exr_job_error_destroy(&j.err);
    fx_os_close(j.raw_fd);
    fx_mem_free(j.raw_off);
    fx_mem_free(j.have_dec);
    fx_mem_free(j.dec);
    fx_mem_free(j.scratch);
    return result;
}

#ifdef LIBFX_DWA_CXX_READER
/* OpenEXRCore before 3.1.13 cannot decode DWA: such parts go through the C++ reader. */
static fx_result decode_dwa_part(reader *rd, int p)
{
    fx_exr_file *f = rd->f;
    const fx_exr_part *pt = &f->parts[p];
    fx_dwa_channel *list = fx_mem_calloc((size_t)pt->channel_count, sizeof *list);
    if (!list)
        return fx_fail(rd->ctx, FX_ERR_OUT_OF_MEMORY, "'%s': out of memory", f->path);
    int n = 0;
    for (int c = 0; c < pt->channel_count; c++) {
        const chan_dest *d = &rd->dest[pt->first_chan + c];
        if (!d->base)
            continue;
        list[n].name = f->chans[pt->first_chan + c].full;
        list[n].first = d->base + d->slot;
        list[n].origin_x = rd->dw[0];
        list[n].origin_y = rd->dw[1];
        list[n].pixel_stride = (size_t)d->stride;
        list[n].line_stride = (size_t)d->stride * (size_t)rd->width;
        n++;
    }
    char err[512] = "";
    int rc = n ? fx_dwa_read_part(f->path, p, list, n, err, sizeof err) : 0;
    fx_mem_free(list);
    if (rc == 2)
        return fx_fail(rd->ctx, FX_ERR_OUT_OF_MEMORY, "'%s': out of memory decoding DWA part %d", f->path, p);
    if (rc != 0)
        return fx_fail(rd->ctx, FX_ERR_BAD_FILE, "'%s': part %d (DWA, OpenEXR C++ reader): %s", f->path, p, err);
    return FX_OK;
}

#endif

static int part_is_dwa(const fx_exr_part *pt)
{
    return pt->compression == EXR_COMPRESSION_DWAA || pt->compression == EXR_COMPRESSION_DWAB;
}

/* String attributes kept as metadata: everything but the structural ones and the
 * ones libfx turns into something else (Cryptomatte, time). */
static int keep_string_attr(const char *name)
{
    static const char *const skip[] = {"name", "view", "type", "Frame"};
    for (size_t i = 0; i < sizeof skip / sizeof skip[0]; i++)
        if (strcmp(name, skip[i]) == 0)
            return 0;
    if (strcmp(name, "libfx:lights") == 0)
        return 1; /* the scene's lights travel with the frame */
    return strncmp(name, "cryptomatte/", 12) != 0 && strncmp(name, "libfx:", 6) != 0;
}

static fx_result read_attributes(reader *rd, int part)
{
    fx_exr_file *f = rd->f;
    int32_t n = 0;
    const exr_attribute_t *w2c = NULL, *ndc = NULL;
    double frame_no = 0, fps = 0;
    int have_frame = 0, have_fps = 0;
    float clip[2] = {0, 0};
    int have_clip[2] = {0, 0};
    fx_frame_time(rd->frame, &frame_no, &fps);
    if (exr_get_attribute_count(f->exr, part, &n) != EXR_ERR_SUCCESS)
        n = 0;
    for (int32_t i = 0; i < n; i++) {
        const exr_attribute_t *a = NULL;
        if (exr_get_attribute_by_index(f->exr, part, EXR_ATTR_LIST_FILE_ORDER, i, &a) != EXR_ERR_SUCCESS ||
            !a || !a->name)
            continue;
        if (a->type == EXR_ATTR_M44F && strcmp(a->name, "worldToCamera") == 0)
            w2c = a;
        else if (a->type == EXR_ATTR_M44F && strcmp(a->name, "worldToNDC") == 0)
            ndc = a;
        else if (a->type == EXR_ATTR_DOUBLE && strcmp(a->name, "libfx:frame") == 0)
            frame_no = a->d, have_frame = 2;
        else if (a->type == EXR_ATTR_DOUBLE && strcmp(a->name, "libfx:fps") == 0)
            fps = a->d, have_fps = 1;
        else if (a->type == EXR_ATTR_FLOAT && strcmp(a->name, "libfx:clipStart") == 0)
            clip[0] = a->f, have_clip[0] = 1;
        else if (a->type == EXR_ATTR_FLOAT && strcmp(a->name, "libfx:clipEnd") == 0)
            clip[1] = a->f, have_clip[1] = 1;
        else if (a->type == EXR_ATTR_STRING && a->string && a->string->str) {
            if (strcmp(a->name, "Frame") == 0 && have_frame < 2) {
                /* Blender's render output: the frame number as text */
                char *end = NULL;
                double v = strtod(a->string->str, &end);
                if (end != a->string->str)
                    frame_no = v, have_frame = 1;
            } else if (keep_string_attr(a->name)) {
                fx_result r = fx_frame_set_meta(rd->frame, a->name, a->string->str);
                if (r != FX_OK)
                    return r;
            }
        }
    }
    if (have_frame || have_fps)
        fx_frame_set_time(rd->frame, frame_no, fps);
    if (w2c && ndc && w2c->m44f && ndc->m44f) {
        fx_camera cam;
        if (fx_exr_camera_from_file(w2c->m44f->m, ndc->m44f->m, &cam)) {
            if (have_clip[0])
                cam.clip_start = clip[0];
            if (have_clip[1])
                cam.clip_end = clip[1];
            fx_result r = fx_frame_set_camera(rd->frame, &cam);
            if (r != FX_OK)
                return r;
        } else {
            fx_warn(rd->ctx, "'%s': worldToCamera is singular: camera ignored", f->path);
        }
    }
    return FX_OK;
}

/* Whether decoding writes every value of the pass: each slot has a source channel, not
 * subsampled, in a part whose data window is the frame's. Such a pass is not filled first:
 * that fill is a serial write of every page of it, which the parallel decode then
 * overwrites. */
static int pass_fully_decoded(const reader *rd, const fx_exr_plan_pass *pp)
{
    for (int s = 0; s < pp->channels; s++) {
        if (pp->src[s] < 0)
            return 0;
        const fx_exr_chan *ch = &rd->f->chans[pp->src[s]];
        if (ch->x_sampling != 1 || ch->y_sampling != 1 || memcmp(rd->f->parts[ch->part].dw, rd->dw, sizeof rd->dw))
            return 0;
    }
    return 1;
}

/* Stage 1, resolve: the view and the layer the caller asked for, checked against the file. */
fx_result fx_exr_resolve_layer_view(fx_context *ctx, const fx_exr_file *f, const fx_exr_read_request *req,
                                    const char **layer, const char **view)
{
    fx_result r = resolve_view(ctx, f, req->view, view);
    if (r == FX_OK)
        r = fx_exr_choose_layer(ctx, f->path, f->chans, f->chan_count, req->layer, layer);
    return r;
}

/* Stage 2, plan: which channels feed which pass slots; a selective read must find Combined. */
static fx_result plan_passes(fx_context *ctx, const fx_exr_file *f, const fx_exr_select *sel,
                             fx_exr_plan_pass **plan, int *np)
{
    fx_result r = fx_exr_plan(ctx, f->path, f->chans, f->chan_count, f->cryptos, f->crypto_count, sel, plan, np);
    if (r != FX_OK)
        return r;
    const char *where_layer = sel->layer[0] ? sel->layer : "(none)";
    const char *view = sel->view;
    if (*np == 0 || (!sel->all && (*plan)[0].id != FX_PASS_COMBINED)) {
        int has_combined = 0;
        for (int i = 0; i < *np; i++)
            has_combined |= (*plan)[i].id == FX_PASS_COMBINED;
        if (!has_combined && !sel->all) {
            fx_mem_free(*plan);
            *plan = NULL;
            return fx_fail(ctx, FX_ERR_MISSING_PASS, "'%s' has no Combined pass (layer %s%s%s)", f->path,
                           where_layer, view[0] ? ", view " : "", view);
        }
        if (*np == 0) {
            return fx_fail(ctx, FX_ERR_BAD_FILE, "'%s' has no readable channels (layer %s%s%s)", f->path,
                           where_layer, view[0] ? ", view " : "", view);
        }
    }
    return FX_OK;
}

/* Stage 3, window: the frame is the union of the data windows of the parts that feed it,
 * within the context's size limits. Sets rd's window and size; *any_dwa when a used part
 * is DWA-compressed. */
static fx_result frame_window(reader *rd, const fx_exr_plan_pass *plan, int np, int *any_dwa)
{
    const fx_exr_file *f = rd->f;
    fx_context *ctx = rd->ctx;
    int first = 1;
    *any_dwa = 0;
    for (int i = 0; i < np; i++)
        for (int s = 0; s < plan[i].channels; s++) {
            if (plan[i].src[s] < 0)
                continue;
            const fx_exr_part *pt = &f->parts[f->chans[plan[i].src[s]].part];
            *any_dwa |= part_is_dwa(pt);
            for (int k = 0; k < 4; k++)
                if (first || (k < 2 ? pt->dw[k] < rd->dw[k] : pt->dw[k] > rd->dw[k]))
                    rd->dw[k] = pt->dw[k];
            first = 0;
        }
    if (first) /* no channel in the file at all (fills only): part 0's window */
        memcpy(rd->dw, f->parts[0].dw, sizeof rd->dw);
    int64_t w64 = (int64_t)rd->dw[2] - rd->dw[0] + 1, h64 = (int64_t)rd->dw[3] - rd->dw[1] + 1;
    if (w64 > ctx->max_width || h64 > ctx->max_height)
        return fx_fail(ctx, FX_ERR_LIMIT, "'%s': data window %lld x %lld is over the limit of %d x %d",
                       f->path, (long long)w64, (long long)h64, ctx->max_width, ctx->max_height);
    rd->width = (int)w64;
    rd->height = (int)h64;
    return FX_OK;
}

/* Stage 4, budget: the total of every pass, with overflow checks, before any pixel
 * allocation. */
static fx_result check_budget(const reader *rd, const fx_exr_plan_pass *plan, int np)
{
    uint64_t total = 0;
    for (int i = 0; i < np; i++) {
        size_t bytes;
        if (!fx_size_mul(&bytes, (size_t)rd->width, (size_t)rd->height, (size_t)plan[i].channels * sizeof(float)))
            return fx_fail(rd->ctx, FX_ERR_LIMIT, "'%s': pass %s: size overflows", rd->f->path, plan[i].name);
        total += bytes;
    }
    char what[FX_NAME_MAX + 1100];
    snprintf(what, sizeof what, "file '%s' (%d passes, %d x %d)", rd->f->path, np, rd->width, rd->height);
    return fx_check_budget(rd->ctx, total, what);
}

/* Stage 5, allocate: the frame, its windows and source, and each planned pass filled
 * with its fill values; records where each decoded channel lands (rd->dest). */
static fx_result allocate_passes(reader *rd, const fx_exr_plan_pass *plan, int np)
{
    fx_context *ctx = rd->ctx;
    const fx_exr_file *f = rd->f;
    fx_result r = fx_frame_new(ctx, rd->width, rd->height, &rd->frame);
    if (r == FX_OK) {
        int disp[4];
        memcpy(disp, f->parts[0].disp, sizeof disp);
        r = fx_frame_set_windows(rd->frame, rd->dw, disp);
    }
    /* Messages about missing passes name the file (never written back: libfx:* is reserved). */
    if (r == FX_OK)
        r = fx_frame_set_meta(rd->frame, "libfx:source", f->path);
    char what[FX_NAME_MAX + 1100];
    for (int i = 0; i < np && r == FX_OK; i++) {
        const fx_exr_plan_pass *pp = &plan[i];
        snprintf(what, sizeof what, "file '%s' pass %s", f->path, pp->name);
        size_t bytes = (size_t)rd->width * (size_t)rd->height * (size_t)pp->channels * sizeof(float);
        float *data = NULL;
        if ((r = fx_check_budget(ctx, bytes, what)) != FX_OK ||
            (r = fx_frame_alloc_pass(rd->frame, pp->name, pp->channels, &data)) != FX_OK)
            break;
        size_t count = (size_t)rd->width * (size_t)rd->height;
        int nc = pp->channels;
        int from_half = 1;
        if (!pass_fully_decoded(rd, pp))
            for (size_t px = 0; px < count; px++)
                for (int s = 0; s < nc; s++)
                    data[px * nc + s] = pp->src[s] >= 0 ? 0.0f : pp->fill[s];
        for (int s = 0; s < nc; s++) {
            if (pp->src[s] < 0)
                continue;
            rd->dest[pp->src[s]].base = data;
            rd->dest[pp->src[s]].stride = nc;
            rd->dest[pp->src[s]].slot = s;
            from_half &= f->chans[pp->src[s]].type == EXR_PIXEL_HALF;
        }
        fx_pass *fp = fx_frame_find_pass(rd->frame, pp->name);
        if (fp)
            fp->from_half = from_half;
    }
    return r;
}

/* Stage 6, decode: every part that feeds a planned channel. */
static fx_result decode_parts(reader *rd, int any_dwa)
{
    const fx_exr_file *f = rd->f;
    if (any_dwa)
        fx_warn(rd->ctx, "'%s' is DWA-compressed: lossy, data passes (Depth/Normal/Position) are approximate",
                f->path);
    fx_result r = FX_OK;
    for (int p = 0; p < f->part_count && r == FX_OK; p++) {
        int used = 0;
        for (int c = 0; c < f->parts[p].channel_count; c++)
            used |= rd->dest[f->parts[p].first_chan + c].base != NULL;
        if (!used)
            continue;
#ifdef LIBFX_DWA_CXX_READER
        r = part_is_dwa(&f->parts[p]) ? decode_dwa_part(rd, p) : decode_core_part(rd, p);
#else
        r = decode_core_part(rd, p);
#endif
    }
    return r;
}

/* Stage 7, fix-ups: gray channels copied to RGB slots, non-finite values replaced (and
 * counted in a warning). */
static fx_result fix_up_passes(reader *rd, const fx_exr_plan_pass *plan, int np)
{
    for (int i = 0; i < np; i++) {
        fx_pass *pass = fx_frame_find_pass(rd->frame, plan[i].name);
        if (!pass)
            return fx_fail(rd->ctx, FX_ERR_INTERNAL, "'%s': pass %s was planned but not made", rd->f->path,
                           plan[i].name);
        float *data = pass->data; /* our own new pass: written in place, still shareable */
        int nc = pass->channels;
        size_t count = (size_t)rd->width * (size_t)rd->height;
        for (int s = 0; s < nc; s++)
            if (plan[i].copy_from[s] >= 0)
                for (size_t px = 0; px < count; px++)
                    data[px * nc + s] = data[px * nc + plan[i].copy_from[s]];
        size_t bad = fx_sanitize_floats(rd->ctx, data, count * (size_t)nc);
        if (bad)
            fx_warn(rd->ctx, "'%s': %zu NaN/Inf values in pass %s replaced", rd->f->path, bad, plan[i].name);
    }
    return FX_OK;
}

static fx_result read_frame(fx_context *ctx, fx_exr_file *f, const fx_exr_read_request *req, fx_frame **out)
{
    const char *layer = NULL, *view = NULL;
    fx_result r = fx_exr_resolve_layer_view(ctx, f, req, &layer, &view);
    if (r != FX_OK)
        return r;
    fx_exr_select sel = {layer, view, 1, 0};
    if (!req->all) {
        sel.all = 0;
        sel.wanted = req->wanted | FX_PASS_BIT(FX_PASS_COMBINED);
    }
    fx_exr_plan_pass *plan = NULL;
    int np = 0;
    if ((r = plan_passes(ctx, f, &sel, &plan, &np)) != FX_OK)
        return r;

    reader rd = {ctx, f, NULL, {0, 0, -1, -1}, 0, 0, NULL};
    int any_dwa = 0;
    if ((r = frame_window(&rd, plan, np, &any_dwa)) != FX_OK || (r = check_budget(&rd, plan, np)) != FX_OK) {
        fx_mem_free(plan);
        return r;
    }
    rd.dest = fx_mem_calloc((size_t)(f->chan_count ? f->chan_count : 1), sizeof *rd.dest);
    if (!rd.dest) {
        fx_mem_free(plan);
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "'%s': out of memory", f->path);
    }
    r = allocate_passes(&rd, plan, np);
    if (r == FX_OK)
        r = decode_parts(&rd, any_dwa);
    if (r == FX_OK)
        r = fix_up_passes(&rd, plan, np);
    if (r == FX_OK)
        r = read_attributes(&rd, 0);
    if (r == FX_OK)
        r = fx_exr_cryptos_to_meta(f, layer, rd.frame);
    fx_mem_free(rd.dest);
    fx_mem_free(plan);
    if (r != FX_OK) {
        fx_frame_free(rd.frame);
        return r;
    }
    *out = rd.frame;
    return FX_OK;
}

fx_result fx_exr_read(fx_context *ctx, const char *path, const fx_exr_read_request *req, fx_frame **out)
{
    static const fx_exr_read_request every_pass = {NULL, NULL, 1, 0};
    fx_exr_file f;
    fx_result r = fx_exr_file_open(ctx, path, &f);
    if (r != FX_OK)
        return r;
    r = read_frame(ctx, &f, req ? req : &every_pass, out);
    fx_exr_file_close(&f);
    return r;
}
