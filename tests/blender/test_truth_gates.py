"""The truth comparisons as a regression gate (issue 28): each tests/bench/truth_*.py runs
here at 128x72 with 16 samples (its own measuring code; truth_gate_lib.py says what is run
and read, and the margins), and libfx's errors against the Cycles truth must stay within
the numbers measured for this Blender's major version (truth_gate_numbers.json, written by
measure_truth_gates.py) plus the margins.

Numbers are per Blender major version because 3.x, 4.x and 5.x render the scenes
differently (other Cycles, other defaults). A Blender whose major version has no numbers
skips the gate and says which command measures them.

An error that falls is not a failure (measure again when a change improves it).
truth_eevee.py is Eevee's render of the truth, the peer of vsm_shadows, not a libfx
output: nothing of libfx to gate.

Renders go to one directory per test session (pytest's tmp), made once and shared by the
gates; nothing is kept between sessions. LIBFX_TRUTH_GATE_DIR=DIR keeps them in DIR and
reuses them in later sessions (for trying a change of the library against the gates
quickly: delete DIR to render again). Whole gate: about 2-3 minutes on 2 cores.
"""
import os
import pathlib

import pytest

import addon_testlib as T
import truth_gate_lib as G


@pytest.fixture(scope="session")
def truth_env(blender, library, cli, tmp_path_factory):
    major, version = G.blender_major(str(blender))
    numbers = G.load_numbers().get(major)
    if not numbers:
        pytest.skip("no truth-gate numbers for %s: measure them with tests/blender/measure_truth_gates.py" % version)
    T.need_oiio()
    keep = os.environ.get("LIBFX_TRUTH_GATE_DIR")
    root = pathlib.Path(keep) if keep else tmp_path_factory.mktemp("truth_gates")
    root.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, LIBFX_LIBRARY=str(library), LIBFX_CLI=str(cli), BLENDER=str(blender))
    return root, env, numbers, version


@pytest.mark.parametrize("name", list(G.GATES))
def test_gate(truth_env, name):
    root, env, numbers, version = truth_env
    measured = numbers["gates"].get(name)
    assert measured, "truth_gate_numbers.json has no '%s' numbers for %s" % (name, version)
    report, out = G.run(root, name, env)
    fails = G.check(measured, G.extract(name, report))
    assert not fails, (version, fails, out[-3000:])
