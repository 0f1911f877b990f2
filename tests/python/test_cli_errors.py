"""Every error class of the CLI: its exit code, one clear line on stderr that names the
file, parameter or pass, and no output (partial or temporary) left behind."""
import json
import os
import pathlib
import shutil
import subprocess
import tempfile

import pytest

from conftest import (EXIT_INPUT, EXIT_OK, EXIT_OUTPUT, EXIT_USAGE, combined, make_frame, read_exr,
                      write_exr, write_recipe)

import numpy as np


def one_error_line(r):
    lines = r.stderr.strip().splitlines()
    errors = [ln for ln in lines if ln.startswith("libfx: error: ")]
    assert len(errors) == 1, r.stderr
    return errors[0]


@pytest.fixture
def recipe(tmp_path):
    return write_recipe(tmp_path / "recipe.json", [{"effect": "pixelate"}])


def listing(folder):
    return sorted(p.name for p in folder.iterdir())


# ---- usage errors (2) ------------------------------------------------------------------

@pytest.mark.parametrize("args, words", [
    (["run", "--bogus"], ["--bogus"]),
    (["run", "--stack"], ["--stack", "value"]),
    (["run", "--threads", "two"], ["--threads", "two"]),
    (["run", "--threads", "-3"], ["--threads", "-3"]),
    (["run", "--quality", "ultra"], ["--quality", "ultra"]),
    (["run", "--fps", "nan"], ["--fps"]),
    (["run", "--frames", "9-3"], ["--frames"]),
    (["list", "extra"], ["extra"]),
    (["describe"], ["effect"]),
    (["info"], ["file"]),
    (["passes"], ["--stack"]),
    (["--bogus"], ["--bogus"]),
])
def test_usage_errors(run, args, words):
    r = run(*args)
    assert r.returncode == EXIT_USAGE, r.stderr
    line = one_error_line(r)
    for w in words:
        assert w in line


def test_run_needs_stack_input_and_output(run, tmp_path, recipe, frame):
    assert "--stack" in one_error_line(run("run", frame, "-o", tmp_path / "o.exr"))
    assert "input" in one_error_line(run("run", "--stack", recipe, "-o", tmp_path / "o.exr"))
    r = run("run", "--stack", recipe, frame)
    assert r.returncode == EXIT_USAGE and "-o" in one_error_line(r)


def test_flag_with_value_is_a_usage_error(run, tmp_path, recipe, frame):
    r = run("run", "--stack", recipe, "--force=yes", frame, "-o", tmp_path / "o.exr")
    assert r.returncode == EXIT_USAGE and "--force" in one_error_line(r)


def test_options_after_positionals_and_equals_form(run, tmp_path, frame):
    recipe = write_recipe(tmp_path / "cells.json", [{"effect": "pixelate", "params": {"mode": "cells", "cell_size": 4}}])
    r = run("run", frame, f"--stack={recipe}", "--threads=1", "-o", tmp_path / "o.exr")
    assert r.returncode == EXIT_OK, r.stderr
    # the options were taken: the same file as the usual order and form writes, and the
    # recipe ran (the output is not the input)
    r = run("run", "--stack", recipe, "--threads", "1", frame, "-o", tmp_path / "usual.exr")
    assert r.returncode == EXIT_OK, r.stderr
    got, want = read_exr(tmp_path / "o.exr"), read_exr(tmp_path / "usual.exr")
    assert sorted(got) == sorted(want)
    for name in want:
        np.testing.assert_array_equal(got[name], want[name], err_msg=name)
    assert np.abs(combined(got) - combined(read_exr(frame))).max() > 0.05


# ---- input errors (3) ------------------------------------------------------------------

def test_missing_input_file(run, tmp_path, recipe):
    missing = tmp_path / "nope.exr"
    r = run("run", "--stack", recipe, missing, "-o", tmp_path / "o.exr")
    assert r.returncode == EXIT_INPUT
    assert str(missing) in one_error_line(r)
    assert listing(tmp_path) == ["recipe.json"]
    # input errors come before output errors
    r = run("run", "--stack", recipe, missing, "-o", tmp_path / "no" / "dir" / "o.exr")
    assert r.returncode == EXIT_INPUT and str(missing) in one_error_line(r)


