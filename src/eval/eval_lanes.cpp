// eval_lanes.cpp — eval_tape for a batch of points sharing a tape (eval.hpp): the tape is walked
// once, and each entry is computed across the points' lanes (lanes.hpp), on a stack of rows of
// kEvalLanes floats. Compiled for the baseline instruction set and for AVX2 and AVX-512
// (lanes.hpp), chosen at run time; all give eval_tape's values bit for bit.
#include <algorithm>

#include "../core/lanes.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/prune.hpp"

namespace sdfprune {
namespace {

template <uint32_t W>
void eval_rows(const Scene& sc, std::span<const uint32_t> tape, const PointLanes& p, uint32_t lanes,
               float* stack) {
    uint32_t top = 0;
    for (const uint32_t w : tape) {
        const uint32_t n = math::tape_node(w);
        const uint32_t k = sc.kind[n];
        float* __restrict v;
        if (k < math::kPrimitiveKindCount) {
            v = stack + size_t(top++) * kEvalLanes;
            lanes::primitive_values_any<W>(k, sc.params[sc.primitive[n]], p.x, p.y, p.z, lanes, v);
        } else {
            --top;
            const float* __restrict b = stack + size_t(top) * kEvalLanes;
            v = stack + size_t(top - 1) * kEvalLanes;
            const float s = math::operator_s(k), blend = sc.blend[n];
            for (uint32_t i = 0; i < lanes::lanes_of<W>(lanes); ++i)
                v[i] = math::apply_operator(s, blend, v[i], b[i]);
        }
        if (math::tape_negated(w))
            for (uint32_t i = 0; i < lanes::lanes_of<W>(lanes); ++i) v[i] = -v[i];
    }
}

inline void eval_any_rows(const Scene& sc, std::span<const uint32_t> tape, const PointLanes& p,
                          uint32_t lanes, float* stack) {
    if (lanes == 1)
        eval_rows<1>(sc, tape, p, lanes, stack);
    else
        eval_rows<lanes::kBlock>(sc, tape, p, lanes, stack);
}

#if SDFPRUNE_X86_LANES
[[SDFPRUNE_AVX2_LANES_TARGET, gnu::flatten]] void eval_rows_avx2(const Scene& sc,
                                                                std::span<const uint32_t> tape,
                                                                const PointLanes& p,
                                                                uint32_t lanes, float* stack) {
    eval_any_rows(sc, tape, p, lanes, stack);
}
[[SDFPRUNE_AVX512_LANES_TARGET, gnu::flatten]] void eval_rows_avx512(
    const Scene& sc, std::span<const uint32_t> tape, const PointLanes& p, uint32_t lanes,
    float* stack) {
    eval_any_rows(sc, tape, p, lanes, stack);
}
#endif

[[gnu::flatten]] void eval_rows_baseline(const Scene& sc, std::span<const uint32_t> tape,
                                         const PointLanes& p, uint32_t lanes, float* stack) {
    eval_any_rows(sc, tape, p, lanes, stack);
}

}  // namespace

void eval_tape_lanes(const Scene& sc, std::span<const uint32_t> tape, PointLanes& p, uint32_t count,
                     float* out, float* stack) {
    const uint32_t lanes = lanes::lanes_for(count);
    for (uint32_t i = count; i < lanes; ++i) {
        p.x[i] = p.x[count - 1];
        p.y[i] = p.y[count - 1];
        p.z[i] = p.z[count - 1];
    }
#if SDFPRUNE_X86_LANES
    if (const LaneIsa isa = lane_isa(); isa == LaneIsa::kAvx512)
        eval_rows_avx512(sc, tape, p, lanes, stack);
    else if (isa == LaneIsa::kAvx2)
        eval_rows_avx2(sc, tape, p, lanes, stack);
    else
#endif
        eval_rows_baseline(sc, tape, p, lanes, stack);
    std::copy_n(stack, count, out);
}

}  // namespace sdfprune
