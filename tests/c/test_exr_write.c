/* fx_frame_write_exr: round trips (bit-exact float, half, windows, camera, time,
 * metadata, Cryptomatte), refusals (output == input, unwritable folder), and ZIP/ZIPS
 * through libdeflate (io/exr_zip.c) decoding to the same values as OpenEXR's zlib. */
#include "testutil.h"
#include "testos.h"
#include "io/exr_write.h"
#include "io/exr_zip.h"

#include <dirent.h>
#include <stddef.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static int count_files(const char *dir)
{
    DIR *d = opendir(dir);
    int n = 0;
    if (!d)
        return -1;
    for (struct dirent *e; (e = readdir(d));)
        if (strcmp(e->d_name, ".") && strcmp(e->d_name, ".."))
            n++;
    closedir(d);
    return n;
}

static int has_temp_file(const char *dir)
{
    DIR *d = opendir(dir);
    int found = 0;
    if (!d)
        return 0;
    for (struct dirent *e; (e = readdir(d));)
        if (strstr(e->d_name, ".tmp-"))
            found = 1;
    closedir(d);
    return found;
}

/* A frame with awkward values and several kinds of passes. */
static fx_frame *rich_frame(fx_context *ctx, int w, int h)
{
    fx_frame *f = tu_pattern_frame(ctx, w, h, 7);
    if (!f)
        return NULL;
    float *c = NULL;
    int nc = 0;
    fx_frame_pass(f, "Combined", &c, &nc);
    /* values half cannot hold: float must round-trip bit-exactly */
    c[0] = 1e-30f, c[1] = 3.4e38f, c[2] = -2.5e-42f /* denormal */, c[3] = 0.1f;
    size_t n = (size_t)w * h;
    float *depth = malloc(n * sizeof *depth), *normal = malloc(n * 3 * sizeof *normal);
    float *idx = malloc(n * sizeof *idx), *crypto = malloc(n * 4 * sizeof *crypto), *custom = malloc(n * 2 * sizeof *custom);
    for (size_t i = 0; i < n; i++) {
        depth[i] = 1.0f + (float)i * 0.37f;
        normal[i * 3] = 0.6f, normal[i * 3 + 1] = -0.8f, normal[i * 3 + 2] = (float)i / n;
        idx[i] = (float)(i % 5);
        uint32_t bits = 0x3f000000u + (uint32_t)i * 2654435761u % 0x00800000u;
        float id;
        memcpy(&id, &bits, 4);
        crypto[i * 4] = id, crypto[i * 4 + 1] = 0.75f, crypto[i * 4 + 2] = -id, crypto[i * 4 + 3] = 0.25f;
        custom[i * 2] = (float)i, custom[i * 2 + 1] = -(float)i;
    }
    fx_frame_add_pass(f, "Depth", 1, depth);
    fx_frame_add_pass(f, "Normal", 3, normal);
    fx_frame_add_pass(f, "IndexOB", 1, idx);
    fx_frame_add_pass(f, "CryptoObject00", 4, crypto);
    fx_frame_add_pass(f, "my custom", 2, custom);
    free(depth), free(normal), free(idx), free(crypto), free(custom);
    return f;
}

static void same_pass(fx_context *ctx, const fx_frame *a, const fx_frame *b, const char *name, int exact)
{
    float *pa = NULL, *pb = NULL;
    int ca = 0, cb = 0;
    CHECK_OK(ctx, fx_frame_pass(a, name, &pa, &ca));
    CHECK_OK(ctx, fx_frame_pass(b, name, &pb, &cb));
    CHECK(ca == cb);
    if (!pa || !pb || ca != cb)
        return;
    size_t n = (size_t)fx_frame_width(a) * fx_frame_height(a) * ca;
    if (exact) {
        int ok = memcmp(pa, pb, n * sizeof(float)) == 0;
        if (!ok)
            fprintf(stderr, "pass %s differs\n", name);
        CHECK(ok);
    } else {
        CHECK(tu_max_abs_diff(pa, pb, n) < 1e-2);
    }
}

