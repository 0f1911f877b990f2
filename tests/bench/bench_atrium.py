"""Atrium measurements (docs/effects/vsm_shadows.md, docs/effects/rain.md, docs/performance.md).

One command renders what is missing, measures, and writes OUT/tables.md, OUT/report.json
and the plots OUT/*.png:

    LIBFX_LIBRARY=build/libfx/libfx.so /usr/bin/python3 tests/bench/bench_atrium.py OUT_DIR \
        [--res 480x270] [--spp 32] [--runs 5] [--only vsm,sun,hd,reuse,sweep] [--gif]

Renders are kept in OUT_DIR and reused by a re-run (delete them to re-render).

1. vsm: VSM against Cycles' ray-traced shadows of the same frame (8, in the courtyard). The
   scene's Sun casts no Cycles shadow (libfx adds them); the truth is the same frame with
   the Sun's cast_shadow on; a second truth with another seed gives the noise floor. Mean
   absolute error of Combined (linear) over the frame and over the pixels the Sun's shadow
   changes, per method, filter size and bleeding reduction, with the time of each run.
   Twice: the full render (world light, bounces: the input also carries the indirect light
   of sun that should have been blocked, which no shadow map can remove), and the Sun's
   direct diffuse light alone (world off, no bounces, Principled specular 0), where input
   and truth differ only by the Sun's visibility.
2. sun: the sun_diffuse model, DiffCol * colour * E * max(N.L, 0) / pi, against Cycles'
   direct light of the Sun alone (world off, no bounces, Principled specular 0, no shadow).
3. hd: the whole rain stack at 1280x720 (frame 1, under the arcade): per-run time of a
   fresh context (every view read and built) and of one context reused (frames 2..N:
   the aux-view cache), medians and same-run ratios; per effect.
4. reuse: batch frames 1..8 (160x90): aux-view renders and reuses from the add-on's log.
5. sweep: tests/bench/bench_atrium.sh on the build holding LIBFX_LIBRARY (1920x1080, light
   maps 512..4096, uncached vs cached, SAT vs Gaussian).
--gif also remakes the flip-book docs/images/atrium_rain.gif (frames 1..8, 320x180).
"""
import argparse
import json
import os
import pathlib
import statistics
import subprocess
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests" / "blender"))
import addon_testlib as T  # noqa: E402
import importlib.util  # noqa: E402

# addon/libfx/native.py imports no bpy; the package's __init__ does: load the file alone
_spec = importlib.util.spec_from_file_location("libfx_native", ROOT / "addon" / "libfx" / "native.py")
native = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(native)

BLEND = ROOT / "blend_scenes" / "atrium" / "atrium.blend"
LIB = os.environ.get("LIBFX_LIBRARY", str(ROOT / "build" / "libfx" / "libfx.so"))
FRAME = 8


def batch(out, frames, res, samples, expr=None, recipe=None, check=None):
    """Renders unless `check` (a file batch writes) exists; returns the libfx log lines."""
    if check is not None and pathlib.Path(check).exists():
        return []
    args = ["blender", "-b", str(BLEND)]
    if expr:
        args += ["--python-expr", expr]
    args += ["--python", str(ROOT / "addon" / "libfx" / "batch.py"), "--", "--keep-passes", "--frames", frames,
             "--output", out, "--resolution", res, "--samples", str(samples)]
    if recipe:
        args += ["--recipe", recipe]
    t0 = time.perf_counter()
    p = subprocess.run(args, capture_output=True, text=True, env=dict(os.environ, LIBFX_LIBRARY=LIB))
    if p.returncode:
        sys.exit(p.stdout[-3000:] + p.stderr[-3000:])
    print("rendered %s (%s, %s spp) in %.0f s" % (out, res, samples, time.perf_counter() - t0), flush=True)
    return [l for l in p.stdout.splitlines() if l.startswith("libfx:")]


