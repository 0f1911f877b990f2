/* Saved recipes keep loading, and the output stays bit-identical.
 *
 * tests/data/recipes_v1/<effect>.json holds one recipe per effect as written before
 * effect parameters had versions, with every parameter set to a non-default value. Each
 * must still load, must still give exactly those parameters, and its output on the
 * synthetic scene must hash to the value in checksums.txt. The checksums also cover each
 * effect with default parameters at every quality preset and under a material mask.
 * checksums.txt was written by the build before the effect-contract refactor (main just
 * before that merge, with the float recursive blur already on), so a change to any
 * effect's arithmetic fails here.
 *
 * LIBFX_WRITE_CHECKSUMS=FILE writes the checksums instead of comparing (only for a
 * deliberate change of output; say why in the commit). */
#include "fx_scene_test.h"

#include <cjson/cJSON.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

enum { W = 48, H = 32 };

static uint64_t fnv1a(const void *data, size_t n)
{
    const unsigned char *p = data;
    uint64_t h = 1469598103934665603ull;
    for (size_t i = 0; i < n; i++) {
        h ^= p[i];
        h *= 1099511628211ull;
    }
    return h;
}

static char *expected_text;
static FILE *write_to;

/* Compares (or writes) the hash of one case's output Combined. */
static void check_hash(const char *name, const float *rgba)
{
    if (!rgba) {
        CHECK(!"the case ran");
        fprintf(stderr, "  case %s did not run\n", name);
        return;
    }
    uint64_t h = fnv1a(rgba, (size_t)W * H * 4 * sizeof(float));
    char line[256];
    snprintf(line, sizeof line, "%s %016llx\n", name, (unsigned long long)h);
    if (write_to) {
        fputs(line, write_to);
        return;
    }
    char key[200];
    snprintf(key, sizeof key, "%s ", name);
    const char *at = expected_text ? strstr(expected_text, key) : NULL;
    while (at && at != expected_text && at[-1] != '\n')
        at = strstr(at + 1, key);
    int ok = at && strncmp(at, line, strlen(line)) == 0;
    CHECK(ok);
    if (!ok)
        fprintf(stderr, "  %s: output hash %016llx, expected: %.40s\n", name, (unsigned long long)h,
                at ? at : "(no line)");
}

static float *run_json(fx_context *ctx, const fx_frame *f, const char *json, const char *name)
{
    fx_stack *s = NULL;
    CHECK_OK(ctx, fx_stack_new(ctx, &s));
    fx_result r = s ? fx_stack_load_json(s, json) : FX_ERR_INTERNAL;
    CHECK_OK(ctx, r);
    float *out = r ? NULL : et_run(ctx, s, f);
    if (r)
        fprintf(stderr, "  %s: %s\n", name, fx_context_error(ctx));
    fx_stack_free(s);
    return out;
}

/* A value as the recipe wrote it and as the library gives it back (floats are stored as
 * float). */
static int same_value(const cJSON *want, const cJSON *got)
{
    if (!got)
        return 0;
    if (cJSON_Compare(want, got, 1))
        return 1;
    if (cJSON_IsNumber(want) && cJSON_IsNumber(got))
        return (float)want->valuedouble == (float)got->valuedouble;
    if (cJSON_IsArray(want) && cJSON_IsArray(got) && cJSON_GetArraySize(want) == cJSON_GetArraySize(got)) {
        for (int i = 0; i < cJSON_GetArraySize(want); i++)
            if ((float)cJSON_GetArrayItem(want, i)->valuedouble != (float)cJSON_GetArrayItem(got, i)->valuedouble)
                return 0;
        return 1;
    }
    return 0;
}

static void check_object(const char *effect, const cJSON *want, const cJSON *got, const char *what)
{
    const cJSON *item;
    cJSON_ArrayForEach(item, want) {
        int same = same_value(item, cJSON_GetObjectItem(got, item->string));
        CHECK(same);
        if (!same)
            fprintf(stderr, "  %s: parameter %s changed (%s)\n", effect, item->string, what);
    }
}

/* Every parameter of the class is in the recipe, and the loaded stack holds exactly the
 * recipe's values, both as explicit values (saved back) and as the effective parameters
 * the effect runs with. */
