// vk_context.cpp — instance, device, queue, kernels and submissions (vk_context.hpp); the
// buffers' memory is vk_memory.cpp's.
#include "vk_context.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <numeric>
#include <thread>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "../core/clock.hpp"
#include "device_layout.hpp"

namespace sdfprune::gpu {
namespace {

// SPIR-V of the kernels, compiled by glslc at build time (CMakeLists.txt).
const uint32_t kPruneSpv[] = {
#include "prune.spv.inc"
};
const uint32_t kPruneBytesSpv[] = {
#include "prune_bytes.spv.inc"
};
const uint32_t kPruneRefineLanesSpv[] = {
#include "prune_refine_lanes.spv.inc"
};
const uint32_t kPruneRefineLanesLongSpv[] = {
#include "prune_refine_lanes_long.spv.inc"
};
const uint32_t kPruneRefineSpv[] = {
#include "prune_refine.spv.inc"
};
const uint32_t kPruneWideSpv[] = {
#include "prune_wide.spv.inc"
};
const uint32_t kPruneWideSubgroupsSpv[] = {
#include "prune_wide_subgroups.spv.inc"
};
const uint32_t kPruneWideRunsSpv[] = {
#include "prune_wide_runs.spv.inc"
};
const uint32_t kExpandSpv[] = {
#include "expand.spv.inc"
};
const uint32_t kCellInfoSpv[] = {
#include "cell_info.spv.inc"
};
const uint32_t kTraceSpv[] = {
#include "trace.spv.inc"
};
const uint32_t kDiscretizeSpv[] = {
#include "discretize.spv.inc"
};

struct KernelCode {
    const char* name;  // its shader's, in SDFPRUNE_VULKAN_KERNEL_STATS's report
    const uint32_t* words;
    size_t bytes;
    uint32_t bindings;                     // storage buffers 0 .. bindings-1
    uint32_t local_size = kWorkgroupSize;  // local_size_x: built only where the device allows it
    bool subgroups = false;     // built only where the device has them (Context::subgroups)
    bool byte_storage = false;  // built only where the device has it (Context::byte_storage)
};

// Binding counts must match the shaders' layouts (shaders/gpu/*.comp).
const KernelCode kKernels[] = {
    {"prune", kPruneSpv, sizeof(kPruneSpv), 13},
    {"prune_bytes", kPruneBytesSpv, sizeof(kPruneBytesSpv), 13, kWorkgroupSize, true, true},
    {"prune_refine_lanes", kPruneRefineLanesSpv, sizeof(kPruneRefineLanesSpv), 13, kWorkgroupSize,
     true},
    {"prune_refine_lanes_long", kPruneRefineLanesLongSpv, sizeof(kPruneRefineLanesLongSpv), 13,
     kWorkgroupSize, true},
    {"prune_refine", kPruneRefineSpv, sizeof(kPruneRefineSpv), 13},
    {"prune_wide", kPruneWideSpv, sizeof(kPruneWideSpv), 13, uint32_t(kPruneWide), false, true},
    {"prune_wide_subgroups", kPruneWideSubgroupsSpv, sizeof(kPruneWideSubgroupsSpv), 13,
     uint32_t(kPruneWide), true, true},
    {"prune_wide_runs", kPruneWideRunsSpv, sizeof(kPruneWideRunsSpv), 13, uint32_t(kPruneWide),
     true, true},
    {"expand", kExpandSpv, sizeof(kExpandSpv), 4},
    {"cell_info", kCellInfoSpv, sizeof(kCellInfoSpv), 3},
    {"trace", kTraceSpv, sizeof(kTraceSpv), 10},
    {"discretize", kDiscretizeSpv, sizeof(kDiscretizeSpv), 10},
};
static_assert(std::size(kKernels) == size_t(KernelId::kCount));

constexpr uint32_t kMaxBindings = 13;
constexpr uint32_t kMaxSets = Context::kMaxDispatches;
constexpr uint32_t kPushBytes = 128;
// Scratch memory of the per-thread arrays and stacks of the kernels.
constexpr uint64_t kScratchBudgetBytes = uint64_t(256) << 20;

// Whether the instance (device null) or the device offers the extension.
bool has_extension(VkPhysicalDevice device, const char* name) {
    uint32_t n = 0;
    std::vector<VkExtensionProperties> ext;
    if (device) {
        vkEnumerateDeviceExtensionProperties(device, nullptr, &n, nullptr);
        ext.resize(n);
        vkEnumerateDeviceExtensionProperties(device, nullptr, &n, ext.data());
    } else {
        vkEnumerateInstanceExtensionProperties(nullptr, &n, nullptr);
        ext.resize(n);
        vkEnumerateInstanceExtensionProperties(nullptr, &n, ext.data());
    }
    ext.resize(n);
    return std::any_of(ext.begin(), ext.end(), [&](const VkExtensionProperties& e) {
        return std::strcmp(e.extensionName, name) == 0;
    });
}

}  // namespace

// SDFPRUNE_VULKAN_KERNEL_STATS: one line per compiled kernel and executable on stderr, the
// driver's statistics of it ("vulkan kernel NAME: statistic=value, ...").
void Context::report_kernel_statistics(const char* name, VkPipeline pipeline) const {
    const auto properties = reinterpret_cast<PFN_vkGetPipelineExecutablePropertiesKHR>(
        vkGetDeviceProcAddr(device_, "vkGetPipelineExecutablePropertiesKHR"));
    const auto statistics = reinterpret_cast<PFN_vkGetPipelineExecutableStatisticsKHR>(
        vkGetDeviceProcAddr(device_, "vkGetPipelineExecutableStatisticsKHR"));
    if (!properties || !statistics) return;
    auto info = vk_struct<VkPipelineInfoKHR>(VK_STRUCTURE_TYPE_PIPELINE_INFO_KHR);
    info.pipeline = pipeline;
    uint32_t executables = 0;
    if (properties(device_, &info, &executables, nullptr) != VK_SUCCESS) return;
    for (uint32_t e = 0; e < executables; ++e) {
        auto exe =
            vk_struct<VkPipelineExecutableInfoKHR>(VK_STRUCTURE_TYPE_PIPELINE_EXECUTABLE_INFO_KHR);
        exe.pipeline = pipeline;
        exe.executableIndex = e;
        uint32_t n = 0;
        if (statistics(device_, &exe, &n, nullptr) != VK_SUCCESS) continue;
        std::vector<VkPipelineExecutableStatisticKHR> stats(
            n, vk_struct<VkPipelineExecutableStatisticKHR>(
                   VK_STRUCTURE_TYPE_PIPELINE_EXECUTABLE_STATISTIC_KHR));
        if (statistics(device_, &exe, &n, stats.data()) != VK_SUCCESS) continue;
        std::string line = std::string("vulkan kernel ") + name + ":";
        for (const VkPipelineExecutableStatisticKHR& st : stats) {
            line += std::string(" ") + st.name + "=";
            switch (st.format) {
                case VK_PIPELINE_EXECUTABLE_STATISTIC_FORMAT_BOOL32_KHR:
                    line += st.value.b32 ? "true" : "false";
                    break;
                case VK_PIPELINE_EXECUTABLE_STATISTIC_FORMAT_INT64_KHR:
                    line += std::to_string(st.value.i64);
                    break;
                case VK_PIPELINE_EXECUTABLE_STATISTIC_FORMAT_UINT64_KHR:
                    line += std::to_string(st.value.u64);
                    break;
                default:
                    line += std::to_string(st.value.f64);
            }
            line += ",";
        }
        line.back() = '\n';
        std::fputs(line.c_str(), stderr);
    }
}

void Context::check(VkResult r, const char* what) const {
    if (r == VK_SUCCESS) return;
    if (r == VK_ERROR_OUT_OF_DEVICE_MEMORY || r == VK_ERROR_OUT_OF_HOST_MEMORY)
        throw GpuError(std::string("Vulkan: out of memory (") + what + ")");
    throw GpuError(std::string("Vulkan: ") + what + " failed (VkResult " + std::to_string(r) + ")");
}

Context::Context() {
    auto app = vk_struct<VkApplicationInfo>(VK_STRUCTURE_TYPE_APPLICATION_INFO);
    app.pApplicationName = "sdfprune";
    app.apiVersion = VK_API_VERSION_1_1;
    auto ici = vk_struct<VkInstanceCreateInfo>(VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO);
    ici.pApplicationInfo = &app;
    // Drivers that implement Vulkan only in part (MoltenVK on Apple GPUs) are listed only to
    // applications that ask for them.
    const char* portability_enumeration = "VK_KHR_portability_enumeration";
    if (has_extension(nullptr, portability_enumeration)) {
        ici.enabledExtensionCount = 1;
        ici.ppEnabledExtensionNames = &portability_enumeration;
        ici.flags |= VK_INSTANCE_CREATE_ENUMERATE_PORTABILITY_BIT_KHR;
    }
    if (vkCreateInstance(&ici, nullptr, &instance_) != VK_SUCCESS)
        throw GpuError(
            "no Vulkan device: the Vulkan loader found no driver (install "
            "mesa-vulkan-drivers or a GPU driver)");
    uint32_t count = 0;
    vkEnumeratePhysicalDevices(instance_, &count, nullptr);
    std::vector<VkPhysicalDevice> devices(count);
    vkEnumeratePhysicalDevices(instance_, &count, devices.data());
    // Candidates with a compute queue; discrete and integrated GPUs before CPU drivers.
    struct Candidate {
        VkPhysicalDevice device;
        uint32_t family;
        int rank;
        uint32_t timestamp_bits;  // of the family's queues
        VkPhysicalDeviceProperties props;
    };
    std::vector<Candidate> candidates;
    for (VkPhysicalDevice d : devices) {
        uint32_t nq = 0;
        vkGetPhysicalDeviceQueueFamilyProperties(d, &nq, nullptr);
        std::vector<VkQueueFamilyProperties> q(nq);
        vkGetPhysicalDeviceQueueFamilyProperties(d, &nq, q.data());
        VkPhysicalDeviceProperties p;
        vkGetPhysicalDeviceProperties(d, &p);
        const int rank = p.deviceType == VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU     ? 0
                         : p.deviceType == VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU ? 1
                         : p.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU            ? 3
                                                                                  : 2;
        for (uint32_t i = 0; i < nq; ++i)
            if (q[i].queueFlags & VK_QUEUE_COMPUTE_BIT) {
                candidates.push_back({d, i, rank, q[i].timestampValidBits, p});
                break;
            }
    }
    std::stable_sort(candidates.begin(), candidates.end(),
                     [](const Candidate& a, const Candidate& b) { return a.rank < b.rank; });
    if (candidates.empty()) {
        vkDestroyInstance(instance_, nullptr);
        instance_ = VK_NULL_HANDLE;
        throw GpuError("no Vulkan device with a compute queue");
    }
    size_t pick = 0;
    if (const char* env = std::getenv("SDFPRUNE_VULKAN_DEVICE")) {
        pick = size_t(std::strtoul(env, nullptr, 10));
        if (pick >= candidates.size()) {
            vkDestroyInstance(instance_, nullptr);
            instance_ = VK_NULL_HANDLE;
            throw GpuError("SDFPRUNE_VULKAN_DEVICE=" + std::string(env) + ": only " +
                           std::to_string(candidates.size()) + " Vulkan device(s)");
        }
    }
    physical_ = candidates[pick].device;
    queue_family_ = candidates[pick].family;
    const VkPhysicalDeviceProperties& props = candidates[pick].props;
    device_name_ = props.deviceName;
    max_range_ = props.limits.maxStorageBufferRange;
    host_log_ = std::getenv("SDFPRUNE_VULKAN_HOST_LOG") != nullptr;
    use_slabs_ = env_flag("SDFPRUNE_VULKAN_SLABS", use_slabs_);
    use_blocks_ = env_flag("SDFPRUNE_VULKAN_BLOCKS", use_blocks_);
    if (const char* env = std::getenv("SDFPRUNE_VULKAN_MAX_BUFFER"))  // a smaller device, for tests
        max_range_ = std::min<uint64_t>(max_range_, std::strtoull(env, nullptr, 10));
    // A device with less memory, for tests: new device-local buffers past this many bytes in
    // use fail as if the device had run out.
    if (const char* env = std::getenv("SDFPRUNE_VULKAN_MEMORY_LIMIT"); env && *env)
        memory_limit_ = std::strtoull(env, nullptr, 10);
    max_range_ &= ~uint64_t(15);  // buffer sizes round up to 16
    max_groups_ = props.limits.maxComputeWorkGroupCount[0];
    device_ends_loops_ = props.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU &&
                         device_name_.find("llvmpipe") != std::string::npos;
    loop_limited_ = device_ends_loops_;
    // For tests: SDFPRUNE_VULKAN_LOOP_LIMITED=0 plans lavapipe as a GPU (a step in one
    // dispatch, jobs taken uncapped), right only where no invocation reaches the limit; 1 plans
    // a GPU as lavapipe.
    loop_limited_ = env_flag("SDFPRUNE_VULKAN_LOOP_LIMITED", loop_limited_);
    timestamp_ns_ = double(props.limits.timestampPeriod);
    {
        auto sg = vk_struct<VkPhysicalDeviceSubgroupProperties>(
            VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_SUBGROUP_PROPERTIES);
        auto p2 =
            vk_struct<VkPhysicalDeviceProperties2>(VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2);
        p2.pNext = &sg;
        vkGetPhysicalDeviceProperties2(physical_, &p2);
        const VkSubgroupFeatureFlags need = VK_SUBGROUP_FEATURE_BASIC_BIT |
                                            VK_SUBGROUP_FEATURE_ARITHMETIC_BIT |
                                            VK_SUBGROUP_FEATURE_BALLOT_BIT;
        subgroups_ = props.apiVersion >= VK_API_VERSION_1_1 &&
                     (sg.supportedStages & VK_SHADER_STAGE_COMPUTE_BIT) != 0 &&
                     (sg.supportedOperations & need) == need && sg.subgroupSize >= 1;
        subgroups_ = subgroups_ && env_flag("SDFPRUNE_VULKAN_SUBGROUPS", true);
        subgroup_size_ = sg.subgroupSize;
    }
    // 8-bit storage (enabled at device creation below, where offered).
    auto storage8 = vk_struct<VkPhysicalDevice8BitStorageFeaturesKHR>(
        VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_8BIT_STORAGE_FEATURES_KHR);
    if (has_extension(physical_, VK_KHR_8BIT_STORAGE_EXTENSION_NAME)) {
        auto f2 =
            vk_struct<VkPhysicalDeviceFeatures2>(VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2);
        f2.pNext = &storage8;
        vkGetPhysicalDeviceFeatures2(physical_, &f2);
        byte_storage_ = storage8.storageBuffer8BitAccess == VK_TRUE &&
                        env_flag("SDFPRUNE_VULKAN_8BIT_STORAGE", true);
    }
    {
        // Invocations resident at once (resident_threads): the vendors' core counts where the
        // device reports them (querying an extension's properties needs no enabling).
        auto nv = vk_struct<VkPhysicalDeviceShaderSMBuiltinsPropertiesNV>(
            VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_SHADER_SM_BUILTINS_PROPERTIES_NV);
        auto amd = vk_struct<VkPhysicalDeviceShaderCorePropertiesAMD>(
            VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_SHADER_CORE_PROPERTIES_AMD);
        auto p2 =
            vk_struct<VkPhysicalDeviceProperties2>(VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2);
        const bool has_nv = has_extension(physical_, VK_NV_SHADER_SM_BUILTINS_EXTENSION_NAME);
        const bool has_amd = has_extension(physical_, VK_AMD_SHADER_CORE_PROPERTIES_EXTENSION_NAME);
        p2.pNext = has_nv ? static_cast<void*>(&nv) : has_amd ? static_cast<void*>(&amd) : nullptr;
        vkGetPhysicalDeviceProperties2(physical_, &p2);
        const uint64_t nv_threads = uint64_t(nv.shaderSMCount) * nv.shaderWarpsPerSM * 32;
        const uint64_t amd_threads = uint64_t(amd.shaderEngineCount) *
                                     amd.shaderArraysPerEngineCount *
                                     amd.computeUnitsPerShaderArray * amd.simdPerComputeUnit *
                                     amd.wavefrontsPerSimd * amd.wavefrontSize;
        if (has_nv && nv_threads > 0)
            resident_threads_ = nv_threads;
        else if (has_amd && amd_threads > 0)
            resident_threads_ = amd_threads;
        else if (props.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU)
            resident_threads_ = uint64_t(std::max(1u, std::thread::hardware_concurrency())) *
                                kCpuGroupsPerCore * kWorkgroupSize;
        if (const char* env = std::getenv("SDFPRUNE_VULKAN_RESIDENT_THREADS"); env && *env)
            resident_threads_ = std::strtoull(env, nullptr, 10);
        resident_threads_ = std::max<uint64_t>(resident_threads_, kWorkgroupSize);
    }
    vkGetPhysicalDeviceMemoryProperties(physical_, &memory_);
    // The idle cache's budget (create_buffer): a quarter of the largest device-local heap (or
    // of any heap, on devices without one), at most 4 GiB. A call's buffers add up to more
    // than its peak (a pool replaced level by level leaves each smaller one behind): the
    // generated fluid's (27,977 nodes) passed 1 GiB and were trimmed before the next call.
    {
        uint64_t heap = 0, any_heap = 0;
        for (uint32_t i = 0; i < memory_.memoryHeapCount; ++i) {
            any_heap = std::max<uint64_t>(any_heap, memory_.memoryHeaps[i].size);
            if (memory_.memoryHeaps[i].flags & VK_MEMORY_HEAP_DEVICE_LOCAL_BIT)
                heap = std::max<uint64_t>(heap, memory_.memoryHeaps[i].size);
        }
        device_heap_ = heap ? heap : any_heap;
        cache_budget_ = std::min<uint64_t>(uint64_t(4) << 30, device_heap_ / 4);
        if (const char* env = std::getenv("SDFPRUNE_VULKAN_CACHE_BYTES"); env && *env)
            cache_budget_ = std::strtoull(env, nullptr, 10);
    }

    const float priority = 1.0f;
    auto qci = vk_struct<VkDeviceQueueCreateInfo>(VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO);
    qci.queueFamilyIndex = queue_family_;
    qci.queueCount = 1;
    qci.pQueuePriorities = &priority;
    auto dci = vk_struct<VkDeviceCreateInfo>(VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO);
    dci.queueCreateInfoCount = 1;
    dci.pQueueCreateInfos = &qci;
    // Such a driver must be told that the application knows (the Vulkan spec).
    const char* extensions[3];
    const char* portability_subset = "VK_KHR_portability_subset";
    if (has_extension(physical_, portability_subset))
        extensions[dci.enabledExtensionCount++] = portability_subset;
    // SDFPRUNE_VULKAN_KERNEL_STATS=1: the driver's statistics of each compiled kernel (an
    // NVIDIA driver's registers, shared memory and the like) on stderr, where the driver has
    // VK_KHR_pipeline_executable_properties: what bounds a kernel's occupancy.
    auto executable_info = vk_struct<VkPhysicalDevicePipelineExecutablePropertiesFeaturesKHR>(
        VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PIPELINE_EXECUTABLE_PROPERTIES_FEATURES_KHR);
    const char* kernel_stats_env = std::getenv("SDFPRUNE_VULKAN_KERNEL_STATS");
    const bool want_kernel_stats = kernel_stats_env && std::atoi(kernel_stats_env) != 0;
    const bool kernel_stats =
        want_kernel_stats &&
        has_extension(physical_, VK_KHR_PIPELINE_EXECUTABLE_PROPERTIES_EXTENSION_NAME);
    if (kernel_stats) {
        extensions[dci.enabledExtensionCount++] =
            VK_KHR_PIPELINE_EXECUTABLE_PROPERTIES_EXTENSION_NAME;
        executable_info.pipelineExecutableInfo = VK_TRUE;
        dci.pNext = &executable_info;
    } else if (want_kernel_stats) {
        std::fprintf(stderr, "vulkan: %s has no VK_KHR_pipeline_executable_properties\n",
                     device_name_.c_str());
    }
    if (byte_storage_) {
        extensions[dci.enabledExtensionCount++] = VK_KHR_8BIT_STORAGE_EXTENSION_NAME;
        storage8 = vk_struct<VkPhysicalDevice8BitStorageFeaturesKHR>(
            VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_8BIT_STORAGE_FEATURES_KHR);
        storage8.storageBuffer8BitAccess = VK_TRUE;
        storage8.pNext = const_cast<void*>(dci.pNext);
        dci.pNext = &storage8;
    }
    dci.ppEnabledExtensionNames = extensions;
    check(vkCreateDevice(physical_, &dci, nullptr, &device_), "vkCreateDevice");
    vkGetDeviceQueue(device_, queue_family_, 0, &queue_);

    auto cpi = vk_struct<VkCommandPoolCreateInfo>(VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO);
    cpi.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
    cpi.queueFamilyIndex = queue_family_;
    check(vkCreateCommandPool(device_, &cpi, nullptr, &command_pool_), "vkCreateCommandPool");
    auto cai =
        vk_struct<VkCommandBufferAllocateInfo>(VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO);
    cai.commandPool = command_pool_;
    cai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
    cai.commandBufferCount = 1;
    check(vkAllocateCommandBuffers(device_, &cai, &cmd_), "vkAllocateCommandBuffers");
    auto fci = vk_struct<VkFenceCreateInfo>(VK_STRUCTURE_TYPE_FENCE_CREATE_INFO);
    check(vkCreateFence(device_, &fci, nullptr, &fence_), "vkCreateFence");

    VkDescriptorPoolSize ps{VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, kMaxSets * kMaxBindings};
    auto dpi = vk_struct<VkDescriptorPoolCreateInfo>(VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO);
    dpi.maxSets = kMaxSets;
    dpi.poolSizeCount = 1;
    dpi.pPoolSizes = &ps;
    check(vkCreateDescriptorPool(device_, &dpi, nullptr, &descriptor_pool_),
          "vkCreateDescriptorPool");

    const uint32_t valid_bits = candidates[pick].timestamp_bits;
    timestamp_mask_ = valid_bits >= 64 ? ~uint64_t(0) : (uint64_t(1) << valid_bits) - 1;
    if (valid_bits > 0) {
        auto qpi = vk_struct<VkQueryPoolCreateInfo>(VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO);
        qpi.queryType = VK_QUERY_TYPE_TIMESTAMP;
        qpi.queryCount = 2 + kMaxStamps;  // a part's start and end, then its stamps
        check(vkCreateQueryPool(device_, &qpi, nullptr, &timestamps_), "vkCreateQueryPool");
    }

    // The reserve's allocation runs beside the kernels' building (the driver's compiles).
    start_reserve(props.deviceType);

    // The kernels, built side by side, the largest first: the driver's compiles take most of a
    // device's making (lavapipe's eleven: about 300 ms one after another on this project's
    // 2-core host; BENCHMARKS.md, stop 46). Vulkan lets threads create objects of one device
    // at once.
    kernels_.assign(std::size(kKernels), Kernel{});
    std::array<size_t, std::size(kKernels)> largest_first;
    std::iota(largest_first.begin(), largest_first.end(), size_t(0));
    std::stable_sort(largest_first.begin(), largest_first.end(),
                     [](size_t a, size_t b) { return kKernels[a].bytes > kKernels[b].bytes; });
    const auto build = [&](size_t index) {
        const KernelCode& code = kKernels[index];
        Kernel& k = kernels_[index];
        k.bindings = code.bindings;
        // (Vulkan guarantees workgroups of 128 invocations only.)
        if ((code.subgroups && !subgroups_) || (code.byte_storage && !byte_storage_) ||
            code.local_size > props.limits.maxComputeWorkGroupInvocations ||
            code.local_size > props.limits.maxComputeWorkGroupSize[0]) {
            return;  // no pipeline: never dispatched (can_run)
        }
        VkDescriptorSetLayoutBinding b[kMaxBindings];
        for (uint32_t i = 0; i < code.bindings; ++i)
            b[i] = {i, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, VK_SHADER_STAGE_COMPUTE_BIT, nullptr};
        auto sli = vk_struct<VkDescriptorSetLayoutCreateInfo>(
            VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO);
        sli.bindingCount = code.bindings;
        sli.pBindings = b;
        check(vkCreateDescriptorSetLayout(device_, &sli, nullptr, &k.set_layout),
              "vkCreateDescriptorSetLayout");
        VkPushConstantRange range{VK_SHADER_STAGE_COMPUTE_BIT, 0, kPushBytes};
        auto pli =
            vk_struct<VkPipelineLayoutCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO);
        pli.setLayoutCount = 1;
        pli.pSetLayouts = &k.set_layout;
        pli.pushConstantRangeCount = 1;
        pli.pPushConstantRanges = &range;
        check(vkCreatePipelineLayout(device_, &pli, nullptr, &k.layout), "vkCreatePipelineLayout");
        auto smi = vk_struct<VkShaderModuleCreateInfo>(VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO);
        smi.codeSize = code.bytes;
        smi.pCode = code.words;
        VkShaderModule module;
        check(vkCreateShaderModule(device_, &smi, nullptr, &module), "vkCreateShaderModule");
        auto cpci =
            vk_struct<VkComputePipelineCreateInfo>(VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO);
        cpci.stage = vk_struct<VkPipelineShaderStageCreateInfo>(
            VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO);
        cpci.stage.stage = VK_SHADER_STAGE_COMPUTE_BIT;
        cpci.stage.module = module;
        cpci.stage.pName = "main";
        cpci.layout = k.layout;
        if (kernel_stats) cpci.flags = VK_PIPELINE_CREATE_CAPTURE_STATISTICS_BIT_KHR;
        const VkResult r =
            vkCreateComputePipelines(device_, VK_NULL_HANDLE, 1, &cpci, nullptr, &k.pipeline);
        vkDestroyShaderModule(device_, module, nullptr);
        check(r, "vkCreateComputePipelines");
    };
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, largest_first.size(), 1),
        [&](const tbb::blocked_range<size_t>& r) {
            for (size_t i = r.begin(); i != r.end(); ++i) build(largest_first[i]);
        },
        tbb::simple_partitioner());
    if (kernel_stats)
        for (size_t i = 0; i < kernels_.size(); ++i)
            if (kernels_[i].pipeline)
                report_kernel_statistics(kKernels[i].name, kernels_[i].pipeline);
}

