"""The truth comparisons as a regression gate (issue 28): what is run, what is read from
each report, and how far a number may move. Used by test_truth_gates.py (the gate) and
measure_truth_gates.py (which writes the numbers the gate compares with, per Blender
major version, into truth_gate_numbers.json).

Each tests/bench/truth_*.py runs with its own measuring code, unchanged, at 128x72 and
16 samples (--runs 1; the Eevee peers left out, the shadow scripts with the light_group
configuration only); its OUT/truth_<name>.json is read.

A number has a kind, and each kind its margin (for what one machine cannot show: another
CPU's Cycles kernels and float rounding; on one machine the fixed-seed renders repeat bit
for bit):
  - mae: an error may grow to measured x 1.15 + 0.002 (an error that falls passes);
  - ratio: a ratio of means (output / truth, added light / truth's) or the caustics'
    contrast (4x4 box) may move by 5 % of itself (the truth at another seed moves these
    by 0.1-1.2 %);
  - corr: god rays' correlation of added light may fall by 0.03;
  - offset: the centroid of god rays' added light may move 1.5 px farther.
"""
import json
import pathlib
import subprocess
import sys

RES, SPP = "128x72", 16
HERE = pathlib.Path(__file__).resolve().parent
BENCH = HERE.parent / "bench"
NUMBERS = HERE / "truth_gate_numbers.json"

# name: (script, extra arguments, extra environment)
GATES = {
    "godrays": ("truth_godrays.py", [], {}),
    "caustics": ("truth_caustics.py", [], {}),
    "mirrors": ("truth_mirrors.py", ["--no-eevee", "--truth-spp", str(SPP)], {}),
    "shadows": ("truth_shadows.py", ["--no-eevee"], {"TRUTH_SHADOWS_CONFIGS": "light_group"}),
    "atrium_shadows": ("truth_atrium_shadows.py", ["--no-eevee", "--configs", "light_group"], {}),
}


def blender_major(blender):
    p = subprocess.run([blender, "--factory-startup", "-b", "--version"], capture_output=True, text=True)
    line = next((x for x in p.stdout.splitlines() if x.startswith("Blender ")), "Blender 0")
    return line.split()[1].split(".")[0], line.strip()


def run(root, name, env, timeout=1800):
    """Runs tests/bench/<script> ROOT/NAME --res RES --spp SPP --runs 1 [args]: (report, stdout)."""
    script, args, extra = GATES[name]
    out = pathlib.Path(root) / name
    cmd = [sys.executable, str(BENCH / script), str(out), "--res", RES, "--spp", str(SPP), "--runs", "1"]
    p = subprocess.run(cmd + args, capture_output=True, text=True, timeout=timeout, env=dict(env, **extra))
    if p.returncode != 0:
        raise RuntimeError("%s exited %d:\n%s\n%s" % (script, p.returncode, p.stdout[-3000:], p.stderr[-3000:]))
    report = out / ("truth_%s.json" % name)
    if not report.is_file():
        raise RuntimeError("%s wrote no %s:\n%s" % (script, report, p.stdout[-3000:]))
    return json.loads(report.read_text()), p.stdout


def _libfx_rows(rows, prefix):
    return [(r[0][len(prefix):], r) for r in rows if r[0].startswith(prefix)]


def extract(name, report):
    """{what: [kind, value]} of one report: every libfx row the script measured."""
    got = {}
    if name == "godrays":
        for q, r in _libfx_rows(report["rows"], "libfx "):
            got[q + " shaft MAE 9x9"] = ["mae", r[4]]
            got[q + " correlation of added light"] = ["corr", r[7]]
            got[q + " centroid offset px"] = ["offset", r[8]]
            got[q + " added light / truth's"] = ["ratio", r[9]]
    elif name == "caustics":
        for q, r in _libfx_rows(report["rows"], "libfx "):
            got[q + " mean / truth"] = ["ratio", r[3]]
            got[q + " contrast 4x4 box"] = ["ratio", r[5]]
            got[q + " whole MAE"] = ["mae", r[7]]
    elif name == "mirrors":
        for v, part in report.items():
            if not isinstance(part, dict) or "rows" not in part:
                continue
            for r in part["rows"]:
                if r[0].startswith("libfx ") or "probe" in r[0]:
                    got["%s %s region MAE" % (v, r[0])] = ["mae", r[2]]
    elif name == "shadows":
        for v, part in report.items():
            if not isinstance(part, dict) or "rows" not in part:
                continue
            for q, r in _libfx_rows(part["rows"], "light_group "):
                got["%s %s shadow MAE" % (v, q)] = ["mae", r[2]]
                got["%s %s mean / truth" % (v, q)] = ["ratio", r[4]]
    elif name == "atrium_shadows":
        for q, r in _libfx_rows(report["rows"], "light_group "):
            got[q + " shadow MAE"] = ["mae", r[2]]
            got[q + " mean / truth"] = ["ratio", r[5]]
    else:
        raise KeyError(name)
    return got


def within(kind, got, measured):
    if kind == "mae":
        return got <= measured * 1.15 + 0.002
    if kind == "ratio":
        return abs(got - measured) <= 0.05 * abs(measured)
    if kind == "corr":
        return got >= measured - 0.03
    if kind == "offset":
        return got <= measured + 1.5
    raise KeyError(kind)


def check(measured, got):
    """What is out of bounds, or missing, in got against measured (both from extract)."""
    fails = []
    for what, (kind, m) in measured.items():
        if what not in got:
            fails.append("%s: not in the report" % what)
        elif not within(kind, got[what][1], m):
            fails.append("%s: %.4f (measured %.4f)" % (what, got[what][1], m))
    return fails


def load_numbers():
    return json.loads(NUMBERS.read_text()) if NUMBERS.is_file() else {}
