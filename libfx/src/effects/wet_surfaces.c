/* wet_surfaces: the wet look where rain reaches (the seed's wet shading): surfaces exposed
 * to the sky per the rain map that face up (or walls, less) get darker albedo and a
 * Fresnel reflection of the sky, plus more of their own glossy light when the frame has
 * GlossDir/GlossCol. docs/effects/wet_surfaces.md.
 *
 * Exposure has soft edges at cover boundaries without a ring of lookups: the rain map is
 * read as a variance shadow map of rain falling straight down, its moments box-filtered
 * once through a summed-area table over edge_softness metres, and each pixel does one
 * Chebyshev lookup (math/rain_map.h). Wetness w = wetness * exposure * facing, where
 * facing is 1 for up-facing normals (N.z >= up_threshold), wall_wetness for walls,
 * smoothly between, 0 facing down. Output: src (1 - darken w) + w specular F(N.V) sky_color
 * + w gloss_boost GlossDir GlossCol, F Schlick's with F0 = 0.02 (water), N.V clamped.
 *
 * Cost: with downsample N > 1 the look (a gain 1 - darken w and an offset per
 * channel) is computed on a lattice of every N-th pixel (at real pixels) and interpolated
 * inside lattice cells whose four corners have a surface with normals within about 25
 * degrees, at pixels whose depth is within 2 % of the corners' interpolated depth and whose normal
 * is within about 25 degrees of theirs (four such pixels at a time). Any other pixel
 * (creases, silhouettes, thin objects) takes the corners on its own surface (depth within
 * 1.5 % x N of its own, normal within about 25 degrees) by their bilinear weights, and is
 * computed exactly when none is; background pixels are the source.
 * downsample 1 (final, reference) is the per-pixel loop, bits unchanged. */
#include "scene/aux_view.h"
#include "core/effect.h"
#include "core/parallel.h"
#include "effects/rain_common.h"
#include "scene/rain_map.h"
#include "math/surface.h"
#include "core/simd4.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

typedef struct wet_params {
    float wetness;
    float darken;
    float specular;
    float sky[3];
    float up_threshold;
    float wall_wetness;
    float softness;
    float gloss_boost;
    int downsample;
} wet_params;

static const float default_sky[3] = {0.55f, 0.62f, 0.72f};

static const fx_param_def wet_param_defs[] = {
    FX_P_FLOAT(wet_params, wetness, "wetness", 1.0, 0.0, 1.0, 0.0, 1.0, "factor",
               "Overall wetness; a pixel's wetness is this x its exposure in the rain map x "
               "its facing (up 1, walls wall_wetness, down 0); 0: identity"),
    FX_P_FLOAT(wet_params, darken, "darken", 0.35, 0.0, 1.0, 0.0, 0.8, "factor",
               "How much water darkens the surface: wet pixels are scaled by 1 - darken x "
               "wetness (0: no darkening)"),
    FX_P_FLOAT(wet_params, specular, "specular", 0.8, 0.0, 10.0, 0.0, 2.0, "",
               "Strength of the wet film's reflection of sky_color, times wetness and Schlick's "
               "Fresnel (F0 0.02, water): strongest at grazing angles"),
    FX_P_FLOATS(wet_params, sky, "sky_color", 3, default_sky, 0.0, 1e4, "color", "Radiance the wet film reflects"),
    FX_P_FLOAT(wet_params, up_threshold, "up_threshold", 0.7, 0.0, 1.0, 0.3, 0.95, "",
               "Normals with a world Z at least this face up (fully wet)"),
    FX_P_FLOAT(wet_params, wall_wetness, "wall_wetness", 0.4, 0.0, 1.0, 0.0, 1.0, "factor",
               "Wetness of exposed walls (normal Z about 0)"),
    FX_P_FLOAT(wet_params, softness, "edge_softness", 0.4, 0.0, 100.0, 0.0, 2.0, "",
               "Width of the wet/dry transition at cover boundaries, metres"),
    FX_P_FLOAT(wet_params, gloss_boost, "gloss_boost", 1.0, 0.0, 10.0, 0.0, 3.0, "",
               "Extra glossy direct light (GlossDir x GlossCol, when the frame has them)"),
    FX_P_INT(wet_params, downsample, "downsample", 1, 1, 8, 1, 4, "",
             "Quality: the wet look (a gain and an offset per channel) is computed every N-th pixel (of the "
             "full-resolution frame: N / k on a 1/k proxy) and "
             "interpolated where the lattice cell lies on one smooth surface (its corners' normals "
             "agree, the pixel's depth matches); at edges, creases and silhouettes a pixel takes the "
             "corners on its own surface (depth and normal alike), and is computed exactly when none "
             "is; 1: every pixel"),
};