Context::~Context() {
    if (device_) {
        vkDeviceWaitIdle(device_);
        reserve_thread_.request_stop();  // (a delayed reserve is not made at all)
        adopt_reserve(true);
        trim(0);
        // (with buffers still bound, if a grid outlived its device)
        for (Slab& slab : slabs_)
            if (slab.memory) vkFreeMemory(device_, slab.memory, nullptr);
        for (Block& block : blocks_)
            if (block.memory) vkFreeMemory(device_, block.memory, nullptr);
        for (Kernel& k : kernels_) {
            vkDestroyPipeline(device_, k.pipeline, nullptr);
            vkDestroyPipelineLayout(device_, k.layout, nullptr);
            vkDestroyDescriptorSetLayout(device_, k.set_layout, nullptr);
        }
        if (timestamps_) vkDestroyQueryPool(device_, timestamps_, nullptr);
        vkDestroyDescriptorPool(device_, descriptor_pool_, nullptr);
        vkDestroyFence(device_, fence_, nullptr);
        vkDestroyCommandPool(device_, command_pool_, nullptr);
        vkDestroyDevice(device_, nullptr);
    }
    if (instance_) vkDestroyInstance(instance_, nullptr);
}

namespace {
// Adds one call and its host time to a tally (Context::HostTime) when it ends, however it ends.
struct HostTally {
    uint64_t& calls;
    double& ms;
    std::chrono::steady_clock::time_point start = std::chrono::steady_clock::now();
    ~HostTally() {
        ++calls;
        ms += ms_since(start);
    }
};

}  // namespace

