/* math/: vectors, matrices, the camera model, hashing, and libc-independent inverse
 * trigonometry and logarithm. */
#include "testutil.h"

#include "math/camera.h"
#include "math/hash.h"
#include "math/log.h"
#include "math/trig.h"
#include "math/vec.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

static int near(float a, float b, float tol) { return fabsf(a - b) <= tol; }

static void test_vectors(void)
{
    fx_vec3 n = fx_v3_normalize_or(fx_v3(0, 0, 0), fx_v3(0, 0, 1));
    CHECK(n.z == 1.0f);
    n = fx_v3_normalize_or(fx_v3(NAN, 0, 0), fx_v3(0, 1, 0));
    CHECK(n.y == 1.0f);
    fx_vec3 r = fx_v3_reflect(fx_v3(1, -1, 0), fx_v3(0, 1, 0));
    CHECK(r.x == 1.0f && r.y == 1.0f);
    CHECK(fx_smoothstep(1, 1, 2) == 1.0f && fx_smoothstep(1, 1, 0) == 0.0f);
    float m[16] = {2, 0, 0, 1, 0, 4, 0, 2, 0, 0, 8, 3, 0, 0, 0, 1}, inv[16], id[16];
    CHECK(fx_m4_inverse(m, inv));
    fx_m4_mul(m, inv, id);
    for (int i = 0; i < 16; i++)
        CHECK(near(id[i], i % 5 == 0 ? 1.0f : 0.0f, 1e-6f));
    float sing[16] = {1, 2, 3, 4, 2, 4, 6, 8, 0, 0, 1, 0, 0, 0, 0, 1};
    CHECK(!fx_m4_inverse(sing, inv));
}

static void test_camera(void)
{
    /* A Blender-like camera at (0,0,5) looking down -Z, 90 degree horizontal FOV, 16:9,
     * clip 0.1..100: project a world point and reconstruct it from pixel + depth. */
    fx_context *ctx = NULL;
    fx_context_new(&ctx, 1);
    fx_frame *f = NULL;
    fx_frame_new(ctx, 160, 90, &f);
    fx_camera cam;
    memset(&cam, 0, sizeof cam);
    cam.size = sizeof cam;
    float w2c[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, -5, 0, 0, 0, 1};
    float n = 0.1f, fa = 100.0f, sx = 1.0f, sy = 16.0f / 9.0f;
    float proj[16] = {sx, 0, 0, 0, 0, sy, 0, 0, 0, 0, -(fa + n) / (fa - n), -2 * fa * n / (fa - n), 0, 0, -1, 0};
    memcpy(cam.world_to_camera, w2c, sizeof w2c);
    memcpy(cam.projection, proj, sizeof proj);
    cam.clip_start = n;
    cam.clip_end = fa;
    fx_frame_set_camera(f, &cam);
    fx_view v;
    CHECK(fx_view_init(&v, f));
    fx_vec3 world = fx_v3(1.5f, -0.7f, -2.0f); /* 7 units in front of the camera */
    fx_vec3 view = fx_world_to_view(&v, world);
    CHECK(near(view.z, -7.0f, 1e-5f));
    fx_vec2 px;
    CHECK(fx_view_project(&v, view, &px) > 0);
    /* x: ndc = 1.5/7 -> pixel (ndc+1)/2*160 */
    CHECK(near(px.x, (1.5f / 7 + 1) * 0.5f * 160, 1e-3f));
    CHECK(near(px.y, (1 - (-0.7f * sy / 7)) * 0.5f * 90, 1e-3f));
    fx_vec3 back = fx_view_to_world(&v, fx_view_position(&v, fx_view_pixel_to_ndc(&v, px.x, px.y), 7.0f));
    CHECK(near(back.x, world.x, 1e-4f) && near(back.y, world.y, 1e-4f) && near(back.z, world.z, 1e-4f));
    /* behind the camera: w <= 0 */
    CHECK(fx_view_project(&v, fx_v3(0, 0, 1), &px) <= 0);
    fx_frame_free(f);
    fx_context_free(ctx);
}

