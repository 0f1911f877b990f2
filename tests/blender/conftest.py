"""Fixtures for tests/blender (helpers in addon_testlib.py)."""
import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from addon_testlib import blender_path, cli_path, library_path  # noqa: E402


@pytest.fixture(scope="session")
def blender():
    path = blender_path()
    if not os.path.exists(path):
        pytest.skip("Blender is not installed (set BLENDER)")
    return path


@pytest.fixture(scope="session")
def library():
    path = library_path()
    if not path.is_file():
        pytest.fail("libfx.so is not built at %s (build it, or set LIBFX_LIBRARY)" % path)
    return path


@pytest.fixture(scope="session")
def cli(library):
    path = cli_path()
    if not path.is_file():
        pytest.fail("the libfx CLI is not built at %s (set LIBFX_CLI)" % path)
    return path


