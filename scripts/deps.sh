#!/usr/bin/env bash
# Builds libfx's dependencies statically from Debian's own source packages, pinned,
# for one release target, once per machine (reused while the pins and this script's
# build recipe are unchanged):
#   linux-x64    inside the Debian 11 "bullseye" build root (glibc 2.31, gcc 10), so the
#                library made from them loads on any x86-64 Linux with glibc >= 2.31;
#                installed into the root at /opt/libfx-deps
#   windows-x64  with Debian 12's MinGW-w64 (gcc 12, posix threads), into
#                $LIBFX_DEPS/windows-x64 (default /var/cache/libfx-deps/windows-x64)
#
#   bash scripts/deps.sh linux-x64 windows-x64      # build (or reuse) both
#   bash scripts/deps.sh --prefix windows-x64       # the prefix, as seen from where it builds
#
# Sources come with `apt-get source` through a private apt state (its own sources list
# with deb-src entries on the mirror this machine uses, its own lists and cache), so the
# machine's apt configuration is left alone. dpkg-source applies Debian's patches.
set -euo pipefail
cd "$(dirname "$0")/.."
here=$PWD
CACHE=${LIBFX_DEPS:-/var/cache/libfx-deps}

# Debian 13 "trixie" source packages, each with the sha256 of its upstream tarball as
# the signed Sources index gives it. OpenEXR 3.1.13 is the first 3.1 whose C API
# (OpenEXRCore) decodes DWAA/DWAB correctly, so the static builds need no C++ reader.
# The package mirror here lacks the .dsc and Debian patch set of libdeflate 1.23, libpng 1.6.48, imath
# 3.1.12 and openexr 3.1.13 (404) but has their upstream tarballs: those build from the
# tarball alone; the other two get Debian's patches through dpkg-source.
PINS=(
  "zlib=1:1.3.dfsg+really1.3.1-1 60dd315c07f616887caa029408308a018ace66e3d142726a97db164b3b8f69fb"
  "libdeflate=1.23-2 1ab18349b9fb0ce8a0ca4116bded725be7dcbfa709e19f6f983d99df1fb8b25f"
  "libpng1.6=1.6.48-1+deb13u6 b17e99026055727e8cba99160c3a9a7f9af788e9f786daeadded5a42243f1dd0"
  "cjson=1.7.18-3.1+deb13u1 3aa806844a03442c00769b83e99970be70fbef03735ff898f4811dd03b9f5ee5"
  "imath=3.1.12-1 8a1bc258f3149b5729c2f4f8ffd337c0e57f09096e4ba9784329f40c4a9035da"
  "openexr=3.1.13-2 26d265d8cf8df4dad115b066ba209118ca8832cda076ec704ce1a57f827c75c6"
)
SUITE=trixie
# Bump when the build recipe below changes: a prefix built by another recipe is rebuilt.
RECIPE=2

stamp() { printf '%s\n' "${PINS[@]}" "recipe $RECIPE" | sha256sum | cut -c1-16; }

prefix_of() {
  case $1 in
    linux-x64) echo /opt/libfx-deps ;;
    windows-x64) echo "$CACHE/windows-x64" ;;
    *) echo "deps: unknown target '$1' (linux-x64 or windows-x64)" >&2; return 2 ;;
  esac
}

if [ "${1:-}" = "--prefix" ]; then
  prefix_of "${2:?usage: deps.sh --prefix TARGET}"
  exit 0
fi

source scripts/apt_missing.sh

# The deb-src mirror: the one the machine's own deb entries name.
mirror() {
  local m
  m=$(grep -rhoE 'https?://[^ ]*/debian/?( |$)' /etc/apt/sources.list /etc/apt/sources.list.d/ 2>/dev/null \
        | grep -v security | head -1 | tr -d ' ')
  echo "${m:-http://deb.debian.org/debian}"
}

