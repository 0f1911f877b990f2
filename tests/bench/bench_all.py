#!/usr/bin/python3
"""bench_all: the trade, measured (issue 8). One command times every effect of `libfx list`
at every quality preset and along its main knob, measures its error against its own
`reference` preset and (mirrors, shadows) against Cycles, runs the peers in the same run,
and writes a CSV, a Markdown report and plots.

    /usr/bin/python3 tests/bench/bench_all.py [--quick] [--runs N] [--out out/bench_all] [--docs]
        [--build build-benchall] [--spp 4] [--docs-root .] [--skip first,peers,cycles]
        [--only-effects god_rays:volumetric,voronoi_caustics:refractive [--merge]]

Entries: each effect of the scenes' recipes (its CSV `effect` column: its name), and the
method variants of VARIANTS, benched as their own entries labelled "effect:variant"
("god_rays:volumetric": the scene's god_rays entry with method volumetric; its own presets,
reference, first frame and scaling rows, never mixed with the radial rows of god_rays).

--only-effects L1,L2: only these entries (effect names or variant labels), only the scenes
that hold them; no peers (they time every effect at once) and no Cycles stage unless its
effect is named; no empty-stack first-frame rows. With --docs it needs --merge, which
replaces in docs/bench/bench_all.csv the rows of the kinds this run measured for these
entries (an entry's (effect, kind) pairs; e.g. its peer rows stay when peers did not run),
keeps every other row where it was, and regenerates the report, the plots and the effect
pages from the merged rows. docs/bench/bench_all.runs.json says which run made which rows
(the performance.md section lists them).

Stages (progress and ETA on stderr):
 1. build    cmake --build BUILD (bench_presets, the CLI, the library); configures BUILD with
             -DLIBFX_BUILD_BENCH=ON when it has no cache.
 2. render   the three scenes (greek_bath, atrium, mirror_room) at 1280x720 and 1920x1080,
             frame 1, SPP samples, through the add-on's batch runner with a recipe that is the
             union of every recipe benchmarked on that scene (so the passes file holds every
             pass they need; the runner also renders the aux views and writes the sidecar).
             Cached in OUT/renders (a stamp holds the recipe, size and samples).
 3. effects  tests/bench/bench_presets (C) per scene, size and effect: the four presets and the
             knob sweeps of KNOBS at 2 and 1 threads with the copy floor; at the largest size
             also the scaling rows (0.25..4 MP, mask area 25..100 %, 2 threads).
 4. peers    run_peers() of tests/bench/bench_peers_all.py on the greek_bath passes file at the
             largest size (Blender compositor nodes, oiiotool, EXR read+write, copy floor).
 5. cycles   ssr_mirror against Cycles' true mirrors (bench_ssr_render.py renders,
             bench_ssr_accuracy.py measures) and vsm_shadows against Cycles' ray-traced sun
             shadows (bench_atrium.py --only vsm), at reduced size; their results as `cycles`
             rows.
 6. report   OUT/bench_all.csv, OUT/bench_all.md, OUT/images/perf_*.png. With --docs also
             docs/bench/bench_all.csv, docs/images/perf_*.png, the generated section of
             docs/performance.md (between <!-- bench_all begin --> and <!-- bench_all end -->)
             and scripts/gen_effect_docs.py (docs/effects/*.md from the CSV).

--quick: 1280x720 only, 2 runs, 2 threads, coarse sweeps, no Cycles stage (development).
CSV: kind,scene,effect,setting,width,height,threads,runs,ms_median,mae,max_err,psnr_db,
mask_px,note (bench_presets.c says how each column is measured).
"""
import argparse
import csv
import datetime
import hashlib
import json
import os
import pathlib
import platform
import re
import shutil
import statistics
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[2]
HERE = ROOT / "tests" / "bench"
SCHEMA = ["kind", "scene", "effect", "setting", "width", "height", "threads", "runs", "ms_median",
          "mae", "max_err", "psnr_db", "mask_px", "note"]
SCENES = ("greek_bath", "atrium", "mirror_room")
SIZES_FULL = ((1280, 720), (1920, 1080))
SIZES_QUICK = ((1280, 720),)
FRAME = 1

# Effects benchmarked beyond the scenes' own recipes, on the bath frame.
BATH_EXTRAS = [
    {"effect": "gaussian_blur", "params": {"sigma": 16.7}},          # = Blender's Blur size 50
    {"effect": "color_matrix", "params": {"operator": "sepia"}},
    {"effect": "bloom", "params": {"radius": 128}},
    {"effect": "edges", "params": {"depth": True, "normal": True, "line_width": 3}},
    {"effect": "posterize", "params": {"levels": 4}},
]
# scene -> [(recipe file or list of entries, effects of it to benchmark (None: all))]
SCENE_RECIPES = {
    "greek_bath": [("blend_scenes/greek_bath/recipe.json", None),
                   ("blend_scenes/greek_bath/recipe_cel.json", None),
                   (BATH_EXTRAS, None)],
    "atrium": [("blend_scenes/atrium/recipe.json", None),
               ("blend_scenes/atrium/recipe_sin_city.json", ["sin_city"])],  # bloom: on the bath
    "mirror_room": [("blend_scenes/mirror_room/recipe.json", None)],
}

# Method variants (issue 27): scene -> [(label "effect:variant", recipe holding the effect's
# entries, params set over theirs)]. A variant is its own entry: its own bench recipe (bench_presets
# --label names its rows), its presets against its own reference preset, its first frame. Its
# entries join the scene's render recipe, so the aux views its method needs are rendered (light:Sun,
# water:Water; render_scene checks the sidecar lists them).
VARIANTS = {
    "greek_bath": [
        # as tests/bench/bench_volumetric_sweep.py's BASE (docs/effects/god_rays.md's speed passes):
        # extinction full darkens this low-sun frame (the ~260 m light-view box)
        ("god_rays:volumetric", "blend_scenes/greek_bath/recipe.json",
         {"method": "volumetric", "extinction": "view", "max_distance": 30.0, "volume_density": 0.03,
          "anisotropy": 0.6}),
        # the bath's water is the mask: its surface, the pool floor 1.05 below it
        ("voronoi_caustics:refractive", "blend_scenes/greek_bath/recipe.json",
         {"mode": "refractive", "water": "Water", "receiver_depth": 1.05, "apply": "combined"}),
    ],
}


def split_label(label):
    """"god_rays:volumetric" -> ("god_rays", "volumetric"); "god_rays" -> ("god_rays", None)."""
    effect, sep, variant = label.partition(":")
    if not effect or (sep and not variant) or ":" in variant:
        raise ValueError("bench_all: entry label %r is not EFFECT or EFFECT:VARIANT" % label)
    return effect, (variant or None)


def label_slug(label):
    """A file name part for a label (no ':' in file names: Windows checkouts)."""
    return label.replace(":", "_")


# The knob sweeps per entry label (a variant has its own key; none has sweeps yet): (kind, param,
# full values, quick values or None, "@p=v;..." fixed params).
# kind "knob": a cost/quality knob, error against the reference preset of the recipe's params;
# "look": a knob that changes the picture, each value at final against the reference preset at
# the same value. Main knobs from `libfx describe EFFECT` (the params the presets set, or
# the one that sets the effect's size/reach).
KNOBS = {
    "bloom": [("knob", "level_sigma", "0.8,1,1.25,1.5,2", "0.8,2", ""),
              ("look", "radius", "32,64,128,256", "256", "")],
    "cel_shading": [("look", "outline_width", "0,1,2,4", "0,4", "")],
    "color_matrix": [("look", "operator", "grayscale_luminance,sepia,custom", "custom", "")],
    "edges": [("look", "line_width", "1,2,4,8", "8", "")],
    "gaussian_blur": [("look", "sigma", "2,8.5,16.7,50", "2,50", ""),
                      ("knob", "box_passes", "2,3,4,5,6", None, "algorithm=box")],
    "god_rays": [("knob", "polar_resolution", "0.25,0.5,1,2", "0.25,1", ""),
                 ("knob", "samples", "25,100,400", None, "method=naive")],
    "pixelate": [("look", "cell_size", "4,12,32", "4", "")],
    "posterize": [("look", "levels", "2,4,8,16", "16", "")],
    "rain": [("look", "density", "0.1,0.35,1", "1", "")],
    "rain_splashes": [("knob", "downsample", "1,2,4,8", "8", ""),
                      ("look", "spacing", "0.25,0.35,1", "0.25", "")],  # size 0.12 <= spacing / 2
    "sin_city": [("look", "levels", "0,4,8", "0", "")],
    "ssr_mirror": [("knob", "max_steps", "16,32,64,128,256", "16,64", ""),
                   ("knob", "resolution_scale", "0.25,0.5,1", "0.5", ""),
                   ("knob", "refine", "0,2,6", None, "")],
    "voronoi_caustics": [("look", "points", "49,196,1024,4096", "4096", ""),
                         ("knob", "method", "grid,brute", None, "")],
    # (the refractive mode is the entry voronoi_caustics:refractive of VARIANTS: its presets and
    # reference, where a look knob gave only `final` against `reference`)
    "vsm_shadows": [("look", "filter_size", "1,5,15,33", "15", ""),
                    ("knob", "method", "hard,vsm,pcf", "hard", "")],
    "wet_surfaces": [("look", "edge_softness", "0.1,0.4,1.6", None, "")],
}
SCALING_RES = "0.25,0.5,1,2,4"
SCALING_MASK = "25,50,75,100"

