/* The effect contract: parameter versions and their migration (with a test-only effect
 * at params_version 3), setters that commit the whole effect, the identity skip and the
 * effective parameters of a stack. */
#include "testutil.h"

#include "core/effect.h"

#include <cjson/cJSON.h>
#include <stdlib.h>
#include <string.h>

/* ---- a test-only effect whose parameters changed twice ---- */

typedef struct mig_params {
    float radius; /* v1: "size" */
    float amount; /* v1, v2: "amount_percent", 0..100 */
    int steps;
} mig_params;

static const fx_param_def mig_table[] = {
    FX_P_FLOAT(mig_params, radius, "radius", 1, 0, 100, 0, 10, "pixels", "Radius (was size)"),
    FX_P_FLOAT(mig_params, amount, "amount", 0.25, 0, 1, 0, 1, "factor", "Amount (was a percentage)"),
    FX_P_INT(mig_params, steps, "steps", 4, 1, 64, 1, 16, "", "Steps"),
};

static const fx_param_migration mig_steps[] = {
    {1, "size", "radius", 0, 0, "renamed in version 2"},
    {2, "amount_percent", "amount", 0.01, 0, "a fraction since version 3"},
};

static fx_result mig_process(const fx_effect_run *run)
{
    return fx_effect_pass_through(run);
}

static const fx_effect_class mig_class = {
    .name = "test_migrated",
    .doc = "test only",
    .params_size = sizeof(mig_params),
    .params = mig_table,
    .param_count = FX_COUNT_OF(mig_table),
    .process = mig_process,
    .params_version = 3,
    .migrations = mig_steps,
    .migration_count = FX_COUNT_OF(mig_steps),
};

static char *load_and_effective(fx_context *ctx, fx_stack *s, const char *recipe, fx_result *r)
{
    *r = fx_stack_load_json(s, recipe);
    char *json = NULL;
    if (*r == FX_OK)
        CHECK_OK(ctx, fx_stack_effective_params_json(s, 0, &json));
    return json;
}

static int warned(fx_context *ctx, const char *needle)
{
    for (int i = 0; i < fx_context_warning_count(ctx); i++)
        if (tu_contains(fx_context_warning(ctx, i), needle))
            return 1;
    return 0;
}

