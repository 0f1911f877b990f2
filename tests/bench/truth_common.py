"""Shared code of the truth comparisons (tests/bench/truth_*.py, docs/accuracy_truth.md):
renders a truth scene's libfx input through the add-on's batch path (as scripts/demo.sh
and the demo scenes do), the Cycles truth (the same .blend with the real effect turned
on by the scene script's apply_truth(), through the same path with a no-op recipe, so
both renders share every setting), a second truth with another seed (the noise floor),
then runs `libfx run` at each preset on the input and measures against the truth.

Errors are on linear RGB clamped to [0, 1] (bench_ssr_accuracy.errors). Renders are
kept in the output directory and reused by a re-run (delete them to re-render).
Run with Debian's /usr/bin/python3; LIBFX_LIBRARY / LIBFX_CLI name the build
(default build/).
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
sys.path.insert(0, str(ROOT / "tests" / "bench"))
import addon_testlib as T  # noqa: E402  Exr, crypto_support
from bench_atrium import md_table, noop_recipe  # noqa: E402,F401
from bench_ssr_accuracy import run_cli  # noqa: E402

LIB = os.environ.get("LIBFX_LIBRARY", str(ROOT / "build" / "libfx" / "libfx.so"))
CLI = os.environ.get("LIBFX_CLI", str(ROOT / "build" / "libfx" / "libfx"))
BLENDER = os.environ.get("BLENDER", "blender")
PRESETS = ("draft", "preview", "final", "reference")
LUM = np.array([0.2126, 0.7152, 0.0722], np.float32)


def scene_dir(name):
    return ROOT / "blend_scenes" / ("truth_" + name)


def truth_expr(name, extra=""):
    """--python-expr that applies blend_scenes/truth_<name>/make_truth_<name>.apply_truth()."""
    d = str(scene_dir(name))
    return ("import sys; sys.path.insert(0, %r); import make_truth_%s as m; m.apply_truth()\n%s"
            % (d, name, extra))


def batch(blend, prefix, res, spp, expr=None, recipe=None, seed=None):
    """Renders frame 1 of `blend` with the add-on's batch runner (--keep-passes); returns
    (passes EXR, camera sidecar, render seconds or None when reused)."""
    prefix = str(prefix)
    passes = prefix + "libfx_passes.0001.exr"
    side = prefix + "libfx.0001.camera.json"
    if os.path.exists(passes) and os.path.exists(side):
        return passes, side, None
    code = expr or ""
    if seed is not None:
        code += "\nimport bpy; bpy.context.scene.cycles.seed = %d\n" % seed
    args = [BLENDER, "-b", str(blend)]
    if code:
        args += ["--python-expr", code]
    args += ["--python", str(ROOT / "addon" / "libfx" / "batch.py"), "--", "--keep-passes", "--frames", "1",
             "--output", prefix, "--resolution", res, "--samples", str(spp)]
    if recipe:
        args += ["--recipe", str(recipe)]
    t0 = time.perf_counter()
    p = subprocess.run(args, capture_output=True, text=True, env=dict(os.environ, LIBFX_LIBRARY=LIB))
    dt = time.perf_counter() - t0
    if p.returncode or not os.path.exists(passes):
        sys.exit("render of %s failed:\n%s\n%s" % (blend, p.stdout[-3000:], p.stderr[-3000:]))
    print("rendered %s (%s, %d spp) in %.0f s" % (os.path.basename(prefix), res, spp, dt), flush=True)
    return passes, side, dt


def parse_args(res="480x270", spp=16, variants=None, eevee=False, extra=()):
    """The command line every truth script takes: OUT, --res, --spp, --runs, --docs (and
    --variants when the scene has several, --no-eevee where Eevee is a peer)."""
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--res", default=res)
    ap.add_argument("--spp", type=int, default=spp)
    ap.add_argument("--runs", type=int, default=3)
    if variants:
        ap.add_argument("--variants", default=",".join(variants))
    ap.add_argument("--docs")
    for name, kw in extra:
        ap.add_argument(name, **kw)
    if eevee:
        ap.add_argument("--no-eevee", dest="eevee", action="store_false", help="skip the Eevee peer renders")
    a = ap.parse_args()
    if not eevee:
        a.eevee = False
    os.makedirs(a.out, exist_ok=True)
    return a


def render_three(name, blend, prefix, a, noop, input_recipe=None):
    """libfx's input, the truth and the truth at another seed (the noise floor) of one scene,
    through the add-on's batch path: (passes, sidecar, truth, truth at seed 17). input_recipe:
    the recipe the input is rendered with (the aux views it asks for are rendered too)."""
    passes, side, _ = batch(blend, prefix + "in_", a.res, a.spp, recipe=input_recipe)
    tpass, _, _ = batch(blend, prefix + "truth_", a.res, a.spp, expr=truth_expr(name), recipe=noop)
    t2pass, _, _ = batch(blend, prefix + "truth2_", a.res, a.spp, expr=truth_expr(name), recipe=noop, seed=17)
    return passes, side, tpass, t2pass


# Runs inside Blender after apply_truth(): Eevee Legacy (Blender 3.x) with its screen-space
# reflections at full quality renders one EXR and prints the render time. (Its probes are
# not measured: a baked reflection cubemap changed no pixel, and a planar probe built
# from the mirror's plane lost the wall behind it; Eevee Next, 4.2+, has other probes.)
EEVEE_CODE = r"""
import bpy, json, time
sc = bpy.context.scene
if "BLENDER_EEVEE" not in {i.identifier for i in sc.render.bl_rna.properties["engine"].enum_items}:
    raise SystemExit("truth: Eevee Legacy is not in this Blender")
