"""Fixtures for the CLI tests: the `libfx` binary, small multilayer EXRs, recipes.

Run with Debian's interpreter (it has OpenImageIO and numpy):
    /usr/bin/python3 -m pytest tests/python
The CLI is $LIBFX_CLI, else build/libfx/libfx under the repository root.
"""
import json
import os
import pathlib
import subprocess

import numpy as np
import pytest

try:
    import OpenImageIO as oiio
except ImportError:  # pragma: no cover - the environment has python3-openimageio
    oiio = None

REPO = pathlib.Path(__file__).resolve().parents[2]
CORPUS = (REPO / ".." / "shared" / "exr-corpus").resolve()

EXIT_OK, EXIT_USAGE, EXIT_INPUT, EXIT_OUTPUT, EXIT_PROCESS, EXIT_INTERRUPTED = 0, 2, 3, 4, 5, 130


def _cli_path():
    env = os.environ.get("LIBFX_CLI")
    return pathlib.Path(env) if env else REPO / "build" / "libfx" / "libfx"


@pytest.fixture(scope="session")
def cli():
    path = _cli_path()
    if not path.is_file() or not os.access(path, os.X_OK):
        pytest.fail(f"the libfx CLI is not built at {path} (build it, or set LIBFX_CLI)")
    return str(path)


@pytest.fixture
def run(cli):
    """run(*args, input=None, timeout=120) -> CompletedProcess with text stdout/stderr."""

    def _run(*args, timeout=120, **kw):
        return subprocess.run([cli, *map(str, args)], capture_output=True, text=True,
                              timeout=timeout, **kw)

    return _run


@pytest.fixture
def corpus():
    if not CORPUS.is_dir():
        pytest.skip(f"the shared EXR corpus is absent ({CORPUS})")
    return CORPUS


def need_oiio():
    if oiio is None:
        pytest.skip("python3-openimageio is not installed")


# ---- EXR helpers -------------------------------------------------------------------

def sample_pixels(width, height, seed=1):
    """Deterministic Combined RGBA: gradients plus noise (so blurs and pixelation show)."""
    rng = np.random.RandomState(seed)
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    rgba = np.empty((height, width, 4), np.float32)
    rgba[..., 0] = x / max(width - 1, 1)
    rgba[..., 1] = y / max(height - 1, 1)
    rgba[..., 2] = rng.rand(height, width).astype(np.float32)
    rgba[..., 3] = 1.0
    return rgba


def write_exr(path, planes, layer="ViewLayer"):
    """Writes a Blender-style multilayer EXR. planes: {"Combined": (array HxWx4, "RGBA"),
    "Depth": (HxWx1, "Z"), "IndexOB": (HxWx1, "X"), ...}; channel names are
    "<layer>.<pass>.<channel>" as Blender's render output writes them."""
    need_oiio()
    names, arrays = [], []
    for pass_name, (array, chans) in planes.items():
        array = np.asarray(array, np.float32)
        if array.ndim == 2:
            array = array[..., None]
        assert array.shape[2] == len(chans)
        for i, c in enumerate(chans):
            names.append(f"{layer}.{pass_name}.{c}" if layer else f"{pass_name}.{c}")
            arrays.append(array[..., i])
    data = np.ascontiguousarray(np.stack(arrays, axis=-1))
    h, w, n = data.shape
    spec = oiio.ImageSpec(w, h, n, oiio.FLOAT)
    spec.channelnames = tuple(names)
    spec.attribute("compression", "zip")
    out = oiio.ImageOutput.create(str(path))
    assert out is not None, oiio.geterror()
    assert out.open(str(path), spec), out.geterror()
    assert out.write_image(data), out.geterror()
    out.close()
    return path


def make_frame(path, width=48, height=32, seed=1, index_ob=True, depth=True, layer="ViewLayer"):
    rgba = sample_pixels(width, height, seed)
    planes = {"Combined": (rgba, "RGBA")}
    if depth:
        y, x = np.mgrid[0:height, 0:width].astype(np.float32)
        planes["Depth"] = (1.0 + x + y, "Z")
    if index_ob:
        idx = np.zeros((height, width), np.float32)
        idx[height // 4: height // 2, width // 4: width // 2] = 1.0
        idx[height // 2:, width // 2:] = 2.0
        planes["IndexOB"] = (idx, "X")
    return write_exr(path, planes, layer=layer)


def read_exr(path):
    """{channel name: HxW float32 array}"""
    need_oiio()
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    spec = inp.spec()
    data = inp.read_image(format=oiio.FLOAT)
    inp.close()
    data = np.asarray(data, np.float32).reshape(spec.height, spec.width, spec.nchannels)
    return {name: data[..., i] for i, name in enumerate(spec.channelnames)}


def combined(channels):
    """The RGBA planes of the Combined pass, whatever the layer prefix (HxWx4)."""
    out = []
    for c in "RGBA":
        names = [n for n in channels if n.endswith(f"Combined.{c}")] or \
                [n for n in channels if n == c]
        assert names, f"no Combined.{c} among {sorted(channels)}"
        out.append(channels[names[0]])
    return np.stack(out, axis=-1)


def write_recipe(path, effects, **extra):
    recipe = {"version": 1, "effects": effects}
    recipe.update(extra)
    pathlib.Path(path).write_text(json.dumps(recipe, indent=2))
    return path


@pytest.fixture
def frame(tmp_path):
    return make_frame(tmp_path / "in.exr")


@pytest.fixture
def helpers():
    """The module's helpers, for tests that need them without importing conftest."""

    class H:
        pass

    h = H()
    h.make_frame = make_frame
    h.write_exr = write_exr
    h.read_exr = read_exr
    h.combined = combined
    h.write_recipe = write_recipe
    h.sample_pixels = sample_pixels
    return h