static void test_round_trip(fx_context *ctx, const char *dir)
{
    fx_frame *f = rich_frame(ctx, 37, 23);
    CHECK(f != NULL);
    if (!f)
        return;
    int dw[4] = {-5, 7, -5 + 36, 7 + 22}, disp[4] = {0, 0, 31, 39};
    CHECK_OK(ctx, fx_frame_set_windows(f, dw, disp));
    fx_camera cam;
    memset(&cam, 0, sizeof cam);
    cam.size = sizeof cam;
    const float w2c[16] = {0.6859f, 0.7277f, 0, -0.0060f, -0.3240f, 0.3054f, 0.8954f, -0.0089f,
                           0.6516f, -0.6142f, 0.4453f, -11.2360f, 0, 0, 0, 1};
    const float proj[16] = {2.7778f, 0, 0, 0, 0, 4.9383f, 0, 0, 0, 0, -1.0020f, -0.2002f, 0, 0, -1, 0};
    memcpy(cam.world_to_camera, w2c, sizeof w2c);
    memcpy(cam.projection, proj, sizeof proj);
    cam.clip_start = 0.1f, cam.clip_end = 100.0f;
    CHECK_OK(ctx, fx_frame_set_camera(f, &cam));
    fx_frame_set_time(f, 42.5, 24.0);
    CHECK_OK(ctx, fx_frame_set_meta(f, "BlenderMultiChannel", "Blender V3.4.1"));
    CHECK_OK(ctx, fx_frame_set_meta(f, "libfx:lights", "[{\"name\":\"Sun\",\"type\":\"SUN\"}]"));
    CHECK_OK(ctx, fx_frame_set_meta(f, "cryptomatte/CryptoObject/manifest", "{\"Cube\":\"3f800000\"}"));

    char path[600];
    snprintf(path, sizeof path, "%s/round.exr", dir);
    fx_write_options wo = {sizeof wo, 0, 0, NULL, NULL};
    CHECK_OK(ctx, fx_frame_write_exr(f, path, &wo));
    CHECK(!has_temp_file(dir));

    fx_frame *g = NULL;
    CHECK_OK(ctx, fx_frame_read_exr(ctx, path, NULL, &g));
    if (g) {
        CHECK(fx_frame_width(g) == 37 && fx_frame_height(g) == 23);
        int gdw[4], gdisp[4];
        fx_frame_windows(g, gdw, gdisp);
        CHECK(memcmp(gdw, dw, sizeof dw) == 0);
        CHECK(memcmp(gdisp, disp, sizeof disp) == 0);
        same_pass(ctx, f, g, "Combined", 1);
        same_pass(ctx, f, g, "Depth", 1);
        same_pass(ctx, f, g, "Normal", 1);
        same_pass(ctx, f, g, "IndexOB", 1);
        same_pass(ctx, f, g, "CryptoObject00", 1);
        same_pass(ctx, f, g, "my custom", 1);
        CHECK(fx_frame_pass_count(g) == 6);
        fx_camera c2;
        CHECK(fx_frame_camera(g, &c2) == 1);
        CHECK(tu_max_abs_diff(c2.world_to_camera, cam.world_to_camera, 16) < 1e-5);
        CHECK(tu_max_abs_diff(c2.projection, cam.projection, 16) < 1e-5);
        CHECK(fabsf(c2.clip_start - 0.1f) < 1e-6f && fabsf(c2.clip_end - 100.0f) < 1e-4f);
        CHECK(c2.orthographic == 0);
        double fr = 0, fps = 0;
        fx_frame_time(g, &fr, &fps);
        CHECK(fr == 42.5 && fps == 24.0);
        CHECK(tu_contains(fx_frame_meta(g, "BlenderMultiChannel"), "Blender V3.4.1"));
        CHECK(tu_contains(fx_frame_meta(g, "libfx:lights"), "\"Sun\""));
        CHECK(tu_contains(fx_frame_meta(g, "libfx:source"), ".exr"));
        CHECK(tu_contains(fx_frame_meta(g, "cryptomatte/CryptoObject/manifest"), "\"Cube\""));
        CHECK(tu_contains(fx_frame_meta(g, "cryptomatte/CryptoObject/layer"), "CryptoObject"));
        fx_frame_free(g);
    }

    /* half_color: Combined becomes half, data passes stay float (bit-exact) */
    char hpath[600];
    snprintf(hpath, sizeof hpath, "%s/half.exr", dir);
    fx_write_options ho = {sizeof ho, 1, 0, NULL, NULL};
    CHECK_OK(ctx, fx_frame_write_exr(f, hpath, &ho));
    char *info = NULL;
    CHECK_OK(ctx, fx_exr_info_json(ctx, hpath, &info));
    CHECK(tu_contains(info, "{\"name\":\"Combined.R\",\"type\":\"half\"}"));
    CHECK(tu_contains(info, "{\"name\":\"Depth.Z\",\"type\":\"float\"}"));
    CHECK(tu_contains(info, "{\"name\":\"CryptoObject00.R\",\"type\":\"float\"}"));
    CHECK(tu_contains(info, "\"camera\":true"));
    fx_free(info);
    g = NULL;
    CHECK_OK(ctx, fx_frame_read_exr(ctx, hpath, NULL, &g));
    if (g) {
        same_pass(ctx, f, g, "Depth", 1);
        same_pass(ctx, f, g, "CryptoObject00", 1);
        same_pass(ctx, f, g, "IndexOB", 1);
        float *a = NULL, *b = NULL;
        int na = 0, nb = 0;
        CHECK_OK(ctx, fx_frame_pass(f, "Combined", &a, &na));
        CHECK_OK(ctx, fx_frame_pass(g, "Combined", &b, &nb));
        CHECK(a && b);
        /* skip pixel 0 (values half cannot hold); the rest is within half's precision */
        double md = 0;
        for (size_t i = 4; a && b && i < (size_t)37 * 23 * 4; i++) {
            double d = fabs((double)a[i] - b[i]) / (fabs((double)a[i]) + 1e-3);
            if (d > md)
                md = d;
        }
        CHECK(md < 1e-3);
        fx_frame_free(g);
    }

    /* only_combined */
    fx_write_options oc = {sizeof oc, 0, 1, NULL, NULL};
    CHECK_OK(ctx, fx_frame_write_exr(f, hpath, &oc));
    g = NULL;
    CHECK_OK(ctx, fx_frame_read_exr(ctx, hpath, NULL, &g));
    CHECK(g && fx_frame_pass_count(g) == 1);
    fx_frame_free(g);

    /* orthographic camera */
    fx_camera ortho = cam;
    const float op[16] = {0.2f, 0, 0, 0, 0, 0.3556f, 0, 0, 0, 0, -0.02002f, -1.002f, 0, 0, 0, 1};
    memcpy(ortho.projection, op, sizeof op);
    ortho.orthographic = 1;
    CHECK_OK(ctx, fx_frame_set_camera(f, &ortho));
    CHECK_OK(ctx, fx_frame_write_exr(f, path, &wo));
    g = NULL;
    CHECK_OK(ctx, fx_frame_read_exr(ctx, path, NULL, &g));
    if (g) {
        fx_camera c3;
        CHECK(fx_frame_camera(g, &c3) == 1);
        CHECK(c3.orthographic == 1);
        CHECK(tu_max_abs_diff(c3.projection, op, 16) < 1e-5);
        fx_frame_free(g);
    }
    fx_frame_free(f);
}

