/* fx_frame_write_png: an 8-bit sRGB preview of one pass.
 *
 * The image is the frame's data window (the pixels libfx holds; the display window
 * is an EXR notion PNG cannot express). Values are scaled by 2^exposure, clamped to
 * [0, 1] and encoded with the sRGB transfer function (IEC 61966-2-1), not a plain
 * gamma 2.2; alpha is linear and not exposed. 1-channel passes are gray, 4-channel
 * passes keep their alpha, 2- and 3-channel passes are RGB (missing blue = 0). */
#include "core/context.h"
#include "core/frame.h"
#include "core/mem.h"
#include "core/platform.h"
#include "io/atomic_file.h"

#include <errno.h>
#include <math.h>
#include <png.h>
#include <setjmp.h>
#include <stdio.h>
#include <string.h>

static unsigned char encode_srgb(float v, float scale)
{
    double x = (double)v * scale;
    if (!(x > 0.0)) /* negatives and NaN */
        return 0;
    if (x >= 1.0)
        return 255;
    x = x <= 0.0031308 ? 12.92 * x : 1.055 * pow(x, 1.0 / 2.4) - 0.055;
    return (unsigned char)(x * 255.0 + 0.5);
}

static unsigned char encode_linear(float v)
{
    if (!(v > 0.0f))
        return 0;
    if (v >= 1.0f)
        return 255;
    return (unsigned char)(v * 255.0f + 0.5f);
}

typedef struct png_job {
    const char *path;
    char message[256];
} png_job;

static void on_png_error(png_structp png, png_const_charp msg)
{
    png_job *job = png_get_error_ptr(png);
    if (job)
        snprintf(job->message, sizeof job->message, "%s", msg);
    png_longjmp(png, 1);
}

static void on_png_warning(png_structp png, png_const_charp msg)
{
    (void)png;
    (void)msg; /* libfx never prints */
}

/* Encodes rows into fp; returns 0 on success. Kept apart so that setjmp's frame holds
 * no variable modified after it (no volatile games). */
static int encode_png(FILE *fp, png_job *job, const unsigned char *rgba, int w, int h, int out_ch)
{
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, job, on_png_error, on_png_warning);
    if (!png)
        return 1;
    png_infop info = png_create_info_struct(png);
    if (!info) {
        png_destroy_write_struct(&png, NULL);
        return 1;
    }
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_write_struct(&png, &info);
        return 1;
    }
    png_init_io(png, fp);
    int type = out_ch == 1 ? PNG_COLOR_TYPE_GRAY : out_ch == 3 ? PNG_COLOR_TYPE_RGB : PNG_COLOR_TYPE_RGBA;
    png_set_IHDR(png, info, (png_uint_32)w, (png_uint_32)h, 8, type, PNG_INTERLACE_NONE,
                 PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_set_sRGB_gAMA_and_cHRM(png, info, PNG_sRGB_INTENT_PERCEPTUAL);
    png_write_info(png, info);
    for (int y = 0; y < h; y++)
        png_write_row(png, rgba + (size_t)y * (size_t)w * (size_t)out_ch);
    png_write_end(png, info);
    png_destroy_write_struct(&png, &info);
    return 0;
}

fx_result fx_frame_write_png(const fx_frame *f, const char *path, const char *pass, float exposure)
{
    fx_context *ctx = f ? f->ctx : NULL;
    if (!f || !path || !path[0])
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "fx_frame_write_png: frame and path must not be NULL");
    if (!isfinite(exposure) || fabsf(exposure) > 64.0f)
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "cannot write '%s': exposure %g is outside [-64, 64] stops",
                       path, (double)exposure);
    const char *name = pass ? pass : "Combined";
    const fx_pass *p = fx_frame_find_pass(f, name);
    if (!p)
        return fx_fail(ctx, FX_ERR_MISSING_PASS, "cannot write '%s': the frame has no pass '%s'", path, name);
    int in_ch = p->channels, out_ch = in_ch == 1 ? 1 : in_ch == 4 ? 4 : 3;
    size_t bytes;
    if (!fx_size_mul(&bytes, (size_t)f->width, (size_t)f->height, (size_t)out_ch))
        return fx_fail(ctx, FX_ERR_LIMIT, "cannot write '%s': image too large", path);
    fx_result r = fx_check_budget(ctx, bytes, "PNG preview");
    if (r != FX_OK)
        return r;
    unsigned char *px = fx_mem_alloc(bytes ? bytes : 1);
    if (!px)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "cannot write '%s': out of memory", path);
    float scale = exp2f(exposure);
    size_t n = (size_t)f->width * (size_t)f->height;
    for (size_t i = 0; i < n; i++) {
        const float *s = p->data + i * (size_t)in_ch;
        unsigned char *d = px + i * (size_t)out_ch;
        if (out_ch == 1) {
            d[0] = encode_srgb(s[0], scale);
        } else {
            for (int c = 0; c < 3; c++)
                d[c] = c < in_ch ? encode_srgb(s[c], scale) : 0;
            if (out_ch == 4)
                d[3] = encode_linear(s[3]);
        }
    }

    char *tmp = NULL;
    if ((r = fx_temp_create(ctx, path, &tmp)) != FX_OK) {
        fx_mem_free(px);
        return r;
    }
    png_job job = {path, ""};
    FILE *fp = fx_os_fopen(tmp, "wb");
    if (!fp) {
        r = fx_fail(ctx, FX_ERR_IO, "cannot write '%s': %s", path, strerror(errno));
    } else {
        int bad = encode_png(fp, &job, px, f->width, f->height, out_ch);
        if (fclose(fp) != 0 && !bad) {
            bad = 1;
            snprintf(job.message, sizeof job.message, "%s", strerror(errno));
        }
        if (bad)
            r = fx_fail(ctx, FX_ERR_IO, "cannot write '%s': %s", path, job.message[0] ? job.message : "libpng failed");
    }
    fx_mem_free(px);
    return fx_temp_commit(ctx, tmp, path, r);
}
