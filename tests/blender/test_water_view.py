"""voronoi_caustics' mode refractive through the add-on (issue 27), in `blender -b` on the pool
truth scene (its water is hidden from the render): the stack asks for the view
'water:Water'; aux_views.prepare renders the water objects alone from the sun with Normal and
Depth, shows the hidden water for that render only, reuses the view while the surface is
unchanged and renders it again when the evaluated surface changes (a displacement's
strength); a material no object uses and a scene without a sun are refused with messages
naming them."""
import json

import numpy as np

import addon_testlib as T

BLEND = T.SCENES_DIR / "truth_caustics" / "truth_caustics_pool.blend"

SCRIPT = T.PRELUDE + r"""
import os
from libfx import aux_views, native, recipe, scene_setup
s = bpy.context.scene
s.render.filepath = %(prefix)r
s.render.resolution_x, s.render.resolution_y, s.render.resolution_percentage = 96, 54, 100
rec = {"version": 1, "effects": [{"effect": "voronoi_caustics", "params": {"mode": "refractive"},
                                  "mask": {"material": "Pool_Floor"}}]}
recipe.from_recipe(s, rec)
scene_setup.sync(s)
need = aux_views.needed(s)
assert need == [{"name": "water:Water", "kind": "water"}], need
water = bpy.data.objects["Water"]
assert water.hide_render and not water.visible_camera
entries = aux_views.prepare(s, [1])
assert [e["name"] for e in entries] == ["water:Water"] and entries[0]["kind"] == "water", entries
assert water.hide_render and not water.visible_camera, "the water's visibility is restored"
path = entries[0]["path"]
t0 = os.path.getmtime(path)
again = aux_views.prepare(s, [1])
assert os.path.getmtime(path) == t0 and again[0]["signature"] == entries[0]["signature"], "reused"
water.modifiers["Waves"].strength = 0.08
moved = aux_views.prepare(s, [1])
assert moved[0]["signature"] != entries[0]["signature"], "a changed surface is rendered again"
water.modifiers["Waves"].strength = 0.05
json.dump(entries[0], open(%(prefix)r + "entry.json", "w"))
# a material no object uses, then no sun
rec["effects"][0]["params"]["water"] = "Nope"
recipe.from_recipe(s, rec)
try:
    aux_views.prepare(s, [1])
    raise AssertionError("no error for a water material no object uses")
except native.LibfxError as e:
    assert "'Nope'" in str(e) and "water" in str(e), e
rec["effects"][0]["params"]["water"] = "Water"
recipe.from_recipe(s, rec)
bpy.data.objects["Sun"].data.type = "POINT"
try:
    aux_views.prepare(s, [1])
    raise AssertionError("no error without a sun")
except native.LibfxError as e:
    assert "no sun" in str(e) and "Sun (POINT)" in str(e), e
print("WATER VIEW OK")
"""


def test_water_view(blender, library, tmp_path):
    assert BLEND.is_file()
    prefix = str(tmp_path / "w_")
    p = T.run_blender([], env=T.addon_env(library), blend=BLEND, python_expr=SCRIPT % {"prefix": prefix},
                      timeout=400)
    out = p.stdout + p.stderr
    assert p.returncode == 0 and "WATER VIEW OK" in out, out[-4000:]
    entry = json.load(open(prefix + "entry.json"))
    e = T.Exr(entry["path"])
    depth = e.channels["Depth.V"]
    n = np.stack([e.channels["Normal." + k] for k in "XYZ"], axis=-1)
    water = depth < 1e9
    # the view is cut to the receivers the camera sees: the 6 m water covers most of it
    assert water.mean() > 0.5, water.mean()
    length = np.linalg.norm(n[water], axis=-1)
    assert np.all(np.abs(length - 1) < 1e-3), (length.min(), length.max())
    # the displaced surface's normals point up and vary (waves), seen from the sun
    assert n[water][:, 2].min() > 0.7 and n[water][:, 0].std() > 0.02, n[water].std(axis=0)
    assert entry["orthographic"] and entry["clip_end"] > entry["clip_start"] > 0
