// prune_update.cpp — incremental re-pruning after an edit (prune.hpp, `update`), in place: from
// the coarsest level down, a block of children is kept where its parent's tape is unchanged and
// names no edited node, and pruned again by the level step (prune_level.hpp) where it stood
// everywhere else. The statistics follow the changed cells (PrunedGrid::Census). The result
// equals a from-scratch prune() cell for cell.
#include <algorithm>
#include <chrono>
#include <cstring>
#include <stdexcept>

#include <tbb/enumerable_thread_specific.h>

#include "../core/clock.hpp"
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

// The edit of a grid in place (a friend of PrunedGrid).
class GridUpdate {
  public:
    // `owner`: the edited scene when shared (kept alive by the grid), else null.
    static void run(PrunedGrid& g, const Scene& sc, const SceneEdit& edit,
                    std::shared_ptr<const Scene> owner);

  private:
    using Census = PrunedGrid::Census;
    // A block of the level being made that is pruned again: its parent (tape in the pool, by
    // offset: the pool grows) and where its cells are; `fresh`: appended, no old cells there.
    struct Job {
        CellCoord origin;
        uint32_t tape = 0;  // offset of the parent's tape header in the pool
        uint32_t first = 0;
        bool fresh = false;
    };
    static void add(Census& c, uint32_t length, uint32_t prims, int sign);
    static void take_census(const PrunedGrid& g, Census& c);
    static void forget_subtree(PrunedGrid& g, uint32_t level, uint32_t first);
    static void compact(PrunedGrid& g);
    static void refresh_shortcut(PrunedGrid& g, uint32_t level, CellCoord at);
};

void GridUpdate::add(Census& c, uint32_t length, uint32_t prims, int sign) {
    if (c.tape_hist.size() <= length) c.tape_hist.resize(length + 1);
    if (c.prim_hist.size() <= prims) c.prim_hist.resize(prims + 1);
    const uint64_t u = uint64_t(int64_t(sign));  // +1 or 2^64 - 1: modular sums
    c.near += u;
    c.tape_sum += u * length;
    c.prim_sum += u * prims;
    c.prim_sq_sum += u * prims * prims;
    c.tape_hist[length] += u;
    c.prim_hist[prims] += u;
}

// The counts of a grid as prune() made it (or as update() left it): one walk of its blocks.
void GridUpdate::take_census(const PrunedGrid& g, Census& c) {
    c = Census{};
    const uint32_t last = g.level_count() - 1, N = g.resolution();
    g.for_each_block([&](const PrunedGrid::Block& b) {
        const uint32_t f = g.level_factor(b.level);
        const uint64_t below = N / g.level_resolution(b.level);
        const PrunedCell* cells = g.levels_[b.level].cells.data() + b.first;
        for (uint32_t i = 0; i < f * f * f; ++i) {
            if (cells[i].tape == PrunedCell::kFarField)
                c.far_finest += below * below * below;
            else if (b.level == last)
                add(c, g.pool_.data[cells[i].tape], g.pool_.data[cells[i].tape + 1], 1);
        }
    });
    c.valid = true;
}

// Takes the subtree under a near-field cell (its child block at `level`, cell `first`) out of
// the census, and its blocks into the free lists: the cell became far-field.
void GridUpdate::forget_subtree(PrunedGrid& g, uint32_t level, uint32_t first) {
    const uint32_t last = g.level_count() - 1, N = g.resolution();
    Census& c = g.census_;
    std::vector<std::pair<uint32_t, uint32_t>> stack{{level, first}};
    while (!stack.empty()) {
        const auto [l, at] = stack.back();
        stack.pop_back();
        g.free_blocks_[l].push_back(at);
        const uint32_t f = g.level_factor(l);
        const uint64_t below = N / g.level_resolution(l);
        const PrunedCell* cells = g.levels_[l].cells.data() + at;
        for (uint32_t i = 0; i < f * f * f; ++i) {
            if (cells[i].tape == PrunedCell::kFarField)
                c.far_finest -= below * below * below;
            else if (l == last)
                add(c, g.pool_.data[cells[i].tape], g.pool_.data[cells[i].tape + 1], -1);
            else
                stack.push_back({l + 1, cells[i].children});
        }
    }
}

