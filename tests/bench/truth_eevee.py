"""Eevee as the real-time peer of vsm_shadows on the shadow truth scenes (issue 14: "the
error against time for each preset, beside Eevee ... in the same run").

The truth scene (the Sun's shadows on) rendered by Eevee Legacy (Blender 3.x) with its own
sun shadows at high quality: 4096 cascades, four of them, soft shadows, high bit depth,
contact shadows and ambient occlusion; no baked light cache (Eevee has no bounce light
without one, which is what an artist gets from a plain F12). One EXR and the render time,
kept beside the Cycles renders and reused like them (OUT.json holds the time).
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import truth_common as C  # noqa: E402

# Runs inside Blender after the scene's truth setup (the Sun casts shadows).
EEVEE_SHADOWS = r"""
import bpy, json, time
sc = bpy.context.scene
if "BLENDER_EEVEE" not in {i.identifier for i in sc.render.bl_rna.properties["engine"].enum_items}:
    raise SystemExit("truth: Eevee Legacy is not in this Blender")
sc.frame_set(%(frame)d)
sc.render.engine = "BLENDER_EEVEE"
w, h = %(res)r
sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = w, h, 100
sc.render.use_compositing = False
sc.render.film_transparent = False
ee = sc.eevee
ee.taa_render_samples = %(spp)d
ee.shadow_cascade_size = "4096"
ee.shadow_cube_size = "2048"
ee.use_soft_shadows = True
ee.use_shadow_high_bitdepth = True
ee.use_gtao = True
for ob in sc.objects:
    if ob.type == "LIGHT":
        ob.data.use_shadow = True
        ob.data.use_contact_shadow = True
        if ob.data.type == "SUN":
            ob.data.shadow_cascade_count = 4
is_ = sc.render.image_settings
is_.file_format, is_.color_depth, is_.color_mode = "OPEN_EXR", "32", "RGBA"
sc.render.filepath = %(out)r
t0 = time.perf_counter()
bpy.ops.render.render(write_still=True)
print("LIBFX_EEVEE " + json.dumps({"render_s": time.perf_counter() - t0}))
"""


def eevee_shadows(blend, out, res, spp, truth_setup="", frame=1):
    """The truth scene by Eevee with its own shadows: (linear RGB, render seconds).
    truth_setup: Python run first in Blender (what makes the scene the truth)."""
    w, h = (int(x) for x in res.split("x"))
    code = EEVEE_SHADOWS % {"res": (w, h), "spp": spp, "out": out, "frame": frame}
    return C.eevee_render(blend, out, truth_setup + "\n" + code)
