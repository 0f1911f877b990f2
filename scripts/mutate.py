#!/usr/bin/python3
"""Mutation run over the effects' kernels (issue 28): do the tests fail when the code is wrong?

A catalogue of small, plausible mutations (a flipped sign, an off-by-one bound, a swapped
channel, a dropped term, a constant changed by 10 %) is generated from the sources by fixed
rules and a fixed seed (--generate writes scripts/mutation_catalogue.tsv, which is committed
and reviewed); a run copies the committed HEAD to out/mutation/tree (the working tree is never
touched), applies each mutation alone to that copy, rebuilds one object and relinks in its
own build folder (build-mut/, Release, no benchmarks), runs the tests, puts the file back
(always: in `finally`, and from a backup copy if a run was killed), and records killed /
survived / not compiled with the test that killed it. docs/mutation.md.

    /usr/bin/python3 scripts/mutate.py --generate           # (re)write the catalogue
    /usr/bin/python3 scripts/mutate.py --list [--effects bloom,edges]
    /usr/bin/python3 scripts/mutate.py --out docs/mutation_results   # the full run
    /usr/bin/python3 scripts/mutate.py --only god_rays-03 --only rain-07
    /usr/bin/python3 scripts/mutate.py --merge FULL.csv RERUN.csv --note TEXT --out BASE  # no run

Tests that count, run in this order and stopped at the first failure (killed = any of them
fails, crashes or times out):
  1. the effect's own C tests (TESTS_OF below), and for edges tests/python/test_edges_gradient.py;
  2. every other CTest test but the four source checkers and the install test (NOT_BEHAVIOUR);
  3. all of tests/python (pytest -x) against this build's CLI and library.
A mutation that survives has therefore passed every C and Python test of the repository.
"""
import argparse
import csv
import io
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import tarfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
TREE = [REPO]  # the snapshot the run mutates, builds and tests (set in main)
CATALOGUE = REPO / "scripts" / "mutation_catalogue.tsv"
EQUIVALENT = REPO / "scripts" / "mutation_equivalent.tsv"
SEED = 28  # the number; change it only with a new catalogue and a new docs/mutation.md
PER_EFFECT = 9

EFFECTS = [
    "bloom", "cel_shading", "color_matrix", "edges", "gaussian_blur", "god_rays", "pixelate",
    "posterize", "rain", "rain_splashes", "sin_city", "ssr_mirror", "voronoi_caustics",
    "vsm_shadows", "wet_surfaces",
]
# The two effects whose kernel lives in a math/ helper of their own get that helper too.
EXTRA_FILES = {
    "gaussian_blur": ["libfx/src/math/blur.c"],
    "posterize": ["libfx/src/math/levels.c"],
}
TESTS_OF = {
    "pixelate": ["test_pixelate", "test_pixelate_world"],
    "rain": ["test_rain"],
    "rain_splashes": ["test_rain"],
    "wet_surfaces": ["test_rain"],
    "gaussian_blur": ["test_gaussian_blur", "test_blur_math"],
}
PYTESTS_OF = {"edges": ["tests/python/test_edges_gradient.py"]}
NOT_BEHAVIOUR = ["install_and_example", "check_layers", "test_check_layers", "check_function_length",
                 "test_check_function_length"]
OPERATORS = ["sign", "bound", "channel", "drop", "const"]
# Functions that are not kernels: which passes, whether a camera, how wide a halo, whether the
# parameters are acceptable. Mutations there are left out of the catalogue.
NOT_KERNEL = re.compile(r"(_passes|_needs_camera|_validate|_halo|_describe)$")
# A line that allocates, frees, fails, asserts or sizes memory is not a kernel line.
SKIP_LINE = re.compile(r"__builtin_prefetch|alloc|fx_mem_free|\bfree\(|fx_fail|FX_ERR|return FX_|assert|sizeof|__builtin_expect")


def effect_files(effect):
    return [f"libfx/src/effects/{effect}.c"] + EXTRA_FILES.get(effect, [])


# ---------------------------------------------------------------------------- generation

def code_only(text):
    """The text with comments, string and character literals blanked (same length)."""
    out = list(text)
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            for k in range(i, j):
                if out[k] != "\n":
                    out[k] = " "
            i = j
        elif text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            for k in range(i, j):
                out[k] = " "
            i = j
        elif c in "\"'":
            j = i + 1
            while j < n and text[j] != c:
                j += 2 if text[j] == "\\" else 1
            for k in range(i, min(j + 1, n)):
                if out[k] != "\n":
                    out[k] = "#"  # a line with a literal is skipped (SKIP on '#')
            i = j + 1
        else:
            i += 1
    return "".join(out)


