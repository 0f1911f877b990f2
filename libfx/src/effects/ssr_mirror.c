/* ssr_mirror: screen-space ray-traced mirrors (after McGuire & Mara 2014) for the pixels
 * of one mirror (the entry's mask). docs/effects/ssr_mirror.md.
 *
 * Per mirror pixel: view-space position from planar Depth and the projection, the
 * Normal pass (world) turned to view space, optionally bent from the pixel's position
 * on the mirror face (curved mirrors), the view ray reflected about it and traced from
 * an origin pushed `bias` pixel footprints along the normal (math/ssr_trace.h). The
 * reflected colour is the current Combined sampled bilinearly at the hit coordinates
 * (from a Gaussian-blurred copy for glossy mirrors: the lookup is blurred, not the
 * result), faded towards the fallback (the mirror's own texture or an environment
 * colour, or the reflection probe) as the hit nears the frame border, put through the
 * colour operator, and mixed by w = reflectivity x Fresnel:
 * C = C_texture (1 - w) + C_reflection w.
 *
 * Reflection probe (fallback "probe", the final and reference presets): an equirectangular
 * panorama with radial depth that the add-on renders from beside the mirror (aux view
 * "probe:<mask key>", scene/aux_view.h, math/panorama.h). Where a ray misses, leaves the
 * frame or meets the back of an object, the reflection is the probe's colour where the
 * reflected ray, marched from the mirror's surface point, meets the probe's depth surface
 * (parallax-corrected), blended with the trace by its confidence. Without the probe (not
 * rendered, failed): a warning and the texture fallback; debug pass "fallback_<name>"
 * names the one in use and holds its weight per pixel.
 *
 * Planar views (planar_view, the final and reference presets): for a flat mirror the add-on renders
 * the scene from the camera mirrored in the mirror's plane (aux view "planar:<mask key>",
 * with the plane); for a mirror whose faces lie in a few planes (a facing pair in one
 * entry) one view per plane ("planar:<mask key>", "...#2", up to PLANAR_VIEWS_MAX). A
 * mirror pixel on one of those planes (its normal within 37 deg of the plane's, within a
 * few centimetres of it; the nearest plane if several) takes that plane's view's colour at
 * the projection of its world position: the exact reflection, no tracing. Other pixels
 * (a curved mirror, a slab's edges) keep the trace and the probe.
 *
 * One stack entry is one mirror kind: many mirrors are many entries, each with its own
 * mask and parameters (the add-on's UI, `libfx describe` and the docs keep working on
 * plain parameter tables). Multiple reflections: a ray that lands on a pixel of this
 * entry's own mask (the other panel of a facing pair, a concave mirror seeing itself)
 * is reflected again there with the normal there and this entry's reflectivity and
 * Fresnel, up to `bounces`; when the bounces run out (or a later bounce misses) it
 * takes that pixel's *finished* one-bounce reflection, iterated three times on the
 * first-bounce hits (cheap: no tracing), instead of the dark backing. A ray that lands
 * on another mirror takes that pixel's current colour: the other mirror's finished
 * reflection when its entry ran earlier in the stack (the seed's trick); or, for
 * pixels of `mirror_surfaces`, is traced again with this entry's reflectivity.
 *
 * Cost follows the mirror: rays are traced only for masked pixels (or one per cell of
 * 1/resolution_scale pixels, with retrace_edges a pixel's own ray where its four cells
 * disagree); the blurred copy for glossy mirrors covers only the bounding box of the
 * hits; scratch buffers come from the context's store (the entries of a stack reuse
 * them). hiz (opt-in) traces through a min/max depth pyramid (math/depth_pyramid.h). Output is bit-identical for any thread count (per-pixel
 * work, serial double-precision reductions) and finite for any input. */
#include "core/effect.h"
#include "core/parallel.h"
#include "math/blur.h"
#include "math/camera.h"
#include "math/color.h"
#include "math/color_ops.h"
#include "math/edge_ops.h"
#include "math/panorama.h"
#include "math/ssr_trace.h"
#include "scene/aux_map.h"
#include "scene/aux_view.h"

#include <cjson/cJSON.h>

#include <float.h>
#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <string.h>

#define PLANAR_VIEWS_MAX 4 /* planar views per entry (the add-on's aux_views.PLANAR_MAX) */
#define PROBES_MAX 4       /* probes per entry: one per mirror plane facing its own way (the add-on's
                              aux_views.probe_specs) */

typedef struct ssr_params {
    float reflectivity;
    float glossiness;
    int fresnel;
    float f0;
    float fresnel_power;
    int op;
    int cel_levels;
    float edge_threshold;
    float bend;
    int fallback;
    float environment[3];
    float edge_fade;
    float bias;
    fx_mask_param mirror_surfaces;
    int bounces;
    /* quality */
    int max_steps;
    float stride;
    float growth;
    int refine;
    float thickness;
    float max_distance;
    float resolution_scale;
    int retrace_edges;
    int hiz;
    int probe_steps;
    int planar_view;
    float planar_samples;
    int footprint;
} ssr_params;

enum { OP_NONE = 0, OP_SEPIA, OP_GRAYSCALE, OP_CEL };
/* Jacobi iterations of the finished one-bounce image (the estimate past the last bounce) */
enum { FIN_ITERATIONS = 3 };
enum { FALLBACK_TEXTURE = 0, FALLBACK_ENVIRONMENT, FALLBACK_PROBE };

static const char *const op_items[] = { "none", "sepia", "grayscale", "cel" };
static const char *const fallback_items[] = { "texture", "environment", "probe" };
static const float env_default[3] = { 0.5f, 0.6f, 0.75f };

static const fx_param_def ssr_param_defs[] = {
    FX_P_FLOAT(ssr_params, reflectivity, "reflectivity", 1.0, 0.0, 1.0, 0.0, 1.0, "factor",
               "R in C = C_texture (1 - R) + C_reflection R (times the Fresnel term when fresnel is on)"),
    FX_P_FLOAT(ssr_params, glossiness, "glossiness", 0.0, 0.0, 256.0, 0.0, 24.0, "pixels",
               "Sigma of the Gaussian blur of the reflected image, sampled through the hit "
               "coordinates (the lookup is blurred, not the result); 0: a sharp mirror"),
    FX_P_BOOL(ssr_params, fresnel, "fresnel", 0,
              "Multiply the reflectivity by Schlick's F = f0 + (1 - f0)(1 - N.V)^fresnel_power"),
    FX_P_FLOAT(ssr_params, f0, "f0", 0.04, 0.0, 1.0, 0.0, 1.0, "factor",
               "Reflectance head-on (0.04: glass, IOR 1.5)"),
    FX_P_FLOAT(ssr_params, fresnel_power, "fresnel_power", 5.0, 0.01, 64.0, 1.0, 10.0, "",
               "Exponent P of the Fresnel term (5: Schlick)"),
    FX_P_ENUM(ssr_params, op, "operator", OP_NONE, op_items,
              "Colour operator on the reflection only: none; sepia; grayscale (Rec.709 luminance); "
              "cel (luminance quantised to cel_levels bands, depth-edge outlines of the reflected image)"),
    FX_P_INT(ssr_params, cel_levels, "cel_levels", 4, 1, 64, 2, 8, "", "Luminance bands of the cel operator"),
    FX_P_FLOAT(ssr_params, edge_threshold, "edge_threshold", 0.05, 0.0, 10.0, 0.005, 0.5, "",
               "Cel outlines: relative depth jump (Sobel on ln depth, math/edge_ops) that draws a line"),
    FX_P_FLOAT(ssr_params, bend, "bend", 0.0, -4.0, 4.0, -1.0, 1.0, "",
               "Curved mirror from a flat one: the normal tilts by bend x (position on the face "
               "from its centre, -1..1); > 0 bulges out (convex, wider view), < 0 in (concave)"),
    FX_P_ENUM(ssr_params, fallback, "fallback", FALLBACK_TEXTURE, fallback_items,
              "Where a ray misses (or leaves the frame), and blended by the hit's confidence where its "
              "evidence is weak (near the border, a back face, a ray that passed behind an object, a "
              "distance the probe's depth contradicts): texture: the mirror's own pixel; environment: "
              "environment_color; probe: the reflection probe (a "
              "panorama with depth the add-on renders beside the mirror), parallax-corrected, or the "
              "texture with a warning when the frame has no probe"),
    FX_P_FLOATS(ssr_params, environment, "environment_color", 3, env_default, 0.0, 65504.0, "color",
                "Reflection colour of missed rays when fallback is environment (linear RGB)"),
    FX_P_FLOAT(ssr_params, edge_fade, "edge_fade", 0.08, 0.0, 0.5, 0.0, 0.2, "factor",
               "Hits closer to the frame border than this fraction of the frame fade smoothly to the fallback"),
    FX_P_FLOAT(ssr_params, bias, "bias", 0.5, 0.0, 64.0, 0.0, 4.0, "pixels",
               "Ray origin pushed off the surface along the normal, in pixel footprints at its depth"),
    FX_P_MASK(ssr_params, mirror_surfaces, "mirror_surfaces",
                "Mask JSON naming every mirror of the scene (as a stack mask: {\"material\": [...]}); "
                "hits on these pixels bounce again (bounces > 1). Empty: no second bounce"),
    FX_P_INT(ssr_params, bounces, "bounces", 4, 1, 8, 1, 8, "",
             "Reflections per ray: a ray landing on this entry's own mirror (or on mirror_surfaces) "
             "is reflected again there, up to this many times; then, and on later misses, it takes "
             "that pixel's finished one-bounce reflection. 1: the colour where the ray lands"),
    FX_P_INT(ssr_params, max_steps, "max_steps", 96, 1, 65536, 8, 1024, "", "Steps per ray at most"),
    FX_P_FLOAT(ssr_params, stride, "stride", 1.5, 0.5, 256.0, 0.5, 16.0, "pixels", "First step along the ray's 2-D line"),
    FX_P_FLOAT(ssr_params, growth, "growth", 1.04, 1.0, 2.0, 1.0, 1.3, "",
               "Step multiplier per step (steps grow with distance)"),
    FX_P_INT(ssr_params, refine, "refine", 6, 0, 24, 0, 10, "", "Binary refinement iterations after a hit"),
    FX_P_FLOAT(ssr_params, thickness, "thickness", 0.35, 0.0, 1e6, 0.01, 2.0, "",
               "Metres a surface is assumed solid behind its front: a ray passing further behind goes on; "
               "one passing within it ends there with confidence 0 (it may be inside the object: the "
               "fallback), unless it crossed the surface's front (a hit)"),
    FX_P_FLOAT(ssr_params, max_distance, "max_distance", 100.0, 0.001, 1e7, 1.0, 1000.0, "",
               "Longest ray in metres (view space)"),
    FX_P_FLOAT(ssr_params, resolution_scale, "resolution_scale", 1.0, 0.0625, 1.0, 0.125, 1.0, "factor",
               "Rays per pixel side: 0.5 traces one ray per 2x2 cell and interpolates the hit coordinates"),
    FX_P_BOOL(ssr_params, retrace_edges, "retrace_edges", 1,
              "With resolution_scale < 1: a pixel whose four surrounding cells disagree (a partial miss, "
              "the mirror's border, or hits not mapping the cells affinely: an edge in the reflection) "
              "traces its own ray instead of taking its cell's hit (no stair steps; a ray per edge pixel)"),
    FX_P_BOOL(ssr_params, hiz, "hiz", 0,
              "Experimental: trace through a min/max depth pyramid (Hi-Z, built per entry): cells the "
              "ray passes in front of (or far behind) are skipped whole, every other pixel is tested "
              "(stride and growth unused, max_steps caps the walk). Closer to reference on the mirror "
              "room, but misses grazing hits between facing mirrors; no preset uses it"),
    FX_P_INT(ssr_params, probe_steps, "probe_steps", 48, 1, 4096, 8, 256, "",
             "fallback probe: steps of the march along the reflected ray to the probe's depth surface "
             "(geometric, 2 cm to max_distance; then refine bisections)"),
    FX_P_BOOL(ssr_params, planar_view, "planar_view", 0,
              "Flat mirrors: the reflection is the add-on's render from the camera mirrored in the "
              "mirror's plane (exact, view-dependent shading included; one more Cycles render per mirror "
              "plane, of the mirror's region only: about the mirror's share of the main render times "
              "planar_samples). final and reference turn it on: on the truth scenes the trace + probe "
              "alone removed 85-86 % of the mirror error and left the room's gloss wrong where the "
              "mirror shows the floor. Pixels off that plane, glossy, bent or cel mirrors, and a frame "
              "without that view keep the trace and the fallback"),
    FX_P_FLOAT(ssr_params, planar_samples, "planar_samples", 2.0, 0.0625, 64.0, 0.25, 4.0, "factor",
               "planar_view: the view's samples per pixel as a multiple of the render's. 1: the reflection "
               "is as noisy as a true mirror's in the render; 2 (final): less, as the trace's filtered "
               "lookups are (at 1 the grazing truth scene fell from 88 % to 84 %); reference: 4"),
    FX_P_BOOL(ssr_params, footprint, "footprint", 1,
              "Filter the reflection over each pixel's footprint (ray differentials, Igehy 1999): a "
              "curved or distant mirror shows the room smaller than the frame does, and one lookup per "
              "pixel aliases it and keeps the render's full noise where the pixel sees a mean. With it, a "
              "pixel the mirror covers in part, or one holding two of its faces, takes the neighbours' "
              "reflections in its shares; final and reference (params_version 2; older recipes keep it off)"),
};

