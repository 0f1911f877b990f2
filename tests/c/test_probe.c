/* Reflection probes (ssr_mirror's fallback "probe"; math/panorama.h, scene/aux_view.h) on
 * a synthetic room made here: a 6 x 6 x 3 m box whose walls carry smooth colour
 * gradients, "rendered" into an equirectangular probe (colour + radial depth) written as
 * an EXR, and a frame looking at the room's +Y wall, which is the mirror.
 *  - conventions: which pixel is which direction (as Cycles' equirectangular camera:
 *    tests/blender/test_probe_view.py checks that side on a real render);
 *  - the parallax-corrected lookup against the exact ray-box intersection, and against
 *    the plain direction lookup it corrects;
 *  - end to end: the stack asks for "probe:<mask key>" with the mask, the mirror reflects
 *    the room behind the camera (what no screen-space ray sees) close to the exact
 *    reflection, the debug pass names the fallback; without the probe a warning and the
 *    texture fallback, bit for bit;
 *  - degenerate probes (zero depth, NaN/Inf colour and depth, 1 x 1, placed outside the
 *    room behind the mirror): finite output;
 *  - the planar view (planar_view, reference): the room rendered from the camera mirrored
 *    in the mirror wall's plane gives the exact reflection; a view whose plane is not the
 *    mirror's is not used; a planar mirror seen edge-on stays finite. */
#include "fx_effect_test.h"
#include "core/mask.h"
#include "math/panorama.h"

#include <cjson/cJSON.h>
#include <math.h>

#define PI 3.14159265358979

static const double LO[3] = { -3, -3, 0 }, HI[3] = { 3, 3, 3 };

/* Exit of the ray o + t d from inside the box: t, and the wall (axis * 2 + (d > 0)). */
static double box_exit(const double o[3], const double d[3], int *wall)
{
    double best = 1e30;
    *wall = -1;
    for (int a = 0; a < 3; a++) {
        if (fabs(d[a]) < 1e-12)
            continue;
        double t = ((d[a] > 0 ? HI[a] : LO[a]) - o[a]) / d[a];
        if (t > 0 && t < best)
            best = t, *wall = a * 2 + (d[a] > 0);
    }
    return best;
}

/* > 0: the walls carry black and white stripes of this width (metres, along x + y + z)
 * instead of gradients: detail a convex mirror shrinks below a pixel (test_footprint) */
static double g_stripes;

static void room_colour(const double p[3], int wall, float c[3])
{
    if (g_stripes) {
        float v = wall >= 0 && fmod(floor((p[0] + p[1] + p[2]) / g_stripes), 2.0) != 0.0 ? 1.0f : 0.0f;
        c[0] = c[1] = c[2] = v;
        return;
    }
    static const float base[6][3] = { { 0.2f, 0.8f, 0.2f }, { 0.9f, 0.2f, 0.2f }, { 0.9f, 0.9f, 0.2f },
                                      { 0.2f, 0.3f, 0.9f }, { 0.5f, 0.5f, 0.5f }, { 1.0f, 1.0f, 1.0f } };
    double g = 0.6 + 0.4 * sin(1.3 * p[0] + 0.7) * cos(0.9 * p[1] - 0.4) * cos(1.1 * p[2]);
    for (int k = 0; k < 3; k++)
        c[k] = wall >= 0 ? (float)(base[wall][k] * g) : 0.0f;
}

/* Probe camera: Blender camera looking along world +Y, up +Z (rotation X 90 deg). Camera
 * to world: x -> (1,0,0), y -> (0,0,1), z -> (0,-1,0). */
static const double R[9] = { 1, 0, 0, 0, 0, -1, 0, 1, 0 };

static void rot(const double m[9], const double v[3], double out[3])
{
    for (int i = 0; i < 3; i++)
        out[i] = m[i * 3] * v[0] + m[i * 3 + 1] * v[1] + m[i * 3 + 2] * v[2];
}

static void w2c(const double pos[3], float m[16])
{
    et_world_to_camera(R, pos, m);
}

/* The probe from pos: colour and radial depth (background where the room is not around). */
static void render_probe(const double pos[3], int w, int h, float *rgba, float *depth)
{
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            fx_vec3 dc = fx_pano_pixel_to_dir(x + 0.5f, y + 0.5f, w, h);
            double d[3], v[3] = { dc.x, dc.y, dc.z };
            rot(R, v, d);
            int wall;
            double t = box_exit(pos, d, &wall);
            size_t i = (size_t)y * w + x;
            int inside = pos[0] > LO[0] && pos[0] < HI[0] && pos[1] > LO[1] && pos[1] < HI[1] && pos[2] > LO[2] &&
                         pos[2] < HI[2];
            if (!inside || wall < 0) {
                depth[i] = 1e10f;
                rgba[i * 4] = rgba[i * 4 + 1] = rgba[i * 4 + 2] = 0.05f;
            } else {
                double p[3] = { pos[0] + t * d[0], pos[1] + t * d[1], pos[2] + t * d[2] };
                room_colour(p, wall, rgba + i * 4);
                depth[i] = (float)t;
            }
            rgba[i * 4 + 3] = 1;
        }
}

static void test_conventions(void)
{
    const int w = 256, h = 128;
    float px, py;
    fx_pano_dir_to_pixel(fx_v3(0, 0, -1), w, h, &px, &py); /* forward: the centre */
    CHECK(fabsf(px - 128) < 1e-3f && fabsf(py - 64) < 1e-3f);
    fx_pano_dir_to_pixel(fx_v3(1, 0, 0), w, h, &px, &py); /* right: three quarters across */
    CHECK(fabsf(px - 192) < 1e-3f && fabsf(py - 64) < 1e-3f);
    fx_pano_dir_to_pixel(fx_v3(-1, 0, 0), w, h, &px, &py);
    CHECK(fabsf(px - 64) < 1e-3f);
    fx_pano_dir_to_pixel(fx_v3(0, 1, 0), w, h, &px, &py); /* up: row 0 */
    CHECK(fabsf(py) < 1e-3f);
    fx_pano_dir_to_pixel(fx_v3(0, -1, 0), w, h, &px, &py);
    CHECK(fabsf(py - 128) < 1e-3f);
    fx_pano_dir_to_pixel(fx_v3(0, 0, 1), w, h, &px, &py); /* back: the seam */
    CHECK(fabsf(px) < 1e-3f || fabsf(px - 256) < 1e-3f);
    fx_pano_dir_to_pixel(fx_v3(0, 0, 0), w, h, &px, &py); /* degenerate: finite */
    CHECK(isfinite(px) && isfinite(py));
    fx_pano_dir_to_pixel(fx_v3(NAN, 0, 1), w, h, &px, &py);
    CHECK(isfinite(px) && isfinite(py));
    double worst = 0;
    for (int y = 0; y < h; y += 7)
        for (int x = 0; x < w; x += 5) {
            fx_vec3 d = fx_pano_pixel_to_dir(x + 0.5f, y + 0.5f, w, h);
            fx_pano_dir_to_pixel(d, w, h, &px, &py);
            double e = fmax(fabs(px - (x + 0.5)), fabs(py - (y + 0.5)));
            worst = e > worst ? e : worst;
            CHECK(fabsf(fx_v3_length(d) - 1) < 1e-5f);
        }
    printf("pixel -> direction -> pixel: worst %.2e px\n", worst);
    CHECK(worst < 1e-3);
}

/* The parallax-corrected lookup against the exact intersection. */
static void test_parallax(void)
{
    const int w = 512, h = 256;
    const double pos[3] = { 0.3, 1.9, 1.4 };
    float *rgba = malloc((size_t)w * h * 4 * sizeof(float)), *dep = malloc((size_t)w * h * sizeof(float));
    render_probe(pos, w, h, rgba, dep);
    fx_pano p = { rgba, dep, w, h, { 0 }, NULL };
    w2c(pos, p.to_probe);
    fx_pano_trace_settings st = fx_pano_trace_setup(64, 8, 0.02f, 100.0f, 0.35f);
    double err = 0, err_dir = 0;
    int n = 0, hits = 0;
    unsigned s = 12345;
    for (int k = 0; k < 2000; k++) {
        double v[6];
        for (int i = 0; i < 6; i++) {
            s = s * 1664525u + 1013904223u;
            v[i] = (s >> 8) / 16777216.0;
        }
        /* origins on and before the mirror wall y = 3, rays into the room */
        double o[3] = { -2.5 + 5 * v[0], 1.0 + 1.9 * v[1], 0.3 + 2.4 * v[2] };
        double th = acos(1 - 2 * v[3]), ph = 2 * PI * v[4];
        double d[3] = { sin(th) * cos(ph), -fabs(sin(th) * sin(ph)) - 0.05, cos(th) };
        double l = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        for (int i = 0; i < 3; i++)
            d[i] /= l;
        int wall;
        double t = box_exit(o, d, &wall);
        double q[3] = { o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2] };
        float want[3], got[3], dir_only[3];
        room_colour(q, wall, want);
        hits += fx_pano_trace(&p, &st, fx_v3((float)o[0], (float)o[1], (float)o[2]),
                              fx_v3((float)d[0], (float)d[1], (float)d[2]), got);
        fx_pano_color(&p, fx_m4_dir(p.to_probe, fx_v3((float)d[0], (float)d[1], (float)d[2])), dir_only);
        for (int c = 0; c < 3; c++) {
            err += fabs(got[c] - want[c]);
            err_dir += fabs(dir_only[c] - want[c]);
        }
        n += 3;
    }
    printf("probe lookup, 2000 rays in the room: MAE parallax-corrected %.4f (%d hits), direction only %.4f\n",
           err / n, hits, err_dir / n);
    CHECK(hits > 1900);
    CHECK(err / n < 0.02);
    CHECK(err / n < 0.25 * err_dir / n);
    /* a probe whose depth is all zero or all background: the direction lookup, finite */
    for (int mode = 0; mode < 3; mode++) {
        for (size_t i = 0; i < (size_t)w * h; i++)
            dep[i] = mode == 0 ? 0.0f : mode == 1 ? 1e10f : NAN;
        float got[3];
        fx_pano_trace(&p, &st, fx_v3(0, 2, 1), fx_v3(0, -1, 0), got);
        CHECK(isfinite(got[0]) && isfinite(got[1]) && isfinite(got[2]));
        fx_pano_trace(&p, &st, fx_v3(NAN, 2, 1), fx_v3(0, -1, 0), got);
        CHECK(isfinite(got[0]) && isfinite(got[1]) && isfinite(got[2]));
        fx_pano_trace(&p, &st, fx_v3(0, 2, 1), fx_v3(0, 0, 0), got);
        CHECK(isfinite(got[0]) && isfinite(got[1]) && isfinite(got[2]));
    }
    free(rgba), free(dep);
}

