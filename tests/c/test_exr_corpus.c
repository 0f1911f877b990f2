/* The reader against real files of other tools (../shared/exr-corpus, see its README):
 * damaged files, numeric extremes, display windows, stereo multipart/singlepart,
 * mipmaps and Cryptomatte. Run it under AddressSanitizer too (LIBFX_ASAN=ON). */
#include "testutil.h"

#include "core/mask.h"

#include <dirent.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static char corpus[1024];

static const char *cpath(const char *rel)
{
    static char buf[4][1400];
    static int next;
    char *b = buf[next++ & 3];
    snprintf(b, sizeof buf[0], "%s/%s", corpus, rel);
    return b;
}

/* The reference conversion of IEEE half bits to float (denormals included). */
static float half_to_float(unsigned h)
{
    unsigned s = (h >> 15) & 1, e = (h >> 10) & 31, m = h & 1023;
    double v;
    if (e == 0)
        v = ldexp((double)m, -24);
    else if (e == 31)
        v = m ? NAN : INFINITY;
    else
        v = ldexp((double)(m | 1024), (int)e - 25);
    return (float)(s ? -v : v);
}

static int warned(fx_context *ctx, const char *needle)
{
    for (int i = 0; i < fx_context_warning_count(ctx); i++)
        if (tu_contains(fx_context_warning(ctx, i), needle))
            return 1;
    return 0;
}

static void test_damaged(fx_context *ctx)
{
    const char *dir = cpath("openexr-images/Damaged");
    DIR *d = opendir(dir);
    CHECK(d != NULL);
    if (!d)
        return;
    int n = 0;
    for (struct dirent *e; (e = readdir(d));) {
        if (e->d_name[0] == '.' || strcmp(e->d_name, "README.rst") == 0)
            continue;
        char path[2048];
        snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
        fx_frame *f = (fx_frame *)(void *)&n; /* must be reset to NULL */
        fx_result r = fx_frame_read_exr(ctx, path, NULL, &f);
        n++;
        CHECK(r != FX_OK);
        CHECK(f == NULL);
        if (r == FX_OK) {
            fprintf(stderr, "damaged file read without error: %s\n", e->d_name);
            fx_frame_free(f);
            continue;
        }
        CHECK(r == FX_ERR_BAD_FILE || r == FX_ERR_LIMIT || r == FX_ERR_IO);
        if (!tu_contains(fx_context_error(ctx), e->d_name)) {
            fprintf(stderr, "message does not name %s: %s\n", e->d_name, fx_context_error(ctx));
            CHECK(0);
        }
        /* the header report must survive them too (it may accept a file whose pixels are bad) */
        char *info = NULL;
        if (fx_exr_info_json(ctx, path, &info) == FX_OK) {
            CHECK(info != NULL);
            fx_free(info);
        } else {
            CHECK(info == NULL);
            CHECK(tu_contains(fx_context_error(ctx), e->d_name));
        }
    }
    closedir(d);
    CHECK(n > 50);
    fx_context_clear_warnings(ctx);
}

