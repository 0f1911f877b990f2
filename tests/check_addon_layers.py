#!/usr/bin/python3
"""Fails when the Blender add-on's modules import in a cycle, or a module imports one of a
layer above its own.

Every module of addon/libfx is parsed with `ast` and every import is counted, at module
level and inside functions alike: `from . import x`, `from .x import y`, `from .. import`
is not used, `import libfx.x`, `from libfx import x`, `from libfx.x import y` (and the
package itself, `import libfx`, as its __init__). An import that is only done inside a
function is still a dependency: it is how a cycle hides.

The layers, bottom to top (docs/architecture.md, "The add-on's layers"), are the LAYERS
table below. A module may import modules of its own layer or of layers below; any cycle
among the modules fails, whatever their layers. A module the table does not know fails
too, and so does a name in the table with no module, so a new file has to be given its
place here. The reload list in __init__.py (the tuple of module names its reload guard
walks) must name every module the package imports, each after the modules it imports.

Usage: check_addon_layers.py [REPO_ROOT | --addon DIR]
(default root: the repository holding this script; the add-on is REPO_ROOT/addon/libfx)
Exit status 0 when the modules form layers that only look down, 1 otherwise (each cycle
and each upward import on stderr), 2 when there is no add-on to check.
"""
import ast
import os
import sys

PACKAGE = "libfx"

#: The add-on's layers, bottom to top. Change notices go up through `hooks` (a lower
#: module calls hooks.notify; a higher one listens from its register()), never by import.
LAYER_NAMES = ("leaves", "model", "adapters", "runtime", "engine", "handlers", "operators",
               "ui", "package")
LAYERS = {
    # leaves: no module of the add-on below them but each other
    "log": 0,          # the console lines and the live trace
    "hooks": 0,        # change notices that go up
    "native": 0,       # the ctypes binding of the library
    "compat": 0,       # Blender version differences
    "catalog": 0,      # the library's effect descriptions as the UI's model
    "frames": 0,       # frame lists (--frames), also loaded by path by the farm's submitters
    # model: no bpy
    "recipe_json": 1,  # the recipe JSON: version, values, parsing, the library's checks
    "sessions": 1,     # live sessions: the frames held per scene, the live settings' meaning
    # Blender adapters
    "props": 2,        # property groups generated from the catalogue
    "recipe": 2,       # the scene's stack <-> the recipe
    "scene_setup": 2,  # the passes the stack needs, output paths, the panel's status
    "passes_file": 2,  # the Render Result's passes as one EXR
    "aux_views": 2,    # light views, rain map, probes, planar views
    "sidecars": 2,     # the scene sidecar of each frame and its store
    "contact_sheet": 2,  # a range's results as one PNG of thumbnails (batch --check)
    # runtime: the shared context, the worker, the UI queue, the results
    "shared_context": 3,
    "worker": 3,
    "ui_queue": 3,
    "results": 3,
    # engine: the live loop, the frame pipeline, the background views job
    "live": 4,
    "pipeline": 4,
    "views_job": 4,
    # handlers
    "handlers": 5,
    # operators
    "operators": 6,
    # UI: panels, list, menu
    "ui": 7,
    # package: registration, the names older scripts use, the batch runner
    "render": 8,
    "__init__": 8,
    "batch": 8,
}


def module_files(addon):
    """{module name: path} of the add-on's Python files (the package's __init__ included)."""
    out = {}
    for name in sorted(os.listdir(addon)):
        if name.endswith(".py"):
            out[name[:-3]] = os.path.join(addon, name)
    return out


def imports(path, known):
    """[(line, imported module)] for every import of an add-on module in the file, at any
    depth."""
    with open(path, encoding="utf-8") as fh:
        tree = ast.parse(fh.read(), filename=path)
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level == 1:
                if node.module is None:          # from . import x, y
                    names = [a.name for a in node.names]
                else:                            # from .x import y (y may be a submodule)
                    names = [node.module.split(".")[0]]
            elif node.level == 0 and node.module and node.module.split(".")[0] == PACKAGE:
                parts = node.module.split(".")
                if len(parts) == 1:              # from libfx import x
                    names = [a.name for a in node.names if a.name in known] or ["__init__"]
                else:                            # from libfx.x import y
                    names = [parts[1]]
            else:
                continue
            out += [(node.lineno, n) for n in names if n in known]
        elif isinstance(node, ast.Import):
            for a in node.names:
                parts = a.name.split(".")
                if parts[0] != PACKAGE:
                    continue
                target = parts[1] if len(parts) > 1 else "__init__"
                if target in known:
                    out.append((node.lineno, target))
    return out


def graph(addon):
    """{module: [(line, imported module)]}; a module's import of itself is kept (a cycle)."""
    files = module_files(addon)
    known = set(files)
    return {m: imports(p, known) for m, p in files.items()}, files


def cycles(edges):
    """The strongly connected components with a cycle (Tarjan), each sorted."""
    succ = {m: sorted({t for _, t in e}) for m, e in edges.items()}
    index, low, on, stack, comps = {}, {}, set(), [], []
    counter = [0]

    def visit(v):   # iterative enough for a few dozen modules
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in succ.get(v, []):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1 or v in succ.get(v, []):
                comps.append(sorted(comp))

    for v in sorted(succ):
        if v not in index:
            visit(v)
    return sorted(comps)


