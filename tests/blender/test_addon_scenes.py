"""Batch renders of every test scene through the add-on, checked against the plain
render and against the CLI on the same input."""
import json
import os
import shutil
import subprocess

import numpy as np
import pytest

import addon_testlib as T

SCENES = T.scenes()
RES = "320x180"
SAMPLES = 4


def batch(blend, out_prefix, library, *extra, expr=None):
    return T.run_blender([], blend=blend, env=T.addon_env(library), python_expr=expr, python=T.BATCH,
                         script_args=["--keep-passes", "--frames", "1", "--output", out_prefix, "--resolution", RES,
                                      "--samples", SAMPLES, *extra], timeout=400)


def expected_passes(cli, recipe_path):
    p = subprocess.run([str(cli), "passes", "--stack", str(recipe_path)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout)


@pytest.mark.skipif(not SCENES, reason="no scene in blend_scenes/ yet")
@pytest.mark.parametrize("blend", SCENES, ids=[b.stem for b in SCENES])
def test_scene_batch_render(blend, blender, library, cli, tmp_path):
    T.need_oiio()
    prefix = str(tmp_path / "out_")
    proc = batch(blend, prefix, library)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-5000:]
    assert not T.tracebacks(out), out[-5000:]
    assert "libfx: frame 1:" in proc.stdout and " ms" in proc.stdout, out[-3000:]  # timings printed

    passes_file = tmp_path / "out_libfx_passes.0001.exr"
    result_file = tmp_path / "out_libfx.0001.exr"
    camera_file = tmp_path / "out_libfx.0001.camera.json"
    recipe_file = tmp_path / "out_libfx_recipe.json"
    for f in (passes_file, result_file, camera_file, recipe_file):
        assert f.is_file(), "%s missing; output: %s" % (f, out[-3000:])

    # The recipe that ran is the scene's (its text block = recipe.json beside the .blend).
    ran = T.read_json(recipe_file)
    scene_recipe = T.read_json(blend.parent / "recipe.json")
    assert [e["effect"] for e in ran["effects"]] == [e["effect"] for e in scene_recipe["effects"]]

    need = expected_passes(cli, recipe_file)
    plain = T.Exr(passes_file)
    res = T.Exr(result_file)
    assert (res.width, res.height) == (320, 180)
    for p in need["passes"]:
        for exr, what in ((plain, "passes file"), (res, "result")):
            if p.startswith("Crypto"):
                assert any(q.startswith(p) for q in exr.passes()), (what, p, exr.passes())
            else:
                assert exr.has(p), (what, p, exr.passes())
    assert "worldToCamera" in res.attrs, sorted(res.attrs)
    w2c = np.array(res.attrs["worldToCamera"], dtype=np.float64).reshape(4, 4)
    side = np.array(T.read_json(camera_file)["world_to_camera"], dtype=np.float64)
    assert np.allclose(w2c, side, atol=1e-4) or np.allclose(w2c.T, side, atol=1e-4), (w2c, side)

    # Masked regions changed; every pixel outside every mask bit-identical to the plain render.
    before = plain.get("Combined", "RGBA")
    after = res.get("Combined", "RGBA")
    assert np.isfinite(after).all()
    changed = np.any(after != before, axis=-1)
    assert changed.any(), "the stack changed nothing"
    supports = [T.mask_support(plain, e.get("mask")) for e in ran["effects"] if e.get("enabled", True)]
    if all(s is not None for s in supports):
        allowed = np.zeros_like(changed)
        for s in supports:
            allowed |= s
        assert allowed.any(), "no mask selects any pixel at this resolution"
        outside = ~allowed
        assert not (changed & outside).any(), "%d pixels outside every mask changed" % (changed & outside).sum()
        assert (changed & allowed).any()

    # The CLI on the same input + recipe + camera gives the same pixels.
    cli_out = tmp_path / "cli.exr"
    p = subprocess.run([str(cli), "run", "--stack", str(recipe_file), str(passes_file), "-o", str(cli_out),
                        "--camera", str(camera_file), "--frame", "1", "--fps", "24"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stdout + p.stderr
    via_cli = T.Exr(cli_out).get("Combined", "RGBA")
    assert np.array_equal(via_cli, after), "add-on and CLI differ in %d values" % (via_cli != after).sum()

    # A re-run skips the finished frame and changes nothing.
    mtime = result_file.stat().st_mtime_ns
    proc2 = batch(blend, prefix, library, "--skip-existing")
    assert proc2.returncode == 0, (proc2.stdout + proc2.stderr)[-3000:]
    assert "exists, skipped" in proc2.stdout
    assert result_file.stat().st_mtime_ns == mtime


SETUP_CUBE = (
    "import bpy\n"
    "s = bpy.context.scene\n"
    "s.render.engine = 'CYCLES'\n"
    "s.cycles.use_denoising = False\n"
    "s.render.dither_intensity = 0.0\n"
    "s.render.image_settings.file_format = 'PNG'\n"
    "s.render.image_settings.color_depth = '16'\n"
    "s.view_settings.view_transform = 'Standard'\n")


def test_image_in_scene_format_through_colour_management(blender, library, tmp_path):
    """A PNG scene: the libfx PNG equals Blender's own PNG outside the mask."""
    T.need_oiio()
    recipe = tmp_path / "r.json"
    recipe.write_text(json.dumps({"version": 1, "effects": [
        {"effect": "gaussian_blur", "params": {"sigma": 3.0}, "mask": {"object": "Cube"}}]}))
    prefix = str(tmp_path / "cube_")
    proc = T.run_blender([], env=T.addon_env(library), python_expr=SETUP_CUBE, python=T.BATCH,
                         script_args=["--keep-passes", "--frames", "1", "--output", prefix, "--resolution", "160x90",
                                      "--samples", "2", "--recipe", recipe])
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-4000:]
    blender_png = T.Exr(tmp_path / "cube_0001.png")
    libfx_png = T.Exr(tmp_path / "cube_libfx.0001.png")
    plain = T.Exr(tmp_path / "cube_libfx_passes.0001.exr")
    a = np.stack([blender_png.channels[c] for c in "RGB"], -1)
    b = np.stack([libfx_png.channels[c] for c in "RGB"], -1)
    support = T.mask_support(plain, {"object": "Cube"})
    assert support.any()
    outside = ~support
    assert np.abs(a - b)[outside].max() <= 1.0 / 65535 + 1e-7, np.abs(a - b)[outside].max()
    assert np.abs(a - b)[support].max() > 1e-3   # the blur shows inside the mask


@pytest.mark.skipif(not shutil.which("xvfb-run"), reason="xvfb-run is not installed")
@pytest.mark.skipif(not (T.SCENES_DIR / "greek_bath" / "greek_bath.blend").is_file(), reason="no greek_bath")
def test_f12_in_the_ui_shows_the_result(blender, library, tmp_path):
    """F12 with a window (xvfb): handlers on the render thread, result via timers."""
    shot = tmp_path / "panel.png"
    cmd = ["xvfb-run", "-a", "-s", "-screen 0 1600x900x24", T.blender_path(), "--factory-startup",
           str(T.SCENES_DIR / "greek_bath" / "greek_bath.blend"),
           "--python", str(T.REPO / "tests" / "blender" / "panel_screenshot.py"), "--", str(shot)]
    env = dict(os.environ, **T.addon_env(library))
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    except subprocess.TimeoutExpired as e:   # what it printed says where it stopped
        out = "".join(t.decode(errors="replace") if isinstance(t, bytes) else t
                      for t in (e.stdout or "", e.stderr or ""))
        raise AssertionError("no exit within 300 s; its output:\n" + out[-8000:]) from None
    assert p.returncode == 0, (p.stdout + p.stderr)[-8000:]
    assert "F12 result image: True" in p.stdout and shot.is_file()
    for line in (p.stdout + p.stderr).splitlines():   # (pytest -s) how often the retries were needed
        if "refused ID writes" in line:
            print(line)
