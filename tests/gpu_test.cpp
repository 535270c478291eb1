// gpu_test.cpp — the Vulkan backend against the CPU backend (the reference): the same
// statistics and the same finest cells (far-field constants, tapes word for word) over random
// scenes and options on lavapipe (on other devices: what the cells must guarantee, statistics
// within 1 %), the same images and samples, buffer growth, a deep chain, and the CLI's handling
// of --backend. Runs on whatever Vulkan device is present (Mesa's lavapipe in CI).
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <initializer_list>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "prune_check.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/discretize.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/generate.hpp"
#include "sdfprune/gpu.hpp"
#include "sdfprune/io.hpp"
#include "sdfprune/render.hpp"
#include "test_util.hpp"

namespace sdfprune::test {
namespace {

// One device for the whole file; a build with Vulkan must find one (make setup installs
// lavapipe), a build without it skips.
gpu::Device* device(std::string& why) {
    static std::string error;
    static std::unique_ptr<gpu::Device> dev = [] {
        try {
            return std::make_unique<gpu::Device>();
        } catch (const gpu::GpuError& e) {
            error = e.what();
            return std::unique_ptr<gpu::Device>();
        }
    }();
    why = error;
    return dev.get();
}

#define SDFPRUNE_REQUIRE_DEVICE(var)                                                   \
    if (!gpu::built_with_vulkan()) GTEST_SKIP() << "built without the Vulkan backend"; \
    std::string why_;                                                                  \
    gpu::Device* var = device(why_);                                                   \
    ASSERT_NE(var, nullptr) << "no Vulkan device (install mesa-vulkan-drivers): " << why_

// Environment variables, each a name and a value.
using EnvSettings = std::initializer_list<std::pair<const char*, const char*>>;

// Environment variables set for a scope (settings the device reads as it is made, or the pruner
// as it runs), then put back as they were, last set first back: unset where they were unset,
// else their value before (a run may set some for all tests). A failed assertion that returns
// early puts them back too.
class ScopedEnv {
  public:
    explicit ScopedEnv(EnvSettings settings) {
        for (const auto& [name, value] : settings) {
            const char* was = std::getenv(name);
            before_.emplace_back(name, was ? std::optional<std::string>(was) : std::nullopt);
            ::setenv(name, value, 1);
        }
    }
    ScopedEnv(const char* name, const char* value) : ScopedEnv({{name, value}}) {}
    ~ScopedEnv() {
        for (auto it = before_.rbegin(); it != before_.rend(); ++it) {
            if (it->second)
                ::setenv(it->first.c_str(), it->second->c_str(), 1);
            else
                ::unsetenv(it->first.c_str());
        }
    }
    ScopedEnv(const ScopedEnv&) = delete;
    ScopedEnv& operator=(const ScopedEnv&) = delete;

