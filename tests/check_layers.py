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

With --objects FILE.o..., the library's object files are checked the same way at the
level of symbols (nm): a call or a reference from an object of one layer to a symbol
defined in a higher layer fails too, which an include check alone would miss (a function
declared in a lower header but defined above). The effect list CMake generates
(generated/effect_registry.c) is the effects' layer; core's registry reads it as data.

Usage: check_layers.py [REPO_ROOT] [--objects FILE.o...]
(default root: the repository holding this script)
Exit status 0 when every include and reference looks down, 1 otherwise (each offender
on stderr).
"""
import os
import re
import subprocess
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


# Core's registry reads the generated list of effect classes: data, not a call upward.
REGISTRY_DATA = {"fx_effect_classes", "fx_effect_class_count"}


def object_layer(path):
    """The layer of an object file from its path (.../src/<layer>/x.c.o, .../generated/...)."""
    parts = path.replace("\\", "/").split("/")
    if "generated" in parts:
        return "effects"
    for i in range(len(parts) - 1, 0, -1):
        if parts[i - 1] == "src" and parts[i] in LAYERS:
            return parts[i]
    return None


def check_objects(objects):
    """Errors for references from an object to a symbol defined in a higher layer."""
    defined, undefined, errors = {}, {}, []
    for obj in objects:
        layer = object_layer(obj)
        if layer is None:
            errors.append((obj, 0, "", "object file outside libfx/src's layers"))
            continue
        out = subprocess.run(["nm", obj], capture_output=True, text=True, check=True).stdout
        for line in out.splitlines():
            f = line.split()
            if len(f) == 3 and f[1] in "TDBRVWi":
                defined[f[2]] = (obj, layer)
            elif len(f) == 2 and f[0] == "U":
                undefined.setdefault(obj, (layer, set()))[1].add(f[1])
    for obj, (layer, names) in sorted(undefined.items()):
        for name in sorted(names):
            if name not in defined or name in REGISTRY_DATA:
                continue
            dobj, dlayer = defined[name]
            src = os.path.basename(dobj)[:-2] if dobj.endswith(".o") else dobj
            if (layer, dlayer) in APART:
                errors.append((obj, 0, name, "%s may not use %s (%s): they stand side by side"
                               % (layer, dlayer, src)))
            elif LAYERS[dlayer] > LAYERS[layer]:
                errors.append((obj, 0, name, "%s may not use %s, defined in %s (%s)"
                               % (layer, dlayer, src, dlayer)))
    return errors


def main(argv):
    args = argv[1:]
    objects = []
    if "--objects" in args:
        k = args.index("--objects")
        # CTest passes $<TARGET_OBJECTS:...> as one ';'-separated argument
        objects = [o for arg in args[k + 1:] for o in arg.split(";") if o]
        args = args[:k]
    root = args[0] if args else os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    if not os.path.isdir(os.path.join(root, "libfx", "src")):
        print("check_layers: no libfx/src under %s" % root, file=sys.stderr)
        return 2
    errors = check_library(root) + check_cli(root) + check_objects(objects)
    for rel, number, inc, reason in errors:
        where = "%s:%d" % (rel, number) if number else rel
        what = (' uses %s' % inc if where.endswith(".o") else ' includes "%s"' % inc) if inc else ""
        print("%s:%s: %s" % (where, what, reason), file=sys.stderr)
    if errors:
        print("check_layers: %d upward or sideways dependencies" % len(errors), file=sys.stderr)
        return 1
    print("check_layers: every include%s looks down" % (" and reference" if objects else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
