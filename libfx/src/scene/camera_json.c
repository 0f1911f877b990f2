/* Cameras in JSON: the sidecar's camera and each aux view's (scene/camera_json.h). */
#include "core/context.h"
#include "core/mem_failures.h"
#include "scene/camera_json.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

static int read_matrix(const cJSON *v, float out[16])
{
    /* 4 rows of 4, or 16 numbers row by row */
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

int fx_camera_parse(const cJSON *obj, int zero_clip_start_ok, fx_camera *cam, char *err, size_t err_size)
{
    memset(cam, 0, sizeof *cam);
    cam->size = sizeof *cam;
    const cJSON *cs = cJSON_GetObjectItemCaseSensitive(obj, "clip_start");
    const cJSON *ce = cJSON_GetObjectItemCaseSensitive(obj, "clip_end");
    if (!read_matrix(cJSON_GetObjectItemCaseSensitive(obj, "world_to_camera"), cam->world_to_camera)) {
        snprintf(err, err_size, "\"world_to_camera\" must be a 4x4 matrix (4 rows of 4 finite numbers)");
        return 0;
    }
    if (!read_matrix(cJSON_GetObjectItemCaseSensitive(obj, "projection"), cam->projection)) {
        snprintf(err, err_size, "\"projection\" must be a 4x4 matrix (4 rows of 4 finite numbers)");
        return 0;
    }
    if (!cJSON_IsNumber(cs) || !cJSON_IsNumber(ce) ||
        !(zero_clip_start_ok ? cs->valuedouble >= 0 : cs->valuedouble > 0) ||
        !(ce->valuedouble > cs->valuedouble) || !isfinite(ce->valuedouble)) {
        snprintf(err, err_size, "needs %s \"clip_start\" < \"clip_end\" (finite)", zero_clip_start_ok ? "0 <=" : "0 <");
        return 0;
    }
    cam->clip_start = (float)cs->valuedouble;
    cam->clip_end = (float)ce->valuedouble;
    /* OpenGL projections: perspective has -1 in the last row's z, orthographic 1 in w. */
    cam->orthographic = cam->projection[15] == 1.0f && cam->projection[14] == 0.0f;
    const cJSON *o = cJSON_GetObjectItemCaseSensitive(obj, "orthographic");
    if (cJSON_IsBool(o))
        cam->orthographic = cJSON_IsTrue(o);
    return 1;
}

fx_result fx_camera_from_json(fx_context *ctx, const char *json, fx_camera *out)
{
    if (!json || !out)
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "fx_camera_from_json: NULL argument");
    unsigned long failures = fx_mem_failure_count();
    cJSON *root = cJSON_Parse(json);
    if (!root && fx_mem_failure_count() != failures)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "camera: out of memory parsing the JSON");
    if (!root || !cJSON_IsObject(root)) {
        cJSON_Delete(root);
        return fx_fail(ctx, FX_ERR_BAD_RECIPE, "camera: not a JSON object");
    }
    fx_camera cam;
    char err[256];
    fx_result r = FX_OK;
    if (!fx_camera_parse(root, 0, &cam, err, sizeof err))
        r = fx_fail(ctx, FX_ERR_BAD_RECIPE, "camera: %s", err);
    else
        *out = cam;
    cJSON_Delete(root);
    return r;
}