T0 = time.time()
FAILURES = []


def log(msg):
    print("bench_all: %s" % msg, file=sys.stderr, flush=True)


class Progress:
    """Stage i/N with an ETA from per-stage cost estimates, scaled by the pace measured on the
    stages done so far (cached renders, which take no time, are left out of the pace)."""

    def __init__(self, stages):
        self.stages = stages  # [(label, estimated seconds)]
        self.i = 0
        self.t_start = time.time()
        self.paced = []  # (estimate, actual) of finished stages that did work
        self.durations = {}

    def start(self, label):
        self.i += 1
        self.label = label
        self.t_stage = time.time()
        est_left = sum(e for _, e in self.stages[self.i - 1:])
        est_done = sum(e for e, _ in self.paced)
        pace = sum(t for _, t in self.paced) / est_done if est_done > 30 else 1.0
        log("[stage %d/%d] %s (elapsed %s, ETA %s)" % (self.i, len(self.stages), label,
                                                    fmt_s(time.time() - self.t_start), fmt_s(est_left * pace)))

    def end(self):
        dt = time.time() - self.t_stage
        est = self.stages[self.i - 1][1]
        if dt > 0.2 * est:
            self.paced.append((est, dt))
        group = self.label.split(":")[0]
        self.durations[group] = self.durations.get(group, 0.0) + dt
        return dt


