/* Reading small text files (recipes, sidecars) whole, with a size cap. */
#include "core/textfile.h"
#include "core/context.h"
#include "core/mem.h"
#include "core/platform.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>

fx_result fx_read_text_file(const fx_context *ctx, const char *path, size_t max_bytes, const char *what,
                            char **out)
{
    *out = NULL;
    FILE *fp = fx_os_fopen(path, "rb");
    if (!fp)
        return fx_fail(ctx, FX_ERR_IO, "cannot open %s '%s': %s", what, path, strerror(errno));
    char *buf = NULL;
    size_t len = 0, cap = 0;
    fx_result r = FX_OK;
    for (;;) {
        if (len + 4096 + 1 > cap) {
            size_t ncap = cap ? cap * 2 : 8192;
            if (ncap > max_bytes + 4096 + 1)
                ncap = max_bytes + 4096 + 1;
            char *nb = fx_mem_realloc(buf, ncap);
            if (!nb) {
                r = fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "out of memory reading %s '%s'", what, path);
                break;
            }
            buf = nb;
            cap = ncap;
        }
        size_t n = fread(buf + len, 1, cap - len - 1, fp);
        len += n;
        if (len > max_bytes) {
            r = fx_fail(ctx, FX_ERR_BAD_RECIPE, "%s '%s' is larger than %zu KiB", what, path, max_bytes >> 10);
            break;
        }
        if (n == 0) {
            if (ferror(fp))
                r = fx_fail(ctx, FX_ERR_IO, "cannot read %s '%s'", what, path);
            break;
        }
    }
    fclose(fp);
    if (r) {
        fx_mem_free(buf);
        return r;
    }
    buf[len] = '\0';
    *out = buf;
    return FX_OK;
}