// SDFPRUNE_VULKAN_HOST_LOG: a line on stderr per buffer allocated (not those taken from the idle
// cache) and per submission, with the host's time in it and the time since the context was
// made, so that the gaps between them show the host's other work.
void Context::log_host(const char* what, uint64_t bytes,
                       std::chrono::steady_clock::time_point start, double gpu_ms) const {
    const auto now = std::chrono::steady_clock::now();
    const auto ms = [&](auto since) {
        return std::chrono::duration<double, std::milli>(now - since).count();
    };
    std::fprintf(stderr,
                 "vulkan host %10.3f ms: %s %llu bytes, host %.3f ms, gpu %.3f ms live %.1f MB\n",
                 ms(made_), what, static_cast<unsigned long long>(bytes), ms(start), gpu_ms,
                 bytes_live() / 1e6);
}

uint32_t Context::groups_for(uint64_t n) const {
    return uint32_t(
        std::clamp<uint64_t>((n + kWorkgroupSize - 1) / kWorkgroupSize, 1, max_groups_));
}

namespace {
// SDFPRUNE_VULKAN_SCRATCH_BYTES, or `fallback`.
uint64_t scratch_override(uint64_t fallback) {
    const char* env = std::getenv("SDFPRUNE_VULKAN_SCRATCH_BYTES");
    return env && *env ? std::strtoull(env, nullptr, 10) : fallback;
}
}  // namespace

