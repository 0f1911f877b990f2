"""edges output=gradient (Blender's compositor Filter node, type Sobel) through the CLI, against
an independent numpy Sobel: per colour channel sqrt(gx^2 + gy^2) of the unnormalised 3x3 kernels,
neighbours clamped to the image (numpy's "edge" padding), alpha kept, mixed with the pixel by
opacity as Blender's Factor mixes; masks, opacity 0, thread counts, in place vs not, and
non-finite input (the C test test_edges.c feeds raw NaN/Inf; an EXR's are replaced at load).
"""
import json

import numpy as np
import pytest

from conftest import combined, need_oiio, read_exr, write_exr, write_recipe


def sobel_ref(img, fac=1.0):
    """float64 reference: np.pad "edge" (Blender's extended reads), the textbook kernels."""
    h, w = img.shape[:2]
    p = np.pad(img[..., :3].astype(np.float64), ((1, 1), (1, 1), (0, 0)), mode="edge")

    def tap(dy, dx):
        return p[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]

    gx = (tap(-1, -1) + 2 * tap(0, -1) + tap(1, -1)) - (tap(-1, 1) + 2 * tap(0, 1) + tap(1, 1))
    gy = (tap(-1, -1) + 2 * tap(-1, 0) + tap(-1, 1)) - (tap(1, -1) + 2 * tap(1, 0) + tap(1, 1))
    out = img.astype(np.float64).copy()
    out[..., :3] = img[..., :3] * (1.0 - fac) + np.sqrt(gx * gx + gy * gy) * fac
    return out


def sobel_blender_f32(img):
    """Blender 5.2's CPU sums in float32, in its order (see fx_edge_gradient): the same bits.
    P is the row below (Blender's y axis points up), Q the row above."""
    h, w = img.shape[:2]
    p = np.pad(img[..., :3].astype(np.float32), ((1, 1), (1, 1), (0, 0)), mode="edge")

    def tap(dy, dx):
        return p[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]

    P = {d: tap(1, d) for d in (-1, 0, 1)}
    M = {d: tap(0, d) for d in (-1, 0, 1)}
    Q = {d: tap(-1, d) for d in (-1, 0, 1)}
    two = np.float32(2)
    gx = ((((P[-1] - P[1]) + two * M[-1]) - two * M[1]) + Q[-1]) - Q[1]
    gy = ((((P[-1] + two * P[0]) + P[1]) - Q[-1]) - two * Q[0]) - Q[1]
    out = img.astype(np.float32).copy()
    out[..., :3] = np.sqrt(gx * gx + gy * gy)
    return out


def random_rgba(h, w, seed):
    rng = np.random.RandomState(seed)
    img = (rng.rand(h, w, 4) * 2.0 - 0.5).astype(np.float32)   # negatives and HDR too
    img[..., 3] = rng.rand(h, w).astype(np.float32)
    return img


def run_gradient(run, tmp_path, img, params=None, mask=None, threads=2, tag="out"):
    need_oiio()
    src = tmp_path / "in.exr"
    write_exr(src, {"Combined": (img, "RGBA")})
    entry = {"effect": "edges", "params": dict({"output": "gradient"}, **(params or {}))}
    if mask is not None:
        entry["mask"] = mask
    recipe = write_recipe(tmp_path / f"{tag}.json", [entry])
    out = tmp_path / f"{tag}.exr"
    r = run("run", "--stack", recipe, "-j", threads, "--force", src, "-o", out)
    assert r.returncode == 0, r.stderr
    return combined(read_exr(out))


# sizes: single pixels and rows (every neighbour clamped), odd widths (the vector loop's
# tails), enough rows for several bands at 2 and 3 threads (in place: the saved rows)
SIZES = [(1, 1), (1, 2), (3, 1), (2, 3), (23, 37), (40, 64), (203, 19)]


@pytest.mark.parametrize("h,w", SIZES)
def test_matches_numpy_sobel(run, tmp_path, h, w):
    img = random_rgba(h, w, seed=h * 1000 + w)
    out = run_gradient(run, tmp_path, img)
    ref = sobel_ref(img)
    # float32 sums of values up to 1.5: a few ulps of |gx| + |gy| <= 16
    np.testing.assert_allclose(out[..., :3], ref[..., :3], rtol=0, atol=2e-6)
    assert np.array_equal(out[..., 3], img[..., 3])   # alpha kept, bit for bit
    # the same bits as Blender's order of the float sums
    assert np.array_equal(out.view(np.uint32), sobel_blender_f32(img).view(np.uint32))


