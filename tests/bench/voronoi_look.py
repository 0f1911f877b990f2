"""The Voronoi modes' look against the pool truth (issue 27): before (params_version 2: straight
sides, manual cells) and after (warp, cell_scale auto) on the truth renders that
tests/bench/truth_caustics.py leaves in OUT (run it first). Prints the truth table's
statistics (mean / truth, contrast 4x4, dominant period) per variant and writes
OUT/voronoi_look.png (variants | Cycles, tone-mapped alike).

    LIBFX_CLI=build/libfx/libfx /usr/bin/python3 tests/bench/voronoi_look.py out/truth_ca [--quality final]
"""
import argparse
import json
import os
import subprocess
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import truth_common as C  # noqa: E402
from truth_caustics import stats  # noqa: E402

BASE = {"mode": "physical", "points": 196, "tile_size": 3.0, "strength": 0.8, "line_width": 0.12, "speed": 2.0}
VARIANTS = [
    ("before (params_version 2)", {"warp": 0.0}),
    ("warp 0.3", {"warp": 0.3}),
    ("warp 0.3, cell_scale auto", {"warp": 0.3, "cell_scale": "auto"}),
]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--quality", default="final")
    ap.add_argument("--ratio", type=float, default=None, help="wave_cell_ratio for the auto row")
    a = ap.parse_args()
    cli = os.environ.get("LIBFX_CLI", "build/libfx/libfx")
    # the add-on's render with the water's view (the refractive rows' input): same floor
    passes = os.path.join(a.out, "c_inr_libfx_passes.0001.exr")
    side = os.path.join(a.out, "c_inr_libfx.0001.camera.json")
    truth = C.rgb(os.path.join(a.out, "c_truth_0001.exr"))
    m_per_px = 2.0 / json.load(open(side))["projection"][0][0] / truth.shape[1]
    tmean = stats(truth, m_per_px)[0]
    imgs, rows = [], []
    for name, extra in VARIANTS:
        params = dict(BASE, **extra)
        if a.ratio and "cell_scale" in extra:
            params["wave_cell_ratio"] = a.ratio
        rec = {"version": 1, "quality": a.quality, "effects": [{"effect": "voronoi_caustics", "params_version": 3,
               "params": params, "mask": {"material": "Pool_Floor"}}]}
        rp = os.path.join(a.out, "vl_recipe.json")
        op = os.path.join(a.out, "vl_out.exr")
        with open(rp, "w") as f:
            json.dump(rec, f)
        r = subprocess.run([cli, "run", "-s", rp, "--sidecar", side, passes, "-o", op, "--force"],
                           capture_output=True, text=True)
        if r.returncode:
            sys.exit(r.stderr)
        for line in r.stderr.splitlines():
            if "cell_scale" in line:
                print("  ", line)
        img = C.rgb(op)
        imgs.append(img)
        mean, cf, cb, per, _ = stats(img, m_per_px)
        rows.append((name, mean, mean / tmean, cf, cb, per, C.mae(img, truth)))
    mean, cf, cb, per, _ = stats(truth, m_per_px)
    rows.append(("Cycles truth", mean, 1.0, cf, cb, per, 0.0))
    print("| variant (%s) | mean lum | mean / truth | contrast | contrast 4x4 box | dominant period (m) | whole MAE |"
          % a.quality)
    print("|---|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print("| %s | %.4f | %.3f | %.3f | %.3f | %.3f | %.4f |" % r)
    C.save_strip(os.path.join(a.out, "voronoi_look.png"), imgs + [truth])


if __name__ == "__main__":
    main()
