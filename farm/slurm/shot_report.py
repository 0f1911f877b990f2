#!/usr/bin/env python3
"""The final job's report when a shot is not complete: for each frame the runner's check
names (`batch.py --check`, read on stdin), what its chunk's last attempt said.

    shot_report.py LOGDIR ADDON LABEL:FRAMES [LABEL:FRAMES...] < check.out

LABEL is a chunk's first-last (its log is LOGDIR/chunk_LABEL.log), FRAMES its frame list,
read by the runner's own parser (ADDON/frames.py). Nothing here decides whether a frame is done: the runner's check did;
this only joins each missing frame to its chunk's own lines: the runner's per-frame
failure, a usage error, or Slurm's note that the task was cancelled or ran out of time.
Prints one line per frame; exits 0 (the final job exits 1 itself).
"""

import glob
import importlib.util
import os
import re
import sys

HEADER = re.compile(r"^== libfx slurm: job (\d+)_(\d+) on (\S+) at (\S+): frames (\S+)")
END = re.compile(r"^== libfx slurm: chunk \S+ exit (\d+)")
FAILED_FRAME = re.compile(r"^\s*frame (-?\d+): (.*)")


def load_frames_module(addon):
    spec = importlib.util.spec_from_file_location("libfx_frames", os.path.join(addon, "frames.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def last_attempt(path):
    """(job id 'A_T', node, lines of the last attempt, exit status or None)."""
    try:
        with open(path, errors="replace") as f:
            lines = f.read().splitlines()
    except FileNotFoundError:
        return None
    start = max((i for i, l in enumerate(lines) if HEADER.match(l)), default=None)
    if start is None:
        return None
    m = HEADER.match(lines[start])
    body = lines[start + 1:]
    end = next((int(END.match(l).group(1)) for l in body if END.match(l)), None)
    return "%s_%s" % (m.group(1), m.group(2)), m.group(3), body, end


def slurm_note(logdir, job):
    """Slurm's own last word on the task (cancelled, time limit, node failure), if any."""
    for p in glob.glob(os.path.join(logdir, "slurm-%s.out" % job)):
        with open(p, errors="replace") as f:
            notes = [l.strip() for l in f if "***" in l or "error" in l.lower()]
        if notes:
            return notes[-1]
    return None


def why(logdir, label, frame):
    att = last_attempt(os.path.join(logdir, "chunk_%s.log" % label))
    if att is None:
        return "chunk %s never started (queued, held, or its job was cancelled before it ran)" % label
    job, node, body, end = att
    where = "chunk %s (job %s on %s)" % (label, job, node)
    if end is None:
        note = slurm_note(logdir, job)
        return "%s did not finish: %s" % (where, note or "killed (cancelled, time limit or node lost)")
    in_errors = False
    usage = None
    for l in body:
        if l.startswith("libfx batch: error:"):
            in_errors = True
            usage = l[len("libfx batch: error:"):].strip()
            continue
        m = FAILED_FRAME.match(l) if in_errors else None
        if m and int(m.group(1)) == frame:
            return "%s exit %d: frame %s: %s" % (where, end, m.group(1), m.group(2))
    if usage and end == 2:
        return "%s exit 2 before rendering: %s" % (where, usage)
    return "%s exit %d without a line for this frame (see its log)" % (where, end)


def main():
    logdir, addon, specs = sys.argv[1], sys.argv[2], sys.argv[3:]
    parse = load_frames_module(addon).parse_frame_list
    chunk_of = {}
    for item in specs:
        label, frames = item.split(":", 1)
        for f in parse(frames):
            chunk_of[f] = label
    missing = []
    for line in sys.stdin:
        m = re.match(r"^\s+frame (-?\d+): (.*)", line)
        if m:
            missing.append((int(m.group(1)), m.group(2)))
    print("libfx slurm: %d frame(s) incomplete:" % len(missing))
    for frame, state in missing:
        label = chunk_of.get(frame)
        print("  frame %d: %s; %s" % (frame, state, why(logdir, label, frame) if label else "in no chunk"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
