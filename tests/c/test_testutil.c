/* The test helpers' own tests: tu_max_abs_diff must never hide a NaN (a NaN early in the
 * buffers followed by a finite difference once came back as that finite difference, so a
 * "< tol" check passed over a NaN output). */
#include "testutil.h"

#include <math.h>
#include <string.h>

/* A NaN or an infinity anywhere must fail "< tol" for every tolerance, even a huge one. */
static int fails_every_tolerance(double d)
{
    return !(d < 1e300) && !(d <= 1e300);
}

static void max_abs_diff_finite(void)
{
    const float a[5] = {0.0f, 1.0f, -2.0f, 3.5f, 1e30f};
    float b[5];
    memcpy(b, a, sizeof a);
    CHECK(tu_max_abs_diff(a, b, 5) == 0.0);
    CHECK(tu_max_abs_diff(a, b, 0) == 0.0);
    b[2] = -2.25f;
    CHECK(tu_max_abs_diff(a, b, 5) == 0.25);
    b[4] = 1e30f * 1.5f; /* the difference in double, not rounded to float */
    CHECK(tu_max_abs_diff(a, b, 5) == fabs((double)a[4] - (double)b[4]));
    const float z[2] = {0.0f, -0.0f}, nz[2] = {-0.0f, 0.0f};
    CHECK(tu_max_abs_diff(z, nz, 2) == 0.0);
}

static void max_abs_diff_nan(void)
{
    /* the NaN at each position (first, middle, last), in a, in b, in both; a finite
     * difference of 0.5 elsewhere that must not overwrite it */
    enum { N = 6 };
    for (int where = 0; where < N; where += 2) {
        for (int in = 0; in < 3; in++) {
            float a[N], b[N];
            for (int i = 0; i < N; i++)
                a[i] = b[i] = (float)i;
            b[where == N - 2 ? 1 : N - 1] += 0.5f;
            if (in != 1)
                a[where] = NAN;
            if (in != 0)
                b[where] = NAN;
            double d = tu_max_abs_diff(a, b, N);
            CHECK(fails_every_tolerance(d));
            if (!fails_every_tolerance(d))
                fprintf(stderr, "  NaN at %d in %s: max diff %g\n", where, in == 0 ? "a" : in == 1 ? "b" : "both", d);
        }
    }
}

static void max_abs_diff_infinite(void)
{
    float a[3] = {1.0f, INFINITY, 2.0f}, b[3] = {1.0f, 5.0f, 2.5f};
    CHECK(fails_every_tolerance(tu_max_abs_diff(a, b, 3)));
    CHECK(fails_every_tolerance(tu_max_abs_diff(b, a, 3)));
    b[1] = -INFINITY; /* opposite infinities */
    CHECK(fails_every_tolerance(tu_max_abs_diff(a, b, 3)));
    b[1] = INFINITY; /* the same infinity is no difference */
    CHECK(tu_max_abs_diff(a, b, 3) == 0.5);
}

static void all_finite(void)
{
    const float ok[3] = {0.0f, -3e38f, 1e-45f};
    const float bad[3][3] = {{0.0f, NAN, 1.0f}, {INFINITY, 0.0f, 0.0f}, {0.0f, 0.0f, -INFINITY}};
    CHECK(tu_all_finite(ok, 3));
    for (int k = 0; k < 3; k++)
        CHECK(!tu_all_finite(bad[k], 3));
}

int main(void)
{
    max_abs_diff_finite();
    max_abs_diff_nan();
    max_abs_diff_infinite();
    all_finite();
    return tu_finish("test_testutil");
}
