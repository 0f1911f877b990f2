/* bench_atrium: vsm_shadows at 1920x1080 per light-map size (512..4096) and method, and the
 * moment filter alone, SAT box vs separable (recursive Gaussian) blur, per filter width.
 * Each vsm row: a context without the aux-view cache (the light view read and its map built
 * every run) against one context reused as frames 2..N are (cached), timed alternately;
 * medians and the median same-run ratio. filter_only rows: SAT box vs Gaussian (columns
 * uncached_ms = box, cached_ms = Gaussian, ratio = Gaussian / box).
 * Built and run by tests/bench/bench_atrium.sh (docs/effects/vsm_shadows.md). */
#include "libfx/fx.h"
#include "math/shadow_map.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bench_util.h"

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

typedef struct scene_ctx {
    fx_context *ctx;
    fx_frame *f;
} scene_ctx;

static scene_ctx make_scene(int threads, int cache)
{
    scene_ctx sc = {NULL, NULL};
    fx_context_new(&sc.ctx, threads);
    if (!cache)
        fx_context_set_aux_cache(sc.ctx, 0);
    const int W = 1920, H = 1080;
    fx_frame_new(sc.ctx, W, H, &sc.f);
    float *rgba = malloc((size_t)W * H * 4 * sizeof(float)), *dep = malloc((size_t)W * H * sizeof(float));
    for (size_t i = 0; i < (size_t)W * H; i++) {
        rgba[4 * i] = rgba[4 * i + 1] = rgba[4 * i + 2] = 0.5f;
        rgba[4 * i + 3] = 1;
        dep[i] = 20.0f;
    }
    fx_frame_add_pass(sc.f, "Combined", 4, rgba);
    fx_frame_add_pass(sc.f, "Depth", 1, dep);
    free(rgba);
    free(dep);
    fx_camera cam = top(10, 20);
    cam.projection[0] = 1.0f / (10.0f * W / H);
    fx_frame_set_camera(sc.f, &cam);
    return sc;
}

static fx_stack *make_stack(fx_context *ctx, const char *method, const char *filter, float size)
{
    fx_stack *s = NULL;
    int idx;
    fx_stack_new(ctx, &s);
    fx_stack_append(s, "vsm_shadows", &idx);
    fx_stack_set_enum(s, 0, "apply", "combined");
    fx_stack_set_enum(s, 0, "method", method);
    fx_stack_set_enum(s, 0, "filter", filter);
    fx_stack_set_float(s, 0, "filter_size", size);
    return s;
}

static double run_once(fx_stack *s, const fx_frame *f, fx_context *ctx)
{
    fx_frame *out = NULL;
    double t0 = now_ms();
    if (fx_stack_run(s, f, &out) != FX_OK) {
        fprintf(stderr, "%s\n", fx_context_error(ctx));
        exit(1);
    }
    double t = now_ms() - t0;
    fx_frame_free(out);
    return t;
}

