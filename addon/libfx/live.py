"""Live look-dev: the rendered frame's passes stay in memory and the stack re-runs on
every change, straight into the "libfx Result" image (no disk round trip).

- A **session** per scene (sessions.py, the model) holds the decoded passes of one rendered frame (a libfx frame,
  kept after F12 or read from a passes file) and, lazily, its 1/2 and 1/4 proxies.
- A change to the stack (parameter, mask, order, enabled flag, quality) calls
  ``changed(scene)``.  It is debounced through ``bpy.app.timers``: the stack first runs
  at the *interactive setting* (draft preset and/or a proxy, ``settings.live_setting``),
  and once no change has come for ``SETTLE_S`` at the stack's own quality, full size.
- One worker thread (worker.py) runs the library (ctypes releases the GIL), so Blender's UI thread
  never waits for more than a pixel copy.  A newer change replaces a run still waiting
  and cancels a final run in progress between effects (the library's progress callback);
  an interactive run in progress finishes and shows, so that a drag keeps updating.  A
  recipe the library refuses leaves the last good image and puts the message in the panel.
- Sequences: with kept passes files, a frame change loads that frame's passes (a few
  frames are cached) and shows its result.

Nothing here is needed for batch renders; ``flush()`` lets headless tests and the
benchmark drive the loop without an event loop.

It hears of changes through hooks ("live_changed", "view_changed"; the handlers call
``changed`` for "stack_changed") and tells the UI through hooks ("status_changed",
"result_shown", "result_replaced"): it redraws no editor itself.
"""

import os
import threading
import time

import bpy

from . import hooks, native, recipe, scene_setup, sessions, shared_context, sidecars, ui_queue
from .log import log as _log
from .log import trace
from .sessions import SETTINGS
from .worker import WORKER

RESULT_IMAGE = "libfx Result"

DEBOUNCE_S = 0.0      # the run starts at the event loop's next timer pass: the property updates of
                      # one drag step (several) have all come by then and run once
SETTLE_S = 0.35       # no change for this long: the final run
BUDGET_MS = sessions.BUDGET_MS   # a change's interactive image within this (issue 13); AUTO keeps to it
AUTO_UP_MS = 60.0     # an interactive run (library + pixels) slower than this: a quarter next (the
                      # rest of BUDGET_MS is for Blender's side: property update, hand-off, image)
# A quarter-size run faster than this: half next. A half-size run costs up to four quarter-size
# ones, so this is a quarter of AUTO_UP_MS with room to spare (at a fixed 20 ms, a stack whose
# quarter run took 18 ms would go back to a half run over the budget, and flip at every change).
AUTO_DOWN_MS = AUTO_UP_MS / 4 * 0.7

WATCH_S = 1.0         # how often the UI looks whether a held frame's passes file changed on disk

_lock = threading.Lock()   # the buffers below
_free_buffers = []   # display-sized float32 arrays given back after the image took their pixels


def _take_buffer(n):
    """A float32 array of n values: reused, since a fresh 1080p one costs 8k page faults."""
    import numpy as np
    with _lock:
        for i, b in enumerate(_free_buffers):
            if b.size == n:
                return _free_buffers.pop(i)
    return np.empty(n, dtype=np.float32)


def _give_buffer(b):
    with _lock:
        if len(_free_buffers) < 2:
            _free_buffers.append(b)


_state = {"generation": 0, "last_change": 0.0, "pending": set(), "final_due": set()}


def log(msg):
    _log("live: " + msg)


def session(scene):
    """The scene's live session (sessions.Session), or None."""
    return sessions.get(scene.name)


def has_frame(scene, frame_no=None):
    s = session(scene)
    return s is not None and (frame_no if frame_no is not None else scene.frame_current) in s.frames


def drop(scene_name=None):
    """Frees held frames (one scene, or all): on unregister, file load."""
    gone = sessions.pop(scene_name)
    # the context lock is taken before the sessions' lock everywhere else (hold()): never inside it
    with shared_context.lock():
        for s in gone:
            s.close()


# ---------------------------------------------------------------- holding frames

