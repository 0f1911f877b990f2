#!/usr/bin/python3
"""god_rays and voronoi_caustics on a rendered Greek-bath frame, beside Blender's Sun Beams
compositor node on the same image, in one run; CSV + plots for docs/effects/god_rays.md.

    /usr/bin/python3 tests/bench/bench_greek_bath.py --render 1920x1080 [--runs 5] [--out out/bench_bath]
        [--max-naive 400] [--skip-caustics]

--render renders frame 1 of blend_scenes/greek_bath with the add-on's batch runner (4
samples) to get the passes and the scene sidecar; --exr/--sidecar use existing ones.
Needs the bench binary (cmake -DLIBFX_BUILD_BENCH=ON; $LIBFX_BENCH or build*/tests/bench).
Medians of --runs runs; the VM is shared: compare ratios within one run."""
import argparse
import csv
import glob
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BLENDER = os.environ.get("BLENDER", "blender")

SUN_BEAMS = r"""
import bpy, sys, time, json
args = sys.argv[sys.argv.index("--") + 1:]
src, sx, sy, length, runs = args[0], float(args[1]), float(args[2]), float(args[3]), int(args[4])
s = bpy.context.scene
img = bpy.data.images.load(src)
s.render.resolution_x, s.render.resolution_y = img.size[0], img.size[1]
s.render.resolution_percentage = 100
s.use_nodes = True
tree = s.node_tree
tree.nodes.clear()
node_img = tree.nodes.new("CompositorNodeImage"); node_img.image = img
beams = tree.nodes.new("CompositorNodeSunBeams")
beams.source = (sx, sy)
beams.ray_length = length
comp = tree.nodes.new("CompositorNodeComposite")
tree.links.new(node_img.outputs[0], beams.inputs[0])
tree.links.new(beams.outputs[0], comp.inputs[0])
times = {}
for em in ("TILED", "FULL_FRAME"):
    tree.execution_mode = em
    bpy.ops.render.render()
    t = []
    for _ in range(runs):
        t0 = time.perf_counter(); bpy.ops.render.render(); t.append(time.perf_counter() - t0)
    times[em] = sorted(t)[len(t) // 2]
# the empty tree's cost (image load, compositor start): subtract it for the node's own time
tree.links.new(node_img.outputs[0], comp.inputs[0])
tree.nodes.remove(beams)
bpy.ops.render.render()
t = []
for _ in range(runs):
    t0 = time.perf_counter(); bpy.ops.render.render(); t.append(time.perf_counter() - t0)
times["identity"] = sorted(t)[len(t) // 2]
print("RESULT " + json.dumps(times))
"""


def find_bench():
    env = os.environ.get("LIBFX_BENCH")
    if env:
        return env
    # build/ (scripts/setup.sh's) first: other build dirs may hold older binaries
    for p in [os.path.join(ROOT, "build", "tests", "bench", "bench_greek_bath")] + \
            sorted(glob.glob(os.path.join(ROOT, "build*", "tests", "bench", "bench_greek_bath"))):
        if os.path.exists(p):
            return p
    sys.exit("bench_greek_bath not built (cmake -DLIBFX_BUILD_BENCH=ON)")


def project_sun(side):
    w2c = np.array(side["world_to_camera"], dtype=np.float64)
    proj = np.array(side["projection"], dtype=np.float64)
    sun = [l for l in side["lights"] if l["name"] == "Sun"][0]
    v = w2c[:3, :3] @ (-np.array(sun["direction"], dtype=np.float64))
    c = proj @ np.array([v[0], v[1], v[2], 0.0])
    return (c[0] / c[3] + 1) * 0.5, (c[1] / c[3] + 1) * 0.5   # Sun Beams: (0,0) bottom-left


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--render", help="WxH: render the bath frame first")
    ap.add_argument("--exr")
    ap.add_argument("--sidecar")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--max-naive", type=int, default=400, help="largest naive sample count in the sweep")
    ap.add_argument("--skip-caustics", action="store_true", help="god_rays rows only")
    ap.add_argument("--csv", help="reuse this bench_greek_bath CSV instead of running the binary")
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "bench_bath"))
    ap.add_argument("--plots", default=os.path.join(ROOT, "docs", "images"))
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    if a.render:
        prefix = os.path.join(a.out, "bath_")
        subprocess.run([BLENDER, "-b", os.path.join(ROOT, "blend_scenes", "greek_bath", "greek_bath.blend"),
                        "--python", os.path.join(ROOT, "addon", "libfx", "batch.py"), "--", "--keep-passes", "--frames", "1",
                        "--output", prefix, "--resolution", a.render, "--samples", "4"], check=True)
        a.exr, a.sidecar = prefix + "libfx_passes.0001.exr", prefix + "libfx.0001.camera.json"
    csv_path = os.path.join(a.out, "bench_greek_bath.csv")
    if a.csv:
        with open(a.csv) as src, open(csv_path, "w") as f:
            f.write("".join(l for l in src if not l.startswith("sun_beams_blender")))
    else:
        with open(csv_path, "w") as f:
            subprocess.run([find_bench(), a.exr, a.sidecar, str(a.runs), str(a.max_naive),
                            "1" if a.skip_caustics else "0"], check=True, stdout=f)

    # Blender's Sun Beams node on the same image (Combined only), source at the sun.
    side = json.load(open(a.sidecar))
    comb = os.path.join(a.out, "combined.exr")
    subprocess.run(["oiiotool", a.exr, "--ch", "R=Combined.R,G=Combined.G,B=Combined.B,A=Combined.A", "-o", comb],
                   check=True)
    sx, sy = project_sun(side)
    with tempfile.NamedTemporaryFile("w", suffix=".py", delete=False) as f:
        f.write(SUN_BEAMS)
    try:
        r = subprocess.run([BLENDER, "-b", "--factory-startup", "--python", f.name, "--", comb, str(sx), str(sy),
                            "0.5", str(a.runs)], capture_output=True, text=True, check=True)
    finally:
        os.unlink(f.name)
    res = json.loads([l for l in r.stdout.splitlines() if l.startswith("RESULT ")][0][7:])
    with open(csv_path, "a") as f:
        for em in ("TILED", "FULL_FRAME"):
            f.write("sun_beams_blender,%s,ray_length,0.5,%.3f,,,\n" % (em, 1000 * (res[em] - res["identity"])))
        f.write("sun_beams_blender,empty_tree,,,%.3f,,,\n" % (1000 * res["identity"]))
    print(open(csv_path).read())
    rows = list(csv.DictReader(open(csv_path)))
    sb = {x["method"]: float(x["ms_median"]) for x in rows if x["effect"] == "sun_beams_blender"}
    print("same run: Sun Beams (full frame, minus empty tree) %.1f ms, tiled %.1f ms" % (sb["FULL_FRAME"], sb["TILED"]))
    for x in rows:
        if x["effect"] == "god_rays" and x["method"] in ("preset", "reference", "identity"):
            ms = float(x["ms_median"])
            print("  god_rays %-9s %-10s %9.1f ms  Sun Beams / this = %6.1fx  (RMS err %s)" % (
                x["method"], x["value"], ms, sb["FULL_FRAME"] / ms, x["err_rms"] or "-"))
    plot(list(csv.DictReader(open(csv_path))), a.plots)


