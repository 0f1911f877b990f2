#!/usr/bin/env bash
# Measures what a farm chunk costs with the batch runner: the fixed cost of one
# Blender process (start, load the .blend, enable the add-on, set up the stack, quit)
# and the cost of each frame, so a chunk size can amortise the first over the second
# (docs/farm.md, "Chunk size").
#
#   farm/measure_chunk_cost.sh [RES[,RES...]] [REPEATS] [FRAMES] [SCENE...]
#       defaults: 320x180 3 5, all three scenes; the scene's own samples, or SAMPLES=N.
#
# The rows also carry the samples, the cores and Blender's peak memory (GNU time's
# maximum resident set), so two resolutions give the Slurm submitter its sizing model
# (farm/slurm/libfx_slurm.py reads farm/slurm/chunk_cost.csv, made by
#  `SAMPLES=16 farm/measure_chunk_cost.sh 160x90,320x180 3 5 > farm/slurm/chunk_cost.csv`).
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
resolutions=${1:-320x180}
reps=${2:-3}
nframes=${3:-5}
shift $(( $# > 3 ? 3 : $# )) || true
scenes=("$@")
[ ${#scenes[@]} -gt 0 ] || scenes=(mirror_room greek_bath atrium)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

samples_args=()
[ -z "${SAMPLES:-}" ] || samples_args=(--samples "$SAMPLES")

run() {  # run OUT LOG [extra...] -> wall seconds (peak memory in LOG.rss, kB)
  local out=$1 log=$2; shift 2
  local t0 t1
  t0=$(date +%s.%N)
  /usr/bin/time -f %M -o "$log.rss" \
    blender -b --factory-startup "blend_scenes/$scene/$scene.blend" --python-exit-code 2 \
    --python addon/libfx/batch.py -- --frames "1-$nframes" --output "$out/o_" --resolution "$res" \
    "${samples_args[@]}" "$@" >"$log" 2>&1 || { echo "failed:" >&2; cat "$log" >&2; exit 1; }
  t1=$(date +%s.%N)
  echo "$t1 - $t0" | bc -l
}

# Seconds of Blender's per-frame 'Time: [hh:]mm:ss.ss' lines and libfx's '(X ms in all, ...)'.
frame_seconds() {
  awk '/^ *Time: / { n = split($2, t, ":"); s = 0; for (i = 1; i <= n; i++) s = s * 60 + t[i]; r += s }
       /ms in all[,)]/ { if (match($0, /\(([0-9.]+) ms in all/)) fx += substr($0, RSTART + 1, RLENGTH - 11) / 1000 }
       END { printf "%.3f %.3f\n", r, fx }' "$1"
}

echo "scene,res,frames,repeat,wall_s,blender_render_s,libfx_s,per_frame_s,fixed_s,skip_all_s,samples,cpus,peak_rss_mb"
rows=()
IFS=, read -r -a res_list <<<"$resolutions"
for res in "${res_list[@]}"; do
for scene in "${scenes[@]}"; do
  # The samples a frame renders with: --samples, else the scene's own (Cycles or Eevee).
  spp=${SAMPLES:-$(blender -b --factory-startup "blend_scenes/$scene/$scene.blend" --python-expr \
    'import bpy; s = bpy.context.scene; print("SPP", s.cycles.samples if s.render.engine == "CYCLES" else s.eevee.taa_render_samples)' \
    2>/dev/null | awk '/^SPP/ {print $2}')}
  for r in $(seq "$reps"); do
    wall=$(run "$tmp/$scene-$res-$r" "$tmp/$scene-$res-$r.log")
    read -r rend fx < <(frame_seconds "$tmp/$scene-$res-$r.log")
    rss=$(tail -n1 "$tmp/$scene-$res-$r.log.rss")
    skip=$(run "$tmp/$scene-$res-$r" "$tmp/$scene-$res-$r-skip.log" --skip-existing)
    per=$(echo "($rend + $fx) / $nframes" | bc -l)
    fixed=$(echo "$wall - $rend - $fx" | bc -l)
    row=$(printf "%s,%s,%d,%d,%.2f,%.2f,%.3f,%.2f,%.2f,%.2f,%d,%d,%d" "$scene" "$res" "$nframes" "$r" \
          "$wall" "$rend" "$fx" "$per" "$fixed" "$skip" "$spp" "$(nproc)" "$((rss / 1024))")
    echo "$row"
    rows+=("$row")
  done
done
done
echo
echo "# medians: scene,res,per_frame_s,fixed_s,skip_all_s,libfx_per_frame_s"
for res in "${res_list[@]}"; do
for scene in "${scenes[@]}"; do
  printf "%s\n" "${rows[@]}" | awk -F, -v s="$scene" -v res="$res" -v nf="$nframes" 'BEGIN { n = 0 }
    $1 == s && $2 == res { p[n] = $8 + 0; f[n] = $9 + 0; k[n] = $10 + 0; x[n] = $7 / nf; n++ }
    function med(a, n,   i, j, t) { for (i = 0; i < n; i++) for (j = i + 1; j < n; j++)
                                     if (a[j] < a[i]) { t = a[i]; a[i] = a[j]; a[j] = t }
                                   return n % 2 ? a[int(n / 2)] : (a[n / 2 - 1] + a[n / 2]) / 2 }
    END { printf "# %s,%s,%.2f,%.2f,%.2f,%.3f\n", s, res, med(p, n), med(f, n), med(k, n), med(x, n) }'
done
done
