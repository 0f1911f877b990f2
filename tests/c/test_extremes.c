/* The extremes suite (issue 8, hardening), table-driven over the registry: every effect
 * (fx_effect_count/fx_effect_name, so new effects are covered without edits) and every
 * numeric parameter (fx_effect_param).
 *
 *  - Refused: NaN, +-Inf, just below min, just above max, non-integers for ints, through
 *    the C setters and through recipe JSON (1e999 parses as Inf): FX_ERR_BAD_PARAM with
 *    a message naming the parameter.
 *  - Run: min, max, 0, +-denormal, -1 and the soft-range midpoint when in range, on a
 *    hostile 17x13 frame at quality draft.
 *  - Inputs: a small synthetic scene with every pass an effect could need (Combined,
 *    Depth, Normal, Position, IndexOB/IndexMA, Cryptomatte ranks, diffuse/glossy/...
 *    lights), a scene sidecar (camera, sun, point, spot lights) and aux views (light
 *    depth view, rain map); "hostile" variants put NaN/+-Inf/1e38/65504/denormals in a
 *    third of the pixels of every pass (NaN/Inf through the EXR reader, which replaces
 *    them, and finite extremes straight through the API), background depth
 *    1e10/1e11/65504, zero-length and non-unit normals; 1x1, 1xN, Nx1 frames;
 *    singular/huge/NaN camera matrices (NaN refused); lights behind and at the camera.
 *  - Every case: no crash, every float of every output pass finite (debug outputs on),
 *    a wall limit per case (a watchdog names the case that hangs), or a clear error.
 *  - A few reference-quality cases.
 *  - Every preset on 1/2 and 1/4 proxies (fx_frame_reduce) of the hostile odd frames.
 */
#include "fx_scene_test.h"

#include "core/internal.h"
#include "testos.h"
#include "core/platform.h"

#include <float.h>
#include <math.h>
#include <stdint.h>
#include <unistd.h>

/* Hard per-case limit (the process exits naming the case) and the soft one that is
 * checked: generous for ASan on a loaded 2-core machine, each case is a few ms. */
#define CASE_HARD_LIMIT_S 120
#define CASE_SOFT_LIMIT_S 30.0

static char current_case[512];
static int runs_ok, runs_refused;

static void on_alarm(void)
{
    static const char msg[] = "\ntest_extremes: case over the wall limit (hang?): ";
    if (write(2, msg, sizeof msg - 1) < 0 || write(2, current_case, strlen(current_case)) < 0 ||
        write(2, "\n", 1) < 0) { /* nothing more to do */ }
    _exit(3);
}

static double now_s(void)
{
    return fx_os_now_ms() / 1000.0;
}

/* ---- running one case ------------------------------------------------------------- */

/* A clear error: one of the expected codes and a message; for FX_ERR_BAD_PARAM from
 * cross-parameter checks the message names one of the effect's parameters. */
static int clear_error(const char *effect, fx_result r, const char *msg)
{
    if (!msg || strlen(msg) < 8)
        return 0;
    switch (r) {
    case FX_ERR_BAD_PARAM: {
        int n = fx_effect_param_count(effect);
        for (int i = 0; i < n; i++) {
            char quoted[128];
            snprintf(quoted, sizeof quoted, "'%s'", fx_effect_param(effect, i)->name);
            if (strstr(msg, quoted) || strstr(msg, fx_effect_param(effect, i)->name))
                return 1;
        }
        return 0;
    }
    case FX_ERR_NO_CAMERA:
    case FX_ERR_NO_AUX_VIEW:
    case FX_ERR_NO_LIGHTS:
    case FX_ERR_MISSING_PASS:
    case FX_ERR_LIMIT:
    case FX_ERR_INVALID_ARGUMENT:
    case FX_ERR_BAD_RECIPE:
        return 1;
    default:
        return 0; /* OOM on a 17x13 frame, INTERNAL, IO, ...: a bug */
    }
}

/* Runs s on f. must_run: FX_OK is required (else a clear error is accepted). Checks every
 * float of every output pass. Returns the result. */
