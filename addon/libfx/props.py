"""Property groups, generated from the library's effect descriptions.

One PropertyGroup per effect (LIBFX_PG_<effect>) holds that effect's parameters;
each stack item (LIBFX_PG_stack_item) points at one group per effect and uses
the one its ``effect`` names.  Pointer groups cost nothing until written, an
item keeps its values when the effect is switched, and there is exactly one
RNA type per effect for drivers and Python access (``item.fx_pixelate.cell_size``).

A parameter the user never touched is *unset* (``is_property_set`` is False):
it is left out of the recipe, so the quality presets keep deciding it.
"""

import re

import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty,
                       FloatVectorProperty, IntProperty, IntVectorProperty, PointerProperty,
                       StringProperty)

from . import catalog as _catalog
from . import hooks, sessions
from .log import trace

#: The catalogue the classes were generated from (set by register()).
CATALOG = None
_generated = []     # classes made at register time, in registration order
_suspend = [0]      # >0 while recipes are being imported: no pass syncing per property


def catalog():
    return CATALOG


def settings_of(context):
    """The context scene's libfx settings (None while the add-on is not registered)."""
    return getattr(context.scene, "libfx", None)


def active_item(context):
    """The stack item the list has active, or None."""
    s = settings_of(context)
    if s is None or not (0 <= s.active_index < len(s.stack)):
        return None
    return s.stack[s.active_index]


def group_attr(effect_name):
    return "fx_" + re.sub(r"\W", "_", effect_name)


def effect_group(item):
    """The parameter group of the item's effect, or None (unknown effect)."""
    if CATALOG is None or item.effect not in CATALOG.effects:
        return None
    return getattr(item, group_attr(item.effect), None)


class suspended:
    """with props.suspended(): ... -- no update callbacks work inside."""

    def __enter__(self):
        _suspend[0] += 1

    def __exit__(self, *exc):
        _suspend[0] -= 1


def _scene_of(self, context):
    return self.id_data if isinstance(self.id_data, bpy.types.Scene) else context.scene


def _on_change(self, context):
    if _suspend[0]:
        return
    trace("update callback")
    hooks.notify("stack_changed", _scene_of(self, context))


def _on_live_change(self, context):
    """Live settings: the stack is the same, only what is shown or how it runs changed."""
    if _suspend[0]:
        return
    hooks.notify("live_changed", _scene_of(self, context))


def _on_view_change(self, context):
    if _suspend[0]:
        return
    hooks.notify("view_changed", _scene_of(self, context))


_DEBUG_ITEMS = []   # Blender keeps no copy of dynamic enum strings: they live here


def _debug_pass_items(self, context):
    s = sessions.get(_scene_of(self, context).name) if context else None
    names = s.debug_passes if s is not None else []
    _DEBUG_ITEMS[:] = [("NONE", "Result", "Show the stack's result", 0)] + [
        (n, n, "Show the debug pass %s of the last run" % n, i + 1) for i, n in enumerate(names)]
    return _DEBUG_ITEMS


def _param_property(p):
    kw = {"name": p.label(), "description": p.doc or p.name, "update": _on_change}
    if p.type == "float":
        sub = {"factor": "FACTOR", "pixels": "PIXEL"}.get(p.hint, "NONE")
        return FloatProperty(default=p.default, min=p.min, max=p.max, soft_min=p.soft_min,
                             soft_max=p.soft_max, subtype=sub, precision=3, **kw)
    if p.type == "int":
        sub = "PIXEL" if p.hint == "pixels" else "NONE"
        return IntProperty(default=int(p.default), min=int(p.min), max=int(p.max),
                           soft_min=int(p.soft_min), soft_max=int(p.soft_max), subtype=sub, **kw)
    if p.type == "bool":
        return BoolProperty(default=bool(p.default), **kw)
    if p.type == "enum":
        items = [(i, i.replace("_", " ").capitalize(), "%s = %s" % (p.name, i)) for i in p.items]
        return EnumProperty(items=items or [("", "", "")], default=p.default or None, **kw)
    if p.type == "floats":
        n = max(1, min(32, p.count))
        if p.hint == "color" and n in (3, 4):
            sub = "COLOR"
        elif p.hint == "matrix4" and n == 16:
            sub = "MATRIX"
        else:
            sub = "NONE"
        return FloatVectorProperty(size=n, default=tuple(p.default[:n]), min=p.min, max=p.max,
                                   soft_min=p.soft_min, soft_max=p.soft_max, subtype=sub, **kw)
    # string
    sub = "FILE_PATH" if p.hint == "path" else "NONE"
    return StringProperty(default=p.default or "", subtype=sub, **kw)


