/* Loading an aux view for an effect: the frame's entry for it, its EXR's Depth pass and
 * its camera (scene/aux_view.h). */
#include "core/context.h"
#include "core/frame.h"
#include "core/mem.h"
#include "core/mem_failures.h"
#include "core/parallel.h"
#include "core/simd4.h"
#include "io/exr_read.h"
#include "io/exr_rows.h"
#include "scene/aux_view.h"
#include "scene/camera_json.h"

#include <cjson/cJSON.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

typedef struct half_range_job {
    float *data;
    size_t row; /* floats per row */
} half_range_job;

/* Non-finite values to 0, the rest clamped to +-65504 (the half-float range). */
static void half_range_rows(void *user, int begin, int end)
{
    const half_range_job *j = user;
    float *q = j->data + (size_t)begin * j->row, *e = j->data + (size_t)end * j->row;
    for (; q + 4 <= e; q += 4) {
        v4f v = ld4(q);
        v4f a = (v4f)((v4i)v & ~(v4i)V4(-0.0f)); /* |v| <= FLT_MAX: false for NaN and +-Inf */
        v = (v4f)((v4i)v & (a <= V4(FLT_MAX)));
        st4(q, max4(min4(v, V4(65504.0f)), V4(-65504.0f)));
    }
    for (; q < e; q++)
        *q = !isfinite(*q) ? 0.0f : *q > 65504.0f ? 65504.0f : *q < -65504.0f ? -65504.0f : *q;
}

void fx_aux_view_free(fx_aux_view *v)
{
    if (!v)
        return;
    fx_frame_free(v->frame);
    fx_mem_free(v);
}

char *fx_aux_view_entry(const fx_frame *f, const char *name, const char *where, char *path, size_t path_size,
                        fx_result *res)
{
    fx_context *ctx = f->ctx;
    const char *text = fx_frame_meta(f, FX_AUX_META_KEY);
    unsigned long failures = fx_mem_failure_count();
    cJSON *list = text ? cJSON_Parse(text) : NULL;
    if (text && !list && fx_mem_failure_count() != failures) {
        *res = fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory reading the frame's aux views", where);
        return NULL;
    }
    const cJSON *found = NULL, *v;
    size_t nlen = strlen(name);
    int prefix_only = nlen > 0 && name[nlen - 1] == ':';
    cJSON_ArrayForEach(v, list) {
        const cJSON *n = cJSON_GetObjectItemCaseSensitive(v, "name");
        if (!found && cJSON_IsString(n) &&
            (prefix_only ? strncmp(n->valuestring, name, nlen) == 0 : strcmp(n->valuestring, name) == 0))
            found = v;
    }
    const cJSON *p = found ? cJSON_GetObjectItemCaseSensitive(found, "path") : NULL;
    char *out = cJSON_IsString(p) ? cJSON_PrintUnformatted(found) : NULL;
    if (out)
        snprintf(path, path_size, "%s", p->valuestring);
    cJSON_Delete(list);
    if (!out && cJSON_IsString(p)) {
        *res = fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory reading the frame's aux views", where);
        return NULL;
    }
    if (!out) {
        /* fx_aux_view_load words the error (missing view, malformed list) */
        fx_aux_view *av = NULL;
        *res = fx_aux_view_load(f, name, where, &av);
        fx_aux_view_free(av);
        if (!*res)
            *res = fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where);
    }
    return out;
}

int fx_aux_view_has(const fx_frame *f, const char *name)
{
    const char *text = fx_frame_meta(f, FX_AUX_META_KEY);
    unsigned long failures = fx_mem_failure_count();
    cJSON *list = text ? cJSON_Parse(text) : NULL;
    if (text && !list && fx_mem_failure_count() != failures)
        return -1;
    int found = 0;
    const cJSON *v;
    cJSON_ArrayForEach(v, list) {
        const cJSON *n = cJSON_GetObjectItemCaseSensitive(v, "name");
        if (!found && cJSON_IsString(n) && strcmp(n->valuestring, name) == 0)
            found = cJSON_GetObjectItemCaseSensitive(v, "absent") ? FX_AUX_ABSENT : FX_AUX_LISTED;
    }
    cJSON_Delete(list);
    return found;
}

