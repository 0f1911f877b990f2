/* Core: contexts and errors, recipes (every kind of bad input names what is wrong),
 * stack editing and JSON round trips, required passes, masks, Cryptomatte IDs and
 * the thread pool's determinism. */
#include "testutil.h"

#include "core/effect.h"
#include "scene/lights.h"
#include "core/mask.h"
#include "core/parallel.h"

#include <cjson/cJSON.h>

#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

static void test_context_and_errors(void)
{
    fx_context *ctx = NULL;
    CHECK(fx_context_new(&ctx, 0) == FX_OK);
    CHECK(fx_context_threads(ctx) >= 1);
    CHECK(strcmp(fx_context_error(ctx), "") == 0);
    CHECK(fx_abi_version() == FX_ABI_VERSION);
    CHECK(strcmp(fx_result_name(FX_ERR_BAD_PARAM), "FX_ERR_BAD_PARAM") == 0);
    CHECK(strcmp(fx_result_name(FX_ERR_NO_AUX_VIEW), "FX_ERR_NO_AUX_VIEW") == 0);
    CHECK(strcmp(fx_result_name(FX_ERR_NO_LIGHTS), "FX_ERR_NO_LIGHTS") == 0);
    CHECK(FX_ERR_NO_CAMERA == 10 && FX_ERR_INTERNAL == 12 && FX_ERR_NO_AUX_VIEW == 13);
    fx_frame *f = NULL;
    CHECK_FAIL(ctx, fx_frame_new(ctx, -1, 4, &f), FX_ERR_INVALID_ARGUMENT, "negative");
    CHECK_FAIL(ctx, fx_context_set_limits(ctx, 0, 1, 1), FX_ERR_INVALID_ARGUMENT, "positive");
    CHECK(fx_context_set_limits(ctx, 100, 100, 1 << 20) == FX_OK);
    CHECK_FAIL(ctx, fx_frame_new(ctx, 101, 4, &f), FX_ERR_LIMIT, "over the limit");
    CHECK(fx_frame_new(ctx, 100, 100, &f) == FX_OK);
    /* 100*100*4 floats = 160 KB < 1 MiB; a budget of 100 KB refuses it */
    CHECK(fx_context_set_limits(ctx, 100, 100, 100000) == FX_OK);
    CHECK_FAIL(ctx, fx_frame_add_pass(f, "Combined", 4, NULL), FX_ERR_LIMIT, "memory budget");
    CHECK_FAIL(ctx, fx_frame_pass(f, "Depth", NULL, NULL), FX_ERR_MISSING_PASS, "Depth");
    CHECK_FAIL(ctx, fx_frame_add_pass(f, "X", 5, NULL), FX_ERR_INVALID_ARGUMENT, "channels");
    fx_frame_free(f);
    fx_frame_free(NULL);
    fx_stack_free(NULL);
    fx_context_free(ctx);
    fx_context_free(NULL);
}

typedef struct thread_arg {
    fx_context *ctx;
    const char *effect;
    int ok;
} thread_arg;

static void *error_thread(void *p)
{
    thread_arg *a = p;
    fx_stack *s = NULL;
    fx_stack_new(a->ctx, &s);
    for (int i = 0; i < 200; i++) {
        fx_stack_append(s, a->effect, NULL);
        /* each thread must read back its own message */
        if (!strstr(fx_context_error(a->ctx), a->effect))
            a->ok = 0;
    }
    fx_stack_free(s);
    return NULL;
}

/* A binding's garbage collector may free frames after their context: the context lives
 * on until its last frame is freed (ASan/LSan check: no use after free, no leak). */
static void test_frames_outlive_their_context(void)
{
    fx_context *ctx = NULL;
    fx_context_new(&ctx, 2);
    fx_frame *a = NULL, *b = NULL;
    CHECK_OK(ctx, fx_frame_new(ctx, 1024, 512, &a)); /* 8 MiB passes: through the buffer store */
    CHECK_OK(ctx, fx_frame_add_pass(a, "Combined", 4, NULL));
    CHECK_OK(ctx, fx_frame_new(ctx, 1024, 512, &b));
    CHECK_OK(ctx, fx_frame_add_pass(b, "Combined", 4, NULL));
    fx_frame_free(a); /* its buffer goes to the store */
    fx_context_free(ctx); /* closed, not yet freed: b lives */
    fx_frame_free(b);     /* releases the context and the store */
}

/* A stack run in one context on a frame of another (a reader context and one per render
 * thread): the output is the running context's, takes the input's other passes (shared, as
 * `libfx run` keeps them) and outlives the input's context; its buffers go back to the running context's store, so the
 * next run there takes the same Combined buffer (made in the input's context, the output
 * gave them to the reader's store and every run faulted fresh pages in). ASan/LSan: no use
 * after free, no leak. */