static void test_refusals(fx_context *ctx, const char *dir)
{
    fx_frame *f = tu_pattern_frame(ctx, 8, 8, 1);
    char in[600], alias[600];
    snprintf(in, sizeof in, "%s/input.exr", dir);
    snprintf(alias, sizeof alias, "%s/./input.exr", dir);
    fx_write_options wo = {sizeof wo, 0, 0, NULL, NULL};
    CHECK_OK(ctx, fx_frame_write_exr(f, in, &wo));
    size_t len0 = 0, len1 = 0;
    char *before = tu_slurp(in, &len0);

    fx_frame *g = tu_pattern_frame(ctx, 8, 8, 2);
    fx_write_options same = {sizeof same, 0, 0, in, NULL};
    CHECK_FAIL(ctx, fx_frame_write_exr(g, alias, &same), FX_ERR_INVALID_ARGUMENT,
               "refusing to overwrite the input file");
    char *after = tu_slurp(in, &len1);
    CHECK(before && after && len0 == len1 && memcmp(before, after, len0) == 0);
    free(before), free(after);

    /* a hard link is the same file too */
    char link_path[600];
    snprintf(link_path, sizeof link_path, "%s/hardlink.exr", dir);
    if (tu_hardlink(in, link_path) == 0) {
        CHECK_FAIL(ctx, fx_frame_write_exr(g, link_path, &same), FX_ERR_INVALID_ARGUMENT, "refusing");
        remove(link_path);
    }

    /* unwritable folder: FX_ERR_IO naming the path, nothing left behind */
    char ro[600], out[700];
    snprintf(ro, sizeof ro, "%s/readonly", dir);
    tu_mkdir(ro, 0500);
    snprintf(out, sizeof out, "%s/out.exr", ro);
    if (access(ro, W_OK) != 0) { /* root ignores permissions */
        CHECK_FAIL(ctx, fx_frame_write_exr(g, out, &wo), FX_ERR_IO, out);
        CHECK(count_files(ro) == 0);
        CHECK_FAIL(ctx, fx_frame_write_png(g, "/proc/nonexistent-dir/x.png", NULL, 0), FX_ERR_IO, "x.png");
    }
    char missing[700];
    snprintf(missing, sizeof missing, "%s/no/such/dir/out.exr", dir);
    CHECK_FAIL(ctx, fx_frame_write_exr(g, missing, &wo), FX_ERR_IO, missing);

    /* a failure after the temporary file exists leaves nothing: only_combined without Combined */
    fx_frame *empty = NULL;
    CHECK_OK(ctx, fx_frame_new(ctx, 4, 4, &empty));
    CHECK_OK(ctx, fx_frame_add_pass(empty, "Depth", 1, NULL));
    char e[600];
    snprintf(e, sizeof e, "%s/empty.exr", dir);
    fx_write_options oc = {sizeof oc, 0, 1, NULL, NULL};
    CHECK_FAIL(ctx, fx_frame_write_exr(empty, e, &oc), FX_ERR_MISSING_PASS, "Combined");
    CHECK(access(e, F_OK) != 0);
    CHECK(!has_temp_file(dir));
    /* compression by name; an unknown name is refused and leaves no file */
    {
        char cpath[600];
        snprintf(cpath, sizeof cpath, "%s/piz.exr", dir);
        fx_write_options po = {sizeof po, 0, 1, NULL, "piz"};
        CHECK_OK(ctx, fx_frame_write_exr(f, cpath, &po));
        fx_frame *pf = NULL;
        CHECK_OK(ctx, fx_frame_read_exr(ctx, cpath, NULL, &pf));
        float *pa = NULL, *pb = NULL;
        fx_frame_pass(f, "Combined", &pa, NULL);
        if (pf)
            fx_frame_pass(pf, "Combined", &pb, NULL);
        CHECK(pa && pb && memcmp(pa, pb, (size_t)fx_frame_width(f) * fx_frame_height(f) * 16) == 0);
        fx_frame_free(pf);
        snprintf(cpath, sizeof cpath, "%s/bad_codec.exr", dir);
        fx_write_options bo = {sizeof bo, 0, 1, NULL, "dwaa"};
        CHECK_FAIL(ctx, fx_frame_write_exr(f, cpath, &bo), FX_ERR_BAD_PARAM, "compression 'dwaa'");
        CHECK(access(cpath, F_OK) != 0);
        fx_write_options lo = {sizeof lo, 0, 1, NULL, "zip:12"};
        CHECK_FAIL(ctx, fx_frame_write_exr(f, cpath, &lo), FX_ERR_BAD_PARAM, "zip:12");
        /* a caller built against 0.1.0 (no compression field) still works */
        fx_write_options old = {offsetof(fx_write_options, compression), 0, 1, NULL, (const char *)1};
        snprintf(cpath, sizeof cpath, "%s/old_size.exr", dir);
        CHECK_OK(ctx, fx_frame_write_exr(f, cpath, &old));
    }
    fx_write_options bad = {3, 0, 0, NULL, NULL};
    CHECK_FAIL(ctx, fx_frame_write_exr(g, e, &bad), FX_ERR_INVALID_ARGUMENT, "size");
    fx_frame_free(empty);
    fx_frame_free(f);
    fx_frame_free(g);
}

