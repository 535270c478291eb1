// gpu_render_test.cpp — images and samples from the Vulkan backend's grids against the CPU's:
// rendering and discretizing (on lavapipe bit for bit), their stacks sized from the pruned tapes,
// the work split into chunks and slices on a device with a small buffer range, and the CLI's
// handling of --backend.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <initializer_list>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "gpu_check.hpp"
#include "prune_check.hpp"
#include "sdfprune/builder.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/discretize.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/gpu.hpp"
#include "sdfprune/prune.hpp"
#include "sdfprune/render.hpp"
#include "test_util.hpp"

namespace sdfprune::test {
namespace {

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

// Lavapipe ends an invocation's loops after 65,535 iterations in all, and the invocation goes on
// as if they had ended: an image whose pixels need more would come out wrong without a word.
// Such an image is refused (a GpuError; the CLI exits 2), also where lavapipe's pruning is
// planned as a GPU's (SDFPRUNE_VULKAN_LOOP_LIMITED=0): the limit is the device's, not the
// plan's. 3,000 equal spheres in a chain of unions: no operator is decided in any cell, so
// every near-field tape holds all 5,999 words. Pruning walks them within the limit, and so does
// a sample's one evaluation; a pixel's march evaluates the tape at every step, and does not.
// With 20,000, a hit pixel's first evaluation takes most of its iterations, its march ends at
// the limit as if it missed, and its count of evaluations stays below the limit: until the
// kernels probed the limit (slice.glsl), lavapipe's image showed no hit at all, without a word.
// 33,000 such spheres make tapes that not even one evaluation walks within the limit: tracing
// and discretizing refuse them before their kernels run (pruning these two takes lavapipe's
// plan, which resumes its steps over several dispatches).
TEST(Gpu, ImagesPastTheLoopLimitAreRefused) {
    SDFPRUNE_REQUIRE_DEVICE(dev);
    if (!is_lavapipe(*dev)) GTEST_SKIP() << dev->name() << " ends no loops";
    const auto equal_spheres = [](int count) {
        SceneBuilder b;
        Shape blob = b.sphere(0.5f);
        for (int i = 1; i < count; ++i) blob = blob | b.sphere(0.5f);
        return b.build(blob);
    };
    // The GpuError's message, or "made" where none is thrown.
    const auto error_of = [](const std::function<void()>& run) {
        try {
            run();
        } catch (const gpu::GpuError& e) {
            return std::string(e.what());
        }
        return std::string("made");
    };
    RenderOptions ro;
    ro.width = ro.height = 16;
    std::vector<float> samples(8 * 8 * 8);
    // The grid's tapes unpruned, the image refused with `expected`; the samples, where they fit
    // the limit, the CPU's (on lavapipe bit for bit).
    const auto check = [&](gpu::Device& d, const Scene& sc, uint32_t grid,
                           const std::string& expected, bool samples_fit) {
        SCOPED_TRACE(std::to_string(sc.size()) + " nodes, " + std::to_string(grid) + "³");
        PruneOptions o;
        o.resolution = grid;
        o.refine = 1;
        const gpu::Grid pruned = gpu::prune(d, sc, o);
        ASSERT_EQ(pruned.stats().tape_max, sc.size()) << "a tape was pruned";
        ro.camera = orbit_camera(sc.aabb, 30, 20, 0, 40);
        const std::string traced = error_of([&] { gpu::render(d, pruned, ro); });
        EXPECT_NE(traced.find(expected), std::string::npos) << "tracing: " << traced;
        if (samples_fit) {
            EXPECT_LE(discretize_mismatches(prune(sc, o), d, pruned, 8),
                      exact_device(d) ? size_t(0) : samples.size());
        } else {
            const std::string sampled = error_of([&] { gpu::discretize(d, pruned, 8, samples); });
            EXPECT_NE(sampled.find(expected), std::string::npos) << "discretizing: " << sampled;
        }
    };
    for (const bool planned_as_a_gpu : {false, true}) {
        SCOPED_TRACE(planned_as_a_gpu ? "planned as a GPU" : "planned for lavapipe");
        // (As the ctest Gpu.planned_as_a_gpu plans it, the jobs dealt; lavapipe's own plan
        // otherwise. The device reads some of these as it opens, the pruning the others.)
        const ScopedEnv plan(planned_as_a_gpu
                                 ? EnvSettings{{"SDFPRUNE_VULKAN_LOOP_LIMITED", "0"},
                                               {"SDFPRUNE_VULKAN_RESIDENT_THREADS", "270336"},
                                               {"SDFPRUNE_VULKAN_TAKE", "0"},
                                               {"SDFPRUNE_VULKAN_WIDE_TAKE", "0"}}
                                 : EnvSettings{{"SDFPRUNE_VULKAN_LOOP_LIMITED", ""}});
        gpu::Device d;
        ASSERT_EQ(d.loop_limited(), !planned_as_a_gpu);
        check(d, equal_spheres(3000), 16, "loop iterations per pixel", true);
        if (planned_as_a_gpu) continue;
        check(d, equal_spheres(20000), 4, "loop iterations per pixel", true);
        check(d, equal_spheres(33000), 4, "exceed the loop limit", false);
    }
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
