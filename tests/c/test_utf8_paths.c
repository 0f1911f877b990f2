/* File names are UTF-8 everywhere: an EXR, a PNG and a recipe in a folder whose name and
 * files are outside ASCII (and outside any single ANSI code page) are written, read,
 * replaced and refused like any other. On Windows this goes through the wide ("W") APIs
 * (core/platform.c); there the C runtime's narrow fopen would not find these files. */
#include "testutil.h"
#include "testos.h"
#include "core/platform.h"

#include <stdio.h>
#include <string.h>

static int same_combined(fx_context *ctx, const fx_frame *a, const fx_frame *b)
{
    float *pa = NULL, *pb = NULL;
    int ca = 0, cb = 0;
    if (fx_frame_pass(a, "Combined", &pa, &ca) != FX_OK || fx_frame_pass(b, "Combined", &pb, &cb) != FX_OK)
        return 0;
    (void)ctx;
    size_t n = (size_t)fx_frame_width(a) * (size_t)fx_frame_height(a) * 4;
    return ca == 4 && cb == 4 && fx_frame_width(a) == fx_frame_width(b) &&
           fx_frame_height(a) == fx_frame_height(b) && memcmp(pa, pb, n * sizeof(float)) == 0;
}

int main(void)
{
    fx_context *ctx = NULL;
    if (fx_context_new(&ctx, 2) != FX_OK)
        return 1;
    /* Latin, Greek, CJK and an emoji (outside the BMP: a UTF-16 surrogate pair) */
    char dir[700], exr[800], png[800], recipe[800];
    snprintf(dir, sizeof dir, "%s/d\xc3\xa9j\xc3\xa0-\xce\xb1\xce\xb2-\xe6\x97\xa5\xe6\x9c\xac", tu_tmpdir("utf8_paths"));
    CHECK(tu_mkdir(dir, 0700) == 0);
    snprintf(exr, sizeof exr, "%s/pl\xc3\xa4n-\xe2\x82\xac-\xf0\x9f\x8e\xac.exr", dir);
    snprintf(png, sizeof png, "%s/aper\xc3\xa7u.png", dir);
    snprintf(recipe, sizeof recipe, "%s/r\xc3\xa9glage.json", dir);

    fx_frame *f = tu_pattern_frame(ctx, 16, 8, 4);
    fx_write_options wo = {sizeof wo, 0, 0, NULL, NULL};
    CHECK_OK(ctx, fx_frame_write_exr(f, exr, &wo));
    CHECK(tu_file_exists(exr));

    fx_frame *g = NULL;
    CHECK_OK(ctx, fx_frame_read_exr(ctx, exr, NULL, &g));
    CHECK(g && same_combined(ctx, f, g));
    char *info = NULL;
    CHECK_OK(ctx, fx_exr_info_json(ctx, exr, &info));
    fx_free(info);

    /* written again over itself from another frame: the old file is replaced */
    fx_frame *h = tu_pattern_frame(ctx, 16, 8, 5);
    CHECK_OK(ctx, fx_frame_write_exr(h, exr, &wo));
    fx_frame_free(g);
    g = NULL;
    CHECK_OK(ctx, fx_frame_read_exr(ctx, exr, NULL, &g));
    CHECK(g && same_combined(ctx, h, g));

    /* the input named as output: refused, the file unchanged */
    fx_write_options same = {sizeof same, 0, 0, exr, NULL};
    CHECK_FAIL(ctx, fx_frame_write_exr(f, exr, &same), FX_ERR_INVALID_ARGUMENT, "refusing to overwrite");
    fx_frame_free(g);
    g = NULL;
    CHECK_OK(ctx, fx_frame_read_exr(ctx, exr, NULL, &g));
    CHECK(g && same_combined(ctx, h, g));

    CHECK_OK(ctx, fx_frame_write_png(f, png, NULL, 0));
    CHECK(tu_file_exists(png));

    /* a recipe read from a file, and a missing file's error naming it */
    FILE *fp = fx_os_fopen(recipe, "wb");
    CHECK(fp != NULL);
    if (fp) {
        fputs("{\"version\": 1, \"effects\": [{\"effect\": \"pixelate\"}]}", fp);
        fclose(fp);
    }
    fx_stack *s = NULL;
    CHECK_OK(ctx, fx_stack_new(ctx, &s));
    CHECK_OK(ctx, fx_stack_load_file(s, recipe));
    fx_stack_free(s);
    char missing[900];
    snprintf(missing, sizeof missing, "%s/\xc3\xb8.exr", dir);
    fx_frame *m = NULL;
    CHECK_FAIL(ctx, fx_frame_read_exr(ctx, missing, NULL, &m), FX_ERR_IO, missing);

    fx_frame_free(g);
    fx_frame_free(h);
    fx_frame_free(f);
    fx_context_free(ctx);
    return tu_finish("test_utf8_paths");
}
