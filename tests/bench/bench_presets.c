/* bench_presets: the speed/accuracy trade of every effect of a recipe, on a real frame.
 *
 *   bench_presets --passes P.exr --recipe R.json [--sidecar S.json] [--scene NAME]
 *                 [--effects a,b] [--threads 1,2] [--runs 5] [--budget-ms 6000]
 *                 [--qualities draft,preview,final,reference]
 *                 [--knob EFFECT.PARAM=v1,v2,...[@P=V;Q=W]] [--look-knob EFFECT.PARAM=v1,v2,...]
 *                 [--scaling-res 0.25,0.5,1,2,4] [--scaling-mask 25,50,75,100]
 *                 [--scaling-threads 2] [--ref-max-ms MS] [--knobs-first-threads-only]
 *                 [--label NAME] [--no-header] [-o out.csv]
 *
 * Per effect of the recipe (all enabled entries of one effect name, in recipe order, with
 * their params and masks: mirror_room's ten ssr_mirror entries run as one ten-entry stack):
 *  - kind reference/effect: the effect alone at each quality preset and at each value of
 *    its knobs, per thread count: median ms of `runs` fx_stack_run calls after one warm-up
 *    (fewer, but 3 at least, when one run takes longer than budget-ms / runs; a warm-up
 *    longer than budget-ms is the only run). Errors of Combined RGB against the reference preset's
 *    output, over the pixels the masks select (coverage > 0; every pixel without a mask):
 *    MAE and max |d| on the scene-linear values; PSNR = 10 log10(1 / MSE) on values clipped
 *    to [0, 1] (display-referred, as the peers' and the Cycles rows': with HDR suns a peak of
 *    the reference's maximum gives meaningless 130 dB figures). --knob: a quality knob (the other params as the recipe's; error
 *    against the reference preset of the recipe's params). --look-knob: a knob that
 *    changes the picture (sigma, radius, filter size): each value at `final`, against the
 *    reference preset at the same value (no error for effects without presets: identical).
 *    "@P=V;Q=W" after the values sets other params with every value (god_rays.samples=25,100
 *    @method=naive: the naive loop's sample count).
 *    Aux views (light maps, rain map) are read and built in every run (no aux cache).
 *    Outputs are hashed: a thread count that changes a bit is flagged in `note`. Errors come
 *    from the first thread count of --threads (list the fastest first); a reference slower
 *    than --ref-max-ms there is not timed again at the others (row with empty ms).
 *  - kind floor (effect = the effect it is the floor for, setting memcpy): a parallel copy of
 *    W x H RGBA floats (in + out) on the same thread pool, the median of samples taken just
 *    before and just after that effect's timings.
 *  - kind scaling_res: `final`, scaling-threads, on the frame resampled to 0.25..4 MP
 *    (same aspect; fx_frame_read_pixels per pass: Combined and light passes bilinear, every
 *    data pass nearest: IDs, Cryptomatte, depth, normals, positions are never blended).
 *  - kind scaling_mask: `final`, scaling-threads, the masks cut by a rectangle [0, 0, x, H]
 *    whose x keeps 25..100 % of the masked pixels (the whole frame without a mask).
 * --label NAME: the effect column says NAME instead of the effect's name (one effect group
 * only): a method variant of an effect benched as its own entry (bench_all's
 * "god_rays:volumetric": a recipe whose god_rays is volumetric, kept apart from the radial
 * rows of the same effect).
 * CSV (docs/performance.md): kind,scene,effect,setting,width,height,threads,runs,ms_median,
 * mae,max_err,psnr_db,mask_px,note. Progress on stderr. Run by tests/bench/bench_all.py. */
#include "core/effect.h"
#include "core/mask.h"
#include "core/parallel.h"
#include "libfx/fx.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bench_util.h"

#define MAX_LIST 32
#define MAX_RUNS 64
#define MAX_KNOBS 16

typedef struct knob {
    char effect[64], param[64];
    char values[MAX_LIST][64];
    int count;
    int look;
    char fixed[256]; /* "p=v;q=w": params set with every value (god_rays.samples@method=naive) */
} knob;

static struct {
    const char *passes, *recipe, *sidecar, *scene, *effects, *out;
    const char *label; /* --label: the effect column's name for the one group benched */
    int threads[4], nthreads;
    int runs;
    double budget_ms;
    int qualities[4], nq;
    knob knobs[MAX_KNOBS];
    int nknobs;
    double res_mp[MAX_LIST];
    int nres;
    double mask_pct[MAX_LIST];
    int nmask;
    int scaling_threads;
    int header;
    double ref_max_ms;
    int knobs_first_only;
} A;

static FILE *g_csv;

/* The name rows and progress lines give an effect: --label when set. */
static const char *row_name(const char *effect)
{
    return A.label ? A.label : effect;
}

static void die(const char *what, fx_context *ctx)
{
    fprintf(stderr, "bench_presets: %s%s%s\n", what, ctx ? ": " : "", ctx ? fx_context_error(ctx) : "");
    exit(1);
}

static int split(const char *s, char out[][64], int max)
{
    int n = 0;
    while (s && *s && n < max) {
        const char *e = strchr(s, ',');
        size_t len = e ? (size_t)(e - s) : strlen(s);
        if (len >= 64)
            len = 63;
        memcpy(out[n], s, len);
        out[n][len] = 0;
        n++;
        s = e ? e + 1 : NULL;
    }
    return n;
}

