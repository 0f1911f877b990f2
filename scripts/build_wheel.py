#!/usr/bin/python3
"""Builds the `libfx` Python wheel for one platform from a built library, with the
standard library only (zipfile + hashlib; no pip, setuptools or PyPI):

    /usr/bin/python3 scripts/build_wheel.py --platform linux-x64 \\
        --library PATH/libfx.so.2 [--cli PATH/libfx] --out DIR
    /usr/bin/python3 scripts/build_wheel.py --platform windows-x64 \\
        --library PATH/libfx.dll [--extra-lib PATH/dep.dll ...] [--cli PATH/libfx.exe] --out DIR

The wheel (libfx-<version>-py3-none-<tag>.whl, printed as the last line) holds

    libfx/__init__.py, __main__.py   python/libfx/ (the public Python API)
    libfx/native.py                  a copy of addon/libfx/native.py, the one ctypes file
    libfx/lib/<library>              libfx.so.2 (Linux), libfx.dll (Windows)
    libfx/bin/libfx[.exe]            the command-line tool, with --cli
    libfx-<version>.dist-info/       METADATA, WHEEL (Root-Is-Purelib: false), entry_points.txt, RECORD

The tag is py3-none-<platform>: the binding is ctypes, so one wheel serves every
Python 3 (and every Blender) of the platform. Before packing, the library is
checked the way auditwheel would: the right binary kind and architecture, not cut
short, and for manylinux_2_31 no glibc/libstdc++ symbol version newer than Debian
11's and no shared library outside the manylinux policy; on Windows no DLL import
outside Windows itself and the --extra-lib files. A library that fails is refused,
naming what it needs; --dev packs it anyway, tagged linux_x86_64 on Linux (a wheel
for this machine only, never for release). The version is addon/libfx/
blender_manifest.toml's, which must equal CMakeLists.txt's project version.
"""

import argparse
import base64
import hashlib
import importlib.util
import io
import os
import re
import struct
import sys
import zipfile

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NATIVE = os.path.join(REPO, "addon", "libfx", "native.py")
PYTHON_PKG = os.path.join(REPO, "python", "libfx")

#: platform -> (release wheel tag, library file name, CLI file name, dev tag)
PLATFORMS = {
    "linux-x64": ("manylinux_2_31_x86_64", "libfx.so.2", "libfx", "linux_x86_64"),
    "windows-x64": ("win_amd64", "libfx.dll", "libfx.exe", None),
}

# manylinux_2_31 (PEP 600; auditwheel's policy for glibc 2.31, i.e. Debian 11/Ubuntu
# 20.04): the libraries a wheel may link from the system and the newest symbol
# version of each it may ask for.
MANYLINUX_LIBS = {
    "libc.so.6", "libm.so.6", "libdl.so.2", "librt.so.1", "libpthread.so.0", "libutil.so.1",
    "libresolv.so.2", "libnsl.so.1", "libgcc_s.so.1", "libstdc++.so.6", "ld-linux-x86-64.so.2",
}
MANYLINUX_MAX = {"GLIBC": (2, 31), "GLIBCXX": (3, 4, 28), "CXXABI": (1, 3, 12), "GCC": (10, 0)}

#: DLLs every Windows x64 has (the MinGW runtime links msvcrt or the UCRT).
WINDOWS_SYSTEM_DLL = re.compile(
    r"^(api-ms-win-[\w.-]+|kernel32|kernelbase|ntdll|msvcrt|ucrtbase|user32|advapi32|ws2_32|"
    r"bcrypt|shell32|ole32|oleaut32|gdi32|shlwapi|psapi|dbghelp|version|secur32|crypt32)\.dll$", re.I)


class Refused(Exception):
    pass


