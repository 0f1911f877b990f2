/* bench_atrium: vsm_shadows at 1920x1080 per light-map size (512..4096) and method, and the
 * moment filter alone, SAT box vs separable (recursive Gaussian) blur, per filter width.
 * Medians of 5 runs. Built and run by tests/bench/bench_atrium.sh (docs/effects/vsm_shadows.md). */
#include "libfx/fx.h"
#include "math/shadow_map.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static double now_ms(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec * 1e3 + t.tv_nsec / 1e6;
}

static int cmp(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static fx_camera top(float half, float z)
{
    fx_camera c;
    memset(&c, 0, sizeof c);
    c.size = sizeof c;
    float w2c[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, -z, 0, 0, 0, 1};
    float n = 0.1f, f = 2 * z;
    float p[16] = {1 / half, 0, 0, 0, 0, 1 / half, 0, 0, 0, 0, -2 / (f - n), -(f + n) / (f - n), 0, 0, 0, 1};
    memcpy(c.world_to_camera, w2c, sizeof w2c);
    memcpy(c.projection, p, sizeof p);
    c.clip_start = n;
    c.clip_end = f;
    c.orthographic = 1;
    return c;
}

/* light view of S x S: columns (discs) and a 'crown' of random blobs over a floor */
static float *light_depth(int S)
{
    float *d = malloc((size_t)S * S * sizeof(float));
    for (int y = 0; y < S; y++)
        for (int x = 0; x < S; x++) {
            float u = (x + 0.5f) / S * 20 - 10, v = (y + 0.5f) / S * 20 - 10, h = 0;
            float cu = u - 4 * floorf(u / 4 + 0.5f), cv = v - 4 * floorf(v / 4 + 0.5f);
            if (cu * cu + cv * cv < 0.09f)
                h = 3.5f;
            uint32_t k = (uint32_t)(floorf(u * 8) * 73856093.0f) ^ (uint32_t)(floorf(v * 8) * 19349663.0f);
            if (u * u + v * v < 6 && (k * 2654435761u >> 28) < 7)
                h = 5 + (k & 7) * 0.1f;
            d[(size_t)y * S + x] = 20 - h;
        }
    return d;
}

int main(int argc, char **argv)
{
    int threads = argc > 1 ? atoi(argv[1]) : 0;
    const char *dir = argc > 2 ? argv[2] : "/tmp";
    fx_context *ctx = NULL;
    fx_context_new(&ctx, threads);
    const int W = 1920, H = 1080;
    fx_frame *f = NULL;
    fx_frame_new(ctx, W, H, &f);
    float *rgba = malloc((size_t)W * H * 4 * sizeof(float)), *dep = malloc((size_t)W * H * sizeof(float));
    for (size_t i = 0; i < (size_t)W * H; i++) {
        rgba[4 * i] = rgba[4 * i + 1] = rgba[4 * i + 2] = 0.5f;
        rgba[4 * i + 3] = 1;
        dep[i] = 20.0f;
    }
    fx_frame_add_pass(f, "Combined", 4, rgba);
    fx_frame_add_pass(f, "Depth", 1, dep);
    fx_camera cam = top(10, 20);
    cam.projection[0] = 1.0f / (10.0f * W / H);
    fx_frame_set_camera(f, &cam);
    printf("# vsm_shadows at %dx%d, %d threads, median of 5 (ms)\n", W, H, fx_context_threads(ctx));
    printf("light_map,method,filter,filter_size,ms\n");
    int sizes[] = {512, 1024, 2048, 4096};
    for (int si = 0; si < 4; si++) {
        int S = sizes[si];
        char path[512];
        snprintf(path, sizeof path, "%s/bench_light_%d.exr", dir, S);
        fx_frame *lv = NULL;
        fx_frame_new(ctx, S, S, &lv);
        float *ld = light_depth(S);
        fx_frame_add_pass(lv, "Depth", 1, ld);
        fx_frame_write_exr(lv, path, NULL);
        fx_frame_free(lv);
        fx_camera lc = top(10, 20);
        fx_frame_set_aux_view(f, "light:Sun", path, &lc);
        struct { const char *method, *filter; float size; } cfg[] = {
            {"hard", "box_sat", 1}, {"vsm", "box_sat", 5}, {"vsm", "gaussian", 5}, {"vsm", "box_sat", 33},
            {"vsm", "gaussian", 33}, {"pcf", "box_sat", 5}};
        for (size_t c = 0; c < sizeof cfg / sizeof cfg[0]; c++) {
            fx_stack *s = NULL;
            int idx;
            fx_stack_new(ctx, &s);
            fx_stack_append(s, "vsm_shadows", &idx);
            fx_stack_set_enum(s, 0, "apply", "combined");
            fx_stack_set_enum(s, 0, "method", cfg[c].method);
            fx_stack_set_enum(s, 0, "filter", cfg[c].filter);
            fx_stack_set_float(s, 0, "filter_size", cfg[c].size);
            double t[5];
            for (int r = 0; r < 5; r++) {
                fx_frame *out = NULL;
                double t0 = now_ms();
                if (fx_stack_run(s, f, &out) != FX_OK) {
                    fprintf(stderr, "%s\n", fx_context_error(ctx));
                    return 1;
                }
                t[r] = now_ms() - t0;
                fx_frame_free(out);
            }
            qsort(t, 5, sizeof t[0], cmp);
            printf("%d,%s,%s,%g,%.1f\n", S, cfg[c].method, cfg[c].filter, cfg[c].size, t[2]);
            fflush(stdout);
            fx_stack_free(s);
        }
        /* the filter alone */
        for (int wi = 0; wi < 3; wi++) {
            float width = wi == 0 ? 5 : wi == 1 ? 33 : 129;
            for (int k = 0; k < 2; k++) {
                double t[3];
                for (int r = 0; r < 3; r++) {
                    fx_shadow_map sm;
                    fx_shadow_map_build(ctx, ld, S, S, 0.1f, 40.0f, 1, &sm, "bench");
                    double t0 = now_ms();
                    fx_shadow_map_filter(ctx, &sm, k ? FX_SHADOW_FILTER_GAUSSIAN : FX_SHADOW_FILTER_BOX_SAT, width,
                                         "bench");
                    t[r] = now_ms() - t0;
                    fx_shadow_map_free(&sm);
                }
                qsort(t, 3, sizeof t[0], cmp);
                printf("%d,filter_only,%s,%g,%.1f\n", S, k ? "gaussian" : "box_sat", width, t[1]);
                fflush(stdout);
            }
        }
        free(ld);
    }
    fx_frame_free(f);
    free(rgba);
    free(dep);
    fx_context_free(ctx);
    return 0;
}
