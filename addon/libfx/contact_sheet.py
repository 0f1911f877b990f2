"""A shot's contact sheet: the results of chosen frames as thumbnails on one PNG.

The batch runner's ``--check --contact-sheet PATH`` writes it once every frame is
complete (the farm's final job, docs/farm.md). Thumbnails come from each result's
Combined pass through the library (resampled by fx_frame_read_pixels), in frame order,
left to right and top to bottom; the sheet goes through the scene's view transform like
a render, and is written to a temporary name and renamed, so a sheet exists only whole.
Plain buffers, no numpy: the farm's final job should not depend on which Python packages
a node's Blender happens to see.
"""

import array
import ctypes
import math
import os

import bpy

from . import compat

# A sheet of a 2,000-frame shot shows an even sample: at most this many thumbnails.
MAX_THUMBS = 48
COLUMNS = 6
THUMB_WIDTH = 240
GAP = 4


def sample_frames(frames, limit=MAX_THUMBS):
    """At most ``limit`` of ``frames``, evenly spaced, first and last included."""
    if len(frames) <= limit:
        return list(frames)
    step = (len(frames) - 1) / (limit - 1)
    return [frames[round(i * step)] for i in range(limit)]


def write(fx, ctx, scene, frames, path):
    """Writes the sheet of ``frames`` (their result EXRs must be complete) to ``path``;
    returns the frames shown."""
    shown = sample_frames(frames)
    first = fx.native.Frame.read(ctx, fx.scene_setup.result_paths(scene, shown[0])["exr"])
    try:
        w, h = first.width, first.height
    finally:
        first.close()
    tw = min(THUMB_WIDTH, w)
    th = max(1, round(h * tw / w))
    cols = min(COLUMNS, len(shown))
    rows = math.ceil(len(shown) / cols)
    sw, sh = cols * tw + (cols + 1) * GAP, rows * th + (rows + 1) * GAP
    # Rows bottom-up, as Blender stores an image; thumbnails read bottom-up to match.
    sheet = array.array("f", [0.0, 0.0, 0.0, 1.0]) * (sw * sh)
    dst = memoryview(sheet)
    thumb = (ctypes.c_float * (tw * th * 4))()
    src = memoryview(thumb).cast("B").cast("f")
    for i, frame in enumerate(shown):
        f = fx.native.Frame.read(ctx, fx.scene_setup.result_paths(scene, frame)["exr"])
        try:
            f.read_pixels("Combined", tw, th, thumb, bottom_up=True)
        finally:
            f.close()
        r, c = divmod(i, cols)
        y0 = sh - GAP - (r + 1) * th - r * GAP   # the thumbnail's bottom row in the sheet
        x0 = GAP + c * (tw + GAP)
        for y in range(th):
            at = ((y0 + y) * sw + x0) * 4
            dst[at:at + tw * 4] = src[y * tw * 4:(y + 1) * tw * 4]
    for k in range(3, len(sheet), 4):
        sheet[k] = 1.0
    _save_png(scene, sheet, sw, sh, path)
    return shown


def _save_png(scene, pixels, width, height, path):
    """Linear RGBA rows (bottom-up, as Blender stores them) -> an 8-bit PNG through the
    scene's view transform, written whole or not at all."""
    img = bpy.data.images.new("libfx contact sheet", width, height, alpha=False, float_buffer=True)
    settings = scene.render.image_settings
    saved = compat.image_format_snapshot(settings)
    d, name = os.path.split(os.path.abspath(path))
    tmp = os.path.join(d, ".%s.tmp-%d.png" % (name, os.getpid()))
    try:
        img.pixels.foreach_set(pixels)
        compat.set_file_format(settings, "PNG", "8")   # 5.0+: an image media type first
        settings.color_mode = "RGB"
        img.save_render(tmp, scene=scene)
        os.replace(tmp, path)
    finally:
        compat.image_format_restore(settings, saved)
        bpy.data.images.remove(img)
        if os.path.exists(tmp):
            os.remove(tmp)
