"""Live look-dev: the rendered frame's passes stay in memory and the stack re-runs on
every change, straight into the "libfx Result" image (no disk round trip).

- A **session** per scene holds the decoded passes of one rendered frame (a libfx frame,
  kept after F12 or read from a passes file) and, lazily, its 1/2 and 1/4 proxies.
- A change to the stack (parameter, mask, order, enabled flag, quality) calls
  ``changed(scene)``.  It is debounced through ``bpy.app.timers``: the stack first runs
  at the *interactive setting* (draft preset and/or a proxy, ``settings.live_setting``),
  and once no change has come for ``SETTLE_S`` at the stack's own quality, full size.
- One worker thread runs the library (ctypes releases the GIL), so Blender's UI thread
  never waits for more than a pixel copy.  A newer change replaces a run still waiting
  and cancels a final run in progress between effects (the library's progress callback);
  an interactive run in progress finishes and shows, so that a drag keeps updating.  A
  recipe the library refuses leaves the last good image and puts the message in the panel.
- Sequences: with kept passes files, a frame change loads that frame's passes (a few
  frames are cached) and shows its result.

Nothing here is needed for batch renders; ``flush()`` lets headless tests and the
benchmark drive the loop without an event loop.
"""

import os
import threading
import time
from collections import OrderedDict

import bpy

from . import native, recipe, render

RESULT_IMAGE = render.RESULT_IMAGE

DEBOUNCE_S = 0.0      # the run starts at the event loop's next timer pass: the property updates of
                      # one drag step (several) have all come by then and run once
SETTLE_S = 0.35       # no change for this long: the final run
CACHE_FRAMES = 3      # held frames per scene while scrubbing a sequence
BUDGET_MS = 100.0     # a change's interactive image within this (issue 13); AUTO keeps to it
AUTO_UP_MS = 60.0     # an interactive run (library + pixels) slower than this: a quarter next (the
                      # rest of BUDGET_MS is for Blender's side: property update, hand-off, image)
# A quarter-size run faster than this: half next. A half-size run costs up to four quarter-size
# ones, so this is a quarter of AUTO_UP_MS with room to spare (at a fixed 20 ms, a stack whose
# quarter run took 18 ms would go back to a half run over the budget, and flip at every change).
AUTO_DOWN_MS = AUTO_UP_MS / 4 * 0.7

#: live_setting -> (proxy factor, quality or None for the stack's own); "AUTO": the factor
#: follows the time the last interactive run took (Session.auto_factor).
SETTINGS = {
    "AUTO": ("auto", "draft"),
    "HALF_DRAFT": (2, "draft"),
    "QUARTER_DRAFT": (4, "draft"),
    "HALF": (2, None),
    "DRAFT": (1, "draft"),
    "FINAL_ONLY": (None, None),
}
SETTING_ITEMS = [
    ("AUTO", "Auto Draft", "While values change: draft preset at half resolution, or a quarter when "
     "half takes longer than the budget of %d ms" % BUDGET_MS, 5),
    ("HALF_DRAFT", "1/2 Draft", "While values change: half resolution, draft preset", 0),
    ("QUARTER_DRAFT", "1/4 Draft", "While values change: quarter resolution, draft preset", 1),
    ("HALF", "1/2", "While values change: half resolution, the stack's quality", 2),
    ("DRAFT", "Draft", "While values change: full resolution, draft preset", 3),
    ("FINAL_ONLY", "Final Only", "Run only the final setting, after the change settles", 4),
]
VIEW_ITEMS = [
    ("RESULT", "Result", "The stack's result", 0),
    ("BEFORE", "Before", "The plain render (the passes' Combined)", 1),
    ("SPLIT", "Split", "Plain render left of the split line, result right of it", 2),
]

_lock = threading.Lock()
SESSIONS = {}        # scene name -> Session
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
    render.log("live: " + msg)


_TRACE = bool(os.environ.get("LIBFX_LIVE_TRACE"))


