"""The panel's Render Views operator (libfx.render_views), in `blender -b` on the atrium: the
status lists the views the stack reads; a render before them fails naming the missing view;
after the operator the views are on disk and the same render runs the whole stack (F12 reads
views from disk: it cannot render them from inside a render)."""
import addon_testlib as T

BLEND = T.SCENES_DIR / "atrium" / "atrium.blend"

SCRIPT = T.PRELUDE + r"""
from libfx import render, scene_setup
render.on_load_post()
s = bpy.context.scene
s.render.filepath = %r
s.render.resolution_x, s.render.resolution_y, s.render.resolution_percentage = 96, 54, 100
s.cycles.samples = 1
scene_setup.sync(s)
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
    if not BLEND.is_file():
        import pytest
        pytest.skip("no atrium.blend")
    p = T.run_blender([], env=T.addon_env(library), blend=BLEND, python_expr=SCRIPT % str(tmp_path / "a_"),
                      timeout=400)
    out = p.stdout + p.stderr
    assert p.returncode == 0 and "VIEWS OK" in out, out[-4000:]
    assert (tmp_path / "a_libfx_aux_light_Sun.exr").is_file() and (tmp_path / "a_libfx_aux_rain_map.json").is_file()
    assert any(tmp_path.glob("a_libfx.[0-9]*.exr"))   # the result of the second render
