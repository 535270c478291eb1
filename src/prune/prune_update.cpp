// prune_update.cpp — incremental re-pruning after an edit (prune.hpp, `update`): from the
// coarsest level down, a block of children is copied from the old grid where its parent's tape
// is unchanged and names no edited node, and pruned again by the level step (prune_level.hpp)
// everywhere else. The result equals a from-scratch prune() cell for cell.
#include <algorithm>
#include <chrono>
#include <cstring>
#include <stdexcept>

#include <tbb/enumerable_thread_specific.h>

#include "../core/parallel.hpp"
#include "prune_level.hpp"
#include "sdfprune/prune.hpp"

namespace sdfprune {
namespace {

// The words of the tape whose header ([length, primitives]) is at `header`.
std::span<const uint32_t> tape_words(const uint32_t* header) {
    return {header + 2, header[0]};
}

bool same_bytes(const auto& a, const auto& b) {
    return std::memcmp(&a, &b, sizeof(a)) == 0;
}

// Whether node n carries different pruning data in the two scenes (same tree).
bool node_changed(const Scene& a, const Scene& b, uint32_t n) {
    if (a.kind[n] != b.kind[n] || a.negated[n] != b.negated[n] || a.blend[n] != b.blend[n] ||
        a.lipschitz[n] != b.lipschitz[n] || a.full_tape[n] != b.full_tape[n])
        return true;
    if (!a.is_primitive(n)) return false;
    const uint32_t p = a.primitive[n];
    return !same_bytes(a.params[p], b.params[p]) || !same_bytes(a.bound[p], b.bound[p]);
}

// Where a block of the level being made comes from: pruned from a parent tape (held in the
// previous level's word buffer), or copied from the old grid's block starting at old cell
// `old_first`.
struct BlockSource {
    ParentBlock parent;
    uint32_t old_first = PrunedCell::kFarField;  // kFarField: prune it
};

}  // namespace

SceneEdit scene_edit(const Scene& before, const Scene& after) {
    if (before.size() != after.size())
        throw std::invalid_argument("scene_edit: the scenes have different node counts");
    if (!same_bytes(before.aabb, after.aabb))
        throw std::invalid_argument("scene_edit: the scenes have different AABBs");
    SceneEdit e;
    for (uint32_t n = 0; n < before.size(); ++n) {
        if (before.left[n] != after.left[n] || before.right[n] != after.right[n] ||
            before.is_primitive(n) != after.is_primitive(n))
            throw std::invalid_argument("scene_edit: the scenes are not the same tree");
        if (node_changed(before, after, n)) e.nodes.push_back(n);
    }
    return e;
}

PrunedGrid update(const PrunedGrid& old, const Scene& edited) {
    return update(old, edited, scene_edit(old.scene(), edited));
}

PrunedGrid update(const PrunedGrid& old, const Scene& sc, const SceneEdit& edit) {
    const auto t0 = std::chrono::steady_clock::now();
    const PruneOptions& opt = old.options();
    if (!opt.coarse_tapes)
        throw std::invalid_argument("update needs a grid pruned with PruneOptions::coarse_tapes");
    const Scene& before = old.scene();
    if (before.size() != sc.size() || !same_bytes(before.aabb, sc.aabb))
        throw std::invalid_argument("update: the edited scene is not the same tree");
    std::vector<uint8_t> dirty(sc.size(), 0);
    for (const uint32_t n : edit.nodes) {
        if (n >= sc.size()) throw std::invalid_argument("update: edited node out of range");
        dirty[n] = 1;
    }
    // Every far-field cell's value reach uses the root's bound.
    if (before.lipschitz[before.root()] != sc.lipschitz[sc.root()]) {
        PrunedGrid g = prune(sc, opt);
        return g;
    }
    const auto clean = [&](std::span<const uint32_t> tape) {
        for (const uint32_t w : tape)
            if (dirty[math::tape_node(w)]) return false;
        return true;
    };

    PrunedGrid g;
    g.scene_ = &sc;
    g.options_ = opt;
    g.lipschitz_ = old.lipschitz_;
    g.cell_size_ = old.cell_size_;
    g.inv_cell_size_ = old.inv_cell_size_;
    g.level_size_ = old.level_size_;
    std::vector<uint32_t> root{sc.size(), sc.primitive_count()};
    root.insert(root.end(), sc.full_tape.begin(), sc.full_tape.end());
    g.pool_.append(root);
    PruneStats& st = g.stats_;
    st.grid = old.stats_.grid;
    st.cells = old.stats_.cells;
    st.levels = old.stats_.levels;
    const uint32_t N = old.resolution();

    tbb::enumerable_thread_specific<CellScratch> scratch;
    LevelChunk sums;  // the finest level's counts, copied cells included
    uint64_t far_finest = 0;
    // The previous level's tapes ([length, primitives, words...]) for this level's pruned
    // blocks, and this level's; a cell's `tape` holds an offset into `words` until placed.
    std::vector<uint32_t> prev_words = root, words;
    std::vector<BlockSource> blocks{{{{0, 0, 0}, sc.size(), prev_words.data() + 2}}};
    for (uint32_t li = 0; li < old.levels_.size(); ++li) {
        const PrunedGrid::Level& old_level = old.levels_[li];
        const bool finest = li + 1 == old.levels_.size();
        PrunedGrid::Level level;
        level.res = old_level.res;
        level.factor = old_level.factor;
        level.pow2 = old_level.pow2;
        level.shift = old_level.shift;
        level.factor_bits = old_level.factor_bits;
        const uint32_t f = level.factor;
        const uint64_t per_block = uint64_t(f) * f * f;
        level.cells.resize(per_block * blocks.size());
        // Per cell: whether its tape equals the old grid's and names no edited node, and then
        // the old cell it equals.
        std::vector<uint32_t> same_as_old(level.cells.size(), PrunedCell::kFarField);
        const LevelGeometry geo = level_geometry(sc, opt, level.res, f, finest, kPruneChunkCells);
        // The blocks to prune again, in parallel (each into its own chunk), with the check of
        // their near-field cells against the old grid; then every block's tapes in order.
        std::vector<uint64_t> pruned;
        for (uint64_t b = 0; b < blocks.size(); ++b)
            if (blocks[b].old_first == PrunedCell::kFarField) pruned.push_back(b);
        std::vector<LevelChunk> outs(pruned.size());
        ParallelOptions po;
        po.threads = opt.threads;
        parallel_for<PruneCancelled>(pruned.size(), po, [&](uint64_t k) {
            const uint64_t b = pruned[k];
            const BlockSource& src = blocks[b];
            const std::span<PrunedCell> cells =
                std::span(level.cells).subspan(b * per_block, per_block);
            LevelChunk& out = outs[k];
            prune_level_step(sc, opt, geo, std::span(&src.parent, 1), cells, scratch.local(), out);
            for (uint32_t local = 0; local < per_block; ++local) {
                const PrunedCell& c = cells[local];
                if (c.tape == PrunedCell::kFarField) continue;
                const std::span<const uint32_t> t = tape_words(out.words.data() + c.tape);
                if (!clean(t)) continue;
                // The old grid's cell at the same place, if it has one at this level.
                const CellCoord at = block_cell(src.parent.origin, f, local);
                const uint32_t scale = N / level.res;
                const PrunedGrid::CellRef ref =
                    old.descend(at.x * scale, at.y * scale, at.z * scale, li);
                if (ref.level != li) continue;
                const PrunedCell& oc = old_level.cells[ref.index];
                if (oc.tape == PrunedCell::kFarField) continue;
                const std::span<const uint32_t> ot = old.tape_at(oc.tape);
                if (std::equal(t.begin(), t.end(), ot.begin(), ot.end()))
                    same_as_old[b * per_block + local] = ref.index;
            }
        });
        words.clear();
        size_t next_pruned = 0;
        for (uint64_t b = 0; b < blocks.size(); ++b) {
            const std::span<PrunedCell> cells =
                std::span(level.cells).subspan(b * per_block, per_block);
            const BlockSource& src = blocks[b];
            if (src.old_first != PrunedCell::kFarField) {
                // Copied: the same parent tape gives the same cells, tapes and constants.
                for (uint32_t local = 0; local < per_block; ++local) {
                    PrunedCell c = old_level.cells[src.old_first + local];
                    if (c.tape != PrunedCell::kFarField) {
                        const uint32_t* header = old.tape_pool().data() + c.tape;
                        c.tape = uint32_t(words.size());
                        words.insert(words.end(), header, header + 2 + header[0]);
                        same_as_old[b * per_block + local] = src.old_first + local;
                    }
                    cells[local] = c;
                }
                continue;
            }
            const LevelChunk& out = outs[next_pruned++];
            st.cells_pruned += out.pruned;
            st.tape_words_visited += out.words_visited;
            for (PrunedCell& c : cells) {
                if (c.tape == PrunedCell::kFarField) continue;
                const uint32_t* header = out.words.data() + c.tape;
                c.tape = uint32_t(words.size());
                words.insert(words.end(), header, header + 2 + header[0]);
            }
        }

        // Place the tapes in the pool, count, and make the next level's blocks.
        const uint64_t base = g.pool_.size;
        g.pool_.append(words);
        std::vector<BlockSource> next;
        const uint32_t nf = finest ? 0 : old.levels_[li + 1].factor;
        const uint64_t below = N / level.res;
        for (uint64_t i = 0; i < level.cells.size(); ++i) {
            PrunedCell& c = level.cells[i];
            if (c.tape == PrunedCell::kFarField) {
                far_finest += below * below * below;
                continue;
            }
            const uint32_t* header = words.data() + c.tape;
            if (finest) {
                const uint32_t len = header[0], prims = header[1];
                ++sums.near;
                sums.tape_sum += len;
                sums.tape_max = std::max(sums.tape_max, len);
                sums.prim_sum += prims;
                sums.prim_sq_sum += uint64_t(prims) * prims;
                sums.prim_max = std::max(sums.prim_max, prims);
            } else {
                const CellCoord at =
                    block_cell(blocks[i / per_block].parent.origin, f, uint32_t(i % per_block));
                BlockSource s;
                s.parent = {{at.x * nf, at.y * nf, at.z * nf}, header[0], header + 2};
                if (same_as_old[i] != PrunedCell::kFarField)
                    s.old_first = old_level.cells[same_as_old[i]].children;
                c.children = uint32_t(next.size() * nf * nf * nf);
                next.push_back(s);
            }
            c.tape = uint32_t(base + c.tape);
        }
        // The next level's parents point into `words`: keep it as prev_words.
        prev_words.swap(words);
        blocks.swap(next);
        g.levels_.push_back(std::move(level));
    }
    g.pool_.shrink_to_fit();
    g.build_shortcut();
    add_chunk_stats(sums, st);
    finish_prune_stats(st, st.active_avg, st.active_std, st.tape_avg, far_finest);
    st.tape_bytes = uint64_t(g.pool_.capacity) * sizeof(uint32_t);
    for (const PrunedGrid::Level& l : g.levels_)
        st.tape_bytes += uint64_t(l.cells.capacity()) * sizeof(PrunedCell);
    st.prune_peak_bytes = st.tape_bytes;
    st.prune_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    return g;
}

bool same_cells(const PrunedGrid& a, const PrunedGrid& b) {
    if (a.level_count() != b.level_count()) return false;
    for (uint32_t l = 0; l < a.level_count(); ++l) {
        const auto ca = a.level_cells(l), cb = b.level_cells(l);
        if (ca.size() != cb.size()) return false;
        const bool finest = l + 1 == a.level_count();
        for (size_t i = 0; i < ca.size(); ++i) {
            const PrunedCell &x = ca[i], &y = cb[i];
            const bool far = x.tape == PrunedCell::kFarField;
            if (far != (y.tape == PrunedCell::kFarField) || !same_bytes(x.value, y.value))
                return false;
            if (far) {
                if (!same_bytes(x.bound, y.bound)) return false;
                continue;
            }
            const auto ta = a.tape_at(x.tape), tb = b.tape_at(y.tape);
            if (!std::equal(ta.begin(), ta.end(), tb.begin(), tb.end()) ||
                a.tape_pool()[x.tape + 1] != b.tape_pool()[y.tape + 1] ||
                (!finest && x.children != y.children))
                return false;
        }
    }
    return true;
}

Scene moved_primitive(const Scene& scene, uint32_t primitive, vec3 offset) {
    if (primitive >= scene.primitive_count())
        throw std::invalid_argument("moved_primitive: no such primitive");
    Scene s = scene;
    // The world->local map A·p + b becomes A·(p − offset) + b.
    math::PrimitiveParams& p = s.params[primitive];
    vec4* rows[3] = {&p.row0, &p.row1, &p.row2};
    for (vec4* r : rows) r->w -= r->x * offset.x + r->y * offset.y + r->z * offset.z;
    PrimitiveBound& b = s.bound[primitive];
    b.centre = b.centre + offset;
    // The node's own matrix (for saving) moves the same way: it is applied first.
    Affine& m = s.local[s.primitive_node[primitive]];
    for (int i = 0; i < 3; ++i)
        m.m[4 * i + 3] -=
            m.m[4 * i] * offset.x + m.m[4 * i + 1] * offset.y + m.m[4 * i + 2] * offset.z;
    return s;
}

}  // namespace sdfprune
