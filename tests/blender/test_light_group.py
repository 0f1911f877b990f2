"""vsm_shadows' apply light_group: the add-on makes the light group the library asks for
(blender_settings "lightgroup:libfx_light"), puts the shadowed light in it, Blender writes
its pass Combined_libfx_light through the File Output node, and the add-on undoes it all
when the stack no longer needs it (Blender 3.2+)."""
import json

import numpy as np

import addon_testlib as T

SUN = ("import bpy\n"
       "ob = bpy.data.objects['Light']\n"
       "ob.data.type = 'SUN'\n"
       "ob.data.energy = 3.0\n"
       "sc = bpy.context.scene\n"
       "sc.render.engine = 'CYCLES'\n"
       "sc.cycles.use_denoising = False\n")
RECIPE = {"version": 1, "effects": [{"effect": "vsm_shadows", "params": {"light": "Light", "apply": "light_group"}}]}


def test_sync_makes_and_restores_the_light_group(blender, library):
    script = T.PRELUDE + SUN + """
from libfx import recipe, scene_setup
vl = sc.view_layers[0]
assert len(vl.lightgroups) == 0 and ob.lightgroup == ''
recipe.from_recipe(sc, %r)
req = scene_setup.sync(sc)
assert 'lightgroup:libfx_light' in req['blender_settings'], req
assert 'Combined_libfx_light' in req['passes'], req
assert [g.name for g in vl.lightgroups] == ['libfx_light'], list(vl.lightgroups)
assert ob.lightgroup == 'libfx_light', ob.lightgroup
assert not scene_setup.status(sc).get('warnings'), scene_setup.status(sc)
# sun_direct needs no group: the add-on's group goes, the light's old one comes back
sc.libfx.stack[0].enabled = False
scene_setup.sync(sc)
assert len(vl.lightgroups) == 0 and ob.lightgroup == '', (list(vl.lightgroups), ob.lightgroup)
sc.libfx.stack[0].enabled = True
scene_setup.sync(sc)
assert ob.lightgroup == 'libfx_light'
from libfx import compat
sc.render.engine = compat.eevee_engine()
scene_setup.sync(sc)
assert any('light group' in w for w in scene_setup.status(sc).get('warnings', [])), scene_setup.status(sc)
sc.render.engine = 'CYCLES'
scene_setup.restore(sc)
assert len(vl.lightgroups) == 0 and ob.lightgroup == ''
print('LIGHT_GROUP_OK')
""" % (RECIPE,)
    proc = T.run_blender([], env=T.addon_env(library), python_expr=script)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0 and "LIGHT_GROUP_OK" in out, out[-4000:]
    assert not T.tracebacks(out), out[-4000:]


def test_batch_writes_the_light_group_pass(blender, library, tmp_path):
    T.need_oiio()
    r = tmp_path / "r.json"
    r.write_text(json.dumps(RECIPE))
    proc = T.run_blender([], env=T.addon_env(library), python_expr=SUN, python=T.BATCH,
                         script_args=["--keep-passes", "--frames", "1", "--output", tmp_path / "o_",
                                      "--resolution", "64x36", "--samples", "2", "--recipe", r])
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-4000:]
    assert not T.tracebacks(out), out[-4000:]
    exr = T.Exr(tmp_path / "o_libfx_passes.0001.exr")
    assert "Combined_libfx_light" in exr.passes(), exr.passes()
    lg, comb = exr.get("Combined_libfx_light", "RGB"), exr.get("Combined", "RGB")
    # the Sun's own share: some light, never more than the whole (the world adds the rest)
    assert np.isfinite(lg).all() and lg.mean() > 0.01, lg.mean()
    assert (lg <= comb + 1e-3).mean() > 0.99
    assert (tmp_path / "o_libfx.0001.exr").is_file()
