// prune_property_test.cpp — property tests of Lipschitz pruning (DESIGN.md §3–5) over many random
// CSG scenes: near-field tapes return the full tree's value, far-field constants are conservative,
// cells near the surface are never culled, ablations and thread counts do not change values.
#include <gtest/gtest.h>

#include <cstring>
#include <sstream>

#include "prune_check.hpp"
#include "sdfprune/builder.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/generate.hpp"
#include "sdfprune/prune.hpp"
#include "src/prune/prune_level.hpp"

namespace sdfprune {
namespace {

using test::Failures;
using test::PointStats;
using test::RandomSceneSpec;

// Scene `i` of the property suite: the tree shape, the placement kind and the share of smooth
// operators cycle with different periods so that every combination occurs.
RandomSceneSpec property_spec(uint32_t i) {
    RandomSceneSpec s;
    Rng r(1000 + i);
    s.tree = test::TreeShape(i % 4);
    s.placement = test::Placement((i / 4) % 5);
    const float smooth[3] = {0.0f, 0.5f, 1.0f};
    s.smooth_prob = smooth[i % 3];
    s.primitives = i % 10 == 0 ? 1 + i % 3 : 2 + uint32_t(r.uniform() * 40.0f);
    s.subtree_place = i % 2 ? 0.25f : 0.0f;
    s.clip_aabb = i % 7 == 6;
    s.plane_cut = i % 5 == 3;
    return s;
}

std::string describe(uint32_t i, const RandomSceneSpec& s, const PruneOptions& o) {
    std::ostringstream os;
    os << "scene " << i << " (" << s.primitives << " primitives, " << test::tree_shape_name(s.tree)
       << ", " << test::placement_name(s.placement) << ", smooth " << s.smooth_prob
       << (s.clip_aabb ? ", clipped AABB" : "") << (s.plane_cut ? ", cut by a plane" : "")
       << "), grid " << o.resolution << " factor " << o.factor << " C " << o.far_field_c
       << (o.bounds == CellBounds::kInterval ? " interval" : " lipschitz")
       << (o.far_field ? "" : " no-far-field") << (o.hierarchy ? "" : " no-hierarchy");
    return os.str();
}

// 1. Near-field cells give the full tree's value, far-field constants are conservative, for
// both cell bounds, over 60 random scenes with every primitive, operator, tree shape and
// placement; resolutions, subdivision factors and far-field C vary with the scene.
TEST(PruneProperty, RandomScenesMatchFullTree) {
    constexpr uint32_t kScenes = 60;
    const uint32_t resolutions[] = {16, 32, 64, 48, 24, 27, 20, 40};
    const uint32_t factors[] = {4, 4, 2, 3, 8};
    const float cs[] = {2.0f, 2.0f, 1.0f, 1.5f, 3.0f, 2.0f};
    uint64_t near = 0, far = 0, bitwise = 0, total_failures = 0;
    uint32_t prim_kinds[math::kPrimitiveKindCount] = {};
    uint32_t unions = 0, inters = 0, diffs = 0, smooth = 0, hard = 0, deep = 0;
    for (uint32_t i = 0; i < kScenes; ++i) {
        const RandomSceneSpec spec = property_spec(i);
        const Scene sc = test::random_scene(77 + i, spec);
        const SceneInfo info = scene_info(sc);
        for (uint32_t k = 0; k < math::kPrimitiveKindCount; ++k)
            prim_kinds[k] += info.per_primitive_kind[k];
        unions += info.unions;
        inters += info.intersections;
        diffs += info.differences;
        smooth += info.smooth_operators;
        hard += info.operators - info.smooth_operators;
        if (info.depth + 1 >= info.primitives && info.primitives > 8) ++deep;
        for (const CellBounds bounds : {CellBounds::kInterval, CellBounds::kLipschitz}) {
            PruneOptions o;
            o.resolution = resolutions[i % 8];
            o.factor = factors[i % 5];
            o.far_field_c = cs[i % 6];
            o.bounds = bounds;
            const PrunedGrid g = prune(sc, o);
            Failures fail(describe(i, spec, o));
            ASSERT_EQ(g.resolution(), o.resolution) << fail.context();
            Rng r(5000 + i);
            const std::vector<vec3> pts = test::sample_points(g, r, 2000, 2000, 500);
            const PointStats st = test::check_points(g, pts, fail);
            near += st.near;
            far += st.far;
            bitwise += st.bitwise;
            total_failures += fail.count();
            EXPECT_EQ(fail.count(), 0u) << fail.context();
        }
    }
    EXPECT_EQ(total_failures, 0u);
    // The suite really covers what it claims.
    for (uint32_t k = 0; k < math::kPrimitiveKindCount; ++k)
        EXPECT_GT(prim_kinds[k], 10u) << primitive_kind_name(k);
    EXPECT_GT(unions, 50u);
    EXPECT_GT(inters, 20u);
    EXPECT_GT(diffs, 20u);
    EXPECT_GT(smooth, 50u);
    EXPECT_GT(hard, 50u);
    EXPECT_GT(deep, 5u);  // left- and right-deep chains
    EXPECT_GT(near, 50000u);
    EXPECT_GT(far, 20000u);
    RecordProperty("near_points", std::to_string(near));
    RecordProperty("near_points_bitwise_equal", std::to_string(bitwise));
    RecordProperty("far_points", std::to_string(far));
}

// Checks, for every finest cell, that |f(centre)| < (C − 1)·R implies near-field, where R is the
// half-diagonal, whatever the scene's Lipschitz bounds (far_field_clearance). Returns the number
// of cells the premise held for.
uint64_t check_near_surface_cells(const PrunedGrid& g, Failures& fail) {
    const Scene& sc = g.scene();
    const uint32_t N = g.resolution();
    const float R = math::length(g.cell_size()) * 0.5f;
    const float threshold = (g.options().far_field_c - 1.0f) * R;
    std::vector<vec3> centres;
    centres.reserve(size_t(N) * N * N);
    for (uint32_t z = 0; z < N; ++z)
        for (uint32_t y = 0; y < N; ++y)
            for (uint32_t x = 0; x < N; ++x) centres.push_back(g.cell_center(x, y, z));
    std::vector<float> f(centres.size());
    eval_points(sc, centres, f);
    uint64_t premise = 0;
    size_t i = 0;
    for (uint32_t z = 0; z < N; ++z)
        for (uint32_t y = 0; y < N; ++y)
            for (uint32_t x = 0; x < N; ++x, ++i) {
                if (!(std::fabs(f[i]) < threshold)) continue;
                ++premise;
                const CellView cv = g.cell(x, y, z);
                if (cv.far_field)
                    fail.add([&](std::ostream& os) {
                        os << "cell (" << x << "," << y << "," << z
                           << ") with |f(centre)| = " << std::fabs(f[i]) << " < " << threshold
                           << " is far-field (constant " << cv.constant << ")";
                    });
            }
    return premise;
}

// 2. With the default C = 2, every finest cell whose centre is nearer the surface than the
// cell's half-diagonal is near-field (rigid scenes: exact distances, L = 1).
TEST(PruneProperty, CellsNearTheSurfaceAreNearField) {
    uint64_t premise = 0;
    for (uint32_t i = 0; i < 16; ++i) {
        RandomSceneSpec spec = property_spec(i);
        spec.placement = test::Placement::kRigid;
        const Scene sc = test::random_scene(300 + i, spec);
        const float lmin = test::min_primitive_lipschitz(sc);
        ASSERT_NEAR(lmin, 1.0f, 1e-5f);
        for (const CellBounds bounds : {CellBounds::kInterval, CellBounds::kLipschitz}) {
            PruneOptions o;
            o.resolution = i % 2 ? 32 : 24;
            o.bounds = bounds;
            const PrunedGrid g = prune(sc, o);
            Failures fail(describe(i, spec, o));
            premise += check_near_surface_cells(g, fail);
            EXPECT_EQ(fail.count(), 0u) << fail.context();
        }
    }
    EXPECT_GT(premise, 1000u);
}

// The same guarantee under scaled and sheared placements, whatever their Lipschitz bounds: cells
// with |f(centre)| < (C − 1)·R are near-field, for C = 2 and C = 3.
TEST(PruneProperty, CellsNearTheSurfaceAreNearFieldUnderScaling) {
    uint64_t premise = 0;
    for (uint32_t i = 0; i < 12; ++i) {
        RandomSceneSpec spec = property_spec(i);
        spec.placement = test::Placement(1 + i % 4);
        const Scene sc = test::random_scene(400 + i, spec);
        for (const CellBounds bounds : {CellBounds::kInterval, CellBounds::kLipschitz}) {
            PruneOptions o;
            o.resolution = 24;
            o.bounds = bounds;
            o.far_field_c = i % 3 == 2 ? 3.0f : 2.0f;
            const PrunedGrid g = prune(sc, o);
            Failures fail(describe(i, spec, o));
            premise += check_near_surface_cells(g, fail);
            EXPECT_EQ(fail.count(), 0u) << fail.context();
        }
    }
    EXPECT_GT(premise, 500u);
}

// Compares two grids of the same scene and resolution at points: where both cells are
// near-field, their tapes give the same value (and the full tree's). Returns points compared.
uint64_t compare_near_values(const PrunedGrid& a, const PrunedGrid& b, std::span<const vec3> pts,
                             Failures& fail, uint64_t& bitwise) {
    const Scene& sc = a.scene();
    std::vector<float> stack(sc.max_stack + 1);
    uint64_t compared = 0;
    for (const vec3& p : pts) {
        uint32_t x, y, z, x2, y2, z2;
        if (!a.cell_index(p, x, y, z) || !b.cell_index(p, x2, y2, z2)) {
            fail.add([&](std::ostream& os) { os << "cell_index false at " << test::str(p); });
            continue;
        }
        if (x != x2 || y != y2 || z != z2) {
            fail.add([&](std::ostream& os) {
                os << "grids place " << test::str(p) << " in different cells";
            });
            continue;
        }
        const CellView ca = a.cell(x, y, z), cb = b.cell(x, y, z);
        if (ca.far_field || cb.far_field) continue;
        ++compared;
        const float va = eval_tape(sc, ca.tape, p, stack.data());
        const float vb = eval_tape(sc, cb.tape, p, stack.data());
        const float f = eval_tape(sc, sc.full_tape, p, stack.data());
        if (va == vb) ++bitwise;
        if (!test::within_rel(va, vb) || !test::within_rel(va, f))
            fail.add([&](std::ostream& os) {
                os << "near-field values differ at " << test::str(p) << ": " << va << " vs " << vb
                   << " (full " << f << ")";
            });
    }
    return compared;
}

// 3. The ablations (no far-field culling, no hierarchy, factor 2 or 8 instead of 4, the paper's
// Lipschitz bounds) give the same values as the default in cells near-field in both.
TEST(PruneProperty, AblationsAgreeInNearFieldCells) {
    uint64_t compared = 0, bitwise = 0;
    for (uint32_t i = 0; i < 16; ++i) {
        const RandomSceneSpec spec = property_spec(i + 3);
        const Scene sc = test::random_scene(600 + i, spec);
        PruneOptions base;
        base.resolution = i % 2 ? 32 : 16;
        const PrunedGrid g = prune(sc, base);
        Rng r(700 + i);
        const std::vector<vec3> pts = test::sample_points(g, r, 600, 900, 100);

        PruneOptions no_far = base;
        no_far.far_field = false;
        PruneOptions no_hier = base;
        no_hier.hierarchy = false;
        PruneOptions f2 = base;
        f2.factor = 2;
        PruneOptions f8 = base;
        f8.factor = 8;
        PruneOptions lip = base;
        lip.bounds = CellBounds::kLipschitz;
        PruneOptions no_hier_lip = no_hier;
        no_hier_lip.bounds = CellBounds::kLipschitz;
        for (const PruneOptions& o : {no_far, no_hier, f2, f8, lip, no_hier_lip}) {
            const PrunedGrid h = prune(sc, o);
            Failures fail(describe(i, spec, o) + " vs default");
            ASSERT_EQ(h.level_count(), grid_levels(o.resolution, o.factor, o.hierarchy).size());
            compared += compare_near_values(g, h, pts, fail, bitwise);
            if (!o.far_field) {
                // Every cell holds a tape; they are exact everywhere, far from the surface too.
                EXPECT_EQ(h.stats().near_field_cells, h.stats().cells) << fail.context();
                const PointStats st = test::check_points(h, pts, fail);
                EXPECT_EQ(st.far, 0u) << fail.context();
            }
            if (!o.hierarchy) {
                EXPECT_EQ(h.level_count(), 1u) << fail.context();
            }
            EXPECT_EQ(fail.count(), 0u) << fail.context();
        }
    }
    EXPECT_GT(compared, 20000u);
    RecordProperty("compared", std::to_string(compared));
    RecordProperty("bitwise_equal", std::to_string(bitwise));
}

// Field-by-field equality of two grids' raw structures.
void expect_same_structure(const PrunedGrid& a, const PrunedGrid& b, const std::string& what) {
    ASSERT_EQ(a.level_count(), b.level_count()) << what;
    const auto pa = a.tape_pool(), pb = b.tape_pool();
    ASSERT_EQ(pa.size(), pb.size()) << what;
    EXPECT_EQ(std::memcmp(pa.data(), pb.data(), pa.size_bytes()), 0)
        << what << ": tape pools differ";
    for (uint32_t l = 0; l < a.level_count(); ++l) {
        EXPECT_EQ(a.level_resolution(l), b.level_resolution(l)) << what;
        const auto ca = a.level_cells(l), cb = b.level_cells(l);
        ASSERT_EQ(ca.size(), cb.size()) << what << " level " << l;
        uint64_t differ = 0;
        for (size_t i = 0; i < ca.size(); ++i) {
            const bool same = ca[i].tape == cb[i].tape && ca[i].children == cb[i].children &&
                              std::memcmp(&ca[i].value, &cb[i].value, sizeof(float)) == 0 &&
                              std::memcmp(&ca[i].bound, &cb[i].bound, sizeof(float)) == 0;
            differ += same ? 0 : 1;
        }
        EXPECT_EQ(differ, 0u) << what << ": cells of level " << l << " differ";
    }
    const PruneStats &sa = a.stats(), &sb = b.stats();
    test::expect_same_prune_stats(sa, sb, what);
    EXPECT_EQ(sa.cells_pruned, sb.cells_pruned) << what;
    EXPECT_EQ(sa.tape_words_visited, sb.tape_words_visited) << what;
    EXPECT_EQ(sa.tape_bytes, sb.tape_bytes) << what;
}

// 4. The output does not depend on the thread count (fixed chunks, merged in order).
TEST(PruneProperty, ThreadCountDoesNotChangeOutput) {
    for (uint32_t i = 0; i < 5; ++i) {
        RandomSceneSpec spec = property_spec(i + 1);
        spec.primitives = 30 + i * 5;
        spec.union_share = 0.9f;  // a large surface: many near-field cells
        const Scene sc = test::random_scene(800 + i, spec);
        PruneOptions o;
        o.resolution = 64;
        o.bounds = i % 2 ? CellBounds::kLipschitz : CellBounds::kInterval;
        o.far_field = i != 4;
        o.threads = 1;
        const PrunedGrid one = prune(sc, o);
        ASSERT_GT(one.level_cells(one.level_count() - 1).size(), 4096u)
            << "the finest level should span several parallel chunks";
        for (const int threads : {0, 2}) {
            o.threads = threads;
            const PrunedGrid g = prune(sc, o);
            expect_same_structure(
                one, g,
                "scene " + std::to_string(i) + ", threads " + std::to_string(threads) + " vs 1");
        }
    }
}

// A parent buffer's pages that no chunk still to run reads are handed back while pruning goes
// on (set_parent_discard_bytes). Handing them back at every chunk, one page at a time, changes
// no cell, tape or count, and the grid stays exact: no block read a page after it went back.
TEST(PruneProperty, ParentPagesHandedBackEarlyChangeNothing) {
    const Scene sc = generate_scene("fluid", 3, 4000);
    PruneOptions o;
    o.resolution = 128;
    o.threads = 2;
    const uint64_t saved = set_parent_discard_bytes(~uint64_t(0));  // never
    const PrunedGrid kept = prune(sc, o);
    set_parent_discard_bytes(1);  // at every chunk
    const uint64_t before = discarded_parent_bytes();
    const PrunedGrid early = prune(sc, o);
    const uint64_t handed_back = discarded_parent_bytes() - before;
    set_parent_discard_bytes(saved);
#if defined(__linux__)
    EXPECT_GT(handed_back, uint64_t(1) << 20) << "the test should hand back pages";
#endif
    expect_same_structure(kept, early, "fluid of 4000 spheres, pages handed back early");
    Failures fail("fluid of 4000 spheres, pages handed back early");
    Rng r(77);
    test::check_points(early, test::sample_points(early, r, 2000, 4000, 1000), fail);
    EXPECT_EQ(fail.count(), 0u) << fail.context();
}

// Unusual resolutions: a single cell, resolutions that do not split evenly, and every factor.
TEST(PruneProperty, SmallAndUnevenResolutions) {
    const Scene sc = test::random_scene(901, property_spec(5));
    for (uint32_t res = 1; res <= 10; ++res) {
        for (uint32_t factor = 2; factor <= 4; ++factor) {
            PruneOptions o;
            o.resolution = res;
            o.factor = factor;
            const PrunedGrid g = prune(sc, o);
            const std::vector<uint32_t> levels = grid_levels(res, factor);
            ASSERT_EQ(g.level_count(), levels.size());
            for (uint32_t l = 0; l < g.level_count(); ++l)
                EXPECT_EQ(g.level_resolution(l), levels[l]);
            EXPECT_EQ(g.stats().cells, uint64_t(res) * res * res);
            Failures fail(describe(0, property_spec(5), o));
            Rng r(res * 10 + factor);
            test::check_points(g, test::sample_points(g, r, 300, 100, 50), fail);
            EXPECT_EQ(fail.count(), 0u) << fail.context();
        }
    }
}

// Every point of the closed AABB lies in the grid: its corners and faces map to the boundary
// cells (cell_index may only answer false outside the grid).
TEST(PruneProperty, CellIndexCoversTheClosedAabb) {
    uint64_t misses = 0;
    for (uint32_t i = 0; i < 40; ++i) {
        Rng r(1200 + i);
        SceneBuilder b;
        const Aabb box{test::random_in_box(r, vec3(-3.0f), vec3(-0.5f)),
                       test::random_in_box(r, vec3(0.5f), vec3(3.0f))};
        const Scene sc = b.build(b.sphere(0.4f), box);
        for (const uint32_t res : {7u, 16u, 24u, 64u}) {
            PruneOptions o;
            o.resolution = res;
            const PrunedGrid g = prune(sc, o);
            for (uint32_t corner = 0; corner < 8; ++corner) {
                const vec3 p((corner & 1) ? box.max.x : box.min.x,
                             (corner & 2) ? box.max.y : box.min.y,
                             (corner & 4) ? box.max.z : box.min.z);
                uint32_t x = 0, y = 0, z = 0;
                const bool in = g.cell_index(p, x, y, z);
                const uint32_t ex = (corner & 1) ? res - 1 : 0, ey = (corner & 2) ? res - 1 : 0,
                               ez = (corner & 4) ? res - 1 : 0;
                if (!in || x != ex || y != ey || z != ez) {
                    if (misses++ < 5)
                        ADD_FAILURE()
                            << "AABB corner " << test::str(p) << " of " << test::str(box.min) << "–"
                            << test::str(box.max) << " at grid " << res << ": "
                            << (in ? "wrong cell" : "reported outside the grid");
                }
            }
        }
    }
    EXPECT_EQ(misses, 0u);
}

// The level lists documented in prune.hpp, and the argument checks.
TEST(PruneProperty, GridLevelsAndInvalidOptions) {
    EXPECT_EQ(grid_levels(256, 4), (std::vector<uint32_t>{4, 16, 64, 256}));
    EXPECT_EQ(grid_levels(128, 4), (std::vector<uint32_t>{2, 8, 32, 128}));
    EXPECT_EQ(grid_levels(100, 4), (std::vector<uint32_t>{25, 100}));
    EXPECT_EQ(grid_levels(256, 4, false), (std::vector<uint32_t>{256}));
    EXPECT_EQ(grid_levels(16, 2), (std::vector<uint32_t>{2, 4, 8, 16}));
    EXPECT_EQ(grid_levels(27, 3), (std::vector<uint32_t>{3, 9, 27}));
    EXPECT_EQ(grid_levels(1, 4), (std::vector<uint32_t>{1}));
    EXPECT_EQ(grid_levels(8, 4), (std::vector<uint32_t>{2, 8}));
    EXPECT_EQ(grid_levels(4, 4), (std::vector<uint32_t>{4}));
    EXPECT_THROW(grid_levels(0, 4), std::invalid_argument);
    EXPECT_THROW(grid_levels(16, 1), std::invalid_argument);

    SceneBuilder b;
    const Scene sc = b.build(b.sphere(1.0f), {vec3(-2.0f), vec3(2.0f)});
    PruneOptions o;
    o.resolution = 0;
    EXPECT_THROW(prune(sc, o), std::invalid_argument);
    o.resolution = 8;
    o.factor = 1;
    EXPECT_THROW(prune(sc, o), std::invalid_argument);
    o.factor = 4;
    o.far_field_c = 0.5f;
    EXPECT_THROW(prune(sc, o), std::invalid_argument);
    o.far_field_c = NAN;
    EXPECT_THROW(prune(sc, o), std::invalid_argument);
}

}  // namespace
}  // namespace sdfprune
