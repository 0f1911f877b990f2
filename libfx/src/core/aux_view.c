/* Auxiliary views (core/aux_view.h): the sidecar's "aux_views", fx_frame_set_aux_view,
 * fx_stack_required_aux_views and loading a view's depth for an effect. */
#include "core/aux_view.h"
#include "core/effect.h"
#include "core/mem_failures.h"

#include <cjson/cJSON.h>
#include <sys/stat.h>
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

/* ---- matrices in JSON (rows, as the camera sidecar) ---- */

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

/* ---- what effects need ---- */

int fx_aux_needs_rain_map(const void *params, fx_aux_need *out, int max)
{
    (void)params;
    if (max < 1)
        return 0;
    memset(out, 0, sizeof *out);
    snprintf(out->name, sizeof out->name, "%s", FX_AUX_RAIN_MAP);
    out->kind = "rain_map";
    return 1;
}

/* ---- loading ---- */

void fx_aux_view_free(fx_aux_view *v)
{
    if (!v)
        return;
    fx_frame_free(v->frame);
    fx_mem_free(v);
}

/* The frame's entry for view `name` (see fx_aux_view_load) as unformatted JSON, and its
 * path; NULL with the error recorded when there is none. Freed with cJSON_free. */
static char *entry_text(const fx_frame *f, const char *name, const char *where, char *path, size_t path_size,
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

fx_result fx_aux_view_load(const fx_frame *f, const char *name, const char *where, fx_aux_view **out)
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
        return fx_fail(ctx, FX_ERR_NO_CAMERA,
                       "%s needs the auxiliary view '%s%s', which the frame does not carry (it has: %s); the "
                       "Blender add-on renders it when the stack needs it (fx_stack_required_aux_views) and "
                       "lists it in the scene sidecar's \"aux_views\"",
                       where, name, prefix_only ? "*" : "", names[0] ? names : "none");
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

/* ---- the cache of built maps (aux_view.h) ---- */

#define AUX_CACHE_DEFAULT_BYTES ((uint64_t)768 << 20) /* a 4096^2 light map is 192 MiB */
#define AUX_CACHE_MAX_ENTRIES 8

typedef struct aux_entry {
    char *key;
    fx_aux_view *av;
    fx_shadow_map sm;
    uint64_t bytes, last_use;
    int refs;
} aux_entry;

struct fx_aux_cache {
    uint64_t limit;
    int limit_set;
    aux_entry e[AUX_CACHE_MAX_ENTRIES];
    int n;
    uint64_t clock;
    long built, reused;
};

static void entry_free(aux_entry *e)
{
    fx_mem_free(e->key);
    fx_aux_view_free(e->av);
    fx_shadow_map_free(&e->sm);
    memset(e, 0, sizeof *e);
}

static struct fx_aux_cache *cache_of(fx_context *ctx)
{
    if (!ctx->aux_cache)
        ctx->aux_cache = fx_mem_calloc(1, sizeof *ctx->aux_cache);
    return ctx->aux_cache;
}

static uint64_t cache_limit(const fx_context *ctx)
{
    uint64_t lim = ctx->aux_cache && ctx->aux_cache->limit_set ? ctx->aux_cache->limit : AUX_CACHE_DEFAULT_BYTES;
    return lim < ctx->max_bytes ? lim : ctx->max_bytes;
}

/* Evicts unused entries, least recently used first, until `need` more bytes and one more
 * entry fit; returns 0 when they cannot. */
static int cache_make_room(fx_context *ctx, uint64_t need)
{
    struct fx_aux_cache *c = ctx->aux_cache;
    uint64_t lim = cache_limit(ctx);
    if (need > lim)
        return 0;
    for (;;) {
        uint64_t used = 0;
        int victim = -1;
        for (int i = 0; i < c->n; i++) {
            used += c->e[i].bytes;
            if (!c->e[i].refs && (victim < 0 || c->e[i].last_use < c->e[victim].last_use))
                victim = i;
        }
        if (used + need <= lim && c->n < AUX_CACHE_MAX_ENTRIES)
            return 1;
        if (victim < 0)
            return 0;
        entry_free(&c->e[victim]);
        c->e[victim] = c->e[--c->n];
        memset(&c->e[c->n], 0, sizeof c->e[c->n]);
    }
}

fx_result fx_context_set_aux_cache(fx_context *ctx, uint64_t max_bytes)
{
    if (!ctx)
        return FX_ERR_INVALID_ARGUMENT;
    struct fx_aux_cache *c = cache_of(ctx);
    if (!c)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "fx_context_set_aux_cache: out of memory");
    c->limit = max_bytes;
    c->limit_set = 1;
    for (int i = c->n - 1; i >= 0; i--)
        if (!c->e[i].refs) {
            entry_free(&c->e[i]);
            c->e[i] = c->e[--c->n];
            memset(&c->e[c->n], 0, sizeof c->e[c->n]);
        }
    return FX_OK;
}

