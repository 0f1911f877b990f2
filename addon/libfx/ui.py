"""The UI: the stack list, the add menu and the panels (Properties > Output, Compositor
sidebar); the operators they show are in operators.py.

Panels only draw: no draw() starts a job or redraws an editor. The UI hears what changed
through hooks.py and does the redrawing itself: "status_changed" (a live run, a views job)
redraws the panels, "result_shown" / "result_replaced" put the "libfx Result" image into
an Image Editor. A held frame's passes file is watched by a timer (live.py), not here.
"""

import bpy

from . import hooks, live, props, scene_setup, views_job
from .operators import (LIBFX_OT_live_load, LIBFX_OT_mask_name_add, LIBFX_OT_mask_name_remove,
                        LIBFX_OT_param_reset, LIBFX_OT_recipe_export, LIBFX_OT_recipe_import,
                        LIBFX_OT_recipe_text, LIBFX_OT_render_views, LIBFX_OT_rerun,
                        LIBFX_OT_restore_scene, LIBFX_OT_stack_add, LIBFX_OT_stack_duplicate,
                        LIBFX_OT_stack_move, LIBFX_OT_stack_remove)

_settings = props.settings_of
_active = props.active_item


# ---------------------------------------------------------------- list and menu

class LIBFX_UL_stack(bpy.types.UIList):
    """The effect stack: runs top to bottom."""

    def draw_item(self, context, layout, data, item, icon, active_data, active_propname, index):
        cat = props.catalog()
        known = cat is not None and item.effect in cat.effects
        row = layout.row(align=True)
        row.prop(item, "enabled", text="")
        text = item.label or (cat.effects[item.effect].label() if known else item.effect)
        row.label(text=text, icon="SHADERFX" if known else "ERROR")
        if item.mask_kinds:
            row.label(text="", icon="MOD_MASK")
        if item.quality != "STACK":
            row.label(text=item.quality.capitalize())


class LIBFX_MT_add(bpy.types.Menu):
    bl_idname = "LIBFX_MT_add"
    bl_label = "Add Effect"

    def draw(self, context):
        cat = props.catalog()
        if cat is None or not cat.order:
            self.layout.label(text="libfx is not loaded", icon="ERROR")
            return
        for name in cat.order:
            self.layout.operator(LIBFX_OT_stack_add.bl_idname, text=cat.effects[name].label()).effect = name


# ---------------------------------------------------------------- drawing

def _fmt(v):
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, (int, float)):
        v = float(v)
    if isinstance(v, float):
        return "%g" % v
    if isinstance(v, list):
        return ", ".join(_fmt(x) for x in v)
    return str(v)


def _current(group, p):
    v = getattr(group, p.prop)
    if p.type == "floats":
        return [float(x) for x in v]
    if p.type in ("float", "int"):
        return float(v)
    return v


def _draw_params(layout, context, item, eff):
    s = _settings(context)
    group = props.effect_group(item)
    quality = s.quality if item.quality == "STACK" else item.quality
    col = layout.column()
    col.use_property_split = True
    col.use_property_decorate = False
    for p in eff.params:
        row = col.row(align=True)
        is_set = group.is_property_set(p.prop)
        sub = row.row(align=True)
        if p.type == "floats" and p.hint == "matrix4":
            sub = row.column(align=True)
        sub.prop(group, p.prop)
        preset = eff.preset_value(quality, p.name)
        if is_set:
            op = row.operator(LIBFX_OT_param_reset.bl_idname, text="", icon="LOOP_BACK")
            op.param = p.prop
        elif preset is not None and _fmt(preset) != _fmt(_current(group, p)):
            row.label(text="", icon="PRESET")
            col.label(text="   %s preset: %s = %s" % (quality, p.label(), _fmt(preset)))
        else:
            row.label(text="", icon="BLANK1")


def _draw_names(layout, item, kind, coll_attr, search_attr, label):
    box = layout.column(align=True)
    row = box.row(align=True)
    row.label(text=label)
    row.operator(LIBFX_OT_mask_name_add.bl_idname, text="", icon="ADD").kind = coll_attr
    for i, entry in enumerate(getattr(item, coll_attr)):
        r = box.row(align=True)
        r.prop_search(entry, "name", bpy.data, search_attr, text="")
        op = r.operator(LIBFX_OT_mask_name_remove.bl_idname, text="", icon="X")
        op.kind, op.index = coll_attr, i


def _draw_mask(layout, item):
    box = layout.box()
    box.label(text="Mask", icon="MOD_MASK")
    box.row().prop(item, "mask_kinds", expand=True)
    kinds = item.mask_kinds
    if not kinds:
        box.label(text="No mask: the effect changes the whole frame")
        return
    if "MATERIAL" in kinds:
        _draw_names(box, item, "MATERIAL", "mask_materials", "materials", "Materials (Cryptomatte)")
    if "OBJECT" in kinds:
        _draw_names(box, item, "OBJECT", "mask_objects", "objects", "Objects (Cryptomatte)")
    if "MATERIAL_INDEX" in kinds:
        box.prop(item, "mask_material_indices")
    if "OBJECT_INDEX" in kinds:
        box.prop(item, "mask_object_indices")
    if "RECT" in kinds:
        box.prop(item, "mask_rect")
    box.prop(item, "mask_invert")


