/* bench_greek_bath: god_rays (naive vs polar: time and error against the reference) and
 * voronoi_caustics (grid vs brute force: time vs points) on a rendered bath frame.
 *
 *   bench_greek_bath passes.exr sidecar.json [runs [max_naive_samples [skip_caustics]]] > out.csv
 *
 * passes.exr: the batch runner's <prefix>libfx_passes.####.exr; sidecar: its camera.json.
 * max_naive_samples (default 400) caps the naive sweep (10..400); skip_caustics 1 leaves
 * out the caustics rows. Polar rows: value "res/levels/downsample".
 * CSV rows: effect,method,param,value,ms_median,err_rms,err_max,err_p99 (errors of the added
 * rays against the reference preset, relative to the reference's peak rays value). Medians of
 * `runs` runs (default 5); the machine is shared: compare ratios within one run. */
#include "libfx/fx.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bench_util.h"

static fx_context *ctx;
static fx_frame *in;
static size_t npx;

/* Runs the recipe `runs` times; returns the median ms and (if keep) the last Combined. */
static double run_recipe(const char *json, int runs, float **keep)
{
    fx_stack *s = NULL;
    if (fx_stack_new(ctx, &s) != FX_OK || fx_stack_load_json(s, json) != FX_OK) {
        fprintf(stderr, "recipe: %s\n%s\n", fx_context_error(ctx), json);
        exit(1);
    }
    double t[64];
    if (runs > 64)
        runs = 64;
    for (int r = 0; r < runs; r++) {
        fx_frame *out = NULL;
        double t0 = now_ms();
        if (fx_stack_run(s, in, &out) != FX_OK) {
            fprintf(stderr, "run: %s\n", fx_context_error(ctx));
            exit(1);
        }
        t[r] = now_ms() - t0;
        if (keep && r == runs - 1) {
            float *d;
            int c;
            fx_frame_pass(out, "Combined", &d, &c);
            *keep = malloc(npx * 4 * sizeof(float));
            memcpy(*keep, d, npx * 4 * sizeof(float));
        }
        fx_frame_free(out);
    }
    fx_stack_free(s);
    qsort(t, (size_t)runs, sizeof(double), cmp_d);
    return t[runs / 2];
}

static void errors(const float *a, const float *ref, const float *src, double *rms, double *mx, double *p99)
{
    double peak = 0, s2 = 0, m = 0;
    double *e = malloc(npx * sizeof(double));
    for (size_t i = 0; i < npx; i++) {
        double le = 0;
        for (int k = 0; k < 3; k++) {
            double rr = ref[i * 4 + k] - src[i * 4 + k];
            peak = fmax(peak, rr);
            double d = fabs((double)a[i * 4 + k] - ref[i * 4 + k]);
            le = fmax(le, d);
        }
        e[i] = le;
        s2 += le * le;
        m = fmax(m, le);
    }
    qsort(e, npx, sizeof(double), cmp_d);
    peak = peak > 0 ? peak : 1;
    *rms = sqrt(s2 / npx) / peak;
    *mx = m / peak;
    *p99 = e[(size_t)(npx * 0.99)] / peak;
    free(e);
}

#define RAYS "\"light\": \"Sun\", \"occlusion\": \"sky\", \"threshold\": 0.9, \"knee\": 0.5, \"max_source\": 6.0, " \
             "\"decay\": 0.975, \"density\": 0.95, \"weight\": 1.0, \"exposure\": 0.006"

