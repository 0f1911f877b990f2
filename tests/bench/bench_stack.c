/* The whole stack's cost for per-pixel effects against the memory-bandwidth floor:
 * fx_stack_run (effect + the stack's copy/guard/composite) vs memcpy of the same bytes,
 * at 1920x1080 RGBA float, medians, in one run.
 *   bench_stack [threads] [runs] */
#include "libfx/fx.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bench_util.h"

int main(int argc, char **argv)
{
    int threads = argc > 1 ? atoi(argv[1]) : 2;
    int runs = argc > 2 ? atoi(argv[2]) : 15;
    if (runs < 1 || runs > 64)
        runs = 15;
    const int W = 1920, H = 1080;
    fx_context *ctx = NULL;
    fx_frame *f = NULL;
    if (fx_context_new(&ctx, threads) || fx_frame_new(ctx, W, H, &f))
        return 1;
    size_t n = (size_t)W * H * 4;
    float *px = malloc(n * sizeof(float)), *dst = malloc(n * sizeof(float));
    if (!px || !dst)
        return 1;
    for (size_t i = 0; i < n; i++)
        px[i] = (float)(i % 977) / 977.0f;
    memcpy(dst, px, n * sizeof(float));
    fx_frame_add_pass(f, "Combined", 4, px);
    static const char *const recipes[][2] = {
        {"empty stack (copy)", "{\"version\":1,\"effects\":[]}"},
        {"color_matrix sepia", "{\"version\":1,\"effects\":[{\"effect\":\"color_matrix\",\"params\":{\"operator\":\"sepia\"}}]}"},
        {"posterize 4 levels", "{\"version\":1,\"effects\":[{\"effect\":\"posterize\"}]}"},
        {"sin_city", "{\"version\":1,\"effects\":[{\"effect\":\"sin_city\"}]}"},
    };
    printf("| effect (1920x1080, %d thread%s) | memcpy ms | stack run ms | x memcpy |\n|---|---:|---:|---:|\n",
           threads, threads == 1 ? "" : "s");
    for (size_t k = 0; k < sizeof recipes / sizeof recipes[0]; k++) {
        fx_stack *s = NULL;
        if (fx_stack_new(ctx, &s) || fx_stack_load_json(s, recipes[k][1])) {
            fprintf(stderr, "%s\n", fx_context_error(ctx));
            return 1;
        }
        double tc[64], ts[64];
        for (int r = 0; r < runs; r++) {
            double t0 = now_ms();
            memcpy(dst, px, n * sizeof(float));
            tc[r] = now_ms() - t0;
            fx_frame *o = NULL;
            t0 = now_ms();
            if (fx_stack_run(s, f, &o))
                return 1;
            ts[r] = now_ms() - t0;
            fx_frame_free(o);
        }
        qsort(tc, (size_t)runs, sizeof *tc, cmp_d);
        qsort(ts, (size_t)runs, sizeof *ts, cmp_d);
        printf("| %s | %.2f | %.2f | %.2f |\n", recipes[k][0], tc[runs / 2], ts[runs / 2], ts[runs / 2] / tc[runs / 2]);
        fx_stack_free(s);
    }
    free(px);
    free(dst);
    fx_frame_free(f);
    fx_context_free(ctx);
    return 0;
}
