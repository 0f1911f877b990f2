"""The `libfx` CLI: help, version, list/describe/info/passes, and `run` on single files.

Errors are in test_cli_errors.py, sequences and Ctrl-C in test_cli_sequences.py.
"""
import json
import re

import numpy as np
import pytest

from conftest import (REPO, EXIT_OK, EXIT_USAGE, combined, make_frame, read_exr, write_exr,
                      write_recipe)

EFFECTS = ("gaussian_blur", "color_matrix", "pixelate")


def describe(run, effect):
    r = run("describe", "--compact", effect)
    assert r.returncode == EXIT_OK, r.stderr
    return json.loads(r.stdout)


def param_names(desc):
    params = desc["params"]
    return [p["name"] for p in params] if isinstance(params, list) else list(params)


# ---- help and version ----------------------------------------------------------------

def test_version(run):
    r = run("--version")
    assert r.returncode == EXIT_OK
    header = (REPO / "libfx" / "include" / "libfx" / "fx.h").read_text()
    abi = re.search(r"#define\s+FX_ABI_VERSION\s+(\d+)", header).group(1)
    assert r.stdout.startswith("libfx ") and "ABI %s" % abi in r.stdout


def test_help_lists_commands_and_exit_codes(run):
    r = run("--help")
    assert r.returncode == EXIT_OK
    for word in ("list", "describe", "info", "passes", "run", "130"):
        assert word in r.stdout
    for code in ("  2 ", "  3 ", "  4 ", "  5 "):
        assert code in r.stdout


@pytest.mark.parametrize("cmd", ["list", "describe", "info", "passes", "run"])
def test_help_per_command(run, cmd):
    r = run(cmd, "--help")
    assert r.returncode == EXIT_OK, r.stderr
    assert r.stdout.startswith(f"usage: libfx {cmd}")
    assert run("help", cmd).stdout == r.stdout


def test_no_command_is_a_usage_error(run):
    r = run()
    assert r.returncode == EXIT_USAGE
    assert "usage:" in r.stderr


def test_unknown_command(run):
    r = run("frobnicate")
    assert r.returncode == EXIT_USAGE
    assert r.stderr.strip().splitlines() == ["libfx: error: unknown command 'frobnicate' "
                                             "(see 'libfx --help')"]


# ---- list / describe / info / passes ----------------------------------------------------

def test_list_one_effect_per_line(run):
    r = run("list")
    assert r.returncode == EXIT_OK
    lines = r.stdout.splitlines()
    names = []
    for line in lines:
        name, doc = line.split("\t")
        assert name and doc.strip(), line
        names.append(name)
    for e in EFFECTS:
        assert e in names


@pytest.mark.parametrize("effect", EFFECTS)
def test_describe_is_json_with_params(run, effect):
    r = run("describe", effect)
    assert r.returncode == EXIT_OK, r.stderr
    desc = json.loads(r.stdout)  # indented for reading, still JSON
    assert desc.get("name", effect) == effect
    assert param_names(desc)
    assert "\n  " in r.stdout  # indented
    compact = json.loads(run("describe", "--compact", effect).stdout)
    assert compact == desc


def test_info_shapes(run, tmp_path):
    path = make_frame(tmp_path / "in.exr", width=40, height=24)
    r = run("info", path)
    assert r.returncode == EXIT_OK, r.stderr
    info = json.loads(r.stdout)
    text = json.dumps(info)
    for word in ("Combined", "Depth", "IndexOB"):
        assert word in text
    assert 40 in _numbers(info) and 24 in _numbers(info)


def _numbers(obj):
    if isinstance(obj, dict):
        return [n for v in obj.values() for n in _numbers(v)]
    if isinstance(obj, list):
        return [n for v in obj for n in _numbers(v)]
    return [obj] if isinstance(obj, (int, float)) and not isinstance(obj, bool) else []


