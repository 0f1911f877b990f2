/* ssr_mirror's planar views per plane (the reference preset's planar_view): a mirror entry
 * whose pixels lie on two planes (a facing pair in one entry) gets one planar view per
 * plane from the add-on ("planar:<key>" and "planar:<key>#2"), and each mirror pixel is
 * looked up in its own plane's view.
 *
 * The frame: a camera at the origin looking along -Z; the mirror (IndexMA 1) fills the
 * frame's left half on plane A (z = -4, facing the camera) and its right half on plane B
 * (turned 30 deg about Y, through (0, 0, -6)). The views are flat colours (A red, B green)
 * seen by the frame's own camera, so every mirror pixel projects into both: only the plane
 * test decides which view a pixel takes. Checked: the debug pass "planar" (1 + the view's
 * index) is 1 on A's pixels and 2 on B's; A's pixels turn red and B's green; with A's view
 * alone B's pixels take none (0) and keep the trace; a "#3" after a missing "#2" is not
 * read (the views are numbered without gaps); the output is the same for 1 and 2 threads. */
#include "fx_effect_test.h"

#include <math.h>

enum { W = 64, H = 32 };

static const double TAN_HALF = 0.57735026918962576; /* tan 30 deg: vertical half-angle */
static const double NB[3] = { 0.5, 0.0, 0.86602540378443865 }; /* plane B's normal */
static const double DB = -6.0 * 0.86602540378443865;           /* n . x = d through (0, 0, -6) */

static void ray(int x, int y, double v[3])
{
    double asp = (double)W / H;
    v[0] = ((x + 0.5) / W * 2 - 1) * TAN_HALF * asp;
    v[1] = (1 - (y + 0.5) / H * 2) * TAN_HALF;
    v[2] = -1;
}

static void camera(fx_camera *c)
{
    static const float identity[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    et_perspective(c, identity, TAN_HALF, W, H, 0.1, 100.0);
}

static fx_frame *pair_frame(fx_context *ctx)
{
    size_t n = (size_t)W * H;
    float *rgba = calloc(n * 4, sizeof(float)), *dep = calloc(n, sizeof(float));
    float *nor = calloc(n * 3, sizeof(float)), *ima = calloc(n, sizeof(float));
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            size_t i = (size_t)y * W + x;
            double v[3];
            ray(x, y, v);
            int b = x >= W / 2;
            /* planar depth t: the point t v lies on the pixel's plane (v.z = -1) */
            double t = b ? DB / (NB[0] * v[0] + NB[2] * v[2]) : 4.0;
            dep[i] = (float)t;
            nor[i * 3] = b ? (float)NB[0] : 0.0f;
            nor[i * 3 + 2] = b ? (float)NB[2] : 1.0f;
            ima[i] = 1;
            rgba[i * 4] = rgba[i * 4 + 1] = rgba[i * 4 + 2] = 0.1f;
            rgba[i * 4 + 3] = 1;
        }
    fx_frame *f = et_frame(ctx, W, H, rgba);
    fx_camera c;
    camera(&c);
    CHECK_OK(ctx, fx_frame_add_pass(f, "Depth", 1, dep));
    CHECK_OK(ctx, fx_frame_add_pass(f, "Normal", 3, nor));
    CHECK_OK(ctx, fx_frame_add_pass(f, "IndexMA", 1, ima));
    CHECK_OK(ctx, fx_frame_set_camera(f, &c));
    free(rgba), free(dep), free(nor), free(ima);
    return f;
}

/* A flat-colour view EXR (colour + Depth 50 m: the room lies beyond both planes) at
 * `path`; columns [band0, band1) instead hold a blue surface 2 m from the camera: between
 * the mirrored camera and plane A (4 m), what a frame's back behind the mirror is. */
