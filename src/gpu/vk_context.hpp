// vk_context.hpp — the little of Vulkan the GPU backend needs: one compute queue, storage
// buffers (recycled through an idle cache), compute kernels built from the SPIR-V embedded at
// build time, and a recorder that batches dispatches and copies into one submission timed with
// GPU timestamps.
//
// Not thread-safe: one Context is used by one thread at a time.
#pragma once

#include <vulkan/vulkan.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <initializer_list>
#include <string>
#include <thread>
#include <vector>

#include "sdfprune/gpu.hpp"

namespace sdfprune::gpu {

// local_size_x of every kernel but prune_wide.comp (kPruneWide, device_layout.hpp).
inline constexpr uint32_t kWorkgroupSize = 64;

// The kernels, one per compute shader in shaders/gpu/.
enum class KernelId : uint32_t {
    kPrune,
    kPruneBytes,  // the same, its decision and sweep flags a byte a lane (needs byte_storage()
                  // and subgroups())
    kPruneRefineLanes,      // refinement's (mode 3) lane pass: a lane per cell with a short tape
                            // (needs subgroups())
    kPruneRefineLanesLong,  // the same for tapes of up to 64 words
    kPruneRefine,           // refinement: a squad of lanes per cell
    kPruneWide,             // the wide kernels need byte_storage() (else not built)
    kPruneWideSubgroups,    // needs subgroups() too
    kPruneWideRuns,         // the same, its long runs walked from shared memory
    kExpand,
    kCellInfo,
    kTrace,
    kDiscretize,
    kCount
};

// An on/off setting from the environment (SDFPRUNE_VULKAN_...=0 or 1): `fallback` where
// `name` is unset or empty.
bool env_flag(const char* name, bool fallback);

// A zeroed Vulkan info struct with its type set.
template <class T>
T vk_struct(VkStructureType type) {
    T s{};
    s.sType = type;
    return s;
}

struct Buffer {
    VkBuffer buffer = VK_NULL_HANDLE;
    VkDeviceMemory memory = VK_NULL_HANDLE;
    // The bytes asked for (rounded up to 16): what the shaders see (the descriptor's range),
    // what fill() clears and what callers take as the array's length.
    VkDeviceSize size = 0;
    // The bytes allocated: size's capacity class (Context::create_buffer), at least size.
    VkDeviceSize capacity = 0;
    void* mapped = nullptr;  // host-visible buffers only
    // The slab (Context's) whose memory the buffer is bound into, or -1: memory of its own.
    int32_t slab = -1;
    // The block (Context's) it is bound into, or -1, and where: its offset and bytes there.
    int32_t block = -1;
    VkDeviceSize offset = 0, span = 0;
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
    // Mesa's CPU driver (llvmpipe) ends an invocation's loops after kLoopLimit iterations in
    // all; kernels must then keep each invocation's work under it (or report that they can't).
    // loop_limited(): the steps are planned so (SDFPRUNE_VULKAN_LOOP_LIMITED may say otherwise,
    // for tests); device_ends_loops(): the device does so, whatever the plan (the pruning
    // kernels then probe for it: prune_common.glsl, probe_loop_limit).
    static constexpr uint64_t kLoopLimit = 65535;
    bool loop_limited() const { return loop_limited_; }
    bool device_ends_loops() const { return device_ends_loops_; }
    // Subgroup arithmetic and ballot in compute shaders (Vulkan 1.1), for the kernels that use
    // them; SDFPRUNE_VULKAN_SUBGROUPS=0 turns them off (the fallbacks, for tests).
    bool subgroups() const { return subgroups_; }
    // Lanes per subgroup where subgroups(), else 0.
    uint32_t subgroup_size() const { return subgroups_ ? subgroup_size_ : 0u; }
    // 8-bit storage buffer access (VK_KHR_8bit_storage), for prune_bytes.comp and the wide
    // kernels (not built without it: their steps then run in teams, prune.comp);
    // SDFPRUNE_VULKAN_8BIT_STORAGE=0: a device without it, for tests.
    bool byte_storage() const { return byte_storage_; }
    // Whether this device runs kernel k (prune_wide's 256-lane workgroups need a device that
    // allows them; the subgroup kernels need subgroups()).
    bool can_run(KernelId k) const { return kernels_[size_t(k)].pipeline != VK_NULL_HANDLE; }
    // Workgroups for a grid-stride loop over n items: all of them, or the most one dispatch
    // may have.
    uint32_t groups_for(uint64_t n) const;
    // Threads in flight (a multiple of kWorkgroupSize) for `work` items when each thread needs
    // `bytes_per_thread` of scratch: as many as fit the scratch budget and one buffer's range.
    // Throws GpuError when not even one workgroup's scratch fits.
    uint32_t threads_for(uint64_t work, uint64_t bytes_per_thread) const;
    // What threads_for shares out: the bytes of scratch all threads in flight may hold, and
    // the most workgroups one dispatch may have.
    uint64_t scratch_budget_bytes() const;
    // The scratch one pruning step may hold: a sixteenth of the device-local heap, at least
    // scratch_budget_bytes(), within one buffer's range. Its steps hold no more teams than the
    // device runs at once (resident_threads), so only long parent tapes take this much: there,
    // teams starved of scratch would walk them one round after another. Both budgets are
    // SDFPRUNE_VULKAN_SCRATCH_BYTES where that is set (read at each call, for tests).
    uint64_t prune_scratch_budget_bytes() const;
    // How many buffers of prune_scratch_budget_bytes() a wide pruning step may spread its
    // workgroups' scratch over (one range of each bound per dispatch, the dispatches running
    // side by side): a quarter of the device-local heap in all, 1 to 8 buffers;
    // SDFPRUNE_VULKAN_SCRATCH_BUFFERS=N sets it (read at each call, for tests).
    uint32_t prune_scratch_buffers() const;
    uint32_t max_workgroups() const { return max_groups_; }
    // About how many invocations the device runs at once: more threads in flight only queue
    // behind these, so scratch for more is held for nothing. From VK_NV_shader_sm_builtins
    // (SMs × warps per SM × 32) or VK_AMD_shader_core_properties (SIMDs × wavefronts per SIMD
    // × wavefront size) where the device has them; on CPU devices (lavapipe: a workgroup per
    // core at a time) kCpuGroupsPerCore workgroups a core; elsewhere kAssumedResidentThreads.
    // SDFPRUNE_VULKAN_RESIDENT_THREADS=N sets it (for tests).
    // (2^18: about an H100's or H200's 132 SMs × 2,048 invocations, 270,336.)
    static constexpr uint64_t kAssumedResidentThreads = uint64_t(1) << 18;
    static constexpr uint64_t kCpuGroupsPerCore = 16;
    uint64_t resident_threads() const { return resident_threads_; }

