"""The add-on on each Blender it supports (3.4 to 5.x): the version differences,
installation the way that release installs, renders started every way an artist
starts them, .blend files made by 3.4 opened by newer releases, and bad set-ups.

scripts/blender_matrix.sh runs this directory once per Blender.
"""
import functools
import json
import os
import re
import shutil
import subprocess
import zipfile

import numpy as np
import pytest

import addon_testlib as T

STATE_BLEND = T.REPO / "tests" / "data" / "blender" / "addon_state_blender34.blend"
CUBE = ("import bpy\n"
        "s = bpy.context.scene\n"
        "s.render.engine = 'CYCLES'\n"
        "s.cycles.use_denoising = False\n"
        "s.render.film_transparent = False\n")


@functools.lru_cache()
def blender_version():
    out = subprocess.run([T.blender_path(), "-b", "--factory-startup", "--version"],
                         capture_output=True, text=True, timeout=120).stdout
    m = re.search(r"^Blender (\d+)\.(\d+)\.(\d+)", out, re.M)
    assert m, out
    return tuple(int(v) for v in m.groups())


def _ok(proc, what=""):
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, "%s\n%s" % (what, out[-5000:])
    assert not T.tracebacks(out), out[-5000:]
    return out


def _recipe(tmp_path, effects):
    p = tmp_path / "r.json"
    p.write_text(json.dumps({"version": 1, "effects": effects}))
    return p


def test_version_differences_follow_the_api(blender, library):
    """Every branch of compat.py taken on this Blender does what its callers expect."""
    script = T.PRELUDE + r"""
from libfx import compat
import bpy, bmesh
assert compat.version_problem() is None, compat.version_problem()
s = bpy.context.scene
# engines
s.render.engine = compat.eevee_engine()
assert compat.is_eevee(s.render.engine), s.render.engine
assert not compat.engine_renders_pass(s.render.engine, 'IndexOB')
assert compat.engine_renders_pass('CYCLES', 'IndexOB')
s.render.engine = 'CYCLES'
# image formats
compat.set_file_format(s.render.image_settings, 'OPEN_EXR_MULTILAYER', '32', 'ZIP')
assert s.render.image_settings.file_format == 'OPEN_EXR_MULTILAYER'
compat.set_file_format(s.render.image_settings, 'PNG')
assert s.render.image_settings.file_format == 'PNG'
# Principled sockets by either name
m = bpy.data.materials.new('m'); m.use_nodes = True
b = m.node_tree.nodes['Principled BSDF']
for old, new in compat.PRINCIPLED_RENAMED.items():
    assert compat.principled_input(b, old) == compat.principled_input(b, new), old
# blend modes
compat.material_alpha_clip(m, 0.4)
compat.material_alpha_blend(m)
# auto smooth
me = bpy.data.meshes.new('x'); bm = bmesh.new(); bmesh.ops.create_cube(bm, size=1.0); bm.to_mesh(me)
compat.mesh_smooth_by_angle(me, 0.5)
assert all(p.use_smooth for p in me.polygons)
# which engine renders which pass: compat's table against Blender's own sockets
vl = s.view_layers[0]
for setting in ('use_pass_z', 'use_pass_normal', 'use_pass_position', 'use_pass_vector',
                'use_pass_object_index', 'use_pass_material_index', 'use_pass_diffuse_direct',
                'use_pass_diffuse_color', 'use_pass_cryptomatte_object'):
    setattr(vl, setting, True)
probe, probe_how = compat.ensure_compositor_tree(s, 'engines')
prl = next(n for n in probe.nodes if n.bl_idname == 'CompositorNodeRLayers')
for engine in ('CYCLES', compat.eevee_engine(), 'BLENDER_WORKBENCH'):
    s.render.engine = engine
    for p in ('Depth', 'Normal', 'Position', 'Vector', 'IndexOB', 'IndexMA', 'DiffDir', 'DiffCol',
              'CryptoObject00'):
        sock = compat.render_layer_output(prl, p)   # 4.3+: None when the engine lacks it
        rendered = sock is not None and sock.enabled
        assert rendered == compat.engine_renders_pass(engine, p), (engine, p)
s.render.engine = 'CYCLES'
compat.release_compositor_tree(s, probe_how)
for setting in ('use_pass_z', 'use_pass_normal', 'use_pass_position', 'use_pass_vector',
                'use_pass_object_index', 'use_pass_material_index', 'use_pass_diffuse_direct',
                'use_pass_diffuse_color', 'use_pass_cryptomatte_object'):
    setattr(vl, setting, False)
# the compositor tree: made, holds Render Layers feeding the final image, released
assert compat.compositor_tree(s) is None or not getattr(s, 'use_nodes', True)
tree, how = compat.ensure_compositor_tree(s, 'probe')
assert how in ('use_nodes', 'node_group') and tree is compat.compositor_tree(s), how
rl = next(n for n in tree.nodes if n.bl_idname == 'CompositorNodeRLayers')
s.view_layers[0].use_pass_object_index = True
assert compat.render_layer_output(rl, 'IndexOB') is not None
assert compat.render_layer_output(rl, 'Combined').name == 'Image'
fo = tree.nodes.new('CompositorNodeOutputFile')
compat.file_output_set_prefix(fo, '/tmp/x/pre_')
assert compat.file_output_prefix(fo) == '/tmp/x/pre_', compat.file_output_prefix(fo)
compat.file_output_link(tree, fo, [('Combined', rl.outputs['Image']),
                                   ('IndexOB', compat.render_layer_output(rl, 'IndexOB'))])
assert compat.file_output_slot_names(fo) == ['Combined', 'IndexOB']
assert fo.inputs['IndexOB'].links[0].from_socket == compat.render_layer_output(rl, 'IndexOB')
compat.release_compositor_tree(s, how)
assert compat.compositor_tree(s) is None or not s.use_nodes
print('COMPAT OK', bpy.app.version_string)
"""
    out = _ok(T.run_blender([], env=T.addon_env(library), python_expr=script))
    assert "COMPAT OK" in out


