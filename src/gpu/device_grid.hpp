// device_grid.hpp — the GPU backend's data: the scene and the pruned grid in device buffers,
// with the host-side mirrors of the shaders' structs (shaders/gpu/*.glsl). Layouts are std430;
// the static_asserts below pin them on the C++ side, the kernels' tests against the CPU
// backend check them on the GLSL side.
#pragma once

#include <cstddef>
#include <vector>

#include "sdfprune/gpu.hpp"
#include "vk_context.hpp"

namespace sdfprune::gpu {

using math::vec4;

struct GpuNode {  // scene.glsl: Node
    uint32_t kind, primitive;
    float blend, lipschitz;
};
struct GpuPrimitiveExtra {  // scene.glsl: PrimitiveExtra
    vec4 bound0, bound1, color;
};
struct GpuBlock {  // cells.glsl: Block
    uint32_t x, y, z, tape;
};
struct GpuLevel {  // grid.glsl: Level
    uint32_t res, factor, offset, pad;
};
struct GpuGridParams {  // grid.glsl: GridParams
    vec4 aabb_min, aabb_max, cell_size, inv_cell;
};
static_assert(sizeof(GpuNode) == 16 && sizeof(GpuPrimitiveExtra) == 48);
static_assert(sizeof(GpuBlock) == 16 && sizeof(GpuLevel) == 16);
static_assert(sizeof(PrunedCell) == 16 && offsetof(PrunedCell, value) == 8);  // cells.glsl: Cell
static_assert(sizeof(math::PrimitiveParams) == 96 && offsetof(math::PrimitiveParams, a) == 48);
static_assert(sizeof(GpuGridParams) == 64);

// Counters of prune.comp / expand.comp.
struct GpuCounters {
    uint32_t pool_used, pool_capacity, overflow, max_len, near_jobs, next_blocks, max_depth;
    uint32_t octant_used, octant_capacity, pad[3];
};

// The pruned grid on the device.
class DeviceGrid {
  public:
    DeviceGrid(Context& ctx, const Scene& scene) : ctx(ctx), scene(&scene) {}
    ~DeviceGrid();
    Context& ctx;
    const Scene* scene;
    DevicePruneStats stats;
    Buffer nodes, params, extras, pool;  // bindings 0-3 of every evaluating kernel
    Buffer cells;                        // all levels' cells, concatenated
    Buffer levels;                       // GpuLevel per level
    std::vector<GpuLevel> level_info;
    uint32_t pool_words = 0;  // words in use in `pool`
    GpuGridParams grid_params() const;
};

}  // namespace sdfprune::gpu
