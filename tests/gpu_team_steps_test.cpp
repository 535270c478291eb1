// gpu_team_steps_test.cpp — the Vulkan backend's steps in teams (lanes that share a parent tape):
// their shapes level by level, the jobs' order, jobs taken as workgroups come free, counters in
// device or host memory, scratch claimed job by job, flags a byte a lane and sweeps that end at
// their last kept entry; none changes a cell, and the cells are the CPU's.
#include <gtest/gtest.h>

#include <algorithm>
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
#include "sdfprune/gpu.hpp"
#include "sdfprune/prune.hpp"

namespace sdfprune::test {
namespace {

// The steps' work shapes (GpuStepShape) follow the hierarchy: per level the cells from their
// blocks (the top levels, splits_into_octants), or the octants then the cells from them, then
// the refinement; jobs are the CPU's cells and octants, lanes come in teams that share a parent
// tape (one lane per cell or octant; in refinement a squad per cell, a lane per sub-box), and
// the busiest lane walks at least one parent tape; their GPU times add up to at most the
// pruning's. (Teams only: SDFPRUNE_VULKAN_WIDE=0.)
TEST(Gpu, StepShapesFollowTheLevels) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const Scene sc = builtin_scene("demo");
    PruneOptions o;
    o.resolution = 64;  // levels 4, 16, 64
    // Teams, and refinement on squads alone (no lane pass).
    const gpu::Grid gpu = prune_with_env(
        *dev, sc, o, {{"SDFPRUNE_VULKAN_WIDE", "0"}, {"SDFPRUNE_VULKAN_REFINE_LANE_TAPE", "0"}});
    // Then refinement's lane pass for tapes of up to 4 words, the squads for the rest.
    const gpu::Grid passes = prune_with_env(
        *dev, sc, o, {{"SDFPRUNE_VULKAN_WIDE", "0"}, {"SDFPRUNE_VULKAN_REFINE_LANE_TAPE", "4"}});
    const std::vector<gpu::GpuStepShape>& steps = gpu.stats().steps;
    ASSERT_EQ(steps.size(), 5u);
    const uint32_t levels[] = {0, 1, 2, 2, 2}, modes[] = {0, 0, 1, 2, 3};
    uint64_t jobs = 0;
    for (size_t i = 0; i < steps.size(); ++i) {
        const gpu::GpuStepShape& st = steps[i];
        SCOPED_TRACE("step " + std::to_string(i));
        EXPECT_EQ(st.level, levels[i]);
        EXPECT_EQ(st.mode, modes[i]);
        EXPECT_GE(st.dispatches, 1u);
        EXPECT_GE(st.workgroups, st.dispatches);
        EXPECT_GT(st.lanes, 0u);
        // Teams of 8 lanes; refinement a squad of 32 lanes (its sub-boxes) per cell.
        EXPECT_EQ(st.lanes_per_tape, st.mode == 3 ? 32u : 8u);
        EXPECT_EQ(st.lanes % st.lanes_per_tape, 0u);
        // One lane per cell or octant; refinement has a squad per cell.
        EXPECT_LE(st.lanes, st.mode == 3 ? st.lanes_per_tape * st.jobs : st.jobs);
        EXPECT_GT(st.longest_walk_words, 0u);
        // The walks measured, refinement's squads' too.
        expect_walks_within_bound(*dev, st, "");
        EXPECT_EQ(st.lanes_ms, 0.0);
        EXPECT_EQ(st.long_jobs, 0u);
        if (st.mode == 0 || st.mode == 2) jobs += st.jobs;
    }
    const PrunedGrid cpu = prune(sc, o);
    const size_t cells_step[] = {0, 1, 3};  // a level's cells, as many as the CPU's
    for (uint32_t l = 0; l < 3; ++l)
        EXPECT_EQ(steps[cells_step[l]].jobs, cpu.level_cells(l).size()) << "level " << l;
    EXPECT_EQ(jobs,
              cpu.level_cells(0).size() + cpu.level_cells(1).size() + cpu.level_cells(2).size());
    // Level 2's octants: 8 a near-field cell of level 1.
    uint64_t near_1 = 0;
    for (const PrunedCell& c : cpu.level_cells(1)) near_1 += c.tape != PrunedCell::kFarField;
    EXPECT_EQ(steps[2].jobs, 8 * near_1);
    // Refinement's jobs are the finest near-field cells before it (the CPU's without it).
    PruneOptions unrefined = o;
    unrefined.refine = 1;
    const PrunedGrid before = prune(sc, unrefined);
    EXPECT_EQ(steps[4].jobs, before.stats().near_field_cells);
    EXPECT_LT(steps[4].jobs, steps[3].jobs);
    // The root's cells walk the full tape: evaluation and compaction, and one more pass. Its 64
    // cells are 8 jobs, one workgroup's: it walks as long as a near cell's lane, the tape
    // three times, with at most a window (64 entries) more in each of two steps where other
    // lanes are in the next phase.
    EXPECT_GE(steps[0].longest_walk_words, 3ull * sc.size());
    EXPECT_GE(steps[0].walked_words, 3ull * sc.size());
    EXPECT_LE(steps[0].walked_words, 3ull * sc.size() + 2 * 64);
    // The steps' GPU times are parts of the pruning's GPU time; with timestamps (every device
    // prune_ms comes from), each step takes some.
    double sum = 0;
    for (const gpu::GpuStepShape& st : steps) {
        EXPECT_GE(st.gpu_ms, 0.0);
        if (gpu.stats().prune_ms > 0) {
            EXPECT_GT(st.gpu_ms, 0.0);
        }
        sum += st.gpu_ms;
    }
    EXPECT_LE(sum, gpu.stats().prune_ms * 1.0001 + 1e-6);

