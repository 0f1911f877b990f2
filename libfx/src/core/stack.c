/* Stacks: ordered effects with their parameters, masks and quality; recipe JSON in
 * and out; and the run loop that chains effects over a frame's Combined pass. */
#include "core/effect.h"
#include "core/mask.h"
#include "core/json_keys.h"
#include "core/mem_failures.h"
#include "core/parallel.h"
#include "core/params.h"
#include "core/platform.h"

#include <cjson/cJSON.h>
#include <errno.h>
#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#define RECIPE_VERSION 1
#define LABEL_MAX 128

typedef struct fx_entry {
    const fx_effect_class *cls;
    void *user_params;           /* values set explicitly (valid where explicit_set[i]) */
    unsigned char *explicit_set; /* one flag per parameter of the class */
    void *effective;             /* defaults, then the preset, then the explicit values: made
                                    and validated by entry_commit whenever one of them changes;
                                    its mask parameters' specs follow it (effective_alloc) */
    int enabled;
    int quality;                 /* -1: the stack's */
    char label[LABEL_MAX];
    fx_mask_spec mask;
    double last_ms;
} fx_entry;

struct fx_stack {
    fx_context *ctx;
    fx_entry *entries;
    int count, cap;
    int quality;
    int debug;
};

/* ---- effective parameters and their parsed mask parameters ----
 * One block: the params struct, then one fx_mask_spec per mask parameter of the class,
 * which the struct's fx_mask_param.spec fields point into. */

static size_t specs_offset(const fx_effect_class *c)
{
    const size_t a = _Alignof(fx_mask_spec);
    return (c->params_size + a - 1) / a * a;
}

static int mask_param_count(const fx_effect_class *c)
{
    int n = 0;
    for (int i = 0; i < c->param_count; i++)
        n += fx_param_is_mask(&c->params[i]);
    return n;
}

static void *effective_alloc(const fx_effect_class *c)
{
    return fx_mem_calloc(1, specs_offset(c) + (size_t)mask_param_count(c) * sizeof(fx_mask_spec));
}

static fx_mask_spec *effective_specs(const fx_effect_class *c, void *p)
{
    return (fx_mask_spec *)((char *)p + specs_offset(c));
}

static void effective_free(const fx_effect_class *c, void *p)
{
    if (!p)
        return;
    fx_mask_spec *specs = effective_specs(c, p);
    for (int k = 0, n = mask_param_count(c); k < n; k++)
        fx_mask_spec_clear(&specs[k]);
    fx_mem_free(p);
}

/* Parses each mask parameter's text into the block's specs and points the field at it. */
static fx_result parse_mask_params(fx_context *ctx, const fx_effect_class *c, void *p, const char *where)
{
    fx_mask_spec *specs = effective_specs(c, p);
    for (int i = 0, k = 0; i < c->param_count; i++) {
        const fx_param_def *d = &c->params[i];
        if (!fx_param_is_mask(d))
            continue;
        fx_mask_param *mp = (fx_mask_param *)((char *)p + d->offset);
        mp->spec = NULL;
        if (!mp->json[0]) {
            k++;
            continue;
        }
        char what[96];
        snprintf(what, sizeof what, "parameter '%s'", d->info.name);
        char at[256];
        snprintf(at, sizeof at, "%s: %s", where, what);
        fx_result r = fx_mask_spec_parse_text(ctx, mp->json, at, "its text", &specs[k]);
        if (r)
            return r == FX_ERR_BAD_RECIPE ? FX_ERR_BAD_PARAM : r;
        mp->spec = fx_mask_spec_is_empty(&specs[k]) ? NULL : &specs[k];
        k++;
    }
    return FX_OK;
}

static void entry_clear(fx_entry *e)
{
    fx_mem_free(e->user_params);
    effective_free(e->cls, e->effective);
    fx_mem_free(e->explicit_set);
    fx_mask_spec_clear(&e->mask);
    memset(e, 0, sizeof *e);
}

static fx_result entry_init(fx_context *ctx, fx_entry *e, const fx_effect_class *cls)
{
    memset(e, 0, sizeof *e);
    e->cls = cls;
    e->enabled = 1;
    e->quality = -1;
    e->user_params = fx_mem_calloc(1, cls->params_size);
    e->explicit_set = fx_mem_calloc((size_t)(cls->param_count ? cls->param_count : 1), 1);
    if (!e->user_params || !e->explicit_set) {
        entry_clear(e);
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "out of memory adding effect '%s'", cls->name);
    }
    fx_params_set_defaults(cls, e->user_params);
    return FX_OK;
}

static void where_of(char *buf, size_t n, int index, const fx_effect_class *cls)
{
    snprintf(buf, n, "effect %d (%s)", index, cls ? cls->name : "?");
}

fx_result fx_stack_new(fx_context *ctx, fx_stack **out)
{
    if (!out)
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "fx_stack_new: out is NULL");
    fx_stack *s = fx_mem_calloc(1, sizeof *s);
    if (!s)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "out of memory for a stack");
    s->ctx = ctx;
    s->quality = FX_QUALITY_FINAL;
    *out = s;
    return FX_OK;
}

static void stack_clear(fx_stack *s)
{
    for (int i = 0; i < s->count; i++)
        entry_clear(&s->entries[i]);
    fx_mem_free(s->entries);
    s->entries = NULL;
    s->count = s->cap = 0;
}

void fx_stack_free(fx_stack *s)
{
    if (!s)
        return;
    stack_clear(s);
    fx_mem_free(s);
}

static fx_result stack_grow(fx_stack *s)
{
    if (s->count < s->cap)
        return FX_OK;
    int cap = s->cap ? s->cap * 2 : 4;
    fx_entry *e = fx_mem_realloc(s->entries, (size_t)cap * sizeof *e);
    if (!e)
        return fx_fail(s->ctx, FX_ERR_OUT_OF_MEMORY, "out of memory growing a stack");
    s->entries = e;
    s->cap = cap;
    return FX_OK;
}

static fx_entry *entry_at(const fx_stack *s, int index, const char *fn)
{
    if (!s)
        return NULL;
    if (index < 0 || index >= s->count) {
        fx_fail(s->ctx, FX_ERR_INVALID_ARGUMENT, "%s: effect index %d is out of range (stack has %d)",
                fn, index, s->count);
        return NULL;
    }
    return &s->entries[index];
}

/* Effective parameters: defaults, then the quality preset, then explicit values. */
static fx_result effective_params(fx_context *ctx, const fx_entry *e, int index, int quality, void *out)
{
    const fx_effect_class *c = e->cls;
    char where[128];
    where_of(where, sizeof where, index, c);
    fx_params_set_defaults(c, out);
    const char *preset = c->presets[quality];
    if (preset) {
        unsigned long failures = fx_mem_failure_count();
        cJSON *p = cJSON_Parse(preset);
        if (!p && fx_mem_failure_count() != failures)
            return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory reading the '%s' preset", where,
                           fx_quality_name(quality));
        if (!p)
            return fx_fail(ctx, FX_ERR_INTERNAL, "%s: preset '%s' is not valid JSON", where,
                           fx_quality_name(quality));
        fx_result r = fx_params_set_object(ctx, c, out, p, NULL, where);
        cJSON_Delete(p);
        if (r)
            return r;
    }
    for (int i = 0; i < c->param_count; i++)
        if (e->explicit_set[i])
            fx_param_copy(&c->params[i], out, e->user_params);
    if (c->validate) {
        char err[512] = "";
        fx_result r = c->validate(out, err, sizeof err);
        if (r)
            return fx_fail(ctx, r, "%s: %s", where, err[0] ? err : "invalid parameters");
    }
    return FX_OK;
}