def test_border_rule_is_extend(run, tmp_path):
    """A step of 2 between columns 0 and 1: clamped neighbours give |gx| = 4 x 2 at both
    (zero padding would give 12 at column 0, mirroring 0), nothing from column 2 on, and no
    vertical response on the top and bottom rows."""
    img = np.zeros((5, 6, 4), np.float32)
    img[..., :3] = 1.0
    img[:, 1:, :3] = 3.0
    img[..., 3] = 0.25
    out = run_gradient(run, tmp_path, img)
    assert np.all(out[:, 0, :3] == 8.0)    # x=0: the left taps clamp to column 0
    assert np.all(out[:, 1, :3] == 8.0)
    assert np.all(out[:, 2:, :3] == 0.0)   # right border clamps to 3: no edge
    assert np.all(out[0, 2:, :3] == 0.0) and np.all(out[-1, 2:, :3] == 0.0)   # top/bottom too
    assert np.all(out[..., 3] == 0.25)


def test_opacity_mixes_and_zero_is_identity(run, tmp_path):
    img = random_rgba(31, 45, seed=7)
    out = run_gradient(run, tmp_path, img, {"opacity": 0.0}, tag="zero")
    assert np.array_equal(out.view(np.uint32), img.view(np.uint32))
    out = run_gradient(run, tmp_path, img, {"opacity": 0.3}, tag="mix")
    np.testing.assert_allclose(out, sobel_ref(img, 0.3), rtol=0, atol=2e-6)
    assert np.array_equal(out[..., 3], img[..., 3])


def test_mask_keeps_unmasked_pixels(run, tmp_path):
    img = random_rgba(40, 52, seed=11)
    out = run_gradient(run, tmp_path, img, mask={"rect": [7, 5, 30, 20]})
    inside = np.zeros(img.shape[:2], bool)
    inside[5:25, 7:37] = True
    assert np.array_equal(out[~inside].view(np.uint32), img[~inside].view(np.uint32))
    ref = sobel_blender_f32(img)   # neighbours read outside the rect too (the image's, not the mask's)
    assert np.array_equal(out[inside].view(np.uint32), ref[inside].view(np.uint32))


def test_threads_and_in_place_same_bits(run, tmp_path):
    """1, 2 and 3 threads (in place: the CLI hands the effect its input) and a mask covering
    the whole frame (the stack then gives a separate output buffer): the same bits."""
    img = random_rgba(157, 83, seed=5)
    runs = [run_gradient(run, tmp_path, img, {"opacity": 0.8}, threads=t, tag=f"j{t}") for t in (1, 2, 3)]
    runs.append(run_gradient(run, tmp_path, img, {"opacity": 0.8}, mask={"rect": [0, 0, 83, 157]}, tag="mask"))
    for o in runs[1:]:
        assert np.array_equal(o.view(np.uint32), runs[0].view(np.uint32))


def test_extreme_input_stays_finite(run, tmp_path):
    """NaN/Inf in an EXR are replaced at load (NaN 0, Inf +-FLT_MAX); FLT_MAX neighbours
    overflow the float sums: those pixels are redone in double and clamped."""
    img = random_rgba(24, 30, seed=3)
    img[3, 4, 0] = np.nan
    img[10, 10, 1] = np.inf
    img[11, 11, 2] = -np.inf
    img[15:17, 20:23, :] = np.float32(3.4e38)
    img[20, 5, 3] = np.nan
    out = run_gradient(run, tmp_path, img)
    assert np.all(np.isfinite(out))
    assert out[16, 23, 0] == np.float32(3.4028235e38)   # next to the FLT_MAX block: clamped
    with np.errstate(invalid="ignore", over="ignore"):
        ref = sobel_blender_f32(img)
    assert np.array_equal(out[0:2, 25:30], ref[0:2, 25:30])   # far from them: as always


def test_operator_must_be_sobel(run, tmp_path):
    need_oiio()
    src = tmp_path / "in.exr"
    write_exr(src, {"Combined": (random_rgba(4, 4, 1), "RGBA")})
    recipe = write_recipe(tmp_path / "r.json", [{"effect": "edges", "params": {"output": "gradient",
                                                                             "operator": "laplace8"}}])
    r = run("run", "--stack", recipe, "--force", src, "-o", tmp_path / "o.exr")
    assert r.returncode != 0
    assert "operator" in r.stderr and "gradient" in r.stderr
