#version 450
// prune_wide_subgroups.comp — one pruning step, a workgroup per parent tape (prune_wide.glsl),
// with its prefix sums and pool appends on subgroup operations.
#define PRUNE_WIDE_SUBGROUPS
#include "prune_wide.glsl"