static int in_list(const char *list, const char *name)
{
    char items[MAX_LIST][64];
    int n = split(list, items, MAX_LIST);
    for (int i = 0; i < n; i++)
        if (strcmp(items[i], name) == 0)
            return 1;
    return 0;
}

/* ---- CSV ------------------------------------------------------------------ */

static void fmt_num(char *buf, size_t n, double v, const char *fmt)
{
    if (isnan(v))
        buf[0] = 0;
    else if (isinf(v))
        snprintf(buf, n, "%s", v > 0 ? "inf" : "-inf");
    else
        snprintf(buf, n, fmt, v);
}

static void csv_row(const char *kind, const char *effect, const char *setting, int w, int h, int threads,
                    int runs, double ms, double mae, double maxe, double psnr, long mask_px, const char *note)
{
    char c_ms[32], c_mae[32], c_max[32], c_psnr[32], c_px[32], c_th[16], c_runs[16], clean[256];
    fmt_num(c_ms, sizeof c_ms, ms, "%.3f");
    fmt_num(c_mae, sizeof c_mae, mae, "%.6g");
    fmt_num(c_max, sizeof c_max, maxe, "%.6g");
    fmt_num(c_psnr, sizeof c_psnr, psnr, "%.2f");
    if (mask_px >= 0)
        snprintf(c_px, sizeof c_px, "%ld", mask_px);
    else
        c_px[0] = 0;
    if (threads > 0)
        snprintf(c_th, sizeof c_th, "%d", threads);
    else
        c_th[0] = 0;
    if (runs > 0)
        snprintf(c_runs, sizeof c_runs, "%d", runs);
    else
        c_runs[0] = 0;
    snprintf(clean, sizeof clean, "%s", note ? note : "");
    for (char *p = clean; *p; p++)
        if (*p == ',' || *p == '\n' || *p == '"')
            *p = ';';
    fprintf(g_csv, "%s,%s,%s,%s,%d,%d,%s,%s,%s,%s,%s,%s,%s,%s\n", kind, A.scene, row_name(effect), setting, w, h,
            c_th, c_runs, c_ms, c_mae, c_max, c_psnr, c_px, clean);
    fflush(g_csv);
}

/* ---- the memory-bandwidth floor: a copy on libfx's own pool ---------------- */

typedef struct floor_samples {
    double ms[MAX_RUNS * 4];
    int n;
} floor_samples;

static void floor_sample(fx_context *ctx, const float *src, float *dst, int w, int h, floor_samples *fs, int k)
{
    bench_copy_job j = {src, dst, w};
    fx_parallel_for(ctx, h, fx_grain_for(ctx, h), bench_copy_rows, &j); /* warm */
    for (int i = 0; i < k && fs->n < MAX_RUNS * 4; i++) {
        double t0 = now_ms();
        fx_parallel_for(ctx, h, fx_grain_for(ctx, h), bench_copy_rows, &j);
        fs->ms[fs->n++] = now_ms() - t0;
    }
}

/* ---- recipes -------------------------------------------------------------- */

/* One-effect recipe: the group's entries, the stack's quality, a knob value on every entry,
 * and optionally a rectangle intersected with each entry's mask. */
static void set_json_param(cJSON *p, const fx_param_info *info, const char *name, const char *value)
{
    cJSON_DeleteItemFromObject(p, name);
    switch (info->type) {
    case FX_PARAM_FLOAT:
    case FX_PARAM_INT:
        cJSON_AddNumberToObject(p, name, atof(value));
        break;
    case FX_PARAM_BOOL:
        cJSON_AddBoolToObject(p, name, strcmp(value, "true") == 0 || strcmp(value, "1") == 0);
        break;
    default:
        cJSON_AddStringToObject(p, name, value);
    }
}

static const fx_param_info *find_param(const char *effect, const char *name);

static char *make_recipe(const cJSON *entries, int quality, const knob *kn, const char *kvalue, const int *rect)
{
    cJSON *root = cJSON_CreateObject();
    cJSON_AddNumberToObject(root, "version", 1);
    cJSON_AddStringToObject(root, "quality", fx_quality_name(quality));
    cJSON *arr = cJSON_AddArrayToObject(root, "effects");
    const cJSON *e;
    cJSON_ArrayForEach(e, entries) {
        cJSON *c = cJSON_Duplicate(e, 1);
        cJSON_DeleteItemFromObject(c, "quality");
        if (kn && kvalue) {
            cJSON *p = cJSON_GetObjectItem(c, "params");
            if (!p)
                p = cJSON_AddObjectToObject(c, "params");
            set_json_param(p, find_param(kn->effect, kn->param), kn->param, kvalue);
            char fixed[256], *save = NULL;
            snprintf(fixed, sizeof fixed, "%s", kn->fixed);
            for (char *t = strtok_r(fixed, ";", &save); t; t = strtok_r(NULL, ";", &save)) {
                char *eq = strchr(t, '=');
                const fx_param_info *fi = eq ? (*eq = 0, find_param(kn->effect, t)) : NULL;
                if (!fi) {
                    fprintf(stderr, "bench_presets: %s has no parameter '%s'\n", kn->effect, t);
                    exit(2);
                }
                set_json_param(p, fi, t, eq + 1);
            }
        }
        if (rect) {
            cJSON *m = cJSON_GetObjectItem(c, "mask");
            if (!m)
                m = cJSON_AddObjectToObject(c, "mask");
            cJSON_DeleteItemFromObject(m, "rect");
            cJSON_AddItemToObject(m, "rect", cJSON_CreateIntArray(rect, 4));
        }
        cJSON_AddItemToArray(arr, c);
    }
    char *s = cJSON_PrintUnformatted(root);
    cJSON_Delete(root);
    return s;
}

