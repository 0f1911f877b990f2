"""Render handlers: the scene sidecar per frame, the passes file, running the stack after a render.

Order (GUIDE §3): ``-b -f/-a``: render_init, then per frame frame_change_post ->
render_pre -> render_post -> render_write, render_complete; all on the main
thread.  F12: no render_write and the handlers run on the render thread, so
anything touching UI data (images, editors, reports) goes through
bpy.app.timers.  A handler's exception does not change Blender's exit code:
results are recorded in RESULTS and batch.py turns failures into an exit code.
"""

import json
import os
import sys
import threading
import time

import bpy
from bpy.app.handlers import persistent

from . import aux_views, native, passes_file, recipe, scene_setup

RESULT_IMAGE = "libfx Result"

_lock = threading.Lock()
SIDECARS = {}    # (scene name, frame) -> the frame's scene sidecar (camera, lights, time)
AUX = {}         # (scene name, frame) -> aux view sidecar entries (aux_views.prepare)
RESULTS = {}     # (scene name, frame) -> {"ok": bool, "error": str, "paths": {...}, "timings": [...]}
_ui_queue = []   # callables (or (callable, tries so far)) to run on the main thread (F12)


def log(msg, err=False):
    stream = sys.stderr if err else sys.stdout
    print("libfx: " + msg, file=stream)
    stream.flush()


# ---------------------------------------------------------------- the scene sidecar

def lights_list(scene, depsgraph):
    """The scene's rendered lights for the sidecar: position, travel direction (-Z of
    the light's matrix), colour, energy; effects find a light by name."""
    out = []
    for ob in scene.objects:
        if ob.type != "LIGHT" or ob.hide_render:
            continue
        ev = ob.evaluated_get(depsgraph) if depsgraph is not None else ob
        mw = ev.matrix_world
        d = -mw.col[2].xyz
        if d.length > 0:
            d.normalize()
        data = ev.data
        light = {"name": ob.name, "type": data.type, "position": list(mw.translation),
                 "direction": list(d), "color": list(data.color), "energy": float(data.energy)}
        if data.type == "SUN":
            light["angle"] = float(data.angle)
        out.append(light)
    return out


def frame_sidecar(scene, depsgraph):
    """The frame's scene sidecar: camera (matrices as rows), lights and time (the aux views
    are added by sidecar_for). None without a scene camera."""
    cam = scene.camera
    if cam is None:
        return None
    ev = cam.evaluated_get(depsgraph) if depsgraph is not None else cam
    r = scene.render
    x = int(r.resolution_x * r.resolution_percentage / 100)
    y = int(r.resolution_y * r.resolution_percentage / 100)
    proj = ev.calc_matrix_camera(depsgraph, x=x, y=y, scale_x=r.pixel_aspect_x,
                                 scale_y=r.pixel_aspect_y)
    w2c = ev.matrix_world.inverted()
    data = ev.data
    return {
        "world_to_camera": [list(row) for row in w2c],
        "projection": [list(row) for row in proj],
        "clip_start": float(getattr(data, "clip_start", 0.1)),
        "clip_end": float(getattr(data, "clip_end", 1000.0)),
        "orthographic": getattr(data, "type", "PERSP") == "ORTHO",
        "lights": lights_list(scene, depsgraph),
        "frame": scene.frame_current,
        "fps": r.fps / (r.fps_base or 1.0),
    }


@persistent
def on_frame_change_post(scene, depsgraph=None):
    if aux_views.BUSY["on"]:
        return  # a depth render of an auxiliary view
    if not scene_setup.has_stack(scene):
        return
    try:
        sidecar = frame_sidecar(scene, depsgraph)
    except Exception as e:  # a light as camera, no depsgraph...
        log("frame %d: camera matrices unavailable: %s" % (scene.frame_current, e), err=True)
        return
    if sidecar is not None:
        with _lock:
            SIDECARS[(scene.name, scene.frame_current)] = sidecar
    from . import live
    try:
        live.on_frame_change(scene)   # scrubbing a held sequence (a no-op in batch renders)
    except Exception as e:
        log("live: frame %d: %s" % (scene.frame_current, e), err=True)


# ---------------------------------------------------------------- render

