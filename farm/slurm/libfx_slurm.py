#!/usr/bin/env python3
"""Submits a shot to Slurm: one array task per chunk of frames, each running libfx's
batch runner with --skip-existing, and a final job that checks every frame and writes
the shot's contact sheet (docs/farm.md, "Slurm").

    libfx_slurm.py shot.blend --frames 1-2000 --chunk 10 --output /shared/renders/shot010/shot010_ \\
        [--resolution 1920x1080] [--samples 64] [--quality final] [--recipe look.json] [--threads 0] \\
        [--blender PATH] [--addon DIR] [--library PATH] [--partition NAME] \\
        [--cpus-per-task N] [--mem MB] [--time MINUTES] [--frame-seconds S] [--dry-run]

What it does not do: keep any record of which frame is done. The runner owns that
(docs/farm.md §1): a result exists exactly when its frame succeeded, and --skip-existing
re-renders only what is missing or damaged. So re-submitting the same command after a
cancelled task, a lost node or a fix finishes the shot, and the final job asks the runner
(`batch.py --check`) whether it is finished.

Files, beside the output prefix P (e.g. /shared/renders/shot010/shot010_):
  P<frame results>               what the runner writes (docs/farm.md §1)
  Pslurm/chunk_<first>-<last>.log   one log per chunk, named by its frames; each attempt
                                 appends, headed by its job id, node and time
  Pslurm/final.log               the final job's check and report
  Pslurm/slurm-<job>_<task>.out  Slurm's own messages for a task (a cancel, a time limit)
  Pslurm/chunk.sh, final.sh      the job scripts this command submitted
  Plibfx.contact_sheet.png       written by the final job once every frame is complete

Exit status: 0 submitted (job ids printed), 2 bad input, refused before anything is queued,
1 sbatch refused the jobs (its message printed).
"""

import argparse
import csv
import importlib.util
import math
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
# The defaults a shared-filesystem farm uses (docs/farm.md §3): Blender on every node's
# PATH, the add-on unpacked once on shared storage, its library in the add-on's lib/.
DEFAULT_BLENDER = "blender"
DEFAULT_ADDON = "/shared/software/libfx-addon/libfx"
SIZING = os.path.join(HERE, "chunk_cost.csv")
# A task's time limit is this many times its expected time: past the limit Slurm kills the
# task and its frame in flight is lost, so the limit guards against a hung task, not a slow one.
TIME_MARGIN = 3.0
MIN_TIME_MIN = 5
MEM_MARGIN = 1.5
BLEND_MAGIC = (b"BLENDER", b"\x1f\x8b", b"\x28\xb5\x2f\xfd")   # plain, gzip, zstd


class Refused(Exception):
    """Bad input: reported before anything is queued."""


