// gpu_wide_steps_test.cpp — the Vulkan backend's wide steps (a workgroup or more per parent
// tape): the top levels and scratch-limited steps run wide, jobs are split where their modelled
// walk falls, and a chain's rounds are walked without barriers, serially or by a scan; the cells
// are the CPU's.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <initializer_list>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "gpu_check.hpp"
#include "sdfprune/builder.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/generate.hpp"
#include "sdfprune/gpu.hpp"
#include "sdfprune/prune.hpp"

namespace sdfprune::test {
namespace {

// By default the top levels' steps, few jobs over long parent tapes, run wide: a workgroup
// per parent tape (or, with fewer jobs than the device holds workgroups, up to 8 workgroups a
// tape, a share of its boxes each), and its busiest lane walks less than a team's would. Every
// split of a job's boxes among workgroups makes the same cells.
TEST(Gpu, TopLevelsRunWide) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const Scene sc = builtin_scene("demo");  // 617 nodes
    PruneOptions o;
    o.resolution = 64;
    const gpu::Grid teams = prune_with_env(*dev, sc, o, "SDFPRUNE_VULKAN_WIDE", "0");
    const gpu::Grid gpu = gpu::prune(*dev, sc, o);
    const std::vector<gpu::GpuStepShape>& steps = gpu.stats().steps;
    ASSERT_EQ(steps.size(), teams.stats().steps.size());
    for (size_t i = 0; i < steps.size(); ++i) {
        const gpu::GpuStepShape &st = steps[i], &team = teams.stats().steps[i];
        SCOPED_TRACE("step " + std::to_string(i));
        EXPECT_EQ(st.jobs, team.jobs);
        EXPECT_FALSE(team.wide);
        if (!st.wide) continue;
        EXPECT_LT(st.mode, 3u);
        EXPECT_EQ(st.lanes_per_tape % 256u, 0u);
        EXPECT_LE(st.lanes_per_tape, 8u * 256u);
        EXPECT_EQ(st.lanes % 256u, 0u);
        EXPECT_LE(st.lanes, (st.jobs + 7) / 8 * st.lanes_per_tape);
        EXPECT_LT(st.longest_walk_words, team.longest_walk_words);
    }
    EXPECT_TRUE(steps[0].wide);  // the root's cells, from the full tape
    expect_matches_cpu(sc, prune(sc, o), gpu, *dev, "demo 64³");
    // Every step wide (at 32³), its jobs' boxes on 1, 2 or 8 workgroups.
    PruneOptions small = o;
    small.resolution = 32;
    std::optional<gpu::Grid> whole;
    for (const char* split : {"1", "2", "8"}) {
        gpu::Grid shared =
            prune_with_env(*dev, sc, small,
                           {{"SDFPRUNE_VULKAN_WIDE", "1"}, {"SDFPRUNE_VULKAN_WIDE_SPLIT", split}});
        const std::string what = std::string("wide, split ") + split;
        for (const gpu::GpuStepShape& st : shared.stats().steps)
            if (st.wide) {
                EXPECT_EQ(st.lanes_per_tape, 256u * uint32_t(std::atoi(split))) << what;
            }
        if (!whole) {
            expect_matches_cpu(sc, prune(sc, small), shared, *dev, what);
            whole.emplace(std::move(shared));
            continue;
        }
        expect_same_stats(whole->stats(), shared.stats(), what);
        expect_same_device_cells(*whole, shared, what);
    }
}

// Planned as on an H100 (270,336 resident lanes, 1,056 wide workgroups), a wide step's jobs
// are split over more workgroups where the model says their walk falls by a quarter or more: a
// balanced tree's (a generated fluid's) level-1 cells, 512 jobs over tapes of hundreds of
// words, where 512 workgroups would leave half the device idle. The busiest lane, measured on
// the device, then walks less than where jobs are split by their count and scratch alone
// (SDFPRUNE_VULKAN_WIDE_SPLIT_BY_COST=0), and the cells are the same.
// A chain's (a generated molecule's) level-1 steps stay whole: a chain's rounds take as long
// on any share of the boxes. And the model the choice rests on follows the walks the device
// measures, within a factor of 2 either way, for every wide step of both scenes, and of a
// right-deep chain whose every search for a left operand spans the rest of the tape.
TEST(Gpu, WideStepsSplitWhereTheirWalkFalls) {
    const std::unique_ptr<gpu::Device> h100 = device_planned_as_h100();
    ASSERT_TRUE(h100);
    // (The wide steps' jobs dealt, whose walks lavapipe measures as a GPU would.)
    const ScopedEnv dealt("SDFPRUNE_VULKAN_WIDE_TAKE", "0");
    PruneOptions o;
    o.resolution = 64;
    o.refine = 1;
    const auto expect_model_follows_walks = [&](const gpu::Grid& g, const std::string& what) {
        int wide = 0;
        for (const gpu::GpuStepShape& st : g.stats().steps) {
            if (!st.wide || st.jobs == 0) continue;
            ++wide;
            SCOPED_TRACE(what + ", level " + std::to_string(st.level) + " mode " +
                         std::to_string(st.mode));
            expect_walks_within_bound(*h100, st, what);
            EXPECT_GE(2 * st.walked_words, st.longest_walk_words);
        }
        EXPECT_GT(wide, 0) << what;
    };
    const Scene fluid = generate_scene("fluid", 1, 1000);
    const gpu::Grid split = gpu::prune(*h100, fluid, o);
    const gpu::Grid whole =
        prune_with_env(*h100, fluid, o, "SDFPRUNE_VULKAN_WIDE_SPLIT_BY_COST", "0");
    ASSERT_EQ(split.stats().steps.size(), whole.stats().steps.size());
    bool gained = false;
    for (size_t i = 0; i < split.stats().steps.size(); ++i) {
        const gpu::GpuStepShape &st = split.stats().steps[i], &one = whole.stats().steps[i];
        SCOPED_TRACE("fluid, step " + std::to_string(i));
        EXPECT_EQ(st.jobs, one.jobs);
        if (!st.wide || !one.wide) continue;
        // (Split by their count alone where they have few jobs, as level 0's, in both.)
        EXPECT_LE(one.lanes_per_tape, st.lanes_per_tape);
        if (st.lanes_per_tape > one.lanes_per_tape) {
            gained = true;
            EXPECT_GE(st.level, 1u);
            EXPECT_LT(4 * st.walked_words, 3 * one.walked_words);
        }
    }
    EXPECT_TRUE(gained) << "no level-1 step of the fluid was split by its modelled walk";
    expect_same_stats(whole.stats(), split.stats(), "fluid, split against whole");
    expect_same_device_cells(whole, split, "fluid, split against whole");
    expect_matches_cpu(fluid, prune(fluid, o), split, *h100, "fluid 1000, 64³");
    expect_model_follows_walks(split, "fluid");
    expect_model_follows_walks(whole, "fluid, whole");

    const Scene molecule = generate_scene("molecule", 1, 400);
    const gpu::Grid chain = gpu::prune(*h100, molecule, o);
    for (const gpu::GpuStepShape& st : chain.stats().steps)
        if (st.wide && st.level >= 1) {
            EXPECT_EQ(st.lanes_per_tape, 256u) << "molecule";
        }
    expect_model_follows_walks(chain, "molecule");
    expect_matches_cpu(molecule, prune(molecule, o), chain, *h100, "molecule 400, 64³");

    const Scene right = right_deep_chain(600);
    PruneOptions small = o;
    small.resolution = 32;
    const gpu::Grid deep = prune_with_env(*h100, right, small, "SDFPRUNE_VULKAN_WIDE", "1");
    expect_model_follows_walks(deep, "right-deep chain");
    expect_matches_cpu(right, prune(right, small), deep, *h100, "right-deep chain, 32³");
}

// Steps of many jobs run wide too where the teams would be held back by scratch: with a small
// scratch budget (SDFPRUNE_VULKAN_SCRATCH_BYTES, standing in for a large scene's long tapes),
// a generated fluid's finer levels have more than 1,024 jobs over tapes of hundreds of words;
// some such step runs wide, its busiest lane walking less than in teams under the same budget,
// and the grid is still the CPU's. Where scratch holds a wide step to fewer workgroups than it
// could run, its jobs are split (a workgroup takes fewer of a job's 8 boxes, and needs less
// scratch): more lanes work than with every job on one workgroup (SDFPRUNE_VULKAN_WIDE_SPLIT=1),
// and the grid is the same. With scratch spread over several buffers (a dispatch a buffer,
// side by side), more workgroups run at once again, and the grid is still the same.
TEST(Gpu, ScratchLimitedStepsRunWide) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const Scene sc = generate_scene("fluid", 1, 1000);
    PruneOptions o;
    o.resolution = 64;
    // (The small budget over 4 buffers, then over one.)
    const char* const budget = "786432";  // SDFPRUNE_VULKAN_SCRATCH_BYTES
    const gpu::Grid spread = prune_with_env(
        *dev, sc, o,
        {{"SDFPRUNE_VULKAN_SCRATCH_BYTES", budget}, {"SDFPRUNE_VULKAN_SCRATCH_BUFFERS", "4"}});
    const gpu::Grid teams = prune_with_env(*dev, sc, o,
                                           {{"SDFPRUNE_VULKAN_SCRATCH_BYTES", budget},
                                            {"SDFPRUNE_VULKAN_SCRATCH_BUFFERS", "1"},
                                            {"SDFPRUNE_VULKAN_WIDE", "0"}});
    const gpu::Grid unsplit = prune_with_env(*dev, sc, o,
                                             {{"SDFPRUNE_VULKAN_SCRATCH_BYTES", budget},
                                              {"SDFPRUNE_VULKAN_SCRATCH_BUFFERS", "1"},
                                              {"SDFPRUNE_VULKAN_WIDE_SPLIT", "1"}});
    const gpu::Grid gpu = prune_with_env(
        *dev, sc, o,
        {{"SDFPRUNE_VULKAN_SCRATCH_BYTES", budget}, {"SDFPRUNE_VULKAN_SCRATCH_BUFFERS", "1"}});
    ASSERT_EQ(unsplit.stats().steps.size(), gpu.stats().steps.size());
    ASSERT_EQ(spread.stats().steps.size(), gpu.stats().steps.size());
    bool spread_wider = false;
    for (size_t i = 0; i < gpu.stats().steps.size(); ++i) {
        const gpu::GpuStepShape &st = spread.stats().steps[i], &one = gpu.stats().steps[i];
        // (scratch_bytes: all the step's buffers together.)
        if (st.wide && one.wide && st.lanes > one.lanes && st.scratch_bytes > one.scratch_bytes)
            spread_wider = true;
    }
    EXPECT_TRUE(spread_wider) << "no wide step spread its scratch over more buffers";
    expect_same_device_cells(gpu, spread, "scratch spread over 4 buffers");
    bool split_wider = false;
    for (size_t i = 0; i < gpu.stats().steps.size(); ++i) {
        const gpu::GpuStepShape &st = gpu.stats().steps[i], &one = unsplit.stats().steps[i];
        if (st.wide && one.wide && st.level > 0 && st.lanes_per_tape > one.lanes_per_tape &&
            st.lanes > one.lanes)
            split_wider = true;
    }
    EXPECT_TRUE(split_wider) << "no scratch-limited wide step was split over more lanes";
    expect_same_device_cells(unsplit, gpu, "scratch-limited steps split");
    const std::vector<gpu::GpuStepShape>& steps = gpu.stats().steps;
    ASSERT_EQ(steps.size(), teams.stats().steps.size());
    bool many_wide = false;
    for (size_t i = 0; i < steps.size(); ++i) {
        const gpu::GpuStepShape &st = steps[i], &team = teams.stats().steps[i];
        SCOPED_TRACE("step " + std::to_string(i));
        EXPECT_EQ(st.jobs, team.jobs);
        if (!st.wide || st.level == 0) continue;
        EXPECT_LT(st.longest_walk_words, team.longest_walk_words);
        if (st.jobs > 8 * 1024) many_wide = true;  // team jobs: a team per 8 boxes
    }
    EXPECT_TRUE(many_wide) << "no step of more than 1,024 team jobs ran wide";
    expect_matches_cpu(sc, prune(sc, o), gpu, *dev, "fluid 1000, 64³, 1 MiB of scratch");
}