# Downloads and unpacks every pinned source into $CACHE/src/<package> (once).
fetch_sources() {
  local src=$CACHE/src apt=$CACHE/apt
  if [ -f "$src/.complete-$(stamp)" ]; then return 0; fi
  apt_install_missing dpkg-dev
  rm -rf "$src" && mkdir -p "$src/dl" "$apt/lists/partial" "$apt/cache/archives/partial"
  echo "deb-src [check-valid-until=no] $(mirror) $SUITE main" >"$apt/sources.list"
  local o=(-o Dir::Etc::SourceList="$apt/sources.list" -o Dir::Etc::SourceParts=/dev/null
           -o Dir::State::Lists="$apt/lists" -o Dir::Cache="$apt/cache"
           -o Acquire::Check-Valid-Until=false)
  echo "deps: fetching Debian $SUITE sources"
  apt-get "${o[@]}" update -qq
  local pin pkg sum tarball dsc
  for pin in "${PINS[@]}"; do
    sum=${pin##* } pin=${pin% *} pkg=${pin%%=*}
    # apt checks every file it gets against the signed index; a file the mirror lacks
    # (see above) is a failure of apt-get that the tarball check below judges.
    (cd "$src/dl" && apt-get "${o[@]}" source --download-only -qq "$pin" 2>"$src/dl/$pkg.err") || true
    tarball=$(ls "$src/dl/${pkg}_"*.orig.tar.* 2>/dev/null | grep -v '\.asc$' | head -1 || true)
    if [ -z "$tarball" ] || [ "$(sha256sum <"$tarball" | cut -d' ' -f1)" != "$sum" ]; then
      echo "deps: $pin: no upstream tarball with sha256 $sum; apt said:" >&2
      cat "$src/dl/$pkg.err" >&2
      return 1
    fi
    dsc=$(ls "$src/dl/${pkg}_"*.dsc 2>/dev/null | head -1 || true)
    if [ -n "$dsc" ]; then
      # apt checked the files against the signed index; dpkg-source cannot check the
      # maintainer's signature without debian-keyring, and says so: kept out of the log.
      dpkg-source -x "$dsc" "$src/$pkg" >/dev/null 2>&1
      echo "$pin: Debian source package (patches applied)" >>"$src/SOURCES"
    else
      mkdir -p "$src/$pkg"
      tar -xf "$tarball" -C "$src/$pkg" --strip-components=1
      echo "$pin: upstream tarball $(basename "$tarball") (sha256 $sum), no Debian patches on the mirror" >>"$src/SOURCES"
    fi
    rm -f "$src/dl/${pkg}_"*
  done
  rm -rf "$src/dl"
  touch "$src/.complete-$(stamp)"
}

# ---- the build itself: runs where the compiler is (the bullseye root, or here) ----
# build_here TARGET PREFIX SRC
build_here() {
  local target=$1 prefix=$2 src=$3 work
  work=$(mktemp -d /tmp/libfx-deps.XXXXXX)
  trap 'rm -rf "$work"' RETURN
  rm -rf "$prefix" && mkdir -p "$prefix"
  local flags="-O2 -fPIC"
  local cm=(-G "Unix Makefiles" -DCMAKE_BUILD_TYPE=Release -DCMAKE_INSTALL_PREFIX="$prefix"
            -DCMAKE_INSTALL_LIBDIR=lib -DBUILD_SHARED_LIBS=OFF
            -DCMAKE_POSITION_INDEPENDENT_CODE=ON -DCMAKE_C_FLAGS="$flags" -DCMAKE_CXX_FLAGS="$flags"
            -DCMAKE_PREFIX_PATH="$prefix" -DZLIB_ROOT="$prefix")
  if [ "$target" = windows-x64 ]; then
    cm+=(-DCMAKE_TOOLCHAIN_FILE="$here/cmake/mingw-w64-x86_64.cmake" -DLIBFX_DEPS_PREFIX="$prefix")
  fi
  local jobs
  jobs=$(nproc)
  one() {   # one NAME [cmake args...]
    local name=$1
    shift
    echo "deps: $target: building $name"
    cmake -S "$src/$name" -B "$work/$name" "${cm[@]}" "$@" >"$work/$name.log" 2>&1 \
      && cmake --build "$work/$name" -j"$jobs" >>"$work/$name.log" 2>&1 \
      && cmake --install "$work/$name" >>"$work/$name.log" 2>&1 \
      || { echo "deps: $target: $name failed; the end of its log:" >&2; tail -30 "$work/$name.log" >&2; return 1; }
  }
  # zlib: only its static target, installed by hand under the name FindZLIB takes.
  # Debian's dfsg tarball dropped win32/, whose resource file the shared target lists
  # (CMake 3.18 wants it to exist even unbuilt): an empty one stands in.
  echo "deps: $target: building zlib"
  [ -e "$src/zlib/win32/zlib1.rc" ] || { mkdir -p "$src/zlib/win32" && : >"$src/zlib/win32/zlib1.rc"; }
  { cmake -S "$src/zlib" -B "$work/zlib" "${cm[@]}" -DZLIB_BUILD_EXAMPLES=OFF \
      && cmake --build "$work/zlib" --target zlibstatic -j"$jobs"; } >"$work/zlib.log" 2>&1 \
    || { echo "deps: $target: zlib failed; the end of its log:" >&2; tail -30 "$work/zlib.log" >&2; return 1; }
  mkdir -p "$prefix/include" "$prefix/lib"
  cp "$src/zlib/zlib.h" "$work/zlib/zconf.h" "$prefix/include/"
  cp "$work/zlib/"lib*.a "$prefix/lib/libz.a"
  one libdeflate -DLIBDEFLATE_BUILD_SHARED_LIB=OFF -DLIBDEFLATE_BUILD_GZIP=OFF
  one libpng1.6 -DPNG_SHARED=OFF -DPNG_STATIC=ON -DPNG_TESTS=OFF -DPNG_TOOLS=OFF \
    -DPNG_FRAMEWORK=OFF -DZLIB_LIBRARY="$prefix/lib/libz.a" -DZLIB_INCLUDE_DIR="$prefix/include"
  one cjson -DENABLE_CJSON_TEST=OFF -DENABLE_CJSON_UTILS=OFF -DBUILD_SHARED_AND_STATIC_LIBS=OFF \
    -DENABLE_TARGET_EXPORT=ON -DENABLE_CUSTOM_COMPILER_FLAGS=OFF
  one imath -DBUILD_TESTING=OFF -DPYTHON=OFF
  # OpenEXR's 3.1.12 and 3.1.13 tarballs still call themselves 3.1.11 in project(); the
  # version matters (libfx takes OpenEXRCore's own DWA decoder from 3.1.13 on, which has
  # the channel-classifier fix), so it is set to the release's number.
  sed -i 's/^project(OpenEXR VERSION 3\.1\.11 /project(OpenEXR VERSION 3.1.13 /' "$src/openexr/CMakeLists.txt"
  grep -q '^project(OpenEXR VERSION 3.1.13 ' "$src/openexr/CMakeLists.txt" \
    || { echo "deps: openexr: expected the 3.1.13 tarball's project() line" >&2; return 1; }
  one openexr -DBUILD_TESTING=OFF -DOPENEXR_BUILD_TOOLS=OFF -DOPENEXR_INSTALL_TOOLS=OFF \
    -DOPENEXR_INSTALL_EXAMPLES=OFF -DOPENEXR_INSTALL_PKG_CONFIG=OFF
  # No shared library may be found in place of a static one.
  find "$prefix" \( -name '*.so' -o -name '*.so.*' -o -name '*.dll' -o -name '*.dll.a' \) -delete
  cp "$src/SOURCES" "$prefix/SOURCES"
  echo "$(stamp)" >"$prefix/.libfx-deps-complete"
  echo "deps: $target: done in $prefix"
}

if [ "${1:-}" = "--build-here" ]; then   # internal: deps.sh --build-here TARGET PREFIX SRC
  build_here "$2" "$3" "$4"
  exit 0
fi

targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(linux-x64 windows-x64)
for t in "${targets[@]}"; do
  prefix_of "$t" >/dev/null
done

for t in "${targets[@]}"; do
  case $t in
    windows-x64)
      prefix=$(prefix_of "$t")
      if [ "$(cat "$prefix/.libfx-deps-complete" 2>/dev/null)" = "$(stamp)" ]; then
        echo "deps: $t: reusing $prefix"
        continue
      fi
      apt_install_missing gcc-mingw-w64-x86-64 g++-mingw-w64-x86-64 cmake
      fetch_sources
      t0=$SECONDS
      build_here "$t" "$prefix" "$CACHE/src"
      echo "deps: $t: built in $((SECONDS - t0)) s"
      ;;
    linux-x64)
      bash scripts/blender_roots.sh bullseye
      root=$(bash scripts/blender_roots.sh --path bullseye)
      prefix=$(prefix_of "$t")
      if [ "$(cat "$root$prefix/.libfx-deps-complete" 2>/dev/null)" = "$(stamp)" ]; then
        echo "deps: $t: reusing $root$prefix"
        continue
      fi
      fetch_sources
      rm -rf "$root/opt/libfx-src" && mkdir -p "$root/opt"
      cp -a "$CACHE/src" "$root/opt/libfx-src"
      t0=$SECONDS
      bash scripts/in_root.sh bullseye bash scripts/deps.sh --build-here "$t" "$prefix" /opt/libfx-src
      rm -rf "$root/opt/libfx-src"
      echo "deps: $t: built in $((SECONDS - t0)) s"
      ;;
  esac
done
