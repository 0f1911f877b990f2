/* bench_exr_io: EXR read and write times for 1 and 2 threads (and a ZIP level sweep).
 *
 *   bench_exr_io IN.exr [reps] [--levels] [--zip]
 *
 * Per repetition and thread count (interleaved, so ratios come from one run on a noisy
 * shared machine): read every pass, read Combined only (what `libfx run` decodes for a
 * Combined-only stack is close to this), write every pass, write Combined only. Prints
 * medians. --levels also writes every pass at ZIP levels 1..9 (2 threads) and prints
 * time and size per level: the data behind FX_EXR_DEFAULT_ZIP_LEVEL (io/exr_write.h).
 * --zip only writes (the file is read once): ZIP at the default level through
 * OpenEXRCore's own deflater (zlib in 3.1, libdeflate from 3.2) and through libfx's
 * (io/exr_zip.c, libdeflate), interleaved per run, 1 and
 * 2 threads, every pass and Combined only; prints medians, the median of the per-run
 * ratios and the sizes, then checks both files decode to the same pixels; with
 * --levels also libdeflate levels 1..9 beside zlib level 1 (2 threads).
 *
 * Not built by CMake (tests/bench/CMakeLists.txt belongs to the benches' owner); build
 * against a Release build tree:
 *   cc -O2 -std=c11 -D_POSIX_C_SOURCE=200809L -Ilibfx/include -Ilibfx/src -I/usr/include/OpenEXR \
 *      tests/bench/bench_exr_io.c build-iop/libfx/libfx.a -o build-iop/bench_exr_io \
 *      -lOpenEXRCore-3_1 -lOpenEXR-3_1 -lImath-3_1 -lIlmThread-3_1 -lIex-3_1 -lcjson \
 *      -lpng -lz -lstdc++ -lpthread -lm
 */
#include "libfx/fx.h"
#ifndef BENCH_PUBLIC_ONLY /* -DBENCH_PUBLIC_ONLY: no --levels, for builds before io/exr_write.h */
#include "io/exr_write.h"
#include "io/exr_zip.h"
#endif

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "bench_util.h"

#define MAX_REPS 64

#ifndef BENCH_PUBLIC_ONLY
static int frames_same(const fx_frame *a, const fx_frame *b)
{
    if (fx_frame_width(a) != fx_frame_width(b) || fx_frame_height(a) != fx_frame_height(b) ||
        fx_frame_pass_count(a) != fx_frame_pass_count(b))
        return 0;
    size_t px = (size_t)fx_frame_width(a) * (size_t)fx_frame_height(a);
    for (int i = 0; i < fx_frame_pass_count(a); i++) {
        const char *name = fx_frame_pass_name(a, i);
        float *pa = NULL, *pb = NULL;
        int ca = 0, cb = 0;
        if (fx_frame_pass(a, name, &pa, &ca) != FX_OK || fx_frame_pass(b, name, &pb, &cb) != FX_OK || ca != cb ||
            memcmp(pa, pb, px * (size_t)ca * sizeof(float)) != 0)
            return 0;
    }
    return 1;
}
#endif

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

