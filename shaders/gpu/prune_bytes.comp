#version 450
// prune_bytes.comp — prune.comp (prune_team.glsl) with each entry's decision and sweep flags a
// byte a lane instead of a word: a team's scratch per parent-tape entry 3 words instead of 9.
// Built where the device has 8-bit storage buffers (Context::byte_storage) and subgroup
// arithmetic and ballot (Context::subgroups): its appends to the pools and to refinement's list
// take one atomic per subgroup (prune_common.glsl: PRUNE_SUBGROUPS).
#extension GL_EXT_shader_8bit_storage : require
#define PRUNE_BYTE_FLAGS
#define PRUNE_SUBGROUPS
#include "prune_team.glsl"
