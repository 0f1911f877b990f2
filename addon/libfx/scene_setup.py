"""What the scene must render for its stack.

- ``sync(scene)`` asks the library which passes the stack needs
  (fx_stack_required_passes) and turns on exactly those view-layer passes,
  remembering what it turned on so it can turn it off again.
- The passes reach libfx as one multilayer EXR per frame beside the scene's output
  path (``passes_path``), written from the Render Result by passes_file.py.
- ``remove_nodes(scene)`` takes out the Render Layers and File Output nodes that
  add-ons before passes_file.py put in the compositor (scenes saved with them).
- ``restore(scene)`` undoes all of it (stack emptied, add-on disabled).

A setting "lightgroup:<group>" (vsm_shadows' apply light_group) is not a view-layer
property: the add-on makes the light group <group> on the view layer and puts the light
of the stack's first light view in it (Blender 3.2+), so Blender writes the pass
Combined_<group>; it remembers what it changed and undoes it as the other settings.
"""

import json
import os
import re
import threading
from collections import OrderedDict

import bpy

from . import compat, native, recipe

RL_NODE = "libfx Render Layers"
FO_NODE = "libfx passes"

# Per scene name: {"error": str|None, "warnings": [...], "passes": [...], "camera": bool}
STATUS = {}


def status(scene):
    return STATUS.get(scene.name, {})


LIGHT_GROUP_SETTING = "lightgroup:"


def set_status(scene, **kw):
    """Sets entries of the scene's status (the panel shows it): "error", "warnings",
    "passes", "camera", "aux_views", "migrated"."""
    st = STATUS.setdefault(scene.name, {})
    st.update(kw)


# ---------------------------------------------------------------- output paths

def output_prefix(scene):
    """Absolute prefix of libfx's files, derived from the scene's output path:
    '//render/bath_' -> '/abs/render/bath_', '/tmp/out' -> '/tmp/out_'."""
    p = bpy.path.abspath(scene.render.filepath or "//")
    p = re.sub(r"#+", "", p)
    if not p:
        p = bpy.app.tempdir
    if p.endswith((os.sep, "_", ".", "-")):
        return p
    if os.path.isdir(p):
        return p + os.sep
    return p + "_"


def passes_base(scene):
    return output_prefix(scene) + "libfx_passes."


def passes_path(scene, frame):
    """The passes file of a frame (passes_file.py writes it)."""
    return "%s%04d.exr" % (passes_base(scene), frame)


def passes_layer(scene):
    """The layer libfx reads from a passes file: the render's view layer when the scene has
    several (the file holds them all), else None (the only one; older add-ons' files name no
    layer)."""
    return render_view_layer(scene).name if len(scene.view_layers) > 1 else None


def result_paths(scene, frame):
    base = "%slibfx.%04d" % (output_prefix(scene), frame)
    # The sidecar keeps the name earlier add-ons gave it (batch outputs, farms and
    # `libfx run --sidecar` command lines name it).
    return {"exr": base + ".exr", "sidecar": base + ".camera.json",
            "image": base + scene.render.file_extension,
            "recipe": output_prefix(scene) + "libfx_recipe.json"}


def writes_image(scene):
    """Whether the scene's output format needs a separate image beside the EXR."""
    return scene.render.image_settings.file_format not in ("OPEN_EXR", "OPEN_EXR_MULTILAYER")


# ---------------------------------------------------------------- owned state

def _owned(scene):
    try:
        d = json.loads(scene.libfx.owned or "{}")
    except ValueError:
        d = {}
    d.setdefault("settings", {})
    return d


def _save_owned(scene, d):
    text = json.dumps(d, sort_keys=True)
    if scene.libfx.owned != text:
        scene.libfx.owned = text


def render_view_layer(scene):
    for vl in scene.view_layers:
        if vl.use:
            return vl
    return scene.view_layers[0]


def _setting_holder(view_layer, setting):
    for holder in (view_layer, getattr(view_layer, "cycles", None), getattr(view_layer, "eevee", None)):
        if holder is not None and hasattr(holder, setting):
            return holder
    return None


def scene_problem(scene, create_folder=True):
    """Why the scene cannot be rendered for libfx (a message naming what to set), or None."""
    if not any(vl.use for vl in scene.view_layers):
        return ("scene '%s' has no view layer enabled for rendering (View Layer Properties > "
                "Use for Rendering)" % scene.name)
    if scene.camera is None:
        return "scene '%s' has no active camera (Scene Properties > Camera)" % scene.name
    if not scene.render.filepath.strip():
        return ("scene '%s' has no output path (Output Properties > Output): libfx writes the "
                "passes and its results beside it" % scene.name)
    folder = os.path.dirname(output_prefix(scene)) or "."
    if create_folder:
        try:
            os.makedirs(folder, exist_ok=True)
        except OSError as e:
            return "scene '%s': cannot create the output folder %s: %s" % (scene.name, folder, e.strerror or e)
    if os.path.isdir(folder) and not os.access(folder, os.W_OK):
        return "scene '%s': the output folder %s is not writable" % (scene.name, folder)
    return None