def run_stack(recipe, passes, sidecar, frame, ctx=None, with_image=True):
    """Runs a recipe on a passes EXR; returns (Combined or None, ms of fx_stack_run, timings)."""
    own = ctx is None
    ctx = ctx or native.Context(0)
    try:
        st = native.Stack(ctx, recipe)
        fin = native.Frame.read(ctx, passes, st)
        fin.apply_sidecar(sidecar)
        fin.set_time(frame, 24)
        t0 = time.perf_counter()
        fout = st.run(fin)
        ms = (time.perf_counter() - t0) * 1e3
        timings = st.timings()
        img = None
        if with_image:
            tmp = str(pathlib.Path(passes).with_suffix(".bench%d.exr" % os.getpid()))
            fout.write_exr(tmp, only_combined=True)
            img = T.Exr(tmp).get("Combined", "RGB")
            os.remove(tmp)
        fout.close(); fin.close(); st.close()
    finally:
        if own:
            ctx.close()
    return img, ms, timings


def noop_recipe(out):
    p = out / "noop.json"
    p.write_text(json.dumps({"version": 1, "effects": [
        {"effect": "color_matrix", "params": {"operator": "sepia", "mix": 0.0}}]}))
    return str(p)


def md_table(head, rows):
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


# ---------------------------------------------------------------- 1. VSM vs Cycles

DIRECT = ("import bpy; sc = bpy.context.scene; sc.world = None; sc.cycles.max_bounces = 0\n"
          "for m in bpy.data.materials:\n"
          "    for n in (m.node_tree.nodes if m.use_nodes else []):\n"
          "        if n.type == 'BSDF_PRINCIPLED': n.inputs['Specular'].default_value = 0.0\n")


def vsm(out, res, spp, report, md, direct=False):
    """direct=False: the full render (world, bounces); direct=True: the Sun's direct
    diffuse light alone (DIRECT), so the truth differs from the input only by the Sun's
    visibility: what the shadow map is responsible for."""
    fr = FRAME
    a, t, u, key = ("s", "d", "e", "vsm_direct") if direct else ("a", "t", "u", "vsm_vs_cycles")
    pre = DIRECT if direct else "import bpy\n"
    pref = lambda p: out / ("%s_libfx_passes.%04d.exr" % (p, fr))
    if direct:
        sun_probe_render(out, res, spp)
    else:
        batch(str(out / "a_"), str(fr), res, spp, check=pref("a"))
    sun_on = pre + "bpy.data.objects['Sun'].data.cycles.cast_shadow = True\n"
    batch(str(out / (t + "_")), str(fr), res, spp, recipe=noop_recipe(out), expr=sun_on, check=pref(t))
    batch(str(out / (u + "_")), str(fr), res, spp, recipe=noop_recipe(out),
          expr=sun_on + "bpy.context.scene.cycles.seed = 17\n", check=pref(u))
    passes = str(pref(a))
    side = json.load(open(out / ("%s_libfx.%04d.camera.json" % (a, fr))))
    truth = T.Exr(pref(t)).get("Combined", "RGB")
    truth2 = T.Exr(pref(u)).get("Combined", "RGB")
    plain = T.Exr(passes).get("Combined", "RGB")
    lum = lambda im: im @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    sh = np.abs(lum(plain) - lum(truth)) > 0.02 * max(1e-6, float(np.percentile(lum(truth), 99)))
    frac = float(sh.mean())

    def err(img):
        d = np.abs(img - truth)
        return float(d.mean()), float(d[sh].mean()) if sh.any() else 0.0

    rows = [("none (no shadow)", "", "", *err(plain), ""),
            ("Cycles, other seed (noise floor)", "", "", *err(truth2), "")]
    for method in ("hard", "pcf", "vsm", "vsm_gauss"):
        for size in ((1,) if method == "hard" else (1, 3, 5, 9, 15, 31) if method == "vsm" else (3, 5, 9, 15, 31)):
            for bleed in ((0.3,) if not method.startswith("vsm") else (0.0, 0.3, 0.6)):
                params = {"light": "Sun", "method": "vsm" if method.startswith("vsm") else method,
                          "filter_size": size, "bleed_reduction": bleed}
                if method == "vsm_gauss":
                    params["filter"] = "gaussian"
                rec = {"version": 1, "effects": [{"effect": "vsm_shadows", "params": params}]}
                img, ms, _ = run_stack(rec, passes, side, fr)
                rows.append((method, size, bleed, *err(img), round(ms, 1)))
    report[key] = {"res": res, "spp": spp, "frame": fr, "shadow_pixel_fraction": frac, "rows": rows}
    md.append("### VSM against Cycles' ray-traced shadows, %s (frame %d, %s, %d spp; shadow-changed pixels: %.1f%%)\n"
              % ("the Sun's direct diffuse light alone" if direct else "full render", fr, res, spp, 100 * frac))
    md.append(md_table(["method", "filter (texels)", "bleed", "MAE frame", "MAE shadow px", "ms"],
                       [(r[0], r[1], r[2], "%.5f" % r[3], "%.5f" % r[4], r[5]) for r in rows]))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(6, 3.6))
        for method, bleed, style in (("pcf", 0.3, "k-o"), ("vsm", 0.0, "b--s"), ("vsm", 0.3, "b-s"),
                                     ("vsm", 0.6, "b:s"), ("vsm_gauss", 0.3, "g-^")):
            pts = [(r[1], r[4]) for r in rows[2:] if r[0] == method and r[2] == bleed]
            ax.plot([p[0] for p in pts], [p[1] for p in pts], style, label="%s bleed %.1f" % (method, bleed)
                    if method != "pcf" else "pcf")
        ax.axhline(rows[0][4], color="r", lw=0.8, label="no shadow")
        ax.axhline(rows[1][4], color="gray", lw=0.8, label="Cycles noise floor")
        ax.set_xscale("log", base=2)
        ax.set_xlabel("filter size (light-map texels)")
        ax.set_ylabel("MAE on shadow-changed pixels")
        ax.legend(fontsize=7)
        fig.tight_layout()
        ax.set_title("Sun direct light only" if direct else "full render (world, bounces)", fontsize=9)
        fig.savefig(out / (key + ".png"), dpi=110)
    except ImportError:
        pass