/* Union of the entries' masks as a coverage image; NULL when some entry selects everything. */
static float *union_mask(fx_context *ctx, const cJSON *entries, const fx_frame *f, long *px)
{
    int w = fx_frame_width(f), h = fx_frame_height(f);
    size_t n = (size_t)w * h;
    float *u = calloc(n, sizeof(float));
    const cJSON *e;
    cJSON_ArrayForEach(e, entries) {
        const cJSON *m = cJSON_GetObjectItem(e, "mask");
        fx_mask_spec spec;
        if (fx_mask_spec_parse(ctx, m, "bench mask", &spec))
            die("mask", ctx);
        fx_mask *mask = NULL;
        if (fx_mask_build(ctx, &spec, f, "bench mask", &mask))
            die("mask", ctx);
        fx_mask_spec_clear(&spec);
        if (!mask) {
            free(u);
            *px = (long)n;
            return NULL;
        }
        for (size_t i = 0; i < n; i++)
            if (mask->coverage[i] > u[i])
                u[i] = mask->coverage[i];
        fx_mask_free(mask);
    }
    long c = 0;
    for (size_t i = 0; i < n; i++)
        c += u[i] > 0.0f;
    *px = c;
    return u;
}

/* ---- running -------------------------------------------------------------- */

static uint64_t hash_rgba(const float *p, size_t n)
{
    const unsigned char *b = (const unsigned char *)p;
    uint64_t h = 1469598103934665603ull;
    for (size_t i = 0; i < n * sizeof(float); i++)
        h = (h ^ b[i]) * 1099511628211ull;
    return h;
}

/* Runs the recipe on f: one warm-up (its Combined copied to *keep if asked), then timed
 * runs. Returns the median ms and the runs taken in *runs_out. */
/* The input read once per context (g_frames[t] by g_ctxs[t]), so each thread count is
 * timed on a frame of its own context, as a one-context caller runs. (Until the library's
 * fix of 2026-12-03, a stack run on a frame another context read gave its result's buffers
 * to that context's store and took fresh pages every run: the 1-thread column, timed in the
 * second context, was 3-10x slow.) */
static fx_context *g_ctxs[4];
static fx_frame *g_frames[4];
static int g_nframes;

/* The frame to time ctx on: its own copy of the input when f is the input. */
static const fx_frame *frame_for(fx_context *ctx, const fx_frame *f)
{
    if (g_nframes && f == g_frames[0])
        for (int t = 0; t < g_nframes; t++)
            if (g_ctxs[t] == ctx)
                return g_frames[t];
    return f;
}

static double time_recipe(fx_context *ctx, const char *json, const fx_frame *f, int runs, float **keep,
                          uint64_t *hash, int *runs_out)
{
    f = frame_for(ctx, f);
    fx_stack *s = NULL;
    if (fx_stack_new(ctx, &s) || fx_stack_load_json(s, json)) {
        fprintf(stderr, "recipe: %s\n", json);
        die("stack", ctx);
    }
    size_t n = (size_t)fx_frame_width(f) * fx_frame_height(f) * 4;
    fx_frame *o = NULL;
    double t0 = now_ms();
    if (fx_stack_run(s, f, &o))
        die("run", ctx);
    double warm = now_ms() - t0;
    float *px = NULL;
    int ch = 0;
    fx_frame_pass(o, "Combined", &px, &ch);
    if (hash)
        *hash = hash_rgba(px, n);
    if (keep) {
        *keep = malloc(n * sizeof(float));
        memcpy(*keep, px, n * sizeof(float));
    }
    fx_frame_free(o);
    double t[MAX_RUNS];
    int k = runs;
    if (warm > A.budget_ms) {
        /* one run is over the budget: the warm-up is the measurement */
        fx_stack_free(s);
        *runs_out = 1;
        return warm;
    }
    if (warm * k > A.budget_ms)
        k = (int)(A.budget_ms / (warm > 1e-3 ? warm : 1e-3));
    if (k < 3)
        k = runs < 3 ? runs : 3; /* a median of three at least, when one run fits the budget */
    if (k > MAX_RUNS)
        k = MAX_RUNS;
    for (int i = 0; i < k; i++) {
        t0 = now_ms();
        if (fx_stack_run(s, f, &o))
            die("run", ctx);
        t[i] = now_ms() - t0;
        fx_frame_free(o);
    }
    fx_stack_free(s);
    *runs_out = k;
    return median_d(t, k);
}

