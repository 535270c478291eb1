// generate_test.cpp — the procedural stand-ins for the paper's scenes: node counts against the
// paper's Table 1, determinism, round trips through the scene format, the operators and tree
// shapes each subject implies, --count scaling, non-empty surfaces, and the CLI.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <map>
#include <set>

#include "sdfprune/eval.hpp"
#include "sdfprune/generate.hpp"
#include "sdfprune/io.hpp"
#include "sdfprune/prune.hpp"
#include "test_util.hpp"

namespace sdfprune {
namespace {

// #N of the paper's Table 1 (../shared/paper/table1.csv), by generator kind.
const std::map<std::string, uint32_t> kPaperNodes = {
    {"camera", 119},        {"car", 117},       {"car-chase", 560}, {"character", 43},
    {"city", 691},          {"console", 61},    {"crowd", 1989},    {"fluid", 27977},
    {"gameboy", 65},        {"molecule", 1999}, {"monument", 6023}, {"raccoon", 53},
    {"train-station", 119}, {"trees", 369}};

// Generated once per process: the default scene of every kind, seed 1.
const std::map<std::string, Scene>& defaults() {
    static const std::map<std::string, Scene> scenes = [] {
        std::map<std::string, Scene> m;
        for (const std::string& k : generator_kinds()) m.emplace(k, generate_scene(k, 1, 0));
        return m;
    }();
    return scenes;
}

TEST(Generate, KindsAreThePapersScenes) {
    std::set<std::string> kinds;
    for (const GeneratorInfo& g : generator_info()) {
        kinds.insert(g.kind);
        ASSERT_TRUE(kPaperNodes.count(g.kind)) << g.kind;
        EXPECT_EQ(g.paper_nodes, kPaperNodes.at(g.kind)) << g.kind;
        EXPECT_FALSE(g.summary.empty());
    }
    EXPECT_EQ(kinds.size(), kPaperNodes.size());
    EXPECT_EQ(generator_kinds().size(), kPaperNodes.size());
}

TEST(Generate, NodeCountsWithinFivePercentOfThePaper) {
    for (const auto& [kind, sc] : defaults()) {
        const double paper = kPaperNodes.at(kind);
        EXPECT_LE(std::fabs(double(sc.size()) - paper), 0.05 * paper)
            << kind << ": " << sc.size() << " nodes, paper " << paper;
        EXPECT_EQ(sc.size(), 2 * sc.primitive_count() - 1) << kind;  // binary trees
        for (const GeneratorInfo& g : generator_info()) {
            if (g.kind == kind) {
                EXPECT_EQ(sc.primitive_count(), g.default_count) << kind;
            }
        }
    }
}

TEST(Generate, DeterministicForASeed) {
    for (const std::string& kind : generator_kinds()) {
        const std::string a = scene_to_json(defaults().at(kind));
        EXPECT_TRUE(a == scene_to_json(generate_scene(kind, 1, 0)))
            << kind << ": not deterministic";
        const std::string other = scene_to_json(generate_scene(kind, 2, 0));
        EXPECT_FALSE(a == other) << kind << ": seed 2 gives the same scene as seed 1";
    }
}

TEST(Generate, RoundTripsThroughTheSceneFormat) {
    for (const auto& [kind, sc] : defaults()) {
        const std::string json = scene_to_json(sc);
        const Scene back = parse_scene(json, kind);
        ASSERT_EQ(back.size(), sc.size()) << kind;
        EXPECT_EQ(back.kind, sc.kind) << kind;
        EXPECT_EQ(back.left, sc.left) << kind;
        EXPECT_EQ(back.blend, sc.blend) << kind;
        EXPECT_EQ(back.shape, sc.shape) << kind;
        EXPECT_EQ(back.color, sc.color) << kind;
        EXPECT_EQ(back.aabb.min, sc.aabb.min) << kind;
        EXPECT_EQ(back.aabb.max, sc.aabb.max) << kind;
        for (uint32_t p = 0; p < sc.primitive_count(); p += 7)
            for (int r = 0; r < 3; ++r)
                EXPECT_EQ((&back.params[p].row0)[r], (&sc.params[p].row0)[r])
                    << kind << " primitive " << p;
        EXPECT_TRUE(scene_to_json(back) == json)
            << kind << ": the file does not read back the same";
    }
}

TEST(Generate, OperatorsFitTheSubjects) {
    std::map<std::string, SceneInfo> info;
    for (const auto& [kind, sc] : defaults()) info[kind] = scene_info(sc);
    // Windows and holes are differences.
    for (const char* k :
         {"city", "camera", "console", "gameboy", "car", "monument", "train-station"})
        EXPECT_GT(info[k].differences, 0u) << k;
    // Organic shapes blend smoothly; the character is capsules and spheres only.
    for (const char* k : {"character", "raccoon", "crowd", "molecule", "fluid", "trees"})
        EXPECT_GT(info[k].smooth_operators, info[k].operators / 3) << k;
    const SceneInfo& ch = info["character"];
    EXPECT_EQ(ch.per_primitive_kind[math::kPrimSphere] + ch.per_primitive_kind[math::kPrimCapsule],
              ch.primitives);
    // Intersections somewhere: slopes, domes, rounded towers, rocks.
    for (const char* k : {"camera", "car", "city", "console", "monument", "trees", "train-station"})
        EXPECT_GT(info[k].intersections, 0u) << k;
    // Hard and smooth CSG mixed within a scene.
    for (const char* k : {"character", "console", "camera", "car", "city", "crowd", "monument"}) {
        EXPECT_GT(info[k].smooth_operators, 0u) << k;
        EXPECT_LT(info[k].smooth_operators, info[k].operators) << k;
    }
    // Varied primitives: every kind appears across the set, several within each hard-surface
    // scene; the particle scenes are spheres.
    uint32_t all[math::kPrimitiveKindCount] = {};
    for (const auto& [kind, i] : info) {
        uint32_t kinds = 0;
        for (uint32_t p = 0; p < math::kPrimitiveKindCount; ++p) {
            all[p] += i.per_primitive_kind[p];
            kinds += i.per_primitive_kind[p] > 0;
        }
        if (kind == "fluid" || kind == "molecule") {
            EXPECT_EQ(i.per_primitive_kind[math::kPrimSphere], i.primitives) << kind;
        } else if (kind != "character") {
            EXPECT_GE(kinds, 3u) << kind;
        }
    }
    // The generators' kinds: sphere to torus (the later kinds are not used by any generator).
    for (uint32_t p = 0; p <= math::kPrimTorus; ++p)
        EXPECT_GT(all[p], 0u) << primitive_kind_name(p);
}

TEST(Generate, TreeShapes) {
    // Chains where the subject is a chain, balanced trees for the big scenes.
    const SceneInfo molecule = scene_info(defaults().at("molecule"));
    EXPECT_EQ(molecule.depth, molecule.primitives - 1);  // one left-deep chain of atoms
    const SceneInfo trees = scene_info(defaults().at("trees"));
    EXPECT_GT(trees.depth, 30u);
    for (const char* k : {"fluid", "crowd", "city", "monument"}) {
        const SceneInfo i = scene_info(defaults().at(k));
        const double log2n = std::log2(double(i.primitives));
        EXPECT_LT(i.depth, (k == std::string("fluid") ? 1.1 : 3.0) * log2n + 24) << k;
    }
    const SceneInfo fluid = scene_info(defaults().at("fluid"));
    EXPECT_EQ(fluid.depth, uint32_t(std::ceil(std::log2(double(fluid.primitives)))));
}

TEST(Generate, CountScalesToExactPrimitives) {
    for (const char* k : {"fluid", "molecule", "crowd", "city"}) {
        const Scene sc = generate_scene(k, 3, 20000);
        EXPECT_EQ(sc.primitive_count(), 20000u) << k;
        EXPECT_EQ(sc.size(), 39999u) << k;
    }
    // Rings of at most 1000 atoms: 20 chains under a balanced union.
    EXPECT_LT(scene_info(generate_scene("molecule", 1, 20000)).depth, 1010u);
    for (const GeneratorInfo& g : generator_info()) {
        if (!g.scalable) {
            EXPECT_THROW(generate_scene(g.kind, 1, 500), SceneError) << g.kind;
            continue;
        }
        EXPECT_EQ(generate_scene(g.kind, 1, g.min_count).primitive_count(), g.min_count) << g.kind;
        EXPECT_THROW(
            generate_scene(g.kind, 1,
                           g.min_count - 1 == 0 ? kMaxGeneratedPrimitives + 1 : g.min_count - 1),
            SceneError)
            << g.kind;
        EXPECT_THROW(generate_scene(g.kind, 1, kMaxGeneratedPrimitives + 1), SceneError) << g.kind;
    }
    EXPECT_THROW(generate_scene("spaceship", 1, 0), SceneError);
    // Small counts of every scalable kind, odd sizes included.
    for (uint32_t n : {101u, 257u, 1001u, 2999u})
        for (const char* k : {"fluid", "molecule", "crowd", "city"})
            EXPECT_EQ(generate_scene(k, n, n).primitive_count(), n) << k << " " << n;
}

TEST(Generate, SurfacesAreInsideTheirBoxesAndNotEmpty) {
    for (const auto& [kind, sc] : defaults()) {
        // Outside on the AABB's boundary: the box holds the whole surface.
        const vec3 lo = sc.aabb.min, hi = sc.aabb.max;
        std::vector<vec3> pts;
        for (int i = 0; i <= 8; ++i)
            for (int j = 0; j <= 8; ++j) {
                const float u = float(i) / 8, v = float(j) / 8;
                for (int axis = 0; axis < 3; ++axis)
                    for (float side : {0.0f, 1.0f}) {
                        vec3 p;
                        p[axis] = side;
                        p[(axis + 1) % 3] = u;
                        p[(axis + 2) % 3] = v;
                        pts.push_back(lo + (hi - lo) * p);
                    }
            }
        std::vector<float> d(pts.size());
        eval_points(sc, pts, d);
        for (size_t i = 0; i < pts.size(); ++i) EXPECT_GT(d[i], 0.0f) << kind << " point " << i;

        // Pruned at grid 32: some finest cells hold the surface, others are culled.
        PruneOptions o;
        o.resolution = 32;
        const PrunedGrid g = prune(sc, o);
        EXPECT_GT(g.stats().near_field_cells, 50u) << kind;
        EXPECT_LT(g.stats().near_field_cells, g.stats().cells) << kind;
    }
}

TEST(GenerateCli, WritesInfoReadsAndErrors) {
    const std::string out = ::testing::TempDir() + "generate_cli_car.json";
    test::CliResult r = test::run_cli("generate car -o " + out + " --json");
    ASSERT_EQ(r.status, 0) << r.err;
    const std::string last = r.out.substr(r.out.rfind('{'));
    for (const char* key : {"\"kind\":\"car\"", "\"seed\":1", "\"count\":0", "\"nodes\":117",
                            "\"primitives\":59", "\"path\"", "\"ms\""})
        EXPECT_NE(last.find(key), std::string::npos) << key << " in " << last;
    EXPECT_TRUE(scene_to_json(load_scene(out)) == scene_to_json(generate_scene("car", 1, 0)));
    r = test::run_cli("info " + out + " --json");
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("\"nodes\":117"), std::string::npos) << r.out;

