"""libfx: render effects over Blender's passes, applied after F12 and batch renders.

The effects live in the C library (libfx.so.2 / libfx.dll, bound in native.py); this add-on
builds its UI from the library's own descriptions, enables the passes the
stack needs, writes them from the Render Result to one EXR (passes_file.py) and
runs the stack after each rendered frame.  See docs/addon.md.
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
# dependency order so that no class of an old copy survives.
if "native" in locals():
    import importlib
    for _m in ("compat", "native", "catalog", "props", "recipe", "scene_setup", "aux_views", "render", "live", "views_job", "ui"):
        if _m in locals():
            importlib.reload(locals()[_m])

import bpy  # noqa: E402

from . import compat, native, catalog, props, recipe, scene_setup, aux_views, render, live, views_job, ui  # noqa: E402,F401

_registered = []


def register():
    if _registered:
        unregister()
    problem = compat.version_problem()
    if problem:
        # Only a panel that says so: the rest of the add-on speaks an API this Blender
        # may not have.
        print("libfx: " + problem)
        ui.UNSUPPORTED[:] = [problem]
        for cls in ui.unsupported_classes:
            bpy.utils.register_class(cls)
            _registered.append(cls)
        return
    ui.UNSUPPORTED.clear()
    cat = catalog.Catalog.load()
    if not cat.ok:
        print("libfx: " + cat.error)
    props.register(cat)
    for cls in ui.classes:
        bpy.utils.register_class(cls)
        _registered.append(cls)
    render.register()


def unregister():
    if ui.UNSUPPORTED:
        for cls in reversed(_registered):
            bpy.utils.unregister_class(cls)
        _registered.clear()
        ui.UNSUPPORTED.clear()
        return
    render.unregister()
    views_job.unregister()
    for cls in reversed(_registered):
        try:
            bpy.utils.unregister_class(cls)
        except RuntimeError:
            pass
    _registered.clear()
    props.unregister()
    scene_setup.forget()
