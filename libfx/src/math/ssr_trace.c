/* Screen-space ray tracing: see ssr_trace.h. The line set-up and the march run in
 * double: a ray from 1e4 m deep or of 1e-4 px/step must not lose its direction. */
#include "math/ssr_trace.h"

#include <math.h>
#include <string.h>

float fx_ssr_pixel_footprint(const fx_view *v, float depth)
{
    float p11 = fabsf(v->cam.projection[5]);
    if (!(p11 > 1e-20f) || !(v->disp_h > 0.0f))
        return 0.0f;
    float h = 2.0f / (p11 * v->disp_h);
    float r = v->orthographic ? h : h * depth;
    return isfinite(r) ? r : 0.0f;
}

typedef struct line_state {
    double p0[2], dp[2];   /* permuted pixel position and its derivative per major-axis pixel */
    double q0[3], dq[3];   /* homogeneous view position (view / w) and derivative */
    double k0, dk;         /* 1 / w and derivative */
    int swap;              /* x and y swapped (major axis is y) */
    int w, h;
} line_state;

static inline void pixel_at(const line_state *L, double s, double *x, double *y)
{
    double a = L->p0[0] + L->dp[0] * s, b = L->p0[1] + L->dp[1] * s;
    *x = L->swap ? b : a;
    *y = L->swap ? a : b;
}

static inline double depth_at(const line_state *L, double s)
{
    double k = L->k0 + L->dk * s;
    double z = L->q0[2] + L->dq[2] * s;
    return k > 0.0 ? -z / k : INFINITY;
}

/* A pixel's surface under the line: its depth sample, and its tangent plane if any. */
typedef struct surface {
    double depth; /* sample, +inf for background */
    double plane[4];
    int has_plane;
} surface;

static void surface_get(const fx_ssr_scene *sc, int ix, int iy, surface *sf)
{
    sf->depth = fx_ssr_depth_at(sc, ix, iy);
    sf->has_plane = sc->surface_plane && isfinite(sf->depth) && sc->surface_plane(sc->user, ix, iy, sf->plane);
}

/* Depth of the surface sf under the line at s: where the view ray through the line's
 * point meets the tangent plane, if that lies within [0.5, 2] x the sample; else the
 * sample (+inf for background). */
static double surface_depth_at(const surface *sf, const line_state *L, double s)
{
    if (!sf->has_plane)
        return sf->depth;
    double k = L->k0 + L->dk * s;
    if (!(k > 0.0))
        return sf->depth;
    double P[3] = { (L->q0[0] + L->dq[0] * s) / k, (L->q0[1] + L->dq[1] * s) / k, (L->q0[2] + L->dq[2] * s) / k };
    double den = sf->plane[0] * P[0] + sf->plane[1] * P[1] + sf->plane[2] * P[2];
    double dr = -P[2]; /* the ray point's planar depth: P / dr has planar depth 1 */
    if (!(fabs(den) > 1e-12) || !(dr > 0.0))
        return sf->depth;
    double t = sf->plane[3] * dr / den;
    return isfinite(t) && t > 0.5 * sf->depth && t < 2.0 * sf->depth ? t : sf->depth;
}

/* A one-pixel memo of surface_get: the refinement's points mostly fall on the pixel of
 * the previous one (the plane comes from the scene's callback: normal, position). */
typedef struct surface_memo {
    int x, y; /* -1: empty */
    surface sf;
} surface_memo;

static double surface_at(const fx_ssr_scene *sc, const line_state *L, double s, int ix, int iy,
                         surface_memo *memo)
{
    if (memo->x != ix || memo->y != iy) {
        surface_get(sc, ix, iy, &memo->sf);
        memo->x = ix;
        memo->y = iy;
    }
    return surface_depth_at(&memo->sf, L, s);
}

