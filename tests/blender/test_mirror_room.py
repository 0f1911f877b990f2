"""The mirror room renders headless through the add-on with its ssr_mirror stack (every
mirror kind) and each mirror region changes as its entry specifies. At final (the recipe's
quality) each flat, sharp mirror gets its planar view at twice the render's samples
(ssr_mirror's planar_samples 2), the curved ones are listed as absent, and no missing view
is warned of."""
import re

import numpy as np
import pytest

import addon_testlib as T

BLEND = T.SCENES_DIR / "mirror_room" / "mirror_room.blend"


@pytest.mark.skipif(not BLEND.is_file(), reason="no mirror_room.blend")
def test_mirror_room_ssr(blender, library, tmp_path):
    T.need_oiio()
    prefix = str(tmp_path / "mr_")
    proc = T.run_blender([], blend=BLEND, env=T.addon_env(library), python=T.BATCH,
                         script_args=["--keep-passes", "--frames", "1", "--output", prefix, "--resolution", "320x180",
                                      "--samples", "4"], timeout=400)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-5000:]
    # planar views: the flat mirrors that are sharp, plain or with a colour operator but not
    # cel (blurred, cel and bent read none), each plane of the pair its own, 2x the samples
    planar = re.findall(r"planar '[^']+' at the plane of (.+?) rendered (\d+)x(\d+) \((\d+) samples\)", out)
    assert sorted(p[0] for p in planar) == ["Mirror_Clear", "Mirror_FacingA", "Mirror_FacingB", "Mirror_Fresnel",
                                            "Mirror_Grayscale", "Mirror_Low", "Mirror_Sepia"], planar
    assert all(p[1:] == ("320", "180", "8") for p in planar), planar
    aux = T.read_json(tmp_path / "mr_libfx.0001.camera.json")["aux_views"]
    # each planar view file is its mirror's region, placed in the 320x180 view by its window
    for v in aux:
        if v["name"].startswith("planar:") and "absent" not in v:
            x0, y0, w, h = v["window"]
            exr = T.Exr(v["path"])
            assert (w, h) == (320, 180) and x0 + exr.width <= w and y0 + exr.height <= h, (v["window"], exr.width)
            assert exr.width * exr.height < 0.5 * w * h, (v["name"], exr.width, exr.height)
    absent = [v for v in aux if "absent" in v]
    assert len(absent) == 2 and all("not flat" in v["absent"] and v["name"].startswith("planar:") for v in absent), \
        absent
    assert "no planar mirror view" not in out, out[-3000:]
    recipe = T.read_json(tmp_path / "mr_libfx_recipe.json")
    entries = [e for e in recipe["effects"] if e.get("enabled", True)]
    # ten entries: one per mirror kind, the facing pair as one entry over both panels
    assert len(entries) == 10 and all(e["effect"] == "ssr_mirror" for e in entries)
    plain = T.Exr(tmp_path / "mr_libfx_passes.0001.exr")
    res = T.Exr(tmp_path / "mr_libfx.0001.exr")
    before = plain.get("Combined", "RGBA")
    after = res.get("Combined", "RGBA")
    assert np.isfinite(after).all()
    assert np.array_equal(before[..., 3], after[..., 3]), "alpha changed"

    def key(e):
        m = e["mask"]["material"]
        return m if isinstance(m, str) else "+".join(m)
    masks = {key(e): T.mask_support(plain, e["mask"]) for e in entries}
    assert "Mirror_FacingA+Mirror_FacingB" in masks, sorted(masks)
    union = np.zeros(before.shape[:2], dtype=bool)
    for name, m in masks.items():
        assert m is not None and m.sum() > 50, (name, None if m is None else m.sum())
        union |= m
    # nothing outside the mirrors changes, bit for bit
    changed = np.any(after != before, axis=-1)
    assert not (changed & ~union).any(), "%d pixels outside the mirrors changed" % (changed & ~union).sum()

    delta = np.abs(after - before)[..., :3].mean(-1)
    mean = {n: float(delta[m].mean()) for n, m in masks.items()}
    # every mirror shows something (a reflection replaced part of its backing)
    for n, v in mean.items():
        assert v > 0.001, "%s barely changed (mean |delta| %.4f)" % (n, v)
    # low reflectivity (0.25) changes its mirror much less than the clear one
    assert mean["Mirror_Low"] < 0.6 * mean["Mirror_Clear"], mean
    # grayscale: the changed pixels are grey; sepia: R >= G >= B where changed
    g = masks["Mirror_Grayscale"] & changed
    rgb = after[..., :3]
    spread = rgb.max(-1) - rgb.min(-1)
    assert g.sum() > 30 and np.median(spread[g]) < 0.02 * max(1e-3, float(np.median(rgb[g].max(-1)))) + 1e-4, \
        np.median(spread[g])
    s = masks["Mirror_Sepia"] & changed
    ok = (rgb[..., 0] >= rgb[..., 1] - 1e-4) & (rgb[..., 1] >= rgb[..., 2] - 1e-4)
    assert s.sum() > 30 and ok[s].mean() > 0.9, ok[s].mean()
    # Fresnel (f0 0.04): head-on the mirror keeps most of its backing: smaller change than clear
    assert mean["Mirror_Fresnel"] < mean["Mirror_Clear"], mean
