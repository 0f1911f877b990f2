/* Messages, exit codes, option parsing, numbers, paths, JSON printing and Ctrl-C. */
#include "cli.h"
#include "os.h"

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>

/* ---- exit codes ---------------------------------------------------------- */

int cli_exit_code(fx_result r, cli_phase phase)
{
    switch (r) {
    case FX_OK:
        return CLI_EXIT_OK;
    case FX_ERR_CANCELLED:
        return CLI_EXIT_INTERRUPTED;
    case FX_ERR_OUT_OF_MEMORY:
    case FX_ERR_LIMIT:
    case FX_ERR_INTERNAL:
        return CLI_EXIT_PROCESS;
    case FX_ERR_MISSING_PASS:
    case FX_ERR_UNKNOWN_EFFECT:
    case FX_ERR_BAD_PARAM:
    case FX_ERR_BAD_RECIPE:
    case FX_ERR_NO_CAMERA:
    case FX_ERR_NO_AUX_VIEW:
    case FX_ERR_NO_LIGHTS:
        return CLI_EXIT_INPUT;
    case FX_ERR_IO:
    case FX_ERR_BAD_FILE:
    case FX_ERR_INVALID_ARGUMENT:
    default:
        if (phase == CLI_PHASE_OUTPUT)
            return CLI_EXIT_OUTPUT;
        if (phase == CLI_PHASE_INPUT)
            return CLI_EXIT_INPUT;
        return CLI_EXIT_PROCESS;
    }
}

/* ---- messages ------------------------------------------------------------ */

static void vmessage(const char *kind, const char *fmt, va_list ap)
{
    cli_progress_clear_line();
    fflush(stdout);
    fprintf(stderr, "libfx: %s: ", kind);
    vfprintf(stderr, fmt, ap);
    fputc('\n', stderr);
    fflush(stderr);
}

void cli_error(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vmessage("error", fmt, ap);
    va_end(ap);
}

void cli_warning(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vmessage("warning", fmt, ap);
    va_end(ap);
}