def _effect_group_class(effect):
    ann = {p.prop: _param_property(p) for p in effect.params}
    name = "LIBFX_PG_" + _catalog.prop_identifier(effect.name)
    return type(name, (bpy.types.PropertyGroup,), {"__annotations__": ann,
                                                     "__doc__": effect.doc or effect.name,
                                                     "libfx_effect": effect.name})


class LIBFX_PG_name(bpy.types.PropertyGroup):
    """A material or object name of a mask (uses the built-in ``name``)."""
    name: StringProperty(name="Name", update=_on_change)


MASK_KINDS = [
    ("MATERIAL", "Material", "Pixels of these materials (Cryptomatte, any engine)", 1),
    ("OBJECT", "Object", "Pixels of these objects (Cryptomatte, any engine)", 2),
    ("MATERIAL_INDEX", "Material Index", "Pixels whose material pass index is listed (Cycles only)", 4),
    ("OBJECT_INDEX", "Object Index", "Pixels whose object pass index is listed (Cycles only)", 8),
    ("RECT", "Rectangle", "A screen rectangle; with other kinds it restricts them", 16),
]


_QUALITY_ITEMS = []
_ITEM_QUALITY_ITEMS = []


def _make_quality_items(qualities):
    _QUALITY_ITEMS[:] = [(q, q.capitalize(), "Quality preset '%s' for every effect" % q, i)
                         for i, q in enumerate(qualities)] or [("final", "Final", "", 2)]
    _ITEM_QUALITY_ITEMS[:] = [("STACK", "Stack", "Use the stack's quality preset", 100)] + [
        (q, q.capitalize(), "Quality preset '%s' for this effect" % q, i)
        for i, q in enumerate(qualities)]


def _default_quality():
    ids = [i[0] for i in _QUALITY_ITEMS]
    return "final" if "final" in ids else ids[0]


def _stack_item_class(cat):
    ann = {
        "effect": StringProperty(name="Effect", description="Effect name, as the library calls it",
                                 update=_on_change),
        "label": StringProperty(name="Label", description="Your name for this step (kept in the recipe)"),
        "enabled": BoolProperty(name="Enabled", default=True, description="Run this effect",
                                update=_on_change),
        "quality": EnumProperty(name="Quality", items=list(_ITEM_QUALITY_ITEMS), default="STACK",
                                description="Quality preset of this effect (overrides the stack's)",
                                update=_on_change),
        "mask_kinds": EnumProperty(name="Mask", items=MASK_KINDS, options={"ENUM_FLAG"}, default=set(),
                                   description="Which pixels the effect may change (none: all)",
                                   update=_on_change),
        "mask_materials": CollectionProperty(type=LIBFX_PG_name),
        "mask_objects": CollectionProperty(type=LIBFX_PG_name),
        "mask_material_indices": StringProperty(
            name="Material Indices", description="Material pass indices, separated by commas",
            update=_on_change),
        "mask_object_indices": StringProperty(
            name="Object Indices", description="Object pass indices, separated by commas",
            update=_on_change),
        "mask_rect": IntVectorProperty(name="Rectangle", size=4, default=(0, 0, 64, 64), min=0,
                                       description="x, y, width, height in pixels, top-left origin",
                                       update=_on_change),
        "mask_invert": BoolProperty(name="Invert", description="Change the pixels outside the mask",
                                    update=_on_change),
        # Recipe entry of an effect this library does not know, kept verbatim.
        "raw_json": StringProperty(options={"HIDDEN"}),
        # The version of the effect's parameter table the stored values were made with
        # (files saved before versions existed read the default: 1). Older than the
        # library's: the values are sent as stored and the library migrates them
        # (recipe.migrate_stack writes the migrated values back).
        "params_version": IntProperty(options={"HIDDEN"}, default=1, min=1),
    }
    for name in cat.order:
        ann[group_attr(name)] = PointerProperty(type=_GROUPS[name])
    return type("LIBFX_PG_stack_item", (bpy.types.PropertyGroup,), {"__annotations__": ann})


_GROUPS = {}

