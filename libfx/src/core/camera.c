/* Camera sidecar JSON: the matrices Blender's EXRs lack, written by the add-on. */
#include "core/internal.h"

#include <cjson/cJSON.h>
#include <errno.h>
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

fx_result fx_camera_from_json(fx_context *ctx, const char *json, fx_camera *out)
{
    if (!json || !out)
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "fx_camera_from_json: NULL argument");
    cJSON *root = cJSON_Parse(json);
    if (!root || !cJSON_IsObject(root)) {
        cJSON_Delete(root);
        return fx_fail(ctx, FX_ERR_BAD_RECIPE, "camera: not a JSON object");
    }
    fx_camera cam;
    memset(&cam, 0, sizeof cam);
    cam.size = sizeof cam;
    fx_result r = FX_OK;
    const cJSON *w2c = cJSON_GetObjectItemCaseSensitive(root, "world_to_camera");
    const cJSON *proj = cJSON_GetObjectItemCaseSensitive(root, "projection");
    const cJSON *cs = cJSON_GetObjectItemCaseSensitive(root, "clip_start");
    const cJSON *ce = cJSON_GetObjectItemCaseSensitive(root, "clip_end");
    if (!read_matrix(w2c, cam.world_to_camera))
        r = fx_fail(ctx, FX_ERR_BAD_RECIPE, "camera: \"world_to_camera\" must be a 4x4 matrix (4 rows of 4 finite numbers)");
    else if (!read_matrix(proj, cam.projection))
        r = fx_fail(ctx, FX_ERR_BAD_RECIPE, "camera: \"projection\" must be a 4x4 matrix (4 rows of 4 finite numbers)");
    else if (!cJSON_IsNumber(cs) || !cJSON_IsNumber(ce) || !(cs->valuedouble > 0) ||
             !(ce->valuedouble > cs->valuedouble) || !isfinite(ce->valuedouble))
        r = fx_fail(ctx, FX_ERR_BAD_RECIPE, "camera: needs 0 < \"clip_start\" < \"clip_end\"");
    if (!r) {
        cam.clip_start = (float)cs->valuedouble;
        cam.clip_end = (float)ce->valuedouble;
        /* OpenGL projections: perspective has -1 in the last row's z, orthographic 1 in w. */
        cam.orthographic = cam.projection[15] == 1.0f && cam.projection[14] == 0.0f;
        const cJSON *ortho = cJSON_GetObjectItemCaseSensitive(root, "orthographic");
        if (cJSON_IsBool(ortho))
            cam.orthographic = cJSON_IsTrue(ortho);
        *out = cam;
    }
    cJSON_Delete(root);
    return r;
}

fx_result fx_camera_load_file(fx_context *ctx, const char *path, fx_camera *out)
{
    if (!path)
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "fx_camera_load_file: path is NULL");
    FILE *fp = fopen(path, "rb");
    if (!fp)
        return fx_fail(ctx, FX_ERR_IO, "cannot open camera file '%s': %s", path, strerror(errno));
    char buf[65536];
    size_t n = fread(buf, 1, sizeof buf - 1, fp);
    int too_big = !feof(fp);
    fclose(fp);
    if (too_big)
        return fx_fail(ctx, FX_ERR_BAD_RECIPE, "camera file '%s' is larger than 64 KiB", path);
    buf[n] = '\0';
    fx_result r = fx_camera_from_json(ctx, buf, out);
    if (r) {
        char msg[1024];
        snprintf(msg, sizeof msg, "%s", fx_context_error(ctx));
        fx_fail(ctx, r, "%s: %s", path, msg);
    }
    return r;
}