@pytest.mark.parametrize("version,words", [((3, 3, 0), "older than 3.4"),
                                           ((6, 0, 0), "does not know")])
def test_unknown_blender_versions_get_a_message(blender, library, tmp_path, version, words):
    """An older or a future major Blender: a panel with the message, no stack UI,
    and a batch run that exits 2 saying why; never a traceback."""
    pretend = ("import sys, bpy\nsys.path.insert(0, %r)\nimport libfx\n"
               "libfx.compat.blender_version = lambda: %r\n" % (str(T.ADDON_DIR), version))
    check = pretend + (
        "libfx.register()\n"
        "assert hasattr(bpy.types, 'LIBFX_PT_unsupported')\n"
        "assert not hasattr(bpy.types.Scene, 'libfx')\n"
        "print('PANEL SAYS', libfx.ui.UNSUPPORTED)\n"
        "libfx.unregister(); libfx.register()\n"
        "libfx.unregister()\n"
        "assert not hasattr(bpy.types, 'LIBFX_PT_unsupported')\n")
    out = _ok(T.run_blender([], env=T.addon_env(library), python_expr=check))
    assert "PANEL SAYS" in out and words in out, out[-3000:]
    r = _recipe(tmp_path, [{"effect": "gaussian_blur"}])
    proc = T.run_blender([], env=T.addon_env(library), python_expr=pretend, python=T.BATCH,
                         script_args=["--frames", "1", "--output", tmp_path / "o_", "--recipe", r])
    assert proc.returncode == 2, (proc.stdout + proc.stderr)[-3000:]
    assert words in proc.stderr and "libfx batch: error" in proc.stderr, proc.stderr[-3000:]
    assert not T.tracebacks(proc.stdout + proc.stderr)
    assert not list(tmp_path.glob("o_*"))


def test_recipe_stored_by_a_newer_libfx(blender, library, tmp_path):
    """A .blend whose recipe text a newer libfx wrote: the panel and the batch run say
    so (the version, and to update libfx)."""
    make = ("import bpy, json\n"
            "t = bpy.data.texts.new('libfx_recipe.json')\n"
            "t.write(json.dumps({'version': 99, 'effects': [{'effect': 'gaussian_blur'}]}))\n")
    proc = T.run_blender([], env=T.addon_env(library), python_expr=make, python=T.BATCH,
                         script_args=["--frames", "1", "--output", tmp_path / "o_"])
    assert proc.returncode == 2, (proc.stdout + proc.stderr)[-3000:]
    assert "version 99 is newer than this libfx reads" in proc.stderr, proc.stderr[-3000:]
    assert not T.tracebacks(proc.stdout + proc.stderr)


