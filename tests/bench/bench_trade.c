/* bench_trade: presets of a one-effect recipe timed interleaved (wall and process CPU per
 * fx_stack_run), with callgrind marks around each run (valgrind's header: scripts/setup.sh
 * installs it). Built with the other bench tools (build/tests/bench/bench_trade):
 *
 *   bench_trade PASSES.exr SIDECAR.json RECIPE.json THREADS ROUNDS CACHE OUTDIR q1 [q2 ...]
 *
 * CACHE 0: the context's aux cache off (light views / rain map read and built every run,
 * as bench_presets does), 1: on (frames 2..N; one warm-up run per preset fills it).
 * OUTDIR (or -): each preset's output EXR from the warm-up run. Per preset it prints every
 * round's wall and CPU ms and their medians. Instruction counts, load-independent:
 *
 *   valgrind --tool=callgrind --callgrind-out-file=cg.%p.out bench_trade ... 1 1 CACHE - draft final
 *
 * writes one dump per timed run (cg.PID.out.1, .2, ...: "Trigger: Client Request: <preset>"),
 * whose `totals:` line is that run's instruction count. Used for docs/effects/bloom.md,
 * vsm_shadows.md, wet_surfaces.md (issue 16). */
#include "bench_util.h"
#include "libfx/fx.h"
#include <valgrind/callgrind.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static void die(const char *w, fx_context *c)
{
    fprintf(stderr, "%s: %s\n", w, c ? fx_context_error(c) : "");
    exit(1);
}

int main(int argc, char **argv)
{
    if (argc < 9)
        return 2;
    int threads = atoi(argv[4]), rounds = atoi(argv[5]), cache = atoi(argv[6]);
    const char *outdir = argv[7];
    int nq = argc - 8;
    fx_context *ctx;
    if (fx_context_new(&ctx, threads))
        die("ctx", NULL);
    if (!cache)
        fx_context_set_aux_cache(ctx, 0);
    fx_frame *f;
    if (fx_frame_read_exr(ctx, argv[1], NULL, &f))
        die("read", ctx);
    if (fx_frame_apply_sidecar_file(f, argv[2]))
        die("sidecar", ctx);
    fx_stack *s[8];
    for (int q = 0; q < nq; q++) {
        fx_stack_new(ctx, &s[q]);
        if (fx_stack_load_file(s[q], argv[3]))
            die("recipe", ctx);
        if (fx_stack_set_quality(s[q], fx_quality_from_name(argv[8 + q])))
            die("quality", ctx);
    }
    if (rounds < 1 || rounds > 64 || nq > 8)
        return 2;
    double wall[8][64], cpu[8][64];
    for (int q = 0; q < nq; q++) { /* warm-up (fills the cache when on), writes outputs */
        fx_frame *o;
        if (fx_stack_run(s[q], f, &o))
            die("run", ctx);
        if (strcmp(outdir, "-")) {
            char path[512];
            snprintf(path, sizeof path, "%s/%s.exr", outdir, argv[8 + q]);
            if (fx_frame_write_exr(o, path, NULL))
                die("write", ctx);
        }
        fx_frame_free(o);
    }
    for (int r = 0; r < rounds; r++)
        for (int q = 0; q < nq; q++) {
            fx_frame *o;
            double w0 = clock_ms(CLOCK_MONOTONIC), c0 = clock_ms(CLOCK_PROCESS_CPUTIME_ID);
            CALLGRIND_ZERO_STATS;
            if (fx_stack_run(s[q], f, &o))
                die("run", ctx);
            CALLGRIND_DUMP_STATS_AT(argv[8 + q]);
            wall[q][r] = clock_ms(CLOCK_MONOTONIC) - w0;
            cpu[q][r] = clock_ms(CLOCK_PROCESS_CPUTIME_ID) - c0;
            fx_frame_free(o);
        }
    for (int q = 0; q < nq; q++) {
        printf("%-10s wall", argv[8 + q]);
        for (int r = 0; r < rounds; r++)
            printf(" %.1f", wall[q][r]);
        printf("  cpu");
        for (int r = 0; r < rounds; r++)
            printf(" %.1f", cpu[q][r]);
        qsort(wall[q], rounds, sizeof(double), cmp_d);
        qsort(cpu[q], rounds, sizeof(double), cmp_d);
        printf("  | median wall %.1f cpu %.1f\n", wall[q][rounds / 2], cpu[q][rounds / 2]);
    }
    return 0;
}
