/* Auxiliary views (core/aux_view.h): the sidecar's "aux_views", fx_frame_set_aux_view,
 * fx_stack_required_aux_views and loading a view's depth for an effect. */
#include "core/aux_view.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

/* ---- matrices in JSON (rows, as the camera sidecar) ---- */

static int read_m4(const cJSON *v, float out[16])
{
    int n = 0;
    const cJSON *row;
    if (!cJSON_IsArray(v))
        return 0;
    cJSON_ArrayForEach(row, v) {
        if (cJSON_IsArray(row)) {
            if (cJSON_GetArraySize(row) != 4)
                return 0;
            const cJSON *x;
            cJSON_ArrayForEach(x, row) {
                if (!cJSON_IsNumber(x) || n >= 16 || !isfinite(x->valuedouble))
                    return 0;
                out[n++] = (float)x->valuedouble;
            }
        } else {
            if (!cJSON_IsNumber(row) || n >= 16 || !isfinite(row->valuedouble))
                return 0;
            out[n++] = (float)row->valuedouble;
        }
    }
    return n == 16;
}

static cJSON *m4_json(const float m[16])
{
    cJSON *rows = cJSON_CreateArray();
    for (int i = 0; rows && i < 4; i++) {
        cJSON *r = cJSON_CreateArray();
        for (int j = 0; r && j < 4; j++)
            cJSON_AddItemToArray(r, cJSON_CreateNumber(m[i * 4 + j]));
        cJSON_AddItemToArray(rows, r);
    }
    return rows;
}

static const char *const view_keys[] = {"name", "path", "world_to_camera", "projection",
                                        "clip_start", "clip_end", "orthographic", "kind", "signature"};

/* One view entry -> camera; 0 with a message in err when malformed. */
static int view_camera(const cJSON *v, fx_camera *cam, char *err, size_t err_size)
{
    memset(cam, 0, sizeof *cam);
    cam->size = sizeof *cam;
    const cJSON *cs = cJSON_GetObjectItemCaseSensitive(v, "clip_start");
    const cJSON *ce = cJSON_GetObjectItemCaseSensitive(v, "clip_end");
    if (!read_m4(cJSON_GetObjectItemCaseSensitive(v, "world_to_camera"), cam->world_to_camera) ||
        !read_m4(cJSON_GetObjectItemCaseSensitive(v, "projection"), cam->projection)) {
        snprintf(err, err_size, "\"world_to_camera\" and \"projection\" must be 4x4 matrices (rows of finite numbers)");
        return 0;
    }
    if (!cJSON_IsNumber(cs) || !cJSON_IsNumber(ce) || !(cs->valuedouble >= 0) ||
        !(ce->valuedouble > cs->valuedouble) || !isfinite(ce->valuedouble)) {
        snprintf(err, err_size, "needs 0 <= \"clip_start\" < \"clip_end\" (finite)");
        return 0;
    }
    cam->clip_start = (float)cs->valuedouble;
    cam->clip_end = (float)ce->valuedouble;
    cam->orthographic = cam->projection[15] == 1.0f && cam->projection[14] == 0.0f;
    const cJSON *o = cJSON_GetObjectItemCaseSensitive(v, "orthographic");
    if (cJSON_IsBool(o))
        cam->orthographic = cJSON_IsTrue(o);
    return 1;
}

fx_result fx_aux_views_check(fx_context *ctx, const cJSON *list)
{
    if (!cJSON_IsArray(list))
        return fx_fail(ctx, FX_ERR_BAD_RECIPE, "sidecar: \"aux_views\" must be a list");
    int i = 0;
    const cJSON *v;
    cJSON_ArrayForEach(v, list) {
        const cJSON *name = cJSON_GetObjectItemCaseSensitive(v, "name");
        const cJSON *path = cJSON_GetObjectItemCaseSensitive(v, "path");
        if (!cJSON_IsObject(v) || !cJSON_IsString(name) || !name->valuestring[0] ||
            strlen(name->valuestring) >= FX_NAME_MAX || !cJSON_IsString(path) || !path->valuestring[0] ||
            strlen(path->valuestring) >= 1024)
            return fx_fail(ctx, FX_ERR_BAD_RECIPE,
                           "sidecar: aux_views[%d] needs a \"name\" (< %d bytes) and a \"path\" (an EXR with a Depth pass)",
                           i, FX_NAME_MAX);
        const cJSON *item;
        cJSON_ArrayForEach(item, v) {
            int known = 0;
            for (size_t k = 0; k < sizeof view_keys / sizeof view_keys[0]; k++)
                known |= strcmp(item->string, view_keys[k]) == 0;
            if (!known)
                return fx_fail(ctx, FX_ERR_BAD_RECIPE,
                               "sidecar: aux_views[%d] ('%s'): unknown key \"%s\" (known: name, path, world_to_camera, "
                               "projection, clip_start, clip_end, orthographic, kind, signature)",
                               i, name->valuestring, item->string);
        }
        fx_camera cam;
        char err[256];
        if (!view_camera(v, &cam, err, sizeof err))
            return fx_fail(ctx, FX_ERR_BAD_RECIPE, "sidecar: aux_views[%d] ('%s'): %s", i, name->valuestring, err);
        i++;
    }
    return FX_OK;
}

