/* fx_camera <-> the standard EXR camera attributes worldToCamera / worldToNDC.
 *
 * Imath (and so every EXR writer) uses row vectors, p' = p * M, while fx_camera keeps
 * Blender's column-vector matrices, p' = M p: the file's matrix is the transpose of
 * ours. libfx writes worldToNDC as (projection * world_to_camera)^T, i.e. world to
 * OpenGL clip space (divide by w for NDC in [-1, 1]); reading inverts that product. */
#ifndef LIBFX_IO_EXR_CAMERA_H
#define LIBFX_IO_EXR_CAMERA_H

#include "libfx/fx.h"

#ifdef __cplusplus
extern "C" {
#endif

/* From the file's matrices (row-vector, 16 floats each). Returns 0 if worldToCamera
 * is singular. clip_start/clip_end/orthographic come from the projection. */
int fx_exr_camera_from_file(const float world_to_camera_file[16], const float world_to_ndc_file[16],
                            fx_camera *out);
/* To the file's matrices. */
void fx_exr_camera_to_file(const fx_camera *cam, float world_to_camera_file[16],
                           float world_to_ndc_file[16]);

#ifdef __cplusplus
}
#endif
#endif
