"""god_rays against Cycles with a volume scatter in the room (blend_scenes/truth_godrays/,
docs/accuracy_truth.md).

    LIBFX_LIBRARY=build/libfx/libfx.so LIBFX_CLI=build/libfx/libfx \\
        /usr/bin/python3 tests/bench/truth_godrays.py OUT_DIR [--res 320x180] [--spp 32] \\
        [--runs 3] [--docs docs]

The input is the room without a volume (the scene's recipe: god_rays from the Sun, sky
occlusion, the Greek bath's parameters); the truth the same room filled with a
homogeneous Volume Scatter (apply_truth), a second truth with seed 17 (the noise floor).
Both renders go through the add-on's batch path; `libfx run` at each preset.

What the volume adds, A_truth = lum(truth) - lum(input), and what god_rays adds,
A_fx = lum(output) - lum(input), both box-filtered 9x9 (the truth is noisy):
  - where: the Pearson correlation of A_fx with A_truth over the frame, and the offset
    (px) between the centroids of their positive parts;
  - how bright: sum(A_fx) / sum(A_truth) over the frame (the volume also dims what lies
    behind it: A_truth sums both);
  - the shaft region: pixels where A_truth exceeds 10 % of its 99th percentile; MAE
    there and over the whole frame (RGB clamped to [0, 1]), per pixel and between the
    9x9 box-filtered images (the truth's volume noise at these samples is as large as
    the error per pixel: the filtered MAE measures the structure).
"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import truth_common as C  # noqa: E402


def box(img, r=4):
    """Mean over a (2r+1)^2 box, edges clamped (a summed-area table in double)."""
    p = np.pad(img.astype(np.float64), r, mode="edge")
    s = np.pad(p.cumsum(0).cumsum(1), ((1, 0), (1, 0)))
    k = 2 * r + 1
    return ((s[k:, k:] - s[:-k, k:] - s[k:, :-k] + s[:-k, :-k]) / (k * k)).astype(np.float32)


def centroid(a):
    w = np.clip(a, 0, None)
    if w.sum() <= 0:
        return np.array([np.nan, np.nan])
    ys, xs = np.mgrid[0:a.shape[0], 0:a.shape[1]]
    return np.array([(xs * w).sum() / w.sum(), (ys * w).sum() / w.sum()])


def main():
    a = C.parse_args(res="320x180", spp=32, extra=[("--volumetric-only", dict(action="store_true",
                     help="skip the radial presets (re-runs while tuning the volumetric method)"))])
    d = C.scene_dir("godrays")
    blend = d / "truth_godrays_window.blend"
    recipe = json.load(open(d / "recipe.json"))
    noop = C.noop_recipe(C.pathlib.Path(a.out))
    p = os.path.join(a.out, "g_")
    # the input is rendered with the volumetric recipe so that the add-on renders the Sun's
    # light view too (the radial blur reads only the passes, the same for both)
    vol_recipe = json.load(open(d / "recipe_volumetric.json"))
    passes, side, tpass, t2pass = C.render_three("godrays", blend, p, a, noop,
                                                 input_recipe=d / "recipe_volumetric.json")
    truth, truth2, plain = C.rgb(tpass), C.rgb(t2pass), C.rgb(passes)
    lp = C.lum(np.clip(plain, 0, 1))
    add_t = box(C.lum(np.clip(truth, 0, 1)) - lp)
    region = add_t > 0.1 * max(1e-6, float(np.percentile(add_t, 99)))
    ct = centroid(add_t)
    outs = {} if a.volumetric_only else C.run_presets(recipe, passes, side, a.out, "g", runs=a.runs)
    vouts = C.run_presets(vol_recipe, passes, side, a.out, "gv", runs=a.runs)

    def row(name, img, ms):
        add = box(C.lum(np.clip(img, 0, 1)) - lp)
        corr = float(np.corrcoef(add.ravel(), add_t.ravel())[0, 1]) if add.std() > 0 else 0.0
        off = float(np.linalg.norm(centroid(add) - ct))
        ratio = float(add.sum() / add_t.sum())
        bi = np.stack([box(np.clip(img[..., c], 0, 1)) for c in range(3)], -1)
        return [name, ms, C.mae(img, truth, region), C.mae(img, truth), C.mae(bi, bt, region), C.mae(bi, bt),
                C.mean_ratio(img, truth), corr, off, ratio]
    bt = np.stack([box(np.clip(truth[..., c], 0, 1)) for c in range(3)], -1)
    rows = [row("no effect (input)", plain, None), row("Cycles, other seed (floor)", truth2, None)]
    for q in C.PRESETS:
        if q in outs:
            rows.append(row("libfx " + q + " (radial)", *outs[q]))
    for q in C.PRESETS:
        rows.append(row("libfx " + q + " (volumetric)", *vouts[q]))
    head = ["method", "ms", "shaft MAE", "whole MAE", "shaft MAE 9x9", "whole MAE 9x9", "mean / truth", "corr. of added light", "centroid offset px",
            "added light / truth's"]
    md = ["### god rays (%s, %d spp; shaft region %.1f %% of the frame)\n" % (a.res, a.spp, 100 * region.mean()),
          C.md_table(head, [[r[0], "" if r[1] is None else "%.1f" % r[1]] + ["%.4f" % x for x in r[2:6]]
                            + ["%.3f" % r[6], "%.2f" % r[7], "%.1f" % r[8], "%.2f" % r[9]] for r in rows]) + "\n"]
    print("\n".join(md))
    C.write_report(a.out, "godrays", md, {"region_px": int(region.sum()), "rows": rows})
    if a.docs:
        os.makedirs(os.path.join(a.docs, "images"), exist_ok=True)
        C.save_strip(os.path.join(a.docs, "images", "truth_godrays.png"),
                     [truth, vouts["reference"][0], vouts["final"][0]] + ([outs["final"][0]] if outs else []) + [plain])
        C.plot_time_error(os.path.join(a.docs, "images", "truth_godrays_time_error.png"), {"window room": rows},
                          "god_rays vs Cycles volume scatter (%s): time vs shaft-region MAE" % a.res,
                          ylabel="shaft-region MAE vs Cycles, 9x9 box-filtered", col=4)


if __name__ == "__main__":
    main()
