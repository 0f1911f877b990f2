/* EXR channel names -> libfx passes: splitting names, choosing the layer, planning the passes (io/exr_channels.h). */
#include "io/exr_channels.h"
#include "core/frame.h"
#include "core/mem.h"

#include <ctype.h>
#include <stdio.h>
#include <string.h>

static void copy_str(char *dst, size_t cap, const char *src, size_t n)
{
    if (n >= cap)
        n = cap - 1;
    memcpy(dst, src, n);
    dst[n] = '\0';
}

static int is_view(const char *tok, size_t n, const char *const *views, int view_count)
{
    for (int i = 0; i < view_count; i++)
        if (views[i] && strlen(views[i]) == n && strncmp(views[i], tok, n) == 0)
            return 1;
    return 0;
}

void fx_exr_split_channel(const char *full, const char *const *views, int view_count,
                          const char *part_view, fx_exr_chan *out)
{
    out->layer[0] = out->pass[0] = out->view[0] = out->chan[0] = '\0';
    copy_str(out->full, sizeof out->full, full, strlen(full));

    /* channel: after the last dot (a name ending in '.' keeps an empty channel) */
    const char *end = full + strlen(full);
    const char *dot = strrchr(full, '.');
    if (!dot) {
        copy_str(out->chan, sizeof out->chan, full, strlen(full));
        /* OpenEXR's multi-view rule: a one-token name belongs to the default view. */
        if (part_view)
            copy_str(out->view, sizeof out->view, part_view, strlen(part_view));
        else if (view_count > 0)
            copy_str(out->view, sizeof out->view, views[0], strlen(views[0]));
        return;
    }
    copy_str(out->chan, sizeof out->chan, dot + 1, (size_t)(end - dot - 1));
    end = dot; /* [full, end) is what remains */

    if (part_view) {
        /* Multipart: the part's view attribute names the view of every channel in it. */
        copy_str(out->view, sizeof out->view, part_view, strlen(part_view));
    } else if (view_count > 0) {
        const char *p = end;
        while (p > full && p[-1] != '.')
            p--;
        if (is_view(p, (size_t)(end - p), views, view_count)) {
            copy_str(out->view, sizeof out->view, p, (size_t)(end - p));
            end = p > full ? p - 1 : p;
            if (p == full) /* "left.R": the default RGBA pass of view left */
                return;
        }
    }
    /* pass: the token before; layer: everything left of it */
    const char *p = end;
    while (p > full && p[-1] != '.')
        p--;
    copy_str(out->pass, sizeof out->pass, p, (size_t)(end - p));
    if (p > full)
        copy_str(out->layer, sizeof out->layer, full, (size_t)(p - 1 - full));
}

void fx_exr_channel_letter(const char *chan, char out[FX_EXR_NAME_MAX])
{
    static const struct {
        const char *lng, *ltr;
    } longs[] = {{"red", "R"}, {"green", "G"}, {"blue", "B"}, {"alpha", "A"}};
    for (size_t i = 0; i < sizeof longs / sizeof longs[0]; i++) {
        const char *a = chan, *b = longs[i].lng;
        while (*a && *b && tolower((unsigned char)*a) == *b)
            a++, b++;
        if (!*a && !*b) {
            strcpy(out, longs[i].ltr);
            return;
        }
    }
    copy_str(out, FX_EXR_NAME_MAX, chan, strlen(chan));
    if (out[0] && !out[1])
        out[0] = (char)toupper((unsigned char)out[0]);
}

void fx_exr_crypto_type(const char *file_type, char out[FX_NAME_MAX])
{
    /* Compare without case and underscores: crypto_object, CryptoObject, cryptoObject. */
    char norm[FX_EXR_NAME_MAX];
    size_t n = 0;
    for (const char *p = file_type; *p && n + 1 < sizeof norm; p++)
        if (*p != '_')
            norm[n++] = (char)tolower((unsigned char)*p);
    norm[n] = '\0';
    if (strcmp(norm, "cryptoobject") == 0)
        strcpy(out, "CryptoObject");
    else if (strcmp(norm, "cryptomaterial") == 0)
        strcpy(out, "CryptoMaterial");
    else if (strcmp(norm, "cryptoasset") == 0)
        strcpy(out, "CryptoAsset");
    else
        copy_str(out, FX_NAME_MAX, file_type, strlen(file_type));
}

