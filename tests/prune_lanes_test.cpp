// prune_lanes_test.cpp — the pruning stages' loops over boxes run on several instruction sets (the
// baseline and, on x86-64 processors that have them, AVX2 and AVX-512; src/prune/prune_cell.cpp).
// All must make the same grids bit for bit: same tapes, same constants, same centre values.
#include <gtest/gtest.h>

#include <bit>

#include "prune_check.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/io.hpp"
#include "test_util.hpp"

namespace sdfprune {
namespace {

// Restores the instruction set in use when a test ends.
class LaneIsaScope {
  public:
    LaneIsaScope() : saved_(lane_isa()) {}
    ~LaneIsaScope() { set_lane_isa(saved_); }

  private:
    LaneIsa saved_;
};

const char* isa_name(LaneIsa isa) {
    return isa == LaneIsa::kAvx512 ? "AVX-512" : isa == LaneIsa::kAvx2 ? "AVX2" : "baseline";
}

// The instruction sets this processor has besides the baseline.
std::vector<LaneIsa> wide_isas() {
    std::vector<LaneIsa> isas;
    for (const LaneIsa isa : {LaneIsa::kAvx2, LaneIsa::kAvx512})
        if (lane_isa_supported(isa)) isas.push_back(isa);
    return isas;
}

// The baseline and the wide instruction sets.
std::vector<LaneIsa> every_isa() {
    std::vector<LaneIsa> isas = wide_isas();
    isas.insert(isas.begin(), LaneIsa::kBaseline);
    return isas;
}

// The same scene pruned on every instruction set gives the same cells.
void expect_isas_agree(const Scene& sc, const PruneOptions& o, const std::string& what) {
    LaneIsaScope scope;
    set_lane_isa(LaneIsa::kBaseline);
    const PrunedGrid baseline = prune(sc, o);
    for (const LaneIsa isa : wide_isas()) {
        set_lane_isa(isa);
        const PrunedGrid wide = prune(sc, o);
        EXPECT_TRUE(same_cells(baseline, wide)) << what << ", " << isa_name(isa);
        EXPECT_EQ(baseline.stats().near_field_cells, wide.stats().near_field_cells) << what;
        EXPECT_EQ(baseline.stats().tape_words_visited, wide.stats().tape_words_visited) << what;
    }
}

// set_lane_isa takes exactly the instruction sets lane_isa_supported names, and the default is
// the widest of them.
TEST(PruneLanes, SupportedIsasAreSettable) {
    LaneIsaScope scope;
    const std::vector<LaneIsa> wide = wide_isas();
    EXPECT_EQ(lane_isa(), wide.empty() ? LaneIsa::kBaseline : wide.back());
    for (const LaneIsa isa : {LaneIsa::kBaseline, LaneIsa::kAvx2, LaneIsa::kAvx512}) {
        if (lane_isa_supported(isa)) {
            EXPECT_NO_THROW(set_lane_isa(isa)) << isa_name(isa);
            EXPECT_EQ(lane_isa(), isa);
        } else {
            EXPECT_THROW(set_lane_isa(isa), std::invalid_argument) << isa_name(isa);
        }
    }
}

TEST(PruneLanes, BaselineIsAlwaysAvailable) {
    LaneIsaScope scope;
    EXPECT_NO_THROW(set_lane_isa(LaneIsa::kBaseline));
    EXPECT_EQ(lane_isa(), LaneIsa::kBaseline);
}

// Random scenes with every primitive kind, operator and placement (similarity maps, non-uniform
// scales, shears), both cell bounds, refinement 1-3, no hierarchy: each cell of the two grids
// equal.
TEST(PruneLanes, WideIsasEqualBaselineOnRandomScenes) {
    if (wide_isas().empty()) GTEST_SKIP() << "this processor has no AVX2: only the baseline runs";
    for (uint32_t i = 0; i < 24; ++i) {
        const test::RandomSceneSpec spec = test::varied_spec(i, 3 + i * 2);
        const Scene sc = test::random_scene(4200 + i, spec);
        PruneOptions o;
        o.resolution = i % 2 ? 64 : 48;
        o.refine = 1 + i % 3;
        o.bounds = i % 4 == 1 ? CellBounds::kLipschitz : CellBounds::kInterval;
        o.hierarchy = i % 6 != 5;
        expect_isas_agree(sc, o, "random scene " + std::to_string(i));
    }
}

// eval_tape_lanes (eval.hpp) gives eval_tape's values bit for bit, on every instruction set, for
// every batch size, on random scenes (every kind, operator and placement), with the full tree
// and with pruned tapes.
TEST(PruneLanes, PointLanesEqualEvalTape) {
    LaneIsaScope scope;
    std::vector<LaneIsa> isas = wide_isas();
    isas.push_back(LaneIsa::kBaseline);
    for (uint32_t i = 0; i < 12; ++i) {
        const test::RandomSceneSpec spec = test::varied_spec(i, 2 + i * 3);
        const Scene sc = test::random_scene(5100 + i, spec);
        PruneOptions o;
        o.resolution = 16;
        const PrunedGrid grid = prune(sc, o);
        Rng r(77 + i);
        std::vector<float> stack(sc.max_stack), lane_stack(size_t(sc.max_stack) * kEvalLanes);
        for (const LaneIsa isa : isas) {
            set_lane_isa(isa);
            for (uint32_t count = 1; count <= kEvalLanes; ++count) {
                PointLanes p;
                vec3 pts[kEvalLanes];
                const uint32_t cx = uint32_t(r.next_u64() % 16), cy = uint32_t(r.next_u64() % 16),
                               cz = uint32_t(r.next_u64() % 16);
                const CellView cell = grid.cell(cx, cy, cz);
                const vec3 c = grid.cell_center(cx, cy, cz), h = grid.cell_size() * 0.5f;
                for (uint32_t k = 0; k < count; ++k) {
                    pts[k] = c + vec3(r.uniform(-1, 1), r.uniform(-1, 1), r.uniform(-1, 1)) * h;
                    p.x[k] = pts[k].x;
                    p.y[k] = pts[k].y;
                    p.z[k] = pts[k].z;
                }
                for (const std::span<const uint32_t> tape :
                     {std::span<const uint32_t>(sc.full_tape), cell.tape}) {
                    if (tape.empty()) continue;  // a far-field cell
                    PointLanes q = p;
                    float out[kEvalLanes];
                    eval_tape_lanes(sc, tape, q, count, out, lane_stack.data());
                    for (uint32_t k = 0; k < count; ++k) {
                        const float want = eval_tape(sc, tape, pts[k], stack.data());
                        ASSERT_EQ(std::bit_cast<uint32_t>(out[k]), std::bit_cast<uint32_t>(want))
                            << "scene " << i << ", " << count << " points, point " << k << ", "
                            << isa_name(isa);
                    }
                }
            }
        }
    }
}

// A tape of one word (most near-field cells' tapes) takes eval_tape's shortcut past its stack
// loop: the same value bit for bit as the loop of eval_tape_lanes and as the primitive itself,
// for every primitive of random scenes (every kind and placement), with and without its sign.
TEST(PruneLanes, OneWordTapesEqualTheLoop) {
    for (uint32_t i = 0; i < 12; ++i) {
        const Scene sc = test::random_scene(5300 + i, test::varied_spec(i, 2 + i * 3));
        Rng r(91 + i);
        std::vector<float> stack(sc.max_stack), lane_stack(size_t(sc.max_stack) * kEvalLanes);
        const vec3 lo = sc.aabb.min, size = sc.aabb.max - sc.aabb.min;
        for (uint32_t n = 0; n < sc.size(); ++n) {
            if (sc.kind[n] >= math::kPrimitiveKindCount) continue;
            PointLanes p;
            vec3 pts[kEvalLanes];
            for (uint32_t k = 0; k < kEvalLanes; ++k) {
                pts[k] = lo + vec3(r.uniform(0, 1), r.uniform(0, 1), r.uniform(0, 1)) * size;
                p.x[k] = pts[k].x;
                p.y[k] = pts[k].y;
                p.z[k] = pts[k].z;
            }
            for (const bool negated : {false, true}) {
                const uint32_t tape[1] = {math::tape_word(n, negated)};
                float out[kEvalLanes];
                PointLanes q = p;
                eval_tape_lanes(sc, tape, q, kEvalLanes, out, lane_stack.data());
                for (uint32_t k = 0; k < kEvalLanes; ++k) {
                    const float v =
                        math::eval_primitive(sc.kind[n], sc.params[sc.primitive[n]], pts[k]);
                    const float got = eval_tape(sc, tape, pts[k], stack.data());
                    ASSERT_EQ(std::bit_cast<uint32_t>(got), std::bit_cast<uint32_t>(out[k]))
                        << "scene " << i << ", node " << n << ", point " << k;
                    ASSERT_EQ(std::bit_cast<uint32_t>(got),
                              std::bit_cast<uint32_t>(negated ? -v : v));
                }
            }
        }
    }
}

TEST(PruneLanes, WideIsasEqualBaselineOnReferenceScenes) {
    if (wide_isas().empty()) GTEST_SKIP() << "this processor has no AVX2: only the baseline runs";
    for (const char* file : {"molecule.json", "trees.json"}) {
        SDFPRUNE_REQUIRE_SCENE(path, file);
        PruneOptions o;
        o.resolution = 128;
        expect_isas_agree(load_scene(path), o, file);
    }
}

// refine_cell (prune_cell.cpp) evaluates its sub-boxes in batches and, after the first, only the
// subtrees of the operators still decided alike; given the centre's value and the may_decide hint
// (blend_may_decide), it skips the work they rule out. Its results
// must be those of deciding every sub-box on its own (evaluate_cell on each) and combining them,
// with hints and without. Random scenes (every kind, operator and placement), random boxes,
// S = 2-4, both bounds, with and without the far field.
TEST(PruneLanes, RefineCellEqualsEverySubBoxAlone) {
    LaneIsaScope scope;
    const std::vector<LaneIsa> isas = every_isa();
    uint32_t far = 0, decided = 0, undecided = 0;
    for (uint32_t i = 0; i < 24; ++i) {
        const test::RandomSceneSpec spec = test::varied_spec(i, 3 + i * 2);
        const Scene sc = test::random_scene(4400 + i, spec);
        const std::span<const uint32_t> tape = sc.full_tape;
        ASSERT_LE(tape.size(), size_t(math::kRefineMaxTape));
        const uint32_t n = uint32_t(tape.size());
        const float L = sc.lipschitz[math::tape_node(tape.back())];
        const vec3 extent = sc.aabb.max - sc.aabb.min;
        Rng r(4500 + i);
        CellScratch s, one;
        for (uint32_t k = 0; k < 60; ++k) {
            const float size = std::max({extent.x, extent.y, extent.z}) * r.uniform(0.004f, 0.2f);
            const vec3 half = vec3(r.uniform(0.5f, 1.0f), r.uniform(0.5f, 1.0f), 1.0f) * size;
            const CellBox box{test::random_in_box(r, sc.aabb.min, sc.aabb.max), half,
                              math::length(half)};
            const uint32_t S = 2 + k % 3;
            const CellBounds bounds = k % 4 == 1 ? CellBounds::kLipschitz : CellBounds::kInterval;
            const bool far_field = k % 5 != 4;
            const float C = k % 7 == 3 ? 4.0f : 2.0f;
            set_lane_isa(isas[k / 3 % isas.size()]);

            // Every sub-box alone: its decisions, and its root's far-field range.
            const vec3 sub_half = box.half / float(S);
            const float sub_radius = math::length(sub_half);
            const float clearance = math::far_field_clearance(C, L, box.radius);
            std::vector<uint32_t> common(n, uint32_t(math::kKeepBoth));
            bool above = far_field, below = far_field;
            float lowest = INFINITY, highest = -INFINITY;
            for (uint32_t b = 0; b < S * S * S; ++b) {
                const CellBox sub{sub_box_centre(box, S, b % S, b / S % S, b / (S * S)), sub_half,
                                  sub_radius};
                evaluate_cell(sc, tape, sub, bounds, one, /*sub_box=*/true);
                for (uint32_t e = 0; e < n; ++e) {
                    if (sc.is_primitive(math::tape_node(tape[e]))) continue;
                    if (b == 0)
                        common[e] = one.decision[e];
                    else if (common[e] != one.decision[e])
                        common[e] = math::kKeepBoth;
                }
                const vec2 range = math::far_field_range(one.value[n - 1], one.lo[n - 1],
                                                         one.hi[n - 1], L, sub_radius);
                above = above && math::clears_above(range.x, clearance);
                below = below && math::clears_below(range.y, clearance);
                lowest = std::min(lowest, range.x);
                highest = std::max(highest, range.y);
            }

            // The hints, from the values at the box's centre.
            evaluate_cell(sc, tape, box, bounds, one);
            bool may_decide = k % 3 == 0;
            for (uint32_t e = 0; e < n; ++e) {
                const uint32_t node = math::tape_node(tape[e]);
                if (!sc.is_primitive(node))
                    may_decide = may_decide ||
                                 math::blend_may_decide(one.value[one.left[e]],
                                                        one.value[one.right[e]], sc.blend[node]);
            }
            float constant = 0;
            const bool near = refine_cell(sc, tape, box, S, bounds, far_field, C, one.value[n - 1],
                                          may_decide, s, constant);
            const std::string what = "scene " + std::to_string(i) + ", box " + std::to_string(k);
            ASSERT_EQ(near, !(above || below)) << what;
            if (!near) {
                EXPECT_EQ(std::bit_cast<uint32_t>(constant),
                          std::bit_cast<uint32_t>(above ? lowest : highest))
                    << what;
                ++far;
                continue;
            }
            bool any = false;
            for (uint32_t e = 0; e < n; ++e) {
                ASSERT_EQ(s.decision[e], common[e]) << what << ", entry " << e;
                any = any || common[e] != math::kKeepBoth;
            }
            ++(any ? decided : undecided);
        }
    }
    // Every outcome was met: far-field, some operator decided, nothing decided.
    EXPECT_GT(far, 20u);
    EXPECT_GT(decided, 20u);
    EXPECT_GT(undecided, 20u);
}

// refine_cells refines several cells sharing one tape together, their sub-boxes packed into the
// same lanes; each cell's result is what refine_cell gives alone, bit for bit: the same outcome,
// constant and decisions, for groups of 2 to 8 cells of a block, on every instruction set.
TEST(PruneLanes, RefineCellsOfAGroupEqualEachCellAlone) {
    LaneIsaScope scope;
    const std::vector<LaneIsa> isas = every_isa();
    uint32_t far = 0, decided = 0, undecided = 0;
    for (uint32_t i = 0; i < 20; ++i) {
        const test::RandomSceneSpec spec = test::varied_spec(i, 3 + i * 2);
        const Scene sc = test::random_scene(4600 + i, spec);
        const std::span<const uint32_t> tape = sc.full_tape;
        ASSERT_LE(tape.size(), size_t(math::kRefineMaxTape));
        const uint32_t n = uint32_t(tape.size());
        const vec3 extent = sc.aabb.max - sc.aabb.min;
        Rng r(4700 + i);
        CellScratch grouped, alone;
        for (uint32_t k = 0; k < 24; ++k) {
            // `count` cells of a 2×2×2 block of cells of one size.
            const float size = std::max({extent.x, extent.y, extent.z}) * r.uniform(0.004f, 0.1f);
            const vec3 half = vec3(r.uniform(0.5f, 1.0f), r.uniform(0.5f, 1.0f), 1.0f) * size;
            const vec3 origin = test::random_in_box(r, sc.aabb.min, sc.aabb.max);
            const uint32_t count = 2 + k % 7, S = 2 + k % 3;
            const CellBounds bounds = k % 5 == 1 ? CellBounds::kLipschitz : CellBounds::kInterval;
            const bool far_field = k % 6 != 5;
            set_lane_isa(isas[k % isas.size()]);
            CellBox boxes[kSiblingLanes];
            float values[kSiblingLanes];
            bool may_decide[kSiblingLanes];
            for (uint32_t c = 0; c < count; ++c) {
                const vec3 at(float(c & 1), float(c >> 1 & 1), float(c >> 2 & 1));
                boxes[c] = {origin + (at * 2.0f + 1.0f) * half, half, math::length(half)};
                values[c] = evaluate_cell(sc, tape, boxes[c], bounds, alone);
                may_decide[c] = (k + c) % 4 != 3;
            }
            RefineResult results[kSiblingLanes];
            refine_cells(sc, tape, boxes, count, S, bounds, far_field, 2.0f, values, may_decide,
                         grouped, results);
            for (uint32_t c = 0; c < count; ++c) {
                const std::string what = "scene " + std::to_string(i) + ", group " +
                                         std::to_string(k) + ", cell " + std::to_string(c);
                float constant = 0;
                const bool near = refine_cell(sc, tape, boxes[c], S, bounds, far_field, 2.0f,
                                              values[c], may_decide[c], alone, constant);
                ASSERT_EQ(near, results[c].near) << what;
                if (!near) {
                    EXPECT_EQ(std::bit_cast<uint32_t>(constant),
                              std::bit_cast<uint32_t>(results[c].constant))
                        << what;
                    ++far;
                    continue;
                }
                bool any = false;
                for (uint32_t e = 0; e < n; ++e) {
                    any = any || alone.decision[e] != math::kKeepBoth;
                    if (results[c].decided) {
                        ASSERT_EQ(alone.decision[e], grouped.refine_decision[c * n + e])
                            << what << ", entry " << e;
                    }
                }
                ASSERT_EQ(any, results[c].decided) << what;
                ++(any ? decided : undecided);
            }
        }
    }
    // Every outcome was met: far-field, some operator decided, nothing decided.
    EXPECT_GT(far, 20u);
    EXPECT_GT(decided, 20u);
    EXPECT_GT(undecided, 5u);  // 10 with these seeds
}

// Parent tapes longer than kSiblingMaxTape are pruned one cell at a time (prune_level.cpp): a
// scene of 40,000 primitives, whose top levels' tapes exceed it, still prunes exactly.
TEST(PruneLanes, LongParentTapesPruneExactly) {
    test::RandomSceneSpec spec;
    spec.primitives = 40000;
    spec.tree = test::TreeShape::kBalanced;
    spec.placement = test::Placement::kMixed;
    spec.smooth_prob = 0.5f;
    const Scene sc = test::random_scene(4300, spec);
    ASSERT_GT(sc.full_tape.size(), size_t(kSiblingMaxTape));
    PruneOptions o;
    o.resolution = 32;
    o.factor = 2;  // levels 2, 4, 8, 16, 32: the first split levels start from the full tape
    const PrunedGrid g = prune(sc, o);
    test::Failures fail("40,000 primitives, grid 32, factor 2");
    Rng r(4301);
    const test::PointStats st =
        test::check_points(g, test::sample_points(g, r, 500, 1500, 200), fail);
    EXPECT_EQ(fail.count(), 0u) << fail.context();
    EXPECT_GT(st.near, 500u);
}

}  // namespace
}  // namespace sdfprune
