"""The only ctypes file of the add-on: finds the libfx library, binds the public C API
(libfx/include/libfx/fx.h) and wraps it in a few small Python classes.

Nothing here imports bpy, so the module can be used by plain Python tools and
tests.  Every function used is declared with ``argtypes``/``restype`` at load
time; a missing or mismatched library never raises at import: ``load()``
returns None and ``load_error()`` says why, so the add-on can still register
and show the message in its panel.  The functions every path needs (_CORE) must
all be there; a function only one feature uses (_OPTIONAL, FEATURES) may be
missing from an older library: that feature is off (``has()``) and
``feature_problems()`` says so.
"""

import ctypes
import glob
import importlib.machinery
import json
import os
import struct
import sys
import threading

#: The ABI this module was written for (FX_ABI_VERSION in fx.h).
ABI_VERSION = 2

_HERE = os.path.dirname(os.path.abspath(__file__))

c_char_p = ctypes.c_char_p
c_int = ctypes.c_int
c_void_p = ctypes.c_void_p
c_double = ctypes.c_double
c_float = ctypes.c_float


class LibfxError(RuntimeError):
    """A failed libfx call; ``code`` is the fx_result name ("FX_ERR_BAD_PARAM")."""

    def __init__(self, message, code="FX_ERR_INTERNAL"):
        super().__init__(message)
        self.code = code


class fx_read_options(ctypes.Structure):
    _fields_ = [("size", ctypes.c_size_t),
                ("layer", c_char_p),
                ("view", c_char_p),
                ("stack", c_void_p)]


class fx_write_options(ctypes.Structure):
    _fields_ = [("size", ctypes.c_size_t),
                ("half_color", c_int),
                ("only_combined", c_int),
                ("input_path", c_char_p),
                ("compression", c_char_p)]   # NULL: the library's default (ZIP, fast)


P = ctypes.POINTER
_PP = P(c_void_p)          # fx_xxx **out
_PSTR = P(c_void_p)        # char **out_json (freed with fx_free)

# name: (restype, argtypes).  fx_result is an int.  Every add-on path needs these: a
# library without one of them is refused at load, naming the function.
_CORE = {
    "fx_abi_version": (c_int, []),
    "fx_version_string": (c_char_p, []),
    "fx_result_name": (c_char_p, [c_int]),
    "fx_free": (None, [c_void_p]),
    "fx_context_new": (c_int, [_PP, c_int]),
    "fx_context_free": (None, [c_void_p]),
    "fx_context_error": (c_char_p, [c_void_p]),
    "fx_context_warning_count": (c_int, [c_void_p]),
    "fx_context_warning": (c_char_p, [c_void_p, c_int]),
    "fx_context_clear_warnings": (None, [c_void_p]),
    "fx_effect_count": (c_int, []),
    "fx_effect_name": (c_char_p, [c_int]),
    "fx_effect_describe_json": (c_int, [c_void_p, c_char_p, _PSTR]),
    "fx_quality_from_name": (c_int, [c_char_p]),
    "fx_quality_name": (c_char_p, [c_int]),
    "fx_frame_free": (None, [c_void_p]),
    "fx_frame_width": (c_int, [c_void_p]),
    "fx_frame_height": (c_int, [c_void_p]),
    "fx_frame_pass_count": (c_int, [c_void_p]),
    "fx_frame_pass_name": (c_char_p, [c_void_p, c_int]),
    "fx_frame_apply_sidecar": (c_int, [c_void_p, c_char_p]),
    "fx_frame_set_time": (None, [c_void_p, c_double, c_double]),
    "fx_frame_read_exr": (c_int, [c_void_p, c_char_p, P(fx_read_options), _PP]),
    "fx_frame_write_exr": (c_int, [c_void_p, c_char_p, P(fx_write_options)]),
    "fx_frame_copy_passes": (c_int, [c_void_p, c_void_p]),
    "fx_stack_new": (c_int, [c_void_p, _PP]),
    "fx_stack_free": (None, [c_void_p]),
    "fx_stack_load_json": (c_int, [c_void_p, c_char_p]),
    "fx_stack_to_json": (c_int, [c_void_p, _PSTR]),
    "fx_stack_count": (c_int, [c_void_p]),
    "fx_stack_required_passes": (c_int, [c_void_p, _PSTR]),
    "fx_stack_run": (c_int, [c_void_p, c_void_p, _PP]),
    "fx_stack_timings_json": (c_int, [c_void_p, _PSTR]),
    "fx_stack_set_quality": (c_int, [c_void_p, c_int]),
    "fx_stack_set_debug_outputs": (None, [c_void_p, c_int]),
    "fx_context_set_progress": (None, [c_void_p, c_void_p, c_void_p]),
}