static int entry_quality(const fx_stack *s, const fx_entry *e)
{
    return e->quality >= 0 ? e->quality : s->quality;
}

/* The commit step (as Open Image Denoise commits a filter before it runs): the entry's
 * effective parameters at `quality`, validated as a whole. On failure the entry keeps
 * its previous ones and the message names the effect and the parameter. */
static fx_result entry_commit(fx_context *ctx, fx_entry *e, int index, int quality)
{
    void *p = effective_alloc(e->cls);
    if (!p)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "out of memory checking effect %d (%s)", index, e->cls->name);
    fx_result r = effective_params(ctx, e, index, quality, p);
    if (!r) {
        char where[128];
        where_of(where, sizeof where, index, e->cls);
        r = parse_mask_params(ctx, e->cls, p, where);
    }
    if (r) {
        effective_free(e->cls, p);
        return r;
    }
    effective_free(e->cls, e->effective);
    e->effective = p;
    return FX_OK;
}

/* ---- recipes ---- */

static fx_result parse_quality(fx_context *ctx, const cJSON *v, const char *where, int *out)
{
    int q = cJSON_IsString(v) ? fx_quality_from_name(v->valuestring) : -1;
    if (q < 0)
        return fx_fail(ctx, FX_ERR_BAD_RECIPE,
                       "%s: \"quality\" must be one of draft, preview, final, reference", where);
    *out = q;
    return FX_OK;
}

/* An entry's "params", migrated first when they were written at an older version. */
static fx_result parse_params(fx_context *ctx, const fx_effect_class *cls, int version, const cJSON *params,
                              fx_entry *e, const char *where)
{
    if (version == fx_effect_version(cls) || !cJSON_IsObject(params))
        return fx_params_set_object(ctx, cls, e->user_params, params, e->explicit_set, where);
    cJSON *copy = cJSON_Duplicate(params, 1);
    if (!copy)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory migrating the parameters", where);
    fx_result r = fx_params_migrate(ctx, cls, version, copy, where);
    if (!r)
        r = fx_params_set_object(ctx, cls, e->user_params, copy, e->explicit_set, where);
    cJSON_Delete(copy);
    return r;
}

static fx_result parse_entry(fx_stack *s, const cJSON *j, int index, fx_entry *e)
{
    char where[128];
    snprintf(where, sizeof where, "effect %d", index);
    if (!cJSON_IsObject(j))
        return fx_fail(s->ctx, FX_ERR_BAD_RECIPE, "recipe: %s must be an object", where);
    const cJSON *name = cJSON_GetObjectItemCaseSensitive(j, "effect");
    if (!cJSON_IsString(name))
        return fx_fail(s->ctx, FX_ERR_BAD_RECIPE, "recipe: %s has no \"effect\" name", where);
    const fx_effect_class *cls = fx_effect_find(name->valuestring);
    if (!cls)
        return fx_fail(s->ctx, FX_ERR_UNKNOWN_EFFECT, "recipe: %s: unknown effect '%s' (see `libfx list`)",
                       where, name->valuestring);
    fx_result r = entry_init(s->ctx, e, cls);
    if (r)
        return r;
    where_of(where, sizeof where, index, cls);
    int version = 1; /* recipes from before parameter versions are version 1 */
    const cJSON *pv = cJSON_GetObjectItemCaseSensitive(j, "params_version");
    if (pv && (!cJSON_IsNumber(pv) || pv->valuedouble != floor(pv->valuedouble) || pv->valuedouble < 1 ||
               pv->valuedouble > INT_MAX))
        r = fx_fail(s->ctx, FX_ERR_BAD_RECIPE, "%s: \"params_version\" must be a whole number from 1", where);
    else if (pv)
        version = (int)pv->valuedouble;
    if (!r && version > fx_effect_version(cls))
        r = fx_params_migrate(s->ctx, cls, version, NULL, where); /* the "newer than known" error */
    const cJSON *item;
    cJSON_ArrayForEach(item, j) {
        if (r)
            break;
        const char *k = item->string;
        if (strcmp(k, "effect") == 0 || strcmp(k, "params_version") == 0)
            continue;
        if (strcmp(k, "enabled") == 0) {
            if (!cJSON_IsBool(item))
                r = fx_fail(s->ctx, FX_ERR_BAD_RECIPE, "%s: \"enabled\" must be true or false", where);
            else
                e->enabled = cJSON_IsTrue(item);
        } else if (strcmp(k, "quality") == 0) {
            r = parse_quality(s->ctx, item, where, &e->quality);
        } else if (strcmp(k, "label") == 0) {
            if (!cJSON_IsString(item) || strlen(item->valuestring) >= LABEL_MAX)
                r = fx_fail(s->ctx, FX_ERR_BAD_RECIPE, "%s: \"label\" must be a string under %d bytes",
                            where, LABEL_MAX);
            else
                snprintf(e->label, LABEL_MAX, "%s", item->valuestring);
        } else if (strcmp(k, "params") == 0) {
            r = parse_params(s->ctx, cls, version, item, e, where);
        } else if (strcmp(k, "mask") == 0) {
            r = fx_mask_spec_parse(s->ctx, item, where, &e->mask);
        } else {
            r = fx_fail(s->ctx, FX_ERR_BAD_RECIPE,
                        "%s: unknown key \"%s\" (known: effect, params_version, enabled, quality, label, "
                        "params, mask)",
                        where, k);
        }
        if (r)
            break;
    }
    if (r)
        entry_clear(e);
    return r;
}

