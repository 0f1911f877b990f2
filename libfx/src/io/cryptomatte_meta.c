/* Cryptomatte header attributes <-> the frame's "cryptomatte/<Type>/manifest" metadata (io/cryptomatte_meta.h). */
#include "io/cryptomatte_meta.h"

#include "core/mask.h"
#include "core/mem.h"
#include "core/platform.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>

#define PREFIX "cryptomatte/"
/* A sidecar manifest bigger than this is not a manifest. */
#define FX_MAX_SIDECAR_BYTES ((long)64 << 20)

/* The 7-hex attribute key of a Cryptomatte name (Blender's and the specification's). */
static void cryptomatte_key(const char *name, char out[8])
{
    char hex[16];
    snprintf(hex, sizeof hex, "%08x", (unsigned)fx_murmur3_32(name, strlen(name), 0));
    memcpy(out, hex, 7);
    out[7] = '\0';
}

void fx_exr_free_cryptos(fx_exr_crypto *c, int count)
{
    for (int i = 0; i < count; i++)
        fx_mem_free(c[i].manifest);
    fx_mem_free(c);
}

static void copy_n(char *dst, size_t cap, const char *src, size_t n)
{
    if (n >= cap)
        n = cap - 1;
    memcpy(dst, src, n);
    dst[n] = '\0';
}

/* The sidecar manifest: a relative path beside the EXR. Absolute paths and ".." are
 * refused: a header must not make us read arbitrary files. */
static char *load_sidecar(fx_context *ctx, const char *exr_path, const char *rel)
{
    if (!rel[0] || fx_os_path_is_absolute(rel) || strstr(rel, "..")) {
        fx_warn(ctx, "'%s': Cryptomatte sidecar manifest '%s' ignored (only relative paths beside the file)",
                exr_path, rel);
        return NULL;
    }
    size_t dir = fx_os_dir_length(exr_path);
    size_t len = dir + strlen(rel) + 1;
    char *full = fx_mem_alloc(len);
    if (!full)
        return NULL;
    memcpy(full, exr_path, dir);
    strcpy(full + dir, rel);
    char *text = NULL;
    FILE *fp = fx_os_fopen(full, "rb");
    if (!fp) {
        fx_warn(ctx, "'%s': cannot open its Cryptomatte sidecar manifest '%s': %s", exr_path, full,
                strerror(errno));
        fx_mem_free(full);
        return NULL;
    }
    long size = -1;
    if (fseek(fp, 0, SEEK_END) == 0)
        size = ftell(fp);
    if (size < 0 || size > FX_MAX_SIDECAR_BYTES || fseek(fp, 0, SEEK_SET) != 0) {
        fx_warn(ctx, "'%s': Cryptomatte sidecar manifest '%s' is unreadable or too large", exr_path, full);
    } else if ((text = fx_mem_alloc((size_t)size + 1)) != NULL) {
        if (fread(text, 1, (size_t)size, fp) != (size_t)size) {
            fx_warn(ctx, "'%s': cannot read its Cryptomatte sidecar manifest '%s'", exr_path, full);
            fx_mem_free(text);
            text = NULL;
        } else {
            text[size] = '\0';
        }
    }
    fclose(fp);
    fx_mem_free(full);
    return text;
}

