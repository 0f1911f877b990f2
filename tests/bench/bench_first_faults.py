#!/usr/bin/python3
"""bench_first_faults.py: a process's first frame against its warm ones, several builds
interleaved (on this shared VM only ratios taken in the same minutes count).

    /usr/bin/python3 tests/bench/bench_first_faults.py RUNS PASSES.exr SIDECAR.json BUILD_DIR[,BUILD_DIR...] RECIPE...

Each run starts BUILD_DIR/tests/bench/bench_first_faults (4 frames, 2 threads: read with the
stack's needs, sidecar, fx_stack_run_consume, as `libfx run`) on one recipe; frame 1 is the
first, the median of frames 2-4 the warm one. Prints per recipe and build the medians over the
runs of the stack run's wall ms, CPU ms (user + sys, every thread), sys ms and minor faults,
first and warm, and each run's first/warm wall ratio."""
import re
import statistics
import subprocess
import sys


def main():
    if len(sys.argv) < 6:
        print(__doc__, file=sys.stderr)
        return 2
    runs, passes, sidecar = int(sys.argv[1]), sys.argv[2], sys.argv[3]
    builds, recs = sys.argv[4].split(","), sys.argv[5:]
    res = {(b, r): [] for b in builds for r in recs}
    pat = re.compile(r"run_ms (\S+) user (\S+) sys (\S+) minflt (\S+)")
    for it in range(runs):
        for r in recs:
            for b in (builds if it % 2 == 0 else builds[::-1]):
                out = subprocess.run([b + "/tests/bench/bench_first_faults", passes, sidecar, r, "4", "2"],
                                     capture_output=True, text=True, check=True).stdout
                res[(b, r)].append([tuple(float(x) for x in pat.search(l).groups()) for l in out.splitlines()])
    med = statistics.median
    for r in recs:
        print(r)
        for b in builds:
            a = res[(b, r)]
            first = lambda k: med(x[0][k] for x in a)
            warm = lambda k: med(med(f[k] for f in x[1:]) for x in a)
            fc = med(x[0][1] + x[0][2] for x in a)
            wc = med(med(f[1] + f[2] for f in x[1:]) for x in a)
            print("  %s: wall first %.2f warm %.2f (%.2fx) | cpu first %.1f warm %.1f (%.2fx) | sys first %.1f "
                  "warm %.1f | faults first %d warm %d | runs' wall first/warm: %s"
                  % (b, first(0), warm(0), first(0) / warm(0), fc, wc, fc / wc, first(2), warm(2), first(3), warm(3),
                     " ".join("%.2f" % (x[0][0] / med(f[0] for f in x[1:])) for x in a)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