static void test_hash(void)
{
    /* deterministic, in [0,1), roughly uniform */
    CHECK(fx_rand4(1, 2, 3, 4) == fx_rand4(1, 2, 3, 4));
    CHECK(fx_rand4(1, 2, 3, 4) != fx_rand4(1, 2, 3, 5));
    double sum = 0;
    int lo = 0;
    for (int i = 0; i < 100000; i++) {
        float u = fx_rand4(i, -i, 7, 0);
        CHECK(u >= 0.0f && u < 1.0f);
        sum += u;
        lo += u < 0.1f;
    }
    CHECK(fabs(sum / 100000 - 0.5) < 0.01);
    CHECK(lo > 9000 && lo < 11000);
}

/* fx_atan2f / fx_acosf against the double-precision libm over a grid of the whole plane
 * (every quadrant, the axes, signed zeros, infinities), and their fixed points; their bits
 * are the same on every libc by construction (no libm call), which tests/matrix checks
 * across Debian 12/13/unstable through the probe lookups. */
static void test_trig(void)
{
    double worst = 0.0;
    for (int i = -200; i <= 200; i++)
        for (int j = -200; j <= 200; j++) {
            float y = (float)i * 0.37f * (float)(abs(i) > 150 ? 1e3 : 1), x = (float)j * 0.41f * (float)(abs(j) > 150 ? 1e-3 : 1);
            double e = fabs((double)fx_atan2f(y, x) - atan2((double)y, (double)x));
            worst = e > worst ? e : worst;
        }
    for (int i = -1000; i <= 1000; i++) {
        float c = (float)i / 1000.0f;
        double e = fabs((double)fx_acosf(c) - acos((double)c));
        worst = e > worst ? e : worst;
    }
    CHECK(worst < 4e-7);
    CHECK(fx_atan2f(0.0f, 0.0f) == 0.0f && fx_atan2f(0.0f, -1.0f) == FX_TRIG_PI && fx_atan2f(-0.0f, -1.0f) == -FX_TRIG_PI);
    CHECK(near(fx_atan2f(1.0f, 0.0f), FX_TRIG_PI_2, 1e-7f) && near(fx_atan2f(INFINITY, INFINITY), FX_TRIG_PI_4, 1e-7f));
    CHECK(fx_atan2f(1.0f, INFINITY) == 0.0f && near(fx_atan2f(-INFINITY, 1.0f), -FX_TRIG_PI_2, 1e-7f));
    CHECK(isnan(fx_atan2f(NAN, 1.0f)) && isnan(fx_acosf(NAN)));
    CHECK(fx_acosf(1.0f) == 0.0f && near(fx_acosf(-1.0f), FX_TRIG_PI, 1e-7f) && fx_acosf(2.0f) == 0.0f);
}

/* fx_logf_pos against libm's double log rounded to float, over every exponent of the float
 * range and a dense walk of mantissas: never more than one float ulp off, and equal to the
 * rounded double almost everywhere (it is the same value up to 1e-12 relative). */
static void test_log(void)
{
    long n = 0, off = 0;
    for (float x = 1.2e-38f; x < 3.0e38f; x *= 1.0001831f) {
        float got = fx_logf_pos(x), want = (float)log((double)x);
        n++;
        if (got != want) {
            off++;
            CHECK(fabsf(got - want) <= fabsf(nextafterf(want, 0.0f) - want) * 1.0001f + 0.0f);
        }
    }
    CHECK(n > 900000);
    CHECK(off * 10000 < n);   /* ties aside, the rounded value */
    CHECK(fx_logf_pos(1.0f) == 0.0f && fx_logf_pos(2.0f) == (float)log(2.0));
    CHECK(isfinite(fx_logf_pos(1.0e-6f)) && fx_logf_pos(FLT_MAX) > 88.0f);
}

int main(void)
{
    test_vectors();
    test_trig();
    test_log();
    test_camera();
    test_hash();
    return tu_finish("test_math");
}
