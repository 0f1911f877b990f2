#!/usr/bin/python3
"""Fails when a function of libfx is longer than 120 lines.

A function's length is counted as universal-ctags reports it: from the line of its
signature (ctags' `line`) to the line of its closing brace (ctags' `end`), both included,
so `end - line + 1`. ctags itself does the parsing: every C and C++ file under libfx/src
and libfx/cli (sources and headers, with ctags' own language map: .h is C++ to it, which
gives the same lines as C for this tree), function definitions only (kind f; prototypes
and macros are not functions).

A function over the limit is split into helpers with one idea each (issue 28). The limit
is --max (default 120).

Usage: check_function_length.py [REPO_ROOT] [--max N] [--ctags PROGRAM]
(default root: the repository holding this script)
Exit status 0 when every function is within the limit; 1 otherwise, each offender on
stderr as FILE:LINE:NAME:LENGTH (FILE relative to the root); 2 when ctags is missing,
is not universal-ctags, or gave a function without its end line.
"""
import json
import os
import subprocess
import sys

DIRS = ("libfx/src", "libfx/cli")
DEFAULT_MAX = 120


def fail(message):
    print("check_function_length: " + message, file=sys.stderr)
    sys.exit(2)


def ctags_functions(root, ctags):
    """(file, line, name, length) of every function definition under DIRS."""
    try:
        version = subprocess.run([ctags, "--version"], capture_output=True, text=True).stdout
    except OSError:
        fail("%s not found: install universal-ctags (scripts/setup.sh does)" % ctags)
    if "Universal Ctags" not in version:
        fail("%s is not universal-ctags (its --version: %r)" % (ctags, version.splitlines()[:1]))
    dirs = [d for d in DIRS if os.path.isdir(os.path.join(root, d))]
    if not dirs:
        fail("no %s under %s" % (" or ".join(DIRS), root))
    cmd = [ctags, "-R", "--languages=C,C++", "--kinds-C=f", "--kinds-C++=f", "--fields=+ne",
           "--output-format=json", "-o", "-"] + dirs
    p = subprocess.run(cmd, cwd=root, capture_output=True, text=True)
    if p.returncode != 0:
        fail("%s failed (%d): %s" % (" ".join(cmd), p.returncode, p.stderr.strip()))
    out = []
    for text in p.stdout.splitlines():
        tag = json.loads(text)
        if tag.get("_type") != "tag" or tag.get("kind") != "function":
            continue
        if "end" not in tag:
            fail("ctags gave no end line for %s:%s:%s" % (tag["path"], tag["line"], tag["name"]))
        out.append((tag["path"], tag["line"], tag["name"], tag["end"] - tag["line"] + 1))
    return sorted(out)


def main(argv):
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    limit = DEFAULT_MAX
    ctags = "ctags"
    args = list(argv)
    while args:
        a = args.pop(0)
        if a == "--max" and args:
            limit = int(args.pop(0))
        elif a == "--ctags" and args:
            ctags = args.pop(0)
        elif a.startswith("-"):
            fail("unknown option %s (usage: check_function_length.py [ROOT] [--max N] [--ctags PROGRAM])" % a)
        else:
            root = a
    functions = ctags_functions(root, ctags)
    long = [f for f in functions if f[3] > limit]
    for path, line, name, length in long:
        print("%s:%d:%s:%d" % (path, line, name, length), file=sys.stderr)
    if long:
        print("check_function_length: %d function%s over %d lines (split into helpers)"
              % (len(long), "s" if len(long) > 1 else "", limit), file=sys.stderr)
        return 1
    print("check_function_length: %d functions, the longest %d lines (limit %d)"
          % (len(functions), max((f[3] for f in functions), default=0), limit))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