fx_result fx_stack_load_json(fx_stack *s, const char *json)
{
    if (!s || !json)
        return fx_fail(s ? s->ctx : NULL, FX_ERR_INVALID_ARGUMENT, "fx_stack_load_json: NULL argument");
    unsigned long failures = fx_mem_failure_count();
    cJSON *root = cJSON_Parse(json);
    if (!root && fx_mem_failure_count() != failures)
        return fx_fail(s->ctx, FX_ERR_OUT_OF_MEMORY, "recipe: out of memory parsing the JSON");
    if (!root) {
        const char *at = cJSON_GetErrorPtr();
        int line = 1;
        for (const char *p = json; at && p < at && *p; p++)
            line += *p == '\n';
        return fx_fail(s->ctx, FX_ERR_BAD_RECIPE, "recipe: invalid JSON near line %d: \"%.30s\"", line,
                       at ? at : "");
    }
    fx_stack tmp = {s->ctx, NULL, 0, 0, FX_QUALITY_FINAL, s->debug};
    fx_result r = fx_json_check_unique_keys(s->ctx, root, "recipe");
    if (!r && !cJSON_IsObject(root))
        r = fx_fail(s->ctx, FX_ERR_BAD_RECIPE, "recipe: the top level must be an object");
    const cJSON *effects = NULL;
    if (!r) {
        const cJSON *item;
        cJSON_ArrayForEach(item, root) {
            const char *k = item->string;
            if (strcmp(k, "version") == 0) {
                if (!cJSON_IsNumber(item) || item->valuedouble != floor(item->valuedouble) ||
                    item->valuedouble < 1)
                    r = fx_fail(s->ctx, FX_ERR_BAD_RECIPE, "recipe: \"version\" must be a whole number");
                else if (item->valuedouble > RECIPE_VERSION)
                    r = fx_fail(s->ctx, FX_ERR_BAD_RECIPE,
                                "recipe: version %g is newer than this libfx reads (%d): update libfx",
                                item->valuedouble, RECIPE_VERSION);
            } else if (strcmp(k, "quality") == 0) {
                r = parse_quality(s->ctx, item, "recipe", &tmp.quality);
            } else if (strcmp(k, "effects") == 0) {
                if (!cJSON_IsArray(item))
                    r = fx_fail(s->ctx, FX_ERR_BAD_RECIPE, "recipe: \"effects\" must be a list");
                effects = item;
            } else if (strcmp(k, "name") != 0 && strcmp(k, "description") != 0) {
                r = fx_fail(s->ctx, FX_ERR_BAD_RECIPE,
                            "recipe: unknown key \"%s\" (known: version, quality, effects, name, description)", k);
            }
            if (r)
                break;
        }
        if (!r && !cJSON_GetObjectItemCaseSensitive(root, "version"))
            r = fx_fail(s->ctx, FX_ERR_BAD_RECIPE, "recipe: \"version\" is missing (use 1)");
    }
    if (!r && effects) {
        int i = 0;
        const cJSON *item;
        cJSON_ArrayForEach(item, effects) {
            if ((r = stack_grow(&tmp)))
                break;
            if ((r = parse_entry(&tmp, item, i, &tmp.entries[tmp.count])))
                break;
            tmp.count++;
            i++;
        }
    }
    /* Cross-parameter checks at load, so a bad recipe fails before any render. */
    for (int i = 0; !r && i < tmp.count; i++)
        r = entry_commit(s->ctx, &tmp.entries[i], i, entry_quality(&tmp, &tmp.entries[i]));
    cJSON_Delete(root);
    if (r) {
        stack_clear(&tmp);
        return r;
    }
    stack_clear(s);
    s->entries = tmp.entries;
    s->count = tmp.count;
    s->cap = tmp.cap;
    s->quality = tmp.quality;
    return FX_OK;
}

fx_result fx_stack_load_file(fx_stack *s, const char *path)
{
    if (!s || !path)
        return fx_fail(s ? s->ctx : NULL, FX_ERR_INVALID_ARGUMENT, "fx_stack_load_file: NULL argument");
    char *text = NULL;
    fx_result r = fx_read_text_file(s->ctx, path, (size_t)64 << 20, "recipe", &text);
    if (r)
        return r;
    r = fx_stack_load_json(s, text);
    if (r)
        fx_fail_prefix(s->ctx, r, path);
    fx_mem_free(text);
    return r;
}

fx_result fx_stack_to_json(const fx_stack *s, char **out_json)
{
    if (!s || !out_json)
        return fx_fail(s ? s->ctx : NULL, FX_ERR_INVALID_ARGUMENT, "fx_stack_to_json: NULL argument");
    *out_json = NULL;
    cJSON *root = cJSON_CreateObject();
    cJSON_AddNumberToObject(root, "version", RECIPE_VERSION);
    cJSON_AddStringToObject(root, "quality", fx_quality_name(s->quality));
    cJSON *effects = cJSON_AddArrayToObject(root, "effects");
    for (int i = 0; i < s->count; i++) {
        const fx_entry *e = &s->entries[i];
        cJSON *o = cJSON_CreateObject();
        cJSON_AddStringToObject(o, "effect", e->cls->name);
        cJSON_AddNumberToObject(o, "params_version", fx_effect_version(e->cls));
        cJSON_AddBoolToObject(o, "enabled", e->enabled);
        if (e->quality >= 0)
            cJSON_AddStringToObject(o, "quality", fx_quality_name(e->quality));
        if (e->label[0])
            cJSON_AddStringToObject(o, "label", e->label);
        cJSON *params = cJSON_AddObjectToObject(o, "params");
        for (int k = 0; k < e->cls->param_count; k++)
            if (e->explicit_set[k])
                cJSON_AddItemToObject(params, e->cls->params[k].info.name,
                                      fx_param_to_json(&e->cls->params[k], e->user_params));
        cJSON *mask = fx_mask_spec_to_json(&e->mask);
        if (mask)
            cJSON_AddItemToObject(o, "mask", mask);
        cJSON_AddItemToArray(effects, o);
    }
    char *str = cJSON_Print(root);
    cJSON_Delete(root);
    if (str)
        *out_json = fx_json_strdup(str);
    cJSON_free(str);
    return *out_json ? FX_OK : fx_fail(s->ctx, FX_ERR_OUT_OF_MEMORY, "out of memory writing a recipe");
}

fx_result fx_stack_effective_params_json(const fx_stack *s, int index, char **out_json)
{
    if (!out_json)
        return fx_fail(s ? s->ctx : NULL, FX_ERR_INVALID_ARGUMENT, "fx_stack_effective_params_json: NULL argument");
    *out_json = NULL;
    fx_entry *e = entry_at(s, index, "fx_stack_effective_params_json");
    if (!e)
        return FX_ERR_INVALID_ARGUMENT;
    cJSON *o = cJSON_CreateObject();
    for (int k = 0; o && k < e->cls->param_count; k++) {
        cJSON *v = fx_param_to_json(&e->cls->params[k], e->effective);
        if (!v || !cJSON_AddItemToObject(o, e->cls->params[k].info.name, v)) {
            cJSON_Delete(v);
            cJSON_Delete(o);
            o = NULL;
        }
    }
    char *str = o ? cJSON_PrintUnformatted(o) : NULL;
    cJSON_Delete(o);
    *out_json = str ? fx_json_strdup(str) : NULL;
    cJSON_free(str);
    return *out_json ? FX_OK : fx_fail(s->ctx, FX_ERR_OUT_OF_MEMORY, "out of memory");
}

/* ---- editing ---- */

int fx_stack_count(const fx_stack *s)
{
    return s ? s->count : 0;
}

const char *fx_stack_effect(const fx_stack *s, int index)
{
    if (!s || index < 0 || index >= s->count)
        return NULL;
    return s->entries[index].cls->name;
}

fx_result fx_stack_append(fx_stack *s, const char *effect, int *out_index)
{
    if (!s)
        return FX_ERR_INVALID_ARGUMENT;
    const fx_effect_class *cls = fx_effect_find(effect);
    if (!cls)
        return fx_fail(s->ctx, FX_ERR_UNKNOWN_EFFECT, "unknown effect '%s' (see `libfx list`)",
                       effect ? effect : "(null)");
    fx_result r = stack_grow(s);
    if (r)
        return r;
    r = entry_init(s->ctx, &s->entries[s->count], cls);
    if (r)
        return r;
    if ((r = entry_commit(s->ctx, &s->entries[s->count], s->count, s->quality))) {
        entry_clear(&s->entries[s->count]);
        return r;
    }
    if (out_index)
        *out_index = s->count;
    s->count++;
    return FX_OK;
}

fx_result fx_stack_remove(fx_stack *s, int index)
{
    fx_entry *e = entry_at(s, index, "fx_stack_remove");
    if (!e)
        return FX_ERR_INVALID_ARGUMENT;
    entry_clear(e);
    memmove(e, e + 1, (size_t)(s->count - index - 1) * sizeof *e);
    s->count--;
    return FX_OK;
}

fx_result fx_stack_set_enabled(fx_stack *s, int index, int enabled)
{
    fx_entry *e = entry_at(s, index, "fx_stack_set_enabled");
    if (!e)
        return FX_ERR_INVALID_ARGUMENT;
    e->enabled = enabled != 0;
    return FX_OK;
}

