// parallel.cpp — the one parallel loop (parallel.hpp): fixed chunks on oneTBB, progress from the
// calling thread, cancellation before every chunk.
#include "parallel.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <thread>

#include "sdfprune/eval.hpp"  // with_threads

namespace sdfprune {

bool parallel_chunks(uint64_t count, const ParallelOptions& o,
                     const std::function<void(uint64_t)>& fn) {
    std::atomic<bool> cancelled{false};
    std::atomic<uint64_t> done{0};
    const std::thread::id caller = std::this_thread::get_id();
    const bool report = o.progress && *o.progress;
    // Never past hi, so that the reported fractions stay sorted across calls.
    const auto fraction = [&](uint64_t d) {
        return std::min(o.progress_hi, o.progress_lo + (o.progress_hi - o.progress_lo) * double(d) /
                                                           double(count));
    };
    const auto run = [&] {
        tbb::parallel_for(tbb::blocked_range<uint64_t>(0, count, 1),
                          [&](const tbb::blocked_range<uint64_t>& r) {
                              for (uint64_t c = r.begin(); c != r.end(); ++c) {
                                  if (cancelled.load(std::memory_order_relaxed)) return;
                                  if (o.cancel && o.cancel->load(std::memory_order_relaxed)) {
                                      cancelled = true;
                                      return;
                                  }
                                  fn(c);
                                  const uint64_t d = ++done;
                                  if (report && std::this_thread::get_id() == caller)
                                      (*o.progress)(fraction(d));
                              }
                          });
    };
    with_threads(o.threads, run);
    if (cancelled) return false;
    if (report) (*o.progress)(o.progress_hi);
    return true;
}

}  // namespace sdfprune
