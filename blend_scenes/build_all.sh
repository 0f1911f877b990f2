#!/bin/sh
# Rebuild the three libfx test scenes (.blend + recipe.json) headless.
# Usage: blend_scenes/build_all.sh   (BLENDER=/path/to/blender to override)
set -eu
here=$(cd "$(dirname "$0")" && pwd)
blender=${BLENDER:-blender}
for scene in greek_bath atrium mirror_room; do
    echo "== $scene"
    "$blender" -b --factory-startup --python "$here/$scene/make_$scene.py"
    test -s "$here/$scene/$scene.blend"
    test -s "$here/$scene/recipe.json"
done
echo "all scenes rebuilt"
