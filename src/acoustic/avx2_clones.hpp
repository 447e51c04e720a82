// BOUNCECAL_AVX2_CLONES: a hot loop compiled twice by function multiversioning (GCC/Clang
// target_clones), for AVX2 and for the baseline x86-64, chosen once at load time by the CPU.
// Without FMA (not enabled by the "avx2" target) the AVX2 copy does the same multiplications
// and additions lane by lane in the same order, only more lanes per instruction, so both give
// the same values to the bit.
//
// Not under the sanitizers: the clones are chosen by an ifunc resolver that runs while the
// program is being relocated, before ThreadSanitizer's runtime is initialised, and the
// instrumented resolver crashes every ThreadSanitizer binary at start-up (measured:
// calibrate_test, SIGSEGV before main). The baseline copy alone computes the same values.
#pragma once

#if defined(__SANITIZE_THREAD__) || defined(__SANITIZE_ADDRESS__)
#define BOUNCECAL_SANITIZED_BUILD 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer) || __has_feature(address_sanitizer)
#define BOUNCECAL_SANITIZED_BUILD 1
#endif
#endif

#if defined(__x86_64__) && defined(__GNUC__) && !defined(BOUNCECAL_SANITIZED_BUILD)
#define BOUNCECAL_AVX2_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define BOUNCECAL_AVX2_CLONES
#endif

#include <cstddef>

namespace bouncecal {

// Lanes of the GCC/Clang vector extension (lane-wise IEEE operations: one AVX2 register, or two
// SSE2 ones in the baseline copy), loaded from unaligned memory with memcpy.
typedef float Float8 __attribute__((vector_size(32)));
typedef double Double4 __attribute__((vector_size(32)));

// The smallest and the largest of x[0, n) (n > 0, no NaN), eight lanes at a time (audio.cpp;
// std::minmax_element's loop is not vectorised). min and max do not depend on the order they
// are taken in.
void MinMax(const float* x, std::size_t n, float* lo, float* hi);

}  // namespace bouncecal