def trace(what):
    """LIBFX_LIVE_TRACE=1: when each step of the loop happens (where a change's time goes), and
    the calling thread's CPU time (busy or waiting)."""
    if _TRACE:
        import resource
        faults = resource.getrusage(getattr(resource, "RUSAGE_THREAD", resource.RUSAGE_SELF)).ru_minflt
        render.log("live trace %.4f %s [%s cpu %.4f, %d minor faults]" % (
            time.perf_counter(), what, threading.current_thread().name, time.thread_time(), faults))


class Held:
    """One rendered frame's passes in memory, with its proxies."""

    def __init__(self, frame_no, frame, path, sidecar):
        self.frame_no = frame_no
        self.frame = frame            # native.Frame, full size, every pass the file had
        self.path = path              # the passes file it came from (None: gone)
        self.stat = _stat(path)
        self.sidecar = sidecar
        self.proxies = {}             # factor -> native.Frame
        self.before = None            # numpy RGBA of the plain render, display size

    def proxy(self, factor):
        if factor in (None, 1):
            return self.frame
        p = self.proxies.get(factor)
        if p is None:
            p = self.frame.reduce(factor)
            self.proxies[factor] = p
        return p

    def close(self):
        for p in self.proxies.values():
            p.close()
        self.proxies.clear()
        self.frame.close()


class Session:
    def __init__(self, scene_name):
        self.scene_name = scene_name
        self.frames = OrderedDict()   # frame number -> Held (LRU)
        self.current = None           # frame number shown
        self.shown = {}               # what the image shows: setting, ms, timings, frame
        self.error = None             # the last refused change (the image keeps the last good one)
        self.debug_passes = []        # debug pass names of the last run
        self.auto_factor = 2          # the proxy factor of the AUTO setting

    def held(self):
        return self.frames.get(self.current)

    def add(self, held):
        old = self.frames.pop(held.frame_no, None)
        if old is not None:
            old.close()
        self.frames[held.frame_no] = held
        while len(self.frames) > CACHE_FRAMES:
            _, h = self.frames.popitem(last=False)
            h.close()
        self.current = held.frame_no

    def close(self):
        for h in self.frames.values():
            h.close()
        self.frames.clear()


def _stat(path):
    try:
        st = os.stat(path)
        return (st.st_mtime_ns, st.st_size)
    except (OSError, TypeError):
        return None


def session(scene):
    with _lock:
        return SESSIONS.get(scene.name)


def has_frame(scene, frame_no=None):
    s = session(scene)
    return s is not None and (frame_no if frame_no is not None else scene.frame_current) in s.frames


def drop(scene_name=None):
    """Frees held frames (one scene, or all): on unregister, file load."""
    with _lock:
        names = [scene_name] if scene_name else list(SESSIONS)
        gone = [s for s in (SESSIONS.pop(n, None) for n in names) if s is not None]
    # the context lock is taken before _lock everywhere else (hold()): never inside it
    with render.ctx_lock():
        for s in gone:
            s.close()


# ---------------------------------------------------------------- holding frames

def hold(scene_name, frame_no, frame, path, sidecar, proxy_factor=None):
    """Keeps a decoded frame (called with the context lock held, any thread). proxy_factor:
    build that proxy on the worker now, so that the first drag does not pay for it."""
    held = Held(frame_no, frame, path, sidecar)
    with _lock:
        s = SESSIONS.get(scene_name)
        if s is None:
            s = SESSIONS[scene_name] = Session(scene_name)
        s.add(held)
        s.error = None
    if proxy_factor and proxy_factor > 1:
        def build():
            with render.ctx_lock():
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


# ---------------------------------------------------------------- the worker

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


