"""The batch runner's contract, which a render farm relies on (docs/farm.md):

- frames in, exactly one result per frame (ranges, lists), each carrying its frame;
- non-zero exit on failure, naming the frame and the effect, and no result (neither a
  partial nor an older one) for a failed frame; usage errors exit 2 before rendering;
- idempotent re-runs with --skip-existing: finished frames untouched, missing or
  damaged ones rendered again, identical to the first run;
- the chunk command of the Flamenco job type (farm/flamenco/libfx_render.js), built
  the way a Flamenco worker builds it, runs and renders exactly its chunk.

On the cheapest scene (the mirror room, an animated camera) at 64x36, 1 sample.
"""
import json
import os
import re
import shlex
import shutil
import subprocess

import numpy as np
import pytest

import addon_testlib as T

BLEND = T.SCENES_DIR / "mirror_room" / "mirror_room.blend"
JOB_TYPE_JS = T.REPO / "farm" / "flamenco" / "libfx_render.js"
RES, SAMPLES = "64x36", "1"
RESULT_RE = re.compile(r"^o_libfx\.(\d{4})\.exr$")

pytestmark = pytest.mark.skipif(not BLEND.is_file(), reason="blend_scenes/mirror_room not built")


def batch(library, out_dir, *extra, expr=None, frames="1-3", timeout=240):
    args = ["--frames", frames] if frames is not None else []
    return T.run_blender([], blend=BLEND, env=T.addon_env(library), python_expr=expr, python=T.BATCH,
                         script_args=args + ["--keep-passes", "--output", str(out_dir / "o_"), "--resolution", RES,
                                             "--samples", SAMPLES, *extra], timeout=timeout)


def results(out_dir):
    """{frame: path} of the libfx results in out_dir."""
    out = {}
    for p in out_dir.iterdir() if out_dir.is_dir() else []:
        m = RESULT_RE.match(p.name)
        if m:
            out[int(m.group(1))] = p
    return out


def leftovers(out_dir):
    """Temporary or partial files (the library's '.<name>.tmp-<pid>-<n>', '*.tmp')."""
    return sorted(p.name for p in out_dir.iterdir() if ".tmp" in p.name) if out_dir.is_dir() else []


def processed(stdout):
    """Frames whose stack ran in this process ('libfx: frame N: <timings> -> path')."""
    return sorted(int(m) for m in re.findall(r"^libfx: frame (\d+): .* -> ", stdout, re.M))


def blender_saves(stdout):
    """The images Blender's render wrote ("Saved: '...'"; 5.x prefixes a time and a
    category), leaving out libfx's passes files and its aux views (the planar views follow
    the camera, so a frame rendered again renders them again; 3.4 prints neither)."""
    return [p for p in re.findall(r"Saved: '([^']*)'", stdout) if "libfx_passes" not in p and "libfx_aux_" not in p]


def pixels(path):
    exr = T.Exr(path)
    return exr, {n: c for n, c in exr.channels.items()}


def same_result(a, b):
    """Two results of the same frame: every channel bit-identical, every header attribute
    equal but Blender's per-run stamps copied from the passes file: 'Date' (differs
    between runs more than a second apart), 'RenderTime' (4.3+ write the real time) and
    Cycles' render statistics ('cycles.<layer>.<phase>_time').
    Returns whether the bytes are identical too."""
    ea, ca = pixels(a)
    eb, cb = pixels(b)
    assert sorted(ca) == sorted(cb)
    for n in ca:
        assert np.array_equal(ca[n], cb[n]), "channel %s differs in %d values" % (n, (ca[n] != cb[n]).sum())
    def stamp(k):   # the Render Result's per-run stats: "cycles.ViewLayer.render_time"...
        return k in ("Date", "RenderTime") or (k.startswith("cycles.") and k.endswith("_time"))
    attrs_a = {k: v for k, v in ea.attrs.items() if not stamp(k)}
    attrs_b = {k: v for k, v in eb.attrs.items() if not stamp(k)}
    assert attrs_a == attrs_b
    return a.read_bytes() == b.read_bytes()


def out_text(proc):
    return (proc.stdout + "\n" + proc.stderr)[-4000:]


# ---------------------------------------------------------------- frames in, one result per frame