    // With refinement's lane pass: the same steps, jobs and cells; the lanes leave to the
    // squads the cells whose tapes are longer than 4 words (counted here from the CPU's cells
    // before refinement).
    const std::vector<gpu::GpuStepShape>& with = passes.stats().steps;
    ASSERT_EQ(with.size(), steps.size());
    for (size_t i = 0; i < with.size(); ++i) {
        SCOPED_TRACE("with the lane pass, step " + std::to_string(i));
        EXPECT_EQ(with[i].mode, steps[i].mode);
        EXPECT_EQ(with[i].jobs, steps[i].jobs);
        EXPECT_LE(with[i].lanes_ms, with[i].gpu_ms);
        if (with[i].mode != 3) {
            EXPECT_EQ(with[i].lanes_ms, 0.0);
            EXPECT_EQ(with[i].long_jobs, 0u);
        } else if (passes.stats().prune_ms > 0) {
            EXPECT_GT(with[i].lanes_ms, 0.0);
        }
        // The lanes' walks measured with the squads'.
        EXPECT_GT(with[i].walked_words, 0u);
        EXPECT_GE(with[i].walked_sum_words, with[i].walked_words);
    }
    uint64_t long_cells = 0;
    for (const PrunedCell& c : before.level_cells(2))
        if (c.tape != PrunedCell::kFarField && before.tape_at(c.tape).size() > 4) ++long_cells;
    EXPECT_GT(long_cells, 0u);
    EXPECT_EQ(with[4].long_jobs, long_cells);
    // Refinement in squads alone, and in lanes then squads: other kernels, so bit for bit only
    // where the device rounds as the CPU does.
    expect_same_grid_if_exact(sc, gpu, passes, *dev, "refinement's lane pass");
}

// The octants' and cells' steps in teams take their parents (blocks, octants) longest tapes
// first within windows of 256, after an order pass (a dispatch more in each such step), or
// sorted whole (SDFPRUNE_VULKAN_TEAM_ORDER=2: two passes, the count by class and the places),
// taken by the workgroups as they come free; the cells are the same as block by block
// (SDFPRUNE_VULKAN_TEAM_ORDER=0), and the CPU's. In teams (the order is theirs), by default
// (the top levels wide), and with 56 teams (448 resident threads), which take the jobs in many
// rounds, odd, even and short.
TEST(Gpu, TeamJobOrderChangesNoCell) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const Scene sc = builtin_scene("demo");
    PruneOptions o;
    o.resolution = 64;
    const auto in_order = [](const gpu::GpuStepShape& st) {
        return (st.mode == 1 || st.mode == 2) && !st.wide;
    };
    for (const bool teams_only : {true, false})
        for (const char* order : {"1", "2"}) {
            SCOPED_TRACE(std::string(teams_only ? "teams" : "default") + ", order " + order);
            // (In teams throughout only where teams_only says so.)
            const auto prune_in_order = [&](const char* team_order) {
                std::optional<ScopedEnv> teams;
                if (teams_only) teams.emplace("SDFPRUNE_VULKAN_WIDE", "0");
                return prune_with_env(*dev, sc, o, "SDFPRUNE_VULKAN_TEAM_ORDER", team_order);
            };
            const gpu::Grid ordered = prune_in_order(order);
            const gpu::Grid blocks = prune_in_order("0");
            const std::vector<gpu::GpuStepShape>&a = ordered.stats().steps,
                  &b = blocks.stats().steps;
            ASSERT_EQ(a.size(), b.size());
            uint32_t ordered_steps = 0;
            const uint32_t passes = order[0] == '2' ? 2 : 1;
            for (size_t i = 0; i < a.size(); ++i) {
                EXPECT_EQ(a[i].jobs, b[i].jobs) << "step " << i;
                EXPECT_EQ(a[i].dispatches, b[i].dispatches + (in_order(a[i]) ? passes : 0))
                    << "step " << i;
                ordered_steps += in_order(a[i]) ? 1 : 0;
            }
            EXPECT_GT(ordered_steps, 0u);
            expect_same_device_cells(ordered, blocks, "ordered against block by block");
            expect_matches_cpu(sc, prune(sc, o), ordered, *dev, "demo 64³, teams in order");
        }
    // (order 3 here: in windows, dealt in advance in rounds, SDFPRUNE_VULKAN_TAKE=0 and
    // SDFPRUNE_VULKAN_SNAKE=0; Gpu.TakenJobsChangeNoCell deals them in a snake)
    const std::unique_ptr<gpu::Device> few_lanes =
        device_with_env("SDFPRUNE_VULKAN_RESIDENT_THREADS", "448");
    ASSERT_TRUE(few_lanes);
    for (const char* order : {"1", "2", "3"}) {
        const gpu::Grid few = [&] {
            if (order[0] != '3')
                return prune_with_env(*few_lanes, sc, o, "SDFPRUNE_VULKAN_TEAM_ORDER", order);
            return prune_with_env(*few_lanes, sc, o,
                                  {{"SDFPRUNE_VULKAN_TEAM_ORDER", "1"},
                                   {"SDFPRUNE_VULKAN_TAKE", "0"},
                                   {"SDFPRUNE_VULKAN_SNAKE", "0"}});
        }();
        uint64_t rounds = 0;
        for (const gpu::GpuStepShape& st : few.stats().steps)
            if (in_order(st)) {
                EXPECT_LE(st.lanes, 448u);
                rounds = std::max(rounds, st.jobs / 56);
            }
        EXPECT_GE(rounds, 3u) << "the teams' jobs in a few rounds only";
        expect_matches_cpu(sc, prune(sc, o), few, *few_lanes,
                           std::string("demo 64³, 56 teams, order ") + order);
    }
}

