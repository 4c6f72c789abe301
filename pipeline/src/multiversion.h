// Run-time dispatch of the decoder's and triangulator's row kernels
// (private). The shipped build targets baseline x86-64 (SSE2); a kernel
// marked SL_MULTIVERSION is also compiled for AVX2 and the loader picks the
// variant the CPU supports (GCC function multiversioning, glibc ifunc). The
// AVX2 variant does the same IEEE operations in the same order (the target
// has no FMA and nothing is reassociated), so the variants agree bit for bit;
// only the vector width differs.
#pragma once

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
#define SL_MULTIVERSION __attribute__((target_clones("avx2", "default")))
#else
#define SL_MULTIVERSION
#endif