static inline int pixel_index(const line_state *L, double s, int *ix, int *iy)
{
    double x, y;
    pixel_at(L, s, &x, &y);
    if (!(x > -1.0 && x < L->w + 1.0 && y > -1.0 && y < L->h + 1.0))
        return 0;
    /* truncation, not floor (a libm call or a long sequence without SSE4.1): the same
     * pixel after the clamp, as x, y > -1 here */
    int i = (int)x, j = (int)y;
    *ix = i < 0 ? 0 : i >= L->w ? L->w - 1 : i;
    *iy = j < 0 ? 0 : j >= L->h ? L->h - 1 : j;
    return 1;
}

/* Liang-Barsky: shrinks [t0, t1] of p(t) = a + t (b - a) to the box [lo, hi]. */
static int clip_axis(double a, double b, double lo, double hi, double *t0, double *t1)
{
    double d = b - a;
    if (fabs(d) < 1e-300)
        return a >= lo && a <= hi;
    double ta = (lo - a) / d, tb = (hi - a) / d;
    if (ta > tb) {
        double t = ta;
        ta = tb;
        tb = t;
    }
    if (ta > *t0)
        *t0 = ta;
    if (tb < *t1)
        *t1 = tb;
    return *t0 <= *t1;
}

static int finite3(fx_vec3 v) { return isfinite(v.x) && isfinite(v.y) && isfinite(v.z); }

/* The exact test of the line's span [s_prev, s_cur] against pixel (ix, iy): a candidate
 * when the ray's depth interval meets the surface slab [depth, depth + thickness] (or
 * crosses the pixel's tangent plane), refined by bisection, kept if it lies on the
 * surface within the thickness and the scene accepts it. Fills *out on a hit. */
static int test_span(const fx_ssr_scene *s, const line_state *L, fx_vec3 dir, const double o[3], double thick,
                     int refine, double s_prev, double s_cur, double d_prev, double d_cur, int ix, int iy,
                     fx_ssr_hit *out)
{
    double sd = fx_ssr_depth_at(s, ix, iy);
    if (!isfinite(sd))
        return 0;
    double dmin = d_prev < d_cur ? d_prev : d_cur, dmax = d_prev < d_cur ? d_cur : d_prev;
    int cand = dmax >= sd && dmin <= sd + thick;
    /* a grazing surface: the ray was in front of this pixel's plane at the span's start
     * and is behind it at its end (crossed it), though the depth samples jump past the
     * slab (the plane's depth is within 2 x the sample: a ray already that far behind
     * has not crossed it). With one-pixel spans (Hi-Z) a crossing that ends in front of
     * the sample is missed: the linear march's longer spans catch more of them. */
    surface_memo memo = { -1, -1, { 0.0, { 0.0, 0.0, 0.0, 0.0 }, 0 } };
    if (!cand && s->surface_plane && d_cur >= sd && d_prev <= 2.0 * sd) {
        /* the end's plane depth only when the start is in front (the same pixel: the memo) */
        cand = d_prev <= surface_at(s, L, s_prev, ix, iy, &memo) && d_cur >= surface_at(s, L, s_cur, ix, iy, &memo);
    }
    if (!cand)
        return 0;
    double lo = s_prev, hi = s_cur;
    for (int r = 0; r < refine; r++) {
        double mid = 0.5 * (lo + hi);
        int mx, my;
        if (!pixel_index(L, mid, &mx, &my))
            break;
        double smid = surface_at(s, L, mid, mx, my, &memo);
        if (isfinite(smid) && depth_at(L, mid) >= smid)
            hi = mid;
        else
            lo = mid;
    }
    int hx, hy;
    double slop = fabs(d_cur - d_prev) / (double)(1u << refine);
    if (!pixel_index(L, hi, &hx, &hy))
        return 0;
    double sh = surface_at(s, L, hi, hx, hy, &memo), dh = depth_at(L, hi);
    if (!(isfinite(sh) && dh >= sh - slop && dh <= sh + thick + slop && (!s->accept || s->accept(s->user, hx, hy, dir))))
        return 0;
    double x, y;
    pixel_at(L, hi, &x, &y);
    double k = L->k0 + L->dk * hi;
    double vx = (L->q0[0] + L->dq[0] * hi) / k - o[0];
    double vy = (L->q0[1] + L->dq[1] * hi) / k - o[1];
    double vz = (L->q0[2] + L->dq[2] * hi) / k - o[2];
    /* the evidence: where the ray was last in front of the depth buffer (lo: the
     * bisection's front end, or the span's start), how far it already lay behind the hit
     * pixel's own surface there (its tangent plane extended, or its sample). A crossing of
     * that surface from its front: <= 0 (the plane's slope over the bracket). A ray that
     * came out from behind a silhouette: the depth gap at the discontinuity. */
    surface hs;
    surface_get(s, hx, hy, &hs);
    double behind = depth_at(L, lo) - surface_depth_at(&hs, L, lo);
    out->behind = isfinite(behind) && behind > 0.0 ? (float)behind : 0.0f;
    double slack = fabs(dh - depth_at(L, lo));
    out->slack = isfinite(slack) ? (float)slack : 0.0f;
    out->hit_depth = (float)sh;
    out->hit = 1;
    out->px = (float)x;
    out->py = (float)y;
    out->ix = hx;
    out->iy = hy;
    double l = sqrt(vx * vx + vy * vy + vz * vz);
    out->length = isfinite(l) ? (float)l : 0.0f;
    return 1;
}