def test_empty_input_file(run, tmp_path, recipe):
    empty = tmp_path / "empty.exr"
    empty.write_bytes(b"")
    r = run("run", "--stack", recipe, empty, "-o", tmp_path / "o.exr")
    assert r.returncode == EXIT_INPUT
    assert str(empty) in one_error_line(r)
    assert not (tmp_path / "o.exr").exists()


def test_non_exr_input_file(run, tmp_path, recipe):
    text = tmp_path / "notes.exr"
    text.write_text("this is not an OpenEXR file\n" * 10)
    r = run("run", "--stack", recipe, text, "-o", tmp_path / "o.exr")
    assert r.returncode == EXIT_INPUT
    assert str(text) in one_error_line(r)
    assert not (tmp_path / "o.exr").exists()


def test_info_on_bad_files(run, tmp_path):
    text = tmp_path / "notes.exr"
    text.write_text("not an EXR")
    r = run("info", text)
    assert r.returncode == EXIT_INPUT and str(text) in one_error_line(r)
    r = run("info", tmp_path / "missing.exr")
    assert r.returncode == EXIT_INPUT and "missing.exr" in one_error_line(r)


DAMAGED = [
    "asan_heap-oob_4cb169_255_cc7ac9cde4b8634b31cb41c8fe89b92d_exr",
    "asan_stack-oob_433d4f_157_4c56ecca982bc10e976527cd314bbcfa_exr",
    "clusterfuzz-testcase-minimized-openexr_exrcheck_fuzzer-4598960264183808",
    "clusterfuzz-testcase-minimized-openexr_deepscanlines_fuzzer-5706205037854720",
]


@pytest.mark.parametrize("name", DAMAGED)
def test_damaged_corpus_files(run, corpus, tmp_path, recipe, name):
    src = corpus / "openexr-images" / "Damaged" / name
    assert src.exists(), f"{src} is missing from the corpus"
    before = src.read_bytes()
    out = tmp_path / "o.exr"
    r = run("run", "--stack", recipe, src, "-o", out)
    assert r.returncode == EXIT_INPUT, (r.returncode, r.stderr)
    assert name in one_error_line(r)
    assert listing(tmp_path) == ["recipe.json"]  # no output, no temporary file
    assert src.read_bytes() == before
    # `info` reads only the header: some damaged files have a sound one
    r = run("info", src)
    if r.returncode == EXIT_OK:
        json.loads(r.stdout)
    else:
        assert r.returncode == EXIT_INPUT, (r.returncode, r.stderr)
        assert name in one_error_line(r)


def test_every_damaged_corpus_file_is_rejected_cleanly(run, corpus, tmp_path, recipe):
    folder = corpus / "openexr-images" / "Damaged"
    names = sorted(p.name for p in folder.iterdir() if p.name != "README.rst")
    assert len(names) > 50
    out = tmp_path / "o.exr"
    wrong = []  # collected, to see every misclassified file at once
    for name in names:
        r = run("run", "--stack", recipe, folder / name, "-o", out)
        assert r.returncode > 0, (name, r.returncode, r.stderr)  # no crash (signal), no success
        assert name in one_error_line(r), name
        assert listing(tmp_path) == ["recipe.json"], name
        if r.returncode != EXIT_INPUT:
            wrong.append((name, r.returncode, r.stderr.strip()))
    assert not wrong, wrong


def test_missing_recipe(run, tmp_path, frame):
    r = run("run", "--stack", tmp_path / "none.json", frame, "-o", tmp_path / "o.exr")
    assert r.returncode == EXIT_INPUT
    assert "none.json" in one_error_line(r)


def test_bad_json_recipe(run, tmp_path, frame):
    bad = tmp_path / "bad.json"
    bad.write_text('{"version": 1, "effects": [ {"effect": "pixelate", }')
    r = run("run", "--stack", bad, frame, "-o", tmp_path / "o.exr")
    assert r.returncode == EXIT_INPUT
    line = one_error_line(r)
    assert "bad.json" in line and "JSON" in line
    assert run("passes", "--stack", bad).returncode == EXIT_INPUT