// Lays the grid out as prune() does: reachable blocks only, children in their parents' order,
// tapes copied into a new pool.
void GridUpdate::compact(PrunedGrid& g) {
    PrunedGrid::Pool pool;
    pool.append(std::span(g.pool_.data, 2 + g.pool_.data[0]));  // the full tree's tape
    std::vector<uint32_t> blocks{0};  // this level's blocks: first cells in the old arrays
    for (uint32_t li = 0; li < g.level_count(); ++li) {
        PrunedGrid::Level& level = g.levels_[li];
        const bool finest = li + 1 == g.level_count();
        const uint32_t f = level.factor, per_block = f * f * f;
        const uint32_t nf = finest ? 0 : g.levels_[li + 1].factor;
        CellVector cells(size_t(per_block) * blocks.size());  // every one written below
        std::vector<uint32_t> next;
        for (size_t b = 0; b < blocks.size(); ++b)
            for (uint32_t i = 0; i < per_block; ++i) {
                PrunedCell c = level.cells[blocks[b] + i];
                if (c.tape != PrunedCell::kFarField) {
                    const uint32_t* header = g.pool_.data + c.tape;
                    c.tape = uint32_t(pool.size);
                    pool.append(std::span(header, 2 + header[0]));
                    if (!finest) {
                        next.push_back(c.children);
                        c.children = uint32_t((next.size() - 1) * nf * nf * nf);
                    }
                }
                cells[b * per_block + i] = c;
            }
        level.cells.swap(cells);
        blocks.swap(next);
    }
    pool.shrink_to_fit();
    g.pool_ = std::move(pool);
    g.shortcut_.clear();
    g.build_shortcut();
    g.free_blocks_.assign(g.level_count(), {});
    g.compact_words_ = g.pool_.size;
    g.compact_cells_ = 0;
    for (const PrunedGrid::Level& l : g.levels_) g.compact_cells_ += l.cells.size();
}

// The lookup shortcut's entries under cell `at` of level `level` (whose far-field state
// changed: at the shortcut's level too, since a near-field cell's entry names its children).
void GridUpdate::refresh_shortcut(PrunedGrid& g, uint32_t level, CellCoord at) {
    if (g.shortcut_.empty() || level > g.shortcut_level_) return;
    const uint32_t S = g.shortcut_level_, r = g.levels_[S].res;
    const uint32_t span = r / g.levels_[level].res;
    for (uint32_t z = at.z * span; z < (at.z + 1) * span; ++z)
        for (uint32_t y = at.y * span; y < (at.y + 1) * span; ++y)
            for (uint32_t x = at.x * span; x < (at.x + 1) * span; ++x)
                g.shortcut_[(size_t(z) * r + y) * r + x] = g.shortcut_entry(x, y, z);
}

