// discretize.hpp — sampling a scene's SDF on a regular grid (DESIGN.md §6): the value at the
// centre of each cell of an n³ grid of box cells spanning the scene's AABB, as float32 in
// [z][y][x] order (index (z·n + y)·n + x; x varies fastest). Cell (ix, iy, iz) has its centre at
// aabb.min + (i + 0.5)·(aabb.max − aabb.min)/n per axis, exactly PrunedGrid::cell_center.
//
// Two ways, same cells:
//   - discretize_pruned: from a PrunedGrid. Near-field cells hold the exact value (the cell's
//     tape gives the full tree's value, bit for bit); far-field cells hold their conservative
//     far-field constant, PrunedGrid::far_field_constant: the sign of the SDF and a magnitude
//     never larger than the true distance (so |pruned| <= |exact| there, and the zero level set
//     is untouched). With PruneOptions::far_field = false every cell is exact.
//   - discretize_naive: the full tree at every cell centre, the paper's baseline, with the same
//     evaluator and threading (speed-ups against it measure pruning alone).
//
// Thread-safety: pure functions of their inputs; both run on oneTBB and may be called from any
// number of threads. Errors: std::invalid_argument when out has the wrong size or n is 0.
#pragma once

#include <cstdint>
#include <functional>
#include <span>

#include "prune.hpp"
#include "scene.hpp"

namespace sdfprune {

// Called from the calling thread with the fraction done in [0, 1]; may be empty.
using ProgressFn = std::function<void(double)>;

// The pruned field at the centres of the grid's own cells (n = grid.resolution(); out holds n³
// values). Walks the pruning hierarchy block by block: a far-field cell of any level fills its
// block of finest cells, a near-field finest cell evaluates its tape once. Threads as in the
// options the grid was built with. Equal, value for value, to grid.eval() at the cell centres.
void discretize_pruned(const PrunedGrid& grid, std::span<float> out,
                       const ProgressFn& progress = {});

// The pruned field at the centres of an n³ grid that differs from the grid's own: each centre
// is looked up through PrunedGrid::eval (slower: one root-to-leaf walk per value). For
// n == grid.resolution() it calls discretize_pruned.
void discretize_pruned(const PrunedGrid& grid, uint32_t n, std::span<float> out,
                       const ProgressFn& progress = {});

// The full tree at the centres of an n³ grid over scene.aabb (out holds n³ values), with at
// most `threads` workers (0 = all hardware threads).
void discretize_naive(const Scene& scene, uint32_t n, std::span<float> out, int threads = 0,
                      const ProgressFn& progress = {});

}  // namespace sdfprune
