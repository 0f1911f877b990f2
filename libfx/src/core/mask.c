/* Masks: parse a mask spec from a recipe, and evaluate it on a frame into coverage. */
#include "core/mask.h"
#include "core/json_keys.h"
#include "core/mem.h"
#include "core/mem_failures.h"
#include "core/parallel.h"

#include <cjson/cJSON.h>
#include <limits.h>
#ifdef __SSE2__
#include <xmmintrin.h>
#endif
#include <math.h>
#include <stdio.h>
#include <string.h>

/* ---- Cryptomatte IDs ---- */

static uint32_t rotl32(uint32_t x, int r)
{
    return (x << r) | (x >> (32 - r));
}

uint32_t fx_murmur3_32(const void *data, size_t len, uint32_t seed)
{
    const uint8_t *p = data;
    const uint32_t c1 = 0xcc9e2d51u, c2 = 0x1b873593u;
    uint32_t h = seed;
    size_t blocks = len / 4;
    for (size_t i = 0; i < blocks; i++) {
        uint32_t k = (uint32_t)p[4 * i] | (uint32_t)p[4 * i + 1] << 8 | (uint32_t)p[4 * i + 2] << 16 |
                     (uint32_t)p[4 * i + 3] << 24;
        k *= c1;
        k = rotl32(k, 15);
        k *= c2;
        h ^= k;
        h = rotl32(h, 13);
        h = h * 5 + 0xe6546b64u;
    }
    const uint8_t *tail = p + blocks * 4;
    uint32_t k = 0;
    switch (len & 3) {
    case 3: k ^= (uint32_t)tail[2] << 16; /* fall through */
    case 2: k ^= (uint32_t)tail[1] << 8;  /* fall through */
    case 1:
        k ^= tail[0];
        k *= c1;
        k = rotl32(k, 15);
        k *= c2;
        h ^= k;
    }
    h ^= (uint32_t)len;
    h ^= h >> 16;
    h *= 0x85ebca6bu;
    h ^= h >> 13;
    h *= 0xc2b2ae35u;
    h ^= h >> 16;
    return h;
}

float fx_cryptomatte_id(const char *name)
{
    uint32_t h = fx_murmur3_32(name, strlen(name), 0);
    /* Keep the float normal and finite: flip the exponent's low bit when it is 0 or 255. */
    uint32_t exp = (h >> 23) & 0xffu;
    if (exp == 0 || exp == 255)
        h ^= 1u << 23;
    float f;
    memcpy(&f, &h, sizeof f);
    return f;
}

/* ---- specs ---- */

int fx_mask_spec_is_empty(const fx_mask_spec *s)
{
    return !s || (s->material_count == 0 && s->object_count == 0 && s->material_index_count == 0 &&
                  s->object_index_count == 0 && !s->has_rect && !s->has_rect_relative && !s->invert);
}

void fx_mask_spec_clear(fx_mask_spec *s)
{
    if (!s)
        return;
    for (int i = 0; i < s->material_count; i++)
        fx_mem_free(s->materials[i]);
    for (int i = 0; i < s->object_count; i++)
        fx_mem_free(s->objects[i]);
    fx_mem_free(s->materials);
    fx_mem_free(s->objects);
    fx_mem_free(s->material_indices);
    fx_mem_free(s->object_indices);
    memset(s, 0, sizeof *s);
}

static fx_result parse_names(fx_context *ctx, const cJSON *v, const char *key, const char *where,
                             char ***out, int *count)
{
    int n = cJSON_IsArray(v) ? cJSON_GetArraySize(v) : 1;
    if (!cJSON_IsArray(v) && !cJSON_IsString(v))
        return fx_fail(ctx, FX_ERR_BAD_RECIPE, "%s: mask \"%s\" must be a name or a list of names",
                       where, key);
    char **names = fx_mem_calloc((size_t)(n ? n : 1), sizeof *names);
    if (!names)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "out of memory for a mask");
    *out = names;
    *count = 0;
    const cJSON *item = cJSON_IsArray(v) ? v->child : v;
    for (int i = 0; i < n; i++, item = item->next) {
        if (!cJSON_IsString(item) || !item->valuestring[0])
            return fx_fail(ctx, FX_ERR_BAD_RECIPE, "%s: mask \"%s\" entries must be non-empty names",
                           where, key);
        names[i] = fx_mem_strdup(item->valuestring);
        if (!names[i])
            return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "out of memory for a mask");
        (*count)++;
    }
    return FX_OK;
}

