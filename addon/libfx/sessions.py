"""The live look-dev model, with no bpy: what each live setting means, the frames held in
memory per scene (a session per scene) and the store of sessions.

- A **session** per scene holds the decoded passes of a few rendered frames (libfx frames,
  kept after F12 or read from a passes file), the frame shown, what the image shows, the
  last refused change, and the AUTO setting's proxy factor.
- A **held frame** is one such frame with its 1/2 and 1/4 proxies, made lazily.

live.py runs the loop on this model; props.py takes the settings' enum items from here.
The store is guarded by its own lock: the render thread and the live worker add frames.
"""

import os
import threading
from collections import OrderedDict

CACHE_FRAMES = 3      # held frames per scene while scrubbing a sequence
BUDGET_MS = 100.0     # a change's interactive image within this (issue 13); AUTO keeps to it

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


def stat(path):
    """(mtime_ns, size) of a file, or None (gone, or no path)."""
    try:
        st = os.stat(path)
        return (st.st_mtime_ns, st.st_size)
    except (OSError, TypeError):
        return None


class Held:
    """One rendered frame's passes in memory, with its proxies."""

    def __init__(self, frame_no, frame, path, sidecar):
        self.frame_no = frame_no
        self.frame = frame            # native.Frame, full size, every pass the file had
        self.path = path              # the passes file it came from (None: gone)
        self.stat = stat(path)
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


_lock = threading.Lock()
_SESSIONS = {}        # scene name -> Session


def get(scene_name):
    """The scene's session, or None."""
    with _lock:
        return _SESSIONS.get(scene_name)


def ensure(scene_name):
    """The scene's session, made when it has none."""
    with _lock:
        s = _SESSIONS.get(scene_name)
        if s is None:
            s = _SESSIONS[scene_name] = Session(scene_name)
        return s


def add_held(scene_name, held):
    """Puts a held frame into the scene's session (made when needed) and shows it; the
    session's last error goes."""
    with _lock:
        s = _SESSIONS.get(scene_name)
        if s is None:
            s = _SESSIONS[scene_name] = Session(scene_name)
        s.add(held)
        s.error = None
        return s


def pop(scene_name=None):
    """Takes one scene's session (or all) out of the store; returns them, to be closed by
    the caller (under the lock of the context their frames belong to)."""
    with _lock:
        names = [scene_name] if scene_name else list(_SESSIONS)
        return [s for s in (_SESSIONS.pop(n, None) for n in names) if s is not None]
