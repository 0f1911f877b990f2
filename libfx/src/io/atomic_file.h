/* Writing output files safely: never over the input, always through a temporary file
 * in the destination's folder renamed into place (atomic on POSIX file systems; on
 * Windows MoveFileExW replacing the old file, core/platform.h). */
#ifndef LIBFX_IO_ATOMIC_FILE_H
#define LIBFX_IO_ATOMIC_FILE_H

#include "libfx/fx.h"

#ifdef __cplusplus
extern "C" {
#endif

/* FX_ERR_INVALID_ARGUMENT "refusing to overwrite the input file" when `path` and
 * `input` name the same file (same device and inode, or the same real path). */
fx_result fx_refuse_input(fx_context *ctx, const char *path, const char *input);

/* Creates (exclusively) "<dir>/.<name>.tmp-<pid>-<n>" and hands its path back (fx_mem).
 * FX_ERR_IO naming `path` if the folder is not writable. */
fx_result fx_temp_create(fx_context *ctx, const char *path, char **tmp);

/* result == FX_OK: renames tmp over path (FX_ERR_IO on failure). Otherwise, or if the
 * rename fails, removes tmp. Frees tmp. Returns the final result. */
fx_result fx_temp_commit(fx_context *ctx, char *tmp, const char *path, fx_result result);

#ifdef __cplusplus
}
#endif
#endif