/* Trace stage 1, the line: the ray clipped to the near plane and its length, projected
 * to a 2-D line over the frame (clipped to it; *clipped: it leaves the frame) with the
 * homogeneous view position and 1/w per pixel of its major axis. 0: nothing to march. */
static int trace_line(const fx_ssr_scene *s, const fx_ssr_settings *st, fx_vec3 origin, fx_vec3 dir,
                      line_state *L, double o[3], double *s_end, int *clipped)
{
    const fx_view *v = s->view;
    double near = v->cam.clip_start > 0.0f && isfinite(v->cam.clip_start) ? v->cam.clip_start : 1e-3;
    double len = st->max_distance > 0.0f && isfinite(st->max_distance) ? st->max_distance : 1e3;
    /* near-plane clipping: view z must stay <= -near */
    if (!((double)origin.z <= -near))
        return 0;
    if (origin.z + dir.z * len > -near)
        len = (-near - origin.z) / dir.z; /* dir.z > 0 here */
    if (!(len > 1e-6))
        return 0;
    double e[3] = {origin.x + dir.x * len, origin.y + dir.y * len, origin.z + dir.z * len};
    const float *P = v->cam.projection;
    o[0] = origin.x;
    o[1] = origin.y;
    o[2] = origin.z;
    double h0[4], h1[4];
    for (int r = 0; r < 4; r++) {
        h0[r] = P[r * 4] * o[0] + P[r * 4 + 1] * o[1] + P[r * 4 + 2] * o[2] + P[r * 4 + 3];
        h1[r] = P[r * 4] * e[0] + P[r * 4 + 1] * e[1] + P[r * 4 + 2] * e[2] + P[r * 4 + 3];
    }
    if (!(h0[3] > 1e-30) || !(h1[3] > 1e-30))
        return 0;
    double k0 = 1.0 / h0[3], k1 = 1.0 / h1[3];
    double q0[3] = {o[0] * k0, o[1] * k0, o[2] * k0}, q1[3] = {e[0] * k1, e[1] * k1, e[2] * k1};
    /* NDC -> frame pixels (as fx_view_ndc_to_pixel, in double) */
    double a0[2] = {(h0[0] * k0 + 1.0) * 0.5 * v->disp_w - v->off_x, (1.0 - h0[1] * k0) * 0.5 * v->disp_h - v->off_y};
    double a1[2] = {(h1[0] * k1 + 1.0) * 0.5 * v->disp_w - v->off_x, (1.0 - h1[1] * k1) * 0.5 * v->disp_h - v->off_y};
    if (!isfinite(a0[0]) || !isfinite(a0[1]) || !isfinite(a1[0]) || !isfinite(a1[1]))
        return 0;
    /* degenerate 2-D line (ray along the view direction): nudge */
    if ((a1[0] - a0[0]) * (a1[0] - a0[0]) + (a1[1] - a0[1]) * (a1[1] - a0[1]) < 1e-4)
        a1[0] += 0.01;
    /* clip the 2-D line to the frame */
    double t0 = 0.0, t1 = 1.0;
    if (!clip_axis(a0[0], a1[0], 0.0, (double)s->width, &t0, &t1) ||
        !clip_axis(a0[1], a1[1], 0.0, (double)s->height, &t0, &t1))
        return 0;
    if (t0 > 1e-9) /* the origin itself is off the frame */
        return 0;
    *clipped = t1 < 1.0;
    if (*clipped) {
        for (int i = 0; i < 2; i++)
            a1[i] = a0[i] + (a1[i] - a0[i]) * t1;
        for (int i = 0; i < 3; i++)
            q1[i] = q0[i] + (q1[i] - q0[i]) * t1;
        k1 = k0 + (k1 - k0) * t1;
    }
    L->w = s->width;
    L->h = s->height;
    double dx = a1[0] - a0[0], dy = a1[1] - a0[1];
    L->swap = fabs(dx) < fabs(dy);
    if (L->swap) {
        double t = dx;
        dx = dy;
        dy = t;
        L->p0[0] = a0[1];
        L->p0[1] = a0[0];
    } else {
        L->p0[0] = a0[0];
        L->p0[1] = a0[1];
    }
    *s_end = fabs(dx);
    if (!(*s_end > 1e-12))
        return 0;
    double sgn = dx > 0 ? 1.0 : -1.0, inv = sgn / dx;
    L->dp[0] = sgn;
    L->dp[1] = dy * inv;
    for (int i = 0; i < 3; i++) {
        L->q0[i] = q0[i];
        L->dq[i] = (q1[i] - q0[i]) * inv;
    }
    L->k0 = k0;
    L->dk = (k1 - k0) * inv;
    return 1;
}

