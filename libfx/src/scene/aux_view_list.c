/* The frame's list of aux views: checking a sidecar's "aux_views" and merging it into the
 * frame's metadata (scene/aux_view.h). */
#include "core/context.h"
#include "core/frame.h"
#include "scene/aux_view.h"
#include "scene/camera_json.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <string.h>

static const char *const view_keys[] = {"name", "path", "world_to_camera", "projection",
                                        "clip_start", "clip_end", "orthographic", "kind", "signature", "panorama", "mask", "plane",
                                        "absent", "window"};

fx_result fx_aux_views_check(fx_context *ctx, const cJSON *list)
{
    if (!cJSON_IsArray(list))
        return fx_fail(ctx, FX_ERR_BAD_RECIPE, "sidecar: \"aux_views\" must be a list");
    int i = 0;
    const cJSON *v;
    cJSON_ArrayForEach(v, list) {
        const cJSON *name = cJSON_GetObjectItemCaseSensitive(v, "name");
        const cJSON *path = cJSON_GetObjectItemCaseSensitive(v, "path");
        const cJSON *absent = cJSON_GetObjectItemCaseSensitive(v, "absent");
        /* "absent": a view the add-on was asked for and did not render, and why (a planar
         * view of a mirror that is not flat): a name and that reason, nothing else */
        if (cJSON_IsObject(v) && cJSON_IsString(name) && name->valuestring[0] &&
            strlen(name->valuestring) < FX_NAME_MAX && absent) {
            if (!cJSON_IsString(absent) || !absent->valuestring[0] || cJSON_GetArraySize(v) != 2)
                return fx_fail(ctx, FX_ERR_BAD_RECIPE,
                               "sidecar: aux_views[%d] ('%s'): an \"absent\" view has its name and the reason "
                               "(a non-empty string) only",
                               i, name->valuestring);
            i++;
            continue;
        }
        if (!cJSON_IsObject(v) || !cJSON_IsString(name) || !name->valuestring[0] ||
            strlen(name->valuestring) >= FX_NAME_MAX || !cJSON_IsString(path) || !path->valuestring[0] ||
            strlen(path->valuestring) >= 1024)
            return fx_fail(ctx, FX_ERR_BAD_RECIPE,
                           "sidecar: aux_views[%d] needs a \"name\" (< %d bytes) and a \"path\" (an EXR with a Depth pass), "
                           "or the \"absent\" reason",
                           i, FX_NAME_MAX);
        const cJSON *item;
        cJSON_ArrayForEach(item, v) {
            int known = 0;
            for (size_t k = 0; k < sizeof view_keys / sizeof view_keys[0]; k++)
                known |= strcmp(item->string, view_keys[k]) == 0;
            if (!known)
                return fx_fail(ctx, FX_ERR_BAD_RECIPE,
                               "sidecar: aux_views[%d] ('%s'): unknown key \"%s\" (known: name, path, world_to_camera, "
                               "projection, clip_start, clip_end, orthographic, kind, signature, panorama, mask, plane, absent, window)",
                               i, name->valuestring, item->string);
        }
        const cJSON *pano = cJSON_GetObjectItemCaseSensitive(v, "panorama");
        if (pano && !(cJSON_IsString(pano) && strcmp(pano->valuestring, "equirect") == 0))
            return fx_fail(ctx, FX_ERR_BAD_RECIPE,
                           "sidecar: aux_views[%d] ('%s'): \"panorama\" must be \"equirect\" (the only kind)", i,
                           name->valuestring);
        const cJSON *plane = cJSON_GetObjectItemCaseSensitive(v, "plane");
        int plane_ok = !plane || (cJSON_IsArray(plane) && cJSON_GetArraySize(plane) == 4);
        for (int k = 0; plane && plane_ok && k < 4; k++)
            plane_ok = cJSON_IsNumber(cJSON_GetArrayItem(plane, k)) &&
                       isfinite(cJSON_GetArrayItem(plane, k)->valuedouble);
        if (!plane_ok)
            return fx_fail(ctx, FX_ERR_BAD_RECIPE,
                           "sidecar: aux_views[%d] ('%s'): \"plane\" must be 4 finite numbers [nx, ny, nz, d] "
                           "(the world plane n . x = d)", i, name->valuestring);
        const cJSON *win = cJSON_GetObjectItemCaseSensitive(v, "window");
        int win_ok = !win || (cJSON_IsArray(win) && cJSON_GetArraySize(win) == 4);
        for (int k = 0; win && win_ok && k < 4; k++) {
            const cJSON *e = cJSON_GetArrayItem(win, k);
            /* the range first: (int) of a double out of range is undefined */
            win_ok = cJSON_IsNumber(e) && e->valuedouble >= (k < 2 ? 0 : 1) && e->valuedouble <= 1048576 &&
                     floor(e->valuedouble) == e->valuedouble;
        }
        if (!win_ok)
            return fx_fail(ctx, FX_ERR_BAD_RECIPE,
                           "sidecar: aux_views[%d] ('%s'): \"window\" must be 4 whole numbers [x0, y0, width, height] "
                           "(x0, y0 >= 0: where the file's pixels sit in a width x height view)",
                           i, name->valuestring);
        fx_camera cam;
        char err[256];
        if (!fx_camera_parse(v, 1, &cam, err, sizeof err))
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

