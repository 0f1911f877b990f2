#!/usr/bin/python3
"""Side-by-side timings at 1920x1080 for the foundation's effects, in one run:

  libfx run (1 and 2 threads)  vs  oiiotool  vs  Blender 3.4's compositor nodes
  (Blur, Pixelate) on the same EXR, beside a plain EXR read+write; plus the peak
  memory of `libfx run` when it decodes only what the stack needs vs every pass.

Usage: /usr/bin/python3 tests/bench/bench_peers.py [--runs 5] [--out out/bench]
Writes out/bench/peers.md and peers.csv. Medians of --runs runs; the machine's memory
bandwidth drifts between runs, so compare ratios within one run (docs/performance.md).
"""
import argparse
import csv
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CLI = os.environ.get("LIBFX_CLI", os.path.join(ROOT, "build", "libfx", "libfx"))
BLENDER = os.environ.get("BLENDER", "blender")
# Blender's Gaussian blur weights exp(-(3 i / size)^2 / 2): sigma = size / 3.
BLENDER_BLUR_SIZE = 50
SIGMA = BLENDER_BLUR_SIZE / 3.0
PIXEL_CELL = 16

RENDER_ALL_PASSES = r"""
import bpy, sys
out = sys.argv[sys.argv.index("--") + 1]
s = bpy.context.scene
s.render.engine = "CYCLES"
s.cycles.samples = 1
s.cycles.use_denoising = False
s.render.resolution_x, s.render.resolution_y, s.render.resolution_percentage = 1920, 1080, 100
vl = s.view_layers[0]
for p in ("use_pass_z", "use_pass_mist", "use_pass_normal", "use_pass_position", "use_pass_vector",
          "use_pass_uv", "use_pass_object_index", "use_pass_material_index", "use_pass_diffuse_direct",
          "use_pass_diffuse_indirect", "use_pass_diffuse_color", "use_pass_glossy_direct",
          "use_pass_glossy_indirect", "use_pass_glossy_color", "use_pass_transmission_direct",
          "use_pass_transmission_indirect", "use_pass_transmission_color", "use_pass_emit",
          "use_pass_environment", "use_pass_ambient_occlusion", "use_pass_cryptomatte_object",
          "use_pass_cryptomatte_material", "use_pass_cryptomatte_asset"):
    if hasattr(vl, p):
        setattr(vl, p, True)
s.render.image_settings.file_format = "OPEN_EXR_MULTILAYER"
s.render.image_settings.color_depth = "32"
s.render.image_settings.exr_codec = "ZIP"
s.render.filepath = out
s.frame_set(1)
bpy.ops.render.render(write_still=True)
"""

# Runs a compositor tree Image -> [node] -> Composite on the EXR and times the render
# (no Render Layers node, so Blender composites without rendering the scene).
BLENDER_COMPOSITE = r"""
import bpy, sys, time, json
args = sys.argv[sys.argv.index("--") + 1:]
src, mode, runs = args[0], args[1], int(args[2])
s = bpy.context.scene
s.render.resolution_x, s.render.resolution_y, s.render.resolution_percentage = 1920, 1080, 100
s.use_nodes = True
tree = s.node_tree
tree.nodes.clear()
img = tree.nodes.new("CompositorNodeImage")
img.image = bpy.data.images.load(src)
comp = tree.nodes.new("CompositorNodeComposite")
if mode == "blur":
    node = tree.nodes.new("CompositorNodeBlur")
    node.filter_type = "GAUSS"
    node.size_x = node.size_y = %(size)d
elif mode == "pixelate":
    # Blender's Pixelate keys its cell size on the input's resolution: scale down by
    # the cell size, pixelate, scale back up (the documented node chain).
    down = tree.nodes.new("CompositorNodeScale"); down.space = "RELATIVE"
    down.inputs[1].default_value = down.inputs[2].default_value = 1.0 / %(cell)d
    node = tree.nodes.new("CompositorNodePixelate")
    up = tree.nodes.new("CompositorNodeScale"); up.space = "RELATIVE"
    up.inputs[1].default_value = up.inputs[2].default_value = float(%(cell)d)
    tree.links.new(img.outputs[0], down.inputs[0]); tree.links.new(down.outputs[0], node.inputs[0])
    tree.links.new(node.outputs[0], up.inputs[0]); tree.links.new(up.outputs[0], comp.inputs[0])
    node = None
else:
    node = None
if mode in ("blur",):
    tree.links.new(img.outputs[0], node.inputs[0])
    tree.links.new(node.outputs[0], comp.inputs[0])
elif mode == "identity":
    tree.links.new(img.outputs[0], comp.inputs[0])
times = {}
for em in ("TILED", "FULL_FRAME"):
    tree.execution_mode = em
    bpy.ops.render.render()  # warm-up: image load and caches
    t = []
    for _ in range(runs):
        t0 = time.perf_counter()
        bpy.ops.render.render()
        t.append(time.perf_counter() - t0)
    times[em] = sorted(t)[len(t) // 2]
print("RESULT " + json.dumps(times))
""" % {"size": BLENDER_BLUR_SIZE, "cell": PIXEL_CELL}


