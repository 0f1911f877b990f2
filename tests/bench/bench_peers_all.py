#!/usr/bin/python3
"""bench_peers_all: the peers of libfx's effects, timed on a scene's passes EXR in the run that
times libfx (tests/bench/bench_all.py calls run_peers right after libfx's own rows).

    /usr/bin/python3 tests/bench/bench_peers_all.py EXR SIDECAR [--runs 5] [--out DIR]

EXR is a scene's multilayer passes file from the batch runner (<prefix>libfx_passes.0001.exr),
SIDECAR its <prefix>libfx.0001.camera.json (camera and lights; '' or '-': no Sun Beams / god_rays
rows). Prints a Markdown table and writes DIR/peers_all.csv (and .md). This module is the one
place for Blender/oiiotool peer timing; bench_peers.py and bench_stylize.py call into it.

Rows (CSV schema SCHEMA; one dict per row from run_peers). Blender 5.x rows come from the
Debian unstable root (scripts/blender_roots.sh) when it exists: blender5_peers.

Rows:
  peer   Blender 3.4's compositor nodes on the same EXR (Image node -> node(s) -> Composite, no
         Render Layers node): the median of `runs` render() calls minus the median of an
         identity tree's (Image -> Composite), in one Blender process, execution modes TILED
         and FULL_FRAME, render threads fixed to 2 (Glare Streaks and a cel-shading chain on
         request: --only). oiiotool's operations (--blur, --ccmatrix, --resize+--resample) on
         the Combined pass, timed as the ImageBufAlgo calls oiiotool makes, in memory through
         OpenImageIO's Python binding, 2 threads (a whole `oiiotool IN op -o OUT` minus
         `oiiotool IN -o OUT` drowns the op in I/O noise on this shared VM). OpenCV's
         GaussianBlur from bench_blur (in memory, its synthetic 1920x1080 frame).
         effect: the libfx effect it is the peer of; setting: the peer and its parameters;
         note: how its size/quality was matched, the libfx parameters it is compared with and
         libfx's time for those (effect alone, `libfx run -v`, same run).
         mae / max_err / psnr_db: the peer's RGB against libfx's output at the matched
         parameters: mae/max_err of the scene-linear values, psnr_db = 10 log10(1 / MSE) of the
         values clipped to [0, 1] (display white = 1; HDR highlights would swamp it). Empty
         where the outputs are not the same kind of image (said in note).
  io     plain EXR read+write: `libfx run` with an empty stack (decodes Combined only; and
         --keep-passes: every pass) vs `oiiotool IN -o OUT` on the same file; and libfx
         read + gaussian_blur + write end to end.
  floor  glibc memcpy of one RGBA float frame (read + write) called through ctypes (C, no
         Python in the copy), 1 thread and 2 threads (two halves at once), at 1920x1080 and
         at the EXR's size; and bench_blur's own C memcpy row when the binary is built.

Tools: $LIBFX_CLI or build/libfx/libfx (else the newest build*/libfx/libfx), $BLENDER or
blender, oiiotool on PATH, $LIBFX_BENCH_DIR or the newest build*/tests/bench for bench_blur.
The VM is shared and its memory bandwidth drifts: compare ratios within one run."""
import argparse
import csv
import ctypes
import glob
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
HERE = os.path.dirname(os.path.abspath(__file__))
BLENDER = os.environ.get("BLENDER", "blender")
SCHEMA = ["kind", "scene", "effect", "setting", "width", "height", "threads", "runs", "ms_median",
          "mae", "max_err", "psnr_db", "mask_px", "note"]

# Blender's Gaussian blur weights exp(-(3 i / size)^2 / 2): sigma = size / 3.
BLENDER_BLUR_SIZE = 50
SIGMA = BLENDER_BLUR_SIZE / 3.0
PIXEL_CELL = 16
FOG_SIZE = 8          # Glare node size: Fog Glow kernel 2^size px
POSTER_LEVELS = 4
SUN_RAY_LENGTH = 0.5
# The classic sepia matrix (libfx color_ops.h) is rank one to 0.3%: every row is the red row
# times (1, 0.888, 0.692). The Blender chain computes the red row and multiplies by the tint.
SEPIA_ROW = (0.393, 0.769, 0.189)
SEPIA_TINT = (1.0, 0.349 / 0.393, 0.272 / 0.393)
SEPIA_3X3 = (0.393, 0.769, 0.189, 0.349, 0.686, 0.168, 0.272, 0.534, 0.131)
LUMA_3X3 = (0.2126, 0.7152, 0.0722) * 3


# ---------------------------------------------------------------- tools and helpers
def _newest(pattern):
    found = [p for p in glob.glob(os.path.join(ROOT, pattern)) if os.access(p, os.X_OK)]
    return max(found, key=os.path.getmtime) if found else None


def find_cli():
    env = os.environ.get("LIBFX_CLI")
    if env:
        return env
    default = os.path.join(ROOT, "build", "libfx", "libfx")
    if os.access(default, os.X_OK):
        return default
    cli = _newest("build*/libfx/libfx")
    if not cli:
        raise SystemExit("no libfx CLI built (cmake --build build); or set LIBFX_CLI")
    return cli


def find_bench(name):
    d = os.environ.get("LIBFX_BENCH_DIR")
    if d:
        p = os.path.join(d, name)
        return p if os.access(p, os.X_OK) else None
    return _newest("build*/tests/bench/" + name)


def row(**kw):
    r = {k: "" for k in SCHEMA}
    r.update(kw)
    return r


def timed(cmd, runs, warm=True):
    """Median wall ms of `runs` runs of cmd (after one untimed warm-up run: page cache)."""
    if warm:
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t = []
    for _ in range(runs):
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        t.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(t)


def scene_name(exr_path):
    """The scene's name: the .blend the EXR came from (its File attribute), else the file name."""
    try:
        import OpenImageIO as oiio
        inp = oiio.ImageInput.open(exr_path)
        f = inp.spec().getattribute("File")
        inp.close()
        if f:
            return os.path.splitext(os.path.basename(f))[0]
    except Exception:
        pass
    return os.path.basename(exr_path).split(".")[0]


def exr_size(path):
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(path)
    if not inp:
        raise SystemExit("cannot open " + path)
    s = inp.spec()
    inp.close()
    return s.width, s.height


def read_rgb(path):
    """The colour of an EXR as HxWx3 float64: its Combined pass if it has one, else R, G, B."""
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(path)
    if not inp:
        raise RuntimeError("cannot open " + path)
    names = list(inp.spec().channelnames)
    px = inp.read_image(oiio.FLOAT)
    inp.close()
    idx = None
    for pre in ("Combined.", "ViewLayer.Combined.", ""):
        try:
            idx = [names.index(pre + c) for c in "RGB"]
            break
        except ValueError:
            continue
    if idx is None:
        raise RuntimeError("%s: no Combined.R/G/B or R/G/B channels" % path)
    return px[..., idx].astype(np.float64)