uint64_t Context::scratch_budget_bytes() const {
    return std::min(scratch_override(kScratchBudgetBytes), max_range_);
}

uint64_t Context::prune_scratch_budget_bytes() const {
    return std::min(scratch_override(std::max(kScratchBudgetBytes, device_heap_ / 16)), max_range_);
}

uint32_t Context::prune_scratch_buffers() const {
    if (const char* env = std::getenv("SDFPRUNE_VULKAN_SCRATCH_BUFFERS"); env && *env)
        return uint32_t(std::clamp<unsigned long>(std::strtoul(env, nullptr, 10), 1, 8));
    return uint32_t(std::clamp<uint64_t>(
        std::max(kScratchBudgetBytes, device_heap_ / 4) / prune_scratch_budget_bytes(), 1, 8));
}

uint32_t Context::threads_for(uint64_t work, uint64_t bytes_per_thread) const {
    const uint64_t budget = scratch_budget_bytes();
    const uint64_t fit = budget / std::max<uint64_t>(bytes_per_thread, 1) / kWorkgroupSize;
    if (fit == 0)
        throw GpuError("Vulkan: the scene needs " + std::to_string(bytes_per_thread) +
                       " bytes of stack per thread, more than the device's buffers allow");
    const uint64_t want = (std::max<uint64_t>(work, 1) + kWorkgroupSize - 1) / kWorkgroupSize;
    return uint32_t(std::min({want, fit, uint64_t(max_groups_)}) * kWorkgroupSize);
}