int main(int argc, char **argv)
{
    if (argc < 3) {
        fprintf(stderr, "usage: bench_greek_bath passes.exr sidecar.json [runs]\n");
        return 2;
    }
    int runs = argc > 3 ? atoi(argv[3]) : 5;
    if (runs < 1)
        runs = 1;
    int max_naive = argc > 4 ? atoi(argv[4]) : 400;
    int skip_caustics = argc > 5 ? atoi(argv[5]) : 0;
    if (fx_context_new(&ctx, 0) != FX_OK || fx_frame_read_exr(ctx, argv[1], NULL, &in) != FX_OK ||
        fx_frame_apply_sidecar_file(in, argv[2]) != FX_OK) {
        fprintf(stderr, "load: %s\n", fx_context_error(ctx));
        return 1;
    }
    npx = (size_t)fx_frame_width(in) * fx_frame_height(in);
    float *src;
    int ch;
    fx_frame_pass(in, "Combined", &src, &ch);
    fprintf(stderr, "%dx%d, %d threads\n", fx_frame_width(in), fx_frame_height(in), fx_context_threads(ctx));
    printf("effect,method,param,value,ms_median,err_rms,err_max,err_p99\n");
    char json[2048];
    /* identity: the stack's own cost (copying Combined) */
    snprintf(json, sizeof json, "{\"version\": 1, \"effects\": [{\"effect\": \"god_rays\", \"params\": {" RAYS
             ", \"weight\": 0}}]}");
    printf("god_rays,identity,weight,0,%.3f,,,\n", run_recipe(json, runs, NULL));
    /* reference: naive, 2000 samples */
    float *ref = NULL;
    snprintf(json, sizeof json, "{\"version\": 1, \"effects\": [{\"effect\": \"god_rays\", \"quality\": \"reference\", "
             "\"params\": {" RAYS "}}]}");
    double tref = run_recipe(json, 1, &ref);
    printf("god_rays,reference,samples,2000,%.3f,0,0,0\n", tref);
    fflush(stdout);
    const int samples[] = {10, 25, 50, 100, 200, 400};
    for (int i = 0; i < 6 && samples[i] <= max_naive; i++)
        for (int jit = 0; jit < 2; jit++) {
            float *o = NULL;
            snprintf(json, sizeof json, "{\"version\": 1, \"effects\": [{\"effect\": \"god_rays\", \"params\": {" RAYS
                     ", \"method\": \"naive\", \"samples\": %d, \"jitter\": %s}}]}", samples[i], jit ? "true" : "false");
            double ms = run_recipe(json, runs, &o);
            double rms, mx, p99;
            errors(o, ref, src, &rms, &mx, &p99);
            printf("god_rays,%s,samples,%d,%.3f,%.5f,%.5f,%.5f\n", jit ? "naive_jitter" : "naive", samples[i], ms, rms, mx, p99);
            fflush(stdout);
            free(o);
        }
    /* polar: resolution (lines and bins per pixel), levels per octave, downsample */
    const struct { double res; int levels, down; } pol[] = {
        {0.25, 2, 1}, {0.5, 2, 1}, {0.75, 2, 1}, {1.0, 2, 1}, {1.5, 3, 1}, {2.0, 3, 1},
        {1.0, 2, 2}, {1.0, 2, 3}, {1.0, 2, 4}, {0.75, 2, 2}, {0.5, 1, 2}, {0.75, 1, 3}, {1.5, 2, 2}, {2.0, 3, 2},
    };
    for (int i = 0; i < (int)(sizeof pol / sizeof pol[0]); i++) {
        float *o = NULL;
        snprintf(json, sizeof json, "{\"version\": 1, \"effects\": [{\"effect\": \"god_rays\", \"params\": {" RAYS
                 ", \"method\": \"polar\", \"polar_resolution\": %g, \"polar_levels\": %d, \"polar_downsample\": %d}}]}",
                 pol[i].res, pol[i].levels, pol[i].down);
        double ms = run_recipe(json, runs, &o);
        double rms, mx, p99;
        errors(o, ref, src, &rms, &mx, &p99);
        printf("god_rays,polar,res/levels/downsample,%g/%d/%d,%.3f,%.5f,%.5f,%.5f\n", pol[i].res, pol[i].levels,
               pol[i].down, ms, rms, mx, p99);
        fflush(stdout);
        free(o);
    }
    const char *q[] = {"draft", "preview", "final"};
    for (int i = 0; i < 3; i++) {
        float *o = NULL;
        snprintf(json, sizeof json, "{\"version\": 1, \"effects\": [{\"effect\": \"god_rays\", \"quality\": \"%s\", "
                 "\"params\": {" RAYS "}}]}", q[i]);
        double ms = run_recipe(json, runs, &o);
        double rms, mx, p99;
        errors(o, ref, src, &rms, &mx, &p99);
        printf("god_rays,preset,quality,%s,%.3f,%.5f,%.5f,%.5f\n", q[i], ms, rms, mx, p99);
        fflush(stdout);
        free(o);
    }
    free(ref);
    /* caustics: time vs points, grid and brute force, on the water */
    const int points[] = {49, 100, 196, 400, 1024, 2025, 5041};
    for (int i = 0; i < 7 && !skip_caustics; i++)
        for (int m = 0; m < 2; m++) {
            snprintf(json, sizeof json, "{\"version\": 1, \"effects\": [{\"effect\": \"voronoi_caustics\", \"params\": "
                     "{\"points\": %d, \"tile_size\": 3.0, \"method\": \"%s\"}, \"mask\": {\"material\": \"Water\"}}]}",
                     points[i], m ? "brute" : "grid");
            double ms = run_recipe(json, m && points[i] > 1000 ? 1 : runs, NULL);
            printf("voronoi_caustics,%s,points,%d,%.3f,,,\n", m ? "brute" : "grid", points[i], ms);
            fflush(stdout);
        }
    fx_frame_free(in);
    fx_context_free(ctx);
    return 0;
}