def load_frames_module(addon):
    """The runner's own frame-list code (addon/libfx/frames.py), so --frames means here
    what it means to batch.py."""
    path = os.path.join(addon, "frames.py")
    spec = importlib.util.spec_from_file_location("libfx_frames", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def parse_args(argv):
    ap = argparse.ArgumentParser(
        prog="libfx_slurm.py", description="Submit a shot to Slurm: chunks of libfx's batch runner, "
        "then a job that checks the shot and writes its contact sheet.")
    ap.add_argument("blend", help="the .blend, on storage every node sees")
    ap.add_argument("--frames", required=True, help="e.g. 1-2000 or 1,3,5-7 (the runner's notation)")
    ap.add_argument("--chunk", type=int, required=True, help="frames per array task")
    ap.add_argument("--output", required=True, help="output prefix, e.g. /shared/renders/shot010/shot010_")
    run = ap.add_argument_group("passed to the batch runner")
    run.add_argument("--resolution", help="WxH at 100%%")
    run.add_argument("--samples", type=int)
    run.add_argument("--quality")
    run.add_argument("--recipe", help="recipe .json replacing the scene's stack")
    run.add_argument("--threads", type=int)
    paths = ap.add_argument_group("software on the nodes")
    paths.add_argument("--blender", default=DEFAULT_BLENDER,
                       help="Blender executable (default: %(default)s, from the nodes' PATH)")
    paths.add_argument("--addon", default=DEFAULT_ADDON,
                       help="the add-on folder holding batch.py (default: %(default)s)")
    paths.add_argument("--library", help="libfx library to load (default: the add-on's own lib/)")
    res = ap.add_argument_group("Slurm")
    res.add_argument("--job-name", help="default: the output prefix's file part, or the .blend's name")
    res.add_argument("--partition")
    res.add_argument("--cpus-per-task", type=int)
    res.add_argument("--mem", type=int, metavar="MB")
    res.add_argument("--time", type=int, metavar="MINUTES")
    res.add_argument("--frame-seconds", type=float,
                     help="seconds one frame takes on --cpus-per-task cores, measured on this shot "
                          "(default: from the measured cost of the demo scenes, scaled)")
    res.add_argument("--sizing", default=SIZING, metavar="CSV",
                     help="measured chunk costs (farm/measure_chunk_cost.sh's output; default: the demo "
                          "scenes' in %(default)s): measure your own shot with it for sizes that fit it")
    res.add_argument("--sbatch-arg", action="append", default=[], metavar="ARG",
                     help="one more sbatch option for both jobs (e.g. --account=fx); repeatable")
    ap.add_argument("--dry-run", action="store_true", help="print the sbatch commands, submit nothing")
    return ap.parse_args(argv)


# ---------------------------------------------------------------- checks before queueing

def check_input(args):
    """Everything that can be known wrong on the submitting machine. Returns the frames."""
    if not shutil.which("sbatch") and not args.dry_run:
        raise Refused("sbatch is not on PATH: this machine cannot submit to Slurm "
                      "(install slurm-client and point SLURM_CONF at the cluster's slurm.conf)")
    blend = args.blend
    if not os.path.isfile(blend):
        raise Refused("%s: no such .blend file" % blend)
    try:
        with open(blend, "rb") as f:
            head = f.read(7)
    except OSError as e:
        raise Refused("%s: cannot read it: %s" % (blend, e.strerror))
    if not head.startswith(BLEND_MAGIC):
        raise Refused("%s: not a .blend file (it does not start with Blender's header)" % blend)
    batch = os.path.join(args.addon, "batch.py")
    if not os.path.isfile(batch) or not os.path.isfile(os.path.join(args.addon, "frames.py")):
        raise Refused("--addon %s: no libfx add-on there (batch.py and frames.py missing)" % args.addon)
    if os.sep in args.blender or (os.altsep and os.altsep in args.blender):
        if not (os.path.isfile(args.blender) and os.access(args.blender, os.X_OK)):
            raise Refused("--blender %s: not an executable file" % args.blender)
    elif not shutil.which(args.blender):
        print("libfx_slurm: warning: '%s' is not on this machine's PATH; the nodes must have it"
              % args.blender, file=sys.stderr)
    if args.library and not os.path.isfile(args.library):
        raise Refused("--library %s: no such file" % args.library)
    if args.recipe and not os.path.isfile(args.recipe):
        raise Refused("--recipe %s: no such file" % args.recipe)
    if args.chunk < 1:
        raise Refused("--chunk %d: a chunk holds at least one frame" % args.chunk)
    try:
        frames = load_frames_module(args.addon).parse_frame_list(args.frames)
    except ValueError as e:
        raise Refused("--frames %s: %s" % (args.frames, e))
    if args.resolution and not re.fullmatch(r"[1-9][0-9]*x[1-9][0-9]*", args.resolution.lower()):
        raise Refused("--resolution wants WxH, got %r" % args.resolution)
    if args.samples is not None and args.samples < 1:
        raise Refused("--samples wants a positive number, got %d" % args.samples)
    for name in ("cpus_per_task", "mem", "time"):
        v = getattr(args, name)
        if v is not None and v < 1:
            raise Refused("--%s wants a positive number, got %d" % (name.replace("_", "-"), v))
    check_output_folder(args.output)
    return frames


def check_output_folder(prefix):
    """The prefix's folder exists (or can be made) and takes a new file."""
    folder = os.path.dirname(os.path.abspath(prefix))
    try:
        os.makedirs(folder, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".libfx_slurm-", dir=folder)
        os.close(fd)
        os.remove(probe)
    except OSError as e:
        raise Refused("--output %s: cannot write in %s: %s" % (prefix, folder, e.strerror or e))


def jobs_in_flight(name):
    """Ids of this shot's jobs still queued or running (a second submission while they
    run would render the same frames twice)."""
    try:
        out = subprocess.run(["squeue", "-h", "--name", name, "-o", "%i"], capture_output=True,
                             text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return []
    return out.stdout.split() if out.returncode == 0 else []


# ---------------------------------------------------------------- sizing

def read_sizing(path=SIZING):
    """Rows of farm/measure_chunk_cost.sh (its CSV with samples, cores and peak memory)."""
    with open(path, newline="") as f:
        return [r for r in csv.DictReader(line for line in f if line.strip() and not line.startswith("#"))]


def fit_line(xs, ys):
    """Least-squares y = a + b x (b >= 0; a flat line through the mean with one x)."""
    n = len(xs)
    mx, my = sum(xs) / n, sum(ys) / n
    sxx = sum((x - mx) ** 2 for x in xs)
    b = max(0.0, sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx) if sxx > 0 else 0.0
    return my - b * mx, b


def scene_model(rows, blend):
    """(scene name, rows) for the .blend: its own measured scene when it is one of the
    demo scenes, else the one whose frames cost most (an unknown shot is sized as the
    most expensive measured one; --frame-seconds replaces the guess with a measurement)."""
    scenes = sorted({r["scene"] for r in rows})
    stem = os.path.splitext(os.path.basename(blend))[0]
    if stem in scenes:
        return stem, [r for r in rows if r["scene"] == stem]

    def cost(s):
        return max(float(r["per_frame_s"]) for r in rows if r["scene"] == s)
    worst = max(scenes, key=cost)
    return worst, [r for r in rows if r["scene"] == worst]


def pixels(res):
    w, h = (int(v) for v in res.lower().split("x"))
    return w * h


def median(values):
    v = sorted(values)
    n = len(v)
    return v[n // 2] if n % 2 else (v[n // 2 - 1] + v[n // 2]) / 2


def medians_by_resolution(rows):
    """One point per measured (resolution, samples): the medians of its repeats, so a run
    slowed by other work on a shared machine does not tilt the fit."""
    groups = {}
    for r in rows:
        groups.setdefault((r["res"], int(r["samples"])), []).append(r)
    out = []
    for (res, spp), rs in sorted(groups.items()):
        out.append({"res": res, "samples": spp, "frames": int(rs[0]["frames"]), "cpus": int(rs[0]["cpus"]),
                    **{k: median(float(r[k]) for r in rs)
                       for k in ("per_frame_s", "fixed_s", "skip_all_s", "peak_rss_mb")}})
    return out


def size_task(args, nframes_per_chunk, rows):
    """--cpus-per-task, --mem (MB) and --time (minutes) for one chunk, the final job's
    check time per frame (s), and how they were derived. Per-frame time is fitted as
    a + b * pixels * samples over the measured points (Cycles' path tracing grows with
    both), scaled by measured cores / task cores; peak memory as a + b * pixels; the
    fixed cost per chunk is the measured median."""
    scene, rs = scene_model(rows, args.blend)
    pts = medians_by_resolution(rs)
    if len({pixels(p["res"]) for p in pts}) < 2:
        raise Refused("--sizing %s: scene %s was measured at one resolution; the fit needs two "
                      "(farm/measure_chunk_cost.sh 960x540,1920x1080 ...)" % (args.sizing, scene))
    cpus_measured = pts[0]["cpus"]
    cpus = args.cpus_per_task or cpus_measured
    res = args.resolution or max((p["res"] for p in pts), key=pixels)
    spp = args.samples or max(p["samples"] for p in pts)
    a, b = fit_line([pixels(p["res"]) * p["samples"] for p in pts], [p["per_frame_s"] for p in pts])
    per_frame = args.frame_seconds or (a + b * pixels(res) * spp) * cpus_measured / cpus
    fixed = median(p["fixed_s"] for p in pts)
    expected_s = fixed + nframes_per_chunk * per_frame
    minutes = args.time or max(MIN_TIME_MIN, math.ceil(TIME_MARGIN * expected_s / 60.0))
    ma, mb = fit_line([pixels(p["res"]) for p in pts], [p["peak_rss_mb"] for p in pts])
    peak = ma + mb * pixels(res)
    mem = args.mem or int(math.ceil(MEM_MARGIN * peak / 64.0) * 64)
    # The final job starts Blender once and reads every result back: a --skip-existing
    # pass over a finished chunk measures exactly that, start + frames x read(pixels).
    sa, sb = fit_line([pixels(p["res"]) for p in pts], [p["skip_all_s"] for p in pts])
    check = (max(sa, 0.0), sb * pixels(res) / pts[0]["frames"])
    how = ("sized from %s (%s, measured on %d cores): %.1f s per frame at %s and %d samples%s, "
           "%.1f s fixed per chunk -> %.0f s per %d-frame chunk; --time %d min (%.0fx), "
           "--mem %d MB (%.1fx the fitted peak of %.0f MB)" % (
               os.path.basename(args.sizing), scene, cpus_measured, per_frame, res, spp,
               " (--frame-seconds)" if args.frame_seconds else " on %d cores" % cpus,
               fixed, expected_s, nframes_per_chunk, minutes, TIME_MARGIN, mem, MEM_MARGIN, peak))
    return {"cpus": cpus, "mem": mem, "minutes": minutes, "how": how,
            # the views job: one Blender start and the auxiliary views, the fixed cost
            "views_minutes": max(MIN_TIME_MIN, math.ceil(TIME_MARGIN * fixed / 60.0)),
            "check": check}


# ---------------------------------------------------------------- the job scripts

def runner_options(args):
    opts = []
    for flag in ("resolution", "samples", "quality", "recipe", "threads"):
        v = getattr(args, flag)
        if v is not None:
            opts += ["--" + flag, os.path.abspath(v) if flag == "recipe" else str(v)]
    return opts


def blender_command(args, runner_args):
    return ([args.blender, "-b", "-y", "--factory-startup", os.path.abspath(args.blend),
             "--python-exit-code", "2", "--python", os.path.join(os.path.abspath(args.addon), "batch.py"), "--"]
            + runner_args)


def library_export(args):
    """The job scripts' line that points the add-on at --library (none: its own lib/)."""
    return "export LIBFX_LIBRARY=%s\n" % shlex.quote(os.path.abspath(args.library)) if args.library else ""


def chunk_label(frames):
    return "%04d-%04d" % (frames[0], frames[-1])


def chunk_script(args, chunk_frames, logdir, fr):
    """The array task: the chunk of index SLURM_ARRAY_TASK_ID, one runner call, its log
    appended to chunk_<first>-<last>.log, the runner's exit status as the task's."""
    lists = " ".join(shlex.quote(fr.format_frame_list(c)) for c in chunk_frames)
    labels = " ".join(chunk_label(c) for c in chunk_frames)
    cmd = blender_command(args, ["--frames", "$frames", "--output", os.path.abspath(args.output),
                                 "--skip-existing"] + runner_options(args))
    cmd_text = " ".join('"$frames"' if c == "$frames" else shlex.quote(c) for c in cmd)
    lib = library_export(args)
    return """#!/bin/bash
# One chunk of the shot (written by farm/slurm/libfx_slurm.py).
set -u
lists=({lists})
labels=({labels})
frames=${{lists[$SLURM_ARRAY_TASK_ID]}}
log={logdir}/chunk_${{labels[$SLURM_ARRAY_TASK_ID]}}.log
exec >>"$log" 2>&1
echo "== libfx slurm: job ${{SLURM_ARRAY_JOB_ID}}_${{SLURM_ARRAY_TASK_ID}} on $(hostname) at $(date -Iseconds): frames $frames"
{lib}{cmd}
rc=$?
echo "== libfx slurm: chunk $frames exit $rc at $(date -Iseconds)"
exit $rc
""".format(lists=lists, labels=labels, logdir=shlex.quote(logdir), lib=lib, cmd=cmd_text)


def views_script(args, frames, logdir, fr):
    """The views job: the auxiliary views the stack reads (light views, rain map, probes,
    planar views) for the whole shot, rendered once beside the output before the chunks,
    which then find them ready instead of each rendering its own (batch.py --views-only).
    A stack that reads none costs one Blender start."""
    cmd = blender_command(args, ["--views-only", "--frames", fr.format_frame_list(frames),
                                 "--output", os.path.abspath(args.output)] + runner_options(args))
    lib = library_export(args)
    return """#!/bin/bash
# The shot's auxiliary views (written by farm/slurm/libfx_slurm.py): before the chunks.
set -u
exec >>{log} 2>&1
echo "== libfx slurm: views job $SLURM_JOB_ID on $(hostname) at $(date -Iseconds)"
{lib}{cmd}
rc=$?
echo "== libfx slurm: views exit $rc at $(date -Iseconds)"
exit $rc
""".format(log=shlex.quote(os.path.join(logdir, "views.log")), lib=lib,
           cmd=" ".join(shlex.quote(c) for c in cmd))


def final_script(args, frames, chunk_frames, logdir, fr):
    """The final job: the runner's completeness check over every frame, with the contact
    sheet when complete; else a report of each missing frame with its chunk's own lines."""
    sheet = os.path.abspath(args.output) + "libfx.contact_sheet.png"
    check = blender_command(args, ["--check", "--frames", fr.format_frame_list(frames),
                                   "--output", os.path.abspath(args.output), "--contact-sheet", sheet])
    lib = library_export(args)
    chunks = ["%s:%s" % (chunk_label(c), fr.format_frame_list(c)) for c in chunk_frames]
    report = [sys.executable if os.path.isabs(sys.executable) else "python3",
              os.path.join(HERE, "shot_report.py"), logdir, os.path.abspath(args.addon)] + chunks
    return """#!/bin/bash
# The shot's final job (written by farm/slurm/libfx_slurm.py): runs after every chunk.
set -u
exec >>{log} 2>&1
echo "== libfx slurm: final job $SLURM_JOB_ID on $(hostname) at $(date -Iseconds)"
rm -f {sheet}
{lib}{check} >{logdir}/check.out 2>&1
rc=$?
grep '^libfx batch' {logdir}/check.out
if [ $rc -eq 0 ] && [ -s {sheet} ]; then
  echo "== libfx slurm: shot complete; contact sheet {sheet}"
  exit 0
fi
echo "== libfx slurm: shot NOT complete (check exit $rc)"
[ $rc -eq 1 ] || tail -n 30 {logdir}/check.out
{report} <{logdir}/check.out
exit 1
""".format(log=shlex.quote(os.path.join(logdir, "final.log")), sheet=shlex.quote(sheet), lib=lib,
           logdir=shlex.quote(logdir), check=" ".join(shlex.quote(c) for c in check),
           report=" ".join(shlex.quote(c) for c in report))


def write_script(path, text):
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        f.write(text)
    os.chmod(tmp, 0o755)
    os.replace(tmp, path)


def sbatch(argv, dry_run):
    print("libfx_slurm: " + " ".join(shlex.quote(a) for a in argv))
    if dry_run:
        return "DRYRUN"
    p = subprocess.run(argv, capture_output=True, text=True)
    if p.returncode != 0:
        sys.stderr.write(p.stderr)
        raise RuntimeError("sbatch refused the job (exit %d)" % p.returncode)
    return p.stdout.strip().split(";")[0]


def job_name(args):
    return args.job_name or os.path.basename(args.output.rstrip("_.-/")) \
        or os.path.splitext(os.path.basename(args.blend))[0]


def submit_jobs(args, name, frames, chunk_frames, size, logdir):
    """views -> chunks (array) -> final, each after the one before whatever its fate
    (afterany): chunks render a view themselves if the views job failed, and the final
    job reports whatever happened. Returns the three job ids."""
    common = ["--job-name", name, "--parsable"] + (["--partition", args.partition] if args.partition else []) \
        + args.sbatch_arg
    views = sbatch(["sbatch"] + common + [
        "--cpus-per-task", str(size["cpus"]), "--mem", str(size["mem"]), "--time", str(size["views_minutes"]),
        "--output", os.path.join(logdir, "slurm-%j.out"), os.path.join(logdir, "views.sh")], args.dry_run)
    array = sbatch(["sbatch"] + common + [
        "--dependency", "afterany:%s" % views,
        # --requeue: a task whose node fails runs again by itself (and resumes: the
        # runner skips finished frames); append: Slurm's note of why stays after it.
        "--array", "0-%d" % (len(chunk_frames) - 1), "--requeue", "--open-mode", "append",
        "--cpus-per-task", str(size["cpus"]), "--mem", str(size["mem"]), "--time", str(size["minutes"]),
        "--output", os.path.join(logdir, "slurm-%A_%a.out"), os.path.join(logdir, "chunk.sh")], args.dry_run)
    start, per_frame = size["check"]
    final = sbatch(["sbatch"] + common + [
        "--dependency", "afterany:%s" % array, "--cpus-per-task", "1", "--mem", str(size["mem"]),
        "--time", str(max(MIN_TIME_MIN, math.ceil(TIME_MARGIN * (start + len(frames) * per_frame) / 60))),
        "--output", os.path.join(logdir, "slurm-%j.out"), os.path.join(logdir, "final.sh")], args.dry_run)
    return views, array, final


def main(argv=None):
    args = parse_args(sys.argv[1:] if argv is None else argv)
    try:
        frames = check_input(args)
        if not os.path.isfile(args.sizing):
            raise Refused("--sizing %s: no such file" % args.sizing)
        name = job_name(args)
        busy = [] if args.dry_run else jobs_in_flight(name)
        if busy:
            raise Refused("jobs of '%s' are still queued or running (%s): let them finish or scancel "
                          "them before submitting the shot again" % (name, ", ".join(busy)))
        fr = load_frames_module(args.addon)
        chunk_frames = fr.chunks(frames, args.chunk)
        size = size_task(args, max(len(c) for c in chunk_frames), read_sizing(args.sizing))
    except Refused as e:
        print("libfx_slurm: error: %s" % e, file=sys.stderr)
        return 2
    logdir = os.path.abspath(args.output) + "slurm"
    os.makedirs(logdir, exist_ok=True)
    write_script(os.path.join(logdir, "views.sh"), views_script(args, frames, logdir, fr))
    write_script(os.path.join(logdir, "chunk.sh"), chunk_script(args, chunk_frames, logdir, fr))
    write_script(os.path.join(logdir, "final.sh"), final_script(args, frames, chunk_frames, logdir, fr))
    print("libfx_slurm: %d frame(s) in %d chunk(s) of up to %d; %s" % (
        len(frames), len(chunk_frames), args.chunk, size["how"]))
    try:
        views, array, final = submit_jobs(args, name, frames, chunk_frames, size, logdir)
    except RuntimeError as e:
        print("libfx_slurm: error: %s" % e, file=sys.stderr)
        return 1
    print("libfx_slurm: submitted job %s (auxiliary views), array job %s (chunks) and job %s "
          "(check, contact sheet); logs in %s" % (views, array, final, logdir))
    print("VIEWS_JOB=%s ARRAY_JOB=%s FINAL_JOB=%s" % (views, array, final))
    return 0


if __name__ == "__main__":
    sys.exit(main())