static fx_pass_set wet_passes(const void *params)
{
    (void)params;
    return FX_PASS_BIT(FX_PASS_DEPTH) | FX_PASS_BIT(FX_PASS_NORMAL);
}

typedef struct wet_job {
    const fx_effect_run *run;
    const wet_params *p;
    fx_surface_src surf;
    fx_rain_map rm;
    const float *gdir, *gcol;
    float *dbg;
    /* downsample > 1: lattice node (i, k) at pixel (node_x[i], node_y[k]) */
    int f, nx, ny;
    int *node_x, *node_y;
    int *col_i0;          /* per ROI column: its lattice column (left corner) ... */
    float *col_t;         /* ... and the weight of the right one */
    float *nodes;         /* nx * ny * 8: gain, offset[3], depth (NaN: no surface), normal[3] */
    unsigned char *smooth;/* per lattice cell: its four corners on one smooth surface */
    struct wet_span *spans; /* per worker: nx spans of the row being written */
} wet_job;

/* A lattice node: G = (gain, gain, gain, 1), O = (offset[3], 0), then wetness, depth (NaN:
 * no surface, or a non-finite look), unit normal, padding */
#define WET_NODE 16
enum { N_G = 0, N_O = 4, N_WET = 8, N_DEPTH = 9, N_NX = 10 };

/* The wet look of pixel i = (x, y) as out = src gain + offset: 0 without a surface (the
 * source then), wet returned for the debug pass. wet_rows (every pixel) and the lattice nodes both use it. */
static int wet_pixel(const wet_job *j, int x, int y, size_t i, float *gain, float off[3], float *wet_out)
{
    const wet_params *p = j->p;
    fx_vec3 w, n;
    float d;
    float wet = 0.0f;
    *wet_out = 0.0f;
    if (!(fx_surface_world(&j->surf, x, y, &w, &d) && fx_surface_normal(&j->surf, x, y, &n)))
        return 0;
    float facing = n.z >= 0.0f ? fx_lerpf(p->wall_wetness, 1.0f, fx_smoothstep(0.0f, p->up_threshold, n.z))
                               : p->wall_wetness * (1.0f - fx_smoothstep(0.0f, 0.3f, -n.z));
    if (facing > 0.0f) {
        fx_vec3 q = fx_v3_add(w, fx_v3_scale(n, 0.05f));
        wet = p->wetness * facing * fx_rain_map_soft(&j->rm, q);
        if (!(wet > 0.0f))
            wet = 0.0f;
    }
    *gain = 1.0f;
    off[0] = off[1] = off[2] = 0.0f;
    if (wet > 0.0f) {
        fx_vec3 eye = fx_v3(j->surf.view.camera_to_world[3], j->surf.view.camera_to_world[7],
                            j->surf.view.camera_to_world[11]);
        fx_vec3 v = fx_v3_normalize_or(fx_v3_sub(eye, w), n);
        if (j->surf.view.orthographic)
            v = fx_v3_normalize_or(fx_v3(j->surf.view.camera_to_world[2], j->surf.view.camera_to_world[6],
                                         j->surf.view.camera_to_world[10]), n);
        float ndv = fx_saturate(fx_v3_dot(n, v));
        float m = 1.0f - ndv, m2 = m * m;
        float fres = 0.02f + 0.98f * m2 * m2 * m;
        *gain = 1.0f - p->darken * wet;
        for (int c = 0; c < 3; c++) {
            float add = p->specular * fres * p->sky[c];
            if (j->gdir && j->gcol)
                add += p->gloss_boost * j->gdir[3 * i + c] * j->gcol[3 * i + c];
            off[c] = wet * add;
        }
    }
    *wet_out = wet;
    return 1;
}

