#version 450
// expand.comp — the next level's blocks: one per near-field cell of this level, allocated with
// an atomic counter (block order does not matter: each cell records where its block went).
#extension GL_GOOGLE_include_directive : require
#include "cells.glsl"

layout(local_size_x = 64) in;

layout(std430, binding = 0) readonly buffer Blocks { Block blocks[]; };
layout(std430, binding = 1) buffer Cells { Cell cells[]; };
layout(std430, binding = 2) writeonly buffer Next { Block next[]; };
layout(std430, binding = 3) buffer Counters { uint counters[]; };  // [5]: blocks allocated

layout(push_constant) uniform Push {
    uint factor;       // f: cells per axis of this level's blocks
    uint cells_count;  // cells of this level
    uint next_factor;  // cells per axis of the next level's blocks
} pc;

void main() {
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    for (uint i = gl_GlobalInvocationID.x; i < pc.cells_count; i += stride) {
    Cell c = cells[i];
    if (c.tape == kFarField) continue;
    uint f = pc.factor, nf = pc.next_factor, per_block = f * f * f;
    uint idx = atomicAdd(counters[5], 1u);
    cells[i].children = idx * nf * nf * nf;
    Block b = blocks[i / per_block];
    uint local = i % per_block;
    Block n;
    n.x = (b.x + local % f) * nf;
    n.y = (b.y + (local / f) % f) * nf;
    n.z = (b.z + local / (f * f)) * nf;
    n.tape = c.tape;
    next[idx] = n;
    }
}