/* Runs one case and checks it; *keep (when not NULL) gets the output, for more checks. */
static fx_result run_case_keep(fx_context *ctx, fx_stack *s, const fx_frame *f, const char *effect, int must_run,
                               fx_frame **keep)
{
    fx_context_clear_warnings(ctx);
    tu_alarm(CASE_HARD_LIMIT_S, on_alarm);
    double t0 = now_s();
    fx_frame *out = NULL;
    fx_result r = fx_stack_run(s, f, &out);
    double dt = now_s() - t0;
    tu_alarm(0, on_alarm);
    tu_checks++;
    if (dt > CASE_SOFT_LIMIT_S) {
        tu_failures++;
        fprintf(stderr, "SLOW (%.1f s): %s\n", dt, current_case);
    }
    if (r == FX_OK) {
        runs_ok++;
        int bad = 0;
        CHECK(out != NULL && fx_frame_width(out) == fx_frame_width(f) && fx_frame_height(out) == fx_frame_height(f));
        for (int p = 0; out && p < fx_frame_pass_count(out); p++) {
            const float *d = NULL;
            int ch = 0;
            const char *pn = fx_frame_pass_name(out, p);
            fx_frame_pass_read(out, pn, &d, &ch);
            size_t n = (size_t)fx_frame_width(out) * fx_frame_height(out) * ch;
            for (size_t i = 0; i < n; i++)
                if (!isfinite(d[i])) {
                    if (!bad)
                        fprintf(stderr, "NON-FINITE output: %s: pass '%s' [%zu] = %g\n", current_case, pn, i,
                                d[i]);
                    bad = 1;
                    break;
                }
        }
        tu_checks++;
        tu_failures += bad;
        /* The stack replaces non-finite values an effect produced (a safety net) and warns;
         * every input here is finite, so such a warning is the effect's own NaN/Inf. */
        for (int w = 0; w < fx_context_warning_count(ctx); w++) {
            const char *msg = fx_context_warning(ctx, w);
            tu_checks++;
            if (tu_contains(msg, "non-finite")) {
                tu_failures++;
                fprintf(stderr, "EFFECT MADE NaN/Inf (replaced by the stack): %s: %s\n", current_case, msg);
            }
        }
    } else {
        runs_refused++;
        const char *msg = fx_context_error(ctx);
        tu_checks++;
        if (must_run || !clear_error(effect, r, msg)) {
            tu_failures++;
            fprintf(stderr, "%s: %s: %s: \"%s\"\n", must_run ? "FAILED TO RUN" : "UNCLEAR ERROR", current_case,
                    fx_result_name(r), msg);
        } else {
            printf("refused (clear error): %s: %s: \"%s\"\n", current_case, fx_result_name(r), msg);
        }
    }
    if (keep)
        *keep = out;
    else
        fx_frame_free(out);
    return r;
}

static fx_result run_case(fx_context *ctx, fx_stack *s, const fx_frame *f, const char *effect, int must_run)
{
    return run_case_keep(ctx, s, f, effect, must_run, NULL);
}

/* A run under a one-pixel mask at (x0, y0) left every other pixel of the w x h output as
 * the input had it, bit for bit. */
static void check_outside_kept(const fx_frame *out, const float *in_px, int w, int h, int x0, int y0)
{
    const float *o = NULL;
    fx_frame_pass_read(out, "Combined", &o, NULL);
    int outside_kept = 1;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            if ((x != x0 || y != y0) &&
                memcmp(o + ((size_t)y * w + x) * 4, in_px + ((size_t)y * w + x) * 4, 16) != 0)
                outside_kept = 0;
    if (!outside_kept)
        fprintf(stderr, "WROTE OUTSIDE ITS MASK: %s\n", current_case);
    CHECK(outside_kept);
}

static fx_stack *stack_for(fx_context *ctx, const char *effect, int quality);

/* One preset of one effect on f, whole or (masked) under a one-pixel mask at (x0, y0) in
 * full-frame pixels; masked, every pixel of the w x h output but (cx, cy) must be in_px's. */
static void run_masked_case(fx_context *ctx, const fx_frame *f, const float *in_px, const char *effect,
                            int quality, int masked, int x0, int y0, int w, int h, int cx, int cy)
{
    fx_stack *s = stack_for(ctx, effect, quality);
    if (!s)
        return;
    char mask[96];
    snprintf(mask, sizeof mask, "{\"rect\": [%d, %d, 1, 1]}", x0, y0);
    if (masked)
        CHECK_OK(ctx, fx_stack_set_mask_json(s, 0, mask));
    fx_frame *out = NULL;
    if (run_case_keep(ctx, s, f, effect, 1, &out) == FX_OK && masked)
        check_outside_kept(out, in_px, w, h, cx, cy);
    fx_frame_free(out);
    fx_stack_free(s);
}

