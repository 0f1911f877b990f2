"""Blender's app handlers, and the add-on's answer to "the stack changed".

Order (GUIDE §3): ``-b -f/-a``: render_init, then per frame frame_change_post ->
render_pre -> render_post -> render_write, render_complete; all on the main
thread.  F12: no render_write and the handlers run on the render thread, so
anything touching UI data (images, editors, reports) goes through the UI queue
(ui_queue.py).  A handler's exception does not change Blender's exit code:
results are recorded (results.py) and batch.py turns failures into an exit code.

- frame_change_post: the frame's scene sidecar (sidecars.py); scrubbing a held sequence.
- render_init: the scene can run its stack, the passes are set (scene_setup.sync).
- render_post: the frame pipeline (pipeline.after_render).
- render_complete / render_cancel: the datablock the result images were saved through goes.
- load_post: held frames go, recipe texts are imported, parameters migrated.
- undo_post / redo_post: values came back without update callbacks: live re-runs.
- the "stack_changed" notice (hooks.py: props, recipe, operators): the recipe is built once,
  the passes follow it and the live loop runs it.
"""

import bpy
from bpy.app.handlers import persistent

from . import aux_views, compat, hooks, live, native, pipeline, recipe, results, scene_setup, sidecars, ui_queue
from .log import log


# ---------------------------------------------------------------- the stack changed

def stack_changed(scene):
    """A stack setting changed (property update, operator, import): the recipe is built once
    here, the passes follow it and the live loop runs it."""
    try:
        rec = recipe.to_recipe(scene)
    except ValueError:
        rec = None   # sync builds it again and puts the message in the panel
    scene_setup.request_sync(scene, rec)
    live.changed(scene, rec)


# ---------------------------------------------------------------- frames

@persistent
def on_frame_change_post(scene, depsgraph=None):
    if aux_views.busy():
        return  # a depth render of an auxiliary view
    if not scene_setup.has_stack(scene):
        return
    try:
        sidecar = sidecars.frame_sidecar(scene, depsgraph)
    except Exception as e:  # a light as camera, no depsgraph...
        log("frame %d: camera matrices unavailable: %s" % (scene.frame_current, e), err=True)
        return
    if sidecar is not None:
        sidecars.store(scene.name, scene.frame_current, sidecar)
    try:
        live.on_frame_change(scene)   # scrubbing a held sequence (a no-op in batch renders)
    except Exception as e:
        log("live: frame %d: %s" % (scene.frame_current, e), err=True)


# ---------------------------------------------------------------- render

@persistent
def on_render_init(scene, *args):
    if aux_views.busy():
        return  # a depth render of an auxiliary view
    if not scene_setup.has_stack(scene):
        scene_setup.remove_nodes(scene)
        return
    if native.load() is None:
        results.record(scene, scene.frame_current, error=native.load_error())
        return
    problem = scene_setup.scene_problem(scene)
    if problem:
        results.record(scene, scene.frame_current, error=problem)
        return
    req = compat.when_writable(scene_setup.sync, scene)   # F12: on the render thread
    st = scene_setup.status(scene)
    if req is None:
        results.record(scene, scene.frame_current, error="stack cannot run: %s" % st.get("error"))
        return
    if bpy.app.background:   # the UI's are gone at load (on_load_post), off the render thread
        scene_setup.remove_nodes(scene)   # the File Output node of add-ons before passes_file.py
    for w in st.get("warnings", []):
        log("warning: " + w, err=True)
    if scene.camera is not None and not sidecars.known(scene.name, scene.frame_current):
        # F12 of the current frame: the evaluated camera of the current frame.
        try:
            dg = bpy.context.evaluated_depsgraph_get()
            sidecars.store(scene.name, scene.frame_current, sidecars.frame_sidecar(scene, dg))
        except Exception:
            pass


@persistent
def on_render_post(scene, *args):
    if aux_views.busy():
        return  # a depth render of an auxiliary view
    if not scene_setup.has_stack(scene):
        return
    pipeline.after_render(scene, scene.frame_current, ui=not bpy.app.background)


@persistent
def on_render_done(*args):
    """render_complete / render_cancel: the save datablock goes (in the UI on the main
    thread, after the queued saves)."""
    if bpy.app.background:
        pipeline.remove_save_image()
    else:
        ui_queue.to_ui(pipeline.remove_save_image)


# ---------------------------------------------------------------- files, undo

@persistent
def on_load_post(*args):
    live.drop()   # frames held for the scenes of the file that was open
    for scene in bpy.data.scenes:
        if getattr(scene, "libfx", None) is None:
            continue
        try:
            if recipe.load_text_block(scene):
                log("imported the recipe of scene '%s' from the text '%s'" % (scene.name, recipe.TEXT_NAME))
        except Exception as e:
            scene_setup.set_status(scene, error="recipe text: %s" % e)
            log("scene '%s': recipe text %s: %s" % (scene.name, recipe.TEXT_NAME, e), err=True)
        migrate_parameters(scene)
        scene_setup.remove_nodes(scene)   # the File Output node of add-ons before passes_file.py


def migrate_parameters(scene):
    """Effect parameters saved with an older parameter table are migrated by the library
    and written back (recipe.migrate_stack); the panel and the log say so."""
    try:
        notes = recipe.migrate_stack(scene)
    except Exception as e:  # never let a file load fail on it
        notes = ["parameter migration failed: %s: %s" % (type(e).__name__, e)]
    scene_setup.set_status(scene, migrated=notes)
    for note in notes:
        log("scene '%s': warning: %s" % (scene.name, note), err=True)


@persistent
def on_undo_redo(*args):
    """Undo/redo puts values back without update callbacks: re-run live sessions."""
    for scene in bpy.data.scenes:
        if getattr(scene, "libfx", None) is not None:
            live.changed(scene)


HANDLERS = (("frame_change_post", on_frame_change_post),
            ("render_init", on_render_init),
            ("render_post", on_render_post),
            ("render_complete", on_render_done),
            ("render_cancel", on_render_done),
            ("load_post", on_load_post),
            ("undo_post", on_undo_redo),
            ("redo_post", on_undo_redo))


def register():
    unregister()  # a reload must never leave two copies
    for name, fn in HANDLERS:
        getattr(bpy.app.handlers, name).append(fn)
    hooks.listen("stack_changed", stack_changed)


def unregister():
    """Removes only our handlers, also those of an older copy of this module (reload)."""
    hooks.unlisten("stack_changed", stack_changed)
    for name, fn in HANDLERS:
        lst = getattr(bpy.app.handlers, name)
        for h in list(lst):
            if h is fn or (getattr(h, "__module__", "") == fn.__module__ and
                           getattr(h, "__name__", "") == fn.__name__):
                lst.remove(h)
