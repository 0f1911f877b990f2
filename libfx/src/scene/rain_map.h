/* The rain map (aux view "rain_map": a top-down orthographic depth view over the rain
 * area) read as a shadow map of rain falling straight down: a world point is exposed to
 * the sky when nothing in the map lies above it (the seed's height-camera test). Points
 * outside the map are exposed (open sky beyond the modelled area). Shared by rain,
 * wet_surfaces and rain_splashes. */
#ifndef LIBFX_SCENE_RAIN_MAP_H
#define LIBFX_SCENE_RAIN_MAP_H

#include "math/shadow_map.h"
#include "scene/aux_map.h"
#include "scene/aux_view.h"

typedef struct fx_rain_map {
    const fx_aux_view *av;
    fx_shadow_map sm;   /* a shallow copy of the cached map's (borrowed arrays) */
    fx_aux_map map;     /* what fx_rain_map_free releases */
    float eps;          /* normalised depth tolerance of the hard test */
    float texel_metres; /* world size of one texel (x) */
} fx_rain_map;

/* The aux_views callback of every effect that reads the rain map: it asks for the view
 * FX_AUX_RAIN_MAP. */
struct fx_aux_need;
int fx_aux_needs_rain_map(const void *params, struct fx_aux_need *out, int max);

/* Loads the frame's rain map (through the context's cache, scene/aux_map.h); soft_width
 * metres > 0 also filters its moments (box, SAT) over that width for fx_rain_map_soft. */
fx_result fx_rain_map_load(const fx_frame *f, float soft_width_metres, const char *where, fx_rain_map *out);
void fx_rain_map_free(fx_rain_map *rm);

/* 1: exposed, 0: under cover (hard test at the nearest texel). */
static inline float fx_rain_map_exposed(const fx_rain_map *rm, fx_vec3 p)
{
    float px, py, d;
    if (!fx_aux_view_project(rm->av, p, &px, &py, &d))
        return 1.0f;
    if (!(px >= 0.0f && py >= 0.0f && px < (float)rm->sm.width && py < (float)rm->sm.height))
        /* also NaN (a hostile Position/Depth): never index the map with it */
        return 1.0f;
    return fx_shadow_map_hard(&rm->sm, px, py, fx_shadow_map_norm(&rm->sm, d), rm->eps);
}

/* Exposure in [0, 1] with soft edges at cover boundaries: the VSM bound over the filtered
 * rain map (one lookup, no ring of samples). */
static inline float fx_rain_map_soft(const fx_rain_map *rm, fx_vec3 p)
{
    float px, py, d;
    if (!fx_aux_view_project(rm->av, p, &px, &py, &d))
        return 1.0f;
    if (!(px >= 0.0f && py >= 0.0f && px < (float)rm->sm.width && py < (float)rm->sm.height))
        /* also NaN (a hostile Position/Depth): never index the map with it */
        return 1.0f;
    if (!rm->sm.moments) /* an unfiltered map (soft width under a texel): the hard test */
        return fx_shadow_map_hard(&rm->sm, px, py, fx_shadow_map_norm(&rm->sm, d), rm->eps);
    float m1, m2;
    fx_shadow_map_moments(&rm->sm, px, py, &m1, &m2);
    float ms = fx_shadow_map_norm_dist(&rm->sm, 0.02f);
    return fx_vsm_visibility(m1, m2, fx_shadow_map_norm(&rm->sm, d), ms * ms, 0.2f, rm->eps);
}

#endif