/* A hash of (i, seed): incompressible bits for the raw-chunk path. */
static uint32_t zip_hash(uint32_t i, uint32_t seed)
{
    uint32_t h = i * 0x9e3779b1u ^ seed * 0x85ebca77u;
    h ^= h >> 16, h *= 0x7feb352du, h ^= h >> 15, h *= 0x846ca68bu, h ^= h >> 16;
    return h;
}

/* rich_frame plus a noise pass (finite floats of random bits) and a constant pass;
 * `noisy`: Combined is noise too, so every chunk of it is stored raw. */
static fx_frame *zip_frame(fx_context *ctx, int w, int h, int noisy)
{
    fx_frame *f = rich_frame(ctx, w, h);
    if (!f)
        return NULL;
    size_t n = (size_t)w * h;
    float *noise = malloc(n * 3 * sizeof *noise), *flat = malloc(n * sizeof *flat);
    for (size_t i = 0; i < n * 3; i++) {
        uint32_t bits = (zip_hash((uint32_t)i, 11) & 0x807fffffu) | ((60u + zip_hash((uint32_t)i, 12) % 100u) << 23);
        memcpy(&noise[i], &bits, 4);
    }
    for (size_t i = 0; i < n; i++)
        flat[i] = 0.5f;
    fx_frame_add_pass(f, "Noise", 3, noise);
    fx_frame_add_pass(f, "Flat", 1, flat);
    if (noisy) {
        float *c = NULL;
        fx_frame_pass(f, "Combined", &c, NULL);
        for (size_t i = 0; i < n * 4; i++) {
            uint32_t bits = (zip_hash((uint32_t)i, 13) & 0x807fffffu) | ((100u + zip_hash((uint32_t)i, 14) % 40u) << 23);
            memcpy(&c[i], &bits, 4);
        }
    }
    free(noise), free(flat);
    return f;
}

