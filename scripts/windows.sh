#!/usr/bin/env bash
# libfx for Windows x64, checked under Wine: cross-builds build-windows-x64/ with Debian's
# MinGW-w64 against the static dependencies of scripts/deps.sh, checks that libfx.dll and
# libfx.exe import only Windows' own DLLs and that the DLL exports exactly the fx_* API of
# fx.h, then runs the C tests (CTest, through the toolchain's Wine emulator) and the CLI
# tests (tests/python/test_cli*.py with LIBFX_CLI=tests/platform/wine_cli.sh).
# With LIBFX_BITS_INPUTS=DIR (tests/matrix/make_bits_inputs.sh DIR: Blender renders) it also
# dumps every recipe and effect preset with the Linux build (build/) and the Windows one and
# checks that they give the same bits (tests/matrix/test_same_bits.py).
# Debian 12, as root or with sudo; installs missing packages. Exit status non-zero on any
# failure, with a summary either way.
# With LIBFX_BITS_INPUTS=DIR (tests/matrix/make_bits_inputs.sh), also the same-bits check
# against the Linux build in build/, for the DLL's AVX2 copy and (LIBFX_CPU=baseline) its
# baseline one.
#   bash scripts/windows.sh            # all of it
#   bash scripts/windows.sh --build    # build and the import/export checks only
set -uo pipefail
only_build=0
[ "${1:-}" = "--build" ] && only_build=1
cd "$(dirname "$0")/.."
here=$PWD
build=${LIBFX_WINDOWS_BUILD_DIR:-build-windows-x64}
deps=${LIBFX_DEPS:-/var/cache/libfx-deps}/windows-x64
# Wine's state lives in the build tree: nothing in $HOME, made once (about 7 s).
export WINEPREFIX=${WINEPREFIX:-$here/$build/wineprefix}
export WINEDEBUG=-all
WINE=/usr/lib/wine/wine64
WINESERVER=/usr/lib/wine/wineserver
# CLI tests that cannot mean anything under Wine (the rest of tests/python/test_cli*.py runs):
EXCLUDED_CLI_TESTS=(
  # caps the child's address space with RLIMIT_AS: under Wine that caps Wine's own Unix
  # process, which aborts reserving its address space (virtual_init) before libfx runs
  tests/python/test_cli_no_data_loss.py::test_out_of_memory
  # Unix permission bits, the CLI run as `nobody` (setpriv): nobody cannot use the Wine
  # prefix, and Windows folders are guarded by ACLs, not mode bits
  tests/python/test_cli_errors.py::test_unwritable_output_directory
)

packages=(
  cmake gcc-mingw-w64-x86-64 g++-mingw-w64-x86-64 binutils-mingw-w64-x86-64  # the cross toolchain
  wine64                                                     # runs the tests (Debian 12's Wine 8.0)
  openimageio-tools                                          # oiiotool: test_exr_dwa's host fixture
  python3-pytest python3-numpy python3-openimageio           # the CLI tests
  universal-ctags                                            # ctest's function-length check
)
source scripts/apt_missing.sh
apt_install_missing "${packages[@]}" || exit 1

# The dependencies are built once per machine and reused (scripts/deps.sh keeps the cache).
if [ ! -f "$deps/.libfx-deps-complete" ]; then
  bash scripts/deps.sh windows-x64 || { echo "windows: FAILED: scripts/deps.sh windows-x64" >&2; exit 1; }
fi

t0=$(date +%s)
declare -a summary=()
failed=0
step() {  # name, command...: runs it, records the outcome
  local name=$1
  shift
  echo "== windows: $name"
  if "$@"; then
    summary+=("ok      $name")
  else
    summary+=("FAILED  $name")
    failed=1
  fi
}

configure_and_build() {
  mkdir -p "$build"
  cmake -B "$build" -S . -DCMAKE_TOOLCHAIN_FILE=cmake/mingw-w64-x86_64.cmake \
    -DLIBFX_SELF_CONTAINED=ON -DLIBFX_DEPS_PREFIX="$deps" -DLIBFX_BUILD_BENCH=OFF \
    -DCMAKE_BUILD_TYPE=Release >"$build/configure.log" 2>&1 \
    || { tail -20 "$build/configure.log"; return 1; }
  cmake --build "$build" -j2 2>&1 | grep -E "error|warning|Error" ; [ "${PIPESTATUS[0]}" -eq 0 ]
}

# Windows' own DLLs: the C runtime (msvcrt or the UCRT's api-ms-win-crt-*) and the Win32 API.
SYSTEM_DLLS='^(kernel32|msvcrt|shell32|user32|advapi32|ntdll|ws2_32|bcrypt|api-ms-win-[a-z0-9-]+)\.dll$'
check_imports() {  # file, extra allowed DLL (or "")
  local file=$1 extra=$2 bad=0
  [ -f "$file" ] || { echo "no $file" >&2; return 1; }
  local dlls
  dlls=$(x86_64-w64-mingw32-objdump -p "$file" | sed -n 's/^\s*DLL Name: //p')
  echo "$(basename "$file") imports: $(echo $dlls)"
  for d in $dlls; do
    local l=${d,,}
    if ! [[ $l =~ $SYSTEM_DLLS ]] && [ "$l" != "${extra,,}" ]; then
      echo "windows: $(basename "$file") imports a non-system DLL: $d" >&2
      bad=1
    fi
  done
  return $bad
}

