// gpu_prune.cpp — hierarchical pruning on the device (gpu.hpp): the host walks the levels as
// src/prune/prune.cpp does. A level's steps (prune.comp: the octants, the cells; then the
// finest cells' refinement, prune_refine_lanes.comp and prune_refine.comp) each run over all
// their jobs in teams of lanes that share a parent tape (in refinement, a lane per cell with a
// short tape, then a squad of lanes per cell, a lane per sub-box), then expand.comp makes the
// next level's blocks. Steps with few jobs and long parent tapes (the top levels) run
// prune_wide.comp instead: a workgroup per parent tape. Each level's tapes go to a pool of
// their own; before each run (the octants, the cells, the refinement) a pool is made room for
// what its parents' tapes bound, and one that overflows all the same grows and the run is
// redone. Statistics are read back at the end.
//
// Reading order: Pruner::run (the levels), prune_level (a level: its pools and buffers),
// prune_slices (its blocks, a slice at a time, and the steps of a slice), run_steps (one
// submission) and record_step (its dispatches); a step's shape (teams, wide, lanes or squads)
// is planned in gpu_prune_plan.cpp.
#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <numeric>
#include <optional>

#include "../core/clock.hpp"
#include "gpu_prune.hpp"

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

namespace pruning {

// Whether a step's kernel measures its walks (PrunePush::walk_slot; prune_common.glsl:
// note_walk): the team steps (modes 0-2, not the order passes), the wide steps, and
// refinement's lanes (not their order pass) and squads.
static bool measures_walks(const Step& s) {
    switch (s.kernel) {
        case KernelId::kPrune:
        case KernelId::kPruneBytes:
            return s.push.mode <= kernel::kModeOctantCells;
        case KernelId::kPruneRefineLanes:
        case KernelId::kPruneRefineLanesLong:
            return !s.order_pass;
        case KernelId::kPruneRefine:
        case KernelId::kPruneWide:
        case KernelId::kPruneWideSubgroups:
        case KernelId::kPruneWideRuns:
            return true;
        default:
            return false;
    }
}

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
      host_counters(env_flag("SDFPRUNE_VULKAN_HOST_COUNTERS", false)),
      counters(local.create(sizeof(GpuCounters), host_counters)),
      counters_mirror(host_counters ? counters : local.create(sizeof(GpuCounters), true)),
      counter(static_cast<GpuCounters*>(counters_mirror.mapped)),
      blocks(local.create(sizeof(GpuBlock))),
      scratch(local.slot()),
      octant_pool(local.create(octant_capacity * 4)),
      refine_list(local.create(16)) {
    // The scene. The primitives' parameters and bounds are in node order (a primitive node's
    // `primitive` is its own index; an operator's record is unused, zeros), so that a kernel that
    // knows an entry is a primitive reads its parameters by the entry's node at once, beside
    // the node, not after it (scene.glsl). The staged tape words of prune_team.glsl take bit 30
    // for that: a node index is below 2^28 wherever 16-byte nodes fit one storage buffer.
    if (sc.size() >= kStagedPrimitiveBit)
        throw GpuError("scene too large for the device's largest storage buffer");
    std::vector<GpuNode> nodes(sc.size());
    std::vector<math::PrimitiveParams> params(sc.size());
    std::vector<GpuPrimitiveExtra> extras(sc.size());
    for (uint32_t n = 0; n < sc.size(); ++n) {
        const bool prim = sc.is_primitive(n);
        nodes[n] = {sc.kind[n], prim ? n : 0u, sc.blend[n], sc.lipschitz[n]};
        if (!prim) continue;
        const uint32_t p = sc.primitive[n];
        const PrimitiveBound& b = sc.bound[p];
        params[n] = sc.params[p];
        extras[n] = {vec4(b.centre.x, b.centre.y, b.centre.z, b.scale), vec4(b.f0, b.rho, 0, 0),
                     vec4(sc.color[p].x, sc.color[p].y, sc.color[p].z, 1)};
    }
    const auto bytes_of = [](const auto& v) { return uint64_t(v.size() * sizeof(v[0])); };
    g.nodes = ctx.create_buffer(bytes_of(nodes));
    g.params = ctx.create_buffer(bytes_of(params));
    g.extras = ctx.create_buffer(bytes_of(extras));
    // For prune_wide.comp: per node the first node of its subtree and its height, and the
    // scene's figures plan_wide counts (device_layout.hpp: wide_scene_shape).
    const WideSceneShape wide = wide_scene_shape(sc);
    const std::vector<uint32_t>& spans = wide.spans;
    scene_height = wide.height;
    shared_heights = wide.shared_heights;
    wide_search_steps = wide.search_steps;
    node_spans = ctx.create_buffer(spans.size() * 4);

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
    g.pool_words = uint32_t(head.size());
    parent_words = head.size();

    // All of it in one submission.
    const GpuBlock root_block{0, 0, 0, 0};
    ctx.upload({{&g.nodes, nodes.data(), bytes_of(nodes)},
                {&g.params, params.data(), bytes_of(params)},
                {&g.extras, extras.data(), bytes_of(extras)},
                {&node_spans, spans.data(), bytes_of(spans)},
                {&g.pool, head.data(), bytes_of(head)},
                {&blocks, &root_block, sizeof(root_block)}});
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
    wide_mean = env_flag("SDFPRUNE_VULKAN_WIDE_MEAN", wide_mean);
    wide_chains = env_flag("SDFPRUNE_VULKAN_WIDE_CHAINS", wide_chains);
    wide_split_by_cost = env_flag("SDFPRUNE_VULKAN_WIDE_SPLIT_BY_COST", wide_split_by_cost);
    wide_scan = env_flag("SDFPRUNE_VULKAN_WIDE_SCAN", wide_scan);
    if (const char* env = std::getenv("SDFPRUNE_VULKAN_WIDE_SPLIT"); env && *env) {
        const unsigned long split = std::strtoul(env, nullptr, 10);
        if (split > 0 && split <= kPruneTeam && (split & (split - 1)) == 0)
            wide_split = uint32_t(split);
    }
    // The longest tape refinement's lane pass takes, at most its arrays' (0: no lane pass,
    // squads for every cell; for tests and measurements; and where the device cannot run it).
    if (const char* env = std::getenv("SDFPRUNE_VULKAN_REFINE_LANE_TAPE"); env && *env) {
        refine_lane_tape =
            std::min<uint32_t>(uint32_t(std::strtoul(env, nullptr, 10)), kLaneTapeMax);
        lane_tape_fixed = true;
    }
    if (!ctx.can_run(KernelId::kPruneRefineLanesLong))
        refine_lane_tape = std::min(refine_lane_tape, kRefineLaneTape);
    if (!ctx.can_run(KernelId::kPruneRefineLanes)) refine_lane_tape = 0;
    refine_second_pass = env_flag("SDFPRUNE_VULKAN_REFINE_SECOND_PASS", refine_second_pass);
    refine_sorted_more = env_flag("SDFPRUNE_VULKAN_REFINE_SORTED_MORE", refine_sorted_more);
    refine_order = env_flag("SDFPRUNE_VULKAN_REFINE_ORDER", refine_order);
    if (const char* env = std::getenv("SDFPRUNE_VULKAN_TEAM_ORDER"); env && *env)
        team_order = std::min<uint32_t>(uint32_t(std::strtoul(env, nullptr, 10)), 2);
    snake = env_flag("SDFPRUNE_VULKAN_SNAKE", snake);
    take_jobs = env_flag("SDFPRUNE_VULKAN_TAKE", take_jobs);
    wide_take = env_flag("SDFPRUNE_VULKAN_WIDE_TAKE", wide_take);
    sweeps_end = env_flag("SDFPRUNE_VULKAN_SWEEP_END", sweeps_end);
    claims = env_flag("SDFPRUNE_VULKAN_CLAIMS", claims);
    byte_flags =
        env_flag("SDFPRUNE_VULKAN_BYTE_FLAGS", byte_flags) && ctx.can_run(KernelId::kPruneBytes);
    origin = sc.aabb.min;
    extent = sc.aabb.max - sc.aabb.min;
    L = sc.lipschitz[sc.root()];
    flags = (opt.far_field ? kernel::kStepFarField : 0u) |
            (opt.bounds == CellBounds::kInterval ? kernel::kStepIntervalBounds : 0u) |
            (sweeps_end ? 0u : kernel::kStepWholeSweeps);
}

void Pruner::run() {
    // (set from the finest level's final cells; the scene's box on a one-level grid: as
    // PrunedGrid::near_box)
    g.near_box = res.size() < 2 ? sc.aabb : Aabb{sc.aabb.max, sc.aabb.min};
    for (uint32_t li = 0; li < res.size(); ++li) prune_level(li);
    ctx.destroy(blocks);
    release_scratch();
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
    lv.split = level_splits_into_octants(sc, opt, res[li], lv.f);
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
    // Where the level's cells are split into octants first, or refined, their pool is made room
    // for an exact bound later, before the cells run (the octants' words) or before refinement
    // (the cells' words; the finest cells' own tapes go to the octant pool): a presize here
    // would only be given back then (molecule's finest level: 134 MB presized, 17 MB used).
    const bool sized_later = lv.split || lv.refine;
    resize(g.pool, capacity,
           head_words +
               std::max<uint64_t>(
                   sized_later ? 0 : std::min(share(main_bound, main_ratio), presize_cap), 1 << 16),
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
    // The finest level's cells buffer has room for the coarser levels' after its own
    // (gather_cells): all levels' cells end in it without a buffer of their own. (Its
    // capacity exactly that: its class could be a quarter more.)
    const uint64_t coarser =
        lv.finest ? std::accumulate(level_totals.begin(), level_totals.end(), uint64_t(0)) : 0;
    lv.cells = &local.create((lv.total + coarser) * sizeof(PrunedCell), false, lv.finest);
    lv.octants = &local.create(lv.split ? block_count * 8 * sizeof(PrunedCell) : 16);
    lv.next = &local.create(lv.finest ? 16 : lv.total * sizeof(GpuBlock));
    lv.first_shape = st.steps.size();

    const GpuCounters c = prune_slices(lv);

    // (A level that wrote nothing, its cells all far-field, says nothing.)
    if (g.pool_words > head_words)
        main_ratio = double(g.pool_words - head_words) / double(main_bound);
    ctx.destroy(*lv.octants);
    ctx.destroy(parents);
    parent_pool = nullptr;
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
    level_totals.push_back(lv.total);
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
            lv.parent_tape_words = parent_words;  // (all the level's blocks': a bound)
            steps = plan_step(lv, kernel::kModeOctants, b0, blocks_in, blocks_in * 8, *lv.octants,
                              *lv.cells, false);
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
            // (The octants' scratch first: the next step holds its own, and a pool's old and
            // new buffers, held at once while its words are copied, are not held beside it.)
            release_scratch();
            if (lv.refine) {
                // Room to list the cells of the near octants for refinement (the others are
                // far-field): molecule's finest level, 4.2 million cells, lists at most 1.4.
                hold(refine_list, 4 * std::max<uint64_t>(hf * hf * hf * sc->near_jobs, 1));
                if (octant_keep + cells_bound > octant_capacity)
                    resize(octant_pool, octant_capacity, octant_keep + cells_bound, octant_keep);
            } else if (g.pool_words + cells_bound > capacity) {
                resize(g.pool, capacity, g.pool_words + cells_bound, g.pool_words);
            }
            lv.parent_tape_words = sc->near_words;  // the octants'
            steps = plan_step(lv, kernel::kModeOctantCells, b0, blocks_in, blocks_in * lv.per_block,
                              *lv.octants, *lv.cells, lv.refine);
        } else {
            lv.parent_tape_words = parent_words;
            // Room to list every cell of the slice for refinement.
            if (lv.refine) hold(refine_list, 4 * blocks_in * lv.per_block);
            steps = plan_step(lv, kernel::kModeCells, b0, blocks_in, blocks_in * lv.per_block,
                              *lv.cells, *lv.cells, lv.refine);
        }
        lv.listed_cells = lv.copied_cells = 0;
        lv.walk_cells.fill(0);
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
            // The finest cells decided again over their sub-boxes (refine_cell), in place, in a
            // run of its own: a refined tape is never longer than its cell's,
            // so the level's pool is first made room for as many words as the cells' tapes
            // have (near_words: shared tapes too), and refinement (the level's costliest step)
            // is never redone for want of it (a pool that cannot grow that far throws): a cell
            // refined in place is never refined twice. The cells' longest tape and deepest
            // stack size its teams.
            lv.listed_cells = sc->refine_cells;
            lv.copied_cells = sc->copy_cells;
            std::copy_n(sc->walk_cells, kRefineWalkClasses, lv.walk_cells.begin());
            const uint64_t room = uint64_t(g.pool_words) + sc->near_words;
            release_scratch();
            if (room > capacity) resize(g.pool, capacity, room, g.pool_words);
            max_len = std::max(sc->max_len, 1u);
            max_depth = std::max(sc->max_depth, 1u);
            lane_tape = choose_lane_tape(lv);
            std::vector<Step> refinement =
                plan_step(lv, kernel::kModeRefine, b0, blocks_in, blocks_in * lv.per_block,
                          *lv.cells, *lv.cells, false);
            const GpuCounters rc = *run_steps(lv, refinement, false, sc->octant_used, false,
                                              bound ? lv.cells : nullptr);
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
        start.copy_cells = lv.copied_cells;
        std::copy_n(lv.walk_cells.begin(), kRefineWalkClasses, start.walk_cells);
        for (int a = 0; a < 3; ++a) {
            start.near_lo[a] = std::numeric_limits<uint32_t>::max();
            start.near_hi[a] = 0;
        }
        ctx.begin();
        if (host_counters)
            *counter = start;
        else
            ctx.update(counters, &start, sizeof(start));
        uint32_t walk_slots = 0;
        for (Step& s : steps) {
            // The walks of the team steps and of refinement's lanes and squads measured, in a
            // slot each (the first kPruneWalkSlots such steps).
            if (measures_walks(s) && walk_slots < kPruneWalkSlots) s.push.walk_slot = walk_slots++;
            // The longest tape and deepest stack read back: the cells' (the next parents'),
            // not the octants'; and after refinement, the refined cells' deepest stack (what
            // the tracing kernels' stacks are sized by; every near-field cell's refinement adds
            // its tape's depth).
            if (s.push.mode == kernel::kModeOctantCells && !s.listed) {
                ctx.fill(counters, 0, offsetof(GpuCounters, max_len), 4);
                ctx.fill(counters, 0, offsetof(GpuCounters, max_depth), 4);
            }
            // Refinement rewrites the near cells listed by the step before in place (the
            // far-field ones stay as they are).
            if (s.push.mode == kernel::kModeRefine && !s.listed && !s.second_pass)
                ctx.fill(counters, 0, offsetof(GpuCounters, max_depth), 4);
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
        if (!host_counters) ctx.copy(counters, counters_mirror, sizeof(GpuCounters));
        gpu_ms += ctx.submit();
        ++st.submissions;
        if (!counter->overflow) break;
        // (Where the device ended an invocation's loops, what the steps made is wrong.)
        if ((counter->overflow & kernel::kOverflowLoopLimit) != 0)
            throw std::logic_error("Vulkan: a pruning step reached the device's limit of " +
                                   std::to_string(Context::kLoopLimit) +
                                   " loop iterations per invocation (its plan is wrong)");
        // Grow the pool that overflowed (keeping what the steps started with) and run them
        // again. A counter that wrapped past 2^32 words (it reads less than the capacity) asks
        // for the most the device allows.
        const bool main_over = (counter->overflow & kernel::kOverflowPool) != 0,
                   octant_over = (counter->overflow & kernel::kOverflowOctantPool) != 0;
        // Refinement rewrites its cells in place and cannot run again over them; its pool was
        // made room for first (prune_slices), so only a pool at the device's limit overflows,
        // which grow() reports.
        const bool refining = std::any_of(steps.begin(), steps.end(), [](const Step& s) {
            return s.push.mode == kernel::kModeRefine;
        });
        if ((counter->overflow & kernel::kOverflowClaim) != 0)
            throw std::logic_error("Vulkan: a step's jobs claimed more scratch than planned");
        if (refining && !(main_over && capacity >= max_pool_words))
            throw std::logic_error("Vulkan: refinement overflowed a pool made room for");
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
        // end returning at once). The cells only copied walk no tape (the longest walk is the
        // other jobs'), but the long list's copies, which are not counted apart.
        if (s.order_pass) {
            // Its time is the lane pass's; its jobs are the lane pass's cells.
            s.shape.gpu_ms = s.shape.lanes_ms =
                ctx.stamp_ms(s.last_stamp) - ctx.stamp_ms(s.first_stamp);
            add_shape(lv, s.shape);
            continue;
        }
        if (s.push.mode == kernel::kModeRefine) {
            const uint64_t walked = s.listed        ? counter->long_jobs
                                    : s.second_pass ? counter->more_jobs
                                                    : counter->refine_cells;
            const uint64_t jobs = walked + (s.listed || s.second_pass ? 0 : counter->copy_cells);
            if (!s.listed && !s.second_pass) {
                s.shape.jobs = jobs;
                s.shape.copy_jobs = counter->copy_cells;
            }
            s.shape.lanes = std::min(jobs, s.teams) * s.shape.lanes_per_tape;
            s.shape.longest_walk_words = ceil_div(walked, s.teams) * s.job_walk;
        }
        s.shape.gpu_ms = ctx.stamp_ms(s.last_stamp) - ctx.stamp_ms(s.first_stamp);
        if (s.push.walk_slot < kPruneWalkSlots) {
            s.shape.walked_words = counter->walk_words[s.push.walk_slot];
            s.shape.walked_sum_words = counter->walk_sum[s.push.walk_slot];
        }
        if (s.kernel == KernelId::kPruneRefineLanes ||
            s.kernel == KernelId::kPruneRefineLanesLong) {
            // Both passes' time; the first counts the lists.
            s.shape.lanes_ms = s.shape.gpu_ms;
            if (!s.second_pass) {
                s.shape.long_jobs = counter->long_jobs;
                s.shape.more_jobs = counter->more_jobs;
            }
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
    same->taken = same->taken || shape.taken;
    same->dispatches += shape.dispatches;
    same->workgroups += shape.workgroups;
    same->jobs += shape.jobs;
    same->lanes = std::max(same->lanes, shape.lanes);
    same->lanes_per_tape = std::max(same->lanes_per_tape, shape.lanes_per_tape);
    same->longest_walk_words += shape.longest_walk_words;  // one slice or pass after another
    same->walked_words += shape.walked_words;
    same->walked_sum_words += shape.walked_sum_words;
    same->gpu_ms += shape.gpu_ms;
    same->lanes_ms += shape.lanes_ms;
    same->long_jobs += shape.long_jobs;
    same->lane_tape = std::max(same->lane_tape, shape.lane_tape);
    same->more_jobs += shape.more_jobs;
    same->copy_jobs += shape.copy_jobs;
    same->scratch_bytes = std::max(same->scratch_bytes, shape.scratch_bytes);
}

// Records a step's dispatches; the pools' words in use before the level start them.
void Pruner::record_step(Step& s) {
    s.first_stamp = ctx.stamp();
    PrunePush push = s.push;
    push.pool_start = g.pool_words;
    // On a device that ends loops (lavapipe), each invocation checks that it did not reach it.
    if (ctx.device_ends_loops())
        push.flags |= kernel::kLoopProbeIterations << kernel::kStepLoopProbeShift;
    const uint64_t end = s.first_team_job + s.team_jobs;
    for (uint64_t first = s.first_team_job; first < std::max<uint64_t>(end, 1);
         first += s.per_dispatch)
        for (uint32_t round = 0; round < s.rounds; ++round) {
            push.first_job = uint32_t(first);
            push.jobs = uint32_t(std::min<uint64_t>(end, first + s.per_dispatch));
            push.round = round;
            // Binding 12: the wide kernels' node spans, the others' second view of scratch. A
            // wide step spread over several scratch buffers: a dispatch a buffer, side by side.
            // Jobs taken as workgroups come free: from a counter of their own each dispatch.
            if (s.shape.taken) ctx.fill(counters, 0, offsetof(GpuCounters, jobs_taken), 4);
            for (uint32_t b = 0; b < s.scratch_buffers; ++b) {
                const Buffer* scratch_b = b == 0 ? &scratch : more_scratch[b - 1];
                push.group_base = b * s.groups;
                ctx.dispatch(s.kernel,
                             {&g.nodes, &g.params, &g.extras, parent_pool, &blocks, s.octants,
                              s.cells, &counters, scratch_b, &octant_pool, &refine_list, &g.pool,
                              s.wide ? &node_spans : scratch_b},
                             &push, sizeof(push), s.groups, b + 1 == s.scratch_buffers);
                ++s.shape.dispatches;
                s.shape.workgroups += s.groups;
            }
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

void Pruner::release_scratch() {
    ctx.destroy(scratch);
    for (Buffer* b : more_scratch) ctx.destroy(*b);
}

void Pruner::hold(Buffer& b, uint64_t bytes) {
    if (b.size >= bytes) return;
    const uint64_t size = (bytes + 15) & ~uint64_t(15);
    if (b.buffer && b.capacity >= size) {  // (a buffer is made as large as its capacity)
        b.size = size;
        return;
    }
    ctx.destroy(b);
    b = ctx.create_buffer(bytes);
}

// All levels' cells in one buffer, for the lookups of the tracing and discretizing kernels,
// and their far-field clearances: the finest level's, with the coarser levels' copied after
// its own (level_info's offsets say where each level is).
void Pruner::gather_cells() {
    const size_t finest = level_cells.size() - 1;
    cell_total = level_totals[finest];
    g.level_info[finest].offset = 0;
    for (size_t li = 0; li < finest; ++li) {
        g.level_info[li].offset = uint32_t(cell_total);
        cell_total += level_totals[li];
    }
    g.cells = *level_cells[finest];
    *level_cells[finest] = Buffer{};
    g.levels = ctx.create_buffer(g.level_info.size() * sizeof(GpuLevel));
    if (finest > 0) {
        ctx.begin();
        for (size_t li = 0; li < finest; ++li)
            ctx.copy(*level_cells[li], g.cells, level_totals[li] * sizeof(PrunedCell), 0,
                     uint64_t(g.level_info[li].offset) * sizeof(PrunedCell));
        gpu_ms += ctx.submit();
    }
    ctx.upload(g.levels, g.level_info.data(), g.level_info.size() * sizeof(GpuLevel));
    for (Buffer* b : level_cells) ctx.destroy(*b);
    // The far-field clearances (set_clearance), on the host: the cells read back, set, and
    // written again (within wall_ms, not prune_ms).
    if (opt.clearance) {
        const auto t_clear = std::chrono::steady_clock::now();
        std::vector<PrunedCell> host(cell_total);
        ctx.download(g.cells, host.data(), cell_total * sizeof(PrunedCell));
        std::vector<LevelCells> levels;
        for (size_t li = 0; li < g.level_info.size(); ++li)
            levels.push_back({g.level_info[li].res, g.level_info[li].factor,
                              std::span(host).subspan(g.level_info[li].offset, level_totals[li])});
        st.clearance_bytes = set_clearance(levels, opt.threads) + cell_total * sizeof(PrunedCell);
        ctx.upload(g.cells, host.data(), cell_total * sizeof(PrunedCell));
        st.clearance_ms = ms_since(t_clear);
    }
    st.prune_ms = gpu_ms;
    st.subgroups = ctx.can_run(KernelId::kPruneWideSubgroups);
    st.subgroup_size = ctx.subgroup_size();
    st.byte_flags = byte_flags;
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
        const uint64_t n = level_totals[li];
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

}  // namespace pruning

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
    pruning::Pruner pruner(device, sc, opt, g);
    pruner.run();
    st.prune_peak_bytes = ctx.bytes_peak() - live_before;
    st.wall_ms = ms_since(t_start);
    const Context::HostTime& host = ctx.host_time();
    st.host_buffers = host.buffers - host_before.buffers;
    st.host_buffers_reused = host.buffers_reused - host_before.buffers_reused;
    st.host_allocations = host.allocations - host_before.allocations;
    st.host_allocated_bytes = host.allocated_bytes - host_before.allocated_bytes;
    st.host_submissions = host.submissions - host_before.submissions;
    st.host_buffer_ms = host.buffer_ms - host_before.buffer_ms;
    st.host_submit_ms = host.submit_ms - host_before.submit_ms;
    pruner.read_statistics();
    return grid;
}

}  // namespace sdfprune::gpu
