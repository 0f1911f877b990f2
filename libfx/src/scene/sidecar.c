/* The scene sidecar: the JSON the add-on writes beside each render with what Blender's
 * EXRs lack (camera matrices, lights, scene time, aux views), checked whole, then applied
 * to a frame. */
#include "core/context.h"
#include "core/frame.h"
#include "core/json_keys.h"
#include "core/mem.h"
#include "core/mem_failures.h"
#include "core/textfile.h"
#include "scene/aux_view.h"
#include "scene/camera_json.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

static const char *const sidecar_keys[] = {"world_to_camera", "projection", "clip_start", "clip_end",
                                            "orthographic", "lights", "frame", "fps", "scene", "camera",
                                            "aux_views"};

static fx_result check_vec(fx_context *ctx, const cJSON *light, const char *key, int n, int i)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(light, key);
    if (!v)
        return FX_OK;
    int ok = cJSON_IsArray(v) && cJSON_GetArraySize(v) == n;
    const cJSON *x;
    cJSON_ArrayForEach(x, v) ok = ok && cJSON_IsNumber(x) && isfinite(x->valuedouble);
    if (!ok)
        return fx_fail(ctx, FX_ERR_BAD_RECIPE, "sidecar: lights[%d].%s must be %d finite numbers", i, key, n);
    return FX_OK;
}

/* Checks the lights array now, so effects can trust its shape later. */
static fx_result check_lights(fx_context *ctx, const cJSON *lights)
{
    if (!cJSON_IsArray(lights))
        return fx_fail(ctx, FX_ERR_BAD_RECIPE, "sidecar: \"lights\" must be a list");
    int i = 0;
    const cJSON *l;
    cJSON_ArrayForEach(l, lights) {
        const cJSON *name = cJSON_GetObjectItemCaseSensitive(l, "name");
        const cJSON *type = cJSON_GetObjectItemCaseSensitive(l, "type");
        if (!cJSON_IsObject(l) || !cJSON_IsString(name) || !cJSON_IsString(type))
            return fx_fail(ctx, FX_ERR_BAD_RECIPE, "sidecar: lights[%d] needs a \"name\" and a \"type\"", i);
        fx_result r;
        if ((r = check_vec(ctx, l, "position", 3, i)) || (r = check_vec(ctx, l, "direction", 3, i)) ||
            (r = check_vec(ctx, l, "color", 3, i)))
            return r;
        i++;
    }
    return FX_OK;
}

fx_result fx_frame_apply_sidecar(fx_frame *f, const char *json)
{
    if (!f || !json)
        return fx_fail(f ? f->ctx : NULL, FX_ERR_INVALID_ARGUMENT, "fx_frame_apply_sidecar: NULL argument");
    fx_context *ctx = f->ctx;
    unsigned long failures = fx_mem_failure_count();
    cJSON *root = cJSON_Parse(json);
    if (!root && fx_mem_failure_count() != failures)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "sidecar: out of memory parsing the JSON");
    if (!root || !cJSON_IsObject(root)) {
        cJSON_Delete(root);
        return fx_fail(ctx, FX_ERR_BAD_RECIPE, "sidecar: not a JSON object");
    }
    fx_result r = fx_json_check_unique_keys(ctx, root, "sidecar");
    const cJSON *item;
    cJSON_ArrayForEach(item, root) {
        if (r)
            break;
        int known = 0;
        for (size_t k = 0; k < sizeof sidecar_keys / sizeof sidecar_keys[0]; k++)
            known |= strcmp(item->string, sidecar_keys[k]) == 0;
        if (!known) {
            r = fx_fail(ctx, FX_ERR_BAD_RECIPE,
                        "sidecar: unknown key \"%s\" (known: world_to_camera, projection, clip_start, "
                        "clip_end, orthographic, lights, frame, fps, scene, camera, aux_views)",
                        item->string);
            break;
        }
    }
    fx_camera cam;
    int has_camera = cJSON_GetObjectItemCaseSensitive(root, "world_to_camera") != NULL;
    if (!r && has_camera)
        r = fx_camera_from_json(ctx, json, &cam);
    const cJSON *lights = cJSON_GetObjectItemCaseSensitive(root, "lights");
    if (!r && lights)
        r = check_lights(ctx, lights);
    const cJSON *frame = cJSON_GetObjectItemCaseSensitive(root, "frame");
    const cJSON *fps = cJSON_GetObjectItemCaseSensitive(root, "fps");
    if (!r && ((frame && (!cJSON_IsNumber(frame) || !isfinite(frame->valuedouble))) ||
               (fps && (!cJSON_IsNumber(fps) || !(fps->valuedouble > 0)))))
        r = fx_fail(ctx, FX_ERR_BAD_RECIPE, "sidecar: \"frame\" must be a number and \"fps\" positive");
    const cJSON *aux = cJSON_GetObjectItemCaseSensitive(root, "aux_views");
    if (!r && aux)
        r = fx_aux_views_check(ctx, aux);
    char *lights_text = NULL;
    if (!r && lights && !(lights_text = cJSON_PrintUnformatted(lights)))
        r = fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "sidecar: out of memory");
    /* Everything checked: apply it all. */
    if (!r && has_camera)
        r = fx_frame_set_camera(f, &cam);
    if (!r && lights_text)
        r = fx_frame_set_meta(f, "libfx:lights", lights_text);
    if (!r && aux)
        r = fx_aux_views_apply(f, aux);
    if (!r && (frame || fps))
        fx_frame_set_time(f, frame ? frame->valuedouble : f->frame_number, fps ? fps->valuedouble : f->fps);
    cJSON_free(lights_text);
    cJSON_Delete(root);
    return r;
}

fx_result fx_frame_apply_sidecar_file(fx_frame *f, const char *path)
{
    if (!f || !path)
        return fx_fail(f ? f->ctx : NULL, FX_ERR_INVALID_ARGUMENT, "fx_frame_apply_sidecar_file: NULL argument");
    char *text = NULL;
    fx_result r = fx_read_text_file(f->ctx, path, (size_t)4 << 20, "sidecar", &text);
    if (r)
        return r;
    r = fx_frame_apply_sidecar(f, text);
    if (r)
        fx_fail_prefix(f->ctx, r, path);
    fx_mem_free(text);
    return r;
}