/* Errors of a's RGB against ref's over the mask (coverage > 0; NULL: every pixel). */
static void errors(const float *a, const float *ref, const float *mask, size_t npx, double *mae, double *maxe,
                   double *psnr)
{
    double s = 0, s2 = 0, m = 0;
    size_t cnt = 0;
    for (size_t i = 0; i < npx; i++) {
        if (mask && !(mask[i] > 0.0f))
            continue;
        for (int c = 0; c < 3; c++) {
            double r = ref[i * 4 + c], d = fabs((double)a[i * 4 + c] - r);
            s += d;
            if (d > m)
                m = d;
            double ac = fmin(fmax(a[i * 4 + c], 0.0), 1.0), rc = fmin(fmax(r, 0.0), 1.0);
            s2 += (ac - rc) * (ac - rc);
        }
        cnt += 3;
    }
    if (!cnt) {
        *mae = *maxe = *psnr = NAN;
        return;
    }
    *mae = s / cnt;
    *maxe = m;
    double mse = s2 / cnt;
    *psnr = mse > 0 ? 10 * log10(1.0 / mse) : INFINITY; /* identical (after the clip) */
}

typedef struct setting {
    char label[96];
    const char *kind;
    int quality;
    const knob *k;
    int value;      /* index into k->values */
    uint64_t hash;  /* output of the first thread count */
    double first_ms; /* median at the first thread count */
    double mae, maxe, psnr;
    int have_err, identical;
} setting;

static int effect_has_presets(fx_context *ctx, const char *effect, int *halo)
{
    char *js = NULL;
    if (fx_effect_describe_json(ctx, effect, &js))
        die("describe", ctx);
    cJSON *d = cJSON_Parse(js);
    fx_free(js);
    const cJSON *p = cJSON_GetObjectItem(d, "presets");
    int has = p && cJSON_IsObject(p) && cJSON_GetArraySize(p) > 0;
    const cJSON *hl = cJSON_GetObjectItem(d, "halo");
    *halo = hl ? hl->valueint : 0;
    cJSON_Delete(d);
    return has;
}

static const fx_param_info *find_param(const char *effect, const char *name)
{
    int n = fx_effect_param_count(effect);
    for (int i = 0; i < n; i++) {
        const fx_param_info *p = fx_effect_param(effect, i);
        if (strcmp(p->name, name) == 0)
            return p;
    }
    return NULL;
}

/* ---- resampling (scaling rows) ------------------------------------------- */

/* The library's display resampling (fx_frame_read_pixels: bilinear for colour and light
 * passes, nearest for IDs, depth, normals...; pixel centres aligned), pass by pass. */
static fx_frame *resample(fx_context *ctx, const fx_frame *src, int W, int H, const char *sidecar)
{
    fx_frame *f = NULL;
    if (fx_frame_new(ctx, W, H, &f))
        die("frame", ctx);
    float *rgba = malloc((size_t)W * H * 4 * sizeof(float));
    for (int p = 0; p < fx_frame_pass_count(src); p++) {
        const char *name = fx_frame_pass_name(src, p);
        int ch = fx_frame_pass_channels(src, p);
        if (fx_frame_read_pixels(src, name, W, H, 0, rgba))
            die("resample", ctx);
        float *out = malloc((size_t)W * H * ch * sizeof(float));
        for (size_t i = 0; i < (size_t)W * H; i++)
            for (int c = 0; c < ch; c++)
                out[i * ch + c] = rgba[i * 4 + c];
        if (fx_frame_add_pass(f, name, ch, out))
            die("add pass", ctx);
        free(out);
    }
    free(rgba);
    fx_camera cam;
    if (fx_frame_camera(src, &cam))
        fx_frame_set_camera(f, &cam);
    double fr, fps;
    fx_frame_time(src, &fr, &fps);
    fx_frame_set_time(f, fr, fps);
    if (sidecar && fx_frame_apply_sidecar_file(f, sidecar))
        die("sidecar", ctx);
    return f;
}

/* ---- one effect ----------------------------------------------------------- */

/* One effect's benchmark: what its stages share. */
typedef struct effect_bench {
    const char *effect;
    const cJSON *entries;
    const fx_frame *f;
    fx_context **ctxs;
    int w, h;
    size_t npx;
    int presets;
    float *mask; /* the union of the entries' masks, or NULL */
    long mask_px;
    char base_note[160];
    setting st[4 + MAX_KNOBS * MAX_LIST];
    int ns;
} effect_bench;

/* The note every row of this effect carries: entries, aux views, presets. */
static void bench_note(effect_bench *b)
{
    const char *effect = b->effect;
    const cJSON *entries = b->entries;
    fx_context *c0 = b->ctxs[0];
    char *base_note = b->base_note;
    const int nentries = cJSON_GetArraySize(entries), presets = b->presets;
    int has_aux = 0;
    {
        char *r = make_recipe(entries, FX_QUALITY_FINAL, NULL, NULL, NULL), *aux = NULL;
        fx_stack *s = NULL;
        fx_stack_new(c0, &s);
        if (fx_stack_load_json(s, r))
            die(effect, c0);
        fx_stack_required_aux_views(s, &aux);
        has_aux = aux && strstr(aux, "\"name\"") != NULL;
        fx_free(aux);
        fx_stack_free(s);
        free(r);
    }
    if (nentries > 1)
        snprintf(base_note, sizeof b->base_note, "%d recipe entries", nentries);
    if (has_aux)
        snprintf(base_note + strlen(base_note), sizeof b->base_note - strlen(base_note), "%saux views read and built every run",
                 base_note[0] ? "; " : "");
    if (!presets)
        snprintf(base_note + strlen(base_note), sizeof b->base_note - strlen(base_note), "%sno quality presets",
                 base_note[0] ? "; " : "");
}

/* The settings: reference first (its output is what the others are measured against),
 * the asked-for qualities, then each knob value. */
