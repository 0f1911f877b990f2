"""Headless batch runner: renders frames and applies the scene's libfx stack.

    blender -b scene.blend --python addon/libfx/batch.py -- \\
        --frames 1-2 --output /path/prefix_ --resolution 320x180 --samples 4 \\
        [--recipe r.json] [--quality final] [--threads 0] [--skip-existing]

Blender exits 0 even when a handler raises (GUIDE §3); this runner exits 1 if
any frame's stack failed (the message names the frame and the effect), 2 on a
usage or setup error, 0 when every frame was written.

Per frame it writes, beside the output prefix:
  <prefix>####.<ext>               Blender's own render (as the scene is set up)
  <prefix>libfx_passes.####.exr    the passes the stack needs (File Output node)
  <prefix>libfx.####.exr           the result: Combined + the passes + camera attributes
  <prefix>libfx.####.<ext>         the result in the scene's format (if not EXR)
  <prefix>libfx.####.camera.json   the camera sidecar (for `libfx run --camera`)
  <prefix>libfx_recipe.json        the recipe that ran
"""

import argparse
import os
import sys

import bpy


def _argv():
    argv = sys.argv
    return argv[argv.index("--") + 1:] if "--" in argv else []


def parse_frames(text, scene):
    if not text:
        return list(range(scene.frame_start, scene.frame_end + 1, max(1, scene.frame_step)))
    frames = []
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        if "-" in part[1:]:
            a, b = part[1:].split("-", 1)
            a = part[0] + a
            lo, hi = int(a), int(b)
            if hi < lo:
                raise ValueError("frame range %s runs backwards" % part)
            frames.extend(range(lo, hi + 1))
        else:
            frames.append(int(part))
    return frames


def parse_args(argv):
    ap = argparse.ArgumentParser(prog="blender -b scene.blend --python batch.py --",
                                 description="Render frames and apply the libfx stack.")
    ap.add_argument("--frames", help="e.g. 1-8 or 1,3,5-7 (default: the scene's range)")
    ap.add_argument("--output", help="output path prefix (default: the scene's)")
    ap.add_argument("--resolution", help="WxH at 100%%, e.g. 320x180")
    ap.add_argument("--samples", type=int, help="render samples")
    ap.add_argument("--recipe", help="recipe .json replacing the scene's stack")
    ap.add_argument("--quality", help="stack quality preset (draft, preview, final, reference)")
    ap.add_argument("--threads", type=int, help="libfx worker threads (0: one per core)")
    ap.add_argument("--skip-existing", action="store_true",
                    help="skip frames whose libfx outputs exist already")
    return ap.parse_args(argv)


def enable_addon():
    """The add-on module: the installed one if enabled, else this source tree's."""
    mod = sys.modules.get("libfx")
    if mod is not None and getattr(bpy.types.Scene, "libfx", None) is not None:
        return mod
    here = os.path.dirname(os.path.abspath(__file__))
    parent = os.path.dirname(here)
    if parent not in sys.path:
        sys.path.insert(0, parent)
    import libfx  # noqa: the package this file lives in
    libfx.register()
    # The .blend was loaded before the add-on existed: import its recipe text now.
    libfx.render.on_load_post()
    return libfx


def die(msg, code=2):
    sys.stdout.flush()
    print("libfx batch: error: " + msg, file=sys.stderr)
    sys.stderr.flush()
    os._exit(code)


