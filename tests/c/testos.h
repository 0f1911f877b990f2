/* The few operating-system services the C tests need that POSIX and Windows spell
 * differently and the library's core/platform.h (which the tests use too: fx_os_fopen,
 * fx_os_pid, fx_os_now_ms) does not give; every #ifdef _WIN32 of the tests lives in testos.c. */
#ifndef LIBFX_TESTOS_H
#define LIBFX_TESTOS_H

/* The folder for scratch files: "/tmp", or Windows' temporary folder (GetTempPath). */
const char *tu_temp_root(void);
#include <stdio.h>

/* a UTF-8 path (on Windows through _wmkdir: the narrow call takes the ANSI code page) */
int tu_mkdir(const char *path, int mode); /* mode: POSIX permissions, ignored on Windows */
void tu_rmtree(const char *path);         /* best effort */
int tu_hardlink(const char *from, const char *to);
/* A watchdog: after `seconds` (0 disarms) handler runs (on POSIX from SIGALRM, on
 * Windows on a timer thread); it must only write to fd 2 and _exit. */
void tu_alarm(unsigned seconds, void (*handler)(void));

#endif