/* All typed setters funnel through the JSON setter: one place checks types and ranges. */
static fx_result set_param(fx_stack *s, int index, const char *param, cJSON *value, const char *fn)
{
    fx_entry *e = entry_at(s, index, fn);
    if (!e) {
        cJSON_Delete(value);
        return FX_ERR_INVALID_ARGUMENT;
    }
    char where[128];
    where_of(where, sizeof where, index, e->cls);
    if (!value)
        return fx_fail(s->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where);
    cJSON *obj = cJSON_CreateObject();
    if (!obj) {
        cJSON_Delete(value);
        return fx_fail(s->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where);
    }
    cJSON_AddItemToObject(obj, param ? param : "", value);
    /* Set on copies and commit the whole effect: a value that passes its own range but
     * not the effect's cross-parameter checks is refused now, and the stack is unchanged. */
    const size_t flags = (size_t)(e->cls->param_count ? e->cls->param_count : 1);
    void *user = fx_mem_alloc(e->cls->params_size);
    unsigned char *set = fx_mem_alloc(flags);
    fx_result r = user && set ? FX_OK : fx_fail(s->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where);
    if (!r) {
        memcpy(user, e->user_params, e->cls->params_size);
        memcpy(set, e->explicit_set, flags);
        r = fx_params_set_object(s->ctx, e->cls, e->user_params, obj, e->explicit_set, where);
        if (!r)
            r = entry_commit(s->ctx, e, index, entry_quality(s, e));
        if (r) {
            memcpy(e->user_params, user, e->cls->params_size);
            memcpy(e->explicit_set, set, flags);
        }
    }
    fx_mem_free(user);
    fx_mem_free(set);
    cJSON_Delete(obj);
    return r;
}

fx_result fx_stack_set_float(fx_stack *s, int index, const char *param, double value)
{
    return set_param(s, index, param, cJSON_CreateNumber(value), "fx_stack_set_float");
}

fx_result fx_stack_set_int(fx_stack *s, int index, const char *param, int value)
{
    fx_entry *e = s && index >= 0 && index < s->count ? &s->entries[index] : NULL;
    const fx_param_def *d = e ? fx_effect_find_param(e->cls, param) : NULL;
    cJSON *v = d && d->info.type == FX_PARAM_BOOL ? cJSON_CreateBool(value) : cJSON_CreateNumber(value);
    return set_param(s, index, param, v, "fx_stack_set_int");
}

fx_result fx_stack_set_enum(fx_stack *s, int index, const char *param, const char *item)
{
    return set_param(s, index, param, cJSON_CreateString(item ? item : ""), "fx_stack_set_enum");
}

fx_result fx_stack_set_floats(fx_stack *s, int index, const char *param, const float *values, int count)
{
    if (!values || count < 0)
        return fx_fail(s ? s->ctx : NULL, FX_ERR_INVALID_ARGUMENT, "fx_stack_set_floats: no values");
    return set_param(s, index, param, cJSON_CreateFloatArray(values, count), "fx_stack_set_floats");
}

fx_result fx_stack_set_string(fx_stack *s, int index, const char *param, const char *value)
{
    return set_param(s, index, param, cJSON_CreateString(value ? value : ""), "fx_stack_set_string");
}

fx_result fx_stack_set_mask_json(fx_stack *s, int index, const char *mask_json)
{
    fx_entry *e = entry_at(s, index, "fx_stack_set_mask_json");
    if (!e)
        return FX_ERR_INVALID_ARGUMENT;
    char where[128];
    where_of(where, sizeof where, index, e->cls);
    fx_mask_spec spec;
    memset(&spec, 0, sizeof spec);
    if (mask_json && mask_json[0]) {
        fx_result r = fx_mask_spec_parse_text(s->ctx, mask_json, where, "the mask", &spec);
        if (r)
            return r;
    }
    fx_mask_spec_clear(&e->mask);
    e->mask = spec;
    return FX_OK;
}

fx_result fx_stack_set_quality(fx_stack *s, int quality)
{
    if (!s)
        return FX_ERR_INVALID_ARGUMENT;
    if (quality < 0 || quality > FX_QUALITY_REFERENCE)
        return fx_fail(s->ctx, FX_ERR_BAD_PARAM, "quality %d is not 0..3 (draft..reference)", quality);
    /* every entry that follows the stack's quality commits its new preset; on a failure
     * (a preset that clashes with an explicit value) the stack keeps the old quality */
    void **fresh = fx_mem_calloc((size_t)(s->count ? s->count : 1), sizeof *fresh);
    if (!fresh)
        return fx_fail(s->ctx, FX_ERR_OUT_OF_MEMORY, "out of memory changing the quality");
    fx_result r = FX_OK;
    for (int i = 0; i < s->count && !r; i++) {
        fx_entry *e = &s->entries[i];
        if (e->quality >= 0)
            continue;
        void *old = e->effective;
        e->effective = NULL;
        r = entry_commit(s->ctx, e, i, quality);
        fresh[i] = e->effective;
        e->effective = old;
    }
    for (int i = 0; i < s->count; i++) {
        if (!fresh[i])
            continue;
        if (r) {
            effective_free(s->entries[i].cls, fresh[i]);
        } else {
            effective_free(s->entries[i].cls, s->entries[i].effective);
            s->entries[i].effective = fresh[i];
        }
    }
    fx_mem_free(fresh);
    if (!r)
        s->quality = quality;
    return r;
}

void fx_stack_set_debug_outputs(fx_stack *s, int enabled)
{
    if (s)
        s->debug = enabled != 0;
}

/* ---- what a stack needs ---- */

static fx_pass_set entry_passes(const fx_entry *e, int *needs_camera)
{
    fx_pass_set set = fx_mask_spec_passes(&e->mask);
    if (e->cls->passes)
        set |= e->cls->passes(e->effective);
    if (needs_camera && fx_effect_needs_camera(e->cls, e->effective))
        *needs_camera = 1;
    return set;
}

fx_pass_set fx_stack_pass_set(const fx_stack *s)
{
    fx_pass_set set = FX_PASS_BIT(FX_PASS_COMBINED);
    for (int i = 0; s && i < s->count; i++)
        if (s->entries[i].enabled)
            set |= entry_passes(&s->entries[i], NULL);
    return set;
}

fx_result fx_stack_required_passes(const fx_stack *s, char **out_json)
{
    if (!s || !out_json)
        return fx_fail(s ? s->ctx : NULL, FX_ERR_INVALID_ARGUMENT, "fx_stack_required_passes: NULL argument");
    *out_json = NULL;
    int camera = 0;
    fx_pass_set set = FX_PASS_BIT(FX_PASS_COMBINED);
    for (int i = 0; i < s->count; i++)
        if (s->entries[i].enabled)
            set |= entry_passes(&s->entries[i], &camera);
    cJSON *o = cJSON_CreateObject();
    cJSON *passes = cJSON_AddArrayToObject(o, "passes");
    cJSON *settings = cJSON_AddArrayToObject(o, "blender_settings");
    for (int i = 0; i < FX_PASS_COUNT; i++) {
        if (!(set & FX_PASS_BIT(i)))
            continue;
        const fx_pass_desc *d = fx_pass_describe((fx_pass_id)i);
        cJSON_AddItemToArray(passes, cJSON_CreateString(d->name));
        if (d->blender_setting[0])
            cJSON_AddItemToArray(settings, cJSON_CreateString(d->blender_setting));
    }
    cJSON_AddBoolToObject(o, "camera", camera);
    char *str = cJSON_PrintUnformatted(o);
    cJSON_Delete(o);
    if (str)
        *out_json = fx_json_strdup(str);
    cJSON_free(str);
    return *out_json ? FX_OK : fx_fail(s->ctx, FX_ERR_OUT_OF_MEMORY, "out of memory");
}