def test_info_corpus_multipart(run, corpus):
    """info lists every part of a multipart file with its name and channel count, as
    OpenImageIO reads them (its subimages)."""
    path = corpus / "openexr-images" / "Beachball" / "multipart.0001.exr"
    r = run("info", path)
    assert r.returncode == EXIT_OK, r.stderr
    info = json.loads(r.stdout)
    assert info["multipart"] is True
    oiio = pytest.importorskip("OpenImageIO")
    inp = oiio.ImageInput.open(str(path))
    want = []
    while inp.seek_subimage(len(want), 0):
        want.append((inp.spec().getattribute("name"), inp.spec().nchannels))
    inp.close()
    assert len(want) == 10
    assert [(p["name"], p["channels"]) for p in info["parts"]] == want


def test_passes_union_with_mask(run, tmp_path):
    recipe = write_recipe(tmp_path / "r.json", [
        {"effect": "pixelate", "mask": {"object_index": 1}},
        {"effect": "gaussian_blur", "params": {"sigma": 2.0}},
    ])
    for args in (("--stack", recipe), (recipe,)):
        r = run("passes", *args)
        assert r.returncode == EXIT_OK, r.stderr
        need = json.loads(r.stdout)
        assert "Combined" in need["passes"] and "IndexOB" in need["passes"]
        assert need["camera"] is False


# ---- run --------------------------------------------------------------------------------

def changing_params(run, effect):
    """Parameters that make each effect visibly change a frame (names checked against
    `describe`, so a renamed parameter fails here with a clear message)."""
    wanted = {
        "gaussian_blur": {"sigma": 3.0},
        "pixelate": {"mode": "cells", "cell_size": 8},
        "color_matrix": {"operator": "sepia"},
    }[effect]
    names = param_names(describe(run, effect))
    for k in wanted:
        assert k in names, f"{effect} has no parameter {k!r}: {names}"
    return wanted


@pytest.mark.parametrize("effect", EFFECTS)
def test_run_each_effect_changes_pixels(run, tmp_path, effect):
    src = make_frame(tmp_path / "in.exr")
    recipe = write_recipe(tmp_path / "r.json",
                          [{"effect": effect, "params": changing_params(run, effect)}])
    out = tmp_path / "out.exr"
    r = run("run", "--stack", recipe, src, "-o", out)
    assert r.returncode == EXIT_OK, r.stderr
    assert r.stderr == ""
    a, b = combined(read_exr(src)), combined(read_exr(out))
    assert a.shape == b.shape
    assert np.isfinite(b).all()
    assert np.abs(a[..., :3] - b[..., :3]).max() > 1e-3


def test_identity_recipe_is_bit_identical(run, tmp_path):
    src = make_frame(tmp_path / "in.exr")
    recipe = write_recipe(tmp_path / "r.json",
                          [{"effect": "gaussian_blur", "params": {"sigma": 0.0}}])
    out = tmp_path / "out.exr"
    r = run("run", "--stack", recipe, src, "-o", out)
    assert r.returncode == EXIT_OK, r.stderr
    a, b = combined(read_exr(src)), combined(read_exr(out))
    assert a.tobytes() == b.tobytes()


@pytest.mark.parametrize("codec", ["zip", "zip:6", "zips", "piz", "rle", "none"])
def test_compression_choices_are_lossless(run, tmp_path, codec):
    src = make_frame(tmp_path / "in.exr")
    recipe = write_recipe(tmp_path / "r.json", [])
    out = tmp_path / "out.exr"
    r = run("run", "--stack", recipe, "--compression", codec, src, "-o", out)
    assert r.returncode == EXIT_OK, r.stderr
    assert combined(read_exr(src)).tobytes() == combined(read_exr(out)).tobytes()


def test_unknown_compression_names_the_choices(run, tmp_path):
    src = make_frame(tmp_path / "in.exr")
    recipe = write_recipe(tmp_path / "r.json", [])
    out = tmp_path / "out.exr"
    r = run("run", "--stack", recipe, "--compression", "dwaa", src, "-o", out)
    assert r.returncode != EXIT_OK
    assert "compression 'dwaa'" in r.stderr and "piz" in r.stderr
    assert not out.exists()


