#!/usr/bin/env bash
# The inputs of the cross-build check: the three scenes rendered small by the host's
# Blender through the add-on's batch runner (passes EXR, scene sidecar with its aux
# views). Made once into DIR and reused while DIR/complete exists.
#   bash tests/matrix/make_bits_inputs.sh DIR
set -euo pipefail
cd "$(dirname "$0")/../.."
dir=${1:?usage: make_bits_inputs.sh DIR}
[ -f "$dir/complete" ] && exit 0
rm -rf "$dir"
mkdir -p "$dir"
export LIBFX_LIBRARY="$PWD/build/libfx/libfx.so"
for scene in greek_bath atrium mirror_room; do
  blender -b --factory-startup "blend_scenes/$scene/$scene.blend" --python-exit-code 3 \
    --python addon/libfx/batch.py -- --keep-passes --frames 1 --output "$dir/$scene/" \
    --resolution 160x90 --samples 2 >"$dir/$scene.log" 2>&1 \
    || { echo "make_bits_inputs: $scene failed (see $dir/$scene.log)" >&2; tail -5 "$dir/$scene.log" >&2; exit 1; }
done
date -u >"$dir/complete"
