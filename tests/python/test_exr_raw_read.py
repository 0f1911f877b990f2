"""Uncompressed EXRs are read channel by channel (io/exr_read.c, raw_chunk): only the
rows of the channels a stack needs are read, straight from the file. The same file
compressed with ZIP goes through OpenEXRCore's decoder, so the two must give the same
bits, for every subset of channels, with data windows away from the origin, with
half channels mixed in (those take OpenEXRCore's path) and for damaged files."""
import pathlib

import numpy as np
import pytest

from conftest import EXIT_INPUT, need_oiio, oiio, read_exr, write_recipe


def _write(path, channels, compression, half=(), origin=(0, 0)):
    """channels: {name: HxW array}; half: names stored as half floats."""
    need_oiio()
    names = list(channels)
    h, w = next(iter(channels.values())).shape
    spec = oiio.ImageSpec(w, h, len(names), oiio.FLOAT)
    spec.channelnames = tuple(names)
    spec.channelformats = tuple(oiio.TypeDesc(oiio.HALF if n in half else oiio.FLOAT) for n in names)
    spec.x, spec.y = origin
    spec.full_x = spec.full_y = 0
    spec.full_width, spec.full_height = w + origin[0] + 3, h + origin[1] + 2
    spec.attribute("compression", compression)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec), out.geterror()
    data = np.ascontiguousarray(np.stack([channels[n] for n in names], axis=-1), np.float32)
    assert out.write_image(data), out.geterror()
    out.close()
    return path


def _passes(w=37, h=23):
    """Blender-like passes: Combined, a 3-level Cryptomatte, Depth, Normal, Position."""
    rng = np.random.RandomState(5)
    chans = {}
    for p, cs in [("Combined", "RGBA"), ("CryptoMaterial00", "RGBA"), ("CryptoMaterial01", "RGBA"),
                  ("Depth", "V"), ("Normal", "XYZ"), ("Position", "XYZ")]:
        for c in cs:
            chans["%s.%s" % (p, c)] = (rng.rand(h, w) * 10 - 2).astype(np.float32)
    chans["Depth.V"] = (1 + rng.rand(h, w) * 50).astype(np.float32)
    return chans


def _bits(path):
    return {k: v.view(np.uint32).copy() for k, v in read_exr(path).items()}


@pytest.mark.parametrize("recipe_effects,extra", [
    ([], []),                                                   # Combined only
    ([], ["--keep-passes"]),                                     # every channel
    ([{"effect": "edges"}], []),                                 # Combined, Depth, Normal
])
@pytest.mark.parametrize("origin", [(0, 0), (4, 3)])
def test_uncompressed_reads_the_same_bits_as_zip(run, tmp_path, recipe_effects, extra, origin):
    chans = _passes()
    recipe = write_recipe(tmp_path / "r.json", recipe_effects)
    outs = {}
    for comp in ("none", "zip"):
        src = _write(tmp_path / ("in_%s.exr" % comp), chans, comp, origin=origin)
        out = tmp_path / ("out_%s.exr" % comp)
        r = run("run", "--quiet", "--stack", recipe, src, "-o", out, *extra)
        assert r.returncode == 0, r.stderr
        outs[comp] = _bits(out)
    assert outs["none"].keys() == outs["zip"].keys()
    for k in outs["zip"]:
        assert np.array_equal(outs["none"][k], outs["zip"][k]), k
    if "--keep-passes" in extra:
        got = read_exr(tmp_path / "out_none.exr")
        for name, plane in chans.items():
            written = "Depth.Z" if name == "Depth.V" else name  # libfx writes depth as Z
            match = [k for k in got if k.endswith(written)]
            assert match and np.array_equal(got[match[0]], plane), name


def test_half_channels_take_the_decoder_and_agree(run, tmp_path):
    chans = _passes()
    half = {"Combined.R", "Combined.G", "Combined.B", "Combined.A"}
    recipe = write_recipe(tmp_path / "r.json", [])
    outs = {}
    for comp in ("none", "zip"):
        src = _write(tmp_path / ("in_%s.exr" % comp), chans, comp, half=half)
        out = tmp_path / ("out_%s.exr" % comp)
        r = run("run", "--quiet", "--stack", recipe, src, "-o", out)
        assert r.returncode == 0, r.stderr
        outs[comp] = _bits(out)
    for k in outs["zip"]:
        assert np.array_equal(outs["none"][k], outs["zip"][k]), k


def test_truncated_uncompressed_file_is_refused(run, tmp_path):
    src = _write(tmp_path / "in.exr", _passes(64, 40), "none")
    data = src.read_bytes()
    cut = tmp_path / "cut.exr"
    cut.write_bytes(data[: len(data) * 2 // 3])
    out = tmp_path / "out.exr"
    r = run("run", "--quiet", "--stack", write_recipe(tmp_path / "r.json", []), cut, "-o", out)
    assert r.returncode == EXIT_INPUT, (r.returncode, r.stderr)
    assert "cut.exr" in r.stderr
    assert not out.exists()
    assert not list(pathlib.Path(tmp_path).glob("*.tmp-*"))


@pytest.mark.parametrize("compression", ["none", "zip", "piz", "pxr24"])
@pytest.mark.parametrize("names", [("R", "G", "B", "X"), ("A", "B", "G", "R", "X"), ("B", "G", "R")])
def test_small_half_part_with_a_skipped_channel(run, tmp_path, compression, names):
    """OpenEXRCore's 3- and 4-channel half routines write every channel of the part: a
    part of 3 or 4 half channels of which the stack skips one crashed the reader (found
    by the fuzzer). Combined must come out as the halves the file holds."""
    rng = np.random.RandomState(3)
    chans = {n: (rng.rand(19, 27) * 4 - 1).astype(np.float16).astype(np.float32) for n in names}
    src = _write(tmp_path / "in.exr", chans, compression, half=set(names))
    out = tmp_path / "out.exr"
    r = run("run", "--quiet", "--stack", write_recipe(tmp_path / "r.json", []), src, "-o", out)
    assert r.returncode == 0, r.stderr
    got = read_exr(out)
    for c in "RGB":
        match = [k for k in got if k.endswith("." + c) or k == c]
        assert match and np.array_equal(got[match[0]], chans[c]), (c, sorted(got))
