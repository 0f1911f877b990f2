"""addon/libfx/frames.py: the frame lists the batch runner reads and the farm submitters
cut into chunks (no Blender, no cluster needed)."""
import importlib.util
import os
import random

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
spec = importlib.util.spec_from_file_location("frames", os.path.join(ROOT, "addon", "libfx", "frames.py"))
frames = importlib.util.module_from_spec(spec)
spec.loader.exec_module(frames)


@pytest.mark.parametrize("text, want", [
    ("1-3", [1, 2, 3]), ("1,3,5-7", [1, 3, 5, 6, 7]), ("2..4", [2, 3, 4]), ("3, 1, 3", [3, 1]),
    ("-2-1", [-2, -1, 0, 1]), ("7", [7])])
def test_parse(text, want):
    assert frames.parse_frame_list(text) == want


@pytest.mark.parametrize("text, message", [
    ("5-1", "runs backwards"), ("1-x", "is not a frame"), ("", "names no frame"), (",", "names no frame")])
def test_parse_refuses(text, message):
    with pytest.raises(ValueError, match=message):
        frames.parse_frame_list(text)


def test_format_reads_back():
    assert frames.format_frame_list([1, 2, 3, 7]) == "1-3,7"
    assert frames.format_frame_list([4, 5]) == "4-5"
    assert frames.format_frame_list([-1, 0, 1, 9, 11]) == "-1-1,9,11"
    rng = random.Random(7)
    for _ in range(200):
        fs = sorted(rng.sample(range(-20, 200), rng.randint(1, 40)))
        assert frames.parse_frame_list(frames.format_frame_list(fs)) == fs


def test_chunks_cover_each_frame_once_in_order():
    fs = frames.parse_frame_list("1-10,20,31-40")
    for size in (1, 3, 4, 21, 100):
        cs = frames.chunks(fs, size)
        assert [f for c in cs for f in c] == fs
        assert all(1 <= len(c) <= size for c in cs) and all(len(c) == size for c in cs[:-1])
    with pytest.raises(ValueError):
        frames.chunks(fs, 0)
