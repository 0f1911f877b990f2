/* Reading one row in every `step` of a pass: see exr_rows.h. */
#include "io/exr_rows.h"

#include "core/context.h"
#include "core/mem.h"
#include "core/parallel.h"
#include "core/platform.h"
#include "core/simd4.h"
#include "io/exr_common.h"
#include "io/exr_read.h"

#include <errno.h>
#include <float.h>
#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <string.h>

struct fx_exr_rows {
    fx_context *ctx;
    fx_exr_file f;
    fx_os_file fd;
    int width, height, dw[4];
    int32_t lines;  /* scanlines per chunk */
    size_t line;    /* bytes of one scanline of all channels */
    size_t offset;  /* the pass's channel's byte offset in a scanline */
    uint64_t first; /* one-line chunks of the pass alone: where the first chunk's header is
                       (0: not that layout), see read_row_direct */
};

/* Whether part 0 holds the pass's channel in the layout exr_rows.h streams. */
static int streamable(const fx_exr_file *f, int chan)
{
    const uint16_t probe = 1;
    const fx_exr_part *pt = &f->parts[0];
    if (f->part_count != 1 || pt->storage != EXR_STORAGE_SCANLINE || pt->compression != EXR_COMPRESSION_NONE ||
        *(const uint8_t *)&probe != 1 || f->chans[chan].type != EXR_PIXEL_FLOAT)
        return 0;
    for (int c = 0; c < pt->channel_count; c++) /* a subsampled channel changes the lines' layout */
        if (f->chans[pt->first_chan + c].x_sampling != 1 || f->chans[pt->first_chan + c].y_sampling != 1)
            return 0;
    return 1;
}

fx_result fx_exr_rows_open(fx_context *ctx, const char *path, const char *pass, fx_exr_rows **out,
                           fx_exr_rows_info *info)
{
    *out = NULL;
    memset(info, 0, sizeof *info);
    fx_exr_rows *r = fx_mem_calloc(1, sizeof *r);
    if (!r)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "'%s': out of memory", path);
    r->ctx = ctx;
    r->fd = FX_OS_NO_FILE;
    fx_result res = fx_exr_file_open(ctx, path, &r->f);
    if (res) {
        fx_mem_free(r);
        return res;
    }
    fx_exr_file *f = &r->f;
    /* the pass as fx_exr_read names it (every pass of the default layer and view) */
    static const fx_exr_read_request every_pass = {NULL, NULL, 1, 0};
    const char *layer = NULL, *view = NULL;
    fx_exr_plan_pass *plan = NULL;
    int np = 0, chan = -1;
    res = fx_exr_resolve_layer_view(ctx, f, &every_pass, &layer, &view);
    if (!res) {
        fx_exr_select sel = {layer, view, 1, 0};
        res = fx_exr_plan(ctx, f->path, f->chans, f->chan_count, f->cryptos, f->crypto_count, &sel, &plan, &np);
    }
    for (int i = 0; !res && i < np; i++)
        if (strcmp(plan[i].name, pass) == 0 && plan[i].channels == 1 && plan[i].copy_from[0] < 0)
            chan = plan[i].src[0];
    fx_mem_free(plan);
    if (res || chan < 0 || !streamable(f, chan)) {
        fx_exr_file_close(f);
        fx_mem_free(r);
        return res; /* not streamable (or no such one-channel pass): the whole read says which */
    }
    const fx_exr_part *pt = &f->parts[0];
    memcpy(r->dw, pt->dw, sizeof r->dw);
    const int64_t w64 = (int64_t)pt->dw[2] - pt->dw[0] + 1, h64 = (int64_t)pt->dw[3] - pt->dw[1] + 1;
    if (w64 <= 0 || h64 <= 0 || w64 > ctx->max_width || h64 > ctx->max_height) {
        res = fx_fail(ctx, FX_ERR_LIMIT, "'%s': data window %lld x %lld is over the limit of %d x %d", f->path,
                      (long long)w64, (long long)h64, ctx->max_width, ctx->max_height);
        fx_exr_file_close(f);
        fx_mem_free(r);
        return res;
    }
    r->width = (int)w64;
    r->height = (int)h64;
    for (int c = 0; c < pt->channel_count; c++) {
        if (pt->first_chan + c == chan)
            r->offset = r->line;
        r->line += (size_t)w64 * (f->chans[pt->first_chan + c].type == EXR_PIXEL_HALF ? 2u : 4u);
    }
    exr_result_t rv = exr_get_scanlines_per_chunk(f->exr, 0, &r->lines);
    if (rv != EXR_ERR_SUCCESS || r->lines <= 0) {
        res = fx_exr_fail(ctx, f, rv, "cannot read the scanlines per chunk");
        fx_exr_file_close(f);
        fx_mem_free(r);
        return res;
    }
    r->fd = fx_os_open_read(f->path);
    if (r->fd == FX_OS_NO_FILE) { /* not readable by pread here: the whole read after all */
        fx_exr_file_close(f);
        fx_mem_free(r);
        return FX_OK;
    }
    exr_chunk_info_t ci;
    if (r->lines == 1 && r->offset == 0 && r->line == (size_t)r->width * sizeof(float) &&
        exr_read_scanline_chunk_info(f->exr, 0, r->dw[1], &ci) == EXR_ERR_SUCCESS && ci.data_offset >= 8)
        r->first = ci.data_offset - 8;
    info->width = r->width;
    info->height = r->height;
    memcpy(info->data_window, pt->dw, sizeof info->data_window);
    memcpy(info->display_window, pt->disp, sizeof info->display_window);
    *out = r;
    return FX_OK;
}

