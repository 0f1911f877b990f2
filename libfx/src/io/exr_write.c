/* fx_frame_write_exr: a frame as one scanline part, ZIP compressed (level
 * FX_EXR_DEFAULT_ZIP_LEVEL; other lossless codecs through fx_exr_write). ZIP and ZIPS
 * chunks are deflated by libdeflate (io/exr_zip.c) when libfx is built with it, by
 * OpenEXRCore's zlib otherwise: the same format, any reader decodes either.
 *
 * Channel names: `<Pass>.<letter>` with the letters of passes.h ("Combined.R",
 * "Depth.Z", "Normal.X", "CryptoObject00.R"), passes libfx does not know get R, G, B, A
 * by count, and debug passes keep their names. No layer prefix: the reader takes such a
 * file as one layer, and Blender's own File Output node writes the same shape.
 *
 * Atomic: the file is written as "<dir>/.<name>.tmp-<pid>-<n>" and renamed over the
 * destination only when complete; on any failure the temporary file is removed and
 * the destination (and the input) are untouched. */
#include "core/context.h"
#include "core/frame.h"
#include "core/mem.h"
#include "core/passes.h"
#include "io/cryptomatte_meta.h"
#include "io/exr_camera.h"
#include "io/exr_common.h"
#include "io/atomic_file.h"
#include "io/exr_write.h"
#include "io/exr_zip.h"
#include "core/parallel.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

typedef struct out_chan {
    char name[FX_NAME_MAX + 8];
    const float *data;
    int stride, slot;
    exr_pixel_type_t type;
} out_chan;

/* Attributes libfx writes itself or OpenEXR owns: metadata never overrides them. */
static fx_result parse_compression(const fx_context *ctx, const char *text, fx_exr_write_params *out);

static int reserved_attr(const char *key)
{
    static const char *const names[] = {
        "channels", "compression", "dataWindow", "displayWindow", "lineOrder", "pixelAspectRatio",
        "screenWindowCenter", "screenWindowWidth", "name", "type", "version", "chunkCount",
        "tiles", "view", "multiView", "worldToCamera", "worldToNDC"};
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++)
        if (strcmp(key, names[i]) == 0)
            return 1;
    /* libfx:* are written from the frame's own fields, except the scene's lights,
     * which are metadata (fx_frame_apply_sidecar). */
    if (strcmp(key, "libfx:lights") == 0)
        return 0;
    return strncmp(key, "cryptomatte/", 12) == 0 || strncmp(key, "libfx:", 6) == 0;
}

static int pass_is_half(const fx_pass *p, int half_color)
{
    if (!half_color)
        return 0;
    int id = fx_pass_lookup(p->name);
    if (id < 0)
        return 0; /* unknown: may be data */
    const fx_pass_desc *d = fx_pass_describe((fx_pass_id)id);
    return d->is_color && !d->categorical;
}

static fx_result build_channels(const fx_frame *f, const fx_write_options *opts, out_chan **out, int *count)
{
    int n = 0;
    for (int i = 0; i < f->pass_count; i++)
        n += f->passes[i].channels;
    out_chan *list = fx_mem_calloc((size_t)(n ? n : 1), sizeof *list);
    if (!list)
        return fx_fail(f->ctx, FX_ERR_OUT_OF_MEMORY, "out of memory writing an EXR");
    int k = 0;
    for (int i = 0; i < f->pass_count; i++) {
        const fx_pass *p = &f->passes[i];
        if (opts && opts->only_combined && strcmp(p->name, "Combined") != 0)
            continue;
        int id = fx_pass_lookup(p->name);
        const char *letters = "RGBA";
        if (id >= 0) {
            const fx_pass_desc *d = fx_pass_describe((fx_pass_id)id);
            if (d->channels == p->channels)
                letters = d->channel_names;
        }
        exr_pixel_type_t type = pass_is_half(p, opts ? opts->half_color : 0) ? EXR_PIXEL_HALF : EXR_PIXEL_FLOAT;
        for (int c = 0; c < p->channels && c < 4; c++) {
            snprintf(list[k].name, sizeof list[k].name, "%s.%c", p->name, letters[c]);
            list[k].data = p->data;
            list[k].stride = p->channels;
            list[k].slot = c;
            list[k].type = type;
            k++;
        }
    }
    *out = list;
    *count = k;
    return FX_OK;
}