@pytest.mark.parametrize("breakage,words", [
    ("s.camera = None", "no active camera"),
    ("for vl in s.view_layers: vl.use = False", "no view layer enabled for rendering"),
    ("s.render.filepath = ''", "no output path"),
])
def test_scene_set_up_problems_are_messages(blender, library, tmp_path, breakage, words):
    r = _recipe(tmp_path, [{"effect": "gaussian_blur"}])
    expr = CUBE + breakage + "\n"
    args = ["--frames", "1", "--recipe", r, "--resolution", "32x18"]
    if "filepath" not in breakage:
        args += ["--output", tmp_path / "o_"]
    proc = T.run_blender([], env=T.addon_env(library), python_expr=expr, python=T.BATCH, script_args=args)
    assert proc.returncode == 2, (proc.stdout + proc.stderr)[-3000:]
    assert words in proc.stderr, proc.stderr[-3000:]
    assert not T.tracebacks(proc.stdout + proc.stderr)


def test_scene_builders_run(blender, tmp_path):
    """blend_scenes/build_all.sh on this Blender: each scene builds, and its recipe is
    the committed one."""
    env = dict(os.environ, BLENDER=T.blender_path(), PYTHONDONTWRITEBYTECODE="1")
    p = subprocess.run(["sh", str(T.SCENES_DIR / "build_all.sh"), str(tmp_path)], capture_output=True,
                       text=True, timeout=900, env=env)
    assert p.returncode == 0, (p.stdout + p.stderr)[-4000:]
    for scene in ("greek_bath", "atrium", "mirror_room"):
        assert (tmp_path / scene / (scene + ".blend")).stat().st_size > 10000
        made = json.loads((tmp_path / scene / "recipe.json").read_text())
        committed = json.loads((T.SCENES_DIR / scene / "recipe.json").read_text())
        assert made == committed, scene


def test_blend_saved_by_34_keeps_the_add_on_state(blender, library, tmp_path):
    """tests/data/blender/addon_state_blender34.blend (saved by 3.4 with a stack,
    masks, passes and the File Output node) after this Blender's versioning: the same
    recipe, passes and node set-up; it renders; 'Undo Scene Changes' restores it."""
    want = json.loads(STATE_BLEND.with_suffix(".json").read_text())
    blend = tmp_path / STATE_BLEND.name
    shutil.copy(STATE_BLEND, blend)
    script = T.PRELUDE + r"""
from libfx import compat, recipe, scene_setup
want = json.loads(%r)
s = bpy.data.scenes[want['scene']]
got = recipe.to_recipe(s, resolve_paths=False)
assert got == want['recipe'], (got, want['recipe'])
vl = s.view_layers[want['view_layer']]
for setting in want['settings']:
    assert getattr(vl, setting), setting
tree = compat.compositor_tree(s)
assert tree is not None
fo = tree.nodes[scene_setup.FO_NODE]
rl = tree.nodes[scene_setup.RL_NODE]
assert compat.file_output_slot_names(fo) == want['file_output_layers'], compat.file_output_slot_names(fo)
for layer in want['file_output_layers']:
    inp = fo.inputs[layer]
    assert inp.is_linked and inp.links[0].from_socket == compat.render_layer_output(rl, layer), layer
assert json.loads(s.libfx.owned) == want['owned'], s.libfx.owned
scene_setup.restore(s)
assert scene_setup.FO_NODE not in getattr(compat.compositor_tree(s), 'nodes', {})
for setting in want['settings']:
    assert not getattr(vl, setting), setting
assert compat.compositor_tree(s) is None or not s.use_nodes
print('STATE OK')
""" % STATE_BLEND.with_suffix(".json").read_text()
    out = _ok(T.run_blender([], env=T.addon_env(library), blend=blend, python_expr=script, factory=True))
    assert "STATE OK" in out
    proc = T.run_blender([], env=T.addon_env(library), blend=blend, python=T.BATCH,
                         script_args=["--keep-passes", "--frames", "1", "--samples", "2"])
    _ok(proc, "batch render of the 3.4 file")
    result = T.Exr(tmp_path / "state_out" / "state_libfx.0001.exr")
    plain = T.Exr(tmp_path / "state_out" / "state_libfx_passes.0001.exr")
    a, b = result.get("Combined", "RGBA"), plain.get("Combined", "RGBA")
    support = T.mask_support(plain, {"object": "Cube"})
    assert support.any() and np.abs(a - b)[support].max() > 1e-3   # the stack ran


def _installed_env(home):
    env = {k: v for k, v in os.environ.items() if k != "LIBFX_LIBRARY"}
    env.update(HOME=str(home), PYTHONDONTWRITEBYTECODE="1")
    return env