static void test_stack_across_contexts(void)
{
    fx_context *reader = NULL, *runner = NULL;
    fx_context_new(&reader, 2);
    fx_context_new(&runner, 2);
    const int w = 1024, h = 512; /* 8 MiB passes: through the buffer stores */
    float *rgba = malloc((size_t)w * h * 4 * sizeof(float)), *depth = malloc((size_t)w * h * sizeof(float));
    for (int i = 0; i < w * h; i++) {
        rgba[4 * i] = rgba[4 * i + 1] = rgba[4 * i + 2] = (float)(i % 97) / 97.0f;
        rgba[4 * i + 3] = 1.0f;
        depth[i] = 1.0f + (float)(i % 13);
    }
    fx_stack *s = NULL;
    CHECK_OK(runner, fx_stack_new(runner, &s));
    CHECK_OK(runner, fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"color_matrix\", "
                                           "\"params\": {\"operator\": \"sepia\"}}]}"));
    const float *first = NULL;
    for (int run = 0; run < 2; run++) {
        fx_frame *in = NULL, *out = NULL;
        CHECK_OK(reader, fx_frame_new(reader, w, h, &in));
        CHECK_OK(reader, fx_frame_add_pass(in, "Combined", 4, rgba));
        CHECK_OK(reader, fx_frame_add_pass(in, "Depth", 1, depth));
        CHECK_OK(runner, fx_stack_run(s, in, &out));
        CHECK_OK(runner, fx_frame_copy_passes(out, in)); /* Depth: shared, not copied */
        fx_frame_free(in);
        if (run == 1)
            fx_context_free(reader); /* the input's context goes first: the output lives on */
        const float *c = NULL, *d = NULL;
        int ch = 0;
        CHECK_OK(runner, fx_frame_pass_read(out, "Depth", &d, &ch));
        CHECK_OK(runner, fx_frame_pass_read(out, "Combined", &c, &ch));
        CHECK(d && memcmp(d, depth, (size_t)w * h * sizeof(float)) == 0);
        /* sepia of a grey g: R = (0.393 + 0.769 + 0.189) g */
        CHECK(c && fabsf(c[4 * 500] - 1.351f * rgba[4 * 500]) < 1e-5f);
        if (run == 0)
            first = c;
        else
            CHECK(c == first); /* the first output's buffer, back in the runner's store */
        fx_frame_free(out);
    }
    fx_stack_free(s);
    fx_context_free(runner);
    free(rgba);
    free(depth);
}

static void test_errors_are_per_thread(void)
{
    fx_context *ctx = NULL;
    fx_context_new(&ctx, 2);
    thread_arg a = {ctx, "no_such_effect_a", 1}, b = {ctx, "no_such_effect_b", 1};
    pthread_t ta, tb;
    pthread_create(&ta, NULL, error_thread, &a);
    pthread_create(&tb, NULL, error_thread, &b);
    pthread_join(ta, NULL);
    pthread_join(tb, NULL);
    CHECK(a.ok && b.ok);
    fx_context_free(ctx);
}