// plan_wide counts a barrier only for the rounds that end at one: a run's rounds (a chain's
// operators, one a round) are walked with none between them. A chain's steps then go wide where
// every round counted as a barrier's kept them in teams (SDFPRUNE_VULKAN_WIDE_CHAINS=0), and
// walk less there, their long runs staged in shared memory (prune_wide_runs.comp) however many
// jobs they have; a scene whose heights are all shared (the fluid's balanced tree) is planned
// as before. Planned as on an H100; the cells are the CPU's.
TEST(Gpu, WideStepsWalkAChainsRoundsWithoutBarriers) {
    const std::unique_ptr<gpu::Device> h100 = device_planned_as_h100();
    ASSERT_TRUE(h100);
    // (The wide steps' jobs dealt: lavapipe, which runs a few workgroups at a time, measures
    // the walks of dealt jobs as a GPU would, not those of jobs taken as workgroups come free.)
    const ScopedEnv dealt("SDFPRUNE_VULKAN_WIDE_TAKE", "0");
    PruneOptions o;
    o.resolution = 64;
    o.refine = 1;
    const Scene chain = right_deep_chain(300);
    const gpu::Grid chained = gpu::prune(*h100, chain, o);
    const gpu::Grid counted = prune_with_env(*h100, chain, o, "SDFPRUNE_VULKAN_WIDE_CHAINS", "0");
    ASSERT_EQ(chained.stats().steps.size(), counted.stats().steps.size());
    int moved = 0;
    for (size_t i = 0; i < chained.stats().steps.size(); ++i) {
        const gpu::GpuStepShape &st = chained.stats().steps[i], &before = counted.stats().steps[i];
        SCOPED_TRACE("chain, step " + std::to_string(i));
        EXPECT_EQ(st.jobs, before.jobs);
        EXPECT_TRUE(st.wide || !before.wide);  // none goes back to teams
        if (st.wide && !before.wide) {
            ++moved;
            EXPECT_LT(2 * st.walked_words, before.walked_words);
            // (Its runs staged, though it has more than 512 team jobs: they are long.)
            EXPECT_TRUE(st.wide_runs);
            EXPECT_GT(st.jobs, 8u * 512);
        }
    }
    EXPECT_GT(moved, 0) << "no step of the chain went wide";
    expect_same_grid_if_exact(chain, counted, chained, *h100, "chain, rounds counted alike");
    expect_matches_cpu(chain, prune(chain, o), chained, *h100, "right-deep chain of 300, 64³");

    const Scene fluid = generate_scene("fluid", 1, 1000);
    const gpu::Grid shared = gpu::prune(*h100, fluid, o);
    const gpu::Grid every = prune_with_env(*h100, fluid, o, "SDFPRUNE_VULKAN_WIDE_CHAINS", "0");
    ASSERT_EQ(shared.stats().steps.size(), every.stats().steps.size());
    for (size_t i = 0; i < shared.stats().steps.size(); ++i) {
        SCOPED_TRACE("fluid, step " + std::to_string(i));
        EXPECT_EQ(shared.stats().steps[i].wide, every.stats().steps[i].wide);
        EXPECT_EQ(shared.stats().steps[i].lanes_per_tape, every.stats().steps[i].lanes_per_tape);
        EXPECT_EQ(shared.stats().steps[i].wide_runs, every.stats().steps[i].wide_runs);
    }
}