class _Worker:
    """One thread, one job slot: a newer job replaces a waiting one (and cancels a running
    final one, _obsolete)."""

    def __init__(self):
        self.cv = threading.Condition()
        self.job = None
        self.tasks = []               # callables that must all run, in order (result writes)
        self.running = None
        self.results = []             # finished jobs' outputs, for the main thread
        self.thread = None
        self.stop = False

    def submit(self, job):
        with self.cv:
            self.job = job
            self._start()
            self.cv.notify_all()

    def submit_task(self, fn):
        """Runs fn() on the worker before any live job (F12's result write)."""
        with self.cv:
            self.tasks.append(fn)
            self._start()
            self.cv.notify_all()

    def _start(self):
        if self.thread is None or not self.thread.is_alive():
            self.stop = False
            self.thread = threading.Thread(target=self._loop, name="libfx live", daemon=True)
            self.thread.start()

    def idle(self):
        with self.cv:
            return self.job is None and not self.tasks and self.running is None

    def wait_idle(self, timeout):
        end = time.monotonic() + timeout
        with self.cv:
            while self.job is not None or self.tasks or self.running is not None:
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self.cv.wait(left)
        return True

    def shutdown(self):
        with self.cv:
            self.stop = True
            self.job = None
            tasks, self.tasks = self.tasks, []
            self.cv.notify_all()
        for fn in tasks:   # result writes are never dropped
            _run_task(fn)

    def _loop(self):
        while True:
            with self.cv:
                while self.job is None and not self.tasks and not self.stop:
                    self.cv.wait()
                if self.stop:
                    return
                task = self.tasks.pop(0) if self.tasks else None
                if task is not None:
                    self.running = task
            if task is not None:
                _run_task(task)
                with self.cv:
                    self.running = None
                    self.cv.notify_all()
                continue
            with self.cv:
                job, self.job = self.job, None
                if job is None:
                    continue
                self.running = job
            try:
                trace("job %s start" % job.kind)
                out = _run_job(job, lambda: self._obsolete(job))
                trace("job %s end" % job.kind)
            except Exception as e:  # never let the thread die
                out = {"job": job, "error": "%s: %s" % (type(e).__name__, e)}
            with self.cv:
                self.running = None
                if out is not None:
                    self.results.append(out)
                self.cv.notify_all()

    def _obsolete(self, job):
        """A newer change cancels a running final run (hundreds of ms), but not a running
        interactive one: during a drag a change comes every few tens of ms, about what an
        interactive run takes, so cancelling those would leave the image still until the
        drag ends. The interactive run finishes and shows; the newest change runs next."""
        with self.cv:
            if self.stop:
                return True
            return self.job is not None and self.job.generation > job.generation and job.kind != "interactive"


WORKER = _Worker()


def _run_task(fn):
    try:
        fn()
    except Exception as e:
        log("background task failed: %s: %s" % (type(e).__name__, e))


def _run_job(job, obsolete):
    """Runs one job on the worker thread; returns what the main thread shows, or None
    (cancelled)."""
    import numpy as np
    with render.ctx_lock():
        ctx = render.shared_context(job.threads)
        if job.load is not None:
            frame_no, path, sidecar, fps, proxy_factor, layer = job.load
            t0 = time.perf_counter()
            try:
                _read_held(ctx, job.scene_name, frame_no, path, sidecar, fps, proxy_factor, layer)
            except native.LibfxError as e:
                return {"job": job, "error": str(e)}
            log("frame %d: passes read in %.0f ms" % (frame_no, (time.perf_counter() - t0) * 1e3))
        with _lock:
            s = SESSIONS.get(job.scene_name)
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


#: scene name -> the recipe the last stack change built (scene_setup.stack_changed): its
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
    recipe as the change left it (built once per change by scene_setup.stack_changed);
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


def _register_timer(fn, interval):
    try:
        if not bpy.app.timers.is_registered(fn):
            bpy.app.timers.register(fn, first_interval=interval)
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
            _redraw_panels()
        return
    _submit(job)


POLL_S = 0.005        # a finished run waits at most this for the main thread to show it


def _submit(job):
    """Main thread: hand a job to the worker and poll for its result (timers run on the
    main thread only, so the worker never touches Blender data)."""
    WORKER.submit(job)
    _register_timer(_poll, POLL_S)


