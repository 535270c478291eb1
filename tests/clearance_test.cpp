// clearance_test.cpp — far-field clearances (set_clearance in prune.hpp): every far-field cell's
// clearance in every octant, checked by brute force against the finest cells' near-field
// states: the box it names holds no near-field finest cell, and (below the cap) the box one cell
// larger does. Random scenes and the demo, levels of factor 4, 2 and 3 (not powers of two) up
// to 128³, and a scene with no surface in the grid.
#include <gtest/gtest.h>

#include <vector>

#include "prune_check.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/prune.hpp"

namespace sdfprune::test {
namespace {

// Per level, whether each of its cells (dense, z-major) holds a near-field finest cell.
std::vector<std::vector<uint8_t>> near_cells(const PrunedGrid& g) {
    const uint32_t N = g.resolution();
    std::vector<std::vector<uint8_t>> near;
    for (uint32_t l = 0; l < g.level_count(); ++l) {
        const uint32_t r = g.level_resolution(l);
        near.emplace_back(size_t(r) * r * r, 0);
    }
    for (uint32_t z = 0; z < N; ++z)
        for (uint32_t y = 0; y < N; ++y)
            for (uint32_t x = 0; x < N; ++x) {
                if (g.cell(x, y, z).far_field) continue;
                for (uint32_t l = 0; l < g.level_count(); ++l) {
                    const uint32_t r = g.level_resolution(l), s = N / r;
                    near[l][(size_t(z / s) * r + y / s) * r + x / s] = 1;
                }
            }
    return near;
}

// Whether the box of cells of a level r wide from `at`, `side` cells along each axis the
// octant's way, holds a near cell (cells outside the level hold none).
bool box_holds_near(const std::vector<uint8_t>& near, uint32_t r, CellCoord at, uint32_t octant,
                    uint32_t side) {
    const int c[3] = {int(at.x), int(at.y), int(at.z)};
    int lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
        const bool up = octant >> a & 1;
        lo[a] = std::max(0, up ? c[a] : c[a] - int(side) + 1);
        hi[a] = std::min(int(r) - 1, up ? c[a] + int(side) - 1 : c[a]);
    }
    for (int z = lo[2]; z <= hi[2]; ++z)
        for (int y = lo[1]; y <= hi[1]; ++y)
            for (int x = lo[0]; x <= hi[0]; ++x)
                if (near[(size_t(z) * r + size_t(y)) * r + size_t(x)]) return true;
    return false;
}

// Every far-field cell's clearances, by brute force; returns how many cells were checked.
uint64_t check_clearances(const PrunedGrid& g, const std::string& what) {
    SCOPED_TRACE(what);
    const auto near = near_cells(g);
    uint64_t checked = 0, wrong = 0;
    g.for_each_block([&](const PrunedGrid::Block& b) {
        const uint32_t f = g.level_factor(b.level), r = g.level_resolution(b.level);
        for (uint32_t local = 0; local < f * f * f; ++local) {
            const PrunedCell& c = g.level_cells(b.level)[b.first + local];
            if (c.tape != PrunedCell::kFarField) continue;
            ++checked;
            const CellCoord at = block_cell(b.origin, f, local);
            for (uint32_t o = 0; o < 8; ++o) {
                const uint32_t k = clearance_in(c, o);
                const bool clear = !box_holds_near(near[b.level], r, at, o, k + 1);
                const bool tight =
                    k == kMaxClearance || box_holds_near(near[b.level], r, at, o, k + 2);
                if ((!clear || !tight) && ++wrong <= 5)
                    ADD_FAILURE() << "level " << b.level << " cell (" << at.x << ", " << at.y
                                  << ", " << at.z << ") octant " << o << ": clearance " << k
                                  << (clear ? " could be larger" : " reaches a near cell");
            }
        }
    });
    EXPECT_EQ(wrong, 0u);
    return checked;
}

TEST(Clearance, MatchesBruteForce) {
    RandomSceneSpec spec;
    spec.primitives = 20;
    spec.placement = Placement::kMixed;
    const std::pair<std::string, Scene> scenes[] = {{"seed 3", random_scene(3, spec)},
                                                    {"seed 4", random_scene(4, spec)},
                                                    {"demo", builtin_scene("demo")}};
    for (const auto& [name, sc] : scenes) {
        for (const auto& [res, factor] :
             std::vector<std::pair<uint32_t, uint32_t>>{{64, 4}, {32, 2}, {54, 3}, {128, 4}}) {
            PruneOptions o;
            o.clearance = true;
            o.resolution = res;
            o.factor = factor;
            const PrunedGrid g = prune(sc, o);
            const std::string what =
                name + ", " + std::to_string(res) + "³ factor " + std::to_string(factor);
            EXPECT_GT(check_clearances(g, what), 0u) << what;
        }
    }
}

TEST(Clearance, EmptyGridIsClearEverywhere) {
    // A sphere far outside the grid's box: every cell far-field, every clearance the cap.
    Scene sc = builtin_scene("sphere");
    sc.aabb.min = sc.aabb.min + vec3(100.0f);
    sc.aabb.max = sc.aabb.max + vec3(100.0f);
    PruneOptions o;
    o.clearance = true;
    o.resolution = 16;
    const PrunedGrid g = prune(sc, o);
    for (const PrunedCell& c : g.level_cells(0)) {
        ASSERT_EQ(c.tape, PrunedCell::kFarField);
        for (uint32_t oct = 0; oct < 8; ++oct) EXPECT_EQ(clearance_in(c, oct), kMaxClearance);
    }
}

TEST(Clearance, OffLeavesZeroAlsoAfterAnUpdate) {
    const Scene sc = builtin_scene("demo");
    PruneOptions o;
    o.resolution = 64;
    o.clearance = false;
    o.coarse_tapes = true;  // for update()
    const auto all_zero = [](const PrunedGrid& g) {
        uint64_t nonzero = 0;
        g.for_each_block([&](const PrunedGrid::Block& b) {
            const uint32_t f = g.level_factor(b.level);
            for (uint32_t i = 0; i < f * f * f; ++i) {
                const PrunedCell& c = g.level_cells(b.level)[b.first + i];
                nonzero += c.tape == PrunedCell::kFarField && c.children != 0;
            }
        });
        return nonzero == 0;
    };
    const PrunedGrid g = prune(sc, o);
    EXPECT_TRUE(all_zero(g));
    EXPECT_EQ(g.stats().clearance_ms, 0.0);
    // A move that turns cells near-field and far-field: the update equals a fresh prune.
    const Scene moved = moved_primitive(sc, 0, (sc.aabb.max - sc.aabb.min) * 0.2f);
    const PrunedGrid u = update(g, moved);
    EXPECT_TRUE(all_zero(u));
    EXPECT_TRUE(same_cells(u, prune(moved, o)));
}

}  // namespace
}  // namespace sdfprune::test
