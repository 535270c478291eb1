// gpu_stub.cpp — the GPU backend's entry points in a build without Vulkan or glslc: every one
// says so with a GpuError (the CLI turns it into a one-line message and exit status 2).
#include "sdfprune/gpu.hpp"

namespace sdfprune::gpu {

class Context {};
class DeviceGrid {};

namespace {
[[noreturn]] void missing() {
    throw GpuError(
        "this sdfprune was built without the Vulkan backend (needs libvulkan-dev "
        "and glslc)");
}
}  // namespace

bool built_with_vulkan() {
    return false;
}
Device::Device() {
    missing();
}
Device::~Device() = default;
Device::Device(Device&&) noexcept = default;
Device& Device::operator=(Device&&) noexcept = default;
std::string Device::name() const {
    missing();
}
uint64_t Device::memory_in_use() const {
    missing();
}
uint64_t Device::memory_cached() const {
    missing();
}
void Device::release_cached_memory() {
    missing();
}
uint64_t Device::memory_reserved() const {
    missing();
}
double Device::reserve_ms() const {
    missing();
}
bool Device::loop_limited() const {
    missing();
}
Grid::Grid() = default;
Grid::~Grid() = default;
Grid::Grid(Grid&&) noexcept = default;
Grid& Grid::operator=(Grid&&) noexcept = default;
const DevicePruneStats& Grid::stats() const {
    missing();
}
const Scene& Grid::scene() const {
    missing();
}
void Grid::for_each_finest_cell(const std::function<void(uint64_t, const CellContents&)>&) const {
    missing();
}
Grid prune(Device&, const Scene&, const PruneOptions&) {
    missing();
}
Image render(Device&, const Grid&, const RenderOptions&, RenderStats*) {
    missing();
}
void discretize(Device&, const Grid&, uint32_t, std::span<float>, DiscretizeStats*) {
    missing();
}

}  // namespace sdfprune::gpu
