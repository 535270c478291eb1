// prune.cpp — the hierarchy (DESIGN.md §5): level by level, every child of a near-field cell
// is pruned starting from its parent's tape, in parallel over fixed chunks of cells so that the
// result does not depend on the thread count. Children of far-field cells are not stored.
//
// Memory: a level's tapes stay in their chunks' buffers, which are the next level's parents; the
// chunks are pruned in waves, and after each wave the parents' buffers no block left refers to
// are freed. Finest tapes go to the pool wave by wave; coarse tapes are dropped once they have
// served as parents (PruneOptions::coarse_tapes keeps them).
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <new>
#include <thread>
#include <unordered_map>
#include <utility>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

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

PrunedGrid::Pool::Pool(const Pool& other) : size(other.size), capacity(other.size) {
    if (size == 0) return;
    data = static_cast<uint32_t*>(std::malloc(size * sizeof(uint32_t)));
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

void PrunedGrid::Pool::shrink_to_fit() {
    if (size == 0 || size == capacity) return;
    if (void* p = std::realloc(data, size * sizeof(uint32_t))) {
        data = static_cast<uint32_t*>(p);
        capacity = size;
    }
}

namespace {

// Cells pruned per parallel task: fixed, so chunk boundaries (and the output) never depend on
// the number of threads.
constexpr uint32_t kChunkCells = 1024;

// Freed bytes worth handing back to the system (return_freed_memory).
constexpr uint64_t kReturnBytes = 64u << 20;

// One chunk's output: its cells' tapes as [length, primitives, words...] (the cells hold offsets
// into this buffer until it is placed in the pool), and statistics.
struct ChunkOut {
    std::vector<uint32_t> words;
    // Finest level only: statistics of the chunk's near-field cells.
    uint64_t near = 0, tape_sum = 0, prim_sum = 0, prim_sq_sum = 0;
    uint32_t tape_max = 0, prim_max = 0;
    uint64_t words_visited = 0, pruned = 0;
};

// Adds a chunk's counts to the sums in `st` (in chunk order, whatever the thread count).
void add_chunk_stats(const ChunkOut& o, PruneStats& st) {
    st.near_field_cells += o.near;
    st.tape_avg += double(o.tape_sum);
    st.tape_max = std::max(st.tape_max, o.tape_max);
    st.active_avg += double(o.prim_sum);
    st.active_std += double(o.prim_sq_sum);
    st.active_max = std::max(st.active_max, o.prim_max);
    st.cells_pruned += o.pruned;
    st.tape_words_visited += o.words_visited;
}

uint64_t bytes_of(const auto& v) {
    return uint64_t(v.capacity()) * sizeof(v[0]);
}

// The words of the tape whose header ([length, primitives]) is at `header`.
std::span<const uint32_t> tape_words(const uint32_t* header) {
    return {header + 2, header[0]};
}

// FNV-1a over a tape's header and words: finds identical tapes within a chunk.
uint64_t tape_hash(std::span<const uint32_t> tape) {
    uint64_t h = 0xcbf29ce484222325ull;
    for (const uint32_t w : tape) h = (h ^ w) * 0x100000001b3ull;
    return h;
}

// Hands memory freed to the C library back to the system. glibc keeps freed blocks below its
// (self-raising) mmap threshold in its heaps, where the parents freed during a level would go on
// counting in the process's memory; elsewhere nothing to do.
void return_freed_memory() {
#if defined(__GLIBC__)
    malloc_trim(0);
#endif
}

}  // namespace

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
    uint64_t peak = 0;

    // Far-field cells above the finest level count for all the finest cells they cover.
    uint64_t far_finest = 0;
    // The previous level's tapes, one buffer per chunk, and the current level's blocks: one per
    // near-field parent, with its origin (in this level's cells), its parent's chunk and tape.
    struct Block {
        uint32_t x, y, z;
        uint32_t chunk;
        const uint32_t* tape;  // header in parents[chunk]
    };
    std::vector<std::vector<uint32_t>> parents;
    parents.push_back(std::move(root));
    std::vector<Block> blocks{{0, 0, 0, 0, parents[0].data()}};
    uint64_t parent_bytes = bytes_of(parents[0]), done_cells_bytes = 0;
    uint64_t unreturned = 0;  // bytes freed since the last return_freed_memory()

    for (uint32_t li = 0; li < res.size(); ++li) {
        const bool finest = li + 1 == res.size();
        PrunedGrid::Level level;
        level.res = res[li];
        level.factor = li == 0 ? res[0] : res[li] / res[li - 1];
        const uint32_t f = level.factor;
        const uint64_t per_block = uint64_t(f) * f * f;
        const uint64_t total = per_block * blocks.size();
        if (total > 0xfffffffeull) throw std::length_error("too many cells in one level");
        level.cells.resize(total);
        const vec3 csize = extent / float(level.res);
        CellBox proto;
        proto.half = csize * 0.5f;
        proto.radius = math::length(proto.half);

        const uint32_t chunks = uint32_t((total + kChunkCells - 1) / kChunkCells);
        // Split blocks into octants first when the factor allows and chunks hold whole blocks.
        const bool split = opt.hierarchy && f >= 4 && f % 2 == 0 && kChunkCells % per_block == 0;
        std::vector<ChunkOut> outs(chunks);
        std::atomic<bool> cancelled{false};
        std::atomic<uint32_t> chunks_done{0};
        const std::thread::id caller = std::this_thread::get_id();
        // Progress is reported by the calling thread, which takes part in the parallel loop.
        const auto report = [&] {
            const uint32_t done = ++chunks_done;
            if (opt.progress && std::this_thread::get_id() == caller)
                opt.progress((double(li) + double(done) / chunks) / double(res.size()));
        };
        const auto prune_chunk = [&](uint32_t c) {
            struct OnExit {
                const decltype(report)& f;
                ~OnExit() { f(); }
            } on_exit{report};
            if (cancelled.load(std::memory_order_relaxed)) return;
            if (opt.cancel && opt.cancel->load(std::memory_order_relaxed)) {
                cancelled = true;
                return;
            }
            CellScratch& s = scratch.local();
            ChunkOut& out = outs[c];
            const uint64_t begin = uint64_t(c) * kChunkCells;
            const uint64_t end = std::min(total, begin + kChunkCells);
            const vec3 origin = sc.aabb.min;
            // The chunk's tapes by hash: a tape equal to one already stored is not stored again.
            std::unordered_map<uint64_t, uint32_t> stored;

            // Prunes cell i from `parent`, leaving far-field cells without a tape.
            const auto prune_cell = [&](uint64_t i, std::span<const uint32_t> parent,
                                        const CellBox& box) {
                PrunedCell& cell = level.cells[i];
                cell.value = evaluate_cell(sc, parent, box, opt.bounds, s);
                out.words_visited += parent.size();
                ++out.pruned;
                float constant = 0;
                if (opt.far_field &&
                    !is_near_field(sc, parent, box, opt.far_field_c, s, constant)) {
                    cell.tape = PrunedCell::kFarField;
                    cell.bound = constant;
                    return;
                }
                const size_t at = out.words.size();
                out.words.push_back(0);
                out.words.push_back(0);
                uint32_t prims = compact_tape(sc, parent, s, out.words);
                if (finest && opt.refine > 1 && out.words.size() - at - 2 <= math::kRefineMaxTape) {
                    // Decided again over the cell's sub-boxes, from the tape just made.
                    s.refined.assign(out.words.begin() + at + 2, out.words.end());
                    float refined_constant = 0;
                    if (!refine_cell(sc, s.refined, box, opt.refine, opt.bounds, opt.far_field,
                                     opt.far_field_c, s, refined_constant)) {
                        out.words.resize(at);
                        cell.tape = PrunedCell::kFarField;
                        cell.bound = refined_constant;
                        return;
                    }
                    out.words.resize(at + 2);
                    prims = compact_tape(sc, s.refined, s, out.words);
                }
                const uint32_t len = uint32_t(out.words.size() - at - 2);
                out.words[at] = len;
                out.words[at + 1] = prims;
                const std::span<const uint32_t> tape(out.words.data() + at, len + 2);
                const auto [it, fresh] = stored.try_emplace(tape_hash(tape), uint32_t(at));
                if (!fresh && out.words[it->second] == len &&
                    std::equal(tape.begin(), tape.end(), out.words.begin() + it->second)) {
                    out.words.resize(at);
                    cell.tape = it->second;
                } else {
                    cell.tape = uint32_t(at);
                }
                if (finest) {
                    ++out.near;
                    out.tape_sum += len;
                    out.tape_max = std::max(out.tape_max, len);
                    out.prim_sum += prims;
                    out.prim_sq_sum += uint64_t(prims) * prims;
                    out.prim_max = std::max(out.prim_max, prims);
                }
            };
            const auto cell_box = [&](uint32_t x, uint32_t y, uint32_t z) {
                CellBox box = proto;
                box.centre =
                    origin + vec3(float(x) + 0.5f, float(y) + 0.5f, float(z) + 0.5f) * csize;
                return box;
            };

            if (!split) {
                for (uint64_t i = begin; i < end; ++i) {
                    const Block& b = blocks[i / per_block];
                    const uint32_t local = uint32_t(i % per_block);
                    prune_cell(
                        i, tape_words(b.tape),
                        cell_box(b.x + local % f, b.y + (local / f) % f, b.z + local / (f * f)));
                }
            } else {
                // Each block in two steps: its 8 octants are pruned first (not stored), then
                // each cell from its octant's tape. Shorter parent tapes for the cells, same
                // guarantees: a tape valid in an octant is valid in every cell inside it.
                const uint32_t hf = f / 2;
                for (uint64_t bi = begin / per_block; bi < end / per_block; ++bi) {
                    const Block& b = blocks[bi];
                    const std::span<const uint32_t> parent = tape_words(b.tape);
                    for (uint32_t o = 0; o < 8; ++o) {
                        const uint32_t ox = (o & 1) * hf, oy = ((o >> 1) & 1) * hf,
                                       oz = ((o >> 2) & 1) * hf;
                        CellBox obox;
                        obox.half = proto.half * float(hf);
                        obox.radius = proto.radius * float(hf);
                        obox.centre = origin + vec3(float(b.x + ox) + 0.5f * float(hf),
                                                    float(b.y + oy) + 0.5f * float(hf),
                                                    float(b.z + oz) + 0.5f * float(hf)) *
                                                   csize;
                        const float ov = evaluate_cell(sc, parent, obox, opt.bounds, s);
                        out.words_visited += parent.size();
                        float oconst = 0;
                        const bool far =
                            opt.far_field &&
                            !is_near_field(sc, parent, obox, opt.far_field_c, s, oconst);
                        std::span<const uint32_t> otape = parent;
                        if (!far) {
                            s.octant.clear();
                            compact_tape(sc, parent, s, s.octant);
                            if (s.octant.size() < parent.size()) otape = s.octant;
                        }
                        for (uint32_t lz = oz; lz < oz + hf; ++lz)
                            for (uint32_t ly = oy; ly < oy + hf; ++ly)
                                for (uint32_t lx = ox; lx < ox + hf; ++lx) {
                                    const uint64_t i = bi * per_block + (lz * f + ly) * f + lx;
                                    const CellBox box = cell_box(b.x + lx, b.y + ly, b.z + lz);
                                    if (!far) {
                                        // otape may be s.octant: the cell's pruning uses the
                                        // other scratch arrays only.
                                        prune_cell(i, otape, box);
                                        continue;
                                    }
                                    // A far octant makes far cells: its constant holds in each;
                                    // the centre value is a conservative stand-in (same sign,
                                    // never larger in magnitude) moved from the octant centre.
                                    PrunedCell& cell = level.cells[i];
                                    const float reach =
                                        g.lipschitz_ * math::length(box.centre - obox.centre);
                                    cell.tape = PrunedCell::kFarField;
                                    cell.bound = oconst;
                                    cell.value = ov > 0 ? std::max(ov - reach, oconst)
                                                        : std::min(ov + reach, oconst);
                                }
                    }
                }
            }
            // Coarse buffers live on as the next level's parents: no slack.
            if (!finest) out.words.shrink_to_fit();
        };

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
        uint32_t released = 0;                         // parents[0, released) are freed
        with_threads(opt.threads, [&] {
            // Waves of chunks: enough for load balance, few enough that parents are freed early
            // and finest buffers are few. Output does not depend on the wave size.
            const uint32_t wave =
                16 * uint32_t(std::max(1, tbb::this_task_arena::max_concurrency()));
            for (uint32_t w0 = 0; w0 < chunks; w0 += wave) {
                const uint32_t w1 = std::min(chunks, w0 + wave);
                tbb::parallel_for(w0, w1, prune_chunk);
                if (cancelled) return;
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
                peak = std::max(peak, pool_bytes() + parent_bytes + level_bytes + wave_bytes +
                                          done_cells_bytes + bytes_of(blocks));
                if (finest)
                    for (uint32_t c = w0; c < w1; ++c) std::vector<uint32_t>().swap(outs[c].words);
                // Free the parents that no block from the next wave on refers to.
                const uint64_t next_cell = uint64_t(w1) * kChunkCells;
                const uint32_t needed = next_cell < total ? blocks[next_cell / per_block].chunk
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
        });
        if (cancelled) throw PruneCancelled();

        // Far-field cells of this level, and the next level's blocks: one per near-field cell.
        const uint64_t below = uint64_t(N / level.res);
        std::vector<Block> next;
        for (uint64_t i = 0; i < total; ++i) {
            PrunedCell& cell = level.cells[i];
            if (cell.tape == PrunedCell::kFarField) {
                if (!finest)
                    far_finest += below * below * below;
                else
                    ++far_finest;
                continue;
            }
            if (finest) continue;
            const Block& b = blocks[i / per_block];
            const uint32_t local = uint32_t(i % per_block);
            const uint32_t nf = res[li + 1] / res[li];
            const uint32_t c = uint32_t(i / kChunkCells);
            cell.children = uint32_t(next.size() * nf * nf * nf);
            next.push_back({(b.x + local % f) * nf, (b.y + (local / f) % f) * nf,
                            (b.z + local / (f * f)) * nf, c, outs[c].words.data() + cell.tape});
        }
        blocks.swap(next);
        if (!finest) {
            // This level's buffers become the parents; the cells' offsets into them go.
            parents.clear();
            parent_bytes = 0;
            for (uint32_t c = 0; c < chunks; ++c) {
                place_chunk(c, opt.coarse_tapes);
                parent_bytes += bytes_of(outs[c].words);
                parents.push_back(std::move(outs[c].words));
            }
            peak = std::max(peak, pool_bytes() + parent_bytes + bytes_of(level.cells) +
                                      done_cells_bytes + bytes_of(blocks));
        }
        done_cells_bytes += bytes_of(level.cells);
        const uint32_t scale = N / level.res;
        if (std::has_single_bit(scale) && std::has_single_bit(level.factor)) {
            level.pow2 = true;
            level.shift = uint32_t(std::countr_zero(scale));
            level.factor_bits = uint32_t(std::countr_zero(level.factor));
        }
        g.level_size_.push_back(csize);
        g.levels_.push_back(std::move(level));
        if (opt.progress) opt.progress(double(li + 1) / double(res.size()));
    }
    g.pool_.shrink_to_fit();

    g.build_shortcut();

    // Until here active_avg, active_std and tape_avg held the near-field cells' sums.
    finish_prune_stats(st, st.active_avg, st.active_std, st.tape_avg, far_finest);
    st.tape_bytes = pool_bytes();
    for (const PrunedGrid::Level& l : g.levels_) st.tape_bytes += bytes_of(l.cells);
    st.prune_peak_bytes = std::max(peak, st.tape_bytes);
    for (const CellScratch& s : scratch)
        st.prune_peak_bytes += bytes_of(s.value) * 3 + bytes_of(s.left) * 4 + bytes_of(s.alive) * 2;
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

bool PrunedGrid::cell_index(vec3 p, uint32_t& ix, uint32_t& iy, uint32_t& iz) const {
    const uint32_t N = resolution();
    const vec3 q = p - scene_->aabb.min;
    uint32_t idx[3];
    for (int a = 0; a < 3; ++a) {
        // The closed box itself decides (q · 1/size can round past N on the max faces).
        if (!(p[a] >= scene_->aabb.min[a]) || !(p[a] <= scene_->aabb.max[a])) return false;
        idx[a] = std::min(uint32_t(q[a] * inv_cell_size_[a]), N - 1);
    }
    ix = idx[0];
    iy = idx[1];
    iz = idx[2];
    return true;
}

vec3 PrunedGrid::cell_center(uint32_t ix, uint32_t iy, uint32_t iz) const {
    return scene_->aabb.min +
           vec3(float(ix) + 0.5f, float(iy) + 0.5f, float(iz) + 0.5f) * cell_size_;
}

float far_field_cell_constant(vec3 origin, vec3 cell_size, uint32_t scale, float lipschitz,
                              const PrunedCell& c, uint32_t ix, uint32_t iy, uint32_t iz) {
    // The Lipschitz bound from the coarse centre over the distance to this finest cell's far
    // corner; tighter than the coarse cell's own constant for cells near its centre.
    const vec3 coarse = origin + vec3(float(ix / scale) + 0.5f, float(iy / scale) + 0.5f,
                                      float(iz / scale) + 0.5f) *
                                     (cell_size * float(scale));
    const vec3 centre =
        origin + vec3(float(ix) + 0.5f, float(iy) + 0.5f, float(iz) + 0.5f) * cell_size;
    const vec3 d = math::abs(centre - coarse) + cell_size * 0.5f;
    return far_field_combine(c.value, c.bound, far_field_reach(lipschitz, math::length(d)));
}

float PrunedGrid::far_field_constant(uint32_t level, const PrunedCell& c, uint32_t ix, uint32_t iy,
                                     uint32_t iz) const {
    return far_field_cell_constant(scene_->aabb.min, cell_size_, resolution() / levels_[level].res,
                                   lipschitz_, c, ix, iy, iz);
}

CellView PrunedGrid::cell(uint32_t ix, uint32_t iy, uint32_t iz) const {
    const uint32_t N = resolution();
    uint32_t block_start = 0;
    for (uint32_t li = 0; li < levels_.size(); ++li) {
        const Level& l = levels_[li];
        const PrunedCell& c = l.cells[block_start + l.local_index(ix, iy, iz, N)];
        CellView v;
        if (c.tape == PrunedCell::kFarField) {
            v.far_field = true;
            v.constant = far_field_constant(li, c, ix, iy, iz);
            return v;
        }
        if (li + 1 == levels_.size()) {
            v.far_field = false;
            v.tape = tape_at(c.tape);
            v.primitives = pool_.data[c.tape + 1];
            return v;
        }
        block_start = c.children;
    }
    return {};
}

void PrunedGrid::build_shortcut() {
    constexpr uint32_t kMaxEntries = 1u << 21;
    if (levels_.size() < 3 || !levels_.back().pow2) return;
    const uint32_t S = uint32_t(levels_.size() - 2), r = levels_[S].res;
    if (uint64_t(r) * r * r > kMaxEntries) return;
    for (const Level& l : levels_)
        if (l.cells.size() >= (1u << 27) || !l.pow2) return;
    shortcut_level_ = S;
    shortcut_.resize(size_t(r) * r * r);
    const uint32_t N = resolution(), scale = N / r;
    for (uint32_t z = 0; z < r; ++z)
        for (uint32_t y = 0; y < r; ++y)
            for (uint32_t x = 0; x < r; ++x) {
                const uint32_t ix = x * scale, iy = y * scale, iz = z * scale;
                uint32_t block_start = 0, li = 0;
                for (;; ++li) {
                    const uint32_t index = block_start + levels_[li].local_index(ix, iy, iz, N);
                    const PrunedCell& c = levels_[li].cells[index];
                    if (li == S || c.tape == PrunedCell::kFarField) {
                        shortcut_[(size_t(z) * r + y) * r + x] = li << 27 | index;
                        break;
                    }
                    block_start = c.children;
                }
            }
}

bool PrunedGrid::locate(vec3 p, Located& out) const {
    uint32_t ix, iy, iz;
    if (!cell_index(p, ix, iy, iz)) return false;
    const uint32_t N = resolution();
    if (!shortcut_.empty()) {
        const Level& s = levels_[shortcut_level_];
        const uint32_t sx = ix >> s.shift, sy = iy >> s.shift, sz = iz >> s.shift;
        const uint32_t entry = shortcut_[(size_t(sz) * s.res + sy) * s.res + sx];
        uint32_t li = entry >> 27;
        const PrunedCell* c = &levels_[li].cells[entry & ((1u << 27) - 1)];
        if (c->tape != PrunedCell::kFarField) {
            li = shortcut_level_ + 1;
            c = &levels_[li].cells[c->children + levels_[li].local_index(ix, iy, iz, N)];
        }
        const uint32_t shift = levels_[li].shift;
        out = {li, ix >> shift, iy >> shift, iz >> shift, c};
        return true;
    }
    uint32_t block_start = 0;
    for (uint32_t li = 0; li < levels_.size(); ++li) {
        const Level& l = levels_[li];
        const PrunedCell& c = l.cells[block_start + l.local_index(ix, iy, iz, N)];
        if (c.tape == PrunedCell::kFarField || li + 1 == levels_.size()) {
            if (l.pow2) {
                out = {li, ix >> l.shift, iy >> l.shift, iz >> l.shift, &c};
            } else {
                const uint32_t scale = N / l.res;
                out = {li, ix / scale, iy / scale, iz / scale, &c};
            }
            return true;
        }
        block_start = c.children;
    }
    return false;
}

float PrunedGrid::eval(vec3 p, float* stack) const {
    uint32_t x, y, z;
    if (!cell_index(p, x, y, z)) return eval_tape(*scene_, scene_->full_tape, p, stack);
    const CellView c = cell(x, y, z);
    return c.far_field ? c.constant : eval_tape(*scene_, c.tape, p, stack);
}

void PrunedGrid::eval_points(std::span<const vec3> points, std::span<float> out) const {
    if (out.size() != points.size()) throw std::invalid_argument("eval_points: size mismatch");
    with_threads(options_.threads, [&] {
        tbb::parallel_for(tbb::blocked_range<size_t>(0, points.size(), 256),
                          [&](const tbb::blocked_range<size_t>& r) {
                              std::vector<float> stack(scene_->max_stack);
                              for (size_t i = r.begin(); i != r.end(); ++i)
                                  out[i] = eval(points[i], stack.data());
                          });
    });
}

}  // namespace sdfprune
