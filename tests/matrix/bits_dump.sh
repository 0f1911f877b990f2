#!/usr/bin/env bash
# One build's outputs for the cross-build check: every recipe of the three scenes on
# that scene's passes, and every effect alone with its defaults at each quality preset
# (draft, final, reference) on each scene's passes
# (an effect that cannot run on a scene writes its error instead of an EXR: the error
# must then be the same in every build too).
#   bash tests/matrix/bits_dump.sh CLI INPUTS OUTDIR
set -uo pipefail
cd "$(dirname "$0")/../.."
cli=${1:?usage: bits_dump.sh CLI INPUTS OUTDIR} inputs=${2:?} out=${3:?}
[ -f "$inputs/complete" ] || { echo "bits_dump: no inputs in $inputs" >&2; exit 2; }
mkdir -p "$out/recipes"
"$cli" --version >"$out/version.txt" 2>&1 || true
run() {  # name, recipe, scene, [quality]
  local name=$1 recipe=$2 scene=$3 quality=${4:+-q $4}
  if ! "$cli" run --quiet -j 2 $quality --stack "$recipe" --camera "$inputs/$scene/libfx.0001.camera.json" \
      "$inputs/$scene/libfx_passes.0001.exr" -o "$out/$name.exr" 2>"$out/$name.err"; then
    rm -f "$out/$name.exr"
  else
    rm -f "$out/$name.err"
  fi
}
for scene in greek_bath atrium mirror_room; do
  for r in blend_scenes/$scene/recipe*.json; do
    run "$scene.$(basename "$r" .json)" "$r" "$scene"
  done
  for effect in $("$cli" list | awk '{print $1}'); do
    printf '{"version": 1, "effects": [{"effect": "%s"}]}\n' "$effect" >"$out/recipes/$effect.json"
    for q in draft final reference; do   # every preset's code path
      run "$scene.$effect.$q" "$out/recipes/$effect.json" "$scene" "$q"
    done
  done
  printf '{"version": 1, "effects": [{"effect": "voronoi_caustics", "params": {"mode": "seed"}}]}\n' \
    >"$out/recipes/caustics_seed.json"
  run "$scene.caustics_seed" "$out/recipes/caustics_seed.json" "$scene"
done
ls "$out"/*.exr | wc -l | xargs echo "bits_dump: outputs:"
