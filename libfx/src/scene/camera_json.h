/* Cameras in JSON, as the scene sidecar and its aux views hold them. */
#ifndef LIBFX_SCENE_CAMERA_JSON_H
#define LIBFX_SCENE_CAMERA_JSON_H

#include "libfx/fx.h"

#include <stddef.h>

struct cJSON;
/* Parses a camera object (the sidecar's or an aux view's): matrices as 4 rows of 4 (or 16
 * numbers), the clip range, and "orthographic" (else inferred from the projection).
 * zero_clip_start_ok: aux depth views may start at clip 0 (an orthographic depth view).
 * 0 with a message in err when malformed. */
int fx_camera_parse(const struct cJSON *obj, int zero_clip_start_ok, fx_camera *cam, char *err, size_t err_size);

#endif
