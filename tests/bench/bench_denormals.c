/* bench_denormals: an input full of denormals must run within 2x of a normal one (issue 8).
 * Per effect: median wall time of a run on a 1280x720 frame whose every value (Combined,
 * Depth, Normal, Position, DiffDir/DiffCol) is a denormal (|x| in [1e-42, 1e-38]) against
 * the same effect on ordinary values, with 1 and 2 threads; prints a Markdown table
 * (docs/performance.md, "Denormal inputs").   bench_denormals [runs=7] */
#include "libfx/fx.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bench_util.h"

static float value(uint32_t i, int denormal)
{
    uint32_t h = i * 2654435761u;
    h ^= h >> 15;
    float u = (float)(h & 0xffffff) / 16777216.0f;
    if (denormal) /* 1e-42 .. 1e-38, both signs */
        return (h & 0x1000000 ? -1.0f : 1.0f) * powf(10.0f, -42.0f + 4.0f * u);
    return 0.05f + 0.95f * u;
}

static fx_frame *make(fx_context *ctx, int w, int h, int denormal)
{
    static const struct { const char *name; int ch; } passes[] = {
        {"Combined", 4}, {"Depth", 1}, {"Normal", 3}, {"Position", 3}, {"DiffDir", 3}, {"DiffCol", 3}};
    fx_frame *f = NULL;
    fx_frame_new(ctx, w, h, &f);
    size_t n = (size_t)w * h;
    float *buf = malloc(n * 4 * sizeof(float));
    for (int p = 0; p < 6; p++) {
        for (size_t i = 0; i < n * passes[p].ch; i++)
            buf[i] = value((uint32_t)(i + p * 7919), denormal);
        if (!denormal && p == 1)
            for (size_t i = 0; i < n; i++)
                buf[i] = 1.0f + 10.0f * buf[i];
        fx_frame_add_pass(f, passes[p].name, passes[p].ch, buf);
    }
    free(buf);
    return f;
}

static const struct { const char *label, *recipe; } cases[] = {
    {"gaussian_blur final (recursive IIR), sigma 8",
     "{\"version\":1,\"quality\":\"final\",\"effects\":[{\"effect\":\"gaussian_blur\",\"params\":{\"sigma\":8}}]}"},
    {"gaussian_blur draft (box), sigma 8",
     "{\"version\":1,\"quality\":\"draft\",\"effects\":[{\"effect\":\"gaussian_blur\",\"params\":{\"sigma\":8}}]}"},
    {"bloom (final)", "{\"version\":1,\"effects\":[{\"effect\":\"bloom\",\"params\":{\"threshold\":0}}]}"},
    {"color_matrix sepia", "{\"version\":1,\"effects\":[{\"effect\":\"color_matrix\",\"params\":{\"operator\":\"sepia\"}}]}"},
    {"edges (luminance, depth, normal)",
     "{\"version\":1,\"effects\":[{\"effect\":\"edges\",\"params\":{\"depth\":true,\"normal\":true}}]}"},
    {"posterize (dither)", "{\"version\":1,\"effects\":[{\"effect\":\"posterize\",\"params\":{\"dither\":1}}]}"},
    {"cel_shading (diffuse passes)", "{\"version\":1,\"effects\":[{\"effect\":\"cel_shading\"}]}"},
    {"voronoi_caustics", "{\"version\":1,\"effects\":[{\"effect\":\"voronoi_caustics\"}]}"},
};

int main(int argc, char **argv)
{
    int runs = argc > 1 ? atoi(argv[1]) : 7;
    if (runs < 1)
        runs = 1;
    const int W = 1280, H = 720;
    printf("| effect (1280x720) | threads | normal ms | denormal ms | ratio |\n|---|---|---|---|---|\n");
    for (int threads = 1; threads <= 2; threads++) {
        fx_context *ctx = NULL;
        fx_context_new(&ctx, threads);
        fx_frame *fr[2] = {make(ctx, W, H, 0), make(ctx, W, H, 1)};
        for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
            fx_stack *s = NULL;
            fx_stack_new(ctx, &s);
            if (fx_stack_load_json(s, cases[c].recipe) != FX_OK) {
                fprintf(stderr, "%s: %s\n", cases[c].label, fx_context_error(ctx));
                fx_stack_free(s);
                continue;
            }
            double med[2];
            double *t = malloc(sizeof(double) * runs * 2);
            /* interleaved: normal, denormal, normal, ... so drift hits both alike */
            for (int r = 0; r < runs + 1; r++)
                for (int k = 0; k < 2; k++) {
                    fx_frame *out = NULL;
                    double t0 = now_ms();
                    fx_result res = fx_stack_run(s, fr[k], &out);
                    double dt = now_ms() - t0;
                    if (res != FX_OK)
                        fprintf(stderr, "%s: %s\n", cases[c].label, fx_context_error(ctx));
                    fx_frame_free(out);
                    if (r > 0) /* the first round warms up */
                        t[k * runs + r - 1] = dt;
                }
            for (int k = 0; k < 2; k++) {
                qsort(t + k * runs, runs, sizeof(double), cmp_d);
                med[k] = t[k * runs + runs / 2];
            }
            free(t);
            printf("| %s | %d | %.2f | %.2f | %.2f |\n", cases[c].label, threads, med[0], med[1], med[1] / med[0]);
            fflush(stdout);
            fx_stack_free(s);
        }
        fx_frame_free(fr[0]);
        fx_frame_free(fr[1]);
        fx_context_free(ctx);
    }
    return 0;
}