def kernel_lines(code):
    """(line index, function name) for every line strictly inside a function body."""
    lines = code.split("\n")
    result = []
    depth = 0
    header = ""
    func = None
    for idx, line in enumerate(lines):
        inside = depth > 0 and func is not None
        if inside and not line.lstrip().startswith("#"):
            result.append((idx, func))
        for ch in line:
            if ch == "{":
                if depth == 0:
                    h = header
                    if "(" in h and "=" not in h.split("(")[0] and not re.search(r"\b(struct|enum|union)\b\s*\w*\s*$", h):
                        names = [n for n in re.findall(r"(\w+)\s*\(", h) if not n.startswith("__")]
                        func = names[0] if names else None
                    else:
                        func = None
                depth += 1
            elif ch == "}":
                depth -= 1
                if depth == 0:
                    func = None
                    header = ""
            elif ch == ";" and depth == 0:
                header = ""
            elif depth == 0:
                header += ch
        if depth == 0 and line.strip().startswith("#"):
            header = ""
        if depth == 0:
            header += " "
    # a line holding the closing brace of a function is listed but has nothing to mutate
    return result


ATOM = r"(?:[A-Za-z_]\w*(?:(?:\.|->)[A-Za-z_]\w*|\[[^\[\]]*\])*|\d[\w.]*)"
TERM = ATOM + r"(?:\s*[*/]\s*" + ATOM + r")*"
FLOAT = re.compile(r"(?<![\w.])(\d+\.\d*(?:[eE][+-]?\d+)?|\d+[eE][+-]?\d+|\.\d+(?:[eE][+-]?\d+)?)(f?)(?![\w.])")


def sites(code_line):
    """Every (operator, start, end, replacement) on one line (positions in the line)."""
    out = []
    for m in re.finditer(r"(?<=[\w\)\]]) ([+-]) (?=[\w(.])", code_line):
        out.append(("sign", m.start(1), m.end(1), "-" if m.group(1) == "+" else "+"))
    for m in re.finditer(r" ([+-])= ", code_line):
        out.append(("sign", m.start(1), m.end(1), "-" if m.group(1) == "+" else "+"))
    for m in re.finditer(r"(?<=[\w\)\]]) (<=|>=|<|>) (?=[\w(\-.!])", code_line):
        op = m.group(1)
        out.append(("bound", m.start(1), m.end(1), {"<": "<=", "<=": "<", ">": ">=", ">=": ">"}[op]))
    for m in re.finditer(r"\[([0-3])\]", code_line):
        d = int(m.group(1))
        out.append(("channel", m.start(1), m.end(1), str({0: 1, 1: 2, 2: 0, 3: 2}[d])))
    for m in re.finditer(r"\+ ([0-3])\]", code_line):
        d = int(m.group(1))
        out.append(("channel", m.start(1), m.end(1), str({0: 1, 1: 2, 2: 0, 3: 2}[d])))
    for m in re.finditer(r"(?<=[\w\)\]])\.([xyz])\b", code_line):
        out.append(("channel", m.start(1), m.end(1), {"x": "y", "y": "z", "z": "x"}[m.group(1)]))
    for m in re.finditer(r"(?<=[\w\)\]]) [+-] " + TERM + r"(?=\s*(?:[;,)]|[+-] ))", code_line):
        out.append(("drop", m.start(), m.end(), ""))
    for m in FLOAT.finditer(code_line):
        v = float(m.group(1))
        if v == 0.0 or abs(v) < 1e-3 or abs(v) > 1e6:
            continue  # epsilons and overflow guards are not model constants
        w = "%.9g" % (v * 1.1)
        if "." not in w and "e" not in w:
            w += ".0"
        out.append(("const", m.start(), m.end(), w + m.group(2)))
    return out


def candidates(effect):
    found = []
    for rel in effect_files(effect):
        text = (REPO / rel).read_text()
        code = code_only(text)
        src_lines = text.split("\n")
        code_lines = code.split("\n")
        for idx, func in kernel_lines(code):
            if NOT_KERNEL.search(func):
                continue
            cl = code_lines[idx]
            if "#" in cl or SKIP_LINE.search(cl) or not cl.strip():
                continue
            for op, a, b, rep in sites(cl):
                line = src_lines[idx]
                found.append({"op": op, "file": rel, "line": idx + 1, "func": func,
                              "before": line, "after": line[:a] + rep + line[b:]})
    return found


