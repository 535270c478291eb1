// The tracer's pruned field (src/render/trace_fields.hpp): its convex blocks, which let a
// convex step run on to a block's exit, against a brute-force reading of the grid; its short
// tapes' evaluation against eval_tape.
#include <gtest/gtest.h>

#include <bit>
#include <cstdint>
#include <vector>

#include "prune_check.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/prune.hpp"
#include "test_util.hpp"
// (The header is trace.cpp's own: this test uses a few of its functions, not all.)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
#include "src/render/trace_fields.hpp"
#pragma GCC diagnostic pop

namespace sdfprune {
namespace {

TEST(TraceFields, ConvexBlocksHoldOneConvexPrimitive) {
    std::vector<Scene> scenes;
    scenes.push_back(test::grains_on_floor());
    scenes.push_back(builtin_scene("demo"));
    for (uint32_t i = 0; i < 3; ++i)
        scenes.push_back(test::random_scene(400 + i, test::varied_spec(i, 24)));
    for (size_t n = 0; n < scenes.size(); ++n) {
        const Scene& sc = scenes[n];
        PruneOptions po;
        po.resolution = 128;
        const PrunedGrid g = prune(sc, po);
        const PrunedField field(g, true);
        ASSERT_FALSE(field.convex_block.empty()) << "scene " << n;
        const uint32_t res = g.resolution(), finest = g.level_count() - 1;
        const uint32_t blocks = g.level_resolution(finest - 1), f = res / blocks;
        const vec3 size = g.level_cell_size(finest - 1);
        uint32_t convex = 0, mixed = 0;
        for (uint32_t bz = 0; bz < blocks; ++bz)
            for (uint32_t by = 0; by < blocks; ++by)
                for (uint32_t bx = 0; bx < blocks; ++bx) {
                    // Brute force, by content: every near-field finest cell of the block has a
                    // tape of one word, the same, a convex primitive not negated; and there is
                    // one. Its first near cell, whose cell the field is asked about.
                    bool any = false, alike = true;
                    uint32_t word = 0, fx = 0, fy = 0, fz = 0;
                    for (uint32_t z = bz * f; z < (bz + 1) * f; ++z)
                        for (uint32_t y = by * f; y < (by + 1) * f; ++y)
                            for (uint32_t x = bx * f; x < (bx + 1) * f; ++x) {
                                const CellView c = g.cell(x, y, z);
                                if (c.far_field) continue;
                                const uint32_t node = math::tape_node(c.tape[0]);
                                const bool one = c.tape.size() == 1 &&
                                                 !math::tape_negated(c.tape[0]) &&
                                                 sc.is_primitive(node) &&
                                                 math::primitive_value_is_convex(sc.kind[node]);
                                alike = alike && one && (!any || c.tape[0] == word);
                                if (!any) {
                                    word = c.tape[0];
                                    fx = x, fy = y, fz = z;
                                }
                                any = true;
                            }
                    if (!any) continue;  // no near-field cell: no convex step asks
                    convex += alike;
                    mixed += !alike;
                    PrunedGrid::Located at;
                    g.locate_cell(fx, fy, fz, at);
                    ASSERT_FALSE(at.far_field());
                    // A convex step runs to the exit of the block's box where it is convex,
                    // else of the cell's. (The field compares tape offsets: the CPU pruner
                    // stores a call's equal tapes once, so here the two answers agree.)
                    const float4 cell_lo = splat(-1), cell_hi = splat(1);
                    float4 lo = cell_lo, hi = cell_hi;
                    field.convex_box(at.cell, int4{int32_t(fx), int32_t(fy), int32_t(fz), 0}, lo,
                                     hi);
                    const bool block_box = !all_xyz(lo == cell_lo);
                    const std::string what = "scene " + std::to_string(n) + ", block " +
                                             std::to_string(bx) + " " + std::to_string(by) + " " +
                                             std::to_string(bz);
                    ASSERT_EQ(block_box, alike) << what;
                    if (block_box)
                        for (int a = 0; a < 3; ++a) {
                            const float corner = g.aabb().min[a] + float(a == 0   ? bx
                                                                         : a == 1 ? by
                                                                                  : bz) *
                                                                       size[a];
                            EXPECT_NEAR(lo[a], corner, 1e-6f) << what;
                            EXPECT_NEAR(hi[a], corner + size[a], 1e-6f) << what;
                        }
                }
        // Both answers occur on the floor (the test is not vacuous); a random scene may have
        // no convex block (a torus, a difference, blends everywhere).
        if (n == 0) {
            EXPECT_GT(convex, 100u);
            EXPECT_GT(mixed, 100u);
        }
    }
}

// tape_value's short paths (one primitive; one operator on two; two operators on three, in both
// post-orders) give eval_tape's value bit for bit, for every sign of every word, and longer
// tapes go to eval_tape itself. The tapes are built from a random scene's nodes: any primitive
// and operator words make a valid tape of these shapes.
TEST(TraceFields, ShortTapesEqualEvalTape) {
    const Scene sc = test::random_scene(77, test::varied_spec(1, 24));
    std::vector<uint32_t> prims, ops;
    for (uint32_t n = 0; n < sc.size(); ++n) (sc.is_primitive(n) ? prims : ops).push_back(n);
    ASSERT_GE(prims.size(), 3u);
    ASSERT_GE(ops.size(), 2u);
    Rng r(5);
    const auto pick = [&](const std::vector<uint32_t>& from) {
        return math::tape_word(from[size_t(r.uniform() * float(from.size())) % from.size()],
                               r.uniform() < 0.5f);
    };
    // 'p': a primitive's word, 'o': an operator's (post-order, operands first)
    const char* shapes[] = {"p", "ppo", "ppopo", "pppoo", "ppopopo", "pppoopo"};
    std::vector<float> stack(64);
    uint32_t compared = 0;
    for (const char* shape : shapes)
        for (uint32_t t = 0; t < 200; ++t) {
            std::vector<uint32_t> tape;
            for (const char* c = shape; *c != 0; ++c) tape.push_back(pick(*c == 'p' ? prims : ops));
            for (uint32_t k = 0; k < 8; ++k) {
                const vec3 p = test::random_in_box(r, sc.aabb.min, sc.aabb.max);
                const float want = eval_tape(sc, tape, p, stack.data());
                const float got = tape_value(sc, tape, p, stack.data());
                ASSERT_EQ(std::bit_cast<uint32_t>(got), std::bit_cast<uint32_t>(want))
                    << shape << ": " << got << " against " << want;
                ++compared;
            }
        }
    EXPECT_EQ(compared, 6u * 200u * 8u);
}

}  // namespace
}  // namespace sdfprune
