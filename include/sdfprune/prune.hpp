// prune.hpp — hierarchical Lipschitz pruning with far-field culling (DESIGN.md §3–5; Barbier et
// al., "Lipschitz Pruning: Hierarchical Simplification of Primitive-Based SDFs", EG 2025).
//
// prune(scene, options) covers the scene's AABB with a grid of resolution³ box cells, built as
// levels of factor³ subdivision (4³, 16³, 64³, 256³ by default). Every cell of the finest grid
// ends up either
//   - near-field: a tape (post-order (node, sign) words) that returns exactly the full tree's
//     value everywhere in the cell, usually a handful of nodes, or
//   - far-field: a constant c with sign(c) = sign(f) and |c| <= |f| everywhere in the cell,
//     a safe sphere-tracing step.
// Storage is sparse: only children of near-field cells exist, and identical tapes of cells pruned
// together (a chunk of 1024 cells) are stored once. Only the finest level's tapes are kept unless
// PruneOptions::coarse_tapes asks for the coarse ones too. Output is identical whatever the thread
// count.
//
// Thread-safety: a PrunedGrid is immutable; any number of threads may query it. It refers to
// the Scene it was built from, which must outlive it, unless it was made by the overload of
// prune() taking a std::shared_ptr, which keeps the scene alive (shared ownership).
#pragma once

#include <algorithm>
#include <atomic>
#include <cmath>
#include <functional>
#include <memory>
#include <new>
#include <span>
#include <type_traits>
#include <utility>
#include <vector>

#include "scene.hpp"

