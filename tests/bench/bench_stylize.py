#!/usr/bin/python3
"""bench_stylize: edges, posterize, sin_city, cel_shading, bloom at 1920x1080 through the
public API (ctypes, in memory: no EXR I/O), 1 and 2 threads, medians of --runs, beside the
memory-bandwidth floor measured in the same run (numpy copy of one RGBA float frame:
read + write of the same bytes a per-pixel effect moves).

  /usr/bin/python3 tests/bench/bench_stylize.py [--lib build/libfx/libfx.so] [--runs 5]

Times are fx_stack_timings_json's per-effect ms (the effect plus the stack's mask/copy
composite). Blender compositor peers: tests/bench/bench_peers.py's method (not run here)."""
import argparse, ctypes, json, os, statistics, time
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
ap = argparse.ArgumentParser()
ap.add_argument("--lib", default=os.path.join(ROOT, "build", "libfx", "libfx.so"))
ap.add_argument("--runs", type=int, default=5)
ap.add_argument("--width", type=int, default=1920)
ap.add_argument("--height", type=int, default=1080)
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

W, H = a.width, a.height
rng = np.random.default_rng(1)
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
dc = comb[..., :3].copy()

def fp(x):
    return np.ascontiguousarray(x).ctypes.data_as(ctypes.POINTER(ctypes.c_float))

CASES = [
    ("edges sobel luminance", "edges", {}),
    ("edges sobel lum+depth+normal, width 3", "edges", {"depth": True, "normal": True, "line_width": 3}),
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

def floor_ms(runs):
    src = comb.copy(); dst = np.empty_like(src)
    t = []
    for _ in range(runs * 3):
        t0 = time.perf_counter(); np.copyto(dst, src); t.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(t)

rows = []
for threads in (1, 2):
    ctx = vp(); L.fx_context_new(ctypes.byref(ctx), threads)
    fr = vp(); L.fx_frame_new(ctx, W, H, ctypes.byref(fr))
    for name, arr, ch in (("Combined", comb, 4), ("Depth", depth, 1), ("Normal", nrm, 3), ("DiffDir", dd, 3), ("DiffCol", dc, 3)):
        L.fx_frame_add_pass(fr, name.encode(), ch, fp(arr))
    floor = floor_ms(a.runs)
    rows.append(("memcpy floor (RGBA float read+write)", threads, floor))
    for label, eff, params in CASES:
        st = vp(); L.fx_stack_new(ctx, ctypes.byref(st))
        r = L.fx_stack_load_json(st, json.dumps({"version": 1, "effects": [{"effect": eff, "params": params}]}).encode())
        if r:
            raise SystemExit(L.fx_context_error(ctx))
        t = []
        for _ in range(a.runs):
            out = vp()
            if L.fx_stack_run(st, fr, ctypes.byref(out)):
                raise SystemExit(L.fx_context_error(ctx))
            js = ctypes.c_char_p(); L.fx_stack_timings_json(st, ctypes.byref(js))
            t.append(json.loads(js.value)[0]["ms"])
            L.fx_frame_free(out)
        L.fx_stack_free(st)
        rows.append((label, threads, statistics.median(t)))
        print("%-42s %d thr %8.2f ms  %5.1fx floor" % (label, threads, rows[-1][2], rows[-1][2] / floor), flush=True)
    L.fx_frame_free(fr); L.fx_context_free(ctx)
print("\n| case | threads | ms (median of %d) | x memcpy floor |\n|---|---|---|---|" % a.runs)
fl = {}
for label, th, ms in rows:
    if label.startswith("memcpy"):
        fl[th] = ms
    print("| %s | %d | %.2f | %.1fx |" % (label, th, ms, ms / fl[th]))
