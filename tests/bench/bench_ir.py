#!/usr/bin/python3
"""Instructions per effect, two builds side by side: a load-independent speed check.

This VM's wall times vary 2x between runs minutes apart, so a claim such as "no effect
got more than 3% slower" cannot rest on them alone. Valgrind's callgrind counts the
instructions of the stack run (fx_stack_run_consume and what it calls: no file read or
write), one thread, for every effect of the three scenes' recipes (with the scene's
parameters) and for the other effects at their defaults on the Greek bath (--others: a
render keeping every pass, as bench_all.py makes), at `final`.

    /usr/bin/python3 tests/bench/bench_ir.py OLD_CLI NEW_CLI [--renders DIR] [--only a,b]
                                             [--quality final] [-o out.csv]

DIR holds <scene>_<W>x<H>/r_libfx_passes.0001.exr, r_libfx.0001.camera.json and
r_libfx_recipe.json as tests/bench/bench_live.py renders them (default
out/bench_live/renders, 1920x1080). Prints a Markdown table: instructions of each build
and new/old."""
import argparse
import csv
import json
import os
import pathlib
import re
import subprocess
import sys
import tempfile

SCENES = ("greek_bath", "atrium", "mirror_room")
# effects no scene recipe uses: their defaults, on the Greek bath
OTHERS = ("gaussian_blur", "bloom", "edges", "cel_shading", "color_matrix", "posterize", "sin_city")


def cases(renders, others, only):
    """(label, scene dir, recipe effects) for each effect of each scene, then the others."""
    out = []
    for scene in SCENES:
        d = next(iter(sorted(pathlib.Path(renders).glob(scene + "_1920x1080"))), None)
        if d is None:
            sys.exit("bench_ir: no %s_1920x1080 under %s (render it with tests/bench/bench_live.py)"
                     % (scene, renders))
        effects = json.loads((d / "r_libfx_recipe.json").read_text())["effects"]
        names = []
        for e in effects:
            if e.get("enabled", True) and e["effect"] not in names:
                names.append(e["effect"])
        for n in names:  # every entry of one effect together (the mirror room's ten)
            out.append(("%s (%s)" % (n, scene), d, [e for e in effects if e["effect"] == n
                                                   and e.get("enabled", True)]))
    for n in OTHERS:
        out.append(("%s (defaults, greek_bath)" % n, pathlib.Path(others), [{"effect": n}]))
    return [c for c in out if not only or c[2][0]["effect"] in only]


def sidecar_option(cli):
    """--sidecar, or --camera for builds from before that name (the alias stays)."""
    r = subprocess.run([cli, "help", "run"], capture_output=True, text=True)
    return "--sidecar" if "--sidecar" in r.stdout + r.stderr else "--camera"


def instructions(cli, scene_dir, effects, quality, tmp):
    recipe = pathlib.Path(tmp) / "recipe.json"
    recipe.write_text(json.dumps({"version": 1, "quality": quality, "effects": effects}))
    outfile = pathlib.Path(tmp) / "callgrind.out"
    cmd = ["valgrind", "--tool=callgrind", "--callgrind-out-file=%s" % outfile,
           "--collect-atstart=no", "--toggle-collect=fx_stack_run_consume",
           cli, "run", "-j", "1", "--quiet", "--force", "--compression", "none",
           sidecar_option(cli), str(scene_dir / "r_libfx.0001.camera.json"), "--stack", str(recipe),
           str(scene_dir / "r_libfx_passes.0001.exr"), "-o", str(pathlib.Path(tmp) / "o.exr")]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit("bench_ir: %s failed:\n%s" % (" ".join(cmd), r.stderr[-2000:]))
    m = re.search(r"^(?:summary|totals):\s*(\d+)", outfile.read_text(), re.M)
    if not m:
        sys.exit("bench_ir: no instruction total in %s" % outfile)
    return int(m.group(1))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("old_cli")
    ap.add_argument("new_cli")
    ap.add_argument("--renders", default="out/bench_live/renders")
    ap.add_argument("--others", default="out/r1080/renders/greek_bath_1920x1080",
                    help="the Greek bath with every pass (cel_shading reads light passes)")
    ap.add_argument("--only", default="", help="effect names, comma-separated")
    ap.add_argument("--quality", default="final")
    ap.add_argument("-o", "--out", help="CSV of the rows")
    a = ap.parse_args()
    only = set(filter(None, a.only.split(",")))
    rows = []
    with tempfile.TemporaryDirectory(dir="/dev/shm" if os.access("/dev/shm", os.W_OK) else None) as tmp:
        for label, d, effects in cases(a.renders, a.others, only):
            old = instructions(a.old_cli, d, effects, a.quality, tmp)
            new = instructions(a.new_cli, d, effects, a.quality, tmp)
            rows.append((label, old, new, new / old if old else float("nan")))
            print("bench_ir: %-40s %14d %14d %.4f" % rows[-1], file=sys.stderr)
    print("| effect (scene) | old instructions | new instructions | new/old |")
    print("|---|---:|---:|---:|")
    for label, old, new, ratio in rows:
        print("| %s | %.1fM | %.1fM | %.3f |" % (label, old / 1e6, new / 1e6, ratio))
    if a.out:
        with open(a.out, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["effect", "old_ir", "new_ir", "ratio"])
            w.writerows(rows)
    worst = max(rows, key=lambda r: r[3])
    print("\nworst: %s at %.3f of the old count" % (worst[0], worst[3]))


if __name__ == "__main__":
    main()
