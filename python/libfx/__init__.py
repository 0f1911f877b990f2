"""libfx: render effects over Blender's multilayer OpenEXR passes, from Python.

    import libfx
    libfx.version()                      # the library's version string
    libfx.effects()                      # ["bloom", "gaussian_blur", ...]
    libfx.describe("gaussian_blur")      # parameters, passes, presets (the library's JSON)
    libfx.run({"version": 1, "effects": [{"effect": "gaussian_blur", "params": {"sigma": 3}}]},
              "in.exr", "out.exr", quality="final")

The wheel carries the C library in libfx/lib/ and the ctypes binding in
libfx/native.py, a copy of the Blender add-on's addon/libfx/native.py made when the
wheel is built: Context, Stack, Frame and LibfxError come from there and are the
lower-level API (docs/python.md). Recipes are the JSON of docs/recipes.md. Nothing
else is defined in Python: effects, parameters and defaults are the library's.
"""

import json
import os

from . import native
from .native import Context, Frame, LibfxError, Stack  # noqa: F401  (the lower-level API)

__all__ = ["version", "effects", "describe", "qualities", "run", "library_path", "cli_path",
           "Context", "Stack", "Frame", "LibfxError", "native"]

_HERE = os.path.dirname(os.path.abspath(__file__))


def library_path():
    """The path of the loaded libfx library (raises LibfxError naming the file and the
    loader's reason when it cannot be loaded)."""
    native.lib()
    return native.library_path()


def version():
    """The library's version string."""
    return native.version()


def effects():
    """The names of the effects the library has."""
    return native.effect_names()


def qualities():
    """The quality presets, fastest first ("draft", "preview", "final", "reference")."""
    return native.quality_names()


def describe(effect):
    """The library's description of ``effect``: doc, parameters, passes, presets."""
    with Context(1) as ctx:
        return ctx.describe(effect)


def _recipe_text(recipe):
    """A recipe given as a dict, JSON text or the path of a .json file -> JSON text."""
    if isinstance(recipe, dict):
        return json.dumps(recipe)
    if isinstance(recipe, os.PathLike) or (isinstance(recipe, str) and not recipe.lstrip().startswith("{")):
        with open(recipe, "r", encoding="utf-8") as f:
            return f.read()
    return recipe


def run(recipe, in_exr, out_exr, quality=None, threads=0, keep_passes=False, sidecar=None):
    """Runs ``recipe`` (dict, JSON text or .json path) on the EXR ``in_exr`` and writes
    ``out_exr`` as `libfx run --stack recipe in -o out` does: the library decodes only
    the passes the stack needs (all of them with ``keep_passes``), writes to a temporary
    file and renames it. ``quality``: a preset name for the whole stack; ``sidecar``: the
    scene sidecar (camera, lights, time) as a dict or the path of its .json, as
    `libfx run --sidecar` takes it (docs/recipes.md). Returns the list of the library's
    warnings; raises LibfxError (its message names the file, pass or parameter) on
    failure."""
    with Context(threads) as ctx:
        stack = Stack(ctx, _recipe_text(recipe))
        try:
            if quality:
                stack.set_quality(quality)
            frame = Frame.read(ctx, os.fspath(in_exr), None if keep_passes else stack)
            if sidecar is not None:
                if not isinstance(sidecar, dict):
                    with open(sidecar, "r", encoding="utf-8") as f:
                        sidecar = json.load(f)
                try:
                    frame.apply_sidecar(sidecar)
                except BaseException:
                    frame.close()
                    raise
            out = stack.run_consume(frame, keep_passes=keep_passes)
            try:
                out.write_exr(os.fspath(out_exr), input_path=os.fspath(in_exr))
            finally:
                out.close()
        finally:
            stack.close()
        return ctx.warnings()


def cli_path():
    """The `libfx` command-line tool shipped in this wheel, or None (a wheel built
    without it)."""
    for name in ("libfx.exe", "libfx"):
        p = os.path.join(_HERE, "bin", name)
        if os.path.isfile(p):
            return p
    return None
