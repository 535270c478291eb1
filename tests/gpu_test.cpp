// gpu_test.cpp — the Vulkan backend's grids against the CPU backend's (the reference): the same
// statistics and the same finest cells (far-field constants, tapes word for word) over random
// scenes and options on lavapipe (on other devices: what the cells must guarantee, statistics
// within 1 %), pools that grow, the subgroup size asked for, deep chains, the reference scenes
// and levels pruned in slices. Runs on whatever Vulkan device is present (Mesa's lavapipe in CI).
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdlib>
#include <initializer_list>
#include <memory>
#include <set>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "gpu_check.hpp"
#include "prune_check.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/generate.hpp"
#include "sdfprune/gpu.hpp"
#include "sdfprune/io.hpp"
#include "sdfprune/prune.hpp"
#include "test_util.hpp"

namespace sdfprune::test {
namespace {

TEST(Gpu, PruningMatchesCpuOnRandomScenes) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const TreeShape shapes[] = {TreeShape::kBalanced, TreeShape::kLeftDeep, TreeShape::kRightDeep,
                                TreeShape::kMixed};
    const Placement places[] = {Placement::kRigid, Placement::kUniform, Placement::kNonUniform,
                                Placement::kSheared, Placement::kMixed};
    // The same device without subgroup operations (their setting is read when it opens).
    gpu::Device plain = [] {
        const ScopedEnv no_subgroups("SDFPRUNE_VULKAN_SUBGROUPS", "0");
        return gpu::Device();
    }();
    // Seeds 1-12; SDFPRUNE_TEST_SEEDS=FIRST-LAST runs others, for a longer campaign by hand.
    uint64_t first_seed = 1, last_seed = 12;
    if (const char* env = std::getenv("SDFPRUNE_TEST_SEEDS"); env && *env) {
        char* end = nullptr;
        first_seed = std::strtoull(env, &end, 10);
        last_seed = *end == '-' ? std::strtoull(end + 1, nullptr, 10) : first_seed;
        ASSERT_GE(first_seed, 1u) << "SDFPRUNE_TEST_SEEDS=" << env;
        ASSERT_GE(last_seed, first_seed) << "SDFPRUNE_TEST_SEEDS=" << env;  // (none run: a typo)
    }
    for (uint64_t seed = first_seed; seed <= last_seed; ++seed) {
        RandomSceneSpec spec;
        spec.primitives = 4 + uint32_t(seed * 7 % 29);
        spec.tree = shapes[seed % 4];
        spec.placement = places[seed % 5];
        spec.subtree_place = seed % 3 == 0 ? 0.3f : 0.0f;
        spec.clip_aabb = seed % 6 == 5;
        spec.plane_cut = seed % 4 == 2;
        const Scene sc = random_scene(seed, spec);
        PruneOptions o;
        o.resolution = seed % 2 ? 32 : 24;
        o.factor = seed % 3 == 1 ? 2 : 4;
        o.far_field = seed % 4 != 3;
        o.hierarchy = seed % 5 != 4;
        o.far_field_c = seed % 2 ? 2.0f : 1.5f;
        o.bounds = seed % 7 == 6 ? CellBounds::kLipschitz : CellBounds::kInterval;
        o.refine = uint32_t(seed % 4 + 1);
        const std::string what =
            "seed " + std::to_string(seed) + ", " + tree_shape_name(spec.tree) + ", " +
            placement_name(spec.placement) + ", grid " + std::to_string(o.resolution) + " factor " +
            std::to_string(o.factor) + " refine " + std::to_string(o.refine) +
            (o.far_field ? "" : " no-farfield") + (o.hierarchy ? "" : " no-hierarchy");
        const PrunedGrid cpu = prune(sc, o);
        // These tapes are short: the team kernel by default, then the wide kernel wherever
        // it fits (prune_wide.comp: a workgroup per parent tape), with subgroup operations
        // where the device has them, and without. Refinement: by default a lane per cell for
        // the tapes of up to 32 words (their longest) and squads for the rest, then squads alone,
        // then lanes up to 16 words, then lanes up to 4 words (with the teams taking their
        // jobs block by block, SDFPRUNE_VULKAN_TEAM_ORDER=0).
        for (int variant = 0; variant < 4; ++variant) {
            const char* const wide = variant == 3 ? "0" : variant > 0 ? "1" : "";
            const char* const lane_tape = variant == 1   ? "0"
                                          : variant == 2 ? "16"
                                          : variant == 3 ? "4"
                                                         : "";
            const char* const team_order = variant == 3 ? "0" : "";
            const gpu::Grid gpu = prune_with_env(variant == 2 ? plain : *dev, sc, o,
                                                 {{"SDFPRUNE_VULKAN_WIDE", wide},
                                                  {"SDFPRUNE_VULKAN_REFINE_LANE_TAPE", lane_tape},
                                                  {"SDFPRUNE_VULKAN_TEAM_ORDER", team_order}});
            if (variant == 2) {
                EXPECT_FALSE(gpu.stats().subgroups);
            }
            const std::string how =
                what + (variant == 1   ? ", wide, refinement on squads"
                        : variant == 2 ? ", wide without subgroups, refinement's lanes up to 16"
                        : variant == 3 ? ", teams block by block, refinement's lanes up to 4 words"
                                       : "");
            const bool exact = exact_device(*dev);
            expect_same_stats(cpu.stats(), gpu.stats(), how, exact);
            if (exact) expect_same_cells(cpu, gpu, how);
            expect_valid_cells(sc, gpu, how);  // on every device
        }
    }
}

TEST(Gpu, PoolGrowsAndTheStepIsRedone) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const Scene sc = builtin_scene("demo");
    PruneOptions o;
    o.resolution = 64;
    const PrunedGrid cpu = prune(sc, o);
    uint64_t submissions = 1;
    const std::vector<uint32_t> res = grid_levels(o.resolution, o.factor);
    for (size_t l = 0; l < res.size(); ++l)
        submissions +=
            splits_into_octants(sc, o, res[l], l == 0 ? res[0] : res[l] / res[l - 1]) ? 2 : 1;
    ASSERT_EQ(submissions, 1u + 1u + 1u + 2u);  // levels 0 and 1 direct, level 2 split
    {
        // Pools sized before each level from the parents' tapes, the cells' from their
        // octants' tapes and refinement's from the cells': two submissions per level split
        // into octants (the octants, then the cells), one per other level, one for
        // refinement, none redone.
        const gpu::Grid gpu = gpu::prune(*dev, sc, o);
        EXPECT_EQ(gpu.stats().pool_grows, 0u);
        EXPECT_EQ(gpu.stats().submissions, submissions);
        expect_matches_cpu(sc, cpu, gpu, *dev, "demo 64³, presized");
    }
    // Without that, the demo's tapes at 64³ outgrow the initial pools (1 Mi words, 64 Ki for
    // the octants'): they grow and their levels are redone.
    const gpu::Grid gpu = prune_with_env(*dev, sc, o, "SDFPRUNE_VULKAN_PRESIZE_WORDS", "0");
    EXPECT_GT(gpu.stats().pool_grows, 0u);
    EXPECT_GT(gpu.stats().submissions, submissions);
    EXPECT_LE(gpu.stats().submissions, submissions + gpu.stats().pool_grows);
    expect_matches_cpu(sc, cpu, gpu, *dev, "demo 64³");
    // The same through the wide kernel wherever it fits (at 32³, where its tapes outgrow the
    // pools too: on lavapipe it is slow over many jobs).
    o.resolution = 32;
    const gpu::Grid wide = prune_with_env(
        *dev, sc, o, {{"SDFPRUNE_VULKAN_PRESIZE_WORDS", "0"}, {"SDFPRUNE_VULKAN_WIDE", "1"}});
    EXPECT_GT(wide.stats().pool_grows, 0u);
    EXPECT_TRUE(wide.stats().steps[0].wide);
    expect_matches_cpu(sc, prune(sc, o), wide, *dev, "demo 32³, wide");
}

