"""The truth scenes (blend_scenes/truth_*, issue 14) build and render: one small variant
of each is built by its script into a temporary directory (LIBFX_SCENES_OUT), then
rendered through the add-on's batch path twice at 96x54, 2 samples: as libfx's input
(the scene's recipe: the passes it needs must be there) and as the Cycles truth (the
script's apply_truth(), a no-op recipe). tests/bench/truth_*.py measure with them."""
import json

import numpy as np
import pytest

import addon_testlib as T

CASES = [("mirrors", ["--variant", "facing"], "truth_mirrors_facing.blend"),
         ("shadows", ["--variant", "floor"], "truth_shadows_floor.blend"),
         ("godrays", [], "truth_godrays_window.blend"),
         ("caustics", [], "truth_caustics_pool.blend")]
NOOP = {"version": 1, "effects": [{"effect": "color_matrix", "params": {"operator": "sepia", "mix": 0.0}}]}


def _batch(blend, prefix, library, expr=None, recipe=None):
    args = ["--keep-passes", "--frames", "1", "--output", prefix, "--resolution", "96x54", "--samples", "2"]
    if recipe:
        args += ["--recipe", str(recipe)]
    proc = T.run_blender([], blend=blend, env=T.addon_env(library), python_expr=expr, python=T.BATCH,
                         script_args=args, timeout=400, factory=False)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-5000:]
    assert not T.tracebacks(out), out[-5000:]
    return out


@pytest.mark.parametrize("name,args,blend_name", CASES, ids=[c[0] for c in CASES])
def test_truth_scene_builds_and_renders(name, args, blend_name, blender, library, cli, tmp_path):
    T.need_oiio()
    sdir = T.REPO / "blend_scenes" / ("truth_" + name)
    script = sdir / ("make_truth_%s.py" % name)
    built = tmp_path / "scene"
    proc = T.run_blender([], python=script, script_args=args, env={"LIBFX_SCENES_OUT": str(built)})
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-5000:]
    blend = built / blend_name
    assert blend.is_file() and (built / "recipe.json").is_file(), out[-3000:]
    # the builder's recipe is the committed one
    assert T.read_json(built / "recipe.json") == T.read_json(sdir / "recipe.json")

    log = _batch(blend, str(tmp_path / "in_"), library)
    passes = tmp_path / "in_libfx_passes.0001.exr"
    assert passes.is_file() and (tmp_path / "in_libfx.0001.camera.json").is_file()
    if name == "mirrors":  # the final preset's reflection probe: rendered and in the sidecar
        assert "probe 'probe:" in log and "rendered" in log, log[-3000:]
        side = T.read_json(tmp_path / "in_libfx.0001.camera.json")
        probes = [v for v in side.get("aux_views", []) if v.get("kind") == "probe"]
        assert len(probes) == 1 and probes[0]["panorama"] == "equirect", side.get("aux_views")
    import subprocess
    need = json.loads(subprocess.run([str(cli), "passes", "--stack", str(built / "recipe.json")],
                                     capture_output=True, text=True, check=True).stdout)
    exr = T.Exr(passes)
    for p in need["passes"]:
        assert any(q == p or q.startswith(p) for q in exr.passes()), (p, exr.passes())

    noop = tmp_path / "noop.json"
    noop.write_text(json.dumps(NOOP))
    expr = "import sys; sys.path.insert(0, %r); import make_truth_%s as m; m.apply_truth()" % (str(sdir), name)
    _batch(blend, str(tmp_path / "truth_"), library, expr=expr, recipe=noop)
    truth = T.Exr(tmp_path / "truth_libfx_passes.0001.exr").get("Combined", "RGB")
    plain = exr.get("Combined", "RGB")
    assert truth.shape == plain.shape == (54, 96, 3)
    assert np.isfinite(truth).all()
    # the real effect changes the picture
    assert np.abs(truth - plain).mean() > 1e-3