# Functions only some features use (added to ABI 1 after its first release, or not yet
# there): a library without one loads, and only that feature is off, with a message.
_OPTIONAL = {
    "fx_frame_reduce": (c_int, [c_void_p, c_int, _PP]),
    "fx_frame_read_pixels": (c_int, [c_void_p, c_char_p, c_int, c_int, c_int, P(c_float)]),
    "fx_stack_required_aux_views": (c_int, [c_void_p, _PSTR]),
    "fx_stack_run_consume": (c_int, [c_void_p, c_void_p, c_int, _PP]),
    "fx_effect_params_version": (c_int, [c_void_p, c_char_p, P(c_int)]),
}

#: feature -> (what it does, for the message; the optional functions it needs).
FEATURES = {
    "live": ("live look-dev and showing the result from memory", ("fx_frame_reduce", "fx_frame_read_pixels")),
    "aux_views": ("auxiliary views (light views, the rain map)", ("fx_stack_required_aux_views",)),
    "run_in_place": ("runs that reuse the input's memory (a plain run is used instead)",
                     ("fx_stack_run_consume",)),
    "params_version": ("migrating parameters saved by an older libfx (every effect is taken as version 1)",
                       ("fx_effect_params_version",)),
}

#: Features whose absence is expected today and not worth a warning in the panel.
_QUIET = {"params_version"}

#: int (*fx_progress_fn)(void *user, const char *stage, double fraction): non-zero cancels.
PROGRESS_FN = ctypes.CFUNCTYPE(c_int, c_void_p, c_char_p, c_double)

_lock = threading.Lock()
_lib = None
_lib_path = None
_load_error = None
_tried = False


def library_name(platform=None):
    """The file name of libfx's shared library (ABI_VERSION is its SOVERSION) on
    ``platform`` (a sys.platform value; this one by default)."""
    platform = sys.platform if platform is None else platform
    if platform.startswith(("win", "cygwin", "msys")):
        return "libfx.dll"
    if platform == "darwin":
        return "libfx.%d.dylib" % ABI_VERSION
    return "libfx.so.%d" % ABI_VERSION


def _dev_names():
    """Names a development build also answers to (the unversioned link name)."""
    name = library_name()
    unversioned = {"libfx.so.%d" % ABI_VERSION: "libfx.so",
                   "libfx.%d.dylib" % ABI_VERSION: "libfx.dylib"}.get(name)
    return [name] + ([unversioned] if unversioned else [])


def _same_dir(a, b):
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.normcase(os.path.abspath(a)) == os.path.normcase(os.path.abspath(b))


def wheel_package_dirs():
    """The directories of the ``libfx`` packages importable from sys.path other than
    the one this file lives in: the libfx wheel (pip-installed, or installed by Blender
    4.2+ from the extension's wheels/ into its site-packages).  Found with importlib's
    path finder one sys.path entry at a time, without importing anything, so a
    same-named package earlier on the path (the legacy add-on is a top-level
    ``libfx`` too) cannot hide the wheel."""
    out = []
    for entry in list(sys.path):
        if not isinstance(entry, str):
            continue
        try:
            spec = importlib.machinery.PathFinder.find_spec("libfx", [entry or os.curdir])
        except (ImportError, OSError, ValueError):
            continue
        if spec is None or spec.origin is None or not spec.submodule_search_locations:
            continue                  # not there, a module, or a namespace package (a plain folder)
        for d in spec.submodule_search_locations:
            if not _same_dir(d, _HERE) and not any(_same_dir(d, o) for o in out):
                out.append(d)
    # an installed distribution (pip's or Blender's wheel install leaves libfx-<v>.dist-info
    # beside the package) before a bare same-named package such as a legacy add-on
    return sorted(out, key=lambda d: not glob.glob(os.path.join(glob.escape(os.path.dirname(d)),
                                                                "libfx-*.dist-info")))