static void test_recipes(void)
{
    fx_context *ctx = NULL;
    fx_context_new(&ctx, 1);
    fx_stack *s = NULL;
    CHECK_OK(ctx, fx_stack_new(ctx, &s));
    const char *good =
        "{\"version\": 1, \"quality\": \"draft\", \"effects\": ["
        "{\"effect\": \"gaussian_blur\", \"params\": {\"sigma\": 3.5}},"
        "{\"effect\": \"color_matrix\", \"enabled\": false, \"quality\": \"reference\","
        " \"params\": {\"operator\": \"sepia\", \"mix\": 0.5}, \"mask\": {\"object\": [\"Statue\"], \"invert\": true}},"
        "{\"effect\": \"pixelate\", \"label\": \"censor\", \"mask\": {\"rect\": [1, 2, 3, 4]}}]}";
    CHECK_OK(ctx, fx_stack_load_json(s, good));
    CHECK(fx_stack_count(s) == 3);
    CHECK(strcmp(fx_stack_effect(s, 1), "color_matrix") == 0);

    /* Bad recipes: each names what is wrong, and the stack keeps its content. */
    CHECK_FAIL(ctx, fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"nope\"}]}"),
               FX_ERR_UNKNOWN_EFFECT, "'nope'");
    CHECK_FAIL(ctx, fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"gaussian_blur\", \"params\": {\"sigmaa\": 1}}]}"),
               FX_ERR_BAD_PARAM, "unknown parameter 'sigmaa'");
    CHECK_FAIL(ctx, fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"gaussian_blur\", \"params\": {\"sigma\": -1}}]}"),
               FX_ERR_BAD_PARAM, "effect 0 (gaussian_blur): parameter 'sigma' = -1 is out of range [0, ");
    CHECK_FAIL(ctx, fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"gaussian_blur\", \"params\": {\"sigma\": \"big\"}}]}"),
               FX_ERR_BAD_PARAM, "must be a number");
    CHECK_FAIL(ctx, fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"color_matrix\", \"params\": {\"operator\": \"purple\"}}]}"),
               FX_ERR_BAD_PARAM, "is not one of: grayscale_average");
    CHECK_FAIL(ctx, fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"color_matrix\", \"params\": {\"matrix\": [1, 2, 3]}}]}"),
               FX_ERR_BAD_PARAM, "needs 16 numbers");
    CHECK_FAIL(ctx, fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"pixelate\", \"params\": {\"cell_size\": 2.5}}]}"),
               FX_ERR_BAD_PARAM, "must be an integer");
    CHECK_FAIL(ctx, fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"pixelate\", \"mask\": {\"object\": 3}}]}"),
               FX_ERR_BAD_RECIPE, "mask \"object\"");
    CHECK_FAIL(ctx, fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"pixelate\", \"mask\": {\"rect\": [0, 0, -2, 3]}}]}"),
               FX_ERR_BAD_RECIPE, "rect");
    CHECK_FAIL(ctx, fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"pixelate\", \"mask\": {\"colour\": 1}}]}"),
               FX_ERR_BAD_RECIPE, "unknown mask key \"colour\"");
    CHECK_FAIL(ctx, fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"pixelate\", \"speed\": 1}]}"),
               FX_ERR_BAD_RECIPE, "unknown key \"speed\"");
    /* a repeated key is refused at any depth (it used to replace, and leak, a mask list) */
    CHECK_FAIL(ctx, fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"pixelate\", \"mask\": {\"material\": [\"a\"], \"material\": [\"b\"]}}]}"),
               FX_ERR_BAD_RECIPE, "key \"material\" appears twice in \"mask\"");
    CHECK_FAIL(ctx, fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"pixelate\", \"params\": {\"cell_size\": 8, \"cell_size\": 9}}]}"),
               FX_ERR_BAD_RECIPE, "key \"cell_size\" appears twice in \"params\"");
    CHECK_FAIL(ctx, fx_stack_load_json(s, "{\"version\": 1, \"version\": 1, \"effects\": []}"), FX_ERR_BAD_RECIPE,
               "key \"version\" appears twice");
    CHECK_FAIL(ctx, fx_stack_set_mask_json(s, 0, "{\"object\": \"a\", \"object\": \"b\"}"), FX_ERR_BAD_RECIPE,
               "appears twice");
    CHECK_FAIL(ctx, fx_stack_load_json(s, "{\"version\": 2, \"effects\": []}"), FX_ERR_BAD_RECIPE, "newer");
    CHECK_FAIL(ctx, fx_stack_load_json(s, "{\"effects\": []}"), FX_ERR_BAD_RECIPE, "\"version\" is missing");
    CHECK_FAIL(ctx, fx_stack_load_json(s, "{\"version\": 1, \"quality\": \"ultra\"}"), FX_ERR_BAD_RECIPE, "quality");
    CHECK_FAIL(ctx, fx_stack_load_json(s, "{\"version\": 1,\n \"effects\": [}"), FX_ERR_BAD_RECIPE, "line 2");
    CHECK_FAIL(ctx, fx_stack_load_json(s, "[]"), FX_ERR_BAD_RECIPE, "top level");
    CHECK_FAIL(ctx, fx_stack_load_file(s, "/nonexistent/recipe.json"), FX_ERR_IO, "/nonexistent/recipe.json");
    CHECK(fx_stack_count(s) == 3);

    /* Round trip: only explicit parameters are written, so presets keep working. */
    char *json = NULL;
    CHECK_OK(ctx, fx_stack_to_json(s, &json));
    CHECK(json && strstr(json, "\"sigma\":\t3.5") && !strstr(json, "box_passes"));
    CHECK(json && strstr(json, "\"label\":\t\"censor\""));
    fx_stack *s2 = NULL;
    fx_stack_new(ctx, &s2);
    CHECK_OK(ctx, fx_stack_load_json(s2, json));
    char *json2 = NULL;
    CHECK_OK(ctx, fx_stack_to_json(s2, &json2));
    CHECK(json && json2 && strcmp(json, json2) == 0);
    fx_free(json);
    fx_free(json2);

    /* Typed setters go through the same checks. */
    int idx = -1;
    CHECK_OK(ctx, fx_stack_append(s2, "color_matrix", &idx));
    CHECK(idx == 3);
    CHECK_OK(ctx, fx_stack_set_float(s2, idx, "mix", 0.25));
    CHECK_FAIL(ctx, fx_stack_set_float(s2, idx, "mix", 2), FX_ERR_BAD_PARAM, "[0, 1]");
    CHECK_OK(ctx, fx_stack_set_enum(s2, idx, "operator", "custom"));
    float m3[9] = {0, 1, 0, 1, 0, 0, 0, 0, 1};
    CHECK_OK(ctx, fx_stack_set_floats(s2, idx, "matrix", m3, 9)); /* 3x3 embeds into 4x4 */
    CHECK_FAIL(ctx, fx_stack_set_int(s2, 99, "mix", 1), FX_ERR_INVALID_ARGUMENT, "out of range");
    CHECK_FAIL(ctx, fx_stack_set_mask_json(s2, idx, "{\"object_index\": -1}"), FX_ERR_BAD_RECIPE, "integers >= 0");
    CHECK_OK(ctx, fx_stack_set_mask_json(s2, idx, "{\"object_index\": [2, 3]}"));
    CHECK_OK(ctx, fx_stack_remove(s2, 0));
    CHECK(fx_stack_count(s2) == 3);

    /* What the stack needs: the mask by object index asks for IndexOB; a disabled
     * effect's Cryptomatte mask asks for nothing. */
    char *need = NULL;
    CHECK_OK(ctx, fx_stack_required_passes(s2, &need));
    CHECK(need && strstr(need, "\"IndexOB\"") && strstr(need, "use_pass_object_index"));
    CHECK(need && !strstr(need, "CryptoObject"));
    fx_free(need);
    fx_stack_free(s2);
    fx_stack_free(s);

    /* Introspection */
    CHECK(fx_effect_count() >= 3);
    CHECK(fx_effect_doc("pixelate") != NULL);
    CHECK(fx_effect_doc("nope") == NULL);
    CHECK(fx_effect_param_count("nope") == -1);
    const fx_param_info *pi = fx_effect_param("gaussian_blur", 0);
    CHECK(pi && pi->size == sizeof(fx_param_info));
    char *desc = NULL;
    CHECK_OK(ctx, fx_effect_describe_json(ctx, "gaussian_blur", &desc));
    CHECK(desc && strstr(desc, "\"presets\"") && strstr(desc, "\"reference\""));
    fx_free(desc);
    CHECK_FAIL(ctx, fx_effect_describe_json(ctx, "nope", &desc), FX_ERR_UNKNOWN_EFFECT, "nope");
    CHECK(fx_quality_from_name("reference") == FX_QUALITY_REFERENCE);
    CHECK(fx_quality_from_name("best") == -1);
    fx_context_free(ctx);
}

static void test_cryptomatte_ids(void)
{
    /* Published MurmurHash3_x86_32 vectors */
    CHECK(fx_murmur3_32("", 0, 0) == 0);
    CHECK(fx_murmur3_32("hello", 5, 0) == 0x248bfa47u);
    const char *fox = "The quick brown fox jumps over the lazy dog";
    CHECK(fx_murmur3_32(fox, strlen(fox), 0) == 0x2e4ff723u);
    /* IDs are always normal, finite floats */
    char name[32];
    for (int i = 0; i < 20000; i++) {
        snprintf(name, sizeof name, "object_%d", i);
        float id = fx_cryptomatte_id(name);
        CHECK(isfinite(id) && (id == 0 || fpclassify(id) == FP_NORMAL));
    }
}