sc.render.engine = "BLENDER_EEVEE"
w, h = %(res)r
sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = w, h, 100
sc.render.use_compositing = False
sc.eevee.taa_render_samples = %(spp)d
sc.eevee.use_ssr = True
sc.eevee.use_ssr_halfres = False
sc.eevee.ssr_quality = 1.0
sc.eevee.ssr_max_roughness = 0.5
t_bake = None
%(probes)s
is_ = sc.render.image_settings
is_.file_format, is_.color_depth, is_.color_mode = "OPEN_EXR", "32", "RGBA"
sc.render.filepath = %(out)r
t0 = time.perf_counter()
bpy.ops.render.render(write_still=True)
t_render = time.perf_counter() - t0
print("LIBFX_EEVEE " + json.dumps({"render_s": t_render, "bake_s": t_bake}))
"""

# Eevee's own probes (eevee(..., probes=True)): a Reflection Cubemap whose box influence is
# the room (the meshes other than the mirrors), at its centre 1.5 m up; then the light
# cache baked (bpy.ops.scene.light_cache_bake works under -b in Blender 3.4: about 100 s
# here on the VM's software OpenGL). USE_PLANES adds a Reflection Plane on each flat
# mirror object (its largest camera-facing "Mirror" face; skipped when the object's seen
# mirror faces turn, as a curved mirror's do), sized to that face: off, because on this
# VM's software OpenGL (Mesa llvmpipe) the plane's clipping leaks into the main render,
# which then loses everything behind the mirror's plane (the back wall, the far floor)
# and the mirror itself (facing scene, 2026-11-26: region MAE 0.184 against SSR's 0.152).
EEVEE_PROBES = r"""
USE_PLANES = False
from mathutils import Vector, Matrix
def _mirror_faces(o):
    slots = [s.material.name if s.material else "" for s in o.material_slots]
    mw = o.matrix_world
    nm = mw.to_3x3().inverted_safe().transposed()
    for p in o.data.polygons:
        if p.material_index < len(slots) and slots[p.material_index] == "Mirror":
            yield p, mw, (nm @ p.normal).normalized()
_meshes = [o for o in sc.objects if o.type == "MESH" and not o.hide_render]
_mirrors = [o for o in _meshes if any(True for _ in _mirror_faces(o))]
_lo, _hi = Vector((1e9,) * 3), Vector((-1e9,) * 3)
for o in _meshes:
    if o in _mirrors:
        continue
    for c in o.bound_box:
        q = o.matrix_world @ Vector(c)
        _lo, _hi = Vector(map(min, _lo, q)), Vector(map(max, _hi, q))