static void test_bad_inputs(fx_context *ctx)
{
    fx_frame *f = NULL;
    CHECK_FAIL(ctx, fx_frame_read_exr(ctx, "/nonexistent/x.exr", NULL, &f), FX_ERR_IO,
               "cannot open '/nonexistent/x.exr': No such file or directory");
    const char *dir = tu_tmpdir("exr_corpus");
    char p[600];
    snprintf(p, sizeof p, "%s/empty.exr", dir);
    FILE *fp = fopen(p, "wb");
    if (fp)
        fclose(fp);
    CHECK_FAIL(ctx, fx_frame_read_exr(ctx, p, NULL, &f), FX_ERR_BAD_FILE, "empty.exr");
    snprintf(p, sizeof p, "%s/text.exr", dir);
    fp = fopen(p, "wb");
    if (fp) {
        fputs("this is not an image\n", fp);
        fclose(fp);
    }
    CHECK_FAIL(ctx, fx_frame_read_exr(ctx, p, NULL, &f), FX_ERR_BAD_FILE, "text.exr");
    CHECK_FAIL(ctx, fx_frame_read_exr(ctx, dir, NULL, &f), FX_ERR_IO, dir);

    /* truncated: the first 60% of a good file */
    const char *good = cpath("openexr-images/DisplayWindow/t08.exr");
    FILE *in = fopen(good, "rb");
    snprintf(p, sizeof p, "%s/truncated.exr", dir);
    FILE *out = fopen(p, "wb");
    if (in && out) {
        fseek(in, 0, SEEK_END);
        long n = ftell(in);
        fseek(in, 0, SEEK_SET);
        char *buf = malloc((size_t)n);
        if (buf && fread(buf, 1, (size_t)n, in) == (size_t)n)
            fwrite(buf, 1, (size_t)(n * 6 / 10), out);
        free(buf);
    }
    if (in)
        fclose(in);
    if (out)
        fclose(out);
    CHECK_FAIL(ctx, fx_frame_read_exr(ctx, p, NULL, &f), FX_ERR_BAD_FILE, "truncated.exr");
    CHECK(f == NULL);

    fx_read_options bad = {1, NULL, NULL, NULL};
    CHECK_FAIL(ctx, fx_frame_read_exr(ctx, good, &bad, &f), FX_ERR_INVALID_ARGUMENT, "size");

    /* limits: a context that allows less than the image */
    fx_context *small = NULL;
    CHECK_OK(small, fx_context_new(&small, 1));
    CHECK_OK(small, fx_context_set_limits(small, 100, 100, 1 << 20));
    CHECK_FAIL(small, fx_frame_read_exr(small, good, NULL, &f), FX_ERR_BAD_FILE, "t08.exr");
    CHECK_OK(small, fx_context_set_limits(small, 1000, 1000, 1 << 20));
    CHECK_FAIL(small, fx_frame_read_exr(small, good, NULL, &f), FX_ERR_LIMIT, "t08.exr");
    fx_context_free(small);
}

static void test_test_images(fx_context *ctx)
{
    fx_frame *f = NULL;
    float *px = NULL;
    int nc = 0;
    fx_context_clear_warnings(ctx);
    CHECK_OK(ctx, fx_frame_read_exr(ctx, cpath("openexr-images/TestImages/BrightRingsNanInf.exr"), NULL, &f));
    if (f) {
        CHECK_OK(ctx, fx_frame_pass(f, "Combined", &px, &nc));
        CHECK(nc == 4 && px && tu_all_finite(px, (size_t)800 * 800 * 4));
        CHECK(warned(ctx, "NaN/Inf values in pass Combined replaced"));
        CHECK(warned(ctx, "BrightRingsNanInf.exr"));
        fx_frame_free(f);
        f = NULL;
    }

    CHECK_OK(ctx, fx_frame_read_exr(ctx, cpath("openexr-images/TestImages/AllHalfValues.exr"), NULL, &f));
    if (f) {
        CHECK(fx_frame_width(f) == 256 && fx_frame_height(f) == 256);
        CHECK_OK(ctx, fx_frame_pass(f, "Combined", &px, &nc));
        int bad = 0;
        for (unsigned i = 0; px && i < 65536; i++) {
            float want = half_to_float(i);
            if (isnan(want))
                want = 0.0f;
            else if (isinf(want))
                want = want > 0 ? FLT_MAX : -FLT_MAX;
            for (int c = 0; c < 3; c++)
                if (memcmp(&px[i * 4 + c], &want, 4) != 0 && !(want == 0 && px[i * 4 + c] == 0))
                    bad++;
            if (px[i * 4 + 3] != 1.0f)
                bad++;
        }
        CHECK(bad == 0);
        /* the smallest denormal is there, exactly */
        CHECK(px && px[1 * 4] == ldexpf(1.0f, -24));
        fx_frame_free(f);
        f = NULL;
    }

    CHECK_OK(ctx, fx_frame_read_exr(ctx, cpath("openexr-images/TestImages/WideFloatRange.exr"), NULL, &f));
    if (f) {
        CHECK_OK(ctx, fx_frame_pass(f, "Combined", &px, &nc));
        size_t n = (size_t)fx_frame_width(f) * fx_frame_height(f);
        float mx = 0, mn = FLT_MAX;
        for (size_t i = 0; px && i < n; i++) {
            float v = fabsf(px[i * 4 + 1]);
            if (v > mx)
                mx = v;
            if (v > 0 && v < mn)
                mn = v;
            if (px[i * 4] != px[i * 4 + 1] || px[i * 4 + 2] != px[i * 4 + 1]) /* lone G: gray */
                mx = NAN;
        }
        CHECK(mx > 1e20f && mn < 1e-20f);
        CHECK(tu_all_finite(px, n * 4));
        fx_frame_free(f);
        f = NULL;
    }

    CHECK_OK(ctx, fx_frame_read_exr(ctx, cpath("openexr-images/TestImages/GrayRampsHorizontal.exr"), NULL, &f));
    if (f) {
        CHECK_OK(ctx, fx_frame_pass(f, "Combined", &px, &nc));
        CHECK(px && px[400 * 4] == px[400 * 4 + 1] && px[400 * 4 + 3] == 1.0f);
        fx_frame_free(f);
        f = NULL;
    }
}

