/* Small vector and matrix helpers (static inline). Matrices are float[16] row-major,
 * column-vector convention (p' = M p), like fx_camera and Blender. */
#ifndef LIBFX_MATH_VEC_H
#define LIBFX_MATH_VEC_H

#include <float.h>
#include <math.h>
#include <string.h>

typedef struct fx_vec2 { float x, y; } fx_vec2;
typedef struct fx_vec3 { float x, y, z; } fx_vec3;
typedef struct fx_vec4 { float x, y, z, w; } fx_vec4;

/* Below this length a vector has no direction: normalising returns the fallback. */
#define FX_VEC_EPS 1e-12f

static inline fx_vec3 fx_v3(float x, float y, float z) { fx_vec3 r = {x, y, z}; return r; }
static inline fx_vec3 fx_v3_add(fx_vec3 a, fx_vec3 b) { return fx_v3(a.x + b.x, a.y + b.y, a.z + b.z); }
static inline fx_vec3 fx_v3_sub(fx_vec3 a, fx_vec3 b) { return fx_v3(a.x - b.x, a.y - b.y, a.z - b.z); }
static inline fx_vec3 fx_v3_scale(fx_vec3 a, float s) { return fx_v3(a.x * s, a.y * s, a.z * s); }
static inline fx_vec3 fx_v3_mul(fx_vec3 a, fx_vec3 b) { return fx_v3(a.x * b.x, a.y * b.y, a.z * b.z); }
static inline float fx_v3_dot(fx_vec3 a, fx_vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline fx_vec3 fx_v3_cross(fx_vec3 a, fx_vec3 b)
{
    return fx_v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static inline float fx_v3_length(fx_vec3 a) { return sqrtf(fx_v3_dot(a, a)); }
static inline fx_vec3 fx_v3_lerp(fx_vec3 a, fx_vec3 b, float t) { return fx_v3_add(a, fx_v3_scale(fx_v3_sub(b, a), t)); }

/* Unit vector, or `fallback` when a is (near) zero or not finite. */
static inline fx_vec3 fx_v3_normalize_or(fx_vec3 a, fx_vec3 fallback)
{
    float l2 = fx_v3_dot(a, a);
    if (!(l2 > FX_VEC_EPS) || !isfinite(l2))
        return fallback;
    return fx_v3_scale(a, 1.0f / sqrtf(l2));
}

/* Reflects incident direction i about unit normal n. */
static inline fx_vec3 fx_v3_reflect(fx_vec3 i, fx_vec3 n)
{
    return fx_v3_sub(i, fx_v3_scale(n, 2.0f * fx_v3_dot(i, n)));
}

static inline float fx_clampf(float v, float lo, float hi) { return v < lo ? lo : v > hi ? hi : v; }
static inline float fx_saturate(float v) { return fx_clampf(v, 0.0f, 1.0f); }
/* NaN -> 0, +-Inf -> +-FLT_MAX (branch-free: compiles to selects) */
static inline float fx_finitef(float v)
{
    v = v == v ? v : 0.0f;
    v = v < FLT_MAX ? v : FLT_MAX;
    return v > -FLT_MAX ? v : -FLT_MAX;
}
static inline float fx_lerpf(float a, float b, float t) { return a + (b - a) * t; }
static inline float fx_smoothstep(float e0, float e1, float x)
{
    float d = e1 - e0;
    float t = fabsf(d) > 1e-20f ? fx_saturate((x - e0) / d) : (x >= e1 ? 1.0f : 0.0f);
    return t * t * (3.0f - 2.0f * t);
}

/* ---- 4x4 matrices ---- */

static inline fx_vec4 fx_m4_mul_v4(const float m[16], fx_vec4 v)
{
    fx_vec4 r;
    r.x = m[0] * v.x + m[1] * v.y + m[2] * v.z + m[3] * v.w;
    r.y = m[4] * v.x + m[5] * v.y + m[6] * v.z + m[7] * v.w;
    r.z = m[8] * v.x + m[9] * v.y + m[10] * v.z + m[11] * v.w;
    r.w = m[12] * v.x + m[13] * v.y + m[14] * v.z + m[15] * v.w;
    return r;
}

/* Transforms a point (w = 1), without the perspective divide. */
static inline fx_vec3 fx_m4_point(const float m[16], fx_vec3 p)
{
    return fx_v3(m[0] * p.x + m[1] * p.y + m[2] * p.z + m[3], m[4] * p.x + m[5] * p.y + m[6] * p.z + m[7],
                 m[8] * p.x + m[9] * p.y + m[10] * p.z + m[11]);
}

/* Transforms a direction (w = 0). */
static inline fx_vec3 fx_m4_dir(const float m[16], fx_vec3 d)
{
    return fx_v3(m[0] * d.x + m[1] * d.y + m[2] * d.z, m[4] * d.x + m[5] * d.y + m[6] * d.z,
                 m[8] * d.x + m[9] * d.y + m[10] * d.z);
}

static inline void fx_m4_mul(const float a[16], const float b[16], float out[16])
{
    float r[16];
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++)
            r[i * 4 + j] = a[i * 4] * b[j] + a[i * 4 + 1] * b[4 + j] + a[i * 4 + 2] * b[8 + j] + a[i * 4 + 3] * b[12 + j];
    memcpy(out, r, sizeof r);
}

static inline void fx_m4_transpose(const float m[16], float out[16])
{
    float r[16];
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++)
            r[j * 4 + i] = m[i * 4 + j];
    memcpy(out, r, sizeof r);
}

/* Inverse in double; returns 0 (and leaves out untouched) if m is singular or not finite. */
static inline int fx_m4_inverse(const float m[16], float out[16])
{
    double a[4][8];
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 8; j++)
            a[i][j] = j < 4 ? (double)m[i * 4 + j] : (j - 4 == i ? 1.0 : 0.0);
    for (int c = 0; c < 4; c++) {
        int piv = c;
        for (int r = c + 1; r < 4; r++)
            if (fabs(a[r][c]) > fabs(a[piv][c]))
                piv = r;
        if (!(fabs(a[piv][c]) > 1e-30))
            return 0;
        if (piv != c)
            for (int j = 0; j < 8; j++) {
                double t = a[c][j];
                a[c][j] = a[piv][j];
                a[piv][j] = t;
            }
        double inv = 1.0 / a[c][c];
        for (int j = 0; j < 8; j++)
            a[c][j] *= inv;
        for (int r = 0; r < 4; r++) {
            if (r == c)
                continue;
            double f = a[r][c];
            for (int j = 0; j < 8; j++)
                a[r][j] -= f * a[c][j];
        }
    }
    float r[16];
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++) {
            r[i * 4 + j] = (float)a[i][j + 4];
            if (!isfinite(r[i * 4 + j]))
                return 0;
        }
    memcpy(out, r, sizeof r);
    return 1;
}

#endif