def generate(per_effect, seed):
    rows = []
    for effect in EFFECTS:
        rng = random.Random(f"{seed}:{effect}")
        by_op = {op: [c for c in candidates(effect) if c["op"] == op] for op in OPERATORS}
        for op in OPERATORS:
            rng.shuffle(by_op[op])
        chosen, used_lines = [], set()
        while len(chosen) < per_effect and any(by_op.values()):
            for op in OPERATORS:
                if len(chosen) >= per_effect:
                    break
                while by_op[op]:
                    c = by_op[op].pop()
                    if (c["file"], c["line"]) not in used_lines:
                        used_lines.add((c["file"], c["line"]))
                        chosen.append(c)
                        break
        chosen.sort(key=lambda c: (c["file"], c["line"]))
        for i, c in enumerate(chosen, 1):
            c["id"] = f"{effect}-{i:02d}"
            c["effect"] = effect
            rows.append(c)
    return rows


FIELDS = ["id", "effect", "op", "file", "line", "func", "before", "after"]


def write_catalogue(rows, path):
    with open(path, "w", newline="") as f:
        f.write(f"# generated by scripts/mutate.py --generate (seed {SEED}, {PER_EFFECT} per effect); "
                "docs/mutation.md gives the rules\n")
        w = csv.DictWriter(f, FIELDS, delimiter="\t", extrasaction="ignore", quoting=csv.QUOTE_NONE,
                           escapechar="\\", lineterminator="\n")
        w.writeheader()
        for r in rows:
            assert "\t" not in r["before"] and "\t" not in r["after"]
            w.writerow(r)


def read_catalogue(path=CATALOGUE):
    with open(path, newline="") as f:
        lines = [l for l in f if not l.startswith("#")]
    rows = list(csv.DictReader(lines, delimiter="\t", quoting=csv.QUOTE_NONE, escapechar="\\"))
    for r in rows:
        r["line"] = int(r["line"])
    return rows


def read_equivalent():
    notes = {}
    if EQUIVALENT.exists():
        for line in EQUIVALENT.read_text().splitlines():
            if line.strip() and not line.startswith("#"):
                k, _, v = line.partition("\t")
                notes[k.strip()] = v.strip()
    return notes


# ---------------------------------------------------------------------------- running

class Restorer:
    """Holds the original text of the one mutated file; restores it on exit, on signal, and
    at the next start from the backup copy if the process was killed outright."""

    def __init__(self, build, tree):
        self.backup_dir = build / "mutate-backup"
        self.tree = tree

    def recover(self):
        if self.backup_dir.is_dir():
            for b in self.backup_dir.iterdir():
                target = self.tree / b.name.replace("__", "/")
                shutil.copyfile(b, target)
                print(f"restored {target} from a killed run's backup", file=sys.stderr)
                b.unlink()

    def apply(self, row):
        path = self.tree / row["file"]
        text = path.read_text()
        lines = text.split("\n")
        i = row["line"] - 1
        if not (0 <= i < len(lines) and lines[i] == row["before"]):
            hits = [k for k, l in enumerate(lines) if l == row["before"]]
            if len(hits) != 1:
                return None
            i = hits[0]
        self.backup_dir.mkdir(parents=True, exist_ok=True)
        backup = self.backup_dir / row["file"].replace("/", "__")
        backup.write_text(text)
        lines[i] = row["after"]
        path.write_text("\n".join(lines))
        return (path, text, backup)

    @staticmethod
    def restore(state):
        path, text, backup = state
        path.write_text(text)
        now = time.time()
        os.utime(path, (now, now))
        backup.unlink(missing_ok=True)


def run_logged(cmd, log, timeout, env=None):
    log.write(f"$ {' '.join(map(str, cmd))}\n")
    log.flush()
    try:
        p = subprocess.run(cmd, cwd=TREE[0], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                           timeout=timeout, env=env, errors="replace")
        log.write(p.stdout)
        return p.returncode, p.stdout
    except subprocess.TimeoutExpired as e:
        out = e.stdout.decode(errors="replace") if isinstance(e.stdout, bytes) else (e.stdout or "")
        log.write(out + "\n[timeout]\n")
        return None, out


