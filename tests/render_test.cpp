// render_test.cpp — sphere tracing: pruned and naive renders agree, outputs and CLI errors.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "prune_check.hpp"
#include "sdfprune/builder.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/io.hpp"
#include "sdfprune/render.hpp"
#include "test_util.hpp"

namespace sdfprune {
namespace {

RenderOptions small_options(const Scene& sc, Shading shading = Shading::kShaded) {
    RenderOptions o;
    o.width = 160;
    o.height = 90;
    o.camera = orbit_camera(sc.aabb, 30, 25, 0, 40);
    o.shading = shading;
    return o;
}

// Fraction of pixels whose channels differ by more than `tolerance`.
double differing_fraction(const Image& a, const Image& b, int tolerance) {
    return double(test::pixels_differing(a, b, tolerance)) / double(a.rgb.size() / 3);
}

TEST(Render, PrunedAndNaiveAgreeOnDemo) {
    const Scene sc = builtin_scene("demo");
    for (const bool clearance : {false, true}) {  // with and without the far-field skips
        PruneOptions po;
        po.resolution = 128;
        po.clearance = clearance;
        const PrunedGrid g = prune(sc, po);
        for (Shading s : {Shading::kShaded, Shading::kNormals}) {
            RenderStats ps, ns;
            const Image pruned = render(g, small_options(sc, s), &ps);
            const Image naive = render_naive(sc, small_options(sc, s), &ns);
            EXPECT_LE(differing_fraction(pruned, naive, 8), 0.001) << clearance;
            EXPECT_GT(ps.hit_fraction, 0.05);
            EXPECT_DOUBLE_EQ(ps.hit_fraction, ns.hit_fraction) << clearance;
            // Pruning is what makes the difference in work.
            EXPECT_LT(ps.evals_avg * 5, ns.evals_avg);
        }
    }
}

// RenderOptions::tile_cones and convex_steps step only over space where no ray stops: against
// the plain sphere tracer's steps on the same grid, each alone and both, the image shows the
// same surfaces (a hit found a step earlier or later moves a few pixels' normals), with fewer
// steps. Random scenes of every placement (shears included) with smooth operators and cuts, and
// a lattice of thin rods and small balls narrower than a tile's cone where it meets them.
TEST(Render, TileConesAndConvexStepsKeepTheImage) {
    std::vector<Scene> scenes;
    // Five placements (varied_spec cycles through them), each with the first seed whose scene
    // covers 2 % of the image (an intersection may leave little to see: mostly unions).
    for (uint32_t i = 0; i < 5; ++i) {
        test::RandomSceneSpec spec = test::varied_spec(i, 24);
        spec.union_share = i % 2 ? 0.85f : 1.0f;
        for (uint64_t seed = 300; seed < 340; ++seed) {
            Scene sc = test::random_scene(seed, spec);
            RenderOptions probe = small_options(sc);
            probe.width = 48;
            probe.height = 27;
            RenderStats st;
            render_naive(sc, probe, &st);
            if (st.hit_fraction > 0.02) {
                scenes.push_back(std::move(sc));
                break;
            }
        }
        ASSERT_EQ(scenes.size(), i + 1) << "no scene of placement " << i << " to see";
    }
    {
        SceneBuilder b;
        Shape lattice = b.sphere(0.02f);
        for (int i = 0; i < 9; ++i)
            for (int j = 0; j < 3; ++j) {
                const vec3 at(-0.8f + 0.2f * float(i), -0.5f + 0.5f * float(j), 0.0f);
                lattice = lattice | b.cylinder(0.004f + 0.002f * float(i), 1.6f)
                                        .rotated({0, 0, 1}, 0.3f * float(j))
                                        .translated(at);
                lattice =
                    lattice | b.sphere(0.01f + 0.01f * float(j)).translated(at + vec3(0, 0, 0.4f));
            }
        scenes.push_back(b.build(lattice));
    }
    // Blocks of finest cells that hold both a floor's face (one convex primitive: convex steps
    // may run to such a block's exit only where every near-field cell of it is the floor's)
    // and a grain.
    scenes.push_back(test::grains_on_floor());
    for (size_t n = 0; n < scenes.size(); ++n) {
        const Scene& sc = scenes[n];
        PruneOptions po;
        po.resolution = 128;
        po.clearance = true;
        const PrunedGrid g = prune(sc, po);
        // Shaded: the shadow rays, which leave the surface, are compared too.
        RenderOptions plain = small_options(sc, Shading::kShaded);
        plain.width = 240;
        plain.height = 135;
        plain.tile_cones = plain.convex_steps = false;
        RenderStats ps;
        const Image base = render(g, plain, &ps);
        EXPECT_GT(ps.hit_fraction, 0.01) << "scene " << n;
        for (const int variant : {1, 2, 3}) {
            RenderOptions ro = plain;
            ro.tile_cones = variant & 1;
            ro.convex_steps = variant & 2;
            RenderStats st;
            const Image img = render(g, ro, &st);
            const std::string what = "scene " + std::to_string(n) +
                                     (ro.tile_cones ? ", tile cones" : "") +
                                     (ro.convex_steps ? ", convex steps" : "");
            EXPECT_LE(differing_fraction(img, base, 8), 0.003) << what;
            EXPECT_NEAR(st.hit_fraction, ps.hit_fraction, 0.001) << what;
            // (Cones alone save nothing where the surface fills the view, as the floor does.)
            EXPECT_LT(st.steps_avg, ps.steps_avg * (variant == 1 ? 1.01 : 1.0)) << what;
        }
    }
}

TEST(Render, HeatmapShowsEvaluationsAndLegend) {
    const Scene sc = builtin_scene("demo");
    PruneOptions po;
    po.resolution = 64;
    const PrunedGrid g = prune(sc, po);
    RenderStats st;
    const Image heat = render(g, small_options(sc, Shading::kHeatmap), &st);
    const Image shaded = render(g, small_options(sc, Shading::kShaded));
    EXPECT_GT(differing_fraction(heat, shaded, 8), 0.5);
    EXPECT_GT(st.evals_max, 0);
    // The legend's white labels sit in the bottom-right corner.
    int white = 0;
    for (uint32_t y = heat.height * 3 / 4; y < heat.height; ++y)
        for (uint32_t x = heat.width * 3 / 5; x < heat.width; ++x) {
            const uint8_t* p = &heat.rgb[3 * (size_t(y) * heat.width + x)];
            white += p[0] > 230 && p[1] > 230 && p[2] > 230;
        }
    EXPECT_GT(white, 10);
}

TEST(Render, SphereSilhouetteMatchesAnalyticDisc) {
    const Scene sc = builtin_scene("sphere");
    const PrunedGrid g = prune(sc, {});
    RenderOptions o = small_options(sc, Shading::kNormals);
    o.width = o.height = 101;
    o.camera.eye = {0, 0, 5};
    o.camera.target = {0, 0, 0};
    RenderStats st;
    render(g, o, &st);
    // A unit sphere at distance 5 seen with a 40° field of view covers a disc of angular radius
    // asin(1/5): its share of the square image is π·tan²(θ)/(2·tan(20°))².
    const double theta = std::asin(0.2), half = std::tan(20.0 * M_PI / 180);
    const double expected = M_PI * std::tan(theta) * std::tan(theta) / (4 * half * half);
    EXPECT_NEAR(st.hit_fraction, expected, 0.01);
}

TEST(Render, WritesPngAtomically) {
    const Scene sc = builtin_scene("sphere");
    const Image img = render_naive(sc, small_options(sc));
    const std::string path = ::testing::TempDir() + "render_test.png";
    write_png(img, path);
    std::ifstream in(path, std::ios::binary);
    char sig[8] = {};
    in.read(sig, 8);
    EXPECT_EQ(std::string(sig + 1, 3), "PNG");
    EXPECT_GT(std::filesystem::file_size(path), 100u);
    EXPECT_THROW(write_png(img, "/nonexistent-dir/x.png"), IoError);
    std::filesystem::remove(path);
}

TEST(RenderCli, JsonAndErrors) {
    const std::string out = ::testing::TempDir() + "render_cli.png";
    test::CliResult r = test::run_cli("render builtin:sphere -o " + out +
                                      " --width 64 --height 48 --json --grid 32");
    ASSERT_EQ(r.status, 0) << r.err;
    const std::string last = r.out.substr(r.out.rfind('{'));
    for (const char* key : {"\"prune_ms\"", "\"trace_ms\"", "\"width\":64", "\"height\":48",
                            "\"steps_avg\"", "\"evals_avg\""})
        EXPECT_NE(last.find(key), std::string::npos) << key;
    EXPECT_TRUE(std::filesystem::exists(out));
    std::filesystem::remove(out);

    r = test::run_cli("render builtin:sphere -o " + ::testing::TempDir() + "x.jpg");
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("extension"), std::string::npos);
    r = test::run_cli("render builtin:sphere -o /nonexistent-dir/x.png");
    EXPECT_EQ(r.status, 2);
    r = test::run_cli("render builtin:sphere -o " + out + " --target 1,2");
    EXPECT_EQ(r.status, 2);
    EXPECT_FALSE(std::filesystem::exists(out));
    r = test::run_cli("render builtin:sphere -o " + out + " --shading fancy");
    EXPECT_EQ(r.status, 2);
}

}  // namespace
}  // namespace sdfprune
