// prune_level_test.cpp — the level step (src/prune/prune_level.hpp) on a subset of a level's
// blocks makes the same cells as the full prune(); the hierarchy walk (PrunedGrid::descend,
// for_each_block) finds the cells the children links lead to, and the point lookups
// (locate_cell, the staged walk) find descend's.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <memory>
#include <vector>

#include "prune_check.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/generate.hpp"
#include "sdfprune/io.hpp"
#include "sdfprune/render.hpp"
#include "src/prune/prune_level.hpp"
#include "test_util.hpp"

namespace sdfprune {
namespace {

// Level `level`'s cells with their coordinates (in that level's cells), found through the
// children links as documented in prune.hpp.
struct CellAt {
    uint32_t index, x, y, z;
};
std::vector<CellAt> cells_of_level(const PrunedGrid& g, uint32_t level) {
    const uint32_t r0 = g.level_resolution(0);
    std::vector<CellAt> cur;
    for (uint32_t i = 0; i < r0 * r0 * r0; ++i)
        cur.push_back({i, i % r0, (i / r0) % r0, i / (r0 * r0)});
    for (uint32_t l = 0; l < level; ++l) {
        const uint32_t f = g.level_resolution(l + 1) / g.level_resolution(l);
        std::vector<CellAt> next;
        for (const CellAt& c : cur) {
            const PrunedCell& cell = g.level_cells(l)[c.index];
            if (cell.tape == PrunedCell::kFarField) continue;
            for (uint32_t k = 0; k < f * f * f; ++k)
                next.push_back({cell.children + k, c.x * f + k % f, c.y * f + (k / f) % f,
                                c.z * f + k / (f * f)});
        }
        cur.swap(next);
    }
    return cur;
}

// Re-prunes the children of every `stride`-th near-field cell of each level but the finest and
// compares them with the grid's.
void check_subset(const Scene& sc, PruneOptions o, uint32_t stride) {
    o.coarse_tapes = true;  // the parents' own tapes, as prune() used them
    const PrunedGrid g = prune(sc, o);
    ASSERT_GE(g.level_count(), 2u);
    CellScratch s;
    uint64_t compared = 0;
    for (uint32_t l = 0; l + 1 < g.level_count(); ++l) {
        const uint32_t f = g.level_resolution(l + 1) / g.level_resolution(l);
        const uint64_t per_block = uint64_t(f) * f * f;
        std::vector<ParentBlock> blocks;
        std::vector<uint32_t> first;  // the grid's first child of each block
        uint32_t seen = 0;
        for (const CellAt& c : cells_of_level(g, l)) {
            const PrunedCell& cell = g.level_cells(l)[c.index];
            if (cell.tape == PrunedCell::kFarField || seen++ % stride != 0) continue;
            const std::span<const uint32_t> tape = g.tape_at(cell.tape);
            blocks.push_back({{c.x * f, c.y * f, c.z * f}, uint32_t(tape.size()), tape.data()});
            first.push_back(cell.children);
        }
        const bool finest = l + 2 == g.level_count();
        const LevelGeometry geo =
            level_geometry(sc, o, g.level_resolution(l + 1), f, finest, kPruneChunkCells);
        std::vector<PrunedCell> cells(blocks.size() * per_block);
        LevelChunk out;
        prune_level_step(sc, o, geo, blocks, cells, s, out);
        for (size_t b = 0; b < blocks.size(); ++b)
            for (uint64_t k = 0; k < per_block; ++k) {
                const PrunedCell& mine = cells[b * per_block + k];
                const PrunedCell& theirs = g.level_cells(l + 1)[first[b] + k];
                ASSERT_EQ(mine.tape == PrunedCell::kFarField, theirs.tape == PrunedCell::kFarField)
                    << "level " << l + 1 << " block " << b << " cell " << k;
                EXPECT_EQ(mine.value, theirs.value);
                if (mine.tape == PrunedCell::kFarField) {
                    EXPECT_EQ(mine.bound, theirs.bound);
                    continue;
                }
                const std::span<const uint32_t> a(out.words.data() + mine.tape + 2,
                                                  out.words[mine.tape]);
                const std::span<const uint32_t> t = g.tape_at(theirs.tape);
                ASSERT_TRUE(std::equal(a.begin(), a.end(), t.begin(), t.end()));
                EXPECT_EQ(out.words[mine.tape + 1], g.tape_pool()[theirs.tape + 1]);
                ++compared;
            }
    }
    EXPECT_GT(compared, 0u);
}

TEST(PruneLevelStep, SubsetOfBlocksGivesTheFullPrunesCells) {
    test::RandomSceneSpec spec;
    spec.primitives = 40;
    const Scene sc = test::random_scene(3000, spec);
    PruneOptions o;
    o.resolution = 64;  // split levels (factor 4)
    check_subset(sc, o, 3);
    o.resolution = 54;  // factor 3: no split
    o.factor = 3;
    check_subset(sc, o, 2);
}

TEST(PruneLevelStep, MoleculeSubset) {
    SDFPRUNE_REQUIRE_SCENE(path, "molecule.json");
    const Scene sc = load_scene(path);
    PruneOptions o;
    o.resolution = 64;
    check_subset(sc, o, 5);
}

TEST(PruneLevelStep, SplitNeedsWholeBlocks) {
    const Scene sc = test::random_scene(3, test::RandomSceneSpec{});
    PruneOptions o;
    const LevelGeometry geo = level_geometry(sc, o, 64, 4, false, kPruneChunkCells);
    ASSERT_TRUE(geo.split);
    const std::vector<ParentBlock> blocks{
        {{0, 0, 0}, uint32_t(sc.full_tape.size()), sc.full_tape.data()}};
    std::vector<PrunedCell> cells(64);
    CellScratch s;
    LevelChunk out;
    EXPECT_THROW(prune_level_step(sc, o, geo, blocks, 0, 10, cells, s, out), std::invalid_argument);
    EXPECT_THROW(prune_level_step(sc, o, geo, blocks, 0, 128, cells, s, out),
                 std::invalid_argument);
    prune_level_step(sc, o, geo, blocks, 0, 64, cells, s, out);
    for (const PrunedCell& c : cells)
        EXPECT_TRUE(c.tape == PrunedCell::kFarField || c.tape < out.words.size());
}

// Levels split into octants where they have more than kDirectMaxParents parents or the full
// tape is long for their cells; the top levels of a scene of a short tape prune their cells
// from their blocks.
// Either way the cells are exact (the property tests prune at 64³–256³, through both).
TEST(PruneLevelStep, TopLevelsOfShortTapesPruneTheirCellsDirectly) {
    const Scene sc = builtin_scene("demo");
    PruneOptions o;
    const std::vector<uint32_t> res = grid_levels(256, 4);
    ASSERT_EQ(res, (std::vector<uint32_t>{4, 16, 64, 256}));
    const bool expected[] = {false, false, true, true};
    for (size_t l = 0; l < res.size(); ++l) {
        const uint32_t f = l == 0 ? res[0] : res[l] / res[l - 1];
        EXPECT_EQ(splits_into_octants(sc, o, res[l], f), expected[l]) << "level " << l;
        EXPECT_EQ(level_geometry(sc, o, res[l], f, false, kPruneChunkCells).split, expected[l]);
    }
    // A level of more parents (an 8³ grid of them) splits; factors 2 and 3 never do, nor
    // a pruning without hierarchy.
    EXPECT_TRUE(splits_into_octants(sc, o, 32, 4));
    EXPECT_FALSE(splits_into_octants(sc, o, 128, 2));
    EXPECT_FALSE(splits_into_octants(sc, o, 162, 3));
    PruneOptions flat = o;
    flat.hierarchy = false;
    EXPECT_FALSE(splits_into_octants(sc, flat, 256, 4));
    // A full tape past kDirectMaxCellWords / 16³ words: level 1 (16³ cells) splits, level 0
    // does not; past kDirectMaxCellWords / 4³ words, every level splits.
    const Scene longer = generate_scene("fluid", 1, 3000);
    ASSERT_GT(longer.full_tape.size() * 4096, kDirectMaxCellWords);
    EXPECT_FALSE(splits_into_octants(longer, o, 4, 4));
    EXPECT_TRUE(splits_into_octants(longer, o, 16, 4));
    const Scene big = generate_scene("fluid", 1, uint32_t(kDirectMaxCellWords / 64 / 2) + 1);
    ASSERT_GT(big.full_tape.size() * 64, kDirectMaxCellWords);
    EXPECT_TRUE(splits_into_octants(big, o, 4, 4));
    EXPECT_TRUE(splits_into_octants(big, o, 16, 4));
}

// The grids the walk tests run on: a random scene of 40 primitives pruned with factor 4 at 64
// (lookups through the shortcut) and with factor 3 at 54 (through descend).
std::vector<PrunedGrid> walk_test_grids(uint64_t seed) {
    test::RandomSceneSpec spec;
    spec.primitives = 40;
    const auto sc = std::make_shared<const Scene>(test::random_scene(seed, spec));
    std::vector<PrunedGrid> grids;
    for (const uint32_t factor : {4u, 3u}) {
        PruneOptions o;
        o.factor = factor;
        o.resolution = factor == 4 ? 64 : 54;
        grids.push_back(prune(sc, o));
    }
    return grids;
}

// The walk (PrunedGrid::descend, for_each_block) against the children links followed by hand.
TEST(PrunedGridWalk, DescendAndBlocksMatchTheLinks) {
    for (const PrunedGrid& g : walk_test_grids(3000)) {
        const uint32_t N = g.resolution(), last = g.level_count() - 1;
        // The deciding cell of every finest cell, by hand: far-field cells of every level fill
        // their span, near-field finest cells themselves.
        std::vector<uint64_t> deciding(uint64_t(N) * N * N, ~0ull);
        uint64_t blocks_by_hand = 0;
        for (uint32_t l = 0; l <= last; ++l) {
            const uint32_t scale = N / g.level_resolution(l);
            for (const CellAt& c : cells_of_level(g, l)) {
                const PrunedCell& cell = g.level_cells(l)[c.index];
                if (l < last && cell.tape != PrunedCell::kFarField) {
                    ++blocks_by_hand;
                    continue;
                }
                for (uint32_t z = c.z * scale; z < (c.z + 1) * scale; ++z)
                    for (uint32_t y = c.y * scale; y < (c.y + 1) * scale; ++y)
                        for (uint32_t x = c.x * scale; x < (c.x + 1) * scale; ++x)
                            deciding[(uint64_t(z) * N + y) * N + x] = uint64_t(l) << 32 | c.index;
            }
        }
        for (uint32_t z = 0; z < N; ++z)
            for (uint32_t y = 0; y < N; ++y)
                for (uint32_t x = 0; x < N; ++x) {
                    const PrunedGrid::CellRef at = g.descend(x, y, z, last);
                    ASSERT_EQ(uint64_t(at.level) << 32 | at.index,
                              deciding[(uint64_t(z) * N + y) * N + x]);
                }
        // Every block once, its cells where the links say.
        uint64_t blocks = 0, finest_covered = 0;
        g.for_each_block([&](const PrunedGrid::Block& b) {
            ++blocks;
            const uint32_t f = g.level_factor(b.level);
            const uint32_t scale = N / g.level_resolution(b.level);
            for (uint32_t k = 0; k < f * f * f; ++k) {
                const PrunedCell& c = g.level_cells(b.level)[b.first + k];
                const CellCoord at = block_cell(b.origin, f, k);
                const PrunedGrid::CellRef d =
                    g.descend(at.x * scale, at.y * scale, at.z * scale, b.level);
                EXPECT_EQ(d.level, b.level);
                EXPECT_EQ(d.index, b.first + k);
                if (c.tape == PrunedCell::kFarField || b.level == last)
                    finest_covered += uint64_t(scale) * scale * scale;
            }
        });
        EXPECT_EQ(blocks, blocks_by_hand + 1);  // level 0's block and one per near-field parent
        EXPECT_EQ(finest_covered, uint64_t(N) * N * N);
    }
}

// PrunedGrid::near_box, the box the tracer marches rays in: it holds every near-field finest
// cell and every sign change of the field between neighbouring samples (the surface), and it
// is tight: each face lies within one finest cell of a near-field finest cell. A one-level
// grid's is the scene's box; a grid without near-field finest cells' is empty.
TEST(PrunedGridNearBox, HoldsTheSurfaceAndIsTight) {
    std::vector<PrunedGrid> grids = walk_test_grids(3002);
    test::RandomSceneSpec spec;
    spec.primitives = 12;
    spec.placement = test::Placement::kMixed;
    spec.union_share = 1.0f;  // a union of solids: a surface
    const auto small = std::make_shared<const Scene>(test::random_scene(3003, spec));
    PruneOptions o;
    o.resolution = 32;
    o.factor = 2;
    grids.push_back(prune(small, o));
    uint64_t changes = 0, surfaces = 0;
    for (const PrunedGrid& g : grids) {
        const Aabb& box = g.near_box();
        const uint32_t N = g.resolution();
        const vec3 lo = g.aabb().min, cs = g.cell_size();
        // The near-field finest cells' bounds, by brute force.
        float reach[6] = {INFINITY, INFINITY, INFINITY, INFINITY, INFINITY, INFINITY};
        bool any = false;
        for (uint32_t z = 0; z < N; ++z)
            for (uint32_t y = 0; y < N; ++y)
                for (uint32_t x = 0; x < N; ++x) {
                    PrunedGrid::Located at;
                    g.locate_cell(x, y, z, at);
                    if (at.far_field()) continue;
                    any = true;
                    const uint32_t i[3] = {x, y, z};
                    for (int a = 0; a < 3; ++a) {
                        const float cmin = lo[a] + float(i[a]) * cs[a],
                                    cmax = lo[a] + float(i[a] + 1) * cs[a];
                        ASSERT_LE(box.min[a], cmin) << "axis " << a;
                        ASSERT_GE(box.max[a], cmax) << "axis " << a;
                        reach[2 * a] = std::min(reach[2 * a], cmin - box.min[a]);
                        reach[2 * a + 1] = std::min(reach[2 * a + 1], box.max[a] - cmax);
                    }
                }
        if (!any) {
            EXPECT_TRUE(box.min.x > box.max.x || box.min.y > box.max.y || box.min.z > box.max.z);
            continue;
        }
        ++surfaces;
        for (int face = 0; face < 6; ++face)
            EXPECT_LE(reach[face], 1.001f * cs[face / 2]) << "face " << face;
        // The field's sign changes between neighbouring samples of a finer lattice lie in it.
        const Scene& sc = g.scene();
        const uint32_t n = 2 * N;
        const vec3 step = (g.aabb().max - lo) / float(n);
        std::vector<float> row(size_t(n + 1) * (n + 1) * (n + 1));
        for (uint32_t z = 0; z <= n; ++z)
            for (uint32_t y = 0; y <= n; ++y)
                for (uint32_t x = 0; x <= n; ++x)
                    row[(size_t(z) * (n + 1) + y) * (n + 1) + x] = eval_point(
                        sc, lo + vec3(float(x) * step.x, float(y) * step.y, float(z) * step.z));
        const auto in_box = [&](uint32_t x, uint32_t y, uint32_t z) {
            const vec3 p = lo + vec3(float(x) * step.x, float(y) * step.y, float(z) * step.z);
            return p.x >= box.min.x && p.y >= box.min.y && p.z >= box.min.z && p.x <= box.max.x &&
                   p.y <= box.max.y && p.z <= box.max.z;
        };
        for (uint32_t z = 0; z <= n; ++z)
            for (uint32_t y = 0; y <= n; ++y)
                for (uint32_t x = 0; x < n; ++x) {
                    const size_t k = (size_t(z) * (n + 1) + y) * (n + 1) + x;
                    if ((row[k] < 0) == (row[k + 1] < 0)) continue;
                    ++changes;
                    ASSERT_TRUE(in_box(x, y, z) && in_box(x + 1, y, z));
                }
    }
    EXPECT_GT(surfaces, 0u);
    EXPECT_GT(changes, 0u);
    // One level: the scene's box.
    o.hierarchy = false;
    const PrunedGrid one = prune(small, o);
    ASSERT_EQ(one.level_count(), 1u);
    EXPECT_EQ(std::memcmp(&one.near_box(), &one.aabb(), sizeof(Aabb)), 0);
    // No near-field cell (a sphere far outside the grid's box): empty, and no ray is marched.
    Scene away = builtin_scene("sphere");
    away.aabb.min = away.aabb.min + vec3(100.0f);
    away.aabb.max = away.aabb.max + vec3(100.0f);
    const PrunedGrid empty = prune(away, {});
    EXPECT_GT(empty.near_box().min.x, empty.near_box().max.x);
    RenderOptions ro;
    ro.width = 32;
    ro.height = 24;
    ro.camera = orbit_camera(away.aabb, 30, 20, 0, 40);
    RenderStats rs;
    render(empty, ro, &rs);
    EXPECT_EQ(rs.steps_avg, 0.0);
    EXPECT_EQ(rs.hit_fraction, 0.0);
}

// locate_cell (through the lookup shortcut on pow2 grids) and the staged walk a tracer uses
// (walk_begin, walk_step, walk_located) find descend's cell for every finest cell, the walk
// naming at most one word per level (and the shortcut's entry).
TEST(PrunedGridWalk, LocateAndStagedWalkMatchDescend) {
    for (const PrunedGrid& g : walk_test_grids(3001)) {
        const uint32_t N = g.resolution(), last = g.level_count() - 1;
        for (uint32_t z = 0; z < N; ++z)
            for (uint32_t y = 0; y < N; ++y)
                for (uint32_t x = 0; x < N; ++x) {
                    const PrunedGrid::CellRef at = g.descend(x, y, z, last);
                    const PrunedCell* cell = &g.level_cells(at.level)[at.index];
                    const uint32_t scale = N / g.level_resolution(at.level);
                    PrunedGrid::Located loc;
                    g.locate_cell(x, y, z, loc);
                    PrunedGrid::Walk w = g.walk_begin(x, y, z);
                    uint32_t reads = 1;
                    while (!g.walk_step(w)) ASSERT_LE(++reads, g.level_count() + 1);
                    for (const PrunedGrid::Located& l : {loc, g.walk_located(w)}) {
                        ASSERT_EQ(l.level, at.level);
                        ASSERT_EQ(l.cell, cell);
                        ASSERT_EQ(l.x, x / scale);
                        ASSERT_EQ(l.y, y / scale);
                        ASSERT_EQ(l.z, z / scale);
                    }
                }
    }
}

}  // namespace
}  // namespace sdfprune
