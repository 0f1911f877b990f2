"""Atrium measurements (docs/effects/vsm_shadows.md, docs/effects/rain.md):

1. VSM against Cycles' ray-traced shadows of the same frame: the scene's Sun casts no
   Cycles shadow (libfx adds them); the truth is the same frame with the Sun's
   cast_shadow on.  Mean absolute error of Combined (linear) per method, filter size and
   bleeding reduction, next to the error with no shadow at all.
2. The whole rain stack per frame at 1280x720 (median of 5 runs through the ctypes API).
3. Aux view reuse: the batch log of frames 1..N (rendered once, reused after).
4. A flip-book GIF of frames 1..8 at 320x180 into docs/images/atrium_rain.gif.

    LIBFX_LIBRARY=build/libfx/libfx.so /usr/bin/python3 tests/bench/bench_atrium.py OUT_DIR
"""
import json
import os
import pathlib
import subprocess
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests" / "blender"))
sys.path.insert(0, str(ROOT / "addon"))
import addon_testlib as T  # noqa: E402
from libfx import native  # noqa: E402

BLEND = ROOT / "blend_scenes" / "atrium" / "atrium.blend"
LIB = os.environ.get("LIBFX_LIBRARY", str(ROOT / "build" / "libfx" / "libfx.so"))


def batch(out, frames, res, samples, expr=None, recipe=None):
    args = ["blender", "-b", str(BLEND)]
    if expr:
        args += ["--python-expr", expr]
    args += ["--python", str(ROOT / "addon" / "libfx" / "batch.py"), "--", "--frames", frames,
             "--output", out, "--resolution", res, "--samples", str(samples)]
    if recipe:
        args += ["--recipe", recipe]
    p = subprocess.run(args, capture_output=True, text=True, env=dict(os.environ, LIBFX_LIBRARY=LIB))
    if p.returncode:
        sys.exit(p.stdout[-3000:] + p.stderr[-3000:])
    return p.stdout


def run_stack(recipe, passes, sidecar, frame):
    with native.Context(0) as ctx:
        st = native.Stack(ctx, recipe)
        fin = native.Frame.read(ctx, passes, st)
        fin.apply_sidecar(sidecar)
        fin.set_time(frame, 24)
        t0 = time.perf_counter()
        fout = st.run(fin)
        ms = (time.perf_counter() - t0) * 1e3
        tmp = str(pathlib.Path(passes).with_suffix(".bench.exr"))
        fout.write_exr(tmp, only_combined=True)
        timings = st.timings()
        fout.close(); fin.close(); st.close()
    img = T.Exr(tmp).get("Combined", "RGB")
    os.remove(tmp)
    return img, ms, timings


def main():
    out = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "/tmp/bench_atrium")
    out.mkdir(parents=True, exist_ok=True)
    native.load()
    report = {}
    # 1. VSM vs Cycles (frame 8: in the courtyard)
    res, spp, fr = "480x270", 16, 8
    batch(str(out / "a_"), str(fr), res, spp)
    truth_recipe = out / "noop.json"
    truth_recipe.write_text(json.dumps({"version": 1, "effects": [
        {"effect": "color_matrix", "params": {"operator": "sepia", "mix": 0.0}}]}))
    batch(str(out / "t_"), str(fr), res, spp, recipe=str(truth_recipe),
          expr="import bpy; bpy.data.objects['Sun'].data.cycles.cast_shadow = True")
    passes = str(out / ("a_libfx_passes.%04d.exr" % fr))
    side = json.load(open(out / ("a_libfx.%04d.camera.json" % fr)))
    truth = T.Exr(out / ("t_libfx_passes.%04d.exr" % fr)).get("Combined", "RGB")
    plain = T.Exr(passes).get("Combined", "RGB")
    rows = [("none (no shadow)", "", "", float(np.abs(plain - truth).mean()), 0.0)]
    for method in ("hard", "pcf", "vsm"):
        for size in ((1,) if method == "hard" else (3, 7, 15, 31)):
            for bleed in ((0.3,) if method != "vsm" else (0.0, 0.3, 0.6)):
                rec = {"version": 1, "effects": [{"effect": "vsm_shadows", "params": {
                    "light": "Sun", "method": method, "filter_size": size, "bleed_reduction": bleed}}]}
                img, ms, _ = run_stack(rec, passes, side, fr)
                rows.append((method, size, bleed, float(np.abs(img - truth).mean()), ms))
    report["vsm_vs_cycles"] = rows
    # 2. rain stack at 1280x720 (frame 1: under the arcade, cover quads)
    log = batch(str(out / "hd_"), "1", "1280x720", 4)
    report["hd_log"] = [l for l in log.splitlines() if l.startswith("libfx:")]
    recipe = json.load(open(ROOT / "blend_scenes" / "atrium" / "recipe.json"))
    side1 = json.load(open(out / "hd_libfx.0001.camera.json"))
    runs = [run_stack(recipe, str(out / "hd_libfx_passes.0001.exr"), side1, 1) for _ in range(5)]
    report["hd_stack_ms"] = sorted(r[1] for r in runs)
    report["hd_effect_ms"] = {t["effect"]: sorted(r[2][i]["ms"] for r in runs)[2]
                              for i, t in enumerate(runs[0][2])}
    # 3 + 4. frames 1..8 at 320x180: aux views rendered once, reused; flip-book
    log = batch(str(out / "fb_"), "1-8", "320x180", 8)
    report["flipbook_log"] = [l for l in log.splitlines() if "aux view" in l or "frame" in l and "libfx:" in l]
    pngs = []
    for f in range(1, 9):
        p = out / ("fb_%d.png" % f)
        subprocess.run(["oiiotool", str(out / ("fb_libfx.%04d.exr" % f)), "--ch", "Combined.R,Combined.G,Combined.B",
                        "--colorconvert", "linear", "sRGB", "-o", str(p)], check=True)
        pngs.append(str(p))
    gif = ROOT / "docs" / "images" / "atrium_rain.gif"
    gif.parent.mkdir(parents=True, exist_ok=True)
    subprocess.run(["convert", "-delay", "12", "-loop", "0", *pngs, str(gif)], check=True)
    (out / "report.json").write_text(json.dumps(report, indent=1))
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