static void bench_settings(effect_bench *b)
{
    const char *effect = b->effect;
    setting *st = b->st;
    int ns = 0;
    int qorder[4] = {FX_QUALITY_REFERENCE, FX_QUALITY_DRAFT, FX_QUALITY_PREVIEW, FX_QUALITY_FINAL};
    for (int qi = 0; qi < 4; qi++) {
        int q = qorder[qi], want = 0;
        for (int k = 0; k < A.nq; k++)
            want |= A.qualities[k] == q;
        if (!want && q != FX_QUALITY_REFERENCE)
            continue;
        setting *s = &st[ns++];
        memset(s, 0, sizeof *s);
        snprintf(s->label, sizeof s->label, "quality=%s", fx_quality_name(q));
        s->kind = q == FX_QUALITY_REFERENCE ? "reference" : "effect";
        s->quality = q;
    }
    for (int k = 0; k < A.nknobs; k++) {
        const knob *kn = &A.knobs[k];
        if (strcmp(kn->effect, effect) != 0)
            continue;
        if (!find_param(effect, kn->param)) {
            fprintf(stderr, "bench_presets: %s has no parameter '%s' (libfx describe %s)\n", effect, kn->param, effect);
            exit(2);
        }
        for (int v = 0; v < kn->count; v++) {
            setting *s = &st[ns++];
            memset(s, 0, sizeof *s);
            snprintf(s->label, sizeof s->label, "%s=%s%s%s", kn->param, kn->values[v], kn->fixed[0] ? " " : "",
                     kn->fixed);
            s->kind = "effect";
            s->quality = FX_QUALITY_FINAL;
            s->k = kn;
            s->value = v;
        }
    }
    b->ns = ns;
}

/* One setting at one thread count: timed, its error against the reference (first
 * thread count), its row. */
static void bench_setting(effect_bench *b, int ti, setting *s, float **refp)
{
    const char *effect = b->effect;
    const cJSON *entries = b->entries;
    const fx_frame *f = b->f;
    const int w = b->w, h = b->h;
    const size_t npx = b->npx;
    const float *mask = b->mask;
    const long mask_px = b->mask_px;
    const int presets = b->presets;
    const char *base_note = b->base_note;
    fx_context **ctxs = b->ctxs;
    fx_context *ctx = ctxs[ti];
    const setting *st = b->st;
    const int th = fx_context_threads(ctx);
    if (ti > 0 && s->k && A.knobs_first_only)
        return; /* knob sweeps at the first thread count only */
    char *json = make_recipe(entries, s->quality, s->k, s->k ? s->k->values[s->value] : NULL, NULL);
    float *out = NULL;
    uint64_t hsh = 0;
    int runs = 0;
    int first = ti == 0;
    if (!first && s->kind[0] == 'r' && A.ref_max_ms > 0 && s->first_ms > A.ref_max_ms) {
        /* a slow reference (god_rays' 2000-sample loop) is timed at the first thread count only */
        char note[320];
        snprintf(note, sizeof note, "%s%snot timed: one run took %.1f s with %d threads (over --ref-max-ms)",
                 base_note, base_note[0] ? "; " : "", s->first_ms / 1e3, fx_context_threads(ctxs[0]));
        csv_row(s->kind, effect, s->label, w, h, th, 0, NAN, NAN, NAN, NAN, mask_px, note);
        free(json);
        return;
    }
    int want_ref = first && s->kind[0] == 'r';
    double ms = time_recipe(ctx, json, f, A.runs, first ? (want_ref ? refp : &out) : NULL, &hsh, &runs);
    free(json);
    char note[320];
    snprintf(note, sizeof note, "%s", base_note);
    if (first) {
        s->hash = hsh;
        s->first_ms = ms;
        if (want_ref) {
            s->have_err = 0; /* it is the reference */
        } else if (s->k && s->k->look) {
            if (presets) {
                /* the reference preset at the same knob value */
                char *rj = make_recipe(entries, FX_QUALITY_REFERENCE, s->k, s->k->values[s->value], NULL);
                float *r2 = NULL;
                uint64_t h2;
                int rr;
                double save = A.budget_ms;
                A.budget_ms = 0; /* one run: the output only */
                time_recipe(ctx, rj, f, 1, &r2, &h2, &rr);
                A.budget_ms = save;
                free(rj);
                errors(out, r2, mask, npx, &s->mae, &s->maxe, &s->psnr);
                s->have_err = 1;
                s->identical = h2 == hsh;
                free(r2);
            }
        } else if (*refp) {
            errors(out, *refp, mask, npx, &s->mae, &s->maxe, &s->psnr);
            s->have_err = 1;
            s->identical = hsh == st[0].hash;
        }
        free(out);
    } else if (hsh != s->hash) {
        size_t l = strlen(note);
        snprintf(note + l, sizeof note - l, "%sOUTPUT DIFFERS FROM %d THREADS", l ? "; " : "",
                 fx_context_threads(ctxs[0]));
    }
    if (s->k && s->k->look) {
        size_t l = strlen(note);
        snprintf(note + l, sizeof note - l, "%slook knob at final: error vs reference preset at the same value",
                 l ? "; " : "");
        if (!presets)
            snprintf(note + strlen(note), sizeof note - strlen(note), " (no presets: none)");
    } else if (s->k) {
        size_t l = strlen(note);
        snprintf(note + l, sizeof note - l, "%sknob at final", l ? "; " : "");
    }
    if (s->have_err && s->identical && s->kind[0] != 'r') {
        size_t l = strlen(note);
        snprintf(note + l, sizeof note - l, "%sbit-identical to reference", l ? "; " : "");
    }
    csv_row(s->kind, effect, s->label, w, h, th, runs, ms, s->have_err ? s->mae : NAN,
            s->have_err ? s->maxe : NAN, s->have_err ? s->psnr : NAN, mask_px, note);
    fprintf(stderr, "bench_presets: [%s %dx%d] %s %s, %d thread%s: %.2f ms (%d run%s)\n", A.scene, w, h,
            row_name(effect), s->label, th, th == 1 ? "" : "s", ms, runs, runs == 1 ? "" : "s");
}