static void write_view_band(fx_context *ctx, const char *path, float r, float g, float b, int band0, int band1)
{
    size_t n = (size_t)W * H;
    float *rgba = malloc(n * 4 * sizeof(float)), *dep = malloc(n * sizeof(float));
    for (size_t i = 0; i < n; i++) {
        int in_band = (int)(i % W) >= band0 && (int)(i % W) < band1;
        rgba[i * 4] = in_band ? 0 : r, rgba[i * 4 + 1] = in_band ? 0 : g, rgba[i * 4 + 2] = in_band ? 1 : b;
        rgba[i * 4 + 3] = 1;
        dep[i] = in_band ? 2.0f : 50.0f;
    }
    et_write_view(ctx, path, W, H, rgba, dep);
    free(rgba), free(dep);
}

static void write_view(fx_context *ctx, const char *path, float r, float g, float b)
{
    write_view_band(ctx, path, r, g, b, 0, 0);
}

/* One planar view entry: the frame's own camera, the given plane; window: "" or the
 * entry's ", \"window\": [...]" (the file holds a region of the view). */
static int add_view_window(fx_context *ctx, fx_frame *f, const char *name, const char *path, const double pl[4],
                           const char *window);

static int add_view(fx_context *ctx, fx_frame *f, const char *name, const char *path, const double pl[4])
{
    return add_view_window(ctx, f, name, path, pl, "");
}

static int add_view_window(fx_context *ctx, fx_frame *f, const char *name, const char *path, const double pl[4],
                           const char *window)
{
    fx_camera c;
    camera(&c);
    char json[4096];
    int n = snprintf(json, sizeof json, "{\"aux_views\": [{\"name\": \"%s\", \"path\": \"%s\", \"world_to_camera\": [",
                     name, path);
    for (int i = 0; i < 16; i++)
        n += snprintf(json + n, sizeof json - n, "%s%.9g", i ? ", " : "", c.world_to_camera[i]);
    n += snprintf(json + n, sizeof json - n, "], \"projection\": [");
    for (int i = 0; i < 16; i++)
        n += snprintf(json + n, sizeof json - n, "%s%.9g", i ? ", " : "", c.projection[i]);
    snprintf(json + n, sizeof json - n,
             "], \"clip_start\": 0.1, \"clip_end\": 100, \"kind\": \"planar\", \"plane\": [%.9g, %.9g, %.9g, %.9g]%s}]}",
             pl[0], pl[1], pl[2], pl[3], window);
    return fx_frame_apply_sidecar(f, json);
}

/* Runs s on f; counts per half the pixels whose debug "planar" value is `a` (left) and
 * `b` (right) and whose colour leans to red (left) / green (right) when asked. */
static void run_check(fx_context *ctx, fx_stack *s, const fx_frame *f, float a, float b, int colours,
                      fx_frame **keep)
{
    fx_frame *o = NULL;
    CHECK_OK(ctx, fx_stack_run(s, f, &o));
    float *pl = NULL, *rgb = NULL;
    int c = 0;
    CHECK(o && fx_frame_pass(o, "fx0_ssr_mirror_planar", &pl, &c) == FX_OK && c == 1);
    CHECK(o && fx_frame_pass(o, "Combined", &rgb, &c) == FX_OK && c == 4);
    int ok_a = 0, ok_b = 0, red = 0, green = 0;
    for (int y = 0; pl && rgb && y < H; y++)
        for (int x = 0; x < W; x++) {
            size_t i = (size_t)y * W + x;
            if (x < W / 2) {
                ok_a += pl[i] == a;
                red += rgb[i * 4] > rgb[i * 4 + 1] + 0.05f;
            } else {
                ok_b += pl[i] == b;
                green += rgb[i * 4 + 1] > rgb[i * 4] + 0.05f;
            }
        }
    int half = W / 2 * H;
    printf("planar %g/%g: %d and %d of %d pixels per half; red %d, green %d\n", a, b, ok_a, ok_b, half, red, green);
    CHECK(ok_a == half && ok_b == half);
    if (colours)
        CHECK(red == half && green == half);
    if (keep)
        *keep = o;
    else
        fx_frame_free(o);
}