void Context::begin() {
    if (recording_) throw std::logic_error("Context::begin while recording");
    carried_ms_ = 0;
    stamps_ms_.clear();
    begin_part();
}

void Context::begin_part() {
    VkCommandBufferBeginInfo bi =
        vk_struct<VkCommandBufferBeginInfo>(VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO);
    bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    check(vkBeginCommandBuffer(cmd_, &bi), "vkBeginCommandBuffer");
    recording_ = true;
    part_stamps_.clear();
    if (timestamps_) {
        vkCmdResetQueryPool(cmd_, timestamps_, 0, 2 + kMaxStamps);
        vkCmdWriteTimestamp(cmd_, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, timestamps_, 0);
    }
}

uint32_t Context::stamp() {
    if (!recording_) throw std::logic_error("Context::stamp without begin");
    const uint32_t id = uint32_t(stamps_ms_.size());
    stamps_ms_.push_back(0);
    if (timestamps_ && part_stamps_.size() < kMaxStamps) {
        vkCmdWriteTimestamp(cmd_, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, timestamps_,
                            2 + uint32_t(part_stamps_.size()));
        part_stamps_.push_back(id);
    }
    return id;
}

void Context::barrier() {
    auto mb = vk_struct<VkMemoryBarrier>(VK_STRUCTURE_TYPE_MEMORY_BARRIER);
    mb.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT;
    mb.dstAccessMask = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT |
                       VK_ACCESS_TRANSFER_READ_BIT | VK_ACCESS_TRANSFER_WRITE_BIT;
    const VkPipelineStageFlags stages =
        VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT;
    vkCmdPipelineBarrier(cmd_, stages, stages, 0, 1, &mb, 0, nullptr, 0, nullptr);
}