/* Merges `list` into the frame's list (same name: replaced). */
fx_result fx_aux_views_apply(fx_frame *f, const cJSON *list)
{
    fx_result r = fx_aux_views_check(f->ctx, list);
    if (r)
        return r;
    const char *old = fx_frame_meta(f, FX_AUX_META_KEY);
    cJSON *merged = old ? cJSON_Parse(old) : NULL;
    if (!cJSON_IsArray(merged)) {
        cJSON_Delete(merged);
        merged = cJSON_CreateArray();
    }
    if (!merged)
        return fx_fail(f->ctx, FX_ERR_OUT_OF_MEMORY, "aux views: out of memory");
    const cJSON *v;
    cJSON_ArrayForEach(v, list) {
        const char *name = cJSON_GetObjectItemCaseSensitive(v, "name")->valuestring;
        int n = cJSON_GetArraySize(merged);
        for (int k = n - 1; k >= 0; k--) {
            const cJSON *e = cJSON_GetArrayItem(merged, k);
            const cJSON *en = cJSON_GetObjectItemCaseSensitive(e, "name");
            if (cJSON_IsString(en) && strcmp(en->valuestring, name) == 0)
                cJSON_DeleteItemFromArray(merged, k);
        }
        cJSON_AddItemToArray(merged, cJSON_Duplicate(v, 1));
    }
    char *text = cJSON_PrintUnformatted(merged);
    cJSON_Delete(merged);
    if (!text)
        return fx_fail(f->ctx, FX_ERR_OUT_OF_MEMORY, "aux views: out of memory");
    r = fx_frame_set_meta(f, FX_AUX_META_KEY, text);
    cJSON_free(text);
    return r;
}

fx_result fx_frame_set_aux_view(fx_frame *f, const char *name, const char *exr_path, const fx_camera *camera)
{
    if (!f || !name || !exr_path || !camera || camera->size != sizeof(fx_camera))
        return fx_fail(f ? f->ctx : NULL, FX_ERR_INVALID_ARGUMENT,
                       "fx_frame_set_aux_view: NULL argument or camera->size != sizeof(fx_camera)");
    cJSON *list = cJSON_CreateArray();
    cJSON *v = cJSON_CreateObject();
    if (!list || !v) {
        cJSON_Delete(list);
        cJSON_Delete(v);
        return fx_fail(f->ctx, FX_ERR_OUT_OF_MEMORY, "fx_frame_set_aux_view: out of memory");
    }
    cJSON_AddItemToArray(list, v);
    cJSON_AddStringToObject(v, "name", name);
    cJSON_AddStringToObject(v, "path", exr_path);
    cJSON_AddItemToObject(v, "world_to_camera", m4_json(camera->world_to_camera));
    cJSON_AddItemToObject(v, "projection", m4_json(camera->projection));
    cJSON_AddNumberToObject(v, "clip_start", camera->clip_start);
    cJSON_AddNumberToObject(v, "clip_end", camera->clip_end);
    cJSON_AddBoolToObject(v, "orthographic", camera->orthographic);
    fx_result r = fx_aux_views_apply(f, list);
    cJSON_Delete(list);
    return r;
}

/* ---- what a stack needs ---- */

/* The effects that read aux views, and which. Kept here (one small table) rather than in
 * the effect class, so the class contract stays as it is. */
static void effect_views(const char *effect, const cJSON *params, cJSON *out)
{
    char name[FX_NAME_MAX];
    const char *kind = NULL, *light = NULL;
    if (strcmp(effect, "vsm_shadows") == 0) {
        const cJSON *l = cJSON_GetObjectItemCaseSensitive(params, "light");
        light = cJSON_IsString(l) ? l->valuestring : "";
        snprintf(name, sizeof name, "light:%s", light);
        kind = "light";
    } else if (strcmp(effect, "rain") == 0 || strcmp(effect, "wet_surfaces") == 0 ||
               strcmp(effect, "rain_splashes") == 0) {
        snprintf(name, sizeof name, "%s", FX_AUX_RAIN_MAP);
        kind = "rain_map";
    } else {
        return;
    }
    const cJSON *e;
    cJSON_ArrayForEach(e, out) {
        const cJSON *n = cJSON_GetObjectItemCaseSensitive(e, "name");
        if (cJSON_IsString(n) && strcmp(n->valuestring, name) == 0)
            return;
    }
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "name", name);
    cJSON_AddStringToObject(o, "kind", kind);
    if (light)
        cJSON_AddStringToObject(o, "light", light);
    cJSON_AddItemToArray(out, o);
}