@persistent
def on_render_init(scene, *args):
    if aux_views.BUSY["on"]:
        return  # a depth render of an auxiliary view
    if not scene_setup.has_stack(scene):
        scene_setup.remove_nodes(scene)
        return
    if native.load() is None:
        _record(scene, scene.frame_current, error=native.load_error())
        return
    problem = scene_setup.scene_problem(scene)
    if problem:
        _record(scene, scene.frame_current, error=problem)
        return
    req = scene_setup.sync(scene)
    st = scene_setup.status(scene)
    if req is None:
        _record(scene, scene.frame_current, error="stack cannot run: %s" % st.get("error"))
        return
    if bpy.app.background:   # the UI's are gone at load (on_load_post), off the render thread
        scene_setup.remove_nodes(scene)   # the File Output node of add-ons before passes_file.py
    for w in st.get("warnings", []):
        log("warning: " + w, err=True)
    if scene.camera is not None and (scene.name, scene.frame_current) not in SIDECARS:
        # F12 of the current frame: the evaluated camera of the current frame.
        try:
            dg = bpy.context.evaluated_depsgraph_get()
            with _lock:
                SIDECARS[(scene.name, scene.frame_current)] = frame_sidecar(scene, dg)
        except Exception:
            pass


def _record(scene, frame, error=None, **kw):
    return _record_named(scene.name, frame, error=error, **kw)


def _record_named(scene_name, frame, error=None, **kw):
    """Any thread: the frame's result record (batch turns failures into an exit code);
    an error is also reported in the UI."""
    rec = {"ok": error is None, "error": error, "frame": frame}
    rec.update(kw)
    with _lock:
        RESULTS[(scene_name, frame)] = rec
    if error:
        log("frame %d: %s" % (frame, error), err=True)
        if not bpy.app.background:
            _to_ui(lambda: _ui_report("ERROR", "libfx: frame %d: %s" % (frame, error)))
    return rec


_ctx_lock = threading.Lock()
_CTX = {"ctx": None, "threads": None}


def _context(threads):
    """One libfx context kept across frames: its aux-view cache (core/aux_view.h) lets
    frames 2..N reuse the light view's and rain map's built maps. Call with _ctx_lock."""
    c = _CTX["ctx"]
    if c is None or _CTX["threads"] != threads or c._L is not native.lib():
        if _CTX["ctx"] is not None:
            _CTX["ctx"].close()
        _CTX["ctx"], _CTX["threads"] = native.Context(threads), threads
    return _CTX["ctx"]


def free_context():
    with _ctx_lock:
        if _CTX["ctx"] is not None:
            _CTX["ctx"].close()
        _CTX["ctx"] = _CTX["threads"] = None


def ctx_lock():
    """The lock around every call into the shared context (render thread, live worker)."""
    return _ctx_lock


def shared_context(threads):
    """The context frames are read and run with; call with ctx_lock() held."""
    return _context(threads)


def sidecar_for(scene, frame, sidecar=None):
    """The scene sidecar of a frame: its camera (from frame_change_post), lights, time and
    the aux views rendered for it. None when the frame's camera is unknown."""
    if sidecar is None:
        with _lock:
            sidecar = SIDECARS.get((scene.name, frame))
    with _lock:
        aux = AUX.get((scene.name, frame))
    if aux is None and sidecar is not None:
        try:
            aux = aux_views.from_disk(scene)
        except Exception as e:
            log("frame %d: aux views: %s" % (frame, e), err=True)
    if aux and sidecar is not None:
        sidecar = dict(sidecar, aux_views=aux)
    return sidecar


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
        "sidecar": sidecar_for(scene, frame, sidecar),
        "fps": fps or scene.render.fps / (scene.render.fps_base or 1.0),
        "keep_passes": scene.libfx.keep_passes, "writes_image": scene_setup.writes_image(scene),
        "hold": hold, "show": show,
    }
    from . import live
    job["proxy_factor"] = live.proxy_factor_of(scene) if hold else None
    if in_background:
        live.WORKER.submit_task(lambda: _run_and_write(job))
        return {"ok": True, "pending": True, "frame": frame, "paths": job["paths"]}
    done = _run(job)
    if not done["ok"]:
        return done
    if defer_write:
        live.WORKER.submit_task(lambda: _write(job, done))
        return {"ok": True, "pending": True, "frame": frame, "paths": job["paths"],
                "timings": done["timings"]}
    return _write(job, done)


