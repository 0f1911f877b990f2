/* Allocation-failure injection (issue 8, hardening) over the recipe parser and every
 * effect of the registry through fx_stack_run: for n = 1, 2, ... until the call succeeds,
 * the nth allocation from the call's start fails (fx_mem_fail_after). Each failure must
 * be clean: FX_ERR_OUT_OF_MEMORY (or another code with a message, printed for review),
 * no output frame, no leak (the ASan build runs LeakSanitizer at exit), and the objects
 * stay usable: the same stack then runs to the same bits, a recipe load leaves the
 * previous stack content unchanged. cJSON allocates through fx_mem (core/mem.c), so the
 * JSON parser is covered as well. (The EXR reader and writer: test_exr_oom.c.) */
#include "fx_scene_test.h"

#include "core/internal.h"

#include <stdlib.h>
#include <string.h>

#define MAX_N 200000 /* a run that still fails at this n never finishes: an error of its own */

static int accepted_error(fx_result r, const char *msg, const char *what)
{
    if (!msg || !msg[0]) {
        fprintf(stderr, "%s: %s with an empty message\n", what, fx_result_name(r));
        return 0;
    }
    if (r == FX_ERR_OUT_OF_MEMORY)
        return 1;
    fprintf(stderr, "%s: under allocation failure got %s (expected FX_ERR_OUT_OF_MEMORY): \"%s\"\n", what,
            fx_result_name(r), msg);
    return 0;
}

/* The recipe parser: the stack keeps its previous content on every failure. */
static void oom_recipe(fx_context *ctx, const char *name, const char *json)
{
    static const char *base = "{\"version\": 1, \"effects\": [{\"effect\": \"pixelate\", \"params\": {\"columns\": 7}}]}";
    fx_stack *s = NULL;
    CHECK_OK(ctx, fx_stack_new(ctx, &s));
    if (!s)
        return;
    CHECK_OK(ctx, fx_stack_load_json(s, base));
    char *before = NULL;
    CHECK_OK(ctx, fx_stack_to_json(s, &before));
    int n, bad = 0;
    for (n = 1; n < MAX_N; n++) {
        fx_mem_fail_after(n);
        fx_result r = fx_stack_load_json(s, json);
        fx_mem_fail_after(0);
        if (r == FX_OK)
            break;
        char what[256];
        snprintf(what, sizeof what, "recipe %s, allocation %d fails", name, n);
        if (!accepted_error(r, fx_context_error(ctx), what))
            bad++;
        char *now = NULL;
        CHECK_OK(ctx, fx_stack_to_json(s, &now));
        if (!now || !before || strcmp(now, before) != 0) {
            bad++;
            fprintf(stderr, "%s: the stack changed\n", what);
        }
        fx_free(now);
    }
    tu_checks++;
    if (n >= MAX_N || bad) {
        tu_failures++;
        fprintf(stderr, "recipe %s: %d bad failures (n reached %d)\n", name, bad, n);
    }
    printf("recipe %s: %d allocation failures injected, all clean: %s\n", name, n - 1, bad ? "no" : "yes");
    fx_free(before);
    fx_stack_free(s);
}

static int same_output(const fx_frame *a, const fx_frame *b)
{
    if (!a || !b || fx_frame_pass_count(a) != fx_frame_pass_count(b))
        return 0;
    for (int i = 0; i < fx_frame_pass_count(a); i++) {
        float *da = NULL, *db = NULL;
        int ca = 0, cb = 0;
        const char *name = fx_frame_pass_name(a, i);
        if (fx_frame_pass(a, name, &da, &ca) || fx_frame_pass(b, name, &db, &cb) || ca != cb)
            return 0;
        if (memcmp(da, db, (size_t)fx_frame_width(a) * fx_frame_height(a) * ca * sizeof(float)))
            return 0;
    }
    return 1;
}

/* One effect through fx_stack_run. fresh_ctx: every attempt in a new context (its aux-view
 * cache empty, so the map builds and the cache insertion are where failures land). */
