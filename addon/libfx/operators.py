"""The add-on's operators: the stack (add, remove, duplicate, move, reset a parameter, mask
names), recipes (import, export, the text datablock), Apply to Last Render, Render Views,
Load Passes, Undo Scene Changes and the report the UI queue shows errors with.

A stack change is announced with the "stack_changed" notice (hooks.py): the handlers sync
the passes and the live loop re-runs, as for a property edited in the panel.
"""

import os

import bpy
from bpy.props import EnumProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ExportHelper, ImportHelper

from . import aux_views, handlers, hooks, live, native, pipeline, props, recipe, scene_setup, sidecars, views_job

_settings = props.settings_of
_active = props.active_item


def _changed(context):
    hooks.notify("stack_changed", context.scene)


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
    if not sidecars.known(scene.name, scene.frame_current):
        handlers.on_frame_change_post(scene, context.evaluated_depsgraph_get())


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
            rec = pipeline.process_frame(scene, frame)
            if not rec["ok"]:
                self.report({"ERROR"}, "libfx: %s" % rec["error"])
                return {"CANCELLED"}
            return {"FINISHED"}
        # read, stack and write on the worker: the UI never waits for them
        pipeline.process_frame(scene, frame, hold=scene.libfx.live, show=True, in_background=True)
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


classes = (
    LIBFX_OT_stack_add, LIBFX_OT_stack_remove, LIBFX_OT_stack_duplicate, LIBFX_OT_stack_move,
    LIBFX_OT_param_reset, LIBFX_OT_mask_name_add, LIBFX_OT_mask_name_remove,
    LIBFX_OT_recipe_import, LIBFX_OT_recipe_export, LIBFX_OT_recipe_text, LIBFX_OT_rerun,
    LIBFX_OT_live_load, LIBFX_OT_render_views,
    LIBFX_OT_restore_scene, LIBFX_OT_report,
)
