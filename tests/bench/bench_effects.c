/* bench_effects: per-effect time at 1920x1080 RGBA float, medians of N runs, 1 and 2
 * threads, next to the memcpy floor and OpenCV's GaussianBlur; error of box/recursive
 * against exact. Calls each effect's process() directly (no stack copies/compositing).
 *
 *   bench_effects [out.csv] [runs=7] [width=1920] [height=1080]
 *
 * Prints a Markdown table; writes the same rows as CSV when a path is given. */
#include "core/effect.h"
#include "libfx/fx.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bench_util.h"

static int W = 1920, H = 1080, RUNS = 7;
static float *g_src, *g_dst, *g_ref;
static FILE *g_csv;

static void set_param(const fx_effect_class *cls, void *params, const char *name, double v,
                      const char *item)
{
    const fx_param_def *d = fx_effect_find_param(cls, name);
    if (!d) {
        fprintf(stderr, "no param %s\n", name);
        exit(1);
    }
    char *p = (char *)params + d->offset;
    if (d->info.type == FX_PARAM_FLOAT)
        *(float *)p = (float)v;
    else if (d->info.type == FX_PARAM_ENUM) {
        for (int i = 0; i < d->info.enum_count; i++)
            if (strcmp(d->info.enum_items[i], item) == 0)
                *(int *)p = i;
    } else
        *(int *)p = (int)v;
}

typedef struct bench_case {
    const char *effect;
    const char *label;
    const char *p1; double v1; const char *i1;
    const char *p2; double v2; const char *i2;
    const char *p3; double v3; const char *i3;
} bench_case;

static double time_effect(fx_context *ctx, const bench_case *bc, float *dst)
{
    const fx_effect_class *cls = fx_effect_find(bc->effect);
    void *params = calloc(1, cls->params_size);
    fx_params_set_defaults(cls, params);
    if (bc->p1) set_param(cls, params, bc->p1, bc->v1, bc->i1);
    if (bc->p2) set_param(cls, params, bc->p2, bc->v2, bc->i2);
    if (bc->p3) set_param(cls, params, bc->p3, bc->v3, bc->i3);
    fx_effect_run run;
    memset(&run, 0, sizeof run);
    run.ctx = ctx;
    run.src = g_src;
    run.dst = dst;
    run.width = W;
    run.height = H;
    run.roi = (fx_rect){ 0, 0, W, H };
    run.params = params;
    run.quality = FX_QUALITY_FINAL;
    run.where = bc->label;
    double t[64];
    int runs = RUNS > 64 ? 64 : RUNS;
    cls->process(&run); /* warm-up: page faults, pool start */
    for (int i = 0; i < runs; i++) {
        double t0 = now_ms();
        if (cls->process(&run) != FX_OK) {
            fprintf(stderr, "%s failed: %s\n", bc->label, fx_context_error(ctx));
            exit(1);
        }
        t[i] = now_ms() - t0;
    }
    free(params);
    qsort(t, runs, sizeof(double), cmp_d);
    return t[runs / 2];
}

static void errors(const float *a, const float *ref, double *mean, double *max)
{
    size_t n = (size_t)W * H * 4;
    double s = 0, m = 0;
    for (size_t i = 0; i < n; i++) {
        double d = fabs((double)a[i] - ref[i]);
        s += d;
        if (d > m)
            m = d;
    }
    *mean = s / n;
    *max = m;
}

static double memcpy_ms(void)
{
    size_t bytes = (size_t)W * H * 16;
    double t[64];
    int runs = RUNS > 64 ? 64 : RUNS;
    memcpy(g_dst, g_src, bytes);
    for (int i = 0; i < runs; i++) {
        double t0 = now_ms();
        memcpy(g_dst, g_src, bytes);
        t[i] = now_ms() - t0;
    }
    qsort(t, runs, sizeof(double), cmp_d);
    return t[runs / 2];
}

static void row(const char *what, int threads, double ms, double floor_ms, const char *err_mean,
                const char *err_max)
{
    printf("| %-40s | %d | %8.2f | %6.1fx | %9s | %9s |\n", what, threads, ms, ms / floor_ms,
           err_mean, err_max);
    if (g_csv)
        fprintf(g_csv, "%s,%d,%.3f,%.3f,%s,%s\n", what, threads, ms, ms / floor_ms,
                err_mean[0] == '-' ? "" : err_mean, err_max[0] == '-' ? "" : err_max);
}

