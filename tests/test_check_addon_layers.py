#!/usr/bin/python3
"""Proves check_addon_layers.py can fail: small add-on packages with one bad import each
(at module level or inside a function, in each import form) must be refused, naming the
file, the line and the modules; a package whose imports only look down must pass; and the
real add-on passes.

    /usr/bin/python3 -m pytest -q tests/test_check_addon_layers.py
    /usr/bin/python3 tests/test_check_addon_layers.py        # the same, without pytest (CTest)
"""
import importlib.util
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
CHECKER = os.path.join(HERE, "check_addon_layers.py")
REPO = os.path.dirname(HERE)

_spec = importlib.util.spec_from_file_location("check_addon_layers", CHECKER)
C = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(C)

#: A small package: leaves, a model, an adapter, the engine, the UI, the package.
LAYERS = {"log": 0, "hooks": 0, "model": 1, "adapter": 2, "engine": 4, "ui": 7,
          "__init__": 8, "batch": 8}
GOOD = {
    "log.py": "import sys\n",
    "hooks.py": "",
    "model.py": "from . import log\n",
    "adapter.py": "import bpy\nfrom . import hooks, model\n\ndef f():\n    hooks.notify('changed')\n",
    "engine.py": "from .adapter import f\nfrom . import hooks\n\ndef register():\n"
                 "    hooks.listen('changed', f)\n",
    "ui.py": "from . import engine\n\ndef g():\n    from . import adapter\n",
    "__init__.py": "if 'log' in locals():\n    for _m in ('log', 'hooks', 'model', 'adapter', 'engine', 'ui'):\n"
                   "        pass\nfrom . import log, hooks, model, adapter, engine, ui\n",
    "batch.py": "def main():\n    import libfx\n",
}


def make(root, changes=None):
    files = dict(GOOD)
    files.update(changes or {})
    for name, text in files.items():
        if text is None:
            continue
        with open(os.path.join(root, name), "w") as fh:
            fh.write(text)
    return root


def errors_of(changes=None, layers=LAYERS):
    with tempfile.TemporaryDirectory() as d:
        saved = C.LAYERS
        C.LAYERS = layers
        try:
            errors, _ = C.check(make(d, changes))
        finally:
            C.LAYERS = saved
        return [e.replace(os.path.relpath(d) + os.sep, "") for e in errors]


def assert_refused(changes, *needles, layers=LAYERS):
    errors = errors_of(changes, layers)
    text = "\n".join(errors)
    assert errors, "accepted: %r" % changes
    for n in needles:
        assert n in text, "%r not in:\n%s" % (n, text)


def test_good_package_passes():
    assert errors_of() == []


def test_cycle_through_an_import_inside_a_function():
    # adapter imports engine only inside a function: still a cycle (and upward)
    assert_refused({"adapter.py": GOOD["adapter.py"] + "\ndef h():\n    from . import engine\n"},
                   "import cycle among adapter, engine", "cycle: adapter -> engine -> adapter",
                   "adapter.py:8: adapter imports engine", "engine.py:1: engine imports adapter",
                   "adapter.py:8: adapter (adapters) imports engine (engine), a layer above it")


def test_cycle_within_one_layer():
    # same layer, so no layer error: the cycle alone must fail
    errors = errors_of({"log.py": "from . import hooks\n", "hooks.py": "def f():\n    from .log import x\n"})
    text = "\n".join(errors)
    assert "cycle: hooks -> log -> hooks" in text, text
    assert "hooks.py:2: hooks imports log" in text and "log.py:1: log imports hooks" in text, text
    assert "a layer above" not in text, text


def test_longer_cycle_is_named_whole():
    assert_refused({"model.py": "from . import log\n", "log.py": "import libfx.adapter\n"},
                   "cycle: adapter -> model -> log -> adapter", "log.py:1: log imports adapter")


def test_each_import_form_counts():
    for text in ("from . import engine\n", "from .engine import x\n", "import libfx.engine\n",
                 "import libfx.engine as e\n", "from libfx import engine\n", "from libfx.engine import x\n",
                 "def f():\n    if True:\n        from . import engine\n",
                 "class K:\n    def m(self):\n        import libfx.engine\n"):
        assert_refused({"model.py": text}, "model (model) imports engine (engine), a layer above it")


def test_the_package_itself_is_its_init():
    assert_refused({"engine.py": "def f():\n    import libfx\n"},
                   "engine (engine) imports __init__ (package), a layer above it",
                   "cycle: __init__ -> engine -> __init__")


def test_other_packages_do_not_count():
    assert errors_of({"model.py": "import bpy\nimport os.path\nfrom bpy import props\n"
                                  "from libfxx import engine\nimport libfx_other.engine\n"}) == []


def test_module_without_a_layer_and_stale_table():
    assert_refused({"newthing.py": "from . import log\n"}, "module 'newthing' has no layer")
    assert_refused({}, "the layer table names 'gone'", layers=dict(LAYERS, gone=3))


def test_reload_list():
    init = GOOD["__init__.py"]
    assert_refused({"__init__.py": init.replace("'model', ", "")},
                   "__init__.py:2: the reload list leaves out 'model'")
    assert_refused({"__init__.py": init.replace("'model', 'adapter'", "'adapter', 'model'")},
                   "the reload list has 'adapter' before 'model', which it imports")
    assert_refused({"__init__.py": init.replace("'ui')", "'ui', 'batch')")},
                   "names 'batch', which is not a module the package imports")
    assert_refused({"__init__.py": "from . import log, hooks, model, adapter, engine, ui\n"},
                   "no reload list")


def test_command_line_on_a_bad_and_the_real_package():
    with tempfile.TemporaryDirectory() as d:
        make(d, {"ui.py": GOOD["ui.py"], "log.py": "def f():\n    from . import ui\n"})
        p = subprocess.run([sys.executable, CHECKER, "--addon", d], capture_output=True, text=True)
    # the real table knows no module named 'model': the run must fail, naming the cycle
    assert p.returncode == 1, p
    assert "log.py:2: log imports ui" in p.stderr and "cycle: " in p.stderr, p.stderr
    p = subprocess.run([sys.executable, CHECKER, REPO], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert "no cycle, every import looks down" in p.stdout, p.stdout


def main():
    failures = 0
    for name, fn in sorted(globals().items()):
        if name.startswith("test_") and callable(fn):
            try:
                fn()
            except AssertionError as e:
                failures += 1
                print("FAIL %s: %s" % (name, e), file=sys.stderr)
    print("test_check_addon_layers: %d case(s) failed" % failures if failures else "test_check_addon_layers: ok")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