    // A storage buffer in device memory, or host-visible (mapped) for uploads and readbacks,
    // of `bytes` (Buffer::size) and contents undefined. Buffers are recycled, since allocating
    // device memory costs the host 0.4-1 ms a buffer on an H200's driver: destroy() puts a
    // buffer in an idle cache, and create_buffer() takes the most recently cached buffer of the
    // same kind (device-local or host-visible) and capacity class before it allocates. Classes
    // are 2^k times 1, 1.25, 1.5 or 1.75 (from 64 bytes; below, multiples of 16; never more
    // than the device's largest storage buffer unless asked for), so a buffer holds at most
    // 25 % more than asked and a call that repeats another's requests finds every buffer it
    // needs in the cache. Throws GpuError when the device has no memory left for it (after
    // freeing the idle cache and trying once more). `exact`: its capacity `bytes` (rounded up
    // to 16), for a large buffer that is never held for more (its class may be a quarter more).
    Buffer create_buffer(uint64_t bytes, bool host_visible = false, bool exact = false);
    // Hands b back to the idle cache (freed at once if it alone is over the budget) and
    // empties it; an empty buffer is ignored.
    void destroy(Buffer& b);
    // Device-local memory held by buffers handed out (their capacities), now and at most since
    // reset_peak(); the idle cache is not counted.
    uint64_t bytes_live() const { return live_; }
    uint64_t bytes_peak() const { return peak_; }
    void reset_peak() { peak_ = live_; }
    // The idle cache: bytes it holds (idle buffers, device-local and host-visible, and empty
    // blocks), and its budget, past which the buffers cached longest are freed first, then
    // empty blocks. By default a quarter of the largest
    // device-local heap, at most 4 GiB; SDFPRUNE_VULKAN_CACHE_BYTES=N sets it (0: no cache).
    uint64_t bytes_cached() const { return cached_; }
    uint64_t cache_budget() const { return cache_budget_; }
    void set_cache_budget(uint64_t bytes);
    // The reserve: device memory allocated while the context is made, on a thread of its own,
    // so that a fresh process's first pruning call finds its buffers' room already allocated
    // (on an H100 a call's allocations cost the host about 0.016 ms per MB and 0.13 ms each,
    // the better part of a first call's wall time): two slabs (device and host-visible), then
    // an empty block (idle memory, in bytes_cached()). A call takes what the thread has made
    // by then, and never waits for the rest: where it comes first, it allocates as it would
    // without a reserve, and the reserve serves later calls. reserve_bytes() is its block's
    // bytes (0: none, or its allocation failed), reserve_ms() the thread's time (both wait for
    // the thread). By default a quarter of the idle cache's budget (1 GiB on an H100) on GPUs,
    // none on CPU devices, whose allocations cost nothing; SDFPRUNE_VULKAN_RESERVE_BYTES=N
    // sets it (at most the cache's budget; none below kReserveMin).
    static constexpr uint64_t kReserveMin = 16 << 20;
    uint64_t reserve_bytes();
    double reserve_ms();
    // Frees idle buffers, those cached longest first, until at most `keep_bytes` are cached.
    void trim(uint64_t keep_bytes = 0);