/* ---- helpers ---- */

typedef struct ssr_frame {
    fx_view view;
    fx_ssr_scene scene;
    const float *depth;
    const float *normal; /* world space */
    int nch;
    int w, h;
    /* A per-pixel memo of the view-space normal and tangent plane (surface_get), filled
     * on first use by whichever thread gets there (a rays' neighbours test the same
     * pixels): state 0 unknown, 1 being filled, SURF_NONE, SURF_NORMAL (no plane),
     * SURF_PLANE. Values are those the direct computation gives, so the same bits. */
    _Atomic unsigned char *sstate;
    float *snormal;   /* 3 per pixel */
    double *splane_c; /* n . centre */
    const fx_mask *mask;     /* the entry's mask (NULL: every pixel), for the tracer's accept */
    const fx_mask *surfaces; /* mirror_surfaces, or NULL */
    int face_normals;        /* footprint: a mirror pixel blending two faces takes one's (face_normal) */
} ssr_frame;

enum { SURF_NONE = 2, SURF_NORMAL = 3, SURF_PLANE = 4 };

static inline fx_vec3 view_pos_at(const ssr_frame *F, int x, int y, float *depth_out)
{
    float d = F->depth[(size_t)y * F->w + x];
    if (depth_out)
        *depth_out = d;
    fx_vec2 ndc = fx_view_pixel_to_ndc(&F->view, (float)x + 0.5f, (float)y + 0.5f);
    return fx_view_position(&F->view, ndc, d);
}

/* Whether pixel i's Normal is one surface's: Cycles' Normal pass is the mean of the unit
 * normals the pixel's samples met, so it is shorter than 1 where the pixel holds two faces
 * (a mirror card's front and its edge: 0.71 half and half for faces 90 deg apart; cos(d/2)
 * for faces d apart) and about 1 across a smooth curve (1 - 3e-5 at the curved truth's
 * 1.5 deg per pixel). The normal of such a blend is no surface's: its ray goes where
 * neither face's does. */
#define NORMAL_WHOLE2 (0.95f * 0.95f)
#define EDGE_FULL 0.999f /* coverage of a wholly covered pixel (Cryptomatte sums may fall short of 1) */
static inline int whole_surface(const ssr_frame *F, size_t i)
{
    const float *p = F->normal + i * F->nch;
    return p[0] * p[0] + p[1] * p[1] + p[2] * p[2] >= NORMAL_WHOLE2; /* NaN: not whole */
}

/* The (world) normal a covered mirror pixel whose Normal blends two faces traces with
 * (*n; returns 1), at its own position: that of the whole, covered neighbour within 2 px
 * whose normal lies nearest its mean N (the face it holds most of; the nearest neighbour
 * may be the other face's), if N lies within 45 deg of it: with faces d apart, a share a
 * of the first puts N within 45 deg of it for a >= 1/2 (90 deg apart) to a >= 0.3 (45
 * apart). Otherwise (0, *n untouched) the face the pixel holds most of has no whole pixel
 * near, as a 3 cm edge seen from afar, and its mean normal is the better guess. Pixel order
 * does not matter: it reads the pass only. */
static int face_normal(const ssr_frame *F, int x, int y, fx_vec3 *n)
{
    const float *cov = F->mask ? F->mask->coverage : NULL;
    size_t i = (size_t)y * F->w + x;
    if (!F->face_normals || whole_surface(F, i) || (cov && !(cov[i] >= EDGE_FULL)))
        return 0;
    const fx_vec3 nm = *n;
    fx_vec3 best = nm;
    float best_dot = -2.0f;
    int best_d = 9;
    for (int dy = -2; dy <= 2; dy++)
        for (int dx = -2; dx <= 2; dx++) {
            int xx = x + dx, yy = y + dy, d2 = dx * dx + dy * dy;
            if (xx < 0 || yy < 0 || xx >= F->w || yy >= F->h)
                continue;
            size_t k = (size_t)yy * F->w + xx;
            if ((cov && !(cov[k] >= EDGE_FULL)) || !whole_surface(F, k))
                continue;
            const float *q = F->normal + k * F->nch;
            fx_vec3 nk = fx_v3_normalize_or(fx_v3(q[0], q[1], q[2]), nm);
            float dot = fx_v3_dot(nm, nk);
            if (dot > best_dot || (dot == best_dot && d2 < best_d)) {
                best = nk;
                best_dot = dot;
                best_d = d2;
            }
        }
    /* N . n1 >= |N| cos 45 deg */
    if (!(best_dot * best_dot >= 0.5f * fx_v3_dot(nm, nm)) || !(best_dot > 0.0f))
        return 0;
    *n = best;
    return 1;
}

/* Whether pixel (x, y)'s ray is the mirror's (with footprint): not where the mirror covers
 * the pixel only in part (its Depth and Normal may be the object in front's), nor where
 * its Normal blends two faces and face_normal found neither (its ray goes where neither
 * face's does). Such a pixel is no ray differential for its neighbours. */
static int mirror_ray_at(const ssr_frame *F, int x, int y)
{
    size_t i = (size_t)y * F->w + x;
    if (F->mask && !(F->mask->coverage[i] >= EDGE_FULL))
        return 0;
    const float *q = F->normal + i * F->nch;
    fx_vec3 n = fx_v3(q[0], q[1], q[2]);
    return whole_surface(F, i) || face_normal(F, x, y, &n);
}

/* The surface of pixel (x, y), computed: its view-space unit normal (none for background,
 * NaN, zero: SURF_NONE) and, for a perspective view, its tangent plane n . p = *c through
 * the pixel's centre position (SURF_PLANE; SURF_NORMAL when that is not finite). */
static int surface_compute(const ssr_frame *F, int x, int y, fx_vec3 *n, double *c)
{
    const float *p = F->normal + ((size_t)y * F->w + x) * F->nch;
    fx_vec3 nw = fx_v3(p[0], p[1], p[2]);
    if (!(fx_v3_dot(nw, nw) > 0.01f) || !isfinite(fx_v3_dot(nw, nw))) /* |N| >= 0.1 (AA edges: ~0.5) */
        return SURF_NONE;
    face_normal(F, x, y, &nw);
    *n = fx_v3_normalize_or(fx_world_dir_to_view(&F->view, nw), fx_v3(0, 0, 0));
    if (!(n->x != 0.0f || n->y != 0.0f || n->z != 0.0f))
        return SURF_NONE;
    if (F->view.orthographic)
        return SURF_NORMAL;
    fx_vec3 ce = view_pos_at(F, x, y, NULL);
    double nc = (double)n->x * ce.x + (double)n->y * ce.y + (double)n->z * ce.z;
    if (!isfinite(nc))
        return SURF_NORMAL;
    *c = nc;
    return SURF_PLANE;
}

/* surface_compute through the per-pixel memo. */
static inline int surface_at_pixel(const ssr_frame *F, int x, int y, fx_vec3 *n, double *c)
{
    if (!F->sstate)
        return surface_compute(F, x, y, n, c);
    size_t i = (size_t)y * F->w + x;
    unsigned char st = atomic_load_explicit(&F->sstate[i], memory_order_acquire);
    if (st >= SURF_NONE) {
        if (st >= SURF_NORMAL) {
            const float *q = F->snormal + i * 3;
            *n = fx_v3(q[0], q[1], q[2]);
            if (st == SURF_PLANE)
                *c = F->splane_c[i];
        }
        return st;
    }
    fx_vec3 nn = fx_v3(0, 0, 0);
    double cc = 0.0;
    int code = surface_compute(F, x, y, &nn, &cc);
    *n = nn;
    *c = cc;
    unsigned char expect = 0;
    /* one thread fills the entry; another arriving meanwhile computes its own copy */
    if (st == 0 && atomic_compare_exchange_strong_explicit(&F->sstate[i], &expect, 1, memory_order_acquire,
                                                           memory_order_relaxed)) {
        float *q = F->snormal + i * 3;
        q[0] = nn.x, q[1] = nn.y, q[2] = nn.z;
        F->splane_c[i] = cc;
        atomic_store_explicit(&F->sstate[i], (unsigned char)code, memory_order_release);
    }
    return code;
}

/* View-space unit normal at a pixel; 0 if there is none (background, NaN, zero). */
static inline int view_normal_at(const ssr_frame *F, int x, int y, fx_vec3 *n)
{
    double c;
    return surface_at_pixel(F, x, y, n, &c) >= SURF_NORMAL;
}

/* Tracer hits: the march goes on past a mirror pixel (this entry's or mirror_surfaces')
 * seen from behind: a ray leaving a mirror seen at a grazing angle otherwise "hits" the far
 * half of its own start pixel. Any other surface is a hit, whichever way it faces: a back
 * face ends the ray with confidence 0 (hit_confidence: the probe or the fallback), as the
 * ray cannot have passed it. */
static int front_facing(const void *user, int x, int y, fx_vec3 dir)
{
    const ssr_frame *F = user;
    size_t i = (size_t)y * F->w + x;
    int mirror = (!F->mask || F->mask->coverage[i] > 0.0f) || (F->surfaces && F->surfaces->coverage[i] > 0.0f);
    fx_vec3 n;
    return !mirror || !view_normal_at(F, x, y, &n) || fx_v3_dot(n, dir) <= 0.25f;
}

/* Tracer: the tangent plane of pixel (x, y) (view space, n . p = n . centre), exact for
 * the flat mirrors and walls that a ray meets at grazing angles. None for orthographic
 * views (the depth samples serve). */
static int surface_plane(const void *user, int x, int y, double plane[4])
{
    const ssr_frame *F = user;
    fx_vec3 n;
    double c;
    if (surface_at_pixel(F, x, y, &n, &c) != SURF_PLANE)
        return 0;
    plane[0] = n.x, plane[1] = n.y, plane[2] = n.z, plane[3] = c;
    return 1;
}

/* Bilinear lookup at frame position (px, py) (pixel centres at +0.5, borders clamped to
 * the frame) in an image that holds only the box [bx0, bx1) x [by0, by1) of the frame
 * (row stride bx1 - bx0): a box covering the taps reads the same as the full frame;
 * taps outside it are clamped into it (never out of the buffer). */
static inline void sample_bilinear_box(const float *img, const fx_rect *box, int w, int h, float px, float py,
                                       float out[3])
{
    float fx = px - 0.5f, fy = py - 0.5f;
    fx = fx < 0 ? 0 : fx > w - 1 ? (float)(w - 1) : fx;
    fy = fy < 0 ? 0 : fy > h - 1 ? (float)(h - 1) : fy;
    int x0 = (int)fx, y0 = (int)fy;
    int x1 = x0 + 1 < w ? x0 + 1 : x0, y1 = y0 + 1 < h ? y0 + 1 : y0;
    float ax = fx - x0, ay = fy - y0;
    const int bw = box->x1 - box->x0;
#define BOX_X(v) ((v) < box->x0 ? 0 : (v) >= box->x1 ? bw - 1 : (v) - box->x0)
#define BOX_Y(v) ((v) < box->y0 ? 0 : (v) >= box->y1 ? box->y1 - box->y0 - 1 : (v) - box->y0)
    int ux0 = BOX_X(x0), ux1 = BOX_X(x1), uy0 = BOX_Y(y0), uy1 = BOX_Y(y1);
#undef BOX_X
#undef BOX_Y
    const float *a = img + ((size_t)uy0 * bw + ux0) * 4, *b = img + ((size_t)uy0 * bw + ux1) * 4;
    const float *c = img + ((size_t)uy1 * bw + ux0) * 4, *d = img + ((size_t)uy1 * bw + ux1) * 4;
    for (int k = 0; k < 3; k++) {
        float top = a[k] + (b[k] - a[k]) * ax, bot = c[k] + (d[k] - c[k]) * ax;
        out[k] = top + (bot - top) * ay;
    }
}

