#!/usr/bin/env bash
# The main job: sets everything up, then renders the three demo scenes headless with
# Blender and the libfx add-on (each scene's own effect stack), and writes for each a
# before/after image side by side into out/<scene>/.
#   bash scripts/demo.sh [--resolution 640x360] [--samples 32] [--frames 1] [--docs]
#                        [--blender host|trixie|unstable]
# --docs also copies the before/after images into docs/images/ (how the README's
# picture is made). --blender runs another Blender: trixie (Debian 13, Blender 4.3) or
# unstable (Blender 5.x), from the roots scripts/blender_roots.sh makes (made on
# first use, a few minutes), with the libfx built inside that root; default: the
# host's Debian 12 Blender 3.4.
set -euo pipefail
cd "$(dirname "$0")/.."
resolution=640x360 samples=32 frames=1 docs=0 target=host
while [ $# -gt 0 ]; do
  case "$1" in
    --resolution) resolution=$2; shift 2 ;;
    --samples) samples=$2; shift 2 ;;
    --frames) frames=$2; shift 2 ;;
    --docs) docs=1; shift ;;
    --blender) target=$2; shift 2 ;;
    *) echo "demo: unknown option $1" >&2; exit 2 ;;
  esac
done
bash scripts/setup.sh

run=() build=build
case "$target" in
  host) ;;
  trixie|unstable)
    bash scripts/blender_roots.sh "$target"
    run=(bash scripts/in_root.sh "$target") build=build-$target
    "${run[@]}" bash -c "cmake -B $build -S . -DCMAKE_BUILD_TYPE=Release -DLIBFX_BUILD_BENCH=OFF >/dev/null \
      && cmake --build $build -j$(nproc) >/dev/null" ;;
  *) echo "demo: --blender takes host, trixie or unstable, not '$target'" >&2; exit 2 ;;
esac
echo "demo: $("${run[@]}" blender -b --factory-startup --version 2>/dev/null | grep -m1 '^Blender')"
first=${frames%%[-,]*}
for scene in greek_bath atrium mirror_room; do
  out="$PWD/out/$scene"
  rm -rf "$out"
  mkdir -p "$out"
  echo "demo: rendering $scene ($resolution, $samples samples, frames $frames)"
  start=$(date +%s.%N)
  "${run[@]}" env LIBFX_LIBRARY="$PWD/$build/libfx/libfx.so" \
    blender -b "blend_scenes/$scene/$scene.blend" --python addon/libfx/batch.py -- \
    --keep-passes --frames "$frames" --output "$out/" --resolution "$resolution" --samples "$samples" \
    > "$out/blender.log" 2>&1 || { echo "demo: $scene failed, see $out/blender.log" >&2; tail -20 "$out/blender.log" >&2; exit 1; }
  grep -E "^libfx" "$out/blender.log" | tail -3 || true
  f=$(printf %04d "$first")
  # Before: the plain render's Combined (the File Output passes); after: libfx's result.
  # Both go through the same linear -> sRGB conversion.
  for pair in "before:$out/libfx_passes.$f.exr" "after:$out/libfx.$f.exr"; do
    name=${pair%%:*} exr=${pair#*:}
    [ -s "$exr" ] || { echo "demo: $scene did not produce $exr" >&2; exit 1; }
    # the Combined pass's channels as the file names them: "Combined.R" in libfx's result,
    # "<view layer>.Combined.R" in the passes file the add-on writes from the Render Result
    ch=$(oiiotool --info -v "$exr" | sed -n 's/^ *channel list: //p' | head -1 | tr ',' '\n' |
         sed 's/^ *//' | grep -m1 'Combined\.R$' || true)
    [ -n "$ch" ] || { echo "demo: $exr has no Combined pass" >&2; exit 1; }
    c=${ch%R}
    oiiotool "$exr" --ch "R=${c}R,G=${c}G,B=${c}B" --colorconvert linear sRGB -d uint8 -o "$out/$name.png"
  done
  oiiotool "$out/before.png" "$out/after.png" --mosaic 2x1 -o "$out/before_after.png"
  printf "demo: %s done in %s s: %s\n" "$scene" "$(awk -v a="$start" -v b="$(date +%s.%N)" "BEGIN{printf \"%.1f\", b-a}")" "$out/before_after.png"
  if [ "$docs" = 1 ]; then
    mkdir -p docs/images
    cp "$out/before_after.png" "docs/images/before_after_$scene.png"
  fi
done
echo "demo: results in $PWD/out/<scene>/ (libfx.NNNN.exr: result with every pass; before_after.png)"
