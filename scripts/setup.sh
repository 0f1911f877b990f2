#!/usr/bin/env bash
# Installs the Debian 12 packages libfx needs (only the missing ones) and builds
# libfx into build/ (or $LIBFX_BUILD_DIR). Safe to run again.
set -euo pipefail
cd "$(dirname "$0")/.."

packages=(
  build-essential cmake pkg-config          # toolchain
  libopenexr-dev libcjson-dev libpng-dev    # the library's dependencies
  libdeflate-dev                            # ZIP EXR writes ~3x faster (optional at build time)
  openimageio-tools python3-openimageio     # oiiotool/idiff and OIIO from Python, for tests and comparisons
  python3-numpy python3-pytest              # Python tests (run with /usr/bin/python3)
  universal-ctags                           # the function-length check (tests/check_function_length.py)
  python3-venv                              # the wheel test: pip install into a fresh venv (tests/platform)
  python3-matplotlib python3-pil            # plots and GIF flip-books in docs/
  blender                                   # Debian's Blender 3.4: the add-on, scenes and renders
  xvfb                                      # a display for the add-on's UI screenshot
  libopencv-imgproc-dev                     # OpenCV's GaussianBlur as the benchmark's peer
  clang libclang-rt-14-dev                  # the fuzz target (libFuzzer is in libclang-rt)
  nodejs                                    # runs the Flamenco job type (farm/flamenco) in its test
  munge slurmctld slurmd slurm-client       # a one-node Slurm cluster for the farm test (tests/farm)
  mmdebstrap                                # makes the Debian 13 / unstable roots holding Blender 4.3 / 5.x
  valgrind                                  # callgrind: instruction counts (bench_ir.py, bench_trade)
)
source scripts/apt_missing.sh
apt_install_missing "${packages[@]}"

build=${LIBFX_BUILD_DIR:-build}
cmake -B "$build" -S . -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$build" -j"$(nproc)"
echo "setup: built libfx in $build/ (CLI: $build/libfx/libfx)"
