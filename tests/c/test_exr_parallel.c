/* Parallel EXR decoding and encoding: the same pixels and the same file bytes for any
 * thread count, every lossless codec round-trips bit-exactly, a damaged chunk gives
 * the same message (naming the file) whatever the thread count, bad codec choices are
 * refused without leaving a file. */
#include "testutil.h"

#include "core/internal.h"
#include "io/exr_common.h"
#include "io/exr_write.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* Same passes, same channels, same bits. */
static int frames_equal(const fx_frame *a, const fx_frame *b)
{
    if (fx_frame_width(a) != fx_frame_width(b) || fx_frame_height(a) != fx_frame_height(b) ||
        fx_frame_pass_count(a) != fx_frame_pass_count(b))
        return 0;
    size_t px = (size_t)fx_frame_width(a) * (size_t)fx_frame_height(a);
    for (int i = 0; i < fx_frame_pass_count(a); i++) {
        const char *name = fx_frame_pass_name(a, i);
        float *da = NULL, *db = NULL;
        int ca = 0, cb = 0;
        if (fx_frame_pass(a, name, &da, &ca) != FX_OK || fx_frame_pass(b, name, &db, &cb) != FX_OK || ca != cb ||
            memcmp(da, db, px * (size_t)ca * sizeof(float)) != 0)
            return 0;
    }
    return 1;
}

/* Tall enough for several chunks and several write batches; odd height (last chunk
 * short), passes of 1, 3 and 4 channels, values that do not compress to nothing. */
static fx_frame *test_frame(fx_context *ctx)
{
    fx_frame *f = tu_pattern_frame(ctx, 97, 1203, 11);
    if (!f)
        return NULL;
    size_t px = 97u * 1203u;
    float *depth = malloc(px * sizeof(float)), *normal = malloc(px * 3 * sizeof(float));
    unsigned s = 12345;
    for (size_t i = 0; i < px; i++) {
        s = s * 1664525u + 1013904223u;
        depth[i] = 1.0f + (float)(s >> 8) * 1e-4f;
        for (int c = 0; c < 3; c++)
            normal[i * 3 + c] = (float)((s >> (4 * c)) & 255) / 127.5f - 1.0f;
    }
    if (fx_frame_add_pass(f, "Depth", 1, depth) != FX_OK || fx_frame_add_pass(f, "Normal", 3, normal) != FX_OK) {
        fx_frame_free(f);
        f = NULL;
    }
    free(depth);
    free(normal);
    return f;
}

/* Writing: every lossless codec, same bytes for any thread count, bit-exact back. */
static void codecs_round_trip(fx_context *const ctx[3], fx_frame *const src[3], const char *dir)
{
    static const int threads[3] = {1, 2, 3};
    static const struct {
        exr_compression_t c;
        int level;
    } codecs[] = {{EXR_COMPRESSION_NONE, 0}, {EXR_COMPRESSION_RLE, 0}, {EXR_COMPRESSION_ZIPS, 1},
                  {EXR_COMPRESSION_ZIP, 1},  {EXR_COMPRESSION_ZIP, 9}, {EXR_COMPRESSION_PIZ, 0}};
    for (size_t k = 0; k < sizeof codecs / sizeof codecs[0] && src[0] && src[1] && src[2]; k++) {
        char *bytes[3] = {NULL, NULL, NULL};
        size_t len[3] = {0, 0, 0};
        for (int t = 0; t < 3; t++) {
            char path[700];
            snprintf(path, sizeof path, "%s/codec%zu_t%d.exr", dir, k, threads[t]);
            fx_exr_write_params p = fx_exr_write_defaults();
            p.compression = codecs[k].c;
            p.zip_level = codecs[k].level;
            fx_write_options wo = {sizeof wo, 0, 0, NULL, NULL};
            CHECK_OK(ctx[t], fx_exr_write(src[t], path, &wo, &p));
            bytes[t] = tu_slurp(path, &len[t]);
            fx_frame *back = NULL;
            CHECK_OK(ctx[t], fx_frame_read_exr(ctx[t], path, NULL, &back));
            CHECK(back && frames_equal(src[t], back));
            if (back && !frames_equal(src[t], back))
                fprintf(stderr, "codec %s: round trip differs (%d threads)\n",
                        fx_exr_compression_name(codecs[k].c), threads[t]);
            fx_frame_free(back);
        }
        CHECK(bytes[0] && bytes[1] && bytes[2]);
        CHECK(len[0] == len[1] && len[0] == len[2]);
        CHECK(bytes[0] && bytes[1] && bytes[2] && len[0] == len[1] && len[0] == len[2] &&
              memcmp(bytes[0], bytes[1], len[0]) == 0 && memcmp(bytes[0], bytes[2], len[0]) == 0);
        for (int t = 0; t < 3; t++)
            free(bytes[t]);
    }
}

