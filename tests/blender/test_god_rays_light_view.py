"""god_rays method volumetric through the add-on (issue 27): the stack asks for the Sun's
light view only when the method is volumetric, the panel's status lists it, and a batch
render of the god-rays truth room renders the view and adds light (the radial method asks
for no view)."""
import json

import addon_testlib as T

BLEND = T.SCENES_DIR / "truth_godrays" / "truth_godrays_window.blend"
VOL = json.loads((T.SCENES_DIR / "truth_godrays" / "recipe_volumetric.json").read_text())
RADIAL = json.loads((T.SCENES_DIR / "truth_godrays" / "recipe.json").read_text())

STATUS = T.PRELUDE + r"""
from libfx import recipe, scene_setup
s = bpy.context.scene
recipe.from_recipe(s, %r)
scene_setup.sync(s)
radial = scene_setup.status(s).get("aux_views")
recipe.from_recipe(s, %r)
scene_setup.sync(s)
vol = scene_setup.status(s).get("aux_views")
assert not radial and vol == ["light:Sun"], (radial, vol)
print("VIEWS_OK")
"""


def test_only_volumetric_asks_for_the_light_view(blender, library):
    p = T.run_blender([], env=T.addon_env(library), blend=BLEND, python_expr=STATUS % (RADIAL, VOL))
    out = p.stdout + p.stderr
    assert p.returncode == 0 and "VIEWS_OK" in out, out[-4000:]
    assert not T.tracebacks(out), out[-4000:]


def test_batch_renders_the_light_view_and_adds_light(blender, library, tmp_path):
    T.need_oiio()
    r = tmp_path / "r.json"
    r.write_text(json.dumps(VOL))
    p = T.run_blender([], env=T.addon_env(library), blend=BLEND, python=T.BATCH, timeout=400,
                      script_args=["--keep-passes", "--frames", "1", "--output", tmp_path / "v_",
                                   "--resolution", "96x54", "--samples", "2", "--recipe", r])
    out = p.stdout + p.stderr
    assert p.returncode == 0, out[-4000:]
    assert (tmp_path / "v_libfx_aux_light_Sun.exr").is_file(), sorted(x.name for x in tmp_path.iterdir())
    import OpenImageIO as oiio
    import numpy as np

    def combined(path):
        buf = oiio.ImageBuf(str(path))
        spec = buf.spec()
        names = list(spec.channelnames)
        px = buf.get_pixels(oiio.FLOAT)
        idx = [i for i, n in enumerate(names) if "Combined" in n and n[-1] in "RGB"][:3]
        return px[..., idx]
    got = combined(next(tmp_path.glob("v_libfx.[0-9]*.exr")))
    src = combined(tmp_path / "v_libfx_passes.0001.exr")
    assert got.shape == src.shape and np.isfinite(got).all()
    assert got.mean() > 1.5 * src.mean(), (got.mean(), src.mean())   # the lit air (truth: ~4x)