def has_stack(scene):
    s = getattr(scene, "libfx", None)
    return bool(s) and any(it.enabled for it in s.stack)


# ---------------------------------------------------------------- sync

_query_lock = threading.Lock()
_QUERY = {"ctx": None, "lib": None}
_ANSWERS = OrderedDict()   # recipe JSON text -> the library's answers about it
_ANSWERS_KEPT = 32


def _query_context():
    """One small context for the questions about a recipe (a new one per property change
    cost a few ms of every live update). Call with _query_lock held: F12's render thread
    asks too (the aux views of a frame)."""
    L = native.lib()
    if _QUERY["ctx"] is None or _QUERY["lib"] is not L:
        _ANSWERS.clear()   # another library may answer otherwise
        _QUERY["ctx"], _QUERY["lib"] = native.Context(1), L
    return _QUERY["ctx"]


def answers(rec):
    """What the library says about a recipe: {"required": fx_stack_required_passes,
    "aux_views": fx_stack_required_aux_views}. Kept per recipe text for the session: the
    answers depend on the recipe alone, and a drag or an undo meets the same recipe again."""
    key = json.dumps(rec, sort_keys=True)
    with _query_lock:
        ctx = _query_context()
        got = _ANSWERS.get(key)
        if got is not None:
            _ANSWERS.move_to_end(key)
            return got
        stack = native.Stack(ctx, key)
        try:
            got = {"required": stack.required(), "aux_views": stack.required_aux_views()}
        finally:
            stack.close()
        _ANSWERS[key] = got
        while len(_ANSWERS) > _ANSWERS_KEPT:
            _ANSWERS.popitem(last=False)
        return got


def forget():
    """Drops the query context and the answers (unregister)."""
    with _query_lock:
        if _QUERY["ctx"] is not None:
            _QUERY["ctx"].close()
        _QUERY["ctx"] = _QUERY["lib"] = None
        _ANSWERS.clear()
    STATUS.clear()


def request_sync(scene, rec=None):
    """From property updates and imports: keep the view layer passes in step."""
    try:
        sync(scene, rec)
    except Exception as e:  # never let a UI update raise
        set_status(scene, error=str(e))


def sync(scene, rec=None):
    """Enables exactly the passes the stack needs; returns the library's answer or None.
    ``rec``: the stack's recipe, when the caller has built it already."""
    if native.load() is None:
        set_status(scene, error=native.load_error())
        return None
    if not has_stack(scene):
        _restore_settings(scene, keep=set())
        _restore_light_group(scene)
        set_status(scene, error=None, warnings=[], passes=[], camera=False, aux_views=[])
        return None
    try:
        got = answers(recipe.to_recipe(scene) if rec is None else rec)
        req = got["required"]
    except (native.LibfxError, ValueError) as e:
        set_status(scene, error=str(e))
        return None
    warnings = []
    vl = render_view_layer(scene)
    settings = req.get("blender_settings")
    if settings is None:
        warnings.append("the library does not name the Blender pass settings (blender_settings): "
                        "enable the passes by hand: " + ", ".join(req.get("passes", [])))
        settings = []
    owned = _owned(scene)
    mine = set(owned["settings"].get(vl.name, []))
    keep = set()
    group_wanted = None
    for setting in settings:
        if not setting:
            continue  # Combined, Alpha: always there
        if setting.startswith(LIGHT_GROUP_SETTING):
            group_wanted = setting[len(LIGHT_GROUP_SETTING):]
            continue
        holder = _setting_holder(vl, setting)
        if holder is None:
            warnings.append("this Blender has no view layer setting '%s'" % setting)
            continue
        keep.add(setting)
        if not getattr(holder, setting):
            setattr(holder, setting, True)
            mine.add(setting)
    owned["settings"][vl.name] = sorted(mine)
    _save_owned(scene, owned)
    _restore_settings(scene, keep={(vl.name, s) for s in keep})
    if group_wanted:
        lname = next((v.get("light") or "" for v in got["aux_views"] if v.get("kind") == "light"), "")
        problem = _ensure_light_group(scene, vl, group_wanted, lname)
        if problem:
            warnings.append(problem)
    else:
        _restore_light_group(scene)
    warnings += engine_warnings(scene, req.get("passes", []))
    problem = scene_problem(scene, create_folder=False)
    if problem:
        warnings.append(problem)
    set_status(scene, error=None, warnings=warnings, passes=req.get("passes", []),
                camera=bool(req.get("camera", False)),
                aux_views=[v["name"] for v in got["aux_views"]])
    return req


def engine_warnings(scene, passes):
    out = []
    engine = scene.render.engine
    idx = [p for p in passes if p in ("IndexOB", "IndexMA") and not compat.engine_renders_pass(engine, p)]
    if idx:
        out.append("%s renders no %s pass: mask by object/material name instead "
                   "(Cryptomatte works in every engine)" % (compat.engine_label(engine), "/".join(idx)))
    other = [p for p in passes if p not in idx and not compat.engine_renders_pass(engine, p)]
    if other:
        out.append("%s renders no %s pass: render with Cycles or Eevee" % (compat.engine_label(engine),
                                                                          "/".join(other)))
    if any(p.startswith("Combined_") for p in passes) and engine != "CYCLES":
        out.append("%s writes no light group passes (Cycles only): vsm_shadows' apply light_group "
                   "cannot run; use apply sun_direct" % compat.engine_label(engine))
    return out