/* The entry's mask key (fx_effect_run.mask_key): 12 hex digits of the 64-bit FNV-1a hash
 * of its canonical mask JSON ("{}" without a mask). Stable across runs and machines, so
 * the add-on's view names and the run's match. */
static int mask_key(const fx_entry *e, char out[16])
{
    out[0] = '\0';
    cJSON *m = fx_mask_spec_to_json(&e->mask);
    if (!m && !fx_mask_spec_is_empty(&e->mask))
        return 0; /* out of memory: no key rather than the key of another mask */
    char *text = m ? cJSON_PrintUnformatted(m) : NULL;
    cJSON_Delete(m);
    if (m && !text)
        return 0;
    const char *t = text ? text : "{}";
    uint64_t h = 1469598103934665603ull;
    for (const unsigned char *c = (const unsigned char *)t; *c; c++)
        h = (h ^ *c) * 1099511628211ull;
    cJSON_free(text);
    snprintf(out, 16, "%012llx", (unsigned long long)(h & 0xffffffffffffull));
    return 1;
}

/* The aux views the enabled effects read, from their effective parameters (so a preset
 * or default counts as much as an explicit value); each view once. */
fx_result fx_stack_required_aux_views(const fx_stack *s, char **out_json)
{
    if (!s || !out_json)
        return fx_fail(s ? s->ctx : NULL, FX_ERR_INVALID_ARGUMENT, "fx_stack_required_aux_views: NULL argument");
    *out_json = NULL;
    cJSON *o = cJSON_CreateObject();
    cJSON *views = o ? cJSON_AddArrayToObject(o, "aux_views") : NULL;
    fx_result r = views ? FX_OK : fx_fail(s->ctx, FX_ERR_OUT_OF_MEMORY, "out of memory listing aux views");
    for (int i = 0; !r && i < s->count; i++) {
        const fx_entry *e = &s->entries[i];
        if (!e->enabled || !e->cls->aux_views)
            continue;
        fx_aux_need need[4];
        memset(need, 0, sizeof need);
        int n = e->cls->aux_views(e->effective, need, 4);
        for (int k = 0; k < n && !r; k++) {
            cJSON *mask = NULL;
            if (need[k].per_mask) {
                char key[16];
                if (!mask_key(e, key)) {
                    r = fx_fail(s->ctx, FX_ERR_OUT_OF_MEMORY, "out of memory listing aux views");
                    break;
                }
                size_t len = strlen(need[k].name);
                snprintf(need[k].name + len, sizeof need[k].name - len, "%s", key);
                mask = fx_mask_spec_to_json(&e->mask);
                if (!mask)
                    mask = cJSON_CreateObject();
                if (!mask) {
                    r = fx_fail(s->ctx, FX_ERR_OUT_OF_MEMORY, "out of memory listing aux views");
                    break;
                }
            }
            int seen = 0;
            const cJSON *v;
            cJSON_ArrayForEach(v, views) {
                const cJSON *name = cJSON_GetObjectItemCaseSensitive(v, "name");
                seen |= cJSON_IsString(name) && strcmp(name->valuestring, need[k].name) == 0;
            }
            if (seen) {
                cJSON_Delete(mask);
                continue;
            }
            cJSON *item = cJSON_CreateObject();
            if (!item || !cJSON_AddStringToObject(item, "name", need[k].name) ||
                !cJSON_AddStringToObject(item, "kind", need[k].kind) ||
                (strcmp(need[k].kind, "light") == 0 && !cJSON_AddStringToObject(item, "light", need[k].light)) ||
                (need[k].samples_scale > 0.0f &&
                 !cJSON_AddNumberToObject(item, "samples_scale", need[k].samples_scale)) ||
                (mask && !cJSON_AddItemToObject(item, "mask", mask))) {
                if (mask && (!item || cJSON_GetObjectItemCaseSensitive(item, "mask") != mask))
                    cJSON_Delete(mask);
                cJSON_Delete(item);
                r = fx_fail(s->ctx, FX_ERR_OUT_OF_MEMORY, "out of memory listing aux views");
            } else {
                cJSON_AddItemToArray(views, item);
            }
        }
    }
    char *str = r ? NULL : cJSON_PrintUnformatted(o);
    cJSON_Delete(o);
    if (!r && !str)
        r = fx_fail(s->ctx, FX_ERR_OUT_OF_MEMORY, "out of memory listing aux views");
    if (str) {
        *out_json = fx_json_strdup(str);
        cJSON_free(str);
        if (!*out_json)
            r = fx_fail(s->ctx, FX_ERR_OUT_OF_MEMORY, "out of memory listing aux views");
    }
    return r;
}

/* ---- running ---- */

typedef struct composite_job {
    const float *src;
    float *dst;
    const fx_mask *mask;
    fx_rect roi;
    fx_rect stale; /* where dst may differ from src before this effect (outside the ROI) */
    int width;
    int own_finite; /* the effect made dst finite already (FX_EFFECT_OWN_FINITE) */
    size_t *bad;    /* per row: non-finite values replaced */
} composite_job;

static void copy_span(const float *s, float *d, int x0, int x1)
{
    if (x1 > x0 && s != d)
        memcpy(d + (size_t)x0 * 4, s + (size_t)x0 * 4, (size_t)(x1 - x0) * 4 * sizeof(float));
}

/* Outside the ROI and where coverage is 0, output is src bit for bit: only the stale
 * part of dst needs copying (it already equals src elsewhere). Inside the ROI, dst is
 * blended by coverage. Any non-finite value an effect produced is replaced and counted. */
static void composite_rows(void *user, int y0, int y1)
{
    composite_job *j = user;
    const size_t w4 = (size_t)j->width * 4;
    const fx_rect *st = &j->stale, *roi = &j->roi;
    for (int y = y0; y < y1; y++) {
        const float *s = j->src + (size_t)y * w4;
        float *d = j->dst + (size_t)y * w4;
        j->bad[y] = 0;
        int in_stale = y >= st->y0 && y < st->y1 && st->x1 > st->x0;
        int in_roi = y >= roi->y0 && y < roi->y1 && roi->x1 > roi->x0;
        if (!in_roi) {
            if (in_stale)
                copy_span(s, d, st->x0, st->x1);
            continue;
        }
        if (in_stale) {
            copy_span(s, d, st->x0, st->x1 < roi->x0 ? st->x1 : roi->x0);
            copy_span(s, d, st->x0 > roi->x1 ? st->x0 : roi->x1, st->x1);
        }
        size_t bad = 0;
        const float *cov = j->mask ? j->mask->coverage + (size_t)y * j->width : NULL;
        /* Most rows are all finite and unmasked: a branch-free check, nothing else (and
         * not even that for an effect that made its rows finite itself). */
        if (!j->own_finite)
            bad = fx_span_make_finite(d + (size_t)roi->x0 * 4, (size_t)(roi->x1 - roi->x0) * 4);
        if (!cov) {
            j->bad[y] = bad;
            continue;
        }
        for (int x = roi->x0; x < roi->x1; x++) {
            float *dp = d + (size_t)x * 4;
            const float *sp = s + (size_t)x * 4;
            float m = cov[x];
            if (m <= 0.0f) {
                memcpy(dp, sp, 4 * sizeof(float));
            } else if (m < 1.0f) {
                for (int c = 0; c < 4; c++) {
                    float v = sp[c] + m * (dp[c] - sp[c]);
                    dp[c] = isfinite(v) ? v : (m < 0.5f ? sp[c] : dp[c]);
                }
            }
        }
        j->bad[y] = bad;
    }
}

