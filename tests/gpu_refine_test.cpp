// gpu_refine_test.cpp — the Vulkan backend's refinement step: it takes the finest near-field
// cells only and copies those it has nothing to try, a second pass takes the cells still open,
// its lanes take tapes of up to 64 words (the squads the rest) and its cells are ordered by walk
// class; each way the cells are the CPU's.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "gpu_check.hpp"
#include "prune_check.hpp"
#include "sdfprune/builder.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/gpu.hpp"
#include "sdfprune/prune.hpp"

namespace sdfprune::test {
namespace {

// Refinement takes the finest near-field cells only (listed by the step that makes the finest
// cells; the far ones are copied as they are): its jobs are as many as those cells before
// refinement, and the grid is the CPU's, also where pools grow and the finest level is redone
// (the cells' steps then run again, from a list made again), where the finest cells come
// from their blocks (no hierarchy: mode 0), and where the cells step runs wide.
TEST(Gpu, RefinementTakesTheNearFieldCellsOnly) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const Scene sc = builtin_scene("demo");
    struct Case {
        const char* what;
        bool hierarchy, grow, wide;
    };
    const Case cases[] = {{"presized", true, false, false},
                          {"pools grow", true, true, false},
                          {"no hierarchy, pools grow", false, true, false},
                          {"wide, pools grow", true, true, true}};
    uint32_t presized_dispatches = 0;
    for (const Case& c : cases) {
        SCOPED_TRACE(c.what);
        PruneOptions o;
        o.resolution = 32;
        o.hierarchy = c.hierarchy;
        PruneOptions unrefined = o;
        unrefined.refine = 1;
        const uint64_t near_before = prune(sc, unrefined).stats().near_field_cells;
        const gpu::Grid gpu = [&] {
            std::optional<ScopedEnv> unsized;  // (only where the case's pools grow)
            if (c.grow) unsized.emplace("SDFPRUNE_VULKAN_PRESIZE_WORDS", "0");
            return prune_with_env(*dev, sc, o, "SDFPRUNE_VULKAN_WIDE", c.wide ? "1" : "0");
        }();
        const std::vector<gpu::GpuStepShape>& steps = gpu.stats().steps;
        ASSERT_GE(steps.size(), 2u);
        const gpu::GpuStepShape &cells = steps[steps.size() - 2], &refine = steps.back();
        ASSERT_EQ(refine.mode, 3u);
        EXPECT_LE(refine.long_jobs, refine.jobs);
        EXPECT_EQ(cells.mode, c.hierarchy ? 2u : 0u);
        EXPECT_EQ(cells.wide, c.wide);
        EXPECT_GT(near_before, 0u);
        EXPECT_EQ(refine.jobs, near_before);
        EXPECT_LE(refine.lanes, std::max(refine.lanes_per_tape, 32u) * refine.jobs);
        if (c.grow) {
            EXPECT_GT(gpu.stats().pool_grows, 0u);
        }
        // Refinement runs after the cells, its pool sized from their tapes: where the cells'
        // steps were redone for want of room, refinement still ran once.
        if (!c.grow && c.hierarchy && !c.wide) presized_dispatches = refine.dispatches;
        if (c.grow && c.hierarchy && !c.wide) {
            EXPECT_GT(cells.dispatches, 1u);
            EXPECT_EQ(refine.dispatches, presized_dispatches);
        }
        expect_matches_cpu(sc, prune(sc, o), gpu, *dev, c.what);
    }
}

// Refinement's lane pass walks every cell's corners and middle first, and a second pass the
// other sub-boxes of the cells that still need them: those with an operator that every sub-box
// so far decided alike, or a far-field test still open. The cells are the same as the CPU's
// for every number of sub-boxes: with 2 per axis the first pass has them all, with 3 or more a
// second pass takes some cells but not all (the demo scene has both kinds), its list sorted by
// walk class or in the order listed.
TEST(Gpu, RefinementsSecondPassTakesTheOpenCells) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const Scene sc = builtin_scene("demo");
    for (const uint32_t refine : {2u, 3u, 4u, 5u}) {
        SCOPED_TRACE("refine " + std::to_string(refine));
        PruneOptions o;
        o.resolution = 32;
        o.refine = refine;
        const gpu::Grid gpu = gpu::prune(*dev, sc, o);
        const gpu::GpuStepShape& st = gpu.stats().steps.back();
        ASSERT_EQ(st.mode, 3u);
        const uint64_t lane_cells = st.jobs - st.long_jobs;
        if (refine == 2) {
            EXPECT_EQ(st.more_jobs, 0u);
        } else {
            EXPECT_GT(st.more_jobs, 0u);
            EXPECT_LT(st.more_jobs, lane_cells);
        }
        expect_matches_cpu(sc, prune(sc, o), gpu, *dev, "refine " + std::to_string(refine));
        // The second pass's list sorted by walk class (by default) or in the order listed: the
        // same cells and the same cells listed.
        const gpu::Grid as_listed =
            prune_with_env(*dev, sc, o, "SDFPRUNE_VULKAN_REFINE_SORTED_MORE", "0");
        EXPECT_EQ(as_listed.stats().steps.back().more_jobs, st.more_jobs);
        expect_same_device_cells(gpu, as_listed, "second list sorted against as listed");
    }
}