void GridUpdate::run(PrunedGrid& g, const Scene& sc, const SceneEdit& edit,
                     std::shared_ptr<const Scene> owner) {
    const auto t0 = std::chrono::steady_clock::now();
    const PruneOptions& opt = g.options_;
    if (!opt.coarse_tapes)
        throw std::invalid_argument("update needs a grid pruned with PruneOptions::coarse_tapes");
    const Scene& before = *g.scene_;
    if (before.size() != sc.size() || !same_bytes(before.aabb, sc.aabb))
        throw std::invalid_argument("update: the edited scene is not the same tree");
    std::vector<uint8_t> dirty(sc.size(), 0);
    for (const uint32_t n : edit.nodes) {
        if (n >= sc.size()) throw std::invalid_argument("update: edited node out of range");
        dirty[n] = 1;
    }
    // Every far-field cell's value reach uses the root's bound.
    if (before.lipschitz[before.root()] != sc.lipschitz[sc.root()]) {
        g = owner ? prune(std::move(owner), opt) : prune(sc, opt);
        return;
    }
    const auto clean = [&](std::span<const uint32_t> tape) {
        for (const uint32_t w : tape)
            if (dirty[math::tape_node(w)]) return false;
        return true;
    };
    if (!g.census_.valid) take_census(g, g.census_);
    g.free_blocks_.resize(g.level_count());
    // Room for what edits append (blocks under cells that became near-field, changed tapes),
    // so that growing, which copies a whole level, is rare. Copies of the grid keep it.
    for (PrunedGrid::Level& l : g.levels_)
        if (l.cells.capacity() < l.cells.size() + l.cells.size() / 16)
            l.cells.reserve(l.cells.size() + l.cells.size() / 8);
    if (g.pool_.capacity < g.pool_.size + g.pool_.size / 16)
        g.pool_.reserve(g.pool_.size + g.pool_.size / 8);
    if (g.compact_words_ == 0) {
        g.compact_words_ = g.pool_.size;
        for (const PrunedGrid::Level& l : g.levels_) g.compact_cells_ += l.cells.size();
    }
    g.scene_ = &sc;
    g.owner_ = std::move(owner);
    Census& census = g.census_;
    PruneStats& st = g.stats_;
    st.cells_pruned = 0;
    st.tape_words_visited = 0;
    const uint32_t N = g.resolution();

    tbb::enumerable_thread_specific<CellScratch> scratch;
    // Level 0 is one block under the full tree's tape (pool offset 0), which names every node.
    std::vector<Job> jobs{{{0, 0, 0}, 0, 0, false}};
    // Cells whose far-field state changed (those below the shortcut's level are ignored).
    std::vector<std::pair<uint32_t, CellCoord>> flipped;
    for (uint32_t li = 0; li < g.level_count() && !jobs.empty(); ++li) {
        PrunedGrid::Level& level = g.levels_[li];
        const bool finest = li + 1 == g.level_count();
        const uint32_t f = level.factor, per_block = f * f * f;
        const uint64_t below = N / level.res, below3 = below * below * below;
        const LevelGeometry geo = level_geometry(sc, opt, level.res, f, finest, kPruneChunkCells);
        // Prune each job's block where it stands, keeping its old cells to compare with.
        std::vector<PrunedCell> old_cells(size_t(per_block) * jobs.size());
        std::vector<LevelChunk> outs(jobs.size());
        ParallelOptions po;
        po.threads = opt.threads;
        parallel_for<PruneCancelled>(jobs.size(), po, [&](uint64_t j) {
            const Job& job = jobs[j];
            const std::span<PrunedCell> cells =
                std::span(level.cells).subspan(job.first, per_block);
            if (!job.fresh)
                std::copy(cells.begin(), cells.end(), old_cells.begin() + j * per_block);
            const uint32_t* header = g.pool_.data + job.tape;
            const ParentBlock parent{job.origin, header[0], header + 2};
            prune_level_step(sc, opt, geo, std::span(&parent, 1), cells, scratch.local(), outs[j]);
        });

        // In order: the census, the new tapes into the pool, and the next level's jobs.
        std::vector<Job> next;
        const uint32_t nf = finest ? 0 : g.levels_[li + 1].factor;
        uint64_t appended = finest ? 0 : g.levels_[li + 1].cells.size();
        for (size_t j = 0; j < jobs.size(); ++j) {
            const Job& job = jobs[j];
            const LevelChunk& out = outs[j];
            st.cells_pruned += out.pruned;
            st.tape_words_visited += out.words_visited;
            for (uint32_t local = 0; local < per_block; ++local) {
                PrunedCell& c = level.cells[job.first + local];
                const PrunedCell* o = job.fresh ? nullptr : &old_cells[j * per_block + local];
                const bool was_near = o && o->tape != PrunedCell::kFarField;
                const bool near = c.tape != PrunedCell::kFarField;
                if (o && !was_near) census.far_finest -= below3;
                if (was_near && finest)
                    add(census, g.pool_.data[o->tape], g.pool_.data[o->tape + 1], -1);
                if (was_near && !near && !finest) forget_subtree(g, li + 1, o->children);
                if (!job.fresh && was_near != near)
                    flipped.push_back({li, block_cell(job.origin, f, local)});
                if (!near) {
                    census.far_finest += below3;
                    // (no clearances: a cell turned far-field keeps 0, not its old children)
                    if (!opt.clearance) c.children = 0;
                    continue;
                }
                const uint32_t* header = out.words.data() + c.tape;
                const std::span<const uint32_t> tape = tape_words(header);
                const bool same =
                    was_near && std::ranges::equal(tape, tape_words(g.pool_.data + o->tape));
                if (same) {
                    c.tape = o->tape;
                } else {
                    if (g.pool_.size + 2 + header[0] >= PrunedCell::kFarField)
                        throw std::length_error("tape pool exceeds 2^32 - 1 words");
                    c.tape = uint32_t(g.pool_.size);
                    g.pool_.append(std::span(header, 2 + header[0]));
                }
                if (finest) {
                    add(census, header[0], header[1], 1);
                    continue;
                }
                const CellCoord at = block_cell(job.origin, f, local);
                const CellCoord origin{at.x * nf, at.y * nf, at.z * nf};
                if (was_near) {
                    c.children = o->children;
                    if (!same || !clean(tape)) next.push_back({origin, c.tape, c.children, false});
                } else {
                    std::vector<uint32_t>& free = g.free_blocks_[li + 1];
                    if (!free.empty()) {
                        c.children = free.back();
                        free.pop_back();
                    } else {
                        c.children = uint32_t(appended);
                        appended += uint64_t(nf) * nf * nf;
                    }
                    next.push_back({origin, c.tape, c.children, true});
                }
            }
        }
        if (!finest) {
            CellVector& below_cells = g.levels_[li + 1].cells;
            if (appended >= PrunedCell::kFarField)
                throw std::length_error("a level exceeds 2^32 - 1 cells");
            if (appended > below_cells.capacity()) below_cells.reserve(appended + appended / 4);
            below_cells.resize(appended, PrunedCell{});
        }
        jobs.swap(next);
    }
    for (const auto& [l, at] : flipped) refresh_shortcut(g, l, at);
    if (!flipped.empty()) g.find_near_box();
    // Clearances change only within reach of the cells that turned near-field or far-field
    // (under them, blocks appeared or went).
    CellRange changed{{N, N, N}, {0, 0, 0}};
    for (const auto& [l, at] : flipped) {
        const uint32_t s = N / g.levels_[l].res;
        changed.lo = {std::min(changed.lo.x, at.x * s), std::min(changed.lo.y, at.y * s),
                      std::min(changed.lo.z, at.z * s)};
        changed.hi = {std::max(changed.hi.x, (at.x + 1) * s),
                      std::max(changed.hi.y, (at.y + 1) * s),
                      std::max(changed.hi.z, (at.z + 1) * s)};
    }
    g.stats_.clearance_ms = 0;
    g.stats_.clearance_bytes = 0;
    if (opt.clearance && !flipped.empty()) g.build_clearance(&changed);

    uint64_t cells = 0;
    for (const PrunedGrid::Level& l : g.levels_) cells += l.cells.size();
    if (g.pool_.size > 2 * g.compact_words_ || cells > 2 * g.compact_cells_) compact(g);

    st.near_field_cells = census.near;
    st.tape_max = 0;
    for (size_t i = census.tape_hist.size(); i-- > 0;)
        if (census.tape_hist[i]) {
            st.tape_max = uint32_t(i);
            break;
        }
    st.active_max = 0;
    for (size_t i = census.prim_hist.size(); i-- > 0;)
        if (census.prim_hist[i]) {
            st.active_max = uint32_t(i);
            break;
        }
    finish_prune_stats(st, double(census.prim_sum), double(census.prim_sq_sum),
                       double(census.tape_sum), census.far_finest);
    st.tape_bytes = uint64_t(g.pool_.capacity) * sizeof(uint32_t);
    for (const PrunedGrid::Level& l : g.levels_)
        st.tape_bytes += uint64_t(l.cells.capacity()) * sizeof(PrunedCell);
    st.prune_peak_bytes = st.tape_bytes;
    st.prune_ms = ms_since(t0);
}

