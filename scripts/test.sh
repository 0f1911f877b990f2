#!/usr/bin/env bash
# Sets everything up and runs every test: the C tests (CTest), the same C tests and
# the damaged-file corpus under AddressSanitizer + UBSan, the Python tests of the
# CLI, a shot on a one-node Slurm cluster (tests/farm), the headless Blender tests
# of the add-on and scenes on Blender 3.4, 4.3 and 5.x (scripts/blender_matrix.sh), and the release builds for every artist's
# machine with their packages (scripts/platforms.sh: self-contained linux-x64 from
# Debian 11, windows-x64 under Wine, wheels, per-platform extensions).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
# What the library-loading tests try (tests/python, the add-on's error test): a Windows DLL
# made with MinGW, and the Debian 11 root a library's glibc floor is tried in (made once
# per machine, reused; scripts/platforms.sh uses it too). Without them those tests skip.
source scripts/apt_missing.sh
apt_install_missing gcc-mingw-w64-x86-64
bash scripts/blender_roots.sh bullseye

status=0
echo "== C tests (release build)"
ctest --test-dir build --output-on-failure -j2 || status=1

echo "== C tests under AddressSanitizer + UndefinedBehaviorSanitizer"
cmake -B build-asan -S . -DCMAKE_BUILD_TYPE=Debug -DLIBFX_ASAN=ON -DLIBFX_UBSAN=ON \
  -DLIBFX_BUILD_BENCH=OFF >/dev/null
cmake --build build-asan -j"$(nproc)" >/dev/null
ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1 \
  ctest --test-dir build-asan --output-on-failure -j2 || status=1

echo "== Fuzz target (EXR reader + recipe parser + one effect; libFuzzer + ASan, 60 s)"
bash tests/fuzz/run_fuzz.sh 60 || status=1

export LIBFX_CLI="$PWD/build/libfx/libfx" LIBFX_LIBRARY="$PWD/build/libfx/libfx.so"
# Two runs: each folder has its own conftest.py.
echo "== Python tests (CLI, interop)"
/usr/bin/python3 -m pytest -q -p no:cacheprovider tests/python || status=1
echo "== Farm: shots through the batch runner on a one-node Slurm cluster (tests/farm)"
/usr/bin/python3 -m pytest -q -p no:cacheprovider tests/farm || status=1
echo "== The Python wheel (a development wheel of build/, installed with pip into a fresh venv)"
rm -rf out/wheel-dev
/usr/bin/python3 scripts/build_wheel.py --platform linux-x64 --library build/libfx/libfx.so.2 \
    --cli build/libfx/libfx --dev --out out/wheel-dev >/dev/null \
  && LIBFX_WHEEL="$PWD/out/wheel-dev" /usr/bin/python3 -m pytest -q -p no:cacheprovider tests/platform \
  || status=1
echo "== Blender tests (add-on, scenes; headless) on every supported Blender"
# Debian 12's Blender 3.4 here, 4.3 and 5.x in Debian roots made (or reused) by
# scripts/blender_roots.sh; then the same-bits check across those builds.
bash scripts/blender_matrix.sh || status=1
echo "== Release builds: linux-x64 (glibc 2.31, static dependencies), windows-x64 (Wine), packages"
bash scripts/platforms.sh || status=1

exit $status
