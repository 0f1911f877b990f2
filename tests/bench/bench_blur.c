/* bench_blur: gaussian_blur alone at 1920x1080 RGBA float: time per algorithm/preset and
 * sigma (median of N runs after a warm-up) as a ratio to a memcpy of the frame measured in
 * the same run, the error against `exact` at the same sigma, and OpenCV's GaussianBlur.
 *
 *   bench_blur [runs=7] [threads=2] [sigmas=2,8.5,16.7,50] [out.csv|-] [only=sub1,sub2,...]
 *
 * At each sigma the selected cases are timed round-robin (one call of each per round), so
 * their ratios hold within the run on a shared machine.
 *
 * Errors: max and mean absolute error over all channels of a test image with values in
 * [0, 1] (smooth gradients + a per-pixel hash texture), and the max error of a centred
 * impulse relative to its exact peak ("impulse"). */
#include "core/effect.h"
#include "libfx/fx.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bench_util.h"

static const int W = 1920, H = 1080;
static int RUNS = 7;
static FILE *g_csv;

typedef struct algo {
    const char *label;
    const char *alg;
    int passes;
} algo;

typedef struct prepared {
    const fx_effect_class *cls;
    void *params;
    fx_effect_run run;
} prepared;

static void prepare(prepared *p, fx_context *ctx, const float *src, float *dst, double sigma,
                    const algo *a)
{
    const fx_effect_class *cls = fx_effect_find("gaussian_blur");
    void *params = calloc(1, cls->params_size);
    fx_params_set_defaults(cls, params);
    const fx_param_def *d = fx_effect_find_param(cls, "sigma");
    *(float *)((char *)params + d->offset) = (float)sigma;
    d = fx_effect_find_param(cls, "algorithm");
    for (int i = 0; i < d->info.enum_count; i++)
        if (strcmp(d->info.enum_items[i], a->alg) == 0)
            *(int *)((char *)params + d->offset) = i;
    d = fx_effect_find_param(cls, "box_passes");
    *(int *)((char *)params + d->offset) = a->passes;
    p->cls = cls;
    p->params = params;
    memset(&p->run, 0, sizeof p->run);
    p->run.ctx = ctx;
    p->run.src = src;
    p->run.dst = dst;
    p->run.width = W;
    p->run.height = H;
    p->run.roi = (fx_rect){ 0, 0, W, H };
    p->run.params = params;
    p->run.quality = FX_QUALITY_FINAL;
    p->run.where = "bench_blur";
}

static double run_once(prepared *p)
{
    double t0 = now_ms();
    if (p->cls->process(&p->run) != FX_OK) {
        fprintf(stderr, "gaussian_blur failed: %s\n", fx_context_error(p->run.ctx));
        exit(1);
    }
    return now_ms() - t0;
}

/* Median of `runs` timed calls after a warm-up (runs 0: the warm-up only). */
static double run_blur(fx_context *ctx, const float *src, float *dst, double sigma, const algo *a,
                       int runs)
{
    prepared p;
    prepare(&p, ctx, src, dst, sigma, a);
    double t[64];
    runs = runs > 64 ? 64 : runs;
    run_once(&p);
    for (int i = 0; i < runs; i++)
        t[i] = run_once(&p);
    free(p.params);
    if (runs == 0)
        return 0;
    qsort(t, runs, sizeof(double), cmp_d);
    return t[runs / 2];
}

static double memcpy_ms(const float *src, float *dst)
{
    size_t bytes = (size_t)W * H * 16;
    double t[64];
    int runs = RUNS > 64 ? 64 : RUNS;
    memcpy(dst, src, bytes);
    for (int i = 0; i < runs; i++) {
        double t0 = now_ms();
        memcpy(dst, src, bytes);
        t[i] = now_ms() - t0;
    }
    qsort(t, runs, sizeof(double), cmp_d);
    return t[runs / 2];
}

/* only: comma-separated substrings of the case labels */
static int matches(const char *label, const char *only)
{
    char buf[256];
    snprintf(buf, sizeof buf, "%s", only);
    for (char *tok = strtok(buf, ","); tok; tok = strtok(NULL, ","))
        if (strstr(label, tok))
            return 1;
    return 0;
}

