/* bench_proxy: the interactive settings of issue 13 (proxy resolution and/or the draft
 * preset) per effect of a scene's recipe, at the scene's size (1920x1080).
 *
 *   bench_proxy --scene NAME --passes P.exr --sidecar S.json --recipe R.json
 *               [--threads 2] [--runs 5] [--effects a,b] [--png-dir DIR] -o out.csv [-m out.md]
 *
 * (--effects: a comma list; "(stack)" in it adds the whole-recipe row, which is there
 * by default.)
 *
 * Per effect (all enabled entries of one effect name, in recipe order, with their params
 * and masks, as bench_presets groups them), plus "(identity)" (an empty stack: the cost
 * and error of the resampling alone) and "(stack)" (the whole recipe), five settings:
 * final and draft at full size, final and draft at 1/2, draft at 1/4. Each is timed as the
 * add-on meets it (median of `runs` after one warm-up, `threads` threads):
 *   reduce_ms  fx_frame_reduce of the frame (the passes the recipe needs); the add-on
 *              reduces once per frame and keeps the proxy while a value is dragged
 *   run_ms     fx_stack_run on the (proxy) frame
 *   read_ms    fx_frame_read_pixels of Combined back to the full size, bottom-up
 *   total_ms   the three together (per change, with the proxy kept: run_ms + read_ms)
 * Errors of the full-size RGB against `final` at full size over the whole frame: MAE on
 * scene-linear values, PSNR = 10 log10(1 / MSE) on values clipped to [0, 1] (as
 * bench_presets); and, for proxies, MAE/PSNR against `final` reduced by the same factor
 * and read back to full size (what a perfect proxy of the effect would show: the error the
 * effect's proxy adds beyond the resampling itself, which on a noisy render is large:
 * see the "(identity)" row). Built aux views (light maps, the rain map) stay in the context's cache
 * between runs, as they do in the add-on while a value is dragged (bench_presets turns the
 * cache off). --png-dir writes each setting's full-size result as a PNG to look at. */
#include "bench_util.h"
#include "libfx/fx.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

static void die(const char *what, fx_context *ctx)
{
    fprintf(stderr, "bench_proxy: %s: %s\n", what, ctx ? fx_context_error(ctx) : "");
    exit(1);
}

/* The recipe with only the enabled entries named `effect` (NULL: all; "": none), at quality q. */
static char *recipe_for(const cJSON *root, const char *effect, int q)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "version", 1);
    cJSON_AddStringToObject(o, "quality", fx_quality_name(q));
    cJSON *arr = cJSON_AddArrayToObject(o, "effects");
    const cJSON *e;
    cJSON_ArrayForEach(e, cJSON_GetObjectItem(root, "effects")) {
        const cJSON *en = cJSON_GetObjectItem(e, "enabled");
        if (en && cJSON_IsFalse(en))
            continue;
        const char *name = cJSON_GetObjectItem(e, "effect")->valuestring;
        if (effect && strcmp(effect, name) != 0)
            continue;
        cJSON *c = cJSON_Duplicate(e, 1);
        cJSON_DeleteItemFromObject(c, "quality");
        cJSON_AddItemToArray(arr, c);
    }
    char *s = cJSON_PrintUnformatted(o);
    cJSON_Delete(o);
    return s;
}

static void errors(const float *a, const float *ref, size_t npx, double *mae, double *psnr)
{
    double s = 0, s2 = 0;
    for (size_t i = 0; i < npx; i++)
        for (int c = 0; c < 3; c++) {
            double r = ref[i * 4 + c], v = a[i * 4 + c];
            s += fabs(v - r);
            double ac = v < 0.0 ? 0.0 : v > 1.0 ? 1.0 : v, rc = r < 0.0 ? 0.0 : r > 1.0 ? 1.0 : r;
            s2 += (ac - rc) * (ac - rc);
        }
    *mae = s / (3.0 * (double)npx);
    double mse = s2 / (3.0 * (double)npx);
    *psnr = mse > 0 ? 10 * log10(1.0 / mse) : INFINITY;
}

typedef struct setting {
    const char *label;
    int quality, factor;
} setting;

