"""Frame lists, with no Blender in them: the batch runner's `--frames` notation.

Shared by the batch runner (batch.py, inside Blender) and the farm submitters
(farm/slurm/libfx_slurm.py, plain Python on a login node), so a frame list means the
same thing wherever it is written. Both load this file by its path, without the add-on
package (whose __init__ needs bpy).
"""


def parse_frame_list(text):
    """'1-3', '1,3,5-7', '2..4' (Blender's notation) -> frames in order, each once.
    Raises ValueError naming the bad part."""
    def number(s, part):
        try:
            return int(s)
        except ValueError:
            raise ValueError("'%s' is not a frame or a range A-B (e.g. 1-8 or 1,3,5-7)" % part) from None

    frames = []
    for part in text.replace("..", "-").split(","):
        part = part.strip()
        if not part:
            continue
        if "-" in part[1:]:   # part[0] may be a minus sign
            a, b = part[1:].split("-", 1)
            lo, hi = number(part[0] + a, part), number(b, part)
            if hi < lo:
                raise ValueError("range '%s' runs backwards" % part)
            frames.extend(range(lo, hi + 1))
        else:
            frames.append(number(part, part))
    if not frames:
        raise ValueError("'%s' names no frame" % text)
    return list(dict.fromkeys(frames))


def format_frame_list(frames):
    """The shortest text parse_frame_list reads back as ``frames`` (runs of consecutive
    frames as A-B): [1, 2, 3, 7] -> '1-3,7'."""
    parts = []
    i = 0
    while i < len(frames):
        j = i
        while j + 1 < len(frames) and frames[j + 1] == frames[j] + 1:
            j += 1
        parts.append(str(frames[i]) if i == j else "%d-%d" % (frames[i], frames[j]))
        i = j + 1
    return ",".join(parts)


def chunks(frames, size):
    """``frames`` cut into consecutive pieces of ``size`` (the last may be shorter)."""
    if size < 1:
        raise ValueError("a chunk holds at least one frame, got %d" % size)
    return [frames[i:i + size] for i in range(0, len(frames), size)]