fx_result fx_stack_required_aux_views(const fx_stack *s, char **out_json)
{
    if (!s || !out_json)
        return fx_fail(NULL, FX_ERR_INVALID_ARGUMENT, "fx_stack_required_aux_views: NULL argument");
    *out_json = NULL;
    char *text = NULL;
    fx_result r = fx_stack_to_json(s, &text);
    if (r)
        return r;
    cJSON *recipe = cJSON_Parse(text);
    fx_free(text);
    cJSON *o = cJSON_CreateObject();
    cJSON *views = o ? cJSON_AddArrayToObject(o, "aux_views") : NULL;
    const cJSON *effects = cJSON_GetObjectItemCaseSensitive(recipe, "effects");
    const cJSON *e;
    cJSON_ArrayForEach(e, effects) {
        const cJSON *name = cJSON_GetObjectItemCaseSensitive(e, "effect");
        const cJSON *en = cJSON_GetObjectItemCaseSensitive(e, "enabled");
        if (views && cJSON_IsString(name) && !cJSON_IsFalse(en))
            effect_views(name->valuestring, cJSON_GetObjectItemCaseSensitive(e, "params"), views);
    }
    char *str = views ? cJSON_PrintUnformatted(o) : NULL;
    cJSON_Delete(o);
    cJSON_Delete(recipe);
    if (str)
        *out_json = fx_json_strdup(str);
    cJSON_free(str);
    return *out_json ? FX_OK : fx_fail(NULL, FX_ERR_OUT_OF_MEMORY, "fx_stack_required_aux_views: out of memory");
}

/* ---- loading ---- */

void fx_aux_view_free(fx_aux_view *v)
{
    if (!v)
        return;
    fx_frame_free(v->frame);
    fx_mem_free(v);
}

fx_result fx_aux_view_load(const fx_frame *f, const char *name, const char *where, fx_aux_view **out)
{
    *out = NULL;
    fx_context *ctx = f->ctx;
    const char *text = fx_frame_meta(f, FX_AUX_META_KEY);
    cJSON *list = text ? cJSON_Parse(text) : NULL;
    const cJSON *found = NULL, *v;
    size_t nlen = strlen(name);
    int prefix_only = nlen > 0 && name[nlen - 1] == ':';
    char names[512] = "";
    size_t len = 0;
    cJSON_ArrayForEach(v, list) {
        const cJSON *n = cJSON_GetObjectItemCaseSensitive(v, "name");
        if (!cJSON_IsString(n))
            continue;
        if (len < sizeof names - 1)
            len += (size_t)snprintf(names + len, sizeof names - len, "%s%s", len ? ", " : "", n->valuestring);
        if (!found && (prefix_only ? strncmp(n->valuestring, name, nlen) == 0 : strcmp(n->valuestring, name) == 0))
            found = v;
    }
    if (!found) {
        cJSON_Delete(list);
        return fx_fail(ctx, FX_ERR_NO_CAMERA,
                       "%s needs the auxiliary view '%s%s', which the frame does not carry (it has: %s); the "
                       "Blender add-on renders it when the stack needs it (fx_stack_required_aux_views) and "
                       "lists it in the scene sidecar's \"aux_views\"",
                       where, name, prefix_only ? "*" : "", names[0] ? names : "none");
    }
    fx_camera cam;
    char err[256];
    if (fx_aux_views_check(ctx, list) || !view_camera(found, &cam, err, sizeof err)) {
        cJSON_Delete(list);
        return fx_fail(ctx, FX_ERR_BAD_FILE, "%s: the frame's aux view list is malformed", where);
    }
    fx_aux_view *av = fx_mem_calloc(1, sizeof *av);
    if (!av) {
        cJSON_Delete(list);
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where);
    }
    snprintf(av->name, sizeof av->name, "%s", cJSON_GetObjectItemCaseSensitive(found, "name")->valuestring);
    snprintf(av->path, sizeof av->path, "%s", cJSON_GetObjectItemCaseSensitive(found, "path")->valuestring);
    cJSON_Delete(list);
    fx_result r = fx_frame_read_exr(ctx, av->path, NULL, &av->frame);
    if (r) {
        char msg[1024];
        snprintf(msg, sizeof msg, "%s", fx_context_error(ctx));
        fx_aux_view_free(av);
        return fx_fail(ctx, r, "%s: aux view '%s': %s", where, name, msg);
    }
    fx_pass *d = fx_frame_find_pass(av->frame, "Depth");
    if (!d) {
        fx_result rr = fx_fail(ctx, FX_ERR_MISSING_PASS, "%s: aux view '%s' (%s) has no Depth pass", where,
                               av->name, av->path);
        fx_aux_view_free(av);
        return rr;
    }
    av->depth = d->data;
    av->width = av->frame->width;
    av->height = av->frame->height;
    if (fx_frame_set_camera(av->frame, &cam) || !fx_view_init(&av->view, av->frame)) {
        fx_aux_view_free(av);
        return fx_fail(ctx, FX_ERR_NO_CAMERA, "%s: aux view '%s' has a singular camera matrix", where, name);
    }
    *out = av;
    return FX_OK;
}
