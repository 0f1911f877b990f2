/* tests/c/testos.h on POSIX systems and on Windows (MinGW-w64, run under Wine). */
#include "testos.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef _WIN32

#define WIN32_LEAN_AND_MEAN
#include <windows.h>
#include <direct.h>

const char *tu_temp_root(void)
{
    static char root[MAX_PATH * 3];
    wchar_t w[MAX_PATH + 1];
    DWORD n = GetTempPathW(MAX_PATH + 1, w);
    if (n == 0 || n > MAX_PATH || !WideCharToMultiByte(CP_UTF8, 0, w, -1, root, sizeof root, NULL, NULL))
        return ".";
    /* forward slashes (Windows takes both): tests print these paths into JSON strings,
     * where a backslash would start an escape */
    for (char *c = root; *c; c++)
        if (*c == '\\')
            *c = '/';
    size_t len = strlen(root);
    if (len > 1 && root[len - 1] == '/')
        root[len - 1] = '\0'; /* callers append "/name" */
    return root;
}

static wchar_t *widen(const char *s)
{
    int n = MultiByteToWideChar(CP_UTF8, 0, s, -1, NULL, 0);
    wchar_t *w = n > 0 ? malloc((size_t)n * sizeof *w) : NULL;
    if (w)
        MultiByteToWideChar(CP_UTF8, 0, s, -1, w, n);
    return w;
}

int tu_mkdir(const char *path, int mode)
{
    (void)mode;
    wchar_t *w = widen(path);
    int r = w ? _wmkdir(w) : -1;
    free(w);
    return r;
}

void tu_rmtree(const char *path)
{
    char pattern[1024];
    snprintf(pattern, sizeof pattern, "%s\\*", path);
    WIN32_FIND_DATAA e;
    HANDLE h = FindFirstFileA(pattern, &e);
    if (h != INVALID_HANDLE_VALUE) {
        do {
            if (!strcmp(e.cFileName, ".") || !strcmp(e.cFileName, ".."))
                continue;
            char child[1024];
            snprintf(child, sizeof child, "%s\\%s", path, e.cFileName);
            if (e.dwFileAttributes & FILE_ATTRIBUTE_DIRECTORY)
                tu_rmtree(child);
            else
                DeleteFileA(child);
        } while (FindNextFileA(h, &e));
        FindClose(h);
    }
    RemoveDirectoryA(path);
}

int tu_hardlink(const char *from, const char *to)
{
    return CreateHardLinkA(to, from, NULL) ? 0 : -1;
}

static void (*alarm_handler)(void);
static HANDLE alarm_timer;

static VOID CALLBACK on_timer(PVOID arg, BOOLEAN fired)
{
    (void)arg;
    (void)fired;
    alarm_handler();
}

void tu_alarm(unsigned seconds, void (*handler)(void))
{
    if (alarm_timer) {
        /* INVALID_HANDLE_VALUE: wait for a running callback (it exits the process anyway) */
        DeleteTimerQueueTimer(NULL, alarm_timer, INVALID_HANDLE_VALUE);
        alarm_timer = NULL;
    }
    alarm_handler = handler;
    if (seconds)
        CreateTimerQueueTimer(&alarm_timer, NULL, on_timer, NULL, (DWORD)seconds * 1000u, 0,
                              WT_EXECUTEONLYONCE);
}

#else /* POSIX */

#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

const char *tu_temp_root(void)
{
    return "/tmp";
}

int tu_mkdir(const char *path, int mode)
{
    return mkdir(path, (mode_t)mode);
}

void tu_rmtree(const char *path)
{
    char cmd[1100];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", path);
    if (system(cmd) != 0) { /* best effort */ }
}

int tu_hardlink(const char *from, const char *to)
{
    return link(from, to);
}

static void (*alarm_handler)(void);

static void on_sigalrm(int sig)
{
    (void)sig;
    alarm_handler();
}

void tu_alarm(unsigned seconds, void (*handler)(void))
{
    alarm_handler = handler;
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_sigalrm;
    sigaction(SIGALRM, &sa, NULL);
    alarm(seconds);
}

#endif
