"""The reflection probe's conventions on a real Cycles render (math/panorama.h states them;
tests/c/test_probe.c checks the library against the same statement):

- the add-on's probe camera (an equirectangular PANO camera at the origin looking along
  world +Y, up +Z) puts world +Y at the image's centre, world +X a quarter of the width
  right of it, world +Z on the top row and world -Y on the left/right seam;
- the Depth pass of a panoramic Cycles camera is the radial distance from its centre
  (checked on a floor 1 m below: depth = 1 / cos(angle from straight down)), not a
  planar depth;
- the mirror objects named in the probe's spec render as perfect mirrors in the probe
  (the yellow cube at -X, its entry's mirror, shows the red cube at +X; the white one at
  -Y, another entry's, the green one at +Y) and get their materials back;
- colour comes with the Depth (the File Output node's Image), rows as the library reads
  them (top row = up);
- its Sky layer is the world alone: the world's colour in every direction, no object
  (math/panorama.h's fx_pano.sky)."""
import math

import numpy as np

import addon_testlib as T

OK = "LIBFX-TEST-OK"

SCRIPT = T.PRELUDE + r"""
import math, os
from mathutils import Matrix, Euler, Vector
from libfx import aux_views
scene = bpy.context.scene
for ob in list(bpy.data.objects):
    bpy.data.objects.remove(ob)
scene.world = bpy.data.worlds.new("plain")
scene.world.color = (0.05, 0.1, 0.3)   # the probe's Sky layer must show it, and nothing else
for n in (scene.world.node_tree.nodes if scene.world.node_tree else []):
    if n.type == "BACKGROUND":         # 5.x: a new world has nodes, which win over .color
        n.inputs["Color"].default_value = (0.05, 0.1, 0.3, 1.0)
scene.render.engine = "CYCLES"
scene.cycles.samples = 4
scene.cycles.use_denoising = False

def emissive(name, rgb):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    nt = m.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    em = nt.nodes.new("ShaderNodeEmission")
    em.inputs["Color"].default_value = (*rgb, 1)
    em.inputs["Strength"].default_value = 1.0
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(em.outputs[0], out.inputs[0])
    return m

def cube(name, loc, size, mat):
    bpy.ops.mesh.primitive_cube_add(size=size, location=loc)
    ob = bpy.context.active_object
    ob.name = name
    ob.data.materials.append(mat)
    return ob

cube("PlusX", (3, 0, 0), 0.8, emissive("red", (1, 0, 0)))
cube("PlusY", (0, 3, 0), 0.8, emissive("green", (0, 1, 0)))
cube("PlusZ", (0, 0, 3), 0.8, emissive("blue", (0, 0, 1)))
cube("MinusY", (0, -3, 0), 0.8, emissive("white", (1, 1, 1)))
cube("Hidden", (-3, 0, 0), 0.8, emissive("yellow", (1, 1, 0)))   # the "mirror": must not show
bpy.ops.mesh.primitive_plane_add(size=60, location=(0, 0, -1))
floor = bpy.context.active_object
floor.name = "Floor"
floor.data.materials.append(emissive("grey", (0.2, 0.2, 0.2)))
mw = Matrix.Translation((0, 0, 0)) @ Euler((math.pi / 2, 0, 0)).to_matrix().to_4x4()
spec = {"name": "probe:test", "kind": "probe", "width": 256, "height": 128, "samples": 4,
        "matrix_world": [list(r) for r in mw], "world_to_camera": [list(r) for r in mw.inverted()],
        "clip_start": 0.0, "clip_end": 1000.0, "hidden": ["Hidden"], "where": "test",
        "mirrors": ["MinusY"]}   # another entry's mirror (aux_views.stack_mirrors)
objs = aux_views._probe_scene_objects(scene)
path = os.environ["PROBE_OUT"]
aux_views._render_probe(scene, spec, objs, path)
assert os.path.exists(path)
assert bpy.data.objects["Hidden"].visible_camera, "the mirror's visibility was not restored"
assert bpy.data.objects["Hidden"].material_slots[0].material.name == "yellow", "the mirror's material was not restored"
assert bpy.data.objects["MinusY"].material_slots[0].material.name == "white", "the other mirror's material was not restored"
print("LIBFX-TEST-OK")
"""


