"""`python -m libfx ARGS...` runs the `libfx` command-line tool shipped in the wheel."""
import os
import subprocess
import sys

from . import cli_path


def main():
    cli = cli_path()
    if cli is None:
        sys.stderr.write("libfx: this wheel was built without the command-line tool\n")
        return 2
    # the tool links the wheel's library in lib/ (whatever RPATH it was built with)
    lib = os.path.join(os.path.dirname(os.path.abspath(__file__)), "lib")
    var = "PATH" if sys.platform.startswith("win") else \
        "DYLD_LIBRARY_PATH" if sys.platform == "darwin" else "LD_LIBRARY_PATH"
    env = dict(os.environ)
    env[var] = lib + (os.pathsep + env[var] if env.get(var) else "")
    return subprocess.call([cli] + sys.argv[1:], env=env)


if __name__ == "__main__":
    sys.exit(main())