/* The march one step at a time, as fx_pano_trace did before it took four steps at once
 * (its lanes must give these bits: the same texel per step, the same crossing), with the
 * refined crossing test of issue 27 (a refined point further behind its texel's surface
 * than the thickness, the bracket and 4 texels' depth step is the ray passing behind an
 * occluder: no hit; the march goes on, and a ray still behind it at the march's end is
 * hidden from the probe: 2, its colour the disocclusion fill's, test_disocclusion). */
static int ref_in_front(const fx_pano *p, fx_vec3 q, float *gap)
{
    float dist = sqrtf(fx_v3_dot(q, q));
    float D = fx_pano_depth(p, q);
    *gap = dist - D;
    return !(dist >= D);
}

static int ref_trace(const fx_pano *p, const fx_pano_trace_settings *st, fx_vec3 o, fx_vec3 dir, float rgb[3])
{
    fx_vec3 po = fx_m4_point(p->to_probe, o);
    fx_vec3 pd = fx_m4_dir(p->to_probe, dir);
    if (!isfinite(po.x + po.y + po.z + pd.x + pd.y + pd.z)) {
        fx_pano_color(p, fx_v3(0.0f, 0.0f, -1.0f), rgb);
        return 0;
    }
    pd = fx_v3_normalize_or(pd, fx_v3(0.0f, 0.0f, -1.0f));
    float gap, prev_t = 0.0f, t = st->t0;
    int prev_front = ref_in_front(p, po, &gap);
    float t_hidden = prev_front ? -1.0f : 0.0f; /* an origin hidden from the probe: hidden until it comes out */
    const float texel = 2.0f * (float)PI / (float)(p->w > p->h ? p->w : 2 * p->h);
    for (int k = 0; k < st->steps; k++, t *= st->growth) {
        int front = ref_in_front(p, fx_v3_add(po, fx_v3_scale(pd, t)), &gap);
        if (prev_front && !front) {
            float lo = prev_t, hi = t, gm;
            for (int r = 0; r < st->refine; r++) {
                float mid = 0.5f * (lo + hi);
                if (ref_in_front(p, fx_v3_add(po, fx_v3_scale(pd, mid)), &gm))
                    lo = mid;
                else
                    hi = mid;
            }
            fx_vec3 q = fx_v3_add(po, fx_v3_scale(pd, hi));
            ref_in_front(p, q, &gm);
            float dist = sqrtf(fx_v3_dot(q, q));
            if (gm <= st->thickness + (hi - lo) + 4.0f * texel * (dist - gm)) {
                fx_pano_color(p, q, rgb);
                return 1;
            }
            t_hidden = lo; /* behind an occluder: its background texel, unless a later hit */
        }
        prev_front = front;
        prev_t = t;
        if (front)
            t_hidden = -1.0f; /* out in front again: the far lookup unless it goes behind again */
    }
    if (t_hidden >= 0.0f)
        return 2; /* hidden from the probe: the disocclusion fill's (test_disocclusion) */
    fx_pano_color(p, pd, rgb);
    return 0;
}

/* fx_pano_trace gives the one-step march's bits: rays from inside and outside the room,
 * along the axes and the poles (atan2's special cases), step counts not a multiple of
 * four, thin and thick surfaces, and a depth with holes (background and zero texels). */
static void test_trace_bits(void)
{
    const int w = 128, h = 64;
    const double pos[3] = { -0.4, 0.7, 1.2 };
    float *rgba = malloc((size_t)w * h * 4 * sizeof(float)), *dep = malloc((size_t)w * h * sizeof(float));
    render_probe(pos, w, h, rgba, dep);
    for (int i = 0; i < w * h; i += 37)
        dep[i] = i % 2 ? 1e10f : 0.0f;
    fx_pano p = { rgba, dep, w, h, { 0 }, NULL };
    w2c(pos, p.to_probe);
    static const int steps[] = { 1, 2, 3, 5, 48, 63 };
    static const float thick[] = { 0.0f, 0.05f, 2.0f };
    unsigned s = 777;
    int n = 0, same = 0, hits = 0, hidden = 0;
    for (int k = 0; k < 3000; k++) {
        float v[7];
        for (int i = 0; i < 7; i++) {
            s = s * 1664525u + 1013904223u;
            v[i] = (float)((s >> 8) / 16777216.0);
        }
        fx_vec3 o = fx_v3(-4.0f + 8.0f * v[0], -4.0f + 8.0f * v[1], -1.0f + 5.0f * v[2]);
        fx_vec3 d = fx_v3(v[3] - 0.5f, v[4] - 0.5f, v[5] - 0.5f);
        if (k % 10 == 0) /* along an axis, through the probe's centre, or zero */
            d = k % 40 == 0 ? fx_v3(0, 0, v[3] - 0.5f) : k % 40 == 10 ? fx_v3(v[3] - 0.5f, 0, 0)
                : k % 40 == 20 ? fx_v3(0, v[3] - 0.5f, 0) : fx_v3(0, 0, 0);
        if (k % 7 == 0)
            o = fx_v3((float)pos[0], (float)pos[1], (float)pos[2]);
        fx_pano_trace_settings st =
            fx_pano_trace_setup(steps[k % 6], k % 9, 0.02f, k % 5 == 0 ? 3.0f : 100.0f, thick[k % 3]);
        float a[3], b[3];
        int ha = fx_pano_trace(&p, &st, o, d, a), hb = ref_trace(&p, &st, o, d, b);
        if (hb == 2) { /* hidden: the same march outcome (no hit, no distance), a finite fill */
            same += ha == 0 && isinf(fx_pano_trace_dist(&p, &st, o, d)) && isfinite(a[0] + a[1] + a[2]);
            hidden++;
        } else {
            same += ha == hb && memcmp(a, b, sizeof a) == 0;
        }
        hits += ha;
        n++;
    }
    printf("probe march, %d rays: %d with the one-step march's bits or outcome (%d hits, %d hidden)\n", n, same,
           hits, hidden);
    CHECK(same == n);
    CHECK(hits > 300);
    free(rgba), free(dep);
}

/* ---- the disocclusion fill (issue 27) ----
 * A probe 1 m above an endless grey floor (0.5) with a yellow ball between it and the
 * floor (centre 0.55 m down, 1 m ahead, r 0.3), the sky above; colour supersampled 4x4 per
 * texel (anti-aliased, as Cycles renders it), depth at the texel's centre (not). Mirror
 * rays from a point off to the side land on the floor where the ball hides it from the
 * probe: the probe cannot see what they meet. The truth there is the floor's grey. Before,
 * such a ray took the one texel beside the ball's silhouette where it disappeared from the
 * probe, and neighbouring rays drew out the silhouette's texels (the ball's anti-aliased
 * yellow) into streaks: mean 0.054 off the grey, worst channel 0.125. The fill is the
 * background around the hidden point, wide and depth-tested: mean 0.0024, worst 0.059 (an
 * anti-aliased silhouette texel among its samples). Checked: mean under 0.01, every ray and
 * every step between neighbouring rays under 0.1. */
static const double BALL[3] = { 0.0, -0.55, -1.0 }, BALL_R = 0.3;

/* t of the ray o + t d (d unit) entering the ball, or -1 */
static double ball_hit(const double o[3], const double d[3])
{
    double oc[3] = { o[0] - BALL[0], o[1] - BALL[1], o[2] - BALL[2] };
    double b = oc[0] * d[0] + oc[1] * d[1] + oc[2] * d[2];
    double c = oc[0] * oc[0] + oc[1] * oc[1] + oc[2] * oc[2] - BALL_R * BALL_R;
    double disc = b * b - c;
    if (disc < 0)
        return -1;
    double t = -b - sqrt(disc);
    return t > 0 ? t : -1;
}

static void ball_scene(const double d[3], float c[3], float *depth)
{
    static const double o[3] = { 0, 0, 0 };
    double tb = ball_hit(o, d);
    if (tb > 0) {
        c[0] = 1.0f, c[1] = 0.9f, c[2] = 0.2f;
        *depth = (float)tb;
    } else if (d[1] < -1e-6) {
        c[0] = c[1] = c[2] = 0.5f;
        *depth = (float)(-1.0 / d[1]); /* radial distance to the floor y = -1 */
    } else {
        c[0] = 0.3f, c[1] = 0.4f, c[2] = 0.8f;
        *depth = 1e10f; /* the sky */
    }
}