static fx_result parse_indices(fx_context *ctx, const cJSON *v, const char *key, const char *where,
                               int **out, int *count)
{
    int n = cJSON_IsArray(v) ? cJSON_GetArraySize(v) : 1;
    if (!cJSON_IsArray(v) && !cJSON_IsNumber(v))
        return fx_fail(ctx, FX_ERR_BAD_RECIPE, "%s: mask \"%s\" must be an index or a list of indices",
                       where, key);
    int *idx = fx_mem_calloc((size_t)(n ? n : 1), sizeof *idx);
    if (!idx)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "out of memory for a mask");
    *out = idx;
    *count = 0;
    const cJSON *item = cJSON_IsArray(v) ? v->child : v;
    for (int i = 0; i < n; i++, item = item->next) {
        if (!cJSON_IsNumber(item) || item->valuedouble != floor(item->valuedouble) ||
            item->valuedouble < 0 || item->valuedouble > 2147483647.0)
            return fx_fail(ctx, FX_ERR_BAD_RECIPE,
                           "%s: mask \"%s\" entries must be pass indices (integers >= 0)", where, key);
        idx[i] = (int)item->valuedouble;
        (*count)++;
    }
    return FX_OK;
}

fx_result fx_mask_spec_parse(fx_context *ctx, const cJSON *json, const char *where, fx_mask_spec *out)
{
    memset(out, 0, sizeof *out);
    if (!json || cJSON_IsNull(json))
        return FX_OK;
    if (!cJSON_IsObject(json))
        return fx_fail(ctx, FX_ERR_BAD_RECIPE, "%s: \"mask\" must be an object", where);
    /* a repeated key would replace (and leak) the first list */
    fx_result r = fx_json_check_unique_keys(ctx, json, where);
    if (r)
        return r;
    const cJSON *item;
    cJSON_ArrayForEach(item, json) {
        const char *k = item->string;
        if (strcmp(k, "material") == 0)
            r = parse_names(ctx, item, k, where, &out->materials, &out->material_count);
        else if (strcmp(k, "object") == 0)
            r = parse_names(ctx, item, k, where, &out->objects, &out->object_count);
        else if (strcmp(k, "material_index") == 0)
            r = parse_indices(ctx, item, k, where, &out->material_indices, &out->material_index_count);
        else if (strcmp(k, "object_index") == 0)
            r = parse_indices(ctx, item, k, where, &out->object_indices, &out->object_index_count);
        else if (strcmp(k, "invert") == 0) {
            if (!cJSON_IsBool(item))
                r = fx_fail(ctx, FX_ERR_BAD_RECIPE, "%s: mask \"invert\" must be true or false", where);
            else
                out->invert = cJSON_IsTrue(item);
        } else if (strcmp(k, "rect") == 0) {
            int ok = cJSON_IsArray(item) && cJSON_GetArraySize(item) == 4;
            for (int i = 0; ok && i < 4; i++) {
                const cJSON *v = cJSON_GetArrayItem(item, i);
                ok = cJSON_IsNumber(v) && v->valuedouble == floor(v->valuedouble) &&
                     fabs(v->valuedouble) < 1e8 && (i < 2 || v->valuedouble >= 0);
                if (ok)
                    out->rect[i] = (int)v->valuedouble;
            }
            if (!ok)
                r = fx_fail(ctx, FX_ERR_BAD_RECIPE,
                            "%s: mask \"rect\" must be [x, y, width, height] in whole pixels, "
                            "width and height >= 0",
                            where);
            out->has_rect = ok;
        } else if (strcmp(k, "rect_relative") == 0) {
            int ok = cJSON_IsArray(item) && cJSON_GetArraySize(item) == 4;
            for (int i = 0; ok && i < 4; i++) {
                const cJSON *v = cJSON_GetArrayItem(item, i);
                ok = cJSON_IsNumber(v) && isfinite(v->valuedouble) && fabs(v->valuedouble) <= 16 &&
                     (i < 2 || v->valuedouble >= 0);
                if (ok)
                    out->rect_relative[i] = (float)v->valuedouble;
            }
            if (!ok)
                r = fx_fail(ctx, FX_ERR_BAD_RECIPE,
                            "%s: mask \"rect_relative\" must be [x, y, width, height] as fractions of "
                            "the display window (0..1), width and height >= 0",
                            where);
            out->has_rect_relative = ok;
        } else {
            r = fx_fail(ctx, FX_ERR_BAD_RECIPE,
                        "%s: unknown mask key \"%s\" (known: material, object, material_index, "
                        "object_index, rect, rect_relative, invert)",
                        where, k);
        }
        if (r)
            break;
    }
    if (r)
        fx_mask_spec_clear(out);
    return r;
}

