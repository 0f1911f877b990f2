/* Output files written safely: through a temporary file renamed into place, never over the input (io/atomic_file.h). */
#include "io/atomic_file.h"
#include "core/context.h"
#include "core/frame.h"
#include "core/mem.h"
#include "core/platform.h"

#include <errno.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

fx_result fx_refuse_input(fx_context *ctx, const char *path, const char *input)
{
    if (!input || !input[0])
        return FX_OK;
    fx_os_stat a, b;
    int same = 0;
    if (fx_os_stat_path(path, &a) == 0 && fx_os_stat_path(input, &b) == 0)
        same = a.dev == b.dev && a.ino == b.ino;
    else if (strcmp(path, input) == 0)
        same = 1;
    if (same)
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "refusing to overwrite the input file '%s'", input);
    return FX_OK;
}

fx_result fx_temp_create(fx_context *ctx, const char *path, char **tmp)
{
    static _Atomic unsigned counter; /* distinct names for threads of one process */
    *tmp = NULL;
    size_t dir = fx_os_dir_length(path);
    const char *base = path + dir;
    if (!base[0])
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "cannot write '%s': it names a folder", path);
    size_t cap = strlen(path) + 64;
    char *t = fx_mem_alloc(cap);
    if (!t)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "cannot write '%s': out of memory", path);
    unsigned n = counter++;
    snprintf(t, cap, "%.*s.%s.tmp-%ld-%u", (int)dir, path, base, fx_os_pid(), n);
    if (fx_os_create_new(t) != 0) {
        int e = errno;
        fx_mem_free(t);
        if (dir)
            return fx_fail(ctx, FX_ERR_IO, "cannot write '%s': folder '%.*s': %s", path, (int)dir, path,
                           strerror(e));
        return fx_fail(ctx, FX_ERR_IO, "cannot write '%s': %s", path, strerror(e));
    }
    *tmp = t;
    return FX_OK;
}

fx_result fx_temp_commit(fx_context *ctx, char *tmp, const char *path, fx_result result)
{
    if (result == FX_OK && fx_os_replace(tmp, path) != 0)
        result = fx_fail(ctx, FX_ERR_IO, "cannot write '%s': renaming the temporary file: %s", path,
                         strerror(errno));
    if (result != FX_OK)
        fx_os_remove(tmp);
    fx_mem_free(tmp);
    return result;
}
