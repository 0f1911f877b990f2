"""The panel's Render Views operator (libfx.render_views), in `blender -b` on the atrium: the
status lists the views the stack reads; a render before them fails naming the missing view;
after the operator the views are on disk and the same render runs the whole stack (F12 reads
views from disk: it cannot render them from inside a render)."""
import os
import shutil
import subprocess

import pytest

import addon_testlib as T

BLEND = T.SCENES_DIR / "atrium" / "atrium.blend"

# the atrium at 96x54, 1 sample; the script is formatted with the output prefix
SETUP = T.PRELUDE + r"""
import os, time
from libfx import render, scene_setup, views_job
render.on_load_post()
s = bpy.context.scene
s.render.filepath = %r
s.render.resolution_x, s.render.resolution_y, s.render.resolution_percentage = 96, 54, 100
s.cycles.samples = 1
scene_setup.sync(s)
"""

SCRIPT = SETUP + r"""
views = scene_setup.status(s).get("aux_views")
assert views == ["light:Sun", "rain_map"], views
bpy.ops.render.render()
rec = render.RESULTS[(s.name, s.frame_current)]
assert not rec["ok"] and "light:Sun" in rec["error"], rec
assert bpy.ops.libfx.render_views() == {"FINISHED"}
render.RESULTS.clear()
bpy.ops.render.render()
rec = render.RESULTS[(s.name, s.frame_current)]
assert rec["ok"], rec
print("VIEWS OK")
"""


def test_render_views_then_render(blender, library, tmp_path):
    assert BLEND.is_file(), "%s is committed beside make_atrium.py" % BLEND
    p = T.run_blender([], env=T.addon_env(library), blend=BLEND, python_expr=SCRIPT % str(tmp_path / "a_"),
                      timeout=400)
    out = p.stdout + p.stderr
    assert p.returncode == 0 and "VIEWS OK" in out, out[-4000:]
    assert (tmp_path / "a_libfx_aux_light_Sun.exr").is_file() and (tmp_path / "a_libfx_aux_rain_map.json").is_file()
    assert any(tmp_path.glob("a_libfx.[0-9]*.exr"))   # the result of the second render


BACKGROUND = SETUP + r"""
prefix = scene_setup.output_prefix(s)
job = views_job.start(s)
# start() hands the renders to another Blender and returns: nothing is rendered yet here
assert job.poll() is None and job.proc.pid != os.getpid(), job.result
assert not os.path.exists(prefix + "libfx_aux_light_Sun.exr")
try:
    views_job.start(s)
    raise AssertionError("a second job started while one runs")
except RuntimeError as e:
    assert "already" in str(e), e
end = time.monotonic() + 300
while job.poll() is None and time.monotonic() < end:
    time.sleep(0.1)
ok, msg = job.poll()
assert ok and "light:Sun" in msg and "rain_map" in msg, msg
assert "Views: 2 ready" in views_job.status_line(), views_job.status_line()
assert not os.path.exists(job._dir), os.listdir(job._dir)   # the file's copy is gone
bpy.ops.render.render()
rec = render.RESULTS[(s.name, s.frame_current)]
assert rec["ok"], rec
# a job that fails says why: an output folder that cannot be made
s.render.filepath = "/proc/libfx_no_such_dir/a_"
job = views_job.start(s)
while job.poll() is None:
    time.sleep(0.1)
ok, msg = job.poll()
assert not ok and msg, msg
print("BACKGROUND VIEWS OK", msg)
"""


def test_render_views_in_a_background_blender(blender, library, tmp_path):
    """The panel's path: the views render in a background Blender on a copy of the file;
    the calling Blender gets the job back at once, polls it, and F12 then finds the views."""
    p = T.run_blender([], env=T.addon_env(library), blend=BLEND, python_expr=BACKGROUND % str(tmp_path / "b_"),
                      timeout=400)
    out = p.stdout + p.stderr
    assert p.returncode == 0 and "BACKGROUND VIEWS OK" in out, out[-4000:]
    assert (tmp_path / "b_libfx_aux_light_Sun.exr").is_file() and (tmp_path / "b_libfx_aux_rain_map.json").is_file()


@pytest.mark.skipif(not shutil.which("xvfb-run"), reason="xvfb-run is not installed")
def test_render_views_button_keeps_the_ui_running(blender, library, tmp_path):
    """With a window: the button's path renders in the background while the UI's timers run."""
    cmd = ["xvfb-run", "-a", "-s", "-screen 0 1280x720x24", T.blender_path(), "--factory-startup", str(BLEND),
           "--python", str(T.REPO / "tests" / "blender" / "ui_render_views.py"), "--", str(tmp_path / "u_")]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=400, env=dict(os.environ, **T.addon_env(library)))
    out = p.stdout + p.stderr
    assert p.returncode == 0 and "UI VIEWS OK" in out, out[-4000:]
