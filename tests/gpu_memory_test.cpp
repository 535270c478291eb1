// gpu_memory_test.cpp — the Vulkan backend's device memory: the host's share of a call
// accounted, buffers reused through the idle cache, small ones sharing slabs and large ones
// blocks, the reserve that serves the first call, the cache's budget and the pruning's peak;
// the grids the same whatever the memory does.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <initializer_list>
#include <memory>
#include <optional>
#include <string>
#include <utility>

#include "gpu_check.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/gpu.hpp"
#include "sdfprune/prune.hpp"

namespace sdfprune::test {
namespace {

// The host's share of a pruning call is accounted: every level's submission among the host's
// (which also counts uploads and readbacks), buffers made, and their times within wall_ms.
TEST(Gpu, HostShareIsAccounted) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const Scene sc = builtin_scene("demo");
    PruneOptions o;
    o.resolution = 32;
    const gpu::Grid g = gpu::prune(*dev, sc, o);
    const gpu::DevicePruneStats& st = g.stats();
    EXPECT_GE(st.host_submissions, uint64_t(st.submissions));
    // (Buffers made or taken from the idle cache, which earlier tests may have filled.)
    EXPECT_GT(st.host_buffers + st.host_buffers_reused, 0u);
    EXPECT_GT(st.host_submit_ms, 0.0);
    EXPECT_LE(st.host_buffer_ms + st.host_submit_ms, st.wall_ms);
    // A second call counts its own share, not the first's too.
    const gpu::Grid again = gpu::prune(*dev, sc, o);
    EXPECT_EQ(again.stats().host_submissions, st.host_submissions);
    EXPECT_EQ(again.stats().host_buffers + again.stats().host_buffers_reused,
              st.host_buffers + st.host_buffers_reused);
}

// Buffers are recycled across levels and calls (Context's idle cache): a pruning that repeats
// another's on the same device allocates nothing new once the other's grid is gone, and no
// more than its own grid's buffers (6) while that grid is alive; the grids are the same.
TEST(Gpu, RepeatedPruneReusesBuffers) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const Scene sc = builtin_scene("demo");
    PruneOptions o;
    o.resolution = 32;
    std::optional<gpu::Grid> first(gpu::prune(*dev, sc, o));
    const uint64_t requests = first->stats().host_buffers + first->stats().host_buffers_reused;
    EXPECT_GT(first->stats().host_buffers_reused, 0u);  // the levels' temporaries at least
    {
        const gpu::Grid alive = gpu::prune(*dev, sc, o);  // the first grid still held
        EXPECT_LE(alive.stats().host_buffers, 6u);
        EXPECT_EQ(alive.stats().host_buffers + alive.stats().host_buffers_reused, requests);
        expect_same_device_cells(*first, alive, "with the first grid alive");
    }
    const uint64_t in_use = dev->memory_in_use();
    const gpu::Grid second = gpu::prune(*dev, sc, o);
    EXPECT_EQ(second.stats().host_buffers, 0u);
    EXPECT_EQ(second.stats().host_buffers_reused, requests);
    EXPECT_EQ(second.stats().prune_peak_bytes, first->stats().prune_peak_bytes);
    expect_same_stats(first->stats(), second.stats(), "second prune");
    expect_same_device_cells(*first, second, "second prune");
    // The memory in use counts the new grid, not the idle buffers.
    EXPECT_GT(dev->memory_in_use(), in_use);
    EXPECT_GT(dev->memory_cached(), 0u);
    first.reset();
}

