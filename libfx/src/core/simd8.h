/* Eight-lane float vectors (GCC/Clang vector extensions): eight pixels' values of one channel
 * at once (one AVX register in an AVX2 clone, two SSE ones in the baseline). Branch-free
 * selects, and the transposes between 8 interleaved RGBA pixels and 4 channel vectors (two
 * shuffle stages each way). Only inside always-inline helpers and the loops that use them
 * (GCC's ABI note for 32-byte vectors then does not apply). */
#ifndef LIBFX_CORE_SIMD8_H
#define LIBFX_CORE_SIMD8_H

#include <float.h>
#include <stdint.h>
#include <string.h>

#if defined(__clang__)
#  pragma clang diagnostic ignored "-Wpsabi"
#elif defined(__GNUC__)
#  pragma GCC diagnostic ignored "-Wpsabi"
#endif

typedef float v8f __attribute__((vector_size(32)));
typedef int32_t v8i __attribute__((vector_size(32)));

#define S8(v) ((v8f){ (v), (v), (v), (v), (v), (v), (v), (v) })
#define S8I(v) ((v8i){ (v), (v), (v), (v), (v), (v), (v), (v) })
/* m ? a : b, lane by lane (m from a vector comparison: all ones or zero) */
#define SEL8(m, a, b) ((v8f)(((v8i)(a) & (m)) | ((v8i)(b) & ~(m))))

#if defined(__clang__)
#  define FX_SHUF8(a, b, i0, i1, i2, i3, i4, i5, i6, i7) __builtin_shufflevector(a, b, i0, i1, i2, i3, i4, i5, i6, i7)
#else
#  define FX_SHUF8(a, b, i0, i1, i2, i3, i4, i5, i6, i7) __builtin_shuffle(a, b, (v8i){ i0, i1, i2, i3, i4, i5, i6, i7 })
#endif

/* 8 floats at p (any alignment) to a vector, and back. */
static inline __attribute__((always_inline)) v8f fx_load8(const float *p)
{
    v8f v;
    memcpy(&v, p, sizeof v);
    return v;
}

static inline __attribute__((always_inline)) void fx_store8(float *p, v8f v)
{
    memcpy(p, &v, sizeof v);
}

/* NaN -> +0, +-Inf -> +-FLT_MAX, lane by lane (finite4's operations on 8 lanes: the same bits) */
static inline __attribute__((always_inline)) v8f fx_finite8(v8f v)
{
    v = (v8f)((v8i)v & (v == v));
    v = SEL8(v < S8(FLT_MAX), v, S8(FLT_MAX));
    return SEL8(v > S8(-FLT_MAX), v, S8(-FLT_MAX));
}

/* Whether any lane, or every lane, of a comparison mask is set. */
static inline __attribute__((always_inline)) int fx_any8(v8i m)
{
    uint64_t u[4];
    memcpy(u, &m, sizeof u);
    return (u[0] | u[1] | u[2] | u[3]) != 0;
}

static inline __attribute__((always_inline)) int fx_all8(v8i m)
{
    uint64_t u[4];
    memcpy(u, &m, sizeof u);
    return (u[0] & u[1] & u[2] & u[3]) == ~(uint64_t)0;
}

/* 8 pixels of 4 interleaved channels (32 floats at p) to 4 channel vectors. */
static inline __attribute__((always_inline)) void fx_load8x4(const float *p, v8f out[4])
{
    v8f m0, m1, m2, m3;
    memcpy(&m0, p, sizeof m0);
    memcpy(&m1, p + 8, sizeof m1);
    memcpy(&m2, p + 16, sizeof m2);
    memcpy(&m3, p + 24, sizeof m3);
    const v8f t0 = FX_SHUF8(m0, m1, 0, 4, 8, 12, 1, 5, 9, 13), t1 = FX_SHUF8(m0, m1, 2, 6, 10, 14, 3, 7, 11, 15);
    const v8f t2 = FX_SHUF8(m2, m3, 0, 4, 8, 12, 1, 5, 9, 13), t3 = FX_SHUF8(m2, m3, 2, 6, 10, 14, 3, 7, 11, 15);
    out[0] = FX_SHUF8(t0, t2, 0, 1, 2, 3, 8, 9, 10, 11);
    out[1] = FX_SHUF8(t0, t2, 4, 5, 6, 7, 12, 13, 14, 15);
    out[2] = FX_SHUF8(t1, t3, 0, 1, 2, 3, 8, 9, 10, 11);
    out[3] = FX_SHUF8(t1, t3, 4, 5, 6, 7, 12, 13, 14, 15);
}

/* The inverse: 4 channel vectors to 8 interleaved pixels (32 floats at p). */
static inline __attribute__((always_inline)) void fx_store8x4(float *p, const v8f in[4])
{
    const v8f u0 = FX_SHUF8(in[0], in[1], 0, 1, 2, 3, 8, 9, 10, 11), u1 = FX_SHUF8(in[2], in[3], 0, 1, 2, 3, 8, 9, 10, 11);
    const v8f u2 = FX_SHUF8(in[0], in[1], 4, 5, 6, 7, 12, 13, 14, 15), u3 = FX_SHUF8(in[2], in[3], 4, 5, 6, 7, 12, 13, 14, 15);
    const v8f m0 = FX_SHUF8(u0, u1, 0, 4, 8, 12, 1, 5, 9, 13), m1 = FX_SHUF8(u0, u1, 2, 6, 10, 14, 3, 7, 11, 15);
    const v8f m2 = FX_SHUF8(u2, u3, 0, 4, 8, 12, 1, 5, 9, 13), m3 = FX_SHUF8(u2, u3, 2, 6, 10, 14, 3, 7, 11, 15);
    memcpy(p, &m0, sizeof m0);
    memcpy(p + 8, &m1, sizeof m1);
    memcpy(p + 16, &m2, sizeof m2);
    memcpy(p + 24, &m3, sizeof m3);
}

#endif