static inline void sample_bilinear(const float *img, int w, int h, float px, float py, float out[3])
{
    const fx_rect frame = { 0, 0, w, h };
    sample_bilinear_box(img, &frame, w, h, px, py, out);
}

/* The mirror face's frame for bending: centre, tangent, bitangent (view space) and the
 * half extents along them. */
typedef struct face_frame {
    int valid;
    fx_vec3 c, t, b;
    float et, eb;
} face_frame;

/* Per traced cell. */
typedef struct cell_hit {
    float px, py;   /* hit coordinates */
    float conf;     /* 0 miss .. 1 full (hit_confidence) */
    float length;
    int state;      /* 0: not a mirror cell, 1: traced (conf may be 0) */
} cell_hit;

typedef struct ssr_job {
    const fx_effect_run *run;
    const ssr_params *p;
    const ssr_frame *F;
    fx_ssr_settings st;
    face_frame face;
    const fx_mask *surfaces;   /* other mirrors (double reflections), or NULL */
    int cell;                  /* cell size in pixels */
    int cx0, cy0, ncx, ncy;    /* cell grid over the roi */
    cell_hit *cells;
    cell_hit *hits;            /* per roi pixel (row stride roi width): cells resolved, or cells itself */
    const float *lookup;       /* image the reflection is sampled from (blurred for glossy) */
    fx_rect lookup_box;        /* where lookup is valid (the blurred box; src elsewhere) */
    const float *fin;          /* finished one-bounce image of this mirror (lookup elsewhere), or NULL;
                                  it holds only fin_box of the frame */
    fx_rect fin_box;           /* the mask's bounds + 2 px (every bilinear tap of an own pixel) */
    float *out;                /* where shade_rows writes: run->dst, or a fin buffer (fin_box) */
    int last_bounce;           /* bounces left after the first: 0 while iterating fin */
    int own_only;              /* iterating fin after the first iteration: only the pixels whose
                                  first hit lands on this mirror change */
    int reuse_fin;             /* final shading after the estimate, no debug layers: pixels whose
                                  first hit bounces no further copy their estimate */
    float opm[16];
    float *dbg_hit, *dbg_xy, *dbg_len, *dbg_fb;
    const fx_pano *probe;      /* the reflection probe (fallback probe and present), or NULL */
    const fx_pano *probes[PROBES_MAX]; /* every probe of the entry (probes[0] == probe) */
    fx_vec3 probe_at_view[PROBES_MAX]; /* their centres in view space */
    int probe_count;
    const fx_aux_view *planar[PLANAR_VIEWS_MAX]; /* the mirrored cameras' views, one per plane */
    int planar_count;          /* how many (0: planar_view off or none rendered) */
    float *dbg_planar;
    fx_pano_trace_settings pst;
} ssr_job;

/* The probe that serves a mirror point at pos with normal n: with one probe, that one;
 * with one per mirror plane (a facing pair), the nearest whose centre lies in front of the
 * surface (each is placed before its own plane), else the nearest. */
static const fx_pano *probe_at(const ssr_job *j, fx_vec3 pos, fx_vec3 n)
{
    if (j->probe_count <= 1)
        return j->probe;
    int best = -1, best_front = 0;
    float best_d = 0.0f;
    for (int k = 0; k < j->probe_count; k++) {
        fx_vec3 d = fx_v3_sub(j->probe_at_view[k], pos);
        int front = fx_v3_dot(d, n) > 0.0f;
        float dist = fx_v3_dot(d, d);
        if (best < 0 || front > best_front || (front == best_front && dist < best_d)) {
            best = k;
            best_front = front;
            best_d = dist;
        }
    }
    return j->probes[best];
}

/* The reflection of ray o + t dir (view space) seen in probe pr, parallax-corrected. */
static inline void probe_colour(const ssr_job *j, const fx_pano *pr, fx_vec3 o, fx_vec3 dir, float rgb[3])
{
    fx_pano_trace(pr, &j->pst, o, dir, rgb);
}

/* The pixel (0..n-1) holding coordinate p: (int)clamp(floorf(p), 0, n - 1) without floorf
 * (a long software sequence without SSE4.1): clamping first gives the same pixel, and
 * truncation is floor for the clamped (non-negative) value; NaN goes the same way. */
static inline int pixel_of(float p, int n)
{
    return (int)fx_clampf(p, 0.0f, (float)(n - 1));
}

/* floorf(v) as an int for finite |v| < 2^31 (the cell grid's coordinates). */
static inline int floor_int(float v)
{
    int i = (int)v;
    return (float)i > v ? i - 1 : i;
}

static inline int in_mask(const fx_mask *m, int w, int x, int y)
{
    return !m || m->coverage[(size_t)y * w + x] > 0.0f;
}

/* The shading normal of a mirror pixel (bent on the face if asked), facing the viewer. */
static int shading_normal(const ssr_job *j, int x, int y, fx_vec3 pos, fx_vec3 incident, fx_vec3 *n)
{
    if (!view_normal_at(j->F, x, y, n))
        return 0;
    if (j->p->bend != 0.0f && j->face.valid) {
        fx_vec3 d = fx_v3_sub(pos, j->face.c);
        float u = fx_clampf(fx_v3_dot(d, j->face.t) / j->face.et, -1.0f, 1.0f);
        float v = fx_clampf(fx_v3_dot(d, j->face.b) / j->face.eb, -1.0f, 1.0f);
        fx_vec3 tilt = fx_v3_add(fx_v3_scale(j->face.t, u), fx_v3_scale(j->face.b, v));
        *n = fx_v3_normalize_or(fx_v3_add(*n, fx_v3_scale(tilt, j->p->bend)), *n);
    }
    if (fx_v3_dot(*n, incident) > 0.0f)
        *n = fx_v3_scale(*n, -1.0f);
    return 1;
}

/* The confidence of a screen-space hit (0..1): how far its evidence goes. The reflection
 * is the hit's colour blended into the fallback (the probe, or the texture/environment) by
 * it. The product of (docs/effects/ssr_mirror.md, "Confidence"):
 *  - the screen border: hits nearer the border than edge_fade of the frame fade out (what
 *    lies past the border is unknown);
 *  - the thickness test: a ray that already lay behind the hit surface before it reached
 *    it (fx_ssr_hit.behind: it came at a silhouette from behind a depth discontinuity,
 *    passing behind or through a foreground object) did not meet that surface's visible
 *    front: 1 up to t0 = the ray's own depth change over the refined bracket (slack) +
 *    CONF_BEHIND0 pixel footprints at the hit's depth, 0 from 2 t0.
 *    This is what makes smears impossible: the silhouette colour a ray "meets" from
 *    behind is never drawn out along the rays that pass behind it;
 *  - back faces: a surface whose normal faces along the ray (n . r > 0: the ray would meet
 *    its back, which the frame does not show): 1 at n . r <= 0, 0 from CONF_BACK1;
 *  - the ray's length: 0 at max_distance (the ray was cut there), from 0.8 of it;
 *  - with a probe (its depth; the one that serves the ray's mirror point, probe_at): the
 *    hit's distance against the probe's distance along the same ray (fx_pano_trace_dist):
 *    a factor CONF_PROBE1 apart or more (either way) is a contradiction (the tracer passed
 *    an occluder the probe sees, or took a silhouette the probe sees past): 0; within
 *    CONF_PROBE0: 1. A ray the probe sees no surface
 *    along gives no evidence either way.
 * Rays towards the camera need no term of their own: the surfaces they can meet that
 * the frame shows are seen edge-on, and the back-face and thickness terms take the rest. */
#define CONF_BEHIND0 0.1f
#define CONF_BACK1 0.1f
#define CONF_PROBE0 1.3f
#define CONF_PROBE1 2.0f
static float hit_confidence(const ssr_job *j, const ssr_frame *F, const fx_ssr_hit *hit, fx_vec3 o, fx_vec3 r,
                            const fx_pano *probe)
{
    float conf = 1.0f;
    if (j->p->edge_fade > 0.0f) {
        float ex = fminf(hit->px, (float)F->w - hit->px) / (j->p->edge_fade * (float)F->w);
        float ey = fminf(hit->py, (float)F->h - hit->py) / (j->p->edge_fade * (float)F->h);
        conf = fx_smoothstep(0.0f, 1.0f, fminf(ex, ey));
    }
    if (hit->behind > 0.0f) {
        float t0 = hit->slack + CONF_BEHIND0 * fx_ssr_pixel_footprint(&F->view, hit->hit_depth);
        conf *= 1.0f - fx_smoothstep(t0, 2.0f * t0, hit->behind);
    }
    fx_vec3 hn;
    if (view_normal_at(F, hit->ix, hit->iy, &hn))
        conf *= 1.0f - fx_smoothstep(0.0f, CONF_BACK1, fx_v3_dot(hn, r));
    conf *= 1.0f - fx_smoothstep(0.8f * j->p->max_distance, j->p->max_distance, hit->length);
    if (probe && conf > 0.0f && hit->length > 0.0f) {
        float tp = fx_pano_trace_dist(probe, &j->pst, o, r);
        if (tp > 0.0f && isfinite(tp)) {
            float q = hit->length > tp ? hit->length / tp : tp / hit->length;
            conf *= 1.0f - fx_smoothstep(CONF_PROBE0, CONF_PROBE1, q);
        }
    }
    return isfinite(conf) ? fx_clampf(conf, 0.0f, 1.0f) : 0.0f;
}

/* Traces the reflection of pixel (x, y) of this mirror; fills *h. */
static void trace_pixel(const ssr_job *j, int x, int y, cell_hit *h)
{
    const ssr_frame *F = j->F;
    h->state = 1;
    h->conf = 0.0f;
    h->px = h->py = h->length = 0.0f;
    float d;
    fx_vec3 pos = view_pos_at(F, x, y, &d);
    if (fx_ssr_is_background(d) || !isfinite(pos.x + pos.y + pos.z))
        return;
    fx_vec3 inc = F->view.orthographic ? fx_v3(0, 0, -1) : fx_v3_normalize_or(pos, fx_v3(0, 0, -1));
    fx_vec3 n;
    if (!shading_normal(j, x, y, pos, inc, &n))
        return;
    fx_vec3 r = fx_v3_reflect(inc, n);
    fx_vec3 o = fx_v3_add(pos, fx_v3_scale(n, j->p->bias * fx_ssr_pixel_footprint(&F->view, d)));
    fx_ssr_hit hit;
    if (!fx_ssr_trace(&F->scene, &j->st, o, r, &hit))
        return;
    float fade = hit_confidence(j, F, &hit, o, r, probe_at(j, pos, n));
    h->px = hit.px;
    h->py = hit.py;
    h->conf = fade;
    h->length = hit.length;
}

static void trace_cells(void *user, int begin, int end)
{
    ssr_job *j = user;
    const int w = j->F->w, h = j->F->h, c = j->cell;
    const fx_mask *m = j->run->mask;
    for (int cy = begin; cy < end; cy++)
        for (int cx = 0; cx < j->ncx; cx++) {
            cell_hit *ch = &j->cells[(size_t)cy * j->ncx + cx];
            memset(ch, 0, sizeof *ch);
            int x0 = (j->cx0 + cx) * c, y0 = (j->cy0 + cy) * c;
            /* the cell's centre pixel if it is a mirror pixel, else the first one */
            int bx = -1, by = -1;
            int mx = x0 + c / 2, my = y0 + c / 2;
            if (mx < w && my < h && in_mask(m, w, mx, my)) {
                bx = mx;
                by = my;
            }
            for (int yy = y0; bx < 0 && yy < y0 + c && yy < h; yy++)
                for (int xx = x0; xx < x0 + c && xx < w; xx++)
                    if (in_mask(m, w, xx, yy)) {
                        bx = xx;
                        by = yy;
                        break;
                    }
            if (bx >= 0)
                trace_pixel(j, bx, by, ch);
        }
}

/* Hit coordinates of mirror pixel (x, y) with cells: the bilinear blend of the 4
 * surrounding cells when all hit and agree: within 2 cells of each other, or, with
 * retrace_edges, within 8 cells and mapping the quad affinely to half a pixel. Else (an
 * edge in the reflection, a partial miss, the mirror's border) its own ray with
 * retrace_edges, else its own cell's hit. */