_cam = sc.camera.matrix_world.translation
_cube = bpy.data.objects.new("libfx_eevee_cubemap", bpy.data.lightprobes.new("libfx_eevee_cubemap", "CUBE"))
sc.collection.objects.link(_cube)
_cube.data.influence_type = "BOX"
_cube.data.influence_distance = 1.0   # the box: the object scale times this (the room)
_cube.location = Vector(((_lo.x + _hi.x) / 2, (_lo.y + _hi.y) / 2, 1.5))
_cube.scale = (_hi - _lo) / 2
_planes = []
for o in (_mirrors if USE_PLANES else []):
    seen = [f for f in _mirror_faces(o) if f[2].dot(_cam - f[1] @ f[0].center) > 0]
    if not seen:
        continue
    p, mw, n = max(seen, key=lambda f: f[0].area)
    if any(f[2].dot(n) < 0.999 and f[0].area > 0.1 * p.area for f in seen):
        continue   # not flat: the cubemap and SSR serve it
    c = mw @ p.center
    t1 = mw @ o.data.vertices[p.vertices[1]].co - mw @ o.data.vertices[p.vertices[0]].co
    t1 = (t1 - n * t1.dot(n)).normalized()
    t2 = n.cross(t1)
    pts = [mw @ o.data.vertices[v].co - c for v in p.vertices]
    e1, e2 = max(abs(q.dot(t1)) for q in pts), max(abs(q.dot(t2)) for q in pts)
    pl = bpy.data.objects.new("libfx_eevee_plane_" + o.name, bpy.data.lightprobes.new("libfx_eevee_plane", "PLANAR"))
    sc.collection.objects.link(pl)
    pl.matrix_world = (Matrix.Translation(c) @ Matrix((t1, t2, n)).transposed().to_4x4()
                       @ Matrix.Diagonal((e1 * 1.05, e2 * 1.05, 1.0, 1.0)))
    pl.data.influence_distance = 0.05
    _planes.append(o.name)
t0 = time.perf_counter()
if bpy.ops.scene.light_cache_bake() != {"FINISHED"}:
    raise SystemExit("truth: Eevee's light cache did not bake")
t_bake = time.perf_counter() - t0
print("LIBFX_EEVEE_PROBES " + json.dumps({"planes": _planes, "cache": sc.eevee.gi_cache_info}))
"""


def eevee(name, blend, out, res, spp, probes=False):
    """The truth scene (apply_truth) rendered by Eevee Legacy with SSR: (linear RGB,
    render seconds); kept and reused like the Cycles renders (OUT.json holds the time).
    probes: with Eevee's own reflection probes too (EEVEE_PROBES; the bake's seconds are
    in OUT.json as bake_s, apart from the render's)."""
    w, h = (int(x) for x in res.split("x"))
    code = EEVEE_CODE % {"res": (w, h), "spp": spp, "out": out, "probes": EEVEE_PROBES if probes else ""}
    return eevee_render(blend, out, truth_expr(name, code))


def eevee_render(blend, out, expr):
    """Runs `blender -b blend --python-expr expr` (a script that renders one EXR to `out` and
    prints LIBFX_EEVEE {"render_s": ...}) unless out and its OUT.json are there already:
    (linear RGB, render seconds)."""
    times = out + ".json"
    if not (os.path.exists(out) and os.path.exists(times)):
        p = subprocess.run(["nice", "-n", "5", BLENDER, "-b", str(blend), "--python-expr", expr],
                           capture_output=True, text=True)
        line = [x for x in p.stdout.splitlines() if x.startswith("LIBFX_EEVEE ")]
        if p.returncode or not line or not os.path.exists(out):
            sys.exit("Eevee render of %s failed:\n%s\n%s" % (blend, p.stdout[-3000:], p.stderr[-3000:]))
        with open(times, "w") as f:
            f.write(line[-1][len("LIBFX_EEVEE "):])
        print("rendered %s with Eevee" % os.path.basename(out), flush=True)
    t = json.load(open(times))
    e = T.Exr(out)
    img = np.stack([e.channels[c] for c in ("R", "G", "B")], axis=-1)
    return img, t["render_s"]