static void test_display_window(fx_context *ctx)
{
    fx_frame *f = NULL;
    int dw[4], disp[4];
    CHECK_OK(ctx, fx_frame_read_exr(ctx, cpath("openexr-images/DisplayWindow/t08.exr"), NULL, &f));
    if (f) {
        fx_frame_windows(f, dw, disp);
        CHECK(dw[0] == 30 && dw[1] == 40 && dw[2] == 429 && dw[3] == 339);
        CHECK(disp[0] == 0 && disp[1] == 0 && disp[2] == 500 && disp[3] == 400);
        CHECK(fx_frame_width(f) == 400 && fx_frame_height(f) == 300);
        fx_frame_free(f);
        f = NULL;
    }
    CHECK_OK(ctx, fx_frame_read_exr(ctx, cpath("openexr-images/DisplayWindow/t16.exr"), NULL, &f));
    if (f) {
        fx_frame_windows(f, dw, disp);
        CHECK(disp[0] == -40 && disp[1] == -40 && disp[2] == 440 && disp[3] == 330);
        CHECK(dw[0] == 0 && dw[2] == 399);
        fx_frame_free(f);
        f = NULL;
    }
}

/* Combined of a (view) from both Beachball files: the same pixels where both have data. */
static void test_beachball(fx_context *ctx)
{
    char *info = NULL;
    CHECK_OK(ctx, fx_exr_info_json(ctx, cpath("openexr-images/Beachball/singlepart.0001.exr"), &info));
    CHECK(tu_contains(info, "\"views\":[\"right\",\"left\"]"));
    CHECK(tu_contains(info, "\"multipart\":false"));
    CHECK(tu_contains(info, "{\"name\":\"forward.left.u\",\"type\":\"half\"}"));
    fx_free(info);
    CHECK_OK(ctx, fx_exr_info_json(ctx, cpath("openexr-images/Beachball/multipart.0001.exr"), &info));
    CHECK(tu_contains(info, "\"views\":[\"right\",\"left\"]"));
    CHECK(tu_contains(info, "\"multipart\":true"));
    CHECK(tu_contains(info, "\"name\":\"whitebarmask_left\""));
    fx_free(info);

    const char *views[2] = {"right", "left"};
    fx_frame *fs[2] = {NULL, NULL}, *fm[2] = {NULL, NULL};
    for (int v = 0; v < 2; v++) {
        fx_read_options o = {sizeof o, NULL, v ? views[v] : NULL, NULL};
        CHECK_OK(ctx, fx_frame_read_exr(ctx, cpath("openexr-images/Beachball/singlepart.0001.exr"), &o, &fs[v]));
        CHECK_OK(ctx, fx_frame_read_exr(ctx, cpath("openexr-images/Beachball/multipart.0001.exr"), &o, &fm[v]));
    }
    for (int v = 0; v < 2; v++) {
        if (!fs[v] || !fm[v])
            continue;
        float *a = NULL, *b = NULL;
        int ca = 0, cb = 0;
        CHECK_OK(ctx, fx_frame_pass(fs[v], "Combined", &a, &ca));
        CHECK_OK(ctx, fx_frame_pass(fm[v], "Combined", &b, &cb));
        CHECK(fx_frame_pass(fs[v], "Depth", &a, &ca) == FX_OK && ca == 1);
        CHECK(fx_frame_pass(fm[v], "Depth", &b, &cb) == FX_OK && cb == 1);
        CHECK(fx_frame_pass(fs[v], "forward", &a, &ca) == FX_OK && ca == 2);
        CHECK(fx_frame_pass(fm[v], "forward", &b, &cb) == FX_OK && cb == 2);
        CHECK(fx_frame_pass(fm[v], "disparityL", &b, &cb) == FX_OK && cb == 2);
        CHECK(fx_frame_pass(fm[v], "whitebarmask", &b, &cb) == FX_OK && cb == 1);
        /* compare Combined over the intersection of the data windows */
        int ds[4], dm[4], disp[4];
        fx_frame_windows(fs[v], ds, disp);
        fx_frame_windows(fm[v], dm, disp);
        fx_frame_pass(fs[v], "Combined", &a, &ca);
        fx_frame_pass(fm[v], "Combined", &b, &cb);
        int x0 = ds[0] > dm[0] ? ds[0] : dm[0], x1 = ds[2] < dm[2] ? ds[2] : dm[2];
        int y0 = ds[1] > dm[1] ? ds[1] : dm[1], y1 = ds[3] < dm[3] ? ds[3] : dm[3];
        int ws = ds[2] - ds[0] + 1, wm = dm[2] - dm[0] + 1;
        long diff = 0, nonzero = 0;
        for (int y = y0; y <= y1; y++)
            for (int x = x0; x <= x1; x++)
                for (int c = 0; c < 4; c++) {
                    float va = a[((size_t)(y - ds[1]) * ws + (x - ds[0])) * 4 + c];
                    float vb = b[((size_t)(y - dm[1]) * wm + (x - dm[0])) * 4 + c];
                    diff += va != vb;
                    nonzero += va != 0;
                }
        CHECK(diff == 0);
        CHECK(nonzero > 1000);
    }
    /* the two views differ */
    if (fs[0] && fs[1]) {
        float *a = NULL, *b = NULL;
        int ca = 0, cb = 0;
        fx_frame_pass(fs[0], "Combined", &a, &ca);
        fx_frame_pass(fs[1], "Combined", &b, &cb);
        size_t n = (size_t)fx_frame_width(fs[0]) * fx_frame_height(fs[0]) * 4;
        CHECK(fx_frame_width(fs[0]) == fx_frame_width(fs[1]) && tu_max_abs_diff(a, b, n) > 0.1);
    }
    for (int v = 0; v < 2; v++) {
        fx_frame_free(fs[v]);
        fx_frame_free(fm[v]);
    }
    fx_frame *f = NULL;
    fx_read_options o = {sizeof o, NULL, "center", NULL};
    CHECK_FAIL(ctx, fx_frame_read_exr(ctx, cpath("openexr-images/Beachball/multipart.0001.exr"), &o, &f),
               FX_ERR_INVALID_ARGUMENT, "views: 'right', 'left'");
    fx_read_options ol = {sizeof ol, "ViewLayer", NULL, NULL};
    CHECK_FAIL(ctx, fx_frame_read_exr(ctx, cpath("openexr-images/Beachball/singlepart.0001.exr"), &ol, &f),
               FX_ERR_INVALID_ARGUMENT, "no layer 'ViewLayer'");
    CHECK(f == NULL);
}