def candidate_paths():
    """Where the library is looked for, in order: $LIBFX_LIBRARY alone when set; the
    package's own lib/ (the legacy add-on zip, the wheel); the installed libfx wheel's
    lib/ (the 4.2+ extension, whose library comes in its platform's wheel); the
    source tree's build directories."""
    env = os.environ.get("LIBFX_LIBRARY")
    if env:
        return [env]  # an explicit choice is never second-guessed
    name = library_name()
    out = [os.path.join(_HERE, "lib", name)]
    for d in wheel_package_dirs():
        out.append(os.path.join(d, "lib", name))
    root = os.path.dirname(os.path.dirname(_HERE))              # source tree
    for build in ("build", "build-addon"):
        for n in _dev_names():
            out.append(os.path.join(root, build, "libfx", n))
    return out


def describe_file(path):
    """What kind of binary ``path`` is, from its first bytes ("ELF 64-bit x86-64",
    "Windows PE x86-64 DLL", "Mach-O", "an empty file", ...), or None."""
    try:
        with open(path, "rb") as f:
            head = f.read(64)
            if head[:2] == b"MZ" and len(head) >= 64:
                f.seek(int.from_bytes(head[60:64], "little"))
                pe = f.read(6)
            else:
                pe = b""
    except OSError:
        return None
    if not head:
        return "an empty file"
    if head[:4] == b"\x7fELF" and len(head) >= 20:
        bits = {1: "32-bit", 2: "64-bit"}.get(head[4], "?-bit")
        order = "little" if head[5] == 1 else "big"
        machine = int.from_bytes(head[18:20], order)
        arch = {3: "i386", 62: "x86-64", 183: "aarch64", 40: "arm", 243: "riscv",
                21: "ppc64", 22: "s390"}.get(machine, "machine %d" % machine)
        return "ELF %s %s" % (bits, arch)
    if pe[:4] == b"PE\0\0":
        machine = int.from_bytes(pe[4:6], "little")
        arch = {0x8664: "x86-64", 0x14c: "i386", 0xaa64: "arm64"}.get(machine, "machine 0x%x" % machine)
        return "Windows PE %s DLL" % arch
    magic = int.from_bytes(head[:4], "little")
    if magic in (0xfeedfacf, 0xfeedface, 0xcafebabe, 0xbebafeca):
        return "Mach-O"
    return "not a shared library (starts with %r)" % head[:8]


def elf_truncation(path):
    """Why the ELF file at ``path`` is shorter than its own headers say (a copy cut
    short), or None.  glibc's loader maps such a file and the process dies of SIGBUS
    when it touches the missing pages, so this is checked before loading."""
    try:
        size = os.path.getsize(path)
        with open(path, "rb") as f:
            head = f.read(64)
            if head[:4] != b"\x7fELF" or len(head) < 52 or head[4] not in (1, 2):
                return None
            e = "<" if head[5] == 1 else ">"
            if head[4] == 2:
                if len(head) < 64:
                    return None
                phoff, shoff = struct.unpack_from(e + "QQ", head, 32)
                phentsize, phnum, shentsize, shnum = struct.unpack_from(e + "HHHH", head, 54)
                ph_fmt, ph_at = e + "QQQQ", 8                 # offset, vaddr, paddr, filesz
            else:
                phoff, shoff = struct.unpack_from(e + "II", head, 28)
                phentsize, phnum, shentsize, shnum = struct.unpack_from(e + "HHHH", head, 42)
                ph_fmt, ph_at = e + "IIII", 4
            need = max(phoff + phentsize * phnum, shoff + shentsize * shnum if shoff else 0)
            if need <= size:
                f.seek(phoff)
                table = f.read(phentsize * phnum)
                for i in range(phnum):
                    off, _, _, filesz = struct.unpack_from(ph_fmt, table, i * phentsize + ph_at)
                    need = max(need, off + filesz)
    except (OSError, struct.error):
        return None
    if need > size:
        return "the file is truncated: %d bytes, its ELF headers need %d" % (size, need)
    return None


def _open(path):
    """ctypes.CDLL(path); on Windows the library's folder also serves its dependencies."""
    if sys.platform.startswith("win") and hasattr(os, "add_dll_directory"):
        d = os.path.dirname(os.path.abspath(path))
        if d not in _dll_dirs:
            try:
                _dll_dirs[d] = os.add_dll_directory(d)
            except OSError:
                pass
    return ctypes.CDLL(path)


_dll_dirs = {}


def _bind(lib, signatures):
    """Declares argtypes/restype of each function the library has; returns the missing."""
    missing = []
    for name, (restype, argtypes) in signatures.items():
        fn = getattr(lib, name, None)
        if fn is None:
            missing.append(name)
            continue
        fn.restype = restype
        fn.argtypes = argtypes
    return missing


