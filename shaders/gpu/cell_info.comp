#version 450
// cell_info.comp — (tape length, primitives) of each cell of a level, kFarField for far-field
// cells: what the host needs for the statistics without reading the whole tape pool.
#extension GL_GOOGLE_include_directive : require
#include "cells.glsl"

layout(local_size_x = 64) in;

layout(std430, binding = 0) readonly buffer Cells { Cell cells[]; };
layout(std430, binding = 1) readonly buffer Pool { uint pool[]; };
layout(std430, binding = 2) writeonly buffer Info { uvec2 info[]; };

layout(push_constant) uniform Push { uint cells_count; } pc;

void main() {
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    for (uint i = gl_GlobalInvocationID.x; i < pc.cells_count; i += stride) {
        uint t = cells[i].tape;
        info[i] = t == kFarField ? uvec2(kFarField, 0u) : uvec2(pool[t], pool[t + 1u]);
    }
}
