/* Opening an EXR with OpenEXRCore and summarising its header for the reader and fx_exr_info_json (io/exr_common.h). */
#include "io/exr_common.h"

#include "io/cryptomatte_meta.h"
#include "core/frame.h"
#include "core/mem.h"
#include "core/platform.h"

#include <errno.h>
#include <limits.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

/* OpenEXR reports through a callback (default: print to stderr). libfx never prints:
 * keep the calling thread's last message for our own error text. Thread-local rather
 * than the context's user_data: OpenEXRCore's built-in file stream keeps its file
 * descriptor there. */
static _Thread_local char last_error[512];

void fx_exr_capture_error(exr_const_context_t exr, exr_result_t code, const char *msg)
{
    (void)exr;
    snprintf(last_error, sizeof last_error, "%s", msg ? msg : exr_get_default_error_message(code));
}

const char *fx_exr_last_error(void)
{
    return last_error;
}

void fx_exr_clear_error(void)
{
    last_error[0] = '\0';
}

const char *fx_exr_compression_name(exr_compression_t c)
{
    static const char *const names[] = {"none", "rle", "zips", "zip", "piz",
                                        "pxr24", "b44", "b44a", "dwaa", "dwab"};
    return (int)c >= 0 && (int)c < (int)(sizeof names / sizeof names[0]) ? names[c] : "unknown";
}

fx_result fx_exr_fail(fx_context *ctx, fx_exr_file *f, exr_result_t rv, const char *what)
{
    const char *detail = last_error[0] ? last_error : exr_get_default_error_message(rv);
    /* Every failure here comes from the file's content (sizes are limited and budgeted
     * before anything is allocated; OpenEXRCore 3.1.5 even says "out of memory" for a
     * chunk that does not decompress), so it is a bad file. */
    return fx_fail(ctx, FX_ERR_BAD_FILE, "'%s': %s: %s", f->path, what, detail);
}

void fx_exr_job_error_init(fx_exr_job_error *e)
{
    pthread_mutex_init(&e->lock, NULL);
    e->first = INT_MAX;
    e->code = FX_OK;
    e->message[0] = '\0';
}

void fx_exr_job_error_destroy(fx_exr_job_error *e)
{
    pthread_mutex_destroy(&e->lock);
}

int fx_exr_job_should_run(fx_exr_job_error *e, int chunk)
{
    pthread_mutex_lock(&e->lock);
    int run = chunk < e->first;
    pthread_mutex_unlock(&e->lock);
    return run;
}

static void job_failv(fx_exr_job_error *e, int chunk, fx_result code, const char *fmt, va_list ap)
{
    pthread_mutex_lock(&e->lock);
    if (chunk < e->first) {
        vsnprintf(e->message, sizeof e->message, fmt, ap);
        e->code = code;
        e->first = chunk;
    }
    pthread_mutex_unlock(&e->lock);
}

void fx_exr_job_fail(fx_exr_job_error *e, int chunk, fx_result code, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    job_failv(e, chunk, code, fmt, ap);
    va_end(ap);
}

void fx_exr_job_fail_exr(fx_exr_job_error *e, int chunk, const char *path, exr_result_t rv, const char *what)
{
    const char *detail = last_error[0] ? last_error : exr_get_default_error_message(rv);
    fx_exr_job_fail(e, chunk, FX_ERR_BAD_FILE, "'%s': %s: %s", path, what, detail);
}

fx_result fx_exr_job_result(const fx_context *ctx, fx_exr_job_error *e)
{
    if (e->first == INT_MAX)
        return FX_OK;
    return fx_fail(ctx, e->code, "%s", e->message);
}

const char *fx_exr_string_attr(const fx_exr_file *f, int part, const char *name)
{
    const exr_attribute_t *a = NULL;
    if (exr_get_attribute_by_name(f->exr, part, name, &a) != EXR_ERR_SUCCESS || !a ||
        a->type != EXR_ATTR_STRING || !a->string || !a->string->str)
        return NULL;
    return a->string->str;
}

