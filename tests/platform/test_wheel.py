"""The libfx wheels as a user gets them: every wheel is checked as a zip (dist-info,
tag, RECORD hashes, the binding equal to the add-on's native.py, the library of the
platform's kind); a wheel for this machine is installed with pip into a fresh venv
(no index, no network) and runs a Gaussian blur on a real EXR there.

    LIBFX_WHEEL=out/pkg/libfx-0.1.0-py3-none-manylinux_2_31_x86_64.whl \\
        /usr/bin/python3 -m pytest -q tests/platform/test_wheel.py
    LIBFX_WHEEL=out/pkg      # every *.whl in the folder

A wheel for another platform (win_amd64 here) gets the zip checks only.
"""
import base64
import csv
import glob
import hashlib
import io
import json
import os
import pathlib
import re
import subprocess
import sys
import sysconfig
import zipfile

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]
CORPUS = (REPO / ".." / "shared" / "exr-corpus").resolve()
INPUT = CORPUS / "openexr-images" / "TestImages" / "GrayRampsHorizontal.exr"
PYTHON = "/usr/bin/python3"
LIB_NAMES = {"manylinux_2_31_x86_64": "libfx.so.2", "linux_x86_64": "libfx.so.2", "win_amd64": "libfx.dll"}
KINDS = {"libfx.so.2": b"\x7fELF", "libfx.dll": b"MZ"}


def _wheels():
    spec = os.environ.get("LIBFX_WHEEL")
    if not spec:
        return []
    out = []
    for part in spec.split(os.pathsep):
        p = pathlib.Path(part)
        out += sorted(pathlib.Path(x) for x in glob.glob(str(p / "*.whl"))) if p.is_dir() else [p]
    return out


WHEELS = _wheels()
if not WHEELS and __name__ != "__main__":
    pytest.fail("LIBFX_WHEEL names no wheel (set it to a .whl or a folder of them)", pytrace=False)


def _tag(wheel):
    m = re.match(r"^libfx-([0-9.]+)-py3-none-([a-z0-9_]+)\.whl$", wheel.name)
    assert m, "not a libfx py3-none wheel name: %s" % wheel.name
    return m.group(1), m.group(2)


def _installable_here(platform_tag):
    here = sysconfig.get_platform().replace("-", "_").replace(".", "_")   # linux_x86_64
    if platform_tag == here:
        return True
    m = re.match(r"^manylinux_(\d+)_(\d+)_(\w+)$", platform_tag)
    if m and here == "linux_" + m.group(3):
        libc = os.confstr("CS_GNU_LIBC_VERSION").split()[-1].split(".")
        return (int(libc[0]), int(libc[1])) >= (int(m.group(1)), int(m.group(2)))
    return False


@pytest.mark.parametrize("wheel", WHEELS, ids=[w.name for w in WHEELS])
def test_wheel_contents(wheel):
    assert wheel.is_file(), wheel
    version, platform_tag = _tag(wheel)
    lib_name = LIB_NAMES[platform_tag]
    dist = "libfx-%s.dist-info" % version
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
        assert z.testzip() is None
        for required in ("libfx/__init__.py", "libfx/native.py", "libfx/lib/" + lib_name,
                         dist + "/METADATA", dist + "/WHEEL", dist + "/RECORD"):
            assert required in names, (required, names)
        wheel_meta = z.read(dist + "/WHEEL").decode()
        assert "Root-Is-Purelib: false" in wheel_meta, wheel_meta
        assert "Tag: py3-none-%s" % platform_tag in wheel_meta, wheel_meta
        meta = z.read(dist + "/METADATA").decode()
        assert "Name: libfx" in meta and "Version: %s" % version in meta, meta[:400]
        # RECORD: every file once, with its sha256 and size
        rows = list(csv.reader(io.StringIO(z.read(dist + "/RECORD").decode())))
        recorded = {r[0]: r for r in rows}
        assert set(recorded) == set(names), set(recorded) ^ set(names)
        for name, digest, size in rows:
            if name == dist + "/RECORD":
                assert digest == "" and size == ""
                continue
            data = z.read(name)
            want = "sha256=" + base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
            assert digest == want and int(size) == len(data), name
        # the binding is the add-on's, copied at build time
        assert z.read("libfx/native.py") == (REPO / "addon" / "libfx" / "native.py").read_bytes(), \
            "the wheel's native.py is not addon/libfx/native.py (rebuild the wheel)"
        lib = z.read("libfx/lib/" + lib_name)
        assert lib.startswith(KINDS[lib_name]) and b"fx_abi_version\0" in lib
        assert not any(n.endswith((".pyc", "/")) or "__pycache__" in n for n in names), names