static void test_masks(void)
{
    fx_context *ctx = NULL;
    fx_context_new(&ctx, 2);
    const int w = 8, h = 6;
    fx_frame *f = tu_pattern_frame(ctx, w, h, 1);
    /* A Cryptomatte rank: left half "Statue" with coverage 1, the pixel at x=4 shared
     * 0.25 / 0.75 between "Statue" and "Floor"; an IndexOB pass: 7 on the top row. */
    float crypto[8 * 6 * 4], index_ob[8 * 6];
    float statue = fx_cryptomatte_id("Statue"), floor_ = fx_cryptomatte_id("Floor");
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            float *p = crypto + (y * w + x) * 4;
            if (x < 4) { p[0] = statue; p[1] = 1; p[2] = 0; p[3] = 0; }
            else if (x == 4) { p[0] = floor_; p[1] = 0.75f; p[2] = statue; p[3] = 0.25f; }
            else { p[0] = floor_; p[1] = 1; p[2] = 0; p[3] = 0; }
            index_ob[y * w + x] = y == 0 ? 7.0f : 1.0f;
        }
    fx_frame_add_pass(f, "CryptoObject00", 4, crypto);
    fx_frame_add_pass(f, "IndexOB", 1, index_ob);
    fx_frame_set_meta(f, "cryptomatte/CryptoObject/manifest", "{\"Statue\": \"x\", \"Floor\": \"y\"}");

    cJSON *j = cJSON_Parse("{\"object\": \"Statue\"}");
    fx_mask_spec spec;
    CHECK_OK(ctx, fx_mask_spec_parse(ctx, j, "t", &spec));
    cJSON_Delete(j);
    fx_mask *m = NULL;
    CHECK_OK(ctx, fx_mask_build(ctx, &spec, f, "t", &m));
    CHECK(m && m->coverage[0] == 1.0f && m->coverage[3] == 1.0f && m->coverage[4] == 0.25f &&
          m->coverage[5] == 0.0f);
    CHECK(m && m->bounds.x0 == 0 && m->bounds.x1 == 5 && m->bounds.y0 == 0 && m->bounds.y1 == h);
    fx_mask_free(m);
    fx_mask_spec_clear(&spec);

    /* index union name, restricted by a rect, inverted */
    j = cJSON_Parse("{\"object_index\": 7, \"rect\": [5, 0, 2, 6], \"invert\": true}");
    CHECK_OK(ctx, fx_mask_spec_parse(ctx, j, "t", &spec));
    cJSON_Delete(j);
    CHECK_OK(ctx, fx_mask_build(ctx, &spec, f, "t", &m));
    CHECK(m && m->coverage[5] == 0.0f && m->coverage[6] == 0.0f && m->coverage[7] == 1.0f &&
          m->coverage[0] == 1.0f && m->coverage[w + 5] == 1.0f);
    fx_mask_free(m);
    fx_mask_spec_clear(&spec);

    /* a relative rect scales with the display window: the right quarter of 8 px */
    j = cJSON_Parse("{\"rect_relative\": [0.75, 0, 0.25, 1]}");
    CHECK_OK(ctx, fx_mask_spec_parse(ctx, j, "t", &spec));
    cJSON_Delete(j);
    CHECK_OK(ctx, fx_mask_build(ctx, &spec, f, "t", &m));
    CHECK(m && m->coverage[5] == 0.0f && m->coverage[6] == 1.0f && m->coverage[7] == 1.0f &&
          m->bounds.x0 == 6 && m->bounds.x1 == 8);
    fx_mask_free(m);
    fx_mask_spec_clear(&spec);
    j = cJSON_Parse("{\"rect_relative\": [0.5, 0, -1, 1]}");
    CHECK_FAIL(ctx, fx_mask_spec_parse(ctx, j, "t", &spec), FX_ERR_BAD_RECIPE, "rect_relative");
    cJSON_Delete(j);

    /* a name not in the manifest warns; a missing pass is an error naming it */
    j = cJSON_Parse("{\"object\": \"Statu\"}");
    fx_mask_spec_parse(ctx, j, "effect 0 (pixelate)", &spec);
    cJSON_Delete(j);
    fx_context_clear_warnings(ctx);
    CHECK_OK(ctx, fx_mask_build(ctx, &spec, f, "effect 0 (pixelate)", &m));
    CHECK(fx_context_warning_count(ctx) >= 1 && tu_contains(fx_context_warning(ctx, 0), "'Statu' is not in"));
    fx_mask_free(m);
    fx_mask_spec_clear(&spec);
    j = cJSON_Parse("{\"material\": \"Water\"}");
    fx_mask_spec_parse(ctx, j, "effect 2 (pixelate)", &spec);
    cJSON_Delete(j);
    CHECK_FAIL(ctx, fx_mask_build(ctx, &spec, f, "effect 2 (pixelate)", &m), FX_ERR_MISSING_PASS,
               "effect 2 (pixelate): a mask by material name needs the CryptoMaterial pass");
    fx_mask_spec_clear(&spec);
    fx_frame_free(f);
    fx_context_free(ctx);
}

