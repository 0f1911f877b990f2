#!/usr/bin/env bash
# Makes the separate Debian roots that hold the newer Blenders (Debian 13 "trixie":
# Blender 4.3; Debian unstable: Blender 5.x), and the Debian 11 "bullseye" build root
# (glibc 2.31, no Blender) in which the self-contained linux-x64 library is built
# (scripts/deps.sh, scripts/platforms.sh), with Debian's own mmdebstrap. Idempotent:
# a root that is complete (its marker file exists) is reused; a half-made one is
# removed and made again. Roots live outside the work tree, in $LIBFX_ROOTS
# (default /var/cache/libfx-roots), so a fresh clone on the same machine reuses them.
#
#   bash scripts/blender_roots.sh                 # trixie and unstable
#   bash scripts/blender_roots.sh trixie          # one of them (or bullseye)
#   bash scripts/blender_roots.sh --path trixie   # print the root's path (no work)
set -euo pipefail
cd "$(dirname "$0")/.."

ROOTS=${LIBFX_ROOTS:-/var/cache/libfx-roots}
# Everything the build and the Blender tests need inside a root. xvfb/xauth/mesa for
# the UI screenshot under a virtual display.
PACKAGES=blender,cmake,build-essential,pkg-config,libopenexr-dev,libcjson-dev,libpng-dev,libdeflate-dev
PACKAGES+=,python3-numpy,python3-pytest,python3-openimageio,openimageio-tools
PACKAGES+=,xvfb,xauth,libgl1-mesa-dri,ca-certificates
PACKAGES+=,nodejs   # the farm test runs the Flamenco job type
PACKAGES+=,imagemagick   # UI screenshots from the X display (4.3+ read back black under Xvfb)
# The build root for the linux-x64 release library: a toolchain, and nothing of
# libfx's dependencies (those are built from source, statically, by scripts/deps.sh).
BUILD_PACKAGES=build-essential,cmake,pkg-config,dpkg-dev,file,ca-certificates,python3
# The package mirror here is a dated snapshot: its Release files are "expired".
APT_OPT='Acquire::Check-Valid-Until "false";'
MARKER=.libfx-root-complete

root_path() { echo "$ROOTS/$1"; }

if [ "${1:-}" = "--path" ]; then
  root_path "${2:?usage: blender_roots.sh --path SUITE}"
  exit 0
fi

suites=("$@")
[ ${#suites[@]} -gt 0 ] || suites=(trixie unstable)

ensure_mmdebstrap() {
  command -v mmdebstrap >/dev/null && return
  local sudo=""
  [ "$(id -u)" -eq 0 ] || sudo=sudo
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq mmdebstrap
}

packages_for() { if [ "$1" = bullseye ]; then echo "$BUILD_PACKAGES"; else echo "$PACKAGES"; fi; }

# A root made before PACKAGES grew gets what it lacks, with the root's own apt.
add_missing() {
  local root=$1 missing=() p pk
  pk=$(packages_for "$(basename "$root")")
  for p in ${pk//,/ }; do
    chroot "$root" dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" \
      || missing+=("$p")
  done
  [ ${#missing[@]} -gt 0 ] || return 0
  echo "roots: adding ${missing[*]} to $root"
  bash scripts/in_root.sh "$(basename "$root")" bash -c \
    "apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq ${missing[*]} >/dev/null"
}

make_root() {
  local suite=$1 root
  root=$(root_path "$suite")
  if [ -f "$root/$MARKER" ]; then
    echo "roots: $suite: reusing $root ($(cat "$root/$MARKER"))"
    add_missing "$root"
    return
  fi
  ensure_mmdebstrap
  mkdir -p "$ROOTS"
  rm -rf "$root" "$root.partial"
  echo "roots: $suite: making $root (a few minutes, about 2 GB)"
  local t0=$SECONDS
  local try
  for try in 1 2; do   # a second try for a mirror's passing hiccup
    rm -rf "$root.partial"
    mmdebstrap --variant=apt --aptopt="$APT_OPT" --include="$(packages_for "$suite")" \
      "$suite" "$root.partial" >"$ROOTS/$suite.log" 2>&1 && break
    echo "roots: $suite: mmdebstrap failed (try $try); the end of $ROOTS/$suite.log:" >&2
    tail -20 "$ROOTS/$suite.log" >&2
    [ "$try" = 2 ] && return 1
  done
  # Later apt-get runs inside the root need the same option.
  echo "$APT_OPT" >"$root.partial/etc/apt/apt.conf.d/99libfx-snapshot"
  local version
  if [ "$suite" = bullseye ]; then
    version=$(chroot "$root.partial" dpkg-query -W -f='gcc ${Version}' gcc)
  else
    version=$(chroot "$root.partial" dpkg-query -W -f='blender ${Version}' blender)
  fi
  ln -sf /proc/self/mounts "$root.partial/etc/mtab"   # Blender asks for the mounted file systems
  mv "$root.partial" "$root"
  echo "$version, made $(date -u +%F) in $((SECONDS - t0)) s" >"$root/$MARKER"
  echo "roots: $suite: done ($(cat "$root/$MARKER"))"
}

for s in "${suites[@]}"; do
  make_root "$s"
done
