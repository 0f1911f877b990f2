"""Operators, the stack list and the panels (Properties > Output, Compositor sidebar)."""

import os

import bpy
from bpy.props import EnumProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ExportHelper, ImportHelper

from . import aux_views, live, native, props, recipe, render, scene_setup, views_job


def _settings(context):
    return getattr(context.scene, "libfx", None)


def _active(context):
    s = _settings(context)
    if s is None or not (0 <= s.active_index < len(s.stack)):
        return None
    return s.stack[s.active_index]


def _changed(context):
    scene_setup.stack_changed(context.scene)


# ---------------------------------------------------------------- operators

class LIBFX_OT_stack_add(bpy.types.Operator):
    bl_idname = "libfx.stack_add"
    bl_label = "Add Effect"
    bl_options = {"REGISTER", "UNDO"}
    effect: StringProperty(name="Effect")

    @classmethod
    def description(cls, context, properties):
        cat = props.catalog()
        eff = cat.effects.get(properties.effect) if cat else None
        return eff.doc if eff else "Add an effect to the libfx stack"

    def execute(self, context):
        cat = props.catalog()
        if cat is None or self.effect not in cat.effects:
            self.report({"ERROR"}, "libfx has no effect '%s'" % self.effect)
            return {"CANCELLED"}
        s = _settings(context)
        with props.suspended():
            item = s.stack.add()
            item.effect = self.effect
            item.params_version = cat.effects[self.effect].params_version
        s.active_index = len(s.stack) - 1
        _changed(context)
        return {"FINISHED"}


class LIBFX_OT_stack_remove(bpy.types.Operator):
    bl_idname = "libfx.stack_remove"
    bl_label = "Remove Effect"
    bl_description = "Remove the active effect from the stack"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return _active(context) is not None

    def execute(self, context):
        s = _settings(context)
        s.stack.remove(s.active_index)
        s.active_index = max(0, min(s.active_index, len(s.stack) - 1))
        _changed(context)
        if not len(s.stack):
            scene_setup.restore(context.scene)
        return {"FINISHED"}


class LIBFX_OT_stack_duplicate(bpy.types.Operator):
    bl_idname = "libfx.stack_duplicate"
    bl_label = "Duplicate Effect"
    bl_description = "Duplicate the active effect, with its parameters and mask"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return _active(context) is not None

    def execute(self, context):
        s = _settings(context)
        entry = recipe.item_to_json(s.stack[s.active_index], resolve_paths=False)
        new = s.stack.add()
        recipe.fill_item(new, entry, len(s.stack) - 1)
        s.stack.move(len(s.stack) - 1, s.active_index + 1)
        s.active_index += 1
        _changed(context)
        return {"FINISHED"}


class LIBFX_OT_stack_move(bpy.types.Operator):
    bl_idname = "libfx.stack_move"
    bl_label = "Move Effect"
    bl_description = "Move the active effect up or down (effects run top to bottom)"
    bl_options = {"REGISTER", "UNDO"}
    direction: EnumProperty(items=[("UP", "Up", ""), ("DOWN", "Down", "")])

    @classmethod
    def poll(cls, context):
        return _active(context) is not None

    def execute(self, context):
        s = _settings(context)
        i = s.active_index
        j = i - 1 if self.direction == "UP" else i + 1
        if 0 <= j < len(s.stack):
            s.stack.move(i, j)
            s.active_index = j
            _changed(context)   # the order is part of the stack: the passes and live follow
        return {"FINISHED"}


class LIBFX_OT_param_reset(bpy.types.Operator):
    bl_idname = "libfx.param_reset"
    bl_label = "Reset Parameter"
    bl_description = "Forget this value: the effect's default and the quality preset decide it again"
    bl_options = {"REGISTER", "UNDO", "INTERNAL"}
    param: StringProperty()

    def execute(self, context):
        item = _active(context)
        group = props.effect_group(item) if item else None
        if group is not None:
            group.property_unset(self.param)
        _changed(context)
        return {"FINISHED"}


class LIBFX_OT_mask_name_add(bpy.types.Operator):
    bl_idname = "libfx.mask_name_add"
    bl_label = "Add Name"
    bl_description = "Add a material or object to the mask"
    bl_options = {"REGISTER", "UNDO", "INTERNAL"}
    kind: StringProperty()

    def execute(self, context):
        item = _active(context)
        if item is not None:
            getattr(item, self.kind).add()
        return {"FINISHED"}


