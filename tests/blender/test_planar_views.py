"""Planar views per plane (addon/libfx/aux_views.planar_specs): a mirror entry whose faces
lie in two planes (a facing pair, one material) gets two planar views, named
"planar:<key>" and "planar:<key>#2", each with its own plane, the camera mirrored in that
plane, and only that plane's mirror hidden from its camera; each view renders (the
mirrors shown as perfect mirrors, materials and visibility restored after) over its
mirror's region only (a render border holding every mirror point the camera sees, its
pixels the whole view's, nothing rendered outside); a curved mirror gets none
(NotPlanar), a single flat card one. The library's side (each pixel looks up its own
plane's view) is tests/c/test_planar_views.c."""
import json

import numpy as np

import addon_testlib as T

OK = "LIBFX-TEST-OK"

SCRIPT = T.PRELUDE + r"""
import json, math, os
from mathutils import Matrix, Vector
from libfx import aux_views
scene = bpy.context.scene
for ob in list(bpy.data.objects):
    bpy.data.objects.remove(ob)
scene.world = bpy.data.worlds.new("grey")
scene.world.color = (0.3, 0.3, 0.3)
scene.render.engine = "CYCLES"
scene.cycles.samples = 2
scene.cycles.use_denoising = False
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 64, 36, 100

mirror = bpy.data.materials.new("Mirror")
grey = bpy.data.materials.new("Grey")

def card(name, loc, rot_z):
    bpy.ops.mesh.primitive_cube_add(size=1, location=loc, rotation=(0, 0, rot_z))
    ob = bpy.context.active_object
    ob.name = name
    ob.scale = (0.04, 2.0, 1.5)   # a slab: its big faces along local +-X
    ob.data.materials.append(mirror)
    return ob

left = card("Mirror_Left", (-2.0, 3.0, 1.0), 0.0)
right = card("Mirror_Right", (2.0, 3.0, 1.0), 0.0)
bpy.ops.mesh.primitive_cube_add(size=0.5, location=(0, 3, 0.5))
block = bpy.context.active_object
block.name = "Block"
block.data.materials.append(grey)
bpy.ops.mesh.primitive_cube_add(size=1, location=(-4, 3, 1))   # wholly behind the left mirror's plane
behind = bpy.context.active_object
behind.name = "Behind_Left"
behind.data.materials.append(grey)
cam_data = bpy.data.cameras.new("cam")
cam = bpy.data.objects.new("cam", cam_data)
scene.collection.objects.link(cam)
cam.location = (0.3, -2.0, 1.2)
cam.rotation_euler = (math.radians(90), 0, 0)
scene.camera = cam
bpy.context.view_layer.update()

view = {"name": "planar:k", "kind": "planar", "mask": {"material": ["Mirror"]}}
specs = aux_views.planar_specs(scene, view)
out = {"specs": [{k: s[k] for k in ("name", "plane", "hidden", "behind", "mirrors", "matrix_world")} for s in specs]}
# each view renders; materials and visibility come back
paths = []
objs = aux_views._probe_scene_objects(scene)
for s in specs:
    path = os.path.join(os.environ["PLANAR_OUT"], aux_views._file_name(s["name"]) + ".exr")
    aux_views._render_probe(scene, s, objs, path)
    assert os.path.exists(path), path
    paths.append(path)
for ob in (left, right, behind):
    assert ob.visible_camera, ob.name + ": visibility not restored"
# the border: every point of a view's own mirror that the camera sees (ray cast through a
# grid of the render's pixels) lands inside it; then one view again without its border
dg = bpy.context.evaluated_depsgraph_get()
frame = cam.data.view_frame(scene=scene)   # top-right, bottom-right, bottom-left, top-left
covered = {}
for s in specs:
    W2C, P = Matrix(s["world_to_camera"]), Matrix(s["projection"])
    seen = outside = 0
    for j in range(36):
        for i in range(64):
            ndc = Vector(((i + 0.5) / 32.0 - 1.0, (j + 0.5) / 18.0 - 1.0))
            local = Vector((frame[2].x + (frame[0].x - frame[2].x) * (ndc.x + 1) / 2,
                            frame[2].y + (frame[0].y - frame[2].y) * (ndc.y + 1) / 2, frame[0].z))
            d = (cam.matrix_world.to_3x3() @ local).normalized()
            hit, loc, _, _, ob, _ = scene.ray_cast(dg, cam.matrix_world.translation, d)
            if not hit or ob.name not in s["hidden"]:
                continue
            h = P @ (W2C @ loc.to_4d())
            u, v = 0.5 * (h.x / h.w + 1.0), 0.5 * (h.y / h.w + 1.0)
            b = s["border"]
            seen += 1
            outside += not (b and b[0] <= u <= b[2] and b[1] <= v <= b[3])
    covered[s["name"]] = [seen, outside, s["border"]]
out["covered"] = covered
# the view of the mirror the camera sees most of (the other one is off the frame here)
k = max(range(len(specs)), key=lambda k: covered[specs[k]["name"]][0])
full = os.path.join(os.environ["PLANAR_OUT"], "full.exr")
aux_views._render_probe(scene, dict(specs[k], border=None), objs, full)
out["full"] = [full, paths[k], specs[k]["border"], specs[k]["crop"]]
out["crops"] = [s["crop"] for s in specs]
assert left.material_slots[0].material.name == "Mirror" and right.material_slots[0].material.name == "Mirror"
out["paths"] = paths
# one flat card: one view, the need's own name
bpy.data.objects.remove(right)
bpy.context.view_layer.update()
out["single"] = [s["name"] for s in aux_views.planar_specs(scene, view)]
# a curved mirror (a cylinder section): none
bpy.data.objects.remove(left)
bpy.ops.mesh.primitive_cylinder_add(vertices=48, radius=0.9, depth=1.5, location=(0, 4, 1))
cyl = bpy.context.active_object
cyl.data.materials.append(mirror)
bpy.context.view_layer.update()
try:
    aux_views.planar_specs(scene, view)
    out["curved"] = "planar"
except aux_views.NotPlanar as e:
    out["curved"] = "not planar: %s" % e
print("PLANAR-RESULT " + json.dumps(out))
print("LIBFX-TEST-OK")
"""