static void test_disocclusion(void)
{
    const int w = 256, h = 128, ss = 4;
    float *rgba = calloc((size_t)w * h * 4, sizeof(float)), *dep = calloc((size_t)w * h, sizeof(float));
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            float acc[3] = { 0, 0, 0 }, c[3], dd;
            for (int sy = 0; sy < ss; sy++)
                for (int sx = 0; sx < ss; sx++) {
                    fx_vec3 v = fx_pano_pixel_to_dir(x + (sx + 0.5f) / ss, y + (sy + 0.5f) / ss, w, h);
                    double d[3] = { v.x, v.y, v.z };
                    ball_scene(d, c, &dd);
                    for (int k = 0; k < 3; k++)
                        acc[k] += c[k] / (ss * ss);
                }
            fx_vec3 v = fx_pano_pixel_to_dir(x + 0.5f, y + 0.5f, w, h);
            double d[3] = { v.x, v.y, v.z };
            ball_scene(d, c, &dd);
            memcpy(rgba + ((size_t)y * w + x) * 4, acc, sizeof acc);
            rgba[((size_t)y * w + x) * 4 + 3] = 1.0f;
            dep[(size_t)y * w + x] = dd;
        }
    fx_pano p = { rgba, dep, w, h, { 0 }, NULL };
    for (int i = 0; i < 16; i++)
        p.to_probe[i] = i % 5 == 0 ? 1.0f : 0.0f; /* the caller's space is the probe's */
    fx_pano_trace_settings st = fx_pano_trace_setup(48, 6, 0.02f, 100.0f, 0.05f); /* final's */
    const double o[3] = { 1.2, -0.6, -1.8 };
    enum { N = 24 };
    static float col[N][N][3];
    static int hid[N][N];
    int n = 0, hidden = 0;
    double worst = 0, worst_step = 0, mean = 0;
    for (int j = 0; j < N; j++)
        for (int i = 0; i < N; i++) {
            /* floor points behind the ball (seen from the probe) */
            double tgt[3] = { -0.2 + 0.4 * i / (N - 1), -1.0, -1.65 - 0.45 * j / (N - 1) };
            double l = sqrt(tgt[0] * tgt[0] + 1.0 + tgt[2] * tgt[2]);
            double pd[3] = { tgt[0] / l, -1.0 / l, tgt[2] / l };
            double rd[3] = { tgt[0] - o[0], tgt[1] - o[1], tgt[2] - o[2] };
            double rl = sqrt(rd[0] * rd[0] + rd[1] * rd[1] + rd[2] * rd[2]);
            for (int k = 0; k < 3; k++)
                rd[k] /= rl;
            static const double z[3] = { 0, 0, 0 };
            hid[j][i] = ball_hit(z, pd) > 0 && ball_hit(o, rd) < 0; /* hidden from the probe, seen by the ray */
            if (!hid[j][i])
                continue;
            n++;
            fx_vec3 ro = fx_v3((float)o[0], (float)o[1], (float)o[2]);
            fx_vec3 dir = fx_v3((float)rd[0], (float)rd[1], (float)rd[2]);
            int hit = fx_pano_trace(&p, &st, ro, dir, col[j][i]);
            hidden += hit == 0 && isinf(fx_pano_trace_dist(&p, &st, ro, dir));
            for (int k = 0; k < 3; k++) {
                worst = fmax(worst, fabs(col[j][i][k] - 0.5));
                mean += fabs(col[j][i][k] - 0.5) / 3;
            }
        }
    for (int j = 0; j < N; j++)
        for (int i = 0; i + 1 < N; i++)
            if (hid[j][i] && hid[j][i + 1])
                for (int k = 0; k < 3; k++) {
                    worst_step = fmax(worst_step, fabs(col[j][i + 1][k] - col[j][i][k]));
                    if (j + 1 < N && hid[j + 1][i])
                        worst_step = fmax(worst_step, fabs(col[j + 1][i][k] - col[j][i][k]));
                }
    mean /= n > 0 ? n : 1;
    printf("disocclusion: %d rays meet the floor behind the ball (%d hidden from the probe's march): "
           "mean %.4f, worst channel %.3f off the floor's grey, worst step between neighbours %.3f\n", n, hidden,
           mean, worst, worst_step);
    /* rays that start hidden from the probe (just above the floor behind the ball) and stay
     * hidden down to the floor: before, the march saw no crossing and took the far lookup,
     * the probe's colour along the ray's direction (the ball: up to 0.5 off the floor's
     * grey); now the same fill */
    double worst0 = 0;
    int n0 = 0;
    const double bd = sqrt(0.55 * 0.55 + 1.0);
    for (int j = 0; j < 5; j++)
        for (int i = 0; i < 5; i++) {
            double o2[3] = { -0.1 + 0.05 * i, -0.95, -1.9 - 0.05 * j }, z[3] = { 0, 0, 0 };
            double l = sqrt(o2[0] * o2[0] + o2[1] * o2[1] + o2[2] * o2[2]);
            double od[3] = { o2[0] / l, o2[1] / l, o2[2] / l };
            if (!(ball_hit(z, od) > 0))
                continue;
            float c2[3];
            fx_pano_trace(&p, &st, fx_v3((float)o2[0], (float)o2[1], (float)o2[2]),
                          fx_v3(0.0f, (float)(-0.55 / bd), (float)(-1.0 / bd)), c2);
            for (int k = 0; k < 3; k++)
                worst0 = fmax(worst0, fabs(c2[k] - 0.5));
            n0++;
        }
    printf("disocclusion from a hidden origin: %d rays, worst channel %.3f off the floor's grey\n", n0, worst0);
    CHECK(n0 > 10);
    CHECK(worst0 < 0.1);
    CHECK(n > 100);
    CHECK(hidden == n); /* the case under test: the march finds them hidden */
    CHECK(mean < 0.01);
    CHECK(worst < 0.1);
    CHECK(worst_step < 0.1);
    free(rgba), free(dep);
}

/* The sky behind a wall: a wall 4 m ahead of the probe, 1.5 m high, hides the sky below
 * 20.6 deg from it. A ray from 1 m higher and 3 m nearer the wall, rising at 15 deg,
 * passes over the wall into the sky; beyond the wall the probe sees its points behind the
 * wall to the end (they stay below 20.6 deg). The ray meets the sky at 15 deg, which the
 * probe cannot show: with the world image (fx_pano.sky) the fill is that sky exactly;
 * without it, the sky nearest the silhouette, higher and darker. */
static void wall_sky_scene(fx_vec3 d, float c[3], float *depth, int world_only)
{
    float len = sqrtf(fx_v3_dot(d, d));
    float up = d.y / len; /* the sky: a gradient with elevation */
    c[0] = 0.8f - 0.6f * up, c[1] = 0.85f - 0.45f * up, c[2] = 1.0f;
    *depth = 1e10f;
    if (!world_only && d.z < 0.0f) {
        float t = -4.0f / (d.z / len); /* radial distance to the plane z = -4 */
        if (t * up < 1.5f)
            c[0] = c[1] = c[2] = 0.3f, *depth = t;
    }
}

static void test_sky_behind_wall(void)
{
    const int w = 512, h = 256;
    float *rgba = malloc((size_t)w * h * 4 * sizeof(float)), *sky = malloc((size_t)w * h * 4 * sizeof(float));
    float *dep = malloc((size_t)w * h * sizeof(float)), dd;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            fx_vec3 d = fx_pano_pixel_to_dir(x + 0.5f, y + 0.5f, w, h);
            wall_sky_scene(d, rgba + i * 4, dep + i, 0);
            wall_sky_scene(d, sky + i * 4, &dd, 1);
            rgba[i * 4 + 3] = sky[i * 4 + 3] = 1.0f;
        }
    fx_pano p = { rgba, dep, w, h, { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 }, NULL };
    fx_pano_trace_settings st = fx_pano_trace_setup(48, 6, 0.02f, 100.0f, 0.05f);
    double worst[2] = { 0, 0 };
    int n = 0;
    for (int k = -4; k <= 4; k++) {
        float az = 0.05f * (float)k, el = 15.0f * (float)PI / 180.0f;
        fx_vec3 dir = fx_v3(sinf(az) * cosf(el), sinf(el), -cosf(az) * cosf(el)), o = fx_v3(0.0f, 1.0f, -1.0f);
        float want[3], got[2][3];
        wall_sky_scene(dir, want, &dd, 1);
        for (int with = 0; with < 2; with++) {
            p.sky = with ? sky : NULL;
            CHECK(fx_pano_trace(&p, &st, o, dir, got[with]) == 0);
            for (int c = 0; c < 3; c++)
                worst[with] = fmax(worst[with], fabs(got[with][c] - want[c]));
        }
        n++;
    }
    printf("sky behind a wall the ray passed over (%d rays): worst channel off the sky at the ray's direction: "
           "without the world image %.3f, with it %.4f\n", n, worst[0], worst[1]);
    CHECK(worst[1] < 0.005);
    CHECK(worst[0] > 0.02); /* the case under test: the probe alone cannot show that sky */
    free(rgba), free(sky), free(dep);
}

/* ---- end to end ---- */

static const double CAM[3] = { 0.0, -1.5, 1.5 };
enum { FW = 96, FH = 54 };

static void cam_dir(double px, double py, double d[3])
{
    double fy = tan(30 * PI / 180), asp = (double)FW / FH;
    double v[3] = { (px / FW * 2 - 1) * fy * asp, (1 - py / FH * 2) * fy, -1 }, r[3];
    rot(R, v, r);
    double l = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
    for (int i = 0; i < 3; i++)
        d[i] = r[i] / l;
}

/* The room seen from CAM; the +Y wall (y = 3) is the mirror (IndexMA 1, grey 0.1).
 * want: the exact reflection on mirror pixels. */
static fx_frame *room_frame(fx_context *ctx, float *want)
{
    size_t n = (size_t)FW * FH;
    float *rgba = calloc(n * 4, sizeof(float)), *dep = calloc(n, sizeof(float));
    float *nor = calloc(n * 3, sizeof(float)), *ima = calloc(n, sizeof(float));
    for (int y = 0; y < FH; y++)
        for (int x = 0; x < FW; x++) {
            size_t i = (size_t)y * FW + x;
            double d[3];
            cam_dir(x + 0.5, y + 0.5, d);
            int wall;
            double t = box_exit(CAM, d, &wall);
            double p[3] = { CAM[0] + t * d[0], CAM[1] + t * d[1], CAM[2] + t * d[2] };
            dep[i] = (float)(p[1] - CAM[1]); /* planar: the camera looks along +Y */
            nor[i * 3 + wall / 2] = wall % 2 ? -1.0f : 1.0f;
            rgba[i * 4 + 3] = 1;
            if (wall == 3) {
                ima[i] = 1;
                rgba[i * 4] = rgba[i * 4 + 1] = rgba[i * 4 + 2] = 0.1f;
                double r[3] = { d[0], -d[1], d[2] };
                int w2;
                double t2 = box_exit(p, r, &w2);
                double q[3] = { p[0] + t2 * r[0], p[1] + t2 * r[1], p[2] + t2 * r[2] };
                room_colour(q, w2, want + i * 3);
            } else if (!g_stripes) {
                room_colour(p, wall, rgba + i * 4);
            } else { /* stripes: the pixel's mean over 8 x 8 rays, as a renderer's pixel filter */
                for (int sy = 0; sy < 8; sy++)
                    for (int sx = 0; sx < 8; sx++) {
                        double ds[3], col3[3];
                        float col[3];
                        int ws;
                        cam_dir(x + (sx + 0.5) / 8, y + (sy + 0.5) / 8, ds);
                        double ts = box_exit(CAM, ds, &ws);
                        for (int k = 0; k < 3; k++)
                            col3[k] = CAM[k] + ts * ds[k];
                        room_colour(col3, ws, col);
                        for (int k = 0; k < 3; k++)
                            rgba[i * 4 + k] += col[k] / 64.0f;
                    }
            }
        }
    fx_frame *f = et_frame(ctx, FW, FH, rgba);
    fx_camera c;
    float cw[16];
    w2c(CAM, cw);
    et_perspective(&c, cw, tan(30 * PI / 180), FW, FH, 0.1, 100.0);
    fx_frame_add_pass(f, "Depth", 1, dep);
    fx_frame_add_pass(f, "Normal", 3, nor);
    fx_frame_add_pass(f, "IndexMA", 1, ima);
    fx_frame_set_camera(f, &c);
    free(rgba), free(dep), free(nor), free(ima);
    return f;
}

