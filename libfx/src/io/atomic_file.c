/* Output files written safely: through a temporary file renamed into place, never over the input (io/atomic_file.h). */
#include "io/atomic_file.h"
#include "core/context.h"
#include "core/frame.h"
#include "core/mem.h"

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

fx_result fx_refuse_input(fx_context *ctx, const char *path, const char *input)
{
    if (!input || !input[0])
        return FX_OK;
    struct stat a, b;
    int same = 0;
    if (stat(path, &a) == 0 && stat(input, &b) == 0)
        same = a.st_dev == b.st_dev && a.st_ino == b.st_ino;
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
    const char *slash = strrchr(path, '/');
    size_t dir = slash ? (size_t)(slash - path + 1) : 0;
    const char *base = path + dir;
    if (!base[0])
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "cannot write '%s': it names a folder", path);
    size_t cap = strlen(path) + 64;
    char *t = fx_mem_alloc(cap);
    if (!t)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "cannot write '%s': out of memory", path);
    unsigned n = counter++;
    snprintf(t, cap, "%.*s.%s.tmp-%ld-%u", (int)dir, path, base, (long)getpid(), n);
    int fd = open(t, O_WRONLY | O_CREAT | O_EXCL, 0666);
    if (fd < 0) {
        int e = errno;
        fx_mem_free(t);
        if (dir)
            return fx_fail(ctx, FX_ERR_IO, "cannot write '%s': folder '%.*s': %s", path, (int)dir, path,
                           strerror(e));
        return fx_fail(ctx, FX_ERR_IO, "cannot write '%s': %s", path, strerror(e));
    }
    close(fd);
    *tmp = t;
    return FX_OK;
}

fx_result fx_temp_commit(fx_context *ctx, char *tmp, const char *path, fx_result result)
{
    if (result == FX_OK && rename(tmp, path) != 0)
        result = fx_fail(ctx, FX_ERR_IO, "cannot write '%s': renaming the temporary file: %s", path,
                         strerror(errno));
    if (result != FX_OK)
        unlink(tmp);
    fx_mem_free(tmp);
    return result;
}
