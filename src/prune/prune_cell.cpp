// prune_cell.cpp — pruning one cell (DESIGN.md §3–4): evaluate the parent's tape at the cell
// centre with a range per entry, decide each operator, test the far field, then the top-down
// pass that compacts the tape. The math of the tests lives in sdf_math.h. The stages run on
// several boxes at once (sibling cells, a cell's sub-boxes) in vector lanes, compiled for the
// baseline instruction set and for AVX2, with the same results bit for bit.
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <stdexcept>
#include <utility>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "../core/lanes.hpp"
#include "sdfprune/eval.hpp"  // lane_isa
#include "sdfprune/prune.hpp"

namespace sdfprune {

void CellScratch::reserve(size_t n) {
    if (value.size() >= n) return;
    for (auto* v : {&value, &lo, &hi}) v->resize(n);
    for (auto* v : {&left, &right, &decision, &stack}) v->resize(n);
    alive.resize(n);
    negate.resize(n);
}

void CellScratch::reserve_siblings(size_t want) {
    if (sib_value.size() >= want) return;
    for (auto* v : {&sib_value, &sib_lo, &sib_hi}) v->resize(want);
    sib_decision.resize(want);
}

size_t CellScratch::bytes() const {
    size_t b = 0;
    const auto add = [&b](const auto& v) { b += v.capacity() * sizeof(v[0]); };
    for (const auto* v : {&value, &lo, &hi, &lane_value, &lane_lo, &lane_hi, &sib_value, &sib_lo,
                          &sib_hi, &sub_offset[0], &sub_offset[1], &sub_offset[2]})
        add(*v);
    for (const auto* v : {&left, &right, &decision, &stack, &lane_decision, &sib_decision,
                          &refine_decision, &refine_needed})
        add(*v);
    add(alive);
    add(negate);
    for (uint32_t i = 0; i < 8; ++i) {
        add(octants[i]);
        add(cell_tapes[i]);
        add(refine_cands[i]);
    }
    return b;
}

namespace {

// Sub-boxes of a cell evaluated in one batch by refine_cells after its first (its corners), for
// each of up to kSiblingLanes cells at once.
constexpr uint32_t kLanes = 32;
constexpr uint32_t kBoxLanes = kLanes * kSiblingLanes;

// Boxes are evaluated in blocks of lanes::kBlock lanes (lanes.hpp): every loop over boxes runs
// over structure-of-arrays data to a multiple of the block, with the same results bit for bit as
// one box at a time. The lanes past the boxes repeat the last box; nothing reads them.
using lanes::kBlock;
using lanes::lanes_for;
using lanes::lanes_of;
static_assert(kSiblingGroupLanes <= kBoxLanes);

// The centres of up to kBoxLanes boxes, coordinate by coordinate, and the lanes to compute.
struct BoxLanes {
    alignas(32) float x[kBoxLanes];
    alignas(32) float y[kBoxLanes];
    alignas(32) float z[kBoxLanes];
    uint32_t lanes = 0;  // 1 for a single box, else the boxes rounded up to whole blocks
};

BoxLanes box_lanes(const vec3* centres, uint32_t count) {
    BoxLanes c;
    c.lanes = lanes_for(count);
    for (uint32_t b = 0; b < c.lanes; ++b) {
        const vec3 p = centres[std::min(b, count - 1)];
        c.x[b] = p.x;
        c.y[b] = p.y;
        c.z[b] = p.z;
    }
    return c;
}

// What an undecided operator's range is, and whether its value is computed (decide_boxes):
//   kSiblings:     the value, and the tighter of its Lipschitz range and (interval bounds) its
//                  range over its operands' ranges;
//   kRefine:       refinement's sub-boxes (interval bounds): the value, and its range over its
//                  operands' ranges alone, which holds the Lipschitz range up to rounding;
//   kRefineRanges: the same ranges without the values (their rows of `value` hold nothing of
//                  use): refinement's decisions read none, only its far-field test (the root's).
// Refinement's ranges do not depend on whether values are computed, so neither do its results.
// With Lipschitz bounds every mode is kSiblings.
enum class OperatorMode { kSiblings, kRefine, kRefineRanges };

// Where evaluate_boxes writes: per tape entry e and box b, index e · stride + b
// (stride >= the lanes computed).
struct LaneArrays {
    float *value, *lo, *hi;
    uint32_t* decision;
    uint32_t stride;
    OperatorMode mode = OperatorMode::kSiblings;
};

// A primitive's range over each box (math::primitive_box_range), `narrow` chosen once for all
// of them (math::primitive_narrows), so that the loop vectorizes.
template <uint32_t W, bool kNarrow>
void primitive_ranges(const PrimitiveBound pb, const BoxLanes& c, vec3 half, float spread,
                      const float* __restrict v, float* __restrict l, float* __restrict h) {
    const float* __restrict x = c.x;
    const float* __restrict y = c.y;
    const float* __restrict z = c.z;
    for (uint32_t b = 0; b < lanes_of<W>(c.lanes); ++b) {
        const vec2 r = math::primitive_box_range(v[b], spread, kNarrow, pb.centre, pb.scale, pb.f0,
                                                 pb.rho, vec3(x[b], y[b], z[b]), half);
        l[b] = r.x;
        h[b] = r.y;
    }
}

// One operator over `count` boxes, from its operands' values and ranges: the decision, the
// value (kValue), and the range (math::operator_box_range: with kLipschitz around the value,
// narrowed with kInterval by the operator's range over its operands' ranges; OperatorMode).
// Computed for every box and then selected, without branches, so the loop vectorizes.
template <uint32_t W, bool kInterval, bool kValue, bool kLipschitz>
void decide_boxes(uint32_t lanes, float sgn, float k, float spread, const float* __restrict va,
                  const float* __restrict la, const float* __restrict ha,
                  const float* __restrict vb, const float* __restrict lb,
                  const float* __restrict hb, uint32_t* __restrict d, float* __restrict v,
                  float* __restrict l, float* __restrict h) {
    static_assert(kInterval || (kValue && kLipschitz), "Lipschitz bounds need the value");
    for (uint32_t b = 0; b < lanes_of<W>(lanes); ++b) {
        const float a_lo = la[b], a_hi = ha[b], b_lo = lb[b], b_hi = hb[b];
        const uint32_t dec = math::prune_decision(sgn, k, a_lo, a_hi, b_lo, b_hi);
        float val = 0;
        if constexpr (kValue) {
            val = math::apply_operator(sgn, k, va[b], vb[b]);
            v[b] = val;
        }
        const vec2 r = math::operator_box_range(dec, sgn, k, val, spread, kInterval, kLipschitz,
                                                a_lo, a_hi, b_lo, b_hi);
        d[b] = dec;
        l[b] = r.x;
        h[b] = r.y;
    }
}

// Evaluates `tape` at the centres of the boxes `c` (all of half sizes `half`), bounds every
// entry over each box and decides every operator in each: entry by entry, across the boxes, so
// that an entry's operands are fetched once. Also fills s.left and s.right.
// With `only` (entries of the tape in tape order, closed under operands: whole subtrees), just
// those entries, their operands found in s.left and s.right as an earlier call over the whole
// tape left them; the other entries' rows are left alone.
template <uint32_t W>
void evaluate_lanes(const Scene& sc, std::span<const uint32_t> tape, const BoxLanes& c, vec3 half,
                    float radius, CellBounds bounds, LaneArrays out, CellScratch& s,
                    std::span<const uint32_t> only) {
    const uint32_t lanes = c.lanes;
    const bool interval = bounds == CellBounds::kInterval;
    const auto entry = [&](uint32_t i, uint32_t left, uint32_t right) {
        const uint32_t w = tape[i];
        const uint32_t node = math::tape_node(w);
        const uint32_t kind = sc.kind[node];
        const float spread = sc.lipschitz[node] * radius;
        const size_t at = size_t(i) * out.stride;
        float* __restrict v = out.value + at;
        float* __restrict l = out.lo + at;
        float* __restrict h = out.hi + at;
        if (kind < math::kPrimitiveKindCount) {
            const uint32_t p = sc.primitive[node];
            lanes::primitive_values_any<W>(kind, sc.params[p], c.x, c.y, c.z, c.lanes, v);
            if (math::primitive_narrows(interval, sc.bound[p].scale))
                primitive_ranges<W, true>(sc.bound[p], c, half, spread, v, l, h);
            else
                primitive_ranges<W, false>(sc.bound[p], c, half, spread, v, l, h);
        } else {
            const float sgn = math::operator_s(kind), k = sc.blend[node];
            const size_t ia = size_t(left) * out.stride, ib = size_t(right) * out.stride;
            // Rows of other entries than this one: no aliasing.
            const float* __restrict va = out.value + ia;
            const float* __restrict la = out.lo + ia;
            const float* __restrict ha = out.hi + ia;
            const float* __restrict vb = out.value + ib;
            const float* __restrict lb = out.lo + ib;
            const float* __restrict hb = out.hi + ib;
            uint32_t* __restrict d = out.decision + at;
            const auto decide = [&]<bool kI, bool kV, bool kL>() {
                decide_boxes<W, kI, kV, kL>(lanes, sgn, k, spread, va, la, ha, vb, lb, hb, d, v, l,
                                            h);
            };
            if (!interval)
                decide.template operator()<false, true, true>();
            else if (out.mode == OperatorMode::kSiblings)
                decide.template operator()<true, true, true>();
            else if (out.mode == OperatorMode::kRefine)
                decide.template operator()<true, true, false>();
            else
                decide.template operator()<true, false, false>();
        }
        if (math::tape_negated(w))
            for (uint32_t b = 0; b < lanes_of<W>(lanes); ++b) {
                const float old_lo = l[b];
                v[b] = -v[b];
                l[b] = -h[b];
                h[b] = -old_lo;
            }
    };
    // The primitives first, then the operators in tape order (each after its operands): the
    // same results, but the primitives' long independent chains (a box: two dependent square
    // roots) run back to back, where the processor overlaps them, not each behind an operator
    // that waits for the one before.
    const auto is_primitive = [&](uint32_t i) { return sc.is_primitive(math::tape_node(tape[i])); };
    if (!only.empty()) {
        for (const uint32_t i : only)
            if (is_primitive(i)) entry(i, 0, 0);
        for (const uint32_t i : only)
            if (!is_primitive(i)) entry(i, s.left[i], s.right[i]);
        return;
    }
    for (uint32_t i = 0; i < uint32_t(tape.size()); ++i)
        if (is_primitive(i)) entry(i, 0, 0);
    uint32_t top = 0;
    for (uint32_t i = 0; i < uint32_t(tape.size()); ++i) {
        if (!is_primitive(i)) {
            const uint32_t right = s.stack[--top];
            const uint32_t left = s.stack[--top];
            s.left[i] = left;
            s.right[i] = right;
            entry(i, left, right);
        }
        s.stack[top++] = i;
    }
}

// evaluate_lanes compiled once per instruction set, each with everything it calls inlined
// (lanes::run_for_isa): for the baseline, and on x86-64 for AVX2 and AVX-512, chosen at run time.
// No FMA: the same operations, rounded the same way, so all give the same results bit for bit
// (PruneLanes tests compare them).
void evaluate_boxes(const Scene& sc, std::span<const uint32_t> tape, const BoxLanes& c, vec3 half,
                    float radius, CellBounds bounds, LaneArrays out, CellScratch& s,
                    std::span<const uint32_t> only = {}) {
    lanes::run_for_isa(lane_isa(), c.lanes, [&]<uint32_t W>() {
        evaluate_lanes<W>(sc, tape, c, half, radius, bounds, out, s, only);
    });
}

}  // namespace

float evaluate_cell(const Scene& sc, std::span<const uint32_t> tape, const CellBox& box,
                    CellBounds bounds, CellScratch& s, bool sub_box) {
    s.reserve(tape.size());
    evaluate_boxes(sc, tape, box_lanes(&box.centre, 1), box.half, box.radius, bounds,
                   {s.value.data(), s.lo.data(), s.hi.data(), s.decision.data(), 1,
                    sub_box ? OperatorMode::kRefine : OperatorMode::kSiblings},
                   s);
    return s.value[tape.size() - 1];
}

namespace {

// Stage 2 on one box's root: value v and range [lo, hi] over a box of radius R (is_near_field).
bool root_is_near_field(float v, float lo, float hi, float L, float R, float far_field_c,
                        float& constant) {
    // The paper's test |f(c)| > C·R says: over the cell, |f| stays above (C − 1)·R, since the
    // Lipschitz range is f(c) ± R. Here the same guarantee is tested on the range itself (the
    // Lipschitz range or, with CellBounds::kInterval, a tighter one), against the clearance of
    // far_field_clearance, so far-field constants keep |c| >= (C − 1)·max(L, 1)·R.
    const float clearance = math::far_field_clearance(far_field_c, L, R);
    const vec2 range = math::far_field_range(v, lo, hi, L, R);
    if (math::clears_above(range.x, clearance)) {
        constant = range.x;
        return false;
    }
    if (math::clears_below(range.y, clearance)) {
        constant = range.y;
        return false;
    }
    return true;
}

}  // namespace

bool is_near_field(const Scene& sc, std::span<const uint32_t> tape, const CellBox& box,
                   float far_field_c, const CellScratch& s, float& constant) {
    const uint32_t root = uint32_t(tape.size() - 1);
    return root_is_near_field(s.value[root], s.lo[root], s.hi[root],
                              sc.lipschitz[math::tape_node(tape[root])], box.radius, far_field_c,
                              constant);
}

void evaluate_siblings(const Scene& sc, std::span<const uint32_t> tape, const vec3* centres,
                       uint32_t count, vec3 half, float radius, CellBounds bounds, CellScratch& s) {
    if (count > kSiblingGroupLanes) throw std::invalid_argument("evaluate_siblings: too many");
    const BoxLanes c = box_lanes(centres, count);
    const uint32_t stride = std::max(kSiblingLanes, c.lanes), offset = s.sib_used;
    s.reserve(tape.size());
    s.reserve_siblings(offset + tape.size() * stride);
    s.sib_at = {offset, stride, 0};
    evaluate_boxes(sc, tape, c, half, radius, bounds,
                   {s.sib_value.data() + offset, s.sib_lo.data() + offset, s.sib_hi.data() + offset,
                    s.sib_decision.data() + offset, stride},
                   s);
}

bool sibling_is_near_field(const Scene& sc, std::span<const uint32_t> tape, uint32_t lane,
                           float radius, float far_field_c, const CellScratch& s, float& constant) {
    const size_t root =
        s.sib_at.offset + (tape.size() - 1) * s.sib_at.stride + s.sib_at.first + lane;
    return root_is_near_field(s.sib_value[root], s.sib_lo[root], s.sib_hi[root],
                              sc.lipschitz[math::tape_node(tape.back())], radius, far_field_c,
                              constant);
}

namespace {

// The S³ sub-boxes of refine_cells in visiting order: the 8 corners first, then the middle, then
// the rest. The order changes nothing but when a cell may stop. Its first batch is one block,
// the corners, where most cells stop: where an operator stays undecided is a band around a
// surface, near a plane across a small cell, and a band that misses every corner misses their
// convex hull, the cell; the middle adds less (its operands' values at the centre were tested
// before, blend_may_decide). Corners before the middle: 1 % fewer instructions in trees' and
// molecule's pruning (callgrind). Each sub-box (i, j, k) is stored as its centre's offsets
// 2i + 1, 2j + 1, 2k + 1 (sub_box_centre's factors), one array per axis, so that a batch's
// centres are a vector loop.
void sub_box_order(uint32_t S, std::vector<float> (&offset)[3]) {
    const uint32_t mid = S / 2, last = S - 1;
    const auto is_corner = [&](uint32_t i, uint32_t j, uint32_t k) {
        return (i == 0 || i == last) && (j == 0 || j == last) && (k == 0 || k == last);
    };
    std::vector<std::array<uint32_t, 3>> order;
    for (uint32_t c = 0; c < 8; ++c)
        order.push_back({c & 1 ? last : 0, c & 2 ? last : 0, c & 4 ? last : 0});
    if (!is_corner(mid, mid, mid)) order.push_back({mid, mid, mid});
    for (uint32_t b = 0; b < S * S * S; ++b) {
        const uint32_t i = b % S, j = b / S % S, k = b / (S * S);
        if (!is_corner(i, j, k) && !(i == mid && j == mid && k == mid)) order.push_back({i, j, k});
    }
    // A corner is listed once however small S is (S = 1: the only box; S = 2: all eight).
    order.erase(std::unique(order.begin(), order.end()), order.end());
    for (uint32_t a = 0; a < 3; ++a) {
        offset[a].clear();
        for (const auto& at : order) offset[a].push_back(float(2 * at[a] + 1));
    }
}

// Lanes [to, to + count) of `c`: the centres of sub-boxes [at, at + count) in visiting order of
// the box with min corner `corner` split into sub-boxes of half sizes `sub_half`, as
// sub_box_centre computes them (from s.sub_offset, made for S here if it was not).
void sub_box_centres(CellScratch& s, uint32_t S, vec3 corner, vec3 sub_half, uint32_t at,
                     uint32_t count, uint32_t to, BoxLanes& c) {
    if (s.sub_offset_of != S) {
        sub_box_order(S, s.sub_offset);
        s.sub_offset_of = S;
    }
    const float* ox = s.sub_offset[0].data() + at;
    const float* oy = s.sub_offset[1].data() + at;
    const float* oz = s.sub_offset[2].data() + at;
    for (uint32_t b = 0; b < count; ++b) {
        c.x[to + b] = corner.x + ox[b] * sub_half.x;
        c.y[to + b] = corner.y + oy[b] * sub_half.y;
        c.z[to + b] = corner.z + oz[b] * sub_half.z;
    }
}

}  // namespace

void link_tape(const Scene& sc, std::span<const uint32_t> tape, CellScratch& s) {
    uint32_t top = 0;
    for (uint32_t i = 0; i < uint32_t(tape.size()); ++i) {
        if (!sc.is_primitive(math::tape_node(tape[i]))) {
            s.right[i] = s.stack[--top];
            s.left[i] = s.stack[--top];
        }
        s.stack[top++] = i;
    }
}

RefineNeed refine_need(const Scene& sc, std::span<const uint32_t> tape, const CellBox& box,
                       bool far_field, float far_field_c, float value, bool may_decide) {
    const uint32_t n = uint32_t(tape.size());
    const float L = sc.lipschitz[math::tape_node(tape[n - 1])];
    RefineNeed need;
    need.clearance = math::far_field_clearance(far_field_c, L, box.radius);
    // sigma: a lone primitive's similarity scale (refine_far_possible).
    const float sigma = n == 1 ? sc.bound[sc.primitive[math::tape_node(tape[0])]].scale : 0.0f;
    need.far = far_field && math::refine_far_possible(value, need.clearance, sigma, box.half);
    need.any = may_decide || need.far;
    return need;
}

RefineNeed refine_need_of_tape(const Scene& sc, std::span<const uint32_t> tape, const CellBox& box,
                               const PruneOptions& opt, float value, CellScratch& s) {
    evaluate_cell(sc, tape, box, opt.bounds, s);
    bool may_decide = false;
    for (uint32_t e = 0; e < uint32_t(tape.size()) && !may_decide; ++e) {
        const uint32_t node = math::tape_node(tape[e]);
        may_decide =
            !sc.is_primitive(node) &&
            math::blend_may_decide(s.value[s.left[e]], s.value[s.right[e]], sc.blend[node]);
    }
    return refine_need(sc, tape, box, opt.far_field, opt.far_field_c, value, may_decide);
}

void refine_cells(const Scene& sc, std::span<const uint32_t> tape, const CellBox* boxes,
                  uint32_t count, uint32_t S, CellBounds bounds, bool far_field, float far_field_c,
                  const float* values, const bool* may_decide, CellScratch& s,
                  RefineResult* results) {
    if (count == 0 || count > kSiblingLanes) throw std::invalid_argument("refine_cells: count");
    const uint32_t n = uint32_t(tape.size());
    s.reserve(n);
    const float L = sc.lipschitz[math::tape_node(tape[n - 1])];
    const vec3 sub_half = boxes[0].half / float(S);
    const float sub_radius = math::length(sub_half);
    const uint32_t total = S * S * S;
    // Per cell: the far-field test so far (every sub-box cleared the cell's clearance above, or
    // below; the sub-boxes' tightest bounds), and its decisions, at s.refine_decision + j · n:
    // the sub-boxes' common decisions so far. Its candidates (s.refine_cands[j]): the operators
    // that may yet be decided alike in every sub-box (none when `may_decide` says that none is
    // decided in the sub-box holding the centre).
    struct CellState {
        bool above = false, below = false;
        float lowest = INFINITY, highest = -INFINITY, clearance = 0;
    } st[kSiblingLanes];
    if (s.refine_decision.size() < size_t(count) * n) s.refine_decision.resize(size_t(count) * n);
    uint32_t open = 0;  // the cells still refined (bit j)
    for (uint32_t j = 0; j < count; ++j) {
        const RefineNeed need =
            refine_need(sc, tape, boxes[j], far_field, far_field_c, values[j], may_decide[j]);
        results[j] = {};
        st[j].above = st[j].below = need.far;
        st[j].clearance = need.clearance;
        s.refine_cands[j].clear();
        open |= need.any ? 1u << j : 0u;
    }
    // A batch evaluates, for every open cell, its next sub-boxes in visiting order (the first
    // batch its corners, one block; the others up to kLanes), packed cell after cell into one
    // pass over the tape: the whole tape at first and while some cell's far-field test is open
    // (it reads the root's value), else only the candidates' subtrees, often a few words of a
    // long tape. The results are the same as cell by cell: every entry a decision reads is
    // evaluated, and ranges do not depend on whether values are computed.
    bool subset = false;
    std::vector<uint32_t>& needed = s.refine_needed;
    for (uint32_t at = 0; at < total && open != 0;) {
        const bool first = at == 0;
        const uint32_t per = std::min(first ? kBlock : kLanes, total - at);
        uint32_t cells[kSiblingLanes], m = 0;
        bool values_needed = false;
        for (uint32_t rest = open; rest != 0; rest &= rest - 1) {
            const uint32_t j = uint32_t(std::countr_zero(rest));
            cells[m++] = j;
            values_needed = values_needed || st[j].above || st[j].below;
        }
        BoxLanes c;
        c.lanes = lanes_for(per * m);
        for (uint32_t k = 0; k < m; ++k) {
            const CellBox& box = boxes[cells[k]];
            sub_box_centres(s, S, box.centre - box.half, sub_half, at, per, per * k, c);
        }
        // The lanes past the boxes repeat the last one.
        for (uint32_t b = per * m; b < c.lanes; ++b) {
            c.x[b] = c.x[b - 1];
            c.y[b] = c.y[b - 1];
            c.z[b] = c.z[b - 1];
        }
        const uint32_t stride = c.lanes;
        const size_t size = size_t(n) * stride;
        for (auto* v : {&s.lane_value, &s.lane_lo, &s.lane_hi})
            if (v->size() < size) v->resize(size);
        if (s.lane_decision.size() < size) s.lane_decision.resize(size);
        evaluate_boxes(
            sc, tape, c, sub_half, sub_radius, bounds,
            {s.lane_value.data(), s.lane_lo.data(), s.lane_hi.data(), s.lane_decision.data(),
             stride, values_needed ? OperatorMode::kRefine : OperatorMode::kRefineRanges},
            s, subset ? std::span<const uint32_t>(needed) : std::span<const uint32_t>());
        at += per;
        bool any_candidates = false, any_far = false;
        for (uint32_t k = 0; k < m; ++k) {
            const uint32_t j = cells[k];
            CellState& cs = st[j];
            uint32_t* decision = s.refine_decision.data() + size_t(j) * n;
            std::vector<uint32_t>& candidates = s.refine_cands[j];
            // Whether each candidate is still decided the same way in every sub-box so far; an
            // operator kept in some sub-box stays kept. The first batch sets every entry's
            // decision (a primitive's, and every operator's without `may_decide`: kKeepBoth).
            const uint32_t* d0 = s.lane_decision.data() + per * k;
            const auto common_decision = [&](uint32_t e, uint32_t common) {
                const uint32_t* d = d0 + size_t(e) * stride;
                uint32_t differ = 0;
                for (uint32_t b = 0; b < per; ++b) differ |= d[b] ^ common;
                return differ == 0 ? common : math::kKeepBoth;
            };
            if (first) {
                const bool may = may_decide[j];
                for (uint32_t e = 0; e < n; ++e) {
                    uint32_t dec = math::kKeepBoth;
                    if (may && !sc.is_primitive(math::tape_node(tape[e])))
                        dec = common_decision(e, d0[size_t(e) * stride]);
                    decision[e] = dec;
                    if (dec != math::kKeepBoth) candidates.push_back(e);
                }
            } else {
                size_t kept = 0;
                for (const uint32_t e : candidates) {
                    decision[e] = common_decision(e, decision[e]);
                    if (decision[e] != math::kKeepBoth) candidates[kept++] = e;
                }
                candidates.resize(kept);
            }
            // The far-field test of is_near_field on each sub-box's root range, against the
            // whole cell's clearance, while every sub-box so far has cleared it.
            if (cs.above || cs.below) {
                const size_t root = size_t(n - 1) * stride + per * k;
                for (uint32_t b = 0; b < per; ++b) {
                    const vec2 range =
                        math::far_field_range(s.lane_value[root + b], s.lane_lo[root + b],
                                              s.lane_hi[root + b], L, sub_radius);
                    cs.above = cs.above && math::clears_above(range.x, cs.clearance);
                    cs.below = cs.below && math::clears_below(range.y, cs.clearance);
                    cs.lowest = std::min(cs.lowest, range.x);
                    cs.highest = std::max(cs.highest, range.y);
                }
            }
            if (candidates.empty() && !cs.above && !cs.below) open &= ~(1u << j);
            any_candidates = any_candidates || ((open >> j & 1) != 0 && !candidates.empty());
            any_far = any_far || cs.above || cs.below;
        }
        // The next batch: only the open cells' candidates' subtrees while no far-field test is
        // open (their marks borrow s.alive, which compaction sets afresh; s.left and s.right
        // link the tape since the first batch, which always walks the whole of it).
        subset = false;
        if (open != 0 && !any_far && at < total && any_candidates) {
            uint8_t* mark = s.alive.data();
            std::fill_n(mark, n, uint8_t(0));
            for (uint32_t rest = open; rest != 0; rest &= rest - 1)
                for (const uint32_t e : s.refine_cands[std::countr_zero(rest)]) mark[e] = 1;
            for (uint32_t i = n; i-- > 0;) {
                if (mark[i] == 0 || sc.is_primitive(math::tape_node(tape[i]))) continue;
                mark[s.left[i]] = 1;
                mark[s.right[i]] = 1;
            }
            needed.clear();
            for (uint32_t i = 0; i < n; ++i)
                if (mark[i] != 0) needed.push_back(i);
            subset = true;
        }
    }
    for (uint32_t j = 0; j < count; ++j) {
        const CellState& cs = st[j];
        if (cs.above || cs.below) {
            results[j].near = false;
            results[j].constant = cs.above ? cs.lowest : cs.highest;
        } else {
            results[j].decided = !s.refine_cands[j].empty();
        }
    }
}

bool refine_cell(const Scene& sc, std::span<const uint32_t> tape, const CellBox& box, uint32_t S,
                 CellBounds bounds, bool far_field, float far_field_c, float value, bool may_decide,
                 CellScratch& s, float& constant) {
    RefineResult r;
    refine_cells(sc, tape, &box, 1, S, bounds, far_field, far_field_c, &value, &may_decide, s, &r);
    const uint32_t n = uint32_t(tape.size());
    if (r.decided)
        std::copy_n(s.refine_decision.begin(), n, s.decision.begin());
    else
        std::fill_n(s.decision.begin(), n, math::kKeepBoth);
    constant = r.constant;
    return r.near;
}

namespace {

// The lanes (bit c: lane c) of kL decisions d[0, kL) in which the left operand wins, and those in
// which the right one does. On x86-64, 8 lanes in two SSE2 compares instead of 16 scalar ones.
template <uint32_t kL>
void winner_lanes(const uint32_t* d, uint32_t& left_wins, uint32_t& right_wins) {
#if defined(__SSE2__)
    if constexpr (kL == 8) {
        const __m128i lo = _mm_loadu_si128(reinterpret_cast<const __m128i*>(d));
        const __m128i hi = _mm_loadu_si128(reinterpret_cast<const __m128i*>(d + 4));
        const auto lanes_equal = [&](uint32_t value) {
            const __m128i v = _mm_set1_epi32(int(value));
            return uint32_t(_mm_movemask_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(lo, v)))) |
                   uint32_t(_mm_movemask_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(hi, v)))) << 4;
        };
        left_wins = lanes_equal(math::kLeftWins);
        right_wins = lanes_equal(math::kRightWins);
        return;
    }
