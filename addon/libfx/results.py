"""Each rendered frame's result record: {"ok", "error", "frame", "paths", "timings", ...},
per (scene name, frame). batch.py turns failures into an exit code (a handler's exception
does not change Blender's); an error is also reported in the UI.
"""

import threading

import bpy

from . import ui_queue
from .log import log

_lock = threading.Lock()
RESULTS = {}     # (scene name, frame) -> {"ok": bool, "error": str, "paths": {...}, "timings": [...]}


def record(scene, frame, error=None, **kw):
    return record_named(scene.name, frame, error=error, **kw)


def record_named(scene_name, frame, error=None, **kw):
    """Any thread: the frame's result record; an error is also reported in the UI."""
    rec = {"ok": error is None, "error": error, "frame": frame}
    rec.update(kw)
    with _lock:
        RESULTS[(scene_name, frame)] = rec
    if error:
        log("frame %d: %s" % (frame, error), err=True)
        if not bpy.app.background:
            ui_queue.to_ui(lambda: ui_queue.report("ERROR", "libfx: frame %d: %s" % (frame, error)))
    return rec


def get(scene_name, frame):
    """The frame's record, or None."""
    with _lock:
        return RESULTS.get((scene_name, frame))


def forget(scene_name, frame):
    """Drops the frame's record (before it renders again)."""
    with _lock:
        RESULTS.pop((scene_name, frame), None)
