#!/usr/bin/env bash
# The Windows CLI (libfx.exe beside libfx.dll) run under Debian's Wine, headless, with
# the arguments as given: a drop-in LIBFX_CLI for the CLI tests (Wine maps Unix absolute
# paths onto drive Z:). LIBFX_WINDOWS_CLI names another libfx.exe than the build tree's.
#   LIBFX_CLI=tests/platform/wine_cli.sh /usr/bin/python3 -m pytest -q tests/python/test_cli.py
here=$(cd "$(dirname "$0")/../.." && pwd)
exe=${LIBFX_WINDOWS_CLI:-$here/build-windows-x64/libfx/libfx.exe}
exec env WINEDEBUG=-all /usr/lib/wine/wine64 "$exe" "$@"
