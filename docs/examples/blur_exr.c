/* A complete libfx program: blur the Combined pass of an EXR.
 * Build: cc blur_exr.c $(pkg-config --cflags --libs libfx)   or   find_package(libfx) */
#include <libfx/fx.h>
#include <stdio.h>

int main(int argc, char **argv)
{
    if (argc != 3) {
        fprintf(stderr, "usage: %s in.exr out.exr\n", argv[0]);
        return 2;
    }
    if (fx_abi_version() != FX_ABI_VERSION) {
        fprintf(stderr, "libfx ABI %d, built against %d\n", fx_abi_version(), FX_ABI_VERSION);
        return 1;
    }
    fx_context *ctx = NULL;
    fx_stack *stack = NULL;
    fx_frame *in = NULL, *out = NULL;
    if (fx_context_new(&ctx, 0) != FX_OK)
        return 1;
    int index = 0;
    fx_result r = fx_stack_new(ctx, &stack);
    if (!r)
        r = fx_stack_append(stack, "gaussian_blur", &index);
    if (!r)
        r = fx_stack_set_float(stack, index, "sigma", 4.0);
    if (!r) {
        /* Decode only what the stack needs. */
        fx_read_options ro = {sizeof ro, NULL, NULL, stack};
        r = fx_frame_read_exr(ctx, argv[1], &ro, &in);
    }
    if (!r)
        r = fx_stack_run(stack, in, &out);
    if (!r) {
        fx_write_options wo = {sizeof wo, 0, 1, argv[1], NULL}; /* float, Combined only, never over the input */
        r = fx_frame_write_exr(out, argv[2], &wo);
    }
    for (int i = 0; i < fx_context_warning_count(ctx); i++)
        fprintf(stderr, "warning: %s\n", fx_context_warning(ctx, i));
    if (r)
        fprintf(stderr, "error: %s\n", fx_context_error(ctx));
    fx_frame_free(out);
    fx_frame_free(in);
    fx_stack_free(stack);
    fx_context_free(ctx);
    return r ? 1 : 0;
}
