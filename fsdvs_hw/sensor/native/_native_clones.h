/* Function multi-versioning for the compiled kernels (_crossings.c, _fused.c).
 *
 * On x86-64 a kernel marked FSDVS_CLONES is also built for x86-64-v3 (AVX2, FMA, SSE4.1) and the
 * loader picks that clone where the CPU has it: floor, ceil and fma become single instructions
 * instead of libm calls, and loops vectorise. Every clone computes the same bits (floor, ceil,
 * fma and nextafter are exact operations; no contraction, no reassociation), so the choice
 * changes speed only (tests/test_fused.py builds the kernels with -DFSDVS_NO_CLONES, the baseline
 * code alone, and compares). Elsewhere the macro is empty.
 */
#ifndef FSDVS_NATIVE_CLONES_H
#define FSDVS_NATIVE_CLONES_H
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__)) && !defined(FSDVS_NO_CLONES)
#define FSDVS_CLONES __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define FSDVS_CLONES
#endif
#endif