/* Writes a probe EXR from pos (w x h; mode 1: zero depth, 2: NaN/Inf colour and depth). */
static void write_probe(fx_context *ctx, const char *path, const double pos[3], int w, int h, int mode)
{
    float *rgba = malloc((size_t)w * h * 4 * sizeof(float)), *dep = malloc((size_t)w * h * sizeof(float));
    render_probe(pos, w, h, rgba, dep);
    for (size_t i = 0; mode && i < (size_t)w * h; i++) {
        dep[i] = mode == 1 ? 0.0f : i % 3 == 0 ? NAN : i % 3 == 1 ? INFINITY : -INFINITY;
        if (mode == 2)
            rgba[i * 4 + i % 3] = i % 2 ? NAN : INFINITY;
    }
    et_write_view(ctx, path, w, h, rgba, dep);
    free(rgba), free(dep);
}

static void add_probe(fx_context *ctx, fx_frame *f, const char *name, const char *path, const double pos[3])
{
    float m[16];
    w2c(pos, m);
    et_add_probe(ctx, f, name, path, m);
}

/* The probe the end-to-end tests attach: beside the mirror, 0.4 m in front of it. */
static const double PROBE_POS[3] = { 0.0, 2.6, 1.5 };

/* Writes that probe (w x h) as dir/probe.exr; its path into path (600 bytes). */
static void write_room_probe(fx_context *ctx, const char *dir, int w, int h, char path[600])
{
    snprintf(path, 600, "%s/probe.exr", dir);
    write_probe(ctx, path, PROBE_POS, w, h, 0);
}

static int has_pass(const fx_frame *f, const char *name)
{
    float *d;
    int c;
    return fx_frame_pass(f, name, &d, &c) == FX_OK;
}

static double mirror_mae(const fx_frame *in, const fx_frame *out, const float *want)
{
    float *ima, *o;
    int c;
    fx_frame_pass(in, "IndexMA", &ima, &c);
    fx_frame_pass(out, "Combined", &o, &c);
    double e = 0;
    int n = 0;
    for (size_t i = 0; i < (size_t)FW * FH; i++)
        if (ima[i] == 1) {
            for (int k = 0; k < 3; k++)
                e += fabs(o[i * 4 + k] - want[i * 3 + k]);
            n += 3;
        }
    return n ? e / n : 1e9;
}

static void test_end_to_end(fx_context *ctx)
{
    const char *dir = tu_tmpdir("probe");
    float *want = calloc((size_t)FW * FH * 3, sizeof(float));
    fx_frame *f = room_frame(ctx, want);
    fx_stack *s = et_stack(ctx, "ssr_mirror");
    CHECK_OK(ctx, fx_stack_set_mask_json(s, 0, "{\"material_index\": 1}"));
    fx_stack_set_debug_outputs(s, 1);
    /* the stack asks for the probe with the mask (final: fallback probe) */
    char *req = NULL;
    CHECK_OK(ctx, fx_stack_required_aux_views(s, &req));
    cJSON *rj = cJSON_Parse(req);
    const cJSON *v0 = cJSON_GetArrayItem(cJSON_GetObjectItem(rj, "aux_views"), 0);
    const cJSON *name = cJSON_GetObjectItem(v0, "name"), *mask = cJSON_GetObjectItem(v0, "mask");
    CHECK(cJSON_IsString(name) && strncmp(name->valuestring, "probe:", 6) == 0 && strlen(name->valuestring) == 18);
    CHECK(cJSON_IsString(cJSON_GetObjectItem(v0, "kind")) &&
          strcmp(cJSON_GetObjectItem(v0, "kind")->valuestring, "probe") == 0);
    CHECK(cJSON_IsObject(mask) && cJSON_GetObjectItem(mask, "material_index"));
    printf("required: %s\n", req);
    char pname[64];
    snprintf(pname, sizeof pname, "%s", cJSON_IsString(name) ? name->valuestring : "probe:?");
    cJSON_Delete(rj);
    fx_free(req);
    /* draft and preview: screen space only, no probe asked */
    CHECK_OK(ctx, fx_stack_set_quality(s, FX_QUALITY_PREVIEW));
    CHECK_OK(ctx, fx_stack_required_aux_views(s, &req));
    CHECK(req && strcmp(req, "{\"aux_views\":[]}") == 0);
    fx_free(req);

    /* without the probe (texture fallback at preview; final warns and takes the texture) */
    fx_frame *o_tex = NULL, *o_missing = NULL, *o_probe = NULL;
    CHECK_OK(ctx, fx_stack_set_quality(s, FX_QUALITY_FINAL));
    fx_stack *st = et_stack(ctx, "ssr_mirror");
    CHECK_OK(ctx, fx_stack_set_mask_json(st, 0, "{\"material_index\": 1}"));
    CHECK_OK(ctx, fx_stack_set_enum(st, 0, "fallback", "texture"));
    CHECK_OK(ctx, fx_stack_run(st, f, &o_tex));
    fx_stack_free(st);
    fx_context_clear_warnings(ctx);
    CHECK_OK(ctx, fx_stack_run(s, f, &o_missing));
    int warned = 0;
    for (int k = 0; k < fx_context_warning_count(ctx); k++)
        warned |= tu_contains(fx_context_warning(ctx, k), "no reflection probe");
    CHECK(warned);
    CHECK(has_pass(o_missing, "fx0_ssr_mirror_fallback_texture"));
    CHECK(!has_pass(o_missing, "fx0_ssr_mirror_fallback_probe"));
    const float *a = et_combined(o_tex), *b = et_combined(o_missing);
    CHECK(a && b && memcmp(a, b, (size_t)FW * FH * 4 * sizeof(float)) == 0);

    /* with the probe beside the mirror */
    char path[600];
    write_room_probe(ctx, dir, 256, 128, path);
    add_probe(ctx, f, pname, path, PROBE_POS);
    fx_context_clear_warnings(ctx);
    CHECK_OK(ctx, fx_stack_run(s, f, &o_probe));
    /* the only warning left: final's planar view, which this frame has not (the probe serves) */
    int others = 0;
    for (int k = 0; k < fx_context_warning_count(ctx); k++)
        others += !tu_contains(fx_context_warning(ctx, k), "no planar mirror view");
    CHECK(others == 0);
    CHECK(has_pass(o_probe, "fx0_ssr_mirror_fallback_probe"));
    double e_tex = mirror_mae(f, o_tex, want), e_probe = mirror_mae(f, o_probe, want);
    printf("mirror facing the camera, MAE against the exact reflection: texture fallback %.4f, probe %.4f\n",
           e_tex, e_probe);
    CHECK(e_probe < 0.04);
    CHECK(e_probe < 0.2 * e_tex);
    /* thread count: the same bits */
    fx_context *ctx1 = NULL;
    fx_context_new(&ctx1, 1);
    fx_stack *s1 = et_stack(ctx1, "ssr_mirror");
    CHECK_OK(ctx1, fx_stack_set_mask_json(s1, 0, "{\"material_index\": 1}"));
    fx_frame *o1 = NULL;
    CHECK_OK(ctx1, fx_stack_run(s1, f, &o1));
    const float *c1 = et_combined(o1), *c2 = et_combined(o_probe);
    CHECK(c1 && c2 && memcmp(c1, c2, (size_t)FW * FH * 4 * sizeof(float)) == 0);
    fx_frame_free(o1);
    fx_stack_free(s1);
    fx_context_free(ctx1);

    /* degenerate probes: finite output, no failure */
    struct { int w, h, mode; double pos[3]; const char *what; } bad[] = {
        { 64, 32, 1, { 0.0, 2.6, 1.5 }, "zero depth" },
        { 64, 32, 2, { 0.0, 2.6, 1.5 }, "NaN/Inf colour and depth" },
        { 1, 1, 0, { 0.0, 2.6, 1.5 }, "1 x 1" },
        { 64, 32, 0, { 0.0, 3.5, 1.5 }, "behind the mirror, outside the room" },
        { 64, 32, 0, { 0.0, 3.0, 1.5 }, "on the mirror's plane" },
    };
    for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
        snprintf(path, sizeof path, "%s/bad%d.exr", dir, (int)k);
        write_probe(ctx, path, bad[k].pos, bad[k].w, bad[k].h, bad[k].mode);
        add_probe(ctx, f, pname, path, bad[k].pos);
        fx_frame *o = NULL;
        fx_context_clear_warnings(ctx);
        CHECK_OK(ctx, fx_stack_run(s, f, &o));
        const float *c = et_combined(o);
        CHECK(c && tu_all_finite(c, (size_t)FW * FH * 4));
        /* the stack's NaN guard must not have had anything to replace */
        int guard = 0;
        for (int i = 0; i < fx_context_warning_count(ctx); i++)
            guard |= tu_contains(fx_context_warning(ctx, i), "non-finite");
        CHECK(!guard);
        printf("probe %s: finite, MAE %.4f\n", bad[k].what, mirror_mae(f, o, want));
        fx_frame_free(o);
    }
    /* a view of that name that is not a panorama: a warning and the texture */
    fx_frame_free(o_tex), fx_frame_free(o_missing), fx_frame_free(o_probe);
    fx_stack_free(s);
    fx_frame_free(f);
    free(want);
}

/* ---- planar view ---- */

/* The planar view: the room seen from CAM mirrored in y = 3 (E' = (0, 7.5, 1.5)) looking
 * along -Y, up +Z, through the (hidden) mirror wall; the same projection as the frame. */