# ---------------------------------------------------------------- 2. sun_diffuse model

def sun_probe_render(out, res, spp):
    """The Sun's direct diffuse light alone, no Cycles shadow, with the passes sun_diffuse
    reads (a vsm_shadows of strength 0 asks for them and changes nothing)."""
    rec = out / "sun_probe.json"
    rec.write_text(json.dumps({"version": 1, "effects": [{"effect": "vsm_shadows", "params": {
        "light": "Sun", "strength": 0.0}}]}))
    batch(str(out / "s_"), str(FRAME), res, spp, recipe=str(rec), expr=DIRECT,
          check=out / ("s_libfx_passes.%04d.exr" % FRAME))


def sun(out, res, spp, report, md):
    fr = FRAME
    sun_probe_render(out, res, spp)
    e = T.Exr(out / ("s_libfx_passes.%04d.exr" % fr))
    side = json.load(open(out / ("s_libfx.%04d.camera.json" % fr)))
    light = [l for l in side["lights"] if l["name"] == "Sun"][0]
    comb, dc, n = e.get("Combined", "RGB"), e.get("DiffCol", "RGB"), e.get("Normal", "XYZ")
    to_l = -np.array(light["direction"], np.float32)
    ndl = np.clip(n @ to_l, 0, None)[..., None]
    pred = dc * ndl * np.array(light["color"], np.float32) * light["energy"] / np.pi
    m = (pred.sum(-1) > 0.05) & (np.linalg.norm(n, axis=-1) > 0.9)
    # Burley's factor (vsm_shadows diffuse "principled"): V from the camera through each pixel
    h, w = n.shape[:2]
    c2w = np.linalg.inv(np.array(side["world_to_camera"], np.float64).reshape(4, 4))
    proj = np.array(side["projection"], np.float64).reshape(4, 4)
    ys, xs = np.mgrid[0:h, 0:w]
    ndc = np.stack([(xs + 0.5) / w * 2 - 1, 1 - (ys + 0.5) / h * 2, np.ones((h, w)), np.ones((h, w))], -1)
    pv = ndc @ np.linalg.inv(proj).T
    d = pv[..., :3] / pv[..., 3:4]
    v = -(d @ c2w[:3, :3].T)
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    nv = np.clip((n * v).sum(-1), 0, 1)
    hv = v + to_l
    hv /= np.linalg.norm(hv, axis=-1, keepdims=True)
    lh = np.clip(hv @ to_l, 0, 1)
    rows, nz = [], n[..., 2]
    groups = (("all", m), ("up-facing (floor, N.z > 0.9)", m & (nz > 0.9)), ("walls (|N.z| < 0.3)", m & (np.abs(nz) < 0.3)))
    for model, rough in (("lambert", None), ("principled", 0.5), ("principled", 0.7)):
        f = 1.0
        if rough is not None:
            f90 = 0.5 + 2 * rough * lh ** 2
            f = ((1 + (f90 - 1) * (1 - ndl[..., 0]) ** 5) * (1 + (f90 - 1) * (1 - nv) ** 5))[..., None]
        ratio = comb.sum(-1) / np.maximum((pred * f).sum(-1), 1e-9)
        for gname, g in groups:
            q = np.percentile(ratio[g], [10, 25, 50, 75, 90])
            rows.append((model + ("" if rough is None else " r=%.1f" % rough), gname, int(g.sum()),
                         *("%.3f" % x for x in q)))
    report["sun_diffuse"] = rows
    md.append("### sun_diffuse model against Cycles (frame %d, %s, Sun only, no bounces, Principled specular 0; "
              "floor roughness 0.7, walls 0.85, columns 0.5)\n" % (fr, res))
    md.append(md_table(["model", "pixels", "n", "Cycles / model: p10", "p25", "median", "p75", "p90"], rows))


