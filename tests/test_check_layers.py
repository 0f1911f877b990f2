#!/usr/bin/python3
"""Proves check_layers.py can fail: small trees with one bad include each must be refused,
naming the file, the line and the include; a tree that only looks down must pass."""
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
CHECKER = os.path.join(HERE, "check_layers.py")

GOOD = {
    "libfx/src/core/mem.h": "#include <stddef.h>\n",
    "libfx/src/core/frame.h": '#include "libfx/fx.h"\n#include "core/mem.h"\n',
    "libfx/src/io/exr_read.c": '#include "core/frame.h"\n#include "io/exr_read.h"\n',
    "libfx/src/io/exr_read.h": '#include "core/frame.h"\n',
    "libfx/src/math/blur.h": '#include "core/frame.h"\n',
    "libfx/src/scene/sidecar.c": '#include "io/exr_read.h"\n#include "math/blur.h"\n',
    "libfx/src/effects/rain.c": '#include "scene/sidecar.h"\n#include "core/mem.h"\n',
    "libfx/cli/main.c": '#include "libfx/fx.h"\n#include "cli.h"\n',
}

BAD = [
    # (file, text, what the message must name)
    ("libfx/src/core/frame.c", '#include "core/frame.h"\n#include "scene/aux_view.h"\n',
     ['libfx/src/core/frame.c:2', '"scene/aux_view.h"', "core may not include scene"]),
    ("libfx/src/math/rain_map.h", '#include "scene/aux_view.h"\n',
     ['libfx/src/math/rain_map.h:1', "math may not include scene"]),
    ("libfx/src/io/exr_write.c", '\n#include "math/blur.h"\n',
     ['libfx/src/io/exr_write.c:2', "io may not include math"]),
    ("libfx/src/math/sat.c", '#include "io/exr_read.h"\n',
     ['libfx/src/math/sat.c:1', "math may not include io"]),
    ("libfx/src/scene/lights.c", '#include "effects/rain.c"\n',
     ["scene may not include effects"]),
    ("libfx/src/core/x.c", '  #  include "scene/y.h"\n', ["core may not include scene"]),
    ("libfx/src/core/z.c", '#include "other/thing.h"\n', ["'other' is not a layer"]),
    ("libfx/src/core/w.c", '#include "local.h"\n', ["by their folder"]),
    ("libfx/src/newfolder/a.c", '#include "core/mem.h"\n', ["folder 'newfolder' has no layer"]),
    ("libfx/cli/util.c", '#include "core/internal.h"\n', ["libfx/cli/util.c:1", "public API only"]),
]


def make_tree(root, extra=None):
    files = dict(GOOD)
    if extra:
        files[extra[0]] = extra[1]
    for rel, text in files.items():
        path = os.path.join(root, rel)
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, "w") as fh:
            fh.write(text)


def run(root):
    p = subprocess.run([sys.executable, CHECKER, root], capture_output=True, text=True)
    return p.returncode, p.stderr


def objects_case():
    """A core object calling a function defined in scene/ fails the symbol check, with no
    include to give it away; the same call the other way passes."""
    with tempfile.TemporaryDirectory() as tmp:
        make_tree(tmp)
        objs = {}
        for rel, text in [("src/core/low.c", "int fx_high(void);\nint fx_low(void) { return fx_high(); }\n"),
                          ("src/scene/high.c", "int fx_high(void) { return 1; }\n"),
                          ("src/scene/user.c", "int fx_low(void);\nint fx_user(void) { return fx_low(); }\n")]:
            c = os.path.join(tmp, "obj", rel)
            os.makedirs(os.path.dirname(c), exist_ok=True)
            with open(c, "w") as fh:
                fh.write(text)
            objs[rel] = c + ".o"
            subprocess.run(["cc", "-c", c, "-o", objs[rel]], check=True)
        p = subprocess.run([sys.executable, CHECKER, tmp, "--objects"] + list(objs.values()),
                           capture_output=True, text=True)
        wanted = ["low.c.o: uses fx_high", "core may not use scene"]
        missing = [w for w in wanted if w not in p.stderr]
        if p.returncode != 1 or missing or "user.c.o" in p.stderr:
            print("objects: exit %d, message lacks %s:\n%s" % (p.returncode, missing, p.stderr))
            return 1
    return 0


def main():
    failures = 0
    with tempfile.TemporaryDirectory() as tmp:
        make_tree(tmp)
        code, err = run(tmp)
        if code != 0:
            print("a tree that only looks down was refused:\n" + err)
            failures += 1
    for rel, text, wanted in BAD:
        with tempfile.TemporaryDirectory() as tmp:
            make_tree(tmp, (rel, text))
            code, err = run(tmp)
            missing = [w for w in wanted if w not in err]
            if code != 1 or missing:
                print("%s: exit %d, message lacks %s:\n%s" % (rel, code, missing, err))
                failures += 1
    failures += objects_case()
    # The real tree passes (the ctest check_layers runs it too; here it guards the test itself).
    code, err = run(os.path.dirname(HERE))
    if code != 0:
        print("the repository's own tree fails:\n" + err)
        failures += 1
    print("test_check_layers: %d case(s) failed" % failures if failures else "test_check_layers: ok")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