def _check(lib, path):
    """None when the library at ``path`` can be used, else why not (and the missing
    optional functions are recorded)."""
    if getattr(lib, "fx_abi_version", None) is None:
        return "%s is not libfx (it has no fx_abi_version)" % path
    missing = _bind(lib, _CORE)
    abi = lib.fx_abi_version()
    if abi != ABI_VERSION:
        return ("libfx at %s has ABI %d; this add-on was written for ABI %d: "
                "install the matching add-on zip" % (path, abi, ABI_VERSION))
    if missing:
        return ("libfx at %s lacks the function%s %s that the add-on needs (an older or "
                "foreign build?): install the matching add-on zip"
                % (path, "s" if len(missing) > 1 else "", ", ".join(missing)))
    _missing_optional[:] = _bind(lib, _OPTIONAL)
    return None


_missing_optional = []


def load():
    """The bound library, or None (then see load_error())."""
    global _lib, _lib_path, _load_error, _tried
    with _lock:
        if _tried:
            return _lib
        _tried = True
        tried = []
        explicit = bool(os.environ.get("LIBFX_LIBRARY"))
        for path in candidate_paths():
            if not os.path.exists(path) and not explicit:
                tried.append(path)
                continue
            try:
                short = elf_truncation(path)
                if short:
                    raise OSError(short)
                lib = _open(path)
            except OSError as e:
                # the loader's own words (missing file, GLIBC version, ELF class...)
                # and what the file is, naming the file
                kind = describe_file(path)
                _load_error = ("libfx library %s%s cannot be loaded: %s%s"
                               % (path, " (LIBFX_LIBRARY)" if explicit else "", e,
                                  " [the file is %s]" % kind if kind else ""))
                return None
            _load_error = _check(lib, path)
            if _load_error is not None:
                return None
            _lib, _lib_path = lib, path
            return lib
        _load_error = ("libfx library not found: no %s in the add-on, an installed libfx "
                       "wheel or a build directory (install the package for this platform "
                       "or set LIBFX_LIBRARY); looked in: %s" % (library_name(), ", ".join(tried)))
        return None


def load_error():
    return _load_error


def library_path():
    return _lib_path


def has(feature):
    """Whether the loaded library has every function ``feature`` (a FEATURES key) needs."""
    return load() is not None and not any(f in _missing_optional for f in FEATURES[feature][1])


def feature_problem(feature):
    """Why ``feature`` is off (naming the library and the functions it lacks), or None."""
    if load() is None:
        return None
    what, names = FEATURES[feature]
    gone = [n for n in names if n in _missing_optional]
    if not gone:
        return None
    return ("libfx at %s has no %s (an older library?), so this is off: %s. "
            "Install the matching add-on zip." % (_lib_path, ", ".join(gone), what))


def feature_problems(include_expected=False):
    """feature_problem() of every feature that is off; ``include_expected``: also those
    whose absence is expected today (_QUIET)."""
    return [m for m in (feature_problem(f) for f in FEATURES if include_expected or f not in _QUIET)
            if m is not None]


def retry_if_failed():
    """A later registration looks again (the library may have been installed since)."""
    global _tried, _load_error
    with _lock:
        if _lib is None:
            _tried = False
            _load_error = None


def lib():
    L = load()
    if L is None:
        raise LibfxError(_load_error or "libfx is not loaded", "FX_ERR_INTERNAL")
    return L


def _s(b):
    return b.decode("utf-8", "replace") if b is not None else None


def _take_string(ptr):
    """A char* the library allocated: copy it, then fx_free it."""
    if not ptr:
        return None
    try:
        return ctypes.string_at(ptr).decode("utf-8", "replace")
    finally:
        lib().fx_free(ptr)


def version():
    return _s(lib().fx_version_string())


def result_name(code):
    return _s(lib().fx_result_name(code)) or str(code)


def effect_names():
    L = lib()
    return [_s(L.fx_effect_name(i)) for i in range(L.fx_effect_count())]


def quality_names():
    L = lib()
    out = []
    for i in range(16):
        n = L.fx_quality_name(i)
        if not n:
            break
        out.append(_s(n))
    return out


