#version 450
// prune_wide_runs.comp — one pruning step, a workgroup per parent tape (prune_wide.glsl), with
// subgroup operations, and its long runs of one-operator rounds (a chain's) walked from shared
// memory, a chunk at a time: for the steps with few jobs and tapes of many heights (molecule's
// top levels). Its staging arrays cost the other steps occupancy, so they run
// prune_wide_subgroups.comp.
#define PRUNE_WIDE_SUBGROUPS
#define PRUNE_WIDE_RUNS
#include "prune_wide.glsl"
