"""Frame sequences (shot.####.exr, %04d), --frames, batch failure semantics, Ctrl-C."""
import re
import signal
import subprocess
import time

import numpy as np
import pytest

from conftest import (EXIT_INPUT, EXIT_INTERRUPTED, EXIT_OK, EXIT_OUTPUT, EXIT_USAGE, combined,
                      make_frame, read_exr, write_recipe)


@pytest.fixture
def shots(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    for f in (1, 2, 3):
        make_frame(src / f"shot.{f:04d}.exr", seed=f)
    make_frame(src / "other.0002.exr")   # does not match the pattern's head
    (src / "shot.12.exr").write_bytes(b"")  # too few digits for ####: not a frame
    return src


@pytest.fixture
def recipe(tmp_path):
    return write_recipe(tmp_path / "r.json", [{"effect": "pixelate", "params": {"mode": "cells", "cell_size": 4}}])


def test_sequence_expands_and_names_outputs(run, tmp_path, shots, recipe):
    out = tmp_path / "out"
    out.mkdir()
    r = run("run", "--stack", recipe, shots / "shot.####.exr", "-o", out / "fx.####.exr")
    assert r.returncode == EXIT_OK, r.stderr
    assert sorted(p.name for p in out.iterdir()) == ["fx.0001.exr", "fx.0002.exr", "fx.0003.exr"]
    lines = r.stdout.splitlines()
    assert len(lines) == 3
    for f, line in zip((1, 2, 3), lines):
        m = re.fullmatch(r"frame (\d+): (\d+\.\d+) s, (.+)", line)
        assert m, line
        assert int(m.group(1)) == f and m.group(3) == str(out / f"fx.{f:04d}.exr")
    # each output is its own input processed (seeds differ)
    a = combined(read_exr(out / "fx.0001.exr"))
    b = combined(read_exr(out / "fx.0002.exr"))
    assert not np.array_equal(a, b)


def test_printf_pattern_and_frame_range(run, tmp_path, shots, recipe):
    r = run("run", "--stack", recipe, "--frames", "2-3", shots / "shot.%04d.exr",
            "-o", tmp_path / "o_%d.exr", "--png", tmp_path / "p.####.png")
    assert r.returncode == EXIT_OK, r.stderr
    names = sorted(p.name for p in tmp_path.iterdir() if p.is_file())
    assert names == ["o_2.exr", "o_3.exr", "p.0002.png", "p.0003.png", "r.json"]
    r = run("run", "--stack", recipe, "--frames", "3", shots / "shot.####.exr",
            "-o", tmp_path / "single.####.exr")
    assert r.returncode == EXIT_OK, r.stderr
    assert (tmp_path / "single.0003.exr").exists() and not (tmp_path / "single.0002.exr").exists()


def test_no_matching_frames(run, tmp_path, shots, recipe):
    r = run("run", "--stack", recipe, shots / "nothing.####.exr", "-o", tmp_path / "o.####.exr")
    assert r.returncode == EXIT_INPUT
    assert "nothing.####.exr" in r.stderr
    r = run("run", "--stack", recipe, "--frames", "50-60", shots / "shot.####.exr",
            "-o", tmp_path / "o.####.exr")
    assert r.returncode == EXIT_INPUT
    assert "50-60" in r.stderr


def test_pattern_mismatch_is_a_usage_error(run, tmp_path, shots, recipe):
    r = run("run", "--stack", recipe, shots / "shot.####.exr", "-o", tmp_path / "o.exr")
    assert r.returncode == EXIT_USAGE and "o.exr" in r.stderr
    r = run("run", "--stack", recipe, shots / "shot.0001.exr", "-o", tmp_path / "o.####.exr")
    assert r.returncode == EXIT_USAGE
    r = run("run", "--stack", recipe, shots / "shot.##.##.exr", "-o", tmp_path / "o.####.exr")
    assert r.returncode == EXIT_USAGE and "more than one" in r.stderr


def test_existing_outputs_are_checked_before_any_work(run, tmp_path, shots, recipe):
    out = tmp_path / "out"
    out.mkdir()
    (out / "fx.0003.exr").write_bytes(b"keep")
    r = run("run", "--stack", recipe, shots / "shot.####.exr", "-o", out / "fx.####.exr")
    assert r.returncode == EXIT_OUTPUT
    assert "fx.0003.exr" in r.stderr and "--force" in r.stderr
    assert sorted(p.name for p in out.iterdir()) == ["fx.0003.exr"]  # nothing processed


def test_sequence_output_onto_its_inputs_is_refused(run, shots, recipe):
    before = (shots / "shot.0002.exr").read_bytes()
    r = run("run", "--stack", recipe, "--force", shots / "shot.####.exr",
            "-o", shots / "shot.####.exr")
    assert r.returncode == EXIT_OUTPUT
    assert (shots / "shot.0002.exr").read_bytes() == before


def test_first_failure_stops_the_batch(run, tmp_path, shots, recipe):
    (shots / "shot.0002.exr").write_bytes(b"broken")
    out = tmp_path / "out"
    out.mkdir()
    r = run("run", "--stack", recipe, shots / "shot.####.exr", "-o", out / "fx.####.exr")
    assert r.returncode == EXIT_INPUT
    assert "shot.0002.exr" in r.stderr
    assert sorted(p.name for p in out.iterdir()) == ["fx.0001.exr"]


def test_keep_going(run, tmp_path, shots, recipe):
    (shots / "shot.0002.exr").write_bytes(b"broken")
    out = tmp_path / "out"
    out.mkdir()
    r = run("run", "--stack", recipe, "--keep-going", shots / "shot.####.exr",
            "-o", out / "fx.####.exr")
    assert r.returncode == EXIT_INPUT
    assert sorted(p.name for p in out.iterdir()) == ["fx.0001.exr", "fx.0003.exr"]
    assert "1 of 3 frames failed" in r.stderr


def test_frame_time_comes_from_the_file_name(run, tmp_path, recipe):
    """Frames >= 10000 have more digits than the pattern: still matched, in order."""
    src = tmp_path / "src"
    src.mkdir()
    for f in (9999, 10000):
        make_frame(src / f"s.{f:04d}.exr", width=8, height=8)
    r = run("run", "--stack", recipe, "--fps", "25", src / "s.####.exr", "-o", tmp_path / "o.####.exr")
    assert r.returncode == EXIT_OK, r.stderr
    assert [ln.split(":")[0] for ln in r.stdout.splitlines()] == ["frame 9999", "frame 10000"]


def test_quiet_prints_nothing(run, tmp_path, shots, recipe):
    r = run("run", "--quiet", "--stack", recipe, shots / "shot.####.exr", "-o", tmp_path / "o.####.exr")
    assert r.returncode == EXIT_OK, r.stderr
    assert r.stdout == "" and r.stderr == ""


def test_ctrl_c_cancels_cleanly(cli, tmp_path):
    """SIGINT after the first frame: exit 130, the finished frame kept, no partial file."""
    src = tmp_path / "src"
    src.mkdir()
    for f in range(1, 31):
        make_frame(src / f"big.{f:04d}.exr", width=640, height=480, seed=f)
    rec = write_recipe(tmp_path / "r.json", [{"effect": "gaussian_blur", "params": {"sigma": 30}},
                                             {"effect": "gaussian_blur", "params": {"sigma": 40}}])
    out = tmp_path / "out"
    out.mkdir()
    p = subprocess.Popen([cli, "run", "--threads", "1", "--stack", str(rec),
                          str(src / "big.####.exr"), "-o", str(out / "o.####.exr")],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    first = p.stdout.readline()
    assert first.startswith("frame 1:"), (first, p.stderr.read() if p.poll() is not None else "")
    time.sleep(0.05)
    p.send_signal(signal.SIGINT)
    stdout, stderr = p.communicate(timeout=60)
    if p.returncode == EXIT_OK:
        pytest.skip("the whole sequence finished before the signal arrived")
    assert p.returncode == EXIT_INTERRUPTED, stderr
    assert "interrupted" in stderr
    written = sorted(x.name for x in out.iterdir())
    done = 1 + len(stdout.splitlines())
    assert written == [f"o.{f:04d}.exr" for f in range(1, done + 1)]  # no partial or temp file
    for name in written:
        assert np.isfinite(combined(read_exr(out / name))).all()
