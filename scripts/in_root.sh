#!/usr/bin/env bash
# Runs a command inside one of the Blender roots (scripts/blender_roots.sh), with
# this work tree and ../shared at the same paths as outside, /proc, /sys and /dev
# bound in. The mounts live in a private mount namespace (unshare), so they vanish
# when the command ends, however it ends, and runs in parallel do not meet.
#
#   bash scripts/in_root.sh unstable blender --version
#
# With IN_ROOT_OVERLAY=DIR the root is the lower layer of an overlay whose changes go to
# DIR (DIR/upper, DIR/work): a throw-away copy of the root (scripts/platforms.sh strips
# packages from such copies) that leaves the root itself untouched.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
suite=${1:?usage: in_root.sh SUITE COMMAND...}
shift
root=$(bash "$here/scripts/blender_roots.sh" --path "$suite")
[ -f "$root/.libfx-root-complete" ] || {
  echo "in_root: no complete root for '$suite' at $root (run scripts/blender_roots.sh $suite)" >&2
  exit 2
}
shared=$(cd "$here/.." && pwd)/shared
overlay=${IN_ROOT_OVERLAY:-}
[ -z "$overlay" ] || { mkdir -p "$overlay/upper" "$overlay/work" "$overlay/merged"; overlay=$(cd "$overlay" && pwd); }
export IN_ROOT_ROOT="$root" IN_ROOT_HERE="$here" IN_ROOT_SHARED="$shared" IN_ROOT_SUITE="$suite"
export IN_ROOT_OVERLAY="$overlay"
exec unshare --mount --propagation private bash -c '
  set -e
  r=$IN_ROOT_ROOT
  if [ -n "$IN_ROOT_OVERLAY" ]; then
    o=$IN_ROOT_OVERLAY
    mount -t overlay overlay -o "lowerdir=$r,upperdir=$o/upper,workdir=$o/work" "$o/merged"
    r=$o/merged
  fi
  for d in proc sys dev; do mount --rbind "/$d" "$r/$d"; done
  mkdir -p "$r$IN_ROOT_HERE"
  mount --bind "$IN_ROOT_HERE" "$r$IN_ROOT_HERE"
  if [ -d "$IN_ROOT_SHARED" ]; then
    mkdir -p "$r$IN_ROOT_SHARED"
    mount --bind "$IN_ROOT_SHARED" "$r$IN_ROOT_SHARED"
  fi
  cd /
  exec chroot "$r" /usr/bin/env -i HOME=/root PATH=/usr/local/bin:/usr/bin:/bin \
    LANG=C.UTF-8 TERM=dumb CI="${CI:-}" LIBFX_ROOT_SUITE="$IN_ROOT_SUITE" \
    bash -c "cd \"\$0\" && exec \"\$@\"" "$IN_ROOT_HERE" "$@"
' bash "$@"
