"""The passes file written from the Render Result (addon/libfx/passes_file.py), in `blender -b`:
every view layer is in it and libfx reads the render's one; the scene's own output format is
untouched by the passes write (Blender writes its image after render_post); a scene saved with
the File Output node of earlier add-ons loses it at the next render."""
import numpy as np

import addon_testlib as T

#: A scene of two rendered view layers: "ViewLayer" (a grey cube on a floor, what libfx must
#: read) and "Red" (everything overridden by a red emission), a blur masked to the cube, the
#: scene's own output a 16-bit PNG, and the two compositor nodes an earlier add-on added.
SETUP = T.PRELUDE + r"""
from libfx import compat, props, scene_setup
s = bpy.context.scene
s.render.engine = "CYCLES"
s.cycles.use_denoising = False
bpy.ops.mesh.primitive_plane_add(size=8, location=(0, 0, -1))
red = bpy.data.materials.new("Red")
red.use_nodes = True
nodes = red.node_tree.nodes
em = nodes.new("ShaderNodeEmission")
em.inputs["Color"].default_value = (1, 0, 0, 1)
red.node_tree.links.new(em.outputs[0], nodes["Material Output"].inputs["Surface"])
other = s.view_layers.new("Red")
other.material_override = red
is_ = s.render.image_settings
compat.set_file_format(is_, "PNG", "16")
is_.color_mode = "RGB"
item = s.libfx.stack.add()
item.effect = "gaussian_blur"
props.effect_group(item).sigma = 3.0
item.mask_kinds = {"OBJECT"}
item.mask_objects.add().name = "Cube"
scene_setup.request_sync(s)
tree, made = compat.ensure_compositor_tree(s, "old add-on")
rl = tree.nodes.new("CompositorNodeRLayers"); rl.name = scene_setup.RL_NODE
fo = tree.nodes.new("CompositorNodeOutputFile"); fo.name = scene_setup.FO_NODE
bpy.ops.wm.save_as_mainfile(filepath=%r)
"""

#: The saved scene rendered again in one session (batch saves nothing), then its compositor
#: listed: the old add-on's nodes must be gone.
AGAIN = T.PRELUDE + r"""
from libfx import compat
s = bpy.context.scene
s.render.filepath = %r
s.render.resolution_percentage = 10
bpy.ops.render.render()
tree = compat.compositor_tree(s)
print("NODES", sorted(tree.nodes.keys()) if tree is not None else [])
"""


def test_passes_file_from_the_render_result(blender, library, tmp_path):
    blend = tmp_path / "layers.blend"
    p = T.run_blender([], env=T.addon_env(library), python_expr=SETUP % str(blend))
    assert p.returncode == 0 and blend.is_file(), (p.stdout + p.stderr)[-3000:]
    prefix = tmp_path / "out_"
    p = T.run_blender([], env=T.addon_env(library), blend=blend, python=T.BATCH,
                      script_args=["--keep-passes", "--frames", "1", "--output", str(prefix),
                                   "--resolution", "160x90", "--samples", "2"], factory=False)
    out = p.stdout + p.stderr
    assert p.returncode == 0, out[-5000:]
    assert not T.tracebacks(out), out[-5000:]
    assert "passes file written in" in out, out[-3000:]

    passes = T.Exr(tmp_path / "out_libfx_passes.0001.exr")
    layers = {n.split(".")[0] for n in passes.names if n.count(".") >= 2}
    assert {"ViewLayer", "Red"} <= layers, passes.names
    mine = np.stack([passes.channels["ViewLayer.Combined." + c] for c in "RGBA"], axis=-1)
    red = np.stack([passes.channels["Red.Combined." + c] for c in "RGBA"], axis=-1)
    assert np.abs(mine - red).mean() > 0.05   # the two layers really differ

    result = T.Exr(tmp_path / "out_libfx.0001.exr").get("Combined", "RGBA")
    changed = np.abs(result - mine).max(axis=-1) > 1e-6
    # the blur ran on the render's layer: inside the cube's mask it changed pixels, and
    # everywhere else the result is that layer's render, bit for bit
    assert 0 < changed.mean() < 0.5, changed.mean()
    assert np.array_equal(result[~changed], mine[~changed])

    # Blender's own image kept the scene's format: the passes write put it back in time
    own = tmp_path / "out_0001.png"
    assert own.is_file(), sorted(x.name for x in tmp_path.iterdir())
    head = own.read_bytes()[:32]
    assert head[:8] == b"\x89PNG\r\n\x1a\n" and head[24] == 16, head   # bit depth 16

    # the File Output node of an earlier add-on went at render time
    p = T.run_blender([], env=T.addon_env(library), blend=blend, factory=False,
                      python_expr=AGAIN % str(tmp_path / "again_"))
    out = p.stdout + p.stderr
    assert p.returncode == 0, out[-3000:]
    nodes = next(l for l in out.splitlines() if l.startswith("NODES"))
    assert "libfx passes" not in nodes and "libfx Render Layers" not in nodes, nodes