def fmt_s(s):
    s = int(round(s))
    return "%dm%02ds" % (s // 60, s % 60) if s >= 60 else "%ds" % s


def run(cmd, env=None, check=True, capture=True, cwd=None):
    p = subprocess.run([str(c) for c in cmd], env=env, cwd=cwd, text=True,
                       stdout=subprocess.PIPE if capture else None,
                       stderr=subprocess.PIPE if capture else None)
    if check and p.returncode:
        tail = ((p.stdout or "")[-3000:] + (p.stderr or "")[-3000:]) if capture else ""
        raise SystemExit("bench_all: failed (%d): %s\n%s" % (p.returncode, " ".join(map(str, cmd)), tail))
    return p


# ---------------------------------------------------------------- machine

def machine():
    model = "unknown CPU"
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = ""
    try:
        for line in open("/proc/meminfo"):
            if line.startswith("MemTotal"):
                mem = "%.0f GiB" % (int(line.split()[1]) / 1024 / 1024)
    except OSError:
        pass
    return {"cpu": model, "cores": os.cpu_count(), "memory": mem, "os": platform.platform()}


def source_state():
    """The commit measured, and the uncommitted files of the library it was built with."""
    try:
        sha = run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"]).stdout.strip()
        dirty = [l[3:] for l in run(["git", "-C", ROOT, "status", "--porcelain", "--", "libfx", "CMakeLists.txt",
                                     "cmake"]).stdout.splitlines() if l.strip()]
    except SystemExit:
        return "unknown (not a git checkout)"
    return "git %s%s" % (sha, "" if not dirty else " + uncommitted changes in %s" % ", ".join(dirty))


def loadavg():
    try:
        return " ".join(open("/proc/loadavg").read().split()[:3])
    except OSError:
        return "?"


# ---------------------------------------------------------------- recipes and renders

def load_entries(src):
    if isinstance(src, list):
        return [dict(e) for e in src]
    return json.load(open(ROOT / src))["effects"]


def variant_entries(src, effect, params):
    """The enabled entries of `effect` in recipe `src`, with `params` set over theirs."""
    es = [json.loads(json.dumps(e)) for e in load_entries(src) if e.get("enabled", True) and e["effect"] == effect]
    if not es:
        raise SystemExit("bench_all: %s has no enabled %s entry (VARIANTS)" % (src, effect))
    for e in es:
        e["params"] = dict(e.get("params", {}), **params)
    return es


def scene_plan(scene):
    """(union recipe for the render, {entry label: its bench recipe}, [entry labels in order]).
    The scene's effects share one bench recipe; each variant of VARIANTS has its own (its
    label right after its effect's)."""
    entries, labels = [], []
    for src, only in SCENE_RECIPES[scene]:
        es = [e for e in load_entries(src) if e.get("enabled", True)]
        for e in es:
            if only is None or e["effect"] in only:
                entries.append(e)
                if e["effect"] not in labels:
                    labels.append(e["effect"])
    base = {"version": 1, "quality": "final", "effects": entries}
    benches = {l: base for l in labels}
    render_entries = list(entries)
    for label, src, params in VARIANTS.get(scene, []):
        effect, variant = split_label(label)
        if not variant:
            raise SystemExit("bench_all: VARIANTS label %r names no variant (EFFECT:VARIANT)" % label)
        es = variant_entries(src, effect, params)
        benches[label] = {"version": 1, "quality": "final", "effects": es}
        after = max([i for i, l in enumerate(labels) if split_label(l)[0] == effect], default=len(labels) - 1)
        labels.insert(after + 1, label)
        render_entries += es  # the render holds its passes and aux views
    render = {"version": 1, "quality": "final", "effects": render_entries}
    return render, benches, labels


def write_bench_recipes(d, benches):
    """{label: path}: the scene's shared bench recipe as bench_recipe.json, a variant's as
    bench_recipe_<label>.json."""
    paths = {}
    for label, recipe in benches.items():
        variant = split_label(label)[1]
        path = d / ("bench_recipe_%s.json" % label_slug(label) if variant else "bench_recipe.json")
        path.write_text(json.dumps(recipe, indent=1))
        paths[label] = path
    return paths


def missing_aux_views(side, benches):
    """The aux views some bench recipe needs (the library says which) that the sidecar lacks."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("libfx_native", ROOT / "addon" / "libfx" / "native.py")
    native = importlib.util.module_from_spec(spec)  # its package's __init__ imports bpy: the file alone
    spec.loader.exec_module(native)
    have = {v.get("name") for v in json.loads(pathlib.Path(side).read_text()).get("aux_views", [])}
    ctx = native.Context(1)
    try:
        need = {v["name"] for recipe in benches.values() for v in native.Stack(ctx, recipe).required_aux_views()}
    finally:
        ctx.close()
    return sorted(need - have)


def render_scene(scene, w, h, spp, out, env):
    """(passes, sidecar, {label: bench recipe path}, labels, render seconds or None if cached)."""
    d = out / "renders" / ("%s_%dx%d" % (scene, w, h))
    d.mkdir(parents=True, exist_ok=True)
    render, benches, labels = scene_plan(scene)
    rpath = d / "render_recipe.json"
    rtext = json.dumps(render, indent=1)
    stamp = {"recipe": hashlib.sha1(rtext.encode()).hexdigest(), "size": [w, h], "spp": spp, "frame": FRAME}
    passes, side = d / ("r_libfx_passes.%04d.exr" % FRAME), d / ("r_libfx.%04d.camera.json" % FRAME)
    bpaths = write_bench_recipes(d, benches)
    sp = d / "stamp.json"
    if passes.exists() and side.exists() and sp.exists() and json.loads(sp.read_text()) == stamp:
        log("%s %dx%d: cached render" % (scene, w, h))
        return passes, side, bpaths, labels, None
    rpath.write_text(rtext)
    t0 = time.time()
    run(["blender", "-b", ROOT / "blend_scenes" / scene / ("%s.blend" % scene), "--python",
         ROOT / "addon" / "libfx" / "batch.py", "--", "--keep-passes", "--frames", str(FRAME), "--output", str(d / "r_"),
         "--resolution", "%dx%d" % (w, h), "--samples", str(spp), "--recipe", rpath], env=env)
    dt = time.time() - t0
    missing = missing_aux_views(side, benches)
    if missing:  # the variants would fail (or the light view be missing) in every run
        raise SystemExit("bench_all: %s: the sidecar lists no aux view %s (render recipe %s)" %
                         (side, ", ".join(missing), rpath))
    sp.write_text(json.dumps(stamp))
    log("%s %dx%d: rendered in %.0f s" % (scene, w, h, dt))
    return passes, side, bpaths, labels, dt


# ---------------------------------------------------------------- effects

FIRST_FRAME_SEQ = 4  # frames per process: the first, then warm ones


def first_frame_rows(cli, scene, passes, side, recipes, labels, w, h, runs, tmp, empty=True):
    """What a one-frame run meets: `libfx run -v` (2 threads, `final`) over FIRST_FRAME_SEQ links
    to the scene's passes, in `runs` fresh processes per entry (`recipes`: label -> its bench
    recipe; its entries of the label's effect); the entry's time on frame 1 (median over
    processes) against the median of the later frames. With `empty` also the empty stack
    (effect "(empty stack)"), with the whole one-frame process's wall time."""
    tmp.mkdir(parents=True, exist_ok=True)
    for i in range(1, FIRST_FRAME_SEQ + 1):
        link = tmp / ("in.%04d.exr" % i)
        link.unlink(missing_ok=True)
        link.symlink_to(pathlib.Path(passes).resolve())
    rows = []
    for eff in ([None] if empty else []) + list(labels):
        es = []
        if eff:
            entries = json.loads(pathlib.Path(recipes[eff]).read_text())["effects"]
            es = [e for e in entries if e["effect"] == split_label(eff)[0] and e.get("enabled", True)]
        rp = tmp / "recipe.json"
        rp.write_text(json.dumps({"version": 1, "quality": "final", "effects": es}))
        first, warm, one = [], [], []
        for _ in range(runs):
            for o in tmp.glob("out.*.exr"):
                o.unlink()
            out = run([cli, "run", "-v", "-j", "2", "--compression", "none", "--sidecar", side, "--stack", rp,
                       tmp / "in.####.exr", "-o", tmp / "out.####.exr"]).stdout
            per_frame = [sum(t["ms"] for t in json.loads(l[len("timings:"):]))
                         for l in out.splitlines() if l.startswith("timings:")]
            if len(per_frame) != FIRST_FRAME_SEQ:
                raise SystemExit("bench_all: libfx run -v printed %d timings for %d frames" %
                                 (len(per_frame), FIRST_FRAME_SEQ))
            first.append(per_frame[0])
            warm += per_frame[1:]
            if eff is None:  # the whole process on one frame: read, empty stack, write
                t0 = time.perf_counter()
                run([cli, "run", "-j", "2", "--quiet", "--force", "--compression", "none", "--sidecar", side,
                     "--stack", rp, tmp / "in.0001.exr", "-o", tmp / "one.exr"])
                one.append((time.perf_counter() - t0) * 1e3)
        f, wm = statistics.median(first), statistics.median(warm)
        note = "warm %.1f ms (frames 2-%d, median); first / warm %.2fx" % (wm, FIRST_FRAME_SEQ, f / wm if wm > 0 else 0)
        if one:
            note += "; one-frame `libfx run` (read, stack, uncompressed write) %.0f ms" % statistics.median(one)
        rows.append(dict(kind="first_frame", scene=scene, effect=eff or "(empty stack)", setting="quality=final",
                         width=w, height=h, threads=2, runs=runs, ms_median="%.3f" % f, mae="", max_err="",
                         psnr_db="", mask_px="", note=note))
        log("  first frame %s: %.1f ms, warm %.1f ms" % (eff or "(empty stack)", f, wm))
    return rows


def fresh_pages_row(bench_dir, scene, w, h, runs=5):
    """The floor under a first frame: filling one fresh w x h RGBA float buffer in a new
    process (bench_fresh_pages), against filling it again."""
    first, again = [], []
    for _ in range(runs):
        a, b = run([bench_dir / "bench_fresh_pages", w, h]).stdout.split()
        first.append(float(a))
        again.append(float(b))
    f, g = statistics.median(first), statistics.median(again)
    log("  fresh pages %dx%d: %.1f ms, again %.1f ms" % (w, h, f, g))
    return dict(kind="first_frame", scene=scene, effect="(fresh frame buffer)", setting="memset", width=w, height=h,
                threads=1, runs=runs, ms_median="%.3f" % f, mae="", max_err="", psnr_db="", mask_px="",
                note="warm %.1f ms (the same buffer filled again); first / warm %.2fx; one RGBA float buffer "
                     "from fx_mem_alloc (huge-page advised) filled in a fresh process: what an effect that "
                     "needs a second frame-sized buffer pays on the first frame" % (g, f / g if g > 0 else 0))


def read_rows(path):
    with open(path, newline="") as f:
        return [dict(r) for r in csv.DictReader(f)]


def bench_effect(bench_bin, scene, label, passes, side, recipe, args, scaling, tmp):
    """bench_presets for one entry (an effect, or a variant "effect:variant" from its own
    recipe, its rows labelled so): the presets and the knob sweeps (every size and thread
    count; --quick: the first thread count only); scaling: the scaling rows too."""
    effect, variant = split_label(label)
    cmd = [bench_bin, "--passes", passes, "--sidecar", side, "--recipe", recipe, "--scene", scene,
           "--effects", effect, "--threads", args.threads, "--runs", str(args.runs),
           "--budget-ms", str(args.budget_ms), "--ref-max-ms", str(args.ref_max_ms), "-o", tmp]
    if variant:
        cmd += ["--label", label]
    for kind, param, full, quick, fixed in KNOBS.get(label, []):
        vals = quick if args.quick else full
        if not vals:
            continue
        cmd += ["--look-knob" if kind == "look" else "--knob",
                "%s.%s=%s%s" % (effect, param, vals, ("@" + fixed) if fixed else "")]
    if args.quick:
        cmd += ["--knobs-first-threads-only"]
    if scaling:
        cmd += ["--scaling-res", args.scaling_res, "--scaling-mask",
                args.scaling_mask, "--scaling-threads", str(max(int(t) for t in args.threads.split(",")))]
    p = subprocess.Popen([str(c) for c in cmd], stderr=subprocess.PIPE, text=True)
    for line in p.stderr:
        if args.verbose or not line.startswith("bench_presets: ["):
            sys.stderr.write("  " + line)
    if p.wait():
        log("ERROR: bench_presets failed for %s on %s (its rows are missing; message above)" % (label, scene))
        FAILURES.append("%s on %s" % (label, scene))
        return []
    return read_rows(tmp)


def describe(cli, effect):
    return json.loads(run([cli, "describe", effect]).stdout)


# ---------------------------------------------------------------- peers

def peers_stage(passes, side, w, h, runs, out, env):
    sys.path.insert(0, str(HERE))
    try:
        os.environ.update({k: v for k, v in env.items() if k.startswith("LIBFX")})
        from bench_peers_all import run_peers
    except Exception as e:  # the peers module is written by another engineer
        log("peers skipped: tests/bench/bench_peers_all.py not importable (%s: %s)" % (type(e).__name__, e))
        return [], "not importable: %s" % e
    try:
        rows = run_peers(str(passes), str(side), w, h, runs, str(out / "peers"))
    except BaseException as e:  # keep the run's other results
        log("peers failed: %s: %s" % (type(e).__name__, e))
        return [], "failed: %s" % e
    return [{k: ("" if r.get(k) is None else str(r.get(k))) for k in SCHEMA} for r in rows], None


# ---------------------------------------------------------------- cycles

def cycles_ssr(out, env, res, runs, cli):
    d = out / "cycles" / "ssr"
    d.mkdir(parents=True, exist_ok=True)
    w, h = (int(v) for v in res.split("x"))
    for mode, name in (("backing", "back"), ("cycles_mirror", "ref")):
        if not (d / ("%s%d.exr" % (name, w))).exists():
            t0 = time.time()
            run(["blender", "-b", "--factory-startup", "--python", HERE / "bench_ssr_render.py", "--",
                 d / ("%s%d" % (name, w)), "--mode", mode, "--resolution", w, h, "--samples", 16], env=env)
            log("mirror_room %s %s rendered in %.0f s" % (mode, res, time.time() - t0))
    p = run(["/usr/bin/python3", HERE / "bench_ssr_accuracy.py", "--cli", cli, "--dir", d, "--res", res,
             "--out", d / "out", "--runs", runs], env=env)
    (d / "accuracy.log").write_text(p.stdout + p.stderr)
    m = re.search(r"region: (\d+) px", p.stdout)
    region = m.group(1) if m else ""
    rows = []
    note = ("vs Cycles true mirrors (bench_ssr_accuracy.py); the whole mirror_room stack; RGB clamped to "
            "[0 1]; PSNR peak 1; region: physical mirrors where the reference preset hit on screen; ms: "
            "libfx run -v effects time")
    with open(d / "out" / "ssr_accuracy.csv") as f:
        lines = f.read().split("\n\n")[0].strip().splitlines()[1:]
    for line in lines:
        method, mae, psnr, ms = line.rsplit(",", 3)
        setting = {"no reflection (input)": "input (no reflection)"}.get(method, method)
        setting = re.sub(r"^libfx (\w+)$", r"quality=\1", setting)
        rows.append(dict(kind="cycles", scene="mirror_room", effect="ssr_mirror", setting=setting, width=w,
                         height=h, threads=2 if setting.startswith("quality") else "",
                         runs=runs if setting.startswith("quality") else "", ms_median=ms if float(ms) > 0 else "",
                         mae=mae, max_err="", psnr_db=psnr, mask_px=region, note=note))
    with open(d / "out" / "ssr_curve.csv") as f:
        for r in csv.DictReader(f):
            k, v = r["variant"].split()
            param = {"steps": "max_steps", "refine": "refine", "scale": "resolution_scale"}[k]
            rows.append(dict(kind="cycles", scene="mirror_room", effect="ssr_mirror", setting="%s=%s" % (param, v),
                             width=w, height=h, threads=2, runs=runs, ms_median=r["ms"], mae=r["mae"], max_err="",
                             psnr_db=r["psnr_db"], mask_px=region,
                             note=note + "; knob sweep (the other knobs at max_steps 64 stride 2 growth 1.05 "
                                         "refine 4 scale 1)"))
    return rows


def cycles_vsm(out, env, res, spp, runs):
    d = out / "cycles" / "vsm"
    d.mkdir(parents=True, exist_ok=True)
    p = run(["/usr/bin/python3", HERE / "bench_atrium.py", d, "--only", "vsm", "--res", res, "--spp", spp,
             "--runs", runs], env=env)
    (d / "atrium.log").write_text(p.stdout + p.stderr)
    rep = json.load(open(d / "report.json"))
    w, h = (int(v) for v in res.split("x"))
    rows = []
    for key, what in (("vsm_vs_cycles", "full render (world; bounces)"),
                      ("vsm_direct", "the Sun's direct diffuse light alone")):
        if key not in rep:
            continue
        r = rep[key]
        shadow_px = int(round(r["shadow_pixel_fraction"] * w * h))
        for method, size, bleed, mae_frame, mae_shadow, ms in r["rows"]:
            if size == "":
                setting = method
            else:
                m = "vsm" if method.startswith("vsm") else method
                setting = "method=%s filter_size=%s" % (m, size)
                if method == "vsm_gauss":
                    setting += " filter=gaussian"
                if m == "vsm":
                    setting += " bleed_reduction=%s" % bleed
            rows.append(dict(kind="cycles", scene="atrium", effect="vsm_shadows", setting=setting, width=w,
                             height=h, threads=os.cpu_count() if ms != "" else "", runs=1 if ms != "" else "",
                             ms_median=ms,
                             mae="%.6g" % mae_shadow, max_err="", psnr_db="", mask_px=shadow_px,
                             note="vs Cycles ray-traced Sun shadows (bench_atrium.py; frame %d; %s); MAE over the "
                                  "pixels the Sun's shadow changes (mask_px); MAE over the frame %.5f; one run"
                                  % (r["frame"], what, mae_frame)))
    return rows


# ---------------------------------------------------------------- report

def fnum(v, kind="err"):
    if v is None or v == "":
        return ""
    try:
        x = float(v)
    except ValueError:
        return str(v)
    if x != x:
        return ""
    if kind == "ms":
        return "%.0f" % x if x >= 100 else "%.1f" % x if x >= 10 else "%.2f" % x
    if kind == "db":
        return "∞" if x == float("inf") else "%.1f" % x
    if kind == "x":
        return "%.1fx" % x
    if x == 0:
        return "0"
    return "%.2g" % x if 0.01 <= abs(x) < 1000 else ("%.1e" % x).replace("e-0", "e-")


def md_table(head, rows, align=None):
    align = align or ["---"] * len(head)
    out = ["| " + " | ".join(head) + " |", "|" + "|".join(align) + "|"]
    out += ["| " + " | ".join(str(c).replace("|", "/") for c in r) + " |" for r in rows]
    return out


def size_of(r):
    return "%sx%s" % (r["width"], r["height"])


def common_note_parts(rows):
    parts = [set((r["note"] or "").split("; ")) - {""} for r in rows]
    return set.intersection(*parts) if parts else set()


def effect_tables(rows, effects, halos):
    """One table per entry (effect or variant label): a row per (scene, setting, size), a
    column pair per thread count."""
    md = []
    floors = {(r["scene"], r["effect"], r["width"], r["height"], r["threads"]): float(r["ms_median"])
              for r in rows if r["kind"] == "floor" and r["ms_median"]}
    for eff in effects:
        er = [r for r in rows if r["effect"] == eff and r["kind"] in ("effect", "reference")]
        if not er:
            continue
        local = halos.get(eff, 99) <= 1
        threads = sorted({r["threads"] for r in er}, key=lambda t: -int(t or 0))
        common = common_note_parts(er)
        md.append("#### %s\n" % eff)
        if variant_note(eff):
            md.append(variant_note(eff) + "\n")
        if common:
            md.append("Every row: %s.\n" % "; ".join(sorted(common)))
        groups = {}
        for r in er:
            groups.setdefault((r["scene"], r["setting"], r["width"], r["height"]), []).append(r)
        body = []
        for (scene, setting, w, h), rs in groups.items():
            by_t = {r["threads"]: r for r in rs}
            cells = [scene, "`%s`%s" % (setting, " (reference)" if rs[0]["kind"] == "reference" else ""), "%sx%s" % (w, h)]
            for t in threads:
                r = by_t.get(t)
                cells.append(fnum(r["ms_median"], "ms") if r else "")
            for t in threads:
                r = by_t.get(t)
                fl = floors.get((scene, eff, w, h, t))
                cells.append(fnum(float(r["ms_median"]) / fl, "x") if (local and r and fl and r["ms_median"]) else "")
            cells.append("/".join(by_t[t]["runs"] if t in by_t else "-" for t in threads))
            first = rs[0]
            notes = []
            for r in rs:
                for part in (r["note"] or "").split("; "):
                    if part and part not in common and part not in notes:
                        notes.append(part)
            cells += [fnum(first["mae"]), fnum(first["max_err"]), fnum(first["psnr_db"], "db"), first["mask_px"],
                      "; ".join(notes)]
            body.append(cells)
        tl = ["%s thr" % t for t in threads]
        md += md_table(["scene", "setting", "size"] + ["ms, " + t for t in tl] + ["x floor, " + t for t in tl] +
                       ["runs (%s)" % "/".join(tl), "MAE", "max err", "PSNR dB", "mask px", "note"], body,
                       ["---"] * 3 + ["---:"] * (2 * len(threads) + 5) + ["---"])
        md.append("")
    return md


def libfx_ms(rows, effect, w, h, threads="2"):
    """libfx's `final` time of an effect at a size (any scene; the bath first)."""
    c = [r for r in rows if r["kind"] == "effect" and r["effect"] == effect and r["setting"] == "quality=final"
         and r["width"] == str(w) and r["height"] == str(h) and r["threads"] == threads and r["ms_median"]]
    c.sort(key=lambda r: r["scene"] != "greek_bath")
    return (float(c[0]["ms_median"]), c[0]["scene"]) if c else (None, None)


def first_frame_table(rows):
    ff = [r for r in rows if r["kind"] == "first_frame"]
    body = []
    for r in ff:
        warm = r["note"].split(" ms")[0].replace("warm ", "")
        ratio = r["note"].split("first / warm ")[1].split(";")[0] if "first / warm" in r["note"] else ""
        rest = r["note"].split("; ", 2)[2] if r["note"].count("; ") >= 2 else ""
        body.append([r["effect"], r["scene"], size_of(r), fnum(r["ms_median"], "ms"), fnum(warm, "ms"), ratio,
                     r["runs"], rest])
    return md_table(["effect", "scene", "size", "first frame ms", "warm ms", "first / warm", "processes", "note"],
                    body, ["---", "---", "---", "---:", "---:", "---:", "---:", "---"])


def peers_table(rows, peer_rows):
    body = []
    for r in peer_rows:
        lib, _ = libfx_ms(rows, r["effect"], r["width"], r["height"]) if r["kind"] == "peer" else (None, None)
        ratio = ""
        if lib and r["ms_median"]:
            try:
                ratio = fnum(float(r["ms_median"]) / lib, "x")
            except ValueError:
                pass
        body.append([r["kind"], r["effect"], r["setting"], size_of(r), r["threads"], r["runs"],
                     fnum(r["ms_median"], "ms"), fnum(lib, "ms") if lib else "", ratio, fnum(r["mae"]),
                     fnum(r["psnr_db"], "db"), r["note"]])
    return md_table(["kind", "effect", "peer", "size", "threads", "runs", "ms", "libfx final ms (2 threads)",
                     "peer / libfx", "MAE", "PSNR dB", "note"], body,
                    ["---", "---", "---", "---", "---:", "---:", "---:", "---:", "---:", "---:", "---:", "---"])


def scaling_tables(rows):
    md = []
    sr = [r for r in rows if r["kind"] == "scaling_res"]
    if sr:
        mps = sorted({r["setting"] for r in sr}, key=lambda s: float(s.split("=")[1]))
        body = []
        for (scene, eff) in dict.fromkeys((r["scene"], r["effect"]) for r in sr):
            by = {r["setting"]: r for r in sr if r["scene"] == scene and r["effect"] == eff}
            cells = [fnum(by[m]["ms_median"], "ms") if m in by else "" for m in mps]
            lo, hi = by.get(mps[0]), by.get(mps[-1])
            growth = ""
            if lo and hi and float(lo["ms_median"]) > 0:
                px = (int(hi["width"]) * int(hi["height"])) / (int(lo["width"]) * int(lo["height"]))
                growth = "%.1fx for %.0fx pixels" % (float(hi["ms_median"]) / float(lo["ms_median"]), px)
            body.append([eff, scene] + cells + [growth])
        th = sr[0]["threads"]
        md.append("#### Time vs resolution (ms, `final`, %s threads; frames resampled from the rendered one)\n" % th)
        md += md_table(["effect", "scene"] + ["%s MP" % m.split("=")[1] for m in mps] + ["growth"], body,
                       ["---", "---"] + ["---:"] * len(mps) + ["---"])
        md.append("")
    sm = [r for r in rows if r["kind"] == "scaling_mask"]
    if sm:
        pcts = sorted({r["setting"] for r in sm}, key=lambda s: float(s.split("=")[1].rstrip("%")))
        body = []
        for (scene, eff) in dict.fromkeys((r["scene"], r["effect"]) for r in sm):
            by = {r["setting"]: r for r in sm if r["scene"] == scene and r["effect"] == eff}
            cells = ["%s (%s px)" % (fnum(by[p]["ms_median"], "ms"), by[p]["mask_px"]) if p in by else ""
                     for p in pcts]
            full = by.get(pcts[-1])
            ns = ""
            if full and full["mask_px"] and int(full["mask_px"]) > 0:
                ns = "%.0f" % (float(full["ms_median"]) * 1e6 / int(full["mask_px"]))
            body.append([eff, scene, size_of(full) if full else ""] + cells + [ns])
        th = sm[0]["threads"]
        md.append("#### Time vs mask area (ms, `final`, %s threads; the effect's masks cut by a rectangle keeping "
                  "that share of the masked pixels; whole-frame effects: that share of the frame)\n" % th)
        md += md_table(["effect", "scene", "size"] + [p.split("=")[1] for p in pcts] + ["ns per mask px (100 %)"],
                       body, ["---", "---", "---"] + ["---:"] * len(pcts) + ["---:"])
        md.append("")
    return md


def plots(rows, effects, img_dir, peer_rows):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        log("matplotlib missing: no plots")
        return []
    img_dir.mkdir(parents=True, exist_ok=True)
    made = []
    for eff in effects:
        er = [r for r in rows if r["effect"] == eff and r["kind"] in ("effect", "reference") and r["ms_median"]]
        if not er:
            continue
        big = max(er, key=lambda r: int(r["width"]) * int(r["height"]))
        scene, W, H = big["scene"], big["width"], big["height"]
        er = [r for r in er if r["scene"] == scene and r["width"] == W and r["height"] == H]
        fig, ax = plt.subplots(figsize=(7, 4.4), dpi=100)
        errs = [float(r["mae"]) for r in er if r["mae"] not in ("", None) and float(r["mae"]) > 0]
        colours = {}
        palette = ["C0", "C1", "C2", "C3", "C4", "C5", "C6"]

        def family(r):
            return "quality preset" if r["setting"].startswith("quality=") else r["setting"].split("=")[0]

        fams = list(dict.fromkeys(family(r) for r in er if r["kind"] == "effect"))
        for i, f in enumerate(fams):
            colours[f] = palette[i % len(palette)]
        threads = sorted({r["threads"] for r in er})
        if errs:
            zero_x = min(errs) / 4
            for f in fams:
                for t in threads:
                    pts = [r for r in er if r["kind"] == "effect" and family(r) == f and r["threads"] == t]
                    xs = [float(r["mae"]) if r["mae"] not in ("",) else float("nan") for r in pts]
                    xs = [zero_x if x == 0 else x for x in xs]
                    ys = [float(r["ms_median"]) for r in pts]
                    ax.plot(xs, ys, "o" + ("-" if t == threads[-1] else "--"), color=colours[f], ms=5,
                            label="%s, %s thread%s" % (f, t, "" if t == "1" else "s"))
                    for x, y, r in zip(xs, ys, pts):
                        ax.annotate(r["setting"].split("=", 1)[1], (x, y), fontsize=6.5, xytext=(3, 3),
                                    textcoords="offset points")
            ax.set_xscale("log")
            ax.set_xlabel("MAE vs the reference preset (inside the mask; 0 drawn at the left)")
        else:
            labels = list(dict.fromkeys(r["setting"] for r in er))
            for t in threads:
                pts = [r for r in er if r["threads"] == t]
                ax.plot([labels.index(r["setting"]) for r in pts], [float(r["ms_median"]) for r in pts],
                        "o" + ("-" if t == threads[-1] else "--"), label="%s thread%s" % (t, "" if t == "1" else "s"))
            ax.set_xticks(range(len(labels)))
            ax.set_xticklabels(labels, rotation=30, ha="right", fontsize=7)
            ax.set_xlabel("setting (no quality presets: every preset gives the same picture)")
        for t in threads:
            ref = [r for r in er if r["kind"] == "reference" and r["threads"] == t]
            if ref and errs:
                ax.axhline(float(ref[0]["ms_median"]), color="k", ls=":", lw=0.9)
                ax.annotate("reference, %s thr" % t, (ax.get_xlim()[0], float(ref[0]["ms_median"])), fontsize=7,
                            xytext=(2, 2), textcoords="offset points")
        for r in peer_rows:  # peers timed at the plot's size
            if r["effect"] == eff and r["kind"] == "peer" and r["ms_median"] and r["width"] == W and r["height"] == H:
                y = float(r["ms_median"])
                ax.axhline(y, color="r", lw=0.8, alpha=0.7)
                ax.annotate(r["setting"][:48], (ax.get_xlim()[0], y), fontsize=6.5, color="r", xytext=(2, -8),
                            textcoords="offset points")
        ax.set_yscale("log")
        ax.set_ylabel("ms (median)")
        ax.set_title("%s on %s at %sx%s: time vs error" % (eff, scene, W, H), fontsize=10)
        ax.legend(fontsize=7, loc="best")
        fig.tight_layout()
        p = img_dir / ("perf_%s.png" % label_slug(eff))
        fig.savefig(p)
        plt.close(fig)
        made.append(p)
    for kind, fname, xlabel in (("scaling_res", "perf_scaling_res.png", "megapixels"),
                                ("scaling_mask", "perf_scaling_mask.png", "masked pixels (millions)")):
        sr = [r for r in rows if r["kind"] == kind and r["ms_median"]]
        if not sr:
            continue
        fig, ax = plt.subplots(figsize=(7.5, 4.6), dpi=100)
        for i, (scene, eff) in enumerate(dict.fromkeys((r["scene"], r["effect"]) for r in sr)):
            pts = [r for r in sr if r["scene"] == scene and r["effect"] == eff]
            if kind == "scaling_res":
                xs = [int(r["width"]) * int(r["height"]) / 1e6 for r in pts]
            else:
                xs = [int(r["mask_px"]) / 1e6 for r in pts]
            pts = [p for _, p in sorted(zip(xs, pts), key=lambda z: z[0])]
            xs = sorted(xs)
            ax.plot(xs, [float(r["ms_median"]) for r in pts], ("o-", "s-", "^-", "v-")[i // 10 % 4],
                    color="C%d" % (i % 10), ms=4, label=eff)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.set_ylabel("ms (median, final, %s threads)" % sr[0]["threads"])
        ax.set_title("time vs %s" % ("resolution" if kind == "scaling_res" else "mask area"), fontsize=10)
        ax.legend(fontsize=6.5, ncol=2)
        ax.grid(True, which="both", alpha=0.2)
        fig.tight_layout()
        p = img_dir / fname
        fig.savefig(p)
        plt.close(fig)
        made.append(p)
    return made


def write_csv(path, rows):
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=SCHEMA, extrasaction="ignore", lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k, "") for k in SCHEMA})