def _find_light(scene, name):
    """The light object `name`, or the scene's first sun when name is empty (as the light
    views find it); None if there is none."""
    for ob in scene.objects:
        if ob.type == "LIGHT" and not ob.hide_render and (ob.name == name or (not name and ob.data.type == "SUN")):
            return ob
    return None


def _ensure_light_group(scene, vl, group, light_name):
    """Makes the light group `group` on view layer vl hold the light `light_name` (empty:
    the first sun); returns a problem to show, or None. What it changes is kept in the
    scene's owned state for _restore_light_group."""
    if not hasattr(vl, "lightgroups"):
        return ("this Blender has no light groups (3.2+): vsm_shadows' apply light_group needs one; "
                "use apply sun_direct")
    light = _find_light(scene, light_name)
    if light is None:
        return "light group '%s': the scene has no light '%s'" % (group, light_name or "(first sun)")
    owned = _owned(scene)
    mine = owned.get("lightgroup")
    if mine and (mine.get("view_layer") != vl.name or mine.get("light") != light.name
                 or mine.get("group") != group):
        _restore_light_group(scene)
        owned = _owned(scene)
        mine = None
    if mine is None:
        mine = {"view_layer": vl.name, "group": group, "light": light.name, "made_group": False,
                "previous": None}
    if vl.lightgroups.get(group) is None:
        vl.lightgroups.add(name=group)
        mine["made_group"] = True
    if light.lightgroup != group:
        if mine["previous"] is None:
            mine["previous"] = light.lightgroup
        light.lightgroup = group
    owned["lightgroup"] = mine
    _save_owned(scene, owned)
    if mine["previous"]:
        return ("light '%s' was in light group '%s': it is in '%s' while the stack needs it (put "
                "back when it no longer does)" % (light.name, mine["previous"], group))
    return None


def _remove_light_group(scene, vl, name):
    """Removes the view layer's light group `name`: Blender 3.4's collection has no
    remove(), only the operator on the active group (run with the view layer as context);
    where neither works the empty group stays (it renders an empty pass, nothing else)."""
    idx = vl.lightgroups.find(name)
    if idx < 0:
        return
    coll = vl.lightgroups
    if hasattr(coll, "remove"):
        coll.remove(coll[idx])
        return
    try:
        vl.active_lightgroup_index = idx
        with bpy.context.temp_override(scene=scene, view_layer=vl):
            bpy.ops.scene.view_layer_remove_lightgroup()
    except (AttributeError, RuntimeError, TypeError):
        pass


def _restore_light_group(scene):
    """Undoes _ensure_light_group: the light's previous group, the group removed if the
    add-on made it."""
    owned = _owned(scene)
    mine = owned.pop("lightgroup", None)
    if not mine:
        return
    ob = scene.objects.get(mine.get("light", ""))
    if ob is not None and ob.type == "LIGHT" and ob.lightgroup == mine.get("group") \
            and mine.get("previous") is not None:
        ob.lightgroup = mine["previous"]
    vl = scene.view_layers.get(mine.get("view_layer", ""))
    if vl is not None and mine.get("made_group") and hasattr(vl, "lightgroups"):
        _remove_light_group(scene, vl, mine.get("group", ""))
    _save_owned(scene, owned)


def _restore_settings(scene, keep):
    """Turns off what the add-on turned on and is not in keep {(view_layer, setting)}."""
    owned = _owned(scene)
    changed = False
    for vl_name, settings in list(owned["settings"].items()):
        vl = scene.view_layers.get(vl_name)
        left = []
        for s in settings:
            if (vl_name, s) in keep:
                left.append(s)
                continue
            holder = _setting_holder(vl, s) if vl else None
            if holder is not None and getattr(holder, s):
                setattr(holder, s, False)
            changed = True
        if left:
            owned["settings"][vl_name] = left
        else:
            del owned["settings"][vl_name]
            changed = True
    if changed:
        _save_owned(scene, owned)


# ---------------------------------------------------------------- nodes of earlier add-ons

def remove_nodes(scene):
    nt = compat.compositor_tree(scene)
    if nt is not None:
        for name in (FO_NODE, RL_NODE):
            n = nt.nodes.get(name)
            if n is not None:
                nt.nodes.remove(n)
    owned = _owned(scene)
    made = owned.pop("compositor", None)
    if owned.pop("use_nodes", False):   # how scenes saved by an earlier add-on say it
        made = made or "use_nodes"
    compat.release_compositor_tree(scene, made)
    _save_owned(scene, owned)


def restore(scene):
    """Undo everything the add-on changed in the scene."""
    if getattr(scene, "libfx", None) is None:
        return
    _restore_settings(scene, keep=set())
    _restore_light_group(scene)
    remove_nodes(scene)
