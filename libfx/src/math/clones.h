/* Runtime dispatch: FX_CLONES before a function makes GCC build an AVX2 clone beside the
 * baseline x86-64 one and pick one at load time (no -march in the shipped build). Neither
 * has FMA (not in the "avx2" target) and ISO C mode contracts nothing, so both give the same
 * bits as long as the function's arithmetic is lane by lane. FX_CLONES_VECTORIZE also asks
 * for loop vectorisation with the dynamic cost model (for loops gcc -O2 would leave
 * scalar). -DFX_NO_CLONES builds the baseline only (the bits checks compare the two).
 * Windows has no ifunc (the loader-time resolver target_clones needs): baseline only
 * there, the same bits. FX_CLONES_AVX2 says whether AVX2 clones exist. */
#ifndef LIBFX_MATH_CLONES_H
#define LIBFX_MATH_CLONES_H

#ifndef FX_CLONES
#  if defined(__GNUC__) && !defined(__clang__) && (defined(__x86_64__) || defined(__i386__)) && \
      !defined(FX_NO_CLONES) && !defined(_WIN32)
#    define FX_CLONES_AVX2 1
#    define FX_CLONES __attribute__((target_clones("avx2", "default")))
#    define FX_CLONES_VECTORIZE                                                                  \
        __attribute__((optimize("tree-vectorize", "vect-cost-model=dynamic"), target_clones("avx2", "default")))
#  else
#    define FX_CLONES
#    define FX_CLONES_VECTORIZE
#  endif
#endif

#endif
