// parallel.hpp — the one parallel loop of the library: a fixed number of chunks run on oneTBB
// with a thread limit, progress reported from the calling thread, cancellation checked before
// every chunk. prune, trace, discretize and mesh all run their work through it.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>

#include "sdfprune/parallel.hpp"  // with_threads: the same limit for a caller's own work

namespace sdfprune {

// What every batch operation's options carry, for parallel_for.
struct ParallelOptions {
    int threads = 0;  // oneTBB workers at most; 0 = no limit (all hardware threads)
    // Called from the calling thread only, with the fraction done mapped onto
    // [progress_lo, progress_hi]; may be null or empty.
    const std::function<void(double)>* progress = nullptr;
    double progress_lo = 0, progress_hi = 1;
    // When set and true, chunks not yet started are skipped and parallel_for throws.
    const std::atomic<bool>* cancel = nullptr;
};

// ParallelOptions from any options struct with threads, progress and cancel members.
template <class Options>
ParallelOptions parallel_options(const Options& o, double lo = 0, double hi = 1) {
    ParallelOptions p;
    p.threads = o.threads;
    p.progress = &o.progress;
    p.progress_lo = lo;
    p.progress_hi = hi;
    if constexpr (requires { o.cancel; }) p.cancel = o.cancel;
    return p;
}

// Runs fn(c) once for every chunk c in [0, count), in parallel, on at most o.threads workers
// that take the chunks in increasing order. The chunks are the caller's (fixed, so results that are
// combined in chunk order do not depend on the thread count). After each chunk run by the calling
// thread, progress gets lo + (hi − lo)·(chunks done)/count; after the last, hi. Returns false,
// having skipped every chunk not started, when o.cancel was seen set (checked before each chunk);
// exceptions from fn propagate.
bool parallel_chunks(uint64_t count, const ParallelOptions& o,
                     const std::function<void(uint64_t)>& fn);

// parallel_chunks with an in-order epilogue (parallel_chunks is this with none): commit(c) runs
// once for every chunk c that ran, in increasing order of c and never two at once, on whichever
// thread finishes the chunk that completes the prefix [0, c] (so results can be placed in chunk
// order while later chunks still run, with no barrier). A chunk not committed yet waits for those
// before it: with chunks handed out in order, about one per thread. Cancellation as parallel_chunks
// (the chunks before the first skipped one are committed); an exception from fn or commit stops the
// handing out and propagates.
bool parallel_chunks_ordered(uint64_t count, const ParallelOptions& o,
                             const std::function<void(uint64_t)>& fn,
                             const std::function<void(uint64_t)>& commit);

// The exception type of loops with no cancel flag (ParallelOptions::cancel null): never thrown.
struct NotCancellable {};

// parallel_chunks, throwing Cancelled() when cancelled.
template <class Cancelled, class F>
void parallel_for(uint64_t count, const ParallelOptions& o, const F& fn) {
    if (!parallel_chunks(count, o, std::function<void(uint64_t)>(std::cref(fn)))) throw Cancelled();
}

// parallel_chunks_ordered, throwing Cancelled() when cancelled.
template <class Cancelled, class F, class G>
void parallel_for_ordered(uint64_t count, const ParallelOptions& o, const F& fn, const G& commit) {
    if (!parallel_chunks_ordered(count, o, std::function<void(uint64_t)>(std::cref(fn)),
                                 std::function<void(uint64_t)>(std::cref(commit))))
        throw Cancelled();
}

// Batch point queries: fn(begin, end) over chunks of 256 of [0, count), no progress or cancel.
template <class F>
void parallel_points(size_t count, int threads, const F& fn) {
    constexpr size_t kChunk = 256;
    ParallelOptions o;
    o.threads = threads;
    parallel_for<NotCancellable>((count + kChunk - 1) / kChunk, o, [&](uint64_t c) {
        fn(size_t(c) * kChunk, std::min(count, size_t(c + 1) * kChunk));
    });
}

}  // namespace sdfprune
