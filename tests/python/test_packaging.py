"""The packaging scripts' own rules, on real files: scripts/build_wheel.py refuses a
library that would not work where its wheel says it does (naming why), the committed
extension manifest lists the wheels build_wheel.py names, and the version is one.
The wheels themselves are tested in tests/platform/test_wheel.py."""
import os
import pathlib
import re
import subprocess
import sys
import zipfile

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import broken_libraries as B  # noqa: E402
from test_exr_interop import _library_path  # noqa: E402

REPO = pathlib.Path(__file__).resolve().parents[2]
BUILD_WHEEL = REPO / "scripts" / "build_wheel.py"


def _build(tmp_path, *args):
    return subprocess.run(["/usr/bin/python3", str(BUILD_WHEEL), "--out", str(tmp_path / "w")] + list(args),
                          capture_output=True, text=True, timeout=120)


def _real():
    lib = _library_path()
    if not lib.is_file():
        pytest.fail("libfx is not built at %s (build it, or set LIBFX_LIBRARY)" % lib)
    return str(lib.resolve())


def test_manifest_lists_the_wheels_build_wheel_makes():
    manifest = (REPO / "addon" / "libfx" / "blender_manifest.toml").read_text()
    version = re.search(r'^version = "([^"]+)"', manifest, re.M).group(1)
    cmake = re.search(r"project\(\s*libfx\s+VERSION\s+([0-9.]+)", (REPO / "CMakeLists.txt").read_text()).group(1)
    assert version == cmake
    platforms = re.findall(r'"([\w-]+)"', re.search(r"^platforms = \[(.*)\]", manifest, re.M).group(1))
    wheels = re.findall(r'"\./wheels/([^"]+)"', re.search(r"^wheels = \[(.*?)\]", manifest, re.M | re.S).group(1))
    assert platforms == ["linux-x64", "windows-x64"], platforms
    assert wheels == ["libfx-%s-py3-none-manylinux_2_31_x86_64.whl" % version,
                      "libfx-%s-py3-none-win_amd64.whl" % version], wheels


@pytest.mark.parametrize("kind", ["truncated", "32-bit", "windows-dll-as-linux", "missing"])
def test_build_wheel_refuses_a_library_that_cannot_work(tmp_path, kind):
    path = {"truncated": lambda: B.truncated(_real(), tmp_path),
            "32-bit": lambda: B.elf32(tmp_path),
            "windows-dll-as-linux": lambda: B.windows_dll(tmp_path),
            "missing": lambda: B.missing(tmp_path)}[kind]()
    p = _build(tmp_path, "--platform", "linux-x64", "--library", path, "--dev")
    assert p.returncode == 2 and path in p.stderr, p.stderr
    want = {"truncated": "truncated", "32-bit": "ELF 32-bit i386", "windows-dll-as-linux": "Windows PE",
            "missing": "no such file"}[kind]
    assert want in p.stderr, p.stderr
    assert not (tmp_path / "w").exists() or not list((tmp_path / "w").iterdir())


def test_build_wheel_refuses_a_dll_that_is_not_libfx(tmp_path):
    path = B.windows_dll(tmp_path)        # a real DLL, but MinGW's one exports fx_abi_version:
    data = pathlib.Path(path).read_bytes().replace(b"fx_abi_version\0", b"xx_abi_version\0")
    other = tmp_path / "other.dll"
    other.write_bytes(data)
    p = _build(tmp_path, "--platform", "windows-x64", "--library", str(other))
    assert p.returncode == 2 and "is not libfx" in p.stderr, p.stderr


def test_a_development_library_is_not_called_manylinux(tmp_path):
    """The source tree's build links the system's OpenEXR and a new glibc: refused for
    manylinux_2_31 naming what it needs; --dev packs it as linux_x86_64."""
    lib = _real()
    needs = subprocess.run(["readelf", "-d", lib], capture_output=True, text=True).stdout
    if "libOpenEXR" not in needs:
        pytest.skip("%s is self-contained (a release build): nothing to refuse" % lib)
    p = _build(tmp_path, "--platform", "linux-x64", "--library", lib)
    assert p.returncode == 2 and "manylinux_2_31" in p.stderr and "libOpenEXRCore" in p.stderr, p.stderr
    p = _build(tmp_path, "--platform", "linux-x64", "--library", lib, "--dev")
    assert p.returncode == 0, p.stderr
    wheel = p.stdout.strip().splitlines()[-1]
    assert wheel.endswith("-py3-none-linux_x86_64.whl"), wheel
    with zipfile.ZipFile(wheel) as z:
        version = os.path.basename(wheel).split("-")[1]
        assert "Tag: py3-none-linux_x86_64" in z.read("libfx-%s.dist-info/WHEEL" % version).decode()