def plot(rows, outdir):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib missing (python3-matplotlib): no plots")
        return
    os.makedirs(outdir, exist_ok=True)
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for method, mk in (("naive", "o-"), ("naive_jitter", "x--")):
        r = [x for x in rows if x["effect"] == "god_rays" and x["method"] == method]
        s = [float(x["value"]) for x in r]
        ax[0].plot(s, [float(x["ms_median"]) for x in r], mk, label=method)
        ax[1].plot([float(x["ms_median"]) for x in r], [float(x["err_rms"]) for x in r], mk, label=method)
        for x in r:
            ax[1].annotate(x["value"], (float(x["ms_median"]), float(x["err_rms"])), fontsize=7)
    r = [x for x in rows if x["effect"] == "god_rays" and x["method"] == "polar"]
    for down, mk in (("1", "s-"), ("2", "D-"), ("3", "^-"), ("4", "v-")):
        rd = [x for x in r if x["value"].split("/")[-1] == down]
        if not rd:
            continue
        rd.sort(key=lambda x: float(x["ms_median"]))
        ax[1].plot([float(x["ms_median"]) for x in rd], [float(x["err_rms"]) for x in rd], mk,
                   label="polar, downsample %s" % down)
    for x in r:
        ax[1].annotate(x["value"], (float(x["ms_median"]), float(x["err_rms"])), fontsize=6)
    rp = [x for x in rows if x["effect"] == "god_rays" and x["method"] == "preset"]
    ax[1].plot([float(x["ms_median"]) for x in rp], [float(x["err_rms"]) for x in rp], "k*", ms=10, label="presets")
    for x in rp:
        ax[0].axhline(float(x["ms_median"]), color="C2", lw=0.8, ls=":")
        ax[0].annotate("polar %s" % x["value"], (10, float(x["ms_median"])), fontsize=7, color="C2")
    sb = [x for x in rows if x["effect"] == "sun_beams_blender" and x["method"] == "FULL_FRAME"]
    if sb:
        ax[0].axhline(float(sb[0]["ms_median"]), color="k", ls="--", label="Blender Sun Beams (full frame)")
    ax[0].set_xscale("log"); ax[0].set_yscale("log")
    ax[0].set_xlabel("samples (naive)"); ax[0].set_ylabel("ms (median)")
    ax[0].set_title("god_rays time (dotted: polar presets)")
    ax[0].legend(fontsize=8)
    ax[1].set_xscale("log"); ax[1].set_yscale("log")
    ax[1].set_xlabel("ms (median)"); ax[1].set_ylabel("RMS error / peak rays (vs naive 2000)")
    ax[1].set_title("error vs time"); ax[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(outdir, "bench_god_rays.png"), dpi=90)
    if not any(x["effect"] == "voronoi_caustics" for x in rows):
        print("plots in", outdir)
        return
    fig, ax = plt.subplots(figsize=(5, 4))
    for method, mk in (("grid", "o-"), ("brute", "s-")):
        r = [x for x in rows if x["effect"] == "voronoi_caustics" and x["method"] == method]
        ax.plot([float(x["value"]) for x in r], [float(x["ms_median"]) for x in r], mk, label=method)
    ax.set_xscale("log"); ax.set_yscale("log")
    ax.set_xlabel("points"); ax.set_ylabel("ms (median)"); ax.set_title("voronoi_caustics on the pool")
    ax.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(outdir, "bench_caustics.png"), dpi=90)
    print("plots in", outdir)


if __name__ == "__main__":
    main()
