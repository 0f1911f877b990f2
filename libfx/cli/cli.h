/* The `libfx` command-line tool: shared declarations.
 *
 * The tool is a thin door onto the library: it includes only the public header and
 * links the shared library. No effect logic, default or range lives here; messages
 * about files, passes and parameters come from the library (fx_context_error).
 *
 * Files: main.c (dispatch, --help, --version), cmd_query.c (list, describe, info,
 * passes), cmd_run.c (run), util.c (messages, exit codes, options, numbers, paths,
 * JSON printing, SIGINT), sequence.c (frame patterns), progress.c (bar and summaries).
 */
#ifndef LIBFX_CLI_H
#define LIBFX_CLI_H

#include <libfx/fx.h>

#include <stddef.h>
#include <stdio.h>

#if defined(__MINGW32__)
/* MinGW's stdio is the C99 one in C11 mode (__USE_MINGW_ANSI_STDIO), not msvcrt's: %zu works */
#  define CLI_PRINTF(a, b) __attribute__((format(gnu_printf, a, b)))
#elif defined(__GNUC__)
#  define CLI_PRINTF(a, b) __attribute__((format(printf, a, b)))
#else
#  define CLI_PRINTF(a, b)
#endif

/* ---- exit status (documented in `libfx --help` and docs/cli.md) ---- */
enum {
    CLI_EXIT_OK = 0,
    CLI_EXIT_USAGE = 2,      /* unknown command/option, missing argument, bad number */
    CLI_EXIT_INPUT = 3,      /* missing/unreadable/bad file, missing pass, bad recipe/params/camera */
    CLI_EXIT_OUTPUT = 4,     /* cannot write, would overwrite the input, exists without --force */
    CLI_EXIT_PROCESS = 5,    /* effect failure, out of memory, limits, internal error */
    CLI_EXIT_INTERRUPTED = 130
};

/* What a failing call was doing: the same fx_result maps to different exit codes
 * (FX_ERR_IO while reading is an input error, while writing an output error). */
typedef enum cli_phase { CLI_PHASE_INPUT, CLI_PHASE_PROCESS, CLI_PHASE_OUTPUT } cli_phase;

int cli_exit_code(fx_result r, cli_phase phase);

/* ---- messages: one line each on stderr, "libfx: error: ..." ---- */
void cli_error(const char *fmt, ...) CLI_PRINTF(1, 2);
void cli_warning(const char *fmt, ...) CLI_PRINTF(1, 2);
/* Prints a usage error naming the command and its help; returns CLI_EXIT_USAGE. */
int cli_usage_error(const char *cmd, const char *fmt, ...) CLI_PRINTF(2, 3);
/* Prints the context's error for r (prefixed by `subject`, e.g. a file name, when the
 * library's message does not already name it) and returns the exit code for r. */
int cli_fail(const fx_context *ctx, fx_result r, cli_phase phase, const char *subject);
/* Prints and clears the warnings collected on ctx. */
void cli_flush_warnings(fx_context *ctx);

/* ---- option parsing: "--opt value", "--opt=value", "-o value", "-j2", "--" ---- */
typedef struct cli_args {
    const char *cmd;          /* for messages */
    int argc;
    char **argv;
    int index;                /* next argv element */
    int options_done;         /* after "--": everything is positional */
    const char *inline_value; /* the "value" of "--opt=value" */
    char opt_buf[64];         /* the "--opt" part of "--opt=value" */
} cli_args;

void cli_args_init(cli_args *a, const char *cmd, int argc, char **argv);
/* Next argument: returns 1 with *opt set (an option) or *pos set (a positional),
 * 0 at the end. */
int cli_args_next(cli_args *a, const char **opt, const char **pos);
/* The value of option `opt`; NULL (after a usage message) if it is missing. */
const char *cli_args_value(cli_args *a, const char *opt);
/* For flags: fails (usage message, returns 0) if "--flag=value" was given. */
int cli_args_flag(cli_args *a, const char *opt);