static inline void wet_apply(const float *s, float *o, float gain, const float off[3])
{
    for (int c = 0; c < 3; c++) {
        float r = s[c] * gain + off[c];
        /* hostile 1e38 glossy passes overflow the product: keep it finite */
        o[c] = r != r ? s[c] : fx_clampf(r, -FLT_MAX, FLT_MAX);
    }
    o[3] = s[3];
}

/* The lattice nodes' values (see WET_NODE) */
static void wet_node_rows(void *user, int k0, int k1)
{
    wet_job *j = user;
    const fx_effect_run *run = j->run;
    for (int k = k0; k < k1; k++)
        for (int i = 0; i < j->nx; i++) {
            int x = j->node_x[i], y = j->node_y[k];
            size_t pi = (size_t)y * run->width + x;
            float *q = j->nodes + ((size_t)k * j->nx + i) * WET_NODE;
            float wet, gain, off[3];
            fx_vec3 n;
            memset(q, 0, WET_NODE * sizeof(float));
            if (wet_pixel(j, x, y, pi, &gain, off, &wet) && fx_surface_normal(&j->surf, x, y, &n) &&
                isfinite(gain) && isfinite(off[0]) && isfinite(off[1]) && isfinite(off[2])) {
                q[N_G] = q[N_G + 1] = q[N_G + 2] = gain;
                q[N_G + 3] = 1.0f;
                q[N_O] = off[0];
                q[N_O + 1] = off[1];
                q[N_O + 2] = off[2];
                q[N_WET] = wet;
                q[N_DEPTH] = j->surf.depth[pi];
                q[N_NX] = n.x;
                q[N_NX + 1] = n.y;
                q[N_NX + 2] = n.z;
            } else {
                q[N_DEPTH] = NAN;
            }
        }
}

/* A lattice cell is smooth when its four corners have a surface and their normals agree
 * (within about 25 degrees of the first): a crease or a silhouette between is not. */
static void wet_cell_rows(void *user, int k0, int k1)
{
    wet_job *j = user;
    const int ncx = j->nx > 1 ? j->nx - 1 : 1;
    for (int k = k0; k < k1; k++)
        for (int i = 0; i < ncx; i++) {
            int i1 = j->nx > 1 ? i + 1 : i, ka = k, kb = j->ny > 1 ? k + 1 : k;
            const float *c[4] = {j->nodes + ((size_t)ka * j->nx + i) * WET_NODE,
                                 j->nodes + ((size_t)ka * j->nx + i1) * WET_NODE,
                                 j->nodes + ((size_t)kb * j->nx + i) * WET_NODE,
                                 j->nodes + ((size_t)kb * j->nx + i1) * WET_NODE};
            int ok = 1;
            for (int m = 0; m < 4 && ok; m++) {
                float dot = c[0][N_NX] * c[m][N_NX] + c[0][N_NX + 1] * c[m][N_NX + 1] + c[0][N_NX + 2] * c[m][N_NX + 2];
                ok = c[m][N_DEPTH] == c[m][N_DEPTH] && dot >= 0.9f;
            }
            j->smooth[(size_t)k * j->nx + i] = (unsigned char)ok;
        }
}

/* out = src G + O (alpha kept); a NaN channel keeps the source's, an overflow clamps */
static inline void wet_apply4(const float *s, float *o, v4f g, v4f off)
{
    const v4f sv = ld4(s);
    v4f r = sv * g + off;
    r = sel4(r == r, r, sv);
    r = sel4(r < V4(FLT_MAX), r, V4(FLT_MAX));
    r = sel4(r > V4(-FLT_MAX), r, V4(-FLT_MAX));
    r[3] = s[3];
    st4(o, r);
}