def ctest_failures(out):
    failed = re.findall(r"^\s*\d+ - (\S+) \((\w[^)]*)\)", out, re.M)
    return [f"{n} ({why})" for n, why in failed]


def build(args, log):
    rc, _ = run_logged(["cmake", "--build", str(args.build), "-j2"], log, 900)
    return rc == 0


def run_tests(args, effect, log, full=True):
    """Returns (killed_by or None). Stops at the first failing stage."""
    b = str(args.build)
    own = TESTS_OF.get(effect, [f"test_{effect}"])
    own_re = "^(" + "|".join(own) + ")$"
    rc, out = run_logged(["ctest", "--test-dir", b, "-R", own_re, "--timeout", str(args.timeout),
                          "--output-on-failure"], log, args.timeout * len(own) + 60)
    if rc != 0:
        return "; ".join(ctest_failures(out)) or ("ctest timeout" if rc is None else "ctest failed")
    env = dict(os.environ, LIBFX_CLI=str(args.build / "libfx" / "libfx"),
               LIBFX_LIBRARY=str(args.build / "libfx" / "libfx.so"))
    pyown = PYTESTS_OF.get(effect, [])
    pytest = ["/usr/bin/python3", "-m", "pytest", "-x", "-q", "-rf", "-p", "no:cacheprovider"]
    if pyown:
        rc, out = run_logged(pytest + pyown, log, 600, env)
        if rc != 0:
            return pytest_failure(out, rc)
    if not full:
        return None
    skip_re = "^(" + "|".join(own + NOT_BEHAVIOUR) + ")$"
    rc, out = run_logged(["ctest", "--test-dir", b, "-E", skip_re, "-j2", "--stop-on-failure", "--timeout",
                          str(args.timeout), "--output-on-failure"], log, 1800)
    if rc != 0:
        return "; ".join(ctest_failures(out)) or ("ctest timeout" if rc is None else "ctest failed")
    rc, out = run_logged(pytest + ["tests/python"], log, 900, env)
    if rc != 0:
        return pytest_failure(out, rc)
    return None


def pytest_failure(out, rc):
    m = re.findall(r"^FAILED (\S+)", out, re.M)
    if m:
        return "pytest " + m[0]
    m = re.findall(r"^ERROR (\S+)", out, re.M)
    if m:
        return "pytest ERROR " + m[0]
    return "pytest timeout" if rc is None else f"pytest exit {rc}"


def write_results(results, out_base, equivalent, elapsed, header=None):
    out_base.parent.mkdir(parents=True, exist_ok=True)
    cols = ["id", "effect", "op", "file", "line", "status", "killed_by", "seconds", "before", "after"]
    with open(str(out_base) + ".csv", "w", newline="") as f:
        w = csv.DictWriter(f, cols, extrasaction="ignore")
        w.writeheader()
        for r in results:
            w.writerow(dict(r, before=r["before"].strip(), after=r["after"].strip()))
    per = {}
    for r in results:
        e = per.setdefault(r["effect"], {"killed": 0, "survived": 0, "equivalent": 0, "not compiled": 0, "stale": 0})
        st = r["status"]
        if st == "survived" and r["id"] in equivalent:
            st = "equivalent"
        e[st] += 1
    md = ["# Mutation run results", "",
          header or f"Generated by `scripts/mutate.py` ({len(results)} mutations, {elapsed / 60:.1f} min).", "",
          "| effect | killed | survived | equivalent | not compiled | killed / compiled | killed / not equivalent |",
          "|---|---:|---:|---:|---:|---:|---:|"]
    tot = {"killed": 0, "survived": 0, "equivalent": 0, "not compiled": 0, "stale": 0}

    def score(e):
        compiled = e["killed"] + e["survived"] + e["equivalent"]
        live = e["killed"] + e["survived"]
        pc = f" ({100.0 * e['killed'] / compiled:.1f} %)" if compiled else ""
        pl = f" ({100.0 * e['killed'] / live:.1f} %)" if live else ""
        return f"{e['killed']}/{compiled}{pc} | {e['killed']}/{live}{pl}"
    for eff in sorted(per):
        e = per[eff]
        for k in tot:
            tot[k] += e[k]
        md.append(f"| {eff} | {e['killed']} | {e['survived']} | {e['equivalent']} | {e['not compiled']} | {score(e)} |")
    md.append(f"| **all** | {tot['killed']} | {tot['survived']} | {tot['equivalent']} | {tot['not compiled']} | "
              + " | ".join(f"**{c.strip()}**" for c in score(tot).split("|")) + " |")
    if tot["stale"]:
        md.append(f"\n{tot['stale']} mutation(s) stale: the catalogue's line is no longer in the source.")
    md += ["", "| id | op | file:line | mutation | status | killed by | s |", "|---|---|---|---|---|---|---:|"]
    for r in results:
        st = r["status"]
        if st == "survived" and r["id"] in equivalent:
            st = "equivalent: " + equivalent[r["id"]]
        mut = f"`{r['before'].strip()}` → `{r['after'].strip()}`".replace("|", "\\|")
        md.append(f"| {r['id']} | {r['op']} | {r['file'].split('/')[-1]}:{r['line']} | {mut} | "
                  f"{st.replace('|', '/')} | {r['killed_by'].replace('|', '/')} | {r['seconds']} |")
    Path(str(out_base) + ".md").write_text("\n".join(md) + "\n")


