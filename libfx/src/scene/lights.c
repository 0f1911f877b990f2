/* Lights from the frame's "libfx:lights" metadata (checked when the sidecar was applied). */
#include "scene/lights.h"
#include "core/context.h"
#include "core/mem_failures.h"

#include <cjson/cJSON.h>
#include <stdio.h>
#include <string.h>

static fx_vec3 vec_or(const cJSON *light, const char *key, fx_vec3 fallback)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(light, key);
    if (!cJSON_IsArray(v) || cJSON_GetArraySize(v) != 3)
        return fallback;
    float c[3];
    for (int i = 0; i < 3; i++) {
        const cJSON *x = cJSON_GetArrayItem(v, i);
        if (!cJSON_IsNumber(x) || !isfinite(x->valuedouble))
            return fallback;
        c[i] = (float)x->valuedouble;
    }
    return fx_v3(c[0], c[1], c[2]);
}

static fx_light_type type_of(const char *t)
{
    if (strcmp(t, "POINT") == 0)
        return FX_LIGHT_POINT;
    if (strcmp(t, "SPOT") == 0)
        return FX_LIGHT_SPOT;
    if (strcmp(t, "AREA") == 0)
        return FX_LIGHT_AREA;
    return FX_LIGHT_SUN;
}

fx_result fx_frame_find_light(const fx_frame *f, const char *name, const char *where, fx_light *out)
{
    const char *text = fx_frame_meta(f, "libfx:lights");
    if (!text)
        return fx_fail(f->ctx, FX_ERR_NO_LIGHTS,
                       "%s needs the scene's lights, which the frame does not carry (give the scene "
                       "sidecar with --sidecar; the Blender add-on writes it)",
                       where);
    unsigned long failures = fx_mem_failure_count();
    cJSON *lights = cJSON_Parse(text);
    if (!lights && fx_mem_failure_count() != failures)
        return fx_fail(f->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory reading the scene's lights", where);
    if (!cJSON_IsArray(lights)) {
        cJSON_Delete(lights);
        return fx_fail(f->ctx, FX_ERR_BAD_FILE, "%s: the frame's libfx:lights metadata is not a JSON list", where);
    }
    const cJSON *found = NULL, *l;
    int want_name = name && name[0];
    cJSON_ArrayForEach(l, lights) {
        const cJSON *n = cJSON_GetObjectItemCaseSensitive(l, "name");
        const cJSON *t = cJSON_GetObjectItemCaseSensitive(l, "type");
        if (!cJSON_IsString(n) || !cJSON_IsString(t))
            continue;
        if (want_name ? strcmp(n->valuestring, name) == 0 : strcmp(t->valuestring, "SUN") == 0) {
            found = l;
            break;
        }
    }
    if (!found && !want_name)
        found = cJSON_GetArrayItem(lights, 0);
    if (!found) {
        char names[512] = "";
        size_t len = 0;
        cJSON_ArrayForEach(l, lights) {
            const cJSON *n = cJSON_GetObjectItemCaseSensitive(l, "name");
            if (cJSON_IsString(n) && len < sizeof names - 1)
                len += (size_t)snprintf(names + len, sizeof names - len, "%s%s", len ? ", " : "", n->valuestring);
        }
        cJSON_Delete(lights);
        return fx_fail(f->ctx, FX_ERR_BAD_PARAM, "%s: no light named '%s' in the scene (lights: %s)", where,
                       want_name ? name : "(any)", names[0] ? names : "none");
    }
    memset(out, 0, sizeof *out);
    const cJSON *n = cJSON_GetObjectItemCaseSensitive(found, "name");
    const cJSON *t = cJSON_GetObjectItemCaseSensitive(found, "type");
    snprintf(out->name, sizeof out->name, "%s", cJSON_IsString(n) ? n->valuestring : "");
    out->type = type_of(cJSON_IsString(t) ? t->valuestring : "SUN");
    out->position = vec_or(found, "position", fx_v3(0, 0, 0));
    out->direction = fx_v3_normalize_or(vec_or(found, "direction", fx_v3(0, 0, -1)), fx_v3(0, 0, -1));
    out->color = vec_or(found, "color", fx_v3(1, 1, 1));
    const cJSON *e = cJSON_GetObjectItemCaseSensitive(found, "energy");
    const cJSON *a = cJSON_GetObjectItemCaseSensitive(found, "angle");
    out->energy = cJSON_IsNumber(e) && isfinite(e->valuedouble) ? (float)e->valuedouble : 1.0f;
    out->angle = cJSON_IsNumber(a) && isfinite(a->valuedouble) ? (float)a->valuedouble : 0.0f;
    cJSON_Delete(lights);
    return FX_OK;
}
