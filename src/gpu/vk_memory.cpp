// vk_memory.cpp — the device memory behind Context's buffers: memory types, the idle cache
// that recycles buffers by capacity class, the slabs small buffers share, and the blocks whose
// free room large buffers take, and the reserve made beside the context (vk_context.hpp says
// why each exists).
#include <algorithm>
#include <bit>
#include <chrono>
#include <condition_variable>
#include <cstdlib>
#include <iterator>
#include <mutex>
#include <stop_token>
#include <string>
#include <thread>
#include <utility>

#include "../core/clock.hpp"
#include "vk_context.hpp"

namespace sdfprune::gpu {

uint32_t Context::memory_type(uint32_t bits, bool host_visible) const {
    const VkMemoryPropertyFlags want =
        host_visible ? VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT
                     : VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT;
    for (uint32_t i = 0; i < memory_.memoryTypeCount; ++i)
        if ((bits & (1u << i)) && (memory_.memoryTypes[i].propertyFlags & want) == want) return i;
    // Devices without a device-local type (some CPU drivers) use any allowed type.
    for (uint32_t i = 0; i < memory_.memoryTypeCount; ++i)
        if ((bits & (1u << i)) && !host_visible) return i;
    throw GpuError("Vulkan: no suitable memory type");
}

namespace {
// The place in `v` of an entry without memory (a freed slab's or block's), made if none.
template <class T>
size_t free_place(std::vector<T>& v) {
    size_t i = 0;
    while (i < v.size() && v[i].memory) ++i;
    if (i == v.size()) v.emplace_back();
    return i;
}

// The capacity class of a buffer of `bytes` (a multiple of 16): up to 64 bytes the size
// itself; above, the next multiple of a quarter of the power of two below it (2^k times 1.25,
// 1.5, 1.75 or 2), so at most 25 % more than asked.
uint64_t capacity_class(uint64_t bytes) {
    if (bytes <= 64) return bytes;
    const uint64_t quarter = uint64_t(1) << (std::bit_width(bytes - 1) - 3);
    return (bytes + quarter - 1) / quarter * quarter;
}
}  // namespace

Buffer Context::create_buffer(uint64_t bytes, bool host_visible, bool exact) {
    const auto start = std::chrono::steady_clock::now();
    const auto add_time = [&] { host_.buffer_ms += ms_since(start); };
    const uint64_t size = (std::max<uint64_t>(bytes, 16) + 15) & ~uint64_t(15);
    // (A buffer as large as the device's largest range is not rounded past it.)
    const uint64_t capacity =
        exact ? size : std::max(size, std::min(capacity_class(size), max_range_));
    const auto hand_out = [&](Buffer b) {
        b.size = size;
        if (!host_visible) {
            live_ += b.capacity;
            peak_ = std::max(peak_, live_);
        }
        add_time();
        return b;
    };
    // The most recently cached buffer of this class and kind (still warm in the driver's and
    // the device's caches).
    for (size_t i = idle_.size(); i-- > 0;)
        if (idle_[i].capacity == capacity && (idle_[i].mapped != nullptr) == host_visible) {
            const Buffer b = idle_[i];
            idle_.erase(idle_.begin() + ptrdiff_t(i));
            cached_ -= b.capacity;
            ++host_.buffers_reused;
            if (host_log_)
                log_host(host_visible ? "host-visible buffer from the idle cache"
                                      : "device buffer from the idle cache",
                         b.capacity, start, 0);
            return hand_out(b);
        }

    Buffer b;
    b.capacity = capacity;
    check(create_buffer_handle(capacity, &b.buffer), "vkCreateBuffer");
    VkMemoryRequirements req;
    vkGetBufferMemoryRequirements(device_, b.buffer, &req);
    const uint32_t type = memory_type(req.memoryTypeBits, host_visible);
    if (use_slabs_ && req.size <= kSlabBufferMax[host_visible] &&
        bind_to_slab(b, req, type, host_visible)) {
        ++host_.buffers;
        return hand_out(b);
    }
    const bool in_block =
        !host_visible && use_blocks_ && cache_budget_ > 0 && req.size > kSlabBufferMax[0];
    if (in_block) adopt_reserve(false);
    // (A block's room, the reserve's too, is no way past SDFPRUNE_VULKAN_MEMORY_LIMIT.)
    if (in_block && live_ + capacity <= memory_limit_ && bind_to_block(b, req, type)) {
        ++host_.buffers_reused;
        if (host_log_) log_host("device buffer in a block's free room", capacity, start, 0);
        return hand_out(b);
    }
    ++host_.allocations;
    host_.allocated_bytes += req.size;
    const auto allocate = [&] {
        return !host_visible && live_ + capacity > memory_limit_
                   ? VK_ERROR_OUT_OF_DEVICE_MEMORY
                   : allocate_memory(req.size, type, &b.memory);
    };
    VkResult r = allocate();
    if (r != VK_SUCCESS && cached_ > 0) {  // the idle buffers may be what is in the way
        trim(0);
        r = allocate();
    }
    if (r != VK_SUCCESS) {
        vkDestroyBuffer(device_, b.buffer, nullptr);
        add_time();
        throw GpuError("Vulkan device out of memory: a buffer of " + std::to_string(bytes) +
                       " bytes did not fit (" + std::to_string(live_) + " bytes in use)");
    }
    vkBindBufferMemory(device_, b.buffer, b.memory, 0);
    if (in_block) {  // the buffer's own block, whose room later buffers may take
        const size_t slot = free_place(blocks_);
        blocks_[slot] = Block{b.memory, req.size, type, 1, {}};
        b.block = int32_t(slot);
        b.offset = 0;
        b.span = req.size;
    }
    if (host_visible) {
        r = vkMapMemory(device_, b.memory, 0, capacity, 0, &b.mapped);
        if (r != VK_SUCCESS) {
            vkDestroyBuffer(device_, b.buffer, nullptr);
            vkFreeMemory(device_, b.memory, nullptr);
            add_time();
            check(r, "vkMapMemory");
        }
    }
    ++host_.buffers;
    if (host_log_)
        log_host(host_visible ? "host-visible buffer" : "device buffer", capacity, start, 0);
    return hand_out(b);
}

void Context::destroy(Buffer& b) {
    if (!b.buffer) return;
    if (host_log_)
        log_host(b.mapped ? "host-visible buffer given back" : "device buffer given back",
                 b.capacity, std::chrono::steady_clock::now(), 0);
    if (!b.mapped) live_ -= b.capacity;
    if (b.block >= 0) {
        vkDestroyBuffer(device_, b.buffer, nullptr);
        unbind_from_block(b);
        b = Buffer{};
        return;
    }
    if (b.capacity > cache_budget_) {
        free_buffer(b);
    } else {
        trim(cache_budget_ - b.capacity);
        idle_.push_back(b);
        cached_ += b.capacity;
    }
    b = Buffer{};
}

bool Context::bind_to_block(Buffer& b, const VkMemoryRequirements& req, uint32_t type) {
    for (size_t i = 0; i < blocks_.size(); ++i) {
        Block& block = blocks_[i];
        if (!block.memory || block.type != type) continue;
        for (size_t k = 0; k < block.free.size(); ++k) {
            const auto [at, bytes] = block.free[k];
            const uint64_t offset = (at + req.alignment - 1) / req.alignment * req.alignment;
            if (offset + req.size > at + bytes) continue;
            // The room taken out of the range: what is left before and after it stays free.
            block.free.erase(block.free.begin() + ptrdiff_t(k));
            if (offset + req.size < at + bytes)
                block.free.insert(block.free.begin() + ptrdiff_t(k),
                                  {offset + req.size, at + bytes - offset - req.size});
            if (offset > at)
                block.free.insert(block.free.begin() + ptrdiff_t(k), {at, offset - at});
            if (block.buffers++ == 0) cached_ -= block.size;
            vkBindBufferMemory(device_, b.buffer, block.memory, offset);
            b.memory = block.memory;
            b.block = int32_t(i);
            b.offset = offset;
            b.span = req.size;
            return true;
        }
    }
    return false;
}

void Context::unbind_from_block(Buffer& b) {
    Block& block = blocks_[size_t(b.block)];
    auto& free = block.free;
    // Back in order, merged with the ranges it touches.
    auto next = std::lower_bound(free.begin(), free.end(), std::make_pair(b.offset, uint64_t(0)));
    uint64_t at = b.offset, bytes = b.span;
    if (next != free.end() && at + bytes == next->first) {
        bytes += next->second;
        next = free.erase(next);
    }
    if (next != free.begin() && std::prev(next)->first + std::prev(next)->second == at) {
        std::prev(next)->second += bytes;
    } else {
        free.insert(next, {at, bytes});
    }
    if (--block.buffers > 0) return;
    // Empty: idle memory, freed at once if it alone is over the cache's budget.
    if (block.size > cache_budget_) {
        vkFreeMemory(device_, block.memory, nullptr);
        block = Block{};
        return;
    }
    cached_ += block.size;
    trim(cache_budget_);
}

void Context::free_buffer(Buffer& b) {
    vkDestroyBuffer(device_, b.buffer, nullptr);
    if (b.slab >= 0) {
        Slab& slab = slabs_[size_t(b.slab)];
        if (--slab.buffers == 0) slab.used = 0;
    } else {
        if (b.mapped) vkUnmapMemory(device_, b.memory);
        vkFreeMemory(device_, b.memory, nullptr);
    }
    b = Buffer{};
}

bool Context::bind_to_slab(Buffer& b, const VkMemoryRequirements& req, uint32_t type,
                           bool host_visible) {
    const auto offset_in = [&](const Slab& s) {
        return (s.used + req.alignment - 1) / req.alignment * req.alignment;
    };
    // The most recent slab of the type with room (a slab never holds buffers of two types).
    const auto most_recent_fit = [&] {
        for (size_t i = slabs_.size(); i-- > 0;)
            if (slabs_[i].memory && slabs_[i].type == type &&
                slabs_[i].host_visible == host_visible &&
                offset_in(slabs_[i]) + req.size <= slabs_[i].size)
                return i;
        return slabs_.size();
    };
    size_t pick = most_recent_fit();
    // Before a slab is allocated: the reserve's, where it has them.
    if (pick == slabs_.size() && take_reserved_slabs()) pick = most_recent_fit();
    if (pick == slabs_.size()) {
        const auto start = std::chrono::steady_clock::now();
        ++host_.allocations;
        host_.allocated_bytes += kSlabBytes[host_visible];
        const Slab slab = allocate_slab(type, host_visible);
        if (!slab.memory) return false;
        if (host_log_)
            log_host(host_visible ? "host-visible slab" : "device slab", slab.size, start, 0);
        pick = free_place(slabs_);  // (a freed slab's place is taken first)
        slabs_[pick] = slab;
    }
    Slab& slab = slabs_[pick];
    const uint64_t offset = offset_in(slab);
    vkBindBufferMemory(device_, b.buffer, slab.memory, offset);
    b.memory = slab.memory;
    b.mapped = slab.mapped ? slab.mapped + offset : nullptr;
    b.slab = int32_t(pick);
    slab.used = offset + req.size;
    ++slab.buffers;
    return true;
}

VkResult Context::create_buffer_handle(uint64_t bytes, VkBuffer* buffer) const {
    auto bci = vk_struct<VkBufferCreateInfo>(VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO);
    bci.size = bytes;
    bci.usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_SRC_BIT |
                VK_BUFFER_USAGE_TRANSFER_DST_BIT;
    bci.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
    return vkCreateBuffer(device_, &bci, nullptr, buffer);
}

VkResult Context::allocate_memory(uint64_t bytes, uint32_t type, VkDeviceMemory* memory) const {
    auto mai = vk_struct<VkMemoryAllocateInfo>(VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO);
    mai.allocationSize = bytes;
    mai.memoryTypeIndex = type;
    return vkAllocateMemory(device_, &mai, nullptr, memory);
}

Context::Slab Context::allocate_slab(uint32_t type, bool host_visible) const {
    Slab slab;
    slab.size = kSlabBytes[host_visible];
    slab.type = type;
    slab.host_visible = host_visible;
    if (allocate_memory(slab.size, type, &slab.memory) != VK_SUCCESS) return Slab{};
    void* mapped = nullptr;
    if (host_visible && vkMapMemory(device_, slab.memory, 0, slab.size, 0, &mapped) != VK_SUCCESS) {
        vkFreeMemory(device_, slab.memory, nullptr);
        return Slab{};
    }
    slab.mapped = static_cast<uint8_t*>(mapped);
    return slab;
}

void Context::free_empty_slabs() {
    for (Slab& slab : slabs_)
        if (slab.memory && slab.buffers == 0) {
            if (slab.mapped) vkUnmapMemory(device_, slab.memory);
            vkFreeMemory(device_, slab.memory, nullptr);
            slab = Slab{};
        }
}

void Context::trim(uint64_t keep_bytes) {
    adopt_reserve(false);
    size_t n = 0;  // idle_'s first n, the oldest, are freed
    while (n < idle_.size() && cached_ > keep_bytes) {
        cached_ -= idle_[n].capacity;
        free_buffer(idle_[n++]);
    }
    idle_.erase(idle_.begin(), idle_.begin() + ptrdiff_t(n));
    for (Block& block : blocks_)
        if (cached_ > keep_bytes && block.memory && block.buffers == 0) {
            cached_ -= block.size;
            vkFreeMemory(device_, block.memory, nullptr);
            block = Block{};
        }
    if (keep_bytes == 0) free_empty_slabs();
}

void Context::start_reserve(VkPhysicalDeviceType device_type) {
    uint64_t bytes = device_type == VK_PHYSICAL_DEVICE_TYPE_CPU ? 0 : cache_budget_ / 4;
    if (const char* env = std::getenv("SDFPRUNE_VULKAN_RESERVE_BYTES"); env && *env)
        bytes = std::strtoull(env, nullptr, 10);
    // Past the cache's budget an empty block is freed; without blocks no buffer takes it; and
    // one smaller than a few large buffers is not worth a thread.
    bytes = std::min(bytes, cache_budget_) & ~uint64_t(15);
    if (bytes < kReserveMin || !use_blocks_) return;
    // The memory types of the buffers that will take its room.
    VkBuffer probe;
    if (create_buffer_handle(bytes, &probe) != VK_SUCCESS) return;
    VkMemoryRequirements req;
    vkGetBufferMemoryRequirements(device_, probe, &req);
    vkDestroyBuffer(device_, probe, nullptr);
    reserve_.size = bytes;
    reserve_.type = memory_type(req.memoryTypeBits, false);
    for (int host_visible = 0; host_visible < 2; ++host_visible)
        reserve_.slab_types[host_visible] = memory_type(req.memoryTypeBits, host_visible != 0);
    // (vkAllocateMemory needs no external synchronization: the thread allocates while this one
    // builds the kernels and the caller uploads its scene.) The slabs first, for the first
    // call's first buffers (take_reserved_slabs), then the block (adopt_reserve).
    // (SDFPRUNE_VULKAN_RESERVE_DELAY_MS: the thread starts that late, for tests of a call that
    // comes before its reserve.)
    const char* delay_env = std::getenv("SDFPRUNE_VULKAN_RESERVE_DELAY_MS");
    const uint64_t delay_ms = delay_env ? std::strtoull(delay_env, nullptr, 10) : 0;
    reserve_thread_ = std::jthread([this, delay_ms](std::stop_token stop) {
        if (delay_ms > 0) {  // (ended early where the context is destroyed first)
            std::mutex m;
            std::condition_variable_any cv;
            std::unique_lock<std::mutex> lock(m);
            cv.wait_for(lock, stop, std::chrono::milliseconds(delay_ms), [] { return false; });
            if (stop.stop_requested()) {
                reserve_.done.store(true, std::memory_order_release);
                return;
            }
        }
        const auto start = std::chrono::steady_clock::now();
        if (use_slabs_)
            for (int host_visible = 0; host_visible < 2; ++host_visible)
                reserve_.slabs[host_visible] =
                    allocate_slab(reserve_.slab_types[host_visible], host_visible != 0);
        reserve_.slabs_ready.store(true, std::memory_order_release);
        if (allocate_memory(reserve_.size, reserve_.type, &reserve_.memory) != VK_SUCCESS)
            reserve_.memory = VK_NULL_HANDLE;
        reserve_.ms = ms_since(start);
        reserve_.done.store(true, std::memory_order_release);
    });
}

bool Context::take_reserved_slabs() {
    if (!reserve_.slabs_ready.load(std::memory_order_acquire)) return false;  // (not waited for)
    bool taken = false;
    for (Slab& slab : reserve_.slabs) {
        if (!slab.memory) continue;
        if (host_log_)
            log_host(slab.host_visible ? "host-visible slab from the reserve"
                                       : "device slab from the reserve",
                     slab.size, std::chrono::steady_clock::now(), 0);
        slabs_[free_place(slabs_)] = slab;
        slab = Slab{};
        taken = true;
    }
    return taken;
}

void Context::adopt_reserve(bool wait) {
    if (!reserve_thread_.joinable()) return;
    if (!wait && !reserve_.done.load(std::memory_order_acquire)) return;
    reserve_thread_.join();
    take_reserved_slabs();
    if (!reserve_.memory) {  // the device had no room for it: buffers allocate as before
        reserve_.size = 0;
        return;
    }
    if (host_log_)
        log_host("device reserve (allocated beside the context's making)", reserve_.size,
                 std::chrono::steady_clock::now(), 0);
    const size_t slot = free_place(blocks_);
    blocks_[slot] = Block{reserve_.memory, reserve_.size, reserve_.type, 0, {{0, reserve_.size}}};
    cached_ += reserve_.size;
}

uint64_t Context::reserve_bytes() {
    adopt_reserve(true);
    return reserve_.size;
}

double Context::reserve_ms() {
    adopt_reserve(true);
    return reserve_.ms;
}

void Context::set_cache_budget(uint64_t bytes) {
    cache_budget_ = bytes;
    trim(bytes);
}

}  // namespace sdfprune::gpu
