"""The panel's Render Views, without blocking the UI (issue 13).

The extra views a stack reads (light views, the rain map, probes, planar views) are
Cycles renders: seconds each, ten probes in the mirror room. Rendered in Blender's own
process they would freeze the UI for all of that. Instead a copy of the open file goes to
a background Blender (`batch.py --views-only`), which renders them beside the output
exactly as a batch run does; the UI polls it from a timer and says when the views are
ready. F12 and the live loop then read them from disk (aux_views.from_disk).

One job at a time. ViewsJob has no bpy.app.timers of its own, so a headless test can
start one and poll it by hand. The panel's line (status_line) changes as it runs: the
"status_changed" notice (hooks.py) lets the UI redraw.
"""

import os
import subprocess
import tempfile
import time

import bpy

from . import hooks, scene_setup
from .log import log

POLL_S = 0.25


class ViewsJob:
    """A background Blender rendering one scene's views for one frame."""

    def __init__(self, scene, frame):
        self.scene_name = scene.name
        self.frame = frame
        self.started = time.monotonic()
        self.result = None           # (ok, message) once the child has exited
        self._dir = tempfile.mkdtemp(prefix="libfx_views_", dir=bpy.app.tempdir or None)
        self._log = None
        try:
            blend = os.path.join(self._dir, "scene.blend")
            # A copy of the file as it is now, unsaved changes included (relative paths are
            # remapped to the copy's folder by Blender); the open file is left as it was.
            bpy.ops.wm.save_as_mainfile(filepath=blend, copy=True, check_existing=False)
            runner = os.path.join(os.path.dirname(os.path.abspath(__file__)), "batch.py")
            self.command = [bpy.app.binary_path, "-b", blend, "--scene", scene.name, "--python", runner, "--",
                            "--views-only", "--frames", str(frame), "--output", scene_setup.output_prefix(scene)]
            self._log = open(os.path.join(self._dir, "log.txt"), "w+", encoding="utf-8", errors="replace")
            self.proc = subprocess.Popen(self.command, stdout=self._log, stderr=subprocess.STDOUT,
                                         stdin=subprocess.DEVNULL)
        except BaseException:
            self._close()   # no copy or log left behind
            raise

    def poll(self):
        """None while the child runs; then (ok, message), the message naming the views
        made or what failed."""
        if self.result is not None:
            return self.result
        code = self.proc.poll()
        if code is None:
            return None
        self._log.seek(0)
        lines = [l.strip() for l in self._log.read().splitlines()]
        self._close()
        done = [l for l in lines if l.startswith("libfx batch: views:")]
        errors = [l for l in lines if l.startswith("libfx batch: error:")]
        if code == 0 and done:
            self.result = (True, done[-1][len("libfx batch: views:"):].strip())
        else:
            why = errors[-1][len("libfx batch: error:"):].strip() if errors else \
                "the background Blender exited with %d: %s" % (code, " | ".join(lines[-3:]))
            self.result = (False, why)
        return self.result

    def cancel(self):
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        if self.result is None:
            self.result = (False, "cancelled")
        self._close()

    def _close(self):
        if self._log is not None and not self._log.closed:
            self._log.close()
        for name in ("scene.blend", "scene.blend1", "log.txt"):
            try:
                os.remove(os.path.join(self._dir, name))
            except OSError:
                pass
        try:
            os.rmdir(self._dir)
        except OSError:
            pass


STATE = {"job": None}   # the current or last job


def running():
    job = STATE["job"]
    return job is not None and job.result is None


def start(scene):
    """Starts the views of the scene's current frame in the background; the job."""
    if running():
        raise RuntimeError("views are being rendered already (since %.0f s)"
                           % (time.monotonic() - STATE["job"].started))
    job = ViewsJob(scene, scene.frame_current)
    STATE["job"] = job
    log("views: frame %d of '%s' in a background Blender: %s"
               % (job.frame, job.scene_name, " ".join(job.command)))
    if not bpy.app.background:
        bpy.app.timers.register(_poll, first_interval=POLL_S)
    return job


def status_line():
    """The panel's line: what is rendering, or how the last job ended (None: nothing)."""
    job = STATE["job"]
    if job is None:
        return None
    if job.result is None:
        return "Rendering views of frame %d in the background (%.0f s)" % (job.frame, time.monotonic() - job.started)
    return ("Views: " if job.result[0] else "Views failed: ") + job.result[1]


def _poll():
    job = STATE["job"]
    if job is None:
        return None
    res = job.poll()
    hooks.notify("status_changed")   # the panels' line (ui.py redraws them)
    if res is None:
        return POLL_S
    log("views: %s%s (%.1f s)" % ("" if res[0] else "failed: ", res[1], time.monotonic() - job.started))
    return None


def unregister():
    job = STATE["job"]
    if job is not None:
        job.cancel()
    STATE["job"] = None
    try:
        if bpy.app.timers.is_registered(_poll):
            bpy.app.timers.unregister(_poll)
    except Exception:
        pass