/* Every setting at every thread count, between two samples of the memcpy floor. */
static void bench_threads(effect_bench *b)
{
    const char *effect = b->effect;
    const int w = b->w, h = b->h;
    const size_t npx = b->npx;
    fx_context **ctxs = b->ctxs;
    floor_samples fl[4];
    memset(fl, 0, sizeof fl);
    float *ref = NULL;
    for (int ti = 0; ti < A.nthreads; ti++) {
        fx_context *ctx = ctxs[ti];
        int th = fx_context_threads(ctx);
        {
            float *fa = malloc(npx * 16), *fb = malloc(npx * 16);
            memset(fa, 0, npx * 16);
            floor_sample(ctx, fa, fb, w, h, &fl[ti], A.runs);
            free(fa);
            free(fb);
        }
        for (int si = 0; si < b->ns; si++)
            bench_setting(b, ti, &b->st[si], &ref);
        /* a second floor sample after the effect's timings */
        float *fa = malloc(npx * 16), *fb = malloc(npx * 16);
        memset(fa, 0, npx * 16);
        floor_sample(ctx, fa, fb, w, h, &fl[ti], A.runs);
        free(fa);
        free(fb);
        char note[128];
        snprintf(note, sizeof note, "parallel copy of %dx%d RGBA float; same run as %s", w, h, row_name(effect));
        csv_row("floor", effect, "memcpy", w, h, th, fl[ti].n, median_d(fl[ti].ms, fl[ti].n), NAN,
                NAN, NAN, -1, note);
    }
    free(ref);
}

/* Scaling rows at `final`: the frame resampled to each size. */
static void bench_scaling_res(effect_bench *b, fx_context *sc, const char *final_json)
{
    const char *effect = b->effect;
    const cJSON *entries = b->entries;
    const fx_frame *f = b->f;
    const int w = b->w, h = b->h;
    const char *base_note = b->base_note;
    const int sth = fx_context_threads(sc);
    for (int ri = 0; ri < A.nres; ri++) {
        double mp = A.res_mp[ri];
        double aspect = (double)w / h;
        int W = (int)lround(sqrt(mp * 1e6 * aspect)), H = (int)lround(sqrt(mp * 1e6 / aspect));
        W += W & 1;
        H += H & 1;
        fx_frame *g = (W == w && H == h) ? NULL : resample(sc, f, W, H, A.sidecar);
        const fx_frame *use = g ? g : f;
        long px = 0;
        float *m2 = union_mask(sc, entries, use, &px);
        free(m2);
        int runs = 0;
        double ms = time_recipe(sc, final_json, use, A.runs, NULL, NULL, &runs);
        char setting_s[32], note[256];
        snprintf(setting_s, sizeof setting_s, "mp=%g", mp);
        if (g)
            snprintf(note, sizeof note, "quality=final; resampled from %dx%d (data passes nearest)%s%s", w, h,
                     base_note[0] ? "; " : "", base_note);
        else
            snprintf(note, sizeof note, "quality=final; the frame as rendered%s%s", base_note[0] ? "; " : "",
                     base_note);
        csv_row("scaling_res", effect, setting_s, W, H, sth, runs, ms, NAN, NAN, NAN, px, note);
        fprintf(stderr, "bench_presets: [%s] %s scaling %dx%d (%.2f MP): %.2f ms\n", A.scene, row_name(effect), W, H,
                W * (double)H / 1e6, ms);
        fx_frame_free(g);
    }
}

/* Scaling rows at `final`: the masks cut to a share of their pixels. */
static void bench_scaling_mask(effect_bench *b, fx_context *sc)
{
    const char *effect = b->effect;
    const cJSON *entries = b->entries;
    const fx_frame *f = b->f;
    const int w = b->w, h = b->h;
    const float *mask = b->mask;
    const char *base_note = b->base_note;
    const int sth = fx_context_threads(sc);
    /* columns holding the masked pixels, cumulative */
    long *cum = calloc((size_t)w + 1, sizeof(long));
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            cum[x + 1] += (!mask || mask[(size_t)y * w + x] > 0.0f);
    for (int x = 0; x < w; x++)
        cum[x + 1] += cum[x];
    for (int mi = 0; mi < A.nmask; mi++) {
        double pct = A.mask_pct[mi];
        long want = (long)ceil(pct / 100.0 * cum[w]);
        int x = 0;
        while (x < w && cum[x] < want)
            x++;
        int rect[4] = {0, 0, x, h};
        char *json = make_recipe(entries, FX_QUALITY_FINAL, NULL, NULL, rect);
        int runs = 0;
        double ms = time_recipe(sc, json, f, A.runs, NULL, NULL, &runs);
        free(json);
        char setting_s[32], note[256];
        snprintf(setting_s, sizeof setting_s, "mask=%g%%", pct);
        snprintf(note, sizeof note, "quality=final; masks cut by rect [0 0 %d %d]%s%s", x, h,
                 base_note[0] ? "; " : "", base_note);
        csv_row("scaling_mask", effect, setting_s, w, h, sth, runs, ms, NAN, NAN, NAN, cum[x], note);
        fprintf(stderr, "bench_presets: [%s] %s mask %g%% (%ld px): %.2f ms\n", A.scene, row_name(effect), pct,
                cum[x], ms);
    }
    free(cum);
}

