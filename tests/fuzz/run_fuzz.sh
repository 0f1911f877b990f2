#!/usr/bin/env bash
# Builds the libFuzzer target (EXR reader + recipe parser + one effect, under ASan) in its
# own build folder and runs it for a bounded time, seeded with the shared EXR corpus and
# the scenes' recipes. A crash leaves its input in tests/fuzz/crashers/: keep it as a
# regression file under tests/data/fuzz/ (test_fuzz_replay replays that folder).
#   tests/fuzz/run_fuzz.sh [seconds]   (default 60; LIBFX_FUZZ_BUILD: the build folder)
set -euo pipefail
cd "$(dirname "$0")/../.."
seconds=${1:-60}
build=${LIBFX_FUZZ_BUILD:-build-fuzz}
if ! command -v clang >/dev/null || ! command -v clang++ >/dev/null; then
  echo "run_fuzz: clang is not installed; skipped" >&2
  exit 0
fi
CC=clang CXX=clang++ cmake -B "$build" -S . -DCMAKE_BUILD_TYPE=RelWithDebInfo -DLIBFX_FUZZ=ON \
  -DLIBFX_BUILD_TESTS=OFF -DLIBFX_BUILD_BENCH=OFF >/dev/null
cmake --build "$build" --target fuzz_exr_recipe -j"$(nproc)" >/dev/null

# Seeds: the corpus's EXRs, the scenes' recipes, the kept crashers; the fuzzer's own
# findings accumulate in $build/corpus (not in the repository).
seeds="$build/seeds"
rm -rf "$seeds"
mkdir -p "$seeds" "$build/corpus" tests/fuzz/crashers
corpus=${LIBFX_CORPUS:-../shared/exr-corpus}
if [ -d "$corpus" ]; then
  find "$corpus" -type f -name '*.exr' -size -1024k -exec cp -t "$seeds" {} +
fi
for r in blend_scenes/*/recipe*.json; do
  cp "$r" "$seeds/$(basename "$(dirname "$r")")_$(basename "$r")"
done
if [ -d tests/data/fuzz ]; then
  find tests/data/fuzz -type f -exec cp -t "$seeds" {} +
fi

echo "run_fuzz: $(ls "$seeds" | wc -l) seeds, ${seconds} s"
ASAN_OPTIONS=detect_leaks=1:allocator_may_return_null=1 \
  "$build/tests/fuzz/fuzz_exr_recipe" "$build/corpus" "$seeds" \
  -max_total_time="$seconds" -max_len=1048576 -timeout=20 -rss_limit_mb=2048 \
  -artifact_prefix=tests/fuzz/crashers/ -print_final_stats=1 2>&1 | tail -25
