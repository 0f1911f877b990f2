"""The Greek bath through the add-on, headless: caustics change the pool (and only the
water), the rays brighten the hall around the sun's direction (never darken anything),
the statue is censored into flat cells that stay on it while the camera moves.

    /usr/bin/python3 -m pytest tests/blender/test_greek_bath.py
"""
import numpy as np
import pytest

import addon_testlib as T

BLEND = T.SCENES_DIR / "greek_bath" / "greek_bath.blend"
RES = (320, 180)


def batch(prefix, library, frames="1,8"):
    return T.run_blender([], blend=BLEND, env=T.addon_env(library), python=T.BATCH,
                         script_args=["--keep-passes", "--frames", frames, "--output", prefix, "--resolution",
                                      "%dx%d" % RES, "--samples", 4], timeout=600)


def project_sun(side):
    """Screen position (pixels) of the sun from the sidecar's camera and light."""
    w2c = np.array(side["world_to_camera"], dtype=np.float64)
    proj = np.array(side["projection"], dtype=np.float64)
    sun = [l for l in side["lights"] if l["name"] == "Sun"][0]
    d = -np.array(sun["direction"], dtype=np.float64)
    v = w2c[:3, :3] @ d
    c = proj @ np.array([v[0], v[1], v[2], 0.0])
    assert c[3] > 0, "the sun is behind the camera in this scene?"
    nx, ny = c[0] / c[3], c[1] / c[3]
    return (nx + 1) * 0.5 * RES[0], (1 - ny) * 0.5 * RES[1]


@pytest.mark.skipif(not BLEND.is_file(), reason="no greek_bath.blend")
def test_greek_bath_stack(blender, library, tmp_path):
    T.need_oiio()
    prefix = str(tmp_path / "bath_")
    proc = batch(prefix, library)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-5000:]
    assert not T.tracebacks(out), out[-5000:]
    ran = T.read_json(tmp_path / "bath_libfx_recipe.json")
    assert [e["effect"] for e in ran["effects"]] == ["voronoi_caustics", "god_rays", "pixelate"]

    statue_cells = {}
    for frame in (1, 8):
        plain = T.Exr(tmp_path / ("bath_libfx_passes.%04d.exr" % frame))
        res = T.Exr(tmp_path / ("bath_libfx.%04d.exr" % frame))
        side = T.read_json(tmp_path / ("bath_libfx.%04d.camera.json" % frame))
        before = plain.get("Combined", "RGB").astype(np.float64)
        after = res.get("Combined", "RGB").astype(np.float64)
        assert np.isfinite(after).all()
        water = T.crypto_support(plain, "CryptoMaterial", ["Water"])
        statue = T.crypto_support(plain, "CryptoObject", ["Statue"])
        assert water.sum() > 2000 and statue.sum() > 100, (water.sum(), statue.sum())
        lum_b = before @ [0.2126, 0.7152, 0.0722]
        lum_a = after @ [0.2126, 0.7152, 0.0722]

        # The pool: the caustics change most water pixels, both ways (light redistributed).
        core = water & ~statue
        d = lum_a[core] - lum_b[core]
        assert (np.abs(d) > 0.01).mean() > 0.5, (np.abs(d) > 0.01).mean()
        assert (d > 0.02).any() and (d < -0.02).any()

        # Outside the water and the statue only the rays act: additive, never darker.
        rest = ~water & ~statue
        assert (after[rest] >= before[rest] - 1e-5).all()

        # The rays: brighter near the sun's screen position than far from it, and they
        # reach well beyond the sky (into the hall below the colonnade).
        sx, sy = project_sun(side)
        assert 0 <= sx < RES[0] and 0 <= sy < RES[1], (sx, sy)
        yy, xx = np.mgrid[0:RES[1], 0:RES[0]]
        dist = np.hypot(xx + 0.5 - sx, yy + 0.5 - sy)
        gain = (lum_a - lum_b)
        near = rest & (dist < 40)
        far = rest & (dist > 120)
        assert gain[near].mean() > 3 * max(gain[far].mean(), 1e-6), (gain[near].mean(), gain[far].mean())
        depth = plain.get("Depth", T.exr_single_channel(plain, "Depth"))[..., 0]
        hall = rest & (depth < 100) & (yy > sy + 20)   # surfaces below the sun: floor, columns
        assert (gain[hall] > 0.01).mean() > 0.2, (gain[hall] > 0.01).mean()

        # The statue: flat cells (few distinct colours) inside its silhouette (its edge
        # pixels are blended with the background by their coverage).
        inner = statue.copy()
        inner[1:, :] &= statue[:-1, :]
        inner[:-1, :] &= statue[1:, :]
        inner[:, 1:] &= statue[:, :-1]
        inner[:, :-1] &= statue[:, 1:]
        cols = after[inner]
        distinct = len(np.unique(np.round(cols, 6), axis=0))
        assert inner.sum() > 50 and distinct < inner.sum() / 6, (distinct, inner.sum())
        statue_cells[frame] = distinct
    assert statue_cells[1] > 0 and statue_cells[8] > 0
