/* Allocation failures at every point of reading and writing: a clean error, no frame,
 * no leak (run under LeakSanitizer), no output file. */
#include "testutil.h"

#include "core/internal.h"

#include <stdio.h>
#include <string.h>
#include <unistd.h>

static char data_dir[1024];

int main(void)
{
    snprintf(data_dir, sizeof data_dir, "%s", __FILE__);
    for (int k = 0; k < 2; k++) {
        char *slash = strrchr(data_dir, '/');
        if (slash)
            *slash = '\0';
    }
    char in[1200];
    snprintf(in, sizeof in, "%s/data/blender/render_multilayer.exr", data_dir);
    /* 1 thread, then 2: parallel decoding/encoding allocates per worker and per chunk. */
    for (int threads = 1; threads <= 2; threads++) {
    fx_context *ctx = NULL;
    if (fx_context_new(&ctx, threads) != FX_OK)
        return 1;

    int failures = 0, n;
    for (n = 1; n < 2000; n++) {
        fx_frame *f = NULL;
        fx_mem_fail_after(n);
        fx_result r = fx_frame_read_exr(ctx, in, NULL, &f);
        fx_mem_fail_after(0);
        if (r == FX_OK) {
            CHECK(f != NULL);
            fx_frame_free(f);
            break;
        }
        failures++;
        CHECK(f == NULL);
        CHECK(r == FX_ERR_OUT_OF_MEMORY);
        if (r != FX_ERR_OUT_OF_MEMORY)
            fprintf(stderr, "allocation %d: %s %s\n", n, fx_result_name(r), fx_context_error(ctx));
    }
    CHECK(failures > 10 && n < 2000);

    fx_frame *f = NULL;
    CHECK_OK(ctx, fx_frame_read_exr(ctx, in, NULL, &f));
    char out[600];
    snprintf(out, sizeof out, "%s/oom%d.exr", tu_tmpdir("exr_oom"), threads);
    fx_write_options wo = {sizeof wo, 0, 0, NULL, NULL};
    for (n = 1; f && n < 2000; n++) {
        fx_mem_fail_after(n);
        fx_result r = fx_frame_write_exr(f, out, &wo);
        fx_mem_fail_after(0);
        if (r == FX_OK)
            break;
        CHECK(r == FX_ERR_OUT_OF_MEMORY);
        CHECK(access(out, F_OK) != 0);
    }
    CHECK(n < 2000 && access(out, F_OK) == 0);
    fx_frame_free(f);
    fx_context_free(ctx);
    }
    return tu_finish("test_exr_oom");
}
