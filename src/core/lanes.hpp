// lanes.hpp — the vector-lane loops shared by the pruner's box evaluation (prune_cell.cpp) and
// the point evaluator eval_tape_lanes (eval_lanes.cpp): one loop over lanes per primitive kind,
// over structure-of-arrays coordinates, so that the kind's distance is inlined whole and the
// compiler turns the loop into vector instructions.
//
// Each lane computes exactly what the scalar code computes for its point: the same operations on
// the same floats, with no reassociation and no fused multiply-add (-ffp-contract=off), so the
// results are bit for bit those of one point at a time (and of the Vulkan kernels, which share
// sdf_math.h). Callers compile these loops inside functions marked flatten, once for the baseline
// instruction set and, on x86-64, once for AVX2 (8 lanes per instruction) and once for AVX-512
// (16), and choose at run time (lane_isa() in eval.hpp): run_for_isa below.
#pragma once

#include <cstdint>
#include <utility>

#include "sdfprune/eval.hpp"  // LaneIsa
#include "sdfprune/scene.hpp"

// The x86-64 instruction sets of the lane loops, as function attributes. GCC would keep AVX-512
// code to 256-bit registers; the wider ones halve the instructions of the loops over 16 or more
// lanes (on a Zen 4 core each runs as two 256-bit halves, still about 10 % faster).
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define SDFPRUNE_X86_LANES 1
#define SDFPRUNE_AVX2_LANES_TARGET gnu::target("avx2")
#if defined(__clang__)
#define SDFPRUNE_AVX512_LANES_TARGET gnu::target("avx512f,avx512vl,avx512dq,avx512bw")
#else
#define SDFPRUNE_AVX512_LANES_TARGET \
    gnu::target("avx512f,avx512vl,avx512dq,avx512bw,prefer-vector-width=512")
#endif
#else
#define SDFPRUNE_X86_LANES 0
#endif

namespace sdfprune::lanes {

// Loops over lanes run to a multiple of kBlock (8 floats: one AVX2 register), so that vectorized
// loops need no scalar remainder; lanes past the real ones repeat a real point, and nobody reads
// what they compute.
inline constexpr uint32_t kBlock = 8;

// The lanes that `count` points or boxes take: 1 for a single one (no loop), else whole blocks.
inline uint32_t lanes_for(uint32_t count) {
    return count == 1 ? 1 : (count + kBlock - 1) / kBlock * kBlock;
}

// The lanes to compute, as the loops see them: W = 1, a single point (the loop disappears);
// W = kBlock, a multiple of kBlock.
template <uint32_t W>
inline uint32_t lanes_of(uint32_t lanes) {
    return W == 1 ? 1 : lanes & ~(W - 1);
}

// A primitive of kind kKind at every lane's point (x[b], y[b], z[b]).
template <uint32_t W, uint32_t kKind>
void primitive_values(const math::PrimitiveParams prm, const float* __restrict x,
                      const float* __restrict y, const float* __restrict z, uint32_t lanes,
                      float* __restrict v) {
    for (uint32_t b = 0; b < lanes_of<W>(lanes); ++b) {
        v[b] = math::eval_primitive_local(kKind, prm, math::to_local(prm, vec3(x[b], y[b], z[b])));
    }
}

// primitive_values for a kind known at run time: direct calls, which the flattened callers
// inline whole.
template <uint32_t W, uint32_t... kKinds>
void primitive_values_of(uint32_t kind, const math::PrimitiveParams& prm, const float* x,
                         const float* y, const float* z, uint32_t lanes, float* v,
                         std::integer_sequence<uint32_t, kKinds...>) {
    ((kind == kKinds ? primitive_values<W, kKinds>(prm, x, y, z, lanes, v) : void()), ...);
}

template <uint32_t W>
void primitive_values_any(uint32_t kind, const math::PrimitiveParams& prm, const float* x,
                          const float* y, const float* z, uint32_t lanes, float* v) {
    primitive_values_of<W>(kind, prm, x, y, z, lanes, v,
                           std::make_integer_sequence<uint32_t, math::kPrimitiveKindCount>());
}

// Runs `body` compiled for the instruction set `isa` (lane_isa()'s choice): one instance of each
// runner per body, each with the body and everything it calls inlined (flatten), for the
// baseline and, on x86-64, for AVX2 and AVX-512. The body takes W: 1 for a single point or box
// (`lanes` == 1: no loop), else kBlock.
template <class Body>
void run_widths(uint32_t lanes, const Body& body) {
    if (lanes == 1)
        body.template operator()<1>();
    else
        body.template operator()<kBlock>();
}
template <class Body>
[[gnu::flatten]] void run_baseline(uint32_t lanes, const Body& body) {
    run_widths(lanes, body);
}
#if SDFPRUNE_X86_LANES
template <class Body>
[[SDFPRUNE_AVX2_LANES_TARGET, gnu::flatten]] void run_avx2(uint32_t lanes, const Body& body) {
    run_widths(lanes, body);
}
template <class Body>
[[SDFPRUNE_AVX512_LANES_TARGET, gnu::flatten]] void run_avx512(uint32_t lanes, const Body& body) {
    run_widths(lanes, body);
}
#endif
template <class Body>
void run_for_isa(LaneIsa isa, uint32_t lanes, const Body& body) {
#if SDFPRUNE_X86_LANES
    if (isa == LaneIsa::kAvx512) return run_avx512(lanes, body);
    if (isa == LaneIsa::kAvx2) return run_avx2(lanes, body);
#endif
    (void)isa;
    run_baseline(lanes, body);
}

}  // namespace sdfprune::lanes
