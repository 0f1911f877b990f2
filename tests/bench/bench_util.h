/* What the benchmark programs share: a monotonic clock, medians, a whole file read, and the
 * rows of the memory-bandwidth floor (a copy on libfx's pool). */
#ifndef LIBFX_BENCH_UTIL_H
#define LIBFX_BENCH_UTIL_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static inline double now_ms(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec * 1e3 + t.tv_nsec / 1e6;
}

/* Milliseconds on clock c: CLOCK_MONOTONIC (wall) or CLOCK_PROCESS_CPUTIME_ID (every
 * thread's CPU time, which other processes on a shared machine disturb far less). */
static inline double clock_ms(clockid_t c)
{
    struct timespec t;
    clock_gettime(c, &t);
    return t.tv_sec * 1e3 + t.tv_nsec / 1e6;
}

/* qsort comparator for doubles */
static inline int cmp_d(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* Median of n values (sorts them). */
static inline double median_d(double *v, int n)
{
    qsort(v, (size_t)n, sizeof *v, cmp_d);
    return n > 0 ? v[n / 2] : 0.0;
}

/* A whole file as a NUL-terminated string (free it), or NULL. */
static inline char *bench_slurp(const char *path)
{
    FILE *f = fopen(path, "rb");
    if (!f)
        return NULL;
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    rewind(f);
    char *b = n >= 0 ? malloc((size_t)n + 1) : NULL;
    if (b && fread(b, 1, (size_t)n, f) != (size_t)n) {
        free(b);
        b = NULL;
    }
    if (b)
        b[n] = 0;
    fclose(f);
    return b;
}

/* The floor: rows [y0, y1) of a w-wide RGBA float frame copied (an fx_parallel_for body). */
typedef struct bench_copy_job {
    const float *src;
    float *dst;
    int w;
} bench_copy_job;

static inline void bench_copy_rows(void *user, int y0, int y1)
{
    bench_copy_job *j = user;
    size_t row = (size_t)j->w * 4;
    memcpy(j->dst + (size_t)y0 * row, j->src + (size_t)y0 * row, (size_t)(y1 - y0) * row * sizeof(float));
}

#ifdef LIBFX_BENCH_OPENCV
/* OpenCV's GaussianBlur (bench_opencv.cpp), the in-memory peer of the blur benches. */
void bench_cv_set_threads(int n);
void bench_cv_gaussian(const float *src, float *dst, int w, int h, int ksize);

/* Median ms of `runs` (at most 64) ksize x ksize blurs of a w x h RGBA frame, after one
 * warm-up. */
static inline double bench_cv_median_ms(const float *src, float *dst, int w, int h, int ksize, int runs)
{
    double t[64];
    runs = runs < 1 ? 1 : runs > 64 ? 64 : runs;
    bench_cv_gaussian(src, dst, w, h, ksize);
    for (int i = 0; i < runs; i++) {
        double t0 = now_ms();
        bench_cv_gaussian(src, dst, w, h, ksize);
        t[i] = now_ms() - t0;
    }
    qsort(t, (size_t)runs, sizeof(double), cmp_d);
    return t[runs / 2];
}
#endif

#endif
