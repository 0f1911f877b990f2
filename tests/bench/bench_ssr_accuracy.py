"""ssr_mirror accuracy against Cycles' true mirrors, Eevee's SSR beside it, and the
error-vs-time curve over the quality knobs. Run with Debian's /usr/bin/python3.

    /usr/bin/python3 tests/bench/bench_ssr_accuracy.py --cli build/libfx/libfx --dir /tmp/ssr \\
        [--res 640x360] [--out docs]

Inputs in --dir, from tests/bench/bench_ssr_render.py (same frame, same resolution):
  back<W>.exr/.camera.json      the scene as built (mirror backing): libfx's input
  ref<W>.exr                    Cycles with real mirrors (the truth)
  eevee_ssr<W>.exr, eevee_nossr<W>.exr, *.time.json   Eevee with SSR on/off (optional)
Region: the pixels of the mirrors that have a physical reference (Clear, Low, Fresnel,
BentOut, BentIn, FacingA, FacingB by IndexMA) where the reference-preset tracer found
an on-screen hit (its debug `hit` > 0.5): "where the reflected point is on screen".
Errors on linear RGB clamped to [0, 1]: MAE and PSNR (peak 1).
Writes ssr_accuracy.csv, ssr_curve.csv and plots to --out (docs/images/ssr_*.png).
"""
import argparse
import json
import os
import re
import subprocess
import sys
import time

import numpy as np
import OpenImageIO as oiio

PHYSICAL = {"Mirror_Clear": 20, "Mirror_Low": 21, "Mirror_Fresnel": 23, "Mirror_FacingA": 25,
            "Mirror_BentOut": 27, "Mirror_FacingB": 28, "Mirror_BentIn": 30}
ALL = {"Mirror_Clear": 20, "Mirror_Low": 21, "Mirror_Blurred": 22, "Mirror_Fresnel": 23,
       "Mirror_Sepia": 24, "Mirror_FacingA": 25, "Mirror_Grayscale": 26, "Mirror_BentOut": 27,
       "Mirror_FacingB": 28, "Mirror_Cel": 29, "Mirror_BentIn": 30}


def read(path):
    inp = oiio.ImageInput.open(path)
    if inp is None:
        raise RuntimeError("cannot open %s: %s" % (path, oiio.geterror()))
    spec = inp.spec()
    px = inp.read_image(0, 0, 0, spec.nchannels, "float")
    inp.close()
    names = list(spec.channelnames)
    return {n: px[:, :, i] for i, n in enumerate(names)}


def chan(img, *cands):
    for c in cands:
        if c in img:
            return img[c]
    for c in cands:  # suffix match (layer prefixes)
        for k in img:
            if k.endswith("." + c) or k == c:
                return img[k]
    raise KeyError("%s not in %s" % (cands, sorted(img)[:20]))


def rgb(img):
    return np.stack([chan(img, "Combined.R", "R"), chan(img, "Combined.G", "G"),
                     chan(img, "Combined.B", "B")], axis=-1)


def errors(a, b, m):
    a = np.clip(a[m], 0, 1)
    b = np.clip(b[m], 0, 1)
    mae = float(np.mean(np.abs(a - b)))
    mse = float(np.mean((a - b) ** 2))
    return mae, (10 * np.log10(1.0 / mse) if mse > 0 else 99.0)


def run_cli(cli, recipe, src, cam, out, quality=None, threads=2, debug=False):
    cmd = [cli, "run", "-s", recipe, "--camera", cam, src, "-o", out, "-f", "-v", "-j", str(threads)]
    if quality:
        cmd += ["-q", quality]
    if debug:
        cmd += ["--debug-outputs"]
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode:
        raise RuntimeError(p.stderr + p.stdout)
    m = re.search(r"effects ([0-9.]+) s", p.stdout)
    return float(m.group(1)) * 1e3 if m else float("nan")


def scene_recipe(root, overrides=None, quality=None):
    rec = json.load(open(os.path.join(root, "blend_scenes", "mirror_room", "recipe.json")))
    if quality:
        rec["quality"] = quality
    for e in rec["effects"]:
        if overrides:
            e["params"].update(overrides)
    return rec


