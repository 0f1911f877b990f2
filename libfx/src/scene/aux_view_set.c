/* fx_frame_set_aux_view: one aux view given from C instead of the sidecar. */
#include "core/context.h"
#include "core/frame.h"
#include "scene/aux_view.h"

#include <cjson/cJSON.h>

/* Matrices as rows, as the sidecar has them. */
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

