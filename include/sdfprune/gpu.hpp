// gpu.hpp — the Vulkan compute backend: the same pruning, tracing and discretization as the CPU
// backend (prune.hpp, render.hpp, discretize.hpp), run as compute shaders on any Vulkan device
// (NVIDIA, AMD, Intel, Apple through MoltenVK, Mesa's lavapipe on the CPU).
//
// The shaders include shaders/shared/sdf_math.h, the same header the CPU code uses, and mirror
// the CPU stages step for step, so both backends find the same tapes and statistics. Tapes are
// allocated in device buffers sized from counts (before each level from the parents' tapes, up
// to a cap; past it the tape pool grows and the level is redone when it overflows); a device
// that truly lacks memory gives a GpuError.
//
// Thread-safety: a Device and the grids made with it are used from one thread at a time.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "prune.hpp"
#include "render.hpp"

namespace sdfprune::gpu {

// No Vulkan device, a device error, or this build has no Vulkan backend. One-line message.
struct GpuError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

class Context;
class DeviceGrid;
struct DiscretizeStats;

// True when this build includes the Vulkan backend.
bool built_with_vulkan();

// One Vulkan device (the first with a compute queue; SDFPRUNE_VULKAN_DEVICE=N picks another).
// SDFPRUNE_VULKAN_MAX_BUFFER=BYTES makes it act as if a shader could address no more than
// BYTES of one buffer (the tests use it to exercise how work is split to fit a small device).
class Device {
  public:
    Device();  // throws GpuError when there is no device
    ~Device();
    Device(Device&&) noexcept;
    Device& operator=(Device&&) noexcept;
    std::string name() const;
    // Device memory held now by sdfprune's buffers on this device (grids included), not
    // counting the idle memory kept for reuse (memory_cached: idle buffers and empty blocks of
    // large ones, at most a quarter of the device's memory, 4 GiB; SDFPRUNE_VULKAN_CACHE_BYTES=N
    // sets the budget).
    uint64_t memory_in_use() const;
    uint64_t memory_cached() const;
    // Frees the idle memory (the next pruning allocates its buffers again; a reserve still
    // being made comes later, as idle memory).
    void release_cached_memory();
    // Device memory allocated while the device was made, on a thread of its own, for the
    // first pruning call's buffers (idle memory until then, in memory_cached; a call that
    // comes before the thread is done does not wait for it, and allocates its own); 0 where
    // there is none. By default a quarter of the idle memory's budget (1 GiB on an H100) on
    // GPUs, none on CPU devices; SDFPRUNE_VULKAN_RESERVE_BYTES=N sets it (0: none). And the
    // milliseconds its thread took to allocate it. Both wait for the thread.
    uint64_t memory_reserved() const;
    double reserve_ms() const;
    // Whether the device ends a shader invocation's loops after a count (lavapipe: 65,535
    // iterations in all), so that the pruner runs long steps in resumable rounds and caps the
    // jobs a workgroup takes at its dealt share; SDFPRUNE_VULKAN_LOOP_LIMITED=0 or 1 overrides
    // it, for tests.
    bool loop_limited() const;
    Context& context() { return *context_; }