int main(int argc, char **argv)
{
    if (argc > 1 && strcmp(argv[1], "-") != 0) {
        g_csv = fopen(argv[1], "w");
        if (!g_csv) {
            perror(argv[1]);
            return 1;
        }
        fprintf(g_csv, "case,threads,median_ms,x_memcpy,mean_abs_err,max_abs_err\n");
    }
    if (argc > 2) RUNS = atoi(argv[2]) < 1 ? 1 : atoi(argv[2]);
    if (argc > 3) W = atoi(argv[3]);
    if (argc > 4) H = atoi(argv[4]);
    size_t n = (size_t)W * H * 4;
    g_src = malloc(n * 4), g_dst = malloc(n * 4), g_ref = malloc(n * 4);
    float *tmp = malloc(n * 4);
    /* a photo-like test image: smooth gradients + a hash texture, alpha 1 */
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            float *p = g_src + ((size_t)y * W + x) * 4;
            unsigned h = (unsigned)x * 73856093u ^ (unsigned)y * 19349663u;
            h ^= h >> 13, h *= 0x5bd1e995u, h ^= h >> 15;
            p[0] = 0.5f + 0.5f * sinf(x * 0.01f) * cosf(y * 0.013f);
            p[1] = (float)y / H;
            p[2] = (float)(h & 0xffff) / 65535.0f;
            p[3] = 1.0f;
        }
    memset(g_dst, 0, n * 4), memset(g_ref, 0, n * 4), memset(tmp, 0, n * 4);
    printf("bench_effects %dx%d RGBA float, median of %d runs\n\n", W, H, RUNS);
    printf("| %-40s | threads | ms (median) | x memcpy | mean abs err | max abs err |\n", "case");
    printf("|---|---|---|---|---|---|\n");
    const double sigmas[] = { 2.0, 8.5, 17.0, 50.0 };
    const char *algs[] = { "exact", "recursive", "box" };
    for (int threads = 1; threads <= 2; threads++) {
        fx_context *ctx = NULL;
        fx_context_new(&ctx, threads);
        double floor_ms = memcpy_ms();
        row("memcpy (the bandwidth floor)", threads, floor_ms, floor_ms, "-", "-");
        for (int si = 0; si < 4; si++) {
            for (int a = 0; a < 3; a++)
                for (int passes = 3; passes <= (a == 2 ? 5 : 3); passes++) {
                    if (a == 2 && passes == 4) continue; /* box 3 (draft) and 5 */
                    char label[96];
                    if (a == 2)
                        snprintf(label, sizeof label, "gaussian_blur box%d sigma %g", passes, sigmas[si]);
                    else
                        snprintf(label, sizeof label, "gaussian_blur %s sigma %g", algs[a], sigmas[si]);
                    bench_case bc = { "gaussian_blur", label, "sigma", sigmas[si], NULL,
                                      "algorithm", 0, algs[a], "box_passes", passes, NULL };
                    float *out = a == 0 ? g_ref : tmp;
                    double ms = time_effect(ctx, &bc, out);
                    char em[32] = "-", ex[32] = "-";
                    if (a > 0) {
                        double mean, max;
                        errors(out, g_ref, &mean, &max);
                        snprintf(em, sizeof em, "%.2e", mean);
                        snprintf(ex, sizeof ex, "%.2e", max);
                    }
                    row(label, threads, ms, floor_ms, em, ex);
                }
        }
        /* box 4 (preview) at one sigma */
        {
            bench_case bc = { "gaussian_blur", "gaussian_blur box4 sigma 8.5", "sigma", 8.5, NULL,
                              "algorithm", 0, "box", "box_passes", 4, NULL };
            row(bc.label, threads, time_effect(ctx, &bc, tmp), floor_ms, "-", "-");
        }
        {
            bench_case bc = { "gaussian_blur", "gaussian_blur paper_5x5", "kernel", 0, "paper_5x5",
                              NULL, 0, NULL, NULL, 0, NULL };
            row(bc.label, threads, time_effect(ctx, &bc, tmp), floor_ms, "-", "-");
        }
#ifdef LIBFX_BENCH_OPENCV
        bench_cv_set_threads(threads);
        const int ks[] = { 11, 51, 101 };
        for (int k = 0; k < 3; k++) {
            const double ms = bench_cv_median_ms(g_src, tmp, W, H, ks[k], RUNS);
            char label[64];
            snprintf(label, sizeof label, "cv::GaussianBlur %dx%d (CV_32FC4)", ks[k], ks[k]);
            row(label, threads, ms, floor_ms, "-", "-");
        }
#endif
        const char *ops[] = { "grayscale_luminance", "sepia", "custom" };
        for (int k = 0; k < 3; k++) {
            char label[64];
            snprintf(label, sizeof label, "color_matrix %s", ops[k]);
            bench_case bc = { "color_matrix", label, "operator", 0, ops[k], NULL, 0, NULL, NULL, 0, NULL };
            row(label, threads, time_effect(ctx, &bc, tmp), floor_ms, "-", "-");
        }
        {
            bench_case bc = { "color_matrix", "color_matrix sepia mix 0.5", "operator", 0, "sepia",
                              "mix", 0.5, NULL, NULL, 0, NULL };
            row(bc.label, threads, time_effect(ctx, &bc, tmp), floor_ms, "-", "-");
        }
        const char *modes[] = { "slices", "cells", "average" };
        for (int k = 0; k < 3; k++) {
            char label[64];
            snprintf(label, sizeof label, "pixelate %s", modes[k]);
            bench_case bc = { "pixelate", label, "mode", 0, modes[k], NULL, 0, NULL, NULL, 0, NULL };
            row(label, threads, time_effect(ctx, &bc, tmp), floor_ms, "-", "-");
        }
        fx_context_free(ctx);
    }
    if (g_csv)
        fclose(g_csv);
    free(g_src), free(g_dst), free(g_ref), free(tmp);
    return 0;
}