/* The planar view a recipe asks the add-on for (fx_stack_required_aux_views): none at
 * draft and preview, at twice the render's samples at final (samples_scale 2), 4x at reference;
 * an explicit planar_samples wins; a glossy mirror reads none. A recipe of params_version 2
 * that turned planar_view on itself rendered it at 4x: it keeps 4 (ssr_migrate). */
static void check_need(fx_context *ctx, const char *quality, int version, const char *params, const char *want)
{
    char recipe[400];
    snprintf(recipe, sizeof recipe,
             "{\"version\": 1, \"quality\": \"%s\", \"effects\": [{\"effect\": \"ssr_mirror\", "
             "\"params_version\": %d, \"params\": %s, \"mask\": {\"material\": \"M\"}}]}",
             quality, version, params);
    fx_stack *s = NULL;
    char *req = NULL;
    CHECK_OK(ctx, fx_stack_new(ctx, &s));
    CHECK_OK(ctx, fx_stack_load_json(s, recipe));
    CHECK_OK(ctx, fx_stack_required_aux_views(s, &req));
    const char *at = req ? strstr(req, "\"kind\":\"planar\"") : NULL;
    const char *scale = at ? strstr(at, "\"samples_scale\":") : NULL;
    char got[16] = "none";
    if (scale)
        snprintf(got, sizeof got, "%.4s", scale + strlen("\"samples_scale\":"));
    else if (at)
        snprintf(got, sizeof got, "unset");
    if (strncmp(got, want, strlen(want)) != 0 || (strcmp(want, "none") && !scale))
        printf("planar need of %s: %s, want %s (%s)\n", recipe, got, want, req ? req : "-");
    CHECK(strncmp(got, want, strlen(want)) == 0);
    fx_free(req);
    fx_stack_free(s);
}

static void test_planar_needs(fx_context *ctx)
{
    static const char *const q[] = { "draft", "preview", "final", "reference" };
    static const char *const want[] = { "none", "none", "2", "4" };
    for (int k = 0; k < 4; k++)
        check_need(ctx, q[k], 3, "{}", want[k]);
    check_need(ctx, "final", 3, "{\"planar_samples\": 3}", "3");
    check_need(ctx, "final", 3, "{\"glossiness\": 2}", "none");
    check_need(ctx, "preview", 2, "{\"planar_view\": true}", "4");
    check_need(ctx, "final", 2, "{}", "2");
}

/* A planar view listed as absent (the add-on found the mirror not flat): the run takes
 * the trace as with no planar_view, with no warning; a frame without the entry warns.
 * Malformed absent entries are refused, naming the entry. */
