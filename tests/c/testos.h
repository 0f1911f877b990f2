/* The few operating-system services the C tests need that POSIX and Windows spell
 * differently; every #ifdef _WIN32 of the tests lives in testos.c. */
#ifndef LIBFX_TESTOS_H
#define LIBFX_TESTOS_H

long tu_pid(void);
/* The folder for scratch files: "/tmp", or Windows' temporary folder (GetTempPath). */
const char *tu_temp_root(void);
#include <stdio.h>

/* UTF-8 paths (on Windows through _wfopen / _wmkdir: the narrow calls take the ANSI code page) */
FILE *tu_fopen(const char *path, const char *mode);
int tu_mkdir(const char *path, int mode); /* mode: POSIX permissions, ignored on Windows */
void tu_rmtree(const char *path);         /* best effort */
int tu_hardlink(const char *from, const char *to);
double tu_now(void); /* monotonic seconds */
/* A watchdog: after `seconds` (0 disarms) handler runs (on POSIX from SIGALRM, on
 * Windows on a timer thread); it must only write to fd 2 and _exit. */
void tu_alarm(unsigned seconds, void (*handler)(void));

#endif