static const double RP[9] = { -1, 0, 0, 0, 0, 1, 0, 1, 0 }; /* columns x -> -X, y -> +Z, z -> +Y */

static void write_planar(fx_context *ctx, const char *path, float w2c_out[16], float proj[16])
{
    const double e[3] = { CAM[0], 6.0 - CAM[1], CAM[2] };
    size_t n = (size_t)FW * FH;
    float *rgba = calloc(n * 4, sizeof(float)), *dep = calloc(n, sizeof(float));
    double fy = tan(30 * PI / 180), asp = (double)FW / FH;
    for (int y = 0; y < FH; y++)
        for (int x = 0; x < FW; x++) {
            size_t i = (size_t)y * FW + x;
            double v[3] = { ((x + 0.5) / FW * 2 - 1) * fy * asp, (1 - (y + 0.5) / FH * 2) * fy, -1 }, d[3];
            rot(RP, v, d);
            rgba[i * 4 + 3] = 1;
            dep[i] = 1e10f;
            if (!(d[1] < -1e-9))
                continue;
            double t0 = (3.0 - e[1]) / d[1]; /* enters the room through the mirror wall */
            double p0[3] = { e[0] + t0 * d[0], e[1] + t0 * d[1], e[2] + t0 * d[2] };
            if (p0[0] <= LO[0] || p0[0] >= HI[0] || p0[2] <= LO[2] || p0[2] >= HI[2])
                continue;
            int wall;
            double t = box_exit(p0, d, &wall);
            double q[3] = { p0[0] + t * d[0], p0[1] + t * d[1], p0[2] + t * d[2] };
            room_colour(q, wall, rgba + i * 4);
            dep[i] = (float)(t0 + t); /* planar depth: d = R v is v rotated, v.z = -1 */
        }
    et_write_view(ctx, path, FW, FH, rgba, dep);
    free(rgba), free(dep);
    memset(w2c_out, 0, 16 * sizeof(float));
    for (int i = 0; i < 3; i++) {
        double tt = 0;
        for (int k = 0; k < 3; k++) {
            w2c_out[i * 4 + k] = (float)RP[k * 3 + i];
            tt -= RP[k * 3 + i] * e[k];
        }
        w2c_out[i * 4 + 3] = (float)tt;
    }
    w2c_out[15] = 1;
    double nn = 0.1, ff = 100.0, f1 = 1.0 / fy;
    memset(proj, 0, 16 * sizeof(float));
    proj[0] = (float)(f1 / asp);
    proj[5] = (float)f1;
    proj[10] = (float)((ff + nn) / (nn - ff));
    proj[11] = (float)(2 * ff * nn / (nn - ff));
    proj[14] = -1;
}

static void add_planar(fx_context *ctx, fx_frame *f, const char *name, const char *path, const float m[16],
                       const float pr[16], const char *plane)
{
    char json[8192];
    int n = snprintf(json, sizeof json, "{\"aux_views\": [{\"name\": \"%s\", \"path\": \"%s\", \"world_to_camera\": [",
                     name, path);
    for (int i = 0; i < 16; i++)
        n += snprintf(json + n, sizeof json - n, "%s%.9g", i ? ", " : "", m[i]);
    n += snprintf(json + n, sizeof json - n, "], \"projection\": [");
    for (int i = 0; i < 16; i++)
        n += snprintf(json + n, sizeof json - n, "%s%.9g", i ? ", " : "", pr[i]);
    snprintf(json + n, sizeof json - n,
             "], \"clip_start\": 0.1, \"clip_end\": 100, \"kind\": \"planar\", \"plane\": %s}]}", plane);
    CHECK_OK(ctx, fx_frame_apply_sidecar(f, json));
}

static void test_planar(fx_context *ctx)
{
    const char *dir = tu_tmpdir("planar");
    float *want = calloc((size_t)FW * FH * 3, sizeof(float));
    fx_frame *f = room_frame(ctx, want);
    fx_stack *s = et_stack(ctx, "ssr_mirror");
    CHECK_OK(ctx, fx_stack_set_mask_json(s, 0, "{\"material_index\": 1}"));
    CHECK_OK(ctx, fx_stack_set_quality(s, FX_QUALITY_REFERENCE));
    fx_stack_set_debug_outputs(s, 1);
    char *req = NULL;
    CHECK_OK(ctx, fx_stack_required_aux_views(s, &req));
    printf("required at reference: %s\n", req);
    CHECK(req && tu_contains(req, "\"planar:") && tu_contains(req, "\"probe:") && tu_contains(req, "\"kind\":\"planar\""));
    char pname[64] = "planar:?";
    const char *at = req ? strstr(req, "\"planar:") : NULL;
    if (at)
        snprintf(pname, 20, "%s", at + 1); /* "planar:" and 12 hex digits */
    fx_free(req);
    /* without it: a warning, the trace (no probe here either) */
    fx_frame *o0 = NULL;
    fx_context_clear_warnings(ctx);
    CHECK_OK(ctx, fx_stack_run(s, f, &o0));
    int warned = 0;
    for (int k = 0; k < fx_context_warning_count(ctx); k++)
        warned |= tu_contains(fx_context_warning(ctx, k), "no planar mirror view");
    CHECK(warned);
    char path[600];
    snprintf(path, sizeof path, "%s/planar.exr", dir);
    float m[16], pr[16];
    write_planar(ctx, path, m, pr);
    add_planar(ctx, f, pname, path, m, pr, "[0, -1, 0, -3]");
    fx_frame *o1 = NULL;
    fx_context_clear_warnings(ctx);
    CHECK_OK(ctx, fx_stack_run(s, f, &o1));
    float *pl = NULL;
    int c;
    CHECK(fx_frame_pass(o1, "fx0_ssr_mirror_planar", &pl, &c) == FX_OK);
    float *ima;
    fx_frame_pass(f, "IndexMA", &ima, &c);
    int used = 0, mirror = 0;
    for (size_t i = 0; pl && i < (size_t)FW * FH; i++) {
        mirror += ima[i] == 1;
        used += pl[i] > 0.5f;
    }
    double e0 = mirror_mae(f, o0, want), e1 = mirror_mae(f, o1, want);
    printf("planar view: %d of %d mirror pixels, MAE against the exact reflection %.4f (trace only: %.4f)\n", used,
           mirror, e1, e0);
    CHECK(used > 0.97 * mirror);
    CHECK(e1 < 0.01 && e1 < 0.25 * e0);
    /* a view whose plane is another one (x = 0): not used, the same bits as without it */
    fx_frame_free(o1);
    o1 = NULL;
    add_planar(ctx, f, pname, path, m, pr, "[1, 0, 0, 0]");
    CHECK_OK(ctx, fx_stack_run(s, f, &o1));
    const float *a = et_combined(o0), *b = et_combined(o1);
    CHECK(a && b && memcmp(a, b, (size_t)FW * FH * 4 * sizeof(float)) == 0);
    /* a degenerate plane (zero normal), a malformed one: refused or unused, never NaN */
    add_planar(ctx, f, pname, path, m, pr, "[0, 0, 0, 1]");
    fx_frame_free(o1);
    o1 = NULL;
    CHECK_OK(ctx, fx_stack_run(s, f, &o1));
    CHECK(tu_all_finite(et_combined(o1), (size_t)FW * FH * 4));
    CHECK(fx_frame_apply_sidecar(f, "{\"aux_views\": [{\"name\": \"planar:x\", \"path\": \"/p\", "
                                    "\"world_to_camera\": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1], "
                                    "\"projection\": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1], \"clip_start\": 0, "
                                    "\"clip_end\": 1, \"plane\": [0, 1, \"a\", 0]}]}") == FX_ERR_BAD_RECIPE);
    fx_frame_free(o0), fx_frame_free(o1);
    fx_stack_free(s);
    fx_frame_free(f);
    free(want);
}

/* ---- footprints (ray differentials) ---- */

/* fx_pano_trace_footprint: no footprint is fx_pano_trace's one tap, bit for bit; a footprint
 * over many texels of 1-texel stripes is their mean (what the pixel sees), where one tap is
 * a stripe's own 0 or 1; at a hit, the footprint grows with the distance. */
static void test_pano_footprint(void)
{
    const int w = 256, h = 128;
    float *rgba = malloc((size_t)w * h * 4 * sizeof(float)), *dep = malloc((size_t)w * h * sizeof(float));
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            rgba[i * 4] = rgba[i * 4 + 1] = rgba[i * 4 + 2] = (float)(x % 2);
            rgba[i * 4 + 3] = 1.0f;
            dep[i] = x < w / 2 ? 1e10f : 2.0f; /* the sky left of forward, a 2 m sphere right */
        }
    fx_pano p = { rgba, dep, w, h, { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 }, NULL };
    fx_pano_trace_settings st = fx_pano_trace_setup(48, 6, 0.02f, 100.0f, 0.05f);
    const float texel = 2.0f * (float)PI / (float)w;
    /* the sky, 21 texels (~30 deg) left of forward, at a texel's centre */
    fx_vec3 dir = fx_pano_pixel_to_dir((float)(w / 2 - 21) + 0.5f, (float)(h / 2) + 0.5f, w, h);
    fx_vec3 o = fx_v3(0, 0, 0), side = fx_v3_normalize_or(fx_v3_cross(dir, fx_v3(0, 1, 0)), fx_v3(1, 0, 0));
    fx_ray_diff none, wide;
    memset(&none, 0, sizeof none);
    memset(&wide, 0, sizeof wide);
    wide.ddx = fx_v3_scale(side, 6.0f * texel); /* 6 texels across */
    float a[3], b[3], c[3];
    int ha = fx_pano_trace(&p, &st, o, dir, a), hb = fx_pano_trace_footprint(&p, &st, o, dir, &none, b);
    CHECK(ha == hb && memcmp(a, b, sizeof a) == 0);
    fx_pano_trace_footprint(&p, &st, o, dir, &wide, c);
    printf("far lookup over 1-texel stripes: one tap %.3f, a 6-texel footprint %.3f (their mean 0.5)\n", a[0], c[0]);
    CHECK(fabsf(a[0] - 0.5f) > 0.4f);
    CHECK(fabsf(c[0] - 0.5f) < 0.1f);
    /* a hit on the 2 m sphere, 30 deg right: the footprint at t spans dox + t ddx; a small
     * origin spread with no direction spread stays within a texel (one tap, the same bits) */
    dir = fx_pano_pixel_to_dir((float)(w / 2 + 21) + 0.5f, (float)(h / 2) + 0.5f, w, h);
    side = fx_v3_normalize_or(fx_v3_cross(dir, fx_v3(0, 1, 0)), fx_v3(1, 0, 0));
    fx_ray_diff small = none;
    small.dox = fx_v3_scale(side, 0.2f * texel * 2.0f);
    ha = fx_pano_trace(&p, &st, o, dir, a);
    hb = fx_pano_trace_footprint(&p, &st, o, dir, &small, b);
    CHECK(ha == 1 && hb == 1 && memcmp(a, b, sizeof a) == 0);
    wide.ddx = fx_v3_scale(side, 6.0f * texel); /* seen from the probe's centre: 6 texels at any t */
    fx_pano_trace_footprint(&p, &st, o, dir, &wide, c);
    printf("hit at 2 m over 1-texel stripes: one tap %.3f, a footprint of 6 texels there %.3f\n", a[0], c[0]);
    CHECK(fabsf(a[0] - 0.5f) > 0.4f && fabsf(c[0] - 0.5f) < 0.1f);
    /* a non-finite differential: finite, one tap */
    wide.ddx = fx_v3(NAN, INFINITY, 0);
    fx_pano_trace_footprint(&p, &st, o, dir, &wide, c);
    CHECK(memcmp(a, c, sizeof a) == 0);
    free(rgba), free(dep);
}