namespace sdfprune {

// How an operand's range over a cell is bounded in the pruning test.
enum class CellBounds {
    kLipschitz,  // the paper's: value at the centre ± L·R (R = half-diagonal)
    kInterval,   // tighter and still exact: the Lipschitz range intersected with exact ranges
                 // of primitives under similarity maps (over the box, not the ball) and ranges
                 // propagated through operators; also tightens far-field constants
};

struct PruneOptions {
    uint32_t resolution = 256;  // finest cells per axis (>= 1)
    uint32_t factor = 4;        // subdivision per level (>= 2); levels: see grid_levels()
    bool far_field = true;      // cull cells far from the surface to a constant
    bool hierarchy = true;      // false: prune the full tree directly in every finest cell
    float far_field_c = 2.0f;   // a cell is far-field when |f(centre)| > C·L·R (C >= 1)
    CellBounds bounds = CellBounds::kInterval;
    // Finest cells are decided again over refine³ sub-boxes (1 = off): an operator is skipped
    // where every sub-box decides it the same way, and the cell is far-field where every
    // sub-box's range clears its margin. Tighter, still exact (the ranges cover the cell).
    uint32_t refine = 3;
    // Keep the pruned tapes of coarse near-field cells in the tape pool (inspection, tests).
    // False: those cells refer to the full tree's tape (offset 0), and the pool holds only the
    // finest level's tapes: every lookup is the same, memory is far smaller on large scenes.
    bool coarse_tapes = false;
    // Far-field clearances (set_clearance): tracers skip whole boxes of far-field cells (about
    // a third fewer steps on molecule and trees). Costs pruning time, about 1G instructions at
    // 256³ (the clearance_ms statistic: +100-120 ms on 2 cores, a third to a half more on
    // molecule and trees), which pays only for tracing: off by default; `sdfprune render` and
    // `sdfprune bench` turn it on. False: every far-field cell's clearance is 0 and the tracer
    // steps cell by cell.
    bool clearance = false;
    int threads = 0;  // 0 = all hardware threads
    // Called from the calling thread with the fraction done in [0, 1]; may be empty.
    std::function<void(double)> progress;
    // When set and true, prune() stops early and throws PruneCancelled.
    const std::atomic<bool>* cancel = nullptr;
};

struct PruneCancelled : std::runtime_error {
    PruneCancelled() : std::runtime_error("pruning cancelled") {}
};

// Cells per axis of each level, coarse to fine: resolution = r0 · factor^k with the largest k
// such that r0 >= 2 (256, 4 → 4 16 64 256; 128, 4 → 2 8 32 128; 100, 4 → 25 100). Without
// hierarchy: just {resolution}.
std::vector<uint32_t> grid_levels(uint32_t resolution, uint32_t factor, bool hierarchy = true);

// Whether the level of `res` cells per axis, in blocks `factor` wide, prunes each block's 8
// octants first and then every cell from its octant's tape, or every cell from its block's
// tape directly (both backends decide so, and give the same cells). The octants shorten the
// tapes the cells walk, so most levels take them (a hierarchy, an even factor >= 4). The top
// levels do not, where they have at most kDirectMaxParents parents and the level's cells times
// the scene's full tape (the longest a cell can walk) are at most kDirectMaxCellWords
// (SDFPRUNE_DIRECT_CELL_WORDS sets another bound, for comparisons): there a few long tapes are
// walked one node after another, and on a GPU the octants' walk is a step of its own about as
// long as the cells' (the reference molecule's level-0 octants took 0.54 ms of 8.1 on an
// H200, for tapes no shorter than the root's). The bound keeps such a step's scratch (on the
// GPU 13 bytes per tape entry and cell, shaders/gpu/prune_wide.glsl) within 256 MB: the
// reference molecule's levels 0 and 1 are direct, the generated fluid's (27,977 words) level 0
// only, a scene of up to 262,144 words its level 0.
constexpr uint32_t kDirectMaxParents = 64;
constexpr uint64_t kDirectMaxCellWords = uint64_t(1) << 24;
bool splits_into_octants(const Scene& scene, const PruneOptions& options, uint32_t res,
                         uint32_t factor);

struct PruneStats {
    uint32_t grid = 0;              // finest resolution
    uint64_t cells = 0;             // grid³
    uint64_t near_field_cells = 0;  // finest cells holding a tape
    // Active primitives per finest cell over all cells, a far-field cell counting as 1 (the
    // metric of the paper's Table 2).
    double active_avg = 0, active_std = 0;
    uint32_t active_max = 0;
    // Tape length in nodes over near-field finest cells only.
    double tape_avg = 0;
    uint32_t tape_max = 0;
    double near_field_prims_avg = 0;  // active primitives over near-field finest cells only
    double prune_ms = 0;              // wall time of prune()
    // Peak bytes allocated at once by pruning's own buffers: tapes (the pool, the parents' and
    // the current level's), cells, blocks, per-thread scratch. The scene is not counted.
    uint64_t prune_peak_bytes = 0;
    uint64_t tape_bytes = 0;          // bytes of the final structure (cells + tape pool)
    uint64_t cells_pruned = 0;        // cells whose tape was pruned, all levels
    uint64_t tape_words_visited = 0;  // tape words processed by the pruning, all levels
    // The far-field clearances (set_clearance), within prune_ms: wall time, and the peak bytes
    // of its working sets (freed when done: the clearances live in the cells' own words).
    double clearance_ms = 0;
    uint64_t clearance_bytes = 0;
    std::vector<uint32_t> levels;
};

// Fills the averages of `st` (near_field_cells, cells and active_max counted already) from the
// sums over near-field finest cells of primitives, their squares and tape lengths, and the
// number of far-field finest cells (each counting 1 active primitive: Table 2's metric). The
// CPU and GPU backends both finish their statistics with it.
void finish_prune_stats(PruneStats& st, double prim_sum, double prim_sq_sum, double tape_sum,
                        uint64_t far_finest);

// One cell of a level.
struct PrunedCell {
    static constexpr uint32_t kFarField = 0xffffffffu;
    // Offset of the tape's header in PrunedGrid::tape_pool(). Coarse levels: 0 (the full tree,
    // valid but not pruned) unless PruneOptions::coarse_tapes.
    uint32_t tape = kFarField;
    // Near-field, not finest: first cell of its child block. Far-field: its clearances, 4 bits
    // per octant (see set_clearance).
    uint32_t children = 0;
    // The tree's value at the cell centre; for far-field cells made from a far-field octant
    // (see prune_level.cpp) a same-sign value no larger in magnitude, which is all lookups need.
    float value = 0;
    float bound = 0;  // far-field: constant valid over the whole cell
};

// An allocator whose construct() without arguments leaves the element's bytes as they are, so
// that a vector of it grows without writing: prune() sizes a level's cells at once and lets the
// threads that prune them write them, touching their pages first, in parallel (a serial
// value-initialization of the finest level's 30 MB took 5 % of trees' pruning). For trivial types
// only; whoever resizes writes every new element before it is read.
// Storage starts on a 64-byte line: a row of 4 cells of a z-major 4³ block is then one line
// (malloc's large blocks start 16 bytes past a page, which split every row over two lines).
template <class T>
struct UninitializedAllocator : std::allocator<T> {
    static_assert(std::is_trivially_copyable_v<T> && std::is_trivially_destructible_v<T>);
    using value_type = T;
    static constexpr std::align_val_t kAlignment{64};
    T* allocate(size_t n) { return static_cast<T*>(::operator new(n * sizeof(T), kAlignment)); }
    void deallocate(T* p, size_t) noexcept { ::operator delete(p, kAlignment); }
    UninitializedAllocator() = default;
    template <class U>
    UninitializedAllocator(const UninitializedAllocator<U>&) noexcept {}
    template <class U>
    struct rebind {
        using other = UninitializedAllocator<U>;
    };
    template <class U>
    void construct(U*) noexcept {}
    template <class U, class... Args>
    void construct(U* p, Args&&... args) {
        ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
    }
};

// The cells of one level of a PrunedGrid.
using CellVector = std::vector<PrunedCell, UninitializedAllocator<PrunedCell>>;

// The far-field arithmetic, in one place (sdf_math.h; PrunedGrid::far_field_constant,
// discretize's fill and the GPU kernels use it).
using math::far_field_combine;
using math::far_field_reach;

// The far-field constant of finest cell (ix, iy, iz) (cells of size `cell_size` from `origin`)
// lying in far-field cell `c`, `scale` finest cells wide, of a field with Lipschitz bound
// `lipschitz`: the tighter of c.bound and the Lipschitz bound from c's centre value over the
// distance to the finest cell's far corner. PrunedGrid::far_field_constant; the GPU read-back.
float far_field_cell_constant(vec3 origin, vec3 cell_size, uint32_t scale, float lipschitz,
                              const PrunedCell& c, uint32_t ix, uint32_t iy, uint32_t iz);

// Cell `local` (z-major: local = (z·f + y)·f + x) of a block f cells wide whose first cell is
// at `origin`: its coordinates at the block's level.
struct CellCoord {
    uint32_t x = 0, y = 0, z = 0;
};
inline CellCoord block_cell(CellCoord origin, uint32_t f, uint32_t local) {
    return {origin.x + local % f, origin.y + (local / f) % f, origin.z + local / (f * f)};
}

// ---- far-field clearance (clearance.cpp): tracers skip whole blocks of far-field cells ----
// A far-field cell's clearance in octant o (bit a of o set: towards +axis a, clear: towards
// -axis a) is the largest r <= kMaxClearance such that none of the (r + 1)³ cells of its level
// from it r cells along each axis the octant's way holds a near-field finest cell (cells
// outside the grid count, and hold none). Every point of those cells lies in some far-field
// cell (of some level), so no surface is there: a ray
// in the cell heading into octant o may go on from the exit of that box. Stored in the cell's
// `children`, bits [4o, 4o + 4): clearance_in.
constexpr uint32_t kMaxClearance = 15;
inline uint32_t clearance_in(const PrunedCell& far_cell, uint32_t octant) {
    return far_cell.children >> (4 * octant) & kMaxClearance;
}
// Levels wider than this keep clearance 0 (a level's near-field set costs res³ / 8 bytes:
// 2 MB at 256³, 16 MB at 512³).
constexpr uint32_t kClearanceMaxRes = 512;
// A level of a grid's raw structure (see PrunedGrid::level_cells), writable.
struct LevelCells {
    uint32_t res = 0, factor = 0;
    std::span<PrunedCell> cells;
};
// A box of finest cells, [lo, hi) along each axis.
struct CellRange {
    CellCoord lo, hi;
};
// Sets the clearances of the far-field cells reachable from level 0's block, on at most
// `threads` workers (0: all): of every one when `changed` is null; else of those within reach
// of `changed`, a box of finest cells outside which no cell changed between near-field and
// far-field (nor appeared or went) since the clearances were last set (update() after an
// edit). prune() and update() call it; the GPU backend calls it on its cells read back.
// Returns the peak bytes of its working sets.
uint64_t set_clearance(std::span<const LevelCells> levels, int threads = 0,
                       const CellRange* changed = nullptr);

// What a finest cell holds.
struct CellView {
    bool far_field = true;
    float constant = 0;              // far-field: sign(f)·(lower bound of |f|) in this cell
    std::span<const uint32_t> tape;  // near-field
    uint32_t primitives = 0;         // near-field: primitives in the tape
};

struct SceneEdit;
class GridUpdate;

class PrunedGrid {
  public:
    const Scene& scene() const { return *scene_; }
    const Aabb& aabb() const { return scene_->aabb; }
    // A box within aabb() that holds every near-field cell, hence the whole surface (f = 0 lies
    // in no far-field cell): the bounds of the near-field finest cells, one finest cell wider
    // (finest_cells_box); aabb() on a one-level grid. Empty (min > max) when there is no
    // near-field finest cell. Tracers march rays within it only.
    const Aabb& near_box() const { return near_box_; }
    uint32_t resolution() const { return levels_.back().res; }
    vec3 cell_size() const { return cell_size_; }
    vec3 inv_cell_size() const { return inv_cell_size_; }  // what cell_index multiplies by
    const PruneStats& stats() const { return stats_; }
    const PruneOptions& options() const { return options_; }