// The wide kernel (forced wherever it fits) walks a run of rounds of one operator each (a
// chain's) with a few lanes and no barriers between its rounds, and sweeps a long one by a
// scan over its rounds (a chunk not a path, round by round): the same cells as the CPU's,
// bit for bit on lavapipe, on a left-deep chain of mixed operators, and on a chain whose lower
// part is bushy (a balanced tree, and chains of other lengths: heights with several
// operators below the run; at the finer levels, their pruned tapes leave runs between such
// heights).
TEST(Gpu, WideKernelWalksChainsSerially) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const Aabb box{vec3(-1.2f), vec3(1.2f)};
    std::vector<std::pair<std::string, Scene>> scenes;
    {
        SceneBuilder b;
        scenes.emplace_back("mixed chain",
                            b.build(mixed_chain(b, b.sphere(0.05f), 300, vec3(0.0f)), box));
    }
    {
        SceneBuilder b;
        // A balanced tree of 32 spheres, then chains of 90, 60 and 30 operators side by side,
        // joined, under a chain of 120.
        std::vector<Shape> leaves;
        for (uint32_t i = 0; i < 32; ++i)
            leaves.push_back(b.sphere(0.04f).translated(
                vec3(-0.6f + 0.04f * float(i), 0.5f * std::sin(float(i)), -0.6f)));
        while (leaves.size() > 1) {
            std::vector<Shape> up;
            for (size_t i = 0; i + 1 < leaves.size(); i += 2)
                up.push_back(smooth_union(leaves[i], leaves[i + 1], 0.02f));
            leaves = up;
        }
        const Shape a = mixed_chain(b, leaves[0], 90, vec3(-0.5f, 0.4f, 0.0f));
        const Shape c = mixed_chain(b, b.sphere(0.05f), 60, vec3(0.5f, 0.4f, 0.0f));
        const Shape d = mixed_chain(b, b.sphere(0.05f), 30, vec3(0.0f, -0.5f, 0.3f));
        const Shape joined = smooth_union(a, c, 0.02f) | d;
        scenes.emplace_back("bushy below a chain",
                            b.build(mixed_chain(b, joined, 120, vec3(0.0f, 0.0f, -0.4f)), box));
    }
    for (const auto& [name, sc] : scenes) {
        PruneOptions o;
        o.resolution = 32;
        const PrunedGrid cpu = prune(sc, o);
        // Runs walked from scratch (prune_wide_subgroups.comp), and long runs from shared
        // memory (prune_wide_runs.comp), in chunks of 32 rounds; runs of 64 rounds or more
        // swept by a scan over their rounds, or (SDFPRUNE_VULKAN_WIDE_SCAN=0) round by round.
        // The scan walks less, where a run is that long (the mixed chain's 300 operators).
        uint64_t scanned_walk = 0, serial_walk = 0;
        for (const auto& [runs, scan] : {std::pair{"0", "1"}, {"1", "1"}, {"1", "0"}}) {
            const std::string what =
                name + ", wide, runs kernel " + runs + ", scanned sweep " + scan;
            const gpu::Grid gpu = prune_with_env(*dev, sc, o,
                                                 {{"SDFPRUNE_VULKAN_WIDE", "1"},
                                                  {"SDFPRUNE_VULKAN_WIDE_RUNS", runs},
                                                  {"SDFPRUNE_VULKAN_WIDE_SCAN", scan}});
            (std::string(scan) == "1" ? scanned_walk : serial_walk) =
                gpu.stats().steps[0].walked_words;
            EXPECT_TRUE(gpu.stats().steps[0].wide) << what;
            EXPECT_TRUE(gpu.stats().steps[1].wide) << what;
            // Their walks measured (the bound counts each round of the chain once a pass). The
            // bound models the scanned sweep: round by round, a long run's sweep walks more
            // (planned as on an H100, the mixed chain's level-2 cells walked 917 words dealt,
            // against a bound of 456).
            for (const gpu::GpuStepShape& st : gpu.stats().steps) {
                if (!st.wide) continue;
                expect_walks_within_bound(*dev, st, what, std::string(scan) == "1" ? 2 : 3);
            }
            expect_matches_cpu(sc, cpu, gpu, *dev, what);
            expect_valid_cells(sc, gpu, what);
        }
        if (name == "mixed chain") {
            EXPECT_LT(4 * scanned_walk, 3 * serial_walk) << name;
        }
    }
}

}  // namespace
}  // namespace sdfprune::test