// Small buffers share slabs of device memory (Context::Slab): a first pruning, which makes
// dozens of buffers, allocates device memory a few times only, and the grid is the one made
// with every buffer allocating its own (SDFPRUNE_VULKAN_SLABS=0). With no idle cache, a slab
// emptied by one call is taken again by the next, which allocates no more than the first.
TEST(Gpu, SmallBuffersShareSlabs) {
    if (!gpu::built_with_vulkan()) GTEST_SKIP() << "built without the Vulkan backend";
    const Scene sc = builtin_scene("demo");
    PruneOptions o;
    o.resolution = 32;
    // (No reserve, whose slabs would spare the call its own.)
    const std::unique_ptr<gpu::Device> own =
        device_with_envs({{"SDFPRUNE_VULKAN_SLABS", "0"}, {"SDFPRUNE_VULKAN_RESERVE_BYTES", "0"}});
    const std::unique_ptr<gpu::Device> slabs =
        device_with_envs({{"SDFPRUNE_VULKAN_SLABS", "1"}, {"SDFPRUNE_VULKAN_RESERVE_BYTES", "0"}});
    ASSERT_TRUE(own && slabs);
    const gpu::Grid a = gpu::prune(*own, sc, o);
    const gpu::Grid b = gpu::prune(*slabs, sc, o);
    EXPECT_EQ(a.stats().host_allocations, a.stats().host_buffers);
    EXPECT_EQ(b.stats().host_buffers, a.stats().host_buffers);
    EXPECT_GE(b.stats().host_buffers, 10u);
    EXPECT_LE(b.stats().host_allocations * 3, b.stats().host_buffers);
    EXPECT_GT(b.stats().host_allocations, 0u);
    expect_same_stats(a.stats(), b.stats(), "slabs");
    expect_same_device_cells(a, b, "slabs");
    EXPECT_EQ(own->memory_in_use(), slabs->memory_in_use());

    const std::unique_ptr<gpu::Device> uncached =
        device_with_env("SDFPRUNE_VULKAN_CACHE_BYTES", "0");
    ASSERT_TRUE(uncached);
    const gpu::Grid first = gpu::prune(*uncached, sc, o);
    const gpu::Grid second = gpu::prune(*uncached, sc, o);
    EXPECT_EQ(second.stats().host_buffers_reused, 0u);
    EXPECT_LE(second.stats().host_allocations, first.stats().host_allocations);
    expect_same_device_cells(first, second, "a slab taken again");
}

// Buffers over 1 MiB are bound into blocks of device memory, and a buffer given back leaves
// its room to later ones that fit (Context::Block): a first pruning peaks the same and makes
// the same grid as through the idle cache alone (SDFPRUNE_VULKAN_BLOCKS=0), and on lavapipe
// allocates device memory fewer times and fewer bytes and reuses more; a repeated call once the
// first grid is gone allocates nothing; empty blocks are idle memory, freed with the cache.
TEST(Gpu, LargeBuffersShareBlocks) {
    if (!gpu::built_with_vulkan()) GTEST_SKIP() << "built without the Vulkan backend";
    const Scene sc = builtin_scene("demo");
    PruneOptions o;
    o.resolution = 128;
    // (No reserve: a first call then allocates what it holds.)
    const std::unique_ptr<gpu::Device> blocks =
        device_with_envs({{"SDFPRUNE_VULKAN_BLOCKS", "1"}, {"SDFPRUNE_VULKAN_RESERVE_BYTES", "0"}});
    const std::unique_ptr<gpu::Device> cache = device_with_env("SDFPRUNE_VULKAN_BLOCKS", "0");
    ASSERT_TRUE(blocks && cache);
    std::optional<gpu::Grid> a(gpu::prune(*blocks, sc, o));
    const gpu::Grid b = gpu::prune(*cache, sc, o);
    const gpu::DevicePruneStats &sa = a->stats(), &sb = b.stats();
    if (exact_device(*blocks)) {  // (lavapipe: this plan's buffers; a GPU plans others)
        EXPECT_LT(sa.host_allocations, sb.host_allocations);
        EXPECT_LT(sa.host_allocated_bytes, sb.host_allocated_bytes);
        EXPECT_GT(sa.host_buffers_reused, sb.host_buffers_reused);
    }
    // A fresh device's first call allocated all it held at once, at least.
    EXPECT_GE(sa.host_allocated_bytes, sa.prune_peak_bytes);
    EXPECT_GE(sb.host_allocated_bytes, sb.prune_peak_bytes);
    EXPECT_EQ(sa.host_buffers + sa.host_buffers_reused, sb.host_buffers + sb.host_buffers_reused);
    EXPECT_EQ(sa.prune_peak_bytes, sb.prune_peak_bytes);
    expect_same_stats(sb, sa, "blocks");
    expect_same_device_cells(*a, b, "blocks");

    const uint64_t requests = sa.host_buffers + sa.host_buffers_reused;
    a.reset();
    const gpu::Grid again = gpu::prune(*blocks, sc, o);
    EXPECT_EQ(again.stats().host_buffers, 0u);
    EXPECT_EQ(again.stats().host_allocations, 0u);
    EXPECT_EQ(again.stats().host_allocated_bytes, 0u);
    EXPECT_EQ(again.stats().host_buffers_reused, requests);
    EXPECT_EQ(again.stats().prune_peak_bytes, sb.prune_peak_bytes);
    expect_same_device_cells(again, b, "blocks, again");
    EXPECT_GT(blocks->memory_cached(), 0u);
    blocks->release_cached_memory();
    EXPECT_EQ(blocks->memory_cached(), 0u);
}