def test_output_has_only_combined_unless_keep_passes(run, tmp_path):
    src = make_frame(tmp_path / "in.exr")
    recipe = write_recipe(tmp_path / "r.json", [{"effect": "pixelate"}])
    r = run("run", "--stack", recipe, src, "-o", tmp_path / "plain.exr")
    assert r.returncode == EXIT_OK, r.stderr
    assert not any("Depth" in n for n in read_exr(tmp_path / "plain.exr"))
    r = run("run", "--stack", recipe, "--keep-passes", src, "-o", tmp_path / "kept.exr")
    assert r.returncode == EXIT_OK, r.stderr
    kept = read_exr(tmp_path / "kept.exr")
    assert any("Depth" in n for n in kept) and any("IndexOB" in n for n in kept)
    depth_in = [v for n, v in read_exr(src).items() if "Depth" in n][0]
    depth_out = [v for n, v in kept.items() if "Depth" in n][0]
    assert depth_in.tobytes() == depth_out.tobytes()


def test_mask_limits_the_effect(run, tmp_path):
    src = make_frame(tmp_path / "in.exr")
    recipe = write_recipe(tmp_path / "r.json", [
        {"effect": "pixelate", "params": {"mode": "cells", "cell_size": 4}, "mask": {"object_index": 2}}])
    out = tmp_path / "out.exr"
    r = run("run", "--stack", recipe, src, "-o", out)
    assert r.returncode == EXIT_OK, r.stderr
    a, b = combined(read_exr(src)), combined(read_exr(out))
    idx = [v for n, v in read_exr(src).items() if n.endswith("IndexOB.X")][0]
    outside = idx != 2
    assert np.array_equal(a[outside], b[outside])
    assert not np.array_equal(a[~outside], b[~outside])


def test_thread_count_does_not_change_a_bit(run, tmp_path):
    src = make_frame(tmp_path / "in.exr", width=97, height=61)
    recipe = write_recipe(tmp_path / "r.json", [
        {"effect": "gaussian_blur", "params": {"sigma": 2.5}},
        {"effect": "pixelate", "params": {"mode": "cells", "cell_size": 5}, "mask": {"object_index": 1}},
        {"effect": "color_matrix", "params": {"operator": "sepia", "mix": 0.5}},
    ])
    outs, files = [], []
    for n, args in ((1, ["--threads", "1"]), (2, ["-j2"]), (3, ["--threads=3"])):
        out = tmp_path / f"out{n}.exr"
        r = run("run", "--stack", recipe, *args, src, "-o", out)
        assert r.returncode == EXIT_OK, r.stderr
        outs.append(combined(read_exr(out)).tobytes())
        files.append(out.read_bytes())
    assert outs[0] == outs[1] == outs[2]  # the pixels, as OpenImageIO decodes them
    assert files[0] == files[1] == files[2]  # and the files themselves


def test_png_preview(run, tmp_path):
    from conftest import oiio
    src = make_frame(tmp_path / "in.exr", width=40, height=24)
    recipe = write_recipe(tmp_path / "r.json", [{"effect": "pixelate"}])
    png = tmp_path / "preview.png"
    r = run("run", "--stack", recipe, src, "-o", tmp_path / "out.exr", "--png", png)
    assert r.returncode == EXIT_OK, r.stderr
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    inp = oiio.ImageInput.open(str(png))
    spec = inp.spec()
    inp.close()
    assert (spec.width, spec.height) == (40, 24)


def test_half_output(run, tmp_path):
    from conftest import oiio
    src = make_frame(tmp_path / "in.exr")
    recipe = write_recipe(tmp_path / "r.json", [{"effect": "pixelate"}])
    out = tmp_path / "out.exr"
    r = run("run", "--stack", recipe, "--half", src, "-o", out)
    assert r.returncode == EXIT_OK, r.stderr
    inp = oiio.ImageInput.open(str(out))
    fmt = inp.spec().format
    inp.close()
    assert fmt == oiio.HALF


def test_quality_option_and_verbose_timings(run, tmp_path):
    src = make_frame(tmp_path / "in.exr")
    recipe = write_recipe(tmp_path / "r.json", [{"effect": "gaussian_blur"}])
    r = run("run", "--stack", recipe, "--quality", "draft", "--verbose", src,
            "-o", tmp_path / "out.exr")
    assert r.returncode == EXIT_OK, r.stderr
    line = [ln for ln in r.stdout.splitlines() if ln.startswith("timings: ")][0]
    timings = json.loads(line[len("timings: "):])
    assert timings[0]["effect"] == "gaussian_blur" and timings[0]["ms"] >= 0