fx_result fx_mask_spec_parse_text(fx_context *ctx, const char *json, const char *where, const char *what,
                                  fx_mask_spec *out)
{
    memset(out, 0, sizeof *out);
    unsigned long failures = fx_mem_failure_count();
    cJSON *j = cJSON_Parse(json);
    if (!j && fx_mem_failure_count() != failures)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory reading %s", where, what);
    if (!j)
        return fx_fail(ctx, FX_ERR_BAD_RECIPE,
                       "%s: %s is not valid JSON (a mask object, e.g. {\"material\": [\"Mirror\"]})", where,
                       what);
    fx_result r = fx_mask_spec_parse(ctx, j, where, out);
    cJSON_Delete(j);
    return r;
}

/* Adds item to o as key; a NULL item (its allocation failed) or a failed add is freed. */
static int add_item(cJSON *o, const char *key, cJSON *item)
{
    if (item && cJSON_AddItemToObject(o, key, item))
        return 1;
    cJSON_Delete(item);
    return 0;
}

cJSON *fx_mask_spec_to_json(const fx_mask_spec *s)
{
    if (fx_mask_spec_is_empty(s))
        return NULL;
    cJSON *o = cJSON_CreateObject();
    int ok = o != NULL;
    if (ok && s->material_count)
        ok = add_item(o, "material", cJSON_CreateStringArray((const char *const *)s->materials, s->material_count));
    if (ok && s->object_count)
        ok = add_item(o, "object", cJSON_CreateStringArray((const char *const *)s->objects, s->object_count));
    if (ok && s->material_index_count)
        ok = add_item(o, "material_index", cJSON_CreateIntArray(s->material_indices, s->material_index_count));
    if (ok && s->object_index_count)
        ok = add_item(o, "object_index", cJSON_CreateIntArray(s->object_indices, s->object_index_count));
    if (ok && s->has_rect)
        ok = add_item(o, "rect", cJSON_CreateIntArray(s->rect, 4));
    if (ok && s->has_rect_relative)
        ok = add_item(o, "rect_relative", cJSON_CreateFloatArray(s->rect_relative, 4));
    if (ok && s->invert)
        ok = add_item(o, "invert", cJSON_CreateTrue());
    if (!ok) {
        cJSON_Delete(o);
        return NULL;
    }
    return o;
}

fx_pass_set fx_mask_spec_passes(const fx_mask_spec *s)
{
    fx_pass_set set = 0;
    if (!s)
        return 0;
    if (s->material_count)
        set |= FX_PASS_BIT(FX_PASS_CRYPTO_MATERIAL);
    if (s->object_count)
        set |= FX_PASS_BIT(FX_PASS_CRYPTO_OBJECT);
    if (s->material_index_count)
        set |= FX_PASS_BIT(FX_PASS_INDEX_MA);
    if (s->object_index_count)
        set |= FX_PASS_BIT(FX_PASS_INDEX_OB);
    return set;
}

/* ---- evaluation ---- */

typedef struct crypto_rank {
    const float *data; /* RGBA: id0, coverage0, id1, coverage1 */
} crypto_rank;