def errors(peer_path, ref_path):
    """(mae, max_err, psnr_db) of a peer's RGB against libfx's: mean and max absolute difference
    of the scene-linear values (HDR: a sun disc of 5000 weighs in), PSNR of the values clipped
    to [0, 1] (the displayable range; peak 1). Non-finite values are left out."""
    a, b = read_rgb(peer_path), read_rgb(ref_path)
    if a.shape != b.shape:
        raise RuntimeError("size differs: %s %s vs %s %s" % (peer_path, a.shape, ref_path, b.shape))
    ok = np.isfinite(a) & np.isfinite(b)
    d = np.abs(a - b)[ok]
    c = (np.clip(a, 0, 1) - np.clip(b, 0, 1))[ok]
    mse = float(np.mean(c * c))
    return float(np.mean(d)), float(np.max(d)), (10 * math.log10(1.0 / mse) if mse > 0 else float("inf"))


def fmt_err(e):
    return {} if e is None else {"mae": "%.3g" % e[0], "max_err": "%.3g" % e[1], "psnr_db": "%.1f" % e[2]}


def params_text(p):
    return " ".join("%s=%s" % (k, json.dumps(v) if not isinstance(v, str) else v) for k, v in p.items()) or "defaults"


RENDER_ALL_PASSES = r"""
import bpy, sys
out, w, h = sys.argv[sys.argv.index("--") + 1:][:3]
s = bpy.context.scene
s.render.engine = "CYCLES"
s.cycles.samples = 1
s.cycles.use_denoising = False
s.render.resolution_x, s.render.resolution_y, s.render.resolution_percentage = int(w), int(h), 100
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


def render_all_passes(path, w=1920, h=1080):
    """Renders frame 1 of the Greek bath with every pass (Cycles, 1 sample; render output route:
    ViewLayer.* channels) to path, unless it exists (bench_peers.py's and bench_stylize.py's
    input: a heavy file for the I/O and memory rows, and the light passes cel shading reads)."""
    if os.path.exists(path):
        return path
    print("rendering %s (%dx%d, every pass, Cycles 1 sample)..." % (path, w, h), file=sys.stderr, flush=True)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    base = os.path.splitext(path)[0] + "_render"
    with tempfile.TemporaryDirectory() as d:
        script = os.path.join(d, "render_all.py")
        with open(script, "w") as f:
            f.write(RENDER_ALL_PASSES)
        subprocess.run([BLENDER, "-b", os.path.join(ROOT, "blend_scenes", "greek_bath", "greek_bath.blend"),
                        "--python", script, "--", base, str(w), str(h)], check=True, capture_output=True)
    os.rename(base + ".exr", path)
    return path


# ---------------------------------------------------------------- libfx reference runs
class Libfx:
    """`libfx run` of one-effect recipes: the output the peers are compared with, and the
    effect's own time (-v prints per-effect ms), median of a few runs."""

    def __init__(self, cli, exr, sidecar, out_dir, threads=2, runs=3):
        self.cli, self.exr, self.sidecar, self.out_dir = cli, exr, sidecar, out_dir
        self.threads, self.runs, self.cache = threads, runs, {}

    def recipe(self, effect, params):
        path = os.path.join(self.out_dir, "recipe_%s.json" % (effect or "empty"))
        with open(path, "w") as f:
            json.dump({"version": 1, "effects": [{"effect": effect, "params": params}] if effect else []}, f)
        return path

    def cmd(self, effect, params, out, threads, src=None, extra=()):
        c = [self.cli, "run", "--stack", self.recipe(effect, params), "--threads", str(threads), "--force",
             "--quiet", src or self.exr, "-o", out] + list(extra)
        if effect == "god_rays" and self.sidecar:
            c += ["--camera", self.sidecar]
        return c

    def run(self, effect, params, src=None, tag=None, runs=None):
        """(output path, median effect ms)."""
        key = (effect, json.dumps(params, sort_keys=True), src)
        if key in self.cache:
            return self.cache[key]
        out = os.path.join(self.out_dir, "libfx_%s_%s.exr" % (effect, tag or len(self.cache)))
        ms = []
        for _ in range(runs or self.runs):
            r = subprocess.run(self.cmd(effect, params, out, self.threads, src, ["-v"]), capture_output=True,
                               text=True)
            if r.returncode:
                raise RuntimeError("libfx run %s %s failed: %s" % (effect, params, r.stderr.strip()))
            for line in r.stdout.splitlines():
                if line.startswith("timings:"):
                    ms.append(sum(t["ms"] for t in json.loads(line[len("timings:"):])))
        self.cache[key] = (out, statistics.median(ms) if ms else float("nan"))
        return self.cache[key]


