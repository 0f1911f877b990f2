"""The add-on's console lines ("libfx: ...") and the live loop's trace (LIBFX_LIVE_TRACE=1).

A leaf: nothing of the add-on below it, no bpy.
"""

import os
import sys
import threading
import time


def log(msg, err=False):
    stream = sys.stderr if err else sys.stdout
    print("libfx: " + msg, file=stream)
    stream.flush()


_TRACE = bool(os.environ.get("LIBFX_LIVE_TRACE"))


def trace(what):
    """LIBFX_LIVE_TRACE=1: when each step of the live loop happens (where a change's time
    goes), and the calling thread's CPU time (busy or waiting)."""
    if _TRACE:
        import resource
        faults = resource.getrusage(getattr(resource, "RUSAGE_THREAD", resource.RUSAGE_SELF)).ru_minflt
        log("live trace %.4f %s [%s cpu %.4f, %d minor faults]" % (
            time.perf_counter(), what, threading.current_thread().name, time.thread_time(), faults))
