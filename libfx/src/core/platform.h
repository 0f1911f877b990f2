/* The few operating-system services the library needs that POSIX and Windows spell
 * differently: files by UTF-8 name, file identity, replacing a file atomically, reading
 * at an offset, the CPU count, a monotonic clock, page-aligned frame buffers. Every
 * #ifdef _WIN32 of the library lives in platform.c; callers see one interface.
 *
 * Paths are UTF-8 everywhere. On Windows they are converted to UTF-16 and passed to the
 * wide ("W") APIs, so names outside the ANSI code page work. Functions that can fail
 * return 0 on success and -1 with errno set (Win32 errors mapped to the nearest errno),
 * so callers keep reporting strerror(errno). */
#ifndef LIBFX_CORE_PLATFORM_H
#define LIBFX_CORE_PLATFORM_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

/* What the library asks of a file's metadata. dev/ino identify the file: equal pairs
 * mean the same file (POSIX st_dev/st_ino; Windows volume serial and file index). */
typedef struct fx_os_stat {
    uint64_t dev, ino;
    int64_t size;
    int64_t mtime_sec;
    long mtime_nsec;
    int is_dir;
} fx_os_stat;

int fx_os_stat_path(const char *path, fx_os_stat *st);
FILE *fx_os_fopen(const char *path, const char *mode);
/* Creates `path` exclusively (fails with EEXIST if anything is there) and closes it. */
int fx_os_create_new(const char *path);
/* Moves `from` over `to`, replacing it atomically where the file system allows (POSIX
 * rename; Windows MoveFileExW with MOVEFILE_REPLACE_EXISTING | MOVEFILE_WRITE_THROUGH). */
int fx_os_replace(const char *from, const char *to);
int fx_os_remove(const char *path);

/* A file opened for positioned reads from many threads at once (pread / ReadFile with
 * an OVERLAPPED offset). */
typedef intptr_t fx_os_file;
#define FX_OS_NO_FILE ((fx_os_file)-1)
fx_os_file fx_os_open_read(const char *path); /* FX_OS_NO_FILE on failure */
/* Bytes read (0 at end of file), or -1 with errno; retries EINTR itself. */
long long fx_os_pread(fx_os_file f, void *buf, size_t n, uint64_t offset);
void fx_os_close(fx_os_file f);

/* Length of the folder part of `path`, separator included (0 for a bare name): '/'
 * everywhere, also '\\' and a drive's ':' on Windows. */
size_t fx_os_dir_length(const char *path);
/* Whether `path` names a file independently of the current folder ("/x"; on Windows
 * also "\\x", "C:x", "C:\\x"). */
int fx_os_path_is_absolute(const char *path);

int fx_os_cpu_count(void);   /* online CPUs, at least 1 */
long fx_os_pid(void);
double fx_os_now_ms(void);   /* monotonic milliseconds */

/* `n` bytes (a multiple of `align`) aligned to `align` and, where the OS takes the hint,
 * backed by huge pages; released with free(). NULL on failure. */
void *fx_os_alloc_pages(size_t n, size_t align);

#endif
