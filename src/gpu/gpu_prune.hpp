// gpu_prune.hpp — the Vulkan pruner's pieces, shared by gpu_prune.cpp (the levels, their runs and
// pools, the statistics) and gpu_prune_plan.cpp (each step's shape: teams, wide, refinement's
// lanes and squads). Internal to src/gpu.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "device_grid.hpp"

namespace sdfprune::gpu::pruning {

inline uint64_t ceil_div(uint64_t a, uint64_t b) {
    return (a + b - 1) / b;
}

// A step of a level (prune.comp): `jobs` cells or octants from their parents' tapes into
// `octants`/`cells`, run as team jobs that each walk one parent tape with kPruneTeam lanes,
// sized by the parents' longest tape and deepest stack (a child's tape is never longer or
// deeper than its parent's); or wide (prune_wide.comp), a workgroup a team job; or in
// refinement (mode 3) a lane a cell (prune_refine_lanes.comp) or a squad a cell
// (prune_refine.comp). Planned in gpu_prune_plan.cpp.
struct Step {
    PrunePush push;
    const Buffer *octants, *cells;
    // Its team jobs are [first_team_job, first_team_job + team_jobs): those of a slice of the
    // level's blocks (refinement: of its list, from 0).
    uint64_t first_team_job, team_jobs, teams, rounds, per_dispatch;
    uint64_t job_walk;         // in teams, the tape words a lane reads per job, at most
    uint32_t threads, groups;  // lanes that take jobs, and their workgroups (a dispatch's)
    // Wide steps: the scratch buffers its workgroups' scratch is spread over, one dispatch of
    // `groups` workgroups a buffer, side by side (Context::prune_scratch_buffers).
    uint32_t scratch_buffers = 1;
    bool wide;
    KernelId kernel = KernelId::kPrune;
    // Refinement's squads after its lane pass (prune_refine_lanes.comp), taking the cells it
    // listed: its jobs are the long list's entries.
    bool listed = false;
    // The lane pass's second pass (kStepRefineSecondPass): its jobs are the cells its first pass
    // listed in the more list, past the first sub-boxes.
    bool second_pass = false;
    // The lane pass's order pass (kStepRefineOrderPass), before it: the list's cells to decide
    // again sorted by walk class into the order list, from which the passes take them
    // (kStepRefineOrdered).
    bool order_pass = false;
    uint64_t scratch_words = 0;  // the scratch its teams (or wide workgroups) take
    GpuStepShape shape;
    uint32_t first_stamp = 0, last_stamp = 0;  // Context::stamp() around its dispatches
};

// A level as it is made: its blocks' shape and its buffers (held by the pruner's LocalBuffers).
struct Level {
    uint32_t index = 0;
    uint32_t f = 0;                     // cells per axis of a block
    uint32_t nf = 0;                    // of the next level's blocks (0 at the finest)
    uint64_t per_block = 0, total = 0;  // cells of a block, of the level
    vec3 csize;
    bool finest = false, refine = false;
    bool split = false;  // octants first (as prune.cpp)
    Buffer *cells = nullptr, *octants = nullptr, *next = nullptr;
    size_t first_shape = 0;  // the level's steps' shapes in the statistics
    // Refinement's list, from the run that made the cells: the cells it decides again (and
    // their count per walk class), and those it only copies (prune_common.glsl: list_near_cell).
    uint32_t listed_cells = 0, copied_cells = 0;
    std::array<uint32_t, kRefineWalkClasses> walk_cells{};
    // The words of the tapes (headers included) of the parents whose jobs the next step in
    // teams takes, summed over them, at most (its jobs' claims: gpu_prune_plan.cpp).
    uint64_t parent_tape_words = 0;
};

class Pruner {
  public:
    Pruner(Device& device, const Scene& sc, const PruneOptions& opt, DeviceGrid& g);
    // All levels, then the cells of all levels in one buffer (timed: prune_ms, wall_ms).
    void run();
    // The statistics, read back (not timed).
    void read_statistics();