# ---------------------------------------------------------------- 3. the stack at 1280x720

def hd(out, runs, report, md):
    log = batch(str(out / "hd_"), "1", "1280x720", 4, check=out / "hd_libfx_passes.0001.exr")
    if log:
        report["hd_log"] = log
    recipe = json.load(open(ROOT / "blend_scenes" / "atrium" / "recipe.json"))
    side = json.load(open(out / "hd_libfx.0001.camera.json"))
    passes = str(out / "hd_libfx_passes.0001.exr")
    cold, warm, eff_cold, eff_warm = [], [], [], []
    # alternate so both see the same machine load; the warm context is made once and
    # primed with one run (frame 1), then times frames 2..N
    with native.Context(0) as wctx:
        run_stack(recipe, passes, side, 1, ctx=wctx, with_image=False)
        for i in range(runs):
            _, ms, t = run_stack(recipe, passes, side, 2 + i, with_image=False)
            cold.append(ms); eff_cold.append(t)
            _, ms, t = run_stack(recipe, passes, side, 2 + i, ctx=wctx, with_image=False)
            warm.append(ms); eff_warm.append(t)
    # same bits, cached or not
    a, _, _ = run_stack(recipe, passes, side, 3)
    with native.Context(0) as c2:
        run_stack(recipe, passes, side, 3, ctx=c2, with_image=False)
        b, _, _ = run_stack(recipe, passes, side, 3, ctx=c2)
    same = bool(np.array_equal(a, b))
    names = [t["effect"] for t in eff_cold[0]]
    med = lambda xs: statistics.median(xs)
    per = [(nm, "%.1f" % med([e[i]["ms"] for e in eff_cold]), "%.1f" % med([e[i]["ms"] for e in eff_warm]))
           for i, nm in enumerate(names)]
    ratios = [w / c for w, c in zip(warm, cold)]
    report["hd"] = {"cold_ms": cold, "warm_ms": warm, "ratio_warm_over_cold": ratios, "per_effect": per,
                    "cached_equals_uncached": same}
    md.append("### The rain stack at 1280x720 (frame 1 passes, %d runs, medians, ms; threads = cores)\n" % runs)
    md.append(md_table(["", "fresh context (frame 1: read + build the views)", "one context (frames 2..N: cached)"],
                       [("whole stack", "%.1f" % med(cold), "%.1f" % med(warm))] + per))
    md.append("\nSame-run ratio cached / fresh: median %.2f (min %.2f, max %.2f); cached output bit-identical to "
              "uncached: %s.\n" % (med(ratios), min(ratios), max(ratios), same))


# ---------------------------------------------------------------- 4. reuse of aux views

