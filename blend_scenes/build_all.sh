#!/bin/sh
# Rebuild the three libfx test scenes (.blend + recipe.json) headless.
# Usage: blend_scenes/build_all.sh [OUTDIR]   (BLENDER=/path/to/blender to override)
# With OUTDIR the scenes are written there (OUTDIR/<scene>/) and the committed
# files are left alone: how tests/blender checks the builders on each Blender.
set -eu
here=$(cd "$(dirname "$0")" && pwd)
blender=${BLENDER:-blender}
for scene in greek_bath atrium mirror_room; do
    echo "== $scene"
    dir=$here/$scene
    if [ $# -gt 0 ]; then
        dir=$1/$scene
        export LIBFX_SCENES_OUT="$dir"
    fi
    "$blender" -b --factory-startup --python-exit-code 3 --python "$here/$scene/make_$scene.py"
    test -s "$dir/$scene.blend"
    test -s "$dir/recipe.json"
done
echo "all scenes rebuilt"
