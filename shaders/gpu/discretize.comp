#version 450
// discretize.comp — the pruned field at the centres of an n³ grid over the AABB, one value per
// thread: the finest cell's tape at the centre, or its far-field constant
// (PrunedGrid::eval and discretize_pruned); a centre outside the grid (only by rounding) gets
// the full tree's value, in the full-tree pass (slice.glsl).
#extension GL_GOOGLE_include_directive : require
#define SCENE_STACK_BINDING 8
#include "scene.glsl"
#include "grid.glsl"
#include "slice.glsl"

layout(local_size_x = 64) in;

struct DiscretizeParams {
    GridParams grid;
    vec4 sample_size;  // (aabb.max - aabb.min) / n
    uint n, pad0, pad1, pad2;
};

layout(std430, binding = 6) readonly buffer DiscretizeParamBlock { DiscretizeParams prm; };
layout(std430, binding = 7) writeonly buffer Values { float values[]; };  // from index base

void main() {
    uint tid = gl_GlobalInvocationID.x;
    if (tid >= pc.count) return;
    uint index = slice_item(tid);  // (z·n + y)·n + x
    uint n = prm.n;
    uvec3 i = uvec3(index % n, (index / n) % n, index / (n * n));
    GridParams g = prm.grid;
    // (cell_centre: no fused multiply-add, so p rounds as on the CPU and lands in the same cell)
    vec3 p = cell_centre(g.aabb_min.xyz, prm.sample_size.xyz, i.x, i.y, i.z);
    Located at;
    float v;
    if (!locate(g, p, at)) {
        if (!stack_holds(kFullTreeTape)) {
            defer_item(index);
            return;
        }
        v = eval_tape(kFullTreeTape, p, tid, pc.stack_threads);
    } else if (at.c.tape == kFarField) {
        v = far_field_constant_at(g, at);
    } else {
        v = eval_tape(at.c.tape, p, tid, pc.stack_threads);
    }
    probe_loop_limit();
    values[index - pc.base] = v;
}
