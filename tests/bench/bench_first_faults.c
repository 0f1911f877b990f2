/* bench_first_faults: a process's first frame against its warm ones, as `libfx run` runs
 * them (read with the stack's needs, sidecar, fx_stack_run_consume, write), with the minor
 * page faults (getrusage, every thread) and wall ms of the stack run per frame.
 *
 *   bench_first_faults PASSES.exr SIDECAR.json RECIPE.json [frames [threads [out.exr]]]
 *
 * Prints one line per frame: "frame N: run_ms R user U sys S minflt F effects_ms E" (U, S:
 * CPU ms of every thread) (E: the stack's
 * per-effect timings summed), the read's ms and faults, then per effect its ms and minor faults (taken at the stack's
 * progress calls, which come before each effect). Under callgrind, `--toggle-collect=fx_stack_run_consume
 * --dump-after=fx_stack_run_consume` gives the instructions of each frame's run. */
#include "libfx/fx.h"

#include "bench_util.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>

static long minflt(void)
{
    struct rusage u;
    getrusage(RUSAGE_SELF, &u);
    return u.ru_minflt;
}

/* user and system CPU ms of every thread so far */
static void cpu_ms(double *user, double *sys)
{
    struct rusage u;
    getrusage(RUSAGE_SELF, &u);
    *user = u.ru_utime.tv_sec * 1e3 + u.ru_utime.tv_usec / 1e3;
    *sys = u.ru_stime.tv_sec * 1e3 + u.ru_stime.tv_usec / 1e3;
}

#define MAX_FX 64
static long stage_flt[MAX_FX + 1];
static double stage_cpu[MAX_FX + 1]; /* user + sys ms, every thread */
static int stage_count;

/* the stack reports "... (k of n)" before effect k */
static int on_progress(void *user, const char *stage, double fraction)
{
    (void)user;
    (void)fraction;
    const char *o = strstr(stage, " of ");
    if (o && o > stage && stage[strlen(stage) - 1] == ')' && stage_count < MAX_FX) {
        double u, sy;
        cpu_ms(&u, &sy);
        stage_cpu[stage_count] = u + sy;
        stage_flt[stage_count++] = minflt();
    }
    return 0;
}

static double effects_ms(fx_stack *s, double *each, int *n)
{
    char *t = NULL;
    double sum = 0.0;
    *n = 0;
    if (fx_stack_timings_json(s, &t) == FX_OK && t) {
        for (const char *p = strstr(t, "\"ms\":"); p; p = strstr(p + 5, "\"ms\":")) {
            sum += atof(p + 5);
            if (*n < MAX_FX)
                each[(*n)++] = atof(p + 5);
        }
    }
    fx_free(t);
    return sum;
}

int main(int argc, char **argv)
{
    if (argc < 4) {
        fprintf(stderr, "usage: bench_first_faults PASSES.exr SIDECAR.json RECIPE.json [frames [threads [out.exr]]]\n");
        return 2;
    }
    int frames = argc > 4 ? atoi(argv[4]) : 4, threads = argc > 5 ? atoi(argv[5]) : 2;
    const char *outp = argc > 6 ? argv[6] : NULL;
    fx_context *ctx = NULL;
    fx_stack *s = NULL;
    if (fx_context_new(&ctx, threads) || fx_stack_new(ctx, &s) || fx_stack_load_file(s, argv[3])) {
        fprintf(stderr, "%s\n", ctx ? fx_context_error(ctx) : "no context");
        return 1;
    }
    for (int k = 0; k < frames; k++) {
        fx_read_options ro;
        memset(&ro, 0, sizeof ro);
        ro.size = sizeof ro;
        ro.stack = s;
        fx_frame *in = NULL, *out = NULL;
        long r0 = minflt();
        double tr = now_ms();
        if (fx_frame_read_exr(ctx, argv[1], &ro, &in) || fx_frame_apply_sidecar_file(in, argv[2])) {
            fprintf(stderr, "%s\n", fx_context_error(ctx));
            return 1;
        }
        tr = now_ms() - tr;
        long read_flt = minflt() - r0;
        fx_context_set_progress(ctx, on_progress, NULL);
        stage_count = 0;
        double u0, s0, u1, s1;
        cpu_ms(&u0, &s0);
        long f0 = minflt();
        double t0 = now_ms();
        if (fx_stack_run_consume(s, in, 0, &out)) {
            fprintf(stderr, "%s\n", fx_context_error(ctx));
            return 1;
        }
        double t1 = now_ms();
        long f1 = minflt();
        cpu_ms(&u1, &s1);
        fx_context_set_progress(ctx, NULL, NULL);
        stage_flt[stage_count] = f1;
        stage_cpu[stage_count] = u1 + s1;
        double each[MAX_FX];
        int n = 0;
        printf("frame %d: run_ms %.2f user %.1f sys %.1f minflt %ld effects_ms %.2f", k + 1, t1 - t0, u1 - u0, s1 - s0,
               f1 - f0, effects_ms(s, each, &n));
        printf(" read_ms %.2f read_flt %ld", tr, read_flt);
        for (int i = 0; i < n; i++)
            printf(" | %.2f ms %ld flt %.1f cpu", each[i], i < stage_count ? stage_flt[i + 1] - stage_flt[i] : -1L,
                   i < stage_count ? stage_cpu[i + 1] - stage_cpu[i] : -1.0);
        printf("\n");
        if (outp) {
            fx_write_options wo;
            memset(&wo, 0, sizeof wo);
            wo.size = sizeof wo;
            wo.compression = "none";
            if (fx_frame_write_exr(out, outp, &wo)) {
                fprintf(stderr, "%s\n", fx_context_error(ctx));
                return 1;
            }
        }
        fx_frame_free(out);
    }
    fx_stack_free(s);
    fx_context_free(ctx);
    return 0;
}
