/* libFuzzer target (issue 8, hardening): the EXR reader, the recipe parser and one effect.
 *
 * Input: either an EXR file (the shared corpus seeds it), run through a fixed stack; or
 * "<recipe JSON>\0<EXR bytes>" (a leading '{'): the recipe is parsed and serialised back,
 * and the frame (if any) runs through the fixed stack. The stack runs one cheap effect
 * (gaussian_blur, box draft, then pixelate) so every input finishes in milliseconds: the
 * point is the reader and the parser, under ASan. Inputs over 1 MiB are skipped and the
 * context's limits cap decoded images at 1024x1024 and 64 MiB.
 *
 * Built by tests/fuzz/run_fuzz.sh (cmake -DLIBFX_FUZZ=ON with clang); the same file is
 * compiled without libFuzzer as a replayer (-DFUZZ_REPLAY_MAIN) for tests/data/fuzz/. */
#include "libfx/fx.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define MAX_INPUT (1u << 20)

static const char *FIXED_RECIPE =
    "{\"version\": 1, \"quality\": \"draft\", \"effects\": ["
    "{\"effect\": \"gaussian_blur\", \"params\": {\"sigma\": 2}},"
    "{\"effect\": \"pixelate\", \"params\": {\"mode\": \"average\", \"columns\": 5, \"rows\": 3}}]}";

static fx_context *ctx;
static fx_stack *fixed;
static char path[256];

static void remove_scratch(void)
{
    remove(path);
}

static void setup(void)
{
    if (ctx)
        return;
    if (fx_context_new(&ctx, 1) != FX_OK)
        abort();
    fx_context_set_limits(ctx, 1024, 1024, (uint64_t)64 << 20);
    if (fx_stack_new(ctx, &fixed) != FX_OK || fx_stack_load_json(fixed, FIXED_RECIPE) != FX_OK)
        abort();
    const char *dir = access("/dev/shm", W_OK) == 0 ? "/dev/shm" : "/tmp";
    snprintf(path, sizeof path, "%s/libfx-fuzz-%d.exr", dir, (int)getpid());
    atexit(remove_scratch); /* libFuzzer ends with exit() at -max_total_time */
}

static void fuzz_recipe(const char *json)
{
    fx_stack *s = NULL;
    if (fx_stack_new(ctx, &s) != FX_OK)
        abort();
    if (fx_stack_load_json(s, json) == FX_OK) {
        char *out = NULL, *passes = NULL, *aux = NULL;
        if (fx_stack_to_json(s, &out) == FX_OK) {
            /* what we write we read back */
            fx_stack *t = NULL;
            if (fx_stack_new(ctx, &t) != FX_OK || fx_stack_load_json(t, out) != FX_OK)
                abort();
            fx_stack_free(t);
        }
        fx_stack_required_passes(s, &passes);
        fx_stack_required_aux_views(s, &aux);
        fx_free(out);
        fx_free(passes);
        fx_free(aux);
    } else if (!fx_context_error(ctx)[0]) {
        abort(); /* every failure has a message */
    }
    fx_stack_free(s);
    /* the same text as a camera sidecar and as a mask */
    fx_camera cam;
    fx_camera_from_json(ctx, json, &cam);
    fx_stack *m = NULL;
    int idx = -1;
    if (fx_stack_new(ctx, &m) == FX_OK && fx_stack_append(m, "pixelate", &idx) == FX_OK)
        fx_stack_set_mask_json(m, idx, json);
    fx_stack_free(m);
}

static void fuzz_exr(const uint8_t *data, size_t size)
{
    FILE *f = fopen(path, "wb");
    if (!f)
        return;
    int ok = fwrite(data, 1, size, f) == size;
    fclose(f);
    if (!ok)
        return;
    char *info = NULL;
    if (fx_exr_info_json(ctx, path, &info) == FX_OK)
        fx_free(info);
    fx_frame *in = NULL;
    fx_read_options opts = {sizeof opts, NULL, NULL, fixed};
    if (fx_frame_read_exr(ctx, path, &opts, &in) == FX_OK) {
        fx_frame *out = NULL;
        if (fx_stack_run(fixed, in, &out) == FX_OK) {
            float *px = NULL;
            int ch = 0;
            if (fx_frame_pass(out, "Combined", &px, &ch) != FX_OK)
                abort();
            size_t n = (size_t)fx_frame_width(out) * fx_frame_height(out) * (size_t)ch;
            for (size_t i = 0; i < n; i++)
                if (px[i] != px[i] || px[i] - px[i] != 0.0f)
                    abort(); /* non-finite output */
        }
        fx_frame_free(out);
        fx_frame_free(in);
    }
    /* every pass, any layer: the reader's other paths */
    in = NULL;
    if (fx_frame_read_exr(ctx, path, NULL, &in) == FX_OK)
        fx_frame_free(in);
    fx_context_clear_warnings(ctx);
    unlink(path);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size > MAX_INPUT)
        return 0;
    setup();
    if (size > 0 && data[0] == '{') {
        const uint8_t *nul = memchr(data, 0, size);
        size_t jlen = nul ? (size_t)(nul - data) : size;
        char *json = malloc(jlen + 1);
        if (!json)
            return 0;
        memcpy(json, data, jlen);
        json[jlen] = 0;
        fuzz_recipe(json);
        free(json);
        if (nul && (size_t)(nul - data) + 1 < size)
            fuzz_exr(nul + 1, size - jlen - 1);
    } else {
        fuzz_exr(data, size);
    }
    return 0;
}

#ifdef FUZZ_REPLAY_MAIN
/* Replays files (crashers kept in tests/data/fuzz/, or any input) without libFuzzer. */
int main(int argc, char **argv)
{
    for (int i = 1; i < argc; i++) {
        FILE *f = fopen(argv[i], "rb");
        if (!f) {
            fprintf(stderr, "cannot open %s\n", argv[i]);
            return 2;
        }
        uint8_t *buf = malloc(MAX_INPUT + 1);
        size_t n = buf ? fread(buf, 1, MAX_INPUT + 1, f) : 0;
        fclose(f);
        LLVMFuzzerTestOneInput(buf, n);
        free(buf);
        printf("replayed %s (%zu bytes)\n", argv[i], n);
    }
    fx_stack_free(fixed);
    fx_context_free(ctx);
    return 0;
}
#endif
