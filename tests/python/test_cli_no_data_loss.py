"""The CLI never loses data (issue 8, hardening): for each error class the input file is
byte-identical afterwards (same bytes, same mtime), and the folders the run touched hold
exactly what they held before: no output, no partial output, no temporary file.

Error classes: bad recipe, bad sidecar, missing pass, damaged input, unwritable output,
output == input (by name, by another spelling, by a hard link, with --force), cancellation
by SIGINT mid-run, out of memory (the CLI has no memory option: RLIMIT_AS in the child,
as `ulimit -v` would)."""
import hashlib
import os
import pathlib
import resource
import signal
import subprocess
import time

import pytest

from conftest import (EXIT_INPUT, EXIT_INTERRUPTED, EXIT_OUTPUT, EXIT_PROCESS, make_frame,
                      sample_pixels, write_exr, write_recipe)


def snapshot(*folders):
    """{path: (sha256, size, mtime_ns)} of every file under the folders."""
    out = {}
    for folder in folders:
        for p in sorted(pathlib.Path(folder).rglob("*")):
            if p.is_file():
                st = p.stat()
                out[str(p)] = (hashlib.sha256(p.read_bytes()).hexdigest(), st.st_size, st.st_mtime_ns)
    return out


@pytest.fixture
def work(tmp_path):
    src = make_frame(tmp_path / "in.exr")
    rec = write_recipe(tmp_path / "recipe.json", [{"effect": "gaussian_blur", "params": {"sigma": 2}}])
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    return tmp_path, src, rec, out_dir


def assert_nothing_lost(before, tmp_path, r, code):
    assert r.returncode == code, (r.returncode, r.stderr)
    assert r.stderr.strip().splitlines()[-1].startswith("libfx: error: ") or code == EXIT_INTERRUPTED, r.stderr
    after = snapshot(tmp_path)
    assert after == before, {k: (before.get(k), after.get(k)) for k in set(before) | set(after)
                             if before.get(k) != after.get(k)}


def test_bad_recipe(run, work):
    tmp, src, _, out = work
    bad = tmp / "bad.json"
    bad.write_text('{"version": 1, "effects": [{"effect": "gaussian_blur", "params": {"sigma": 1e999}}]}')
    before = snapshot(tmp)
    r = run("run", "--stack", bad, src, "-o", out / "o.exr", "--png", out / "o.png")
    assert_nothing_lost(before, tmp, r, EXIT_INPUT)
    bad.write_text('{"version": 1, "effects": [')
    before = snapshot(tmp)
    r = run("run", "--stack", bad, src, "-o", out / "o.exr")
    assert_nothing_lost(before, tmp, r, EXIT_INPUT)


def test_bad_sidecar(run, work):
    tmp, src, rec, out = work
    side = tmp / "scene.json"
    for text in ('{"world_to_camera": [[1, 0, 0, 0]], "projection": 3}',
                 '{"world_to_camera": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1e999]],'
                 ' "projection": [[1,0,0,0],[0,1,0,0],[0,0,-1,-0.2],[0,0,-1,0]],'
                 ' "clip_start": 0.1, "clip_end": 100}',
                 "not json"):
        side.write_text(text)
        before = snapshot(tmp)
        r = run("run", "--stack", rec, "--camera", side, src, "-o", out / "o.exr")
        assert_nothing_lost(before, tmp, r, EXIT_INPUT)


def test_missing_pass(run, work):
    tmp, _, _, out = work
    src = make_frame(tmp / "plain.exr", index_ob=False, depth=False)
    for effects in ([{"effect": "pixelate", "mask": {"object_index": 1}}],
                    [{"effect": "gaussian_blur"}, {"effect": "edges", "params": {"depth": True}}]):
        rec = write_recipe(tmp / "needs.json", effects)
        before = snapshot(tmp)
        r = run("run", "--stack", rec, src, "-o", out / "o.exr", "--png", out / "o.png")
        assert_nothing_lost(before, tmp, r, EXIT_INPUT)


