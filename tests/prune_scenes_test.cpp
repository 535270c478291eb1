// prune_scenes_test.cpp — pruning on specific scenes (DESIGN.md §3–5): the per-cell stages on
// hand-built trees, statistics and the raw hierarchy against brute force, the exact near-field
// set of a sphere, the reference scenes at 256³ and a 100,000-deep chain.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cstring>
#include <string>
#include <unordered_map>
#include <unordered_set>

#include "prune_check.hpp"
#include "sdfprune/builder.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/io.hpp"
#include "sdfprune/prune.hpp"
#include "test_util.hpp"

namespace sdfprune {
namespace {

using test::Failures;
using test::PointStats;

CellBox make_box(vec3 centre, float half) {
    CellBox b;
    b.centre = centre;
    b.half = vec3(half);
    b.radius = math::length(b.half);
    return b;
}

// f at random points of the box equals the given tape's value exactly.
void expect_tape_exact_in_box(const Scene& sc, std::span<const uint32_t> tape, const CellBox& box,
                              uint64_t seed) {
    Rng r(seed);
    std::vector<float> stack(sc.max_stack);
    for (int i = 0; i < 500; ++i) {
        const vec3 p = test::random_in_box(r, box.centre - box.half, box.centre + box.half);
        const float f = eval_point(sc, p);
        const float v = eval_tape(sc, tape, p, stack.data());
        ASSERT_EQ(v, f) << "at " << test::str(p);
    }
}

// ---- 6. the per-cell stages ---------------------------------------------------------------------

// Two spheres, one far from the cell: the union is decided for the near one, whose single node
// makes the pruned tape; with the operands swapped the right operand wins.
TEST(PruneStages, UnionWithAFarSphereKeepsTheNearOne) {
    for (const bool swapped : {false, true}) {
        SceneBuilder b;
        const Shape near = b.sphere(0.5f);
        const Shape far = b.sphere(0.5f).translated({5, 0, 0});
        const Scene sc =
            b.build(swapped ? smooth_union(far, near, 0.2f) : smooth_union(near, far, 0.2f),
                    {vec3(-1, -1, -1), vec3(6, 1, 1)});
        ASSERT_EQ(sc.size(), 3u);
        const uint32_t near_node = swapped ? 1 : 0;
        const CellBox box = make_box({0.4f, 0, 0}, 0.25f);
        for (const CellBounds bounds : {CellBounds::kInterval, CellBounds::kLipschitz}) {
            CellScratch s;
            const float v = evaluate_cell(sc, sc.full_tape, box, bounds, s);
            EXPECT_FLOAT_EQ(v, eval_point(sc, box.centre));
            EXPECT_FLOAT_EQ(v, -0.1f);
            EXPECT_EQ(s.left[2], 0u);
            EXPECT_EQ(s.right[2], 1u);
            EXPECT_EQ(s.decision[2], swapped ? math::kRightWins : math::kLeftWins);
            // The near sphere's range over the box: exact with interval bounds (the box spans
            // x in [0.15, 0.65], |y|, |z| <= 0.25), centre ± R with Lipschitz bounds.
            if (bounds == CellBounds::kInterval) {
                EXPECT_NEAR(s.lo[near_node], 0.15f - 0.5f, 1e-5f);
                EXPECT_NEAR(s.hi[near_node], std::sqrt(0.65f * 0.65f + 0.125f) - 0.5f, 1e-5f);
            } else {
                EXPECT_NEAR(s.lo[near_node], -0.1f - box.radius, 1e-6f);
                EXPECT_NEAR(s.hi[near_node], -0.1f + box.radius, 1e-6f);
            }
            // The operator took its winner's range.
            EXPECT_EQ(s.lo[2], s.lo[near_node]);
            EXPECT_EQ(s.hi[2], s.hi[near_node]);
            float constant = 123;
            EXPECT_TRUE(is_near_field(sc, sc.full_tape, box, 2.0f, s, constant));
            std::vector<uint32_t> out{77};  // compact_tape appends
            EXPECT_EQ(compact_tape(sc, sc.full_tape, s, out), 1u);
            ASSERT_EQ(out.size(), 2u);
            EXPECT_EQ(out[0], 77u);
            EXPECT_EQ(out[1], math::tape_word(near_node, false));
            expect_tape_exact_in_box(sc, std::span(out).subspan(1), box, 1);
        }
    }
}

// Both operands matter in a cell where the smooth union blends them: nothing is pruned.
TEST(PruneStages, OverlappingOperandsAreKept) {
    SceneBuilder b;
    const Scene sc =
        b.build(smooth_union(b.sphere(0.5f), b.sphere(0.5f).translated({0.8f, 0, 0}), 0.3f),
                {vec3(-1), vec3(2)});
    const CellBox box = make_box({0.4f, 0.4f, 0}, 0.05f);
    CellScratch s;
    evaluate_cell(sc, sc.full_tape, box, CellBounds::kInterval, s);
    EXPECT_EQ(s.decision[2], math::kKeepBoth);
    float constant = 0;
    EXPECT_TRUE(is_near_field(sc, sc.full_tape, box, 2.0f, s, constant));
    std::vector<uint32_t> out;
    EXPECT_EQ(compact_tape(sc, sc.full_tape, s, out), 2u);
    EXPECT_EQ(out, sc.full_tape);
    // The operator's range holds its values over the box.
    Rng r(3);
    for (int i = 0; i < 200; ++i) {
        const vec3 p = test::random_in_box(r, box.centre - box.half, box.centre + box.half);
        const float f = eval_point(sc, p);
        EXPECT_LE(s.lo[2], f);
        EXPECT_GE(s.hi[2], f);
    }
}

// A difference (and an intersection) whose right operand wins everywhere in the cell: the
// pruned tape is that operand alone, with the sign bit set for the difference, and gives the
// full value exactly.
TEST(PruneStages, RightOperandOfDifferenceKeepsItsSign) {
    for (const uint32_t op : {math::kOpDifference, math::kOpIntersection}) {
        SceneBuilder b;
        // A cell inside the small sphere, on its surface: max(a, -b) = -b (difference) and
        // max(a, b) = b (intersection), far from the big sphere's surface.
        const Scene sc = b.build(b.combine(op, b.sphere(2.0f), b.sphere(1.0f), 0.15f),
                                 {vec3(-2.5f), vec3(2.5f)});
        const bool diff = op == math::kOpDifference;
        ASSERT_EQ(math::tape_negated(sc.full_tape[1]), diff);
        for (const vec3 c : {vec3(0.1f, 0.05f, 0), vec3(0.95f, 0.01f, 0.02f)}) {
            const CellBox box = make_box(c, 0.05f);
            for (const CellBounds bounds : {CellBounds::kInterval, CellBounds::kLipschitz}) {
                CellScratch s;
                const float v = evaluate_cell(sc, sc.full_tape, box, bounds, s);
                EXPECT_FLOAT_EQ(v, eval_point(sc, c));
                // Entry 1 holds the operand as the operator sees it (negated for a difference).
                EXPECT_FLOAT_EQ(s.value[1], diff ? 1 - math::length(c) : math::length(c) - 1);
                EXPECT_EQ(s.decision[2], math::kRightWins);
                std::vector<uint32_t> out;
                EXPECT_EQ(compact_tape(sc, sc.full_tape, s, out), 1u);
                ASSERT_EQ(out.size(), 1u);
                EXPECT_EQ(math::tape_node(out[0]), 1u);
                EXPECT_EQ(math::tape_negated(out[0]), diff);
                expect_tape_exact_in_box(sc, out, box, 2);
            }
        }
    }
}

// Signs compose through a chain of skipped operators: in A − (C − B), where both differences
// are decided for their right operands, the tape is +B (the two negations cancel).
TEST(PruneStages, SignsComposeThroughSkippedOperators) {
    SceneBuilder b;
    const Shape a = b.sphere(3.0f), c = b.sphere(2.5f), bb = b.sphere(1.0f);
    const Scene sc = b.build(smooth_difference(a, smooth_difference(c, bb, 0.1f), 0.1f),
                             {vec3(-3.2f), vec3(3.2f)});
    ASSERT_EQ(sc.size(), 5u);  // A=0, C=1, B=2, C−B=3, root=4
    EXPECT_TRUE(math::tape_negated(sc.full_tape[2]));
    EXPECT_TRUE(math::tape_negated(sc.full_tape[3]));
    const CellBox box = make_box({0.9f, 0.02f, -0.01f}, 0.05f);
    CellScratch s;
    evaluate_cell(sc, sc.full_tape, box, CellBounds::kInterval, s);
    EXPECT_EQ(s.decision[3], math::kRightWins);
    EXPECT_EQ(s.decision[4], math::kRightWins);
    float constant = 0;
    EXPECT_TRUE(is_near_field(sc, sc.full_tape, box, 2.0f, s, constant));
    std::vector<uint32_t> out;
    EXPECT_EQ(compact_tape(sc, sc.full_tape, s, out), 1u);
    EXPECT_EQ(out, (std::vector<uint32_t>{math::tape_word(2, false)}));
    expect_tape_exact_in_box(sc, out, box, 4);

    // The whole pipeline: the finest cell holding that point carries the same tape.
    PruneOptions o;
    o.resolution = 64;
    const PrunedGrid g = prune(sc, o);
    uint32_t x, y, z;
    ASSERT_TRUE(g.cell_index({0.95f, 0.01f, 0.01f}, x, y, z));
    const CellView cv = g.cell(x, y, z);
    ASSERT_FALSE(cv.far_field);
    EXPECT_EQ(cv.primitives, 1u);
    ASSERT_EQ(cv.tape.size(), 1u);
    EXPECT_EQ(cv.tape[0], math::tape_word(2, false));
}

// The stages work on a pruned parent tape, not only the full one: scratch entries are tape
// positions and the output holds node indices.
TEST(PruneStages, StagesRunOnAPrunedParentTape) {
    SceneBuilder b;
    // ((A ∪ B) ∪ C), a parent tape that already dropped A: [B, C, root].
    const Shape a = b.sphere(0.3f).translated({-3, 0, 0});
    const Shape bb = b.sphere(0.3f).translated({0, 0, 0});
    const Shape c = b.sphere(0.3f).translated({3, 0, 0});
    const Scene sc = b.build((a | bb) | c, {vec3(-4), vec3(4)});
    ASSERT_EQ(sc.size(), 5u);  // A=0, B=1, A∪B=2, C=3, root=4
    const std::vector<uint32_t> parent{1, 3, 4};
    const CellBox box = make_box({2.8f, 0.1f, 0}, 0.2f);
    CellScratch s;
    const float v = evaluate_cell(sc, parent, box, CellBounds::kInterval, s);
    EXPECT_FLOAT_EQ(v, eval_point(sc, box.centre));
    EXPECT_EQ(s.left[2], 0u);
    EXPECT_EQ(s.right[2], 1u);
    EXPECT_EQ(s.decision[2], math::kRightWins);
    std::vector<uint32_t> out;
    EXPECT_EQ(compact_tape(sc, parent, s, out), 1u);
    EXPECT_EQ(out, (std::vector<uint32_t>{3}));
    expect_tape_exact_in_box(sc, out, box, 5);
}

// Far-field cells: outside (positive constant) and deep inside (negative), with interval bounds
// nearly the exact minimum of |f| over the box and Lipschitz bounds |f(c)| − R.
TEST(PruneStages, FarFieldConstants) {
    SceneBuilder b;
    const Scene sc = b.build(b.sphere(0.5f) | b.sphere(0.5f).translated({5, 0, 0}),
                             {vec3(-1, -3, -3), vec3(6, 3, 3)});
    const CellBox out_box = make_box({2.5f, 0, 0}, 0.25f);  // halfway between the spheres
    const Scene big = b.build(b.sphere(3.0f), {vec3(-3.5f), vec3(3.5f)});
    const CellBox in_box = make_box({0, 0, 0}, 0.25f);
    for (const CellBounds bounds : {CellBounds::kInterval, CellBounds::kLipschitz}) {
        const bool interval = bounds == CellBounds::kInterval;
        CellScratch s;
        const float v = evaluate_cell(sc, sc.full_tape, out_box, bounds, s);
        EXPECT_FLOAT_EQ(v, 2.0f);
        float constant = 0;
        EXPECT_FALSE(is_near_field(sc, sc.full_tape, out_box, 2.0f, s, constant));
        // min over the box of f is 1.75 (x = 2.25 for A, x = 2.75 for B).
        const float expect = interval ? 1.75f : 2.0f - out_box.radius;
        EXPECT_LE(constant, expect);
        EXPECT_GE(constant, expect - 1e-4f);
        // With a C large enough that the clearance (C − 1)·R reaches f(c) = 2, it is near-field.
        EXPECT_TRUE(
            is_near_field(sc, sc.full_tape, out_box, 1 + 2.0f / out_box.radius, s, constant));

        const float vi = evaluate_cell(big, big.full_tape, in_box, bounds, s);
        EXPECT_FLOAT_EQ(vi, -3.0f);
        EXPECT_FALSE(is_near_field(big, big.full_tape, in_box, 2.0f, s, constant));
        // max over the box is |(0.25, 0.25, 0.25)| − 3, the same for both bounds here.
        EXPECT_GE(constant, -3.0f + in_box.radius);
        EXPECT_LE(constant, -3.0f + in_box.radius + 1e-4f);
    }
}

// ---- 5. statistics and the raw hierarchy against brute force
// --------------------------------------

struct BruteStats {
    uint64_t near = 0;
    double active_sum = 0, active_sq = 0, tape_sum = 0, near_prims = 0;
    uint32_t active_max = 0, tape_max = 0;
};

BruteStats brute_stats(const PrunedGrid& g) {
    BruteStats b;
    const Scene& sc = g.scene();
    const uint32_t N = g.resolution();
    for (uint32_t z = 0; z < N; ++z)
        for (uint32_t y = 0; y < N; ++y)
            for (uint32_t x = 0; x < N; ++x) {
                const CellView cv = g.cell(x, y, z);
                uint32_t active = 1;
                if (!cv.far_field) {
                    uint32_t prims = 0;
                    for (const uint32_t w : cv.tape)
                        prims += sc.is_primitive(math::tape_node(w)) ? 1 : 0;
                    EXPECT_EQ(prims, cv.primitives);
                    active = prims;
                    ++b.near;
                    b.tape_sum += double(cv.tape.size());
                    b.tape_max = std::max(b.tape_max, uint32_t(cv.tape.size()));
                    b.near_prims += prims;
                }
                b.active_sum += active;
                b.active_sq += double(active) * active;
                b.active_max = std::max(b.active_max, active);
            }
    return b;
}

void expect_stats_match(const PrunedGrid& g, const std::string& what) {
    const PruneStats& st = g.stats();
    const uint32_t N = g.resolution();
    const double cells = double(N) * N * N;
    const BruteStats b = brute_stats(g);
    const double avg = b.active_sum / cells;
    const double std_dev = std::sqrt(std::max(0.0, b.active_sq / cells - avg * avg));
    EXPECT_EQ(st.grid, N) << what;
    EXPECT_EQ(st.cells, uint64_t(N) * N * N) << what;
    EXPECT_EQ(st.levels,
              grid_levels(g.options().resolution, g.options().factor, g.options().hierarchy))
        << what;
    EXPECT_EQ(st.near_field_cells, b.near) << what;
    EXPECT_NEAR(st.active_avg, avg, 1e-9) << what;
    EXPECT_NEAR(st.active_std, std_dev, 1e-9) << what;
    EXPECT_EQ(st.active_max, b.active_max) << what;
    EXPECT_NEAR(st.tape_avg, b.near ? b.tape_sum / double(b.near) : 0.0, 1e-9) << what;
    EXPECT_EQ(st.tape_max, b.tape_max) << what;
    EXPECT_NEAR(st.near_field_prims_avg, b.near ? b.near_prims / double(b.near) : 0.0, 1e-9)
        << what;
    EXPECT_GT(st.tape_bytes, 0u) << what;
    EXPECT_GE(st.prune_peak_bytes, st.tape_bytes) << what;
    EXPECT_GE(st.prune_ms, 0.0) << what;
}

// Walks the raw hierarchy as prune.hpp documents it (level 0 z-major, children blocks of f³)
// and checks: the blocks tile every level exactly once; a near-field child's tape uses only
// nodes of its parent's tape, is no longer, and equals it when equally long (coarse tapes are
// the full tree's unless PruneOptions::coarse_tapes); near-field cells store the tree's value at
// their centre; far-field cells store a bound and a centre value with the sign of f there and no
// larger magnitude.
void check_hierarchy(const PrunedGrid& g, Failures& fail) {
    const Scene& sc = g.scene();
    const Aabb& box = g.aabb();
    const vec3 extent = box.max - box.min;
    const auto pool = g.tape_pool();
    struct Ref {
        uint32_t x, y, z;
        uint32_t parent_tape;  // offset of the parent's tape; kNone: the full tree
    };
    std::vector<Ref> refs;  // per cell of the current level
    const uint32_t r0 = g.level_resolution(0);
    if (g.level_cells(0).size() != size_t(r0) * r0 * r0) {
        fail.add(
            [&](std::ostream& os) { os << "level 0 has " << g.level_cells(0).size() << " cells"; });
        return;
    }
    for (uint32_t i = 0; i < r0 * r0 * r0; ++i)
        refs.push_back({i % r0, (i / r0) % r0, i / (r0 * r0), kNone});
    Rng rng(11);
    std::vector<float> stack(sc.max_stack + 1);
    for (uint32_t l = 0; l < g.level_count(); ++l) {
        const auto cells = g.level_cells(l);
        const uint32_t res = g.level_resolution(l);
        const vec3 csize = extent / float(res);
        const bool finest = l + 1 == g.level_count();
        const uint32_t f = finest ? 0 : g.level_resolution(l + 1) / res;
        const size_t next_size = finest ? 0 : g.level_cells(l + 1).size();
        std::vector<Ref> next(next_size, Ref{kNone, kNone, kNone, kNone});
        for (size_t i = 0; i < cells.size(); ++i) {
            const PrunedCell& c = cells[i];
            const Ref& ref = refs[i];
            const vec3 centre =
                box.min +
                vec3(float(ref.x) + 0.5f, float(ref.y) + 0.5f, float(ref.z) + 0.5f) * csize;
            const float fc = eval_point(sc, centre);
            const auto where = [&](std::ostream& os) {
                os << " (level " << l << ", cell " << i << " at " << ref.x << "," << ref.y << ","
                   << ref.z << ")";
            };
            if (c.tape == PrunedCell::kFarField) {
                const bool sign_ok = (fc > 0 && c.bound > 0 && c.value > 0) ||
                                     (fc < 0 && c.bound < 0 && c.value < 0);
                if (!sign_ok || std::fabs(c.bound) > std::fabs(fc) ||
                    std::fabs(c.value) > std::fabs(fc) * (1 + 1e-6f) + 1e-6f)
                    fail.add([&](std::ostream& os) {
                        os << "far-field cell with bound " << c.bound << ", value " << c.value
                           << " but f(centre) = " << fc;
                        where(os);
                    });
                // The bound holds over the whole (coarse) cell.
                for (int k = 0; k < 4; ++k) {
                    const vec3 p =
                        test::random_in_box(rng, centre - csize * 0.5f, centre + csize * 0.5f);
                    const float fp = eval_point(sc, p);
                    if (!(fc > 0 ? (c.bound <= fp) : (c.bound >= fp)))
                        fail.add([&](std::ostream& os) {
                            os << "far-field bound " << c.bound << " exceeds |f| = " << fp << " at "
                               << test::str(p);
                            where(os);
                        });
                }
                continue;
            }
            if (!test::within_rel(c.value, fc))
                fail.add([&](std::ostream& os) {
                    os << "near-field cell value " << c.value << " != f(centre) " << fc;
                    where(os);
                });
            if (size_t(c.tape) + 2 > pool.size() ||
                size_t(c.tape) + 2 + pool[c.tape] > pool.size()) {
                fail.add([&](std::ostream& os) {
                    os << "tape offset out of the pool";
                    where(os);
                });
                continue;
            }
            const auto tape = g.tape_at(c.tape);
            std::string why;
            if (!test::tape_well_formed(sc, tape, pool[c.tape + 1], why))
                fail.add([&](std::ostream& os) {
                    os << "malformed tape: " << why;
                    where(os);
                });
            // Against the parent's tape.
            const std::span<const uint32_t> parent = ref.parent_tape == kNone
                                                         ? std::span<const uint32_t>(sc.full_tape)
                                                         : g.tape_at(ref.parent_tape);
            std::unordered_set<uint32_t> parent_nodes;
            for (const uint32_t w : parent) parent_nodes.insert(math::tape_node(w));
            for (const uint32_t w : tape)
                if (!parent_nodes.count(math::tape_node(w))) {
                    fail.add([&](std::ostream& os) {
                        os << "node " << math::tape_node(w) << " not in the parent's tape";
                        where(os);
                    });
                    break;
                }
            if (tape.size() > parent.size())
                fail.add([&](std::ostream& os) {
                    os << "tape longer than its parent's";
                    where(os);
                });
            if (tape.size() == parent.size() &&
                !std::equal(tape.begin(), tape.end(), parent.begin()))
                fail.add([&](std::ostream& os) {
                    os << "tape as long as its parent's but different";
                    where(os);
                });
            if (finest) continue;
            const uint64_t block = uint64_t(f) * f * f;
            if (c.children % block != 0 || c.children + block > next_size) {
                fail.add([&](std::ostream& os) {
                    os << "children block " << c.children << " out of range";
                    where(os);
                });
                continue;
            }
            for (uint32_t j = 0; j < block; ++j) {
                Ref& child = next[c.children + j];
                if (child.x != kNone)
                    fail.add([&](std::ostream& os) {
                        os << "child " << c.children + j << " claimed twice";
                        where(os);
                    });
                child = {ref.x * f + j % f, ref.y * f + (j / f) % f, ref.z * f + j / (f * f),
                         c.tape};
            }
        }
        for (size_t j = 0; j < next.size(); ++j)
            if (next[j].x == kNone) {
                fail.add([&](std::ostream& os) {
                    os << "cell " << j << " of level " << l + 1 << " has no parent";
                });
                break;
            }
        refs.swap(next);
    }
}

// A single unit sphere at grid 64: one primitive per near-field cell, stats = brute force.
TEST(PruneStats, SingleSphere) {
    SceneBuilder b;
    const Scene sc = b.build(b.sphere(1.0f), {vec3(-2.0f), vec3(2.0f)});
    for (const CellBounds bounds : {CellBounds::kInterval, CellBounds::kLipschitz}) {
        PruneOptions o;
        o.resolution = 64;
        o.bounds = bounds;
        o.coarse_tapes = true;
        const PrunedGrid g = prune(sc, o);
        const PruneStats& st = g.stats();
        EXPECT_EQ(st.active_max, 1u);
        EXPECT_EQ(st.tape_avg, 1.0);
        EXPECT_EQ(st.tape_max, 1u);
        EXPECT_EQ(st.active_avg, 1.0);
        EXPECT_EQ(st.active_std, 0.0);
        EXPECT_EQ(st.near_field_prims_avg, 1.0);
        EXPECT_GT(st.near_field_cells, 0u);
        EXPECT_LT(st.near_field_cells, st.cells / 10);
        expect_stats_match(g, "sphere");
        Failures fail("sphere hierarchy");
        check_hierarchy(g, fail);
        EXPECT_EQ(fail.count(), 0u);
    }
    PruneOptions o;
    o.resolution = 32;
    o.far_field = false;
    const PrunedGrid g = prune(sc, o);
    EXPECT_EQ(g.stats().near_field_cells, g.stats().cells);
    EXPECT_EQ(g.stats().active_avg, 1.0);
    expect_stats_match(g, "sphere, no far field");
}

// For a sphere the near-field set is known in closed form: with interval bounds (exact ranges
// over the box) a cell is near-field iff min_box f <= R and max_box f >= −R (C = 2); with
// Lipschitz bounds iff |f(centre)| <= 2R. Cells within a small band of the thresholds are
// not judged (the pruning test keeps a safety margin).
TEST(PruneStats, SphereNearFieldSetIsAsPredicted) {
    SceneBuilder b;
    const vec3 c0(0.13f, -0.07f, 0.21f);
    const Scene sc =
        b.build(b.sphere(1.1f).translated(c0), {vec3(-2, -1.7f, -1.9f), vec3(1.8f, 2.1f, 2.0f)});
    // The cell-level rule with both bounds, then exact ranges over 3³ sub-boxes (refine).
    const struct {
        CellBounds bounds;
        uint32_t refine;
    } configs[] = {
        {CellBounds::kInterval, 1}, {CellBounds::kLipschitz, 1}, {CellBounds::kInterval, 3}};
    for (const auto& config : configs) {
        const CellBounds bounds = config.bounds;
        PruneOptions o;
        o.resolution = 48;
        o.bounds = bounds;
        o.refine = config.refine;
        const PrunedGrid g = prune(sc, o);
        const vec3 cs = g.cell_size();
        const double R = math::length(cs) * 0.5;
        // Exact range of the sphere over the box (centre c, half sizes h): its nearest and
        // farthest points' distances to the sphere's centre, minus the radius.
        const auto range = [&](const vec3& c, const vec3& h, double& fmin, double& fmax) {
            double dn = 0, df = 0;
            for (int a = 0; a < 3; ++a) {
                const double d = std::fabs(double(c[a]) - c0[a]);
                dn += std::pow(std::max(d - h[a], 0.0), 2);
                df += std::pow(d + h[a], 2);
            }
            fmin = std::sqrt(dn) - 1.1;
            fmax = std::sqrt(df) - 1.1;
        };
        uint64_t judged = 0, wrong = 0, near = 0;
        for (uint32_t z = 0; z < 48; ++z)
            for (uint32_t y = 0; y < 48; ++y)
                for (uint32_t x = 0; x < 48; ++x) {
                    const vec3 c = g.cell_center(x, y, z);
                    double d[3], dn = 0, df = 0, dc = 0;
                    for (int a = 0; a < 3; ++a) {
                        d[a] = std::fabs(double(c[a]) - c0[a]);
                        dn += std::pow(std::max(d[a] - cs[a] * 0.5, 0.0), 2);
                        df += std::pow(d[a] + cs[a] * 0.5, 2);
                        dc += d[a] * d[a];
                    }
                    const double fmin = std::sqrt(dn) - 1.1, fmax = std::sqrt(df) - 1.1,
                                 fc = std::sqrt(dc) - 1.1;
                    double margin;  // signed distance of the cell from the decision threshold
                    if (config.refine > 1) {
                        // Near when some sub-box's range comes within the cell's clearance R.
                        margin = -INFINITY;
                        const uint32_t S = config.refine;
                        CellBox box;
                        box.centre = c;
                        box.half = cs * 0.5f;
                        for (uint32_t b = 0; b < S * S * S; ++b) {
                            double lo, hi;
                            range(sub_box_centre(box, S, b % S, b / S % S, b / (S * S)),
                                  box.half / float(S), lo, hi);
                            margin = std::max(margin, std::min(R - lo, hi + R));
                        }
                    } else if (bounds == CellBounds::kInterval) {
                        margin = std::min(R - fmin, fmax + R);  // > 0: near
                    } else {
                        margin = 2 * R - std::fabs(fc);
                    }
                    if (std::fabs(margin) < 1e-4) continue;
                    ++judged;
                    const bool expect_near = margin > 0;
                    near += expect_near;
                    if (g.cell(x, y, z).far_field == expect_near && wrong++ < 5)
                        ADD_FAILURE()
                            << "cell " << x << "," << y << "," << z << " should be "
                            << (expect_near ? "near" : "far") << " (margin " << margin << ")";
                }
        EXPECT_EQ(wrong, 0u);
        EXPECT_GT(judged, 48u * 48 * 48 - 100);
        EXPECT_GT(near, 1000u);
    }
}

// Sub-box refinement only removes: a cell near-field with it is near-field without it, and its
// tape keeps no primitive more (both stay exact: the property tests check the values).
TEST(PruneStats, RefinementOnlyRemoves) {
    uint64_t removed = 0;  // near-field cells made far, and primitives dropped
    for (uint32_t i = 0; i < 4; ++i) {
        test::RandomSceneSpec spec;
        spec.primitives = 12 + 6 * i;
        spec.tree = test::TreeShape(i % 4);
        spec.placement = test::Placement((i + 1) % 5);
        const Scene sc = test::random_scene(900 + i, spec);
        PruneOptions plain, refined;
        plain.resolution = refined.resolution = 32;
        plain.refine = 1;
        refined.refine = 2 + i % 3;
        const PrunedGrid a = prune(sc, plain), b = prune(sc, refined);
        for (uint32_t z = 0; z < 32; ++z)
            for (uint32_t y = 0; y < 32; ++y)
                for (uint32_t x = 0; x < 32; ++x) {
                    const CellView u = a.cell(x, y, z), v = b.cell(x, y, z);
                    if (u.far_field) {
                        EXPECT_TRUE(v.far_field) << x << "," << y << "," << z;
                        continue;
                    }
                    if (v.far_field) {
                        ++removed;
                        continue;
                    }
                    EXPECT_LE(v.primitives, u.primitives) << x << "," << y << "," << z;
                    removed += u.primitives - v.primitives;
                }
        EXPECT_LE(b.stats().active_avg, a.stats().active_avg);
        EXPECT_LE(b.stats().near_field_cells, a.stats().near_field_cells);
    }
    EXPECT_GT(removed, 0u) << "refinement removed nothing";
}

// Brute-force statistics and the hierarchy of random multi-primitive scenes, for both bounds,
// with and without far-field culling, with factor 2 and 4.
TEST(PruneStats, RandomScenesMatchBruteForce) {
    for (uint32_t i = 0; i < 6; ++i) {
        test::RandomSceneSpec spec;
        spec.primitives = 10 + 4 * i;
        spec.tree = test::TreeShape(i % 4);
        spec.placement = test::Placement(i % 5);
        spec.union_share = 0.7f;
        const Scene sc = test::random_scene(2000 + i, spec);
        PruneOptions o;
        o.resolution = i % 2 ? 64 : 32;
        o.factor = i % 3 == 2 ? 2 : 4;
        o.bounds = i % 2 ? CellBounds::kLipschitz : CellBounds::kInterval;
        o.coarse_tapes = true;
        const PrunedGrid g = prune(sc, o);
        const std::string what = "scene " + std::to_string(i);
        expect_stats_match(g, what);
        EXPECT_GT(g.stats().active_max, 1u) << what;
        EXPECT_LT(g.stats().tape_avg, double(sc.size())) << what;
        Failures fail(what + " hierarchy");
        check_hierarchy(g, fail);
        EXPECT_EQ(fail.count(), 0u);
        o.far_field = false;
        const PrunedGrid all = prune(sc, o);
        EXPECT_EQ(all.stats().near_field_cells, all.stats().cells) << what;
        expect_stats_match(all, what + ", no far field");
        Failures fail2(what + " hierarchy, no far field");
        check_hierarchy(all, fail2);
        EXPECT_EQ(fail2.count(), 0u);
    }
}

// Dropping the coarse tapes (the default) changes nothing else: same cells, same finest tapes,
// same statistics; coarse near-field cells refer to the full tree (offset 0). Identical tapes
// pruned in one chunk of 1024 cells are stored once.
TEST(PruneStats, CoarseTapesOnlyChangeCoarseCells) {
    for (uint32_t i = 0; i < 4; ++i) {
        test::RandomSceneSpec spec;
        spec.primitives = 12 + 6 * i;
        spec.tree = test::TreeShape(i % 4);
        spec.placement = test::Placement(i % 5);
        const Scene sc = test::random_scene(4100 + i, spec);
        PruneOptions o;
        o.resolution = i % 2 ? 64 : 48;
        o.factor = i == 3 ? 2 : 4;
        o.far_field = i != 2;
        const PrunedGrid dropped = prune(sc, o);
        o.coarse_tapes = true;
        const PrunedGrid kept = prune(sc, o);
        const std::string what = "scene " + std::to_string(i);
        ASSERT_EQ(dropped.level_count(), kept.level_count()) << what;
        EXPECT_LT(dropped.tape_pool().size(), kept.tape_pool().size()) << what;
        const auto full = dropped.tape_at(0);
        EXPECT_TRUE(std::equal(full.begin(), full.end(), sc.full_tape.begin(), sc.full_tape.end()))
            << what;
        uint64_t differ = 0, coarse_near = 0, duplicates = 0;
        for (uint32_t l = 0; l < kept.level_count(); ++l) {
            const bool finest = l + 1 == kept.level_count();
            const auto a = dropped.level_cells(l), b = kept.level_cells(l);
            ASSERT_EQ(a.size(), b.size()) << what;
            std::unordered_map<std::string, uint32_t> chunk_tapes;  // tape words -> offset
            for (size_t c = 0; c < a.size(); ++c) {
                if (c % 1024 == 0) chunk_tapes.clear();
                const bool same_rest = a[c].children == b[c].children &&
                                       std::memcmp(&a[c].value, &b[c].value, 4) == 0 &&
                                       std::memcmp(&a[c].bound, &b[c].bound, 4) == 0;
                if (b[c].tape == PrunedCell::kFarField) {
                    differ += same_rest && a[c].tape == PrunedCell::kFarField ? 0 : 1;
                    continue;
                }
                if (!finest) {
                    ++coarse_near;
                    differ += same_rest && a[c].tape == 0 ? 0 : 1;
                    continue;
                }
                const auto ta = dropped.tape_at(a[c].tape), tb = kept.tape_at(b[c].tape);
                const bool same_tape =
                    std::equal(ta.begin(), ta.end(), tb.begin(), tb.end()) &&
                    dropped.tape_pool()[a[c].tape + 1] == kept.tape_pool()[b[c].tape + 1];
                differ += same_rest && same_tape ? 0 : 1;
                const std::string key(reinterpret_cast<const char*>(ta.data()), ta.size_bytes());
                const auto [it, fresh] = chunk_tapes.try_emplace(key, a[c].tape);
                duplicates += !fresh && it->second != a[c].tape ? 1 : 0;
            }
        }
        EXPECT_EQ(differ, 0u) << what;
        EXPECT_GT(coarse_near, 0u) << what;
        EXPECT_EQ(duplicates, 0u) << what;
        const PruneStats &sa = dropped.stats(), &sb = kept.stats();
        test::expect_same_prune_stats(sa, sb, what);
        EXPECT_EQ(sa.tape_words_visited, sb.tape_words_visited) << what;
        EXPECT_LT(sa.tape_bytes, sb.tape_bytes) << what;
        Failures fail(what + " hierarchy, coarse tapes dropped");
        check_hierarchy(dropped, fail);
        EXPECT_EQ(fail.count(), 0u);
    }
}

// Far-field constants and centre values keep the sign of f for every allowed C (>= 1), whatever
// the subdivision factor. Small C leaves far-field cells close to the surface, where a stand-in
// value moved by the Lipschitz bound can cross zero.
TEST(PruneStats, FarFieldSignsHoldForSmallC) {
    uint64_t bad_points = 0;
    for (uint32_t i = 0; i < 8; ++i) {
        test::RandomSceneSpec spec;
        spec.primitives = 3 + i;
        spec.placement = test::Placement(i % 5);
        spec.union_share = 0.8f;
        const Scene sc = test::random_scene(17 + i, spec);
        for (const uint32_t factor : {4u, 8u}) {
            for (const float C : {1.0f, 1.1f}) {
                PruneOptions o;
                o.resolution = factor == 4 ? 128 : 64;
                o.factor = factor;
                o.far_field_c = C;
                o.coarse_tapes = o.resolution <= 64;  // for check_hierarchy
                const PrunedGrid g = prune(sc, o);
                std::ostringstream what;
                what << "scene " << i << ", grid " << o.resolution << ", factor " << factor
                     << ", C " << C;
                Failures fail(what.str(), 2);
                Rng r(i);
                test::check_points(g, test::sample_points(g, r, 3000, 500, 0), fail);
                bad_points += fail.count();
                Failures hier(what.str() + " hierarchy", 2);
                if (o.resolution <= 64) check_hierarchy(g, hier);
                EXPECT_EQ(fail.count() + hier.count(), 0u) << what.str();
            }
        }
    }
    EXPECT_EQ(bad_points, 0u);
}

// ---- progress and cancellation ------------------------------------------------------------------

TEST(PruneApi, ProgressReachesOneAndCancelThrows) {
    const Scene sc = test::random_scene(3000, test::RandomSceneSpec{});
    std::vector<double> seen;
    PruneOptions o;
    o.resolution = 64;
    o.threads = 1;
    o.progress = [&](double f) { seen.push_back(f); };
    const PrunedGrid g = prune(sc, o);
    ASSERT_FALSE(seen.empty());
    EXPECT_TRUE(std::is_sorted(seen.begin(), seen.end()));
    EXPECT_GE(seen.front(), 0.0);
    EXPECT_DOUBLE_EQ(seen.back(), 1.0);

    std::atomic<bool> cancel{true};
    o.progress = nullptr;
    o.cancel = &cancel;
    EXPECT_THROW(prune(sc, o), PruneCancelled);
    cancel = false;
    const PrunedGrid again = prune(sc, o);
    EXPECT_EQ(again.stats().near_field_cells, g.stats().near_field_cells);
}

// ---- 7. reference scenes at 256³
// --------------------------------------------------------------------

void check_reference_scene(const std::string& path, double avg_lo, double avg_hi, uint32_t max_hi) {
    const Scene sc = load_scene(path);
    const PrunedGrid g = prune(sc);  // 256³, factor 4, C = 2, interval bounds
    const PruneStats& st = g.stats();
    EXPECT_EQ(st.grid, 256u);
    EXPECT_GE(st.active_avg, avg_lo);
    EXPECT_LE(st.active_avg, avg_hi);
    EXPECT_LE(st.active_max, max_hi);
    EXPECT_GT(st.active_max, 1u);
    // DESIGN.md §4: a few percent of the cells stay near-field, with a handful of primitives.
    const double near_share = double(st.near_field_cells) / double(st.cells);
    EXPECT_GT(near_share, 0.005);
    EXPECT_LT(near_share, 0.08);
    EXPECT_GT(st.near_field_prims_avg, 1.5);
    EXPECT_LT(st.near_field_prims_avg, 10.0);
    EXPECT_LT(st.tape_avg, 20.0);
    Failures fail(path);
    Rng r(42);
    const std::vector<vec3> pts = test::sample_points(g, r, 9000, 9000, 2000);
    ASSERT_EQ(pts.size(), 20000u);
    const PointStats ps = test::check_points(g, pts, fail);
    EXPECT_EQ(fail.count(), 0u);
    EXPECT_GT(ps.near, 9000u);
    EXPECT_GT(ps.far, 5000u);
    ::testing::Test::RecordProperty("active_avg", std::to_string(st.active_avg));
    ::testing::Test::RecordProperty("active_max", std::to_string(st.active_max));
    ::testing::Test::RecordProperty("near_field_cells", std::to_string(st.near_field_cells));
    std::printf(
        "%s: active %.4f ± %.4f, max %u; near-field %.2f %%, %.2f primitives, %.2f "
        "words; %.0f ms\n",
        path.c_str(), st.active_avg, st.active_std, st.active_max, 100 * near_share,
        st.near_field_prims_avg, st.tape_avg, st.prune_ms);
}

TEST(PruneReference, Molecule) {
    SDFPRUNE_REQUIRE_SCENE(path, "molecule.json");
    check_reference_scene(path, 1.05, 1.12, 62);
}

TEST(PruneReference, Trees) {
    SDFPRUNE_REQUIRE_SCENE(path, "trees.json");
    check_reference_scene(path, 1.05, 1.16, 40);
}

// ---- 8. a 100,000-deep chain
// ------------------------------------------------------------------------

constexpr uint32_t kChainDepth = 100000;

// kChainDepth + 1 small spheres spread uniformly through a column ten times as tall as the
// pruned AABB [-1, 1]³: the grid holds a tenth of them (a dense forest of ~10,000 surfaces),
// the rest must be pruned away on the way down the hierarchy.
std::vector<vec3> chain_centres() {
    Rng r(99);
    std::vector<vec3> c(kChainDepth + 1);
    for (vec3& p : c) p = test::random_in_box(r, {-0.95f, -0.95f, -9.5f}, {0.95f, 0.95f, 9.5f});
    return c;
}

// A right-deep chain as JSON text: s0 ∪ (s1 ∪ (s2 ∪ ...)), smooth unions, nested 100,000 deep.
std::string right_deep_chain_json(const std::vector<vec3>& centres) {
    std::string out;
    out.reserve(centres.size() * 260);
    char buf[256];
    const auto sphere = [&](vec3 c) {
        std::snprintf(buf, sizeof buf,
                      R"({"nodeType":"primitive","primitiveType":"sphere","radius":0.012,)"
                      R"("matrix":[1,0,0,%.9g,0,1,0,%.9g,0,0,1,%.9g],"color":[0.5,0.5,0.5]})",
                      -c.x, -c.y, -c.z);
        out += buf;
    };
    out += R"({"aabb_min":[-1,-1,-1],"aabb_max":[1,1,1],)";
    for (uint32_t i = 0; i < kChainDepth; ++i) {
        if (i > 0) out += "{";
        out += R"("nodeType":"binaryOperator","blendMode":"union","blendRadius":0.01,)"
               R"("matrix":[1,0,0,0,0,1,0,0,0,0,1,0],"leftChild":)";
        sphere(centres[i]);
        out += R"(,"rightChild":)";
    }
    sphere(centres[kChainDepth]);
    out.append(kChainDepth - 1, '}');
    out += "}";
    return out;
}

void check_deep_chain(const Scene& sc, const std::string& what) {
    ASSERT_EQ(sc.size(), 2 * kChainDepth + 1) << what;
    ASSERT_EQ(scene_info(sc).depth, kChainDepth) << what;
    PruneOptions o;
    o.resolution = 32;
    const PrunedGrid g = prune(sc, o);
    EXPECT_GT(g.stats().near_field_cells, 0u) << what;
    EXPECT_LT(g.stats().tape_max, 1000u) << what;  // pruning did its work
    Failures fail(what);
    Rng r(7);
    const std::vector<vec3> pts = test::sample_points(g, r, 150, 150, 50);
    const PointStats st = test::check_points(g, pts, fail);
    EXPECT_EQ(fail.count(), 0u);
    EXPECT_GT(st.near, 100u);
    // Outside the grid the pruned field is the full tree.
    std::vector<float> stack(sc.max_stack);
    for (int i = 0; i < 10; ++i) {
        const vec3 p = test::random_in_box(r, {-1, -1, 1.01f}, {1, 1, 3});
        uint32_t x, y, z;
        EXPECT_FALSE(g.cell_index(p, x, y, z));
        EXPECT_EQ(g.eval(p, stack.data()), eval_point(sc, p)) << test::str(p);
    }
}

TEST(PruneDeepChain, LeftDeepBuilderChain) {
    const std::vector<vec3> c = chain_centres();
    SceneBuilder b;
    Shape acc = b.sphere(0.012f).translated(c[0]);
    for (uint32_t i = 1; i <= kChainDepth; ++i)
        acc = smooth_union(acc, b.sphere(0.012f).translated(c[i]), 0.01f);
    const Scene sc = b.build(acc, {vec3(-1.0f), vec3(1.0f)});
    EXPECT_LE(sc.max_stack, 2u);
    check_deep_chain(sc, "left-deep chain");
}

TEST(PruneDeepChain, RightDeepJsonChain) {
    const Scene sc = parse_scene(right_deep_chain_json(chain_centres()), "right_deep.json");
    EXPECT_EQ(sc.max_stack, kChainDepth + 1);
    check_deep_chain(sc, "right-deep chain");
}

}  // namespace
}  // namespace sdfprune
