#!/usr/bin/python3
"""bench_first_frame: one effect's first frame in fresh processes, several CLIs interleaved
(an old and a new build in the same minutes: on this shared VM only such ratios count).

    /usr/bin/python3 tests/bench/bench_first_frame.py EFFECT PARAMS_JSON RUNS PASSES.exr CLI [CLI ...]

Each run starts `CLI run -v --threads T` on a one-effect recipe (uncompressed output) and sums
the `timings:` line's ms, as bench_peers_all's Libfx.run does. A CLI may be a wrapper script
(LD_LIBRARY_PATH=<old lib dir> exec <old libfx> "$@": the CLI's RUNPATH yields to it).
Environment: FF_T threads (default 2); FF_EXTRA more CLI options (--sidecar S --quality Q).
Prints each CLI's median, minimum and every run."""
import json
import os
import statistics
import subprocess
import sys
import tempfile


def main():
    if len(sys.argv) < 6:
        print(__doc__, file=sys.stderr)
        return 2
    eff, params, runs, exr = sys.argv[1], json.loads(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
    clis = sys.argv[5:]
    extra = os.environ.get("FF_EXTRA", "").split()
    res = {c: [] for c in clis}
    with tempfile.TemporaryDirectory() as d:
        rec = os.path.join(d, "recipe.json")
        with open(rec, "w") as f:
            json.dump({"version": 1, "effects": [{"effect": eff, "params": params}]}, f)
        for _ in range(runs):
            for c in clis:
                r = subprocess.run([c, "run", "--stack", rec, "--threads", os.environ.get("FF_T", "2"), "--force",
                                    "--quiet", exr, "-o", os.path.join(d, "out.exr"), "--compression", "none",
                                    "-v"] + extra, capture_output=True, text=True)
                if r.returncode:
                    print(r.stderr, file=sys.stderr)
                    return 1
                for line in r.stdout.splitlines():
                    if line.startswith("timings:"):
                        res[c].append(sum(t["ms"] for t in json.loads(line[len("timings:"):])))
    for c in clis:
        v = res[c]
        print("%-40s median %.2f ms  min %.2f  (%s)" % (c, statistics.median(v), min(v), " ".join("%.1f" % x for x in v)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
