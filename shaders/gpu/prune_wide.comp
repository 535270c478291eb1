#version 450
// prune_wide.comp — one pruning step, a workgroup per parent tape (prune_wide.glsl), with its
// prefix sums in shared memory: for devices without subgroup operations.
#include "prune_wide.glsl"