// A device's reserve (SDFPRUNE_VULKAN_RESERVE_BYTES), allocated while the device is made, is
// idle memory until the first call, whose large buffers take their room in it: that call
// allocates less than the same call on a device without one, and only its small buffers'
// slabs where the reserve holds its peak; the grid is the same. Without blocks, without an
// idle cache or below kReserveMin there is none; by default GPUs have one, CPU devices none.
TEST(Gpu, ReserveServesTheFirstCall) {
    if (!gpu::built_with_vulkan()) GTEST_SKIP() << "built without the Vulkan backend";
    const Scene sc = builtin_scene("demo");
    PruneOptions o;
    o.resolution = 128;
    const std::unique_ptr<gpu::Device> none = device_with_env("SDFPRUNE_VULKAN_RESERVE_BYTES", "0");
    ASSERT_TRUE(none);
    EXPECT_EQ(none->memory_reserved(), 0u);
    const gpu::Grid b = gpu::prune(*none, sc, o);
    const gpu::DevicePruneStats& sb = b.stats();
    // Room for the call's buffers wherever first fit places them: 4 times its peak.
    const uint64_t reserve = (sb.prune_peak_bytes * 4 + (1 << 20)) & ~uint64_t(15);
    const std::unique_ptr<gpu::Device> reserved =
        device_with_env("SDFPRUNE_VULKAN_RESERVE_BYTES", std::to_string(reserve).c_str());
    ASSERT_TRUE(reserved);
    EXPECT_EQ(reserved->memory_reserved(), reserve);
    EXPECT_GE(reserved->reserve_ms(), 0.0);
    EXPECT_GE(reserved->memory_cached(), reserve);  // an empty block until a call takes it
    const gpu::Grid a = gpu::prune(*reserved, sc, o);
    const gpu::DevicePruneStats& sa = a.stats();
    EXPECT_LT(sa.host_allocated_bytes, sb.host_allocated_bytes);
    EXPECT_GE(sb.host_allocated_bytes, sb.prune_peak_bytes);
    // Only slabs (16 MiB of device memory, 2 MiB host-visible) were allocated in the call.
    EXPECT_LE(sa.host_allocated_bytes, uint64_t(18) << 20);
    EXPECT_EQ(sa.prune_peak_bytes, sb.prune_peak_bytes);
    expect_same_stats(sb, sa, "reserve");
    expect_same_device_cells(a, b, "reserve");

    for (const auto& [name, value] : {std::pair{"SDFPRUNE_VULKAN_BLOCKS", "0"},
                                      std::pair{"SDFPRUNE_VULKAN_CACHE_BYTES", "0"}}) {
        const std::unique_ptr<gpu::Device> without =
            device_with_envs({{"SDFPRUNE_VULKAN_RESERVE_BYTES", "67108864"}, {name, value}});
        ASSERT_TRUE(without);
        EXPECT_EQ(without->memory_reserved(), 0u) << name;
    }
    // A call that comes before the reserve's thread is done does not wait for it: it
    // allocates its own (the device's end then stops the thread's delay).
    const std::unique_ptr<gpu::Device> late =
        device_with_envs({{"SDFPRUNE_VULKAN_RESERVE_BYTES", std::to_string(reserve).c_str()},
                          {"SDFPRUNE_VULKAN_RESERVE_DELAY_MS", "60000"}});
    ASSERT_TRUE(late);
    const auto start = std::chrono::steady_clock::now();
    std::optional<gpu::Grid> early(gpu::prune(*late, sc, o));
    EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(50));
    EXPECT_GE(early->stats().host_allocated_bytes, sb.host_allocated_bytes);
    expect_same_device_cells(*early, b, "before the reserve");
    const std::unique_ptr<gpu::Device> small =
        device_with_env("SDFPRUNE_VULKAN_RESERVE_BYTES", "1048576");
    const std::unique_ptr<gpu::Device> plain = device_with_envs({});
    ASSERT_TRUE(small && plain);
    EXPECT_EQ(small->memory_reserved(), 0u);
    if (std::getenv("SDFPRUNE_VULKAN_RESERVE_BYTES")) return;  // (a run that sets one for all)
    if (is_lavapipe(*plain))
        EXPECT_EQ(plain->memory_reserved(), 0u);
    else
        EXPECT_GT(plain->memory_reserved(), 0u);
}

