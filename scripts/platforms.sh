#!/usr/bin/env bash
# The release builds and their checks: a self-contained libfx for every artist's machine.
#
#   linux-x64    built against the Debian 11 root as sysroot (glibc 2.31) with this machine's
#                gcc 12, and the static dependencies scripts/deps.sh made in that root:
#                needs only glibc >= 2.31
#   windows-x64  cross-built with MinGW-w64, run under Wine (scripts/windows.sh)
#
# then the Python wheels and the per-platform Blender extensions (scripts/package.sh),
# installed where nothing else is (tests/platform/). Everything long (the roots, the
# dependencies) is made once per machine and reused.
#
#   bash scripts/platforms.sh            # all of it (the test command runs this)
#   bash scripts/platforms.sh --build    # only build build-linux-x64/ and build-windows-x64/
# Output: build-linux-x64/, build-windows-x64/, out/dist/ (wheels, zips), out/platforms/ (logs).
set -uo pipefail
cd "$(dirname "$0")/.."
here=$PWD
logs=out/platforms
mkdir -p "$logs"
status=0
summary=()
only_build=0
[ "${1:-}" = "--build" ] && only_build=1

stamp() { date -u +%H:%M:%S; }
step() {  # step NAME COMMAND...: runs, logs to $logs/NAME.log, records the outcome
  local name=$1 t0=$SECONDS rc
  shift
  echo "== platforms: $name ($(stamp))"
  "$@" >"$logs/$name.log" 2>&1
  rc=$?
  if [ $rc -eq 0 ]; then
    summary+=("$name: ok ($((SECONDS - t0)) s)")
  else
    summary+=("$name: FAILED, exit $rc ($((SECONDS - t0)) s; $logs/$name.log)")
    status=1
    tail -25 "$logs/$name.log"
  fi
  return $rc
}

# The Debian 11 root is the sysroot; the compiler is this machine's gcc, the development
# build's own (gcc 10 in the root made ssr_mirror 5-20 % and sin_city 30 % slower:
# docs/platforms.md).
build_linux() {
  bash scripts/deps.sh linux-x64 || return 1
  local root prefix
  root=$(bash scripts/blender_roots.sh --path bullseye)
  prefix=$root$(bash scripts/deps.sh --prefix linux-x64)
  # Debian 11's library links are absolute (libpthread.so -> /lib/...): used as a sysroot
  # they must resolve inside the root, not on this machine
  local l t
  while IFS= read -r l; do
    t=$(readlink "$l")
    [ -e "$root$t" ] && ln -sfn "$(realpath --relative-to="$(dirname "$l")" "$root$t")" "$l"
  done < <(find "$root/lib64" "$root/usr/lib/x86_64-linux-gnu" -maxdepth 1 -type l -lname '/*')
  cmake -B build-linux-x64 -S . -DCMAKE_TOOLCHAIN_FILE=cmake/linux-x64-sysroot.cmake \
      -DLIBFX_SYSROOT="$root" -DCMAKE_BUILD_TYPE=Release -DLIBFX_SELF_CONTAINED=ON \
      -DLIBFX_DEPS_PREFIX="$prefix" -DLIBFX_BUILD_BENCH=OFF >/dev/null \
    && cmake --build build-linux-x64 -j"$(nproc)"
}

# What the linux library and CLI need at run time: glibc alone, nothing newer than 2.31,
# and only libfx's own API exported.
check_linux_deps() {
  local f bad=0 newest
  for f in build-linux-x64/libfx/libfx.so.2 build-linux-x64/libfx/libfx; do
    echo "-- $f"
    [ -f "$f" ] || { echo "no $f"; return 1; }
    ldd "$f"
    if ldd "$f" | grep -vE 'linux-vdso|ld-linux-x86-64|lib(c|m|pthread|dl|fx)\.so'; then
      echo "$f needs more than glibc (above)"; bad=1
    fi
    newest=$(objdump -T "$f" | grep -o 'GLIBC_[0-9.]*' | sort -uV | tail -1)
    echo "newest glibc symbol version: $newest"
    [ -n "$newest" ] || { echo "$f has no glibc symbol versions?"; bad=1; }
    printf '%s\n%s\n' "$newest" GLIBC_2.31 | sort -V -C || { echo "$f needs $newest > GLIBC_2.31"; bad=1; }
  done
  local foreign
  # every defined dynamic symbol but the version node: fx_* only (no OpenEXR, zlib, png_*)
  foreign=$(objdump -T build-linux-x64/libfx/libfx.so.2 | awk '/^[0-9a-f]+ / && $0 !~ /\*UND\*|\*ABS\*/ {print $NF}' \
    | grep -v '^fx_' || true)
  [ -z "$foreign" ] || { echo "exported besides fx_*: $foreign"; bad=1; }
  echo "exports: $(objdump -T build-linux-x64/libfx/libfx.so.2 | awk '$4 == ".text"' | grep -c ' fx_') fx_* functions"
  return $bad
}