def run_record(a, info, durations, rows):
    """What docs/bench/bench_all.runs.json keeps of a run: the report's header, and which
    (entry, kind) pairs of the CSV it made ("all" for a whole run)."""
    mode = ("%s; runs per setting: %d (fewer, 3 at least, where one run exceeds %.0f ms / runs; one where "
            "it exceeds %.0f ms: `runs` column); threads: %s; sizes: %s (presets and knob sweeps at every size%s; "
            "the scaling rows at the largest, %s threads)" % (
                "--quick" if a.quick else "full", a.runs, a.budget_ms, a.budget_ms, a.threads,
                ", ".join("%dx%d" % s for s in info["sizes"]),
                " and the first thread count only" if a.quick else " and thread count",
                max(int(t) for t in a.threads.split(","))))
    made = "all" if not a.merge else sorted([list(p) for p in replaced_pairs(rows)])
    return {"rows": made, "command": info["command"], "cpu": info["cpu"], "cores": info["cores"],
            "memory": info["memory"], "os": info["os"], "date": info["date"], "seconds": round(info["seconds"]),
            "source": info["source"], "load_start": info["load_start"], "load_end": info["load_end"],
            "sizes": [list(s) for s in info["sizes"]], "spp": info["spp"], "frame": FRAME,
            "durations": {k: round(v) for k, v in durations.items()}, "failures": list(FAILURES), "mode": mode}


