"""Helpers for the Blender add-on tests: `blender -b` driven from Debian's Python.

    /usr/bin/python3 -m pytest tests/blender

Needs /usr/bin/blender (or $BLENDER), the built library ($LIBFX_LIBRARY, else
build/libfx/libfx.so, else build-addon/libfx/libfx.so) and, for the comparison with
the CLI, the `libfx` tool ($LIBFX_CLI, else beside the library).  Renders are tiny
(320x180, 4 samples) so the whole directory runs in a few minutes on 2 cores.
"""
import json
import os
import re
import pathlib
import shutil
import struct
import subprocess

import numpy as np
import pytest

try:
    import OpenImageIO as oiio
except ImportError:  # pragma: no cover
    oiio = None

REPO = pathlib.Path(__file__).resolve().parents[2]
ADDON_DIR = REPO / "addon"
BATCH = ADDON_DIR / "libfx" / "batch.py"
SCENES_DIR = REPO / "blend_scenes"


def blender_path():
    return os.environ.get("BLENDER") or shutil.which("blender") or "/usr/bin/blender"


def library_path():
    env = os.environ.get("LIBFX_LIBRARY")
    if env:
        return pathlib.Path(env)
    for build in ("build", "build-addon"):
        p = REPO / build / "libfx" / "libfx.so"
        if p.exists():
            return p
    return REPO / "build" / "libfx" / "libfx.so"


def cli_path():
    env = os.environ.get("LIBFX_CLI")
    if env:
        return pathlib.Path(env)
    return library_path().parent / "libfx"


def scenes():
    """Every blend_scenes/<scene>/<scene>.blend that exists now."""
    if not SCENES_DIR.is_dir():
        return []
    out = []
    for d in sorted(SCENES_DIR.iterdir()):
        blend = d / (d.name + ".blend")
        if blend.is_file():
            out.append(blend)
    return out


def run_blender(args, env=None, timeout=240, blend=None, python=None, python_expr=None,
                script_args=None, factory=True):
    """Runs `blender -b` and returns the CompletedProcess (text output)."""
    cmd = [blender_path(), "-b"]
    if factory:
        cmd.append("--factory-startup")
    if blend:
        cmd.append(str(blend))
    cmd += ["--python-exit-code", "3"]
    if python_expr:  # runs first: scene set-up before a --python script
        cmd += ["--python-expr", python_expr]
    if python:
        cmd += ["--python", str(python)]
    cmd += list(args)
    if script_args is not None:
        cmd += ["--"] + [str(a) for a in script_args]
    e = dict(os.environ)
    e.update(env or {})
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=e)


_TB_FILE = re.compile(r'^\s*File "([^"]+)"', re.M)
#: Where Blender keeps its own scripts and Python: a traceback only through these is
#: Blender's (5.2's bundled extensions add-on fails to import 'cattrs' at every start).
_BLENDER_OWN = ("/usr/share/blender/", "/usr/lib/python3")


def tracebacks(text):
    """The Python tracebacks in Blender's output that pass through libfx's or the
    tests' code (a frame outside Blender's own scripts); Blender's start-up noise
    from its bundled add-ons is left out."""
    out = []
    for block in re.split(r"(?=Traceback \(most recent call last\):)", text)[1:]:
        lines = block.splitlines()
        end = next((i for i, l in enumerate(lines[1:], 1) if l and not l.startswith(" ")), len(lines) - 1)
        block = "\n".join(lines[:end + 1])
        files = _TB_FILE.findall(block)
        if not files or any(not f.startswith(_BLENDER_OWN) for f in files):
            out.append(block)
    return out


def addon_env(library):
    return {"LIBFX_LIBRARY": str(library), "PYTHONDONTWRITEBYTECODE": "1"}


#: Prelude for --python-expr scripts: the add-on from this source tree, registered.
PRELUDE = (
    "import sys, json, bpy\n"
    "sys.path.insert(0, %r)\n"
    "import libfx\n"
    "libfx.register()\n" % str(ADDON_DIR))

# Script text: a fake panel layout that records the labels ui.draw_stack() draws, in `lay`.
FAKE_LAYOUT = """
class L:
    def __init__(s): s.labels = []
    def __getattr__(s, n): return lambda *a, **k: s
    def label(s, text='', **k): s.labels.append(text)
    def box(s): return s
    def row(s, **k): return s
    def column(s, **k): return s
lay = L()
"""


def need_oiio():
    if oiio is None:
        pytest.skip("python3-openimageio is not installed")


# ---------------------------------------------------------------- EXR helpers

#: Blender 5.x names these passes in its render output (the Render Result the add-on saves)
#: by their UI names; libfx reads them as the short names (libfx/src/core/passes.c).
BLENDER5_PASS_NAMES = {
    "Object Index": "IndexOB", "Material Index": "IndexMA",
    "Diffuse Direct": "DiffDir", "Diffuse Indirect": "DiffInd", "Diffuse Color": "DiffCol",
    "Glossy Direct": "GlossDir", "Glossy Indirect": "GlossInd", "Glossy Color": "GlossCol",
    "Transmission Direct": "TransDir", "Transmission Indirect": "TransInd",
    "Transmission Color": "TransCol", "Emission": "Emit", "Environment": "Env",
    "Ambient Occlusion": "AO",
}


