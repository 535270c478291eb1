// discretize.cpp — the SDF at the cell centres of an n³ grid (DESIGN.md §6). The pruned path
// walks the pruning hierarchy instead of looking every cell up from the root: a far-field cell
// of a coarse level covers a whole block of finest cells, filled by a tight loop; a near-field
// finest cell evaluates its (short) tape once. The naive path evaluates the full tree at every
// centre with the same evaluator and threading.
#include "sdfprune/discretize.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>  // the walk's nested loop over a block

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "../core/parallel.hpp"
#include "sdfprune/eval.hpp"

namespace sdfprune {
namespace {

void check_size(std::span<float> out, uint32_t n) {
    if (n == 0) throw std::invalid_argument("discretize: resolution must be >= 1");
    const uint64_t N = n;
    if (out.size() != N * N * N)
        throw std::invalid_argument("discretize: output must hold n³ values");
}

ParallelOptions loop_options(int threads, const ProgressFn& progress) {
    ParallelOptions p;
    p.threads = threads;
    p.progress = &progress;
    return p;
}

// Evaluates `value(x, y, z, stack)` at every cell of an n³ grid, in parallel over chunks of rows.
template <class Value>
void for_each_cell(uint32_t n, uint32_t max_stack, int threads, std::span<float> out,
                   const ProgressFn& progress, const Value& value) {
    const uint64_t N = n, rows = N * N;
    // About 64k values per chunk: small enough for balance and progress, large enough that
    // the per-chunk stack allocation does not matter.
    const uint64_t grain = std::max<uint64_t>(1, 65536 / N);
    parallel_for<NotCancellable>(
        (rows + grain - 1) / grain, loop_options(threads, progress), [&](uint64_t chunk) {
            std::vector<float> stack(max_stack);
            for (uint64_t row = chunk * grain; row < std::min(rows, (chunk + 1) * grain); ++row) {
                const uint32_t y = uint32_t(row % N), z = uint32_t(row / N);
                float* o = out.data() + row * N;
                for (uint32_t x = 0; x < n; ++x) o[x] = value(x, y, z, stack.data());
            }
        });
}

// The walk of discretize_pruned.
class PrunedWalk {
  public:
    PrunedWalk(const PrunedGrid& g, std::span<float> out)
        : g_(g),
          sc_(g.scene()),
          n_(g.resolution()),
          out_(out.data()),
          cs_(g.cell_size()),
          lipschitz_(sc_.lipschitz[sc_.root()]) {
        // A far-field finest cell: PrunedGrid::far_field_constant with scale 1 reaches the
        // cell's corner from its own centre, the same for every such cell.
        const vec3 d = math::abs(vec3(0.0f)) + cs_ * 0.5f;
        finest_reach_ = reach(math::length(d));
    }

    // Cell `local` of block b (PrunedGrid::Block: the walk's own steps, child_block).
    void visit(const PrunedGrid::Block& b, uint32_t local, float* stack) const {
        const PrunedCell& c = g_.level_cells(b.level)[b.first + local];
        const CellCoord at = block_cell(b.origin, g_.level_factor(b.level), local);
        if (b.level + 1 == g_.level_count()) {
            out_[(uint64_t(at.z) * n_ + at.y) * n_ + at.x] = finest(c, at.x, at.y, at.z, stack);
            return;
        }
        if (c.tape == PrunedCell::kFarField) {
            fill_far(c, at.x, at.y, at.z, n_ / g_.level_resolution(b.level));
            return;
        }
        const PrunedGrid::Block kids = g_.child_block(b, local);
        const uint32_t f = g_.level_factor(kids.level);
        if (kids.level + 1 == g_.level_count()) {
            // Children are finest cells: too little work each to spawn tasks or recurse.
            const PrunedCell* cells = g_.level_cells(kids.level).data() + kids.first;
            const CellCoord o0 = kids.origin;
            for (uint32_t lz = 0; lz < f; ++lz)
                for (uint32_t ly = 0; ly < f; ++ly) {
                    const uint32_t z = o0.z + lz, y = o0.y + ly;
                    float* o = out_ + (uint64_t(z) * n_ + y) * n_ + o0.x;
                    const PrunedCell* row = cells + (lz * f + ly) * f;
                    for (uint32_t lx = 0; lx < f; ++lx)
                        o[lx] = finest(row[lx], o0.x + lx, y, z, stack);
                }
            return;
        }
        tbb::parallel_for(tbb::blocked_range<uint32_t>(0, f * f * f),
                          [&](const tbb::blocked_range<uint32_t>& r) {
                              std::vector<float> st(sc_.max_stack);
                              for (uint32_t k = r.begin(); k != r.end(); ++k)
                                  visit(kids, k, st.data());
                          });
    }

