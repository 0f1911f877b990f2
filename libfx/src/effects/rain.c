/* rain: falling streaks in three layers at distances near/mid/far (the seed's double cone
 * of rain particles around the camera, reproduced in screen space), each depth-tested
 * against the Depth pass and against the rain map, plus rain on the scene's cover quads
 * when the camera stands under cover. docs/effects/rain.md.
 *
 * Layer k lies at planar distance d_k: its pattern is scaled by d_0 / d_k (nearer:
 * larger, faster) and a streak pixel shows only where the scene is farther than d_k and
 * the streak's world point (the pixel's ray at d_k) is exposed in the rain map. The
 * pattern: rotated by the wind angle, cut into cells (spacing wide, 1.5 streak lengths
 * tall) that scroll down with time; a cell holds a streak with probability `density`,
 * its place and length from a hash of (cell, layer, seed): the same frame gives the same
 * bits, consecutive frames move the same streaks. Cover quads (material cover_material,
 * found through Cryptomatte, coverage normalised by cover_opacity) get the nearest layer's
 * pattern, unclipped, when the camera is under cover (rain map at the camera). Additive. */
#include "scene/aux_view.h"
#include "core/effect.h"
#include "core/parallel.h"
#include "effects/rain_common.h"
#include "math/hash.h"
#include "scene/rain_map.h"
#include "math/surface.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

typedef struct rain_params {
    float density;
    float length;
    float width;
    float brightness;
    float wind;
    float speed;
    float distances[3];
    float color[3];
    char cover_material[FX_STRING_PARAM_MAX];
    float cover_opacity;
    float cover_brightness;
    int seed;
    int layers;
    int downsample;
} rain_params;

static const float default_color[3] = {0.8f, 0.85f, 0.9f};

static const fx_param_def rain_param_defs[] = {
    FX_P_FLOAT(rain_params, density, "density", 0.35, 0.0, 1.0, 0.0, 1.0, "factor",
               "Fraction of pattern cells holding a streak"),
    FX_P_FLOAT(rain_params, length, "streak_length", 40.0, 1.0, 2000.0, 5.0, 200.0, "texels",
               "Streak length of the near layer, in pixels of a 720-line image (scales with the height)"),
    FX_P_FLOAT(rain_params, width, "streak_width", 1.2, 0.3, 20.0, 0.5, 4.0, "texels",
               "Streak width of the near layer (720-line pixels)"),
    FX_P_FLOAT(rain_params, brightness, "brightness", 0.35, 0.0, 10.0, 0.0, 2.0, "",
               "Added radiance of a streak's core (times colour)"),
    FX_P_FLOAT(rain_params, wind, "wind_angle", 10.0, -80.0, 80.0, -45.0, 45.0, "angle",
               "Slant of the streaks from vertical, degrees"),
    FX_P_FLOAT(rain_params, speed, "speed", 1800.0, 0.0, 100000.0, 0.0, 5000.0, "",
               "Fall speed of the near layer, 720-line pixels per second (farther layers slower)"),
    FX_P_FLOAT(rain_params, distances[0], "near", 2.0, 0.05, 1e5, 0.5, 10.0, "",
               "Planar distance of the near layer, metres"),
    FX_P_FLOAT(rain_params, distances[1], "mid", 5.0, 0.05, 1e5, 1.0, 30.0, "",
               "Planar distance of the middle layer, metres"),
    FX_P_FLOAT(rain_params, distances[2], "far", 12.0, 0.05, 1e5, 2.0, 100.0, "",
               "Planar distance of the far layer, metres"),
    FX_P_FLOATS(rain_params, color, "color", 3, default_color, 0.0, 1e4, "color", "Streak colour"),
    FX_P_STRING(rain_params, cover_material, "cover_material", "Rain_Cover", "",
                "Material of the cover quads (Cryptomatte); empty: none"),
    FX_P_FLOAT(rain_params, cover_opacity, "cover_opacity", 0.07, 0.001, 1.0, 0.01, 1.0, "factor",
               "The quads' coverage in Cryptomatte that counts as fully on the quad"),
    FX_P_FLOAT(rain_params, cover_brightness, "cover_brightness", 0.6, 0.0, 10.0, 0.0, 2.0, "",
               "Brightness of the rain drawn on cover quads, relative to brightness"),
    FX_P_INT(rain_params, seed, "seed", 7, -2147483647, 2147483647, 0, 100, "", "Pattern seed"),
    FX_P_INT(rain_params, layers, "layers", 3, 1, 3, 1, 3, "",
             "How many of the near/mid/far layers are drawn, nearest first (the cost is about one "
             "layer's per layer; fewer layers: less distant rain)"),
    FX_P_INT(rain_params, downsample, "downsample", 1, 1, 32, 1, 16, "",
             "Quality: the streaks are evaluated on every N-th pixel row (N times fewer evaluations) "
             "and interpolated along their slant: they keep their width, their ends soften over N rows; "
             "the depth test and the cover quads stay per pixel; 1: every pixel"),
};