static fx_stack *stack_for(fx_context *ctx, const char *effect, int quality)
{
    fx_stack *s = et_stack(ctx, effect);
    if (s) {
        fx_stack_set_quality(s, quality);
        fx_stack_set_debug_outputs(s, 1);
    }
    return s;
}

/* ---- parameter sweep ------------------------------------------------------------------ */

static int is_numeric(const fx_param_info *p)
{
    return p->type == FX_PARAM_FLOAT || p->type == FX_PARAM_INT || p->type == FX_PARAM_FLOATS;
}

static int has_range(const fx_param_info *p)
{
    return p->type != FX_PARAM_FLOATS || p->min < p->max;
}

/* Sets one numeric value (FLOATS: every element, or only the last one). */
static fx_result set_value(fx_stack *s, const fx_param_info *p, double v, int last_only)
{
    if (p->type == FX_PARAM_FLOAT)
        return fx_stack_set_float(s, 0, p->name, v);
    if (p->type == FX_PARAM_INT)
        return fx_stack_set_float(s, 0, p->name, v); /* through the JSON number: NaN, 0.5 too */
    float vals[64];
    for (int i = 0; i < p->count && i < 64; i++)
        vals[i] = p->default_floats ? p->default_floats[i] : 0.0f;
    for (int i = last_only ? p->count - 1 : 0; i < p->count && i < 64; i++)
        vals[i] = (float)v;
    return fx_stack_set_floats(s, 0, p->name, vals, p->count);
}

static int param_named(const char *msg, const char *name)
{
    char quoted[128];
    snprintf(quoted, sizeof quoted, "'%s'", name);
    return tu_contains(msg, quoted);
}

/* Values outside the hard range: the setter refuses them, the stack is unchanged. */
static void sweep_refused(fx_context *ctx, const char *effect, const fx_param_info *p)
{
    double bad[12];
    int n = 0;
    bad[n++] = NAN;
    bad[n++] = INFINITY;
    bad[n++] = -INFINITY;
    if (has_range(p)) {
        /* just outside: the next float (or integer) beyond each end */
        if (p->type == FX_PARAM_INT) {
            bad[n++] = p->min - 1;
            bad[n++] = p->max + 1;
            bad[n++] = fmin(p->max, fmax(p->min, p->default_value)) + 0.5; /* not an integer */
        } else {
            float lo = (float)p->min, hi = (float)p->max;
            double below = nextafterf(lo, -INFINITY), above = nextafterf(hi, INFINITY);
            if (below < p->min)
                bad[n++] = below;
            if (above > p->max && isfinite(above))
                bad[n++] = above;
            bad[n++] = p->min - fmax(1.0, fabs(p->min));
            bad[n++] = p->max + fmax(1.0, fabs(p->max));
        }
    }
    for (int i = 0; i < n; i++)
        for (int last = 0; last <= (p->type == FX_PARAM_FLOATS); last++) {
            snprintf(current_case, sizeof current_case, "%s.%s = %g%s (refused)", effect, p->name, bad[i],
                     last ? " (last element)" : "");
            fx_stack *s = stack_for(ctx, effect, FX_QUALITY_DRAFT);
            CHECK(s != NULL);
            if (!s)
                continue;
            fx_result r = set_value(s, p, bad[i], last);
            tu_checks++;
            if (r != FX_ERR_BAD_PARAM || !param_named(fx_context_error(ctx), p->name)) {
                tu_failures++;
                fprintf(stderr, "NOT REFUSED: %s: %s \"%s\"\n", current_case, fx_result_name(r),
                        fx_context_error(ctx));
            }
            /* the stack still holds the defaults: it serialises without the value */
            char *json = NULL;
            CHECK_OK(ctx, fx_stack_to_json(s, &json));
            char key[128];
            snprintf(key, sizeof key, "\"%s\":", p->name);
            tu_checks++;
            if (!json || tu_contains(json, key)) {
                tu_failures++;
                fprintf(stderr, "STACK CHANGED by a refused value: %s: %s\n", current_case, json ? json : "");
            }
            fx_free(json);
            fx_stack_free(s);
        }
    /* The recipe parser: out of range and overflowing numbers (1e999 is Inf to strtod). */
    const char *texts[4];
    char lo_txt[64], hi_txt[64];
    int m = 0;
    texts[m++] = "1e999";
    texts[m++] = "-1e999";
    if (has_range(p)) {
        snprintf(lo_txt, sizeof lo_txt, "%.17g", p->min - fmax(1.0, fabs(p->min)));
        snprintf(hi_txt, sizeof hi_txt, "%.17g", p->max + fmax(1.0, fabs(p->max)));
        texts[m++] = lo_txt;
        texts[m++] = hi_txt;
    }
    for (int i = 0; i < m; i++) {
        char value[1200], recipe[1600];
        if (p->type == FX_PARAM_FLOATS) {
            size_t len = 0;
            len += (size_t)snprintf(value + len, sizeof value - len, "[");
            for (int k = 0; k < p->count && len < sizeof value - 40; k++)
                len += (size_t)snprintf(value + len, sizeof value - len, "%s%s", k ? ", " : "", texts[i]);
            snprintf(value + len, sizeof value - len, "]");
        } else {
            snprintf(value, sizeof value, "%s", texts[i]);
        }
        snprintf(recipe, sizeof recipe,
                 "{\"version\": 1, \"effects\": [{\"effect\": \"%s\", \"params\": {\"%s\": %s}}]}", effect, p->name,
                 value);
        snprintf(current_case, sizeof current_case, "recipe %s.%s = %s (refused)", effect, p->name, texts[i]);
        fx_stack *s = NULL;
        CHECK_OK(ctx, fx_stack_new(ctx, &s));
        fx_result r = fx_stack_load_json(s, recipe);
        tu_checks++;
        if (r != FX_ERR_BAD_PARAM || !param_named(fx_context_error(ctx), p->name)) {
            tu_failures++;
            fprintf(stderr, "NOT REFUSED: %s: %s \"%s\"\n", current_case, fx_result_name(r), fx_context_error(ctx));
        }
        CHECK(fx_stack_count(s) == 0);
        fx_stack_free(s);
    }
}

