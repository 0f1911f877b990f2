"""libfx: render effects over Blender's passes, applied after F12 and batch renders.

The effects live in the C library (libfx.so.2 / libfx.dll, bound in native.py); this add-on
builds its UI from the library's own descriptions, enables the passes the
stack needs, writes them from the Render Result to one EXR (passes_file.py) and
runs the stack after each rendered frame.  See docs/addon.md; its modules stand in
layers that only look down (docs/architecture.md, "The add-on's layers";
tests/check_addon_layers.py checks it), changes go up through hooks.py.
"""

bl_info = {
    "name": "libfx",
    "author": "libfx authors",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "Properties > Output > libfx Effects; Compositor > Sidebar > libfx",
    "description": "Render effects (blur, pixelate, mirrors...) over the render passes, after each render",
    "doc_url": "https://example.invalid/libfx/docs/addon.md",
    "category": "Render",
}

# Reload guard (F3 > Reload Scripts, or register() twice): reload submodules in
# dependency order, bottom layer first, so that no class of an old copy survives
# (tests/check_addon_layers.py checks that this list names every module, in order).
if "native" in locals():
    import importlib
    for _m in ("log", "hooks", "native", "compat", "catalog", "frames",
               "recipe_json", "sessions",
               "props", "recipe", "scene_setup", "passes_file", "aux_views", "sidecars", "contact_sheet",
               "shared_context", "worker", "ui_queue", "results",
               "live", "pipeline", "views_job",
               "handlers", "operators", "ui", "render"):
        if _m in locals():
            importlib.reload(locals()[_m])

import bpy  # noqa: E402

from . import (log, hooks, native, compat, catalog, frames,  # noqa: E402,F401
               recipe_json, sessions,
               props, recipe, scene_setup, passes_file, aux_views, sidecars, contact_sheet,
               shared_context, worker, ui_queue, results,
               live, pipeline, views_job,
               handlers, operators, ui, render)

_registered = []


def register():
    if _registered:
        unregister()
    problem = compat.version_problem()
    if problem:
        # Only a panel that says so: the rest of the add-on speaks an API this Blender
        # may not have.
        print("libfx: " + problem)
        ui.set_unsupported(problem)
        for cls in ui.unsupported_classes:
            bpy.utils.register_class(cls)
            _registered.append(cls)
        return
    ui.set_unsupported(None)
    cat = catalog.Catalog.load()
    if not cat.ok:
        print("libfx: " + cat.error)
    props.register(cat)
    for cls in operators.classes + ui.classes:
        bpy.utils.register_class(cls)
        _registered.append(cls)
    ui.register()
    live.register()
    handlers.register()


def unregister():
    if ui.UNSUPPORTED:
        for cls in reversed(_registered):
            bpy.utils.unregister_class(cls)
        _registered.clear()
        ui.set_unsupported(None)
        return
    handlers.unregister()
    live.unregister()
    shared_context.free()
    views_job.unregister()
    ui.unregister()
    for cls in reversed(_registered):
        try:
            bpy.utils.unregister_class(cls)
        except RuntimeError:
            pass
    _registered.clear()
    props.unregister()
    scene_setup.forget()
    hooks.clear()