static void bench_effect(const char *effect, const cJSON *entries, const fx_frame *f, fx_context **ctxs)
{
    effect_bench *b = calloc(1, sizeof *b);
    if (!b)
        die(effect, ctxs[0]);
    b->effect = effect;
    b->entries = entries;
    b->f = f;
    b->ctxs = ctxs;
    b->w = fx_frame_width(f);
    b->h = fx_frame_height(f);
    b->npx = (size_t)b->w * b->h;
    int halo = 0;
    b->presets = effect_has_presets(ctxs[0], effect, &halo);
    b->mask = union_mask(ctxs[0], entries, f, &b->mask_px);
    bench_note(b);
    bench_settings(b);
    bench_threads(b);
    /* scaling rows at `final` */
    fx_context *sc = NULL;
    for (int ti = 0; ti < A.nthreads; ti++)
        if (fx_context_threads(ctxs[ti]) == A.scaling_threads)
            sc = ctxs[ti];
    if (!sc)
        sc = ctxs[A.nthreads - 1];
    char *final_json = make_recipe(entries, FX_QUALITY_FINAL, NULL, NULL, NULL);
    bench_scaling_res(b, sc, final_json);
    if (A.nmask > 0)
        bench_scaling_mask(b, sc);
    free(final_json);
    free(b->mask);
    free(b);
}

/* ---- main ------------------------------------------------------------------ */

static void usage(void)
{
    fprintf(stderr, "usage: bench_presets --passes P.exr --recipe R.json [--sidecar S.json] [--scene NAME]\n"
                    "  [--effects a,b] [--threads 1,2] [--runs 5] [--budget-ms 6000]\n"
                    "  [--qualities draft,preview,final,reference] [--knob EFFECT.PARAM=v1,v2[@P=V;Q=W]]\n"
                    "  [--look-knob EFFECT.PARAM=v1,v2] [--scaling-res 0.25,0.5,1,2,4]\n"
                    "  [--scaling-mask 25,50,75,100] [--scaling-threads 2] [--ref-max-ms 0] [--knobs-first-threads-only]\n"
                    "  [--label NAME] [--no-header] [-o out.csv]\n");
    exit(2);
}

static void parse_knob(const char *arg, int look)
{
    if (A.nknobs >= MAX_KNOBS)
        usage();
    knob *k = &A.knobs[A.nknobs++];
    memset(k, 0, sizeof *k);
    const char *dot = strchr(arg, '.'), *eq = strchr(arg, '=');
    if (!dot || !eq || eq < dot || dot - arg >= 64 || eq - dot - 1 >= 64)
        usage();
    memcpy(k->effect, arg, (size_t)(dot - arg));
    memcpy(k->param, dot + 1, (size_t)(eq - dot - 1));
    char vals[1024];
    snprintf(vals, sizeof vals, "%s", eq + 1);
    char *at = strchr(vals, '@');
    if (at) {
        *at = 0;
        snprintf(k->fixed, sizeof k->fixed, "%s", at + 1);
    }
    k->count = split(vals, k->values, MAX_LIST);
    k->look = look;
}

static int parse_doubles(const char *s, double *out, int max)
{
    char items[MAX_LIST][64];
    int n = split(s, items, max < MAX_LIST ? max : MAX_LIST);
    for (int i = 0; i < n; i++)
        out[i] = atof(items[i]);
    return n;
}

/* The command line into A (usage() on a bad one). */
static void parse_args(int argc, char **argv)
{
    A.scene = "";
    A.runs = 5;
    A.budget_ms = 6000;
    A.threads[0] = 1, A.threads[1] = 2, A.nthreads = 2;
    A.qualities[0] = 0, A.qualities[1] = 1, A.qualities[2] = 2, A.qualities[3] = 3, A.nq = 4;
    A.scaling_threads = 2;
    A.header = 1;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
#define OPT(name) (strcmp(a, name) == 0 && v && (i++, 1))
        if (OPT("--passes"))
            A.passes = v;
        else if (OPT("--recipe"))
            A.recipe = v;
        else if (OPT("--sidecar"))
            A.sidecar = v;
        else if (OPT("--scene"))
            A.scene = v;
        else if (OPT("--effects"))
            A.effects = v;
        else if (OPT("--label"))
            A.label = v;
        else if (OPT("-o"))
            A.out = v;
        else if (OPT("--runs"))
            A.runs = atoi(v) < 1 ? 1 : atoi(v) > MAX_RUNS ? MAX_RUNS : atoi(v);
        else if (OPT("--budget-ms"))
            A.budget_ms = atof(v);
        else if (OPT("--threads")) {
            double t[4];
            A.nthreads = parse_doubles(v, t, 4);
            for (int k = 0; k < A.nthreads; k++)
                A.threads[k] = (int)t[k];
        } else if (OPT("--qualities")) {
            char q[4][64];
            A.nq = split(v, q, 4);
            for (int k = 0; k < A.nq; k++)
                if ((A.qualities[k] = fx_quality_from_name(q[k])) < 0)
                    usage();
        } else if (OPT("--knob"))
            parse_knob(v, 0);
        else if (OPT("--look-knob"))
            parse_knob(v, 1);
        else if (OPT("--scaling-res"))
            A.nres = parse_doubles(v, A.res_mp, MAX_LIST);
        else if (OPT("--scaling-mask"))
            A.nmask = parse_doubles(v, A.mask_pct, MAX_LIST);
        else if (OPT("--scaling-threads"))
            A.scaling_threads = atoi(v);
        else if (OPT("--ref-max-ms"))
            A.ref_max_ms = atof(v);
        else if (strcmp(a, "--knobs-first-threads-only") == 0)
            A.knobs_first_only = 1;
        else if (strcmp(a, "--no-header") == 0)
            A.header = 0;
        else
            usage();
#undef OPT
    }
    if (!A.passes || !A.recipe || A.nthreads < 1)
        usage();
}