/* Strict numbers: the whole string, within [lo, hi]. Return 0 and print a usage
 * error naming the option otherwise. */
int cli_parse_int(const char *cmd, const char *opt, const char *s, long lo, long hi, long *out);
int cli_parse_double(const char *cmd, const char *opt, const char *s, double lo, double hi,
                     double *out);

/* ---- paths ---- */
/* 1 if both name the same existing file (same device and inode: hard links too). */
int cli_same_file(const char *a, const char *b);
int cli_file_exists(const char *path);
/* Checks that `path` can be created: not the input, not a directory, not existing
 * (unless force), in an existing writable folder. Prints the error and returns
 * CLI_EXIT_OUTPUT, or returns 0. */
int cli_check_output(const char *path, const char *input, int force);

/* ---- JSON from the library, indented for reading (compact: as is) ---- */
void cli_print_json(FILE *out, const char *json, int compact);

/* ---- Ctrl-C: the first sets a flag (clean cancel), a second one kills ---- */
void cli_install_sigint(void);
int cli_interrupted(void);

double cli_now(void); /* monotonic seconds */

/* ---- frame sequences: "shot.####.exr", "shot.%04d.exr" ---- */
typedef struct cli_pattern {
    char *dir;    /* folder part, "." if none (for listing) */
    char *head;   /* path up to the frame number (with the folder as given) */
    char *tail;   /* after the frame number */
    char *name_head; /* file-name part of head (for matching directory entries) */
    int width;    /* minimum digits (zero padded); 0: "%d" (no padding) */
} cli_pattern;

typedef struct cli_seq_item {
    long frame;
    char *path;
} cli_seq_item;

/* 1: `path` is a pattern (filled), 0: a plain file name, -1: malformed (err filled). */
int cli_pattern_parse(const char *path, cli_pattern *out, char *err, size_t err_size);
void cli_pattern_free(cli_pattern *p);
char *cli_pattern_format(const cli_pattern *p, long frame); /* malloc'd; NULL on OOM */
/* The existing files matching p with first <= frame <= last, sorted by frame.
 * Returns 0, or -1 if the folder cannot be read (errno set). */
int cli_pattern_expand(const cli_pattern *p, long first, long last, cli_seq_item **items,
                       int *count);
void cli_seq_free(cli_seq_item *items, int count);

/* ---- progress: a one-line bar on a TTY, else one summary line per frame ---- */
typedef struct cli_progress {
    int tty;          /* draw the bar on stderr */
    int summaries;    /* print "frame N: 0.41 s, out.exr" lines on stdout */
    int total, done;  /* frames */
    long frame;       /* number of the frame in work */
    int show_number;  /* show it (sequences) */
    int phase;        /* 0 read, 1 effects, 2 write: where the library's fractions go */
    double start, last_draw, fraction;
    const char *stage;
    int drawn;        /* a bar is on screen (to be erased before messages) */
} cli_progress;

void cli_progress_init(cli_progress *p, int total, int tty, int summaries);
void cli_progress_frame_begin(cli_progress *p, long frame, int show_number);
/* Marks the start of a frame's read (0), effects (1) or write (2). */
void cli_progress_phase(cli_progress *p, int phase, const char *stage);
/* fx_progress_fn: redraws the bar (throttled); returns non-zero after Ctrl-C. */
int cli_progress_callback(void *user, const char *stage, double fraction);
void cli_progress_frame_end(cli_progress *p, double seconds, const char *out_path);
void cli_progress_finish(cli_progress *p);
/* Erases the bar (if any) so a message can be printed; messages call it. */
void cli_progress_clear_line(void);

/* ---- commands (argv[0] is the command name) ---- */
int cli_cmd_list(int argc, char **argv);
int cli_cmd_describe(int argc, char **argv);
int cli_cmd_info(int argc, char **argv);
int cli_cmd_passes(int argc, char **argv);
int cli_cmd_run(int argc, char **argv);

/* Help texts (main.c). */
void cli_help_main(FILE *out);
int cli_help_command(FILE *out, const char *cmd); /* 0 if the command is unknown */

#endif
