/* Replays the fuzz target's kept inputs (tests/data/fuzz/: crashers found by
 * tests/fuzz/run_fuzz.sh, kept as regression files) through the same code as the fuzzer,
 * in the normal and ASan builds: each must finish without a crash, a leak or an abort. */
#define LLVMFuzzerTestOneInput fuzz_one_input
#include "../fuzz/fuzz_exr_recipe.c"
#undef LLVMFuzzerTestOneInput

#include "testutil.h"

#include <dirent.h>

static int replay(const char *file)
{
    FILE *f = fopen(file, "rb");
    if (!f)
        return 0;
    uint8_t *buf = malloc(MAX_INPUT + 1);
    size_t n = buf ? fread(buf, 1, MAX_INPUT + 1, f) : 0;
    fclose(f);
    fuzz_one_input(buf, n);
    free(buf);
    return 1;
}

int main(void)
{
    const char *data = getenv("LIBFX_TEST_DATA");
    char dir[1024];
    snprintf(dir, sizeof dir, "%s/fuzz", data ? data : "tests/data");
    DIR *d = opendir(dir);
    CHECK(d != NULL);
    int count = 0;
    struct dirent *e;
    while (d && (e = readdir(d))) {
        if (e->d_name[0] == '.' || strcmp(e->d_name, "README.md") == 0)
            continue;
        char path[2048];
        snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
        CHECK(replay(path));
        count++;
    }
    if (d)
        closedir(d);
    /* an inline pair: a recipe, then a few bytes that are not an EXR */
    static const uint8_t pair[] = "{\"version\": 1, \"effects\": [{\"effect\": \"bloom\"}]}\0v/1\x01\x02";
    fuzz_one_input(pair, sizeof pair - 1);
    printf("test_fuzz_replay: %d kept inputs replayed\n", count);
    fx_stack_free(fixed);
    fx_context_free(ctx);
    return tu_finish("test_fuzz_replay");
}
