// pruned_grid.cpp — the queries of a PrunedGrid (DESIGN.md §6): the finest cell holding a point,
// the walk down the hierarchy to the cell deciding it (PrunedGrid::descend, the one descent every
// lookup uses; for_each_block in prune.hpp is the one traversal of whole blocks), far-field
// constants, and the pruned field's value at points.
#include <algorithm>
#include <chrono>
#include <stdexcept>
#include <vector>

#include "../core/clock.hpp"
#include "../core/parallel.hpp"
#include "sdfprune/eval.hpp"
#include "sdfprune/prune.hpp"

namespace sdfprune {

vec3 PrunedGrid::cell_center(uint32_t ix, uint32_t iy, uint32_t iz) const {
    return math::cell_centre(scene_->aabb.min, cell_size_, ix, iy, iz);
}

float far_field_cell_constant(vec3 origin, vec3 cell_size, uint32_t scale, float lipschitz,
                              const PrunedCell& c, uint32_t ix, uint32_t iy, uint32_t iz) {
    return math::far_field_cell_constant(origin, cell_size, scale, lipschitz, c.value, c.bound, ix,
                                         iy, iz);
}

float PrunedGrid::far_field_constant(uint32_t level, const PrunedCell& c, uint32_t ix, uint32_t iy,
                                     uint32_t iz) const {
    return far_field_cell_constant(scene_->aabb.min, cell_size_, resolution() / levels_[level].res,
                                   lipschitz_, c, ix, iy, iz);
}

CellView PrunedGrid::cell(uint32_t ix, uint32_t iy, uint32_t iz) const {
    const CellRef at = descend(ix, iy, iz, level_count() - 1);
    const PrunedCell& c = levels_[at.level].cells[at.index];
    CellView v;
    if (c.tape == PrunedCell::kFarField) {
        v.far_field = true;
        v.constant = far_field_constant(at.level, c, ix, iy, iz);
        return v;
    }
    v.far_field = false;
    v.tape = tape_at(c.tape);
    v.primitives = pool_.data[c.tape + 1];
    return v;
}

void PrunedGrid::build_shortcut() {
    constexpr uint32_t kMaxEntries = 1u << 21;
    if (levels_.size() < 3 || !levels_.back().pow2) return;
    const uint32_t S = uint32_t(levels_.size() - 2), r = levels_[S].res;
    if (uint64_t(r) * r * r > kMaxEntries) return;
    for (const Level& l : levels_)
        if (l.cells.size() >= (1u << kShortcutLevelShift) || !l.pow2) return;
    shortcut_level_ = S;
    shortcut_shift_ = levels_[S].shift;
    shortcut_res_ = r;
    shortcut_.resize(size_t(r) * r * r);
    // A slice of the shortcut per chunk (disjoint writes).
    ParallelOptions po;
    po.threads = options_.threads;
    parallel_for<NotCancellable>(r, po, [&](uint64_t z) {
        for (uint32_t y = 0; y < r; ++y)
            for (uint32_t x = 0; x < r; ++x)
                shortcut_[(size_t(z) * r + y) * r + x] = shortcut_entry(x, y, uint32_t(z));
    });
}

// The bounds of the near-field cells of the level above the finest (level k), then of the
// near-field finest cells, from the faces of the first inwards.
void PrunedGrid::find_near_box() {
    if (levels_.size() < 2) {  // (one level: the scene's box, sparing a scan of every cell)
        near_box_ = aabb();
        return;
    }
    const uint32_t k = uint32_t(levels_.size() - 2);
    const uint32_t f = levels_[k].factor, scale = resolution() / levels_[k].res;
    uint32_t lo[3] = {UINT32_MAX, UINT32_MAX, UINT32_MAX}, hi[3] = {0, 0, 0};
    for_each_block([&](const Block& b) {
        if (b.level != k) return;
        for (uint32_t local = 0; local < f * f * f; ++local) {
            if (levels_[k].cells[b.first + local].tape == PrunedCell::kFarField) continue;
            const CellCoord c = block_cell(b.origin, f, local);
            const uint32_t at[3] = {c.x, c.y, c.z};
            for (int a = 0; a < 3; ++a) {
                lo[a] = std::min(lo[a], at[a]);
                hi[a] = std::max(hi[a], at[a] + 1);
            }
        }
    });
    // Each face then moves in to the near-field finest cells: the layers of level-k cells from
    // the face inwards are searched (their near-field cells' blocks of finest cells, of side
    // `scale`) until one holds a near-field finest cell, mostly the first.
    uint32_t finest_lo[3] = {UINT32_MAX, UINT32_MAX, UINT32_MAX}, finest_hi[3] = {0, 0, 0};
    const Level& finest = levels_.back();
    for (int a = 0; a < 3 && lo[0] < hi[0]; ++a) {
        const int b = (a + 1) % 3, c = (a + 2) % 3;
        for (const bool upper : {false, true}) {
            bool found = false;
            for (uint32_t step = 0; !found && step < hi[a] - lo[a]; ++step) {
                uint32_t at[3];
                at[a] = upper ? hi[a] - 1 - step : lo[a] + step;
                for (at[b] = lo[b]; at[b] < hi[b]; ++at[b])
                    for (at[c] = lo[c]; at[c] < hi[c]; ++at[c]) {
                        const CellRef r = descend(at[0] * scale, at[1] * scale, at[2] * scale, k);
                        const PrunedCell& parent = levels_[r.level].cells[r.index];
                        if (r.level != k || parent.tape == PrunedCell::kFarField) continue;
                        for (uint32_t local = 0; local < scale * scale * scale; ++local) {
                            if (finest.cells[parent.children + local].tape == PrunedCell::kFarField)
                                continue;
                            const uint32_t d[3] = {local % scale, local / scale % scale,
                                                   local / (scale * scale)};
                            const uint32_t x = at[a] * scale + d[a];
                            finest_lo[a] = std::min(finest_lo[a], x);
                            finest_hi[a] = std::max(finest_hi[a], x + 1);
                            found = true;
                        }
                    }
            }
        }
    }
    near_box_ = finest_cells_box(aabb(), cell_size_, resolution(), finest_lo, finest_hi);
}

Aabb finest_cells_box(const Aabb& box, vec3 cell_size, uint32_t N, const uint32_t lo[3],
                      const uint32_t hi[3]) {
    if (lo[0] > hi[0] || lo[1] > hi[1] || lo[2] > hi[2]) return {box.max, box.min};
    Aabb out;
    for (int a = 0; a < 3; ++a) {
        out.min[a] = box.min[a] + float(std::max(lo[a], 1u) - 1) * cell_size[a];
        out.max[a] =
            std::min(box.max[a], box.min[a] + float(std::min(hi[a] + 1, N)) * cell_size[a]);
    }
    return out;
}

uint32_t PrunedGrid::shortcut_entry(uint32_t x, uint32_t y, uint32_t z) const {
    const uint32_t scale = resolution() / shortcut_res_;
    const CellRef at = descend(x * scale, y * scale, z * scale, shortcut_level_);
    const PrunedCell& c = levels_[at.level].cells[at.index];
    if (c.tape != PrunedCell::kFarField) return kShortcutChildren | c.children;
    return at.level << kShortcutLevelShift | at.index;
}

void PrunedGrid::build_clearance(const CellRange* changed) {
    const auto t0 = std::chrono::steady_clock::now();
    std::vector<LevelCells> levels;
    for (Level& l : levels_) levels.push_back({l.res, l.factor, l.cells});
    stats_.clearance_bytes = set_clearance(levels, options_.threads, changed);
    stats_.clearance_ms = ms_since(t0);
}

float PrunedGrid::eval(vec3 p, float* stack) const {
    uint32_t x, y, z;
    if (!cell_index(p, x, y, z)) return eval_tape(*scene_, scene_->full_tape, p, stack);
    const CellView c = cell(x, y, z);
    return c.far_field ? c.constant : eval_tape(*scene_, c.tape, p, stack);
}

void PrunedGrid::eval_points(std::span<const vec3> points, std::span<float> out) const {
    if (out.size() != points.size()) throw std::invalid_argument("eval_points: size mismatch");
    parallel_points(points.size(), options_.threads, [&](size_t begin, size_t end) {
        std::vector<float> stack(scene_->max_stack);
        for (size_t i = begin; i != end; ++i) out[i] = eval(points[i], stack.data());
    });
}

}  // namespace sdfprune
