/* Runtime dispatch (as math/blur.c and math/levels.c do): FX_CLONES before a function makes
 * GCC build an AVX2 clone beside the baseline x86-64 one and pick one at load time. Neither
 * has FMA (not in the "avx2" target) and ISO C mode contracts nothing, so both give the same
 * bits as long as the function's arithmetic is lane by lane. */
#ifndef LIBFX_MATH_CLONES_H
#define LIBFX_MATH_CLONES_H

#ifndef FX_CLONES
#  if defined(__GNUC__) && !defined(__clang__) && (defined(__x86_64__) || defined(__i386__)) && \
      !defined(FX_NO_CLONES)
#    define FX_CLONES __attribute__((target_clones("avx2", "default")))
#  else
#    define FX_CLONES
#  endif
#endif

#endif