  private:
    float reach(float len) const { return far_field_reach(lipschitz_, len); }
    // The value of finest cell (x, y, z): its exact tape value at the centre, or its
    // far-field constant (far_field_constant with scale 1: the cell's own corner distance).
    float finest(const PrunedCell& c, uint32_t x, uint32_t y, uint32_t z, float* stack) const {
        return c.tape == PrunedCell::kFarField
                   ? combine(c, finest_reach_)
                   : eval_tape(sc_, g_.tape_at(c.tape), g_.cell_center(x, y, z), stack);
    }
    static float combine(const PrunedCell& c, float reach) {
        return far_field_combine(c.value, c.bound, reach);
    }

    // Far-field cell (cx, cy, cz) covering scale³ finest cells: each gets
    // PrunedGrid::far_field_constant, computed with the same float operations in the same
    // order (so the values are identical; tests check it) but with the per-axis terms hoisted
    // out of the loops.
    void fill_far(const PrunedCell& c, uint32_t cx, uint32_t cy, uint32_t cz,
                  uint32_t scale) const {
        const vec3 lo = sc_.aabb.min;
        const vec3 coarse_size = cs_ * float(scale);
        const vec3 half = cs_ * 0.5f;
        // Squared per-axis distances from the coarse centre to each finest cell's far corner.
        constexpr uint32_t kLocal = 64;
        float local[3 * kLocal];
        std::vector<float> heap;
        float* d2 = local;
        if (scale > kLocal) {
            heap.resize(3 * size_t(scale));
            d2 = heap.data();
        }
        const uint32_t origin[3] = {cx * scale, cy * scale, cz * scale};
        const uint32_t coarse_index[3] = {cx, cy, cz};
        for (int a = 0; a < 3; ++a) {
            const float coarse = lo[a] + (float(coarse_index[a]) + 0.5f) * coarse_size[a];
            for (uint32_t i = 0; i < scale; ++i) {
                const float centre = lo[a] + (float(origin[a] + i) + 0.5f) * cs_[a];
                const float d = std::fabs(centre - coarse) + half[a];
                d2[a * scale + i] = d * d;
            }
        }
        const float* dx2 = d2;
        const float* dy2 = dx2 + scale;
        const float* dz2 = dy2 + scale;
        const FarRow row{c.value > 0, c.bound, std::fabs(c.value), lipschitz_};
        for (uint32_t k = 0; k < scale; ++k)
            for (uint32_t j = 0; j < scale; ++j)
                row.fill(out_ + (uint64_t(origin[2] + k) * n_ + origin[1] + j) * n_ + origin[0],
                         dx2, dy2[j], dz2[k], scale);
    }

    // One row of far-field constants: o[i] from the squared corner distance (dx2[i] + y2) + z2
    // (the order math::length sums in). SSE where available: the same IEEE operations lane by
    // lane (and _mm_max_ps / _mm_min_ps pick operands exactly as std::max / std::min do here),
    // so the values do not change; std::sqrt alone would not vectorize (errno).
    struct FarRow {
        bool positive;
        float bound, abs_value, lipschitz;

