// prune.cpp — the hierarchy (DESIGN.md §5): level by level, the level step (prune_level.hpp)
// prunes every child of a near-field cell from its parent's tape, in parallel over fixed chunks
// of cells (parallel_for, src/core/parallel.hpp) so that the result does not depend on the
// thread count. Children of far-field cells are not stored. Also the tape pool and the
// statistics' totals; the grid's queries are in pruned_grid.cpp.
//
// Memory: a level's tapes stay in their chunks' buffers, which are the next level's parents. The
// chunks are committed in order as they finish (parallel_for_ordered): a parent buffer is freed
// as soon as no chunk still to run refers to it (and, on Linux, the pages of a large one that no
// chunk still to run reads are handed back before that), and finest tapes go to the pool chunk by
// chunk; coarse tapes are dropped once they have served as parents (PruneOptions::coarse_tapes
// keeps them).
#include <tbb/enumerable_thread_specific.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <new>
#include <utility>

#if defined(__GLIBC__)
#include <malloc.h>
#endif
#if defined(__linux__)
#include <sys/mman.h>
#include <unistd.h>
#endif

#include "../core/clock.hpp"
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

// Pages of a parent buffer that no chunk still to run reads are handed back to the system while
// the buffer lives on (their contents are never read again), once this many bytes of them are
// (set_parent_discard_bytes). Without it a million-sphere scene's level of 64³ cells held each
// of its parent buffers, 300 MB apiece, until the buffer's last block was done.
std::atomic<uint64_t> discard_bytes{1u << 20};
std::atomic<uint64_t> discarded_bytes{0};

// Hands back the whole pages within [begin, end) (Linux: MADV_DONTNEED; elsewhere nothing).
void discard_pages(const uint32_t* begin, const uint32_t* end) {
#if defined(__linux__)
    static const uintptr_t page = uintptr_t(sysconf(_SC_PAGESIZE));
    const uintptr_t lo = (reinterpret_cast<uintptr_t>(begin) + page - 1) & ~(page - 1);
    const uintptr_t hi = reinterpret_cast<uintptr_t>(end) & ~(page - 1);
    if (hi > lo && madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_DONTNEED) == 0)
        discarded_bytes.fetch_add(hi - lo, std::memory_order_relaxed);
#else
    (void)begin;
    (void)end;
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
    // read_from[b]: the lowest parent word that blocks b, b + 1, ... of b's parent buffer read
    // (equal tapes are stored once, so a block may read words before its predecessors').
    std::vector<const uint32_t*> read_from;
    const uint32_t* discarded_to = nullptr;  // parents[released]'s pages before this are gone

    // Called when `blocks` become the level's blocks, with their parents and first_block set.
    void start_level(std::span<const ParentBlock> blocks) {
        read_from.resize(blocks.size());
        for (size_t c = first_block.size(); c-- > 0;) {
            const size_t end = c + 1 < first_block.size() ? first_block[c + 1] : blocks.size();
            const uint32_t* lowest = nullptr;
            for (size_t b = end; b-- > first_block[c];) {
                if (!lowest || blocks[b].words < lowest) lowest = blocks[b].words;
                read_from[b] = lowest;
            }
        }
        released = 0;
        discarded_to = parents.empty() ? nullptr : parents[0].data();
    }

    // Frees the parents of blocks before `block` (all of them when block = number of blocks),
    // and hands back the pages of block's parent buffer below what it and later blocks read.
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
            discarded_to = released + 1 < parents.size() ? parents[released + 1].data() : nullptr;
        }
        if (unreturned >= kReturnBytes) {
            return_freed_memory();
            unreturned = 0;
        }
        if (block < blocks && discarded_to &&
            uint64_t(read_from[block] - discarded_to) * sizeof(uint32_t) >=
                discard_bytes.load(std::memory_order_relaxed)) {
            discard_pages(discarded_to, read_from[block]);
            discarded_to = read_from[block];
        }
    }
};

