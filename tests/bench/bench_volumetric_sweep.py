#!/usr/bin/python3
"""Volumetric god rays: instructions and error against `reference` per setting (issue 27).

    /usr/bin/python3 tests/bench/bench_volumetric_sweep.py BUILD DIR NAME:JSON [NAME:JSON ...]

DIR holds a 1080p render through the add-on's batch runner with a volumetric god_rays
recipe (so the light view is rendered): r_libfx_passes.0001.exr, r_libfx.0001.camera.json
(made with `blender -b blend_scenes/greek_bath/greek_bath.blend --python addon/libfx/batch.py
-- --keep-passes --passes-codec NONE --frames 1 --output DIR/r_ --resolution 1920x1080
--samples 4 --recipe RECIPE`). Each NAME:JSON is god_rays' parameters over BASE below; the
reference (quality reference, BASE) is run once into DIR/ref.exr. Per setting: callgrind's
instructions (1 thread, BUILD/tests/bench/bench_first_faults, one frame: the light view's
read included) of god_rays_process and its parts, and the mean / 99th percentile / max of
|output - reference| over RGB."""
import json
import os
import subprocess
import sys

import numpy as np
import OpenImageIO as oiio

BASE = {"light": "Sun", "method": "volumetric", "extinction": "view", "max_distance": 30.0,
        "volume_density": 0.03}
PARTS = ("god_rays_process", "fx_aux_map_acquire_reduced", "fx_volume_scatter_lo")


def rgb(path):
    b = oiio.ImageBuf(path)
    names = b.spec().channelnames
    idx = [names.index(c) for c in ("Combined.R", "Combined.G", "Combined.B")]
    return b.get_pixels(oiio.FLOAT)[:, :, idx]


def run(build, d, recipe, out, callgrind=None):
    cmd = [os.path.join(build, "tests", "bench", "bench_first_faults"), os.path.join(d, "r_libfx_passes.0001.exr"),
           os.path.join(d, "r_libfx.0001.camera.json"), recipe, "1", "1", out]
    if callgrind:
        cmd = ["valgrind", "--tool=callgrind", "--callgrind-out-file=" + callgrind] + cmd
    subprocess.run(cmd, check=True, capture_output=True)


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    build, d = sys.argv[1], sys.argv[2]
    sweep = os.path.join(d, "sweep")
    os.makedirs(sweep, exist_ok=True)
    ref_recipe = os.path.join(sweep, "reference.json")
    json.dump({"version": 1, "quality": "reference", "effects": [{"effect": "god_rays", "params": BASE}]},
              open(ref_recipe, "w"))
    ref_path = os.path.join(d, "ref.exr")
    if not os.path.exists(ref_path):
        run(build, d, ref_recipe, ref_path)
    ref = rgb(ref_path)
    print("| setting | Ir (M) | light view read | march | MAE | p99 | max |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for arg in sys.argv[3:]:
        name, params = arg.split(":", 1)
        recipe = os.path.join(sweep, name + ".json")
        json.dump({"version": 1, "quality": "final",
                   "effects": [{"effect": "god_rays", "params": dict(BASE, **json.loads(params))}]}, open(recipe, "w"))
        out, cg = os.path.join(sweep, name + ".exr"), os.path.join(sweep, name + ".cg")
        run(build, d, recipe, out, cg)
        ann = subprocess.run(["callgrind_annotate", "--inclusive=yes", cg], capture_output=True, text=True).stdout
        ir = {}
        for line in ann.splitlines():
            for fn in PARTS:
                if ":" + fn + " " in line and fn not in ir:
                    ir[fn] = int(line.split()[0].replace(",", "")) / 1e6
        e = np.abs(rgb(out) - ref).mean(axis=2)
        print("| %s | %.1f | %.1f | %.1f | %.2e | %.2e | %.2e |" % (
            name, ir.get(PARTS[0], 0), ir.get(PARTS[1], 0), ir.get(PARTS[2], 0), e.mean(), np.percentile(e, 99),
            e.max()), flush=True)


if __name__ == "__main__":
    main()