#: The default cube at 160x90 (Cycles, 1 sample) under a small blur; the output prefix is
#: the script's %r.
SMALL_BLURRED = T.PRELUDE + r"""
import json, os
from libfx import props, scene_setup
s = bpy.context.scene
s.render.filepath = %r
s.render.resolution_x, s.render.resolution_y, s.render.resolution_percentage = 160, 90, 100
s.render.engine = "CYCLES"
s.cycles.samples = 1
s.cycles.use_denoising = False
item = s.libfx.stack.add()
item.effect = "gaussian_blur"
props.effect_group(item).sigma = 2.0
scene_setup.request_sync(s)
"""


#: Three renders of a small blurred cube, passes not kept: the first two with RAM to spare,
#: the third with RAM "too small" (the room asked per pixel made huge). A folder left by a
#: process that is gone waits in the RAM root. Prints where each passes file went.
RAM = SMALL_BLURRED + r"""
from libfx import passes_file, render
base = os.path.join(passes_file.RAM_ROOT, "libfx-passes-%%d" %% os.getuid())
dead = os.path.join(base, "999999999")   # above any pid_max: no such process
if os.path.isdir(passes_file.RAM_ROOT):
    os.makedirs(dead, exist_ok=True)
    open(os.path.join(dead, "left.exr"), "w").close()
written = []
_write = passes_file.write
passes_file.write = lambda sc, f: written.append(_write(sc, f)[0]) or (written[-1], 0.0)
rows = []
for room in ("ample", "ample", "none"):
    if room == "none":
        passes_file.RAM_BYTES_PER_PIXEL = 1 << 60
    bpy.ops.render.render()
    rows.append({"room": room, "path": written[-1], "exists_after": os.path.exists(written[-1])})
print("RAM " + json.dumps({"rows": rows, "pid": os.getpid(), "base": base,
                           "has_ram": os.path.isdir(passes_file.RAM_ROOT),
                           "dead_left": os.path.exists(dead),
                           "beside": scene_setup.passes_path(s, s.frame_current),
                           "result": scene_setup.result_paths(s, s.frame_current)["exr"]}))
"""


def _run_tagged(library, script, prefix, tag):
    """Runs a scene script in `blender -b` (exit 0, no traceback) and returns the JSON it
    printed after `tag` and a space."""
    import json
    p = T.run_blender([], env=T.addon_env(library), python_expr=script % prefix)
    out = p.stdout + p.stderr
    assert p.returncode == 0, out[-5000:]
    assert not T.tracebacks(out), out[-5000:]
    return json.loads(next(l for l in out.splitlines() if l.startswith(tag + " "))[len(tag) + 1:])


def test_passes_not_kept_go_to_ram_when_there_is_room(blender, library, tmp_path):
    import os
    r = _run_tagged(library, RAM, str(tmp_path / "ram_"), "RAM")
    rows = r["rows"]
    assert os.path.isfile(r["result"]), r
    for row in rows:   # never left behind: the result holds the passes
        assert not row["exists_after"], rows
    assert rows[2]["path"] == r["beside"], rows   # no room in RAM: beside the output, as kept
    if r["has_ram"]:
        mine = os.path.join(r["base"], str(r["pid"]))
        assert os.path.dirname(rows[0]["path"]) == mine and rows[1]["path"] == rows[0]["path"], rows
        assert not r["dead_left"], r    # a gone process's folder was removed
        assert not os.path.exists(mine)   # and this one's at exit
    else:
        assert all(row["path"] == r["beside"] for row in rows), rows