static exr_result_t write_attributes(exr_context_t exr, int part, const fx_frame *f, const char *path,
                                     char *failed, size_t cap)
{
    exr_result_t rv = EXR_ERR_SUCCESS;
    fx_camera cam;
    if (fx_frame_camera(f, &cam)) {
        exr_attr_m44f_t w2c, ndc;
        fx_exr_camera_to_file(&cam, w2c.m, ndc.m);
        snprintf(failed, cap, "camera attributes");
        if ((rv = exr_attr_set_m44f(exr, part, "worldToCamera", &w2c)) != EXR_ERR_SUCCESS ||
            (rv = exr_attr_set_m44f(exr, part, "worldToNDC", &ndc)) != EXR_ERR_SUCCESS ||
            (rv = exr_attr_set_float(exr, part, "libfx:clipStart", cam.clip_start)) != EXR_ERR_SUCCESS ||
            (rv = exr_attr_set_float(exr, part, "libfx:clipEnd", cam.clip_end)) != EXR_ERR_SUCCESS)
            return rv;
    }
    double frame_no = 0, fps = 0;
    fx_frame_time(f, &frame_no, &fps);
    snprintf(failed, cap, "time attributes");
    if ((rv = exr_attr_set_double(exr, part, "libfx:frame", frame_no)) != EXR_ERR_SUCCESS ||
        (rv = exr_attr_set_double(exr, part, "libfx:fps", fps)) != EXR_ERR_SUCCESS)
        return rv;
    for (int i = 0; i < f->meta_count; i++) {
        const char *key = f->meta[i].key;
        if (reserved_attr(key) || strlen(key) > 255)
            continue;
        /* Metadata is a courtesy: one attribute OpenEXR refuses must not lose the image. */
        if (exr_attr_set_string(exr, part, key, f->meta[i].value) != EXR_ERR_SUCCESS)
            fx_warn(f->ctx, "'%s': metadata '%s' not written: %s", path, key, fx_exr_last_error());
    }
    snprintf(failed, cap, "Cryptomatte attributes");
    return fx_exr_write_cryptos(exr, part, f);
}

/* Encoding: chunks are packed and compressed on the context's pool, each worker with
 * its own exr_encode_pipeline_t (openexr_encode.h: one per thread, many threads on one
 * context), then written in increasing y on the calling thread with
 * exr_write_scanline_chunk, which OpenEXRCore requires for INCREASING_Y parts and
 * which fills the chunk table. A worker's pipeline stops short of writing: its
 * write_fn copies the compressed chunk into a slot of the current batch and
 * yield_until_ready_fn (which would insist on file order) is dropped. The bytes of a
 * chunk do not depend on who compressed it, so the file is the same for any thread
 * count. Batches of chunks bound the memory held for compressed data.
 *
 * ZIP/ZIPS through libdeflate: the pipeline's compress_fn is zip_chunk, which deflates
 * the packed bytes into the worker's own buffer (the pipeline's compressed_buffer stays
 * OpenEXR's and unused); stash_chunk copies from there, so a slot holds only the
 * compressed size, as on OpenEXR's path. */
typedef struct chunk_slot {
    uint8_t *data;
    size_t size, cap;
    int y;
} chunk_slot;

typedef struct encode_worker {
    chunk_slot *slot;  /* the chunk being encoded */
    fx_exr_zip *zip;   /* libdeflate path: this worker's compressor, made on first use */
    uint8_t *buf;      /* libdeflate path: the compressed chunk */
    size_t buf_cap;
    int in_buf;        /* zip_chunk put this chunk into buf */
} encode_worker;

typedef struct encode_job {
    const fx_frame *f;
    exr_context_t exr;
    int part;
    const out_chan *chans;
    int nchan;
    const char *path;
    int32_t lines;
    int first;                     /* chunk index of slots[0] */
    chunk_slot *slots;
    exr_encode_pipeline_t *enc;    /* per worker */
    unsigned char *have_enc;       /* per worker */
    encode_worker *wk;             /* per worker */
    int zip_level;                 /* > 0: ZIP/ZIPS through libdeflate at this level */
    fx_exr_job_error err;
} encode_job;

static int grow_slot(chunk_slot *slot, size_t n)
{
    if (n <= slot->cap)
        return 1;
    uint8_t *grown = fx_mem_realloc(slot->data, n);
    if (!grown)
        return 0;
    slot->data = grown;
    slot->cap = n;
    return 1;
}