  private:
    std::unique_ptr<Context> context_;
};

// Pruning statistics as PruneStats; prune_ms is GPU time (timestamps), prune_peak_bytes the
// device memory held at most while pruning, tape_bytes the device bytes of the result.
// wall_ms adds the host's share (submissions, waits, buffer growth); pool_grows counts the
// times a pool overflowed and grew (its level is then redone); submissions counts the
// pruning's submissions to the device, each waited for (one per level, and one more per
// level redone).
// The work shape of one pruning step on the device (a kernel over one level's octants, cells
// or refinement jobs), to judge the kernel's fit to a GPU without one: how many dispatches and
// workgroups it took, how many invocations (lanes) had work, and how far the busiest lane walks
// tapes one word after another.
struct GpuStepShape {
    uint32_t level = 0;
    // 0: cells from their parents' tapes; 1: a block's octants; 2: cells from their octants';
    // 3: the finest cells' sub-box refinement
    uint32_t mode = 0;
    uint32_t dispatches = 0;  // redone levels (a pool grew) included
    uint64_t workgroups = 0;  // over all dispatches
    uint64_t jobs = 0;        // cells or octants; in refinement, the near-field cells it takes
    uint64_t lanes = 0;       // invocations with a job (whole teams, see lanes_per_tape)
    // false: a team of lanes walks one parent tape in lockstep, one lane per child box (cell,
    // octant, or sub-box in refinement); true ("wide", modes 0–2 only): a whole workgroup
    // takes one parent tape and its kPruneTeam boxes, the tape's nodes spread over its lanes
    // and combined height by height.
    bool wide = false;
    // Wide: whether it ran prune_wide_runs.comp, which walks a long run of rounds (a chain's)
    // from shared memory, each chunk staged first, instead of from scratch as it is.
    bool wide_runs = false;
    // In teams and wide: whether its workgroups took their jobs as they came free (from a
    // counter, SDFPRUNE_VULKAN_TAKE), not dealt out to the teams or workgroups in advance.
    bool taken = false;
    // Lanes that take one parent tape together: the team (8), the workgroup (256) when wide, in
    // refinement a squad (32), or 1 where its lane pass took every cell (see long_jobs).
    uint32_t lanes_per_tape = 1;
    // The tape words one lane reads in sequence, at most: its jobs (rounded up) times, per job,
    // in a team the passes over a parent tape (evaluation once per batch of sub-boxes, the
    // sweep, the write) times the parents' longest tape; when wide, a lane's share of the
    // tape in each stage plus one step per height of the scene (the operators of one height
    // after another; heights of one operator each, a chain's, without a barrier between). A
    // bound, not a count.
    uint64_t longest_walk_words = 0;
    // The same measured on the device: the most tape entries a workgroup walked in one
    // dispatch. In teams (modes 0-2), a workgroup's lockstep walk: over the steps of its loop,
    // each phase's busiest lane (evaluated, swept, written), summed. When wide, over its stages
    // (barrier to barrier), each stage's busiest lane (the entries, items, heights and rounds
    // it took, a binary search's steps), summed. In refinement, its lanes' and squads' longest
    // lane over its jobs (each cell's tape staged, each walk over it, the sweep and the write),
    // its passes summed. The walks of a level's slices summed. 0 where not measured (the order
    // passes, past a submission's first 8 measured steps).
    uint64_t walked_words = 0;
    // The walks of all the step's workgroups (64 lanes each), summed likewise: the step's work
    // in workgroup-words, against which walked_words is its critical path. A 32-bit count on
    // the device: it wraps past 2^32 words a submission.
    uint64_t walked_sum_words = 0;
    // The step's GPU time (timestamps around its dispatches; 0 where the device has none), in
    // its level's last run.
    double gpu_ms = 0;
    // Refinement runs first a lane per cell where the cell's tape is short
    // (prune_refine_lanes.comp): its GPU time, within gpu_ms, and the cells it left to the squads
    // after it (0 in other steps). The lane pass walks every cell's first sub-boxes (the corners
    // and the middle), then in a second pass the others of the cells that need them: more_jobs.
    double lanes_ms = 0;
    uint64_t long_jobs = 0;
    // The longest tape the lane pass took (the longer ones left to the squads): chosen per
    // slice, by how many cells have longer tapes than 32 words (the most of a level's slices;
    // 0 without a lane pass).
    uint32_t lane_tape = 0;
    uint64_t more_jobs = 0;
    // Refinement's jobs (within `jobs`) that it only copies: the cells where it has nothing to
    // try (no operator a sub-box might decide, no far-field test that might pass), or tapes
    // too long to refine. They are listed apart, so that their lanes do not wait on walks.
    uint64_t copy_jobs = 0;
    // The scratch the step's lanes hold (modes 0-2; the most of a level's slices): in teams,
    // each team's state and stack and each job's tape entries, room for the parents' longest
    // tape in every team, or where the jobs' tapes sum to less, what they claim at most (each
    // job room for its own); when wide, every workgroup's in all its buffers.
    uint64_t scratch_bytes = 0;
};

struct DevicePruneStats : PruneStats {
    double wall_ms = 0;
    uint32_t pool_grows = 0;
    uint32_t submissions = 0;
    // Slices of blocks over all levels (one a level, unless a level's octant pool would outgrow
    // the device's largest buffer: its blocks are then pruned a slice at a time).
    uint32_t slices = 0;
    // The host's share of wall_ms: buffers newly made (staging buffers of uploads and
    // readbacks too), buffers taken instead from the device's idle cache (those a previous
    // level or call gave back), the time of both; the device memory allocations among the new
    // buffers (buffers up to 1 MiB, host-visible up to 256 KiB, share slabs of 16 MiB and
    // 2 MiB allocated once: SDFPRUNE_VULKAN_SLABS=0 gives every buffer its own); and every
    // submission's (uploads and readbacks included) from the end of its recording to its
    // results being back, which holds the GPU's time.
    uint64_t host_buffers = 0, host_buffers_reused = 0, host_allocations = 0, host_submissions = 0;
    // The bytes of those device allocations: on an NVIDIA H100 a first call's allocations
    // cost the host about 0.016 ms per MB (BENCHMARKS.md, stop 29).
    uint64_t host_allocated_bytes = 0;
    double host_buffer_ms = 0, host_submit_ms = 0;
    // Whether the wide steps used subgroup operations (the device has them and
    // SDFPRUNE_VULKAN_SUBGROUPS is not 0), else shared memory.
    bool subgroups = false;
    // The device's subgroup size (lanes that run in lockstep: 32 on NVIDIA, 4-16 on lavapipe
    // by LP_NATIVE_VECTOR_WIDTH), or 0 where the kernels use no subgroup operations.
    uint32_t subgroup_size = 0;
    // Whether the team steps kept their decision and sweep flags a byte a lane (the device has
    // 8-bit storage and SDFPRUNE_VULKAN_BYTE_FLAGS is not 0: prune_bytes.comp), else a word.
    // (The wide steps always do: without 8-bit storage every step runs in teams.)
    bool byte_flags = false;
    std::vector<GpuStepShape> steps;  // in the order they ran
};

// A step's figures and a device pruning's own (not its steps', not PruneStats'), by the names
// `sdfprune stats --json` and the Python package's GpuGrid.stats give them: add(name, value)
// for each, the value a bool, uint32_t, uint64_t or double.
template <class Add>
void for_each_figure(const GpuStepShape& st, Add&& add) {
    add("level", st.level);
    add("mode", st.mode);
    add("wide", st.wide);
    add("wide_runs", st.wide_runs);
    add("taken", st.taken);
    add("dispatches", st.dispatches);
    add("workgroups", st.workgroups);
    add("jobs", st.jobs);
    add("lanes", st.lanes);
    add("lanes_per_tape", st.lanes_per_tape);
    add("longest_walk_words", st.longest_walk_words);
    add("walked_words", st.walked_words);
    add("walked_sum_words", st.walked_sum_words);
    add("gpu_ms", st.gpu_ms);
    add("lanes_ms", st.lanes_ms);
    add("long_jobs", st.long_jobs);
    add("lane_tape", st.lane_tape);
    add("more_jobs", st.more_jobs);
    add("copy_jobs", st.copy_jobs);
    add("scratch_bytes", st.scratch_bytes);
}
template <class Add>
void for_each_figure(const DevicePruneStats& s, Add&& add) {
    add("wall_ms", s.wall_ms);
    add("submissions", s.submissions);
    add("subgroups", s.subgroups);
    add("subgroup_size", s.subgroup_size);
    add("byte_flags", s.byte_flags);
    add("pool_grows", s.pool_grows);
    add("slices", s.slices);
    add("host_buffers", s.host_buffers);
    add("host_buffers_reused", s.host_buffers_reused);
    add("host_allocations", s.host_allocations);
    add("host_allocated_bytes", s.host_allocated_bytes);
    add("host_buffer_ms", s.host_buffer_ms);
    add("host_submissions", s.host_submissions);
    add("host_submit_ms", s.host_submit_ms);
}

// A pruned grid living in device memory; refers to its Scene and Device, which must outlive it.
class Grid {
  public:
    Grid(Grid&&) noexcept;
    Grid& operator=(Grid&&) noexcept;
    ~Grid();
    const DevicePruneStats& stats() const;
    const Scene& scene() const;