typedef struct mask_job {
    const fx_mask_spec *spec;
    const fx_frame *frame;
    float *cov;
    int w, h;
    crypto_rank *obj_ranks, *mat_ranks;
    int obj_rank_count, mat_rank_count;
    float *obj_ids, *mat_ids;
    const float *index_ob, *index_ma;
    int selectors;    /* names or indices given */
    fx_rect rect;     /* in frame pixels, clipped */
    int *row_first, *row_last; /* per row: first and last x with coverage > 0, or -1 */
} mask_job;

/* Ranks hold (id, coverage) pairs sorted by coverage: once the coverage seen in a pixel
 * reaches 1, later ranks hold nothing, so most pixels read rank 0 only. */
static float crypto_coverage(const crypto_rank *ranks, int nranks, const float *ids, int nids, size_t i)
{
    float c = 0, seen = 0;
    for (int r = 0; r < nranks && seen < 0.99999f; r++) {
        const float *p = ranks[r].data + i * 4;
        for (int k = 0; k < nids; k++) {
            if (p[0] == ids[k])
                c += p[1];
            if (p[2] == ids[k])
                c += p[3];
        }
        seen += p[1] + p[3];
    }
    return c;
}

static int index_match(float v, const int *idx, int n)
{
    long iv = lroundf(v);
    for (int k = 0; k < n; k++)
        if (iv == idx[k])
            return 1;
    return 0;
}

/* The coverage of one pixel for one Cryptomatte name, clamped to [0, 1] as mask_rows
 * does: rank 0 first, the later ranks only while the coverage seen is below 1 (the same
 * sums in the same order as crypto_coverage, so the same bits). */
static inline float crypto_pixel_one_id(const crypto_rank *ranks, int nranks, float id, size_t i)
{
    const float *p = ranks[0].data + i * 4;
    float c = (p[0] == id ? p[1] : 0.0f) + (p[2] == id ? p[3] : 0.0f);
    float seen = p[1] + p[3];
    for (int r = 1; r < nranks && seen < 0.99999f; r++) {
        const float *q = ranks[r].data + i * 4;
        if (q[0] == id)
            c += q[1];
        if (q[2] == id)
            c += q[3];
        seen += q[1] + q[3];
    }
    return !(c >= 0.0f) ? 0.0f : c > 1.0f ? 1.0f : c;
}

#ifdef __SSE2__
/* The first and last x with coverage > 0, moved on by row[x .. x + 3]. */
static inline void row_extent4(const float *row, int x, int *first, int *last)
{
    const int pos = _mm_movemask_ps(_mm_cmpgt_ps(_mm_loadu_ps(row + x), _mm_setzero_ps()));
    if (pos) {
        if (*first < 0)
            *first = x + __builtin_ctz((unsigned)pos);
        *last = x + 31 - __builtin_clz((unsigned)pos);
    }
}
#endif

/* One Cryptomatte name of one type, the usual mask (a material, an object), a row at a
 * time; returns the row's first and last x with coverage > 0. With SSE2, four pixels per
 * step from rank 0 (a transpose of their RGBA), the pixels whose rank 0 does not hold their
 * whole coverage done one at a time; the same operations per pixel, so the same bits. */