static const setting settings[] = {
    {"final 1/1", FX_QUALITY_FINAL, 1}, {"draft 1/1", FX_QUALITY_DRAFT, 1}, {"final 1/2", FX_QUALITY_FINAL, 2},
    {"draft 1/2", FX_QUALITY_DRAFT, 2}, {"draft 1/4", FX_QUALITY_DRAFT, 4},
};
#define NSET ((int)(sizeof settings / sizeof settings[0]))

/* The command line. */
typedef struct options {
    const char *scene, *passes, *sidecar, *recipe, *csv, *md, *effects, *png_dir;
    int threads, runs;
} options;

static int parse_options(int argc, char **argv, options *o)
{
    memset(o, 0, sizeof *o);
    o->scene = "scene";
    o->threads = 2;
    o->runs = 5;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
#define OPT(s) (strcmp(a, s) == 0 && v && (i++, 1))
        if (OPT("--scene")) o->scene = v;
        else if (OPT("--passes")) o->passes = v;
        else if (OPT("--sidecar")) o->sidecar = v;
        else if (OPT("--recipe")) o->recipe = v;
        else if (OPT("--threads")) o->threads = atoi(v);
        else if (OPT("--runs")) o->runs = atoi(v);
        else if (OPT("--effects")) o->effects = v;
        else if (OPT("--png-dir")) o->png_dir = v;
        else if (OPT("-o")) o->csv = v;
        else if (OPT("-m")) o->md = v;
        else {
            fprintf(stderr, "usage: bench_proxy --scene NAME --passes P.exr --sidecar S.json --recipe R.json "
                            "[--threads 2] [--runs 5] [--effects a,b] [--png-dir DIR] -o out.csv [-m out.md]\n");
            return 2;
        }
#undef OPT
    }
    if (!o->passes || !o->recipe || !o->csv) {
        fprintf(stderr, "bench_proxy: --passes, --recipe and -o are required\n");
        return 2;
    }
    if (o->runs < 1)
        o->runs = 1;
    return 0;
}

/* The frame, with the passes the whole recipe needs, and the sidecar. */
static fx_frame *load_frame(fx_context *ctx, const cJSON *root, const options *o)
{
    fx_stack *all = NULL;
    char *all_json = recipe_for(root, NULL, FX_QUALITY_FINAL);
    if (fx_stack_new(ctx, &all) || fx_stack_load_json(all, all_json))
        die("recipe", ctx);
    fx_read_options ro;
    memset(&ro, 0, sizeof ro);
    ro.size = sizeof ro;
    ro.stack = all;
    fx_frame *frame = NULL;
    if (fx_frame_read_exr(ctx, o->passes, &ro, &frame))
        die(o->passes, ctx);
    if (o->sidecar && fx_frame_apply_sidecar_file(frame, o->sidecar))
        die(o->sidecar, ctx);
    fx_stack_free(all);
    free(all_json);
    return frame;
}

/* The effects to bench: names in recipe order, once each (those of --effects), then the
 * identity and the whole stack. Returns how many (names has room for 64). */
static int effect_names(const cJSON *root, const char *effects_opt, const char *names[64])
{
    int nnames = 0;
    const cJSON *e;
    cJSON_ArrayForEach(e, cJSON_GetObjectItem(root, "effects")) {
        const cJSON *en = cJSON_GetObjectItem(e, "enabled");
        if (en && cJSON_IsFalse(en))
            continue;
        const char *n = cJSON_GetObjectItem(e, "effect")->valuestring;
        int seen = 0;
        for (int k = 0; k < nnames; k++)
            seen |= strcmp(names[k], n) == 0;
        if (effects_opt) {
            char buf[512];
            snprintf(buf, sizeof buf, ",%s,", effects_opt);
            char key[128];
            snprintf(key, sizeof key, ",%s,", n);
            if (!strstr(buf, key))
                seen = 1;
        }
        if (!seen && nnames < 62)
            names[nnames++] = n;
    }
    names[nnames++] = "(identity)";
    if (!effects_opt || strstr(effects_opt, "(stack)"))
        names[nnames++] = "(stack)";
    return nnames;
}