def test_unknown_effect(run, tmp_path, frame):
    rec = write_recipe(tmp_path / "r.json", [{"effect": "lens_flare_9000"}])
    r = run("run", "--stack", rec, frame, "-o", tmp_path / "o.exr")
    assert r.returncode == EXIT_INPUT
    assert "lens_flare_9000" in one_error_line(r)
    r = run("describe", "lens_flare_9000")
    assert r.returncode == EXIT_INPUT and "lens_flare_9000" in one_error_line(r)


def test_unknown_param(run, tmp_path, frame):
    rec = write_recipe(tmp_path / "r.json",
                       [{"effect": "gaussian_blur", "params": {"sigmaa": 2}}])
    r = run("run", "--stack", rec, frame, "-o", tmp_path / "o.exr")
    assert r.returncode == EXIT_INPUT
    line = one_error_line(r)
    assert "sigmaa" in line and "gaussian_blur" in line


def test_out_of_range_param_shows_the_range(run, tmp_path, frame):
    desc = json.loads(run("describe", "--compact", "gaussian_blur").stdout)
    params = desc["params"]
    sigma = [p for p in params if p["name"] == "sigma"][0] if isinstance(params, list) \
        else params["sigma"]
    rec = write_recipe(tmp_path / "r.json",
                       [{"effect": "gaussian_blur", "params": {"sigma": -5}}])
    r = run("run", "--stack", rec, frame, "-o", tmp_path / "o.exr")
    assert r.returncode == EXIT_INPUT
    line = one_error_line(r)
    assert "sigma" in line and "-5" in line
    assert f"{sigma['min']:g}" in line and f"{sigma['max']:g}" in line


def test_missing_pass_for_a_mask(run, tmp_path):
    src = make_frame(tmp_path / "in.exr", index_ob=False)
    rec = write_recipe(tmp_path / "r.json",
                       [{"effect": "pixelate", "mask": {"object_index": 1}}])
    r = run("run", "--stack", rec, src, "-o", tmp_path / "o.exr")
    assert r.returncode == EXIT_INPUT
    line = one_error_line(r)
    assert "IndexOB" in line and "pixelate" in line
    assert not (tmp_path / "o.exr").exists()


def test_file_without_combined(run, tmp_path, recipe):
    depth = np.ones((8, 8), np.float32)
    src = write_exr(tmp_path / "depth.exr", {"Depth": (depth, "Z")})
    r = run("run", "--stack", recipe, src, "-o", tmp_path / "o.exr")
    assert r.returncode == EXIT_INPUT
    assert "Combined" in one_error_line(r)


def test_bad_camera_file(run, tmp_path, recipe, frame):
    cam = tmp_path / "cam.json"
    cam.write_text('{"world_to_camera": [[1, 0, 0]], "projection": 3}')
    r = run("run", "--stack", recipe, "--camera", cam, frame, "-o", tmp_path / "o.exr")
    assert r.returncode == EXIT_INPUT
    assert "cam.json" in one_error_line(r)


def test_missing_layer(run, tmp_path, recipe, frame):
    r = run("run", "--stack", recipe, "--layer", "NoSuchLayer", frame, "-o", tmp_path / "o.exr")
    assert r.returncode == EXIT_INPUT
    assert "NoSuchLayer" in one_error_line(r)


# ---- output errors (4) -----------------------------------------------------------------

def test_output_is_input(run, tmp_path, recipe, frame):
    before = frame.read_bytes()
    for force in ([], ["--force"]):
        r = run("run", "--stack", recipe, *force, frame, "-o", frame)
        assert r.returncode == EXIT_OUTPUT
        assert "input" in one_error_line(r)
        assert frame.read_bytes() == before
    # the same file under another name (a hard link) is the input too
    link = tmp_path / "link.exr"
    os.link(frame, link)
    r = run("run", "--stack", recipe, "--force", frame, "-o", link)
    assert r.returncode == EXIT_OUTPUT
    assert frame.read_bytes() == before
    # the PNG preview may not overwrite the input either
    r = run("run", "--stack", recipe, "--force", frame, "-o", tmp_path / "o.exr", "--png", frame)
    assert r.returncode == EXIT_OUTPUT
    assert frame.read_bytes() == before
    assert listing(tmp_path) == ["in.exr", "link.exr", "recipe.json"]


