#!/usr/bin/python3
"""bench_passes_codec: which EXR codec the add-on's passes file should use, measured as a
frame meets it: Blender's File Output node writing the passes, then libfx reading them.

    /usr/bin/python3 tests/bench/bench_passes_codec.py PASSES.exr [--runs 3] [--out DIR]
        [--blender host|unstable] [--codecs NONE,ZIP,...]

PASSES.exr is a passes file the add-on wrote (every pass a scene's stack needs). For each
codec, one Blender process loads it as a multilayer image and writes every pass again
through a File Output node (multilayer, 32-bit float, the codec): the write's cost is
render() with that node minus render() without it (median of runs, warm). Then libfx reads
the written file with the stack's needs (`libfx run -v` with the recipe given by --recipe,
default: an empty stack, which decodes Combined only; the read phase, median of runs, each a
fresh process) and the file's size is listed. Prints a Markdown table."""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CODECS = ["NONE", "RLE", "ZIPS", "ZIP", "PIZ", "DWAA"]

SCRIPT = r"""
import bpy, sys, json, time, importlib.util
A = json.load(open(sys.argv[sys.argv.index("--") + 1]))
spec = importlib.util.spec_from_file_location("compat", A["compat"])
compat = importlib.util.module_from_spec(spec); spec.loader.exec_module(compat)
s = bpy.context.scene
s.render.resolution_x, s.render.resolution_y, s.render.resolution_percentage = A["w"], A["h"], 100
s.render.threads_mode = "FIXED"; s.render.threads = 2
s.render.engine = "BLENDER_WORKBENCH"
tree = compat.ensure_compositor_tree(s, "codec bench")[0]
img = bpy.data.images.load(A["src"])
def build(codec):
    for n in list(tree.nodes):
        if n.bl_idname != "NodeGroupOutput":
            tree.nodes.remove(n)
    node = tree.nodes.new("CompositorNodeImage"); node.image = img
    outs = [o for o in node.outputs if o.enabled and o.name not in ("Alpha",)]
    if codec:
        fo = tree.nodes.new("CompositorNodeOutputFile")
        compat.file_output_format(fo, codec=codec)
        compat.file_output_set_prefix(fo, A["out"] + "/" + codec + "_")
        compat.file_output_link(tree, fo, [(o.name, o) for o in outs])
def median_render(runs):
    bpy.ops.render.render()
    t = []
    for _ in range(runs):
        t0 = time.perf_counter(); bpy.ops.render.render(); t.append((time.perf_counter() - t0) * 1e3)
    return sorted(t)[len(t) // 2]
res = {}
for codec in [None] + A["codecs"]:
    build(codec)
    res[codec or "identity"] = median_render(A["runs"])
print("RESULT " + json.dumps(res))
"""


def blender_cmd(which):
    if which == "host":
        return ["blender"]
    return ["bash", os.path.join(ROOT, "scripts", "in_root.sh"), which, "env", "HOME=/tmp", "blender"]


def exr_size(path):
    out = subprocess.run(["oiiotool", "--info", path], capture_output=True, text=True).stdout
    w, h = out.split(":")[1].split(",")[0].split("x")
    return int(w), int(h.strip().split()[0])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("passes")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "bench_codec"))
    ap.add_argument("--blender", default="host")
    ap.add_argument("--codecs", default=",".join(CODECS))
    ap.add_argument("--recipe", default=None, help="the stack whose passes libfx decodes (default: empty)")
    ap.add_argument("--cli", default=os.environ.get("LIBFX_CLI", os.path.join(ROOT, "build", "libfx", "libfx")))
    a = ap.parse_args()
    out = os.path.abspath(a.out)
    os.makedirs(out, exist_ok=True)
    codecs = [c for c in a.codecs.split(",") if c]
    w, h = exr_size(a.passes)
    with tempfile.TemporaryDirectory(dir=out) as d:
        script, args = os.path.join(d, "codec.py"), os.path.join(d, "args.json")
        with open(script, "w") as f:
            f.write(SCRIPT)
        with open(args, "w") as f:
            json.dump({"src": os.path.abspath(a.passes), "w": w, "h": h, "runs": a.runs, "codecs": codecs,
                       "out": out, "compat": os.path.join(ROOT, "addon", "libfx", "compat.py")}, f)
        r = subprocess.run(blender_cmd(a.blender) + ["-b", "--factory-startup", "--python", script, "--", args],
                           capture_output=True, text=True)
    res = None
    for line in r.stdout.splitlines():
        if line.startswith("RESULT "):
            res = json.loads(line[7:])
    if res is None:
        raise SystemExit("blender printed no result:\n" + r.stdout[-3000:] + r.stderr[-2000:])
    recipe = a.recipe
    if not recipe:
        recipe = os.path.join(out, "empty.json")
        with open(recipe, "w") as f:
            json.dump({"version": 1, "effects": []}, f)
    print("| codec | Blender write ms | libfx read ms | write + read ms | file MB |")
    print("|---|---:|---:|---:|---:|")
    for c in codecs:
        path = [os.path.join(out, n) for n in sorted(os.listdir(out)) if n.startswith(c + "_") and n.endswith(".exr")]
        if not path:
            print("| %s | no file written |  |  |  |" % c)
            continue
        reads = []
        for _ in range(a.runs):
            v = subprocess.run([a.cli, "run", "-v", "-j", "2", "--force", "--quiet", "--compression", "none",
                                "--stack", recipe, path[-1], "-o", os.path.join(out, "o.exr")],
                               capture_output=True, text=True)
            for line in v.stdout.splitlines():
                if ": read " in line:
                    reads.append(float(line.split(": read ")[1].split(" s")[0]) * 1e3)
        wr = max(res[c] - res["identity"], 0.0)
        rd = statistics.median(reads) if reads else float("nan")
        print("| %s | %.0f | %.0f | %.0f | %.1f |" % (c, wr, rd, wr + rd, os.path.getsize(path[-1]) / 1e6))
    print("\n%dx%d, %s Blender, %d runs; identity tree render() %.0f ms" % (w, h, a.blender, a.runs, res["identity"]))


if __name__ == "__main__":
    main()