void Context::dispatch(KernelId id, std::initializer_list<const Buffer*> buffers, const void* push,
                       uint32_t push_bytes, uint32_t groups, bool then_barrier) {
    const Kernel& k = kernels_[size_t(id)];
    if (buffers.size() != k.bindings || push_bytes > kPushBytes)
        throw std::logic_error("Context::dispatch: bindings do not match the kernel");
    if (k.pipeline == VK_NULL_HANDLE)
        throw std::logic_error("Context::dispatch: a kernel this device cannot run");
    if (sets_used_ == kMaxSets) {
        carried_ms_ += submit_part();
        begin_part();
    }
    auto ai =
        vk_struct<VkDescriptorSetAllocateInfo>(VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO);
    ai.descriptorPool = descriptor_pool_;
    ai.descriptorSetCount = 1;
    ai.pSetLayouts = &k.set_layout;
    VkDescriptorSet set;
    check(vkAllocateDescriptorSets(device_, &ai, &set), "vkAllocateDescriptorSets");
    ++sets_used_;
    VkDescriptorBufferInfo info[kMaxBindings];
    VkWriteDescriptorSet writes[kMaxBindings];
    uint32_t i = 0;
    for (const Buffer* b : buffers) {
        if (b->size > max_range_) {
            abandon();
            throw GpuError("Vulkan: a buffer of " + std::to_string(b->size) +
                           " bytes is more than " + device_name_ + " lets a shader address (" +
                           std::to_string(max_range_) + " bytes); use --backend cpu");
        }
        info[i] = {b->buffer, 0, b->size};
        writes[i] = vk_struct<VkWriteDescriptorSet>(VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET);
        writes[i].dstSet = set;
        writes[i].dstBinding = i;
        writes[i].descriptorCount = 1;
        writes[i].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
        writes[i].pBufferInfo = &info[i];
        ++i;
    }
    vkUpdateDescriptorSets(device_, i, writes, 0, nullptr);
    vkCmdBindPipeline(cmd_, VK_PIPELINE_BIND_POINT_COMPUTE, k.pipeline);
    vkCmdBindDescriptorSets(cmd_, VK_PIPELINE_BIND_POINT_COMPUTE, k.layout, 0, 1, &set, 0, nullptr);
    uint8_t padded[kPushBytes] = {};
    std::memcpy(padded, push, push_bytes);
    vkCmdPushConstants(cmd_, k.layout, VK_SHADER_STAGE_COMPUTE_BIT, 0, kPushBytes, padded);
    if (groups > max_groups_) throw std::logic_error("Context::dispatch: too many workgroups");
    vkCmdDispatch(cmd_, std::max(groups, 1u), 1, 1);
    if (then_barrier) barrier();
}