/* compress_fn for ZIP/ZIPS (the libdeflate path). */
static exr_result_t zip_chunk(exr_encode_pipeline_t *enc)
{
    encode_worker *w = enc->encoding_user_data;
    size_t n = (size_t)enc->packed_bytes, out = 0, need = fx_exr_zip_bound(w->zip, n);
    if (need > w->buf_cap) {
        uint8_t *grown = fx_mem_realloc(w->buf, need);
        if (!grown)
            return EXR_ERR_OUT_OF_MEMORY;
        w->buf = grown;
        w->buf_cap = need;
    }
    if (fx_exr_zip_compress(w->zip, enc->packed_buffer, n, w->buf, w->buf_cap, &out) != 0)
        return EXR_ERR_OUT_OF_MEMORY;
    enc->compressed_bytes = out;
    w->in_buf = 1;
    return EXR_ERR_SUCCESS;
}

static exr_result_t stash_chunk(exr_encode_pipeline_t *enc)
{
    encode_worker *w = enc->encoding_user_data;
    chunk_slot *slot = w->slot;
    size_t n = (size_t)enc->compressed_bytes;
    if (!grow_slot(slot, n))
        return EXR_ERR_OUT_OF_MEMORY;
    if (n)
        memcpy(slot->data, w->in_buf ? w->buf : (const uint8_t *)enc->compressed_buffer, n);
    slot->size = n;
    slot->y = enc->chunk.start_y;
    return EXR_ERR_SUCCESS;
}

static void encode_chunk(encode_job *j, int k, int worker)
{
    const fx_frame *f = j->f;
    exr_encode_pipeline_t *enc = &j->enc[worker];
    encode_worker *w = &j->wk[worker];
    w->slot = &j->slots[k - j->first];
    w->in_buf = 0;
    int y = k * j->lines;
    int fy = f->data_window[1] + y;
    exr_chunk_info_t ci;
    exr_result_t rv;

    fx_exr_clear_error(); /* this thread's OpenEXR message: never a stale one */
    if ((rv = exr_write_scanline_chunk_info(j->exr, j->part, fy, &ci)) == EXR_ERR_SUCCESS)
        rv = j->have_enc[worker] ? exr_encoding_update(j->exr, j->part, &ci, enc)
                                 : exr_encoding_initialize(j->exr, j->part, &ci, enc);
    if (rv == EXR_ERR_SUCCESS) {
        j->have_enc[worker] = 1;
        for (int c = 0; c < enc->channel_count; c++) {
            exr_coding_channel_info_t *ch = &enc->channels[c];
            const out_chan *oc = NULL;
            for (int i = 0; i < j->nchan && !oc; i++)
                if (strcmp(j->chans[i].name, ch->channel_name) == 0)
                    oc = &j->chans[i];
            if (!oc) { /* cannot happen: we declared every channel */
                rv = EXR_ERR_INVALID_ARGUMENT;
                break;
            }
            size_t px = (size_t)y * (size_t)f->width;
            ch->encode_from_ptr = (const uint8_t *)(oc->data + px * (size_t)oc->stride + (size_t)oc->slot);
            ch->user_pixel_stride = oc->stride * (int32_t)sizeof(float);
            ch->user_line_stride = f->width * oc->stride * (int32_t)sizeof(float);
            ch->user_data_type = EXR_PIXEL_FLOAT;
            ch->user_bytes_per_element = sizeof(float);
        }
    }
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_encoding_choose_default_routines(j->exr, j->part, enc);
    if (rv == EXR_ERR_SUCCESS && j->zip_level > 0 && !w->zip && !(w->zip = fx_exr_zip_new(j->zip_level)))
        rv = EXR_ERR_OUT_OF_MEMORY;
    if (rv == EXR_ERR_SUCCESS) {
        enc->yield_until_ready_fn = NULL;
        enc->write_fn = stash_chunk;
        if (j->zip_level > 0)
            enc->compress_fn = zip_chunk;
        enc->encoding_user_data = w;
        rv = exr_encoding_run(j->exr, j->part, enc);
    }
    if (rv != EXR_ERR_SUCCESS) {
        const char *m = fx_exr_last_error();
        fx_exr_job_fail(&j->err, k,
                        rv == EXR_ERR_OUT_OF_MEMORY ? FX_ERR_OUT_OF_MEMORY
                        : rv == EXR_ERR_WRITE_IO    ? FX_ERR_IO
                                                    : FX_ERR_INTERNAL,
                        "cannot write '%s': scanlines from %d: %s", j->path, fy,
                        m[0] ? m : exr_get_default_error_message(rv));
    }
}

