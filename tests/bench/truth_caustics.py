"""voronoi_caustics against Cycles' refractive caustics (blend_scenes/truth_caustics/,
docs/accuracy_truth.md): the shapes cannot match, so the pattern's statistics are compared.

    LIBFX_LIBRARY=build/libfx/libfx.so LIBFX_CLI=build/libfx/libfx \\
        /usr/bin/python3 tests/bench/truth_caustics.py OUT_DIR [--res 480x270] [--spp 32] \\
        [--runs 3] [--docs docs]

The input is the pool floor in plain sunlight, seen straight down by an orthographic
camera (the water disabled; the scene's recipe: voronoi_caustics on Pool_Floor with the
Greek bath's parameters); the truth the same floor under the displaced refractive water
(apply_truth: MNEE caustics), a second truth with seed 17 (the noise floor).

The refractive rows run voronoi_caustics' mode refractive (strength 1, white tint: the
physical setting; apply sun_diffuse) on the same input rendered through the add-on with
that recipe (the add-on then adds the DiffCol and Normal passes and renders the water's
view from the Sun into the sidecar; kept and reused like the other renders).

Statistics of the luminance over the central square (H x H px; the whole frame is floor):
mean (and its ratio to the truth's), contrast (std / mean) at full resolution and after a
4x4 box average (which divides uncorrelated pixel noise by 4: the truth's Monte Carlo
noise inflates its full-resolution contrast), and the dominant spatial frequency: the peak
of the radially averaged power spectrum (Hann window, DC and the first bin excluded), as
a period in metres (the orthographic camera's width / pixels, from the sidecar).
"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import truth_common as C  # noqa: E402


def stats(img, m_per_px):
    y = C.lum(img)
    h, w = y.shape
    s = min(h, w)
    x0 = (w - s) // 2
    y = y[(h - s) // 2:(h - s) // 2 + s, x0:x0 + s].astype(np.float64)
    mean = float(y.mean())
    c_full = float(y.std() / max(mean, 1e-9))
    b = y[:s // 4 * 4, :s // 4 * 4].reshape(s // 4, 4, s // 4, 4).mean(axis=(1, 3))
    c_box = float(b.std() / max(mean, 1e-9))
    win = np.outer(np.hanning(s), np.hanning(s))
    f = np.abs(np.fft.fftshift(np.fft.fft2((y - mean) * win))) ** 2
    yy, xx = np.mgrid[0:s, 0:s]
    r = np.hypot(yy - s // 2, xx - s // 2).astype(int)
    radial = np.bincount(r.ravel(), f.ravel()) / np.maximum(np.bincount(r.ravel()), 1)
    radial = radial[:s // 2]
    k = 2 + int(np.argmax(radial[2:])) if mean > 0 and radial[2:].max() > 0 else 0
    period = float(s * m_per_px / k) if k else float("nan")
    return mean, c_full, c_box, period, radial


def refractive_recipe(recipe):
    """The scene's recipe in mode refractive: strength 1 and a white tint (the physical
    setting: the gain is the refracted light's own ratio), the water's material 'Water'."""
    r = json.loads(json.dumps(recipe))
    r["effects"][0]["params"].update({"mode": "refractive", "strength": 1.0, "tint": [1.0, 1.0, 1.0],
                                      "water": "Water"})
    return r


def main():
    a = C.parse_args(res="480x270", spp=32)
    d = C.scene_dir("caustics")
    blend = d / "truth_caustics_pool.blend"
    recipe = json.load(open(d / "recipe.json"))
    noop = C.noop_recipe(C.pathlib.Path(a.out))
    p = os.path.join(a.out, "c_")
    passes, side, tpass, t2pass = C.render_three("caustics", blend, p, a, noop)
    truth, truth2, plain = C.rgb(tpass), C.rgb(t2pass), C.rgb(passes)
    # the orthographic camera's width in metres is 2 / projection[0][0] (the sidecar)
    m_per_px = 2.0 / json.load(open(side))["projection"][0][0] / plain.shape[1]
    outs = C.run_presets(recipe, passes, side, a.out, "c", runs=a.runs, frame=1)
    # the refractive rows' input: the same render through the add-on with the refractive
    # recipe, which adds the passes it reads (DiffCol, Normal) and the water's view
    refr = refractive_recipe(recipe)
    rec_path = os.path.join(a.out, "refractive_recipe.json")
    with open(rec_path, "w") as f:
        json.dump(refr, f)
    rpasses, rside, _ = C.batch(blend, p + "inr_", a.res, a.spp, recipe=rec_path)
    outs_r = C.run_presets(refr, rpasses, rside, a.out, "cr", runs=a.runs, frame=1)
    tmean = stats(truth, m_per_px)[0]
    rows, spectra = [], {}
    for name, img, ms in ([("no effect (input)", plain, None), ("Cycles truth", truth, None),
                           ("Cycles, other seed", truth2, None)]
                          + [("libfx " + q, *outs[q]) for q in C.PRESETS]
                          + [("libfx refractive " + q, *outs_r[q]) for q in C.PRESETS]):
        mean, cf, cb, per, rad = stats(img, m_per_px)
        rows.append([name, ms, mean, mean / tmean, cf, cb, per, C.mae(img, truth)])
        spectra[name] = rad
    head = ["method", "ms", "mean lum", "mean / truth", "contrast (std/mean)", "contrast 4x4 box",
            "dominant period (m)", "whole MAE"]
    md = ["### pool caustics (%s, %d spp, %.2f cm per pixel)\n" % (a.res, a.spp, 100 * m_per_px),
          C.md_table(head, [[r[0], "" if r[1] is None else "%.1f" % r[1], "%.4f" % r[2], "%.3f" % r[3],
                             "%.3f" % r[4], "%.3f" % r[5], "%.3f" % r[6], "%.4f" % r[7]] for r in rows]) + "\n"]
    print("\n".join(md))
    C.write_report(a.out, "caustics", md, {"m_per_px": m_per_px, "rows": rows,
                                              "spectra": {k: [float(x) for x in v] for k, v in spectra.items()}})
    if a.docs:
        os.makedirs(os.path.join(a.docs, "images"), exist_ok=True)
        C.save_strip(os.path.join(a.docs, "images", "truth_caustics.png"),
                     [truth, outs_r["final"][0], outs["final"][0], plain])
        try:
            import matplotlib
            matplotlib.use("Agg")
            import matplotlib.pyplot as plt
            fig, axs = plt.subplots(1, 2, figsize=(9, 3.4), dpi=100)
            s = len(spectra["Cycles truth"]) * 2
            fr = np.arange(len(spectra["Cycles truth"])) / (s * m_per_px)
            for name in ("Cycles truth", "Cycles, other seed", "libfx final", "libfx draft", "libfx refractive final"):
                sp = spectra[name]
                axs[0].loglog(fr[1:], sp[1:] / sp[1:].sum(), label=name)
            axs[0].set_xlabel("spatial frequency (cycles per metre)")
            axs[0].set_ylabel("radial power (normalised)")
            axs[0].legend(fontsize=7)
            axs[0].set_title("radial power spectrum of the floor's luminance", fontsize=9)
            pts = [r for r in rows if r[0].startswith("libfx ")]
            axs[1].plot([r[1] for r in pts], [r[5] for r in pts], "o-", label="libfx contrast (4x4 box)")
            for r in pts:
                axs[1].annotate(r[0].split()[1], (r[1], r[5]), fontsize=7, xytext=(3, 3), textcoords="offset points")
            tr = [r for r in rows if r[0] == "Cycles truth"][0]
            axs[1].axhline(tr[5], color="k", ls="--", lw=0.8, label="Cycles contrast (4x4 box)")
            axs[1].set_xscale("log")
            axs[1].set_xlabel("libfx effects time, ms (2 threads)")
            axs[1].set_ylabel("contrast std/mean")
            axs[1].legend(fontsize=7)
            fig.tight_layout()
            fig.savefig(os.path.join(a.docs, "images", "truth_caustics_stats.png"))
            plt.close(fig)
        except ImportError:
            pass


if __name__ == "__main__":
    main()
