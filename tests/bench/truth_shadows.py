"""vsm_shadows against Cycles' ray-traced sun shadows on the shadow truth scenes
(blend_scenes/truth_shadows/, docs/accuracy_truth.md).

    LIBFX_LIBRARY=build/libfx/libfx.so LIBFX_CLI=build/libfx/libfx \\
        /usr/bin/python3 tests/bench/truth_shadows.py OUT_DIR [--res 480x270] [--spp 16] \\
        [--runs 3] [--variants floor,wall,roof] [--configs NAME,...] [--docs docs] [--no-eevee]

Per variant: the input (the Sun casts no Cycles shadow; rendered with the scene's recipe
turned to apply light_group, so the passes hold everything every apply mode reads, the
light group Combined_libfx_light included, and the Sun's light view the add-on renders;
each configuration of CONFIGS is the scene's recipe with those params) and the truth
(apply_truth: the Sun's shadow on) through the add-on's batch path, a second truth with
seed 17 (the noise floor); `libfx run` at each preset. Region: the pixels the Sun's
shadow changes (|input - truth| luminance above 2 % of the truth's 99th percentile, as
bench_atrium.py). Noise: the mean |Laplacian| of the luminance over flat geometry
(truth_common.flat_mask), libfx beside Cycles' own. The real-time peer: the truth scene
rendered by Eevee Legacy with its own sun shadows (truth_eevee.py), its ms the whole render
on this VM's software OpenGL.
"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import truth_common as C  # noqa: E402
import truth_eevee as E  # noqa: E402

VARIANTS = ("floor", "wall", "roof")
# vsm_shadows params over the scene's recipe; the first is the one the docs' strips show
CONFIGS = {
    "light_group": {"apply": "light_group"},
    "sun_diffuse difference": {"apply": "sun_diffuse", "remove_as": "difference"},
    "sun_diffuse ratio": {"apply": "sun_diffuse", "remove_as": "ratio"},
    "sun_direct": {"apply": "sun_direct"},
    "light_group b0": {"apply": "light_group", "bounce_loss": 0.0},
    "light_group b0.5": {"apply": "light_group", "bounce_loss": 0.5},
    "light_group reach 0": {"apply": "light_group", "bounce_reach": 0.0},
    "light_group difference": {"apply": "light_group", "remove_as": "difference"},
}


def with_params(recipe, params):
    r = json.loads(json.dumps(recipe))
    r["effects"][0]["params_version"] = 2   # the params as written here, not migrated from 1
    r["effects"][0]["params"].update(params)
    return r


def shadow_region(plain, truth):
    lt = C.lum(truth)
    return np.abs(C.lum(plain) - lt) > 0.02 * max(1e-6, float(np.percentile(lt, 99)))


def main():
    configs = [c for c in os.environ.get("TRUTH_SHADOWS_CONFIGS", ",".join(CONFIGS)).split(",") if c]
    a = C.parse_args(res="480x270", spp=16, variants=VARIANTS, eevee=True)
    d = C.scene_dir("shadows")
    recipe = json.load(open(d / "recipe.json"))
    noop = C.noop_recipe(C.pathlib.Path(a.out))
    in_recipe = os.path.join(a.out, "input_recipe.json")
    with open(in_recipe, "w") as f:
        json.dump(with_params(recipe, {"apply": "light_group"}), f)
    md, report, series = [], {}, {}
    for v in a.variants.split(","):
        blend = d / ("truth_shadows_%s.blend" % v)
        p = os.path.join(a.out, "s_%s_" % v)
        passes, side, _ = C.batch(blend, p + "in_", a.res, a.spp, recipe=in_recipe)
        tpass, _, _ = C.batch(blend, p + "truth_", a.res, a.spp, expr=C.truth_expr("shadows"), recipe=noop)
        t2pass, _, _ = C.batch(blend, p + "truth2_", a.res, a.spp, expr=C.truth_expr("shadows"), recipe=noop,
                               seed=17)
        truth, truth2, plain = C.rgb(tpass), C.rgb(t2pass), C.rgb(passes)
        region = shadow_region(plain, truth)
        flat = C.flat_mask(passes)
        rows = None
        for ci, cname in enumerate(configs):
            outs = C.run_presets(with_params(recipe, CONFIGS[cname]), passes, side, a.out,
                                 "s_%s_%s" % (v, cname.replace(" ", "_")), runs=a.runs)
            crow = C.rows_for(truth, truth2, plain, outs, region, flat=flat)
            if rows is None:
                rows = crow[:3]
                first = outs
            rows += [[cname + " " + r[0][len("libfx "):]] + list(r[1:]) for r in crow[3:]]
        if a.eevee:   # the real-time peer: Eevee's own sun shadows on the truth scene
            img, secs = E.eevee_shadows(blend, p + "eevee.exr", a.res, a.spp, C.truth_expr("shadows"))
            rows.append(C.error_row("Eevee (its own shadows)", img, 1e3 * secs, truth, region, flat))
        outs = first
        series[v] = rows[1:3] + [["libfx " + r[0][len(configs[0]) + 1:]] + list(r[1:]) for r in rows[3:]
                                 if r[0][len(configs[0]) + 1:] in C.PRESETS and r[0].startswith(configs[0] + " ")]
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