static void row(const char *what, double sigma, int threads, double ms, double floor_ms, double mean,
                double max, double imp)
{
    char s[16] = "-", e1[16] = "-", e2[16] = "-", e3[16] = "-";
    if (sigma > 0)
        snprintf(s, sizeof s, "%g", sigma);
    if (mean >= 0) {
        snprintf(e1, sizeof e1, "%.2e", mean);
        snprintf(e2, sizeof e2, "%.2e", max);
        snprintf(e3, sizeof e3, "%.2e", imp);
    }
    printf("| %-34s | %5s | %d | %8.2f | %6.2fx | %9s | %9s | %9s |\n", what, s, threads, ms,
           ms / floor_ms, e1, e2, e3);
    fflush(stdout);
    if (g_csv)
        fprintf(g_csv, "%s,%s,%d,%.3f,%.3f,%s,%s,%s\n", what, s, threads, ms, ms / floor_ms,
                mean >= 0 ? e1 : "", mean >= 0 ? e2 : "", mean >= 0 ? e3 : "");
}

/* The test frame (smooth gradients and hashed noise) and an impulse at its centre. */
static void synth_frames(float *src, float *imp)
{
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            float *p = src + ((size_t)y * W + x) * 4;
            unsigned h = (unsigned)x * 73856093u ^ (unsigned)y * 19349663u;
            h ^= h >> 13, h *= 0x5bd1e995u, h ^= h >> 15;
            p[0] = 0.5f + 0.5f * sinf(x * 0.01f) * cosf(y * 0.013f);
            p[1] = (float)y / H;
            p[2] = (float)(h & 0xffff) / 65535.0f;
            p[3] = 1.0f;
        }
    for (int c = 0; c < 4; c++)
        imp[((size_t)(H / 2) * W + W / 2) * 4 + c] = 1.0f;
}

typedef struct bench_buffers {
    float *src, *dst, *ref, *imp, *impref;
    size_t n;
    double floor_ms;
    int threads;
    const char *only;
} bench_buffers;

static const algo algos[] = {
    { "box 3 (draft)", "box", 3 },   { "box 4 (preview)", "box", 4 }, { "box 5", "box", 5 },
    { "box 6", "box", 6 },           { "recursive (final)", "recursive", 3 },
};
static const algo exact = { "exact (reference)", "exact", 3 };

/* Every case at sigma sg: timed round-robin, then its errors against the exact reference. */
static void bench_sigma(fx_context *ctx, bench_buffers *b, double sg, int time_only)
{
    float *src = b->src, *dst = b->dst, *ref = b->ref, *imp = b->imp, *impref = b->impref;
    const size_t n = b->n;
    const double floor_ms = b->floor_ms;
    const int threads = b->threads;
    const char *only = b->only;
    if (!time_only) {
        run_blur(ctx, imp, impref, sg, &exact, 0);
        double tref = run_blur(ctx, src, ref, sg, &exact, sg > 20 ? 1 : 3);
        row(exact.label, sg, threads, tref, floor_ms, -1, -1, -1);
    }
    double peak = impref[((size_t)(H / 2) * W + W / 2) * 4];
    /* the cases are timed round-robin (one call of each per round), so that the
     * machine's load shifts hit them alike and their ratios hold within the run */
    enum { NA = sizeof algos / sizeof algos[0] };
    prepared pr[NA];
    double tm[NA][64];
    int sel[NA], runs = RUNS > 64 ? 64 : RUNS;
    for (int k = 0; k < NA; k++) {
        sel[k] = !only || matches(algos[k].label, only);
        if (sel[k]) {
            prepare(&pr[k], ctx, src, dst, sg, &algos[k]);
            run_once(&pr[k]);
        }
    }
    for (int i = 0; i < runs; i++)
        for (int k = 0; k < NA; k++)
            if (sel[k])
                tm[k][i] = run_once(&pr[k]);
    for (int k = 0; k < NA; k++) {
        if (!sel[k])
            continue;
        qsort(tm[k], runs, sizeof(double), cmp_d);
        double ms = tm[k][runs / 2];
        if (time_only) {
            free(pr[k].params);
            row(algos[k].label, sg, threads, ms, floor_ms, -1, -1, -1);
            continue;
        }
        run_once(&pr[k]); /* dst = this case's result */
        free(pr[k].params);
        double s = 0, m = 0;
        for (size_t i = 0; i < n; i++) {
            double d = fabs((double)dst[i] - ref[i]);
            s += d;
            m = d > m ? d : m;
        }
        run_blur(ctx, imp, dst, sg, &algos[k], 0);
        double mi = 0;
        for (size_t i = 0; i < n; i++) {
            double d = fabs((double)dst[i] - impref[i]);
            mi = d > mi ? d : mi;
        }
        row(algos[k].label, sg, threads, ms, floor_ms, s / n, m, mi / peak);
    }
}

