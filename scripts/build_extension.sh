#!/usr/bin/env bash
# Packs the add-on as a Blender 4.2+ extension (linux-x64) with the shared library
# inside, using Blender's own tools: `extension validate`, then `extension build`.
#   bash scripts/build_extension.sh [BUILD_DIR] [OUT_DIR]     (BLENDER=/path/to/blender)
# BUILD_DIR holds the libfx built for the Blender's system (default build/); the
# package lands in OUT_DIR (default BUILD_DIR) as libfx-<version>.zip, and its path
# is the last line printed. Blender 3.4-4.1 install the legacy zip instead
# (BUILD_DIR/libfx-addon-linux-x64.zip, made by the build).
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}
out=${2:-$build}
blender=${BLENDER:-blender}
[ -e "$build/libfx/libfx.so.2" ] || { echo "build_extension: no $build/libfx/libfx.so.2 (build libfx first)" >&2; exit 2; }
stage=$build/extension_stage/libfx
rm -rf "$build/extension_stage"
mkdir -p "$stage/lib" "$out"
cp addon/libfx/*.py addon/libfx/blender_manifest.toml "$stage/"
cp -L "$build/libfx/libfx.so.2" "$stage/lib/libfx.so.2"
"$blender" --factory-startup --command extension validate "$stage"
version=$(sed -n 's/^version = "\(.*\)"/\1/p' addon/libfx/blender_manifest.toml)
rm -f "$out/libfx-$version.zip"
"$blender" --factory-startup --command extension build --source-dir "$stage" --output-dir "$out" >&2
[ -s "$out/libfx-$version.zip" ] || { echo "build_extension: Blender made no $out/libfx-$version.zip" >&2; exit 1; }
echo "$out/libfx-$version.zip"
