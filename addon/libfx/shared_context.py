"""The one libfx context frames are read and run with, kept across frames, and the lock
around every call into it (F12's render thread, batch's main thread, the live worker).

Kept across frames because its aux-view cache (core/aux_view.h) lets frames 2..N reuse the
light view's and rain map's built maps. One thread at a time per context (GUIDE §1): take
lock() around get() and every use of what it returns, and around closing frames made with
it. No bpy.
"""

import threading

from . import native

_lock = threading.Lock()
_CTX = {"ctx": None, "threads": None}


def lock():
    """The lock around every call into the shared context."""
    return _lock


def get(threads):
    """The shared context with `threads` worker threads (made anew when the count or the
    loaded library changed). Call with lock() held."""
    c = _CTX["ctx"]
    if c is None or _CTX["threads"] != threads or c._L is not native.lib():
        if _CTX["ctx"] is not None:
            _CTX["ctx"].close()
        _CTX["ctx"], _CTX["threads"] = native.Context(threads), threads
    return _CTX["ctx"]


def free():
    """Closes the shared context (unregister)."""
    with _lock:
        if _CTX["ctx"] is not None:
            _CTX["ctx"].close()
        _CTX["ctx"] = _CTX["threads"] = None
