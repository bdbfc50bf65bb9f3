// PRIOIK_VECTOR_CLONES marks a hot function of the core (a solver phase, the nested QR):
// in a portable x86-64 GCC build on Linux it is compiled twice, for AVX2 and for baseline
// x86-64, and the clone is picked once at load by the CPU (GCC function multiversioning:
// an ifunc). `flatten` inlines every call it makes into each clone, so that the helpers
// run at the clone's vector width too. Both clones do the same IEEE operations in the
// same order: no contraction (-ffp-contract=off; the avx2 target has no FMA either), no
// reassociation (GCC vectorises no floating-point reduction without it; householder.hpp's
// dot writes its eight partial sums out), so their answers are the same bits; only the
// vector width of element-wise loops and of dot's independent partial sums differs.
// Elsewhere (PRIOIK_VECTOR_CLONES=OFF, PRIOIK_NATIVE, another compiler or system, the
// sanitized build) it is empty.
#pragma once

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__) && \
    PRIOIK_VECTOR_CLONES_BUILD && !PRIOIK_NATIVE_BUILD && !PRIOIK_SANITIZE_BUILD
#define PRIOIK_HAS_VECTOR_CLONES 1
#define PRIOIK_VECTOR_CLONES __attribute__((target_clones("avx2", "default"), flatten))
#else
#define PRIOIK_HAS_VECTOR_CLONES 0
#define PRIOIK_VECTOR_CLONES
#endif
