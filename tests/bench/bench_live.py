#!/usr/bin/python3
"""bench_live: how long an artist waits in the add-on's live loop (issue 13), measured in a
headless Blender session driven by a script (not a timed test).

    /usr/bin/python3 tests/bench/bench_live.py [--renders DIR] [--runs 5] [--blender host|unstable]
        [--scenes greek_bath,atrium,mirror_room] [--out out/bench_live]

For each scene it needs a 1920x1080 batch render with kept passes: DIR/<scene>_1920x1080/
r_libfx_passes.0001.exr and r_libfx.0001.camera.json (default DIR: OUT/renders; missing
ones are rendered here through the add-on's batch runner, 4 samples, with the add-on's
default passes codec, NONE, so the read is the one F12 meets).
In one Blender session per scene:

- **held**: `live.start()` reads the passes into memory and shows the final result
  (read + stack + pixels into the "libfx Result" image);
- **after render**: what F12 adds after Blender's File Output node has written the passes:
  `pipeline.process_frame(hold, show)`: read, stack, result pixels into the image
  (the result EXR is written after that, on the worker, and is listed apart);
- per effect of the stack, a change of its first look parameter: from setting the property
  (the update callback, the debounced run) to the updated image, at the interactive
  setting (1/2 proxy + draft, and 1/4 + draft) and at final; each the median of --runs
  changes (each to a value not set before: +-5 %, +-10 %, ... of the soft range); plus the
  interactive image's error against the final one (MAE, PSNR over RGB).

Writes OUT/bench_live.csv and prints a Markdown table.
"""
import argparse
import csv
import json
import os
import statistics
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENES = ["greek_bath", "atrium", "mirror_room"]

SCRIPT = r'''
import bpy, json, sys, time, math
import numpy as np
A = json.loads(sys.argv[sys.argv.index("--") + 1])
sys.path.insert(0, A["addon"])
import libfx
libfx.register()
from libfx import handlers, live, pipeline, props, sidecars, ui_queue
handlers.on_load_post()   # the .blend was read before the add-on registered: its recipe text
scene = bpy.context.scene
scene.render.filepath = A["prefix"]
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 1920, 1080, 100
scene.frame_set(1)
side = json.load(open(A["sidecar"]))
rows = []
def med(v):
    v = sorted(v); return v[len(v) // 2] if v else float("nan")
def img():
    im = bpy.data.images[live.RESULT_IMAGE]; a = np.empty(im.size[0] * im.size[1] * 4, np.float32)
    im.pixels.foreach_get(a); return a.reshape(-1, 4)[:, :3]
def box4(a):
    h, w = 1080 // 4, 1920 // 4
    return a.reshape(1080, 1920, 3)[:h * 4, :w * 4].reshape(h, 4, w, 4, 3).mean(axis=(1, 3))
def err(a, b):
    a = np.clip(a, 0.0, 1.0); b = np.clip(b, 0.0, 1.0)   # display range: the sun's 1e3 would rule
    mae = float(np.abs(a - b).mean()); mse = float(((a - b) ** 2).mean())
    # at 1/4 scale, where the render's noise (which a proxy averages away) is gone
    mae4 = float(np.abs(box4(a) - box4(b)).mean())
    return mae, (99.0 if mse == 0 else 10 * math.log10(1.0 / mse)), mae4
# held: load + final
t = []
for r in range(A["runs"]):
    live.drop()
    t0 = time.perf_counter(); live.start(scene, 1, A["passes"], side); live.flush()
    t.append((time.perf_counter() - t0) * 1e3)
rows.append({"what": "load passes + final + image", "effect": "stack", "ms": med(t)})
# after render: process_frame as F12 calls it (hold, show), the write apart
sidecars.store(scene.name, 1, side)
scene.libfx.keep_passes = True
tr, tw = [], []
for r in range(A["runs"]):
    live.drop()
    t0 = time.perf_counter()
    rec = pipeline.process_frame(scene, 1, passes_file=A["passes"], sidecar=side, hold=True, show=True,
                                 defer_write=True)
    ui_queue.drain()
    t1 = time.perf_counter()
    live.WORKER.wait_idle(120)
    t2 = time.perf_counter()
    assert rec["ok"], rec
    tr.append((t1 - t0) * 1e3); tw.append((t2 - t1) * 1e3)
rows.append({"what": "after render: read + stack + image", "effect": "stack", "ms": med(tr)})
rows.append({"what": "after render: result EXR written (worker)", "effect": "stack", "ms": med(tw)})
live.drop(); live.start(scene, 1, A["passes"], side); live.flush()
final0 = img()
s = scene.libfx
cat = props.catalog()
for setting in A["settings"]:
    s.live_setting = setting
    live.flush()
    for i, it in enumerate(s.stack):
        if not it.enabled:
            continue
        eff = cat.effects.get(it.effect)
        group = props.effect_group(it)
        # the first look parameter: numeric, and not a knob the presets set
        knob = next((p for p in eff.params if p.type in ("float", "int") and p.soft_max > p.soft_min
                     and all(eff.preset_value(q, p.name) is None for q in cat.qualities)), None)
        if knob is None:
            continue
        base = getattr(group, knob.prop)
        ti, tf, errs, parts = [], [], [], []
        for r in range(A["runs"]):
            # a value not seen before at every change, as a drag makes them (a value met
            # again can hit a cache keyed by it: vsm_shadows' filtered light map)
            step = (knob.soft_max - knob.soft_min) * 0.05 * (1 + r // 2) * (1 if r % 2 == 0 else -1)
            v = base + step
            v = max(knob.min, min(knob.max, v))
            if knob.type == "int":
                v = int(round(v)) if int(round(v)) != int(base) else int(base) + (1 if step > 0 else -1)
            t0 = time.perf_counter()
            setattr(group, knob.prop, v)
            applied = live.flush()
            inter = [a for a in applied if a["job"].kind == "interactive" and "applied_at" in a]
            fin = [a for a in applied if a["job"].kind == "final" and "applied_at" in a]
            if inter:
                ti.append((inter[0]["applied_at"] - t0) * 1e3)
                ipx = inter[0]["pixels"].reshape(-1, 4)[:, :3]
                m = inter[0]["ms"]
                parts.append((m["proxy"], m["stack"], m["pixels"], (inter[0]["applied_at"] - t0) * 1e3 - m["total"]))
            if fin:
                tf.append((fin[0]["applied_at"] - fin[0]["job"].created) * 1e3)
                if inter:
                    errs.append(err(ipx, img()))
            setattr(group, knob.prop, base)
            live.flush()
        row = {"what": "change %s.%s" % (it.effect, knob.name), "effect": it.effect, "setting": setting,
               "interactive_ms": med(ti), "final_ms": med(tf)}
        if parts:
            row["parts"] = "proxy %.1f, stack %.1f, pixels %.1f, Blender side %.1f" % tuple(
                med([p[k] for p in parts]) for k in range(4))
        if errs:
            row["mae"] = med([e[0] for e in errs]); row["psnr_db"] = med([e[1] for e in errs])
            row["mae_quarter"] = med([e[2] for e in errs])
        rows.append(row)
print("RESULT " + json.dumps(rows))
'''


