"""Drives the add-on's live loop in `blender -b` (tests/blender/test_live.py).

    blender -b scene.blend --python-expr PRELUDE --python live_session.py -- PREFIX OUT.json

PREFIX is a batch render's output prefix with kept passes (frame 1, and frame 2 for the
file-change check). Headless Blender runs no timers, so the script calls live.flush(),
which does what the timers would. It writes what it saw to OUT.json; the test asserts.
"""
import json
import os
import shutil
import sys
import time

import bpy
import numpy as np

import libfx
from libfx import live, recipe

prefix, out_path = sys.argv[sys.argv.index("--") + 1:][:2]
libfx.render.on_load_post()   # the .blend was read before the add-on registered: its recipe text
scene = bpy.context.scene
scene.render.filepath = prefix
scene.frame_set(1)
res = {}


def image():
    img = bpy.data.images[live.RESULT_IMAGE]
    w, h = img.size
    a = np.empty(w * h * 4, dtype=np.float32)
    img.pixels.foreach_get(a)
    return a.reshape(h, w, 4)[::-1]   # top row first, as in the EXR


def save(name, a):
    np.save(os.path.join(os.path.dirname(out_path), name + ".npy"), a)


def entry(effect):
    s = scene.libfx
    for i, it in enumerate(s.stack):
        if it.effect == effect:
            return i, it
    raise KeyError(effect)


with open(prefix + "libfx.0001.camera.json") as f:
    sidecar = json.load(f)
passes1 = prefix + "libfx_passes.0001.exr"

# 1. Load the kept passes: the image shows the final result, as the batch wrote it.
live.start(scene, 1, passes1, sidecar)
applied = live.flush()
res["start"] = [a["job"].kind for a in applied]
res["start_image_ok"] = live.RESULT_IMAGE in bpy.data.images
img0 = image()
save("start", img0)
res["shown_after_start"] = dict(live.session(scene).shown, timings=None)

# 2. A parameter change runs the interactive setting, then final.
i, it = entry("pixelate")
t0 = time.perf_counter()
it.fx_pixelate.cell_size = it.fx_pixelate.cell_size + 6
applied = live.flush()
res["change_ms"] = (time.perf_counter() - t0) * 1e3
res["change"] = [{"kind": a["job"].kind, "factor": a["job"].factor, "quality": a["job"].quality,
                  "ms": a.get("ms"), "error": a.get("error")} for a in applied]
inter = [a for a in applied if a["job"].kind == "interactive"]
if inter:
    save("interactive", inter[0]["pixels"].reshape(img0.shape)[::-1])
img1 = image()
save("final", img1)
res["shown_after_change"] = dict(live.session(scene).shown, timings=None)
with open(os.path.join(os.path.dirname(out_path), "changed_recipe.json"), "w") as f:
    json.dump(recipe.to_recipe(scene), f)

# 2b. A drag: a change that comes while an interactive run is in progress does not cancel
# it (it shows, then the newest runs); one that comes during a final run cancels that. The
# context lock, held here, keeps the first job in the worker's hands until the second is in.
def overlapped(first_kind):
    with libfx.render.ctx_lock():
        first = live._make_job(scene, first_kind)
        live.WORKER.submit(first)
        end = time.monotonic() + 30
        while live.WORKER.running is not first and time.monotonic() < end:
            time.sleep(0.001)
        second = live._make_job(scene, "interactive")
        live.WORKER.submit(second)
    live.WORKER.wait_idle(120)
    with live.WORKER.cv:
        outs, live.WORKER.results = live.WORKER.results, []
    return [o["job"].generation - first.generation for o in outs if "pixels" in o]


res["drag_interactive"] = overlapped("interactive")
res["drag_final"] = overlapped("final")

# 2c. Auto Draft's proxy factor: over budget at 1/2 goes to 1/4; back to 1/2 only when a
# quarter run leaves room for a half one (about four times as long) inside the budget.
res["auto"] = [live.next_auto_factor(2, live.AUTO_UP_MS + 1), live.next_auto_factor(2, live.AUTO_UP_MS - 1),
               live.next_auto_factor(4, live.AUTO_UP_MS / 4 - 0.5), live.next_auto_factor(4, live.AUTO_UP_MS / 8)]

# 3. An invalid value keeps the last image and says why.
g, gr = entry("god_rays")
gr.fx_god_rays.light = "NoSuchLight"
applied = live.flush()
res["invalid"] = [{"kind": a["job"].kind, "error": a.get("error")} for a in applied]
res["invalid_panel_error"] = live.session(scene).error
res["invalid_image_same"] = bool(np.array_equal(image(), img1))
gr.fx_god_rays.light = "Sun"
applied = live.flush()
res["repaired"] = [{"kind": a["job"].kind, "error": a.get("error")} for a in applied]
res["repaired_image_same"] = bool(np.array_equal(image(), img1))
res["repaired_panel_error"] = live.session(scene).error

# 4. Before / split views and solo.
scene.libfx.live_view = "BEFORE"
live.flush()
save("before", image())
scene.libfx.live_view = "SPLIT"
scene.libfx.live_split = 0.5
live.flush()
save("split", image())
scene.libfx.live_view = "RESULT"
scene.libfx.active_index = i
scene.libfx.live_solo = True
live.flush()
save("solo", image())
scene.libfx.live_solo = False
live.flush()
# Inspect: debug passes on, one of them shown, then the result again
scene.libfx.live_debug = True
live.flush()
res["debug_passes"] = list(live.session(scene).debug_passes)
if res["debug_passes"]:
    scene.libfx.live_debug_pass = res["debug_passes"][0]
    live.flush()
    save("debug", image())
scene.libfx.live_debug = False
live.flush()
res["debug_off_same"] = bool(np.array_equal(image(), img1))

# 5. Scrubbing: frame 2's kept passes are read and shown; back on frame 1, the held one.
scene.frame_set(2)
applied = live.flush()
res["scrub"] = [{"kind": a["job"].kind, "frame": a.get("frame"), "error": a.get("error")} for a in applied]
save("frame2", image())
scene.frame_set(1)
applied = live.flush()
res["scrub_back"] = [{"kind": a["job"].kind, "frame": a.get("frame"), "load": a["job"].load is not None}
                     for a in applied]
res["scrub_back_same"] = bool(np.array_equal(image(), img1))

# 6. The passes file changes on disk (a re-render): noticed and read again.
shutil.copyfile(prefix + "libfx_passes.0002.exr", passes1 + ".tmp")
os.replace(passes1 + ".tmp", passes1)
live.refresh_if_stale(scene)
live.flush()
save("after_file_change", image())
# deleted: the held frame stays, with a message
os.unlink(passes1)
live.refresh_if_stale(scene)
res["deleted_panel_error"] = live.session(scene).error

res["ok"] = True
with open(out_path, "w") as f:
    json.dump(res, f, indent=1, default=str)
print("LIVE SESSION DONE")