class Context:
    """fx_context: threads, per-thread errors, warnings."""

    def __init__(self, threads=0):
        L = lib()
        self._L = L
        self._ptr = c_void_p()
        r = L.fx_context_new(ctypes.byref(self._ptr), int(threads))
        if r != 0:
            raise LibfxError("fx_context_new failed: %s" % result_name(r), result_name(r))

    @property
    def ptr(self):
        return self._ptr

    def error(self):
        return _s(self._L.fx_context_error(self._ptr)) or ""

    def check(self, r, what):
        if r != 0:
            msg = self.error() or what
            raise LibfxError(msg, result_name(r))

    def warnings(self, clear=True):
        n = self._L.fx_context_warning_count(self._ptr)
        out = [_s(self._L.fx_context_warning(self._ptr, i)) for i in range(n)]
        if clear:
            self._L.fx_context_clear_warnings(self._ptr)
        return out

    def set_cancel_check(self, should_cancel):
        """``should_cancel()`` is asked between effects (on the calling thread); True stops
        the run with FX_ERR_CANCELLED. None: never."""
        if should_cancel is None:
            self._progress = None
            self._L.fx_context_set_progress(self._ptr, None, None)
            return
        self._progress = PROGRESS_FN(lambda user, stage, fraction: 1 if should_cancel() else 0)
        self._L.fx_context_set_progress(self._ptr, ctypes.cast(self._progress, c_void_p), None)

    def describe(self, effect):
        out = c_void_p()
        self.check(self._L.fx_effect_describe_json(self._ptr, effect.encode(), ctypes.byref(out)),
                   "describe %s" % effect)
        return json.loads(_take_string(out.value))

    def close(self):
        if getattr(self, "_ptr", None):
            self._L.fx_context_free(self._ptr)
            self._ptr = None

    __del__ = close

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def effect_params_version(effect):
    """The version of ``effect``'s parameter table (1 for a library without parameter
    versions, and for an effect it does not know)."""
    if not has("params_version"):
        return 1
    ctx = Context(1)
    try:
        v = c_int(1)
        if lib().fx_effect_params_version(ctx.ptr, effect.encode("utf-8"), ctypes.byref(v)) != 0:
            return 1
        return max(1, v.value)
    finally:
        ctx.close()


class Stack:
    """fx_stack loaded from recipe JSON."""

    def __init__(self, ctx, recipe=None):
        self._ctx = ctx
        self._L = ctx._L
        self._ptr = c_void_p()
        ctx.check(self._L.fx_stack_new(ctx.ptr, ctypes.byref(self._ptr)), "fx_stack_new")
        if recipe is not None:
            self.load(recipe)

    @property
    def ptr(self):
        return self._ptr

    def load(self, recipe):
        text = recipe if isinstance(recipe, str) else json.dumps(recipe)
        self._ctx.check(self._L.fx_stack_load_json(self._ptr, text.encode("utf-8")), "load recipe")

    def to_json(self):
        out = c_void_p()
        self._ctx.check(self._L.fx_stack_to_json(self._ptr, ctypes.byref(out)), "fx_stack_to_json")
        return json.loads(_take_string(out.value))

    def __len__(self):
        return self._L.fx_stack_count(self._ptr)

    def required(self):
        """{"passes": [...], "camera": bool, ...} as the library says."""
        out = c_void_p()
        self._ctx.check(self._L.fx_stack_required_passes(self._ptr, ctypes.byref(out)),
                        "fx_stack_required_passes")
        return json.loads(_take_string(out.value))

    def required_aux_views(self):
        """[{"name": "light:Sun", "kind": "light", "light": "Sun"}, {"name": "rain_map", ...}]:
        the auxiliary views the enabled effects need (empty for most stacks, and with a
        library that cannot say: see feature_problems())."""
        if not has("aux_views"):
            return []
        out = c_void_p()
        self._ctx.check(self._L.fx_stack_required_aux_views(self._ptr, ctypes.byref(out)),
                        "fx_stack_required_aux_views")
        return json.loads(_take_string(out.value)).get("aux_views", [])

    def run(self, frame):
        out = c_void_p()
        self._ctx.check(self._L.fx_stack_run(self._ptr, frame.ptr, ctypes.byref(out)), "fx_stack_run")
        return Frame(self._ctx, out)

    def run_consume(self, frame, keep_passes=False):
        """run() for a frame not needed again: the library may write the result over its
        pixels (no second frame-sized buffer) and frees it; ``frame`` is closed either way."""
        if not has("run_in_place"):
            try:
                fout = self.run(frame)
                if keep_passes:
                    fout.copy_passes_from(frame)
                return fout
            finally:
                frame.close()
        out = c_void_p()
        ptr, frame._ptr = frame._ptr, None   # the library frees it, success or not
        self._ctx.check(self._L.fx_stack_run_consume(self._ptr, ptr, 1 if keep_passes else 0,
                                                     ctypes.byref(out)), "fx_stack_run_consume")
        return Frame(self._ctx, out)

    def set_quality(self, quality):
        """The stack's preset by name ("draft"...): effects with their own quality keep it."""
        q = self._L.fx_quality_from_name(quality.encode())
        if q < 0:
            raise LibfxError("unknown quality '%s'" % quality, "FX_ERR_BAD_PARAM")
        self._ctx.check(self._L.fx_stack_set_quality(self._ptr, q), "set quality %s" % quality)

    def set_debug_outputs(self, enabled):
        self._L.fx_stack_set_debug_outputs(self._ptr, 1 if enabled else 0)

    def timings(self):
        out = c_void_p()
        self._ctx.check(self._L.fx_stack_timings_json(self._ptr, ctypes.byref(out)), "timings")
        return json.loads(_take_string(out.value))

    def close(self):
        if getattr(self, "_ptr", None):
            self._L.fx_stack_free(self._ptr)
            self._ptr = None

    __del__ = close