#: The passes file's codecs, fastest first (Blender write + libfx read, docs/performance.md).
PASSES_CODECS = [
    ("NONE", "None (fastest)", "Uncompressed: the fastest to write and read, about 4x the disk of ZIP", 0),
    ("RLE", "RLE", "Run-length: in between in speed and size", 1),
    ("ZIP", "ZIP (smallest)", "ZIP: the smallest kept file, about 2.5x slower to write and read", 2),
]


def _live_items(name):
    return list(getattr(sessions, name))


def _settings_class(item_cls):
    ann = {
        "stack": CollectionProperty(type=item_cls),
        "active_index": IntProperty(name="Active Effect", default=0, min=0),
        "quality": EnumProperty(name="Quality", items=list(_QUALITY_ITEMS), default=_default_quality(),
                                description="Quality preset of the whole stack (from the library)",
                                update=_on_change),
        "threads": IntProperty(name="Threads", default=0, min=0, max=1024,
                               description="libfx worker threads (0: one per core)"),
        "show_result": BoolProperty(name="Show Result", default=True,
                                    description="After F12, show 'libfx Result' in an Image Editor"),
        "keep_passes": BoolProperty(
            name="Keep Passes Files",
            description=("Keep each frame's passes file beside the output (for Apply to Last Render "
                         "and for scrubbing a rendered sequence live); off: removed once the result, "
                         "which holds the same passes, is written"),
            default=False),
        "passes_codec": EnumProperty(
            name="Passes Codec", items=PASSES_CODECS, default="NONE",
            description="EXR codec of the passes file Blender writes for libfx (docs/performance.md)"),
        "live": BoolProperty(
            name="Live Update", default=True, update=_on_live_change,
            description=("Keep the rendered frame's passes in memory and re-run the stack on every "
                         "change, into 'libfx Result'")),
        "live_setting": EnumProperty(
            name="While Changing", items=_live_items("SETTING_ITEMS"), default="AUTO",
            update=_on_live_change,
            description="How the stack runs while values change; the final run follows when they settle"),
        "live_view": EnumProperty(name="Show", items=_live_items("VIEW_ITEMS"), default="RESULT",
                                  update=_on_view_change, description="Result, plain render, or both"),
        "live_split": FloatProperty(name="Split", default=0.5, min=0.0, max=1.0, subtype="FACTOR",
                                    update=_on_view_change,
                                    description="Where the plain render ends in the split view"),
        "live_solo": BoolProperty(name="Solo", default=False, update=_on_live_change,
                                  description="Run only the active effect"),
        "live_debug": BoolProperty(name="Debug Passes", default=False, update=_on_live_change,
                                   description="Live runs also make the effects' debug passes (mask "
                                               "coverage, hit maps, shadow visibility...) to inspect"),
        "live_debug_pass": EnumProperty(name="Inspect", items=_debug_pass_items, update=_on_live_change,
                                        description="Show one of the effects' debug passes instead of the result"),
        # What the add-on changed in the scene, to undo it (JSON, see scene_setup.py).
        "owned": StringProperty(default="{}", options={"HIDDEN"}),
    }
    return type("LIBFX_PG_settings", (bpy.types.PropertyGroup,), {"__annotations__": ann})


def register(cat):
    global CATALOG
    CATALOG = cat
    _make_quality_items(cat.qualities)
    _generated.clear()
    _GROUPS.clear()
    bpy.utils.register_class(LIBFX_PG_name)
    for name in cat.order:
        cls = _effect_group_class(cat.effects[name])
        bpy.utils.register_class(cls)
        _GROUPS[name] = cls
        _generated.append(cls)
    item_cls = _stack_item_class(cat)
    bpy.utils.register_class(item_cls)
    _generated.append(item_cls)
    settings_cls = _settings_class(item_cls)
    bpy.utils.register_class(settings_cls)
    _generated.append(settings_cls)
    bpy.types.Scene.libfx = PointerProperty(type=settings_cls)


def unregister():
    global CATALOG
    if hasattr(bpy.types.Scene, "libfx"):
        del bpy.types.Scene.libfx
    for cls in reversed(_generated):
        try:
            bpy.utils.unregister_class(cls)
        except RuntimeError:
            pass
    _generated.clear()
    _GROUPS.clear()
    try:
        bpy.utils.unregister_class(LIBFX_PG_name)
    except RuntimeError:
        pass
    CATALOG = None
