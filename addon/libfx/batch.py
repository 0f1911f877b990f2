"""Headless batch runner: renders frames and applies the scene's libfx stack.

    blender -b scene.blend --python addon/libfx/batch.py -- \\
        --frames 1-2 --output /path/prefix_ --resolution 320x180 --samples 4 \\
        [--recipe r.json] [--quality final] [--threads 0] [--skip-existing]
        [--keep-passes] [--passes-codec NONE|RLE|ZIP]
    blender -b scene.blend --python addon/libfx/batch.py -- --check --frames 1-12 --output P \\
        [--contact-sheet P_sheet.png]
    blender -b scene.blend --python addon/libfx/batch.py -- --views-only --frames 5 [--output P]

Blender exits 0 even when a handler raises (GUIDE §3); this runner exits 1 if
any frame's stack failed (the message names the frame and the effect), 2 on a
usage or setup error, 0 when every frame was written.  The contract a render
farm relies on (docs/farm.md; tests/blender/test_batch_contract.py):

- frames in, one result per frame: ``--frames 1-3`` / ``1,3`` / ``2-3`` writes
  <prefix>libfx.0001.exr ... and nothing for other frames; a bad range exits 2
  before anything renders;
- a frame's result exists only when that frame succeeded: its old results (and
  temporary files an interrupted writer left) are removed before it renders and
  after it fails; the library writes temp + rename, so no partial file appears;
- ``--skip-existing`` skips a frame only when its results are complete (the
  EXR reads back whole, the image loads), so a re-queued chunk renders only what
  is missing or damaged.

Per frame it writes, beside the output prefix:
  <prefix>####.<ext>               Blender's own render (as the scene is set up)
  <prefix>libfx_passes.####.exr    with --keep-passes: the render's passes (from the Render
                                   Result); without, they go to RAM (/dev/shm) when there
                                   is room and are removed once the result is written
  <prefix>libfx.####.exr           the result: Combined + the passes + camera attributes
  <prefix>libfx.####.<ext>         the result in the scene's format (if not EXR)
  <prefix>libfx.####.camera.json   the scene sidecar: camera, lights, time, aux views
                                   (for `libfx run --sidecar`; the file keeps its old name)
  <prefix>libfx_recipe.json        the recipe that ran
"""

import argparse
import glob
import importlib
import importlib.util
import os
import sys

import bpy


def _argv():
    argv = sys.argv
    return argv[argv.index("--") + 1:] if "--" in argv else []


