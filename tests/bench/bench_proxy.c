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

int main(int argc, char **argv)
{
    const char *scene = "scene", *passes = NULL, *sidecar = NULL, *recipe = NULL, *csv = NULL, *md = NULL;
    const char *effects_opt = NULL, *png_dir = NULL;
    int threads = 2, runs = 5;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
#define OPT(s) (strcmp(a, s) == 0 && v && (i++, 1))
        if (OPT("--scene")) scene = v;
        else if (OPT("--passes")) passes = v;
        else if (OPT("--sidecar")) sidecar = v;
        else if (OPT("--recipe")) recipe = v;
        else if (OPT("--threads")) threads = atoi(v);
        else if (OPT("--runs")) runs = atoi(v);
        else if (OPT("--effects")) effects_opt = v;
        else if (OPT("--png-dir")) png_dir = v;
        else if (OPT("-o")) csv = v;
        else if (OPT("-m")) md = v;
        else {
            fprintf(stderr, "usage: bench_proxy --scene NAME --passes P.exr --sidecar S.json --recipe R.json "
                            "[--threads 2] [--runs 5] [--effects a,b] [--png-dir DIR] -o out.csv [-m out.md]\n");
            return 2;
        }
#undef OPT
    }
    if (!passes || !recipe || !csv) {
        fprintf(stderr, "bench_proxy: --passes, --recipe and -o are required\n");
        return 2;
    }
    if (runs < 1)
        runs = 1;
    fx_context *ctx = NULL;
    if (fx_context_new(&ctx, threads))
        die("context", NULL);
    char *rtext = bench_slurp(recipe);
    cJSON *root = rtext ? cJSON_Parse(rtext) : NULL;
    if (!root)
        die("recipe", NULL);
    /* the frame, with the passes the whole recipe needs */
    fx_stack *all = NULL;
    char *all_json = recipe_for(root, NULL, FX_QUALITY_FINAL);
    if (fx_stack_new(ctx, &all) || fx_stack_load_json(all, all_json))
        die("recipe", ctx);
    fx_read_options ro;
    memset(&ro, 0, sizeof ro);
    ro.size = sizeof ro;
    ro.stack = all;
    fx_frame *frame = NULL;
    if (fx_frame_read_exr(ctx, passes, &ro, &frame))
        die(passes, ctx);
    if (sidecar && fx_frame_apply_sidecar_file(frame, sidecar))
        die(sidecar, ctx);
    fx_stack_free(all);
    free(all_json);
    const int W = fx_frame_width(frame), H = fx_frame_height(frame);
    const size_t npx = (size_t)W * H;

    /* the effects: names in recipe order, once each, then the identity and the stack */
    const char *names[64];
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

    FILE *out = fopen(csv, "a");
    if (!out)
        die(csv, NULL);
    fseek(out, 0, SEEK_END);
    if (ftell(out) == 0)
        fprintf(out, "scene,effect,setting,quality,factor,width,height,threads,runs,reduce_ms,run_ms,read_ms,"
                     "total_ms,per_change_ms,mae,psnr_db,mae_vs_resampled,psnr_vs_resampled_db\n");
    FILE *mdf = md ? fopen(md, "a") : NULL;

    float *ref = malloc(npx * 4 * sizeof(float)), *img = malloc(npx * 4 * sizeof(float));
    float *ref2 = malloc(npx * 4 * sizeof(float)), *ref4 = malloc(npx * 4 * sizeof(float));
    double *t_red = malloc((size_t)runs * sizeof(double)), *t_run = malloc((size_t)runs * sizeof(double));
    double *t_read = malloc((size_t)runs * sizeof(double)), *t_tot = malloc((size_t)runs * sizeof(double));
    for (int ni = 0; ni < nnames; ni++) {
        const char *name = names[ni];
        const char *filter = strcmp(name, "(identity)") == 0 ? "" : strcmp(name, "(stack)") == 0 ? NULL : name;
        double row_ms[NSET], row_change[NSET], row_mae[NSET], row_psnr[NSET], row_mae_rs[NSET];
        fx_frame *final_out = NULL;
        for (int si = 0; si < NSET; si++) {
            const setting *st = &settings[si];
            char *json = recipe_for(root, filter, st->quality);
            fx_stack *s = NULL;
            if (fx_stack_new(ctx, &s) || fx_stack_load_json(s, json))
                die(json, ctx);
            for (int k = -1; k < runs; k++) {
                double t0 = now_ms();
                fx_frame *p = NULL, *o = NULL;
                if (st->factor > 1 && fx_frame_reduce(frame, st->factor, &p))
                    die("reduce", ctx);
                double t1 = now_ms();
                if (fx_stack_run(s, p ? p : frame, &o))
                    die(name, ctx);
                double t2 = now_ms();
                if (fx_frame_read_pixels(o, "Combined", W, H, 1, img))
                    die("read_pixels", ctx);
                double t3 = now_ms();
                if (k >= 0) {
                    t_red[k] = t1 - t0;
                    t_run[k] = t2 - t1;
                    t_read[k] = t3 - t2;
                    t_tot[k] = t3 - t0;
                }
                if (si == 0 && k == runs - 1) {
                    fx_frame_free(final_out);
                    final_out = o; /* for the resampled references */
                } else {
                    fx_frame_free(o);
                }
                fx_frame_free(p);
            }
            double red = median_d(t_red, runs), run = median_d(t_run, runs), rd = median_d(t_read, runs);
            double tot = median_d(t_tot, runs);
            if (si == 0) {
                memcpy(ref, img, npx * 4 * sizeof(float));
                /* final, reduced and read back: what a perfect proxy of the effect would show */
                for (int fi = 0; fi < 2; fi++) {
                    fx_frame *r = NULL;
                    if (fx_frame_reduce(final_out, fi ? 4 : 2, &r) ||
                        fx_frame_read_pixels(r, "Combined", W, H, 1, fi ? ref4 : ref2))
                        die("reference", ctx);
                    fx_frame_free(r);
                }
            }
            double mae, psnr, mae_rs, psnr_rs;
            errors(img, ref, npx, &mae, &psnr);
            errors(img, st->factor == 2 ? ref2 : st->factor == 4 ? ref4 : ref, npx, &mae_rs, &psnr_rs);
            row_ms[si] = tot;
            row_change[si] = run + rd;
            row_mae[si] = mae;
            row_psnr[si] = psnr;
            row_mae_rs[si] = mae_rs;
            fprintf(out, "%s,%s,%s,%s,%d,%d,%d,%d,%d,%.3f,%.3f,%.3f,%.3f,%.3f,%.6g,%.2f,%.6g,%.2f\n", scene, name,
                    st->label, fx_quality_name(st->quality), st->factor, W, H, threads, runs, red, run, rd, tot,
                    run + rd, mae, psnr, mae_rs, psnr_rs);
            fflush(out);
            fprintf(stderr, "bench_proxy: [%s] %-16s %-9s reduce %6.2f run %7.2f read %5.2f total %7.2f ms; "
                            "MAE %.5f PSNR %.1f dB; vs final resampled MAE %.5f PSNR %.1f dB\n",
                    scene, name, st->label, red, run, rd, tot, mae, psnr, mae_rs, psnr_rs);
            if (png_dir) {
                fx_frame *pf = NULL;
                char path[1024];
                snprintf(path, sizeof path, "%s/%s_%s_%s_%d.png", png_dir, scene,
                         filter ? (filter[0] ? filter : "identity") : "stack", fx_quality_name(st->quality),
                         st->factor);
                /* read_pixels wrote bottom-up: read it back top-down for the PNG */
                float *td = malloc(npx * 4 * sizeof(float));
                for (int y = 0; y < H; y++)
                    memcpy(td + (size_t)y * W * 4, img + (size_t)(H - 1 - y) * W * 4, (size_t)W * 4 * sizeof(float));
                if (!fx_frame_new(ctx, W, H, &pf) && !fx_frame_add_pass(pf, "Combined", 4, td))
                    fx_frame_write_png(pf, path, NULL, 0.0f);
                free(td);
                fx_frame_free(pf);
            }
            fx_stack_free(s);
            free(json);
        }
        if (mdf) {
            fprintf(mdf, "| %s | %s |", scene, name);
            for (int si = 0; si < NSET; si++)
                fprintf(mdf, " %.1f (%.1f) |", row_ms[si], row_change[si]);
            for (int si = 1; si < NSET; si++) {
                if (isinf(row_psnr[si]))
                    fprintf(mdf, " %.4f / inf", row_mae[si]);
                else
                    fprintf(mdf, " %.4f / %.1f", row_mae[si], row_psnr[si]);
                if (settings[si].factor > 1)
                    fprintf(mdf, " (%.4f)", row_mae_rs[si]);
                fprintf(mdf, " |");
            }
            fprintf(mdf, "\n");
            fflush(mdf);
        }
        fx_frame_free(final_out);
    }
    free(ref);
    free(ref2);
    free(ref4);
    free(img);
    free(t_red);
    free(t_run);
    free(t_read);
    free(t_tot);
    if (mdf)
        fclose(mdf);
    fclose(out);
    fx_frame_free(frame);
    cJSON_Delete(root);
    free(rtext);
    fx_context_free(ctx);
    return 0;
}