@pytest.mark.parametrize("frames, expected", [("1-3", [1, 2, 3]), ("1,3", [1, 3]), ("2-3", [2, 3])])
def test_one_result_per_frame(blender, library, tmp_path, frames, expected):
    T.need_oiio()
    out = tmp_path / "out"
    proc = batch(library, out, frames=frames)
    assert proc.returncode == 0, out_text(proc)
    assert sorted(results(out)) == expected, sorted(p.name for p in out.iterdir())
    passes = sorted(int(m) for m in (re.match(r"^o_libfx_passes\.(\d{4})\.exr$", p.name)
                                     for p in out.iterdir()) if m for m in [m.group(1)])
    assert passes == expected
    assert processed(proc.stdout) == expected, out_text(proc)
    assert leftovers(out) == []

    combined, w2c = {}, {}
    for f, path in results(out).items():
        exr = T.Exr(path)
        assert (exr.width, exr.height) == (64, 36)
        assert exr.attrs.get("libfx:frame") == f, exr.attrs.get("libfx:frame")
        assert exr.attrs.get("libfx:fps") == 24
        assert T.read_json(out / ("o_libfx.%04d.camera.json" % f))["frame"] == f
        combined[f] = exr.get("Combined", "RGBA")
        assert np.isfinite(combined[f]).all()
        w2c[f] = np.array(exr.attrs["worldToCamera"], dtype=np.float64)
    # The camera moves over the scene's range: each frame is its own.
    for a, b in zip(expected, expected[1:]):
        assert not np.allclose(w2c[a], w2c[b], atol=1e-6), (a, b)
        assert np.abs(combined[a] - combined[b]).max() > 1e-3, (a, b)


# ---------------------------------------------------------------- non-zero exit on failure

# The Sun is visible to the render on frame 1 only: god_rays naming it fails at run time
# (the library finds no such light in frame 2's scene sidecar), not at set-up.
SUN_ON_FRAME_1_ONLY = (
    "import bpy\n"
    "sun = bpy.data.objects['Sun']\n"
    "sun.hide_render = False\n"
    "sun.keyframe_insert('hide_render', frame=1)\n"
    "sun.hide_render = True\n"
    "sun.keyframe_insert('hide_render', frame=2)\n")


def test_runtime_failure_exits_1_and_leaves_no_result(blender, library, tmp_path):
    T.need_oiio()
    recipe = tmp_path / "god_rays_sun.json"
    recipe.write_text(json.dumps({"version": 1, "effects": [
        {"effect": "god_rays", "params": {"light": "Sun"}}]}))
    out = tmp_path / "out"
    out.mkdir()
    # What an older run left for frame 2: a result and a killed writer's temporary file.
    (out / "o_libfx.0002.exr").write_bytes(b"an older result of frame 2")
    (out / ".o_libfx.0002.exr.tmp-999999-0").write_bytes(b"half a file")
    proc = batch(library, out, "--recipe", recipe, frames="1-2", expr=SUN_ON_FRAME_1_ONLY)
    assert proc.returncode == 1, out_text(proc)
    err = proc.stderr[proc.stderr.index("libfx batch: error:"):]
    assert "1 of 2 frame(s) failed" in err, err
    assert re.search(r"frame 2: .*god_rays.*'Sun'", err), err
    assert "frame 1:" not in err, err
    assert not T.tracebacks(proc.stdout + proc.stderr)
    # Frame 1 is done; frame 2 has no result at all, no sidecar, no temporary file.
    assert sorted(results(out)) == [1]
    assert T.Exr(out / "o_libfx.0001.exr").attrs["libfx:frame"] == 1
    assert not (out / "o_libfx.0002.camera.json").exists()
    assert leftovers(out) == []


@pytest.mark.parametrize("args, names", [
    (["--frames", "5-2"], ["--frames 5-2", "backwards"]),
    (["--frames", "a-b"], ["--frames a-b", "'a-b'"]),
    (["--frames", "1,,x"], ["--frames 1,,x", "'x'"]),
    (["--frames", "1", "--resolution", "64by36"], ["--resolution", "64by36"]),
    (["--frames", "1", "--quality", "ultra"], ["--quality", "draft"]),
    (["--frames", "1", "--recipe", "/nonexistent/recipe.json"], ["recipe /nonexistent/recipe.json"]),
], ids=["backwards", "letters", "list-letter", "resolution", "quality", "recipe-missing"])
def test_usage_errors_exit_2_before_rendering(blender, library, tmp_path, args, names):
    out = tmp_path / "out"
    proc = T.run_blender([], blend=BLEND, env=T.addon_env(library), python=T.BATCH,
                         script_args=args + ["--keep-passes", "--output", str(out / "o_"), "--samples", SAMPLES])
    assert proc.returncode == 2, out_text(proc)
    err = proc.stderr
    for n in names:
        assert n in err, (n, err[-2000:])
    assert not T.tracebacks(proc.stdout + err)
    assert not blender_saves(proc.stdout)
    assert not out.exists() or not any(out.iterdir())