// The idle cache keeps to its budget (SDFPRUNE_VULKAN_CACHE_BYTES), buffers cached longest
// going first; with no budget nothing is kept or reused; release_cached_memory empties it.
// Grids are the same whatever the cache holds.
TEST(Gpu, IdleCacheKeepsToItsBudget) {
    if (!gpu::built_with_vulkan()) GTEST_SKIP() << "built without the Vulkan backend";
    const Scene sc = builtin_scene("demo");
    PruneOptions o;
    o.resolution = 32;
    const std::unique_ptr<gpu::Device> none = device_with_env("SDFPRUNE_VULKAN_CACHE_BYTES", "0");
    ASSERT_TRUE(none);
    const gpu::Grid a = gpu::prune(*none, sc, o);
    const gpu::Grid b = gpu::prune(*none, sc, o);
    EXPECT_EQ(none->memory_cached(), 0u);
    EXPECT_EQ(a.stats().host_buffers_reused, 0u);
    EXPECT_EQ(b.stats().host_buffers_reused, 0u);
    EXPECT_EQ(b.stats().host_buffers, a.stats().host_buffers);

    constexpr uint64_t kBudget = 256 << 10;
    const std::unique_ptr<gpu::Device> small =
        device_with_env("SDFPRUNE_VULKAN_CACHE_BYTES", "262144");
    ASSERT_TRUE(small);
    for (int i = 0; i < 2; ++i) {
        const gpu::Grid g = gpu::prune(*small, sc, o);
        EXPECT_LE(small->memory_cached(), kBudget);
        EXPECT_GT(small->memory_cached(), 0u);  // the small buffers stay
        if (i == 1) {
            EXPECT_GT(g.stats().host_buffers_reused, 0u);
        }
        expect_same_device_cells(a, g, "a 256 KiB cache");
    }
    EXPECT_LE(small->memory_cached(), kBudget);
    small->release_cached_memory();
    EXPECT_EQ(small->memory_cached(), 0u);
    EXPECT_EQ(small->memory_in_use(), 0u);
}

// The pruning's peak device memory stays near what it makes. Scratch is held only for the
// teams a device runs at once (here 2,048 invocations: 256 teams, whatever the device), not
// for every team the scratch budget would allow (up to 128 MiB on lavapipe, 256 MiB on GPUs,
// for a small scene's many short-tape jobs). Beyond scratch, the peak is the result
// (tape_bytes) and the finest level's working set: the main pool presized for twice the share
// of its bound the previous level used, the refinement's transient tapes (about as many again,
// in the octant pool), the old pool held while its words are copied, the cells before and
// after refinement, capacities up to 1.25 times what was asked: about 6 times the pool and 3
// times the cells; 16 times tape_bytes leaves room for a device that prunes a few cells the
// other way, and catches a return of the scratch budget held in full (over 20 times here).
TEST(Gpu, PrunePeakStaysNearTheResult) {
    if (!gpu::built_with_vulkan()) GTEST_SKIP() << "built without the Vulkan backend";
    const Scene sc = builtin_scene("demo");
    PruneOptions o;
    o.resolution = 64;
    const std::unique_ptr<gpu::Device> capped =
        device_with_env("SDFPRUNE_VULKAN_RESIDENT_THREADS", "2048");
    const std::unique_ptr<gpu::Device> uncapped =
        device_with_env("SDFPRUNE_VULKAN_RESIDENT_THREADS", "1073741824");
    ASSERT_TRUE(capped && uncapped);
    const gpu::Grid small = gpu::prune(*capped, sc, o);
    const gpu::Grid large = gpu::prune(*uncapped, sc, o);
    const gpu::DevicePruneStats& st = small.stats();
    // (8.1 × the tapes + 8 MiB since the pools are no longer presized where an exact bound
    // follows; 13.2 × before.)
    EXPECT_LE(st.prune_peak_bytes, 10 * st.tape_bytes + (8u << 20))
        << "tape_bytes " << st.tape_bytes;
    EXPECT_LT(st.prune_peak_bytes, large.stats().prune_peak_bytes);
    for (const gpu::GpuStepShape& step : st.steps)
        EXPECT_LE(step.lanes, 2048u) << "level " << step.level << " mode " << step.mode;
    expect_same_grid_if_exact(sc, large, small, *capped, "resident teams capped");
}

}  // namespace
}  // namespace sdfprune::test