check_exports() {  # libfx.dll exports exactly the FX_API functions of fx.h
  local dll=$build/libfx/libfx.dll
  local api exported
  api=$(grep -o '^FX_API[^(]*(' libfx/include/libfx/fx.h | sed -E 's/.*[ *]([a-z_0-9]+)\($/\1/' | sort)
  exported=$(x86_64-w64-mingw32-objdump -p "$dll" | sed -n '/\[Ordinal\/Name Pointer\] Table/,/^$/p' \
    | sed -n 's/^\s*\[ *[0-9]*\] //p' | sort)
  echo "libfx.dll exports $(echo "$exported" | wc -l) symbols; fx.h declares $(echo "$api" | wc -l)"
  if [ "$api" != "$exported" ]; then
    echo "windows: libfx.dll's export table differs from fx.h's FX_API functions:" >&2
    diff <(echo "$api") <(echo "$exported") >&2
    return 1
  fi
  [ -n "$api" ]
}

ctest_under_wine() {
  ctest --test-dir "$build" --output-on-failure -j2
}

cli_tests_under_wine() {
  LIBFX_CLI="$here/tests/platform/wine_cli.sh" LIBFX_WINDOWS_CLI="$here/$build/libfx/libfx.exe" \
    /usr/bin/python3 -m pytest -q -p no:cacheprovider "${EXCLUDED_CLI_TESTS[@]/#/--deselect=}" \
    tests/python/test_cli*.py
}

# One persistent Wine server (and its system processes) for every test program, started
# with no pipe attached. Otherwise each CLI run starts a server whose system processes
# inherit the run's stdout/stderr pipes, and the test waits about 3 s per run for them to
# close (10 minutes instead of 20 s). Stopped on exit: only this script's prefix's server.
start_wine() {
  "$WINE" wineboot -i </dev/null >/dev/null 2>&1 || true   # makes the prefix (about 7 s)
  timeout 60 "$WINESERVER" -w || true                       # the boot's own server is gone
  # status 2: a persistent server runs already (an interrupted run's), which serves as well
  "$WINESERVER" -p </dev/null >/dev/null 2>&1
  trap '"$WINESERVER" -k 2>/dev/null' EXIT
  "$WINE" cmd /c exit </dev/null >/dev/null 2>&1            # its system processes, no pipes
}

same_bits_as_linux() {
  local out=$here/$build/bits
  rm -rf "$out"
  [ -x build/libfx/libfx ] || { echo "no Linux build in build/ (bash scripts/setup.sh)" >&2; return 1; }
  bash tests/matrix/bits_dump.sh "$here/build/libfx/libfx" "$LIBFX_BITS_INPUTS" "$out/linux" >/dev/null &&
    LIBFX_WINDOWS_CLI="$here/$build/libfx/libfx.exe" bash tests/matrix/bits_dump.sh \
      "$here/tests/platform/wine_cli.sh" "$LIBFX_BITS_INPUTS" "$out/windows" >/dev/null &&
    LIBFX_CPU=baseline LIBFX_WINDOWS_CLI="$here/$build/libfx/libfx.exe" bash tests/matrix/bits_dump.sh \
      "$here/tests/platform/wine_cli.sh" "$LIBFX_BITS_INPUTS" "$out/windows-baseline" >/dev/null &&
    LIBFX_BITS_DIRS="$out/linux $out/windows $out/windows-baseline" \
      /usr/bin/python3 -m pytest -q -p no:cacheprovider tests/matrix
}

step "configure + build ($build)" configure_and_build
if [ $failed -eq 0 ]; then
  step "libfx.dll imports only system DLLs" check_imports "$build/libfx/libfx.dll" ""
  step "libfx.exe imports only system DLLs + libfx.dll" check_imports "$build/libfx/libfx.exe" libfx.dll
  step "libfx.dll exports exactly fx.h's API" check_exports
fi
if [ $failed -eq 0 ] && [ $only_build = 0 ]; then
  start_wine
  step "C tests (ctest under Wine)" ctest_under_wine
  step "CLI tests (pytest tests/python/test_cli*.py under Wine)" cli_tests_under_wine
  if [ -n "${LIBFX_BITS_INPUTS:-}" ]; then
    step "same bits as the Linux build (tests/matrix)" same_bits_as_linux
  fi
fi

echo "== windows: summary ($(( $(date +%s) - t0 )) s)"
printf '  %s\n' "${summary[@]}"
exit $failed
