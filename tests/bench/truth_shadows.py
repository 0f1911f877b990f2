"""vsm_shadows against Cycles' ray-traced sun shadows on the shadow truth scenes
(blend_scenes/truth_shadows/, docs/accuracy_truth.md).

    LIBFX_LIBRARY=build/libfx/libfx.so LIBFX_CLI=build/libfx/libfx \\
        /usr/bin/python3 tests/bench/truth_shadows.py OUT_DIR [--res 480x270] [--spp 16] \\
        [--runs 3] [--variants floor,wall,roof] [--docs docs]

Per variant: the input (the Sun casts no Cycles shadow; the scene's recipe: vsm_shadows,
apply sun_diffuse, with the Sun's light view the add-on renders) and the truth
(apply_truth: the Sun's shadow on) through the add-on's batch path, a second truth with
seed 17 (the noise floor); `libfx run` at each preset. Region: the pixels the Sun's
shadow changes (|input - truth| luminance above 2 % of the truth's 99th percentile, as
bench_atrium.py). Noise: the mean |Laplacian| of the luminance over flat geometry
(truth_common.flat_mask), libfx beside Cycles' own.
"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import truth_common as C  # noqa: E402

VARIANTS = ("floor", "wall", "roof")


def shadow_region(plain, truth):
    lt = C.lum(truth)
    return np.abs(C.lum(plain) - lt) > 0.02 * max(1e-6, float(np.percentile(lt, 99)))


def main():
    a = C.parse_args(res="480x270", spp=16, variants=VARIANTS)
    d = C.scene_dir("shadows")
    recipe = json.load(open(d / "recipe.json"))
    noop = C.noop_recipe(C.pathlib.Path(a.out))
    md, report, series = [], {}, {}
    for v in a.variants.split(","):
        blend = d / ("truth_shadows_%s.blend" % v)
        p = os.path.join(a.out, "s_%s_" % v)
        passes, side, tpass, t2pass = C.render_three("shadows", blend, p, a, noop)
        truth, truth2, plain = C.rgb(tpass), C.rgb(t2pass), C.rgb(passes)
        region = shadow_region(plain, truth)
        flat = C.flat_mask(passes)
        outs = C.run_presets(recipe, passes, side, a.out, "s_%s" % v, runs=a.runs)
        rows = C.rows_for(truth, truth2, plain, outs, region, flat=flat)
        series[v] = [r for r in rows if r[0] != "Cycles truth"]
        report[v] = {"region_px": int(region.sum()), "flat_px": int(flat.sum()), "rows": rows}
        md.append("### %s (%s, %d spp; shadow-changed pixels %.1f %%, flat pixels %.1f %%)\n"
                  % (v, a.res, a.spp, 100 * region.mean(), 100 * flat.mean()))
        md.append(C.fmt_rows(rows, noise=True) + "\n")
        print(md[-2] + md[-1], flush=True)
        if a.docs:
            os.makedirs(os.path.join(a.docs, "images"), exist_ok=True)
            C.save_strip(os.path.join(a.docs, "images", "truth_shadows_%s.png" % v),
                         [truth, outs["final"][0], plain])
            if v == "floor":  # a crop: truth | reference (pcf) | final (vsm)
                h, w = truth.shape[:2]
                crop = (slice(int(0.22 * h), int(0.74 * h)), slice(int(0.21 * w), int(0.71 * w)))
                C.save_strip(os.path.join(a.docs, "images", "truth_shadows_pcf_acne.png"),
                             [truth[crop], outs["reference"][0][crop], outs["final"][0][crop]])
    C.write_report(a.out, "shadows", md, report)
    if a.docs:
        C.plot_time_error(os.path.join(a.docs, "images", "truth_shadows_time_error.png"), series,
                          "vsm_shadows vs Cycles' sun shadows (%s): time vs shadow-region MAE" % a.res)


if __name__ == "__main__":
    main()
