/* Commands that only ask: list, describe, info, passes. */
#include "cli.h"

#include <string.h>

/* Handles the options every query command shares (--help, --compact); returns 1 if
 * `opt` was one of them, -1 on a usage error (already printed). */
static int common_option(cli_args *a, const char *opt, int *compact, int *help)
{
    if (strcmp(opt, "-h") == 0 || strcmp(opt, "--help") == 0) {
        *help = 1;
        return cli_args_flag(a, opt) ? 1 : -1;
    }
    if (compact && strcmp(opt, "--compact") == 0) {
        *compact = 1;
        return cli_args_flag(a, opt) ? 1 : -1;
    }
    return 0;
}

static int new_context(fx_context **ctx)
{
    fx_result r = fx_context_new(ctx, 1);
    if (r != FX_OK) {
        cli_error("cannot create a context: %s", fx_result_name(r));
        return CLI_EXIT_PROCESS;
    }
    return 0;
}

int cli_cmd_list(int argc, char **argv)
{
    cli_args a;
    const char *opt, *pos;
    int help = 0;
    cli_args_init(&a, "list", argc, argv);
    while (cli_args_next(&a, &opt, &pos)) {
        if (pos)
            return cli_usage_error(a.cmd, "unexpected argument '%s'", pos);
        int c = common_option(&a, opt, NULL, &help);
        if (c < 0)
            return CLI_EXIT_USAGE;
        if (c == 0)
            return cli_usage_error(a.cmd, "unknown option '%s'", opt);
    }
    if (help) {
        cli_help_command(stdout, a.cmd);
        return 0;
    }
    int n = fx_effect_count();
    for (int i = 0; i < n; i++) {
        const char *name = fx_effect_name(i);
        const char *doc = name ? fx_effect_doc(name) : NULL;
        if (name)
            printf("%s\t%s\n", name, doc ? doc : "");
    }
    return fflush(stdout) == 0 ? 0 : CLI_EXIT_OUTPUT;
}

/* describe and info: one positional argument in, the library's JSON out. */
typedef fx_result (*json_query_fn)(fx_context *ctx, const char *subject, char **out_json);

static int json_query(int argc, char **argv, const char *cmd, const char *missing, const char *one_at_a_time,
                      json_query_fn query)
{
    cli_args a;
    const char *opt, *pos, *subject = NULL;
    int help = 0, compact = 0;
    cli_args_init(&a, cmd, argc, argv);
    while (cli_args_next(&a, &opt, &pos)) {
        if (pos) {
            if (subject)
                return cli_usage_error(a.cmd, "unexpected argument '%s' (%s)", pos, one_at_a_time);
            subject = pos;
            continue;
        }
        int c = common_option(&a, opt, &compact, &help);
        if (c < 0)
            return CLI_EXIT_USAGE;
        if (c == 0)
            return cli_usage_error(a.cmd, "unknown option '%s'", opt);
    }
    if (help) {
        cli_help_command(stdout, a.cmd);
        return 0;
    }
    if (!subject)
        return cli_usage_error(a.cmd, "%s", missing);

    fx_context *ctx = NULL;
    int rc = new_context(&ctx);
    if (rc)
        return rc;
    char *json = NULL;
    fx_result r = query(ctx, subject, &json);
    if (r != FX_OK) {
        rc = cli_fail(ctx, r, CLI_PHASE_INPUT, subject);
    } else {
        cli_flush_warnings(ctx);
        cli_print_json(stdout, json, compact);
        rc = fflush(stdout) == 0 ? 0 : CLI_EXIT_OUTPUT;
    }
    fx_free(json);
    fx_context_free(ctx);
    return rc;
}

int cli_cmd_describe(int argc, char **argv)
{
    return json_query(argc, argv, "describe", "which effect? ('libfx list' shows them)",
                      "one effect at a time", fx_effect_describe_json);
}

int cli_cmd_info(int argc, char **argv)
{
    return json_query(argc, argv, "info", "which file?", "one file at a time", fx_exr_info_json);
}

int cli_cmd_passes(int argc, char **argv)
{
    cli_args a;
    const char *opt, *pos, *recipe = NULL;
    int help = 0, compact = 0;
    cli_args_init(&a, "passes", argc, argv);
    while (cli_args_next(&a, &opt, &pos)) {
        if (pos) { /* "libfx passes RECIPE.json" reads as well as --stack */
            if (recipe)
                return cli_usage_error(a.cmd, "unexpected argument '%s' (one recipe)", pos);
            recipe = pos;
            continue;
        }
        if (strcmp(opt, "--stack") == 0 || strcmp(opt, "-s") == 0) {
            if (recipe)
                return cli_usage_error(a.cmd, "one recipe only");
            if (!(recipe = cli_args_value(&a, opt)))
                return CLI_EXIT_USAGE;
            continue;
        }
        int c = common_option(&a, opt, &compact, &help);
        if (c < 0)
            return CLI_EXIT_USAGE;
        if (c == 0)
            return cli_usage_error(a.cmd, "unknown option '%s'", opt);
    }
    if (help) {
        cli_help_command(stdout, a.cmd);
        return 0;
    }
    if (!recipe)
        return cli_usage_error(a.cmd, "missing --stack RECIPE.json");

    fx_context *ctx = NULL;
    fx_stack *stack = NULL;
    char *json = NULL;
    int rc = new_context(&ctx);
    if (rc)
        return rc;
    fx_result r = fx_stack_new(ctx, &stack);
    if (r != FX_OK)
        rc = cli_fail(ctx, r, CLI_PHASE_PROCESS, NULL);
    else if ((r = fx_stack_load_file(stack, recipe)) != FX_OK)
        rc = cli_fail(ctx, r, CLI_PHASE_INPUT, recipe);
    else if ((r = fx_stack_required_passes(stack, &json)) != FX_OK)
        rc = cli_fail(ctx, r, CLI_PHASE_PROCESS, recipe);
    else {
        cli_flush_warnings(ctx);
        cli_print_json(stdout, json, compact);
        rc = fflush(stdout) == 0 ? 0 : CLI_EXIT_OUTPUT;
    }
    fx_free(json);
    fx_stack_free(stack);
    fx_context_free(ctx);
    return rc;
}
