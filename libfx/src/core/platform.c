/* core/platform.h on POSIX systems and on Windows (MinGW-w64): the only file of the
 * library that knows which one it is built for. */
#define _DEFAULT_SOURCE /* madvise(MADV_HUGEPAGE) */
#include "core/platform.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>

#ifdef _WIN32

#define WIN32_LEAN_AND_MEAN
#include <windows.h>

/* The nearest errno of a Win32 error, so messages keep using strerror. */
static int errno_of(DWORD e)
{
    switch (e) {
    case ERROR_FILE_NOT_FOUND:
    case ERROR_PATH_NOT_FOUND:
    case ERROR_INVALID_NAME:
    case ERROR_INVALID_DRIVE:
    case ERROR_BAD_NETPATH:
        return ENOENT;
    case ERROR_ACCESS_DENIED:
    case ERROR_SHARING_VIOLATION:
    case ERROR_LOCK_VIOLATION:
    case ERROR_WRITE_PROTECT:
        return EACCES;
    case ERROR_FILE_EXISTS:
    case ERROR_ALREADY_EXISTS:
        return EEXIST;
    case ERROR_NOT_ENOUGH_MEMORY:
    case ERROR_OUTOFMEMORY:
        return ENOMEM;
    case ERROR_DISK_FULL:
    case ERROR_HANDLE_DISK_FULL:
        return ENOSPC;
    case ERROR_DIRECTORY:
        return ENOTDIR;
    case ERROR_FILENAME_EXCED_RANGE:
        return ENAMETOOLONG;
    default:
        return EIO;
    }
}

static int fail_win32(void)
{
    errno = errno_of(GetLastError());
    return -1;
}

/* UTF-8 to a malloc'd UTF-16 string; NULL with errno on invalid UTF-8 or no memory. */
static wchar_t *widen(const char *s)
{
    int n = MultiByteToWideChar(CP_UTF8, MB_ERR_INVALID_CHARS, s, -1, NULL, 0);
    if (n <= 0) {
        errno = EINVAL;
        return NULL;
    }
    wchar_t *w = malloc((size_t)n * sizeof *w);
    if (!w) {
        errno = ENOMEM;
        return NULL;
    }
    MultiByteToWideChar(CP_UTF8, MB_ERR_INVALID_CHARS, s, -1, w, n);
    return w;
}

int fx_os_stat_path(const char *path, fx_os_stat *st)
{
    wchar_t *w = widen(path);
    if (!w)
        return -1;
    /* no access rights asked: metadata only; BACKUP_SEMANTICS lets it open folders */
    HANDLE h = CreateFileW(w, 0, FILE_SHARE_READ | FILE_SHARE_WRITE | FILE_SHARE_DELETE, NULL, OPEN_EXISTING,
                           FILE_FLAG_BACKUP_SEMANTICS, NULL);
    free(w);
    if (h == INVALID_HANDLE_VALUE)
        return fail_win32();
    BY_HANDLE_FILE_INFORMATION info;
    BOOL ok = GetFileInformationByHandle(h, &info);
    CloseHandle(h);
    if (!ok)
        return fail_win32();
    st->dev = info.dwVolumeSerialNumber;
    st->ino = ((uint64_t)info.nFileIndexHigh << 32) | info.nFileIndexLow;
    st->size = (int64_t)(((uint64_t)info.nFileSizeHigh << 32) | info.nFileSizeLow);
    /* FILETIME: 100 ns ticks since 1601; the Unix epoch is 11644473600 s later */
    uint64_t t = ((uint64_t)info.ftLastWriteTime.dwHighDateTime << 32) | info.ftLastWriteTime.dwLowDateTime;
    st->mtime_sec = (int64_t)(t / 10000000u) - INT64_C(11644473600);
    st->mtime_nsec = (long)(t % 10000000u) * 100;
    st->is_dir = (info.dwFileAttributes & FILE_ATTRIBUTE_DIRECTORY) != 0;
    return 0;
}

FILE *fx_os_fopen(const char *path, const char *mode)
{
    wchar_t *w = widen(path), *m = widen(mode);
    FILE *fp = w && m ? _wfopen(w, m) : NULL;
    free(w);
    free(m);
    return fp;
}

int fx_os_create_new(const char *path)
{
    wchar_t *w = widen(path);
    if (!w)
        return -1;
    HANDLE h = CreateFileW(w, GENERIC_WRITE, FILE_SHARE_READ | FILE_SHARE_WRITE | FILE_SHARE_DELETE, NULL,
                           CREATE_NEW, FILE_ATTRIBUTE_NORMAL, NULL);
    free(w);
    if (h == INVALID_HANDLE_VALUE)
        return fail_win32();
    CloseHandle(h);
    return 0;
}

int fx_os_replace(const char *from, const char *to)
{
    wchar_t *a = widen(from), *b = widen(to);
    int r = -1;
    if (a && b)
        r = MoveFileExW(a, b, MOVEFILE_REPLACE_EXISTING | MOVEFILE_WRITE_THROUGH) ? 0 : fail_win32();
    free(a);
    free(b);
    return r;
}

int fx_os_remove(const char *path)
{
    wchar_t *w = widen(path);
    if (!w)
        return -1;
    int r = DeleteFileW(w) ? 0 : fail_win32();
    free(w);
    return r;
}