def run_header(r):
    """The report's header lines for one run record."""
    return ["Command: `%s`" % r["command"], "",
            "- Machine: %s, %s cores, %s RAM; %s" % (r["cpu"], r["cores"], r["memory"], r["os"]),
            "- Date: %s (UTC); run took %s" % (r["date"], fmt_s(r["seconds"])),
            "- Source: %s" % r["source"],
            "- Load average (1/5/15 min): %s at the start, %s at the end" % (r["load_start"], r["load_end"]),
            "- Renders: %s, %d samples, frame %d, through the add-on's batch runner" % (
                ", ".join("%dx%d" % tuple(s) for s in r["sizes"]), r["spp"], r["frame"]),
            "- Stage durations: %s" % ", ".join("%s %s" % (k, fmt_s(v)) for k, v in r["durations"].items()),
            "- Failures: %s" % (", ".join(r["failures"]) or "none"),
            "- Mode: %s" % r["mode"]]


def merged_runs_md(runs):
    """The runs merged over the first one (--merge): which rows each made, and its header."""
    if not runs:
        return []
    md = ["", "Rows replaced since by `--merge` runs: each made the rows of the kinds it names for the entries "
              "it names (docs/bench/bench_all.runs.json); every other row is the run above's.", ""]
    for r in runs:
        by_label = {}
        for label, kind in r["rows"]:
            by_label.setdefault(label, []).append(kind)
        md.append("- %s:" % "; ".join("`%s` (%s)" % (l, ", ".join(k)) for l, k in by_label.items()))
        md += ["  " + l if l else "" for l in run_header(r) if l]
    return md


