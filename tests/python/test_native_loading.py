"""The add-on's ctypes layer (addon/libfx/native.py, no bpy) loading a library: the core
functions are required and a missing one is named with the library's path; a function
only one feature uses may be missing (an older libfx.so): that feature is off and says
why; the ABI is checked before anything else is used."""
import importlib.util
import os
import re
import pathlib
import sys

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from test_exr_interop import _library_path  # noqa: E402

REPO = pathlib.Path(__file__).resolve().parents[2]
NATIVE = REPO / "addon" / "libfx" / "native.py"


def fresh_native():
    """A new copy of the module (its load state is module-global)."""
    spec = importlib.util.spec_from_file_location("libfx_native_under_test", NATIVE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


class FakeLib:
    """Stands in for a ctypes.CDLL: has every function but those in ``without``."""

    def __init__(self, native, without=(), abi=None):
        abi = native.ABI_VERSION if abi is None else abi
        names = set(native._CORE) | set(native._OPTIONAL)
        for name in names - set(without):
            fn = (lambda abi=abi: abi) if name == "fx_abi_version" else (lambda *a: 0)
            setattr(self, name, fn)


def test_the_real_library_loads_with_every_feature_it_has(monkeypatch):
    library = _library_path()
    if not library.is_file():
        pytest.fail("libfx is not built at %s (build it, or set LIBFX_LIBRARY)" % library)
    native = fresh_native()
    monkeypatch.setenv("LIBFX_LIBRARY", str(library))
    assert native.load() is not None, native.load_error()
    assert native.load_error() is None
    for feature in ("live", "aux_views", "run_in_place"):
        assert native.has(feature), native.feature_problems(include_expected=True)
    # today's library may not have parameter versions yet: every effect is then version 1
    v = native.effect_params_version("gaussian_blur")
    assert v >= 1 and (native.has("params_version") or v == 1)
    assert native.effect_params_version("no_such_effect") == 1


def test_a_missing_core_function_refuses_the_library_naming_it():
    native = fresh_native()
    why = native._check(FakeLib(native, without=["fx_stack_run"]), "/old/libfx.so.1")
    assert why is not None and "/old/libfx.so.1" in why and "fx_stack_run" in why, why


def test_a_missing_optional_function_turns_only_its_feature_off():
    native = fresh_native()
    fake = FakeLib(native, without=["fx_frame_reduce", "fx_effect_params_version"])
    assert native._check(fake, "/old/libfx.so.1") is None
    native._lib, native._lib_path, native._tried = fake, "/old/libfx.so.1", True
    assert not native.has("live") and native.has("aux_views") and native.has("run_in_place")
    problems = native.feature_problems()
    assert len(problems) == 1, problems           # parameter versions: expected, quiet
    assert "/old/libfx.so.1" in problems[0] and "fx_frame_reduce" in problems[0], problems
    assert "live" in problems[0]
    assert any("fx_effect_params_version" in p for p in native.feature_problems(include_expected=True))
    assert native.effect_params_version("gaussian_blur") == 1


def test_abi_and_foreign_libraries_are_refused():
    native = fresh_native()
    why = native._check(FakeLib(native, abi=3), "/new/libfx.so.3")
    assert "ABI 3" in why and "ABI %d" % native.ABI_VERSION in why, why
    why = native._check(FakeLib(native, without=["fx_abi_version"]), "/usr/lib/libz.so")
    assert "is not libfx" in why, why
    # the ABI is named before missing functions: a library of another ABI lacks some
    why = native._check(FakeLib(native, without=["fx_stack_run"], abi=3), "/new/libfx.so.3")
    assert "ABI 3" in why, why


def test_nothing_declared_is_left_unused():
    """Every function native.py binds is called by it (dead declarations are how a missing
    symbol used to refuse a library that the add-on could have used)."""
    native = fresh_native()
    text = NATIVE.read_text()
    for name in list(native._CORE) + list(native._OPTIONAL):
        if name == "fx_abi_version":
            continue
        assert text.count(name) >= 2, "%s is declared but never called" % name


def test_the_abi_the_add_on_expects_is_the_header_s():
    import re
    native = fresh_native()
    header = (REPO / "libfx" / "include" / "libfx" / "fx.h").read_text()
    m = re.search(r"#define\s+FX_ABI_VERSION\s+(\d+)", header)
    assert m and int(m.group(1)) == native.ABI_VERSION, (m and m.group(0), native.ABI_VERSION)


# ---------------------------------------------------------------- real loader failures

import broken_libraries as B  # noqa: E402


def _load_with(monkeypatch, path):
    native = fresh_native()
    monkeypatch.setenv("LIBFX_LIBRARY", str(path))
    assert native.load() is None
    return native.load_error()


def _real():
    library = _library_path()
    if not library.is_file():
        pytest.fail("libfx is not built at %s (build it, or set LIBFX_LIBRARY)" % library)
    return library


def test_a_truncated_copy_is_refused_naming_the_file_not_a_crash(monkeypatch, tmp_path):
    # glibc maps a truncated ELF and dies of SIGBUS on the missing pages: native.py
    # checks the file against its own headers first (in this process: a crash fails the run)
    path = B.truncated(_real(), tmp_path)
    why = _load_with(monkeypatch, path)
    assert path in why and "truncated" in why and "4096 bytes" in why and "ELF 64-bit x86-64" in why, why


def test_a_32_bit_library_gives_the_loaders_reason(monkeypatch, tmp_path):
    path = B.elf32(tmp_path)
    why = _load_with(monkeypatch, path)
    assert path in why and "wrong ELF class: ELFCLASS32" in why and "ELF 32-bit i386" in why, why


def test_a_windows_dll_gives_the_loaders_reason(monkeypatch, tmp_path):
    path = B.windows_dll(tmp_path)
    why = _load_with(monkeypatch, path)
    assert path in why and "invalid ELF header" in why and "Windows PE x86-64 DLL" in why, why


def test_a_missing_file_gives_the_loaders_reason(monkeypatch, tmp_path):
    path = B.missing(tmp_path)
    why = _load_with(monkeypatch, path)
    assert path in why and "No such file or directory" in why and "LIBFX_LIBRARY" in why, why


def test_nothing_found_lists_where_it_looked(monkeypatch, tmp_path):
    native = fresh_native()
    monkeypatch.delenv("LIBFX_LIBRARY", raising=False)
    monkeypatch.setattr(native, "candidate_paths", lambda: [str(tmp_path / "a" / "libfx.so.2")])
    assert native.load() is None
    why = native.load_error()
    assert "not found" in why and str(tmp_path / "a" / "libfx.so.2") in why and native.library_name() in why, why


def test_library_names_per_platform():
    native = fresh_native()
    assert native.library_name("linux") == "libfx.so.%d" % native.ABI_VERSION
    assert native.library_name("win32") == "libfx.dll"
    assert native.library_name("darwin") == "libfx.%d.dylib" % native.ABI_VERSION
    assert native.library_name().startswith("libfx")


def test_the_installed_wheel_package_is_found_after_a_same_named_package(monkeypatch, tmp_path):
    """Two top-level `libfx` packages on sys.path, as inside Blender when the legacy add-on
    (a top-level `libfx`) sits before the wheel: the first has no lib/, the second, a
    wheel's, has the real library; native.py (living elsewhere) finds and loads it."""
    import shutil
    real = _real()
    first = tmp_path / "addons" / "libfx"
    wheel = tmp_path / "site-packages" / "libfx"
    (first / "lib").mkdir(parents=True)
    (first / "__init__.py").write_text("")
    # a bare package earlier on the path with a broken library of its own: the installed
    # distribution (the one with libfx-<v>.dist-info beside it) goes first
    B.truncated(real, first / "lib")
    (first / "lib" / "libfx-truncated.so.2").rename(first / "lib" / "libfx.so.2")
    (wheel / "lib").mkdir(parents=True)
    (wheel / "__init__.py").write_text("")
    (wheel.parent / "libfx-0.1.0.dist-info").mkdir()
    shutil.copy(str(real), str(wheel / "lib" / "libfx.so.2"))
    native = fresh_native()
    monkeypatch.delenv("LIBFX_LIBRARY", raising=False)
    monkeypatch.setattr(sys, "path", [str(tmp_path / "addons"), str(tmp_path / "site-packages")] + sys.path)
    paths = native.candidate_paths()
    want = str(wheel / "lib" / native.library_name())
    assert want in paths, paths
    # a namespace package (a folder named libfx without __init__.py, like the C sources') is no wheel
    assert os.path.join(str(REPO), "libfx", "lib", native.library_name()) not in paths, paths
    # the package's own lib/ comes first; the wheel's before the build directories
    assert paths[0] == os.path.join(native._HERE, "lib", native.library_name())
    assert paths.index(want) < min(i for i, p in enumerate(paths) if os.sep + "build" in p), paths
    assert paths.index(want) < paths.index(str(first / "lib" / "libfx.so.2")), paths
    assert native.load() is not None, native.load_error()
    assert native.library_path() == want


def test_a_library_built_for_a_newer_glibc_says_which_version(tmp_path):
    """This tree's library (built against the host's glibc, 2.36 on Debian 12) loaded on
    Debian 11 (glibc 2.31, the bullseye root of scripts/blender_roots.sh), its other
    dependencies copied beside it: the loader's 'version `GLIBC_2.3x' not found'."""
    import shutil
    import subprocess

    def newest_glibc(path):
        out = subprocess.run(["objdump", "-T", str(path)], capture_output=True, text=True).stdout
        found = [tuple(int(v) for v in m.split(".")) for m in re.findall(r"GLIBC_([0-9.]+)", out)]
        return max(found, default=(0,))

    # the library under test, unless it is the release build (glibc 2.31: it loads there);
    # then the development build of this tree
    real = next((p for p in (_real(), REPO / "build" / "libfx" / "libfx.so.2")
                 if p.is_file() and newest_glibc(p) > (2, 31)), None)
    if real is None:
        pytest.fail("no library built for a glibc newer than 2.31 here (build/ is the development build)")
    try:
        root = subprocess.run(["bash", str(REPO / "scripts" / "blender_roots.sh"), "--path", "bullseye"],
                              capture_output=True, text=True, timeout=60).stdout.strip()
    except OSError:
        root = ""
    if not root or not os.path.isfile(os.path.join(root, ".libfx-root-complete")):
        pytest.skip("no Debian 11 root (bash scripts/blender_roots.sh bullseye)")
    work = REPO / "out" / "glibc-test"          # in_root.sh sees only the work tree
    shutil.rmtree(str(work), ignore_errors=True)
    (work / "deps").mkdir(parents=True)
    lib = work / "libfx.so.2"
    shutil.copy(str(real), str(lib))
    ldd = subprocess.run(["ldd", str(real)], capture_output=True, text=True).stdout
    system = ("libc.so", "libm.so", "ld-linux", "libstdc++", "libgcc_s", "libpthread", "libdl", "librt")
    for line in ldd.splitlines():
        parts = line.split("=>")
        if len(parts) == 2 and parts[1].split() and not any(s in parts[0] for s in system):
            shutil.copy(os.path.realpath(parts[1].split()[0]), str(work / "deps" / parts[0].strip()))
    code = ("import sys; sys.path.insert(0, %r); import native\n"
            "print(native.load() is not None); print(native.load_error())" % str(REPO / "addon" / "libfx"))
    try:
        p = subprocess.run(["bash", str(REPO / "scripts" / "in_root.sh"), "bullseye", "env",
                            "LD_LIBRARY_PATH=%s" % (work / "deps"), "LIBFX_LIBRARY=%s" % lib,
                            "python3", "-c", code], capture_output=True, text=True, timeout=120)
        assert p.returncode == 0, p.stdout + p.stderr
        loaded, why = p.stdout.splitlines()[:2]
        assert loaded == "False" and str(lib) in why, p.stdout
        assert "version `GLIBC_2.3" in why and "not found" in why, why
    finally:
        shutil.rmtree(str(work), ignore_errors=True)
