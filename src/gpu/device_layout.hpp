// device_layout.hpp — the host's mirrors of every struct, buffer block and push-constant block
// the kernels (shaders/gpu/*) share with it, in std430 / push-constant layout. The
// static_asserts pin them on the C++ side; tests/gpu_layout_test.cpp reads the member offsets
// and array strides glslc gave the GLSL side (SPIR-V reflection) and checks they match. Also
// the few figures of the pruning's plan that tools/prune_order_model.cpp models as well (a wide
// job's walk, a scene's shape for the wide kernel, which levels split into octants), so that
// the tool builds without the Vulkan backend's sources. The pruning kernels' modes, flags and
// sizes are written once, in shaders/gpu/prune_constants.h; here the sizes take the 64-bit types
// the plans count in.
#pragma once

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "../../shaders/gpu/prune_constants.h"
#include "sdfprune/prune.hpp"

namespace sdfprune::gpu {

using math::vec4;

// The scene (scene.glsl). PrimitiveParams is sdf_math.h's, the same struct on both sides.
// Parameters and extras are in node order: node n's at n (gpu_prune.cpp).
inline constexpr uint32_t kStagedPrimitiveBit = kernel::kStagedPrimitive;
struct GpuNode {  // Node
    uint32_t kind, primitive;
    float blend, lipschitz;
};
struct GpuPrimitiveExtra {  // PrimitiveExtra
    vec4 bound0, bound1, color;
};

// The pruned grid (cells.glsl, grid.glsl). Cell is PrunedCell (prune.hpp).
struct GpuBlock {  // Block
    uint32_t x, y, z, tape;
};
struct GpuLevel {  // Level
    uint32_t res, factor, offset, pad;
};
struct GpuGridParams {  // GridParams
    vec4 aabb_min, aabb_max, cell_size, inv_cell;
};

// counters.glsl: Counters (the pruning kernels' and expand.comp's).
// refine_cells: the entries of the refinement's list (prune_common.glsl: RefineList).
// near_lo, near_hi: expand.comp's bounds of the finest level's near-field cells ([lo, hi)).
// more_jobs: the cells the lane pass's first walks left to its second (its more list).
// long_jobs: the entries of refinement's long list, the cells its lane pass
// (prune_refine_lanes.comp) leaves to the squads after it.
// copy_cells: the entries at the back of refinement's list, the cells it only copies.
// walk_cells: the cells listed to decide again, per walk class; walk_placed: the order pass's
// places taken per class (prune_refine_lanes.comp).
inline constexpr uint32_t kRefineWalkClasses = kernel::kWalkClasses;
inline constexpr uint32_t kPruneOrderClasses = kernel::kOrderClasses;
inline constexpr uint32_t kPruneWalkSlots = kernel::kWalkSlots;
struct GpuCounters {
    uint32_t pool_used, pool_capacity, overflow, max_len, near_jobs, next_blocks, max_depth;
    uint32_t octant_used, octant_capacity, near_words, refine_cells;
    uint32_t near_lo[3], near_hi[3], long_jobs, more_jobs, copy_cells;
    uint32_t walk_cells[kRefineWalkClasses], walk_placed[kRefineWalkClasses];
    uint32_t scratch_claimed;
    // The team steps' order passes (prune_team.glsl: order_parents), the octants step's then the
    // cells step's: per class, the parents counted and the places taken.
    uint32_t order_count[2 * kPruneOrderClasses], order_placed[2 * kPruneOrderClasses];
    // A team step's jobs taken so far by its workgroups (prune_team.glsl: take_jobs), zeroed
    // before each of its dispatches.
    uint32_t jobs_taken;
    // Per step of a submission (PrunePush::walk_slot), the longest a workgroup walked in one
    // dispatch, in tape entries, and all its workgroups' walks summed (prune_common.glsl:
    // note_walk).
    uint32_t walk_words[kPruneWalkSlots], walk_sum[kPruneWalkSlots];
    // Refinement's second list (refine_lanes.glsl: more_place): its cells of each walk class.
    uint32_t more_class[kRefineWalkClasses];
};
// The lane pass of refinement takes tapes up to kRefineLaneTape words where few cells have
// longer ones (Pruner::choose_lane_tape), unless SDFPRUNE_VULKAN_REFINE_LANE_TAPE says (0: no
// lane pass, squads for every cell).
inline constexpr uint64_t kPruneStateWords = kernel::kStateWords;
inline constexpr uint64_t kPruneTeam = kernel::kTeam;
inline constexpr uint64_t kPruneWindow = kernel::kWindow;
inline constexpr uint64_t kPruneOrderWindow = kernel::kOrderWindow;
inline constexpr uint64_t kRefineSquad = kernel::kSquad;
inline constexpr uint32_t kLaneTapeMax = kernel::kLaneTapeMax;
inline constexpr uint32_t kRefineLaneTape = kernel::kRefineLaneTape;
inline constexpr uint64_t kRefineFirstBoxes = kernel::kFirstBoxes;
using kernel::refine_more_words;
// prune_wide.comp: kPruneWide lanes a workgroup; its scratch words for `items` items (an item
// per tape entry and box: value and range, then its flags a byte: prune_wide.glsl's
// item_words); kPruneWideHeightWords per scene height.
inline constexpr uint64_t kPruneWide = kernel::kWide;
inline constexpr uint64_t prune_wide_item_words(uint64_t items) {
    return items * kernel::kWideValueWords + (items + 3) / 4;
}
inline constexpr uint64_t kPruneWideHeightWords = kernel::kWideHeightWords;
// The walk of one of its workgroups over a job's parent tape of n entries, as gpu_prune_plan.cpp
// (plan_wide) and tools/prune_order_model.cpp model it: `boxes` boxes a workgroup, `rounds`
// the tape's rounds at most (a height of the scene each), `search` steps a search. Each lane's
// share of the entries in the sort with its searches; a step a round (at most n / 2 + 1) and
// its share of each round's items in the evaluation and the top-down pass; its slice of a
// box's tape in the compaction's two passes.
inline constexpr uint64_t prune_wide_job_walk(uint64_t n, uint64_t rounds, uint64_t boxes,
                                              uint64_t search) {
    const auto up = [](uint64_t a, uint64_t b) { return (a + b - 1) / b; };
    const uint64_t job_rounds = rounds < n / 2 + 1 ? rounds : n / 2 + 1;
    return up(n, kPruneWide) * (2 + search) + 2 * (job_rounds + up(n * boxes, kPruneWide)) +
           2 * up(n, kPruneWide / boxes);
}
inline constexpr uint64_t kPruneWideRunChunk = kernel::kRunChunk;
// A scene's figures for the wide kernel, from one pass over its nodes (post-order: operands
// first), as gpu_prune.cpp uploads them and plan_wide and tools/prune_order_model.cpp count:
// - spans: per node n, the first node of its subtree (2n) and its height (2n + 1);
// - height: the root's, so height + 1 rounds at most a tape;
// - shared_heights: the heights above the primitives' that more than one operator shares. Only
//   those can be a round of more than one entry in a tape, with a barrier of its own; the rest
//   are a chain's rounds, walked in runs (none but chain rounds in a left-deep chain, the
//   reference molecule);
// - search_steps: the steps of the search for an operator's left operand (prune_wide.glsl), back
//   from the right operand over at most that operand's subtree: the bit width of its nodes less
//   one, a step per level of a balanced subtree, none for a primitive (a left-deep chain's); per
//   entry, rounded up, and a step more for the lanes' spread (the generated fluid's 13,988
//   operators take 20,967 steps, 1 an entry, so 2).
struct WideSceneShape {
    std::vector<uint32_t> spans;
    uint32_t height = 0, shared_heights = 0, search_steps = 0;
};
inline WideSceneShape wide_scene_shape(const Scene& sc) {
    WideSceneShape shape;
    std::vector<uint32_t>& spans = shape.spans;
    spans.resize(2 * uint64_t(sc.size()));
    uint64_t steps = 0;
    for (uint32_t n = 0; n < sc.size(); ++n) {
        const bool prim = sc.is_primitive(n);
        spans[2 * n] = prim ? n : spans[2 * sc.left[n]];
        spans[2 * n + 1] =
            prim ? 0 : 1 + std::max(spans[2 * sc.left[n] + 1], spans[2 * sc.right[n] + 1]);
        if (!prim) steps += std::bit_width(sc.right[n] - spans[2 * sc.right[n]]);
    }
    const uint64_t count = std::max(sc.size(), 1u);
    shape.search_steps = uint32_t((steps + count - 1) / count + 1);
    if (sc.size() == 0) return shape;
    shape.height = spans[2 * sc.root() + 1];
    std::vector<uint32_t> height_operators(uint64_t(shape.height) + 1, 0);
    for (uint32_t n = 0; n < sc.size(); ++n)
        if (!sc.is_primitive(n)) ++height_operators[spans[2 * n + 1]];
    shape.shared_heights = uint32_t(std::count_if(height_operators.begin(), height_operators.end(),
                                                  [](uint32_t c) { return c > 1; }));
    return shape;
}
// Whether the Vulkan backend makes a level of `res` cells a side, `factor` a block, from octants
// first (an octants step, then a cells step from them), as gpu_prune.cpp does and
// tools/prune_order_model.cpp models: where the CPU splits it (splits_into_octants) and a
// block's cells divide 1,024.
inline bool level_splits_into_octants(const Scene& sc, const PruneOptions& opt, uint32_t res,
                                      uint32_t factor) {
    return splits_into_octants(sc, opt, res, factor) &&
           1024 % (uint64_t(factor) * factor * factor) == 0;
}
struct PrunePush {  // prune.comp and prune_wide.comp: Push
    vec4 origin, csize;
    uint32_t mode, factor, jobs, threads, max_len, max_stack, flags, pool_start, first_job;
    uint32_t round, budget, refine, octant_start, list_start, lane_tape, wide_split;
    uint32_t more_start, group_base, order_start, order_first, claim_words, walk_slot;
};
struct ExpandPush {  // expand.comp: Push
    uint32_t factor, cells_count, next_factor, bound_only;
};
struct CellInfoPush {  // cell_info.comp: Push
    uint32_t cells_count;
};

// trace.comp
struct TraceParams {
    GpuGridParams grid;
    vec4 march_min, march_max;  // the box rays are marched in (PrunedGrid::near_box)
    vec4 eye, forward, right, up, light;
    uint32_t width, height, shading, shadows;
};
struct GpuPixel {  // Pixel
    vec4 color;
    uint32_t evals, steps, pad0, pad1;
};
// discretize.comp
struct DiscretizeParams {
    GpuGridParams grid;
    vec4 sample_size;
    uint32_t n, pad0, pad1, pad2;
};
// trace.comp and discretize.comp: Push (slice.glsl). Items [first, first + count) of a slice,
// written from index `base` of the output buffer; full_tree_pass 1 takes them from the deferred
// list instead (slice.glsl says how the two passes share the work); loop_probe, the iterations
// of the loop limit's probe (0: none).
struct SlicePush {
    uint32_t first, count, stack_threads, base;
    uint32_t full_tree_pass, full_tree_fits, deferred_capacity, loop_probe;
};

static_assert(sizeof(GpuNode) == 16 && sizeof(GpuPrimitiveExtra) == 48);
static_assert(sizeof(math::PrimitiveParams) == 96 && offsetof(math::PrimitiveParams, a) == 48);
static_assert(sizeof(PrunedCell) == 16 && offsetof(PrunedCell, value) == 8);
static_assert(sizeof(GpuBlock) == 16 && sizeof(GpuLevel) == 16 && sizeof(GpuGridParams) == 64);
static_assert(sizeof(GpuCounters) ==
                  216 + 4 * 4 * kPruneOrderClasses + 8 * kPruneWalkSlots + 4 * kRefineWalkClasses &&
              offsetof(GpuCounters, near_lo) == 44 && offsetof(GpuCounters, long_jobs) == 68 &&
              offsetof(GpuCounters, copy_cells) == 76 &&
              offsetof(GpuCounters, walk_placed) == 80 + 4 * kRefineWalkClasses &&
              offsetof(GpuCounters, scratch_claimed) == 80 + 8 * kRefineWalkClasses &&
              offsetof(GpuCounters, order_placed) == 212 + 4 * 2 * kPruneOrderClasses &&
              offsetof(GpuCounters, jobs_taken) == 212 + 4 * 4 * kPruneOrderClasses);
static_assert(offsetof(PrunePush, first_job) == 64 && sizeof(PrunePush) == 128);
static_assert(sizeof(TraceParams) == 192 && sizeof(DiscretizeParams) == 96);
static_assert(sizeof(GpuPixel) == 32 && sizeof(SlicePush) == 32);

}  // namespace sdfprune::gpu