/* The stack honours masks for every effect: outside bit-identical. */
static void test_stack_masking(void)
{
    fx_context *ctx = NULL;
    fx_context_new(&ctx, 2);
    fx_frame *f = tu_pattern_frame(ctx, 37, 23, 3);
    fx_stack *s = NULL;
    fx_stack_new(ctx, &s);
    CHECK_OK(ctx, fx_stack_load_json(s, "{\"version\": 1, \"effects\": ["
                                        "{\"effect\": \"color_matrix\", \"params\": {\"operator\": \"sepia\"},"
                                        " \"mask\": {\"rect\": [5, 4, 10, 7]}},"
                                        "{\"effect\": \"gaussian_blur\", \"params\": {\"sigma\": 2},"
                                        " \"mask\": {\"rect\": [20, 10, 8, 8], \"invert\": true}}]}"));
    fx_frame *out = NULL;
    CHECK_OK(ctx, fx_stack_run(s, f, &out));
    float *a, *b;
    fx_frame_pass(f, "Combined", &a, NULL);
    fx_frame_pass(out, "Combined", &b, NULL);
    int outside_same = 1, inside_changed = 0;
    for (int y = 0; y < 23; y++)
        for (int x = 0; x < 37; x++) {
            int in1 = x >= 5 && x < 15 && y >= 4 && y < 11;
            int in2 = !(x >= 20 && x < 28 && y >= 10 && y < 18);
            size_t i = ((size_t)y * 37 + x) * 4;
            if (!in1 && !in2 && memcmp(a + i, b + i, 16) != 0)
                outside_same = 0;
            if (in1 && memcmp(a + i, b + i, 16) != 0)
                inside_changed = 1;
        }
    CHECK(outside_same);
    CHECK(inside_changed);
    char *t = NULL;
    CHECK_OK(ctx, fx_stack_timings_json(s, &t));
    CHECK(t && strstr(t, "\"effect\":\"gaussian_blur\""));
    fx_free(t);
    fx_frame_free(out);

    /* An empty stack, and a stack whose effects are all disabled, copy the image. */
    CHECK_OK(ctx, fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"pixelate\", \"enabled\": false}]}"));
    CHECK_OK(ctx, fx_stack_run(s, f, &out));
    fx_frame_pass(out, "Combined", &b, NULL);
    CHECK(memcmp(a, b, 37 * 23 * 16) == 0);
    fx_frame_free(out);

    /* No Combined: a clear error */
    fx_frame *empty = NULL;
    fx_frame_new(ctx, 4, 4, &empty);
    CHECK_FAIL(ctx, fx_stack_run(s, empty, &out), FX_ERR_MISSING_PASS, "Combined");
    CHECK(out == NULL);
    fx_frame_free(empty);
    fx_stack_free(s);
    fx_frame_free(f);
    fx_context_free(ctx);
}

typedef struct sum_job {
    double *partial;
} sum_job;

static void sum_range(void *user, int b, int e)
{
    sum_job *j = user;
    for (int i = b; i < e; i++) {
        double acc = 0;
        for (int k = 0; k < 1000; k++)
            acc += sin(i * 0.001 + k);
        j->partial[i] = acc;
    }
}

typedef struct worker_job {
    int workers;
    int bad;
    int *count; /* per item: how many times it ran */
} worker_job;

static void worker_range(void *user, int b, int e, int worker)
{
    worker_job *j = user;
    if (worker < 0 || worker >= j->workers)
        j->bad = 1;
    for (int i = b; i < e; i++)
        j->count[i]++;
}

/* Unchanged pixels are shared between frames of one context, never aliased for
 * writing: a writer gets its own copy, and freeing either frame leaves the other whole. */
static void test_shared_pixels(void)
{
    fx_context *ctx = NULL, *other = NULL;
    fx_context_new(&ctx, 2);
    fx_context_new(&other, 1);
    const size_t n = 29 * 17 * 4;
    fx_frame *in = tu_pattern_frame(ctx, 29, 17, 5);
    const float *in_px = NULL, *out_px = NULL;
    CHECK_OK(ctx, fx_frame_pass_read(in, "Combined", &in_px, NULL));
    float *keep = malloc(n * sizeof(float));
    memcpy(keep, in_px, n * sizeof(float));

    fx_stack *s = NULL;
    fx_stack_new(ctx, &s);
    CHECK_OK(ctx, fx_stack_load_json(s, "{\"version\": 1, \"effects\": []}"));
    fx_frame *out = NULL;
    CHECK_OK(ctx, fx_stack_run(s, in, &out));
    CHECK_OK(ctx, fx_frame_pass_read(out, "Combined", &out_px, NULL));
    CHECK(out_px == in_px); /* an empty stack allocates nothing */
    CHECK(strcmp(fx_frame_pass_name(out, 0), "Combined") == 0);

    /* Writing to the output copies first: the input keeps its pixels. */
    float *w = NULL;
    CHECK_OK(ctx, fx_frame_pass(out, "Combined", &w, NULL));
    CHECK(w != in_px);
    CHECK(memcmp(w, keep, n * sizeof(float)) == 0);
    w[0] = -7.0f;
    CHECK(memcmp(in_px, keep, n * sizeof(float)) == 0);
    fx_frame_free(out);

    /* The output outlives its input (ASan checks the buffer's lifetime). */
    CHECK_OK(ctx, fx_stack_run(s, in, &out));
    fx_frame *copy = NULL;
    fx_frame_new(ctx, 29, 17, &copy);
    CHECK_OK(ctx, fx_frame_copy_passes(copy, in));
    fx_frame_free(in);
    CHECK_OK(ctx, fx_frame_pass_read(out, "Combined", &out_px, NULL));
    CHECK(memcmp(out_px, keep, n * sizeof(float)) == 0);
    const float *copy_px = NULL;
    CHECK_OK(ctx, fx_frame_pass_read(copy, "Combined", &copy_px, NULL));
    CHECK(copy_px == out_px); /* three holders once, two now */
    fx_frame_free(out);
    CHECK(memcmp(copy_px, keep, n * sizeof(float)) == 0);

    /* A pass handed out writable is never shared again: writes through that pointer
     * after a run must not reach the run's output. */
    CHECK_OK(ctx, fx_frame_pass(copy, "Combined", &w, NULL));
    CHECK(w == copy_px); /* the last holder writes in place */
    CHECK_OK(ctx, fx_stack_run(s, copy, &out));
    CHECK_OK(ctx, fx_frame_pass_read(out, "Combined", &out_px, NULL));
    CHECK(out_px != w);
    w[1] = 1234.0f;
    CHECK(out_px[1] == keep[1]);
    fx_frame_free(out);

    /* Frames of another context get a copy (each context has its own buffer store). */
    fx_frame *far = NULL;
    fx_frame_new(other, 29, 17, &far);
    CHECK_OK(other, fx_frame_copy_passes(far, copy));
    const float *far_px = NULL;
    CHECK_OK(other, fx_frame_pass_read(far, "Combined", &far_px, NULL));
    CHECK(far_px != w && far_px[1] == 1234.0f);
    fx_frame_free(far);

    CHECK_FAIL(ctx, fx_frame_pass_read(copy, "Depth", &out_px, NULL), FX_ERR_MISSING_PASS, "Depth");
    fx_frame_free(copy);
    fx_stack_free(s);
    free(keep);
    fx_context_free(other);
    fx_context_free(ctx);
}