static void test_migration(void)
{
    fx_context *ctx = NULL;
    CHECK_OK(ctx, fx_context_new(&ctx, 2));
    fx_effect_register_test_class(&mig_class);
    fx_stack *s = NULL;
    CHECK_OK(ctx, fx_stack_new(ctx, &s));
    fx_result r;

    /* version 1: both steps, a warning for each, nothing dropped */
    fx_context_clear_warnings(ctx);
    char *eff = load_and_effective(
        ctx, s,
        "{\"version\": 1, \"effects\": [{\"effect\": \"test_migrated\", \"params_version\": 1,"
        " \"params\": {\"size\": 4, \"amount_percent\": 50, \"steps\": 7}}]}",
        &r);
    CHECK_OK(ctx, r);
    CHECK(eff && tu_contains(eff, "\"radius\":4") && tu_contains(eff, "\"amount\":0.5") &&
          tu_contains(eff, "\"steps\":7"));
    CHECK(warned(ctx, "'size'") && warned(ctx, "now 'radius'"));
    CHECK(warned(ctx, "'amount_percent'") && warned(ctx, "fraction"));
    fx_free(eff);
    /* the saved recipe is at the current version, under the new names */
    char *saved = NULL;
    CHECK_OK(ctx, fx_stack_to_json(s, &saved));
    CHECK(saved != NULL);
    cJSON *j = saved ? cJSON_Parse(saved) : NULL;
    const cJSON *e0 = cJSON_GetArrayItem(cJSON_GetObjectItem(j, "effects"), 0);
    CHECK(cJSON_GetNumberValue(cJSON_GetObjectItem(e0, "params_version")) == 3);
    CHECK(cJSON_GetObjectItem(cJSON_GetObjectItem(e0, "params"), "radius") != NULL);
    CHECK(cJSON_GetObjectItem(cJSON_GetObjectItem(e0, "params"), "size") == NULL);
    cJSON_Delete(j);
    /* ... and loads again without a warning */
    fx_context_clear_warnings(ctx);
    eff = load_and_effective(ctx, s, saved, &r);
    CHECK_OK(ctx, r);
    CHECK(eff && tu_contains(eff, "\"radius\":4") && tu_contains(eff, "\"amount\":0.5"));
    CHECK(fx_context_warning_count(ctx) == 0);
    fx_free(eff);
    fx_free(saved);

    /* no params_version: version 1 (recipes from before versions) */
    eff = load_and_effective(
        ctx, s, "{\"version\": 1, \"effects\": [{\"effect\": \"test_migrated\", \"params\": {\"size\": 2}}]}", &r);
    CHECK_OK(ctx, r);
    CHECK(eff && tu_contains(eff, "\"radius\":2"));
    fx_free(eff);

    /* version 2: only the second step */
    eff = load_and_effective(ctx, s,
                             "{\"version\": 1, \"effects\": [{\"effect\": \"test_migrated\", \"params_version\": 2,"
                             " \"params\": {\"radius\": 3, \"amount_percent\": 20}}]}",
                             &r);
    CHECK_OK(ctx, r);
    CHECK(eff && tu_contains(eff, "\"radius\":3") && tu_contains(eff, "\"amount\":0.2"));
    fx_free(eff);

    /* refusals leave the stack as it was */
    CHECK_FAIL(ctx,
               fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"test_migrated\","
                                     " \"params_version\": 4, \"params\": {}}]}"),
               FX_ERR_BAD_RECIPE, "newer than this libfx knows");
    CHECK_FAIL(ctx,
               fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"test_migrated\","
                                     " \"params_version\": 1, \"params\": {\"size\": 1, \"radius\": 2}}]}"),
               FX_ERR_BAD_PARAM, "keep one");
    CHECK_FAIL(ctx,
               fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"test_migrated\","
                                     " \"params_version\": 1.5}]}"),
               FX_ERR_BAD_RECIPE, "params_version");
    /* a version-1 value out of the new range after conversion is refused, not clamped */
    CHECK_FAIL(ctx,
               fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"test_migrated\","
                                     " \"params_version\": 2, \"params\": {\"amount_percent\": 150}}]}"),
               FX_ERR_BAD_PARAM, "amount");
    /* an old name the migration does not know is not dropped: an error */
    CHECK_FAIL(ctx,
               fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"test_migrated\","
                                     " \"params_version\": 3, \"params\": {\"size\": 1}}]}"),
               FX_ERR_BAD_PARAM, "size");
    eff = NULL;
    CHECK_OK(ctx, fx_stack_effective_params_json(s, 0, &eff));
    CHECK(eff && tu_contains(eff, "\"radius\":3")); /* the last good load */
    fx_free(eff);

    /* the public helpers the add-on uses */
    int v = 0;
    CHECK_OK(ctx, fx_effect_params_version(ctx, "test_migrated", &v));
    CHECK(v == 3);
    CHECK_OK(ctx, fx_effect_params_version(ctx, "gaussian_blur", &v));
    CHECK(v == 1);
    CHECK_FAIL(ctx, fx_effect_params_version(ctx, "nope", &v), FX_ERR_UNKNOWN_EFFECT, "nope");
    char *out = NULL;
    CHECK_OK(ctx, fx_effect_migrate_params(ctx, "test_migrated", 1, "{\"size\": 5, \"amount_percent\": 10}", &out));
    CHECK(out && tu_contains(out, "\"radius\":5") && tu_contains(out, "\"amount\":0.1"));
    fx_free(out);
    out = NULL;
    CHECK_OK(ctx, fx_effect_migrate_params(ctx, "gaussian_blur", 1, "{\"sigma\": 2}", &out));
    CHECK(out && strcmp(out, "{\"sigma\":2}") == 0);
    fx_free(out);
    CHECK_FAIL(ctx, fx_effect_migrate_params(ctx, "gaussian_blur", 2, "{}", &out), FX_ERR_BAD_RECIPE, "newer");
    char *desc = NULL;
    CHECK_OK(ctx, fx_effect_describe_json(ctx, "test_migrated", &desc));
    CHECK(desc && tu_contains(desc, "\"params_version\":3"));
    fx_free(desc);
    CHECK_OK(ctx, fx_effect_describe_json(ctx, "pixelate", &desc));
    CHECK(desc && tu_contains(desc, "\"params_version\":1"));
    fx_free(desc);

    fx_stack_free(s);
    fx_effect_register_test_class(NULL);
    fx_context_free(ctx);
}

/* A setter that breaks a check between parameters is refused at once, naming the effect
 * and the parameter, and changes nothing. */