/* usage: bench_atrium THREADS DIR [RUNS] [MAX_LIGHT_MAP] */
int main(int argc, char **argv)
{
    int threads = argc > 1 ? atoi(argv[1]) : 0;
    const char *dir = argc > 2 ? argv[2] : "/tmp";
    int runs = argc > 3 ? atoi(argv[3]) : 5;
    int max_size = argc > 4 ? atoi(argv[4]) : 4096;
    if (runs < 1 || runs > 99)
        runs = 5;
    /* plain: the light view is read and its map built every run (as before the cache);
     * cached: one context reused, as frames 2..N of a batch (primed by one run) */
    scene_ctx plain = make_scene(threads, 0), cached = make_scene(threads, 1);
    printf("# vsm_shadows at 1920x1080, %d threads, median of %d runs (ms); uncached and cached timed "
           "alternately (same-run ratio)\n", fx_context_threads(plain.ctx), runs);
    printf("light_map,method,filter,filter_size,uncached_ms,cached_ms,cached_over_uncached\n");
    int sizes[] = {512, 1024, 2048, 4096};
    for (int si = 0; si < 4 && sizes[si] <= max_size; si++) {
        int S = sizes[si];
        char path[512];
        snprintf(path, sizeof path, "%s/bench_light_%d.exr", dir, S);
        fx_frame *lv = NULL;
        fx_frame_new(plain.ctx, S, S, &lv);
        float *ld = light_depth(S);
        fx_frame_add_pass(lv, "Depth", 1, ld);
        fx_frame_write_exr(lv, path, NULL);
        fx_frame_free(lv);
        fx_camera lc = top(10, 20);
        fx_frame_set_aux_view(plain.f, "light:Sun", path, &lc);
        fx_frame_set_aux_view(cached.f, "light:Sun", path, &lc);
        struct { const char *method, *filter; float size; } cfg[] = {
            {"hard", "box_sat", 1}, {"vsm", "box_sat", 5}, {"vsm", "gaussian", 5}, {"vsm", "box_sat", 33},
            {"vsm", "gaussian", 33}, {"pcf", "box_sat", 5}, {"pcf", "box_sat", 15}};
        for (size_t c = 0; c < sizeof cfg / sizeof cfg[0]; c++) {
            fx_stack *sp = make_stack(plain.ctx, cfg[c].method, cfg[c].filter, cfg[c].size);
            fx_stack *sc = make_stack(cached.ctx, cfg[c].method, cfg[c].filter, cfg[c].size);
            run_once(sc, cached.f, cached.ctx); /* frame 1: builds the map */
            double tp[99], tc[99], ratio[99];
            for (int r = 0; r < runs; r++) {
                tp[r] = run_once(sp, plain.f, plain.ctx);
                tc[r] = run_once(sc, cached.f, cached.ctx);
                ratio[r] = tc[r] / tp[r];
            }
            qsort(tp, runs, sizeof tp[0], cmp_d);
            qsort(tc, runs, sizeof tc[0], cmp_d);
            qsort(ratio, runs, sizeof ratio[0], cmp_d);
            printf("%d,%s,%s,%g,%.1f,%.1f,%.3f\n", S, cfg[c].method, cfg[c].filter, cfg[c].size, tp[runs / 2],
                   tc[runs / 2], ratio[runs / 2]);
            fflush(stdout);
            fx_stack_free(sp);
            fx_stack_free(sc);
        }
        /* the filter alone, SAT box vs separable recursive Gaussian, alternately */
        for (int wi = 0; wi < 3; wi++) {
            float width = wi == 0 ? 5 : wi == 1 ? 33 : 129;
            double t[2][99], ratio[99];
            for (int r = 0; r < runs; r++) {
                for (int k = 0; k < 2; k++) {
                    fx_shadow_map sm;
                    fx_shadow_map_build(plain.ctx, ld, S, S, 0.1f, 40.0f, 1, &sm, "bench");
                    double t0 = now_ms();
                    fx_shadow_map_filter(plain.ctx, &sm, k ? FX_SHADOW_FILTER_GAUSSIAN : FX_SHADOW_FILTER_BOX_SAT,
                                         width, "bench");
                    t[k][r] = now_ms() - t0;
                    fx_shadow_map_free(&sm);
                }
                ratio[r] = t[1][r] / t[0][r];
            }
            qsort(t[0], runs, sizeof t[0][0], cmp_d);
            qsort(t[1], runs, sizeof t[1][0], cmp_d);
            qsort(ratio, runs, sizeof ratio[0], cmp_d);
            printf("%d,filter_only,box_sat_vs_gaussian,%g,%.1f,%.1f,%.3f\n", S, width, t[0][runs / 2],
                   t[1][runs / 2], ratio[runs / 2]);
            fflush(stdout);
        }
        free(ld);
    }
    fx_frame_free(plain.f);
    fx_frame_free(cached.f);
    fx_context_free(plain.ctx);
    fx_context_free(cached.ctx);
    return 0;
}