static fx_pass_set rain_passes(const void *params)
{
    const rain_params *p = params;
    fx_pass_set s = FX_PASS_BIT(FX_PASS_DEPTH);
    if (p->cover_material[0])
        s |= FX_PASS_BIT(FX_PASS_CRYPTO_MATERIAL);
    return s;
}

static fx_result rain_validate(const void *params, char *err, size_t n)
{
    const rain_params *p = params;
    if (!(p->distances[0] < p->distances[1] && p->distances[1] < p->distances[2])) {
        snprintf(err, n, "near < mid < far is required (got %g, %g, %g)", p->distances[0], p->distances[1],
                 p->distances[2]);
        return FX_ERR_BAD_PARAM;
    }
    return FX_OK;
}

typedef struct rain_job {
    const fx_effect_run *run;
    const rain_params *p;
    fx_surface_src surf;
    fx_rain_map rm;
    const fx_mask *cover;
    int camera_covered;
    /* downsample > 1: the cover quads' coverage read from Cryptomatte only at the pixels
     * a cover streak reaches, instead of a whole-frame mask (cover NULL then) */
    const float *crypto[8];
    int crypto_n;
    float cover_id;
    float t, res, cs, sn;
    float *dbg;
    int f, gw, gh, nb;
    int *row_y;         /* gh grid rows: every f-th row of the ROI, the last on its last row */
    float slant;        /* tan(wind): columns per row along a streak */
    float *grid;        /* gw x gh nodes of 4 floats: layers 0..2 (weighted, exposure), cover */
    unsigned char *lit; /* per node: some value is not 0 */
    float *bmax;        /* per band between grid rows and RAIN_BLOCK columns: farthest depth ... */
    unsigned char *bcov;/* ... and whether a pixel of it is on a cover quad */
} rain_job;

/* The streaks of the cells a pixel can see, per layer: the cells (ci + di, cj + dj) for
 * di in [-reach, reach], dj in {-1, 0}, with the streak each holds (x0 < 0 marks none).
 * Consecutive pixels of a row mostly fall in the same cells (a cell is 14 x 60 pattern
 * pixels, 1.5 to 9 frame pixels per pattern pixel), so the hashes are computed once per
 * cell change: the same values as per pixel, bit for bit. */
/* Columns of cells a streak can reach into at most: a streak of cell ci + r lies at least
 * (|r| - 0.85) cells from any point of cell ci, so a streak drawn we wide reaches r up to
 * we / cw + 0.85; 3 covers we up to 3.15 cells (a pixel 44 near-layer pattern pixels wide:
 * the far layer of a frame under ~100 lines at the defaults). Wider is clipped. */
#define RAIN_MAX_REACH 3
#define RAIN_SLOTS (2 * (2 * RAIN_MAX_REACH + 1))

typedef struct cell_cache {
    int ci, cj, valid;
    int n;
    float x0[RAIN_SLOTS], y0[RAIN_SLOTS], len[RAIN_SLOTS];
    int has[RAIN_SLOTS];
} cell_cache;

