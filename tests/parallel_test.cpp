// parallel_test.cpp — the one parallel loop (src/core/parallel.hpp): every chunk once, progress
// from the calling thread only, sorted and ending at hi, cancellation with the caller's type;
// and its ordered form: every chunk committed once, in order, one at a time, after it ran.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <stdexcept>
#include <thread>
#include <vector>

#include "sdfprune/mesh.hpp"
#include "sdfprune/prune.hpp"
#include "src/core/parallel.hpp"

namespace sdfprune {
namespace {

TEST(ParallelFor, EveryChunkOnceProgressFromTheCaller) {
    for (const int threads : {0, 1, 2, 4}) {
        std::vector<std::atomic<int>> runs(1000);
        std::vector<double> seen;
        const std::thread::id caller = std::this_thread::get_id();
        bool other_thread = false;
        const std::function<void(double)> progress = [&](double f) {
            if (std::this_thread::get_id() != caller) other_thread = true;
            seen.push_back(f);
        };
        ParallelOptions o;
        o.threads = threads;
        o.progress = &progress;
        o.progress_lo = 0.25;
        o.progress_hi = 0.5;
        parallel_for<NotCancellable>(runs.size(), o, [&](uint64_t c) { ++runs[c]; });
        for (const auto& r : runs) ASSERT_EQ(r.load(), 1);
        EXPECT_FALSE(other_thread);
        ASSERT_FALSE(seen.empty());
        EXPECT_TRUE(std::is_sorted(seen.begin(), seen.end()));
        EXPECT_GE(seen.front(), 0.25);
        EXPECT_EQ(seen.back(), 0.5);
    }
}

TEST(ParallelFor, ThreadLimit) {
    std::atomic<int> running{0}, most{0};
    ParallelOptions o;
    o.threads = 2;
    parallel_for<NotCancellable>(64, o, [&](uint64_t) {
        const int now = ++running;
        int m = most.load();
        while (now > m && !most.compare_exchange_weak(m, now)) {
        }
        std::this_thread::sleep_for(std::chrono::microseconds(200));
        --running;
    });
    EXPECT_LE(most.load(), 2);
}

TEST(ParallelFor, CancelSkipsTheRestAndThrowsTheCallersType) {
    std::atomic<bool> cancel{false};
    std::atomic<int> ran{0};
    std::vector<double> seen;
    const std::function<void(double)> progress = [&](double f) { seen.push_back(f); };
    ParallelOptions o;
    o.threads = 1;
    o.cancel = &cancel;
    o.progress = &progress;
    EXPECT_THROW(parallel_for<PruneCancelled>(100, o,
                                              [&](uint64_t c) {
                                                  ++ran;
                                                  if (c == 9) cancel = true;
                                              }),
                 PruneCancelled);
    EXPECT_EQ(ran.load(), 10);  // one thread, chunks in order: cancel seen before chunk 10
    ASSERT_FALSE(seen.empty());
    EXPECT_LT(seen.back(), 1.0);  // no final report when cancelled

    cancel = true;
    ran = 0;
    EXPECT_THROW(parallel_for<MeshCancelled>(100, o, [&](uint64_t) { ++ran; }), MeshCancelled);
    EXPECT_EQ(ran.load(), 0);
    // A loop without a flag is never cancelled.
    o.cancel = nullptr;
    parallel_for<NotCancellable>(100, o, [&](uint64_t) { ++ran; });
    EXPECT_EQ(ran.load(), 100);
}

TEST(ParallelFor, ExceptionsPropagate) {
    ParallelOptions o;
    o.threads = 2;
    EXPECT_THROW(parallel_for<NotCancellable>(50, o,
                                              [](uint64_t c) {
                                                  if (c == 17) throw std::runtime_error("x");
                                              }),
                 std::runtime_error);
}

TEST(ParallelFor, EmptyLoopReportsHi) {
    std::vector<double> seen;
    const std::function<void(double)> progress = [&](double f) { seen.push_back(f); };
    ParallelOptions o;
    o.progress = &progress;
    parallel_for<NotCancellable>(0, o, [](uint64_t) { FAIL(); });
    ASSERT_EQ(seen.size(), 1u);
    EXPECT_EQ(seen[0], 1.0);
}

TEST(ParallelForOrdered, CommitsEveryChunkOnceInOrderAfterItRan) {
    for (const int threads : {0, 1, 2, 4}) {
        constexpr uint64_t kCount = 600;
        std::vector<std::atomic<int>> runs(kCount);
        std::vector<uint64_t> order;
        std::atomic<int> committing{0};
        bool overlapped = false, before_run = false;
        std::vector<double> seen;
        const std::function<void(double)> progress = [&](double f) { seen.push_back(f); };
        ParallelOptions o;
        o.threads = threads;
        o.progress = &progress;
        o.progress_lo = 0.5;
        o.progress_hi = 0.75;
        parallel_for_ordered<NotCancellable>(
            kCount, o,
            [&](uint64_t c) {
                // Uneven chunks, so that they finish out of order.
                if (c % 7 == 0) std::this_thread::sleep_for(std::chrono::microseconds(300));
                ++runs[c];
            },
            [&](uint64_t c) {
                if (++committing != 1) overlapped = true;
                if (runs[c].load() != 1) before_run = true;
                order.push_back(c);
                --committing;
            });
        ASSERT_EQ(order.size(), kCount) << threads << " threads";
        for (uint64_t c = 0; c < kCount; ++c) ASSERT_EQ(order[c], c);
        for (const auto& r : runs) ASSERT_EQ(r.load(), 1);
        EXPECT_FALSE(overlapped);
        EXPECT_FALSE(before_run);
        ASSERT_FALSE(seen.empty());
        EXPECT_TRUE(std::is_sorted(seen.begin(), seen.end()));
        EXPECT_GE(seen.front(), 0.5);
        EXPECT_EQ(seen.back(), 0.75);
    }
}

TEST(ParallelForOrdered, CancelCommitsWhatRanThenThrows) {
    std::atomic<bool> cancel{false};
    std::atomic<int> ran{0};
    std::vector<uint64_t> order;
    ParallelOptions o;
    o.threads = 1;
    o.cancel = &cancel;
    EXPECT_THROW(parallel_for_ordered<PruneCancelled>(
                     100, o,
                     [&](uint64_t c) {
                         ++ran;
                         if (c == 9) cancel = true;
                     },
                     [&](uint64_t c) { order.push_back(c); }),
                 PruneCancelled);
    EXPECT_EQ(ran.load(), 10);
    ASSERT_EQ(order.size(), 10u);
    for (uint64_t c = 0; c < order.size(); ++c) EXPECT_EQ(order[c], c);
}

TEST(ParallelForOrdered, ExceptionsFromEitherPartPropagate) {
    ParallelOptions o;
    o.threads = 2;
    std::atomic<uint64_t> committed{0};
    EXPECT_THROW(parallel_for_ordered<NotCancellable>(
                     50, o,
                     [](uint64_t c) {
                         if (c == 17) throw std::runtime_error("chunk");
                     },
                     [&](uint64_t) { ++committed; }),
                 std::runtime_error);
    EXPECT_LE(committed.load(), 17u);  // never past the chunk that failed
    EXPECT_THROW(parallel_for_ordered<NotCancellable>(
                     50, o, [](uint64_t) {},
                     [](uint64_t c) {
                         if (c == 5) throw std::length_error("commit");
                     }),
                 std::length_error);
}

}  // namespace
}  // namespace sdfprune