int cli_usage_error(const char *cmd, const char *fmt, ...)
{
    char msg[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (cmd)
        cli_error("%s: %s (see 'libfx %s --help')", cmd, msg, cmd);
    else
        cli_error("%s (see 'libfx --help')", msg);
    return CLI_EXIT_USAGE;
}

/* Library messages are one line; keep ours one line even if one is not. */
static void one_line(char *s)
{
    for (; *s; s++)
        if (*s == '\n' || *s == '\r')
            *s = ' ';
}

int cli_fail(const fx_context *ctx, fx_result r, cli_phase phase, const char *subject)
{
    char msg[2048];
    const char *lib = ctx ? fx_context_error(ctx) : "";
    if (!lib || !*lib)
        lib = fx_result_name(r);
    snprintf(msg, sizeof msg, "%s", lib);
    one_line(msg);
    if (r == FX_ERR_CANCELLED)
        cli_error("interrupted: %s", msg);
    else if (subject && *subject && !strstr(msg, subject))
        cli_error("%s: %s", subject, msg);
    else
        cli_error("%s", msg);
    return cli_exit_code(r, phase);
}

void cli_flush_warnings(fx_context *ctx)
{
    if (!ctx)
        return;
    int n = fx_context_warning_count(ctx);
    for (int i = 0; i < n; i++) {
        const char *w = fx_context_warning(ctx, i);
        if (w) {
            char msg[2048];
            snprintf(msg, sizeof msg, "%s", w);
            one_line(msg);
            cli_warning("%s", msg);
        }
    }
    if (n > 0)
        fx_context_clear_warnings(ctx);
}

/* ---- options ------------------------------------------------------------- */

void cli_args_init(cli_args *a, const char *cmd, int argc, char **argv)
{
    memset(a, 0, sizeof *a);
    a->cmd = cmd;
    a->argc = argc;
    a->argv = argv;
    a->index = 1; /* argv[0] is the command */
}

int cli_args_next(cli_args *a, const char **opt, const char **pos)
{
    *opt = NULL;
    *pos = NULL;
    a->inline_value = NULL;
    while (a->index < a->argc) {
        const char *s = a->argv[a->index++];
        if (a->options_done || s[0] != '-' || s[1] == '\0') { /* "-" alone is a positional */
            *pos = s;
            return 1;
        }
        if (strcmp(s, "--") == 0) {
            a->options_done = 1;
            continue;
        }
        const char *eq = (s[1] == '-') ? strchr(s, '=') : NULL;
        if (s[1] != '-' && s[2] != '\0') { /* "-j2": a short option with its value attached */
            a->opt_buf[0] = '-';
            a->opt_buf[1] = s[1];
            a->opt_buf[2] = '\0';
            a->inline_value = s + 2;
            *opt = a->opt_buf;
        } else if (eq) {
            size_t n = (size_t)(eq - s);
            if (n >= sizeof a->opt_buf)
                n = sizeof a->opt_buf - 1;
            memcpy(a->opt_buf, s, n);
            a->opt_buf[n] = '\0';
            a->inline_value = eq + 1;
            *opt = a->opt_buf;
        } else {
            *opt = s;
        }
        return 1;
    }
    return 0;
}

const char *cli_args_value(cli_args *a, const char *opt)
{
    if (a->inline_value)
        return a->inline_value;
    if (a->index >= a->argc) {
        cli_usage_error(a->cmd, "option '%s' needs a value", opt);
        return NULL;
    }
    return a->argv[a->index++];
}

int cli_args_flag(cli_args *a, const char *opt)
{
    if (a->inline_value) {
        cli_usage_error(a->cmd, "option '%s' takes no value", opt);
        return 0;
    }
    return 1;
}

int cli_parse_int(const char *cmd, const char *opt, const char *s, long lo, long hi, long *out)
{
    char *end = NULL;
    errno = 0;
    long v = strtol(s, &end, 10);
    if (!*s || errno || !end || *end) {
        cli_usage_error(cmd, "option '%s' needs an integer, not '%s'", opt, s);
        return 0;
    }
    if (v < lo || v > hi) {
        cli_usage_error(cmd, "option '%s' is %ld, outside [%ld, %ld]", opt, v, lo, hi);
        return 0;
    }
    *out = v;
    return 1;
}

int cli_parse_double(const char *cmd, const char *opt, const char *s, double lo, double hi,
                     double *out)
{
    char *end = NULL;
    errno = 0;
    double v = strtod(s, &end);
    if (!*s || errno || !end || *end || !isfinite(v)) {
        cli_usage_error(cmd, "option '%s' needs a number, not '%s'", opt, s);
        return 0;
    }
    if (v < lo || v > hi) {
        cli_usage_error(cmd, "option '%s' is %g, outside [%g, %g]", opt, v, lo, hi);
        return 0;
    }
    *out = v;
    return 1;
}

/* ---- paths --------------------------------------------------------------- */

int cli_same_file(const char *a, const char *b)
{
    cli_os_stat sa, sb;
    if (cli_os_stat_path(a, &sa) != 0 || cli_os_stat_path(b, &sb) != 0)
        return 0;
    return sa.dev == sb.dev && sa.ino == sb.ino;
}

int cli_file_exists(const char *path)
{
    cli_os_stat st;
    return cli_os_stat_path(path, &st) == 0;
}

/* The folder part of a path ("." for a bare name), in buf. */
static void dir_of(const char *path, char *buf, size_t size)
{
    const char *slash = cli_os_last_separator(path);
    if (!slash) {
        snprintf(buf, size, ".");
    } else if (slash == path) {
        snprintf(buf, size, "/");
    } else {
        size_t n = (size_t)(slash - path);
        if (n >= size)
            n = size - 1;
        memcpy(buf, path, n);
        buf[n] = '\0';
    }
}

int cli_check_output(const char *path, const char *input, int force)
{
    cli_os_stat st;
    char dir[PATH_MAX];
    if (input && cli_same_file(path, input)) {
        cli_error("refusing to write '%s': it is the input file '%s'", path, input);
        return CLI_EXIT_OUTPUT;
    }
    if (cli_os_stat_path(path, &st) == 0) {
        if (st.is_dir) {
            cli_error("cannot write '%s': it is a directory", path);
            return CLI_EXIT_OUTPUT;
        }
        if (!force) {
            cli_error("'%s' exists (use --force to overwrite it)", path);
            return CLI_EXIT_OUTPUT;
        }
    }
    dir_of(path, dir, sizeof dir);
    if (cli_os_stat_path(dir, &st) != 0) {
        cli_error("cannot write '%s': directory '%s' does not exist", path, dir);
        return CLI_EXIT_OUTPUT;
    }
    if (!st.is_dir) {
        cli_error("cannot write '%s': '%s' is not a directory", path, dir);
        return CLI_EXIT_OUTPUT;
    }
    if (!cli_os_dir_writable(dir)) {
        cli_error("cannot write '%s': directory '%s' is not writable", path, dir);
        return CLI_EXIT_OUTPUT;
    }
    return 0;
}

/* ---- JSON printing --------------------------------------------------------- */

/* Index just past the string starting at s[i] == '"'. */
static size_t skip_string(const char *s, size_t i)
{
    for (i++; s[i]; i++) {
        if (s[i] == '\\' && s[i + 1])
            i++;
        else if (s[i] == '"')
            return i + 1;
    }
    return i;
}

/* 1 if the array or object opening at s[i] holds no nested array or object. */
static int is_flat(const char *s, size_t i)
{
    for (i++; s[i];) {
        char c = s[i];
        if (c == '"') {
            i = skip_string(s, i);
            continue;
        }
        if (c == '[' || c == '{')
            return 0;
        if (c == ']' || c == '}')
            return 1;
        i++;
    }
    return 1;
}

static void newline(FILE *out, int depth)
{
    fputc('\n', out);
    for (int k = 0; k < depth; k++)
        fputs("  ", out);
}

/* Re-indents JSON two spaces per level; arrays of scalars (vectors, matrix rows,
 * pass lists) stay on one line. Whitespace inside strings is kept. */
void cli_print_json(FILE *out, const char *json, int compact)
{
    if (compact) {
        fputs(json, out);
        fputc('\n', out);
        return;
    }
    int depth = 0, flat = 0; /* flat: depth at which a one-line array started (0: none) */
    for (size_t i = 0; json[i];) {
        char c = json[i];
        if (c == '"') {
            size_t end = skip_string(json, i);
            fwrite(json + i, 1, end - i, out);
            i = end;
            continue;
        }
        i++;
        if (c == ' ' || c == '\t' || c == '\n' || c == '\r')
            continue;
        if (c == '{' || c == '[') {
            size_t j = i;
            while (json[j] == ' ' || json[j] == '\t' || json[j] == '\n' || json[j] == '\r')
                j++;
            if (json[j] == (c == '{' ? '}' : ']')) { /* empty */
                fputc(c, out);
                fputc(json[j], out);
                i = j + 1;
                continue;
            }
            fputc(c, out);
            depth++;
            if (!flat && c == '[' && is_flat(json, i - 1))
                flat = depth;
            if (!flat)
                newline(out, depth);
        } else if (c == '}' || c == ']') {
            depth--;
            if (flat && depth < flat)
                flat = 0;
            else if (!flat)
                newline(out, depth);
            fputc(c, out);
        } else if (c == ',') {
            fputc(',', out);
            if (flat)
                fputc(' ', out);
            else
                newline(out, depth);
        } else if (c == ':') {
            fputs(": ", out);
        } else {
            fputc(c, out);
        }
    }
    fputc('\n', out);
}

/* ---- Ctrl-C ------------------------------------------------------------------ */

static volatile sig_atomic_t g_interrupted = 0;

static void on_sigint(int sig)
{
    (void)sig;
    g_interrupted = 1; /* SA_RESETHAND: a second Ctrl-C kills the process */
}

void cli_install_sigint(void)
{
    cli_os_catch_interrupt(on_sigint);
}

int cli_interrupted(void)
{
    return g_interrupted != 0;
}

double cli_now(void)
{
    return cli_os_now();
}