void fx_exr_rows_close(fx_exr_rows *r)
{
    if (!r)
        return;
    fx_os_close(r->fd);
    fx_exr_file_close(&r->f);
    fx_mem_free(r);
}

typedef struct band_job {
    fx_exr_rows *r;
    int step, offset, bands;
    fx_exr_row_fn fn;
    void *user;
    float *scratch;   /* per worker: one row of width floats */
    size_t *replaced; /* per band */
    fx_exr_job_error err;
    atomic_int done;
    int reported;
} band_job;

/* Row y by one pread of its chunk, header and pixels, where a file of one-line chunks of
 * the pass alone (what the add-on writes) puts it when its chunks follow each other in
 * order: r->first + (y - ymin) (8 + line). That it is there is not taken on trust: the
 * header must name line y and hold line bytes. hdr: 8 bytes, then the row (line bytes).
 * Returns 1 when the row was there, 0 when not (read it the way the chunk table says). */
static int read_row_direct(fx_exr_rows *r, int y, unsigned char *hdr)
{
    if (!r->first)
        return 0;
    const uint64_t at = r->first + (uint64_t)(y - r->dw[1]) * (8 + r->line);
    const size_t want = 8 + r->line;
    size_t got = 0;
    while (got < want) {
        long long n = fx_os_pread(r->fd, (char *)hdr + got, want - got, at + got);
        if (n <= 0)
            return 0;
        got += (size_t)n;
    }
    int32_t line_y, bytes; /* little-endian (streamable) */
    memcpy(&line_y, hdr, 4);
    memcpy(&bytes, hdr + 4, 4);
    return line_y == y && bytes >= 0 && (size_t)bytes == r->line;
}

/* Row y (file coordinates) into dst as the chunk table says: the pass's bytes of its
 * scanline, with one pread. 0, or -1 on failure (reported in the job). */
static int read_row_by_table(band_job *j, int band, int y, float *dst)
{
    fx_exr_rows *r = j->r;
    const int y0 = r->dw[1] + (y - r->dw[1]) / r->lines * r->lines; /* its chunk's first line */
    char what[96];
    exr_chunk_info_t ci;
    exr_result_t rv = exr_read_scanline_chunk_info(r->f.exr, 0, y0, &ci);
    if (rv != EXR_ERR_SUCCESS) {
        snprintf(what, sizeof what, "part 0, scanlines from %d", y0);
        fx_exr_job_fail_exr(&j->err, band, r->f.path, rv, what);
        return -1;
    }
    /* never trust the chunk table: the chunk must be the lines it says, whole */
    if (ci.width != r->width || ci.height <= 0 || ci.height > r->lines || ci.start_y != y0 ||
        y - y0 >= ci.height || ci.packed_size != (uint64_t)r->line * (uint64_t)ci.height) {
        snprintf(what, sizeof what, "part 0, scanlines from %d", y0);
        fx_exr_job_fail(&j->err, band, FX_ERR_BAD_FILE, "'%s': %s: chunk of %dx%d (%llu bytes) does not fit",
                        r->f.path, what, ci.width, ci.height, (unsigned long long)ci.packed_size);
        return -1;
    }
    const uint64_t at = ci.data_offset + (uint64_t)(y - y0) * r->line + r->offset;
    const size_t want = (size_t)r->width * sizeof(float);
    size_t got = 0;
    while (got < want) {
        long long n = fx_os_pread(r->fd, (char *)dst + got, want - got, at + got);
        if (n <= 0) {
            snprintf(what, sizeof what, "part 0, scanlines from %d", y0);
            fx_exr_job_fail(&j->err, band, n < 0 ? FX_ERR_IO : FX_ERR_BAD_FILE, "'%s': %s: %s", r->f.path, what,
                            n < 0 ? strerror(errno) : "the file ends inside the chunk");
            return -1;
        }
        got += (size_t)n;
    }
    return 0;
}