int fx_exr_layers(const fx_exr_chan *chans, int count, const char **out, int max)
{
    int n = 0;
    for (int i = 0; i < count; i++) {
        if (!chans[i].layer[0])
            continue;
        int seen = 0;
        for (int j = 0; j < n && !seen; j++)
            seen = strcmp(out[j], chans[i].layer) == 0;
        if (!seen && n < max)
            out[n++] = chans[i].layer;
    }
    return n;
}

/* "'A', 'B'" into buf */
static void join_names(char *buf, size_t cap, const char **names, int n)
{
    size_t len = 0;
    buf[0] = '\0';
    for (int i = 0; i < n && len + 1 < cap; i++) {
        int w = snprintf(buf + len, cap - len, "%s'%s'", i ? ", " : "", names[i]);
        if (w < 0)
            break;
        len += (size_t)w;
    }
    if (len >= cap && cap > 4)
        strcpy(buf + cap - 4, "...");
}

#define FX_EXR_MAX_LAYERS 64

fx_result fx_exr_choose_layer(fx_context *ctx, const char *path, const fx_exr_chan *chans,
                              int count, const char *requested, const char **out)
{
    const char *layers[FX_EXR_MAX_LAYERS];
    int n = fx_exr_layers(chans, count, layers, FX_EXR_MAX_LAYERS);
    char list[768];
    if (requested && requested[0]) {
        for (int i = 0; i < n; i++)
            if (strcmp(layers[i], requested) == 0) {
                *out = layers[i];
                return FX_OK;
            }
        join_names(list, sizeof list, layers, n);
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT, "'%s' has no layer '%s' (layers: %s)", path,
                       requested, n ? list : "none");
    }
    /* Blender's render output adds "Composite" beside the view layers: not a choice. */
    const char *pick[FX_EXR_MAX_LAYERS];
    int m = 0;
    for (int i = 0; i < n; i++)
        if (strcmp(layers[i], "Composite") != 0)
            pick[m++] = layers[i];
    if (m > 1) {
        join_names(list, sizeof list, pick, m);
        return fx_fail(ctx, FX_ERR_INVALID_ARGUMENT,
                       "'%s' has several layers (%s): choose one", path, list);
    }
    if (m == 1)
        *out = pick[0];
    else if (n == 1) /* only Composite */
        *out = layers[0];
    else
        *out = "";
    return FX_OK;
}

/* Frame pass name of a (non-root) pass token: aliases resolved, Cryptomatte ranks of
 * other tools renamed to the canonical type ("crypto_asset01" -> "CryptoAsset01"). */
static int pass_name_for(const char *token, const fx_exr_crypto *cryptos, int crypto_count,
                         char out[FX_NAME_MAX])
{
    for (int i = 0; i < crypto_count; i++) {
        const char *ft = cryptos[i].file_type;
        size_t n = strlen(ft);
        if (n && strncmp(token, ft, n) == 0 && isdigit((unsigned char)token[n]) &&
            isdigit((unsigned char)token[n + 1]) && token[n + 2] == '\0') {
            if (strlen(cryptos[i].type) + 3 > FX_NAME_MAX)
                return -2;
            snprintf(out, FX_NAME_MAX, "%s%s", cryptos[i].type, token + n);
            return fx_pass_lookup(out);
        }
    }
    int id = fx_pass_lookup(token);
    if (id >= 0) {
        const fx_pass_desc *d = fx_pass_describe((fx_pass_id)id);
        if (d->is_crypto)
            copy_str(out, FX_NAME_MAX, token, strlen(token));
        else
            strcpy(out, d->name);
        return id;
    }
    if (strlen(token) >= FX_NAME_MAX)
        return -2;
    strcpy(out, token);
    return -1;
}

typedef struct group {
    char name[FX_NAME_MAX];
    int id;
    int best;        /* highest priority among members */
    int first_member;/* index into members */
} group;

typedef struct member {
    int chan;
    int prio;
    int group;
} member;

static int letter_slot(const char *letters, const char *letter)
{
    if (!letter[0] || letter[1])
        return -1;
    const char *p = strchr(letters, letter[0]);
    return p ? (int)(p - letters) : -1;
}

/* Order of a channel in a pass libfx does not know: RGBA, XYZW, UV orders first, then
 * the file's order. */
static int unknown_rank(const char *chan, int file_order)
{
    char letter[FX_EXR_NAME_MAX];
    fx_exr_channel_letter(chan, letter);
    static const char *const orders[] = {"RGBA", "XYZW", "UV"};
    if (letter[0] && !letter[1])
        for (int i = 0; i < 3; i++) {
            const char *p = strchr(orders[i], letter[0]);
            if (p)
                return (int)(p - orders[i]);
        }
    return 100 + file_order;
}

