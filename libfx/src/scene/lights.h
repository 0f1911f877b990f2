/* The scene's lights, as the sidecar delivered them (frame metadata "libfx:lights"). */
#ifndef LIBFX_SCENE_LIGHTS_H
#define LIBFX_SCENE_LIGHTS_H

#include "core/frame.h"
#include "math/vec.h"

typedef enum fx_light_type { FX_LIGHT_SUN, FX_LIGHT_POINT, FX_LIGHT_SPOT, FX_LIGHT_AREA } fx_light_type;

typedef struct fx_light {
    char name[64];
    fx_light_type type;
    fx_vec3 position;  /* world */
    fx_vec3 direction; /* world, unit, the way the light travels */
    fx_vec3 color;
    float energy;
    float angle;       /* sun disc angle, radians */
} fx_light;

/* Finds a light by name; an empty or NULL name picks the first sun (else the first
 * light). Fails with FX_ERR_BAD_PARAM naming `where` and the lights the frame has, or
 * FX_ERR_NO_LIGHTS when the frame carries no lights (they come with the scene sidecar:
 * the CLI's --sidecar, or the add-on). */
fx_result fx_frame_find_light(const fx_frame *f, const char *name, const char *where, fx_light *out);

#endif
