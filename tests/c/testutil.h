/* A tiny test harness: CHECK never aborts, tu_finish() prints "N passed, N failed"
 * and returns the exit code. Helpers build synthetic frames and compare buffers. */
#ifndef LIBFX_TESTUTIL_H
#define LIBFX_TESTUTIL_H

#include "libfx/fx.h"

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

extern int tu_checks, tu_failures;

#define CHECK(cond)                                                                   \
    do {                                                                              \
        tu_checks++;                                                                  \
        if (!(cond)) {                                                                \
            tu_failures++;                                                            \
            fprintf(stderr, "%s:%d: CHECK failed: %s\n", __FILE__, __LINE__, #cond);  \
        }                                                                             \
    } while (0)

/* Checks that an fx call returned FX_OK, printing the context's message if not. */
#define CHECK_OK(ctx, expr)                                                           \
    do {                                                                              \
        tu_checks++;                                                                  \
        fx_result tu_r_ = (expr);                                                     \
        if (tu_r_ != FX_OK) {                                                         \
            tu_failures++;                                                            \
            fprintf(stderr, "%s:%d: %s returned %s: %s\n", __FILE__, __LINE__, #expr, \
                    fx_result_name(tu_r_), fx_context_error(ctx));                    \
        }                                                                             \
    } while (0)

/* Checks an expected failure code and that the message contains `needle`. */
#define CHECK_FAIL(ctx, expr, code, needle)                                           \
    do {                                                                              \
        tu_checks++;                                                                  \
        fx_result tu_r_ = (expr);                                                     \
        if (tu_r_ != (code) || !tu_contains(fx_context_error(ctx), needle)) {         \
            tu_failures++;                                                            \
            fprintf(stderr, "%s:%d: %s: expected %s with \"%s\", got %s: \"%s\"\n",   \
                    __FILE__, __LINE__, #expr, fx_result_name(code), needle,          \
                    fx_result_name(tu_r_), fx_context_error(ctx));                    \
        }                                                                             \
    } while (0)

int tu_contains(const char *haystack, const char *needle);
int tu_finish(const char *name);
/* A w x h frame with a Combined pass filled by a smooth colourful pattern (seeded). */
fx_frame *tu_pattern_frame(fx_context *ctx, int w, int h, unsigned seed);
/* Max |a-b| over n floats (+inf when either buffer holds a NaN anywhere, or an infinity
 * against a finite value; equal values, infinities included, differ by 0), and whether
 * every value is finite. */
double tu_max_abs_diff(const float *a, const float *b, size_t n);
int tu_all_finite(const float *a, size_t n);
/* A whole file, NUL-terminated, malloc'ed (len may be NULL); NULL if unreadable. */
char *tu_slurp(const char *path, size_t *len);
int tu_file_exists(const char *path); /* can be opened for reading */
/* A fresh empty directory under /tmp (Windows: its temporary folder) for this test;
 * returns its path (static storage). */
const char *tu_tmpdir(const char *name);
/* The effects' documented hash (libfx/src/math/hash.h), written out again for the
 * independent references of the tests (they must not call the library's code): lowbias32,
 * a boost-style combine of (a, b, c, d), and the top 24 bits as a unit double. */
uint32_t tu_ref_hash_u32(uint32_t x);
uint32_t tu_ref_hash4(int32_t a, int32_t b, int32_t c, int32_t d);
double tu_ref_unit(uint32_t h);

#endif