@pytest.mark.parametrize("wheel", WHEELS, ids=[w.name for w in WHEELS])
def test_pip_installs_the_wheel_and_it_blurs_an_exr(wheel, tmp_path):
    _, platform_tag = _tag(wheel)
    if not _installable_here(platform_tag):
        pytest.skip("a %s wheel does not install on %s" % (platform_tag, sysconfig.get_platform()))
    if not INPUT.is_file():
        pytest.skip("the shared EXR corpus is absent (%s)" % INPUT)
    venv = tmp_path / "venv"
    subprocess.run([PYTHON, "-m", "venv", str(venv)], check=True, capture_output=True)
    py = str(venv / "bin" / "python")
    env = {k: v for k, v in os.environ.items() if k not in ("LIBFX_LIBRARY", "PYTHONPATH")}
    p = subprocess.run([py, "-m", "pip", "install", "--no-index", "--disable-pip-version-check",
                        str(wheel)], capture_output=True, text=True, env=env, timeout=300)
    assert p.returncode == 0, p.stdout + p.stderr
    out = tmp_path / "blurred.exr"
    # the user's ten lines: import, blur, check (from tmp_path: nothing of the source tree)
    script = """
import json, sys, libfx
recipe = {"version": 1, "effects": [{"effect": "gaussian_blur", "params": {"sigma": 4.0}}]}
warnings = libfx.run(recipe, sys.argv[1], sys.argv[2], quality="final")
with libfx.Context() as ctx:
    frame = libfx.Frame.read(ctx, sys.argv[2])
    print(json.dumps({"file": libfx.__file__, "library": libfx.library_path(), "version": libfx.version(),
                      "effects": libfx.effects(), "size": [frame.width, frame.height],
                      "passes": frame.pass_names(), "warnings": warnings}))
    frame.close()
"""
    p = subprocess.run([py, "-c", script, str(INPUT), str(out)], capture_output=True, text=True,
                       env=env, cwd=str(tmp_path), timeout=300)
    assert p.returncode == 0, p.stdout + p.stderr
    info = json.loads(p.stdout.strip().splitlines()[-1])
    site = str(venv)
    assert info["file"].startswith(site) and info["library"].startswith(site), info
    assert info["library"].endswith(os.path.join("libfx", "lib", LIB_NAMES[platform_tag])), info
    assert "gaussian_blur" in info["effects"] and info["size"][0] > 0, info
    assert out.is_file() and out.stat().st_size > 0
    assert not list(tmp_path.glob(".blurred.exr.tmp*")), "a temporary file was left"
    _pixels_changed_but_mean_kept(INPUT, out)

    # a failure is an exception naming the file, not a crash
    p = subprocess.run([py, "-c", "import libfx, sys\n"
                        "try:\n    libfx.run({'version': 1, 'effects': []}, sys.argv[1], 'x.exr')\n"
                        "except libfx.LibfxError as e:\n    print('ERR', e); sys.exit(7)\n",
                        str(tmp_path / "missing.exr")], capture_output=True, text=True, env=env,
                       cwd=str(tmp_path), timeout=120)
    assert p.returncode == 7 and "missing.exr" in p.stdout, p.stdout + p.stderr

    # the command-line tool, when the wheel has it, runs through the console script
    with zipfile.ZipFile(wheel) as z:
        has_cli = any(n.startswith("libfx/bin/") for n in z.namelist())
    if has_cli:
        tool = str(venv / "bin" / "libfx")
        p = subprocess.run([tool, "list"], capture_output=True, text=True, env=env, cwd=str(tmp_path), timeout=120)
        assert p.returncode == 0 and "gaussian_blur" in p.stdout, p.stdout + p.stderr
        # one engine, two doors: the tool's `run` writes the bytes libfx.run() wrote, and
        # a sidecar given to libfx.run() puts the camera into the output as --sidecar does
        recipe = tmp_path / "blur.json"
        recipe.write_text(json.dumps({"version": 1, "quality": "final",
                                      "effects": [{"effect": "gaussian_blur", "params": {"sigma": 4.0}}]}))
        by_tool = tmp_path / "by_tool.exr"
        p = subprocess.run([tool, "run", "--stack", str(recipe), str(INPUT), "-o", str(by_tool)],
                           capture_output=True, text=True, env=env, cwd=str(tmp_path), timeout=300)
        assert p.returncode == 0, p.stdout + p.stderr
        assert by_tool.read_bytes() == out.read_bytes(), "libfx.run() and `libfx run` differ"
        side = {"world_to_camera": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -5], [0, 0, 0, 1]],
                "projection": [[1.5, 0, 0, 0], [0, 2.0, 0, 0], [0, 0, -1.002, -0.2002], [0, 0, -1, 0]],
                "clip_start": 0.1, "clip_end": 100.0, "frame": 3, "fps": 24}
        p = subprocess.run([py, "-c", "import json, sys, libfx\n"
                            "libfx.run(json.loads(sys.argv[1]), sys.argv[2], 'cam.exr', sidecar=json.loads(sys.argv[3]))",
                            recipe.read_text(), str(INPUT), json.dumps(side)],
                           capture_output=True, text=True, env=env, cwd=str(tmp_path), timeout=300)
        assert p.returncode == 0, p.stdout + p.stderr
        p = subprocess.run([tool, "info", "--compact", str(tmp_path / "cam.exr")], capture_output=True,
                           text=True, env=env, cwd=str(tmp_path), timeout=120)
        assert p.returncode == 0 and json.loads(p.stdout)["camera"] is True, p.stdout + p.stderr