#endif
    left_wins = right_wins = 0;
    for (uint32_t c = 0; c < kL; ++c) {
        left_wins |= uint32_t(d[c] == math::kLeftWins) << c;
        right_wins |= uint32_t(d[c] == math::kRightWins) << c;
    }
}

// Stage 3 for up to 8 lanes at once (kL: 1, or kSiblingLanes with the decision of entry e in
// lane c at decision[e · stride + c]), for the lanes in `lanes` (bit c: lane c). One sweep of the
// tape serves them all: per entry, a byte says in which lanes it is alive (s.alive) and one in
// which its word is negated (s.negate). Each entry has one parent, which decides it first
// (parents come after their children: a reverse sweep), so its bytes are set once:
//   - where the parent keeps both operands, the entry is alive with its own sign;
//   - where the parent is skipped and the entry wins, it stands in for the parent, taking the
//     parent's composed sign along (the parent is then not emitted);
//   - elsewhere it is dead.
// A forward sweep emits each alive entry's word to the lanes it is alive in, in tape order.
// With `values` (the entries' values at the lanes' centres, as `decision`), also `decidable`:
// the lanes where refine_cell might decide some operator of their tapes (blend_may_decide).
template <uint32_t kL>
void compact_lanes(const Scene& sc, std::span<const uint32_t> tape, const uint32_t* decision,
                   size_t stride, uint32_t lanes, CellScratch& s, std::vector<uint32_t>* out,
                   uint32_t* prims, const float* values = nullptr, uint32_t* decidable = nullptr) {
    uint32_t may_decide = 0;
    const uint32_t n = uint32_t(tape.size());
    uint8_t* __restrict alive = s.alive.data();
    uint8_t* __restrict negate = s.negate.data();
    const auto sign_mask = [&](uint32_t e) { return math::tape_negated(tape[e]) ? 0xffu : 0u; };
    std::fill_n(alive, n, uint8_t(0));
    alive[n - 1] = uint8_t(lanes);
    negate[n - 1] = uint8_t(lanes & sign_mask(n - 1));
    for (uint32_t i = n; i-- > 0;) {
        const uint32_t here = alive[i];
        if (here == 0 || sc.is_primitive(math::tape_node(tape[i]))) continue;
        uint32_t left_wins, right_wins;
        winner_lanes<kL>(decision + size_t(i) * stride, left_wins, right_wins);
        left_wins &= here;
        right_wins &= here;
        const uint32_t keep = here & ~(left_wins | right_wins);
        const uint32_t l = s.left[i], r = s.right[i];
        const uint32_t nl = sign_mask(l), nr = sign_mask(r);
        alive[l] = uint8_t(keep | left_wins);
        alive[r] = uint8_t(keep | right_wins);
        negate[l] = uint8_t((keep & nl) | (left_wins & (negate[i] ^ nl)));
        negate[r] = uint8_t((keep & nr) | (right_wins & (negate[i] ^ nr)));
        alive[i] = uint8_t(keep);  // from here on: the lanes that emit entry i
        // (lanes already known to have a decidable operator need no more tests)
        if (const uint32_t open = keep & ~may_decide; values && open != 0) {
            const float k = sc.blend[math::tape_node(tape[i])];
            for (uint32_t c = 0; c < kL; ++c)
                if ((open >> c & 1) != 0 &&
                    math::blend_may_decide(values[size_t(l) * stride + c],
                                           values[size_t(r) * stride + c], k))
                    may_decide |= 1u << c;
        }
    }
    for (uint32_t c = 0; c < kL; ++c) prims[c] = 0;
    for (uint32_t i = 0; i < n; ++i) {
        uint32_t emit = alive[i];
        if (emit == 0) continue;
        const uint32_t node = math::tape_node(tape[i]);
        const uint32_t prim = sc.is_primitive(node) ? 1 : 0;
        for (; emit != 0; emit &= emit - 1) {
            const uint32_t c = uint32_t(std::countr_zero(emit));
            out[c].push_back(math::tape_word(node, (negate[i] >> c & 1) != 0));
            prims[c] += prim;
        }
    }
    if (decidable) *decidable = may_decide;
}

}  // namespace

uint32_t compact_tape(const Scene& sc, std::span<const uint32_t> tape, CellScratch& s,
                      std::vector<uint32_t>& out) {
    uint32_t prims = 0;
    compact_lanes<1>(sc, tape, s.decision.data(), 1, 1, s, &out, &prims);
    return prims;
}

void compact_siblings(const Scene& sc, std::span<const uint32_t> tape, uint32_t lanes,
                      CellScratch& s, std::vector<uint32_t>* out, uint32_t* prims,
                      uint32_t* decidable) {
    const size_t at = s.sib_at.offset + s.sib_at.first;
    compact_lanes<kSiblingLanes>(sc, tape, s.sib_decision.data() + at, s.sib_at.stride, lanes, s,
                                 out, prims, decidable ? s.sib_value.data() + at : nullptr,
                                 decidable);
}

}  // namespace sdfprune