static fx_rect rect_union(fx_rect a, fx_rect b)
{
    if (a.x1 <= a.x0 || a.y1 <= a.y0)
        return b;
    if (b.x1 <= b.x0 || b.y1 <= b.y0)
        return a;
    fx_rect r = {a.x0 < b.x0 ? a.x0 : b.x0, a.y0 < b.y0 ? a.y0 : b.y0, a.x1 > b.x1 ? a.x1 : b.x1,
                 a.y1 > b.y1 ? a.y1 : b.y1};
    return r;
}

static double now_ms(void)
{
    return fx_os_now_ms();
}

float *fx_effect_debug_pass(const fx_effect_run *run, const char *name, int channels, fx_result *result)
{
    if (result)
        *result = FX_OK;
    if (!run->debug)
        return NULL;
    char full[FX_NAME_MAX];
    snprintf(full, sizeof full, "fx%d_%s_%s", run->index, run->effect_name, name);
    float *buf = NULL;
    fx_result r = fx_frame_alloc_pass(run->debug, full, channels, &buf);
    if (r) {
        if (result)
            *result = r;
        return NULL;
    }
    memset(buf, 0, (size_t)run->width * run->height * channels * sizeof(float));
    return buf;
}

void fx_effect_finish_row(const fx_effect_run *run, float *row, size_t n)
{
    size_t bad = fx_span_make_finite(row, n);
    if (bad && run->nonfinite)
        atomic_fetch_add(run->nonfinite, bad);
}

fx_result fx_effect_pass_through(const fx_effect_run *run)
{
    const fx_rect *roi = &run->roi;
    if (roi->x1 <= roi->x0)
        return FX_OK;
    const size_t n = (size_t)(roi->x1 - roi->x0) * 4;
    for (int y = roi->y0; y < roi->y1; y++) {
        float *d = run->dst + ((size_t)y * run->width + roi->x0) * 4;
        if (run->dst != run->src)
            memcpy(d, run->src + ((size_t)y * run->width + roi->x0) * 4, n * sizeof(float));
        fx_effect_finish_row(run, d, n); /* for effects that keep their output finite themselves */
    }
    return FX_OK;
}

double fx_effect_scene_time(const fx_effect_run *run)
{
    double frame = 1, fps = 24;
    fx_frame_time(run->frame, &frame, &fps);
    return frame / (fps > 0 ? fps : 24.0);
}

double fx_effect_scene_frame(const fx_effect_run *run)
{
    double frame = 1;
    fx_frame_time(run->frame, &frame, NULL);
    return frame;
}

static fx_result check_passes(const fx_stack *s, const fx_frame *in, fx_pass_set set, const char *where)
{
    for (int i = 0; i < FX_PASS_COUNT; i++) {
        if (!(set & FX_PASS_BIT(i)) || i == FX_PASS_COMBINED)
            continue;
        const fx_pass_desc *d = fx_pass_describe((fx_pass_id)i);
        char name[FX_NAME_MAX];
        snprintf(name, sizeof name, d->is_crypto ? "%s00" : "%s", d->name);
        if (!fx_frame_find_pass(in, name)) {
            const char *src = fx_frame_meta(in, "libfx:source");
            return fx_fail(s->ctx, FX_ERR_MISSING_PASS,
                           "%s needs the %s pass, which %s%s%s does not have (enable it in Blender: "
                           "View Layer > Passes, or `libfx passes --stack ...`)",
                           where, d->name, src ? "'" : "", src ? src : "the frame", src ? "'" : "");
        }
    }
    return FX_OK;
}

/* Combined leads the output's passes (debug passes were added before it). */
static void combined_first(fx_frame *o)
{
    for (int i = 1; i < o->pass_count; i++)
        if (strcmp(o->passes[i].name, "Combined") == 0) {
            fx_pass c = o->passes[i];
            memmove(o->passes + 1, o->passes, (size_t)i * sizeof *o->passes);
            o->passes[0] = c;
            return;
        }
}

/* The image's buffers during a run. Effects ping-pong between `cur` and `spare`, taken
 * when the first effect that changes pixels needs them: a stack that changes nothing
 * allocates nothing and its output shares the input's Combined. `owned` is the input's
 * Combined when the caller gave the frame up (fx_stack_run_consume): in-place effects may
 * write into it. Each of cur/spare keeps the rect where it may differ from the current
 * image, so an effect limited to a small mask copies only what is stale, not the frame. */
typedef struct run_buffers {
    const float *image; /* the current image: the input's Combined, cur, spare or owned */
    float *cur, *spare, *owned;
    fx_rect stale_cur, stale_spare;
    size_t bytes;
} run_buffers;

/* Where the effect writes: the current image itself for an in-place effect on a buffer
 * the run may write (no mask: blending needs the old pixels), else the other buffer. */
static fx_result pick_dst(fx_context *ctx, run_buffers *b, const fx_effect_class *cls, const void *params,
                          const fx_mask *mask, const char *where, float **dst)
{
    float *writable = b->image == b->cur ? b->cur : b->image == b->spare ? b->spare
                      : b->image == b->owned ? b->owned : NULL;
    int in_place = (cls->flags & FX_EFFECT_IN_PLACE) || (cls->in_place && cls->in_place(params));
    if (writable && !mask && in_place) {
        *dst = writable;
        return FX_OK;
    }
    float **buf = b->image == b->cur ? &b->spare : &b->cur;
    if (!*buf) {
        fx_result r = fx_check_budget(ctx, b->bytes, "an effect's output");
        if (r)
            return r;
        if (!(*buf = fx_buffer_get(ctx, b->bytes)))
            return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where);
    }
    *dst = *buf;
    return FX_OK;
}

/* After an effect wrote dst over roi: dst is the image; every other buffer of ours lags
 * by the roi (dst itself is whole: the composite copied its stale part). */
static void image_moved(run_buffers *b, float *dst, fx_rect roi)
{
    if (dst == b->cur)
        b->stale_cur = (fx_rect){0, 0, 0, 0};
    else
        b->stale_cur = rect_union(b->stale_cur, roi);
    if (dst == b->spare)
        b->stale_spare = (fx_rect){0, 0, 0, 0};
    else
        b->stale_spare = rect_union(b->stale_spare, roi);
    b->image = dst;
}

/* ---- proxies ---- */

static long floor_div_l(long a, long b)
{
    long q = a / b;
    return (a % b != 0 && a < 0) ? q - 1 : q;
}

static long clamp_l(long v)
{
    return v < -1000000000L ? -1000000000L : v > 1000000000L ? 1000000000L : v;
}

/* The mask of a run on a proxy: its rectangle (given in the full frame's display-window
 * pixels, or as fractions of it) becomes the proxy pixels it touches, so a rectangle
 * smaller than a proxy pixel still selects that pixel. A shallow copy: the name and index
 * lists stay the entry's. */