def report_md(a, runs, rows, peer_rows, peer_note, effects, halos, images, img_prefix):
    """The report; `runs`: the run that made the rows, or the base run and the merged ones."""
    md = ["<!-- generated by tests/bench/bench_all.py: do not edit by hand; rerun the command -->", "",
          "## bench_all: every effect, preset and knob, measured in one run (issue 8)", ""]
    md += run_header(runs[0])
    md += merged_runs_md(runs[1:])
    md += ["", "How each number is made (tests/bench/bench_presets.c):", "",
          "- **ms**: median wall time of `fx_stack_run` on a one-effect stack (the recipe's entries of that "
          "effect with their params and masks) after one warm-up run; the input is the scene's passes EXR "
          "and sidecar (aux views read and built in every run: no aux cache). 1 and 2 threads are separate "
          "contexts; the outputs of both are hashed and a difference would be flagged in `note`.",
          "- **error** (MAE, max, PSNR): Combined RGB against the same stack at the `reference` preset, over "
          "the pixels the masks select (coverage > 0; all pixels without a mask); MAE and max on the "
          "scene-linear values, PSNR = 10 log10(1 / MSE) on values clipped to [0, 1] (display-referred, "
          "as the peers' and the Cycles rows'); "
          "∞: bit-identical. Quality knobs (`--knob`): the other params as the recipe's, at `final`, against "
          "the reference preset of the recipe. Look knobs (sigma, radius, filter size...): each value at "
          "`final` against the reference preset at the same value; effects without quality presets have "
          "none (every preset is the same computation).",
          "- **x floor**: ms over a parallel copy of the same frame's RGBA floats (read + write) on the same "
          "thread pool, taken just before and after that effect in the same process (kind `floor`); shown "
          "for per-pixel and 3x3 effects (halo <= 1).",
          "- **cycles** rows: the effect against what Cycles renders for real, at reduced size "
          "(bench_ssr_accuracy.py, bench_atrium.py); their notes say the region and metric.",
          "- **scaling**: `final` at the frame resampled to 0.25..4 MP (Combined and light passes bilinear, "
          "depth/normals/positions/IDs/Cryptomatte nearest), and with the masks cut by a rectangle keeping "
          "25..100 % of their pixels.", "",
          "This VM is shared: compare ratios within this run, not absolute times across runs. CSV: "
          "[docs/bench/bench_all.csv](bench/bench_all.csv) (schema: `%s`)." % ",".join(SCHEMA), ""]
    md.append("### Per effect\n")
    md += effect_tables(rows, effects, halos)
    if any(r["kind"] == "first_frame" for r in rows):
        md.append("### The first frame of a process\n")
        md.append("Each effect alone (the scene's entries, `final`, 2 threads) through `libfx run -v` over %d links "
                  "to the scene's passes file, in fresh processes: the effect's time on frame 1 (median over the "
                  "processes) and on the later frames (warm).\n" % FIRST_FRAME_SEQ)
        md += first_frame_table(rows)
        md.append("")
    md.append("### Peers (same run)\n")
    if peer_rows:
        md.append("Peer / libfx: the peer's time over libfx's `final` time for that effect at the same size with 2 "
                  "threads, from this run (on the greek_bath frame where the effect is measured there).\n")
        md += peers_table(rows, peer_rows)
    else:
        md.append("No peer rows in this run (%s)." % (peer_note or "skipped"))
    md.append("")
    cyc = [r for r in rows if r["kind"] == "cycles"]
    md.append("### Against Cycles\n")
    if cyc:
        body = [[r["effect"], r["scene"], r["setting"], size_of(r), r["threads"], fnum(r["ms_median"], "ms"),
                 fnum(r["mae"]), fnum(r["psnr_db"], "db"), r["mask_px"], r["note"]] for r in cyc]
        common = common_note_parts([r for r in cyc if r["effect"] == "ssr_mirror"]) | \
            common_note_parts([r for r in cyc if r["effect"] == "vsm_shadows"])
        for b in body:
            b[-1] = "; ".join(p for p in b[-1].split("; ") if p not in common)
        for eff in ("ssr_mirror", "vsm_shadows"):
            c = common_note_parts([r for r in cyc if r["effect"] == eff])
            if c:
                md.append("%s rows: %s.\n" % (eff, "; ".join(sorted(c))))
        md += md_table(["effect", "scene", "setting", "size", "threads", "ms", "MAE", "PSNR dB", "px", "note"], body,
                       ["---", "---", "---", "---", "---:", "---:", "---:", "---:", "---:", "---"])
    else:
        md.append("Not run (%s)." % ("--quick" if a.quick and len(runs) == 1 else "skipped"))
    md.append("")
    md.append("### Scaling: cost follows what the scene requires\n")
    md += scaling_tables(rows)
    md.append("### Plots\n")
    for p in images:
        md.append("![%s](%s%s)" % (p.stem, img_prefix, p.name))
    md.append("")
    return "\n".join(md)


BEGIN, END = "<!-- bench_all begin -->", "<!-- bench_all end -->"