static cell_hit resolve_hit(const ssr_job *j, int x, int y)
{
    const int c = j->cell;
    int gx = x / c - j->cx0, gy = y / c - j->cy0;
    cell_hit own = j->cells[(size_t)gy * j->ncx + gx];
    float fx = ((float)x + 0.5f) / (float)c - 0.5f - (float)j->cx0;
    float fy = ((float)y + 0.5f) / (float)c - 0.5f - (float)j->cy0;
    int ax = floor_int(fx), ay = floor_int(fy);
    int agree = ax >= 0 && ay >= 0 && ax + 1 < j->ncx && ay + 1 < j->ncy;
    const cell_hit *q[4] = { NULL, NULL, NULL, NULL };
    if (agree) {
        q[0] = &j->cells[(size_t)ay * j->ncx + ax];
        q[1] = &j->cells[(size_t)ay * j->ncx + ax + 1];
        q[2] = &j->cells[(size_t)(ay + 1) * j->ncx + ax];
        q[3] = &j->cells[(size_t)(ay + 1) * j->ncx + ax + 1];
        float lim = (j->p->retrace_edges ? 8.0f : 2.0f) * (float)c;
        for (int k = 0; k < 4 && agree; k++)
            agree = q[k]->state == 1 && q[k]->conf > 0.0f && fabsf(q[k]->px - q[0]->px) <= lim &&
                    fabsf(q[k]->py - q[0]->py) <= lim;
        if (agree && j->p->retrace_edges) {
            /* the hits must map the quad affinely (to half a pixel): a smooth reflection
             * may stretch it, an edge in the reflected image breaks it */
            float ex = q[0]->px + q[3]->px - q[1]->px - q[2]->px, ey = q[0]->py + q[3]->py - q[1]->py - q[2]->py;
            agree = fabsf(ex) <= 0.5f && fabsf(ey) <= 0.5f;
        }
    }
    if (!agree) {
        if (!j->p->retrace_edges)
            return own;
        /* all four traced and all missed: a miss region, nothing to sharpen */
        int misses = 0;
        for (int k = 0; k < 4 && q[0]; k++)
            misses += q[k]->state == 1 && !(q[k]->conf > 0.0f);
        if (misses == 4)
            return own;
        cell_hit h;
        trace_pixel(j, x, y, &h);
        return h;
    }
    float tx = fx - ax, ty = fy - ay;
    float wts[4] = { (1 - tx) * (1 - ty), tx * (1 - ty), (1 - tx) * ty, tx * ty };
    cell_hit r = { 0, 0, 0, 0, 1 };
    for (int k = 0; k < 4; k++) {
        r.px += wts[k] * q[k]->px;
        r.py += wts[k] * q[k]->py;
        r.conf += wts[k] * q[k]->conf;
        r.length += wts[k] * q[k]->length;
    }
    return r;
}

/* Fills j->hits for the mirror pixels of rows [begin, end) of the roi (cells > 1). */
static void resolve_rows(void *user, int begin, int end)
{
    ssr_job *j = user;
    const fx_rect *roi = &j->run->roi;
    const int rw = roi->x1 - roi->x0;
    for (int y = roi->y0 + begin; y < roi->y0 + end; y++)
        for (int x = roi->x0; x < roi->x1; x++) {
            cell_hit *h = &j->hits[(size_t)(y - roi->y0) * rw + (x - roi->x0)];
            if (in_mask(j->run->mask, j->F->w, x, y))
                *h = resolve_hit(j, x, y);
            else
                memset(h, 0, sizeof *h);
        }
}

static inline cell_hit pixel_hit(const ssr_job *j, int x, int y)
{
    const fx_rect *roi = &j->run->roi;
    return j->hits[(size_t)(y - roi->y0) * (roi->x1 - roi->x0) + (x - roi->x0)];
}

static inline int own_at(const ssr_job *j, int x, int y)
{
    return j->run->mask && j->run->mask->coverage[(size_t)y * j->F->w + x] > 0.5f;
}

/* Whether a first hit lands on this entry's own mirror (the pixel ray_colour finds). */
static inline int hit_on_own(const ssr_job *j, const cell_hit *h)
{
    if (h->state != 1 || !(h->conf > 0.0f))
        return 0;
    int hx = pixel_of(h->px, j->F->w);
    int hy = pixel_of(h->py, j->F->h);
    return own_at(j, hx, hy);
}

/* Whether ray_colour would reflect a first hit again (it lands on this mirror or on a
 * mirror_surfaces pixel); a miss (conf 0) does not. */
static inline int hit_bounces(const ssr_job *j, const cell_hit *h)
{
    if (h->state != 1 || !(h->conf > 0.0f))
        return 0;
    int hx = pixel_of(h->px, j->F->w);
    int hy = pixel_of(h->py, j->F->h);
    return own_at(j, hx, hy) || (j->surfaces && j->surfaces->coverage[(size_t)hy * j->F->w + hx] > 0.5f);
}

/* Weight of the reflection on a pixel of this mirror seen along `incident`. */
static inline float mirror_weight(const ssr_params *p, fx_vec3 n, fx_vec3 incident)
{
    float wgt = p->reflectivity;
    if (p->fresnel) {
        float ndv = fx_saturate(-fx_v3_dot(n, incident));
        wgt *= p->f0 + (1.0f - p->f0) * powf(1.0f - ndv, p->fresnel_power);
    }
    return wgt;
}

/* Where the ray o + t dir meets the surface of pixel (x, y) at (px, py): the exact
 * intersection with the pixel's tangent plane when it projects within 1.5 px of the
 * hit (a mirror seen at a grazing angle spans decimetres per pixel, and the next bounce
 * starts here), else the pixel's centre position. */
static fx_vec3 surface_point(const ssr_frame *F, int x, int y, float px, float py, fx_vec3 o, fx_vec3 dir,
                             fx_vec3 centre)
{
    fx_vec3 n;
    if (!view_normal_at(F, x, y, &n))
        return centre;
    float den = fx_v3_dot(n, dir);
    if (!(fabsf(den) > 1e-6f))
        return centre;
    float t = fx_v3_dot(n, fx_v3_sub(centre, o)) / den;
    if (!(t > 0.0f) || !isfinite(t))
        return centre;
    fx_vec3 q = fx_v3_add(o, fx_v3_scale(dir, t));
    fx_vec2 pix = { -1e30f, -1e30f };
    if (!(fx_view_project(&F->view, q, &pix) > 0.0f) || !(fabsf(pix.x - px) < 1.5f && fabsf(pix.y - py) < 1.5f))
        return centre;
    return q;
}

/* The reflected image at (px, py): the lookup (blurred for glossy mirrors) where all four
 * bilinear taps lie in its box, else the unblurred current image (a later bounce landing
 * outside the first hits' box). */
static void sample_lookup(const ssr_job *j, float px, float py, float rgb[3])
{
    const int w = j->F->w, h = j->F->h;
    float fx = fx_clampf(px - 0.5f, 0.0f, (float)(w - 1)), fy = fx_clampf(py - 0.5f, 0.0f, (float)(h - 1));
    int x0 = (int)fx, y0 = (int)fy;
    const fx_rect *b = &j->lookup_box;
    if (x0 >= b->x0 && y0 >= b->y0 && (x0 + 1 < w ? x0 + 1 : x0) < b->x1 && (y0 + 1 < h ? y0 + 1 : y0) < b->y1)
        sample_bilinear(j->lookup, w, h, px, py, rgb);
    else
        sample_bilinear(j->run->src, w, h, px, py, rgb);
}

/* Colour the ray o + t dir brings back from (px, py), where it landed. Not a mirror
 * there: the lookup. This entry's own mirror or a mirror_surfaces pixel: reflected
 * again (up to `left` more bounces). The estimate where no further bounce is traced or
 * it misses: the pixel's finished one-bounce reflection (own mirror, j->fin) or its
 * current colour (another mirror, whose entry may have finished it). */
static void ray_colour(const ssr_job *j, fx_vec3 ro, fx_vec3 rd, float px, float py, int left, float rgb[3])
{
    const ssr_frame *F = j->F;
    int hx = pixel_of(px, F->w);
    int hy = pixel_of(py, F->h);
    int own = own_at(j, hx, hy);
    int other = !own && j->surfaces && j->surfaces->coverage[(size_t)hy * F->w + hx] > 0.5f;
    if (own && j->fin)
        sample_bilinear_box(j->fin, &j->fin_box, F->w, F->h, px, py, rgb);
    else
        sample_lookup(j, px, py, rgb);
    if ((!own && !other) || left <= 0)
        return;
    float d;
    fx_vec3 pos = view_pos_at(F, hx, hy, &d);
    if (fx_ssr_is_background(d) || !isfinite(pos.x + pos.y + pos.z))
        return;
    pos = surface_point(F, hx, hy, px, py, ro, rd, pos);
    fx_vec3 inc = fx_v3_normalize_or(rd, fx_v3(0, 0, -1));
    fx_vec3 n;
    if (own) {
        if (!shading_normal(j, hx, hy, pos, inc, &n))
            return;
    } else {
        if (!view_normal_at(F, hx, hy, &n))
            return;
        if (fx_v3_dot(n, inc) > 0.0f)
            n = fx_v3_scale(n, -1.0f);
    }
    fx_vec3 r = fx_v3_reflect(inc, n);
    fx_vec3 o = fx_v3_add(pos, fx_v3_scale(n, j->p->bias * fx_ssr_pixel_footprint(&F->view, -pos.z)));
    fx_ssr_hit hit;
    const fx_pano *probe = probe_at(j, pos, n);
    float fade = fx_ssr_trace(&F->scene, &j->st, o, r, &hit) ? hit_confidence(j, F, &hit, o, r, probe) : 0.0f;
    if (!(fade > 0.0f) && !j->probe)
        return;
    float next[3] = { 0.0f, 0.0f, 0.0f }, tex[3], est[3] = { rgb[0], rgb[1], rgb[2] };
    if (fade > 0.0f)
        ray_colour(j, o, r, hit.px, hit.py, left - 1, next);
    if (j->probe && fade < 1.0f) {
        /* the bounce's miss: the probe, blended by the hit's confidence */
        float pc[3];
        probe_colour(j, probe, pos, r, pc);
        for (int k = 0; k < 3; k++)
            next[k] = pc[k] + (next[k] - pc[k]) * fade;
        fade = 1.0f;
    }
    float wgt;
    if (own) {
        /* this mirror again: its backing under its reflectivity x Fresnel at this angle */
        sample_bilinear(j->run->src, F->w, F->h, px, py, tex);
        wgt = mirror_weight(j->p, n, inc);
    } else {
        memcpy(tex, est, sizeof tex);
        wgt = j->p->reflectivity;
    }
    for (int k = 0; k < 3; k++) {
        float v = tex[k] * (1.0f - wgt) + next[k] * wgt;
        rgb[k] = est[k] + (v - est[k]) * fade;
    }
}

/* Whether planar view pv shows, around (px, py), only what lies beyond the mirror point
 * at depth dd (the mirror's side of the plane): the mirrored camera stands behind the
 * plane, and a surface between it and the plane (a frame's back, behind the mirror's face,
 * that no object test can hide: one frame object spans the room) is nothing the mirror
 * reflects. The bilinear taps and their neighbours (Depth is not anti-aliased, the colour
 * is: a pixel beside such a surface holds part of it) must lie beyond the plane, within
 * 1 mm + 0.1 %; otherwise the pixel keeps the trace and the fallback. */
static int planar_in_front(const fx_aux_view *pv, float px, float py, float dd)
{
    const float near = dd * (1.0f - 1e-3f) - 1e-3f;
    int x0 = (int)floorf(px - 0.5f), y0 = (int)floorf(py - 0.5f);
    for (int y = y0 - 1; y <= y0 + 2; y++)
        for (int x = x0 - 1; x <= x0 + 2; x++) {
            int cx = x < 0 ? 0 : x >= pv->width ? pv->width - 1 : x;
            int cy = y < 0 ? 0 : y >= pv->height ? pv->height - 1 : y;
            if (!(pv->depth[(size_t)cy * pv->width + cx] >= near))
                return 0;
        }
    return 1;
}

/* The colour of mirror pixel (x, y) at view position pos in the planar view of its plane:
 * 1 + that view's index, or 0 when the pixel lies on none of the views' planes (or
 * projects outside its view). */