def _pixel(d, w, h):
    """math/panorama.h's fx_pano_dir_to_pixel (probe camera space: -Z forward, +Y up)."""
    dx, dy, dz = d
    n = math.sqrt(dx * dx + dy * dy + dz * dz)
    u = 0.5 - math.atan2(-dx, -dz) / (2 * math.pi)
    v = math.acos(max(-1.0, min(1.0, dy / n))) / math.pi
    return min(w - 1, int(u * w)), min(h - 1, int(v * h))


def _world_to_probe(d):
    """World direction -> the probe camera's space (camera looks along +Y, up +Z)."""
    x, y, z = d
    return (x, z, -y)


def test_probe_conventions(blender, library, tmp_path):
    T.need_oiio()
    out = tmp_path / "probe.exr"
    proc = T.run_blender([], python_expr=SCRIPT, env=dict(T.addon_env(library), PROBE_OUT=str(out)), timeout=300)
    text = proc.stdout + proc.stderr
    assert proc.returncode == 0 and OK in proc.stdout, text[-4000:]
    exr = T.Exr(out)
    assert (exr.width, exr.height) == (256, 128)
    rgb = exr.get("Combined", "RGB")
    depth = exr.get("Depth", ["V" if any(n.endswith("Depth.V") for n in exr.names) else "Z"])[..., 0]
    w, h = exr.width, exr.height

    def colour_at(world_dir):
        x, y = _pixel(_world_to_probe(world_dir), w, h)
        return rgb[y, x], depth[y, x], (x, y)

    c, d, xy = colour_at((0, 1, 0))     # +Y: the centre, green
    assert xy == (128, 64) and c[1] > 0.5 and c[0] < 0.2 and c[2] < 0.2, (xy, c)
    assert abs(d - 2.6) < 0.05, d       # the cube's near face, 2.6 m away
    c, d, xy = colour_at((1, 0, 0))     # +X: three quarters across, red
    assert xy == (192, 64) and c[0] > 0.5 and c[1] < 0.2 and c[2] < 0.2, (xy, c)
    c, d, xy = colour_at((0, 0, 1))     # +Z: the top rows, blue
    assert xy[1] < 4 and c[2] > 0.5 and c[0] < 0.2, (xy, c)
    c, d, xy = colour_at((0, -1, 0))    # -Y: the seam; the white cube, another entry's mirror
    assert (xy[0] < 2 or xy[0] > w - 3) and c[1] > 0.5 and c[0] < 0.2 and c[2] < 0.2, \
        ("the other entry's mirror does not reflect the green cube", xy, c)
    c, d, xy = colour_at((-1, 0, 0))    # -X: the "mirror" cube, a perfect mirror: the red cube
    assert c[0] > 0.5 and c[1] < 0.2 and c[2] < 0.2, ("the mirror does not reflect the red cube", c)
    # radial depth on the floor 1 m below: 1 / cos(angle from straight down)
    worst = 0.0
    for row in range(h // 2 + 8, h - 2, 4):
        theta = (row + 0.5) / h * math.pi          # from straight up
        down = math.pi - theta
        want = 1.0 / math.cos(down)
        if want > 20:
            continue
        for col in (40, 100, 128, 170, 230):
            worst = max(worst, abs(depth[row, col] - want) / want)
    assert worst < 0.03, "floor depth is not the radial distance (worst relative error %.3f)" % worst
    # the rows are stored top down: the top rows are the blue cube overhead, the bottom
    # rows the grey floor
    assert rgb[0:3, :, 2].mean() > 0.9 and rgb[0:3, :, 0].mean() < 0.05
    assert np.allclose(rgb[-3:], 0.2, atol=0.02)
    # the Sky layer: the world alone (Combined shows the cubes and the floor there)
    assert "Sky" in exr.passes(), exr.passes()
    sky = exr.get("Sky", "RGB")
    assert np.allclose(sky, (0.05, 0.1, 0.3), atol=0.01), (sky.min(axis=(0, 1)), sky.max(axis=(0, 1)))
    c, _, _ = colour_at((0, 1, 0))
    assert c[1] > 0.5, "Combined lost the green cube"
