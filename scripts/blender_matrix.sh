#!/usr/bin/env bash
# The Blender test matrix: tests/blender against every Blender the project supports,
# each with the libfx that its own system builds, then the cross-build check that
# those libfx builds give the same output bits.
#
#   bash scripts/blender_matrix.sh                 # host (Debian 12: Blender 3.4) + trixie (4.3) + unstable (5.x)
#   bash scripts/blender_matrix.sh host unstable   # some of them
#   PYTEST_ARGS="-k atrium" bash scripts/blender_matrix.sh trixie
#
# The host's build is build/ (scripts/setup.sh makes it); a root's is build-<suite>/,
# made inside the root with its own compiler and OpenEXR. Roots are made (or reused)
# by scripts/blender_roots.sh. Logs: out/matrix/<target>.log; summary at the end.
# Exit status: non-zero if any target failed.
set -uo pipefail
cd "$(dirname "$0")/.."
here=$PWD
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(host trixie unstable)
logs=out/matrix
mkdir -p "$logs"
status=0
summary=()
bits_dirs=()

stamp() { date -u +%H:%M:%S; }

# The per-build output of the same recipes on the same EXRs (tests/matrix/bits_dump.sh).
dump_bits() {  # target, cli path, runner...
  local target=$1 cli=$2; shift 2
  rm -rf "$logs/bits/$target"
  [ -f "$logs/bits_inputs/complete" ] || return 0
  "$@" bash tests/matrix/bits_dump.sh "$cli" "$logs/bits_inputs" "$logs/bits/$target" >>"$logs/$target.log" 2>&1 \
    && bits_dirs+=("$logs/bits/$target")
}

# The host's packages first (mmdebstrap among them: two root jobs must not both
# apt-get install it at once), then the roots that are missing are made in the
# background (mostly download and unpack) while the host's Blender is tested.
bash scripts/setup.sh >"$logs/setup.log" 2>&1
declare -A root_job
for t in "${targets[@]}"; do
  [ "$t" = host ] && continue
  bash scripts/blender_roots.sh "$t" >"$logs/root-$t.log" 2>&1 &
  root_job[$t]=$!
done

# The inputs of the cross-build check, rendered once by the host's Blender.
if ! bash tests/matrix/make_bits_inputs.sh "$logs/bits_inputs"; then
  summary+=("same bits: FAILED to render the inputs"); status=1
fi

for t in "${targets[@]}"; do
  t0=$SECONDS
  log="$logs/$t.log"
  : >"$log"
  echo "== matrix: $t ($(stamp))"
  if [ "$t" = host ]; then
    run=()
    build=build
    bash scripts/setup.sh >>"$log" 2>&1   # builds what changed (the add-on zip too)
  else
    if ! wait "${root_job[$t]}"; then
      cat "$logs/root-$t.log" >>"$log"
      summary+=("$t: FAILED to make the root (see $logs/root-$t.log)"); status=1; continue
    fi
    cat "$logs/root-$t.log" | tee -a "$log"
    run=(bash scripts/in_root.sh "$t")
    build=build-$t
    echo "-- building libfx in the $t root" | tee -a "$log"
    if ! "${run[@]}" bash -c "cmake -B $build -S . -DCMAKE_BUILD_TYPE=Release -DLIBFX_BUILD_BENCH=OFF >/dev/null \
          && cmake --build $build -j$(nproc)" >>"$log" 2>&1; then
      summary+=("$t: FAILED to build libfx (see $log)"); status=1; continue
    fi
  fi
  version=$("${run[@]}" blender --factory-startup -b --version 2>/dev/null | grep -m1 '^Blender' || echo "Blender ?")
  compiler=$("${run[@]}" bash -c 'gcc -dumpfullversion; dpkg-query -W -f="\${Version}" libopenexr-dev' 2>/dev/null | tr '\n' ' ')
  echo "-- $version; gcc / OpenEXR: $compiler" | tee -a "$log"
  dump_bits "$t" "$build/libfx/libfx" "${run[@]}"
  "${run[@]}" env LIBFX_LIBRARY="$here/$build/libfx/libfx.so" LIBFX_CLI="$here/$build/libfx/libfx" \
      PYTHONDONTWRITEBYTECODE=1 \
      /usr/bin/python3 -m pytest -q -p no:cacheprovider ${PYTEST_ARGS:-} tests/blender >>"$log" 2>&1
  rc=$?
  result=$(grep -E '^(=+ )?[0-9]+ (passed|failed)|(passed|failed|error).* in [0-9.]+s' "$log" | tail -1)
  summary+=("$t: $version: ${result:-no pytest summary} ($((SECONDS - t0)) s)")
  [ $rc -eq 0 ] || status=1
  tail -3 "$log"
done

if [ ${#bits_dirs[@]} -ge 2 ]; then
  echo "== matrix: same output bits from every build ($(stamp))"
  LIBFX_BITS_DIRS="${bits_dirs[*]}" /usr/bin/python3 -m pytest -q -p no:cacheprovider tests/matrix \
    >"$logs/bits.log" 2>&1
  rc=$?
  summary+=("same bits (${bits_dirs[*]}): $(tail -1 "$logs/bits.log")")
  [ $rc -eq 0 ] || status=1
elif [ ${#targets[@]} -ge 2 ]; then
  summary+=("same bits: FAILED, fewer than two builds dumped their outputs"); status=1
fi

echo "== matrix summary"
printf '  %s\n' "${summary[@]}"
exit $status
