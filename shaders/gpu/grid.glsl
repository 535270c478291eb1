// grid.glsl — finding the cell that decides a point in the pruned grid (PrunedGrid::cell_index,
// locate, far_field_constant in src/prune/prune.cpp), for the tracing and discretization
// kernels. Uses bindings 4 (all levels' cells, concatenated) and 5 (the levels).
#include "cells.glsl"

struct Level {
    uint res;     // cells per axis of the whole level
    uint factor;  // cells per axis of one block (level 0: res)
    uint offset;  // first cell of the level in `cells`
    uint pad;
};
struct GridParams {
    vec4 aabb_min;   // w: Lipschitz bound of the root
    vec4 aabb_max;   // w: 1 / that bound
    vec4 cell_size;  // finest cells; w: finest resolution N (as float, exact)
    vec4 inv_cell;   // 1 / cell_size (computed on the host, as the CPU does); w: levels
};

layout(std430, binding = 4) restrict readonly buffer Cells { Cell cells[]; };
layout(std430, binding = 5) restrict readonly buffer Levels { Level levels[]; };

struct Located {
    uint level;
    uvec3 cell;   // coordinates at that level
    uvec3 finest; // finest cell holding the point
    Cell c;
};

bool locate(GridParams g, vec3 p, out Located at) {
    uint N = uint(g.cell_size.w);
    at.level = 0u;
    at.cell = uvec3(0u);
    at.finest = uvec3(0u);
    at.c = Cell(kFarField, 0u, 0.0, 0.0);
    for (int a = 0; a < 3; ++a) {
        if (!(p[a] >= g.aabb_min[a]) || !(p[a] <= g.aabb_max[a])) return false;
        at.finest[a] = finest_cell_on_axis(p[a], g.aabb_min[a], g.inv_cell[a], N - 1u);
    }
    uint count = uint(g.inv_cell.w);
    uint block_start = 0u;
    for (uint li = 0u; li < count; ++li) {
        Level l = levels[li];
        uint scale = N / l.res, f = l.factor;
        uint local = block_local_index(at.finest.x, at.finest.y, at.finest.z, scale, f);
        Cell c = cells[l.offset + block_start + local];
        if (c.tape == kFarField || li + 1u == count) {
            at.level = li;
            at.cell = at.finest / scale;
            at.c = c;
            return true;
        }
        block_start = c.children;
    }
    return false;
}

vec3 level_cell_size(GridParams g, uint level) {
    return (g.aabb_max.xyz - g.aabb_min.xyz) / float(levels[level].res);
}

// The far-field constant of a finest cell inside far-field cell `at` (far_field_constant).
float far_field_constant_at(GridParams g, Located at) {
    uint scale = uint(g.cell_size.w) / levels[at.level].res;
    return far_field_cell_constant(g.aabb_min.xyz, g.cell_size.xyz, scale, g.aabb_min.w,
                                   at.c.value, at.c.bound, at.finest.x, at.finest.y, at.finest.z);
}
