"""The same recipe on the same EXR gives the same output bits from every libfx build.

Run by scripts/blender_matrix.sh after each system (Debian 12, 13, unstable: gcc
12.2/14.2/16.2, OpenEXR 3.1.5/3.2.12/3.4.16) built libfx and ran tests/matrix/bits_dump.sh:

    LIBFX_BITS_DIRS="out/matrix/bits/host out/matrix/bits/trixie" \\
        /usr/bin/python3 -m pytest tests/matrix

Pixels are compared as bits (float32 patterns, so -0.0 != 0.0 and any NaN payload
counts), with every channel name and the camera attributes; the EXR files' bytes
may differ since OpenEXR versions compress differently.  An effect that fails on
a scene must fail with the same message in every build.
"""
import os
import pathlib

import numpy as np
import pytest

import OpenImageIO as oiio

DIRS = [pathlib.Path(d) for d in os.environ.get("LIBFX_BITS_DIRS", "").split()]
#: The least number of outputs a dump must hold: three scenes' recipes and most effects.
MIN_OUTPUTS = 20


def _read(path):
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, "cannot open %s: %s" % (path, oiio.geterror())
    spec = inp.spec()
    data = inp.read_image(0, 0, 0, spec.nchannels, "float")
    inp.close()
    attrs = {a.name: a.value for a in spec.extra_attribs if a.name in ("worldToCamera", "worldToNDC")}
    return list(spec.channelnames), np.ascontiguousarray(data, dtype=np.float32), attrs


def _names(d, ext):
    return sorted(p.name for p in d.glob("*" + ext))


def test_at_least_two_builds_dumped():
    assert len(DIRS) >= 2, "LIBFX_BITS_DIRS must name two or more dumps, got %r" % DIRS
    for d in DIRS:
        assert len(_names(d, ".exr")) >= MIN_OUTPUTS, "%s holds only %d outputs" % (d, len(_names(d, ".exr")))


def test_same_outputs_and_errors():
    base = DIRS[0]
    for d in DIRS[1:]:
        assert _names(d, ".exr") == _names(base, ".exr"), (base, d)
        assert _names(d, ".err") == _names(base, ".err"), (base, d)
        for name in _names(base, ".err"):
            a = (base / name).read_text().strip()
            b = (d / name).read_text().strip()
            assert a == b, "%s: %s says %r, %s says %r" % (name, base, a, d, b)


def _params():
    return _names(DIRS[0], ".exr") if len(DIRS) >= 2 else []


@pytest.mark.parametrize("name", _params())
def test_same_bits(name):
    ref_names, ref, ref_attrs = _read(DIRS[0] / name)
    for d in DIRS[1:]:
        names, px, attrs = _read(d / name)
        assert names == ref_names, (name, d)
        assert attrs.keys() == ref_attrs.keys(), (name, d)
        for k in ref_attrs:
            assert np.array_equal(np.asarray(attrs[k]), np.asarray(ref_attrs[k])), (name, d, k)
        a, b = ref.view(np.uint32), px.view(np.uint32)
        differ = a != b
        if differ.any():
            where = np.argwhere(differ)
            y, x, c = where[0]
            delta = np.abs(ref.astype(np.float64) - px.astype(np.float64))[differ]
            pytest.fail("%s: %s and %s differ in %d of %d values (max |diff| %.3g); first at x=%d y=%d "
                        "channel %s: %r vs %r" % (name, DIRS[0].name, d.name, differ.sum(), differ.size,
                                                  np.nanmax(delta), x, y, ref_names[c], ref[y, x, c], px[y, x, c]))