    // Where the host's time goes, summed since the context was made: buffers allocated (device
    // memory allocated, mapped) and buffers taken from the idle cache instead, with the time
    // create_buffer took for both; and submissions (uploads and readbacks too) with the host's
    // wall time from ending the recording to the results being back.
    struct HostTime {
        uint64_t buffers = 0, buffers_reused = 0, submissions = 0;
        uint64_t allocations = 0;      // device memory allocations (buffers' own and slabs)
        uint64_t allocated_bytes = 0;  // their bytes
        double buffer_ms = 0, submit_ms = 0;
    };
    const HostTime& host_time() const { return host_; }

    // Recording: begin(), any number of dispatch()/copy()/fill(), then submit() runs them in
    // order (each waits for the previous one's writes) and returns the GPU milliseconds they took.
    // Long recordings are submitted in parts on the way (kMaxDispatches at a time).
    static constexpr uint32_t kMaxDispatches = 4096;
    void begin();
    // A dispatch waits for everything recorded before it, and what follows waits for it,
    // unless `then_barrier` is false: then the next dispatch may run beside it (they must not
    // touch the same memory but through atomics).
    void dispatch(KernelId k, std::initializer_list<const Buffer*> buffers, const void* push,
                  uint32_t push_bytes, uint32_t groups, bool then_barrier = true);
    void copy(const Buffer& src, const Buffer& dst, uint64_t bytes, uint64_t src_offset = 0,
              uint64_t dst_offset = 0);
    // Writes `bytes` (a multiple of 4, at most 65,536) of `data` to dst from `offset`, from
    // the command buffer itself (no staging buffer).
    void update(const Buffer& dst, const void* data, uint64_t bytes, uint64_t offset = 0);
    void fill(const Buffer& dst, uint32_t value);
    // Fills `bytes` of dst from `offset` (both multiples of 4).
    void fill(const Buffer& dst, uint32_t value, uint64_t offset, uint64_t bytes);
    double submit();
    // A timestamp after everything recorded so far (each dispatch waits for the one before):
    // after submit(), stamp_ms(id) is the GPU milliseconds from begin() to it, summed over the
    // parts a long recording was submitted in. Up to kMaxStamps per part are taken; further
    // stamps of a part, and all on a device without timestamps, read 0.
    static constexpr uint32_t kMaxStamps = 256;
    uint32_t stamp();
    double stamp_ms(uint32_t id) const { return id < stamps_ms_.size() ? stamps_ms_[id] : 0; }

    // Blocking transfers through a staging buffer.
    void upload(const Buffer& dst, const void* data, uint64_t bytes, uint64_t dst_offset = 0);
    // Several uploads through one staging buffer and one submission.
    struct Upload {
        const Buffer* dst;
        const void* data;
        uint64_t bytes;
        uint64_t dst_offset = 0;
    };
    void upload(std::initializer_list<Upload> uploads);
    void download(const Buffer& src, void* data, uint64_t bytes, uint64_t src_offset = 0);