void fx_aux_cache_free(fx_context *ctx)
{
    if (!ctx || !ctx->aux_cache)
        return;
    for (int i = 0; i < ctx->aux_cache->n; i++)
        entry_free(&ctx->aux_cache->e[i]);
    fx_mem_free(ctx->aux_cache);
    ctx->aux_cache = NULL;
}

void fx_aux_cache_stats(const fx_context *ctx, long *built, long *reused)
{
    *built = ctx && ctx->aux_cache ? ctx->aux_cache->built : 0;
    *reused = ctx && ctx->aux_cache ? ctx->aux_cache->reused : 0;
}

/* Builds the map of entry e (key already set). */
static fx_result entry_build(const fx_frame *f, const char *name, int bias, int filter, float width,
                             const char *where, aux_entry *e)
{
    fx_result r = fx_aux_view_load(f, name, where, &e->av);
    if (r)
        return r;
    fx_aux_view *av = e->av;
    r = fx_shadow_map_build(f->ctx, av->depth, av->width, av->height, av->view.cam.clip_start,
                            av->view.cam.clip_end, bias, &e->sm, where);
    if (!r && filter >= 0 && width > 1.0f)
        r = fx_shadow_map_filter(f->ctx, &e->sm, (fx_shadow_filter)filter, width, where);
    if (r)
        return r;
    /* the raw depth is in the map now: drop the EXR */
    fx_frame_free(av->frame);
    av->frame = NULL;
    av->depth = NULL;
    e->bytes = (uint64_t)av->width * av->height * 3 * sizeof(float) + sizeof *av;
    return FX_OK;
}

fx_result fx_aux_map_acquire(const fx_frame *f, const char *name, int derivative_bias, int filter, float width,
                             const char *where, fx_aux_map *out)
{
    memset(out, 0, sizeof *out);
    fx_context *ctx = f->ctx;
    char path[1024];
    fx_result r = FX_OK;
    char *entry = entry_text(f, name, where, path, sizeof path, &r);
    if (!entry)
        return r;
    struct stat st;
    char *key = NULL;
    struct fx_aux_cache *c = cache_of(ctx);
    if (c && cache_limit(ctx) > 0 && stat(path, &st) == 0) {
        char tail[160];
        if (!(filter >= 0 && width > 1.0f)) {
            filter = -1;
            width = 0.0f;
        }
        /* device + inode too: writers replace the file (temp + rename), which gives it a new
         * inode even when size and the coarse mtime clock are the same */
        int n = snprintf(tail, sizeof tail, "|%llu:%llu|%lld|%lld.%09ld|%d|%d|%.9g", (unsigned long long)st.st_dev,
                         (unsigned long long)st.st_ino, (long long)st.st_size, (long long)st.st_mtim.tv_sec,
                         (long)st.st_mtim.tv_nsec, derivative_bias ? 1 : 0, filter, (double)width);
        size_t len = strlen(entry);
        key = fx_mem_alloc(len + (size_t)n + 1);
        if (key) {
            memcpy(key, entry, len);
            memcpy(key + len, tail, (size_t)n + 1);
        }
    }
    cJSON_free(entry);
    if (key) {
        for (int i = 0; i < c->n; i++)
            if (strcmp(c->e[i].key, key) == 0) {
                c->e[i].refs++;
                c->e[i].last_use = ++c->clock;
                c->reused++;
                out->av = c->e[i].av;
                out->sm = &c->e[i].sm;
                out->cached = 1;
                fx_mem_free(key);
                return FX_OK;
            }
    }
    aux_entry tmp;
    memset(&tmp, 0, sizeof tmp);
    r = entry_build(f, name, derivative_bias, filter, width, where, &tmp);
    if (r) {
        entry_free(&tmp);
        fx_mem_free(key);
        return r;
    }
    if (c)
        c->built++;
    if (key && cache_make_room(ctx, tmp.bytes)) {
        aux_entry *e = &c->e[c->n++];
        *e = tmp;
        e->key = key;
        e->refs = 1;
        e->last_use = ++c->clock;
        out->av = e->av;
        out->sm = &e->sm;
        out->cached = 1;
        return FX_OK;
    }
    fx_mem_free(key);
    /* private: owned by the caller until release */
    aux_entry *e = fx_mem_alloc(sizeof *e);
    if (!e) {
        entry_free(&tmp);
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where);
    }
    *e = tmp;
    out->av = e->av;
    out->sm = &e->sm;
    out->cached = 0;
    return FX_OK;
}

void fx_aux_map_release(fx_context *ctx, fx_aux_map *m)
{
    if (!m || !m->sm)
        return;
    if (m->cached) {
        struct fx_aux_cache *c = ctx ? ctx->aux_cache : NULL;
        for (int i = 0; c && i < c->n; i++)
            if (&c->e[i].sm == m->sm && c->e[i].refs > 0)
                c->e[i].refs--;
    } else {
        /* the private entry: sm is its first field after key and av */
        aux_entry *e = (aux_entry *)((char *)m->sm - offsetof(aux_entry, sm));
        entry_free(e);
        fx_mem_free(e);
    }
    memset(m, 0, sizeof *m);
}