/* Values inside the hard range: they must be accepted and run (or fail a documented
 * cross-parameter check, naming a parameter) with finite output. */
static void sweep_accepted(fx_context *ctx, const char *effect, const fx_param_info *p, const fx_frame *f)
{
    double vals[12];
    int n = 0;
    double lo = has_range(p) ? p->min : -1e3, hi = has_range(p) ? p->max : 1e3;
    vals[n++] = lo;
    vals[n++] = hi;
    const double extra[] = {0.0, 1.4e-45, -1.4e-45, 1e-40, -1.0, 1.0};
    for (int i = 0; i < FX_COUNT_OF(extra); i++) {
        double v = extra[i];
        if (p->type == FX_PARAM_INT && v != floor(v))
            continue;
        if (v >= lo && v <= hi && v != lo && v != hi)
            vals[n++] = v;
    }
    if (p->soft_min < p->soft_max && p->type != FX_PARAM_FLOATS) {
        double mid = 0.5 * (p->soft_min + p->soft_max);
        if (p->type == FX_PARAM_INT)
            mid = floor(mid);
        vals[n++] = mid;
    }
    for (int i = 0; i < n; i++) {
        snprintf(current_case, sizeof current_case, "%s.%s = %.9g (draft, hostile %dx%d)", effect, p->name, vals[i],
                 fx_frame_width(f), fx_frame_height(f));
        fx_stack *s = stack_for(ctx, effect, FX_QUALITY_DRAFT);
        CHECK(s != NULL);
        if (!s)
            continue;
        fx_result r = set_value(s, p, vals[i], 0);
        tu_checks++;
        if (r == FX_ERR_BAD_PARAM && clear_error(effect, r, fx_context_error(ctx))) {
            /* refused by the effect's cross-parameter check (setters commit the whole
             * effect): the stack keeps its defaults and still runs */
            run_case(ctx, s, f, effect, 1);
        } else if (r != FX_OK) {
            tu_failures++;
            fprintf(stderr, "IN-RANGE VALUE REFUSED: %s: %s \"%s\"\n", current_case, fx_result_name(r),
                    fx_context_error(ctx));
        } else {
            run_case(ctx, s, f, effect, 0);
        }
        fx_stack_free(s);
    }
}

/* ---- frames and cameras ----------------------------------------------------------------- */

static const char *dir;

typedef enum { PLAIN, HOSTILE_API, HOSTILE_EXR } variant;

