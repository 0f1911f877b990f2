#!/usr/bin/env bash
# Measures what a farm chunk costs with the batch runner: the fixed cost of one
# Blender process (start, load the .blend, enable the add-on, set up the stack, quit)
# and the cost of each frame, so a chunk size can amortise the first over the second
# (docs/farm.md, "Chunk size").
#
#   farm/measure_chunk_cost.sh [RES] [REPEATS] [FRAMES] [SCENE...]
#       defaults: 320x180 3 5, all three scenes; the scene's own samples.
#
# Per scene and repeat, two runs:
#   render: --frames 1-FRAMES into an empty folder. Its wall time splits, within the
#           run, into the frames (Blender's own 'Time:' per frame + libfx's 'ms in all')
#           and the rest, the fixed cost; on a shared machine the split is steadier
#           than differences between runs.
#   skip:   the same again with --skip-existing (every frame done): what a re-queued
#           finished chunk costs (the fixed cost plus the completeness checks).
# Prints one CSV row per run and the medians. LIBFX_LIBRARY picks the library.
set -euo pipefail
cd "$(dirname "$0")/.."
res=${1:-320x180}
reps=${2:-3}
nframes=${3:-5}
shift $(( $# > 3 ? 3 : $# )) || true
scenes=("$@")
[ ${#scenes[@]} -gt 0 ] || scenes=(mirror_room greek_bath atrium)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

run() {  # run OUT LOG [extra...] -> wall seconds
  local out=$1 log=$2; shift 2
  local t0 t1
  t0=$(date +%s.%N)
  blender -b --factory-startup "blend_scenes/$scene/$scene.blend" --python-exit-code 2 \
    --python addon/libfx/batch.py -- --frames "1-$nframes" --output "$out/o_" --resolution "$res" "$@" \
    >"$log" 2>&1 || { echo "failed:" >&2; cat "$log" >&2; exit 1; }
  t1=$(date +%s.%N)
  echo "$t1 - $t0" | bc -l
}

# Seconds of Blender's per-frame 'Time: [hh:]mm:ss.ss' lines and libfx's '(X ms in all)'.
frame_seconds() {
  awk '/^ *Time: / { n = split($2, t, ":"); s = 0; for (i = 1; i <= n; i++) s = s * 60 + t[i]; r += s }
       /ms in all\)/ { if (match($0, /\(([0-9.]+) ms in all\)/)) fx += substr($0, RSTART + 1, RLENGTH - 12) / 1000 }
       END { printf "%.3f %.3f\n", r, fx }' "$1"
}

echo "scene,res,frames,repeat,wall_s,blender_render_s,libfx_s,per_frame_s,fixed_s,skip_all_s"
rows=()
for scene in "${scenes[@]}"; do
  for r in $(seq "$reps"); do
    wall=$(run "$tmp/$scene-$r" "$tmp/$scene-$r.log")
    read -r rend fx < <(frame_seconds "$tmp/$scene-$r.log")
    skip=$(run "$tmp/$scene-$r" "$tmp/$scene-$r-skip.log" --skip-existing)
    per=$(echo "($rend + $fx) / $nframes" | bc -l)
    fixed=$(echo "$wall - $rend - $fx" | bc -l)
    row=$(printf "%s,%s,%d,%d,%.2f,%.2f,%.3f,%.2f,%.2f,%.2f" "$scene" "$res" "$nframes" "$r" \
          "$wall" "$rend" "$fx" "$per" "$fixed" "$skip")
    echo "$row"
    rows+=("$row")
  done
done
echo
echo "medians: scene,per_frame_s,fixed_s,skip_all_s,libfx_per_frame_s"
for scene in "${scenes[@]}"; do
  printf "%s\n" "${rows[@]}" | awk -F, -v s="$scene" -v nf="$nframes" 'BEGIN { n = 0 }
    $1 == s { p[n] = $8 + 0; f[n] = $9 + 0; k[n] = $10 + 0; x[n] = $7 / nf; n++ }
    function med(a, n,   i, j, t) { for (i = 0; i < n; i++) for (j = i + 1; j < n; j++)
                                     if (a[j] < a[i]) { t = a[i]; a[i] = a[j]; a[j] = t }
                                   return n % 2 ? a[int(n / 2)] : (a[n / 2 - 1] + a[n / 2]) / 2 }
    END { printf "%s,%.2f,%.2f,%.2f,%.3f\n", s, med(p, n), med(f, n), med(k, n), med(x, n) }'
done