def test_planar_views_per_plane(blender, library, tmp_path):
    proc = T.run_blender([], python_expr=SCRIPT, env=dict(T.addon_env(library), PLANAR_OUT=str(tmp_path)),
                         timeout=300)
    text = proc.stdout + proc.stderr
    assert proc.returncode == 0 and OK in proc.stdout, text[-4000:]
    line = [x for x in proc.stdout.splitlines() if x.startswith("PLANAR-RESULT ")][-1]
    res = json.loads(line[len("PLANAR-RESULT "):])
    specs = {s["name"]: s for s in res["specs"]}
    assert sorted(specs) == ["planar:k", "planar:k#2"], specs.keys()
    cam = (0.3, -2.0, 1.2)
    seen = {}
    for s in specs.values():
        n, d = s["plane"][:3], s["plane"][3]
        # a side wall's plane, facing the camera (n . cam > d)
        assert abs(abs(n[0]) - 1) < 1e-5 and abs(n[1]) < 1e-5 and abs(n[2]) < 1e-5, s
        assert sum(a * b for a, b in zip(n, cam)) > d
        # the mirrored camera: the camera reflected in the view's plane
        dist = sum(a * b for a, b in zip(n, cam)) - d
        want = [c - 2 * dist * a for c, a in zip(cam, n)]
        got = [row[3] for row in s["matrix_world"][:3]]
        assert max(abs(a - b) for a, b in zip(got, want)) < 1e-4, (got, want)
        assert sorted(s["mirrors"]) == ["Mirror_Left", "Mirror_Right"]
        seen["left" if n[0] > 0 else "right"] = s
    # each view hides only its own plane's mirror (the other one reflects the room again)
    assert seen["left"]["hidden"] == ["Mirror_Left"] and seen["right"]["hidden"] == ["Mirror_Right"], seen
    assert "Behind_Left" in seen["left"]["behind"] and "Behind_Left" not in seen["right"]["behind"]
    for p, crop in zip(res["paths"], res["crops"]):   # each file: its region of the 64x36 view
        exr = T.Exr(p)
        assert (exr.width, exr.height) == tuple(crop[2:]) and crop[0] + crop[2] <= 64 and crop[1] + crop[3] <= 36
    # each view renders only its mirror's region (Cycles' border, cropped): every mirror
    # point the camera sees lies in it, the region is a part of the view, the file holds
    # just the region ("window": its place in the view), and its pixels are the whole
    # view's there (the same samples) -- the window is where Blender put the crop
    for name, (seen, outside, border) in res["covered"].items():
        assert outside == 0 and (border[2] - border[0]) * (border[3] - border[1]) < 0.6, (name, seen, outside, border)
    assert max(c[0] for c in res["covered"].values()) > 100, res["covered"]
    full_path, border_path, b, (x0, y0, w, h) = res["full"]
    full, part = T.Exr(full_path).get("Combined", "RGB"), T.Exr(border_path).get("Combined", "RGB")
    assert part.shape[:2] == (h, w) and full.shape[:2] == (36, 64) and w * h < 0.6 * 64 * 36, \
        (part.shape, (x0, y0, w, h))
    assert abs(x0 - b[0] * 64) < 1 and abs(36 - y0 - h - b[1] * 36) < 1, (b, x0, y0, w, h)
    assert np.array_equal(full[y0:y0 + h, x0:x0 + w], part), np.abs(full[y0:y0 + h, x0:x0 + w] - part).max()
    assert res["single"] == ["planar:k"]
    assert res["curved"].startswith("not planar"), res["curved"]
