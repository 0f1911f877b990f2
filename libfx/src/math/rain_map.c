/* The rain map: see rain_map.h. */
#include "math/rain_map.h"

#include <math.h>
#include <string.h>

fx_result fx_rain_map_load(const fx_frame *f, float soft_width_texels, const char *where, fx_rain_map *out)
{
    memset(out, 0, sizeof *out);
    fx_result r = fx_aux_view_load(f, FX_AUX_RAIN_MAP, where, &out->av);
    if (r)
        return r;
    const fx_aux_view *av = out->av;
    r = fx_shadow_map_build(f->ctx, av->depth, av->width, av->height, av->view.cam.clip_start,
                            av->view.cam.clip_end, 0, &out->sm, where);
    if (!r && soft_width_texels > 1.0f)
        r = fx_shadow_map_filter(f->ctx, &out->sm, FX_SHADOW_FILTER_BOX_SAT, soft_width_texels, where);
    if (r) {
        fx_rain_map_free(out);
        return r;
    }
    out->eps = fx_shadow_map_norm_dist(&out->sm, 0.05f);
    /* texel size: the projection's x scale maps [-1, 1] NDC over the width */
    float sx = av->view.cam.projection[0];
    out->texel_metres = fabsf(sx) > 1e-20f ? 2.0f / fabsf(sx) / (float)av->width : 0.0f;
    return FX_OK;
}

void fx_rain_map_free(fx_rain_map *rm)
{
    if (!rm)
        return;
    fx_shadow_map_free(&rm->sm);
    fx_aux_view_free(rm->av);
    rm->av = NULL;
}
