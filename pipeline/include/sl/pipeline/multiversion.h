// Run-time dispatch of the row kernels of the decoder, the triangulator and
// the simulator's noise (an implementation detail of sl_pipeline and
// sl_driver_sim, not an API). The shipped build targets baseline x86-64
// (SSE2); a kernel marked SL_MULTIVERSION is also compiled for AVX2 and for x86-64-v4
// (AVX-512) and the loader picks the best variant the CPU supports (GCC
// function multiversioning, glibc ifunc). The variants do the same IEEE
// operations in the same order: the kernels' files are compiled with
// -ffp-contract=off, so the FMA that x86-64-v4 offers is never fused into a
// multiply-add, and nothing is reassociated. They agree bit for bit; only the
// vector width differs (16 floats with AVX-512; bench_codecs compares them,
// figures in docs/measurements.md).
//
// ThreadSanitizer builds (SL_SANITIZE=thread) compile the baseline variant
// only: glibc runs ifunc resolvers while relocating, before the TSan runtime
// is initialised, and an instrumented resolver crashes the process before
// main. The variants share one source and agree bit for bit (above), and what
// TSan checks, the threads around the kernels, does not depend on the vector
// width.
#pragma once

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__) && \
    !defined(__SANITIZE_THREAD__)
#define SL_MULTIVERSION __attribute__((target_clones("arch=x86-64-v4", "avx2", "default")))
#define SL_MULTIVERSION_ENABLED 1
#else
#define SL_MULTIVERSION_ENABLED 0
#define SL_MULTIVERSION
#endif