class LIBFX_OT_mask_name_remove(bpy.types.Operator):
    bl_idname = "libfx.mask_name_remove"
    bl_label = "Remove Name"
    bl_description = "Remove this name from the mask"
    bl_options = {"REGISTER", "UNDO", "INTERNAL"}
    kind: StringProperty()
    index: IntProperty()

    def execute(self, context):
        item = _active(context)
        if item is not None:
            coll = getattr(item, self.kind)
            if 0 <= self.index < len(coll):
                coll.remove(self.index)
        _changed(context)
        return {"FINISHED"}


class LIBFX_OT_recipe_import(bpy.types.Operator, ImportHelper):
    bl_idname = "libfx.recipe_import"
    bl_label = "Import Recipe"
    bl_description = "Replace the stack with a libfx recipe (.json)"
    bl_options = {"REGISTER", "UNDO"}
    filename_ext = ".json"
    filter_glob: StringProperty(default="*.json", options={"HIDDEN"})

    def execute(self, context):
        try:
            with open(self.filepath, encoding="utf-8") as f:
                recipe.from_recipe(context.scene, f.read())
        except (OSError, ValueError, native.LibfxError) as e:
            self.report({"ERROR"}, "%s: %s" % (os.path.basename(self.filepath), e))
            return {"CANCELLED"}
        return {"FINISHED"}


