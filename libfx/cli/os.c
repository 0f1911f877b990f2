/* cli/os.h on POSIX systems and on Windows (MinGW-w64). */
#include "os.h"

#include <errno.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>

#ifdef _WIN32

#define WIN32_LEAN_AND_MEAN
#include <windows.h>
#include <io.h>
#include <shellapi.h>
#include <stdio.h>

static wchar_t *widen(const char *s)
{
    int n = MultiByteToWideChar(CP_UTF8, MB_ERR_INVALID_CHARS, s, -1, NULL, 0);
    if (n <= 0) {
        errno = EINVAL;
        return NULL;
    }
    wchar_t *w = malloc((size_t)n * sizeof *w);
    if (w)
        MultiByteToWideChar(CP_UTF8, MB_ERR_INVALID_CHARS, s, -1, w, n);
    else
        errno = ENOMEM;
    return w;
}

static char *narrow(const wchar_t *w)
{
    int n = WideCharToMultiByte(CP_UTF8, 0, w, -1, NULL, 0, NULL, NULL);
    char *s = n > 0 ? malloc((size_t)n) : NULL;
    if (s)
        WideCharToMultiByte(CP_UTF8, 0, w, -1, s, n, NULL, NULL);
    return s;
}

static int fail_win32(void)
{
    DWORD e = GetLastError();
    errno = e == ERROR_FILE_NOT_FOUND || e == ERROR_PATH_NOT_FOUND || e == ERROR_INVALID_NAME ? ENOENT
            : e == ERROR_ACCESS_DENIED || e == ERROR_SHARING_VIOLATION                    ? EACCES
                                                                                           : EIO;
    return -1;
}

int cli_os_stat_path(const char *path, cli_os_stat *st)
{
    wchar_t *w = widen(path);
    if (!w)
        return -1;
    /* metadata only; BACKUP_SEMANTICS opens folders too */
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
    st->ino = ((unsigned long long)info.nFileIndexHigh << 32) | info.nFileIndexLow;
    st->is_dir = (info.dwFileAttributes & FILE_ATTRIBUTE_DIRECTORY) != 0;
    return 0;
}

int cli_os_dir_writable(const char *dir)
{
    /* a folder's read-only attribute does not stop file creation on Windows: only an
     * ACL does, which the library's own error reports when it happens */
    wchar_t *w = widen(dir);
    int ok = w && _waccess(w, 0) == 0;
    free(w);
    return ok;
}

const char *cli_os_last_separator(const char *path)
{
    const char *a = strrchr(path, '/'), *b = strrchr(path, '\\');
    return a > b ? a : b;
}

struct cli_os_dir {
    HANDLE h;
    WIN32_FIND_DATAW data;
    int have; /* data holds an entry not yet returned */
    char *name;
};

cli_os_dir *cli_os_opendir(const char *path)
{
    size_t n = strlen(path);
    char *pattern = malloc(n + 3);
    if (!pattern) {
        errno = ENOMEM;
        return NULL;
    }
    memcpy(pattern, path, n);
    memcpy(pattern + n, "/*", 3);
    wchar_t *w = widen(pattern);
    free(pattern);
    cli_os_dir *d = w ? calloc(1, sizeof *d) : NULL;
    if (!d) {
        free(w);
        return NULL;
    }
    d->h = FindFirstFileW(w, &d->data);
    free(w);
    if (d->h == INVALID_HANDLE_VALUE) {
        fail_win32();
        free(d);
        return NULL;
    }
    d->have = 1;
    return d;
}

const char *cli_os_readdir(cli_os_dir *d)
{
    free(d->name);
    d->name = NULL;
    if (!d->have && !FindNextFileW(d->h, &d->data))
        return NULL;
    d->have = 0;
    d->name = narrow(d->data.cFileName);
    return d->name ? d->name : "";
}

void cli_os_closedir(cli_os_dir *d)
{
    if (!d)
        return;
    FindClose(d->h);
    free(d->name);
    free(d);
}

void cli_os_catch_interrupt(void (*handler)(int))
{
    /* The C runtime maps Ctrl-C and Ctrl-Break to SIGINT (through its console control
     * handler) and resets the handler to the default before calling it: a second
     * Ctrl-C ends the process, as SA_RESETHAND does on POSIX. */
    signal(SIGINT, handler);
    signal(SIGTERM, handler);
}

double cli_os_now(void)
{
    LARGE_INTEGER f, t;
    QueryPerformanceFrequency(&f);
    QueryPerformanceCounter(&t);
    return (double)t.QuadPart / (double)f.QuadPart;
}

int cli_os_stderr_is_tty(void)
{
    return _isatty(_fileno(stderr));
}

void cli_os_utf8_args(int *argc, char ***argv)
{
    int n = 0;
    wchar_t **w = CommandLineToArgvW(GetCommandLineW(), &n);
    if (!w)
        return;
    /* kept for the life of the process, like the runtime's own argv */
    char **v = calloc((size_t)n + 1, sizeof *v);
    for (int i = 0; v && i < n; i++)
        if (!(v[i] = narrow(w[i]))) {
            v = NULL; /* out of memory: keep the runtime's arguments */
            break;
        }
    LocalFree(w);
    if (v) {
        *argc = n;
        *argv = v;
    }
}

#else /* POSIX */

#include <dirent.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

int cli_os_stat_path(const char *path, cli_os_stat *st)
{
    struct stat s;
    if (stat(path, &s) != 0)
        return -1;
    st->dev = (unsigned long long)s.st_dev;
    st->ino = (unsigned long long)s.st_ino;
    st->is_dir = S_ISDIR(s.st_mode) != 0;
    return 0;
}

int cli_os_dir_writable(const char *dir)
{
    return access(dir, W_OK | X_OK) == 0;
}

const char *cli_os_last_separator(const char *path)
{
    return strrchr(path, '/');
}

struct cli_os_dir {
    DIR *d;
};

cli_os_dir *cli_os_opendir(const char *path)
{
    DIR *dir = opendir(path);
    if (!dir)
        return NULL;
    cli_os_dir *d = malloc(sizeof *d);
    if (!d) {
        closedir(dir);
        errno = ENOMEM;
        return NULL;
    }
    d->d = dir;
    return d;
}

const char *cli_os_readdir(cli_os_dir *d)
{
    struct dirent *e = readdir(d->d);
    return e ? e->d_name : NULL;
}

void cli_os_closedir(cli_os_dir *d)
{
    if (!d)
        return;
    closedir(d->d);
    free(d);
}

void cli_os_catch_interrupt(void (*handler)(int))
{
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = handler;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = SA_RESETHAND;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
}

double cli_os_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

int cli_os_stderr_is_tty(void)
{
    return isatty(STDERR_FILENO);
}

void cli_os_utf8_args(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
}

#endif