def merge_results(full_csv, rerun_csv, out_base, note):
    """A re-run's rows (mutate.py --only ... --out RERUN) in place of the same ids of a full
    run's results: the score over the whole catalogue with the tests added since."""
    def rows_of(path):
        with open(path, newline="") as f:
            return list(csv.DictReader(f))
    full, rerun = rows_of(full_csv), rows_of(rerun_csv)
    by_id = {r["id"]: r for r in rerun}
    merged = [by_id.pop(r["id"], r) for r in full] + list(by_id.values())
    header = note or (f"Merged by `scripts/mutate.py --merge`: {len(full)} rows of {full_csv.name}, "
                      f"{len(rerun)} of them replaced by {rerun_csv.name}.")
    write_results(merged, out_base, read_equivalent(), 0.0, header)
    print(f"{len(merged)} rows ({len(rerun)} from {rerun_csv}) written to {out_base}.md/.csv")
    return 0


def snapshot(tree):
    """Copies the committed HEAD into TREE (a file whose bytes are unchanged keeps its time, so
    the build stays incremental): the run never touches the working tree, and editing tests
    while it runs cannot change what it measures."""
    tree.mkdir(parents=True, exist_ok=True)
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO, stdout=subprocess.PIPE, text=True,
                          check=True).stdout.strip()
    data = subprocess.run(["git", "archive", "--format=tar", "HEAD"], cwd=REPO, stdout=subprocess.PIPE,
                          check=True).stdout
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        for m in tar.getmembers():
            if not m.isfile():
                continue
            dest = tree / m.name
            blob = tar.extractfile(m).read()
            if dest.exists() and dest.read_bytes() == blob:
                continue
            dest.parent.mkdir(parents=True, exist_ok=True)
            dest.write_bytes(blob)
            os.chmod(dest, m.mode)
    return head