/* Per row and lattice cell: the look at the cell's left edge (L) and its change to the
 * right edge (D), interpolated between the cell's two node rows: G, O, then wetness and
 * depth (lanes 0, 1 of W). */
typedef struct wet_span {
    v4f gl, gd, ol, od, wl, wd;
} wet_span;

/* A pixel of a cell that is not smooth (or that failed the smooth test): the corners on
 * its own surface (depth within 1.5 % x N of its own, normal within about 25 degrees),
 * by their bilinear weights; 0 when none is (then it is computed exactly). */
static int wet_partial(const wet_job *j, const float *const c[4], const float bw[4], float d, const float *nq,
                       v4f *g, v4f *off, float *wet)
{
    const float nn = nq[0] * nq[0] + nq[1] * nq[1] + nq[2] * nq[2];
    const float lim = 0.015f * (float)j->f * d;
    v4f ag = V4(0.0f), ao = V4(0.0f);
    float aw = 0.0f, ws = 0.0f;
    for (int m = 0; m < 4; m++) {
        const float *q = c[m];
        const float dd = fabsf(d - q[N_DEPTH]);
        if (!(dd <= lim))
            continue; /* also no surface (NaN) */
        const float nd = nq[0] * q[N_NX] + nq[1] * q[N_NX + 1] + nq[2] * q[N_NX + 2];
        if (!(nd > 0.0f && nd * nd >= 0.81f * nn))
            continue;
        const float w = bw[m] + 1e-3f;
        ag += V4(w) * ld4(q + N_G);
        ao += V4(w) * ld4(q + N_O);
        aw += w * q[N_WET];
        ws += w;
    }
    if (!(ws > 0.0f))
        return 0;
    const float inv = 1.0f / ws;
    *g = ag * V4(inv);
    *off = ao * V4(inv);
    *wet = aw * inv;
    return 1;
}

/* Each smooth cell of lattice row k (next k1) as a span along this pixel row, at weight
 * vty between the rows: left values and their differences to the right corners. */
static inline __attribute__((always_inline)) void row_spans(const wet_job *j, wet_span *sp, int k, int k1, int ncx,
                                                            v4f vty)
{
    for (int i = 0; i < ncx; i++) {
        if (!j->smooth[(size_t)k * j->nx + i])
            continue;
        const int i1 = j->nx > 1 ? i + 1 : i;
        const float *a = j->nodes + ((size_t)k * j->nx + i) * WET_NODE;
        const float *b = j->nodes + ((size_t)k * j->nx + i1) * WET_NODE;
        const float *c = j->nodes + ((size_t)k1 * j->nx + i) * WET_NODE;
        const float *e = j->nodes + ((size_t)k1 * j->nx + i1) * WET_NODE;
        wet_span *s = &sp[i];
#define LERP(p, q) (ld4(p) + vty * (ld4(q) - ld4(p)))
        const v4f gl = LERP(a + N_G, c + N_G), gr = LERP(b + N_G, e + N_G);
        const v4f ol = LERP(a + N_O, c + N_O), orr = LERP(b + N_O, e + N_O);
        const v4f wl = LERP(a + N_WET, c + N_WET), wr = LERP(b + N_WET, e + N_WET);
#undef LERP
        s->gl = gl;
        s->gd = gr - gl;
        s->ol = ol;
        s->od = orr - ol;
        s->wl = wl;
        s->wd = wr - wl;
    }
}

/* A smooth cell's pixels [xs, xe) four at a time while all four lie on the cell's surface
 * (the same tests, lane by lane, as wet_lattice_rows' one-pixel loop: the same bits);
 * returns the first pixel not done. an: the cell's first corner's normal. */