def reuse(out, report, md, gif):
    res, spp = ("320x180", 8) if gif else ("160x90", 1)
    pre = out / ("fb_" if gif else "ru_")
    for p in out.glob(pre.name + "*"):
        p.unlink()
    t0 = time.perf_counter()
    log = batch(str(pre), "1-8", res, spp)
    wall = time.perf_counter() - t0
    rendered = [l for l in log if "aux view" in l and "rendered" in l]
    reused = [l for l in log if "aux view" in l and "reused" in l]
    import re
    per = {}
    for l in log:
        mt = re.match(r"libfx: frame (\d+): (.*) \(([\d.]+) ms in all\)", l)
        if mt:
            per[int(mt.group(1))] = {k: float(v) for k, v in re.findall(r"(\w+) ([\d.]+) ms", mt.group(2))}
    report["reuse"] = {"frames": 8, "res": res, "aux_rendered": rendered, "aux_reused": len(reused), "wall_s": wall,
                       "effect_ms_per_frame": per}
    md.append("### Aux views over a batch of 8 frames (%s)\n" % res)
    md.append(md_table(["aux views rendered", "reused", "batch wall (s)"],
                       [(len(rendered), len(reused), "%.0f" % wall)]))
    if per:
        names = list(per[min(per)].keys())
        md.append("\nThe stack per frame in that batch (ms; frame 1 reads and builds the views' maps, frames "
                  "2..8 take them from the context's cache):\n")
        md.append(md_table(["frame"] + names, [(f, *("%.1f" % per[f].get(n, 0) for n in names)) for f in sorted(per)]))
    md.append("\n" + "\n".join("    " + l for l in rendered) + "\n")
    if gif:
        pngs = []
        for f in range(1, 9):
            p = out / ("fb_%d.png" % f)
            subprocess.run(["oiiotool", str(out / ("fb_libfx.%04d.exr" % f)), "--ch",
                            "Combined.R,Combined.G,Combined.B", "--colorconvert", "linear", "sRGB", "-o", str(p)],
                           check=True)
            pngs.append(str(p))
        g = ROOT / "docs" / "images" / "atrium_rain.gif"
        from PIL import Image   # python3-pil (scripts/setup.sh)
        ims = [Image.open(p).convert("RGB") for p in pngs]
        ims[0].save(g, save_all=True, append_images=ims[1:], duration=120, loop=0)


# ---------------------------------------------------------------- 5. the 1080p light-map sweep

def sweep(out, runs, report, md):
    """tests/bench/bench_atrium.sh against the build that holds LIBFX_LIBRARY: vsm_shadows at
    1920x1080 per light-map size, uncached vs cached, and SAT vs Gaussian (2 threads)."""
    build = pathlib.Path(LIB).resolve().parent.parent
    p = subprocess.run(["sh", str(ROOT / "tests" / "bench" / "bench_atrium.sh"), str(build), "2", str(runs)],
                       capture_output=True, text=True)
    if p.returncode:
        sys.exit(p.stdout[-2000:] + p.stderr[-2000:])
    (out / "vsm_bench.csv").write_text(p.stdout)
    report["sweep_csv"] = p.stdout
    md.append("### vsm_shadows at 1920x1080 per light-map size (bench_atrium.sh, 2 threads; OUT/vsm_bench.csv)\n")
    md.append("```\n" + p.stdout.strip() + "\n```")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out", nargs="?", default="/tmp/bench_atrium")
    ap.add_argument("--res", default="480x270")
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--only", default="vsm,sun,hd,reuse,sweep")
    ap.add_argument("--gif", action="store_true")
    a = ap.parse_args()
    out = pathlib.Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    native.load()
    report, md = {"library": LIB}, []
    only = a.only.split(",")
    if "vsm" in only:
        vsm(out, a.res, a.spp, report, md)
        vsm(out, a.res, a.spp, report, md, direct=True)
    if "sun" in only:
        sun(out, a.res, a.spp, report, md)
    if "hd" in only:
        hd(out, a.runs, report, md)
    if "reuse" in only:
        reuse(out, report, md, a.gif)
    if "sweep" in only:
        sweep(out, a.runs, report, md)
    (out / "report.json").write_text(json.dumps(report, indent=1))
    (out / "tables.md").write_text("\n\n".join(md) + "\n")
    print("\n\n".join(md))


if __name__ == "__main__":
    main()