    // Seed and count reach the generator.
    r = test::run_cli("generate crowd --seed 5 --count 300 -o " + out + " --json");
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("\"primitives\":300"), std::string::npos) << r.out;
    EXPECT_TRUE(scene_to_json(load_scene(out)) == scene_to_json(generate_scene("crowd", 5, 300)));
    std::filesystem::remove(out);

    // builtin:KIND reaches the generators too.
    r = test::run_cli("info builtin:gameboy --json");
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("\"nodes\":65"), std::string::npos) << r.out;

    // Bad input: exit 2, nothing written.
    r = test::run_cli("generate spaceship -o " + out);
    EXPECT_EQ(r.status, 2);
    r = test::run_cli("generate car -o " + ::testing::TempDir() + "car.txt");
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("extension"), std::string::npos) << r.err;
    r = test::run_cli("generate car -o /nonexistent-dir/car.json");
    EXPECT_EQ(r.status, 2);
    r = test::run_cli("generate car --count 10 -o " + out);
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("fixed size"), std::string::npos) << r.err;
    r = test::run_cli("generate fluid --count 5 -o " + out);
    EXPECT_EQ(r.status, 2);
    EXPECT_FALSE(std::filesystem::exists(out));
    r = test::run_cli("generate --help");
    EXPECT_EQ(r.status, 0);
    for (const std::string& k : generator_kinds()) EXPECT_NE(r.out.find(k), std::string::npos) << k;
}

}  // namespace
}  // namespace sdfprune