  private:
    void prune_level(uint32_t li);
    GpuCounters prune_slices(Level& lv);
    // (bound: the finest level's final cells, whose near-field cells' bounds give near_box)
    std::optional<GpuCounters> run_steps(Level& lv, std::vector<Step>& steps, bool expand,
                                         uint64_t octant_keep, bool may_slice,
                                         Buffer* bound = nullptr);
    void add_shape(const Level& lv, const GpuStepShape& shape);
    std::vector<Step> plan_step(const Level& lv, uint32_t mode, uint64_t first_block,
                                uint64_t blocks, uint64_t jobs, const Buffer& octants,
                                const Buffer& cells, bool transient);
    Step plan_teams(const Level& lv, uint32_t mode, uint64_t first_block, uint64_t blocks,
                    uint64_t jobs, const Buffer& octants, const Buffer& cells, bool transient);
    uint32_t choose_lane_tape(const Level& lv) const;
    Step plan_refine_lanes(const Step& squads, bool second_pass) const;
    Step plan_refine_more(const Step& lanes) const;
    Step plan_order_pass(const Step& step, uint64_t items, uint64_t per_group) const;
    Step plan_refine_order(const Step& lanes, uint64_t listed) const;
    Step plan_job_order(const Step& step, uint64_t parents, uint32_t mode) const;
    void plan_squads(const Level& lv, Step& s);
    PrunePush push_for(const Level& lv, uint32_t mode, uint32_t threads, uint32_t step_flags,
                       uint32_t budget) const;
    void plan_wide(Step& s, uint64_t& scratch_bytes, uint64_t claimable_words);
    void record_step(Step& s);
    void resize(Buffer& pool, uint64_t& cap, uint64_t words, uint64_t keep);
    void grow(Buffer& pool, uint64_t& cap, uint64_t need, uint64_t keep);
    void presize(Buffer& pool, uint64_t& cap, uint64_t used, uint64_t bound);
    // Makes b hold at least `bytes`: within its capacity (its class's, Context::create_buffer),
    // or in a new buffer (its contents are not kept).
    void hold(Buffer& b, uint64_t bytes);
    // Gives back the steps' scratch (between steps: each step holds what it needs).
    void release_scratch();
    void gather_cells();

