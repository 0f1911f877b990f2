/* `libfx run`: applies a recipe to one EXR or a frame sequence.
 *
 * Per frame: read (only the passes the stack needs, unless --keep-passes), set the
 * camera and the scene time, run the stack, copy input passes if asked, write the EXR
 * (atomically, never over the input) and the PNG preview. Every output is checked
 * before any work starts, so a run that would fail on its outputs fails at once.
 * Batch semantics: the first failing frame stops the run (non-zero exit) unless
 * --keep-going; Ctrl-C cancels cleanly (no partial file) with exit 130. */
#include "cli.h"
#include "os.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>

typedef struct run_opts {
    const char *stack_path, *sidecar_path, *layer, *view, *quality, *png, *in, *out, *compression;
    long threads;
    long proxy; /* --proxy N: run on a 1/N proxy (0: off) */
    double fps;
    long frame; /* --frame, for a single file */
    int has_frame;
    long first, last; /* --frames */
    int has_range;
    int keep_passes, debug_outputs, half, force, keep_going, verbose, quiet, help;
} run_opts;

typedef struct run_item {
    long frame;
    int has_frame;
    char *in, *out, *png;
} run_item;

typedef struct run_job {
    const run_opts *o;
    fx_context *ctx;
    fx_stack *stack;
    int has_sidecar; /* a scene sidecar (--sidecar) applies to every frame */
    int sequence;
    cli_progress progress;
} run_job;

/* "12" or "12-40" */
static int parse_range(const char *s, long *first, long *last)
{
    const char *dash = strchr(s, '-');
    char a[32];
    if (!dash) {
        if (!cli_parse_int("run", "--frames", s, 0, 999999999, first))
            return 0;
        *last = *first;
        return 1;
    }
    size_t n = (size_t)(dash - s);
    if (n == 0 || n >= sizeof a) {
        cli_usage_error("run", "option '--frames' needs A-B or A, not '%s'", s);
        return 0;
    }
    memcpy(a, s, n);
    a[n] = '\0';
    if (!cli_parse_int("run", "--frames", a, 0, 999999999, first) ||
        !cli_parse_int("run", "--frames", dash + 1, 0, 999999999, last))
        return 0;
    if (*last < *first) {
        cli_usage_error("run", "option '--frames' range '%s' is empty (B < A)", s);
        return 0;
    }
    return 1;
}

static int is(const char *opt, const char *a, const char *b)
{
    return strcmp(opt, a) == 0 || (b && strcmp(opt, b) == 0);
}

