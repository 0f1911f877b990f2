/* bench_ssr: ssr_mirror time per quality preset and thread count on real mirror-room
 * passes, and cost against mirror area. Public API only.
 *
 *   bench_ssr PASSES.exr CAMERA.json [runs]
 *
 * PASSES.exr: a mirror-room render with Combined, Depth, Normal, IndexMA (made by
 * tests/bench/bench_ssr_render.py). One ssr_mirror entry masked by every mirror material
 * (material_index 20..30), and the same restricted to the left / right half of the
 * frame (rect_relative), for each preset and 1 and 2 threads. Prints CSV:
 * width,height,preset,threads,mask,mirror_px,median_ms,min_ms,ns_per_mirror_px */
#include "libfx/fx.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bench_util.h"

static long mirror_pixels(const fx_frame *f, const float rect[4])
{
    float *ima = NULL;
    int c = 0;
    if (fx_frame_pass(f, "IndexMA", &ima, &c) != FX_OK)
        return -1;
    int w = fx_frame_width(f), h = fx_frame_height(f);
    long n = 0;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            float fx = (x + 0.5f) / w, fy = (y + 0.5f) / h;
            if (fx < rect[0] || fx >= rect[0] + rect[2] || fy < rect[1] || fy >= rect[1] + rect[3])
                continue;
            float v = ima[(size_t)y * w + x];
            n += v >= 19.5f && v <= 30.5f;
        }
    return n;
}

int main(int argc, char **argv)
{
    if (argc < 3) {
        fprintf(stderr, "usage: bench_ssr PASSES.exr CAMERA.json [runs]\n");
        return 2;
    }
    int runs = argc > 3 ? atoi(argv[3]) : 5;
    if (runs < 1)
        runs = 1;
    const char *presets[] = { "draft", "preview", "final", "reference" };
    struct { const char *name; float r[4]; } masks[] = {
        { "all", { 0, 0, 1, 1 } }, { "left_half", { 0, 0, 0.5f, 1 } }, { "right_half", { 0.5f, 0, 0.5f, 1 } } };
    printf("width,height,preset,threads,mask,mirror_px,median_ms,min_ms,ns_per_mirror_px\n");
    for (int threads = 1; threads <= 2; threads++) {
        fx_context *ctx = NULL;
        fx_frame *f = NULL;
        if (fx_context_new(&ctx, threads) != FX_OK || fx_frame_read_exr(ctx, argv[1], NULL, &f) != FX_OK ||
            fx_frame_apply_sidecar_file(f, argv[2]) != FX_OK) {
            fprintf(stderr, "bench_ssr: %s\n", fx_context_error(ctx));
            return 1;
        }
        for (int p = 0; p < 4; p++)
            for (int m = 0; m < 3; m++) {
                char recipe[512];
                snprintf(recipe, sizeof recipe,
                         "{\"version\": 1, \"quality\": \"%s\", \"effects\": [{\"effect\": \"ssr_mirror\", "
                         "\"mask\": {\"material_index\": [20,21,22,23,24,25,26,27,28,29,30], "
                         "\"rect_relative\": [%g, %g, %g, %g]}}]}",
                         presets[p], masks[m].r[0], masks[m].r[1], masks[m].r[2], masks[m].r[3]);
                fx_stack *s = NULL;
                if (fx_stack_new(ctx, &s) != FX_OK || fx_stack_load_json(s, recipe) != FX_OK) {
                    fprintf(stderr, "bench_ssr: %s\n", fx_context_error(ctx));
                    return 1;
                }
                double *t = calloc((size_t)runs, sizeof *t);
                for (int r = 0; r <= runs; r++) {
                    fx_frame *o = NULL;
                    double t0 = now_ms();
                    if (fx_stack_run(s, f, &o) != FX_OK) {
                        fprintf(stderr, "bench_ssr: %s\n", fx_context_error(ctx));
                        return 1;
                    }
                    double dt = now_ms() - t0;
                    fx_frame_free(o);
                    if (r > 0) /* the first run warms caches and the pool */
                        t[r - 1] = dt;
                }
                qsort(t, (size_t)runs, sizeof *t, cmp_d);
                long px = mirror_pixels(f, masks[m].r);
                double med = t[runs / 2];
                printf("%d,%d,%s,%d,%s,%ld,%.3f,%.3f,%.1f\n", fx_frame_width(f), fx_frame_height(f), presets[p],
                       threads, masks[m].name, px, med, t[0], px > 0 ? med * 1e6 / px : 0.0);
                fflush(stdout);
                free(t);
                fx_stack_free(s);
            }
        fx_frame_free(f);
        fx_context_free(ctx);
    }
    return 0;
}