def _run_and_write(job):
    done = _run(job)
    return _write(job, done) if done["ok"] else done


def _run(job):
    """Any thread: reads the passes, runs the stack; holds and shows as asked."""
    from . import live
    frame, paths, passes_file = job["frame"], job["paths"], job["passes_file"]
    try:
        if not os.path.exists(passes_file):
            raise native.LibfxError("the passes file %s is missing (removed, or never written: "
                                    "render the frame again)" % passes_file)
        t0 = time.perf_counter()
        with _ctx_lock:   # one thread at a time per context (F12's render thread, batch's main)
            ctx = _context(job["threads"])
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
        return _record_named(job["scene"], frame, error=str(e), paths=paths)
    except Exception as e:  # never let a handler die silently
        return _record_named(job["scene"], frame, error="%s: %s" % (type(e).__name__, e), paths=paths)


def _write(job, done):
    """Any thread: the result files, the record; the passes file goes unless kept."""
    frame, paths, passes_file, scene_name = job["frame"], job["paths"], job["passes_file"], job["scene"]
    timings, warnings, fout = done["timings"], done["warnings"], done["fout"]
    try:
        with _ctx_lock:
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
        rec = _record_named(scene_name, frame, paths=paths, timings=timings, warnings=warnings,
                            passes_file=passes_file)
        if job["writes_image"] and not bpy.app.background:
            exr, image = paths["exr"], paths["image"]
            _to_ui(lambda: _ui_save_image(scene_name, exr, image))
        return rec
    except native.LibfxError as e:
        return _record_named(scene_name, frame, error=str(e), paths=paths)
    except Exception as e:
        return _record_named(scene_name, frame, error="%s: %s" % (type(e).__name__, e), paths=paths)


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


def _remove_save_image():
    img = bpy.data.images.get(SAVE_IMAGE)
    if img is not None:
        bpy.data.images.remove(img)


@persistent
def on_render_done(*args):
    """render_complete / render_cancel: the save datablock goes (in the UI on the main
    thread, after the queued saves)."""
    if bpy.app.background:
        _remove_save_image()
    else:
        _to_ui(_remove_save_image)


@persistent
def on_render_post(scene, *args):
    if aux_views.BUSY["on"]:
        return  # a depth render of an auxiliary view
    if not scene_setup.has_stack(scene):
        return
    after_render(scene, scene.frame_current, ui=not bpy.app.background)


def after_render(scene, frame, ui):
    """render_post's work: the passes file from the Render Result, then the stack.
    ui (F12 / UI animation render): the result shows from memory (held for live re-runs
    when live is on) and the files are written by the live worker meanwhile; else (-b) the
    result files are written here. Returns the result record."""
    try:
        path, secs = passes_file.write(scene, frame)
        log("frame %d: passes file written in %.0f ms" % (frame, secs * 1e3))
    except native.LibfxError as e:
        return _record(scene, frame, error=str(e))
    if ui:
        return process_frame(scene, frame, passes_file=path, hold=scene.libfx.live,
                             show=scene.libfx.show_result, defer_write=True)
    rec = process_frame(scene, frame, passes_file=path)
    if rec["ok"] and scene_setup.writes_image(scene):
        try:
            save_image(scene, rec["paths"]["exr"], rec["paths"]["image"])
        except Exception as e:
            rec = _record(scene, frame, error="cannot save %s: %s" % (rec["paths"]["image"], e))
    return rec


@persistent
def on_load_post(*args):
    from . import live
    live.drop()   # frames held for the scenes of the file that was open
    for scene in bpy.data.scenes:
        if getattr(scene, "libfx", None) is None:
            continue
        try:
            if recipe.load_text_block(scene):
                log("imported the recipe of scene '%s' from the text '%s'" % (scene.name, recipe.TEXT_NAME))
        except Exception as e:
            scene_setup.STATUS.setdefault(scene.name, {})["error"] = "recipe text: %s" % e
            log("scene '%s': recipe text %s: %s" % (scene.name, recipe.TEXT_NAME, e), err=True)
        migrate_parameters(scene)
        scene_setup.remove_nodes(scene)   # the File Output node of add-ons before passes_file.py