# The CLI on Debian 11 itself (glibc 2.31): loads and runs a blur on a scene's passes.
smoke_on_glibc_231() {
  local in=out/matrix/bits_inputs/greek_bath/libfx_passes.0001.exr
  [ -f "$in" ] || bash tests/matrix/make_bits_inputs.sh out/matrix/bits_inputs || return 1
  rm -rf "$logs/smoke" && mkdir -p "$logs/smoke"
  printf '{"version": 1, "effects": [{"effect": "gaussian_blur", "params": {"sigma": 4}}]}\n' >"$logs/smoke/blur.json"
  bash scripts/in_root.sh bullseye bash -c "ldd --version | head -1 \
    && build-linux-x64/libfx/libfx run --stack $logs/smoke/blur.json $in -o $logs/smoke/blur.exr \
    && test -s $logs/smoke/blur.exr && echo 'Debian 11: libfx run wrote $logs/smoke/blur.exr'"
}

# Same output bits as the development build (Debian 12's shared OpenEXR 3.1.5, gcc 12),
# on the cross-build check's recipes (tests/matrix/bits_dump.sh).
same_bits() {  # target cli-runner...
  local target=$1
  shift
  bash tests/matrix/make_bits_inputs.sh out/matrix/bits_inputs || return 1
  [ -f out/matrix/bits/host/version.txt ] \
    || bash tests/matrix/bits_dump.sh build/libfx/libfx out/matrix/bits_inputs out/matrix/bits/host || return 1
  rm -rf "out/matrix/bits/$target"
  bash tests/matrix/bits_dump.sh "$@" out/matrix/bits_inputs "out/matrix/bits/$target" || return 1
  LIBFX_BITS_DIRS="out/matrix/bits/host out/matrix/bits/$target" \
    /usr/bin/python3 -m pytest -q -p no:cacheprovider tests/matrix
}

step deps-windows bash scripts/deps.sh windows-x64
step build-linux-x64 build_linux
if [ $only_build = 1 ]; then
  step build-windows-x64 bash scripts/windows.sh --build
  printf '  %s\n' "${summary[@]}"
  exit $status
fi
step linux-x64-deps check_linux_deps
step linux-x64-ctest bash -c "cd build-linux-x64 && ctest --output-on-failure -j2"
step linux-x64-cli-tests env LIBFX_CLI="$here/build-linux-x64/libfx/libfx" \
  LIBFX_LIBRARY="$here/build-linux-x64/libfx/libfx.so.2" \
  /usr/bin/python3 -m pytest -q -p no:cacheprovider tests/python
step linux-x64-on-debian11 smoke_on_glibc_231
step linux-x64-same-bits same_bits linux-x64 build-linux-x64/libfx/libfx

# windows.sh: build, imports/exports, C and CLI tests under Wine, and the same bits as the
# development build (the DLL's AVX2 copy and its baseline one)
bash tests/matrix/make_bits_inputs.sh out/matrix/bits_inputs >/dev/null 2>&1 || true
step windows-x64 env LIBFX_BITS_INPUTS="$here/out/matrix/bits_inputs" bash scripts/windows.sh

# The packages of the two release libraries (wheels, per-platform extensions, legacy zips),
# then the linux-x64 extension where none of libfx's dependencies are installed.
rm -rf out/dist
step packages bash scripts/package.sh build-linux-x64/libfx/libfx.so.2 build-windows-x64/libfx/libfx.dll \
  out/dist --linux-cli build-linux-x64/libfx/libfx --windows-cli build-windows-x64/libfx/libfx.exe
for suite in trixie unstable; do
  step "extension-$suite" bash tests/platform/extension_in_root.sh "$suite" \
    "$(ls out/dist/libfx-*-linux_x64.zip 2>/dev/null | head -1)" "out/platforms/ext-$suite"
done

echo "== platforms summary"
printf '  %s\n' "${summary[@]}"
exit $status