static void encode_range(void *user, int begin, int end, int worker)
{
    encode_job *j = user;
    for (int i = begin; i < end; i++)
        if (fx_exr_job_should_run(&j->err, j->first + i))
            encode_chunk(j, j->first + i, worker);
}

static fx_result encode_pixels(const fx_frame *f, exr_context_t exr, int part, const out_chan *chans, int nchan,
                               const char *path, int zip_level)
{
    int32_t lines = 0;
    exr_result_t rv = exr_get_scanlines_per_chunk(exr, part, &lines);
    if (rv != EXR_ERR_SUCCESS || lines <= 0)
        return fx_fail(f->ctx, FX_ERR_INTERNAL, "cannot write '%s': scanlines per chunk: %s", path,
                       exr_get_default_error_message(rv));
    int chunks = (int)(((int64_t)f->height + lines - 1) / lines);
    int workers = fx_parallel_workers(f->ctx);
    /* A few chunks per worker and batch: enough to balance, little memory held. */
    int batch = 8 * workers;
    if (batch > chunks)
        batch = chunks;

    encode_job j;
    memset(&j, 0, sizeof j);
    j.f = f, j.exr = exr, j.part = part, j.chans = chans, j.nchan = nchan, j.path = path, j.lines = lines;
    j.zip_level = zip_level;
    j.slots = fx_mem_calloc((size_t)batch, sizeof *j.slots);
    j.enc = fx_mem_calloc((size_t)workers, sizeof *j.enc);
    j.have_enc = fx_mem_calloc((size_t)workers, 1);
    j.wk = fx_mem_calloc((size_t)workers, sizeof *j.wk);
    if (!j.slots || !j.enc || !j.have_enc || !j.wk) {
        fx_mem_free(j.slots);
        fx_mem_free(j.enc);
        fx_mem_free(j.have_enc);
        fx_mem_free(j.wk);
        return fx_fail(f->ctx, FX_ERR_OUT_OF_MEMORY, "cannot write '%s': out of memory", path);
    }
    fx_exr_job_error_init(&j.err);

    fx_result r = FX_OK;
    for (j.first = 0; j.first < chunks && r == FX_OK; j.first += batch) {
        int n = chunks - j.first < batch ? chunks - j.first : batch;
        fx_parallel_for_worker(f->ctx, n, 1, encode_range, &j);
        if ((r = fx_exr_job_result(f->ctx, &j.err)) != FX_OK)
            break;
        for (int i = 0; i < n && r == FX_OK; i++) {
            fx_exr_clear_error();
            rv = exr_write_scanline_chunk(exr, part, j.slots[i].y, j.slots[i].data, j.slots[i].size);
            if (rv != EXR_ERR_SUCCESS) {
                const char *m = fx_exr_last_error();
                r = fx_fail(f->ctx, rv == EXR_ERR_WRITE_IO ? FX_ERR_IO : FX_ERR_INTERNAL,
                            "cannot write '%s': scanlines from %d: %s", path, j.slots[i].y,
                            m[0] ? m : exr_get_default_error_message(rv));
            }
        }
        if (r == FX_OK && j.first + n < chunks)
            r = fx_progress(f->ctx, "write", (double)(j.first + n) / chunks);
    }

    for (int w = 0; w < workers; w++) {
        if (j.have_enc[w])
            exr_encoding_destroy(exr, &j.enc[w]);
        fx_exr_zip_free(j.wk[w].zip);
        fx_mem_free(j.wk[w].buf);
    }
    for (int i = 0; i < batch; i++)
        fx_mem_free(j.slots[i].data);
    fx_exr_job_error_destroy(&j.err);
    fx_mem_free(j.slots);
    fx_mem_free(j.enc);
    fx_mem_free(j.have_enc);
    fx_mem_free(j.wk);
    return r;
}