// A smooth union of `count` spheres of radius 0.3 whose centres lie on a sphere of radius
// `spread` (a Fibonacci spiral): near its surface the finest cells' tapes hold many of them.
Scene sphere_cluster(uint32_t count, float spread, float blend) {
    SceneBuilder b;
    Shape cluster = b.sphere(0.3f);
    for (uint32_t i = 1; i < count; ++i) {
        const float a = float(i) * 2.39996f, z = 1 - 2 * (float(i) + 0.5f) / float(count);
        const float r = std::sqrt(1 - z * z);
        const vec3 centre = spread * vec3(r * std::cos(a), r * std::sin(a), z);
        cluster = smooth_union(b.sphere(0.3f).translated(centre), cluster, blend);
    }
    return b.build(cluster);
}

// Refinement's lanes take cells with tapes of up to 64 words alone where told
// (SDFPRUNE_VULKAN_REFINE_LANE_TAPE), leaving the longer ones to the squads. By default they
// take up to 32 words, or up to 64 where the cells with longer tapes would fill the device's
// lanes as squads more than once (choose_lane_tape): with many resident lanes, and with few.
// The cluster's finest cells have tapes of 17 to 80 words. The cells are the CPU's each time.
TEST(Gpu, RefinementsLanesTakeTapesOfUpTo64Words) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const Scene sc = sphere_cluster(40, 0.2f, 0.2f);
    PruneOptions o;
    o.resolution = 32;
    PruneOptions unrefined = o;
    unrefined.refine = 1;
    const PrunedGrid before = prune(sc, unrefined);
    uint64_t past_32 = 0, past_64 = 0;  // near cells with longer tapes (to the squads)
    for (const PrunedCell& c : before.level_cells(before.level_count() - 1)) {
        if (c.tape == PrunedCell::kFarField) continue;
        const size_t len = before.tape_at(c.tape).size();
        past_32 += len > 32;
        past_64 += len > 64;
    }
    ASSERT_GT(past_64, 0u);
    ASSERT_GT(past_32, past_64);
    const PrunedGrid cpu = prune(sc, o);
    const std::unique_ptr<gpu::Device> many =
        device_with_env("SDFPRUNE_VULKAN_RESIDENT_THREADS", "100000000");
    const std::unique_ptr<gpu::Device> few =
        device_with_env("SDFPRUNE_VULKAN_RESIDENT_THREADS", "64");
    ASSERT_TRUE(many && few);
    struct Case {
        const char* what;
        gpu::Device& device;
        const char* lane_tape;  // SDFPRUNE_VULKAN_REFINE_LANE_TAPE, or "" for the choice
        uint32_t expect_lane_tape;
        uint64_t expect_long;
    } cases[] = {{"lanes up to 64 words", *dev, "64", 64, past_64},
                 {"lanes up to 32 words", *dev, "32", 32, past_32},
                 {"chosen, many lanes", *many, "", 32, past_32},
                 {"chosen, 64 lanes", *few, "", 64, past_64}};
    std::optional<gpu::Grid> first;
    for (const Case& c : cases) {
        SCOPED_TRACE(c.what);
        gpu::Grid g =
            prune_with_env(c.device, sc, o, "SDFPRUNE_VULKAN_REFINE_LANE_TAPE", c.lane_tape);
        const gpu::GpuStepShape& st = g.stats().steps.back();
        ASSERT_EQ(st.mode, 3u);
        EXPECT_EQ(st.lane_tape, c.expect_lane_tape);
        EXPECT_EQ(st.long_jobs, c.expect_long);
        expect_matches_cpu(sc, cpu, g, c.device, c.what);
        if (!first)
            first.emplace(std::move(g));
        else if (&c.device == dev)
            expect_same_grid_if_exact(sc, *first, g, *dev,
                                      std::string(c.what) + " against 64 words");
    }
}