// The kernels' subgroup appends and prefix sums hold for any subgroup size: 32 lanes on NVIDIA,
// 8 on lavapipe by default. ctest runs the tests that compare whole grids with the CPU's again on
// lavapipe with 4 and with 16 lanes a subgroup (LP_NATIVE_VECTOR_WIDTH=128 and 512,
// CMakeLists.txt), SDFPRUNE_TEST_SUBGROUP_SIZE saying which; this test checks that the device
// gave them that size, so those runs test what they say.
TEST(Gpu, SubgroupSizeIsTheOneAskedFor) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const Scene sc = builtin_scene("demo");
    PruneOptions o;
    o.resolution = 16;
    const uint32_t size = gpu::prune(*dev, sc, o).stats().subgroup_size;
    // (Only lavapipe takes its subgroup size from LP_NATIVE_VECTOR_WIDTH.)
    const char* asked = std::getenv("SDFPRUNE_TEST_SUBGROUP_SIZE");
    if (asked && is_lavapipe(*dev)) {
        EXPECT_EQ(size, uint32_t(std::strtoul(asked, nullptr, 10)));
    }
    if (size != 0) {
        EXPECT_EQ(size & (size - 1), 0u) << "a subgroup of " << size << " lanes";
        EXPECT_LE(size, 128u);
    }
    // Without subgroup operations the kernels use none, and the size says so.
    gpu::Device without = [] {
        const ScopedEnv no_subgroups("SDFPRUNE_VULKAN_SUBGROUPS", "0");
        return gpu::Device();
    }();
    const gpu::Grid g = gpu::prune(without, sc, o);
    EXPECT_EQ(g.stats().subgroup_size, 0u);
    EXPECT_FALSE(g.stats().subgroups);
}

