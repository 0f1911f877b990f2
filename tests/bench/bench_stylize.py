#!/usr/bin/python3
"""bench_stylize: edges, posterize, sin_city, cel_shading, bloom at 1920x1080, in one command:

  /usr/bin/python3 tests/bench/bench_stylize.py --lib build/libfx/libfx.so --runs 5 --peers

1. In memory through the public API (ctypes; no EXR I/O), 1 and 2 threads, medians of --runs,
   on a synthetic frame, beside two floors measured in the same run: a numpy copy of one RGBA
   float frame (the bytes a per-pixel effect reads + writes) and an identity effect through the
   stack (posterize mix 0: the effect's memcpy plus the stack's own work: output allocation,
   non-finite scan/mask composite). "x floor" columns are ratios within the run.
2. --peers: the same effects on a real Cycles EXR (every pass; out/bench/allpasses_1080p.exr,
   rendered by tests/bench/bench_peers.py's method when missing) beside Blender 3.4's
   compositor on that EXR: Image node -> nodes -> Composite (no Render Layers node), median
   render() time minus an identity tree's (Image -> Composite), TILED and FULL_FRAME, with
   the render threads fixed to 1 and 2. Peers: Filter Sobel / Laplace (edges), Glare Fog Glow
   and Streaks (bloom), RGB to BW + constant Color Ramp (posterize), and a cel chain
   (DiffDir -> RGB to BW -> constant ramp x DiffCol + DiffInd..., Sobel of Depth outlines).
3. --peers also matches the bloom's radius to Fog Glow's: a single bright pixel through
   Fog Glow (size --fog-size, mix 1: the glare alone) and through bloom (intensity 1, add: the
   glow is output - input) at several radii; the radius holding 90% of each glow's energy (r90)
   is printed, and the bloom whose r90 is closest is timed beside Fog Glow.

Writes out/bench/stylize.md (the tables) and prints them."""
import argparse, ctypes, json, os, statistics, subprocess, sys, tempfile, time
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
ap = argparse.ArgumentParser()
ap.add_argument("--lib", default=os.path.join(ROOT, "build", "libfx", "libfx.so"))
ap.add_argument("--runs", type=int, default=5)
ap.add_argument("--width", type=int, default=1920)
ap.add_argument("--height", type=int, default=1080)
ap.add_argument("--peers", action="store_true", help="also time Blender's compositor peers on a real EXR")
ap.add_argument("--exr", default=os.path.join(ROOT, "out", "bench", "allpasses_1080p.exr"))
ap.add_argument("--blender", default=os.environ.get("BLENDER", "blender"))
ap.add_argument("--fog-size", type=int, default=8, help="Glare node size (Fog Glow kernel 2^size px)")
ap.add_argument("--out", default=os.path.join(ROOT, "out", "bench"))
a = ap.parse_args()
L = ctypes.CDLL(a.lib)
vp = ctypes.c_void_p
L.fx_context_new.argtypes = [ctypes.POINTER(vp), ctypes.c_int]
L.fx_context_error.restype = ctypes.c_char_p
L.fx_context_error.argtypes = [vp]
L.fx_frame_new.argtypes = [vp, ctypes.c_int, ctypes.c_int, ctypes.POINTER(vp)]
L.fx_frame_add_pass.argtypes = [vp, ctypes.c_char_p, ctypes.c_int, ctypes.POINTER(ctypes.c_float)]
L.fx_stack_new.argtypes = [vp, ctypes.POINTER(vp)]
L.fx_stack_load_json.argtypes = [vp, ctypes.c_char_p]
L.fx_stack_run.argtypes = [vp, vp, ctypes.POINTER(vp)]
L.fx_stack_timings_json.argtypes = [vp, ctypes.POINTER(ctypes.c_char_p)]
L.fx_frame_free.argtypes = [vp]
L.fx_stack_free.argtypes = [vp]
L.fx_context_free.argtypes = [vp]
L.fx_frame_pass.argtypes = [vp, ctypes.c_char_p, ctypes.POINTER(ctypes.POINTER(ctypes.c_float)), ctypes.POINTER(ctypes.c_int)]

W, H = a.width, a.height


def fp(x):
    return np.ascontiguousarray(x).ctypes.data_as(ctypes.POINTER(ctypes.c_float))