/* Returns 0 or an exit code (usage message printed). */
static int parse_options(int argc, char **argv, run_opts *o)
{
    cli_args a;
    const char *opt, *pos, *v;
    memset(o, 0, sizeof *o);
    o->threads = 0;
    o->fps = 24.0;
    cli_args_init(&a, "run", argc, argv);
#define VALUE(dst)                                  \
    do {                                            \
        if (!(v = cli_args_value(&a, opt)))         \
            return CLI_EXIT_USAGE;                  \
        (dst) = v;                                  \
    } while (0)
#define FLAG(dst)                                   \
    do {                                            \
        if (!cli_args_flag(&a, opt))                \
            return CLI_EXIT_USAGE;                  \
        (dst) = 1;                                  \
    } while (0)
    while (cli_args_next(&a, &opt, &pos)) {
        if (pos) {
            if (o->in)
                return cli_usage_error(a.cmd, "unexpected argument '%s' (one input: a file or a "
                                              "pattern such as shot.####.exr)", pos);
            o->in = pos;
        } else if (is(opt, "-o", "--output")) {
            VALUE(o->out);
        } else if (is(opt, "-s", "--stack")) {
            VALUE(o->stack_path);
        } else if (is(opt, "--sidecar", "--camera")) {
            VALUE(o->sidecar_path);
        } else if (is(opt, "--layer", NULL)) {
            VALUE(o->layer);
        } else if (is(opt, "--view", NULL)) {
            VALUE(o->view);
        } else if (is(opt, "--compression", NULL)) {
            VALUE(o->compression);
        } else if (is(opt, "-q", "--quality")) {
            VALUE(o->quality);
            if (fx_quality_from_name(o->quality) < 0)
                return cli_usage_error(a.cmd, "option '--quality' is one of draft, preview, "
                                              "final, reference, not '%s'", o->quality);
        } else if (is(opt, "--png", NULL)) {
            VALUE(o->png);
        } else if (is(opt, "-j", "--threads")) {
            VALUE(v);
            if (!cli_parse_int(a.cmd, opt, v, 0, 1024, &o->threads))
                return CLI_EXIT_USAGE;
        } else if (is(opt, "--proxy", NULL)) {
            VALUE(v);
            if (!cli_parse_int(a.cmd, opt, v, 1, 16, &o->proxy))
                return CLI_EXIT_USAGE;
        } else if (is(opt, "--fps", NULL)) {
            VALUE(v);
            if (!cli_parse_double(a.cmd, opt, v, 1e-3, 1e6, &o->fps))
                return CLI_EXIT_USAGE;
        } else if (is(opt, "--frame", NULL)) {
            VALUE(v);
            if (!cli_parse_int(a.cmd, opt, v, -999999999, 999999999, &o->frame))
                return CLI_EXIT_USAGE;
            o->has_frame = 1;
        } else if (is(opt, "--frames", NULL)) {
            VALUE(v);
            if (!parse_range(v, &o->first, &o->last))
                return CLI_EXIT_USAGE;
            o->has_range = 1;
        } else if (is(opt, "--keep-passes", NULL)) {
            FLAG(o->keep_passes);
        } else if (is(opt, "--debug-outputs", NULL)) {
            FLAG(o->debug_outputs);
        } else if (is(opt, "--half", NULL)) {
            FLAG(o->half);
        } else if (is(opt, "-f", "--force")) {
            FLAG(o->force);
        } else if (is(opt, "-k", "--keep-going")) {
            FLAG(o->keep_going);
        } else if (is(opt, "-v", "--verbose")) {
            FLAG(o->verbose);
        } else if (is(opt, "--quiet", NULL)) {
            FLAG(o->quiet);
        } else if (is(opt, "-h", "--help")) {
            FLAG(o->help);
        } else {
            return cli_usage_error(a.cmd, "unknown option '%s'", opt);
        }
    }
#undef VALUE
#undef FLAG
    if (o->help)
        return 0;
    if (!o->stack_path)
        return cli_usage_error(a.cmd, "missing --stack RECIPE.json");
    if (!o->in)
        return cli_usage_error(a.cmd, "missing the input EXR");
    if (!o->out)
        return cli_usage_error(a.cmd, "missing -o OUTPUT.exr");
    return 0;
}

static void free_items(run_item *items, int count)
{
    for (int i = 0; items && i < count; i++) {
        free(items[i].in);
        free(items[i].out);
        free(items[i].png);
    }
    free(items);
}

/* Expands the input (file or pattern) into frames with their output names.
 * Returns 0 or an exit code (message printed). */