/* The streak of cell (cx, cy) of a layer into slot k */
static inline void cell_one(const rain_job *j, cell_cache *cc, int k, int cx, int cy, int layer)
{
    const rain_params *p = j->p;
    float cw = 14.0f, ch = 1.5f * p->length;
    uint32_t h = fx_hash4(cx, cy, layer, p->seed);
    cc->has[k] = fx_hash_to_unit(h) < p->density;
    if (!cc->has[k])
        return;
    uint32_t h1 = fx_hash_u32(h), h2 = fx_hash_u32(h1), h3 = fx_hash_u32(h2);
    cc->x0[k] = ((float)cx + 0.15f + 0.7f * fx_hash_to_unit(h1)) * cw;
    cc->y0[k] = ((float)cy + fx_hash_to_unit(h2)) * ch;
    cc->len[k] = p->length * (0.7f + 0.6f * fx_hash_to_unit(h3));
}

/* Slot k = 2 (di + reach) + (dj + 1). A step to the next column (ci + 1, same row of cells:
 * most steps along a pixel row) slides the slots and fills the new column only. */
static void cells_fill(const rain_job *j, cell_cache *cc, int ci, int cj, int layer, int reach)
{
    int n = 2 * (2 * reach + 1);
    if (cc->valid && cc->n == n && cc->cj == cj && cc->ci + 1 == ci) {
        for (int k = 0; k + 2 < n; k++) {
            cc->has[k] = cc->has[k + 2];
            cc->x0[k] = cc->x0[k + 2];
            cc->y0[k] = cc->y0[k + 2];
            cc->len[k] = cc->len[k + 2];
        }
        cc->ci = ci;
        cell_one(j, cc, n - 2, ci + reach, cj - 1, layer);
        cell_one(j, cc, n - 1, ci + reach, cj, layer);
        return;
    }
    cc->ci = ci;
    cc->cj = cj;
    cc->valid = 1;
    cc->n = 0;
    for (int di = -reach; di <= reach; di++)
        for (int dj = -1; dj <= 0; dj++)
            cell_one(j, cc, cc->n++, ci + di, cj + dj, layer);
}

/* Streak intensity in [0, 1] of layer `layer` at frame pixel (x, y) (continuous). */
static float streak(const rain_job *j, float x, float y, int layer, float scale, float footprint, cell_cache *cc)
{
    const rain_params *p = j->p;
    float k = j->res * scale;
    /* pattern space: rotated so streaks are vertical, in near-layer 720-line pixels */
    float u = (x * j->cs - y * j->sn) / k;
    float v = (x * j->sn + y * j->cs) / k - j->t * p->speed * scale;
    float cw = 14.0f, ch = 1.5f * p->length;
    int ci = (int)floorf(u / cw), cj = (int)floorf(v / ch);
    float best = 0.0f;
    float wmin = footprint / k, we = p->width > wmin ? p->width : wmin;
    int reach = we > 0.15f * cw ? 1 : 0; /* wide streaks reach into the next columns */
    if (we > 1.15f * cw) { /* and beyond them (a pixel wider than a cell: far layers at low resolution) */
        float r = floorf(we / cw + 0.85f);
        reach = r < (float)RAIN_MAX_REACH ? (int)r : RAIN_MAX_REACH;
    }
    if (!cc->valid || cc->ci != ci || cc->cj != cj)
        cells_fill(j, cc, ci, cj, layer, reach);
    for (int c = 0; c < cc->n; c++) {
        if (!cc->has[c])
            continue;
        float a = (v - cc->y0[c]) / cc->len[c];
        if (a <= 0.0f || a >= 1.0f)
            continue;
        /* a streak narrower than a pixel is drawn a pixel wide and dimmer (its coverage),
         * so it does not alias into speckle at small sizes */
        float across = 1.0f - fabsf(u - cc->x0[c]) / we;
        if (across <= 0.0f)
            continue;
        float i = across * (p->width / we) * 4.0f * a * (1.0f - a);
        best = i > best ? i : best;
    }
    return best;
}

