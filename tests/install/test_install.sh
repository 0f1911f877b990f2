#!/usr/bin/env bash
# Installs libfx into a temporary prefix, then builds and runs docs/examples/blur_exr.c
# against it twice: through find_package(libfx) and through pkg-config.
set -euo pipefail
build=$1 src=$2 corpus=$3
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cmake --install "$build" --prefix "$tmp/prefix" >/dev/null
test -f "$tmp/prefix/include/libfx/fx.h"
test -x "$tmp/prefix/bin/libfx"
"$tmp/prefix/bin/libfx" list | grep -q gaussian_blur   # the installed CLI finds its library (RPATH)

cmake -S "$src/docs/examples" -B "$tmp/ex" -DCMAKE_PREFIX_PATH="$tmp/prefix" >/dev/null
cmake --build "$tmp/ex" >/dev/null
in="$corpus/openexr-images/TestImages/GrayRampsHorizontal.exr"
LD_LIBRARY_PATH="$tmp/prefix/lib" "$tmp/ex/blur_exr" "$in" "$tmp/out1.exr"
test -s "$tmp/out1.exr"

libdir=$(ls -d "$tmp"/prefix/lib*/pkgconfig | head -1)
PKG_CONFIG_PATH="$libdir" cc -o "$tmp/ex2" "$src/docs/examples/blur_exr.c" \
  $(PKG_CONFIG_PATH="$libdir" pkg-config --cflags --libs libfx)
LD_LIBRARY_PATH="$(dirname "$libdir")" "$tmp/ex2" "$in" "$tmp/out2.exr"
cmp "$tmp/out1.exr" "$tmp/out2.exr" >/dev/null || { echo "the two builds disagree"; exit 1; }
# Only the public API is exported from the shared library.
nm -D --defined-only "$(dirname "$libdir")/libfx.so" | awk '{print $3}' | grep -v -e '^fx_' -e '^LIBFX_' -e '^$' \
  && { echo "symbols outside fx_* are exported"; exit 1; }
nm -D --defined-only "$(dirname "$libdir")/libfx.so" | grep -q fx_mem_alloc \
  && { echo "internal fx_mem_alloc is exported"; exit 1; }
echo "install test: 1 passed, 0 failed"
