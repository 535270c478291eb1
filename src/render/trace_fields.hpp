// trace_fields.hpp — what the tracer (trace.cpp) marches rays through, for its one translation
// unit: the two fields, the full tree's (NaiveField) and the pruned grid's (PrunedField: cell
// lookups, the tile cones' free space), with the vector helpers and the short-tape evaluation
// their steps share. Everything here is internal to trace.cpp (an unnamed namespace).
#pragma once

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include "sdfprune/eval.hpp"
#include "sdfprune/prune.hpp"
#include "sdfprune/render.hpp"

namespace sdfprune {
namespace {
vec3 normalize(vec3 v) {
    return v / math::length(v);
}
vec3 cross(vec3 a, vec3 b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

// Four floats in one SIMD register (GCC/Clang vector extension, any target): a point's x, y, z
// and an unused lane. Each operation is the IEEE operation of the scalar vec3 code it stands
// for, lane by lane and in the same order, so the tracer's steps are bit for bit those of that
// code; it only takes fewer instructions.
using float4 = float __attribute__((vector_size(16)));
using int4 = int32_t __attribute__((vector_size(16)));

float4 splat(float v) {
    return float4{v, v, v, v};
}
float4 load4(vec3 v) {
    return float4{v.x, v.y, v.z, 0};
}
// math::min and math::max (a < b ? a : b), lane by lane.
float4 min4(float4 a, float4 b) {
    return a < b ? a : b;
}
float4 max4(float4 a, float4 b) {
    return a > b ? a : b;
}
// math::length of (x, y, z): the same sum, in the same order.
float length3(float4 v) {
    const float4 sq = v * v;
    return std::sqrt(sq[0] + sq[1] + sq[2]);
}

// Whether lanes x, y and z of a comparison's mask are all true (the unused lane is ignored).
// With SSE, the three verdicts are taken as one mask (movmskps) rather than one by one: 11
// instructions a box test went to 5 (callgrind, character).
bool all_xyz(int4 mask) {
#if defined(__SSE__)
    return (__builtin_ia32_movmskps(float4(mask)) & 7) == 7;
#else
    return (mask[0] & mask[1] & mask[2]) != 0;
#endif
}

// Whether p lies in the closed box [lo, hi] (x, y, z).
bool in_box(float4 p, float4 lo, float4 hi) {
    return all_xyz((p >= lo) & (p <= hi));
}

// Whether the three lanes (x, y, z) of a and b are equal.
bool all_equal(int4 a, int4 b) {
    return all_xyz(a == b);
}

// Whether the box [lo, hi] holds no point (some min > max: PrunedGrid::near_box without a
// near-field cell). The slab tests below would take it for the box between its corners.
bool empty_box(vec3 lo, vec3 hi) {
    return !(lo.x <= hi.x && lo.y <= hi.y && lo.z <= hi.z);
}

// x⁸ in three multiplications (std::pow took 70 instructions a hit pixel).
float pow8(float x) {
    const float x2 = x * x, x4 = x2 * x2;
    return x4 * x4;
}

// Ray / box intersection: [t0, t1] inside the box, false if missed (always, if it is empty).
bool ray_box(vec3 o, vec3 inv_dir, vec3 lo, vec3 hi, float& t0, float& t1) {
    t0 = 0;
    t1 = INFINITY;
    if (empty_box(lo, hi)) return false;
    for (int a = 0; a < 3; ++a) {
        float ta = (lo[a] - o[a]) * inv_dir[a], tb = (hi[a] - o[a]) * inv_dir[a];
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta);
        t1 = std::min(t1, tb);
    }
    return t0 <= t1;
}

// eval_tape's value of `tape` at p. The tapes of most near-field cells are one primitive (one
// word), one operator on two primitives (three words: post-order, operands first) or two
// operators on three (five words, in two post-orders: "a b op c op" is (a ∘ b) ∘ c, "a b c op
// op" is a ∘ (b ∘ c)). At 256³ city's near-field cells hold 54 %, 32 % and 11 % of these. These
// are eval_tape's loop without the loop and without the call, whose saving of registers cost
// 8 instructions a call (callgrind, character), each word's value negated as eval_tape pushes
// it. Flattened: eval_primitive inline, so its 96 bytes of parameters are read in place rather
// than copied for a call.
float primitive_value(const Scene& sc, uint32_t word, vec3 p) {
    const uint32_t n = math::tape_node(word);
    const float v = math::eval_primitive(sc.kind[n], sc.params[sc.primitive[n]], p);
    return math::tape_negated(word) ? -v : v;
}
float operator_value(const Scene& sc, uint32_t word, float a, float b) {
    const uint32_t n = math::tape_node(word);
    const float v = math::apply_operator(math::operator_s(sc.kind[n]), sc.blend[n], a, b);
    return math::tape_negated(word) ? -v : v;
}
[[gnu::flatten]] float tape_value(const Scene& sc, std::span<const uint32_t> tape, vec3 p,
                                  float* stack) {
    if (tape.size() == 1) return primitive_value(sc, tape[0], p);
    if (tape.size() == 3)
        return operator_value(sc, tape[2], primitive_value(sc, tape[0], p),
                              primitive_value(sc, tape[1], p));
    if (tape.size() != 5) return eval_tape(sc, tape, p, stack);
    const float a = primitive_value(sc, tape[0], p), b = primitive_value(sc, tape[1], p);
    if (!sc.is_primitive(math::tape_node(tape[2])))
        return operator_value(sc, tape[4], operator_value(sc, tape[2], a, b),
                              primitive_value(sc, tape[3], p));
    const float c = primitive_value(sc, tape[2], p);
    return operator_value(sc, tape[4], a, operator_value(sc, tape[3], b, c));
}

// A ray stops (hits) where the field is below kHitBelow · min(1, t).
constexpr float kHitBelow = 5e-4f;

struct Counters {
    uint64_t steps = 0;
    uint64_t evals = 0;
};

// The primary rays of a tile of pixels, from one eye, as a cone: its axis (a unit vector) and
// its spread, the largest |d - axis| over the tile's ray directions d, so that the point at
// distance s along any of those rays lies within s · spread of the axis's point at s. (The
// rays pass through the pixels' centres: their directions' angle to the axis is largest at a
// corner of the tile, the image plane's section of a cone about the axis being convex.)
struct Cone {
    float4 eye, axis;
    float spread;
};

// The largest step from axis distance t after which every point of `cone` at an axis
// distance s in [t, t + step] still lies in the box [lo, hi] (0 if some does not at s = t):
// per axis a, eye_a + s · (axis_a ∓ spread) stays within [lo_a, hi_a], each a linear bound
// in s.
float cone_step_in_box(const Cone& cone, float t, float4 lo, float4 hi) {
    const float4 c = splat(cone.spread), s4 = splat(t);
    const float4 low = cone.eye + s4 * (cone.axis - c), high = cone.eye + s4 * (cone.axis + c);
    if (!all_xyz((low >= lo) & (high <= hi))) return 0;
    // The lower side approaches lo where axis - spread < 0, the upper side hi where
    // axis + spread > 0: the distance s at which each reaches it.
    const float4 down = c - cone.axis, up = cone.axis + c;
    const float4 s_lo = (cone.eye - lo) / down, s_hi = (hi - cone.eye) / up;
    float s_max = INFINITY;
    for (int a = 0; a < 3; ++a) {
        if (down[a] > 0) s_max = std::min(s_max, s_lo[a]);
        if (up[a] > 0) s_max = std::min(s_max, s_hi[a]);
    }
    return std::max(0.0f, s_max - t);
}

// The largest step from axis distance t after which every point of `cone` at an axis
// distance s in [t, t + step] still lies within `radius` of the axis's point at t: such a
// point lies within s · spread + (s - t) of it.
float cone_step_in_ball(const Cone& cone, float t, float radius) {
    return std::max(0.0f, (radius - t * cone.spread) / (1 + cone.spread));
}

// The full tree at every query.
struct NaiveField {
    const Scene& sc;
    // A hit's tape, for its normal's stencil (see PrunedField::Hint).
    struct Hint {
        std::span<const uint32_t> tape;
    };
    Hint hint_at(vec3) const { return {sc.full_tape}; }
    // The box rays are marched in: the scene's.
    Aabb march_box() const { return sc.aabb; }
    // The exact value at p; `hint` is unused.
    float value(vec3 p, const Hint&, float* stack, Counters& c) const {
        c.evals += sc.size();
        return eval_tape(sc, sc.full_tape, p, stack);
    }
};

// What a far-field step needs of a level of the grid, worked out once per image with the
// expressions a step would use (so the steps stay bit for bit the same).
struct LevelGeometry {
    float4 size;  // cell size
    float4 half;  // size · 0.5: from a cell's corner to its centre
    float tiny;   // how far past a cell's exit a far-field step lands: 1e-4 · smallest side
    int shift;    // log2 of the finest cells per cell and axis (when PrunedField::pow2)
};

// The pruned grid.
struct PrunedField {
    const PrunedGrid& g;
    std::vector<LevelGeometry> levels;
    // PrunedGrid::cell_index's terms: the grid's corners, 1 / cell size, the last index
    float4 grid_lo, grid_hi, inv_cell, last_index;
    // Every level's cells hold a power of two finest cells per axis: a cell's coordinates at
    // its level are the finest index >> LevelGeometry::shift.
    bool pow2 = true;
    // Per node: a primitive whose value is a convex function (math::primitive_value_is_convex).
    std::vector<uint8_t> convex;
    // How much two values of one primitive may differ by rounding alone (see convex_step).
    float secant_margin = 0;
    // Per block of the finest level (its cells lie at block · block_cells in level_cells, one
    // block per near-field cell of the level above), once a convex step has asked (0: not
    // yet): 1 where the block is convex, every near-field cell of it having the same tape (by
    // offset: the CPU pruner stores a call's equal tapes once; equal tapes stored apart only
    // make fewer convex blocks), one convex primitive (convex_tape); else 2. In a convex block the
    // field is that primitive in the near cells and has no zero in the far ones, so a convex step
    // may go on to the block's exit rather than its cell's (see convex_step). Found when asked,
    // since most blocks never are (a pass over all of them cost 3–26 ms a render). Empty where not
    // wanted (one ray, no convex steps) or not pow2 or of one level.
    mutable std::vector<std::atomic<uint8_t>> convex_block;
    const PrunedCell* finest_cells = nullptr;
    uint32_t block_cells = 0, block_shift = 0;  // f³ cells a block, log2 of it (f: pow2)
    // `convex_blocks`: keep the blocks' answers (for convex steps over many rays).
    PrunedField(const PrunedGrid& grid, bool convex_blocks) : PrunedField(grid) {
        const uint32_t finest = g.level_count() - 1;
        if (!convex_blocks || !pow2 || finest == 0) return;
        const std::span<const PrunedCell> cells = g.level_cells(finest);
        const uint32_t f = g.level_factor(finest);
        block_cells = f * f * f;
        block_shift = uint32_t(std::countr_zero(block_cells));
        finest_cells = cells.data();
        convex_block = std::vector<std::atomic<uint8_t>>(cells.size() / block_cells);
    }
    bool block_is_convex(size_t b) const {
        const PrunedCell* block = finest_cells + b * block_cells;
        uint32_t tape = PrunedCell::kFarField;
        for (uint32_t k = 0; k < block_cells; ++k) {
            const uint32_t t = block[k].tape;
            if (t == PrunedCell::kFarField) continue;
            if (tape != PrunedCell::kFarField && t != tape) return false;
            tape = t;
        }
        return tape != PrunedCell::kFarField && convex_tape(g.tape_at(tape));
    }
    // The box a convex step in finest near-field cell `cell` (index i; lo, hi its box) may go
    // to the exit of: the cell's, or its block's where that block is convex. (Threads that
    // ask about one block at once find the same answer.)
    void convex_box(const PrunedCell* cell, int4 i, float4& lo, float4& hi) const {
        if (convex_block.empty()) return;
        const size_t b = size_t(cell - finest_cells) >> block_shift;
        uint8_t state = convex_block[b].load(std::memory_order_relaxed);
        if (state == 0) {
            state = block_is_convex(b) ? 1 : 2;
            convex_block[b].store(state, std::memory_order_relaxed);
        }
        if (state != 1) return;
        const LevelGeometry& geo = levels[levels.size() - 2];
        const int4 c = i >> geo.shift;
        lo = grid_lo + __builtin_convertvector(int4{c[0], c[1], c[2], 0}, float4) * geo.size;
        hi = lo + geo.size;
    }
    explicit PrunedField(const PrunedGrid& grid)
        : g(grid),
          grid_lo(load4(grid.aabb().min)),
          grid_hi(load4(grid.aabb().max)),
          inv_cell(load4(grid.inv_cell_size())),
          last_index(splat(float(grid.resolution() - 1))) {
        const uint32_t n = g.resolution();
        for (uint32_t l = 0; l < g.level_count(); ++l) {
            const vec3 size = g.level_cell_size(l);
            const uint32_t scale = n / g.level_resolution(l);
            pow2 = pow2 && std::has_single_bit(scale) && scale * g.level_resolution(l) == n;
            levels.push_back({load4(size), load4(size * 0.5f),
                              1e-4f * std::min({size.x, size.y, size.z}), std::countr_zero(scale)});
        }
        const Scene& sc = g.scene();
        convex.resize(sc.size());
        for (uint32_t n = 0; n < sc.size(); ++n)
            convex[n] = sc.is_primitive(n) && math::primitive_value_is_convex(sc.kind[n]);
        secant_margin = 1e-5f * math::length(sc.aabb.max - sc.aabb.min);
    }
    // Whether `tape` is one primitive, not negated, whose value is convex.
    bool convex_tape(std::span<const uint32_t> tape) const {
        return tape.size() == 1 && !math::tape_negated(tape[0]) && convex[math::tape_node(tape[0])];
    }
    // The finest cell holding p in the grid's closed box: PrunedGrid::cell_index's,
    // min(uint(x), last) for x = (p - corner) / size, computed as uint(min(x, last)): the same
    // for x >= 0 (and resolutions below 2^24), in a few vector instructions.
    int4 finest_index(float4 p) const {
        return __builtin_convertvector(min4((p - grid_lo) * inv_cell, last_index), int4);
    }
    // A hit's tape (its cell's, or the full tree's), for its normal's stencil, with the finest
    // cell the hit lies in: a stencil point in that cell has that tape, which value() then
    // takes with no lookup. Most stencil points are: at 256³ the stencil's offsets are about a
    // tenth of a cell.
    struct Hint {
        std::span<const uint32_t> tape;
        bool in_grid = false;
        int4 index = {};  // the finest cell (x, y, z, 0), when in_grid
    };
    // PrunedGrid::cell_index in vector lanes: whether p lies in the grid's closed box (the same
    // comparisons) and, if so, its finest cell (see finest_index: the same index for p >= the
    // corner), with 0 in the unused lane.
    bool finest_cell(vec3 p, int4& index) const {
        const float4 q = load4(p);
        if (!in_box(q, grid_lo, grid_hi)) return false;
        index = finest_index(q);
        index[3] = 0;
        return true;
    }
    // Sets `tape` to finest cell i's tape, if it is near-field.
    void near_tape(int4 i, std::span<const uint32_t>& tape) const {
        PrunedGrid::Located at;
        g.locate_cell(uint32_t(i[0]), uint32_t(i[1]), uint32_t(i[2]), at);
        if (!at.far_field()) tape = g.tape_at(at.cell->tape);
    }
    // The box rays are marched in: the near-field cells' (PrunedGrid::near_box), which holds
    // the surface. A ray starts at its entry, past the empty margin of the scene's box, and one
    // that misses it is not marched.
    const Aabb& march_box() const { return g.near_box(); }
    Hint hint_at(vec3 p) const {
        Hint h{g.scene().full_tape};
        if (!finest_cell(p, h.index)) return h;
        h.in_grid = true;
        near_tape(h.index, h.tape);
        return h;
    }
    // How far the rays of `cone` may start along its axis, from t (where none of them has
    // entered the box rays are marched in): every point of the cone before it lies outside that
    // box, or in far-field cells of positive value (the tracer never stops there: it steps
    // through them), or where the field is at least kHitBelow (none of the rays' steps can stop
    // there). Cone marching (Amanatides' cones, as demo renderers march a tile's rays): each
    // step takes the free space around the axis's point (a box of far-field cells, from the
    // cell's clearances in every octant, or a ball from the field's value or the cell's bound)
    // and moves on as far as the cone's section stays in it. INFINITY when the cone leaves the
    // box [.., t_end]: no ray of it meets the surface.
    static constexpr uint32_t kMaxConeSteps = 64;
    float cone_start(const Cone& cone, float t, float t_end, float* stack, Counters& c) const {
        const Aabb& box = g.near_box();
        const float4 box_lo = load4(box.min), box_hi = load4(box.max);
        const float inv_lipschitz = 1.0f / g.scene().lipschitz[g.scene().root()];
        // (a twentieth of a finest cell's smallest side, of which `tiny` is 1e-4)
        const float min_step = 500 * levels.back().tiny;
        for (uint32_t i = 0; i < kMaxConeSteps; ++i) {
            if (t > t_end) return INFINITY;
            ++c.steps;
            const float4 q = cone.eye + cone.axis * splat(t);
            // The distance from q to the box (0 inside): a ball of it around q is outside.
            const float4 outside = max4(max4(box_lo - q, q - box_hi), splat(0));
            float step = cone_step_in_ball(cone, t, length3(outside));
            if (in_box(q, grid_lo, grid_hi)) {
                PrunedGrid::Located at;
                const int4 i4 = finest_index(q);
                g.locate_cell(uint32_t(i4[0]), uint32_t(i4[1]), uint32_t(i4[2]), at);
                const PrunedCell& cell = *at.cell;
                if (!at.far_field()) {
                    const std::span<const uint32_t> tape = g.tape_at(cell.tape);
                    c.evals += tape.size();
                    const float d = tape_value(g.scene(), tape, vec3(q[0], q[1], q[2]), stack);
                    step =
                        std::max(step, cone_step_in_ball(cone, t, (d - kHitBelow) * inv_lipschitz));
                } else if (cell.value > 0) {
                    const LevelGeometry& geo = levels[at.level];
                    const float4 lo =
                        grid_lo +
                        __builtin_convertvector(
                            int4{int32_t(at.x), int32_t(at.y), int32_t(at.z), 0}, float4) *
                            geo.size;
                    uint32_t r = kMaxClearance;
                    for (uint32_t o = 0; o < 8; ++o) r = std::min(r, clearance_in(cell, o));
                    const float4 reach = geo.size * splat(float(r));
                    step = std::max(step,
                                    cone_step_in_box(cone, t, lo - reach, lo + geo.size + reach));
                    const float from_centre =
                        cell.value * inv_lipschitz - length3(q - (lo + geo.half));
                    const float free = std::max(std::fabs(cell.bound) * inv_lipschitz, from_centre);
                    step = std::max(step,
                                    cone_step_in_ball(cone, t, free - kHitBelow * inv_lipschitz));
                }
            }
            if (step < min_step) return t;
            t += step;
        }
        return t;
    }
    // The pruned field at p: its cell's tape, or the hint's where p's cell is far-field (that
    // cell holds a bound, not a value) or is the hit's.
    float value(vec3 p, const Hint& hint, float* stack, Counters& c) const {
        std::span<const uint32_t> tape = hint.tape;
        int4 i;
        if (finest_cell(p, i) && !(hint.in_grid && all_equal(i, hint.index))) near_tape(i, tape);
        c.evals += tape.size();
        return tape_value(g.scene(), tape, p, stack);
    }
};

}  // namespace
}  // namespace sdfprune