class LIBFX_OT_recipe_export(bpy.types.Operator, ExportHelper):
    bl_idname = "libfx.recipe_export"
    bl_label = "Export Recipe"
    bl_description = "Save the stack as a libfx recipe (.json) for the CLI or another scene"
    filename_ext = ".json"
    filter_glob: StringProperty(default="*.json", options={"HIDDEN"})

    def execute(self, context):
        try:
            text = recipe.to_json_text(context.scene, resolve_paths=False)
            with open(self.filepath, "w", encoding="utf-8") as f:
                f.write(text)
        except (OSError, ValueError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        self.report({"INFO"}, "libfx recipe saved to %s" % self.filepath)
        return {"FINISHED"}


class LIBFX_OT_recipe_text(bpy.types.Operator):
    bl_idname = "libfx.recipe_text"
    bl_label = "Recipe Text"
    bl_description = "Store the stack in (or load it from) the text datablock libfx_recipe.json"
    bl_options = {"REGISTER", "UNDO"}
    action: EnumProperty(items=[("STORE", "Store", "Write the stack into the text"),
                                ("LOAD", "Load", "Replace the stack with the text's recipe")])

    def execute(self, context):
        if self.action == "STORE":
            text = bpy.data.texts.get(recipe.TEXT_NAME) or bpy.data.texts.new(recipe.TEXT_NAME)
            text.clear()
            text.write(recipe.to_json_text(context.scene, resolve_paths=False))
            return {"FINISHED"}
        try:
            if not recipe.load_text_block(context.scene, force=True):
                self.report({"ERROR"}, "no text datablock '%s'" % recipe.TEXT_NAME)
                return {"CANCELLED"}
        except (ValueError, native.LibfxError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        return {"FINISHED"}


def _passes_on_disk(scene):
    return os.path.exists(scene_setup.passes_path(scene, scene.frame_current))


def _ensure_sidecar(context):
    """The current frame's scene sidecar (frame_change_post has not run for it when the
    file was just opened)."""
    scene = context.scene
    if (scene.name, scene.frame_current) not in render.SIDECARS:
        render.on_frame_change_post(scene, context.evaluated_depsgraph_get())


class LIBFX_OT_rerun(bpy.types.Operator):
    bl_idname = "libfx.rerun"
    bl_label = "Apply to Last Render"
    bl_description = ("Run the stack again on the passes rendered for the current frame, from "
                      "memory or from its passes file, and write the results")

    @classmethod
    def poll(cls, context):
        s = context.scene
        return scene_setup.has_stack(s) and (live.has_frame(s) or _passes_on_disk(s))

    def execute(self, context):
        scene = context.scene
        frame = scene.frame_current
        _ensure_sidecar(context)
        if not _passes_on_disk(scene):
            live.changed(scene)   # only in memory: a live run of the held frame
            return {"FINISHED"}
        if bpy.app.background:   # no UI to keep responsive: done when the operator returns
            rec = render.process_frame(scene, frame)
            if not rec["ok"]:
                self.report({"ERROR"}, "libfx: %s" % rec["error"])
                return {"CANCELLED"}
            return {"FINISHED"}
        # read, stack and write on the worker: the UI never waits for them
        render.process_frame(scene, frame, hold=scene.libfx.live, show=True, in_background=True)
        self.report({"INFO"}, "libfx: running the stack on frame %d" % frame)
        return {"FINISHED"}


class LIBFX_OT_render_views(bpy.types.Operator):
    bl_idname = "libfx.render_views"
    bl_label = "Render Views"
    bl_description = ("Render the extra views the stack reads (a light's shadow view, the rain map, "
                      "the mirrors' probes and planar views) for the current frame, beside the output: "
                      "F12 uses them (it cannot render them itself); reused while nothing moves")

    @classmethod
    def poll(cls, context):
        return scene_setup.has_stack(context.scene) and bool(scene_setup.status(context.scene).get("aux_views"))

    def invoke(self, context, event):
        """From the panel: in a background Blender (views_job), the UI stays free."""
        try:
            views_job.start(context.scene)
        except Exception as e:   # one job at a time; a file that cannot be copied
            self.report({"ERROR"}, "libfx: views: %s" % e)
            return {"CANCELLED"}
        self.report({"INFO"}, "libfx: rendering the views of frame %d in the background"
                    % context.scene.frame_current)
        return {"FINISHED"}

    def execute(self, context):
        """From a script (or headless): here, and done when it returns."""
        scene = context.scene
        try:
            views = aux_views.prepare(scene, [scene.frame_current])
        except Exception as e:   # a failed Cycles render, an unwritable folder
            self.report({"ERROR"}, "libfx: views: %s" % e)
            return {"CANCELLED"}
        self.report({"INFO"}, "libfx: %d view(s) ready: %s" % (len(views), ", ".join(v["name"] for v in views)))
        return {"FINISHED"}


class LIBFX_OT_live_load(bpy.types.Operator):
    bl_idname = "libfx.live_load"
    bl_label = "Load Passes"
    bl_description = ("Hold the current frame's passes file in memory and show its result; "
                      "changes then re-run the stack live")

    @classmethod
    def poll(cls, context):
        return scene_setup.has_stack(context.scene) and _passes_on_disk(context.scene)

    def execute(self, context):
        scene = context.scene
        _ensure_sidecar(context)
        scene.libfx.live = True
        live.start(scene)
        return {"FINISHED"}


class LIBFX_OT_restore_scene(bpy.types.Operator):
    bl_idname = "libfx.restore_scene"
    bl_label = "Undo Scene Changes"
    bl_description = "Turn off the passes the add-on turned on (and remove the compositor nodes of earlier versions)"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        scene_setup.restore(context.scene)
        return {"FINISHED"}


class LIBFX_OT_report(bpy.types.Operator):
    bl_idname = "libfx.report"
    bl_label = "libfx Report"
    bl_options = {"INTERNAL"}
    kind: StringProperty(default="INFO")
    message: StringProperty()

    def invoke(self, context, event):
        return self.execute(context)

    def execute(self, context):
        self.report({self.kind if self.kind in {"INFO", "WARNING", "ERROR"} else "INFO"}, self.message)
        return {"FINISHED"}


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
    live.refresh_if_stale(context.scene)
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


unsupported_classes = (LIBFX_PT_unsupported,)

classes = (
    LIBFX_OT_stack_add, LIBFX_OT_stack_remove, LIBFX_OT_stack_duplicate, LIBFX_OT_stack_move,
    LIBFX_OT_param_reset, LIBFX_OT_mask_name_add, LIBFX_OT_mask_name_remove,
    LIBFX_OT_recipe_import, LIBFX_OT_recipe_export, LIBFX_OT_recipe_text, LIBFX_OT_rerun,
    LIBFX_OT_live_load, LIBFX_OT_render_views,
    LIBFX_OT_restore_scene, LIBFX_OT_report,
    LIBFX_UL_stack, LIBFX_MT_add, LIBFX_PT_output, LIBFX_PT_compositor,
)
