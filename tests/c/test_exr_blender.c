/* Real Blender 3.4.1 files (tests/data/blender/, made by tests/data/make_blender_fixtures.py):
 * the render output (ViewLayer.* + Composite.*) and a File Output node's file (Image.R,
 * Depth.V, ...) must give the same canonical passes with the same pixels. */
#include "testutil.h"

#include "core/mask.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static char data_dir[1024];

static const char *fixture(const char *name)
{
    static char buf[2][1200];
    static int next;
    char *b = buf[next++ & 1];
    snprintf(b, sizeof buf[0], "%s/%s", data_dir, name);
    return b;
}

/* The fixtures live beside the tests: tests/c/<this file> -> tests/data/blender. */
static void find_data_dir(void)
{
    const char *env = getenv("LIBFX_TEST_DATA");
    if (env && env[0]) {
        snprintf(data_dir, sizeof data_dir, "%s/blender", env);
        return;
    }
    snprintf(data_dir, sizeof data_dir, "%s", __FILE__);
    char *slash = strrchr(data_dir, '/');
    if (slash)
        *slash = '\0'; /* tests/c */
    slash = strrchr(data_dir, '/');
    if (slash)
        *slash = '\0'; /* tests */
    else
        snprintf(data_dir, sizeof data_dir, "..");
    strncat(data_dir, "/data/blender", sizeof data_dir - strlen(data_dir) - 1);
}

static int same_pixels(const fx_frame *a, const fx_frame *b, const char *pass)
{
    float *pa = NULL, *pb = NULL;
    int ca = 0, cb = 0;
    if (fx_frame_pass(a, pass, &pa, &ca) != FX_OK || fx_frame_pass(b, pass, &pb, &cb) != FX_OK || ca != cb)
        return 0;
    size_t n = (size_t)fx_frame_width(a) * fx_frame_height(a) * ca;
    return memcmp(pa, pb, n * sizeof(float)) == 0;
}

static int has_value(const fx_frame *f, const char *pass, float v)
{
    float *p = NULL;
    int c = 0;
    if (fx_frame_pass(f, pass, &p, &c) != FX_OK)
        return 0;
    size_t n = (size_t)fx_frame_width(f) * fx_frame_height(f) * c;
    for (size_t i = 0; i < n; i++)
        if (p[i] == v)
            return 1;
    return 0;
}

