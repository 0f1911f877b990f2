/* The registry: every effect the library ships, in the order `libfx list` shows them. */
#include "core/effect.h"

#include <string.h>

extern const fx_effect_class fx_effect_gaussian_blur;
extern const fx_effect_class fx_effect_color_matrix;
extern const fx_effect_class fx_effect_pixelate;
extern const fx_effect_class fx_effect_god_rays;
extern const fx_effect_class fx_effect_voronoi_caustics;
extern const fx_effect_class fx_effect_ssr_mirror;
extern const fx_effect_class fx_effect_vsm_shadows;
extern const fx_effect_class fx_effect_edges;
extern const fx_effect_class fx_effect_posterize;
extern const fx_effect_class fx_effect_sin_city;
extern const fx_effect_class fx_effect_rain;
extern const fx_effect_class fx_effect_wet_surfaces;
extern const fx_effect_class fx_effect_rain_splashes;
extern const fx_effect_class fx_effect_bloom;
const fx_effect_class *const fx_effect_classes[] = {
    &fx_effect_gaussian_blur,
    &fx_effect_color_matrix,
    &fx_effect_pixelate,
    &fx_effect_god_rays,
    &fx_effect_voronoi_caustics,
    &fx_effect_ssr_mirror,
    &fx_effect_edges,
    &fx_effect_posterize,
    &fx_effect_sin_city,
    &fx_effect_vsm_shadows,
    &fx_effect_rain,
    &fx_effect_wet_surfaces,
    &fx_effect_rain_splashes,
    &fx_effect_bloom,
};
const int fx_effect_class_count = (int)(sizeof(fx_effect_classes) / sizeof(fx_effect_classes[0]));

const fx_effect_class *fx_effect_find(const char *name)
{
    if (!name)
        return NULL;
    for (int i = 0; i < fx_effect_class_count; i++)
        if (strcmp(fx_effect_classes[i]->name, name) == 0)
            return fx_effect_classes[i];
    return NULL;
}

const fx_param_def *fx_effect_find_param(const fx_effect_class *cls, const char *name)
{
    if (!cls || !name)
        return NULL;
    for (int i = 0; i < cls->param_count; i++)
        if (strcmp(cls->params[i].info.name, name) == 0)
            return &cls->params[i];
    return NULL;
}
