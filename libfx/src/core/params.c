/* Parameters are declared once per effect (core/effect.h); this file turns JSON into
 * the effect's params struct and back, checks types and ranges with messages that
 * name the effect, the parameter and the allowed values, and describes a parameter as
 * JSON. What the public API tells about effects is the registry's (core/registry.c). */
#include "core/params.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

static const char *const quality_names[] = {"draft", "preview", "final", "reference"};

int fx_quality_from_name(const char *name)
{
    if (!name)
        return -1;
    for (int i = 0; i < 4; i++)
        if (strcmp(name, quality_names[i]) == 0)
            return i;
    return -1;
}

const char *fx_quality_name(int quality)
{
    return quality >= 0 && quality < 4 ? quality_names[quality] : NULL;
}

static void *field(void *params, const fx_param_def *def)
{
    return (char *)params + def->offset;
}

static const void *cfield(const void *params, const fx_param_def *def)
{
    return (const char *)params + def->offset;
}

static size_t field_size(const fx_param_def *def)
{
    switch (def->info.type) {
    case FX_PARAM_FLOAT: return sizeof(float);
    case FX_PARAM_INT:
    case FX_PARAM_BOOL:
    case FX_PARAM_ENUM: return sizeof(int);
    case FX_PARAM_FLOATS: return (size_t)def->info.count * sizeof(float);
    case FX_PARAM_STRING: return FX_STRING_PARAM_MAX;
    }
    return 0;
}

int fx_param_is_mask(const fx_param_def *def)
{
    return def->info.type == FX_PARAM_STRING && def->info.hint && strcmp(def->info.hint, FX_HINT_MASK) == 0;
}

void fx_param_copy(const fx_param_def *def, void *dst, const void *src)
{
    memcpy(field(dst, def), cfield(src, def), field_size(def));
}

void fx_params_set_defaults(const fx_effect_class *cls, void *params)
{
    memset(params, 0, cls->params_size);
    for (int i = 0; i < cls->param_count; i++) {
        const fx_param_def *d = &cls->params[i];
        void *p = field(params, d);
        switch (d->info.type) {
        case FX_PARAM_FLOAT: *(float *)p = (float)d->info.default_value; break;
        case FX_PARAM_INT:
        case FX_PARAM_BOOL:
        case FX_PARAM_ENUM: *(int *)p = (int)d->info.default_value; break;
        case FX_PARAM_FLOATS:
            if (d->info.default_floats)
                memcpy(p, d->info.default_floats, (size_t)d->info.count * sizeof(float));
            break;
        case FX_PARAM_STRING:
            if (d->info.default_string)
                snprintf((char *)p, FX_STRING_PARAM_MAX, "%s", d->info.default_string);
            break;
        }
    }
}

static double clamp_range(double v, const fx_param_info *in)
{
    return v < in->min ? in->min : v > in->max ? in->max : v;
}

void fx_params_scale_pixels(const fx_effect_class *cls, void *params, int factor)
{
    if (factor <= 1)
        return;
    for (int i = 0; i < cls->param_count; i++) {
        const fx_param_def *d = &cls->params[i];
        if (!d->info.hint || strcmp(d->info.hint, "pixels") != 0)
            continue;
        void *p = field(params, d);
        switch (d->info.type) {
        case FX_PARAM_FLOAT:
            *(float *)p = (float)clamp_range((double)*(float *)p / factor, &d->info);
            break;
        case FX_PARAM_INT:
            *(int *)p = (int)clamp_range((double)lround((double)*(int *)p / factor), &d->info);
            break;
        case FX_PARAM_FLOATS:
            for (int k = 0; k < d->info.count; k++)
                ((float *)p)[k] = (float)clamp_range((double)((float *)p)[k] / factor, &d->info);
            break;
        default:
            break;
        }
    }
}

static const char *type_name(fx_param_type t)
{
    switch (t) {
    case FX_PARAM_FLOAT: return "a number";
    case FX_PARAM_INT: return "an integer";
    case FX_PARAM_BOOL: return "true or false";
    case FX_PARAM_ENUM: return "one of the listed names";
    case FX_PARAM_FLOATS: return "an array of numbers";
    case FX_PARAM_STRING: return "a string";
    }
    return "?";
}

static fx_result out_of_range(fx_context *ctx, const char *where, const fx_param_def *d, double v)
{
    return fx_fail(ctx, FX_ERR_BAD_PARAM, "%s: parameter '%s' = %g is out of range [%g, %g]", where,
                   d->info.name, v, d->info.min, d->info.max);
}