class Exr:
    """All channels of a (multilayer, single-part) EXR as float32 arrays by name."""

    def __init__(self, path):
        need_oiio()
        inp = oiio.ImageInput.open(str(path))
        assert inp is not None, "cannot open %s: %s" % (path, oiio.geterror())
        spec = inp.spec()
        self.spec = spec
        self.width, self.height = spec.width, spec.height
        self.attrs = {a.name: a.value for a in spec.extra_attribs}
        self.names = []
        self.channels = {}
        # Blender 5.x writes multilayer EXRs as one part per layer: read every part.
        part = 0
        while inp.seek_subimage(part, 0):
            ps = inp.spec()
            data = inp.read_image(part, 0, 0, ps.nchannels, "float")
            for i, n in enumerate(ps.channelnames):
                self.names.append(n)
                self.channels[n] = np.array(data[:, :, i], dtype=np.float32)
            part += 1
        inp.close()

    def passes(self):
        """Pass names: 'Layer.Pass.C' -> 'Pass' (parsed from the right, GUIDE §3); 5.x's
        render-output names as libfx's canonical ones ('Diffuse Color' -> 'DiffCol')."""
        out = []
        for n in self.names:
            parts = n.split(".")
            p = parts[-2] if len(parts) >= 2 else parts[0]
            p = BLENDER5_PASS_NAMES.get(p, p)
            if p not in out:
                out.append(p)
        return out

    def get(self, pass_name, chans):
        """Channels of a pass, e.g. get('Combined', 'RGBA') -> HxWx4 (Image is Combined)."""
        aliases = {"Combined": ("Combined", "Image")}.get(pass_name, (pass_name,))
        aliases += tuple(k for k, v in BLENDER5_PASS_NAMES.items() if v == pass_name)
        out = []
        for c in chans:
            found = None
            # 4.3+ File Output nodes name Cryptomatte channels .r/.g/.b/.a
            for same in (str.__eq__, lambda a, b: a.lower() == b.lower()):
                for n in self.names:
                    parts = n.split(".")
                    if len(parts) >= 2 and same(parts[-1], c) and parts[-2] in aliases:
                        found = n
                        break
                if found:
                    break
            assert found is not None, "no channel %s.%s in %s" % (pass_name, c, self.names)
            out.append(self.channels[found])
        return np.stack(out, axis=-1)

    def has(self, pass_name):
        return pass_name in self.passes() or (pass_name == "Combined" and "Image" in self.passes())


# ---------------------------------------------------------------- Cryptomatte (spec)

def murmur3_32(data, seed=0):
    c1, c2 = 0xCC9E2D51, 0x1B873593
    h = seed
    n = len(data)
    for i in range(0, n - n % 4, 4):
        k = struct.unpack_from("<I", data, i)[0]
        k = (k * c1) & 0xFFFFFFFF
        k = ((k << 15) | (k >> 17)) & 0xFFFFFFFF
        k = (k * c2) & 0xFFFFFFFF
        h ^= k
        h = ((h << 13) | (h >> 19)) & 0xFFFFFFFF
        h = (h * 5 + 0xE6546B64) & 0xFFFFFFFF
    tail = data[n - n % 4:]
    k = 0
    for i, b in enumerate(tail):
        k |= b << (8 * i)
    if tail:
        k = (k * c1) & 0xFFFFFFFF
        k = ((k << 15) | (k >> 17)) & 0xFFFFFFFF
        k = (k * c2) & 0xFFFFFFFF
        h ^= k
    h ^= n
    h ^= h >> 16
    h = (h * 0x85EBCA6B) & 0xFFFFFFFF
    h ^= h >> 13
    h = (h * 0xC2B2AE35) & 0xFFFFFFFF
    h ^= h >> 16
    return h


def cryptomatte_id(name):
    h = murmur3_32(name.encode("utf-8"))
    exp = (h >> 23) & 255
    if exp in (0, 255):
        h ^= 1 << 23
    return struct.unpack("<f", struct.pack("<I", h))[0]


def crypto_support(exr, type_name, names):
    """Pixels with some coverage of any of names in the Cryptomatte type's ranks."""
    ids = np.array([cryptomatte_id(n) for n in names], dtype=np.float32)
    support = np.zeros((exr.height, exr.width), dtype=bool)
    ranks = sorted(p for p in exr.passes() if p.startswith(type_name) and p[len(type_name):].isdigit())
    assert ranks, "no %s ranks in %s" % (type_name, exr.passes())
    for r in ranks:
        px = exr.get(r, "RGBA")
        for pair in ((0, 1), (2, 3)):
            hit = np.isin(px[..., pair[0]], ids) & (px[..., pair[1]] > 0)
            support |= hit
    return support


def mask_support(exr, mask):
    """Where an effect with this recipe mask may change pixels (None: everywhere)."""
    if not mask:
        return None
    sel = None

    def union(a, b):
        return b if a is None else (a | b)

    def listify(v):
        return v if isinstance(v, list) else [v]

    if "material" in mask:
        sel = union(sel, crypto_support(exr, "CryptoMaterial", listify(mask["material"])))
    if "object" in mask:
        sel = union(sel, crypto_support(exr, "CryptoObject", listify(mask["object"])))
    for key, pas in (("material_index", "IndexMA"), ("object_index", "IndexOB")):
        if key in mask:
            v = exr.get(pas, exr_single_channel(exr, pas))[..., 0]
            sel = union(sel, np.isin(np.rint(v).astype(np.int64), listify(mask[key])))
    if "rect" in mask:
        x, y, w, h = mask["rect"]
        r = np.zeros((exr.height, exr.width), dtype=bool)
        r[y:y + h, x:x + w] = True
        sel = r if sel is None else (sel & r)
    if mask.get("invert"):
        return None  # the inverse of a soft mask: everything may change
    return sel


def exr_single_channel(exr, pass_name):
    for n in exr.names:
        parts = n.split(".")
        if len(parts) >= 2 and BLENDER5_PASS_NAMES.get(parts[-2], parts[-2]) == pass_name:
            return parts[-1]
    raise AssertionError("no pass %s in %s" % (pass_name, exr.names))


def read_json(path):
    with open(path, encoding="utf-8") as f:
        return json.load(f)