/* Trace stage 2a, the Hi-Z walk over the depth pyramid. 1: a hit in *out. */
static int march_hiz(const fx_ssr_scene *s, const fx_ssr_settings *st, const line_state *L, fx_vec3 dir,
                     const double o[3], double s_end, fx_ssr_hit *out)
{
    const double thick = st->thickness > 0.0f ? st->thickness : 0.0;
    const int max_steps = st->max_steps > 0 ? st->max_steps : 1;
    const int refine = st->refine < 0 ? 0 : st->refine > 30 ? 30 : st->refine;
    const fx_depth_pyramid *hz = s->hiz;
    /* Hi-Z: at level l the line crosses one 2^l cell per step; a cell whose nearest
     * surface lies behind the ray's depths across it holds no candidate and is
     * skipped whole (level up); otherwise level down, and at level 0 the pixel's span
     * of the line gets the linear march's exact test. */
    const int top = hz->levels - 1;
    int level = 0;
    /* the walk starts one pixel out, as the linear march's first test: the origin's
     * own pixel is the surface the ray leaves */
    double s_prev = 0.0;
    for (int i = 0; i < max_steps && s_prev < s_end; i++) {
        out->steps = i + 1;
        double cell = (double)(1 << level);
        /* the cell the line enters just after s_prev (a point on a boundary belongs
         * to the cell ahead) */
        double ahead = s_prev + 1e-6 < s_end ? s_prev + 1e-6 : s_prev;
        double a = L->p0[0] + L->dp[0] * ahead, b = L->p0[1] + L->dp[1] * ahead;
        double ca = floor(a / cell), cb = floor(b / cell);
        a = L->p0[0] + L->dp[0] * s_prev;
        b = L->p0[1] + L->dp[1] * s_prev;
        double bound_a = L->dp[0] > 0 ? (ca + 1.0) * cell : ca * cell;
        double s_next = s_prev + fabs(bound_a - a); /* |dp[0]| = 1 */
        if (fabs(L->dp[1]) > 1e-12) {
            double bound_b = L->dp[1] > 0 ? (cb + 1.0) * cell : cb * cell;
            double sb = s_prev + (bound_b - b) / L->dp[1];
            if (sb < s_next)
                s_next = sb;
        }
        if (!(s_next > s_prev)) /* rounding at a boundary: move on by a hair */
            s_next = s_prev + 1e-6;
        if (s_next > s_end)
            s_next = s_end;
        double d_prev = depth_at(L, s_prev), d_cur = depth_at(L, s_next);
        int cx = (int)(L->swap ? cb : ca), cy = (int)(L->swap ? ca : cb);
        cx = cx < 0 ? 0 : cx >= hz->w[level] ? hz->w[level] - 1 : cx;
        cy = cy < 0 ? 0 : cy >= hz->h[level] ? hz->h[level] - 1 : cy;
        if (level > 0) {
            const float *z = hz->level[level] + ((size_t)cy * hz->w[level] + cx) * 2;
            double dmax = d_prev > d_cur ? d_prev : d_cur, dmin = d_prev > d_cur ? d_cur : d_prev;
            /* no candidate in the cell: the ray passes in front of every sample, or
             * behind all of them by more than the thickness and the tangent planes'
             * reach (twice the sample); a cell of background only holds (+inf, -inf) */
            double back = (double)z[1] + thick;
            if (dmax < (double)z[0] || dmin > back) {
                s_prev = s_next;
                if (level < top)
                    level++;
            } else {
                level--;
            }
            continue;
        }
        if (test_span(s, L, dir, o, thick, refine, s_prev, s_next, d_prev, d_cur, cx, cy, out))
            return 1;
        s_prev = s_next;
        if (top >= 1)
            level = 1;
    }
    return 0;
}

