"""The frame pipeline: a rendered frame's passes file -> the scene's stack -> the result
files (EXR, the image in the scene's format, the sidecar, the recipe) and the frame's
result record.

- ``after_render`` is render_post's work: the passes file from the Render Result
  (passes_file.py), then ``process_frame``.
- ``process_frame`` takes everything from Blender's data on the calling thread (paths,
  recipe, sidecar, settings), then reads, runs and writes, here or on the worker
  (worker.py): F12 shows the result from memory (live.py holds the frame for live re-runs)
  while the worker writes the files; a batch render (``-b``) does it all on the main thread.
- Every call into the library is made under the shared context's lock (shared_context.py).
"""

import json
import os
import time

import bpy

from . import live, native, passes_file, recipe, results, scene_setup, shared_context, sidecars, ui_queue
from .log import log
from .worker import WORKER


def process_frame(scene, frame, recipe_dict=None, passes_file=None, sidecar=None, fps=None,
                  hold=False, show=False, defer_write=False, in_background=False):
    """Runs the scene's stack on the passes file of a frame and writes the results.

    hold: keep the decoded passes in memory for live re-runs (live.py). show: put the result
    into the "libfx Result" image from memory (UI). defer_write: write the result files on
    the live worker after this returns (F12: the render job ends and the image shows while
    the EXR is written). in_background: all of it on the worker (an operator: Blender's UI
    thread never waits for a read, a stack or a write).
    Returns the result record ({"pending": True} until the worker is done); raises nothing."""
    # Everything taken from Blender's data here, on the calling thread.
    if not native.has("live"):   # an older library: the files only (the panel says why)
        hold = show = False
    job = {
        "scene": scene.name, "frame": frame, "threads": scene.libfx.threads,
        "paths": scene_setup.result_paths(scene, frame),
        "passes_file": passes_file or scene_setup.passes_path(scene, frame),
        "layer": scene_setup.passes_layer(scene),
        "recipe": recipe_dict or recipe.to_recipe(scene),
        "sidecar": sidecars.sidecar_for(scene, frame, sidecar),
        "fps": fps or scene.render.fps / (scene.render.fps_base or 1.0),
        "keep_passes": scene.libfx.keep_passes, "writes_image": scene_setup.writes_image(scene),
        "hold": hold, "show": show,
    }
    job["proxy_factor"] = live.proxy_factor_of(scene) if hold else None
    if in_background:
        WORKER.submit_task(lambda: _run_and_write(job))
        return {"ok": True, "pending": True, "frame": frame, "paths": job["paths"]}
    done = _run(job)
    if not done["ok"]:
        return done
    if defer_write:
        WORKER.submit_task(lambda: _write(job, done))
        return {"ok": True, "pending": True, "frame": frame, "paths": job["paths"],
                "timings": done["timings"]}
    return _write(job, done)


def _run_and_write(job):
    done = _run(job)
    return _write(job, done) if done["ok"] else done


def _run(job):
    """Any thread: reads the passes, runs the stack; holds and shows as asked."""
    frame, paths, passes_file = job["frame"], job["paths"], job["passes_file"]
    try:
        if not os.path.exists(passes_file):
            raise native.LibfxError("the passes file %s is missing (removed, or never written: "
                                    "render the frame again)" % passes_file)
        t0 = time.perf_counter()
        with shared_context.lock():   # one thread at a time per context (F12's render thread, batch's main)
            ctx = shared_context.get(job["threads"])
            ctx.warnings()   # drop what an earlier frame left
            stack = native.Stack(ctx, job["recipe"])
            try:
                # held: every pass, so that any later stack can run on it
                fin = native.Frame.read(ctx, passes_file, None if job["hold"] else stack, layer=job["layer"])
                if job["sidecar"] is not None:
                    fin.apply_sidecar(job["sidecar"])
                fin.set_time(frame, job["fps"])
                if job["hold"]:
                    fout = stack.run(fin)
                    fout.copy_passes_from(fin)   # shared with the held frame, not copied
                    live.hold(job["scene"], frame, fin, passes_file if job["keep_passes"] else None,
                              job["sidecar"], job["proxy_factor"])
                else:
                    fout = stack.run_consume(fin, keep_passes=True)   # the passes go along, not copied
                timings = stack.timings()
                if job["show"]:
                    live.show_after_render(job["scene"], frame, fout, timings)
                warnings = ctx.warnings()
            finally:
                stack.close()
        return {"ok": True, "fout": fout, "timings": timings, "warnings": warnings, "t0": t0,
                "t_run": time.perf_counter()}
    except native.LibfxError as e:
        return results.record_named(job["scene"], frame, error=str(e), paths=paths)
    except Exception as e:  # never let a handler die silently
        return results.record_named(job["scene"], frame, error="%s: %s" % (type(e).__name__, e), paths=paths)


