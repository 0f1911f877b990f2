#!/usr/bin/env bash
# The linux-x64 extension on a system that has none of libfx's dependencies for it:
#
#  1. In a throw-away copy (overlay) of a Blender root (trixie: 4.3, unstable: 5.2) with
#     the development packages of OpenEXR, Imath, cJSON, libpng and libdeflate purged, the
#     zip installs with `extension install-file`, registers, and renders the mirror room
#     through the installed batch runner with the library its wheel brought (no
#     LIBFX_LIBRARY); every masked mirror changes and nothing else does. The runtime
#     packages of those libraries stay in this copy only because Debian's Blender itself
#     links them (Blender from blender.org bundles its own).
#  2. In a second copy with those runtime packages force-removed as well (Blender cannot
#     start there), `ldd` of the installed library shows only glibc, and plain Python
#     loads it from the installed wheel and blurs an EXR.
#
#   bash tests/platform/extension_in_root.sh SUITE EXTENSION_ZIP OUTDIR
# EXTENSION_ZIP and OUTDIR must lie inside this work tree (it is what the root sees).
set -euo pipefail
cd "$(dirname "$0")/../.."
here=$PWD
suite=${1:?usage: extension_in_root.sh SUITE EXTENSION_ZIP OUTDIR} zip=$(realpath "${2:?}") out=${3:?}
rm -rf "$out" && mkdir -p "$out" && out=$(realpath "$out")
case $zip/ in "$here"/*) ;; *) echo "extension_in_root: $zip is outside $here" >&2; exit 2 ;; esac
case $out/ in "$here"/*) ;; *) echo "extension_in_root: $out is outside $here" >&2; exit 2 ;; esac
ovl=$(mktemp -d /tmp/libfx-ovl.XXXXXX)
trap 'rm -rf "$ovl"' EXIT

DEV="libopenexr-dev libimath-dev libcjson-dev libpng-dev libdeflate-dev"
# Runtime packages by pattern: their names carry soname and t64 suffixes that differ by suite.
RUNTIME='^(libopenexr-3|libimath-3|libcjson1|libpng16-16|libdeflate0)'

echo "== $suite, step 1: Blender with the extension, no development packages"
IN_ROOT_OVERLAY=$ovl/a bash scripts/in_root.sh "$suite" env HOME="$out/home" ZIP="$zip" OUT="$out" DEV="$DEV" bash -c '
  set -euo pipefail
  export PATH=/usr/sbin:/sbin:$PATH   # dpkg wants ldconfig
  dpkg --purge --force-depends $DEV >"$OUT/purge-a.log" 2>&1 || { cat "$OUT/purge-a.log" >&2; exit 1; }
  for p in $DEV; do
    ! dpkg-query -W -f="\${Status}" "$p" 2>/dev/null | grep -q "install ok installed" \
      || { echo "still installed: $p" >&2; exit 1; }
  done
  echo "purged: $DEV"
  blender --version 2>/dev/null | head -1
  blender --factory-startup --command extension install-file "$ZIP" -r user_default --enable 2>&1 | tail -2
  ext=$(ls -d "$HOME"/.config/blender/*/extensions/user_default/libfx)
  lib=$(find "$HOME"/.config/blender/*/extensions/.local -name "libfx.so.2" | head -1)
  [ -n "$lib" ] || { echo "the installed extension brought no libfx.so.2 (from its wheel)" >&2; exit 1; }
  echo "installed: $ext; library: $lib"
  unset LIBFX_LIBRARY LIBFX_CLI
  blender -b blend_scenes/mirror_room/mirror_room.blend --python-exit-code 2 --python "$ext/batch.py" -- \
    --keep-passes --frames 1 --output "$OUT/mr_" --resolution 320x180 --samples 4 >"$OUT/render.log" 2>&1 \
    || { tail -40 "$OUT/render.log" >&2; exit 1; }
  # the add-on Blender registered took its library from the wheel Blender installed
  blender -b --python-expr "import importlib; n = importlib.import_module(\"bl_ext.user_default.libfx.native\"); \
n.load(); print(\"LIBFX-LIBRARY\", n.library_path())" 2>/dev/null | grep "^LIBFX-LIBRARY" >"$OUT/library.txt" || true
  [ "$(cat "$OUT/library.txt")" = "LIBFX-LIBRARY $lib" ] \
    || { echo "the add-on loaded \"$(cat "$OUT/library.txt")\", not the wheel'"'"'s $lib" >&2; exit 1; }
  echo "the add-on loads $lib"
  python3 tests/platform/check_mirror_room.py "$OUT/mr_"
'

echo "== $suite, step 2: no OpenEXR, Imath, cJSON, libpng or libdeflate at all"
src=$(cd .. && pwd)/shared/exr-corpus/openexr-images/TestImages/GrayRampsHorizontal.exr
IN_ROOT_OVERLAY=$ovl/b bash scripts/in_root.sh "$suite" env HOME="$out/home" RUNTIME="$RUNTIME" DEV="$DEV" \
    SRC="$src" OUT="$out" bash -c '
  set -euo pipefail
  export PATH=/usr/sbin:/sbin:$PATH
  gone=$(dpkg-query -W -f="\${Package}\n" | grep -E "$RUNTIME" | tr "\n" " ")
  dpkg --purge --force-depends $DEV $gone >"$OUT/purge-b.log" 2>&1 || { cat "$OUT/purge-b.log" >&2; exit 1; }
  left=$(dpkg-query -W -f="\${Package} \${Status}\n" | grep -E "$RUNTIME" | grep "install ok installed" || true)
  [ -z "$left" ] || { echo "still installed: $left" >&2; exit 1; }
  ! ls /usr/lib/x86_64-linux-gnu/ | grep -E "^lib(OpenEXR|Imath|cjson|png16|deflate)" \
    || { echo "library files left behind" >&2; exit 1; }
  echo "removed: $DEV $gone"
  lib=$(find "$HOME"/.config/blender/*/extensions/.local -name "libfx.so.2" | head -1)
  ldd "$lib"
  if ldd "$lib" | grep -vE "linux-vdso|ld-linux|lib(c|m|pthread|dl)\.so"; then
    echo "libfx needs more than glibc (above)" >&2; exit 1
  fi
  site=$(dirname "$(dirname "$(dirname "$lib")")")
  python3 - "$site" "$OUT" <<PY
import os, sys
sys.path.insert(0, sys.argv[1])
import libfx
src = "$SRC"
dst = os.path.join(sys.argv[2], "blur.exr")
libfx.run({"version": 1, "effects": [{"effect": "gaussian_blur", "params": {"sigma": 3}}]}, src, dst)
assert os.path.getsize(dst) > 0
print("plain python %s: libfx %s from %s blurred %s" % (sys.version.split()[0], libfx.version(),
                                                     libfx.library_path(), os.path.basename(src)))
PY
'
echo "extension_in_root: $suite passed"
