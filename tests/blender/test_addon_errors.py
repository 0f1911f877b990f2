"""Failures make batch runs exit non-zero with a message naming the frame and the effect,
and a library that cannot load makes them exit 2 with the loader's own reason."""
import importlib.util
import json
import os
import sys

import pytest

import addon_testlib as T

sys.path.insert(0, str(T.REPO / "tests" / "python"))
import broken_libraries as B  # noqa: E402

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
    assert "/nonexistent/libfx.so" in proc.stderr and "No such file or directory" in proc.stderr
    assert not T.tracebacks(proc.stdout + proc.stderr)


def _plain_python_error(path):
    """native.load_error() for ``path`` in this (non-Blender) Python: the same module."""
    spec = importlib.util.spec_from_file_location("native_for_errors", T.ADDON_DIR / "libfx" / "native.py")
    native = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(native)
    old = os.environ.get("LIBFX_LIBRARY")
    os.environ["LIBFX_LIBRARY"] = path
    try:
        assert native.load() is None
        return native.load_error()
    finally:
        if old is None:
            del os.environ["LIBFX_LIBRARY"]
        else:
            os.environ["LIBFX_LIBRARY"] = old


BROKEN = {   # how the library is broken -> (make it, the loader's words it must show)
    "truncated": (lambda lib, d: B.truncated(lib, d), "the file is truncated: 4096 bytes"),
    "32-bit": (lambda lib, d: B.elf32(d), "wrong ELF class: ELFCLASS32"),
    "windows-dll": (lambda lib, d: B.windows_dll(d), "invalid ELF header"),
    "missing": (lambda lib, d: B.missing(d), "No such file or directory"),
}


@pytest.mark.parametrize("kind", sorted(BROKEN))
def test_unloadable_library_batch_exits_2_and_panel_shows_the_loaders_reason(blender, library, tmp_path, kind):
    make, words = BROKEN[kind]
    path = make(library, tmp_path)
    message = _plain_python_error(path)
    assert path in message and words in message, message
    proc = T.run_blender([], env={"LIBFX_LIBRARY": path}, python=T.BATCH,
                         script_args=["--frames", "1", "--output", tmp_path / "o_"])
    assert proc.returncode == 2, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert "libfx batch: error: " + message in proc.stderr, (message, proc.stderr[-2000:])
    assert not T.tracebacks(proc.stdout + proc.stderr)
    assert not list(tmp_path.glob("o_*"))
    # the panel: the same text, wrapped into labels under "libfx library unavailable"
    script = T.PRELUDE + T.FAKE_LAYOUT + """
libfx.ui.draw_stack(lay, bpy.context)
i = lay.labels.index('libfx library unavailable')
lines = libfx.ui._wrap(libfx.native.load_error(), libfx.ui._chars(bpy.context))
assert lay.labels[i + 1:i + 1 + len(lines)] == lines, lay.labels
print('PANEL ' + json.dumps(lines))
"""
    proc = T.run_blender([], env={"LIBFX_LIBRARY": path}, python_expr=script)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    shown = json.loads(next(l for l in proc.stdout.splitlines() if l.startswith("PANEL "))[6:])
    assert "".join(shown).replace(" ", "") == message.replace(" ", ""), (shown, message)