def _load_frames():
    """frames.py beside this file, loaded by path: the runner runs as a script, before
    the add-on package (and with it bpy's registration) is imported."""
    spec = importlib.util.spec_from_file_location(
        "libfx_batch_frames", os.path.join(os.path.dirname(os.path.abspath(__file__)), "frames.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


parse_frame_list = _load_frames().parse_frame_list


def parse_frames(text, scene):
    if not text:
        return list(range(scene.frame_start, scene.frame_end + 1, max(1, scene.frame_step)))
    return parse_frame_list(text)


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
    ap.add_argument("--keep-passes", action="store_true",
                    help="keep each frame's passes file (default: removed once the result, "
                         "which holds the same passes, is written)")
    ap.add_argument("--passes-codec", choices=("NONE", "RLE", "ZIP"),
                    help="EXR codec of the passes file (default: the scene's, NONE: fastest)")
    ap.add_argument("--views-only", action="store_true",
                    help="render only the extra views the stack reads (light views, rain map, probes, "
                         "planar views) for --frames, beside the output, and exit: the panel's Render "
                         "Views runs this in a background Blender so the UI never waits for Cycles")
    ap.add_argument("--check", action="store_true",
                    help="render nothing: check that every frame of --frames has complete results "
                         "(the test --skip-existing makes); one line per frame that has not, exit 1 "
                         "if any (a farm's final job runs this)")
    ap.add_argument("--contact-sheet", metavar="PNG",
                    help="with --check, when every frame is complete: write the frames' results "
                         "as thumbnails on one PNG (at most 48, evenly spaced)")
    return ap.parse_args(argv)


def enable_addon():
    """The add-on module: the one Blender has enabled (the legacy add-on 'libfx' or
    the extension 'bl_ext.<repository>.libfx'), else this source tree's, registered."""
    if getattr(bpy.types.Scene, "libfx", None) is not None:
        for name in sorted(sys.modules):
            mod = sys.modules[name]
            if (name == "libfx" or (name.startswith("bl_ext.") and name.endswith(".libfx"))) \
                    and hasattr(mod, "handlers"):
                return mod
    here = os.path.dirname(os.path.abspath(__file__))
    parent = os.path.dirname(here)
    # An installed 4.2+ extension not enabled in this session (--factory-startup): enable
    # it as Blender names it, bl_ext.<repository>.libfx, so that a top-level 'libfx'
    # stays the wheel that carries its library, not this add-on put on sys.path.
    repo = sys.modules.get("bl_ext." + os.path.basename(parent))
    if repo is not None and any(os.path.realpath(p) == os.path.realpath(parent)
                                for p in getattr(repo, "__path__", [])):
        import addon_utils
        name = "%s.%s" % (repo.__name__, os.path.basename(here))
        mod = addon_utils.enable(name, default_set=False)
        if mod is None:
            die("cannot enable the extension %s (see the messages above)" % name)
        mod.handlers.on_load_post()
        return mod
    if parent not in sys.path:
        sys.path.insert(0, parent)
    import libfx  # noqa: the package this file lives in
    libfx.register()
    # The .blend was loaded before the add-on existed: import its recipe text now.
    libfx.handlers.on_load_post()
    return libfx


def die(msg, code=2):
    sys.stdout.flush()
    print("libfx batch: error: " + msg, file=sys.stderr)
    sys.stderr.flush()
    os._exit(code)


def say(msg):
    print("libfx batch: " + msg)
    sys.stdout.flush()


# ---------------------------------------------------------------- one result per frame

def result_files(fx, scene, frame, with_image):
    """(the files whose completeness means 'frame done': the EXR, and the image in
    the scene's format when it is not EXR; all of the frame's result paths)."""
    paths = fx.scene_setup.result_paths(scene, frame)
    return [paths["exr"]] + ([paths["image"]] if with_image else []), paths


def unfinished(fx, ctx, files):
    """None when every file is complete, else why not. A result is complete when
    the EXR reads back whole (every chunk: a truncated file fails) and the image
    loads; files of an older, interrupted run are not counted as finished."""
    for p in files:
        if not os.path.isfile(p):
            return "%s is missing" % p
    try:
        fx.native.Frame.read(ctx, files[0]).close()
    except fx.native.LibfxError as e:
        return "%s is damaged or incomplete: %s" % (files[0], e)
    for p in files[1:]:
        img = bpy.data.images.load(p, check_existing=False)
        try:
            if tuple(img.size) == (0, 0):
                return "%s is damaged or incomplete (Blender cannot load it)" % p
        finally:
            bpy.data.images.remove(img)
    return None


def discard(paths):
    """Removes a frame's results and the temporary files an interrupted writer left
    (the library writes '<dir>/.<name>.tmp-<pid>-<n>' and renames it when complete;
    the sidecar goes through '<name>.tmp')."""
    # "camera": how an add-on older than this runner names the sidecar
    for key in ("exr", "image", "sidecar" if "sidecar" in paths else "camera"):
        p = paths[key]
        d, name = os.path.split(p)
        for q in [p, p + ".tmp"] + glob.glob(os.path.join(d, "." + glob.escape(name) + ".tmp-*")):
            try:
                os.remove(q)
            except FileNotFoundError:
                pass


def check_usage(args):
    """The options that need no scene, checked before anything renders (a farm's wrong
    command must fail at once): (frames or None for the scene's range, (w, h) or None)."""
    if args.contact_sheet and not args.check:
        die("--contact-sheet goes with --check (the sheet is made once every frame is complete)")
    frames = None
    if args.frames is not None:
        try:
            frames = parse_frame_list(args.frames)
        except ValueError as e:
            die("--frames %s: %s" % (args.frames, e))
    size = None
    if args.resolution:
        try:
            size = tuple(int(v) for v in args.resolution.lower().split("x"))
            if len(size) != 2 or min(size) < 1:
                raise ValueError
        except ValueError:
            die("--resolution wants WxH, got %r" % args.resolution)
    if args.samples is not None and args.samples < 1:
        die("--samples wants a positive number, got %d" % args.samples)
    return frames, size


def open_addon():
    """The add-on, enabled, on a Blender it supports, with its library loaded."""
    fx = enable_addon()
    problem = fx.compat.version_problem()
    if problem:
        die(problem)
    if fx.props.catalog() is None or not fx.props.catalog().ok:
        die(fx.native.load_error() or "libfx library unavailable")
    return fx


def apply_overrides(fx, scene, args, size):
    """The command line's output, size, samples, recipe and stack settings, on the scene."""
    r = scene.render
    if args.output:
        r.filepath = args.output
    if size:
        r.resolution_x, r.resolution_y, r.resolution_percentage = size[0], size[1], 100
    if args.samples:
        fx.compat.set_render_samples(scene, args.samples)
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
    if args.keep_passes:
        scene.libfx.keep_passes = True
    if args.passes_codec:
        scene.libfx.passes_codec = args.passes_codec


def check_scene(fx, scene, args):
    """The scene can run its stack: a stack, a camera, an output path, the passes set up.
    Returns the status of the pass sync (its "passes")."""
    if not fx.scene_setup.has_stack(scene):
        die("scene '%s' has no enabled libfx effect (no stack, no %s text, no --recipe)"
            % (scene.name, fx.recipe.TEXT_NAME))
    problem = fx.scene_setup.scene_problem(scene)
    if problem:
        die(problem)
    fx.scene_setup.sync(scene)
    st = fx.scene_setup.status(scene)
    if st.get("error"):
        die("the stack cannot run: %s" % st["error"], 1)
    for w in st.get("warnings", []):
        print("libfx batch: warning: " + w, file=sys.stderr)
    return st


def render_frame(fx, scene, frame, files, paths, span):
    """Renders one frame and runs its stack; None when its results are written, else why
    not (the frame's results are removed then)."""
    # From here until it succeeds the frame has no result: never an older one.
    discard(paths)
    fx.results.forget(scene.name, frame)
    # Auxiliary views (light view, rain map) only when the stack needs them; reused
    # while light and geometry do not move.
    try:
        scene.frame_set(frame)
        aux = fx.aux_views.prepare(scene, span)
    except Exception as e:
        return "frame %d: auxiliary views: %s" % (frame, e)
    fx.sidecars.set_aux(scene.name, frame, aux)
    # A one-frame animation: Blender numbers the file (a still would not) and
    # frame_change_post gives this frame's scene sidecar.
    scene.frame_start = scene.frame_end = frame
    try:
        bpy.ops.render.render(animation=True)
    except RuntimeError as e:
        discard(paths)
        return "frame %d: Blender's render failed: %s" % (frame, str(e).strip())
    rec = fx.results.get(scene.name, frame)
    failed = None
    if rec is None:
        failed = "frame %d: the stack did not run (no render_post)" % frame
    elif not rec["ok"]:
        failed = "frame %d: %s" % (frame, rec["error"])
    else:
        missing = [p for p in files if not os.path.exists(p)]
        if missing:
            failed = "frame %d: not written: %s" % (frame, ", ".join(missing))
    if failed:
        discard(paths)
    return failed


def render_frames(fx, scene, frames, skip_existing):
    """Every frame asked for, in order: (failures, frames skipped as complete)."""
    with_image = fx.scene_setup.writes_image(scene)
    failures = []
    skipped = 0
    check_ctx = fx.native.Context(1) if skip_existing else None
    # The aux views cover the camera over the scene's whole range (and the frames asked
    # for), so every frame and every later run can reuse them.
    span = sorted(set(frames) | set(range(scene.frame_start, scene.frame_end + 1)))
    try:
        for frame in frames:
            files, paths = result_files(fx, scene, frame, with_image)
            if skip_existing:
                why = unfinished(fx, check_ctx, files)
                if why is None:
                    say("frame %d: exists, skipped" % frame)
                    skipped += 1
                    continue
                if os.path.exists(files[0]) or any(os.path.exists(p) for p in files[1:]):
                    say("frame %d: %s: rendering it again" % (frame, why))
            failed = render_frame(fx, scene, frame, files, paths, span)
            if failed:
                failures.append(failed)
            sys.stdout.flush()
    finally:
        if check_ctx is not None:
            check_ctx.close()
    return failures, skipped


def check_frames(fx, scene, frames, sheet):
    """--check: exits 1 listing each frame whose results are not complete (nothing is
    rendered or removed); when all are, writes the contact sheet if asked and returns."""
    with_image = fx.scene_setup.writes_image(scene)
    with fx.native.Context(0) as ctx:
        incomplete = []
        for frame in frames:
            why = unfinished(fx, ctx, result_files(fx, scene, frame, with_image)[0])
            if why is not None:
                incomplete.append("frame %d: %s" % (frame, why))
        if incomplete:
            die("check: %d of %d frame(s) incomplete:\n  %s"
                % (len(incomplete), len(frames), "\n  ".join(incomplete)), 1)
        say("check: all %d frame(s) complete" % len(frames))
        if sheet:
            mod = importlib.import_module(fx.__name__ + ".contact_sheet")
            try:
                shown = mod.write(fx, ctx, scene, frames, sheet)
            except (OSError, RuntimeError, fx.native.LibfxError) as e:
                die("contact sheet %s: %s" % (sheet, e), 1)
            say("contact sheet: %d frame(s) -> %s" % (len(shown), sheet))


def render_views(fx, scene, frames):
    """--views-only: the aux views for the frames (as the panel's Render Views makes them for
    the current frame); one line "libfx batch: views: N ready: names" on success, exit 1 when
    a view fails to render."""
    scene.frame_set(frames[0])
    try:
        views = fx.aux_views.prepare(scene, frames)
    except Exception as e:   # a failed Cycles render, an unwritable folder
        die("views: %s" % e, 1)
    say("views: %d ready: %s" % (len(views), ", ".join(v["name"] for v in views)) if views
        else "views: none (the stack reads no auxiliary view)")


def main():
    args = parse_args(_argv())
    frames, size = check_usage(args)
    fx = open_addon()
    scene = bpy.context.scene
    loaded = fx.scene_setup.status(scene).get("error")
    if loaded and not args.recipe:
        die("scene '%s': %s" % (scene.name, loaded))
    apply_overrides(fx, scene, args, size)
    if frames is None:
        frames = parse_frames(None, scene)
    if args.check:
        check_frames(fx, scene, frames, args.contact_sheet)
        return
    st = check_scene(fx, scene, args)
    r = scene.render
    say("scene '%s', frames %s, %dx%d, passes %s" % (
        scene.name, args.frames or "%d-%d" % (scene.frame_start, scene.frame_end),
        r.resolution_x, r.resolution_y, ", ".join(st.get("passes", []))))
    if args.views_only:
        render_views(fx, scene, frames)
        return
    failures, skipped = render_frames(fx, scene, frames, args.skip_existing)
    if failures:
        die("%d of %d frame(s) failed:\n  %s" % (len(failures), len(frames), "\n  ".join(failures)), 1)
    say("%d frame(s) done: %d rendered, %d skipped" % (len(frames), len(frames) - skipped, skipped))


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
