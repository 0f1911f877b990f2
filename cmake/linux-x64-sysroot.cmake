# The linux-x64 release build: this machine's gcc (the development build's compiler, so the
# same code and speed) against the Debian 11 root as sysroot (glibc 2.31 headers and
# libraries), so the library needs nothing newer than glibc 2.31.
#   cmake -B build-linux-x64 -DCMAKE_TOOLCHAIN_FILE=cmake/linux-x64-sysroot.cmake \
#         -DLIBFX_SYSROOT=/var/cache/libfx-roots/bullseye ...
# (scripts/platforms.sh; the root comes from scripts/blender_roots.sh bullseye.)
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR x86_64)
if(NOT LIBFX_SYSROOT)
  message(FATAL_ERROR "linux-x64-sysroot.cmake: set LIBFX_SYSROOT to the Debian 11 root")
endif()
set(CMAKE_SYSROOT ${LIBFX_SYSROOT})
list(APPEND CMAKE_TRY_COMPILE_PLATFORM_VARIABLES LIBFX_SYSROOT)   # CMake's probes read this file too
set(CMAKE_C_COMPILER gcc)
set(CMAKE_CXX_COMPILER g++)
# gcc finds its start files and libc through paths relative to its own prefix, which the
# sysroot does not rewrite: point those at the root's multiarch folders.
set(_multiarch "-B${LIBFX_SYSROOT}/usr/lib/x86_64-linux-gnu -L${LIBFX_SYSROOT}/usr/lib/x86_64-linux-gnu -L${LIBFX_SYSROOT}/lib/x86_64-linux-gnu")
set(CMAKE_EXE_LINKER_FLAGS_INIT "${_multiarch}")
set(CMAKE_SHARED_LINKER_FLAGS_INIT "${_multiarch}")
set(CMAKE_MODULE_LINKER_FLAGS_INIT "${_multiarch}")
set(CMAKE_FIND_ROOT_PATH ${LIBFX_SYSROOT})
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE ONLY)
# The tests built here run on this machine (glibc is backward compatible).