static fx_result write_to(const fx_frame *f, const char *tmp, const char *path, const fx_write_options *opts,
                          const fx_exr_write_params *params, int zip_level)
{
    out_chan *chans = NULL;
    int nchan = 0;
    fx_result r = build_channels(f, opts, &chans, &nchan);
    if (r != FX_OK)
        return r;
    if (nchan == 0) {
        fx_mem_free(chans);
        return fx_fail(f->ctx, FX_ERR_MISSING_PASS, "cannot write '%s': the frame has no %s", path,
                       opts && opts->only_combined ? "Combined pass" : "passes");
    }
    fx_exr_clear_error();
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = fx_exr_capture_error;
    exr_context_t exr = NULL;
    exr_result_t rv = exr_start_write(&exr, tmp, EXR_WRITE_FILE_DIRECTLY, &init);
    char failed[300] = "the header";
    int part = 0;
    if (rv == EXR_ERR_SUCCESS) {
        exr_attr_box2i_t dw, disp;
        exr_attr_v2f_t swc;
        dw.min.x = f->data_window[0], dw.min.y = f->data_window[1];
        dw.max.x = f->data_window[2], dw.max.y = f->data_window[3];
        disp.min.x = f->display_window[0], disp.min.y = f->display_window[1];
        disp.max.x = f->display_window[2], disp.max.y = f->display_window[3];
        swc.x = 0.0f, swc.y = 0.0f;
        snprintf(failed, sizeof failed, "the part");
        /* Names up to 255 bytes (Blender writes "cycles.ViewLayer.synchronization_time");
         * readers since OpenEXR 1.7 accept them. */
        rv = exr_set_longname_support(exr, 1);
        if (rv == EXR_ERR_SUCCESS)
            rv = exr_add_part(exr, "libfx", EXR_STORAGE_SCANLINE, &part);
        if (rv == EXR_ERR_SUCCESS)
            rv = exr_initialize_required_attr(exr, part, &disp, &dw, 1.0f, &swc, 1.0f,
                                              EXR_LINEORDER_INCREASING_Y, params->compression);
        if (rv == EXR_ERR_SUCCESS &&
            (params->compression == EXR_COMPRESSION_ZIP || params->compression == EXR_COMPRESSION_ZIPS))
            rv = exr_set_zip_compression_level(exr, part, params->zip_level);
        for (int k = 0; k < nchan && rv == EXR_ERR_SUCCESS; k++) {
            snprintf(failed, sizeof failed, "channel '%s'", chans[k].name);
            /* The hint for lossy codecs: colour is perceptually logarithmic, data linear. */
            int ret = exr_add_channel(exr, part, chans[k].name, chans[k].type,
                                      chans[k].type == EXR_PIXEL_HALF ? EXR_PERCEPTUALLY_LOGARITHMIC
                                                                      : EXR_PERCEPTUALLY_LINEAR,
                                      1, 1);
            if (ret != EXR_ERR_SUCCESS)
                rv = (exr_result_t)ret;
        }
        if (rv == EXR_ERR_SUCCESS)
            rv = write_attributes(exr, part, f, path, failed, sizeof failed);
        if (rv == EXR_ERR_SUCCESS) {
            snprintf(failed, sizeof failed, "the header");
            rv = exr_write_header(exr);
        }
    }
    if (rv != EXR_ERR_SUCCESS) {
        const char *m = fx_exr_last_error();
        r = fx_fail(f->ctx, rv == EXR_ERR_FILE_ACCESS || rv == EXR_ERR_WRITE_IO ? FX_ERR_IO : FX_ERR_INTERNAL,
                    "cannot write '%s': %s: %s", path, failed, m[0] ? m : exr_get_default_error_message(rv));
    } else {
        r = encode_pixels(f, exr, part, chans, nchan, path, zip_level);
    }
    if (exr) {
        exr_result_t fin = exr_finish(&exr);
        if (r == FX_OK && fin != EXR_ERR_SUCCESS)
            r = fx_fail(f->ctx, FX_ERR_IO, "cannot write '%s': finishing the file: %s", path,
                        exr_get_default_error_message(fin));
    }
    fx_mem_free(chans);
    return r;
}

fx_exr_write_params fx_exr_write_defaults(void)
{
    fx_exr_write_params p = {EXR_COMPRESSION_ZIP, FX_EXR_DEFAULT_ZIP_LEVEL};
    return p;
}

