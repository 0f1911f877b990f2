#!/usr/bin/env bash
# The add-on's F12 path in each Blender's UI, under a virtual display: the Greek bath
# rendered with F12, "libfx Result" in the Image Editor, the libfx panel beside it.
# Writes docs/images/addon_f12_blender<major.minor>.png per Blender.
#   bash scripts/addon_screenshots.sh [host|trixie|unstable ...]
set -euo pipefail
cd "$(dirname "$0")/.."
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(host trixie unstable)
for t in "${targets[@]}"; do
  if [ "$t" = host ]; then run=() build=build; else run=(bash scripts/in_root.sh "$t") build=build-$t; fi
  [ -e "$build/libfx/libfx.so" ] || { echo "screenshots: build libfx in $build first (scripts/blender_matrix.sh $t)" >&2; exit 2; }
  ver=$("${run[@]}" blender -b --factory-startup --version 2>/dev/null | sed -n 's/^Blender \([0-9]*\.[0-9]*\).*/\1/p' | head -1)
  shot=docs/images/addon_f12_blender$ver.png
  # A profile with saved preferences: 4.2+ show their first-start Quick Setup over
  # the window otherwise.
  home=$PWD/out/screenshot_home_$t
  rm -rf "$home" && mkdir -p "$home"
  "${run[@]}" env HOME="$home" blender -b --factory-startup --python-expr \
    "import bpy; bpy.ops.wm.save_userpref()" >/dev/null 2>&1
  "${run[@]}" env HOME="$home" LIBFX_LIBRARY="$PWD/$build/libfx/libfx.so" xvfb-run -a -s "-screen 0 1600x900x24" \
    blender --factory-startup blend_scenes/greek_bath/greek_bath.blend \
    --python tests/blender/panel_screenshot.py -- "$PWD/$shot" >"out/screenshot_$t.log" 2>&1 \
    || { echo "screenshots: $t failed (out/screenshot_$t.log)" >&2; tail -5 "out/screenshot_$t.log" >&2; exit 1; }
  echo "screenshots: Blender $ver -> $shot"
done