/* Adds to f the data passes stack s needs that f lacks (finite, varied values: a position
 * on a plane, a depth, a normal, colours), so that an effect needing more than Combined runs.
 * 0 when s needs something this cannot make (a camera, Cryptomatte): the caller says so. */
static int add_needed_passes(fx_context *ctx, fx_frame *f, const fx_stack *s)
{
    char *json = NULL;
    CHECK_OK(ctx, fx_stack_required_passes(s, &json));
    cJSON *root = json ? cJSON_Parse(json) : NULL;
    fx_free(json);
    const cJSON *passes = cJSON_GetObjectItem(root, "passes");
    int ok = root && !cJSON_IsTrue(cJSON_GetObjectItem(root, "camera"));
    const int w = fx_frame_width(f), h = fx_frame_height(f);
    const cJSON *it = NULL;
    cJSON_ArrayForEach(it, passes)
    {
        const char *name = cJSON_GetStringValue(it);
        float *have = NULL;
        if (!ok || !name || fx_frame_pass(f, name, &have, NULL) == FX_OK)
            continue;
        const int ch = strcmp(name, "Depth") == 0 ? 1 : strncmp(name, "Crypto", 6) == 0 ? 0 : 3;
        if (!ch) {
            ok = 0;
            break;
        }
        float *d = malloc((size_t)w * h * ch * sizeof(float));
        for (int i = 0; d && i < w * h; i++)
            for (int c = 0; c < ch; c++)
                d[(size_t)i * ch + c] = ch == 1 ? 2.0f + 0.01f * (float)(i % w)
                                      : strcmp(name, "Position") == 0 ? (c == 0 ? 0.1f * (float)(i % w)
                                                                          : c == 1 ? 0.1f * (float)(i / w) : 0.0f)
                                      : strcmp(name, "Normal") == 0 ? (c == 2 ? 1.0f : 0.0f)
                                                                    : 0.25f + 0.5f * (float)c / 3.0f;
        CHECK(d && fx_frame_add_pass(f, name, ch, d) == FX_OK);
        free(d);
    }
    cJSON_Delete(root);
    return ok;
}

/* Effects that keep their output finite themselves (the stack then skips its scan) must
 * do so for a Combined built through the API, which the reader never sanitised: NaN and
 * +-Inf in a third of the pixels, through the effect and through its identity path. */
static void test_own_finite_effects(void)
{
    fx_context *ctx = NULL;
    fx_context_new(&ctx, 2);
    const int w = 23, h = 11;
    fx_frame *f = tu_pattern_frame(ctx, w, h, 9);
    float *px = NULL;
    CHECK_OK(ctx, fx_frame_pass(f, "Combined", &px, NULL));
    const float odd[3] = {NAN, INFINITY, -INFINITY};
    for (int i = 0; i < w * h * 4; i += 3)
        px[i] = odd[(i / 3) % 3];
    int flagged = 0;
    for (int c = 0; c < fx_effect_class_count; c++) {
        const fx_effect_class *cls = fx_effect_classes[c];
        if (!(cls->flags & FX_EFFECT_OWN_FINITE))
            continue;
        flagged++;
        /* the defaults, the identity, and every preset (other code paths: caustics' draft) */
        const char *variants[5] = {"{}", "{\"mix\": 0}", "{}", "{}", "{}"};
        const char *quality[5] = {"final", "final", "draft", "preview", "reference"};
        for (int v = 0; v < 5; v++) {
            if (v == 1 && !fx_effect_find_param(cls, "mix"))
                continue;
            char json[256];
            snprintf(json, sizeof json,
                     "{\"version\": 1, \"quality\": \"%s\", \"effects\": [{\"effect\": \"%s\", \"params\": %s}]}",
                     quality[v], cls->name, variants[v]);
            fx_stack *s = NULL;
            fx_stack_new(ctx, &s);
            CHECK_OK(ctx, fx_stack_load_json(s, json));
            if (!add_needed_passes(ctx, f, s))
                fprintf(stderr, "  %s: needs what this test cannot make (a camera, Cryptomatte)\n", cls->name);
            fx_context_clear_warnings(ctx);
            fx_frame *out = NULL;
            CHECK_OK(ctx, fx_stack_run(s, f, &out));
            const float *o = NULL;
            CHECK_OK(ctx, fx_frame_pass_read(out, "Combined", &o, NULL));
            if (!tu_all_finite(o, (size_t)w * h * 4))
                fprintf(stderr, "  %s %s at %s: non-finite output\n", cls->name, variants[v], quality[v]);
            CHECK(tu_all_finite(o, (size_t)w * h * 4));
            if (v == 1) /* the identity copies the NaN: replaced, and reported */
                CHECK(fx_context_warning_count(ctx) > 0);
            fx_frame_free(out);
            fx_stack_free(s);
        }
    }
    CHECK(flagged >= 2);
    fx_frame_free(f);
    fx_context_free(ctx);
}

/* Runs `json` on a copy of f that the stack may consume; compares with fx_stack_run on f
 * and with the effects run one stack at a time (in-place effects must give the same bits). */
