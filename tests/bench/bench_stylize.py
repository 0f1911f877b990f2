#!/usr/bin/python3
"""bench_stylize: edges, posterize, sin_city, cel_shading, bloom at 1920x1080, in one command:

  /usr/bin/python3 tests/bench/bench_stylize.py --lib build/libfx/libfx.so --runs 5 --peers

1. In memory through the public API (ctypes; no EXR I/O), 1 and 2 threads, medians of --runs,
   on a synthetic frame, beside two floors measured in the same run: a C memcpy of one RGBA
   float frame on 1 or 2 threads (the bytes a per-pixel effect reads + writes;
   bench_peers_all.memcpy_floor_ms) and an identity effect through the
   stack (posterize mix 0: the effect's memcpy plus the stack's own work: output allocation,
   non-finite scan/mask composite). "x floor" columns are ratios within the run.
2. --peers: the same effects on a real Cycles EXR (every pass; out/bench/allpasses_1080p.exr,
   rendered by bench_peers_all.render_all_passes when missing) beside Blender 3.4's
   compositor on that EXR, timed by bench_peers_all (the one place for peer timing): Image
   node -> nodes -> Composite (no Render Layers node), median render() time minus an identity
   tree's (Image -> Composite), TILED and FULL_FRAME, with the render threads fixed to 1 and 2.
   Peers: Filter Sobel / Laplace (edges), Glare Fog Glow and Streaks (bloom), RGB to BW +
   constant Color Ramp (posterize), and a cel chain (DiffDir -> RGB to BW -> constant ramp x
   DiffCol + GlossDir, x a Sobel-of-ln-Depth outline).
3. --peers also matches the bloom's radius to Fog Glow's (bench_peers_all.match_bloom_radius):
   a single bright pixel through Fog Glow (size --fog-size, mix 1: the glare alone) and
   through bloom (`libfx run`, intensity 1, add: the glow is output - input) at several radii;
   the radius holding 90% of each glow's energy (r90) is printed, and the bloom whose r90 is
   closest is timed beside Fog Glow.

Writes out/bench/stylize.md (the tables) and prints them."""
import argparse, ctypes, json, os, statistics, sys
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_peers_all as peers  # noqa: E402

ROOT = peers.ROOT
ap = argparse.ArgumentParser()
ap.add_argument("--lib", default=os.path.join(ROOT, "build", "libfx", "libfx.so"))
ap.add_argument("--runs", type=int, default=5)
ap.add_argument("--width", type=int, default=1920)
ap.add_argument("--height", type=int, default=1080)
ap.add_argument("--peers", action="store_true", help="also time Blender's compositor peers on a real EXR")
ap.add_argument("--exr", default=os.path.join(ROOT, "out", "bench", "allpasses_1080p.exr"))
ap.add_argument("--blender", default=peers.BLENDER)
ap.add_argument("--fog-size", type=int, default=8, help="Glare node size (Fog Glow kernel 2^size px)")
ap.add_argument("--out", default=os.path.join(ROOT, "out", "bench"))
a = ap.parse_args()
peers.BLENDER = a.blender
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
        rows.append(("memcpy floor (RGBA float read+write)", threads, peers.memcpy_floor_ms(w, h, threads, runs)))
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


def main():
    os.makedirs(a.out, exist_ok=True)
    md = ["## In memory, synthetic %dx%d frame" % (W, H), ""]
    md += table(time_cases(synthetic(), W, H, CASES, a.runs), a.runs)
    if a.peers:
        peers.render_all_passes(a.exr)
        passes, w, h = read_exr(a.exr)
        # --- radius match: one bright pixel through Fog Glow and through bloom ---
        cli = os.path.join(os.path.dirname(os.path.abspath(a.lib)), "libfx")
        lib = peers.Libfx(cli if os.access(cli, os.X_OK) else peers.find_cli(), a.exr, None, a.out, runs=1)
        spot_path, fog_path = peers.fog_glow_spot(a.out, w, h, a.fog_size)
        rad, rr, fog_r90, radii = peers.match_bloom_radius(lib, spot_path, fog_path, w, h)
        match = ["", "| glow | r90 (px) |", "|---|---:|", "| Fog Glow size %d | %.1f |" % (a.fog_size, fog_r90)]
        match += ["| bloom radius %d | %.1f |" % t for t in radii]
        print("\n".join(match), flush=True)
        peer_cases = [c for c in CASES if not c[2].get("radius")] + [
            ("bloom soft knee radius %d (r90 %.0f px ~ Fog Glow size %d)" % (rad, rr, a.fog_size),
             "bloom", {"radius": rad})]
        md += ["", "## In memory, %s (%dx%d, Cycles passes)" % (os.path.basename(a.exr), w, h), ""]
        md += table(time_cases(passes, w, h, peer_cases, a.runs), a.runs)
        md += ["", "Bloom radius matched to Fog Glow by the radius holding 90% of a spot's glow:"] + match
        # --- Blender's compositor (bench_peers_all's trees) ---
        modes = ["sobel", "laplace", "fog_glow", "streaks", "posterize", "cel_chain"]
        labels = {"sobel": "Filter Sobel (vs edges sobel luminance)", "laplace": "Filter Laplace (vs edges laplace8)",
                  "fog_glow": "Glare Fog Glow HIGH size %d (vs bloom)" % a.fog_size,
                  "streaks": "Glare Streaks HIGH (vs bloom)",
                  "posterize": "RGB to BW + Color Ramp constant %d (vs posterize luminance linear)" % peers.POSTER_LEVELS,
                  "cel_chain": "cel node chain: ramp(BW(DiffDir)) x DiffCol + GlossDir, x Sobel(ln Depth) outline (vs cel_shading)"}
        md += ["", "## Blender 3.4 compositor on %s, render() minus the identity tree, median of %d" % (os.path.basename(a.exr), a.runs),
               "", "| node(s) | threads | TILED ms | FULL_FRAME ms |", "|---|---:|---:|---:|"]
        for th in (1, 2):
            res = peers.blender_node_times(a.exr, w, h, modes, a.runs, th, a.fog_size)
            idn = res["identity"]
            md.append("| identity tree (Image -> Composite), whole render() | %d | %.1f | %.1f |" % (th, idn["TILED"], idn["FULL_FRAME"]))
            for m in modes:
                md.append("| %s | %d | %.1f | %.1f |" % (labels[m], th, res[m]["TILED"], res[m]["FULL_FRAME"]))
                print(md[-1], flush=True)
    text = "\n".join(md) + "\n"
    with open(os.path.join(a.out, "stylize.md"), "w") as f:
        f.write(text)
    print("\n" + text)


if __name__ == "__main__":
    main()