static fx_result enum_error(fx_context *ctx, const char *where, const fx_param_def *d, const char *got)
{
    char items[512] = "";
    size_t len = 0;
    for (int i = 0; i < d->info.enum_count && len < sizeof items - 1; i++)
        len += (size_t)snprintf(items + len, sizeof items - len, "%s%s", i ? ", " : "",
                                d->info.enum_items[i]);
    return fx_fail(ctx, FX_ERR_BAD_PARAM, "%s: parameter '%s' = \"%s\" is not one of: %s", where,
                   d->info.name, got, items);
}

/* Reads an array of numbers, flattening one level of nesting (matrix rows). */
static int read_floats(const cJSON *value, float *out, int max, int *count)
{
    int n = 0;
    const cJSON *item;
    cJSON_ArrayForEach(item, value) {
        if (cJSON_IsArray(item)) {
            const cJSON *inner;
            cJSON_ArrayForEach(inner, item) {
                if (!cJSON_IsNumber(inner) || n >= max)
                    return 0;
                out[n++] = (float)inner->valuedouble;
            }
        } else {
            if (!cJSON_IsNumber(item) || n >= max)
                return 0;
            out[n++] = (float)item->valuedouble;
        }
    }
    *count = n;
    return 1;
}

/* Sets one parameter from JSON after checking type and range. `where` names the effect
 * in messages ("effect 2 (pixelate)"). */
static fx_result param_set_json(fx_context *ctx, const fx_param_def *d, void *params, const cJSON *value,
                                const char *where)
{
    const fx_param_info *in = &d->info;
    void *p = field(params, d);
    switch (in->type) {
    case FX_PARAM_FLOAT: {
        if (!cJSON_IsNumber(value))
            break;
        double v = value->valuedouble;
        if (!isfinite(v) || v < in->min || v > in->max)
            return out_of_range(ctx, where, d, v);
        *(float *)p = (float)v;
        return FX_OK;
    }
    case FX_PARAM_INT: {
        if (!cJSON_IsNumber(value))
            break;
        double v = value->valuedouble;
        if (v != floor(v))
            return fx_fail(ctx, FX_ERR_BAD_PARAM, "%s: parameter '%s' = %g must be an integer", where,
                           in->name, v);
        if (v < in->min || v > in->max)
            return out_of_range(ctx, where, d, v);
        *(int *)p = (int)v;
        return FX_OK;
    }
    case FX_PARAM_BOOL:
        if (!cJSON_IsBool(value))
            break;
        *(int *)p = cJSON_IsTrue(value) ? 1 : 0;
        return FX_OK;
    case FX_PARAM_ENUM: {
        if (!cJSON_IsString(value))
            break;
        for (int i = 0; i < in->enum_count; i++)
            if (strcmp(value->valuestring, in->enum_items[i]) == 0) {
                *(int *)p = i;
                return FX_OK;
            }
        return enum_error(ctx, where, d, value->valuestring);
    }
    case FX_PARAM_FLOATS: {
        if (!cJSON_IsArray(value))
            break;
        float tmp[64];
        int n = 0;
        int max = in->count < 64 ? in->count : 64;
        if (!read_floats(value, tmp, max, &n))
            n = -1;
        int is_matrix4 = in->hint && strcmp(in->hint, "matrix4") == 0;
        if (is_matrix4 && n == 9) {
            /* A 3x3 colour matrix acts on RGB and leaves alpha alone. */
            float m[16] = {tmp[0], tmp[1], tmp[2], 0, tmp[3], tmp[4], tmp[5], 0,
                           tmp[6], tmp[7], tmp[8], 0, 0,      0,      0,      1};
            memcpy(tmp, m, sizeof m);
            n = 16;
        }
        if (n != in->count)
            return fx_fail(ctx, FX_ERR_BAD_PARAM, "%s: parameter '%s' needs %d numbers%s", where,
                           in->name, in->count, is_matrix4 ? " (a 4x4 matrix) or 9 (3x3)" : "");
        for (int i = 0; i < n; i++) {
            /* Compared with the bounds as floats: a bound such as 1e30 is not a float, and
             * the value given as exactly that bound must not be refused. */
            if (!isfinite(tmp[i]) ||
                (in->min < in->max && (tmp[i] < (float)in->min || tmp[i] > (float)in->max)))
                return fx_fail(ctx, FX_ERR_BAD_PARAM,
                               "%s: parameter '%s'[%d] = %g is out of range [%g, %g]", where, in->name,
                               i, tmp[i], in->min, in->max);
        }
        memcpy(p, tmp, (size_t)n * sizeof(float));
        return FX_OK;
    }
    case FX_PARAM_STRING:
        if (!cJSON_IsString(value))
            break;
        if (strlen(value->valuestring) >= FX_STRING_PARAM_MAX)
            return fx_fail(ctx, FX_ERR_BAD_PARAM, "%s: parameter '%s' is longer than %d bytes", where,
                           in->name, FX_STRING_PARAM_MAX - 1);
        snprintf((char *)p, FX_STRING_PARAM_MAX, "%s", value->valuestring);
        return FX_OK;
    }
    return fx_fail(ctx, FX_ERR_BAD_PARAM, "%s: parameter '%s' must be %s", where, in->name,
                   type_name(in->type));
}