def update_performance_md(path, section):
    text = path.read_text()
    block = BEGIN + "\n" + section.rstrip() + "\n" + END
    if BEGIN in text and END in text:
        a, b = text.index(BEGIN), text.index(END) + len(END)
        text = text[:a] + block + text[b:]
    else:
        # right after the summary table at the top (its last '|' line), before the next section
        lines = text.split("\n")
        i = next((k for k, l in enumerate(lines) if l.startswith("|")), None)
        if i is None:
            raise SystemExit("bench_all: no summary table in %s" % path)
        while i < len(lines) and lines[i].startswith("|"):
            i += 1
        lines[i:i] = ["", block]
        text = "\n".join(lines)
    tmp = path.with_suffix(".md.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


# ---------------------------------------------------------------- merge (--merge)

RUNS_JSON = "bench_all.runs.json"  # beside docs/bench/bench_all.csv: which run made which rows


def as_text(row):
    """A row with every value as the CSV gives it back (str; None and missing as "")."""
    return {k: ("" if row.get(k) is None else str(row.get(k))) for k in SCHEMA}


def replaced_pairs(rows):
    """The (entry, kind) pairs that rows hold: what --merge replaces in the docs CSV."""
    return {(r["effect"], r["kind"]) for r in rows}


def row_block(r):
    """Where a row sits in the CSV: bench_presets' rows by size (the 720p block, then the
    1080p one), the other kinds by kind (first frames, scaling, peers, cycles)."""
    if r["kind"] in ("effect", "reference", "floor"):
        return ("effect", str(r["width"]), str(r["height"]))
    return (r["kind"],)


def merge_rows(old, new):
    """`old` with the rows of every (entry, kind) pair that `new` holds replaced by new's;
    every other row kept, in its place. New rows go where the first replaced row of their
    block was; a block with none replaced (an entry new to the CSV) gets them after its last
    row (at the end when the CSV has no such block)."""
    gone = replaced_pairs(new)
    pending = {}
    for r in new:
        pending.setdefault(row_block(r), []).append(r)
    out = []
    for r in old:
        if (r["effect"], r["kind"]) in gone:
            out += pending.pop(row_block(r), [])
        else:
            out.append(r)
    for block, rs in pending.items():
        at = max((i for i, r in enumerate(out) if row_block(r) == block), default=len(out) - 1)
        out[at + 1:at + 1] = rs
    return out


def unknown_run():
    """The record of a CSV whose run left no runs file (before --merge existed)."""
    return {"rows": "all", "command": "unknown (no docs/bench/%s)" % RUNS_JSON, "cpu": "?", "cores": "?",
            "memory": "?", "os": "?", "date": "?", "seconds": 0, "source": "?", "load_start": "?", "load_end": "?",
            "sizes": [], "spp": 0, "frame": FRAME, "durations": {}, "failures": [], "mode": "?"}


def merge_runs(runs, new_run):
    """The runs after a merge: the first (whole) run stays; the earlier merged runs lose the
    pairs new_run made again (one left with none is dropped); new_run last."""
    pairs = {tuple(p) for p in new_run["rows"]}
    out = []
    for i, r in enumerate(runs):
        if i > 0:
            r = dict(r, rows=[p for p in r["rows"] if tuple(p) not in pairs])
            if not r["rows"]:
                continue
        out.append(r)
    return (out or [unknown_run()]) + [new_run]


def peer_rows_of(rows):
    """The rows bench_peers_all.py made (its floor rows are the effect 'memcpy')."""
    return [r for r in rows if r["kind"] in ("peer", "io") or (r["kind"] == "floor" and r["effect"] == "memcpy")]


def entry_labels(effects, rows):
    """The report's entries: each listed effect, then its variants that have rows."""
    seen = list(dict.fromkeys(r["effect"] for r in rows))
    out = []
    for e in effects:
        out.append(e)
        out += [l for l in seen if ":" in l and split_label(l)[0] == e]
    return out


def variant_note(label):
    """How a variant's entries are made (VARIANTS), for the report."""
    for scene, vs in VARIANTS.items():
        for l, src, params in vs:
            if l == label:
                return ("The %s entries of %s with `%s` over their params (VARIANTS in tests/bench/bench_all.py); "
                        "its own presets, reference and first frame." % (split_label(l)[0], src,
                                                                       json.dumps(params)))
    return ""


# ---------------------------------------------------------------- main

def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="1280x720, 2 runs, 2 threads, coarse sweeps, no Cycles")
    ap.add_argument("--runs", type=int, help="runs per setting (default 5; --quick 2)")
    ap.add_argument("--out", default=str(ROOT / "out" / "bench_all"))
    ap.add_argument("--docs", action="store_true", help="also write docs/ (CSV, plots, performance.md section)")
    ap.add_argument("--docs-root", default=str(ROOT), help="tree whose docs/ --docs writes (default: this one)")
    ap.add_argument("--build", default=os.environ.get("LIBFX_BUILD", str(ROOT / "build-benchall")))
    ap.add_argument("--spp", type=int, default=4, help="render samples (default 4)")
    ap.add_argument("--budget-ms", type=float, default=None,
                    help="time budget per setting: fewer runs where one run is longer than BUDGET / runs "
                         "(3 at least while one run fits the budget; default 2000; quick 3000)")
    ap.add_argument("--cycles-ssr-res", default="640x360", help=argparse.SUPPRESS)
    ap.add_argument("--cycles-vsm-res", default="480x270", help=argparse.SUPPRESS)
    ap.add_argument("--skip", default="", help="comma list of stages to skip: first, peers, cycles")
    ap.add_argument("--only-effects", default="",
                    help="comma list of entries: effect names or variant labels (god_rays:volumetric); only "
                         "their scenes, no peers, no Cycles stage unless its effect is named")
    ap.add_argument("--merge", action="store_true",
                    help="with --docs: replace only this run's (entry, kind) rows in docs/bench/bench_all.csv, "
                         "keep the others, regenerate the report, plots and pages from the merged rows")
    ap.add_argument("--verbose", "-v", action="store_true", help="every bench_presets line on stderr")
    a = ap.parse_args(argv)
    a.runs = a.runs or (2 if a.quick else 5)
    a.budget_ms = a.budget_ms or (3000 if a.quick else 2000)
    a.threads = "2" if a.quick else "2,1"  # the fastest first: errors and the slow reference come from it
    a.ref_max_ms = 15000
    a.scaling_res = "0.25,1" if a.quick else SCALING_RES
    a.scaling_mask = "50,100" if a.quick else SCALING_MASK
    a.sizes = SIZES_QUICK if a.quick else SIZES_FULL
    a.skip_stages = set(filter(None, a.skip.split(",")))
    if a.quick:
        a.skip_stages.add("cycles")
    a.only = list(dict.fromkeys(filter(None, a.only_effects.split(","))))
    for label in a.only:
        try:
            split_label(label)
        except ValueError as e:
            ap.error(str(e))
    if a.merge and not a.docs:
        ap.error("--merge merges into docs/bench/bench_all.csv: give --docs")
    if a.merge and a.quick:
        ap.error("--merge --quick would put 720p-only, 2-run rows beside the full run's: merge full runs")
    if a.docs and a.only and not a.merge:
        ap.error("--only-effects with --docs would replace docs/bench/bench_all.csv by these entries' rows "
                 "alone: add --merge")
    if a.only:  # the peers time every effect at once: a subset run keeps their rows as they are
        a.skip_stages.add("peers")
    return a


def select_plan(plan, only):
    """The plan cut to the --only-effects entries (SystemExit naming the known ones when an
    entry is in no scene)."""
    if not only:
        return plan
    known = [l for labels in plan.values() for l in labels]
    unknown = [l for l in only if l not in known]
    if unknown:
        raise SystemExit("bench_all: --only-effects: no entry %s (entries: %s)" % (", ".join(unknown),
                                                                                 ", ".join(known)))
    return {sc: [l for l in labels if l in only] for sc, labels in plan.items()}


def plan_stages(a, plan, scenes):
    """The stages with rough cost estimates (s) for the ETA (measured on the 2-core VM)."""
    sizes, skip = a.sizes, a.skip_stages
    # seconds per effect at 1280x720 in a --quick run (2-core VM); the full run's 720p pass
    # (presets only, 2 thread counts, 5 runs) costs ~1.5x that, its 1080p pass (with the
    # sweeps and scaling rows) ~4x
    quick_s = {"god_rays": 52, "ssr_mirror": 27, "vsm_shadows": 15, "rain": 9, "voronoi_caustics": 7,
               "gaussian_blur": 5, "god_rays:volumetric": 30, "voronoi_caustics:refractive": 30}
    stages = [("build", 20)]
    stages += [("render: %s %dx%d" % (sc, w, h), (40 if sc == "greek_bath" else 80) * w * h / 0.92e6 *
                (0.5 + a.spp / 16)) for sc in scenes for (w, h) in sizes]
    for (w, h) in sizes:
        for sc in scenes:
            for e in plan[sc]:
                f = 1.0 if a.quick else 4.0 if (w, h) == sizes[-1] else 1.5
                stages.append(("effects: %s %s %dx%d" % (sc, e, w, h), quick_s.get(e, 3) * f))
    if "first" not in skip:
        stages += [("first frame: %s" % sc, 12 * ((not a.only) + len(plan[sc]))) for sc in scenes]
    if "peers" not in skip:
        stages.append(("peers", 240 if a.quick else 480))
    for eff in cycles_effects(a):
        stages.append(("cycles: %s" % eff, {"ssr_mirror": 240, "vsm_shadows": 180}[eff]))
    stages.append(("report", 15))
    return stages


def cycles_effects(a):
    """The Cycles stage's effects this run measures."""
    if "cycles" in a.skip_stages:
        return []
    return [e for e in ("ssr_mirror", "vsm_shadows") if not a.only or e in a.only]


def build_stage(build, prog):
    """Builds the bench tools: (bench_presets, the CLI, the environment naming the build)."""
    prog.start("build")
    if not (build / "CMakeCache.txt").exists():
        run(["cmake", "-S", ROOT, "-B", build, "-DCMAKE_BUILD_TYPE=Release", "-DLIBFX_BUILD_BENCH=ON"])
    run(["cmake", "--build", build, "-j2", "--target", "bench_presets", "bench_fresh_pages", "libfx_cli", "fx"])
    bench_bin, cli, lib = build / "tests" / "bench" / "bench_presets", build / "libfx" / "libfx", \
        build / "libfx" / "libfx.so"
    for p in (bench_bin, cli, lib):
        if not p.exists():
            raise SystemExit("bench_all: %s not built (configure %s with -DLIBFX_BUILD_BENCH=ON)" % (p, build))
    env = dict(os.environ, LIBFX_LIBRARY=str(lib), LIBFX_CLI=str(cli), LIBFX_BENCH_DIR=str(build / "tests" / "bench"))
    os.environ["LIBFX_LIBRARY"] = str(lib)  # the sidecar check loads the library (addon/libfx/native.py)
    prog.end()
    return bench_bin, cli, env


