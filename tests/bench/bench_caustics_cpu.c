/* bench_caustics_cpu: one recipe on one frame, timed by wall clock AND by process CPU time
 * (the sum over threads: less sensitive to other processes on a shared machine than the
 * wall clock). The first run (the first frame of the process) is reported apart.
 *   bench_caustics_cpu PASSES.exr SIDECAR.json RECIPE.json QUALITY THREADS RUNS
 * Built with the other bench tools: build/tests/bench/bench_caustics_cpu. */
#define _POSIX_C_SOURCE 200809L
#include "bench_util.h"
#include "libfx/fx.h"

#include <stdio.h>
#include <stdlib.h>
#include <time.h>

int main(int argc, char **argv)
{
    if (argc < 7) {
        fprintf(stderr, "usage: %s PASSES.exr SIDECAR.json RECIPE.json QUALITY THREADS RUNS\n", argv[0]);
        return 2;
    }
    int threads = atoi(argv[5]), runs = atoi(argv[6]);
    if (runs < 1 || runs > 100)
        runs = 9;
    fx_context *ctx = NULL;
    fx_stack *s = NULL;
    fx_frame *f = NULL;
    if (fx_context_new(&ctx, threads) || fx_stack_new(ctx, &s) || fx_stack_load_file(s, argv[3]) ||
        fx_stack_set_quality(s, fx_quality_from_name(argv[4])) || fx_frame_read_exr(ctx, argv[1], NULL, &f) ||
        fx_frame_apply_sidecar_file(f, argv[2])) {
        fprintf(stderr, "setup failed: %s\n", ctx ? fx_context_error(ctx) : "no context");
        return 1;
    }
    double wall[100], cpu[100];
    for (int r = 0; r <= runs; r++) {
        fx_frame *out = NULL;
        double w0 = clock_ms(CLOCK_MONOTONIC), c0 = clock_ms(CLOCK_PROCESS_CPUTIME_ID);
        if (fx_stack_run(s, f, &out)) {
            fprintf(stderr, "run failed: %s\n", fx_context_error(ctx));
            return 1;
        }
        double w1 = clock_ms(CLOCK_MONOTONIC), c1 = clock_ms(CLOCK_PROCESS_CPUTIME_ID);
        fx_frame_free(out);
        if (r == 0)
            printf("first: wall %.1f ms, cpu %.1f ms\n", w1 - w0, c1 - c0);
        else
            wall[r - 1] = w1 - w0, cpu[r - 1] = c1 - c0;
    }
    qsort(wall, runs, sizeof(double), cmp_d);
    qsort(cpu, runs, sizeof(double), cmp_d);
    printf("warm median of %d: wall %.1f ms (min %.1f), cpu %.1f ms (min %.1f)\n", runs, wall[runs / 2], wall[0],
           cpu[runs / 2], cpu[0]);
    fx_frame_free(f);
    fx_stack_free(s);
    fx_context_free(ctx);
    return 0;
}
