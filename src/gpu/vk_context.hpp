// vk_context.hpp — the little of Vulkan the GPU backend needs: one compute queue, storage
// buffers, compute kernels built from the SPIR-V embedded at build time, and a recorder that
// batches dispatches and copies into one submission timed with GPU timestamps.
//
// Not thread-safe: one Context is used by one thread at a time.
#pragma once

#include <vulkan/vulkan.h>

#include <cstdint>
#include <string>
#include <vector>

#include "sdfprune/gpu.hpp"

namespace sdfprune::gpu {

// The kernels, one per compute shader in shaders/gpu/.
enum class KernelId : uint32_t { kPrune, kExpand, kCellInfo, kTrace, kDiscretize, kCount };

struct Buffer {
    VkBuffer buffer = VK_NULL_HANDLE;
    VkDeviceMemory memory = VK_NULL_HANDLE;
    VkDeviceSize size = 0;
    void* mapped = nullptr;  // host-visible buffers only
};

class Context {
public:
    // Opens the first Vulkan device with a compute queue (SDFPRUNE_VULKAN_DEVICE=N picks the
    // N-th); throws GpuError when there is none.
    Context();
    ~Context();
    Context(const Context&) = delete;
    Context& operator=(const Context&) = delete;

    const std::string& device_name() const { return device_name_; }
    // Largest storage buffer a shader may address, in bytes.
    uint64_t max_buffer_bytes() const { return max_range_; }

    // A storage buffer in device memory, or host-visible (mapped) for uploads and readbacks.
    // Throws GpuError when the device has no memory left for it.
    Buffer create_buffer(uint64_t bytes, bool host_visible = false);
    void destroy(Buffer& b);
    // Device memory held by live buffers, now and at most since reset_peak().
    uint64_t bytes_live() const { return live_; }
    uint64_t bytes_peak() const { return peak_; }
    void reset_peak() { peak_ = live_; }

    // Recording: begin(), any number of dispatch()/copy()/fill(), then submit() runs them in
    // order (each waits for the previous one's writes) and returns the GPU milliseconds they took.
    void begin();
    void dispatch(KernelId k, std::initializer_list<const Buffer*> buffers, const void* push,
                  uint32_t push_bytes, uint32_t groups);
    void copy(const Buffer& src, const Buffer& dst, uint64_t bytes, uint64_t src_offset = 0,
              uint64_t dst_offset = 0);
    void fill(const Buffer& dst, uint32_t value);
    double submit();

    // Blocking transfers through a staging buffer.
    void upload(const Buffer& dst, const void* data, uint64_t bytes, uint64_t dst_offset = 0);
    void download(const Buffer& src, void* data, uint64_t bytes, uint64_t src_offset = 0);

private:
    struct Kernel {
        VkDescriptorSetLayout set_layout = VK_NULL_HANDLE;
        VkPipelineLayout layout = VK_NULL_HANDLE;
        VkPipeline pipeline = VK_NULL_HANDLE;
        uint32_t bindings = 0;
    };
    void barrier();
    void check(VkResult r, const char* what) const;
    uint32_t memory_type(uint32_t bits, bool host_visible) const;

    VkInstance instance_ = VK_NULL_HANDLE;
    VkPhysicalDevice physical_ = VK_NULL_HANDLE;
    VkDevice device_ = VK_NULL_HANDLE;
    VkQueue queue_ = VK_NULL_HANDLE;
    uint32_t queue_family_ = 0;
    VkCommandPool command_pool_ = VK_NULL_HANDLE;
    VkCommandBuffer cmd_ = VK_NULL_HANDLE;
    VkFence fence_ = VK_NULL_HANDLE;
    VkDescriptorPool descriptor_pool_ = VK_NULL_HANDLE;
    VkQueryPool timestamps_ = VK_NULL_HANDLE;
    double timestamp_ns_ = 1;  // nanoseconds per tick
    std::vector<Kernel> kernels_;
    VkPhysicalDeviceMemoryProperties memory_{};
    std::string device_name_;
    uint64_t max_range_ = 0;
    uint64_t live_ = 0, peak_ = 0;
    uint32_t sets_used_ = 0;
    bool recording_ = false;
};

}  // namespace sdfprune::gpu