// The next level's blocks under the near-field cells [begin, end) of one chunk of `cells` (the
// level just pruned, whose blocks are `blocks`, f wide), appended to `next` in cell order, their
// children nf wide, each with its tape in the chunk's buffer `words`. Sets those cells'
// `children`.
void link_chunk(std::span<PrunedCell> cells, std::span<const ParentBlock> blocks, uint32_t f,
                uint32_t nf, uint64_t begin, uint64_t end, const std::vector<uint32_t>& words,
                std::vector<ParentBlock>& next) {
    const uint64_t per_block = uint64_t(f) * f * f;
    for (uint64_t i = begin; i < end; ++i) {
        PrunedCell& cell = cells[i];
        if (cell.tape == PrunedCell::kFarField) continue;
        const CellCoord at = block_cell(blocks[i / per_block].origin, f, uint32_t(i % per_block));
        cell.children = uint32_t(next.size() * nf * nf * nf);
        const uint32_t* header = words.data() + cell.tape;
        next.push_back({{at.x * nf, at.y * nf, at.z * nf}, header[0], header + 2});
    }
}

}  // namespace

uint64_t set_parent_discard_bytes(uint64_t bytes) {
    return discard_bytes.exchange(bytes);
}

uint64_t discarded_parent_bytes() {
    return discarded_bytes.load();
}