/* The frame pass a selected channel feeds: its name and id (-1: a pass libfx does not
 * know, -2: a name too long to keep). */
static int channel_pass(const fx_exr_chan *c, const fx_exr_crypto *cryptos, int crypto_count, char name[FX_NAME_MAX])
{
    if (c->pass[0])
        return pass_name_for(c->pass, cryptos, crypto_count, name);
    /* A bare channel: R, G, B, A, Y make Combined; Z is depth (OpenEXR's RGBAZ);
     * anything else ("pscale") is a one-channel pass of its own. */
    char letter[FX_EXR_NAME_MAX];
    fx_exr_channel_letter(c->chan, letter);
    if (strcmp(letter, "Z") == 0) {
        strcpy(name, "Depth");
        return FX_PASS_DEPTH;
    }
    if (strlen(letter) == 1 && strchr("RGBAY", letter[0])) {
        strcpy(name, "Combined");
        return FX_PASS_COMBINED;
    }
    return pass_name_for(c->chan, cryptos, crypto_count, name);
}

typedef struct planner {
    fx_context *ctx;
    const char *path;
    const fx_exr_chan *chans;
    group *groups;
    member *members;
    int ngroups, nmembers;
} planner;

/* Stage 1, select and group: the channels of the chosen layer and view (and layer-less
 * ones) that the selection wants, grouped by the frame pass they feed, each with its
 * priority. */
static void group_channels(planner *pl, int count, const fx_exr_crypto *cryptos, int crypto_count,
                           const fx_exr_select *sel)
{
    int warned_sampling = 0;
    for (int i = 0; i < count; i++) {
        const fx_exr_chan *c = &pl->chans[i];
        if (c->view[0] && strcmp(c->view, sel->view) != 0)
            continue;
        int layer_match = strcmp(c->layer, sel->layer) == 0;
        if (!layer_match && c->layer[0])
            continue;
        if (c->x_sampling != 1 || c->y_sampling != 1) {
            if (!warned_sampling++)
                fx_warn(pl->ctx, "'%s': channel '%s' is subsampled (%dx%d): skipped", pl->path, c->full,
                        c->x_sampling, c->y_sampling);
            continue;
        }
        /* Channels of the chosen layer beat layer-less ones; view-tagged beat untagged. */
        int prio = (layer_match && sel->layer[0] ? 2 : 0) + (c->view[0] ? 1 : 0);
        char name[FX_NAME_MAX];
        int id = channel_pass(c, cryptos, crypto_count, name);
        if (id == -2) {
            fx_warn(pl->ctx, "'%s': channel '%s' has a pass name too long for libfx: skipped", pl->path, c->full);
            continue;
        }
        if (!sel->all && id != FX_PASS_COMBINED && (id < 0 || !(sel->wanted & FX_PASS_BIT(id))))
            continue;

        group *groups = pl->groups;
        int g = 0;
        while (g < pl->ngroups && strcmp(groups[g].name, name) != 0)
            g++;
        if (g == pl->ngroups) {
            strcpy(groups[g].name, name);
            groups[g].id = id;
            groups[g].best = prio;
            pl->ngroups++;
        } else if (prio > groups[g].best) {
            groups[g].best = prio;
        }
        member *m = &pl->members[pl->nmembers++];
        m->chan = i;
        m->prio = prio;
        m->group = g;
    }
}

/* Stage 2a, a pass libfx knows: channels to slots by letter, then unexpected letters by
 * position; Combined also turns one colour channel into gray and is opaque without alpha. */
static void fill_known_pass(const planner *pl, fx_exr_plan_pass *p, const int *mine, int nm)
{
    const fx_pass_desc *d = fx_pass_describe((fx_pass_id)p->id);
    p->channels = d->channels;
    int unmatched[FX_EXR_NAME_MAX], nu = 0;
    int gray = -1; /* a Y channel */
    for (int k = 0; k < nm; k++) {
        char letter[FX_EXR_NAME_MAX];
        fx_exr_channel_letter(pl->chans[mine[k]].chan, letter);
        int s = d->channels == 1 ? 0 : letter_slot(d->channel_names, letter);
        if (p->id == FX_PASS_COMBINED && strcmp(letter, "Y") == 0) {
            gray = mine[k];
            continue;
        }
        if (s >= 0 && p->src[s] < 0)
            p->src[s] = mine[k];
        else if (s < 0 && strcmp(letter, "A") != 0) /* colour passes drop A */
            unmatched[nu++] = mine[k];
    }
    /* Letters libfx does not expect (Normal written as R,G,B): by position. */
    for (int k = 0, s = 0; k < nu; k++) {
        while (s < d->channels && p->src[s] >= 0)
            s++;
        if (s == d->channels) {
            fx_warn(pl->ctx, "'%s': channel '%s' does not fit pass %s: skipped", pl->path,
                    pl->chans[unmatched[k]].full, p->name);
            continue;
        }
        p->src[s] = unmatched[k];
    }
    if (p->id == FX_PASS_COMBINED) {
        int have = (p->src[0] >= 0) + (p->src[1] >= 0) + (p->src[2] >= 0);
        if (have == 0 && gray >= 0) {
            p->src[0] = gray;
            have = 1;
        }
        if (have == 1) {
            /* One colour channel (Y, or a lone G): a gray image, not a tinted one. */
            int s = p->src[0] >= 0 ? 0 : p->src[1] >= 0 ? 1 : 2;
            for (int t = 0; t < 3; t++)
                if (t != s)
                    p->copy_from[t] = s;
        }
        if (p->src[3] < 0)
            p->fill[3] = 1.0f; /* no alpha: opaque */
    }
}

