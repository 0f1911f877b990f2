#!/usr/bin/env bash
# The host half of test_exr_dwa: copies of DIR/src.exr (written by `test_exr_dwa write`,
# perhaps a Windows build under Wine) made with the host's oiiotool, which
# `test_exr_dwa check DIR` then reads: DWAA and DWAB, tiled 32x16, and a mipmapped tiled
# texture (-otex) padded out to the display window.
#   bash tests/c/exr_dwa_convert.sh DIR
set -euo pipefail
dir=${1:?usage: exr_dwa_convert.sh DIR}
command -v oiiotool >/dev/null || { echo "exr_dwa_convert: no oiiotool (apt install openimageio-tools)" >&2; exit 1; }
[ -s "$dir/src.exr" ] || { echo "exr_dwa_convert: no $dir/src.exr (test_exr_dwa write)" >&2; exit 1; }
rm -f "$dir"/x_dwaa.exr "$dir"/x_dwab.exr "$dir"/tiled0.exr "$dir"/tiled1.exr
for codec in dwaa dwab; do
  oiiotool "$dir/src.exr" --compression "$codec" -o "$dir/x_$codec.exr"
done
oiiotool "$dir/src.exr" --tile 32 16 --compression zip -o "$dir/tiled0.exr"
oiiotool "$dir/src.exr" --compression zip -otex:fileformatname=openexr "$dir/tiled1.exr"
