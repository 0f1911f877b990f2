#!/usr/bin/python3
"""bench_live_change: what one live change costs Blender's main thread (the add-on's side,
not the library's run), per scene, in a headless session (not a timed test).

    /usr/bin/python3 tests/bench/bench_live_change.py [--blender host|unstable] [--runs 30]
        [--scenes greek_bath,atrium,mirror_room] [--resolution 320x180] [--fresh] [--busy]
        [--out out/bench_live_change]

For each scene it renders frame 1 through the batch runner at --resolution (kept passes;
reused when present), holds it live, then changes each effect's first numeric parameter
--runs times: back and forth around its value, or with --fresh a new value each time;
with --busy the next change comes while the worker still runs the last one (a drag).
Per change it measures, on the main thread:

- **update**: the property's update callbacks (pass sync + scheduling the live run);
- **kick**: the debounced timer that builds the interactive job;
- **settle**: the timer that builds the final job;
- how many times the recipe was built and how many library stacks were made for it
  (the worker's own stack for the run is not counted).

Prints a Markdown table of medians (ms) and the counts per change.
"""
import argparse
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENES = ["greek_bath", "atrium", "mirror_room"]
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_live import blender_cmd, render_if_missing  # noqa: E402  one copy of each

SCRIPT = r'''
import bpy, json, sys, threading, time
A = json.loads(sys.argv[sys.argv.index("--") + 1])
sys.path.insert(0, A["addon"])
import libfx
libfx.register()
from libfx import handlers, live, props, recipe, native
handlers.on_load_post()
scene = bpy.context.scene
scene.render.filepath = A["prefix"]
scene.frame_set(1)
side = json.load(open(A["sidecar"]))
live.start(scene, 1, A["passes"], side)
live.flush()
count = {"recipe": 0, "stack": 0}
_to_recipe = recipe.to_recipe
def counted_to_recipe(*a, **k):
    count["recipe"] += 1
    return _to_recipe(*a, **k)
recipe.to_recipe = counted_to_recipe
_stack_init = native.Stack.__init__
def counted_stack_init(self, *a, **k):
    if threading.current_thread() is threading.main_thread():
        count["stack"] += 1
    return _stack_init(self, *a, **k)
native.Stack.__init__ = counted_stack_init
def med(v):
    v = sorted(v); return v[len(v) // 2] if v else float("nan")
cat = props.catalog()
rows = []
for it in scene.libfx.stack:
    if not it.enabled:
        continue
    eff = cat.effects.get(it.effect)
    group = props.effect_group(it)
    knob = next((p for p in eff.params if p.type in ("float", "int") and p.soft_max > p.soft_min), None)
    if knob is None:
        continue
    base = getattr(group, knob.prop)
    tu, tk, ts, nr, ns = [], [], [], [], []
    for r in range(A["runs"]):
        if A["fresh"]:   # a drag: every value new (no answer of the library is reused)
            step = (knob.soft_max - knob.soft_min) * 0.001 * (r + 1)
        else:            # back and forth around the value, as bench_live.py changes it
            step = (knob.soft_max - knob.soft_min) * 0.01 * (1 if r % 2 == 0 else -1)
        v = max(knob.min, min(knob.max, base + step))
        if knob.type == "int":
            v = int(base) + (r + 1 if A["fresh"] else (1 if step > 0 else -1))
            v = max(int(knob.min), min(int(knob.max), v))
        count["recipe"] = count["stack"] = 0
        t0 = time.perf_counter()
        setattr(group, knob.prop, v)
        t1 = time.perf_counter()
        live._kick()
        t2 = time.perf_counter()
        live._state["last_change"] = 0.0
        live._settle()
        t3 = time.perf_counter()
        nr.append(count["recipe"]); ns.append(count["stack"])
        tu.append((t1 - t0) * 1e3); tk.append((t2 - t1) * 1e3); ts.append((t3 - t2) * 1e3)
        if not A["busy"]:
            live.WORKER.wait_idle(120)
            live.flush()
    live.WORKER.wait_idle(120)
    live.flush()
    rows.append({"change": "%s.%s" % (it.effect, knob.name), "update_ms": med(tu), "kick_ms": med(tk),
                 "settle_ms": med(ts), "recipes": med(nr), "stacks": med(ns),
                 "update_max_ms": max(tu)})
print("RESULT " + json.dumps(rows))
'''


def run_scene(a, scene):
    d = os.path.join(a.out, "renders", "%s_%s" % (scene, a.resolution))
    render_if_missing(scene, d, a.blender, a.resolution, samples=2)
    args = {"addon": os.path.join(ROOT, "addon"), "prefix": os.path.join(a.out, scene + "_"),
            "passes": os.path.join(d, "r_libfx_passes.0001.exr"),
            "sidecar": os.path.join(d, "r_libfx.0001.camera.json"), "runs": a.runs, "busy": a.busy,
            "fresh": a.fresh}
    cmd = blender_cmd(a.blender) + ["-b", os.path.join(ROOT, "blend_scenes", scene, scene + ".blend"),
                                    "--python-expr", SCRIPT, "--", json.dumps(args)]
    p = subprocess.run(cmd, capture_output=True, text=True,
                       env=dict(os.environ, PYTHONDONTWRITEBYTECODE="1"))
    line = next((l for l in p.stdout.splitlines() if l.startswith("RESULT ")), None)
    if line is None:
        sys.stderr.write(p.stdout[-3000:] + p.stderr[-3000:])
        sys.exit("bench_live_change: %s failed" % scene)
    return json.loads(line[7:])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=30)
    ap.add_argument("--blender", default="host")
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--resolution", default="320x180")
    ap.add_argument("--fresh", action="store_true",
                    help="every change sets a new value (default: back and forth around it)")
    ap.add_argument("--busy", action="store_true",
                    help="the next change comes while the worker still runs the last one (a drag)")
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "bench_live_change"))
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    print("| scene | change | update ms | update max ms | kick ms | settle ms | recipes built | library stacks (main thread) |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for scene in a.scenes.split(","):
        for r in run_scene(a, scene):
            print("| %s | %s | %.2f | %.2f | %.2f | %.2f | %d | %d |" % (
                scene, r["change"], r["update_ms"], r["update_max_ms"], r["kick_ms"], r["settle_ms"],
                r["recipes"], r["stacks"]))
        sys.stdout.flush()


if __name__ == "__main__":
    main()