static void test_absent_view(fx_context *ctx, const char *name)
{
    fx_frame *f = pair_frame(ctx), *o_abs = NULL, *o_off = NULL, *o_missing = NULL;
    fx_stack *s = et_stack(ctx, "ssr_mirror");
    CHECK_OK(ctx, fx_stack_set_mask_json(s, 0, "{\"material_index\": 1}"));
    CHECK_OK(ctx, fx_stack_set_quality(s, FX_QUALITY_FINAL));
    fx_context_clear_warnings(ctx);
    CHECK_OK(ctx, fx_stack_run(s, f, &o_missing));
    int warned = 0;
    for (int k = 0; k < fx_context_warning_count(ctx); k++)
        warned += tu_contains(fx_context_warning(ctx, k), "no planar mirror view");
    CHECK(warned == 1);
    char json[400];
    snprintf(json, sizeof json, "{\"aux_views\": [{\"name\": \"%s\", \"absent\": \"the mirror is not flat\"}]}",
             name);
    CHECK_OK(ctx, fx_frame_apply_sidecar(f, json));
    fx_context_clear_warnings(ctx);
    CHECK_OK(ctx, fx_stack_run(s, f, &o_abs));
    warned = 0; /* (the missing probe still warns) */
    for (int k = 0; k < fx_context_warning_count(ctx); k++)
        warned += tu_contains(fx_context_warning(ctx, k), "no planar mirror view");
    CHECK(warned == 0);
    CHECK_OK(ctx, fx_stack_set_int(s, 0, "planar_view", 0));
    CHECK_OK(ctx, fx_stack_run(s, f, &o_off));
    const float *a = et_combined(o_abs), *b = et_combined(o_off), *c = et_combined(o_missing);
    CHECK(a && b && c && memcmp(a, b, (size_t)W * H * 4 * sizeof(float)) == 0);
    CHECK(a && c && memcmp(a, c, (size_t)W * H * 4 * sizeof(float)) == 0);
    static const char *const bad[] = {
        "{\"aux_views\": [{\"name\": \"planar:x\", \"absent\": \"\"}]}",
        "{\"aux_views\": [{\"name\": \"planar:x\", \"absent\": 1}]}",
        "{\"aux_views\": [{\"name\": \"planar:x\", \"absent\": \"r\", \"path\": \"/tmp/v.exr\"}]}",
    };
    for (int k = 0; k < 3; k++) {
        fx_result r = fx_frame_apply_sidecar(f, bad[k]);
        CHECK(r == FX_ERR_BAD_RECIPE && tu_contains(fx_context_error(ctx), "'planar:x'") &&
              tu_contains(fx_context_error(ctx), "absent"));
        if (r != FX_ERR_BAD_RECIPE)
            printf("absent entry %d accepted\n", k);
    }
    fx_frame_free(o_abs), fx_frame_free(o_off), fx_frame_free(o_missing), fx_frame_free(f);
    fx_stack_free(s);
}

/* A view that shows, over columns 10-13, a surface between the mirrored camera and the
 * plane: the mirror pixels whose lookup (or its neighbours) falls there keep the trace
 * (debug "planar" 0) and show none of its blue; every other pixel of plane A takes the view. */
static void test_behind_plane(fx_context *ctx, const char *name, const double plane_a[4])
{
    const char *dir = tu_tmpdir("planar_views_band");
    char pa[600];
    snprintf(pa, sizeof pa, "%s/plane_a_band.exr", dir);
    write_view_band(ctx, pa, 1.0f, 0.0f, 0.0f, 10, 14);
    fx_frame *f = pair_frame(ctx), *o = NULL;
    fx_stack *s = et_stack(ctx, "ssr_mirror");
    CHECK_OK(ctx, fx_stack_set_mask_json(s, 0, "{\"material_index\": 1}"));
    CHECK_OK(ctx, fx_stack_set_quality(s, FX_QUALITY_REFERENCE));
    fx_stack_set_debug_outputs(s, 1);
    CHECK_OK(ctx, add_view(ctx, f, name, pa, plane_a));
    CHECK_OK(ctx, fx_stack_run(s, f, &o));
    float *pl = NULL, *rgb = NULL;
    int c = 0, wrong = 0, blue = 0;
    CHECK(o && fx_frame_pass(o, "fx0_ssr_mirror_planar", &pl, &c) == FX_OK);
    CHECK(o && fx_frame_pass(o, "Combined", &rgb, &c) == FX_OK);
    for (int y = 0; pl && rgb && y < H; y++)
        for (int x = 0; x < W / 2; x++) {
            size_t i = (size_t)y * W + x;
            int near_band = x >= 8 && x <= 14; /* the taps x-1 .. x+2 meet columns 10-13 */
            wrong += pl[i] != (near_band ? 0.0f : 1.0f);
            blue += rgb[i * 4 + 2] > 0.5f;
        }
    printf("a surface behind plane A over columns 10-13: %d pixels wrongly looked up, %d blue\n", wrong, blue);
    CHECK(wrong == 0 && blue == 0);
    fx_frame_free(o), fx_frame_free(f);
    fx_stack_free(s);
}

