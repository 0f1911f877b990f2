"""Checks a mirror-room frame the batch runner wrote: every masked mirror changed, nothing
outside the mirrors changed (bit for bit), alpha kept, all finite.

    python3 tests/platform/check_mirror_room.py PREFIX     (PREFIX as given to --output)
"""
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "blender"))
import addon_testlib as T  # noqa: E402


def main(prefix):
    recipe = T.read_json(prefix + "libfx_recipe.json")
    entries = [e for e in recipe["effects"] if e.get("enabled", True)]
    assert entries and all(e["effect"] == "ssr_mirror" for e in entries), entries
    plain = T.Exr(prefix + "libfx_passes.0001.exr")
    res = T.Exr(prefix + "libfx.0001.exr")
    before = plain.get("Combined", "RGBA")
    after = res.get("Combined", "RGBA")
    assert np.isfinite(after).all(), "non-finite output"
    assert np.array_equal(before[..., 3], after[..., 3]), "alpha changed"
    union = np.zeros(before.shape[:2], dtype=bool)
    changed = np.any(after != before, axis=-1)
    delta = np.abs(after - before)[..., :3].mean(-1)
    for e in entries:
        m = T.mask_support(plain, e["mask"])
        assert m is not None and m.sum() > 50, e["mask"]
        union |= m
        assert float(delta[m].mean()) > 0.001, ("mirror barely changed", e["mask"], float(delta[m].mean()))
    outside = int((changed & ~union).sum())
    assert outside == 0, "%d pixels outside the mirrors changed" % outside
    print("mirror room: %d mirrors changed, %d pixels inside them differ, none outside"
          % (len(entries), int((changed & union).sum())))


if __name__ == "__main__":
    main(sys.argv[1])
