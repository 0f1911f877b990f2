"""Files libfx writes open in other tools: OpenImageIO (python3-openimageio) and
`oiiotool --info -v` see the channel names, types, windows, values and attributes.

    /usr/bin/python3 -m pytest tests/python/test_exr_interop.py

The library is $LIBFX_LIBRARY, else build*/libfx/libfx.so.2 under the repository root.
Only the public C API is used (through a few ctypes declarations here).
"""
import ctypes
import pathlib
import os
import subprocess

import numpy as np
import pytest

oiio = pytest.importorskip("OpenImageIO")

REPO = pathlib.Path(__file__).resolve().parents[2]


class Camera(ctypes.Structure):
    _fields_ = [("size", ctypes.c_size_t), ("world_to_camera", ctypes.c_float * 16),
                ("projection", ctypes.c_float * 16), ("clip_start", ctypes.c_float),
                ("clip_end", ctypes.c_float), ("orthographic", ctypes.c_int)]


class WriteOptions(ctypes.Structure):
    _fields_ = [("size", ctypes.c_size_t), ("half_color", ctypes.c_int),
                ("only_combined", ctypes.c_int), ("input_path", ctypes.c_char_p),
                ("compression", ctypes.c_char_p)]


def _library_path():
    env = os.environ.get("LIBFX_LIBRARY")
    if env:
        return pathlib.Path(env)
    for build in ("build", "build-h", "build-io", "build-addon"):
        p = REPO / build / "libfx" / "libfx.so.2"
        if p.is_file():
            return p
    return REPO / "build" / "libfx" / "libfx.so.2"


def load_fx(threads):
    """The library with the functions these tests call bound, and a context of `threads`
    as lib.ctx (free it with lib.fx_context_free(lib.ctx))."""
    path = _library_path()
    if not path.is_file():
        pytest.fail(f"libfx is not built at {path} (build it, or set LIBFX_LIBRARY)")
    lib = ctypes.CDLL(str(path))
    vp, cp, i, f = ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int, ctypes.c_float
    fp = ctypes.POINTER(ctypes.c_float)
    sig = {
        "fx_context_new": (i, [ctypes.POINTER(vp), i]),
        "fx_context_free": (None, [vp]),
        "fx_context_error": (cp, [vp]),
        "fx_frame_new": (i, [vp, i, i, ctypes.POINTER(vp)]),
        "fx_frame_free": (None, [vp]),
        "fx_frame_add_pass": (i, [vp, cp, i, fp]),
        "fx_frame_set_windows": (i, [vp, ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_int)]),
        "fx_frame_set_camera": (i, [vp, ctypes.POINTER(Camera)]),
        "fx_frame_set_time": (None, [vp, ctypes.c_double, ctypes.c_double]),
        "fx_frame_set_meta": (i, [vp, cp, cp]),
        "fx_frame_write_exr": (i, [vp, cp, ctypes.POINTER(WriteOptions)]),
        "fx_frame_write_png": (i, [vp, cp, cp, f]),
    }
    for name, (res, args) in sig.items():
        fn = getattr(lib, name)
        fn.restype, fn.argtypes = res, args
    ctx = ctypes.c_void_p()
    assert lib.fx_context_new(ctypes.byref(ctx), threads) == 0
    lib.ctx = ctx
    return lib


@pytest.fixture(scope="module")
def fx():
    lib = load_fx(1)
    yield lib
    lib.fx_context_free(lib.ctx)


def _floats(a):
    a = np.ascontiguousarray(a, np.float32)
    return a, a.ctypes.data_as(ctypes.POINTER(ctypes.c_float))


W, H = 40, 24
DW = (-3, 5, -3 + W - 1, 5 + H - 1)
DISP = (0, 0, 63, 47)


def _frame(fx):
    rng = np.random.RandomState(4)
    planes = {
        "Combined": rng.rand(H, W, 4).astype(np.float32) * 4.0,
        "Depth": (1.0 + rng.rand(H, W, 1) * 100).astype(np.float32),
        "Normal": (rng.rand(H, W, 3) * 2 - 1).astype(np.float32),
        "IndexOB": rng.randint(0, 7, (H, W, 1)).astype(np.float32),
        "CryptoObject00": rng.rand(H, W, 4).astype(np.float32),
    }
    fr = ctypes.c_void_p()
    assert fx.fx_frame_new(fx.ctx, W, H, ctypes.byref(fr)) == 0
    keep = []
    for name, arr in planes.items():
        a, p = _floats(arr)
        keep.append(a)
        assert fx.fx_frame_add_pass(fr, name.encode(), arr.shape[2], p) == 0, fx.fx_context_error(fx.ctx)
    dw, disp = (ctypes.c_int * 4)(*DW), (ctypes.c_int * 4)(*DISP)
    assert fx.fx_frame_set_windows(fr, dw, disp) == 0, fx.fx_context_error(fx.ctx)
    cam = Camera(ctypes.sizeof(Camera))
    w2c = [1, 0, 0, -1, 0, 1, 0, -2, 0, 0, 1, -10, 0, 0, 0, 1]
    proj = [2, 0, 0, 0, 0, 3, 0, 0, 0, 0, -1.002, -0.2002, 0, 0, -1, 0]
    cam.world_to_camera[:] = w2c
    cam.projection[:] = proj
    cam.clip_start, cam.clip_end = 0.1, 100.0
    assert fx.fx_frame_set_camera(fr, ctypes.byref(cam)) == 0
    fx.fx_frame_set_time(fr, 12.0, 25.0)
    assert fx.fx_frame_set_meta(fr, b"Scene", b"Interop") == 0
    return fr, planes, np.array(w2c, np.float32).reshape(4, 4)


