// Transparent huge pages for the detection's block-sized buffers, and memory mapped before it
// is written (PrefaultHeap) (internal to the library and the program, src/).
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
#include <cstdlib>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#endif
#if defined(__GLIBC__)
#include <malloc.h>
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

// Heap memory for the allocations that follow, in huge pages mapped now. On this project's
// 2-core virtual machine the first write to a 4 KiB page costs 13 us (3.3 ms per MB: the
// hypervisor maps each page on its own) and to a 2 MiB huge page 1.8 ms per MB, while
// MADV_POPULATE_WRITE on a MADV_HUGEPAGE range maps it for 0.08 ms per MB, after which
// writing it is as fast as writing memory written before (measured on 64 MB: first writes in
// 212 ms with 4 KiB pages, 117 ms with huge pages; 5 ms to populate, then 3 ms to write). The
// detection of a 1-minute recording (~40 MB of arrays) took 4 700 page faults, a third of its
// time; with its memory mapped beforehand, 1 900.
//
// `bytes` are allocated in pieces, their span marked for huge pages and populated, and freed:
// malloc then serves the next allocations of this thread from that memory, as long as the
// program keeps freed heap memory (main.cpp's mallopt; glibc's default returns a large free
// top of the heap to the system). Pieces malloc maps on their own (above its mmap threshold:
// with glibc's defaults, any piece) are freed untouched, so in a program with the default
// settings this does nothing. Populating needs Linux 5.14; elsewhere the advice is ignored and
// only the allocation remains. Values are unchanged: only how the memory is mapped, and when.
inline void PrefaultHeap(std::size_t bytes) {
#if defined(__linux__) && defined(__GLIBC__) && defined(MADV_HUGEPAGE)
  if (bytes < 2 * kHugePageBytes) return;                // holds no whole huge page for sure
  constexpr std::size_t kPiece = std::size_t{16} << 20;  // below the mmap threshold main.cpp sets
#if defined(MADV_POPULATE_WRITE)
  constexpr int kPopulateWrite = MADV_POPULATE_WRITE;
#else
  constexpr int kPopulateWrite = 23;  // Linux's value, for headers older than the kernel
#endif
  struct Piece {
    char* p;
    std::size_t n;
  };
  // The list of pieces is allocated first: a small block between two pieces would keep them
  // from merging again when freed.
  std::vector<Piece> pieces;
  pieces.reserve(bytes / kPiece + 1);
  for (std::size_t done = 0; done < bytes;) {
    const std::size_t n = std::min(kPiece, bytes - done);
    const std::size_t mapped_before = mallinfo2().hblkhd;
    char* p = static_cast<char*>(std::malloc(n));
    if (p == nullptr) break;
    if (mallinfo2().hblkhd != mapped_before) {  // mapped on its own: freeing it unmaps it
      std::free(p);
      break;
    }
    pieces.push_back({p, n});
    done += n;
  }
  // Consecutive pieces (the heap's top, as usual) are one span, so that the huge pages
  // straddling their boundaries are included.
  std::sort(pieces.begin(), pieces.end(), [](const Piece& x, const Piece& y) { return x.p < y.p; });
  for (std::size_t i = 0; i < pieces.size();) {
    std::size_t j = i + 1;
    while (j < pieces.size() && pieces[j].p - (pieces[j - 1].p + pieces[j - 1].n) <= 64) ++j;
    const std::uintptr_t b = reinterpret_cast<std::uintptr_t>(pieces[i].p);
    const std::uintptr_t e = reinterpret_cast<std::uintptr_t>(pieces[j - 1].p) + pieces[j - 1].n;
    const std::uintptr_t lo = (b + kHugePageBytes - 1) & ~(kHugePageBytes - 1);
    const std::uintptr_t hi = e & ~(kHugePageBytes - 1);
    if (hi > lo && madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_HUGEPAGE) == 0)
      madvise(reinterpret_cast<void*>(lo), hi - lo, kPopulateWrite);
    i = j;
  }
  for (auto it = pieces.rbegin(); it != pieces.rend(); ++it) std::free(it->p);
#else
  (void)bytes;
#endif
}

}  // namespace bouncecal