static void oom_effect(const char *effect, int threads, int debug, int fresh_ctx, const scene *sc)
{
    fx_context *ctx = NULL;
    CHECK_OK(ctx, fx_context_new(&ctx, threads));
    if (!ctx)
        return;
    if (!fresh_ctx)
        fx_context_set_aux_cache(ctx, 0); /* every run loads and builds its aux views */
    fx_frame *f = frame_from_scene(ctx, sc, SIDECAR_LIGHTS_FRONT);
    fx_stack *s = et_stack(ctx, effect);
    CHECK(f && s);
    if (!f || !s) {
        fx_frame_free(f);
        fx_stack_free(s);
        fx_context_free(ctx);
        return;
    }
    fx_stack_set_quality(s, FX_QUALITY_DRAFT);
    fx_stack_set_debug_outputs(s, debug);
    /* a mask too, so the mask builder is covered */
    CHECK_OK(ctx, fx_stack_set_mask_json(s, 0, "{\"object_index\": [1, 2], \"rect_relative\": [0, 0, 0.9, 1]}"));
    fx_frame *ref = NULL;
    CHECK_OK(ctx, fx_stack_run(s, f, &ref));
    int n, bad = 0, failures = 0;
    for (n = 1; n < MAX_N && ref; n++) {
        fx_context *c = ctx;
        fx_frame *g = f;
        fx_stack *t = s;
        if (fresh_ctx) {
            c = NULL, g = NULL, t = NULL;
            fx_context_new(&c, threads);
            g = c ? frame_from_scene(c, sc, SIDECAR_LIGHTS_FRONT) : NULL;
            t = c ? et_stack(c, effect) : NULL;
            if (!t || !g) {
                CHECK(0);
                fx_stack_free(t);
                fx_frame_free(g);
                fx_context_free(c);
                break;
            }
            fx_stack_set_quality(t, FX_QUALITY_DRAFT);
            fx_stack_set_debug_outputs(t, debug);
            fx_stack_set_mask_json(t, 0, "{\"object_index\": [1, 2], \"rect_relative\": [0, 0, 0.9, 1]}");
        }
        fx_frame *out = (fx_frame *)(uintptr_t)1;
        fx_mem_fail_after(n);
        fx_result r = fx_stack_run(t, g, &out);
        fx_mem_fail_after(0);
        int done = r == FX_OK;
        if (!done) {
            failures++;
            char what[256];
            snprintf(what, sizeof what, "%s (threads %d, debug %d%s): allocation %d fails", effect, threads, debug,
                     fresh_ctx ? ", fresh context" : "", n);
            if (!accepted_error(r, fx_context_error(c), what))
                bad++;
            if (out != NULL) {
                bad++;
                fprintf(stderr, "%s: *out is not NULL after a failure\n", what);
                out = NULL;
            }
            /* still usable: the same objects give the same bits */
            fx_frame *again = NULL;
            fx_result r2 = fx_stack_run(t, g, &again);
            if (r2 != FX_OK || !same_output(again, ref)) {
                bad++;
                fprintf(stderr, "%s: the next run %s\n", what,
                        r2 ? fx_context_error(c) : "differs from the reference");
            }
            fx_frame_free(again);
        } else {
            CHECK(same_output(out, ref));
        }
        fx_frame_free(out);
        if (fresh_ctx) {
            fx_stack_free(t);
            fx_frame_free(g);
            fx_context_free(c);
        }
        if (done)
            break;
    }
    tu_checks++;
    if (n >= MAX_N || bad) {
        tu_failures++;
        fprintf(stderr, "%s: %d unclean failures (n reached %d)\n", effect, bad, n);
    }
    printf("%-16s threads %d debug %d%s: %d allocation failures injected, %s\n", effect, threads, debug,
           fresh_ctx ? " fresh ctx" : "", failures, bad ? "NOT clean" : "all clean");
    fx_frame_free(ref);
    fx_stack_free(s);
    fx_frame_free(f);
    fx_context_free(ctx);
}

int main(void)
{
    fx_context *ctx = NULL;
    CHECK_OK(ctx, fx_context_new(&ctx, 1));
    if (!ctx)
        return tu_finish("test_oom_effects");
    write_aux_views(ctx, tu_tmpdir("oom_effects"));

    /* the recipe parser: the scenes' recipes and one with every key and mask kind */
    oom_recipe(ctx, "inline",
               "{\"version\": 1, \"quality\": \"preview\", \"name\": \"x\", \"description\": \"y\", \"effects\": ["
               "{\"effect\": \"gaussian_blur\", \"enabled\": true, \"quality\": \"draft\", \"label\": \"soft\","
               " \"params\": {\"sigma\": 3, \"algorithm\": \"box\"},"
               " \"mask\": {\"object\": [\"Statue\", \"Wall\"], \"material\": \"Glass\", \"invert\": true}},"
               "{\"effect\": \"color_matrix\", \"params\": {\"operator\": \"custom\","
               " \"matrix\": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}, \"mask\": {\"rect\": [1, 2, 3, 4]}},"
               "{\"effect\": \"ssr_mirror\", \"params\": {\"mirror_surfaces\": \"{\\\"material\\\": \\\"Mirror\\\"}\"},"
               " \"mask\": {\"material_index\": [1, 2], \"object_index\": 3, \"rect_relative\": [0, 0, 0.5, 0.5]}}]}");
    const char *data = getenv("LIBFX_TEST_DATA");
    static const char *const recipes[] = {"atrium/recipe.json", "atrium/recipe_sin_city.json", "greek_bath/recipe.json",
                                          "greek_bath/recipe_cel.json", "mirror_room/recipe.json"};
    for (int i = 0; data && i < FX_COUNT_OF(recipes); i++) {
        char path[1024];
        snprintf(path, sizeof path, "%s/../../blend_scenes/%s", data, recipes[i]);
        char *json = tu_slurp(path, NULL);
        if (json)
            oom_recipe(ctx, recipes[i], json);
        free(json);
    }

    /* every effect on a small frame with every pass */
    scene sc;
    scene_build(&sc, 12, 9);
    for (int e = 0; e < fx_effect_count(); e++) {
        const char *effect = fx_effect_name(e);
        oom_effect(effect, 1, 1, 0, &sc);  /* one thread, debug outputs on */
        oom_effect(effect, 2, 0, 0, &sc);  /* the worker pool */
        char *req = NULL;
        fx_stack *s = et_stack(ctx, effect);
        if (s && fx_stack_required_aux_views(s, &req) == FX_OK && req && !tu_contains(req, "[]"))
            oom_effect(effect, 1, 0, 1, &sc); /* aux views through a fresh context's cache */
        fx_free(req);
        fx_stack_free(s);
    }
    scene_free(&sc);
    fx_context_free(ctx);
    return tu_finish("test_oom_effects");
}
