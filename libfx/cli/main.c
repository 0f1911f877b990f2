/* `libfx`: the command-line door onto the library. Dispatch, --help, --version. */
#include "cli.h"
#include "os.h"

#include <string.h>

static const char EXIT_CODES[] =
    "Exit status:\n"
    "  0    success\n"
    "  2    usage error: unknown command or option, missing argument, bad number\n"
    "  3    input error: missing, unreadable, damaged or non-EXR file; missing pass;\n"
    "       bad recipe, parameter, mask or camera\n"
    "  4    output error: cannot write, would overwrite the input, exists without --force\n"
    "  5    processing error: effect failure, out of memory, over the size limits\n"
    "  130  interrupted (Ctrl-C) or cancelled; no partial output file is left\n"
    "Every error is one line on stderr: 'libfx: error: <message>'.\n";

void cli_help_main(FILE *out)
{
    fprintf(out,
            "usage: libfx <command> [options] [arguments]\n"
            "\n"
            "Render effects over Blender's multilayer OpenEXR passes.\n"
            "\n"
            "Commands:\n"
            "  list                          the effects: name<TAB>one-line doc\n"
            "  describe EFFECT               an effect's parameters, presets and passes (JSON)\n"
            "  info FILE.exr                 an EXR's header summary (JSON; no pixels decoded)\n"
            "  passes --stack RECIPE.json    what a recipe needs from Blender (JSON)\n"
            "  run --stack RECIPE.json IN.exr -o OUT.exr\n"
            "                                apply a recipe to an EXR or a frame sequence\n"
            "  help [COMMAND]                this text, or a command's\n"
            "\n"
            "Options:\n"
            "  -h, --help       help (after a command: that command's help)\n"
            "  -V, --version    the library version and ABI\n"
            "\n"
            "%s"
            "\n"
            "Docs: docs/cli.md. Example:\n"
            "  libfx run --stack blur.json render.exr -o blurred.exr --png preview.png\n",
            EXIT_CODES);
}

int cli_help_command(FILE *out, const char *cmd)
{
    if (strcmp(cmd, "list") == 0) {
        fputs("usage: libfx list\n\n"
              "Prints every effect, one per line: its recipe name, a TAB, its one-line doc.\n",
              out);
    } else if (strcmp(cmd, "describe") == 0) {
        fputs("usage: libfx describe [--compact] EFFECT\n\n"
              "Prints an effect as JSON: doc, parameters (type, default, hard and soft range,\n"
              "enum items), quality presets, halo and the passes it needs with its defaults.\n\n"
              "  --compact    the library's JSON on one line, unindented\n",
              out);
    } else if (strcmp(cmd, "info") == 0) {
        fputs("usage: libfx info [--compact] FILE.exr\n\n"
              "Prints the header of an EXR as JSON: size, data and display windows, parts,\n"
              "layers, views, passes with channel types, compression, camera, Cryptomattes.\n"
              "No pixels are decoded.\n\n"
              "  --compact    the library's JSON on one line, unindented\n",
              out);
    } else if (strcmp(cmd, "passes") == 0) {
        fputs("usage: libfx passes [--compact] --stack RECIPE.json\n\n"
              "Prints what the recipe's enabled effects and masks need, as JSON:\n"
              "{\"passes\": [\"Combined\", ...], \"camera\": bool}. Enable these render passes\n"
              "in Blender (Cryptomatte is named by type: CryptoObject, CryptoMaterial...).\n\n"
              "  -s, --stack RECIPE.json   the recipe (may also be given as the argument)\n"
              "  --compact                 the library's JSON on one line\n",
              out);
    } else if (strcmp(cmd, "run") == 0) {
        fprintf(out,
                "usage: libfx run --stack RECIPE.json [options] IN.exr -o OUT.exr\n"
                "       libfx run --stack RECIPE.json [options] shot.####.exr -o out.####.exr\n\n"
                "Applies the recipe's effects to IN and writes OUT (a multilayer EXR with the\n"
                "result as Combined). Only the passes the recipe needs are decoded. The input\n"
                "is never overwritten; an existing OUT is refused unless --force. Outputs are\n"
                "written atomically: a failed or interrupted run leaves no partial file.\n\n"
                "Options:\n"
                "  -s, --stack FILE      the recipe JSON (required)\n"
                "  -o, --output FILE     the output EXR (required)\n"
                "  --sidecar FILE        the scene sidecar JSON the add-on writes beside each\n"
                "                        render: camera matrices and clips, lights, scene time,\n"
                "                        aux views (--camera FILE: the same, its former name)\n"
                "  --layer NAME          the view layer to read (required if the file has several)\n"
                "  --view NAME           the stereo view to read (default: the default view)\n"
                "  -q, --quality Q       draft, preview, final or reference: the recipe's quality\n"
                "                        (effects with their own quality keep it)\n"
                "  -j, --threads N       worker threads; 0 (default): one per core. The output\n"
                "                        is bit-identical for any N\n"
                "  --proxy N             run on a 1/N proxy (N 1..16; output at the reduced size):\n"
                "                        colour passes box-averaged, IDs/depth/normals from one\n"
                "                        pixel per block; pixel-sized parameters divided by N\n"
                "  --png FILE            also write an 8-bit sRGB PNG preview of the result\n"
                "  --keep-passes         read every pass and copy the input's passes to OUT\n"
                "  --debug-outputs       add the effects' debug passes (masks, mattes...) to OUT\n"
                "  --half                write colour passes as half floats (data stay float)\n"
                "  --compression C       zip (default, fast level), zip:1..zip:9, zips, piz, rle, none\n"
                "  -f, --force           overwrite existing outputs (never the input)\n"
                "  --frame N             the scene frame of a single input (for animated effects)\n"
                "  -v, --verbose         per-frame phase times and per-effect timings (stdout)\n"
                "  --quiet               no progress bar or summary lines\n"
                "  -h, --help            this text\n\n"
                "Frame sequences: an input whose file name holds a run of '#' (shot.####.exr,\n"
                "at least that many digits, zero padded) or printf's %%04d / %%d is expanded over\n"
                "the existing files, in frame order. OUT (and --png) must then be patterns too;\n"
                "each frame's number sets the scene time (frame / fps).\n"
                "  --frames A-B          only frames A to B (or one frame: --frames A)\n"
                "  --fps F               frames per second for the scene time (default 24)\n"
                "  -k, --keep-going      go on after a failing frame (default: stop at the first\n"
                "                        failure); the exit status is the first failure's\n"
                "On a terminal a progress bar shows frame i/N and the ETA; otherwise each frame\n"
                "prints 'frame 12: 0.41 s, out.0012.exr' on stdout. Warnings (replaced NaN/Inf,\n"
                "lossy DWA data...) are printed as 'libfx: warning: ...' on stderr.\n\n"
                "%s",
                EXIT_CODES);
    } else if (strcmp(cmd, "help") == 0) {
        fputs("usage: libfx help [COMMAND]\n", out);
    } else {
        return 0;
    }
    return 1;
}

