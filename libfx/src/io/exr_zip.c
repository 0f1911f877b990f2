/* EXR ZIP chunks through libdeflate: see io/exr_zip.h for the format. */
#include "io/exr_zip.h"
#include "core/mem.h"

#include <string.h>

#ifdef LIBFX_HAVE_LIBDEFLATE
#include <libdeflate.h>
#endif

struct fx_exr_zip {
#ifdef LIBFX_HAVE_LIBDEFLATE
    struct libdeflate_compressor *c;
#endif
    uint8_t *scratch;
    size_t scratch_cap;
};

void fx_exr_zip_predict(const uint8_t *in, size_t n, uint8_t *out)
{
    if (n == 0)
        return;
    /* Reordered array r: r[k] = in[2k] for k < h, r[h + k] = in[2k + 1]. Each output
     * byte is r[i] - r[i-1] + 128, computed straight from `in` so the loops have no
     * carried dependency (and vectorise). */
    size_t h = (n + 1) / 2, odd = n / 2;
    uint8_t *lo = out, *hi = out + h;
    lo[0] = in[0];
    for (size_t k = 1; k < h; k++)
        lo[k] = (uint8_t)(in[2 * k] - in[2 * k - 2] + 128u);
    if (odd) {
        hi[0] = (uint8_t)(in[1] - in[2 * (h - 1)] + 128u);
        for (size_t k = 1; k < odd; k++)
            hi[k] = (uint8_t)(in[2 * k + 1] - in[2 * k - 1] + 128u);
    }
}

#ifdef LIBFX_HAVE_LIBDEFLATE

int fx_exr_zip_available(void)
{
    return 1;
}

/* libdeflate's level for the writer's ZIP level (1..9, zlib's scale). */
static int deflate_level(int zip_level)
{
    /* The same number: libdeflate's 1..9 are meant as zlib's, and on renders its
     * levels 1..6 differ by under 0.5% in size and little in time (docs/performance.md,
     * "Writing EXR: ZIP through libfx's compressor"). */
    if (zip_level < 1)
        zip_level = 1;
    if (zip_level > 9)
        zip_level = 9;
    return zip_level;
}

fx_exr_zip *fx_exr_zip_new(int zip_level)
{
    fx_exr_zip *z = fx_mem_calloc(1, sizeof *z);
    if (!z)
        return NULL;
    z->c = libdeflate_alloc_compressor(deflate_level(zip_level));
    if (!z->c) {
        fx_mem_free(z);
        return NULL;
    }
    return z;
}

void fx_exr_zip_free(fx_exr_zip *z)
{
    if (!z)
        return;
    libdeflate_free_compressor(z->c);
    fx_mem_free(z->scratch);
    fx_mem_free(z);
}

size_t fx_exr_zip_bound(fx_exr_zip *z, size_t n)
{
    size_t b = libdeflate_zlib_compress_bound(z->c, n);
    return b > n ? b : n;
}

int fx_exr_zip_compress(fx_exr_zip *z, const uint8_t *in, size_t n, uint8_t *out, size_t cap, size_t *out_size)
{
    if (cap < n)
        return -1;
    if (n > z->scratch_cap) {
        uint8_t *grown = fx_mem_realloc(z->scratch, n);
        if (!grown)
            return -1;
        z->scratch = grown;
        z->scratch_cap = n;
    }
    fx_exr_zip_predict(in, n, z->scratch);
    size_t got = libdeflate_zlib_compress(z->c, z->scratch, n, out, cap);
    /* 0: it did not fit in cap (>= n), so it would not have been smaller. */
    if (got == 0 || got >= n) {
        memcpy(out, in, n);
        got = n;
    }
    *out_size = got;
    return 0;
}

#else /* no libdeflate: the writer keeps OpenEXRCore's zlib path */

int fx_exr_zip_available(void)
{
    return 0;
}

fx_exr_zip *fx_exr_zip_new(int zip_level)
{
    (void)zip_level;
    return NULL;
}

void fx_exr_zip_free(fx_exr_zip *z)
{
    (void)z;
}

size_t fx_exr_zip_bound(fx_exr_zip *z, size_t n)
{
    (void)z;
    return n;
}

int fx_exr_zip_compress(fx_exr_zip *z, const uint8_t *in, size_t n, uint8_t *out, size_t cap, size_t *out_size)
{
    (void)z, (void)in, (void)n, (void)out, (void)cap, (void)out_size;
    return -1;
}

#endif