/* Stage 2b, a pass libfx does not know: its channels in the usual letter order, at most 4. */
static void fill_unknown_pass(const planner *pl, fx_exr_plan_pass *p, int *mine, int nm)
{
    /* EXR sorts channels by name (G before R): restore the usual letter order. */
    int rank[FX_EXR_NAME_MAX];
    for (int k = 0; k < nm; k++)
        rank[k] = unknown_rank(pl->chans[mine[k]].chan, k);
    for (int k = 1; k < nm; k++)
        for (int j = k; j > 0 && rank[j] < rank[j - 1]; j--) {
            int t = rank[j];
            rank[j] = rank[j - 1], rank[j - 1] = t;
            t = mine[j];
            mine[j] = mine[j - 1], mine[j - 1] = t;
        }
    if (nm > 4)
        fx_warn(pl->ctx, "'%s': pass '%s' has %d channels, libfx keeps the first 4", pl->path, p->name, nm);
    p->channels = nm > 4 ? 4 : nm;
    for (int k = 0; k < p->channels; k++)
        p->src[k] = mine[k];
}

/* Stage 2, one pass per group, fed only by the group's best source: never R from one
 * layer and A from another. Returns 1 when the pass has channels. */
static int plan_group(const planner *pl, int g, fx_exr_plan_pass *p)
{
    strcpy(p->name, pl->groups[g].name);
    p->id = pl->groups[g].id;
    for (int s = 0; s < 4; s++) {
        p->src[s] = -1;
        p->fill[s] = 0.0f;
        p->copy_from[s] = -1;
    }
    int mine[FX_EXR_NAME_MAX], nm = 0;
    for (int m = 0; m < pl->nmembers; m++)
        if (pl->members[m].group == g && pl->members[m].prio == pl->groups[g].best && nm < FX_EXR_NAME_MAX)
            mine[nm++] = pl->members[m].chan;
    if (p->id >= 0)
        fill_known_pass(pl, p, mine, nm);
    else
        fill_unknown_pass(pl, p, mine, nm);
    return p->channels > 0;
}

fx_result fx_exr_plan(fx_context *ctx, const char *path, const fx_exr_chan *chans, int count,
                      const fx_exr_crypto *cryptos, int crypto_count, const fx_exr_select *sel,
                      fx_exr_plan_pass **out, int *out_count)
{
    *out = NULL;
    *out_count = 0;
    if (count <= 0)
        return FX_OK;
    planner pl = {ctx, path, chans, NULL, NULL, 0, 0};
    pl.groups = fx_mem_calloc((size_t)count, sizeof *pl.groups);
    pl.members = fx_mem_calloc((size_t)count, sizeof *pl.members);
    fx_exr_plan_pass *plan = fx_mem_calloc((size_t)count, sizeof *plan);
    if (!pl.groups || !pl.members || !plan) {
        fx_mem_free(pl.groups);
        fx_mem_free(pl.members);
        fx_mem_free(plan);
        return fx_fail(ctx, FX_ERR_OUT_OF_MEMORY, "out of memory planning the channels of '%s'", path);
    }
    group_channels(&pl, count, cryptos, crypto_count, sel);
    int np = 0;
    for (int g = 0; g < pl.ngroups; g++)
        np += plan_group(&pl, g, &plan[np]);
    fx_mem_free(pl.groups);
    fx_mem_free(pl.members);
    if (np == 0) {
        fx_mem_free(plan);
        plan = NULL;
    }
    *out = plan;
    *out_count = np;
    return FX_OK;
}