/* march_linear's step from s_prev to s_cur over pixel (ix, iy), whose depth sample is sdf:
 * test_span's first test inline (most steps are no candidate), then test_span itself. */
static inline __attribute__((always_inline)) int step_hits(const fx_ssr_scene *s, const line_state *L, fx_vec3 dir,
                                                           const double o[3], double thick, int refine, int planes,
                                                           float sdf, double s_prev, double s_cur, double d_prev,
                                                           double d_cur, int ix, int iy, fx_ssr_hit *out)
{
    if (fx_ssr_is_background(sdf))
        return 0;
    const double sd = sdf;
    const double dmin = d_prev < d_cur ? d_prev : d_cur, dmax = d_prev < d_cur ? d_cur : d_prev;
    const int maybe = (dmax >= sd && dmin <= sd + thick) || (planes && d_cur >= sd && d_prev <= 2.0 * sd);
    return maybe && test_span(s, L, dir, o, thick, refine, s_prev, s_cur, d_prev, d_cur, ix, iy, out);
}

/* Trace stage 2b, the linear march: strides growing by `growth`, each span tested. The
 * per-step work is test_span's first test, inline, on the line's coordinates unpermuted
 * once per ray (the same arithmetic as pixel_index and depth_at, so the same pixels and
 * depths): most steps are no candidate and never reach test_span. */
