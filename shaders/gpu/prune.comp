#version 450
// prune.comp — one pruning step of a level on teams of lanes (prune_team.glsl): the octants and
// the cells (modes 0–2), and refinement on devices that run it here.
#include "prune_team.glsl"