/* A file of one one-channel pass (a light view's Depth), uncompressed, with its data window
 * off the origin: its rows are read straight into the pass (raw_chunk), the same bits for
 * 1, 2 and 3 threads. */
static void depth_only_raw(fx_context *const ctx[3], const char *dir)
{
    const int w = 53, h = 41;
    float *depth = malloc((size_t)w * h * sizeof(float));
    for (int i = 0; i < w * h; i++)
        depth[i] = 0.5f + (float)i * 0.25f;
    for (int t = 0; t < 3; t++) {
        fx_frame *f = NULL, *back = NULL;
        CHECK_OK(ctx[t], fx_frame_new(ctx[t], w, h, &f));
        CHECK_OK(ctx[t], fx_frame_add_pass(f, "Depth", 1, depth));
        const int dw[4] = {7, 5, 7 + w - 1, 5 + h - 1}, disp[4] = {0, 0, 79, 59};
        CHECK_OK(ctx[t], fx_frame_set_windows(f, dw, disp));
        char path[700];
        snprintf(path, sizeof path, "%s/depth_raw_t%d.exr", dir, t);
        fx_exr_write_params p = fx_exr_write_defaults();
        p.compression = EXR_COMPRESSION_NONE;
        fx_write_options wo = {sizeof wo, 0, 0, NULL, NULL};
        CHECK_OK(ctx[t], fx_exr_write(f, path, &wo, &p));
        CHECK_OK(ctx[t], fx_frame_read_exr(ctx[t], path, NULL, &back));
        CHECK(back && frames_equal(f, back));
        fx_frame_free(back);
        fx_frame_free(f);
    }
    free(depth);
}

/* A damaged chunk in the middle of the file: the same error, naming the file and the
 * chunk, for 1, 2 and 3 threads (the lowest failing chunk wins). */
static void damaged_chunk(fx_context *const ctx[3], fx_frame *const src[3], const char *dir)
{
    if (src[0]) {
        char good[700], bad[700];
        snprintf(good, sizeof good, "%s/good.exr", dir);
        snprintf(bad, sizeof bad, "%s/bad.exr", dir);
        CHECK_OK(ctx[0], fx_frame_write_exr(src[0], good, NULL));
        size_t len = 0;
        char *b = tu_slurp(good, &len);
        CHECK(b && len > 4096);
        if (b && len > 4096) {
            /* garbage over the compressed data of a few chunks past the middle */
            for (size_t i = len / 2; i < len / 2 + 2000; i++)
                b[i] = (char)(i * 7919u >> 3);
            FILE *fp = fopen(bad, "wb");
            CHECK(fp && fwrite(b, 1, len, fp) == len);
            if (fp)
                fclose(fp);
            char msg[3][1024];
            for (int t = 0; t < 3; t++) {
                fx_frame *f = NULL;
                fx_result r = fx_frame_read_exr(ctx[t], bad, NULL, &f);
                CHECK(r == FX_ERR_BAD_FILE && f == NULL);
                snprintf(msg[t], sizeof msg[t], "%s", fx_context_error(ctx[t]));
                CHECK(tu_contains(msg[t], "bad.exr") && tu_contains(msg[t], "scanlines from"));
            }
            CHECK(strcmp(msg[0], msg[1]) == 0 && strcmp(msg[0], msg[2]) == 0);
            if (strcmp(msg[0], msg[1]) || strcmp(msg[0], msg[2]))
                fprintf(stderr, "messages differ:\n  %s\n  %s\n  %s\n", msg[0], msg[1], msg[2]);
        }
        free(b);
    }
}