void fx_exr_file_close(fx_exr_file *f)
{
    if (f->exr)
        exr_finish(&f->exr);
    f->exr = NULL;
    fx_mem_free(f->parts);
    fx_mem_free(f->views);
    fx_mem_free(f->chans);
    fx_exr_free_cryptos(f->cryptos, f->crypto_count);
    f->parts = NULL;
    f->views = NULL;
    f->chans = NULL;
    f->cryptos = NULL;
    f->part_count = f->view_count = f->chan_count = f->crypto_count = 0;
}

static fx_result summarise(fx_context *ctx, fx_exr_file *f)
{
    exr_result_t rv;
    int parts = 0;
    if ((rv = exr_get_count(f->exr, &parts)) != EXR_ERR_SUCCESS || parts <= 0)
        return fx_exr_fail(ctx, f, rv, "cannot count the parts");
    f->parts = fx_mem_calloc((size_t)parts, sizeof *f->parts);
    if (!f->parts)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "'%s': out of memory", f->path);
    f->part_count = parts;

    int total = 0;
    for (int p = 0; p < parts; p++) {
        fx_exr_part *pt = &f->parts[p];
        exr_attr_box2i_t dw, disp;
        const exr_attr_chlist_t *cl = NULL;
        if ((rv = exr_get_storage(f->exr, p, &pt->storage)) != EXR_ERR_SUCCESS)
            return fx_exr_fail(ctx, f, rv, "cannot read the storage type");
        if (pt->storage == EXR_STORAGE_DEEP_SCANLINE || pt->storage == EXR_STORAGE_DEEP_TILED)
            return fx_fail(ctx, FX_ERR_BAD_FILE, "'%s': deep images are not supported", f->path);
        if ((rv = exr_get_compression(f->exr, p, &pt->compression)) != EXR_ERR_SUCCESS)
            return fx_exr_fail(ctx, f, rv, "cannot read the compression");
        if ((rv = exr_get_data_window(f->exr, p, &dw)) != EXR_ERR_SUCCESS)
            return fx_exr_fail(ctx, f, rv, "cannot read the data window");
        if ((rv = exr_get_display_window(f->exr, p, &disp)) != EXR_ERR_SUCCESS)
            return fx_exr_fail(ctx, f, rv, "cannot read the display window");
        if ((rv = exr_get_channels(f->exr, p, &cl)) != EXR_ERR_SUCCESS || !cl)
            return fx_exr_fail(ctx, f, rv, "cannot read the channel list");
        /* OpenEXRCore validated these against the size limits; keep them sane anyway so
         * (max - min + 1) can never overflow an int below. */
        if (dw.max.x < dw.min.x || dw.max.y < dw.min.y ||
            (int64_t)dw.max.x - dw.min.x >= ctx->max_width ||
            (int64_t)dw.max.y - dw.min.y >= ctx->max_height)
            return fx_fail(ctx, FX_ERR_LIMIT,
                           "'%s': data window [%d,%d]-[%d,%d] is empty or over the limit of %d x %d",
                           f->path, dw.min.x, dw.min.y, dw.max.x, dw.max.y, ctx->max_width,
                           ctx->max_height);
        pt->dw[0] = dw.min.x, pt->dw[1] = dw.min.y, pt->dw[2] = dw.max.x, pt->dw[3] = dw.max.y;
        pt->disp[0] = disp.min.x, pt->disp[1] = disp.min.y;
        pt->disp[2] = disp.max.x, pt->disp[3] = disp.max.y;
        const char *name = NULL;
        if (exr_get_name(f->exr, p, &name) == EXR_ERR_SUCCESS)
            pt->name = name;
        if (parts > 1)
            pt->view = fx_exr_string_attr(f, p, "view");
        pt->channel_count = cl->num_channels;
        pt->first_chan = total;
        total += cl->num_channels;
    }

    /* Views: the multiView attribute of single-part files (default first), or the view
     * attributes of multipart files in part order (the first part's is the default). */
    const exr_attribute_t *mv = NULL;
    if (exr_get_attribute_by_name(f->exr, 0, "multiView", &mv) == EXR_ERR_SUCCESS && mv &&
        mv->type == EXR_ATTR_STRING_VECTOR && mv->stringvector && mv->stringvector->n_strings > 0) {
        int n = mv->stringvector->n_strings;
        f->views = fx_mem_calloc((size_t)n, sizeof *f->views);
        if (!f->views)
            return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "'%s': out of memory", f->path);
        for (int i = 0; i < n; i++)
            if (mv->stringvector->strings[i].str && mv->stringvector->strings[i].str[0])
                f->views[f->view_count++] = mv->stringvector->strings[i].str;
    } else if (parts > 1) {
        f->views = fx_mem_calloc((size_t)parts, sizeof *f->views);
        if (!f->views)
            return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "'%s': out of memory", f->path);
        for (int p = 0; p < parts; p++) {
            const char *v = f->parts[p].view;
            if (!v || !v[0])
                continue;
            int seen = 0;
            for (int i = 0; i < f->view_count && !seen; i++)
                seen = strcmp(f->views[i], v) == 0;
            if (!seen)
                f->views[f->view_count++] = v;
        }
    }

    f->chans = fx_mem_calloc(total ? (size_t)total : 1, sizeof *f->chans);
    if (!f->chans)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "'%s': out of memory", f->path);
    for (int p = 0; p < parts; p++) {
        const exr_attr_chlist_t *cl = NULL;
        exr_get_channels(f->exr, p, &cl);
        for (int i = 0; i < cl->num_channels; i++) {
            const exr_attr_chlist_entry_t *e = &cl->entries[i];
            fx_exr_chan *c = &f->chans[f->chan_count++];
            fx_exr_split_channel(e->name.str ? e->name.str : "", f->views, f->view_count,
                                 f->parts[p].view && f->parts[p].view[0] ? f->parts[p].view : NULL, c);
            c->part = p;
            c->index = i;
            c->type = (int)e->pixel_type;
            c->x_sampling = e->x_sampling;
            c->y_sampling = e->y_sampling;
        }
    }
    return fx_exr_read_cryptos(ctx, f);
}

