// gpu_prune.cpp — hierarchical pruning on the device (gpu.hpp): the host walks the levels as
// src/prune/prune.cpp does. A level's steps (prune.comp: the octants, the cells; then
// prune_refine.comp: the finest cells' refinement) each run over all their jobs in teams of
// lanes that share a parent tape (in refinement, a squad of lanes per cell, a lane per
// sub-box), then expand.comp makes the next level's blocks. Steps with few
// jobs and long parent tapes (the top levels) run prune_wide.comp instead: a workgroup per
// parent tape. Each level's tapes go to a pool of their own; before each run (the octants, the
// cells, the refinement) a pool is made room for what its parents' tapes bound, and one that
// overflows all the same grows and the run is redone. Statistics are read back at the end.
//
// Reading order: Pruner::run (the levels), prune_level (a level: its pools and buffers),
// prune_slices (its blocks, a slice at a time, and the steps of a slice), run_steps (one
// submission), plan_step / plan_wide / plan_refine (a step's shape: teams, wide or squads) and
// record_step (its dispatches).
#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <optional>

#include "device_grid.hpp"

namespace sdfprune::gpu {
DeviceGrid::~DeviceGrid() {
    for (Buffer* b : {&nodes, &params, &extras, &pool, &cells, &levels}) ctx.destroy(*b);
}

GpuGridParams DeviceGrid::grid_params() const {
    const Aabb& box = scene->aabb;
    const GpuLevel& finest = level_info.back();
    const vec3 cs = (box.max - box.min) / float(finest.res);
    const float L = scene->lipschitz[scene->root()];
    GpuGridParams g;
    g.aabb_min = vec4(box.min.x, box.min.y, box.min.z, L);
    g.aabb_max = vec4(box.max.x, box.max.y, box.max.z, 1.0f / L);
    g.cell_size = vec4(cs.x, cs.y, cs.z, float(finest.res));
    g.inv_cell = vec4(1.0f / cs.x, 1.0f / cs.y, 1.0f / cs.z, float(level_info.size()));
    return g;
}

namespace {

// Which steps run wide (prune_wide.comp): those with parent tapes of kWideMinTape words or
// more where the modelled cost is less than twice a team's longest walk. The cost is the wide
// walk with every round (a height of the tape, a workgroup barrier and a chain of global loads)
// counted kWideRoundCost times. Both constants fit the per-step GPU times measured on an NVIDIA
// H200 (stop 23: 18 steps of six scenes at levels 2 and 3, where the two kernels were timed
// against each other): a team's word costs up to twice a wide lane's, its scratch per lane
// being larger, and a round costs about four words. Any number of team jobs may run wide (a
// workgroup each, in a grid-stride loop): the generated fluid's level-2 octants, 3,518 team
// jobs, take 3.0 ms wide against 12.5 ms in teams. SDFPRUNE_VULKAN_WIDE=0 never, =1 wherever
// the kernel fits (for tests).
constexpr uint64_t kWideMinTape = 128, kWideRoundCost = 4;
constexpr uint64_t kWideSplitGroups = 64;  // plan_wide
// Wide steps of at most kWideRunsJobs jobs over tapes of kWideRunsRounds heights or more run
// prune_wide_runs.comp (long runs walked from shared memory): on an H200 molecule's four top
// steps went from 3.18 to 2.14 ms, but its staging arrays slowed the steps of many jobs and
// short runs that shared the kernel (monument's level-2 cells 1.24 -> 1.97 ms; stop 28).
constexpr uint64_t kWideRunsJobs = 512, kWideRunsRounds = 64;

uint64_t ceil_div(uint64_t a, uint64_t b) {
    return (a + b - 1) / b;
}

// A step of a level (prune.comp): `jobs` cells or octants from their parents' tapes into
// `octants`/`cells`, run as team jobs that each walk one parent tape with kPruneTeam lanes,
// sized by the parents' longest tape and deepest stack (a child's tape is never longer or
// deeper than its parent's); or wide (prune_wide.comp), a workgroup a team job.
struct Step {
    PrunePush push;
    const Buffer *octants, *cells;
    // Its team jobs are [first_team_job, first_team_job + team_jobs): those of a slice of the
    // level's blocks (refinement: of its list, from 0; its slice's cells start at first_cell).
    uint64_t first_team_job, team_jobs, teams, rounds, per_dispatch, first_cell = 0;
    uint64_t job_walk;         // in teams, the tape words a lane reads per job, at most
    uint32_t threads, groups;  // lanes that take jobs, and their workgroups
    bool wide;
    KernelId kernel = KernelId::kPrune;  // (wide steps: record_step's choice)
    // Refinement's lane pass (prune_refine_lanes.comp), or the squads after it that take the
    // cells it listed (`listed`: its jobs are the long list's entries).
    bool lane_pass = false, listed = false;
    bool wide_runs = false;  // wide, on prune_wide_runs.comp (plan_wide)
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
    Buffer *cells = nullptr, *octants = nullptr, *refined = nullptr, *next = nullptr;
    size_t first_shape = 0;     // the level's steps' shapes in the statistics
    uint32_t listed_cells = 0;  // refinement's list, from the run that made the cells
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
    Step plan_refine_lanes(const Step& squads) const;
    void plan_squads(const Level& lv, Step& s);
    PrunePush push_for(const Level& lv, uint32_t mode, uint32_t threads, uint32_t step_flags,
                       uint32_t budget) const;
    void plan_wide(Step& s, uint64_t& scratch_bytes);
    void record_step(Step& s);
    void resize(Buffer& pool, uint64_t& cap, uint64_t words, uint64_t keep);
    void grow(Buffer& pool, uint64_t& cap, uint64_t need, uint64_t keep);
    void presize(Buffer& pool, uint64_t& cap, uint64_t used, uint64_t bound);
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
    std::vector<uint32_t> head;                        // the full tape with its header
    uint32_t scene_height = 0;                         // the root's height (prune_wide.comp)
    uint64_t capacity = 0, octant_capacity = 1 << 16;  // of g.pool and octant_pool, in words
    Buffer& node_spans;
    Buffer& counters;
    GpuCounters* counter;
    Buffer& blocks;  // the current level's blocks
    Buffer& scratch;
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
    uint32_t wide_split = 0;  // SDFPRUNE_VULKAN_WIDE_SPLIT (1, 2, 4 or 8); 0: plan_wide's choice
    int wide_runs_override =
        -1;  // SDFPRUNE_VULKAN_WIDE_RUNS=0|1: prune_wide_runs.comp never, always
    // The longest tape refinement's lane pass takes (prune_refine_lanes.comp);
    // SDFPRUNE_VULKAN_REFINE_LANE_TAPE.
    uint32_t refine_lane_tape = kRefineLaneTape;
    vec3 origin, extent;
    float L = 1;
    uint32_t flags = 0;  // the push constants' (prune_common.glsl)
    std::vector<Buffer*> level_cells;
    uint64_t cell_total = 0;  // of all levels
};

Pruner::Pruner(Device& device, const Scene& scene, const PruneOptions& options, DeviceGrid& grid)
    : ctx(device.context()),
      sc(scene),
      opt(options),
      g(grid),
      st(grid.stats),
      res(grid_levels(options.resolution, options.factor, options.hierarchy)),
      local(ctx),
      max_pool_words(std::min<uint64_t>(ctx.max_buffer_bytes() / 4, 0xfffffff0u)),
      node_spans(local.slot()),
      counters(local.create(sizeof(GpuCounters), true)),
      counter(static_cast<GpuCounters*>(counters.mapped)),
      blocks(local.create(sizeof(GpuBlock))),
      scratch(local.slot()),
      octant_pool(local.create(octant_capacity * 4)),
      refine_list(local.create(16)) {
    // The scene.
    std::vector<GpuNode> nodes(sc.size());
    for (uint32_t n = 0; n < sc.size(); ++n)
        nodes[n] = {sc.kind[n], sc.is_primitive(n) ? sc.primitive[n] : 0u, sc.blend[n],
                    sc.lipschitz[n]};
    std::vector<GpuPrimitiveExtra> extras(sc.primitive_count());
    for (uint32_t p = 0; p < sc.primitive_count(); ++p) {
        const PrimitiveBound& b = sc.bound[p];
        extras[p] = {vec4(b.centre.x, b.centre.y, b.centre.z, b.scale), vec4(b.f0, b.rho, 0, 0),
                     vec4(sc.color[p].x, sc.color[p].y, sc.color[p].z, 1)};
    }
    const auto upload_vector = [&](const auto& v) {
        const uint64_t bytes = v.size() * sizeof(v[0]);
        Buffer b = ctx.create_buffer(bytes);
        ctx.upload(b, v.data(), bytes);
        return b;
    };
    g.nodes = upload_vector(nodes);
    g.params = upload_vector(sc.params);
    g.extras = upload_vector(extras);
    // For prune_wide.comp: per node the first node of its subtree and its height (post-order:
    // operands first, so one pass), and the highest, the root's.
    std::vector<uint32_t> spans(2 * uint64_t(sc.size()));
    for (uint32_t n = 0; n < sc.size(); ++n) {
        const bool prim = sc.is_primitive(n);
        spans[2 * n] = prim ? n : spans[2 * sc.left[n]];
        spans[2 * n + 1] =
            prim ? 0 : 1 + std::max(spans[2 * sc.left[n] + 1], spans[2 * sc.right[n] + 1]);
    }
    scene_height = spans[2 * sc.root() + 1];
    node_spans = ctx.create_buffer(spans.size() * 4);
    ctx.upload(node_spans, spans.data(), spans.size() * 4);

    // Each level's tapes go to a pool of its own (g.pool while the level is made; it grows on
    // overflow), read as the parents' by the next level and then freed: a level never holds
    // its grandparents' tapes (the million-sphere fluid's coarse levels alone outgrew one 4 GiB
    // buffer). Tracing reads only the finest cells' tapes. The first parents' pool holds the
    // full tape.
    head = {sc.size(), sc.primitive_count()};
    head.insert(head.end(), sc.full_tape.begin(), sc.full_tape.end());
    if (head.size() > max_pool_words)
        throw GpuError("scene too large for the device's largest storage buffer");
    capacity = head.size();
    g.pool = ctx.create_buffer(capacity * 4);
    ctx.upload(g.pool, head.data(), head.size() * 4);
    g.pool_words = uint32_t(head.size());
    parent_words = head.size();

    const GpuBlock root_block{0, 0, 0, 0};
    ctx.upload(blocks, &root_block, sizeof(root_block));
    max_len = sc.size();
    max_depth = sc.max_stack;
    // Before a level: room for what its parents' tapes can give, within 64 Mi words more than
    // in use (presize). SDFPRUNE_VULKAN_PRESIZE_WORDS=N sets the cap (0: pools only grow on
    // overflow, for tests).
    room_cap = max_pool_words;
    if (const char* env = std::getenv("SDFPRUNE_VULKAN_PRESIZE_WORDS"))
        room_cap = presize_cap = std::strtoull(env, nullptr, 10);
    if (const char* env = std::getenv("SDFPRUNE_VULKAN_WIDE"); env && *env)
        wide_override = std::atoi(env) != 0;
    if (const char* env = std::getenv("SDFPRUNE_VULKAN_WIDE_RUNS"); env && *env)
        wide_runs_override = std::atoi(env) != 0;
    if (const char* env = std::getenv("SDFPRUNE_VULKAN_WIDE_SPLIT"); env && *env) {
        const unsigned long split = std::strtoul(env, nullptr, 10);
        if (split > 0 && split <= kPruneTeam && (split & (split - 1)) == 0)
            wide_split = uint32_t(split);
    }
    // The longest tape refinement's lane pass takes, at most its arrays' (0: no lane pass,
    // squads for every cell; for tests and measurements).
    if (const char* env = std::getenv("SDFPRUNE_VULKAN_REFINE_LANE_TAPE"); env && *env)
        refine_lane_tape =
            std::min<uint32_t>(uint32_t(std::strtoul(env, nullptr, 10)), kLaneTapeMax);
    origin = sc.aabb.min;
    extent = sc.aabb.max - sc.aabb.min;
    L = sc.lipschitz[sc.root()];
    flags = (opt.far_field ? 1u : 0u) | (opt.bounds == CellBounds::kInterval ? 2u : 0u);
}

void Pruner::run() {
    // (set from the finest level's final cells; the scene's box on a one-level grid: as
    // PrunedGrid::near_box)
    g.near_box = res.size() < 2 ? sc.aabb : Aabb{sc.aabb.max, sc.aabb.min};
    for (uint32_t li = 0; li < res.size(); ++li) prune_level(li);
    ctx.destroy(blocks);
    ctx.destroy(scratch);
    ctx.destroy(octant_pool);
    ctx.destroy(refine_list);
    g.finest_stack_depth = max_depth;  // the last level's: the finest cells' (refined)
    gather_cells();
}

// One level: its pool (the parents' freed after it), its cells (and octants, refined cells,
// next blocks), its blocks' steps (prune_slices), and what the next level starts from.
void Pruner::prune_level(uint32_t li) {
    level_index = li;
    Level lv;
    lv.index = li;
    lv.finest = li + 1 == res.size();
    lv.refine = lv.finest && opt.refine > 1;
    lv.f = li == 0 ? res[0] : res[li] / res[li - 1];
    lv.per_block = uint64_t(lv.f) * lv.f * lv.f;
    lv.total = lv.per_block * block_count;
    if (lv.total > 0xfffffffeull) throw std::length_error("too many cells in one level");
    lv.csize = extent / float(res[li]);
    // The same split as the CPU backend (prune.cpp): octants first where it applies.
    lv.split = opt.hierarchy && lv.f >= 4 && lv.f % 2 == 0 && 1024 % lv.per_block == 0;
    lv.nf = lv.finest ? 0 : res[li + 1] / res[li];
    // Every cell's tape (with its header) is at most its parent's: the octants' go to the
    // octant pool, the cells' to the main pool (or first to the octant pool, refined into the
    // main pool). Sized for twice the share of that bound the last level used (finer levels
    // tend to use less of it, more of their cells being far-field; with 1.25 times, the
    // generated fluid's finest level overflowed and was redone).
    const uint64_t main_bound = lv.per_block * parent_words;
    const uint64_t octant_bound = lv.split ? 8 * parent_words : 0;
    const auto share = [](uint64_t bound, double ratio) {
        return uint64_t(std::ceil(double(bound) * std::min(1.0, 2 * ratio)));
    };
    // The parents' pool, freed after the level, and the level's own.
    Buffer& parents = local.slot();
    parents = g.pool;
    g.pool = Buffer{};
    parent_pool = &parents;
    capacity = 0;
    g.pool_words = 0;
    // The finest level's pool starts with the full tape: the tracing kernels' full-tree pass
    // reads it there (scene.glsl: kFullTreeTape).
    const uint64_t head_words = lv.finest ? head.size() : 0;
    resize(g.pool, capacity,
           head_words +
               std::max<uint64_t>(std::min(share(main_bound, main_ratio), presize_cap), 1 << 16),
           0);
    if (lv.finest) {
        ctx.upload(g.pool, head.data(), head_words * 4);
        g.pool_words = uint32_t(head_words);
    }
    // Split, the octants run first and their pool is made room for their bound (each octant's
    // tape no longer than its block's), the cells' room made after them (prune_slices);
    // otherwise the transient cells' share too.
    if (lv.split) {
        const uint64_t want = std::min(octant_bound, room_cap);
        if (want > octant_capacity) resize(octant_pool, octant_capacity, want, 0);
    } else {
        presize(octant_pool, octant_capacity, 0, lv.refine ? share(main_bound, main_ratio) : 0);
    }
    // The level's cells, made after the pools grew (a pool's old and new buffers, held at once
    // while its words are copied, are not held beside them).
    lv.cells = &local.create(lv.total * sizeof(PrunedCell));
    lv.octants = &local.create(lv.split ? block_count * 8 * sizeof(PrunedCell) : 16);
    lv.refined = &local.create(lv.refine ? lv.total * sizeof(PrunedCell) : 16);
    lv.next = &local.create(lv.finest ? 16 : lv.total * sizeof(GpuBlock));
    // Room to list every finest cell for refinement.
    if (lv.refine && refine_list.size < lv.total * 4) {
        ctx.destroy(refine_list);
        refine_list = ctx.create_buffer(lv.total * 4);
    }
    lv.first_shape = st.steps.size();

    const GpuCounters c = prune_slices(lv);

    // (A level that wrote nothing, its cells all far-field, says nothing.)
    if (g.pool_words > head_words)
        main_ratio = double(g.pool_words - head_words) / double(main_bound);
    ctx.destroy(*lv.octants);
    ctx.destroy(parents);
    parent_pool = nullptr;
    if (lv.refine) {
        ctx.destroy(*lv.cells);
        *lv.cells = *lv.refined;
        *lv.refined = Buffer{};
    }
    max_len = std::max(c.max_len, 1u);
    max_depth = std::max(c.max_depth, 1u);
    if (!lv.finest) {
        ctx.destroy(blocks);
        blocks = *lv.next;
        *lv.next = Buffer{};
        block_count = c.near_jobs;
        parent_words = c.near_words;
    }
    g.level_info.push_back({res[li], lv.f, 0, 0});
    level_cells.push_back(lv.cells);
}

// The level's blocks in slices, each in its own submissions with the octant pool emptied
// between them: one slice of all blocks, unless the octants' and (refining) the unrefined
// cells' tapes would not fit the device's largest buffer at once (a million spheres' finest
// level); then half as many blocks at a time, and so on. A slice's steps take its blocks'
// jobs; the next level's blocks are made after the last. Per slice, a submission for the
// octants, whose longest tape sizes the cells' teams and whose words bound the cells' pool, one
// for the cells (or the blocks' cells, where the level is not split), and one for refinement.
// Gives the level's counters: near cells and words summed, longest tapes the longest.
GpuCounters Pruner::prune_slices(Level& lv) {
    const uint32_t parent_len = max_len, parent_depth = max_depth;
    GpuCounters c{};
    uint64_t slice_blocks = std::max<uint64_t>(block_count, 1);
    for (uint64_t b0 = 0;;) {
        const uint64_t b1 = std::min(block_count, b0 + slice_blocks), blocks_in = b1 - b0;
        const bool last = b1 == block_count;
        max_len = parent_len;
        max_depth = parent_depth;
        std::vector<Step> steps;
        uint64_t octant_keep = 0;
        std::optional<GpuCounters> sc;
        if (lv.split) {
            // The octants first: their longest tape sizes the cells' teams, and their tapes'
            // words (near_words, shared tapes too) bound the cells' (each no longer than its
            // octant's), so the cells' pool is made room for them before they run: a level is
            // not redone for want of room (generated car-chase and city at 256³ with
            // --lipschitz-bounds were, their finest pool sized by the last level's share),
            // unless the bound passes the device's largest buffer.
            steps = plan_step(lv, 1, b0, blocks_in, blocks_in * 8, *lv.octants, *lv.cells, false);
            sc = run_steps(lv, steps, false, 0, blocks_in > 1);
            if (!sc) {
                slice_blocks = blocks_in / 2;
                continue;
            }
            octant_keep = sc->octant_used;
            max_len = std::max(std::min(sc->max_len, max_len), 1u);
            max_depth = std::max(std::min(sc->max_depth, max_depth), 1u);
            const uint64_t hf = lv.f / 2;
            const uint64_t cells_bound = std::min(hf * hf * hf * sc->near_words, room_cap);
            if (lv.refine) {
                if (octant_keep + cells_bound > octant_capacity)
                    resize(octant_pool, octant_capacity, octant_keep + cells_bound, octant_keep);
            } else if (g.pool_words + cells_bound > capacity) {
                resize(g.pool, capacity, g.pool_words + cells_bound, g.pool_words);
            }
            steps = plan_step(lv, 2, b0, blocks_in, blocks_in * lv.per_block, *lv.octants,
                              *lv.cells, lv.refine);
        } else {
            steps = plan_step(lv, 0, b0, blocks_in, blocks_in * lv.per_block, *lv.cells, *lv.cells,
                              lv.refine);
        }
        lv.listed_cells = 0;
        // (the finest level's final cells, after its last slice: bounded, for near_box; on a
        // one-level grid near_box is the scene's box)
        const bool bound = lv.finest && last && res.size() > 1;
        sc = run_steps(lv, steps, !lv.finest && last, octant_keep, blocks_in > 1,
                       bound && !lv.refine ? lv.cells : nullptr);
        if (!sc) {
            slice_blocks = blocks_in / 2;
            continue;
        }
        if (lv.refine) {
            // The finest cells decided again over their sub-boxes (refine_cell), into a new
            // cell array, in a run of its own: a refined tape is never longer than its cell's,
            // so the level's pool is first made room for as many words as the cells' tapes
            // have (near_words: shared tapes too), and refinement (the level's costliest step)
            // is never redone for want of it. The cells' longest tape and deepest stack size
            // its teams.
            lv.listed_cells = sc->refine_cells;
            const uint64_t room = uint64_t(g.pool_words) + sc->near_words;
            if (room > capacity) resize(g.pool, capacity, room, g.pool_words);
            max_len = std::max(sc->max_len, 1u);
            max_depth = std::max(sc->max_depth, 1u);
            std::vector<Step> refinement = plan_step(lv, 3, b0, blocks_in, blocks_in * lv.per_block,
                                                     *lv.refined, *lv.cells, false);
            const GpuCounters rc = *run_steps(lv, refinement, false, sc->octant_used, false,
                                              bound ? lv.refined : nullptr);
            sc->max_depth = rc.max_depth;
        }
        c.near_jobs += sc->near_jobs;
        c.near_words += sc->near_words;
        c.max_len = std::max(c.max_len, sc->max_len);
        c.max_depth = std::max(c.max_depth, sc->max_depth);
        ++st.slices;
        if (last) break;
        b0 = b1;
    }
    return c;
}

// Runs `steps` (and expand.comp when `expand`) in one submission, the octant pool holding
// `octant_keep` words from before; grows a pool and runs them again while one overflows. Gives
// nothing where the octant pool would have to outgrow the device's largest buffer and
// `may_slice`: the caller then takes fewer blocks at a time.
std::optional<GpuCounters> Pruner::run_steps(Level& lv, std::vector<Step>& steps, bool expand,
                                             uint64_t octant_keep, bool may_slice, Buffer* bound) {
    for (;;) {
        GpuCounters start{};
        start.pool_used = g.pool_words;
        start.pool_capacity = uint32_t(capacity);
        start.octant_used = uint32_t(octant_keep);
        start.octant_capacity = uint32_t(octant_capacity);
        start.refine_cells = lv.listed_cells;
        for (int a = 0; a < 3; ++a) {
            start.near_lo[a] = std::numeric_limits<uint32_t>::max();
            start.near_hi[a] = 0;
        }
        *counter = start;
        ctx.begin();
        for (Step& s : steps) {
            // The longest tape and deepest stack read back: the cells' (the next parents'),
            // not the octants'; and after refinement, the refined cells' deepest stack (what
            // the tracing kernels' stacks are sized by; every near-field cell's refinement adds
            // its tape's depth).
            if (s.push.mode == 2 && !s.listed) {
                ctx.fill(counters, 0, offsetof(GpuCounters, max_len), 4);
                ctx.fill(counters, 0, offsetof(GpuCounters, max_depth), 4);
            }
            if (s.push.mode == 3 && !s.listed) {
                ctx.fill(counters, 0, offsetof(GpuCounters, max_depth), 4);
                // The far-field cells refined as they are: the slice's cells copied, the near
                // ones (listed by the step before) then refined over them.
                if (s.team_jobs > 0)
                    ctx.copy(*s.cells, *s.octants, s.team_jobs * sizeof(PrunedCell),
                             s.first_cell * sizeof(PrunedCell), s.first_cell * sizeof(PrunedCell));
            }
            record_step(s);
        }
        if (expand) {
            const ExpandPush push{lv.f, uint32_t(lv.total), lv.nf, 0};
            ctx.dispatch(KernelId::kExpand, {&blocks, lv.cells, lv.next, &counters}, &push,
                         sizeof(push), ctx.groups_for(lv.total));
        }
        if (bound) {
            const ExpandPush push{lv.f, uint32_t(lv.total), 0, 1};
            ctx.dispatch(KernelId::kExpand, {&blocks, bound, lv.next, &counters}, &push,
                         sizeof(push), ctx.groups_for(lv.total));
        }
        gpu_ms += ctx.submit();
        ++st.submissions;
        if (!counter->overflow) break;
        // Grow the pool that overflowed (keeping what the steps started with) and run them
        // again. A counter that wrapped past 2^32 words (it reads less than the capacity) asks
        // for the most the device allows.
        const bool main_over = (counter->overflow & 1u) != 0,
                   octant_over = (counter->overflow & 2u) != 0;
        const auto need = [](uint32_t used, uint64_t cap) {
            return used > cap ? uint64_t(used) : std::numeric_limits<uint64_t>::max();
        };
        if (octant_over && may_slice &&
            need(counter->octant_used, octant_capacity) > max_pool_words)
            return std::nullopt;
        if (main_over) grow(g.pool, capacity, need(counter->pool_used, capacity), g.pool_words);
        if (octant_over)
            grow(octant_pool, octant_capacity, need(counter->octant_used, octant_capacity),
                 octant_keep);
    }
    g.pool_words = counter->pool_used;
    // The finest level's near-field cells' bounds: PrunedGrid::near_box.
    if (bound)
        g.near_box = finest_cells_box(sc.aabb, extent / float(res.back()), res.back(),
                                      counter->near_lo, counter->near_hi);
    for (Step& s : steps) {
        // Jobs counted on the device: refinement's, the listed cells, and the long list's, the
        // jobs a lane pass left (their dispatches were recorded for all, those past the list's
        // end returning at once).
        const bool refine_jobs = s.push.mode == 3 && !s.listed;
        if (refine_jobs || s.listed) {
            const uint64_t jobs = s.listed ? counter->long_jobs : counter->refine_cells;
            if (refine_jobs) s.shape.jobs = jobs;
            s.shape.lanes = std::min(jobs, s.teams) * s.shape.lanes_per_tape;
            s.shape.longest_walk_words = ceil_div(jobs, s.teams) * s.job_walk;
        }
        s.shape.gpu_ms = ctx.stamp_ms(s.last_stamp) - ctx.stamp_ms(s.first_stamp);
        if (s.lane_pass) {
            s.shape.long_jobs = counter->long_jobs;
            s.shape.lanes_ms = s.shape.gpu_ms;
        }
        add_shape(lv, s.shape);
    }
    return *counter;
}

// A step's shape into the statistics; a step of an earlier slice of the level makes one
// shape with it.
void Pruner::add_shape(const Level& lv, const GpuStepShape& shape) {
    const auto same = std::find_if(st.steps.begin() + lv.first_shape, st.steps.end(),
                                   [&](const GpuStepShape& o) { return o.mode == shape.mode; });
    if (same == st.steps.end()) {
        st.steps.push_back(shape);
        return;
    }
    same->wide = same->wide || shape.wide;
    same->dispatches += shape.dispatches;
    same->workgroups += shape.workgroups;
    same->jobs += shape.jobs;
    same->lanes = std::max(same->lanes, shape.lanes);
    same->lanes_per_tape = std::max(same->lanes_per_tape, shape.lanes_per_tape);
    same->longest_walk_words += shape.longest_walk_words;  // one slice or pass after another
    same->gpu_ms += shape.gpu_ms;
    same->lanes_ms += shape.lanes_ms;
    same->long_jobs += shape.long_jobs;
}

// A step over the blocks [first_block, first_block + blocks), `jobs` cells or octants (or in
// refinement, mode 3, cells), `transient`: new tapes go to the octant pool (the finest cells'
// tapes before refinement): in teams (or wide). Refinement runs first a lane per cell
// (plan_refine_lanes), then, unless the cells' longest tape is short enough for the lanes, the
// squads over the cells the lanes listed (the long list, in scratch); without a lane pass
// (its setting 0, or no room for the list), squads alone.
std::vector<Step> Pruner::plan_step(const Level& lv, uint32_t mode, uint64_t first_block,
                                    uint64_t blocks, uint64_t jobs, const Buffer& octants,
                                    const Buffer& cells, bool transient) {
    Step teams = plan_teams(lv, mode, first_block, blocks, jobs, octants, cells, transient);
    if (mode != 3 || refine_lane_tape == 0 || 4 * teams.team_jobs > ctx.max_buffer_bytes())
        return {teams};
    Step lanes = plan_refine_lanes(teams);
    if (scratch.size < 4 * teams.team_jobs) {
        ctx.destroy(scratch);
        scratch = ctx.create_buffer(4 * teams.team_jobs);
    }
    if (max_len <= refine_lane_tape) return {lanes};
    teams.listed = true;
    teams.push.flags |= 8u;
    teams.shape.jobs = 0;  // the lanes' (one shape, add_shape)
    return {lanes, teams};
}

// A step's jobs in teams (or wide, plan_wide), or in refinement squads (plan_squads).
Step Pruner::plan_teams(const Level& lv, uint32_t mode, uint64_t first_block, uint64_t blocks,
                        uint64_t jobs, const Buffer& octants, const Buffer& cells, bool transient) {
    const uint64_t hf = lv.f / 2;
    const auto teams_for = [](uint64_t boxes) { return ceil_div(boxes, kPruneTeam); };
    Step s;
    s.octants = &octants;
    s.cells = &cells;
    // Team jobs run block by block in every mode (prune_common.glsl: job_box).
    const uint64_t per_block_jobs = mode == 0   ? teams_for(lv.per_block)
                                    : mode == 1 ? 1
                                    : mode == 2 ? 8 * teams_for(hf * hf * hf)
                                                : lv.per_block;
    s.first_team_job = first_block * per_block_jobs;
    s.team_jobs = blocks * per_block_jobs;
    if (mode == 3) {
        // Refinement takes the slice's listed near cells (a list a run, from 0).
        s.first_cell = s.first_team_job;
        s.first_team_job = 0;
    }
    if (s.first_team_job + s.team_jobs > 0xfffffffeull)
        throw std::length_error("too many cells in one level");
    if (mode == 3) {
        plan_squads(lv, s);
        return s;
    }
    // A team's scratch: its lanes' state, per parent-tape entry a left operand and a word per
    // lane (decision and sweep flags), per stack slot and lane 4 words.
    const uint64_t team_bytes =
        (kPruneStateWords * kPruneTeam + uint64_t(max_len) * (1 + kPruneTeam) +
         4ull * max_depth * kPruneTeam) *
        4;
    // Teams in flight: as many as have jobs, their scratch fits the budget and the device runs
    // at once (more would only queue, their scratch held for nothing; the teams take the jobs
    // in a grid-stride loop). Only teams with jobs hold scratch, so one parent tape as long as
    // the budget allows can be pruned (the root's, the full tree, at level 0) even where a
    // workgroup's 8 teams could not.
    const uint64_t fit = ctx.prune_scratch_budget_bytes() / team_bytes;
    if (fit == 0)
        throw GpuError("Vulkan: pruning a tape of " + std::to_string(max_len) + " words needs " +
                       std::to_string(team_bytes) +
                       " bytes of scratch, more than the device's buffers allow; use "
                       "--backend cpu");
    const uint64_t unlimited =
        std::min({std::max<uint64_t>(s.team_jobs, 1),
                  uint64_t(ctx.max_workgroups()) * (kWorkgroupSize / kPruneTeam),
                  std::max<uint64_t>(ctx.resident_threads() / kPruneTeam, 1)});
    s.teams = std::min(unlimited, fit);
    s.threads = uint32_t(s.teams * kPruneTeam);
    s.groups = uint32_t(ceil_div(s.threads, kWorkgroupSize));
    // Steps of a job: the evaluation window by window, the sweep and the write window by
    // window (and one to spare).
    const uint64_t per_job = 3 * ceil_div(max_len, kPruneWindow) + 2;
    // Under a loop limit (lavapipe), as many jobs per team and dispatch as fit the limit, or
    // one job resumed over as many rounds as its steps need; elsewhere one unlimited round. A
    // step's loops: staging the window, evaluating it, the sweep, the write; each over at most
    // the longest tape.
    const bool limited = ctx.loop_limited();
    const uint64_t step_len = std::min<uint64_t>(max_len, kPruneWindow);
    const uint64_t step_loops = kPruneWindow / kPruneTeam + 3 * step_len + 8;
    const uint64_t max_steps = (Context::kLoopLimit - 1024) / step_loops;
    s.rounds = limited ? ceil_div(per_job, max_steps) : 1;
    const uint32_t budget = !limited ? 0xffffffffu : uint32_t(s.rounds > 1 ? max_steps : per_job);
    s.per_dispatch = limited ? s.teams * std::max<uint64_t>(1, max_steps / per_job)
                             : std::max<uint64_t>(s.team_jobs, 1);
    s.push = push_for(lv, mode, s.threads, flags | (transient ? 4u : 0u), budget);
    s.shape.level = lv.index;
    s.shape.mode = mode;
    s.shape.jobs = jobs;
    s.shape.lanes_per_tape = uint32_t(kPruneTeam);
    s.shape.lanes = std::min<uint64_t>(s.team_jobs, s.teams) * kPruneTeam;
    // A lane's walk per job: the evaluation, the sweep and the write.
    s.job_walk = 3 * max_len;
    s.shape.longest_walk_words = s.team_jobs == 0 ? 0 : ceil_div(s.team_jobs, s.teams) * s.job_walk;
    s.wide = false;
    uint64_t scratch_bytes = s.teams * team_bytes;
    if (wide_override != 0 && ctx.can_run(KernelId::kPruneWide)) plan_wide(s, scratch_bytes);
    if (scratch.size < scratch_bytes) {
        ctx.destroy(scratch);
        scratch = ctx.create_buffer(scratch_bytes);
    }
    return s;
}

// A step's push constants (prune_common.glsl: Push): the level's, the parents' longest tape and
// deepest stack; record_step sets the pools' starts and each dispatch's jobs.
PrunePush Pruner::push_for(const Level& lv, uint32_t mode, uint32_t threads, uint32_t step_flags,
                           uint32_t budget) const {
    return PrunePush{vec4(origin.x, origin.y, origin.z, L),
                     vec4(lv.csize.x, lv.csize.y, lv.csize.z, opt.far_field_c),
                     mode,
                     lv.f,
                     0,
                     threads,
                     max_len,
                     max_depth,
                     step_flags,
                     0,
                     0,
                     0,
                     budget,
                     opt.refine,
                     0,
                     0,
                     0,
                     1};
}

// Refinement's lane pass (prune_refine_lanes.comp): a lane per listed cell, as many lanes as
// the device runs at once in a grid-stride loop, each refining its cell alone where its tape
// has at most refine_lane_tape words, and listing it for the squads where not (from scratch
// word 0: the squads use no other scratch). Under a loop limit (lavapipe), as many cells per
// lane and dispatch as its loops allow: per cell, the tape staged, one walk per sub-box, the
// sweep and the write.
Step Pruner::plan_refine_lanes(const Step& squads) const {
    Step s = squads;
    const uint64_t len = std::min<uint64_t>(max_len, refine_lane_tape);
    const uint64_t subs = uint64_t(opt.refine) * opt.refine * opt.refine;
    const uint64_t walk = subs * len;
    const uint64_t per_cell = walk + 3 * len + 8;
    const uint64_t cells = s.team_jobs;
    const uint64_t lanes =
        std::min({std::max<uint64_t>(cells, 1), uint64_t(ctx.max_workgroups()) * kWorkgroupSize,
                  std::max<uint64_t>(ctx.resident_threads(), 1)});
    s.kernel = KernelId::kPruneRefineLanes;
    s.lane_pass = true;
    s.listed = false;
    s.teams = lanes;
    s.threads = uint32_t(ceil_div(lanes, kWorkgroupSize) * kWorkgroupSize);
    s.groups = uint32_t(s.threads / kWorkgroupSize);
    s.per_dispatch =
        ctx.loop_limited()
            ? s.threads * std::max<uint64_t>(1, (Context::kLoopLimit - 1024) / per_cell)
            : std::max<uint64_t>(cells, 1);
    s.push.threads = s.threads;
    s.push.list_start = 0;
    s.push.lane_tape = refine_lane_tape;
    s.job_walk = walk;
    s.shape.lanes_per_tape = 1;
    s.shape.lanes = lanes;
    s.shape.longest_walk_words = ceil_div(cells, lanes) * walk;
    return s;
}

// Refinement's squads (prune_refine.comp): a squad of kRefineSquad lanes a listed cell, its
// sub-boxes a lane each, as many squads as the device runs at once, in a grid-stride loop over
// the list. Its jobs' count is the device's (refine_cells, or after a lane pass long_jobs):
// the dispatches are recorded for all the slice's cells. A lane's loops per job: staging the
// tape, one walk per batch of kRefineSquad sub-boxes over at most kRefineMaxTape words, the
// far-field test over the squad, the sweep and the write (one lane), or a chunk of a copied
// tape and the chunks' depths.
void Pruner::plan_squads(const Level& lv, Step& s) {
    const uint64_t len = max_len, walked = std::min<uint64_t>(len, math::kRefineMaxTape);
    const uint64_t subs = uint64_t(opt.refine) * opt.refine * opt.refine;
    const uint64_t batches = ceil_div(subs, kRefineSquad);
    const uint64_t per_job =
        2 * ceil_div(len, kRefineSquad) + batches * walked + 2 * walked + 2 * kRefineSquad + 8;
    const uint64_t squads =
        std::min({std::max<uint64_t>(s.team_jobs, 1),
                  uint64_t(ctx.max_workgroups()) * (kWorkgroupSize / kRefineSquad),
                  std::max<uint64_t>(ctx.resident_threads() / kRefineSquad, 1)});
    s.kernel = KernelId::kPruneRefine;
    s.teams = squads;
    s.threads = uint32_t(squads * kRefineSquad);
    s.groups = uint32_t(ceil_div(s.threads, kWorkgroupSize));
    s.rounds = 1;
    s.per_dispatch = ctx.loop_limited()
                         ? squads * std::max<uint64_t>(1, (Context::kLoopLimit - 1024) / per_job)
                         : std::max<uint64_t>(s.team_jobs, 1);
    s.push = push_for(lv, 3, s.threads, flags, 0);
    s.job_walk = batches * walked;
    s.wide = false;
    s.shape.level = lv.index;
    s.shape.mode = 3;
    s.shape.jobs = s.team_jobs;  // until the device's count is read back
    s.shape.lanes_per_tape = uint32_t(kRefineSquad);
    s.shape.lanes = std::min<uint64_t>(s.team_jobs, squads) * kRefineSquad;
    s.shape.longest_walk_words = ceil_div(s.team_jobs, squads) * s.job_walk;
}

// The wide kernel instead of teams, where it fits and its modelled cost wins (kWideRoundCost).
// Per job the tape entries a lane takes one after another (prune_wide.comp): its share of the
// entries counted, then placed (with a binary search for an operator's left operand), in the
// evaluation and the top-down pass its share of each round's entries and kPruneTeam boxes (at
// most one more than an even share per round: a round per height the tape has, no more than
// its operators plus one), and the compaction's two passes over a slice. A run of rounds of
// one operator each (a chain) is walked by kPruneTeam lanes, a step a round as before, but
// with no barrier between its rounds, kPruneWideRunChunk rounds at a time, each chunk staged in
// shared memory by the whole workgroup first (and a search of the chunk's rounds for its
// operands' entries). Its loops add the heights cleared and summed, the rounds (and the runs
// found among them) themselves and the prefix sums' steps: a job ends in the dispatch
// that starts it, within lavapipe's loop limit; only where twice that count fits (a deep chain
// near the limit came out wrong on lavapipe: the count is taken as approximate).
void Pruner::plan_wide(Step& s, uint64_t& scratch_bytes) {
    const uint64_t len = max_len, heights = uint64_t(scene_height) + 1;
    const uint64_t rounds = std::min<uint64_t>(heights, len / 2 + 1);
    // Workgroups per job (wide_split): where a step has very few jobs (level 0: one, the root's
    // octants, then 8), a job's boxes are shared out among up to kPruneTeam workgroups, each
    // walking the tape for its share (all of them sort it), up to kWideSplitGroups workgroups
    // in all. On an H200, level 0 of the generated fluid went from 2.47 + 3.32 ms to 0.74 +
    // 1.11 ms; level 1's steps (63 and 504 jobs) ran slower split than not (stop 28).
    const uint64_t resident_groups = std::max<uint64_t>(ctx.resident_threads() / kPruneWide, 1);
    uint64_t split = 1;
    while (split < kPruneTeam && std::max<uint64_t>(s.team_jobs, 1) * split * 2 <=
                                     std::min(kWideSplitGroups, resident_groups))
        split *= 2;
    if (wide_split > 0) split = wide_split;
    const uint64_t boxes = kPruneTeam / split;
    const uint64_t walk_job = ceil_div(len, kPruneWide) * (2 + std::bit_width(len)) +
                              2 * (rounds + ceil_div(len * boxes, kPruneWide)) +
                              2 * ceil_div(len, kPruneWide / boxes);
    const uint64_t per_job = walk_job + 3 * ceil_div(heights, kPruneWide) +
                             ceil_div(rounds, kPruneWide) + 2 * rounds +
                             2 * ceil_div(rounds, kPruneWideRunChunk) * (kPruneWideRunChunk + 4) +
                             4 * std::bit_width(kPruneWide);
    const uint64_t group_bytes =
        (len * (2 + kPruneWideEntryWords * kPruneTeam) + kPruneWideHeightWords * heights) * 4;
    const uint64_t fit_groups = ctx.prune_scratch_budget_bytes() / group_bytes;
    const bool limited = ctx.loop_limited();
    if (fit_groups == 0 || (limited && 2 * per_job + 1024 > Context::kLoopLimit)) return;
    const uint64_t parts = s.team_jobs * split;
    const uint64_t unlimited_groups =
        std::min({std::max<uint64_t>(parts, 1), uint64_t(ctx.max_workgroups()), resident_groups});
    const uint64_t groups = std::min(unlimited_groups, fit_groups);
    const uint64_t group_jobs = ceil_div(parts, groups);
    const uint64_t walk = s.team_jobs == 0 ? 0 : group_jobs * walk_job;
    const uint64_t cost = walk + group_jobs * 2 * (kWideRoundCost - 1) * rounds;
    const bool pick =
        wide_override == 1 || (len >= kWideMinTape && cost < 2 * s.shape.longest_walk_words);
    if (!pick) return;
    s.wide = true;
    s.teams = groups;
    s.groups = uint32_t(groups);
    s.threads = uint32_t(groups * kPruneWide);
    s.rounds = 1;
    s.per_dispatch =
        limited
            ? std::max<uint64_t>(
                  1, groups * std::max<uint64_t>(1, (Context::kLoopLimit - 1024) / (2 * per_job)) /
                         split)
            : std::max<uint64_t>(s.team_jobs, 1);
    s.push.threads = s.threads;
    s.push.max_stack = scene_height;
    s.push.budget = 0;
    s.push.wide_split = uint32_t(split);
    s.wide_runs =
        wide_runs_override == 1 ||
        (wide_runs_override != 0 && s.team_jobs <= kWideRunsJobs && rounds >= kWideRunsRounds);
    s.shape.wide = true;
    s.shape.lanes_per_tape = uint32_t(kPruneWide * split);
    s.shape.lanes = std::min<uint64_t>(parts, groups) * kPruneWide;
    s.shape.longest_walk_words = walk;
    scratch_bytes = groups * group_bytes;
}

// Records a step's dispatches; the pools' words in use before the level start them.
void Pruner::record_step(Step& s) {
    s.first_stamp = ctx.stamp();
    PrunePush push = s.push;
    push.pool_start = g.pool_words;
    const uint64_t end = s.first_team_job + s.team_jobs;
    for (uint64_t first = s.first_team_job; first < std::max<uint64_t>(end, 1);
         first += s.per_dispatch)
        for (uint32_t round = 0; round < s.rounds; ++round) {
            push.first_job = uint32_t(first);
            push.jobs = uint32_t(std::min<uint64_t>(end, first + s.per_dispatch));
            push.round = round;
            if (s.wide)
                ctx.dispatch(
                    s.wide_runs && ctx.can_run(KernelId::kPruneWideRuns) ? KernelId::kPruneWideRuns
                    : ctx.can_run(KernelId::kPruneWideSubgroups) ? KernelId::kPruneWideSubgroups
                                                                 : KernelId::kPruneWide,
                    {&g.nodes, &g.params, &g.extras, parent_pool, &blocks, s.octants, s.cells,
                     &counters, &scratch, &octant_pool, &refine_list, &g.pool, &node_spans},
                    &push, sizeof(push), s.groups);
            else
                ctx.dispatch(
                    s.kernel,
                    {&g.nodes, &g.params, &g.extras, parent_pool, &blocks, s.octants, s.cells,
                     &counters, &scratch, &octant_pool, &refine_list, &g.pool, &scratch},
                    &push, sizeof(push), s.groups);
            ++s.shape.dispatches;
            s.shape.workgroups += s.groups;
        }
    s.last_stamp = ctx.stamp();
}

// Replaces `pool` by one of `words` words (at most the device's limit), keeping its first
// `keep` words (with none to keep, the old one goes first: the two are never held at once).
void Pruner::resize(Buffer& pool, uint64_t& cap, uint64_t words, uint64_t keep) {
    const uint64_t grown = std::min(words, max_pool_words);
    if (keep == 0) ctx.destroy(pool);
    Buffer& bigger = local.create(grown * 4);
    if (keep > 0) {
        ctx.begin();
        ctx.copy(pool, bigger, keep * 4);
        ctx.submit();
    }
    ctx.destroy(pool);
    pool = bigger;
    bigger = Buffer{};
    cap = grown;
}

// After an overflow: at least `need` words, at least twice as many as before.
void Pruner::grow(Buffer& pool, uint64_t& cap, uint64_t need, uint64_t keep) {
    if (cap >= max_pool_words)
        throw GpuError(std::string(&pool == &g.pool ? "the tape pool" : "the octant pool") +
                       " of level " + std::to_string(level_index) + " needs " +
                       (need == std::numeric_limits<uint64_t>::max() ? std::string("over 4 Gi")
                                                                     : std::to_string(need)) +
                       " words (" + std::to_string(keep) +
                       " in use before it), more than the device's largest storage buffer "
                       "holds (" +
                       std::to_string(ctx.max_buffer_bytes()) + " bytes); use --backend cpu");
    resize(pool, cap, std::max(cap * 2, need + need / 4), keep);
    ++st.pool_grows;
}

// Before a level: room for what its parents' tapes can give (a bound: a child's tape is never
// longer than its parent's), within presize_cap words more than in use; past the cap an
// overflow grows the pool and redoes the level.
void Pruner::presize(Buffer& pool, uint64_t& cap, uint64_t used, uint64_t bound) {
    const uint64_t want = used + std::min(bound, presize_cap);
    if (want > cap) resize(pool, cap, want, used);
}

// All levels' cells in one buffer, for the lookups of the tracing and discretizing kernels,
// and their far-field clearances.
void Pruner::gather_cells() {
    for (size_t li = 0; li < level_cells.size(); ++li) {
        g.level_info[li].offset = uint32_t(cell_total);
        cell_total += level_cells[li]->size / sizeof(PrunedCell);
    }
    g.cells = ctx.create_buffer(cell_total * sizeof(PrunedCell));
    g.levels = ctx.create_buffer(g.level_info.size() * sizeof(GpuLevel));
    ctx.begin();
    for (size_t li = 0; li < level_cells.size(); ++li)
        ctx.copy(*level_cells[li], g.cells, level_cells[li]->size, 0,
                 uint64_t(g.level_info[li].offset) * sizeof(PrunedCell));
    gpu_ms += ctx.submit();
    ctx.upload(g.levels, g.level_info.data(), g.level_info.size() * sizeof(GpuLevel));
    for (Buffer* b : level_cells) ctx.destroy(*b);
    // The far-field clearances (set_clearance), on the host: the cells read back, set, and
    // written again (within wall_ms, not prune_ms).
    if (opt.clearance) {
        const auto t_clear = std::chrono::steady_clock::now();
        std::vector<PrunedCell> host(cell_total);
        ctx.download(g.cells, host.data(), cell_total * sizeof(PrunedCell));
        std::vector<LevelCells> levels;
        for (size_t li = 0; li < g.level_info.size(); ++li) {
            const uint64_t end =
                li + 1 < g.level_info.size() ? g.level_info[li + 1].offset : cell_total;
            levels.push_back(
                {g.level_info[li].res, g.level_info[li].factor,
                 std::span(host).subspan(g.level_info[li].offset, end - g.level_info[li].offset)});
        }
        st.clearance_bytes = set_clearance(levels, opt.threads) + cell_total * sizeof(PrunedCell);
        ctx.upload(g.cells, host.data(), cell_total * sizeof(PrunedCell));
        st.clearance_ms =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_clear)
                .count();
    }
    st.prune_ms = gpu_ms;
    st.subgroups = ctx.can_run(KernelId::kPruneWideSubgroups);
}

// Statistics (not timed): per cell (length, primitives) or far-field, level by level.
void Pruner::read_statistics() {
    const uint32_t N = res.back();
    st.grid = N;
    st.cells = uint64_t(N) * N * N;
    st.levels = res;
    uint64_t far_finest = 0;
    double prim_sum = 0, prim_sq = 0, tape_sum = 0;
    for (size_t li = 0; li < g.level_info.size(); ++li) {
        const uint64_t n = li + 1 < g.level_info.size()
                               ? g.level_info[li + 1].offset - g.level_info[li].offset
                               : cell_total - g.level_info[li].offset;
        const uint64_t below = N / g.level_info[li].res;
        const bool finest = li + 1 == g.level_info.size();
        Buffer& level = local.create(n * sizeof(PrunedCell));
        ctx.begin();
        ctx.copy(g.cells, level, n * sizeof(PrunedCell),
                 uint64_t(g.level_info[li].offset) * sizeof(PrunedCell));
        if (!finest) {
            // A coarser level's far-field cells, from the cells themselves (their tapes went
            // with their pools).
            ctx.submit();
            std::vector<PrunedCell> cells(n);
            ctx.download(level, cells.data(), n * sizeof(PrunedCell));
            ctx.destroy(level);
            for (const PrunedCell& c : cells)
                if (c.tape == PrunedCell::kFarField) far_finest += below * below * below;
            continue;
        }
        Buffer& info = local.create(n * 8);
        const CellInfoPush push{uint32_t(n)};
        ctx.dispatch(KernelId::kCellInfo, {&level, &g.pool, &info}, &push, sizeof(push),
                     ctx.groups_for(n));
        ctx.submit();
        std::vector<uint32_t> host(n * 2);
        ctx.download(info, host.data(), n * 8);
        ctx.destroy(level);
        ctx.destroy(info);
        for (uint64_t i = 0; i < n; ++i) {
            const uint32_t len = host[2 * i], prims = host[2 * i + 1];
            if (len == PrunedCell::kFarField) {
                ++far_finest;
                continue;
            }
            ++st.near_field_cells;
            tape_sum += len;
            st.tape_max = std::max(st.tape_max, len);
            prim_sum += prims;
            prim_sq += double(prims) * prims;
            st.active_max = std::max(st.active_max, prims);
        }
    }
    finish_prune_stats(st, prim_sum, prim_sq, tape_sum, far_finest);
    st.tape_bytes = uint64_t(g.pool_words) * 4 + cell_total * sizeof(PrunedCell);
}

}  // namespace

