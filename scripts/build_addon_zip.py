#!/usr/bin/python3
"""The legacy add-on zip (Blender 3.4-4.1) for one platform from a built library,
laid out as addon/CMakeLists.txt lays out the development build's:

    /usr/bin/python3 scripts/build_addon_zip.py --platform linux-x64|windows-x64 \\
        --library PATH [--dev] --out DIR

    libfx/*.py, libfx/blender_manifest.toml   addon/libfx/
    libfx/lib/<library>                       libfx.so.2 (Linux), libfx.dll (Windows)

-> DIR/libfx-addon-<platform>.zip (printed). The library passes the same checks as
for the wheel (scripts/build_wheel.py: kind, architecture, truncation, portable
dependencies; --dev relaxes the last).
"""
import argparse
import glob
import os
import sys
import zipfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import build_wheel as W  # noqa: E402


def build(platform, library, out_dir, dev=False):
    W.check_library(platform, library, [], dev)
    lib_name = W.PLATFORMS[platform][1]
    addon = os.path.join(W.REPO, "addon", "libfx")
    files = sorted(glob.glob(os.path.join(addon, "*.py"))) + [os.path.join(addon, "blender_manifest.toml")]
    os.makedirs(out_dir, exist_ok=True)
    out = os.path.join(out_dir, "libfx-addon-%s.zip" % platform)
    tmp = out + ".tmp"
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        for f in files:
            z.write(f, "libfx/" + os.path.basename(f))
        info = zipfile.ZipInfo("libfx/lib/" + lib_name, (1980, 1, 1, 0, 0, 0))
        info.external_attr = 0o100755 << 16
        info.compress_type = zipfile.ZIP_DEFLATED
        with open(library, "rb") as f:
            z.writestr(info, f.read())
    os.replace(tmp, out)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--platform", required=True, choices=sorted(W.PLATFORMS))
    ap.add_argument("--library", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--dev", action="store_true")
    args = ap.parse_args(argv)
    try:
        print(build(args.platform, args.library, args.out, args.dev))
    except W.Refused as e:
        print("build_addon_zip: error: %s" % e, file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