static int planar_colour(const ssr_job *j, int x, int y, fx_vec3 pos, float rgb[3])
{
    const ssr_frame *F = j->F;
    const float *np = F->normal + ((size_t)y * F->w + x) * F->nch;
    fx_vec3 nw = fx_v3_normalize_or(fx_v3(np[0], np[1], np[2]), fx_v3(0, 0, 0));
    fx_vec3 wp = fx_view_to_world(&F->view, pos);
    float tol = 0.02f + 0.002f * fx_v3_length(pos);
    int best = -1;
    float best_dist = 0.0f;
    for (int k = 0; k < j->planar_count; k++) {
        const fx_aux_view *pv = j->planar[k];
        fx_vec3 pn = fx_v3(pv->plane[0], pv->plane[1], pv->plane[2]);
        float dist = fabsf(fx_v3_dot(pn, wp) - pv->plane[3]);
        /* on the plane (Depth is not anti-aliased) with a normal within 37 deg of it: an
         * anti-aliased border pixel blends the mirror's normal with its neighbour's (0.99
         * left 1 347 of the truth pair's border pixels to the trace: 0.3 pt of its fall);
         * a slab's side faces (90 deg) stay out */
        if (fabsf(fx_v3_dot(nw, pn)) > 0.8f && dist < tol && (best < 0 || dist < best_dist)) {
            best = k;
            best_dist = dist;
        }
    }
    if (best < 0)
        return 0;
    const fx_aux_view *pv = j->planar[best];
    float px, py, dd;
    if (!fx_aux_view_project(pv, wp, &px, &py, &dd) || !(px >= 0.0f && px <= (float)pv->width) ||
        !(py >= 0.0f && py <= (float)pv->height) || !planar_in_front(pv, px, py, dd))
        return 0;
    sample_bilinear(pv->color, pv->width, pv->height, px, py, rgb);
    return best + 1;
}

static void apply_operator(const ssr_job *j, float px, float py, float rgb[3])
{
    const ssr_params *p = j->p;
    if (p->op == OP_SEPIA || p->op == OP_GRAYSCALE) {
        fx_color_op_apply3(j->opm, rgb, rgb);
    } else if (p->op == OP_CEL) {
        float L = fx_luminance_rgb(rgb);
        if (L > 1e-6f && isfinite(L)) {
            float lv = (float)p->cel_levels;
            float q = ceilf(fx_clampf(L, 0.0f, 1.0f) * lv) / lv;
            if (L > 1.0f)
                q = L; /* above white: keep (quantising HDR makes no sense) */
            float s = q / L;
            for (int k = 0; k < 3; k++)
                rgb[k] *= s;
        }
        const ssr_frame *F = j->F;
        int ix = pixel_of(px, F->w);
        int iy = pixel_of(py, F->h);
        /* the shared depth edge operator (math/edge_ops: Sobel on ln depth, i.e. the
         * relative depth jump) on the 3x3 around the hit, borders replicated */
        float patch[9];
        for (int dy = -1; dy <= 1; dy++)
            for (int dx = -1; dx <= 1; dx++) {
                int xx = (int)fx_clampf((float)(ix + dx), 0.0f, (float)(F->w - 1));
                int yy = (int)fx_clampf((float)(iy + dy), 0.0f, (float)(F->h - 1));
                float dv = F->depth[(size_t)yy * F->w + xx];
                dv = !(dv < FX_EDGE_FAR_DEPTH) ? FX_EDGE_FAR_DEPTH : dv < FX_EDGE_NEAR_DEPTH ? FX_EDGE_NEAR_DEPTH : dv;
                patch[(dy + 1) * 3 + dx + 1] = logf(dv);
            }
        float e = fx_edge_response_at(patch, 1, 3, 3, 1, 1, FX_EDGE_SOBEL);
        float t = p->edge_threshold;
        float line = t > 0.0f ? fx_smoothstep(t, 1.5f * t, e) : (e > 0.0f ? 1.0f : 0.0f);
        for (int k = 0; k < 3; k++)
            rgb[k] *= 1.0f - line;
    }
}

/* The reflected ray of the mirror pixel beside (x, y) at step (sx, sy), as differentials
 * of this pixel's (pos, rd): 0 where that pixel is not on the same smooth surface (outside
 * the frame or the mask, no surface, off this pixel's tangent plane by more than ~6 deg and
 * more than 2 % away in depth, or its normal more than ~45 deg away): a depth edge is not a
 * footprint. */
static int neighbour_ray(const ssr_job *j, int x, int y, int sx, int sy, fx_vec3 pos, fx_vec3 n, fx_vec3 rd,
                         fx_vec3 *dpos, fx_vec3 *ddir)
{
    const ssr_frame *F = j->F;
    int xn = x + sx, yn = y + sy;
    if (xn < 0 || yn < 0 || xn >= F->w || yn >= F->h || !in_mask(j->run->mask, F->w, xn, yn))
        return 0;
    float d;
    fx_vec3 q = view_pos_at(F, xn, yn, &d);
    if (fx_ssr_is_background(d) || !isfinite(q.x + q.y + q.z))
        return 0;
    fx_vec3 inc = F->view.orthographic ? fx_v3(0, 0, -1) : fx_v3_normalize_or(q, fx_v3(0, 0, -1));
    fx_vec3 nn;
    if (!shading_normal(j, xn, yn, q, inc, &nn) || fx_v3_dot(nn, n) < 0.7f || !mirror_ray_at(F, xn, yn))
        return 0;
    fx_vec3 dp = fx_v3_sub(q, pos);
    /* on this pixel's tangent plane, or at nearly its depth (a bent or normal-mapped mirror's
     * shading normal is not its surface's) */
    if (!(fabsf(fx_v3_dot(n, dp)) <= 0.1f * fx_v3_length(dp)) && !(fabsf(q.z - pos.z) <= 0.02f * fabsf(pos.z)))
        return 0;
    *dpos = dp;
    *ddir = fx_v3_sub(fx_v3_reflect(inc, nn), rd);
    return 1;
}

/* The pixel's ray differentials along x and y (math/panorama.h's fx_ray_diff): the
 * neighbour's reflected ray after it, or the one before it turned round; a pixel with
 * neither along an axis (a one-pixel sliver) gets no footprint along it. */
static void ray_diff_at(const ssr_job *j, int x, int y, fx_vec3 pos, fx_vec3 n, fx_vec3 rd, fx_ray_diff *df)
{
    memset(df, 0, sizeof *df);
    if (!neighbour_ray(j, x, y, 1, 0, pos, n, rd, &df->dox, &df->ddx) &&
        neighbour_ray(j, x, y, -1, 0, pos, n, rd, &df->dox, &df->ddx)) {
        df->dox = fx_v3_scale(df->dox, -1.0f);
        df->ddx = fx_v3_scale(df->ddx, -1.0f);
    }
    if (!neighbour_ray(j, x, y, 0, 1, pos, n, rd, &df->doy, &df->ddy) &&
        neighbour_ray(j, x, y, 0, -1, pos, n, rd, &df->doy, &df->ddy)) {
        df->doy = fx_v3_scale(df->doy, -1.0f);
        df->ddy = fx_v3_scale(df->ddy, -1.0f);
    }
}

/* Frame pixels spanned by view-space footprint axis e at view point c (c - e/2 to c + e/2
 * projected): the pixel offset, 0 if either end is behind the eye. */
static fx_vec2 screen_axis(const ssr_frame *F, fx_vec3 c, fx_vec3 e)
{
    fx_vec2 a = { 0.0f, 0.0f }, b = { 0.0f, 0.0f }, none = { 0.0f, 0.0f };
    fx_vec3 h = fx_v3_scale(e, 0.5f);
    if (!(fx_view_project(&F->view, fx_v3_sub(c, h), &a) > 0.0f) ||
        !(fx_view_project(&F->view, fx_v3_add(c, h), &b) > 0.0f))
        return none;
    fx_vec2 r = { b.x - a.x, b.y - a.y };
    return isfinite(r.x + r.y) ? r : none;
}

/* The reflected image over the pixel's footprint where its ray landed at (px, py) after
 * `length` along rd from ro (a first hit that bounces no further): the mean of a grid of
 * lookup taps over the footprint's projection, one per frame pixel it spans along each axis
 * (at most FX_FOOTPRINT_TAPS_MAX). Taps that land on a mirror pixel (this entry's or
 * mirror_surfaces') are left out: its backing is not what the ray sees. A footprint within
 * one pixel is the one tap at (px, py) (the same bits as without footprints). */
static void footprint_lookup(const ssr_job *j, fx_vec3 ro, fx_vec3 rd, float length, float px, float py,
                             const fx_ray_diff *df, float rgb[3])
{
    const ssr_frame *F = j->F;
    fx_vec3 c = fx_v3_add(ro, fx_v3_scale(rd, length));
    fx_vec2 ax = screen_axis(F, c, fx_v3_add(df->dox, fx_v3_scale(df->ddx, length)));
    fx_vec2 ay = screen_axis(F, c, fx_v3_add(df->doy, fx_v3_scale(df->ddy, length)));
    int nx = fx_footprint_taps(fmaxf(fabsf(ax.x), fabsf(ax.y)));
    int ny = fx_footprint_taps(fmaxf(fabsf(ay.x), fabsf(ay.y)));
    sample_lookup(j, px, py, rgb);
    if (nx == 1 && ny == 1)
        return;
    float sum[3] = { 0.0f, 0.0f, 0.0f }, tap[3];
    int n = 0;
    for (int b = 0; b < ny; b++)
        for (int a = 0; a < nx; a++) {
            float s = ((float)a + 0.5f) / (float)nx - 0.5f, r = ((float)b + 0.5f) / (float)ny - 0.5f;
            float tx = px + s * ax.x + r * ay.x, ty = py + s * ax.y + r * ay.y;
            int hx = pixel_of(tx, F->w), hy = pixel_of(ty, F->h);
            if (own_at(j, hx, hy) || (j->surfaces && j->surfaces->coverage[(size_t)hy * F->w + hx] > 0.5f))
                continue;
            sample_lookup(j, tx, ty, tap);
            for (int k = 0; k < 3; k++)
                sum[k] += tap[k];
            n++;
        }
    if (n > 0)
        for (int k = 0; k < 3; k++)
            rgb[k] = sum[k] / (float)n;
}