def test_damaged_input(run, work):
    tmp, src, rec, out = work
    data = src.read_bytes()
    cases = {"truncated.exr": data[: len(data) // 2], "header_only.exr": data[:300],
             "flipped.exr": data[:400] + bytes(b ^ 0x5A for b in data[400:800]) + data[800:]}
    for name, payload in cases.items():
        bad = tmp / name
        bad.write_bytes(payload)
        before = snapshot(tmp)
        r = run("run", "--stack", rec, bad, "-o", out / "o.exr", "--png", out / "o.png")
        assert r.returncode in (EXIT_INPUT, EXIT_PROCESS), r.stderr
        assert_nothing_lost(before, tmp, r, r.returncode)
        bad.unlink()


def test_unwritable_output(run, work):
    tmp, src, rec, out = work
    blocker = tmp / "a_file"
    blocker.write_text("x")
    for target in (blocker / "o.exr", out, tmp / "missing" / "o.exr"):
        before = snapshot(tmp)
        r = run("run", "--stack", rec, "--force", src, "-o", target)
        assert_nothing_lost(before, tmp, r, EXIT_OUTPUT)
    # the EXR could be written but the PNG cannot: neither is left
    before = snapshot(tmp)
    r = run("run", "--stack", rec, src, "-o", out / "o.exr", "--png", blocker / "o.png")
    assert_nothing_lost(before, tmp, r, EXIT_OUTPUT)


def test_output_is_input(run, work):
    tmp, src, rec, _ = work
    os.link(src, tmp / "hard.exr")
    (tmp / "sym.exr").symlink_to(src)
    sub = tmp / "sub"
    sub.mkdir()
    for target in (src, tmp / "sub" / ".." / "in.exr", tmp / "hard.exr", tmp / "sym.exr"):
        for force in ([], ["--force"]):
            before = snapshot(tmp)
            r = run("run", "--stack", rec, *force, src, "-o", target)
            assert_nothing_lost(before, tmp, r, EXIT_OUTPUT)


def test_sigint_mid_run(cli, work):
    tmp, _, _, out = work
    src = write_exr(tmp / "big.exr", {"Combined": (sample_pixels(1024, 512), "RGBA")})
    rec = write_recipe(tmp / "slow.json", [{"effect": "gaussian_blur", "quality": "reference",
                                            "params": {"sigma": 400}}] * 16)
    before = snapshot(tmp)
    p = subprocess.Popen([cli, "run", "--stack", str(rec), str(src), "-o", str(out / "o.exr"),
                          "--png", str(out / "o.png"), "-j", "2"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(1.0)
    assert p.poll() is None, "the run finished before the signal; make it slower"
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    assert p.returncode == EXIT_INTERRUPTED, err
    assert snapshot(tmp) == before
    assert not list(out.iterdir())


def test_out_of_memory(cli, work):
    tmp, _, _, out = work
    src = write_exr(tmp / "big.exr", {"Combined": (sample_pixels(2560, 2560), "RGBA")})
    rec = write_recipe(tmp / "mem.json", [{"effect": "gaussian_blur", "params": {"sigma": 20}},
                                          {"effect": "bloom", "mask": {"rect": [0, 0, 2560, 2560]}}])
    before = snapshot(tmp)
    # reads the 100 MiB frame (the blur then works over it in place), then runs out in bloom
    # (masked: not in place, so it needs a second frame-sized buffer)
    limit = 200 << 20

    def cap():
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    r = subprocess.run([cli, "run", "--stack", str(rec), str(src), "-o", str(out / "o.exr"), "-j", "1"],
                       capture_output=True, text=True, timeout=120, preexec_fn=cap)
    if r.returncode == 0:
        pytest.fail("the run fitted in 200 MiB of address space; raise the frame size")
    assert r.returncode in (EXIT_PROCESS, EXIT_INPUT), r.stderr
    assert "memory" in r.stderr
    assert_nothing_lost(before, tmp, r, r.returncode)