int main(void)
{
    find_data_dir();
    fx_context *ctx = NULL;
    if (fx_context_new(&ctx, 2) != FX_OK)
        return 1;
    fx_frame *r = NULL, *o = NULL;
    CHECK_OK(ctx, fx_frame_read_exr(ctx, fixture("render_multilayer.exr"), NULL, &r));
    CHECK_OK(ctx, fx_frame_read_exr(ctx, fixture("fileoutput_multilayer.exr"), NULL, &o));
    if (!r || !o) {
        fprintf(stderr, "fixtures missing in %s (set LIBFX_TEST_DATA to tests/data)\n", data_dir);
        fx_frame_free(r);
        fx_frame_free(o);
        fx_context_free(ctx);
        CHECK(0);
        return tu_finish("test_exr_blender");
    }
    CHECK(fx_frame_width(r) == 64 && fx_frame_height(r) == 36);
    CHECK(fx_frame_width(o) == 64 && fx_frame_height(o) == 36);

    /* the File Output node's route: exactly Combined, Depth, IndexOB, Normal */
    CHECK(fx_frame_pass_count(o) == 4);
    const char *common[] = {"Combined", "Depth", "Normal", "IndexOB"};
    for (int i = 0; i < 4; i++) {
        int ok = same_pixels(r, o, common[i]);
        if (!ok)
            fprintf(stderr, "pass %s differs between the routes\n", common[i]);
        CHECK(ok);
    }
    /* the render output route: the view layer (not Composite) with every enabled pass */
    const char *more[] = {"Position", "IndexMA", "DiffDir", "CryptoObject00", "CryptoObject02", "CryptoMaterial00"};
    for (int i = 0; i < 6; i++) {
        float *p = NULL;
        int c = 0;
        CHECK_OK(ctx, fx_frame_pass(r, more[i], &p, &c));
    }
    CHECK(has_value(r, "IndexOB", 3.0f) && has_value(o, "IndexOB", 3.0f));
    CHECK(has_value(r, "IndexMA", 5.0f));
    CHECK(has_value(r, "Depth", 1e10f)); /* Cycles' background depth */

    /* Blender's "Frame" attribute ("001") */
    double fr = -1, fps = -1;
    fx_frame_time(r, &fr, &fps);
    CHECK(fr == 1.0);
    CHECK(tu_contains(fx_frame_meta(r, "BlenderMultiChannel"), "Blender"));

    /* Cryptomatte: manifest and layer by canonical type; the cube's id is in the pixels */
    CHECK(tu_contains(fx_frame_meta(r, "cryptomatte/CryptoObject/manifest"), "\"Cube\""));
    CHECK(tu_contains(fx_frame_meta(r, "cryptomatte/CryptoObject/layer"), "ViewLayer.CryptoObject"));
    CHECK(tu_contains(fx_frame_meta(r, "cryptomatte/CryptoMaterial/manifest"), "\"Material\""));
    CHECK(has_value(r, "CryptoObject00", fx_cryptomatte_id("Cube")));
    CHECK(has_value(r, "CryptoMaterial00", fx_cryptomatte_id("Material")));

    /* Depth is planar, not the distance to the camera: compare with Position at the
     * default camera's location (7.3589, -6.9258, 4.9583). */
    float *z = NULL, *pos = NULL;
    int cz = 0, cp = 0;
    CHECK_OK(ctx, fx_frame_pass(r, "Depth", &z, &cz));
    CHECK_OK(ctx, fx_frame_pass(r, "Position", &pos, &cp));
    if (z && pos) {
        double max_radial_gap = 0;
        int hits = 0;
        for (int i = 0; i < 64 * 36; i++) {
            if (z[i] > 1e9f)
                continue;
            double dx = pos[i * 3] - 7.3589, dy = pos[i * 3 + 1] + 6.9258, dz = pos[i * 3 + 2] - 4.9583;
            double radial = sqrt(dx * dx + dy * dy + dz * dz);
            CHECK(z[i] <= radial + 1e-3); /* planar depth never exceeds the distance */
            if (radial - z[i] > max_radial_gap)
                max_radial_gap = radial - z[i];
            hits++;
        }
        CHECK(hits > 100);
        CHECK(max_radial_gap > 0.05); /* off-axis pixels: planar < radial */
    }

    /* choosing Composite gives its Combined only */
    fx_frame *c = NULL;
    fx_read_options oc = {sizeof oc, "Composite", NULL, NULL};
    CHECK_OK(ctx, fx_frame_read_exr(ctx, fixture("render_multilayer.exr"), &oc, &c));
    CHECK(c && fx_frame_pass_count(c) == 1);
    fx_frame_free(c);

    /* info lists both layers */
    char *info = NULL;
    CHECK_OK(ctx, fx_exr_info_json(ctx, fixture("render_multilayer.exr"), &info));
    CHECK(tu_contains(info, "\"layers\":[\"Composite\",\"ViewLayer\"]") ||
          tu_contains(info, "\"layers\":[\"ViewLayer\",\"Composite\"]"));
    CHECK(tu_contains(info, "\"frame\":1"));
    CHECK(tu_contains(info, "\"names\":[\"Cube\"]"));
    fx_free(info);

    /* a processed file can be read again: write the render route, read it back */
    char out[600];
    snprintf(out, sizeof out, "%s/again.exr", tu_tmpdir("exr_blender"));
    fx_write_options wo = {sizeof wo, 1, 0, fixture("render_multilayer.exr"), NULL};
    CHECK_OK(ctx, fx_frame_write_exr(r, out, &wo));
    fx_frame *again = NULL;
    CHECK_OK(ctx, fx_frame_read_exr(ctx, out, NULL, &again));
    if (again) {
        CHECK(fx_frame_pass_count(again) == fx_frame_pass_count(r));
        CHECK(same_pixels(r, again, "Depth") && same_pixels(r, again, "CryptoObject00"));
        CHECK(tu_contains(fx_frame_meta(again, "cryptomatte/CryptoObject/manifest"), "\"Cube\""));
        CHECK(has_value(again, "CryptoObject00", fx_cryptomatte_id("Cube")));
        fx_frame_free(again);
    }
    fx_frame_free(r);
    fx_frame_free(o);
    fx_context_free(ctx);
    return tu_finish("test_exr_blender");
}