static inline __attribute__((always_inline)) int smooth_quads(const wet_span *sc, const float *an, float far,
                                                              const float *restrict depth,
                                                              const float *restrict normal,
                                                              const float *restrict col_t, const float *restrict src,
                                                              float *restrict dst, float *restrict dbg, int xs, int xe)
{
    const float an0 = an[0], an1 = an[1], an2 = an[2];
    const v4f wl0 = V4(sc->wl[0]), wd0 = V4(sc->wd[0]), wl1 = V4(sc->wl[1]), wd1 = V4(sc->wd[1]);
    int x = xs;
    for (; x + 4 <= xe; x += 4) {
        const v4f d4 = ld4(depth + x), tx4 = ld4(col_t + x);
        v4f nx, ny, nz;
        ld3x4(normal + 3 * (size_t)x, &nx, &ny, &nz);
        const v4f dz = wl1 + tx4 * wd1;
        const v4f nd = nx * V4(an0) + ny * V4(an1) + nz * V4(an2);
        const v4f nn = nx * nx + ny * ny + nz * nz;
        const v4f dd = (v4f)((v4i)(d4 - dz) & (v4i){0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff}); /* |d - dz| */
        const v4i ok = (d4 > V4(0.0f)) & (d4 < V4(far)) & (dd <= V4(0.02f) * d4) & (nd > V4(0.0f)) &
                       (nd * nd >= V4(0.81f) * nn);
        if (!all4(ok))
            break;
        const v4f wet4 = wl0 + tx4 * wd0;
        for (int m = 0; m < 4; m++) {
            const float *s = src + 4 * (size_t)(x + m);
            float *o = dst + 4 * (size_t)(x + m);
            if (wet4[m] > 0.0f)
                wet_apply4(s, o, sc->gl + V4(tx4[m]) * sc->gd, sc->ol + V4(tx4[m]) * sc->od);
            else
                memcpy(o, s, 4 * sizeof(float)); /* dry: the source */
            if (dbg)
                dbg[x + m] = wet4[m];
        }
    }
    return x;
}

/* A cell that is not smooth: its pixels [xs, xe) four at a time through wet_partial's
 * tests and sums with the four pixels in the lanes (the same operations per pixel in the
 * same order: a corner that fails adds w = 0, which changes no sum: the same bits), while
 * all four have a surface and a corner on it; returns the first pixel not done. */
static inline __attribute__((always_inline)) int partial_quads(const wet_job *j, const float *const c[4], float ty,
                                                               float far, const float *restrict depth,
                                                               const float *restrict normal,
                                                               const float *restrict col_t, const float *restrict src,
                                                               float *restrict dst, float *restrict dbg, int xs, int xe)
{
    const v4f lim_f = V4(0.015f * (float)j->f), uy = V4(1.0f - ty), vy = V4(ty);
    const v4i absm = {0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff};
    int x = xs;
    for (; x + 4 <= xe; x += 4) {
        const v4f d4 = ld4(depth + x), tx4 = ld4(col_t + x);
        v4f nx, ny, nz;
        ld3x4(normal + 3 * (size_t)x, &nx, &ny, &nz);
        const v4f nn = nx * nx + ny * ny + nz * nz;
        const v4f lim = lim_f * d4;
        const v4f ux = V4(1.0f) - tx4;
        const v4f bw[4] = {ux * uy, tx4 * uy, ux * vy, tx4 * vy};
        v4f sg = V4(0.0f), s0 = V4(0.0f), s1 = V4(0.0f), s2 = V4(0.0f), sw = V4(0.0f), ws = V4(0.0f);
        for (int m = 0; m < 4; m++) {
            const float *q = c[m];
            const v4f dd = (v4f)((v4i)(d4 - V4(q[N_DEPTH])) & absm);
            const v4f nd = nx * V4(q[N_NX]) + ny * V4(q[N_NX + 1]) + nz * V4(q[N_NX + 2]);
            const v4i ok = (dd <= lim) & (nd > V4(0.0f)) & (nd * nd >= V4(0.81f) * nn);
            const v4f w = (v4f)((v4i)(bw[m] + V4(1e-3f)) & ok);
            sg = sg + w * V4(q[N_G]);
            s0 = s0 + w * V4(q[N_O]);
            s1 = s1 + w * V4(q[N_O + 1]);
            s2 = s2 + w * V4(q[N_O + 2]);
            sw = sw + w * V4(q[N_WET]);
            ws = ws + w;
        }
        const v4i good = (d4 > V4(0.0f)) & (d4 < V4(far)) & (ws > V4(0.0f));
        if (!all4(good))
            break;
        const v4f inv = V4(1.0f) / ws;
        const v4f g = sg * inv, o0 = s0 * inv, o1 = s1 * inv, o2 = s2 * inv, wet = sw * inv;
        for (int m = 0; m < 4; m++) {
            const float *s = src + 4 * (size_t)(x + m);
            float *o = dst + 4 * (size_t)(x + m);
            if (wet[m] > 0.0f)
                wet_apply4(s, o, (v4f){g[m], g[m], g[m], 1.0f}, (v4f){o0[m], o1[m], o2[m], 0.0f});
            else
                memcpy(o, s, 4 * sizeof(float)); /* dry: the source */
            if (dbg)
                dbg[x + m] = wet[m];
        }
    }
    return x;
}

