/* The rain map: see rain_map.h. */
#include "scene/rain_map.h"
#include "core/effect.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

int fx_aux_needs_rain_map(const void *params, fx_aux_need *out, int max)
{
    (void)params;
    if (max < 1)
        return 0;
    memset(out, 0, sizeof *out);
    snprintf(out->name, sizeof out->name, "%s", FX_AUX_RAIN_MAP);
    out->kind = "rain_map";
    return 1;
}

static float texel_size(const fx_aux_view *av)
{
    /* the projection's x scale maps [-1, 1] NDC over the width */
    float sx = av->view.cam.projection[0];
    return fabsf(sx) > 1e-20f ? 2.0f / fabsf(sx) / (float)av->width : 0.0f;
}

fx_result fx_rain_map_load(const fx_frame *f, float soft_width_metres, const char *where, fx_rain_map *out)
{
    memset(out, 0, sizeof *out);
    fx_result r = fx_aux_map_acquire(f, FX_AUX_RAIN_MAP, 0, -1, 0.0f, where, &out->map);
    if (r)
        return r;
    float texel = texel_size(out->map.av);
    float width = texel > 0.0f && soft_width_metres > 0.0f ? soft_width_metres / texel : 0.0f;
    if (width > 1.0f) {
        /* the texel size is known once the map is read: the filtered map is a second entry */
        fx_aux_map filtered;
        r = fx_aux_map_acquire(f, FX_AUX_RAIN_MAP, 0, FX_SHADOW_FILTER_BOX_SAT, width, where, &filtered);
        fx_aux_map_release(&out->map);
        if (r)
            return r;
        out->map = filtered;
    }
    out->av = out->map.av;
    out->sm = *out->map.sm;
    out->eps = fx_shadow_map_norm_dist(&out->sm, 0.05f);
    out->texel_metres = texel;
    return FX_OK;
}

void fx_rain_map_free(fx_rain_map *rm)
{
    if (!rm)
        return;
    fx_aux_map_release(&rm->map);
    memset(rm, 0, sizeof *rm);
}