def run_timed(cmd, runs, env=None):
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def peak_rss_mib(cmd):
    r = subprocess.run(["/usr/bin/time", "-f", "%M"] + cmd, check=True, capture_output=True, text=True)
    return int(r.stderr.strip().splitlines()[-1]) / 1024.0


def blender_composite(src, mode, runs):
    with tempfile.NamedTemporaryFile("w", suffix=".py", delete=False) as f:
        f.write(BLENDER_COMPOSITE)
    try:
        r = subprocess.run([BLENDER, "-b", "--factory-startup", "--python", f.name, "--", src, mode, str(runs)],
                           check=True, capture_output=True, text=True)
    finally:
        os.unlink(f.name)
    for line in r.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    raise RuntimeError("blender printed no result:\n" + r.stdout[-2000:] + r.stderr[-2000:])


def write_recipe(path, effect, params):
    with open(path, "w") as f:
        json.dump({"version": 1, "effects": [{"effect": effect, "params": params}]} if effect
                  else {"version": 1, "effects": []}, f)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "bench"))
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    src = os.path.join(a.out, "allpasses_1080p.exr")
    if not os.path.exists(src):
        print("rendering a 1920x1080 frame with every pass (Cycles, 1 sample)...", flush=True)
        with tempfile.NamedTemporaryFile("w", suffix=".py", delete=False) as f:
            f.write(RENDER_ALL_PASSES)
        scene = os.path.join(ROOT, "blend_scenes", "greek_bath", "greek_bath.blend")
        cmd = [BLENDER, "-b"] + ([scene] if os.path.exists(scene) else []) + \
              ["--python", f.name, "--", os.path.join(a.out, "allpasses_1080p_render")]
        subprocess.run(cmd, check=True, capture_output=True)
        os.unlink(f.name)
        os.rename(os.path.join(a.out, "allpasses_1080p_render.exr"), src)
    info = json.loads(subprocess.run([CLI, "info", src], check=True, capture_output=True, text=True).stdout)

    recipes = {
        "read+write (empty stack)": (None, {}),
        "gaussian_blur sigma %.1f (final)" % SIGMA: ("gaussian_blur", {"sigma": SIGMA}),
        "gaussian_blur sigma %.1f (draft)" % SIGMA: ("gaussian_blur", {"sigma": SIGMA, "algorithm": "box", "box_passes": 3}),
        "gaussian_blur sigma %.1f (reference)" % SIGMA: ("gaussian_blur", {"sigma": SIGMA, "algorithm": "exact"}),
        "color_matrix sepia": ("color_matrix", {"operator": "sepia"}),
        "pixelate cells %d" % PIXEL_CELL: ("pixelate", {"mode": "cells", "cell_size": PIXEL_CELL}),
        "pixelate average %d" % PIXEL_CELL: ("pixelate", {"mode": "average", "cell_size": PIXEL_CELL}),
    }
    rows = []
    out_exr = os.path.join(a.out, "peer_out.exr")
    for label, (effect, params) in recipes.items():
        rp = os.path.join(a.out, "recipe.json")
        write_recipe(rp, effect, params)
        for threads in (1, 2):
            t = run_timed([CLI, "run", "--stack", rp, "--threads", str(threads), "--force", src, "-o", out_exr], a.runs)
            rows.append(("libfx run", label, threads, t))
            print("%-12s %-40s %d thr %8.1f ms" % ("libfx", label, threads, t * 1e3), flush=True)

    # oiiotool: the same jobs from the command line (whole file in, Combined out).
    comb = "ViewLayer.Combined.R,ViewLayer.Combined.G,ViewLayer.Combined.B,ViewLayer.Combined.A"
    width = int(round(SIGMA * 4))  # OIIO's gaussian of width w has sigma w/4
    for label, extra in (("read+write (Combined)", []),
                         ("blur gaussian %dx%d (sigma %.1f)" % (width, width, SIGMA), ["--blur", "%dx%d" % (width, width)])):
        t = run_timed(["oiiotool", "--threads", "2", src, "--ch", comb] + extra + ["-o", out_exr], a.runs)
        rows.append(("oiiotool", label, 2, t))
        print("%-12s %-40s %d thr %8.1f ms" % ("oiiotool", label, 2, t * 1e3), flush=True)

    # Blender's compositor on the same EXR, minus an identity tree's overhead.
    base = blender_composite(src, "identity", a.runs)
    for mode, label in (("blur", "Blur node Gaussian size %d" % BLENDER_BLUR_SIZE),
                        ("pixelate", "Scale+Pixelate+Scale, cell %d" % PIXEL_CELL)):
        res = blender_composite(src, mode, a.runs)
        for em, t in res.items():
            rows.append(("Blender 3.4 compositor (%s)" % em, label + " (minus identity tree)", 2, max(t - base[em], 0)))
            rows.append(("Blender 3.4 compositor (%s)" % em, label + " (whole render call)", 2, t))
            print("%-12s %-40s %s %8.1f ms (identity %.1f ms)" % ("blender", label, em, t * 1e3, base[em] * 1e3), flush=True)

    # Memory: only the needed passes are decoded, unless --keep-passes asks for all.
    rp = os.path.join(a.out, "recipe.json")
    write_recipe(rp, "gaussian_blur", {"sigma": SIGMA})
    mem_needed = peak_rss_mib([CLI, "run", "--stack", rp, "--force", src, "-o", out_exr])
    mem_all = peak_rss_mib([CLI, "run", "--stack", rp, "--keep-passes", "--force", src, "-o", out_exr])
    n_channels = sum(len(p["channels"]) for p in info["passes"])
    px = info["width"] * info["height"]
    mem_rows = [
        ("channels in the file", n_channels),
        ("all passes as float, MiB", px * n_channels * 4 / 2**20),
        ("Combined only as float, MiB", px * 4 * 4 / 2**20),
        ("peak RSS, blur decoding only Combined, MiB", mem_needed),
        ("peak RSS, blur with --keep-passes (decodes all), MiB", mem_all),
    ]

    with open(os.path.join(a.out, "peers.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["tool", "job", "threads", "median_ms"])
        for r in rows:
            w.writerow([r[0], r[1], r[2], "%.2f" % (r[3] * 1e3)])
    md = ["| tool | job | threads | median ms |", "|---|---|---:|---:|"]
    md += ["| %s | %s | %d | %.1f |" % (r[0], r[1], r[2], r[3] * 1e3) for r in rows]
    md += ["", "| memory (%dx%d, %s) | value |" % (info["width"], info["height"], os.path.basename(src)), "|---|---:|"]
    md += ["| %s | %s |" % (k, ("%.1f" % v) if isinstance(v, float) else v) for k, v in mem_rows]
    with open(os.path.join(a.out, "peers.md"), "w") as f:
        f.write("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    sys.exit(main())