def test_installs_the_way_this_blender_installs(blender, library, tmp_path):
    """4.2+: the library packed in a wheel (scripts/build_wheel.py), the extension built
    by Blender's own `extension build --split-platforms` around it, the linux-x64 zip
    installed with `extension install-file`; 3.4-4.1: the legacy add-on zip. Then, in
    a fresh Blender with that user profile and no LIBFX_LIBRARY, the installed add-on
    registers headless, loads its library (from the wheel Blender installed, on 4.2+)
    and renders; a top-level `import libfx` there is the wheel, not the add-on."""
    home = tmp_path / "home"
    home.mkdir()
    env = _installed_env(home)
    build = library.parent.parent
    extension = blender_version() >= (4, 2, 0)
    if extension:
        p = subprocess.run(["/usr/bin/python3", str(T.REPO / "scripts" / "build_wheel.py"),
                            "--platform", "linux-x64", "--library", str(library.resolve()),
                            "--out", str(tmp_path / "wheels"), "--dev"],
                           capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, (p.stdout + p.stderr)[-4000:]
        wheel = p.stdout.strip().splitlines()[-1]
        p = subprocess.run(["bash", str(T.REPO / "scripts" / "build_extension.sh"), str(tmp_path / "ext"), wheel],
                           capture_output=True, text=True, timeout=300,
                           env=dict(env, BLENDER=T.blender_path()))
        assert p.returncode == 0, (p.stdout + p.stderr)[-4000:]
        package = p.stdout.strip().splitlines()[-1]
        assert package.endswith("-linux_x64.zip"), package
        with zipfile.ZipFile(package) as z:
            names = z.namelist()
        assert "wheels/" + os.path.basename(wheel) in names, names
        assert not any(n.startswith("lib/") for n in names), names     # the library is in the wheel
        p = subprocess.run([T.blender_path(), "--command", "extension", "install-file", package,
                            "-r", "user_default", "--enable"], capture_output=True, text=True,
                           timeout=300, env=env)
        assert p.returncode == 0, (p.stdout + p.stderr)[-4000:]
        module = "bl_ext.user_default.libfx"
    else:
        package = build / "libfx-addon-linux-x64.zip"
        assert package.is_file(), package
        install = ("import bpy\n"
                   "bpy.ops.preferences.addon_install(filepath=%r)\n"
                   "bpy.ops.preferences.addon_enable(module='libfx')\n"
                   "bpy.ops.wm.save_userpref()\n" % str(package))
        p = subprocess.run([T.blender_path(), "-b", "--python-expr", install], capture_output=True,
                           text=True, timeout=300, env=env)
        assert p.returncode == 0, (p.stdout + p.stderr)[-4000:]
        module = "libfx"
    where = ("import sys, bpy\n"
             "mod = sys.modules.get(%r)\n"
             "assert mod is not None and hasattr(bpy.types.Scene, 'libfx'), sorted(sys.modules)\n"
             "assert mod.native.load() is not None, mod.native.load_error()\n"
             "import libfx as top\n"
             "print('INSTALLED AT', mod.__file__, mod.native.library_path(), top.__file__)\n" % module)
    prefix = tmp_path / "inst_"
    cmd = [T.blender_path(), "-b", str(T.SCENES_DIR / "mirror_room" / "mirror_room.blend"),
           "--python-exit-code", "3", "--python-expr", where, "--python", str(T.BATCH), "--",
           "--frames", "1", "--output", str(prefix), "--resolution", "64x36", "--samples", "1"]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    out = _ok(p, "render with the installed add-on")
    line = next(l for l in out.splitlines() if l.startswith("INSTALLED AT"))
    addon_file, lib_path, top_file = line.split()[2:5]
    assert str(home) in addon_file and str(home) in lib_path, line
    if extension:
        # the library is the wheel's, installed by Blender into its site-packages, and a
        # top-level `import libfx` is that wheel, not the add-on (bl_ext.user_default.libfx)
        wheel_pkg = os.path.join("site-packages", "libfx")
        assert wheel_pkg + os.sep + os.path.join("lib", "libfx.so.2") in lib_path, line
        assert wheel_pkg in top_file and top_file != addon_file, line
        # the installed batch.py under --factory-startup (the extension not enabled by
        # the preferences) enables it as bl_ext.user_default.libfx, not as a top-level libfx
        installed_batch = os.path.join(os.path.dirname(addon_file), "batch.py")
        probe = ("import runpy\n"
                 "g = runpy.run_path(%r, run_name='batch_under_test')\n"
                 "mod = g['enable_addon']()\n"
                 "import libfx\n"
                 "print('ENABLED', mod.__name__, mod.native.library_path(), libfx.__file__)\n" % installed_batch)
        p = subprocess.run([T.blender_path(), "-b", "--factory-startup", "--python-exit-code", "3",
                            "--python-expr", probe], capture_output=True, text=True, timeout=300, env=env)
        out = _ok(p, "the installed batch.py under --factory-startup")
        name, lib2, top2 = next(l for l in out.splitlines() if l.startswith("ENABLED")).split()[1:4]
        assert name == module and lib2 == lib_path and top2 == top_file, (name, lib2, top2)
    assert (tmp_path / "inst_libfx.0001.exr").is_file()


def test_animation_render_dash_a_and_apply_to_last_render(blender, library, cli, tmp_path):
    """`blender -b file -a` over three frames with the add-on enabled gives three
    results, `-f 2` one; then, in a new session, "Apply to Last Render" re-runs a changed stack on
    frame 2's passes and writes what `libfx run` writes."""
    r1 = {"version": 1, "effects": [{"effect": "gaussian_blur", "params": {"sigma": 1.5},
                                     "mask": {"object": "Cube"}}]}
    setup = (T.PRELUDE + CUBE +
             "from libfx import recipe\n"
             "s.render.resolution_x, s.render.resolution_y, s.render.resolution_percentage = 64, 36, 100\n"
             "s.cycles.samples = 2\n"
             "s.frame_start, s.frame_end = 1, 3\n"
             "s.libfx.keep_passes = True\n"
             "bpy.data.objects['Cube'].rotation_euler.z = 0.0\n"
             "bpy.data.objects['Cube'].keyframe_insert('rotation_euler', frame=1)\n"
             "bpy.data.objects['Cube'].rotation_euler.z = 1.0\n"
             "bpy.data.objects['Cube'].keyframe_insert('rotation_euler', frame=3)\n"
             "recipe.from_recipe(s, %r)\n"
             "bpy.ops.wm.save_as_mainfile(filepath=%r)\n" % (json.dumps(r1), str(tmp_path / "anim.blend")))
    _ok(T.run_blender([], env=T.addon_env(library), python_expr=setup), "set-up")
    prefix = str(tmp_path / "anim_")
    proc = T.run_blender(["-o", prefix, "-a"], env=T.addon_env(library), blend=tmp_path / "anim.blend",
                         python_expr=T.PRELUDE)
    _ok(proc, "blender -b -a")
    for f in (1, 2, 3):
        assert (tmp_path / ("anim_libfx.%04d.exr" % f)).is_file(), f
        assert (tmp_path / ("anim_libfx_passes.%04d.exr" % f)).is_file(), f
    # -f: one frame the same way
    _ok(T.run_blender(["-o", str(tmp_path / "still_"), "-f", "2"], env=T.addon_env(library),
                      blend=tmp_path / "anim.blend", python_expr=T.PRELUDE), "blender -b -f 2")
    assert sorted(p.name for p in tmp_path.glob("still_libfx.*.exr")) == ["still_libfx.0002.exr"]
    p1 = T.Exr(tmp_path / "anim_libfx_passes.0001.exr").get("Combined", "RGB")
    p3 = T.Exr(tmp_path / "anim_libfx_passes.0003.exr").get("Combined", "RGB")
    assert np.abs(p1 - p3).max() > 1e-3   # three frames, not one frame three times

    r2 = {"version": 1, "effects": [{"effect": "gaussian_blur", "params": {"sigma": 4.0},
                                     "mask": {"object": "Cube"}}]}
    apply = (T.PRELUDE +
             "from libfx import recipe\n"
             "s = bpy.context.scene\n"
             "s.render.filepath = %r\n"
             "s.frame_set(2)\n"
             "recipe.from_recipe(s, %r)\n"
             "assert bpy.ops.libfx.rerun.poll()\n"
             "assert bpy.ops.libfx.rerun() == {'FINISHED'}\n"
             "print('APPLIED')\n" % (prefix, json.dumps(r2)))
    out = _ok(T.run_blender([], env=T.addon_env(library), blend=tmp_path / "anim.blend", python_expr=apply),
              "Apply to Last Render")
    assert "APPLIED" in out
    rfile = tmp_path / "r2.json"
    rfile.write_text(json.dumps(r2))
    ref = tmp_path / "cli.exr"
    p = subprocess.run([str(cli), "run", "--quiet", "--stack", str(rfile), "--camera",
                        str(tmp_path / "anim_libfx.0002.camera.json"),
                        str(tmp_path / "anim_libfx_passes.0002.exr"), "-o", str(ref)],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    got = T.Exr(tmp_path / "anim_libfx.0002.exr").get("Combined", "RGBA")
    assert np.array_equal(got, T.Exr(ref).get("Combined", "RGBA"))
    before = T.Exr(tmp_path / "anim_libfx_passes.0002.exr").get("Combined", "RGBA")
    assert np.abs(got - before).max() > 1e-3
