#!/usr/bin/python3
"""bench_static: the self-contained release build against the development build, effect by
effect at `final`, interleaved in one run (issue: a self-contained libfx must be as fast).

    /usr/bin/python3 tests/bench/bench_static.py [--rounds 5] [--runs 5] [--size 1920x1080]
        [--dev build] [--release build-linux-x64-bench] [--out out/bench_static]

Both sides are tests/bench/bench_presets (the tool bench_all.py runs), one built on Debian 12
(gcc 12, Debian's shared OpenEXR) in DEV, the other in the Debian 11 root against the static
dependencies (gcc 10; `bash scripts/in_root.sh bullseye cmake --build build-linux-x64-bench
--target bench_presets`, configured with -DLIBFX_SELF_CONTAINED=ON -DLIBFX_BUILD_BENCH=ON).
Each round runs every (scene, effect) of bench_all's plan on both, the order alternating from
round to round; a row's time is bench_presets' median of RUNS at 2 threads, and the table
gives, per effect, the median over rounds of each side and their ratio.
The scenes' passes are bench_all's renders (rendered here if the cache lacks them).
"""
import argparse
import csv
import os
import pathlib
import statistics
import subprocess
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import bench_all as B  # noqa: E402


def one(bench_bin, scene, effect, passes, side, recipe, runs, tmp):
    cmd = [bench_bin, "--passes", passes, "--sidecar", side, "--recipe", recipe, "--scene", scene,
           "--effects", effect, "--threads", "2", "--runs", str(runs), "--qualities", "final",
           "--ref-max-ms", "0", "-o", tmp]
    subprocess.run([str(c) for c in cmd], check=True, stderr=subprocess.DEVNULL)
    rows = [r for r in csv.DictReader(open(tmp)) if r["kind"] == "effect"
            and r["setting"] == "quality=final" and r["threads"] == "2"]
    if not rows:
        raise SystemExit("bench_static: no final row from %s for %s on %s" % (bench_bin, effect, scene))
    return float(rows[0]["ms_median"])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--dev", default="build")
    ap.add_argument("--release", default="build-linux-x64-bench")
    ap.add_argument("--out", default="out/bench_static")
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.split("x"))
    out = pathlib.Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    bins = {"dev": B.ROOT / a.dev / "tests/bench/bench_presets",
            "release": B.ROOT / a.release / "tests/bench/bench_presets"}
    for k, p in bins.items():
        if not p.exists():
            raise SystemExit("bench_static: no %s bench_presets at %s (see the docstring)" % (k, p))
    env = dict(os.environ, LIBFX_LIBRARY=str(B.ROOT / a.dev / "libfx/libfx.so"))
    renders_root = B.ROOT / "out" / "bench_all"
    work = []
    for sc in B.SCENES:
        passes, side, recipe, effects, _ = B.render_scene(sc, w, h, a.spp, renders_root, env)
        work += [(sc, e, passes, side, recipe) for e in effects]
    times = {(sc, e, k): [] for sc, e, *_ in work for k in bins}
    tmp = out / "one.csv"
    for r in range(a.rounds):
        order = list(bins) if r % 2 == 0 else list(reversed(list(bins)))
        for sc, e, passes, side, recipe in work:
            for k in order:
                times[(sc, e, k)].append(one(bins[k], sc, e, passes, side, recipe, a.runs, tmp))
        print("round %d/%d done" % (r + 1, a.rounds), file=sys.stderr, flush=True)
    lines = ["| scene | effect | dev ms | release ms | release / dev |", "|---|---|---:|---:|---:|"]
    ratios = []
    with open(out / "bench_static.csv", "w", newline="") as f:
        wr = csv.writer(f)
        wr.writerow(["scene", "effect", "dev_ms", "release_ms", "ratio", "dev_rounds", "release_rounds"])
        for sc, e, *_ in work:
            d, s = statistics.median(times[(sc, e, "dev")]), statistics.median(times[(sc, e, "release")])
            ratios.append(s / d)
            wr.writerow([sc, e, "%.2f" % d, "%.2f" % s, "%.3f" % (s / d),
                         " ".join("%.2f" % v for v in times[(sc, e, "dev")]),
                         " ".join("%.2f" % v for v in times[(sc, e, "release")])])
            lines.append("| %s | %s | %.1f | %.1f | %.3f |" % (sc, e, d, s, s / d))
    total_d = sum(statistics.median(times[(sc, e, "dev")]) for sc, e, *_ in work)
    total_s = sum(statistics.median(times[(sc, e, "release")]) for sc, e, *_ in work)
    lines.append("| all | sum of medians | %.1f | %.1f | %.3f |" % (total_d, total_s, total_s / total_d))
    lines.append("")
    lines.append("%dx%d, 2 threads, %d rounds x %d runs; ratio median %.3f, range %.3f-%.3f"
                 % (w, h, a.rounds, a.runs, statistics.median(ratios), min(ratios), max(ratios)))
    (out / "bench_static.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
