/* Fast sRGB encoding table (math/srgb_lut.h). */
#include "math/srgb_lut.h"

#include <math.h>
#include <pthread.h>

static float table[FX_SRGB_LUT_SIZE];
static pthread_once_t once = PTHREAD_ONCE_INIT;

static void build(void)
{
    for (int i = 0; i < FX_SRGB_LUT_SIZE; i++) {
        int e = FX_SRGB_LUT_MIN_EXP + (i >> FX_SRGB_LUT_BITS);
        double m = 1.0 + (double)(i & ((1 << FX_SRGB_LUT_BITS) - 1)) / (1 << FX_SRGB_LUT_BITS);
        double a = ldexp(m, e);
        table[i] = (float)(a <= 0.0031308 ? 12.92 * a : 1.055 * pow(a, 1.0 / 2.4) - 0.055);
    }
}

const float *fx_srgb_lut(void)
{
    pthread_once(&once, build);
    return table;
}