def main():
    args = parse_args(_argv())
    fx = enable_addon()
    scene = bpy.context.scene
    if fx.props.catalog() is None or not fx.props.catalog().ok:
        die(fx.native.load_error() or "libfx library unavailable")
    r = scene.render
    if args.output:
        r.filepath = args.output
    if args.resolution:
        try:
            w, h = (int(v) for v in args.resolution.lower().split("x"))
        except ValueError:
            die("--resolution wants WxH, got %r" % args.resolution)
        r.resolution_x, r.resolution_y, r.resolution_percentage = w, h, 100
    if args.samples:
        if r.engine == "CYCLES":
            scene.cycles.samples = args.samples
        elif hasattr(scene, "eevee"):
            scene.eevee.taa_render_samples = args.samples
    if args.recipe:
        try:
            with open(args.recipe, encoding="utf-8") as f:
                fx.recipe.from_recipe(scene, f.read())
        except (OSError, ValueError, fx.native.LibfxError) as e:
            die("recipe %s: %s" % (args.recipe, e))
    if args.quality:
        if args.quality not in fx.props.catalog().qualities:
            die("--quality must be one of %s" % ", ".join(fx.props.catalog().qualities))
        scene.libfx.quality = args.quality
    if args.threads is not None:
        scene.libfx.threads = args.threads
    if not fx.scene_setup.has_stack(scene):
        die("scene '%s' has no enabled libfx effect (no stack, no %s text, no --recipe)"
            % (scene.name, fx.recipe.TEXT_NAME))
    fx.scene_setup.sync(scene)
    st = fx.scene_setup.status(scene)
    if st.get("error"):
        die("the stack cannot run: %s" % st["error"], 1)
    for w in st.get("warnings", []):
        print("libfx batch: warning: " + w, file=sys.stderr)
    try:
        frames = parse_frames(args.frames, scene)
    except ValueError as e:
        die("--frames: %s" % e)

    print("libfx batch: scene '%s', frames %s, %dx%d, passes %s" % (
        scene.name, args.frames or "%d-%d" % (scene.frame_start, scene.frame_end),
        r.resolution_x, r.resolution_y, ", ".join(st.get("passes", []))))
    sys.stdout.flush()
    failures = []
    # The aux views cover the camera over the scene's whole range (and the frames asked
    # for), so every frame and every later run can reuse them.
    span = sorted(set(frames) | set(range(scene.frame_start, scene.frame_end + 1)))
    for frame in frames:
        paths = fx.scene_setup.result_paths(scene, frame)
        wanted = [paths["exr"]] + ([paths["image"]] if fx.scene_setup.writes_image(scene) else [])
        if args.skip_existing and all(os.path.exists(p) for p in wanted):
            print("libfx batch: frame %d: exists, skipped" % frame)
            continue
        fx.render.RESULTS.pop((scene.name, frame), None)
        # Auxiliary views (light view, rain map) only when the stack needs them; reused
        # while light and geometry do not move.
        try:
            scene.frame_set(frame)
            aux = fx.aux_views.prepare(scene, span)
        except Exception as e:
            failures.append("frame %d: auxiliary views: %s" % (frame, e))
            continue
        with fx.render._lock:
            fx.render.AUX[(scene.name, frame)] = aux
        # A one-frame animation: Blender numbers the file (a still would not) and
        # frame_change_post gives this frame's camera.
        scene.frame_start = scene.frame_end = frame
        bpy.ops.render.render(animation=True)
        rec = fx.render.RESULTS.get((scene.name, frame))
        if rec is None:
            failures.append("frame %d: the stack did not run (no render_post)" % frame)
        elif not rec["ok"]:
            failures.append("frame %d: %s" % (frame, rec["error"]))
        else:
            missing = [p for p in wanted if not os.path.exists(p)]
            if missing:
                failures.append("frame %d: not written: %s" % (frame, ", ".join(missing)))
        sys.stdout.flush()
    if failures:
        die("%d of %d frame(s) failed:\n  %s" % (len(failures), len(frames), "\n  ".join(failures)), 1)
    print("libfx batch: %d frame(s) done" % len(frames))
    sys.stdout.flush()


if __name__ == "__main__":
    try:
        main()
    except SystemExit as e:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(e.code if isinstance(e.code, int) else 2)
    except BaseException:
        import traceback
        traceback.print_exc()
        die("unexpected error (traceback above)")