static void crypto_row_one_id(const crypto_rank *ranks, int nranks, float id, size_t i0, int w, float *row,
                              int *first, int *last)
{
    int f = -1, l = -1, x = 0;
#ifdef __SSE2__
    const __m128 vid = _mm_set1_ps(id), zero = _mm_setzero_ps(), one = _mm_set1_ps(1.0f);
    const __m128 full = _mm_set1_ps(0.99999f);
    const float *p = ranks[0].data + i0 * 4;
    for (; x + 4 <= w; x += 4, p += 16) {
        __m128 id0 = _mm_loadu_ps(p), cov0 = _mm_loadu_ps(p + 4);
        __m128 id1 = _mm_loadu_ps(p + 8), cov1 = _mm_loadu_ps(p + 12);
        _MM_TRANSPOSE4_PS(id0, cov0, id1, cov1); /* now: id0, cov0, id1, cov1 of four pixels */
        __m128 c = _mm_add_ps(_mm_and_ps(_mm_cmpeq_ps(id0, vid), cov0), _mm_and_ps(_mm_cmpeq_ps(id1, vid), cov1));
        const int partial = nranks > 1 ? _mm_movemask_ps(_mm_cmplt_ps(_mm_add_ps(cov0, cov1), full)) : 0;
        c = _mm_and_ps(c, _mm_cmpge_ps(c, zero)); /* NaN and negatives: 0 (-0 stays, as below) */
        c = _mm_min_ps(c, one);
        _mm_storeu_ps(row + x, c);
        for (int k = 0; partial && k < 4; k++)
            if (partial & (1 << k))
                row[x + k] = crypto_pixel_one_id(ranks, nranks, id, i0 + (size_t)(x + k));
        row_extent4(row, x, &f, &l);
    }
#endif
    for (; x < w; x++) {
        float c = crypto_pixel_one_id(ranks, nranks, id, i0 + (size_t)x);
        row[x] = c;
        if (c > 0.0f) {
            if (f < 0)
                f = x;
            l = x;
        }
    }
    *first = f;
    *last = l;
}

/* Several Cryptomatte names of one type (a mask of a few materials): the rows of
 * crypto_coverage, clamped as mask_rows does, with the pixels' rank 0 four at a time with
 * SSE2. The same additions in the same order as crypto_coverage: a name that does not
 * match adds +0, which changes no sum (a sum that starts at +0 is never -0). Pixels whose
 * rank 0 does not hold their whole coverage go through crypto_coverage itself. Returns the
 * row's first and last x with coverage > 0. */
static void crypto_row_ids(const crypto_rank *ranks, int nranks, const float *ids, int nids, size_t i0, int w,
                           float *row, int *first, int *last)
{
    int f = -1, l = -1, x = 0;
#ifdef __SSE2__
    const __m128 zero = _mm_setzero_ps(), one = _mm_set1_ps(1.0f), full = _mm_set1_ps(0.99999f);
    const float *p = ranks[0].data + i0 * 4;
    for (; x + 4 <= w; x += 4, p += 16) {
        __m128 id0 = _mm_loadu_ps(p), cov0 = _mm_loadu_ps(p + 4);
        __m128 id1 = _mm_loadu_ps(p + 8), cov1 = _mm_loadu_ps(p + 12);
        _MM_TRANSPOSE4_PS(id0, cov0, id1, cov1); /* now: id0, cov0, id1, cov1 of four pixels */
        __m128 c = zero;
        for (int k = 0; k < nids; k++) {
            const __m128 vid = _mm_set1_ps(ids[k]);
            c = _mm_add_ps(c, _mm_and_ps(_mm_cmpeq_ps(id0, vid), cov0));
            c = _mm_add_ps(c, _mm_and_ps(_mm_cmpeq_ps(id1, vid), cov1));
        }
        const int partial = nranks > 1 ? _mm_movemask_ps(_mm_cmplt_ps(_mm_add_ps(cov0, cov1), full)) : 0;
        c = _mm_and_ps(c, _mm_cmpge_ps(c, zero)); /* NaN and negatives: 0 */
        c = _mm_min_ps(c, one);
        _mm_storeu_ps(row + x, c);
        for (int k = 0; partial && k < 4; k++)
            if (partial & (1 << k)) {
                float v = 0.0f + crypto_coverage(ranks, nranks, ids, nids, i0 + (size_t)(x + k));
                row[x + k] = !(v >= 0.0f) ? 0.0f : v > 1.0f ? 1.0f : v;
            }
        row_extent4(row, x, &f, &l);
    }
#endif
    for (; x < w; x++) {
        float v = 0.0f + crypto_coverage(ranks, nranks, ids, nids, i0 + (size_t)x);
        v = !(v >= 0.0f) ? 0.0f : v > 1.0f ? 1.0f : v;
        row[x] = v;
        if (v > 0.0f) {
            if (f < 0)
                f = x;
            l = x;
        }
    }
    *first = f;
    *last = l;
}

