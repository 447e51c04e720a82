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
#include <functional>
#include <thread>
#include <utility>
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
//
// HeapPrefault does the same for `now_bytes + later_bytes`, with the populating of all but the
// first now_bytes on a thread of its own while this thread goes on (a detection reads the
// recording into the first part meanwhile, and uses the rest after): the spans are marked and
// the pieces freed here, at once, so that this thread's next allocations come from them, the
// lowest addresses first (glibc's heap top, as usual), whether or not the helper has populated
// them yet (a page this thread writes first is mapped by its own fault, as without the helper;
// populating skips it). `first`, if set, runs on the helper before the populating. The
// destructor waits for the helper.
class HeapPrefault {
 public:
  HeapPrefault(std::size_t now_bytes, std::size_t later_bytes, std::function<void()> first = {}) {
    std::vector<Span> later = MarkedSpans(now_bytes + later_bytes, false);
    // The first now_bytes (in whole huge pages) of the lowest spans, here.
    std::size_t left = now_bytes;
    std::size_t done = 0;
    for (; done < later.size() && left > 0; ++done) {
      Span& s = later[done];
      const std::size_t take =
          std::min(left + kHugePageBytes - 1, s.hi - s.lo) & ~(kHugePageBytes - 1);
      Populate({s.lo, s.lo + take});
      left -= std::min(left, take);
      s.lo += take;
      if (s.lo < s.hi) break;
    }
    later.erase(later.begin(), later.begin() + static_cast<std::ptrdiff_t>(done));
    if (later.empty() && !first) return;
    helper_ = std::thread([later = std::move(later), first = std::move(first)] {
      if (first) first();
      for (const Span& s : later) Populate(s);
    });
  }
  ~HeapPrefault() {
    if (helper_.joinable()) helper_.join();
  }
  HeapPrefault(const HeapPrefault&) = delete;
  HeapPrefault& operator=(const HeapPrefault&) = delete;

  // PrefaultHeap's work, all on this thread.
  static void Now(std::size_t bytes) { MarkedSpans(bytes, true); }

 private:
  struct Span {
    std::uintptr_t lo = 0, hi = 0;  // whole huge pages marked MADV_HUGEPAGE
  };

  // Allocates `bytes` in pieces on this thread's heap, marks the whole huge pages of their
  // spans MADV_HUGEPAGE (and populates them, if `populate`) and frees the pieces; returns the
  // marked spans (none where it does not apply: see PrefaultHeap).
  static std::vector<Span> MarkedSpans(std::size_t bytes, bool populate) {
    std::vector<Span> spans;
#if defined(__linux__) && defined(__GLIBC__) && defined(MADV_HUGEPAGE)
    if (bytes < 2 * kHugePageBytes) return spans;          // holds no whole huge page for sure
    constexpr std::size_t kPiece = std::size_t{16} << 20;  // below the mmap threshold main.cpp sets
    struct Piece {
      char* p;
      std::size_t n;
    };
    // The list of pieces is allocated first: a small block between two pieces would keep them
    // from merging again when freed.
    std::vector<Piece> pieces;
    pieces.reserve(bytes / kPiece + 1);
    spans.reserve(bytes / kPiece + 1);
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
    std::sort(pieces.begin(), pieces.end(),
              [](const Piece& x, const Piece& y) { return x.p < y.p; });
    for (std::size_t i = 0; i < pieces.size();) {
      std::size_t j = i + 1;
      while (j < pieces.size() && pieces[j].p - (pieces[j - 1].p + pieces[j - 1].n) <= 64) ++j;
      const std::uintptr_t b = reinterpret_cast<std::uintptr_t>(pieces[i].p);
      const std::uintptr_t e = reinterpret_cast<std::uintptr_t>(pieces[j - 1].p) + pieces[j - 1].n;
      const std::uintptr_t lo = (b + kHugePageBytes - 1) & ~(kHugePageBytes - 1);
      const std::uintptr_t hi = e & ~(kHugePageBytes - 1);
      if (hi > lo && madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_HUGEPAGE) == 0) {
        spans.push_back({lo, hi});
        if (populate) Populate(spans.back());
      }
      i = j;
    }
    for (auto it = pieces.rbegin(); it != pieces.rend(); ++it) std::free(it->p);
#else
    (void)bytes;
    (void)populate;
#endif
    return spans;
  }

  // Maps a span's pages now (Linux 5.14's MADV_POPULATE_WRITE; ignored where unknown). It writes
  // nothing: pages mapped already, by any thread, are left as they are.
  static void Populate(const Span& s) {
    if (s.hi <= s.lo) return;
#if defined(__linux__)
#if defined(MADV_POPULATE_WRITE)
    constexpr int kPopulateWrite = MADV_POPULATE_WRITE;
#else
    constexpr int kPopulateWrite = 23;  // Linux's value, for headers older than the kernel
#endif
    madvise(reinterpret_cast<void*>(s.lo), s.hi - s.lo, kPopulateWrite);
#else
    (void)s;
#endif
  }

  std::thread helper_;
};

inline void PrefaultHeap(std::size_t bytes) { HeapPrefault::Now(bytes); }

}  // namespace bouncecal