/* The mirror wall bent into a convex mirror (its normals turn by BEND radians across the frame) over
 * a striped room: the mirror shrinks the room, so each pixel sees many stripes. The exact
 * answer is the pixel's mean of the exact reflection (8 x 8 rays across the pixel, normals
 * following the same bend); footprint on (final's default) must come much closer to it
 * than one lookup per pixel, and must not touch a pixel off the mirror. */
#define BEND 2.5
/* ssr_mirror at final over f (mask: the stack's mask JSON, footprint on or off), with the
 * room's probe written at `path` (write_room_probe) attached under the name the stack asks
 * for. */
static fx_frame *run_final_with_probe(fx_context *ctx, fx_frame *f, const char *mask, int footprint,
                                      const char *path)
{
    fx_stack *s = et_stack(ctx, "ssr_mirror");
    CHECK_OK(ctx, fx_stack_set_mask_json(s, 0, mask));
    CHECK_OK(ctx, fx_stack_set_quality(s, FX_QUALITY_FINAL));
    CHECK_OK(ctx, fx_stack_set_int(s, 0, "footprint", footprint));
    char *req = NULL;
    CHECK_OK(ctx, fx_stack_required_aux_views(s, &req));
    const char *at = req ? strstr(req, "\"probe:") : NULL;
    char pname[64] = "probe:?";
    if (at)
        snprintf(pname, 19, "%s", at + 1);
    fx_free(req);
    add_probe(ctx, f, pname, path, PROBE_POS);
    fx_frame *o = NULL;
    CHECK_OK(ctx, fx_stack_run(s, f, &o));
    fx_stack_free(s);
    return o;
}

/* A Cryptomatte pass over room_frame's mirror (IndexMA 1): material Mirror covers every
 * mirror pixel wholly but column px, which it covers by mirror_cov, the rest a "Post". */
static void add_post_crypto(fx_frame *f, const float *ima, int px, float mirror_cov)
{
    const float mirror_id = fx_cryptomatte_id("Mirror"), post_id = fx_cryptomatte_id("Post");
    float *crypto = calloc((size_t)FW * FH * 4, sizeof(float));
    for (size_t i = 0; crypto && i < (size_t)FW * FH; i++) {
        float *cr = crypto + i * 4;
        if (ima[i] != 1)
            continue;
        if ((int)(i % FW) != px)
            cr[0] = mirror_id, cr[1] = 1.0f;
        else
            cr[0] = post_id, cr[1] = 1.0f - mirror_cov, cr[2] = mirror_id, cr[3] = mirror_cov;
    }
    CHECK(crypto && fx_frame_add_pass(f, "CryptoMaterial00", 4, crypto) == FX_OK);
    fx_frame_set_meta(f, "cryptomatte/CryptoMaterial/manifest", "{\"Mirror\": \"x\", \"Post\": \"y\"}");
    free(crypto);
}

static void bent_normal(double px, double n[3])
{
    double a = BEND * (px / FW - 0.5); /* radians: the normal turns about Z across the frame */
    n[0] = sin(a), n[1] = -cos(a), n[2] = 0.0;
}

static void test_footprint(fx_context *ctx)
{
    const char *dir = tu_tmpdir("footprint");
    g_stripes = 0.08; /* one to two frame pixels on the walls */
    float *want = calloc((size_t)FW * FH * 3, sizeof(float));
    fx_frame *f = room_frame(ctx, want);
    float *nor, *ima;
    int c;
    fx_frame_pass(f, "Normal", &nor, &c);
    fx_frame_pass(f, "IndexMA", &ima, &c);
    for (int y = 0; y < FH; y++)
        for (int x = 0; x < FW; x++) {
            size_t i = (size_t)y * FW + x;
            if (ima[i] != 1)
                continue;
            double n[3], acc[3] = { 0, 0, 0 };
            bent_normal(x + 0.5, n);
            for (int k = 0; k < 3; k++)
                nor[i * 3 + k] = (float)n[k];
            for (int sy = 0; sy < 8; sy++)
                for (int sx = 0; sx < 8; sx++) {
                    double px = x + (sx + 0.5) / 8, py = y + (sy + 0.5) / 8, d[3], nn[3], r[3], q[3];
                    cam_dir(px, py, d);
                    int wall, w2;
                    double t = box_exit(CAM, d, &wall);
                    double pt[3] = { CAM[0] + t * d[0], CAM[1] + t * d[1], CAM[2] + t * d[2] };
                    bent_normal(px, nn);
                    double dn = d[0] * nn[0] + d[1] * nn[1] + d[2] * nn[2];
                    for (int k = 0; k < 3; k++)
                        r[k] = d[k] - 2 * dn * nn[k];
                    double t2 = box_exit(pt, r, &w2);
                    for (int k = 0; k < 3; k++)
                        q[k] = pt[k] + t2 * r[k];
                    float col[3];
                    room_colour(q, w2, col);
                    for (int k = 0; k < 3; k++)
                        acc[k] += col[k] / 64.0;
                }
            for (int k = 0; k < 3; k++)
                want[i * 3 + k] = (float)acc[k];
        }
    char path[600];
    write_room_probe(ctx, dir, 1024, 512, path);
    double err[2];
    fx_frame *out[2] = { NULL, NULL };
    for (int on = 0; on < 2; on++) {
        out[on] = run_final_with_probe(ctx, f, "{\"material_index\": 1}", on, path);
        err[on] = mirror_mae(f, out[on], want);
    }
    printf("convex mirror over 8 cm stripes, MAE against the pixels' exact mean: one lookup %.4f, footprint %.4f\n",
           err[0], err[1]);
    CHECK(err[1] < 0.6 * err[0]);
    /* the screen-space hits alone (no probe; the pixels whose hit is trusted fully): the
     * lookup over the footprint's projection in the frame */
    double serr[2] = { 0, 0 };
    int sn = 0;
    fx_frame *so[2] = { NULL, NULL };
    for (int on = 0; on < 2; on++) {
        fx_stack *s = et_stack(ctx, "ssr_mirror");
        CHECK_OK(ctx, fx_stack_set_mask_json(s, 0, "{\"material_index\": 1}"));
        CHECK_OK(ctx, fx_stack_set_quality(s, FX_QUALITY_FINAL));
        CHECK_OK(ctx, fx_stack_set_enum(s, 0, "fallback", "texture"));
        CHECK_OK(ctx, fx_stack_set_int(s, 0, "footprint", on));
        fx_stack_set_debug_outputs(s, 1);
        CHECK_OK(ctx, fx_stack_run(s, f, &so[on]));
        fx_stack_free(s);
    }
    float *hit0 = NULL, *hit1 = NULL;
    CHECK(fx_frame_pass(so[0], "fx0_ssr_mirror_hit", &hit0, &c) == FX_OK);
    CHECK(fx_frame_pass(so[1], "fx0_ssr_mirror_hit", &hit1, &c) == FX_OK);
    const float *c0 = et_combined(so[0]), *c1 = et_combined(so[1]);
    for (size_t i = 0; hit0 && hit1 && c0 && c1 && i < (size_t)FW * FH; i++)
        if (ima[i] == 1 && hit0[i] == 1.0f && hit1[i] == 1.0f) {
            for (int k = 0; k < 3; k++) {
                serr[0] += fabs(c0[i * 4 + k] - want[i * 3 + k]);
                serr[1] += fabs(c1[i * 4 + k] - want[i * 3 + k]);
            }
            sn += 3;
        }
    printf("  its %d screen-space hits: one lookup %.4f, footprint %.4f\n", sn / 3, serr[0] / (sn ? sn : 1),
           serr[1] / (sn ? sn : 1));
    /* the frame's pixels are already their own means: less to gain than in the probe */
    CHECK(sn > 300 && serr[1] < 0.9 * serr[0]);
    fx_frame_free(so[0]), fx_frame_free(so[1]);
    /* outside the mirror: the input, bit for bit */
    const float *in = et_combined(f), *o = et_combined(out[1]);
    int same = 1;
    for (size_t i = 0; in && o && i < (size_t)FW * FH; i++)
        if (ima[i] != 1)
            same &= memcmp(in + i * 4, o + i * 4, 4 * sizeof(float)) == 0;
    CHECK(in && o && same);
    fx_frame_free(out[0]), fx_frame_free(out[1]);
    fx_frame_free(f);
    free(want);
    g_stripes = 0;
}

/* Two mirrors facing different ways in one entry (the +Y wall and the -X wall), one probe
 * before each ("probe:<key>" and "probe:<key>#2", as the add-on's probe_specs places
 * them): each mirror point takes the nearest probe in front of it. The trace is cut to one
 * step, so the probes serve every pixel. With a second probe that is all magenta, the
 * pixels nearer the first probe show none of it and those nearer the second show it. (In
 * this empty box either probe sees the whole room, so which one is nearer does not change
 * the error; the pair truth scene, whose blocks and ball hide the floor from a probe
 * between the mirrors, measures that: docs/accuracy_truth.md.) */