static void shade_rows(void *user, int begin, int end)
{
    ssr_job *j = user;
    const fx_effect_run *run = j->run;
    const ssr_params *p = j->p;
    const ssr_frame *F = j->F;
    const int w = run->width;
    const fx_mask *m = run->mask;
    for (int y = run->roi.y0 + begin; y < run->roi.y0 + end; y++)
        for (int x = run->roi.x0; x < run->roi.x1; x++) {
            size_t i = (size_t)y * w + x;
            const float *s = run->src + i * 4;
            float *o = j->out == run->dst
                           ? j->out + i * 4
                           : j->out + ((size_t)(y - j->fin_box.y0) * (j->fin_box.x1 - j->fin_box.x0) +
                                       (x - j->fin_box.x0)) * 4;
            if (j->out == run->dst)
                memcpy(o, s, 4 * sizeof(float));
            if (!in_mask(m, w, x, y))
                continue;
            cell_hit h = pixel_hit(j, x, y);
            if (j->own_only && !hit_on_own(j, &h))
                continue; /* reads no estimate: the previous iterate's value stands */
            if (j->reuse_fin && !hit_bounces(j, &h)) {
                /* a first hit that bounces no further: the final shading equals the
                 * estimate's (same lookup, same mix), which holds it */
                memcpy(o, j->fin + ((size_t)(y - j->fin_box.y0) * (j->fin_box.x1 - j->fin_box.x0) +
                                    (x - j->fin_box.x0)) * 4, 4 * sizeof(float));
                continue;
            }
            if (j->out != run->dst)
                memcpy(o, s, 4 * sizeof(float));
            float d;
            fx_vec3 pos = view_pos_at(F, x, y, &d);
            fx_vec3 inc = F->view.orthographic ? fx_v3(0, 0, -1) : fx_v3_normalize_or(pos, fx_v3(0, 0, -1));
            fx_vec3 n;
            if (fx_ssr_is_background(d) || !shading_normal(j, x, y, pos, inc, &n))
                continue; /* no surface: the texture stays */
            float refl[3], fb[3];
            float conf = h.state == 1 ? h.conf : 0.0f;
            fx_vec3 rd = fx_v3_reflect(inc, n);
            fx_ray_diff df;
            if (p->footprint)
                ray_diff_at(j, x, y, pos, n, rd, &df);
            int on_plane = j->planar_count ? planar_colour(j, x, y, pos, refl) : 0; /* 1 + its view */
            if (on_plane) {
                if (p->op == OP_SEPIA || p->op == OP_GRAYSCALE)
                    fx_color_op_apply3(j->opm, refl, refl);
                conf = 1.0f;
            } else if (j->probe && conf < 1.0f) {
                /* only where the fallback shows */
                const fx_pano *pr = probe_at(j, pos, n);
                if (p->footprint)
                    fx_pano_trace_footprint(pr, &j->pst, pos, rd, &df, fb);
                else
                    probe_colour(j, pr, pos, rd, fb);
                /* the probe's colour is the reflection there: the colour operator's too (as the
                 * planar view's; cel's outlines need the hit's depth edges: not on the probe) */
                if (p->op == OP_SEPIA || p->op == OP_GRAYSCALE)
                    fx_color_op_apply3(j->opm, fb, fb);
            } else if (p->fallback == FALLBACK_ENVIRONMENT)
                memcpy(fb, p->environment, sizeof fb);
            else
                memcpy(fb, s, sizeof fb);
            if (on_plane) {
                /* the mirrored camera's view: refl holds it */
            } else if (conf > 0.0f) {
                fx_vec3 ro = fx_v3_add(pos, fx_v3_scale(n, p->bias * fx_ssr_pixel_footprint(&F->view, d)));
                if (p->footprint && !hit_bounces(j, &h))
                    footprint_lookup(j, ro, rd, h.length, h.px, h.py, &df, refl);
                else
                    ray_colour(j, ro, rd, h.px, h.py, j->last_bounce, refl);
                if (p->op != OP_NONE)
                    apply_operator(j, h.px, h.py, refl);
                for (int k = 0; k < 3; k++)
                    refl[k] = fb[k] + (refl[k] - fb[k]) * conf;
            } else {
                memcpy(refl, fb, sizeof refl);
            }
            float wgt = mirror_weight(p, n, inc);
            for (int k = 0; k < 3; k++) {
                float v = s[k] * (1.0f - wgt) + refl[k] * wgt;
                o[k] = isfinite(v) ? v : s[k];
            }
            if (j->out != run->dst)
                continue; /* iterating the finished one-bounce image: no debug layers */
            if (j->dbg_hit)
                j->dbg_hit[i] = conf;
            if (j->dbg_xy) {
                j->dbg_xy[i * 3] = conf > 0 ? h.px : 0.0f;
                j->dbg_xy[i * 3 + 1] = conf > 0 ? h.py : 0.0f;
                j->dbg_xy[i * 3 + 2] = conf > 0 ? 1.0f : 0.0f;
            }
            if (j->dbg_len)
                j->dbg_len[i] = conf > 0 ? h.length : 0.0f;
            if (j->dbg_fb)
                j->dbg_fb[i] = 1.0f - conf;
            if (j->dbg_planar)
                j->dbg_planar[i] = (float)on_plane;
        }
}

/* With footprint: a pixel the mirror only partly covers (0 < coverage < 1: anti-aliased,
 * the rest is the object in front or the frame around it) takes the change its nearest
 * fully covered neighbour within 2 px got (dst - src there), which the stack scales by the
 * coverage. Its own ray is not the mirror's (Depth and Normal are not anti-aliased: they
 * may be the other surface's), and the stack's blend of a whole-pixel result keeps
 * coverage x (1 - coverage) of the mirror's backing in the pixel: a grey seam around
 * everything in front of the mirror. Reads only fully covered pixels, which this pass
 * does not write: any row order gives the same bits. */
static void edge_rows(void *user, int begin, int end)
{
    const ssr_job *j = user;
    const fx_effect_run *run = j->run;
    const float *cov = run->mask->coverage;
    const int w = run->width, h = run->height;
    for (int y = run->roi.y0 + begin; y < run->roi.y0 + end; y++)
        for (int x = run->roi.x0; x < run->roi.x1; x++) {
            size_t i = (size_t)y * w + x;
            if (!(cov[i] > 0.0f && cov[i] < EDGE_FULL))
                continue;
            long best = -1;
            int best_d = 9;
            for (int dy = -2; dy <= 2; dy++)
                for (int dx = -2; dx <= 2; dx++) {
                    int xx = x + dx, yy = y + dy, d2 = dx * dx + dy * dy;
                    if (xx < 0 || yy < 0 || xx >= w || yy >= h || d2 >= best_d)
                        continue;
                    size_t k = (size_t)yy * w + xx;
                    if (cov[k] >= EDGE_FULL) {
                        best = (long)k;
                        best_d = d2;
                    }
                }
            if (best < 0)
                continue; /* a sliver: its own result stands */
            const float *sn = run->src + (size_t)best * 4, *dn = run->dst + (size_t)best * 4;
            const float *s = run->src + i * 4;
            float *o = run->dst + i * 4;
            for (int k = 0; k < 3; k++) {
                /* the object in front can be darker than the neighbour's backing: the sum
                 * can fall below black, which no reflection is */
                float v = s[k] + (dn[k] - sn[k]);
                o[k] = isfinite(v) ? (v > 0.0f ? v : 0.0f) : s[k];
            }
        }
}

/* With footprint: a covered pixel whose Normal blends two of the mirror's faces was traced
 * with the face it holds most of (face_normal). Its colour is both faces' reflections in
 * their shares: the second face's is the change of the whole, covered neighbour within 2 px
 * (another face: its normal more than ~20 deg from the first's) whose normal best explains
 * what the first leaves of the pixel's mean normal N; the shares solve N = a n1 + b n2 in
 * least squares. Reads whole pixels only, which this pass does not write, so any row order
 * gives the same bits; runs before edge_rows, which reads the pixels it writes. */
#define FACE_APART 0.94f
static void two_face_rows(void *user, int begin, int end)
{
    const ssr_job *j = user;
    const fx_effect_run *run = j->run;
    const ssr_frame *F = j->F;
    const float *cov = run->mask ? run->mask->coverage : NULL;
    const int w = run->width, h = run->height;
    for (int y = run->roi.y0 + begin; y < run->roi.y0 + end; y++)
        for (int x = run->roi.x0; x < run->roi.x1; x++) {
            size_t i = (size_t)y * w + x;
            if ((cov && !(cov[i] >= EDGE_FULL)) || whole_surface(F, i))
                continue;
            const float *q = F->normal + i * F->nch;
            fx_vec3 nm = fx_v3(q[0], q[1], q[2]);
            if (!(fx_v3_dot(nm, nm) > 0.01f) || !isfinite(fx_v3_dot(nm, nm)))
                continue; /* no surface (surface_compute's test) */
            fx_vec3 n1 = nm;
            if (!face_normal(F, x, y, &n1))
                continue; /* traced with its own mean normal: no share to split */
            float m1 = fx_v3_dot(nm, n1);
            fx_vec3 rest = fx_v3_sub(nm, fx_v3_scale(n1, m1));
            long k2 = -1;
            float best = 0.0f;
            int best_d = 9;
            fx_vec3 n2 = n1;
            for (int dy = -2; dy <= 2; dy++)
                for (int dx = -2; dx <= 2; dx++) {
                    int xx = x + dx, yy = y + dy, d2 = dx * dx + dy * dy;
                    if (xx < 0 || yy < 0 || xx >= w || yy >= h)
                        continue;
                    size_t k = (size_t)yy * w + xx;
                    if ((cov && !(cov[k] >= EDGE_FULL)) || !whole_surface(F, k))
                        continue;
                    const float *qk = F->normal + k * F->nch;
                    fx_vec3 nk = fx_v3_normalize_or(fx_v3(qk[0], qk[1], qk[2]), n1);
                    float along = fx_v3_dot(nk, rest);
                    if (!(fx_v3_dot(nk, n1) < FACE_APART) || !(along > best || (along == best && d2 < best_d)))
                        continue;
                    k2 = (long)k;
                    best = along;
                    best_d = d2;
                    n2 = nk;
                }
            if (k2 < 0)
                continue; /* the other face has no whole pixel near: the first face alone */
            float c = fx_v3_dot(n1, n2), det = 1.0f - c * c, m2 = fx_v3_dot(nm, n2);
            float a = (m1 - c * m2) / det, b = (m2 - c * m1) / det;
            a = a > 0.0f ? a : 0.0f;
            b = b > 0.0f ? b : 0.0f;
            if (!(det > 1e-3f) || !(a + b > 0.0f) || !isfinite(a + b))
                continue;
            b /= a + b;
            const float *sn = run->src + (size_t)k2 * 4, *dn = run->dst + (size_t)k2 * 4;
            const float *s = run->src + i * 4;
            float *o = run->dst + i * 4;
            for (int k = 0; k < 3; k++) {
                float second = s[k] + (dn[k] - sn[k]);
                float v = (1.0f - b) * o[k] + b * (second > 0.0f ? second : 0.0f);
                o[k] = isfinite(v) ? v : o[k];
            }
        }
}

/* Centre, axes and extents of the mirror face (view space), serial in double: the same
 * bits for any thread count. */
static void fit_face(ssr_job *j)
{
    const fx_effect_run *run = j->run;
    const ssr_frame *F = j->F;
    double sp[3] = { 0, 0, 0 }, sn[3] = { 0, 0, 0 }, cnt = 0;
    for (int y = run->roi.y0; y < run->roi.y1; y++)
        for (int x = run->roi.x0; x < run->roi.x1; x++) {
            if (!in_mask(run->mask, F->w, x, y))
                continue;
            float d;
            fx_vec3 p = view_pos_at(F, x, y, &d);
            fx_vec3 n;
            if (fx_ssr_is_background(d) || !view_normal_at(F, x, y, &n))
                continue;
            sp[0] += p.x, sp[1] += p.y, sp[2] += p.z;
            sn[0] += n.x, sn[1] += n.y, sn[2] += n.z;
            cnt += 1;
        }
    j->face.valid = 0;
    if (cnt < 1)
        return;
    fx_vec3 c = fx_v3((float)(sp[0] / cnt), (float)(sp[1] / cnt), (float)(sp[2] / cnt));
    fx_vec3 n = fx_v3_normalize_or(fx_v3((float)sn[0], (float)sn[1], (float)sn[2]), fx_v3(0, 0, 1));
    /* tangent: the view's up x n (horizontal on the face), bitangent n x t */
    fx_vec3 up = fabsf(n.y) < 0.95f ? fx_v3(0, 1, 0) : fx_v3(1, 0, 0);
    fx_vec3 t = fx_v3_normalize_or(fx_v3_cross(up, n), fx_v3(1, 0, 0));
    fx_vec3 b = fx_v3_normalize_or(fx_v3_cross(n, t), fx_v3(0, 1, 0));
    double et = 0, eb = 0;
    for (int y = run->roi.y0; y < run->roi.y1; y++)
        for (int x = run->roi.x0; x < run->roi.x1; x++) {
            if (!in_mask(run->mask, F->w, x, y))
                continue;
            float d;
            fx_vec3 p = view_pos_at(F, x, y, &d);
            if (fx_ssr_is_background(d) || !isfinite(p.x + p.y + p.z))
                continue;
            fx_vec3 q = fx_v3_sub(p, c);
            double a = fabs(fx_v3_dot(q, t)), bb = fabs(fx_v3_dot(q, b));
            et = a > et ? a : et;
            eb = bb > eb ? bb : eb;
        }
    if (!(et > 1e-9) || !(eb > 1e-9) || !isfinite(et) || !isfinite(eb))
        return;
    j->face = (face_frame){ 1, c, t, b, (float)et, (float)eb };
}

static fx_pass_set ssr_passes(const void *params)
{
    const ssr_params *p = params;
    fx_pass_set set = FX_PASS_BIT(FX_PASS_DEPTH) | FX_PASS_BIT(FX_PASS_NORMAL);
    if (p->bounces > 1 && p->mirror_surfaces.spec) /* read only for second bounces */
        set |= fx_mask_spec_passes(p->mirror_surfaces.spec);
    return set;
}

/* Rays reach anywhere on the frame. */
static int ssr_halo(const void *params, int width, int height)
{
    (void)params;
    return width > height ? width : height;
}

static fx_result ssr_validate(const void *params, char *err, size_t err_size)
{
    const ssr_params *p = params;
    for (int k = 0; k < 3; k++)
        if (!isfinite(p->environment[k])) {
            snprintf(err, err_size, "environment_color[%d] is not finite", k);
            return FX_ERR_BAD_PARAM;
        }
    return FX_OK;
}