def _write(job, done):
    """Any thread: the result files, the record; the passes file goes unless kept."""
    frame, paths, passes_file, scene_name = job["frame"], job["paths"], job["passes_file"], job["scene"]
    timings, warnings, fout = done["timings"], done["warnings"], done["fout"]
    try:
        with shared_context.lock():
            try:
                os.makedirs(os.path.dirname(paths["exr"]) or ".", exist_ok=True)
                fout.write_exr(paths["exr"], input_path=passes_file)
            finally:
                fout.close()
        if job["sidecar"] is not None:
            _write_json(paths["sidecar"], job["sidecar"])
        _write_json(paths["recipe"], job["recipe"])
        if not job["keep_passes"]:
            _remove_quietly(passes_file)   # the result holds every pass it had
        total = (time.perf_counter() - done["t0"]) * 1000.0
        log("frame %d: %s (%.1f ms in all, %.1f ms to the result) -> %s" % (
            frame, ", ".join("%s %.1f ms" % (t.get("effect"), t.get("ms", 0.0))
                             for t in timings if t.get("enabled", True)) or "no effect",
            total, (done["t_run"] - done["t0"]) * 1000.0, paths["exr"]))
        for w in warnings:
            log("frame %d: warning: %s" % (frame, w), err=True)
        rec = results.record_named(scene_name, frame, paths=paths, timings=timings, warnings=warnings,
                            passes_file=passes_file)
        if job["writes_image"] and not bpy.app.background:
            exr, image = paths["exr"], paths["image"]
            ui_queue.to_ui(lambda: _ui_save_image(scene_name, exr, image))
        return rec
    except native.LibfxError as e:
        return results.record_named(scene_name, frame, error=str(e), paths=paths)
    except Exception as e:
        return results.record_named(scene_name, frame, error="%s: %s" % (type(e).__name__, e), paths=paths)


def _remove_quietly(path):
    try:
        os.unlink(path)
    except OSError as e:
        log("cannot remove %s: %s" % (path, e.strerror or e), err=True)


def _write_json(path, obj):
    tmp = path + ".tmp"
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(obj, f, indent=2)
        f.write("\n")
    os.replace(tmp, path)


SAVE_IMAGE = ".libfx save"   # hidden: the one image datablock save_image reuses


def _image_showing(name, path):
    """The image datablock `name`, loaded from `path` the first time, then pointed at
    `path` and reloaded."""
    img = bpy.data.images.get(name)
    if img is None:
        img = bpy.data.images.load(path, check_existing=False)
        img.name = name
    else:
        img.filepath = path
        img.reload()
    return img


def save_image(scene, exr_path, image_path):
    """The result in the scene's output format, through Blender's colour management.
    Main thread only. One datablock is reloaded for every frame and removed when the
    render completes: 5.2 crashes on the next frame of `-a` when an image is removed
    inside render_post."""
    img = _image_showing(SAVE_IMAGE, exr_path)
    # atomic like libfx's own EXR writer: a temp file beside the target, then a rename,
    # so a killed render never leaves a partial image under the final name
    folder, name = os.path.split(image_path)
    tmp = os.path.join(folder, ".%s.tmp-%d%s" % (name, os.getpid(), os.path.splitext(name)[1]))
    try:
        img.save_render(tmp, scene=scene)
        os.replace(tmp, image_path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def remove_save_image():
    img = bpy.data.images.get(SAVE_IMAGE)
    if img is not None:
        bpy.data.images.remove(img)


def after_render(scene, frame, ui):
    """render_post's work: the passes file from the Render Result, then the stack.
    ui (F12 / UI animation render): the result shows from memory (held for live re-runs
    when live is on) and the files are written by the live worker meanwhile; else (-b) the
    result files are written here. Returns the result record."""
    try:
        path, secs = passes_file.write(scene, frame)
        log("frame %d: passes file written in %.0f ms" % (frame, secs * 1e3))
    except native.LibfxError as e:
        return results.record(scene, frame, error=str(e))
    if ui:
        return process_frame(scene, frame, passes_file=path, hold=scene.libfx.live,
                             show=scene.libfx.show_result, defer_write=True)
    rec = process_frame(scene, frame, passes_file=path)
    if rec["ok"] and scene_setup.writes_image(scene):
        try:
            save_image(scene, rec["paths"]["exr"], rec["paths"]["image"])
        except Exception as e:
            rec = results.record(scene, frame, error="cannot save %s: %s" % (rec["paths"]["image"], e))
    return rec


def _ui_save_image(scene_name, exr, image):
    scene = bpy.data.scenes.get(scene_name)
    if scene is not None:
        try:
            save_image(scene, exr, image)
        except Exception as e:
            ui_queue.report("ERROR", "libfx: cannot save %s: %s" % (image, e))