fx_result fx_exr_write_with(const fx_frame *f, const char *path, const fx_write_options *opts,
                            const fx_exr_write_params *params, fx_exr_zip_impl impl)
{
    fx_context *ctx = f ? f->ctx : NULL;
    if (!f || !path || !path[0])
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "fx_frame_write_exr: frame and path must not be NULL");
    /* Older callers pass the struct without `compression`: accept that prefix. */
    const size_t v1_size = offsetof(fx_write_options, compression);
    if (opts && opts->size < v1_size)
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT,
                       "fx_frame_write_exr: opts->size is %zu, expected %zu (set it to sizeof(fx_write_options))",
                       opts->size, sizeof(fx_write_options));
    fx_exr_write_params p = params ? *params : fx_exr_write_defaults();
    if (!params && opts && opts->size >= sizeof(fx_write_options) && opts->compression) {
        fx_result pr = parse_compression(ctx, opts->compression, &p);
        if (pr != FX_OK)
            return pr;
    }
    switch (p.compression) {
    case EXR_COMPRESSION_NONE:
    case EXR_COMPRESSION_RLE:
    case EXR_COMPRESSION_ZIPS:
    case EXR_COMPRESSION_ZIP:
    case EXR_COMPRESSION_PIZ:
        break;
    default:
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT,
                       "cannot write '%s': compression '%s' is not supported (none, rle, zips, zip, piz)", path,
                       fx_exr_compression_name(p.compression));
    }
    if ((p.compression == EXR_COMPRESSION_ZIP || p.compression == EXR_COMPRESSION_ZIPS) &&
        (p.zip_level < 1 || p.zip_level > 9))
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "cannot write '%s': ZIP level %d is not in 1..9", path,
                       p.zip_level);
    if (impl == FX_EXR_ZIP_LIBDEFLATE && !fx_exr_zip_available())
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "cannot write '%s': libfx was built without libdeflate", path);
    int zip_level = 0; /* > 0: libdeflate */
    if ((p.compression == EXR_COMPRESSION_ZIP || p.compression == EXR_COMPRESSION_ZIPS) &&
        impl != FX_EXR_ZIP_STOCK && fx_exr_zip_available())
        zip_level = p.zip_level;
    fx_result r = fx_refuse_input(ctx, path, opts ? opts->input_path : NULL);
    if (r != FX_OK)
        return r;
    char *tmp = NULL;
    if ((r = fx_temp_create(ctx, path, &tmp)) != FX_OK)
        return r;
    r = write_to(f, tmp, path, opts, &p, zip_level);
    return fx_temp_commit(ctx, tmp, path, r);
}

fx_result fx_exr_write(const fx_frame *f, const char *path, const fx_write_options *opts,
                       const fx_exr_write_params *params)
{
    return fx_exr_write_with(f, path, opts, params, FX_EXR_ZIP_AUTO);
}

/* "zip", "zip:6", "zips", "piz", "rle", "none" -> params; FX_ERR_BAD_PARAM otherwise. */
static fx_result parse_compression(const fx_context *ctx, const char *text, fx_exr_write_params *out)
{
    static const struct {
        const char *name;
        exr_compression_t c;
    } codecs[] = {{"none", EXR_COMPRESSION_NONE}, {"rle", EXR_COMPRESSION_RLE}, {"zips", EXR_COMPRESSION_ZIPS},
                  {"zip", EXR_COMPRESSION_ZIP}, {"piz", EXR_COMPRESSION_PIZ}};
    fx_exr_write_params p = fx_exr_write_defaults();
    const char *colon = strchr(text, ':');
    size_t n = colon ? (size_t)(colon - text) : strlen(text);
    int found = 0;
    for (size_t i = 0; i < sizeof codecs / sizeof codecs[0]; i++)
        if (strlen(codecs[i].name) == n && strncmp(text, codecs[i].name, n) == 0) {
            p.compression = codecs[i].c;
            found = 1;
        }
    int zip = p.compression == EXR_COMPRESSION_ZIP || p.compression == EXR_COMPRESSION_ZIPS;
    if (found && colon) {
        char *end = NULL;
        long level = strtol(colon + 1, &end, 10);
        if (!zip || end == colon + 1 || *end || level < 1 || level > 9)
            found = 0;
        else
            p.zip_level = (int)level;
    }
    if (!found)
        return fx_fail(ctx, FX_ERR_BAD_PARAM,
                       "compression '%s' is not one of: zip, zip:1..zip:9, zips, zips:N, piz, rle, none", text);
    *out = p;
    return FX_OK;
}

fx_result fx_frame_write_exr(const fx_frame *f, const char *path, const fx_write_options *opts)
{
    return fx_exr_write(f, path, opts, NULL);
}