# ---------------------------------------------------------------- Blender's compositor
# One Blender process: every tree built from the same Image node, timed as render() minus the
# identity tree's render(), both execution modes; each result also written once (not timed).
BLENDER_SCRIPT = r"""
import bpy, sys, time, json
A = json.load(open(sys.argv[sys.argv.index("--") + 1]))
s = bpy.context.scene
s.render.resolution_x, s.render.resolution_y, s.render.resolution_percentage = A["w"], A["h"], 100
s.render.threads_mode = "FIXED"
s.render.threads = A["threads"]
s.render.image_settings.file_format = "OPEN_EXR"
s.render.image_settings.color_depth = "32"
s.render.image_settings.exr_codec = "ZIP"
# Blender 5 keeps the compositor in a node group with a Group Output, node settings in
# input sockets, no execution modes; 3.4 has scene.node_tree, a Composite node, attributes.
NEW = bpy.app.version >= (5, 0, 0)
if NEW:
    tree = bpy.data.node_groups.new("peers", "CompositorNodeTree")
    tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    s.compositing_node_group = tree
    s.render.compositor_device = "CPU"
else:
    s.use_nodes = True
    tree = s.node_tree
images = {}

def setting(node, socket, new_value, attr=None, old_value=None):
    if NEW:
        node.inputs[socket].default_value = new_value
    else:
        setattr(node, attr, old_value)

def ramp_constant(node, positions, values):
    cr = node.color_ramp
    cr.interpolation = "CONSTANT"
    while len(cr.elements) > 1:
        cr.elements.remove(cr.elements[-1])
    cr.elements[0].position = positions[0]
    for p in positions[1:]:
        cr.elements.new(p)
    for e, v in zip(cr.elements, values):   # elements are kept sorted by position
        e.color = (v, v, v, 1)

def build(mode, src):
    if src not in images:
        images[src] = bpy.data.images.load(src)
    tree.nodes.clear()
    img = tree.nodes.new("CompositorNodeImage"); img.image = images[src]
    comp = tree.nodes.new("NodeGroupOutput" if NEW else "CompositorNodeComposite")
    out = lambda name: img.outputs[name] if name in img.outputs and img.outputs[name].enabled else img.outputs[0]
    N, L = tree.nodes.new, tree.links.new
    if mode == "identity":
        L(out("Combined"), comp.inputs[0])
    elif NEW:
        build_new(mode, out, comp, N, L)
    elif mode == "blur":
        n = N("CompositorNodeBlur"); n.filter_type = "GAUSS"; n.size_x = n.size_y = A["blur_size"]
        L(out("Combined"), n.inputs[0]); L(n.outputs[0], comp.inputs[0])
    elif mode == "pixelate":
        # Pixelate keys on the input's pixels: scale down by the cell, pixelate, scale back up
        down = N("CompositorNodeScale"); down.space = "RELATIVE"
        down.inputs[1].default_value = down.inputs[2].default_value = 1.0 / A["cell"]
        px = N("CompositorNodePixelate")
        up = N("CompositorNodeScale"); up.space = "RELATIVE"
        up.inputs[1].default_value = up.inputs[2].default_value = float(A["cell"])
        L(out("Combined"), down.inputs[0]); L(down.outputs[0], px.inputs[0])
        L(px.outputs[0], up.inputs[0]); L(up.outputs[0], comp.inputs[0])
    elif mode in ("sobel", "laplace"):
        f = N("CompositorNodeFilter"); f.filter_type = mode.upper()
        L(out("Combined"), f.inputs[1]); L(f.outputs[0], comp.inputs[0])
    elif mode in ("fog_glow", "streaks", "spot_fog_glow"):
        g = N("CompositorNodeGlare"); g.glare_type = "STREAKS" if mode == "streaks" else "FOG_GLOW"
        g.quality = "HIGH"; g.size = A["fog_size"]; g.threshold = 1.0
        g.mix = 1.0 if mode == "spot_fog_glow" else 0.0   # 1: the glare alone; 0: image + glare
        L(out("Combined"), g.inputs[0]); L(g.outputs[0], comp.inputs[0])
    elif mode == "sun_beams":
        b = N("CompositorNodeSunBeams"); b.source = A["sun"]; b.ray_length = A["ray_length"]
        L(out("Combined"), b.inputs[0]); L(b.outputs[0], comp.inputs[0])
    elif mode == "bw":
        bw = N("CompositorNodeRGBToBW")
        L(out("Combined"), bw.inputs[0]); L(bw.outputs[0], comp.inputs[0])
    elif mode == "sepia":
        sep = N("CompositorNodeSepRGBA")
        L(out("Combined"), sep.inputs[0])
        m0 = N("CompositorNodeMath"); m0.operation = "MULTIPLY"; m0.inputs[1].default_value = A["sepia_row"][2]
        L(sep.outputs[2], m0.inputs[0])
        m1 = N("CompositorNodeMath"); m1.operation = "MULTIPLY_ADD"; m1.inputs[1].default_value = A["sepia_row"][1]
        L(sep.outputs[1], m1.inputs[0]); L(m0.outputs[0], m1.inputs[2])
        m2 = N("CompositorNodeMath"); m2.operation = "MULTIPLY_ADD"; m2.inputs[1].default_value = A["sepia_row"][0]
        L(sep.outputs[0], m2.inputs[0]); L(m1.outputs[0], m2.inputs[2])
        mix = N("CompositorNodeMixRGB"); mix.blend_type = "MULTIPLY"; mix.inputs[0].default_value = 1.0
        mix.inputs[2].default_value = tuple(A["sepia_tint"]) + (1.0,)
        L(m2.outputs[0], mix.inputs[1]); L(mix.outputs[0], comp.inputs[0])
    elif mode == "posterize":
        bw = N("CompositorNodeRGBToBW")
        cr = N("CompositorNodeValToRGB")
        n = A["levels"]
        ramp_constant(cr, [k / n for k in range(n)], [k / (n - 1) for k in range(n)])
        L(out("Combined"), bw.inputs[0]); L(bw.outputs[0], cr.inputs[0]); L(cr.outputs[0], comp.inputs[0])
    elif mode == "cel_chain":
        # banded diffuse light x diffuse colour + glossy, x an outline from Sobel(ln Depth)
        bw = N("CompositorNodeRGBToBW")
        cr = N("CompositorNodeValToRGB"); ramp_constant(cr, [0.0, 1 / 3, 2 / 3], [0.1, 0.5, 1.0])
        mul = N("CompositorNodeMixRGB"); mul.blend_type = "MULTIPLY"; mul.inputs[0].default_value = 1
        L(out("DiffDir"), bw.inputs[0]); L(bw.outputs[0], cr.inputs[0])
        L(cr.outputs[0], mul.inputs[1]); L(out("DiffCol"), mul.inputs[2])
        add = N("CompositorNodeMixRGB"); add.blend_type = "ADD"; add.inputs[0].default_value = 1
        L(mul.outputs[0], add.inputs[1]); L(out("GlossDir"), add.inputs[2])
        lg = N("CompositorNodeMath"); lg.operation = "LOGARITHM"; lg.inputs[1].default_value = 2.718281828
        L(out("Depth"), lg.inputs[0])
        so = N("CompositorNodeFilter"); so.filter_type = "SOBEL"
        L(lg.outputs[0], so.inputs[1])
        th = N("CompositorNodeValToRGB"); ramp_constant(th, [0.0, 0.1], [1.0, 0.0])
        L(so.outputs[0], th.inputs[0])
        o = N("CompositorNodeMixRGB"); o.blend_type = "MULTIPLY"; o.inputs[0].default_value = 1
        L(add.outputs[0], o.inputs[1]); L(th.outputs[0], o.inputs[2]); L(o.outputs[0], comp.inputs[0])
    else:
        raise SystemExit("unknown mode " + mode)

def build_new(mode, out, comp, N, L):
    # Blender 5's nodes for the modes it has (sockets for settings)
    if mode in ("blur", "fast_blur"):
        n = N("CompositorNodeBlur")
        n.inputs["Type"].default_value = "Fast Gaussian" if mode == "fast_blur" else "Gaussian"
        n.inputs["Size"].default_value = (A["blur_size"], A["blur_size"])
        L(out("Combined"), n.inputs["Image"]); L(n.outputs[0], comp.inputs[0])
    elif mode == "pixelate":
        # Blender 5's Pixelate node has a Size (cell) input: no scale chain
        px = N("CompositorNodePixelate"); px.inputs["Size"].default_value = A["cell"]
        L(out("Combined"), px.inputs[0]); L(px.outputs[0], comp.inputs[0])
    elif mode in ("sobel", "laplace"):
        f = N("CompositorNodeFilter"); f.inputs["Type"].default_value = mode.capitalize()
        L(out("Combined"), f.inputs["Image"]); L(f.outputs[0], comp.inputs[0])
    elif mode in ("bloom", "fog_glow", "spot_bloom", "spot_fog_glow"):
        g = N("CompositorNodeGlare")
        g.inputs["Type"].default_value = "Fog Glow" if "fog_glow" in mode else "Bloom"
        g.inputs["Quality"].default_value = "High"
        g.inputs["Threshold"].default_value = 1.0
        # spot_*: the glare alone (for the radius match); else image + glare
        L(out("Combined"), g.inputs["Image"]); L(g.outputs["Glare" if mode.startswith("spot") else "Image"], comp.inputs[0])
    elif mode == "sun_beams":
        g = N("CompositorNodeGlare"); g.inputs["Type"].default_value = "Sun Beams"
        g.inputs["Sun Position"].default_value = tuple(A["sun"])
        g.inputs["Size"].default_value = A["ray_length"]
        g.inputs["Threshold"].default_value = 0.0
        L(out("Combined"), g.inputs["Image"]); L(g.outputs["Image"], comp.inputs[0])
    elif mode == "bw":
        bw = N("CompositorNodeRGBToBW")
        L(out("Combined"), bw.inputs[0]); L(bw.outputs[0], comp.inputs[0])
    else:
        raise SystemExit("no Blender 5 tree for mode " + mode)

def median_render(runs):
    bpy.ops.render.render()   # warm-up: image load, caches
    t = []
    for _ in range(runs):
        t0 = time.perf_counter(); bpy.ops.render.render(); t.append((time.perf_counter() - t0) * 1e3)
    return sorted(t)[len(t) // 2]

res = {}
for mode in A["modes"]:
    res[mode] = {}
    build(mode, A["src"])
    for em in A["exec_modes"]:
        if not NEW:
            tree.execution_mode = em
        res[mode][em] = median_render(A["runs"])
        if A.get("write") and mode != "identity":
            s.render.filepath = "%s/blender_%s_%s.exr" % (A["write"], mode, em)
            bpy.ops.render.render(write_still=True)
for mode, src, path in A.get("extra_writes", []):
    build(mode, src)
    if not NEW:
        tree.execution_mode = "FULL_FRAME"
    s.render.filepath = path
    bpy.ops.render.render(write_still=True)
print("RESULT " + json.dumps(res))
"""