static double median(double *v, int n)
{
    qsort(v, (size_t)n, sizeof *v, cmp_d);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

static long file_size(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 ? (long)st.st_size : -1;
}

static void die(fx_context *ctx, const char *what)
{
    fprintf(stderr, "bench_exr_io: %s: %s\n", what, fx_context_error(ctx));
    exit(1);
}

/* One combined-only stack: a recipe with no effects needs only Combined. */
static const int bench_threads[2] = {1, 2};

static fx_stack *combined_stack(fx_context *ctx)
{
    fx_stack *s = NULL;
    if (fx_stack_new(ctx, &s) != FX_OK ||
        fx_stack_load_json(s, "{\"version\": 1, \"effects\": []}") != FX_OK)
        die(ctx, "stack");
    return s;
}

#ifndef BENCH_PUBLIC_ONLY
/* --zip: OpenEXR's zlib against libfx's libdeflate writer, per thread count, every pass
 * and Combined only (and with --levels, the ZIP levels); 0 when both decode the same. */
static int bench_zip(fx_context *const ctx[2], const char *in, const char *out, int reps, int levels)
{
    /* [threads][stock, libdeflate][all, Combined][run] */
    static double tz[2][2][2][MAX_REPS];
    long sz[2][2] = {{0, 0}, {0, 0}};
    static const fx_exr_zip_impl impl[2] = {FX_EXR_ZIP_STOCK, FX_EXR_ZIP_LIBDEFLATE};
    char out2[300];
    snprintf(out2, sizeof out2, "%s.libdeflate.exr", out);
    fx_frame *f[2] = {NULL, NULL};
    for (int t = 0; t < 2; t++)
        if (fx_frame_read_exr(ctx[t], in, NULL, &f[t]) != FX_OK)
            die(ctx[t], "read");
    fx_exr_write_params p = fx_exr_write_defaults();
    for (int r = 0; r < reps; r++)
        for (int t = 0; t < 2; t++)
            for (int k = 0; k < 2; k++)
                for (int c = 0; c < 2; c++) {
                    fx_write_options wo = {sizeof wo, 0, c, NULL, NULL};
                    const char *path = k ? out2 : out;
                    double t0 = now();
                    if (fx_exr_write_with(f[t], path, &wo, &p, impl[k]) != FX_OK)
                        die(ctx[t], "write");
                    tz[t][k][c][r] = now() - t0;
                    sz[k][c] = file_size(path);
                }
    /* the last files written are Combined only; check every pass too */
    int same = 1;
    for (int c = 1; c >= 0; c--) {
        fx_write_options wo = {sizeof wo, 0, c, NULL, NULL};
        fx_frame *a = NULL, *b = NULL;
        if (fx_exr_write_with(f[1], out, &wo, &p, FX_EXR_ZIP_STOCK) != FX_OK ||
            fx_exr_write_with(f[1], out2, &wo, &p, FX_EXR_ZIP_LIBDEFLATE) != FX_OK ||
            fx_frame_read_exr(ctx[1], out, NULL, &a) != FX_OK || fx_frame_read_exr(ctx[1], out2, NULL, &b) != FX_OK)
            die(ctx[1], "check");
        same = same && frames_same(a, b);
        fx_frame_free(a);
        fx_frame_free(b);
    }
    printf("# %s: %dx%d, %d passes; ZIP level %d, write only, median of %d runs (ms)\n", in,
           fx_frame_width(f[0]), fx_frame_height(f[0]), fx_frame_pass_count(f[0]), p.zip_level, reps);
    printf("| write | threads | OpenEXR | libfx+libdeflate | OpenEXR / libfx | OpenEXR MB | libfx MB |\n"
           "|---|---:|---:|---:|---:|---:|---:|\n");
    for (int c = 0; c < 2; c++)
        for (int t = 0; t < 2; t++) {
            double ratio[MAX_REPS];
            for (int r = 0; r < reps; r++)
                ratio[r] = tz[t][0][c][r] / tz[t][1][c][r];
            double m0 = median(tz[t][0][c], reps), m1 = median(tz[t][1][c], reps);
            printf("| %s | %d | %.1f | %.1f | %.2f | %.2f | %.2f |\n", c ? "Combined" : "all passes", bench_threads[t],
                   m0 * 1e3, m1 * 1e3, median(ratio, reps), sz[0][c] / 1e6, sz[1][c] / 1e6);
        }
    printf("decoded pixels of the two: %s\n", same ? "identical" : "DIFFERENT");
    if (levels) {
        /* libdeflate levels 1..9 beside zlib 1, interleaved per run, 2 threads */
        static double tl[10][2][MAX_REPS];
        long szl[10][2];
        for (int r = 0; r < reps; r++)
            for (int l = 0; l <= 9; l++)
                for (int c = 0; c < 2; c++) {
                    fx_exr_write_params q = fx_exr_write_defaults();
                    q.zip_level = l ? l : 1;
                    fx_write_options wo = {sizeof wo, 0, c, NULL, NULL};
                    double t0 = now();
                    if (fx_exr_write_with(f[1], out, &wo, &q, l ? FX_EXR_ZIP_LIBDEFLATE : FX_EXR_ZIP_STOCK) != FX_OK)
                        die(ctx[1], "write");
                    tl[l][c][r] = now() - t0;
                    szl[l][c] = file_size(out);
                }
        printf("\n# ZIP levels, 2 threads, median of %d runs (ms; time relative to zlib level 1 from the "
               "same runs)\n| deflater | level | all passes ms | rel. | MB | Combined ms | rel. | MB |\n"
               "|---|---:|---:|---:|---:|---:|---:|---:|\n", reps);
        for (int l = 0; l <= 9; l++) {
            double rel[2][MAX_REPS];
            for (int c = 0; c < 2; c++)
                for (int r = 0; r < reps; r++)
                    rel[c][r] = tl[l][c][r] / tl[0][c][r];
            double m0 = median(tl[l][0], reps), m1 = median(tl[l][1], reps);
            printf("| %s | %d | %.1f | %.2f | %.2f | %.1f | %.2f | %.2f |\n", l ? "libfx+libdeflate" : "OpenEXR",
                   l ? l : 1, m0 * 1e3, median(rel[0], reps), szl[l][0] / 1e6, m1 * 1e3, median(rel[1], reps),
                   szl[l][1] / 1e6);
        }
    }
    unlink(out2);
    unlink(out);
    for (int t = 0; t < 2; t++)
        fx_frame_free(f[t]);
    return same ? 0 : 1;
}
#endif

/* Read (every pass, Combined only) and write (the same) at 1 and 2 threads. */
static void bench_read_write(fx_context *const ctx[2], fx_stack *const stack[2], const char *in, const char *out,
                             int reps)
{
    double rd_all[2][MAX_REPS], rd_comb[2][MAX_REPS], wr_all[2][MAX_REPS], wr_comb[2][MAX_REPS];
    int w = 0, h = 0, passes = 0;
    long size_all = 0, size_comb = 0;
    for (int r = 0; r < reps; r++) {
        for (int t = 0; t < 2; t++) {
            fx_frame *f = NULL, *fc = NULL;
            double t0 = now();
            if (fx_frame_read_exr(ctx[t], in, NULL, &f) != FX_OK)
                die(ctx[t], "read");
            double t1 = now();
            fx_read_options ro = {sizeof ro, NULL, NULL, stack[t]};
            if (fx_frame_read_exr(ctx[t], in, &ro, &fc) != FX_OK)
                die(ctx[t], "read Combined");
            double t2 = now();
            fx_write_options wo = {sizeof wo, 0, 0, NULL, NULL};
            if (fx_frame_write_exr(f, out, &wo) != FX_OK)
                die(ctx[t], "write");
            double t3 = now();
            size_all = file_size(out);
            wo.only_combined = 1;
            if (fx_frame_write_exr(f, out, &wo) != FX_OK)
                die(ctx[t], "write Combined");
            double t4 = now();
            size_comb = file_size(out);
            rd_all[t][r] = t1 - t0, rd_comb[t][r] = t2 - t1;
            wr_all[t][r] = t3 - t2, wr_comb[t][r] = t4 - t3;
            w = fx_frame_width(f), h = fx_frame_height(f);
            passes = fx_frame_pass_count(f);
            fx_frame_free(f);
            fx_frame_free(fc);
            fx_context_clear_warnings(ctx[t]);
        }
    }
    printf("# %s: %dx%d, %d passes; median of %d runs (ms)\n", in, w, h, passes, reps);
    printf("| operation | 1 thread | 2 threads | 1t / 2t |\n|---|---:|---:|---:|\n");
    struct { const char *name; double (*v)[MAX_REPS]; } rows[] = {
        {"read all passes", rd_all}, {"read Combined", rd_comb},
        {"write all passes", wr_all}, {"write Combined", wr_comb}};
    for (size_t i = 0; i < sizeof rows / sizeof rows[0]; i++) {
        /* the ratio of the medians of per-run ratios: both from the same runs */
        double ratio[MAX_REPS];
        for (int r = 0; r < reps; r++)
            ratio[r] = rows[i].v[0][r] / rows[i].v[1][r];
        double m1 = median(rows[i].v[0], reps), m2 = median(rows[i].v[1], reps);
        printf("| %s | %.1f | %.1f | %.2f |\n", rows[i].name, m1 * 1e3, m2 * 1e3, median(ratio, reps));
    }
    printf("output sizes: all passes %.2f MB, Combined %.2f MB (input %.2f MB)\n", size_all / 1e6,
           size_comb / 1e6, file_size(in) / 1e6);
}

#ifndef BENCH_PUBLIC_ONLY
/* --levels: the ZIP level sweep of the library's writer, every pass, 2 threads. */
static void bench_levels(fx_context *ctx, const char *in, const char *out, int reps)
{
    fx_frame *f = NULL;
    if (fx_frame_read_exr(ctx, in, NULL, &f) != FX_OK)
        die(ctx, "read");
    printf("\n# ZIP level sweep (%s), every pass, 2 threads, median of %d runs\n",
           fx_exr_zip_available() ? "libdeflate" : "OpenEXR's zlib", reps);
    printf("| level | write ms | MB | MB Combined only | write ms Combined only |\n|---:|---:|---:|---:|---:|\n");
    for (int level = 1; level <= 9; level++) {
        double tv[MAX_REPS], tc[MAX_REPS];
        long sz = 0, szc = 0;
        for (int r = 0; r < reps; r++) {
            fx_exr_write_params p = fx_exr_write_defaults();
            p.zip_level = level;
            fx_write_options wo = {sizeof wo, 0, 0, NULL, NULL};
            double t0 = now();
            if (fx_exr_write(f, out, &wo, &p) != FX_OK)
                die(ctx, "write");
            double t1 = now();
            sz = file_size(out);
            wo.only_combined = 1;
            if (fx_exr_write(f, out, &wo, &p) != FX_OK)
                die(ctx, "write");
            tc[r] = now() - t1;
            szc = file_size(out);
            tv[r] = t1 - t0;
        }
        printf("| %d | %.1f | %.2f | %.2f | %.1f |\n", level, median(tv, reps) * 1e3, sz / 1e6, szc / 1e6,
               median(tc, reps) * 1e3);
    }
    fx_frame_free(f);
}
#endif

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "usage: bench_exr_io IN.exr [reps] [--levels]\n");
        return 2;
    }
    const char *in = argv[1];
    int reps = 7, levels = 0, zip = 0;
    for (int i = 2; i < argc; i++) {
        if (strcmp(argv[i], "--levels") == 0)
            levels = 1;
        else if (strcmp(argv[i], "--zip") == 0)
            zip = 1;
        else
            reps = atoi(argv[i]);
    }
    if (reps < 1 || reps > MAX_REPS)
        reps = 7;
    char out[256];
    snprintf(out, sizeof out, "/tmp/bench_exr_io_%ld.exr", (long)getpid());

    fx_context *ctx[2];
    fx_stack *stack[2];
    for (int t = 0; t < 2; t++) {
        if (fx_context_new(&ctx[t], bench_threads[t]) != FX_OK)
            return 1;
        stack[t] = combined_stack(ctx[t]);
    }
#ifndef BENCH_PUBLIC_ONLY
    if (zip) {
        int rc = bench_zip(ctx, in, out, reps, levels);
        for (int t = 0; t < 2; t++) {
            fx_stack_free(stack[t]);
            fx_context_free(ctx[t]);
        }
        return rc;
    }
#else
    (void)zip;
#endif
    bench_read_write(ctx, stack, in, out, reps);
#ifndef BENCH_PUBLIC_ONLY
    if (levels)
        bench_levels(ctx[1], in, out, reps);
#else
    (void)levels;
#endif
    unlink(out);
    for (int t = 0; t < 2; t++) {
        fx_stack_free(stack[t]);
        fx_context_free(ctx[t]);
    }
    return 0;
}