static fx_frame *make_frame(fx_context *ctx, int w, int h, variant v, const char *lights)
{
    scene s;
    scene_build(&s, w, h);
    if (v != PLAIN)
        scene_make_hostile(&s, v == HOSTILE_EXR);
    fx_frame *f = frame_from_scene(ctx, &s, lights);
    scene_free(&s);
    if (f && v == HOSTILE_EXR) {
        char name[64];
        snprintf(name, sizeof name, "hostile_%dx%d", w, h);
        f = through_exr(ctx, f, dir, name);
    }
    return f;
}

static int needs_camera(fx_context *ctx, const char *effect)
{
    fx_stack *s = et_stack(ctx, effect);
    char *json = NULL;
    int yes = s && fx_stack_required_passes(s, &json) == FX_OK && tu_contains(json, "\"camera\":true");
    fx_free(json);
    fx_stack_free(s);
    return yes;
}

/* Cameras that are finite but degenerate: accepted by fx_frame_set_camera, and then the
 * effects must refuse clearly or produce finite output. NaN ones are refused up front. */
static void camera_cases(fx_context *ctx, const char *effect, fx_frame *f)
{
    fx_camera good;
    CHECK(fx_frame_camera(f, &good));
    for (int k = 0; k < 7; k++) {
        fx_camera c = good;
        const char *what = "";
        switch (k) {
        case 0: memset(c.world_to_camera, 0, sizeof c.world_to_camera), what = "zero world_to_camera"; break;
        case 1: memset(c.projection, 0, sizeof c.projection), what = "zero projection"; break;
        case 2: /* rank 2: one axis collapsed */
            c.world_to_camera[4] = c.world_to_camera[5] = c.world_to_camera[6] = 0;
            what = "singular world_to_camera";
            break;
        case 3:
            for (int i = 0; i < 16; i++)
                c.world_to_camera[i] *= 1e38f;
            what = "1e38 world_to_camera";
            break;
        case 4: c.projection[14] = 0, c.projection[15] = 0, what = "projection w row zero"; break;
        case 5: { /* orthographic, 10 m wide */
            fx_camera o;
            ortho(&o, good.world_to_camera, 5.0f, 0.1f, 1000.0f);
            c = o;
            what = "orthographic";
            break;
        }
        case 6: c.clip_start = 0, c.clip_end = 0, what = "zero clip range"; break;
        }
        snprintf(current_case, sizeof current_case, "%s: camera %s", effect, what);
        fx_frame *g = NULL;
        CHECK_OK(ctx, fx_frame_new_like(f, &g));
        CHECK_OK(ctx, fx_frame_copy_passes(g, f));
        fx_result r = fx_frame_set_camera(g, &c);
        if (r == FX_OK) {
            fx_stack *s = stack_for(ctx, effect, FX_QUALITY_DRAFT);
            if (s)
                run_case(ctx, s, g, effect, 0);
            fx_stack_free(s);
        } else {
            CHECK(strlen(fx_context_error(ctx)) > 8);
        }
        fx_frame_free(g);
    }
    /* NaN / Inf matrices are refused by the API and by the sidecar parser */
    fx_camera c = good;
    c.world_to_camera[5] = NAN;
    CHECK_FAIL(ctx, fx_frame_set_camera(f, &c), FX_ERR_INVALID_ARGUMENT, "NaN");
    c = good;
    c.projection[0] = INFINITY;
    CHECK_FAIL(ctx, fx_frame_set_camera(f, &c), FX_ERR_INVALID_ARGUMENT, "NaN or Inf");
    fx_camera tmp;
    CHECK(fx_camera_from_json(ctx,
                              "{\"world_to_camera\": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1e999]],"
                              " \"projection\": [[1,0,0,0],[0,1,0,0],[0,0,-1,-0.2],[0,0,-1,0]],"
                              " \"clip_start\": 0.1, \"clip_end\": 100}",
                              &tmp) != FX_OK);
    CHECK(fx_frame_camera(f, &tmp) && memcmp(&tmp, &good, sizeof tmp) == 0); /* unchanged */
}

/* Odd and tiny frame sizes, where the reduced-resolution paths meet their edges. */
static const int odd_sizes[][2] = {{1, 1}, {1, 9}, {9, 1}, {3, 5}, {17, 13}, {37, 23}};