/* The view's EXR read whole: its Depth pass, and a probe's colour and sky made finite.
 * On failure the caller frees av. */
static fx_result read_whole(fx_context *ctx, fx_aux_view *av, const char *name, const char *where)
{
    fx_result r = fx_exr_read(ctx, av->path, NULL, &av->frame);
    if (r) {
        char msg[1024];
        snprintf(msg, sizeof msg, "%s", fx_context_error(ctx));
        return fx_fail(ctx, r, "%s: aux view '%s': %s", where, name, msg);
    }
    fx_pass *d = fx_frame_find_pass(av->frame, "Depth");
    if (!d) {
        return fx_fail(ctx, FX_ERR_MISSING_PASS, "%s: aux view '%s' (%s) has no Depth pass", where, av->name,
                       av->path);
    }
    av->depth = d->data;
    av->width = av->frame->width;
    av->height = av->frame->height;
    /* the colour (probes reflect it): finite and within half-float range (the reader
     * turns +-Inf into +-FLT_MAX, which a blend would overflow) */
    fx_pass *c = fx_frame_find_pass(av->frame, "Combined");
    if (c && c->channels == 4) {
        /* a probe's colour is read whole before the first mirror pixel can use it: on
         * the context's threads, four floats at a time */
        fx_parallel_for(ctx, av->height, 16, half_range_rows, &(half_range_job){ c->data, (size_t)av->width * 4 });
        av->color = c->data;
    } else if (av->panorama) {
        return fx_fail(ctx, FX_ERR_MISSING_PASS, "%s: probe '%s' (%s) has no RGBA colour (Combined/Image) pass",
                       where, av->name, av->path);
    }
    fx_pass *sk = av->panorama ? fx_frame_find_pass(av->frame, "Sky") : NULL;
    if (sk && sk->channels == 4) {
        fx_parallel_for(ctx, av->height, 16, half_range_rows, &(half_range_job){ sk->data, (size_t)av->width * 4 });
        av->sky = sk->data;
    }
    return FX_OK;
}

/* A view rendered cropped to a region ("window": [x0, y0, W, H]: its pixels are columns
 * x0.. and rows y0.. (top down) of a W x H view, a planar view over its mirror's region):
 * the file's pixels become the data window inside that display window, so the camera maps
 * world points to the file's pixels (math/camera.h). */
static fx_result place_window(fx_context *ctx, fx_aux_view *av, const int window[4], const char *name,
                              const char *where)
{
    const int *dw = av->frame->data_window, *dp = av->frame->display_window;
    const int w = av->width, h = av->height;
    if (dw[0] != dp[0] || dw[1] != dp[1] || dw[2] != dp[2] || dw[3] != dp[3] || window[0] + w > window[2] ||
        window[1] + h > window[3])
        return fx_fail(ctx, FX_ERR_BAD_FILE,
                       "%s: aux view '%s' (%s): its %dx%d pixels at (%d, %d) do not fit its \"window\" of %dx%d", where,
                       name, av->path, w, h, window[0], window[1], window[2], window[3]);
    const int data[4] = { window[0], window[1], window[0] + w - 1, window[1] + h - 1 };
    const int display[4] = { 0, 0, window[2] - 1, window[3] - 1 };
    return fx_frame_set_windows(av->frame, data, display);
}

/* fx_aux_view_load; with rows (a light view's map built row by row), the Depth pass is
 * opened to stream when the file allows it (*rows set, the view's frame without passes). */
