// parallel.cpp — the one parallel loop (parallel.hpp): fixed chunks on oneTBB, progress from the
// calling thread, cancellation before every chunk.
#include "parallel.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <tbb/task_arena.h>

#include <algorithm>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

#include "sdfprune/eval.hpp"  // with_threads

namespace sdfprune {

namespace {
// The progress reported after `done` of `count` chunks: never past hi, so that the reported
// fractions stay sorted across calls.
double progress_at(const ParallelOptions& o, uint64_t done, uint64_t count) {
    return std::min(o.progress_hi,
                    o.progress_lo + (o.progress_hi - o.progress_lo) * double(done) / double(count));
}
}  // namespace

bool parallel_chunks(uint64_t count, const ParallelOptions& o,
                     const std::function<void(uint64_t)>& fn) {
    std::atomic<bool> cancelled{false};
    std::atomic<uint64_t> done{0};
    const std::thread::id caller = std::this_thread::get_id();
    const bool report = o.progress && *o.progress;
    const auto fraction = [&](uint64_t d) { return progress_at(o, d, count); };
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

bool parallel_chunks_ordered(uint64_t count, const ParallelOptions& o,
                             const std::function<void(uint64_t)>& fn,
                             const std::function<void(uint64_t)>& commit) {
    std::atomic<uint64_t> next{0};  // the next chunk to hand out
    std::atomic<bool> stop{false};  // cancelled, or failed
    bool cancelled = false;         // (under `m`, as the rest)
    std::mutex m;
    std::vector<uint8_t> finished(count, 0);
    uint64_t committed = 0, done = 0;
    std::exception_ptr error;
    const std::thread::id caller = std::this_thread::get_id();
    const bool report = o.progress && *o.progress;
    const auto fraction = [&](uint64_t d) { return progress_at(o, d, count); };
    // Each worker takes the next chunk until none is left; finishing one, it commits the
    // finished prefix.
    const auto work = [&] {
        while (!stop.load(std::memory_order_relaxed)) {
            if (o.cancel && o.cancel->load(std::memory_order_relaxed)) {
                std::lock_guard lock(m);
                cancelled = true;
                stop = true;
                return;
            }
            const uint64_t c = next.fetch_add(1, std::memory_order_relaxed);
            if (c >= count) return;
            try {
                fn(c);
                uint64_t now_done;
                {
                    std::lock_guard lock(m);
                    finished[c] = 1;
                    now_done = ++done;
                    for (; committed < count && finished[committed] != 0 && !error; ++committed)
                        commit(committed);
                }
                // (Outside the lock: a slow callback holds no other thread's commits back.)
                if (report && std::this_thread::get_id() == caller)
                    (*o.progress)(fraction(now_done));
            } catch (...) {
                std::lock_guard lock(m);
                if (!error) error = std::current_exception();
                stop = true;
                return;
            }
        }
    };
    const auto run = [&] {
        const int workers =
            int(std::min<uint64_t>(count, uint64_t(tbb::this_task_arena::max_concurrency())));
        tbb::parallel_for(0, workers, [&](int) { work(); });
    };
    with_threads(o.threads, run);
    if (error) std::rethrow_exception(error);
    if (cancelled) return false;
    if (report) (*o.progress)(o.progress_hi);
    return true;
}

}  // namespace sdfprune