def _pixels_changed_but_mean_kept(src, dst):
    """With OpenImageIO (Debian's python3-openimageio): the blur changed the pixels and
    kept the mean (GUIDE §5's property); without it, the file checks above stand."""
    try:
        import numpy as np
        import OpenImageIO as oiio
    except ImportError:
        return
    a, b = oiio.ImageBuf(str(src)), oiio.ImageBuf(str(dst))
    assert not a.has_error and not b.has_error, (a.geterror(), b.geterror())
    pa = np.asarray(a.get_pixels(oiio.FLOAT))[..., 0]          # the input's first channel (Y)
    names = b.spec().channelnames
    red = next(i for i, n in enumerate(names) if n.split(".")[-1] == "R")
    pb = np.asarray(b.get_pixels(oiio.FLOAT))[..., red]        # libfx's Combined.R from it
    assert pa.shape == pb.shape, (pa.shape, pb.shape, names)
    assert np.abs(pa - pb).max() > 1e-3, "the blur changed nothing"
    assert abs(float(pa.mean()) - float(pb.mean())) < 2e-3 * max(1.0, abs(float(pa.mean())))


if __name__ == "__main__":   # python3 tests/platform/test_wheel.py WHEEL...
    if len(sys.argv) > 1:
        os.environ["LIBFX_WHEEL"] = os.pathsep.join(sys.argv[1:])
    sys.exit(pytest.main(["-q", "-p", "no:cacheprovider", __file__]))


WINE = "/usr/lib/wine/wine64"   # Debian's wine64 (GUIDE §3c): not on PATH


@pytest.mark.parametrize("wheel", [w for w in WHEELS if w.name.endswith("-win_amd64.whl")] or
                         [pytest.param(None, marks=pytest.mark.skip(reason="no win_amd64 wheel given"))])
def test_windows_wheel_tool_and_dll_run_under_wine(wheel, tmp_path):
    """No Windows Python here: the wheel's libfx.exe, loading the wheel's libfx.dll from
    libfx/lib/, blurs an EXR under wine: the DLL the Windows users get is a working one."""
    if not os.path.exists(WINE):
        pytest.skip("wine64 is not installed (apt-get install wine64)")
    if not INPUT.is_file():
        pytest.skip("the shared EXR corpus is absent (%s)" % INPUT)
    with zipfile.ZipFile(wheel) as z:
        if "libfx/bin/libfx.exe" not in z.namelist():
            pytest.skip("this Windows wheel was built without the command-line tool (--cli)")
        z.extractall(tmp_path / "w")
    pkg = tmp_path / "w" / "libfx"
    recipe = tmp_path / "blur.json"
    recipe.write_text(json.dumps({"version": 1, "effects": [{"effect": "gaussian_blur", "params": {"sigma": 4.0}}]}))
    out = tmp_path / "blurred.exr"
    env = dict(os.environ, WINEDEBUG="-all", WINEPATH="Z:" + str(pkg / "lib").replace("/", "\\"))
    p = subprocess.run([WINE, str(pkg / "bin" / "libfx.exe"), "run", "--stack", str(recipe), str(INPUT),
                        "-o", str(out)], capture_output=True, text=True, env=env, timeout=300)
    assert p.returncode == 0, p.stdout + p.stderr
    _pixels_changed_but_mean_kept(INPUT, out)