    // Finest cell holding p; false when p lies outside the grid (then use the full tree).
    bool cell_index(vec3 p, uint32_t& ix, uint32_t& iy, uint32_t& iz) const;
    CellView cell(uint32_t ix, uint32_t iy, uint32_t iz) const;
    vec3 cell_center(uint32_t ix, uint32_t iy, uint32_t iz) const;

    // The pruned field at p: the cell's tape, or its far-field constant; outside the grid the
    // full tree. `stack` must hold scene().max_stack floats.
    float eval(vec3 p, float* stack) const;
    // Batch version, in parallel (threads as in the options it was built with).
    void eval_points(std::span<const vec3> points, std::span<float> out) const;

    // Where p falls: the cell at the coarsest level that decides it (a far-field cell at any
    // level, or a near-field finest cell), with its coordinates at that level. False outside
    // the grid. Used by tracers to skip whole far-field blocks.
    struct Located {
        uint32_t level = 0;
        uint32_t x = 0, y = 0, z = 0;
        const PrunedCell* cell = nullptr;
        bool far_field() const { return cell->tape == PrunedCell::kFarField; }
    };
    bool locate(vec3 p, Located& out) const;
    // The same for finest cell (ix, iy, iz) (from cell_index, or a tracer's own clamped index).
    void locate_cell(uint32_t ix, uint32_t iy, uint32_t iz, Located& out) const;
    // Size of a cell of level `level`.
    vec3 level_cell_size(uint32_t level) const { return level_size_[level]; }

    // locate_cell's walk in stages, for a tracer that interleaves the lookups of several rays
    // and prefetches what each names next (most of the structure is out of cache): walk_begin
    // names the first word to read, each walk_step reads the word named and names the next,
    // until the deciding cell (then read, so in cache) is reached. walk_located gives
    // locate_cell's answer. On a grid with a lookup shortcut (built when every level is a power
    // of two and the level above the finest is small enough) the walk is two steps at most: the
    // shortcut's entry, which names either the deciding far-field cell or, where the cell of the
    // level above the finest is near-field, its block of finest cells, then that block's finest
    // cell. This is the one implementation of the lookup: locate_cell runs it to the end.
    struct Walk {
        uint32_t ix = 0, iy = 0, iz = 0;   // the finest cell looked up
        uint32_t level = 0;                // of `cell`
        const uint32_t* entry = nullptr;   // the shortcut's entry to read next, if any
        const PrunedCell* cell = nullptr;  // else the cell to read next, or the deciding one
        bool decided = false;              // `cell` is the deciding one (perhaps not read yet)
        const void* next() const { return entry ? static_cast<const void*>(entry) : cell; }
    };
    Walk walk_begin(uint32_t ix, uint32_t iy, uint32_t iz) const;
    // Reads what w names; true when w.cell is the deciding cell, false when w names a new word.
    bool walk_step(Walk& w) const;
    Located walk_located(const Walk& w) const;