TEST(Gpu, DeepChainPrunes) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    // Right-deep chains: the evaluation stack is as deep as the chain, the tapes are long.
    // (lavapipe ends an invocation's loops after 65,535 iterations in all: there the longer
    // tapes are pruned over several resumed rounds.)
    for (uint32_t depth : {3000u, 12000u}) {
        const Scene sc = right_deep_chain(depth);
        ASSERT_EQ(sc.max_stack, depth + 1);
        PruneOptions o;
        o.resolution = 16;
        const PrunedGrid cpu = prune(sc, o);
        const gpu::Grid gpu = gpu::prune(*dev, sc, o);
        const std::string what = "chain of " + std::to_string(depth);
        expect_matches_cpu(sc, cpu, gpu, *dev, what);
    }
}

// Lavapipe ends an invocation's loops after 65,535 iterations in all, and the invocation goes
// on as if they had ended: a step planned past that limit would make wrong cells without a
// word. The pruning kernels probe for it (prune_common.glsl: probe_loop_limit) and the pruning
// throws. Planned as a GPU (a step in one dispatch) on lavapipe's own resident lanes, with the
// jobs taken, the 12,000-deep chain passes the limit; planned for lavapipe, it does not
// (DeepChainPrunes). (Those settings are the test's own: with an H100's resident lanes, 32 lanes
// a subgroup and the jobs dealt, no invocation reaches the limit.)
TEST(Gpu, ReachedLoopLimitIsReported) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    if (!is_lavapipe(*dev)) GTEST_SKIP() << dev->name() << " ends no loops";
    const Scene sc = right_deep_chain(12000);
    PruneOptions o;
    o.resolution = 16;
    const ScopedEnv as_a_gpu_here({{"SDFPRUNE_VULKAN_LOOP_LIMITED", "0"},
                                   {"SDFPRUNE_VULKAN_RESIDENT_THREADS", ""},
                                   {"SDFPRUNE_VULKAN_TAKE", ""},
                                   {"SDFPRUNE_VULKAN_WIDE_TAKE", ""}});
    gpu::Device as_a_gpu;
    std::string error;
    try {
        gpu::prune(as_a_gpu, sc, o);
    } catch (const std::logic_error& e) {
        error = e.what();
    }
    EXPECT_NE(error.find("limit of 65535 loop iterations"), std::string::npos) << error;
}

TEST(Gpu, ReferenceScenesMatchCpu) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    for (const char* file : {"molecule.json", "trees.json"}) {
        SDFPRUNE_REQUIRE_SCENE(path, file);
        const Scene sc = load_scene(path);
        PruneOptions o;
        o.resolution = 128;
        const PrunedGrid cpu = prune(sc, o);
        const gpu::Grid gpu = gpu::prune(*dev, sc, o);
        // Every cell, tape word for tape word where the device rounds as the CPU does: the
        // molecule's chain is where the team steps' sweeps end early the most.
        expect_matches_cpu(sc, cpu, gpu, *dev, file);
    }
}

// Where a level's octants' and unrefined cells' tapes would outgrow the device's largest buffer
// (the million-sphere fluid's finest level on a real GPU), its blocks are pruned a slice at a
// time, the octant pool emptied between slices: the grid is still the CPU's, cell for cell. On
// a device that addresses 1 MiB of a buffer, the generated city at 32³ needs slices.
TEST(Gpu, LevelsTooLargeForOneBufferArePrunedInSlices) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const std::unique_ptr<gpu::Device> small =
        device_with_env("SDFPRUNE_VULKAN_MAX_BUFFER", "1048576");
    ASSERT_TRUE(small);
    const Scene sc = generate_scene("city", 1);
    PruneOptions o;
    o.resolution = 32;
    const PrunedGrid cpu = prune(sc, o);
    const gpu::Grid gpu = gpu::prune(*small, sc, o);
    const uint32_t levels = uint32_t(gpu.stats().levels.size());
    EXPECT_GT(gpu.stats().slices, levels) << "no level was sliced";
    expect_matches_cpu(sc, cpu, gpu, *small, "city 32³ in slices");
    // Each step's shape is one, summed over the slices: one per level and mode.
    std::set<std::pair<uint32_t, uint32_t>> seen;
    for (const gpu::GpuStepShape& s : gpu.stats().steps)
        EXPECT_TRUE(seen.insert({s.level, s.mode}).second)
            << "level " << s.level << " mode " << s.mode << " reported twice";
    // The teams taking their jobs block by block (SDFPRUNE_VULKAN_TEAM_ORDER=0), slice by slice.
    const gpu::Grid blocks = prune_with_env(*small, sc, o, "SDFPRUNE_VULKAN_TEAM_ORDER", "0");
    EXPECT_GT(blocks.stats().slices, levels) << "no level was sliced";
    expect_matches_cpu(sc, cpu, blocks, *small, "city 32³ in slices, teams block by block");
    // On the device as it is, the same scene needs a slice a level.
    const gpu::Grid whole = gpu::prune(*dev, sc, o);
    EXPECT_EQ(whole.stats().slices, levels);
    expect_matches_cpu(sc, cpu, whole, *dev, "city 32³");
}

}  // namespace
}  // namespace sdfprune::test
