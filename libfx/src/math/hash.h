/* Deterministic randomness: a hash of integer coordinates (pixel, cell, frame, seed),
 * never rand(). Same inputs, same bits, on every thread count and machine. */
#ifndef LIBFX_MATH_HASH_H
#define LIBFX_MATH_HASH_H

#include <stdint.h>

/* A 32-bit integer mix with full avalanche (lowbias32 by Chris Wellons). */
static inline uint32_t fx_hash_u32(uint32_t x)
{
    x ^= x >> 16;
    x *= 0x7feb352dU;
    x ^= x >> 15;
    x *= 0x846ca68bU;
    x ^= x >> 16;
    return x;
}

static inline uint32_t fx_hash_combine(uint32_t h, uint32_t v)
{
    return fx_hash_u32(h ^ (v + 0x9e3779b9U + (h << 6) + (h >> 2)));
}

/* Hash of up to four integers (e.g. x, y, frame, seed). */
static inline uint32_t fx_hash4(int32_t a, int32_t b, int32_t c, int32_t d)
{
    uint32_t h = fx_hash_u32((uint32_t)a);
    h = fx_hash_combine(h, (uint32_t)b);
    h = fx_hash_combine(h, (uint32_t)c);
    return fx_hash_combine(h, (uint32_t)d);
}

/* Uniform float in [0, 1) from a hash (24 bits: exact in float). */
static inline float fx_hash_to_unit(uint32_t h)
{
    return (float)(h >> 8) * (1.0f / 16777216.0f);
}

static inline float fx_rand4(int32_t a, int32_t b, int32_t c, int32_t d)
{
    return fx_hash_to_unit(fx_hash4(a, b, c, d));
}

#endif