// The team steps' workgroups take their jobs as they come free, from a counter zeroed before
// each dispatch (prune_team.glsl: take_jobs), and the wide steps' workgroups their jobs' parts
// (prune_wide.glsl: take_part), instead of having them dealt out in advance
// (SDFPRUNE_VULKAN_TAKE=0, SDFPRUNE_VULKAN_WIDE_TAKE=0): the same cells, statistics and
// dispatches, and the CPU's. In teams throughout and by default (the top levels wide), in order
// and block by block, and with 56 teams (448 resident threads), which take many jobs each, each
// workgroup at most as many as dealt out (lavapipe's loop limit); and wide wherever it fits, a
// workgroup then taking many parts.
TEST(Gpu, TakenJobsChangeNoCell) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const Scene sc = builtin_scene("demo");
    PruneOptions o;
    o.resolution = 64;
    const PrunedGrid cpu = prune(sc, o);
    struct Case {
        const char* what;
        const char* wide;     // SDFPRUNE_VULKAN_WIDE, or none
        const char* order;    // SDFPRUNE_VULKAN_TEAM_ORDER
        const char* threads;  // SDFPRUNE_VULKAN_RESIDENT_THREADS, or none
    } cases[] = {{"teams, in order", "0", "1", nullptr},
                 {"default", nullptr, "1", nullptr},
                 {"teams, block by block", "0", "0", nullptr},
                 {"56 teams, in order", "0", "1", "448"},
                 {"wide wherever it fits", "1", "1", nullptr}};
    for (const Case& c : cases) {
        SCOPED_TRACE(c.what);
        // (The device reads its resident threads as it is made.)
        const std::unique_ptr<gpu::Device> own =
            c.threads ? device_with_env("SDFPRUNE_VULKAN_RESIDENT_THREADS", c.threads) : nullptr;
        gpu::Device& d = own ? *own : *dev;
        // (The case's kernels, SDFPRUNE_VULKAN_WIDE only where it names one, and order.)
        const auto prune_case = [&](EnvSettings more) {
            std::optional<ScopedEnv> wide;
            if (c.wide) wide.emplace("SDFPRUNE_VULKAN_WIDE", c.wide);
            const ScopedEnv order("SDFPRUNE_VULKAN_TEAM_ORDER", c.order);
            return prune_with_env(d, sc, o, more);
        };
        const gpu::Grid taken = prune_case({});
        const gpu::Grid dealt =
            prune_case({{"SDFPRUNE_VULKAN_WIDE_TAKE", "0"}, {"SDFPRUNE_VULKAN_TAKE", "0"}});
        const std::vector<gpu::GpuStepShape>&a = taken.stats().steps, &b = dealt.stats().steps;
        ASSERT_EQ(a.size(), b.size());
        uint32_t taking_steps = 0;
        uint64_t most_jobs_a_team = 0;
        for (size_t i = 0; i < a.size(); ++i) {
            EXPECT_EQ(a[i].jobs, b[i].jobs) << "step " << i;
            EXPECT_EQ(a[i].dispatches, b[i].dispatches) << "step " << i;
            EXPECT_EQ(a[i].taken, a[i].mode <= 2) << "step " << i;  // teams and wide
            EXPECT_FALSE(b[i].taken) << "step " << i;
            if (a[i].taken && a[i].lanes >= 8) {
                ++taking_steps;
                most_jobs_a_team = std::max(most_jobs_a_team, a[i].jobs / (a[i].lanes / 8));
            }
        }
        EXPECT_GT(taking_steps, 0u);
        if (c.wide && std::string(c.wide) == "1") {
            const auto wide_taken = [](const gpu::GpuStepShape& st) {
                return st.wide && st.taken && st.jobs > st.lanes / 32;  // many parts a workgroup
            };
            EXPECT_TRUE(std::any_of(a.begin(), a.end(), wide_taken));
        }
        if (c.threads) {
            EXPECT_GE(most_jobs_a_team, 3u) << "the teams' jobs in a few rounds only";
            for (const gpu::GpuStepShape& st : a) {
                if (st.taken) {
                    EXPECT_LE(st.lanes, std::strtoull(c.threads, nullptr, 10));
                }
            }
        }
        expect_same_stats(taken.stats(), dealt.stats(), "taken against dealt");
        expect_same_device_cells(taken, dealt, "taken against dealt");
        expect_matches_cpu(sc, cpu, taken, d, std::string("demo 64³, ") + c.what);
    }
}

