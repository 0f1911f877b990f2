"""Real files that are not a loadable libfx for this machine, made on the spot, for the
loading-error tests of native.py (tests/python) and of the add-on (tests/blender):

- truncated(real, dir): the first 4096 bytes of the real library (a copy cut short);
- elf32(dir): a real 32-bit i386 ELF shared object exporting fx_abi_version
  (binutils' `as --32` and `ld -m elf_i386`, which x86-64 binutils can do without
  a multilib compiler);
- windows_dll(dir): a real x86-64 Windows DLL (MinGW-w64's gcc, else one of wine's);
- missing(dir): a path with no file.

Each returns the path, or calls pytest.skip naming the tool that is missing.
"""
import glob
import os
import shutil
import subprocess

import pytest


def truncated(real, directory):
    out = os.path.join(str(directory), "libfx-truncated.so.2")
    with open(str(real), "rb") as f:
        head = f.read(4096)
    with open(out, "wb") as f:
        f.write(head)
    return out


def elf32(directory):
    d = str(directory)
    if not (shutil.which("as") and shutil.which("ld")):
        pytest.skip("binutils (as, ld) are not installed")
    src, obj, out = (os.path.join(d, n) for n in ("x32.s", "x32.o", "libfx-i386.so.2"))
    with open(src, "w") as f:
        f.write(".globl fx_abi_version\nfx_abi_version:\n  movl $2, %eax\n  ret\n")
    p = subprocess.run(["as", "--32", "-o", obj, src], capture_output=True, text=True)
    if p.returncode == 0:
        p = subprocess.run(["ld", "-m", "elf_i386", "-shared", "-o", out, obj], capture_output=True, text=True)
    if p.returncode != 0:
        pytest.skip("binutils cannot make a 32-bit ELF here: " + p.stderr.strip())
    return out


def windows_dll(directory):
    d = str(directory)
    out = os.path.join(d, "libfx.dll")
    gcc = shutil.which("x86_64-w64-mingw32-gcc")
    if gcc:
        src = os.path.join(d, "dll.c")
        with open(src, "w") as f:
            f.write("__declspec(dllexport) int fx_abi_version(void) { return 2; }\n")
        subprocess.run([gcc, "-shared", "-o", out, src], check=True, capture_output=True)
        return out
    found = sorted(glob.glob("/usr/lib/x86_64-linux-gnu/wine/x86_64-windows/*.dll"))
    if found:
        shutil.copy(found[0], out)
        return out
    pytest.skip("no x86-64 Windows DLL to try: install gcc-mingw-w64-x86-64 or wine64")


def missing(directory):
    return os.path.join(str(directory), "no-such-dir", "libfx.so.2")