static void test_mipmap(fx_context *ctx)
{
    fx_frame *f = NULL;
    CHECK_OK(ctx, fx_frame_read_exr(ctx, cpath("openexr-images/MultiResolution/ColorCodedLevels.exr"), NULL, &f));
    if (f) {
        CHECK(fx_frame_width(f) == 512 && fx_frame_height(f) == 512);
        float *px = NULL;
        int nc = 0;
        CHECK_OK(ctx, fx_frame_pass(f, "Combined", &px, &nc));
        /* values checked against OpenImageIO's reading of level 0 */
        CHECK(px && fabsf(px[0] - 0.21862793f) < 1e-6f && px[3] == 1.0f);
        CHECK(px && px[(100 * 512 + 100) * 4] == 0.0f && px[(100 * 512 + 100) * 4 + 3] == 1.0f);
        fx_frame_free(f);
    }
}

/* An id of `name` (via the Cryptomatte hash) appears in a rank's R or B channel. */
static int id_in_pass(const fx_frame *f, const char *pass, const char *name)
{
    float *px = NULL;
    int nc = 0;
    if (fx_frame_pass(f, pass, &px, &nc) != FX_OK || nc != 4)
        return 0;
    float id = fx_cryptomatte_id(name);
    size_t n = (size_t)fx_frame_width(f) * fx_frame_height(f);
    for (size_t i = 0; i < n; i++)
        if (memcmp(&px[i * 4], &id, 4) == 0 || memcmp(&px[i * 4 + 2], &id, 4) == 0)
            return 1;
    return 0;
}

