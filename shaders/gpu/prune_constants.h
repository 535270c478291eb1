// prune_constants.h — what the pruning kernels (prune*.comp) and the host that plans their
// steps (src/gpu/gpu_prune_plan.cpp) must agree on, written once: the steps' modes, the bits of
// the push constants' flags, and the sizes both sides count scratch and jobs with. Valid GLSL
// 450 and C++20, like sdf_math.h. In C++ its names are in sdfprune::gpu::kernel;
// device_layout.hpp gives the sizes the 64-bit types the host's plans count in.
#ifndef SDFPRUNE_PRUNE_CONSTANTS_H
#define SDFPRUNE_PRUNE_CONSTANTS_H

#ifdef __cplusplus
#include <cstdint>
#define SDFPRUNE_KERNEL_CONST inline constexpr
#define SDFPRUNE_KERNEL_FN inline constexpr
namespace sdfprune::gpu::kernel {
using uint = std::uint32_t;
#else
#define SDFPRUNE_KERNEL_CONST const
#define SDFPRUNE_KERNEL_FN
#endif

// ---- a step's mode (the push constants' mode) ------------------------------------------------
// Team and wide steps: the cells of a block from the block's tape; a block's 8 octants; the
// cells of an octant from the octant's tape (prune_common.glsl: job_box).
SDFPRUNE_KERNEL_CONST uint kModeCells = 0u;
SDFPRUNE_KERNEL_CONST uint kModeOctants = 1u;
SDFPRUNE_KERNEL_CONST uint kModeOctantCells = 2u;
// The finest near-field cells' sub-box refinement (prune_refine*.comp).
SDFPRUNE_KERNEL_CONST uint kModeRefine = 3u;
// The order passes before a team step (prune_team.glsl: order_parents): the parents counted
// per class, then each parent's place taken.
SDFPRUNE_KERNEL_CONST uint kModeOrderCount = 4u;
SDFPRUNE_KERNEL_CONST uint kModeOrderPlace = 5u;

// ---- the bits of a step's flags (the push constants' flags) ----------------------------------
// The far field is on; the cells' bounds are intervals (else Lipschitz bounds).
SDFPRUNE_KERNEL_CONST uint kStepFarField = 1u;
SDFPRUNE_KERNEL_CONST uint kStepIntervalBounds = 2u;
// The step makes the finest cells before refinement: their new tapes go to the octant pool
// (transient), and the near ones are listed for refinement (refine_list).
SDFPRUNE_KERNEL_CONST uint kStepTransientTapes = 4u;
// prune_refine.comp takes its jobs from the long list (the cells the lane pass left it).
SDFPRUNE_KERNEL_CONST uint kStepLongList = 8u;
// prune_refine_lanes.comp: its second pass (its jobs the more list); every sub-box in one
// pass; its order pass; refinement's walks taken from the order list (refine_job).
SDFPRUNE_KERNEL_CONST uint kStepRefineSecondPass = 32u;
SDFPRUNE_KERNEL_CONST uint kStepRefineOnePass = 64u;
SDFPRUNE_KERNEL_CONST uint kStepRefineOrderPass = 128u;
SDFPRUNE_KERNEL_CONST uint kStepRefineOrdered = 256u;
// Modes 1 and 2: the team jobs taken from the order list (prune_team.glsl: ordered_job).
SDFPRUNE_KERNEL_CONST uint kStepTeamsOrdered = 512u;
// Modes 4 and 5: the parents ordered are blocks (else octants); mode 5 sorts each window of
// parents apart (else the whole step's).
SDFPRUNE_KERNEL_CONST uint kStepOrderBlocks = 1024u;
SDFPRUNE_KERNEL_CONST uint kStepOrderWindows = 2048u;
// Ordered jobs are dealt in rounds, not in a snake (prune_common.glsl: snake_deal).
SDFPRUNE_KERNEL_CONST uint kStepDealInRounds = 4096u;
// Modes 0-2: the jobs are taken as workgroups come free (take_from_counter), not dealt.
SDFPRUNE_KERNEL_CONST uint kStepTakeJobs = 8192u;
// The sweeps pass over the whole tape (no early end once the kept entries are all reached).
SDFPRUNE_KERNEL_CONST uint kStepWholeSweeps = 16384u;
// Refinement's second list in the order listed (else sorted by walk class).
SDFPRUNE_KERNEL_CONST uint kStepMoreAsListed = 32768u;
// prune_wide.comp sweeps long runs round by round (no scan).
SDFPRUNE_KERNEL_CONST uint kStepWideNoScan = 65536u;
// Bits 24-31 are a count, not a flag: where it is not 0 (on a device with a loop limit), every
// invocation ends its step with a loop of that many iterations, and one that ran fewer found
// the limit reached: its loops may have ended early (prune_common.glsl: probe_loop_limit).
SDFPRUNE_KERNEL_CONST uint kStepLoopProbeShift = 24u;
SDFPRUNE_KERNEL_CONST uint kLoopProbeIterations = 2u;
// The bits of the counters' overflow word: the main pool overflowed; the octant pool; a job's
// scratch claim failed (a bug); an invocation reached the device's loop limit (a bug).
SDFPRUNE_KERNEL_CONST uint kOverflowPool = 1u;
SDFPRUNE_KERNEL_CONST uint kOverflowOctantPool = 2u;
SDFPRUNE_KERNEL_CONST uint kOverflowClaim = 4u;
SDFPRUNE_KERNEL_CONST uint kOverflowLoopLimit = 8u;

// ---- sizes ------------------------------------------------------------------------------------
// Boxes per team job: the lanes of a team that walk one parent tape in lockstep, a box each
// (prune_team.glsl), and the boxes of a wide job (prune_wide.glsl).
SDFPRUNE_KERNEL_CONST uint kTeam = 8u;
// prune_team.glsl: the tape entries a lane advances per step and phase; the words of a lane's
// job state in its team's scratch; the parents a workgroup counts together in the order passes.
SDFPRUNE_KERNEL_CONST uint kWindow = 64u;
SDFPRUNE_KERNEL_CONST uint kStateWords = 16u;
SDFPRUNE_KERNEL_CONST uint kOrderWindow = 256u;
// The team steps' order classes (prune_team.glsl: parent_class), refinement's walk classes
// (refine_walk_class), and the steps of a submission whose walks are measured (walk_words).
SDFPRUNE_KERNEL_CONST uint kOrderClasses = 32u;
SDFPRUNE_KERNEL_CONST uint kWalkClasses = 16u;
SDFPRUNE_KERNEL_CONST uint kWalkSlots = 8u;
// Bit 30 of a tape word staged by prune_team.glsl, set for a primitive (node indices are below
// it on a device: gpu_prune.cpp).
SDFPRUNE_KERNEL_CONST uint kStagedPrimitive = 1u << 30;
// prune_refine.comp: the lanes that refine one cell.
SDFPRUNE_KERNEL_CONST uint kSquad = 32u;
// prune_refine_lanes.comp: the longest tape a lane may refine alone (the size of its arrays,
// prune_refine_lanes_long.comp), and the longest it does where few cells have longer tapes
// (prune_refine_lanes.comp; Pruner::choose_lane_tape).
SDFPRUNE_KERNEL_CONST uint kLaneTapeMax = 64u;
SDFPRUNE_KERNEL_CONST uint kRefineLaneTape = 32u;
// prune_refine_lanes.comp: the sub-boxes its first pass walks for every cell (the corners and
// the middle), and the words of a cell's state in the more list: kMoreWords where the lanes
// take tapes longer than kRefineLaneTape (its entries' decisions in two words each), else 3
// fewer (refine_lanes.glsl: more_words).
SDFPRUNE_KERNEL_CONST uint kFirstBoxes = 9u;
SDFPRUNE_KERNEL_CONST uint kMoreWords = 10u;
SDFPRUNE_KERNEL_FN uint refine_more_words(uint lane_tape) {
    return lane_tape > kRefineLaneTape ? kMoreWords : kMoreWords - 3u;
}
// prune_wide.glsl: the lanes of a workgroup that takes one wide job; the words of an item's
// value and range (its flags are a byte more); the words of a round's record; the scratch words
// per scene height (3 for the counting sort, a round's, 1 in the list of breaks); the rounds of a
// run staged at a time.
SDFPRUNE_KERNEL_CONST uint kWide = 256u;
SDFPRUNE_KERNEL_CONST uint kWideValueWords = 3u;
SDFPRUNE_KERNEL_CONST uint kRoundWords = 8u;
SDFPRUNE_KERNEL_CONST uint kWideHeightWords = 3u + kRoundWords + 1u;
SDFPRUNE_KERNEL_CONST uint kRunChunk = 32u;

#ifdef __cplusplus
}  // namespace sdfprune::gpu::kernel
#endif

#endif  // SDFPRUNE_PRUNE_CONSTANTS_H