static void rain_rows(void *user, int y0, int y1)
{
    rain_job *j = user;
    const fx_effect_run *run = j->run;
    const rain_params *p = j->p;
    const fx_rect *roi = &run->roi;
    for (int y = roi->y0 + y0; y < roi->y0 + y1; y++) {
        cell_cache cc[4];
        for (int l = 0; l < 4; l++)
            cc[l].valid = 0;
        for (int x = roi->x0; x < roi->x1; x++) {
            size_t i = (size_t)y * run->width + x;
            const float *s = run->src + 4 * i;
            float *o = run->dst + 4 * i;
            float d = j->surf.depth[i];
            if (!(d > 0.0f))
                d = 0.0f;
            if (!isfinite(d))
                d = 3.0e38f;
            float sum = 0.0f;
            for (int l = 0; l < p->layers; l++) {
                float dl = p->distances[l];
                if (!(d > dl))
                    continue; /* the scene is nearer than the layer */
                float scale = p->distances[0] / dl;
                float st = streak(j, (float)x + 0.5f, (float)y + 0.5f, l, scale, 1.0f, &cc[l]);
                if (st <= 0.0f)
                    continue;
                fx_vec2 ndc = fx_view_pixel_to_ndc(&j->surf.view, (float)x + 0.5f, (float)y + 0.5f);
                fx_vec3 w = fx_view_to_world(&j->surf.view, fx_view_position(&j->surf.view, ndc, dl));
                if (fx_rain_map_exposed(&j->rm, w) <= 0.0f)
                    continue; /* under cover */
                sum += st * (0.5f + 0.5f * scale);
            }
            if (j->cover && j->camera_covered) {
                float c = fx_saturate(j->cover->coverage[i] / p->cover_opacity);
                if (c > 0.0f)
                    sum += c * p->cover_brightness * streak(j, (float)x + 0.5f, (float)y + 0.5f, 3, 1.0f, 1.0f, &cc[3]);
            }
            if (j->dbg)
                j->dbg[i] = sum;
            float a = sum * p->brightness;
            for (int c = 0; c < 3; c++)
                o[c] = s[c] + a * p->color[c];
            o[3] = s[3];
        }
    }
}

/* downsample f > 1: the streaks are evaluated on every f-th pixel row of the ROI (rows
 * row_y[r], the last on the ROI's last row), at every column, and a pixel between two such
 * rows interpolates them along the streaks' slant (x shifted by tan(wind) per row): a
 * streak's intensity varies slowly along its length (4 a (1 - a)) and sharply across it,
 * so the streaks keep their width and only their ends soften over f rows. Per layer: the
 * streak times its weight, 0 where the layer's point is under cover; the depth test and
 * the cover quads' coverage stay per pixel (rain_composite_rows). Nodes no pixel can add
 * (the layer nearer than every surface around, no cover quad near) are left 0. */
#define RAIN_BLOCK 16 /* columns per block of the depth / cover bounds */

static inline float depth_of(const rain_job *j, size_t i)
{
    float d = j->surf.depth[i];
    if (!(d > 0.0f))
        d = 0.0f;
    if (!isfinite(d))
        d = 3.0e38f;
    return d;
}

/* Coverage of the cover material at pixel i, as fx_mask_build computes it for one material
 * name (core/mask.c: ranks sorted by coverage, stop once 1 is seen, clamped to [0, 1]) */
static inline float cover_coverage(const rain_job *j, size_t i)
{
    if (j->cover)
        return j->cover->coverage[i];
    float c = 0.0f, seen = 0.0f;
    for (int r = 0; r < j->crypto_n && seen < 0.99999f; r++) {
        const float *q = j->crypto[r] + i * 4;
        if (q[0] == j->cover_id)
            c += q[1];
        if (q[2] == j->cover_id)
            c += q[3];
        seen += q[1] + q[3];
    }
    if (!(c >= 0.0f))
        c = 0.0f;
    return c > 1.0f ? 1.0f : c;
}

/* Per band r (rows row_y[r] .. row_y[r + 1]) and block of RAIN_BLOCK columns: the farthest
 * depth and whether a pixel is on a cover quad. */