def test_existing_output_needs_force(run, tmp_path, recipe, frame):
    out = tmp_path / "o.exr"
    out.write_bytes(b"precious")
    r = run("run", "--stack", recipe, frame, "-o", out)
    assert r.returncode == EXIT_OUTPUT
    line = one_error_line(r)
    assert "o.exr" in line and "--force" in line
    assert out.read_bytes() == b"precious"
    r = run("run", "--stack", recipe, "--force", frame, "-o", out)
    assert r.returncode == EXIT_OK, r.stderr
    assert out.read_bytes()[:4] == b"\x76\x2f\x31\x01"  # the EXR magic number


def test_output_directory_missing(run, tmp_path, recipe, frame):
    before = frame.read_bytes()
    out = tmp_path / "no" / "such" / "dir" / "o.exr"
    r = run("run", "--stack", recipe, frame, "-o", out)
    assert r.returncode == EXIT_OUTPUT
    assert str(out) in one_error_line(r)
    assert frame.read_bytes() == before
    assert listing(tmp_path) == ["in.exr", "recipe.json"]


def test_output_under_a_regular_file(run, tmp_path, recipe, frame):
    out = tmp_path / "recipe.json" / "o.exr"
    r = run("run", "--stack", recipe, frame, "-o", out)
    assert r.returncode == EXIT_OUTPUT
    assert "o.exr" in one_error_line(r)


def test_output_is_a_directory(run, tmp_path, recipe, frame):
    (tmp_path / "d.exr").mkdir()
    r = run("run", "--stack", recipe, "--force", frame, "-o", tmp_path / "d.exr")
    assert r.returncode == EXIT_OUTPUT
    assert "d.exr" in one_error_line(r)
    assert listing(tmp_path / "d.exr") == []


def test_unwritable_output_directory(cli, tmp_path):
    """A read-only output folder: exit 4, input unchanged, nothing left in the folder.
    As root, permission bits do not stop writes, so the CLI runs as `nobody` (setpriv)."""
    prefix = []
    work = tmp_path
    if os.geteuid() == 0:
        setpriv = shutil.which("setpriv")
        if not setpriv:
            pytest.skip("running as root without setpriv: permission bits would not stop writes")
        prefix = [setpriv, "--reuid=65534", "--regid=65534", "--clear-groups"]
        work = pathlib.Path(tempfile.mkdtemp(prefix="libfx-ro-"))
        work.chmod(0o777)
    try:
        src = make_frame(work / "in.exr")
        rec = write_recipe(work / "r.json", [{"effect": "pixelate"}])
        ro = work / "ro"
        ro.mkdir()
        ro.chmod(0o555)
        before = src.read_bytes()
        r = subprocess.run(prefix + [cli, "run", "--stack", str(rec), str(src), "-o",
                                     str(ro / "o.exr")], capture_output=True, text=True, timeout=60)
        if r.returncode != EXIT_OUTPUT and "Permission denied" in r.stderr and prefix:
            pytest.skip(f"`nobody` cannot run the CLI from here: {r.stderr.strip()}")
        assert r.returncode == EXIT_OUTPUT, r.stderr
        assert "o.exr" in one_error_line(r)
        assert listing(ro) == []  # no output, no temporary file
        assert src.read_bytes() == before
    finally:
        if work != tmp_path:
            shutil.rmtree(work, ignore_errors=True)


def test_failed_run_leaves_no_files(run, tmp_path):
    """A frame that fails after reading (missing mask pass) writes nothing at all."""
    src = make_frame(tmp_path / "in.exr", index_ob=False)
    rec = write_recipe(tmp_path / "r.json",
                       [{"effect": "pixelate", "mask": {"object_index": 1}}])
    r = run("run", "--stack", rec, src, "-o", tmp_path / "o.exr", "--png", tmp_path / "o.png")
    assert r.returncode == EXIT_INPUT
    assert listing(tmp_path) == ["in.exr", "r.json"]