def _native():
    """addon/libfx/native.py as a module (stdlib only, no bpy; nothing is loaded)."""
    spec = importlib.util.spec_from_file_location("libfx_native_for_wheel", NATIVE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def project_version():
    with open(os.path.join(REPO, "addon", "libfx", "blender_manifest.toml"), encoding="utf-8") as f:
        m = re.search(r'^version\s*=\s*"([^"]+)"', f.read(), re.M)
    with open(os.path.join(REPO, "CMakeLists.txt"), encoding="utf-8") as f:
        c = re.search(r"project\(\s*libfx\s+VERSION\s+([0-9.]+)", f.read())
    if not m or not c:
        raise Refused("no version in addon/libfx/blender_manifest.toml or CMakeLists.txt's project()")
    if m.group(1) != c.group(1):
        raise Refused("blender_manifest.toml says version %s, CMakeLists.txt %s: make them agree"
                      % (m.group(1), c.group(1)))
    return m.group(1)


# ---------------------------------------------------------------- ELF (Linux)

def elf_dependencies(data):
    """(DT_NEEDED names, {"GLIBC": [(2, 14), ...], ...}) of a 64-bit little-endian ELF."""
    shoff, = struct.unpack_from("<Q", data, 40)
    shentsize, shnum, shstrndx = struct.unpack_from("<HHH", data, 58)
    sections = [struct.unpack_from("<IIQQQQIIQQ", data, shoff + i * shentsize) for i in range(shnum)]

    def cstr(sec, off):
        start = sec[4] + off
        return data[start:data.index(b"\0", start)].decode("ascii", "replace")

    needed, versions = [], {}
    for s in sections:
        stype, offset, size, link = s[1], s[4], s[5], s[6]
        if stype == 6:                                  # SHT_DYNAMIC
            for i in range(0, size, 16):
                tag, val = struct.unpack_from("<qQ", data, offset + i)
                if tag == 0:
                    break
                if tag == 1:                            # DT_NEEDED
                    needed.append(cstr(sections[link], val))
        elif stype == 0x6ffffffe:                       # SHT_GNU_verneed
            pos = offset
            while True:
                _, cnt, _, aux, nxt = struct.unpack_from("<HHIII", data, pos)
                apos = pos + aux
                for _ in range(cnt):
                    _, _, _, name, anext = struct.unpack_from("<IHHII", data, apos)
                    m = re.match(r"^([A-Z]+)_([0-9.]+)$", cstr(sections[link], name))
                    if m:
                        versions.setdefault(m.group(1), []).append(
                            tuple(int(x) for x in m.group(2).split(".")))
                    apos += anext
                    if not anext:
                        break
                if not nxt:
                    break
                pos += nxt
    return needed, versions


def audit_linux(path, data, extra_names):
    problems = []
    needed, versions = elf_dependencies(data)
    foreign = [n for n in needed if n not in MANYLINUX_LIBS and n not in extra_names]
    if foreign:
        problems.append("links shared libraries outside the manylinux policy: %s "
                        "(link them statically: the self-contained build)" % ", ".join(foreign))
    for family, limit in MANYLINUX_MAX.items():
        too_new = sorted(v for v in versions.get(family, []) if v > limit)
        if too_new:
            problems.append("needs %s_%s, newer than manylinux_2_31's %s_%s (build it on Debian 11)"
                            % (family, ".".join(map(str, too_new[-1])), family, ".".join(map(str, limit))))
    return problems, needed, versions


# ---------------------------------------------------------------- PE (Windows)

def pe_imports(data):
    """The DLL names a PE32+ file imports."""
    pe = struct.unpack_from("<I", data, 0x3c)[0]
    nsec, = struct.unpack_from("<H", data, pe + 6)
    optsize, = struct.unpack_from("<H", data, pe + 20)
    opt = pe + 24
    if struct.unpack_from("<H", data, opt)[0] != 0x20b:
        raise Refused("not a PE32+ (64-bit) image")
    imp_rva, _ = struct.unpack_from("<II", data, opt + 112 + 8)      # data directory 1
    secs = [struct.unpack_from("<8sIIII", data, opt + optsize + i * 40) for i in range(nsec)]

    def off(rva):
        for _, vsize, vaddr, rawsize, rawptr in secs:
            if vaddr <= rva < vaddr + max(vsize, rawsize):
                return rawptr + rva - vaddr
        raise Refused("import table outside every section")

    out = []
    if not imp_rva:
        return out
    pos = off(imp_rva)
    while True:
        name_rva = struct.unpack_from("<IIIII", data, pos)[3]
        if not name_rva:
            break
        start = off(name_rva)
        out.append(data[start:data.index(b"\0", start)].decode("ascii", "replace"))
        pos += 20
    return out


def audit_windows(path, data, extra_names):
    imports = pe_imports(data)
    lower = {n.lower() for n in extra_names}
    foreign = [n for n in imports if not WINDOWS_SYSTEM_DLL.match(n) and n.lower() not in lower]
    problems = []
    if foreign:
        problems.append("imports DLLs that are neither Windows' nor shipped with --extra-lib: %s"
                        % ", ".join(foreign))
    return problems, imports


# ---------------------------------------------------------------- checks

def check_library(platform, path, extras, dev):
    """The release tag, or the dev tag with --dev; raises Refused with every reason."""
    native = _native()
    tag, _, _, dev_tag = PLATFORMS[platform]
    if not os.path.isfile(path):
        raise Refused("%s: no such file" % path)
    kind = native.describe_file(path)
    want = {"linux-x64": "ELF 64-bit x86-64", "windows-x64": "Windows PE x86-64 DLL"}[platform]
    if kind != want:
        raise Refused("%s is %s, not the %s a %s library is" % (path, kind, want, platform))
    short = native.elf_truncation(path)
    if short:
        raise Refused("%s: %s" % (path, short))
    with open(path, "rb") as f:
        data = f.read()
    if b"fx_abi_version\0" not in data:
        raise Refused("%s is not libfx: it exports no fx_abi_version" % path)
    names = [os.path.basename(e) for e in extras]
    if platform == "linux-x64":
        problems, needed, versions = audit_linux(path, data, names)
        glibc = max(versions.get("GLIBC", [(0,)]))
        print("build_wheel: %s needs %s; newest GLIBC_%s" % (path, ", ".join(needed), ".".join(map(str, glibc))),
              file=sys.stderr)
    else:
        problems, imports = audit_windows(path, data, names)
        print("build_wheel: %s imports %s" % (path, ", ".join(imports)), file=sys.stderr)
    if problems and not dev:
        raise Refused("%s cannot go in a %s wheel: it %s" % (path, tag, "; it ".join(problems)))
    if problems:
        if dev_tag is None:
            raise Refused("%s: %s (and --dev has no tag for %s)" % (path, "; ".join(problems), platform))
        print("build_wheel: --dev: tagged %s, not %s, because it %s"
              % (dev_tag, tag, "; it ".join(problems)), file=sys.stderr)
        return dev_tag
    return tag


# ---------------------------------------------------------------- the wheel

def _record_hash(data):
    return "sha256=" + base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()


def build(platform, library, cli, extras, out_dir, dev=False):
    version = project_version()
    tag = check_library(platform, library, extras, dev)
    _, lib_name, cli_name, _ = PLATFORMS[platform]
    for e in extras:
        if not os.path.isfile(e):
            raise Refused("--extra-lib %s: no such file" % e)
    if cli and not os.path.isfile(cli):
        raise Refused("--cli %s: no such file" % cli)
    dist = "libfx-%s.dist-info" % version
    files = []   # (archive name, bytes, executable)

    def add_file(arcname, src, executable=False):
        with open(src, "rb") as f:
            files.append((arcname, f.read(), executable))

    for name in sorted(os.listdir(PYTHON_PKG)):
        if name.endswith(".py"):
            add_file("libfx/" + name, os.path.join(PYTHON_PKG, name))
    add_file("libfx/native.py", NATIVE)                      # the add-on's binding, copied now
    add_file("libfx/lib/" + lib_name, library, True)
    for e in extras:
        add_file("libfx/lib/" + os.path.basename(e), e, True)
    if cli:
        add_file("libfx/bin/" + cli_name, cli, True)

    with open(os.path.join(REPO, "README.md"), encoding="utf-8") as f:
        readme = f.read()
    metadata = "\n".join([
        "Metadata-Version: 2.1",
        "Name: libfx",
        "Version: " + version,
        "Summary: Render effects over Blender's multilayer OpenEXR passes (the C library and its ctypes binding)",
        "Author: libfx authors",
        "License: MIT",
        "Requires-Python: >=3.8",
        "Classifier: Programming Language :: Python :: 3",
        "Classifier: Programming Language :: C",
        "Classifier: Topic :: Multimedia :: Graphics",
        "Description-Content-Type: text/markdown",
        "", readme])
    wheel = "\n".join(["Wheel-Version: 1.0", "Generator: libfx scripts/build_wheel.py",
                       "Root-Is-Purelib: false", "Tag: py3-none-" + tag, ""])
    entry_points = "[console_scripts]\nlibfx = libfx.__main__:main\n" if cli else None
    files.append((dist + "/METADATA", metadata.encode("utf-8"), False))
    files.append((dist + "/WHEEL", wheel.encode("utf-8"), False))
    if entry_points:
        files.append((dist + "/entry_points.txt", entry_points.encode("utf-8"), False))
    record = "".join("%s,%s,%d\n" % (n, _record_hash(d), len(d)) for n, d, _ in files)
    record += dist + "/RECORD,,\n"
    files.append((dist + "/RECORD", record.encode("utf-8"), False))

    os.makedirs(out_dir, exist_ok=True)
    out = os.path.join(out_dir, "libfx-%s-py3-none-%s.whl" % (version, tag))
    # Reproducible: fixed order, time (SOURCE_DATE_EPOCH when set) and permissions.
    epoch = int(os.environ.get("SOURCE_DATE_EPOCH", "315532800"))
    import time
    stamp = time.gmtime(max(epoch, 315532800))[:6]
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data, executable in files:
            info = zipfile.ZipInfo(name, stamp)
            info.external_attr = (0o100755 if executable else 0o100644) << 16
            info.compress_type = zipfile.ZIP_DEFLATED
            z.writestr(info, data)
    tmp = out + ".tmp"
    with open(tmp, "wb") as f:
        f.write(buf.getvalue())
    os.replace(tmp, out)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--platform", required=True, choices=sorted(PLATFORMS))
    ap.add_argument("--library", required=True, help="the built libfx shared library")
    ap.add_argument("--cli", help="the libfx command-line tool to ship in libfx/bin/")
    ap.add_argument("--extra-lib", action="append", default=[],
                    help="a library the main one needs, shipped beside it in libfx/lib/ (repeatable)")
    ap.add_argument("--out", required=True, help="output directory")
    ap.add_argument("--dev", action="store_true",
                    help="pack a library that fails the portability check (tagged linux_x86_64: "
                         "for this machine, never for release)")
    args = ap.parse_args(argv)
    try:
        out = build(args.platform, args.library, args.cli, args.extra_lib, args.out, args.dev)
    except Refused as e:
        print("build_wheel: error: %s" % e, file=sys.stderr)
        return 2
    print(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