#: A kept passes file rendered twice, the cube moved between the renders: the second render
#: replaces the first's file (set aside and removed on a thread, off the way to the result).
AGAIN_KEPT = SMALL_BLURRED + r"""
import shutil
s.libfx.keep_passes = True
stats = []
for x in (0.0, 2.0):
    bpy.data.objects["Cube"].location.x = x
    bpy.ops.render.render()
    path = scene_setup.passes_path(s, s.frame_current)
    st = os.stat(path)
    stats.append([st.st_ino, st.st_mtime_ns])
    if x == 0.0:
        shutil.copy(path, path + ".first.exr")
print("KEPT " + json.dumps({"passes": scene_setup.passes_path(s, s.frame_current), "stats": stats}))
"""


def test_kept_passes_rendered_again_replace_the_file(blender, library, tmp_path):
    import os
    import OpenImageIO as oiio
    r = _run_tagged(library, AGAIN_KEPT, str(tmp_path / "kept_"), "KEPT")
    assert r["stats"][0] != r["stats"][1], r   # a new file each render
    assert os.path.isfile(r["passes"]), r
    # nothing set aside is left once Blender has exited
    assert [f for f in os.listdir(tmp_path) if ".old-" in f] == [], os.listdir(tmp_path)
    # the kept file is the second render's (the cube moved), not the first's
    first, second = oiio.ImageBuf(r["passes"] + ".first.exr"), oiio.ImageBuf(r["passes"])
    assert second.spec().width == 160 and second.spec().channelnames == first.spec().channelnames
    a, b = first.get_pixels(oiio.FLOAT), second.get_pixels(oiio.FLOAT)
    assert np.abs(a - b).max() > 0.1, "the passes file still holds the first render"


#: compat.when_writable in Blender's Python: a write Blender refuses twice is made on the third
#: try (and said so on stderr), any other AttributeError is raised at once, and a refusal that
#: lasts longer than the wait is raised after it; image_format_restore names what it could not
#: put back instead of passing over it.
WHEN_WRITABLE = T.PRELUDE + r"""
import time
from libfx import compat
REFUSED = "Writing to ID classes in this context is not allowed: Scene, Scene datablock, error setting x"
calls = []
def refused_twice(v):
    calls.append(v)
    if len(calls) < 3:
        raise AttributeError(REFUSED)
    return v * 2
print("RESULT", compat.when_writable(refused_twice, 21), len(calls))
other = []
def other_error():
    other.append(1)
    raise AttributeError("'Scene' object has no attribute 'nope'")
try:
    compat.when_writable(other_error)
except AttributeError as e:
    print("OTHER", len(other), "no attribute" in str(e))
t0 = time.monotonic()
def always():
    raise AttributeError(REFUSED)
try:
    compat.when_writable(always, wait=0.2)
except AttributeError:
    print("GAVE_UP %.2f" % (time.monotonic() - t0))
class Settings:
    file_format = "PNG"
    def __setattr__(self, k, v):
        raise AttributeError(REFUSED)
compat.WRITE_WAIT_S = 0.1
print("MISSED", compat.image_format_restore(Settings(), [("file_format", "JPEG")]))
"""


def test_when_writable_waits_out_a_refused_write(blender, library):
    p = T.run_blender([], env=T.addon_env(library), python_expr=WHEN_WRITABLE)
    out = p.stdout + p.stderr
    assert p.returncode == 0 and not T.tracebacks(out), out[-3000:]
    assert "RESULT 42 3" in p.stdout                      # made on the third try
    assert "refused ID writes for" in out                   # and said so
    assert "OTHER 1 True" in p.stdout                      # another error: at once, unchanged
    gave_up = float(p.stdout.split("GAVE_UP ")[1].split()[0])
    assert 0.2 <= gave_up < 2.0                            # a lasting refusal: after the wait
    assert "MISSED ['file_format']" in p.stdout            # restore names what it could not do