def test_other_layer_names_and_layer_option(run, tmp_path):
    rgba = np.random.RandomState(3).rand(16, 20, 4).astype(np.float32)
    src = write_exr(tmp_path / "in.exr", {"Combined": (rgba, "RGBA")}, layer="My.Layer 1")
    recipe = write_recipe(tmp_path / "r.json", [{"effect": "pixelate", "params": {"mode": "cells", "cell_size": 4}}])
    r = run("run", "--stack", recipe, "--layer", "My.Layer 1", src, "-o", tmp_path / "o.exr")
    assert r.returncode == EXIT_OK, r.stderr
    # the layer (dots and a space in its name) was read: the same result as the same pixels
    # under Blender's usual layer name, and pixelated (not the input passed through)
    plain = write_exr(tmp_path / "plain.exr", {"Combined": (rgba, "RGBA")})
    r = run("run", "--stack", recipe, plain, "-o", tmp_path / "p.exr")
    assert r.returncode == EXIT_OK, r.stderr
    got, want = combined(read_exr(tmp_path / "o.exr")), combined(read_exr(tmp_path / "p.exr"))
    np.testing.assert_array_equal(got, want)
    assert np.abs(got - rgba).max() > 0.05
    # a layer the file does not have is refused by name
    r = run("run", "--stack", recipe, "--layer", "Nope", src, "-o", tmp_path / "n.exr")
    assert r.returncode != EXIT_OK and "Nope" in r.stderr


def test_nan_inf_corpus_file_gives_finite_output_and_a_warning(run, corpus, tmp_path):
    src = corpus / "openexr-images" / "TestImages" / "BrightRingsNanInf.exr"
    recipe = write_recipe(tmp_path / "r.json",
                          [{"effect": "gaussian_blur", "params": {"sigma": 2.0}}])
    out = tmp_path / "out.exr"
    r = run("run", "--stack", recipe, src, "-o", out)
    assert r.returncode == EXIT_OK, r.stderr
    warnings = [ln for ln in r.stderr.splitlines() if ln.startswith("libfx: warning: ")]
    assert warnings, r.stderr
    assert np.isfinite(combined(read_exr(out))).all()


@pytest.mark.parametrize("name", ["TestImages/WideFloatRange.exr", "TestImages/AllHalfValues.exr",
                                  "DisplayWindow/t08.exr"])
def test_corpus_files_run(run, corpus, tmp_path, name):
    src = corpus / "openexr-images" / name
    if not src.exists():
        pytest.skip(f"{src} is not in this corpus")
    recipe = write_recipe(tmp_path / "r.json", [{"effect": "pixelate"}])
    out = tmp_path / "out.exr"
    r = run("run", "--stack", recipe, src, "-o", out)
    assert r.returncode == EXIT_OK, r.stderr
    assert np.isfinite(combined(read_exr(out))).all()


def test_processed_file_can_be_processed_again(run, tmp_path):
    src = make_frame(tmp_path / "in.exr")
    recipe = write_recipe(tmp_path / "r.json", [{"effect": "pixelate", "params": {"mode": "cells", "cell_size": 4}}])
    assert run("run", "--stack", recipe, src, "-o", tmp_path / "a.exr").returncode == EXIT_OK
    r = run("run", "--stack", recipe, tmp_path / "a.exr", "-o", tmp_path / "b.exr")
    assert r.returncode == EXIT_OK, r.stderr
    # the second run read the first's output: pixelate of a pixelated frame is that frame
    # (each cell is already its own mean), and the first run did change the input
    a, b = combined(read_exr(tmp_path / "a.exr")), combined(read_exr(tmp_path / "b.exr"))
    assert np.abs(a - combined(read_exr(src))).max() > 0.05
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-6)
    assert sorted(read_exr(tmp_path / "b.exr")) == sorted(read_exr(tmp_path / "a.exr"))