static void test_zip(fx_context *ctx, const char *dir)
{
    /* the predictor against its definition: even bytes, then odd, then differences */
    for (size_t n = 0; n <= 41; n++) {
        uint8_t in[41] = {0}, want[41] = {0}, got[41] = {0}, r[41] = {0};
        for (size_t i = 0; i < n; i++)
            in[i] = (uint8_t)zip_hash((uint32_t)i, (uint32_t)n);
        size_t k = 0;
        for (size_t i = 0; i < n; i += 2)
            r[k++] = in[i];
        for (size_t i = 1; i < n; i += 2)
            r[k++] = in[i];
        for (size_t i = 0; i < n; i++)
            want[i] = i ? (uint8_t)(r[i] - r[i - 1] + 128) : r[0];
        fx_exr_zip_predict(in, n, got);
        CHECK(n == 0 || memcmp(want, got, n) == 0);
    }
    if (!fx_exr_zip_available()) {
        fprintf(stderr, "test_exr_write: built without libdeflate, ZIP through OpenEXR's zlib only\n");
    } else {
        /* a chunk that does not shrink is stored as it is; one that does, smaller */
        fx_exr_zip *z = fx_exr_zip_new(FX_EXR_DEFAULT_ZIP_LEVEL);
        CHECK(z != NULL);
        if (z) {
            enum { N = 4096 };
            uint8_t in[N], *out = malloc(fx_exr_zip_bound(z, N));
            for (size_t i = 0; i < N; i++)
                in[i] = (uint8_t)zip_hash((uint32_t)i, 5);
            size_t got = 0;
            CHECK(out && fx_exr_zip_compress(z, in, N, out, fx_exr_zip_bound(z, N), &got) == 0);
            CHECK(out && got == N && memcmp(in, out, N) == 0);
            memset(in, 7, N);
            CHECK(out && fx_exr_zip_compress(z, in, N, out, fx_exr_zip_bound(z, N), &got) == 0);
            CHECK(got > 2 && got < N / 8 && (out[0] & 0x0f) == 8); /* a zlib stream: deflate */
            CHECK(fx_exr_zip_compress(z, in, N, out, N - 1, &got) != 0); /* too small for raw */
            free(out);
            fx_exr_zip_free(z);
        }
    }
    fx_exr_zip_free(NULL);

    /* Whole files: odd widths, 1x1, rows, columns, several chunks (ZIP: 16 lines, ZIPS:
     * 1), half and float channels, raw chunks among compressed ones. Decoded by OpenEXR
     * (libfx's reader), the libdeflate file equals the zlib one and floats the source. */
    static const int sizes[][3] = {{1, 1, 0}, {1, 9, 0}, {9, 1, 1}, {33, 17, 0}, {257, 40, 0}, {31, 35, 1}};
    static const exr_compression_t codecs[2] = {EXR_COMPRESSION_ZIP, EXR_COMPRESSION_ZIPS};
    fx_context *one = NULL;
    CHECK(fx_context_new(&one, 1) == FX_OK);
    for (size_t s = 0; s < sizeof sizes / sizeof sizes[0]; s++)
        for (int c = 0; c < 2; c++)
            for (int half = 0; half < 2; half++) {
                fx_frame *f = zip_frame(ctx, sizes[s][0], sizes[s][1], sizes[s][2]);
                CHECK(f != NULL);
                if (!f)
                    continue;
                char a[600], b[600];
                snprintf(a, sizeof a, "%s/zip_deflate_%zu_%d_%d.exr", dir, s, c, half);
                snprintf(b, sizeof b, "%s/zip_zlib_%zu_%d_%d.exr", dir, s, c, half);
                fx_exr_write_params p = fx_exr_write_defaults();
                p.compression = codecs[c];
                fx_write_options wo = {sizeof wo, half, 0, NULL, NULL};
                fx_exr_zip_impl mine = fx_exr_zip_available() ? FX_EXR_ZIP_LIBDEFLATE : FX_EXR_ZIP_AUTO;
                CHECK_OK(ctx, fx_exr_write_with(f, a, &wo, &p, mine));
                CHECK_OK(ctx, fx_exr_write_with(f, b, &wo, &p, FX_EXR_ZIP_STOCK));
                fx_frame *ra = NULL, *rb = NULL;
                CHECK_OK(ctx, fx_frame_read_exr(ctx, a, NULL, &ra));
                CHECK_OK(ctx, fx_frame_read_exr(ctx, b, NULL, &rb));
                if (ra && rb) {
                    CHECK(fx_frame_pass_count(ra) == fx_frame_pass_count(f));
                    for (int i = 0; i < fx_frame_pass_count(f); i++) {
                        const char *name = fx_frame_pass_name(f, i);
                        same_pass(ctx, ra, rb, name, 1);
                        if (!half || strcmp(name, "Combined") != 0)
                            same_pass(ctx, f, ra, name, 1);
                    }
                    if (half) { /* half rounding of finite values: relative 2^-11 */
                        float *pf = NULL, *pa = NULL;
                        fx_frame_pass(f, "Combined", &pf, NULL);
                        fx_frame_pass(ra, "Combined", &pa, NULL);
                        size_t n = (size_t)sizes[s][0] * sizes[s][1] * 4;
                        int ok = 1;
                        for (size_t i = 0; i < n && pf && pa; i++)
                            if (fabsf(pf[i]) < 60000.0f && fabsf(pf[i]) > 1e-4f &&
                                !(fabsf(pa[i] - pf[i]) <= fabsf(pf[i]) * (1.0f / 1024.0f)))
                                ok = 0;
                        CHECK(ok);
                    }
                }
                /* the same bytes from one worker as from two */
                if (s == 4 && one) {
                    char o[600];
                    snprintf(o, sizeof o, "%s/zip_deflate_one_%d_%d.exr", dir, c, half);
                    fx_frame *g = zip_frame(one, sizes[s][0], sizes[s][1], sizes[s][2]);
                    CHECK_OK(one, fx_exr_write_with(g, o, &wo, &p, mine));
                    size_t l1 = 0, l2 = 0;
                    char *b1 = tu_slurp(a, &l1), *b2 = tu_slurp(o, &l2);
                    CHECK(b1 && b2 && l1 == l2 && memcmp(b1, b2, l1) == 0);
                    free(b1), free(b2);
                    fx_frame_free(g);
                }
                fx_frame_free(ra);
                fx_frame_free(rb);
                fx_frame_free(f);
            }
    /* built without libdeflate, asking for it is refused */
    if (!fx_exr_zip_available()) {
        fx_frame *f = zip_frame(ctx, 3, 3, 0);
        char a[600];
        snprintf(a, sizeof a, "%s/zip_refused.exr", dir);
        CHECK_FAIL(ctx, fx_exr_write_with(f, a, NULL, NULL, FX_EXR_ZIP_LIBDEFLATE), FX_ERR_INVALID_ARGUMENT,
                   "libdeflate");
        fx_frame_free(f);
    }
    fx_context_free(one);
}