def blender_run(args, blender=None, tmp_dir=None):
    """Runs BLENDER_SCRIPT with args (dict); returns {mode: {exec_mode: median ms of render()}}.
    blender: the command (default [$BLENDER]); tmp_dir: where the script goes (inside the
    tree for a Blender in a Debian root, which sees only the tree and shared/)."""
    with tempfile.TemporaryDirectory(dir=tmp_dir) as d:
        script, aj = os.path.join(d, "peers.py"), os.path.join(d, "args.json")
        with open(script, "w") as f:
            f.write(BLENDER_SCRIPT)
        with open(aj, "w") as f:
            json.dump(args, f)
        r = subprocess.run((blender or [BLENDER]) + ["-b", "--factory-startup", "--python", script, "--", aj],
                           capture_output=True, text=True)
    for line in r.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    raise RuntimeError("blender printed no result:\n" + r.stdout[-3000:] + r.stderr[-2000:])


def blender_args(src, w, h, modes, runs, threads=2, exec_modes=("TILED", "FULL_FRAME"), write=None, sun=(0.5, 0.5),
                 extra_writes=(), fog_size=FOG_SIZE):
    return {"src": src, "w": w, "h": h, "modes": list(modes), "runs": runs, "threads": threads,
            "exec_modes": list(exec_modes), "write": write, "blur_size": BLENDER_BLUR_SIZE, "cell": PIXEL_CELL,
            "fog_size": fog_size, "levels": POSTER_LEVELS, "sepia_row": SEPIA_ROW, "sepia_tint": SEPIA_TINT,
            "sun": list(sun), "ray_length": SUN_RAY_LENGTH, "extra_writes": [list(x) for x in extra_writes]}


def blender_node_times(src, w, h, modes, runs, threads=2, fog_size=FOG_SIZE):
    """{mode: {TILED, FULL_FRAME}} of the node(s) alone (render() minus the identity tree's),
    plus 'identity' (the whole render() of Image -> Composite). For bench_stylize."""
    res = blender_run(blender_args(src, w, h, ["identity"] + [m for m in modes if m != "identity"], runs, threads,
                                   fog_size=fog_size))
    idn = res["identity"]
    return {m: ({em: t for em, t in v.items()} if m == "identity" else
                {em: max(t - idn[em], 0.0) for em, t in v.items()}) for m, v in res.items()}


# ---------------------------------------------------------------- bloom radius vs Fog Glow
def write_rgba_exr(path, rgba):
    import OpenImageIO as oiio
    h, w = rgba.shape[:2]
    spec = oiio.ImageSpec(w, h, 4, oiio.FLOAT)
    spec.channelnames = ("R", "G", "B", "A")
    o = oiio.ImageOutput.create(path)
    o.open(path, spec)
    o.write_image(rgba)
    o.close()