int main(void)
{
    const char *data = getenv("LIBFX_TEST_DATA");
    char blender[1200];
    snprintf(blender, sizeof blender, "%s/blender/render_multilayer.exr", data ? data : "tests/data");
    const char *dir = tu_tmpdir("exr_parallel");
    static const int threads[3] = {1, 2, 3};
    fx_context *ctx[3];
    for (int t = 0; t < 3; t++)
        if (fx_context_new(&ctx[t], threads[t]) != FX_OK)
            return 1;

    /* Reading: a Blender render decodes to the same bits with 1, 2 and 3 threads. */
    fx_frame *rd[3] = {NULL, NULL, NULL};
    for (int t = 0; t < 3; t++)
        CHECK_OK(ctx[t], fx_frame_read_exr(ctx[t], blender, NULL, &rd[t]));
    CHECK(rd[0] && rd[1] && rd[2] && frames_equal(rd[0], rd[1]) && frames_equal(rd[0], rd[2]));
    for (int t = 0; t < 3; t++)
        fx_frame_free(rd[t]);

    fx_frame *src[3];
    for (int t = 0; t < 3; t++)
        src[t] = test_frame(ctx[t]);
    CHECK(src[0] && src[1] && src[2]);
    codecs_round_trip(ctx, src, dir);
    depth_only_raw(ctx, dir);

    /* The default is ZIP at FX_EXR_DEFAULT_ZIP_LEVEL: the same bytes as asking for it. */
    if (src[1]) {
        char a[700], b[700];
        snprintf(a, sizeof a, "%s/default.exr", dir);
        snprintf(b, sizeof b, "%s/explicit.exr", dir);
        fx_exr_write_params p = {EXR_COMPRESSION_ZIP, FX_EXR_DEFAULT_ZIP_LEVEL};
        CHECK_OK(ctx[1], fx_frame_write_exr(src[1], a, NULL));
        CHECK_OK(ctx[1], fx_exr_write(src[1], b, NULL, &p));
        size_t la = 0, lb = 0;
        char *ba = tu_slurp(a, &la), *bb = tu_slurp(b, &lb);
        CHECK(ba && bb && la == lb && memcmp(ba, bb, la) == 0);
        free(ba);
        free(bb);
    }

    /* Refused choices: lossy or unknown codecs, ZIP levels outside 1..9; no file left. */
    if (src[1]) {
        char path[700];
        snprintf(path, sizeof path, "%s/refused.exr", dir);
        fx_exr_write_params p = {EXR_COMPRESSION_DWAA, 1};
        CHECK_FAIL(ctx[1], fx_exr_write(src[1], path, NULL, &p), FX_ERR_INVALID_ARGUMENT, "dwaa");
        p.compression = EXR_COMPRESSION_ZIP, p.zip_level = 0;
        CHECK_FAIL(ctx[1], fx_exr_write(src[1], path, NULL, &p), FX_ERR_INVALID_ARGUMENT, "level 0");
        p.zip_level = 10;
        CHECK_FAIL(ctx[1], fx_exr_write(src[1], path, NULL, &p), FX_ERR_INVALID_ARGUMENT, "level 10");
        CHECK(access(path, F_OK) != 0);
    }

    damaged_chunk(ctx, src, dir);

    for (int t = 0; t < 3; t++) {
        fx_frame_free(src[t]);
        fx_context_free(ctx[t]);
    }
    return tu_finish("test_exr_parallel");
}