Grid prune(Device& device, const Scene& sc, const PruneOptions& opt) {
    const auto t_start = std::chrono::steady_clock::now();
    if (!(opt.far_field_c >= 1.0f)) throw std::invalid_argument("far-field C must be >= 1");
    Context& ctx = device.context();
    ctx.reset_peak();
    const uint64_t live_before = ctx.bytes_live();
    const Context::HostTime host_before = ctx.host_time();
    Grid grid;
    grid.impl_ = std::make_unique<DeviceGrid>(ctx, sc);
    DeviceGrid& g = *grid.impl_;
    DevicePruneStats& st = g.stats;
    Pruner pruner(device, sc, opt, g);
    pruner.run();
    st.prune_peak_bytes = ctx.bytes_peak() - live_before;
    st.wall_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_start)
            .count();
    const Context::HostTime& host = ctx.host_time();
    st.host_buffers = host.buffers - host_before.buffers;
    st.host_buffers_reused = host.buffers_reused - host_before.buffers_reused;
    st.host_submissions = host.submissions - host_before.submissions;
    st.host_buffer_ms = host.buffer_ms - host_before.buffer_ms;
    st.host_submit_ms = host.submit_ms - host_before.submit_ms;
    pruner.read_statistics();
    return grid;
}

}  // namespace sdfprune::gpu
