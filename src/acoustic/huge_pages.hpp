// Transparent huge pages for the detection's block-sized buffers (internal to src/acoustic).
//
// A block of a long recording is 2 minutes of audio: each of its per-sample arrays (the samples,
// the whitened signal, the template correlation and energy) is ~23 MB at 48 kHz, first touched
// in 4 KiB pages: 28 000 page faults per run of one thread, 9-11 % of the detection of a
// 10-minute file (perf, this machine: a virtual machine, where a fault costs ~5 us), more with
// two threads. With the kernel's transparent huge pages in "madvise" mode (the common default)
// a range marked MADV_HUGEPAGE before its first touch faults in 2 MiB pages instead. Values
// are unchanged: only how the kernel maps the memory.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace bouncecal {

// Buffers smaller than this are left alone (a huge page is 2 MiB: a range needs at least one
// whole aligned one).
constexpr std::size_t kHugePageBytes = std::size_t{2} << 20;

// Marks the whole 2 MiB pages inside [p, p + bytes) for transparent huge pages (Linux; a no-op
// elsewhere, for small ranges, or when the kernel refuses: it is only advice).
inline void AdviseHugePages(const void* p, std::size_t bytes) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  if (bytes < 2 * kHugePageBytes) return;
  const std::uintptr_t b = reinterpret_cast<std::uintptr_t>(p);
  const std::uintptr_t lo = (b + kHugePageBytes - 1) & ~(kHugePageBytes - 1);
  const std::uintptr_t hi = (b + bytes) & ~(kHugePageBytes - 1);
  if (hi > lo) madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_HUGEPAGE);
#else
  (void)p;
  (void)bytes;
#endif
}

// Makes room for n elements in v as growing it would (at least doubling the capacity, so that
// appending chunk by chunk stays linear), the new storage marked for huge pages before anything
// is written to it.
template <typename T>
void ReserveHugePages(std::vector<T>* v, std::size_t n) {
  if (v->capacity() >= n) return;
  const std::size_t cap = std::max(n, 2 * v->capacity());
  std::vector<T> bigger;
  bigger.reserve(cap);
  AdviseHugePages(bigger.data(), cap * sizeof(T));
  bigger.insert(bigger.end(), v->begin(), v->end());
  v->swap(bigger);
}

}  // namespace bouncecal