// The finest cells where refinement has nothing to try (refine_need on the CPU: no operator of
// the cell's tape whose operands at its centre pass blend_may_decide, and no far-field test
// that might pass), and those with tapes too long to refine, are listed apart and only copied:
// as many as the CPU counts from the tapes and centre values it makes before refinement (its
// grid with refine 1), and the cells are the same as the CPU's. With and without the far field
// (then only the operators count); the demo scene (smooth and hard operators) and a random one.
uint64_t cells_refinement_copies(const Scene& sc, const PruneOptions& o) {
    PruneOptions before = o;
    before.refine = 1;
    const PrunedGrid grid = prune(sc, before);
    const uint32_t N = grid.resolution(), finest = grid.level_count() - 1;
    const vec3 cell_size = (sc.aabb.max - sc.aabb.min) / float(N);
    const vec3 half = cell_size * 0.5f;
    CellScratch s;
    uint64_t copies = 0;
    for (uint32_t z = 0; z < N; ++z)
        for (uint32_t y = 0; y < N; ++y)
            for (uint32_t x = 0; x < N; ++x) {
                const PrunedGrid::CellRef at = grid.descend(x, y, z, finest);
                const PrunedCell& c = grid.level_cells(at.level)[at.index];
                if (at.level != finest || c.tape == PrunedCell::kFarField) continue;
                const std::span<const uint32_t> tape =
                    grid.tape_pool().subspan(c.tape + 2, grid.tape_pool()[c.tape]);
                if (tape.size() > math::kRefineMaxTape) {
                    ++copies;
                    continue;
                }
                const CellBox box{
                    sc.aabb.min +
                        vec3(float(x) + 0.5f, float(y) + 0.5f, float(z) + 0.5f) * cell_size,
                    half, math::length(half)};
                copies += refine_need_of_tape(sc, tape, box, o, c.value, s).any ? 0 : 1;
            }
    return copies;
}

TEST(Gpu, RefinementOnlyCopiesTheCellsItHasNothingToTry) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const Scene demo = builtin_scene("demo");
    test::RandomSceneSpec spec = test::varied_spec(5, 40);
    const Scene random = test::random_scene(9100, spec);
    struct Case {
        const Scene* sc;
        uint32_t resolution;
        bool far_field;
        const char* what;
    } cases[] = {{&demo, 32, true, "demo 32³"},
                 {&demo, 64, true, "demo 64³"},
                 {&demo, 32, false, "demo 32³, no far field"},
                 {&random, 32, true, "random scene 32³"}};
    // Teams: the wide kernel does not look for operators refinement might decide.
    const ScopedEnv teams("SDFPRUNE_VULKAN_WIDE", "0");
    for (const Case& c : cases) {
        SCOPED_TRACE(c.what);
        PruneOptions o;
        o.resolution = c.resolution;
        o.far_field = c.far_field;
        const gpu::Grid gpu = gpu::prune(*dev, *c.sc, o);
        const gpu::GpuStepShape& st = gpu.stats().steps.back();
        ASSERT_EQ(st.mode, 3u);
        EXPECT_EQ(st.copy_jobs, cells_refinement_copies(*c.sc, o));
        EXPECT_GT(st.copy_jobs, 0u);
        EXPECT_LT(st.copy_jobs, st.jobs);
        expect_matches_cpu(*c.sc, prune(*c.sc, o), gpu, *dev, c.what);
    }
}

// Refinement's lane pass takes its cells to decide again sorted by walk class, longest tapes
// first, after an order pass (one dispatch more), dealt out to its lanes in a snake; the cells
// are the same as in the order they were listed (SDFPRUNE_VULKAN_REFINE_ORDER=0), bit for bit
// on every device, and the CPU's; also with 448 lanes, which take the cells in many rounds.
TEST(Gpu, RefinementOrderChangesNoCell) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const Scene sc = builtin_scene("demo");
    PruneOptions o;
    o.resolution = 64;
    const gpu::Grid ordered = gpu::prune(*dev, sc, o);
    const gpu::Grid listed = prune_with_env(*dev, sc, o, "SDFPRUNE_VULKAN_REFINE_ORDER", "0");
    const gpu::GpuStepShape &a = ordered.stats().steps.back(), &b = listed.stats().steps.back();
    ASSERT_EQ(a.mode, 3u);
    ASSERT_EQ(b.mode, 3u);
    EXPECT_EQ(a.dispatches, b.dispatches + 1);
    EXPECT_EQ(a.jobs, b.jobs);
    EXPECT_EQ(a.copy_jobs, b.copy_jobs);
    EXPECT_EQ(a.more_jobs, b.more_jobs);
    expect_same_device_cells(ordered, listed, "ordered against listed");
    expect_matches_cpu(sc, prune(sc, o), ordered, *dev, "demo 64³, ordered");
    // (The device reads its resident threads as it is made.)
    const std::unique_ptr<gpu::Device> few_lanes =
        device_with_env("SDFPRUNE_VULKAN_RESIDENT_THREADS", "448");
    ASSERT_TRUE(few_lanes);
    const gpu::Grid few = gpu::prune(*few_lanes, sc, o);
    EXPECT_LE(few.stats().steps.back().lanes, 448u);
    EXPECT_GE(few.stats().steps.back().jobs, 3u * 448) << "the lanes' cells in a few rounds only";
    // (Its plan may take other kernels: the lane tape, the top levels wide or not.)
    expect_same_grid_if_exact(sc, few, listed, *few_lanes, "448 lanes against listed");
}

}  // namespace
}  // namespace sdfprune::test