        float one(float sq) const {
            return far_field_combine(positive ? abs_value : -abs_value, bound,
                                     far_field_reach(lipschitz, std::sqrt(sq)));
        }
        void fill(float* o, const float* dx2, float y2, float z2, uint32_t count) const {
            uint32_t i = 0;
#if defined(__SSE2__)
            const __m128 vy2 = _mm_set1_ps(y2), vz2 = _mm_set1_ps(z2);
            const __m128 vl = _mm_set1_ps(lipschitz), vk = _mm_set1_ps(1.0f + 1e-5f);
            const __m128 vm = _mm_set1_ps(math::kPruneMarginAbs), va = _mm_set1_ps(abs_value);
            const __m128 vb = _mm_set1_ps(bound), sign = _mm_set1_ps(-0.0f);
            for (; i + 4 <= count; i += 4) {
                const __m128 sq = _mm_add_ps(_mm_add_ps(_mm_loadu_ps(dx2 + i), vy2), vz2);
                const __m128 r = _mm_add_ps(_mm_mul_ps(_mm_mul_ps(vl, _mm_sqrt_ps(sq)), vk), vm);
                const __m128 lb = _mm_sub_ps(va, r);
                _mm_storeu_ps(o + i,
                              positive ? _mm_max_ps(lb, vb) : _mm_min_ps(_mm_xor_ps(lb, sign), vb));
            }
#endif
            for (; i < count; ++i) o[i] = one((dx2[i] + y2) + z2);
        }
    };

    const PrunedGrid& g_;
    const Scene& sc_;
    uint32_t n_;
    float* out_;
    vec3 cs_;
    float lipschitz_;
    float finest_reach_ = 0;
};

}  // namespace

void discretize_pruned(const PrunedGrid& grid, std::span<float> out, const ProgressFn& progress) {
    const uint32_t n = grid.resolution();
    check_size(out, n);
    const PrunedWalk walk(grid, out);
    const uint32_t r0 = grid.level_resolution(0);
    const uint32_t cells0 = r0 * r0 * r0;
    // Level 0 in z-major order, one chunk per cell; the walk is fast enough (tens of ms at
    // 256³) that progress per level-0 cell is enough.
    parallel_for<NotCancellable>(cells0, loop_options(grid.options().threads, progress),
                                 [&](uint64_t i) {
                                     // Not thread_local: visit's nested loop may run another
                                     // level-0 cell on this thread.
                                     std::vector<float> stack(grid.scene().max_stack);
                                     walk.visit(PrunedGrid::Block{}, uint32_t(i), stack.data());
                                 });
}

void discretize_pruned(const PrunedGrid& grid, uint32_t n, std::span<float> out,
                       const ProgressFn& progress) {
    if (n == grid.resolution()) return discretize_pruned(grid, out, progress);
    check_size(out, n);
    const Aabb box = grid.aabb();
    const vec3 cell = (box.max - box.min) / float(n);
    for_each_cell(n, grid.scene().max_stack, grid.options().threads, out, progress,
                  [&](uint32_t x, uint32_t y, uint32_t z, float* stack) {
                      return grid.eval(math::cell_centre(box.min, cell, x, y, z), stack);
                  });
}

void discretize_naive(const Scene& scene, uint32_t n, std::span<float> out, int threads,
                      const ProgressFn& progress) {
    check_size(out, n);
    const vec3 lo = scene.aabb.min;
    const vec3 cell = (scene.aabb.max - scene.aabb.min) / float(n);
    const std::span<const uint32_t> tape = scene.full_tape;
    for_each_cell(n, scene.max_stack, threads, out, progress,
                  [&](uint32_t x, uint32_t y, uint32_t z, float* stack) {
                      return eval_tape(scene, tape, math::cell_centre(lo, cell, x, y, z), stack);
                  });
}

}  // namespace sdfprune