static void rain_band_rows(void *user, int r0, int r1)
{
    rain_job *j = user;
    const fx_effect_run *run = j->run;
    const fx_rect *roi = &run->roi;
    for (int r = r0; r < r1; r++) {
        int ya = j->row_y[r], yb = r + 1 < j->gh ? j->row_y[r + 1] : ya;
        for (int b = 0; b < j->nb; b++) {
            int xa = roi->x0 + b * RAIN_BLOCK, xb = xa + RAIN_BLOCK < roi->x1 ? xa + RAIN_BLOCK : roi->x1;
            float m = 0.0f;
            int cov = 0;
            for (int y = ya; y <= yb; y++) {
                const float *dr = j->surf.depth + (size_t)y * run->width;
                for (int x = xa; x < xb; x++) {
                    float d = dr[x]; /* depth_of's order: NaN and <= 0 never win, +inf does */
                    m = d > m ? d : m;
                }
                if (j->cover) {
                    const float *cr = j->cover->coverage + (size_t)y * run->width;
                    for (int x = xa; x < xb; x++)
                        cov |= cr[x] > 0.0f; /* coverage / cover_opacity > 0 */
                } else if (j->camera_covered) {
                    cov = 1; /* Cryptomatte read later, where a cover streak is */
                }
            }
            m = isfinite(m) ? m : 3.0e38f;
            j->bmax[(size_t)r * j->nb + b] = m;
            j->bcov[(size_t)r * j->nb + b] = (unsigned char)cov;
        }
    }
}

static void rain_grid_rows(void *user, int r0, int r1)
{
    rain_job *j = user;
    const fx_effect_run *run = j->run;
    const rain_params *p = j->p;
    const fx_rect *roi = &run->roi;
    const int slack = (int)ceilf((float)j->f * fabsf(j->slant)) + 2; /* columns a node reaches */
    for (int r = r0; r < r1; r++) {
        cell_cache cc[4];
        for (int l = 0; l < 4; l++)
            cc[l].valid = 0;
        float py = (float)j->row_y[r] + 0.5f;
        int ba = r > 0 ? r - 1 : 0, bb = r < j->gh - 1 ? r : j->gh - 2; /* the bands around */
        if (bb < ba)
            bb = ba;
        for (int gx = 0; gx < j->gw; gx++) {
            float px = (float)(roi->x0 + gx) + 0.5f;
            float *q = j->grid + 4 * ((size_t)r * j->gw + gx);
            q[0] = q[1] = q[2] = q[3] = 0.0f;
            int ka = (gx - slack) / RAIN_BLOCK, kb = (gx + slack) / RAIN_BLOCK;
            ka = ka < 0 ? 0 : ka;
            kb = kb >= j->nb ? j->nb - 1 : kb;
            float far = 0.0f;
            int cov = 0;
            for (int band = ba; band <= bb; band++)
                for (int k = ka; k <= kb; k++) {
                    float m = j->bmax[(size_t)band * j->nb + k];
                    far = m > far ? m : far;
                    cov |= j->bcov[(size_t)band * j->nb + k];
                }
            for (int l = 0; l < p->layers; l++) {
                float dl = p->distances[l];
                if (!(far > dl))
                    continue; /* every surface around is nearer than the layer */
                float scale = p->distances[0] / dl;
                float st = streak(j, px, py, l, scale, 1.0f, &cc[l]);
                if (st <= 0.0f)
                    continue;
                fx_vec2 ndc = fx_view_pixel_to_ndc(&j->surf.view, px, py);
                fx_vec3 w = fx_view_to_world(&j->surf.view, fx_view_position(&j->surf.view, ndc, dl));
                if (fx_rain_map_exposed(&j->rm, w) <= 0.0f)
                    continue;
                q[l] = st * (0.5f + 0.5f * scale);
            }
            if (cov)
                q[3] = streak(j, px, py, 3, 1.0f, 1.0f, &cc[3]);
            j->lit[(size_t)r * j->gw + gx] = q[0] != 0.0f || q[1] != 0.0f || q[2] != 0.0f || q[3] != 0.0f;
        }
    }
}

/* Where a pixel row reads grid row r: the column offset (whole and fraction) of the point
 * on the streak through the pixel, dy rows away */
static inline void slant_offset(float slant, float dy, int *whole, float *frac)
{
    float o = slant * dy;
    float w = floorf(o);
    *whole = (int)w;
    *frac = o - w;
}

static inline int clamp_col(int c, int n)
{
    return c < 0 ? 0 : c >= n ? n - 1 : c;
}

