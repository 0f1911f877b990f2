"""Saves a .blend holding the add-on's state, made by Debian 12's Blender 3.4, for the
test that Blender's versioning in newer releases keeps it (tests/blender/test_versions.py).

    LIBFX_LIBRARY=build/libfx/libfx.so blender -b --factory-startup \\
        --python tests/data/make_addon_state_blend.py

The default cube scene (Cycles, 64x36) with a stack of three effects: parameters,
quality overrides, object/material/index/rectangle masks, one effect disabled; the
add-on's passes enabled and its File Output node added, as a render would leave
them. Beside it, the JSON of what the test expects to find again: the recipe, the
view-layer settings, the File Output node's layers and the sockets feeding them.
Both files are committed; rerun this only to remake them.
"""
import json
import os
import sys

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(HERE)), "addon"))
import libfx  # noqa: E402
from libfx import compat, recipe, scene_setup  # noqa: E402

OUT = os.path.join(HERE, "blender", "addon_state_blender34.blend")


def main():
    libfx.register()
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 2
    scene.cycles.use_denoising = False
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 64, 36, 100
    scene.render.filepath = "//state_out/state_"
    cube = bpy.data.objects["Cube"]
    cube.pass_index = 3
    recipe.from_recipe(scene, {"version": 1, "quality": "preview", "effects": [
        {"effect": "gaussian_blur", "label": "soft cube", "params": {"sigma": 2.5},
         "mask": {"object": "Cube"}},
        {"effect": "pixelate", "quality": "draft", "params": {"cell_size": 6},
         "mask": {"material": "Material", "rect": [4, 2, 40, 30], "invert": True}},
        {"effect": "color_matrix", "enabled": False, "params": {"operator": "sepia"},
         "mask": {"object_index": 3}},
    ]})
    req = scene_setup.sync(scene)
    missing = scene_setup.ensure_nodes(scene, req["passes"])
    assert not missing, missing
    vl = scene_setup.render_view_layer(scene)
    tree = compat.compositor_tree(scene)
    fo = tree.nodes[scene_setup.FO_NODE]
    expected = {
        "blender": bpy.app.version_string,
        "scene": scene.name,
        "recipe": recipe.to_recipe(scene, resolve_paths=False),
        "view_layer": vl.name,
        "settings": sorted(json.loads(scene.libfx.owned)["settings"][vl.name]),
        "file_output_layers": compat.file_output_slot_names(fo),
        "file_output_links": {i.name: i.links[0].from_socket.name for i in fo.inputs if i.is_linked},
        "owned": json.loads(scene.libfx.owned),
    }
    bpy.ops.wm.save_as_mainfile(filepath=OUT, compress=True)
    with open(OUT[:-len(".blend")] + ".json", "w", encoding="utf-8") as f:
        json.dump(expected, f, indent=1, sort_keys=True)
        f.write("\n")
    print("saved", OUT)


try:
    main()
except Exception:
    import traceback
    traceback.print_exc()
    sys.stdout.flush()
    os._exit(1)