static int build_items(const run_opts *o, run_item **out_items, int *out_count, int *sequence)
{
    char err[512];
    cli_pattern pin, pout, ppng;
    int rc = 0;
    int kin = cli_pattern_parse(o->in, &pin, err, sizeof err);
    if (kin < 0)
        return cli_usage_error("run", "%s", err);
    int kout = cli_pattern_parse(o->out, &pout, err, sizeof err);
    if (kout < 0) {
        cli_pattern_free(&pin);
        return cli_usage_error("run", "%s", err);
    }
    int kpng = o->png ? cli_pattern_parse(o->png, &ppng, err, sizeof err) : 0;
    if (kpng < 0) {
        cli_pattern_free(&pin);
        cli_pattern_free(&pout);
        return cli_usage_error("run", "%s", err);
    }
    *sequence = kin;
    *out_items = NULL;
    *out_count = 0;

    if (!kin) {
        if (kout || kpng) {
            rc = cli_usage_error("run", "'%s' is a frame pattern but the input '%s' is one file",
                                 kout ? o->out : o->png, o->in);
        } else if (o->has_range) {
            rc = cli_usage_error("run", "--frames needs a sequence input such as shot.####.exr");
        } else if (!cli_file_exists(o->in)) {
            cli_error("cannot open '%s': %s", o->in, strerror(errno));
            rc = CLI_EXIT_INPUT;
        } else {
            run_item *it = calloc(1, sizeof *it);
            if (it) {
                it->frame = o->frame;
                it->has_frame = o->has_frame;
                it->in = strdup(o->in);
                it->out = strdup(o->out);
                it->png = o->png ? strdup(o->png) : NULL;
            }
            if (!it || !it->in || !it->out || (o->png && !it->png)) {
                free_items(it, 1);
                cli_error("out of memory");
                rc = CLI_EXIT_PROCESS;
            } else {
                *out_items = it;
                *out_count = 1;
            }
        }
        goto done;
    }
    if (!kout || (o->png && !kpng)) {
        rc = cli_usage_error("run", "the input '%s' is a frame pattern: '%s' needs one too "
                                    "(such as out.####.exr)", o->in, !kout ? o->out : o->png);
        goto done;
    }
    if (o->has_frame) {
        rc = cli_usage_error("run", "--frame is for a single file; a sequence takes each frame's "
                                    "number from its name (use --frames A-B to choose)");
        goto done;
    }
    cli_seq_item *seq = NULL;
    int n = 0;
    long first = o->has_range ? o->first : 0, last = o->has_range ? o->last : 999999999;
    if (cli_pattern_expand(&pin, first, last, &seq, &n) != 0) {
        cli_error("cannot list the frames of '%s': directory '%s': %s", o->in, pin.dir,
                  strerror(errno));
        rc = CLI_EXIT_INPUT;
        goto done;
    }
    if (n == 0) {
        if (o->has_range)
            cli_error("no file matches '%s' for frames %ld-%ld", o->in, first, last);
        else
            cli_error("no file matches '%s'", o->in);
        rc = CLI_EXIT_INPUT;
        goto done;
    }
    run_item *items = calloc((size_t)n, sizeof *items);
    if (!items) {
        cli_seq_free(seq, n);
        cli_error("out of memory");
        rc = CLI_EXIT_PROCESS;
        goto done;
    }
    for (int i = 0; i < n; i++) {
        items[i].frame = seq[i].frame;
        items[i].has_frame = 1;
        items[i].in = seq[i].path;
        seq[i].path = NULL;
        items[i].out = cli_pattern_format(&pout, seq[i].frame);
        items[i].png = o->png ? cli_pattern_format(&ppng, seq[i].frame) : NULL;
        if (!items[i].out || (o->png && !items[i].png)) {
            cli_seq_free(seq, n);
            free_items(items, n);
            cli_error("out of memory");
            rc = CLI_EXIT_PROCESS;
            goto done;
        }
    }
    cli_seq_free(seq, n);
    *out_items = items;
    *out_count = n;
done:
    cli_pattern_free(&pin);
    cli_pattern_free(&pout);
    if (kpng > 0)
        cli_pattern_free(&ppng);
    return rc;
}

/* Every output is checked before any work: writable, not an input, not existing
 * unless --force. */
static int check_outputs(const run_opts *o, const run_item *items, int count)
{
    cli_os_stat *ins = calloc((size_t)count, sizeof *ins);
    if (!ins) {
        cli_error("out of memory");
        return CLI_EXIT_PROCESS;
    }
    for (int i = 0; i < count; i++)
        if (cli_os_stat_path(items[i].in, &ins[i]) != 0)
            ins[i].ino = 0, ins[i].dev = 0;
    int rc = 0;
    for (int i = 0; i < count && !rc; i++) {
        const char *outs[2] = { items[i].out, items[i].png };
        if (items[i].png && strcmp(items[i].png, items[i].out) == 0) {
            rc = cli_usage_error("run", "--png and -o name the same file '%s'", items[i].out);
            break;
        }
        for (int k = 0; k < 2 && !rc; k++) {
            if (!outs[k])
                continue;
            rc = cli_check_output(outs[k], items[i].in, o->force);
            cli_os_stat st;
            if (!rc && count > 1 && cli_os_stat_path(outs[k], &st) == 0) { /* another frame's input? */
                for (int j = 0; j < count; j++)
                    if (ins[j].ino && ins[j].dev == st.dev && ins[j].ino == st.ino) {
                        cli_error("refusing to write '%s': it is the input file '%s'", outs[k],
                                  items[j].in);
                        rc = CLI_EXIT_OUTPUT;
                        break;
                    }
            }
        }
    }
    free(ins);
    return rc;
}

