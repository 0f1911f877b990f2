#!/usr/bin/python3
"""Proves check_function_length.py counts as ctags does and can fail: in a small tree, a
function of 120 lines (signature to closing brace) passes and one of 121 fails, named as
FILE:LINE:NAME:LENGTH; in a header and in the CLI too; prototypes and macros are no
functions."""
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
CHECKER = os.path.join(HERE, "check_function_length.py")


def function(name, lines, static_inline=False):
    """C text of a function `lines` long from its signature line to its closing brace."""
    assert lines >= 3
    head = ("static inline int %s(int x)" if static_inline else "int %s(int x)") % name
    body = ["{"] + ["    x += %d;" % i for i in range(lines - 4)] + ["    return x;", "}"]
    return "\n".join([head] + body) + "\n"


def make_tree(root, files):
    for rel, text in files.items():
        path = os.path.join(root, rel)
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, "w") as fh:
            fh.write(text)


def run(root, *extra):
    p = subprocess.run([sys.executable, CHECKER, root] + list(extra), capture_output=True, text=True)
    return p.returncode, p.stderr


failures = 0


def expect(cond, what):
    global failures
    if not cond:
        failures += 1
        print("FAIL: " + what, file=sys.stderr)


BASE = {
    # a comment line and a prototype above: the count starts at the signature
    "libfx/src/core/a.c": "/* a */\nint fits(int x);\n\n" + function("fits", 120),
    "libfx/src/math/m.h": "#define LONG_MACRO(x) \\\n" + "    (x) + \\\n" * 200 + "    0\n" + function("inline_fits", 120, True),
    "libfx/cli/main.c": function("small", 10),
}

with tempfile.TemporaryDirectory() as tmp:
    # 120 lines everywhere: passes
    good = os.path.join(tmp, "good")
    make_tree(good, BASE)
    rc, err = run(good)
    expect(rc == 0, "120-line functions pass (rc %d: %s)" % (rc, err))

    # 121 lines: fails, named file:line:name:length
    for rel, line, name, text in [
        ("libfx/src/core/b.c", 4, "too_long", "\n\n\n" + function("too_long", 121)),
        ("libfx/src/effects/e.h", 1, "inline_too_long", function("inline_too_long", 121, True)),
        ("libfx/cli/cmd.c", 2, "cli_too_long", "\n" + function("cli_too_long", 121)),
    ]:
        bad = os.path.join(tmp, "bad_" + name)
        make_tree(bad, dict(BASE, **{rel: text}))
        rc, err = run(bad)
        expect(rc == 1, "%s of 121 lines fails (rc %d)" % (name, rc))
        expect("%s:%d:%s:121" % (rel, line, name) in err, "%s named as file:line:name:length: %r" % (name, err))
        expect("fits" not in err, "the 120-line functions are not named: %r" % err)

    # --max moves the limit: the 120-line function fails at 119
    rc, err = run(good, "--max", "119")
    expect(rc == 1 and "libfx/src/core/a.c:4:fits:120" in err, "--max 119 fails the 120-line one: %r" % err)

    # no ctags: a clear error, not a pass
    rc, err = run(good, "--ctags", os.path.join(tmp, "no-such-ctags"))
    expect(rc == 2 and "universal-ctags" in err, "a missing ctags is an error (rc %d: %r)" % (rc, err))

print("test_check_function_length: %s" % ("ok" if not failures else "%d failed" % failures))
sys.exit(1 if failures else 0)
