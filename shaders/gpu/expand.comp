#version 450
// expand.comp — the next level's blocks: one per near-field cell of this level, allocated with
// an atomic counter (block order does not matter: each cell records where its block went).
// With bound_only, on the finest level's final cells instead: the bounds of its near-field
// cells (near_lo, near_hi in counters.glsl, in finest cells, [lo, hi)), from which the host
// makes PrunedGrid::near_box, the box the tracer marches in.
#extension GL_GOOGLE_include_directive : require
#include "cells.glsl"

layout(local_size_x = 64) in;

layout(std430, binding = 0) readonly buffer Blocks { Block blocks[]; };
layout(std430, binding = 1) buffer Cells { Cell cells[]; };
layout(std430, binding = 2) writeonly buffer Next { Block next[]; };
#define COUNTERS_BINDING 3
#include "counters.glsl"

layout(push_constant) uniform Push {
    uint factor;       // f: cells per axis of this level's blocks
    uint cells_count;  // cells of this level
    uint next_factor;  // cells per axis of the next level's blocks
    uint bound_only;   // 1: bound this level's near-field cells, make no blocks
} pc;

shared uint group_lo[3], group_hi[3];

void bound_near_cells() {
    if (gl_LocalInvocationIndex == 0u) {
        for (int a = 0; a < 3; ++a) {
            group_lo[a] = 0xffffffffu;
            group_hi[a] = 0u;
        }
    }
    barrier();
    uvec3 lo = uvec3(0xffffffffu), hi = uvec3(0u);
    uint f = pc.factor, per_block = f * f * f;
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    for (uint i = gl_GlobalInvocationID.x; i < pc.cells_count; i += stride) {
        if (cells[i].tape == kFarField) continue;
        Block b = blocks[i / per_block];
        uint local = i % per_block;
        uvec3 at = uvec3(b.x + local % f, b.y + (local / f) % f, b.z + local / (f * f));
        lo = min(lo, at);
        hi = max(hi, at + 1u);
    }
    // The workgroup's bounds in shared memory, then one global atomic per axis and side.
    for (int a = 0; a < 3; ++a) {
        atomicMin(group_lo[a], lo[a]);
        atomicMax(group_hi[a], hi[a]);
    }
    barrier();
    if (gl_LocalInvocationIndex == 0u && group_lo[0] <= group_hi[0]) {
        for (int a = 0; a < 3; ++a) {
            atomicMin(near_lo[a], group_lo[a]);
            atomicMax(near_hi[a], group_hi[a]);
        }
    }
}

void main() {
    if (pc.bound_only != 0u) {
        bound_near_cells();
        return;
    }
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    for (uint i = gl_GlobalInvocationID.x; i < pc.cells_count; i += stride) {
    Cell c = cells[i];
    if (c.tape == kFarField) continue;
    uint f = pc.factor, nf = pc.next_factor, per_block = f * f * f;
    uint idx = atomicAdd(next_blocks, 1u);
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