/* The image (bottom-up rows, as fx_frame_read_pixels gives them) as a PNG. */
static void write_png(fx_context *ctx, const float *img, int W, int H, const char *path)
{
    const size_t npx = (size_t)W * H;
    fx_frame *pf = NULL;
    float *td = malloc(npx * 4 * sizeof(float));
    for (int y = 0; y < H; y++)
        memcpy(td + (size_t)y * W * 4, img + (size_t)(H - 1 - y) * W * 4, (size_t)W * 4 * sizeof(float));
    if (!fx_frame_new(ctx, W, H, &pf) && !fx_frame_add_pass(pf, "Combined", 4, td))
        fx_frame_write_png(pf, path, NULL, 0.0f);
    free(td);
    fx_frame_free(pf);
}

/* Buffers every effect's rows share: the final image (ref), final reduced 1/2 and 1/4 and
 * read back (what a perfect proxy would show), the image at hand, and the run times. */
typedef struct bench_state {
    fx_context *ctx;
    const options *o;
    const cJSON *root;
    const fx_frame *frame;
    int W, H;
    FILE *out, *mdf;
    float *ref, *ref2, *ref4, *img;
    double *t_red, *t_run, *t_read, *t_tot;
} bench_state;

/* One effect (or the identity, or the stack) at every setting: its CSV rows, its Markdown
 * row. */
static void bench_effect(bench_state *b, const char *name)
{
    fx_context *ctx = b->ctx;
    const options *o = b->o;
    const int W = b->W, H = b->H, runs = o->runs;
    const size_t npx = (size_t)W * H;
    const char *filter = strcmp(name, "(identity)") == 0 ? "" : strcmp(name, "(stack)") == 0 ? NULL : name;
    double row_ms[NSET], row_change[NSET], row_mae[NSET], row_psnr[NSET], row_mae_rs[NSET];
    fx_frame *final_out = NULL;
    for (int si = 0; si < NSET; si++) {
        const setting *st = &settings[si];
        char *json = recipe_for(b->root, filter, st->quality);
        fx_stack *s = NULL;
        if (fx_stack_new(ctx, &s) || fx_stack_load_json(s, json))
            die(json, ctx);
        for (int k = -1; k < runs; k++) {
            double t0 = now_ms();
            fx_frame *p = NULL, *out = NULL;
            if (st->factor > 1 && fx_frame_reduce(b->frame, st->factor, &p))
                die("reduce", ctx);
            double t1 = now_ms();
            if (fx_stack_run(s, p ? p : b->frame, &out))
                die(name, ctx);
            double t2 = now_ms();
            if (fx_frame_read_pixels(out, "Combined", W, H, 1, b->img))
                die("read_pixels", ctx);
            double t3 = now_ms();
            if (k >= 0) {
                b->t_red[k] = t1 - t0;
                b->t_run[k] = t2 - t1;
                b->t_read[k] = t3 - t2;
                b->t_tot[k] = t3 - t0;
            }
            if (si == 0 && k == runs - 1) {
                fx_frame_free(final_out);
                final_out = out; /* for the resampled references */
            } else {
                fx_frame_free(out);
            }
            fx_frame_free(p);
        }
        double red = median_d(b->t_red, runs), run = median_d(b->t_run, runs), rd = median_d(b->t_read, runs);
        double tot = median_d(b->t_tot, runs);
        if (si == 0) {
            memcpy(b->ref, b->img, npx * 4 * sizeof(float));
            /* final, reduced and read back: what a perfect proxy of the effect would show */
            for (int fi = 0; fi < 2; fi++) {
                fx_frame *r = NULL;
                if (fx_frame_reduce(final_out, fi ? 4 : 2, &r) ||
                    fx_frame_read_pixels(r, "Combined", W, H, 1, fi ? b->ref4 : b->ref2))
                    die("reference", ctx);
                fx_frame_free(r);
            }
        }
        double mae, psnr, mae_rs, psnr_rs;
        errors(b->img, b->ref, npx, &mae, &psnr);
        errors(b->img, st->factor == 2 ? b->ref2 : st->factor == 4 ? b->ref4 : b->ref, npx, &mae_rs, &psnr_rs);
        row_ms[si] = tot;
        row_change[si] = run + rd;
        row_mae[si] = mae;
        row_psnr[si] = psnr;
        row_mae_rs[si] = mae_rs;
        fprintf(b->out, "%s,%s,%s,%s,%d,%d,%d,%d,%d,%.3f,%.3f,%.3f,%.3f,%.3f,%.6g,%.2f,%.6g,%.2f\n", o->scene, name,
                st->label, fx_quality_name(st->quality), st->factor, W, H, o->threads, runs, red, run, rd, tot,
                run + rd, mae, psnr, mae_rs, psnr_rs);
        fflush(b->out);
        fprintf(stderr, "bench_proxy: [%s] %-16s %-9s reduce %6.2f run %7.2f read %5.2f total %7.2f ms; "
                        "MAE %.5f PSNR %.1f dB; vs final resampled MAE %.5f PSNR %.1f dB\n",
                o->scene, name, st->label, red, run, rd, tot, mae, psnr, mae_rs, psnr_rs);
        if (o->png_dir) {
            char path[1024];
            snprintf(path, sizeof path, "%s/%s_%s_%s_%d.png", o->png_dir, o->scene,
                     filter ? (filter[0] ? filter : "identity") : "stack", fx_quality_name(st->quality), st->factor);
            write_png(ctx, b->img, W, H, path);
        }
        fx_stack_free(s);
        free(json);
    }
    if (b->mdf) {
        fprintf(b->mdf, "| %s | %s |", o->scene, name);
        for (int si = 0; si < NSET; si++)
            fprintf(b->mdf, " %.1f (%.1f) |", row_ms[si], row_change[si]);
        for (int si = 1; si < NSET; si++) {
            if (isinf(row_psnr[si]))
                fprintf(b->mdf, " %.4f / inf", row_mae[si]);
            else
                fprintf(b->mdf, " %.4f / %.1f", row_mae[si], row_psnr[si]);
            if (settings[si].factor > 1)
                fprintf(b->mdf, " (%.4f)", row_mae_rs[si]);
            fprintf(b->mdf, " |");
        }
        fprintf(b->mdf, "\n");
        fflush(b->mdf);
    }
    fx_frame_free(final_out);
}