    // Finest-cell contents read back from the device, for comparisons with the CPU backend:
    // for each finest cell in z-major order, the tape's words (empty for far-field cells)
    // through `visit(index, far_field, constant, tape)`.
    struct CellContents {
        bool far_field = true;
        float constant = 0;
        std::span<const uint32_t> tape;
    };
    void for_each_finest_cell(
        const std::function<void(uint64_t index, const CellContents&)>& visit) const;

  private:
    friend Grid prune(Device&, const Scene&, const PruneOptions&);
    friend Image render(Device&, const Grid&, const RenderOptions&, RenderStats*);
    friend void discretize(Device&, const Grid&, uint32_t, std::span<float>, DiscretizeStats*);
    Grid();
    std::unique_ptr<DeviceGrid> impl_;
};

// Hierarchical pruning on the device; same options and results as sdfprune::prune (threads,
// progress and cancel are ignored).
Grid prune(Device& device, const Scene& scene, const PruneOptions& options = {});

// Sphere tracing (primary + shadow ray) on the device; stats->trace_ms is GPU time.
// Each thread's evaluation stack is sized from the grid's finest tapes (stats->stack_words),
// not from the full tree. The few pixels that need the full tree (a hit point outside the grid
// or in a far-field cell, as PrunedField::tape_at on the CPU) are traced again in a second
// pass with full-depth stacks and as few threads as need them (stats->full_tree_pixels); it
// throws GpuError only when not even one thread's full-depth stack fits the device.
Image render(Device& device, const Grid& grid, const RenderOptions& options,
             RenderStats* stats = nullptr);

// What discretize did.
struct DiscretizeStats {
    double gpu_ms = 0;
    // 32-bit words of evaluation stack per thread, sized from the grid's finest tapes.
    uint64_t stack_words = 0;
    // Samples outside the grid (only by rounding), evaluated on the full tree in a second
    // pass with full-depth stacks (see render).
    uint64_t full_tree_samples = 0;
};

// The pruned field at the centres of an n³ grid over the scene's AABB, as discretize_pruned,
// with per-thread stacks sized as render's; *stats (if given) receives what it did.
void discretize(Device& device, const Grid& grid, uint32_t n, std::span<float> out,
                DiscretizeStats* stats = nullptr);

}  // namespace sdfprune::gpu