def migrate_parameters(scene):
    """Effect parameters saved with an older parameter table are migrated by the library
    and written back (recipe.migrate_stack); the panel and the log say so."""
    try:
        notes = recipe.migrate_stack(scene)
    except Exception as e:  # never let a file load fail on it
        notes = ["parameter migration failed: %s: %s" % (type(e).__name__, e)]
    scene_setup.STATUS.setdefault(scene.name, {})["migrated"] = notes
    for note in notes:
        log("scene '%s': warning: %s" % (scene.name, note), err=True)


# ---------------------------------------------------------------- UI side (main thread)

def to_ui(fn):
    """Runs fn on the main thread when Blender allows data changes (after the render job)."""
    _to_ui(fn)


def _to_ui(fn):
    with _lock:
        _ui_queue.append(fn)
    try:
        if not bpy.app.timers.is_registered(_drain_ui):
            bpy.app.timers.register(_drain_ui, first_interval=UI_FIRST_S)
    except Exception:
        pass


#: The UI queue is first looked at this soon (F12's result waits for it: the timer is what
#: stands between the stack's end and the image), then every UI_RETRY_S while the render
#: job still runs or Blender refuses the update ("not allowed in this context"; the
#: refusal can outlast the render job by a moment, seen on 4.3), at most UI_RETRIES times
#: (5 s). Each pass costs the main thread one function call.
UI_FIRST_S = 0.005
UI_RETRY_S = 0.02
UI_RETRIES = 250


def _drain_ui():
    # While the render job runs Blender refuses writes to data-blocks (an image's
    # name, a reload): try again when it has finished.
    if bpy.app.is_job_running("RENDER"):
        return UI_RETRY_S
    with _lock:
        todo = list(_ui_queue)
        _ui_queue.clear()
    again = []
    for item in todo:
        fn, tries = item if isinstance(item, tuple) else (item, 0)
        try:
            fn()
        except Exception as e:
            if "not allowed" in str(e) and tries < UI_RETRIES:
                again.append((fn, tries + 1))
            else:
                log("UI update failed: %s" % e, err=True)
    if again:
        with _lock:
            _ui_queue[:0] = again
        return UI_RETRY_S
    return None


def _ui_report(kind, message):
    wm = bpy.context.window_manager
    win = wm.windows[0] if wm and wm.windows else None
    if win is None:
        return
    with bpy.context.temp_override(window=win):
        bpy.ops.libfx.report("INVOKE_DEFAULT", kind=kind, message=message)


def _ui_save_image(scene_name, exr, image):
    scene = bpy.data.scenes.get(scene_name)
    if scene is not None:
        try:
            save_image(scene, exr, image)
        except Exception as e:
            _ui_report("ERROR", "libfx: cannot save %s: %s" % (image, e))


@persistent
def on_undo_redo(*args):
    """Undo/redo puts values back without update callbacks: re-run live sessions."""
    from . import live
    for scene in bpy.data.scenes:
        if getattr(scene, "libfx", None) is not None:
            live.changed(scene)


HANDLERS = (("frame_change_post", on_frame_change_post),
            ("render_init", on_render_init),
            ("render_post", on_render_post),
            ("render_complete", on_render_done),
            ("render_cancel", on_render_done),
            ("load_post", on_load_post),
            ("undo_post", on_undo_redo),
            ("redo_post", on_undo_redo))


def register():
    unregister()  # a reload must never leave two copies
    for name, fn in HANDLERS:
        getattr(bpy.app.handlers, name).append(fn)


def unregister():
    """Removes only our handlers, also those of an older copy of this module (reload)."""
    from . import live
    live.unregister()
    free_context()
    for name, fn in HANDLERS:
        lst = getattr(bpy.app.handlers, name)
        for h in list(lst):
            if h is fn or (getattr(h, "__module__", "") == fn.__module__ and
                           getattr(h, "__name__", "") == fn.__name__):
                lst.remove(h)
