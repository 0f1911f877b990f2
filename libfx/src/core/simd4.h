/* Four-lane float vectors (GCC/Clang vector extensions): one RGBA pixel per vector, or
 * four values at once. Branch-free lane selects, so loops stay vectorised. */
#ifndef LIBFX_CORE_SIMD4_H
#define LIBFX_CORE_SIMD4_H

#include <float.h>
#include <math.h>
#include <stdint.h>
#include <string.h>
#ifdef __SSE__
#include <xmmintrin.h>
#endif

typedef float v4f __attribute__((vector_size(16)));
typedef int32_t v4i __attribute__((vector_size(16)));

#define V4(v) ((v4f){ (v), (v), (v), (v) })

/* unaligned load / store of four floats (an RGBA pixel) */
static inline v4f ld4(const float *p)
{
    v4f v;
    memcpy(&v, p, sizeof v);
    return v;
}

static inline void st4(float *p, v4f v)
{
    memcpy(p, &v, sizeof v);
}

/* m ? a : b, lane by lane (m from a vector comparison: all ones or zero) */
static inline v4f sel4(v4i m, v4f a, v4f b)
{
    return (v4f)(((v4i)a & m) | ((v4i)b & ~m));
}

/* lane-wise min / max of ordered values (SSE's minps/maxps where the target has them) */
static inline v4f min4(v4f a, v4f b)
{
#ifdef __SSE__
    return (v4f)_mm_min_ps((__m128)a, (__m128)b);
#else
    return sel4(a < b, a, b);
#endif
}

static inline v4f max4(v4f a, v4f b)
{
#ifdef __SSE__
    return (v4f)_mm_max_ps((__m128)a, (__m128)b);
#else
    return sel4(a > b, a, b);
#endif
}

/* Lanes that are NaN or <= 0 become +0, lanes above hi become hi (hi not NaN): the same
 * bits as sel4(v > 0, v, 0) then sel4(v < hi, v, hi), in three instructions. */
static inline v4f clamp4_pos(v4f v, v4f hi)
{
    return min4((v4f)((v4i)v & (v > V4(0.0f))), hi);
}

/* correctly rounded square root of each lane (sqrtf's value) */
static inline v4f sqrt4(v4f v)
{
#ifdef __SSE__
    return (v4f)_mm_sqrt_ps((__m128)v);
#else
    return (v4f){ sqrtf(v[0]), sqrtf(v[1]), sqrtf(v[2]), sqrtf(v[3]) };
#endif
}

/* NaN -> 0, +-Inf -> +-FLT_MAX */
static inline v4f finite4(v4f v)
{
    v = (v4f)((v4i)v & (v == v)); /* NaN lanes to +0; then min/max need no select */
    return max4(min4(v, V4(FLT_MAX)), V4(-FLT_MAX));
}

/* Three interleaved floats of four points (the XYZ of four Normal or Position pixels: 12
 * floats at q) as three vectors: the four x, the four y, the four z. */
static inline void ld3x4(const float *q, v4f *x, v4f *y, v4f *z)
{
#ifdef __SSE__
    const __m128 p0 = _mm_loadu_ps(q), p1 = _mm_loadu_ps(q + 4), p2 = _mm_loadu_ps(q + 8);
    const __m128 x01 = _mm_shuffle_ps(p0, p1, _MM_SHUFFLE(2, 0, 3, 0)); /* x0 x1 y1 x2 */
    const __m128 x23 = _mm_shuffle_ps(p1, p2, _MM_SHUFFLE(2, 1, 3, 2)); /* x2 y2 x3 y3 */
    *x = (v4f)_mm_shuffle_ps(x01, x23, _MM_SHUFFLE(2, 0, 1, 0));
    const __m128 y01 = _mm_shuffle_ps(p0, p1, _MM_SHUFFLE(0, 0, 1, 1)); /* y0 y0 y1 y1 */
    *y = (v4f)_mm_shuffle_ps(y01, x23, _MM_SHUFFLE(3, 1, 2, 0));
    const __m128 z01 = _mm_shuffle_ps(p0, p1, _MM_SHUFFLE(1, 1, 2, 2)); /* z0 z0 z1 z1 */
    const __m128 z23 = _mm_shuffle_ps(p2, p2, _MM_SHUFFLE(3, 3, 0, 0)); /* z2 z2 z3 z3 */
    *z = (v4f)_mm_shuffle_ps(z01, z23, _MM_SHUFFLE(2, 0, 2, 0));
#else
    *x = (v4f){ q[0], q[3], q[6], q[9] };
    *y = (v4f){ q[1], q[4], q[7], q[10] };
    *z = (v4f){ q[2], q[5], q[8], q[11] };
#endif
}

/* Whether every lane of a comparison mask is set. */
static inline int all4(v4i m)
{
#ifdef __SSE__
    return _mm_movemask_ps((__m128)m) == 15;
#else
    return (m[0] & m[1] & m[2] & m[3]) != 0;
#endif
}

#endif