int main(int argc, char **argv)
{
    options o;
    int rc = parse_options(argc, argv, &o);
    if (rc)
        return rc;
    fx_context *ctx = NULL;
    if (fx_context_new(&ctx, o.threads))
        die("context", NULL);
    char *rtext = bench_slurp(o.recipe);
    cJSON *root = rtext ? cJSON_Parse(rtext) : NULL;
    if (!root)
        die("recipe", NULL);
    fx_frame *frame = load_frame(ctx, root, &o);
    const char *names[64];
    const int nnames = effect_names(root, o.effects, names);

    FILE *out = fopen(o.csv, "a");
    if (!out)
        die(o.csv, NULL);
    fseek(out, 0, SEEK_END);
    if (ftell(out) == 0)
        fprintf(out, "scene,effect,setting,quality,factor,width,height,threads,runs,reduce_ms,run_ms,read_ms,"
                     "total_ms,per_change_ms,mae,psnr_db,mae_vs_resampled,psnr_vs_resampled_db\n");
    bench_state b = {ctx, &o, root, frame, fx_frame_width(frame), fx_frame_height(frame), out,
                     o.md ? fopen(o.md, "a") : NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL};
    const size_t bytes = (size_t)b.W * b.H * 4 * sizeof(float), tb = (size_t)o.runs * sizeof(double);
    b.ref = malloc(bytes), b.ref2 = malloc(bytes), b.ref4 = malloc(bytes), b.img = malloc(bytes);
    b.t_red = malloc(tb), b.t_run = malloc(tb), b.t_read = malloc(tb), b.t_tot = malloc(tb);
    for (int ni = 0; ni < nnames; ni++)
        bench_effect(&b, names[ni]);
    free(b.ref);
    free(b.ref2);
    free(b.ref4);
    free(b.img);
    free(b.t_red);
    free(b.t_run);
    free(b.t_read);
    free(b.t_tot);
    if (b.mdf)
        fclose(b.mdf);
    fclose(out);
    fx_frame_free(frame);
    cJSON_Delete(root);
    free(rtext);
    fx_context_free(ctx);
    return 0;
}