def spot_image(w, h):
    spot = np.zeros((h, w, 4), np.float32)
    spot[..., 3] = 1
    spot[h // 2, w // 2, :3] = 1000.0
    return spot


def r90(glow, cx, cy):
    """Radius (px) holding 90% of a glow's energy (luminance, negatives dropped)."""
    lum = np.clip(glow @ np.array([0.2126, 0.7152, 0.0722]), 0, None)
    yy, xx = np.mgrid[0:lum.shape[0], 0:lum.shape[1]]
    r = np.hypot(xx - cx, yy - cy).ravel()
    order = np.argsort(r)
    c = np.cumsum(lum.ravel()[order])
    return float(r[order][np.searchsorted(c, 0.9 * c[-1])])


def fog_glow_spot(out_dir, w, h, fog_size=FOG_SIZE):
    """Writes spot.exr (one bright pixel) and its Glare Fog Glow (mix 1: the glare alone) in
    out_dir; returns their paths."""
    spot_path = os.path.join(out_dir, "spot.exr")
    fog_path = os.path.join(out_dir, "blender_spot_fog_glow.exr")
    write_rgba_exr(spot_path, spot_image(w, h))
    blender_run(blender_args(spot_path, w, h, [], 1, fog_size=fog_size,
                             extra_writes=[("spot_fog_glow", spot_path, fog_path)]))
    return spot_path, fog_path


def match_bloom_radius(lib, spot_path, fog_path, w, h, radii=(2, 4, 8, 16, 32, 64, 128, 256)):
    """The bloom radius whose glow of one bright pixel holds 90% of its energy at the radius
    closest to Fog Glow's (fog_path: the spot through Glare Fog Glow, mix 1). Returns
    (radius, bloom r90, fog r90, [(radius, r90)])."""
    cx, cy = w // 2, h // 2
    spot = spot_image(w, h)[..., :3].astype(np.float64)
    fog = r90(read_rgb(fog_path), cx, cy)
    table = []
    for rad in radii:
        if rad > max(w, h):
            break
        out, _ = lib.run("bloom", {"radius": rad, "threshold": 1.0, "intensity": 1.0, "composite": "add"},
                         src=spot_path, tag="spot_r%d" % rad, runs=1)
        table.append((rad, r90(read_rgb(out) - spot, cx, cy)))
    best = min(table, key=lambda t: abs(t[1] - fog))
    return best[0], best[1], fog, table


# ---------------------------------------------------------------- memory-bandwidth floor
def memcpy_floor_ms(w, h, threads, runs):
    """Median ms of glibc memcpy of a w x h RGBA float frame (read + write), through ctypes (the
    call releases the GIL); 2 threads copy one half each, timed from the first start to the
    last end (thread wake-up skew included: an upper bound)."""
    libc = ctypes.CDLL("libc.so.6")
    libc.memcpy.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t]
    libc.memcpy.restype = ctypes.c_void_p
    n = w * h * 4
    src = (np.arange(n, dtype=np.uint32) % 977).astype(np.float32)
    dst = np.zeros_like(src)
    nbytes = n * 4
    parts = [(i * nbytes // threads, (i + 1) * nbytes // threads) for i in range(threads)]
    sa, da = src.ctypes.data, dst.ctypes.data
    if threads == 1:
        libc.memcpy(da, sa, nbytes)
        t = []
        for _ in range(max(runs * 3, 15)):
            t0 = time.perf_counter()
            libc.memcpy(da, sa, nbytes)
            t.append((time.perf_counter() - t0) * 1e3)
        return statistics.median(t)
    rounds = max(runs * 3, 15) + 1
    start, done = threading.Barrier(threads + 1), threading.Barrier(threads + 1)
    stamps = [[None] * rounds for _ in range(threads)]

    def worker(i):
        a, b = parts[i]
        for r in range(rounds):
            start.wait()
            t0 = time.perf_counter()
            libc.memcpy(da + a, sa + a, b - a)
            stamps[i][r] = (t0, time.perf_counter())
            done.wait()

    ths = [threading.Thread(target=worker, args=(i,)) for i in range(threads)]
    for t in ths:
        t.start()
    for _ in range(rounds):
        start.wait()
        done.wait()
    for t in ths:
        t.join()
    t = [(max(stamps[i][r][1] for i in range(threads)) - min(stamps[i][r][0] for i in range(threads))) * 1e3
         for r in range(1, rounds)]
    return statistics.median(t)


def floor_rows(scene, w, h, runs, log, end=False):
    rows = []
    sizes = [(1920, 1080)] + ([(w, h)] if (w, h) != (1920, 1080) else [])
    for sw, sh in (sizes[-1:] if end else sizes):
        for th in (1, 2):
            ms = memcpy_floor_ms(sw, sh, th, runs)
            rows.append(row(kind="floor", scene=scene, effect="memcpy", threads=th, runs=max(runs * 3, 15),
                            setting="memcpy RGBA float %dx%d (%.1f MB read + written)%s" % (
                                sw, sh, sw * sh * 16 / 1e6, " again (end of run)" if end else ""),
                            width=sw, height=sh, ms_median="%.3f" % ms,
                            note="glibc memcpy through ctypes (C; the GIL is released)" +
                                 ("; two halves on two threads, first start to last end" if th == 2 else "")))
            log(rows[-1])
    return rows


def bench_blur_rows(scene, runs, log):
    """OpenCV GaussianBlur and the C memcpy from bench_blur (1920x1080, in memory)."""
    exe = find_bench("bench_blur")
    if not exe:
        print("bench_blur not built (-DLIBFX_BUILD_BENCH=ON): no OpenCV rows", file=sys.stderr)
        return []
    rows = []
    # sigma 0.3 and only=opencv: no libfx case is timed, just the memcpy and cv::GaussianBlur
    for th in (1, 2):
        out = subprocess.run([exe, str(runs), str(th), "0.3", "-", "opencv"], check=True, capture_output=True,
                             text=True).stdout
        for line in out.splitlines():
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if len(cells) < 4:
                continue
            label = cells[0]
            if label.startswith("cv::GaussianBlur"):
                k = int(label.split()[1].split("x")[0])
                sig = 0.3 * ((k - 1) * 0.5 - 1) + 0.8     # OpenCV's sigma for sigma=0
                rows.append(row(kind="peer", scene=scene, effect="gaussian_blur", threads=th, runs=runs,
                                setting="opencv GaussianBlur %dx%d CV_32FC4" % (k, k), width=1920, height=1080,
                                ms_median=cells[3],
                                note="bench_blur, in memory on its synthetic 1920x1080 frame (no I/O, not this "
                                     "EXR); sigma 0 means OpenCV's %.1f for this kernel (libfx's peer row: sigma %.1f);"
                                     " cost grows with the kernel" % (sig, SIGMA)))
            elif label.startswith("memcpy (the bandwidth floor)"):
                if th != 1:
                    continue   # bench_blur's memcpy is one thread whatever its thread count
                rows.append(row(kind="floor", scene=scene, effect="memcpy", threads=1, runs=runs,
                                setting="memcpy RGBA float 1920x1080 (bench_blur, C)", width=1920, height=1080,
                                ms_median=cells[3], note="bench_blur's own memcpy row (C, one thread)"))
            else:
                continue
            log(rows[-1])
    return rows


# ---------------------------------------------------------------- the peers
def blender_peers(ctx, modes, log):
    """Blender rows for the modes (each: effect, setting, note, libfx params or None)."""
    sc, w, h, runs, lib = ctx["scene"], ctx["w"], ctx["h"], ctx["runs"], ctx["lib"]
    spot_path = os.path.join(ctx["out"], "spot.exr")
    fog_path = os.path.join(ctx["out"], "blender_spot_fog_glow.exr")
    write_rgba_exr(spot_path, spot_image(w, h))
    t0 = time.perf_counter()
    res = blender_run(blender_args(ctx["exr"], w, h, ["identity"] + list(modes), runs, write=ctx["out"],
                                   sun=ctx.get("sun", (0.5, 0.5)),
                                   extra_writes=[("spot_fog_glow", spot_path, fog_path)]))
    print("blender: %.0f s" % (time.perf_counter() - t0), file=sys.stderr, flush=True)
    rad, brr, fog_r90, radii = match_bloom_radius(lib, spot_path, fog_path, w, h)
    ctx["bloom_match"] = (rad, brr, fog_r90, radii)
    r = "%.3f %.3f" % tuple(ctx.get("sun", (0.5, 0.5)))
    spec = {
        "blur": ("gaussian_blur", "blender Blur GAUSS size=%d" % BLENDER_BLUR_SIZE, {"sigma": round(SIGMA, 3)},
                 "Blender's Gaussian weights exp(-(3i/size)^2/2): sigma = size/3 = %.2f" % SIGMA),
        "pixelate": ("pixelate", "blender Scale 1/%d > Pixelate > Scale %d" % (PIXEL_CELL, PIXEL_CELL),
                     {"mode": "cells", "cell_size": PIXEL_CELL},
                     "the documented chain for %d px cells; the downscale samples near each cell's centre "
                     "(libfx cells: centre sample); where the size does not divide by %d Blender rounds the "
                     "small image and re-centres it, so its grid shifts by up to half a cell: most of the "
                     "error then" % (PIXEL_CELL, PIXEL_CELL)),
        "sobel": ("edges", "blender Filter SOBEL", {"output": "gradient"},
                  "the same job: per-channel Sobel magnitude, borders extended, alpha kept (factor 1; at other "
                  "factors 3.4 clamps the mix at 0, 5.2 does not)"),
        "laplace": ("edges", "blender Filter LAPLACE", None,
                    "Laplace 3x3 (8-neighbour) like edges operator=laplace8; Blender outputs the filtered colour, "
                    "libfx lines: not the same image, no error figure"),
        "fog_glow": ("bloom", "blender Glare FOG_GLOW HIGH size=%d threshold=1 mix=0" % FOG_SIZE, None, ""),
        "streaks": ("bloom", "blender Glare STREAKS HIGH size=%d threshold=1 mix=0" % FOG_SIZE, None,
                    "a different look (4 streaks), timed only: no error figure"),
        "sun_beams": ("god_rays", "blender Sun Beams source=(%s) ray_length=%g" % (r, SUN_RAY_LENGTH), None,
                      "source = the sidecar's sun through its camera ((0,0) bottom-left); Sun Beams smears every "
                      "pixel towards the source, god_rays only the sky and bright pixels (defaults, sidecar camera): "
                      "not the same image, no error figure"),
        "bw": ("color_matrix", "blender RGB to BW", {"operator": "grayscale_luminance"},
               "Rec.709 luma 0.2126/0.7152/0.0722 on both sides"),
        "sepia": ("color_matrix", "blender Separate RGBA > 3 Math > Mix Multiply tint",
                  {"operator": "sepia"},
                  "the classic sepia matrix is the red row (0.393,0.769,0.189) x tint (1,0.888,0.692) to 0.3%: "
                  "Math nodes compute the row, Multiply the tint (max_err: that 0.3% on HDR sun pixels)"),
        "posterize": ("posterize", "blender RGB to BW > Color Ramp CONSTANT %d" % POSTER_LEVELS,
                      {"mode": "luminance", "space": "linear", "levels": POSTER_LEVELS, "keep_hdr": False},
                      "ramp stops k/%d -> k/%d: libfx's linear bands exactly" % (POSTER_LEVELS, POSTER_LEVELS - 1)),
        "cel_chain": ("cel_shading", "blender ramp(BW(DiffDir)) x DiffCol + GlossDir, x ramp(Sobel(ln Depth))",
                      None, "the usual node recipe for toon shading: not the same image, no error figure"),
    }
    bloom_params = {"radius": rad, "threshold": 1.0, "knee": 0.0, "intensity": 1.0, "composite": "add"}
    spec["fog_glow"] = spec["fog_glow"][:2] + (bloom_params, (
        "radius matched on one bright pixel: Fog Glow holds 90%% of its glow within %.0f px, bloom radius %d "
        "within %.0f px (closest power of two); same threshold 1, hard knee, glow added (mix 0 = image + glare); "
        "energy not matched" % (fog_r90, rad, brr)),)
    idn = res["identity"]
    rows = []
    for m in modes:
        effect, setting, params, note = spec[m]
        lib_note = ""
        out_ref = None
        if params is not None:
            out_ref, lms = lib.run(effect, params, tag=m)
            lib_note = "; vs libfx %s %s: %.1f ms (effect alone, same run)" % (effect, params_text(params), lms)
        elif m in ("sobel", "laplace", "sun_beams", "streaks"):
            p = {"sobel": {"operator": "sobel"}, "laplace": {"operator": "laplace8"}, "sun_beams": {},
                 "streaks": bloom_params}[m]
            _, lms = lib.run(effect, p, tag=m)
            lib_note = "; libfx %s %s: %.1f ms (effect alone, same run)" % (effect, params_text(p), lms)
        for em in ("TILED", "FULL_FRAME"):
            err = None
            if out_ref:
                try:
                    err = errors(os.path.join(ctx["out"], "blender_%s_%s.exr" % (m, em)), out_ref)
                except RuntimeError as e:
                    print("no error figure for %s: %s" % (m, e), file=sys.stderr)
            rows.append(row(kind="peer", scene=sc, effect=effect, setting="%s [%s]" % (setting, em), width=w,
                            height=h, threads=2, runs=runs, ms_median="%.1f" % max(res[m][em] - idn[em], 0.0),
                            note="%s; node(s) alone: render() %.1f ms minus identity tree %.1f ms%s"
                                 % (note, res[m][em], idn[em], lib_note), **fmt_err(err)))
            log(rows[-1])
    return rows


# Blender 5.x (the compositor artists have today) from the Debian unstable root that
# scripts/blender_roots.sh makes; the modes it has nodes for.
BLENDER5_MODES = ["blur", "fast_blur", "pixelate", "sobel", "bloom", "fog_glow", "sun_beams", "bw"]


def blender5_command():
    """The command running Blender 5 in its root, or None when the root is missing."""
    root = os.environ.get("LIBFX_ROOTS", "/var/cache/libfx-roots") + "/unstable"
    if not os.path.exists(os.path.join(root, "usr/bin/blender")):
        return None
    return ["bash", os.path.join(ROOT, "scripts", "in_root.sh"), "unstable", "env", "HOME=/tmp", "blender"]


def blender5_peers(ctx, log):
    """Blender 5's compositor (CPU) on the same EXR: the node(s) alone, render() minus the
    identity tree's, warm median; libfx's time beside it is its first frame in a fresh process
    (`libfx run -v`, median of runs), so the ratio includes libfx's first-frame cost."""
    cmd = blender5_command()
    if not cmd:
        print("no Blender 5 root (scripts/blender_roots.sh): no Blender 5 rows", file=sys.stderr)
        return []
    sc, w, h, runs, lib = ctx["scene"], ctx["w"], ctx["h"], ctx["runs"], ctx["lib"]
    modes = [m for m in BLENDER5_MODES if m != "sun_beams" or "sun" in ctx]
    spot_path = os.path.join(ctx["out"], "spot.exr")
    write_rgba_exr(spot_path, spot_image(w, h))
    spots = {m: os.path.join(ctx["out"], "blender5_%s.exr" % m) for m in ("spot_bloom", "spot_fog_glow")}
    out5 = os.path.join(ctx["out"], "b5")
    os.makedirs(out5, exist_ok=True)
    t0 = time.perf_counter()
    res = blender_run(blender_args(ctx["exr"], w, h, ["identity"] + modes, runs, exec_modes=("CPU",), write=out5,
                                   sun=ctx.get("sun", (0.5, 0.5)),
                                   extra_writes=[(m, spot_path, p) for m, p in spots.items()]),
                      blender=cmd, tmp_dir=ctx["out"])
    print("blender 5: %.0f s" % (time.perf_counter() - t0), file=sys.stderr, flush=True)
    matched = {m: match_bloom_radius(lib, spot_path, spots["spot_" + m], w, h) for m in ("bloom", "fog_glow")}
    sigma = BLENDER_BLUR_SIZE / 3.0
    spec = {
        "blur": ("gaussian_blur", "Blur Gaussian size=%d" % BLENDER_BLUR_SIZE, {"sigma": round(sigma, 3)},
                 "sigma = size/3 as in Blender 3.4"),
        "fast_blur": ("gaussian_blur", "Blur Fast Gaussian size=%d" % BLENDER_BLUR_SIZE, {"sigma": round(sigma, 3)},
                      "sigma = size/3; the error column says how close the recursive filter is"),
        "pixelate": ("pixelate", "Pixelate size=%d" % PIXEL_CELL, {"mode": "cells", "cell_size": PIXEL_CELL},
                     "one node with a Size input in Blender 5"),
        "sobel": ("edges", "Filter Sobel", {"output": "gradient"},
                  "the same job: per-channel Sobel magnitude, borders extended, alpha kept, Blender's sums in its "
                  "order (bit-identical on finite input)"),
        "sun_beams": ("god_rays", "Glare Sun Beams size=%g threshold=0" % SUN_RAY_LENGTH, None,
                      "source = the sidecar's sun; smears every pixel, god_rays only sky and bright pixels: "
                      "timed only"),
        "bw": ("color_matrix", "RGB to BW", {"operator": "grayscale_luminance"}, "Rec.709 luma on both sides"),
    }
    for m in ("bloom", "fog_glow"):
        rad, brr, r90_b, _ = matched[m]
        spec[m] = ("bloom", "Glare %s High threshold=1 size=0.5" % ("Bloom" if m == "bloom" else "Fog Glow"),
                   {"radius": rad, "threshold": 1.0, "knee": 0.0, "intensity": 1.0, "composite": "add"},
                   "radius matched on one bright pixel: Blender's glare holds 90%% of its light within %.0f px, "
                   "bloom radius %d within %.0f px; energy not matched" % (r90_b, rad, brr))
    idn = res["identity"]["CPU"]
    rows = []
    for m in modes:
        effect, setting, params, note = spec[m]
        p = params if params is not None else {"sobel": {"operator": "sobel"}, "sun_beams": {}}[m]
        out_ref, lms = lib.run(effect, p, tag="b5_" + m)
        err = None
        if params is not None:
            try:
                err = errors(os.path.join(out5, "blender_%s_CPU.exr" % m), out_ref)
            except RuntimeError as e:
                print("no error figure for %s: %s" % (m, e), file=sys.stderr)
        bms = max(res[m]["CPU"] - idn, 0.0)
        rows.append(row(kind="peer", scene=sc, effect=effect, setting="blender 5 %s [CPU]" % setting, width=w,
                        height=h, threads=2, runs=runs, ms_median="%.1f" % bms,
                        note="%s; node(s) alone: render() %.1f ms minus identity tree %.1f ms; libfx %s %s: "
                             "%.1f ms first frame (fresh process, same run): %.1fx faster"
                             % (note, res[m]["CPU"], idn, effect, params_text(p), lms, bms / lms if lms else 0),
                        **fmt_err(err)))
        log(rows[-1])
    return rows


def oiio_peers(ctx, log):
    """oiiotool's operations, timed as the ImageBufAlgo calls oiiotool makes for them, in memory
    through OpenImageIO's Python binding (2 threads): on a loaded machine the op's time is lost
    in the noise of a whole `oiiotool IN op -o OUT` minus `oiiotool IN -o OUT`."""
    import OpenImageIO as oiio
    from OpenImageIO import ImageBuf, ImageBufAlgo as IBA, ROI
    sc, w, h, runs, lib, out = ctx["scene"], ctx["w"], ctx["h"], ctx["runs"], ctx["lib"], ctx["out"]
    full = ImageBuf(ctx["exr"])
    names = list(full.spec().channelnames)
    pre = [n[:-len("Combined.R")] for n in names if n.endswith("Combined.R")]
    if not pre:
        raise RuntimeError("%s has no Combined pass" % ctx["exr"])
    src = ImageBuf()
    IBA.channels(src, full, tuple(names.index(pre[0] + "Combined." + c) for c in "RGBA"), ("R", "G", "B", "A"))
    del full
    nt = 2

    def blur(k):
        def op():
            kern, dst = ImageBuf(), ImageBuf()
            IBA.make_kernel(kern, "gaussian", k, k)
            IBA.convolve(dst, src, kern, nthreads=nt)
            return dst
        return op

    def matrix(m3):
        # libfx: out = M c (column vector); ImageBufAlgo: out = c M (row vector): pass M transposed
        m4 = [m3[0], m3[1], m3[2], 0, m3[3], m3[4], m3[5], 0, m3[6], m3[7], m3[8], 0, 0, 0, 0, 1]
        mt = tuple(float(m4[c * 4 + r]) for r in range(4) for c in range(4))

        def op():
            dst = ImageBuf()
            IBA.colormatrixtransform(dst, src, mt, unpremult=False, nthreads=nt)
            return dst
        return op

    cw, ch = max(1, round(w / PIXEL_CELL)), max(1, round(h / PIXEL_CELL))

    def pixelate():
        small, dst = ImageBuf(), ImageBuf()
        IBA.resize(small, src, "box", roi=ROI(0, cw, 0, ch, 0, 1, 0, 4), nthreads=nt)
        IBA.resample(dst, small, False, roi=ROI(0, w, 0, h, 0, 1, 0, 4), nthreads=nt)
        return dst

    jobs = [
        ("gaussian_blur", "--blur 67x67", blur(67), {"sigma": round(SIGMA, 3)}, 1,
         "OIIO's gaussian of width w has sigma w/4: 67/4 = 16.75 ~ %.2f; a 2-D convolution whose cost grows with "
         "the kernel (w^2 taps): one run" % SIGMA),
        ("gaussian_blur", "--blur 17x17", blur(17), {"sigma": 4.25}, 1,
         "sigma 17/4 = 4.25: the same convolution at a quarter of the width, to show how its cost grows: one run"),
        ("color_matrix", "--ccmatrix sepia", matrix(SEPIA_3X3), {"operator": "sepia"}, runs,
         "the same 3x3 matrix (oiiotool --ccmatrix:transpose=1 with libfx's rows)"),
        ("color_matrix", "--ccmatrix luminance", matrix(LUMA_3X3), {"operator": "grayscale_luminance"}, runs,
         "the same Rec.709 luma rows"),
        ("pixelate", "--resize:filter=box %dx%d --resample:interp=0 %dx%d" % (cw, ch, w, h), pixelate,
         {"mode": "average", "cell_size": PIXEL_CELL}, runs,
         "box-filtered downscale (cell means) then nearest upscale ~ pixelate average %d; cells are %.2f x %.2f px "
         "where the size does not divide by %d" % (PIXEL_CELL, w / cw, h / ch, PIXEL_CELL)),
    ]
    calls = {"--blur": "make_kernel + convolve", "--ccmatrix": "colormatrixtransform",
             "--resize:filter=box": "resize + resample"}
    rows = []
    for i, (effect, label, op, params, n, note) in enumerate(jobs):
        peer_out = os.path.join(out, "oiiotool_%d_%s.exr" % (i, effect))
        if n > 1:
            op()   # warm-up
        t = []
        for _ in range(n):
            t0 = time.perf_counter()
            dst = op()
            t.append((time.perf_counter() - t0) * 1e3)
        dst.write(peer_out, "float")
        ref, lms = lib.run(effect, params, tag="oiiotool_%d" % i)
        err = None
        try:
            err = errors(peer_out, ref)
        except RuntimeError as e:
            print("no error figure for oiiotool %s: %s" % (label, e), file=sys.stderr)
        rows.append(row(kind="peer", scene=sc, effect=effect, setting="oiiotool %s" % label, width=w, height=h,
                        threads=nt, runs=n, ms_median="%.1f" % statistics.median(t),
                        note="%s; timed as the ImageBufAlgo %s that oiiotool runs, in memory (OpenImageIO %s Python "
                             "binding; no I/O); vs libfx %s %s: %.1f ms (effect alone, same run)"
                             % (note, calls[label.split()[0]], oiio.VERSION_STRING, effect, params_text(params), lms),
                        **fmt_err(err)))
        log(rows[-1])
    return rows


def io_rows(ctx, log):
    sc, w, h, runs, lib, out = ctx["scene"], ctx["w"], ctx["h"], ctx["runs"], ctx["lib"], ctx["out"]
    dst = os.path.join(out, "io_out.exr")
    size_mb = os.path.getsize(ctx["exr"]) / 1e6
    rows = []
    for th in (2,):   # 1 thread too would double the slowest part of the run (oiiotool's whole file)
        for keep in (False, True):
            ms = timed(lib.cmd(None, {}, dst, th, extra=["--keep-passes"] if keep else []), runs)
            rows.append(row(kind="io", scene=sc, effect="read+write", threads=th, runs=runs, width=w, height=h,
                            setting="libfx run empty stack" + (" --keep-passes" if keep else ""),
                            ms_median="%.1f" % ms,
                            note=("every pass read and written (oiiotool's work)" if keep else
                                  "decodes Combined only, writes Combined") + "; %.0f MB input" % size_mb))
            log(rows[-1])
        ms = timed(["oiiotool", "--threads", str(th), ctx["exr"], "-o", dst], runs)
        rows.append(row(kind="io", scene=sc, effect="read+write", threads=th, runs=runs, width=w, height=h,
                        setting="oiiotool --threads %d IN -o OUT" % th, ms_median="%.1f" % ms,
                        note="every pass read and written; %.0f MB input" % size_mb))
        log(rows[-1])
        params = {"sigma": round(SIGMA, 3)}
        ms = timed(lib.cmd("gaussian_blur", params, dst, th), runs)
        rows.append(row(kind="io", scene=sc, effect="gaussian_blur", threads=th, runs=runs, width=w, height=h,
                        setting="libfx run gaussian_blur sigma=%.3f (read + effect + write)" % SIGMA,
                        ms_median="%.1f" % ms, note="end to end, final preset (recursive); %.0f MB input" % size_mb))
        log(rows[-1])
    return rows


def run_peers(exr_path, sidecar_path, width, height, runs, out_dir, blender_modes=None, log=None):
    """Every peer, io and floor row for one scene's passes EXR, as dicts with the SCHEMA keys.
    width/height: the EXR's size (Blender renders at it; the floor is also taken at it).
    sidecar_path '' / None: no Sun Beams row. blender_modes: a subset of the Blender peers."""
    t_start = time.perf_counter()
    os.makedirs(out_dir, exist_ok=True)
    fw, fh = exr_size(exr_path)
    if (fw, fh) != (width, height):
        print("warning: %s is %dx%d, not %dx%d: using the file's size" % (exr_path, fw, fh, width, height),
              file=sys.stderr)
        width, height = fw, fh
    log = log or (lambda r: print("%-5s %-13s %-62s %2s thr %9s ms %s" % (
        r["kind"], r["effect"], r["setting"][:62], r["threads"], r["ms_median"],
        ("mae %s psnr %s" % (r["mae"], r["psnr_db"])) if r["mae"] != "" else ""), file=sys.stderr, flush=True))
    sidecar = sidecar_path if sidecar_path and sidecar_path not in ("-", "None") else None
    if sidecar and not os.path.exists(sidecar):
        print("warning: no sidecar %s: no Sun Beams row" % sidecar, file=sys.stderr)
        sidecar = None
    ctx = {"scene": scene_name(exr_path), "exr": exr_path, "w": width, "h": height, "runs": runs, "out": out_dir,
           # libfx's first frame: a median of 7 fresh processes (0.2-0.4 s each), since one
           # first frame on this VM varies more than a warm one (the 16:21 run: the blur's
           # first frame 13.0 ms here, 8.3 ms in bench_all's first-frame stage)
           "lib": Libfx(find_cli(), exr_path, sidecar, out_dir, threads=2, runs=7)}
    # Glare Streaks and the cel chain on request (--only): streaks costs as much as Fog Glow and
    # has no libfx twin; the cel chain needs the light passes (DiffDir, DiffCol, GlossDir)
    modes = blender_modes or ["blur", "pixelate", "sobel", "laplace", "fog_glow", "sun_beams", "bw", "sepia",
                              "posterize"]
    if not sidecar:
        modes = [m for m in modes if m != "sun_beams"]
    else:
        sys.path.insert(0, HERE)
        from bench_greek_bath import project_sun   # the god-rays bench's projection, one copy
        with open(sidecar) as f:
            ctx["sun"] = project_sun(json.load(f))
    rows = floor_rows(ctx["scene"], width, height, runs, log)
    rows += blender_peers(ctx, modes, log)
    rows += blender5_peers(ctx, log)
    rows += oiio_peers(ctx, log)
    rows += bench_blur_rows(ctx["scene"], runs, log)
    rows += io_rows(ctx, log)
    rows += floor_rows(ctx["scene"], width, height, runs, log, end=True)   # the drift over the run
    print("peers: %.0f s in all (%dx%d, %d runs)" % (time.perf_counter() - t_start, width, height, runs),
          file=sys.stderr, flush=True)
    return rows


# ---------------------------------------------------------------- output
def write_csv(rows, path):
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=SCHEMA)
        w.writeheader()
        w.writerows(rows)


def markdown(rows):
    """The rows as a Markdown table, with 'x floor': ms over the memcpy floor of the same size
    and thread count (glibc rows) measured in the same run."""
    fl = {}
    for r in rows:   # the first glibc floor of each size and thread count (not the end-of-run one)
        if r["kind"] == "floor" and "ctypes" in r["note"]:
            fl.setdefault((r["width"], r["height"], r["threads"]), float(r["ms_median"]))
    md = ["| kind | effect | setting | size | thr | runs | ms (median) | x floor | mae | max err | PSNR dB |",
          "|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        f = fl.get((r["width"], r["height"], r["threads"]))
        xf = "%.0fx" % (float(r["ms_median"]) / f) if f and r["kind"] == "peer" else ""
        md.append("| %s | %s | %s | %sx%s | %s | %s | %s | %s | %s | %s | %s |" % (
            r["kind"], r["effect"], r["setting"], r["width"], r["height"], r["threads"], r["runs"], r["ms_median"],
            xf, r["mae"], r["max_err"], r["psnr_db"]))
    return md


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("exr", help="the scene's passes EXR (<prefix>libfx_passes.0001.exr)")
    ap.add_argument("sidecar", help="its camera sidecar (<prefix>libfx.0001.camera.json), or - for none")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "bench_peers"))
    ap.add_argument("--only", help="comma-separated Blender peers (blur,pixelate,sobel,laplace,fog_glow,streaks,"
                                   "sun_beams,bw,sepia,posterize,cel_chain)")
    a = ap.parse_args()
    w, h = exr_size(a.exr)
    rows = run_peers(a.exr, a.sidecar, w, h, a.runs, a.out, blender_modes=a.only.split(",") if a.only else None)
    write_csv(rows, os.path.join(a.out, "peers_all.csv"))
    md = markdown(rows)
    with open(os.path.join(a.out, "peers_all.md"), "w") as f:
        f.write("\n".join(md) + "\n\nNotes (how each peer was matched):\n\n" +
                "\n".join("- %s / %s: %s" % (r["effect"], r["setting"], r["note"]) for r in rows) + "\n")
    print("\n".join(md))
    print("\n%s and peers_all.md (with the notes) in %s" % ("peers_all.csv", a.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
