// parallel.cpp — the one parallel loop (parallel.hpp): fixed chunks handed out in order to oneTBB
// workers, progress from the calling thread, cancellation before every chunk, and in the ordered
// form commits in chunk order.
#include "parallel.hpp"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace sdfprune {

void with_threads(int threads, const std::function<void()>& fn) {
    if (threads <= 0) {
        fn();
        return;
    }
    tbb::task_arena arena(threads);
    arena.execute(fn);
}

namespace {
// The progress reported after `done` of `count` chunks: never past hi, so that the reported
// fractions stay sorted across calls.
double progress_at(const ParallelOptions& o, uint64_t done, uint64_t count) {
    return std::min(o.progress_hi,
                    o.progress_lo + (o.progress_hi - o.progress_lo) * double(done) / double(count));
}
}  // namespace

bool parallel_chunks_ordered(uint64_t count, const ParallelOptions& o,
                             const std::function<void(uint64_t)>& fn,
                             const std::function<void(uint64_t)>& commit) {
    std::atomic<uint64_t> next{0};  // the next chunk to hand out
    std::atomic<uint64_t> done{0};
    std::atomic<bool> stop{false};  // cancelled, or failed
    std::atomic<bool> cancelled{false};
    std::mutex m;  // the commits' state and the first error
    std::vector<uint8_t> finished(commit ? count : 0, 0);
    uint64_t committed = 0;
    std::exception_ptr error;
    const std::thread::id caller = std::this_thread::get_id();
    const bool report = o.progress && *o.progress;
    // Each worker takes the next chunk until none is left; finishing one, it commits the
    // finished prefix.
    const auto work = [&] {
        while (!stop.load(std::memory_order_relaxed)) {
            if (o.cancel && o.cancel->load(std::memory_order_relaxed)) {
                cancelled = true;
                stop = true;
                return;
            }
            const uint64_t c = next.fetch_add(1, std::memory_order_relaxed);
            if (c >= count) return;
            try {
                fn(c);
                if (commit) {
                    std::lock_guard lock(m);
                    finished[c] = 1;
                    for (; committed < count && finished[committed] != 0 && !error; ++committed)
                        commit(committed);
                }
                const uint64_t now_done = ++done;
                // (Outside the lock: a slow callback holds no other thread's commits back.)
                if (report && std::this_thread::get_id() == caller)
                    (*o.progress)(progress_at(o, now_done, count));
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

bool parallel_chunks(uint64_t count, const ParallelOptions& o,
                     const std::function<void(uint64_t)>& fn) {
    return parallel_chunks_ordered(count, o, fn, nullptr);
}

}  // namespace sdfprune
