#!/usr/bin/python3
"""bench_after_render: from "render finished" to "result shown" (issue 13), as F12 meets it,
measured in a headless Blender session driven by a script (not a timed test).

    /usr/bin/python3 tests/bench/bench_after_render.py [--runs 3] [--blender host|trixie|unstable]
        [--scenes greek_bath,atrium,mirror_room] [--resolution 1920x1080] [--out out/bench_after_render]

Per scene, one Blender session renders frame 1 (Cycles, 1 sample: the render's own time is not
counted) --runs times with the add-on's render_post replaced by the F12 branch of it
(`pipeline.after_render(scene, frame, ui=True)`, then the UI queue drained, as the timers do in
the UI): the passes file written from the Render Result, read, the stack, the result's pixels
in the "libfx Result" image. The aux views the stack reads are rendered once before, untimed. The clock starts in a render_post handler placed before the
add-on's, i.e. when Blender has finished the render, and stops when the image holds the result.
The result EXR is written afterwards on the worker: listed apart. Renders alternate between
the add-on's default (passes not kept: the file goes to RAM, /dev/shm, when there is room) and
Keep Passes Files on (the file beside the output, on disk): both columns come from one session.

For comparison, the same session then writes the same passes through a compositor File Output
node (the add-on's route before passes_file.py): a Workbench render() of an Image node holding
the passes file, with the node minus without it (median of --runs), as
tests/bench/bench_passes_codec.py measures it.

Prints a Markdown table; writes OUT/bench_after_render.csv.
"""
import argparse
import csv
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENES = ["greek_bath", "atrium", "mirror_room"]

SCRIPT = r'''
import bpy, json, os, sys, time
A = json.loads(sys.argv[sys.argv.index("--") + 1])
sys.path.insert(0, A["addon"])
import libfx
libfx.register()
from libfx import aux_views, compat, handlers, live, passes_file, pipeline, scene_setup, sidecars, ui_queue
handlers.on_load_post()
scene = bpy.context.scene
scene.render.filepath = A["prefix"]
scene.render.resolution_x, scene.render.resolution_y = A["w"], A["h"]
scene.render.resolution_percentage = 100
scene.cycles.samples = 1
scene.cycles.use_adaptive_sampling = False
scene.cycles.use_denoising = False
scene.libfx.live = True
scene.libfx.show_result = True
if A["codec"]:
    scene.libfx.passes_codec = A["codec"]
bpy.app.handlers.render_post.remove(handlers.on_render_post)
MODES = ("ram", "kept")
T = {m: {"shown": [], "write_passes": [], "result_exr": [], "parts": []} for m in MODES}
_write = passes_file.write

def timed_write(sc, frame):
    t = time.perf_counter()
    try:
        return _write(sc, frame)
    finally:
        T[T["mode"]]["write_passes"].append((time.perf_counter() - t) * 1e3)
passes_file.write = timed_write

def stamp(sc, *a):
    T["t0"] = time.perf_counter()

def f12(sc, *a):
    if aux_views.busy():
        return
    t_w = time.perf_counter()
    rec = pipeline.after_render(sc, sc.frame_current, ui=True)
    t_pf = time.perf_counter()
    ui_queue.drain()
    t1 = time.perf_counter()
    M = T[T["mode"]]
    M["parts"].append([(t_w - T["t0"]) * 1e3, (t_pf - t_w) * 1e3, (t1 - t_pf) * 1e3])
    assert rec["ok"], rec
    assert bpy.data.images.get(live.RESULT_IMAGE) is not None
    live.WORKER.wait_idle(300)
    M["result_exr"].append((time.perf_counter() - t1) * 1e3)
    M["shown"].append((t1 - T["t0"]) * 1e3)
    T["stack"] = sum(t["ms"] for t in rec.get("timings", []))

# the aux views the stack reads (light view, rain map, probes), rendered once beforehand as
# a batch or the panel's button does; not timed
sidecars.set_aux(scene.name, scene.frame_current, aux_views.prepare(scene, [scene.frame_current]))
bpy.app.handlers.render_post.insert(0, stamp)
bpy.app.handlers.render_post.append(f12)
for r in range(A["runs"]):
    for mode in MODES:   # the kept one last: the File Output comparison reads its file
        T["mode"] = mode
        scene.libfx.keep_passes = mode == "kept"
        live.drop()
        bpy.ops.render.render()
passes = scene_setup.passes_path(scene, scene.frame_current)
nchan = None
try:
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(passes)
    nchan = 0
    sub = 0
    while inp.seek_subimage(sub, 0):
        nchan += inp.spec().nchannels
        sub += 1
    inp.close()
except Exception:
    pass
bpy.app.handlers.render_post.remove(stamp)
bpy.app.handlers.render_post.remove(f12)

# the route before: the same passes through a File Output node
fo_scene = bpy.data.scenes.new("fo bench")
fo_scene.render.resolution_x, fo_scene.render.resolution_y = A["w"], A["h"]
fo_scene.render.resolution_percentage = 100
fo_scene.render.engine = "BLENDER_WORKBENCH"
tree, made = compat.ensure_compositor_tree(fo_scene, "fo bench")
img = bpy.data.images.load(passes)
def build(with_node):
    for n in list(tree.nodes):
        if n.bl_idname != "NodeGroupOutput":
            tree.nodes.remove(n)
    node = tree.nodes.new("CompositorNodeImage"); node.image = img
    outs = [o for o in node.outputs if o.enabled and o.name != "Alpha"]
    if with_node:
        fo = tree.nodes.new("CompositorNodeOutputFile")
        compat.file_output_format(fo, codec="NONE")
        compat.file_output_set_prefix(fo, A["prefix"] + "fo_")
        compat.file_output_link(tree, fo, [(o.name, o) for o in outs])
def med_render():
    bpy.ops.render.render(scene=fo_scene.name)
    t = []
    for _ in range(A["runs"]):
        t0 = time.perf_counter(); bpy.ops.render.render(scene=fo_scene.name); t.append((time.perf_counter() - t0) * 1e3)
    return sorted(t)[len(t) // 2]
build(False); base = med_render()
build(True); with_fo = med_render()
T["file_output"] = max(with_fo - base, 0.0)
T["channels"] = nchan
print("RESULT " + json.dumps(T))
'''


