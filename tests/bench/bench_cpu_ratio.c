/* bench_cpu_ratio: one-effect recipes against a parallel copy of the frame's RGBA floats on the
 * same pool, interleaved run by run, in wall time and in process CPU time.
 *
 *   bench_cpu_ratio PASSES.exr RUNS THREADS RECIPE.json [RECIPE.json ...]
 *
 * Each run times the copy, then fx_stack_run of each recipe (not in place: the stack writes a
 * pooled buffer, as bench_presets does). Per recipe: the median and minimum wall ms, the median
 * and minimum CPU ms (CLOCK_PROCESS_CPUTIME_ID: all threads' time, which other processes on a shared
 * machine disturb far less than wall time) and both medians' ratios to the copy's. The CPU
 * ratio is the load-independent one when the machine is busy (issue 16: per-pixel effects
 * within 2x of a copy). Two warm-up runs first. */
#include "bench_util.h"
#include "core/parallel.h"
#include "libfx/fx.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define MAX_RECIPES 16

int main(int argc, char **argv)
{
    if (argc < 5) {
        fprintf(stderr, "usage: bench_cpu_ratio PASSES.exr RUNS THREADS RECIPE.json [RECIPE.json ...]\n");
        return 2;
    }
    const int runs = atoi(argv[2]) > 0 ? atoi(argv[2]) : 9, threads = atoi(argv[3]);
    const int ne = argc - 4 < MAX_RECIPES ? argc - 4 : MAX_RECIPES;
    fx_context *ctx = NULL;
    fx_frame *f = NULL;
    if (fx_context_new(&ctx, threads) || fx_frame_read_exr(ctx, argv[1], NULL, &f)) {
        fprintf(stderr, "bench_cpu_ratio: %s\n", ctx ? fx_context_error(ctx) : "no context");
        return 1;
    }
    fx_stack *st[MAX_RECIPES] = { 0 };
    for (int e = 0; e < ne; e++) {
        char *json = bench_slurp(argv[4 + e]);
        if (!json || fx_stack_new(ctx, &st[e]) || fx_stack_load_json(st[e], json)) {
            fprintf(stderr, "bench_cpu_ratio: %s: %s\n", argv[4 + e], json ? fx_context_error(ctx) : "unreadable");
            return 1;
        }
        free(json);
    }
    const int w = fx_frame_width(f), h = fx_frame_height(f);
    const size_t n = (size_t)w * h * 4;
    float *a = malloc(n * sizeof(float)), *b = malloc(n * sizeof(float));
    double *wall = calloc((size_t)(ne + 1) * runs, sizeof(double)), *cpu = calloc((size_t)(ne + 1) * runs, sizeof(double));
    if (!a || !b || !wall || !cpu)
        return 1;
    memset(a, 0, n * sizeof(float));
    memset(b, 0, n * sizeof(float));
    bench_copy_job cj = { a, b, w };
    for (int r = -2; r < runs; r++) {
        for (int e = -1; e < ne; e++) {
            double t0 = clock_ms(CLOCK_MONOTONIC), c0 = clock_ms(CLOCK_PROCESS_CPUTIME_ID);
            fx_frame *o = NULL;
            if (e < 0)
                fx_parallel_for(ctx, h, fx_grain_for(ctx, h), bench_copy_rows, &cj);
            else if (fx_stack_run(st[e], f, &o)) {
                fprintf(stderr, "bench_cpu_ratio: %s: %s\n", argv[4 + e], fx_context_error(ctx));
                return 1;
            }
            double t1 = clock_ms(CLOCK_MONOTONIC), c1 = clock_ms(CLOCK_PROCESS_CPUTIME_ID);
            fx_frame_free(o);
            if (r >= 0) {
                wall[(size_t)(e + 1) * runs + r] = t1 - t0;
                cpu[(size_t)(e + 1) * runs + r] = c1 - c0;
            }
        }
    }
    printf("recipe,width,height,threads,runs,wall_ms_median,wall_ms_min,cpu_ms_median,cpu_ms_min,wall_ratio,cpu_ratio\n");
    double copy_wall = 0, copy_cpu = 0;
    for (int e = -1; e < ne; e++) {
        double *wv = wall + (size_t)(e + 1) * runs, *cv = cpu + (size_t)(e + 1) * runs;
        double wm = median_d(wv, runs), wmin = wv[0], cm = median_d(cv, runs), cmin = cv[0];
        if (e < 0) {
            copy_wall = wm;
            copy_cpu = cm;
        }
        printf("%s,%d,%d,%d,%d,%.3f,%.3f,%.3f,%.3f,%.2f,%.2f\n", e < 0 ? "copy" : argv[4 + e], w, h, threads, runs,
               wm, wmin, cm, cmin, wm / copy_wall, cm / copy_cpu);
    }
    for (int e = 0; e < ne; e++)
        fx_stack_free(st[e]);
    fx_frame_free(f);
    fx_context_free(ctx);
    free(a);
    free(b);
    free(wall);
    free(cpu);
    return 0;
}