/* Process stage 1: the frame's camera, Depth and Normal as the tracer's scene. F must
 * not move afterwards (its scene points at F->view). */
static fx_result ssr_frame_init(const fx_effect_run *run, ssr_frame *F)
{
    const char *where = run->where;
    memset(F, 0, sizeof *F);
    F->w = run->width;
    F->h = run->height;
    if (!fx_view_init(&F->view, run->frame))
        return fx_fail(run->ctx, FX_ERR_NO_CAMERA, "%s: the frame has no usable camera (missing or singular matrices)",
                       where);
    fx_pass *dp = fx_frame_find_pass(run->frame, "Depth");
    fx_pass *np = fx_frame_find_pass(run->frame, "Normal");
    if (!dp || !np)
        return fx_fail(run->ctx, FX_ERR_MISSING_PASS, "%s needs the %s pass", where, !dp ? "Depth" : "Normal");
    if (np->channels < 3)
        return fx_fail(run->ctx, FX_ERR_MISSING_PASS, "%s: the Normal pass has %d channels, 3 needed", where,
                       np->channels);
    F->depth = dp->data;
    F->normal = np->data;
    F->nch = np->channels;
    F->mask = run->mask;
    F->face_normals = ((const ssr_params *)run->params)->footprint;
    F->scene = (fx_ssr_scene){ &F->view, F->depth, F->w, F->h, front_facing, surface_plane, F, NULL };
    return FX_OK;
}

/* Process stage 2: the rays, one per cell of resolution_scale (through the depth
 * pyramid when hiz), resolved to one hit per ROI pixel in j->hits. */
static fx_result ssr_trace_hits(const fx_effect_run *run, ssr_job *j, ssr_frame *F, fx_depth_pyramid *pyr,
                                size_t hits_bytes)
{
    const ssr_params *p = run->params;
    const fx_rect *roi = &run->roi;
    fx_result r;
    int cell = 1;
    while (cell < 16 && (float)(cell * 2) <= 1.0f / p->resolution_scale + 1e-4f)
        cell *= 2;
    j->cell = cell;
    j->cx0 = roi->x0 / cell;
    j->cy0 = roi->y0 / cell;
    j->ncx = (roi->x1 - 1) / cell - j->cx0 + 1;
    j->ncy = (roi->y1 - 1) / cell - j->cy0 + 1;
    /* scratch buffers come from the context's store in frame-sized units, so the ten
     * entries of a mirror room reuse memory already mapped instead of page-faulting
     * fresh buffers (every byte read below is written first) */
    if ((r = fx_check_budget(run->ctx, 2 * hits_bytes, "the ray hits")))
        return r;
    /* one scratch for the cells and the resolved hits (each at most one per frame pixel) */
    j->cells = fx_buffer_get(run->ctx, 2 * hits_bytes);
    if (!j->cells)
        return fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for %d x %d ray cells", run->where, j->ncx,
                       j->ncy);
    if (p->hiz) {
        if ((r = fx_check_budget(run->ctx, (size_t)F->w * F->h / 3 * sizeof(float) + 64, "the depth pyramid")) ||
            (r = fx_depth_pyramid_build(run->ctx, F->depth, F->w, F->h, 12, run->where, pyr)))
            return r;
        F->scene.hiz = pyr;
    }
    fx_parallel_for(run->ctx, j->ncy, 1, trace_cells, j);
    const int rows = roi->y1 - roi->y0;
    if (cell == 1) {
        j->hits = j->cells; /* one cell per roi pixel, same layout */
    } else {
        j->hits = j->cells + (size_t)F->w * F->h;
        fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), resolve_rows, j);
    }
    return FX_OK;
}

/* Process stage 3: the image reflections are looked up in; for glossiness, src blurred
 * over the hits' bounding box only (*blurred, frame-sized). */
static fx_result ssr_glossy_lookup(const fx_effect_run *run, ssr_job *j, float **blurred, size_t frame_bytes)
{
    const ssr_params *p = run->params;
    const fx_rect *roi = &run->roi;
    const ssr_frame *F = j->F;
    const int cell = j->cell, rows = roi->y1 - roi->y0;
    const size_t rw = (size_t)(roi->x1 - roi->x0);
    j->lookup = run->src;
    j->lookup_box = (fx_rect){ 0, 0, F->w, F->h };
    fx_blur_spec bs = { p->glossiness, FX_BLUR_RECURSIVE, 3 };
    if (fx_blur_is_identity(&bs))
        return FX_OK;
    /* blur only the hits' bounding box (+1 px for the bilinear lookup) */
    float bx0 = 1e30f, by0 = 1e30f, bx1 = -1e30f, by1 = -1e30f;
    for (size_t k = 0; k < rw * rows; k++) {
        const cell_hit *c = &j->hits[k];
        if (c->state == 1 && c->conf > 0.0f) {
            bx0 = fminf(bx0, c->px), by0 = fminf(by0, c->py);
            bx1 = fmaxf(bx1, c->px), by1 = fmaxf(by1, c->py);
        }
    }
    if (!(bx1 >= bx0))
        return FX_OK;
    fx_rect br = { (int)floorf(bx0) - 2 - cell, (int)floorf(by0) - 2 - cell, (int)ceilf(bx1) + 2 + cell,
                   (int)ceilf(by1) + 2 + cell };
    br.x0 = br.x0 < 0 ? 0 : br.x0;
    br.y0 = br.y0 < 0 ? 0 : br.y0;
    br.x1 = br.x1 > F->w ? F->w : br.x1;
    br.y1 = br.y1 > F->h ? F->h : br.y1;
    fx_result r = fx_check_budget(run->ctx, frame_bytes, "the glossy reflection lookup");
    if (r)
        return r;
    *blurred = fx_buffer_get(run->ctx, frame_bytes);
    if (!*blurred)
        return fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the glossy lookup", run->where);
    /* outside br the lookup is never read (hits lie inside, bilinear reads +1) */
    for (int y = br.y0; y < br.y1; y++)
        memcpy(*blurred + ((size_t)y * F->w + br.x0) * 4, run->src + ((size_t)y * F->w + br.x0) * 4,
               (size_t)(br.x1 - br.x0) * 4 * sizeof(float));
    if ((r = fx_blur_image(run->ctx, run->src, *blurred, F->w, F->h, 4, &bs, &br, run->where)))
        return r;
    j->lookup = *blurred;
    j->lookup_box = br;
    return FX_OK;
}

/* Whether the shading reads the finished one-bounce image: only a ray that lands on this
 * entry's own mirror reads it, and without mirror_surfaces only first hits can (the
 * recursion starts only on own pixels). A flat mirror never sees itself: its three
 * estimate iterations would be computed and never read. Serial, O(ROI). */
static int ssr_needs_estimate(const ssr_job *j)
{
    if (j->surfaces)
        return 1;
    const fx_rect *roi = &j->run->roi;
    const size_t n = (size_t)(roi->x1 - roi->x0) * (size_t)(roi->y1 - roi->y0);
    for (size_t k = 0; k < n; k++)
        if (hit_on_own(j, &j->hits[k]))
            return 1;
    return 0;
}

/* Process stage 4 (bounces > 1 under a mask): the finished one-bounce image of this
 * mirror, Jacobi-iterated on the first-bounce hits (a ray landing on this mirror sees its
 * previous iterate): the estimate where the traced bounces run out. Two buffers over the
 * mask's bounds + 2 px (lookup elsewhere), from one frame-sized pair in fin[0]. */
static fx_result ssr_multi_bounce(const fx_effect_run *run, ssr_job *j, float *fin[2], size_t frame_bytes)
{
    const fx_rect *roi = &run->roi;
    const ssr_frame *F = j->F;
    const int rows = roi->y1 - roi->y0;
    fx_rect fb = { roi->x0 - 2, roi->y0 - 2, roi->x1 + 2, roi->y1 + 2 };
    fb.x0 = fb.x0 < 0 ? 0 : fb.x0;
    fb.y0 = fb.y0 < 0 ? 0 : fb.y0;
    fb.x1 = fb.x1 > F->w ? F->w : fb.x1;
    fb.y1 = fb.y1 > F->h ? F->h : fb.y1;
    j->fin_box = fb;
    size_t bw = (size_t)(fb.x1 - fb.x0);
    fx_result r = fx_check_budget(run->ctx, 2 * frame_bytes, "the mirror's multi-bounce estimate");
    if (r)
        return r;
    fin[0] = fx_buffer_get(run->ctx, 2 * frame_bytes);
    fin[1] = fin[0] ? fin[0] + (size_t)F->w * F->h * 4 : NULL;
    if (!fin[0])
        return fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the multi-bounce estimate", run->where);
    for (int y = fb.y0; y < fb.y1; y++)
        for (int x = fb.x0; x < fb.x1; x++) {
            const fx_rect *lb = &j->lookup_box;
            int in = x >= lb->x0 && x < lb->x1 && y >= lb->y0 && y < lb->y1;
            const float *sp = (in ? j->lookup : run->src) + ((size_t)y * F->w + x) * 4;
            size_t o = ((size_t)(y - fb.y0) * bw + (x - fb.x0)) * 4;
            memcpy(fin[0] + o, sp, 4 * sizeof(float)); /* fin[1]: a copy after the first iteration */
        }
    j->last_bounce = 0;
    j->fin = NULL;
    /* Jacobi iterations: a pixel whose first hit misses this mirror reads no estimate, so
     * it has the same value in every iterate. The first iteration shades every pixel and
     * is copied to the other buffer; the later ones redo only the pixels seeing this
     * mirror (the same bits as shading all of them). */
    for (int it = 0; it < FIN_ITERATIONS; it++) {
        j->out = fin[it & 1];
        j->own_only = it > 0;
        fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), shade_rows, j);
        j->fin = j->out;
        if (it == 0)
            memcpy(fin[1], fin[0], (size_t)(fb.y1 - fb.y0) * bw * 4 * sizeof(float));
    }
    j->own_only = 0;
    return FX_OK;
}

/* One probe (aux view `name`) into *pano, in the frame's view space; 0 when it is
 * unusable (a warning), 1 when loaded, or an error (out of memory). */
static fx_result probe_load_one(const fx_effect_run *run, const ssr_frame *F, const char *name, fx_aux_map *pm,
                                fx_pano *pano, int *loaded)
{
    *loaded = 0;
    /* from the context's cache: a batch or a live session decodes each probe once */
    fx_result r = fx_aux_view_acquire(run->frame, name, run->where, pm);
    if (r == FX_ERR_OUT_OF_MEMORY)
        return r;
    if (!r && !pm->av->panorama) {
        fx_warn(run->ctx, "%s: aux view '%s' is not a panorama (\"panorama\": \"equirect\"): missed rays take "
                "the mirror's texture", run->where, name);
        fx_aux_map_release(pm);
        return FX_OK;
    }
    if (r) {
        char msg[1024];
        snprintf(msg, sizeof msg, "%s", fx_context_error(run->ctx));
        fx_warn(run->ctx, "%s: no reflection probe (%s): missed rays take the mirror's texture", run->where, msg);
        return FX_OK;
    }
    const fx_aux_view *av = pm->av;
    pano->color = av->color;
    pano->depth = av->depth;
    pano->sky = av->sky;
    pano->w = av->width;
    pano->h = av->height;
    fx_m4_mul(av->view.cam.world_to_camera, F->view.camera_to_world, pano->to_probe);
    *loaded = 1;
    return FX_OK;
}

/* Process stage 0 (fallback probe): the entry's reflection probes, "probe:<key>" and, for
 * a mirror whose planes face different ways (a facing pair), "probe:<key>#2", ... while
 * the frame has them, in the frame's view space (j->probes; j->probe the first). Missing or
 * unreadable: a warning, and the texture fallback where no probe is left. pm[] and pano[]
 * receive them (released by the caller). */
