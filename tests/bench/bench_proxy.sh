#!/bin/sh
# The proxy-resolution benchmark of issue 13 over the three scenes (docs/proxy.md):
#   tests/bench/bench_proxy.sh [BUILD_DIR] [OUT_DIR]
# Writes OUT_DIR/bench_proxy.csv, OUT_DIR/bench_proxy.md (table rows) and the PNGs of
# every setting in OUT_DIR/png. Needs the 1080p renders in /work/main/out/r1080/renders
# (or RENDERS=...).
set -e
BUILD=${1:-build-h}
OUT=${2:-out/bench_proxy}
RENDERS=${RENDERS:-/work/main/out/r1080/renders}
mkdir -p "$OUT/png"
rm -f "$OUT/bench_proxy.csv" "$OUT/bench_proxy.md"
for scene in greek_bath atrium mirror_room; do
  D="$RENDERS/${scene}_1920x1080"
  "$BUILD/tests/bench/bench_proxy" --scene "$scene" --passes "$D/r_libfx_passes.0001.exr" \
    --sidecar "$D/r_libfx.0001.camera.json" --recipe "$D/bench_recipe.json" \
    --threads 2 --runs 5 --png-dir "$OUT/png" -o "$OUT/bench_proxy.csv" -m "$OUT/bench_proxy.md"
done