def _poll():
    with WORKER.cv:
        results, WORKER.results = WORKER.results, []
    for out in results:
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
    with _lock:
        s = SESSIONS.get(job.scene_name)
    if scene is None or s is None:
        return
    if out.get("error"):
        s.error = out["error"] + ("  (showing the last good result)" if s.shown else "")
        log("%s: %s" % (job.scene_name, out["error"]))
        _redraw_panels()
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
    _redraw_panels()


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
        _replace_in_editors(old, img)
        bpy.data.images.remove(old)
    return img


def show_pixels(pixels, w, h):
    img = result_image(w, h)
    trace("image ready")
    img.pixels.foreach_set(pixels)
    trace("pixels set")
    img.update()
    trace("image updated")
    _show_in_editor(img)


def _replace_in_editors(old, new):
    wm = bpy.context.window_manager
    for win in (wm.windows if wm else []):
        for area in win.screen.areas:
            if area.type == "IMAGE_EDITOR" and area.spaces.active.image == old:
                area.spaces.active.image = new


def _show_in_editor(img):
    wm = bpy.context.window_manager
    if wm is None:
        return
    for win in wm.windows:
        for area in win.screen.areas:
            if area.type == "IMAGE_EDITOR":
                space = area.spaces.active
                if space.image is None or space.image.type == "RENDER_RESULT" or space.image == img:
                    space.image = img
                    area.tag_redraw()
                    return


def _redraw_panels():
    wm = bpy.context.window_manager
    for win in (wm.windows if wm else []):
        for area in win.screen.areas:
            if area.type in ("PROPERTIES", "NODE_EDITOR", "IMAGE_EDITOR"):
                area.tag_redraw()


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
        with _lock:
            s = SESSIONS.get(scene_name)
        if s is not None:
            s.shown = info
            s.error = None
        _redraw_panels()

    render.to_ui(show)


def start(scene, frame_no=None, path=None, sidecar=None):
    """Loads a frame's passes (from ``path``, default the scene's passes file of the frame)
    and shows its final result: "Apply to Last Render", scrubbing, file reloads."""
    from . import scene_setup
    if not native.has("live"):
        log(native.feature_problem("live") or "live look-dev is unavailable")
        return
    frame_no = scene.frame_current if frame_no is None else frame_no
    path = path or scene_setup.passes_path(scene, frame_no)
    if sidecar is None:
        sidecar = render.sidecar_for(scene, frame_no)
    with _lock:
        if scene.name not in SESSIONS:
            SESSIONS[scene.name] = Session(scene.name)
    fps = scene.render.fps / (scene.render.fps_base or 1.0)
    layer = scene_setup.passes_layer(scene)
    _submit(_make_job(scene, "final", load=(frame_no, path, sidecar, fps, proxy_factor_of(scene), layer)))


def refresh_if_stale(scene):
    """The held frame's passes file changed on disk (re-rendered, replaced): read it again.
    Deleted: keep what is in memory and say so."""
    s = session(scene)
    h = s.held() if s else None
    if h is None or h.path is None:
        return
    st = _stat(h.path)
    if st is None:
        if h.stat is not None:
            s.error = "the passes file %s is gone: showing the frame held in memory" % h.path
            h.stat = None
        return
    if st != h.stat:
        log("frame %d: %s changed on disk: reading it again" % (h.frame_no, h.path))
        start(scene, h.frame_no, h.path, h.sidecar)


def on_frame_change(scene):
    """Scrubbing: show the new frame's result when its passes are held or on disk."""
    from . import scene_setup
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
        with WORKER.cv:
            res, WORKER.results = WORKER.results, []
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


def unregister():
    for fn in (_kick, _settle, _poll):
        try:
            if bpy.app.timers.is_registered(fn):
                bpy.app.timers.unregister(fn)
        except Exception:
            pass
    WORKER.shutdown()
    drop()