static void mask_rows(void *user, int y0, int y1)
{
    mask_job *j = user;
    const fx_mask_spec *s = j->spec;
    const int has_rect = s->has_rect || s->has_rect_relative;
    /* one name of one Cryptomatte type and nothing else: crypto_row_one_id */
    const int one_obj = s->object_count == 1 && !s->material_count && !j->index_ob && !j->index_ma;
    const int one_mat = s->material_count == 1 && !s->object_count && !j->index_ob && !j->index_ma;
    const int some_obj = s->object_count > 1 && !s->material_count && !j->index_ob && !j->index_ma;
    const int some_mat = s->material_count > 1 && !s->object_count && !j->index_ob && !j->index_ma;
    for (int y = y0; y < y1; y++) {
        const size_t i0 = (size_t)y * j->w;
        float *row = j->cov + i0;
        if (!j->selectors) {
            for (int x = 0; x < j->w; x++)
                row[x] = 1.0f;
        } else if (one_obj || one_mat) {
            if (one_obj)
                crypto_row_one_id(j->obj_ranks, j->obj_rank_count, j->obj_ids[0], i0, j->w, row,
                                  &j->row_first[y], &j->row_last[y]);
            else
                crypto_row_one_id(j->mat_ranks, j->mat_rank_count, j->mat_ids[0], i0, j->w, row,
                                  &j->row_first[y], &j->row_last[y]);
            if (!has_rect && !s->invert)
                continue;   /* the row's extent is known */
        } else if (some_obj || some_mat) {
            if (some_obj)
                crypto_row_ids(j->obj_ranks, j->obj_rank_count, j->obj_ids, s->object_count, i0, j->w, row,
                               &j->row_first[y], &j->row_last[y]);
            else
                crypto_row_ids(j->mat_ranks, j->mat_rank_count, j->mat_ids, s->material_count, i0, j->w, row,
                               &j->row_first[y], &j->row_last[y]);
            if (!has_rect && !s->invert)
                continue;   /* the row's extent is known */
        } else {
            for (int x = 0; x < j->w; x++) {
                size_t i = i0 + (size_t)x;
                float c = 0.0f;
                if (j->obj_rank_count)
                    c += crypto_coverage(j->obj_ranks, j->obj_rank_count, j->obj_ids, s->object_count, i);
                if (j->mat_rank_count)
                    c += crypto_coverage(j->mat_ranks, j->mat_rank_count, j->mat_ids, s->material_count, i);
                if (j->index_ob && index_match(j->index_ob[i], s->object_indices, s->object_index_count))
                    c = 1.0f;
                if (j->index_ma && index_match(j->index_ma[i], s->material_indices, s->material_index_count))
                    c = 1.0f;
                if (!(c >= 0.0f))
                    c = 0.0f;
                if (c > 1.0f)
                    c = 1.0f;
                row[x] = c;
            }
        }
        if (has_rect) {
            int x0 = j->rect.x0, x1 = j->rect.x1;
            if (y < j->rect.y0 || y >= j->rect.y1)
                x0 = x1 = j->w;
            for (int x = 0; x < x0; x++)
                row[x] = 0.0f;
            for (int x = x1; x < j->w; x++)
                row[x] = 0.0f;
        }
        if (s->invert)
            for (int x = 0; x < j->w; x++)
                row[x] = 1.0f - row[x];
        int first = -1, last = -1;
        for (int x = 0; x < j->w; x++)
            if (row[x] > 0.0f) {
                if (first < 0)
                    first = x;
                last = x;
            }
        j->row_first[y] = first;
        j->row_last[y] = last;
    }
}

static fx_result collect_ranks(fx_context *ctx, const fx_frame *f, const char *prefix, const char *what,
                               const char *where, crypto_rank **out, int *count)
{
    int n = 0;
    char name[FX_NAME_MAX];
    for (int r = 0; r < 100; r++) {
        snprintf(name, sizeof name, "%s%02d", prefix, r);
        const fx_pass *p = fx_frame_find_pass(f, name);
        if (!p)
            break;
        if (p->channels != 4)
            return fx_fail(ctx, FX_ERR_BAD_FILE, "%s: Cryptomatte pass '%s' has %d channels, not 4",
                           where, name, p->channels);
        n++;
    }
    if (n == 0) {
        const char *src = fx_frame_meta(f, "libfx:source");
        return fx_fail(ctx, FX_ERR_MISSING_PASS,
                       "%s: a mask by %s name needs the %s pass (Cryptomatte), which %s%s%s does not have",
                       where, what, prefix, src ? "'" : "", src ? src : "the frame", src ? "'" : "");
    }
    *out = fx_mem_calloc((size_t)n, sizeof **out);
    if (!*out)
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "out of memory for a mask");
    for (int r = 0; r < n; r++) {
        snprintf(name, sizeof name, "%s%02d", prefix, r);
        (*out)[r].data = fx_frame_find_pass(f, name)->data;
    }
    *count = n;
    return FX_OK;
}