/* One frame, start to end. Returns 0 or an exit code (message printed). */
static int run_frame(run_job *job, const run_item *it)
{
    const run_opts *o = job->o;
    fx_context *ctx = job->ctx;
    fx_frame *in = NULL, *out = NULL;
    fx_result r;
    int rc = 0;
    double t0 = cli_now(), t_read = 0, t_run = 0, t_write = 0;

    fx_read_options ro;
    memset(&ro, 0, sizeof ro);
    ro.size = sizeof ro;
    ro.layer = o->layer;
    ro.view = o->view;
    ro.stack = o->keep_passes ? NULL : job->stack;
    r = fx_frame_read_exr(ctx, it->in, &ro, &in);
    cli_flush_warnings(ctx);
    if (r == FX_ERR_CANCELLED)
        goto interrupted;
    if (r != FX_OK) {
        rc = cli_fail(ctx, r, CLI_PHASE_INPUT, it->in);
        goto done;
    }
    if (job->has_sidecar && (r = fx_frame_apply_sidecar_file(in, o->sidecar_path)) != FX_OK) {
        rc = cli_fail(ctx, r, CLI_PHASE_INPUT, o->sidecar_path);
        goto done;
    }
    if (it->has_frame)
        fx_frame_set_time(in, (double)it->frame, o->fps);
    if (o->proxy > 1) {
        fx_frame *proxy = NULL;
        r = fx_frame_reduce(in, (int)o->proxy, &proxy);
        fx_frame_free(in);
        in = proxy;
        if (r != FX_OK) {
            rc = cli_fail(ctx, r, CLI_PHASE_INPUT, it->in);
            goto done;
        }
    }
    t_read = cli_now() - t0;
    if (cli_interrupted())
        goto interrupted;

    cli_progress_phase(&job->progress, 1, "effects");
    /* the input is not needed again: the stack may write over its Combined */
    r = fx_stack_run_consume(job->stack, in, o->keep_passes, &out);
    in = NULL;
    cli_flush_warnings(ctx);
    if (r == FX_ERR_CANCELLED)
        goto interrupted;
    if (r != FX_OK) {
        rc = cli_fail(ctx, r, CLI_PHASE_PROCESS, it->in);
        goto done;
    }
    t_run = cli_now() - t0 - t_read;
    if (cli_interrupted())
        goto interrupted;

    cli_progress_phase(&job->progress, 2, "write");
    fx_write_options wo;
    memset(&wo, 0, sizeof wo);
    wo.size = sizeof wo;
    wo.half_color = o->half;
    wo.only_combined = 0; /* the output holds Combined, debug passes and kept passes only */
    wo.input_path = it->in;
    wo.compression = o->compression; /* NULL: the library's default (ZIP, fast level) */
    r = fx_frame_write_exr(out, it->out, &wo);
    cli_flush_warnings(ctx);
    if (r == FX_ERR_CANCELLED)
        goto interrupted;
    if (r != FX_OK) {
        rc = cli_fail(ctx, r, CLI_PHASE_OUTPUT, it->out);
        goto done;
    }
    if (it->png) {
        r = fx_frame_write_png(out, it->png, NULL, 0.0f);
        cli_flush_warnings(ctx);
        if (r == FX_ERR_CANCELLED) { /* the EXR is complete; the PNG is not written */
            cli_error("interrupted: '%s' written, preview '%s' not", it->out, it->png);
            rc = CLI_EXIT_INTERRUPTED;
            goto done;
        }
        if (r != FX_OK) {
            rc = cli_fail(ctx, r, CLI_PHASE_OUTPUT, it->png);
            goto done;
        }
    }
    t_write = cli_now() - t0 - t_read - t_run;

    if (o->verbose) {
        char *timings = NULL;
        cli_progress_clear_line();
        printf("%s: read %.3f s, effects %.3f s, write %.3f s\n", it->in, t_read, t_run, t_write);
        if (fx_stack_timings_json(job->stack, &timings) == FX_OK && timings) {
            printf("timings: ");
            cli_print_json(stdout, timings, 1);
        }
        fx_free(timings);
        fflush(stdout);
    }
    goto done;

interrupted:
    cli_error("interrupted: nothing written for '%s'", it->out);
    rc = CLI_EXIT_INTERRUPTED;
done:
    fx_frame_free(out);
    fx_frame_free(in);
    return rc;
}