def write_report(out, name, md, report):
    """OUT/truth_<name>.md (the tables) and OUT/truth_<name>.json (the numbers)."""
    with open(os.path.join(out, "truth_%s.md" % name), "w") as f:
        f.write("\n".join(md))
    with open(os.path.join(out, "truth_%s.json" % name), "w") as f:
        json.dump(report, f, indent=1)


def rgb(path):
    return T.Exr(path).get("Combined", "RGB")


def lum(img):
    return np.clip(img, 0, None) @ LUM


def mae(a, b, mask=None):
    d = np.abs(np.clip(a, 0, 1) - np.clip(b, 0, 1))
    if mask is not None:
        if not mask.any():
            return float("nan")
        d = d[mask]
    return float(d.mean())


def mean_ratio(a, b, mask=None):
    la, lb = lum(np.clip(a, 0, 1)), lum(np.clip(b, 0, 1))
    if mask is not None:
        la, lb = la[mask], lb[mask]
    return float(la.mean() / max(lb.mean(), 1e-9))


def laplacian_noise(img, flat):
    """Mean |4-neighbour Laplacian| of the luminance over `flat` pixels (their whole
    3x3 neighbourhood flat): the high-frequency energy of issue 14's shadow goal."""
    y = lum(np.clip(img, 0, 1))
    lap = np.zeros_like(y)
    lap[1:-1, 1:-1] = (4 * y[1:-1, 1:-1] - y[:-2, 1:-1] - y[2:, 1:-1] - y[1:-1, :-2] - y[1:-1, 2:])
    return float(np.abs(lap[flat]).mean()) if flat.any() else float("nan")


def flat_mask(passes):
    """Pixels on flat geometry: unit normals, equal to their 8 neighbours' within 1e-3,
    planar depth varying smoothly (second difference < 1 % of the depth)."""
    e = T.Exr(passes)
    n = e.get("Normal", "XYZ")
    d = e.get("Depth", T.exr_single_channel(e, "Depth"))[..., 0]
    ok = (np.abs(np.linalg.norm(n, axis=-1) - 1) < 1e-3) & (d < 1e5)
    flat = ok.copy()
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            sh = np.roll(np.roll(n, dy, 0), dx, 1)
            flat &= np.abs(sh - n).max(-1) < 1e-3
            flat &= np.roll(np.roll(ok, dy, 0), dx, 1)
    dd = np.zeros_like(d)
    dd[1:-1, 1:-1] = np.maximum(np.abs(d[2:, 1:-1] + d[:-2, 1:-1] - 2 * d[1:-1, 1:-1]),
                                np.abs(d[1:-1, 2:] + d[1:-1, :-2] - 2 * d[1:-1, 1:-1]))
    flat &= dd < 0.01 * d
    flat[[0, -1], :] = False
    flat[:, [0, -1]] = False
    return flat


def run_presets(recipe, passes, side, outdir, tag, runs=3, frame=1, debug=False, presets=PRESETS):
    """`libfx run -q P -v` at each preset (of `presets`): {preset: (image, median ms of
    `runs`)}. The ms is the CLI's own effects time (-v), 2 threads."""
    res = {}
    rec_path = os.path.join(outdir, "%s_recipe.json" % tag)
    with open(rec_path, "w") as f:
        json.dump(recipe, f)
    for q in presets:
        out = os.path.join(outdir, "%s_%s.exr" % (tag, q))
        ts = []
        for _ in range(runs):
            ts.append(run_cli_frame(rec_path, passes, side, out, q, frame, debug))
        res[q] = (rgb(out), statistics.median(ts))
    return res