static void sweep_params(fx_context *ctx, fx_frame *hostile)
{
    /* 1. every numeric parameter of every effect */
    for (int e = 0; e < fx_effect_count() && hostile; e++) {
        const char *effect = fx_effect_name(e);
        for (int i = 0; i < fx_effect_param_count(effect); i++) {
            const fx_param_info *p = fx_effect_param(effect, i);
            if (!is_numeric(p))
                continue;
            sweep_refused(ctx, effect, p);
            sweep_accepted(ctx, effect, p, hostile);
        }
    }
}

static void defaults_on_shapes(fx_context *ctx)
{
    /* 2. defaults on every input variant and frame shape (draft, and final on 1x1) */
    static const int sizes[][2] = {{1, 1}, {1, 9}, {9, 1}, {2, 2}, {17, 13}};
    const char *lights[3] = {SIDECAR_LIGHTS_FRONT, SIDECAR_LIGHTS_BEHIND, SIDECAR_LIGHTS_GRAZING};
    const char *light_names[3] = {"lights in front", "sun behind the camera", "sun on the view axis, w = 0"};
    for (int z = 0; z < FX_COUNT_OF(sizes); z++)
        for (int v = PLAIN; v <= HOSTILE_EXR; v++)
            for (int l = 0; l < 3; l++) {
                if (l > 0 && (z < 4 || v == HOSTILE_API))
                    continue; /* light placement matters on the larger frame */
                fx_frame *f = make_frame(ctx, sizes[z][0], sizes[z][1], (variant)v, lights[l]);
                CHECK(f != NULL);
                for (int e = 0; f && e < fx_effect_count(); e++) {
                    const char *effect = fx_effect_name(e);
                    static const char *const vn[] = {"plain", "hostile finite (API)", "hostile NaN/Inf (EXR)"};
                    for (int q = FX_QUALITY_DRAFT; q <= FX_QUALITY_FINAL; q += 2) {
                        if (q == FX_QUALITY_FINAL && z != 0)
                            continue;
                        snprintf(current_case, sizeof current_case, "%s defaults (%s) on %dx%d %s, %s", effect,
                                 fx_quality_name(q), sizes[z][0], sizes[z][1], vn[v], light_names[l]);
                        fx_stack *s = stack_for(ctx, effect, q);
                        if (s)
                            run_case(ctx, s, f, effect, 1);
                        fx_stack_free(s);
                    }
                }
                fx_frame_free(f);
            }
}

static void presets_on_odd_frames(fx_context *ctx)
{
    /* 2b. every preset, where the reduced-resolution paths live (cells, proxies, pyramid
     * levels), on odd_sizes and tiny frames, whole and under a one-pixel mask (smaller than any
     * reduced pixel): it runs, stays finite, and leaves every pixel outside the mask as it was */
    for (int z = 0; z < FX_COUNT_OF(odd_sizes); z++) {
        const int w = odd_sizes[z][0], h = odd_sizes[z][1];
        fx_frame *f = make_frame(ctx, w, h, HOSTILE_EXR, SIDECAR_LIGHTS_FRONT);
        CHECK(f != NULL);
        const float *in_px = NULL;
        if (f)
            fx_frame_pass_read(f, "Combined", &in_px, NULL);
        const int mx = (w / 2) | 1, my = (h / 2) | 1; /* odd_sizes: off any 2x2 or 4x4 cell's corner */
        for (int e = 0; f && e < fx_effect_count(); e++) {
            const char *effect = fx_effect_name(e);
            for (int q = FX_QUALITY_DRAFT; q <= FX_QUALITY_REFERENCE; q++)
                for (int masked = 0; masked < 2; masked++) {
                    const int x0 = mx < w ? mx : w - 1, y0 = my < h ? my : h - 1;
                    snprintf(current_case, sizeof current_case, "%s (%s) on hostile %dx%d%s", effect,
                             fx_quality_name(q), w, h, masked ? ", one-pixel mask" : "");
                    run_masked_case(ctx, f, in_px, effect, q, masked, x0, y0, w, h, x0, y0);
                }
        }
        fx_frame_free(f);
    }
}