/* A view rendered cropped to its region (the add-on's planar views: "window": [x0, y0, W,
 * H]): a 24x28 file for columns 4-27 and rows 2-29 of the 64x32 view. Plane A's pixels
 * that look up inside it take it, the others keep the trace; a window the file does not
 * fit in is refused with a warning naming it. */
static void test_cropped_view(fx_context *ctx, const char *name, const double plane_a[4])
{
    const char *dir = tu_tmpdir("planar_views_crop");
    char pa[600];
    snprintf(pa, sizeof pa, "%s/plane_a_crop.exr", dir);
    enum { CW = 24, CH = 28 };
    float *rgba = malloc((size_t)CW * CH * 4 * sizeof(float)), *dep = malloc((size_t)CW * CH * sizeof(float));
    for (size_t i = 0; i < (size_t)CW * CH; i++) {
        rgba[i * 4] = 1, rgba[i * 4 + 1] = 0, rgba[i * 4 + 2] = 0, rgba[i * 4 + 3] = 1;
        dep[i] = 50.0f;
    }
    et_write_view(ctx, pa, CW, CH, rgba, dep);
    free(rgba), free(dep);
    fx_frame *f = pair_frame(ctx), *o = NULL;
    fx_stack *s = et_stack(ctx, "ssr_mirror");
    CHECK_OK(ctx, fx_stack_set_mask_json(s, 0, "{\"material_index\": 1}"));
    CHECK_OK(ctx, fx_stack_set_quality(s, FX_QUALITY_REFERENCE));
    fx_stack_set_debug_outputs(s, 1);
    CHECK_OK(ctx, add_view_window(ctx, f, name, pa, plane_a, ", \"window\": [4, 2, 64, 32]"));
    CHECK_OK(ctx, fx_stack_run(s, f, &o));
    float *pl = NULL;
    int c = 0, wrong = 0;
    CHECK(o && fx_frame_pass(o, "fx0_ssr_mirror_planar", &pl, &c) == FX_OK);
    for (int y = 0; pl && y < H; y++)
        for (int x = 0; x < W / 2; x++)
            wrong += pl[(size_t)y * W + x] != ((x >= 4 && x <= 27 && y >= 2 && y <= 29) ? 1.0f : 0.0f);
    printf("a view cropped to columns 4-27, rows 2-29: %d pixels wrongly looked up\n", wrong);
    CHECK(wrong == 0);
    fx_frame_free(o);
    o = NULL;
    /* the file does not fit: 4 + 24 > 27 */
    CHECK_OK(ctx, add_view_window(ctx, f, name, pa, plane_a, ", \"window\": [4, 2, 27, 32]"));
    fx_context_clear_warnings(ctx);
    CHECK_OK(ctx, fx_stack_run(s, f, &o));
    int warned = 0;
    for (int k = 0; k < fx_context_warning_count(ctx); k++)
        warned += tu_contains(fx_context_warning(ctx, k), "no planar mirror view") &&
                  tu_contains(fx_context_warning(ctx, k), "do not fit its \"window\" of 27x32");
    CHECK(warned == 1);
    /* a window of fractions: refused with the sidecar */
    CHECK(add_view_window(ctx, f, name, pa, plane_a, ", \"window\": [4.5, 2, 64, 32]") == FX_ERR_BAD_RECIPE &&
          tu_contains(fx_context_error(ctx), "\"window\" must be 4 whole numbers"));
    fx_frame_free(o), fx_frame_free(f);
    fx_stack_free(s);
}

