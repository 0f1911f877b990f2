/* Four-lane float vectors (GCC/Clang vector extensions): one RGBA pixel per vector, or
 * four values at once. Branch-free lane selects, so loops stay vectorised. */
#ifndef LIBFX_CORE_SIMD4_H
#define LIBFX_CORE_SIMD4_H

#include <float.h>
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

/* NaN -> 0, +-Inf -> +-FLT_MAX */
static inline v4f finite4(v4f v)
{
    v = (v4f)((v4i)v & (v == v)); /* NaN lanes to +0; then min/max need no select */
    return max4(min4(v, V4(FLT_MAX)), V4(-FLT_MAX));
}

#endif
