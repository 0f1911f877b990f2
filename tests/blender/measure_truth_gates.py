"""Measures the numbers the truth gate (test_truth_gates.py) compares with, for the
Blender on PATH (or $BLENDER), and writes them into truth_gate_numbers.json under that
Blender's major version. Run it when a change improves a number on purpose, and once per
new Blender major version (a Blender whose major has no numbers skips the gate, saying so).

  LIBFX_LIBRARY=build/libfx/libfx.so LIBFX_CLI=build/libfx/libfx \
    /usr/bin/python3 tests/blender/measure_truth_gates.py OUT [--runs 2] [--only godrays,...]
  bash scripts/in_root.sh trixie env LIBFX_LIBRARY=$PWD/build-trixie/libfx/libfx.so \
    LIBFX_CLI=$PWD/build-trixie/libfx/libfx python3 tests/blender/measure_truth_gates.py OUT

Each run renders from an empty OUT/run<k>; with --runs 2 or more, every number must agree
in every run within 1e-4 + 1e-4 x itself (far inside the gate's smallest margin, 0.002), or
nothing is written. The fixed-seed renders repeat bit for bit on one machine, except the
caustics truth (manifold next-event estimation), whose numbers moved in the 10th digit
between two runs on 3.4 once. --keep reuses the renders already in OUT/run<k> (the truth
scripts render only what is missing): for updating the numbers after a library change that
leaves the renders alone.
"""
import argparse
import datetime
import json
import os
import pathlib
import shutil
import subprocess
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import truth_gate_lib as G  # noqa: E402


def _agree(a, b):
    """Two measurements of one number ([kind, value]) agree: same kind, values within
    1e-4 + 1e-4 x |value|."""
    return b is not None and a[0] == b[0] and abs(a[1] - b[1]) <= 1e-4 + 1e-4 * abs(a[1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out")
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--only", default="", help="comma-separated gate names (default: all)")
    ap.add_argument("--keep", action="store_true", help="reuse the renders in OUT/run<k>")
    a = ap.parse_args()
    for var in ("LIBFX_LIBRARY", "LIBFX_CLI"):
        if not os.environ.get(var):
            sys.exit("measure_truth_gates: set %s" % var)
    blender = os.environ.get("BLENDER") or shutil.which("blender")
    if not blender:
        sys.exit("measure_truth_gates: no blender on PATH (or set BLENDER)")
    major, version = G.blender_major(blender)
    names = [n for n in a.only.split(",") if n] or list(G.GATES)
    unknown = [n for n in names if n not in G.GATES]
    if unknown:
        sys.exit("measure_truth_gates: unknown gate(s) %s; known: %s" % (", ".join(unknown), ", ".join(G.GATES)))
    env = dict(os.environ, BLENDER=blender)
    runs = []
    for k in range(1, max(1, a.runs) + 1):
        root = pathlib.Path(a.out) / ("run%d" % k)
        if root.exists() and not a.keep:
            shutil.rmtree(root)
        root.mkdir(parents=True, exist_ok=True)
        got = {}
        for n in names:
            print("measure_truth_gates: %s run %d (%s)" % (n, k, version), flush=True)
            got[n] = G.extract(n, G.run(root, n, env)[0])
        runs.append(got)
    for k, other in enumerate(runs[1:], 2):
        for n in names:
            diff = [w for w in runs[0][n] if not _agree(runs[0][n][w], other[n].get(w))]
            if diff:
                sys.exit("measure_truth_gates: run %d differs from run 1 beyond 1e-4 in %s: %s; nothing written"
                         % (k, n, ", ".join(diff[:6])))
    numbers = G.load_numbers()
    entry = numbers.setdefault(major, {"gates": {}})
    entry["blender"] = version
    entry["measured"] = "%s, %d run(s)%s" % (datetime.date.today().isoformat(), len(runs),
                                              ", agreeing within 1e-4" if len(runs) > 1 else "")
    try:   # a Blender root may have no git
        entry["commit"] = subprocess.run(["git", "-C", str(G.HERE), "rev-parse", "--short", "HEAD"],
                                         capture_output=True, text=True).stdout.strip()
    except OSError:
        entry["commit"] = ""
    entry["gates"].update(runs[0])
    G.NUMBERS.write_text(json.dumps(dict(sorted(numbers.items())), indent=1) + "\n")
    print("measure_truth_gates: %s: %d numbers written to %s" % (version, sum(len(runs[0][n]) for n in names),
                                                                  G.NUMBERS))


if __name__ == "__main__":
    main()