static void test_setters_commit(void)
{
    fx_context *ctx = NULL;
    CHECK_OK(ctx, fx_context_new(&ctx, 2));
    fx_stack *s = NULL;
    CHECK_OK(ctx, fx_stack_new(ctx, &s));
    int idx = -1;
    CHECK_OK(ctx, fx_stack_append(s, "rain", &idx));
    char *before = NULL, *after = NULL, *eff0 = NULL, *eff1 = NULL;
    CHECK_OK(ctx, fx_stack_to_json(s, &before));
    CHECK_OK(ctx, fx_stack_effective_params_json(s, idx, &eff0));
    CHECK_FAIL(ctx, fx_stack_set_float(s, idx, "near", 50), FX_ERR_BAD_PARAM, "effect 0 (rain)");
    CHECK(tu_contains(fx_context_error(ctx), "near"));
    CHECK_OK(ctx, fx_stack_to_json(s, &after));
    CHECK_OK(ctx, fx_stack_effective_params_json(s, idx, &eff1));
    CHECK(before && after && strcmp(before, after) == 0);
    CHECK(eff0 && eff1 && strcmp(eff0, eff1) == 0);
    fx_free(after);
    fx_free(eff1);
    /* a good value is taken, and shows in the effective parameters */
    CHECK_OK(ctx, fx_stack_set_float(s, idx, "near", 3));
    CHECK_OK(ctx, fx_stack_effective_params_json(s, idx, &eff1));
    CHECK(eff1 && tu_contains(eff1, "\"near\":3"));
    fx_free(eff1);
    fx_free(before);
    fx_free(eff0);
    /* the stack's quality commits each effect's preset */
    CHECK_OK(ctx, fx_stack_append(s, "ssr_mirror", &idx));
    CHECK_OK(ctx, fx_stack_set_quality(s, FX_QUALITY_DRAFT));
    CHECK_OK(ctx, fx_stack_effective_params_json(s, idx, &eff0));
    CHECK_OK(ctx, fx_stack_set_quality(s, FX_QUALITY_REFERENCE));
    CHECK_OK(ctx, fx_stack_effective_params_json(s, idx, &eff1));
    CHECK(eff0 && eff1 && strcmp(eff0, eff1) != 0);
    fx_free(eff0);
    fx_free(eff1);
    CHECK_FAIL(ctx, fx_stack_effective_params_json(s, 9, &eff0), FX_ERR_INVALID_ARGUMENT, "out of range");
    fx_stack_free(s);
    fx_context_free(ctx);
}

/* An identity is skipped: the output is the input, bit for bit, and no buffer is taken
 * (the output shares the input's Combined). */
static void test_identity_skip(void)
{
    fx_context *ctx = NULL;
    CHECK_OK(ctx, fx_context_new(&ctx, 2));
    fx_frame *f = tu_pattern_frame(ctx, 31, 17, 3);
    static const char *const recipes[] = {
        "{\"effect\": \"gaussian_blur\", \"params\": {\"sigma\": 0}}",
        "{\"effect\": \"bloom\", \"params\": {\"intensity\": 0}}",
        "{\"effect\": \"posterize\", \"params\": {\"mix\": 0}}",
        "{\"effect\": \"edges\", \"params\": {\"opacity\": 0}}",
    };
    for (int i = 0; i < FX_COUNT_OF(recipes); i++) {
        char json[512];
        snprintf(json, sizeof json, "{\"version\": 1, \"effects\": [%s]}", recipes[i]);
        fx_stack *s = NULL;
        CHECK_OK(ctx, fx_stack_new(ctx, &s));
        CHECK_OK(ctx, fx_stack_load_json(s, json));
        fx_frame *out = NULL;
        CHECK_OK(ctx, fx_stack_run(s, f, &out));
        const float *a = NULL, *b = NULL;
        CHECK_OK(ctx, fx_frame_pass_read(f, "Combined", &a, NULL));
        CHECK_OK(ctx, fx_frame_pass_read(out, "Combined", &b, NULL));
        CHECK(a && b && a == b); /* shared, not copied */
        fx_frame_free(out);
        fx_stack_free(s);
    }
    fx_frame_free(f);
    fx_context_free(ctx);
}

/* ---- a test-only effect with a mask parameter: R = the mask's coverage ---- */

typedef struct sel_params {
    fx_mask_param sel;
} sel_params;

static const fx_param_def sel_table[] = {
    FX_P_MASK(sel_params, sel, "sel", "Pixels to mark"),
};

static fx_pass_set sel_passes(const void *params)
{
    const sel_params *p = params;
    return p->sel.spec ? fx_mask_spec_passes(p->sel.spec) : 0;
}

static fx_result sel_process(const fx_effect_run *run)
{
    const sel_params *p = run->params;
    fx_mask *m = NULL;
    if (p->sel.spec) {
        fx_result r = fx_mask_build(run->ctx, p->sel.spec, run->frame, run->where, &m);
        if (r)
            return r;
    }
    for (int y = run->roi.y0; y < run->roi.y1; y++)
        for (int x = run->roi.x0; x < run->roi.x1; x++) {
            size_t i = (size_t)y * run->width + x;
            run->dst[i * 4] = m ? m->coverage[i] : -1.0f;
            run->dst[i * 4 + 1] = run->dst[i * 4 + 2] = 0.0f;
            run->dst[i * 4 + 3] = 1.0f;
        }
    fx_mask_free(m);
    return FX_OK;
}

static const fx_effect_class sel_class = {
    .name = "test_mask_param",
    .doc = "test only",
    .params_size = sizeof(sel_params),
    .params = sel_table,
    .param_count = FX_COUNT_OF(sel_table),
    .passes = sel_passes,
    .process = sel_process,
};

