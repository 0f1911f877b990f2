"""Failures make batch runs exit non-zero with a message naming the frame and the effect."""
import json

import addon_testlib as T

WORKBENCH = "import bpy\nbpy.context.scene.render.engine = 'BLENDER_WORKBENCH'\n"


def _recipe(tmp_path, entry):
    p = tmp_path / "r.json"
    p.write_text(json.dumps({"version": 1, "quality": "final", "effects": [entry]}))
    return p


def test_effect_failing_on_a_frame_exits_nonzero(blender, library, tmp_path):
    # Workbench renders no Object Index pass: the masked effect cannot run on frame 1.
    r = _recipe(tmp_path, {"effect": "gaussian_blur", "params": {"sigma": 2.0}, "mask": {"object_index": 1}})
    proc = T.run_blender([], env=T.addon_env(library), python_expr=WORKBENCH, python=T.BATCH,
                         script_args=["--frames", "1", "--output", tmp_path / "o_", "--resolution", "64x36",
                                      "--recipe", r])
    err = proc.stderr
    assert proc.returncode == 1, proc.stdout[-2000:] + err[-2000:]
    assert "frame 1" in err and "gaussian_blur" in err and "IndexOB" in err, err[-3000:]
    assert not T.tracebacks(proc.stdout + err)
    # the engine limitation was explained before rendering
    assert "Cryptomatte" in err, err[-3000:]
    assert not (tmp_path / "o_libfx.0001.exr").exists()


def test_impossible_parameter_exits_nonzero_naming_effect_and_parameter(blender, library, tmp_path):
    r = _recipe(tmp_path, {"effect": "gaussian_blur", "params": {"sigma": -5.0}})
    proc = T.run_blender([], env=T.addon_env(library), python=T.BATCH,
                         script_args=["--frames", "1", "--output", tmp_path / "o_", "--recipe", r])
    assert proc.returncode == 2, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert "gaussian_blur" in proc.stderr and "sigma" in proc.stderr, proc.stderr[-2000:]


def test_batch_without_library_exits_nonzero(blender, tmp_path):
    proc = T.run_blender([], env={"LIBFX_LIBRARY": "/nonexistent/libfx.so"}, python=T.BATCH,
                         script_args=["--frames", "1", "--output", tmp_path / "o_"])
    assert proc.returncode == 2, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert "libfx library not found" in proc.stderr
    assert not T.tracebacks(proc.stdout + proc.stderr)