static void rain_composite_rows(void *user, int y0, int y1)
{
    rain_job *j = user;
    const fx_effect_run *run = j->run;
    const rain_params *p = j->p;
    const fx_rect *roi = &run->roi;
    const int covered = j->camera_covered;
    const float inv_opacity = 1.0f / p->cover_opacity; /* >= 0.001 */
    for (int y = roi->y0 + y0; y < roi->y0 + y1; y++) {
        int r0 = (y - roi->y0) / j->f;
        if (r0 > j->gh - 2)
            r0 = j->gh - 2;
        if (r0 < 0)
            r0 = 0;
        int r1 = j->gh > 1 ? r0 + 1 : 0;
        int span = j->row_y[r1] - j->row_y[r0];
        float ty = span > 0 ? (float)(y - j->row_y[r0]) / (float)span : 0.0f;
        ty = ty > 1.0f ? 1.0f : ty;
        /* x + slant (row_y - y): the streak's column in rows r0 (above) and r1 (below) */
        int o0, o1;
        float f0, f1;
        slant_offset(j->slant, (float)(j->row_y[r0] - y), &o0, &f0);
        slant_offset(j->slant, (float)(j->row_y[r1] - y), &o1, &f1);
        const float *g0 = j->grid + 4 * (size_t)r0 * j->gw, *g1 = j->grid + 4 * (size_t)r1 * j->gw;
        const unsigned char *l0 = j->lit + (size_t)r0 * j->gw, *l1 = j->lit + (size_t)r1 * j->gw;
        const float w00 = (1.0f - ty) * (1.0f - f0), w10 = (1.0f - ty) * f0;
        const float w01 = ty * (1.0f - f1), w11 = ty * f1;
        for (int x = roi->x0; x < roi->x1; x++) {
            size_t i = (size_t)y * run->width + x;
            const float *s = run->src + 4 * i;
            float *o = run->dst + 4 * i;
            int col = x - roi->x0;
            int a0 = clamp_col(col + o0, j->gw), b0 = clamp_col(col + o0 + 1, j->gw);
            int a1 = clamp_col(col + o1, j->gw), b1 = clamp_col(col + o1 + 1, j->gw);
            if (!(l0[a0] | l0[b0] | l1[a1] | l1[b1])) { /* no streak near: the source */
                if (j->dbg)
                    j->dbg[i] = 0.0f;
                if (o != s) /* in place: already the source */
                    memcpy(o, s, 4 * sizeof(float));
                continue;
            }
            const float *a = g0 + 4 * a0, *b = g0 + 4 * b0, *c = g1 + 4 * a1, *e = g1 + 4 * b1;
            float d = depth_of(j, i);
            float sum = 0.0f;
            for (int l = 0; l < p->layers; l++)
                if (d > p->distances[l])
                    sum += w00 * a[l] + w10 * b[l] + w01 * c[l] + w11 * e[l];
            if (covered) {
                float cs = w00 * a[3] + w10 * b[3] + w01 * c[3] + w11 * e[3];
                if (cs > 0.0f) {
                    float cv = fx_saturate(cover_coverage(j, i) * inv_opacity);
                    if (cv > 0.0f)
                        sum += cv * p->cover_brightness * cs;
                }
            }
            if (j->dbg)
                j->dbg[i] = sum;
            float am = sum * p->brightness;
            for (int k = 0; k < 3; k++)
                o[k] = s[k] + am * p->color[k];
            o[3] = s[3];
        }
    }
}