def _chars(context):
    """How many characters of label text fit the region's width."""
    region = getattr(context, "region", None)
    scale = (context.preferences.system.ui_scale if context.preferences else 0.0) or 1.0
    return max(24, int((region.width if region else 300) / (6.5 * scale)) - 6)


def draw_stack(layout, context):
    width = _chars(context)
    s = _settings(context)
    cat = props.catalog()
    scene = context.scene
    if cat is None or s is None:
        layout.label(text="libfx add-on is not registered", icon="ERROR")
        return
    if not cat.ok:
        box = layout.box()
        box.alert = True
        box.label(text="libfx library unavailable", icon="ERROR")
        for line in _wrap(cat.error, width):
            box.label(text=line)
    st = scene_setup.status(scene)

    row = layout.row()
    row.prop(s, "quality")
    row = layout.row()
    row.template_list("LIBFX_UL_stack", "", s, "stack", s, "active_index", rows=4)
    col = row.column(align=True)
    col.menu(LIBFX_MT_add.bl_idname, text="", icon="ADD")
    col.operator(LIBFX_OT_stack_remove.bl_idname, text="", icon="REMOVE")
    col.operator(LIBFX_OT_stack_duplicate.bl_idname, text="", icon="DUPLICATE")
    col.separator()
    col.operator(LIBFX_OT_stack_move.bl_idname, text="", icon="TRIA_UP").direction = "UP"
    col.operator(LIBFX_OT_stack_move.bl_idname, text="", icon="TRIA_DOWN").direction = "DOWN"

    item = _active(context)
    if item is not None:
        eff = cat.effects.get(item.effect)
        box = layout.box()
        if eff is None:
            box.alert = True
            box.label(text="Unknown effect '%s' (kept as written in the recipe)" % item.effect, icon="ERROR")
        else:
            for i, line in enumerate(_wrap(eff.doc, width)):
                box.label(text=line, icon="INFO" if i == 0 else "BLANK1")
            r = box.row()
            r.prop(item, "label")
            r.prop(item, "quality", text="")
            _draw_params(box, context, item, eff)
            _draw_mask(box, item)

    if st.get("error"):
        b = layout.box()
        b.alert = True
        for i, line in enumerate(_wrap(st["error"], width)):
            b.label(text=line, icon="ERROR" if i == 0 else "BLANK1")
    for w in st.get("warnings", []) + st.get("migrated", []):
        for i, line in enumerate(_wrap(w, width)):
            layout.label(text=line, icon="ERROR" if i == 0 else "BLANK1")
    if st.get("passes"):
        row = layout.row()
        row.label(text="Renders: " + ", ".join(st["passes"]) +
                  ("  + camera" if st.get("camera") else ""), icon="RENDERLAYERS")
        row.operator(LIBFX_OT_restore_scene.bl_idname, text="", icon="TRASH")
    if st.get("aux_views"):
        row = layout.row()
        row.label(text="Views: " + ", ".join(st["aux_views"]), icon="LIGHT_SUN")
        row.operator(LIBFX_OT_render_views.bl_idname, text="Render Views", icon="RENDER_STILL")
        vs = views_job.status_line()
        if vs:
            for i, line in enumerate(_wrap(vs, width)):
                layout.label(text=line, icon=("TIME" if views_job.running() else "INFO") if i == 0 else "BLANK1")

    row = layout.row(align=True)
    row.operator(LIBFX_OT_recipe_import.bl_idname, icon="IMPORT", text="Import")
    row.operator(LIBFX_OT_recipe_export.bl_idname, icon="EXPORT", text="Export")
    row.operator(LIBFX_OT_recipe_text.bl_idname, icon="TEXT", text="To Text").action = "STORE"
    row = layout.row(align=True)
    row.operator(LIBFX_OT_rerun.bl_idname, icon="FILE_REFRESH")
    row.prop(s, "show_result", text="", icon="IMAGE")
    row.prop(s, "threads")
    _draw_live(layout, context, s, width)
    row = layout.row(align=True)
    row.prop(s, "keep_passes")
    row.prop(s, "passes_codec", text="")
    if cat.ok:
        layout.label(text="libfx %s  %s" % (cat.version, cat.path), icon="CHECKMARK")
    for w in cat.warnings:
        layout.label(text=w, icon="ERROR")


