#!/usr/bin/env bash
# The release packages from the two release libraries, and their checks: what CI calls.
#
#   bash scripts/package.sh LINUX_LIB WINDOWS_DLL OUTDIR [options]
#     --linux-cli PATH     the Linux `libfx` tool, shipped in the Linux wheel
#     --windows-cli PATH   libfx.exe, shipped in the Windows wheel
#     --dev                accept libraries that are not portable (a development build:
#                          the Linux wheel is then tagged linux_x86_64; never for release)
#     --blender-root SUITE the Debian root whose Blender (4.2+) builds and installs the
#                          extension (default: trixie; BLENDER=path uses that Blender instead)
#
# Makes, in OUTDIR:
#   libfx-<v>-py3-none-manylinux_2_31_x86_64.whl, libfx-<v>-py3-none-win_amd64.whl  (scripts/build_wheel.py)
#   libfx-<v>-linux_x64.zip, libfx-<v>-windows_x64.zip        4.2+ extensions (scripts/build_extension.sh)
#   libfx-addon-linux-x64.zip, libfx-addon-windows-x64.zip    3.4-4.1 legacy add-on zips
# then checks them: tests/platform/test_wheel.py on both wheels (pip into a fresh venv
# and a Gaussian blur for the Linux one; the Windows one's tool and DLL run under wine
# when wine64 and --windows-cli are there), `extension validate` on each extension
# zip, and `extension install-file` of the Linux zip into a fresh profile, where the
# add-on must register and load its library from the installed wheel.
# Prints the packages (path and size) and the wall time; exits non-zero on any failure.
set -euo pipefail
t0=$SECONDS
here=$(cd "$(dirname "$0")/.." && pwd)
[ $# -ge 3 ] || { sed -n '2,12p' "$0" >&2; exit 2; }
linux_lib=$(readlink -f "$1") win_dll=$(readlink -f "$2") outdir=$3; shift 3
linux_cli= win_cli= dev=() suite=trixie
while [ $# -gt 0 ]; do
  case $1 in
    --linux-cli) linux_cli=$(readlink -f "$2"); shift 2 ;;
    --windows-cli) win_cli=$(readlink -f "$2"); shift 2 ;;
    --dev) dev=(--dev); shift ;;
    --blender-root) suite=$2; shift 2 ;;
    *) echo "package: unknown option $1" >&2; exit 2 ;;
  esac
done
mkdir -p "$outdir"
outdir=$(cd "$outdir" && pwd)
py=/usr/bin/python3
stamp() { echo "== package: $* ($((SECONDS - t0)) s)"; }

# Blender 4.2+ for `--command extension`: $BLENDER, else the Debian root's.
if [ -n "${BLENDER:-}" ]; then
  blender_run=(env)
  blender_cmd=$BLENDER
else
  blender_run=(bash "$here/scripts/in_root.sh" "$suite" env)
  blender_cmd=blender
fi
# The root sees only the work tree (and ../shared): stage under it.
work=$(mktemp -d "$here/out/.package.XXXXXX" 2>/dev/null || { mkdir -p "$here/out"; mktemp -d "$here/out/.package.XXXXXX"; })
trap 'rm -rf "$work"' EXIT

stamp "wheels"
$py "$here/scripts/build_wheel.py" --platform linux-x64 --library "$linux_lib" \
  ${linux_cli:+--cli "$linux_cli"} "${dev[@]}" --out "$work/wheels" >"$work/linux-wheel"
$py "$here/scripts/build_wheel.py" --platform windows-x64 --library "$win_dll" \
  ${win_cli:+--cli "$win_cli"} --out "$work/wheels" >"$work/windows-wheel"
linux_whl=$(tail -1 "$work/linux-wheel") win_whl=$(tail -1 "$work/windows-wheel")

stamp "legacy add-on zips (Blender 3.4-4.1)"
$py "$here/scripts/build_addon_zip.py" --platform linux-x64 --library "$linux_lib" "${dev[@]}" --out "$work/legacy" >/dev/null
$py "$here/scripts/build_addon_zip.py" --platform windows-x64 --library "$win_dll" --out "$work/legacy" >/dev/null