class Frame:
    """fx_frame: named float passes + camera + time."""

    def __init__(self, ctx, ptr):
        self._ctx = ctx
        self._L = ctx._L
        self._ptr = ptr

    @property
    def ptr(self):
        return self._ptr

    @classmethod
    def read(cls, ctx, path, stack=None, layer=None):
        """Reads an EXR, decoding only what ``stack`` needs (all passes without one)."""
        opts = fx_read_options()
        opts.size = ctypes.sizeof(fx_read_options)
        opts.layer = layer.encode() if layer else None
        opts.view = None
        opts.stack = stack.ptr if stack is not None else None
        out = c_void_p()
        ctx.check(ctx._L.fx_frame_read_exr(ctx.ptr, os.fsencode(path), ctypes.byref(opts),
                                           ctypes.byref(out)), "read %s" % path)
        return cls(ctx, out)

    @property
    def width(self):
        return self._L.fx_frame_width(self._ptr)

    @property
    def height(self):
        return self._L.fx_frame_height(self._ptr)

    def pass_names(self):
        return [_s(self._L.fx_frame_pass_name(self._ptr, i))
                for i in range(self._L.fx_frame_pass_count(self._ptr))]

    def apply_sidecar(self, sidecar):
        """Camera, lights and time from a scene sidecar dict (docs/recipes.md)."""
        text = json.dumps(sidecar).encode("utf-8")
        self._ctx.check(self._L.fx_frame_apply_sidecar(self._ptr, text), "apply the scene sidecar")

    def set_time(self, frame, fps):
        self._L.fx_frame_set_time(self._ptr, float(frame), float(fps))

    def reduce(self, factor):
        """A 1/factor proxy of this frame (colour averaged, IDs/depth/normals from one pixel
        per block); the stack scales pixel-sized parameters when it runs on it."""
        out = c_void_p()
        self._ctx.check(self._L.fx_frame_reduce(self._ptr, int(factor), ctypes.byref(out)),
                        "reduce the frame to 1/%d" % factor)
        return Frame(self._ctx, out)

    def read_pixels(self, pass_name, width, height, out, bottom_up=True):
        """Fills ``out`` (a writable float32 buffer of width*height*4, e.g. a numpy array)
        with the pass as RGBA, resampled to width x height, rows bottom-up for Blender."""
        addr = out.ctypes.data if hasattr(out, "ctypes") else ctypes.addressof(out)
        self._ctx.check(self._L.fx_frame_read_pixels(self._ptr, pass_name.encode(), int(width), int(height),
                                                     1 if bottom_up else 0,
                                                     ctypes.cast(addr, P(c_float))),
                        "read pass %s" % pass_name)

    def copy_passes_from(self, other):
        self._ctx.check(self._L.fx_frame_copy_passes(self._ptr, other.ptr), "copy passes")

    def write_exr(self, path, half_color=False, only_combined=False, input_path=None):
        opts = fx_write_options()
        opts.size = ctypes.sizeof(fx_write_options)
        opts.half_color = 1 if half_color else 0
        opts.only_combined = 1 if only_combined else 0
        opts.input_path = os.fsencode(input_path) if input_path else None
        self._ctx.check(self._L.fx_frame_write_exr(self._ptr, os.fsencode(path), ctypes.byref(opts)),
                        "write %s" % path)

    def close(self):
        if getattr(self, "_ptr", None):
            self._L.fx_frame_free(self._ptr)
            self._ptr = None

    __del__ = close