void Context::copy(const Buffer& src, const Buffer& dst, uint64_t bytes, uint64_t src_offset,
                   uint64_t dst_offset) {
    if (bytes == 0) return;
    VkBufferCopy region{src_offset, dst_offset, bytes};
    vkCmdCopyBuffer(cmd_, src.buffer, dst.buffer, 1, &region);
    barrier();
}

void Context::update(const Buffer& dst, const void* data, uint64_t bytes, uint64_t offset) {
    if (bytes == 0) return;
    if (bytes % 4 != 0 || bytes > 65536)
        throw std::logic_error("Context::update: a size that is no multiple of 4, or over 64 KiB");
    vkCmdUpdateBuffer(cmd_, dst.buffer, offset, bytes, data);
    barrier();
}

void Context::fill(const Buffer& dst, uint32_t value) {
    vkCmdFillBuffer(cmd_, dst.buffer, 0, dst.size, value);
    barrier();
}

void Context::fill(const Buffer& dst, uint32_t value, uint64_t offset, uint64_t bytes) {
    vkCmdFillBuffer(cmd_, dst.buffer, offset, bytes, value);
    barrier();
}

void Context::abandon() {
    vkEndCommandBuffer(cmd_);
    vkResetCommandBuffer(cmd_, 0);
    vkResetDescriptorPool(device_, descriptor_pool_, 0);
    sets_used_ = 0;
    recording_ = false;
}