# Inside Blender on the committed pool scene: the waves flattened, frame 1 rendered four times
# at 64x36, 16 samples, to single-layer EXRs: the truth (apply_truth) and the input (the water
# hidden), each with the Sun on and off (the sky, a second light, always on).
FLAT_POOL = r"""
import bpy, json, sys
sys.path.insert(0, %(sdir)r)
import make_truth_caustics as m
sc = bpy.context.scene
m.apply_truth(sc)
bpy.data.objects["Water"].modifiers["Waves"].strength = 0.0
sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = 64, 36, 100
sc.cycles.samples = 16
sc.render.use_compositing = False
im = sc.render.image_settings
if hasattr(im, "media_type"):
    im.media_type = "IMAGE"
im.file_format, im.color_depth, im.color_mode = "OPEN_EXR", "32", "RGB"
sun = bpy.data.objects["Sun"]
energy = sun.data.energy
for water in (True, False):
    bpy.data.objects["Water"].hide_render = not water
    for lit in (True, False):
        sun.data.energy = energy if lit else 0.0
        sc.render.filepath = "%(out)s/%%s_%%s.exr" %% ("truth" if water else "input", "sun" if lit else "sky")
        bpy.ops.render.render(write_still=True)
import numpy as np
means = {}
for name in ("truth_sun", "truth_sky", "input_sun", "input_sky"):
    img = bpy.data.images.load("%(out)s/" + name + ".exr")   # linear float pixels, bottom row first
    px = np.empty(img.size[0] * img.size[1] * 4, dtype=np.float32)
    img.pixels.foreach_get(px)
    rgb = px.reshape(img.size[1], img.size[0], 4)[:, :, :3].astype(np.float64)
    means[name] = float((rgb @ [0.2126, 0.7152, 0.0722])[:, 14:50].mean())   # the central 36 x 36
d = sun.matrix_world.to_quaternion() @ __import__("mathutils").Vector((0, 0, 1))
print("LIBFX_SUN " + json.dumps({"cos": d.normalized().z, "means": means}))
"""


def _fresnel_t(cos_i, n):
    """The unpolarised Fresnel transmittance from air into index n (the exact formula)."""
    cos_t = np.sqrt(1.0 - (1.0 - cos_i * cos_i) / (n * n))
    rs = (cos_i - n * cos_t) / (cos_i + n * cos_t)
    rp = (n * cos_i - cos_t) / (n * cos_i + cos_t)
    return 1.0 - 0.5 * (rs * rs + rp * rp)


def test_caustics_truth_flat_water_transmits_fresnel(blender, tmp_path):
    """Under flat water the floor gets the sun's light in air times the Fresnel transmittance T
    (flux through parallel planes is conserved): the truth's Sun share (Sun on minus off) over
    the input's, on the central square. Cycles alone gave 2 T / n^2 = 1.108 (its MNEE counts a
    sun's caustic once per sampled light, and its refraction leaves out the radiance factor n^2);
    apply_truth corrects both (0.991 on 3.4, whose Principled floor adds a glossy bounce off the
    water's underside; 0.982 on 4.3 and 5.2)."""
    sdir = T.REPO / "blend_scenes" / "truth_caustics"
    proc = T.run_blender([], blend=sdir / "truth_caustics_pool.blend", timeout=400,
                         python_expr=FLAT_POOL % {"sdir": str(sdir), "out": str(tmp_path)})
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0 and not T.tracebacks(out), out[-5000:]
    # the means are taken inside Blender (its own EXR reader: no OpenImageIO needed in the roots)
    got = json.loads([x for x in out.splitlines() if x.startswith("LIBFX_SUN ")][-1][len("LIBFX_SUN "):])
    cos_i, m = got["cos"], got["means"]
    share = (m["truth_sun"] - m["truth_sky"]) / (m["input_sun"] - m["input_sky"])
    t = _fresnel_t(cos_i, 1.33)
    assert abs(cos_i - np.cos(np.radians(20.0))) < 1e-3   # the scene's sun, 70 deg up
    assert abs(share - t) < 0.025, (share, t)
    print("flat water: share %.4f, Fresnel T %.4f" % (share, t))