def shortest_path(succ, start, goal, inside):
    """Modules from start to goal along imports, staying inside one component (BFS)."""
    prev, todo = {start: None}, [start]
    while todo:
        nxt = []
        for v in todo:
            if v == goal:
                path = []
                while v is not None:
                    path.append(v)
                    v = prev[v]
                return path[::-1]
            for w in succ.get(v, []):
                if w in inside and w not in prev:
                    prev[w] = v
                    nxt.append(w)
        todo = nxt
    return None


def describe_cycles(edges, comps):
    """Per component: its modules and the cycles through each of its imports, each once."""
    succ = {m: sorted({t for _, t in e}) for m, e in edges.items()}
    out = []
    for comp in comps:
        inside = set(comp)
        seen, loops = set(), []
        for a in comp:
            for b in succ.get(a, []):
                if b not in inside:
                    continue
                back = [a] if a == b else shortest_path(succ, b, a, inside)
                loop = [a] + (back if a != b else [])
                body = loop[:-1] if len(loop) > 1 and loop[-1] == loop[0] else loop
                k = body.index(min(body))
                key = tuple(body[k:] + body[:k])
                if key not in seen:
                    seen.add(key)
                    loops.append(list(key) + [key[0]])
        out.append((comp, sorted(loops, key=lambda l: (len(l), l))))
    return out


#: Modules the package never imports: not in the reload list.
NOT_RELOADED = {"__init__", "batch"}


def reload_list(path):
    """(line, [names]) of the reload guard's list in __init__.py: the tuple or list of
    module-name strings a `for` loop walks; (0, None) when there is none."""
    with open(path, encoding="utf-8") as fh:
        tree = ast.parse(fh.read(), filename=path)
    for node in ast.walk(tree):
        if isinstance(node, ast.For) and isinstance(node.iter, (ast.Tuple, ast.List)) and node.iter.elts \
                and all(isinstance(e, ast.Constant) and isinstance(e.value, str) for e in node.iter.elts):
            return node.lineno, [e.value for e in node.iter.elts]
    return 0, None


def check_reload(files, edges):
    """Errors of __init__.py's reload list: missing or unknown modules, wrong order."""
    init = files.get("__init__")
    if init is None:
        return []
    line, names = reload_list(init)
    where = "%s:%d" % (os.path.relpath(init), line)
    if names is None:
        return ["%s: no reload list (a for loop over a tuple of module names)" % os.path.relpath(init)]
    errors = []
    for m in sorted(set(files) - NOT_RELOADED - set(names)):
        errors.append("%s: the reload list leaves out '%s'" % (where, m))
    for m in names:
        if m not in files or m in NOT_RELOADED:
            errors.append("%s: the reload list names '%s', which is not a module the package imports"
                          % (where, m))
    pos = {m: i for i, m in enumerate(names)}
    for m in names:
        for _, t in sorted(edges.get(m, [])):
            if t in pos and t != m and pos[t] > pos[m]:
                errors.append("%s: the reload list has '%s' before '%s', which it imports"
                              % (where, m, t))
    return sorted(set(errors), key=errors.index)


def check(addon):
    """(errors, the import graph): errors are lines to print."""
    edges, files = graph(addon)
    errors = []
    for m in sorted(files):
        if m not in LAYERS:
            errors.append("%s: module '%s' has no layer in tests/check_addon_layers.py" % (files[m], m))
    for m in sorted(set(LAYERS) - set(files)):
        errors.append("%s: the layer table names '%s', which is not a module of the add-on"
                      % (addon, m))
    for m in sorted(files):
        if m not in LAYERS:
            continue
        for line, t in sorted(edges[m]):
            if t in LAYERS and LAYERS[t] > LAYERS[m]:
                errors.append("%s:%d: %s (%s) imports %s (%s), a layer above it"
                              % (os.path.relpath(files[m]), line, m, LAYER_NAMES[LAYERS[m]], t,
                                 LAYER_NAMES[LAYERS[t]]))
    errors += check_reload(files, edges)
    for comp, loops in describe_cycles(edges, cycles(edges)):
        errors.append("import cycle among %s:" % ", ".join(comp))
        for loop in loops:
            errors.append("  cycle: %s" % " -> ".join(loop))
        for m in comp:
            for line, t in sorted(edges[m]):
                if t in comp:
                    errors.append("    %s:%d: %s imports %s" % (os.path.relpath(files[m]), line, m, t))
    return errors, edges


def main(argv):
    args = argv[1:]
    if args[:1] == ["--addon"] and len(args) == 2:
        addon = args[1]
    else:
        root = args[0] if args else os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        addon = os.path.join(root, "addon", PACKAGE)
    if not os.path.isfile(os.path.join(addon, "__init__.py")):
        print("check_addon_layers: no add-on package at %s" % addon, file=sys.stderr)
        return 2
    errors, edges = check(addon)
    for e in errors:
        print(e, file=sys.stderr)
    n = sum(len(e) for e in edges.values())
    if errors:
        print("check_addon_layers: %d problem(s) in %d modules, %d imports"
              % (sum(1 for e in errors if not e.startswith(" ")), len(edges), n), file=sys.stderr)
        return 1
    print("check_addon_layers: %d modules, %d imports, no cycle, every import looks down"
          % (len(edges), n))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