# ---------------------------------------------------------------- idempotent re-runs

def test_skip_existing_is_idempotent(blender, library, tmp_path):
    T.need_oiio()
    out = tmp_path / "out"
    first = batch(library, out, "--skip-existing")
    assert first.returncode == 0, out_text(first)
    assert processed(first.stdout) == [1, 2, 3]
    res = results(out)
    keep = tmp_path / "first"
    keep.mkdir()
    for f, p in res.items():
        shutil.copy2(p, keep / p.name)
    stat = {f: (p.stat().st_mtime_ns, p.read_bytes()) for f, p in res.items()}

    # Same range again: nothing renders, nothing changes.
    again = batch(library, out, "--skip-existing")
    assert again.returncode == 0, out_text(again)
    for f in (1, 2, 3):
        assert "libfx batch: frame %d: exists, skipped" % f in again.stdout
    assert processed(again.stdout) == [] and blender_saves(again.stdout) == [], out_text(again)
    assert "3 frame(s) done: 0 rendered, 3 skipped" in again.stdout
    assert {f: (p.stat().st_mtime_ns, p.read_bytes()) for f, p in results(out).items()} == stat

    # Frame 2's result lost: only frame 2 renders, and it is the same frame again.
    (out / "o_libfx.0002.exr").unlink()
    redo = batch(library, out, "--skip-existing")
    assert redo.returncode == 0, out_text(redo)
    assert processed(redo.stdout) == [2], out_text(redo)
    assert len(blender_saves(redo.stdout)) == 1
    for f in (1, 3):
        assert results(out)[f].stat().st_mtime_ns == stat[f][0]
    identical_bytes = same_result(keep / "o_libfx.0002.exr", out / "o_libfx.0002.exr")
    print("re-rendered frame 2: bytes identical: %s" % identical_bytes)

    # An interrupted older run: frame 3's file cut short plus a killed writer's temp file.
    # It is not finished: it renders again, and the leftovers go.
    full = (out / "o_libfx.0003.exr").read_bytes()
    (out / "o_libfx.0003.exr").write_bytes(full[:len(full) // 2])
    (out / ".o_libfx.0003.exr.tmp-999999-0").write_bytes(full[:100])
    mtimes = {f: p.stat().st_mtime_ns for f, p in results(out).items() if f != 3}
    healed = batch(library, out, "--skip-existing")
    assert healed.returncode == 0, out_text(healed)
    assert processed(healed.stdout) == [3], out_text(healed)
    assert re.search(r"frame 3: .*o_libfx\.0003\.exr is damaged or incomplete.*rendering it again",
                     healed.stdout), out_text(healed)
    assert {f: p.stat().st_mtime_ns for f, p in results(out).items() if f != 3} == mtimes
    same_result(keep / "o_libfx.0003.exr", out / "o_libfx.0003.exr")
    assert leftovers(out) == []
    assert sorted(results(out)) == [1, 2, 3]


# ---------------------------------------------------------------- the Flamenco job type

# A stand-in for the Manager's job compiler globals (author, path, frameChunker, print),
# following Flamenco 3's documented behaviour: frameChunker explodes 'A-B,C' (also
# Blender's 'A..B'), sorts and dedups, cuts every chunk_size frames and writes each chunk
# back as ranges, two consecutive frames as 'A,B' (internal/manager/job_compilers/js_globals.go).
FAKE_MANAGER_JS = r"""
const fs = require("fs"), vm = require("vm"), nodePath = require("path");
globalThis.print = () => {};
globalThis.path = { join: nodePath.posix.join, basename: nodePath.posix.basename,
                    dirname: nodePath.posix.dirname };
globalThis.author = {
  Task: (name, type) => ({ name, type, commands: [], deps: [],
                           addCommand(c) { this.commands.push(c); },
                           addDependency(t) { this.deps.push(t.name); } }),
  Command: (name, parameters) => ({ name, parameters }),
};
globalThis.frameChunker = (text, size) => {
  if (!(size >= 1)) throw "invalid chunk size";
  const set = new Set();
  for (const part of text.replace(/\.\./g, "-").split(",")) {
    const ends = part.split("-").map((s) => s.trim());
    if (ends.length > 2 || ends.some((s) => !/^[0-9]+$/.test(s))) throw "invalid range " + text;
    const a = parseInt(ends[0]), b = parseInt(ends[ends.length - 1]);
    for (let f = a; f <= b; f++) set.add(f);
  }
  const frames = [...set].sort((x, y) => x - y);
  const merge = (fr) => {
    const out = [];
    let start = fr[0], prev = fr[0];
    const flush = (a, b) => { if (a === b) out.push(`${a}`);
                              else if (a + 1 === b) out.push(`${a}`, `${b}`);
                              else out.push(`${a}-${b}`); };
    for (const f of fr.slice(1)) { if (f > prev + 1) { flush(start, prev); start = f; } prev = f; }
    flush(start, prev);
    return out.join(",");
  };
  const chunks = [];
  for (let i = 0; i < frames.length; i += size) chunks.push(merge(frames.slice(i, i + size)));
  return chunks;
};
const src = fs.readFileSync(process.argv[2], "utf8");
const api = vm.runInThisContext("\"use strict\";\n" + src + "\n;({ JOB_TYPE, compileJob });", { filename: process.argv[2] });
const jobs = JSON.parse(fs.readFileSync(0, "utf8"));
const out = { job_type: api.JOB_TYPE, jobs: [] };
for (const settings of jobs) {
  const job = { settings, tasks: [], addTask(t) { this.tasks.push(t); } };
  try { api.compileJob(job); out.jobs.push({ tasks: job.tasks }); }
  catch (e) { out.jobs.push({ error: String(e) }); }
}
process.stdout.write(JSON.stringify(out));
"""


def compile_jobs(tmp_path, jobs):
    node = shutil.which("node") or shutil.which("nodejs")
    if node is None:
        pytest.skip("node is not installed: the Flamenco job type is not checked")
    harness = tmp_path / "fake_manager.js"
    harness.write_text(FAKE_MANAGER_JS)
    p = subprocess.run([node, str(harness), str(JOB_TYPE_JS)], input=json.dumps(jobs),
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout)


def explode(chunk):
    frames = []
    for part in chunk.split(","):
        a, _, b = part.partition("-")
        frames.extend(range(int(a), int(b or a) + 1))
    return frames


def worker_argv(command, variables):
    """The argv a Flamenco 3 worker runs for a blender-render command
    (internal/worker/command_blender.go): exe, shlex-split exeArgs, argsBefore, the
    blend file, args; '{name}' variables replaced with the worker platform's values."""
    def sub(s):
        return re.sub(r"\{(\w+)\}", lambda m: variables.get(m.group(1), m.group(0)), s)
    p = command["parameters"]
    argv = [sub(p["exe"])] + shlex.split(sub(p.get("exeArgs", "")))
    argv += [sub(a) for a in p.get("argsBefore", [])]
    if p.get("blendfile"):
        argv.append(sub(p["blendfile"]))
    return argv + [sub(a) for a in p["args"]]


def settings_for(out_prefix, frames, chunk_size, **kw):
    s = {"frames": frames, "chunk_size": chunk_size, "output_root": "/unused",
         "output_prefix": out_prefix, "resolution": RES, "samples": int(SAMPLES), "quality": "scene",
         "recipe": "", "threads": 0, "skip_existing": True, "addon_dir": "{libfx_addon}",
         "factory_startup": True, "blendfile": str(BLEND)}
    s.update(kw)
    return s


def test_flamenco_job_type_chunks_and_commands(blender, library, tmp_path):
    prefix = str(tmp_path / "farm" / "shot_")
    cases = [("1-3", 2), ("1-250", 10), ("1-10,20,31-40", 4), ("7", 3), ("3..5, 1", 1)]
    jobs = [settings_for(prefix, f, c) for f, c in cases]
    jobs.append(settings_for(prefix, "1-3", 2, resolution="64by36"))
    jobs.append(settings_for(prefix, "1-3", 2, samples=0, resolution="", quality="final",
                             recipe="/shared/r.json", threads=4, skip_existing=False,
                             factory_startup=False))
    got = compile_jobs(tmp_path, jobs)

    keys = {s["key"]: s for s in got["job_type"]["settings"]}
    for k in ("frames", "chunk_size", "output_root", "output_prefix", "resolution", "samples",
              "quality", "recipe", "threads", "skip_existing", "addon_dir", "blendfile"):
        assert k in keys, k
    assert keys["skip_existing"]["default"] is True and keys["addon_dir"]["default"] == "{libfx_addon}"

    for (frames, chunk_size), job in zip(cases, got["jobs"]):
        assert "error" not in job, job
        wanted = sorted(set(explode(frames.replace("..", "-").replace(" ", ""))))
        covered = []
        *chunk_tasks, check = job["tasks"]
        # The last task checks the whole range once every chunk is done.
        assert check["name"] == "libfx-check" and check["deps"] == [t["name"] for t in chunk_tasks]
        check_runner = check["commands"][0]["parameters"]["args"][5:]
        assert check_runner[0] == "--check" and check_runner[3:5] == ["--output", prefix]
        assert sorted(explode(check_runner[2])) == wanted
        assert check_runner[5:] == ["--contact-sheet", prefix + "libfx.contact_sheet.png"]
        for task in chunk_tasks:
            assert task["type"] == "blender" and len(task["commands"]) == 1
            cmd = task["commands"][0]
            assert cmd["name"] == "blender-render"
            args = cmd["parameters"]["args"]
            assert args[:5] == ["--python-exit-code", "2", "--python", "{libfx_addon}/batch.py", "--"]
            runner = args[5:]
            assert runner[0] == "--frames" and runner[2:4] == ["--output", prefix]
            assert "--skip-existing" in runner
            assert runner[runner.index("--resolution") + 1] == RES
            assert runner[runner.index("--samples") + 1] == SAMPLES
            assert "--quality" not in runner and "--recipe" not in runner
            assert cmd["parameters"]["argsBefore"] == ["--factory-startup"]
            assert cmd["parameters"]["blendfile"] == str(BLEND)
            chunk = explode(runner[1])
            assert len(chunk) <= chunk_size
            covered += chunk
        assert sorted(covered) == wanted, (frames, chunk_size)   # every frame exactly once
        assert len(chunk_tasks) == -(-len(wanted) // chunk_size)

    assert "resolution" in got["jobs"][len(cases)]["error"]
    opt = got["jobs"][len(cases) + 1]["tasks"][0]["commands"][0]["parameters"]
    runner = opt["args"][opt["args"].index("--") + 1:]
    assert runner[runner.index("--quality") + 1] == "final"
    assert runner[runner.index("--recipe") + 1] == "/shared/r.json"
    assert runner[runner.index("--threads") + 1] == "4"
    assert "--skip-existing" not in runner and "--resolution" not in runner and "--samples" not in runner
    assert opt["argsBefore"] == []

    # The first job ('1-3' in chunks of 2 -> '1,2' and '3'), run as a worker would run it,
    # with Flamenco's default blenderArgs.
    variables = {"blender": T.blender_path(), "blenderArgs": "-b -y",
                 "libfx_addon": str(T.REPO / "addon" / "libfx")}
    *tasks, check = got["jobs"][0]["tasks"]
    assert [explode(t["commands"][0]["parameters"]["args"][6]) for t in tasks] == [[1, 2], [3]]
    env = dict(os.environ, **T.addon_env(library))
    out = tmp_path / "farm"
    # Before the chunks: the check task fails, naming the missing frames, and writes no sheet.
    p = subprocess.run(worker_argv(check["commands"][0], variables), capture_output=True, text=True,
                       timeout=240, env=env)
    assert p.returncode == 1 and "check: 3 of 3 frame(s) incomplete" in p.stderr, out_text(p)
    assert not (out / "shot_libfx.contact_sheet.png").exists()
    for i, task in enumerate(tasks):
        argv = worker_argv(task["commands"][0], variables)
        p = subprocess.run(argv, capture_output=True, text=True, timeout=240, env=env)
        assert p.returncode == 0, out_text(p)
        assert sorted(int(m) for m in re.findall(r"^shot_libfx\.(\d{4})\.exr$", "\n".join(
            x.name for x in out.iterdir()), re.M)) == ([1, 2] if i == 0 else [1, 2, 3])
    assert leftovers(out) == []
    p = subprocess.run(worker_argv(check["commands"][0], variables), capture_output=True, text=True,
                       timeout=240, env=env)
    assert p.returncode == 0 and "check: all 3 frame(s) complete" in p.stdout, out_text(p)
    assert (out / "shot_libfx.contact_sheet.png").stat().st_size > 0

    # A wrong add-on path on a worker fails the task instead of exiting 0 with nothing done.
    bad = worker_argv(tasks[1]["commands"][0], dict(variables, libfx_addon="/nonexistent/libfx"))
    p = subprocess.run(bad, capture_output=True, text=True, timeout=120, env=env)
    assert p.returncode != 0, out_text(p)