static fx_result index_pass(fx_context *ctx, const fx_frame *f, const char *pass, const char *what,
                            const char *where, const float **out)
{
    const fx_pass *p = fx_frame_find_pass(f, pass);
    if (!p) {
        const char *src = fx_frame_meta(f, "libfx:source");
        return fx_fail(ctx, FX_ERR_MISSING_PASS,
                       "%s: a mask by %s index needs the %s pass, which %s%s%s does not have "
                       "(Cycles only: with Eevee, mask by name through Cryptomatte)",
                       where, what, pass, src ? "'" : "", src ? src : "the frame", src ? "'" : "");
    }
    *out = p->data;
    return FX_OK;
}

static float *ids_for(const char *const *names, int n)
{
    float *ids = fx_mem_calloc((size_t)(n ? n : 1), sizeof *ids);
    if (ids)
        for (int i = 0; i < n; i++)
            ids[i] = fx_cryptomatte_id(names[i]);
    return ids;
}

/* Warns about names missing from a Cryptomatte manifest: most often a typo. */
static void check_manifest(fx_context *ctx, const fx_frame *f, const char *type, char **names, int n,
                           const char *where)
{
    char key[128];
    snprintf(key, sizeof key, "cryptomatte/%s/manifest", type);
    const char *m = fx_frame_meta(f, key);
    if (!m)
        return;
    cJSON *manifest = cJSON_Parse(m);
    if (!manifest)
        return;
    for (int i = 0; i < n; i++)
        if (!cJSON_GetObjectItemCaseSensitive(manifest, names[i]))
            fx_warn(ctx, "%s: mask name '%s' is not in the %s manifest", where, names[i], type);
    cJSON_Delete(manifest);
}