int main(void)
{
    fx_context *ctx = NULL;
    fx_context_new(&ctx, 2);
    test_planar_needs(ctx);
    const char *dir = tu_tmpdir("planar_views");
    char pa[600], pb[600];
    snprintf(pa, sizeof pa, "%s/plane_a.exr", dir);
    snprintf(pb, sizeof pb, "%s/plane_b.exr", dir);
    write_view(ctx, pa, 1.0f, 0.0f, 0.0f);
    write_view(ctx, pb, 0.0f, 1.0f, 0.0f);
    const double plane_a[4] = { 0, 0, 1, -4 }, plane_b[4] = { NB[0], NB[1], NB[2], DB };

    fx_frame *f = pair_frame(ctx);
    fx_stack *s = et_stack(ctx, "ssr_mirror");
    CHECK_OK(ctx, fx_stack_set_mask_json(s, 0, "{\"material_index\": 1}"));
    CHECK_OK(ctx, fx_stack_set_quality(s, FX_QUALITY_REFERENCE));
    fx_stack_set_debug_outputs(s, 1);
    char *req = NULL;
    CHECK_OK(ctx, fx_stack_required_aux_views(s, &req));
    char name[64] = "planar:?", name2[80], name3[80];
    const char *at = req ? strstr(req, "\"planar:") : NULL;
    if (at)
        snprintf(name, 20, "%s", at + 1); /* "planar:" and 12 hex digits */
    fx_free(req);
    test_absent_view(ctx, name);
    test_behind_plane(ctx, name, plane_a);
    test_cropped_view(ctx, name, plane_a);
    snprintf(name2, sizeof name2, "%s#2", name);
    snprintf(name3, sizeof name3, "%s#3", name);

    /* A's view alone: A's pixels take it (1), B's none (0) */
    CHECK_OK(ctx, add_view(ctx, f, name, pa, plane_a));
    run_check(ctx, s, f, 1.0f, 0.0f, 0, NULL);
    /* a "#3" without a "#2": not read */
    CHECK_OK(ctx, add_view(ctx, f, name3, pb, plane_b));
    run_check(ctx, s, f, 1.0f, 0.0f, 0, NULL);
    /* both planes: each pixel its own plane's view, in its colour */
    CHECK_OK(ctx, add_view(ctx, f, name2, pb, plane_b));
    fx_frame *o2 = NULL, *o1 = NULL;
    run_check(ctx, s, f, 1.0f, 2.0f, 1, &o2);
    /* the views in the other order (B first): the pixels follow their plane, not the name */
    CHECK_OK(ctx, add_view(ctx, f, name, pb, plane_b));
    CHECK_OK(ctx, add_view(ctx, f, name2, pa, plane_a));
    run_check(ctx, s, f, 2.0f, 1.0f, 1, NULL);
    /* one thread: the same bits */
    CHECK_OK(ctx, add_view(ctx, f, name, pa, plane_a));
    CHECK_OK(ctx, add_view(ctx, f, name2, pb, plane_b));
    fx_context *ctx1 = NULL;
    fx_context_new(&ctx1, 1);
    fx_frame *f1 = pair_frame(ctx1);
    CHECK_OK(ctx1, add_view(ctx1, f1, name, pa, plane_a));
    CHECK_OK(ctx1, add_view(ctx1, f1, name2, pb, plane_b));
    fx_stack *s1 = et_stack(ctx1, "ssr_mirror");
    CHECK_OK(ctx1, fx_stack_set_mask_json(s1, 0, "{\"material_index\": 1}"));
    CHECK_OK(ctx1, fx_stack_set_quality(s1, FX_QUALITY_REFERENCE));
    fx_stack_set_debug_outputs(s1, 1);
    CHECK_OK(ctx1, fx_stack_run(s1, f1, &o1));
    const float *a = et_combined(o2), *b = et_combined(o1);
    CHECK(a && b && memcmp(a, b, (size_t)W * H * 4 * sizeof(float)) == 0);
    CHECK(b && tu_all_finite(b, (size_t)W * H * 4));
    fx_frame_free(o1), fx_frame_free(o2), fx_frame_free(f1), fx_frame_free(f);
    fx_stack_free(s1), fx_stack_free(s);
    fx_context_free(ctx1);
    fx_context_free(ctx);
    return tu_finish("test_planar_views");
}