def render_stage(a, scenes, out, env, prog):
    renders = {}
    for sc in scenes:
        for (w, h) in a.sizes:
            prog.start("render: %s %dx%d" % (sc, w, h))
            renders[(sc, w, h)] = render_scene(sc, w, h, a.spp, out, env)
            prog.end()
    return renders


def effects_stage(a, bench_bin, plan, scenes, renders, out, prog):
    """Every planned entry at every size: the rows of bench_presets."""
    sizes = a.sizes
    rows = []
    tmp = out / "bench_presets.tmp.csv"
    for (w, h) in sizes:
        for sc in scenes:
            passes, side, recipes, _, _ = renders[(sc, w, h)]
            for e in plan[sc]:
                prog.start("effects: %s %s %dx%d" % (sc, e, w, h))
                rows += bench_effect(bench_bin, sc, e, passes, side, recipes[e], a, (w, h) == sizes[-1], tmp)
                dt = prog.end()
                log("  %s on %s %dx%d: %d rows in %.0f s" % (e, sc, w, h, len(rows), dt))
                write_csv(out / "bench_all.partial.csv", rows)
    tmp.unlink(missing_ok=True)
    return rows


def first_frame_stage(a, build, cli, plan, scenes, renders, out, prog):
    """The first frames of the planned entries at the largest size; a whole run also the
    fresh-pages floor and each scene's empty stack."""
    rows = []
    w, h = a.sizes[-1]
    for sc in scenes:
        prog.start("first frame: %s" % sc)
        passes, side, recipes = renders[(sc, w, h)][:3]
        if sc == SCENES[0] and not a.only:
            rows.append(fresh_pages_row(build / "tests" / "bench", sc, w, h))
        rows += first_frame_rows(cli, sc, passes, side, recipes, plan[sc], w, h, 3, out / "first_frame" / sc,
                                 empty=not a.only)
        prog.end()
    return rows


def cycles_stage(a, cli, out, env, prog):
    rows = []
    for eff in cycles_effects(a):
        prog.start("cycles: %s" % eff)
        try:
            if eff == "ssr_mirror":
                rows += cycles_ssr(out, env, a.cycles_ssr_res, 2, cli)
            else:
                rows += cycles_vsm(out, env, a.cycles_vsm_res, 16, 1)
        except SystemExit as e:
            log("cycles %s failed: %s" % (eff, str(e)[:2000]))
        prog.end()
    return rows


def write_docs(a, rows, runs, peer_note, labels, halos, images, cli):
    """--docs: the CSV (merged when --merge), its runs file, the plots and the performance.md
    section in the docs tree, and the effect pages' generated blocks."""
    droot = pathlib.Path(a.docs_root).resolve()
    write_csv(droot / "docs" / "bench" / "bench_all.csv", rows)
    (droot / "docs" / "bench" / RUNS_JSON).write_text(json.dumps(runs, indent=1) + "\n")
    dimg = droot / "docs" / "images"
    dimg.mkdir(parents=True, exist_ok=True)
    for p in images:
        shutil.copyfile(p, dimg / p.name)
    section = report_md(a, runs, rows, peer_rows_of(rows), peer_note, labels, halos, images, "images/")
    update_performance_md(droot / "docs" / "performance.md", section)
    gen = droot / "scripts" / "gen_effect_docs.py"
    if gen.exists():
        p = run(["/usr/bin/python3", gen, "--cli", cli, "--docs", droot / "docs" / "effects", "--bench-csv",
                 droot / "docs" / "bench" / "bench_all.csv"], check=False)
        log("gen_effect_docs.py: exit %d\n%s" % (p.returncode, (p.stdout + p.stderr)[-1500:]))


def merged_docs_state(a, rows, record):
    """--merge: (the docs CSV's rows with this run's replacing theirs, the runs after it)."""
    dbench = pathlib.Path(a.docs_root).resolve() / "docs" / "bench"
    old = read_rows(dbench / "bench_all.csv") if (dbench / "bench_all.csv").exists() else []
    runs = json.loads((dbench / RUNS_JSON).read_text()) if (dbench / RUNS_JSON).exists() else [unknown_run()]
    merged = merge_rows(old, [as_text(r) for r in rows])
    kept = len(old) - sum((r["effect"], r["kind"]) in replaced_pairs(rows) for r in old)
    log("merge: %d rows kept, %d replaced by %d of this run (%s)" % (
        kept, len(old) - kept, len(rows), ", ".join("%s/%s" % p for p in sorted(replaced_pairs(rows)))))
    return merged, merge_runs(runs, record)


def report_stage(a, cli, rows, peer_note, info, out, prog):
    prog.start("report")
    effects = [l.split("\t")[0] for l in run([cli, "list"]).stdout.splitlines() if l.strip()]
    halos = {e: describe(cli, e).get("halo", 99) for e in effects}
    missing = [e for e in effects if not any(r["effect"] == e and r["kind"] == "effect" for r in rows)]
    if missing and not a.only:
        log("WARNING: no rows for %s" % ", ".join(missing))
    info["load_end"] = loadavg()
    info["seconds"] = time.time() - T0
    write_csv(out / "bench_all.csv", rows)
    (out / "bench_all.partial.csv").unlink(missing_ok=True)
    durations = dict(prog.durations)
    record = run_record(a, info, durations, rows)
    # OUT/: this run's rows alone
    labels = entry_labels(effects, rows)
    halos.update({l: halos.get(split_label(l)[0], 99) for l in labels})
    images = plots(rows, labels, out / "images", peer_rows_of(rows))
    md = report_md(a, [dict(record, rows="all")], rows, peer_rows_of(rows), peer_note, labels, halos, images,
                   "images/")
    (out / "bench_all.md").write_text(md)
    if a.docs:
        runs, drows = [record], rows
        if a.merge:  # every entry's plot and table again, from the merged rows
            drows, runs = merged_docs_state(a, rows, record)
            labels = entry_labels(effects, drows)
            halos.update({l: halos.get(split_label(l)[0], 99) for l in labels})
            images = plots(drows, labels, out / "images_merged", peer_rows_of(drows))
            peer_note = peer_note if peer_rows_of(drows) else (peer_note or "skipped")
        write_docs(a, drows, runs, peer_note, labels, halos, images, cli)
    prog.end()


def main():
    a = parse_args()
    sizes, skip = a.sizes, a.skip_stages
    out = pathlib.Path(a.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    build = pathlib.Path(a.build).resolve()
    info = machine()
    info["command"] = "/usr/bin/python3 tests/bench/bench_all.py" + "".join(" " + x for x in sys.argv[1:])
    info["load_start"] = loadavg()
    info["source"] = source_state()
    info["date"] = datetime.datetime.utcnow().strftime("%Y-%m-%d %H:%M")
    info["sizes"], info["spp"] = sizes, a.spp
    log("%s; %s cores; load %s" % (info["cpu"], info["cores"], info["load_start"]))

    plan = select_plan({sc: scene_plan(sc)[2] for sc in SCENES}, a.only)
    # a subset run renders only the scenes of its entries (the peers, which need the bath, are off)
    scenes = [sc for sc in SCENES if plan[sc] or not a.only]
    prog = Progress(plan_stages(a, plan, scenes))
    bench_bin, cli, env = build_stage(build, prog)
    renders = render_stage(a, scenes, out, env, prog)
    rows = effects_stage(a, bench_bin, plan, scenes, renders, out, prog)
    if "first" not in skip:
        rows += first_frame_stage(a, build, cli, plan, scenes, renders, out, prog)
        write_csv(out / "bench_all.partial.csv", rows)
    peer_note = "skipped (--only-effects: the peers time every effect at once)" if a.only else None
    if "peers" not in skip:
        prog.start("peers")
        w, h = sizes[-1]
        passes, side = renders[("greek_bath", w, h)][:2]
        peer_rows, peer_note = peers_stage(passes, side, w, h, min(a.runs, 3), out, env)
        rows += peer_rows
        prog.end()
    rows += cycles_stage(a, cli, out, env, prog)
    report_stage(a, cli, rows, peer_note, info, out, prog)
    durations = dict(prog.durations)
    log("done in %s: %s" % (fmt_s(time.time() - T0), ", ".join("%s %s" % (k, fmt_s(v)) for k, v in durations.items())))
    log("wrote %s, %s%s" % (out / "bench_all.csv", out / "bench_all.md",
                            " and docs/ (merged)" if a.merge else " and docs/" if a.docs else ""))
    if FAILURES:
        log("FAILED: %s" % ", ".join(FAILURES))
        sys.exit(1)


if __name__ == "__main__":
    main()