static void test_cryptomatte(fx_context *ctx)
{
    fx_frame *f = NULL;
    CHECK_OK(ctx, fx_frame_read_exr(ctx, cpath("cryptomatte/multichannel.exr"), NULL, &f));
    if (f) {
        const char *m = fx_frame_meta(f, "cryptomatte/CryptoObject/manifest");
        CHECK(tu_contains(m, "box:polygons:1")); /* JSON escapes the slashes */
        CHECK(tu_contains(fx_frame_meta(f, "cryptomatte/CryptoAsset/manifest"), "ball_asset"));
        CHECK(tu_contains(fx_frame_meta(f, "cryptomatte/CryptoMaterial/manifest"), "standard_surface1"));
        CHECK(tu_contains(fx_frame_meta(f, "cryptomatte/CryptoAsset/layer"), "crypto_asset"));
        CHECK(id_in_pass(f, "CryptoAsset00", "ball_asset"));
        CHECK(id_in_pass(f, "CryptoAsset00", "toroidal_asset"));
        CHECK(id_in_pass(f, "CryptoObject00", "/obj/box:polygons:1"));
        float *px = NULL;
        int nc = 0;
        CHECK(fx_frame_pass(f, "CryptoMaterial02", &px, &nc) == FX_OK && nc == 4);
        CHECK(fx_frame_pass(f, "pscale", &px, &nc) == FX_OK && nc == 1);
        CHECK(fx_frame_pass(f, "Cd", &px, &nc) == FX_OK && nc == 3);
        fx_frame_free(f);
        f = NULL;
    }
    /* the murmur hash of the manifest's names is the hex in the manifest */
    CHECK(fx_murmur3_32("ball_asset", strlen("ball_asset"), 0) == 0x79b62f5eu);

    CHECK_OK(ctx, fx_frame_read_exr(ctx, cpath("cryptomatte/special_chars.exr"), NULL, &f));
    if (f) {
        const char *m = fx_frame_meta(f, "cryptomatte/special_chars/manifest");
        CHECK(tu_contains(m, "равнина"));
        CHECK(id_in_pass(f, "special_chars00", "равнина"));
        CHECK(id_in_pass(f, "special_chars00", "name, with, comma"));
        fx_frame_free(f);
        f = NULL;
    }
    fx_context_clear_warnings(ctx);
    CHECK_OK(ctx, fx_frame_read_exr(ctx, cpath("cryptomatte/sidecar_manifest.exr"), NULL, &f));
    if (f) {
        CHECK(tu_contains(fx_frame_meta(f, "cryptomatte/CryptoAsset/manifest"), "leftAsset"));
        CHECK(id_in_pass(f, "CryptoAsset00", "leftAsset"));
        CHECK(fx_context_warning_count(ctx) == 0);
        fx_frame_free(f);
        f = NULL;
    }
    CHECK_OK(ctx, fx_frame_read_exr(ctx, cpath("cryptomatte/cornellBox_CryptoWildcard.0001.exr"), NULL, &f));
    if (f) {
        int dw[4], disp[4];
        fx_frame_windows(f, dw, disp);
        CHECK(dw[0] == 167 && disp[2] == 959);
        CHECK(tu_contains(fx_frame_meta(f, "cryptomatte/uCryptoWildcard/manifest"), "sphere_?_2"));
        CHECK(id_in_pass(f, "uCryptoWildcard00", "sphere_?_2"));
        CHECK(tu_contains(fx_frame_meta(f, "vrayInfo/camera"), "RENDER_CAM"));
        fx_frame_free(f);
        f = NULL;
    }
    char *info = NULL;
    CHECK_OK(ctx, fx_exr_info_json(ctx, cpath("cryptomatte/multichannel.exr"), &info));
    CHECK(tu_contains(info, "\"type\":\"CryptoObject\""));
    CHECK(tu_contains(info, "\"tiled\":true"));
    CHECK(tu_contains(info, "\"names\":[\"ball_asset\",\"toroidal_asset\"]"));
    CHECK(tu_contains(info, "\"manifest_entries\":2"));
    fx_free(info);
    CHECK_OK(ctx, fx_exr_info_json(ctx, cpath("cryptomatte/sidecar_manifest.exr"), &info));
    CHECK(tu_contains(info, "\"manifest_entries\":8"));
    fx_free(info);
}