def run_presets(a, root, d, src, cam, rec_path):
    """Each quality preset's output (with debug passes) and its median time."""
    outs, times = {}, {}
    for q in ("draft", "preview", "final", "reference"):
        json.dump(scene_recipe(root, quality=q), open(rec_path, "w"))
        out = os.path.join(d, "ssr_%s.exr" % q)
        ts = [run_cli(a.cli, rec_path, src, cam, out, debug=True) for _ in range(a.runs)]
        times[q] = float(np.median(ts))
        outs[q] = read(out)
    return outs, times


def measured_region(phys, ima, reference_out):
    """Physical mirrors whose reflected point the reference preset found on screen."""
    hit = np.zeros_like(ima, dtype=bool)
    for k in reference_out:
        if re.match(r"fx\d+_ssr_mirror_hit\.", k) or re.match(r"fx\d+_ssr_mirror_hit$", k):
            hit |= reference_out[k] > 0.5
    return phys & hit


def method_rows(d, W, before, truth, region, outs, times):
    """(method, MAE, PSNR, ms): the input, each preset, Eevee with and without SSR."""
    rows = [("no reflection (input)", *errors(before, truth, region), 0.0)]
    for q in ("draft", "preview", "final", "reference"):
        rows.append(("libfx %s" % q, *errors(rgb(outs[q]), truth, region), times[q]))
    for mode in ("eevee_ssr", "eevee_nossr"):
        p = os.path.join(d, "%s%s.exr" % (mode, W))
        if os.path.exists(p):
            t = json.load(open(os.path.join(d, "%s%s.time.json" % (mode, W))))
            rows.append(("Eevee %s" % ("SSR on" if mode == "eevee_ssr" else "SSR off"),
                         *errors(rgb(read(p)), truth, region), t["seconds"] * 1e3))
    return rows


def mirror_rows(ima, before, truth, region, final):
    out = []
    for name, idx in sorted(PHYSICAL.items(), key=lambda kv: kv[1]):
        m = region & (np.rint(ima) == idx)
        if m.sum() == 0:
            continue
        out.append((name, int(m.sum()), errors(before, truth, m)[0], errors(final, truth, m)[0]))
    return out


def write_tables(a, rows, per_mirror, region, phys):
    os.makedirs(os.path.join(a.out, "images"), exist_ok=True)
    with open(os.path.join(a.out, "ssr_accuracy.csv"), "w") as f:
        f.write("method,mae,psnr_db,ms\n")
        for r in rows:
            f.write("%s,%.5f,%.2f,%.1f\n" % r)
        f.write("\nmirror,region_px,mae_no_reflection,mae_final\n")
        for r in per_mirror:
            f.write("%s,%d,%.5f,%.5f\n" % r)
    print("region: %d px of %d physical-mirror px (%s)" % (region.sum(), phys.sum(), a.res))
    for r in rows:
        print("%-24s MAE %.4f  PSNR %6.2f dB  %9.1f ms" % r)
    for r in per_mirror:
        print("  %-18s %6d px  MAE none %.4f  final %.4f" % r)


def knob_curve(a, root, d, src, cam, rec_path, truth, region):
    """Error against time over the knobs (steps, refinement, resolution scale)."""
    variants = []
    for steps in (8, 16, 32, 64, 128, 256):
        variants.append(("steps %d" % steps, {"max_steps": steps, "stride": 2.0, "growth": 1.05,
                                              "refine": 4, "resolution_scale": 1.0}))
    for refine in (0, 1, 2, 4, 8):
        variants.append(("refine %d" % refine, {"max_steps": 64, "stride": 2.0, "growth": 1.05,
                                                "refine": refine, "resolution_scale": 1.0}))
    for scale in (0.25, 0.5, 1.0):
        variants.append(("scale %g" % scale, {"max_steps": 64, "stride": 2.0, "growth": 1.05,
                                              "refine": 4, "resolution_scale": scale}))
    curve = []
    for label, ov in variants:
        json.dump(scene_recipe(root, overrides=ov), open(rec_path, "w"))
        out = os.path.join(d, "ssr_curve.exr")
        ts = [run_cli(a.cli, rec_path, src, cam, out) for _ in range(a.runs)]
        mae, psnr = errors(rgb(read(out)), truth, region)
        curve.append((label, float(np.median(ts)), mae, psnr))
        print("curve %-10s %8.1f ms MAE %.4f PSNR %.2f" % curve[-1])
    with open(os.path.join(a.out, "ssr_curve.csv"), "w") as f:
        f.write("variant,ms,mae,psnr_db\n")
        for c in curve:
            f.write("%s,%.2f,%.5f,%.2f\n" % c)
    return curve