  private:
    std::vector<std::pair<std::string, std::optional<std::string>>> before_;  // name, value
};

// A pruning with the environment variables `settings` set for its duration.
gpu::Grid prune_with_env(gpu::Device& dev, const Scene& sc, const PruneOptions& o,
                         EnvSettings settings) {
    const ScopedEnv env(settings);
    return gpu::prune(dev, sc, o);
}
gpu::Grid prune_with_env(gpu::Device& dev, const Scene& sc, const PruneOptions& o, const char* name,
                         const char* value) {
    return prune_with_env(dev, sc, o, {{name, value}});
}

// Whether the device should give the CPU's grids bit for bit: lavapipe (the same LLVM code
// generation rules as the CPU build, no fused multiply-add). Other drivers may round a centre
// or a bound differently and so decide a borderline operator or cell the other way; there the
// tests check what a grid must guarantee instead (expect_valid_cells). SDFPRUNE_GPU_EXACT=0 or
// 1 overrides the choice.
bool exact_device(const gpu::Device& dev) {
    if (const char* env = std::getenv("SDFPRUNE_GPU_EXACT")) return std::string(env) != "0";
    return dev.name().find("llvmpipe") != std::string::npos;
}

// On an exact device the same statistics; elsewhere within 1 % (cells that flip near a
// decision's margin move the averages a little).
void expect_same_stats(const PruneStats& cpu, const PruneStats& gpu, const std::string& what,
                       bool exact = true) {
    EXPECT_EQ(cpu.levels, gpu.levels) << what;
    if (exact) return expect_same_prune_stats(cpu, gpu, what);
    SCOPED_TRACE(what);
    EXPECT_EQ(cpu.cells, gpu.cells);
    const auto near = [](double a, double b) {
        return std::fabs(a - b) <= 0.01 * (1 + std::fabs(a));
    };
    EXPECT_PRED2(near, double(cpu.near_field_cells), double(gpu.near_field_cells));
    EXPECT_PRED2(near, cpu.active_avg, gpu.active_avg);
    EXPECT_PRED2(near, cpu.tape_avg, gpu.tape_avg);
}

// A step's walks as measured on the device: some, the longest within twice the planned bound
// (a team's lane may pass from one phase to the next within a step; a wide lane's bound counts
// its searches by the scene's mean steps, and a chain's top-down pass round by round), and all
// workgroups' walks at least the longest and at most as if every workgroup walked as long.
void expect_walks_within_bound(const gpu::GpuStepShape& st, const std::string& what) {
    EXPECT_GT(st.walked_words, 0u) << what;
    EXPECT_LE(st.walked_words, 2 * st.longest_walk_words) << what;
    EXPECT_GE(st.walked_sum_words, st.walked_words) << what;
    EXPECT_LE(st.walked_sum_words, st.workgroups * st.walked_words) << what;
}

// Whether a tape walk can run `tape`: every word names a node of the scene, each operator finds
// two values on the stack, which is at most scene.max_stack deep, and one value is left. (A
// broken kernel's tape must fail a test, not crash the test binary.)
bool runnable_tape(const Scene& sc, std::span<const uint32_t> tape) {
    uint64_t depth = 0;
    for (const uint32_t w : tape) {
        const uint32_t n = math::tape_node(w);
        if (n >= sc.size()) return false;
        if (sc.is_primitive(n)) {
            if (++depth > sc.max_stack) return false;
        } else if (depth < 2) {
            return false;
        } else {
            --depth;
        }
    }
    return depth == 1;
}

// What every finest cell must guarantee, whichever device made it, at its centre and 8 points
// near its corners: a near-field cell's tape gives the full tree's value (within float
// rounding); a far-field constant has the value's sign and never overstates it (a lower bound of
// |f| over the cell).
void expect_valid_cells(const Scene& sc, const gpu::Grid& gpu, const std::string& what) {
    SCOPED_TRACE(what);
    const uint32_t N = gpu.stats().grid;
    const vec3 cs = (sc.aabb.max - sc.aabb.min) / float(N);
    std::vector<float> stack(sc.max_stack + 1);
    uint64_t bad = 0;
    gpu.for_each_finest_cell([&](uint64_t i, const gpu::Grid::CellContents& c) {
        const uint32_t x = uint32_t(i % N), y = uint32_t(i / N % N), z = uint32_t(i / N / N);
        const vec3 centre =
            sc.aabb.min + vec3(float(x) + 0.5f, float(y) + 0.5f, float(z) + 0.5f) * cs;
        if (!c.far_field && !runnable_tape(sc, c.tape)) {
            if (++bad <= 3)
                ADD_FAILURE() << "cell (" << x << ", " << y << ", " << z << "): a tape of "
                              << c.tape.size() << " words that no walk can run";
            return;
        }
        for (uint32_t k = 0; k < 9; ++k) {
            const vec3 d = k == 0 ? vec3(0, 0, 0)
                                  : vec3(k & 1 ? 0.45f : -0.45f, k & 2 ? 0.45f : -0.45f,
                                         k & 4 ? 0.45f : -0.45f);
            const vec3 p = centre + d * cs;
            const float f = eval_tape(sc, sc.full_tape, p, stack.data());
            const float tol = 1e-5f * (1 + std::fabs(f));
            bool ok;
            if (c.far_field)
                ok = c.constant > 0 ? f >= c.constant - tol : f <= c.constant + tol;
            else
                ok = std::fabs(eval_tape(sc, c.tape, p, stack.data()) - f) <= tol;
            if (!ok && ++bad <= 3)
                ADD_FAILURE() << "cell (" << x << ", " << y << ", " << z << ") point " << k
                              << ": full tree " << f << ", "
                              << (c.far_field ? "far " + std::to_string(c.constant)
                                              : "tape gives " + std::to_string(eval_tape(
                                                                    sc, c.tape, p, stack.data())));
        }
    });
    EXPECT_EQ(bad, 0u);
}

// Every finest cell: same kind, same far-field constant, same tape.
void expect_same_cells(const PrunedGrid& cpu, const gpu::Grid& gpu, const std::string& what) {
    SCOPED_TRACE(what);
    const uint32_t N = cpu.resolution();
    uint64_t visited = 0, mismatches = 0;
    gpu.for_each_finest_cell([&](uint64_t i, const gpu::Grid::CellContents& c) {
        ++visited;
        const uint32_t x = uint32_t(i % N), y = uint32_t(i / N % N), z = uint32_t(i / N / N);
        const CellView v = cpu.cell(x, y, z);
        const bool same =
            v.far_field == c.far_field &&
            (v.far_field ? v.constant == c.constant
                         : std::equal(v.tape.begin(), v.tape.end(), c.tape.begin(), c.tape.end()));
        if (!same && ++mismatches <= 3)
            ADD_FAILURE() << "cell (" << x << ", " << y << ", " << z << "): cpu "
                          << (v.far_field ? "far " + std::to_string(v.constant)
                                          : "tape of " + std::to_string(v.tape.size()))
                          << ", gpu "
                          << (c.far_field ? "far " + std::to_string(c.constant)
                                          : "tape of " + std::to_string(c.tape.size()));
    });
    EXPECT_EQ(visited, uint64_t(N) * N * N);
    EXPECT_EQ(mismatches, 0u);
}

// The GPU's grid against the CPU's: the statistics, and every finest cell bit for bit where the
// device rounds as the CPU does (lavapipe), else what every device must give.
void expect_matches_cpu(const Scene& sc, const PrunedGrid& cpu, const gpu::Grid& gpu,
                        const gpu::Device& dev, const std::string& what) {
    const bool exact = exact_device(dev);
    expect_same_stats(cpu.stats(), gpu.stats(), what, exact);
    if (exact)
        expect_same_cells(cpu, gpu, what);
    else
        expect_valid_cells(sc, gpu, what);
}

// Two grids of one device, cell by cell: the same far-field constants and tapes.
void expect_same_device_cells(const gpu::Grid& a, const gpu::Grid& b, const std::string& what);

// Two grids of one scene whose plans may take other kernels for some steps (teams or wide,
// refinement's lanes or squads): on an exact device the same statistics and cells, bit for bit;
// elsewhere each kernel may round a bound differently, so the statistics agree within their
// tolerance and each grid holds what a grid guarantees.
void expect_same_grid_if_exact(const Scene& sc, const gpu::Grid& a, const gpu::Grid& b,
                               const gpu::Device& dev, const std::string& what) {
    const bool exact = exact_device(dev);
    expect_same_stats(a.stats(), b.stats(), what, exact);
    if (exact) return expect_same_device_cells(a, b, what);
    expect_valid_cells(sc, a, what);
    expect_valid_cells(sc, b, what);
}

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
    for (uint64_t seed = 1; seed <= 12; ++seed) {
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

// A device made with environment variables set (for the figures it reads once).
std::unique_ptr<gpu::Device> device_with_envs(EnvSettings settings) {
    const ScopedEnv env(settings);
    try {
        return std::make_unique<gpu::Device>();
    } catch (const gpu::GpuError& e) {
        ADD_FAILURE() << "no Vulkan device (install mesa-vulkan-drivers): " << e.what();
        return nullptr;
    }
}
std::unique_ptr<gpu::Device> device_with_env(const char* name, const char* value) {
    return device_with_envs({{name, value}});
}
// A device that plans its steps for an H100's or H200's resident lanes (132 SMs of 2,048), so
// that lavapipe takes the shapes a GPU takes.
std::unique_ptr<gpu::Device> device_planned_as_h100() {
    return device_with_env("SDFPRUNE_VULKAN_RESIDENT_THREADS", "270336");
}

// A right-deep chain of `depth` smooth unions of small spheres on a helix: its evaluation
// stack is as deep as the chain, its tapes long.
Scene right_deep_chain(uint32_t depth) {
    SceneBuilder b;
    Shape chain = b.sphere(0.05f).translated(vec3(0.9f, 0, 0));
    for (uint32_t i = 1; i <= depth; ++i) {
        const float a = float(i) * 0.0031f;
        const Shape s =
            b.sphere(0.04f).translated(vec3(std::cos(a), std::sin(a), 0.1f * std::sin(3 * a)));
        chain = smooth_union(s, chain, 0.02f);
    }
    return b.build(chain);
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
    if (asked && dev->name().find("llvmpipe") != std::string::npos) {
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
        expect_walks_within_bound(st, "");
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
    expect_same_stats(gpu.stats(), passes.stats(), "refinement's lane pass");
    expect_same_device_cells(gpu, passes, "refinement's lane pass");
}

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
    const auto expect_model_follows_walks = [](const gpu::Grid& g, const std::string& what) {
        int wide = 0;
        for (const gpu::GpuStepShape& st : g.stats().steps) {
            if (!st.wide || st.jobs == 0) continue;
            ++wide;
            SCOPED_TRACE(what + ", level " + std::to_string(st.level) + " mode " +
                         std::to_string(st.mode));
            expect_walks_within_bound(st, what);
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

// Every finest cell of two device grids, compared: the same kind, constant and tape.
void expect_same_device_cells(const gpu::Grid& a, const gpu::Grid& b, const std::string& what) {
    SCOPED_TRACE(what);
    struct Cell {  // a copy (CellContents' tape lives only within the visit)
        bool far_field;
        float constant;
        std::vector<uint32_t> tape;
    };
    std::vector<Cell> cells;
    a.for_each_finest_cell([&](uint64_t, const gpu::Grid::CellContents& c) {
        cells.push_back({c.far_field, c.constant, {c.tape.begin(), c.tape.end()}});
    });
    uint64_t mismatches = 0, i = 0;
    b.for_each_finest_cell([&](uint64_t, const gpu::Grid::CellContents& c) {
        ASSERT_LT(i, cells.size());
        const Cell& want = cells[i];
        const bool same = want.far_field == c.far_field &&
                          (c.far_field ? want.constant == c.constant
                                       : std::equal(want.tape.begin(), want.tape.end(),
                                                    c.tape.begin(), c.tape.end()));
        if (!same && ++mismatches <= 3) ADD_FAILURE() << "finest cell " << i << " differs";
        ++i;
    });
    EXPECT_EQ(i, cells.size());
    EXPECT_EQ(mismatches, 0u);
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
    if (plain->name().find("llvmpipe") != std::string::npos)
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

// `base` grown into a left-deep chain by `ops` more operators, each with a small sphere on a
// helix around `centre`, their kinds in turn: smooth and hard unions, a smooth difference (a
// negated right operand), an intersection and a smooth intersection with large shapes, and a
// union with the chain as its right operand; every 16th operator subtracts the chain from a
// large sphere (the chain negated), the next 16th does so again.
Shape mixed_chain(SceneBuilder& b, Shape base, uint32_t ops, vec3 centre) {
    Shape chain = base;
    for (uint32_t i = 1; i <= ops; ++i) {
        const float a = float(i) * 0.21f;
        const Shape s = b.sphere(0.03f + 0.01f * float(i % 3))
                            .translated(centre + vec3(0.3f * std::cos(a), 0.3f * std::sin(a),
                                                      0.5f * float(i) / float(ops) - 0.25f));
        switch (i % 6) {
            case 0:
                chain = smooth_union(chain, s, 0.03f);
                break;
            case 1:
                chain = chain | s;
                break;
            case 2:
                chain = smooth_difference(chain, s.scaled(0.5f), 0.01f);
                break;
            case 3:
                chain = chain & b.sphere(0.6f).translated(centre);
                break;
            case 4:
                chain = smooth_union(s, chain, 0.02f);
                break;
            default:
                chain = smooth_intersection(chain, b.box(vec3(0.8f)).translated(centre), 0.05f);
        }
        if (i % 16 == 0) chain = b.sphere(0.7f).translated(centre) - chain;
    }
    return chain;
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
            // Their walks measured (the bound counts each round of the chain once a pass).
            for (const gpu::GpuStepShape& st : gpu.stats().steps) {
                if (!st.wide) continue;
                expect_walks_within_bound(st, what);
            }
            expect_matches_cpu(sc, cpu, gpu, *dev, what);
            expect_valid_cells(sc, gpu, what);
        }
        if (name == "mixed chain") {
            EXPECT_LT(4 * scanned_walk, 3 * serial_walk) << name;
        }
    }
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

// Images: the same rays and arithmetic; a driver may round differently, so a few pixels may
// differ slightly (none do on lavapipe).
void expect_similar(const Image& a, const Image& b, const std::string& what) {
    SCOPED_TRACE(what);
    ASSERT_EQ(a.rgb.size(), b.rgb.size());
    const size_t differ = test::pixels_differing(a, b, 2);
    EXPECT_LE(double(differ), 0.002 * double(a.rgb.size() / 3)) << differ << " pixels differ";
}

// The deepest evaluation stack any finest cell's tape needs (a primitive pushes a value, an
// operator pops two and pushes one), worked out on the host from the tapes read back.
uint32_t deepest_finest_stack(const Scene& sc, const gpu::Grid& grid) {
    uint32_t deepest = 0;
    grid.for_each_finest_cell([&](uint64_t, const gpu::Grid::CellContents& c) {
        uint32_t depth = 0;
        for (uint32_t w : c.tape) {
            depth = sc.is_primitive(math::tape_node(w)) ? depth + 1 : depth - 1;
            deepest = std::max(deepest, depth);
        }
    });
    return deepest;
}

TEST(Gpu, RenderMatchesCpu) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    RandomSceneSpec spec;
    spec.primitives = 24;
    spec.placement = Placement::kMixed;
    RandomSceneSpec cut = spec;
    cut.plane_cut = true;
    cut.union_share = 1.0f;  // a union of solids, half of it cut away: something to hit
    const Scene scenes[] = {builtin_scene("demo"), random_scene(77, spec), random_scene(78, cut)};
    for (const Scene& sc : scenes)
        for (const bool clearance : {false, true}) {  // with and without the far-field skips
            PruneOptions o;
            o.resolution = 64;
            o.clearance = clearance;
            const PrunedGrid cpu = prune(sc, o);
            const gpu::Grid gpu = gpu::prune(*dev, sc, o);
            for (Shading shading : {Shading::kShaded, Shading::kNormals, Shading::kHeatmap}) {
                RenderOptions ro;
                ro.tile_cones = ro.convex_steps = false;  // the Vulkan renderer's steps
                ro.width = 160;
                ro.height = 96;
                ro.shading = shading;
                ro.camera = orbit_camera(sc.aabb, 35, 20, 0, 40);
                RenderStats cs, gs;
                const Image a = render(cpu, ro, &cs);
                const Image b = gpu::render(*dev, gpu, ro, &gs);
                expect_similar(
                    a, b,
                    "shading " + std::to_string(int(shading)) + (clearance ? ", clearances" : ""));
                EXPECT_NEAR(cs.hit_fraction, gs.hit_fraction, 1e-3);
                EXPECT_NEAR(cs.steps_avg, gs.steps_avg, 0.01 * cs.steps_avg);
                EXPECT_GT(gs.hit_fraction, 0.0);
                // Stacks for the deepest finest tape, 4 words a value.
                EXPECT_EQ(gs.stack_words, 4u * deepest_finest_stack(sc, gpu));
            }
        }
}

// The box rays are marched in (PrunedGrid::near_box; the GPU's from expand.comp's bounds) on
// grids of factor 3 and of one level (the scene's box): the same steps and hits as the CPU's.
TEST(Gpu, RenderMarchesTheCpusBox) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    RandomSceneSpec spec;
    spec.primitives = 16;
    spec.placement = Placement::kMixed;
    spec.union_share = 1.0f;  // a union of solids: something to hit
    const Scene sc = random_scene(79, spec);
    for (const bool hierarchy : {true, false}) {
        PruneOptions o;
        o.resolution = hierarchy ? 54 : 32;
        o.factor = 3;
        o.hierarchy = hierarchy;
        const PrunedGrid cpu = prune(sc, o);
        const gpu::Grid gpu = gpu::prune(*dev, sc, o);
        RenderOptions ro;
        ro.tile_cones = ro.convex_steps = false;  // the Vulkan renderer's steps
        ro.width = 96;
        ro.height = 64;
        ro.camera = orbit_camera(sc.aabb, 35, 20, 0, 40);
        RenderStats cs, gs;
        const Image a = render(cpu, ro, &cs);
        const Image b = gpu::render(*dev, gpu, ro, &gs);
        const std::string what = hierarchy ? "factor 3" : "one level";
        expect_similar(a, b, what);
        EXPECT_NEAR(cs.hit_fraction, gs.hit_fraction, 1e-3) << what;
        EXPECT_NEAR(cs.steps_avg, gs.steps_avg, 0.01 * cs.steps_avg) << what;
        EXPECT_GT(cs.hit_fraction, 0.0) << what;
    }
}

// Samples of an n³ discretization on which the backends differ beyond float rounding.
size_t discretize_mismatches(const PrunedGrid& cpu, gpu::Device& dev, const gpu::Grid& gpu,
                             uint32_t n) {
    std::vector<float> a(size_t(n) * n * n), b(a.size());
    discretize_pruned(cpu, n, a);
    gpu::discretize(dev, gpu, n, b);
    size_t bad = 0;
    for (size_t i = 0; i < a.size(); ++i)
        bad += std::fabs(a[i] - b[i]) <= 1e-6f * (1 + std::fabs(a[i])) ? 0 : 1;
    return bad;
}

// The device's samples of an n³ grid against what they must be on any device, whatever its
// rounding: the full tree's sign, never a magnitude above the full tree's (far-field bounds), and
// the full tree's value within float rounding wherever |f| < (C − 1)·R (R: the finest cells'
// half-diagonal), since such points always lie in near-field cells. Returns the samples that
// break one, reporting the first few.
size_t discretize_violations(const Scene& sc, const PruneOptions& o, gpu::Device& dev,
                             const gpu::Grid& gpu, uint32_t n) {
    std::vector<float> got(size_t(n) * n * n);
    gpu::discretize(dev, gpu, n, got);
    const vec3 extent = sc.aabb.max - sc.aabb.min;
    const float near_band = (o.far_field_c - 1) * 0.5f * math::length(extent / float(o.resolution));
    std::vector<float> stack(sc.max_stack + 1);
    size_t bad = 0;
    for (size_t i = 0; i < got.size(); ++i) {
        const vec3 p = sc.aabb.min +
                       vec3(float(i % n) + 0.5f, float(i / n % n) + 0.5f, float(i / n / n) + 0.5f) *
                           (extent / float(n));
        const float f = eval_tape(sc, sc.full_tape, p, stack.data()), g = got[i];
        const float tol = 1e-5f * (1 + std::fabs(f));
        const bool sign_flipped = (f > tol && g < -tol) || (f < -tol && g > tol);
        const bool overstated = std::fabs(g) > std::fabs(f) + tol;
        const bool inexact = std::fabs(f) < near_band - tol && std::fabs(g - f) > tol;
        if ((sign_flipped || overstated || inexact) && ++bad <= 3)
            ADD_FAILURE() << "n = " << n << ", sample " << i << ": full tree " << f << ", device "
                          << g;
    }
    return bad;
}

// Bit for bit the CPU's samples on an exact device; elsewhere what every device must give.
TEST(Gpu, DiscretizeMatchesCpu) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    RandomSceneSpec spec;
    spec.primitives = 16;
    spec.placement = Placement::kNonUniform;
    spec.plane_cut = true;
    const Scene sc = random_scene(5, spec);
    PruneOptions o;
    o.resolution = 32;
    const PrunedGrid cpu = prune(sc, o);
    const gpu::Grid gpu = gpu::prune(*dev, sc, o);
    for (uint32_t n : {32u, 20u, 48u}) {
        if (exact_device(*dev)) {
            EXPECT_EQ(discretize_mismatches(cpu, *dev, gpu, n), 0u) << "n = " << n;
        }
        EXPECT_EQ(discretize_violations(sc, o, *dev, gpu, n), 0u) << "n = " << n;
    }
}

// A right-deep chain of 3025 spheres on a slab needs a 3026-value stack on the full tree, but
// only tens on the finest cells' tapes (the slab, innermost in the chain, decides every far
// sphere away): the kernels' stacks are sized from those, and the images and samples still
// equal the CPU's. The box's top face cuts through the spheres, so rays entering the box inside
// one hit at once, and about half of those hit points round to just outside the box, where the
// CPU (PrunedField::tape_at) uses the full tree: those pixels go through the full-tree pass.
TEST(Gpu, StacksAreSizedFromThePrunedTapes) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    SceneBuilder b;
    Shape chain = b.box(vec3(2.2f, 2.2f, 0.2f)).translated(vec3(0, 0, -0.1f));
    constexpr uint32_t kSide = 55, kChain = kSide * kSide;
    for (uint32_t i = 0; i < kChain; ++i) {
        const vec3 at(-1 + 2 * float(i % kSide) / kSide, -1 + 2 * float(i / kSide) / kSide, 0);
        chain = smooth_union(b.sphere(0.03f).translated(at), chain, 0.02f);
    }
    const Scene sc = b.build(chain, Aabb{vec3(-1.2f, -1.2f, -0.3f), vec3(1.2f, 1.2f, 0.02f)});
    ASSERT_EQ(sc.max_stack, kChain + 1);
    PruneOptions o;
    o.resolution = 32;
    const PrunedGrid cpu = prune(sc, o);
    const gpu::Grid gpu = gpu::prune(*dev, sc, o);
    const bool exact = exact_device(*dev);
    expect_matches_cpu(sc, cpu, gpu, *dev, "chain of 3025 in a cut box");
    const uint32_t deepest = deepest_finest_stack(sc, gpu);
    ASSERT_GT(deepest, 1u);

    RenderOptions ro;
    ro.tile_cones = ro.convex_steps = false;  // the Vulkan renderer's steps
    ro.width = 96;
    ro.height = 64;
    ro.camera = orbit_camera(sc.aabb, 0, 0, 0, 40);  // looking down -z, at the cut face
    RenderStats cs, gs;
    const Image a = render(cpu, ro, &cs);
    const Image image = gpu::render(*dev, gpu, ro, &gs);
    if (exact)
        EXPECT_TRUE(a.rgb == image.rgb) << "the image differs from the CPU's";
    else
        expect_similar(a, image, "chain of 3025");
    EXPECT_EQ(cs.steps_avg, gs.steps_avg);
    EXPECT_GT(gs.hit_fraction, 0.05);
    // 4 words a value, for the deepest finest tape: far below the full tree's 3026 values.
    EXPECT_EQ(gs.stack_words, 4u * deepest);
    EXPECT_LT(gs.stack_words * 20, 4u * sc.max_stack) << "stack of " << gs.stack_words << " words";
    EXPECT_GT(gs.full_tree_pixels, 0u) << "no pixel went through the full-tree pass";

    // A deferred list of 8 items overflows: each chunk runs again with a longer one.
    RenderStats short_list;
    const Image again = [&] {
        const ScopedEnv short_deferred("SDFPRUNE_VULKAN_DEFERRED_LIST", "8");
        return gpu::render(*dev, gpu, ro, &short_list);
    }();
    EXPECT_TRUE(again.rgb == image.rgb);
    EXPECT_EQ(short_list.full_tree_pixels, gs.full_tree_pixels);

    const uint32_t n = 24;
    std::vector<float> want(size_t(n) * n * n), got(want.size());
    discretize_pruned(cpu, n, want);
    gpu::DiscretizeStats ds;
    gpu::discretize(*dev, gpu, n, got, &ds);
    EXPECT_EQ(ds.stack_words, gs.stack_words);
    EXPECT_EQ(ds.full_tree_samples, 0u);  // sample centres lie inside the box
    size_t bad = 0;
    for (size_t i = 0; i < want.size(); ++i)
        bad += exact ? (want[i] == got[i] ? 0 : 1)
                     : (std::fabs(want[i] - got[i]) <= 1e-6f * (1 + std::fabs(want[i])) ? 0 : 1);
    EXPECT_LE(bad, exact ? 0u : want.size() / 100);
}

// A device whose shaders address at most 1 MiB of one buffer: images and grids come back in
// many chunks and slices and still equal the CPU's; a grid too large for it is refused with a
// clear error instead of being addressed out of range.
TEST(Gpu, SmallBufferRangeSplitsTheWork) {
    if (!gpu::built_with_vulkan()) GTEST_SKIP() << "built without the Vulkan backend";
    std::unique_ptr<gpu::Device> small;
    {
        const ScopedEnv max_buffer("SDFPRUNE_VULKAN_MAX_BUFFER", "1048576");
        try {
            small = std::make_unique<gpu::Device>();
        } catch (const gpu::GpuError& e) {
            FAIL() << "no Vulkan device (install mesa-vulkan-drivers): " << e.what();
        }
    }
    RandomSceneSpec spec;
    spec.primitives = 24;
    spec.placement = Placement::kMixed;
    const Scene sc = random_scene(77, spec);
    PruneOptions o;
    o.resolution = 16;
    const PrunedGrid cpu = prune(sc, o);
    const gpu::Grid gpu = gpu::prune(*small, sc, o);
    expect_same_stats(cpu.stats(), gpu.stats(), "16^3 on a 1 MiB device", exact_device(*small));

    RenderOptions ro;
    ro.tile_cones = ro.convex_steps = false;  // the Vulkan renderer's steps
    ro.width = 256;                           // 49,152 pixels of 32 bytes: chunks of 32,768
    ro.height = 192;
    ro.camera = orbit_camera(sc.aabb, 35, 20, 0, 40);
    RenderStats cs, gs;
    ro.shading = Shading::kHeatmap;  // every pixel shows its own work, hit or miss
    const Image chunked = gpu::render(*small, gpu, ro, &gs);
    // The chunks give the image in one piece, as the same driver renders it whole, bit for bit;
    // and, where the driver rounds as the CPU does, the CPU's image. (Elsewhere a last-bit
    // difference moves a heat-map pixel's steps: on an H100, 108 of these 49,152 pixels, and
    // Gpu.RenderMatchesCpu bounds the difference of shaded images.)
    {
        SDFPRUNE_REQUIRE_DEVICE(dev);
        const Image whole = gpu::render(*dev, gpu::prune(*dev, sc, o), ro);
        EXPECT_TRUE(chunked.rgb == whole.rgb) << "the chunked image differs from the whole one";
    }
    const Image on_cpu = render(cpu, ro, &cs);
    if (exact_device(*small)) expect_similar(on_cpu, chunked, "chunked image");
    EXPECT_NEAR(cs.hit_fraction, gs.hit_fraction, 1e-3);
    EXPECT_NEAR(cs.steps_avg, gs.steps_avg, 0.01 * cs.steps_avg);
    EXPECT_GT(gs.hit_fraction, 0.0);

    // 729,000 values: 3 slices.
    EXPECT_LE(discretize_mismatches(cpu, *small, gpu, 90), exact_device(*small) ? 0u : 7290u);

    o.resolution = 256;
    const uint64_t held = small->memory_in_use();
    try {
        gpu::prune(*small, sc, o);
        ADD_FAILURE() << "256^3 cells cannot fit 1 MiB buffers, yet pruning succeeded";
    } catch (const gpu::GpuError& e) {
        EXPECT_NE(std::string(e.what()).find("lets a shader address"), std::string::npos)
            << e.what();
    }
    EXPECT_EQ(small->memory_in_use(), held) << "buffers left behind by the refused pruning";
    // The device is still usable after the refused step.
    o.resolution = 16;
    expect_same_stats(cpu.stats(), gpu::prune(*small, sc, o).stats(), "after the error");
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

TEST(GpuCli, StatsOnVulkanEqualCpu) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const CliResult cpu = run_cli("stats builtin:demo --grid 32 --json");
    const CliResult gpu = run_cli("stats builtin:demo --grid 32 --json --backend vulkan");
    ASSERT_EQ(cpu.status, 0) << cpu.err;
    ASSERT_EQ(gpu.status, 0) << gpu.err;
    const auto field = [](const std::string& json, const std::string& key) {
        const size_t at = json.find("\"" + key + "\":");
        return at == std::string::npos ? std::string("missing")
                                       : json.substr(at, json.find(',', at) - at);
    };
    // Elsewhere than lavapipe the figures may differ a little (see exact_device).
    for (const char* key :
         {"near_field_cells", "active_avg", "active_std", "active_max", "tape_avg", "tape_max"}) {
        if (exact_device(*dev))
            EXPECT_EQ(field(cpu.out, key), field(gpu.out, key)) << key;
        else
            EXPECT_NE(field(gpu.out, key), "missing") << key;
    }
    EXPECT_NE(gpu.out.find("\"backend\":\"vulkan\""), std::string::npos);
    EXPECT_NE(gpu.out.find("\"device\":"), std::string::npos);
    // With --repeat, the first call's figures beside the last's (bench/gpu_steps.sh reads
    // them), and each step's shape.
    const CliResult repeated =
        run_cli("stats builtin:demo --grid 32 --json --backend vulkan --repeat 2");
    ASSERT_EQ(repeated.status, 0) << repeated.err;
    for (const char* key :
         {"wall_ms", "submissions", "host_buffer_ms", "host_allocated_bytes", "host_submit_ms",
          "first_prune_ms", "first_wall_ms", "first_prune_peak_bytes", "first_submissions",
          "first_host_buffer_ms", "first_host_allocated_bytes", "first_host_submit_ms", "gpu_steps",
          "walked_words", "walked_sum_words", "taken"})
        EXPECT_NE(field(repeated.out, key), "missing") << key;
}

TEST(GpuCli, RenderAndDiscretizeOnVulkan) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    const std::string png = ::testing::TempDir() + "gpu_cli.png";
    const std::string npy = ::testing::TempDir() + "gpu_cli.npy";
    const CliResult r = run_cli(
        "render builtin:sphere --width 64 --height 48 --grid 32 --backend "
        "vulkan --json -o " +
        png);
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_TRUE(std::filesystem::file_size(png) > 100);
    const CliResult d =
        run_cli("discretize builtin:sphere --res 16 --backend vulkan --json -o " + npy);
    ASSERT_EQ(d.status, 0) << d.err;
    EXPECT_EQ(std::filesystem::file_size(npy), 128u + 16u * 16 * 16 * 4);
    std::remove(png.c_str());
    std::remove(npy.c_str());
}

TEST(GpuCli, BadBackendUseExitsTwo) {
    const CliResult bad = run_cli("stats builtin:sphere --backend metal");
    EXPECT_EQ(bad.status, 2);
    const CliResult naive = run_cli(
        "render builtin:sphere -o /tmp/x.png --method naive "
        "--backend vulkan");
    EXPECT_EQ(naive.status, 2);
    EXPECT_NE(naive.err.find("--backend vulkan"), std::string::npos) << naive.err;
    // No driver at all: the loader is pointed at a driver list that does not exist.
    const CliResult none = run_cli("stats builtin:sphere --grid 8 --backend vulkan",
                                   "VK_ICD_FILENAMES=/nonexistent.json "
                                   "VK_DRIVER_FILES=/nonexistent.json");
    EXPECT_EQ(none.status, 2);
    EXPECT_NE(none.err.find("Vulkan"), std::string::npos) << none.err;
    EXPECT_EQ(std::count(none.err.begin(), none.err.end(), '\n'), 1) << none.err;
    const CliResult cpu = run_cli("stats builtin:sphere --grid 8 --backend cpu");
    EXPECT_EQ(cpu.status, 0) << cpu.err;
}

// A device that runs out of memory while pruning (SDFPRUNE_VULKAN_MEMORY_LIMIT: one of 4 MB,
// with or without a reserve) gets a one-line message and exit status 2, not a crash, and no output
// file; render and discretize too. With the memory it needs, the same command succeeds.
TEST(GpuCli, DeviceOutOfMemoryExitsTwo) {
    if (!gpu::built_with_vulkan()) GTEST_SKIP() << "built without the Vulkan backend";
    const std::string png = "/tmp/sdfprune_oom_test.png", npy = "/tmp/sdfprune_oom_test.npy";
    const std::pair<std::string, std::string> commands[] = {
        {"stats builtin:demo --grid 32 --backend vulkan", ""},
        {"render builtin:demo --grid 32 --width 32 --height 32 --backend vulkan -o " + png, png},
        {"discretize builtin:demo --res 32 --grid 32 --backend vulkan -o " + npy, npy}};
    for (const auto& [command, output] : commands) {
        SCOPED_TRACE(command);
        if (!output.empty()) std::remove(output.c_str());
        // (With a reserve too: its room is no way past the limit.)
        for (const char* reserve : {"", " SDFPRUNE_VULKAN_RESERVE_BYTES=268435456"}) {
            const CliResult small =
                run_cli(command, std::string("SDFPRUNE_VULKAN_MEMORY_LIMIT=4000000") + reserve);
            EXPECT_EQ(small.status, 2) << reserve;
            EXPECT_NE(small.err.find("out of memory"), std::string::npos) << small.err;
            EXPECT_EQ(std::count(small.err.begin(), small.err.end(), '\n'), 1) << small.err;
            if (!output.empty()) {
                EXPECT_FALSE(std::filesystem::exists(output));
            }
        }
        const CliResult enough = run_cli(command);
        EXPECT_EQ(enough.status, 0) << enough.err;
        if (!output.empty()) {
            EXPECT_TRUE(std::filesystem::exists(output));
            std::remove(output.c_str());
        }
    }
}

}  // namespace
}  // namespace sdfprune::test