/* A stack decodes only what it needs: an empty stack -> Combined only. */
static void test_stack_selection(fx_context *ctx)
{
    fx_stack *s = NULL;
    CHECK_OK(ctx, fx_stack_new(ctx, &s));
    fx_frame *f = NULL;
    fx_read_options o = {sizeof o, NULL, NULL, s};
    CHECK_OK(ctx, fx_frame_read_exr(ctx, cpath("cryptomatte/multichannel.exr"), &o, &f));
    CHECK(f && fx_frame_pass_count(f) == 1 && strcmp(fx_frame_pass_name(f, 0), "Combined") == 0);
    fx_frame_free(f);
    f = NULL;
    /* an effect masked by object name needs CryptoObject: those ranks come too */
    int idx = -1;
    if (fx_effect_count() > 0 && fx_stack_append(s, fx_effect_name(0), &idx) == FX_OK &&
        fx_stack_set_mask_json(s, idx, "{\"object\": \"/obj/box:polygons:1\"}") == FX_OK) {
        CHECK_OK(ctx, fx_frame_read_exr(ctx, cpath("cryptomatte/multichannel.exr"), &o, &f));
        float *px = NULL;
        int nc = 0;
        CHECK(f && fx_frame_pass(f, "CryptoObject00", &px, &nc) == FX_OK);
        CHECK(f && fx_frame_pass(f, "CryptoAsset00", &px, &nc) != FX_OK);
        CHECK(f && fx_frame_pass(f, "pscale", &px, &nc) != FX_OK);
        fx_frame_free(f);
    }
    fx_stack_free(s);
}

int main(void)
{
    const char *env = getenv("LIBFX_CORPUS");
    snprintf(corpus, sizeof corpus, "%s", env && env[0] ? env : "../shared/exr-corpus");
    DIR *d = opendir(corpus);
    if (!d) {
        fprintf(stderr, "test_exr_corpus: the EXR corpus is missing at '%s' (set LIBFX_CORPUS)\n", corpus);
        return 1;
    }
    closedir(d);
    fx_context *ctx = NULL;
    if (fx_context_new(&ctx, 2) != FX_OK)
        return 1;
    test_damaged(ctx);
    test_bad_inputs(ctx);
    test_test_images(ctx);
    test_display_window(ctx);
    test_beachball(ctx);
    test_mipmap(ctx);
    test_cryptomatte(ctx);
    test_stack_selection(ctx);
    fx_context_free(ctx);
    return tu_finish("test_exr_corpus");
}