def plot_curve(plt, a, curve, rows):
    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=100)
    for fam, mk in (("steps", "o-"), ("refine", "s-"), ("scale", "^-")):
        pts = [c for c in curve if c[0].startswith(fam)]
        ax.plot([c[1] for c in pts], [c[2] for c in pts], mk, label=fam)
        for c in pts:
            ax.annotate(c[0].split()[1], (c[1], c[2]), fontsize=7, xytext=(3, 3), textcoords="offset points")
    for q in ("draft", "preview", "final", "reference"):
        r = [x for x in rows if x[0] == "libfx %s" % q][0]
        ax.plot([r[3]], [r[1]], "k*", ms=10)
        ax.annotate(q, (r[3], r[1]), fontsize=8, xytext=(4, -10), textcoords="offset points")
    none = rows[0][1]
    ax.axhline(none, color="grey", ls="--", lw=1)
    ax.text(ax.get_xlim()[0], none, " no reflection", va="bottom", fontsize=8, color="grey")
    ax.set_xscale("log")
    ax.set_xlabel("ssr_mirror time for the whole mirror-room stack, ms (%s, 2 threads)" % a.res)
    ax.set_ylabel("MAE vs Cycles mirrors (mirror pixels, hit on screen)")
    ax.set_title("ssr_mirror: error vs time over the knobs")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(a.out, "images", "ssr_error_vs_time.png"))


def srgb(x):
    x = np.clip(x, 0, 1)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def plot_images(plt, a, d, W, before, final, truth, region):
    """Side by side: input | libfx final | Cycles truth | Eevee SSR; and the region."""
    tiles = [("input (mirror backing)", before), ("libfx ssr_mirror (final)", final),
             ("Cycles true mirrors", truth)]
    pe = os.path.join(d, "eevee_ssr%s.exr" % W)
    if os.path.exists(pe):
        tiles.append(("Eevee SSR", rgb(read(pe))))
    fig, axs = plt.subplots(2, 2, figsize=(12, 7), dpi=80)
    for axx, (t, im) in zip(axs.flat, tiles):
        axx.imshow(srgb(im))
        axx.set_title(t, fontsize=10)
        axx.axis("off")
    fig.tight_layout()
    fig.savefig(os.path.join(a.out, "images", "ssr_mirror_room.png"))
    fig, axx = plt.subplots(figsize=(6.4, 3.6), dpi=100)
    show = srgb(truth) * 0.35
    show[region] = [1.0, 0.55, 0.0]
    axx.imshow(show)
    axx.set_title("measured region (orange): physical mirrors, reflected point on screen", fontsize=9)
    axx.axis("off")
    fig.tight_layout()
    fig.savefig(os.path.join(a.out, "images", "ssr_region.png"))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cli", required=True)
    ap.add_argument("--dir", default="/tmp/ssr")
    ap.add_argument("--res", default="640x360")
    ap.add_argument("--out", default="docs")
    ap.add_argument("--runs", type=int, default=3)
    a = ap.parse_args()
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    W = a.res.split("x")[0]
    d = a.dir
    src, cam = os.path.join(d, "back%s.exr" % W), os.path.join(d, "back%s.camera.json" % W)
    back = read(src)
    ref = read(os.path.join(d, "ref%s.exr" % W))
    ima = chan(back, "IndexMA.X", "IndexMA.V", "IndexMA")
    truth = rgb(ref)
    before = rgb(back)
    phys = np.isin(np.rint(ima), list(PHYSICAL.values()))
    rec_path = os.path.join(d, "ssr_recipe_tmp.json")

    outs, times = run_presets(a, root, d, src, cam, rec_path)
    region = measured_region(phys, ima, outs["reference"])
    rows = method_rows(d, W, before, truth, region, outs, times)
    final = rgb(outs["final"])
    write_tables(a, rows, mirror_rows(ima, before, truth, region, final), region, phys)
    curve = knob_curve(a, root, d, src, cam, rec_path, truth, region)

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    plot_curve(plt, a, curve, rows)
    plot_images(plt, a, d, W, before, final, truth, region)


if __name__ == "__main__":
    main()
