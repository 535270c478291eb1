#version 450
// prune_refine_lanes_long.comp — refinement's lane pass (refine_lanes.glsl), a lane per finest
// cell whose tape has at most 64 words: where the host chooses so (gpu_prune_plan.cpp:
// choose_lane_tape), the squads would take the longer tapes in several rounds.
#define REFINE_LANES_LONG
#include "refine_lanes.glsl"