static fx_mask_spec proxy_mask_spec(const fx_mask_spec *m, const fx_frame *in)
{
    fx_mask_spec s = *m;
    const long f = in->proxy_factor;
    if (f <= 1 || (!m->has_rect && !m->has_rect_relative))
        return s;
    const int *dw = in->full_data_window, *dp = in->full_display_window;
    long x0 = LONG_MIN / 4, y0 = LONG_MIN / 4, x1 = LONG_MAX / 4, y1 = LONG_MAX / 4;
    if (m->has_rect) {
        x0 = m->rect[0];
        y0 = m->rect[1];
        x1 = x0 + m->rect[2];
        y1 = y0 + m->rect[3];
    }
    if (m->has_rect_relative) {
        /* as fx_mask_build rounds it on the full frame */
        double w = (double)dp[2] - dp[0] + 1, h = (double)dp[3] - dp[1] + 1;
        const float *q = m->rect_relative;
        long rx0 = lround(q[0] * w), ry0 = lround(q[1] * h);
        long rx1 = lround((q[0] + q[2]) * w), ry1 = lround((q[1] + q[3]) * h);
        if (rx0 > x0) x0 = rx0;
        if (ry0 > y0) y0 = ry0;
        if (rx1 < x1) x1 = rx1;
        if (ry1 < y1) y1 = ry1;
    }
    /* full data-window pixels -> the proxy pixels they touch -> the proxy's display window */
    long fx0 = x0 + dp[0] - dw[0], fy0 = y0 + dp[1] - dw[1];
    long fx1 = x1 + dp[0] - dw[0], fy1 = y1 + dp[1] - dw[1];
    long px0 = floor_div_l(fx0, f), py0 = floor_div_l(fy0, f);
    long px1 = fx1 > fx0 ? -floor_div_l(-fx1, f) : px0, py1 = fy1 > fy0 ? -floor_div_l(-fy1, f) : py0;
    long ox = (long)in->display_window[0] - in->data_window[0];
    long oy = (long)in->display_window[1] - in->data_window[1];
    s.has_rect = 1;
    s.has_rect_relative = 0;
    s.rect[0] = (int)clamp_l(px0 - ox);
    s.rect[1] = (int)clamp_l(py0 - oy);
    s.rect[2] = (int)clamp_l(px1 - px0);
    s.rect[3] = (int)clamp_l(py1 - py0);
    return s;
}

/* The parameters an entry runs with: its committed ones, or on a proxy a copy with the
 * pixel-sized ones and the mask parameters' rectangles scaled (the proxy looks like the
 * frame). *owned is the copy to free with fx_mem_free: its specs are shallow copies. */
static fx_result run_params(fx_context *ctx, const fx_entry *e, const fx_frame *in, const char *where,
                            const void **params, void **owned)
{
    *owned = NULL;
    *params = e->effective;
    if (in->proxy_factor <= 1)
        return FX_OK;
    const fx_effect_class *c = e->cls;
    if (!(*owned = effective_alloc(c)))
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where);
    memcpy(*owned, e->effective, c->params_size);
    fx_params_scale_pixels(c, *owned, in->proxy_factor);
    fx_mask_spec *specs = effective_specs(c, *owned);
    for (int i = 0, k = 0; i < c->param_count; i++) {
        if (!fx_param_is_mask(&c->params[i]))
            continue;
        fx_mask_param *mp = (fx_mask_param *)((char *)*owned + c->params[i].offset);
        if (mp->spec) {
            specs[k] = proxy_mask_spec(mp->spec, in);
            mp->spec = &specs[k];
        }
        k++;
    }
    *params = *owned;
    return FX_OK;
}

/* What the effect needs from the frame: its passes and, if it needs one, the camera. */
static fx_result check_inputs(const fx_stack *s, const fx_entry *e, const void *params, const fx_frame *in,
                              const char *where)
{
    fx_result r = check_passes(s, in, e->cls->passes ? e->cls->passes(e->effective) : 0, where);
    if (!r && fx_effect_needs_camera(e->cls, params) && !in->has_camera)
        r = fx_fail(s->ctx, FX_ERR_NO_CAMERA,
                    "%s needs the camera matrices: the file has no worldToCamera/worldToNDC "
                    "attributes (give a camera sidecar with --sidecar)",
                    where);
    return r;
}

/* Blends the effect's output into the image by the mask, replaces non-finite values
 * (warning with their count) and makes dst the image. */
static fx_result composite(fx_context *ctx, run_buffers *b, const fx_effect_run *run, int own_finite,
                           atomic_size_t *own_bad)
{
    const int w = run->width, h = run->height;
    size_t *bad = fx_mem_calloc((size_t)(h ? h : 1), sizeof *bad);
    if (!bad)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", run->where);
    float *dst = run->dst;
    fx_rect stale = dst == b->cur ? b->stale_cur : dst == b->spare ? b->stale_spare : (fx_rect){0, 0, 0, 0};
    composite_job job = {b->image, dst, run->mask, run->roi, stale, w, own_finite, bad};
    fx_parallel_for(ctx, h, fx_grain_for(ctx, h), composite_rows, &job);
    image_moved(b, dst, run->roi);
    size_t total = atomic_load(own_bad);
    for (int y = 0; y < h; y++)
        total += bad[y];
    fx_mem_free(bad);
    if (total)
        fx_warn(ctx, "%s produced %zu non-finite values; they were replaced", run->where, total);
    return FX_OK;
}

/* Whether every value of the image is finite (a frame built through the API may hold
 * NaN/Inf; the reader's are sanitised): read-only, in parallel. */
typedef struct finite_job {
    const float *image;
    size_t row;
    atomic_int bad;
} finite_job;

static void finite_rows(void *user, int y0, int y1)
{
    finite_job *j = user;
    const uint32_t *u = (const uint32_t *)(const void *)(j->image + (size_t)y0 * j->row);
    const size_t n = (size_t)(y1 - y0) * j->row;
    uint32_t any = 0;
    for (size_t i = 0; i < n; i++) /* exponent all ones: Inf or NaN */
        any |= (uint32_t)((u[i] & 0x7f800000u) == 0x7f800000u);
    if (any)
        atomic_store(&j->bad, 1);
}

static int image_finite(fx_context *ctx, const float *image, int w, int h)
{
    finite_job j = {image, (size_t)w * 4, 0};
    atomic_init(&j.bad, 0);
    fx_parallel_for(ctx, h, fx_grain_for(ctx, h), finite_rows, &j);
    return !atomic_load(&j.bad);
}

/* Runs one enabled effect on the current image. The stack does for every effect what
 * none repeats: inputs checked, identity and empty masks skipped, buffers picked, the
 * result blended by the mask and made finite. */