def _draw_live(layout, context, s, width):
    box = layout.box()
    row = box.row(align=True)
    row.prop(s, "live", icon="PLAY" if s.live else "PAUSE")
    row.prop(s, "live_setting", text="")
    row.operator(LIBFX_OT_live_load.bl_idname, text="", icon="FILE_FOLDER")
    if not s.live:
        return
    sess = live.session(context.scene)
    row = box.row(align=True)
    row.prop(s, "live_view", expand=True)
    if s.live_view == "SPLIT":
        row.prop(s, "live_split", text="")
    row = box.row(align=True)
    row.prop(s, "live_solo", toggle=True, icon="SOLO_ON" if s.live_solo else "SOLO_OFF")
    row.prop(s, "live_debug", toggle=True, icon="VIEWZOOM")
    if s.live_debug:
        row.prop(s, "live_debug_pass", text="")
    if sess is None or not sess.frames:
        box.label(text="Render (F12) or Load Passes to start", icon="INFO")
        return
    shown = sess.shown
    if shown:
        what = {"render": "After render", "interactive": "Interactive", "final": "Final"}.get(
            shown["kind"], shown["kind"])
        size = "full size" if shown.get("factor", 1) == 1 else "1/%d size" % shown["factor"]
        ms = shown.get("ms", {}).get("total")
        box.label(text="Frame %d. %s: %s preset, %s%s" % (
            shown["frame"], what, shown.get("quality") or s.quality, size,
            (", %.0f ms" % ms) if ms is not None else ""), icon="TIME")
        col = box.column(align=True)
        for t in shown.get("timings", []):
            if t.get("enabled", True):
                col.label(text="  %s  %.1f ms" % (t.get("effect"), t.get("ms", 0.0)))
    if sess.error:
        b = box.box()
        b.alert = True
        for i, line in enumerate(_wrap(sess.error, width)):
            b.label(text=line, icon="ERROR" if i == 0 else "BLANK1")


def _wrap(text, width):
    import textwrap
    return textwrap.wrap(text or "", width) or [""]


class LIBFX_PT_output(bpy.types.Panel):
    bl_idname = "LIBFX_PT_output"
    bl_label = "libfx Effects"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "output"

    def draw(self, context):
        draw_stack(self.layout, context)


class LIBFX_PT_compositor(bpy.types.Panel):
    bl_idname = "LIBFX_PT_compositor"
    bl_label = "libfx Effects"
    bl_space_type = "NODE_EDITOR"
    bl_region_type = "UI"
    bl_category = "libfx"

    @classmethod
    def poll(cls, context):
        space = context.space_data
        return space is not None and getattr(space, "tree_type", "") == "CompositorNodeTree"

    def draw(self, context):
        draw_stack(self.layout, context)


#: The message of a Blender this add-on does not support (then only this panel registers).
UNSUPPORTED = []


class LIBFX_PT_unsupported(bpy.types.Panel):
    bl_idname = "LIBFX_PT_unsupported"
    bl_label = "libfx Effects"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "output"

    def draw(self, context):
        box = self.layout.box()
        box.alert = True
        for i, line in enumerate(_wrap(" ".join(UNSUPPORTED), _chars(context))):
            box.label(text=line, icon="ERROR" if i == 0 else "BLANK1")


def set_unsupported(problem):
    """The message of a Blender this add-on does not support (None: supported)."""
    UNSUPPORTED[:] = [problem] if problem else []


# ---------------------------------------------------------------- what the hooks ask of the UI

def redraw_panels():
    """"status_changed": the panels show a new status (a live run, a views job)."""
    wm = bpy.context.window_manager
    for win in (wm.windows if wm else []):
        for area in win.screen.areas:
            if area.type in ("PROPERTIES", "NODE_EDITOR", "IMAGE_EDITOR"):
                area.tag_redraw()


def show_in_image_editor(img):
    """"result_shown": the first Image Editor showing nothing, the Render Result or the
    image itself shows the image."""
    wm = bpy.context.window_manager
    if wm is None:
        return
    for win in wm.windows:
        for area in win.screen.areas:
            if area.type == "IMAGE_EDITOR":
                space = area.spaces.active
                if space.image is None or space.image.type == "RENDER_RESULT" or space.image == img:
                    space.image = img
                    area.tag_redraw()
                    return


def replace_in_image_editors(old, new):
    """"result_replaced": editors showing the old result image show the new one."""
    wm = bpy.context.window_manager
    for win in (wm.windows if wm else []):
        for area in win.screen.areas:
            if area.type == "IMAGE_EDITOR" and area.spaces.active.image == old:
                area.spaces.active.image = new


_LISTENERS = (("status_changed", redraw_panels), ("result_shown", show_in_image_editor),
              ("result_replaced", replace_in_image_editors))


def register():
    """Listens to the notices that ask for a redraw or an editor (the classes are registered
    by the package)."""
    for name, fn in _LISTENERS:
        hooks.listen(name, fn)


def unregister():
    for name, fn in _LISTENERS:
        hooks.unlisten(name, fn)


unsupported_classes = (LIBFX_PT_unsupported,)

classes = (
    LIBFX_UL_stack, LIBFX_MT_add, LIBFX_PT_output, LIBFX_PT_compositor,
)
