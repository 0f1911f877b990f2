"""The rainy atrium (issue 7) headless: the auxiliary views (the Sun's light view, the
rain map) are rendered only when the stack needs them, once, and reused for the next
frames; the stack runs; the CLI gives the same pixels from the sidecar the add-on wrote.
Renders are tiny (160x90, 2 samples)."""
import json
import re
import subprocess

import numpy as np
import pytest

import addon_testlib as T

BLEND = T.SCENES_DIR / "atrium" / "atrium.blend"
RES = "160x90"


def batch(out_prefix, library, *extra, frames="1-2"):
    return T.run_blender([], blend=BLEND, env=T.addon_env(library), python=T.BATCH,
                         script_args=["--keep-passes", "--frames", frames, "--output", out_prefix, "--resolution", RES,
                                      "--samples", "2", *extra], timeout=600)


@pytest.mark.skipif(not BLEND.is_file(), reason="no atrium.blend")
def test_atrium_aux_views_made_once_and_reused(blender, library, cli, tmp_path):
    T.need_oiio()
    prefix = str(tmp_path / "a_")
    proc = batch(prefix, library)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-5000:]
    assert not T.tracebacks(out), out[-5000:]
    # rendered once (frame 1), reused on frame 2
    for name in ("light:Sun", "rain_map"):
        assert out.count("aux view '%s' rendered" % name) == 1, out[-4000:]
        assert out.count("aux view '%s' reused" % name) == 1, out[-4000:]
    light = tmp_path / "a_libfx_aux_light_Sun.exr"
    rain = tmp_path / "a_libfx_aux_rain_map.exr"
    assert light.is_file() and rain.is_file()
    depth = T.Exr(light).get("Depth", "V") if T.Exr(light).has("Depth") else None
    assert depth is not None
    assert np.isfinite(depth).all() and (depth < 1e9).mean() > 0.5   # the scene fills the light view

    for frame in (1, 2):
        side = T.read_json(tmp_path / ("a_libfx.%04d.camera.json" % frame))
        assert [v["name"] for v in side["aux_views"]] == ["light:Sun", "rain_map"]
        plain = T.Exr(tmp_path / ("a_libfx_passes.%04d.exr" % frame)).get("Combined", "RGBA")
        res = T.Exr(tmp_path / ("a_libfx.%04d.exr" % frame)).get("Combined", "RGBA")
        assert np.isfinite(res).all()
        assert (np.abs(res - plain).max(axis=-1) > 1e-4).mean() > 0.05   # shadows, wet, rain

    # the CLI, given the sidecar (which lists the aux views), gives the same pixels
    cli_out = tmp_path / "cli.exr"
    p = subprocess.run([str(cli), "run", "--stack", str(tmp_path / "a_libfx_recipe.json"),
                        str(tmp_path / "a_libfx_passes.0002.exr"), "-o", str(cli_out),
                        "--camera", str(tmp_path / "a_libfx.0002.camera.json"), "--frame", "2", "--fps", "24"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stdout + p.stderr
    a = T.Exr(cli_out).get("Combined", "RGBA")
    b = T.Exr(tmp_path / "a_libfx.0002.exr").get("Combined", "RGBA")
    assert np.array_equal(a, b)

    # a second run: nothing re-rendered (light and geometry did not move)
    proc2 = batch(prefix, library, frames="3")
    out2 = proc2.stdout + proc2.stderr
    assert proc2.returncode == 0, out2[-4000:]
    assert not re.search(r"aux view '[^']*' rendered", out2), out2[-3000:]
    assert out2.count("reused") == 2


@pytest.mark.skipif(not BLEND.is_file(), reason="no atrium.blend")
def test_atrium_no_aux_views_when_the_stack_needs_none(blender, library, tmp_path):
    recipe = tmp_path / "r.json"
    recipe.write_text(json.dumps({"version": 1, "effects": [
        {"effect": "color_matrix", "params": {"operator": "sepia", "mix": 0.5}}]}))
    prefix = str(tmp_path / "n_")
    proc = batch(prefix, library, "--recipe", str(recipe), frames="1")
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-4000:]
    assert "aux view" not in out, out[-3000:]
    assert not list(tmp_path.glob("n_libfx_aux_*")), list(tmp_path.iterdir())
    side = T.read_json(tmp_path / "n_libfx.0001.camera.json")
    assert "aux_views" not in side