def hold(scene_name, frame_no, frame, path, sidecar, proxy_factor=None):
    """Keeps a decoded frame (called with the context lock held, any thread). proxy_factor:
    build that proxy on the worker now, so that the first drag does not pay for it."""
    held = sessions.Held(frame_no, frame, path, sidecar)
    sessions.add_held(scene_name, held)
    if proxy_factor and proxy_factor > 1:
        def build():
            with shared_context.lock():
                if held.frame.ptr:   # not dropped meanwhile
                    held.proxy(proxy_factor)
        WORKER.submit_task(build)


def _read_held(ctx, scene_name, frame_no, path, sidecar, fps, proxy_factor=None, layer=None):
    """Reads a passes file into a held frame (worker thread, context lock held)."""
    fin = native.Frame.read(ctx, path, None, layer=layer)   # every pass it has: any later stack can run
    if sidecar is not None:
        fin.apply_sidecar(sidecar)
    fin.set_time(frame_no, fps)
    hold(scene_name, frame_no, fin, path, sidecar, proxy_factor)


# ---------------------------------------------------------------- jobs (run on worker.WORKER)

class _Job:
    def __init__(self, scene_name, generation, recipe_dict, kind, factor, quality, view, split,
                 debug_pass, threads, load=None):
        self.scene_name = scene_name
        self.generation = generation
        self.recipe = recipe_dict
        self.kind = kind              # "interactive" or "final"
        self.factor = factor
        self.quality = quality
        self.view = view
        self.split = split
        self.debug_pass = debug_pass
        self.threads = threads
        self.load = load              # (frame_no, path, sidecar, fps, proxy factor, layer): read this frame first
        self.created = time.perf_counter()

    def run(self, obsolete):
        """On the worker (worker.Worker): what the main thread shows, or None."""
        return _run_job(self, obsolete)


def _run_job(job, obsolete):
    """Runs one job on the worker thread; returns what the main thread shows, or None
    (cancelled)."""
    import numpy as np
    with shared_context.lock():
        ctx = shared_context.get(job.threads)
        if job.load is not None:
            frame_no, path, sidecar, fps, proxy_factor, layer = job.load
            t0 = time.perf_counter()
            try:
                _read_held(ctx, job.scene_name, frame_no, path, sidecar, fps, proxy_factor, layer)
            except native.LibfxError as e:
                return {"job": job, "error": str(e)}
            log("frame %d: passes read in %.0f ms" % (frame_no, (time.perf_counter() - t0) * 1e3))
        s = sessions.get(job.scene_name)
        held = s.held() if s is not None else None
        if held is None:
            return None
        if obsolete():
            return None
        t0 = time.perf_counter()
        stack = native.Stack(ctx)
        try:
            try:
                stack.load(job.recipe)
                if job.quality:
                    stack.set_quality(job.quality)
            except native.LibfxError as e:
                return {"job": job, "error": str(e), "refused": True}
            stack.set_debug_outputs(job.debug_pass is not None)
            src = held.proxy(job.factor)
            t_reduce = time.perf_counter()
            ctx.warnings()
            ctx.set_cancel_check(obsolete)
            try:
                fout = stack.run(src)
            except native.LibfxError as e:
                if e.code == "FX_ERR_CANCELLED":
                    return None
                return {"job": job, "error": str(e)}
            finally:
                ctx.set_cancel_check(None)
            t_run = time.perf_counter()
            try:
                w, h = held.frame.width, held.frame.height
                pixels = _take_buffer(w * h * 4)
                names = fout.pass_names()
                show = job.debug_pass if job.debug_pass in names else "Combined"
                if job.view != "RESULT" or held.before is None:
                    if held.before is None:
                        held.before = np.empty(w * h * 4, dtype=np.float32)
                        held.frame.read_pixels("Combined", w, h, held.before)
                fout.read_pixels(show, w, h, pixels)
                debug = [n for n in names if n.startswith("fx")]
                timings = stack.timings()
                warnings = ctx.warnings()
            finally:
                fout.close()
        finally:
            stack.close()
    pixels = _compose(pixels, held.before, job.view, job.split, w, h)
    t_end = time.perf_counter()
    return {"job": job, "pixels": pixels, "width": w, "height": h, "timings": timings,
            "warnings": warnings, "debug_passes": debug, "frame": held.frame_no,
            "ms": {"proxy": (t_reduce - t0) * 1e3, "stack": (t_run - t_reduce) * 1e3,
                   "pixels": (t_end - t_run) * 1e3, "total": (t_end - t0) * 1e3}}


