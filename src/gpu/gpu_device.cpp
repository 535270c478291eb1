// gpu_device.cpp — Device and Grid (gpu.hpp): ownership, and reading a device grid back.
#include <cstring>

#include "device_grid.hpp"

namespace sdfprune::gpu {

bool built_with_vulkan() {
    return true;
}

Device::Device() : context_(std::make_unique<Context>()) {}
Device::~Device() = default;
Device::Device(Device&&) noexcept = default;
Device& Device::operator=(Device&&) noexcept = default;
std::string Device::name() const {
    return context_->device_name();
}

uint64_t Device::memory_in_use() const {
    return context_->bytes_live();
}

uint64_t Device::memory_cached() const {
    return context_->bytes_cached();
}

void Device::release_cached_memory() {
    context_->trim();
}

uint64_t Device::memory_reserved() const {
    return context_->reserve_bytes();
}

double Device::reserve_ms() const {
    return context_->reserve_ms();
}

bool Device::loop_limited() const {
    return context_->loop_limited();
}

Grid::Grid() = default;
Grid::~Grid() = default;
Grid::Grid(Grid&&) noexcept = default;
Grid& Grid::operator=(Grid&&) noexcept = default;
const DevicePruneStats& Grid::stats() const {
    return impl_->stats;
}
const Scene& Grid::scene() const {
    return *impl_->scene;
}

void Grid::for_each_finest_cell(
    const std::function<void(uint64_t, const CellContents&)>& visit) const {
    DeviceGrid& g = *impl_;
    const GpuLevel& last = g.level_info.back();
    const uint64_t cell_total = last.offset + (g.cells.size / sizeof(PrunedCell) - last.offset);
    std::vector<PrunedCell> cells(cell_total);
    g.ctx.download(g.cells, cells.data(), cells.size() * sizeof(PrunedCell));
    std::vector<uint32_t> pool(g.pool_words);
    g.ctx.download(g.pool, pool.data(), pool.size() * 4);
    const uint32_t N = last.res;
    const Scene& sc = *g.scene;
    const vec3 cs = (sc.aabb.max - sc.aabb.min) / float(N);
    const float L = sc.lipschitz[sc.root()];
    // What the device wrote is read with bounds: a cell or tape out of place (a kernel's bug, a
    // driver's) is an error, not a read past the copies.
    const auto malformed = [](const char* what) {
        return GpuError(std::string("the device's grid is malformed: ") + what);
    };
    for (uint32_t z = 0; z < N; ++z)
        for (uint32_t y = 0; y < N; ++y)
            for (uint32_t x = 0; x < N; ++x) {
                // The walk of PrunedGrid::cell and grid.glsl's locate.
                uint32_t block_start = 0;
                CellContents out;
                for (size_t li = 0; li < g.level_info.size(); ++li) {
                    const GpuLevel& l = g.level_info[li];
                    const uint32_t scale = N / l.res, f = l.factor;
                    const uint32_t sx = x / scale, sy = y / scale, sz = z / scale;
                    const uint64_t at =
                        uint64_t(l.offset) + block_start + ((sz % f) * f + sy % f) * f + sx % f;
                    if (at >= cells.size()) throw malformed("a cell past the cells");
                    const PrunedCell& c = cells[at];
                    if (c.tape == PrunedCell::kFarField) {
                        out.constant =
                            far_field_cell_constant(sc.aabb.min, cs, scale, L, c, x, y, z);
                        break;
                    }
                    if (li + 1 == g.level_info.size()) {
                        out.far_field = false;
                        if (uint64_t(c.tape) + 2 > pool.size() ||
                            pool[c.tape] > pool.size() - c.tape - 2)
                            throw malformed("a tape past the pool");
                        out.tape = {pool.data() + c.tape + 2, pool[c.tape]};
                        break;
                    }
                    block_start = c.children;
                }
                visit((uint64_t(z) * N + y) * N + x, out);
            }
}

}  // namespace sdfprune::gpu