fx_result fx_exr_file_open(fx_context *ctx, const char *path, fx_exr_file *f)
{
    memset(f, 0, sizeof *f);
    f->path = path;
    fx_os_stat st;
    if (fx_os_stat_path(path, &st) != 0)
        return fx_fail(ctx, FX_ERR_IO, "cannot open '%s': %s", path, strerror(errno));
    if (st.is_dir)
        return fx_fail(ctx, FX_ERR_IO, "cannot open '%s': %s", path, strerror(EISDIR));
    if (st.size == 0)
        return fx_fail(ctx, FX_ERR_BAD_FILE, "'%s' is empty (0 bytes): not an EXR file", path);
    FILE *probe = fx_os_fopen(path, "rb");
    if (!probe)
        return fx_fail(ctx, FX_ERR_IO, "cannot open '%s': %s", path, strerror(errno));
    unsigned char magic[4] = {0};
    size_t got = fread(magic, 1, 4, probe);
    fclose(probe);
    if (got < 4 || magic[0] != 0x76 || magic[1] != 0x2f || magic[2] != 0x31 || magic[3] != 0x01)
        return fx_fail(ctx, FX_ERR_BAD_FILE, "'%s' is not an EXR file (no OpenEXR magic number)", path);

    fx_exr_clear_error();
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = fx_exr_capture_error;
    /* Hostile headers: OpenEXRCore rejects sizes over these before allocating anything. */
    init.max_image_width = ctx->max_width;
    init.max_image_height = ctx->max_height;
    init.max_tile_width = ctx->max_width;
    init.max_tile_height = ctx->max_height;
    exr_result_t rv = exr_start_read(&f->exr, path, &init);
    if (rv != EXR_ERR_SUCCESS) {
        fx_result r = rv == EXR_ERR_FILE_ACCESS
                          ? fx_fail(ctx, FX_ERR_IO, "cannot open '%s': %s", path,
                                    last_error[0] ? last_error : exr_get_default_error_message(rv))
                          : fx_exr_fail(ctx, f, rv, "not a readable EXR header");
        if (f->exr)
            exr_finish(&f->exr);
        f->exr = NULL;
        return r;
    }
    fx_result r = summarise(ctx, f);
    if (r != FX_OK)
        fx_exr_file_close(f);
    return r;
}