static void add_probes(fx_context *ctx, fx_frame *f, const char *name, const char *pa, const double a[3],
                       const char *pb, const double b[3])
{
    char json[8192];
    int n = snprintf(json, sizeof json, "{\"aux_views\": [");
    for (int k = 0; k < (pb ? 2 : 1); k++) {
        float m[16];
        w2c(k ? b : a, m);
        n += snprintf(json + n, sizeof json - n, "%s{\"name\": \"%s%s\", \"path\": \"%s\", \"world_to_camera\": [",
                      k ? ", " : "", name, k ? "#2" : "", k ? pb : pa);
        for (int i = 0; i < 16; i++)
            n += snprintf(json + n, sizeof json - n, "%s%.9g", i ? ", " : "", m[i]);
        n += snprintf(json + n, sizeof json - n,
                      "], \"projection\": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1], \"clip_start\": 0, "
                      "\"clip_end\": 1e6, \"orthographic\": false, \"kind\": \"probe\", \"panorama\": \"equirect\"}");
    }
    snprintf(json + n, sizeof json - n, "]}");
    CHECK_OK(ctx, fx_frame_apply_sidecar(f, json));
}

static void test_two_probes(fx_context *ctx)
{
    const char *dir = tu_tmpdir("twoprobes");
    float *want = calloc((size_t)FW * FH * 3, sizeof(float));
    fx_frame *f = room_frame(ctx, want);
    float *rgba, *ima;
    int c;
    fx_frame_pass(f, "Combined", &rgba, &c);
    fx_frame_pass(f, "IndexMA", &ima, &c);
    unsigned char *side = calloc((size_t)FW * FH, 1); /* 1: the +Y wall, 2: the -X wall */
    for (int y = 0; y < FH; y++)
        for (int x = 0; x < FW; x++) {
            size_t i = (size_t)y * FW + x;
            double d[3];
            cam_dir(x + 0.5, y + 0.5, d);
            int wall, w2;
            double t = box_exit(CAM, d, &wall);
            if (wall == 3)
                side[i] = 1;
            if (wall != 0)
                continue;
            /* the -X wall is a mirror too: grey backing, its exact reflection */
            side[i] = 2;
            ima[i] = 1;
            rgba[i * 4] = rgba[i * 4 + 1] = rgba[i * 4 + 2] = 0.1f;
            double p[3] = { CAM[0] + t * d[0], CAM[1] + t * d[1], CAM[2] + t * d[2] }, r[3] = { -d[0], d[1], d[2] };
            double t2 = box_exit(p, r, &w2);
            double q[3] = { p[0] + t2 * r[0], p[1] + t2 * r[1], p[2] + t2 * r[2] };
            room_colour(q, w2, want + i * 3);
        }
    fx_stack *s = et_stack(ctx, "ssr_mirror");
    CHECK_OK(ctx, fx_stack_set_mask_json(s, 0, "{\"material_index\": 1}"));
    CHECK_OK(ctx, fx_stack_set_quality(s, FX_QUALITY_FINAL));
    CHECK_OK(ctx, fx_stack_set_int(s, 0, "max_steps", 1));
    char *req = NULL;
    CHECK_OK(ctx, fx_stack_required_aux_views(s, &req));
    const char *at = req ? strstr(req, "\"probe:") : NULL;
    char pname[64] = "probe:?";
    if (at)
        snprintf(pname, 19, "%s", at + 1);
    fx_free(req);
    char pa[600], pm[600];
    snprintf(pa, sizeof pa, "%s/a.exr", dir);
    snprintf(pm, sizeof pm, "%s/magenta.exr", dir);
    const double a[3] = { 0.0, 2.6, 1.5 }, b[3] = { -2.1, 0.0, 1.5 };
    write_probe(ctx, pa, a, 256, 128, 0);
    {
        float *col = malloc((size_t)256 * 128 * 4 * sizeof(float)), *dep = malloc((size_t)256 * 128 * sizeof(float));
        render_probe(b, 256, 128, col, dep);
        for (size_t i = 0; i < (size_t)256 * 128; i++)
            col[i * 4] = 1.0f, col[i * 4 + 1] = 0.0f, col[i * 4 + 2] = 1.0f;
        et_write_view(ctx, pm, 256, 128, col, dep);
        free(col), free(dep);
    }
    fx_frame *o[2] = { NULL, NULL };
    add_probes(ctx, f, pname, pa, a, NULL, NULL);
    CHECK_OK(ctx, fx_stack_run(s, f, &o[0]));
    add_probes(ctx, f, pname, pa, a, pm, b);
    CHECK_OK(ctx, fx_stack_run(s, f, &o[1]));
    const float *c0 = et_combined(o[0]), *c1 = et_combined(o[1]);
    int na = 0, nb = 0;
    double mag_a = 0, mag_b = 0;
    for (int y = 0; c0 && c1 && y < FH; y++)
        for (int x = 0; x < FW; x++) {
            size_t i = (size_t)y * FW + x;
            if (!side[i])
                continue;
            /* the pixel's wall point and which probe lies nearer */
            double d[3], p[3];
            int wall;
            cam_dir(x + 0.5, y + 0.5, d);
            double t = box_exit(CAM, d, &wall), da = 0, db = 0;
            for (int k = 0; k < 3; k++) {
                p[k] = CAM[k] + t * d[k];
                da += (p[k] - a[k]) * (p[k] - a[k]);
                db += (p[k] - b[k]) * (p[k] - b[k]);
            }
            /* magenta: (R + B) / 2 - G, against the first probe's run alone */
            double mg = (c1[i * 4] + c1[i * 4 + 2]) / 2 - c1[i * 4 + 1] -
                        ((c0[i * 4] + c0[i * 4 + 2]) / 2 - c0[i * 4 + 1]);
            if (da < 0.8 * db) {
                mag_a += mg, na++;
            } else if (db < 0.8 * da) {
                mag_b += mg, nb++;
            }
        }
    na = na ? na : 1, nb = nb ? nb : 1;
    printf("two mirrors, two probes, a magenta second probe: magenta %.3f on the %d pixels nearer the first, %.3f "
           "on the %d nearer the second\n", mag_a / na, na, mag_b / nb, nb);
    CHECK(na > 100 && nb > 100);
    CHECK(fabs(mag_a / na) < 0.01 && mag_b / nb > 0.5);
    fx_frame_free(o[0]), fx_frame_free(o[1]);
    fx_stack_free(s);
    fx_frame_free(f);
    free(want), free(side);
}

/* Saved recipes keep their bits: a recipe of params_version 1 (before footprint) runs with
 * footprint off at final; version 2 takes final's footprint. */
static void test_footprint_migration(fx_context *ctx)
{
    const char *v[2] = { "", "\"params_version\": 2, " };
    for (int k = 0; k < 2; k++) {
        char json[400], *eff = NULL;
        snprintf(json, sizeof json, "{\"version\": 1, \"quality\": \"final\", \"effects\": [{\"effect\": "
                 "\"ssr_mirror\", %s\"params\": {}}]}", v[k]);
        fx_stack *s = NULL;
        CHECK_OK(ctx, fx_stack_new(ctx, &s));
        CHECK_OK(ctx, fx_stack_load_json(s, json));
        CHECK_OK(ctx, fx_stack_effective_params_json(s, 0, &eff));
        cJSON *e = eff ? cJSON_Parse(eff) : NULL;
        const cJSON *fp = cJSON_GetObjectItem(e, "footprint");
        CHECK(cJSON_IsBool(fp) && cJSON_IsTrue(fp) == (k == 1));
        cJSON_Delete(e);
        fx_free(eff);
        fx_stack_free(s);
    }
}

/* A pixel the mirror only partly covers: a thin red post stands in front of the mirror's
 * middle column, covering 0.6 of each of its pixels (Cryptomatte), and those pixels' Depth
 * and Normal are the post's (not anti-aliased). The truth there is 0.4 x the mirror's
 * exact reflection + 0.6 x the post. With footprint the pixel takes its fully covered
 * neighbour's change scaled by 0.4; without it, the stack's blend of the pixel's own
 * result (the post's ray, and 0.24 of the mirror's grey backing) errs far more. */
static void test_edge_coverage(fx_context *ctx)
{
    const char *dir = tu_tmpdir("edgecov");
    float *want = calloc((size_t)FW * FH * 3, sizeof(float));
    fx_frame *f = room_frame(ctx, want);
    float *rgba, *dep, *nor, *ima;
    int c;
    fx_frame_pass(f, "Combined", &rgba, &c);
    fx_frame_pass(f, "Depth", &dep, &c);
    fx_frame_pass(f, "Normal", &nor, &c);
    fx_frame_pass(f, "IndexMA", &ima, &c);
    const float cov = 0.4f, post[3] = { 1.0f, 0.0f, 0.0f };
    float *truth = calloc((size_t)FW * FH * 3, sizeof(float));
    const int px = FW / 2;
    int edge = 0;
    for (int y = 0; y < FH; y++) {
        /* the post: 0.6 of the pixel, 1 m in front of the camera, facing +X */
        size_t i = (size_t)y * FW + px;
        if (ima[i] != 1)
            continue;
        for (int k = 0; k < 3; k++) {
            rgba[i * 4 + k] = cov * rgba[i * 4 + k] + (1.0f - cov) * post[k];
            truth[i * 3 + k] = cov * want[i * 3 + k] + (1.0f - cov) * post[k];
            nor[i * 3 + k] = k == 0 ? 1.0f : 0.0f;
        }
        dep[i] = 1.0f;
        edge++;
    }
    add_post_crypto(f, ima, px, cov);
    char path[600];
    write_room_probe(ctx, dir, 256, 128, path);
    double err[2];
    for (int on = 0; on < 2; on++) {
        fx_frame *o = run_final_with_probe(ctx, f, "{\"material\": \"Mirror\"}", on, path);
        const float *oc = et_combined(o);
        double e = 0;
        for (int y = 0; oc && y < FH; y++) {
            size_t i = (size_t)y * FW + px;
            if (ima[i] == 1)
                for (int k = 0; k < 3; k++)
                    e += fabs(oc[i * 4 + k] - truth[i * 3 + k]) / (3.0 * edge);
        }
        err[on] = e;
        fx_frame_free(o);
    }
    printf("%d pixels 0.4 mirror / 0.6 post, MAE against 0.4 x the exact reflection + 0.6 x the post: "
           "own ray %.4f, the neighbour's change %.4f\n", edge, err[0], err[1]);
    CHECK(edge > 10);
    CHECK(err[1] < 0.03 && err[1] < 0.4 * err[0]);
    fx_frame_free(f);
    free(want), free(truth);
}