// The steps' counters live in device memory, set at each submission's start and copied to a
// host-visible mirror at its end; with SDFPRUNE_VULKAN_HOST_COUNTERS=1 the kernels' atomics hit
// the host-visible buffer itself. Either way the same grid, statistics and submissions.
TEST(Gpu, CountersInDeviceOrHostMemoryGiveOneGrid) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const Scene sc = builtin_scene("demo");
    PruneOptions o;
    o.resolution = 64;
    const gpu::Grid device_counters = gpu::prune(*dev, sc, o);
    const gpu::Grid host_counters =
        prune_with_env(*dev, sc, o, "SDFPRUNE_VULKAN_HOST_COUNTERS", "1");
    EXPECT_EQ(device_counters.stats().submissions, host_counters.stats().submissions);
    EXPECT_EQ(device_counters.stats().pool_grows, host_counters.stats().pool_grows);
    expect_same_stats(host_counters.stats(), device_counters.stats(), "counters in device memory");
    expect_same_device_cells(device_counters, host_counters, "counters in device memory");
    expect_matches_cpu(sc, prune(sc, o), device_counters, *dev, "demo 64³");
}

// A step whose jobs' tapes sum to less than the longest tape per team (or wide, per
// workgroup) has each job claim scratch for its own tape (prune_team.glsl: claim_entries;
// prune_wide.glsl: claim_items) instead of every team or workgroup holding room for the
// longest: less scratch, the same cells as with room for the longest (SDFPRUNE_VULKAN_CLAIMS=0)
// and the CPU's. On the demo scene in teams throughout and wide wherever the kernel fits,
// both planned for as many teams and workgroups in flight as an H100's (so that they are not
// far fewer than the jobs, whose tapes would then sum to more than a longest one each), and
// in teams on a right-deep chain of 12,000 whose long tapes lavapipe prunes over resumed
// rounds (a job's claim kept in its team's state between them).
TEST(Gpu, ClaimsChangeNoCell) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    struct Case {
        std::string what;
        Scene sc;
        uint32_t resolution;
        bool wide;  // wide too, and planned as on an H100 (the chain's tapes are too long
                    // for its jobs on lavapipe)
    };
    std::vector<Case> cases;
    cases.push_back({"demo 64³", builtin_scene("demo"), 64, true});
    cases.push_back({"chain of 12,000 at 16³", right_deep_chain(12000), 16, false});
    const std::unique_ptr<gpu::Device> h100_like = device_planned_as_h100();
    ASSERT_TRUE(h100_like);
    for (const Case& c : cases)
        for (const bool wide : {false, true}) {
            if (wide && !c.wide) continue;
            SCOPED_TRACE(c.what + (wide ? ", wide" : ", in teams"));
            gpu::Device& d = c.wide ? *h100_like : *dev;
            PruneOptions o;
            o.resolution = c.resolution;
            const char* const kernels = wide ? "1" : "0";  // SDFPRUNE_VULKAN_WIDE
            const gpu::Grid claims = prune_with_env(d, c.sc, o, "SDFPRUNE_VULKAN_WIDE", kernels);
            const gpu::Grid longest = prune_with_env(
                d, c.sc, o, {{"SDFPRUNE_VULKAN_WIDE", kernels}, {"SDFPRUNE_VULKAN_CLAIMS", "0"}});
            const std::vector<gpu::GpuStepShape>&a = claims.stats().steps,
                  &b = longest.stats().steps;
            ASSERT_EQ(a.size(), b.size());
            uint32_t smaller = 0;
            for (size_t i = 0; i < a.size(); ++i) {
                EXPECT_EQ(a[i].jobs, b[i].jobs) << "step " << i;
                EXPECT_EQ(a[i].wide, b[i].wide) << "step " << i;
                EXPECT_LE(a[i].scratch_bytes, b[i].scratch_bytes) << "step " << i;
                smaller += a[i].scratch_bytes < b[i].scratch_bytes && a[i].wide == wide ? 1 : 0;
            }
            EXPECT_GT(smaller, 0u);
            expect_same_stats(longest.stats(), claims.stats(), "claims against the longest");
            expect_same_device_cells(claims, longest, "claims against room for the longest");
            expect_matches_cpu(c.sc, prune(c.sc, o), claims, d, c.what);
        }
}

