"""The scene sidecar of each frame: the camera's matrices (as rows), the rendered lights,
the time, and the aux views rendered for it (JSON, as `libfx run --sidecar` reads it).

Blender's EXRs carry no camera; the right matrices of an animated camera are those of
frame_change_post's depsgraph (render handlers see frame 1's, GUIDE §3), so the handlers
store each frame's sidecar here as the frame changes, and the frame pipeline takes it when
the frame's passes are run. The aux views' entries come from batch.py (aux_views.prepare,
before each frame renders) or, for F12, from the files an earlier batch run left.
The store is guarded by its own lock (F12 reads it on the render thread).
"""

import threading

from . import aux_views
from .log import log

_lock = threading.Lock()
_SIDECARS = {}   # (scene name, frame) -> the frame's scene sidecar (camera, lights, time)
_AUX = {}        # (scene name, frame) -> aux view sidecar entries (aux_views.prepare)


def lights_list(scene, depsgraph):
    """The scene's rendered lights for the sidecar: position, travel direction (-Z of
    the light's matrix), colour, energy; effects find a light by name."""
    out = []
    for ob in scene.objects:
        if ob.type != "LIGHT" or ob.hide_render:
            continue
        ev = ob.evaluated_get(depsgraph) if depsgraph is not None else ob
        mw = ev.matrix_world
        d = -mw.col[2].xyz
        if d.length > 0:
            d.normalize()
        data = ev.data
        light = {"name": ob.name, "type": data.type, "position": list(mw.translation),
                 "direction": list(d), "color": list(data.color), "energy": float(data.energy)}
        if data.type == "SUN":
            light["angle"] = float(data.angle)
        out.append(light)
    return out


def frame_sidecar(scene, depsgraph):
    """The frame's scene sidecar: camera (matrices as rows), lights and time (the aux views
    are added by sidecar_for). None without a scene camera."""
    cam = scene.camera
    if cam is None:
        return None
    ev = cam.evaluated_get(depsgraph) if depsgraph is not None else cam
    r = scene.render
    x = int(r.resolution_x * r.resolution_percentage / 100)
    y = int(r.resolution_y * r.resolution_percentage / 100)
    proj = ev.calc_matrix_camera(depsgraph, x=x, y=y, scale_x=r.pixel_aspect_x,
                                 scale_y=r.pixel_aspect_y)
    w2c = ev.matrix_world.inverted()
    data = ev.data
    return {
        "world_to_camera": [list(row) for row in w2c],
        "projection": [list(row) for row in proj],
        "clip_start": float(getattr(data, "clip_start", 0.1)),
        "clip_end": float(getattr(data, "clip_end", 1000.0)),
        "orthographic": getattr(data, "type", "PERSP") == "ORTHO",
        "lights": lights_list(scene, depsgraph),
        "frame": scene.frame_current,
        "fps": r.fps / (r.fps_base or 1.0),
    }


def store(scene_name, frame, sidecar):
    """Keeps a frame's sidecar (frame_change_post, F12's render_init)."""
    with _lock:
        _SIDECARS[(scene_name, frame)] = sidecar


def known(scene_name, frame):
    """Whether the frame's sidecar is kept."""
    with _lock:
        return (scene_name, frame) in _SIDECARS


def set_aux(scene_name, frame, entries):
    """The aux views rendered for a frame (batch.py, before the frame renders)."""
    with _lock:
        _AUX[(scene_name, frame)] = entries


def sidecar_for(scene, frame, sidecar=None):
    """The scene sidecar of a frame: its camera (from frame_change_post), lights, time and
    the aux views rendered for it. None when the frame's camera is unknown."""
    if sidecar is None:
        with _lock:
            sidecar = _SIDECARS.get((scene.name, frame))
    with _lock:
        aux = _AUX.get((scene.name, frame))
    if aux is None and sidecar is not None:
        try:
            aux = aux_views.from_disk(scene)
        except Exception as e:
            log("frame %d: aux views: %s" % (frame, e), err=True)
    if aux and sidecar is not None:
        sidecar = dict(sidecar, aux_views=aux)
    return sidecar