stamp "extensions (Blender 4.2+, split per platform)"
"${blender_run[@]}" HOME="$work/home-build" BLENDER="$blender_cmd" \
  bash "$here/scripts/build_extension.sh" "$work/ext" "$linux_whl" "$win_whl" >"$work/ext-list"
mapfile -t ext_zips <"$work/ext-list"
[ ${#ext_zips[@]} -eq 2 ] || { echo "package: expected two extension zips, got: ${ext_zips[*]}" >&2; exit 1; }

stamp "check: the wheels (tests/platform/test_wheel.py)"
LIBFX_WHEEL="$linux_whl:$win_whl" $py -m pytest -q -p no:cacheprovider "$here/tests/platform/test_wheel.py"

stamp "check: extension validate of each zip"
for z in "${ext_zips[@]}"; do
  "${blender_run[@]}" HOME="$work/home-build" "$blender_cmd" --factory-startup --command extension validate "$z"
done

stamp "check: the Linux extension installs and loads its library from the wheel"
linux_zip=$(printf '%s\n' "${ext_zips[@]}" | grep -- '-linux_x64\.zip$')
probe='import sys, bpy
m = sys.modules.get("bl_ext.user_default.libfx")
assert m is not None and hasattr(bpy.types.Scene, "libfx"), "the extension did not register"
assert m.native.load() is not None, m.native.load_error()
import libfx
assert "site-packages" in m.native.library_path() and libfx.__file__ != m.__file__, (m.native.library_path(), libfx.__file__)
print("PACKAGE-CHECK", bpy.app.version_string, m.native.library_path(), m.native.version())'
"${blender_run[@]}" HOME="$work/home-install" "$blender_cmd" --command extension install-file "$linux_zip" \
  -r user_default --enable >"$work/install.log" 2>&1 || { cat "$work/install.log" >&2; exit 1; }
"${blender_run[@]}" HOME="$work/home-install" "$blender_cmd" -b --python-exit-code 3 --python-expr "$probe" \
  >"$work/probe.log" 2>&1 || { tail -30 "$work/probe.log" >&2; exit 1; }
grep '^PACKAGE-CHECK' "$work/probe.log"

# Blender 3.4-4.1 (Debian 12's 3.4 here): the legacy Linux zip installs and loads its lib/.
legacy=${LEGACY_BLENDER:-/usr/bin/blender}
if [ -x "$legacy" ] && "$legacy" -b --factory-startup --python-expr \
     'import bpy, sys; sys.exit(0 if bpy.app.version < (4, 2, 0) else 1)' >/dev/null 2>&1; then
  stamp "check: the legacy Linux zip installs in $("$legacy" -b --version 2>/dev/null | head -1) and loads its lib/"
  install='import bpy
bpy.ops.preferences.addon_install(filepath=sys.argv[-1])
bpy.ops.preferences.addon_enable(module="libfx")
m = sys.modules["libfx"]
assert m.native.load() is not None, m.native.load_error()
assert m.native.library_path() == os.path.join(os.path.dirname(m.__file__), "lib", "libfx.so.2"), m.native.library_path()
print("PACKAGE-CHECK", bpy.app.version_string, m.native.library_path(), m.native.version())'
  env -u LIBFX_LIBRARY HOME="$work/home-legacy" "$legacy" -b --factory-startup --python-exit-code 3 \
    --python-expr "import sys, os
$install" -- "$work/legacy/libfx-addon-linux-x64.zip" >"$work/legacy.log" 2>&1 || { tail -30 "$work/legacy.log" >&2; exit 1; }
  grep '^PACKAGE-CHECK' "$work/legacy.log"
fi

mv -f "$linux_whl" "$win_whl" "${ext_zips[@]}" "$work"/legacy/*.zip "$outdir/"
stamp "done"
for f in "$outdir"/$(basename "$linux_whl") "$outdir"/$(basename "$win_whl") \
         "$outdir"/$(basename "${ext_zips[0]}") "$outdir"/$(basename "${ext_zips[1]}") \
         "$outdir"/libfx-addon-linux-x64.zip "$outdir"/libfx-addon-windows-x64.zip; do
  printf '%s\t%s\n' "$(stat -c %s "$f")" "$f"
done
echo "package: wall time $((SECONDS - t0)) s"
