#version 450
// prune_refine_lanes.comp — refinement's lane pass (refine_lanes.glsl), a lane per finest cell
// whose tape has at most 32 words: the host's usual choice.
#include "refine_lanes.glsl"
