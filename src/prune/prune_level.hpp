// prune_level.hpp — one step of the hierarchy (DESIGN.md §3–5): the children of some near-field
// cells of a level, pruned from their parents' tapes. prune() runs it over every block of every
// level; re-pruning after an edit, or pruning one brick of a larger grid, runs it over a subset.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "sdfprune/prune.hpp"

namespace sdfprune {

// Cells per chunk of prune()'s parallel loop: fixed, so chunk boundaries (and the output) never
// depend on the number of threads.
constexpr uint32_t kPruneChunkCells = 1024;

// The level being made: where its cells are and how they are pruned.
struct LevelGeometry {
    vec3 origin;          // min corner of the grid (the scene's AABB)
    vec3 cell_size;       // size of one cell of this level
    uint32_t factor = 4;  // cells per axis of a block (the children of one parent)
    bool finest = false;  // the finest level: cells are refined and counted in the statistics
    // Prune each block's 8 octants first, then every cell from its octant's tape (not stored).
    // Needs an even factor >= 4, and ranges made of whole blocks (prune_level_step checks).
    bool split = false;
};

// LevelGeometry of level `res` cells per axis (blocks `factor` wide) over the scene's AABB, with
// the split prune() uses (a hierarchy, an even factor >= 4, chunks of whole blocks).
LevelGeometry level_geometry(const Scene& scene, const PruneOptions& options, uint32_t res,
                             uint32_t factor, bool finest, uint32_t chunk_cells);

// One near-field parent: the origin of its block of children (in this level's cells) and its
// tape (words without the [length, primitives] header), valid everywhere in the parent.
// A block of a stored grid: origin = parent's coordinates · f; tape = PrunedGrid::tape_at().
struct ParentBlock {
    CellCoord origin;
    uint32_t length = 0;              // words in the parent's tape
    const uint32_t* words = nullptr;  // the parent's tape; must outlive the step
    std::span<const uint32_t> tape() const { return {words, length}; }
};

// What pruning some cells made besides the cells: their tapes and counts.
struct LevelChunk {
    // Tapes as [length, primitives, words...]; a near-field cell's PrunedCell::tape is the
    // offset of its header in here. Identical tapes within one call are stored once.
    std::vector<uint32_t> words;
    // Finest level only: the near-field cells, sums and maxima of tape lengths and primitives.
    uint64_t near = 0, tape_sum = 0, prim_sum = 0, prim_sq_sum = 0;
    uint32_t tape_max = 0, prim_max = 0;
    // All levels: parent tape words read, and cells (and octants) pruned.
    uint64_t words_visited = 0, pruned = 0;
};

// Adds a chunk's counts to `stats` (sums and maxima: add chunks in a fixed order for totals that
// do not depend on the thread count).
void add_chunk_stats(const LevelChunk& chunk, PruneStats& stats);

// The level step. Cell i of the range [begin, end) is child i % f³ (z-major within the block) of
// blocks[i / f³] (f = geometry.factor); it is written to cells[i - begin]:
//   - far-field: tape = PrunedCell::kFarField, bound = its constant, value = the tree's value
//     at its centre (or a same-sign value no larger in magnitude, from a far-field octant);
//   - near-field: tape = offset of its header in out.words, value = the tree's value at the
//     centre; `children` is left alone (the caller links the next level).
// Pruning is exact (the tape equals the parent's tape everywhere in the cell) and depends only
// on the parent tape, the cell and the options: the same cell gives the same tape and constant
// whichever subset or chunk it is pruned in; only tape offsets and sharing depend on the range.
// With geometry.split, begin and end must be multiples of f³. `s` is the calling thread's
// scratch; appends to out.words and adds to out's counts. Thread-safe for distinct outputs.
void prune_level_step(const Scene& scene, const PruneOptions& options,
                      const LevelGeometry& geometry, std::span<const ParentBlock> blocks,
                      uint64_t begin, uint64_t end, std::span<PrunedCell> cells, CellScratch& s,
                      LevelChunk& out);

// All the children of `blocks`: cells.size() must be blocks.size() · f³.
inline void prune_level_step(const Scene& scene, const PruneOptions& options,
                             const LevelGeometry& geometry, std::span<const ParentBlock> blocks,
                             std::span<PrunedCell> cells, CellScratch& s, LevelChunk& out) {
    const uint64_t f = geometry.factor;
    prune_level_step(scene, options, geometry, blocks, 0, blocks.size() * f * f * f, cells, s, out);
}

// Pruning hands back the pages of a parent buffer that no chunk still to run reads once at least
// this many bytes of them are (default 1 MiB; Linux only). Returns the previous setting; tests
// set 1 to exercise it on small scenes. discarded_parent_bytes(): the bytes handed back so far in
// this process.
uint64_t set_parent_discard_bytes(uint64_t bytes);
uint64_t discarded_parent_bytes();

}  // namespace sdfprune
