"""vsm_shadows against Cycles' ray-traced sun shadows on the atrium (issue 14's shadow
goals; docs/accuracy_truth.md, "Sun shadows", the atrium table).

    LIBFX_LIBRARY=build/libfx/libfx.so LIBFX_CLI=build/libfx/libfx \\
        /usr/bin/python3 tests/bench/truth_atrium_shadows.py OUT_DIR [--res 640x360] [--spp 32] \\
        [--runs 3] [--configs NAME,...] [--docs docs] [--no-eevee]

Renders (kept in OUT_DIR and reused) frame 8 of blend_scenes/atrium through the add-on's
batch path: the input with a recipe asking for every pass the apply modes read (the light
group Combined_libfx_light included: the add-on makes the group), the truth (the Sun's
cast_shadow on, a no-op recipe) and the truth at seed 17 (the noise floor), as
bench_atrium.py's vsm section. Then `libfx run` of each configuration (a vsm_shadows
params object) at each preset. Columns as truth_shadows.py: shadow-region MAE, whole-frame
MAE (linear RGB clamped to [0, 1]), whole-frame MAE unclamped (issue 14's 0.119), mean
luminance / truth, mean |Laplacian| over flat geometry.
"""
import argparse
import json
import os
import pathlib
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import truth_common as C  # noqa: E402
import bench_atrium as B  # noqa: E402
import truth_eevee as E  # noqa: E402

FRAME = 8
BASE = {"light": "Sun", "filter_size": 5.0, "bleed_reduction": 0.3}
# the first is the old default (issue 14's figures), the last the new one (the docs' strip
# shows both)
CONFIGS = {
    "sun_diffuse difference": {"apply": "sun_diffuse", "remove_as": "difference"},
    "sun_diffuse ratio": {"apply": "sun_diffuse", "remove_as": "ratio"},
    "sun_direct": {"apply": "sun_direct"},
    "light_group b0": {"apply": "light_group", "bounce_loss": 0.0},
    "light_group b0.5": {"apply": "light_group", "bounce_loss": 0.5},
    "light_group reach 0 difference": {"apply": "light_group", "bounce_reach": 0.0, "remove_as": "difference"},
    "light_group reach 0": {"apply": "light_group", "bounce_reach": 0.0},
    "light_group reach 0.3": {"apply": "light_group", "bounce_reach": 0.3},
    "light_group difference": {"apply": "light_group", "remove_as": "difference"},
    "light_group": {"apply": "light_group"},
}


# what makes the atrium the truth: the Sun casts its shadows. Both switches, as the add-on's
# compat.light_cast_shadow sets them: 4.x's Cycles reads use_shadow (setting only
# cycles.cast_shadow there left the truth without shadows), 5.x has no cycles.cast_shadow.
TRUTH_SETUP = ("import bpy\nsun = bpy.data.objects['Sun'].data\nsun.use_shadow = True\n"
               "if hasattr(sun.cycles, 'cast_shadow'):\n    sun.cycles.cast_shadow = True\n")


def render(out, res, spp):
    rec = out / "input_recipe.json"
    rec.write_text(json.dumps({"version": 1, "effects": [
        {"effect": "vsm_shadows", "params": dict(BASE, apply="light_group")}]}))
    pref = lambda p: out / ("%s_libfx_passes.%04d.exr" % (p, FRAME))
    B.batch(str(out / "a_"), str(FRAME), res, spp, recipe=str(rec), check=pref("a"))
    on = TRUTH_SETUP
    B.batch(str(out / "t_"), str(FRAME), res, spp, recipe=B.noop_recipe(out), expr=on, check=pref("t"))
    B.batch(str(out / "u_"), str(FRAME), res, spp, recipe=B.noop_recipe(out),
            expr=on + "bpy.context.scene.cycles.seed = 17\n", check=pref("u"))
    return str(pref("a")), str(out / ("a_libfx.%04d.camera.json" % FRAME)), str(pref("t")), str(pref("u"))


def row(name, img, ms, truth, region, flat):
    r = C.error_row(name, img, ms, truth, region, flat)
    return r[:4] + [float(np.abs(img - truth).mean())] + r[4:]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--res", default="640x360")
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--configs", default=",".join(CONFIGS))
    ap.add_argument("--presets", default=",".join(C.PRESETS))
    ap.add_argument("--docs")
    ap.add_argument("--no-eevee", dest="eevee", action="store_false", help="skip the Eevee peer render")
    a = ap.parse_args()
    out = pathlib.Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    passes, side, tpass, upass = render(out, a.res, a.spp)
    truth, truth2, plain = C.rgb(tpass), C.rgb(upass), C.rgb(passes)
    lt = C.lum(truth)
    region = np.abs(C.lum(plain) - lt) > 0.02 * max(1e-6, float(np.percentile(lt, 99)))
    flat = C.flat_mask(passes)
    rows = [row("Cycles truth", truth, None, truth, region, flat),
            row("no effect (input)", plain, None, truth, region, flat),
            row("Cycles, other seed (floor)", truth2, None, truth, region, flat)]
    images = {}
    for name in a.configs.split(","):
        rec = {"version": 1, "effects": [{"effect": "vsm_shadows", "params_version": 2,
                                          "params": dict(BASE, **CONFIGS[name])}]}
        tag = "c_" + name.replace(" ", "_")
        rp = out / (tag + "_recipe.json")
        rp.write_text(json.dumps(rec))
        for q in a.presets.split(","):
            o = str(out / ("%s_%s.exr" % (tag, q)))
            ts = [C.run_cli_frame(str(rp), passes, side, o, q, FRAME, False) for _ in range(a.runs)]
            img = C.rgb(o)
            images[(name, q)] = img
            rows.append(row("%s %s" % (name, q), img, float(np.median(ts)), truth, region, flat))
            print(rows[-1], flush=True)
    if a.eevee:   # the real-time peer: the truth frame by Eevee with its own sun shadows
        img, secs = E.eevee_shadows(C.ROOT / "blend_scenes" / "atrium" / "atrium.blend", str(out / "eevee.exr"),
                                    a.res, a.spp, TRUTH_SETUP, frame=FRAME)
        rows.append(row("Eevee (its own shadows)", img, 1e3 * secs, truth, region, flat))
    head = ["method", "ms", "shadow MAE", "whole MAE", "whole MAE (unclamped)", "mean / truth", "Laplacian (flat)"]
    md = C.md_table(head, [[r[0], "" if r[1] is None else "%.0f" % r[1], "%.4f" % r[2], "%.4f" % r[3],
                            "%.4f" % r[4], "%.3f" % r[5], "%.4f" % r[6]] for r in rows])
    md = ("atrium frame %d, %s, %d spp; shadow-changed pixels %.1f %%, flat pixels %.1f %%\n\n"
          % (FRAME, a.res, a.spp, 100 * region.mean(), 100 * flat.mean())) + md
    (out / "truth_atrium_shadows.md").write_text(md + "\n")
    (out / "truth_atrium_shadows.json").write_text(json.dumps({"rows": rows}, indent=1))
    print(md)
    if a.docs:
        first = a.configs.split(",")[0]
        best = a.configs.split(",")[-1]
        C.save_strip(os.path.join(a.docs, "images", "truth_shadows_atrium.png"),
                     [truth, images[(best, "final")], images[(first, "final")], plain], width=480)


if __name__ == "__main__":
    main()