fx_result fx_params_set_object(fx_context *ctx, const fx_effect_class *cls, void *params,
                               const cJSON *object, unsigned char *explicit_set, const char *where)
{
    if (!cJSON_IsObject(object))
        return fx_fail(ctx, FX_ERR_BAD_RECIPE, "%s: \"params\" must be an object", where);
    const cJSON *item;
    cJSON_ArrayForEach(item, object) {
        const fx_param_def *d = fx_effect_find_param(cls, item->string);
        if (!d) {
            char names[512] = "";
            size_t len = 0;
            for (int i = 0; i < cls->param_count && len < sizeof names - 1; i++)
                len += (size_t)snprintf(names + len, sizeof names - len, "%s%s", i ? ", " : "",
                                        cls->params[i].info.name);
            return fx_fail(ctx, FX_ERR_BAD_PARAM, "%s: unknown parameter '%s' (parameters: %s)", where,
                           item->string, names);
        }
        fx_result r = param_set_json(ctx, d, params, item, where);
        if (r)
            return r;
        if (explicit_set)
            explicit_set[d - cls->params] = 1;
    }
    return FX_OK;
}

cJSON *fx_param_to_json(const fx_param_def *d, const void *params)
{
    const void *p = cfield(params, d);
    switch (d->info.type) {
    case FX_PARAM_FLOAT: return cJSON_CreateNumber(*(const float *)p);
    case FX_PARAM_INT: return cJSON_CreateNumber(*(const int *)p);
    case FX_PARAM_BOOL: return cJSON_CreateBool(*(const int *)p);
    case FX_PARAM_ENUM: {
        int i = *(const int *)p;
        return cJSON_CreateString(i >= 0 && i < d->info.enum_count ? d->info.enum_items[i] : "");
    }
    case FX_PARAM_FLOATS: return cJSON_CreateFloatArray((const float *)p, d->info.count);
    case FX_PARAM_STRING: return cJSON_CreateString((const char *)p);
    }
    return cJSON_CreateNull();
}

static const char *param_type_word(fx_param_type t)
{
    switch (t) {
    case FX_PARAM_FLOAT: return "float";
    case FX_PARAM_INT: return "int";
    case FX_PARAM_BOOL: return "bool";
    case FX_PARAM_ENUM: return "enum";
    case FX_PARAM_FLOATS: return "floats";
    case FX_PARAM_STRING: return "string";
    }
    return "?";
}

cJSON *fx_param_info_json(const fx_param_def *d)
{
    const fx_param_info *in = &d->info;
    cJSON *o = cJSON_CreateObject();
    if (!o)
        return NULL;
    cJSON_AddStringToObject(o, "name", in->name);
    cJSON_AddStringToObject(o, "type", param_type_word(in->type));
    cJSON_AddStringToObject(o, "doc", in->doc ? in->doc : "");
    cJSON_AddStringToObject(o, "hint", in->hint ? in->hint : "");
    switch (in->type) {
    case FX_PARAM_FLOAT:
    case FX_PARAM_INT:
        cJSON_AddNumberToObject(o, "default", in->default_value);
        cJSON_AddNumberToObject(o, "min", in->min);
        cJSON_AddNumberToObject(o, "max", in->max);
        cJSON_AddNumberToObject(o, "soft_min", in->soft_min);
        cJSON_AddNumberToObject(o, "soft_max", in->soft_max);
        break;
    case FX_PARAM_BOOL:
        cJSON_AddBoolToObject(o, "default", in->default_value != 0);
        break;
    case FX_PARAM_ENUM: {
        int di = (int)in->default_value;
        cJSON_AddStringToObject(o, "default", di >= 0 && di < in->enum_count ? in->enum_items[di] : "");
        cJSON_AddItemToObject(o, "items", cJSON_CreateStringArray(in->enum_items, in->enum_count));
        break;
    }
    case FX_PARAM_FLOATS: {
        static const float zeros[64];
        cJSON_AddNumberToObject(o, "count", in->count);
        cJSON_AddItemToObject(o, "default",
                              cJSON_CreateFloatArray(in->default_floats ? in->default_floats : zeros,
                                                     in->count));
        if (in->min < in->max) {
            cJSON_AddNumberToObject(o, "min", in->min);
            cJSON_AddNumberToObject(o, "max", in->max);
        }
        break;
    }
    case FX_PARAM_STRING:
        cJSON_AddStringToObject(o, "default", in->default_string ? in->default_string : "");
        break;
    }
    return o;
}