def _write(fx, fr, path, half=0):
    opts = WriteOptions(ctypes.sizeof(WriteOptions), half, 0, None)
    rc = fx.fx_frame_write_exr(fr, str(path).encode(), ctypes.byref(opts))
    assert rc == 0, fx.fx_context_error(fx.ctx)


EXPECTED = {"Combined": "RGBA", "Depth": "Z", "Normal": "XYZ", "IndexOB": "X", "CryptoObject00": "RGBA"}


def test_openimageio_reads_channels_values_and_windows(fx, tmp_path):
    fr, planes, w2c = _frame(fx)
    path = tmp_path / "out.exr"
    try:
        _write(fx, fr, path)
    finally:
        fx.fx_frame_free(fr)
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    spec = inp.spec()
    data = np.asarray(inp.read_image(format=oiio.FLOAT), np.float32).reshape(H, W, spec.nchannels)
    inp.close()
    names = list(spec.channelnames)
    want = [f"{p}.{c}" for p, letters in EXPECTED.items() for c in letters]
    assert sorted(names) == sorted(want)
    for p, letters in EXPECTED.items():
        for k, c in enumerate(letters):
            got = data[..., names.index(f"{p}.{c}")]
            np.testing.assert_array_equal(got, planes[p][..., k])  # float: bit-exact
    assert (spec.x, spec.y, spec.width, spec.height) == (DW[0], DW[1], W, H)
    assert (spec.full_x, spec.full_y, spec.full_width, spec.full_height) == (0, 0, 64, 48)
    assert spec.get_string_attribute("compression") == "zip"
    assert spec.get_string_attribute("Scene") == "Interop"
    # Imath's row-vector convention: the file holds the transpose of Blender's matrix
    m = np.array(spec.getattribute("worldToCamera"), np.float32).reshape(4, 4)
    np.testing.assert_allclose(m, w2c.T, atol=1e-6)
    assert spec.getattribute("worldToNDC") is not None
    assert abs(spec.getattribute("libfx:frame") - 12.0) < 1e-9


def test_half_color_types(fx, tmp_path):
    fr, planes, _ = _frame(fx)
    path = tmp_path / "half.exr"
    try:
        _write(fx, fr, path, half=1)
    finally:
        fx.fx_frame_free(fr)
    spec = oiio.ImageInput.open(str(path)).spec()
    fmts = dict(zip(spec.channelnames, [str(f) for f in spec.channelformats]))
    assert fmts["Combined.R"] == "half"
    for data_channel in ("Depth.Z", "Normal.X", "IndexOB.X", "CryptoObject00.R"):
        assert fmts[data_channel] == "float", data_channel


def test_oiiotool_info(fx, tmp_path):
    fr, _, _ = _frame(fx)
    path = tmp_path / "info.exr"
    try:
        _write(fx, fr, path)
    finally:
        fx.fx_frame_free(fr)
    out = subprocess.run(["oiiotool", "--info", "-v", str(path)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    text = out.stdout
    for needle in (" 40 x   24", "Combined.R", "Depth.Z", "Normal.X", "CryptoObject00.A", 'compression: "zip"',
                   "worldToCamera", "worldToNDC", "pixel data origin: x=-3, y=5"):
        assert needle in text, (needle, text)


def test_png_preview_is_srgb(fx, tmp_path):
    fr = ctypes.c_void_p()
    assert fx.fx_frame_new(fx.ctx, 4, 1, ctypes.byref(fr)) == 0
    # OpenImageIO premultiplies PNG alpha on read: keep colour and alpha checks apart
    px = np.array([[0, 0, 0, 0.5], [0.18, 0.18, 0.18, 1], [0.5, 0.5, 0.5, 1], [4, 4, 4, 1]], np.float32)
    a, p = _floats(px)
    assert fx.fx_frame_add_pass(fr, b"Combined", 4, p) == 0
    path = tmp_path / "p.png"
    try:
        assert fx.fx_frame_write_png(fr, str(path).encode(), None, 0.0) == 0, fx.fx_context_error(fx.ctx)
    finally:
        fx.fx_frame_free(fr)
    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    img = np.asarray(inp.read_image(format=oiio.UINT8)).reshape(1, 4, 4)
    inp.close()
    assert spec.nchannels == 4
    # sRGB OETF: 0.18 -> 0.4614 -> 118; 0.5 -> 0.7354 -> 188; alpha linear
    assert list(img[0, :, 0]) == [0, 118, 188, 255]
    assert list(img[0, :, 3]) == [128, 255, 255, 255]