def _compose(result, before, view, split, w, h):
    if view == "BEFORE" and before is not None:
        result[:] = before
        return result
    if view == "SPLIT" and before is not None:
        out = result.reshape(h, w, 4)
        x = max(0, min(w, int(round(split * w))))
        out[:, :x] = before.reshape(h, w, 4)[:, :x]
        if 0 < x < w:
            out[:, x] = (1.0, 1.0, 1.0, 1.0)   # the split line
        return result
    return result


# ---------------------------------------------------------------- main thread

def _settings_of(scene):
    return getattr(scene, "libfx", None)


def proxy_factor_of(scene):
    """The proxy factor of the scene's interactive setting (None: full size)."""
    s = _settings_of(scene)
    if s is None or not s.live:
        return None
    f = SETTINGS.get(s.live_setting, (None, None))[0]
    return 2 if f == "auto" else f


def active(scene):
    s = _settings_of(scene)
    return s is not None and s.live and session(scene) is not None and native.has("live")


#: scene name -> the recipe the last stack change built (handlers.stack_changed): its
#: interactive and final runs use it instead of building it again; dropped once the final
#: run is submitted, and by any change that comes without one (undo, live settings).
_RECIPES = {}


def _job_recipe(scene, solo):
    rec = _RECIPES.get(scene.name)
    if rec is None:
        rec = recipe.to_recipe(scene)
    if solo is None:
        return rec
    # solo: the active effect alone (a copy: the kept recipe stays as built)
    return dict(rec, effects=[dict(entry, enabled=(i == solo))
                              for i, entry in enumerate(rec.get("effects", []))])


def _make_job(scene, kind, load=None):
    s = _settings_of(scene)
    factor, quality = SETTINGS.get(s.live_setting, (None, None)) if kind == "interactive" else (None, None)
    if factor == "auto":
        sess = session(scene)
        factor = sess.auto_factor if sess is not None else 2
    solo = s.active_index if s.live_solo and 0 <= s.active_index < len(s.stack) else None
    rec = _job_recipe(scene, solo)
    _state["generation"] += 1
    debug = None
    if s.live_debug:   # debug outputs on; "NONE" shows the result still
        debug = s.live_debug_pass if s.live_debug_pass not in ("", "NONE") else "NONE"
    return _Job(scene.name, _state["generation"], rec, kind, factor, quality, s.live_view,
                s.live_split, debug, s.threads, load=load)


def changed(scene, rec=None):
    """A setting changed (property update, operator): re-run soon. ``rec``: the stack's
    recipe as the change left it (built once per change by handlers.stack_changed);
    None: built again when the run is made."""
    if not active(scene):
        _RECIPES.pop(scene.name, None)
        return
    trace("changed")
    if rec is None:
        _RECIPES.pop(scene.name, None)
    else:
        _RECIPES[scene.name] = rec
    _state["last_change"] = time.monotonic()
    _state["pending"].add(scene.name)
    _state["final_due"].add(scene.name)
    _register_timer(_kick, DEBOUNCE_S)
    _register_timer(_settle, SETTLE_S)


def reshow(scene):
    """Only the view (before/after, split) changed: run final again (cheap next to a drag)."""
    if not active(scene):
        return
    _state["final_due"].add(scene.name)
    _register_timer(_settle, DEBOUNCE_S)


def _register_timer(fn, interval, persistent=False):
    try:
        if not bpy.app.timers.is_registered(fn):
            bpy.app.timers.register(fn, first_interval=interval, persistent=persistent)
    except Exception:
        pass


def _kick():
    """Debounced: the interactive run of every scene that changed."""
    trace("kick")
    names, _state["pending"] = _state["pending"], set()
    for name in names:
        scene = bpy.data.scenes.get(name)
        if scene is None or not active(scene):
            continue
        s = _settings_of(scene)
        if SETTINGS.get(s.live_setting, (None, None))[0] is None:
            continue   # final only
        _submit_new(scene, "interactive")
    return None


def _settle():
    """The final run once changes stop."""
    left = SETTLE_S - (time.monotonic() - _state["last_change"])
    if left > 0.005 and _state["pending"] | _state["final_due"]:
        return left
    names, _state["final_due"] = _state["final_due"], set()
    for name in names:
        scene = bpy.data.scenes.get(name)
        if scene is not None and active(scene):
            _submit_new(scene, "final")
        _RECIPES.pop(name, None)   # this change is done with its recipe
    return None


