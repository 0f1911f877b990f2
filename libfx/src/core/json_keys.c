#include "core/json_keys.h"

#include "core/context.h"
#include "core/mem.h"

#include <stdlib.h>
#include <string.h>

static int cmp_key(const void *a, const void *b)
{
    return strcmp(*(const char *const *)a, *(const char *const *)b);
}

/* Sorting keeps a hostile object with many keys at n log n. */
static fx_result check_object(const fx_context *ctx, const cJSON *obj, const char *what)
{
    int n = cJSON_GetArraySize(obj);
    if (n < 2)
        return FX_OK;
    const char **keys = fx_mem_calloc((size_t)n, sizeof *keys);
    if (!keys)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory checking keys", what);
    int i = 0;
    for (const cJSON *c = obj->child; c && i < n; c = c->next)
        keys[i++] = c->string ? c->string : "";
    qsort(keys, (size_t)i, sizeof *keys, cmp_key);
    const char *dup = NULL;
    for (int k = 1; k < i && !dup; k++)
        if (strcmp(keys[k - 1], keys[k]) == 0)
            dup = keys[k];
    fx_result r = FX_OK;
    if (dup)
        r = fx_fail(ctx, FX_ERR_BAD_RECIPE, "%s: key \"%.64s\" appears twice in %s%.64s%s: keep one", what,
                    dup, obj->string ? "\"" : "one object", obj->string ? obj->string : "",
                    obj->string ? "\"" : "");
    fx_mem_free(keys);
    return r;
}

fx_result fx_json_check_unique_keys(const fx_context *ctx, const cJSON *root, const char *what)
{
    /* cJSON caps nesting at parse (CJSON_NESTING_LIMIT), which bounds this recursion. */
    if (!root)
        return FX_OK;
    if (cJSON_IsObject(root)) {
        fx_result r = check_object(ctx, root, what);
        if (r)
            return r;
    }
    for (const cJSON *c = root->child; c; c = c->next) {
        if (!cJSON_IsObject(c) && !cJSON_IsArray(c))
            continue;
        fx_result r = fx_json_check_unique_keys(ctx, c, what);
        if (r)
            return r;
    }
    return FX_OK;
}
