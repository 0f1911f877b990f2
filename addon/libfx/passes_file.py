"""The passes file: the finished render's passes as one multilayer EXR, for libfx to read.

It is written in render_post from the "Render Result" image (``Image.save_render``), which
holds every pass of every view layer the render made. That writer takes 0.2-0.3 s for the
Greek bath's 35 channels at 1920x1080, where a compositor File Output node took 1.5-2.8 s for
the same channels (docs/performance.md, "The passes file"); it also leaves the artist's
compositor alone. Blender writes the file with the scene's image settings, so they are set to
32-bit multilayer EXR with the Passes Codec for the call and put back at once (render_post runs
before Blender writes the frame's own output in ``-b`` renders). The file is written under a
temporary name and renamed, so a reader never meets half a file.

5.0+ writes one part per pass (multipart EXR) where 3.4-4.5 write one part; libfx reads both.

A passes file that is not kept (Keep Passes Files off, the default) lives only until the result
is written, so it goes to a folder in RAM (``/dev/shm``) when there is room: Blender writes the
Greek bath's 276 MB there in about half the time it takes on the disk's file system, which
throttles a writer that dirties that much (docs/performance.md, "Render finished to result
shown"). Each Blender process has its own folder; those of processes that are gone are removed.
"""

import atexit
import os
import re
import shutil
import threading
import time

import bpy

from . import compat, native, scene_setup
from .log import log

RENDER_RESULT = "Render Result"


RAM_ROOT = "/dev/shm"
# Room asked for in RAM per pixel and view layer: 64 float channels (the Greek bath writes 35),
# so a file never fills the folder half-way.
RAM_BYTES_PER_PIXEL = 64 * 4


def write(scene, frame):
    """Writes frame's passes file from the Render Result; returns (path, seconds).
    Kept passes go to scene_setup.passes_path; the others to RAM when there is room (else
    there too). Raises native.LibfxError naming what went wrong."""
    img = next((i for i in bpy.data.images if i.type == "RENDER_RESULT"), None)
    if img is None:
        raise native.LibfxError("no '%s' image after the render: libfx has no passes to read" % RENDER_RESULT)
    path = scene_setup.passes_path(scene, frame)
    if not scene.libfx.keep_passes:
        ram = ram_path(scene, frame)
        if ram is not None:
            try:
                return _write(scene, img, ram)
            except native.LibfxError:
                pass   # the RAM folder failed us (full, gone): the output folder, as if kept
    return _write(scene, img, path)


def ram_path(scene, frame):
    """Where a passes file that is not kept goes in RAM, or None (no RAM folder, or not room
    enough for this render)."""
    folder = _ram_folder()
    if folder is None:
        return None
    r = scene.render
    pixels = (r.resolution_x * r.resolution_percentage // 100) * (r.resolution_y * r.resolution_percentage // 100)
    layers = max(1, sum(1 for vl in scene.view_layers if vl.use))
    try:
        st = os.statvfs(folder)
    except OSError:
        return None
    if st.f_bavail * st.f_frsize < pixels * layers * RAM_BYTES_PER_PIXEL:
        return None
    name = re.sub(r"[^A-Za-z0-9_.-]", "_", scene.name)[:60]
    return os.path.join(folder, "%s.%04d.exr" % (name, frame))


_RAM = {"folder": None, "checked": False}


def _ram_folder():
    """This process's folder in RAM (made once; the folders of processes that are gone are
    removed then), or None."""
    if _RAM["checked"]:
        return _RAM["folder"]
    _RAM["checked"] = True
    if not os.path.isdir(RAM_ROOT) or not os.access(RAM_ROOT, os.W_OK):
        return None
    base = os.path.join(RAM_ROOT, "libfx-passes-%d" % os.getuid())
    try:
        os.makedirs(base, mode=0o700, exist_ok=True)
        for entry in os.listdir(base):
            if entry.isdigit() and not _alive(int(entry)):
                shutil.rmtree(os.path.join(base, entry), ignore_errors=True)
        folder = os.path.join(base, str(os.getpid()))
        os.makedirs(folder, exist_ok=True)
    except OSError:
        return None
    atexit.register(shutil.rmtree, folder, True)   # what a failed frame left, at Blender's exit
    _RAM["folder"] = folder
    return folder


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True   # someone else's
    return True


def _write(scene, img, path):
    folder = os.path.dirname(path)
    if folder:
        os.makedirs(folder, exist_ok=True)
    tmp = "%s.tmp-%d.exr" % (path[:-len(".exr")], os.getpid())
    settings = scene.render.image_settings
    saved = compat.image_format_snapshot(settings)
    t0 = time.perf_counter()
    try:
        compat.when_writable(compat.set_file_format, settings, "OPEN_EXR_MULTILAYER", "32",
                             scene.libfx.passes_codec)
        img.save_render(tmp, scene=scene)
    except (RuntimeError, OSError, AttributeError) as e:
        _remove_quietly(tmp)
        raise native.LibfxError("cannot write the passes file %s: %s" % (path, e))
    finally:
        missed = compat.image_format_restore(settings, saved)
        if missed:
            log("scene '%s': the output format's %s could not be put back after the passes file"
                % (scene.name, ", ".join(missed)), err=True)
    if not os.path.exists(tmp):
        raise native.LibfxError("Blender wrote no passes file at %s" % tmp)
    old = _set_aside(path)
    os.replace(tmp, path)
    secs = time.perf_counter() - t0
    if old is not None:
        _remove_later(old)
    return path, secs


def _set_aside(path):
    """The previous frame's file at path (a kept passes file rendered again) renamed aside,
    or None. Replacing it in place makes the file system free its blocks before the rename
    returns, on the way to the result: 63-337 ms for a 290 MB file (the Greek bath's passes
    at 1080p) on this project's VM, 0.1-0.3 ms for the rename aside."""
    if not os.path.exists(path):
        return None
    old = "%s.old-%d.exr" % (path[:-len(".exr")], os.getpid())
    try:
        os.replace(path, old)
    except OSError:
        return None   # replaced in place then, as before
    return old


def _remove_later(path):
    """Unlinks path on a thread of its own (os.unlink releases the GIL); not a daemon thread,
    so Blender's exit waits for it rather than leaving the file behind."""
    threading.Thread(target=_remove_quietly, args=(path,), name="libfx unlink").start()


def _remove_quietly(path):
    try:
        os.remove(path)
    except OSError:
        pass