static void presets_on_proxies(fx_context *ctx)
{
    /* 2c. proxies (issue 13): every preset on 1/2 and 1/4 proxies of the hostile frames
     * (fx_frame_reduce: colour averaged, data passes from one pixel per block), whole and
     * under a one-pixel mask given in full-frame pixels (smaller than a proxy pixel: it
     * selects the proxy pixel holding it). Output at the proxy's size, finite, and
     * untouched outside that proxy pixel. */
    for (int z = 0; z < FX_COUNT_OF(odd_sizes); z++) {
        const int w = odd_sizes[z][0], h = odd_sizes[z][1];
        fx_frame *f = make_frame(ctx, w, h, HOSTILE_EXR, SIDECAR_LIGHTS_FRONT);
        CHECK(f != NULL);
        for (int factor = 2; f && factor <= 4; factor *= 2) {
            fx_frame *p = NULL;
            CHECK_OK(ctx, fx_frame_reduce(f, factor, &p));
            if (!p)
                continue;
            const int pw = (w + factor - 1) / factor, ph = (h + factor - 1) / factor;
            CHECK(fx_frame_width(p) == pw && fx_frame_height(p) == ph && fx_frame_proxy_factor(p) == factor);
            const float *in_px = NULL;
            fx_frame_pass_read(p, "Combined", &in_px, NULL);
            const int mx = (w / 2) | 1, my = (h / 2) | 1;
            const int x0 = mx < w ? mx : w - 1, y0 = my < h ? my : h - 1;
            const int px = x0 / factor, py = y0 / factor;
            for (int e = 0; e < fx_effect_count(); e++) {
                const char *effect = fx_effect_name(e);
                for (int q = FX_QUALITY_DRAFT; q <= FX_QUALITY_REFERENCE; q++)
                    for (int masked = 0; masked < 2; masked++) {
                        snprintf(current_case, sizeof current_case, "%s (%s) on a 1/%d proxy of hostile %dx%d%s",
                                 effect, fx_quality_name(q), factor, w, h, masked ? ", one-pixel mask" : "");
                        run_masked_case(ctx, p, in_px, effect, q, masked, x0, y0, pw, ph, px, py);
                    }
            }
            fx_frame_free(p);
        }
        fx_frame_free(f);
    }
}

static void cameras_reference_all(fx_context *ctx, fx_frame *hostile)
{
    /* 3. degenerate cameras, for the effects that use one */
    for (int e = 0; e < fx_effect_count() && hostile; e++) {
        const char *effect = fx_effect_name(e);
        if (needs_camera(ctx, effect))
            camera_cases(ctx, effect, hostile);
    }

    /* 4. reference quality on the hostile frame (the slow, converged settings) */
    for (int e = 0; e < fx_effect_count() && hostile; e++) {
        const char *effect = fx_effect_name(e);
        snprintf(current_case, sizeof current_case, "%s defaults (reference) on hostile 17x13", effect);
        fx_stack *s = stack_for(ctx, effect, FX_QUALITY_REFERENCE);
        if (s)
            run_case(ctx, s, hostile, effect, 1);
        fx_stack_free(s);
    }

    /* 5. the whole registry as one stack (effects feed each other's extremes) */
    fx_stack *all = NULL;
    CHECK_OK(ctx, fx_stack_new(ctx, &all));
    for (int e = 0; e < fx_effect_count(); e++)
        CHECK_OK(ctx, fx_stack_append(all, fx_effect_name(e), NULL));
    fx_stack_set_quality(all, FX_QUALITY_DRAFT);
    fx_stack_set_debug_outputs(all, 1);
    snprintf(current_case, sizeof current_case, "every effect in one stack (draft) on hostile 17x13");
    if (hostile)
        run_case(ctx, all, hostile, "", 1);
    fx_stack_free(all);
}

int main(void)
{
    double t_start = now_s();

    fx_context *ctx = NULL;
    CHECK_OK(ctx, fx_context_new(&ctx, 2));
    if (!ctx)
        return tu_finish("test_extremes");
    dir = tu_tmpdir("extremes");
    write_aux_views(ctx, dir);

    fx_frame *hostile = make_frame(ctx, 17, 13, HOSTILE_EXR, SIDECAR_LIGHTS_FRONT);
    CHECK(hostile != NULL);

    sweep_params(ctx, hostile);
    double t_sweep = now_s();

    defaults_on_shapes(ctx);
    presets_on_odd_frames(ctx);
    presets_on_proxies(ctx);
    cameras_reference_all(ctx, hostile);
    fx_frame_free(hostile);
    fx_context_free(ctx);
    printf("test_extremes: %d runs finished, %d refused with a clear error; sweep %.1f s, total %.1f s\n",
           runs_ok, runs_refused, t_sweep - t_start, now_s() - t_start);
    return tu_finish("test_extremes");
}
