// eval.hpp — evaluating a scene's SDF: a tape (post-order list of 32-bit (node, sign) words, see
// sdf_math.h) run on a small value stack. The full tree is the tape Scene::full_tape: evaluating
// it at every query is the paper's naive baseline.
//
// Thread-safety: all functions are pure; batch functions run on oneTBB.
#pragma once

#include <span>

#include "parallel.hpp"  // with_threads, for callers of the batch functions
#include "scene.hpp"

namespace sdfprune {

struct EvalOptions {
    int threads = 0;  // worker threads; 0 = all hardware threads
};

// Evaluates `tape` at p. `stack` must hold scene.max_stack floats.
float eval_tape(const Scene& scene, std::span<const uint32_t> tape, vec3 p, float* stack);

// Points evaluated together by eval_tape_lanes, coordinate by coordinate (structure of arrays).
inline constexpr uint32_t kEvalLanes = 16;
struct PointLanes {
    alignas(32) float x[kEvalLanes];
    alignas(32) float y[kEvalLanes];
    alignas(32) float z[kEvalLanes];
};

// Evaluates `tape` at points 0..count-1 of `points` (count in 1..kEvalLanes) into
// out[0..count): eval_tape's values bit for bit, computed in vector lanes (AVX2 or AVX-512 where
// the processor has it, see lane_isa()), so a batch of points sharing a tape costs
// little more than one. Lanes past `count` are overwritten. `stack` must hold
// scene.max_stack · kEvalLanes floats.
void eval_tape_lanes(const Scene& scene, std::span<const uint32_t> tape, PointLanes& points,
                     uint32_t count, float* out, float* stack);

// The instruction set that the loops over vector lanes run on (eval_tape_lanes' over points, and
// the pruner's over boxes): the widest the processor has (x86-64: kAvx512, else kAvx2; chosen on
// first use), else kBaseline. All give the same results bit for bit. set_lane_isa is for tests
// and benchmarks (process-wide; not to be called while pruning or evaluating); it throws
// std::invalid_argument for an instruction set the processor lacks (lane_isa_supported).
enum class LaneIsa { kBaseline, kAvx2, kAvx512 };
LaneIsa lane_isa();
bool lane_isa_supported(LaneIsa isa);
void set_lane_isa(LaneIsa isa);

// The albedo at p: primitives' colors blended through the operators by operator_weight_b, the
// way smooth operators blend the shapes. Stacks must hold scene.max_stack entries each.
vec3 eval_tape_color(const Scene& scene, std::span<const uint32_t> tape, vec3 p, float* stack,
                     vec3* color_stack);

// The primitive (index into the scene's per-primitive arrays) that decides the value at p, as
// the tape decides: at each operator, the operand with the larger blend weight
// (operator_weight_b), i.e. the one the hard min / max picks, or the nearer one within a smooth
// blend. Stacks must hold scene.max_stack entries each.
uint32_t eval_tape_winner(const Scene& scene, std::span<const uint32_t> tape, vec3 p, float* stack,
                          uint32_t* winner_stack);

// The full tree's value at p (allocates its stack; use eval_points for many points).
float eval_point(const Scene& scene, vec3 p);

// The full tree's values at many points, in parallel. out.size() must equal points.size().
void eval_points(const Scene& scene, std::span<const vec3> points, std::span<float> out,
                 const EvalOptions& options = {});

}  // namespace sdfprune