def run_cli_frame(recipe, passes, side, out, quality, frame, debug):
    if frame is None:
        return run_cli(CLI, recipe, passes, side, out, quality=quality, debug=debug)
    # bench_ssr_accuracy.run_cli has no --frame: the same command with it
    import re
    cmd = [CLI, "run", "-s", recipe, "--camera", side, passes, "-o", out, "-f", "-v", "-j", "2",
           "-q", quality, "--frame", str(frame)]
    if debug:
        cmd.append("--debug-outputs")
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode:
        raise RuntimeError(p.stderr + p.stdout)
    m = re.search(r"effects ([0-9.]+) s", p.stdout)
    return float(m.group(1)) * 1e3 if m else float("nan")


def error_row(name, img, ms, truth, region, flat=None):
    """(method, ms, region MAE, whole MAE, mean ratio [, noise]) of one image."""
    r = [name, ms, mae(img, truth, region), mae(img, truth), mean_ratio(img, truth)]
    if flat is not None:
        r.append(laplacian_noise(img, flat))
    return r


def rows_for(truth, truth2, plain, outs, region, flat=None):
    """Table rows (error_row) for the no-effect input, Cycles with another seed (the
    floor) and each preset."""
    def row(name, img, ms):
        return error_row(name, img, ms, truth, region, flat)
    rows = [row("no effect (input)", plain, None), row("Cycles, other seed (floor)", truth2, None)]
    if flat is not None:
        rows.insert(0, row("Cycles truth", truth, None))
    for q in PRESETS:
        img, ms = outs[q]
        rows.append(row("libfx " + q, img, ms))
    return rows


def fmt_rows(rows, noise=False):
    head = ["method", "ms", "region MAE", "whole MAE", "mean / truth"] + (["Laplacian |L| flat"] if noise else [])
    out = []
    for r in rows:
        c = [r[0], "" if r[1] is None else "%.1f" % r[1]] + ["%.4f" % r[2], "%.4f" % r[3], "%.3f" % r[4]]
        if noise:
            c.append("%.4f" % r[5])
        out.append(c)
    return md_table(head, out)


def srgb8(img):
    x = np.clip(img, 0, 1)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return (x * 255 + 0.5).astype(np.uint8)


def save_strip(path, images, width=480):
    """The images side by side, each resized to `width` px wide (nearest), as 8-bit sRGB PNG."""
    import OpenImageIO as oiio
    tiles = []
    for im in images:
        h, w = im.shape[:2]
        s = width / w
        ys = np.minimum((np.arange(int(round(h * s))) / s).astype(int), h - 1)
        xs = np.minimum((np.arange(width) / s).astype(int), w - 1)
        tiles.append(srgb8(im[ys][:, xs]))
    gap = np.full((tiles[0].shape[0], 4, 3), 255, np.uint8)
    strip = tiles[0]
    for t in tiles[1:]:
        strip = np.concatenate([strip, gap, t], axis=1)
    strip = np.ascontiguousarray(strip)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(strip.shape[1], strip.shape[0], 3, "uint8"))
    out.write_image(strip)
    out.close()


def plot_time_error(path, series, title, ylabel="region MAE vs Cycles", col=2):
    """series: {label: (rows)}: each libfx preset as a point (ms, the row's column `col`:
    the region MAE), the no-effect error as a dashed line of the series' colour."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    fig, ax = plt.subplots(figsize=(6, 3.6), dpi=100)
    for i, (label, rows) in enumerate(series.items()):
        colour = "C%d" % i
        pts = [r for r in rows if r[0].startswith("libfx ")]
        ax.plot([r[1] for r in pts], [r[col] for r in pts], "o-", color=colour, label=label)
        for r in pts:
            ax.annotate(r[0].split()[1], (r[1], r[col]), fontsize=7, xytext=(3, 3), textcoords="offset points")
        none = [r for r in rows if r[0].startswith("no effect")][0][col]
        ax.axhline(none, color=colour, ls="--", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("libfx effects time, ms (2 threads; dashed: no effect)")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(str(path))
    plt.close(fig)
    return True
