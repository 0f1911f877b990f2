"""The add-on's ctypes layer (addon/libfx/native.py, no bpy) loading a library: the core
functions are required and a missing one is named with the library's path; a function
only one feature uses may be missing (an older libfx.so): that feature is off and says
why; the ABI is checked before anything else is used."""
import importlib.util
import os
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