// The team steps' decision and sweep flags a byte a lane (prune_bytes.comp, where the device
// has 8-bit storage) make the same cells as a word a lane (prune.comp,
// SDFPRUNE_VULKAN_BYTE_FLAGS=0), and the CPU's, in a third of the entries' scratch: every team
// step holds less a lane. On the demo scene planned as on an H100 (as many teams as jobs, each
// job's entries claimed) and on a right-deep chain of 12,000 whose long tapes lavapipe prunes
// over resumed rounds (room for the longest tape). A device without 8-bit storage
// (SDFPRUNE_VULKAN_8BIT_STORAGE=0) runs every step in teams, with word flags: the wide kernels,
// whose items' flags are bytes too, are not built there.
TEST(Gpu, ByteFlagsChangeNoCell) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const std::unique_ptr<gpu::Device> h100_like = device_planned_as_h100();
    const std::unique_ptr<gpu::Device> no_bytes =
        device_with_env("SDFPRUNE_VULKAN_8BIT_STORAGE", "0");
    ASSERT_TRUE(h100_like && no_bytes);
    struct Case {
        std::string what;
        Scene sc;
        uint32_t resolution;
        gpu::Device* device;
    };
    const Case cases[] = {
        {"demo 64³, planned as on an H100", builtin_scene("demo"), 64, h100_like.get()},
        {"chain of 12,000 at 16³", right_deep_chain(12000), 16, dev}};
    for (const Case& c : cases) {
        SCOPED_TRACE(c.what);
        PruneOptions o;
        o.resolution = c.resolution;
        const gpu::Grid bytes = prune_with_env(*c.device, c.sc, o, "SDFPRUNE_VULKAN_WIDE", "0");
        const gpu::Grid word =
            prune_with_env(*c.device, c.sc, o,
                           {{"SDFPRUNE_VULKAN_WIDE", "0"}, {"SDFPRUNE_VULKAN_BYTE_FLAGS", "0"}});
        if (!bytes.stats().byte_flags) GTEST_SKIP() << "the device has no 8-bit storage buffers";
        EXPECT_FALSE(word.stats().byte_flags);
        const std::vector<gpu::GpuStepShape>&a = bytes.stats().steps, &b = word.stats().steps;
        ASSERT_EQ(a.size(), b.size());
        for (size_t i = 0; i < a.size(); ++i) {
            SCOPED_TRACE("step " + std::to_string(i));
            EXPECT_EQ(a[i].jobs, b[i].jobs);
            // Less scratch a lane in flight (where the scratch budget holds a step to fewer
            // teams than its jobs, as the chain's, more teams in the same scratch).
            if (a[i].mode < 3 && a[i].jobs > 0) {
                ASSERT_GT(a[i].lanes * b[i].lanes, 0u);
                EXPECT_LT(double(a[i].scratch_bytes) / double(a[i].lanes),
                          double(b[i].scratch_bytes) / double(b[i].lanes));
            }
        }
        expect_same_stats(word.stats(), bytes.stats(), "bytes against words");
        expect_same_device_cells(bytes, word, "bytes against words");
        expect_matches_cpu(c.sc, prune(c.sc, o), bytes, *c.device, c.what);
    }
    SCOPED_TRACE("without 8-bit storage");
    PruneOptions o;
    o.resolution = 64;
    const Scene sc = builtin_scene("demo");
    const gpu::Grid teams = gpu::prune(*no_bytes, sc, o);
    EXPECT_FALSE(teams.stats().byte_flags);
    for (const gpu::GpuStepShape& st : teams.stats().steps) EXPECT_FALSE(st.wide);
    const gpu::Grid wide = gpu::prune(*dev, sc, o);
    EXPECT_TRUE(std::any_of(wide.stats().steps.begin(), wide.stats().steps.end(),
                            [](const gpu::GpuStepShape& st) { return st.wide; }));
    // (Two kernels' float rounding may differ on a GPU: there each against the CPU.)
    if (exact_device(*dev)) expect_same_device_cells(teams, wide, "without 8-bit storage");
    expect_matches_cpu(sc, prune(sc, o), teams, *no_bytes, "without 8-bit storage");
}