static fx_result rain_process(const fx_effect_run *run)
{
    const rain_params *p = run->params;
    const fx_rect *roi = &run->roi;
    const char *where = run->where;
    rain_job j;
    memset(&j, 0, sizeof j);
    j.run = run;
    j.p = p;
    fx_result r = fx_rain_effect_begin(run, 0, 0.0f, "streaks", &j.surf, &j.rm, &j.dbg);
    if (r)
        return r;
    j.t = (float)fx_effect_scene_time(run);
    j.res = (float)run->height / 720.0f;
    float a = p->wind * 0.017453293f;
    j.cs = cosf(a);
    j.sn = sinf(a);
    fx_mask *cover = NULL;
    fx_vec3 cam = fx_v3(j.surf.view.camera_to_world[3], j.surf.view.camera_to_world[7],
                        j.surf.view.camera_to_world[11]);
    /* the cover quads get rain only when the camera stands under cover: otherwise their
     * mask (a Cryptomatte match over the frame) is not built */
    if (p->cover_material[0] && fx_rain_map_exposed(&j.rm, cam) <= 0.0f) {
        fx_mask_spec spec;
        memset(&spec, 0, sizeof spec);
        char *names[1] = {(char *)p->cover_material};
        spec.materials = names;
        spec.material_count = 1;
        int lazy = p->downsample > 1 && roi->y1 - roi->y0 > 2;
        if (lazy) { /* the rank passes as fx_mask_build reads them; else it gives the error */
            char name[32];
            for (int k = 0; k < 100 && lazy; k++) {
                snprintf(name, sizeof name, "CryptoMaterial%02d", k);
                const fx_pass *cp = fx_frame_find_pass(run->frame, name);
                if (!cp)
                    break;
                if (cp->channels != 4 || k >= 8)
                    lazy = 0;
                else
                    j.crypto[j.crypto_n++] = cp->data;
            }
            lazy = lazy && j.crypto_n > 0;
        }
        if (lazy)
            j.cover_id = fx_cryptomatte_id(p->cover_material);
        else
            r = fx_mask_build(run->ctx, &spec, run->frame, where, &cover);
        if (r)
            return fx_rain_effect_end(&j.rm, r);
        j.cover = cover;
        j.camera_covered = 1;
    }
    int rows = roi->y1 - roi->y0;
    if (p->downsample > 1 && rows > 2) {
        j.f = p->downsample;
        j.gw = roi->x1 - roi->x0;
        j.gh = (rows - 2) / j.f + 2;
        j.nb = (j.gw + RAIN_BLOCK - 1) / RAIN_BLOCK;
        j.slant = j.sn / j.cs;
        j.row_y = fx_mem_alloc((size_t)j.gh * sizeof(int));
        j.grid = fx_mem_alloc((size_t)j.gw * j.gh * 4 * sizeof(float));
        j.lit = fx_mem_alloc((size_t)j.gw * j.gh);
        j.bmax = fx_mem_alloc((size_t)j.nb * j.gh * sizeof(float));
        j.bcov = fx_mem_alloc((size_t)j.nb * j.gh);
        int ok = j.row_y && j.grid && j.lit && j.bmax && j.bcov;
        if (ok) {
            for (int r = 0; r < j.gh; r++)
                j.row_y[r] = r == j.gh - 1 ? roi->y1 - 1 : roi->y0 + r * j.f;
            fx_parallel_for(run->ctx, j.gh, 1, rain_band_rows, &j);
            fx_parallel_for(run->ctx, j.gh, 1, rain_grid_rows, &j);
            fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), rain_composite_rows, &j);
        }
        fx_mem_free(j.row_y);
        fx_mem_free(j.grid);
        fx_mem_free(j.lit);
        fx_mem_free(j.bmax);
        fx_mem_free(j.bcov);
        if (!ok) {
            fx_mask_free(cover);
            return fx_rain_effect_end(&j.rm, fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory", where));
        }
    } else {
        fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), rain_rows, &j);
    }
    fx_mask_free(cover);
    return fx_rain_effect_end(&j.rm, FX_OK);
}

const fx_effect_class fx_effect_rain = {
    .name = "rain",
    .doc = "Rain streaks in three depth layers, depth-tested and hidden under cover (rain map); rain on cover quads",
    .params_size = sizeof(rain_params),
    .params = rain_param_defs,
    .param_count = FX_COUNT_OF(rain_param_defs),
    /* draft at least 3x faster than final: the streaks on every 16th row, interpolated */
    .presets = {"{\"layers\": 3, \"downsample\": 16}", "{\"layers\": 3, \"downsample\": 4}",
                "{\"layers\": 3, \"downsample\": 1}", "{\"layers\": 3, \"downsample\": 1}"},
    .passes = rain_passes,
    /* in place (dst == src) for every parameter set: an output pixel reads only its own
     * colour pixel, just before writing it; the streaks are a hash pattern, and the depth
     * test, the rain map and the cover quads read Depth and Cryptomatte, never the colour.
     * On a consumed frame no fresh frame-sized output, and (downsample > 1) the pixels with
     * no streak near are not copied */
    .flags = FX_EFFECT_NEEDS_CAMERA | FX_EFFECT_IN_PLACE,
    .aux_views = fx_aux_needs_rain_map, /* what is under cover */
    .halo = NULL,
    .validate = rain_validate,
    .process = rain_process,
};