    Context& ctx;
    const Scene& sc;
    const PruneOptions& opt;
    DeviceGrid& g;
    DevicePruneStats& st;
    const std::vector<uint32_t> res;
    // Temporaries: what is left of them is freed on return, or when an error is thrown.
    LocalBuffers local;
    const uint64_t max_pool_words;
    std::vector<uint32_t> head;  // the full tape with its header
    uint32_t scene_height = 0;   // the root's height (prune_wide.comp)
    // prune_wide.comp's search for an operator's left operand: its steps per tape entry, on
    // average over the scene (plan_wide).
    uint32_t wide_search_steps = 0;
    // The scene's heights above 0 that more than one operator shares (plan_wide's barriers).
    uint32_t shared_heights = 0;
    uint64_t capacity = 0, octant_capacity = 1 << 16;  // of g.pool and octant_pool, in words
    Buffer& node_spans;
    // The steps' counters (prune_common.glsl: Counters), which every workgroup's atomics hit:
    // in device memory, set at the start of each submission (Context::update) and copied to
    // a host-visible mirror at its end, whence the host reads them (`counter`).
    // SDFPRUNE_VULKAN_HOST_COUNTERS=1: the kernels' atomics on the host-visible buffer itself
    // (before stop 40; system memory on NVIDIA's drivers), to compare on a GPU.
    const bool host_counters;
    Buffer& counters;
    Buffer& counters_mirror;
    GpuCounters* counter;
    Buffer& blocks;  // the current level's blocks
    Buffer& scratch;
    // A wide step's scratch beyond the first buffer's (Step::scratch_buffers), and the most
    // buffers a step may take (1 after the device had no memory for more).
    std::vector<Buffer*> more_scratch;
    uint32_t scratch_buffers_cap = 8;
    // The octants' tapes of the current level (prune.comp: OctantPool), reused level by level.
    Buffer& octant_pool;
    // Refinement's jobs: the finest near-field cells (prune_common.glsl: RefineList), listed by
    // the step that makes them; sized at the finest level.
    Buffer& refine_list;
    Buffer* parent_pool = nullptr;  // the last level's pool (binding 3); the level's own: g.pool
    uint64_t block_count = 1;
    uint64_t parent_words = 0;  // the parents' tapes, headers included
    // The share of the main pool's bound (see presize) the last level used.
    double main_ratio = 1;
    uint32_t max_len = 0;    // longest tape of the current parents
    uint32_t max_depth = 0;  // deepest evaluation stack of the current parents
    double gpu_ms = 0;
    uint32_t level_index = 0;  // the level being made (for the steps' shapes and errors)
    uint64_t presize_cap = uint64_t(64) << 20;
    // At most the room made for the cells from their octants' words (the device's largest
    // buffer, or SDFPRUNE_VULKAN_PRESIZE_WORDS).
    uint64_t room_cap = 0;
    int wide_override = -1;
    // plan_wide's cost of a workgroup that takes several jobs: from their mean tape (1) or as
    // if every tape were the longest (0); SDFPRUNE_VULKAN_WIDE_MEAN.
    bool wide_mean = true;
    // plan_wide's cost counts a barrier for the rounds that end at one (1), or for every round
    // (0, as before stop 50); SDFPRUNE_VULKAN_WIDE_CHAINS.
    bool wide_chains = true;
    // plan_wide splits a step's jobs further where its modelled cost falls (kWideSplitGain), or
    // only by their count and scratch (0, as before); SDFPRUNE_VULKAN_WIDE_SPLIT_BY_COST.
    bool wide_split_by_cost = true;
    // prune_wide.comp sweeps a long run by a scan over its rounds (1) or round by round (0);
    // SDFPRUNE_VULKAN_WIDE_SCAN.
    bool wide_scan = true;
    uint32_t wide_split = 0;  // SDFPRUNE_VULKAN_WIDE_SPLIT (1, 2, 4 or 8); 0: plan_wide's choice
    int wide_runs_override =
        -1;  // SDFPRUNE_VULKAN_WIDE_RUNS=0|1: prune_wide_runs.comp never, always
    // The longest tape refinement's lane pass takes (prune_refine_lanes.comp), chosen per slice
    // (choose_lane_tape): kRefineLaneTape, or up to kLaneTapeMax where the squads would take
    // the longer tapes in more than one round. SDFPRUNE_VULKAN_REFINE_LANE_TAPE fixes it.
    uint32_t refine_lane_tape = kLaneTapeMax;
    bool lane_tape_fixed = false;
    uint32_t lane_tape = 0;  // the current slice's (choose_lane_tape)
    // The lane pass walks every cell's first sub-boxes, then the others of the cells that need
    // them in a second pass; SDFPRUNE_VULKAN_REFINE_SECOND_PASS=0: all of them in one pass.
    bool refine_second_pass = true;
    // The second pass's list is sorted by walk class as the cells are listed (refine_lanes.glsl:
    // more_place); SDFPRUNE_VULKAN_REFINE_SORTED_MORE=0: in the order listed (kStepMoreAsListed),
    // as before stop 48.
    bool refine_sorted_more = true;
    // The lane pass takes its cells longest tapes first, in an order pass before it;
    // SDFPRUNE_VULKAN_REFINE_ORDER=0: in the order they were listed.
    bool refine_order = true;
    // Where the jobs' tapes sum to less than the longest per team or workgroup, each job claims
    // scratch for its own tape (prune_team.glsl: claim_entries; prune_wide.glsl:
    // claim_items); SDFPRUNE_VULKAN_CLAIMS=0: every team or workgroup holds room for the
    // longest.
    bool claims = true;
    // The team steps keep their flags a byte a lane (prune_bytes.comp) where the device has
    // 8-bit storage; SDFPRUNE_VULKAN_BYTE_FLAGS=0: a word a lane (prune.comp), to compare.
    bool byte_flags = true;
    // The octants' and cells' team jobs take their parents (blocks, octants) longest tapes
    // first, after an order pass that sorts each window of 256 parents (1), dealt out in a
    // snake; SDFPRUNE_VULKAN_TEAM_ORDER=2: two passes that sort the whole step (a shorter
    // critical path on a GPU, by tools/prune_order_model.cpp, but 9 % slower on lavapipe),
    // 0: block by block (none measured on a GPU yet: BENCHMARKS.md, stops 39 and 45).
    uint32_t team_order = 1;
    // The ordered jobs of the team steps and of refinement's lane pass are dealt out in a snake
    // (prune_common.glsl: snake_deal); SDFPRUNE_VULKAN_SNAKE=0: in rounds (kStepDealInRounds), as
    // before stop 45, to compare.
    bool snake = true;
    // The team steps' workgroups take their jobs as they come free, from a counter
    // (prune_team.glsl: take_jobs; kStepTakeJobs), the order list's longest first: a shorter
    // critical path on an H100 than the snake's, by tools/prune_order_model.cpp (not measured
    // on a GPU yet); SDFPRUNE_VULKAN_TAKE=0: dealt out in advance, as before stop 46.
    bool take_jobs = true;
    // The wide steps' workgroups take their jobs' parts as they come free, likewise
    // (prune_wide.glsl: take_part): a shorter critical path on an H100 by
    // tools/prune_order_model.cpp (the generated fluid's level-2 octants 1,824 -> 1,308 words;
    // not measured on a GPU yet); SDFPRUNE_VULKAN_WIDE_TAKE=0: dealt in advance, as before
    // stop 50.
    bool wide_take = true;
    // A lane's sweep of a parent tape (compact_tape) ends once it has reached every entry it
    // kept, and its write starts at the last one (prune_team.glsl, refine_common.glsl:
    // refine_write); SDFPRUNE_VULKAN_SWEEP_END=0: both pass over the whole tape (push flag
    // 16384), as before stop 47, to compare.
    bool sweeps_end = true;
    vec3 origin, extent;
    float L = 1;
    uint32_t flags = 0;  // the push constants' (prune_common.glsl)
    std::vector<Buffer*> level_cells;
    std::vector<uint64_t> level_totals;  // each level's cells
    uint64_t cell_total = 0;             // of all levels
};

}  // namespace sdfprune::gpu::pruning
