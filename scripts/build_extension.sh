#!/usr/bin/env bash
# Packs the add-on as a Blender 4.2+ extension, one zip per platform, with Blender's
# own tools: `extension validate`, then `extension build --split-platforms`.
#
#   BLENDER=blender bash scripts/build_extension.sh OUT_DIR WHEEL_OR_DIR...
#
# WHEEL_OR_DIR: libfx wheels (scripts/build_wheel.py), or folders of them. The
# extension carries no library of its own: each platform's library comes in its
# wheel, which Blender installs into its site-packages, where native.py finds it.
# The wheels are staged under wheels/, and the staged manifest lists exactly the
# given wheels and their platforms (the committed addon/libfx/blender_manifest.toml
# lists the release's: linux-x64 and windows-x64; giving fewer wheels builds fewer
# platforms, with a note). The zips land in OUT_DIR as
# libfx-<version>-<platform>.zip (linux_x64, windows_x64); their paths are printed,
# one a line, last. Blender 3.4-4.1 install the legacy zip instead
# (build/libfx-addon-linux-x64.zip, made by the build).
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
[ $# -ge 2 ] || { echo "usage: build_extension.sh OUT_DIR WHEEL_OR_DIR..." >&2; exit 2; }
out=$1; shift
blender=${BLENDER:-blender}
wheels=()
for w in "$@"; do
  if [ -d "$w" ]; then
    for f in "$w"/libfx-*.whl; do [ -e "$f" ] && wheels+=("$f"); done
  elif [ -f "$w" ]; then
    wheels+=("$w")
  else
    echo "build_extension: no wheel or folder $w" >&2; exit 2
  fi
done
[ ${#wheels[@]} -gt 0 ] || { echo "build_extension: no libfx-*.whl in $*" >&2; exit 2; }
mkdir -p "$out"
out=$(cd "$out" && pwd)
stage=$(mktemp -d "$out/.extension_stage.XXXXXX")
trap 'rm -rf "$stage"' EXIT
mkdir -p "$stage/libfx/wheels"
cp "$here"/addon/libfx/*.py "$here/addon/libfx/blender_manifest.toml" "$stage/libfx/"
for w in "${wheels[@]}"; do cp "$w" "$stage/libfx/wheels/"; done

# The staged manifest: platforms and wheels from the wheels given (Blender's own
# mapping of wheel tags: manylinux_*_x86_64 / linux_x86_64 -> linux-x64, win_amd64 ->
# windows-x64), in the committed manifest's order.
/usr/bin/env python3 - "$stage/libfx" <<'EOF'
import os, re, sys
stage = sys.argv[1]
path = os.path.join(stage, "blender_manifest.toml")
text = open(path, encoding="utf-8").read()
version = re.search(r'^version = "([^"]+)"', text, re.M).group(1)
def platform(tag):
    if re.fullmatch(r"(many)?linux(_\d+_\d+|\d+)?_x86_64", tag): return "linux-x64"
    if tag == "win_amd64": return "windows-x64"
    if re.fullmatch(r"macosx_\d+_\d+_arm64", tag): return "macos-arm64"
    if re.fullmatch(r"macosx_\d+_\d+_x86_64", tag): return "macos-x64"
    sys.exit("build_extension: no Blender platform for the wheel tag %s" % tag)
found = {}
for name in sorted(os.listdir(os.path.join(stage, "wheels"))):
    m = re.fullmatch(r"libfx-([^-]+)-py3-none-(\w+)\.whl", name)
    if not m:
        sys.exit("build_extension: %s is not a libfx py3-none wheel" % name)
    if m.group(1) != version:
        sys.exit("build_extension: %s is version %s, the add-on %s" % (name, m.group(1), version))
    p = platform(m.group(2))
    if p in found:
        sys.exit("build_extension: two wheels for %s: %s and %s" % (p, found[p], name))
    found[p] = name
listed = re.findall(r'"([\w-]+)"', re.search(r"^platforms = \[(.*)\]", text, re.M).group(1))
order = [p for p in listed if p in found] + sorted(p for p in found if p not in listed)
missing = [p for p in listed if p not in found]
if missing:
    print("build_extension: note: no wheel for %s: building %s only" % (", ".join(missing), ", ".join(order)),
          file=sys.stderr)
text = re.sub(r"^platforms = \[.*\]$", "platforms = [%s]" % ", ".join('"%s"' % p for p in order), text, flags=re.M)
text = re.sub(r"^wheels = \[.*?\]$", "wheels = [\n%s\n]" % ",\n".join('  "./wheels/%s"' % found[p] for p in order),
              text, flags=re.M | re.S)
open(path, "w", encoding="utf-8").write(text)
EOF

"$blender" --factory-startup --command extension validate "$stage/libfx" >&2
version=$(sed -n 's/^version = "\(.*\)"/\1/p' "$here/addon/libfx/blender_manifest.toml")
platforms=$(sed -n 's/^platforms = \[\(.*\)\]/\1/p' "$stage/libfx/blender_manifest.toml" | tr -d '" ' | tr ',' ' ')
for p in $platforms; do rm -f "$out/libfx-$version-${p/-/_}.zip"; done
"$blender" --factory-startup --command extension build --split-platforms \
  --source-dir "$stage/libfx" --output-dir "$out" >&2
for p in $platforms; do
  zip="$out/libfx-$version-${p/-/_}.zip"
  [ -s "$zip" ] || { echo "build_extension: Blender made no $zip" >&2; exit 1; }
  echo "$zip"
done
