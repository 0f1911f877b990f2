#include "testutil.h"
#include "testos.h"
#include "core/platform.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

int tu_checks, tu_failures;

int tu_contains(const char *haystack, const char *needle)
{
    return haystack && needle && strstr(haystack, needle) != NULL;
}

int tu_finish(const char *name)
{
    printf("%s: %d passed, %d failed\n", name, tu_checks - tu_failures, tu_failures);
    return tu_failures ? 1 : 0;
}

fx_frame *tu_pattern_frame(fx_context *ctx, int w, int h, unsigned seed)
{
    fx_frame *f = NULL;
    if (fx_frame_new(ctx, w, h, &f) != FX_OK)
        return NULL;
    float *px = malloc((size_t)w * h * 4 * sizeof(float));
    if (!px) {
        fx_frame_free(f);
        return NULL;
    }
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            float *p = px + ((size_t)y * w + x) * 4;
            float fx_ = (float)x / (w > 1 ? w - 1 : 1), fy = (float)y / (h > 1 ? h - 1 : 1);
            uint32_t hsh = (uint32_t)(x * 73856093u) ^ (uint32_t)(y * 19349663u) ^ (seed * 83492791u);
            hsh ^= hsh >> 13;
            hsh *= 0x5bd1e995u;
            hsh ^= hsh >> 15;
            p[0] = 0.5f + 0.5f * sinf(6.0f * fx_ + seed);
            p[1] = fy * 1.5f;
            p[2] = (float)(hsh & 0xffff) / 65535.0f;
            p[3] = 1.0f;
        }
    fx_frame_add_pass(f, "Combined", 4, px);
    free(px);
    return f;
}

double tu_max_abs_diff(const float *a, const float *b, size_t n)
{
    double m = 0;
    for (size_t i = 0; i < n; i++) {
        if (isnan(a[i]) || isnan(b[i]))
            return INFINITY; /* a NaN anywhere: fails every "< tol", passes "> tol" */
        if (a[i] == b[i])
            continue; /* equal infinities too (inf - inf would be NaN) */
        double d = fabs((double)a[i] - (double)b[i]);
        if (d > m)
            m = d; /* an infinity against a finite value: +inf */
    }
    return m;
}

int tu_all_finite(const float *a, size_t n)
{
    for (size_t i = 0; i < n; i++)
        if (!isfinite(a[i]))
            return 0;
    return 1;
}

const char *tu_tmpdir(const char *name)
{
    static char path[512];
    /* a fresh folder: Wine reuses small process ids, and a folder an earlier run left that
     * cannot be removed (seen: a UTF-8 name under Wine) takes the next suffix */
    for (int k = 0; k < 100; k++) {
        if (k == 0)
            snprintf(path, sizeof path, "%s/libfx-test-%s-%ld", tu_temp_root(), name, fx_os_pid());
        else
            snprintf(path, sizeof path, "%s/libfx-test-%s-%ld-%d", tu_temp_root(), name, fx_os_pid(), k);
        tu_rmtree(path);
        if (tu_mkdir(path, 0700) == 0)
            break;
    }
    return path;
}

int tu_file_exists(const char *path)
{
    FILE *fp = fx_os_fopen(path, "rb");
    if (fp)
        fclose(fp);
    return fp != NULL;
}

char *tu_slurp(const char *path, size_t *len)
{
    FILE *fp = fx_os_fopen(path, "rb");
    if (!fp)
        return NULL;
    fseek(fp, 0, SEEK_END);
    long n = ftell(fp);
    fseek(fp, 0, SEEK_SET);
    char *b = n >= 0 ? malloc((size_t)n + 1) : NULL;
    if (b && fread(b, 1, (size_t)n, fp) != (size_t)n) {
        free(b);
        b = NULL;
    }
    fclose(fp);
    if (b)
        b[n] = '\0';
    if (len)
        *len = b ? (size_t)n : 0;
    return b;
}

uint32_t tu_ref_hash_u32(uint32_t x)
{
    x ^= x >> 16;
    x *= 0x7feb352dU;
    x ^= x >> 15;
    x *= 0x846ca68bU;
    x ^= x >> 16;
    return x;
}

uint32_t tu_ref_hash4(int32_t a, int32_t b, int32_t c, int32_t d)
{
    const int32_t v[3] = {b, c, d};
    uint32_t h = tu_ref_hash_u32((uint32_t)a);
    for (int k = 0; k < 3; k++)
        h = tu_ref_hash_u32(h ^ ((uint32_t)v[k] + 0x9e3779b9U + (h << 6) + (h >> 2)));
    return h;
}

double tu_ref_unit(uint32_t h)
{
    return (double)(h >> 8) / 16777216.0;
}