def configure(args):
    if not (args.build / "CMakeCache.txt").exists():
        subprocess.run(["cmake", "-B", str(args.build), "-S", str(args.tree), "-DCMAKE_BUILD_TYPE=Release",
                        "-DLIBFX_BUILD_BENCH=OFF", f"-DLIBFX_CORPUS_DIR={REPO.parent / 'shared' / 'exr-corpus'}"],
                       cwd=args.tree, check=True, stdout=subprocess.DEVNULL)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--generate", action="store_true", help="write the catalogue from the rules and exit")
    ap.add_argument("--list", action="store_true", help="print the (filtered) catalogue and exit")
    ap.add_argument("--effects", help="comma-separated effects to run (default: all)")
    ap.add_argument("--only", action="append", default=[], help="run only this id (repeatable, or a,b)")
    ap.add_argument("--limit", type=int, help="run at most this many mutations")
    ap.add_argument("--build", type=Path, default=REPO / "build-mut", help="build folder (default build-mut)")
    ap.add_argument("--tree", type=Path, default=REPO / "out" / "mutation" / "tree",
                    help="where the snapshot of HEAD is mutated (default out/mutation/tree; no 'build' in "
                         "its path: test_native_loading orders candidate paths by it)")
    ap.add_argument("--out", type=Path, default=REPO / "out" / "mutation" / "results",
                    help="results base path: writes BASE.csv and BASE.md (default out/mutation/results)")
    ap.add_argument("--timeout", type=int, default=90, help="seconds per test (default 90; the slowest test takes about 12 s alone)")
    ap.add_argument("--quick", action="store_true", help="only the effect's own tests (not the counted run)")
    ap.add_argument("--no-baseline", action="store_true", help="skip the unmutated build's test run")
    ap.add_argument("--merge", nargs=2, type=Path, metavar=("FULL_CSV", "RERUN_CSV"),
                    help="no run: RERUN_CSV's rows replace FULL_CSV's rows of the same ids; writes --out's .csv "
                         "and .md (with the current equivalents)")
    ap.add_argument("--note", help="with --merge: the .md's first line (say which rows come from which run)")
    args = ap.parse_args()
    args.build = args.build.resolve()
    args.out = args.out.resolve()

    if args.merge:
        return merge_results(args.merge[0], args.merge[1], args.out, args.note)
    if args.generate:
        rows = generate(PER_EFFECT, SEED)
        write_catalogue(rows, CATALOGUE)
        print(f"{len(rows)} mutations written to {CATALOGUE.relative_to(REPO)}")
        return 0
    rows = read_catalogue()
    if args.effects:
        want = set(args.effects.split(","))
        unknown = want - set(EFFECTS)
        if unknown:
            ap.error(f"unknown effects: {', '.join(sorted(unknown))}")
        rows = [r for r in rows if r["effect"] in want]
    only = {i for o in args.only for i in o.split(",") if i}
    if only:
        missing = only - {r["id"] for r in rows}
        if missing:
            ap.error(f"unknown ids: {', '.join(sorted(missing))}")
        rows = [r for r in rows if r["id"] in only]
    if args.limit:
        rows = rows[: args.limit]
    if args.list:
        for r in rows:
            print(f"{r['id']:22} {r['op']:8} {r['file']}:{r['line']} ({r['func']})\n"
                  f"    - {r['before'].strip()}\n    + {r['after'].strip()}")
        print(f"{len(rows)} mutations")
        return 0

    args.tree = args.tree.resolve()
    TREE[0] = args.tree
    restorer = Restorer(args.build, args.tree)
    restorer.recover()
    head = snapshot(args.tree)
    print(f"tree: {args.tree} at HEAD {head[:12]} (committed state; uncommitted edits do not count)", flush=True)
    configure(args)

    def on_term(signum, frame):
        raise KeyboardInterrupt
    signal.signal(signal.SIGTERM, on_term)

    logdir = args.build / "mutate-logs"
    logdir.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    if not args.no_baseline:
        with open(logdir / "baseline.log", "w") as log:
            if not build(args, log):
                print("baseline build fails; see " + str(logdir / "baseline.log"), file=sys.stderr)
                return 2
            why = run_tests(args, rows[0]["effect"] if rows else "bloom", log, full=True)
            if why:
                print(f"baseline tests fail ({why}); see {logdir / 'baseline.log'}", file=sys.stderr)
                return 2
        print(f"baseline: build and tests pass ({time.time() - t0:.0f} s)", flush=True)

    equivalent = read_equivalent()
    results = []
    try:
        for n, row in enumerate(rows, 1):
            t = time.time()
            res = dict(row, status="", killed_by="")
            with open(logdir / f"{row['id']}.log", "w") as log:
                state = restorer.apply(row)
                if state is None:
                    res["status"] = "stale"
                else:
                    try:
                        if not build(args, log):
                            res["status"] = "not compiled"
                        else:
                            why = run_tests(args, row["effect"], log, full=not args.quick)
                            res["status"] = "killed" if why else "survived"
                            res["killed_by"] = why or ""
                    finally:
                        restorer.restore(state)
            res["seconds"] = f"{time.time() - t:.0f}"
            results.append(res)
            print(f"[{n}/{len(rows)}] {row['id']:22} {res['status']:12} {res['killed_by'][:70]} "
                  f"({res['seconds']} s)", flush=True)
            write_results(results, args.out, equivalent, time.time() - t0)
    except KeyboardInterrupt:
        print("interrupted: the source is restored; partial results written", file=sys.stderr)
    finally:
        with open(logdir / "final-build.log", "w") as log:
            build(args, log)  # leave the build folder matching the sources
    write_results(results, args.out, equivalent, time.time() - t0)
    killed = sum(r["status"] == "killed" for r in results)
    counted = sum(r["status"] in ("killed", "survived") for r in results)
    print(f"killed {killed}/{counted} ({time.time() - t0:.0f} s); results in {args.out}.md/.csv")
    return 0


if __name__ == "__main__":
    sys.exit(main())