static fx_result load(const fx_frame *f, const char *name, const char *where, fx_aux_view **out,
                      fx_exr_rows **rows)
{
    *out = NULL;
    fx_context *ctx = f->ctx;
    const char *text = fx_frame_meta(f, FX_AUX_META_KEY);
    unsigned long failures = fx_mem_failure_count();
    cJSON *list = text ? cJSON_Parse(text) : NULL;
    if (text && !list && fx_mem_failure_count() != failures)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory reading the frame's aux views", where);
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
        return fx_fail(ctx, FX_ERR_NO_AUX_VIEW,
                       "%s needs the auxiliary view '%s%s', which the frame does not carry (it has: %s); the "
                       "Blender add-on renders it when the stack needs it (fx_stack_required_aux_views) and "
                       "lists it in the scene sidecar's \"aux_views\"",
                       where, name, prefix_only ? "*" : "", names[0] ? names : "none");
    }
    const cJSON *absent = cJSON_GetObjectItemCaseSensitive(found, "absent");
    if (cJSON_IsString(absent)) {
        fx_result r = fx_fail(ctx, FX_ERR_NO_AUX_VIEW, "%s needs the auxiliary view '%s', which was not rendered: %s",
                              where, cJSON_GetObjectItemCaseSensitive(found, "name")->valuestring,
                              absent->valuestring);
        cJSON_Delete(list);
        return r;
    }
    fx_camera cam;
    char err[256];
    if (fx_aux_views_check(ctx, list) || !fx_camera_parse(found, 1, &cam, err, sizeof err)) {
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
    av->panorama = cJSON_IsString(cJSON_GetObjectItemCaseSensitive(found, "panorama"));
    const cJSON *plane = cJSON_GetObjectItemCaseSensitive(found, "plane");
    if (cJSON_IsArray(plane) && cJSON_GetArraySize(plane) == 4) {
        for (int k = 0; k < 4; k++)
            av->plane[k] = (float)cJSON_GetArrayItem(plane, k)->valuedouble;
        float n = sqrtf(av->plane[0] * av->plane[0] + av->plane[1] * av->plane[1] + av->plane[2] * av->plane[2]);
        av->has_plane = n > 1e-6f && isfinite(n);
        for (int k = 0; av->has_plane && k < 4; k++)
            av->plane[k] /= n;
    }
    int window[4] = { 0, 0, 0, 0 }; /* "window": [x0, y0, W, H], or W 0 */
    const cJSON *win = cJSON_GetObjectItemCaseSensitive(found, "window");
    for (int k = 0; cJSON_IsArray(win) && k < 4; k++)
        window[k] = (int)cJSON_GetArrayItem(win, k)->valuedouble;
    cJSON_Delete(list);
    fx_result r = FX_OK;
    if (rows && !av->panorama) {
        fx_exr_rows_info info;
        r = fx_exr_rows_open(ctx, av->path, "Depth", rows, &info);
        if (!r && *rows) {
            r = fx_frame_new(ctx, info.width, info.height, &av->frame);
            if (!r)
                r = fx_frame_set_windows(av->frame, info.data_window, info.display_window);
            if (r) {
                fx_exr_rows_close(*rows);
                *rows = NULL;
                fx_aux_view_free(av);
                return r;
            }
            av->width = info.width;
            av->height = info.height;
        }
    }
    if (r) {
        char msg[1024];
        snprintf(msg, sizeof msg, "%s", fx_context_error(ctx));
        r = fx_fail(ctx, r, "%s: aux view '%s': %s", where, name, msg);
    } else if (!rows || !*rows) {
        r = read_whole(ctx, av, name, where);
    }
    if (!r && window[2] > 0)
        r = place_window(ctx, av, window, name, where);
    if (r) {
        if (rows && *rows) {
            fx_exr_rows_close(*rows);
            *rows = NULL;
        }
        fx_aux_view_free(av);
        return r;
    }
    if (fx_frame_set_camera(av->frame, &cam) || !fx_view_init(&av->view, av->frame)) {
        if (rows) {
            fx_exr_rows_close(*rows);
            *rows = NULL;
        }
        fx_aux_view_free(av);
        return fx_fail(ctx, FX_ERR_NO_CAMERA, "%s: aux view '%s' has a singular camera matrix", where, name);
    }
    *out = av;
    return FX_OK;
}

fx_result fx_aux_view_load(const fx_frame *f, const char *name, const char *where, fx_aux_view **out)
{
    return load(f, name, where, out, NULL);
}

fx_result fx_aux_view_open_rows(const fx_frame *f, const char *name, const char *where, fx_aux_view **out,
                                fx_exr_rows **rows)
{
    *rows = NULL;
    return load(f, name, where, out, rows);
}