static void test_png(fx_context *ctx, const char *dir)
{
    fx_frame *f = NULL;
    CHECK_OK(ctx, fx_frame_new(ctx, 4, 2, &f));
    const float px[4 * 2 * 4] = {0, 0, 0, 1, 1, 1, 1, 0.5f, 0.5f, 0.5f, 0.5f, 1, 0.0031308f, 2, -1, 1,
                                 0.18f, 0.18f, 0.18f, 1, 0.25f, 0.25f, 0.25f, 1, NAN, 0, 0, 1, 0, 0, 0, 0};
    CHECK_OK(ctx, fx_frame_add_pass(f, "Combined", 4, px));
    const float d[8] = {0, 1, 0.5f, 0.25f, 0, 0, 0, 1};
    CHECK_OK(ctx, fx_frame_add_pass(f, "Depth", 1, d));
    char path[600];
    snprintf(path, sizeof path, "%s/p.png", dir);
    CHECK_OK(ctx, fx_frame_write_png(f, path, NULL, 0.0f));
    struct stat st;
    CHECK(stat(path, &st) == 0 && st.st_size > 50);
    FILE *fp = fopen(path, "rb");
    unsigned char sig[8] = {0};
    if (fp) {
        CHECK(fread(sig, 1, 8, fp) == 8);
        fclose(fp);
    }
    CHECK(sig[1] == 'P' && sig[2] == 'N' && sig[3] == 'G');
    CHECK_OK(ctx, fx_frame_write_png(f, path, "Depth", -1.0f));
    CHECK_FAIL(ctx, fx_frame_write_png(f, path, "Nope", 0.0f), FX_ERR_MISSING_PASS, "Nope");
    CHECK_FAIL(ctx, fx_frame_write_png(f, path, NULL, NAN), FX_ERR_INVALID_ARGUMENT, "exposure");
    CHECK(!has_temp_file(dir));
    fx_frame_free(f);
}

int main(void)
{
    fx_context *ctx = NULL;
    if (fx_context_new(&ctx, 2) != FX_OK)
        return 1;
    const char *dir = tu_tmpdir("exr_write");
    char d[512];
    snprintf(d, sizeof d, "%s", dir);
    test_round_trip(ctx, d);
    test_zip(ctx, d);
    test_refusals(ctx, d);
    test_png(ctx, d);
    fx_context_free(ctx);
    return tu_finish("test_exr_write");
}
