// prune.cpp — the hierarchy (DESIGN.md §5): level by level, the level step (prune_level.hpp)
// prunes every child of a near-field cell from its parent's tape, in parallel over fixed chunks
// of cells (parallel_for, src/core/parallel.hpp) so that the result does not depend on the
// thread count. Children of far-field cells are not stored. Also the tape pool and the
// statistics' totals; the grid's queries are in pruned_grid.cpp.
//
// Memory: a level's tapes stay in their chunks' buffers, which are the next level's parents; the
// chunks are pruned in waves, and after each wave the parents' buffers no block left refers to
// are freed. Finest tapes go to the pool wave by wave; coarse tapes are dropped once they have
// served as parents (PruneOptions::coarse_tapes keeps them).
#include <tbb/enumerable_thread_specific.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <new>
#include <utility>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include "../core/parallel.hpp"
#include "prune_level.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/prune.hpp"

namespace sdfprune {

std::vector<uint32_t> grid_levels(uint32_t resolution, uint32_t factor, bool hierarchy) {
    if (resolution == 0) throw std::invalid_argument("grid resolution must be >= 1");
    if (factor < 2) throw std::invalid_argument("subdivision factor must be >= 2");
    std::vector<uint32_t> levels{resolution};
    if (!hierarchy) return levels;
    while (levels.back() % factor == 0 && levels.back() / factor >= 2)
        levels.push_back(levels.back() / factor);
    std::reverse(levels.begin(), levels.end());
    return levels;
}

// A copy keeps the spare capacity (update() reserves some for the tapes edits append).
PrunedGrid::Pool::Pool(const Pool& other) : size(other.size), capacity(other.capacity) {
    if (capacity == 0) return;
    data = static_cast<uint32_t*>(std::malloc(capacity * sizeof(uint32_t)));
    if (!data) throw std::bad_alloc();
    std::memcpy(data, other.data, size * sizeof(uint32_t));
}

PrunedGrid::Pool::Pool(Pool&& other) noexcept
    : data(std::exchange(other.data, nullptr)),
      size(std::exchange(other.size, 0)),
      capacity(std::exchange(other.capacity, 0)) {}

PrunedGrid::Pool& PrunedGrid::Pool::operator=(Pool other) noexcept {
    std::swap(data, other.data);
    std::swap(size, other.size);
    std::swap(capacity, other.capacity);
    return *this;
}

PrunedGrid::Pool::~Pool() {
    std::free(data);
}

void PrunedGrid::Pool::append(std::span<const uint32_t> words) {
    if (words.empty()) return;
    if (size + words.size() > capacity) {
        const size_t want = std::max(size + words.size(), capacity + capacity / 2);
        void* p = std::realloc(data, want * sizeof(uint32_t));
        if (!p) throw std::bad_alloc();
        data = static_cast<uint32_t*>(p);
        capacity = want;
    }
    std::memcpy(data + size, words.data(), words.size_bytes());
    size += words.size();
}

void PrunedGrid::Pool::reserve(size_t words) {
    if (words <= capacity) return;
    void* p = std::realloc(data, words * sizeof(uint32_t));
    if (!p) throw std::bad_alloc();
    data = static_cast<uint32_t*>(p);
    capacity = words;
}

void PrunedGrid::Pool::shrink_to_fit() {
    if (size == 0 || size == capacity) return;
    if (void* p = std::realloc(data, size * sizeof(uint32_t))) {
        data = static_cast<uint32_t*>(p);
        capacity = size;
    }
}

namespace {

constexpr uint32_t kChunkCells = kPruneChunkCells;

// Freed bytes worth handing back to the system (return_freed_memory).
constexpr uint64_t kReturnBytes = 64u << 20;

uint64_t bytes_of(const auto& v) {
    return uint64_t(v.capacity()) * sizeof(v[0]);
}

// Hands memory freed to the C library back to the system. glibc keeps freed blocks below its
// (self-raising) mmap threshold in its heaps, where the parents freed during a level would go on
// counting in the process's memory; elsewhere nothing to do.
void return_freed_memory() {
#if defined(__GLIBC__)
    malloc_trim(0);
#endif
}

// The buffers of one level's pruning as it runs: the parents (the previous level's chunk
// buffers), which are freed as soon as no block left refers to them, and the byte counts of the
// peak-memory statistic.
struct LevelBuffers {
    std::vector<std::vector<uint32_t>> parents;
    // first_block[c]: the first block whose parent is in parents[c] (blocks are in parent order).
    std::vector<uint32_t> first_block;
    uint32_t released = 0;  // parents[0, released) are freed
    uint64_t parent_bytes = 0, done_cells_bytes = 0, peak = 0;
    uint64_t unreturned = 0;  // bytes freed since the last return_freed_memory()