fx_result fx_exr_read_cryptos(fx_context *ctx, fx_exr_file *f)
{
    for (int p = 0; p < f->part_count; p++) {
        int32_t n = 0;
        if (exr_get_attribute_count(f->exr, p, &n) != EXR_ERR_SUCCESS)
            continue;
        for (int32_t i = 0; i < n; i++) {
            const exr_attribute_t *a = NULL;
            if (exr_get_attribute_by_index(f->exr, p, EXR_ATTR_LIST_FILE_ORDER, i, &a) != EXR_ERR_SUCCESS ||
                !a || !a->name || a->type != EXR_ATTR_STRING || !a->string || !a->string->str)
                continue;
            if (strncmp(a->name, PREFIX, strlen(PREFIX)) != 0)
                continue;
            const char *key = a->name + strlen(PREFIX);
            const char *field = strchr(key, '/');
            if (!field || field == key || (size_t)(field - key) >= sizeof f->cryptos->key)
                continue;
            field++;
            int k = 0;
            while (k < f->crypto_count &&
                   !(strlen(f->cryptos[k].key) == (size_t)(field - 1 - key) &&
                     strncmp(f->cryptos[k].key, key, (size_t)(field - 1 - key)) == 0))
                k++;
            if (k == f->crypto_count) {
                fx_exr_crypto *grown = fx_mem_realloc(f->cryptos, (size_t)(k + 1) * sizeof *grown);
                if (!grown)
                    return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "'%s': out of memory", f->path);
                f->cryptos = grown;
                memset(&grown[k], 0, sizeof grown[k]);
                copy_n(grown[k].key, sizeof grown[k].key, key, (size_t)(field - 1 - key));
                f->crypto_count++;
            }
            fx_exr_crypto *c = &f->cryptos[k];
            const char *v = a->string->str;
            size_t vlen = (size_t)(a->string->length > 0 ? a->string->length : 0);
            if (strcmp(field, "name") == 0) {
                copy_n(c->name, sizeof c->name, v, vlen);
            } else if (strcmp(field, "manif_file") == 0) {
                copy_n(c->manif_file, sizeof c->manif_file, v, vlen);
            } else if (strcmp(field, "manifest") == 0 && !c->manifest) {
                c->manifest = fx_mem_alloc(vlen + 1);
                if (!c->manifest)
                    return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "'%s': out of memory", f->path);
                memcpy(c->manifest, v, vlen);
                c->manifest[vlen] = '\0';
            }
        }
    }
    /* Names without a name attribute are of no use: drop them. */
    int kept = 0;
    for (int k = 0; k < f->crypto_count; k++) {
        fx_exr_crypto *c = &f->cryptos[k];
        if (!c->name[0]) {
            fx_mem_free(c->manifest);
            continue;
        }
        const char *dot = strrchr(c->name, '.');
        copy_n(c->file_type, sizeof c->file_type, dot ? dot + 1 : c->name, strlen(dot ? dot + 1 : c->name));
        copy_n(c->layer, sizeof c->layer, c->name, dot ? (size_t)(dot - c->name) : 0);
        fx_exr_crypto_type(c->file_type, c->type);
        if (!c->manifest && c->manif_file[0])
            c->manifest = load_sidecar(ctx, f->path, c->manif_file);
        if (kept != k)
            f->cryptos[kept] = *c;
        kept++;
    }
    f->crypto_count = kept;
    return FX_OK;
}

fx_result fx_exr_cryptos_to_meta(const fx_exr_file *f, const char *layer, fx_frame *frame)
{
    for (int k = 0; k < f->crypto_count; k++) {
        const fx_exr_crypto *c = &f->cryptos[k];
        /* The channels read are the chosen layer's and the layer-less ones. */
        if (c->layer[0] && strcmp(c->layer, layer) != 0)
            continue;
        char key[FX_NAME_MAX + 32];
        snprintf(key, sizeof key, PREFIX "%s/layer", c->type);
        fx_result r = fx_frame_set_meta(frame, key, c->name);
        if (r == FX_OK && c->manifest) {
            snprintf(key, sizeof key, PREFIX "%s/manifest", c->type);
            r = fx_frame_set_meta(frame, key, c->manifest);
        }
        if (r != FX_OK)
            return r;
    }
    return FX_OK;
}

exr_result_t fx_exr_write_cryptos(exr_context_t exr, int part, const fx_frame *frame)
{
    for (int i = 0; i < frame->meta_count; i++) {
        const char *k = frame->meta[i].key;
        if (strncmp(k, PREFIX, strlen(PREFIX)) != 0)
            continue;
        const char *type = k + strlen(PREFIX);
        const char *slash = strchr(type, '/');
        if (!slash || strcmp(slash, "/manifest") != 0 || slash == type)
            continue;
        char name[FX_NAME_MAX], hk[8], attr[FX_NAME_MAX + 32];
        copy_n(name, sizeof name, type, (size_t)(slash - type));
        cryptomatte_key(name, hk);
        static const char *const fields[] = {"name", "hash", "conversion", "manifest"};
        const char *values[] = {name, "MurmurHash3_32", "uint32_to_float32", frame->meta[i].value};
        for (int j = 0; j < 4; j++) {
            snprintf(attr, sizeof attr, PREFIX "%s/%s", hk, fields[j]);
            exr_result_t rv = exr_attr_set_string(exr, part, attr, values[j]);
            if (rv != EXR_ERR_SUCCESS)
                return rv;
        }
    }
    return EXR_ERR_SUCCESS;
}
