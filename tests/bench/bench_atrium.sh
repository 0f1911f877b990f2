#!/bin/sh
# VSM timings for docs/effects/vsm_shadows.md: builds bench_atrium.c against a build's static
# library and runs it.  usage: tests/bench/bench_atrium.sh [BUILD_DIR] [THREADS] [RUNS] [MAX_LIGHT_MAP]
set -e
here=$(cd "$(dirname "$0")" && pwd); root=$(dirname "$(dirname "$here")")
build=${1:-$root/build}; threads=${2:-0}; runs=${3:-5}; max=${4:-4096}
out=$(mktemp -d)
cc -O2 -std=c11 -D_POSIX_C_SOURCE=200809L -I"$root/libfx/include" -I"$root/libfx/src" \
   "$here/bench_atrium.c" "$build/libfx/libfx.a" -o "$out/bench_atrium" \
   $(pkg-config --libs OpenEXR 2>/dev/null || echo -lOpenEXRCore) -lcjson -lpng -lz -lpthread -lm -lstdc++
"$out/bench_atrium" "$threads" "$out" "$runs" "$max"
rm -rf "$out"