#ifdef LIBFX_BENCH_OPENCV
/* OpenCV's GaussianBlur at three kernel sizes, the in-memory peer. */
static void bench_opencv(const bench_buffers *b)
{
    float *src = b->src, *dst = b->dst;
    const char *only = b->only;
    const int threads = b->threads;
    const double floor_ms = b->floor_ms;
    bench_cv_set_threads(threads);
    const int ks[] = { 11, 51, 101 };
    for (int k = 0; k < (only && !matches("opencv", only) ? 0 : 3); k++) {
        const double ms = bench_cv_median_ms(src, dst, W, H, ks[k], RUNS);
        char label[64];
        snprintf(label, sizeof label, "cv::GaussianBlur %dx%d (CV_32FC4)", ks[k], ks[k]);
        row(label, 0, threads, ms, floor_ms, -1, -1, -1);
    }
}
#endif

int main(int argc, char **argv)
{
    int threads = 2;
    double sigmas[8] = { 2.0, 8.5, 16.7, 50.0 };
    int ns = 4;
    if (argc > 1) RUNS = atoi(argv[1]) < 1 ? 1 : atoi(argv[1]);
    if (argc > 2) threads = atoi(argv[2]) < 1 ? 1 : atoi(argv[2]);
    if (argc > 3) {
        ns = 0;
        for (char *p = argv[3]; *p && ns < 8;) {
            sigmas[ns++] = strtod(p, &p);
            if (*p == ',') p++;
            else break;
        }
    }
    const char *only = argc > 5 ? argv[5] : NULL;
    if (argc > 4 && strcmp(argv[4], "-") != 0) {
        g_csv = fopen(argv[4], "w");
        if (!g_csv) {
            perror(argv[4]);
            return 1;
        }
        fprintf(g_csv, "case,sigma,threads,median_ms,x_memcpy,mean_abs_err,max_abs_err,impulse_rel_err\n");
    }
    size_t n = (size_t)W * H * 4;
    float *src = malloc(n * 4), *dst = malloc(n * 4), *ref = malloc(n * 4);
    float *imp = calloc(n, 4), *impref = malloc(n * 4);
    synth_frames(src, imp);
    memset(dst, 0, n * 4), memset(ref, 0, n * 4), memset(impref, 0, n * 4);
    fx_context *ctx = NULL;
    fx_context_new(&ctx, threads);
    printf("bench_blur %dx%d RGBA float, %d threads, median of %d runs\n\n", W, H, threads, RUNS);
    printf("| %-34s | sigma | threads | ms (median) | x memcpy | mean abs err | max abs err | impulse err / peak |\n",
           "case");
    printf("|---|---|---|---|---|---|---|---|\n");
    double floor_ms = memcpy_ms(src, dst);
    row("memcpy (the bandwidth floor)", 0, threads, floor_ms, floor_ms, -1, -1, -1);
    bench_buffers b = {src, dst, ref, imp, impref, n, floor_ms, threads, only};
    /* BENCH_BLUR_TIME_ONLY=1: no exact reference and no errors (for profiling the cases) */
    const int time_only = getenv("BENCH_BLUR_TIME_ONLY") && atoi(getenv("BENCH_BLUR_TIME_ONLY"));
    for (int si = 0; si < ns; si++)
        bench_sigma(ctx, &b, sigmas[si], time_only);
#ifdef LIBFX_BENCH_OPENCV
    bench_opencv(&b);
#endif
    floor_ms = memcpy_ms(src, dst);
    row("memcpy again (end of run)", 0, threads, floor_ms, floor_ms, -1, -1, -1);
    fx_context_free(ctx);
    if (g_csv)
        fclose(g_csv);
    free(src), free(dst), free(ref), free(imp), free(impref);
    return 0;
}
