#!/usr/bin/env bash
# Render + libfx processing time per demo scene (one frame), at a test size and at
# 1280x720, through the add-on's batch runner. Prints a Markdown table.
#   bash tests/bench/bench_scenes.sh [out_dir]
set -euo pipefail
cd "$(dirname "$0")/../.."
out=${1:-out/bench_scenes}
mkdir -p "$out"
export LIBFX_LIBRARY=${LIBFX_LIBRARY:-$PWD/build/libfx/libfx.so}
echo "| scene | size | samples | wall s (Blender run) | libfx ms (stack) | libfx ms (read+run+write) |"
echo "|---|---|---:|---:|---:|---:|"
for size in "320x180:4" "1280x720:16"; do
  res=${size%%:*} spp=${size#*:}
  for scene in greek_bath atrium mirror_room; do
    dir="$out/$scene-$res"
    rm -rf "$dir"; mkdir -p "$dir"
    t0=$(date +%s.%N)
    blender -b "blend_scenes/$scene/$scene.blend" --python addon/libfx/batch.py -- \
      --keep-passes --frames 1 --output "$dir/" --resolution "$res" --samples "$spp" > "$dir/log.txt" 2>&1
    t1=$(date +%s.%N)
    # "libfx: frame 1: pixelate 2.2 ms (166.0 ms in all) -> ..."
    line=$(grep -E "^libfx: frame 1:" "$dir/log.txt" | tail -1)
    stack=$(echo "$line" | sed 's/([^)]*in all)//' | grep -oE "[0-9.]+ ms" | awk '{s+=$1} END {printf "%.1f", s}')
    all=$(echo "$line" | grep -oE "\(([0-9.]+) ms in all\)" | grep -oE "[0-9.]+")
    printf "| %s | %s | %s | %.1f | %s | %s |\n" "$scene" "$res" "$spp" "$(awk -v a="$t0" -v b="$t1" 'BEGIN{print b-a}')" "$stack" "$all"
  done
done
