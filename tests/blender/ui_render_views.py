"""Render Views from the panel, in a Blender with a window (run under xvfb by
test_render_views.py): the button's path (the operator's invoke) hands the Cycles
renders to a background Blender, and the UI's event loop keeps running meanwhile.

    xvfb-run -a blender --factory-startup blend_scenes/atrium/atrium.blend \
        --python tests/blender/ui_render_views.py -- OUTPUT_PREFIX

Prints "UI VIEWS OK ..." and exits 0 when the views were made with the event loop
turning while they rendered; exits 1 otherwise.
"""
import os
import sys
import time

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(HERE)), "addon"))
import libfx  # noqa: E402

PREFIX = sys.argv[sys.argv.index("--") + 1]
state = {"phase": "setup", "ticks": 0, "t0": 0.0}


def finish(ok, msg):
    print(("UI VIEWS OK " if ok else "UI VIEWS FAILED ") + msg)
    sys.stdout.flush()
    os._exit(0 if ok else 1)


def step():
    try:
        if state["phase"] == "setup":
            libfx.register()
            libfx.render.on_load_post()
            s = bpy.context.scene
            s.render.filepath = PREFIX
            s.render.resolution_x, s.render.resolution_y, s.render.resolution_percentage = 96, 54, 100
            s.cycles.samples = 1
            libfx.scene_setup.sync(s)
            win = bpy.context.window_manager.windows[0]
            with bpy.context.temp_override(window=win):
                res = bpy.ops.libfx.render_views("INVOKE_DEFAULT")
            if res != {"FINISHED"} or not libfx.views_job.running():
                finish(False, "the operator did not start a background job: %s" % res)
            state.update(phase="wait", t0=time.monotonic())
            return 0.02
        # The event loop turns while the views render: this timer keeps firing.
        if libfx.views_job.running():
            state["ticks"] += 1
            if time.monotonic() - state["t0"] > 240:
                finish(False, "no result in 240 s")
            return 0.02
        ok, msg = libfx.views_job.STATE["job"].poll()
        if not ok:
            finish(False, msg)
        if state["ticks"] < 3:
            finish(False, "the UI's timers ran %d times while the views rendered" % state["ticks"])
        missing = [p for p in ("light_Sun.exr", "rain_map.exr") if not os.path.exists(PREFIX + "libfx_aux_" + p)]
        if missing:
            finish(False, "views missing: %s" % missing)
        finish(True, "%s; %d timer passes while they rendered (%.1f s); panel: %s"
               % (msg, state["ticks"], time.monotonic() - state["t0"], libfx.views_job.status_line()))
    except Exception as e:
        import traceback
        traceback.print_exc()
        finish(False, "%s: %s" % (type(e).__name__, e))


bpy.app.timers.register(step, first_interval=0.5)
