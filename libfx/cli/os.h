/* The operating-system services the CLI needs that POSIX and Windows spell differently
 * (the CLI sees only the public API, so the library's core/platform.h is out of reach).
 * Every #ifdef _WIN32 of the tool lives in os.c. Paths are UTF-8; on Windows they go to
 * the wide ("W") APIs and the arguments are taken from the UTF-16 command line. */
#ifndef LIBFX_CLI_OS_H
#define LIBFX_CLI_OS_H

#include <stddef.h>

/* dev/ino identify a file: equal pairs, same file (Windows: volume serial, file index). */
typedef struct cli_os_stat {
    unsigned long long dev, ino;
    int is_dir;
} cli_os_stat;

int cli_os_stat_path(const char *path, cli_os_stat *st); /* 0, or -1 with errno */
int cli_os_dir_writable(const char *dir);           /* can files be created in it */
/* The last folder separator of path ('/'; on Windows also '\\'), or NULL. */
const char *cli_os_last_separator(const char *path);

/* Folder listing: names in UTF-8, "." and ".." included or not, any order. */
typedef struct cli_os_dir cli_os_dir;
cli_os_dir *cli_os_opendir(const char *path); /* NULL with errno */
const char *cli_os_readdir(cli_os_dir *d);    /* NULL at the end; valid until the next call */
void cli_os_closedir(cli_os_dir *d);

/* Calls handler once on Ctrl-C (or SIGTERM); a second Ctrl-C ends the process. */
void cli_os_catch_interrupt(void (*handler)(int));
double cli_os_now(void); /* monotonic seconds */
int cli_os_stderr_is_tty(void);

/* On Windows, replaces argv with the command line's UTF-16 arguments in UTF-8 (the
 * C runtime's argv is in the ANSI code page); elsewhere does nothing. */
void cli_os_utf8_args(int *argc, char ***argv);

#endif
