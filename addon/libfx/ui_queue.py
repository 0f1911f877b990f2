"""Work for Blender's main thread, from any thread: F12's handlers run on the render
thread, where UI data (images, editors, reports) must not be touched; what they queue here
runs from a bpy.app.timers timer once Blender allows data changes (after the render job).
"""

import threading

import bpy

from .log import log

_lock = threading.Lock()
_queue = []   # callables (or (callable, tries so far)) to run on the main thread

#: The UI queue is first looked at this soon (F12's result waits for it: the timer is what
#: stands between the stack's end and the image), then every UI_RETRY_S while the render
#: job still runs or Blender refuses the update ("not allowed in this context"; the
#: refusal can outlast the render job by a moment, seen on 4.3), at most UI_RETRIES times
#: (5 s). Each pass costs the main thread one function call.
UI_FIRST_S = 0.005
UI_RETRY_S = 0.02
UI_RETRIES = 250


def to_ui(fn):
    """Runs fn on the main thread when Blender allows data changes (after the render job)."""
    with _lock:
        _queue.append(fn)
    try:
        if not bpy.app.timers.is_registered(drain):
            bpy.app.timers.register(drain, first_interval=UI_FIRST_S)
    except Exception:
        pass


def drain():
    """The timer: runs what is queued (main thread); again soon while Blender refuses."""
    # While the render job runs Blender refuses writes to data-blocks (an image's
    # name, a reload): try again when it has finished.
    if bpy.app.is_job_running("RENDER"):
        return UI_RETRY_S
    with _lock:
        todo = list(_queue)
        _queue.clear()
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
            _queue[:0] = again
        return UI_RETRY_S
    return None


def report(kind, message):
    """A report in Blender's status bar and Info log (main thread; the add-on's
    libfx.report operator)."""
    wm = bpy.context.window_manager
    win = wm.windows[0] if wm and wm.windows else None
    if win is None:
        return
    with bpy.context.temp_override(window=win):
        bpy.ops.libfx.report("INVOKE_DEFAULT", kind=kind, message=message)