static fx_result run_entry(fx_stack *s, fx_entry *e, int i, const fx_frame *in, fx_frame *o, run_buffers *b,
                           const char *where)
{
    fx_context *ctx = s->ctx;
    const int w = in->width, h = in->height;
    const void *params = NULL;
    void *scaled = NULL;
    fx_mask *mask = NULL;
    fx_result r = run_params(ctx, e, in, where, &params, &scaled);
    if (!r)
        r = check_inputs(s, e, params, in, where);
    /* An identity is skipped and the image passes through, unless it holds non-finite
     * values: then it goes through the stack's guard (a copy, replaced and reported) as
     * the output of any effect does. */
    const int identity = !r && e->cls->identity && e->cls->identity(params);
    if (r || (identity && image_finite(ctx, b->image, w, h)))
        goto out;
    fx_mask_spec spec = proxy_mask_spec(&e->mask, in);
    if ((r = fx_mask_build(ctx, &spec, in, where, &mask)))
        goto out;
    const fx_rect roi = mask ? mask->bounds : (fx_rect){0, 0, w, h};
    if (roi.x1 <= roi.x0 || roi.y1 <= roi.y0)
        goto out; /* nothing selected: the effect is skipped and the image passes through */
    char key[16] = "";
    if (e->cls->aux_views && !mask_key(e, key)) {
        r = fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where);
        goto out;
    }
    float *dst = NULL;
    if ((r = pick_dst(ctx, b, e->cls, params, mask, where, &dst)))
        goto out;
    fx_effect_run run;
    memset(&run, 0, sizeof run);
    run.ctx = ctx;
    run.frame = in;
    run.src = b->image;
    run.dst = dst;
    run.width = w;
    run.height = h;
    run.roi = roi;
    run.mask = mask;
    run.params = params;
    run.quality = entry_quality(s, e);
    run.index = i;
    run.effect_name = e->cls->name;
    run.where = where;
    run.debug = s->debug ? o : NULL;
    run.proxy_factor = in->proxy_factor > 1 ? in->proxy_factor : 1;
    run.mask_key = key;
    atomic_size_t own_bad;
    atomic_init(&own_bad, 0);
    run.nonfinite = &own_bad;
    if (!(r = identity ? fx_effect_pass_through(&run) : e->cls->process(&run)))
        r = composite(ctx, b, &run,
                      (e->cls->flags & FX_EFFECT_OWN_FINITE) || (e->cls->own_finite && e->cls->own_finite(params)),
                      &own_bad);
out:
    fx_mask_free(mask);
    fx_mem_free(scaled);
    return r;
}

/* The output's Combined: the input's pixels when nothing changed them (shared), else the
 * buffer holding the image. */
static fx_result take_result(fx_frame *o, const fx_frame *in, const fx_pass *combined, run_buffers *b)
{
    fx_result r;
    if (b->image == combined->data) {
        r = fx_frame_share_pass(o, "Combined", in, combined);
    } else {
        float **result = b->image == b->cur ? &b->cur : &b->spare;
        r = fx_frame_adopt_pass(o, "Combined", 4, *result);
        *result = NULL;
    }
    if (!r)
        combined_first(o);
    return r;
}

/* Run stage 1, prepare: the input's Combined and an output frame like the input, in the
 * stack's context: the result's buffers come from that context's store and go back to it
 * when the output is freed (in the input's context, a stack run on a frame read by another
 * context gave its store's buffers away every run and faulted fresh pages in for the next:
 * 10x the time of draft god rays at 1080p here). */
static fx_result run_prepare(fx_stack *s, const fx_frame *in, const fx_pass **combined, fx_frame **o)
{
    *combined = fx_frame_find_pass(in, "Combined");
    if (!*combined || (*combined)->channels != 4) {
        const char *src = fx_frame_meta(in, "libfx:source");
        return fx_fail(s->ctx, FX_ERR_MISSING_PASS, "%s%s%s has no RGBA Combined pass to process",
                       src ? "'" : "", src ? src : "the frame", src ? "'" : "");
    }
    return fx_frame_new_like_in(s->ctx, in, o);
}

/* Run stage 2, pick buffers: the image starts as the input's Combined; it is ours to
 * write when the caller gave the frame up and no other frame holds those pixels. */
static run_buffers run_buffers_for(const fx_stack *s, const fx_frame *in, const fx_pass *combined, int consume)
{
    const int w = in->width, h = in->height;
    const fx_rect full = {0, 0, w, h};
    run_buffers b = {combined->data, NULL, NULL, NULL, full, full, (size_t)w * h * 4 * sizeof(float)};
    if (consume && in->ctx == s->ctx && combined->pixels && fx_frame_pixels_holders(combined) == 1)
        b.owned = combined->data;
    return b;
}

/* Run stage 3, run and composite: the enabled effects in order, with progress (which
 * may cancel) and per-effect timings. */
static fx_result run_effects(fx_stack *s, const fx_frame *in, fx_frame *o, run_buffers *b)
{
    int enabled = 0;
    for (int i = 0; i < s->count; i++)
        enabled += s->entries[i].enabled;
    int done = 0;
    fx_result r = FX_OK;
    for (int i = 0; i < s->count && !r; i++) {
        fx_entry *e = &s->entries[i];
        e->last_ms = 0;
        if (!e->enabled)
            continue;
        double t0 = now_ms();
        char where[128];
        where_of(where, sizeof where, i, e->cls);
        char stage[160];
        snprintf(stage, sizeof stage, "%s (%d of %d)", where, done + 1, enabled);
        if ((r = fx_progress(s->ctx, stage, (double)done / (enabled ? enabled : 1))))
            break;
        r = run_entry(s, e, i, in, o, b, where);
        e->last_ms = now_ms() - t0;
        done++;
    }
    return r;
}

static fx_result stack_run(fx_stack *s, const fx_frame *in, int consume, fx_frame **out)
{
    if (!s || !in || !out)
        return fx_fail(s ? s->ctx : NULL, FX_ERR_INVALID_ARGUMENT, "fx_stack_run: NULL argument");
    *out = NULL;
    fx_context *ctx = s->ctx;
    const fx_pass *combined = NULL;
    fx_frame *o = NULL;
    fx_result r = run_prepare(s, in, &combined, &o);
    if (r)
        return r;
    run_buffers b = run_buffers_for(s, in, combined, consume);
    r = run_effects(s, in, o, &b);
    /* stage 4, finish: the result, the last progress call, the buffers back to the pool */
    if (!r)
        r = take_result(o, in, combined, &b);
    if (!r && ctx->progress)
        ctx->progress(ctx->progress_user, "done", 1.0); /* the work is finished: no cancel now */
    fx_buffer_put(ctx, b.cur, b.bytes);
    fx_buffer_put(ctx, b.spare, b.bytes);
    if (r) {
        fx_frame_free(o);
        return r;
    }
    *out = o;
    return FX_OK;
}

fx_result fx_stack_run(fx_stack *s, const fx_frame *in, fx_frame **out)
{
    return stack_run(s, in, 0, out);
}

fx_result fx_stack_run_consume(fx_stack *s, fx_frame *in, int keep_passes, fx_frame **out)
{
    if (!in) {
        if (out)
            *out = NULL;
        return fx_fail(s ? s->ctx : NULL, FX_ERR_INVALID_ARGUMENT, "fx_stack_run_consume: NULL frame");
    }
    fx_result r = stack_run(s, in, 1, out);
    if (!r && keep_passes && (r = fx_frame_copy_passes(*out, in)) != FX_OK) {
        fx_frame_free(*out);
        *out = NULL;
    }
    fx_frame_free(in); /* the output may hold its pixels: shared pixels outlive the frame */
    return r;
}

fx_result fx_stack_timings_json(const fx_stack *s, char **out_json)
{
    if (!s || !out_json)
        return FX_ERR_INVALID_ARGUMENT;
    cJSON *a = cJSON_CreateArray();
    for (int i = 0; i < s->count; i++) {
        cJSON *o = cJSON_CreateObject();
        cJSON_AddNumberToObject(o, "index", i);
        cJSON_AddStringToObject(o, "effect", s->entries[i].cls->name);
        cJSON_AddBoolToObject(o, "enabled", s->entries[i].enabled);
        cJSON_AddNumberToObject(o, "ms", s->entries[i].last_ms);
        cJSON_AddItemToArray(a, o);
    }
    char *str = cJSON_PrintUnformatted(a);
    cJSON_Delete(a);
    *out_json = str ? fx_json_strdup(str) : NULL;
    cJSON_free(str);
    return *out_json ? FX_OK : fx_fail(s->ctx, FX_ERR_OUT_OF_MEMORY, "out of memory");
}
