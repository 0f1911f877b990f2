#!/usr/bin/python3
"""bench_platforms: the release builds against the development build, effect by effect at
`final`, interleaved in one run. A self-contained or cross-built libfx must be as fast as the
build made on the machine itself (docs/platforms.md).

    /usr/bin/python3 tests/bench/bench_platforms.py [--rounds 5] [--frames 4] [--size 1920x1080]
        [--builds dev,linux-x64,windows-x64] [--out out/bench_platforms]

Builds (the `libfx` CLI of each; absent ones are left out with a note):
  dev          build/libfx/libfx: Debian 12, gcc 12, Debian's shared OpenEXR 3.1.5
  linux-x64    build-linux-x64/libfx/libfx: the release library (Debian 11 root, gcc 10,
               static dependencies; scripts/platforms.sh --build)
  windows-x64  build-windows-x64/libfx/libfx.exe under Wine (MinGW gcc 12, static
               dependencies): Wine runs the compute natively; only process start and file
               calls go through it, and those are outside the effects' timings
For each scene of bench_all (the bath, the atrium, the mirror room: bench_all's renders and
recipes, every effect it benchmarks on that scene, in one stack at `final`), each round runs
each build on a sequence of FRAMES copies of the frame (`libfx run -v -j 2`), the order of the
builds rotating from round to round. An effect's time is the library's own per-effect timing
(fx_stack_timings_json); "warm" is the median over rounds of the median of frames 2..FRAMES,
"first" the median over rounds of frame 1 (a fresh process). Ratios are against dev.
"""
import argparse
import json
import os
import pathlib
import shutil
import statistics
import subprocess
import sys
import tempfile

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import bench_all as B  # noqa: E402

ROOT = B.ROOT
BUILDS = {
    "dev": [str(ROOT / "build/libfx/libfx")],
    "linux-x64": [str(ROOT / "build-linux-x64/libfx/libfx")],
    "windows-x64": ["env", "WINEDEBUG=-all", "/usr/lib/wine/wine64", str(ROOT / "build-windows-x64/libfx/libfx.exe")],
}


def run_sequence(cmd, recipe, side, pattern, out_pattern):
    """Per frame, the list of (effect, ms) the library timed."""
    p = subprocess.run(cmd + ["run", "-v", "-j", "2", "-f", "--stack", str(recipe), "--sidecar", str(side),
                              pattern, "-o", out_pattern], capture_output=True, text=True)
    if p.returncode:
        raise SystemExit("bench_platforms: %s failed:\n%s" % (" ".join(cmd), (p.stdout + p.stderr)[-3000:]))
    frames = []
    for line in p.stdout.splitlines():
        if line.startswith("timings: "):
            frames.append([(t["effect"], t["ms"]) for t in json.loads(line[len("timings: "):])])
    return frames


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--frames", type=int, default=4)
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--builds", default="dev,linux-x64,windows-x64")
    ap.add_argument("--out", default="out/bench_platforms")
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.split("x"))
    out = pathlib.Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    builds = []
    for name in a.builds.split(","):
        exe = BUILDS[name][-1]
        if os.path.exists(exe):
            builds.append(name)
        else:
            print("bench_platforms: no %s build at %s: left out" % (name, exe), file=sys.stderr)
    if "dev" not in builds:
        raise SystemExit("bench_platforms: the dev build (build/) is the reference and is missing")
    env = dict(os.environ, LIBFX_LIBRARY=str(ROOT / "build/libfx/libfx.so"))
    tmp = pathlib.Path(tempfile.mkdtemp(prefix="bench_platforms.", dir=str(out)))
    warm, first = {}, {}   # (scene, index, effect, build) -> [per-round value]
    order = []
    for sc in B.SCENES:
        passes, side, recipe, _, _ = B.render_scene(sc, w, h, a.spp, ROOT / "out" / "bench_all", env)
        seq = tmp / sc
        seq.mkdir()
        for f in range(1, a.frames + 1):
            os.link(passes, seq / ("p.%04d.exr" % f))
        for r in range(a.rounds):
            rot = builds[r % len(builds):] + builds[:r % len(builds)]
            for b in rot:
                frames = run_sequence(BUILDS[b], recipe, side, str(seq / "p.####.exr"), str(seq / "o.####.exr"))
                for i, (effect, _) in enumerate(frames[0]):
                    key = (sc, i, effect)
                    if key not in order:
                        order.append(key)
                    first.setdefault(key + (b,), []).append(frames[0][i][1])
                    warm.setdefault(key + (b,), []).append(statistics.median(fr[i][1] for fr in frames[1:]))
            print("%s: round %d/%d" % (sc, r + 1, a.rounds), file=sys.stderr, flush=True)
    shutil.rmtree(tmp, ignore_errors=True)

    others = [b for b in builds if b != "dev"]
    head = ["scene", "effect", "dev warm ms"] + ["%s / dev warm" % b for b in others] + \
           ["dev first ms"] + ["%s / dev first" % b for b in others]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * 2 + "---:|" * (len(head) - 2)]
    ratios = {b: [] for b in others}
    totals = {b: [0.0, 0.0] for b in builds}
    for key in order:
        med = {b: statistics.median(warm[key + (b,)]) for b in builds}
        fmed = {b: statistics.median(first[key + (b,)]) for b in builds}
        for b in builds:
            totals[b][0] += med[b]
            totals[b][1] += fmed[b]
        for b in others:
            ratios[b].append(med[b] / med["dev"])
        lines.append("| %s | %s | %.1f | %s | %.1f | %s |" % (
            key[0], key[2], med["dev"], " | ".join("%.3f" % (med[b] / med["dev"]) for b in others),
            fmed["dev"], " | ".join("%.3f" % (fmed[b] / fmed["dev"]) for b in others)))
    lines.append("| all | sum | %.1f | %s | %.1f | %s |" % (
        totals["dev"][0], " | ".join("%.3f" % (totals[b][0] / totals["dev"][0]) for b in others),
        totals["dev"][1], " | ".join("%.3f" % (totals[b][1] / totals["dev"][1]) for b in others)))
    lines.append("")
    for b in others:
        lines.append("%s warm / dev: median %.3f, range %.3f-%.3f over %d effects" % (
            b, statistics.median(ratios[b]), min(ratios[b]), max(ratios[b]), len(ratios[b])))
    m = B.machine()
    lines.append("%dx%d, `libfx run -v -j 2`, %d rounds of %d frames per build, builds rotating; %s, %s cores"
                 % (w, h, a.rounds, a.frames, m["cpu"], m["cores"]))
    text = "\n".join(lines) + "\n"
    (out / "bench_platforms.md").write_text(text)
    with open(out / "bench_platforms.json", "w") as f:
        json.dump({"warm": {"|".join(map(str, k)): v for k, v in warm.items()},
                   "first": {"|".join(map(str, k)): v for k, v in first.items()}}, f, indent=1)
    print(text)


if __name__ == "__main__":
    main()