static void wet_lattice_rows(void *user, int y0, int y1, int worker)
{
    wet_job *j = user;
    const fx_effect_run *run = j->run;
    const fx_rect *roi = &run->roi;
    wet_span *sp = j->spans + (size_t)worker * j->nx;
    const int ncx = j->nx > 1 ? j->nx - 1 : 1;
    const float far = j->surf.far_limit;
    for (int y = roi->y0 + y0; y < roi->y0 + y1; y++) {
        int k = (y - roi->y0) / j->f;
        if (k > j->ny - 2)
            k = j->ny - 2;
        if (k < 0)
            k = 0;
        int k1 = j->ny > 1 ? k + 1 : k;
        int span = j->node_y[k1] - j->node_y[k];
        float ty = span > 0 ? (float)(y - j->node_y[k]) / (float)span : 0.0f;
        ty = ty > 1.0f ? 1.0f : ty;
        const v4f vty = V4(ty);
        row_spans(j, sp, k, k1, ncx, vty);
        const float *restrict depth = j->surf.depth + (size_t)y * run->width;
        const float *restrict normal = j->surf.normal + (size_t)y * run->width * 3;
        const float *restrict src = run->src + (size_t)y * run->width * 4;
        float *restrict dst = run->dst + (size_t)y * run->width * 4;
        float *restrict dbg = j->dbg ? j->dbg + (size_t)y * run->width : NULL;
        const unsigned char *srow = j->smooth + (size_t)k * j->nx;
        const float *nrow0 = j->nodes + (size_t)k * j->nx * WET_NODE, *nrow1 = j->nodes + (size_t)k1 * j->nx * WET_NODE;
        const float *restrict col_t = j->col_t - roi->x0;
        for (int cc = 0; cc < ncx; cc++) {
            /* the pixels of this cell's columns (the last cell takes the ROI's rest) */
            const int xs = roi->x0 + cc * j->f, xe = cc == ncx - 1 ? roi->x1 : xs + j->f;
            const int smooth = srow[cc], c1 = j->nx > 1 ? cc + 1 : cc;
            const wet_span sc = smooth ? sp[cc] : (wet_span){0};
            const float *an = nrow0 + (size_t)cc * WET_NODE + N_NX;
            const float an0 = an[0], an1 = an[1], an2 = an[2];
            const float *c[4] = {nrow0 + (size_t)cc * WET_NODE, nrow0 + (size_t)c1 * WET_NODE,
                                 nrow1 + (size_t)cc * WET_NODE, nrow1 + (size_t)c1 * WET_NODE};
            int x = xs;
            if (smooth)
                x = smooth_quads(&sc, an, far, depth, normal, col_t, src, dst, dbg, xs, xe);
            else if (xe - xs >= 4) /* (narrower cells, downsample 2 and 3: a pixel at a time) */
                x = partial_quads(j, c, ty, far, depth, normal, col_t, src, dst, dbg, xs, xe);
            for (; x < xe; x++) {
                const float *s = src + 4 * (size_t)x;
                float *o = dst + 4 * (size_t)x;
                const float d = depth[x];
                if (!(d > 0.0f && d < far)) { /* no surface: the source */
                    memcpy(o, s, 4 * sizeof(float));
                    if (dbg)
                        dbg[x] = 0.0f;
                    continue;
                }
                const float tx = col_t[x];
                const float *nq = normal + 3 * (size_t)x;
                v4f g, off;
                float wet = 0.0f;
                int done = 0;
                if (smooth) {
                    const v4f w = sc.wl + V4(tx) * sc.wd; /* wetness, depth */
                    /* the pixel on the corners' surface: its depth within 2 % of theirs and
                     * its normal within about 25 degrees of the first corner's */
                    const float nd = nq[0] * an0 + nq[1] * an1 + nq[2] * an2;
                    const float nn = nq[0] * nq[0] + nq[1] * nq[1] + nq[2] * nq[2];
                    if (fabsf(d - w[1]) <= 0.02f * d && nd > 0.0f && nd * nd >= 0.81f * nn) {
                        g = sc.gl + V4(tx) * sc.gd;
                        off = sc.ol + V4(tx) * sc.od;
                        wet = w[0];
                        done = 1;
                    }
                }
                if (!done) {
                    const float bw[4] = {(1.0f - tx) * (1.0f - ty), tx * (1.0f - ty), (1.0f - tx) * ty, tx * ty};
                    done = wet_partial(j, c, bw, d, nq, &g, &off, &wet);
                }
                if (!done) {
                    float gain, o3[3];
                    wet_pixel(j, x, y, (size_t)y * run->width + x, &gain, o3, &wet);
                    g = (v4f){gain, gain, gain, 1.0f};
                    off = (v4f){o3[0], o3[1], o3[2], 0.0f};
                }
                if (wet > 0.0f)
                    wet_apply4(s, o, g, off);
                else
                    memcpy(o, s, 4 * sizeof(float)); /* dry: the source */
                if (dbg)
                    dbg[x] = wet;
            }
        }
    }
}