    // The far-field constant of finest cell (ix, iy, iz) lying in far-field cell `c` of level
    // `level`: the tighter of c.bound and the Lipschitz bound from c's centre value.
    float far_field_constant(uint32_t level, const PrunedCell& c, uint32_t ix, uint32_t iy,
                             uint32_t iz) const;

    // ---- the walk down the hierarchy: every lookup and traversal goes through these ----
    // A cell of the structure: level_cells(level)[index].
    struct CellRef {
        uint32_t level = 0, index = 0;
    };
    // From the block of level `level` starting at cell `first` (default: level 0) towards finest
    // cell (ix, iy, iz): the first cell on the way that is far-field or at level `stop`. The
    // starting block must contain the finest cell (a near-field cell's children do).
    CellRef descend(uint32_t ix, uint32_t iy, uint32_t iz, uint32_t stop, uint32_t level = 0,
                    uint32_t first = 0) const {
        for (;; ++level) {
            const CellRef at = block_cell_at(level, first, ix, iy, iz);
            const PrunedCell& c = levels_[level].cells[at.index];
            if (level >= stop || c.tape == PrunedCell::kFarField) return at;
            first = c.children;
        }
    }
    // One step of descend: the cell of the block of `level` starting at `first` that holds
    // finest cell (ix, iy, iz).
    CellRef block_cell_at(uint32_t level, uint32_t first, uint32_t ix, uint32_t iy,
                          uint32_t iz) const {
        return {level, first + levels_[level].local_index(ix, iy, iz, resolution())};
    }
    // A block of level `level`: cells [first, first + f³) with f = level_factor(level) (level 0:
    // the whole level), its first cell at `origin` in that level's cells.
    struct Block {
        uint32_t level = 0, first = 0;
        CellCoord origin;
    };
    uint32_t level_factor(uint32_t level) const { return levels_[level].factor; }
    // The block of children of cell `local` of block b (near-field, b.level not the finest).
    Block child_block(const Block& b, uint32_t local) const {
        const uint32_t f = levels_[b.level].factor, nf = levels_[b.level + 1].factor;
        const CellCoord c = block_cell(b.origin, f, local);
        return {b.level + 1,
                levels_[b.level].cells[b.first + local].children,
                {c.x * nf, c.y * nf, c.z * nf}};
    }
    // Every block of the hierarchy, each before its children, calling fn(block): the one
    // traversal of the whole structure. Depth first, children blocks in reverse z-major order
    // of their parents (a fixed order: callers may rely on it for deterministic output).
    template <class F>
    void for_each_block(const F& fn) const {
        std::vector<Block> stack{Block{}};
        while (!stack.empty()) {
            const Block b = stack.back();
            stack.pop_back();
            fn(b);
            if (b.level + 1 == levels_.size()) continue;
            const uint32_t f = levels_[b.level].factor;
            const PrunedCell* cells = levels_[b.level].cells.data() + b.first;
            for (uint32_t local = 0; local < f * f * f; ++local)
                if (cells[local].tape != PrunedCell::kFarField)
                    stack.push_back(child_block(b, local));
        }
    }

    // Raw structure, for backends and tests. Level 0 holds level_resolution(0)³ cells in
    // z-major order (index (z·r + y)·r + x). Each near-field cell of level l < last has its
    // children in level l+1 at [children, children + f³), f = level_resolution(l+1) /
    // level_resolution(l), in the same z-major order within the block; far-field cells have no
    // children. The tape pool holds each tape as [length, primitive count, words...], the full
    // tree's first (offset 0); cells may share a tape.
    std::span<const PrunedCell> level_cells(uint32_t level) const { return levels_[level].cells; }
    uint32_t level_count() const { return uint32_t(levels_.size()); }
    uint32_t level_resolution(uint32_t level) const { return levels_[level].res; }
    std::span<const uint32_t> tape_pool() const { return {pool_.data, pool_.size}; }
    std::span<const uint32_t> tape_at(uint32_t offset) const {
        return {pool_.data + offset + 2, pool_.data[offset]};
    }

