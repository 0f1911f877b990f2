"""ssr_mirror against Cycles' true mirrors on the mirror truth scenes
(blend_scenes/truth_mirrors/, docs/accuracy_truth.md).

    LIBFX_LIBRARY=build/libfx/libfx.so LIBFX_CLI=build/libfx/libfx \\
        /usr/bin/python3 tests/bench/truth_mirrors.py OUT_DIR [--res 480x270] [--spp 16] \\
        [--runs 3] [--variants facing,grazing,pair,curved] [--docs docs] [--no-eevee]

Per variant: the input (the card is diffuse grey; the scene's recipe, one ssr_mirror on
material Mirror) and the truth (apply_truth: a perfect Glossy mirror) rendered through
the add-on's batch path, a second truth with seed 17 (the noise floor); `libfx run` at
each preset; the truth scene rendered by Eevee (Blender 3.x's Eevee Legacy, the same
samples) with its screen-space reflections: the real-time peer, its ms the whole render
on this VM's software OpenGL. Region: the Mirror material's pixels
(Cryptomatte of the input). Writes
OUT_DIR/truth_mirrors.md and .json; with --docs the images and plot into DOCS/images/.
"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import truth_common as C  # noqa: E402

VARIANTS = ("facing", "grazing", "pair", "curved")


def main():
    a = C.parse_args(res="480x270", spp=16, variants=VARIANTS, eevee=True)
    d = C.scene_dir("mirrors")
    recipe = json.load(open(d / "recipe.json"))
    noop = C.noop_recipe(C.pathlib.Path(a.out))
    md, report, series = [], {}, {}
    for v in a.variants.split(","):
        blend = d / ("truth_mirrors_%s.blend" % v)
        p = os.path.join(a.out, "m_%s_" % v)
        passes, side, tpass, t2pass = C.render_three("mirrors", blend, p, a, noop)
        region = C.T.crypto_support(C.T.Exr(passes), "CryptoMaterial", ["Mirror"])
        truth, truth2, plain = C.rgb(tpass), C.rgb(t2pass), C.rgb(passes)
        outs = C.run_presets(recipe, passes, side, a.out, "m_%s" % v, runs=a.runs)
        rows = C.rows_for(truth, truth2, plain, outs, region)
        if a.eevee:  # the real-time peer: Eevee's own screen-space reflections
            img, render_s = C.eevee("mirrors", blend, p + "eevee_ssr.exr", a.res, a.spp)
            rows.append(C.error_row("Eevee SSR", img, 1e3 * render_s, truth, region))
        series[v] = rows
        report[v] = {"region_px": int(region.sum()), "rows": rows}
        md.append("### %s (%s, %d spp; mirror region %d px, %.1f %% of the frame)\n"
                  % (v, a.res, a.spp, region.sum(), 100 * region.mean()))
        md.append(C.fmt_rows(rows) + "\n")
        print(md[-2] + md[-1], flush=True)
        if a.docs:
            os.makedirs(os.path.join(a.docs, "images"), exist_ok=True)
            C.save_strip(os.path.join(a.docs, "images", "truth_mirrors_%s.png" % v),
                         [truth, outs["final"][0], plain])
    # the goal: the region error's fall relative to no reflection, averaged
    summ = []
    methods = ["libfx " + q for q in C.PRESETS]
    if a.eevee:
        methods.append("Eevee SSR")
    for m in methods:
        falls = []
        for v, rows in series.items():
            none = rows[0][2]
            r = [x for x in rows if x[0] == m][0]
            falls.append(1 - r[2] / none)
        summ.append([m, "%.0f %%" % (100 * np.mean(falls))] + ["%.0f %%" % (100 * f) for f in falls])
    md.append("### Mirror-region error fall relative to no reflection (issue 14 goal: >= 60 % at "
              "final, >= 85 % at reference)\n")
    md.append(C.md_table(["method", "mean"] + list(series), summ) + "\n")
    print(md[-1])
    report["fall"] = summ
    C.write_report(a.out, "mirrors", md, report)
    if a.docs:
        C.plot_time_error(os.path.join(a.docs, "images", "truth_mirrors_time_error.png"), series,
                          "ssr_mirror vs Cycles mirrors (%s): time vs mirror-region MAE" % a.res)


if __name__ == "__main__":
    main()