/* Count of pixels whose R is 1, and their bounds. */
static int marked(const float *rgba, int w, int h, int box[4])
{
    int n = 0;
    box[0] = w, box[1] = h, box[2] = -1, box[3] = -1;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            if (rgba[((size_t)y * w + x) * 4] == 1.0f) {
                n++;
                box[0] = x < box[0] ? x : box[0];
                box[1] = y < box[1] ? y : box[1];
                box[2] = x > box[2] ? x : box[2];
                box[3] = y > box[3] ? y : box[3];
            }
    return n;
}

/* A mask parameter is parsed once per commit: a bad one is refused when set, naming the
 * parameter; its passes reach the stack's needs; its rectangle scales on a proxy as the
 * stack's own mask does. */
static void test_mask_param(void)
{
    fx_context *ctx = NULL;
    CHECK_OK(ctx, fx_context_new(&ctx, 2));
    fx_effect_register_test_class(&sel_class);
    fx_stack *s = NULL;
    CHECK_OK(ctx, fx_stack_new(ctx, &s));
    int idx = -1;
    CHECK_OK(ctx, fx_stack_append(s, "test_mask_param", &idx));
    CHECK_FAIL(ctx, fx_stack_set_string(s, idx, "sel", "{\"colour\": 1}"), FX_ERR_BAD_PARAM,
               "parameter 'sel': unknown mask key \"colour\"");
    CHECK_FAIL(ctx, fx_stack_set_string(s, idx, "sel", "[1, 2"), FX_ERR_BAD_PARAM, "parameter 'sel'");
    CHECK_FAIL(ctx, fx_stack_load_json(s, "{\"version\": 1, \"effects\": [{\"effect\": \"test_mask_param\", "
                                          "\"params\": {\"sel\": \"{\\\"rect\\\": [1, 2]}\"}}]}"),
               FX_ERR_BAD_PARAM, "rect");
    CHECK(fx_stack_count(s) == 1);
    char *eff = NULL;
    CHECK_OK(ctx, fx_stack_effective_params_json(s, idx, &eff));
    CHECK(eff && tu_contains(eff, "\"sel\":\"\""));
    fx_free(eff);

    /* passes: a material selection needs the material Cryptomatte */
    char *passes = NULL;
    CHECK_OK(ctx, fx_stack_set_string(s, idx, "sel", "{\"material\": \"Mirror\"}"));
    CHECK_OK(ctx, fx_stack_required_passes(s, &passes));
    CHECK(passes && tu_contains(passes, "CryptoMaterial"));
    fx_free(passes);

    /* a rectangle: exact on the frame, the proxy pixels it touches on a 1/2 proxy */
    enum { W = 24, H = 16 };
    fx_frame *f = tu_pattern_frame(ctx, W, H, 5);
    CHECK_OK(ctx, fx_stack_set_string(s, idx, "sel", "{\"rect\": [5, 3, 6, 5]}"));
    fx_frame *o = NULL;
    const float *rgba = NULL;
    int ch = 0, box[4];
    CHECK_OK(ctx, fx_stack_run(s, f, &o));
    CHECK_OK(ctx, fx_frame_pass_read(o, "Combined", &rgba, &ch));
    CHECK(rgba && marked(rgba, W, H, box) == 30 && box[0] == 5 && box[1] == 3 && box[2] == 10 && box[3] == 7);
    fx_frame_free(o);
    fx_frame *proxy = NULL;
    CHECK_OK(ctx, fx_frame_reduce(f, 2, &proxy));
    CHECK_OK(ctx, fx_stack_run(s, proxy, &o));
    CHECK_OK(ctx, fx_frame_pass_read(o, "Combined", &rgba, &ch));
    /* full pixels 5..10 x 3..7 touch proxy pixels 2..5 x 1..3 */
    CHECK(rgba && marked(rgba, W / 2, H / 2, box) == 12 && box[0] == 2 && box[1] == 1 && box[2] == 5 &&
          box[3] == 3);
    fx_frame_free(o);
    /* "{}" selects nothing given: the effect sees no spec */
    CHECK_OK(ctx, fx_stack_set_string(s, idx, "sel", "{}"));
    CHECK_OK(ctx, fx_stack_run(s, f, &o));
    CHECK_OK(ctx, fx_frame_pass_read(o, "Combined", &rgba, &ch));
    CHECK(rgba && rgba[0] == -1.0f);
    fx_frame_free(o);
    fx_frame_free(proxy);
    fx_frame_free(f);
    fx_stack_free(s);
    fx_effect_register_test_class(NULL);
    fx_context_free(ctx);
}

int main(void)
{
    test_migration();
    test_setters_commit();
    test_identity_skip();
    test_mask_param();
    return tu_finish("test_contract");
}
