#!/usr/bin/python3
"""Fails when a file of libfx includes a header of a layer above its own.

The layers, bottom to top (docs/architecture.md draws them):

    core     memory, context, frames, buffers, passes, masks, stack, parameters, registry
    io, math EXR/PNG files; numerical building blocks (neither includes the other)
    scene    the sidecar, camera and lights, aux views and their cache, maps built from them
    effects  one file per effect

The CLI stands outside: it includes the public header libfx/fx.h and its own headers only.
Every quoted #include of libfx/src and libfx/cli is checked; angle-bracket includes are
system headers. A header in a folder the table does not know is an error too, so a new
folder has to be given its place here.

Usage: check_layers.py [REPO_ROOT]   (default: the repository holding this script)
Exit status 0 when every include looks down, 1 otherwise (each offender on stderr).
"""
import os
import re
import sys

LAYERS = {"core": 0, "io": 1, "math": 1, "scene": 2, "effects": 3}
# Same level, still apart: the file formats and the numerics do not know each other.
APART = {("io", "math"), ("math", "io")}
PUBLIC = "libfx/fx.h"
INCLUDE = re.compile(r'^\s*#\s*include\s*"([^"]+)"')
SOURCE_EXT = (".c", ".h", ".cpp", ".in")


def includes(path):
    with open(path, encoding="utf-8", errors="replace") as fh:
        for number, line in enumerate(fh, 1):
            m = INCLUDE.match(line)
            if m:
                yield number, m.group(1)


def check_library(root):
    """Errors for libfx/src: (file, line, include, reason)."""
    src = os.path.join(root, "libfx", "src")
    errors = []
    for folder in sorted(os.listdir(src)):
        base = os.path.join(src, folder)
        if not os.path.isdir(base):
            continue
        for dirpath, _dirs, files in os.walk(base):
            for name in sorted(files):
                if not name.endswith(SOURCE_EXT):
                    continue
                path = os.path.join(dirpath, name)
                rel = os.path.relpath(path, root)
                if folder not in LAYERS:
                    errors.append((rel, 0, "", "folder '%s' has no layer in tests/check_layers.py" % folder))
                    continue
                for number, inc in includes(path):
                    if inc == PUBLIC:
                        continue
                    target = inc.split("/", 1)[0] if "/" in inc else None
                    if target is None:
                        errors.append((rel, number, inc, "include headers by their folder (core/..., math/...)"))
                    elif target not in LAYERS:
                        errors.append((rel, number, inc, "'%s' is not a layer of libfx/src" % target))
                    elif (folder, target) in APART:
                        errors.append((rel, number, inc, "%s may not include %s (they stand side by side)"
                                       % (folder, target)))
                    elif LAYERS[target] > LAYERS[folder]:
                        errors.append((rel, number, inc, "%s may not include %s, a layer above it"
                                       % (folder, target)))
    return errors


def check_cli(root):
    """The CLI uses the public API only: libfx/fx.h and headers beside its own files."""
    cli = os.path.join(root, "libfx", "cli")
    errors = []
    if not os.path.isdir(cli):
        return errors
    for name in sorted(os.listdir(cli)):
        if not name.endswith(SOURCE_EXT):
            continue
        path = os.path.join(cli, name)
        for number, inc in includes(path):
            if inc != PUBLIC and "/" in inc:
                errors.append((os.path.relpath(path, root), number, inc,
                               "the CLI uses the public API only (libfx/fx.h)"))
    return errors


def main(argv):
    root = argv[1] if len(argv) > 1 else os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    if not os.path.isdir(os.path.join(root, "libfx", "src")):
        print("check_layers: no libfx/src under %s" % root, file=sys.stderr)
        return 2
    errors = check_library(root) + check_cli(root)
    for rel, number, inc, reason in errors:
        where = "%s:%d" % (rel, number) if number else rel
        what = ' includes "%s"' % inc if inc else ""
        print("%s:%s: %s" % (where, what, reason), file=sys.stderr)
    if errors:
        print("check_layers: %d upward or sideways include(s)" % len(errors), file=sys.stderr)
        return 1
    print("check_layers: every include looks down")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
