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