def blender_cmd(which):
    if which == "host":
        return ["blender"]
    lib = os.environ.get("LIBFX_LIBRARY_" + which.upper(),
                         os.path.join(ROOT, "build-" + which, "libfx", "libfx.so"))
    return ["bash", os.path.join(ROOT, "scripts", "in_root.sh"), which, "env", "HOME=/tmp",
            "LIBFX_LIBRARY=" + lib, "PYTHONDONTWRITEBYTECODE=1", "blender"]


def med(v):
    v = sorted(v)
    return v[len(v) // 2] if v else float("nan")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--blender", default="host")
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--resolution", default="1920x1080")
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "bench_after_render"))
    ap.add_argument("--verbose", action="store_true", help="print the add-on's log lines")
    ap.add_argument("--codec", default="", help="the Passes Codec (default: the add-on's)")
    a = ap.parse_args()
    w, h = (int(v) for v in a.resolution.split("x"))
    out = os.path.abspath(a.out)
    os.makedirs(out, exist_ok=True)
    rows = []
    for scene in a.scenes.split(","):
        args = {"addon": os.path.join(ROOT, "addon"), "prefix": os.path.join(out, scene + "_"),
                "runs": a.runs, "w": w, "h": h, "codec": a.codec}
        cmd = blender_cmd(a.blender) + ["-b", os.path.join(ROOT, "blend_scenes", scene, scene + ".blend"),
                                        "--python-expr", SCRIPT, "--", json.dumps(args)]
        p = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ, PYTHONDONTWRITEBYTECODE="1"))
        line = next((l for l in p.stdout.splitlines() if l.startswith("RESULT ")), None)
        if line is None:
            sys.stderr.write(p.stdout[-3000:] + p.stderr[-3000:])
            sys.exit("bench_after_render: %s failed" % scene)
        t = json.loads(line[7:])
        if a.verbose:
            sys.stderr.write("".join(l + "\n" for l in (p.stdout + p.stderr).splitlines() if l.startswith(("libfx", "live", "Assert"))))
        for mode in ("ram", "kept"):
            m = t[mode]
            print("%s, %s: shown %s ms; parts %s" % (scene, mode, ", ".join("%.0f" % v for v in m["shown"]),
                                                     m["parts"]), file=sys.stderr)
            rows.append({"scene": scene, "passes": mode, "channels": t.get("channels"), "shown_ms": med(m["shown"]),
                         "passes_write_ms": med(m["write_passes"]), "stack_ms": t.get("stack"),
                         "result_exr_ms": med(m["result_exr"]), "file_output_ms": t["file_output"],
                         "runs": len(m["shown"])})
    keys = ["scene", "passes", "channels", "shown_ms", "passes_write_ms", "stack_ms", "result_exr_ms",
            "file_output_ms", "runs"]
    with open(os.path.join(out, "bench_after_render.csv"), "w", newline="") as f:
        wr = csv.DictWriter(f, fieldnames=keys)
        wr.writeheader()
        wr.writerows(rows)
    print("| scene | passes file | channels | render finished to result shown ms | of which: passes file written | "
          "stack (effects) | shown minus stack | result EXR after (worker) | File Output node, same passes (the route before) |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print("| %s | %s | %s | %.0f | %.0f | %.0f | %.0f | %.0f | %.0f |" % (
            r["scene"], {"ram": "not kept (RAM)", "kept": "kept (disk)"}[r["passes"]], r["channels"],
            r["shown_ms"], r["passes_write_ms"], r["stack_ms"] or 0,
            r["shown_ms"] - (r["stack_ms"] or 0), r["result_exr_ms"], r["file_output_ms"]))
    print("\n%dx%d, %s Blender, median of %d renders" % (w, h, a.blender, a.runs))


if __name__ == "__main__":
    main()