double Context::submit() {
    if (!recording_) throw std::logic_error("Context::submit without begin");
    return carried_ms_ + submit_part();
}

double Context::submit_part() {
    const HostTally tally{host_.submissions, host_.submit_ms};
    if (timestamps_)
        vkCmdWriteTimestamp(cmd_, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, timestamps_, 1);
    check(vkEndCommandBuffer(cmd_), "vkEndCommandBuffer");
    recording_ = false;
    auto si = vk_struct<VkSubmitInfo>(VK_STRUCTURE_TYPE_SUBMIT_INFO);
    si.commandBufferCount = 1;
    si.pCommandBuffers = &cmd_;
    check(vkQueueSubmit(queue_, 1, &si, fence_), "vkQueueSubmit");
    check(vkWaitForFences(device_, 1, &fence_, VK_TRUE, UINT64_MAX), "vkWaitForFences");
    vkResetFences(device_, 1, &fence_);
    vkResetCommandBuffer(cmd_, 0);
    vkResetDescriptorPool(device_, descriptor_pool_, 0);
    sets_used_ = 0;
    if (!timestamps_) return 0;
    // The part's start and end, then its stamps (ms since the part's start, plus the parts
    // before it: carried_ms_).
    const uint32_t queries = 2 + uint32_t(part_stamps_.size());
    uint64_t ticks[2 + kMaxStamps] = {};
    if (vkGetQueryPoolResults(device_, timestamps_, 0, queries, queries * sizeof(uint64_t), ticks,
                              sizeof(uint64_t),
                              VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT) != VK_SUCCESS)
        return 0;
    const auto ms = [&](uint64_t t) {
        return double((t - ticks[0]) & timestamp_mask_) * timestamp_ns_ * 1e-6;
    };
    for (size_t j = 0; j < part_stamps_.size(); ++j)
        stamps_ms_[part_stamps_[j]] = carried_ms_ + ms(ticks[2 + j]);
    if (host_log_) log_host("submission", 0, tally.start, ms(ticks[1]));
    return ms(ticks[1]);
}

void Context::upload(const Buffer& dst, const void* data, uint64_t bytes, uint64_t dst_offset) {
    upload({{&dst, data, bytes, dst_offset}});
}

void Context::upload(std::initializer_list<Upload> uploads) {
    // Each piece at a multiple of 16 bytes in the staging buffer.
    const auto padded = [](uint64_t bytes) { return (bytes + 15) & ~uint64_t(15); };
    uint64_t total = 0;
    for (const Upload& u : uploads) total += padded(u.bytes);
    if (total == 0) return;
    Buffer staging = create_buffer(total, true);
    begin();
    uint64_t at = 0;
    for (const Upload& u : uploads) {
        if (u.bytes == 0) continue;
        std::memcpy(static_cast<uint8_t*>(staging.mapped) + at, u.data, u.bytes);
        copy(staging, *u.dst, u.bytes, at, u.dst_offset);
        at += padded(u.bytes);
    }
    submit();
    destroy(staging);
}

void Context::download(const Buffer& src, void* data, uint64_t bytes, uint64_t src_offset) {
    if (bytes == 0) return;
    Buffer staging = create_buffer(bytes, true);
    begin();
    copy(src, staging, bytes, src_offset, 0);
    submit();
    std::memcpy(data, staging.mapped, bytes);
    destroy(staging);
}

bool env_flag(const char* name, bool fallback) {
    const char* env = std::getenv(name);
    return env && *env ? std::atoi(env) != 0 : fallback;
}

}  // namespace sdfprune::gpu
