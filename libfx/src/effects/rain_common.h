/* What the rain-map effects (rain, rain_splashes, wet_surfaces) do first and last: the
 * surface source (camera, Depth, and Normal when they shade by it), the frame's rain map
 * (through the context's cache) and their one debug pass; at the end the map goes back to
 * the cache. Header-only: every .c file in effects/ is an effect (the registry is made
 * from their names). */
#ifndef LIBFX_EFFECTS_RAIN_COMMON_H
#define LIBFX_EFFECTS_RAIN_COMMON_H

#include "core/effect.h"
#include "scene/rain_map.h"
#include "math/surface.h"

/* need_normal: the effect shades by the Normal pass. soft_width: metres of moment
 * filtering of the map (0: the hard test only). debug_pass: the effect's one debug pass
 * (*dbg NULL when debug outputs are off). On failure nothing is held. */
static inline fx_result fx_rain_effect_begin(const fx_effect_run *run, int need_normal, float soft_width,
                                             const char *debug_pass, fx_surface_src *surf, fx_rain_map *rm,
                                             float **dbg)
{
    if (!fx_surface_src_init(surf, run->frame))
        return need_normal ? fx_fail(run->ctx, FX_ERR_NO_CAMERA,
                                     "%s needs the camera and the Depth and Normal passes", run->where)
                           : fx_fail(run->ctx, FX_ERR_NO_CAMERA, "%s needs the camera and the Depth pass",
                                     run->where);
    if (need_normal && !surf->normal)
        return fx_fail(run->ctx, FX_ERR_NO_CAMERA, "%s needs the camera and the Depth and Normal passes",
                       run->where);
    fx_result r = fx_rain_map_load(run->frame, soft_width, run->where, rm);
    if (r)
        return r;
    *dbg = fx_effect_debug_pass(run, debug_pass, 1, &r);
    if (!*dbg && r) {
        fx_rain_map_free(rm);
        return r;
    }
    return FX_OK;
}

/* Gives the rain map back and returns r (the effect's result). */
static inline fx_result fx_rain_effect_end(fx_rain_map *rm, fx_result r)
{
    fx_rain_map_free(rm);
    return r;
}

#endif
