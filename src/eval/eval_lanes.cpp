// eval_lanes.cpp — eval_tape for a batch of points sharing a tape (eval.hpp): the tape is walked
// once, and each entry is computed across the points' lanes (lanes.hpp), on a stack of rows of
// kEvalLanes floats. Compiled for the baseline instruction set and for AVX2 and AVX-512
// (lanes.hpp), chosen at run time by lane_isa (defined here; the pruner's loops over boxes take
// the same choice); all give eval_tape's values bit for bit.
#include <algorithm>
#include <atomic>
#include <stdexcept>

#include "../core/lanes.hpp"
#include "sdfprune/eval.hpp"

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

// The instruction set in use: chosen on first use, or by set_lane_isa.
std::atomic<int> g_lane_isa{-1};

LaneIsa best_lane_isa() {
    for (const LaneIsa isa : {LaneIsa::kAvx512, LaneIsa::kAvx2})
        if (lane_isa_supported(isa)) return isa;
    return LaneIsa::kBaseline;
}

}  // namespace

bool lane_isa_supported(LaneIsa isa) {
#if SDFPRUNE_X86_LANES
    __builtin_cpu_init();
    if (isa == LaneIsa::kAvx2) return __builtin_cpu_supports("avx2");
    if (isa == LaneIsa::kAvx512)
        return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
               __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512bw");
#endif
    return isa == LaneIsa::kBaseline;
}

LaneIsa lane_isa() {
    int isa = g_lane_isa.load(std::memory_order_relaxed);
    if (isa < 0) {
        isa = int(best_lane_isa());
        g_lane_isa.store(isa, std::memory_order_relaxed);
    }
    return LaneIsa(isa);
}

void set_lane_isa(LaneIsa isa) {
    if (!lane_isa_supported(isa))
        throw std::invalid_argument("set_lane_isa: this processor lacks the instruction set");
    g_lane_isa.store(int(isa), std::memory_order_relaxed);
}

void eval_tape_lanes(const Scene& sc, std::span<const uint32_t> tape, PointLanes& p, uint32_t count,
                     float* out, float* stack) {
    const uint32_t lanes = lanes::lanes_for(count);
    for (uint32_t i = count; i < lanes; ++i) {
        p.x[i] = p.x[count - 1];
        p.y[i] = p.y[count - 1];
        p.z[i] = p.z[count - 1];
    }
    lanes::run_for_isa(lane_isa(), lanes,
                       [&]<uint32_t W>() { eval_rows<W>(sc, tape, p, lanes, stack); });
    std::copy_n(stack, count, out);
}

}  // namespace sdfprune
