/* fx_exr_info_json: a header summary, decoding no pixels. */
#include "core/context.h"
#include "core/mem.h"
#include "io/exr_common.h"

#include <cjson/cJSON.h>
#include <stdlib.h>
#include <string.h>

#define FX_INFO_MAX_NAMES 50

static cJSON *box_json(const int b[4])
{
    cJSON *a = cJSON_CreateArray();
    for (int i = 0; a && i < 4; i++)
        cJSON_AddItemToArray(a, cJSON_CreateNumber(b[i]));
    return a;
}

static const char *type_name(int t)
{
    return t == EXR_PIXEL_UINT ? "uint" : t == EXR_PIXEL_HALF ? "half" : t == EXR_PIXEL_FLOAT ? "float" : "unknown";
}

static int has_m44f(const fx_exr_file *f, const char *name)
{
    const exr_attribute_t *a = NULL;
    return exr_get_attribute_by_name(f->exr, 0, name, &a) == EXR_ERR_SUCCESS && a && a->type == EXR_ATTR_M44F;
}

static cJSON *crypto_json(const fx_exr_crypto *c)
{
    cJSON *o = cJSON_CreateObject();
    if (!o)
        return NULL;
    cJSON_AddStringToObject(o, "name", c->name);
    cJSON_AddStringToObject(o, "type", c->type);
    cJSON *names = cJSON_AddArrayToObject(o, "names");
    int entries = 0;
    cJSON *m = c->manifest ? cJSON_Parse(c->manifest) : NULL;
    if (cJSON_IsObject(m)) {
        for (cJSON *e = m->child; e; e = e->next) {
            if (entries < FX_INFO_MAX_NAMES && e->string)
                cJSON_AddItemToArray(names, cJSON_CreateString(e->string));
            entries++;
        }
    }
    cJSON_Delete(m);
    cJSON_AddNumberToObject(o, "manifest_entries", entries);
    if (c->manif_file[0])
        cJSON_AddStringToObject(o, "manifest_file", c->manif_file);
    return o;
}

static cJSON *build(fx_exr_file *f)
{
    cJSON *root = cJSON_CreateObject();
    if (!root)
        return NULL;
    cJSON_AddStringToObject(root, "file", f->path);
    const fx_exr_part *p0 = &f->parts[0];
    cJSON_AddNumberToObject(root, "width", (double)p0->dw[2] - p0->dw[0] + 1);
    cJSON_AddNumberToObject(root, "height", (double)p0->dw[3] - p0->dw[1] + 1);
    cJSON_AddItemToObject(root, "data_window", box_json(p0->dw));
    cJSON_AddItemToObject(root, "display_window", box_json(p0->disp));
    cJSON_AddStringToObject(root, "compression", fx_exr_compression_name(p0->compression));
    int tiled = 0;
    for (int p = 0; p < f->part_count; p++)
        tiled |= f->parts[p].storage == EXR_STORAGE_TILED;
    cJSON_AddBoolToObject(root, "tiled", tiled);
    cJSON_AddBoolToObject(root, "multipart", f->part_count > 1);

    cJSON *parts = cJSON_AddArrayToObject(root, "parts");
    for (int p = 0; p < f->part_count; p++) {
        const fx_exr_part *pt = &f->parts[p];
        cJSON *o = cJSON_CreateObject();
        cJSON_AddItemToArray(parts, o);
        if (pt->name)
            cJSON_AddStringToObject(o, "name", pt->name);
        else
            cJSON_AddNullToObject(o, "name");
        if (pt->view)
            cJSON_AddStringToObject(o, "view", pt->view);
        cJSON_AddStringToObject(o, "storage", pt->storage == EXR_STORAGE_TILED ? "tiled" : "scanline");
        cJSON_AddStringToObject(o, "compression", fx_exr_compression_name(pt->compression));
        cJSON_AddItemToObject(o, "data_window", box_json(pt->dw));
        cJSON_AddItemToObject(o, "display_window", box_json(pt->disp));
        cJSON_AddNumberToObject(o, "channels", pt->channel_count);
    }

    cJSON *views = cJSON_AddArrayToObject(root, "views");
    for (int i = 0; i < f->view_count; i++)
        cJSON_AddItemToArray(views, cJSON_CreateString(f->views[i]));

    const char *layers[256];
    int nl = fx_exr_layers(f->chans, f->chan_count, layers, 256);
    cJSON *jl = cJSON_AddArrayToObject(root, "layers");
    for (int i = 0; i < nl; i++)
        cJSON_AddItemToArray(jl, cJSON_CreateString(layers[i]));

    /* passes: channels grouped by (layer, pass, view), in file order */
    cJSON *passes = cJSON_AddArrayToObject(root, "passes");
    char *done = calloc((size_t)f->chan_count + 1, 1);
    for (int i = 0; done && i < f->chan_count; i++) {
        if (done[i])
            continue;
        const fx_exr_chan *c = &f->chans[i];
        cJSON *o = cJSON_CreateObject();
        cJSON_AddItemToArray(passes, o);
        cJSON_AddStringToObject(o, "layer", c->layer);
        cJSON_AddStringToObject(o, "pass", c->pass);
        cJSON_AddStringToObject(o, "view", c->view);
        cJSON *chs = cJSON_AddArrayToObject(o, "channels");
        for (int j = i; j < f->chan_count; j++) {
            const fx_exr_chan *d = &f->chans[j];
            if (done[j] || strcmp(d->layer, c->layer) || strcmp(d->pass, c->pass) || strcmp(d->view, c->view))
                continue;
            done[j] = 1;
            cJSON *ch = cJSON_CreateObject();
            cJSON_AddStringToObject(ch, "name", d->full);
            cJSON_AddStringToObject(ch, "type", type_name(d->type));
            cJSON_AddItemToArray(chs, ch);
        }
    }
    free(done);

    cJSON_AddBoolToObject(root, "camera", has_m44f(f, "worldToCamera") && has_m44f(f, "worldToNDC"));
    cJSON *cr = cJSON_AddArrayToObject(root, "cryptomatte");
    for (int k = 0; k < f->crypto_count; k++)
        cJSON_AddItemToArray(cr, crypto_json(&f->cryptos[k]));

    const exr_attribute_t *a = NULL;
    if (exr_get_attribute_by_name(f->exr, 0, "libfx:frame", &a) == EXR_ERR_SUCCESS && a && a->type == EXR_ATTR_DOUBLE)
        cJSON_AddNumberToObject(root, "frame", a->d);
    else if (fx_exr_string_attr(f, 0, "Frame"))
        cJSON_AddNumberToObject(root, "frame", strtod(fx_exr_string_attr(f, 0, "Frame"), NULL));
    else
        cJSON_AddNullToObject(root, "frame");
    return root;
}

fx_result fx_exr_info_json(fx_context *ctx, const char *path, char **out_json)
{
    if (out_json)
        *out_json = NULL;
    if (!ctx || !path || !out_json)
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "fx_exr_info_json: ctx, path and out_json must not be NULL");
    fx_exr_file f;
    fx_result r = fx_exr_file_open(ctx, path, &f);
    if (r != FX_OK)
        return r;
    cJSON *root = build(&f);
    fx_exr_file_close(&f);
    char *text = root ? cJSON_PrintUnformatted(root) : NULL;
    cJSON_Delete(root);
    if (!text)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "'%s': out of memory building the header summary", path);
    *out_json = fx_json_strdup(text);
    cJSON_free(text);
    if (!*out_json)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "'%s': out of memory building the header summary", path);
    return FX_OK;
}