static int march_linear(const fx_ssr_scene *s, const fx_ssr_settings *st, const line_state *L, fx_vec3 dir,
                        const double o[3], double s_end, double origin_depth, fx_ssr_hit *out)
{
    const double thick = st->thickness > 0.0f ? st->thickness : 0.0;
    const int max_steps = st->max_steps > 0 ? st->max_steps : 1;
    const int refine = st->refine < 0 ? 0 : st->refine > 30 ? 30 : st->refine;
    double stride = st->stride > 0.5f ? st->stride : 0.5;
    const double growth = st->growth >= 1.0f && isfinite(st->growth) ? st->growth : 1.0;
    const int planes = s->surface_plane != NULL;
    const double x0 = L->p0[L->swap], dx = L->dp[L->swap], y0 = L->p0[!L->swap], dy = L->dp[!L->swap];
    const double k0 = L->k0, dk = L->dk, z0 = L->q0[2], dz = L->dq[2];
    const double xlim = L->w + 1.0, ylim = L->h + 1.0;
    const int w = L->w, h = L->h;
    const float *depth = s->depth;
    double s_prev = 0.0, d_prev = origin_depth;
    /* Up to s_in (2 px short of the line's end) every step lies inside the frame, so the
     * bounds test and the clamps below cannot act: x0 + dx s and y0 + dy s are monotone
     * in s (rounding is monotone), so checking both ends of [0, s_in] proves it. */
    double s_in = s_end - 2.0;
    if (s_in > 0.0) {
        double xe = x0 + dx * s_in, ye = y0 + dy * s_in;
        if (!(x0 >= 0.0 && x0 < (double)w && xe >= 0.0 && xe < (double)w && y0 >= 0.0 && y0 < (double)h &&
              ye >= 0.0 && ye < (double)h))
            s_in = -1.0;
    }
    int i = 0;
    /* the steps inside the frame: no end clamp, bounds test or clamps */
    while (i < max_steps) {
        double s_cur = s_prev + stride;
        if (!(s_cur <= s_in))
            break; /* the loop below takes this step */
        i++;
        double k = k0 + dk * s_cur, z = z0 + dz * s_cur;
        double d_cur = k > 0.0 ? -z / k : INFINITY;
        int ix = (int)(x0 + dx * s_cur), iy = (int)(y0 + dy * s_cur);
        if (step_hits(s, L, dir, o, thick, refine, planes, depth[(size_t)iy * w + ix], s_prev, s_cur, d_prev, d_cur,
                      ix, iy, out)) {
            out->steps = i;
            return 1;
        }
        s_prev = s_cur;
        d_prev = d_cur;
        stride *= growth;
        if (stride > 1e7)
            stride = 1e7;
    }
    while (i < max_steps) {
        double s_cur = s_prev + stride;
        if (s_cur > s_end)
            s_cur = s_end;
        i++;
        double k = k0 + dk * s_cur, z = z0 + dz * s_cur;
        double d_cur = k > 0.0 ? -z / k : INFINITY;
        double x = x0 + dx * s_cur, y = y0 + dy * s_cur;
        if (!(x > -1.0 && x < xlim && y > -1.0 && y < ylim))
            break;
        int ix = (int)x, iy = (int)y; /* as pixel_index */
        ix = ix < 0 ? 0 : ix >= w ? w - 1 : ix;
        iy = iy < 0 ? 0 : iy >= h ? h - 1 : iy;
        if (step_hits(s, L, dir, o, thick, refine, planes, depth[(size_t)iy * w + ix], s_prev, s_cur, d_prev, d_cur,
                      ix, iy, out)) {
            out->steps = i;
            return 1;
        }
        if (s_cur >= s_end)
            break;
        s_prev = s_cur;
        d_prev = d_cur;
        stride *= growth;
        if (stride > 1e7)
            stride = 1e7;
    }
    out->steps = i;
    return 0;
}

int fx_ssr_trace(const fx_ssr_scene *s, const fx_ssr_settings *st, fx_vec3 origin, fx_vec3 dir,
                 fx_ssr_hit *out)
{
    memset(out, 0, sizeof *out);
    if (!finite3(origin) || !finite3(dir) || s->width <= 0 || s->height <= 0)
        return 0;
    dir = fx_v3_normalize_or(dir, fx_v3(0.0f, 0.0f, 0.0f));
    if (dir.x == 0.0f && dir.y == 0.0f && dir.z == 0.0f)
        return 0;
    line_state L;
    double o[3], s_end = 0.0;
    int clipped = 0;
    if (!trace_line(s, st, origin, dir, &L, o, &s_end, &clipped))
        return 0;
    const fx_depth_pyramid *hz = s->hiz;
    int hit = hz && hz->levels > 1 && hz->w[0] == s->width && hz->h[0] == s->height
                  ? march_hiz(s, st, &L, dir, o, s_end, out)
                  : march_linear(s, st, &L, dir, o, s_end, -(double)origin.z, out);
    if (!hit)
        out->left_screen = clipped;
    return hit;
}