fx_result fx_mask_build(fx_context *ctx, const fx_mask_spec *spec, const fx_frame *frame,
                        const char *where, fx_mask **out)
{
    *out = NULL;
    if (fx_mask_spec_is_empty(spec))
        return FX_OK;
    mask_job j;
    memset(&j, 0, sizeof j);
    j.spec = spec;
    j.frame = frame;
    j.w = frame->width;
    j.h = frame->height;
    j.selectors = spec->material_count || spec->object_count || spec->material_index_count ||
                  spec->object_index_count;
    fx_result r = FX_OK;
    if (spec->object_count && !(r = collect_ranks(ctx, frame, "CryptoObject", "object", where,
                                                  &j.obj_ranks, &j.obj_rank_count)))
        check_manifest(ctx, frame, "CryptoObject", spec->objects, spec->object_count, where);
    if (!r && spec->material_count &&
        !(r = collect_ranks(ctx, frame, "CryptoMaterial", "material", where, &j.mat_ranks, &j.mat_rank_count)))
        check_manifest(ctx, frame, "CryptoMaterial", spec->materials, spec->material_count, where);
    if (!r && spec->object_index_count)
        r = index_pass(ctx, frame, "IndexOB", "object", where, &j.index_ob);
    if (!r && spec->material_index_count)
        r = index_pass(ctx, frame, "IndexMA", "material", where, &j.index_ma);
    fx_mask *m = NULL;
    if (!r) {
        j.obj_ids = ids_for((const char *const *)spec->objects, spec->object_count);
        j.mat_ids = ids_for((const char *const *)spec->materials, spec->material_count);
        m = fx_mem_calloc(1, sizeof *m);
        size_t bytes;
        if (!fx_size_mul(&bytes, (size_t)j.w, (size_t)j.h, sizeof(float)))
            r = fx_fail(ctx, FX_ERR_LIMIT, "%s: mask too large", where);
        else if (!(r = fx_check_budget(ctx, bytes, "a mask")) && m)
            m->coverage = fx_mem_alloc(bytes);
        if (!r) {
            j.row_first = fx_mem_alloc((size_t)(j.h ? j.h : 1) * sizeof(int));
            j.row_last = fx_mem_alloc((size_t)(j.h ? j.h : 1) * sizeof(int));
        }
        if (!r && (!j.obj_ids || !j.mat_ids || !m || !m->coverage || !j.row_first || !j.row_last))
            r = fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the mask", where);
    }
    if (!r) {
        if (spec->has_rect || spec->has_rect_relative) {
            /* Rects are in display-window pixels from its top-left; frame pixel (0,0) is
             * the data window's corner. A relative rect scales with the display window;
             * both together intersect. */
            long dx = (long)frame->display_window[0] - frame->data_window[0];
            long dy = (long)frame->display_window[1] - frame->data_window[1];
            long x0 = LONG_MIN / 4, y0 = LONG_MIN / 4, x1 = LONG_MAX / 4, y1 = LONG_MAX / 4;
            if (spec->has_rect) {
                x0 = dx + spec->rect[0];
                y0 = dy + spec->rect[1];
                x1 = x0 + spec->rect[2];
                y1 = y0 + spec->rect[3];
            }
            if (spec->has_rect_relative) {
                double dw = (double)frame->display_window[2] - frame->display_window[0] + 1;
                double dh = (double)frame->display_window[3] - frame->display_window[1] + 1;
                const float *q = spec->rect_relative;
                long rx0 = dx + lround(q[0] * dw), ry0 = dy + lround(q[1] * dh);
                long rx1 = dx + lround((q[0] + q[2]) * dw), ry1 = dy + lround((q[1] + q[3]) * dh);
                if (rx0 > x0) x0 = rx0;
                if (ry0 > y0) y0 = ry0;
                if (rx1 < x1) x1 = rx1;
                if (ry1 < y1) y1 = ry1;
            }
            j.rect.x0 = (int)(x0 < 0 ? 0 : x0 > j.w ? j.w : x0);
            j.rect.y0 = (int)(y0 < 0 ? 0 : y0 > j.h ? j.h : y0);
            j.rect.x1 = (int)(x1 < j.rect.x0 ? j.rect.x0 : x1 > j.w ? j.w : x1);
            j.rect.y1 = (int)(y1 < j.rect.y0 ? j.rect.y0 : y1 > j.h ? j.h : y1);
        }
        j.cov = m->coverage;
        m->width = j.w;
        m->height = j.h;
        fx_parallel_for(ctx, j.h, fx_grain_for(ctx, j.h), mask_rows, &j);
        /* bounds of coverage > 0, from the rows' extents */
        fx_rect b = {j.w, j.h, 0, 0};
        for (int y = 0; y < j.h; y++) {
            int first = j.row_first[y], last = j.row_last[y];
            if (first < 0)
                continue;
            if (first < b.x0) b.x0 = first;
            if (last + 1 > b.x1) b.x1 = last + 1;
            if (y < b.y0) b.y0 = y;
            if (y + 1 > b.y1) b.y1 = y + 1;
        }
        if (b.x1 <= b.x0 || b.y1 <= b.y0) {
            b.x0 = b.x1 = b.y0 = b.y1 = 0;
            fx_warn(ctx, "%s: the mask selects no pixels in this frame", where);
        }
        m->bounds = b;
    }
    fx_mem_free(j.obj_ranks);
    fx_mem_free(j.mat_ranks);
    fx_mem_free(j.obj_ids);
    fx_mem_free(j.mat_ids);
    fx_mem_free(j.row_first);
    fx_mem_free(j.row_last);
    if (r) {
        fx_mask_free(m);
        return r;
    }
    *out = m;
    return FX_OK;
}

void fx_mask_free(fx_mask *m)
{
    if (!m)
        return;
    fx_mem_free(m->coverage);
    fx_mem_free(m);
}