// The driver of the hierarchy: for each level, the level step (prune_level.hpp) over fixed
// chunks of its blocks' cells in parallel, committed in chunk order: the chunks' tapes are placed
// (finest: in the pool; coarse: kept as the next level's parents) and the near-field cells become
// the next level's blocks.
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
    buf.start_level(blocks);

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
        level.cells.resize(total);  // not written: each chunk writes its own (prune_chunk)
        const LevelGeometry geo = level_geometry(sc, opt, level.res, f, finest, kChunkCells);
        const uint32_t chunks = uint32_t((total + kChunkCells - 1) / kChunkCells);
        std::vector<LevelChunk> outs(chunks);

        // Moves chunk c's tapes into the pool (or, for coarse tapes not kept, points its
        // near-field cells to the full tree's tape); returns its far-field cells.
        const auto place_chunk = [&](uint32_t c, bool into_pool) {
            const uint64_t base = g.pool_.size;
            if (into_pool) {
                if (base + outs[c].words.size() >= PrunedCell::kFarField)
                    throw std::length_error("tape pool exceeds 2^32 - 1 words");
                g.pool_.append(outs[c].words);
            }
            const uint64_t end = std::min(total, uint64_t(c + 1) * kChunkCells);
            uint64_t far = 0;
            for (uint64_t i = uint64_t(c) * kChunkCells; i < end; ++i) {
                uint32_t& t = level.cells[i].tape;
                if (t != PrunedCell::kFarField)
                    t = into_pool ? uint32_t(base + t) : 0;
                else
                    ++far;
            }
            return far;
        };
        uint64_t level_bytes = bytes_of(level.cells);  // this level's cells and kept buffers
        // Above the finest level: the next level's blocks, and per chunk the first of them
        // whose parent is in the chunk.
        const uint32_t nf = finest ? 0 : res[li + 1] / res[li];
        const uint64_t below = N / level.res;
        std::vector<ParentBlock> next;
        std::vector<uint32_t> first_block(finest ? 0 : chunks, 0);
        // Bytes of each chunk's buffer plus one, once done (0: not done yet).
        const auto chunk_bytes = std::make_unique<std::atomic<uint64_t>[]>(chunks);
        uint64_t level_peak = 0;  // the level's peak but scratch
        // One loop over the level's chunks. Each chunk is committed in chunk order as soon as
        // it and all before it are done, while later chunks run: its counts are added, its
        // finest tapes go to the pool (or, above the finest level, the blocks under its cells
        // are linked), and the parents no later chunk refers to are freed. Output does not
        // depend on the order in which chunks finish.
        const auto prune_chunk = [&](uint64_t k) {
            const uint64_t begin = k * kChunkCells;
            const uint64_t end = std::min(total, begin + kChunkCells);
            LevelChunk& out = outs[k];
            // The chunk's cells are first written here, in parallel (UninitializedAllocator).
            std::fill(level.cells.begin() + begin, level.cells.begin() + end, PrunedCell{});
            prune_level_step(sc, opt, geo, blocks, begin, end,
                             std::span(level.cells).subspan(begin, end - begin), scratch.local(),
                             out);
            // Coarse buffers live on as the next level's parents: no slack.
            if (!finest) out.words.shrink_to_fit();
            chunk_bytes[k].store(bytes_of(out.words) + 1, std::memory_order_relaxed);
        };
        // Runs in chunk order, one at a time (parallel_for_ordered).
        const auto commit_chunk = [&](uint64_t k) {
            const uint64_t bytes = chunk_bytes[k].load(std::memory_order_relaxed) - 1;
            // The chunks done after this one, waiting for their turn.
            uint64_t waiting = 0;
            for (uint64_t d = k + 1; d < chunks; ++d) {
                const uint64_t b = chunk_bytes[d].load(std::memory_order_relaxed);
                if (b == 0) break;
                waiting += b - 1;
            }
            level_peak =
                std::max(level_peak, pool_bytes() + buf.parent_bytes + level_bytes + bytes +
                                         waiting + buf.done_cells_bytes + bytes_of(blocks));
            add_chunk_stats(outs[k], st);
            if (finest) {
                far_finest += place_chunk(uint32_t(k), true);
                std::vector<uint32_t>().swap(outs[k].words);
            } else {
                // The next level's blocks under this chunk (before its tapes' offsets go).
                first_block[k] = uint32_t(next.size());
                const uint64_t begin = k * kChunkCells, end = std::min(total, begin + kChunkCells);
                link_chunk(level.cells, blocks, f, nf, begin, end, outs[k].words, next);
                far_finest += below * below * below * place_chunk(uint32_t(k), opt.coarse_tapes);
                level_bytes += bytes;
            }
            // Free the parents that no chunk after this one refers to.
            buf.release_before((k + 1) * kChunkCells / per_block, blocks.size());
        };
        ParallelOptions po = parallel_options(opt);
        po.progress_lo = double(li) / double(res.size());
        po.progress_hi = double(li + 1) / double(res.size());
        parallel_for_ordered<PruneCancelled>(chunks, po, prune_chunk, commit_chunk);
        // Scratch only grows within a level: its size now bounds its size at every commit.
        buf.peak = std::max(buf.peak, level_peak + scratch_bytes());

        // Above the finest level, the next level's blocks (one per near-field cell, linked as
        // the chunks were committed) become the blocks.
        if (!finest) {
            blocks.swap(next);
            // This level's buffers become the parents.
            buf.parents.clear();
            buf.parent_bytes = 0;
            buf.first_block.swap(first_block);
            for (uint32_t c = 0; c < chunks; ++c) {
                buf.parent_bytes += bytes_of(outs[c].words);
                buf.parents.push_back(std::move(outs[c].words));
            }
            buf.start_level(blocks);
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
    g.find_near_box();
    if (opt.clearance) g.build_clearance();

    // Until here active_avg, active_std and tape_avg held the near-field cells' sums.
    finish_prune_stats(st, st.active_avg, st.active_std, st.tape_avg, far_finest);
    st.tape_bytes = pool_bytes();
    for (const PrunedGrid::Level& l : g.levels_) st.tape_bytes += bytes_of(l.cells);
    st.prune_peak_bytes =
        std::max({buf.peak, st.tape_bytes + scratch_bytes(), st.tape_bytes + st.clearance_bytes});
    st.prune_ms = ms_since(t0);
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
