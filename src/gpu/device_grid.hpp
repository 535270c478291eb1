// device_grid.hpp — the GPU backend's data: the scene and the pruned grid in device buffers,
// as the host keeps them (the structs the shaders see are in device_layout.hpp).
#pragma once

#include <cstddef>
#include <vector>

#include "device_layout.hpp"
#include "sdfprune/gpu.hpp"
#include "vk_context.hpp"

namespace sdfprune::gpu {

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
    // The deepest evaluation stack (values) of the finest cells' tapes, the only pruned tapes
    // the tracing and discretizing kernels evaluate: it sizes their per-thread stacks. The
    // pruning steps' own figure for the finest level after refinement (GpuCounters::max_depth:
    // each tape written or shared adds its depth as the steps walk it).
    uint32_t finest_stack_depth = 1;
    // PrunedGrid::near_box, from the bounds of the finest level's near-field cells (expand.comp,
    // bound_only; the scene's box on a one-level grid).
    Aabb near_box;
    GpuGridParams grid_params() const;
};

}  // namespace sdfprune::gpu