def test_camera_sidecar_is_written_to_the_output(run, tmp_path):
    src = make_frame(tmp_path / "in.exr")
    cam = tmp_path / "cam.json"
    cam.write_text(json.dumps({
        "world_to_camera": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -5], [0, 0, 0, 1]],
        "projection": [[1.5, 0, 0, 0], [0, 2.0, 0, 0], [0, 0, -1.002, -0.2002], [0, 0, -1, 0]],
        "clip_start": 0.1, "clip_end": 100.0}))
    recipe = write_recipe(tmp_path / "r.json", [{"effect": "pixelate"}])
    assert json.loads(run("info", "--compact", src).stdout)["camera"] is False
    out = tmp_path / "out.exr"
    r = run("run", "--stack", recipe, "--camera", cam, "--frame", "12", src, "-o", out)
    assert r.returncode == EXIT_OK, r.stderr
    assert json.loads(run("info", "--compact", out).stdout)["camera"] is True


def test_debug_outputs_option(run, tmp_path):
    """--debug-outputs adds the stack's debug passes (edges: fx0_edges_strengths, RGBA, and
    fx0_edges_matte, one channel), named by effect position and name; without it they are
    absent, and the passes both files hold carry the same pixels."""
    src = make_frame(tmp_path / "in.exr")
    recipe = write_recipe(tmp_path / "r.json", [{"effect": "edges"}])
    plain, debug = tmp_path / "plain.exr", tmp_path / "debug.exr"
    r = run("run", "--stack", recipe, src, "-o", plain)
    assert r.returncode == EXIT_OK, r.stderr
    r = run("run", "--stack", recipe, "--debug-outputs", src, "-o", debug)
    assert r.returncode == EXIT_OK, r.stderr
    p, d = read_exr(plain), read_exr(debug)
    debug_only = sorted(n for n in d if n not in p)
    assert [n for n in debug_only if "fx0_edges_strengths." in n] and \
        [n for n in debug_only if "fx0_edges_matte." in n], debug_only
    assert len([n for n in debug_only if "fx0_edges_strengths." in n]) == 4, debug_only
    assert len([n for n in debug_only if "fx0_edges_matte." in n]) == 1, debug_only
    assert not [n for n in p if "fx0_" in n], sorted(p)
    for name in p:
        np.testing.assert_array_equal(p[name], d[name], err_msg=name)
    matte = d[[n for n in debug_only if "fx0_edges_matte." in n][0]]
    assert np.all(np.isfinite(matte)) and matte.max() > 0.0 and matte.min() >= 0.0


def test_non_ascii_paths(run, tmp_path):
    """UTF-8 file names in the arguments: folder and files outside ASCII (an emoji is a
    UTF-16 surrogate pair on Windows), written under exactly those names; an output that
    exists is replaced with --force, and the input is never overwritten."""
    folder = tmp_path / "déjà-αβ-日本"
    folder.mkdir()
    src = make_frame(folder / "plän-€.exr")
    recipe = write_recipe(folder / "réglage.json", [{"effect": "pixelate"}])
    out, png = folder / "sortie-🎬.exr", folder / "aperçu.png"
    r = run("run", "--stack", recipe, src, "-o", out, "--png", png)
    assert r.returncode == EXIT_OK, r.stderr
    assert sorted(p.name for p in folder.iterdir()) == sorted(
        ["plän-€.exr", "réglage.json", "sortie-🎬.exr", "aperçu.png"])  # no temporary file left
    first = combined(read_exr(out))
    assert np.abs(first - combined(read_exr(src))).max() > 1e-3
    blur = write_recipe(folder / "flou.json", [{"effect": "gaussian_blur", "params": {"sigma": 2.0}}])
    old = combined(read_exr(src))
    r = run("run", "--force", "--stack", blur, out, "-o", src)   # replaces an existing file
    assert r.returncode == EXIT_OK, r.stderr
    assert np.abs(combined(read_exr(src)) - old).max() > 1e-3
    before = out.read_bytes()
    r = run("run", "--force", "--stack", recipe, out, "-o", out)
    assert r.returncode != EXIT_OK and "input" in r.stderr
    assert out.read_bytes() == before
    r = run("info", folder / "ø.exr")
    assert r.returncode != EXIT_OK and "ø.exr" in r.stderr