  private:
    friend PrunedGrid prune(const Scene&, const PruneOptions&);
    friend PrunedGrid prune(std::shared_ptr<const Scene>, const PruneOptions&);
    friend class GridUpdate;              // prune_update.cpp: edits a grid in place
    std::shared_ptr<const Scene> owner_;  // set by the shared-ownership prune(); else empty
    struct Level {
        uint32_t res = 0;     // cells per axis of the whole level
        uint32_t factor = 0;  // cells per axis of one block (level 0: res)
        CellVector cells;
        Level() = default;
        // A copy keeps the spare capacity update() reserves for the blocks edits append.
        Level(const Level& o)
            : res(o.res),
              factor(o.factor),
              pow2(o.pow2),
              shift(o.shift),
              factor_bits(o.factor_bits) {
            cells.reserve(o.cells.capacity());
            cells = o.cells;
        }
        Level(Level&&) = default;
        Level& operator=(const Level&) = default;
        Level& operator=(Level&&) = default;
        // When finest-cells-per-cell and factor are powers of two, lookups use shifts.
        bool pow2 = false;
        uint32_t shift = 0, factor_bits = 0;
        // Index within its block of the level cell holding finest cell (ix, iy, iz).
        uint32_t local_index(uint32_t ix, uint32_t iy, uint32_t iz, uint32_t N) const {
            if (pow2) return local_index_pow2(ix, iy, iz);
            return math::block_local_index(ix, iy, iz, N / res, factor);
        }
        // The same, for a pow2 level (shifts and masks only).
        uint32_t local_index_pow2(uint32_t ix, uint32_t iy, uint32_t iz) const {
            return block_local_pow2(ix >> shift, iy >> shift, iz >> shift);
        }
        // Index within its block of cell (x, y, z) of this pow2 level.
        uint32_t block_local_pow2(uint32_t x, uint32_t y, uint32_t z) const {
            const uint32_t m = factor - 1;
            return ((z & m) << factor_bits | (y & m)) << factor_bits | (x & m);
        }
    };
    const Scene* scene_ = nullptr;
    PruneOptions options_;
    std::vector<Level> levels_;
    // The tape pool grows with realloc while the finest level is appended: a large block is
    // moved page by page (mremap on Linux) where a std::vector would copy it next to its old
    // buffer, holding both at once.
    struct Pool {
        uint32_t* data = nullptr;
        size_t size = 0, capacity = 0;
        Pool() = default;
        Pool(const Pool& other);
        Pool(Pool&& other) noexcept;
        Pool& operator=(Pool other) noexcept;
        ~Pool();
        void append(std::span<const uint32_t> words);  // grows the capacity by half at least
        void reserve(size_t words);                    // capacity for at least `words`
        void shrink_to_fit();
    };
    Pool pool_;
    vec3 cell_size_;
    vec3 inv_cell_size_;
    std::vector<vec3> level_size_;  // cell size of each level
    // Lookup shortcut, which walk_begin reads first: for every cell of level shortcut_level_
    // (the one above the finest; z-major), the far-field cell at or above it that decides it,
    // as level << kShortcutLevelShift | index in its level's cells, or, where that cell is
    // near-field, kShortcutChildren | the first finest cell of its children (so a lookup there
    // reads no coarse cell: that read, at once and not prefetched, missed D1 in one of eight
    // lookups on character at 256³); empty when not worth it. When there is one, every level's
    // resolution and block factor are powers of two: finest index >> shortcut_shift_ is the
    // shortcut level's cell, shortcut_res_ that level's resolution.
    static constexpr uint32_t kShortcutLevelShift = 27;
    static constexpr uint32_t kShortcutChildren = 1u << 31;
    std::vector<uint32_t> shortcut_;
    uint32_t shortcut_level_ = 0, shortcut_shift_ = 0, shortcut_res_ = 0;
    void build_shortcut();
    Aabb near_box_;
    void find_near_box();  // sets near_box_ (prune(), and update() after an edit)
    // The shortcut's entry of shortcut-level cell (x, y, z) (build_shortcut, and update()
    // where cells above it or the cell itself changed between near-field and far-field).
    uint32_t shortcut_entry(uint32_t x, uint32_t y, uint32_t z) const;
    void build_clearance(const CellRange* changed = nullptr);  // set_clearance on levels_
    // The Located of finest cell (ix, iy, iz), decided by `cell` of level `level`.
    Located located_at(uint32_t level, const PrunedCell* cell, uint32_t ix, uint32_t iy,
                       uint32_t iz) const;
    float lipschitz_ = 1;  // of the root: bounds the far-field constants
    PruneStats stats_;
    // Kept by update() (prune_update.cpp), so that statistics follow an edit without a walk of
    // the whole grid: the finest level's counts, with histograms of tape lengths and primitive
    // counts for the maxima. Edits leave unreachable cells and tapes behind; the sizes of the
    // last compact layout tell when to lay the grid out afresh.
    struct Census {
        bool valid = false;
        uint64_t near = 0, tape_sum = 0, prim_sum = 0, prim_sq_sum = 0, far_finest = 0;
        std::vector<uint64_t> tape_hist, prim_hist;
    };
    Census census_;
    uint64_t compact_cells_ = 0, compact_words_ = 0;
    // Per level, blocks left unreachable by edits, which update() fills again before it appends.
    std::vector<std::vector<uint32_t>> free_blocks_;
};

// The lookups every query makes, inline: a tracer makes one per step.
[[gnu::always_inline]] inline bool PrunedGrid::cell_index(vec3 p, uint32_t& ix, uint32_t& iy,
                                                          uint32_t& iz) const {
    // The closed box itself decides (q · 1/size can round past N on the max faces).
    const vec3 lo = scene_->aabb.min, hi = scene_->aabb.max;
    if (!(p.x >= lo.x && p.x <= hi.x && p.y >= lo.y && p.y <= hi.y && p.z >= lo.z && p.z <= hi.z))
        return false;
    const uint32_t last = resolution() - 1;
    ix = math::finest_cell_on_axis(p.x, lo.x, inv_cell_size_.x, last);
    iy = math::finest_cell_on_axis(p.y, lo.y, inv_cell_size_.y, last);
    iz = math::finest_cell_on_axis(p.z, lo.z, inv_cell_size_.z, last);
    return true;
}

[[gnu::always_inline]] inline bool PrunedGrid::locate(vec3 p, Located& out) const {
    uint32_t ix, iy, iz;
    if (!cell_index(p, ix, iy, iz)) return false;
    locate_cell(ix, iy, iz, out);
    return true;
}

[[gnu::always_inline]] inline void PrunedGrid::locate_cell(uint32_t ix, uint32_t iy, uint32_t iz,
                                                           Located& out) const {
    Walk w = walk_begin(ix, iy, iz);
    while (!walk_step(w)) {
    }
    out = walk_located(w);
}

[[gnu::always_inline]] inline PrunedGrid::Located PrunedGrid::located_at(uint32_t level,
                                                                         const PrunedCell* cell,
                                                                         uint32_t ix, uint32_t iy,
                                                                         uint32_t iz) const {
    const Level& l = levels_[level];
    if (l.pow2) return {level, ix >> l.shift, iy >> l.shift, iz >> l.shift, cell};
    const uint32_t scale = resolution() / l.res;
    return {level, ix / scale, iy / scale, iz / scale, cell};
}

[[gnu::always_inline]] inline PrunedGrid::Walk PrunedGrid::walk_begin(uint32_t ix, uint32_t iy,
                                                                      uint32_t iz) const {
    if (!shortcut_.empty()) {
        const uint32_t s = shortcut_shift_, r = shortcut_res_;
        return {ix, iy, iz, 0, shortcut_.data() + ((iz >> s) * r + (iy >> s)) * r + (ix >> s)};
    }
    const PrunedCell* root_cell =
        &levels_[0].cells[levels_[0].local_index(ix, iy, iz, resolution())];
    return {ix, iy, iz, 0, nullptr, root_cell};
}

[[gnu::always_inline]] inline bool PrunedGrid::walk_step(Walk& w) const {
    if (w.entry) {
        // descend's result down to the shortcut's level: the deciding far-field cell, or the
        // block of finest cells under a near-field cell of the level above the finest.
        const uint32_t entry = *w.entry;
        w.entry = nullptr;
        if (entry & kShortcutChildren) {
            // (the finest level: its cells are the finest cells)
            w.level = shortcut_level_ + 1;
            const Level& f = levels_[w.level];
            w.cell = &f.cells[(entry & ~kShortcutChildren) + f.block_local_pow2(w.ix, w.iy, w.iz)];
            w.decided = true;
            return false;
        }
        w.level = entry >> kShortcutLevelShift;
        w.cell = &levels_[w.level].cells[entry & ((1u << kShortcutLevelShift) - 1)];
        return true;
    }
    if (w.decided) return true;
    // (the address of the finest level rather than the level count: a size() divides)
    if (w.cell->tape == PrunedCell::kFarField || &levels_[w.level] == &levels_.back()) return true;
    const Level& f = levels_[++w.level];
    w.cell = &f.cells[w.cell->children + f.local_index(w.ix, w.iy, w.iz, resolution())];
    return false;
}

[[gnu::always_inline]] inline PrunedGrid::Located PrunedGrid::walk_located(const Walk& w) const {
    return located_at(w.level, w.cell, w.ix, w.iy, w.iz);
}

// The box of the finest cells [lo, hi) (per axis) of an N³ grid over `box` with cells of
// `cell_size`, one cell wider on each side (the corners' rounding), within `box`; empty
// (min > max) where lo > hi. PrunedGrid::near_box, and the GPU backend's the same way.
Aabb finest_cells_box(const Aabb& box, vec3 cell_size, uint32_t N, const uint32_t lo[3],
                      const uint32_t hi[3]);

PrunedGrid prune(const Scene& scene, const PruneOptions& options = {});
// The same, sharing ownership of an immutable scene: the grid (and its copies) keep it alive,
// so it may be dropped by the caller (language bindings rely on this). Throws
// std::invalid_argument for a null scene.
PrunedGrid prune(std::shared_ptr<const Scene> scene, const PruneOptions& options = {});

// ---- the per-cell stages, exposed for tests ------------------------------------------------

// An axis-aligned cell.
struct CellBox {
    vec3 centre;
    vec3 half;     // half sizes
    float radius;  // half-diagonal R = |half|
};

// Working memory of one pruning thread.
struct CellScratch {
    std::vector<float> value, lo, hi;
    std::vector<uint32_t> left, right, decision, stack;
    std::vector<uint8_t> alive, negate;
    // refine_cell: the sub-boxes' centres in visiting order, per axis in half sub-box sizes from
    // the cell's min corner (2i + 1), for S = sub_offset_of
    std::vector<float> sub_offset[3];
    uint32_t sub_offset_of = 0;
    // refine_cells: per cell, the operators still decided alike in every sub-box and their
    // decisions (cell j's n entries at j · n); the subtrees of all cells' candidates
    std::vector<uint32_t> refine_cands[8], refine_decision, refine_needed;
    // refine_cells: per tape entry, the values, ranges and decisions of a batch of sub-boxes
    std::vector<float> lane_value, lane_lo, lane_hi;
    std::vector<uint32_t> lane_decision;
    // evaluate_siblings: the same per tape entry for sibling cells; where the lanes that
    // sibling_value, sibling_is_near_field and compact_siblings read lie (entry e of lane c at
    // offset + e · stride + first + c: SiblingLanes), and the words that groups of them hold,
    // where evaluate_siblings writes next (sib_used; prune_level.cpp's octant groups)
    std::vector<float> sib_value, sib_lo, sib_hi;
    std::vector<uint32_t> sib_decision;
    struct SiblingLanes {
        uint32_t offset = 0, stride = 8, first = 0;
    } sib_at;
    uint32_t sib_used = 0;
    // Per octant of a split block, and per sibling cell: its compacted tape (prune_level.cpp).
    std::vector<uint32_t> octants[8];
    std::vector<uint32_t> cell_tapes[8];
    void reserve(size_t n);
    void reserve_siblings(size_t words);  // of each sib_* array
    size_t bytes() const;  // memory held (capacities), for PruneStats::prune_peak_bytes
};

// Stage 1: evaluates `tape` at the cell centre, bounds every entry over the cell and decides
// every operator (math::kKeepBoth / kLeftWins / kRightWins). Returns the root's value.
// `sub_box`: bound it as refine_cell bounds a sub-box (with interval bounds, an undecided
// operator's range is its range over its operands' ranges alone, not also intersected with
// the Lipschitz range around its value, which it holds up to rounding).
float evaluate_cell(const Scene& scene, std::span<const uint32_t> tape, const CellBox& box,
                    CellBounds bounds, CellScratch& s, bool sub_box = false);

// Stage 2: whether the surface may be in the cell (false = far-field), and if not, the
// far-field constant (sign of f, |c| <= |f| over the cell).
bool is_near_field(const Scene& scene, std::span<const uint32_t> tape, const CellBox& box,
                   float far_field_c, const CellScratch& s, float& constant);

// Stages 1–3 for up to kSiblingLanes cells of one size at once (a block's octants, an octant's
// cells): one pass over the tape evaluates entry by entry across the cells, so each entry's
// operands are fetched once and the arithmetic runs in vector lanes. Each lane's results are
// those of evaluate_cell, is_near_field and compact_tape for that cell, bit for bit.
constexpr uint32_t kSiblingLanes = 8;
// Parent tapes longer than this (only near the root of huge scenes) are evaluated one cell at
// a time instead: the sibling arrays cost 128 bytes per tape word and thread (256 MB per thread
// for a 1,000,000-sphere scene's full tape), the one-cell ones 30. Same results either way.
constexpr uint32_t kSiblingMaxTape = 1u << 16;
// Octants with tapes up to this long are evaluated together where they share one (8 lanes and
// 128 bytes per word and octant: up to 4 MB per thread).
constexpr uint32_t kSiblingGroupMaxTape = 1u << 12;

// Stage 1 for the boxes centred at centres[0, count) with half sizes `half`, count <=
// kSiblingGroupLanes: written at s.sib_used, with a stride of the lanes rounded up to 8, and
// s.sib_at set to them (lane c: box c).
// `radius` is the boxes' half-diagonal as the caller computes it (the Lipschitz spread).
constexpr uint32_t kSiblingGroupLanes = 64;
void evaluate_siblings(const Scene& scene, std::span<const uint32_t> tape, const vec3* centres,
                       uint32_t count, vec3 half, float radius, CellBounds bounds, CellScratch& s);

// The root's value at lane `lane`'s centre, after evaluate_siblings.
inline float sibling_value(const CellScratch& s, std::span<const uint32_t> tape, uint32_t lane) {
    return s
        .sib_value[s.sib_at.offset + (tape.size() - 1) * s.sib_at.stride + s.sib_at.first + lane];
}

// Links each operator entry of `tape` to its operands (s.left, s.right), as evaluating the tape
// does: for compact_siblings on lanes evaluated before another tape was.
void link_tape(const Scene& scene, std::span<const uint32_t> tape, CellScratch& s);

// Stage 2 for lane `lane` (boxes of half-diagonal `radius`).
bool sibling_is_near_field(const Scene& scene, std::span<const uint32_t> tape, uint32_t lane,
                           float radius, float far_field_c, const CellScratch& s, float& constant);

// Stage 3 for the lanes whose bit is set in `lanes` (bit c: lane c < kSiblingLanes), in one
// sweep of the tape: appends lane c's pruned tape to out[c] and sets prims[c] to its number of
// primitives (out and prims: kSiblingLanes entries; other lanes' are left alone but prims).
// With `decidable`, also the lanes (bits) whose tape has an operator that refine_cell might
// decide (blend_may_decide on its operands' values at the cell's centre).
void compact_siblings(const Scene& scene, std::span<const uint32_t> tape, uint32_t lanes,
                      CellScratch& s, std::vector<uint32_t>* out, uint32_t* prims,
                      uint32_t* decidable = nullptr);

// Stage 1b, for finest cells with PruneOptions::refine = S > 1, on the tape stage 3 made for the
// cell: decides every operator over each of the cell's S³ sub-boxes and keeps a decision only
// where all agree (leaving `s` ready for compact_tape); returns false when every sub-box's range
// clears the cell's far-field margin, with the constant (the sub-boxes' tightest common bound).
// `value` is the tree's value at the cell's centre; `may_decide` false says that no operator of
// the tape could be decided in the sub-box holding the centre (blend_may_decide). Neither
// changes the results, only the work: with neither an operator to try nor a far-field test that
// could pass, nothing is evaluated.
bool refine_cell(const Scene& scene, std::span<const uint32_t> tape, const CellBox& box,
                 uint32_t subdivisions, CellBounds bounds, bool far_field, float far_field_c,
                 float value, bool may_decide, CellScratch& s, float& constant);

// Whether refine_cell evaluates anything for a cell (`any`; else it returns at once and keeps
// every operator), and whether its far-field test may pass (`far`: refine_far_possible), which
// reads values, where decisions read ranges only; and the cell's far-field clearance.
struct RefineNeed {
    bool any = false, far = false;
    float clearance = 0;
};
RefineNeed refine_need(const Scene& scene, std::span<const uint32_t> tape, const CellBox& box,
                       bool far_field, float far_field_c, float value, bool may_decide);
// refine_need for a finest near cell's `tape` taken alone, as tools and tests that look at
// pruned tapes need it: evaluates the tape at the box's centre into `s` (evaluate_cell, with
// `options`' bounds) and takes `may_decide` from every operator of it (blend_may_decide on
// its operands' values there). Pruning finds that for the operators its compaction keeps
// (compact_siblings' `decidable`), the same on a compacted tape.
RefineNeed refine_need_of_tape(const Scene& scene, std::span<const uint32_t> tape,
                               const CellBox& box, const PruneOptions& options, float value,
                               CellScratch& s);

// refine_cell for `count` <= kSiblingLanes cells of one size that share one `tape` (values[j]
// and may_decide[j]: cell j's), in one pass over the tape per batch of sub-boxes, the cells'
// sub-boxes packed into the same lanes: the corners of every cell, then the other sub-boxes of
// the cells still open. The same results bit for bit as refine_cell on each cell alone. On a
// sibling group's cells, which share their compacted tape more often than not (trees: 3 of 4
// near cells), a tape entry's fixed costs are paid once per batch, not once per cell, and the
// lanes are padded once. Cell j's decisions are left at s.refine_decision + j · n, for
// compact_tape (after link_tape) where results[j].decided.
struct RefineResult {
    bool near = true;      // false: far-field, with `constant`
    bool decided = false;  // near, with some operator decided alike over every sub-box
    float constant = 0;
};
void refine_cells(const Scene& scene, std::span<const uint32_t> tape, const CellBox* boxes,
                  uint32_t count, uint32_t subdivisions, CellBounds bounds, bool far_field,
                  float far_field_c, const float* values, const bool* may_decide, CellScratch& s,
                  RefineResult* results);

// The centre of sub-box (i, j, k) of a box with min corner `corner` split into sub-boxes of
// half sizes `sub_half` ...
inline vec3 sub_box_centre(vec3 corner, vec3 sub_half, uint32_t i, uint32_t j, uint32_t k) {
    return corner + vec3(float(2 * i + 1), float(2 * j + 1), float(2 * k + 1)) * sub_half;
}
// ... and of `box` split into S³.
inline vec3 sub_box_centre(const CellBox& box, uint32_t S, uint32_t i, uint32_t j, uint32_t k) {
    return sub_box_centre(box.centre - box.half, box.half / float(S), i, j, k);
}

// Stage 3: the top-down pass: keeps active operators with no inactive ancestor and the
// primitives under them, re-attaching kept nodes through skipped operators with composed signs.
// Appends the pruned tape to `out`; returns the number of primitives in it.
uint32_t compact_tape(const Scene& scene, std::span<const uint32_t> tape, CellScratch& s,
                      std::vector<uint32_t>& out);

// ---- incremental re-pruning (prune_update.cpp) -----------------------------------------------
// An edit between two scenes of the same tree (same nodes, kinds of node and children): the
// nodes whose pruning data changed (kind, sign, blend radius, Lipschitz bound, or a primitive's
// parameters, transform and bound). Colors do not count: pruning never reads them.
struct SceneEdit {
    std::vector<uint32_t> nodes;
};

// The edit from `before` to `after`. Throws std::invalid_argument when the two are not the same
// tree (a different node count, children or kinds of node), or their AABBs differ.
SceneEdit scene_edit(const Scene& before, const Scene& after);

// The pruned grid of `edited`, re-pruning only the blocks an edit can reach and keeping every
// other cell, tape and constant. The result holds the same cells as prune(edited,
// old.options()): cell for cell, tape word for tape word, constant for constant, and the same
// statistics (same_cells compares the cells; the arrays' layout may differ). Why it is exact: a
// cell's result depends only on its parent's tape words and the data of the nodes those words
// name. So from the coarsest level down, a block of children is kept where its parent's new
// tape equals its old tape word for word and names no edited node (nor does any tape below it,
// each being a subset of its parent's); every other block goes through prune_level_step again,
// in place (or appended, for a parent that was far-field), and a parent that became far-field
// leaves its old subtree unreachable. An edit that changes the root's Lipschitz bound (used by
// every far-field cell) prunes everything again. When unreachable cells and tapes pile up
// (more than half of the arrays), the grid is laid out afresh.
// `old` must have been built with PruneOptions::coarse_tapes (it needs the coarse cells' own
// tapes: std::invalid_argument otherwise), and `edit` must name every changed node (see
// scene_edit). stats().prune_ms is the update's time; cells_pruned and tape_words_visited count
// its own work.
// The rvalue overloads reuse old's storage (an editor's loop: no copy of the grid); the others
// copy `old` first. `edited` must outlive the result, unless passed as a shared_ptr, which the
// result then keeps alive.
PrunedGrid update(PrunedGrid&& old, const Scene& edited, const SceneEdit& edit);
PrunedGrid update(PrunedGrid&& old, std::shared_ptr<const Scene> edited, const SceneEdit& edit);
PrunedGrid update(const PrunedGrid& old, const Scene& edited, const SceneEdit& edit);
PrunedGrid update(const PrunedGrid& old, const Scene& edited);  // edit = scene_edit(old, edited)

// Whether two grids hold the same cells: the same hierarchy (which cells are far-field, which
// have children), the same constants, clearances, values and tape words at every cell. The layouts
// of the cell arrays and tape pools may differ (update() leaves unreachable cells behind).
bool same_cells(const PrunedGrid& a, const PrunedGrid& b);

// `scene` with primitive `primitive` (an index into scene.params) moved by `offset` in world
// space: the edit that incremental re-pruning is measured with (--edit-bench).
Scene moved_primitive(const Scene& scene, uint32_t primitive, vec3 offset);

}  // namespace sdfprune
