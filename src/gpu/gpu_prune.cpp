// gpu_prune.cpp — hierarchical pruning on the device (gpu.hpp): the host walks the levels as
// src/prune/prune.cpp does and runs each step as a dispatch of prune.comp over all its cells
// (or octants), then expand.comp to make the next level's blocks. The tape pool grows and the
// step is redone when a step overflows it; statistics are read back at the end.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstring>

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

Grid prune(Device& device, const Scene& sc, const PruneOptions& opt) {
    const auto t_start = std::chrono::steady_clock::now();
    if (!(opt.far_field_c >= 1.0f)) throw std::invalid_argument("far-field C must be >= 1");
    const std::vector<uint32_t> res = grid_levels(opt.resolution, opt.factor, opt.hierarchy);
    Context& ctx = device.context();
    ctx.reset_peak();
    const uint64_t live_before = ctx.bytes_live();
    Grid grid;
    grid.impl_ = std::make_unique<DeviceGrid>(ctx, sc);
    DeviceGrid& g = *grid.impl_;
    DevicePruneStats& st = g.stats;

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

    // The pool starts with the full tape; it grows on overflow.
    const uint64_t max_pool_words = std::min<uint64_t>(ctx.max_buffer_bytes() / 4, 0xfffffff0u);
    std::vector<uint32_t> head{sc.size(), sc.primitive_count()};
    head.insert(head.end(), sc.full_tape.begin(), sc.full_tape.end());
    if (head.size() > max_pool_words)
        throw GpuError("scene too large for the device's largest storage buffer");
    uint64_t capacity =
        std::min<uint64_t>(max_pool_words, std::max<uint64_t>(4 * head.size(), 1 << 20));
    g.pool = ctx.create_buffer(capacity * 4);
    ctx.upload(g.pool, head.data(), head.size() * 4);
    g.pool_words = uint32_t(head.size());

    // Temporaries: what is left of them is freed on return, or when an error is thrown.
    LocalBuffers local(ctx);
    Buffer& counters = local.create(sizeof(GpuCounters), true);
    auto* counter = static_cast<GpuCounters*>(counters.mapped);
    Buffer& blocks = local.create(sizeof(GpuBlock));
    const GpuBlock root_block{0, 0, 0, 0};
    ctx.upload(blocks, &root_block, sizeof(root_block));
    uint64_t block_count = 1;
    uint32_t max_len = sc.size();       // longest tape of the current parents
    uint32_t max_depth = sc.max_stack;  // deepest evaluation stack of the current parents
    Buffer& scratch = local.slot();
    // The octants' tapes of the current level (prune.comp: OctantPool), reused level by level.
    uint64_t octant_capacity = 1 << 16;
    Buffer& octant_pool = local.create(octant_capacity * 4);
    double gpu_ms = 0;

    // Replaces `pool` by one of at least `need` words (at most the device's limit), keeping
    // its first `keep` words.
    const auto grow = [&](Buffer& pool, uint64_t& cap, uint64_t need, uint64_t keep) {
        if (cap >= max_pool_words)
            throw GpuError("tape pool exceeds the device's largest storage buffer (" +
                           std::to_string(ctx.max_buffer_bytes()) + " bytes); use --backend cpu");
        const uint64_t grown = std::min(std::max(cap * 2, need + need / 4), max_pool_words);
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
        ++st.pool_grows;
    };

    const vec3 origin = sc.aabb.min, extent = sc.aabb.max - sc.aabb.min;
    const float L = sc.lipschitz[sc.root()];
    const uint32_t flags =
        (opt.far_field ? 1u : 0u) | (opt.bounds == CellBounds::kInterval ? 2u : 0u);
    uint64_t octant_words = 0;  // in use in octant_pool, from earlier steps of this level
    uint32_t level_index = 0;   // the level being made (for the steps' shapes)

    // One step: `jobs` cells or octants from their parents' tapes into `octants`/`cells`.
    // `transient`: new tapes go to the octant pool (the finest cells' tapes before refinement).
    const auto run_step = [&](uint32_t mode, uint32_t factor, uint64_t jobs, vec3 csize,
                              const Buffer& octants, const Buffer& cells, bool transient) {
        const uint64_t thread_bytes = (kPruneStateWords + 2ull * max_len + 4ull * max_depth) * 4;
        const uint32_t threads = ctx.threads_for(jobs, thread_bytes);
        // Under a loop limit (lavapipe), as many jobs per invocation as fit the limit, or one
        // job resumed over as many rounds as its three passes over the parent tape need;
        // elsewhere one unlimited round.
        const bool limited = ctx.loop_limited();
        const uint32_t budget = limited ? uint32_t(Context::kLoopLimit - 512) : 0xffffffffu;
        const uint64_t evaluations = mode == 3 ? uint64_t(opt.refine) * opt.refine * opt.refine : 1;
        const uint64_t per_job = (evaluations + 2) * max_len + evaluations + 16;
        const uint64_t rounds = limited ? (per_job + budget - 1) / budget : 1;
        const uint64_t jobs_per_invocation = limited ? std::max<uint64_t>(1, budget / per_job) : 0;
        if (scratch.size < threads * thread_bytes) {
            ctx.destroy(scratch);
            scratch = ctx.create_buffer(threads * thread_bytes);
        }
        GpuStepShape shape;
        shape.level = level_index;
        shape.mode = mode;
        shape.jobs = jobs;
        shape.lanes = std::min<uint64_t>(jobs, threads);
        shape.longest_walk_words =
            shape.lanes == 0 ? 0
                             : (jobs + shape.lanes - 1) / shape.lanes * (evaluations + 2) * max_len;
        for (;;) {
            GpuCounters start{};
            start.pool_used = g.pool_words;
            start.pool_capacity = uint32_t(capacity);
            start.octant_capacity = uint32_t(octant_capacity);
            start.octant_used = uint32_t(octant_words);
            *counter = start;
            PrunePush push{vec4(origin.x, origin.y, origin.z, L),
                           vec4(csize.x, csize.y, csize.z, opt.far_field_c),
                           mode,
                           factor,
                           uint32_t(jobs),
                           threads,
                           max_len,
                           max_depth,
                           flags | (transient ? 4u : 0u),
                           g.pool_words,
                           0,
                           0,
                           budget,
                           opt.refine,
                           uint32_t(octant_words)};
            const uint64_t per_dispatch =
                limited ? threads * jobs_per_invocation : std::max<uint64_t>(jobs, 1);
            ctx.begin();
            for (uint64_t first = 0; first < std::max<uint64_t>(jobs, 1); first += per_dispatch)
                for (uint32_t round = 0; round < rounds; ++round) {
                    push.first_job = uint32_t(first);
                    push.jobs = uint32_t(std::min<uint64_t>(jobs, first + per_dispatch));
                    push.round = round;
                    ctx.dispatch(KernelId::kPrune,
                                 {&g.nodes, &g.params, &g.extras, &g.pool, &blocks, &octants,
                                  &cells, &counters, &scratch, &octant_pool},
                                 &push, sizeof(push), threads / kWorkgroupSize);
                    ++shape.dispatches;
                    shape.workgroups += threads / kWorkgroupSize;
                }
            gpu_ms += ctx.submit();
            if (!counter->overflow) break;
            // Grow the pool that overflowed (keeping what the step started with) and redo it.
            // A counter that wrapped past 2^32 words asks for the most the device allows.
            const bool main_over = counter->pool_used > capacity,
                       octant_over = counter->octant_used > octant_capacity;
            if (main_over || !octant_over)
                grow(g.pool, capacity, main_over ? counter->pool_used : max_pool_words,
                     g.pool_words);
            if (octant_over) grow(octant_pool, octant_capacity, counter->octant_used, octant_words);
        }
        g.pool_words = counter->pool_used;
        octant_words = counter->octant_used;
        st.steps.push_back(shape);
        return *counter;
    };

    std::vector<Buffer*> level_cells;
    for (uint32_t li = 0; li < res.size(); ++li) {
        level_index = li;
        const bool finest = li + 1 == res.size();
        const uint32_t f = li == 0 ? res[0] : res[li] / res[li - 1];
        const uint64_t per_block = uint64_t(f) * f * f;
        const uint64_t total = per_block * block_count;
        if (total > 0xfffffffeull) throw std::length_error("too many cells in one level");
        const vec3 csize = extent / float(res[li]);
        Buffer& cells = local.create(total * sizeof(PrunedCell));
        // The same split as the CPU backend (prune.cpp): octants first where it applies.
        const bool split = opt.hierarchy && f >= 4 && f % 2 == 0 && 1024 % per_block == 0;
        GpuCounters c;
        if (split) {
            Buffer& octants = local.create(block_count * 8 * sizeof(PrunedCell));
            octant_words = 0;
            c = run_step(1, f, block_count * 8, csize, octants, cells, false);
            max_len = std::max(c.max_len, 1u);
            max_depth = std::max(c.max_depth, 1u);
            c = run_step(2, f, total, csize, octants, cells, finest && opt.refine > 1);
            ctx.destroy(octants);
        } else {
            octant_words = 0;
            c = run_step(0, f, total, csize, cells, cells, finest && opt.refine > 1);
        }
        if (finest && opt.refine > 1) {
            // The finest cells decided again over their sub-boxes (refine_cell), into a new
            // cell array.
            max_len = std::max(c.max_len, 1u);
            max_depth = std::max(c.max_depth, 1u);
            Buffer& refined = local.create(total * sizeof(PrunedCell));
            run_step(3, f, total, csize, refined, cells, false);
            ctx.destroy(cells);
            cells = refined;
            refined = Buffer{};
        }
        max_len = std::max(c.max_len, 1u);
        max_depth = std::max(c.max_depth, 1u);
        if (!finest) {
            const uint32_t nf = res[li + 1] / res[li];
            Buffer& next = local.create(uint64_t(c.near_jobs) * sizeof(GpuBlock));
            *counter = GpuCounters{};
            const ExpandPush push{f, uint32_t(total), nf};
            ctx.begin();
            ctx.dispatch(KernelId::kExpand, {&blocks, &cells, &next, &counters}, &push,
                         sizeof(push), ctx.groups_for(total));
            gpu_ms += ctx.submit();
            ctx.destroy(blocks);
            blocks = next;
            next = Buffer{};
            block_count = c.near_jobs;
        }
        g.level_info.push_back({res[li], f, 0, 0});
        level_cells.push_back(&cells);
    }
    ctx.destroy(blocks);
    ctx.destroy(scratch);
    ctx.destroy(octant_pool);

    // All levels' cells in one buffer, for the lookups of the tracing and discretizing kernels.
    uint64_t cell_total = 0;
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
    st.prune_peak_bytes = ctx.bytes_peak() - live_before;
    st.wall_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_start)
            .count();

    // Statistics (not timed): per cell (length, primitives) or far-field, level by level.
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
        Buffer& level = local.create(n * sizeof(PrunedCell));
        Buffer& info = local.create(n * 8);
        const CellInfoPush push{uint32_t(n)};
        ctx.begin();
        ctx.copy(g.cells, level, n * sizeof(PrunedCell),
                 uint64_t(g.level_info[li].offset) * sizeof(PrunedCell));
        ctx.dispatch(KernelId::kCellInfo, {&level, &g.pool, &info}, &push, sizeof(push),
                     ctx.groups_for(n));
        ctx.submit();
        std::vector<uint32_t> host(n * 2);
        ctx.download(info, host.data(), n * 8);
        ctx.destroy(level);
        ctx.destroy(info);
        const uint64_t below = N / g.level_info[li].res;
        const bool finest = li + 1 == g.level_info.size();
        for (uint64_t i = 0; i < n; ++i) {
            const uint32_t len = host[2 * i], prims = host[2 * i + 1];
            if (len == PrunedCell::kFarField) {
                far_finest += finest ? 1 : below * below * below;
                continue;
            }
            if (!finest) continue;
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
    return grid;
}

}  // namespace sdfprune::gpu