PrunedGrid update(PrunedGrid&& old, const Scene& edited, const SceneEdit& edit) {
    PrunedGrid g = std::move(old);
    GridUpdate::run(g, edited, edit, nullptr);
    return g;
}

PrunedGrid update(PrunedGrid&& old, std::shared_ptr<const Scene> edited, const SceneEdit& edit) {
    if (!edited) throw std::invalid_argument("update: null scene");
    PrunedGrid g = std::move(old);
    const Scene& scene = *edited;
    GridUpdate::run(g, scene, edit, std::move(edited));
    return g;
}

PrunedGrid update(const PrunedGrid& old, const Scene& edited, const SceneEdit& edit) {
    return update(PrunedGrid(old), edited, edit);
}

PrunedGrid update(const PrunedGrid& old, const Scene& edited) {
    return update(PrunedGrid(old), edited, scene_edit(old.scene(), edited));
}

bool same_cells(const PrunedGrid& a, const PrunedGrid& b) {
    if (a.level_count() != b.level_count() || a.resolution() != b.resolution()) return false;
    for (uint32_t l = 0; l < a.level_count(); ++l)
        if (a.level_factor(l) != b.level_factor(l)) return false;
    // The two hierarchies in step: pairs of blocks (level, first cell in a, first cell in b).
    struct Pair {
        uint32_t level, first_a, first_b;
    };
    std::vector<Pair> stack{{0, 0, 0}};
    while (!stack.empty()) {
        const Pair p = stack.back();
        stack.pop_back();
        const bool finest = p.level + 1 == a.level_count();
        const uint32_t f = a.level_factor(p.level);
        const auto ca = a.level_cells(p.level), cb = b.level_cells(p.level);
        if (uint64_t(p.first_a) + f * f * f > ca.size() ||
            uint64_t(p.first_b) + f * f * f > cb.size())
            return false;
        for (uint32_t i = 0; i < f * f * f; ++i) {
            const PrunedCell &x = ca[p.first_a + i], &y = cb[p.first_b + i];
            const bool far = x.tape == PrunedCell::kFarField;
            if (far != (y.tape == PrunedCell::kFarField) || !same_bytes(x.value, y.value))
                return false;
            if (far) {
                if (!same_bytes(x.bound, y.bound) || x.children != y.children) return false;
                continue;
            }
            const auto ta = a.tape_at(x.tape), tb = b.tape_at(y.tape);
            if (!std::ranges::equal(ta, tb) ||
                a.tape_pool()[x.tape + 1] != b.tape_pool()[y.tape + 1])
                return false;
            if (!finest) stack.push_back({p.level + 1, x.children, y.children});
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
