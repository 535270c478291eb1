// cells.glsl — the pruned grid's cells and blocks as the kernels see them; layouts match
// PrunedCell (prune.hpp) and src/gpu/device_layout.hpp (checked by the GpuLayout tests).
struct Cell {
    uint tape;      // kFarField or offset of [length, primitives, words...] in the pool
    uint children;  // near-field, not finest: first cell of its child block in the next level;
                    // far-field: 4 bits of clearance per octant (clearance_in, prune.hpp)
    float value;    // value at the centre
    float bound;    // far-field constant
};
struct Block {
    uint x, y, z;  // origin, in its level's cells
    uint tape;
};
const uint kFarField = 0xffffffffu;
