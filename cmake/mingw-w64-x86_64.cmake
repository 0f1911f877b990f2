# Cross-builds for Windows x64 with Debian's MinGW-w64 (gcc-mingw-w64-x86-64):
#   cmake -B build-windows-x64 -DCMAKE_TOOLCHAIN_FILE=cmake/mingw-w64-x86_64.cmake ...
# The "posix" variants take winpthreads, which libfx's worker pool and C11 atomics use;
# it is linked statically (-static), so the DLL needs only Windows' own DLLs.
set(CMAKE_SYSTEM_NAME Windows)
set(CMAKE_SYSTEM_PROCESSOR x86_64)
set(LIBFX_MINGW_PREFIX x86_64-w64-mingw32)
set(CMAKE_C_COMPILER ${LIBFX_MINGW_PREFIX}-gcc-posix)
set(CMAKE_CXX_COMPILER ${LIBFX_MINGW_PREFIX}-g++-posix)
set(CMAKE_RC_COMPILER ${LIBFX_MINGW_PREFIX}-windres)
set(CMAKE_AR ${LIBFX_MINGW_PREFIX}-gcc-ar-posix CACHE FILEPATH "")
set(CMAKE_RANLIB ${LIBFX_MINGW_PREFIX}-gcc-ranlib-posix CACHE FILEPATH "")
set(CMAKE_FIND_ROOT_PATH /usr/${LIBFX_MINGW_PREFIX})
# The static dependencies scripts/deps.sh builds for Windows.
if(LIBFX_DEPS_PREFIX)
  list(APPEND CMAKE_FIND_ROOT_PATH ${LIBFX_DEPS_PREFIX})
endif()
# Programs (cmake, python) come from the build machine; headers and libraries never do.
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE ONLY)
# Tests and tools built here run under Debian's Wine (wine64), headless.
find_program(LIBFX_WINE64 NAMES wine64 PATHS /usr/lib/wine NO_CMAKE_FIND_ROOT_PATH)
if(LIBFX_WINE64)
  set(CMAKE_CROSSCOMPILING_EMULATOR /usr/bin/env WINEDEBUG=-all ${LIBFX_WINE64})
endif()
