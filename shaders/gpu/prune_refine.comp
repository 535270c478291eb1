#version 450
// prune_refine.comp — refinement (mode 3) on teams of lanes (prune_team.glsl), the tapes that
// fit a team's window refined in shared memory (s_meta).
#define PRUNE_REFINE_WINDOW
#include "prune_team.glsl"