static void print_version(void)
{
    printf("libfx %s (ABI %d)\n", fx_version_string(), fx_abi_version());
}

typedef int (*cli_command_fn)(int argc, char **argv);

static const struct {
    const char *name;
    cli_command_fn fn;
} COMMANDS[] = {
    { "list", cli_cmd_list },
    { "describe", cli_cmd_describe },
    { "info", cli_cmd_info },
    { "passes", cli_cmd_passes },
    { "run", cli_cmd_run },
};

int main(int argc, char **argv)
{
    cli_os_utf8_args(&argc, &argv);
    if (fx_abi_version() != FX_ABI_VERSION) {
        cli_error("this tool was built for libfx ABI %d but the loaded library has ABI %d",
                  FX_ABI_VERSION, fx_abi_version());
        return CLI_EXIT_PROCESS;
    }
    if (argc < 2) {
        cli_help_main(stderr);
        return CLI_EXIT_USAGE;
    }
    const char *cmd = argv[1];
    if (strcmp(cmd, "-h") == 0 || strcmp(cmd, "--help") == 0) {
        cli_help_main(stdout);
        return 0;
    }
    if (strcmp(cmd, "-V") == 0 || strcmp(cmd, "--version") == 0) {
        print_version();
        return 0;
    }
    if (strcmp(cmd, "help") == 0) {
        if (argc < 3) {
            cli_help_main(stdout);
            return 0;
        }
        if (!cli_help_command(stdout, argv[2]))
            return cli_usage_error(NULL, "unknown command '%s'", argv[2]);
        return 0;
    }
    for (size_t i = 0; i < sizeof COMMANDS / sizeof COMMANDS[0]; i++)
        if (strcmp(cmd, COMMANDS[i].name) == 0)
            return COMMANDS[i].fn(argc - 1, argv + 1);
    if (cmd[0] == '-')
        return cli_usage_error(NULL, "unknown option '%s'", cmd);
    return cli_usage_error(NULL, "unknown command '%s'", cmd);
}