// A lane's sweep of its parent tape ends where it has reached every entry it kept, and its
// write starts at the last one (prune_team.glsl, refine_common.glsl: refine_write). The cells
// are those of sweeps over the whole tape (SDFPRUNE_VULKAN_SWEEP_END=0) and the CPU's, in teams
// (forced at every level): on a left-deep chain of smooth unions of spheres along a helix
// (molecule's shape: a cell near a few spheres keeps none of the chain below them), where the
// team steps and refinement walk less; on the mixed chain; and on a right-deep chain of 3,000,
// whose jobs lavapipe resumes over several rounds.
TEST(Gpu, SweepsEndAtTheirLastKeptEntry) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const Aabb box{vec3(-1.2f), vec3(1.2f)};
    std::vector<std::pair<std::string, Scene>> scenes;
    {
        SceneBuilder b;
        Shape chain = b.sphere(0.05f).translated(vec3(0.6f, 0.0f, -0.9f));
        for (uint32_t i = 1; i < 240; ++i) {
            const float a = float(i) * 0.3f;
            chain =
                smooth_union(chain,
                             b.sphere(0.05f).translated(vec3(0.6f * std::cos(a), 0.6f * std::sin(a),
                                                             -0.9f + 1.8f * float(i) / 240.0f)),
                             0.02f);
        }
        scenes.emplace_back("left-deep chain", b.build(chain, box));
    }
    {
        SceneBuilder b;
        scenes.emplace_back("mixed chain",
                            b.build(mixed_chain(b, b.sphere(0.05f), 300, vec3(0.0f)), box));
    }
    scenes.emplace_back("right-deep chain", right_deep_chain(3000));
    for (const auto& [name, sc] : scenes) {
        SCOPED_TRACE(name);
        PruneOptions o;
        o.resolution = name == "left-deep chain" ? 64 : 32;
        const PrunedGrid cpu = prune(sc, o);
        const gpu::Grid ended = prune_with_env(*dev, sc, o, "SDFPRUNE_VULKAN_WIDE", "0");
        const gpu::Grid whole = prune_with_env(
            *dev, sc, o, {{"SDFPRUNE_VULKAN_WIDE", "0"}, {"SDFPRUNE_VULKAN_SWEEP_END", "0"}});
        expect_same_stats(ended.stats(), whole.stats(), "sweeps ended against whole");
        expect_same_device_cells(ended, whole, "sweeps ended against whole");
        expect_matches_cpu(sc, cpu, ended, *dev, name);
        if (name != "left-deep chain") continue;
        // The team steps' walks and refinement's, all workgroups' together (at 64³ the cells
        // step from the octants walks about half as much, the team steps 30 % less in all).
        const auto walked = [](const gpu::Grid& g) {
            uint64_t teams = 0, refinement = 0;
            for (const gpu::GpuStepShape& st : g.stats().steps)
                (st.mode == 3 ? refinement : teams) += st.walked_sum_words;
            return std::pair{teams, refinement};
        };
        const auto [ended_teams, ended_refinement] = walked(ended);
        const auto [whole_teams, whole_refinement] = walked(whole);
        EXPECT_LT(double(ended_teams), 0.9 * double(whole_teams));
        EXPECT_LT(ended_refinement, whole_refinement);
    }
}

}  // namespace
}  // namespace sdfprune::test