def _submit_new(scene, kind):
    """A job for the scene's stack; a recipe the add-on cannot build (a mask's index list
    that is not numbers) goes to the panel instead, the last image stays."""
    try:
        job = _make_job(scene, kind)
    except recipe.RecipeError as e:
        s = session(scene)
        if s is not None:
            s.error = str(e)
            hooks.notify("status_changed")
        return
    _submit(job)


POLL_S = 0.005        # a finished run waits at most this for the main thread to show it


def _submit(job):
    """Main thread: hand a job to the worker and poll for its result (timers run on the
    main thread only, so the worker never touches Blender data)."""
    WORKER.submit(job)
    _register_timer(_poll, POLL_S)


def _poll():
    for out in WORKER.take_results():
        _apply(out)
    return None if WORKER.idle() and not WORKER.results else POLL_S


def next_auto_factor(factor, ms):
    """The AUTO setting's next proxy factor after an interactive run at `factor` took `ms`."""
    if factor == 2 and ms > AUTO_UP_MS:
        return 4
    if factor == 4 and ms < AUTO_DOWN_MS:
        return 2
    return factor


def _apply(out):
    job = out["job"]
    scene = bpy.data.scenes.get(job.scene_name)
    s = sessions.get(job.scene_name)
    if scene is None or s is None:
        return
    if out.get("error"):
        s.error = out["error"] + ("  (showing the last good result)" if s.shown else "")
        log("%s: %s" % (job.scene_name, out["error"]))
        hooks.notify("status_changed")
        return
    s.error = None
    s.debug_passes = out["debug_passes"]
    if job.kind == "interactive" and job.factor in (2, 4):   # AUTO: the next run inside the budget
        s.auto_factor = next_auto_factor(job.factor, out["ms"]["total"])
    show_pixels(out["pixels"], out["width"], out["height"])
    out["applied_at"] = time.perf_counter()
    trace("applied %s" % job.kind)
    if not out.get("keep_pixels"):
        _give_buffer(out.pop("pixels"))
    s.shown = {"kind": job.kind, "factor": job.factor or 1, "quality": job.quality or scene.libfx.quality,
               "frame": out["frame"], "timings": out["timings"], "ms": out["ms"],
               "warnings": out["warnings"], "time": time.time(), "generation": job.generation}
    hooks.notify("status_changed")


def result_image(w, h):
    """The "libfx Result" image as a float image of w x h (recreated when it is not one)."""
    img = bpy.data.images.get(RESULT_IMAGE)
    if img is not None and (img.source != "GENERATED" or tuple(img.size) != (w, h)
                            or not img.is_float):
        old = img
        old.name = RESULT_IMAGE + " (old)"
        img = None
    else:
        old = None
    if img is None:
        img = bpy.data.images.new(RESULT_IMAGE, w, h, alpha=True, float_buffer=True)
    # Colour-managed like the render: the scene's view transform, look, exposure.
    img.use_view_as_render = True
    if old is not None:
        hooks.notify("result_replaced", old, img)   # editors showing the old one show the new one
        bpy.data.images.remove(old)
    return img


def show_pixels(pixels, w, h):
    img = result_image(w, h)
    trace("image ready")
    img.pixels.foreach_set(pixels)
    trace("pixels set")
    img.update()
    trace("image updated")
    hooks.notify("result_shown", img)   # an Image Editor shows it (ui.py)


# ---------------------------------------------------------------- entry points

def show_after_render(scene_name, frame_no, fout, timings):
    """From process_frame (render thread, context lock held): the result's pixels now, the
    image on the main thread as soon as the render job lets it."""
    w, h = fout.width, fout.height
    pixels = _take_buffer(w * h * 4)
    fout.read_pixels("Combined", w, h, pixels)
    info = {"kind": "render", "factor": 1, "quality": None, "frame": frame_no, "timings": timings,
            "ms": {}, "warnings": [], "time": time.time(), "generation": _state["generation"]}

    def show():
        show_pixels(pixels, w, h)
        _give_buffer(pixels)
        info["shown_at"] = time.perf_counter()
        s = sessions.get(scene_name)
        if s is not None:
            s.shown = info
            s.error = None
        hooks.notify("status_changed")

    ui_queue.to_ui(show)