/* Every effect of the recipe in recipe order, each with all its enabled entries (the
 * mirror room's ten ssr_mirror entries run as one stack). */
static void bench_groups(const cJSON *effects, const fx_frame *f, fx_context **ctxs)
{
    /* effect groups in recipe order */
    char done[MAX_LIST][64];
    int ndone = 0;
    const cJSON *e;
    cJSON_ArrayForEach(e, effects) {
        const cJSON *name = cJSON_GetObjectItem(e, "effect"), *en = cJSON_GetObjectItem(e, "enabled");
        if (!cJSON_IsString(name) || (en && cJSON_IsFalse(en)))
            continue;
        int seen = 0;
        for (int k = 0; k < ndone; k++)
            seen |= strcmp(done[k], name->valuestring) == 0;
        if (seen || ndone >= MAX_LIST || (A.effects && !in_list(A.effects, name->valuestring)))
            continue;
        if (A.label && ndone == 1) {
            /* two groups under one label would be one entry's rows in the CSV */
            fprintf(stderr, "bench_presets: --label %s names one effect, the recipe has %s and %s (--effects)\n",
                    A.label, done[0], name->valuestring);
            exit(2);
        }
        snprintf(done[ndone++], 64, "%s", name->valuestring);
        cJSON *group = cJSON_CreateArray();
        const cJSON *g;
        cJSON_ArrayForEach(g, effects) {
            const cJSON *gn = cJSON_GetObjectItem(g, "effect"), *ge = cJSON_GetObjectItem(g, "enabled");
            if (cJSON_IsString(gn) && strcmp(gn->valuestring, name->valuestring) == 0 && !(ge && cJSON_IsFalse(ge)))
                cJSON_AddItemToArray(group, cJSON_Duplicate(g, 1));
        }
        bench_effect(name->valuestring, group, f, ctxs);
        cJSON_Delete(group);
    }
}

int main(int argc, char **argv)
{
    parse_args(argc, argv);
    g_csv = stdout;
    if (A.out && !(g_csv = fopen(A.out, A.header ? "w" : "a"))) {
        perror(A.out);
        return 1;
    }
    if (A.header)
        fprintf(g_csv, "kind,scene,effect,setting,width,height,threads,runs,ms_median,mae,max_err,psnr_db,mask_px,note\n");

    fx_context *ctxs[4];
    for (int t = 0; t < A.nthreads; t++) {
        if (fx_context_new(&ctxs[t], A.threads[t]))
            die("context", NULL);
        fx_context_set_aux_cache(ctxs[t], 0);
    }
    char *rtext = NULL;
    if (fx_read_text_file(ctxs[0], A.recipe, 16u << 20, "recipe", &rtext))
        die("recipe", ctxs[0]);
    cJSON *recipe = cJSON_Parse(rtext);
    fx_free(rtext);
    const cJSON *effects = recipe ? cJSON_GetObjectItem(recipe, "effects") : NULL;
    if (!cJSON_IsArray(effects))
        die("the recipe has no \"effects\" array", NULL);
    double t0 = now_ms();
    for (int t = 0; t < A.nthreads; t++) {
        fx_frame *ft = NULL;
        if (fx_frame_read_exr(ctxs[t], A.passes, NULL, &ft))
            die("read", ctxs[t]);
        if (A.sidecar && fx_frame_apply_sidecar_file(ft, A.sidecar))
            die("sidecar", ctxs[t]);
        g_ctxs[t] = ctxs[t];
        g_frames[t] = ft;
    }
    g_nframes = A.nthreads;
    fx_frame *f = g_frames[0];
    fprintf(stderr, "bench_presets: read %s (%dx%d, %d passes; once per context) in %.0f ms\n", A.passes,
            fx_frame_width(f), fx_frame_height(f), fx_frame_pass_count(f), now_ms() - t0);

    bench_groups(effects, f, ctxs);
    cJSON_Delete(recipe);
    for (int t = 0; t < g_nframes; t++)
        fx_frame_free(g_frames[t]);
    for (int t = 0; t < A.nthreads; t++)
        fx_context_free(ctxs[t]);
    if (g_csv != stdout)
        fclose(g_csv);
    return 0;
}
