#!/usr/bin/python3
"""bench_vsm_change: what a drag of vsm_shadows' filter_size costs the live loop's stack run
(issue 13), through the add-on's own ctypes binding, without Blender.

    /usr/bin/python3 tests/bench/bench_vsm_change.py [--renders DIR] [--runs 9] [--step 0.25] LIB.so [LIB2.so ...]

One process per library and round (three rounds, libraries interleaved): one context holds
the atrium's 1080p passes and their 1/2 proxy, as the live loop does, and runs the atrium's
stack at draft --runs times, filter_size 5, 5 + step, 5 + 2 step, ... (a value not used
before at every run, as a drag makes them; --step 0: the same value, the cached map). Prints
the first run and the median of the others, in ms.
"""
import argparse
import importlib.util
import json
import os
import statistics
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def one(renders, runs, step):
    spec = importlib.util.spec_from_file_location("native", os.path.join(ROOT, "addon", "libfx", "native.py"))
    native = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(native)
    d = os.path.join(renders, "atrium_1920x1080")
    rec = json.load(open(os.path.join(d, "bench_recipe.json")))
    ctx = native.Context(2)
    st = native.Stack(ctx, json.dumps(rec))
    f = native.Frame.read(ctx, os.path.join(d, "r_libfx_passes.0001.exr"), st)
    f.apply_sidecar(json.load(open(os.path.join(d, "r_libfx.0001.camera.json"))))
    p = f.reduce(2)
    ts = []
    for i in range(runs):
        for e in rec["effects"]:
            if e["effect"] == "vsm_shadows":
                e.setdefault("params", {})["filter_size"] = 5.0 + step * i
        s = native.Stack(ctx, json.dumps(rec))
        s.set_quality("draft")
        t0 = time.perf_counter()
        o = s.run(p)
        ts.append((time.perf_counter() - t0) * 1e3)
        o.close()
        s.close()
    print("%s: first %.1f ms, then median %.1f ms (%s)" % (native.library_path(), ts[0], statistics.median(ts[1:]),
                                                          " ".join("%.0f" % t for t in ts)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--renders", default=os.path.join(ROOT, "out", "bench_all", "renders"))
    ap.add_argument("--runs", type=int, default=9)
    ap.add_argument("--step", type=float, default=0.25)
    ap.add_argument("--one", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("libs", nargs="+")
    a = ap.parse_args()
    if a.one:
        return one(a.renders, a.runs, a.step)
    for _ in range(3):
        for lib in a.libs:
            subprocess.run([sys.executable, __file__, "--one", "--renders", a.renders, "--runs", str(a.runs),
                            "--step", str(a.step), lib], env=dict(os.environ, LIBFX_LIBRARY=os.path.abspath(lib)),
                           check=True)


if __name__ == "__main__":
    main()