def start(scene, frame_no=None, path=None, sidecar=None):
    """Loads a frame's passes (from ``path``, default the scene's passes file of the frame)
    and shows its final result: "Apply to Last Render", scrubbing, file reloads."""
    if not native.has("live"):
        log(native.feature_problem("live") or "live look-dev is unavailable")
        return
    frame_no = scene.frame_current if frame_no is None else frame_no
    path = path or scene_setup.passes_path(scene, frame_no)
    if sidecar is None:
        sidecar = sidecars.sidecar_for(scene, frame_no)
    sessions.ensure(scene.name)
    fps = scene.render.fps / (scene.render.fps_base or 1.0)
    layer = scene_setup.passes_layer(scene)
    _submit(_make_job(scene, "final", load=(frame_no, path, sidecar, fps, proxy_factor_of(scene), layer)))


def refresh_if_stale(scene):
    """The held frame's passes file changed on disk (re-rendered, replaced): read it again.
    Deleted: keep what is in memory and say so. The UI calls it from a timer
    (_watch_passes_files), for the scenes its windows show."""
    s = session(scene)
    h = s.held() if s else None
    if h is None or h.path is None:
        return
    st = sessions.stat(h.path)
    if st is None:
        if h.stat is not None:
            s.error = "the passes file %s is gone: showing the frame held in memory" % h.path
            h.stat = None
            hooks.notify("status_changed")
        return
    if st != h.stat:
        log("frame %d: %s changed on disk: reading it again" % (h.frame_no, h.path))
        start(scene, h.frame_no, h.path, h.sidecar)


def on_frame_change(scene):
    """Scrubbing: show the new frame's result when its passes are held or on disk."""
    if not active(scene) or bpy.app.is_job_running("RENDER"):
        return
    s = session(scene)
    frame_no = scene.frame_current
    if frame_no in s.frames:
        s.current = frame_no
        s.frames.move_to_end(frame_no)
        _state["final_due"].add(scene.name)
        _register_timer(_settle, DEBOUNCE_S)
        return
    path = scene_setup.passes_path(scene, frame_no)
    if os.path.exists(path):
        start(scene, frame_no, path)


def flush(timeout=60.0):
    """Runs what the timers would (headless tests, the benchmark): pending interactive runs,
    then the final one, each applied to the image. Returns the results applied."""
    applied = []

    def drain():   # the pixels stay with the results for the caller
        WORKER.wait_idle(timeout)
        res = WORKER.take_results()
        for out in res:
            out["keep_pixels"] = True
            _apply(out)
        applied.extend(res)

    if _state["pending"]:
        _kick()
        drain()
    drain()
    if _state["final_due"]:
        _state["last_change"] = 0.0
        _settle()
        drain()
    return applied


def _watch_passes_files():
    """Timer (UI sessions only): for the scenes the windows show with Live Update on, a held
    frame's passes file that changed on disk is read again and one that is gone is said so
    in the panel (refresh_if_stale). Never from a panel's draw()."""
    try:
        wm = bpy.context.window_manager
        seen = set()
        for win in (wm.windows if wm else []):
            scene = win.scene
            if scene is None or scene.name in seen:
                continue
            seen.add(scene.name)
            s = _settings_of(scene)
            if s is not None and s.live:
                refresh_if_stale(scene)
    except Exception as e:   # a timer that raises is dropped by Blender: keep watching
        log("watching the passes files: %s: %s" % (type(e).__name__, e))
    return WATCH_S


def register():
    """Listens to the live settings' notices; in a UI session, watches the held frames'
    passes files."""
    hooks.listen("live_changed", changed)
    hooks.listen("view_changed", reshow)
    if not bpy.app.background:
        _register_timer(_watch_passes_files, WATCH_S, persistent=True)


def unregister():
    hooks.unlisten("live_changed", changed)
    hooks.unlisten("view_changed", reshow)
    for fn in (_kick, _settle, _poll, _watch_passes_files):
        try:
            if bpy.app.timers.is_registered(fn):
                bpy.app.timers.unregister(fn)
        except Exception:
            pass
    WORKER.shutdown()
    drop()