/* The horizontal unit vector (sx, sy, 0) at right angles to normal n: a face meeting the
 * mirror at 90 degrees along a vertical edge (a card's front and its edge). */
static void across_normal(const float n[3], float *sx, float *sy)
{
    float x = -n[1], y = n[0], l = sqrtf(x * x + y * y);
    if (l < 1e-3f)
        x = 1.0f, y = 0.0f, l = 1.0f;
    *sx = x / l, *sy = y / l;
}

/* A covered mirror pixel whose Normal blends two faces (a card's front and its edge: Cycles'
 * Normal pass is the mean of the unit normals in the pixel, 0.71 long for faces 90 deg
 * apart): its ray is neither face's. The mirror's middle column gets the mean of the
 * mirror's normal and one at right angles to it (0.6 and 0.4: |N| 0.72), full coverage. With footprint it traces
 * with its neighbour's normal (the face it holds most of) from its own position: the exact
 * reflection here; its own normal's ray errs far more, and so do its neighbours, which
 * take that ray as a differential. */
static void test_edge_normal(fx_context *ctx)
{
    const char *dir = tu_tmpdir("edgenormal");
    float *want = calloc((size_t)FW * FH * 3, sizeof(float));
    fx_frame *f = room_frame(ctx, want);
    float *nor, *ima;
    int c;
    fx_frame_pass(f, "Normal", &nor, &c);
    fx_frame_pass(f, "IndexMA", &ima, &c);
    const int px = FW / 2;
    int edge = 0, beside = 0;
    for (int y = 0; y < FH; y++) {
        size_t i = (size_t)y * FW + px;
        if (ima[i] != 1)
            continue;
        float *n = nor + i * 3, sx, sy;
        across_normal(n, &sx, &sy); /* the pixel holds 0.6 of the mirror, 0.4 of a face at right angles */
        n[0] = 0.6f * n[0] + 0.4f * sx, n[1] = 0.6f * n[1] + 0.4f * sy, n[2] = 0.6f * n[2];
        edge++;
    }
    char path[600];
    write_room_probe(ctx, dir, 256, 128, path);
    double err[2], err_beside[2];
    for (int on = 0; on < 2; on++) {
        fx_frame *o = run_final_with_probe(ctx, f, "{\"material_index\": 1}", on, path);
        const float *oc = et_combined(o);
        double e = 0, eb = 0;
        beside = 0;
        for (int y = 0; oc && y < FH; y++)
            for (int x = px - 1; x <= px + 1; x++) {
                size_t i = (size_t)y * FW + x;
                if (ima[i] != 1 || ima[(size_t)y * FW + px] != 1)
                    continue;
                double d = 0;
                for (int k = 0; k < 3; k++)
                    d += fabs(oc[i * 4 + k] - want[i * 3 + k]) / 3.0;
                if (x == px)
                    e += d / edge;
                else
                    eb += d, beside++;
            }
        err[on] = e;
        err_beside[on] = beside ? eb / beside : 1.0;
        fx_frame_free(o);
    }
    printf("%d pixels with a two-face Normal (|N| 0.72), MAE against the exact reflection: own normal %.4f, a "
           "face's %.4f; their neighbours %.4f / %.4f\n", edge, err[0], err[1], err_beside[0], err_beside[1]);
    CHECK(edge > 10);
    CHECK(err[1] < 0.015 && err[1] < 0.1 * err[0]);
    CHECK(err_beside[1] < 0.015);
    fx_frame_free(f);
    free(want);
}

/* A pixel holding two faces shows both reflections in their shares: the mirror's middle
 * column holds 0.6 of the mirror and 0.4 of a face at right angles to it (its Normal the
 * mean of the two), and the three columns right of it are that face (whole). With footprint
 * the column is the mirror's reflection traced from its own position (the exact one here)
 * times 0.6 plus 0.4 times its input plus the change the face's nearest pixel got; without
 * the second face, the mirror's reflection alone. */
static void test_two_faces(fx_context *ctx)
{
    const char *dir = tu_tmpdir("twofaces");
    float *want = calloc((size_t)FW * FH * 3, sizeof(float));
    fx_frame *f = room_frame(ctx, want);
    float *nor, *ima, *rgba;
    int c;
    fx_frame_pass(f, "Normal", &nor, &c);
    fx_frame_pass(f, "IndexMA", &ima, &c);
    fx_frame_pass(f, "Combined", &rgba, &c);
    const int px = FW / 2;
    int rows = 0;
    for (int y = 0; y < FH; y++) {
        if (ima[(size_t)y * FW + px] != 1 || ima[(size_t)y * FW + px + 3] != 1)
            continue;
        float *n = nor + ((size_t)y * FW + px) * 3, sx, sy;
        across_normal(n, &sx, &sy);
        n[0] = 0.6f * n[0] + 0.4f * sx, n[1] = 0.6f * n[1] + 0.4f * sy, n[2] = 0.6f * n[2];
        for (int x = px + 1; x <= px + 3; x++) {
            float *m = nor + ((size_t)y * FW + x) * 3;
            m[0] = sx, m[1] = sy, m[2] = 0.0f;
        }
        rows++;
    }
    char path[600];
    write_room_probe(ctx, dir, 256, 128, path);
    fx_frame *o = run_final_with_probe(ctx, f, "{\"material_index\": 1}", 1, path);
    const float *oc = et_combined(o);
    double e_mix = 0, e_one = 0, apart = 0;
    for (int y = 0; oc && y < FH; y++) {
        if (ima[(size_t)y * FW + px] != 1 || ima[(size_t)y * FW + px + 3] != 1)
            continue;
        size_t i = (size_t)y * FW + px, k = i + 1;
        for (int ch = 0; ch < 3; ch++) {
            double second = rgba[i * 4 + ch] + (oc[k * 4 + ch] - rgba[k * 4 + ch]);
            second = second > 0 ? second : 0;
            double mix = 0.6 * want[i * 3 + ch] + 0.4 * second;
            e_mix += fabs(oc[i * 4 + ch] - mix) / (3.0 * rows);
            e_one += fabs(oc[i * 4 + ch] - want[i * 3 + ch]) / (3.0 * rows);
            apart += fabs(mix - want[i * 3 + ch]) / (3.0 * rows);
        }
    }
    printf("%d pixels 0.6 mirror / 0.4 a face at right angles: off the 0.6 / 0.4 mix of the two reflections "
           "%.4f, off the mirror's alone %.4f (the two %.4f apart)\n", rows, e_mix, e_one, apart);
    CHECK(rows > 10);
    CHECK(apart > 0.05);              /* the faces' reflections differ: the test can tell */
    CHECK(e_mix < 0.01 && e_mix < 0.2 * e_one);
    fx_frame_free(o);
    fx_frame_free(f);
    free(want);
}

/* A partly covered mirror pixel is no ray differential for its neighbours: its Normal may
 * be the object in front's. The middle column is half mirror, half a post at the mirror's
 * depth whose normal is 40 deg off the mirror's (near enough to pass for the same smooth
 * surface); the columns beside it must keep their exact reflection (their footprints
 * would otherwise span the post's turned ray). */
static void test_edge_differentials(fx_context *ctx)
{
    const char *dir = tu_tmpdir("edgediff");
    float *want = calloc((size_t)FW * FH * 3, sizeof(float));
    fx_frame *f = room_frame(ctx, want);
    float *nor, *ima;
    int c;
    fx_frame_pass(f, "Normal", &nor, &c);
    fx_frame_pass(f, "IndexMA", &ima, &c);
    const int px = FW / 2;
    const float ca = cosf(40.0f * 3.14159265f / 180.0f), sa = sinf(40.0f * 3.14159265f / 180.0f);
    for (int y = 0; y < FH; y++) {
        size_t i = (size_t)y * FW + px;
        if (ima[i] != 1)
            continue;
        float *n = nor + i * 3; /* turned 40 deg about world Z */
        float nx = ca * n[0] - sa * n[1], ny = sa * n[0] + ca * n[1];
        n[0] = nx, n[1] = ny;
    }
    add_post_crypto(f, ima, px, 0.5f);
    char path[600];
    write_room_probe(ctx, dir, 256, 128, path);
    double err[2];
    for (int on = 0; on < 2; on++) {
        fx_frame *o = run_final_with_probe(ctx, f, "{\"material\": \"Mirror\"}", on, path);
        const float *oc = et_combined(o);
        double e = 0;
        int n = 0;
        for (int y = 0; oc && y < FH; y++)
            for (int x = px - 1; x <= px + 1; x += 2) {
                size_t i = (size_t)y * FW + x;
                if (ima[i] != 1 || ima[(size_t)y * FW + px] != 1)
                    continue;
                for (int k = 0; k < 3; k++)
                    e += fabs(oc[i * 4 + k] - want[i * 3 + k]) / 3.0;
                n++;
            }
        err[on] = n ? e / n : 1.0;
        fx_frame_free(o);
    }
    printf("the columns beside a half-covered one with a turned Normal, MAE against the exact reflection: "
           "footprint off %.4f, on %.4f\n", err[0], err[1]);
    CHECK(err[1] < 0.015 && err[1] < 2.0 * err[0] + 0.002);
    fx_frame_free(f);
    free(want);
}

int main(void)
{
    fx_context *ctx = NULL;
    fx_context_new(&ctx, 2);
    test_conventions();
    test_parallax();
    test_trace_bits();
    test_disocclusion();
    test_sky_behind_wall();
    test_end_to_end(ctx);
    test_planar(ctx);
    test_pano_footprint();
    test_footprint(ctx);
    test_edge_coverage(ctx);
    test_edge_normal(ctx);
    test_two_faces(ctx);
    test_edge_differentials(ctx);
    test_footprint_migration(ctx);
    test_two_probes(ctx);
    fx_context_free(ctx);
    return tu_finish("test_probe");
}
