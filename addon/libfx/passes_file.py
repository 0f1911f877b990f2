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
"""

import os
import time

import bpy

from . import compat, native, scene_setup

RENDER_RESULT = "Render Result"


def write(scene, frame):
    """Writes frame's passes file (scene_setup.passes_path) from the Render Result; returns
    (path, seconds). Raises native.LibfxError naming what went wrong."""
    img = next((i for i in bpy.data.images if i.type == "RENDER_RESULT"), None)
    if img is None:
        raise native.LibfxError("no '%s' image after the render: libfx has no passes to read" % RENDER_RESULT)
    path = scene_setup.passes_path(scene, frame)
    folder = os.path.dirname(path)
    if folder:
        os.makedirs(folder, exist_ok=True)
    tmp = "%s.tmp-%d.exr" % (path[:-len(".exr")], os.getpid())
    settings = scene.render.image_settings
    saved = compat.image_format_snapshot(settings)
    t0 = time.perf_counter()
    try:
        compat.set_file_format(settings, "OPEN_EXR_MULTILAYER", "32", scene.libfx.passes_codec)
        img.save_render(tmp, scene=scene)
    except (RuntimeError, OSError) as e:
        _remove_quietly(tmp)
        raise native.LibfxError("cannot write the passes file %s: %s" % (path, e))
    finally:
        compat.image_format_restore(settings, saved)
    if not os.path.exists(tmp):
        raise native.LibfxError("Blender wrote no passes file at %s" % tmp)
    os.replace(tmp, path)
    return path, time.perf_counter() - t0


def _remove_quietly(path):
    try:
        os.remove(path)
    except OSError:
        pass