static void wet_rows(void *user, int y0, int y1)
{
    wet_job *j = user;
    const fx_effect_run *run = j->run;
    const fx_rect *roi = &run->roi;
    for (int y = roi->y0 + y0; y < roi->y0 + y1; y++)
        for (int x = roi->x0; x < roi->x1; x++) {
            size_t i = (size_t)y * run->width + x;
            const float *s = run->src + 4 * i;
            float *o = run->dst + 4 * i;
            memcpy(o, s, 4 * sizeof(float));
            float gain, off[3], wet = 0.0f;
            if (wet_pixel(j, x, y, i, &gain, off, &wet) && wet > 0.0f)
                wet_apply(s, o, gain, off);
            if (j->dbg)
                j->dbg[i] = wet;
        }
}

/* Lattice positions along one axis of the ROI [a, b) (b - a >= 2): every f-th pixel, the
 * last on b - 1 */
static int *wet_lattice_axis(int a, int b, int f, int *n)
{
    *n = (b - a - 2) / f + 2;
    int *v = fx_mem_alloc((size_t)*n * sizeof(int));
    if (v)
        for (int i = 0; i < *n; i++)
            v[i] = i == *n - 1 ? b - 1 : a + i * f;
    return v;
}

static fx_result wet_process(const fx_effect_run *run)
{
    const wet_params *p = run->params;
    const fx_rect *roi = &run->roi;
    const char *where = run->where;
    wet_job j;
    memset(&j, 0, sizeof j);
    j.run = run;
    j.p = p;
    /* the rain map's moments box-filtered over `softness` metres (cached per context) */
    fx_result r = fx_rain_effect_begin(run, 1, p->softness, "wetness", &j.surf, &j.rm, &j.dbg);
    if (r)
        return r;
    fx_pass *gd = fx_frame_find_pass(run->frame, "GlossDir"), *gc = fx_frame_find_pass(run->frame, "GlossCol");
    if (gd && gc && gd->channels >= 3 && gc->channels >= 3 && gd->channels == gc->channels && gd->channels == 3) {
        j.gdir = gd->data;
        j.gcol = gc->data;
    }
    int rows = roi->y1 - roi->y0, cols = roi->x1 - roi->x0;
    /* the lattice spacing is in full-resolution pixels: a 1/k proxy's is N / k (rounded,
     * at least 1: then every pixel) */
    const int pf = run->proxy_factor > 1 ? run->proxy_factor : 1;
    const int ds = (p->downsample + pf / 2) / pf;
    if (ds > 1 && rows > 2 && cols > 2) {
        j.f = ds;
        j.node_x = wet_lattice_axis(roi->x0, roi->x1, j.f, &j.nx);
        j.node_y = wet_lattice_axis(roi->y0, roi->y1, j.f, &j.ny);
        j.col_i0 = fx_mem_alloc((size_t)cols * sizeof(int));
        j.col_t = fx_mem_alloc((size_t)cols * sizeof(float));
        j.nodes = j.node_x && j.node_y ? fx_mem_alloc((size_t)j.nx * j.ny * WET_NODE * sizeof(float)) : NULL;
        j.smooth = j.node_x && j.node_y ? fx_mem_alloc((size_t)j.nx * j.ny) : NULL;
        const int workers = fx_parallel_workers(run->ctx) > 0 ? fx_parallel_workers(run->ctx) : 1;
        j.spans = j.node_x && j.node_y ? fx_mem_alloc((size_t)workers * j.nx * sizeof(wet_span)) : NULL;
        int ok = j.node_x && j.node_y && j.col_i0 && j.col_t && j.nodes && j.smooth && j.spans;
        if (ok) {
            for (int c = 0; c < cols; c++) {
                int i0 = c / j.f;
                i0 = i0 > j.nx - 2 ? j.nx - 2 : i0;
                int span = j.node_x[i0 + 1] - j.node_x[i0];
                float t = span > 0 ? (float)(roi->x0 + c - j.node_x[i0]) / (float)span : 0.0f;
                j.col_i0[c] = i0;
                j.col_t[c] = t > 1.0f ? 1.0f : t;
            }
            fx_parallel_for(run->ctx, j.ny, 1, wet_node_rows, &j);
            fx_parallel_for(run->ctx, j.ny - 1, 1, wet_cell_rows, &j);
            fx_parallel_for_worker(run->ctx, rows, fx_grain_for(run->ctx, rows), wet_lattice_rows, &j);
        }
        fx_mem_free(j.node_x);
        fx_mem_free(j.node_y);
        fx_mem_free(j.col_i0);
        fx_mem_free(j.col_t);
        fx_mem_free(j.nodes);
        fx_mem_free(j.smooth);
        fx_mem_free(j.spans);
        if (!ok)
            return fx_rain_effect_end(&j.rm, fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where));
    } else {
        fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), wet_rows, &j);
    }
    return fx_rain_effect_end(&j.rm, FX_OK);
}

const fx_effect_class fx_effect_wet_surfaces = {
    .name = "wet_surfaces",
    .doc = "Wet look where rain reaches (rain map): darker albedo, Fresnel sky reflection, soft edges at covers",
    .params_size = sizeof(wet_params),
    .params = wet_param_defs,
    .param_count = FX_COUNT_OF(wet_param_defs),
    /* draft at least 3x faster than final (docs/effects/wet_surfaces.md) */
    .presets = {"{\"downsample\": 8}", "{\"downsample\": 3}", "{\"downsample\": 1}", "{\"downsample\": 1}"},
    .passes = wet_passes,
    .flags = FX_EFFECT_NEEDS_CAMERA,
    .aux_views = fx_aux_needs_rain_map, /* what is under cover */
    .halo = NULL,
    .validate = NULL,
    .process = wet_process,
};
