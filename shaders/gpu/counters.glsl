// counters.glsl — the pruning's counters (device_layout.hpp: GpuCounters), one buffer that
// the pruning kernels (prune_common.glsl, binding 7) and expand.comp (binding 3) share: pool
// appends, the lists' entries, the next level's blocks, the near-field cells' bounds and the
// walks measured. The includer defines COUNTERS_BINDING.
#ifndef SDFPRUNE_COUNTERS_GLSL
#define SDFPRUNE_COUNTERS_GLSL
#include "prune_constants.h"

layout(std430, binding = COUNTERS_BINDING) buffer Counters {
    uint pool_used;
    uint pool_capacity;
    uint overflow;  // kOverflow* bits (prune_constants.h)
    uint max_len;  // longest tape written or shared in this step
    uint near_jobs;  // near-field cells (octants) in this step
    uint next_blocks;  // the next level's blocks made so far (expand.comp)
    uint max_depth;  // deepest evaluation stack of the tapes written or shared in this step
    uint octant_used;      // the octant pool, as pool_used, pool_capacity
    uint octant_capacity;
    uint near_words;  // words of the near-field cells' tapes with their headers (modes 0 and 2;
                      // mode 1: the octants' tapes, shared ones too)
    uint refine_cells;  // entries of refine_list
    uint near_lo[3];    // expand.comp's (GpuCounters)
    uint near_hi[3];
    uint long_jobs;  // entries of refinement's long list (prune_refine_lanes.comp)
    uint more_jobs;  // entries of the lane pass's second list (prune_refine_lanes.comp)
    uint copy_cells;  // entries of refine_list that refinement only copies (list_near_cell)
    // Per walk class (refine_walk_class) the cells listed to decide again, and in refinement's
    // order pass the places of that class taken so far (prune_refine_lanes.comp).
    uint walk_cells[kWalkClasses];
    uint walk_placed[kWalkClasses];
    uint scratch_claimed;  // scratch words the jobs of a team step claimed (prune_team.glsl)
    // The team steps' order passes (prune_team.glsl: order_parents), the octants step's then
    // the cells step's: per class, the parents counted (mode 4) and the places taken (mode 5).
    uint order_count[2u * kOrderClasses];
    uint order_placed[2u * kOrderClasses];
    uint jobs_taken;  // a team step's jobs taken so far (prune_team.glsl: take_jobs, kStepTakeJobs)
    // Per step of a submission (pc.walk_slot), the longest walk of a workgroup in one dispatch,
    // in tape entries (note_walk), and the walks of all its workgroups summed.
    uint walk_words[kWalkSlots];
    uint walk_sum[kWalkSlots];
    // Refinement's second list by walk class (refine_lanes.glsl: more_place), its cells of each
    // class listed so far.
    uint more_class[kWalkClasses];
};

#endif  // SDFPRUNE_COUNTERS_GLSL