static void check_consume(fx_context *ctx, const fx_frame *f, const char *json, const char *const *singles,
                          int all_in_place)
{
    const int w = fx_frame_width(f), h = fx_frame_height(f);
    const size_t n = (size_t)w * h * 4;
    fx_stack *s = NULL;
    fx_stack_new(ctx, &s);
    CHECK_OK(ctx, fx_stack_load_json(s, json));
    fx_frame *ref = NULL, *got = NULL, *copy = NULL;
    CHECK_OK(ctx, fx_stack_run(s, f, &ref));
    fx_frame_new(ctx, w, h, &copy);
    const float *fp = NULL;
    fx_frame_pass_read(f, "Combined", &fp, NULL);
    CHECK_OK(ctx, fx_frame_add_pass(copy, "Combined", 4, fp)); /* its own pixels: consumable */
    const float *given = NULL;
    fx_frame_pass_read(copy, "Combined", &given, NULL);
    CHECK_OK(ctx, fx_stack_run_consume(s, copy, 0, &got));
    const float *a = NULL, *b = NULL;
    CHECK_OK(ctx, fx_frame_pass_read(ref, "Combined", &a, NULL));
    CHECK_OK(ctx, fx_frame_pass_read(got, "Combined", &b, NULL));
    CHECK(memcmp(a, b, n * sizeof(float)) == 0);
    if (all_in_place)
        CHECK(b == given); /* written over the consumed input: no second buffer */
    /* one effect at a time */
    fx_frame *step = NULL;
    fx_frame_new(ctx, w, h, &step);
    CHECK_OK(ctx, fx_frame_add_pass(step, "Combined", 4, fp));
    for (int i = 0; singles[i]; i++) {
        fx_stack *one = NULL;
        fx_stack_new(ctx, &one);
        CHECK_OK(ctx, fx_stack_load_json(one, singles[i]));
        fx_frame *next = NULL;
        CHECK_OK(ctx, fx_stack_run(one, step, &next));
        fx_frame_free(step);
        step = next;
        fx_stack_free(one);
    }
    const float *c = NULL;
    CHECK_OK(ctx, fx_frame_pass_read(step, "Combined", &c, NULL));
    if (memcmp(a, c, n * sizeof(float)) != 0)
        fprintf(stderr, "  %s: differs from its effects run one by one\n", json);
    CHECK(memcmp(a, c, n * sizeof(float)) == 0);
    fx_frame_free(step);
    fx_frame_free(ref);
    fx_frame_free(got);
    fx_stack_free(s);
}

/* In-place effects and consumed inputs: same bits as the plain run; a consumed frame's
 * Combined that another frame also holds is never written. */
static void test_in_place(void)
{
    fx_context *ctx = NULL;
    fx_context_new(&ctx, 2);
    fx_frame *f = tu_pattern_frame(ctx, 41, 19, 4);
#define E(x) "{\"effect\": " x "}"
#define R(x) "{\"version\": 1, \"effects\": [" x "]}"
    const char *cm = E("\"color_matrix\", \"params\": {\"operator\": \"sepia\"}");
    const char *po = E("\"posterize\", \"params\": {\"levels\": 3}");
    const char *bl = E("\"gaussian_blur\", \"params\": {\"sigma\": 1.5}");
    const char *pm = E("\"posterize\", \"params\": {\"levels\": 5}, \"mask\": {\"rect\": [3, 2, 20, 9]}");
    char json[1024], s1[256], s2[256], s3[256];
    snprintf(s1, sizeof s1, R("%s"), cm);
    snprintf(s2, sizeof s2, R("%s"), po);
    snprintf(json, sizeof json, R("%s, %s"), cm, po);
    check_consume(ctx, f, json, (const char *const[]){s1, s2, NULL}, 1);
    snprintf(s1, sizeof s1, R("%s"), bl);
    snprintf(s3, sizeof s3, R("%s"), pm);
    snprintf(s2, sizeof s2, R("%s"), cm);
    snprintf(json, sizeof json, R("%s, %s, %s, %s"), bl, cm, pm, cm);
    check_consume(ctx, f, json, (const char *const[]){s1, s2, s3, s2, NULL}, 0);
    snprintf(json, sizeof json, R("%s, %s"), pm, cm);
    check_consume(ctx, f, json, (const char *const[]){s3, s2, NULL}, 0);
    const char *sc = E("\"sin_city\", \"params\": {\"levels\": 3, \"mix\": 0.8}");
    snprintf(s1, sizeof s1, R("%s"), sc);
    snprintf(s3, sizeof s3, R("%s"), po);
    snprintf(json, sizeof json, R("%s, %s"), sc, po);
    check_consume(ctx, f, json, (const char *const[]){s1, s3, NULL}, 1);
    /* the blur writes over its input with every algorithm (not when it keeps alpha) */
    static const char *const blurs[] = {
        E("\"gaussian_blur\", \"params\": {\"sigma\": 3.5, \"algorithm\": \"box\"}"),
        E("\"gaussian_blur\", \"params\": {\"sigma\": 2.5, \"algorithm\": \"recursive\"}"),
        E("\"gaussian_blur\", \"params\": {\"sigma\": 1.7, \"algorithm\": \"exact\"}"),
        E("\"gaussian_blur\", \"params\": {\"sigma\": 0.1}"),
        E("\"gaussian_blur\", \"params\": {\"sigma\": 2.5, \"alpha\": false}"),
        E("\"gaussian_blur\", \"params\": {\"kernel\": \"paper_5x5\"}"),
    };
    for (int i = 0; i < FX_COUNT_OF(blurs); i++) {
        snprintf(s1, sizeof s1, R("%s"), blurs[i]);
        snprintf(json, sizeof json, R("%s, %s"), blurs[i], cm);
        check_consume(ctx, f, json, (const char *const[]){s1, s2, NULL}, i < 4);
    }

    /* A consumed frame whose Combined another frame holds: that frame keeps its pixels. */
    fx_frame *keeper = NULL, *given = NULL, *out = NULL;
    fx_frame_new(ctx, 41, 19, &keeper);
    fx_frame_new(ctx, 41, 19, &given);
    CHECK_OK(ctx, fx_frame_copy_passes(keeper, f));
    CHECK_OK(ctx, fx_frame_copy_passes(given, f)); /* three holders of f's Combined */
    const float *fp = NULL, *kp = NULL;
    fx_frame_pass_read(f, "Combined", &fp, NULL);
    float *before = malloc(41 * 19 * 16);
    memcpy(before, fp, 41 * 19 * 16);
    fx_stack *s = NULL;
    fx_stack_new(ctx, &s);
    snprintf(json, sizeof json, R("%s"), cm);
    CHECK_OK(ctx, fx_stack_load_json(s, json));
    CHECK_OK(ctx, fx_stack_run_consume(s, given, 1, &out));
    CHECK(fx_frame_pass_count(out) == fx_frame_pass_count(f)); /* keep_passes: every pass handed over */
    fx_frame_pass_read(keeper, "Combined", &kp, NULL);
    CHECK(memcmp(kp, before, 41 * 19 * 16) == 0);
    CHECK(memcmp(fp, before, 41 * 19 * 16) == 0);
    fx_frame_free(out);
    CHECK_FAIL(ctx, fx_stack_run_consume(s, NULL, 0, &out), FX_ERR_INVALID_ARGUMENT, "NULL");
    CHECK(out == NULL);
#undef E
#undef R
    free(before);
    fx_stack_free(s);
    fx_frame_free(keeper);
    fx_frame_free(f);
    fx_context_free(ctx);
}