/* Row y (file coordinates) into dst, then made finite as the reader does. Returns the values
 * replaced, or (size_t)-1 on failure. dst has 8 bytes of scratch before it (read_row_direct:
 * one pread, not two, per row). */
static size_t read_row(band_job *j, int band, int y, float *dst)
{
    fx_exr_rows *r = j->r;
    if (!read_row_direct(r, y, (unsigned char *)dst - 8) && read_row_by_table(j, band, y, dst) < 0)
        return (size_t)-1;
    /* finite as a rule: tested 4 lanes at a time, fixed one by one only when not */
    v4i fin = {-1, -1, -1, -1};
    int x = 0;
    for (; x + 4 <= r->width; x += 4) {
        const v4f a = (v4f)((v4i)ld4(dst + x) & ~(v4i)V4(-0.0f)); /* |v| <= FLT_MAX: not NaN nor +-Inf */
        fin &= a <= V4(FLT_MAX);
    }
    for (; x < r->width; x++)
        fin[0] &= -(int32_t)(fabsf(dst[x]) <= FLT_MAX);
    if ((fin[0] & fin[1] & fin[2] & fin[3]) == -1)
        return 0;
    size_t bad = 0;
    for (x = 0; x < r->width; x++) /* fx_sanitize_floats' rule */
        if (!isfinite(dst[x])) {
            dst[x] = isnan(dst[x]) ? 0.0f : dst[x] > 0.0f ? FLT_MAX : -FLT_MAX;
            bad++;
        }
    return bad;
}

static void band_range(void *user, int begin, int end, int worker)
{
    band_job *j = user;
    fx_exr_rows *r = j->r;
    float *row = j->scratch + (size_t)worker * ((size_t)r->width + 4) + 4; /* 8 bytes before it: the header */
    fx_exr_clear_error(); /* this thread's OpenEXR message: never a stale one */
    for (int b = begin; b < end; b++) {
        if (!fx_exr_job_should_run(&j->err, b))
            continue;
        const long long y = (long long)b * j->step + j->offset;
        const size_t k = read_row(j, b, r->dw[1] + (int)(y < r->height ? y : r->height - 1), row);
        if (k == (size_t)-1)
            continue;
        j->replaced[b] = k;
        j->fn(j->user, b, row, worker);
        int done = atomic_fetch_add(&j->done, 1) + 1;
        /* progress (and cancellation) from the calling thread only: it is worker 0 */
        if (worker == 0 && done - j->reported >= 16) {
            j->reported = done;
            if (fx_progress(r->ctx, "read", (double)done / j->bands) != FX_OK)
                fx_exr_job_fail(&j->err, b + 1, FX_ERR_CANCELLED, "%s", fx_context_error(r->ctx));
        }
    }
}

fx_result fx_exr_rows_read_sampled(fx_exr_rows *r, int step, int offset, fx_exr_row_fn fn, void *user,
                                   size_t *replaced)
{
    *replaced = 0;
    if (step < 1 || offset < 0 || offset >= step)
        return fx_fail(r->ctx, FX_ERR_INVALID_ARGUMENT, "'%s': row %d of every %d", r->f.path, offset, step);
    band_job j;
    memset(&j, 0, sizeof j);
    j.r = r;
    j.step = step;
    j.offset = offset;
    j.bands = (int)(((long long)r->height + step - 1) / step);
    j.fn = fn;
    j.user = user;
    const int workers = fx_parallel_workers(r->ctx);
    j.scratch = fx_mem_alloc((size_t)workers * ((size_t)r->width + 4) * sizeof(float));
    j.replaced = fx_mem_calloc((size_t)j.bands, sizeof *j.replaced);
    if (!j.scratch || !j.replaced) {
        fx_mem_free(j.scratch);
        fx_mem_free(j.replaced);
        return fx_fail(r->ctx, FX_ERR_OUT_OF_MEMORY, "'%s': out of memory reading its rows", r->f.path);
    }
    atomic_init(&j.done, 0);
    fx_exr_job_error_init(&j.err);
    fx_parallel_for_worker(r->ctx, j.bands, 1, band_range, &j);
    fx_result res = fx_exr_job_result(r->ctx, &j.err);
    fx_exr_job_error_destroy(&j.err);
    for (int b = 0; b < j.bands; b++)
        *replaced += j.replaced[b];
    fx_mem_free(j.scratch);
    fx_mem_free(j.replaced);
    return res;
}