static int setup(run_job *job)
{
    const run_opts *o = job->o;
    fx_result r = fx_context_new(&job->ctx, (int)o->threads);
    if (r != FX_OK) {
        cli_error("cannot create a context with %ld threads: %s", o->threads, fx_result_name(r));
        return CLI_EXIT_PROCESS;
    }
    fx_context_set_progress(job->ctx, cli_progress_callback, &job->progress);
    if ((r = fx_stack_new(job->ctx, &job->stack)) != FX_OK)
        return cli_fail(job->ctx, r, CLI_PHASE_PROCESS, NULL);
    if ((r = fx_stack_load_file(job->stack, o->stack_path)) != FX_OK)
        return cli_fail(job->ctx, r, CLI_PHASE_INPUT, o->stack_path);
    if (o->quality && (r = fx_stack_set_quality(job->stack, fx_quality_from_name(o->quality))) != FX_OK)
        return cli_fail(job->ctx, r, CLI_PHASE_INPUT, o->stack_path);
    fx_stack_set_debug_outputs(job->stack, o->debug_outputs);
    if (o->sidecar_path) {
        /* Check the sidecar (camera, lights, time) once, before any frame is read. */
        fx_frame *probe = NULL;
        if ((r = fx_frame_new(job->ctx, 1, 1, &probe)) == FX_OK)
            r = fx_frame_apply_sidecar_file(probe, o->sidecar_path);
        fx_frame_free(probe);
        if (r != FX_OK)
            return cli_fail(job->ctx, r, CLI_PHASE_INPUT, o->sidecar_path);
        job->has_sidecar = 1;
    }
    cli_flush_warnings(job->ctx);
    return 0;
}

int cli_cmd_run(int argc, char **argv)
{
    run_opts o;
    run_job job;
    run_item *items = NULL;
    int count = 0, rc;

    if ((rc = parse_options(argc, argv, &o)) != 0)
        return rc;
    if (o.help) {
        cli_help_command(stdout, "run");
        return 0;
    }
    memset(&job, 0, sizeof job);
    job.o = &o;
    if ((rc = build_items(&o, &items, &count, &job.sequence)) != 0)
        return rc;
    /* input errors (3) before output errors (4), both before any pixel is read */
    if ((rc = setup(&job)) != 0)
        goto done;
    if ((rc = check_outputs(&o, items, count)) != 0)
        goto done;
    cli_install_sigint();

    int tty = !o.quiet && cli_os_stderr_is_tty();
    int summaries = !o.quiet && !tty && job.sequence;
    cli_progress_init(&job.progress, count, tty, summaries);
    int failed = 0, first_rc = 0;
    long first_failed = 0;
    for (int i = 0; i < count; i++) {
        if (cli_interrupted()) {
            cli_error("interrupted after %d of %d frames", i, count);
            first_rc = CLI_EXIT_INTERRUPTED;
            break;
        }
        double t0 = cli_now();
        cli_progress_frame_begin(&job.progress, items[i].frame, job.sequence);
        int frc = run_frame(&job, &items[i]);
        if (frc == 0) {
            cli_progress_frame_end(&job.progress, cli_now() - t0, items[i].out);
            continue;
        }
        if (!failed++) {
            first_rc = frc;
            first_failed = items[i].frame;
        }
        if (frc == CLI_EXIT_INTERRUPTED || !o.keep_going)
            break;
        job.progress.done++;
    }
    cli_progress_finish(&job.progress);
    if (failed && o.keep_going && first_rc != CLI_EXIT_INTERRUPTED && count > 1)
        cli_error("%d of %d frames failed (the first: frame %ld)", failed, count, first_failed);
    rc = first_rc;
done:
    fx_stack_free(job.stack);
    fx_context_free(job.ctx);
    free_items(items, count);
    return rc;
}