static fx_result ssr_probe_load(const fx_effect_run *run, ssr_job *j, const ssr_frame *F,
                                fx_aux_map pm[PROBES_MAX], fx_pano pano[PROBES_MAX])
{
    const ssr_params *p = run->params;
    for (int k = 0; k < PROBES_MAX; k++) {
        char name[FX_NAME_MAX];
        if (k == 0)
            snprintf(name, sizeof name, FX_AUX_PROBE "%s", run->mask_key ? run->mask_key : "");
        else
            snprintf(name, sizeof name, FX_AUX_PROBE "%s#%d", run->mask_key ? run->mask_key : "", k + 1);
        if (k > 0) {
            int has = fx_aux_view_has(run->frame, name);
            if (has < 0)
                return fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory reading the frame's aux views",
                               run->where);
            if (!has)
                break;
        }
        int loaded;
        fx_result r = probe_load_one(run, F, name, &pm[k], &pano[k], &loaded);
        if (r)
            return r;
        if (!loaded)
            continue;
        /* its centre in view space: to_probe is rigid (R, t), the centre is -R^T t */
        const float *m = pano[k].to_probe;
        fx_vec3 c = fx_v3(-(m[0] * m[3] + m[4] * m[7] + m[8] * m[11]), -(m[1] * m[3] + m[5] * m[7] + m[9] * m[11]),
                          -(m[2] * m[3] + m[6] * m[7] + m[10] * m[11]));
        j->probe_at_view[j->probe_count] = c;
        j->probes[j->probe_count++] = &pano[k];
    }
    j->probe = j->probe_count ? j->probes[0] : NULL;
    if (j->probe)
        j->pst = fx_pano_trace_setup(p->probe_steps, p->refine, 0.02f, p->max_distance, 0.05f);
    return FX_OK;
}

/* Process stage 0 (planar_view): the entry's mirrored-camera views, one per plane
 * ("planar:<key>", then "planar:<key>#2", ... while the frame has them), as j->planar.
 * A view listed as absent (the add-on's word for a curved mirror): none, silently; a
 * missing or unusable one (a CLI run without it, a failed render): a warning. The trace
 * serves their pixels. pm[] receives the views, from the context's cache as the probe
 * (released by the caller). */
static fx_result ssr_planar_load(const fx_effect_run *run, ssr_job *j, fx_aux_map pm[PLANAR_VIEWS_MAX])
{
    for (int k = 0; k < PLANAR_VIEWS_MAX; k++) {
        char name[FX_NAME_MAX];
        if (k == 0)
            snprintf(name, sizeof name, FX_AUX_PLANAR "%s", run->mask_key ? run->mask_key : "");
        else
            snprintf(name, sizeof name, FX_AUX_PLANAR "%s#%d", run->mask_key ? run->mask_key : "", k + 1);
        int has = fx_aux_view_has(run->frame, name);
        if (has < 0)
            return fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory reading the frame's aux views",
                           run->where);
        /* not rendered on purpose (the add-on found the mirror not flat): the trace and the
         * fallback serve, and nothing is wrong; a later plane not listed: no more planes */
        if (has == FX_AUX_ABSENT || (k > 0 && !has))
            break;
        fx_result r = fx_aux_view_acquire(run->frame, name, run->where, &pm[k]);
        if (r == FX_ERR_OUT_OF_MEMORY)
            return r;
        if (r || !pm[k].av->color || !pm[k].av->has_plane || pm[k].av->panorama) {
            char msg[1024];
            snprintf(msg, sizeof msg, "%s", r ? fx_context_error(run->ctx) : "it has no colour pass or no \"plane\"");
            fx_warn(run->ctx, "%s: no planar mirror view '%s' (%s): the trace and the fallback serve", run->where,
                    name, msg);
            fx_aux_map_release(&pm[k]);
            continue;
        }
        j->planar[j->planar_count++] = pm[k].av;
    }
    return FX_OK;
}

static fx_result ssr_process(const fx_effect_run *run)
{
    const ssr_params *p = run->params;
    const fx_rect *roi = &run->roi;
    const char *where = run->where;
    ssr_frame F;
    fx_result r = ssr_frame_init(run, &F);
    if (r)
        return r;
    /* the surfaces' memo: plane constants, normals, states (zeroed: only these) */
    const size_t npix = (size_t)F.w * F.h, surf_bytes = npix * (sizeof(double) + 3 * sizeof(float) + 1);
    if ((r = fx_check_budget(run->ctx, surf_bytes, "the surfaces' memo")))
        return r;
    void *surf = fx_buffer_get(run->ctx, surf_bytes);
    if (!surf)
        return fx_fail(run->ctx, FX_ERR_OUT_OF_MEMORY, "%s: out of memory for the surfaces' memo", where);
    F.splane_c = surf;
    F.snormal = (float *)(F.splane_c + npix);
    F.sstate = (_Atomic unsigned char *)(F.snormal + 3 * npix);
    memset((void *)F.sstate, 0, npix);
    ssr_job j;
    memset(&j, 0, sizeof j);
    j.run = run;
    j.p = p;
    j.F = &F;
    j.st = (fx_ssr_settings){ p->max_steps, p->stride, p->growth, p->refine, p->thickness, p->max_distance };
    fx_color_op_matrix(p->op == OP_SEPIA ? FX_COLOR_OP_SEPIA : FX_COLOR_OP_GRAY_LUMINANCE, j.opm);
    if (p->bend != 0.0f)
        fit_face(&j);
    fx_aux_map probe_maps[PROBES_MAX];
    memset(probe_maps, 0, sizeof probe_maps);
    fx_pano panos[PROBES_MAX];
    memset(panos, 0, sizeof panos);
    fx_aux_map planar_maps[PLANAR_VIEWS_MAX];
    memset(planar_maps, 0, sizeof planar_maps);
    fx_mask *surfaces = NULL;
    float *blurred = NULL, *fin[2] = { NULL, NULL };
    const size_t frame_bytes = (size_t)F.w * F.h * 4 * sizeof(float);
    const size_t hits_bytes = (size_t)F.w * F.h * sizeof(cell_hit);
    fx_depth_pyramid pyr;
    memset(&pyr, 0, sizeof pyr);
    if (p->fallback == FALLBACK_PROBE && (r = ssr_probe_load(run, &j, &F, probe_maps, panos)))
        goto out;
    if (p->planar_view && p->glossiness == 0.0f && p->bend == 0.0f && p->op != OP_CEL &&
        (r = ssr_planar_load(run, &j, planar_maps)))
        goto out; /* releases the probe and the views loaded so far */

    if (p->bounces > 1 && p->mirror_surfaces.spec) {
        r = fx_mask_build(run->ctx, p->mirror_surfaces.spec, run->frame, where, &surfaces);
        if (r)
            goto out; /* frees the probe and planar views */
        j.surfaces = surfaces;
        F.surfaces = surfaces;
    }
    if ((r = ssr_trace_hits(run, &j, &F, &pyr, hits_bytes)) || (r = ssr_glossy_lookup(run, &j, &blurred, frame_bytes)))
        goto out;
    j.dbg_hit = fx_effect_debug_pass(run, "hit", 1, &r);
    if (!r)
        j.dbg_xy = fx_effect_debug_pass(run, "hit_xy", 3, &r);
    if (!r)
        j.dbg_len = fx_effect_debug_pass(run, "ray_length", 1, &r);
    if (!r) /* the fallback in use, by name; its weight per pixel */
        j.dbg_fb = fx_effect_debug_pass(run, j.probe ? "fallback_probe"
                                             : p->fallback == FALLBACK_ENVIRONMENT ? "fallback_environment"
                                                                                   : "fallback_texture", 1, &r);
    if (!r && j.planar_count) /* 1 + the index of the planar view a pixel took, 0 for none */
        j.dbg_planar = fx_effect_debug_pass(run, "planar", 1, &r);
    if (r || (p->bounces > 1 && run->mask && ssr_needs_estimate(&j) && (r = ssr_multi_bounce(run, &j, fin, frame_bytes))))
        goto out;
    /* stage 5: the mirror shaded into dst */
    const int rows = roi->y1 - roi->y0;
    j.out = run->dst;
    j.last_bounce = p->bounces - 1;
    j.reuse_fin = j.fin && !j.dbg_hit && !j.dbg_xy && !j.dbg_len && !j.dbg_fb && !j.dbg_planar;
    fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), shade_rows, &j);
    if (p->footprint)
        fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), two_face_rows, &j);
    if (p->footprint && run->mask)
        fx_parallel_for(run->ctx, rows, fx_grain_for(run->ctx, rows), edge_rows, &j);
out:
    fx_buffer_put(run->ctx, surf, surf_bytes);
    fx_buffer_put(run->ctx, fin[0], 2 * frame_bytes);
    fx_buffer_put(run->ctx, j.cells, 2 * hits_bytes);
    fx_buffer_put(run->ctx, blurred, frame_bytes);
    fx_mask_free(surfaces);
    fx_depth_pyramid_free(run->ctx, &pyr);
    for (int k = 0; k < PROBES_MAX; k++)
        fx_aux_map_release(&probe_maps[k]);
    for (int k = 0; k < PLANAR_VIEWS_MAX; k++)
        fx_aux_map_release(&planar_maps[k]);
    return r;
}

/* fallback probe: this entry's probe ("probe:<mask key>", placed by the add-on at the
 * entry's mask). */
static int ssr_aux_views(const void *params, fx_aux_need *out, int max)
{
    const ssr_params *p = params;
    int n = 0;
    if (p->fallback == FALLBACK_PROBE && n < max) {
        memset(&out[n], 0, sizeof out[n]);
        snprintf(out[n].name, sizeof out[n].name, "%s", FX_AUX_PROBE);
        out[n].kind = "probe";
        out[n].per_mask = 1;
        n++;
    }
    if (p->planar_view && p->glossiness == 0.0f && p->bend == 0.0f && p->op != OP_CEL && n < max) {
        memset(&out[n], 0, sizeof out[n]);
        snprintf(out[n].name, sizeof out[n].name, "%s", FX_AUX_PLANAR);
        out[n].kind = "planar";
        out[n].per_mask = 1;
        out[n].samples_scale = p->planar_samples;
        n++;
    }
    return n;
}

/* params_version 2 added footprint (default on): a recipe of version 1 keeps one lookup per
 * pixel (footprint off) unless it names one. Silent: its output is the same as before.
 * params_version 3 added planar_samples (default 2): a planar view used to render at 4x
 * the render's samples, so a recipe of version 2 that turns planar_view on itself keeps 4
 * unless it names planar_samples (the same view, the same output; the presets set theirs). */
static fx_result ssr_migrate(int from_version, cJSON *params, char *note, size_t note_size)
{
    (void)note;
    (void)note_size;
    if (!params)
        return FX_OK;
    if (from_version == 1 && !cJSON_GetObjectItemCaseSensitive(params, "footprint") &&
        !cJSON_AddBoolToObject(params, "footprint", 0))
        return FX_ERR_OUT_OF_MEMORY;
    if (from_version == 2 && cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(params, "planar_view")) &&
        !cJSON_GetObjectItemCaseSensitive(params, "planar_samples") &&
        !cJSON_AddNumberToObject(params, "planar_samples", 4))
        return FX_ERR_OUT_OF_MEMORY;
    return FX_OK;
}

const fx_effect_class fx_effect_ssr_mirror = {
    .name = "ssr_mirror",
    .doc = "Screen-space ray-traced mirror (McGuire & Mara 2014) on the masked pixels: reflectivity, "
           "glossiness, Fresnel, colour operator, bending, double reflections",
    .params_size = sizeof(ssr_params),
    .params = ssr_param_defs,
    .param_count = FX_COUNT_OF(ssr_param_defs),
    .presets = {
        "{\"max_steps\": 48, \"stride\": 2, \"growth\": 1.08, \"refine\": 3, \"resolution_scale\": 0.25, "
        "\"retrace_edges\": false, \"footprint\": false}",
        "{\"max_steps\": 96, \"stride\": 1.5, \"growth\": 1.04, \"refine\": 6, \"resolution_scale\": 0.5, "
        "\"retrace_edges\": true, \"footprint\": false}",
        "{\"max_steps\": 96, \"stride\": 1.5, \"growth\": 1.04, \"refine\": 6, \"resolution_scale\": 1, "
        "\"fallback\": \"probe\", \"probe_steps\": 48, \"planar_view\": true, \"planar_samples\": 2, "
        "\"footprint\": true}",
        "{\"max_steps\": 4096, \"stride\": 1, \"growth\": 1, \"refine\": 10, \"resolution_scale\": 1, "
        "\"fallback\": \"probe\", \"probe_steps\": 160, \"planar_view\": true, \"planar_samples\": 4, "
        "\"footprint\": true}",
    },
    .passes = ssr_passes,
    .aux_views = ssr_aux_views,
    .flags = FX_EFFECT_NEEDS_CAMERA,
    .halo = ssr_halo,
    .validate = ssr_validate,
    .process = ssr_process,
    .params_version = 3,
    .migrate = ssr_migrate,
};
