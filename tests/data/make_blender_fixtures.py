"""Renders the tiny Blender EXR fixtures the C tests read (tests/data/blender/).

    blender -b --factory-startup --python tests/data/make_blender_fixtures.py

The default cube at 64x36, Cycles, 4 samples, no denoising (Debian's Blender has no
OpenImageDenoise), with the passes libfx uses, written by both of Blender's routes:

- render_multilayer.exr: the render output, OPEN_EXR_MULTILAYER, 32-bit, ZIP
  (channels "ViewLayer.Combined.R", "ViewLayer.Depth.Z", ... and "Composite.Combined.*")
- fileoutput_multilayer.exr: a compositor File Output node, 32-bit multilayer, ZIP, slots
  Image, Depth, Normal, IndexOB (channels "Image.R", "Depth.V", "Normal.X", "IndexOB.V")

Both files are committed; rerun this script only to regenerate them.
"""
import glob
import os
import shutil
import sys
import tempfile

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "blender")


def main():
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 4
    scene.cycles.use_denoising = False
    scene.cycles.device = "CPU"
    scene.render.resolution_x = 64
    scene.render.resolution_y = 36
    scene.render.resolution_percentage = 100
    scene.frame_set(1)

    cube = bpy.data.objects["Cube"]
    cube.pass_index = 3
    cube.active_material.pass_index = 5

    vl = scene.view_layers["ViewLayer"]
    vl.use_pass_z = True
    vl.use_pass_normal = True
    vl.use_pass_position = True
    vl.use_pass_object_index = True
    vl.use_pass_material_index = True
    vl.use_pass_cryptomatte_object = True
    vl.use_pass_cryptomatte_material = True
    vl.use_pass_diffuse_direct = True

    tmp = tempfile.mkdtemp(prefix="libfx-fixtures-")
    img = scene.render.image_settings
    img.file_format = "OPEN_EXR_MULTILAYER"
    img.color_depth = "32"
    img.exr_codec = "ZIP"
    scene.render.filepath = os.path.join(tmp, "render_####")

    scene.use_nodes = True
    tree = scene.node_tree
    rl = next(n for n in tree.nodes if n.type == "R_LAYERS")
    fo = tree.nodes.new("CompositorNodeOutputFile")
    fo.base_path = os.path.join(tmp, "fileoutput_")
    fo.format.file_format = "OPEN_EXR_MULTILAYER"
    fo.format.color_depth = "32"
    fo.format.exr_codec = "ZIP"
    fo.layer_slots.clear()
    for name in ("Image", "Depth", "Normal", "IndexOB"):
        fo.layer_slots.new(name)
        tree.links.new(rl.outputs[name], fo.inputs[name])

    bpy.ops.render.render(write_still=True)

    os.makedirs(OUT, exist_ok=True)
    for pattern, name in (("render_*.exr", "render_multilayer.exr"),
                          ("fileoutput_*.exr", "fileoutput_multilayer.exr")):
        found = glob.glob(os.path.join(tmp, pattern))
        if len(found) != 1:
            raise RuntimeError("expected one %s in %s, found %r" % (pattern, tmp, found))
        shutil.move(found[0], os.path.join(OUT, name))
    shutil.rmtree(tmp, ignore_errors=True)


try:
    main()
except Exception:
    import traceback
    traceback.print_exc()
    sys.exit(1)  # Blender exits 0 after a failing script otherwise