static void check_params_kept(fx_context *ctx, const char *effect, const char *json)
{
    cJSON *want = cJSON_Parse(json);
    const cJSON *eff = cJSON_GetArrayItem(cJSON_GetObjectItem(want, "effects"), 0);
    const cJSON *wp = cJSON_GetObjectItem(eff, "params");
    CHECK(cJSON_GetArraySize(wp) == fx_effect_param_count(effect));
    fx_stack *s = NULL;
    CHECK_OK(ctx, fx_stack_new(ctx, &s));
    CHECK_OK(ctx, fx_stack_load_json(s, json));
    char *saved = NULL, *effective = NULL;
    CHECK_OK(ctx, fx_stack_to_json(s, &saved));
    cJSON *got = saved ? cJSON_Parse(saved) : NULL;
    check_object(effect, wp,
                 cJSON_GetObjectItem(cJSON_GetArrayItem(cJSON_GetObjectItem(got, "effects"), 0), "params"),
                 "saved recipe");
    CHECK_OK(ctx, fx_stack_effective_params_json(s, 0, &effective));
    cJSON *e = effective ? cJSON_Parse(effective) : NULL;
    CHECK(cJSON_GetArraySize(e) == fx_effect_param_count(effect));
    check_object(effect, wp, e, "effective parameters");
    cJSON_Delete(e);
    cJSON_Delete(got);
    fx_free(saved);
    fx_free(effective);
    fx_stack_free(s);
    cJSON_Delete(want);
}

/* A small lat-long environment for voronoi_caustics' "environment" parameter. */
static void write_environment(fx_context *ctx, const char *path)
{
    enum { EW = 16, EH = 8 };
    float px[EW * EH * 4];
    for (int i = 0; i < EW * EH; i++) {
        px[i * 4 + 0] = 0.2f + 0.05f * (float)(i % EW);
        px[i * 4 + 1] = 0.3f + 0.07f * (float)(i / EW);
        px[i * 4 + 2] = 0.9f;
        px[i * 4 + 3] = 1.0f;
    }
    fx_frame *f = NULL;
    CHECK_OK(ctx, fx_frame_new(ctx, EW, EH, &f));
    CHECK_OK(ctx, fx_frame_add_pass(f, "Combined", 4, px));
    CHECK_OK(ctx, fx_frame_write_exr(f, path, NULL));
    fx_frame_free(f);
}

int main(void)
{
    const char *data = getenv("LIBFX_TEST_DATA");
    const char *write_path = getenv("LIBFX_WRITE_CHECKSUMS");
    if (!data) {
        fprintf(stderr, "LIBFX_TEST_DATA is not set\n");
        return 1;
    }
    char path[1024];
    snprintf(path, sizeof path, "%s/recipes_v1/checksums.txt", data);
    if (write_path)
        write_to = fopen(write_path, "w");
    else
        expected_text = tu_slurp(path, NULL);
    CHECK(write_to || expected_text);

    fx_context *ctx = NULL;
    CHECK_OK(ctx, fx_context_new(&ctx, 2));
    const char *dir = tu_tmpdir("recipes_v1");
    write_aux_views(ctx, dir);
    char env[600];
    snprintf(env, sizeof env, "%s/recipes_v1_env.exr", dir);
    write_environment(ctx, env);
    CHECK(chdir(dir) == 0); /* the recipes name the environment relative to here */
    scene sc;
    scene_build(&sc, W, H);
    fx_frame *f = frame_from_scene(ctx, &sc, SIDECAR_LIGHTS_FRONT);
    scene_free(&sc);
    CHECK(f != NULL);

    for (int e = 0; f && e < fx_effect_count(); e++) {
        const char *effect = fx_effect_name(e);
        char name[200];
        snprintf(path, sizeof path, "%s/recipes_v1/%s.json", data, effect);
        char *json = tu_slurp(path, NULL);
        CHECK(json != NULL);
        if (!json) {
            fprintf(stderr, "  no recipe %s\n", path);
            continue;
        }
        check_params_kept(ctx, effect, json);
        snprintf(name, sizeof name, "%s/recipe", effect);
        float *out = run_json(ctx, f, json, name);
        check_hash(name, out);
        free(out);
        free(json);
        for (int q = FX_QUALITY_DRAFT; q <= FX_QUALITY_REFERENCE; q++) {
            char recipe[512];
            snprintf(recipe, sizeof recipe,
                     "{\"version\": 1, \"quality\": \"%s\", \"effects\": [{\"effect\": \"%s\"}]}",
                     fx_quality_name(q), effect);
            snprintf(name, sizeof name, "%s/default/%s", effect, fx_quality_name(q));
            out = run_json(ctx, f, recipe, name);
            check_hash(name, out);
            free(out);
        }
        char recipe[512];
        snprintf(recipe, sizeof recipe,
                 "{\"version\": 1, \"effects\": [{\"effect\": \"%s\", \"mask\": {\"rect_relative\": [0.2, 0.3, 0.5, 0.4]}}]}",
                 effect);
        snprintf(name, sizeof name, "%s/default/masked", effect);
        out = run_json(ctx, f, recipe, name);
        check_hash(name, out);
        free(out);
    }
    fx_frame_free(f);
    fx_context_free(ctx);
    free(expected_text);
    if (write_to)
        fclose(write_to);
    return tu_finish("test_recipes_v1");
}