static void test_parallel_for(void)
{
    /* Same results whatever the thread count; nested loops do not deadlock. */
    double r1[257], r2[257];
    fx_context *c1 = NULL, *c2 = NULL;
    fx_context_new(&c1, 1);
    fx_context_new(&c2, 3);
    sum_job j1 = {r1}, j2 = {r2};
    fx_parallel_for(c1, 257, 5, sum_range, &j1);
    fx_parallel_for(c2, 257, fx_grain_for(c2, 257), sum_range, &j2);
    CHECK(memcmp(r1, r2, sizeof r1) == 0);
    for (int rep = 0; rep < 50; rep++)
        fx_parallel_for(c2, 257, 1, sum_range, &j2);
    CHECK(memcmp(r1, r2, sizeof r1) == 0);
    /* worker indices stay below fx_parallel_workers; every item runs exactly once */
    int count[1000] = {0};
    worker_job wj = {fx_parallel_workers(c2), 0, count};
    CHECK(wj.workers == 3);
    for (int rep = 0; rep < 20; rep++)
        fx_parallel_for_worker(c2, 1000, 7, worker_range, &wj);
    int all20 = 1;
    for (int i = 0; i < 1000; i++)
        all20 &= count[i] == 20;
    CHECK(!wj.bad && all20);
    fx_context_free(c1);
    fx_context_free(c2);
}

static void test_sidecar(void)
{
    fx_context *ctx = NULL;
    fx_context_new(&ctx, 1);
    fx_frame *f = NULL;
    fx_frame_new(ctx, 4, 4, &f);
    const char *good =
        "{\"world_to_camera\": [[1,0,0,0],[0,1,0,0],[0,0,1,-5],[0,0,0,1]],"
        " \"projection\": [[1,0,0,0],[0,1.7,0,0],[0,0,-1.002,-0.2002],[0,0,-1,0]],"
        " \"clip_start\": 0.1, \"clip_end\": 100, \"frame\": 12, \"fps\": 25,"
        " \"lights\": [{\"name\": \"Sun\", \"type\": \"SUN\", \"direction\": [0, 0.5, -1]}]}";
    CHECK_OK(ctx, fx_frame_apply_sidecar(f, good));
    fx_camera cam;
    CHECK(fx_frame_camera(f, &cam) && cam.world_to_camera[11] == -5.0f && !cam.orthographic);
    double frame = 0, fps = 0;
    fx_frame_time(f, &frame, &fps);
    CHECK(frame == 12 && fps == 25);
    CHECK(tu_contains(fx_frame_meta(f, "libfx:lights"), "\"Sun\""));
    /* bad sidecars change nothing and name the problem */
    CHECK_FAIL(ctx, fx_frame_apply_sidecar(f, "{\"lights\": [{\"name\": \"L\", \"type\": \"POINT\", \"position\": [1, 2]}]}"),
               FX_ERR_BAD_RECIPE, "lights[0].position");
    CHECK_FAIL(ctx, fx_frame_apply_sidecar(f, "{\"camera_pos\": 1}"), FX_ERR_BAD_RECIPE, "unknown key \"camera_pos\"");
    CHECK_FAIL(ctx, fx_frame_apply_sidecar(f, "{\"frame\": 3, \"frame\": 4}"), FX_ERR_BAD_RECIPE,
               "sidecar: key \"frame\" appears twice");
    CHECK_FAIL(ctx, fx_frame_apply_sidecar(f, "{\"world_to_camera\": [1, 2]}"), FX_ERR_BAD_RECIPE, "world_to_camera");
    CHECK_FAIL(ctx, fx_frame_apply_sidecar_file(f, "/nonexistent/cam.json"), FX_ERR_IO, "/nonexistent/cam.json");
    fx_frame_time(f, &frame, &fps);
    CHECK(frame == 12);
    /* lights by name, or the first sun */
    fx_light light;
    CHECK_OK(ctx, fx_frame_find_light(f, NULL, "effect 0 (god_rays)", &light));
    CHECK(light.type == FX_LIGHT_SUN && strcmp(light.name, "Sun") == 0 && light.direction.z < -0.8f);
    CHECK_FAIL(ctx, fx_frame_find_light(f, "Lamp", "effect 0 (god_rays)", &light), FX_ERR_BAD_PARAM,
               "no light named 'Lamp' in the scene (lights: Sun)");
    fx_frame *bare = NULL;
    fx_frame_new(ctx, 1, 1, &bare);
    CHECK_FAIL(ctx, fx_frame_find_light(bare, NULL, "effect 1 (vsm_shadows)", &light), FX_ERR_NO_LIGHTS,
               "effect 1 (vsm_shadows) needs the scene's lights");
    fx_frame_free(bare);
    fx_frame_free(f);
    fx_context_free(ctx);
}

int main(void)
{
    test_sidecar();
    test_context_and_errors();
    test_errors_are_per_thread();
    test_frames_outlive_their_context();
    test_stack_across_contexts();
    test_recipes();
    test_cryptomatte_ids();
    test_masks();
    test_stack_masking();
    test_shared_pixels();
    test_own_finite_effects();
    test_in_place();
    test_parallel_for();
    return tu_finish("test_core");
}