def synthetic():
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    comb = np.empty((H, W, 4), np.float32)
    comb[..., 0] = 0.5 + 0.5 * np.sin(xx / 37.0) * np.cos(yy / 23.0)
    comb[..., 1] = 0.5 + 0.5 * np.sin((xx + yy) / 51.0)
    comb[..., 2] = (xx / W) * (yy / H)
    comb[..., 3] = 1
    comb[(xx % 211 < 6) & (yy % 173 < 6)] = [20, 18, 15, 1]      # highlights for bloom
    depth = (2.0 + 3.0 * (yy / H) + np.where((xx // 160 + yy // 120) % 2 == 0, 0, 1.5)).astype(np.float32)
    depth[yy < 80] = 1e10                                         # sky
    nrm = np.stack([np.sin(xx / 90.0), np.cos(yy / 70.0), np.full_like(xx, 0.5)], -1).astype(np.float32)
    dd = np.repeat((0.5 + 0.5 * np.sin(xx / 64.0))[..., None], 3, -1).astype(np.float32)
    return {"Combined": comb, "Depth": depth, "Normal": nrm, "DiffDir": dd, "DiffCol": comb[..., :3].copy()}


def read_exr(path):
    """Passes of a multilayer EXR as {name: HxWxC float32} (OpenImageIO)."""
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(path)
    if not inp:
        raise SystemExit("cannot open " + path)
    spec = inp.spec()
    px = inp.read_image(oiio.FLOAT)
    inp.close()
    names = list(spec.channelnames)
    groups = {}
    for i, n in enumerate(names):
        parts = n.split(".")
        p = parts[-2] if len(parts) >= 2 else "Combined"
        groups.setdefault(p, []).append(i)
    out = {}
    for p, idx in groups.items():
        out[p] = np.ascontiguousarray(px[..., idx].astype(np.float32))
    return out, spec.width, spec.height


IDENTITY = ("identity through the stack (posterize mix 0)", "posterize", {"mix": 0})
CASES = [
    ("edges sobel luminance", "edges", {}),
    ("edges sobel lum+depth+normal, width 3", "edges", {"depth": True, "normal": True, "line_width": 3}),
    ("edges laplace8 luminance", "edges", {"operator": "laplace8"}),
    ("edges laplace8 depth", "edges", {"operator": "laplace8", "luminance": False, "depth": True}),
    ("posterize color 4 (sRGB steps)", "posterize", {"levels": 4}),
    ("posterize luminance 4 linear", "posterize", {"levels": 4, "mode": "luminance", "space": "linear"}),
    ("posterize color 4 dithered", "posterize", {"levels": 4, "dither": 1}),
    ("sin_city levels 6, keep hue", "sin_city", {"levels": 6}),
    ("sin_city keep dot", "sin_city", {"keep": "dot"}),
    ("cel_shading diffuse passes + outlines", "cel_shading", {}),
    ("cel_shading N.L (direction) + outlines", "cel_shading", {"lighting": "normal_light", "use_direction": True}),
    ("bloom soft knee radius 128", "bloom", {"radius": 128}),
    ("bloom seed radius 128", "bloom", {"mode": "seed", "radius": 128}),
    ("bloom soft knee radius 512", "bloom", {"radius": 512}),
]


def floor_ms(src, runs):
    dst = np.empty_like(src)
    t = []
    for _ in range(runs * 3):
        t0 = time.perf_counter()
        np.copyto(dst, src)
        t.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(t)


def time_cases(passes, w, h, cases, runs, threads_list=(1, 2), keep=()):
    """[(label, threads, ms)] with the memcpy floor and the identity-through-stack rows first."""
    rows = []
    for threads in threads_list:
        ctx = vp(); L.fx_context_new(ctypes.byref(ctx), threads)
        fr = vp(); L.fx_frame_new(ctx, w, h, ctypes.byref(fr))
        for name, arr in passes.items():
            if name in ("Combined", "Depth", "Normal", "DiffDir", "DiffCol", "DiffInd") or name in keep:
                ch = arr.shape[2] if arr.ndim == 3 else 1
                L.fx_frame_add_pass(fr, name.encode(), ch, fp(arr))
        rows.append(("memcpy floor (RGBA float read+write)", threads, floor_ms(passes["Combined"], runs)))
        for label, eff, params in [IDENTITY] + cases:
            st = vp(); L.fx_stack_new(ctx, ctypes.byref(st))
            if L.fx_stack_load_json(st, json.dumps({"version": 1, "effects": [{"effect": eff, "params": params}]}).encode()):
                raise SystemExit(L.fx_context_error(ctx))
            t = []
            for _ in range(runs):
                out = vp()
                if L.fx_stack_run(st, fr, ctypes.byref(out)):
                    raise SystemExit(L.fx_context_error(ctx))
                js = ctypes.c_char_p(); L.fx_stack_timings_json(st, ctypes.byref(js))
                t.append(json.loads(js.value)[0]["ms"])
                L.fx_frame_free(out)
            L.fx_stack_free(st)
            rows.append((label, threads, statistics.median(t)))
            print("%-46s %d thr %8.2f ms" % (label, threads, rows[-1][2]), flush=True)
        L.fx_frame_free(fr); L.fx_context_free(ctx)
    return rows


def table(rows, runs):
    md = ["| case | threads | ms (median of %d) | x memcpy floor | x identity through the stack |" % runs,
          "|---|---:|---:|---:|---:|"]
    fl, idn = {}, {}
    for label, th, ms in rows:
        if label.startswith("memcpy"):
            fl[th] = ms
        if label == IDENTITY[0]:
            idn[th] = ms
    for label, th, ms in rows:
        md.append("| %s | %d | %.2f | %.1fx | %s |" % (label, th, ms, ms / fl[th],
                  ("%.2fx" % (ms / idn[th])) if th in idn and not label.startswith("memcpy") else ""))
    return md


# ---------- Blender's compositor ----------
BLENDER_SCRIPT = r"""
import bpy, sys, time, json
args = json.loads(sys.argv[sys.argv.index("--") + 1])
s = bpy.context.scene
s.render.resolution_x, s.render.resolution_y, s.render.resolution_percentage = args["w"], args["h"], 100
s.render.threads_mode = "FIXED"
s.render.threads = args["threads"]
s.use_nodes = True
tree = s.node_tree
img_data = bpy.data.images.load(args["src"])

def ramp_constant(node, stops):
    cr = node.color_ramp
    cr.interpolation = "CONSTANT"
    while len(cr.elements) > 1:
        cr.elements.remove(cr.elements[-1])
    cr.elements[0].position = 0.0
    cr.elements[0].color = (stops[0], stops[0], stops[0], 1)
    for i, v in enumerate(stops[1:], 1):
        e = cr.elements.new(i / len(stops))
        e.color = (v, v, v, 1)

def build(mode):
    tree.nodes.clear()
    img = tree.nodes.new("CompositorNodeImage"); img.image = img_data
    comp = tree.nodes.new("CompositorNodeComposite")
    out = lambda name: img.outputs[name] if name in img.outputs else img.outputs[0]
    L = tree.links.new
    if mode == "identity":
        L(out("Combined"), comp.inputs[0])
    elif mode in ("sobel", "laplace"):
        f = tree.nodes.new("CompositorNodeFilter"); f.filter_type = mode.upper()
        L(out("Combined"), f.inputs[1]); L(f.outputs[0], comp.inputs[0])
    elif mode in ("fog_glow", "streaks"):
        g = tree.nodes.new("CompositorNodeGlare"); g.glare_type = mode.upper(); g.quality = "HIGH"
        g.size = args["fog_size"]; g.threshold = 1.0; g.mix = args.get("mix", 0.0)
        L(out("Combined"), g.inputs[0]); L(g.outputs[0], comp.inputs[0])
    elif mode == "bw_ramp":
        bw = tree.nodes.new("CompositorNodeRGBToBW")
        cr = tree.nodes.new("CompositorNodeValToRGB"); ramp_constant(cr, [0.0, 0.05, 0.3, 1.0])
        L(out("Combined"), bw.inputs[0]); L(bw.outputs[0], cr.inputs[0]); L(cr.outputs[0], comp.inputs[0])
    elif mode == "cel_chain":
        # banded diffuse light times diffuse colour, plus the other light, times depth outlines
        bw = tree.nodes.new("CompositorNodeRGBToBW")
        cr = tree.nodes.new("CompositorNodeValToRGB"); ramp_constant(cr, [0.1, 0.5, 1.0])
        mul = tree.nodes.new("CompositorNodeMixRGB"); mul.blend_type = "MULTIPLY"; mul.inputs[0].default_value = 1
        L(out("DiffDir"), bw.inputs[0]); L(bw.outputs[0], cr.inputs[0])
        L(cr.outputs[0], mul.inputs[1]); L(out("DiffCol"), mul.inputs[2])
        add = tree.nodes.new("CompositorNodeMixRGB"); add.blend_type = "ADD"; add.inputs[0].default_value = 1
        L(mul.outputs[0], add.inputs[1]); L(out("GlossDir"), add.inputs[2])
        lg = tree.nodes.new("CompositorNodeMath"); lg.operation = "LOGARITHM"; lg.inputs[1].default_value = 2.718281828
        L(out("Depth"), lg.inputs[0])
        so = tree.nodes.new("CompositorNodeFilter"); so.filter_type = "SOBEL"
        L(lg.outputs[0], so.inputs[1])
        th = tree.nodes.new("CompositorNodeValToRGB"); ramp_constant(th, [1.0, 0.0])
        th.color_ramp.elements[1].position = 0.1
        L(so.outputs[0], th.inputs[0])
        o = tree.nodes.new("CompositorNodeMixRGB"); o.blend_type = "MULTIPLY"; o.inputs[0].default_value = 1
        L(add.outputs[0], o.inputs[1]); L(th.outputs[0], o.inputs[2]); L(o.outputs[0], comp.inputs[0])
    else:
        raise SystemExit("unknown mode " + mode)

res = {}
for mode in args["modes"]:
    build(mode)
    res[mode] = {}
    for em in ("TILED", "FULL_FRAME"):
        tree.execution_mode = em
        bpy.ops.render.render()  # warm-up: image load and caches
        t = []
        for _ in range(args["runs"]):
            t0 = time.perf_counter(); bpy.ops.render.render(); t.append(time.perf_counter() - t0)
        res[mode][em] = sorted(t)[len(t) // 2] * 1e3
if args.get("write"):
    build(args["write_mode"])
    tree.execution_mode = "FULL_FRAME"
    s.render.image_settings.file_format = "OPEN_EXR"; s.render.image_settings.color_depth = "32"
    s.render.filepath = args["write"]
    bpy.ops.render.render(write_still=True)
print("RESULT " + json.dumps(res))
"""


def blender(args):
    with tempfile.NamedTemporaryFile("w", suffix=".py", delete=False) as f:
        f.write(BLENDER_SCRIPT)
    try:
        r = subprocess.run([a.blender, "-b", "--factory-startup", "--python", f.name, "--", json.dumps(args)],
                           capture_output=True, text=True)
    finally:
        os.unlink(f.name)
    for line in r.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    raise RuntimeError("blender printed no result:\n" + r.stdout[-3000:] + r.stderr[-2000:])


def write_exr(path, rgba):
    import OpenImageIO as oiio
    h, w = rgba.shape[:2]
    spec = oiio.ImageSpec(w, h, 4, oiio.FLOAT)
    o = oiio.ImageOutput.create(path)
    o.open(path, spec)
    o.write_image(rgba)
    o.close()


def read_rgb(path):
    import OpenImageIO as oiio
    i = oiio.ImageInput.open(path)
    px = i.read_image(oiio.FLOAT)
    i.close()
    return px[..., :3]


def r90(glow, cx, cy):
    """Radius (px) holding 90% of the energy of a glow image (luminance, background removed)."""
    lum = np.clip(glow @ np.array([0.2126, 0.7152, 0.0722], np.float32), 0, None)
    yy, xx = np.mgrid[0:lum.shape[0], 0:lum.shape[1]]
    r = np.hypot(xx - cx, yy - cy).ravel()
    order = np.argsort(r)
    c = np.cumsum(lum.ravel()[order])
    return float(r[order][np.searchsorted(c, 0.9 * c[-1])])


def bloom_on(rgba, params, threads=2):
    h, w = rgba.shape[:2]
    ctx = vp(); L.fx_context_new(ctypes.byref(ctx), threads)
    fr = vp(); L.fx_frame_new(ctx, w, h, ctypes.byref(fr))
    L.fx_frame_add_pass(fr, b"Combined", 4, fp(rgba))
    st = vp(); L.fx_stack_new(ctx, ctypes.byref(st))
    L.fx_stack_load_json(st, json.dumps({"version": 1, "effects": [{"effect": "bloom", "params": params}]}).encode())
    out = vp()
    if L.fx_stack_run(st, fr, ctypes.byref(out)):
        raise SystemExit(L.fx_context_error(ctx))
    ch = ctypes.c_int(); data = ctypes.POINTER(ctypes.c_float)()
    L.fx_frame_pass(out, b"Combined", ctypes.byref(data), ctypes.byref(ch))
    res = np.ctypeslib.as_array(data, shape=(h, w, 4)).copy()
    L.fx_frame_free(out); L.fx_stack_free(st); L.fx_frame_free(fr); L.fx_context_free(ctx)
    return res


def main():
    os.makedirs(a.out, exist_ok=True)
    md = ["## In memory, synthetic %dx%d frame" % (W, H), ""]
    md += table(time_cases(synthetic(), W, H, CASES, a.runs), a.runs)
    if a.peers:
        if not os.path.exists(a.exr):
            sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
            import bench_peers  # noqa: E402  (its RENDER_ALL_PASSES script)
            with tempfile.NamedTemporaryFile("w", suffix=".py", delete=False) as f:
                f.write(bench_peers.RENDER_ALL_PASSES)
            scene = os.path.join(ROOT, "blend_scenes", "greek_bath", "greek_bath.blend")
            base = os.path.splitext(a.exr)[0] + "_render"
            subprocess.run([a.blender, "-b", scene, "--python", f.name, "--", base], check=True, capture_output=True)
            os.rename(base + ".exr", a.exr)
        passes, w, h = read_exr(a.exr)
        # --- radius match: one bright pixel through Fog Glow and through bloom ---
        spot = np.zeros((h, w, 4), np.float32); spot[..., 3] = 1
        cx, cy = w // 2, h // 2
        spot[cy, cx, :3] = 1000.0
        spot_path = os.path.join(a.out, "spot.exr"); fog_path = os.path.join(a.out, "spot_fog_glow.exr")
        write_exr(spot_path, spot)
        blender({"src": spot_path, "w": w, "h": h, "threads": 2, "modes": [], "runs": 1, "fog_size": a.fog_size,
                 "write": fog_path, "write_mode": "fog_glow", "mix": 1.0})
        fog = read_rgb(fog_path)  # mix 1: the glare alone
        fog_r90 = r90(fog, cx, cy)
        best, match = None, ["", "| glow | r90 (px) |", "|---|---:|", "| Fog Glow size %d | %.1f |" % (a.fog_size, fog_r90)]
        for rad in (4, 8, 16, 32, 64, 128, 256):
            g = bloom_on(spot, {"radius": rad, "threshold": 1.0, "intensity": 1.0})[..., :3] - spot[..., :3]
            rr = r90(g, cx, cy)
            match.append("| bloom radius %d | %.1f |" % (rad, rr))
            if best is None or abs(rr - fog_r90) < abs(best[1] - fog_r90):
                best = (rad, rr)
        print("\n".join(match), flush=True)
        peer_cases = [c for c in CASES if not c[2].get("radius")] + [
            ("bloom soft knee radius %d (r90 %.0f px ~ Fog Glow size %d)" % (best[0], best[1], a.fog_size),
             "bloom", {"radius": best[0]})]
        md += ["", "## In memory, %s (%dx%d, Cycles passes)" % (os.path.basename(a.exr), w, h), ""]
        md += table(time_cases(passes, w, h, peer_cases, a.runs), a.runs)
        md += ["", "Bloom radius matched to Fog Glow by the radius holding 90% of a spot's glow:"] + match
        # --- Blender's compositor ---
        modes = ["identity", "sobel", "laplace", "fog_glow", "streaks", "bw_ramp", "cel_chain"]
        labels = {"sobel": "Filter Sobel (vs edges sobel luminance)", "laplace": "Filter Laplace (vs edges laplace8)",
                  "fog_glow": "Glare Fog Glow HIGH size %d (vs bloom)" % a.fog_size,
                  "streaks": "Glare Streaks HIGH (vs bloom)", "bw_ramp": "RGB to BW + Color Ramp constant 4 (vs posterize)",
                  "cel_chain": "cel node chain: ramp(BW(DiffDir)) x DiffCol + GlossDir, x Sobel(ln Depth) outline (vs cel_shading)"}
        md += ["", "## Blender 3.4 compositor on %s, render() minus the identity tree, median of %d" % (os.path.basename(a.exr), a.runs),
               "", "| node(s) | threads | TILED ms | FULL_FRAME ms |", "|---|---:|---:|---:|"]
        for th in (1, 2):
            res = blender({"src": a.exr, "w": w, "h": h, "threads": th, "modes": modes, "runs": a.runs, "fog_size": a.fog_size})
            idn = res["identity"]
            md.append("| identity tree (Image -> Composite), whole render() | %d | %.1f | %.1f |" % (th, idn["TILED"], idn["FULL_FRAME"]))
            for m in modes[1:]:
                md.append("| %s | %d | %.1f | %.1f |" % (labels[m], th, res[m]["TILED"] - idn["TILED"],
                                                      res[m]["FULL_FRAME"] - idn["FULL_FRAME"]))
                print(md[-1], flush=True)
    text = "\n".join(md) + "\n"
    with open(os.path.join(a.out, "stylize.md"), "w") as f:
        f.write(text)
    print("\n" + text)


if __name__ == "__main__":
    main()