fx_os_file fx_os_open_read(const char *path)
{
    wchar_t *w = widen(path);
    if (!w)
        return FX_OS_NO_FILE;
    /* not inherited by child processes (O_CLOEXEC): the default without SECURITY_ATTRIBUTES */
    HANDLE h = CreateFileW(w, GENERIC_READ, FILE_SHARE_READ | FILE_SHARE_WRITE | FILE_SHARE_DELETE, NULL,
                           OPEN_EXISTING, FILE_ATTRIBUTE_NORMAL, NULL);
    free(w);
    if (h == INVALID_HANDLE_VALUE) {
        fail_win32();
        return FX_OS_NO_FILE;
    }
    return (fx_os_file)h;
}

long long fx_os_pread(fx_os_file f, void *buf, size_t n, uint64_t offset)
{
    /* the OVERLAPPED offset makes each read independent of the handle's file pointer,
     * so threads may read one handle at once, like pread */
    OVERLAPPED ov;
    memset(&ov, 0, sizeof ov);
    ov.Offset = (DWORD)offset;
    ov.OffsetHigh = (DWORD)(offset >> 32);
    DWORD want = n > 0x40000000u ? 0x40000000u : (DWORD)n, got = 0;
    if (!ReadFile((HANDLE)f, buf, want, &got, &ov)) {
        if (GetLastError() == ERROR_HANDLE_EOF)
            return 0;
        return fail_win32();
    }
    return (long long)got;
}

void fx_os_close(fx_os_file f)
{
    if (f != FX_OS_NO_FILE)
        CloseHandle((HANDLE)f);
}

size_t fx_os_dir_length(const char *path)
{
    size_t n = 0;
    for (size_t i = 0; path[i]; i++)
        if (path[i] == '/' || path[i] == '\\' || (i == 1 && path[i] == ':'))
            n = i + 1;
    return n;
}

int fx_os_path_is_absolute(const char *path)
{
    return path[0] == '/' || path[0] == '\\' || (path[0] && path[1] == ':');
}

int fx_os_cpu_count(void)
{
    /* all processor groups: GetSystemInfo counts only the caller's group (64 at most) */
    DWORD n = GetActiveProcessorCount(ALL_PROCESSOR_GROUPS);
    return n > 0 ? (int)n : 1;
}

long fx_os_pid(void)
{
    return (long)GetCurrentProcessId();
}

double fx_os_now_ms(void)
{
    static LARGE_INTEGER freq; /* constant while the system runs; a racy first write is harmless */
    LARGE_INTEGER t;
    if (!freq.QuadPart)
        QueryPerformanceFrequency(&freq);
    QueryPerformanceCounter(&t);
    return (double)t.QuadPart * 1e3 / (double)freq.QuadPart;
}

void *fx_os_alloc_pages(size_t n, size_t align)
{
    /* Large pages on Windows need a privilege users lack; the C runtime's heap (16-byte
     * aligned, like glibc's malloc for smaller buffers) keeps free() as the release. */
    (void)align;
    return malloc(n);
}

#else /* POSIX */

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

int fx_os_stat_path(const char *path, fx_os_stat *st)
{
    struct stat s;
    if (stat(path, &s) != 0)
        return -1;
    st->dev = (uint64_t)s.st_dev;
    st->ino = (uint64_t)s.st_ino;
    st->size = (int64_t)s.st_size;
    st->mtime_sec = (int64_t)s.st_mtim.tv_sec;
    st->mtime_nsec = (long)s.st_mtim.tv_nsec;
    st->is_dir = S_ISDIR(s.st_mode) != 0;
    return 0;
}

FILE *fx_os_fopen(const char *path, const char *mode)
{
    return fopen(path, mode);
}

int fx_os_create_new(const char *path)
{
    int fd = open(path, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd < 0)
        return -1;
    close(fd);
    return 0;
}

int fx_os_replace(const char *from, const char *to)
{
    return rename(from, to);
}

int fx_os_remove(const char *path)
{
    return unlink(path);
}

fx_os_file fx_os_open_read(const char *path)
{
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    return fd < 0 ? FX_OS_NO_FILE : (fx_os_file)fd;
}

long long fx_os_pread(fx_os_file f, void *buf, size_t n, uint64_t offset)
{
    for (;;) {
        ssize_t r = pread((int)f, buf, n, (off_t)offset);
        if (r < 0 && errno == EINTR)
            continue;
        return (long long)r;
    }
}

void fx_os_close(fx_os_file f)
{
    if (f != FX_OS_NO_FILE)
        close((int)f);
}

size_t fx_os_dir_length(const char *path)
{
    const char *slash = strrchr(path, '/');
    return slash ? (size_t)(slash - path + 1) : 0;
}

int fx_os_path_is_absolute(const char *path)
{
    return path[0] == '/';
}

int fx_os_cpu_count(void)
{
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n > 0 ? (int)n : 1;
}

long fx_os_pid(void)
{
    return (long)getpid();
}

double fx_os_now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec / 1e6;
}

void *fx_os_alloc_pages(size_t n, size_t align)
{
    void *p = NULL;
    if (posix_memalign(&p, align, n) != 0)
        return NULL;
#ifdef MADV_HUGEPAGE
    (void)madvise(p, n, MADV_HUGEPAGE); /* a hint: without THP the pages stay small */
#endif
    return p;
}

#endif
