/* Files made at run time with oiiotool (a build dependency) from a file libfx writes:
 * DWAA/DWAB (OpenEXRCore 3.1.5 cannot decode them, libfx reads them through OpenEXR's
 * C++ reader and warns that data passes are lossy), and tiled/mipmapped copies of a
 * file whose data window is off the origin (tile coordinates start at its corner).
 *
 * Three CTest steps share DIR (tests/c/CMakeLists.txt): `test_exr_dwa write DIR` writes
 * src.exr, tests/c/exr_dwa_convert.sh DIR runs oiiotool on the host, `test_exr_dwa check
 * DIR` reads the copies. Split so that a cross-built test (Windows, under Wine, which
 * cannot run the host's oiiotool) is checked against the same host-made files. */
#include "testutil.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int warned(fx_context *ctx, const char *needle)
{
    for (int i = 0; i < fx_context_warning_count(ctx); i++)
        if (tu_contains(fx_context_warning(ctx, i), needle))
            return 1;
    return 0;
}

int main(int argc, char **argv)
{
    if (argc != 3 || (strcmp(argv[1], "write") != 0 && strcmp(argv[1], "check") != 0)) {
        fprintf(stderr, "usage: test_exr_dwa write|check DIR\n");
        return 2;
    }
    const int write_only = strcmp(argv[1], "write") == 0;
    fx_context *ctx = NULL;
    if (fx_context_new(&ctx, 2) != FX_OK)
        return 1;
    char dir[512], src[600];
    snprintf(dir, sizeof dir, "%s", argv[2]);
    snprintf(src, sizeof src, "%s/src.exr", dir);

    int w = 96, h = 40;
    fx_frame *f = tu_pattern_frame(ctx, w, h, 3);
    float *depth = malloc((size_t)w * h * sizeof *depth);
    for (int i = 0; i < w * h; i++)
        depth[i] = 2.0f + 0.01f * (float)(i % w);
    CHECK_OK(ctx, fx_frame_add_pass(f, "Depth", 1, depth));
    int dw[4] = {10, -3, 10 + w - 1, -3 + h - 1}, disp[4] = {0, 0, 119, 49};
    CHECK_OK(ctx, fx_frame_set_windows(f, dw, disp));
    if (write_only) {
        fx_write_options wo = {sizeof wo, 0, 0, NULL, NULL};
        remove(src);
        CHECK_OK(ctx, fx_frame_write_exr(f, src, &wo));
        free(depth);
        fx_frame_free(f);
        fx_context_free(ctx);
        return tu_finish("test_exr_dwa write");
    }

    const char *codecs[2] = {"dwaa", "dwab"};
    for (int k = 0; k < 2; k++) {
        char dst[700];
        snprintf(dst, sizeof dst, "%s/x_%s.exr", dir, codecs[k]);
        CHECK(tu_file_exists(dst)); /* made by exr_dwa_convert.sh */
        char *info = NULL;
        CHECK_OK(ctx, fx_exr_info_json(ctx, dst, &info));
        CHECK(tu_contains(info, codecs[k]));
        fx_free(info);

        fx_context_clear_warnings(ctx);
        fx_frame *g = NULL;
        CHECK_OK(ctx, fx_frame_read_exr(ctx, dst, NULL, &g));
        CHECK(warned(ctx, "is DWA-compressed: lossy, data passes (Depth/Normal/Position) are approximate"));
        CHECK(warned(ctx, dst));
        if (!g)
            continue;
        int gdw[4], gdisp[4];
        fx_frame_windows(g, gdw, gdisp);
        CHECK(memcmp(gdw, dw, sizeof dw) == 0 && memcmp(gdisp, disp, sizeof disp) == 0);
        float *a = NULL, *b = NULL;
        int ca = 0, cb = 0;
        CHECK_OK(ctx, fx_frame_pass(f, "Combined", &a, &ca));
        CHECK_OK(ctx, fx_frame_pass(g, "Combined", &b, &cb));
        CHECK(ca == 4 && cb == 4);
        if (a && b) {
            double err = tu_max_abs_diff(a, b, (size_t)w * h * 4);
            CHECK(err < 0.1); /* lossy but close; alpha exact */
            CHECK(b[3] == 1.0f);
        }
        CHECK_OK(ctx, fx_frame_pass(g, "Depth", &b, &cb));
        if (b)
            CHECK(tu_max_abs_diff(depth, b, (size_t)w * h) < 0.05);
        fx_frame_free(g);
    }

    /* a stack-limited read of a DWA file decodes Combined only */
    fx_stack *s = NULL;
    CHECK_OK(ctx, fx_stack_new(ctx, &s));
    fx_read_options ro = {sizeof ro, NULL, NULL, s};
    char dst[700];
    snprintf(dst, sizeof dst, "%s/x_dwaa.exr", dir);
    fx_frame *g = NULL;
    CHECK_OK(ctx, fx_frame_read_exr(ctx, dst, &ro, &g));
    CHECK(g && fx_frame_pass_count(g) == 1);
    fx_frame_free(g);
    fx_stack_free(s);

    /* tiled and mipmapped, data window at (10, -3): same pixels as the scanline source */
    /* tiled1: -otex's mipmapped tiled texture, padded out to the display window */
    for (int k = 0; k < 2; k++) {
        char dst2[700];
        snprintf(dst2, sizeof dst2, "%s/tiled%d.exr", dir, k);
        CHECK(tu_file_exists(dst2));
        fx_frame *t = NULL;
        CHECK_OK(ctx, fx_frame_read_exr(ctx, dst2, NULL, &t));
        if (!t)
            continue;
        int tdw[4], tdisp[4];
        fx_frame_windows(t, tdw, tdisp);
        CHECK(k == 1 || memcmp(tdw, dw, sizeof dw) == 0);
        CHECK(tdw[0] <= dw[0] && tdw[1] <= dw[1] && tdw[2] >= dw[2] && tdw[3] >= dw[3]);
        float *a = NULL, *b = NULL, *tz = NULL;
        int ca = 0, cb = 0, cz = 0;
        CHECK_OK(ctx, fx_frame_pass(f, "Combined", &a, &ca));
        CHECK_OK(ctx, fx_frame_pass(t, "Combined", &b, &cb));
        CHECK_OK(ctx, fx_frame_pass(t, "Depth", &tz, &cz));
        int tw = fx_frame_width(t), diff = 0;
        for (int y = 0; a && b && tz && y < h; y++)
            for (int x = 0; x < w; x++) {
                size_t ti = (size_t)(y + dw[1] - tdw[1]) * tw + (size_t)(x + dw[0] - tdw[0]);
                diff += memcmp(&a[((size_t)y * w + x) * 4], &b[ti * 4], 4 * sizeof(float)) != 0;
                diff += depth[(size_t)y * w + x] != tz[ti];
            }
        CHECK(a && b && tz && diff == 0);
        fx_frame_free(t);
    }

    free(depth);
    fx_frame_free(f);
    fx_context_free(ctx);
    return tu_finish("test_exr_dwa");
}