  private:
    void report_kernel_statistics(const char* name, VkPipeline pipeline) const;
    // SDFPRUNE_VULKAN_HOST_LOG's line: what, its bytes, the host's time since `start`.
    void log_host(const char* what, uint64_t bytes, std::chrono::steady_clock::time_point start,
                  double gpu_ms) const;
    struct Kernel {
        VkDescriptorSetLayout set_layout = VK_NULL_HANDLE;
        VkPipelineLayout layout = VK_NULL_HANDLE;
        VkPipeline pipeline = VK_NULL_HANDLE;
        uint32_t bindings = 0;
    };
    void barrier();
    void begin_part();
    // Drops what was recorded since begin() (after an error while recording).
    void abandon();
    double submit_part();
    void check(VkResult r, const char* what) const;
    uint32_t memory_type(uint32_t bits, bool host_visible) const;
    // A buffer handle of `bytes` with every buffer's usage (no memory bound), and device memory
    // of `bytes` and memory type `type`: the one place each is asked for (create_buffer, the
    // slabs, the reserve's thread; neither counts anything).
    VkResult create_buffer_handle(uint64_t bytes, VkBuffer* buffer) const;
    VkResult allocate_memory(uint64_t bytes, uint32_t type, VkDeviceMemory* memory) const;
    // Unmaps and frees b's memory (not through the idle cache).
    void free_buffer(Buffer& b);
    // Binds a new buffer of memory requirements `req` into a slab of memory type `type`
    // (making a slab if none has room); false if the device has no memory for one.
    bool bind_to_slab(Buffer& b, const VkMemoryRequirements& req, uint32_t type, bool host_visible);
    // A new slab of kSlabBytes[host_visible] of memory type `type` (mapped where host-visible),
    // or one without memory where the device has none for it. Counts nothing (the reserve's
    // thread calls it too).
    struct Slab;
    Slab allocate_slab(uint32_t type, bool host_visible) const;
    // Frees the slabs no buffer is bound into.
    void free_empty_slabs();
    // Binds a new device-local buffer of memory requirements `req` into free room of a block of
    // memory type `type`; false if no block has room.
    bool bind_to_block(Buffer& b, const VkMemoryRequirements& req, uint32_t type);
    // Gives a block-bound buffer's room back to its block (its buffer destroyed).
    void unbind_from_block(Buffer& b);
    // Starts the reserve's allocation (reserve_bytes) on reserve_thread_.
    void start_reserve(VkPhysicalDeviceType type);
    // Where the reserve's thread is done (or, with `wait`, once it is), ends it and makes its
    // memory an empty block (and takes its slabs).
    void adopt_reserve(bool wait);
    // Adds the reserve's slabs to slabs_ where its thread has made them (never waits); false
    // where none came.
    bool take_reserved_slabs();

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
    double timestamp_ns_ = 1;                 // nanoseconds per tick
    uint64_t timestamp_mask_ = ~uint64_t(0);  // the bits a timestamp holds
    std::vector<Kernel> kernels_;
    VkPhysicalDeviceMemoryProperties memory_{};
    std::string device_name_;
    uint64_t max_range_ = 0;
    uint32_t max_groups_ = 65535;
    uint64_t resident_threads_ = kAssumedResidentThreads;
    uint64_t device_heap_ = 0;  // the largest device-local heap (or any heap), in bytes
    bool loop_limited_ = false, device_ends_loops_ = false;
    bool subgroups_ = false;
    uint32_t subgroup_size_ = 0;
    bool byte_storage_ = false;
    uint64_t live_ = 0, peak_ = 0;
    uint64_t memory_limit_ = ~uint64_t(0);  // SDFPRUNE_VULKAN_MEMORY_LIMIT
    // Small buffers' memory. A device allocation costs the host about 0.13 ms however small
    // (and about 0.02 ms per MB beyond; host-visible memory 0.4 ms per MB) on an H100's
    // driver, and a pruning call makes dozens of buffers of a few KB, so buffers up to
    // kSlabBufferMax are bound into slabs of kSlabBytes, allocated once and reused (bump
    // allocation; a slab starts over when no buffer is left in it). Not counted in
    // bytes_live(): only the buffers' capacities are.
    struct Slab {
        VkDeviceMemory memory = VK_NULL_HANDLE;
        uint8_t* mapped = nullptr;  // host-visible slabs
        uint64_t size = 0, used = 0;
        uint32_t type = 0;
        bool host_visible = false;  // its buffers' kind (one memory type may serve both)
        uint32_t buffers = 0;       // bound into it now
    };
    static constexpr uint64_t kSlabBytes[2] = {16 << 20, 2 << 20};       // device, host
    static constexpr uint64_t kSlabBufferMax[2] = {1 << 20, 256 << 10};  // device, host
    std::vector<Slab> slabs_;
    bool use_slabs_ = true;  // SDFPRUNE_VULKAN_SLABS=0: every buffer allocates its own
    // Large device-local buffers' memory (over kSlabBufferMax). A pruning call's pools and
    // scratch grow level by level: a buffer given back is smaller than the next one asked for,
    // so an idle cache by capacity class gave a first call few of them and it allocated far
    // more than its peak (the generated fluid at 256³: 7.0 GB for a 2.7 GB peak). Such a
    // buffer is bound into a block of device memory allocated for it, and when it is destroyed
    // its room goes back to the block, where later buffers take what fits (first fit); a block
    // left empty is idle memory (counted in bytes_cached(), freed past the cache's budget).
    // SDFPRUNE_VULKAN_BLOCKS=0 (or no cache budget): through the idle cache, as before.
    struct Block {
        VkDeviceMemory memory = VK_NULL_HANDLE;
        uint64_t size = 0;
        uint32_t type = 0;
        uint32_t buffers = 0;                             // bound into it now
        std::vector<std::pair<uint64_t, uint64_t>> free;  // (offset, bytes), in order
    };
    std::vector<Block> blocks_;
    bool use_blocks_ = true;
    // The reserve (reserve_bytes): its thread, and what the thread made: a slab of each kind
    // (read once slabs_ready is set), then the block's memory (read once done is set).
    struct Reserve {
        uint32_t slab_types[2] = {0, 0};  // their memory types
        Slab slabs[2];                    // device, host-visible (none without slabs)
        std::atomic<bool> slabs_ready{false}, done{false};
        VkDeviceMemory memory = VK_NULL_HANDLE;
        uint64_t size = 0;
        uint32_t type = 0;
        double ms = 0;  // the thread's time making them
    } reserve_;
    std::jthread reserve_thread_;
    // Idle buffers, cached longest first, and empty blocks; cached_ counts their bytes.
    std::vector<Buffer> idle_;
    uint64_t cached_ = 0, cache_budget_ = 0;
    uint32_t sets_used_ = 0;
    double carried_ms_ = 0;              // GPU time of the parts already submitted
    std::vector<double> stamps_ms_;      // the recording's stamps (stamp())
    std::vector<uint32_t> part_stamps_;  // the current part's stamps, in query order
    HostTime host_;
    bool host_log_ = false;  // SDFPRUNE_VULKAN_HOST_LOG
    std::chrono::steady_clock::time_point made_ = std::chrono::steady_clock::now();
    bool recording_ = false;
};

// The buffers a function holds for a while: whatever is left of them is destroyed when it
// returns or throws. Entries keep their addresses; a buffer destroyed early (Context::destroy)
// or handed on (then set to Buffer{}) is skipped.
class LocalBuffers {
  public:
    explicit LocalBuffers(Context& ctx) : ctx_(ctx) {}
    ~LocalBuffers() {
        for (Buffer& b : buffers_) ctx_.destroy(b);
    }
    LocalBuffers(const LocalBuffers&) = delete;
    LocalBuffers& operator=(const LocalBuffers&) = delete;
    Buffer& create(uint64_t bytes, bool host_visible = false, bool exact = false) {
        Buffer& b = slot();
        b = ctx_.create_buffer(bytes, host_visible, exact);
        return b;
    }
    // An empty entry, for a buffer made later.
    Buffer& slot() { return buffers_.emplace_back(); }

  private:
    Context& ctx_;
    std::deque<Buffer> buffers_;
};

}  // namespace sdfprune::gpu
