"""ZIP and ZIPS files libfx writes (deflated by libdeflate when libfx is built with it,
io/exr_zip.c) decode in other readers to exactly the frame's values: OpenImageIO
(OpenEXR's C++ library) and idiff against the same frame written uncompressed.
Odd widths, 1x1, one row, one column, several chunks, half and float channels, and
chunks of noise that are stored raw because they do not shrink.

    /usr/bin/python3 -m pytest tests/python/test_exr_zip.py

The library is $LIBFX_LIBRARY, else build*/libfx/libfx.so.2 under the repository root.
"""
import ctypes
import subprocess

import numpy as np
import pytest

oiio = pytest.importorskip("OpenImageIO")



# one binding of the library for both ctypes test files
from test_exr_interop import WriteOptions, load_fx  # noqa: E402


@pytest.fixture(scope="module")
def fx():
    lib = load_fx(2)
    yield lib
    lib.fx_context_free(lib.ctx)


def _planes(w, h, seed):
    rng = np.random.RandomState(seed)
    # noise: random mantissa and sign, exponents of ordinary values: does not deflate
    bits = rng.randint(0, 2**32, (h, w, 3), dtype=np.uint64).astype(np.uint32) & np.uint32(0x807FFFFF)
    bits |= (rng.randint(100, 140, (h, w, 3)).astype(np.uint32) << np.uint32(23))
    yy, xx = np.mgrid[0:h, 0:w]
    return {
        "Combined": (rng.rand(h, w, 4) * 4).astype(np.float32),
        "Depth": (1.0 + xx * 0.25 + yy * 3.0).astype(np.float32)[..., None],
        "Noise": bits.view(np.float32),
        "Emit": np.full((h, w, 3), 0.5, np.float32),
    }


LETTERS = {"Combined": "RGBA", "Depth": "Z", "Emit": "RGB", "Noise": "RGB"}


def _write(fx, planes, w, h, path, codec, half):
    fr = ctypes.c_void_p()
    assert fx.fx_frame_new(fx.ctx, w, h, ctypes.byref(fr)) == 0
    try:
        for name, arr in planes.items():
            a = np.ascontiguousarray(arr, np.float32)
            rc = fx.fx_frame_add_pass(fr, name.encode(), a.shape[2], a.ctypes.data_as(ctypes.POINTER(ctypes.c_float)))
            assert rc == 0, fx.fx_context_error(fx.ctx)
        opts = WriteOptions(ctypes.sizeof(WriteOptions), half, 0, None, codec.encode())
        rc = fx.fx_frame_write_exr(fr, str(path).encode(), ctypes.byref(opts))
        assert rc == 0, fx.fx_context_error(fx.ctx)
    finally:
        fx.fx_frame_free(fr)


def _read(path):
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    spec = inp.spec()
    data = np.asarray(inp.read_image(format=oiio.FLOAT), np.float32).reshape(spec.height, spec.width, spec.nchannels)
    inp.close()
    return spec, data


SIZES = [(1, 1), (1, 9), (9, 1), (33, 17), (257, 40)]


@pytest.mark.parametrize("codec", ["zip", "zips"])
@pytest.mark.parametrize("half", [0, 1])
@pytest.mark.parametrize("size", SIZES, ids=[f"{w}x{h}" for w, h in SIZES])
def test_zip_decodes_to_the_frame(fx, tmp_path, codec, half, size):
    w, h = size
    planes = _planes(w, h, seed=w * 100 + h)
    packed, plain = tmp_path / f"{codec}.exr", tmp_path / "none.exr"
    _write(fx, planes, w, h, packed, codec, half)
    _write(fx, planes, w, h, plain, "none", half)
    spec, data = _read(packed)
    _, ref = _read(plain)
    assert spec.get_string_attribute("compression") == codec
    assert (spec.width, spec.height) == (w, h)
    names = list(spec.channelnames)
    np.testing.assert_array_equal(data.view(np.uint32), ref.view(np.uint32))  # bit for bit
    for p, letters in LETTERS.items():
        for k, c in enumerate(letters):
            got = data[..., names.index(f"{p}.{c}")]
            want = planes[p][..., k]
            if half and p in ("Combined", "Emit"):
                fmt = dict(zip(names, [str(f) for f in spec.channelformats]))[f"{p}.{c}"]
                assert fmt == "half"
                np.testing.assert_allclose(got, want.astype(np.float16).astype(np.float32), rtol=0, atol=0)
            else:
                np.testing.assert_array_equal(got.view(np.uint32), want.view(np.uint32))
    out = subprocess.run(["idiff", "-fail", "0", "-warn", "0", str(packed), str(plain)],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stdout + out.stderr


def test_zip_is_smaller_than_raw_where_data_repeats(fx, tmp_path):
    """Flat and smooth passes shrink; the noise chunks stay raw, so the file is never
    much larger than the uncompressed one."""
    w, h = 257, 40
    planes = _planes(w, h, seed=3)
    _write(fx, planes, w, h, tmp_path / "zip.exr", "zip", 0)
    _write(fx, planes, w, h, tmp_path / "none.exr", "none", 0)
    flat = {"Emit": planes["Emit"], "Depth": planes["Depth"]}
    _write(fx, flat, w, h, tmp_path / "flat_zip.exr", "zip", 0)
    _write(fx, flat, w, h, tmp_path / "flat_none.exr", "none", 0)
    size = lambda n: (tmp_path / n).stat().st_size
    assert size("zip.exr") < size("none.exr")
    assert size("flat_zip.exr") * 10 < size("flat_none.exr")
    noise = {"Noise": planes["Noise"]}
    _write(fx, noise, w, h, tmp_path / "noise_zip.exr", "zip", 0)
    _write(fx, noise, w, h, tmp_path / "noise_none.exr", "none", 0)
    # every chunk stored raw: the files differ only by the chunk count (NONE: one line a
    # chunk, ZIP: 16), 8 bytes of offset table and 8 of chunk header per chunk
    chunks_none, chunks_zip = h, (h + 15) // 16
    assert size("noise_none.exr") - size("noise_zip.exr") == 16 * (chunks_none - chunks_zip)