    // Frees the parents of blocks before `block` (all of them when block = number of blocks).
    void release_before(uint64_t block, uint64_t blocks) {
        const uint32_t needed =
            block < blocks
                ? uint32_t(std::upper_bound(first_block.begin(), first_block.end(), block) -
                           first_block.begin() - 1)
                : uint32_t(parents.size());
        for (; released < needed; ++released) {
            parent_bytes -= bytes_of(parents[released]);
            unreturned += bytes_of(parents[released]);
            std::vector<uint32_t>().swap(parents[released]);
        }
        if (unreturned >= kReturnBytes) {
            return_freed_memory();
            unreturned = 0;
        }
    }
};

// The blocks of the next level: one per near-field cell of `cells` (the level just pruned, whose
// blocks are `blocks`, f wide), in cell order, their children nf wide (nf = 0: `cells` is the
// finest level, no blocks), each with its tape in its chunk's buffer in `outs`. Sets the cells'
// `children`; adds to far_finest the finest cells (`below`³ each) the far-field cells cover;
// first_block[c] = the first block whose parent is in chunk c.
std::vector<ParentBlock> link_children(std::span<PrunedCell> cells,
                                       std::span<const ParentBlock> blocks, uint32_t f, uint32_t nf,
                                       const std::vector<LevelChunk>& outs, uint64_t below,
                                       uint64_t& far_finest, std::vector<uint32_t>& first_block) {
    const uint64_t per_block = uint64_t(f) * f * f;
    std::vector<ParentBlock> next;
    first_block.assign(outs.size() + 1, 0);
    for (uint64_t i = 0; i < cells.size(); ++i) {
        PrunedCell& cell = cells[i];
        if (cell.tape == PrunedCell::kFarField) {
            far_finest += below * below * below;
            continue;
        }
        if (nf == 0) continue;
        const CellCoord at = block_cell(blocks[i / per_block].origin, f, uint32_t(i % per_block));
        const uint32_t c = uint32_t(i / kChunkCells);
        cell.children = uint32_t(next.size() * nf * nf * nf);
        const uint32_t* header = outs[c].words.data() + cell.tape;
        ++first_block[c + 1];
        next.push_back({{at.x * nf, at.y * nf, at.z * nf}, header[0], header + 2});
    }
    for (size_t c = 0; c + 1 < first_block.size(); ++c) first_block[c + 1] += first_block[c];
    first_block.pop_back();
    return next;
}

}  // namespace

// The driver of the hierarchy: for each level, the level step (prune_level.hpp) over fixed
// chunks of its blocks' cells in parallel waves; then the chunks' tapes are placed (finest: in
// the pool; coarse: kept as the next level's parents) and the near-field cells become the next
// level's blocks.
PrunedGrid prune(const Scene& sc, const PruneOptions& opt) {
    const auto t0 = std::chrono::steady_clock::now();
    if (!(opt.far_field_c >= 1.0f)) throw std::invalid_argument("far-field C must be >= 1");
    PrunedGrid g;
    g.scene_ = &sc;
    g.options_ = opt;
    g.lipschitz_ = sc.lipschitz[sc.root()];
    const std::vector<uint32_t> res = grid_levels(opt.resolution, opt.factor, opt.hierarchy);
    const uint32_t N = res.back();
    const vec3 extent = sc.aabb.max - sc.aabb.min;
    g.cell_size_ = extent / float(N);
    g.inv_cell_size_ = vec3(1.0f / g.cell_size_.x, 1.0f / g.cell_size_.y, 1.0f / g.cell_size_.z);

    // The full tape opens the pool and is the parent of level 0.
    std::vector<uint32_t> root{sc.size(), sc.primitive_count()};
    root.insert(root.end(), sc.full_tape.begin(), sc.full_tape.end());
    g.pool_.append(root);
    const auto pool_bytes = [&] { return uint64_t(g.pool_.capacity) * sizeof(uint32_t); };

    tbb::enumerable_thread_specific<CellScratch> scratch;
    PruneStats& st = g.stats_;
    st.grid = N;
    st.cells = uint64_t(N) * N * N;
    st.levels = res;

    // Far-field cells above the finest level count for all the finest cells they cover.
    uint64_t far_finest = 0;
    // The previous level's tapes, one buffer per chunk, and the current level's blocks: one per
    // near-field parent, with its origin (in this level's cells) and its parent's tape.
    LevelBuffers buf;
    buf.parents.push_back(std::move(root));
    buf.first_block = {0};
    std::vector<ParentBlock> blocks{{{0, 0, 0}, sc.size(), buf.parents[0].data() + 2}};
    buf.parent_bytes = bytes_of(buf.parents[0]);
    const int workers = opt.threads > 0 ? opt.threads : tbb::this_task_arena::max_concurrency();

    const auto scratch_bytes = [&] {
        uint64_t b = 0;
        for (const CellScratch& s : scratch) b += s.bytes();
        return b;
    };

    for (uint32_t li = 0; li < res.size(); ++li) {
        const bool finest = li + 1 == res.size();
        // Scratch is sized by the longest tape a thread has walked; near the root of a huge
        // scene that is millions of words, which the lower levels' short tapes do not need.
        uint32_t longest = 0;
        for (const ParentBlock& b : blocks) longest = std::max(longest, b.length);
        for (CellScratch& s : scratch)
            if (s.value.size() > 4 * size_t(longest) + 4096) s = CellScratch{};
        PrunedGrid::Level level;
        level.res = res[li];
        level.factor = li == 0 ? res[0] : res[li] / res[li - 1];
        const uint32_t f = level.factor;
        const uint64_t per_block = uint64_t(f) * f * f;
        const uint64_t total = per_block * blocks.size();
        if (total > 0xfffffffeull) throw std::length_error("too many cells in one level");
        level.cells.resize(total);
        const LevelGeometry geo = level_geometry(sc, opt, level.res, f, finest, kChunkCells);
        const uint32_t chunks = uint32_t((total + kChunkCells - 1) / kChunkCells);
        std::vector<LevelChunk> outs(chunks);

        // Moves chunk c's tapes into the pool (or, for coarse tapes not kept, points its
        // near-field cells to the full tree's tape).
        const auto place_chunk = [&](uint32_t c, bool into_pool) {
            const uint64_t base = g.pool_.size;
            if (into_pool) {
                if (base + outs[c].words.size() >= PrunedCell::kFarField)
                    throw std::length_error("tape pool exceeds 2^32 - 1 words");
                g.pool_.append(outs[c].words);
            }
            const uint64_t end = std::min(total, uint64_t(c + 1) * kChunkCells);
            for (uint64_t i = uint64_t(c) * kChunkCells; i < end; ++i) {
                uint32_t& t = level.cells[i].tape;
                if (t != PrunedCell::kFarField) t = into_pool ? uint32_t(base + t) : 0;
            }
        };
        uint64_t level_bytes = bytes_of(level.cells);  // this level's cells and kept buffers
        // Waves of chunks: enough for load balance, few enough that parents are freed early
        // and finest buffers are few. Output does not depend on the wave size.
        const uint32_t wave = 16 * uint32_t(std::max(1, workers));
        for (uint32_t w0 = 0; w0 < chunks; w0 += wave) {
            const uint32_t w1 = std::min(chunks, w0 + wave);
            ParallelOptions po = parallel_options(opt);
            po.progress_lo = (double(li) + double(w0) / chunks) / double(res.size());
            po.progress_hi = (double(li) + double(w1) / chunks) / double(res.size());
            parallel_for<PruneCancelled>(w1 - w0, po, [&](uint64_t k) {
                const uint32_t c = uint32_t(w0 + k);
                const uint64_t begin = uint64_t(c) * kChunkCells;
                const uint64_t end = std::min(total, begin + kChunkCells);
                LevelChunk& out = outs[c];
                prune_level_step(sc, opt, geo, blocks, begin, end,
                                 std::span(level.cells).subspan(begin, end - begin),
                                 scratch.local(), out);
                // Coarse buffers live on as the next level's parents: no slack.
                if (!finest) out.words.shrink_to_fit();
            });
            uint64_t wave_bytes = 0;
            for (uint32_t c = w0; c < w1; ++c) {
                wave_bytes += bytes_of(outs[c].words);
                add_chunk_stats(outs[c], st);
            }
            if (finest) {
                for (uint32_t c = w0; c < w1; ++c) place_chunk(c, true);
            } else {
                level_bytes += wave_bytes;
                wave_bytes = 0;
            }
            buf.peak =
                std::max(buf.peak, pool_bytes() + buf.parent_bytes + level_bytes + wave_bytes +
                                       buf.done_cells_bytes + bytes_of(blocks) + scratch_bytes());
            if (finest)
                for (uint32_t c = w0; c < w1; ++c) std::vector<uint32_t>().swap(outs[c].words);
            // Free the parents that no block from the next wave on refers to.
            buf.release_before(uint64_t(w1) * kChunkCells / per_block, blocks.size());
        }

        // Far-field cells of this level, and the next level's blocks: one per near-field cell.
        std::vector<uint32_t> first_block;
        std::vector<ParentBlock> next =
            link_children(level.cells, blocks, f, finest ? 0 : res[li + 1] / res[li], outs,
                          N / level.res, far_finest, first_block);
        blocks.swap(next);
        if (!finest) {
            // This level's buffers become the parents; the cells' offsets into them go.
            buf.parents.clear();
            buf.parent_bytes = 0;
            buf.released = 0;
            buf.first_block.swap(first_block);
            for (uint32_t c = 0; c < chunks; ++c) {
                place_chunk(c, opt.coarse_tapes);
                buf.parent_bytes += bytes_of(outs[c].words);
                buf.parents.push_back(std::move(outs[c].words));
            }
            buf.peak =
                std::max(buf.peak, pool_bytes() + buf.parent_bytes + bytes_of(level.cells) +
                                       buf.done_cells_bytes + bytes_of(blocks) + scratch_bytes());
        }
        buf.done_cells_bytes += bytes_of(level.cells);
        const uint32_t scale = N / level.res;
        if (std::has_single_bit(scale) && std::has_single_bit(level.factor)) {
            level.pow2 = true;
            level.shift = uint32_t(std::countr_zero(scale));
            level.factor_bits = uint32_t(std::countr_zero(level.factor));
        }
        g.level_size_.push_back(geo.cell_size);
        g.levels_.push_back(std::move(level));
        if (opt.progress) opt.progress(double(li + 1) / double(res.size()));
    }
    g.pool_.shrink_to_fit();

    g.build_shortcut();
    if (opt.clearance) g.build_clearance();

    // Until here active_avg, active_std and tape_avg held the near-field cells' sums.
    finish_prune_stats(st, st.active_avg, st.active_std, st.tape_avg, far_finest);
    st.tape_bytes = pool_bytes();
    for (const PrunedGrid::Level& l : g.levels_) st.tape_bytes += bytes_of(l.cells);
    st.prune_peak_bytes =
        std::max({buf.peak, st.tape_bytes + scratch_bytes(), st.tape_bytes + st.clearance_bytes});
    st.prune_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    return g;
}

void finish_prune_stats(PruneStats& st, double prim_sum, double prim_sq_sum, double tape_sum,
                        uint64_t far_finest) {
    const double cells = double(st.cells), near = double(st.near_field_cells);
    st.near_field_prims_avg = st.near_field_cells ? prim_sum / near : 0;
    st.tape_avg = st.near_field_cells ? tape_sum / near : 0;
    st.active_avg = (prim_sum + double(far_finest)) / cells;
    const double mean_sq = (prim_sq_sum + double(far_finest)) / cells;
    st.active_std = std::sqrt(std::max(0.0, mean_sq - st.active_avg * st.active_avg));
    if (far_finest > 0) st.active_max = std::max(st.active_max, 1u);
}

}  // namespace sdfprune