def blender_cmd(which):
    if which == "host":
        return ["blender"]
    # the root's own libfx build (build-<suite>, scripts/blender_matrix.sh) unless told
    lib = os.environ.get("LIBFX_LIBRARY_" + which.upper(),
                         os.path.join(ROOT, "build-" + which, "libfx", "libfx.so"))
    return ["bash", os.path.join(ROOT, "scripts", "in_root.sh"), which, "env", "LIBFX_LIBRARY=" + lib,
            "PYTHONDONTWRITEBYTECODE=1", "blender"]


def render_if_missing(scene, d, which, resolution="1920x1080", samples=4):
    """Frame 1 of a demo scene through the add-on's batch path into d (r_ prefix), with its
    passes file kept, unless d holds it already. Also used by bench_live_change.py."""
    passes = os.path.join(d, "r_libfx_passes.0001.exr")
    if os.path.exists(passes):
        return
    os.makedirs(d, exist_ok=True)
    cmd = blender_cmd(which) + ["-b", os.path.join(ROOT, "blend_scenes", scene, scene + ".blend"),
                                "--python", os.path.join(ROOT, "addon", "libfx", "batch.py"), "--",
                                "--keep-passes", "--passes-codec", "NONE", "--frames", "1",
                                "--output", os.path.join(d, "r_"),
                                "--resolution", resolution, "--samples", str(samples)]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--renders", default=None, help="default: OUT/renders")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--blender", default="host")
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--settings", default="AUTO,HALF_DRAFT,QUARTER_DRAFT")
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "bench_live"))
    a = ap.parse_args()
    a.renders = a.renders or os.path.join(a.out, "renders")
    os.makedirs(a.out, exist_ok=True)
    all_rows = []
    for scene in a.scenes.split(","):
        d = os.path.join(a.renders, scene + "_1920x1080")
        render_if_missing(scene, d, a.blender)
        args = {"addon": os.path.join(ROOT, "addon"), "prefix": os.path.join(a.out, scene + "_"),
                "passes": os.path.join(d, "r_libfx_passes.0001.exr"),
                "sidecar": os.path.join(d, "r_libfx.0001.camera.json"), "runs": a.runs,
                "settings": a.settings.split(",")}
        cmd = blender_cmd(a.blender) + ["-b", os.path.join(ROOT, "blend_scenes", scene, scene + ".blend"),
                                        "--python-expr", SCRIPT, "--", json.dumps(args)]
        p = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ, PYTHONDONTWRITEBYTECODE="1"))
        line = next((l for l in p.stdout.splitlines() if l.startswith("RESULT ")), None)
        if line is None:
            sys.stderr.write(p.stdout[-3000:] + p.stderr[-3000:])
            sys.exit("bench_live: %s failed" % scene)
        for r in json.loads(line[7:]):
            r["scene"] = scene
            all_rows.append(r)
    keys = ["scene", "what", "effect", "setting", "ms", "interactive_ms", "final_ms", "mae", "psnr_db", "mae_quarter", "parts"]
    with open(os.path.join(a.out, "bench_live.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        for r in all_rows:
            w.writerow({k: r.get(k, "") for k in keys})
    fmt = lambda v: "" if v in (None, "") else ("%.1f" % v if isinstance(v, float) else str(v))
    print("| scene | what | setting | ms | interactive ms | final ms | MAE | PSNR dB | MAE at 1/4 | interactive: where the time goes (ms) |")
    print("|---|---|---|---:|---:|---:|---:|---:|---:|---|")
    for r in all_rows:
        print("| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s |" % (
            r["scene"], r["what"], r.get("setting", ""), fmt(r.get("ms")), fmt(r.get("interactive_ms")),
            fmt(r.get("final_ms")), ("%.4f" % r["mae"]) if "mae" in r else "", fmt(r.get("psnr_db")),
            ("%.4f" % r["mae_quarter"]) if "mae_quarter" in r else "", r.get("parts", "")))


if __name__ == "__main__":
    main()
