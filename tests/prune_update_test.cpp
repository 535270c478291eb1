// prune_update_test.cpp — incremental re-pruning (update in prune.hpp): after random edits of
// random scenes (moves, scales, radius and blend-radius changes, operator kind swaps), the
// updated grid equals a from-scratch prune of the edited scene, cell for cell and word for word.
#include <gtest/gtest.h>

#include <cstring>

#include "prune_check.hpp"
#include "sdfprune/io.hpp"
#include "sdfprune/prune.hpp"
#include "test_util.hpp"

namespace sdfprune {
namespace {

// The same hierarchy, cell for cell (tape contents, constants, values), and the statistics. The
// blocks are matched by walking both hierarchies (update() lays its arrays out differently).
void expect_same_grid(const PrunedGrid& a, const PrunedGrid& b, const std::string& what) {
    SCOPED_TRACE(what);
    ASSERT_EQ(a.level_count(), b.level_count());
    std::vector<PrunedGrid::Block> ba, bb;
    a.for_each_block([&](const PrunedGrid::Block& x) { ba.push_back(x); });
    b.for_each_block([&](const PrunedGrid::Block& x) { bb.push_back(x); });
    uint64_t differing = 0;
    for (size_t k = 0; k < std::min(ba.size(), bb.size()) && differing < 5; ++k) {
        const PrunedGrid::Block &x = ba[k], &y = bb[k];
        if (x.level != y.level || x.origin.x != y.origin.x || x.origin.y != y.origin.y ||
            x.origin.z != y.origin.z) {
            ADD_FAILURE() << "block " << k << " at level " << x.level << " vs " << y.level;
            ++differing;
            continue;
        }
        const uint32_t f = a.level_factor(x.level);
        for (uint32_t i = 0; i < f * f * f; ++i) {
            const PrunedCell &p = a.level_cells(x.level)[x.first + i],
                             &q = b.level_cells(y.level)[y.first + i];
            bool same = (p.tape == PrunedCell::kFarField) == (q.tape == PrunedCell::kFarField) &&
                        std::memcmp(&p.value, &q.value, sizeof(float)) == 0;
            if (same && p.tape == PrunedCell::kFarField) {
                same = std::memcmp(&p.bound, &q.bound, sizeof(float)) == 0 &&
                       p.children == q.children;  // the clearances
            } else if (same) {
                const auto ta = a.tape_at(p.tape), tb = b.tape_at(q.tape);
                same = std::equal(ta.begin(), ta.end(), tb.begin(), tb.end()) &&
                       a.tape_pool()[p.tape + 1] == b.tape_pool()[q.tape + 1];
            }
            if (!same && differing++ < 5)
                ADD_FAILURE() << "level " << x.level << " block " << k << " cell " << i
                              << " differs";
        }
    }
    EXPECT_EQ(ba.size(), bb.size());
    EXPECT_EQ(differing, 0u);
    EXPECT_TRUE(same_cells(a, b));
    EXPECT_EQ(std::memcmp(&a.near_box(), &b.near_box(), sizeof(Aabb)), 0) << "near_box";
    test::expect_same_prune_stats(a.stats(), b.stats(), what);
}

// The operators and primitives of a scene, by index.
std::vector<uint32_t> nodes_where(const Scene& sc, bool primitives) {
    std::vector<uint32_t> out;
    for (uint32_t n = 0; n < sc.size(); ++n)
        if (sc.is_primitive(n) == primitives) out.push_back(n);
    return out;
}

// Recomputes the operators' Lipschitz bounds (the max of their children's) after a primitive's
// bound changed.
void refresh_lipschitz(Scene& sc) {
    for (uint32_t n = 0; n < sc.size(); ++n)
        if (!sc.is_primitive(n))
            sc.lipschitz[n] = std::max(sc.lipschitz[sc.left[n]], sc.lipschitz[sc.right[n]]);
}

enum class Edit { kMove, kScale, kRadius, kBlend, kKindSwap };

const char* edit_name(Edit e) {
    switch (e) {
        case Edit::kMove:
            return "move";
        case Edit::kScale:
            return "scale";
        case Edit::kRadius:
            return "radius";
        case Edit::kBlend:
            return "blend radius";
        default:
            return "operator kind swap";
    }
}

// A random edit of kind `e` of `sc` (false when the scene has nothing of that kind).
bool random_edit(const Scene& sc, Edit e, Rng& r, Scene& out) {
    const std::vector<uint32_t> prims = nodes_where(sc, true), ops = nodes_where(sc, false);
    const auto pick = [&](const std::vector<uint32_t>& v) {
        return v[std::min(size_t(r.uniform() * float(v.size())), v.size() - 1)];
    };
    const float extent = math::length(sc.aabb.max - sc.aabb.min);
    switch (e) {
        case Edit::kMove: {
            const uint32_t p = sc.primitive[pick(prims)];
            const float d = extent * (r.uniform() < 0.5f ? 0.01f : 0.15f);
            out = moved_primitive(sc, p, test::random_direction(r) * d);
            return true;
        }
        case Edit::kScale: {
            // The shape grows by s about its frame's origin: local = (A·p + b) / s.
            out = sc;
            const uint32_t n = pick(prims), p = sc.primitive[n];
            const float s = r.uniform(0.7f, 1.4f);
            for (vec4* row : {&out.params[p].row0, &out.params[p].row1, &out.params[p].row2})
                *row = vec4(row->x / s, row->y / s, row->z / s, row->w / s);
            out.lipschitz[n] = sc.lipschitz[n] / s * (1 + 1e-6f);
            if (out.bound[p].scale > 0) out.bound[p].scale = sc.bound[p].scale / s * (1 - 4e-6f);
            refresh_lipschitz(out);
            return true;
        }
        case Edit::kRadius: {
            std::vector<uint32_t> spheres;
            for (uint32_t n : prims)
                if (sc.kind[n] == math::kPrimSphere) spheres.push_back(n);
            if (spheres.empty()) return false;
            out = sc;
            const uint32_t p = sc.primitive[pick(spheres)];
            const float radius = sc.params[p].a.x * r.uniform(0.6f, 1.5f);
            out.params[p].a.x = radius;
            out.bound[p].f0 = -radius;
            out.bound[p].rho = radius * (1 + 1e-6f);
            return true;
        }
        case Edit::kBlend: {
            if (ops.empty()) return false;
            out = sc;
            out.blend[pick(ops)] = r.uniform() < 0.3f ? 0.0f : r.uniform(0.01f, 0.3f);
            return true;
        }
        default: {
            std::vector<uint32_t> swappable;  // union <-> intersection (signs unchanged)
            for (uint32_t n : ops)
                if (sc.kind[n] != math::kOpDifference) swappable.push_back(n);
            if (swappable.empty()) return false;
            out = sc;
            const uint32_t n = pick(swappable);
            out.kind[n] = sc.kind[n] == math::kOpUnion ? math::kOpIntersection : math::kOpUnion;
            return true;
        }
    }
}

TEST(PruneUpdate, RandomEditsEqualAFullPrune) {
    uint32_t compared = 0, cheaper = 0;
    for (uint32_t i = 0; i < 12; ++i) {
        test::RandomSceneSpec spec;
        spec.primitives = 6 + i * 5;
        spec.tree = test::TreeShape(i % 4);
        spec.placement = test::Placement(i % 5);
        const Scene sc = test::random_scene(700 + i, spec);
        PruneOptions o;
        o.resolution = i % 3 == 0 ? 32 : 64;
        o.factor = i % 4 == 3 ? 2 : 4;
        o.coarse_tapes = true;
        o.bounds = i % 5 == 4 ? CellBounds::kLipschitz : CellBounds::kInterval;
        o.clearance = i % 2 == 0;  // updates keep the far-field clearances right
        const PrunedGrid before = prune(sc, o);
        Rng r(40 + i);
        for (const Edit e :
             {Edit::kMove, Edit::kScale, Edit::kRadius, Edit::kBlend, Edit::kKindSwap}) {
            Scene edited;
            if (!random_edit(sc, e, r, edited)) continue;
            const SceneEdit edit = scene_edit(sc, edited);
            const PrunedGrid incremental = update(before, edited, edit);
            const PrunedGrid full = prune(edited, o);
            std::string what = "scene ";
            what += std::to_string(i);
            what += ", ";
            what += edit_name(e);
            expect_same_grid(incremental, full, what);
            ++compared;
            cheaper += incremental.stats().cells_pruned < full.stats().cells_pruned;
            // A second edit on the updated grid.
            Scene twice;
            if (random_edit(edited, Edit::kMove, r, twice)) {
                expect_same_grid(update(incremental, twice), prune(twice, o), what);
                ++compared;
            }
        }
    }
    EXPECT_GT(compared, 80u);
    // Edits are local: most updates prune fewer cells than a full prune.
    EXPECT_GT(cheaper, compared / 4);
}

// Point lookups (PrunedGrid::locate, through the lookup shortcut that update() refreshes) agree:
// the same deciding level and cell contents at random points and at every cell centre of a
// coarse lattice.
void expect_same_lookups(const PrunedGrid& a, const PrunedGrid& b, Rng& r,
                         const std::string& what) {
    SCOPED_TRACE(what);
    const Aabb box = a.aabb();
    uint32_t differing = 0;
    for (uint32_t i = 0; i < 4000 && differing < 5; ++i) {
        const vec3 p(r.uniform(box.min.x, box.max.x), r.uniform(box.min.y, box.max.y),
                     r.uniform(box.min.z, box.max.z));
        PrunedGrid::Located x, y;
        ASSERT_TRUE(a.locate(p, x));
        ASSERT_TRUE(b.locate(p, y));
        bool same = x.level == y.level && x.x == y.x && x.y == y.y && x.z == y.z &&
                    x.far_field() == y.far_field();
        if (same && x.far_field()) {
            same = std::memcmp(&x.cell->bound, &y.cell->bound, sizeof(float)) == 0;
        } else if (same) {
            const auto ta = a.tape_at(x.cell->tape), tb = b.tape_at(y.cell->tape);
            same = std::equal(ta.begin(), ta.end(), tb.begin(), tb.end());
        }
        if (!same && differing++ < 5)
            ADD_FAILURE() << "lookup at (" << p.x << ", " << p.y << ", " << p.z << ") differs";
    }
}

// A session of edits, each applied in place to the previous result (update(std::move(g), ...)):
// large moves make cells change between near and far field (blocks freed and reused, the arrays
// laid out afresh when garbage piles up); every step equals a full prune, lookups included.
TEST(PruneUpdate, ASessionOfEditsInPlace) {
    for (uint32_t i = 0; i < 3; ++i) {
        test::RandomSceneSpec spec;
        spec.primitives = 12 + 8 * i;
        spec.tree = test::TreeShape(i % 4);
        const auto scene = std::make_shared<Scene>(test::random_scene(900 + i, spec));
        PruneOptions o;
        o.resolution = 64;
        o.coarse_tapes = true;
        o.clearance = i != 1;  // the viewer's edits, with clearances as it prunes them
        PrunedGrid g = prune(scene, o);
        std::shared_ptr<const Scene> current = scene;
        Rng r(77 + i);
        const float extent = math::length(scene->aabb.max - scene->aabb.min);
        for (uint32_t step = 0; step < 25; ++step) {
            const uint32_t p = std::min(uint32_t(r.uniform() * float(current->primitive_count())),
                                        current->primitive_count() - 1);
            const float d = extent * (step % 3 == 0 ? 0.2f : 0.02f);
            auto next = std::make_shared<const Scene>(
                moved_primitive(*current, p, test::random_direction(r) * d));
            const SceneEdit edit = scene_edit(*current, *next);
            g = update(std::move(g), next, edit);
            current = next;
            const std::string what =
                "scene " + std::to_string(i) + ", edit " + std::to_string(step);
            const PrunedGrid full = prune(*current, o);
            expect_same_grid(g, full, what);
            expect_same_lookups(g, full, r, what);
            ASSERT_EQ(&g.scene(), current.get());
        }
    }
}

TEST(PruneUpdate, NoEditCopiesEverything) {
    test::RandomSceneSpec spec;
    spec.primitives = 20;
    const Scene sc = test::random_scene(31, spec);
    PruneOptions o;
    o.resolution = 64;
    o.coarse_tapes = true;
    const PrunedGrid g = prune(sc, o);
    const PrunedGrid u = update(g, sc, SceneEdit{});
    expect_same_grid(u, g, "no edit");
    // Only level 0 (the full tree's children) is pruned again, the rest copied.
    EXPECT_LT(u.stats().cells_pruned, g.stats().cells_pruned);
    EXPECT_EQ(u.stats().cells_pruned, uint64_t(g.level_cells(0).size()));
}

TEST(PruneUpdate, RefusesWhatItCannotUpdate) {
    test::RandomSceneSpec spec;
    spec.primitives = 5;
    const Scene sc = test::random_scene(5, spec);
    PruneOptions o;
    o.resolution = 16;
    const PrunedGrid without = prune(sc, o);
    EXPECT_THROW(update(without, sc), std::invalid_argument);
    o.coarse_tapes = true;
    const PrunedGrid g = prune(sc, o);
    spec.primitives = 6;
    const Scene other = test::random_scene(6, spec);
    EXPECT_THROW(update(g, other), std::invalid_argument);
    EXPECT_THROW(update(g, sc, SceneEdit{{sc.size()}}), std::invalid_argument);
    EXPECT_THROW(moved_primitive(sc, sc.primitive_count(), vec3(0.1f)), std::invalid_argument);
}

// One atom of molecule moved: the update equals a full prune and prunes far fewer cells.
TEST(PruneUpdate, MoleculeAtomMove) {
    SDFPRUNE_REQUIRE_SCENE(path, "molecule.json");
    const Scene sc = load_scene(path);
    PruneOptions o;
    o.resolution = 128;
    o.coarse_tapes = true;
    const PrunedGrid g = prune(sc, o);
    const Scene moved = moved_primitive(sc, 500, vec3(0.01f, -0.005f, 0.0f));
    const PrunedGrid u = update(g, moved);
    const PrunedGrid full = prune(moved, o);
    expect_same_grid(u, full, "molecule, atom 500 moved");
    EXPECT_LT(u.stats().tape_words_visited * 10, full.stats().tape_words_visited);
}

}  // namespace
}  // namespace sdfprune
